//! The pose vector of RMR sec. 4 and back, and its normalisation statistics.
//!
//! Frame `t` of a sequence is `x_t = {r_t, p_t, q_t, v_t, c_t}` (`f32`):
//! - `r_t` (3): root displacement `(dx, dtheta, dz)` from the previous frame's ground root, in
//!   that root's frame (clip units, radians);
//! - `p_t` (3 J_lower): lower-body joint positions in the frame's ground root;
//! - `q_t` (4 J): local rotation quaternions `(x, y, z, w)` of every joint, the root joint's
//!   relative to the ground root's heading; each joint's quaternions are made continuous along
//!   time starting from `w >= 0` at frame 0;
//! - `v_t` (3 J_lower): lower-body joint displacements since the previous frame, in the
//!   previous frame's ground root;
//! - `c_t` (4): contacts (0 or 1) of left heel, left toe, right heel, right toe.
//!
//! The first frame has no predecessor: its `r` and `v` repeat frame 1's. The layout is
//! contiguous, so the "pose" part of the loss is the first `dim - 4` values.

use crate::error::{RmrError, RmrResult};
use serde::{Deserialize, Serialize};
use zoo_data::stitch::{GroundRoot, StitchLayout};
use zoo_motion::glam::{DQuat, DVec3};
use zoo_motion::{Clip, Skeleton};

/// Offsets of the parts of the pose vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeatureLayout {
    /// Joints J.
    pub joints: usize,
    /// Lower-body joints J_lower.
    pub lower: usize,
}

impl FeatureLayout {
    /// The layout for `joints` joints of which `lower` are lower body.
    pub fn new(joints: usize, lower: usize) -> Self {
        FeatureLayout { joints, lower }
    }

    /// Values per frame: `3 + 3 J_lower + 4 J + 3 J_lower + 4`.
    pub fn dim(&self) -> usize {
        7 + 6 * self.lower + 4 * self.joints
    }

    /// Start of `p_t`.
    pub fn positions(&self) -> usize {
        3
    }

    /// Start of `q_t`.
    pub fn rotations(&self) -> usize {
        3 + 3 * self.lower
    }

    /// Start of `v_t`.
    pub fn velocities(&self) -> usize {
        self.rotations() + 4 * self.joints
    }

    /// Start of `c_t` (= number of pose values `r, p, q, v`).
    pub fn contacts(&self) -> usize {
        self.velocities() + 3 * self.lower
    }
}

fn wrap(a: f64) -> f64 {
    let a = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if a == -std::f64::consts::PI { std::f64::consts::PI } else { a }
}

/// Encodes every frame of `clip` (at least 2 frames) into pose vectors (`frames * dim`).
pub fn encode_clip(clip: &Clip, layout: &StitchLayout) -> RmrResult<Vec<f32>> {
    let (frames, j) = (clip.frames(), clip.joints());
    if frames < 2 {
        return Err(RmrError::Config(format!("a sequence needs at least 2 frames to encode, found {frames}")));
    }
    layout.validate(&clip.skeleton)?;
    let fl = FeatureLayout::new(j, layout.lower_body.len());
    let d = fl.dim();
    let (_, gp) = clip.global();
    let roots = zoo_data::stitch::ground_roots(clip, layout);
    let mut out = vec![0.0f32; frames * d];
    let mut prev_q: Vec<DQuat> = Vec::new();
    for f in 0..frames {
        let x = &mut out[f * d..(f + 1) * d];
        let root = roots[f];
        // r_t and v_t: frame 0 repeats frame 1's.
        let (a, b) = if f == 0 { (0, 1) } else { (f - 1, f) };
        let disp = roots[a].inverse().compose(&roots[b]);
        x[..3].copy_from_slice(&[disp.pos.x as f32, wrap(disp.yaw) as f32, disp.pos.z as f32]);
        for (k, &jl) in layout.lower_body.iter().enumerate() {
            let p = root.to_local(gp[f * j + jl]);
            x[fl.positions() + 3 * k..][..3].copy_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
            let v = roots[a].rotation().inverse() * (gp[b * j + jl] - gp[a * j + jl]);
            x[fl.velocities() + 3 * k..][..3].copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
        }
        let mut qs: Vec<DQuat> = (0..j).map(|k| clip.local_rotations[f * j + k]).collect();
        qs[0] = root.rotation().inverse() * qs[0];
        for (k, q) in qs.iter_mut().enumerate() {
            let reference = if f == 0 { DQuat::IDENTITY } else { prev_q[k] };
            if q.dot(reference) < 0.0 {
                *q = -*q;
            }
            x[fl.rotations() + 4 * k..][..4].copy_from_slice(&[q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
        }
        prev_q = qs;
        let c = layout.contacts_of(&gp[f * j..(f + 1) * j]);
        for k in 0..4 {
            x[fl.contacts() + k] = if c[k] { 1.0 } else { 0.0 };
        }
    }
    Ok(out)
}

/// Ground roots of a sequence of pose vectors: frame 0 is `start`, frame `t` is frame `t - 1`'s
/// root moved by `r_t` (RMR sec. 5.1: "accumulating the predicted root displacement").
pub fn accumulate_roots(features: &[f32], dim: usize, start: GroundRoot) -> Vec<GroundRoot> {
    let mut roots = Vec::with_capacity(features.len() / dim);
    let mut root = start;
    for (f, x) in features.chunks_exact(dim).enumerate() {
        if f > 0 {
            let d = GroundRoot { pos: DVec3::new(x[0] as f64, 0.0, x[2] as f64), yaw: x[1] as f64 };
            root = root.compose(&d);
        }
        roots.push(root);
    }
    roots
}

/// Decodes pose vectors into a clip on `skeleton` (frame 0's ground root is `start`; non-root
/// joints take the skeleton's offsets; quaternions are normalised) and the contacts
/// (`c > 0.5`; pass probabilities, e.g. the sigmoid of the model's contact outputs).
pub fn decode(
    features: &[f32],
    skeleton: &Skeleton,
    layout: &StitchLayout,
    frame_time: f64,
    start: GroundRoot,
) -> RmrResult<(Clip, Vec<[bool; 4]>)> {
    let j = skeleton.len();
    let fl = FeatureLayout::new(j, layout.lower_body.len());
    let d = fl.dim();
    if features.is_empty() || !features.len().is_multiple_of(d) {
        return Err(RmrError::Size {
            what: "pose vectors".into(),
            expected: d,
            detail: format!("a multiple of {d} = 7 + 6 x {} lower-body joints + 4 x {j} joints", fl.lower),
            found: features.len(),
        });
    }
    let hips_slot = layout.lower_body.iter().position(|&k| k == 0).expect("validated: the root joint is lower body");
    let roots = accumulate_roots(features, d, start);
    let frames = features.len() / d;
    let mut clip = Clip {
        skeleton: skeleton.clone(),
        frame_time,
        local_rotations: Vec::with_capacity(frames * j),
        local_positions: Vec::with_capacity(frames * j),
    };
    let mut contacts = Vec::with_capacity(frames);
    for (x, root) in features.chunks_exact(d).zip(&roots) {
        for k in 0..j {
            let q = &x[fl.rotations() + 4 * k..][..4];
            let q = DQuat::from_xyzw(q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
            let q = if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY };
            if k == 0 {
                let p = &x[fl.positions() + 3 * hips_slot..][..3];
                let (r, p) = root.apply(q, DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
                clip.local_rotations.push(r);
                clip.local_positions.push(p);
            } else {
                clip.local_rotations.push(q);
                clip.local_positions.push(skeleton.offsets[k]);
            }
        }
        contacts.push(std::array::from_fn(|k| x[fl.contacts() + k] > 0.5));
    }
    Ok((clip, contacts))
}

/// Per-value mean and standard deviation of the pose vector over the generated training data
/// (RMR sec. 5). Contacts are left as they are (mean 0, std 1) so that the sigmoid of the
/// contact outputs compares with 0/1 labels; values that never vary get std 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureStats {
    /// Mean per value.
    pub mean: Vec<f32>,
    /// Standard deviation per value.
    pub std: Vec<f32>,
}

impl FeatureStats {
    /// Fits the statistics over every frame of `sequences` (each `frames * dim`).
    pub fn fit<'a>(sequences: impl IntoIterator<Item = &'a [f32]>, fl: FeatureLayout) -> FeatureStats {
        let d = fl.dim();
        let (mut n, mut sum, mut sq) = (0usize, vec![0.0f64; d], vec![0.0f64; d]);
        for s in sequences {
            for x in s.chunks_exact(d) {
                n += 1;
                for (i, &v) in x.iter().enumerate() {
                    sum[i] += v as f64;
                    sq[i] += (v as f64) * (v as f64);
                }
            }
        }
        let n = n.max(1) as f64;
        let mut mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        let mut std: Vec<f32> = sum
            .iter()
            .zip(&sq)
            .map(|(s, q)| {
                let m = s / n;
                let sd = (q / n - m * m).max(0.0).sqrt();
                if sd < 1e-6 { 1.0 } else { sd as f32 }
            })
            .collect();
        for i in fl.contacts()..d {
            mean[i] = 0.0;
            std[i] = 1.0;
        }
        FeatureStats { mean, std }
    }

    /// Values per frame.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Normalises whole frames in place.
    pub fn normalize(&self, x: &mut [f32]) {
        let d = self.dim();
        for f in x.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / s;
            }
        }
    }

    /// Undoes [`FeatureStats::normalize`] in place.
    pub fn denormalize(&self, x: &mut [f32]) {
        let d = self.dim();
        for f in x.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = *v * s + m;
            }
        }
    }
}

/// Encoded pairs: `count` input and target sequences of `frames` frames of `dim` values,
/// `[pair][frame][value]`.
#[derive(Clone, Debug, PartialEq)]
pub struct PairFeatures {
    /// Number of pairs.
    pub count: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// Values per frame.
    pub dim: usize,
    /// Inputs `X`.
    pub inputs: Vec<f32>,
    /// Ground truths `Y`.
    pub targets: Vec<f32>,
    /// First frame of each retrieved segment of each pair (the seams; empty when unknown).
    pub seams: Vec<Vec<usize>>,
}

impl PairFeatures {
    /// Encodes stitching pairs (all the same length).
    pub fn encode(pairs: &[zoo_data::stitch::StitchPair], layout: &StitchLayout) -> RmrResult<PairFeatures> {
        let first = pairs.first().ok_or_else(|| RmrError::Config("no stitching pairs to encode".into()))?;
        let frames = first.target.frames();
        let dim = FeatureLayout::new(first.target.joints(), layout.lower_body.len()).dim();
        let mut inputs = Vec::with_capacity(pairs.len() * frames * dim);
        let mut targets = Vec::with_capacity(pairs.len() * frames * dim);
        let mut seams = Vec::with_capacity(pairs.len());
        for (i, p) in pairs.iter().enumerate() {
            if p.input.frames() != frames || p.target.frames() != frames {
                return Err(RmrError::Config(format!("pair {i} has {} frames, pair 0 {frames}", p.input.frames())));
            }
            inputs.extend(encode_clip(&p.input, layout)?);
            targets.extend(encode_clip(&p.target, layout)?);
            seams.push(p.seams.clone());
        }
        Ok(PairFeatures { count: pairs.len(), frames, dim, inputs, targets, seams })
    }

    /// Sequence `i` of the inputs.
    pub fn input(&self, i: usize) -> &[f32] {
        &self.inputs[i * self.frames * self.dim..(i + 1) * self.frames * self.dim]
    }

    /// Sequence `i` of the targets.
    pub fn target(&self, i: usize) -> &[f32] {
        &self.targets[i * self.frames * self.dim..(i + 1) * self.frames * self.dim]
    }

    /// A normalised copy.
    pub fn normalized(&self, stats: &FeatureStats) -> RmrResult<PairFeatures> {
        if stats.dim() != self.dim {
            return Err(RmrError::Config(format!(
                "statistics have {} values per frame, the pairs {}",
                stats.dim(),
                self.dim
            )));
        }
        let mut out = self.clone();
        stats.normalize(&mut out.inputs);
        stats.normalize(&mut out.targets);
        Ok(out)
    }
}
