//! Training of the in-betweening network ([`crate::inbetween`]) on humanoid windows: keys drawn
//! afresh for every batch, the loss, [`InbetweenTrainer`] for the shared loop, and the run of
//! `zoo train arnn --design inbetween`.
//!
//! Each batch takes one span `S` (half the time 60 frames, the keys-only benchmark's, otherwise
//! 40 to 65) starting at a random frame of each window; per window a base spacing `K` in
//! `min_gap..=max_gap`, keys at `0, K, 2K, ...` ([`InbetweenConfig::regular_fraction`] of the
//! windows) or at gaps drawn in `[0.6 K, 1.4 K]`, the last key at `S` (a last gap under `K / 2`
//! merged into the one before); [`InbetweenConfig::partial_fraction`] of the windows get the
//! benchmark's partial keys between the first and the last.
//!
//! Loss: `L = |x - y|_1 + lambda_fk |FK(x) - FK(y)|_1 / fk_unit + lambda_vel w |dFK(x) -
//! dFK(y)|_1 / vel_unit`, means over frames and values: the pose values in network units; every
//! joint's global position by forward kinematics of the (normalised) quaternions from the root
//! position (as RMR's `L_fk`, `offline/models/rmr/src/loss.rs`, over the whole body); and every joint's
//! frame-to-frame displacement `dFK`, the feet weighted `w = foot_weight` (a foot moving where
//! the truth's is planted is the foot skate). The ground truth's quaternions take the sign
//! nearest the Bezier pose's.

use crate::inbetween::{Inbetween, InbetweenConfig, ShotBatch, ShotInputs, shot_inputs};
use crate::train::Normalization;
use crate::{ArnnError, ArnnResult};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Optimizer, VarMap};
use std::path::Path;
use zoo_data::benchmark::N_PAST;
use zoo_data::dataset::Windows;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{Adam, ParamsAdam, StatefulOptimizer};
use zoo_nn::rng::SplitMix64;
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{DataParallel, RowRngs, SeededVarMap, TrainError};

/// At most this many validation windows (evenly spaced) are scored each epoch.
pub const VALID_MAX: usize = 600;

/// The groups a partial key fixes: the root and the limbs' end joints (joints without children
/// and joints named `foot`), as the keys-only benchmark's partial layout.
pub fn partial_groups(config: &InbetweenConfig) -> Vec<bool> {
    let s = &config.skeleton;
    let mut g = vec![false; config.groups()];
    g[0] = true;
    g[1] = true;
    for j in 0..s.names.len() {
        let leaf = !s.parents.contains(&(j as i32));
        if leaf || s.names[j].to_ascii_lowercase().contains("foot") {
            g[1 + j] = true;
        }
    }
    g
}

/// Transition lengths (frames between the context and the target) drawn for the transition
/// layout ([`InbetweenConfig::transition_fraction`]): the in-betweening benchmark's 5 to 45.
pub const TRANSITION_GAPS: (usize, usize) = (5, 45);

/// The key frames of a transition of `n` frames: the context `0..N_PAST`, the target at
/// `N_PAST + n`.
pub fn transition_keys(n: usize) -> Vec<usize> {
    (0..N_PAST).chain(std::iter::once(N_PAST + n)).collect()
}

/// Key frames `0..=span` with base spacing `k`: regular, or each gap drawn in `[0.6 k, 1.4 k]`;
/// the last key at `span` (a last gap under `k / 2` merged into the one before).
pub fn draw_keys(span: usize, k: usize, regular: bool, rng: &mut SplitMix64) -> Vec<usize> {
    let mut frames = vec![0];
    let (lo, hi) = (((0.6 * k as f64).round() as usize).max(2), ((1.4 * k as f64).round() as usize).max(2));
    loop {
        let gap = if regular { k } else { lo + rng.below((hi - lo + 1) as u64) as usize };
        let next = frames.last().copied().unwrap_or(0) + gap;
        if next >= span {
            break;
        }
        frames.push(next);
    }
    let last = frames.last().copied().unwrap_or(0);
    if frames.len() > 1 && 2 * (span - last) < k {
        frames.pop();
    }
    frames.push(span);
    frames
}

/// The global positions `(b, T, 3 J)` of poses in network units `(b, T, d)` by forward
/// kinematics (quaternions normalised; parents before children).
fn global_positions(config: &InbetweenConfig, norm: &(Tensor, Tensor), x: &Tensor) -> candle_core::Result<Tensor> {
    let raw = x.broadcast_mul(&norm.1)?.broadcast_add(&norm.0)?;
    let c = |i: usize| raw.narrow(2, i, 1);
    let j = config.joints();
    let mut rots: Vec<[Tensor; 4]> = Vec::with_capacity(j);
    let mut pos: Vec<[Tensor; 3]> = Vec::with_capacity(j);
    for jj in 0..j {
        let o = 3 + 4 * jj;
        let q = [c(o)?, c(o + 1)?, c(o + 2)?, c(o + 3)?];
        let len = ((((q[0].sqr()? + q[1].sqr()?)? + q[2].sqr()?)? + q[3].sqr()?)? + 1e-12)?.sqrt()?;
        let q = [q[0].div(&len)?, q[1].div(&len)?, q[2].div(&len)?, q[3].div(&len)?];
        match config.skeleton.parents[jj] {
            p if p < 0 => {
                rots.push(q);
                pos.push([c(0)?, c(1)?, c(2)?]);
            }
            p => {
                let p = p as usize;
                let off = rotate(&rots[p], config.skeleton.offsets[jj])?;
                let at = [(&pos[p][0] + &off[0])?, (&pos[p][1] + &off[1])?, (&pos[p][2] + &off[2])?];
                rots.push(quat_mul(&rots[p], &q)?);
                pos.push(at);
            }
        }
    }
    Tensor::cat(&pos.iter().flat_map(|p| p.iter()).collect::<Vec<_>>(), 2)
}

/// Hamilton product of quaternions given as `w, x, y, z` component tensors.
fn quat_mul(a: &[Tensor; 4], b: &[Tensor; 4]) -> candle_core::Result<[Tensor; 4]> {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    Ok([
        (((aw * bw)? - (ax * bx)?)? - ((ay * by)? + (az * bz)?)?)?,
        (((aw * bx)? + (ax * bw)?)? + ((ay * bz)? - (az * by)?)?)?,
        (((aw * by)? - (ax * bz)?)? + ((ay * bw)? + (az * bx)?)?)?,
        (((aw * bz)? + (ax * by)?)? + ((az * bw)? - (ay * bx)?)?)?,
    ])
}

/// A constant vector `v` rotated by the unit quaternion `q` (`w, x, y, z` components):
/// `v + w t + u x t`, `t = 2 u x v`.
fn rotate(q: &[Tensor; 4], v: [f64; 3]) -> candle_core::Result<[Tensor; 3]> {
    let [w, x, y, z] = q;
    // t = 2 u x v with v constant.
    let t = [
        ((y * (2.0 * v[2]))? - (z * (2.0 * v[1]))?)?,
        ((z * (2.0 * v[0]))? - (x * (2.0 * v[2]))?)?,
        ((x * (2.0 * v[1]))? - (y * (2.0 * v[0]))?)?,
    ];
    let cross = [((y * &t[2])? - (z * &t[1])?)?, ((z * &t[0])? - (x * &t[2])?)?, ((x * &t[1])? - (y * &t[0])?)?];
    Ok([
        (((w * &t[0])? + &cross[0])? + v[0])?,
        (((w * &t[1])? + &cross[1])? + v[1])?,
        (((w * &t[2])? + &cross[2])? + v[2])?,
    ])
}

/// A shot to train on: key frames, the true pose of every frame, fixed groups (empty: whole).
type TruthShot<'a> = (&'a [usize], &'a [Vec<f64>], Vec<Vec<bool>>);

/// [`TruthShot`] owning its values.
type OwnedShot = (Vec<usize>, Vec<Vec<f64>>, Vec<Vec<bool>>);

/// A batch ready for the loss: the shot tensors and the ground truth in network units.
struct Prepared {
    batch: ShotBatch,
    target: Tensor,
}

/// Trains the in-betweening network with Adam on windows of humanoid clips; implements
/// [`Trainable`].
pub struct InbetweenTrainer {
    config: InbetweenConfig,
    norm: Normalization,
    norm_t: (Tensor, Tensor),
    /// `(1, 1, 3 J)`: each joint's weight in the velocity loss.
    joint_weights: Tensor,
    varmap: VarMap,
    model: Inbetween,
    opt: Adam,
    /// Key draws and the dropout seed, in that order per step.
    rng: SplitMix64,
    step: u64,
    train: Windows,
    valid: Vec<Prepared>,
    device: Device,
    vars: Vec<candle_core::Var>,
    parallel: DataParallel,
}

/// One window's poses of frames `start..=start + span`, the humanoid pose layout.
fn window_poses(w: &Windows, i: usize, start: usize, span: usize) -> Vec<Vec<f64>> {
    let j = w.joints();
    let (rot, pos) = (w.rot(i), w.pos(i));
    let root: Vec<glam::DVec3> = (start..=start + span).map(|f| pos[f * j]).collect();
    crate::humanoid::poses(&root, &rot[start * j..(start + span + 1) * j], j)
}

/// Quantile of the validation intervals' correction sizes that the fallback's `start` is set
/// to (per range of gaps): shots like the training data's trigger it about 5 % of the time.
pub const FALLBACK_QUANTILE: f64 = 0.95;
/// The fallback's `full` is this multiple of its `start`.
pub const FALLBACK_FACTOR: f32 = 2.0;

/// The least share of the curves' error that the network must take off on the validation shots
/// with keys as far apart, in pose values and in their frame-to-frame changes, for a range of
/// gaps to use it: where it gains less, the curves are nearly as good on motion like the training
/// data's and can be much better on motion it never saw (keys 5 frames apart on held-out running,
/// docs/ood.md), so such a range is the curves.
pub const FALLBACK_MIN_GAIN: f64 = 0.1;

/// What [`calibrate_fallback`] found: the thresholds (`None` without enough intervals), every
/// interval's size, and per calibrated range of gaps the network's error over the curves' (pose
/// values, frame-to-frame changes, normalised L1) and whether the range is the curves.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The thresholds, per range of gaps.
    pub fallback: Option<zoo_protocol::inbetween::Fallback>,
    /// Every validation interval's correction size.
    pub sizes: Vec<zoo_protocol::inbetween::IntervalSize>,
    /// The network's gain over the curves per calibrated range (as `fallback.gaps`).
    pub ranges: Vec<RangeGain>,
}

/// The network's error over the curves' on one range of gaps of the validation shots.
#[derive(Clone, Copy, Debug)]
pub struct RangeGain {
    /// The range's longest gap.
    pub up_to: usize,
    /// Network over curves, pose values (normalised L1 between the keys).
    pub pose: f64,
    /// Network over curves, frame-to-frame changes of the pose values.
    pub change: f64,
    /// Whether the range is the curves ([`FALLBACK_MIN_GAIN`]).
    pub curves: bool,
}

/// The fallback towards the curves ([`zoo_protocol::inbetween::Fallback`]) calibrated on
/// in-distribution windows `valid` (at most [`VALID_MAX`], evenly spaced): each window keyed
/// every 5, 10, 15, 20 and 30 frames over frames `0..=60`, and in the transition layout with the
/// target 5, 15, 30 and 45 frames after the context, whole keys, as both benchmarks lay them
/// out. Thresholds per range of gaps from the intervals' correction sizes; a range where the
/// network takes off less than [`FALLBACK_MIN_GAIN`] of the curves' error is the curves.
pub fn calibrate_fallback(model: &Inbetween, norm: &Normalization, valid: &Windows) -> ArnnResult<Calibration> {
    use zoo_protocol::inbetween::{FALLBACK_GAP_RANGES, Fallback, GapFallback};
    let features = crate::inbetween::features(model.config(), norm)?;
    let d = features.dofs();
    let stride = valid.count.div_ceil(VALID_MAX).max(1);
    // Per shot its key frames, key poses and every frame's pose (the truth).
    let mut shots: Vec<(Vec<usize>, Vec<Vec<f64>>, Vec<Vec<f64>>)> = Vec::new();
    let keyed = |frames: Vec<usize>, poses: Vec<Vec<f64>>| {
        let keys = frames.iter().map(|&f| poses[f].clone()).collect();
        (frames, keys, poses)
    };
    for i in (0..valid.count).step_by(stride) {
        for k in [5, 10, 15, 20, 30] {
            shots.push(keyed((0..=60).step_by(k).collect(), window_poses(valid, i, 0, 60)));
        }
        for n in [5, 15, 30, 45] {
            if N_PAST + n < valid.window {
                shots.push(keyed(transition_keys(n), window_poses(valid, i, 0, N_PAST + n)));
            }
        }
    }
    let mut sizes = Vec::new();
    // Per range: network and curves errors of the pose values and of their changes.
    let mut errors = vec![[0.0f64; 4]; FALLBACK_GAP_RANGES.len()];
    for chunk in shots.chunks(256) {
        let refs: Vec<crate::inbetween::ShotKeyRefs<'_>> =
            chunk.iter().map(|(f, p, _)| (f.as_slice(), p.as_slice(), &[][..])).collect();
        for ((shot, correction), (_, _, truth)) in
            crate::inbetween::shot_corrections(model, norm, &refs)?.iter().zip(chunk)
        {
            let net = features.complete(shot, correction, None).poses;
            let bez = &shot.bezier;
            // The truth's quaternions with the curves' signs, normalised like the outputs.
            let mut y = vec![0.0f64; shot.frames * d];
            for (t, pose) in truth.iter().enumerate().take(shot.frames) {
                let b = &bez[t * d..(t + 1) * d];
                y[t * d..(t + 1) * d].copy_from_slice(pose);
                for q in (3..d).step_by(4) {
                    if (q..q + 4).map(|k| pose[k] * b[k]).sum::<f64>() < 0.0 {
                        y[t * d + q..t * d + q + 4].iter_mut().for_each(|v| *v = -*v);
                    }
                }
            }
            let at = |x: &[f64], t: usize, v: usize| x[t * d + v] / norm.std[v];
            for i in features.interval_sizes(shot, correction) {
                let r = FALLBACK_GAP_RANGES.iter().position(|&u| i.gap() <= u).expect("the last range is open");
                let e = &mut errors[r];
                for t in i.from + 1..=i.to {
                    for v in 0..d {
                        let truth_change = at(&y, t, v) - at(&y, t - 1, v);
                        if t < i.to {
                            e[0] += (at(&net, t, v) - at(&y, t, v)).abs();
                            e[1] += (at(bez, t, v) - at(&y, t, v)).abs();
                        }
                        e[2] += (at(&net, t, v) - at(&net, t - 1, v) - truth_change).abs();
                        e[3] += (at(bez, t, v) - at(bez, t - 1, v) - truth_change).abs();
                    }
                }
                sizes.push(i);
            }
        }
    }
    let mut fallback = Fallback::calibrate(&sizes, FALLBACK_QUANTILE, FALLBACK_FACTOR);
    let mut ranges = Vec::new();
    if let Some(f) = &mut fallback {
        for g in &mut f.gaps {
            let r = FALLBACK_GAP_RANGES.iter().position(|&u| g.up_to <= u).expect("the last range is open");
            let e = errors[r];
            let (pose, change) = (e[0] / e[1].max(1e-12), e[2] / e[3].max(1e-12));
            let curves = pose.max(change) > 1.0 - FALLBACK_MIN_GAIN;
            if curves {
                *g = GapFallback::curves(g.up_to);
            }
            ranges.push(RangeGain { up_to: g.up_to, pose, change, curves });
        }
    }
    Ok(Calibration { fallback, sizes, ranges })
}

/// Normalisation statistics of every frame of the windows (standard deviations at least
/// [`crate::humanoid::STD_FLOOR`]).
pub fn window_normalization(w: &Windows) -> Normalization {
    let mut sum: Vec<f64> = Vec::new();
    let mut sq: Vec<f64> = Vec::new();
    let mut n = 0usize;
    for i in 0..w.count {
        for p in window_poses(w, i, 0, w.window - 1) {
            sum.resize(p.len(), 0.0);
            sq.resize(p.len(), 0.0);
            for (k, v) in p.iter().enumerate() {
                sum[k] += v;
                sq[k] += v * v;
            }
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    let mean: Vec<f64> = sum.iter().map(|s| s / n).collect();
    let std =
        sq.iter().zip(&mean).map(|(q, m)| (q / n - m * m).max(0.0).sqrt().max(crate::humanoid::STD_FLOOR)).collect();
    Normalization { mean, std }
}

impl InbetweenTrainer {
    /// A fresh network (weights from `config.seed`) on training windows `train`, scored on
    /// `valid` (at most [`VALID_MAX`] of them, evenly spaced; keys every 5, 10, 15, 20, 30
    /// frames in turn over frames `0..=60`, whole, as the keys-only benchmark's).
    pub fn new(config: &InbetweenConfig, norm: Normalization, train: Windows, valid: &Windows) -> ArnnResult<Self> {
        config.validate()?;
        let device = Device::Cpu;
        let d = config.dofs();
        if norm.mean.len() != d || norm.std.len() != d {
            return Err(ArnnError::Config(format!("normalization of {} values for a model of {d}", norm.mean.len())));
        }
        if train.count == 0 || valid.count == 0 || train.window < 41 || valid.window < 61 {
            return Err(ArnnError::Config(format!(
                "{} training windows of {} frames and {} validation windows of {}: both need windows, training ones \
                 of at least 41 frames, validation ones of at least 61",
                train.count, train.window, valid.count, valid.window
            )));
        }
        if train.joints() != config.joints() || valid.joints() != config.joints() {
            return Err(ArnnError::Config(format!(
                "the windows have {} joints, the model {}: train on one skeleton",
                train.joints(),
                config.joints()
            )));
        }
        let norm_t = (Tensor::new(to_f32(&norm.mean), &device)?, Tensor::new(to_f32(&norm.std), &device)?);
        let weights: Vec<f32> = config
            .skeleton
            .names
            .iter()
            .flat_map(|n| {
                let n = n.to_ascii_lowercase();
                let w = if n.contains("foot") || n.contains("toe") { config.foot_weight as f32 } else { 1.0 };
                [w; 3]
            })
            .collect();
        let joint_weights = Tensor::from_vec(weights, (1, 1, 3 * config.joints()), &device)?;
        let varmap = VarMap::new();
        let model = Inbetween::new(config, SeededVarMap::builder(&varmap, config.seed, DType::F32, &device))?;
        let mut named: Vec<(String, candle_core::Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let vars = named.iter().map(|(_, v)| v.clone()).collect();
        let opt = Adam::new_named(named, ParamsAdam { lr: config.learning_rate, ..ParamsAdam::default() })?;
        let mut t = InbetweenTrainer {
            config: config.clone(),
            norm,
            norm_t,
            joint_weights,
            varmap,
            model,
            opt,
            rng: SplitMix64::new(config.seed ^ 0x1B7),
            step: 0,
            train,
            valid: Vec::new(),
            device,
            vars,
            parallel: DataParallel::new(1).map_err(|e| ArnnError::Config(e.to_string()))?,
        };
        let stride = valid.count.div_ceil(VALID_MAX);
        let picked: Vec<usize> = (0..valid.count).step_by(stride).collect();
        let shots: Vec<(Vec<usize>, Vec<Vec<f64>>)> = picked
            .iter()
            .enumerate()
            .map(|(n, &i)| {
                let k = [5, 10, 15, 20, 30][n % 5];
                ((0..=60).step_by(k).collect(), window_poses(valid, i, 0, 60))
            })
            .collect();
        for chunk in shots.chunks(64) {
            let items: Vec<TruthShot<'_>> = chunk.iter().map(|(k, p)| (k.as_slice(), p.as_slice(), vec![])).collect();
            let prepared = t.prepare(&items)?;
            t.valid.push(prepared);
        }
        if config.transition_fraction > 0.0 {
            // The transition layout too: the benchmark's lengths in turn, one batch per length.
            for (l, n) in [5, 15, 30, 45].into_iter().enumerate() {
                let frames = transition_keys(n);
                let shots: Vec<(Vec<usize>, Vec<Vec<f64>>)> = picked
                    .iter()
                    .skip(l)
                    .step_by(4)
                    .map(|&i| (frames.clone(), window_poses(valid, i, 0, N_PAST + n)))
                    .collect();
                for chunk in shots.chunks(64) {
                    let items: Vec<TruthShot<'_>> =
                        chunk.iter().map(|(k, p)| (k.as_slice(), p.as_slice(), vec![])).collect();
                    let prepared = t.prepare(&items)?;
                    t.valid.push(prepared);
                }
            }
        }
        Ok(t)
    }

    /// The configuration.
    pub fn config(&self) -> &InbetweenConfig {
        &self.config
    }

    /// The network.
    pub fn model(&self) -> &Inbetween {
        &self.model
    }

    /// The normalisation statistics.
    pub fn normalization(&self) -> &Normalization {
        &self.norm
    }

    /// Scalar parameters.
    pub fn parameter_count(&self) -> usize {
        self.varmap.all_vars().iter().map(|v| v.elem_count()).sum()
    }

    /// The learning rate of the next step ([`InbetweenConfig::lr_half_life`]).
    pub fn learning_rate(&self) -> f64 {
        match self.config.lr_half_life {
            0 => self.config.learning_rate,
            h => self.config.learning_rate * 0.5f64.powf(self.step as f64 / h as f64),
        }
    }

    /// Shares each step's batch among `threads` data-parallel workers ([`zoo_nn::parallel`]).
    pub fn set_threads(&mut self, threads: usize) -> ArnnResult<()> {
        self.parallel = DataParallel::new(threads).map_err(|e| ArnnError::Config(e.to_string()))?;
        Ok(())
    }

    /// Shot tensors and targets of shots of one length: per shot its key frames, the poses of
    /// every frame (the truth; keys taken from it) and the fixed groups (empty: whole keys).
    fn prepare(&self, shots: &[TruthShot<'_>]) -> ArnnResult<Prepared> {
        let d = self.config.dofs();
        let mut inputs: Vec<ShotInputs> = Vec::with_capacity(shots.len());
        let mut target: Vec<f32> = Vec::new();
        for (frames, truth, fixed) in shots {
            let keys: Vec<Vec<f64>> = frames.iter().map(|&f| truth[f].clone()).collect();
            let s = shot_inputs(&self.config, &self.norm, frames, &keys, fixed)?;
            for (t, pose) in truth.iter().enumerate().take(s.frames) {
                let bez = &s.bezier[t * d..(t + 1) * d];
                let mut p = pose.clone();
                for q in (3..d).step_by(4) {
                    if (q..q + 4).map(|k| p[k] * bez[k]).sum::<f64>() < 0.0 {
                        p[q..q + 4].iter_mut().for_each(|v| *v = -*v);
                    }
                }
                target.extend(self.norm.apply(&p));
            }
            inputs.push(s);
        }
        let refs: Vec<&ShotInputs> = inputs.iter().collect();
        let batch = ShotBatch::new(&refs, &self.norm, &self.device)?;
        let (b, t) = (inputs.len(), inputs[0].frames);
        Ok(Prepared { batch, target: Tensor::from_vec(target, (b, t, d), &self.device)? })
    }

    /// `(total, pose, fk, velocity)` losses of samples `r` of a prepared batch.
    fn losses(
        &self,
        p: &Prepared,
        r: std::ops::Range<usize>,
        rng: Option<&mut RowRngs>,
    ) -> ArnnResult<(Tensor, Tensor, Tensor, Tensor)> {
        let n = r.len();
        let sub = ShotBatch {
            features: p.batch.features.narrow(0, r.start, n)?,
            bezier: p.batch.bezier.narrow(0, r.start, n)?,
            envelope: p.batch.envelope.narrow(0, r.start, n)?,
            lerp_a: p.batch.lerp_a.narrow(0, r.start, n)?,
            lerp_c: p.batch.lerp_c.narrow(0, r.start, n)?,
            lerp_s: p.batch.lerp_s.narrow(0, r.start, n)?,
        };
        let target = p.target.narrow(0, r.start, n)?;
        let x = self.model.forward(&sub, rng)?;
        let pose = (&x - &target)?.abs()?.mean_all()?;
        let c = &self.config;
        let (mut fk, mut vel) = (pose.zeros_like()?, pose.zeros_like()?);
        if c.lambda_fk > 0.0 || c.lambda_vel > 0.0 {
            let gx = global_positions(c, &self.norm_t, &x)?;
            let gy = global_positions(c, &self.norm_t, &target)?;
            fk = ((&gx - &gy)?.abs()?.mean_all()? / c.fk_unit)?;
            let t = gx.dim(1)?;
            if c.lambda_vel > 0.0 && t > 1 {
                let step =
                    |g: &Tensor| -> candle_core::Result<Tensor> { g.narrow(1, 1, t - 1)? - g.narrow(1, 0, t - 1)? };
                let err = (step(&gx)? - step(&gy)?)?.abs()?.broadcast_mul(&self.joint_weights)?;
                vel = (err.mean_all()? / c.vel_unit)?;
            }
        }
        let total = ((&pose + (&fk * c.lambda_fk)?)? + (&vel * c.lambda_vel)?)?;
        Ok((total, pose, fk, vel))
    }

    /// One Adam step on training windows `samples` with freshly drawn keys; the draws are made
    /// before the batch is shared out, so they do not depend on the thread count.
    pub fn train_on(&mut self, samples: &[usize]) -> ArnnResult<f64> {
        let w = self.train.window - 1;
        // A batch in the transition layout (drawn only when the configuration asks for some, so
        // that runs without them draw the same keys as before).
        let c = &self.config;
        if c.transition_fraction > 0.0 && w >= N_PAST + TRANSITION_GAPS.0 && self.rng.next_f64() < c.transition_fraction
        {
            let longest = TRANSITION_GAPS.1.min(w - N_PAST);
            let n = TRANSITION_GAPS.0 + self.rng.below((longest - TRANSITION_GAPS.0 + 1) as u64) as usize;
            let span = N_PAST + n;
            let frames = transition_keys(n);
            let mut shots: Vec<OwnedShot> = Vec::with_capacity(samples.len());
            for &i in samples {
                let start = self.rng.below((w - span + 1) as u64) as usize;
                shots.push((frames.clone(), window_poses(&self.train, i, start, span), vec![]));
            }
            return self.step_on(shots, samples.len());
        }
        let span = if w >= 60 && self.rng.next_f64() < 0.5 {
            60
        } else {
            40.min(w) + self.rng.below((w - 40.min(w) + 1) as u64) as usize
        };
        let partial = partial_groups(c);
        let mut shots: Vec<OwnedShot> = Vec::with_capacity(samples.len());
        for &i in samples {
            let start = self.rng.below((w - span + 1) as u64) as usize;
            let k = c.min_gap + self.rng.below((c.max_gap - c.min_gap + 1) as u64) as usize;
            let regular = self.rng.next_f64() < c.regular_fraction;
            let frames = draw_keys(span, k, regular, &mut self.rng);
            let fixed = if self.rng.next_f64() < c.partial_fraction {
                let last = frames.len() - 1;
                (0..frames.len())
                    .map(|k| if k == 0 || k == last { vec![true; c.groups()] } else { partial.clone() })
                    .collect()
            } else {
                vec![]
            };
            shots.push((frames, window_poses(&self.train, i, start, span), fixed));
        }
        self.step_on(shots, samples.len())
    }

    /// One Adam step on `shots` (one per sample of the batch).
    fn step_on(&mut self, shots: Vec<OwnedShot>, samples: usize) -> ArnnResult<f64> {
        let seed = self.rng.next_u64();
        let items: Vec<TruthShot<'_>> = shots.iter().map(|(k, p, m)| (k.as_slice(), p.as_slice(), m.clone())).collect();
        let prepared = self.prepare(&items)?;
        let n = samples;
        let this = &*self;
        let shard_loss = |r: std::ops::Range<usize>| -> candle_core::Result<Tensor> {
            let mut rngs = RowRngs::new(seed, r.clone());
            let (total, ..) = this.losses(&prepared, r, Some(&mut rngs)).map_err(candle_core::Error::wrap)?;
            Ok(total)
        };
        let (value, grads) = this.parallel.backward(n, &this.vars, shard_loss)?;
        match grads {
            Some(mut grads) if value.is_finite() => {
                if self.config.max_grad_norm > 0.0 {
                    zoo_nn::optim::clip_grad_norm(&mut grads, &self.vars, self.config.max_grad_norm)?;
                }
                self.opt.set_learning_rate(self.learning_rate());
                self.opt.step(&grads)?
            }
            _ => return Err(ArnnError::NonFiniteLoss { step: self.step, loss: value }),
        }
        self.step += 1;
        Ok(value)
    }

    /// Mean `(total, pose, fk, velocity)` losses on the validation shots.
    pub fn evaluate(&self) -> ArnnResult<(f64, f64, f64, f64)> {
        let (mut sums, mut count) = ([0.0f64; 4], 0usize);
        for p in &self.valid {
            let b = p.target.dim(0)?;
            let (t, q, k, v) = self.losses(p, 0..b, None)?;
            for (s, v) in sums.iter_mut().zip([t, q, k, v]) {
                *s += v.to_scalar::<f32>()? as f64 * b as f64;
            }
            count += b;
        }
        let n = count.max(1) as f64;
        Ok((sums[0] / n, sums[1] / n, sums[2] / n, sums[3] / n))
    }

    /// Writes `config.json`, `model.safetensors` and `normalization.json`.
    pub fn save(&self, dir: &Path) -> ArnnResult<()> {
        let w = ck::stage_varmap(&dir.join(ck::WEIGHTS_FILE), &self.varmap)?;
        let n = ck::stage_json(&dir.join(ck::STATS_FILE), &self.norm)?;
        let c = ck::stage_json(&dir.join(ck::CONFIG_FILE), &self.config)?;
        ck::commit([w, n, c])?;
        Ok(())
    }
}

fn to_f32(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

impl Trainable for InbetweenTrainer {
    fn train_len(&self) -> usize {
        self.train.count
    }

    fn batch_size(&self) -> usize {
        self.config.batch_size
    }

    fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError> {
        Ok(self.train_on(samples)?)
    }

    fn steps(&self) -> u64 {
        self.step
    }

    fn validate(&mut self) -> Result<Validation, TrainError> {
        let (total, pose, fk, vel) = self.evaluate()?;
        Ok(Validation { loss: total, averaged: None, detail: Some(format!("pose {pose:.4} fk {fk:.4} vel {vel:.4}")) })
    }

    fn save_model(&mut self, dir: &Path, _averaged: bool) -> Result<(), TrainError> {
        Ok(self.save(dir)?)
    }

    fn save_training_state(&self, dir: &Path) -> Result<(), TrainError> {
        crate::train::save_optimizer_and_rng(dir, &self.opt, &self.rng)
    }

    fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError> {
        self.rng = crate::train::load_optimizer_and_rng(dir, &self.varmap, &mut self.opt, &self.device)?;
        self.step = self.opt.steps();
        Ok(())
    }

    fn summary(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("model".into(), "arnn".into());
        m.insert("design".into(), crate::inbetween::DESIGN.into());
        m.insert("parameters".into(), self.parameter_count().into());
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DQuat, DVec3};
    use zoo_motion::{JointChannels, Skeleton};

    fn windows(count: usize, frames: usize, phase: f64) -> Windows {
        let skeleton = Skeleton {
            names: vec!["Hips".into(), "Spine".into(), "Hand".into()],
            parents: vec![None, Some(0), Some(1)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, 10.0, 0.0), DVec3::new(0.0, 10.0, 0.0)],
            end_sites: vec![None; 3],
            channels: vec![JointChannels::default(); 3],
        };
        let (mut local_rot, mut local_pos) = (Vec::new(), Vec::new());
        for w in 0..count {
            for f in 0..frames {
                let a = 0.3 * (f as f64 * 0.4 + w as f64 + phase).sin();
                local_rot.extend([
                    DQuat::from_rotation_y(a),
                    DQuat::from_rotation_x(2.0 * a),
                    DQuat::from_rotation_z(a),
                ]);
                local_pos.extend([DVec3::new(f as f64, 90.0 + 5.0 * a, 0.0), skeleton.offsets[1], skeleton.offsets[2]]);
            }
        }
        let source = (0..count).map(|w| (w, 0)).collect();
        Windows { skeleton, window: frames, count, local_rot, local_pos, source }
    }

    fn trainer(seed: u64) -> InbetweenTrainer {
        trainer_with(seed, 0.0)
    }

    fn trainer_with(seed: u64, transition_fraction: f64) -> InbetweenTrainer {
        let train = windows(8, 66, 0.0);
        let valid = windows(4, 66, 0.5);
        let mut config = crate::inbetween::config_for(&train.skeleton, 30.0);
        config =
            InbetweenConfig { seed, transition_fraction, ..InbetweenConfig::tiny(config.skeleton, config.euler_axes) };
        let norm = window_normalization(&train);
        InbetweenTrainer::new(&config, norm, train, &valid).unwrap()
    }

    #[test]
    fn transitions_train_as_keys_of_the_context_and_the_target() {
        assert_eq!(transition_keys(5), vec![0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 15]);
        // Validation: one batch of keys (4 windows), then one per transition length.
        let (keys_only, both) = (trainer_with(5, 0.0), trainer_with(5, 1.0));
        assert_eq!((keys_only.valid.len(), both.valid.len()), (1, 5));
        let mut t = trainer_with(5, 1.0);
        let before = t.evaluate().unwrap().0;
        for _ in 0..30 {
            t.train_on(&[0, 1, 2, 3, 4, 5, 6, 7]).unwrap();
        }
        let after = t.evaluate().unwrap().0;
        assert!(after < 0.8 * before, "validation loss {before} -> {after}");
    }

    #[test]
    fn training_lowers_the_validation_loss_and_is_reproducible() {
        let mut t = trainer(5);
        let before = t.evaluate().unwrap().0;
        let mut losses = Vec::new();
        for _ in 0..30 {
            losses.push(t.train_on(&[0, 1, 2, 3, 4, 5, 6, 7]).unwrap());
        }
        let after = t.evaluate().unwrap().0;
        assert!(after < 0.8 * before, "validation loss {before} -> {after}");
        let mut again = trainer(5);
        let repeat: Vec<f64> = (0..3).map(|_| again.train_on(&[0, 1, 2, 3, 4, 5, 6, 7]).unwrap()).collect();
        assert_eq!(repeat, losses[..3].to_vec());
    }

    #[test]
    fn drawn_keys_start_at_zero_end_at_the_span_and_increase() {
        let mut rng = SplitMix64::new(3);
        for k in 5..=30 {
            for regular in [true, false] {
                let f = draw_keys(60, k, regular, &mut rng);
                assert_eq!((f[0], *f.last().unwrap()), (0, 60));
                assert!(f.windows(2).all(|w| w[0] < w[1] && w[1] - w[0] >= 2), "{k}: {f:?}");
            }
        }
        assert_eq!(draw_keys(60, 15, true, &mut rng), vec![0, 15, 30, 45, 60]);
    }

    #[test]
    fn a_saved_trainer_resumes_to_the_same_weights() {
        let dir = tempfile::tempdir().unwrap();
        let mut a = trainer(9);
        a.train_on(&[0, 1, 2, 3]).unwrap();
        a.save(dir.path()).unwrap();
        a.save_training_state(dir.path()).unwrap();
        let next = a.train_on(&[4, 5, 6, 7]).unwrap();
        let mut b = trainer(9);
        b.load_training_state(dir.path()).unwrap();
        assert_eq!(b.train_on(&[4, 5, 6, 7]).unwrap(), next);
        let (model, norm) = crate::inbetween::load(dir.path(), &Device::Cpu).unwrap();
        assert_eq!(model.config(), a.config());
        // JSON keeps the statistics to within an ulp (serde_json's float parsing).
        let close = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-12 * q.abs().max(1.0));
        assert!(close(&norm.mean, &a.normalization().mean) && close(&norm.std, &a.normalization().std));
    }
}
