//! `zoo bench control`: the online control benchmark (RNN-GMM control, issue 15, paper sec.
//! 5.3): a control script (by default [`ControlScript::benchmark`]: walk, run, stop and 180-degree
//! turns) followed by the candle controller (proposals and L-BFGS through the generator) and by
//! the runtime's controller (tract, the exported generator, proposals only), with each key's
//! speed and heading error from 1 s after it, foot skate beside the real clips', and the compute
//! per frame on one core.

use crate::cmd::bench_follow::skate_reference;
use crate::cmd::control::{OnlineArgs, control_with_progress, plot, read_script};
use crate::cmd::generate::{load_model, start_clip};
use anyhow::{Context, bail};
use clap::Args;
use glam::DVec3;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_motion::Clip;
use zoo_rnngmm::controls::{ControlScript, SegmentScore, score};
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::pose::EnginePose;
use zoo_runtime::synthesis::SynthesisModel;

/// Arguments of `zoo bench control`.
#[derive(Args)]
pub struct BenchControlArgs {
    /// Run folder of `zoo train rnn-gmm` (the candle controller's generator).
    #[arg(long)]
    pub model: PathBuf,
    /// The same generator exported for the runtime (`zoo export --onnx DIR --out FILE.onnx`);
    /// without it only the candle controller runs.
    #[arg(long)]
    pub onnx: Option<PathBuf>,
    /// Start clip and frame, `CLIP.bvh:FRAME` [default: the run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Option<String>,
    /// Control script (`.json`, see `zoo control`) [default: the built-in benchmark script].
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Controllers to run, comma-separated: candle, runtime (the runtime needs --onnx).
    #[arg(long, value_delimiter = ',', default_values_t = vec!["candle".to_string(), "runtime".to_string()])]
    pub controllers: Vec<String>,
    /// Seeds of the proposals, comma-separated: one run of each controller per seed.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1u64, 2, 3], value_parser = crate::args::seed)]
    pub seeds: Vec<u64>,
    /// Real clips whose foot skate is the reference (a folder or file of BVH); with --glob.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Clip-name pattern within --data.
    #[arg(long, default_value = "*")]
    pub glob: String,
    /// Seed frames the runtime controller warms its generator with (it has no eq. 26 initial
    /// state; the candle controller estimates one from 2 frames).
    #[arg(long, default_value_t = 30, value_parser = crate::args::frame_count)]
    pub runtime_seed_frames: usize,
    /// Folder that receives, per run, the speed and heading plot and the BVH.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// The candle controller's settings (the runtime's take the same batch, offsets and sigmas).
    #[command(flatten)]
    pub online: OnlineArgs,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One controller with one seed.
#[derive(Serialize)]
struct Run {
    controller: String,
    seed: u64,
    frames: usize,
    segments: Vec<SegmentScore>,
    passed: usize,
    foot_skate: f64,
    /// Compute per frame (ms): median, mean and largest over batches (candle: a batch's time
    /// over its frames) or steps (runtime: each step), after the first; the first alone (it
    /// warms up: the runtime feeds its seed frames and plans its first batch then).
    ms_first: f64,
    /// See `ms_first`.
    ms_per_frame_median: f64,
    ms_per_frame_mean: f64,
    ms_per_frame_max: f64,
}

#[derive(Serialize)]
struct Report {
    model: String,
    onnx: Option<String>,
    start: String,
    script: String,
    options: String,
    real_foot_skate: Option<f64>,
    real: Option<String>,
    runs: Vec<Run>,
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
) -> anyhow::Result<(Vec<f64>, Vec<f64>, Vec<DVec3>, Vec<f64>)> {
    let mut ch = ControlledCharacter::new(model, seed, settings.clone())?;
    ch.start(model, seed_frames, 0.0, 0.0, script.keys()[0].heading as f32)?;
    let mut runner = ControlRunner::new(model)?;
    let mut pose = EnginePose::with_global_positions(model.joints());
    let total = (script.duration() * fps).round() as usize;
    let (mut speed, mut yaw, mut global, mut ms) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for f in 0..total {
        let k = script.at(f as f64 / fps);
        let clock = Instant::now();
        runner.step(&mut ch, Control::new(k.speed as f32, k.heading as f32), &mut pose)?;
        ms.push(1e3 * clock.elapsed().as_secs_f64());
        let d = pose.root_delta_position;
        speed.push((d.x as f64).hypot(d.z as f64) * fps);
        yaw.push(ch.placement()[2]);
        global.extend(pose.global_positions.iter().map(|p| p.as_dvec3()));
    }
    Ok((speed, yaw, global, ms))
}

/// Runs the benchmark.
pub fn run(a: BenchControlArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    if let Some(d) = &a.plots {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    if a.seeds.is_empty() {
        bail!("--seeds is empty: give at least one seed");
    }
    if let Some(c) = a.controllers.iter().find(|c| !matches!(c.as_str(), "candle" | "runtime")) {
        bail!("unknown controller `{c}` in --controllers: use candle, runtime or both");
    }
    let run_candle = a.controllers.iter().any(|c| c == "candle");
    let run_runtime = a.controllers.iter().any(|c| c == "runtime");
    if run_runtime && a.onnx.is_none() && a.controllers.len() == 1 {
        bail!(
            "--controllers runtime needs --onnx FILE (the generator exported with `zoo export --onnx DIR --out FILE.onnx`)"
        );
    }
    let script = match &a.script {
        Some(p) => read_script(p)?,
        None => ControlScript::benchmark(),
    };
    let (g, _) = load_model(&a.model, true)?;
    let (clip, frame, label) = start_clip(&a.model, a.from.as_deref(), &g)?;
    let runtime = match &a.onnx {
        Some(p) => Some(
            crate::exported::load(p, &[zoo_runtime::MotionTaskKind::Synthesis], "`zoo bench control --onnx`")?
                .into_synthesis()?
                .without_refiner(),
        ),
        None => None,
    };
    if let Some(m) = &runtime
        && (m.frame_dim() != g.spec.dim() || m.joints() != g.spec.skeleton.len())
    {
        bail!(
            "--onnx is not the export of --model: its frames have {} values on {} joints, the model's {} on {}; export \
             the run folder with `zoo export --onnx {} --out FILE.onnx`",
            m.frame_dim(),
            m.joints(),
            g.spec.dim(),
            g.spec.skeleton.len(),
            a.model.display()
        );
    }
    let (skate, real) = skate_reference(&g, a.data.as_deref(), &a.glob, &[&clip])?;
    let real_skate = real.as_ref().map(|r| r.1);
    let opts = a.online.options();
    let settings = ControlSettings {
        batch: opts.batch,
        speed_offsets: opts.speed_offsets.iter().map(|v| *v as f32).collect(),
        turn_offsets: opts.turn_offsets.iter().map(|v| *v as f32).collect(),
        sigma_speed: opts.sigma_speed as f32,
        sigma_heading: opts.sigma_heading as f32,
        temperature: opts.temperature as f32,
    };
    // The runtime's warm-up frames (clip units), ending at the start frame.
    let enc = g.spec.encode(&clip)?;
    let dim = g.spec.dim();
    let first = (frame + 1).saturating_sub(a.runtime_seed_frames);
    let seed_frames = &enc.values[first * dim..(frame + 1) * dim];
    let fps = g.spec.fps;
    let mut runs = Vec::new();
    let mut record = |controller: &str,
                      seed: u64,
                      speed: &[f64],
                      yaw: &[f64],
                      foot_skate: f64,
                      ms: &[f64],
                      bvh: Option<Clip>|
     -> anyhow::Result<()> {
        let segments = score(&script, fps, speed, yaw, 1.0);
        let (med, mean, max) = summary(ms.get(1..).unwrap_or_default());
        let first = ms.first().copied().unwrap_or(f64::NAN);
        println!(
            "{controller}, seed {seed}: foot skate {foot_skate:.3}, {med:.1} ms per frame (median; mean {mean:.1}, max \
             {max:.1}; the first {first:.1})"
        );
        println!(
            "| key (s) | target speed | speed after 1 s | error | target heading | error at 1 s (deg) | mean after (deg) | max after (deg) | pass |"
        );
        println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
        for s in &segments {
            println!(
                "| {:.0} | {:.0} | {:.0} | {:.1}% | {:.0} | {:.1} | {:.1} | {:.1} | {} |",
                s.time,
                s.target_speed,
                s.speed_after,
                100.0 * s.speed_error,
                s.target_heading_deg,
                s.heading_at_settle_deg,
                s.heading_mean_deg,
                s.heading_max_deg,
                if s.pass { "yes" } else { "no" }
            );
        }
        if let Some(dir) = &a.plots {
            let stem = format!("{controller}-seed{seed}");
            plot(&dir.join(format!("{stem}.png")), &script, fps, speed, yaw)?;
            if let Some(mut c) = bvh {
                c.skeleton = clip.skeleton.clone();
                zoo_data::bvh::write_file(&c, &dir.join(format!("{stem}.bvh")))
                    .with_context(|| format!("writing {stem}.bvh"))?;
            }
        }
        runs.push(Run {
            controller: controller.to_string(),
            seed,
            frames: speed.len(),
            passed: segments.iter().filter(|s| s.pass).count(),
            segments,
            foot_skate,
            ms_first: first,
            ms_per_frame_median: med,
            ms_per_frame_mean: mean,
            ms_per_frame_max: max,
        });
        Ok(())
    };
    for &seed in &a.seeds {
        if run_candle {
            let o = zoo_rnngmm::OnlineOptions { seed, ..opts.clone() };
            let c = control_with_progress(&g, &clip, frame, &script, &o, &format!("candle, seed {seed}"))
                .with_context(|| format!("the candle controller from {label}"))?;
            let ms: Vec<f64> = c.batch_seconds.iter().map(|s| 1e3 * s / o.batch as f64).collect();
            let fs = skate.mean_over(&[&c.motion.clip]);
            record("candle", seed, &c.speed, &c.yaw, fs, &ms, Some(c.motion.clip.clone()))?;
        }
        if let Some(m) = runtime.as_ref().filter(|_| run_runtime) {
            let (speed, yaw, global, ms) = runtime_run(m, &settings, seed, seed_frames, &script, fps)
                .with_context(|| format!("the runtime controller from {label}"))?;
            let fs = skate.skate(&global, speed.len(), m.joints());
            record("runtime", seed, &speed, &yaw, fs, &ms, None)?;
        }
    }
    println!();
    println!(
        "| controller | seed | keys passed | foot skate (cm/frame) | ms per frame, median | mean | max | first frame (ms) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for r in &runs {
        println!(
            "| {} | {} | {}/{} | {:.3} | {:.1} | {:.1} | {:.1} | {:.1} |",
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
    if let Some((what, s)) = &real {
        println!("real foot skate: {s:.3} cm/frame ({what})");
    }
    println!("one core (RAYON_NUM_THREADS=1); start {label}");
    if let Some(p) = &a.json {
        let report = Report {
            model: a.model.display().to_string(),
            onnx: a.onnx.as_ref().map(|p| p.display().to_string()),
            start: label.clone(),
            script: a.script.as_ref().map_or("built-in benchmark".into(), |p| p.display().to_string()),
            options: format!("{opts:?}"),
            real_foot_skate: real_skate,
            real: real.as_ref().map(|(w, _)| w.clone()),
            runs,
        };
        let tmp = p.with_extension("json.tmp");
        std::fs::write(&tmp, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, p).with_context(|| format!("writing {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    Ok(())
}
