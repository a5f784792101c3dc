//! `zoo bench follow`: the path-following benchmark ([`zoo_bench::follow`], protocol
//! in docs/rnn-gmm-control.md).

use crate::cmd::follow::OptimiserArgs;
use clap::Args;
use std::path::PathBuf;
use zoo_bench::follow::FollowBenchOptions;
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
    /// The same generator exported for the runtime (`zoo export --onnx DIR --out FILE.onnx`):
    /// the runtime's real-time follower runs with it.
    #[arg(long)]
    pub onnx: Option<PathBuf>,
    /// Followers to run, comma-separated: offline (candle), runtime (needs --onnx).
    #[arg(long, value_delimiter = ',', default_values_t = vec!["offline".to_string(), "runtime".to_string()])]
    pub followers: Vec<String>,
    /// Speed the runtime's follower walks at, in clip units per second (cm/s for the zoo's
    /// data) [default: the data's mean speed].
    #[arg(long, value_parser = crate::args::speed_units)]
    pub speed: Option<f64>,
    /// Seed frames the runtime's follower warms its generator with.
    #[arg(long, default_value_t = 30, value_parser = crate::args::frame_count)]
    pub runtime_seed_frames: usize,
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
    let [offline, runtime] =
        zoo_bench::control::methods_of(&a.followers, ["offline", "runtime"], "--followers", a.onnx.is_some())?;
    let onnx = match a.onnx.filter(|_| runtime) {
        Some(p) => Some((crate::cmd::bench_control::runtime_model(&p, "`zoo bench follow --onnx`")?, p)),
        None => None,
    };
    let o = FollowBenchOptions {
        model: a.model,
        from: a.from.iter().map(|s| crate::args::clip_and_frame(s)).collect::<anyhow::Result<_>>()?,
        paths: a.paths,
        data: a.data,
        glob: a.glob,
        plots: a.plots,
        optimiser: a.optimiser.options(),
        offline,
        onnx,
        speed: a.speed,
        runtime_seed_frames: a.runtime_seed_frames,
    };
    let report = zoo_bench::follow::run(&o, &zoo_nn::progress::Bar::new())?;
    println!("{}", report.text());
    if let Some(p) = &a.json {
        crate::cmd::write_json(p, &report)?;
    }
    Ok(())
}
