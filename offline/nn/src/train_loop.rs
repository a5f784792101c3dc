//! The one training loop of the zoo: epochs or a time limit, shuffling with the one seeded
//! generator, a progress bar with the loss and throughput, validation every epoch, the best
//! checkpoint (run folder root) and the last one ([`LAST_DIR`]), `train_state.json`,
//! `summary.json`, the loss curve, a resume that continues exactly, and a stop on a NaN/inf loss
//! that keeps the last good checkpoint.
//!
//! A model plugs in through [`Trainable`]. An adversarial model (a generator and a critic, two
//! optimisers, several critic updates per generator update) fits it the same way: its
//! `train_step` runs one round of updates on the samples it is given (e.g. the critic's updates
//! then the generator's) and returns the loss it wants to track (e.g. the generator's);
//! `save_training_state` writes both optimisers (e.g. under name prefixes `generator.` and
//! `critic.` in one [`OPTIMIZER_FILE`], or two files) and `load_training_state` reads them back;
//! `validate` reports the loss it selects the best checkpoint on.
//!
//! Run folder: the best checkpoint at the root (`save_model(root, averaged)`, only when the
//! validation loss improves and is finite), `last/` every epoch (`save_model(last, false)`,
//! `save_training_state(last)` and a copy of `train_state.json`, replaced as a whole), then the
//! root `train_state.json`, the loss curve and, at the end, `summary.json`.

use crate::checkpoint::{self, CONFIG_FILE, LAST_DIR, LOSS_CURVE_FILE, SUMMARY_FILE, TRAIN_STATE_FILE};
use crate::error::TrainError;
use crate::rng::SplitMix64;
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Validation losses of one epoch.
#[derive(Clone, Debug, PartialEq)]
pub struct Validation {
    /// Loss of the trained weights.
    pub loss: f64,
    /// Loss of the averaged weights, for models that keep a moving average.
    pub averaged: Option<f64>,
    /// The loss's terms in words, printed after it (e.g. `skate 0.41 range 0.00`).
    pub detail: Option<String>,
}

/// A model the loop can train. Samples are indices `0..train_len()`; the loop shuffles them
/// each epoch and hands them out in batches of `batch_size()` (the last batch may be smaller).
pub trait Trainable {
    /// Training samples per epoch.
    fn train_len(&self) -> usize;
    /// Samples per batch.
    fn batch_size(&self) -> usize;
    /// One optimiser update (or one round of updates, for adversarial pairs) on these samples;
    /// returns the batch's mean loss. A NaN/inf loss should be returned as an error (or as the
    /// value) without updating the weights.
    fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError>;
    /// Optimiser steps taken so far.
    fn steps(&self) -> u64;
    /// Called after each epoch's training steps, before validation (e.g. a per-epoch
    /// learning-rate decay). Its effect must be part of the training state.
    fn end_epoch(&mut self) -> Result<(), TrainError> {
        Ok(())
    }
    /// Validation loss of the trained weights, and of the averaged weights if any. Must not
    /// draw from the model's random generators (or the resumed run would differ).
    fn validate(&mut self) -> Result<Validation, TrainError>;
    /// Writes a checkpoint the model can be rebuilt from: [`CONFIG_FILE`] naming the model,
    /// its weights (the averaged ones when `averaged`) and its statistics.
    fn save_model(&mut self, dir: &Path, averaged: bool) -> Result<(), TrainError>;
    /// Writes what continuing the run needs beyond `save_model`: optimiser(s), moving average,
    /// the states of the model's random generators.
    fn save_training_state(&self, dir: &Path) -> Result<(), TrainError>;
    /// Restores the weights and the training state from a folder written by `save_model(dir,
    /// false)` and `save_training_state(dir)`.
    fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError>;
    /// Model-specific fields of `summary.json` (e.g. `"model"`, parameter count).
    fn summary(&self) -> Map<String, Value>;
}

/// How to run the loop.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Run folder.
    pub out: PathBuf,
    /// Total epochs (a resumed run continues up to this number).
    pub epochs: usize,
    /// Stop once this much time has passed (checked before each epoch: the epoch in progress
    /// finishes first).
    pub time_limit: Option<Duration>,
    /// Seed of the epoch shuffles (the generator is saved every epoch; a resumed run continues it).
    pub seed: u64,
    /// Continue the run in `out` (its `last/` checkpoint and `train_state.json`).
    pub resume: bool,
    /// Where the data came from (recorded in `train_state.json` and `summary.json`).
    pub data: String,
    /// A digest of the training data (e.g. [`data_fingerprint`] of its values), recorded in
    /// `train_state.json`: a resume whose data digests differently is refused, so that a run
    /// never silently continues on other data. `None`: only the sample count is checked.
    pub data_fingerprint: Option<u64>,
    /// Extra fields recorded in `train_state.json` and `summary.json` of a fresh run.
    pub extra: Map<String, Value>,
    /// Show a progress bar (on stderr, hidden when it is not a terminal).
    pub progress: bool,
    /// Print one line per epoch on stdout.
    pub print: bool,
}

impl TrainOptions {
    /// Options for `epochs` epochs into `out` with `seed`, progress bar and epoch lines on.
    pub fn new(out: impl Into<PathBuf>, epochs: usize, seed: u64) -> Self {
        TrainOptions {
            out: out.into(),
            epochs,
            time_limit: None,
            seed,
            resume: false,
            data: String::new(),
            data_fingerprint: None,
            extra: Map::new(),
            progress: true,
            print: true,
        }
    }
}

/// Progress of a run, written every epoch (`train_state.json`, also in `last/`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct TrainState {
    /// Epochs completed.
    pub epoch: usize,
    /// Optimiser steps taken.
    pub steps: u64,
    /// Mean training loss per epoch.
    pub train_loss: Vec<f64>,
    /// Validation loss per epoch.
    pub valid_loss: Vec<f64>,
    /// Best validation loss so far (its weights are the run folder's checkpoint).
    pub best_valid: Option<f64>,
    /// Epoch of the best validation loss (1-based; 0 before the first).
    pub best_epoch: usize,
    /// Validation loss of the moving-average weights per epoch (models that keep one).
    #[serde(default)]
    pub valid_loss_ema: Vec<f64>,
    /// Whether the best checkpoint holds the moving-average weights.
    #[serde(default)]
    pub best_is_ema: bool,
    /// Seconds of training so far.
    pub seconds: f64,
    /// Training windows per second over the run.
    pub windows_per_second: f64,
    /// Where the data came from.
    #[serde(default)]
    pub data: String,
    /// Training samples per epoch (absent in runs written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_samples: Option<usize>,
    /// [`TrainOptions::data_fingerprint`] of the data the run started on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_fingerprint: Option<u64>,
    /// State of the shuffle generator after the last completed epoch (absent in runs written
    /// before it was saved: those resume with a generator reseeded from the epoch).
    #[serde(default)]
    pub shuffle_rng: Option<u64>,
    /// Other fields (e.g. the model variant), kept as they are.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// The folder a run in `out` resumes from: `out/last` (or the previous version left by an
/// interrupted save) when it holds a checkpoint, else `out` (runs written before `last/` existed).
pub fn resume_dir(out: &Path) -> PathBuf {
    let last = checkpoint::resolve_dir(&out.join(LAST_DIR));
    if last.join(CONFIG_FILE).is_file() { last } else { out.to_path_buf() }
}

/// Reads the progress of the run in `out` that a resume continues (the copy in `last/` first).
pub fn read_state(out: &Path) -> Result<TrainState, TrainError> {
    let inner = resume_dir(out).join(TRAIN_STATE_FILE);
    let path = if inner.is_file() { inner } else { out.join(TRAIN_STATE_FILE) };
    if !path.is_file() {
        return Err(TrainError::Config(format!(
            "{} has no {TRAIN_STATE_FILE}: it is not a run folder (start a new run with --out instead of --resume)",
            out.display()
        )));
    }
    Ok(checkpoint::read_json(&path)?)
}

/// A digest of training values (FNV-1a over their bits): the same data gives the same digest
/// on every run and machine, wherever its files are.
pub fn data_fingerprint(values: &[f32]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in values {
        h ^= u64::from(v.to_bits());
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h ^ values.len() as u64
}

/// Refuses to resume a run on data other than its own: another number of training samples,
/// or another [`TrainOptions::data_fingerprint`] (each checked where the run recorded it).
/// Runs written before the check record their sample count and digest from this resume on.
fn check_same_data(state: &mut TrainState, opts: &TrainOptions, n: usize) -> Result<(), TrainError> {
    let other_count = state.train_samples.is_some_and(|saved| saved != n);
    let other_digest = matches!((state.data_fingerprint, opts.data_fingerprint), (Some(a), Some(b)) if a != b);
    if other_count || other_digest {
        let saved = state.train_samples.map_or(String::new(), |s| format!(", {s} training samples"));
        return Err(TrainError::Config(format!(
            "{} was trained on other data ({}{saved}) than this resume loads ({}, {n} training samples{}): resume \
             with the data and options it was started with (the same --data, --valid-glob and --exclude-glob, or \
             the same --synth-minutes and --seed), or start a new run with --out",
            opts.out.display(),
            if state.data.is_empty() { "not recorded" } else { &state.data },
            if opts.data.is_empty() { "not described" } else { &opts.data },
            if other_digest && !other_count { ", the same count but other values" } else { "" },
        )));
    }
    state.train_samples.get_or_insert(n);
    if state.data_fingerprint.is_none() {
        state.data_fingerprint = opts.data_fingerprint;
    }
    Ok(())
}

fn kept(state: &TrainState, out: &Path) -> String {
    if state.epoch == 0 {
        "no checkpoint had been written yet".into()
    } else {
        format!(
            "the last good checkpoint is kept: {} (best: epoch {}) and {} (epoch {}) are untouched",
            out.display(),
            state.best_epoch,
            out.join(LAST_DIR).display(),
            state.epoch
        )
    }
}

/// The state and shuffle generator a run starts from: a resumed run's (its data checked, the
/// model's training state loaded), or a fresh one's.
fn start<M: Trainable + ?Sized>(
    model: &mut M,
    opts: &TrainOptions,
    n: usize,
) -> Result<(TrainState, SplitMix64), TrainError> {
    let out = &opts.out;
    if !opts.resume {
        let state = TrainState {
            data: opts.data.clone(),
            train_samples: Some(n),
            data_fingerprint: opts.data_fingerprint,
            extra: opts.extra.clone(),
            ..TrainState::default()
        };
        return Ok((state, SplitMix64::new(opts.seed)));
    }
    let mut state = read_state(out)?;
    check_same_data(&mut state, opts, n)?;
    model.load_training_state(&resume_dir(out))?;
    let rng = match state.shuffle_rng {
        Some(s) => SplitMix64::from_state(s),
        None => SplitMix64::new(opts.seed ^ (state.epoch as u64).wrapping_mul(0x9e37_79b9)),
    };
    Ok((state, rng))
}

/// One epoch's training steps over the shuffled samples; the summed loss and the samples seen.
fn train_epoch<M: Trainable + ?Sized>(
    model: &mut M,
    opts: &TrainOptions,
    state: &TrainState,
    order: &[usize],
    style: &ProgressStyle,
) -> Result<(f64, usize), TrainError> {
    let pb = if opts.progress { ProgressBar::new(order.len() as u64) } else { ProgressBar::hidden() };
    pb.set_style(style.clone());
    pb.set_prefix(format!("{}/{}", state.epoch + 1, opts.epochs));
    let epoch_start = Instant::now();
    let (mut sum, mut count) = (0.0, 0usize);
    for idx in order.chunks(model.batch_size()) {
        let loss = match model.train_step(idx) {
            Ok(l) if l.is_finite() => l,
            failed => {
                pb.abandon();
                let reason = match failed {
                    Ok(l) => format!("the training loss became {l}"),
                    Err(e) => e.to_string(),
                };
                let kept = kept(state, &opts.out);
                return Err(TrainError::Stopped { epoch: state.epoch + 1, step: model.steps(), reason, kept });
            }
        };
        sum += loss * idx.len() as f64;
        count += idx.len();
        pb.inc(idx.len() as u64);
        let wps = count as f64 / epoch_start.elapsed().as_secs_f64();
        pb.set_message(format!("loss {:.4}  {wps:.1} windows/s", sum / count as f64));
    }
    pb.finish_and_clear();
    Ok((sum, count))
}

/// Validates after an epoch, records it in `state` and writes the checkpoints: the best model
/// when it improved, `last/`, the state and the loss curve. Returns the validation and whether
/// the epoch is the best (and its averaged weights are).
fn end_epoch<M: Trainable + ?Sized>(
    model: &mut M,
    out: &Path,
    state: &mut TrainState,
    train_loss: f64,
) -> Result<(Validation, bool, bool), TrainError> {
    model.end_epoch()?;
    let v = model.validate()?;
    if !v.loss.is_finite() || v.averaged.is_some_and(|a| !a.is_finite()) {
        let averaged = v.averaged.map(|a| format!(", averaged weights {a}")).unwrap_or_default();
        return Err(TrainError::Stopped {
            epoch: state.epoch + 1,
            step: model.steps(),
            reason: format!("the validation loss became {}{averaged}", v.loss),
            kept: kept(state, out),
        });
    }
    let use_avg = v.averaged.is_some_and(|a| a < v.loss);
    let vbest = v.averaged.filter(|_| use_avg).unwrap_or(v.loss);
    state.epoch += 1;
    state.steps = model.steps();
    state.train_loss.push(train_loss);
    state.valid_loss.push(v.loss);
    if let Some(a) = v.averaged {
        state.valid_loss_ema.push(a);
    }
    let best = state.best_valid.is_none_or(|b| vbest < b);
    if best {
        let _writing = crate::run_folder::checkpoint_writing();
        model.save_model(out, use_avg)?;
        state.best_valid = Some(vbest);
        state.best_epoch = state.epoch;
        state.best_is_ema = use_avg;
    }
    Ok((v, best, use_avg))
}

/// Writes `last/` (the model and its training state) and the run's state and loss curve.
fn write_epoch<M: Trainable + ?Sized>(model: &mut M, out: &Path, state: &TrainState) -> Result<(), TrainError> {
    let _writing = crate::run_folder::checkpoint_writing();
    checkpoint::replace_dir(&out.join(LAST_DIR), |dir| -> Result<(), TrainError> {
        model.save_model(dir, false)?;
        model.save_training_state(dir)?;
        Ok(checkpoint::write_json(&dir.join(TRAIN_STATE_FILE), state)?)
    })?;
    checkpoint::write_json(&out.join(TRAIN_STATE_FILE), state)?;
    crate::plot::loss_curve(&out.join(LOSS_CURVE_FILE), &state.train_loss, &state.valid_loss)?;
    crate::run_folder::epoch_done(out);
    Ok(())
}

/// `summary.json`: the model's fields, the run's extra fields and the loop's.
fn write_summary<M: Trainable + ?Sized>(model: &M, out: &Path, state: &TrainState) -> Result<(), TrainError> {
    let mut summary = model.summary();
    for (k, v) in &state.extra {
        summary.entry(k.clone()).or_insert_with(|| v.clone());
    }
    let loop_fields = serde_json::json!({
        "data": state.data,
        "epochs": state.epoch,
        "steps": state.steps,
        "best_epoch": state.best_epoch,
        "best_valid_loss": state.best_valid,
        "best_is_moving_average": state.best_is_ema,
        "final_train_loss": state.train_loss.last(),
        "seconds": state.seconds,
        "windows_per_second": state.windows_per_second,
    });
    if let Value::Object(fields) = loop_fields {
        summary.extend(fields);
    }
    Ok(checkpoint::write_json(&out.join(SUMMARY_FILE), &summary)?)
}

/// Trains `model` as `opts` says; returns the run's final state. See the module docs.
pub fn train<M: Trainable + ?Sized>(model: &mut M, opts: &TrainOptions) -> Result<TrainState, TrainError> {
    let out = &opts.out;
    std::fs::create_dir_all(out).map_err(checkpoint::io(out))?;
    let n = model.train_len();
    let batch = model.batch_size();
    if n == 0 || batch == 0 {
        return Err(TrainError::Config(format!("nothing to train on: {n} training samples, batch size {batch}")));
    }
    let (mut state, mut rng) = start(model, opts, n)?;
    let started = Instant::now();
    let seconds_before = state.seconds;
    let style = ProgressStyle::with_template("epoch {prefix} [{bar:30}] {pos}/{len} windows  {msg}  {elapsed}<{eta}")
        .map_err(|e| TrainError::Config(format!("progress bar template: {e}")))?;
    while state.epoch < opts.epochs {
        if let Some(limit) = opts.time_limit
            && started.elapsed() >= limit
        {
            if opts.print {
                println!("time limit of {} min reached after {} epochs", limit.as_secs_f64() / 60.0, state.epoch);
            }
            break;
        }
        let mut order: Vec<usize> = (0..n).collect();
        rng.shuffle(&mut order);
        let epoch_start = Instant::now();
        let (sum, count) = train_epoch(model, opts, &state, &order, &style)?;
        let epoch_secs = epoch_start.elapsed().as_secs_f64();
        let (v, best, use_avg) = end_epoch(model, out, &mut state, sum / count as f64)?;
        state.seconds = seconds_before + started.elapsed().as_secs_f64();
        state.windows_per_second = (state.epoch * n) as f64 / state.seconds;
        state.shuffle_rng = Some(rng.state());
        write_epoch(model, out, &state)?;
        if opts.print {
            println!(
                "epoch {:>3}: train loss {:.5}  valid loss {:.5}{}{}{}  {:.1} windows/s  {:.0} s",
                state.epoch,
                sum / count as f64,
                v.loss,
                v.detail.as_ref().map(|d| format!(" ({d})")).unwrap_or_default(),
                v.averaged.map(|a| format!("  averaged {a:.5}")).unwrap_or_default(),
                if best { if use_avg { " (best: averaged)" } else { " (best)" } } else { "" },
                n as f64 / epoch_secs,
                epoch_secs
            );
        }
    }
    if state.epoch == 0 {
        return Err(TrainError::Config(format!(
            "no epoch was trained ({} epochs asked, time limit {:?}): {} holds no model; ask for at least one \
             epoch and a positive time limit",
            opts.epochs,
            opts.time_limit,
            out.display()
        )));
    }
    write_summary(model, out, &state)?;
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checkpoint::{EMA_FILE, OPTIMIZER_FILE, RNG_FILE, WEIGHTS_FILE};
    use crate::ema::Ema;
    use crate::init::SeededVarMap;
    use crate::optim::{Adam, ParamsAdam, StatefulOptimizer};
    use candle_core::{DType, Device, Tensor, Var};
    use candle_nn::{Init, Optimizer, VarMap};

    /// Linear regression `y = x . w + b` on fixed data, with Adam, a moving average and a
    /// model generator (noise added to the targets of each batch), so that every piece of
    /// training state matters for an exact resume.
    struct Toy {
        varmap: VarMap,
        w: Var,
        b: Var,
        opt: Adam,
        ema: Ema,
        rng: SplitMix64,
        x: Vec<[f64; 3]>,
        y: Vec<f64>,
        nan_at_step: Option<u64>,
        bad_validation: Option<f64>,
        sleep: Duration,
        train_len: usize,
    }

    impl Toy {
        fn new(seed: u64) -> Self {
            let varmap = VarMap::new();
            let vb = SeededVarMap::builder(&varmap, seed, DType::F64, &Device::Cpu);
            vb.get_with_hints(3, "w", Init::Randn { mean: 0.0, stdev: 1.0 }).unwrap();
            vb.get_with_hints(1, "b", Init::Const(0.0)).unwrap();
            let mut named: Vec<(String, Var)> =
                varmap.data().lock().unwrap().iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            named.sort_by(|a, b| a.0.cmp(&b.0));
            let get = |n: &str| named.iter().find(|(k, _)| k == n).unwrap().1.clone();
            let (w, b) = (get("w"), get("b"));
            let opt = Adam::new_named(named.clone(), ParamsAdam { lr: 0.05, ..ParamsAdam::default() }).unwrap();
            let ema = Ema::new(named, 0.9).unwrap();
            let mut data = SplitMix64::new(99);
            let x: Vec<[f64; 3]> = (0..40).map(|_| [data.normal(), data.normal(), data.normal()]).collect();
            let y = x.iter().map(|v| 2.0 * v[0] - v[1] + 0.5 * v[2] + 1.0).collect();
            Toy {
                varmap,
                w,
                b,
                opt,
                ema,
                rng: SplitMix64::new(seed),
                x,
                y,
                nan_at_step: None,
                bad_validation: None,
                sleep: Duration::ZERO,
                train_len: 30,
            }
        }

        fn loss(&self, idx: &[usize], noise: &[f64]) -> candle_core::Result<Tensor> {
            let x: Vec<f64> = idx.iter().flat_map(|&i| self.x[i]).collect();
            let y: Vec<f64> = idx.iter().zip(noise).map(|(&i, n)| self.y[i] + n).collect();
            let x = Tensor::from_vec(x, (idx.len(), 3), &Device::Cpu)?;
            let y = Tensor::from_vec(y, idx.len(), &Device::Cpu)?;
            let pred = x.matmul(&self.w.as_tensor().unsqueeze(1)?)?.squeeze(1)?.broadcast_add(self.b.as_tensor())?;
            (pred - y)?.sqr()?.mean_all()
        }

        fn valid_loss(&self) -> f64 {
            let idx: Vec<usize> = (30..40).collect();
            self.loss(&idx, &[0.0; 10]).unwrap().to_scalar::<f64>().unwrap()
        }
    }

    impl Trainable for Toy {
        fn train_len(&self) -> usize {
            self.train_len
        }
        fn batch_size(&self) -> usize {
            7
        }
        fn train_step(&mut self, samples: &[usize]) -> Result<f64, TrainError> {
            std::thread::sleep(self.sleep);
            if self.nan_at_step == Some(self.opt.steps()) {
                return Ok(f64::NAN);
            }
            let noise: Vec<f64> = samples.iter().map(|_| 0.1 * self.rng.normal()).collect();
            let loss = self.loss(samples, &noise).map_err(crate::NnError::from)?;
            self.opt.backward_step(&loss).map_err(crate::NnError::from)?;
            self.ema.update(self.opt.steps())?;
            Ok(loss.to_scalar::<f64>().map_err(crate::NnError::from)?)
        }
        fn steps(&self) -> u64 {
            self.opt.steps()
        }
        fn validate(&mut self) -> Result<Validation, TrainError> {
            let loss = self.bad_validation.unwrap_or_else(|| self.valid_loss());
            let trained = self.ema.swap_in()?;
            let averaged = self.valid_loss();
            self.ema.swap_out(trained)?;
            Ok(Validation { loss, averaged: Some(averaged), detail: None })
        }
        fn save_model(&mut self, dir: &Path, averaged: bool) -> Result<(), TrainError> {
            let trained = if averaged { Some(self.ema.swap_in()?) } else { None };
            let saved = checkpoint::write_varmap(&dir.join(WEIGHTS_FILE), &self.varmap);
            if let Some(t) = trained {
                self.ema.swap_out(t)?;
            }
            saved?;
            Ok(checkpoint::write_json(&dir.join(CONFIG_FILE), &serde_json::json!({"model": "toy"}))?)
        }
        fn save_training_state(&self, dir: &Path) -> Result<(), TrainError> {
            checkpoint::write_tensors(&dir.join(OPTIMIZER_FILE), &self.opt.state()?)?;
            checkpoint::write_tensors(&dir.join(EMA_FILE), &self.ema.state())?;
            Ok(checkpoint::write_json(&dir.join(RNG_FILE), &serde_json::json!({"model": self.rng.state()}))?)
        }
        fn load_training_state(&mut self, dir: &Path) -> Result<(), TrainError> {
            checkpoint::read_varmap(&dir.join(WEIGHTS_FILE), &self.varmap)?;
            self.opt.set_state(&checkpoint::read_tensors(&dir.join(OPTIMIZER_FILE), &Device::Cpu)?)?;
            self.ema.set_state(&checkpoint::read_tensors(&dir.join(EMA_FILE), &Device::Cpu)?)?;
            let rng: Value = checkpoint::read_json(&dir.join(RNG_FILE))?;
            self.rng = SplitMix64::from_state(rng["model"].as_u64().unwrap());
            Ok(())
        }
        fn summary(&self) -> Map<String, Value> {
            let mut m = Map::new();
            m.insert("model".into(), "toy".into());
            m
        }
    }

    fn opts(out: &Path, epochs: usize) -> TrainOptions {
        TrainOptions { progress: false, print: false, ..TrainOptions::new(out, epochs, 3) }
    }

    fn bytes(p: PathBuf) -> Vec<u8> {
        std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    #[test]
    fn four_epochs_equal_two_plus_a_resumed_two() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        let whole = train(&mut Toy::new(1), &opts(&a, 4)).unwrap();
        let first = train(&mut Toy::new(1), &opts(&b, 2)).unwrap();
        assert_eq!(first.epoch, 2);
        let resumed = train(&mut Toy::new(1), &TrainOptions { resume: true, ..opts(&b, 4) }).unwrap();
        assert_eq!(resumed.epoch, 4);
        assert_eq!(resumed.steps, whole.steps);
        assert_eq!(resumed.train_loss, whole.train_loss);
        assert_eq!(resumed.valid_loss, whole.valid_loss);
        assert_eq!(resumed.valid_loss_ema, whole.valid_loss_ema);
        assert_eq!(resumed.shuffle_rng, whole.shuffle_rng);
        assert_eq!((resumed.best_epoch, resumed.best_is_ema), (whole.best_epoch, whole.best_is_ema));
        for f in [WEIGHTS_FILE, "last/model.safetensors", "last/optimizer.safetensors", "last/ema.safetensors"] {
            assert_eq!(bytes(a.join(f)), bytes(b.join(f)), "{f}");
        }
        assert!(whole.train_loss[3] < whole.train_loss[0], "the toy learns: {:?}", whole.train_loss);
        for f in [SUMMARY_FILE, LOSS_CURVE_FILE, TRAIN_STATE_FILE, "last/train_state.json", "last/rng.json"] {
            assert!(a.join(f).is_file(), "{f}");
        }
        let summary: Value = checkpoint::read_json(&a.join(SUMMARY_FILE)).unwrap();
        assert_eq!((summary["model"].as_str(), summary["epochs"].as_u64()), (Some("toy"), Some(4)));
        let names: Vec<String> =
            std::fs::read_dir(&a).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        assert!(names.iter().all(|n| !n.starts_with('.')), "temporary files left: {names:?}");
    }

    #[test]
    fn a_resume_on_other_data_is_refused_and_touches_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        let with = |fp: u64, epochs: usize| TrainOptions {
            data: format!("data {fp}"),
            data_fingerprint: Some(fp),
            ..opts(&out, epochs)
        };
        train(&mut Toy::new(1), &with(7, 1)).unwrap();
        let state = bytes(out.join(TRAIN_STATE_FILE));
        let fewer = Toy { train_len: 20, ..Toy::new(1) };
        let err = train(&mut { fewer }, &TrainOptions { resume: true, ..with(7, 2) }).unwrap_err().to_string();
        assert!(err.contains("trained on other data (data 7, 30 training samples)"), "{err}");
        assert!(err.contains("(data 7, 20 training samples)") && err.contains("--synth-minutes"), "{err}");
        let err = train(&mut Toy::new(1), &TrainOptions { resume: true, ..with(8, 2) }).unwrap_err().to_string();
        assert!(err.contains("the same count but other values"), "{err}");
        assert_eq!(bytes(out.join(TRAIN_STATE_FILE)), state, "a refused resume writes nothing");
        let resumed = train(&mut Toy::new(1), &TrainOptions { resume: true, ..with(7, 2) }).unwrap();
        assert_eq!((resumed.epoch, resumed.train_samples, resumed.data_fingerprint), (2, Some(30), Some(7)));

        // A run written before the check records its count on the first resume, then holds to it.
        let mut old: Value = checkpoint::read_json(&out.join("last").join(TRAIN_STATE_FILE)).unwrap();
        let o = old.as_object_mut().unwrap();
        o.remove("train_samples");
        o.remove("data_fingerprint");
        checkpoint::write_json(&out.join("last").join(TRAIN_STATE_FILE), &old).unwrap();
        let fewer = Toy { train_len: 20, ..Toy::new(1) };
        let resumed =
            train(&mut { fewer }, &TrainOptions { resume: true, data_fingerprint: None, ..with(7, 3) }).unwrap();
        assert_eq!((resumed.epoch, resumed.train_samples, resumed.data_fingerprint), (3, Some(20), None));
        let err = train(&mut Toy::new(1), &TrainOptions { resume: true, ..with(7, 4) }).unwrap_err().to_string();
        assert!(err.contains("20 training samples") && err.contains("30 training samples"), "{err}");
    }

    #[test]
    fn data_fingerprints_tell_values_and_lengths_apart() {
        let a = data_fingerprint(&[1.0, 2.0, 3.0]);
        assert_eq!(a, data_fingerprint(&[1.0, 2.0, 3.0]));
        assert_ne!(a, data_fingerprint(&[1.0, 2.0, 3.5]));
        assert_ne!(a, data_fingerprint(&[1.0, 3.0, 2.0]));
        assert_ne!(data_fingerprint(&[]), data_fingerprint(&[0.0]));
    }

    #[test]
    fn a_nan_loss_stops_and_keeps_the_best_checkpoint() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        let before = train(&mut Toy::new(2), &opts(&out, 2)).unwrap();
        let (weights, state) = (bytes(out.join(WEIGHTS_FILE)), bytes(out.join(TRAIN_STATE_FILE)));
        let last = bytes(out.join("last/model.safetensors"));
        let mut toy = Toy::new(2);
        toy.nan_at_step = Some(before.steps + 3);
        let err = train(&mut toy, &TrainOptions { resume: true, ..opts(&out, 5) }).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, TrainError::Stopped { epoch: 3, .. }), "{msg}");
        assert!(msg.contains("NaN") && msg.contains("last good checkpoint is kept"), "{msg}");
        assert_eq!(bytes(out.join(WEIGHTS_FILE)), weights);
        assert_eq!(bytes(out.join(TRAIN_STATE_FILE)), state);
        assert_eq!(bytes(out.join("last/model.safetensors")), last);
        // A NaN validation loss stops the run too, and is not recorded as the best.
        let mut toy = Toy::new(2);
        toy.bad_validation = Some(f64::NAN);
        let err = train(&mut toy, &TrainOptions { resume: true, ..opts(&out, 5) }).unwrap_err().to_string();
        assert!(err.contains("validation loss became NaN") && err.contains("best: epoch"), "{err}");
        assert_eq!(bytes(out.join(WEIGHTS_FILE)), weights);
        let kept: TrainState = checkpoint::read_json(&out.join(TRAIN_STATE_FILE)).unwrap();
        assert_eq!((kept.epoch, kept.best_epoch), (2, before.best_epoch));
        // Before any checkpoint, the message says so.
        let mut toy = Toy::new(2);
        toy.nan_at_step = Some(0);
        let err = train(&mut toy, &opts(&dir.path().join("fresh"), 1)).unwrap_err().to_string();
        assert!(err.contains("no checkpoint had been written yet"), "{err}");
        assert!(!dir.path().join("fresh").join(WEIGHTS_FILE).exists());
    }

    #[test]
    fn an_infinite_validation_loss_is_divergence_and_the_run_resumes() {
        let dir = tempfile::tempdir().unwrap();
        let (out, whole) = (dir.path().join("run"), dir.path().join("whole"));
        let uninterrupted = train(&mut Toy::new(4), &opts(&whole, 3)).unwrap();
        let before = train(&mut Toy::new(4), &opts(&out, 2)).unwrap();
        let weights = bytes(out.join(WEIGHTS_FILE));
        let mut toy = Toy::new(4);
        toy.bad_validation = Some(f64::INFINITY);
        let err = train(&mut toy, &TrainOptions { resume: true, ..opts(&out, 3) }).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, TrainError::Stopped { epoch: 3, .. }), "{msg}");
        assert!(msg.contains("validation loss became inf") && msg.contains("last good checkpoint is kept"), "{msg}");
        assert_eq!(bytes(out.join(WEIGHTS_FILE)), weights, "an inf loss is never the best checkpoint");
        let kept: TrainState = checkpoint::read_json(&out.join(TRAIN_STATE_FILE)).unwrap();
        assert_eq!((kept.epoch, kept.best_epoch, kept.best_valid), (2, before.best_epoch, before.best_valid));
        // The kept checkpoint resumes, and ends where an uninterrupted run ends.
        let resumed = train(&mut Toy::new(4), &TrainOptions { resume: true, ..opts(&out, 3) }).unwrap();
        assert_eq!(resumed.valid_loss, uninterrupted.valid_loss);
        assert!(resumed.best_valid.unwrap().is_finite());
        assert_eq!(bytes(out.join("last/model.safetensors")), bytes(whole.join("last/model.safetensors")));
    }

    #[test]
    fn a_run_that_trains_no_epoch_says_so_and_claims_no_model() {
        let dir = tempfile::tempdir().unwrap();
        let o = TrainOptions { time_limit: Some(Duration::ZERO), ..opts(dir.path(), 3) };
        let err = train(&mut Toy::new(5), &o).unwrap_err().to_string();
        assert!(err.contains("no epoch was trained") && err.contains("holds no model"), "{err}");
        assert!(!dir.path().join(SUMMARY_FILE).exists() && !dir.path().join(WEIGHTS_FILE).exists());
        let err = train(&mut Toy::new(5), &opts(&dir.path().join("zero"), 0)).unwrap_err().to_string();
        assert!(err.contains("no epoch was trained (0 epochs asked"), "{err}");
    }

    #[test]
    fn a_time_limit_stops_between_epochs() {
        let dir = tempfile::tempdir().unwrap();
        let mut toy = Toy::new(3);
        toy.sleep = Duration::from_millis(10);
        let o = TrainOptions { time_limit: Some(Duration::from_millis(120)), ..opts(dir.path(), 1000) };
        let state = train(&mut toy, &o).unwrap();
        assert!(state.epoch >= 1 && state.epoch < 20, "{} epochs", state.epoch);
        assert!(dir.path().join(SUMMARY_FILE).is_file());
        let err = train(&mut Toy::new(3), &TrainOptions { resume: true, ..opts(&dir.path().join("none"), 2) });
        assert!(err.unwrap_err().to_string().contains("not a run folder"));
    }
}
