//! `zoo bench control`: the online control benchmark ([`zoo_bench::control`], protocol
//! in docs/rnn-gmm-control.md).

use crate::cmd::control::OnlineArgs;
use clap::Args;
use std::path::PathBuf;
use zoo_bench::control::ControlBenchOptions;

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

/// The exported generator of `--onnx` (for `command`), without its refiner.
pub fn runtime_model(path: &std::path::Path, command: &str) -> anyhow::Result<zoo_runtime::synthesis::SynthesisModel> {
    let model = zoo_bench::exported::load(path, &[zoo_runtime::MotionTaskKind::Synthesis], command)?;
    Ok(model.into_synthesis()?.without_refiner())
}

/// Runs the benchmark.
pub fn run(a: BenchControlArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    let [candle, runtime] =
        zoo_bench::control::methods_of(&a.controllers, ["candle", "runtime"], "--controllers", a.onnx.is_some())?;
    let script = match &a.script {
        Some(p) => Some((crate::cmd::control::read_script(p)?, p.clone())),
        None => None,
    };
    let o = ControlBenchOptions {
        onnx: a.onnx.map(|p| anyhow::Ok((runtime_model(&p, "`zoo bench control --onnx`")?, p))).transpose()?,
        from: a.from.as_deref().map(crate::args::clip_and_frame).transpose()?,
        model: a.model,
        script,
        candle,
        runtime,
        seeds: a.seeds,
        data: a.data,
        glob: a.glob,
        runtime_seed_frames: a.runtime_seed_frames,
        plots: a.plots,
        online: a.online.options(),
    };
    let report = zoo_bench::control::run(&o, &zoo_nn::progress::Bar::new())?;
    println!("{}", report.text());
    crate::cmd::write_report(a.json.as_deref(), &report)
}
