//! `zoo bench follow`: the path-following benchmark ([`zoo_rnngmm::bench::follow`], protocol
//! in docs/rnn-gmm-control.md).

use crate::cmd::follow::OptimiserArgs;
use clap::Args;
use std::path::PathBuf;
use zoo_rnngmm::bench::follow::FollowBenchOptions;
use zoo_rnngmm::path::TEST_PATHS;

/// Arguments of `zoo bench follow`.
#[derive(Args)]
pub struct BenchFollowArgs {
    /// Run folder of `zoo train rnn-gmm`.
    #[arg(long)]
    pub model: PathBuf,
    /// Start clips and frames, `CLIP.bvh:FRAME`, one per gait (repeat the option) [default: the
    /// run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Vec<String>,
    /// Test paths, comma-separated, of straight, circle, s-curve, corner, spiral.
    #[arg(long, value_delimiter = ',', default_values_t = TEST_PATHS.map(String::from))]
    pub paths: Vec<String>,
    /// Real clips whose foot skate is the reference (a folder or file of BVH); with --glob.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Clip-name pattern within --data.
    #[arg(long, default_value = "*")]
    pub glob: String,
    /// Folder that receives a top-view PNG and the BVH of every run, and all the top views in one
    /// sheet (`all.png`: a row per start, a column per path).
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// The optimiser's settings.
    #[command(flatten)]
    pub optimiser: OptimiserArgs,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs the benchmark.
pub fn run(a: BenchFollowArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    let o = FollowBenchOptions {
        model: a.model,
        from: a.from.iter().map(|s| crate::args::clip_and_frame(s)).collect::<anyhow::Result<_>>()?,
        paths: a.paths,
        data: a.data,
        glob: a.glob,
        plots: a.plots,
        optimiser: a.optimiser.options(),
    };
    let report = zoo_rnngmm::bench::follow::run(&o, &crate::progress::Bar::new())?;
    println!("{}", report.text());
    if let Some(p) = &a.json {
        crate::cmd::write_json(p, &report)?;
    }
    Ok(())
}
