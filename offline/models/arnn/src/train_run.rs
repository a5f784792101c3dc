//! The training command of the ARNN (`zoo train arnn`): the keyframe autocompletion network
//! (Zhang & van de Panne 2018) on hop sequences of the simulated lamp, from a folder written by
//! `zoo data luxo` or generated in memory, ending with the test error of completion against
//! linear and spline interpolation; or on humanoid BVH clips ([`train_humanoid`]); and the
//! evaluation of a lamp run (`zoo eval-arnn`, [`evaluate_run`]).

use crate::completion::DofSeries;
use crate::eval::{CompletionError, CompletionReport};
use crate::luxo::preprocess::{self, KeyedSequence};
use crate::luxo::{self, DOF_NAMES, GenerateOptions, LampParams, LuxoSequence};
use crate::{Architecture, ArnnConfig, ArnnResult, ArnnTrainer, NoMemoryOutput, humanoid};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use zoo_data::dataset::{NamedClip, Windows};
use zoo_data::{Context, Message, Progress, bail};
use zoo_nn::checkpoint;
use zoo_nn::run_folder::RunSpec;
use zoo_nn::train_loop::{self, TrainOptions};

/// Which ARNN to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
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

/// Which network `zoo train arnn` trains.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ArnnDesign {
    /// The paper's autoregressive ARNN (lamp or humanoid clips).
    #[default]
    Autoregressive,
    /// Humanoid clips only: the bidirectional GRU over the whole shot that corrects Blender's
    /// Bezier curves through the keys, the keys met by construction ([`crate::inbetween`]).
    Inbetween,
}

/// What the no-memory net's output is added to ([`NoMemoryOutput`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
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
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ArnnPreset {
    /// The paper's sizes (`ArnnConfig::paper`: GRUs of 100, decoder of 10; with `--design
    /// inbetween`, `InbetweenConfig::humanoid`).
    Paper,
    /// The in-betweening design to try in minutes (`InbetweenConfig::quick`: widths of 128;
    /// [`QUICK_INBETWEEN_EPOCHS`] epochs and, without `--data`, [`QUICK_SYNTH_MINUTES`] of
    /// synthetic locomotion unless given): about 5 minutes of one thread, under half Bezier's
    /// pose error from keys 10 frames apart on held-out synthetic clips (docs/keys-only.md).
    /// `--design inbetween` only.
    Quick,
    /// A small model for tests (`ArnnConfig::tiny`, `InbetweenConfig::tiny`).
    Tiny,
}

/// The options of `zoo train arnn` (`None`: the preset's or the default value).
#[derive(Clone, Debug)]
pub struct ArnnRunOptions {
    /// The run folder, its length, seed and threads.
    pub run: RunSpec,
    /// A `zoo data luxo` folder (lamp), or humanoid BVH clips with `valid_glob`.
    pub data: Option<PathBuf>,
    /// Humanoid clips: the validation split of `data`.
    pub valid_glob: Option<String>,
    /// Humanoid clips: clips of `data` left out of both splits (a held-out content).
    pub exclude_glob: Option<String>,
    /// Lamp sequences generated without `data`.
    pub sequences: usize,
    /// Simulated annealing iterations per run for the generated sequences.
    pub k_max: usize,
    /// Fraction of the lamp sequences held out as the test set.
    pub test_fraction: f64,
    /// Model variant.
    pub variant: ArnnVariant,
    /// Which network: the paper's ARNN or the in-betweening design (humanoid clips).
    pub design: ArnnDesign,
    /// With the no-memory variant: what the net's output is added to.
    pub no_memory_output: Option<NoMemoryOutputArg>,
    /// Model sizes.
    pub preset: ArnnPreset,
    /// Whether `--epochs` was given (the quick preset has its own epochs otherwise).
    pub epochs_given: bool,
    /// The in-betweening design without `--data`: minutes of synthetic locomotion.
    pub synth_minutes: Option<f64>,
    /// The in-betweening design with `data`: minutes of synthetic locomotion mixed into the
    /// training split.
    pub synth_mix: Option<f64>,
    /// The in-betweening design: fraction of batches in the transition layout.
    pub transition_fraction: Option<f64>,
    /// The in-betweening design: dropout in training.
    pub dropout: Option<f64>,
    /// The in-betweening design: the network over the shot.
    pub backbone: Option<crate::inbetween::Backbone>,
    /// Sequences per batch.
    pub batch_size: Option<usize>,
    /// Adam learning rate.
    pub lr: Option<f64>,
    /// Weight of the ground penalty on the base plate.
    pub ground_weight: Option<f64>,
    /// Fraction of the epochs, at the end, trained after the curriculum (the frame phase).
    pub frame_phase: Option<f64>,
    /// Key importance omega in the frame phase.
    pub frame_phase_omega: Option<f64>,
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
fn run_files() -> Vec<&'static str> {
    std::iter::once(PLOT_FILE).chain(zoo_nn::run_folder::COMMON_RUN_FILES).collect()
}

/// The run folder, checked before any data is generated or loaded (as `zoo train rtn` does).
fn prepare_run_folder(o: &ArnnRunOptions) -> ArnnResult<PathBuf> {
    Ok(zoo_nn::run_folder::prepare(&o.run, &run_files(), |dir| {
        let kind = zoo_nn::checkpoint::model_kind(dir)?;
        if kind != "arnn" {
            return Err(zoo_nn::TrainError::Config(format!(
                "--resume {}: the folder holds a `{kind}` run, not an ARNN (train it with `zoo train {kind}`)",
                dir.display()
            )));
        }
        Ok(())
    })?)
}

/// The raw sequences and the lamp they were simulated with.
fn load_sequences(settings: &DataSettings, p: &dyn Progress) -> ArnnResult<(Vec<LuxoSequence>, LampParams, String)> {
    match &settings.dir {
        Some(dir) => {
            if !dir.is_dir() {
                bail!("--data {}: no such folder (write one with `zoo data luxo --out {0}`)", dir.display());
            }
            let seqs = luxo::load_dir(dir).with_context(|| format!("--data {}", dir.display()))?;
            let lamp = match luxo::read_options(dir) {
                Ok(o) => o.lamp,
                Err(e) => {
                    p.notice(&format!("note: {e}; assuming the default lamp for the BVH of `zoo complete`"));
                    LampParams::default()
                }
            };
            let source = format!("{} ({} lamp sequences)", dir.display(), seqs.len());
            Ok((seqs, lamp, source))
        }
        None => {
            let mut options = GenerateOptions::new(settings.sequences, settings.seed);
            options.anneal.k_max = settings.k_max;
            p.start(settings.sequences as u64, "generating lamp hops");
            let seqs = luxo::generate_in_memory(&options, &|| p.advance(1)).context("generating lamp hops")?;
            p.finish();
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
pub fn lamp_data(settings: &DataSettings, p: &dyn Progress) -> ArnnResult<LampData> {
    let (raw, lamp, source) = load_sequences(settings, p)?;
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
fn set_frame_phase(a: &ArnnRunOptions, config: &mut ArnnConfig, default_on: bool) -> ArnnResult<()> {
    (config.curriculum.frame_phase, config.curriculum.frame_phase_omega) = frame_phase_of(a, default_on)?;
    Ok(())
}

/// The frame phase and its omega that [`set_frame_phase`] sets.
fn frame_phase_of(a: &ArnnRunOptions, default_on: bool) -> ArnnResult<(f64, f64)> {
    let f = a.frame_phase.unwrap_or(if default_on { DEFAULT_FRAME_PHASE } else { 0.0 });
    if f == 0.0 && a.frame_phase_omega.is_some() {
        bail!(
            "--frame-phase-omega sets omega in the frame phase, and this run has none: add --frame-phase 0.25 or drop it"
        );
    }
    Ok((f, if f > 0.0 { a.frame_phase_omega.unwrap_or(DEFAULT_FRAME_PHASE_OMEGA) } else { 1.0 }))
}

/// How a curriculum ends, for the start-up line: its frame phase, if any.
fn phase_note(c: &crate::Curriculum) -> String {
    if c.enabled && c.frame_phase > 0.0 {
        format!(" (the last {}% a frame phase with omega {})", c.frame_phase * 100.0, c.frame_phase_omega)
    } else {
        String::new()
    }
}

/// The data of a humanoid run, recorded in `train_state.json` so that `--resume` rebuilds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HumanoidData {
    /// The BVH folder or file (empty with `synth_minutes`).
    pub dir: PathBuf,
    /// Synthetic locomotion of this many minutes instead of `dir` (seed `seed`; every tenth
    /// clip validates): the in-betweening design without `--data`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synth_minutes: Option<f64>,
    /// Minutes of synthetic locomotion (seed `seed`) mixed into the training split of `dir`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synth_mix: Option<f64>,
    /// Glob of the validation split.
    pub valid_glob: String,
    /// Glob of the clips of `dir` left out of both splits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exclude_glob: Option<String>,
    /// Seed of the validation keys.
    pub seed: u64,
}

const STATE_KEY: &str = "humanoid_data";

/// Whether `dir` holds a humanoid ARNN run (its `train_state.json` records [`HumanoidData`]).
pub fn is_humanoid_run(dir: &Path) -> bool {
    train_loop::read_state(dir).is_ok_and(|s| s.extra.contains_key(STATE_KEY))
}

/// Refuses option combinations of `zoo train arnn` that cannot work, before any data is read.
fn check_options(a: &ArnnRunOptions) -> ArnnResult<()> {
    let humanoid = match &a.run.resume {
        Some(dir) => is_humanoid_run(dir),
        None => a.valid_glob.is_some(),
    };
    if a.exclude_glob.is_some() && !humanoid {
        bail!("--exclude-glob leaves humanoid clips of --data out: pass --data BVH_FOLDER --valid-glob GLOB too");
    }
    // `--frame-phase 0` (none) fits a run without a curriculum.
    let phase_args = a.frame_phase.is_some_and(|f| f > 0.0) || a.frame_phase_omega.is_some();
    let resumed = a.run.resume.is_some();
    if (phase_args && a.variant == ArnnVariant::NoCurriculum)
        || ((a.frame_phase.is_some() || a.frame_phase_omega.is_some()) && resumed)
    {
        bail!(
            "--frame-phase and --frame-phase-omega are settings of a new run's curriculum (a resumed run keeps its \
             own; `--variant no-curriculum` has no curriculum to follow): drop them, or start a new run with another \
             variant"
        );
    }
    if a.no_memory_output.is_some() && (a.variant != ArnnVariant::NoMemory || resumed) {
        bail!(
            "--no-memory-output is a setting of a new `--variant no-memory` lamp run (a resumed run keeps its own); \
             drop it or add --variant no-memory"
        );
    }
    if !resumed {
        frame_phase_of(a, a.valid_glob.is_none() && a.variant != ArnnVariant::NoCurriculum)?;
    }
    Ok(())
}

/// The data settings of a lamp run (a resumed run's recorded ones, `--data` replacing its
/// folder), its variant, and whether it is resumed.
fn lamp_settings(
    a: &ArnnRunOptions,
    extra: &mut serde_json::Map<String, serde_json::Value>,
) -> ArnnResult<(DataSettings, ArnnVariant, bool)> {
    let Some(dir) = &a.run.resume else {
        let settings = DataSettings {
            dir: a.data.clone(),
            sequences: a.sequences,
            k_max: a.k_max,
            seed: a.run.seed,
            test_fraction: a.test_fraction,
        };
        extra.insert("data_settings".into(), serde_json::to_value(&settings).context("the data settings")?);
        extra.insert("variant".into(), serde_json::to_value(a.variant).context("the variant")?);
        return Ok((settings, a.variant, false));
    };
    let state = train_loop::read_state(dir)?;
    let stored = state.extra.get("data_settings").cloned().with_context(|| {
        format!("{}: train_state.json has no data_settings (not written by `zoo train arnn`)", dir.display())
    })?;
    let mut settings: DataSettings = serde_json::from_value(stored).context("the recorded data settings")?;
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
    Ok((settings, variant.unwrap_or(a.variant), true))
}

/// The trainer of a fresh lamp run: the preset, the lamp, the options and the variant.
fn fresh_lamp_trainer(a: &ArnnRunOptions, data: &LampData, variant: ArnnVariant) -> ArnnResult<ArnnTrainer> {
    let mut config = match a.preset {
        ArnnPreset::Paper => ArnnConfig::paper(),
        ArnnPreset::Tiny => ArnnConfig::tiny(),
        ArnnPreset::Quick => bail!("{QUICK_ONLY}"),
    };
    config.dof_names = DOF_NAMES.iter().map(|s| s.to_string()).collect();
    config.lamp = Some(data.lamp.clone());
    if let Some(b) = a.batch_size {
        config.batch_size = b;
    }
    if let Some(lr) = a.lr {
        config.learning_rate = lr;
    }
    config.seed = a.run.seed;
    let steps_per_epoch = data.train.len().div_ceil(config.batch_size) as u64;
    config.curriculum.total_steps = steps_per_epoch * a.run.epochs as u64;
    if let Some(w) = a.ground_weight {
        config.ground_weight = w;
    }
    set_frame_phase(a, &mut config, variant != ArnnVariant::NoCurriculum)?;
    let mut config = variant.configure(&config);
    if let Some(o) = a.no_memory_output {
        config.no_memory_output = o.into();
    }
    ArnnTrainer::new(&config, data.train.clone(), data.test.clone(), &candle_core::Device::Cpu)
}

/// The refusal of `--preset quick` outside the in-betweening design.
const QUICK_ONLY: &str = "--preset quick is the in-betweening design's (add --design inbetween); the autoregressive ARNN \
                          takes --preset paper or tiny";

/// Minutes of synthetic locomotion of the in-betweening design without `--data` and
/// `--synth-minutes`.
pub const DEFAULT_SYNTH_MINUTES: f64 = 10.0;

/// Epochs of `--preset quick` when `--epochs` is not given: about 5 minutes of one thread on its
/// [`QUICK_SYNTH_MINUTES`] of synthetic locomotion (docs/keys-only.md, "Try it in minutes").
pub const QUICK_INBETWEEN_EPOCHS: usize = 30;

/// Minutes of synthetic locomotion of `--preset quick` without `--data` and `--synth-minutes`.
pub const QUICK_SYNTH_MINUTES: f64 = 20.0;

/// Runs `zoo train arnn` (a humanoid run with `valid_glob` or on a humanoid run folder).
pub fn run(a: &ArnnRunOptions, p: &dyn Progress) -> ArnnResult<()> {
    let resumed_inbetween = a.run.resume.as_deref().is_some_and(|d| {
        crate::inbetween::is_inbetween_run(d) || crate::inbetween::is_inbetween_run(&train_loop::resume_dir(d))
    });
    if a.design == ArnnDesign::Inbetween || resumed_inbetween {
        return train_inbetween(a, p);
    }
    if a.preset == ArnnPreset::Quick {
        bail!("{QUICK_ONLY}");
    }
    if a.synth_minutes.is_some() {
        bail!(
            "--synth-minutes gives the in-betweening design synthetic locomotion (add --design inbetween); the \
             autoregressive ARNN trains on lamp hops (--sequences) or --data"
        );
    }
    if a.synth_mix.is_some() {
        bail!(
            "--synth-mix mixes synthetic locomotion into the in-betweening design's training (add --design \
             inbetween); the autoregressive ARNN trains on lamp hops (--sequences) or --data"
        );
    }
    if a.backbone.is_some() {
        bail!(
            "--backbone chooses the in-betweening design's network (add --design inbetween); the autoregressive ARNN \
             is its own network"
        );
    }
    if a.dropout.is_some() {
        bail!(
            "--dropout sets the in-betweening design's dropout (add --design inbetween); the autoregressive ARNN's \
             dropout is part of its --preset"
        );
    }
    if a.transition_fraction.is_some() {
        bail!(
            "--transition-fraction sets the in-betweening design's training keys (add --design inbetween); the \
             autoregressive ARNN's humanoid keys already include the benchmark's transition layout"
        );
    }
    check_options(a)?;
    if a.valid_glob.is_some() || a.run.resume.as_deref().is_some_and(is_humanoid_run) {
        return train_humanoid(a, p);
    }
    if a.test_fraction >= 1.0 {
        bail!("--test-fraction {} must be below 1 (0.2 holds out a fifth of the sequences)", a.test_fraction);
    }
    let out = prepare_run_folder(a)?;
    let mut extra = serde_json::Map::new();
    let (settings, variant, resumed) = lamp_settings(a, &mut extra)?;
    let data = lamp_data(&settings, p)?;
    if !resumed {
        extra.insert("test_sequences".into(), data.test.iter().map(|s| s.name.clone()).collect());
    }
    let mut trainer = if resumed {
        let from = train_loop::resume_dir(&out);
        let (config, norm) = crate::checkpoint::read_meta(&from)
            .with_context(|| format!("resuming from {}: it holds no ARNN checkpoint", from.display()))?;
        ArnnTrainer::with_normalization(
            &config,
            norm,
            data.train.clone(),
            data.test.clone(),
            &candle_core::Device::Cpu,
        )?
    } else {
        fresh_lamp_trainer(a, &data, variant)?
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
    let state = train(a, &mut trainer, &out, (data.source.clone(), extra, resumed), seed)?;
    println!("{}", done_line(&state, "test", &out));
    test_best(&out, &data.test)
}

/// The line a finished run prints: epochs, steps, minutes, the best `loss` loss and the folder.
fn done_line(state: &train_loop::TrainState, loss: &str, out: &Path) -> String {
    format!(
        "done: {} epochs ({} steps) in {:.1} min, best {loss} loss {:.5} at epoch {}; model in {}",
        state.epoch,
        state.steps,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        out.display()
    )
}

/// Trains with the shared loop on the run's threads (`data`: the source in words, the fields
/// recorded in `train_state.json`, whether the run is resumed).
fn train(
    a: &ArnnRunOptions,
    trainer: &mut ArnnTrainer,
    out: &Path,
    (source, mut extra, resumed): (String, serde_json::Map<String, serde_json::Value>, bool),
    seed: u64,
) -> ArnnResult<train_loop::TrainState> {
    let threads = a.run.thread_count();
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    extra.insert("threads".into(), threads.into());
    let opts = TrainOptions {
        time_limit: a.run.time_limit(),
        resume: resumed,
        data: source,
        extra,
        ..TrainOptions::new(out, a.run.epochs, seed)
    };
    Ok(train_loop::train(trainer, &opts)?)
}

/// The best checkpoint against interpolation of the same keys (printed, and recorded in
/// summary.json), and the paper's Figure 8 for the first test sequence.
fn test_best(out: &Path, test: &[KeyedSequence]) -> ArnnResult<()> {
    let (model, norm) = crate::checkpoint::load(out, &candle_core::Device::Cpu)
        .with_context(|| format!("loading the best checkpoint in {}", out.display()))?;
    let r = crate::eval::evaluate(&model, &norm, test)?;
    println!("{}", report_text(&r));
    let completion = serde_json::to_value(&r).unwrap_or_default();
    // Figure 8: the first test sequence, ground truth, spline and ARNN, keys circled.
    let seq = &test[0];
    let poses: Vec<Vec<f64>> = seq.keys.iter().map(|&k| seq.frames[k].to_vec()).collect();
    let arnn = crate::complete(&model, &norm, &seq.keys, &poses)?;
    let spline = crate::eval::cubic_spline(&seq.keys, &poses);
    let truth: Vec<Vec<f64>> = seq.frames.iter().map(|f| f.to_vec()).collect();
    let keyed: Vec<(usize, Vec<f64>)> = seq.keys.iter().copied().zip(poses).collect();
    let plot = out.join(PLOT_FILE);
    crate::completion::plot_dofs(
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

impl HumanoidData {
    /// Loads the clips, splits them by `valid_glob` and cuts both splits into the humanoid
    /// training windows ([`humanoid::WINDOW`]); refuses a split without a window.
    fn load(&self, p: &dyn Progress) -> ArnnResult<(Vec<NamedClip>, Vec<NamedClip>, Windows, Windows)> {
        let (train_clips, valid_clips) = match self.synth_minutes {
            Some(minutes) => {
                let t = zoo_data::dataset::TrainingClips {
                    data: None,
                    valid_glob: None,
                    exclude_glob: None,
                    skip_invalid: false,
                    synth_minutes: minutes,
                    seed: self.seed,
                };
                let (train, valid, _) = zoo_data::dataset::training_clips(&t, p).map_err(|e| Message::new(e.0))?;
                (train, valid)
            }
            None => {
                let t = zoo_data::dataset::TrainingClips {
                    data: Some(self.dir.clone()),
                    valid_glob: Some(self.valid_glob.clone()),
                    exclude_glob: self.exclude_glob.clone(),
                    skip_invalid: false,
                    synth_minutes: 0.0,
                    seed: self.seed,
                };
                let (mut train, valid, _) = zoo_data::dataset::training_clips(&t, p).map_err(|e| Message::new(e.0))?;
                if let Some(minutes) = self.synth_mix {
                    train.extend(self.synth_mix_clips(&train, minutes)?);
                }
                (train, valid)
            }
        };
        let train_w = zoo_data::dataset::windows(&train_clips, &humanoid::WINDOW);
        let valid_w = zoo_data::dataset::windows(&valid_clips, &humanoid::WINDOW);
        if train_w.count == 0 || valid_w.count == 0 {
            bail!(
                "{}: {} training and {} validation windows of {} frames: both splits need clips longer than {} frames",
                self.source(),
                train_w.count,
                valid_w.count,
                humanoid::WINDOW.window,
                humanoid::WINDOW.window
            );
        }
        Ok((train_clips, valid_clips, train_w, valid_w))
    }

    /// `minutes` of the synthetic generator's default locomotion (walks with turns, jogging,
    /// running, standing; seed `seed`, flat ground) for the training split of `--synth-mix`,
    /// refused unless `train` (the data's clips) is on the generator's skeleton and frame rate.
    fn synth_mix_clips(&self, train: &[NamedClip], minutes: f64) -> ArnnResult<Vec<NamedClip>> {
        let cfg = zoo_data::synth::SynthConfig { minutes, seed: self.seed, ..Default::default() };
        if let Some(c) = train.first() {
            let fps = Some(c.clip.fps());
            if let Err(m) = zoo_data::synth::check_mixable("--synth-mix", &c.name, &c.clip.skeleton, fps, cfg.fps) {
                bail!("{m}");
            }
        }
        let clips: Vec<NamedClip> =
            zoo_data::synth::generate(&cfg).into_iter().map(zoo_data::dataset::named_synth).collect();
        println!("--synth-mix {minutes}: {} synthetic clips of walks, turns, jogging and running", clips.len());
        Ok(clips)
    }

    /// Where the clips come from, in words.
    fn source(&self) -> String {
        match self.synth_minutes {
            Some(minutes) => format!("synthetic locomotion, {minutes} min, seed {}", self.seed),
            None => self.dir.display().to_string(),
        }
    }
}

/// The data of a humanoid run: a resumed run's recorded ones (`--data` replacing its folder),
/// or the options'; and whether it is resumed.
fn humanoid_settings(
    a: &ArnnRunOptions,
    extra: &mut serde_json::Map<String, serde_json::Value>,
) -> ArnnResult<(HumanoidData, bool)> {
    let Some(dir) = &a.run.resume else {
        let s = match (&a.data, a.design) {
            (None, ArnnDesign::Inbetween) => HumanoidData {
                dir: PathBuf::new(),
                synth_minutes: Some(a.synth_minutes.unwrap_or(match a.preset {
                    ArnnPreset::Quick => QUICK_SYNTH_MINUTES,
                    _ => DEFAULT_SYNTH_MINUTES,
                })),
                synth_mix: None,
                valid_glob: String::new(),
                exclude_glob: None,
                seed: a.run.seed,
            },
            _ => HumanoidData {
                dir: a.data.clone().context("pass --data BVH_FOLDER")?,
                synth_minutes: None,
                synth_mix: a.synth_mix.filter(|&m| m > 0.0),
                valid_glob: a.valid_glob.clone().context("pass --valid-glob GLOB")?,
                exclude_glob: a.exclude_glob.clone(),
                seed: a.run.seed,
            },
        };
        extra.insert(STATE_KEY.into(), serde_json::to_value(&s).context("the humanoid data")?);
        return Ok((s, false));
    };
    let state = train_loop::read_state(dir)?;
    let stored = state.extra.get(STATE_KEY).cloned().with_context(|| {
        format!(
            "{}: train_state.json records no humanoid data (a lamp run: resume it without --valid-glob)",
            dir.display()
        )
    })?;
    let mut s: HumanoidData = serde_json::from_value(stored).context("the recorded humanoid data")?;
    if let Some(d) = &a.data {
        if s.synth_minutes.is_some() {
            bail!("--resume {}: the run trained on synthetic locomotion, not on --data", dir.display());
        }
        s.dir = d.clone();
    }
    if let Some(g) = &a.valid_glob
        && *g != s.valid_glob
    {
        bail!("--resume {}: the run validates on `{}`, not `{g}`", dir.display(), s.valid_glob);
    }
    if a.exclude_glob.is_some() && a.exclude_glob != s.exclude_glob {
        bail!(
            "--resume {}: the run leaves out {}, not `{}`: resume without --exclude-glob",
            dir.display(),
            s.exclude_glob.as_deref().map_or("no clip".to_string(), |g| format!("`{g}`")),
            a.exclude_glob.as_deref().unwrap_or_default()
        );
    }
    Ok((s, true))
}

/// The trainer of a humanoid run on the windows of its clips (`resumed`: from its last
/// checkpoint in `out`).
fn humanoid_trainer(
    a: &ArnnRunOptions,
    out: &Path,
    resumed: bool,
    s: &HumanoidData,
    clips: (&[zoo_data::dataset::NamedClip], &zoo_data::dataset::Windows, &zoo_data::dataset::Windows),
) -> ArnnResult<ArnnTrainer> {
    let (train_clips, train_w, valid_w) = clips;
    let skeleton = &train_clips[0].clip.skeleton;
    let device = candle_core::Device::Cpu;
    if resumed {
        let from = train_loop::resume_dir(out);
        let (config, norm) = crate::checkpoint::read_meta(&from)
            .with_context(|| format!("resuming from {}: it holds no ARNN checkpoint", from.display()))?;
        humanoid::check_skeleton(&config, skeleton)?;
        let train = humanoid::sequences(train_w, &config.key_sampling, s.seed);
        let valid = humanoid::sequences(valid_w, &config.key_sampling, s.seed ^ 0x5EED);
        return ArnnTrainer::with_normalization(&config, norm, train, valid, &device);
    }
    let mut config = humanoid::config_for(skeleton, 1.0 / train_clips[0].clip.frame_time);
    if a.preset == ArnnPreset::Tiny {
        config = config.sized_like(&ArnnConfig::tiny());
    }
    if let Some(b) = a.batch_size {
        config.batch_size = b;
    }
    if let Some(lr) = a.lr {
        config.learning_rate = lr;
    }
    if a.ground_weight.is_some() {
        bail!("--ground-weight is the lamp's base penalty; humanoid runs have none");
    }
    config.seed = a.run.seed;
    config.curriculum.total_steps = train_w.count.div_ceil(config.batch_size) as u64 * a.run.epochs as u64;
    set_frame_phase(a, &mut config, false)?;
    let train = humanoid::sequences(train_w, &config.key_sampling, s.seed);
    let valid = humanoid::sequences(valid_w, &config.key_sampling, s.seed ^ 0x5EED);
    let norm = humanoid::normalization(&train);
    ArnnTrainer::with_normalization(&config, norm, train, valid, &device)
}

/// `zoo train arnn --data BVH_FOLDER --valid-glob GLOB`: the keyframe autocompletion network on
/// humanoid motion (beyond the paper): 66-frame windows of the training split, keys drawn afresh
/// each time a window is fed (every 5-30 frames, half the time in the in-betweening benchmark's
/// layout), a fifth of the keys partial. Scored afterwards by `zoo bench --methods
/// interp,arnn:DIR`.
pub fn train_humanoid(a: &ArnnRunOptions, p: &dyn Progress) -> ArnnResult<()> {
    if a.variant != ArnnVariant::Arnn {
        bail!(
            "--variant {:?} is a comparison of the paper's tables on the lamp; humanoid runs train the ARNN",
            a.variant
        );
    }
    let out = prepare_run_folder(a)?;
    let mut extra = serde_json::Map::new();
    let (s, resumed) = humanoid_settings(a, &mut extra)?;
    let (train_clips, valid_clips, train_w, valid_w) = s.load(p)?;
    let mut trainer = humanoid_trainer(a, &out, resumed, &s, (&train_clips, &train_w, &valid_w))?;
    let source = format!(
        "{} ({} training clips, {} validation clips matching `{}`)",
        s.dir.display(),
        train_clips.len(),
        valid_clips.len(),
        s.valid_glob
    );
    println!(
        "training the humanoid ARNN on {source}: {} training / {} validation windows of {} frames, {} joints, {} \
         parameters, curriculum over {} steps, run folder {}",
        train_w.count,
        valid_w.count,
        humanoid::WINDOW.window,
        train_clips[0].clip.skeleton.len(),
        trainer.parameter_count(),
        trainer.config().curriculum.total_steps,
        out.display()
    );
    let seed = trainer.config().seed;
    let state = train(a, &mut trainer, &out, (source, extra, resumed), seed)?;
    println!(
        "{}\nscore it: zoo bench --data {} --valid-glob '{}' --methods interp,arnn:{}",
        done_line(&state, "validation", &out),
        s.dir.display(),
        s.valid_glob,
        out.display()
    );
    Ok(())
}

/// `zoo train arnn --design inbetween --data BVH_FOLDER --valid-glob GLOB`: the in-betweening
/// network ([`crate::inbetween`]) on 66-frame windows of the training split, keys drawn afresh
/// for every batch ([`crate::inbetween_train`]); validated on up to
/// [`crate::inbetween_train::VALID_MAX`] windows of the validation split keyed as the keys-only
/// benchmark. Scored afterwards by `zoo bench --layout keys --methods linear,bezier,arnn:DIR`.
pub fn train_inbetween(a: &ArnnRunOptions, p: &dyn Progress) -> ArnnResult<()> {
    if a.variant != ArnnVariant::Arnn
        || a.no_memory_output.is_some()
        || a.frame_phase.is_some()
        || a.frame_phase_omega.is_some()
        || a.ground_weight.is_some()
    {
        bail!(
            "--variant, --no-memory-output, --frame-phase, --frame-phase-omega and --ground-weight are settings of the autoregressive ARNN; the in-betweening design has none of them: drop them"
        );
    }
    if a.run.resume.is_none() && a.data.is_some() != a.valid_glob.is_some() {
        bail!(
            "--design inbetween trains on humanoid clips: pass --data BVH_FOLDER --valid-glob GLOB, or neither for \
             synthetic locomotion (--synth-minutes)"
        );
    }
    if a.data.is_some() && a.synth_minutes.is_some() {
        bail!("--synth-minutes is the synthetic locomotion used without --data: drop one of them");
    }
    let out = prepare_run_folder(a)?;
    let mut extra = serde_json::Map::new();
    extra.insert("design".into(), crate::inbetween::DESIGN.into());
    let (s, resumed) = humanoid_settings(a, &mut extra)?;
    let epochs = match (a.preset, a.epochs_given || resumed) {
        (ArnnPreset::Quick, false) => QUICK_INBETWEEN_EPOCHS,
        _ => a.run.epochs,
    };
    let (train_clips, valid_clips, train_w, valid_w) = s.load(p)?;
    let skeleton = &train_clips[0].clip.skeleton;
    let (config, norm) = if resumed {
        let from = train_loop::resume_dir(&out);
        let (mut config, norm) = crate::inbetween::read_meta(&from)
            .with_context(|| format!("resuming from {}: it holds no in-betweening checkpoint", from.display()))?;
        // The fallback is calibrated again at the end, on the weights trained by then.
        config.fallback = None;
        if config.skeleton.names != skeleton.names {
            bail!("--resume {}: the run was trained on another skeleton than {}'s", out.display(), s.source());
        }
        if let Some(b) = a.backbone.filter(|&b| b != config.backbone) {
            // The names `--backbone` takes (no variant is skipped).
            let name = |b: crate::inbetween::Backbone| {
                clap::ValueEnum::to_possible_value(&b)
                    .expect("every backbone has an option value")
                    .get_name()
                    .to_string()
            };
            bail!(
                "--resume {}: the run's network is the {} backbone, not {}: drop --backbone to resume it, or train a \
                 new run",
                out.display(),
                name(config.backbone),
                name(b)
            );
        }
        (config, norm)
    } else {
        let fps = 1.0 / train_clips[0].clip.frame_time;
        let mut config = crate::inbetween::config_for(skeleton, fps);
        match a.preset {
            ArnnPreset::Paper => {}
            ArnnPreset::Quick => config = crate::inbetween::InbetweenConfig::quick(config.skeleton, config.euler_axes),
            ArnnPreset::Tiny => config = crate::inbetween::InbetweenConfig::tiny(config.skeleton, config.euler_axes),
        }
        if let Some(b) = a.backbone {
            config = config.with_backbone(b);
        }
        if let Some(b) = a.batch_size {
            config.batch_size = b;
        }
        if let Some(lr) = a.lr {
            config.learning_rate = lr;
        }
        if let Some(f) = a.transition_fraction {
            config.transition_fraction = f;
        }
        if let Some(p) = a.dropout {
            config.dropout = p;
        }
        config.seed = a.run.seed;
        config.lr_half_life = (train_w.count.div_ceil(config.batch_size) * epochs).div_ceil(4) as u64;
        let norm = crate::inbetween_train::window_normalization(&train_w);
        (config, norm)
    };
    let (n_train, n_valid) = (train_w.count, valid_w.count);
    let mut trainer = crate::inbetween_train::InbetweenTrainer::new(&config, norm, train_w, &valid_w)?;
    let source = match s.synth_minutes {
        Some(_) => format!(
            "{} ({} training clips, {} validation clips: every tenth)",
            s.source(),
            train_clips.len(),
            valid_clips.len()
        ),
        None => format!(
            "{} ({} training clips{}, {} validation clips matching `{}`)",
            s.dir.display(),
            train_clips.len(),
            s.synth_mix.map_or(String::new(), |m| format!(" with {m} min of synthetic locomotion")),
            valid_clips.len(),
            s.valid_glob
        ),
    };
    println!(
        "training the in-betweening network ({}) on {source}: {n_train} training / {n_valid} validation windows of {} \
         frames, {} joints, {} parameters, learning rate {} halved every {} steps, run folder {}",
        match config.backbone {
            crate::inbetween::Backbone::Bgru => "bidirectional GRU",
            crate::inbetween::Backbone::Transformer => "transformer",
        },
        humanoid::WINDOW.window,
        skeleton.len(),
        trainer.parameter_count(),
        config.learning_rate,
        config.lr_half_life,
        out.display()
    );
    let threads = a.run.thread_count();
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    extra.insert("threads".into(), threads.into());
    let opts = TrainOptions {
        time_limit: a.run.time_limit(),
        resume: resumed,
        data: source,
        extra,
        ..TrainOptions::new(&out, epochs, config.seed)
    };
    let state = train_loop::train(&mut trainer, &opts)?;
    calibrate_inbetween(&out, &valid_w)?;
    let methods = format!("linear,bezier,arnn:{},arnn+lock:{}", out.display(), out.display());
    match s.synth_minutes {
        Some(_) => println!(
            "{}\nscore it on clips it never saw: zoo data synth --out synth-test --seed {} && zoo bench --data synth-test \
             --valid-glob '*' --layout keys --methods {methods}",
            done_line(&state, "validation", &out),
            s.seed + 1000,
        ),
        None => println!(
            "{}\nscore it: zoo bench --data {} --valid-glob '{}' --layout keys --methods {methods}",
            done_line(&state, "validation", &out),
            s.dir.display(),
            s.valid_glob,
        ),
    }
    Ok(())
}

/// Calibrates the fallback towards the curves of the best in-betweening network in `out`
/// ([`crate::inbetween_train::calibrate_fallback`]) on the validation windows and writes it into
/// the folder's `config.json` (atomically). `--resume RUN --epochs N` with `N` the epochs done
/// calibrates an older run without training it.
fn calibrate_inbetween(out: &std::path::Path, valid: &zoo_data::dataset::Windows) -> ArnnResult<()> {
    if !out.join(zoo_nn::checkpoint::CONFIG_FILE).is_file() || valid.count == 0 {
        return Ok(());
    }
    let (model, norm) = crate::inbetween::load(out, &candle_core::Device::Cpu)?;
    let cal = crate::inbetween_train::calibrate_fallback(&model, &norm, valid)?;
    let Some(fallback) = cal.fallback else { return Ok(()) };
    let mut config = model.config().clone();
    config.fallback = Some(fallback.clone());
    zoo_nn::checkpoint::write_json(&out.join(zoo_nn::checkpoint::CONFIG_FILE), &config)?;
    let ranges: Vec<String> = fallback
        .gaps
        .iter()
        .zip(&cal.ranges)
        .map(|(g, r)| {
            let gain = format!("network/curves error {:.2} (pose), {:.2} (changes)", r.pose, r.change);
            match r.curves {
                true => format!("up to {} frames: the curves ({gain})", g.up_to),
                false => format!("up to {} frames: {:.3}-{:.3} ({gain})", g.up_to, g.start, g.full),
            }
        })
        .collect();
    println!(
        "fallback calibrated on {} validation intervals between keys: towards the curves from the 95th percentile of \
         the correction size per gap, fully at twice it; the curves alone where the network takes off less than {:.0} \
         % of their error; stored in config.json:\n  {}",
        cal.sizes.len(),
        100.0 * crate::inbetween_train::FALLBACK_MIN_GAIN,
        ranges.join("\n  ")
    );
    Ok(())
}

fn line(name: &str, e: &CompletionError) -> String {
    let miss = &e.max_key_miss;
    format!(
        "  {name:<14} key {:.5}  frame {:.5}  total {:.5}  RMSE base x {:.1} cm, y {:.1} cm, angles \
         {:.1}/{:.1}/{:.1}/{:.1} deg; largest key miss x {:.1} cm, y {:.1} cm, angle {:.1} deg; lowest base point {}",
        e.key,
        e.frame,
        e.key + e.frame,
        e.rmse[0] * 100.0,
        e.rmse[1] * 100.0,
        e.rmse[2].to_degrees(),
        e.rmse[3].to_degrees(),
        e.rmse[4].to_degrees(),
        e.rmse[5].to_degrees(),
        miss[0] * 100.0,
        miss[1] * 100.0,
        miss[2..].iter().fold(0.0f64, |a, b| a.max(*b)).to_degrees(),
        e.lowest_base.map_or("-".into(), |l| format!("{:.2} cm", l * 100.0)),
    )
}

/// A completion report in words (frame / key error: normalised MSE; total = key + frame as in
/// the paper's Tables 1-2).
pub fn report_text(r: &CompletionReport) -> String {
    let mut s = format!(
        "test set, {} sequences completed from all their keys (normalised MSE per degree of freedom, every frame \
         after the first; key: the key frames after the first):",
        r.sequences
    );
    s += &format!("\n{}", line("network", &r.arnn));
    if let Some(g) = &r.arnn_grounded {
        s += &format!("\n{}", line("network+ground", g));
    }
    s += &format!("\n{}\n{}\n", line("linear", &r.linear), line("cubic spline", &r.spline));
    s + &format!(
        "  network frame error / spline frame error = {:.3} (linear: {:.3})",
        r.arnn.frame / r.spline.frame.max(1e-30),
        r.arnn.frame / r.linear.frame.max(1e-30)
    )
}

/// Which weights of a run folder to evaluate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Checkpoint {
    /// The run folder's checkpoint: the best validation loss (frame + key).
    Best,
    /// The last epoch's weights (`last/`).
    Last,
}

/// The test set of a lamp run, rebuilt from its recorded settings (`data`: its folder when it
/// has moved), refused when it is not the one the run recorded.
fn recorded_test_set(
    model: &Path,
    state: &train_loop::TrainState,
    data: Option<&Path>,
    p: &dyn Progress,
) -> ArnnResult<LampData> {
    let stored = state.extra.get("data_settings").cloned().with_context(|| {
        format!("{}: train_state.json has no data_settings (not written by `zoo train arnn`)", model.display())
    })?;
    let mut settings: DataSettings = serde_json::from_value(stored).context("the recorded data settings")?;
    if let Some(d) = data {
        if settings.dir.is_none() {
            bail!("--data {}: the run trained on sequences generated in memory, not on a folder", d.display());
        }
        settings.dir = Some(d.to_path_buf());
    }
    let data = lamp_data(&settings, p).with_context(|| {
        format!("rebuilding the test set of {} (give the data folder with --data if it moved)", model.display())
    })?;
    if let Some(names) = state.extra.get("test_sequences").and_then(|v| v.as_array()) {
        let now: Vec<&str> = data.test.iter().map(|s| s.name.as_str()).collect();
        let then: Vec<&str> = names.iter().filter_map(|v| v.as_str()).collect();
        if now != then {
            bail!(
                "the test set rebuilt from {} is not the run's ({} sequences recorded, {} found, first {:?} vs {:?}): \
                 the data folder changed",
                data.source,
                then.len(),
                now.len(),
                then.first(),
                now.first()
            );
        }
    }
    Ok(data)
}

/// `zoo eval-arnn`: the completion test of a lamp run on its held-out sequences against linear
/// and spline interpolation of the same keys (one row of the paper's Tables 1-2); returns the
/// text the command prints and the report as JSON.
pub fn evaluate_run(
    model: &Path,
    which: Checkpoint,
    data: Option<&Path>,
    p: &dyn Progress,
) -> ArnnResult<(String, serde_json::Value)> {
    let state = train_loop::read_state(model)?;
    let variant: Option<ArnnVariant> = state.extra.get("variant").and_then(|v| serde_json::from_value(v.clone()).ok());
    let (weights, epoch) = match which {
        Checkpoint::Best => (model.to_path_buf(), state.best_epoch),
        Checkpoint::Last => (model.join(checkpoint::LAST_DIR), state.epoch),
    };
    let (net, norm) = crate::checkpoint::load(&weights, &candle_core::Device::Cpu)
        .with_context(|| format!("loading the ARNN in {}", weights.display()))?;
    let data = recorded_test_set(model, &state, data, p)?;
    let config = net.config();
    let architecture = match config.architecture {
        Architecture::NoMemory => {
            format!("{:?} architecture ({:?} output)", config.architecture, config.no_memory_output)
        }
        other => format!("{other:?} architecture"),
    };
    let head = format!(
        "{}: {} ({architecture}, {} parameters, ground weight {}), {which:?} checkpoint (epoch {epoch} of {}), data {}",
        model.display(),
        variant.map_or("arnn".into(), |v| format!("{v:?}")),
        config.parameter_count(),
        config.ground_weight,
        state.epoch,
        data.source
    );
    let r = crate::eval::evaluate(&net, &norm, &data.test)?;
    let mut v = serde_json::to_value(&r).unwrap_or_default();
    if let Some(m) = v.as_object_mut() {
        m.insert("run".into(), serde_json::json!(model));
        m.insert("checkpoint".into(), format!("{which:?}").to_lowercase().into());
        m.insert("epoch".into(), epoch.into());
        m.insert("variant".into(), serde_json::to_value(variant).unwrap_or_default());
        m.insert("parameters".into(), config.parameter_count().into());
    }
    Ok((format!("{head}\n{}", report_text(&r)), v))
}
