//! The online control benchmark (`zoo bench control`, paper sec. 5.3, protocol in
//! docs/rnn-gmm-control.md): a control script (by default [`ControlScript::benchmark`]: walk,
//! run, stop and 180-degree turns) followed by the candle controller (proposals and L-BFGS
//! through the generator) and by the runtime's controller (tract, the exported generator,
//! proposals only), with each key's speed and heading error from 1 s after it, foot skate
//! beside the real clips', and the compute per frame on one core.

use glam::DVec3;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::{Context, Message, Progress, bail};
use zoo_motion::Clip;
use zoo_rnngmm::OnlineOptions;
use zoo_rnngmm::checkpoint::LoadedGenerator;
use zoo_rnngmm::controls::{ControlScript, SegmentScore, score};
use zoo_rnngmm::error::RnnGmmResult;
use zoo_rnngmm::run::{control_with_progress, plot_controls};
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::pose::EnginePose;
use zoo_runtime::synthesis::SynthesisModel;

/// The benchmark's settings and inputs.
pub struct ControlBenchOptions {
    /// Run folder of `zoo train rnn-gmm` (the candle controller's generator).
    pub model: PathBuf,
    /// The same generator exported and loaded by the runtime (without its refiner), and its
    /// file; without it only the candle controller runs.
    pub onnx: Option<(SynthesisModel, PathBuf)>,
    /// Start clip and frame (`None`: the run folder's start clip, frame 29).
    pub from: Option<(PathBuf, usize)>,
    /// The control script and its file (`None`: [`ControlScript::benchmark`]).
    pub script: Option<(ControlScript, PathBuf)>,
    /// Run the candle controller.
    pub candle: bool,
    /// Run the runtime's controller (with `onnx`).
    pub runtime: bool,
    /// Seeds of the proposals: one run of each controller per seed.
    pub seeds: Vec<u64>,
    /// Real clips whose foot skate is the reference, with `glob`.
    pub data: Option<PathBuf>,
    /// Clip-name pattern within `data`.
    pub glob: String,
    /// Seed frames the runtime controller warms its generator with.
    pub runtime_seed_frames: usize,
    /// Folder that receives, per run, the speed and heading plot and the BVH.
    pub plots: Option<PathBuf>,
    /// The candle controller's settings (the runtime's take the same batch, offsets and sigmas).
    pub online: OnlineOptions,
}

/// One controller with one seed.
#[derive(Clone, Debug, Serialize)]
pub struct Run {
    /// `candle` or `runtime`.
    pub controller: String,
    /// Seed of the proposals.
    pub seed: u64,
    /// Frames generated.
    pub frames: usize,
    /// Each key's scores.
    pub segments: Vec<SegmentScore>,
    /// Keys passed.
    pub passed: usize,
    /// Foot skate (cm per frame).
    pub foot_skate: f64,
    /// Compute per frame (ms): median, mean and largest over batches (candle: a batch's time
    /// over its frames) or steps (runtime: each step), after the first; the first alone (it
    /// warms up: the runtime feeds its seed frames and plans its first batch then).
    pub ms_first: f64,
    /// See `ms_first`.
    pub ms_per_frame_median: f64,
    /// See `ms_first`.
    pub ms_per_frame_mean: f64,
    /// See `ms_first`.
    pub ms_per_frame_max: f64,
}

/// What the benchmark measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Run folder.
    pub model: String,
    /// The exported generator, when the runtime ran.
    pub onnx: Option<String>,
    /// The start clip and frame.
    pub start: String,
    /// The control script.
    pub script: String,
    /// The candle controller's settings.
    pub options: String,
    /// The real clips' foot skate, with `data`.
    pub real_foot_skate: Option<f64>,
    /// The real clips, with `data`.
    pub real: Option<String>,
    /// One entry per controller and seed.
    pub runs: Vec<Run>,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() { f64::NAN } else { s[s.len() / 2] }
}

fn summary(v: &[f64]) -> (f64, f64, f64) {
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    (median(v), mean, v.iter().copied().fold(0.0, f64::max))
}

/// The runtime controller over `script`: per frame speed (clip units/s), yaw, global positions
/// and the step's time (ms).
#[allow(clippy::type_complexity)]
fn runtime_run(
    model: &SynthesisModel,
    settings: &ControlSettings,
    seed: u64,
    seed_frames: &[f32],
    script: &ControlScript,
    fps: f64,
) -> RnnGmmResult<(Vec<f64>, Vec<f64>, Vec<DVec3>, Vec<f64>)> {
    let runtime = |e: zoo_runtime::MotionError| Message::new(e);
    let mut ch = ControlledCharacter::new(model, seed, settings.clone()).map_err(runtime)?;
    ch.start(model, seed_frames, 0.0, 0.0, script.keys()[0].heading as f32).map_err(runtime)?;
    let mut runner = ControlRunner::new(model).map_err(runtime)?;
    let mut pose = EnginePose::with_global_positions(model.joints());
    let total = (script.duration() * fps).round() as usize;
    let (mut speed, mut yaw, mut global, mut ms) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for f in 0..total {
        let k = script.at(f as f64 / fps);
        let clock = Instant::now();
        runner.step(&mut ch, Control::new(k.speed as f32, k.heading as f32), &mut pose).map_err(runtime)?;
        ms.push(1e3 * clock.elapsed().as_secs_f64());
        let d = pose.root_delta_position;
        speed.push((d.x as f64).hypot(d.z as f64) * fps);
        yaw.push(ch.placement()[2]);
        global.extend(pose.global_positions.iter().map(|p| p.as_dvec3()));
    }
    Ok((speed, yaw, global, ms))
}

/// One controller's run, measured.
struct Measured<'a> {
    controller: &'a str,
    seed: u64,
    speed: &'a [f64],
    yaw: &'a [f64],
    foot_skate: f64,
    ms: &'a [f64],
    bvh: Option<Clip>,
}

/// Scores a run against the script, writes its plot and BVH (with `plots`).
fn record(
    o: &ControlBenchOptions,
    script: &ControlScript,
    fps: f64,
    skeleton: &zoo_motion::Skeleton,
    m: Measured,
) -> RnnGmmResult<Run> {
    let segments = score(script, fps, m.speed, m.yaw, 1.0);
    let (med, mean, max) = summary(m.ms.get(1..).unwrap_or_default());
    if let Some(dir) = &o.plots {
        let stem = format!("{}-seed{}", m.controller, m.seed);
        plot_controls(&dir.join(format!("{stem}.png")), script, fps, m.speed, m.yaw)?;
        if let Some(mut c) = m.bvh {
            c.skeleton = skeleton.clone();
            zoo_data::bvh::write_file(&c, &dir.join(format!("{stem}.bvh")))
                .with_context(|| format!("writing {stem}.bvh"))?;
        }
    }
    Ok(Run {
        controller: m.controller.to_string(),
        seed: m.seed,
        frames: m.speed.len(),
        passed: segments.iter().filter(|s| s.pass).count(),
        segments,
        foot_skate: m.foot_skate,
        ms_first: m.ms.first().copied().unwrap_or(f64::NAN),
        ms_per_frame_median: med,
        ms_per_frame_mean: mean,
        ms_per_frame_max: max,
    })
}

/// Which of two methods a comma-separated `option` list asks for, `[candle or offline,
/// runtime]`, given whether an exported generator (`--onnx`) was given: the runtime alone needs
/// one; both without one run the first only. `--controllers` of `zoo bench control` and
/// `--followers` of `zoo bench follow`.
pub fn methods_of(list: &[String], names: [&str; 2], option: &str, onnx: bool) -> RnnGmmResult<[bool; 2]> {
    if let Some(m) = list.iter().find(|m| !names.contains(&m.as_str())) {
        bail!("unknown method `{m}` in {option}: use {}, {} or both", names[0], names[1]);
    }
    let asked = names.map(|n| list.iter().any(|m| m == n));
    if asked == [false, true] && !onnx {
        bail!(
            "{option} {} needs --onnx FILE (the generator exported with `zoo export --onnx DIR --out FILE.onnx`)",
            names[1]
        );
    }
    Ok(asked)
}

/// Refuses an exported generator `m` that is not the export of the run folder `dir` (`g`).
pub(crate) fn check_export(m: &SynthesisModel, g: &LoadedGenerator, dir: &std::path::Path) -> RnnGmmResult<()> {
    if m.frame_dim() != g.spec.dim() || m.joints() != g.spec.skeleton.len() {
        bail!(
            "--onnx is not the export of --model: its frames have {} values on {} joints, the model's {} on {}; export \
             the run folder with `zoo export --onnx {} --out FILE.onnx`",
            m.frame_dim(),
            m.joints(),
            g.spec.dim(),
            g.spec.skeleton.len(),
            dir.display()
        );
    }
    Ok(())
}

/// The runtime's warm-up frames (clip units): up to `count` feature frames of `clip` ending at
/// `frame` (its last frame when beyond).
pub(crate) fn seed_frames(g: &LoadedGenerator, clip: &Clip, frame: usize, count: usize) -> RnnGmmResult<Vec<f32>> {
    let enc = g.spec.encode(clip)?;
    let dim = g.spec.dim();
    let frame = frame.min(enc.values.len() / dim - 1);
    let first = (frame + 1).saturating_sub(count);
    Ok(enc.values[first * dim..(frame + 1) * dim].to_vec())
}

/// The runtime's settings from the candle controller's.
fn runtime_settings(opts: &OnlineOptions) -> ControlSettings {
    ControlSettings {
        batch: opts.batch,
        speed_offsets: opts.speed_offsets.iter().map(|v| *v as f32).collect(),
        turn_offsets: opts.turn_offsets.iter().map(|v| *v as f32).collect(),
        side_offsets: vec![0.0],
        sigma_speed: opts.sigma_speed as f32,
        sigma_heading: opts.sigma_heading as f32,
        temperature: opts.temperature as f32,
    }
}

/// Runs the benchmark.
pub fn run(o: &ControlBenchOptions, p: &dyn Progress) -> RnnGmmResult<Report> {
    if let Some(d) = &o.plots {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    if o.seeds.is_empty() {
        bail!("--seeds is empty: give at least one seed");
    }
    let script = o.script.as_ref().map_or_else(ControlScript::benchmark, |(s, _)| s.clone());
    let (g, _) = zoo_rnngmm::run::load_run(&o.model, true)?;
    let from = o.from.as_ref().map(|(p, f)| (p.as_path(), *f));
    let (clip, frame, label) = zoo_rnngmm::run::start_clip(&o.model, from, &g)?;
    let runtime = o.onnx.as_ref().map(|(m, _)| m);
    if let Some(m) = runtime {
        check_export(m, &g, &o.model)?;
    }
    let (skate, real) = zoo_rnngmm::bench::skate_reference(&g, o.data.as_deref(), &o.glob, &[&clip], p)?;
    let settings = runtime_settings(&o.online);
    let seed_frames = &seed_frames(&g, &clip, frame, o.runtime_seed_frames)?;
    let fps = g.spec.fps;
    let mut runs = Vec::new();
    for &seed in &o.seeds {
        if o.candle {
            let opts = OnlineOptions { seed, ..o.online.clone() };
            let c = control_with_progress(&g, &clip, frame, &script, &opts, &format!("candle, seed {seed}"), p)
                .with_context(|| format!("the candle controller from {label}"))?;
            let ms: Vec<f64> = c.batch_seconds.iter().map(|s| 1e3 * s / opts.batch as f64).collect();
            let foot_skate = skate.mean_over(&[&c.motion.clip]);
            let (speed, yaw, bvh) = (&c.speed, &c.yaw, Some(c.motion.clip.clone()));
            let m = Measured { controller: "candle", seed, speed, yaw, foot_skate, ms: &ms, bvh };
            runs.push(record(o, &script, fps, &clip.skeleton, m)?);
        }
        if let Some(model) = runtime.filter(|_| o.runtime) {
            let (speed, yaw, global, ms) = runtime_run(model, &settings, seed, seed_frames, &script, fps)
                .with_context(|| format!("the runtime controller from {label}"))?;
            let foot_skate = skate.skate(&global, speed.len(), model.joints());
            let m = Measured { controller: "runtime", seed, speed: &speed, yaw: &yaw, foot_skate, ms: &ms, bvh: None };
            runs.push(record(o, &script, fps, &clip.skeleton, m)?);
        }
    }
    Ok(Report {
        model: o.model.display().to_string(),
        onnx: o.onnx.as_ref().map(|(_, p)| p.display().to_string()),
        start: label,
        script: o.script.as_ref().map_or("built-in benchmark".into(), |(_, p)| p.display().to_string()),
        options: format!("{:?}", o.online),
        real_foot_skate: real.as_ref().map(|r| r.1),
        real: real.as_ref().map(|(w, _)| w.clone()),
        runs,
    })
}

impl Run {
    /// The run's summary line and its table of keys.
    pub fn text(&self) -> String {
        let (c, seed, skate) = (&self.controller, self.seed, self.foot_skate);
        let mut s = format!(
            "{c}, seed {seed}: foot skate {skate:.3}, {:.1} ms per frame (median; mean {:.1}, max {:.1}; the first \
             {:.1})\n",
            self.ms_per_frame_median, self.ms_per_frame_mean, self.ms_per_frame_max, self.ms_first
        );
        s += "| key (s) | target speed | speed after 1 s | error | target heading | error at 1 s (deg) | mean after \
              (deg) | max after (deg) | pass |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
        for k in &self.segments {
            s += &format!(
                "| {:.0} | {:.0} | {:.0} | {:.1}% | {:.0} | {:.1} | {:.1} | {:.1} | {} |\n",
                k.time,
                k.target_speed,
                k.speed_after,
                100.0 * k.speed_error,
                k.target_heading_deg,
                k.heading_at_settle_deg,
                k.heading_mean_deg,
                k.heading_max_deg,
                if k.pass { "yes" } else { "no" }
            );
        }
        s
    }
}

impl Report {
    /// The report as the command prints it: every run, then the summary table.
    pub fn text(&self) -> String {
        let mut s: String = self.runs.iter().map(Run::text).collect();
        s += "\n| controller | seed | keys passed | foot skate (cm/frame) | ms per frame, median | mean | max | first \
              frame (ms) |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n";
        for r in &self.runs {
            s += &format!(
                "| {} | {} | {}/{} | {:.3} | {:.1} | {:.1} | {:.1} | {:.1} |\n",
                r.controller,
                r.seed,
                r.passed,
                r.segments.len(),
                r.foot_skate,
                r.ms_per_frame_median,
                r.ms_per_frame_mean,
                r.ms_per_frame_max,
                r.ms_first
            );
        }
        if let (Some(what), Some(skate)) = (&self.real, self.real_foot_skate) {
            s += &format!("real foot skate: {skate:.3} cm/frame ({what})\n");
        }
        s + &format!("one core (RAYON_NUM_THREADS=1); start {}", self.start)
    }
}
