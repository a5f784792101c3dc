//! The training command of the RNN-GMM (`zoo train rnn-gmm`), in two stages: the generator (an
//! LSTM into a Gaussian mixture over the next frame) and then the refiner against a
//! discriminator.
//!
//! Run folder `OUT` (see `docs/rnn-gmm.md`):
//! - `OUT/generator/`: the generator stage's run (the shared training loop's folder: best model,
//!   `last/`, `train_state.json`, `summary.json`, `loss_curve.png`, and `start.bvh`);
//! - `OUT/refiner/`: the refiner stage's run (the generator's files, the refiner, the
//!   discriminator, their training state);
//! - `OUT` itself: the model to use, the best checkpoint of the latest stage copied up
//!   (`config.json`, `model.safetensors`, `features.json`, `normalization.json`, `start.bvh`, and
//!   after the refiner stage `refiner.safetensors`, `discriminator.safetensors`,
//!   `effectors.json`). `zoo generate --model OUT` runs it.

use crate::checkpoint::{self as rck, START_FILE};
use crate::error::RnnGmmResult;
use crate::features::EncodedClip;
use crate::prelude::*;
use crate::refiner::{DISCRIMINATOR_FILE, EFFECTORS_FILE, REFINER_FILE};
use std::path::{Path, PathBuf};
use std::time::Duration;
use zoo_data::dataset::{self, NamedClip, TrainingClips};
use zoo_data::{Context, Message, Progress, bail};
use zoo_nn::run_folder::RunSpec;
use zoo_nn::train_loop::{self, TrainOptions};

/// The generator stage's sub-folder of a run folder.
pub const GENERATOR_DIR: &str = "generator";
/// The refiner stage's sub-folder of a run folder.
pub const REFINER_DIR: &str = "refiner";
/// Frames of the start clip (at most).
const START_FRAMES: usize = 90;

/// Which stage(s) to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Stage {
    /// The generator, then the refiner on it.
    Both,
    /// The generator only (sec. 4.1).
    Generator,
    /// The refiner and the discriminator on the generator already trained in the run folder
    /// (sec. 4.2).
    Refiner,
}

/// Sizes of the RNN-GMM to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RnnGmmPreset {
    /// `Config::paper`: 3 x 512 fully connected, 2 x 512 LSTM, M = 5, refiner 256, discriminator 128.
    Paper,
    /// `Config::tiny`: 32-wide, M = 3, windows of 20 frames (tests and quick checks).
    Tiny,
}

/// The refiner stage's settings that a fresh stage takes from the command (`None`: the
/// generator run's; ignored when a refiner stage is resumed).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RefinerOverrides {
    /// Warm-up updates, refiner and discriminator each.
    pub warmup: Option<usize>,
    /// Weight of the root regularisation (eq. 13's lambda).
    pub lambda: Option<f64>,
    /// Weight of the foot-skate term.
    pub skate_weight: Option<f64>,
    /// Weight of the joint-range term.
    pub range_weight: Option<f64>,
    /// Percentile of the joint-range term's bounds.
    pub range_percentile: Option<f64>,
    /// Frames the generator runs past its seed before each training window.
    pub fake_lead: Option<usize>,
    /// Fake windows sampled afresh after every round.
    pub fresh_fakes: Option<usize>,
    /// Clamp the output joint angles to the training windows' range (default: on).
    pub joint_limits: Option<bool>,
    /// Standard deviation in frames of the smoothing of the generator's root (default: 0).
    pub root_smoothing: Option<f64>,
}

/// The options of `zoo train rnn-gmm`.
#[derive(Clone, Debug)]
pub struct RnnGmmRunOptions {
    /// The run folder, the generator's epochs and time limit, the seed and threads.
    pub run: RunSpec,
    /// The clips.
    pub data: TrainingClips,
    /// Glob on file names selecting the clips of `data` to use.
    pub glob: Option<String>,
    /// Stage(s) to train.
    pub stage: Stage,
    /// Refiner epochs (the total of a resumed stage).
    pub refiner_epochs: usize,
    /// Adversarial rounds per refiner epoch.
    pub refiner_rounds: usize,
    /// The refiner's settings from the command.
    pub refiner: RefinerOverrides,
    /// Stop the refiner stage after this many minutes (`None`: the run's time limit).
    pub refiner_time_limit: Option<f64>,
    /// Model sizes.
    pub preset: RnnGmmPreset,
}

/// The files of a model folder that the stages copy up into the run folder.
const MODEL_FILES: [&str; 5] = [rck::CONFIG_FILE, rck::WEIGHTS_FILE, rck::FEATURES_FILE, rck::STATS_FILE, START_FILE];
/// The refiner stage's model files.
const REFINER_FILES: [&str; 3] = [REFINER_FILE, DISCRIMINATOR_FILE, EFFECTORS_FILE];

fn minutes(m: Option<f64>) -> Option<Duration> {
    // A limit too large for a Duration is no limit.
    m.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok())
}

fn remove(p: &Path) -> RnnGmmResult<()> {
    let r = if p.is_dir() {
        std::fs::remove_dir_all(p)
    } else if p.exists() {
        std::fs::remove_file(p)
    } else {
        Ok(())
    };
    Ok(r.with_context(|| format!("--overwrite: cannot delete {}", p.display()))?)
}

/// Whether `dir` holds a stage's run (a model, a state or a `last/` checkpoint).
fn holds_run(dir: &Path) -> bool {
    [rck::CONFIG_FILE, rck::WEIGHTS_FILE, "train_state.json", "last"].iter().any(|f| dir.join(f).exists())
}

/// What the command will do, decided before any data is loaded.
struct Plan {
    out: PathBuf,
    /// Train (or continue) the generator stage.
    generator: bool,
    /// Train the refiner stage; `Some(true)` continues it.
    refiner: Option<bool>,
    resume_generator: bool,
}

/// Checks the run folder against the stage and the flags: a fresh run never replaces a trained
/// one without `--overwrite`, a resumed run must be one, a refiner needs a generator, and the
/// folder must be writable.
fn plan(a: &RnnGmmRunOptions) -> RnnGmmResult<Plan> {
    let wants_gen = a.stage != Stage::Refiner;
    let wants_ref = a.stage != Stage::Generator;
    match &a.run.resume {
        Some(dir) => {
            if !dir.is_dir() {
                bail!("--resume {}: no such folder (start a new run with --out instead)", dir.display());
            }
            let gen_dir = dir.join(GENERATOR_DIR);
            if !gen_dir.join(rck::CONFIG_FILE).is_file() {
                bail!(
                    "--resume {}: no trained generator in {} (a run folder of `zoo train rnn-gmm`?); start a new run \
                     with --out",
                    dir.display(),
                    gen_dir.display()
                );
            }
            zoo_nn::run_folder::writable_dir("--resume", dir)?;
            zoo_nn::run_folder::lock(dir)?;
            let ref_dir = dir.join(REFINER_DIR);
            let refiner_started = ref_dir.join("train_state.json").is_file();
            if wants_gen {
                let state = train_loop::read_state(&gen_dir)?;
                if state.epoch < a.run.epochs && refiner_started {
                    bail!(
                        "--resume {}: training the generator further ({} -> {} epochs) would leave the refiner in {} \
                         trained on the older generator; continue the generator with --stage generator and then \
                         retrain the refiner with --stage refiner --overwrite --out {0}",
                        dir.display(),
                        state.epoch,
                        a.run.epochs,
                        ref_dir.display()
                    );
                }
            }
            Ok(Plan {
                out: dir.clone(),
                generator: wants_gen,
                refiner: wants_ref.then_some(refiner_started),
                resume_generator: true,
            })
        }
        None => {
            let out = &a.run.out;
            if wants_gen {
                let parts = [out.to_path_buf(), out.join(GENERATOR_DIR), out.join(REFINER_DIR)];
                if parts.iter().any(|p| holds_run(p)) {
                    // A run stopped before its first checkpoint is trained again from the start.
                    if !a.run.overwrite && !zoo_nn::run_folder::unfinished(out) {
                        bail!(
                            "--out {} already holds a run: continue it with `--resume {0}`, replace it with \
                             --overwrite, or choose another --out",
                            out.display()
                        );
                    }
                    zoo_nn::run_folder::lock(out)?;
                    let names: Vec<&str> = [GENERATOR_DIR, REFINER_DIR, zoo_nn::run_folder::COMMAND_FILE]
                        .into_iter()
                        .chain(MODEL_FILES)
                        .chain(REFINER_FILES)
                        .collect();
                    zoo_nn::run_folder::set_aside(out, &names)?;
                }
            } else {
                let gen_dir = out.join(GENERATOR_DIR);
                if !gen_dir.join(rck::CONFIG_FILE).is_file() {
                    bail!(
                        "--stage refiner: {} holds no trained generator ({} is missing); train it first with \
                         --stage generator --out {}",
                        out.display(),
                        gen_dir.join(rck::CONFIG_FILE).display(),
                        out.display()
                    );
                }
                let ref_dir = out.join(REFINER_DIR);
                if holds_run(&ref_dir) {
                    if !a.run.overwrite {
                        bail!(
                            "--out {} already holds a refiner stage ({}): continue it with `--resume {0} --stage \
                             refiner`, replace it with --overwrite, or choose another --out",
                            out.display(),
                            ref_dir.display()
                        );
                    }
                    zoo_nn::run_folder::lock(out)?;
                    zoo_nn::run_folder::set_aside(out, &[REFINER_DIR])?;
                }
            }
            zoo_nn::run_folder::writable_dir("--out", out)?;
            zoo_nn::run_folder::lock(out)?;
            zoo_nn::run_folder::record_command(out, &a.run)?;
            Ok(Plan {
                out: out.clone(),
                generator: wants_gen,
                refiner: wants_ref.then_some(false),
                resume_generator: false,
            })
        }
    }
}

/// Training and validation clips with a description of the source.
fn load(a: &RnnGmmRunOptions, p: &dyn Progress) -> RnnGmmResult<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    match &a.data.data {
        Some(path) => {
            let Some(vglob) = &a.data.valid_glob else {
                bail!("--data needs --valid-glob GLOB to choose the validation clips (bandai2: '*_youthful_*')")
            };
            dataset::glob(vglob).map_err(Message::new)?;
            let clips = dataset::load_reporting(path, a.glob.as_deref(), a.data.skip_invalid, p)?;
            let (train, valid) = dataset::split(clips, vglob).map_err(Message::new)?;
            let chosen = a.glob.as_ref().map(|g| format!(", clips {g}")).unwrap_or_default();
            Ok((train, valid, format!("{}{chosen} (validation: {vglob})", path.display())))
        }
        None => {
            if a.glob.is_some() || a.data.valid_glob.is_some() {
                bail!("--glob and --valid-glob choose clips of --data; give --data PATH or leave them out");
            }
            Ok(dataset::training_clips(&TrainingClips { skip_invalid: false, ..a.data.clone() }, p)?)
        }
    }
}

/// Encodes clips with the generator's feature and cuts them into its normalised windows.
fn windows_with(
    spec: &FeatureSpec,
    norm: &Normalization,
    config: &Config,
    clips: &[NamedClip],
    what: &str,
) -> RnnGmmResult<Windows> {
    let enc: Vec<EncodedClip> = clips
        .iter()
        .map(|c| spec.encode(&c.clip).with_context(|| format!("{what} clip {}", c.path.display())))
        .collect::<Result<_, _>>()?;
    let w = Windows::from_clips(&enc, norm, config.train.window, config.train.window_stride)?;
    if w.is_empty() {
        bail!("no {what} window of {} frames: the {what} clips are too short or too few", config.train.window);
    }
    Ok(w)
}

/// Copies the model files of a stage's best checkpoint up into the run folder.
fn publish(from: &Path, out: &Path, refiner: bool) -> RnnGmmResult<()> {
    let files: Vec<&str> =
        if refiner { MODEL_FILES.iter().chain(&REFINER_FILES).copied().collect() } else { MODEL_FILES.to_vec() };
    if !refiner {
        for f in REFINER_FILES {
            remove(&out.join(f))?;
        }
    }
    for f in files {
        let src = from.join(f);
        if src.is_file() {
            let bytes = std::fs::read(&src).with_context(|| format!("reading {}", src.display()))?;
            zoo_format::atomic::write(&out.join(f), bytes)
                .with_context(|| format!("writing {}", out.join(f).display()))?;
        }
    }
    Ok(())
}

/// The generator stage (sec. 4.1): a fresh or resumed generator trained into `OUT/generator/`,
/// its best checkpoint copied up when it changed.
fn generator_stage(a: &RnnGmmRunOptions, p: &Plan, clips: &Clips) -> RnnGmmResult<()> {
    let device = candle_core::Device::Cpu;
    let (train, valid, source, fps) = (&clips.train, &clips.valid, &clips.source, clips.fps);
    let gen_dir = p.out.join(GENERATOR_DIR);
    let train_refs: Vec<&zoo_motion::Clip> = train.iter().map(|c| &c.clip).collect();
    let valid_refs: Vec<&zoo_motion::Clip> = valid.iter().map(|c| &c.clip).collect();
    let (mut trainer, data) = if p.resume_generator {
        let from = train_loop::resume_dir(&gen_dir);
        let trainer = GeneratorTrainer::load(&from, &device)
            .with_context(|| format!("resuming the generator from {}", from.display()))?;
        let (spec, norm, config) = (trainer.spec().clone(), trainer.norm().clone(), trainer.config().clone());
        let tw = windows_with(&spec, &norm, &config, train, "training")?;
        let vw = windows_with(&spec, &norm, &config, valid, "validation")?;
        (trainer, TrainingData { spec, norm, train: tw, valid: vw })
    } else {
        let mut config = match a.preset {
            RnnGmmPreset::Paper => Config::paper(),
            RnnGmmPreset::Tiny => Config::tiny(),
        };
        config.train.seed = a.run.seed;
        config.refiner.seed = a.run.seed;
        let data = TrainingData::from_clips(&config, fps, &train_refs, &valid_refs)?;
        let config = config.with_dim(data.spec.dim());
        let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &device)?;
        std::fs::create_dir_all(&gen_dir).with_context(|| format!("creating {}", gen_dir.display()))?;
        let start = &valid[0].clip;
        let start = start.slice(0, start.frames().min(START_FRAMES));
        zoo_data::bvh::write_file(&start, &gen_dir.join(START_FILE))
            .with_context(|| format!("writing {}", gen_dir.join(START_FILE).display()))?;
        (trainer, data)
    };
    println!(
        "training the RNN-GMM generator on {source}: {} training / {} validation windows of {} frames, {} \
         parameters, run folder {}",
        data.train.len(),
        data.valid.len(),
        trainer.config().train.window,
        trainer.model().parameter_count(),
        gen_dir.display()
    );
    let threads = a.run.thread_count();
    trainer.set_threads(threads)?;
    println!("generator training threads: {threads} (data-parallel; --threads to change)");
    let seed = trainer.config().train.seed;
    let mut training = GeneratorTraining::new(trainer, &data.train, &data.valid)?;
    let opts = TrainOptions {
        time_limit: a.run.time_limit(),
        resume: p.resume_generator,
        data: source.clone(),
        ..TrainOptions::new(&gen_dir, a.run.epochs, seed)
    };
    let before = if p.resume_generator { train_loop::read_state(&gen_dir)?.epoch } else { 0 };
    let state = train_loop::train(&mut training, &opts)?;
    // Only a generator that changed replaces the model of the run folder (and its refiner).
    if state.epoch > before {
        publish(&gen_dir, &p.out, false)?;
    }
    println!(
        "generator: {} epochs in {:.1} min, best validation NLL {:.3} nats/frame at epoch {}; model in {}",
        state.epoch,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        p.out.display()
    );
    Ok(())
}

/// The refiner stage (sec. 4.2): the refiner and the discriminator trained against the
/// generator of `OUT/generator/` into `OUT/refiner/`, the best checkpoint copied up.
fn refiner_stage(a: &RnnGmmRunOptions, p: &Plan, clips: &Clips, resume: bool) -> RnnGmmResult<()> {
    let device = candle_core::Device::Cpu;
    let (train, valid, source) = (&clips.train, &clips.valid, &clips.source);
    let gen_dir = p.out.join(GENERATOR_DIR);
    let ref_dir = p.out.join(REFINER_DIR);
    let (config, spec, norm) =
        rck::read_meta(&gen_dir).with_context(|| format!("reading the generator in {}", gen_dir.display()))?;
    let tw = windows_with(&spec, &norm, &config, train, "training")?;
    let vw = windows_with(&spec, &norm, &config, valid, "validation")?;
    // A resumed stage keeps its own refiner settings; a fresh one takes the generator's
    // (the preset's) with the command's overrides.
    let refiner_config = if resume {
        let from = train_loop::resume_dir(&ref_dir);
        rck::read_meta(&from).with_context(|| format!("resuming the refiner from {}", from.display()))?.0.refiner
    } else {
        let mut r = config.refiner.clone();
        if let Some(n) = a.refiner.warmup {
            (r.warmup_refiner, r.warmup_discriminator) = (n, n);
        }
        r.lambda = a.refiner.lambda.unwrap_or(r.lambda);
        r.skate_weight = a.refiner.skate_weight.unwrap_or(r.skate_weight);
        r.range_weight = a.refiner.range_weight.unwrap_or(r.range_weight);
        r.range_percentile = a.refiner.range_percentile.unwrap_or(r.range_percentile);
        r.fake_lead_frames = a.refiner.fake_lead.unwrap_or(r.fake_lead_frames);
        r.fresh_fakes = a.refiner.fresh_fakes.unwrap_or(r.fresh_fakes);
        // Settings newer than the generator's config.json take this version's defaults.
        let new = crate::RefinerConfig::default();
        r.joint_limits = a.refiner.joint_limits.unwrap_or(new.joint_limits);
        r.root_smoothing = a.refiner.root_smoothing.unwrap_or(new.root_smoothing);
        r
    };
    let c = &refiner_config;
    println!(
        "training the RNN-GMM refiner on {} real windows against {} generator samples (warm-up: {} refiner + {} \
         discriminator updates in the first round; skate weight {}, range weight {}, {} lead frames, {} fresh fakes per \
         round, joint limits {}, root smoothing {} frames), run folder {}",
        tw.len(),
        c.fake_windows,
        c.warmup_refiner,
        c.warmup_discriminator,
        c.skate_weight,
        c.range_weight,
        c.fake_lead_frames,
        c.fresh_fakes,
        if c.joint_limits { "on" } else { "off" },
        c.root_smoothing,
        ref_dir.display()
    );
    let mut trainer = AdversarialTrainer::new(&gen_dir, &refiner_config, &tw, &vw, &device)
        .with_context(|| format!("building the refiner stage on {}", gen_dir.display()))?;
    let threads = a.run.thread_count();
    trainer.set_threads(threads)?;
    println!("refiner training threads: {threads} (data-parallel; --threads to change)");
    let mut training = AdversarialTraining::new(trainer, &tw).with_rounds_per_epoch(a.refiner_rounds);
    let opts = TrainOptions {
        time_limit: minutes(a.refiner_time_limit.or(a.run.time_limit_minutes)),
        resume,
        data: source.clone(),
        ..TrainOptions::new(&ref_dir, a.refiner_epochs, refiner_config.seed)
    };
    let result = train_loop::train(&mut training, &opts);
    let published = ref_dir.join(REFINER_FILE).is_file();
    if published {
        publish(&ref_dir, &p.out, true)?;
    }
    let state = match result {
        Ok(s) => s,
        Err(e) if published => {
            bail!("the refiner stage stopped; its best checkpoint so far is in {}: {e}", p.out.display());
        }
        Err(e) => return Err(e.into()),
    };
    println!(
        "refiner: {} epochs ({} rounds) in {:.1} min, best validation measure (skate + range + lambda * root term) {:.4} at epoch {}; model in {}",
        state.epoch,
        training.trainer().rounds(),
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        p.out.display()
    );
    Ok(())
}

/// The clips of the run.
struct Clips {
    train: Vec<NamedClip>,
    valid: Vec<NamedClip>,
    source: String,
    fps: f64,
}

/// Runs `zoo train rnn-gmm`: the generator stage, then the refiner stage on it (or either).
pub fn run(a: &RnnGmmRunOptions, progress: &dyn Progress) -> RnnGmmResult<()> {
    let p = plan(a)?;
    let (train, valid, source) = load(a, progress)?;
    let Some(first) = train.first() else { bail!("no training clips in {source}") };
    if valid.is_empty() {
        bail!("no validation clips in {source}");
    }
    let fps = first.clip.fps();
    let clips = Clips { train, valid, source, fps };
    if p.generator {
        generator_stage(a, &p, &clips)?;
    }
    if let Some(resume) = p.refiner {
        refiner_stage(a, &p, &clips, resume)?;
    }
    Ok(())
}
