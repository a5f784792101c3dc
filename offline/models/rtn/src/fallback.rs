//! A confidence signal computed from the inputs only, and the fallback it drives (issue 19,
//! not in the paper): the network's own miss at the target before the target blend.
//!
//! The target pose is an input of every transition, so how far the network's predicted target
//! frame lands from it (mean over joints of the distance, clip units) is known without any
//! ground truth. A model on motion it has seen lands close; on motion it has not, its unroll
//! drifts and the target blend of eq. 15-16 has to hide a large miss. [`Fallback`] turns the
//! miss into a weight `w` in `[0, 1]` (0 below `start`, 1 above `full`, linear between) and the
//! transition becomes `(1 - w) * RTN + w * interpolation` (the linear interpolation of
//! positions between the last context frame and the target). The thresholds are calibrated on
//! the validation windows at the end of `zoo train rtn` and stored in `config.json` (field
//! `fallback`), which the exported file's `transition` section carries; the runtime reads
//! them from there (`TransitionModel::default_fallback`).

use crate::error::RtnResult;
use crate::features::FeatureStats;
use crate::model::Rtn;
use serde::{Deserialize, Serialize};

/// Thresholds on the target miss (mean per-joint distance, clip units) of the fallback.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Fallback {
    /// Below this miss the RTN's transition is kept as it is.
    pub start: f32,
    /// From this miss on the transition is the interpolation.
    pub full: f32,
}

impl Fallback {
    /// Quantile of the validation misses that `start` is set to: in-distribution transitions
    /// trigger the fallback about 5% of the time.
    pub const START_QUANTILE: f64 = 0.95;
    /// `full` is this multiple of `start`.
    pub const FULL_FACTOR: f32 = 2.0;

    /// The weight of the interpolation for a target miss: 0 below `start`, 1 from `full` on
    /// (the runtime's rule, so that candle and the engine blend alike).
    pub fn weight(&self, miss: f32) -> f32 {
        zoo_format::TransitionFallback { start: self.start, full: self.full }.weight(miss)
    }

    /// Thresholds from the misses of in-distribution transitions: `start` at their
    /// [`Fallback::START_QUANTILE`], `full` at [`Fallback::FULL_FACTOR`] times it. `None`
    /// without misses.
    pub fn calibrate(misses: &[f32]) -> Option<Fallback> {
        zoo_nn::calibrate::fallback_thresholds(misses, Self::START_QUANTILE, Self::FULL_FACTOR)
            .map(|(start, full)| Fallback { start, full })
    }
}

/// Mean over joints of the distance between two poses of global positions (`3K` each).
pub fn mean_joint_distance(a: &[f32], b: &[f32]) -> f32 {
    let k = a.len() / 3;
    let sum: f32 = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .sum();
    sum / k.max(1) as f32
}

/// Blends `frames` (`n + 1` poses of global positions, the last one the target) towards the
/// linear interpolation of positions from `last` (the last context pose) to `target` with
/// weight `w`: frame `i` moves to `(1 - w) * frame + w * lerp(last, target, (i + 1) / (n + 1))`.
pub fn blend_towards_interpolation(frames: &mut [f32], last: &[f32], target: &[f32], w: f32) {
    let d = target.len();
    if w <= 0.0 || d == 0 {
        return;
    }
    let steps = (frames.len() / d) as f32;
    for (i, f) in frames.chunks_exact_mut(d).enumerate() {
        let a = (i + 1) as f32 / steps;
        for ((y, l), t) in f.iter_mut().zip(last).zip(target) {
            let lerp = l + a * (t - l);
            *y += w * (lerp - *y);
        }
    }
}

/// A transition with its confidence: the frames and what the fallback did.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckedTransition {
    /// `n + 1` frames of global positions, the last one the target.
    pub frames: Vec<f32>,
    /// The network's miss at the target before the blend (mean per-joint distance).
    pub miss: f32,
    /// The interpolation's weight in the frames (0: the RTN alone).
    pub weight: f32,
}

impl Rtn {
    /// [`Rtn::transition`] with the confidence signal: the miss of the unroll's target frame,
    /// and with `fallback` the blend towards interpolation it calls for. `terrain`: the ground
    /// of a terrain-aware model (required by one, ignored otherwise).
    #[allow(clippy::too_many_arguments)]
    pub fn transition_checked(
        &self,
        stats: &FeatureStats,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        n_frames: usize,
        terrain: Option<&crate::features::Heightmap>,
        fallback: Option<&Fallback>,
    ) -> RtnResult<CheckedTransition> {
        let mut frames = self.unroll(stats, past, target, next, n_frames, terrain)?;
        let d = target.len();
        let miss = mean_joint_distance(&frames[frames.len() - d..], target);
        crate::features::target_blend(&mut frames, target, self.config().target_blend);
        let weight = fallback.map_or(0.0, |f| f.weight(miss));
        blend_towards_interpolation(&mut frames, &past[past.len() - d..], target, weight);
        Ok(CheckedTransition { frames, miss, weight })
    }
}

/// The target misses of the model's transitions of its trained length on `windows` (no
/// teacher forcing, no rotation), in batches of 64: what [`Fallback::calibrate`] reads.
pub fn target_misses(model: &Rtn, stats: &FeatureStats, windows: &[crate::MotionWindow]) -> RtnResult<Vec<f32>> {
    target_misses_at(model, stats, windows, model.config().transition_frames)
}

/// [`target_misses`] of transitions of `n` frames (at most the trained length: the target is
/// frame `past + n` of each window).
pub fn target_misses_at(
    model: &Rtn,
    stats: &FeatureStats,
    windows: &[crate::MotionWindow],
    n: usize,
) -> RtnResult<Vec<f32>> {
    use crate::transition::{SequenceInput, encode_batch, generate};
    let c = model.config();
    if n == 0 || n > c.transition_frames {
        return Err(crate::error::RtnError::Config(format!(
            "target misses at {n} frames: between 1 and the trained length {}",
            c.transition_frames
        )));
    }
    let (d, past, tf) = (c.dim(), c.past_frames, c.past_frames + n);
    let device = model.device();
    let offsets = crate::model::OffsetTensors::new(stats, device)?;
    let mut out = Vec::with_capacity(windows.len());
    for chunk in windows.chunks(64) {
        let items: Vec<SequenceInput> = chunk
            .iter()
            .map(|w| SequenceInput {
                known: w.positions[..past * d].into(),
                target: w.positions[tf * d..(tf + 1) * d].into(),
                next: w.positions[(tf + 1) * d..(tf + 2) * d].into(),
                terrain: w.terrain,
                rotation: None,
            })
            .collect();
        let batch = encode_batch(stats, &items, device)?;
        let outs = generate(model, stats, &offsets, &batch, past, n + 1, false, &mut || false)?;
        // Integrate the root velocities to the predicted target frame, then decode it.
        let mut roots: Vec<[f32; 3]> =
            items.iter().map(|it| crate::features::root_of(&it.known[(past - 1) * d..])).collect();
        let mut last = Vec::new();
        for o in &outs {
            last = o.to_vec2::<f32>()?;
            for (r, row) in roots.iter_mut().zip(&last) {
                for a in 0..3 {
                    r[a] += row[a] * stats.x.std[a] + stats.x.mean[a];
                }
            }
        }
        for ((it, row), r) in items.iter().zip(&last).zip(&roots) {
            let mut f = row.clone();
            stats.x.denormalize(&mut f);
            let mut y = vec![0.0; d];
            let prev = [r[0] - f[0], r[1] - f[1], r[2] - f[2]];
            crate::features::decode_frame(prev, &f, &mut y);
            out.push(mean_joint_distance(&y, &it.target));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weight_ramps_between_the_thresholds() {
        let f = Fallback { start: 2.0, full: 4.0 };
        assert_eq!(f.weight(1.0), 0.0);
        assert_eq!(f.weight(3.0), 0.5);
        assert_eq!(f.weight(9.0), 1.0);
        assert_eq!(f.weight(f32::NAN), 1.0);
    }

    #[test]
    fn calibration_puts_start_at_the_95th_percentile() {
        let misses: Vec<f32> = (1..=100).map(|i| i as f32).collect();
        let f = Fallback::calibrate(&misses).unwrap();
        assert!((f.start - 95.0).abs() <= 1.0, "{f:?}");
        assert_eq!(f.full, 2.0 * f.start);
        let triggered = misses.iter().filter(|&&m| f.weight(m) > 0.0).count();
        assert!(triggered <= 6, "{triggered}");
        assert!(Fallback::calibrate(&[]).is_none());
    }

    #[test]
    fn full_weight_is_the_interpolation_and_zero_changes_nothing() {
        let last = [0.0, 0.0, 0.0, 0.0, 10.0, 0.0];
        let target = [4.0, 0.0, 0.0, 4.0, 10.0, 0.0];
        let rtn: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let mut same = rtn.clone();
        blend_towards_interpolation(&mut same, &last, &target, 0.0);
        assert_eq!(same, rtn);
        let mut interp = rtn.clone();
        blend_towards_interpolation(&mut interp, &last, &target, 1.0);
        assert_eq!(&interp[..6], &[2.0, 0.0, 0.0, 2.0, 10.0, 0.0]);
        assert_eq!(&interp[6..], &target);
        assert!((mean_joint_distance(&last, &target) - 4.0).abs() < 1e-6);
    }
}
