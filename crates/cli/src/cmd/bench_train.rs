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
    /// The Recurrent Motion Refiner at the paper's sizes (BGRU 2 x 256, batch 32 pairs of 60
    /// frames, bandai2's 145-value pose vector) on random normalised pairs.
    Rmr,
    /// ARNN keyframe completion at the paper's sizes (GRU 2 x 100, batch 16) on simulated lamp
    /// sequences.
    Arnn,
    /// The RNN-GMM generator (paper sizes, batch 20).
    RnnGmm,
    /// The RNN-GMM refiner stage: one refiner update and one discriminator update per step
    /// (paper sizes, batch 32, against an untrained paper-size generator's samples).
    RnnGmmRefiner,
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
    /// Windows per step instead of the model's paper batch (RTN and ARNN; `1..=4096`): to see how
    /// the step's cost per window depends on the rows each worker's matmuls get.
    #[arg(long, allow_hyphen_values = true, value_parser = |v: &str| whole_in(v, 1, 4096))]
    pub batch: Option<usize>,
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

/// What one thread count's timed training steps run: a closure doing one step.
type Step<'a> = Box<dyn FnMut() -> anyhow::Result<()> + 'a>;

/// The model under test: its description, the windows per step, the matmul FLOPs per window
/// and the main matmul shape `(m, k, n)` of one step.
struct Bench<'a> {
    what: String,
    batch: usize,
    flops: f64,
    gate: (usize, usize, usize),
    steps: Vec<Step<'a>>,
}

/// The paper-size RNN-GMM configuration and its training windows from two minutes of the
/// embedded synthetic locomotion.
fn rnn_gmm_data() -> anyhow::Result<(zoo_rnngmm::prelude::Config, zoo_rnngmm::TrainingData)> {
    let cfg = zoo_data::synth::SynthConfig { minutes: 2.0, seed: 1, terrain: false, ..Default::default() };
    let clips = zoo_data::synth::generate(&cfg);
    let refs: Vec<&zoo_motion::Clip> = clips.iter().map(|c| &c.clip).collect();
    let config = zoo_rnngmm::prelude::Config::paper();
    let data = zoo_rnngmm::TrainingData::from_clips(&config, cfg.fps, &refs[1..], &refs[..1])?;
    Ok((config.with_dim(data.spec.dim()), data))
}

/// Refuses synthetic data with fewer training windows than a batch of `b`.
fn enough_windows(data: &zoo_rnngmm::TrainingData, b: usize) -> anyhow::Result<()> {
    if data.train.len() < b {
        bail!("the synthetic data gave {} windows, fewer than a batch of {b}", data.train.len());
    }
    Ok(())
}

/// The RNN-GMM generator at the paper's sizes (3 x 512 dense, 2 x 512 LSTM, M = 5, windows of
/// 50 frames, batch 20) on the embedded synthetic locomotion.
fn rnn_gmm_bench(threads: &[usize]) -> anyhow::Result<Bench<'static>> {
    use zoo_rnngmm::prelude::*;
    let (config, data) = rnn_gmm_data()?;
    let b = config.train.batch_size;
    enough_windows(&data, b)?;
    let windows: Vec<Vec<f32>> = (0..b).map(|i| data.train.get(i).to_vec()).collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu)?;
        tr.set_threads(t)?;
        params = tr.model().parameter_count();
        let windows = windows.clone();
        let refs: Vec<&[f32]> = windows.iter().map(|w| w.as_slice()).collect();
        tr.train_step(&refs)?; // warm-up
        steps.push(Box::new(move || {
            let refs: Vec<&[f32]> = windows.iter().map(|w| w.as_slice()).collect();
            tr.train_step(&refs)?;
            Ok(())
        }));
    }
    let w = config.train.window;
    Ok(Bench {
        what: format!("RNN-GMM generator, paper sizes ({params} parameters, batch {b}, windows of {w} frames)"),
        batch: b,
        // Forward 2 flops per weight per frame, backward twice that.
        flops: 6.0 * params as f64 * (w - 1) as f64,
        gate: (b, 2 * config.lstm, 4 * config.lstm),
        steps,
    })
}

/// The RNN-GMM refiner stage at the paper's sizes (refiner FC 256 + LSTM 256, discriminator FC
/// 128 + bidirectional LSTM 128, batch 32, windows of 50 frames): a step is one refiner update
/// and one discriminator update (half fresh refined windows, half from the history buffer).
fn rnn_gmm_refiner_bench(threads: &[usize]) -> anyhow::Result<Bench<'static>> {
    use zoo_rnngmm::prelude::*;
    let (config, data) = rnn_gmm_data()?;
    let rc = config.refiner.clone();
    let b = rc.batch;
    enough_windows(&data, b)?;
    let dir = tempfile::tempdir().context("a temporary folder for the generator")?;
    GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu)?.save(dir.path())?;
    let w = config.train.window;
    let real: Vec<f32> = (0..b).flat_map(|i| data.train.get(i).to_vec()).collect();
    let real = Tensor::from_vec(real, (b, w, config.dim), &Device::Cpu)?;
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = AdversarialTrainer::new(dir.path(), &rc, &data.train, &data.valid, &Device::Cpu)?;
        tr.set_threads(t)?;
        let (r, d) = tr.varmaps();
        params = [r, d].iter().map(|v| v.all_vars().iter().map(|x| x.elem_count()).sum::<usize>()).sum();
        let real = real.clone();
        tr.refiner_update()?; // warm-up
        tr.discriminator_update(&real)?;
        steps.push(Box::new(move || {
            tr.refiner_update()?;
            tr.discriminator_update(&real)?;
            Ok(())
        }));
    }
    // Per window and frame: the refiner update runs refiner + discriminator forward and
    // backward; the discriminator update runs the refiner forward once (fresh half) and the
    // discriminator forward and backward on real and refined windows. Counted as 6 flops per
    // parameter per frame for each of the two updates (an estimate; the FK of the effector
    // features is left out).
    Ok(Bench {
        what: format!(
            "RNN-GMM refiner stage, paper sizes ({params} refiner + discriminator parameters, batch {b}, windows of \
             {w} frames; a step = one refiner update + one discriminator update)"
        ),
        batch: b,
        flops: 2.0 * 6.0 * params as f64 * w as f64,
        gate: (b, rc.refiner_fc + rc.refiner_lstm, 4 * rc.refiner_lstm),
        steps,
    })
}

/// The paper-size RMR (BGRU 2 x 256, batch 32 pairs of 60 frames, 145 values per frame) on
/// seeded random normalised pairs (the step's cost does not depend on the values).
fn rmr_bench(threads: &[usize]) -> anyhow::Result<Bench<'static>> {
    use zoo_rmr::{Config, RmrTrainer, features::FeatureStats};
    let config = Config::paper();
    let d = config.dim();
    let (b, frames) = (config.train.batch_size, config.pairs.window);
    let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let dev = Device::Cpu;
    let x = Tensor::randn(0f32, 1.0, (b, frames, d), &dev)?;
    let y = Tensor::randn(0f32, 1.0, (b, frames, d), &dev)?;
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = RmrTrainer::new(&config, stats.clone(), &dev)?;
        tr.set_threads(t)?;
        params = zoo_rmr::model::parameter_count(tr.varmap());
        tr.train_step(&x, &y)?; // warm-up
        let (x, y) = (x.clone(), y.clone());
        steps.push(Box::new(move || {
            tr.train_step(&x, &y)?;
            Ok(())
        }));
    }
    Ok(Bench {
        what: format!("RMR paper sizes ({params} parameters, BGRU 2 x {}, batch {b}, {frames} frames)", config.hidden),
        batch: b,
        // Every weight is used once per frame: forward 2 flops per weight, backward twice that.
        flops: 6.0 * params as f64 * frames as f64,
        gate: (b, config.hidden, 3 * config.hidden),
        steps,
    })
}

/// The paper-size ARNN (GRU 2 x 100, batch 16) on simulated lamp sequences (a small annealing
/// budget: the step's cost does not depend on how good the hops are).
fn arnn_bench(threads: &[usize], batch: Option<usize>) -> anyhow::Result<Bench<'static>> {
    use zoo_arnn::luxo::{GenerateOptions, generate_sequence, preprocess::preprocess};
    use zoo_arnn::{ArnnConfig, ArnnTrainer};
    let mut config = ArnnConfig::paper();
    config.batch_size = batch.unwrap_or(config.batch_size);
    let b = config.batch_size;
    let mut o = GenerateOptions::new(b, 17);
    o.anneal.k_max = 2;
    let seqs = (0..b).map(|i| Ok(preprocess(&generate_sequence(&o, i)?)?)).collect::<anyhow::Result<Vec<_>>>()?;
    let frames = seqs[0].frames.len();
    let samples: Vec<usize> = (0..b).collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = ArnnTrainer::new(&config, seqs.clone(), seqs[..2].to_vec(), &Device::Cpu)?;
        tr.set_threads(t)?;
        params = tr.parameter_count();
        tr.train_on(&samples)?; // warm-up
        let samples = samples.clone();
        steps.push(Box::new(move || {
            tr.train_on(&samples)?;
            Ok(())
        }));
    }
    Ok(Bench {
        what: format!("ARNN paper sizes ({params} parameters, GRU 2 x {}, batch {b}, {frames} frames)", config.hidden),
        batch: b,
        flops: 6.0 * params as f64 * (frames - 1) as f64,
        gate: (b, config.hidden, 3 * config.hidden),
        steps,
    })
}

/// The RTN at the paper's sizes on deterministic synthetic windows.
fn rtn_bench<'a>(threads: &[usize], ws: &'a [Vec<f32>], batch: Option<usize>) -> anyhow::Result<Bench<'a>> {
    let parents: Vec<Option<usize>> = (0..22).map(|j| if j == 0 { None } else { Some((j - 1) / 2) }).collect();
    let mut config = Config::paper().with_parents(&parents);
    if let Some(b) = batch {
        config.train.batch_size = b;
    }
    let b = config.train.batch_size;
    let mw: Vec<MotionWindow> = ws.iter().map(|w| MotionWindow::new(w)).collect();
    let stats = fit_stats(&config, &mw)?;
    let mut steps: Vec<Step> = Vec::new();
    for &t in threads {
        let mut tr = RtnTrainer::new(&config, stats.clone(), &Device::Cpu)?;
        tr.set_threads(t)?;
        tr.train_step(&mw[..b])?; // warm-up: first-touch allocations
        let mw = mw.clone();
        steps.push(Box::new(move || {
            tr.train_step(&mw[..b])?;
            Ok(())
        }));
    }
    let e = *config.frame_encoder.last().unwrap_or(&0);
    let gate_k = e + config.lstm + config.offset_encoder.last().copied().unwrap_or(0);
    Ok(Bench {
        what: format!(
            "RTN paper sizes (K = 22, batch {b}, {} + {} frames)",
            config.past_frames, config.transition_frames
        ),
        batch: b,
        flops: rtn_flops_per_window(&config),
        gate: (b, gate_k, 4 * config.lstm),
        steps,
    })
}

/// Runs `zoo bench train`.
pub fn run(a: TrainBenchArgs) -> anyhow::Result<()> {
    if let Some(j) = &a.json {
        crate::cmd::check_output_file("--json", j)?;
    }
    let parents_frames = Config::paper().window_frames();
    let ws: Vec<Vec<f32>> = (0..a.batch.unwrap_or(0).max(64)).map(|i| window(parents_frames, 22, i)).collect();
    if a.batch.is_some() && !matches!(a.model, TrainBenchModel::Rtn | TrainBenchModel::Arnn) {
        bail!("--batch: only the RTN and ARNN benches take another batch size");
    }
    let mut bench = match a.model {
        TrainBenchModel::Rtn => rtn_bench(&a.threads, &ws, a.batch)?,
        TrainBenchModel::RnnGmm => rnn_gmm_bench(&a.threads)?,
        TrainBenchModel::RnnGmmRefiner => rnn_gmm_refiner_bench(&a.threads)?,
        TrainBenchModel::Rmr => rmr_bench(&a.threads)?,
        TrainBenchModel::Arnn => arnn_bench(&a.threads, a.batch)?,
    };
    let (b, flops) = (bench.batch, bench.flops);
    println!("{}: {:.2} GFLOP per window; {} repeats of {} steps", bench.what, flops / 1e9, a.repeats, a.steps);
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
        for (k, step) in bench.steps.iter_mut().enumerate() {
            let t0 = Instant::now();
            for _ in 0..a.steps {
                step()?;
            }
            rates[k].push((a.steps * b) as f64 / t0.elapsed().as_secs_f64());
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    // The matmul reference on one thread, at the main (LSTM gate) shape of one step.
    let (gm, gk, gn) = bench.gate;
    let mm = matmul_gflops(gm, gk, gn)?;
    let mut rows = Vec::new();
    let base = median(&rates[0]);
    for (k, &t) in a.threads.iter().enumerate() {
        let m = median(&rates[k]);
        let gflops = m * flops / 1e9;
        let frac = gflops / (t as f64 * mm);
        println!(
            "zoo   {t} thread(s): {m:7.1} windows/s (median; {:.2}x the first row), {gflops:6.1} GFLOP/s, \
             {:.0}% of {t} x {mm:.1} GFLOP/s (one-thread candle matmul {gm}x{gk}x{gn})",
            m / base,
            100.0 * frac,
        );
        rows.push(json!({"framework": "zoo", "model": format!("{:?}", a.model), "threads": t, "batch": b,
            "windows_per_s_median": m, "windows_per_s": rates[k], "gflops": gflops,
            "matmul_fraction": frac}));
    }
    if a.pytorch && a.model != TrainBenchModel::Rtn {
        bail!("--pytorch: the PyTorch reference script covers the RTN only");
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
