//! `zoo data ...`: dataset statistics and synthetic data.

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use zoo_data::synth::{self, SynthConfig};

/// `zoo data` subcommands.
#[derive(Subcommand)]
pub enum DataCommand {
    /// Statistics of a BVH file or folder: clips, frames, fps, joints, root speed, foot skate.
    Stats(StatsArgs),
    /// Generate procedural locomotion (BVH + heightmaps + manifest) into a folder.
    Synth(SynthArgs),
}

/// Arguments of `zoo data stats`.
#[derive(Args)]
pub struct StatsArgs {
    /// A `.bvh`/`.bvh.gz` file or a folder searched recursively.
    pub path: std::path::PathBuf,
    /// Also write the statistics as JSON to this file.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

/// Arguments of `zoo data synth`.
#[derive(Args)]
pub struct SynthArgs {
    /// Output folder (created if needed).
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Minutes of motion to generate.
    #[arg(long, default_value_t = 10.0)]
    pub minutes: f64,
    /// Random seed: the same seed writes the same files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Uneven terrain (slopes, steps, bumps) with a heightmap per clip; flat floor otherwise.
    #[arg(long)]
    pub terrain: bool,
    /// Seconds per clip.
    #[arg(long, default_value_t = 10.0)]
    pub clip_seconds: f64,
    /// Frames per second.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
}

/// Runs a `zoo data` subcommand.
pub fn run(cmd: DataCommand) -> anyhow::Result<()> {
    match cmd {
        DataCommand::Stats(_a) => anyhow::bail!("not yet"),
        DataCommand::Synth(a) => run_synth(a),
    }
}

fn run_synth(a: SynthArgs) -> anyhow::Result<()> {
    if !(a.minutes > 0.0 && a.clip_seconds > 0.0 && a.fps > 0.0) {
        anyhow::bail!("--minutes, --clip-seconds and --fps must be positive");
    }
    let cfg = SynthConfig {
        minutes: a.minutes,
        seed: a.seed,
        terrain: a.terrain,
        fps: a.fps,
        clip_seconds: a.clip_seconds,
    };
    let start = std::time::Instant::now();
    let n = cfg.clip_count();
    let bar = ProgressBar::new(2 * n as u64);
    bar.set_style(
        ProgressStyle::with_template("{msg:10} [{bar:40}] {pos}/{len} {elapsed}")
            .expect("template"),
    );
    bar.set_message("generate");
    let clips = synth::generate_with_progress(&cfg, &|| bar.inc(1));
    bar.set_message("write");
    synth::write_dir(&clips, &cfg, &a.out, &|| bar.inc(1))?;
    bar.finish_and_clear();
    let frames: usize = clips.iter().map(|c| c.clip.frames()).sum();
    let mut by_gait = std::collections::BTreeMap::new();
    for c in &clips {
        *by_gait.entry(c.gait.name()).or_insert(0usize) += 1;
    }
    let gaits: Vec<String> = by_gait.iter().map(|(g, k)| format!("{k} {g}")).collect();
    println!(
        "wrote {} clips ({} frames, {:.1} min at {} fps; {}){} to {} in {:.2} s",
        clips.len(),
        frames,
        frames as f64 / cfg.fps / 60.0,
        cfg.fps,
        gaits.join(", "),
        if cfg.terrain { " with terrain" } else { "" },
        a.out.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
