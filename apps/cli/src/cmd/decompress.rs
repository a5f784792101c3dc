//! `zoo decompress`: temporal super-resolution (RTN sec. 7.4), rebuilding a clip from its
//! first 10 frames and one keyframe per interval by chaining RTN transitions.

use anyhow::Context;
use clap::Args;
use std::path::PathBuf;
use zoo_motion::pipeline;

/// Arguments of `zoo decompress`.
#[derive(Args)]
pub struct DecompressArgs {
    /// Run folder of `zoo train rtn`.
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
    let mut clip = zoo_data::clip_io::read_model_clip(&a.input)?;
    let (model, stats) = zoo_rtn::checkpoint::load_run(&a.model, "decompress")?;
    zoo_rtn::command::check_skeleton(&a.model, model.config(), &mut clip, &a.input)?;
    let interval = a.interval.unwrap_or_else(|| clip.fps().round() as usize).max(1);
    let j = clip.joints();
    let keys = pipeline::keyframe_inputs(&clip, interval).with_context(|| format!("{}", a.input.display()))?;
    let y = model.super_resolve(&stats, &keys.context, &keys.keys, interval).context("rebuilding the clip")?;
    let frames = y.len() / (3 * j);
    let mut out = pipeline::rebuild_from_keyframes(&clip, interval, &y);
    let tail = pipeline::fill_tail(&mut out, &clip);
    zoo_data::clip_io::write(&out, &a.out)?;
    let err = pipeline::mean_position_error(&clip, &y);
    let tail = match tail {
        0 => String::new(),
        n => format!(", and the last {n} frame(s) after the last keyframe in-betweened to the clip's last frame"),
    };
    println!(
        "rebuilt {frames} frames of {} from {} context frames and {} keyframes (every {interval}){tail}; \
         mean joint position error {err:.2} (clip units, network frames); wrote {} ({} frames)",
        a.input.display(),
        pipeline::CONTEXT_FRAMES,
        keys.key_count,
        a.out.display(),
        out.frames()
    );
    Ok(())
}
