//! The training command of the RTN (`zoo train rtn`): the clips (BVH data or synthetic
//! locomotion, over terrain for the terrain-aware model), the windows, a fresh or resumed
//! trainer, the shared training loop and the fallback calibrated at the end.

use crate::RtnResult;
use crate::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;
use zoo_data::dataset::{self, NamedClip, TrainingClips, WindowOptions};
use zoo_data::synth::{self, SynthConfig};
use zoo_data::terrain::Heightmap;
use zoo_data::{Context, Progress, bail};
use zoo_nn::checkpoint;
use zoo_nn::run_folder::RunSpec;
use zoo_nn::train_loop::{self, TrainOptions};

/// Which RTN to train: the paper's model or one of its Table 4 ablations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
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

/// A training-window augmentation of `zoo train rtn --augment` ([`crate::augment`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RtnAugment {
    /// Time reversal (walking backwards).
    Reverse,
    /// Left-right mirroring.
    Mirror,
    /// Speed changes (factors 0.7-1.2 unless `--speed-range` says otherwise).
    Speed,
}

/// Sizes of the RTN to train.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RtnPreset {
    /// The paper's sizes (`Config::paper`).
    Paper,
    /// A small model for tests and quick checks (`Config::tiny`: 12-frame windows).
    Tiny,
}

/// Speed factors of `--augment speed` unless `--speed-range` says otherwise.
pub const SPEED_RANGE: (f32, f32) = (0.7, 1.2);

/// Probabilities of `--augment reverse`, `mirror` and `speed` for each training window.
const AUGMENT_P: (f64, f64, f64) = (0.3, 0.5, 0.3);

/// The options of `zoo train rtn`.
#[derive(Clone, Debug)]
pub struct RtnRunOptions {
    /// The run folder, its length, seed and threads.
    pub run: RunSpec,
    /// The clips.
    pub data: TrainingClips,
    /// Model variant (Table 4 ablations).
    pub variant: RtnVariant,
    /// Model sizes.
    pub preset: RtnPreset,
    /// Predict a correction on top of the interpolation of context and target.
    pub interp_residual: bool,
    /// Train the terrain-aware RTN (every clip needs its heightmap).
    pub terrain: bool,
    /// Training-window augmentations.
    pub augment: Vec<RtnAugment>,
    /// Minutes of the synthetic generator's stepping clips mixed into the training split.
    pub synth_steps: f64,
    /// Minutes of the synthetic generator's jogging and running clips mixed into the training
    /// split.
    pub synth_runs: f64,
    /// Speed factors of `--augment speed` (`None`: [`SPEED_RANGE`]).
    pub speed_range: Option<(f32, f32)>,
    /// Mini-batch size (`None`: the preset's).
    pub batch_size: Option<usize>,
    /// Learning rate (`None`: the preset's).
    pub lr: Option<f64>,
    /// Decay of the moving average of the weights (0: none).
    pub ema: f64,
    /// Transition lengths to train over, `[shortest, longest]` (`None`: [`DEFAULT_LENGTHS`] for
    /// the paper's sizes, the tiny preset's one length; `[n, n]`: one length, `n` frames).
    pub lengths: Option<[usize; 2]>,
    /// Values of the time-to-arrival embedding (`None`: [`DEFAULT_TTA_DIMS`] with `lengths`, none
    /// without; `Some(0)`: none).
    pub time_to_arrival: Option<usize>,
}

/// Values of the time-to-arrival embedding of a run over several lengths unless told otherwise.
pub const DEFAULT_TTA_DIMS: usize = 16;

/// The transition lengths a paper-size run trains over unless `--lengths` says otherwise: the
/// benchmark's 5-45 (docs/experiments/rtn.md: better than one length at every length but the one).
pub const DEFAULT_LENGTHS: [usize; 2] = [5, 45];

impl RtnRunOptions {
    /// The lengths a fresh run trains over, `[shortest, longest]` with `shortest < longest`
    /// (`--lengths`, [`DEFAULT_LENGTHS`] for the paper's sizes), or `None` for one length (the
    /// tiny preset's, or `--lengths N-N`).
    pub fn trained_lengths(&self) -> Option<[usize; 2]> {
        let lengths = match (self.lengths, self.preset) {
            (Some(l), _) => l,
            (None, RtnPreset::Paper) => DEFAULT_LENGTHS,
            (None, RtnPreset::Tiny) => return None,
        };
        (lengths[0] < lengths[1]).then_some(lengths)
    }
}

/// The validation windows of a run: the standard 50 frames, longer when the longest
/// transition to train needs more (10 context frames, the transition, the target and the frame
/// after).
fn window_options(longest: Option<usize>) -> WindowOptions {
    let need = longest.map_or(0, |hi| WindowOptions::TRAIN.n_past + hi + 2);
    WindowOptions { window: WindowOptions::TRAIN.window.max(need), ..WindowOptions::TRAIN }
}

/// The frames a training window holds for a `--speed-range` faster than [`SPEED_RANGE`]: the
/// windows are continued past their end where their clips go on
/// ([`dataset::windows_continued`]), so that the fastest factor can play the frames a step
/// reads (`factor * (frames - 1) + 1`). `None` within the standard range: the windows are the
/// validation ones (a factor a window is too short for is clamped), as docs/ood.md's runs had.
fn continued_frames(longest: Option<usize>, fastest: f32) -> Option<usize> {
    let frames = WindowOptions::TRAIN.n_past + longest.unwrap_or(30) + 2;
    (fastest > SPEED_RANGE.1).then(|| (fastest * (frames - 1) as f32).ceil() as usize + 1)
}

/// The longest transition and the fastest speed change of a run: a resumed run's own (its
/// `config.json`), a fresh run's options.
fn run_shape(o: &RtnRunOptions) -> (Option<usize>, f32) {
    let from_options = || {
        let fastest = if o.augment.contains(&RtnAugment::Speed) { o.speed_range.unwrap_or(SPEED_RANGE).1 } else { 0.0 };
        (o.lengths.or(o.trained_lengths()).map(|[_, hi]| hi), fastest)
    };
    let Some(dir) = &o.run.resume else { return from_options() };
    match crate::checkpoint::read_meta(&train_loop::resume_dir(dir)) {
        Ok((c, _)) => (
            Some(c.transition_frames),
            c.train.augment.as_ref().filter(|a| a.speed > 0.0).map_or(0.0, |a| a.speed_range.1),
        ),
        Err(_) => from_options(),
    }
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

/// Refuses options that cannot work with a terrain-aware run (`terrain`), naming the fix.
fn check_terrain_options(o: &RtnRunOptions, terrain: bool) -> RtnResult<()> {
    if o.terrain && !terrain {
        bail!("--terrain: the run in --resume was trained without terrain; resume it without --terrain");
    }
    if !terrain {
        return Ok(());
    }
    if o.augment.contains(&RtnAugment::Mirror) {
        bail!("--augment mirror moves the motion off its terrain: leave mirror out of --augment with --terrain");
    }
    if o.synth_steps > 0.0 {
        bail!("--synth-steps adds clips without terrain: leave it out with --terrain");
    }
    if o.synth_runs > 0.0 {
        bail!("--synth-runs adds clips without terrain: leave it out with --terrain");
    }
    let (_, fastest) = run_shape(o);
    if fastest > SPEED_RANGE.1 {
        bail!(
            "--speed-range above {}: the terrain-aware RTN keeps the standard range; leave it out with --terrain",
            SPEED_RANGE.1
        );
    }
    Ok(())
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
fn load_terrain_clips(o: &RtnRunOptions, p: &dyn Progress) -> RtnResult<TerrainClips> {
    let t = &o.data;
    if t.data.is_none() {
        let cfg = SynthConfig { minutes: t.synth_minutes, seed: t.seed, terrain: true, ..SynthConfig::default() };
        let clips = synth::generate(&cfg)
            .into_iter()
            .map(|mut c| {
                let map = c.terrain.take().unwrap_or_else(|| Heightmap::flat(0.0));
                (dataset::named_synth(c), map)
            })
            .collect();
        let (train, valid) = dataset::split_synth(clips);
        let source = format!("synthetic locomotion over terrain, {} min, seed {}", t.synth_minutes, t.seed);
        return Ok(TerrainClips { train, valid, source });
    }
    let (train, valid, source) = dataset::training_clips(t, p)?;
    let with_maps = |clips: Vec<NamedClip>| -> RtnResult<Vec<(NamedClip, Heightmap)>> {
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

/// The configuration of a fresh run: the preset, the data's skeleton and the arguments.
fn fresh_config(
    a: &RtnRunOptions,
    names: &[String],
    parents: &[Option<usize>],
    train_windows: usize,
) -> RtnResult<Config> {
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
    if let Some([lo, hi]) = a.lengths
        && !(1 <= lo && lo <= hi)
    {
        bail!("--lengths {lo}-{hi}: give the shortest and the longest transition, 1 <= shortest <= longest");
    }
    let lengths = a.trained_lengths();
    if let Some([lo, hi]) = lengths {
        config.transition_frames = hi;
        config.train.lengths = Some([lo, hi]);
    } else if let Some([_, n]) = a.lengths {
        // One length (`--lengths 30-30`): the paper's windows of that length.
        config.transition_frames = n;
    }
    let dims = a.time_to_arrival.unwrap_or(if lengths.is_some() { DEFAULT_TTA_DIMS } else { 0 });
    if dims > 0 {
        // Constant from the longest transition trained on: the context frames before it look alike.
        let z = zoo_format::TimeToArrival { dims, max: config.transition_frames };
        if let Err(e) = z.check() {
            bail!("--time-to-arrival {dims}: {e}");
        }
        config.time_to_arrival = Some(z);
    }
    config.train.seed = a.run.seed;
    config.interp_residual = a.interp_residual;
    config.terrain = a.terrain;
    if a.speed_range.is_some() && !a.augment.contains(&RtnAugment::Speed) {
        bail!("--speed-range sets the factors of --augment speed: add `--augment speed` (or leave --speed-range out)");
    }
    if !a.augment.is_empty() {
        let has = |x| a.augment.contains(&x);
        let mirror_pairs = if has(RtnAugment::Mirror) {
            let pairs = crate::augment::mirror_pairs(names)?;
            crate::augment::check_mirror_pairs(&pairs, parents, names)?;
            pairs
        } else {
            Vec::new()
        };
        config.train.augment = Some(crate::augment::Augment {
            reverse: if has(RtnAugment::Reverse) { AUGMENT_P.0 } else { 0.0 },
            mirror: if has(RtnAugment::Mirror) { AUGMENT_P.1 } else { 0.0 },
            mirror_pairs,
            speed: if has(RtnAugment::Speed) { AUGMENT_P.2 } else { 0.0 },
            speed_range: a.speed_range.unwrap_or(SPEED_RANGE),
        });
    }
    if !(0.0..1.0).contains(&a.ema) {
        bail!("--ema {} is not a decay in [0, 1) (0.999 averages over about 1000 steps; 0 turns it off)", a.ema);
    }
    config.train.ema_decay = (a.ema > 0.0).then_some(a.ema);
    let steps_per_epoch = train_windows.div_ceil(config.train.batch_size) as u64;
    apply_variant(&mut config, a.variant, steps_per_epoch * a.run.epochs as u64);
    Ok(config)
}

/// The training and validation windows (global positions) with the heightmaps of their clips,
/// and what the run records about them.
struct Data {
    tw: dataset::Windows,
    vw: dataset::Windows,
    /// The training windows' global positions, `train_stride` frames each.
    train_pos: Vec<f32>,
    /// How many frames of each training window are its clip's (at least `tw.window`).
    train_frames: Vec<usize>,
    train_stride: usize,
    valid_pos: Vec<f32>,
    /// Windows (`vw`'s length) the fallback is calibrated on beside the validation ones: held-out
    /// synthetic running of a run with `--synth-runs`.
    calib_pos: Vec<f32>,
    train_maps: Vec<Heightmap>,
    valid_maps: Vec<Heightmap>,
    source: String,
    fps: f32,
    extra: serde_json::Map<String, serde_json::Value>,
}

/// The clips of the run (with their heightmaps on terrain) cut into windows, the stepping
/// clips added to the training windows.
fn data(o: &RtnRunOptions, terrain: bool, p: &dyn Progress) -> RtnResult<Data> {
    let (train, valid, train_maps, valid_maps, source) = if terrain {
        let t = load_terrain_clips(o, p)?;
        let (train, train_maps): (Vec<_>, Vec<_>) = t.train.into_iter().unzip();
        let (valid, valid_maps): (Vec<_>, Vec<_>) = t.valid.into_iter().unzip();
        (train, valid, train_maps, valid_maps, t.source)
    } else {
        let (train, valid, source) = dataset::training_clips(&o.data, p)?;
        (train, valid, Vec::new(), Vec::new(), source)
    };
    let (longest, fastest) = run_shape(o);
    let wo = window_options(longest);
    let tw = dataset::windows(&train, &wo);
    let vw = dataset::windows(&valid, &wo);
    let continued = continued_frames(longest, fastest).filter(|&n| n > wo.window);
    if tw.count == 0 || vw.count == 0 {
        bail!(
            "need at least one {}-frame window in both splits (training {}, validation {})",
            wo.window,
            tw.count,
            vw.count
        );
    }
    let (mut train_pos, valid_pos) = if terrain {
        (world_positions(&train, &tw), world_positions(&valid, &vw))
    } else {
        (tw.global_positions_f32(), vw.global_positions_f32())
    };
    let mut train_frames = vec![tw.window; tw.count];
    if let Some(n) = continued {
        (train_pos, train_frames) = dataset::windows_continued(&train, &tw, &wo, n);
    }
    let mut extra = serde_json::Map::new();
    // Synthetic clips: a resumed run keeps what it was started with.
    let saved = o.run.resume.as_ref().map(|dir| train_loop::read_state(dir)).transpose()?;
    let mut calib_pos = Vec::new();
    for kind in [SynthKind::Steps, SynthKind::Runs] {
        let minutes = match &saved {
            Some(state) => state.extra.get(kind.key()).and_then(|v| v.as_f64()).unwrap_or(0.0),
            None => kind.minutes(o),
        };
        extra.insert(kind.key().into(), minutes.into());
        if minutes > 0.0 {
            let (pos, frames) = synth_windows(o, &tw, kind, minutes, continued)?;
            train_pos.extend(pos);
            train_frames.extend(frames);
            if let SynthKind::Runs = kind {
                calib_pos = running_calibration_windows(o, &vw, minutes);
            }
        }
    }
    let fps = train.first().map_or(30.0, |c| c.clip.fps() as f32);
    let train_stride = continued.unwrap_or(tw.window);
    Ok(Data {
        tw,
        vw,
        train_pos,
        train_frames,
        train_stride,
        valid_pos,
        calib_pos,
        train_maps,
        valid_maps,
        source,
        fps,
        extra,
    })
}

/// Synthetic clips mixed into the training split of `--data`.
#[derive(Clone, Copy)]
enum SynthKind {
    /// `--synth-steps`: walks made mostly of side and back steps.
    Steps,
    /// `--synth-runs`: jogging and running.
    Runs,
}

impl SynthKind {
    /// The key of `train_state.json` and the option's name without its dashes.
    fn key(self) -> &'static str {
        match self {
            SynthKind::Steps => "synth_steps",
            SynthKind::Runs => "synth_runs",
        }
    }

    fn minutes(self, o: &RtnRunOptions) -> f64 {
        match self {
            SynthKind::Steps => o.synth_steps,
            SynthKind::Runs => o.synth_runs,
        }
    }
}

/// The global positions of the training windows (`tw`'s length, or `continued` frames as
/// [`dataset::windows_continued`] has them) of `minutes` of the synthetic generator's stepping
/// or running clips (on bandai2's skeleton, which the data must be on), and the frames of each
/// that are its clip's.
fn synth_windows(
    o: &RtnRunOptions,
    tw: &dataset::Windows,
    kind: SynthKind,
    minutes: f64,
    continued: Option<usize>,
) -> RtnResult<(Vec<f32>, Vec<usize>)> {
    let option = format!("--{}", kind.key().replace('_', "-"));
    let cfg = SynthConfig { minutes, seed: o.run.seed, terrain: false, ..SynthConfig::default() };
    if let Err(m) = synth::check_mixable(&option, "the data", &tw.skeleton, None, cfg.fps) {
        bail!("{m}");
    }
    let (clips, what) = match kind {
        SynthKind::Steps => (synth::generate_stepping(&cfg), "side and back steps"),
        SynthKind::Runs => (synth::generate_running(&cfg), "jogging and running"),
    };
    let (clips, sw, wo) = synth_clip_windows(clips, tw.window);
    println!("{option} {minutes}: {} clips, {} windows of {what}", clips.len(), sw.count);
    Ok(match continued {
        Some(n) => dataset::windows_continued(&clips, &sw, &wo, n),
        None => (sw.global_positions_f32(), vec![sw.window; sw.count]),
    })
}

/// The seed offset of the held-out synthetic running the fallback of a `--synth-runs` run is
/// calibrated on (clips the training never sees).
const RUNNING_CALIBRATION_SEED: u64 = 0x0ca1_1b4a_7e00;

/// The global positions of validation-length windows (`vw`'s) of held-out synthetic running, a
/// tenth of the `minutes` trained on (at least a minute), generated with another seed: with
/// `--synth-runs` the network is trained to run, so the fallback's calibration must know how far
/// it misses on running, not only on the validation clips.
fn running_calibration_windows(o: &RtnRunOptions, vw: &dataset::Windows, minutes: f64) -> Vec<f32> {
    let seed = o.run.seed.wrapping_add(RUNNING_CALIBRATION_SEED);
    let cfg = SynthConfig { minutes: (minutes / 10.0).max(1.0), seed, terrain: false, ..SynthConfig::default() };
    synth_clip_windows(synth::generate_running(&cfg), vw.window).1.global_positions_f32()
}

/// Synthetic clips cut into windows of `window` frames (the benchmark's offset and context).
fn synth_clip_windows(
    clips: Vec<synth::SynthClip>,
    window: usize,
) -> (Vec<NamedClip>, dataset::Windows, WindowOptions) {
    let clips: Vec<NamedClip> = clips.into_iter().map(dataset::named_synth).collect();
    let wo = WindowOptions { window, ..WindowOptions::TRAIN };
    let w = dataset::windows(&clips, &wo);
    (clips, w, wo)
}

/// The trainer of a resumed run (its configuration and statistics, refused on another
/// skeleton) or of a fresh one, and the variant it trains.
fn trainer(o: &RtnRunOptions, d: &mut Data, train: &[MotionWindow]) -> RtnResult<(RtnTrainer, RtnVariant)> {
    let device = candle_core::Device::Cpu;
    let tw = &d.tw;
    let Some(dir) = &o.run.resume else {
        let config = fresh_config(o, &tw.skeleton.names, &tw.skeleton.parents, train.len())?;
        let stats = fit_stats(&config, train)?;
        d.extra.insert("variant".into(), serde_json::to_value(o.variant).context("the variant")?);
        return Ok((RtnTrainer::new(&config, stats, &device)?, o.variant));
    };
    let from = train_loop::resume_dir(dir);
    let (config, stats) = crate::checkpoint::read_meta(&from)
        .with_context(|| format!("resuming from {}: it holds no RTN checkpoint", from.display()))?;
    if config.joints != tw.joints() || (!config.parents.is_empty() && config.parents != tw.skeleton.parents_i32()) {
        bail!(
            "{} holds a model for {} joints (parents {:?}) but the data's skeleton differs ({} joints, parents {:?}): \
             resume with the data it was trained on",
            dir.display(),
            config.joints,
            config.parents,
            tw.joints(),
            tw.skeleton.parents_i32()
        );
    }
    if !from.join(crate::checkpoint::OPTIMIZER_FILE).is_file() {
        println!(
            "note: {} has no optimiser state (written by an older zoo): AMSGrad restarts from zero moments, which \
             perturbs the first epochs",
            from.display()
        );
    }
    let state = train_loop::read_state(dir)?;
    let variant = state.extra.get("variant").and_then(|v| serde_json::from_value(v.clone()).ok());
    Ok((RtnTrainer::new(&config, stats, &device)?, variant.unwrap_or(o.variant)))
}

/// Runs `zoo train rtn`: trains into the run folder and calibrates the fallback of the best
/// model.
pub fn run(o: &RtnRunOptions, p: &dyn Progress) -> RtnResult<()> {
    let out = zoo_nn::run_folder::prepare(&o.run, &RUN_FILES, |_| Ok(()))?;
    // A resumed run keeps its configuration, terrain included.
    let terrain = match &o.run.resume {
        Some(dir) => crate::checkpoint::read_meta(&train_loop::resume_dir(dir)).map_or(o.terrain, |(c, _)| c.terrain),
        None => o.terrain,
    };
    check_terrain_options(o, terrain)?;
    let mut d = data(o, terrain, p)?;
    let (per, valid_per) = (d.train_stride * d.tw.joints() * 3, d.vw.window * d.vw.joints() * 3);
    let (train_pos, valid_pos) = (std::mem::take(&mut d.train_pos), std::mem::take(&mut d.valid_pos));
    let (train_maps, valid_maps) = (std::mem::take(&mut d.train_maps), std::mem::take(&mut d.valid_maps));
    let mut train_windows = motion_windows(&train_pos, per, &d.tw, &train_maps);
    // A continued window ends where its clip does.
    for (w, &frames) in train_windows.iter_mut().zip(&d.train_frames) {
        w.positions = &w.positions[..frames * d.tw.joints() * 3];
    }
    let valid_windows = motion_windows(&valid_pos, valid_per, &d.vw, &valid_maps);
    // A resume on other data (another --synth-minutes, --data or split) is refused.
    let fingerprint =
        train_loop::data_fingerprint(&train_pos) ^ train_loop::data_fingerprint(&valid_pos).rotate_left(1);
    let (mut trainer, variant) = trainer(o, &mut d, &train_windows)?;
    println!(
        "training RTN ({variant:?}) on {}: {} training / {} validation windows, {} parameters, run folder {}",
        d.source,
        train_windows.len(),
        valid_windows.len(),
        trainer.model().parameter_count(),
        out.display()
    );
    // What `zoo export` needs beyond the config: names, rest offsets, fps and units (BVH
    // carries no unit: zoo's data is in centimetres, Y up, right-handed).
    if zoo_nn::checkpoint::RunSkeleton::read(&out)?.is_none() {
        zoo_nn::checkpoint::RunSkeleton::new(&d.tw.skeleton, d.fps, zoo_motion::frame::CoordinateFrame::ZOO_CM)
            .write(&out)?;
    }
    let seed = trainer.config().train.seed;
    let threads = o.run.thread_count();
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    d.extra.insert("threads".into(), threads.into());
    let mut training = RtnTraining::new(trainer, &train_windows, &valid_windows)?;
    let opts = TrainOptions {
        time_limit: o.run.time_limit(),
        resume: o.run.resume.is_some(),
        data: d.source.clone(),
        data_fingerprint: Some(fingerprint),
        extra: d.extra.clone(),
        ..TrainOptions::new(&out, o.run.epochs, seed)
    };
    let state = train_loop::train(&mut training, &opts)?;
    println!("{}", zoo_nn::run_folder::done_line(&state, &out));
    let calib = std::mem::take(&mut d.calib_pos);
    let mut calib_windows = valid_windows.clone();
    calib_windows.extend(calib.chunks_exact(valid_per).map(MotionWindow::new));
    if !calib.is_empty() {
        println!(
            "the fallback is calibrated on the {} validation windows and {} of held-out synthetic running",
            valid_windows.len(),
            calib_windows.len() - valid_windows.len()
        );
    }
    calibrate_fallback(&out, &calib_windows, &candle_core::Device::Cpu)
}

/// Calibrates the fallback of the best model in `out` on the validation windows
/// (`zoo_rtn::fallback`): its target misses at the trained length set the thresholds, and for a
/// run over several lengths its misses at each validation length set them per length; written
/// into the folder's `config.json` (atomically).
fn calibrate_fallback(out: &Path, valid: &[MotionWindow], device: &candle_core::Device) -> RtnResult<()> {
    if !out.join(checkpoint::CONFIG_FILE).is_file() {
        return Ok(());
    }
    let (model, stats) = crate::checkpoint::load(out, device)?;
    let misses = crate::fallback::target_misses(&model, &stats, valid)?;
    let Some(fallback) = crate::fallback::Fallback::calibrate(&misses) else { return Ok(()) };
    let mut config = model.config().clone();
    config.fallback = Some(fallback);
    config.fallback_lengths.clear();
    let lengths = config.validation_lengths();
    if config.train.lengths.is_some() && lengths.len() > 1 {
        for n in lengths {
            // The longest length's misses are the ones measured above.
            let at = if n == config.transition_frames {
                None
            } else {
                Some(crate::fallback::target_misses_at(&model, &stats, valid, n)?)
            };
            if let Some(f) = crate::fallback::Fallback::calibrate(at.as_deref().unwrap_or(&misses)) {
                config.fallback_lengths.push(zoo_format::TransitionFallbackAt {
                    length: n,
                    start: f.start,
                    full: f.full,
                });
                println!("fallback at {n} frames: from a miss of {:.2}, fully at {:.2}", f.start, f.full);
            }
        }
    }
    checkpoint::write_json(&out.join(checkpoint::CONFIG_FILE), &config)?;
    let mean = misses.iter().sum::<f32>() / misses.len() as f32;
    println!(
        "fallback calibrated on {} windows (target miss mean {mean:.2}): towards interpolation from a \
         miss of {:.2} (95th percentile), fully at {:.2}; stored in config.json",
        misses.len(),
        fallback.start,
        fallback.full
    );
    Ok(())
}
