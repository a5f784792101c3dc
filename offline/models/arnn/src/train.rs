//! Training (section 7): the loss `MSE(Y, Y') + 100 omega key loss` (eq. 4), the curriculum
//! (omega annealing and scheduled sampling), key dropping, Adam; [`ArnnTrainer`] implements
//! [`Trainable`] for the shared loop.
//!
//! The key loss is the mean squared error over the key frames after the first (the first key
//! is the given start pose), so that it and the frame loss are on one scale, as in Tables 1-2.
//! Beyond the paper, a ground penalty (`ArnnConfig::ground_weight`) on the depth of the base
//! plate's lowest point below the ground ([`crate::eval::base_clearance`] in candle ops).

use crate::config::ArnnConfig;
use crate::keys::{choose_keys, choose_masks};
use crate::luxo::preprocess::KeyedSequence;
use crate::model::Arnn;
use crate::{ArnnError, ArnnResult};
use candle_core::{D, DType, Device, Tensor};
use candle_nn::{Optimizer, VarMap};
use serde::{Deserialize, Serialize};
use std::path::Path;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{Adam, ParamsAdam, StatefulOptimizer};
use zoo_nn::rng::SplitMix64;
use zoo_nn::tape::frame_leaves;
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{DataParallel, RowRngs, SeededVarMap, TrainError};

/// Mean and standard deviation of each degree of freedom; the network sees `(x - mean) / std`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Mean per degree of freedom.
    pub mean: Vec<f64>,
    /// Standard deviation per degree of freedom (never below 1e-6).
    pub std: Vec<f64>,
}

impl Normalization {
    /// Fits the statistics of a training set.
    pub fn fit(seqs: &[KeyedSequence]) -> Self {
        let (mean, std) = crate::luxo::preprocess::dof_statistics(seqs);
        Normalization { mean, std }
    }

    /// A pose in network units, `(x - mean) / std`.
    pub(crate) fn apply<'a>(&'a self, pose: &'a [f64]) -> impl Iterator<Item = f32> + 'a {
        pose.iter().zip(&self.mean).zip(&self.std).map(|((v, m), s)| ((v - m) / s) as f32)
    }

    /// A network output back in physical units, `y * std + mean`.
    pub(crate) fn restore(&self, y: &[f32]) -> Vec<f64> {
        y.iter().zip(&self.mean).zip(&self.std).map(|((x, m), s)| *x as f64 * s + m).collect()
    }

    /// A key's input to its feature net ([`ArnnConfig::key_width`] values): the normalised
    /// pose; with key groups (`groups[d]` per degree of freedom), the values of the groups the
    /// key does not fix (`fixed[g]` false) set to 0, then one 0/1 flag per group. `fixed` empty
    /// or `None`: every group fixed.
    pub fn key_input(&self, pose: &[f64], groups: &[usize], fixed: Option<&[bool]>) -> Vec<f32> {
        let mut out = Vec::with_capacity(pose.len() + groups.len());
        self.extend_key_input(&mut out, pose, groups, fixed);
        out
    }

    /// [`Normalization::key_input`] appended to `out`.
    pub fn extend_key_input(&self, out: &mut Vec<f32>, pose: &[f64], groups: &[usize], fixed: Option<&[bool]>) {
        let n_groups = groups.iter().max().map_or(0, |g| g + 1);
        let keep = |g: usize| fixed.is_none_or(|f| f.is_empty() || f[g]);
        let start = out.len();
        out.extend(self.apply(pose));
        if n_groups > 0 {
            for (v, &g) in out[start..].iter_mut().zip(groups) {
                if !keep(g) {
                    *v = 0.0;
                }
            }
            out.extend((0..n_groups).map(|g| if keep(g) { 1.0 } else { 0.0 }));
        }
    }
}

/// Losses of one batch (normalised units).
#[derive(Clone, Debug)]
pub struct Losses {
    /// `frame + key_weight * omega * key`, the optimised loss.
    pub total: Tensor,
    /// Frame loss: MSE over every predicted frame.
    pub frame: Tensor,
    /// Key loss: MSE over the key frames after the first.
    pub key: Tensor,
    /// Ground penalty: mean over predicted frames of `(max(0, -clearance) / std(base y))^2`,
    /// with `clearance` the height of the base plate's lowest point (0 without a lamp).
    pub ground: Tensor,
}

/// Trains an ARNN on preprocessed lamp sequences.
pub struct ArnnTrainer {
    config: ArnnConfig,
    norm: Normalization,
    varmap: VarMap,
    model: Arnn,
    opt: Adam,
    /// Key drops, teacher-forcing draws and the dropout seed, in that order per step.
    rng: SplitMix64,
    step: u64,
    train: Vec<KeyedSequence>,
    valid: Vec<KeyedSequence>,
    device: Device,
    /// The variables sorted by name (the gradients of data-parallel steps are summed over them).
    vars: Vec<candle_core::Var>,
    /// Workers of the data-parallel training step ([`ArnnTrainer::set_threads`]; one by default).
    parallel: DataParallel,
}

const RNG_KEY: &str = "trainer";

impl ArnnTrainer {
    /// A fresh model (weights from `config.seed`) and the statistics of `train`.
    pub fn new(
        config: &ArnnConfig,
        train: Vec<KeyedSequence>,
        valid: Vec<KeyedSequence>,
        device: &Device,
    ) -> ArnnResult<Self> {
        let norm = Normalization::fit(&train);
        Self::with_normalization(config, norm, train, valid, device)
    }

    /// A fresh model (weights from `config.seed`) with given statistics (a resumed run keeps
    /// the ones it started with).
    pub fn with_normalization(
        config: &ArnnConfig,
        norm: Normalization,
        train: Vec<KeyedSequence>,
        valid: Vec<KeyedSequence>,
        device: &Device,
    ) -> ArnnResult<Self> {
        config.validate().map_err(ArnnError::Config)?;
        for s in train.iter().chain(&valid) {
            check_sequence(config, s)?;
        }
        if train.is_empty() {
            return Err(ArnnError::Config("no training sequence".into()));
        }
        if norm.mean.len() != config.dofs || norm.std.len() != config.dofs {
            return Err(ArnnError::Config(format!(
                "normalization is for {} values, the model for {}",
                norm.mean.len(),
                config.dofs
            )));
        }
        let varmap = VarMap::new();
        let model = Arnn::new(config, SeededVarMap::builder(&varmap, config.seed, DType::F32, device))?;
        let mut named: Vec<(String, candle_core::Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let vars = named.iter().map(|(_, v)| v.clone()).collect();
        let opt = Adam::new_named(named, ParamsAdam { lr: config.learning_rate, ..ParamsAdam::default() })?;
        Ok(ArnnTrainer {
            config: config.clone(),
            norm,
            varmap,
            model,
            opt,
            rng: SplitMix64::new(config.seed ^ 0xA77),
            step: 0,
            train,
            valid,
            device: device.clone(),
            vars,
            parallel: DataParallel::new(1).map_err(|e| ArnnError::Config(e.to_string()))?,
        })
    }

    /// The model.
    pub fn model(&self) -> &Arnn {
        &self.model
    }

    /// The normalisation statistics of the training set.
    pub fn normalization(&self) -> &Normalization {
        &self.norm
    }

    /// The configuration.
    pub fn config(&self) -> &ArnnConfig {
        &self.config
    }

    /// Optimiser steps taken.
    pub fn step(&self) -> u64 {
        self.step
    }

    /// Number of trainable values.
    pub fn parameter_count(&self) -> usize {
        self.varmap.all_vars().iter().map(|v| v.elem_count()).sum()
    }

    /// The lamp's base half height and half width when the ground penalty applies: a lamp in
    /// the configuration, the lamp's degrees of freedom and a positive weight.
    fn ground_geometry(&self) -> Option<(f64, f64)> {
        let lamp = self.config.lamp.as_ref()?;
        let lamp_dofs = self.config.dofs == crate::luxo::DOFS
            && (self.config.dof_names.is_empty() || self.config.dof_names == crate::luxo::DOF_NAMES);
        (lamp_dofs && self.config.ground_weight > 0.0).then_some((lamp.base_half_height, lamp.base_half_width))
    }

    /// The ground penalty of normalised poses `(.., dofs)` (see [`Losses::ground`]), before its
    /// weight; 0 when the penalty does not apply (no lamp, other degrees of freedom, weight 0).
    pub fn ground_penalty(&self, pred: &Tensor) -> ArnnResult<Tensor> {
        let Some((hh, hw)) = self.ground_geometry() else {
            return Ok(Tensor::zeros((), DType::F32, &self.device)?);
        };
        let last = pred.rank() - 1;
        let (sy, sa) = (self.norm.std[1], self.norm.std[2]);
        let y = pred.narrow(last, 1, 1)?.affine(sy, self.norm.mean[1])?;
        let a = pred.narrow(last, 2, 1)?.affine(sa, self.norm.mean[2])?;
        // eval::base_clearance: y - hh |cos a| - hw |sin a|.
        let clearance = ((y - a.cos()?.abs()?.affine(hh, 0.0)?)? - a.sin()?.abs()?.affine(hw, 0.0)?)?;
        let depth = clearance.neg()?.relu()?.affine(1.0 / sy, 0.0)?;
        Ok(depth.sqr()?.mean_all()?)
    }

    /// Runs the model over sequences with the given keys (frame 0 is the start pose), feeding
    /// the ground truth back with probability `teacher` per step; dropout when `train`.
    pub fn losses(
        &mut self,
        seqs: &[&KeyedSequence],
        keys: &[Vec<usize>],
        teacher: f64,
        omega: f64,
        train: bool,
    ) -> ArnnResult<Losses> {
        let steps = seqs.first().map_or(0, |s| s.frames.len().saturating_sub(1));
        let draws: Vec<bool> = (0..steps).map(|_| train && self.rng.next_f64() < teacher).collect();
        let mut rngs = train.then(|| RowRngs::new(self.rng.next_u64(), 0..seqs.len()));
        self.batch_losses(seqs, keys, &[], &draws, omega, rngs.as_mut(), None)
    }

    /// The losses of sequences `seqs` (a batch, or one data-parallel shard of it) with the
    /// given keys and the groups each key fixes (`masks[i][k]`; `masks` or `masks[i]` empty:
    /// whole keys; the key loss counts the fixed groups only): `teacher[t - 1]` feeds the ground truth back after step `t`, `rngs` (one
    /// stream per sequence) applies dropout. `share` `(keys, fraction)`: this is a shard holding
    /// `fraction` of a batch with `keys` key frames in all; its key loss is then the share of
    /// the batch's key loss (over all of the batch's key frames) divided by `fraction`, so that
    /// the shards' losses weighted by their fractions sum to the batch's loss.
    #[allow(clippy::too_many_arguments)]
    fn batch_losses(
        &self,
        seqs: &[&KeyedSequence],
        keys: &[Vec<usize>],
        masks: &[Vec<Vec<bool>>],
        teacher: &[bool],
        omega: f64,
        mut rngs: Option<&mut RowRngs>,
        share: Option<(f64, f64)>,
    ) -> ArnnResult<Losses> {
        let (b, d) = (seqs.len(), self.config.dofs);
        let t_len = seqs.first().map_or(0, |s| s.frames.len());
        if b == 0 || t_len < 2 || seqs.iter().any(|s| s.frames.len() != t_len) {
            return Err(ArnnError::Config(format!(
                "a batch needs sequences of one length of at least 2 frames, found {:?}",
                seqs.iter().map(|s| s.frames.len()).collect::<Vec<_>>()
            )));
        }
        let mut gt = Vec::with_capacity(b * t_len * d);
        for s in seqs {
            for f in &s.frames {
                gt.extend(self.norm.apply(f));
            }
        }
        let gt = Tensor::from_vec(gt, (b, t_len, d), &self.device)?;
        // Inputs per step t = 1..T: X_K, X_{K+1}, t_rel; and the key mask of the outputs (per
        // degree of freedom: a partial key counts for its fixed groups only).
        let steps = t_len - 1;
        let kw = self.config.key_width();
        let groups = &self.config.key_groups;
        let (mut ka, mut kb) = (Vec::with_capacity(steps * b * kw), Vec::with_capacity(steps * b * kw));
        let (mut tr, mut mask) = (Vec::with_capacity(steps * b), vec![0f32; steps * b * d]);
        let fixed = |i: usize, k: usize| masks.get(i).and_then(|m| m.get(k)).map(|m| m.as_slice());
        for t in 1..t_len {
            for (i, s) in seqs.iter().enumerate() {
                let k = &keys[i];
                let (a, c, rel) = KeyedSequence::interval(k, t);
                self.norm.extend_key_input(&mut ka, &s.frames[k[a]], groups, fixed(i, a));
                self.norm.extend_key_input(&mut kb, &s.frames[k[c]], groups, fixed(i, c));
                tr.push(rel as f32);
                if let Some(ki) = k[1..].iter().position(|&f| f == t) {
                    let row = &mut mask[((t - 1) * b + i) * d..((t - 1) * b + i + 1) * d];
                    match fixed(i, ki + 1) {
                        Some(f) if !f.is_empty() && !groups.is_empty() => {
                            for (m, &g) in row.iter_mut().zip(groups) {
                                *m = if f[g] { 1.0 } else { 0.0 };
                            }
                        }
                        _ => row.fill(1.0),
                    }
                }
            }
        }
        let ka = Tensor::from_vec(ka, (steps, b, kw), &self.device)?;
        let kb = Tensor::from_vec(kb, (steps, b, kw), &self.device)?;
        let tr = Tensor::from_vec(tr, (steps, b, 1), &self.device)?;
        let mask = Tensor::from_vec(mask, (steps, b, d), &self.device)?;
        let mut state = self.model.zero_state(b)?;
        let mut prev = gt.narrow(1, 0, 1)?.squeeze(1)?;
        let mut outs = Vec::with_capacity(steps);
        // The keys' features of every step at once (they do not depend on the recurrence).
        // The keys' part of every step's input at once (it does not depend on the recurrence),
        // read frame by frame through a sequence tape in training (`frame_leaves`).
        let (fa, fb) = self.model.key_features(&ka, &kb)?;
        let keys = frame_leaves(&Tensor::cat(&[&fa, &fb, &tr], D::Minus1)?)?;
        for t in 1..t_len {
            let (y, s) = self.model.step_with_keys(
                &prev,
                (&ka.get(t - 1)?, &kb.get(t - 1)?),
                &keys[t - 1],
                &state,
                rngs.as_deref_mut(),
            )?;
            state = s;
            let use_truth = teacher.get(t - 1).copied().unwrap_or(false);
            prev = if use_truth { gt.narrow(1, t, 1)?.squeeze(1)? } else { y.clone() };
            outs.push(y);
        }
        let pred = Tensor::stack(&outs, 0)?; // (steps, b, d)
        let target = gt.narrow(1, 1, steps)?.transpose(0, 1)?;
        let sq = (&pred - target)?.sqr()?;
        let frame = sq.mean_all()?;
        // Normalised by the fixed key values (whole keys: key frames times `d`).
        let key = match share {
            Some((batch_key_values, fraction)) => (sq.mul(&mask)?.sum_all()? / (batch_key_values.max(1.0) * fraction))?,
            None => {
                let n_values = mask.sum_all()?.to_scalar::<f32>()?.max(1.0) as f64;
                (sq.mul(&mask)?.sum_all()? / n_values)?
            }
        };
        let ground = self.ground_penalty(&pred)?;
        let total = ((&frame + (&key * (self.config.key_weight * omega))?)? + (&ground * self.config.ground_weight)?)?;
        Ok(Losses { total, frame, key, ground })
    }

    /// One Adam step on training sequences `samples`, 0-2 keys dropped from each, over the
    /// data-parallel workers ([`ArnnTrainer::set_threads`]). The step's random draws (dropped
    /// keys, teacher forcing per frame, the dropout seed; per sequence streams) are made before
    /// the batch is shared out, so they do not depend on the thread count.
    pub fn train_on(&mut self, samples: &[usize]) -> ArnnResult<f64> {
        let seqs: Vec<KeyedSequence> = samples.iter().map(|&i| self.train[i].clone()).collect();
        let sampling = self.config.key_sampling;
        let keys: Vec<Vec<usize>> =
            seqs.iter().map(|s| choose_keys(&sampling, &s.keys, s.frames.len(), &mut self.rng)).collect();
        let (groups, partial) = (self.config.groups(), self.config.partial_keys);
        let masks: Vec<Vec<Vec<bool>>> =
            keys.iter().map(|k| choose_masks(k.len(), groups, partial, &mut self.rng)).collect();
        let c = self.config.curriculum;
        let (teacher, omega) = (c.teacher_forcing(self.step), c.omega(self.step));
        let steps = seqs.first().map_or(0, |s| s.frames.len().saturating_sub(1));
        let draws: Vec<bool> = (0..steps).map(|_| self.rng.next_f64() < teacher).collect();
        let seed = self.rng.next_u64();
        // Fixed key values after the first key of the whole batch (the key loss's denominator).
        let d = self.config.dofs;
        let group_size: Vec<usize> =
            (0..groups).map(|g| self.config.key_groups.iter().filter(|&&x| x == g).count()).collect();
        let fixed_values = |i: usize, k: usize| -> usize {
            match masks[i].get(k) {
                Some(m) => m.iter().zip(&group_size).filter(|(f, _)| **f).map(|(_, n)| n).sum(),
                None => d,
            }
        };
        let batch_keys = (0..keys.len())
            .map(|i| (1..keys[i].len()).map(|k| fixed_values(i, k)).sum::<usize>())
            .sum::<usize>() as f64;
        let n = seqs.len();
        let this = &*self;
        let shard_loss = |r: std::ops::Range<usize>| -> candle_core::Result<Tensor> {
            let refs: Vec<&KeyedSequence> = seqs[r.clone()].iter().collect();
            let mut rngs = RowRngs::new(seed, r.clone());
            let fraction = r.len() as f64 / n as f64;
            let l = this
                .batch_losses(
                    &refs,
                    &keys[r.clone()],
                    &masks[r],
                    &draws,
                    omega,
                    Some(&mut rngs),
                    Some((batch_keys, fraction)),
                )
                .map_err(candle_core::Error::wrap)?;
            Ok(l.total)
        };
        let (value, grads) = this.parallel.backward(n, &this.vars, shard_loss)?;
        match grads {
            Some(mut grads) if value.is_finite() => {
                if self.config.max_grad_norm > 0.0 {
                    zoo_nn::optim::clip_grad_norm(&mut grads, &self.vars, self.config.max_grad_norm)?;
                }
                self.opt.step(&grads)?
            }
            _ => return Err(ArnnError::NonFiniteLoss { step: self.step, loss: value }),
        }
        self.step += 1;
        Ok(value)
    }

    /// Shares each training step's batch out among `threads` workers (data-parallel training,
    /// [`zoo_nn::parallel`]); the update equals the one-worker update up to float summation
    /// order, and runs are bit-identical for a fixed seed and thread count.
    pub fn set_threads(&mut self, threads: usize) -> ArnnResult<()> {
        self.parallel = DataParallel::new(threads).map_err(|e| ArnnError::Config(e.to_string()))?;
        Ok(())
    }

    /// The number of data-parallel workers.
    pub fn threads(&self) -> usize {
        self.parallel.threads()
    }

    /// Frame and key losses on the validation sequences with all their keys, no teacher
    /// forcing, no dropout.
    pub fn evaluate(&mut self) -> ArnnResult<(f64, f64)> {
        let valid = std::mem::take(&mut self.valid);
        let result = (|| {
            let (mut frame, mut key) = (0.0, 0.0);
            for chunk in valid.chunks(self.config.batch_size) {
                let refs: Vec<&KeyedSequence> = chunk.iter().collect();
                let keys: Vec<Vec<usize>> = chunk.iter().map(|s| s.keys.clone()).collect();
                let l = self.losses(&refs, &keys, 0.0, 1.0, false)?;
                frame += l.frame.to_scalar::<f32>()? as f64 * chunk.len() as f64;
                key += l.key.to_scalar::<f32>()? as f64 * chunk.len() as f64;
            }
            let n = valid.len().max(1) as f64;
            Ok((frame / n, key / n))
        })();
        self.valid = valid;
        result
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

fn check_sequence(config: &ArnnConfig, s: &KeyedSequence) -> ArnnResult<()> {
    let n = s.frames.len();
    if n < 2 {
        return Err(ArnnError::Config(format!("{}: {n} frame(s), a sequence needs at least 2", s.name)));
    }
    let ok_keys = s.keys.len() >= 2
        && s.keys[0] == 0
        && *s.keys.last().unwrap_or(&0) == n - 1
        && s.keys.windows(2).all(|w| w[0] < w[1]);
    if !ok_keys {
        return Err(ArnnError::Config(format!(
            "{}: keys must increase from frame 0 to the last frame ({}), found {:?}",
            s.name,
            n.saturating_sub(1),
            s.keys
        )));
    }
    if s.frames.iter().any(|f| f.len() != config.dofs || f.iter().any(|v| !v.is_finite())) {
        return Err(ArnnError::Config(format!("{}: frames must hold {} finite values", s.name, config.dofs)));
    }
    Ok(())
}

impl Trainable for ArnnTrainer {
    fn train_len(&self) -> usize {
        self.train.len()
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
        let (frame, key) = self.evaluate()?;
        Ok(Validation { loss: frame + key, averaged: None, detail: None })
    }

    fn save_model(&mut self, dir: &Path, _averaged: bool) -> Result<(), TrainError> {
        Ok(self.save(dir)?)
    }

    fn save_training_state(&self, dir: &Path) -> Result<(), TrainError> {
        save_optimizer_and_rng(dir, &self.opt, &self.rng)
    }

    fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError> {
        self.rng = load_optimizer_and_rng(dir, &self.varmap, &mut self.opt, &self.device)?;
        self.step = self.opt.steps();
        Ok(())
    }

    fn summary(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("model".into(), "arnn".into());
        m.insert("parameters".into(), self.parameter_count().into());
        m
    }
}

/// Fills in every frame from keys (section 8): `key_frames` (increasing, the first 0) and one
/// pose per key, in physical units (metres, radians). Returns `key_frames.last() + 1` poses;
/// frame 0 is the first key, later frames are the network's autoregressive predictions.
pub fn complete(
    model: &Arnn,
    norm: &Normalization,
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
) -> ArnnResult<Vec<Vec<f64>>> {
    complete_partial(model, norm, key_frames, key_poses, &[])
}

/// [`complete`] without hitting the keys: the network's own output ([`complete_partial_raw`]).
pub fn complete_raw(
    model: &Arnn,
    norm: &Normalization,
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
) -> ArnnResult<Vec<Vec<f64>>> {
    complete_partial_raw(model, norm, key_frames, key_poses, &[])
}

/// [`complete`] with partial keys: `fixed[k][g]` says whether key `k` fixes group `g` of the
/// model's key groups (`fixed` empty: whole keys; a model without key groups refuses partial
/// keys). The free values of a partial key's pose are ignored (any finite value).
///
/// The network's output is corrected so that every key frame equals its key
/// ([`hit_keys`]); [`complete_partial_raw`] is the network's own output.
pub fn complete_partial(
    model: &Arnn,
    norm: &Normalization,
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
) -> ArnnResult<Vec<Vec<f64>>> {
    let mut out = complete_partial_raw(model, norm, key_frames, key_poses, fixed)?;
    hit_keys(model.config(), key_frames, key_poses, fixed, &mut out);
    Ok(out)
}

/// Corrects a completion (`key_frames.last() + 1` poses) so that each key frame equals its key
/// in the groups the key fixes, the miss spread over the frames before it
/// ([`zoo_protocol::keyhit`]; a humanoid's rotations are compared up to sign).
pub fn hit_keys(
    config: &ArnnConfig,
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
    out: &mut [Vec<f64>],
) {
    let d = config.dofs;
    let keys = zoo_protocol::keyhit::KeyLayout {
        dofs: d,
        frames: key_frames,
        key_groups: &config.key_groups,
        quaternions: config.skeleton.is_some(),
    };
    let poses: Vec<f64> = key_poses.iter().flatten().copied().collect();
    let mut flat: Vec<f64> = out.iter().flatten().copied().collect();
    let fixes = |k: usize, g: usize| fixed.get(k).is_none_or(|m| m.get(g).copied().unwrap_or(true));
    zoo_protocol::keyhit::hit_keys(keys, &poses, fixes, &mut flat, &mut vec![0.0; d]);
    for (o, f) in out.iter_mut().zip(flat.chunks_exact(d)) {
        o.copy_from_slice(f);
    }
}

/// The network's own completion of the keys ([`complete_partial`] before the keys are hit):
/// the key misses of this output are the network's quality figure.
pub fn complete_partial_raw(
    model: &Arnn,
    norm: &Normalization,
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
) -> ArnnResult<Vec<Vec<f64>>> {
    let d = model.config().dofs;
    let groups = model.config().groups();
    if !fixed.is_empty() {
        if groups == 0 {
            return Err(ArnnError::Config(
                "this model was trained on whole keys only: give every key a whole pose (no mask)".into(),
            ));
        }
        if fixed.len() != key_frames.len() || fixed.iter().any(|m| m.len() != groups) {
            return Err(ArnnError::Config(format!(
                "need one mask of {groups} groups per key, found {} masks for {} keys",
                fixed.len(),
                key_frames.len()
            )));
        }
        if fixed[0].contains(&false) {
            return Err(ArnnError::Config("the first key is the start pose: it must fix every group".into()));
        }
    }
    if key_frames.len() < 2 || key_frames.len() != key_poses.len() {
        return Err(ArnnError::Config(format!(
            "need at least two keys and one pose per key, found {} key frames and {} poses",
            key_frames.len(),
            key_poses.len()
        )));
    }
    if key_frames[0] != 0 || key_frames.windows(2).any(|w| w[0] >= w[1]) {
        return Err(ArnnError::Config(format!(
            "key frames must start at 0 and strictly increase, found {key_frames:?}"
        )));
    }
    if let Some(k) = key_poses.iter().position(|p| p.len() != d || p.iter().any(|v| !v.is_finite())) {
        return Err(ArnnError::Config(format!("key {k} must hold {d} finite values, found {:?}", key_poses[k])));
    }
    if norm.mean.len() != d || norm.std.len() != d {
        return Err(ArnnError::Config(format!("normalization is for {} values, the model for {d}", norm.mean.len())));
    }
    let device = model.device();
    let kw = model.config().key_width();
    let key_groups = &model.config().key_groups;
    let keys: Vec<Tensor> = key_poses
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let x = norm.key_input(p, key_groups, fixed.get(k).map(|m| m.as_slice()));
            Tensor::from_vec(x, (1, kw), device)
        })
        .collect::<candle_core::Result<_>>()?;
    let prev0 = Tensor::from_vec(norm.apply(&key_poses[0]).collect::<Vec<f32>>(), (1, d), device)?;
    let last = *key_frames.last().unwrap_or(&0);
    let mut out = vec![key_poses[0].clone()];
    let mut prev = prev0;
    let mut state = model.zero_state(1)?;
    for t in 1..=last {
        let (a, b, rel) = KeyedSequence::interval(key_frames, t);
        let t_rel = Tensor::full(rel as f32, (1, 1), device)?;
        let (y, s) = model.step(&prev, &keys[a], &keys[b], &t_rel, &state, None)?;
        state = s;
        let v: Vec<f32> = y.flatten_all()?.to_vec1()?;
        out.push(norm.restore(&v));
        prev = y;
    }
    Ok(out)
}

/// Writes an ARNN trainer's optimizer state and generator state into a checkpoint folder (both
/// designs' trainers).
pub(crate) fn save_optimizer_and_rng(dir: &Path, opt: &Adam, rng: &SplitMix64) -> Result<(), TrainError> {
    ck::write_tensors(&dir.join(ck::OPTIMIZER_FILE), &opt.state()?)?;
    ck::write_json(&dir.join(ck::RNG_FILE), &serde_json::json!({ RNG_KEY: rng.state() }))?;
    Ok(())
}

/// Reads back what [`save_optimizer_and_rng`] wrote, with the weights into `varmap`; returns the
/// generator.
pub(crate) fn load_optimizer_and_rng(
    dir: &Path,
    varmap: &VarMap,
    opt: &mut Adam,
    device: &Device,
) -> Result<SplitMix64, TrainError> {
    ck::read_varmap(&dir.join(ck::WEIGHTS_FILE), varmap)?;
    opt.set_state(&ck::read_tensors(&dir.join(ck::OPTIMIZER_FILE), device)?)?;
    let saved: serde_json::Value = ck::read_json(&dir.join(ck::RNG_FILE))?;
    let state = saved[RNG_KEY].as_u64().ok_or_else(|| {
        TrainError::Config(format!("{}: no \"{RNG_KEY}\" generator state", dir.join(ck::RNG_FILE).display()))
    })?;
    Ok(SplitMix64::from_state(state))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Smooth made-up sequences of 31 frames with keys every 10 frames.
    fn sequences(n: usize) -> Vec<KeyedSequence> {
        (0..n)
            .map(|i| KeyedSequence {
                name: format!("s{i}"),
                frames: (0..31)
                    .map(|t| {
                        let u = t as f64 / 30.0 + 0.1 * i as f64;
                        vec![u, 0.1 * (3.0 * u).sin(), 0.0, 0.5 + 0.2 * u, -1.0 - 0.3 * (2.0 * u).cos(), -1.2]
                    })
                    .collect(),
                keys: vec![0, 10, 20, 30],
            })
            .collect()
    }

    #[test]
    fn training_lowers_the_loss_and_a_saved_model_completes_the_same() {
        let config = ArnnConfig { learning_rate: 1e-2, ..ArnnConfig::tiny() };
        let mut t = ArnnTrainer::new(&config, sequences(4), sequences(2), &Device::Cpu).unwrap();
        let (f0, k0) = t.evaluate().unwrap();
        for _ in 0..30 {
            t.train_on(&[0, 1, 2, 3]).unwrap();
        }
        let (f1, k1) = t.evaluate().unwrap();
        assert!(f1 + k1 < 0.5 * (f0 + k0), "validation loss {} -> {}", f0 + k0, f1 + k1);
        let dir = tempfile::tempdir().unwrap();
        t.save(dir.path()).unwrap();
        let (model, norm) = crate::checkpoint::load(dir.path(), &Device::Cpu).unwrap();
        let s = &sequences(1)[0];
        let poses: Vec<Vec<f64>> = s.keys.iter().map(|&k| s.frames[k].to_vec()).collect();
        let a = complete(t.model(), t.normalization(), &s.keys, &poses).unwrap();
        let b = complete(&model, &norm, &s.keys, &poses).unwrap();
        assert_eq!((a.len(), b.len()), (31, 31));
        // The statistics go through JSON: equal to the last bits of an f64.
        let diff = a.iter().flatten().zip(b.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(diff < 1e-9, "the reloaded model differs by {diff}");
        assert_eq!(a[0], poses[0]);
    }

    /// Issue 18: a data-parallel step over two workers gives the one-worker step (the same key
    /// drops, teacher-forcing draws and per-sequence dropout masks; the key loss normalised by
    /// the whole batch's keys) up to float summation order, and the same bits for the same
    /// thread count.
    #[test]
    fn two_thread_step_matches_the_one_thread_step() {
        let config = ArnnConfig {
            learning_rate: 1e-2,
            gru_dropout: [0.1, 0.05],
            linear_dropout: [0.2, 0.1],
            ..ArnnConfig::tiny()
        };
        assert!(config.gru_dropout[0] > 0.0 && config.linear_dropout[0] > 0.0, "the test must exercise dropout");
        let trainer = |threads: usize| {
            let mut t = ArnnTrainer::new(&config, sequences(5), sequences(2), &Device::Cpu).unwrap();
            t.set_threads(threads).unwrap();
            t
        };
        let weights = |t: &ArnnTrainer| -> Vec<(String, Vec<f32>)> {
            let mut w: Vec<(String, Vec<f32>)> = t
                .varmap
                .data()
                .lock()
                .unwrap()
                .iter()
                .map(|(n, v)| (n.clone(), v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap()))
                .collect();
            w.sort_by(|a, b| a.0.cmp(&b.0));
            w
        };
        let (mut one, mut two) = (trainer(1), trainer(2));
        assert_eq!(two.threads(), 2);
        let before = weights(&one);
        let batch = [0, 1, 2, 3, 4]; // shards of 3 and 2 sequences
        let (l1, l2) = (one.train_on(&batch).unwrap(), two.train_on(&batch).unwrap());
        assert!((l1 - l2).abs() <= 1e-5 * l1.abs(), "loss {l1} vs {l2}");
        let lr = config.learning_rate as f32;
        let (w1, w2) = (weights(&one), weights(&two));
        let (mut moved, mut noisy, mut total) = (0usize, 0usize, 0usize);
        for (((n, a), (_, b)), (_, w0)) in w1.iter().zip(&w2).zip(&before) {
            let scale = w0.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-3);
            for ((p, q), z) in a.iter().zip(b).zip(w0) {
                let d = (p - q).abs();
                assert!(d <= 2.0 * lr, "{n}: {p} (1 thread) vs {q} (2 threads)");
                noisy += usize::from(d > 1e-5 * scale);
                moved += usize::from(p != z);
                total += 1;
            }
        }
        assert!(moved > 0, "the step changed no weight");
        assert!(noisy * 1000 <= total, "{noisy} of {total} weights differ by more than 1e-5 relative");
        let mut again = trainer(2);
        assert_eq!(again.train_on(&batch).unwrap().to_bits(), l2.to_bits());
        assert_eq!(weights(&again), w2);
    }

    #[test]
    fn complete_refuses_bad_keys() {
        let t = ArnnTrainer::new(&ArnnConfig::tiny(), sequences(1), vec![], &Device::Cpu).unwrap();
        let p = vec![vec![0.0; 6]; 3];
        let err = |frames: &[usize], poses: &[Vec<f64>]| {
            complete(t.model(), t.normalization(), frames, poses).unwrap_err().to_string()
        };
        assert!(err(&[0, 5, 3], &p).contains("strictly increase"));
        assert!(err(&[0], &p[..1]).contains("at least two keys"));
        assert!(err(&[0, 5], &[vec![0.0; 6], vec![f64::NAN; 6]]).contains("finite"));
        assert!(err(&[0, 5], &[vec![0.0; 6], vec![0.0; 4]]).contains("6 finite values"));
    }
}
