//! `zoo train arnn`: the keyframe autocompletion network (Zhang & van de Panne 2018) on hop
//! sequences of the simulated lamp, from a folder written by `zoo data luxo` or generated in
//! memory. Ends with the test error of completion against linear and spline interpolation.

use crate::cmd::complete::DofSeries;
use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Duration;
use zoo_arnn::luxo::preprocess::{self, KeyedSequence};
use zoo_arnn::luxo::{self, DOF_NAMES, GenerateOptions, LampParams, LuxoSequence};
use zoo_arnn::{Architecture, ArnnConfig, ArnnTrainer, NoMemoryOutput};
use zoo_nn::checkpoint;
use zoo_nn::train_loop::{self, TrainOptions};

/// Which ARNN to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ArnnVariant {
    /// The paper's ARNN with its curriculum (omega annealing and scheduled sampling).
    Arnn,
    /// Table 1's "no curriculum": omega = 1 and no teacher forcing from the start.
    NoCurriculum,
    /// Table 2's no-memory net: a keyframe-conditioned feed-forward net (keys and t_rel in, a
    /// residual on the keys' linear interpolation out), its widths matched to the ARNN's
    /// parameter count; the ARNN's curriculum.
    NoMemory,
    /// Table 2's segregated net: an RNN with no keyframe input plus a keyframe-conditioned
    /// feed-forward correction, parameter count matched to the ARNN's; the ARNN's curriculum.
    Segregated,
}

impl ArnnVariant {
    /// The configuration of this variant from the ARNN's.
    pub fn configure(self, arnn: &ArnnConfig) -> ArnnConfig {
        let mut c = match self {
            ArnnVariant::Arnn | ArnnVariant::NoCurriculum => arnn.clone(),
            ArnnVariant::NoMemory => arnn.with_matched_architecture(Architecture::NoMemory),
            ArnnVariant::Segregated => arnn.with_matched_architecture(Architecture::Segregated),
        };
        c.curriculum.enabled = self != ArnnVariant::NoCurriculum;
        c
    }
}

/// What the no-memory net's output is added to ([`NoMemoryOutput`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum NoMemoryOutputArg {
    /// Nothing: the output is the pose (the first design).
    Pose,
    /// A residual on the pose of the last key.
    KeyResidual,
    /// A residual on the keys' linear interpolation.
    Interpolation,
}

impl From<NoMemoryOutputArg> for NoMemoryOutput {
    fn from(a: NoMemoryOutputArg) -> Self {
        match a {
            NoMemoryOutputArg::Pose => NoMemoryOutput::Pose,
            NoMemoryOutputArg::KeyResidual => NoMemoryOutput::KeyResidual,
            NoMemoryOutputArg::Interpolation => NoMemoryOutput::Interpolation,
        }
    }
}

/// Sizes of the ARNN to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ArnnPreset {
    /// The paper's sizes (`ArnnConfig::paper`: GRUs of 100, decoder of 10).
    Paper,
    /// A small model for tests and quick checks (`ArnnConfig::tiny`).
    Tiny,
}

/// Arguments of `zoo train arnn`.
#[derive(Args)]
pub struct ArnnArgs {
    /// Folder written by `zoo data luxo`; without it, lamp hops are generated in memory
    /// (`--sequences`, `--k-max`, deterministic for `--seed`). With `--valid-glob`: a folder
    /// (or file) of humanoid BVH clips instead (docs/arnn.md, "Humanoid keys").
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Train on humanoid BVH clips in `--data` (not the lamp): clips whose file name matches
    /// this glob are the validation split (bandai2: `'*_youthful_*'`), the others the training
    /// split; keys are drawn every 5-30 frames and in the in-betweening benchmark's layout.
    #[arg(long, requires = "data")]
    pub valid_glob: Option<String>,
    /// Sequences generated when `--data` is not given.
    #[arg(long, default_value_t = 24, conflicts_with = "data", allow_hyphen_values = true, value_parser = crate::args::sequences)]
    pub sequences: usize,
    /// Simulated annealing iterations per run for the generated sequences (the paper's
    /// K_max = 1000; fewer is faster and gives hops closer to the hand-set one).
    #[arg(long, default_value_t = 100, conflicts_with = "data", allow_hyphen_values = true, value_parser = crate::args::anneal_iterations)]
    pub k_max: usize,
    /// Fraction of the sequences held out as the test set (whole sequences, fixed by `--seed`;
    /// 0.2 gives the paper's 240/60 of 300). The test set also picks the best checkpoint.
    #[arg(long, default_value_t = 0.2, allow_hyphen_values = true, value_parser = crate::args::unit_fraction, conflicts_with = "valid_glob")]
    pub test_fraction: f64,
    /// Epochs to train (an epoch visits every training sequence once). The curriculum spans
    /// this many epochs: with `--time-limit`, choose epochs that fit in it.
    #[arg(long, default_value_t = 300, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub epochs: usize,
    /// Stop after this many minutes of training (the epoch in progress finishes first).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub time_limit: Option<f64>,
    /// Run folder: config, weights, statistics, loss curve and summary.
    #[arg(long, default_value = "runs/arnn")]
    pub out: PathBuf,
    /// Continue the run in this folder (its config, data and split are kept; `--epochs` is
    /// the new total).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run already in `--out`. Without it, `--out` on a folder that holds a run is
    /// refused.
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Model variant: the ARNN, or a comparison of Table 1 (no curriculum) or Table 2
    /// (no-memory, segregated; parameter counts matched to the ARNN's).
    #[arg(long, value_enum, default_value_t = ArnnVariant::Arnn)]
    pub variant: ArnnVariant,
    /// With `--variant no-memory`: what the net's output is added to [default: interpolation]
    /// (docs/arnn.md, "Table 2 and the no-memory net's output")
    #[arg(long, value_enum)]
    pub no_memory_output: Option<NoMemoryOutputArg>,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = ArnnPreset::Paper)]
    pub preset: ArnnPreset,
    /// Sequences per batch [default: the preset's].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::batch_size)]
    pub batch_size: Option<usize>,
    /// Adam learning rate [default: the preset's; paper: 1e-3].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::learning_rate)]
    pub lr: Option<f64>,
    /// Weight of the ground penalty on the base plate sinking below the ground [default: 0,
    /// off] (docs/arnn.md, "The ground"; `zoo complete` lifts a sunken base onto the ground).
    #[arg(long, allow_hyphen_values = true, value_parser = ground_weight)]
    pub ground_weight: Option<f64>,
    /// Fraction of the epochs, at the end, trained after the curriculum with the key weight at
    /// `--frame-phase-omega` (section 9's extra training that weights the frame loss more; the
    /// curriculum's ramps then run over the other epochs; 0: the paper's schedule alone)
    /// [default: 0.25 for lamp runs, 0 for humanoid clips] (docs/arnn.md, "The frame phase")
    #[arg(long, allow_hyphen_values = true, value_parser = frame_phase)]
    pub frame_phase: Option<f64>,
    /// Key importance omega in the frame phase (the key loss weighs `100 omega` there)
    /// [default: 0.01]
    #[arg(long, allow_hyphen_values = true, value_parser = frame_phase_omega)]
    pub frame_phase_omega: Option<f64>,
    /// Seed of the generated data, the split, the weights and the trainer.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Data-parallel training threads (`1..=256`) [default: the cores available]: the same
    /// update as one thread up to float summation order; reproducible for a fixed seed and
    /// thread count.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::cmd::train::training_threads)]
    pub threads: Option<usize>,
}

/// `--frame-phase`: a fraction in [0, 1).
fn frame_phase(s: &str) -> Result<f64, String> {
    crate::args::real_in(s, crate::args::Interval { lo: 0.0, lo_open: false, hi: 1.0, hi_open: true }, "")
}

/// `--frame-phase-omega`: a weight in [0, 1].
fn frame_phase_omega(s: &str) -> Result<f64, String> {
    crate::args::real_in(s, crate::args::Interval::closed(0.0, 1.0), "")
}

/// `--ground-weight`: a weight in [0, 1e6].
fn ground_weight(s: &str) -> Result<f64, String> {
    crate::args::real_in(s, crate::args::Interval::closed(0.0, 1e6), "")
}

/// Where a run's sequences come from, recorded in `train_state.json` so that `--resume`
/// rebuilds the same training and test sets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataSettings {
    /// Folder of `zoo data luxo`, or `None` for sequences generated in memory.
    pub dir: Option<PathBuf>,
    /// Generated sequences (when `dir` is `None`).
    pub sequences: usize,
    /// Annealing iterations of the generated sequences.
    pub k_max: usize,
    /// Seed of the generated sequences and of the split.
    pub seed: u64,
    /// Fraction of the sequences in the test set.
    pub test_fraction: f64,
}

/// The plot of a test sequence written at the end of training.
pub const PLOT_FILE: &str = "completion_test.png";

/// The files and folders of a run that `--overwrite` deletes (the ones training writes).
const RUN_FILES: [&str; 10] = [
    PLOT_FILE,
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

/// The run folder, checked before any data is generated or loaded (as `zoo train rtn` does).
pub(crate) fn prepare_run_folder(a: &ArnnArgs) -> anyhow::Result<PathBuf> {
    crate::cmd::train::prepare_run_folder_for(&a.out, a.resume.as_deref(), a.overwrite, &RUN_FILES, |dir| {
        let kind = zoo_nn::checkpoint::model_kind(dir)?;
        if kind != "arnn" {
            bail!(
                "--resume {}: the folder holds a `{kind}` run, not an ARNN (train it with `zoo train {kind}`)",
                dir.display()
            );
        }
        Ok(())
    })
}

/// The raw sequences and the lamp they were simulated with.
fn load_sequences(settings: &DataSettings) -> anyhow::Result<(Vec<LuxoSequence>, LampParams, String)> {
    match &settings.dir {
        Some(dir) => {
            if !dir.is_dir() {
                bail!("--data {}: no such folder (write one with `zoo data luxo --out {0}`)", dir.display());
            }
            let seqs = luxo::load_dir(dir).with_context(|| format!("--data {}", dir.display()))?;
            let lamp = match luxo::read_options(dir) {
                Ok(o) => o.lamp,
                Err(e) => {
                    eprintln!("note: {e}; assuming the default lamp for the BVH of `zoo complete`");
                    LampParams::default()
                }
            };
            let source = format!("{} ({} lamp sequences)", dir.display(), seqs.len());
            Ok((seqs, lamp, source))
        }
        None => {
            let mut options = GenerateOptions::new(settings.sequences, settings.seed);
            options.anneal.k_max = settings.k_max;
            let bar = ProgressBar::new(settings.sequences as u64);
            bar.set_style(
                ProgressStyle::with_template("generating lamp hops [{bar:30}] {pos}/{len} {elapsed} (eta {eta})")
                    .expect("template"),
            );
            let seqs = luxo::generate_in_memory(&options, &|| bar.inc(1)).context("generating lamp hops")?;
            bar.finish_and_clear();
            let source = format!(
                "{} lamp sequences generated in memory (seed {}, K_max {})",
                settings.sequences, settings.seed, settings.k_max
            );
            Ok((seqs, options.lamp, source))
        }
    }
}

/// Training and test sets: preprocessed sequences split by the settings' seed.
pub struct LampData {
    /// Training sequences.
    pub train: Vec<KeyedSequence>,
    /// Test sequences (validation during training).
    pub test: Vec<KeyedSequence>,
    /// The lamp.
    pub lamp: LampParams,
    /// Where the data came from, in words.
    pub source: String,
}

/// Loads or generates the sequences of `settings`, preprocesses and splits them.
pub fn lamp_data(settings: &DataSettings) -> anyhow::Result<LampData> {
    let (raw, lamp, source) = load_sequences(settings)?;
    let mut seqs = Vec::with_capacity(raw.len());
    for s in &raw {
        seqs.push(preprocess::preprocess(s).with_context(|| format!("preprocessing {}", s.name))?);
    }
    if seqs.len() < 2 {
        bail!("need at least 2 lamp sequences (one to train on, one to test), found {}", seqs.len());
    }
    let len = seqs[0].frames.len();
    if let Some(s) = seqs.iter().find(|s| s.frames.len() != len) {
        bail!(
            "{} has {} frames and {} has {len}: the sequences must have one number of hops (regenerate them with one \
             `zoo data luxo` run)",
            s.name,
            s.frames.len(),
            seqs[0].name
        );
    }
    let split = preprocess::split(seqs.len(), settings.test_fraction, settings.seed)?;
    let pick = |idx: &[usize]| idx.iter().map(|&i| seqs[i].clone()).collect::<Vec<_>>();
    let (train, test) = (pick(&split.train), pick(&split.test));
    if test.is_empty() {
        bail!("--test-fraction {} leaves no test sequence out of {}", settings.test_fraction, seqs.len());
    }
    Ok(LampData { train, test, lamp, source })
}

/// The frame phase of a new lamp run with the curriculum when `--frame-phase` is not given.
pub const DEFAULT_FRAME_PHASE: f64 = 0.25;
/// Omega in the frame phase when `--frame-phase-omega` is not given.
pub const DEFAULT_FRAME_PHASE_OMEGA: f64 = 0.01;

/// `--frame-phase` and `--frame-phase-omega` into a new run's curriculum: without
/// `--frame-phase`, [`DEFAULT_FRAME_PHASE`] where `default_on` (a lamp run with the curriculum),
/// none elsewhere (humanoid clips: not measured there). Refuses `--frame-phase-omega` for a
/// run without a frame phase, where it would do nothing.
pub(crate) fn set_frame_phase(a: &ArnnArgs, config: &mut ArnnConfig, default_on: bool) -> anyhow::Result<()> {
    (config.curriculum.frame_phase, config.curriculum.frame_phase_omega) = frame_phase_of(a, default_on)?;
    Ok(())
}

/// The frame phase and its omega that [`set_frame_phase`] sets.
fn frame_phase_of(a: &ArnnArgs, default_on: bool) -> anyhow::Result<(f64, f64)> {
    let f = a.frame_phase.unwrap_or(if default_on { DEFAULT_FRAME_PHASE } else { 0.0 });
    if f == 0.0 && a.frame_phase_omega.is_some() {
        bail!(
            "--frame-phase-omega sets omega in the frame phase, and this run has none: add --frame-phase 0.25 or drop it"
        );
    }
    Ok((f, if f > 0.0 { a.frame_phase_omega.unwrap_or(DEFAULT_FRAME_PHASE_OMEGA) } else { 1.0 }))
}

/// How a curriculum ends, for the start-up line: its frame phase, if any.
fn phase_note(c: &zoo_arnn::Curriculum) -> String {
    if c.enabled && c.frame_phase > 0.0 {
        format!(" (the last {}% a frame phase with omega {})", c.frame_phase * 100.0, c.frame_phase_omega)
    } else {
        String::new()
    }
}

/// Runs `zoo train arnn`.
pub fn run(a: ArnnArgs) -> anyhow::Result<()> {
    // `--frame-phase 0` (none) fits a run without a curriculum.
    let phase_args = a.frame_phase.is_some_and(|f| f > 0.0) || a.frame_phase_omega.is_some();
    if (phase_args && a.variant == ArnnVariant::NoCurriculum)
        || ((a.frame_phase.is_some() || a.frame_phase_omega.is_some()) && a.resume.is_some())
    {
        bail!(
            "--frame-phase and --frame-phase-omega are settings of a new run's curriculum (a resumed run keeps its \
             own; `--variant no-curriculum` has no curriculum to follow): drop them, or start a new run with another \
             variant"
        );
    }
    if a.no_memory_output.is_some() && (a.variant != ArnnVariant::NoMemory || a.resume.is_some()) {
        bail!(
            "--no-memory-output is a setting of a new `--variant no-memory` lamp run (a resumed run keeps its own); \
             drop it or add --variant no-memory"
        );
    }
    if a.resume.is_none() {
        // Checked before any data is read or generated.
        frame_phase_of(&a, a.valid_glob.is_none() && a.variant != ArnnVariant::NoCurriculum)?;
    }
    if a.valid_glob.is_some() || a.resume.as_deref().is_some_and(crate::cmd::train_arnn_humanoid::is_humanoid_run) {
        return crate::cmd::train_arnn_humanoid::run(a);
    }
    let device = candle_core::Device::Cpu;
    if a.test_fraction >= 1.0 {
        bail!("--test-fraction {} must be below 1 (0.2 holds out a fifth of the sequences)", a.test_fraction);
    }
    let out = prepare_run_folder(&a)?;
    let mut extra = serde_json::Map::new();
    let (settings, variant, resumed) = match &a.resume {
        Some(dir) => {
            let state = train_loop::read_state(dir)?;
            let stored = state.extra.get("data_settings").cloned().context(format!(
                "{}: train_state.json has no data_settings (not written by `zoo train arnn`)",
                dir.display()
            ))?;
            let mut settings: DataSettings = serde_json::from_value(stored)?;
            if let Some(d) = &a.data {
                if settings.dir.as_ref() != Some(d) {
                    if settings.dir.is_none() {
                        bail!("--resume {}: the run trained on generated sequences, not on --data", dir.display());
                    }
                    println!("note: the run trained on {:?}; reading it from {} now", settings.dir, d.display());
                }
                settings.dir = Some(d.clone());
            }
            let variant = state.extra.get("variant").and_then(|v| serde_json::from_value(v.clone()).ok());
            (settings, variant.unwrap_or(a.variant), true)
        }
        None => {
            let settings = DataSettings {
                dir: a.data.clone(),
                sequences: a.sequences,
                k_max: a.k_max,
                seed: a.seed,
                test_fraction: a.test_fraction,
            };
            extra.insert("data_settings".into(), serde_json::to_value(&settings)?);
            extra.insert("variant".into(), serde_json::to_value(a.variant)?);
            (settings, a.variant, false)
        }
    };
    let data = lamp_data(&settings)?;
    if !resumed {
        extra.insert("test_sequences".into(), data.test.iter().map(|s| s.name.clone()).collect());
    }
    let trainer = if resumed {
        let from = train_loop::resume_dir(&out);
        let (config, norm) = zoo_arnn::checkpoint::read_meta(&from)
            .with_context(|| format!("resuming from {}: it holds no ARNN checkpoint", from.display()))?;
        ArnnTrainer::with_normalization(&config, norm, data.train.clone(), data.test.clone(), &device)?
    } else {
        let mut config = match a.preset {
            ArnnPreset::Paper => ArnnConfig::paper(),
            ArnnPreset::Tiny => ArnnConfig::tiny(),
        };
        config.dof_names = DOF_NAMES.iter().map(|s| s.to_string()).collect();
        config.lamp = Some(data.lamp.clone());
        if let Some(b) = a.batch_size {
            config.batch_size = b;
        }
        if let Some(lr) = a.lr {
            config.learning_rate = lr;
        }
        config.seed = a.seed;
        let steps_per_epoch = data.train.len().div_ceil(config.batch_size) as u64;
        config.curriculum.total_steps = steps_per_epoch * a.epochs as u64;
        if let Some(w) = a.ground_weight {
            config.ground_weight = w;
        }
        set_frame_phase(&a, &mut config, variant != ArnnVariant::NoCurriculum)?;
        let mut config = variant.configure(&config);
        if let Some(o) = a.no_memory_output {
            config.no_memory_output = o.into();
        }
        ArnnTrainer::new(&config, data.train.clone(), data.test.clone(), &device)?
    };
    println!(
        "training ARNN ({variant:?}) on {}: {} training / {} test sequences of {} frames, {} parameters, curriculum \
         over {} steps{}, run folder {}",
        data.source,
        data.train.len(),
        data.test.len(),
        data.train[0].frames.len(),
        trainer.parameter_count(),
        trainer.config().curriculum.total_steps,
        phase_note(&trainer.config().curriculum),
        out.display()
    );
    let seed = trainer.config().seed;
    let mut trainer = trainer;
    let threads = crate::cmd::train::default_threads(a.threads);
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    let mut extra = extra;
    extra.insert("threads".into(), threads.into());
    let opts = TrainOptions {
        // A limit too large for a Duration is no limit.
        time_limit: a.time_limit.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok()),
        resume: resumed,
        data: data.source.clone(),
        extra,
        ..TrainOptions::new(&out, a.epochs, seed)
    };
    let state = train_loop::train(&mut trainer, &opts)?;
    println!(
        "done: {} epochs ({} steps) in {:.1} min, best test loss {:.5} at epoch {}; model in {}",
        state.epoch,
        state.steps,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        out.display()
    );
    // The best checkpoint against interpolation of the same keys, recorded in summary.json.
    let (model, norm) = zoo_arnn::checkpoint::load(&out, &device)
        .with_context(|| format!("loading the best checkpoint in {}", out.display()))?;
    let r = zoo_arnn::eval::evaluate(&model, &norm, &data.test)?;
    let completion = crate::cmd::eval_arnn::print_report(&r);
    // Figure 8: the first test sequence, ground truth, spline and ARNN, keys circled.
    let seq = &data.test[0];
    let poses: Vec<Vec<f64>> = seq.keys.iter().map(|&k| seq.frames[k].to_vec()).collect();
    let arnn = zoo_arnn::complete(&model, &norm, &seq.keys, &poses)?;
    let spline = zoo_arnn::eval::cubic_spline(&seq.keys, &poses);
    let truth: Vec<Vec<f64>> = seq.frames.iter().map(|f| f.to_vec()).collect();
    let keyed: Vec<(usize, Vec<f64>)> = seq.keys.iter().copied().zip(poses).collect();
    let plot = out.join(PLOT_FILE);
    crate::cmd::complete::plot_dofs(
        &plot,
        &[
            DofSeries { frames: &truth, rgb: (150, 220, 150), width: 5.0 },
            DofSeries { frames: &spline, rgb: (170, 170, 170), width: 1.5 },
            DofSeries { frames: &arnn, rgb: (31, 80, 180), width: 2.0 },
        ],
        &keyed,
    )?;
    println!("{}: {} completed (blue) against the simulation (green) and the spline (grey)", plot.display(), seq.name);
    let summary_path = out.join(checkpoint::SUMMARY_FILE);
    let mut summary: serde_json::Map<String, serde_json::Value> = checkpoint::read_json(&summary_path)?;
    summary.insert("completion".into(), completion);
    checkpoint::write_json(&summary_path, &summary)?;
    Ok(())
}
