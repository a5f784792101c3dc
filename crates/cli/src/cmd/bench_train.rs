//! `zoo bench train`: training throughput of a model at its paper sizes, per thread count
//! (data-parallel training, [`zoo_nn::parallel`]), with the achieved GFLOP/s, the fraction of
//! a candle matmul at the model's main shape measured in the same run, and optionally the
//! PyTorch reference of the same shapes (`scripts/bench_train_torch.sh`) run right after.

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;
use zoo_nn::parallel::DataParallel;
use zoo_rtn::prelude::*;

/// Models `zoo bench train` can measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TrainBenchModel {
    /// The Recurrent Transition Network at the paper's sizes (K = 22, batch 32, 10 + 30 frames).
    Rtn,
    /// The Recurrent Motion Refiner (not data-parallel yet: refused with a message).
    Rmr,
    /// ARNN keyframe completion (not data-parallel yet: refused with a message).
    Arnn,
    /// RNN-GMM and its refiner (not data-parallel yet: refused with a message).
    RnnGmm,
}

/// Arguments of `zoo bench train`.
#[derive(Args)]
pub struct TrainBenchArgs {
    /// The model whose training step is measured.
    #[arg(long, value_enum, default_value = "rtn")]
    pub model: TrainBenchModel,
    /// Thread counts to measure, comma-separated (each `1..=256`).
    #[arg(long, value_delimiter = ',', default_value = "1,2", allow_hyphen_values = true, value_parser = thread_count)]
    pub threads: Vec<usize>,
    /// Training steps per timed repeat.
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = |v: &str| whole_in(v, 1, 100_000))]
    pub steps: usize,
    /// Timed repeats per thread count; the median is reported. The thread counts are measured
    /// in turn within each repeat, so that a change of machine load hits them alike.
    #[arg(long, default_value_t = 5, allow_hyphen_values = true, value_parser = |v: &str| whole_in(v, 1, 1_000))]
    pub repeats: usize,
    /// Also run the PyTorch reference of the same shapes (`scripts/bench_train_torch.sh`,
    /// which installs the pinned PyTorch into `.venv-bench/` the first time) after zoo's runs.
    #[arg(long)]
    pub pytorch: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// A whole number in `lo..=hi`.
fn whole_in(s: &str, lo: usize, hi: usize) -> Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| format!("`{s}` is not a whole number (valid range {lo}..={hi})"))?;
    if (lo..=hi).contains(&n) { Ok(n) } else { Err(format!("{n} is outside the valid range {lo}..={hi}")) }
}

/// A training thread count in `1..=MAX_THREADS`.
fn thread_count(s: &str) -> Result<usize, String> {
    whole_in(s, 1, zoo_nn::parallel::MAX_THREADS)
}

/// Matmul FLOPs of one training window of the paper-size RTN: forward `2 m k n` per layer per
/// frame, backward twice that (the per-sequence target encoder and initial state are left out:
/// they run once per window, not once per frame).
fn rtn_flops_per_window(config: &Config) -> f64 {
    let d = config.dim();
    let e = *config.frame_encoder.last().unwrap_or(&d);
    let hu = config.lstm;
    let o = *config.offset_encoder.last().unwrap_or(&0);
    let mut layers = vec![];
    let mut prev = d;
    for &w in &config.frame_encoder {
        layers.push((prev, w));
        prev = w;
    }
    layers.push((e + hu + o, 4 * hu));
    prev = hu;
    for &w in config.decoder.iter().chain(std::iter::once(&d)) {
        layers.push((prev, w));
        prev = w;
    }
    prev = d;
    for &w in &config.offset_encoder {
        layers.push((prev, w));
        prev = w;
    }
    let per_frame: usize = layers.iter().map(|(i, o)| 2 * i * o).sum();
    3.0 * (per_frame * (config.past_frames + config.transition_frames)) as f64
}

/// Deterministic synthetic windows of global positions (no data needed).
fn window(frames: usize, joints: usize, seed: usize) -> Vec<f32> {
    let s = seed as f32;
    let mut p = Vec::with_capacity(frames * joints * 3);
    for f in 0..frames {
        let t = f as f32 + 7.0 * s;
        let root = [2.5 * t * (0.3 * s).cos(), 90.0 + 3.0 * (0.3 * t).sin(), 2.5 * t * (0.3 * s).sin()];
        for j in 0..joints {
            let ph = 0.25 * t + j as f32 * 0.4 + s;
            p.extend_from_slice(&[
                root[0] + 10.0 * ph.sin(),
                root[1] + 5.0 * j as f32 + 4.0 * ph.cos(),
                root[2] + 8.0 * (2.0 * ph).sin(),
            ]);
        }
    }
    p
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) }
}

/// GFLOP/s of one candle matmul `(m, k) x (k, n)` on one thread.
fn matmul_gflops(m: usize, k: usize, n: usize) -> anyhow::Result<f64> {
    let pool = DataParallel::new(1)?;
    pool.install(|| -> anyhow::Result<f64> {
        let dev = Device::Cpu;
        let a = Tensor::randn(0f32, 1.0, (m, k), &dev)?;
        let w = Tensor::randn(0f32, 1.0, (k, n), &dev)?;
        let _ = a.matmul(&w)?;
        let reps = 100;
        let t = Instant::now();
        for _ in 0..reps {
            let _ = a.matmul(&w)?.to_dtype(DType::F32)?;
        }
        Ok(reps as f64 * 2.0 * (m * k * n) as f64 / t.elapsed().as_secs_f64() / 1e9)
    })
}

/// Runs `zoo bench train`.
pub fn run(a: TrainBenchArgs) -> anyhow::Result<()> {
    if a.model != TrainBenchModel::Rtn {
        bail!(
            "--model {:?}: only rtn is data-parallel so far; rmr, arnn and rnn-gmm train through the \
             shared loop on one thread (issue 18 is open for them)",
            a.model
        );
    }
    if let Some(j) = &a.json {
        crate::cmd::check_output_file("--json", j)?;
    }
    let parents: Vec<Option<usize>> = (0..22).map(|j| if j == 0 { None } else { Some((j - 1) / 2) }).collect();
    let config = Config::paper().with_parents(&parents);
    let dev = Device::Cpu;
    let b = config.train.batch_size;
    let ws: Vec<Vec<f32>> = (0..2 * b).map(|i| window(config.window_frames(), 22, i)).collect();
    let mw: Vec<MotionWindow> = ws.iter().map(|w| MotionWindow::new(w)).collect();
    let stats = fit_stats(&config, &mw)?;
    let flops = rtn_flops_per_window(&config);
    let e = *config.frame_encoder.last().unwrap_or(&0);
    let gate_k = e + config.lstm + config.offset_encoder.last().copied().unwrap_or(0);
    let mut trainers = a
        .threads
        .iter()
        .map(|&t| -> anyhow::Result<RtnTrainer> {
            let mut tr = RtnTrainer::new(&config, stats.clone(), &dev)?;
            tr.set_threads(t)?;
            tr.train_step(&mw[..b])?; // warm-up: first-touch allocations
            Ok(tr)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    println!(
        "RTN paper sizes (K = 22, batch {b}, {} + {} frames, {:.2} GFLOP per window); {} repeats of {} steps",
        config.past_frames,
        config.transition_frames,
        flops / 1e9,
        a.repeats,
        a.steps
    );
    let env = |k: &str| std::env::var(k).unwrap_or_else(|_| "unset".into());
    println!(
        "environment: CANDLE_NUM_THREADS={} MIMALLOC_PURGE_DELAY={} RAYON_NUM_THREADS={}",
        env("CANDLE_NUM_THREADS"),
        env("MIMALLOC_PURGE_DELAY"),
        env("RAYON_NUM_THREADS")
    );
    let bar = indicatif::ProgressBar::new((a.repeats * a.threads.len()) as u64);
    bar.set_style(indicatif::ProgressStyle::with_template("bench train: [{bar:30}] {pos}/{len} timed runs {elapsed}")?);
    let mut rates = vec![Vec::new(); a.threads.len()];
    for _ in 0..a.repeats {
        for (k, tr) in trainers.iter_mut().enumerate() {
            let t0 = Instant::now();
            for s in 0..a.steps {
                let off = (s * b) % b;
                tr.train_step(&mw[off..off + b])?;
            }
            rates[k].push((a.steps * b) as f64 / t0.elapsed().as_secs_f64());
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    // The matmul reference on one thread, at the fused LSTM gate shape of one worker's shard.
    let mm = matmul_gflops(b, gate_k, 4 * config.lstm)?;
    let mut rows = Vec::new();
    let base = median(&rates[0]);
    for (k, &t) in a.threads.iter().enumerate() {
        let m = median(&rates[k]);
        let gflops = m * flops / 1e9;
        let frac = gflops / (t as f64 * mm);
        println!(
            "zoo   {t} thread(s): {m:7.1} windows/s (median; {:.2}x the first row), {gflops:6.1} GFLOP/s, \
             {:.0}% of {t} x {mm:.1} GFLOP/s (one-thread candle matmul {b}x{gate_k}x{})",
            m / base,
            100.0 * frac,
            4 * config.lstm
        );
        rows.push(json!({"framework": "zoo", "model": "rtn", "threads": t, "batch": b,
            "windows_per_s_median": m, "windows_per_s": rates[k], "gflops": gflops,
            "matmul_fraction": frac}));
    }
    if a.pytorch {
        let script = std::path::Path::new("scripts/bench_train_torch.sh");
        if !script.is_file() {
            bail!("--pytorch: {} not found; run zoo from the repository root", script.display());
        }
        let threads = a.threads.iter().map(|t| t.to_string()).collect::<Vec<_>>().join(",");
        let out = std::process::Command::new("bash")
            .arg(script)
            .args(["--threads", &threads, "--steps", &a.steps.to_string(), "--repeats", &a.repeats.to_string()])
            .stderr(std::process::Stdio::inherit())
            .output()
            .with_context(|| format!("running {}", script.display()))?;
        if !out.status.success() {
            bail!("--pytorch: {} failed ({})", script.display(), out.status);
        }
        for line in String::from_utf8_lossy(&out.stdout).lines().filter(|l| l.starts_with('{')) {
            let v: serde_json::Value = serde_json::from_str(line).context("reading the PyTorch script's output")?;
            let m = v["windows_per_s_median"].as_f64().unwrap_or(f64::NAN);
            println!(
                "torch {} thread(s): {m:7.1} windows/s (median; {})",
                v["threads"],
                v["framework"].as_str().unwrap_or("pytorch")
            );
            rows.push(v);
        }
    }
    if let Some(j) = &a.json {
        let text = serde_json::to_string_pretty(&json!({"matmul_gflops_one_thread": mm, "results": rows}))?;
        std::fs::write(j, text).with_context(|| format!("writing {}", j.display()))?;
    }
    Ok(())
}
