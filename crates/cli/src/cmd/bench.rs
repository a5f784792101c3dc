//! `zoo bench`: the in-betweening benchmark (LaFAN1 protocol, `BENCHMARK.md`).

use crate::registry::MethodSpec;
use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use zoo_data::benchmark::{BenchResult, Benchmark, TransitionMethod};
use zoo_data::dataset;

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
    /// folder whose config.json names model KIND, e.g. `rtn:runs/rtn`), `onnx:FILE.onnx` (a
    /// `zoo export --onnx` file run by the engine runtime on tract); `KIND+lock:RUN_DIR` and
    /// `onnx+lock:FILE.onnx` add the foot-lock post-process.
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
    /// interpolation (the thresholds `zoo train rtn` calibrates; docs/ood.md). With it on (the
    /// default) such methods are named with a `+fallback` suffix and how often the fallback
    /// triggered is printed per length.
    #[arg(long)]
    pub no_fallback: bool,
    /// Test every K-th clip of the test split only (in name order: clips 0, K, 2K, ...), for a
    /// quicker, stated subsample; the statistics still come from the whole training split.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub test_every: u64,
}

/// Benchmarks other than the in-betweening table.
#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Per-frame step latency (batch 1) and throughput (batch 64) of an exported model through
    /// candle, tract and onnxruntime, side by side.
    Runtime(crate::cmd::bench_runtime::RuntimeArgs),
    /// Training throughput per thread count (data-parallel), GFLOP/s and the fraction of a
    /// candle matmul, optionally beside the PyTorch reference of the same shapes.
    Train(crate::cmd::bench_train::TrainBenchArgs),
    /// The stitching benchmark (RMR, issue 12): concatenation, inertialization, interpolation
    /// and trained RMRs on section-4 cases with a ground truth and on free multi-clip cases.
    Stitch(crate::cmd::bench_stitch::StitchBenchArgs),
    /// The exported ARNN's step through tract and onnxruntime (batch 1 latency, batch 64 throughput) and whole keyframe completions.
    Keyframes(crate::cmd::bench_keyframes::KeyframesBenchArgs),
    /// The synthesis benchmark (RNN-GMM, issue 14): seeded sequences against held-out real
    /// motion, with and without the refiner (protocol in docs/rnn-gmm.md).
    Synthesis(crate::cmd::bench_synthesis::BenchSynthesisArgs),
    /// The denoising benchmark (RNN-GMM control, issue 15): held-out clips with seeded noise,
    /// cleaned by the MAP denoiser and by Savitzky-Golay filters (protocol in docs/rnn-gmm-control.md).
    Denoise(crate::cmd::bench_denoise::BenchDenoiseArgs),
    /// The path-following benchmark (RNN-GMM control, issue 15): five test paths from each start
    /// clip, root-to-path distance, foot skate and time (protocol in docs/rnn-gmm-control.md).
    Follow(crate::cmd::bench_follow::BenchFollowArgs),
    /// The online control benchmark (RNN-GMM control, issue 15): a script of speed and heading
    /// changes followed by the candle and the runtime controllers (protocol in docs/rnn-gmm-control.md).
    Control(Box<crate::cmd::bench_control::BenchControlArgs>),
}

/// The hierarchy a benchmarked model was trained on, checked against the dataset's.
struct TrainedOn {
    /// Parent of each joint, -1 for the root.
    parents: Vec<i32>,
    /// Joint names, when the model records real ones (an exported file made with `--skeleton`).
    names: Option<Vec<String>>,
}

/// A `--methods` entry, loaded, with the hierarchy its model was trained on (`None` for the
/// baselines and for models that record none).
fn method(spec: &str) -> anyhow::Result<(Box<dyn TransitionMethod>, Option<TrainedOn>)> {
    let parsed = crate::registry::parse_method(spec)?;
    match &parsed {
        MethodSpec::Model { name, kind, path, foot_lock } if kind == crate::registry::ONNX_KIND => {
            let (m, s) = crate::methods::load_onnx_with_skeleton(path, name.clone(), *foot_lock)?;
            // `zoo export` without `--skeleton` names the joints `joint0`, `joint1`, ...
            let placeholder = s.names.iter().enumerate().all(|(j, n)| *n == format!("joint{j}"));
            Ok((Box::new(m), Some(TrainedOn { parents: s.parents, names: (!placeholder).then_some(s.names) })))
        }
        MethodSpec::Model { kind, path, .. } if kind == "rtn" => {
            let m = crate::registry::load_method(&parsed)?;
            let (config, _) = zoo_rtn::checkpoint::read_meta(path)
                .with_context(|| format!("method `{spec}`: loading the RTN in {}", path.display()))?;
            Ok((m, (!config.parents.is_empty()).then_some(TrainedOn { parents: config.parents, names: None })))
        }
        _ => Ok((crate::registry::load_method(&parsed)?, None)),
    }
}

/// Runs the benchmark.
pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    if let Some(BenchCommand::Train(t)) = a.command {
        return crate::cmd::bench_train::run(t);
    }
    if let Some(BenchCommand::Stitch(s)) = a.command {
        return crate::cmd::bench_stitch::run(s);
    }
    if let Some(BenchCommand::Keyframes(k)) = a.command {
        return crate::cmd::bench_keyframes::run(k);
    }
    if let Some(BenchCommand::Follow(f)) = a.command {
        return crate::cmd::bench_follow::run(f);
    }
    if let Some(BenchCommand::Control(c)) = a.command {
        return crate::cmd::bench_control::run(*c);
    }
    if let Some(BenchCommand::Denoise(d)) = a.command {
        return crate::cmd::bench_denoise::run(d);
    }
    if let Some(BenchCommand::Synthesis(s)) = a.command {
        return crate::cmd::bench_synthesis::run(s);
    }
    if let Some(BenchCommand::Runtime(r)) = a.command {
        return crate::cmd::bench_runtime::run(r);
    }
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
    let start = Instant::now();
    let (methods, trained_on): (Vec<_>, Vec<_>) =
        a.methods.iter().map(|m| method(m.trim())).collect::<anyhow::Result<Vec<_>>>()?.into_iter().unzip();
    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")?);
    pb.enable_steady_tick(Duration::from_millis(120));
    pb.set_message(format!("loading {}", data.display()));
    let clips = crate::cmd::load_dataset(&data, None, a.skip_invalid)?;
    let clips = crate::cmd::exclude_clips(clips, a.exclude_glob.as_deref())?;
    let (train, test) = match (&a.test_data, &a.valid_glob) {
        (Some(test_path), glob) => {
            let train = match glob {
                Some(g) => dataset::split(clips, g)?.0,
                None => clips,
            };
            pb.set_message(format!("loading {}", test_path.display()));
            let test = crate::cmd::load_dataset(test_path, None, a.skip_invalid)?;
            (train, test)
        }
        (None, Some(g)) => dataset::split(clips, g)?,
        (None, None) => bail!("pass --valid-glob GLOB to choose the test split of --data, or --test-data PATH"),
    };
    let test: Vec<_> = test.into_iter().step_by(a.test_every as usize).collect();
    check_skeletons(&a.methods, &trained_on, &train)?;
    pb.set_message("preparing windows and statistics");
    let bench = Benchmark::new(&train, &test).map_err(anyhow::Error::msg)?;
    pb.set_message(format!("evaluating {} test windows", bench.windows()));
    let refs: Vec<&dyn TransitionMethod> = methods.iter().map(|m| m.as_ref()).collect();
    let picks: Vec<usize> = match &a.save_bvh {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let k = a.save_count.min(bench.windows()).max(1);
            (0..k).map(|i| i * bench.windows() / k).collect()
        }
        None => Vec::new(),
    };
    let mut write_err: Option<anyhow::Error> = None;
    let mut save = |method: &str, n: usize, transitions: &[zoo_data::benchmark::Transition]| {
        let Some(dir) = &a.save_bvh else { return };
        for &w in &picks {
            // `rtn:runs/rtn-bandai2` -> `rtn-rtn-bandai2`
            let tag = match method.split_once(':') {
                Some((kind, path)) => {
                    let last = std::path::Path::new(path).file_name().map(|f| f.to_string_lossy().into_owned());
                    format!("{kind}-{}", last.unwrap_or_default())
                }
                None => method.to_string(),
            };
            for (name, t) in [("gt".to_string(), None), (tag, Some(&transitions[w]))] {
                let path = dir.join(format!("w{w:04}_n{n}_{name}.bvh"));
                if let Err(e) = zoo_data::bvh::write_file(&bench.window_clip(w, n, t), &path) {
                    write_err.get_or_insert(anyhow::anyhow!("writing {}: {e}", path.display()));
                }
            }
        }
    };
    let result = bench.run_with(&refs, &a.lengths, &mut save).map_err(anyhow::Error::msg)?;
    if let Some(e) = write_err {
        return Err(e);
    }
    pb.finish_and_clear();
    println!("{}", result.table(&a.lengths));
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&result)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    println!(
        "{} training clips, {} test clips, {} test windows, {:.2} s",
        train.len(),
        test.len(),
        result.windows,
        start.elapsed().as_secs_f64()
    );
    if let Some(r) = &a.reference {
        check_reference(&result, r, a.tolerance)?;
    }
    Ok(())
}

/// Refuses a model (an RTN run folder or an exported file) trained on another hierarchy than
/// the dataset's: the same joint count is not enough, the joints would be paired with the wrong
/// bones.
fn check_skeletons(
    specs: &[String],
    trained_on: &[Option<TrainedOn>],
    train: &[dataset::NamedClip],
) -> anyhow::Result<()> {
    let Some(first) = train.first() else { return Ok(()) };
    let parents = first.clip.skeleton.parents_i32();
    let names = &first.clip.skeleton.names;
    for (spec, trained) in specs.iter().zip(trained_on) {
        let Some(t) = trained else { continue };
        if t.parents != parents {
            bail!(
                "method `{spec}`: the model was trained on another skeleton ({} joints, parents {:?}) than the \
                 dataset's ({} joints, parents {:?}, from {})",
                t.parents.len(),
                t.parents,
                parents.len(),
                parents,
                first.path.display()
            );
        }
        if let Some(model_names) = &t.names
            && let Some(j) = (0..names.len()).find(|&j| model_names[j] != names[j])
        {
            bail!(
                "method `{spec}`: the model was trained on another skeleton: its joint {j} is `{}`, the dataset's \
                 is `{}` (from {})",
                model_names[j],
                names[j],
                first.path.display()
            );
        }
    }
    Ok(())
}

/// Maps a LaFAN1 benchmark key (`zerov_quat_loss@30`) to ours (`zerovel`, `l2q@30`).
fn map_reference_key(key: &str) -> Option<(String, String)> {
    let (name, n) = key.split_once('@')?;
    let (method, metric) = name.split_once('_')?;
    let method = match method {
        "zerov" => "zerovel",
        "interp" => "interp",
        other => other,
    };
    let metric = match metric {
        "quat_loss" => "l2q",
        "pos_loss" => "l2p",
        "npss_loss" => "npss",
        other => other,
    };
    Some((method.to_string(), format!("{metric}@{n}")))
}

fn check_reference(result: &BenchResult, path: &PathBuf, tol: f64) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let reference: BTreeMap<String, f64> = serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a JSON object of numbers", path.display()))?;
    let mut worst: f64 = 0.0;
    let mut failures = Vec::new();
    for (key, want) in &reference {
        let Some((m, k)) = map_reference_key(key) else {
            failures.push(format!("{key}: not a `method_metric@n` key"));
            continue;
        };
        let Some(got) = result.methods.get(&m).and_then(|row| row.get(&k)) else {
            failures.push(format!("{key}: not computed (run with the method and length it names)"));
            continue;
        };
        let rel = (got - want).abs() / want.abs().max(1e-300);
        worst = worst.max(rel);
        println!("{key:<24} reference {want:<22.15} ours {got:<22.15} rel {rel:.2e}");
        if !(rel <= tol) {
            failures.push(format!("{key}: ours {got} vs reference {want} (relative error {rel:.2e} > {tol:e})"));
        }
    }
    if failures.is_empty() {
        println!("reference check: {} values match within {tol:e} (worst relative error {worst:.2e})", reference.len());
        Ok(())
    } else {
        bail!("reference check failed:\n  {}", failures.join("\n  "))
    }
}
