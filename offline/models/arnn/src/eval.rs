//! How well keys are completed, against what an animator has without the network: linear and
//! natural cubic spline interpolation of the same keys (`docs/arnn.md`, "Test error").
//!
//! Errors compare a completed sequence with the ground truth on every frame after the first
//! (frame 0 is the first key, given): the frame error is the mean squared error in normalised
//! units (each degree of freedom divided by its training standard deviation), the training's
//! frame loss; the key error is the same over the key frames after the first; the RMSE per
//! degree of freedom is in physical units (metres, radians).

use crate::luxo::LampParams;
use crate::luxo::preprocess::KeyedSequence;
use crate::train::{Normalization, complete_raw};
use crate::{Arnn, ArnnError, ArnnResult};
use serde::{Deserialize, Serialize};

/// Linear interpolation of each degree of freedom between the keys: one pose per frame from
/// the first key to the last (`key_frames` strictly increasing).
pub fn linear(key_frames: &[usize], key_poses: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (first, last) = (key_frames[0], key_frames[key_frames.len() - 1]);
    (first..=last)
        .map(|t| {
            let k = key_frames.partition_point(|&f| f <= t).clamp(1, key_frames.len() - 1);
            let (a, b) = (key_frames[k - 1], key_frames[k]);
            let w = (t - a) as f64 / (b - a) as f64;
            key_poses[k - 1].iter().zip(&key_poses[k]).map(|(x, y)| x + (y - x) * w).collect()
        })
        .collect()
}

/// Natural cubic spline (zero second derivative at both ends) through the keys of each degree
/// of freedom, sampled at every frame from the first key to the last; two keys give a line.
pub fn cubic_spline(key_frames: &[usize], key_poses: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = key_frames.len();
    let d = key_poses[0].len();
    let x: Vec<f64> = key_frames.iter().map(|&f| f as f64).collect();
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    // Second derivatives m per key and degree of freedom: a tridiagonal system (Thomas
    // algorithm) for the interior keys, m = 0 at the ends.
    let mut m = vec![vec![0.0; d]; n];
    if n > 2 {
        for j in 0..d {
            let y: Vec<f64> = key_poses.iter().map(|p| p[j]).collect();
            let k = n - 2;
            let (mut diag, mut rhs) = (vec![0.0; k], vec![0.0; k]);
            let mut upper = vec![0.0; k];
            for i in 0..k {
                diag[i] = 2.0 * (h[i] + h[i + 1]);
                upper[i] = h[i + 1];
                rhs[i] = 6.0 * ((y[i + 2] - y[i + 1]) / h[i + 1] - (y[i + 1] - y[i]) / h[i]);
            }
            for i in 1..k {
                let w = h[i] / diag[i - 1];
                diag[i] -= w * upper[i - 1];
                rhs[i] -= w * rhs[i - 1];
            }
            let mut sol = vec![0.0; k];
            for i in (0..k).rev() {
                let next = if i + 1 < k { upper[i] * sol[i + 1] } else { 0.0 };
                sol[i] = (rhs[i] - next) / diag[i];
            }
            for i in 0..k {
                m[i + 1][j] = sol[i];
            }
        }
    }
    let (first, last) = (key_frames[0], key_frames[n - 1]);
    (first..=last)
        .map(|t| {
            let k = key_frames.partition_point(|&f| f <= t).clamp(1, n - 1) - 1;
            let (hk, u) = (h[k], t as f64 - x[k]);
            let v = hk - u;
            (0..d)
                .map(|j| {
                    let (y0, y1, m0, m1) = (key_poses[k][j], key_poses[k + 1][j], m[k][j], m[k + 1][j]);
                    m0 * v.powi(3) / (6.0 * hk)
                        + m1 * u.powi(3) / (6.0 * hk)
                        + (y0 / hk - m0 * hk / 6.0) * v
                        + (y1 / hk - m1 * hk / 6.0) * u
                })
                .collect()
        })
        .collect()
}

/// Errors of one completion method over a set of sequences (see the module docs).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompletionError {
    /// Mean squared error over every frame after the first, normalised units.
    pub frame: f64,
    /// Mean squared error over the key frames after the first, normalised units.
    pub key: f64,
    /// Root mean squared error per degree of freedom over every frame after the first
    /// (metres, radians).
    pub rmse: Vec<f64>,
    /// Largest absolute error at a key frame, per degree of freedom (metres, radians).
    pub max_key_miss: Vec<f64>,
    /// Lowest point of the base plate over all frames, below the ground when negative
    /// (metres; computed from the lamp's geometry, `None` without it).
    pub lowest_base: Option<f64>,
}

/// The lowest point of the lamp's base plate in `pose` (metres above the ground).
pub fn base_clearance(lamp: &LampParams, pose: &[f64]) -> f64 {
    let (s, c) = pose[2].sin_cos();
    pose[1] - lamp.base_half_height * c.abs() - lamp.base_half_width * s.abs()
}

/// Lifts the base of every pose whose base plate is below the ground by that depth, so that
/// its lowest point is on the ground (`base_clearance >= 0` afterwards, up to rounding); other
/// poses and the other degrees of freedom are unchanged. Returns the largest lift (metres, 0 when
/// no pose was below). The lamp's degrees of freedom ([`crate::luxo::DOF_NAMES`]) in each
/// pose.
///
/// This is the minimal change that satisfies the ground (raising the base moves every link by
/// the same amount and keeps the joint angles and the base's tilt, which animators key).
pub fn project_to_ground(lamp: &LampParams, poses: &mut [Vec<f64>]) -> f64 {
    let mut lift = 0.0f64;
    for p in poses.iter_mut() {
        let c = base_clearance(lamp, p);
        if c < 0.0 {
            p[1] -= c;
            lift = lift.max(-c);
        }
    }
    lift
}

/// Accumulates [`CompletionError`] over sequences.
#[derive(Clone, Debug)]
struct Accumulator {
    sq_norm: f64,
    frames: usize,
    key_sq_norm: f64,
    keys: usize,
    sq: Vec<f64>,
    max_key: Vec<f64>,
    lowest: Option<f64>,
}

impl Accumulator {
    fn new(d: usize) -> Self {
        Accumulator {
            sq_norm: 0.0,
            frames: 0,
            key_sq_norm: 0.0,
            keys: 0,
            sq: vec![0.0; d],
            max_key: vec![0.0; d],
            lowest: None,
        }
    }

    fn add(&mut self, pred: &[Vec<f64>], seq: &KeyedSequence, norm: &Normalization, lamp: Option<&LampParams>) {
        for (t, (p, y)) in pred.iter().zip(&seq.frames).enumerate().skip(1) {
            let is_key = seq.keys.contains(&t);
            for j in 0..p.len() {
                let e = p[j] - y[j];
                let en = (e / norm.std[j]).powi(2);
                self.sq_norm += en;
                self.sq[j] += e * e;
                if is_key {
                    self.key_sq_norm += en;
                    self.max_key[j] = self.max_key[j].max(e.abs());
                }
            }
            self.frames += 1;
            if is_key {
                self.keys += 1;
            }
        }
        if let Some(lamp) = lamp {
            let low = pred.iter().map(|p| base_clearance(lamp, p)).fold(f64::INFINITY, f64::min);
            self.lowest = Some(self.lowest.map_or(low, |l| l.min(low)));
        }
    }

    fn finish(self) -> CompletionError {
        let d = self.sq.len().max(1) as f64;
        let frames = self.frames.max(1) as f64;
        CompletionError {
            frame: self.sq_norm / (frames * d),
            key: self.key_sq_norm / (self.keys.max(1) as f64 * d),
            rmse: self.sq.iter().map(|s| (s / frames).sqrt()).collect(),
            max_key_miss: self.max_key,
            lowest_base: self.lowest,
        }
    }
}

/// The network against linear and spline interpolation on the same keys (every key of each
/// sequence).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompletionReport {
    /// Sequences evaluated.
    pub sequences: usize,
    /// The network (the ARNN or a Table 2 architecture), its output as is.
    pub arnn: CompletionError,
    /// The network's output with the base lifted out of the ground ([`project_to_ground`]),
    /// what `zoo complete` writes (absent without the lamp's geometry).
    #[serde(default)]
    pub arnn_grounded: Option<CompletionError>,
    /// Linear interpolation of the keys.
    pub linear: CompletionError,
    /// Natural cubic spline through the keys.
    pub spline: CompletionError,
}

/// Completes every sequence from all its keys with the network, linear and spline
/// interpolation, and measures each against the ground truth.
pub fn evaluate(model: &Arnn, norm: &Normalization, seqs: &[KeyedSequence]) -> ArnnResult<CompletionReport> {
    if seqs.is_empty() {
        return Err(ArnnError::Config("no sequence to evaluate".into()));
    }
    let d = model.config().dofs;
    let lamp = model.config().lamp.as_ref();
    let (mut a, mut l, mut s) = (Accumulator::new(d), Accumulator::new(d), Accumulator::new(d));
    let mut g = Accumulator::new(d);
    for seq in seqs {
        let poses: Vec<Vec<f64>> = seq.keys.iter().map(|&k| seq.frames[k].to_vec()).collect();
        // The network's own output: its key misses are its quality figure (`zoo complete` hits them).
        let mut out = complete_raw(model, norm, &seq.keys, &poses)?;
        a.add(&out, seq, norm, lamp);
        if let Some(lamp) = lamp {
            project_to_ground(lamp, &mut out);
            g.add(&out, seq, norm, Some(lamp));
        }
        l.add(&linear(&seq.keys, &poses), seq, norm, lamp);
        s.add(&cubic_spline(&seq.keys, &poses), seq, norm, lamp);
    }
    Ok(CompletionReport {
        sequences: seqs.len(),
        arnn: a.finish(),
        arnn_grounded: lamp.map(|_| g.finish()),
        linear: l.finish(),
        spline: s.finish(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_and_spline_pass_through_the_keys() {
        let frames = [0, 4, 10, 13];
        let poses = vec![vec![0.0, 1.0], vec![2.0, -1.0], vec![1.0, 3.0], vec![5.0, 0.5]];
        for out in [linear(&frames, &poses), cubic_spline(&frames, &poses)] {
            assert_eq!(out.len(), 14);
            for (f, p) in frames.iter().zip(&poses) {
                for j in 0..2 {
                    assert!((out[*f][j] - p[j]).abs() < 1e-9, "frame {f}: {:?} vs {p:?}", out[*f]);
                }
            }
        }
        assert!((linear(&frames, &poses)[2][0] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn spline_reproduces_a_line_and_is_smooth() {
        let frames = [0, 3, 9, 20];
        let poses: Vec<Vec<f64>> = frames.iter().map(|&f| vec![2.0 * f as f64 - 1.0]).collect();
        let out = cubic_spline(&frames, &poses);
        for (t, p) in out.iter().enumerate() {
            assert!((p[0] - (2.0 * t as f64 - 1.0)).abs() < 1e-9, "frame {t}: {}", p[0]);
        }
        // A curved case: second differences stay bounded across the keys (C2 continuity).
        let poses = vec![vec![0.0], vec![5.0], vec![-2.0], vec![1.0]];
        let out = cubic_spline(&frames, &poses);
        let second: Vec<f64> = out.windows(3).map(|w| w[0][0] - 2.0 * w[1][0] + w[2][0]).collect();
        let jumps = second.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
        assert!(jumps < 0.5, "second difference jumps by {jumps}");
    }

    #[test]
    fn projection_lifts_only_sunken_bases_onto_the_ground() {
        let lamp = LampParams::default();
        let mut poses = vec![
            vec![0.1, 0.01, 0.2, 0.5, -1.1, -1.2],                         // tilted and sunk
            vec![0.2, lamp.base_half_height + 0.05, 0.0, 0.5, -1.1, -1.2], // in the air
            vec![0.3, -0.04, -0.4, 0.4, -1.0, -1.3],                       // deep, tilted the other way
        ];
        let before = poses.clone();
        let depth = -base_clearance(&lamp, &before[2]);
        let lift = project_to_ground(&lamp, &mut poses);
        assert!((lift - depth).abs() < 1e-12, "lift {lift}, deepest {depth}");
        for (p, b) in poses.iter().zip(&before) {
            assert!(base_clearance(&lamp, p) > -1e-12, "{p:?} still below the ground");
            // Only the base height changes.
            assert!(p.iter().zip(b).enumerate().all(|(j, (x, y))| j == 1 || x == y));
        }
        assert_eq!(poses[1], before[1]);
        assert!(base_clearance(&lamp, &poses[0]).abs() < 1e-12);
    }

    #[test]
    fn base_clearance_accounts_for_tilt() {
        let lamp = LampParams::default();
        let flat = base_clearance(&lamp, &[0.0, lamp.base_half_height, 0.0, 0.0, 0.0, 0.0]);
        assert!(flat.abs() < 1e-12);
        let tilted = base_clearance(&lamp, &[0.0, lamp.base_half_height, 0.3, 0.0, 0.0, 0.0]);
        assert!(tilted < -0.02, "{tilted}");
    }
}
