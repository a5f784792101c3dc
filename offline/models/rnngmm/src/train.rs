//! Training of the generator (sec. 4.1.2-4.1.3): NLL of the next frame over windows of 50
//! frames, Gaussian noise (sigma 0.05) on the normalised inputs, RMSProp (lr 1e-3, times 0.95
//! after every epoch), every gradient component clipped to [-5, 5], batches of 20;
//! [`GeneratorTraining`] plugs it into the shared training loop ([`zoo_nn::train_loop`]).

use crate::config::Config;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{EncodedClip, FeatureSpec, Normalization};
use crate::model::Generator;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{Optimizer, VarMap};
use std::path::Path;
use zoo_motion::Clip;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{ParamsRmsProp, RmsProp, StatefulOptimizer, clip_grad_value};
use zoo_nn::rng::SplitMix64;
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{SeededVarMap, TrainError};

/// Normalised training windows of one length, stored one after the other.
#[derive(Clone, Debug, PartialEq)]
pub struct Windows {
    /// Frames per window.
    pub window: usize,
    /// Values per frame.
    pub dim: usize,
    /// `len * window * dim` normalised values.
    pub data: Vec<f32>,
}

impl Windows {
    /// Cuts every clip into windows of `window` frames starting every `stride` frames
    /// (`0, stride, ...` while the window fits; a clip shorter than a window gives none) and
    /// normalises them.
    pub fn from_clips(clips: &[EncodedClip], norm: &Normalization, window: usize, stride: usize) -> RnnGmmResult<Self> {
        if window < 2 || stride == 0 {
            return Err(RnnGmmError::Config(format!(
                "windows need at least 2 frames and a positive stride, found {window} and {stride}"
            )));
        }
        let dim = norm.dim();
        let mut data = Vec::new();
        for (i, c) in clips.iter().enumerate() {
            if c.dim != dim {
                return Err(RnnGmmError::Config(format!(
                    "clip {i} has {} values per frame, the statistics {dim}",
                    c.dim
                )));
            }
            let mut start = 0;
            while start + window <= c.frames() {
                data.extend_from_slice(&c.values[start * dim..(start + window) * dim]);
                start += stride;
            }
        }
        norm.normalize(&mut data);
        Ok(Windows { window, dim, data })
    }

    /// Number of windows.
    pub fn len(&self) -> usize {
        self.data.len() / (self.window * self.dim).max(1)
    }

    /// True without windows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Window `i` (`window * dim` values).
    pub fn get(&self, i: usize) -> &[f32] {
        let n = self.window * self.dim;
        &self.data[i * n..(i + 1) * n]
    }
}

/// Everything training needs from clips: the feature (references fitted on the training clips),
/// the statistics (training clips) and the windows of both sets.
#[derive(Clone, Debug)]
pub struct TrainingData {
    /// The state feature.
    pub spec: FeatureSpec,
    /// Normalisation statistics of the training clips.
    pub norm: Normalization,
    /// Training windows.
    pub train: Windows,
    /// Validation windows.
    pub valid: Windows,
}

impl TrainingData {
    /// Encodes `train` and `valid` clips (one skeleton, at `fps`) and cuts them into the
    /// windows of `config`. Both sets must give at least one window.
    pub fn from_clips(config: &Config, fps: f64, train: &[&Clip], valid: &[&Clip]) -> RnnGmmResult<Self> {
        let Some(first) = train.first() else {
            return Err(RnnGmmError::Config("no training clips".into()));
        };
        let spec = FeatureSpec::fit(&first.skeleton, fps, train)?;
        let encode = |clips: &[&Clip], what: &str| -> RnnGmmResult<Vec<EncodedClip>> {
            clips
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    spec.encode(c).map_err(|e| match e {
                        RnnGmmError::Motion(m) => RnnGmmError::Motion(format!("{what} clip {i}: {m}")),
                        e => e,
                    })
                })
                .collect()
        };
        let (train_enc, valid_enc) = (encode(train, "training")?, encode(valid, "validation")?);
        let norm = Normalization::fit(&train_enc)?;
        let t = &config.train;
        let train = Windows::from_clips(&train_enc, &norm, t.window, t.window_stride)?;
        let valid = Windows::from_clips(&valid_enc, &norm, t.window, t.window_stride)?;
        if train.is_empty() || valid.is_empty() {
            return Err(RnnGmmError::Config(format!(
                "{} training and {} validation windows of {} frames: the clips are too short or too few",
                train.len(),
                valid.len(),
                t.window
            )));
        }
        Ok(TrainingData { spec, norm, train, valid })
    }
}

/// The key of the trainer's generator in `rng.json`.
const RNG_KEY: &str = "noise";

/// Trains a generator: owns the variables, the RMSProp state, the feature, the statistics and
/// the noise generator.
pub struct GeneratorTrainer {
    config: Config,
    spec: FeatureSpec,
    norm: Normalization,
    varmap: VarMap,
    model: Generator,
    opt: RmsProp,
    vars: Vec<Var>,
    /// Input noise, one standard normal per input value, batch after batch.
    rng: SplitMix64,
    /// Workers of the data-parallel step ([`GeneratorTrainer::set_threads`]; one by default).
    parallel: zoo_nn::DataParallel,
}

impl GeneratorTrainer {
    /// A freshly initialised generator: weights drawn with `config.train.seed` and their names
    /// ([`SeededVarMap`]), so one seed gives one initial model.
    pub fn new(config: &Config, spec: FeatureSpec, norm: Normalization, device: &Device) -> RnnGmmResult<Self> {
        crate::checkpoint::check_agree(config, &spec, &norm)?;
        let varmap = VarMap::new();
        let vb = SeededVarMap::builder(&varmap, config.train.seed, DType::F32, device);
        let model = Generator::new(config, vb)?;
        let mut named: Vec<(String, Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let vars = named.iter().map(|(_, v)| v.clone()).collect();
        let t = &config.train;
        let params = ParamsRmsProp { lr: t.learning_rate, rho: t.rho, eps: t.eps, lr_decay: t.lr_decay };
        let opt = RmsProp::new_named(named, params)?;
        Ok(GeneratorTrainer {
            config: config.clone(),
            spec,
            norm,
            varmap,
            model,
            opt,
            vars,
            rng: SplitMix64::new(t.seed),
            parallel: zoo_nn::DataParallel::new(1)?,
        })
    }

    /// Trains with `threads` data-parallel workers (`zoo_nn::parallel`): the batch (its input
    /// noise drawn first, in the batch's order) is shared out among them and their gradients
    /// are summed before clipping and the one RMSProp step, so the update equals the one-worker
    /// update up to float summation order.
    pub fn set_threads(&mut self, threads: usize) -> RnnGmmResult<()> {
        self.parallel = zoo_nn::DataParallel::new(threads)?;
        Ok(())
    }

    /// The generator being trained.
    pub fn model(&self) -> &Generator {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The state feature.
    pub fn spec(&self) -> &FeatureSpec {
        &self.spec
    }

    /// The normalisation statistics.
    pub fn norm(&self) -> &Normalization {
        &self.norm
    }

    /// The variables.
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// The optimiser (its learning rate: [`Optimizer::learning_rate`]).
    pub fn optimizer(&self) -> &RmsProp {
        &self.opt
    }

    /// Optimiser steps taken.
    pub fn steps(&self) -> u64 {
        self.opt.steps()
    }

    /// Inputs (frames `0..W-1`, plus noise when `noise`) and targets (frames `1..W`) of a batch,
    /// each `(batch, W - 1, D)`.
    fn batch(&mut self, windows: &[&[f32]], noise: bool) -> RnnGmmResult<(Tensor, Tensor)> {
        let (w, d) = (self.config.train.window, self.config.dim);
        if windows.is_empty() {
            return Err(RnnGmmError::Config("an empty batch".into()));
        }
        let mut inputs = Vec::with_capacity(windows.len() * (w - 1) * d);
        let mut targets = Vec::with_capacity(windows.len() * (w - 1) * d);
        for (i, win) in windows.iter().enumerate() {
            if win.len() != w * d {
                return Err(RnnGmmError::Size {
                    what: format!("training window {i}"),
                    expected: w * d,
                    detail: format!("{w} frames of D = {d}"),
                    found: win.len(),
                });
            }
            inputs.extend_from_slice(&win[..(w - 1) * d]);
            targets.extend_from_slice(&win[d..]);
        }
        if let Some(i) = inputs.iter().chain(&targets).position(|v| !v.is_finite()) {
            return Err(RnnGmmError::Config(format!("training value {i} of the batch is NaN or infinite")));
        }
        if noise && self.config.train.input_noise > 0.0 {
            let s = self.config.train.input_noise;
            for v in &mut inputs {
                *v += (s * self.rng.normal()) as f32;
            }
        }
        let dev = self.model.device();
        let shape = (windows.len(), w - 1, d);
        Ok((Tensor::from_vec(inputs, shape, dev)?, Tensor::from_vec(targets, shape, dev)?))
    }

    /// One RMSProp step on a batch of normalised windows (`window * D` values each); returns the
    /// mean NLL per frame before the step (sec. 4.1.2-4.1.3: noisy inputs, clipped gradients).
    ///
    /// A NaN or infinite loss returns [`RnnGmmError::NonFiniteLoss`] and leaves the parameters
    /// as they were.
    pub fn train_step(&mut self, windows: &[&[f32]]) -> RnnGmmResult<f64> {
        let (inputs, targets) = self.batch(windows, true)?;
        let model = &self.model;
        let shard = |r: std::ops::Range<usize>| {
            model.sequence_nll(&inputs.narrow(0, r.start, r.len())?, &targets.narrow(0, r.start, r.len())?)
        };
        let (value, grads) = self.parallel.backward(windows.len(), &self.vars, shard)?;
        let Some(mut grads) = grads.filter(|_| value.is_finite()) else {
            return Err(RnnGmmError::NonFiniteLoss { step: self.opt.steps(), loss: value });
        };
        clip_grad_value(&mut grads, &self.vars, self.config.train.clip)?;
        self.opt.step(&grads)?;
        Ok(value)
    }

    /// Mean NLL per frame of a batch without input noise and without updating anything.
    pub fn eval_loss(&mut self, windows: &[&[f32]]) -> RnnGmmResult<f64> {
        let (inputs, targets) = self.batch(windows, false)?;
        Ok(self.model.sequence_nll(&inputs, &targets)?.to_scalar::<f32>()? as f64)
    }

    /// Mean NLL per frame over all `windows`, in batches of 64.
    pub fn eval_windows(&mut self, windows: &Windows) -> RnnGmmResult<f64> {
        let all: Vec<&[f32]> = (0..windows.len()).map(|i| windows.get(i)).collect();
        let mut sum = 0.0;
        for c in all.chunks(64) {
            sum += self.eval_loss(c)? * c.len() as f64;
        }
        Ok(sum / all.len().max(1) as f64)
    }

    /// The per-epoch learning-rate decay (`lr *= lr_decay`).
    pub fn end_epoch(&mut self) {
        self.opt.end_epoch();
    }

    /// Saves `config.json`, `model.safetensors`, `features.json` and `normalization.json`.
    pub fn save(&self, dir: &Path) -> RnnGmmResult<()> {
        crate::checkpoint::save(dir, &self.config, &self.varmap, &self.spec, &self.norm)
    }

    /// Writes the optimiser state (`optimizer.safetensors`: the mean squares, the step count and
    /// the decayed learning rate) and the noise generator's state (`rng.json`).
    pub fn save_training_state(&self, dir: &Path) -> RnnGmmResult<()> {
        ck::write_tensors(&dir.join(ck::OPTIMIZER_FILE), &self.opt.state()?)?;
        ck::write_json(&dir.join(ck::RNG_FILE), &serde_json::json!({ RNG_KEY: self.rng.state() }))?;
        Ok(())
    }

    /// Restores the weights, the optimiser and the noise generator from a folder written by
    /// [`GeneratorTrainer::save`] and [`GeneratorTrainer::save_training_state`].
    pub fn load_training_state(&mut self, dir: &Path) -> RnnGmmResult<()> {
        crate::checkpoint::load_weights(dir, &self.varmap)?;
        let path = dir.join(ck::OPTIMIZER_FILE);
        let state = ck::read_tensors(&path, self.model.device())?;
        self.opt.set_state(&state).map_err(|e| RnnGmmError::Config(format!("{}: {e}", path.display())))?;
        let rng_path = dir.join(ck::RNG_FILE);
        let saved: serde_json::Value = ck::read_json(&rng_path)?;
        let Some(s) = saved[RNG_KEY].as_u64() else {
            return Err(RnnGmmError::Config(format!(
                "{}: no `{RNG_KEY}` generator state (a u64): the file was written for another model",
                rng_path.display()
            )));
        };
        self.rng = SplitMix64::from_state(s);
        Ok(())
    }

    /// Resumes from a checkpoint folder holding the training state.
    pub fn load(dir: &Path, device: &Device) -> RnnGmmResult<Self> {
        let (config, spec, norm) = crate::checkpoint::read_meta(dir)?;
        let mut t = GeneratorTrainer::new(&config, spec, norm, device)?;
        t.load_training_state(dir)?;
        Ok(t)
    }
}

/// A [`GeneratorTrainer`] with its windows, for the shared training loop
/// ([`zoo_nn::train_loop::train`]): one RMSProp step per batch, the learning-rate decay at the
/// end of each epoch, the validation NLL without noise.
pub struct GeneratorTraining<'a> {
    trainer: GeneratorTrainer,
    train: &'a Windows,
    valid: &'a Windows,
}

impl<'a> GeneratorTraining<'a> {
    /// Trains `trainer` on `train`, validating on `valid` (neither may be empty, both of the
    /// trainer's window length and frame size).
    pub fn new(trainer: GeneratorTrainer, train: &'a Windows, valid: &'a Windows) -> RnnGmmResult<Self> {
        let c = trainer.config();
        for (what, w) in [("training", train), ("validation", valid)] {
            if w.is_empty() || w.window != c.train.window || w.dim != c.dim {
                return Err(RnnGmmError::Config(format!(
                    "{what} windows: {} windows of {} frames of {} values, the configuration wants at least one of \
                     {} frames of {}",
                    w.len(),
                    w.window,
                    w.dim,
                    c.train.window,
                    c.dim
                )));
            }
        }
        Ok(GeneratorTraining { trainer, train, valid })
    }

    /// The trainer.
    pub fn trainer(&self) -> &GeneratorTrainer {
        &self.trainer
    }

    /// The trainer, once training is over.
    pub fn into_trainer(self) -> GeneratorTrainer {
        self.trainer
    }
}

impl Trainable for GeneratorTraining<'_> {
    fn train_len(&self) -> usize {
        self.train.len()
    }

    fn batch_size(&self) -> usize {
        self.trainer.config.train.batch_size
    }

    fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError> {
        let batch: Vec<&[f32]> = samples.iter().map(|&i| self.train.get(i)).collect();
        Ok(self.trainer.train_step(&batch)?)
    }

    fn steps(&self) -> u64 {
        self.trainer.steps()
    }

    fn end_epoch(&mut self) -> Result<(), TrainError> {
        self.trainer.end_epoch();
        Ok(())
    }

    fn validate(&mut self) -> Result<Validation, TrainError> {
        Ok(Validation { loss: self.trainer.eval_windows(self.valid)?, averaged: None, detail: None })
    }

    fn save_model(&mut self, dir: &Path, _averaged: bool) -> Result<(), TrainError> {
        Ok(self.trainer.save(dir)?)
    }

    fn save_training_state(&self, dir: &Path) -> Result<(), TrainError> {
        Ok(self.trainer.save_training_state(dir)?)
    }

    fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError> {
        Ok(self.trainer.load_training_state(dir)?)
    }

    fn summary(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("model".into(), "rnn-gmm".into());
        m.insert("stage".into(), "generator".into());
        m.insert("parameters".into(), serde_json::json!(self.trainer.model.parameter_count()));
        m.insert("learning_rate".into(), serde_json::json!(self.trainer.opt.learning_rate()));
        m
    }
}
