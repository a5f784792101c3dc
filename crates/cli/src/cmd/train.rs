//! `zoo train ...`: train a model of the zoo on BVH data or on the embedded synthetic data.

use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;
use zoo_data::dataset::{self, NamedClip, WindowOptions};
use zoo_data::synth::{self, SynthConfig};
use zoo_nn::checkpoint;
use zoo_nn::train_loop::{self, TrainOptions};
use zoo_rtn::prelude::*;

/// `zoo train` subcommands.
#[derive(Subcommand)]
pub enum TrainCommand {
    /// The Recurrent Transition Network (Harvey & Pal 2018).
    Rtn(RtnArgs),
    /// The Recurrent Motion Refiner for locomotion stitching (Kim et al. 2023).
    Rmr(crate::cmd::train_rmr::RmrArgs),
    /// RNN-GMM with an adversarial refiner (Wang, Chai & Xia 2019): random motion synthesis.
    RnnGmm(crate::cmd::train_rnngmm::RnnGmmArgs),
    /// The keyframe autocompletion network ARNN (Zhang & van de Panne 2018) on the simulated lamp.
    Arnn(crate::cmd::train_arnn::ArnnArgs),
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

/// A training-window augmentation of `zoo train rtn --augment` (`zoo_rtn::augment`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RtnAugment {
    /// Time reversal (walking backwards).
    Reverse,
    /// Left-right mirroring.
    Mirror,
    /// Speed changes (factors 0.7-1.2).
    Speed,
}

/// Speed factors of `--augment speed`.
const SPEED_RANGE: (f32, f32) = (0.7, 1.2);

/// Probabilities of `--augment reverse`, `mirror` and `speed` for each training window.
const AUGMENT_P: (f64, f64, f64) = (0.3, 0.5, 0.3);

/// Minutes of stepping clips: `0..=600`.
fn synth_steps_minutes(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(m) if (0.0..=600.0).contains(&m) => Ok(m),
        _ => Err(format!("`{s}` is not a number of minutes: valid range 0..=600")),
    }
}

/// Sizes of the RTN to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RtnPreset {
    /// The paper's sizes (`Config::paper`).
    Paper,
    /// A small model for tests and quick checks (`Config::tiny`: 12-frame windows).
    Tiny,
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
    /// Leave out of `--data` every clip whose file name matches this glob (e.g. a content type
    /// held out for the out-of-distribution protocol of docs/ood.md).
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Leave out the clips of `--data` that cannot join the dataset (unreadable, another
    /// skeleton or frame rate) and list them, instead of refusing the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Epochs to train (an epoch visits every training window once). The default, with the
    /// default 30 synthetic minutes, is the README's quick model (docs/rtn.md).
    #[arg(long, default_value_t = 20, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub epochs: usize,
    /// Stop after this many minutes of training (the epoch in progress finishes first).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub time_limit: Option<f64>,
    /// Run folder: config, weights, statistics, loss curve and summary.
    #[arg(long, default_value = "runs/rtn")]
    pub out: PathBuf,
    /// Continue the run in this folder (its config is kept; `--epochs` is the new total).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run already in `--out`: its model, statistics, state and `last/` checkpoint
    /// are deleted before training. Without it, `--out` on a folder that holds a run is refused.
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Model variant (Table 4 ablations).
    #[arg(long, value_enum, default_value_t = RtnVariant::Rtn)]
    pub variant: RtnVariant,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = RtnPreset::Paper)]
    pub preset: RtnPreset,
    /// Predict a correction on top of the interpolation of context and target instead of the
    /// next frame (the Delta-interpolator idea of Oreshkin et al. 2022; `interp_residual` in
    /// config.json): an untrained model is the interpolation, and what the network learns is
    /// added to it. On by default: it learns faster and stays near interpolation on motion the
    /// data lacks (docs/ood.md). `--interp-residual false` trains the paper's RTN, which
    /// predicts the next frame itself.
    #[arg(long, default_value_t = true, num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    pub interp_residual: bool,
    /// Train the terrain-aware RTN (RTN sec. 3.2: the local terrain patch under the root feeds
    /// the frame encoder; `terrain` in config.json). Every clip needs its heightmap: `--data`
    /// written by `zoo data synth --terrain` (`NAME.terrain.json` beside each clip), or without
    /// `--data` synthetic locomotion over uneven terrain generated in memory. The windows stay
    /// in the clips' world frame, the heightmaps'. Run the model with `zoo transition
    /// --heightmap` or the runtime's `TransitionState::set_heightmap`.
    #[arg(long)]
    pub terrain: bool,
    /// Augment the training windows on the fly with motion the data lacks (comma-separated;
    /// stored in config.json as `train.augment`): `reverse` (time reversal, 30% of the windows:
    /// forward walks become backward walks), `mirror` (left-right mirroring, 50%, joints
    /// paired by name: `_L`/`_R`, `.L`/`.R`, `Left`/`Right`), `speed` (30%, resampled at a
    /// factor drawn from 0.7-1.2). Epochs keep their size; validation is never augmented.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub augment: Vec<RtnAugment>,
    /// Minutes of the synthetic generator's stepping clips (walks made mostly of side and back
    /// steps, `zoo_data::synth::generate_stepping`) mixed into the training split of `--data`;
    /// its skeleton is bandai2's, so the data must be on it. 0: none.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = synth_steps_minutes)]
    pub synth_steps: f64,
    /// Mini-batch size [default: the preset's; paper: 32].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::batch_size)]
    pub batch_size: Option<usize>,
    /// AMSGrad learning rate [default: the preset's; paper: 5e-4].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::learning_rate)]
    pub lr: Option<f64>,
    /// Minutes of synthetic motion when `--data` is not given (every tenth clip validates).
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true, value_parser = crate::args::synth_minutes)]
    pub synth_minutes: f64,
    /// Seed of the synthetic data and of the trainer.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Decay of a moving average of the weights kept beside the trained ones (not in the
    /// paper). Each epoch both are validated and the better one becomes the best checkpoint;
    /// 0 keeps no average (the paper's recipe exactly).
    #[arg(long, default_value_t = 0.999, allow_hyphen_values = true, value_parser = crate::args::decay)]
    pub ema: f64,
    /// Data-parallel training threads (`1..=256`) [default: the cores available]. Each thread
    /// trains on its share of every batch and the gradients are summed before the one update:
    /// the same update as one thread up to float summation order. Results are reproducible
    /// for a fixed seed and thread count, not across thread counts.
    #[arg(long, allow_hyphen_values = true, value_parser = training_threads)]
    pub threads: Option<usize>,
}

/// A training thread count in `1..=MAX_THREADS`.
pub fn training_threads(s: &str) -> Result<usize, String> {
    let max = zoo_nn::parallel::MAX_THREADS;
    match s.trim().parse::<usize>() {
        Ok(n @ 1..) if n <= max => Ok(n),
        _ => Err(format!("`{s}` is not a thread count: valid range 1..={max}")),
    }
}

/// The thread count of a run: `--threads`, else the cores available to the process.
pub fn default_threads(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
}

/// Runs a `zoo train` subcommand.
pub fn run(cmd: TrainCommand) -> anyhow::Result<()> {
    match cmd {
        TrainCommand::Rtn(a) => train_rtn(a),
        TrainCommand::Rmr(a) => crate::cmd::train_rmr::run(a),
        TrainCommand::RnnGmm(a) => crate::cmd::train_rnngmm::run(a),
        TrainCommand::Arnn(a) => crate::cmd::train_arnn::run(a),
    }
}

/// Training and validation clips: `--data` split by `--valid-glob`, or synthetic clips with
/// every tenth clip held out.
pub fn load_clips(
    data: &Option<PathBuf>,
    valid_glob: &Option<String>,
    minutes: f64,
    seed: u64,
    skip_invalid: bool,
) -> anyhow::Result<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    load_clips_excluding(data, valid_glob, None, minutes, seed, skip_invalid)
}

/// [`load_clips`] leaving out the clips of `--data` that match `exclude` (`--exclude-glob`).
pub fn load_clips_excluding(
    data: &Option<PathBuf>,
    valid_glob: &Option<String>,
    exclude: Option<&str>,
    minutes: f64,
    seed: u64,
    skip_invalid: bool,
) -> anyhow::Result<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    match data {
        Some(path) => {
            let Some(glob) = valid_glob else {
                bail!("--data needs --valid-glob GLOB to choose the validation clips (bandai2: '*_youthful_*')")
            };
            dataset::glob(glob)?;
            let clips = crate::cmd::load_dataset(path, None, skip_invalid)?;
            let clips = crate::cmd::exclude_clips(clips, exclude)?;
            let (train, valid) = dataset::split(clips, glob)?;
            let without = exclude.map_or(String::new(), |e| format!(", without {e}"));
            Ok((train, valid, format!("{} (validation: {glob}{without})", path.display())))
        }
        None => {
            let cfg = SynthConfig { minutes, seed, terrain: false, ..SynthConfig::default() };
            let (train, valid) = split_synth(synth::generate(&cfg).into_iter().map(named_synth).collect());
            Ok((train, valid, format!("synthetic locomotion, {minutes} min, seed {seed}")))
        }
    }
}

fn named_synth(c: synth::SynthClip) -> NamedClip {
    NamedClip { path: PathBuf::from(&c.name), name: c.name, clip: c.clip }
}

/// The split of synthetic clips: every tenth clip validates; with fewer than ten, the last one.
fn split_synth<T>(clips: Vec<T>) -> (Vec<T>, Vec<T>) {
    let n = clips.len();
    let (mut train, mut valid) = (Vec::new(), Vec::new());
    for (i, c) in clips.into_iter().enumerate() {
        if i % 10 == 9 || (n < 10 && i + 1 == n) { valid.push(c) } else { train.push(c) }
    }
    (train, valid)
}

/// The clips of `zoo train rtn` ([`load_clips_excluding`] with its arguments).
fn load_rtn_clips(a: &RtnArgs) -> anyhow::Result<(Vec<NamedClip>, Vec<NamedClip>, String)> {
    load_clips_excluding(&a.data, &a.valid_glob, a.exclude_glob.as_deref(), a.synth_minutes, a.seed, a.skip_invalid)
}

/// Clips with their heightmaps for `zoo train rtn --terrain`.
struct TerrainClips {
    train: Vec<(NamedClip, Heightmap)>,
    valid: Vec<(NamedClip, Heightmap)>,
    source: String,
}

/// [`load_clips_excluding`] for `--terrain`: each clip of `--data` with the heightmap beside it
/// (`zoo_data::terrain::sibling_of`; a clip without one is refused with the fix), or synthetic
/// locomotion over uneven terrain (flat-floor clips get a flat map at height 0).
fn load_terrain_clips(a: &RtnArgs) -> anyhow::Result<TerrainClips> {
    if a.data.is_none() {
        let cfg = SynthConfig { minutes: a.synth_minutes, seed: a.seed, terrain: true, ..SynthConfig::default() };
        let clips = synth::generate(&cfg)
            .into_iter()
            .map(|mut c| {
                let map = c.terrain.take().unwrap_or_else(|| Heightmap::flat(0.0));
                (named_synth(c), map)
            })
            .collect();
        let (train, valid) = split_synth(clips);
        let source = format!("synthetic locomotion over terrain, {} min, seed {}", a.synth_minutes, a.seed);
        return Ok(TerrainClips { train, valid, source });
    }
    let (train, valid, source) = load_rtn_clips(a)?;
    let with_maps = |clips: Vec<NamedClip>| -> anyhow::Result<Vec<(NamedClip, Heightmap)>> {
        clips
            .into_iter()
            .map(|c| {
                let Some(path) = zoo_data::terrain::sibling_of(&c.path) else {
                    bail!(
                        "--terrain: {} has no heightmap beside it (NAME.terrain.json, as `zoo data synth --terrain` \
                         writes): train on such data, or leave --terrain out for data without terrain",
                        c.path.display()
                    )
                };
                let map = zoo_data::terrain::read(&path).with_context(|| format!("--terrain: {}", c.path.display()))?;
                Ok((c, map))
            })
            .collect()
    };
    Ok(TerrainClips { train: with_maps(train)?, valid: with_maps(valid)?, source: format!("{source}, with terrain") })
}

/// The training windows of `pos` (`per` values each), each with the heightmap of its clip in
/// `maps` when there is one (windows past `w`'s, the stepping clips', have none).
fn motion_windows<'a>(
    pos: &'a [f32],
    per: usize,
    w: &dataset::Windows,
    maps: &'a [Heightmap],
) -> Vec<MotionWindow<'a>> {
    pos.chunks_exact(per)
        .enumerate()
        .map(|(i, p)| MotionWindow { positions: p, terrain: w.source.get(i).and_then(|&(c, _)| maps.get(c)) })
        .collect()
}

/// The global positions of `w`'s windows in their clips' world frame (cut as `w` was, without
/// its centring and facing unification, so that the terrain under them stays where the
/// heightmap has it), `w.count * w.window * 3K` values.
fn world_positions(clips: &[NamedClip], w: &dataset::Windows) -> Vec<f32> {
    let j = w.skeleton.len();
    let globals: Vec<Vec<glam::DVec3>> = clips.iter().map(|c| c.clip.global().1).collect();
    w.source
        .iter()
        .flat_map(|&(ci, start)| &globals[ci][start * j..(start + w.window) * j])
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
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

/// Refuses options that cannot work with a terrain-aware run (`terrain`), naming the fix.
fn check_terrain_options(a: &RtnArgs, terrain: bool) -> anyhow::Result<()> {
    if a.terrain && !terrain {
        bail!("--terrain: the run in --resume was trained without terrain; resume it without --terrain");
    }
    if !terrain {
        return Ok(());
    }
    if a.augment.contains(&RtnAugment::Mirror) {
        bail!("--augment mirror moves the motion off its terrain: leave mirror out of --augment with --terrain");
    }
    if a.synth_steps > 0.0 {
        bail!("--synth-steps adds clips without terrain: leave it out with --terrain");
    }
    Ok(())
}

/// The configuration of a fresh run: the preset, the data's skeleton and the arguments.
fn fresh_config(
    a: &RtnArgs,
    names: &[String],
    parents: &[Option<usize>],
    train_windows: usize,
) -> anyhow::Result<Config> {
    let preset = match a.preset {
        RtnPreset::Paper => Config::paper(),
        RtnPreset::Tiny => Config::tiny(),
    };
    let mut config = preset.with_parents(parents);
    if let Some(b) = a.batch_size {
        config.train.batch_size = b;
    }
    if let Some(lr) = a.lr {
        config.train.learning_rate = lr;
    }
    if config.train.batch_size == 0 {
        bail!("--batch-size must be at least 1");
    }
    config.train.seed = a.seed;
    config.interp_residual = a.interp_residual;
    config.terrain = a.terrain;
    if !a.augment.is_empty() {
        let has = |x| a.augment.contains(&x);
        let mirror_pairs = if has(RtnAugment::Mirror) {
            let pairs = zoo_rtn::augment::mirror_pairs(names)?;
            zoo_rtn::augment::check_mirror_pairs(&pairs, parents, names)?;
            pairs
        } else {
            Vec::new()
        };
        config.train.augment = Some(zoo_rtn::augment::Augment {
            reverse: if has(RtnAugment::Reverse) { AUGMENT_P.0 } else { 0.0 },
            mirror: if has(RtnAugment::Mirror) { AUGMENT_P.1 } else { 0.0 },
            mirror_pairs,
            speed: if has(RtnAugment::Speed) { AUGMENT_P.2 } else { 0.0 },
            speed_range: SPEED_RANGE,
        });
    }
    if !(0.0..1.0).contains(&a.ema) {
        bail!("--ema {} is not a decay in [0, 1) (0.999 averages over about 1000 steps; 0 turns it off)", a.ema);
    }
    config.train.ema_decay = (a.ema > 0.0).then_some(a.ema);
    let steps_per_epoch = train_windows.div_ceil(config.train.batch_size) as u64;
    apply_variant(&mut config, a.variant, steps_per_epoch * a.epochs as u64);
    Ok(config)
}

/// The files and folders of a run that `--overwrite` deletes (the ones training writes).
const RUN_FILES: [&str; 11] = [
    checkpoint::SKELETON_FILE,
    checkpoint::CONFIG_FILE,
    checkpoint::WEIGHTS_FILE,
    checkpoint::STATS_FILE,
    checkpoint::OPTIMIZER_FILE,
    checkpoint::EMA_FILE,
    checkpoint::RNG_FILE,
    checkpoint::TRAIN_STATE_FILE,
    checkpoint::SUMMARY_FILE,
    checkpoint::LOSS_CURVE_FILE,
    checkpoint::LAST_DIR,
];

/// Whether `dir` holds (part of) a run: a model, a state or a `last/` checkpoint.
fn holds_run(dir: &Path) -> bool {
    [checkpoint::CONFIG_FILE, checkpoint::WEIGHTS_FILE, checkpoint::TRAIN_STATE_FILE, checkpoint::LAST_DIR]
        .iter()
        .any(|f| dir.join(f).exists())
}

/// The run folder, checked before any data is loaded: a fresh run never replaces a trained one
/// unless `--overwrite` says so (then the old run's files are deleted), a resumed run must be
/// a run folder, and the folder must be writable.
fn prepare_run_folder(a: &RtnArgs) -> anyhow::Result<PathBuf> {
    prepare_run_folder_for(&a.out, a.resume.as_deref(), a.overwrite, &RUN_FILES, |_| Ok(()))
}

/// [`prepare_run_folder`] for any model: `run_files` are the files and folders of its runs
/// (what `--overwrite` deletes); `check_resume` checks that a folder to resume holds a run of
/// this model (after it is known to be a run folder).
pub fn prepare_run_folder_for(
    out: &Path,
    resume: Option<&Path>,
    overwrite: bool,
    run_files: &[&str],
    check_resume: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<PathBuf> {
    if let Some(dir) = resume {
        if !dir.is_dir() {
            bail!("--resume {}: no such folder (start a new run with --out instead)", dir.display());
        }
        train_loop::read_state(dir)?;
        check_resume(dir)?;
        crate::cmd::check_output_dir("--resume", dir)?;
        return Ok(dir.to_path_buf());
    }
    if holds_run(out) {
        if !overwrite {
            let what = match train_loop::read_state(out).ok() {
                Some(s) if s.epoch > 0 => format!(
                    "a run trained for {} epochs (best validation loss {:.5} at epoch {})",
                    s.epoch,
                    s.best_valid.unwrap_or(f64::NAN),
                    s.best_epoch
                ),
                _ => "a run".to_string(),
            };
            bail!(
                "--out {} already holds {what}: continue it with `--resume {0}`, replace it with --overwrite, or \
                 choose another --out",
                out.display()
            );
        }
        for name in run_files {
            let p = out.join(name);
            let removed = if p.is_dir() {
                std::fs::remove_dir_all(&p)
            } else if p.exists() {
                std::fs::remove_file(&p)
            } else {
                Ok(())
            };
            removed.with_context(|| format!("--overwrite: cannot delete {}", p.display()))?;
        }
        println!("--overwrite: deleted the run in {}", out.display());
    }
    crate::cmd::check_output_dir("--out", out)?;
    Ok(out.to_path_buf())
}

fn train_rtn(a: RtnArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    if a.data.is_none() {
        let cfg = SynthConfig::default();
        crate::args::check_synth_size(("--synth-minutes", a.synth_minutes), cfg.clip_seconds, cfg.fps)
            .map_err(anyhow::Error::msg)?;
    }
    let out = prepare_run_folder(&a)?;
    if a.exclude_glob.is_some() && a.data.is_none() {
        bail!("--exclude-glob leaves clips of --data out: pass --data too");
    }
    // A resumed run keeps its configuration, terrain included.
    let terrain = match &a.resume {
        Some(dir) => zoo_rtn::checkpoint::read_meta(&train_loop::resume_dir(dir)).map_or(a.terrain, |(c, _)| c.terrain),
        None => a.terrain,
    };
    check_terrain_options(&a, terrain)?;
    let (train, valid, train_maps, valid_maps, source) = if terrain {
        let t = load_terrain_clips(&a)?;
        let (train, train_maps): (Vec<_>, Vec<_>) = t.train.into_iter().unzip();
        let (valid, valid_maps): (Vec<_>, Vec<_>) = t.valid.into_iter().unzip();
        (train, valid, train_maps, valid_maps, t.source)
    } else {
        let (train, valid, source) = load_rtn_clips(&a)?;
        (train, valid, Vec::new(), Vec::new(), source)
    };
    let tw = dataset::windows(&train, &WindowOptions::TRAIN);
    let vw = dataset::windows(&valid, &WindowOptions::TRAIN);
    if tw.count == 0 || vw.count == 0 {
        bail!("need at least one 50-frame window in both splits (training {}, validation {})", tw.count, vw.count);
    }
    let d = tw.joints() * 3;
    let per = tw.window * d;
    let (mut train_pos, valid_pos) = if terrain {
        (world_positions(&train, &tw), world_positions(&valid, &vw))
    } else {
        (tw.global_positions_f32(), vw.global_positions_f32())
    };
    let mut extra = serde_json::Map::new();
    // Stepping clips: a resumed run keeps what it was started with.
    let saved = a.resume.as_ref().map(|dir| train_loop::read_state(dir)).transpose()?;
    let synth_steps = match &saved {
        Some(state) => state.extra.get("synth_steps").and_then(|v| v.as_f64()).unwrap_or(0.0),
        None => a.synth_steps,
    };
    extra.insert("synth_steps".into(), synth_steps.into());
    if synth_steps > 0.0 {
        let names = &tw.skeleton.names;
        let sk = synth::skeleton();
        if *names != sk.names || tw.skeleton.parents != sk.parents {
            bail!(
                "--synth-steps: the synthetic clips are on bandai2's skeleton ({} joints, `{}` first) but the data's \
                 differs ({} joints, `{}` first); leave --synth-steps out for this data",
                sk.names.len(),
                sk.names[0],
                names.len(),
                names.first().map_or("", String::as_str)
            );
        }
        let cfg = SynthConfig { minutes: synth_steps, seed: a.seed, terrain: false, ..SynthConfig::default() };
        let steps: Vec<NamedClip> = synth::generate_stepping(&cfg)
            .into_iter()
            .map(|c| NamedClip { path: PathBuf::from(&c.name), name: c.name, clip: c.clip })
            .collect();
        let sw = dataset::windows(&steps, &WindowOptions::TRAIN);
        println!("--synth-steps {synth_steps}: {} clips, {} windows of side and back steps", steps.len(), sw.count);
        train_pos.extend(sw.global_positions_f32());
    }
    let train_windows = motion_windows(&train_pos, per, &tw, &train_maps);
    let valid_windows = motion_windows(&valid_pos, per, &vw, &valid_maps);
    // A resume on other data (another --synth-minutes, --data or split) is refused.
    let fingerprint =
        train_loop::data_fingerprint(&train_pos) ^ train_loop::data_fingerprint(&valid_pos).rotate_left(1);

    let (mut trainer, variant) = match &a.resume {
        Some(dir) => {
            let from = train_loop::resume_dir(dir);
            let (config, stats) = zoo_rtn::checkpoint::read_meta(&from)
                .with_context(|| format!("resuming from {}: it holds no RTN checkpoint", from.display()))?;
            if config.joints != tw.joints()
                || (!config.parents.is_empty() && config.parents != tw.skeleton.parents_i32())
            {
                bail!(
                    "{} holds a model for {} joints (parents {:?}) but the data's skeleton differs ({} joints, parents \
                     {:?}): resume with the data it was trained on",
                    dir.display(),
                    config.joints,
                    config.parents,
                    tw.joints(),
                    tw.skeleton.parents_i32()
                );
            }
            if !from.join(zoo_rtn::checkpoint::OPTIMIZER_FILE).is_file() {
                println!(
                    "note: {} has no optimiser state (written by an older zoo): AMSGrad restarts from zero moments, \
                     which perturbs the first epochs",
                    from.display()
                );
            }
            let state = train_loop::read_state(dir)?;
            let variant = state.extra.get("variant").and_then(|v| serde_json::from_value(v.clone()).ok());
            (RtnTrainer::new(&config, stats, &device)?, variant.unwrap_or(a.variant))
        }
        None => {
            let config = fresh_config(&a, &tw.skeleton.names, &tw.skeleton.parents, train_windows.len())?;
            let stats = fit_stats(&config, &train_windows)?;
            extra.insert("variant".into(), serde_json::to_value(a.variant)?);
            (RtnTrainer::new(&config, stats, &device)?, a.variant)
        }
    };
    println!(
        "training RTN ({variant:?}) on {source}: {} training / {} validation windows, {} parameters, run folder {}",
        train_windows.len(),
        valid_windows.len(),
        trainer.model().parameter_count(),
        out.display()
    );
    // What `zoo export` needs beyond the config: names, rest offsets, fps and units (BVH
    // carries no unit: zoo's data is in centimetres, Y up, right-handed).
    if zoo_nn::checkpoint::RunSkeleton::read(&out)?.is_none() {
        let fps = train.first().map_or(30.0, |c| c.clip.fps() as f32);
        zoo_nn::checkpoint::RunSkeleton::new(&tw.skeleton, fps, zoo_motion::frame::CoordinateFrame::ZOO_CM)
            .write(&out)?;
    }
    let seed = trainer.config().train.seed;
    let threads = default_threads(a.threads);
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    extra.insert("threads".into(), threads.into());
    let mut training = RtnTraining::new(trainer, &train_windows, &valid_windows)?;
    let opts = TrainOptions {
        // A limit too large for a Duration is no limit.
        time_limit: a.time_limit.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok()),
        resume: a.resume.is_some(),
        data: source,
        data_fingerprint: Some(fingerprint),
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
    calibrate_fallback(&out, &valid_windows, &device)
}

/// Calibrates the fallback of the best model in `out` on the validation windows
/// (`zoo_rtn::fallback`): its target misses at the trained length set the thresholds, written
/// into the folder's `config.json` (atomically).
fn calibrate_fallback(out: &Path, valid: &[MotionWindow], device: &candle_core::Device) -> anyhow::Result<()> {
    if !out.join(checkpoint::CONFIG_FILE).is_file() {
        return Ok(());
    }
    let (model, stats) = zoo_rtn::checkpoint::load(out, device)?;
    let misses = zoo_rtn::fallback::target_misses(&model, &stats, valid)?;
    let Some(fallback) = zoo_rtn::fallback::Fallback::calibrate(&misses) else { return Ok(()) };
    let mut config = model.config().clone();
    config.fallback = Some(fallback);
    checkpoint::write_json(&out.join(checkpoint::CONFIG_FILE), &config)?;
    let mean = misses.iter().sum::<f32>() / misses.len() as f32;
    println!(
        "fallback calibrated on {} validation windows (target miss mean {mean:.2}): towards interpolation from a \
         miss of {:.2} (95th percentile), fully at {:.2}; stored in config.json",
        misses.len(),
        fallback.start,
        fallback.full
    );
    Ok(())
}
