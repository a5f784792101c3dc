//! The `transition` task section (`zoo.transition`): what the runtime needs to run an RTN
//! transition (Harvey & Pal 2018) beyond the step graph itself.

use serde::{Deserialize, Serialize};

/// metadata_props key of the [`TransitionTask`] section.
pub const KEY: &str = "zoo.transition";

/// Largest terrain patch side the runtime accepts (the training side's limit too).
const MAX_TERRAIN_SIDE: usize = 1024;

/// How a `transition` model is driven: written by the RTN exporter from its config, parsed
/// strictly by the runtime (every field required, no unknown field).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitionTask {
    /// Context frames fed before the transition, as in training (the paper's 10).
    pub past_frames: usize,
    /// Transition length P the model was trained on, in frames (the paper's 30); the model
    /// then predicts P + 1 frames, the last one the target.
    pub transition_frames: usize,
    /// Target-blend length of the post-process in frames (RTN eq. 15-16); 0 disables it.
    pub target_blend: usize,
    /// Values of one feature frame, `D = 3K` for `K` joints: the width of the step graph's
    /// `x`, `offset` and `x_next`; the start graph's `target` has `2D`.
    pub frame_dim: usize,
    /// Whether the step graph takes the offset to the target, `offset` (RTN eq. 4; false for
    /// the `RTN\FUTURE` ablation).
    pub offset_input: bool,
    /// The local terrain patch input `terrain` of a terrain-aware RTN (RTN sec. 3.2), if any.
    pub terrain: Option<TransitionTerrain>,
}

/// The terrain patch of a terrain-aware RTN: `side * side` heights sampled on a square of
/// `extent` clip units around the root, fed as the step graph's `terrain` input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitionTerrain {
    /// Samples per side (the paper's 13).
    pub side: usize,
    /// Side length of the patch in clip units (the paper's 2.06 m).
    pub extent: f32,
}

impl TransitionTask {
    pub(crate) fn check(&self) -> Result<(), String> {
        if self.frame_dim == 0 || !self.frame_dim.is_multiple_of(3) {
            return Err(format!("frame_dim {} is not 3 values per joint", self.frame_dim));
        }
        if self.past_frames == 0 {
            return Err("past_frames is 0; a transition needs at least one context frame".into());
        }
        if let Some(t) = &self.terrain
            && !((1..=MAX_TERRAIN_SIDE).contains(&t.side) && t.extent.is_finite() && t.extent > 0.0)
        {
            return Err(format!(
                "terrain patch of side {} (1..={MAX_TERRAIN_SIDE}) and extent {} (> 0) is not a patch",
                t.side, t.extent
            ));
        }
        Ok(())
    }
}
