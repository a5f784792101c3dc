//! The `stitch` section (`zoo.stitch`): what the runtime needs to refine a stitched sequence
//! with an exported RMR (Kim et al. 2023) beyond its window graph.
//!
//! The graph is not a per-frame step: it maps one window of normalised pose vectors
//! `x [frames, batch, dim]` to refined ones `y [frames, batch, dim]` (contacts as logits), with
//! `dim = 7 + 6 L + 4 J` for `J` joints (`zoo.skeleton`) of which `L` are the lower body
//! ([`StitchTask::layout`]); the statistics are the normalization group `x` (`dim` values), and
//! `zoo.state` is empty.

use serde::{Deserialize, Serialize};
pub use zoo_protocol::stitch::StitchLayout;

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
    /// The model was trained on sequences inertialized at their seams (`zoo train rmr
    /// --pre-blend`): give the runtime the seams so that it inertializes them before refining,
    /// as `zoo stitch` does. Files written before the field existed: `false`.
    #[serde(default)]
    pub pre_blend: bool,
    /// The fallback towards the refiner's input calibrated by `zoo train rmr`
    /// ([`StitchFallback`]); `null` or absent: none.
    #[serde(default)]
    pub fallback: Option<StitchFallback>,
}

/// The fallback towards the refiner's input on a window it corrects far more than it corrected
/// its validation pairs: the confidence signal is the window's correction size
/// ([`correction_size`]); from `start` on the window's pose values are blended towards its
/// input, fully from `full` on. Thresholds in normalised units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StitchFallback {
    /// Correction size below which the refined window is kept.
    pub start: f32,
    /// Correction size from which the window is its input.
    pub full: f32,
}

impl StitchFallback {
    /// The input's weight for a correction `size`: 0 below `start`, 1 from `full` on, linear
    /// between, 1 for a non-finite size (the transition fallback's rule).
    pub fn weight(&self, size: f32) -> f32 {
        crate::TransitionFallback { start: self.start, full: self.full }.weight(size)
    }

    /// Blends the refined window `output` towards its `input` (normalised, whole frames of
    /// `dim` values whose first `pose` are pose values and the rest contacts) by the weight of
    /// its [`correction_size`]: pose values become `(1 - w) output + w input`, contacts stay.
    /// Returns the weight.
    pub fn apply(&self, input: &[f32], output: &mut [f32], dim: usize, pose: usize) -> f32 {
        let w = self.weight(correction_size(input, output, dim, pose));
        if w > 0.0 {
            for (x, y) in input.chunks_exact(dim).zip(output.chunks_exact_mut(dim)) {
                for (xv, yv) in x[..pose].iter().zip(&mut y[..pose]) {
                    *yv = (1.0 - w) * *yv + w * xv;
                }
            }
        }
        w
    }

    /// Checks the thresholds: finite, `0 <= start <= full`.
    pub fn check(&self) -> Result<(), String> {
        crate::TransitionFallback { start: self.start, full: self.full }.check()
    }
}

/// A refined window's correction size: the root mean square of `output - input` over the pose
/// values (the first `pose` of each frame of `dim` values; not the contacts); 0 for no frame.
pub fn correction_size(input: &[f32], output: &[f32], dim: usize, pose: usize) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (x, y) in input.chunks_exact(dim).zip(output.chunks_exact(dim)) {
        for (xv, yv) in x[..pose].iter().zip(&y[..pose]) {
            let e = (yv - xv) as f64;
            sum += e * e;
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { (sum / n as f64).sqrt() as f32 }
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
        if let Some(f) = &self.fallback {
            f.check()?;
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
