//! The training command of the RMR (`zoo train rmr`): the training pairs (sec. 4) are generated
//! first; their plans (the KNN searches, the slow part) are cached in the run folder and reused
//! when the same clips and configuration come back (a resume, or `--overwrite` on the same
//! data).

use crate::pairs::{MotionSet, StitchLayout};
use crate::prelude::*;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::dataset::TrainingClips;
use zoo_data::{Context, Progress, bail};
use zoo_nn::run_folder::RunSpec;
use zoo_nn::train_loop::{self, TrainOptions};

/// Sizes of the RMR to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RmrPreset {
    /// The paper's sizes (`Config::paper`: encoder 256, BGRU 2 x 256, T = 60 frames).
    Paper,
    /// The model to try the tools with (`Config::quick`: the paper's windows, half its widths;
    /// 80 epochs unless `--epochs` is given): about 5 minutes of one thread on the default
    /// synthetic data, less foot sliding than inertialization on held-out cases with a ground
    /// truth (docs/rmr.md, "Quick start").
    Quick,
    /// A small model for tests (`Config::tiny`: 30-frame windows; trains in seconds, learns little).
    Tiny,
}

/// The refiner cell (RMR Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
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

/// The options of `zoo train rmr` (`None`: the preset's value).
#[derive(Clone, Debug)]
pub struct RmrRunOptions {
    /// The run folder, its length, seed and threads.
    pub run: RunSpec,
    /// The clips.
    pub data: TrainingClips,
    /// Model sizes.
    pub preset: RmrPreset,
    /// Whether `--epochs` was given (the quick preset has its own, [`QUICK_EPOCHS`], otherwise).
    pub epochs_given: bool,
    /// Refiner cell (Table 1 ablation).
    pub cell: Option<CellArg>,
    /// Frames of the beginning loss `T_begin` (0 turns it off).
    pub t_begin: Option<usize>,
    /// Train without the root trajectory loss (the Figure 9 ablation).
    pub no_trajectory_loss: bool,
    /// The paper's decoder (the pose itself) instead of the residual one.
    pub no_residual: bool,
    /// The paper's training: the raw concatenation as input ([`crate::Config::pre_blend`]
    /// off) and its loss alone (seam and velocity weights 0 unless given). Without it the run
    /// trains on the inputs inertialized at their seams with [`crate::config::RECIPE_SEAM_WEIGHT`]
    /// and [`crate::config::RECIPE_VELOCITY_WEIGHT`] (the default recipe; docs/rmr.md).
    pub paper: bool,
    /// Extra weight of the pose loss within 5 frames of each seam.
    pub seam_weight: Option<f64>,
    /// Weight of the forward-kinematics term.
    pub fk_weight: Option<f64>,
    /// Weight of the foot-slide term.
    pub slide_weight: Option<f64>,
    /// Weight of the velocity term.
    pub velocity_weight: Option<f64>,
    /// Units of each recurrent layer, per direction.
    pub hidden: Option<usize>,
    /// Mini-batch size.
    pub batch_size: Option<usize>,
    /// Adam learning rate.
    pub lr: Option<f64>,
    /// Database segments start every this many frames.
    pub database_stride: Option<usize>,
}

/// Epochs of `--preset quick` when `--epochs` is not given: under 10 minutes on one thread on the
/// default 10 minutes of synthetic locomotion (docs/rmr.md, "Quick start").
pub const QUICK_EPOCHS: usize = 80;

/// The run folder, checked before any data is loaded: a fresh run never replaces a trained one
/// unless `--overwrite` says so (the cached pair plans are kept), a resumed run must be an RMR
/// run folder, and the folder must be writable.
fn prepare_run_folder(o: &RmrRunOptions) -> RmrResult<PathBuf> {
    Ok(zoo_nn::run_folder::prepare(&o.run, &zoo_nn::run_folder::COMMON_RUN_FILES, |dir| {
        crate::checkpoint::read_meta(&train_loop::resume_dir(dir))
            .map_err(|e| zoo_nn::TrainError::Config(format!("--resume {}: {e}", dir.display())))?;
        Ok(())
    })?)
}

/// The configuration of a fresh run: the preset, the data's skeleton and the arguments.
fn fresh_config(a: &RmrRunOptions, skeleton: &zoo_motion::Skeleton) -> RmrResult<Config> {
    let preset = match a.preset {
        RmrPreset::Paper => Config::paper(),
        RmrPreset::Quick => Config::quick(),
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
    if !a.paper {
        config.pre_blend = true;
        config.seam_weight = crate::config::RECIPE_SEAM_WEIGHT;
        config.lambda_velocity = crate::config::RECIPE_VELOCITY_WEIGHT;
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
    if let Some(w) = a.velocity_weight {
        config.lambda_velocity = w;
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
    config.train.seed = a.run.seed;
    config.pairs.seed = a.run.seed;
    if config.t_begin > config.pairs.window {
        bail!("--t-begin {} is longer than the training window of {} frames", config.t_begin, config.pairs.window);
    }
    config.validate()?;
    Ok(config)
}

/// Runs `zoo train rmr`: the training pairs (their plans cached in the run folder), a fresh or
/// resumed trainer, the shared training loop.
pub fn run(a: &RmrRunOptions, p: &dyn Progress) -> RmrResult<()> {
    let device = candle_core::Device::Cpu;
    let out = prepare_run_folder(a)?;
    let t0 = Instant::now();
    let (train, valid, source) = zoo_data::dataset::training_clips(&a.data, p)?;
    if train.is_empty() || valid.is_empty() {
        bail!("need clips in both splits (training {}, validation {}): check --valid-glob", train.len(), valid.len());
    }
    let skeleton = train[0].clip.skeleton.clone();
    let resumed = match &a.run.resume {
        Some(dir) => Some(crate::checkpoint::read_meta(&train_loop::resume_dir(dir))?),
        None => None,
    };
    let config = match &resumed {
        Some((config, _)) => config.clone(),
        None => fresh_config(a, &skeleton)?,
    };
    let layout = config.layout.clone();
    let (n_train, n_valid) = (train.len(), valid.len());
    let train_set = MotionSet::from_named(train, layout.clone())?;
    let valid_set = MotionSet::from_named(valid, layout)?;

    p.stage(&format!("generating training pairs (sec. 4) from {n_train} clips, validation pairs from {n_valid} clips"));
    let data = crate::data::make_pairs_cached(&config, train_set, valid_set, Some(&out))?;
    p.finish();
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
                    a.run.resume.as_ref().map(|d| d.display().to_string()).unwrap_or_default()
                );
            }
            RmrTrainer::new(&config, stats, &device)?
        }
        None => RmrTrainer::new(&data.config, data.stats.clone(), &device)?,
    };
    let c = trainer.config();
    println!(
        "training RMR ({:?}, {} decoder, T_begin {}, trajectory loss {}, seam weight {}, fk weight {}, slide weight {}, velocity weight {}) on {source}: \
         {} parameters, batch {}, lr {:e}, run folder {}",
        c.cell,
        if c.residual { "residual" } else { "absolute" },
        c.t_begin,
        if c.lambda_trajectory > 0.0 { "on" } else { "off" },
        c.seam_weight,
        c.lambda_fk,
        c.lambda_slide,
        c.lambda_velocity,
        crate::model::parameter_count(trainer.varmap()),
        c.train.batch_size,
        c.train.learning_rate,
        out.display()
    );
    let seed = c.train.seed;
    let epochs = match (a.preset, a.epochs_given || a.run.resume.is_some()) {
        (RmrPreset::Quick, false) => QUICK_EPOCHS,
        _ => a.run.epochs,
    };
    let mut trainer = trainer;
    let threads = a.run.thread_count();
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    let mut extra = serde_json::Map::new();
    extra.insert("threads".into(), threads.into());
    extra.insert("train_pairs".into(), data.train.count.into());
    extra.insert("valid_pairs".into(), data.valid.count.into());
    let mut training = RmrTraining::new(trainer, &data.train, &data.valid)?;
    let opts = TrainOptions {
        time_limit: a.run.time_limit(),
        resume: a.run.resume.is_some(),
        data: source,
        extra,
        ..TrainOptions::new(&out, epochs, seed)
    };
    let state = train_loop::train(&mut training, &opts)?;
    println!("{}", zoo_nn::run_folder::done_line(&state, &out));
    calibrate_fallback(&out, &data.valid, &device)
}

/// Calibrates the fallback of the best model in `out` ([`crate::fallback`]) on the validation
/// pairs' correction sizes and writes it into the folder's `config.json` (atomically).
fn calibrate_fallback(out: &std::path::Path, valid: &PairFeatures, device: &candle_core::Device) -> RmrResult<()> {
    if !out.join(checkpoint::CONFIG_FILE).is_file() || valid.count == 0 {
        return Ok(());
    }
    let (model, _) = checkpoint::load(out, device)?;
    let sizes = crate::fallback::correction_sizes(&model, valid)?;
    let Some(fallback) = crate::fallback::calibrate(&sizes) else { return Ok(()) };
    let mut config = model.config().clone();
    config.fallback = Some(fallback);
    zoo_nn::checkpoint::write_json(&out.join(checkpoint::CONFIG_FILE), &config)?;
    let mean = sizes.iter().sum::<f32>() / sizes.len() as f32;
    println!(
        "fallback calibrated on {} validation pairs (correction size mean {mean:.3}): towards the input from a \
         size of {:.3} (95th percentile), fully at {:.3}; stored in config.json",
        sizes.len(),
        fallback.start,
        fallback.full
    );
    Ok(())
}
