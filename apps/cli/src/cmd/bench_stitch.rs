//! `zoo bench stitch`: the stitching benchmark ([`zoo_rmr::bench`], protocol in docs/rmr.md).

use clap::Args;
use std::path::PathBuf;
use zoo_rmr::bench::{StitchBenchOptions, StitchMethod};

/// Arguments of `zoo bench stitch`.
#[derive(Args)]
pub struct StitchBenchArgs {
    /// Dataset folder: files not matching `--valid-glob` are the training split (segment
    /// databases, statistics, planted foot heights); matching files are the test split.
    #[arg(long)]
    pub data: PathBuf,
    /// Glob on file names selecting the test split, e.g. `'*_youthful_*'`.
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// A held-out dataset on the same skeleton: its clips are the test split instead.
    #[arg(long)]
    pub test_data: Option<PathBuf>,
    /// Comma-separated methods: `concat` (aligned concatenation), `inertialize`, `interp`,
    /// `rmr:RUN` (a `zoo train rmr` folder or its exported file, run by the engine runtime as
    /// `zoo stitch` runs it; no post-process), `rmr+ik:RUN` (the ankles placed at its predicted
    /// lower-body positions by IK, RMR sec. 5), `rmr+lock:RUN` (with the foot lock by its
    /// predicted contacts), `rmr+ik+lock:RUN` (both, in that order), `+guard` after `rmr` or
    /// `rmr+ik` for the seam guard (`rmr+ik+guard+lock:RUN` is what `zoo stitch` writes by
    /// default), each RMR form also as `inert+rmr...:RUN` (the seams inertialized before
    /// refining: `zoo stitch --pre-blend`) and as `candle-rmr...:RUN_DIR` (the training model in
    /// candle, for parity checks), `rtn:RUN_DIR` / `rtn+lock:RUN_DIR` (a `zoo train rtn` folder
    /// in-betweening across each seam: 10 context frames before, target after).
    #[arg(long, default_value = "concat,inertialize,interp", value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Frames of the blend at each seam (inertialize, interp) and after each RMR window.
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub blend_frames: usize,
    /// Free cases of each kind (two clips, three clips).
    #[arg(long, default_value_t = 50, allow_hyphen_values = true, value_parser = crate::args::case_count)]
    pub free_cases: usize,
    /// Seed of the test cases (segment lengths, neighbour ranks, free cuts).
    #[arg(long, default_value_t = 12, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Database segments start every this many frames (1: every segment, exact search).
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub database_stride: usize,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Leave out the clips that cannot join the dataset and list them, instead of refusing it.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Leave out of `--data` every clip whose file name matches this glob, before the split.
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Benchmark RMR run folders without their fallback towards the refiner's input (the
    /// thresholds `zoo train rmr` calibrates; docs/rmr.md): the network alone.
    #[arg(long)]
    pub no_fallback: bool,
}

/// Runs the benchmark.
pub fn run(a: StitchBenchArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    let load = |spec: &str| Ok(zoo_bench::registry::load_method(&zoo_bench::registry::parse_method(spec)?)?);
    let methods = a
        .methods
        .iter()
        .map(|m| {
            StitchMethod::parse(
                m.trim(),
                |spec| load(spec).map_err(crate::cmd::message),
                |path, post| {
                    let r = zoo_tasks::stitch::RuntimeSeamRefiner::load(path, post)
                        .map_err(|e| zoo_data::Message(e.to_string()))?;
                    Ok(Box::new(r) as Box<dyn zoo_rmr::bench::SeamRefiner>)
                },
            )
        })
        .map(|m| {
            m.map(|mut m| {
                if let (true, StitchMethod::Rmr { refiner, .. }) = (a.no_fallback, &mut m) {
                    refiner.drop_fallback();
                }
                m
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let bar = zoo_nn::progress::Bar::new();
    let split = crate::cmd::Split {
        valid_glob: a.valid_glob.as_deref(),
        test_data: a.test_data.as_deref(),
        exclude_glob: a.exclude_glob.as_deref(),
    };
    let (train, test) = crate::cmd::load_split(&a.data, &split, a.skip_invalid, &bar)?;
    let opts = StitchBenchOptions {
        blend_frames: a.blend_frames,
        free_cases: a.free_cases,
        seed: a.seed,
        database_stride: a.database_stride,
    };
    let result = zoo_rmr::bench::run(train, test, &a.data, &methods, &opts, &bar)?;
    drop(bar);
    println!("{}", zoo_rmr::bench::table(&result));
    for m in &methods {
        if let StitchMethod::Rmr { name, refiner, .. } = m
            && let Some((windows, triggered, weight)) = refiner.fallback_summary()
        {
            println!(
                "{name}: the fallback towards the refiner's input acted on {:.1} % of {windows} windows (mean weight {weight:.3})",
                100.0 * triggered
            );
        }
    }
    if let Some(path) = &a.json {
        crate::cmd::write_json(path, &result)?;
    }
    println!("{}", result.summary());
    Ok(())
}
