//! The `transition` section (`zoo.transition`): what the runtime needs to run an RTN
//! transition (Harvey & Pal 2018) beyond the step graph itself.

use serde::{Deserialize, Serialize};

/// metadata_props key of the [`TransitionTask`] section.
pub const KEY: &str = "zoo.transition";

/// Largest terrain patch side the runtime accepts (the training side's limit too).
pub const MAX_TERRAIN_SIDE: usize = 1024;

/// How a `transition` model is driven: written by the RTN exporter from its config, parsed
/// strictly (every field required, `null` where a feature is off; no unknown field).
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
    /// The local terrain patch input `terrain` of a terrain-aware RTN (RTN sec. 3.2); `null`
    /// for a model without terrain.
    #[serde(deserialize_with = "Option::deserialize")]
    pub terrain: Option<TransitionTerrain>,
    /// The fallback towards interpolation calibrated by `zoo train rtn`; `null` when the run
    /// has none (the runtime then applies none unless the engine sets one).
    #[serde(deserialize_with = "Option::deserialize")]
    pub fallback: Option<TransitionFallback>,
    /// The time-to-arrival input `tta` of a model trained over several transition lengths
    /// (Harvey et al. 2020's embedding of the frames left to the target); `null` for a model
    /// without it. Files written before the field existed load as `null`.
    #[serde(default)]
    pub time_to_arrival: Option<TimeToArrival>,
    /// Fallback thresholds calibrated at several transition lengths, shortest first, for a model
    /// trained over several lengths (empty: `fallback` for every length). Files written before
    /// the field existed load with none.
    #[serde(default)]
    pub fallback_lengths: Vec<TransitionFallbackAt>,
}

/// Fallback thresholds calibrated at one transition length (see [`TransitionFallback`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitionFallbackAt {
    /// The transition length, frames.
    pub length: usize,
    /// Miss below which the network's transition is kept.
    pub start: f32,
    /// Miss from which the transition is the interpolation.
    pub full: f32,
}

/// The fallback thresholds for a transition of `length` frames: with a table calibrated at
/// several lengths (shortest first), interpolated linearly in the length between the two
/// calibrated lengths around it (the nearest one outside their range); without one, `fallback`.
pub fn fallback_for(
    fallback: Option<TransitionFallback>,
    table: &[TransitionFallbackAt],
    length: usize,
) -> Option<TransitionFallback> {
    let (Some(first), Some(last)) = (table.first(), table.last()) else { return fallback };
    let at = |e: &TransitionFallbackAt| TransitionFallback { start: e.start, full: e.full };
    if length <= first.length {
        return Some(at(first));
    }
    if length >= last.length {
        return Some(at(last));
    }
    let i = table.iter().position(|e| e.length >= length).expect("length is below the last entry's");
    let (a, b) = (&table[i - 1], &table[i]);
    let w = (length - a.length) as f32 / (b.length - a.length) as f32;
    Some(TransitionFallback { start: a.start + w * (b.start - a.start), full: a.full + w * (b.full - a.full) })
}

/// The time-to-arrival embedding fed to the step graph as `tta` (`dims` values): the frames
/// left from the predicted frame to the target (0 at the target), clamped at `max`, as pairs of
/// sines and cosines of geometrically spaced frequencies, from a quarter turn over `max` frames
/// (the slowest, monotonic over the range) to one radian a frame (the fastest). Training and the
/// runtime compute it with [`TimeToArrival::embed`], so both feed the same values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeToArrival {
    /// Values of the embedding (even, at least 2).
    pub dims: usize,
    /// Frames from which the embedding stays constant (at least 1).
    pub max: usize,
}

impl TimeToArrival {
    /// Largest `dims` accepted.
    pub const MAX_DIMS: usize = 256;
    /// Largest `max` accepted (frames).
    pub const MAX_FRAMES: usize = 100_000;

    /// Writes the embedding of `frames_left` (frames from the predicted frame to the target)
    /// into `out` (`dims` values).
    pub fn embed(&self, frames_left: usize, out: &mut [f32]) {
        let max = self.max.max(1);
        let t = frames_left.min(max) as f64;
        let pairs = out.len() / 2;
        let slow = std::f64::consts::FRAC_PI_2 / max as f64;
        for (i, pair) in out.chunks_exact_mut(2).enumerate() {
            // Frequencies from `slow` (i = 0) to 1 rad/frame (the last pair), geometric.
            let a = if pairs > 1 { i as f64 / (pairs - 1) as f64 } else { 0.0 };
            let w = slow * (1.0 / slow).powf(a);
            pair[0] = (t * w).sin() as f32;
            pair[1] = (t * w).cos() as f32;
        }
    }

    /// Checks the sizes: `dims` even in `2..=MAX_DIMS`, `max` in `1..=MAX_FRAMES`.
    pub fn check(&self) -> Result<(), String> {
        if !(2..=Self::MAX_DIMS).contains(&self.dims) || !self.dims.is_multiple_of(2) {
            return Err(format!("time_to_arrival.dims {} must be an even number in 2..={}", self.dims, Self::MAX_DIMS));
        }
        if !(1..=Self::MAX_FRAMES).contains(&self.max) {
            return Err(format!("time_to_arrival.max {} must be in 1..={} frames", self.max, Self::MAX_FRAMES));
        }
        Ok(())
    }
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

/// The fallback towards interpolation on a low-confidence transition: the confidence signal is
/// the network's own miss at the target (the mean over joints of the distance between the
/// predicted target frame and the requested one, computed from the inputs only); from `start`
/// on, the transition is blended towards the linear interpolation of positions between the last
/// context pose and the target, fully from `full` on. Thresholds in the model's units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransitionFallback {
    /// Miss below which the network's transition is kept.
    pub start: f32,
    /// Miss from which the transition is the interpolation.
    pub full: f32,
}

impl TransitionFallback {
    /// The interpolation's weight for a target miss: 0 below `start`, 1 from `full` on, linear
    /// between (a non-finite miss gives 1).
    pub fn weight(&self, miss: f32) -> f32 {
        if !miss.is_finite() {
            return 1.0;
        }
        if self.full <= self.start {
            return if miss >= self.start { 1.0 } else { 0.0 };
        }
        ((miss - self.start) / (self.full - self.start)).clamp(0.0, 1.0)
    }

    /// Checks the thresholds: finite, `0 <= start`, `start <= full`.
    pub fn check(&self) -> Result<(), String> {
        if !(self.start.is_finite() && self.full.is_finite() && self.start >= 0.0 && self.full >= self.start) {
            return Err(format!(
                "fallback thresholds start {} and full {}: they must be finite with 0 <= start <= full",
                self.start, self.full
            ));
        }
        Ok(())
    }
}

impl TransitionTask {
    /// The fallback thresholds for a transition of `length` frames ([`fallback_for`] of
    /// `fallback` and `fallback_lengths`).
    pub fn fallback_for(&self, length: usize) -> Option<TransitionFallback> {
        fallback_for(self.fallback, &self.fallback_lengths, length)
    }

    /// Checks the section against a skeleton of `joints` joints.
    pub fn check(&self, joints: usize) -> Result<(), String> {
        if self.frame_dim == 0 || !self.frame_dim.is_multiple_of(3) {
            return Err(format!("frame_dim {} is not 3 values per joint", self.frame_dim));
        }
        if self.frame_dim != 3 * joints {
            return Err(format!(
                "frame_dim is {} but the skeleton has {joints} joints ({} values)",
                self.frame_dim,
                3 * joints
            ));
        }
        if self.past_frames == 0 {
            return Err("past_frames is 0; a transition needs at least one context frame".into());
        }
        if self.transition_frames == 0 {
            return Err("transition_frames is 0; a model is trained for at least one frame".into());
        }
        if let Some(t) = &self.terrain
            && !((1..=MAX_TERRAIN_SIDE).contains(&t.side) && t.extent.is_finite() && t.extent > 0.0)
        {
            return Err(format!(
                "terrain patch of side {} (1..={MAX_TERRAIN_SIDE}) and extent {} (> 0) is not a patch",
                t.side, t.extent
            ));
        }
        if let Some(f) = &self.fallback {
            f.check()?;
        }
        if let Some(t) = &self.time_to_arrival {
            t.check()?;
        }
        for (i, e) in self.fallback_lengths.iter().enumerate() {
            TransitionFallback { start: e.start, full: e.full }.check()?;
            if e.length == 0 || (i > 0 && e.length <= self.fallback_lengths[i - 1].length) {
                return Err(format!(
                    "fallback_lengths: length {} at entry {i}: the lengths must be at least 1 and strictly increase",
                    e.length
                ));
            }
        }
        Ok(())
    }
}
