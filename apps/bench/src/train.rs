//! The training-speed benchmark (`zoo bench train`): a model's training step at its paper
//! sizes per thread count ([`zoo_nn::speed`], each model's step from its crate), optionally
//! beside the PyTorch reference of the same shapes (`scripts/bench_train_torch.sh`) run right
//! after.

use crate::{Result, msg};
use serde_json::json;
use zoo_data::{Context, Progress, bail};

/// Models whose training step is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpeedModel {
    /// The Recurrent Transition Network at the paper's sizes (K = 22, batch 32, 10 + 30 frames).
    Rtn,
    /// The Recurrent Motion Refiner at the paper's sizes on random normalised pairs.
    Rmr,
    /// ARNN keyframe completion at the paper's sizes on simulated lamp sequences.
    Arnn,
    /// The RNN-GMM generator (paper sizes, batch 20).
    RnnGmm,
    /// The RNN-GMM refiner stage: one refiner update and one discriminator update per step.
    RnnGmmRefiner,
}

/// The benchmark's settings.
#[derive(Clone, Debug)]
pub struct TrainSpeedOptions {
    /// The model whose training step is measured.
    pub model: SpeedModel,
    /// Thread counts to measure.
    pub threads: Vec<usize>,
    /// Training steps per timed repeat.
    pub steps: usize,
    /// Timed repeats per thread count; the median is reported.
    pub repeats: usize,
    /// Also run the PyTorch reference of the same shapes (RTN only).
    pub pytorch: bool,
    /// Windows per step instead of the model's paper batch (RTN and ARNN).
    pub batch: Option<usize>,
}

/// What the benchmark measured: the lines it says and the JSON of the command.
#[derive(Clone, Debug)]
pub struct TrainSpeedReport {
    /// The model and the environment, one line each.
    pub header: Vec<String>,
    /// One line per thread count (and per PyTorch row).
    pub lines: Vec<String>,
    /// `{"matmul_gflops_one_thread": ..., "results": [...]}`.
    pub json: serde_json::Value,
}

/// The model's training step for each thread count (the RTN's on the windows `ws`).
fn bench<'a>(o: &TrainSpeedOptions, ws: &'a [Vec<f32>]) -> Result<zoo_nn::speed::SpeedBench<'a>> {
    if o.batch.is_some() && !matches!(o.model, SpeedModel::Rtn | SpeedModel::Arnn) {
        bail!("--batch: only the RTN and ARNN benches take another batch size");
    }
    Ok(match o.model {
        SpeedModel::Rtn => zoo_rtn::speed::train_bench(&o.threads, ws, o.batch)?,
        SpeedModel::RnnGmm => zoo_rnngmm::speed::generator_bench(&o.threads)?,
        SpeedModel::RnnGmmRefiner => zoo_rnngmm::speed::refiner_bench(&o.threads)?,
        SpeedModel::Rmr => zoo_rmr::speed::train_bench(&o.threads)?,
        SpeedModel::Arnn => zoo_arnn::speed::train_bench(&o.threads, o.batch)?,
    })
}

/// Runs the benchmark.
pub fn run(o: &TrainSpeedOptions, p: &dyn Progress) -> Result<TrainSpeedReport> {
    let frames = zoo_rtn::Config::paper().window_frames();
    let ws: Vec<Vec<f32>> = (0..o.batch.unwrap_or(0).max(64)).map(|i| zoo_rtn::speed::window(frames, 22, i)).collect();
    let mut bench = bench(o, &ws)?;
    let (b, flops) = (bench.batch, bench.flops);
    let env = |k: &str| std::env::var(k).unwrap_or_else(|_| "unset".into());
    let header = vec![
        format!("{}: {:.2} GFLOP per window; {} repeats of {} steps", bench.what, flops / 1e9, o.repeats, o.steps),
        format!(
            "environment: CANDLE_NUM_THREADS={} MIMALLOC_PURGE_DELAY={} RAYON_NUM_THREADS={}",
            env("CANDLE_NUM_THREADS"),
            env("MIMALLOC_PURGE_DELAY"),
            env("RAYON_NUM_THREADS")
        ),
    ];
    p.start((o.repeats * o.threads.len()) as u64, "bench train: timed runs");
    let (speed, mm) = bench.measure(&o.threads, o.steps, o.repeats, &mut || p.advance(1))?;
    p.finish();
    let (gm, gk, gn) = bench.gate;
    let base = speed[0].windows_per_s_median;
    let mut lines = Vec::new();
    let mut rows = Vec::new();
    for r in &speed {
        let (t, m, gflops) = (r.threads, r.windows_per_s_median, r.gflops);
        lines.push(format!(
            "zoo   {t} thread(s): {m:7.1} windows/s (median; {:.2}x the first row), {gflops:6.1} GFLOP/s, {:.0}% of \
             {t} x {mm:.1} GFLOP/s (one-thread candle matmul {gm}x{gk}x{gn})",
            m / base,
            100.0 * r.matmul_fraction,
        ));
        rows.push(json!({"framework": "zoo", "model": format!("{:?}", o.model), "threads": t, "batch": b,
            "windows_per_s_median": m, "windows_per_s": r.windows_per_s, "gflops": gflops,
            "matmul_fraction": r.matmul_fraction}));
    }
    if o.pytorch {
        pytorch(o, &mut lines, &mut rows)?;
    }
    Ok(TrainSpeedReport { header, lines, json: json!({"matmul_gflops_one_thread": mm, "results": rows}) })
}

/// The PyTorch reference of the same shapes, run by `scripts/bench_train_torch.sh`.
fn pytorch(o: &TrainSpeedOptions, lines: &mut Vec<String>, rows: &mut Vec<serde_json::Value>) -> Result<()> {
    if o.model != SpeedModel::Rtn {
        bail!("--pytorch: the PyTorch reference script covers the RTN only");
    }
    let script = std::path::Path::new("scripts/bench_train_torch.sh");
    if !script.is_file() {
        bail!("--pytorch: {} not found; run zoo from the repository root", script.display());
    }
    let threads = o.threads.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(",");
    let out = std::process::Command::new("bash")
        .arg(script)
        .args(["--threads", &threads, "--steps", &o.steps.to_string(), "--repeats", &o.repeats.to_string()])
        .stderr(std::process::Stdio::inherit())
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    if !out.status.success() {
        bail!("--pytorch: {} failed ({})", script.display(), out.status);
    }
    for line in String::from_utf8_lossy(&out.stdout).lines().filter(|l| l.starts_with('{')) {
        let v: serde_json::Value =
            serde_json::from_str(line).map_err(|e| msg!("reading the PyTorch script's output: {e}"))?;
        let m = v["windows_per_s_median"].as_f64().unwrap_or(f64::NAN);
        lines.push(format!(
            "torch {} thread(s): {m:7.1} windows/s (median; {})",
            v["threads"],
            v["framework"].as_str().unwrap_or("pytorch")
        ));
        rows.push(v);
    }
    Ok(())
}
