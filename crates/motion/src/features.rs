//! Positional motion features of the Recurrent Transition Network (Harvey & Pal 2018, sec. 3.2),
//! on plain `f32` slices so that the training code and the engine-side runtime share them.
//!
//! Layout conventions (all frame-major, Y up, clip units):
//! - global positions: `positions[(f * joints + j) * 3 + axis]`;
//! - a feature frame `x~_t` has `D = 3 * joints` values: the root's global velocity
//!   `r_t - r_(t-1)` (3) followed by the root-relative positions of joints `1..joints` (RTN sec. 3.2);
//! - the target vector has `2 * D` values: the target pose features (its root slot holds the
//!   forward root velocity `r_(T+1) - r_T`, because frame `T - 1` is what is being generated)
//!   followed by the global velocities `y_(T+1) - y_T` of every joint;
//! - the global offset `o_t = y_T - y_t` of every joint (D values).
//!
//! Normalisation (sec. 3.2, "standardization") uses [`FeatureStats`], fitted on training windows.

use crate::blend::target_blend_offset_weight;
use serde::{Deserialize, Serialize};

/// Number of values of one feature frame for `joints` joints.
pub fn feature_dim(joints: usize) -> usize {
    3 * joints
}

/// Root position (joint 0) of one frame of global positions.
#[inline]
pub fn root_of(frame: &[f32]) -> [f32; 3] {
    [frame[0], frame[1], frame[2]]
}

/// Encodes one frame of global positions (`3 * joints`) into features `x~_t` (RTN sec. 3.2)
/// given the previous frame's root position.
pub fn encode_frame(prev_root: [f32; 3], frame: &[f32], out: &mut [f32]) {
    debug_assert_eq!(frame.len(), out.len());
    let r = root_of(frame);
    for a in 0..3 {
        out[a] = r[a] - prev_root[a];
    }
    for (o, p) in out[3..].chunks_exact_mut(3).zip(frame[3..].chunks_exact(3)) {
        for a in 0..3 {
            o[a] = p[a] - r[a];
        }
    }
}

/// Decodes one feature frame back to global positions given the previous frame's root
/// position; returns the new root position (root velocity integration, RTN sec. 4.5).
pub fn decode_frame(prev_root: [f32; 3], features: &[f32], out: &mut [f32]) -> [f32; 3] {
    debug_assert_eq!(features.len(), out.len());
    out.copy_from_slice(features);
    decode_frame_in_place(prev_root, out)
}

/// [`decode_frame`] on a buffer holding the features, replaced by the positions.
pub fn decode_frame_in_place(prev_root: [f32; 3], frame: &mut [f32]) -> [f32; 3] {
    let r = [prev_root[0] + frame[0], prev_root[1] + frame[1], prev_root[2] + frame[2]];
    frame[..3].copy_from_slice(&r);
    for p in frame[3..].chunks_exact_mut(3) {
        for a in 0..3 {
            p[a] += r[a];
        }
    }
    r
}

/// Encodes every frame of a sequence of global positions (`frames * 3 * joints`) into
/// features. Frame 0 has no predecessor: its root velocity is taken equal to frame 1's
/// (zero for a one-frame sequence).
pub fn encode_positions(positions: &[f32], joints: usize, out: &mut [f32]) {
    let d = feature_dim(joints);
    assert_eq!(positions.len(), out.len(), "positions and features must have the same length");
    assert_eq!(positions.len() % d, 0, "positions must hold whole frames of {joints} joints");
    let frames = positions.len() / d;
    for f in 0..frames {
        let frame = &positions[f * d..(f + 1) * d];
        let prev = if f > 0 {
            root_of(&positions[(f - 1) * d..])
        } else if frames > 1 {
            let (r0, r1) = (root_of(frame), root_of(&positions[d..]));
            [2.0 * r0[0] - r1[0], 2.0 * r0[1] - r1[1], 2.0 * r0[2] - r1[2]]
        } else {
            root_of(frame)
        };
        encode_frame(prev, frame, &mut out[f * d..(f + 1) * d]);
    }
}

/// Decodes a sequence of feature frames to global positions, integrating root velocities
/// from `start_root` (the root of the frame before the first one).
pub fn decode_features(start_root: [f32; 3], features: &[f32], joints: usize, out: &mut [f32]) {
    let d = feature_dim(joints);
    assert_eq!(features.len(), out.len(), "features and positions must have the same length");
    let mut root = start_root;
    for (x, y) in features.chunks_exact(d).zip(out.chunks_exact_mut(d)) {
        root = decode_frame(root, x, y);
    }
}

/// Global offset `o_t = y_T - y_t` of every joint from the target frame (RTN sec. 3.2).
pub fn global_offset(frame: &[f32], target: &[f32], out: &mut [f32]) {
    for ((o, y), t) in out.iter_mut().zip(frame).zip(target) {
        *o = t - y;
    }
}

/// Unnormalised target vector `t` (`2 * D` values) from the target frame `y_T` and the one
/// after it `y_(T+1)` (RTN sec. 3.2): the target pose features, whose root slot is the
/// forward root velocity, then the global velocity of every joint.
pub fn target_vector(target: &[f32], next: &[f32], out: &mut [f32]) {
    let d = target.len();
    assert_eq!(next.len(), d, "target and next frames must have the same length");
    assert_eq!(out.len(), 2 * d, "the target vector has twice the frame size");
    let (r, n) = (root_of(target), root_of(next));
    let prev = [2.0 * r[0] - n[0], 2.0 * r[1] - n[1], 2.0 * r[2] - n[2]];
    encode_frame(prev, target, &mut out[..d]);
    for ((o, a), b) in out[d..].iter_mut().zip(target).zip(next) {
        *o = b - a;
    }
}

/// Rotates global positions (`... x 3`) by `angle` radians about the vertical (+Y) axis
/// through `center = (x, z)` (the augmentation of RTN sec. 3.3).
pub fn rotate_about_y(positions: &mut [f32], angle: f32, center: [f32; 2]) {
    let (s, c) = angle.sin_cos();
    for p in positions.chunks_exact_mut(3) {
        let (x, z) = (p[0] - center[0], p[2] - center[1]);
        p[0] = c * x + s * z + center[0];
        p[2] = -s * x + c * z + center[1];
    }
}

/// Target blend (RTN eq. 15-16) of a generated transition in global positions.
///
/// `frames` holds the generated frames (`n * 3 * joints`), the last one being the predicted
/// target; each frame `t` within `blend_len` frames of the target is moved by `w_t * e`,
/// `e = target - predicted target`, `w_t = 1 - (T - t) / blend_len`, so the last frame lands on
/// `target` exactly.
pub fn target_blend(frames: &mut [f32], target: &[f32], blend_len: usize) {
    let d = target.len();
    assert!(
        d > 0 && frames.len().is_multiple_of(d) && !frames.is_empty(),
        "frames must hold whole target-sized frames"
    );
    let n = frames.len() / d;
    let e: Vec<f32> = target.iter().zip(&frames[(n - 1) * d..]).map(|(t, y)| t - y).collect();
    for f in 0..n {
        let w = target_blend_offset_weight(f, n - 1, blend_len) as f32;
        if w > 0.0 {
            for (y, e) in frames[f * d..(f + 1) * d].iter_mut().zip(&e) {
                *y += w * e;
            }
        }
    }
}

/// A terrain heightmap sampled bilinearly: `heights[z * cols + x]` is the height at
/// `(origin[0] + x * cell, origin[1] + z * cell)`; outside the grid the border is repeated.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Heightmap {
    /// Number of samples along X.
    pub cols: usize,
    /// Number of samples along Z.
    pub rows: usize,
    /// Distance between samples (clip units).
    pub cell: f32,
    /// World (x, z) of sample (0, 0).
    pub origin: [f32; 2],
    /// Heights, row-major (`rows * cols`).
    pub heights: Vec<f32>,
}

impl Heightmap {
    /// A flat heightmap at height `h`.
    pub fn flat(h: f32) -> Self {
        Heightmap { cols: 1, rows: 1, cell: 1.0, origin: [0.0, 0.0], heights: vec![h] }
    }

    /// Height at world `(x, z)`, bilinear, clamped at the border.
    pub fn sample(&self, x: f32, z: f32) -> f32 {
        let fx = ((x - self.origin[0]) / self.cell).clamp(0.0, (self.cols - 1) as f32);
        let fz = ((z - self.origin[1]) / self.cell).clamp(0.0, (self.rows - 1) as f32);
        let (x0, z0) = (fx.floor() as usize, fz.floor() as usize);
        let (x1, z1) = ((x0 + 1).min(self.cols - 1), (z0 + 1).min(self.rows - 1));
        let (tx, tz) = (fx - x0 as f32, fz - z0 as f32);
        let h = |x: usize, z: usize| self.heights[z * self.cols + x];
        let a = h(x0, z0) * (1.0 - tx) + h(x1, z0) * tx;
        let b = h(x0, z1) * (1.0 - tx) + h(x1, z1) * tx;
        a * (1.0 - tz) + b * tz
    }
}

/// A rotation of the world about the vertical axis through `center` (x, z), applied to the
/// positions of a training window; terrain is sampled through its inverse (RTN sec. 3.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawAbout {
    /// Angle in radians (as in [`rotate_about_y`]).
    pub angle: f32,
    /// Vertical axis position (x, z).
    pub center: [f32; 2],
}

/// Local terrain patch `p_t` (RTN sec. 3.2): a `side x side` grid spanning `extent` around the
/// root's (x, z), world-axis aligned, holding terrain height minus root height; `rotation`
/// is the augmentation applied to the positions (the terrain is rotated with them).
pub fn terrain_patch(
    map: &Heightmap,
    root: [f32; 3],
    extent: f32,
    side: usize,
    rotation: Option<YawAbout>,
    out: &mut [f32],
) {
    assert_eq!(out.len(), side * side, "a terrain patch has side * side values");
    let step = if side > 1 { extent / (side - 1) as f32 } else { 0.0 };
    let half = extent * 0.5;
    for i in 0..side {
        for j in 0..side {
            let mut p = [root[0] - half + j as f32 * step, 0.0, root[2] - half + i as f32 * step];
            if let Some(r) = rotation {
                rotate_about_y(&mut p, -r.angle, r.center);
            }
            out[i * side + j] = map.sample(p[0], p[2]) - root[1];
        }
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

/// Normalisation statistics of the RTN inputs, fitted on the training set (RTN sec. 3.2).
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
    /// Identity statistics (no normalisation) for `joints` joints.
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

    /// Normalises an unnormalised target vector (`2 * D`) in place.
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
    fn encode_decode_round_trip() {
        let (frames, joints) = (6, 4);
        let p = walk(frames, joints);
        let mut x = vec![0.0; p.len()];
        encode_positions(&p, joints, &mut x);
        // root velocity of frame 3 and root-relative joint 2 of frame 3
        let d = 3 * joints;
        assert!((x[3 * d] - (p[3 * d] - p[2 * d])).abs() < 1e-6);
        assert!((x[3 * d + 7] - (p[3 * d + 7] - p[3 * d + 1])).abs() < 1e-6);
        let start = root_of(&p[..]);
        let mut y = vec![0.0; p.len()];
        decode_features(start, &x[d..], joints, &mut y[d..]);
        for (a, b) in y[d..].iter().zip(&p[d..]) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
    }

    #[test]
    fn target_vector_layout() {
        let joints = 3;
        let p = walk(2, joints);
        let d = 3 * joints;
        let mut t = vec![0.0; 2 * d];
        target_vector(&p[..d], &p[d..], &mut t);
        assert!((t[0] - (p[d] - p[0])).abs() < 1e-6, "root slot is the forward root velocity");
        assert!((t[d + 4] - (p[d + 4] - p[4])).abs() < 1e-6);
        assert!((t[5] - (p[5] - p[2])).abs() < 1e-6);
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
    fn target_blend_lands_on_target() {
        let mut frames = vec![0.0f32; 5 * 3];
        let target = [3.0, 3.0, 3.0];
        target_blend(&mut frames, &target, 2);
        assert_eq!(&frames[12..15], &target);
        assert_eq!(&frames[..9], &[0.0; 9]);
        assert!((frames[9] - 1.5).abs() < 1e-6);
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
