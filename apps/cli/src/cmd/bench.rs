//! `zoo bench`: the in-betweening benchmark ([`zoo_bench::inbetween`], LaFAN1 protocol,
//! `BENCHMARK.md`), and the other benchmarks as subcommands.

use anyhow::bail;
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;
use zoo_bench::inbetween::InbetweenOptions;
use zoo_data::Progress;

/// Arguments of `zoo bench`.
#[derive(Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct BenchArgs {
    /// Other benchmarks.
    #[command(subcommand)]
    pub command: Option<BenchCommand>,
    /// Dataset folder: files not matching `--valid-glob` are the training split (statistics,
    /// bone offsets, planted foot heights); matching files are the test split.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the validation/test split, e.g. `'*_youthful_*'`
    /// (LaFAN1: `'*subject5*'`).
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// A held-out dataset on the same skeleton: every clip of it is tested instead of the
    /// validation split of `--data`.
    #[arg(long)]
    pub test_data: Option<PathBuf>,
    /// Comma-separated methods: `zerovel`, `interp`, `KIND:RUN_DIR` (a `zoo train KIND` run
    /// folder whose config.json names model KIND, e.g. `rtn:runs/rtn`: exported in memory and
    /// run by the engine runtime, as the commands and engines run it), `onnx:FILE.onnx` (a `zoo
    /// export --onnx` file, likewise), `candle-KIND:RUN_DIR` (the training model in candle, for
    /// parity checks); `KIND+lock:RUN_DIR` and `onnx+lock:FILE.onnx` add the foot-lock
    /// post-process.
    #[arg(long, default_value = "zerovel,interp", value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Comma-separated transition lengths in frames.
    #[arg(long, default_value = "5,15,30,45", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub lengths: Vec<usize>,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Compare with reference values (LaFAN1 benchmark key names, e.g.
    /// `interp_pos_loss@30`) and fail when one differs by more than `--tolerance`.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Relative tolerance of `--reference`.
    #[arg(long, default_value_t = 1e-3, allow_hyphen_values = true, value_parser = crate::args::relative_tolerance)]
    pub tolerance: f64,
    /// Write BVH files of the first `--save-count` test windows into this folder: the ground
    /// truth and every method's transition, per length (`w0003_n30_interp.bvh`, ...), ready for
    /// `zoo render ... --compare ...`.
    #[arg(long)]
    pub save_bvh: Option<PathBuf>,
    /// How many test windows `--save-bvh` writes (evenly spread over the test set).
    #[arg(long, default_value_t = 4, allow_hyphen_values = true, value_parser = crate::args::save_count)]
    pub save_count: usize,
    /// Leave out the clips that cannot join the dataset (unreadable, another skeleton or
    /// frame rate) and list them, instead of refusing the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Leave out of `--data` every clip whose file name matches this glob, before the split
    /// (e.g. a content type, for the out-of-distribution protocol of docs/ood.md).
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Benchmark RTN run folders and exported files without their fallback towards
    /// interpolation (the thresholds `zoo train rtn` calibrates; docs/ood.md), and in-betweening
    /// runs and files without theirs towards the curves through the keys (`zoo train arnn
    /// --design inbetween`; docs/keys-only.md). With it on (the default) such methods are named
    /// with a `+fallback` suffix and how often the fallback acted is printed.
    #[arg(long)]
    pub no_fallback: bool,
    /// Test every K-th clip of the test split only (in name order: clips 0, K, 2K, ...), for a
    /// quicker, stated subsample; the statistics still come from the whole training split.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub test_every: u64,
    /// What a method is given: `context` (the LaFAN1 protocol: 10 context frames and a target),
    /// `keys` (key poses every K frames and nothing else; methods `linear`, `bezier`,
    /// `arnn:RUN_DIR`, `onnx:FILE.onnx`, `candle-arnn:RUN_DIR`) or `keys-partial` (the keys
    /// between the first and the last fix the root and the limbs' end joints only).
    #[arg(long, value_enum, default_value_t = Layout::Context)]
    pub layout: Layout,
    /// With `--layout keys` / `keys-partial`: the key spacings K in frames (the table's columns).
    #[arg(long, default_value = "5,10,15,20,30", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub every: Vec<usize>,
}

/// What the in-betweening benchmark gives its methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Layout {
    /// 10 context frames and a target (LaFAN1).
    Context,
    /// Whole key poses every K frames.
    Keys,
    /// Key poses every K frames, the ones between the first and the last partial.
    KeysPartial,
}

/// Benchmarks other than the in-betweening table.
#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Per-frame step latency (batch 1) and throughput (batch 64) of an exported model through
    /// candle, tract and onnxruntime, side by side.
    Runtime(crate::cmd::bench_speed::RuntimeArgs),
    /// Training throughput per thread count (data-parallel), GFLOP/s and the fraction of a
    /// candle matmul, optionally beside the PyTorch reference of the same shapes.
    Train(crate::cmd::bench_speed::TrainBenchArgs),
    /// The stitching benchmark (RMR): concatenation, inertialization, interpolation and trained
    /// RMRs on cases with a ground truth (the RMR paper's section-4 pairs) and on free
    /// multi-clip cases (protocol in docs/rmr.md).
    Stitch(crate::cmd::bench_stitch::StitchBenchArgs),
    /// The exported ARNN's step through tract and onnxruntime (batch 1 latency, batch 64
    /// throughput) and whole keyframe completions; for the in-betweening design, whole
    /// transitions in one call, beside an RTN's start and steps (`--against`).
    Keyframes(crate::cmd::bench_speed::KeyframesArgs),
    /// The synthesis benchmark (RNN-GMM): seeded sequences against held-out real
    /// motion, with and without the refiner (protocol in docs/rnn-gmm.md).
    Synthesis(crate::cmd::bench_synthesis::BenchSynthesisArgs),
    /// The denoising benchmark (RNN-GMM control): held-out clips with seeded noise,
    /// cleaned by the MAP denoiser and by Savitzky-Golay filters (protocol in docs/rnn-gmm-control.md).
    Denoise(crate::cmd::bench_denoise::BenchDenoiseArgs),
    /// The path-following benchmark (RNN-GMM control): five test paths from each start
    /// clip, root-to-path distance, foot skate and time (protocol in docs/rnn-gmm-control.md).
    Follow(crate::cmd::bench_follow::BenchFollowArgs),
    /// The online control benchmark (RNN-GMM control): a script of speed and heading
    /// changes followed by the candle and the runtime controllers (protocol in docs/rnn-gmm-control.md).
    Control(Box<crate::cmd::bench_control::BenchControlArgs>),
}

/// Runs a benchmark.
pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    match a.command {
        Some(BenchCommand::Train(t)) => crate::cmd::bench_speed::train(t),
        Some(BenchCommand::Stitch(s)) => crate::cmd::bench_stitch::run(s),
        Some(BenchCommand::Keyframes(k)) => crate::cmd::bench_speed::keyframes(k),
        Some(BenchCommand::Follow(f)) => crate::cmd::bench_follow::run(f),
        Some(BenchCommand::Control(c)) => crate::cmd::bench_control::run(*c),
        Some(BenchCommand::Denoise(d)) => crate::cmd::bench_denoise::run(d),
        Some(BenchCommand::Synthesis(s)) => crate::cmd::bench_synthesis::run(s),
        Some(BenchCommand::Runtime(r)) => crate::cmd::bench_speed::runtime(r),
        None => inbetween(a),
    }
}

/// Runs the in-betweening benchmark.
fn inbetween(a: BenchArgs) -> anyhow::Result<()> {
    zoo_rtn::method::set_fallback_enabled(!a.no_fallback);
    let Some(data) = a.data.clone() else {
        bail!("pass --data DATASET (and --valid-glob GLOB) for the in-betweening benchmark, or use `zoo bench runtime`")
    };
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    if let Some(dir) = &a.save_bvh {
        crate::cmd::check_output_dir("--save-bvh", dir)?;
    }
    if a.layout != Layout::Context {
        return keys(a, &data);
    }
    let start = Instant::now();
    let (methods, trained_on) = zoo_bench::inbetween::load_methods(&a.methods)?;
    let bar = zoo_nn::progress::Bar::new();
    let (train, test) = load(&a, &data, &bar)?;
    zoo_bench::inbetween::check_skeletons(&a.methods, &trained_on, &train)?;
    let o = InbetweenOptions { lengths: a.lengths.clone(), save_bvh: a.save_bvh.clone(), save_count: a.save_count };
    let result = zoo_bench::inbetween::run(&train, &test, &methods, &o, &bar)?;
    bar.finish();
    println!("{}", result.table(&a.lengths));
    summary(&a, &result, (train.len(), test.len()), start)?;
    if let Some(r) = &a.reference {
        let check = zoo_bench::inbetween::check_reference(&result, r, a.tolerance)?;
        for line in &check.lines {
            println!("{line}");
        }
        println!("{}", check.verdict(a.tolerance)?);
    }
    Ok(())
}

/// Runs the keys-only benchmark (`--layout keys` / `keys-partial`).
fn keys(a: BenchArgs, data: &std::path::Path) -> anyhow::Result<()> {
    use zoo_bench::keys::{KeyLayout, KeysBench};
    if a.reference.is_some() || a.save_bvh.is_some() {
        bail!("--reference and --save-bvh are for `--layout context`");
    }
    let layout = if a.layout == Layout::Keys { KeyLayout::Whole } else { KeyLayout::Partial };
    let methods = zoo_bench::keys::methods(&a.methods)?;
    let start = Instant::now();
    let bar = zoo_nn::progress::Bar::new();
    let (train, test) = load(&a, data, &bar)?;
    bar.stage("preparing windows and statistics");
    let bench = KeysBench::new(&train, &test)?;
    let result = bench.run(&methods, &a.every, layout, &bar)?;
    bar.finish();
    println!("{}", zoo_bench::keys::table(&result, &a.every, layout));
    summary(&a, &result, (train.len(), test.len()), start)
}

/// The training and test clips of `--data` (`--valid-glob`, `--test-data`, `--exclude-glob`),
/// every `--test-every`-th test clip kept.
fn load(
    a: &BenchArgs,
    data: &std::path::Path,
    bar: &zoo_nn::progress::Bar,
) -> anyhow::Result<(Vec<zoo_data::dataset::NamedClip>, Vec<zoo_data::dataset::NamedClip>)> {
    let split = crate::cmd::Split {
        valid_glob: a.valid_glob.as_deref(),
        test_data: a.test_data.as_deref(),
        exclude_glob: a.exclude_glob.as_deref(),
    };
    let (train, test) = crate::cmd::load_split(data, &split, a.skip_invalid, bar)?;
    Ok((train, test.into_iter().step_by(a.test_every as usize).collect()))
}

/// Writes `--json` and prints the closing line.
fn summary(
    a: &BenchArgs,
    result: &zoo_data::benchmark::BenchResult,
    (train, test): (usize, usize),
    start: Instant,
) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::write_json(path, result)?;
    }
    println!(
        "{train} training clips, {test} test clips, {} test windows, {:.2} s",
        result.windows,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
