//! The `stitch` section (`zoo.stitch`): what the runtime needs to refine a stitched sequence
//! with an exported RMR (Kim et al. 2023) beyond its window graph.
//!
//! The graph is not a per-frame step: it maps one window of normalised pose vectors
//! `x [frames, batch, dim]` to refined ones `y [frames, batch, dim]` (contacts as logits), with
//! `dim = 7 + 6 L + 4 J` for `J` joints (`zoo.skeleton`) of which `L` are the lower body
//! ([`StitchTask::layout`]); the statistics are the normalization group `x` (`dim` values), and
//! `zoo.state` is empty.

use serde::{Deserialize, Serialize};
pub use zoo_motion::stitch::StitchLayout;

/// metadata_props key of the [`StitchTask`] section.
pub const KEY: &str = "zoo.stitch";

/// How a `stitch` model is driven (RMR sec. 6): windows of `window` frames every `stride`
/// frames plus one ending on the last frame, each window's first-frame difference blended away
/// over `blend_frames` frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StitchTask {
    /// Window `w`, frames (the paper's 60).
    pub window: usize,
    /// Stride `s` between windows, frames (`1..=window`; the paper's 30).
    pub stride: usize,
    /// Frames over which a window's first-frame difference is blended away.
    pub blend_frames: usize,
    /// Lower body, contact joints and their thresholds, forward axis of the hips.
    pub layout: StitchLayout,
}

impl StitchTask {
    /// Values per pose vector for a skeleton of `joints` joints: `7 + 6 L + 4 J`.
    pub fn dim(&self, joints: usize) -> usize {
        7 + 6 * self.layout.lower_body.len() + 4 * joints
    }

    /// Checks the section against the model's skeleton.
    pub fn check(&self, skeleton: &zoo_motion::Skeleton) -> Result<(), String> {
        if self.window == 0 || self.stride == 0 || self.stride > self.window {
            return Err(format!(
                "a window of {} frames with a stride of {}: the window must be at least 1 frame and the stride in 1..=window",
                self.window, self.stride
            ));
        }
        if self.blend_frames == 0 {
            return Err("blend_frames is 0; a window's difference is blended away over at least 1 frame".into());
        }
        if self.layout.contact_thresholds.iter().chain(&self.layout.planted).any(|v| !v.is_finite()) {
            return Err("the layout's contact thresholds and planted heights must be finite".into());
        }
        self.layout.validate(skeleton).map_err(|e| format!("`layout` does not fit the skeleton: {e}"))
    }
}
