//! `zoo train ...`: train a model of the zoo on BVH data or on the embedded synthetic data.

use crate::plot;
use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;
use zoo_data::dataset::{self, NamedClip, WindowOptions};
use zoo_data::synth::{self, SynthConfig};
use zoo_rtn::prelude::*;
use zoo_rtn::train::SplitMix64;

/// `zoo train` subcommands.
#[derive(Subcommand)]
pub enum TrainCommand {
    /// The Recurrent Transition Network (Harvey & Pal 2018).
    Rtn(RtnArgs),
}

/// Which RTN to train: the paper's model or one of its Table 4 ablations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RtnVariant {
    /// The paper's RTN (future conditioning, learned initial state, residual, p = 0.2).
    Rtn,
    /// RTN\FUTURE: no target/offset conditioning of the LSTM.
    NoFuture,
    /// RTN\H0: zero initial LSTM state.
    H0,
    /// RTN\HCOMMON: one learned initial state for all sequences.
    Hcommon,
    /// RTN\RESNET: the decoder predicts the next frame directly.
    NoResidual,
    /// Teacher forcing never (p = 0).
    Tf0,
    /// Teacher forcing always (p = 1).
    Tf1,
    /// Scheduled teacher forcing: p falls from 1 to 0 over the run.
    TfScheduled,
}

/// Arguments of `zoo train rtn`.
#[derive(Args)]
pub struct RtnArgs {
    /// BVH file or folder to train on; without it, synthetic locomotion generated in memory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the validation split of `--data` (best checkpoint).
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// Epochs to train (an epoch visits every training window once).
    #[arg(long, default_value_t = 10)]
    pub epochs: usize,
    /// Stop after this many minutes of training (the epoch in progress finishes first).
    #[arg(long)]
    pub time_limit: Option<f64>,
    /// Run folder: config, weights, statistics, loss curve and summary.
    #[arg(long, default_value = "runs/rtn")]
    pub out: PathBuf,
    /// Continue the run in this folder (its config is kept; `--epochs` is the new total).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Model variant (Table 4 ablations).
    #[arg(long, value_enum, default_value_t = RtnVariant::Rtn)]
    pub variant: RtnVariant,
    /// Mini-batch size (paper: 32).
    #[arg(long, default_value_t = 32)]
    pub batch_size: usize,
    /// AMSGrad learning rate (paper: 5e-4).
    #[arg(long, default_value_t = 5e-4)]
    pub lr: f64,
    /// Minutes of synthetic motion when `--data` is not given.
    #[arg(long, default_value_t = 10.0)]
    pub synth_minutes: f64,
    /// Seed of the synthetic data and of the trainer.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Decay of a moving average of the weights kept beside the trained ones (not in the
    /// paper). Each epoch both are validated and the better one becomes the best checkpoint;
    /// 0 keeps no average (the paper's recipe exactly).
    #[arg(long, default_value_t = 0.999)]
    pub ema: f64,
}

/// Runs a `zoo train` subcommand.
pub fn run(cmd: TrainCommand) -> anyhow::Result<()> {
    match cmd {
        TrainCommand::Rtn(a) => train_rtn(a),
    }
}

/// Progress of a run, written beside the checkpoints so `--resume` can continue it.
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
    /// Best validation loss so far (its weights are the run folder's `model.safetensors`).
    pub best_valid: Option<f64>,
    /// Epoch of the best validation loss (1-based).
    pub best_epoch: usize,
    /// Validation loss of the moving-average weights per epoch (runs that keep one).
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
    pub data: String,
    /// The variant trained.
    pub variant: Option<RtnVariant>,
}

const STATE_FILE: &str = "train_state.json";
const LAST_DIR: &str = "last";

/// Training and validation clips: `--data` split by `--valid-glob`, or synthetic clips with
/// every tenth clip held out.
pub fn load_clips(
    data: &Option<PathBuf>,
    valid_glob: &Option<String>,
    minutes: f64,
    seed: u64,
) -> anyhow::Result<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    match data {
        Some(path) => {
            let clips = dataset::load(path).with_context(|| format!("loading {}", path.display()))?;
            let Some(glob) = valid_glob else {
                bail!("--data needs --valid-glob GLOB to choose the validation clips (bandai2: '*_youthful_*')")
            };
            let (train, valid) = dataset::split(clips, glob)?;
            Ok((train, valid, format!("{} (validation: {glob})", path.display())))
        }
        None => {
            let cfg = SynthConfig { minutes, seed, terrain: false, ..SynthConfig::default() };
            let clips = synth::generate(&cfg);
            let (mut train, mut valid) = (Vec::new(), Vec::new());
            for (i, c) in clips.into_iter().enumerate() {
                let named = NamedClip { path: PathBuf::from(&c.name), name: c.name, clip: c.clip };
                if i % 10 == 9 { valid.push(named) } else { train.push(named) }
            }
            Ok((train, valid, format!("synthetic locomotion, {minutes} min, seed {seed}")))
        }
    }
}

fn apply_variant(config: &mut Config, v: RtnVariant, total_steps: u64) {
    match v {
        RtnVariant::Rtn => {}
        RtnVariant::NoFuture => config.future_conditioning = false,
        RtnVariant::H0 => config.init_state = InitState::Zero,
        RtnVariant::Hcommon => config.init_state = InitState::Common,
        RtnVariant::NoResidual => config.residual = false,
        RtnVariant::Tf0 => config.train.teacher_forcing = TeacherForcing::Fixed(0.0),
        RtnVariant::Tf1 => config.train.teacher_forcing = TeacherForcing::Fixed(1.0),
        RtnVariant::TfScheduled => config.train.teacher_forcing = TeacherForcing::Scheduled { steps: total_steps },
    }
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> anyhow::Result<T> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a valid file of this zoo version", path.display()))
}

/// Writes `value` as JSON to `path` through a temporary file and a rename.
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> anyhow::Result<()> {
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(value)?).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Mean validation loss over `windows`, in batches of 64.
fn valid_loss(trainer: &mut RtnTrainer, windows: &[MotionWindow]) -> RtnResult<f64> {
    let mut sum = 0.0;
    for c in windows.chunks(64) {
        sum += trainer.eval_loss(c)? as f64 * c.len() as f64;
    }
    Ok(sum / windows.len() as f64)
}

fn train_rtn(a: RtnArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    let out = a.resume.clone().unwrap_or_else(|| a.out.clone());
    let (train, valid, source) = load_clips(&a.data, &a.valid_glob, a.synth_minutes, a.seed)?;
    let tw = dataset::windows(&train, &WindowOptions::TRAIN);
    let vw = dataset::windows(&valid, &WindowOptions::TRAIN);
    if tw.count == 0 || vw.count == 0 {
        bail!("need at least one 50-frame window in both splits (training {}, validation {})", tw.count, vw.count);
    }
    let d = tw.joints() * 3;
    let per = tw.window * d;
    let train_pos = tw.global_positions_f32();
    let valid_pos = vw.global_positions_f32();
    let train_windows: Vec<MotionWindow> = train_pos.chunks_exact(per).map(MotionWindow::new).collect();
    let valid_windows: Vec<MotionWindow> = valid_pos.chunks_exact(per).map(MotionWindow::new).collect();
    let steps_per_epoch = train_windows.len().div_ceil(a.batch_size) as u64;

    let (mut trainer, mut state) = match &a.resume {
        Some(dir) => {
            let last = dir.join(LAST_DIR);
            let from = if last.join(zoo_rtn::checkpoint::CONFIG_FILE).is_file() { last } else { dir.clone() };
            let (trainer, restored) = RtnTrainer::load_with_optimizer(&from, &device)
                .with_context(|| format!("resuming from {}", from.display()))?;
            if !restored {
                println!(
                    "note: {} has no optimiser state (written by an older zoo): AMSGrad restarts from zero moments, \
                     which perturbs the first epochs",
                    from.display()
                );
            }
            if trainer.config().joints != tw.joints() {
                bail!(
                    "{} holds a model for {} joints but the data has {}: resume with the data it was trained on",
                    dir.display(),
                    trainer.config().joints,
                    tw.joints()
                );
            }
            let state: TrainState = read_json(&dir.join(STATE_FILE))?;
            (trainer, state)
        }
        None => {
            let mut config = Config::paper().with_parents(&tw.skeleton.parents);
            config.train.batch_size = a.batch_size;
            config.train.learning_rate = a.lr;
            config.train.seed = a.seed;
            if !(0.0..1.0).contains(&a.ema) {
                bail!(
                    "--ema {} is not a decay in [0, 1) (0.999 averages over about 1000 steps; 0 turns it off)",
                    a.ema
                );
            }
            config.train.ema_decay = (a.ema > 0.0).then_some(a.ema);
            apply_variant(&mut config, a.variant, steps_per_epoch * a.epochs as u64);
            let stats = fit_stats(&config, &train_windows)?;
            let trainer = RtnTrainer::new(&config, stats, &device)?;
            let state = TrainState { data: source.clone(), variant: Some(a.variant), ..TrainState::default() };
            (trainer, state)
        }
    };
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    println!(
        "training RTN ({:?}) on {source}: {} training / {} validation windows, {} parameters, run folder {}",
        state.variant.unwrap_or(a.variant),
        train_windows.len(),
        valid_windows.len(),
        trainer.model().parameter_count(),
        out.display()
    );
    let batch = trainer.config().train.batch_size;
    let mut rng = SplitMix64::new(a.seed ^ (state.epoch as u64).wrapping_mul(0x9e37_79b9));
    let started = Instant::now();
    let seconds_before = state.seconds;
    while state.epoch < a.epochs {
        if let Some(limit) = a.time_limit {
            if started.elapsed().as_secs_f64() / 60.0 >= limit {
                println!("time limit of {limit} min reached after {} epochs", state.epoch);
                break;
            }
        }
        let mut order: Vec<usize> = (0..train_windows.len()).collect();
        for i in (1..order.len()).rev() {
            order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
        }
        let pb = ProgressBar::new(train_windows.len() as u64);
        pb.set_style(ProgressStyle::with_template(
            "epoch {prefix} [{bar:30}] {pos}/{len} windows  {msg}  {elapsed}<{eta}",
        )?);
        pb.set_prefix(format!("{}/{}", state.epoch + 1, a.epochs));
        let epoch_start = Instant::now();
        let (mut sum, mut n) = (0.0, 0usize);
        let mut chunk = Vec::with_capacity(batch);
        for idx in order.chunks(batch) {
            chunk.clear();
            chunk.extend(idx.iter().map(|&i| train_windows[i]));
            let loss = match trainer.train_step(&chunk) {
                Ok(l) => l,
                Err(e) => {
                    pb.abandon();
                    let kept = if state.epoch > 0 {
                        format!("the checkpoints in {} (best: epoch {}) are untouched", out.display(), state.best_epoch)
                    } else {
                        "no checkpoint had been written yet".to_string()
                    };
                    bail!("training stopped in epoch {} at step {}: {e} ({kept})", state.epoch + 1, trainer.steps());
                }
            };
            sum += loss as f64 * chunk.len() as f64;
            n += chunk.len();
            pb.inc(chunk.len() as u64);
            let wps = n as f64 / epoch_start.elapsed().as_secs_f64();
            pb.set_message(format!("loss {:.4}  {wps:.1} windows/s", sum / n as f64));
        }
        pb.finish_and_clear();
        let epoch_secs = epoch_start.elapsed().as_secs_f64();
        let vloss = valid_loss(&mut trainer, &valid_windows)?;
        let vloss_ema = if trainer.has_ema() {
            let v = trainer.with_ema_weights(|t| valid_loss(t, &valid_windows))?;
            state.valid_loss_ema.push(v);
            Some(v)
        } else {
            None
        };
        let use_ema = vloss_ema.is_some_and(|v| v < vloss);
        let vbest = vloss_ema.filter(|_| use_ema).unwrap_or(vloss);
        state.epoch += 1;
        state.steps = trainer.steps();
        state.train_loss.push(sum / n as f64);
        state.valid_loss.push(vloss);
        state.seconds = seconds_before + started.elapsed().as_secs_f64();
        state.windows_per_second = (state.epoch * train_windows.len()) as f64 / state.seconds;
        let best = state.best_valid.is_none_or(|b| vbest < b);
        if best {
            if use_ema {
                trainer.with_ema_weights(|t| t.save(&out))?;
            } else {
                trainer.save(&out)?;
            }
            state.best_valid = Some(vbest);
            state.best_epoch = state.epoch;
            state.best_is_ema = use_ema;
        }
        trainer.save_with_optimizer(&out.join(LAST_DIR))?;
        write_json_atomic(&out.join(STATE_FILE), &state)?;
        plot::loss_curve(&out.join("loss_curve.png"), &state.train_loss, &state.valid_loss)?;
        println!(
            "epoch {:>3}: train loss {:.5}  valid loss {:.5}{}{}  {:.1} windows/s  {:.0} s",
            state.epoch,
            sum / n as f64,
            vloss,
            vloss_ema.map(|v| format!("  averaged {v:.5}")).unwrap_or_default(),
            if best { if use_ema { " (best: averaged)" } else { " (best)" } } else { "" },
            train_windows.len() as f64 / epoch_secs,
            epoch_secs
        );
    }
    let summary = serde_json::json!({
        "model": "rtn",
        "variant": state.variant,
        "data": state.data,
        "epochs": state.epoch,
        "steps": state.steps,
        "best_epoch": state.best_epoch,
        "best_valid_loss": state.best_valid,
        "best_is_moving_average": state.best_is_ema,
        "ema_decay": trainer.config().train.ema_decay,
        "final_train_loss": state.train_loss.last(),
        "seconds": state.seconds,
        "windows_per_second": state.windows_per_second,
        "parameters": trainer.model().parameter_count(),
    });
    write_json_atomic(&out.join("summary.json"), &summary)?;
    println!(
        "done: {} epochs in {:.1} min, best valid loss {:.5} at epoch {}; model in {}",
        state.epoch,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        out.display()
    );
    Ok(())
}
