//! The training core (RMR sec. 5.1 and 7.1): Adam on the loss of [`crate::loss`], dropout drawn
//! from the trainer's own generator; [`RmrTraining`] plugs it into the shared training loop.

use crate::config::Config;
use crate::error::{RmrError, RmrResult};
use crate::features::{FeatureStats, PairFeatures};
use crate::loss::{Loss, LossValues};
use crate::model::{Rmr, parameter_count};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Optimizer, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{Adam, ParamsAdam, StatefulOptimizer};
use zoo_nn::rng::SplitMix64;
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{DataParallel, RowRngs, SeededVarMap, TrainError};

const RNG_KEY: &str = "trainer";

/// Trains an RMR: the variables, Adam's state, the statistics, the loss and the dropout generator.
pub struct RmrTrainer {
    config: Config,
    stats: FeatureStats,
    varmap: VarMap,
    model: Rmr,
    opt: Adam,
    loss: Loss,
    rng: SplitMix64,
    step: u64,
    /// The variables sorted by name (the gradients of data-parallel steps are summed over them).
    vars: Vec<candle_core::Var>,
    /// Workers of the data-parallel training step ([`RmrTrainer::set_threads`]; one by default).
    parallel: DataParallel,
}

impl RmrTrainer {
    /// A fresh model, weights drawn from `config.train.seed` and their names.
    pub fn new(config: &Config, stats: FeatureStats, device: &Device) -> RmrResult<Self> {
        if stats.dim() != config.dim() {
            return Err(RmrError::Config(format!(
                "statistics have {} values per frame, the configuration's pose vector {}",
                stats.dim(),
                config.dim()
            )));
        }
        let varmap = VarMap::new();
        let vb = SeededVarMap::builder(&varmap, config.train.seed, DType::F32, device);
        let model = Rmr::new(config, vb)?;
        if config.residual {
            zero_output_layer(&varmap, config)?;
        }
        let t = &config.train;
        let mut named: Vec<(String, candle_core::Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let vars = named.iter().map(|(_, v)| v.clone()).collect();
        let opt =
            Adam::new_named(named, ParamsAdam { lr: t.learning_rate, beta1: t.beta1, beta2: t.beta2, eps: t.eps })?;
        let loss = Loss::new(config, &stats, device)?;
        Ok(RmrTrainer {
            config: config.clone(),
            stats,
            varmap,
            model,
            opt,
            loss,
            rng: SplitMix64::new(t.seed),
            step: 0,
            vars,
            parallel: DataParallel::new(1)?,
        })
    }

    /// Shares each training step's batch out among `threads` workers (data-parallel training,
    /// [`zoo_nn::parallel`]) whose gradients are summed before the one Adam step. Dropout masks
    /// are drawn per sample, so the update equals the one-worker update up to float summation
    /// order; runs are bit-identical for a fixed seed and thread count.
    pub fn set_threads(&mut self, threads: usize) -> RmrResult<()> {
        self.parallel = DataParallel::new(threads)?;
        Ok(())
    }

    /// The number of data-parallel workers.
    pub fn threads(&self) -> usize {
        self.parallel.threads()
    }

    /// The model.
    pub fn model(&self) -> &Rmr {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The statistics.
    pub fn stats(&self) -> &FeatureStats {
        &self.stats
    }

    /// The variables.
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Input and target batches `(batch, frames, dim)` of pairs `indices`.
    pub fn batch(&self, data: &PairFeatures, indices: &[usize]) -> RmrResult<(Tensor, Tensor)> {
        if data.dim != self.config.dim() {
            return Err(RmrError::Config(format!(
                "pairs have {} values per frame, the model {}",
                data.dim,
                self.config.dim()
            )));
        }
        let n = data.frames * data.dim;
        let (mut x, mut y) = (Vec::with_capacity(indices.len() * n), Vec::with_capacity(indices.len() * n));
        for &i in indices {
            if i >= data.count {
                return Err(RmrError::Config(format!("pair {i} requested, only {} exist", data.count)));
            }
            x.extend_from_slice(data.input(i));
            y.extend_from_slice(data.target(i));
        }
        let shape = (indices.len(), data.frames, data.dim);
        let dev = self.model.device();
        Ok((Tensor::from_vec(x, shape, dev)?, Tensor::from_vec(y, shape, dev)?))
    }

    /// Per-frame pose-loss weights `(batch, frames)` of pairs `indices` ([`Config::seam_weight`]);
    /// `None` when the weight is 0 or the pairs carry no seams.
    pub fn batch_weights(&self, data: &PairFeatures, indices: &[usize]) -> RmrResult<Option<Tensor>> {
        if self.config.seam_weight == 0.0 || data.seams.len() != data.count {
            return Ok(None);
        }
        let seams: Vec<Vec<usize>> = indices.iter().map(|&i| data.seams[i].clone()).collect();
        let w = crate::loss::seam_weights(&seams, data.frames, self.config.seam_weight, crate::config::SEAM_FRAMES);
        Ok(Some(Tensor::from_vec(w, (indices.len(), data.frames), self.model.device())?))
    }

    /// One Adam step on a batch; returns the loss terms before the step. A NaN or infinite loss
    /// leaves the parameters as they were.
    pub fn train_step(&mut self, x: &Tensor, y: &Tensor) -> RmrResult<LossValues> {
        self.train_step_weighted(x, y, None)
    }

    /// [`RmrTrainer::train_step`] with per-frame pose-loss weights ([`RmrTrainer::batch_weights`]).
    pub fn train_step_weighted(&mut self, x: &Tensor, y: &Tensor, w: Option<&Tensor>) -> RmrResult<LossValues> {
        let (values, grads) = self.loss_and_gradients(x, y, w)?;
        match grads {
            Some(grads) if values.total.is_finite() => self.opt.step(&grads)?,
            _ => return Err(RmrError::NonFiniteLoss { step: self.step, loss: values.total as f32 }),
        }
        self.step += 1;
        Ok(values)
    }

    /// The loss terms of a training step over the data-parallel workers and the gradients of
    /// their total (`None` for a non-finite loss). The step's dropout seed is drawn first, so
    /// each sample's masks do not depend on the thread count.
    fn loss_and_gradients(
        &mut self,
        x: &Tensor,
        y: &Tensor,
        w: Option<&Tensor>,
    ) -> RmrResult<(LossValues, Option<candle_core::backprop::GradStore>)> {
        let seed = self.rng.next_u64();
        let n = x.dim(0)?;
        let (model, loss) = (&self.model, &self.loss);
        let shards = std::sync::Mutex::new(Vec::new());
        let shard_loss = |r: std::ops::Range<usize>| -> candle_core::Result<Tensor> {
            let (xs, ys) = (x.narrow(0, r.start, r.len())?, y.narrow(0, r.start, r.len())?);
            let ws = w.map(|w| w.narrow(0, r.start, r.len())).transpose()?;
            let mut rngs = RowRngs::new(seed, r.clone());
            let out = model.forward(&xs, Some(&mut rngs)).map_err(candle_core::Error::wrap)?;
            let terms = loss.terms_weighted(&out, &xs, &ys, ws.as_ref()).map_err(candle_core::Error::wrap)?;
            let v = terms.values().map_err(candle_core::Error::wrap)?;
            shards.lock().map_err(|_| candle_core::Error::Msg("a training thread panicked".into()))?.push((r, v));
            Ok(terms.total)
        };
        let (_, grads) = self.parallel.backward(n, &self.vars, shard_loss)?;
        let mut parts = shards.into_inner().map_err(|_| RmrError::Config("a training thread panicked".into()))?;
        parts.sort_by_key(|(r, _)| r.start);
        let mut acc = LossValues::default();
        for (r, v) in parts {
            let f = r.len() as f64 / n as f64;
            acc.total += v.total * f;
            acc.pose += v.pose * f;
            acc.trajectory += v.trajectory * f;
            acc.foot += v.foot * f;
            acc.begin += v.begin * f;
            acc.fk += v.fk * f;
            acc.slide += v.slide * f;
            acc.velocity += v.velocity * f;
        }
        Ok((acc, grads))
    }

    /// The loss terms without dropout and without a step.
    pub fn eval_loss(&self, x: &Tensor, y: &Tensor) -> RmrResult<LossValues> {
        self.eval_loss_weighted(x, y, None)
    }

    /// [`RmrTrainer::eval_loss`] with per-frame pose-loss weights.
    pub fn eval_loss_weighted(&self, x: &Tensor, y: &Tensor, w: Option<&Tensor>) -> RmrResult<LossValues> {
        let out = self.model.forward(x, None)?.detach();
        self.loss.terms_weighted(&out, x, y, w)?.values()
    }

    /// Mean loss terms over every pair of `data`, in chunks of 64 (with the seam weights of
    /// [`Config::seam_weight`], as in training).
    pub fn eval_all(&self, data: &PairFeatures) -> RmrResult<LossValues> {
        let mut acc = LossValues::default();
        let idx: Vec<usize> = (0..data.count).collect();
        for c in idx.chunks(64) {
            let (x, y) = self.batch(data, c)?;
            let v = self.eval_loss_weighted(&x, &y, self.batch_weights(data, c)?.as_ref())?;
            let w = c.len() as f64 / data.count as f64;
            acc.total += v.total * w;
            acc.pose += v.pose * w;
            acc.trajectory += v.trajectory * w;
            acc.foot += v.foot * w;
            acc.begin += v.begin * w;
            acc.fk += v.fk * w;
            acc.slide += v.slide * w;
            acc.velocity += v.velocity * w;
        }
        Ok(acc)
    }

    /// Saves `config.json`, `model.safetensors` and `normalization.json`.
    pub fn save(&self, dir: &Path) -> RmrResult<()> {
        crate::checkpoint::save(dir, &self.config, &self.varmap, &self.stats)
    }

    /// Writes Adam's state and the dropout generator's state.
    pub fn save_training_state(&self, dir: &Path) -> RmrResult<()> {
        ck::write_tensors(&dir.join(ck::OPTIMIZER_FILE), &self.opt.state()?)?;
        ck::write_json(&dir.join(ck::RNG_FILE), &serde_json::json!({ RNG_KEY: self.rng.state() }))?;
        Ok(())
    }

    /// Restores the weights, Adam's state and the generator from a folder.
    pub fn load_training_state(&mut self, dir: &Path) -> RmrResult<()> {
        crate::checkpoint::load_weights(dir, &self.varmap)?;
        let device = self.model.device().clone();
        let path = dir.join(ck::OPTIMIZER_FILE);
        self.opt
            .set_state(&ck::read_tensors(&path, &device)?)
            .map_err(|e| RmrError::Config(format!("{}: {e}", path.display())))?;
        self.step = self.opt.steps();
        let rng_path = dir.join(ck::RNG_FILE);
        let saved: serde_json::Value = ck::read_json(&rng_path)?;
        let Some(state) = saved[RNG_KEY].as_u64() else {
            return Err(RmrError::Config(format!(
                "{}: no `{RNG_KEY}` generator state (a u64): the file was written for another model",
                rng_path.display()
            )));
        };
        self.rng = SplitMix64::from_state(state);
        Ok(())
    }

    /// Resumes a trainer from a folder written by [`RmrTrainer::save`] and
    /// [`RmrTrainer::save_training_state`].
    pub fn load(dir: &Path, device: &Device) -> RmrResult<Self> {
        let (config, stats) = crate::checkpoint::read_meta(dir)?;
        let mut t = Self::new(&config, stats, device)?;
        t.load_training_state(dir)?;
        Ok(t)
    }
}

/// Sets the decoder's output layer (`decoder.{n}.weight` and `.bias`) to zero: a residual
/// model then starts as the identity on the pose values (contact logits 0).
fn zero_output_layer(varmap: &VarMap, config: &Config) -> RmrResult<()> {
    let data = varmap.data().lock().expect("varmap lock");
    for part in ["weight", "bias"] {
        let name = format!("decoder.{}.{part}", config.decoder.len());
        let var = data.get(&name).ok_or_else(|| RmrError::Config(format!("the model has no weight `{name}`")))?;
        var.set(&var.as_tensor().zeros_like()?)?;
    }
    Ok(())
}

/// An [`RmrTrainer`] with its normalised training and validation pairs, for
/// [`zoo_nn::train_loop::train`].
pub struct RmrTraining<'a> {
    trainer: RmrTrainer,
    train: &'a PairFeatures,
    valid: &'a PairFeatures,
}

impl<'a> RmrTraining<'a> {
    /// Trains `trainer` on `train`, validating on `valid` (neither may be empty).
    pub fn new(trainer: RmrTrainer, train: &'a PairFeatures, valid: &'a PairFeatures) -> RmrResult<Self> {
        if train.count == 0 || valid.count == 0 {
            return Err(RmrError::Config(format!(
                "need training and validation pairs (training {}, validation {}): use more or longer clips",
                train.count, valid.count
            )));
        }
        for (what, d) in [("training", train), ("validation", valid)] {
            if d.dim != trainer.config.dim() {
                return Err(RmrError::Config(format!(
                    "{what} pairs have {} values per frame, the model {}",
                    d.dim,
                    trainer.config.dim()
                )));
            }
        }
        Ok(RmrTraining { trainer, train, valid })
    }

    /// The trainer.
    pub fn trainer(&self) -> &RmrTrainer {
        &self.trainer
    }

    /// The trainer, once training is over.
    pub fn into_trainer(self) -> RmrTrainer {
        self.trainer
    }
}

impl Trainable for RmrTraining<'_> {
    fn train_len(&self) -> usize {
        self.train.count
    }

    fn batch_size(&self) -> usize {
        self.trainer.config.train.batch_size
    }

    fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError> {
        let (x, y) = self.trainer.batch(self.train, samples)?;
        let w = self.trainer.batch_weights(self.train, samples)?;
        Ok(self.trainer.train_step_weighted(&x, &y, w.as_ref())?.total)
    }

    fn steps(&self) -> u64 {
        self.trainer.steps()
    }

    fn validate(&mut self) -> Result<Validation, TrainError> {
        let loss = self.trainer.eval_all(self.valid)?.total;
        let n = self.valid.count.min(64);
        let (x, _) = self.trainer.batch(self.valid, &(0..n).collect::<Vec<_>>())?;
        let (active, units) = self.trainer.model.active_decoder_units(&x)?;
        let mut detail = format!("decoder units active {active}/{units}");
        if active == 0 {
            // Dead ReLUs get no gradient again: the model is stuck at its output bias.
            detail += ": none left, the model can no longer learn; start again with a lower --lr (the paper's 1e-4)";
        }
        Ok(Validation { loss, averaged: None, detail: Some(detail) })
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
        m.insert("model".into(), "rmr".into());
        m.insert("cell".into(), serde_json::json!(self.trainer.config.cell));
        m.insert("t_begin".into(), serde_json::json!(self.trainer.config.t_begin));
        m.insert("lambda_trajectory".into(), serde_json::json!(self.trainer.config.lambda_trajectory));
        m.insert("parameters".into(), serde_json::json!(parameter_count(&self.trainer.varmap)));
        m
    }
}
