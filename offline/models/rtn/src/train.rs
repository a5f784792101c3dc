//! The training core (RTN sec. 3.3 and 6): random rotations, probabilistic teacher forcing,
//! MSE over the P + 1 predicted frames, AMSGrad; [`RtnTraining`] plugs it into the shared
//! training loop ([`zoo_nn::train_loop`]).

use crate::config::Config;
use crate::error::{RtnError, RtnResult};
use crate::features::{self, FeatureStats, Heightmap, MeanStd, Moments, YawAbout};
use crate::model::{OffsetTensors, Rtn};
use crate::transition::{SequenceInput, check_frames, encode_batch, generate, teacher_calls};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Optimizer, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{AmsGrad, ParamsAmsGrad, StatefulOptimizer};
use zoo_nn::parallel::DataParallel;
use zoo_nn::rng::SplitMix64;
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{Ema, SeededVarMap, TrainError};

/// A training window: global joint positions (`frames * joints * 3`, frame-major, at least
/// [`Config::window_frames`] frames: past context, transition, target and the frame after it;
/// later frames are ignored) and, for the terrain-aware model, its heightmap.
#[derive(Clone, Copy, Debug)]
pub struct MotionWindow<'a> {
    /// Global positions.
    pub positions: &'a [f32],
    /// Terrain under the motion.
    pub terrain: Option<&'a Heightmap>,
}

impl<'a> MotionWindow<'a> {
    /// A window without terrain.
    pub fn new(positions: &'a [f32]) -> Self {
        MotionWindow { positions, terrain: None }
    }
}

/// Fits the normalisation statistics of a training set (RTN sec. 3.2): features, target
/// velocities and offsets (yaw-invariant when the training rotates windows), and for the
/// terrain-aware model one mean/std shared by every terrain cell.
pub fn fit_stats(config: &Config, windows: &[MotionWindow]) -> RtnResult<FeatureStats> {
    let k = config.joints;
    for (i, w) in windows.iter().enumerate() {
        check_frames(&format!("training window {i}"), w.positions.len(), config.window_frames(), k, true)?;
    }
    let mut stats =
        FeatureStats::fit(windows.iter().map(|w| w.positions), k, config.target_frame(), config.train.random_rotation);
    if config.terrain {
        let mut m = Moments::new(1);
        let n = config.terrain_dim();
        let mut patch = vec![0f32; n];
        let d = config.dim();
        for (i, w) in windows.iter().enumerate() {
            let Some(map) = w.terrain else {
                return Err(RtnError::Config(format!(
                    "training window {i} has no terrain but the RTN is terrain-aware"
                )));
            };
            for f in 0..=config.target_frame() {
                let r = features::root_of(&w.positions[f * d..]);
                features::terrain_patch(map, r, config.terrain_extent, config.terrain_side, None, &mut patch);
                m.add(&patch);
            }
        }
        let s = m.finish(false);
        stats.terrain = Some(MeanStd { mean: vec![s.mean[0]; n], std: vec![s.std[0]; n] });
    }
    Ok(stats)
}

/// Trains an RTN: owns the variables, the optimiser state, the statistics and the random source.
pub struct RtnTrainer {
    config: Config,
    stats: FeatureStats,
    varmap: VarMap,
    model: Rtn,
    opt: AmsGrad,
    offsets: OffsetTensors,
    /// Rotation angles (one per window) and teacher-forcing draws (one per step), in that order.
    rng: SplitMix64,
    step: u64,
    /// Moving average of every variable when `config.train.ema_decay` is set.
    ema: Option<Ema>,
    /// The variables sorted by name (the gradients of data-parallel steps are summed over them).
    vars: Vec<candle_core::Var>,
    /// Workers of the data-parallel training step ([`RtnTrainer::set_threads`]; one by default).
    parallel: DataParallel,
}

/// The key of the trainer's generator in `rng.json`.
const RNG_KEY: &str = "trainer";

impl RtnTrainer {
    /// A freshly initialised model: weights drawn with `config.train.seed` and their names
    /// ([`SeededVarMap`]), so one seed gives one initial model.
    pub fn new(config: &Config, stats: FeatureStats, device: &Device) -> RtnResult<Self> {
        Self::with_varmap(config, stats, VarMap::new(), device)
    }

    /// A trainer around `varmap`: variables it already holds are reused (e.g. loaded weights).
    pub(crate) fn with_varmap(
        config: &Config,
        stats: FeatureStats,
        varmap: VarMap,
        device: &Device,
    ) -> RtnResult<Self> {
        if stats.joints != config.joints {
            return Err(RtnError::Config(format!(
                "statistics are for {} joints, the configuration for {}",
                stats.joints, config.joints
            )));
        }
        if config.terrain && stats.terrain.is_none() {
            return Err(RtnError::Config("terrain-aware configuration but no terrain statistics".into()));
        }
        if let Some(aug) = &config.train.augment {
            aug.check(config.joints)?;
            if config.terrain && aug.mirror > 0.0 {
                return Err(RtnError::Config(
                    "mirroring moves the motion off its terrain: train a terrain-aware RTN without it".into(),
                ));
            }
        }
        let vb = SeededVarMap::builder(&varmap, config.train.seed, DType::F32, device);
        let model = Rtn::new(config, vb)?;
        let t = &config.train;
        let params = ParamsAmsGrad { lr: t.learning_rate, beta1: t.beta1, beta2: t.beta2, eps: t.eps };
        let mut named: Vec<(String, candle_core::Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let ema = t.ema_decay.map(|d| Ema::new(named.clone(), d)).transpose()?;
        let vars = named.iter().map(|(_, v)| v.clone()).collect();
        let opt = AmsGrad::new_named(named, params)?;
        let offsets = OffsetTensors::new(&stats, device)?;
        Ok(RtnTrainer {
            config: config.clone(),
            stats,
            varmap,
            model,
            opt,
            offsets,
            rng: SplitMix64::new(t.seed),
            step: 0,
            ema,
            vars,
            parallel: DataParallel::new(1)?,
        })
    }

    /// Trains with `threads` data-parallel workers ([`zoo_nn::parallel`]): each runs candle on
    /// one thread over its share of every batch, and their gradients are summed before the one
    /// optimiser step. The update equals the one-worker update up to float summation order;
    /// runs are bit-identical for a fixed seed and thread count, not across thread counts.
    pub fn set_threads(&mut self, threads: usize) -> RtnResult<()> {
        self.parallel = DataParallel::new(threads)?;
        Ok(())
    }

    /// The number of data-parallel workers.
    pub fn threads(&self) -> usize {
        self.parallel.threads()
    }

    /// The model being trained.
    pub fn model(&self) -> &Rtn {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The normalisation statistics.
    pub fn stats(&self) -> &FeatureStats {
        &self.stats
    }

    /// The variables (for saving).
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// Training steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// The transition length of the next training batch: drawn in
    /// [`crate::TrainConfig::lengths`] (one draw of the trainer's generator), else the window's.
    fn draw_length(&mut self) -> usize {
        match self.config.train.lengths {
            Some([lo, hi]) if lo < hi => lo + self.rng.below((hi - lo + 1) as u64) as usize,
            _ => self.config.transition_frames,
        }
    }

    /// The lengths validation averages: 5, 15, 30 and 45 frames within
    /// [`crate::TrainConfig::lengths`] (its longest when none is), else the window's.
    pub fn validation_lengths(&self) -> Vec<usize> {
        self.config.validation_lengths()
    }

    /// One AMSGrad step on a mini-batch; returns the loss before the step: the MSE over the
    /// P + 1 predicted frames including the target (RTN eq. 17, averaged over values).
    ///
    /// The random draws of the step (one rotation per window, then the teacher-forcing draws)
    /// are made here, in the batch's order, before the batch is shared out among the workers
    /// ([`RtnTrainer::set_threads`]), so they do not depend on the thread count.
    ///
    /// A NaN or infinite loss returns [`RtnError::NonFiniteLoss`] and leaves the parameters as
    /// they were.
    pub fn train_step(&mut self, windows: &[MotionWindow]) -> RtnResult<f32> {
        let (value, grads) = self.loss_and_gradients(windows)?;
        let Some(grads) = grads else {
            return Err(RtnError::NonFiniteLoss { step: self.step, loss: value });
        };
        self.opt.step(&grads)?;
        self.step += 1;
        if let Some(ema) = self.ema.as_mut() {
            ema.update(self.step)?;
        }
        Ok(value)
    }

    /// The loss of a training step on `windows` and the gradient of every variable, by name,
    /// without updating anything but the trainer's generator (the step's random draws are
    /// made as [`RtnTrainer::train_step`] makes them). For checking the data-parallel sum.
    pub fn batch_gradients(&mut self, windows: &[MotionWindow]) -> RtnResult<(f32, Vec<(String, Tensor)>)> {
        let (value, grads) = self.loss_and_gradients(windows)?;
        let Some(grads) = grads else {
            return Err(RtnError::NonFiniteLoss { step: self.step, loss: value });
        };
        let data = self.varmap.data().lock().expect("varmap lock");
        let mut out: Vec<(String, Tensor)> =
            data.iter().filter_map(|(n, v)| grads.get(v.as_tensor()).map(|g| (n.clone(), g.clone()))).collect();
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok((value, out))
    }

    /// The step's random draws, then the loss and gradients over the data-parallel workers;
    /// no gradients for a non-finite loss.
    fn loss_and_gradients(
        &mut self,
        windows: &[MotionWindow],
    ) -> RtnResult<(f32, Option<candle_core::backprop::GradStore>)> {
        let p = self.config.train.teacher_forcing.probability(self.step);
        let rotate = self.config.train.random_rotation;
        let n = self.draw_length();
        let items = sequence_inputs(&self.config, windows, Some(&mut self.rng), rotate, true, n)?;
        let (past, n_out) = (self.config.past_frames, n + 1);
        let calls = teacher_calls(past, n_out, past + n + 1);
        let rng = &mut self.rng;
        let draws: Vec<bool> = (0..calls).map(|_| p > 0.0 && (p >= 1.0 || rng.next_f64() < p)).collect();
        let (model, stats, offsets) = (&self.model, &self.stats, &self.offsets);
        let shard_loss = |r: std::ops::Range<usize>| -> candle_core::Result<Tensor> {
            let batch = encode_batch(stats, &items[r], model.device()).map_err(candle_core::Error::wrap)?;
            let mut next = draws.iter().copied();
            let mut teacher = || next.next().unwrap_or(false);
            unroll_mse(model, stats, offsets, &batch, n_out, true, &mut teacher).map_err(candle_core::Error::wrap)
        };
        let (value, grads) = self.parallel.backward(items.len(), &self.vars, shard_loss)?;
        let value = value as f32;
        Ok((value, grads.filter(|_| value.is_finite())))
    }

    /// Whether the trainer keeps a moving average of the weights.
    pub fn has_ema(&self) -> bool {
        self.ema.is_some()
    }

    /// Runs `f` with the moving-average weights in place of the trained ones, then puts the
    /// trained weights back (also when `f` fails). Without a moving average, `f` sees the trained
    /// weights.
    pub fn with_ema_weights<R>(&mut self, f: impl FnOnce(&mut Self) -> RtnResult<R>) -> RtnResult<R> {
        let trained = self.ema.as_ref().map(Ema::swap_in).transpose()?;
        let out = f(self);
        if let (Some(ema), Some(trained)) = (self.ema.as_ref(), trained) {
            ema.swap_out(trained)?;
        }
        out
    }

    /// The moving-average tensors by variable name (`ema.{name}`, for `--resume`), or `None`.
    pub fn ema_state(&self) -> Option<std::collections::HashMap<String, Tensor>> {
        self.ema.as_ref().map(Ema::state)
    }

    /// Validation loss: the same MSE without teacher forcing and without rotation, averaged over
    /// the [`RtnTrainer::validation_lengths`].
    pub fn eval_loss(&self, windows: &[MotionWindow]) -> RtnResult<f32> {
        let lengths = self.validation_lengths();
        let mut sum = 0.0;
        for &n in &lengths {
            sum += chunk_loss(self, windows, n)?;
        }
        Ok(sum / lengths.len() as f32)
    }

    /// Saves `config.json`, `model.safetensors` and `normalization.json` into `dir` (see
    /// [`crate::checkpoint::save`]).
    pub fn save(&self, dir: &std::path::Path) -> RtnResult<()> {
        crate::checkpoint::save(dir, &self.config, &self.varmap, &self.stats)
    }

    /// The optimiser (its state: [`StatefulOptimizer::state`]).
    pub fn optimizer(&self) -> &AmsGrad {
        &self.opt
    }

    /// [`RtnTrainer::save`] plus the training state ([`RtnTrainer::save_training_state`]), so
    /// that [`RtnTrainer::load`] continues the run exactly.
    pub fn save_with_optimizer(&self, dir: &Path) -> RtnResult<()> {
        self.save(dir)?;
        self.save_training_state(dir)
    }

    /// Writes the optimiser state (`optimizer.safetensors`), the moving average
    /// (`ema.safetensors`, when kept) and the generator's state (`rng.json`), each atomically.
    pub fn save_training_state(&self, dir: &Path) -> RtnResult<()> {
        ck::write_tensors(&dir.join(ck::OPTIMIZER_FILE), &self.opt.state()?)?;
        if let Some(ema) = self.ema_state() {
            ck::write_tensors(&dir.join(ck::EMA_FILE), &ema)?;
        }
        ck::write_json(&dir.join(ck::RNG_FILE), &serde_json::json!({ "trainer": self.rng.state() }))?;
        Ok(())
    }

    /// Restores the weights and whatever training state the folder holds: the optimiser
    /// (returns `false` when the folder has none: a fresh one is kept), the moving average and
    /// the generator (folders written before it was saved keep the freshly seeded one).
    pub fn load_training_state(&mut self, dir: &Path) -> RtnResult<bool> {
        crate::checkpoint::load_weights(dir, &self.varmap)?;
        let device = self.model.device().clone();
        let path = dir.join(ck::OPTIMIZER_FILE);
        if !path.is_file() {
            return Ok(false);
        }
        self.opt.set_state(&ck::read_tensors(&path, &device)?).map_err(|e| in_file(&path, e))?;
        self.step = self.opt.steps();
        let ema_path = dir.join(ck::EMA_FILE);
        if let Some(ema) = self.ema.as_mut().filter(|_| ema_path.is_file()) {
            ema.set_state(&ck::read_tensors(&ema_path, &device)?).map_err(|e| in_file(&ema_path, e))?;
        }
        let rng_path = dir.join(ck::RNG_FILE);
        if rng_path.is_file() {
            let saved: serde_json::Value = ck::read_json(&rng_path)?;
            let Some(state) = saved[RNG_KEY].as_u64() else {
                return Err(RtnError::Config(format!(
                    "{}: no `{RNG_KEY}` generator state (a u64): the file was written for another model",
                    rng_path.display()
                )));
            };
            self.rng = SplitMix64::from_state(state);
        }
        Ok(true)
    }

    /// Resumes from a checkpoint folder: weights, statistics and, when the folder has one, the
    /// optimiser state (else a fresh one; returned `false`).
    pub fn load(dir: &Path, device: &Device) -> RtnResult<Self> {
        Ok(Self::load_with_optimizer(dir, device)?.0)
    }

    /// [`RtnTrainer::load`], also telling whether the optimiser state was restored.
    pub fn load_with_optimizer(dir: &Path, device: &Device) -> RtnResult<(Self, bool)> {
        let (config, stats) = crate::checkpoint::read_meta(dir)?;
        let mut t = Self::with_varmap(&config, stats, VarMap::new(), device)?;
        let restored = t.load_training_state(dir)?;
        Ok((t, restored))
    }
}

fn in_file(path: &Path, e: zoo_nn::NnError) -> RtnError {
    RtnError::Config(format!("{}: {e}", path.display()))
}

/// Mean loss over `windows` in chunks of 64 (the RTN's validation batches).
/// The sequences of `windows` to encode at transition length `n`, each rotated about the
/// vertical when `rotate` (one draw of `rng` per window). `augment`: apply the configured
/// augmentation ([`crate::TrainConfig::augment`]; training steps only), drawn before each
/// window's rotation. Without `rng` (validation) nothing is drawn: no rotation, no augmentation.
fn sequence_inputs<'a>(
    c: &Config,
    windows: &[MotionWindow<'a>],
    mut rng: Option<&mut SplitMix64>,
    rotate: bool,
    augment: bool,
    n: usize,
) -> RtnResult<Vec<SequenceInput<'a>>> {
    let d = c.dim();
    let tf = c.past_frames + n.min(c.transition_frames);
    let mut items = Vec::with_capacity(windows.len());
    for (i, w) in windows.iter().enumerate() {
        check_frames(&format!("training window {i}"), w.positions.len(), c.window_frames(), c.joints, true)?;
        if !w.positions[..(tf + 2) * d].iter().all(|v| v.is_finite()) {
            return Err(RtnError::Config(format!("training window {i} holds NaN or inf positions")));
        }
        // Augmentation (time reversal, mirroring, speed) before the rotation, in training
        // steps only, and only when configured, so runs without it draw as before.
        let mut p = match (&c.train.augment, augment, rng.as_deref_mut()) {
            (Some(aug), true, Some(r)) => aug.apply(w.positions, c.joints, tf + 2, r),
            _ => w.positions[..(tf + 2) * d].to_vec(),
        };
        let rotation = match (rotate, rng.as_deref_mut()) {
            (true, Some(r)) => {
                let angle = ((r.next_f64() * 2.0 - 1.0) * std::f64::consts::PI) as f32;
                let root = features::root_of(&p[(c.past_frames - 1) * d..]);
                let rot = YawAbout { angle, center: [root[0], root[2]] };
                features::rotate_about_y(&mut p, rot.angle, rot.center);
                Some(rot)
            }
            _ => None,
        };
        items.push(SequenceInput {
            target: p[tf * d..(tf + 1) * d].to_vec().into(),
            next: p[(tf + 1) * d..(tf + 2) * d].to_vec().into(),
            known: {
                p.truncate((tf + 1) * d);
                p.into()
            },
            terrain: w.terrain,
            rotation,
        });
    }
    Ok(items)
}

/// The validation MSE of `windows` at transition length `n`: the unroll without teacher
/// forcing, rotation or any draw, over the `P + 1` predicted frames.
fn chunk_loss(t: &RtnTrainer, windows: &[MotionWindow], n: usize) -> RtnResult<f32> {
    let items = sequence_inputs(&t.config, windows, None, false, false, n)?;
    let batch = encode_batch(&t.stats, &items, t.model.device())?;
    let mse = unroll_mse(&t.model, &t.stats, &t.offsets, &batch, n + 1, false, &mut || false)?;
    Ok(mse.to_scalar::<f32>()?)
}

/// The MSE (RTN eq. 17, averaged over values) of the `n_out` frames the model unrolls after
/// the batch's past frames against the batch's own frames: the training loss (`grad`, with
/// the step's teacher-forcing draws) and the validation loss (no graph, no forcing).
fn unroll_mse(
    model: &Rtn,
    stats: &FeatureStats,
    offsets: &OffsetTensors,
    batch: &crate::transition::EncodedBatch,
    n_out: usize,
    grad: bool,
    teacher: &mut dyn FnMut() -> bool,
) -> RtnResult<Tensor> {
    let past = model.config().past_frames;
    let outs = generate(model, stats, offsets, batch, past, n_out, grad, teacher)?;
    let pred = Tensor::stack(&outs, 1)?;
    let truth = Tensor::stack(&batch.x[past..past + n_out], 1)?;
    Ok((pred - truth)?.sqr()?.mean_all()?)
}

/// [`RtnTrainer::eval_loss`] of `windows` in chunks of 64, the chunks shared out among the
/// data-parallel workers (each on its one thread, as in a training step) and summed in order:
/// the same value for every thread count, in about `1 / threads` of the time.
fn mean_eval_loss(trainer: &RtnTrainer, windows: &[MotionWindow]) -> RtnResult<f64> {
    let chunks: Vec<&[MotionWindow]> = windows.chunks(64).collect();
    let losses = trainer.parallel.map(chunks.len(), |i| trainer.eval_loss(chunks[i]));
    let mut sum = 0.0;
    for (c, l) in chunks.iter().zip(losses) {
        sum += l? as f64 * c.len() as f64;
    }
    Ok(sum / windows.len() as f64)
}

/// An [`RtnTrainer`] with its training and validation windows, for the shared training loop
/// ([`zoo_nn::train_loop::train`]): one AMSGrad step per batch, validation in chunks of 64 of
/// the trained weights and then of the moving average, checkpoints through
/// [`RtnTrainer::save`] and [`RtnTrainer::save_training_state`].
pub struct RtnTraining<'a> {
    trainer: RtnTrainer,
    train: &'a [MotionWindow<'a>],
    valid: &'a [MotionWindow<'a>],
    batch: Vec<MotionWindow<'a>>,
}

impl<'a> RtnTraining<'a> {
    /// Trains `trainer` on `train`, validating on `valid` (neither may be empty).
    pub fn new(trainer: RtnTrainer, train: &'a [MotionWindow<'a>], valid: &'a [MotionWindow<'a>]) -> RtnResult<Self> {
        if train.is_empty() || valid.is_empty() {
            return Err(RtnError::Config(format!(
                "need training and validation windows (training {}, validation {})",
                train.len(),
                valid.len()
            )));
        }
        Ok(RtnTraining { trainer, train, valid, batch: Vec::new() })
    }

    /// The trainer.
    pub fn trainer(&self) -> &RtnTrainer {
        &self.trainer
    }

    /// The trainer, once training is over.
    pub fn into_trainer(self) -> RtnTrainer {
        self.trainer
    }
}

impl Trainable for RtnTraining<'_> {
    fn train_len(&self) -> usize {
        self.train.len()
    }

    fn batch_size(&self) -> usize {
        self.trainer.config.train.batch_size
    }

    fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError> {
        self.batch.clear();
        self.batch.extend(samples.iter().map(|&i| self.train[i]));
        Ok(self.trainer.train_step(&self.batch)? as f64)
    }

    fn steps(&self) -> u64 {
        self.trainer.steps()
    }

    fn validate(&mut self) -> Result<Validation, TrainError> {
        let valid = self.valid;
        let loss = mean_eval_loss(&self.trainer, valid)?;
        let averaged = if self.trainer.has_ema() {
            Some(self.trainer.with_ema_weights(|t| mean_eval_loss(t, valid))?)
        } else {
            None
        };
        Ok(Validation { loss, averaged, detail: None })
    }

    fn save_model(&mut self, dir: &Path, averaged: bool) -> Result<(), TrainError> {
        if averaged {
            self.trainer.with_ema_weights(|t| t.save(dir))?;
        } else {
            self.trainer.save(dir)?;
        }
        Ok(())
    }

    fn save_training_state(&self, dir: &Path) -> Result<(), TrainError> {
        Ok(self.trainer.save_training_state(dir)?)
    }

    fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError> {
        self.trainer.load_training_state(dir)?;
        Ok(())
    }

    fn summary(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("model".into(), "rtn".into());
        m.insert("ema_decay".into(), serde_json::json!(self.trainer.config.train.ema_decay));
        m.insert("parameters".into(), serde_json::json!(self.trainer.model.parameter_count()));
        m
    }
}

/// Generated frames for a batch with the given teacher-forcing decisions; exposed for tests.
#[doc(hidden)]
pub fn predict_with_teacher(
    model: &Rtn,
    stats: &FeatureStats,
    windows: &[MotionWindow],
    teacher: &mut dyn FnMut() -> bool,
) -> RtnResult<Tensor> {
    let c = model.config();
    let d = c.dim();
    let tf = c.target_frame();
    let items: Vec<SequenceInput> = windows
        .iter()
        .map(|w| SequenceInput {
            known: w.positions[..(tf + 1) * d].into(),
            target: w.positions[tf * d..(tf + 1) * d].into(),
            next: w.positions[(tf + 1) * d..(tf + 2) * d].into(),
            terrain: w.terrain,
            rotation: None,
        })
        .collect();
    let batch = encode_batch(stats, &items, model.device())?;
    let offsets = OffsetTensors::new(stats, model.device())?;
    let outs = generate(model, stats, &offsets, &batch, c.past_frames, c.transition_frames + 1, true, teacher)?;
    Ok(Tensor::stack(&outs, 1)?)
}
