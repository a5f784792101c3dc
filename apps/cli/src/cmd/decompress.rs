//! `zoo decompress`: temporal super-resolution (RTN sec. 7.4), rebuilding a clip from its
//! first 10 frames and one keyframe per interval by chaining RTN transitions on the runtime
//! ([`zoo_tasks::transition::decompress`]).

use clap::Args;
use std::path::PathBuf;

/// Arguments of `zoo decompress`.
#[derive(Args)]
pub struct DecompressArgs {
    /// Run folder of `zoo train rtn`, or its exported file (`zoo export --onnx`).
    #[arg(long)]
    pub model: PathBuf,
    /// Clip to compress and rebuild.
    pub input: PathBuf,
    /// Frames between keyframes (default: one keyframe per second).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub interval: Option<usize>,
    /// Output clip of the rebuilt motion (`.bvh`, `.bvh.gz`, `.glb` or `.gltf`).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `zoo decompress`.
pub fn run(a: DecompressArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    let o =
        zoo_tasks::transition::DecompressOptions { model: a.model, input: a.input, interval: a.interval, out: a.out };
    println!("{}", zoo_tasks::transition::decompress(&o)?);
    Ok(())
}
