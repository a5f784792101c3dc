//! RTN's own features (Harvey & Pal 2018, sec. 3.2-3.3): the normalization statistics
//! ([`FeatureStats`], fitted on training windows), the global offset `o_t`, the local terrain
//! patch `p_t` and the yaw augmentation. The encoding shared with the engine runtime (feature
//! frames, target vector, target blend) lives in [`zoo_protocol::features`] and is re-exported
//! here, so RTN code reads every feature through this module.
//!
//! Layout conventions are those of [`zoo_protocol::features`]; the global offset
//! `o_t = y_T - y_t` of every joint has `D = 3 * joints` values.

use serde::{Deserialize, Serialize};
pub use zoo_protocol::features::{
    decode_features, decode_frame, decode_frame_in_place, encode_frame, encode_positions, feature_dim, root_of,
    target_blend, target_vector,
};
pub use zoo_protocol::terrain::{Heightmap, YawAbout, rotate_about_y, terrain_patch};

/// Global offset `o_t = y_T - y_t` of every joint from the target frame (RTN sec. 3.2).
pub fn global_offset(frame: &[f32], target: &[f32], out: &mut [f32]) {
    for ((o, y), t) in out.iter_mut().zip(frame).zip(target) {
        *o = t - y;
    }
}

/// Unnormalised features of frame `i` (`0..=n`) of the linear interpolation of global
/// positions between the last context frame `last` and the target `target` over a transition
/// of `n` frames before the target (interpolation weight `(i + 1) / (n + 1)`, so frame `n` is
/// the target's pose): the root velocity `(r_T - r_last) / (n + 1)` and the interpolated
/// root-relative positions. The base of the interpolation-residual RTN
/// ([`crate::Config::interp_residual`]); the runtime computes the same (docs/runtime-protocol.md).
pub fn interpolation_frame(last: &[f32], target: &[f32], i: usize, n: usize, out: &mut [f32]) {
    let d = last.len();
    assert!(target.len() == d && out.len() == d && d >= 3, "frames of the same size");
    let steps = (n + 1) as f32;
    let w = (i + 1) as f32 / steps;
    let (rl, rt) = (root_of(last), root_of(target));
    for a in 0..3 {
        out[a] = (rt[a] - rl[a]) / steps;
    }
    for j in 3..d {
        let a = j % 3;
        out[j] = (1.0 - w) * (last[j] - rl[a]) + w * (target[j] - rt[a]);
    }
}

/// Mean and standard deviation of each value of a feature vector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeanStd {
    /// Means.
    pub mean: Vec<f32>,
    /// Standard deviations (floored at [`MeanStd::MIN_STD`]).
    pub std: Vec<f32>,
}

impl MeanStd {
    /// Smallest standard deviation kept, so constant features do not divide by zero.
    pub const MIN_STD: f32 = 1e-4;

    /// Identity statistics (mean 0, std 1) of `n` values.
    pub fn identity(n: usize) -> Self {
        MeanStd { mean: vec![0.0; n], std: vec![1.0; n] }
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.mean.len()
    }

    /// True for zero values.
    pub fn is_empty(&self) -> bool {
        self.mean.is_empty()
    }

    /// `v = (v - mean) / std`, over consecutive vectors of `len()` values.
    pub fn normalize(&self, v: &mut [f32]) {
        for chunk in v.chunks_exact_mut(self.len()) {
            for ((x, m), s) in chunk.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = (*x - m) / s;
            }
        }
    }

    /// `v = v * std + mean`, over consecutive vectors of `len()` values.
    pub fn denormalize(&self, v: &mut [f32]) {
        for chunk in v.chunks_exact_mut(self.len()) {
            for ((x, m), s) in chunk.iter_mut().zip(&self.mean).zip(&self.std) {
                *x = *x * s + m;
            }
        }
    }
}

/// Running first and second moments of `n` values (f64).
#[derive(Clone, Debug)]
pub struct Moments {
    count: f64,
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
}

impl Moments {
    /// Empty moments of `n` values.
    pub fn new(n: usize) -> Self {
        Moments { count: 0.0, sum: vec![0.0; n], sum_sq: vec![0.0; n] }
    }

    /// Adds consecutive vectors of `n` values.
    pub fn add(&mut self, v: &[f32]) {
        let n = self.sum.len();
        for chunk in v.chunks_exact(n) {
            self.count += 1.0;
            for ((s, q), x) in self.sum.iter_mut().zip(&mut self.sum_sq).zip(chunk) {
                *s += *x as f64;
                *q += (*x as f64) * (*x as f64);
            }
        }
    }

    /// Mean and std. With `yaw_invariant`, values are read as 3-D vectors (Y up) and the
    /// statistics are those of the data under a uniformly random rotation about Y: x and z get
    /// mean 0 and the std `sqrt((E[x^2] + E[z^2]) / 2)` (matches the augmentation of sec. 3.3).
    pub fn finish(&self, yaw_invariant: bool) -> MeanStd {
        let c = self.count.max(1.0);
        let n = self.sum.len();
        let mut mean: Vec<f64> = self.sum.iter().map(|s| s / c).collect();
        let mut var: Vec<f64> = (0..n).map(|i| (self.sum_sq[i] / c - mean[i] * mean[i]).max(0.0)).collect();
        if yaw_invariant {
            assert_eq!(n % 3, 0, "yaw-invariant statistics need 3-D vectors");
            for k in 0..n / 3 {
                let (x, z) = (3 * k, 3 * k + 2);
                let e2 = 0.5 * (self.sum_sq[x] + self.sum_sq[z]) / c;
                mean[x] = 0.0;
                mean[z] = 0.0;
                var[x] = e2;
                var[z] = e2;
            }
        }
        MeanStd {
            mean: mean.iter().map(|&m| m as f32).collect(),
            std: var.iter().map(|&v| (v.sqrt() as f32).max(MeanStd::MIN_STD)).collect(),
        }
    }
}

/// Normalization statistics of the RTN inputs, fitted on the training set (RTN sec. 3.2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureStats {
    /// Number of joints.
    pub joints: usize,
    /// Statistics of the feature frames `x~_t` (D values).
    pub x: MeanStd,
    /// Statistics of the joint velocities of the target vector (D values).
    pub velocity: MeanStd,
    /// Statistics of the global offsets `o_t` (D values).
    pub offset: MeanStd,
    /// Statistics of the terrain patch values (one value per cell), when terrain is used.
    pub terrain: Option<MeanStd>,
}

impl FeatureStats {
    /// Identity statistics (no normalization) for `joints` joints.
    pub fn identity(joints: usize) -> Self {
        let d = feature_dim(joints);
        FeatureStats {
            joints,
            x: MeanStd::identity(d),
            velocity: MeanStd::identity(d),
            offset: MeanStd::identity(d),
            terrain: None,
        }
    }

    /// Fits the statistics on windows of global positions (`frames * 3 * joints` each) whose
    /// target frame is `target_frame` (offsets are taken for frames `0..=target_frame`).
    /// `yaw_invariant`: see [`Moments::finish`].
    pub fn fit<'a>(
        windows: impl IntoIterator<Item = &'a [f32]>,
        joints: usize,
        target_frame: usize,
        yaw_invariant: bool,
    ) -> Self {
        let d = feature_dim(joints);
        let (mut mx, mut mv, mut mo) = (Moments::new(d), Moments::new(d), Moments::new(d));
        let mut buf = Vec::new();
        for w in windows {
            assert!(w.len() >= d * (target_frame + 2), "window shorter than target frame + 2");
            buf.resize(w.len(), 0.0);
            encode_positions(w, joints, &mut buf);
            mx.add(&buf);
            let frames = w.len() / d;
            for f in 0..frames - 1 {
                let vel: Vec<f32> = (0..d).map(|i| w[(f + 1) * d + i] - w[f * d + i]).collect();
                mv.add(&vel);
            }
            let target = &w[target_frame * d..(target_frame + 1) * d];
            let mut o = vec![0.0; d];
            for f in 0..=target_frame {
                global_offset(&w[f * d..(f + 1) * d], target, &mut o);
                mo.add(&o);
            }
        }
        FeatureStats {
            joints,
            x: mx.finish(yaw_invariant),
            velocity: mv.finish(yaw_invariant),
            offset: mo.finish(yaw_invariant),
            terrain: None,
        }
    }

    /// Feature size `D`.
    pub fn dim(&self) -> usize {
        feature_dim(self.joints)
    }

    /// Normalizes an unnormalized target vector (`2 * D`) in place.
    pub fn normalize_target(&self, t: &mut [f32]) {
        let d = self.dim();
        self.x.normalize(&mut t[..d]);
        self.velocity.normalize(&mut t[d..]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk(frames: usize, joints: usize) -> Vec<f32> {
        let mut p = Vec::new();
        for f in 0..frames {
            let t = f as f32 * 0.1;
            for j in 0..joints {
                p.extend_from_slice(&[t * 3.0 + j as f32, 90.0 + (t + j as f32).sin(), t * 2.0 - j as f32 * 0.5]);
            }
        }
        p
    }

    #[test]
    fn rotation_preserves_relative_distances_and_terrain_follows() {
        let mut p = vec![1.0, 0.0, 0.0, 0.0, 5.0, 2.0];
        rotate_about_y(&mut p, std::f32::consts::FRAC_PI_2, [0.0, 0.0]);
        assert!((p[0] - 0.0).abs() < 1e-6 && (p[2] + 1.0).abs() < 1e-6);
        assert!((p[3] - 2.0).abs() < 1e-6 && (p[4] - 5.0).abs() < 1e-6);
        // a ramp rising along +X, rotated by 90 degrees, rises along -Z
        let map = Heightmap {
            cols: 11,
            rows: 11,
            cell: 1.0,
            origin: [-5.0, -5.0],
            heights: (0..121).map(|i| (i % 11) as f32).collect(),
        };
        let rot = YawAbout { angle: std::f32::consts::FRAC_PI_2, center: [0.0, 0.0] };
        let mut patch = vec![0.0; 9];
        terrain_patch(&map, [0.0, 0.0, 0.0], 2.0, 3, Some(rot), &mut patch);
        // rows go along +Z: height decreases with z after the rotation
        assert!(patch[0] > patch[6], "{patch:?}");
        assert!((patch[0] - patch[2]).abs() < 1e-5);
    }

    #[test]
    fn yaw_invariant_stats_are_symmetric() {
        let p = walk(20, 2);
        let s = FeatureStats::fit([p.as_slice()], 2, 10, true);
        assert_eq!(s.x.mean[0], 0.0);
        assert_eq!(s.x.std[0], s.x.std[2]);
        let mut v = p[..6].to_vec();
        s.offset.normalize(&mut v);
        s.offset.denormalize(&mut v);
        assert!(v.iter().zip(&p[..6]).all(|(a, b)| (a - b).abs() < 1e-3));
    }
}
