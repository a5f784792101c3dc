//! The in-betweening metrics of `BENCHMARK.md`: L2Q, L2P, NPSS, ACO and foot skate.
//!
//! Arrays are `(windows, frames, joints)` flattened frame-major per window, in f64 (the
//! reference implementation is float64).

use glam::{DQuat, DVec3};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// L2Q: per frame, the L2 norm over all joints' global quaternion components of
/// `pred - gt` (no sign canonicalisation); mean over frames and windows.
pub fn l2q(pred: &[DQuat], gt: &[DQuat], joints: usize) -> f64 {
    let frames = gt.len() / joints;
    let mut total = 0.0;
    for (p, g) in pred.chunks_exact(joints).zip(gt.chunks_exact(joints)) {
        let mut s = 0.0;
        for (a, b) in p.iter().zip(g) {
            let d = *a - *b;
            s += d.length_squared();
        }
        total += s.sqrt();
    }
    total / frames as f64
}

/// L2P: global positions normalized per coordinate with training `mean`/`std`
/// (joint-major, 3 per joint), per-frame L2 norm over coordinates, mean over frames.
pub fn l2p(pred: &[DVec3], gt: &[DVec3], joints: usize, std: &[f64]) -> f64 {
    // (p - m) / s - (g - m) / s = (p - g) / s: the mean cancels.
    let frames = gt.len() / joints;
    let inv: Vec<f64> = std.iter().map(|s| 1.0 / s).collect();
    let mut total = 0.0;
    for (p, g) in pred.chunks_exact(joints).zip(gt.chunks_exact(joints)) {
        let mut s = 0.0;
        for j in 0..joints {
            let d = p[j] - g[j];
            for a in 0..3 {
                let v = d[a] * inv[j * 3 + a];
                s += v * v;
            }
        }
        total += s.sqrt();
    }
    total / frames as f64
}

/// ACO: mean absolute offset of global positions over joints, coordinates and frames
/// (clip units, e.g. cm).
pub fn aco(pred: &[DVec3], gt: &[DVec3]) -> f64 {
    let s: f64 = pred.iter().zip(gt).map(|(p, g)| (*p - *g).abs().element_sum()).sum();
    s / (gt.len() * 3) as f64
}

/// NPSS of global quaternions, `(windows, frames, joints)`: per (window, component) the
/// normalized cumulative power spectrum (real part of the FFT along time, squared), EMD = L1
/// distance of the cumulative sums, averaged with the ground truth's total power as weight.
pub fn npss(pred: &[DQuat], gt: &[DQuat], windows: usize, frames: usize, joints: usize) -> f64 {
    let dims = joints * 4;
    let mut planner = FftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(frames);
    let mut buf_g = vec![Complex::new(0.0, 0.0); frames];
    let mut buf_p = vec![Complex::new(0.0, 0.0); frames];
    let mut scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
    let comp = |q: &DQuat, c: usize| -> f64 {
        // (w, x, y, z) order as in the reference; any fixed order gives the same average.
        match c {
            0 => q.w,
            1 => q.x,
            2 => q.y,
            _ => q.z,
        }
    };
    let (mut weighted, mut weights) = (0.0, 0.0);
    for w in 0..windows {
        for d in 0..dims {
            let (j, c) = (d / 4, d % 4);
            for f in 0..frames {
                let i = (w * frames + f) * joints + j;
                buf_g[f] = Complex::new(comp(&gt[i], c), 0.0);
                buf_p[f] = Complex::new(comp(&pred[i], c), 0.0);
            }
            fft.process_with_scratch(&mut buf_g, &mut scratch);
            fft.process_with_scratch(&mut buf_p, &mut scratch);
            let tg: f64 = buf_g.iter().map(|z| z.re * z.re).sum();
            let tp: f64 = buf_p.iter().map(|z| z.re * z.re).sum();
            if tg == 0.0 {
                continue; // zero weight (the reference would produce NaN here)
            }
            let (mut cg, mut cp, mut emd) = (0.0, 0.0, 0.0);
            for f in 0..frames {
                cg += buf_g[f].re * buf_g[f].re / tg;
                cp += if tp > 0.0 { buf_p[f].re * buf_p[f].re / tp } else { 0.0 };
                emd += (cp - cg).abs();
            }
            weighted += emd * tg;
            weights += tg;
        }
    }
    weighted / weights
}

/// Foot-skate parameters: which joints are feet and their planted heights.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct FootSkate {
    /// Foot joint indices.
    pub joints: Vec<usize>,
    /// Planted height of each foot joint (5th percentile of its height on the training set).
    pub planted: Vec<f64>,
    /// Height scale of the contact weight, in clip units (2.5 for cm).
    pub scale: f64,
}

impl FootSkate {
    /// Skate parameters for foot `joints` with their planted heights measured on `clips` (the
    /// 5th percentile of each joint's height over every frame), scale 2.5 (cm).
    pub fn fit(joints: Vec<usize>, clips: &[&zoo_motion::Clip]) -> FootSkate {
        let mut heights = vec![Vec::new(); joints.len()];
        for c in clips {
            let (_, gp) = c.global();
            for f in 0..c.frames() {
                for (k, &j) in joints.iter().enumerate() {
                    heights[k].push(gp[f * c.joints() + j].y);
                }
            }
        }
        let planted = heights.iter().map(|h| crate::plausibility::percentile(h, 5.0)).collect();
        FootSkate { joints, planted, scale: 2.5 }
    }

    /// Mean skate over whole clips (frames 1.. of each, weighted by their frame count; clips of
    /// fewer than 2 frames are skipped; NaN when none is left).
    pub fn mean_over(&self, clips: &[&zoo_motion::Clip]) -> f64 {
        let (mut sum, mut n) = (0.0, 0usize);
        for c in clips.iter().filter(|c| c.frames() >= 2) {
            let (_, gp) = c.global();
            sum += self.skate(&gp, c.frames(), c.joints()) * (c.frames() - 1) as f64;
            n += c.frames() - 1;
        }
        if n == 0 { f64::NAN } else { sum / n as f64 }
    }

    /// Mean skate (units per frame) over foot joints and frames `1..` of each sequence, where
    /// frame 0 of each sequence only provides the previous position.
    ///
    /// `global_pos` is `(sequences, frames, joints)` frame-major with `frames` including that
    /// leading frame. skate = v * clamp(2 - 2^(h / scale), 0, 1), v the horizontal displacement
    /// since the previous frame, h the height above the planted height.
    /// NaN when there is nothing to measure (no foot joint, or fewer than two frames).
    pub fn skate(&self, global_pos: &[DVec3], frames: usize, joints: usize) -> f64 {
        if frames * joints == 0 {
            return f64::NAN;
        }
        let seqs = global_pos.len() / (frames * joints);
        let (mut total, mut count) = (0.0, 0usize);
        for s in 0..seqs {
            for f in 1..frames {
                for (k, &j) in self.joints.iter().enumerate() {
                    let cur = global_pos[(s * frames + f) * joints + j];
                    let prev = global_pos[(s * frames + f - 1) * joints + j];
                    let v = ((cur.x - prev.x).powi(2) + (cur.z - prev.z).powi(2)).sqrt();
                    let h = cur.y - self.planted[k];
                    total += v * (2.0 - 2f64.powf(h / self.scale)).clamp(0.0, 1.0);
                    count += 1;
                }
            }
        }
        if count == 0 { f64::NAN } else { total / count as f64 }
    }
}

/// Foot joints found by name: the joints whose name contains `foot` or `toe` (any case).
pub fn foot_joints(names: &[String]) -> Vec<usize> {
    names
        .iter()
        .enumerate()
        .filter(|(_, n)| {
            let n = n.to_ascii_lowercase();
            n.contains("foot") || n.contains("toe")
        })
        .map(|(i, _)| i)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wave(windows: usize, frames: usize, joints: usize, phase: f64) -> Vec<DQuat> {
        (0..windows * frames * joints)
            .map(|i| DQuat::from_rotation_y(((i / joints) as f64 * 0.3 + phase).sin()))
            .collect()
    }

    #[test]
    fn npss_of_identical_sequences_is_zero() {
        let a = wave(3, 20, 2, 0.0);
        assert!(npss(&a, &a, 3, 20, 2).abs() < 1e-15);
        let b = wave(3, 20, 2, 1.0);
        assert!(npss(&b, &a, 3, 20, 2) > 1e-3);
    }

    #[test]
    fn l2q_hand_computed() {
        // one frame, two joints: difference (0,0,0,1) and (0,1,0,0) -> sqrt(2)
        let gt = [DQuat::from_xyzw(0.0, 0.0, 0.0, 1.0), DQuat::from_xyzw(0.0, 0.0, 0.0, 1.0)];
        let pred = [DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0), DQuat::from_xyzw(0.0, 1.0, 0.0, 1.0)];
        assert!((l2q(&pred, &gt, 2) - 2f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn l2p_and_aco_hand_computed() {
        let gt = [DVec3::ZERO];
        let pred = [DVec3::new(3.0, 4.0, 0.0)];
        assert!((l2p(&pred, &gt, 1, &[1.0, 2.0, 1.0]) - 13f64.sqrt()).abs() < 1e-15);
        assert!((aco(&pred, &gt) - 7.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn skate_counts_only_low_feet() {
        let fs = FootSkate { joints: vec![0], planted: vec![0.0], scale: 2.5 };
        // planted foot sliding 1 unit per frame: skate 1; foot 10 units up: 0.
        let low = [DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0)];
        let high = [DVec3::new(0.0, 10.0, 0.0), DVec3::new(1.0, 10.0, 0.0)];
        assert!((fs.skate(&low, 2, 1) - 1.0).abs() < 1e-15);
        assert_eq!(fs.skate(&high, 2, 1), 0.0);
    }

    #[test]
    fn feet_found_by_name() {
        let names: Vec<String> =
            ["Hips", "Foot_L", "Toes_L", "LeftFoot", "LeftToe", "Spine"].iter().map(|s| s.to_string()).collect();
        assert_eq!(foot_joints(&names), vec![1, 2, 3, 4]);
    }
}
