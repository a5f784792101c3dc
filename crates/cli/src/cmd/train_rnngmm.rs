//! `zoo train rnn-gmm`: the RNN-GMM of Wang, Chai & Xia in two stages, the generator (an LSTM
//! into a Gaussian mixture over the next frame) and then the refiner against a discriminator.
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

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use std::time::Duration;
use zoo_data::dataset::{self, NamedClip};
use zoo_data::synth::SynthConfig;
use zoo_nn::train_loop::{self, TrainOptions};
use zoo_rnngmm::checkpoint as rck;
use zoo_rnngmm::features::EncodedClip;
use zoo_rnngmm::prelude::*;
use zoo_rnngmm::refiner::{DISCRIMINATOR_FILE, EFFECTORS_FILE, REFINER_FILE};

/// The generator stage's sub-folder of a run folder.
pub const GENERATOR_DIR: &str = "generator";
/// The refiner stage's sub-folder of a run folder.
pub const REFINER_DIR: &str = "refiner";
/// A short real clip saved with the model: `zoo generate` starts from it when no `--from` clip
/// is given.
pub const START_FILE: &str = "start.bvh";
/// Frames of the start clip (at most).
const START_FRAMES: usize = 90;

/// Which stage(s) to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RnnGmmPreset {
    /// `Config::paper`: 3 x 512 fully connected, 2 x 512 LSTM, M = 5, refiner 256, discriminator 128.
    Paper,
    /// `Config::tiny`: 32-wide, M = 3, windows of 20 frames (tests and quick checks).
    Tiny,
}

/// Arguments of `zoo train rnn-gmm`.
#[derive(Args)]
pub struct RnnGmmArgs {
    /// BVH file or folder to train on; without it, synthetic locomotion generated in memory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the clips of `--data` to use (e.g. `'*_00[1-3].bvh*'`).
    #[arg(long)]
    pub glob: Option<String>,
    /// Glob on file names selecting the validation split of `--data` (bandai2: '*_youthful_*').
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// Leave out the clips of `--data` that cannot join the dataset and list them.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Stage(s) to train: `both` (generator, then refiner), `generator`, or `refiner` (on the
    /// generator of the run folder).
    #[arg(long, value_enum, default_value_t = Stage::Both)]
    pub stage: Stage,
    /// Generator epochs (an epoch visits every training window once; a resumed run continues
    /// up to this total).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub epochs: usize,
    /// Refiner epochs (an epoch is `--refiner-rounds` adversarial rounds; a resumed run
    /// continues up to this total).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub refiner_epochs: usize,
    /// Adversarial rounds per refiner epoch (a round: k refiner updates and one discriminator
    /// update; the first also runs the warm-up).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::rounds)]
    pub refiner_rounds: usize,
    /// Warm-up updates of the refiner stage, refiner and discriminator each [default: the
    /// preset's; paper: 75]. Ignored when a refiner stage is resumed (its own setting is kept).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::rounds)]
    pub refiner_warmup: Option<usize>,
    /// Weight of the refiner's root regularisation (eq. 13's lambda; paper: 20) [default: the
    /// generator run's setting]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::loss_weight)]
    pub refiner_lambda: Option<f64>,
    /// Weight of the refiner's foot-skate term (not in the paper's eq. 13; see
    /// `docs/rnn-gmm.md`) [default: the generator run's setting; 300 in new runs, 0 means eq.
    /// 13 alone]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::loss_weight)]
    pub refiner_skate_weight: Option<f64>,
    /// Weight of the refiner's joint-range term (not in the paper) [default: the generator
    /// run's setting; 500 in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::loss_weight)]
    pub refiner_range_weight: Option<f64>,
    /// Percentile of the joint-range term's bounds: each value's range runs from this
    /// percentile to 100 minus it in the training windows [default: the generator run's
    /// setting; 1 in new runs, 0 for min to max]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::range_percentile)]
    pub refiner_range_percentile: Option<f64>,
    /// Frames the generator runs past its seed before each of the refiner's training windows
    /// starts, so the refiner also sees the generator's drift [default: the generator run's
    /// setting; 0 in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frames_or_zero)]
    pub refiner_fake_lead: Option<usize>,
    /// Fake windows sampled afresh from the generator after every adversarial round, replacing
    /// as many in the refiner's pool [default: the generator run's setting; 16 in new runs, 0
    /// keeps the pool sampled at the start]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::count_or_zero)]
    pub refiner_fresh_fakes: Option<usize>,
    /// Clamp the refiner's output joint angles (and root tilt) to their min and max over the
    /// real training windows (not in the paper; `false` for the paper's refiner) [default: true
    /// in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    pub refiner_joint_limits: Option<bool>,
    /// Standard deviation, in frames, of the Gaussian that smooths the generator's root before
    /// eq. 13 holds the refined root to it, so the refiner may remove the root's frame-to-frame
    /// jitter (not in the paper) [default: 0, eq. 13 as written]. Ignored when a refiner stage
    /// is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::smoothing_frames)]
    pub refiner_root_smoothing: Option<f64>,
    /// Stop the generator stage after this many minutes (checked between epochs: the epoch in
    /// progress finishes first).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub time_limit: Option<f64>,
    /// Stop the refiner stage after this many minutes [default: --time-limit].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub refiner_time_limit: Option<f64>,
    /// Run folder (see `docs/rnn-gmm.md`).
    #[arg(long, default_value = "runs/rnn-gmm")]
    pub out: PathBuf,
    /// Continue the run in this folder (its configuration is kept; the epoch counts are the new
    /// totals). With `--stage refiner` or `both`, a refiner stage not started yet starts.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run already in `--out` (with `--stage refiner`: its refiner stage only).
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = RnnGmmPreset::Paper)]
    pub preset: RnnGmmPreset,
    /// Minutes of synthetic motion when `--data` is not given.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true, value_parser = crate::args::synth_minutes)]
    pub synth_minutes: f64,
    /// Seed of the synthetic data, the weights, the input noise, the shuffles and the
    /// adversarial draws.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Data-parallel threads of both stages (`1..=256`) [default: the cores available]. See
    /// `zoo train rtn --help`.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::cmd::train::training_threads)]
    pub threads: Option<usize>,
}

/// The files of a model folder that the stages copy up into the run folder.
const MODEL_FILES: [&str; 5] = [rck::CONFIG_FILE, rck::WEIGHTS_FILE, rck::FEATURES_FILE, rck::STATS_FILE, START_FILE];
/// The refiner stage's model files.
const REFINER_FILES: [&str; 3] = [REFINER_FILE, DISCRIMINATOR_FILE, EFFECTORS_FILE];

fn minutes(m: Option<f64>) -> Option<Duration> {
    // A limit too large for a Duration is no limit.
    m.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok())
}

fn remove(p: &Path) -> anyhow::Result<()> {
    let r = if p.is_dir() {
        std::fs::remove_dir_all(p)
    } else if p.exists() {
        std::fs::remove_file(p)
    } else {
        Ok(())
    };
    r.with_context(|| format!("--overwrite: cannot delete {}", p.display()))
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
fn plan(a: &RnnGmmArgs) -> anyhow::Result<Plan> {
    let wants_gen = a.stage != Stage::Refiner;
    let wants_ref = a.stage != Stage::Generator;
    match &a.resume {
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
            crate::cmd::check_output_dir("--resume", dir)?;
            let ref_dir = dir.join(REFINER_DIR);
            let refiner_started = ref_dir.join("train_state.json").is_file();
            if wants_gen {
                let state = train_loop::read_state(&gen_dir)?;
                if state.epoch < a.epochs && refiner_started {
                    bail!(
                        "--resume {}: training the generator further ({} -> {} epochs) would leave the refiner in {} \
                         trained on the older generator; continue the generator with --stage generator and then \
                         retrain the refiner with --stage refiner --overwrite --out {0}",
                        dir.display(),
                        state.epoch,
                        a.epochs,
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
            let out = &a.out;
            if wants_gen {
                let parts = [out.to_path_buf(), out.join(GENERATOR_DIR), out.join(REFINER_DIR)];
                if parts.iter().any(|p| holds_run(p)) {
                    if !a.overwrite {
                        bail!(
                            "--out {} already holds a run: continue it with `--resume {0}`, replace it with \
                             --overwrite, or choose another --out",
                            out.display()
                        );
                    }
                    remove(&out.join(GENERATOR_DIR))?;
                    remove(&out.join(REFINER_DIR))?;
                    for f in MODEL_FILES.iter().chain(&REFINER_FILES) {
                        remove(&out.join(f))?;
                    }
                    println!("--overwrite: deleted the run in {}", out.display());
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
                    if !a.overwrite {
                        bail!(
                            "--out {} already holds a refiner stage ({}): continue it with `--resume {0} --stage \
                             refiner`, replace it with --overwrite, or choose another --out",
                            out.display(),
                            ref_dir.display()
                        );
                    }
                    remove(&ref_dir)?;
                    println!("--overwrite: deleted the refiner stage in {}", ref_dir.display());
                }
            }
            crate::cmd::check_output_dir("--out", out)?;
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
fn load(a: &RnnGmmArgs) -> anyhow::Result<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    match &a.data {
        Some(path) => {
            let Some(vglob) = &a.valid_glob else {
                bail!("--data needs --valid-glob GLOB to choose the validation clips (bandai2: '*_youthful_*')")
            };
            dataset::glob(vglob)?;
            let clips = crate::cmd::load_dataset(path, a.glob.as_deref(), a.skip_invalid)?;
            let (train, valid) = dataset::split(clips, vglob)?;
            let chosen = a.glob.as_ref().map(|g| format!(", clips {g}")).unwrap_or_default();
            Ok((train, valid, format!("{}{chosen} (validation: {vglob})", path.display())))
        }
        None => {
            if a.glob.is_some() || a.valid_glob.is_some() {
                bail!("--glob and --valid-glob choose clips of --data; give --data PATH or leave them out");
            }
            crate::cmd::train::load_clips(&None, &None, a.synth_minutes, a.seed, false)
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
) -> anyhow::Result<Windows> {
    let enc: Vec<EncodedClip> = clips
        .iter()
        .map(|c| spec.encode(&c.clip).with_context(|| format!("{what} clip {}", c.path.display())))
        .collect::<anyhow::Result<_>>()?;
    let w = Windows::from_clips(&enc, norm, config.train.window, config.train.window_stride)?;
    if w.is_empty() {
        bail!("no {what} window of {} frames: the {what} clips are too short or too few", config.train.window);
    }
    Ok(w)
}

/// Copies the model files of a stage's best checkpoint up into the run folder.
fn publish(from: &Path, out: &Path, refiner: bool) -> anyhow::Result<()> {
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
            let tmp = out.join(format!(".{f}.tmp"));
            std::fs::copy(&src, &tmp).with_context(|| format!("copying {} to {}", src.display(), tmp.display()))?;
            std::fs::rename(&tmp, out.join(f)).with_context(|| format!("writing {}", out.join(f).display()))?;
        }
    }
    Ok(())
}

/// Runs `zoo train rnn-gmm`.
pub fn run(a: RnnGmmArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    if a.data.is_none() {
        let cfg = SynthConfig::default();
        crate::args::check_synth_size(("--synth-minutes", a.synth_minutes), cfg.clip_seconds, cfg.fps)
            .map_err(anyhow::Error::msg)?;
    }
    let p = plan(&a)?;
    let (train, valid, source) = load(&a)?;
    let Some(first) = train.first() else { bail!("no training clips in {source}") };
    if valid.is_empty() {
        bail!("no validation clips in {source}");
    }
    let fps = first.clip.fps();
    let gen_dir = p.out.join(GENERATOR_DIR);
    let train_refs: Vec<&zoo_motion::Clip> = train.iter().map(|c| &c.clip).collect();
    let valid_refs: Vec<&zoo_motion::Clip> = valid.iter().map(|c| &c.clip).collect();

    if p.generator {
        let (mut trainer, data) = if p.resume_generator {
            let from = train_loop::resume_dir(&gen_dir);
            let trainer = GeneratorTrainer::load(&from, &device)
                .with_context(|| format!("resuming the generator from {}", from.display()))?;
            let (spec, norm, config) = (trainer.spec().clone(), trainer.norm().clone(), trainer.config().clone());
            let tw = windows_with(&spec, &norm, &config, &train, "training")?;
            let vw = windows_with(&spec, &norm, &config, &valid, "validation")?;
            (trainer, TrainingData { spec, norm, train: tw, valid: vw })
        } else {
            let mut config = match a.preset {
                RnnGmmPreset::Paper => Config::paper(),
                RnnGmmPreset::Tiny => Config::tiny(),
            };
            config.train.seed = a.seed;
            config.refiner.seed = a.seed;
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
        let threads = crate::cmd::train::default_threads(a.threads);
        trainer.set_threads(threads)?;
        println!("generator training threads: {threads} (data-parallel; --threads to change)");
        let seed = trainer.config().train.seed;
        let mut training = GeneratorTraining::new(trainer, &data.train, &data.valid)?;
        let opts = TrainOptions {
            time_limit: minutes(a.time_limit),
            resume: p.resume_generator,
            data: source.clone(),
            ..TrainOptions::new(&gen_dir, a.epochs, seed)
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
    }

    if let Some(resume) = p.refiner {
        let ref_dir = p.out.join(REFINER_DIR);
        let (config, spec, norm) =
            rck::read_meta(&gen_dir).with_context(|| format!("reading the generator in {}", gen_dir.display()))?;
        let tw = windows_with(&spec, &norm, &config, &train, "training")?;
        let vw = windows_with(&spec, &norm, &config, &valid, "validation")?;
        // A resumed stage keeps its own refiner settings; a fresh one takes the generator's
        // (the preset's) with the command's overrides.
        let refiner_config = if resume {
            let from = train_loop::resume_dir(&ref_dir);
            rck::read_meta(&from).with_context(|| format!("resuming the refiner from {}", from.display()))?.0.refiner
        } else {
            let mut r = config.refiner.clone();
            if let Some(n) = a.refiner_warmup {
                (r.warmup_refiner, r.warmup_discriminator) = (n, n);
            }
            r.lambda = a.refiner_lambda.unwrap_or(r.lambda);
            r.skate_weight = a.refiner_skate_weight.unwrap_or(r.skate_weight);
            r.range_weight = a.refiner_range_weight.unwrap_or(r.range_weight);
            r.range_percentile = a.refiner_range_percentile.unwrap_or(r.range_percentile);
            r.fake_lead_frames = a.refiner_fake_lead.unwrap_or(r.fake_lead_frames);
            r.fresh_fakes = a.refiner_fresh_fakes.unwrap_or(r.fresh_fakes);
            // Settings newer than the generator's config.json take this version's defaults.
            let new = zoo_rnngmm::RefinerConfig::default();
            r.joint_limits = a.refiner_joint_limits.unwrap_or(new.joint_limits);
            r.root_smoothing = a.refiner_root_smoothing.unwrap_or(new.root_smoothing);
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
        let threads = crate::cmd::train::default_threads(a.threads);
        trainer.set_threads(threads)?;
        println!("refiner training threads: {threads} (data-parallel; --threads to change)");
        let mut training = AdversarialTraining::new(trainer, &tw).with_rounds_per_epoch(a.refiner_rounds);
        let opts = TrainOptions {
            time_limit: minutes(a.refiner_time_limit.or(a.time_limit)),
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
                return Err(anyhow::Error::new(e).context(format!(
                    "the refiner stage stopped; its best checkpoint so far is in {}",
                    p.out.display()
                )));
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
    }
    Ok(())
}
