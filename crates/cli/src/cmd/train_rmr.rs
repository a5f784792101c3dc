//! `zoo train rmr`: train the Recurrent Motion Refiner (Kim et al. 2023) on BVH data or on the
//! embedded synthetic locomotion. The training pairs (RMR sec. 4) are generated first; their
//! plans (the KNN searches, the slow part) are cached in the run folder and reused when the
//! same clips and configuration come back (a resume, or `--overwrite` on the same data).

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::{Duration, Instant};
use zoo_data::synth::SynthConfig;
use zoo_nn::checkpoint;
use zoo_nn::train_loop::{self, TrainOptions};
use zoo_rmr::pairs::{MotionSet, StitchLayout};
use zoo_rmr::prelude::*;

/// Sizes of the RMR to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RmrPreset {
    /// The paper's sizes (`Config::paper`: encoder 256, BGRU 2 x 256, T = 60 frames).
    Paper,
    /// A small model for tests and quick checks (`Config::tiny`: 30-frame windows).
    Tiny,
}

/// The refiner cell (RMR Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CellArg {
    /// Unidirectional LSTM.
    Lstm,
    /// Unidirectional GRU.
    Gru,
    /// Bidirectional LSTM.
    Blstm,
    /// Bidirectional GRU (the paper's).
    Bgru,
}

impl From<CellArg> for RefinerCell {
    fn from(c: CellArg) -> RefinerCell {
        match c {
            CellArg::Lstm => RefinerCell::Lstm,
            CellArg::Gru => RefinerCell::Gru,
            CellArg::Blstm => RefinerCell::Blstm,
            CellArg::Bgru => RefinerCell::Bgru,
        }
    }
}

/// Arguments of `zoo train rmr`.
#[derive(Args)]
pub struct RmrArgs {
    /// BVH file or folder to train on; without it, synthetic locomotion generated in memory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the validation split of `--data` (best checkpoint;
    /// bandai2: `'*_youthful_*'`).
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// Leave out the clips of `--data` that cannot join the dataset (unreadable, another
    /// skeleton or frame rate) and list them, instead of refusing the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Epochs to train (an epoch visits every training pair once).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub epochs: usize,
    /// Stop after this many minutes of training (the epoch in progress finishes first).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub time_limit: Option<f64>,
    /// Run folder: config, weights, statistics, cached pair plans, loss curve and summary.
    #[arg(long, default_value = "runs/rmr")]
    pub out: PathBuf,
    /// Continue the run in this folder (its config is kept; `--epochs` is the new total).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run already in `--out`: its model, statistics, state and `last/` checkpoint
    /// are deleted before training (the cached pair plans are kept: they are reused only when
    /// they were made from the same clips and configuration).
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = RmrPreset::Paper)]
    pub preset: RmrPreset,
    /// Refiner cell (Table 1 ablation) [default: the preset's, bgru].
    #[arg(long, value_enum)]
    pub cell: Option<CellArg>,
    /// Frames of the beginning loss, `T_begin` (Table 2: 3, 5, 10; 0 turns it off) [default: 5].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frames_or_zero)]
    pub t_begin: Option<usize>,
    /// Train without the root trajectory loss (the Figure 9 ablation).
    #[arg(long)]
    pub no_trajectory_loss: bool,
    /// The paper's decoder, predicting the pose itself, instead of our default residual
    /// decoder (a correction added to the input, starting at zero; docs/rmr.md).
    #[arg(long)]
    pub no_residual: bool,
    /// Extra weight of the pose loss within 5 frames of each seam of the training pairs
    /// (0: the paper's loss) [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub seam_weight: Option<f64>,
    /// Weight of our forward-kinematics term: the lower-body positions the output's rotations
    /// give, against the ground truth's (0: the paper's loss) [default: 0; docs/rmr.md].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub fk_weight: Option<f64>,
    /// Weight of our foot-slide term: the contact joints' horizontal motion (cm per frame) on
    /// the ground truth's contact frames, by forward kinematics (0: the paper's loss) [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub slide_weight: Option<f64>,
    /// Units of each recurrent layer, per direction [default: the preset's; paper: 256].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::layer_width)]
    pub hidden: Option<usize>,
    /// Mini-batch size [default: the preset's; paper: 32].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::batch_size)]
    pub batch_size: Option<usize>,
    /// Adam learning rate [default: the preset's; paper: 1e-4].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::learning_rate)]
    pub lr: Option<f64>,
    /// Database segments start every this many frames (1: every frame, the exact search over
    /// every segment; 2 halves the databases and the planning time) [default: the preset's].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub database_stride: Option<usize>,
    /// Minutes of synthetic motion when `--data` is not given.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true, value_parser = crate::args::synth_minutes)]
    pub synth_minutes: f64,
    /// Seed of the synthetic data, of the weights, the dropout and the shuffles.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Data-parallel training threads (`1..=256`) [default: the cores available]: the same
    /// update as one thread up to float summation order (dropout masks are drawn per pair);
    /// reproducible for a fixed seed and thread count.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::cmd::train::training_threads)]
    pub threads: Option<usize>,
}

/// `--seam-weight`, `--fk-weight`, `--slide-weight`: a weight in `[0, 1000]`.
fn seam_weight(s: &str) -> Result<f64, String> {
    crate::args::real_in(s, crate::args::Interval::closed(0.0, 1000.0), "")
}

/// The files and folders of a run that `--overwrite` deletes (the ones training writes).
const RUN_FILES: [&str; 9] = [
    checkpoint::CONFIG_FILE,
    checkpoint::WEIGHTS_FILE,
    checkpoint::STATS_FILE,
    checkpoint::OPTIMIZER_FILE,
    checkpoint::RNG_FILE,
    checkpoint::TRAIN_STATE_FILE,
    checkpoint::SUMMARY_FILE,
    checkpoint::LOSS_CURVE_FILE,
    checkpoint::LAST_DIR,
];

/// The run folder, checked before any data is loaded: a fresh run never replaces a trained one
/// unless `--overwrite` says so, a resumed run must be an RMR run folder, and the folder must
/// be writable.
fn prepare_run_folder(a: &RmrArgs) -> anyhow::Result<PathBuf> {
    crate::cmd::train::prepare_run_folder_for(&a.out, a.resume.as_deref(), a.overwrite, &RUN_FILES, |dir| {
        zoo_rmr::checkpoint::read_meta(&train_loop::resume_dir(dir))
            .with_context(|| format!("--resume {}", dir.display()))?;
        Ok(())
    })
}

/// The configuration of a fresh run: the preset, the data's skeleton and the arguments.
fn fresh_config(a: &RmrArgs, skeleton: &zoo_motion::Skeleton) -> anyhow::Result<Config> {
    let preset = match a.preset {
        RmrPreset::Paper => Config::paper(),
        RmrPreset::Tiny => Config::tiny(),
    };
    let layout = StitchLayout::bandai2(skeleton).context(
        "the training clips' skeleton lacks a joint RMR reads (bandai2's lower body and feet, found by name)",
    )?;
    let mut config = preset.with_skeleton(skeleton, layout)?;
    if let Some(c) = a.cell {
        config.cell = c.into();
    }
    if let Some(t) = a.t_begin {
        config.t_begin = t;
    }
    if a.no_trajectory_loss {
        config = config.with_trajectory_loss(false);
    }
    if a.no_residual {
        config = config.with_residual(false);
    }
    if let Some(w) = a.seam_weight {
        config.seam_weight = w;
    }
    if let Some(w) = a.fk_weight {
        config.lambda_fk = w;
    }
    if let Some(w) = a.slide_weight {
        config.lambda_slide = w;
    }
    if let Some(h) = a.hidden {
        config.hidden = h;
    }
    if let Some(b) = a.batch_size {
        config.train.batch_size = b;
    }
    if let Some(lr) = a.lr {
        config.train.learning_rate = lr;
    }
    if let Some(s) = a.database_stride {
        config.pairs.database_stride = s;
    }
    config.train.seed = a.seed;
    config.pairs.seed = a.seed;
    if config.t_begin > config.pairs.window {
        bail!("--t-begin {} is longer than the training window of {} frames", config.t_begin, config.pairs.window);
    }
    config.validate()?;
    Ok(config)
}

/// Runs `zoo train rmr`.
pub fn run(a: RmrArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    if a.data.is_none() {
        let cfg = SynthConfig::default();
        crate::args::check_synth_size(("--synth-minutes", a.synth_minutes), cfg.clip_seconds, cfg.fps)
            .map_err(anyhow::Error::msg)?;
    }
    let out = prepare_run_folder(&a)?;
    let t0 = Instant::now();
    let (train, valid, source) =
        crate::cmd::train::load_clips(&a.data, &a.valid_glob, a.synth_minutes, a.seed, a.skip_invalid)?;
    if train.is_empty() || valid.is_empty() {
        bail!("need clips in both splits (training {}, validation {}): check --valid-glob", train.len(), valid.len());
    }
    let skeleton = train[0].clip.skeleton.clone();
    let resumed = match &a.resume {
        Some(dir) => Some(zoo_rmr::checkpoint::read_meta(&train_loop::resume_dir(dir))?),
        None => None,
    };
    let config = match &resumed {
        Some((config, _)) => config.clone(),
        None => fresh_config(&a, &skeleton)?,
    };
    let layout = config.layout.clone();
    let (n_train, n_valid) = (train.len(), valid.len());
    let train_set = MotionSet::from_named(train, layout.clone())?;
    let valid_set = MotionSet::from_named(valid, layout)?;

    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")?);
    pb.enable_steady_tick(Duration::from_millis(120));
    pb.set_message(format!(
        "generating training pairs (sec. 4) from {n_train} clips, validation pairs from {n_valid} clips"
    ));
    let data = zoo_rmr::data::make_pairs_cached(&config, train_set, valid_set, Some(&out))?;
    pb.finish_and_clear();
    let planning = if data.database_segments > 0 {
        format!("{} database segments built in {:.1} s", data.database_segments, data.database_seconds)
    } else {
        format!("pair plans reused from {}", out.display())
    };
    println!(
        "pairs: {} training / {} validation of {} frames ({planning}; data ready in {:.1} s)",
        data.train.count,
        data.valid.count,
        data.train.frames,
        t0.elapsed().as_secs_f64()
    );

    let trainer = match resumed {
        Some((config, stats)) => {
            if stats != data.stats {
                bail!(
                    "{}: the run's normalisation statistics differ from those of the data given now: resume with \
                     the data (and --seed, --synth-minutes) it was trained on",
                    a.resume.as_ref().map(|d| d.display().to_string()).unwrap_or_default()
                );
            }
            RmrTrainer::new(&config, stats, &device)?
        }
        None => RmrTrainer::new(&data.config, data.stats.clone(), &device)?,
    };
    let c = trainer.config();
    println!(
        "training RMR ({:?}, {} decoder, T_begin {}, trajectory loss {}, seam weight {}, fk weight {}, slide weight {}) on {source}: \
         {} parameters, batch {}, lr {:e}, run folder {}",
        c.cell,
        if c.residual { "residual" } else { "absolute" },
        c.t_begin,
        if c.lambda_trajectory > 0.0 { "on" } else { "off" },
        c.seam_weight,
        c.lambda_fk,
        c.lambda_slide,
        zoo_rmr::model::parameter_count(trainer.varmap()),
        c.train.batch_size,
        c.train.learning_rate,
        out.display()
    );
    let seed = c.train.seed;
    let mut trainer = trainer;
    let threads = crate::cmd::train::default_threads(a.threads);
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    let mut extra = serde_json::Map::new();
    extra.insert("threads".into(), threads.into());
    extra.insert("train_pairs".into(), data.train.count.into());
    extra.insert("valid_pairs".into(), data.valid.count.into());
    let mut training = RmrTraining::new(trainer, &data.train, &data.valid)?;
    let opts = TrainOptions {
        // A limit too large for a Duration is no limit.
        time_limit: a.time_limit.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok()),
        resume: a.resume.is_some(),
        data: source,
        extra,
        ..TrainOptions::new(&out, a.epochs, seed)
    };
    let state = train_loop::train(&mut training, &opts)?;
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
