//! `zoo bench runtime`, `zoo bench keyframes` and `zoo bench train`: the speed benchmarks of
//! [`zoo_bench::runtime`], [`zoo_bench::keyframes`] and [`zoo_bench::train`].

use anyhow::Context as _;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use zoo_bench::runtime::RuntimeOptions;
use zoo_bench::train::{SpeedModel, TrainSpeedOptions};

/// Arguments of `zoo bench runtime`.
#[derive(Args)]
pub struct RuntimeArgs {
    /// A file written by `zoo export --onnx` (an RTN for `zoo bench runtime`, an ARNN or an
    /// in-betweening network for `zoo bench keyframes`).
    #[arg(long)]
    pub model: PathBuf,
    /// Batch sizes to measure (characters per step).
    #[arg(long, default_value = "1,64", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::runtime_batch)]
    pub batch: Vec<usize>,
    /// Rounds per batch size (each backend runs once per round).
    #[arg(long, default_value_t = 11, allow_hyphen_values = true, value_parser = crate::args::rounds)]
    pub rounds: usize,
    /// Character-steps per backend per round (steps = this / batch, at least 5).
    #[arg(long, default_value_t = 1280, allow_hyphen_values = true, value_parser = crate::args::character_steps)]
    pub work: usize,
    /// onnxruntime library (default: `ORT_DYLIB_PATH`, else `.onnxruntime/libonnxruntime.so*`
    /// in the current folder or one of its parents).
    #[arg(long)]
    pub onnxruntime: Option<PathBuf>,
    /// Write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// `zoo bench runtime`: weight widths to measure tract and onnxruntime at, comma-separated
    /// (f32, f16, int8; default: the file's own). The file must be f32 to measure other widths:
    /// it is rewritten at each, as `zoo export --weights` writes it.
    #[arg(long, value_delimiter = ',', value_parser = ["f32", "f16", "int8"])]
    pub weights: Vec<String>,
    /// `zoo bench runtime`: instead of throughput, time N single per-frame calls of the model's
    /// task at each batch size (transition starts and steps, keyframe completions, stitch
    /// stream frames, synthesis and control steps) and report their median, 99th percentile and
    /// maximum: what a game's frame budget sees.
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = |v: &str| whole_in(v, 10, 1_000_000))]
    pub per_call: Option<usize>,
}

/// Arguments of `zoo bench keyframes`.
#[derive(Args)]
pub struct KeyframesArgs {
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// In-betweening design: also time this RTN (a file written by `zoo export --onnx`) on the
    /// same transitions, its start and one step per frame, beside the whole shot's one call.
    #[arg(long)]
    pub against: Option<PathBuf>,
    /// In-betweening design: frames between the last context frame and the target.
    #[arg(long, default_value_t = 30, allow_hyphen_values = true, value_parser = |v: &str| whole_in(v, 1, 1_000))]
    pub gap: usize,
}

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

impl RuntimeArgs {
    /// The benchmark's settings.
    fn options(&self) -> RuntimeOptions {
        RuntimeOptions {
            widths: self.weights.iter().filter_map(|w| zoo_export::WeightWidth::parse(w).ok()).collect(),
            model: self.model.clone(),
            batch: self.batch.clone(),
            rounds: self.rounds,
            work: self.work,
            onnxruntime: self.onnxruntime.clone(),
        }
    }
}

/// Runs `zoo bench runtime`.
pub fn runtime(a: RuntimeArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    if let Some(calls) = a.per_call {
        if !a.weights.is_empty() {
            anyhow::bail!("--per-call times the file as it is; drop --weights (export at another width to time it)");
        }
        let bytes = std::fs::read(&a.model).with_context(|| format!("cannot read {}", a.model.display()))?;
        zoo_bench::runtime::refuse_portable(&a.model, &bytes)?;
        let figures = zoo_bench::frame_budget::run(&bytes, &a.batch, calls)?;
        println!(
            "per-call times of {} on one thread ({}):",
            a.model.display(),
            zoo_bench::runtime::cpu_features().unwrap_or_else(|| "CPU features unknown".into())
        );
        println!("{}", zoo_bench::frame_budget::table(&figures));
        if let Some(path) = &a.json {
            crate::cmd::write_json(path, &figures)?;
        }
        return Ok(());
    }
    let report = zoo_bench::runtime::run(&a.options(), &zoo_nn::progress::Bar::new())?;
    println!("{}", report.header);
    println!("{}", zoo_bench::runtime::table(&report.figures, a.rounds, a.work));
    if let Some(path) = &a.json {
        crate::cmd::write_json(path, &report.figures)?;
    }
    Ok(())
}

/// Runs `zoo bench keyframes` (the arguments of `zoo bench runtime`, `--model` naming an
/// exported ARNN or in-betweening network).
pub fn keyframes(k: KeyframesArgs) -> anyhow::Result<()> {
    let a = k.runtime;
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    if !a.weights.is_empty() {
        anyhow::bail!("--weights applies to `zoo bench runtime`; `zoo bench keyframes` measures the file as it is");
    }
    if a.per_call.is_some() {
        anyhow::bail!("--per-call applies to `zoo bench runtime` (it times a keyframe model's calls too)");
    }
    let km = zoo_bench::exported::load(&a.model, &[zoo_runtime::MotionTaskKind::Keyframes], "`zoo bench keyframes`")?
        .into_keyframes()?;
    if km.is_inbetween() {
        let figures = zoo_bench::whole_shot::run(&km, k.against.as_deref(), k.gap, &a.batch, a.rounds, a.work)?;
        println!(
            "{}: in-betweening design; {}",
            a.model.display(),
            zoo_bench::runtime::cpu_features().unwrap_or_else(|| "CPU features unknown".into())
        );
        println!("{}", zoo_bench::whole_shot::table(&figures, a.rounds));
        if let Some(path) = &a.json {
            crate::cmd::write_json(path, &figures)?;
        }
        return Ok(());
    }
    if k.against.is_some() {
        anyhow::bail!(
            "--against times whole transitions of the in-betweening design; {} is an ARNN step graph",
            a.model.display()
        );
    }
    let (header, figures) = zoo_bench::keyframes::run(&a.options(), &km)?;
    println!("{header}");
    println!("{}", zoo_bench::keyframes::table(&figures, a.rounds, a.work));
    if let Some(path) = &a.json {
        crate::cmd::write_json(path, &figures)?;
    }
    Ok(())
}

/// Runs `zoo bench train`.
pub fn train(a: TrainBenchArgs) -> anyhow::Result<()> {
    if let Some(j) = &a.json {
        crate::cmd::check_output_file("--json", j)?;
    }
    let model = match a.model {
        TrainBenchModel::Rtn => SpeedModel::Rtn,
        TrainBenchModel::Rmr => SpeedModel::Rmr,
        TrainBenchModel::Arnn => SpeedModel::Arnn,
        TrainBenchModel::RnnGmm => SpeedModel::RnnGmm,
        TrainBenchModel::RnnGmmRefiner => SpeedModel::RnnGmmRefiner,
    };
    let o = TrainSpeedOptions {
        model,
        threads: a.threads,
        steps: a.steps,
        repeats: a.repeats,
        pytorch: a.pytorch,
        batch: a.batch,
    };
    let report = zoo_bench::train::run(&o, &zoo_nn::progress::Bar::new())?;
    for line in report.header.iter().chain(&report.lines) {
        println!("{line}");
    }
    if let Some(j) = &a.json {
        crate::cmd::write_json(j, &report.json)?;
    }
    Ok(())
}
