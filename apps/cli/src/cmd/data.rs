//! `zoo data ...`: dataset statistics and synthetic data.

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use zoo_data::synth::{self, SynthConfig};

/// `zoo data` subcommands.
#[derive(Subcommand)]
pub enum DataCommand {
    /// Statistics of a BVH file or folder: clips, frames, fps, joints, root speed, foot skate.
    Stats(StatsArgs),
    /// Generate procedural locomotion (BVH + heightmaps + manifest) into a folder.
    Synth(SynthArgs),
    /// Simulate hop sequences of the planar lamp (ARNN): BVH + JSON per sequence.
    Luxo(super::data_luxo::LuxoArgs),
    /// Convert a clip between formats: BVH, glTF or FBX in; the output's extension picks BVH
    /// (`.bvh`, `.bvh.gz`) or glTF (`.glb`, `.gltf`) (`zoo data convert take.fbx take.glb`).
    Convert(ConvertArgs),
    /// Resample a clip to another frame rate over the same span (rotations by slerp, positions
    /// linearly): BVH, glTF or FBX in, BVH or glTF out (`zoo data resample take60.bvh take30.bvh --fps 30`).
    Resample(ResampleArgs),
}

/// Arguments of `zoo data resample`.
#[derive(Args)]
pub struct ResampleArgs {
    /// The clip to read (`.bvh`, `.bvh.gz`, `.glb`, `.gltf`, `.fbx`).
    pub input: PathBuf,
    /// The file to write: `.bvh`, `.bvh.gz`, `.glb` or `.gltf`.
    pub output: PathBuf,
    /// Frames per second of the output.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::fps)]
    pub fps: f64,
    /// The animation to read: an FBX take or a glTF animation, by name (default: the first).
    #[arg(long)]
    pub take: Option<String>,
    /// Memory bound of the resampled clip, in GB (its size is computed before it is made).
    #[arg(long, default_value_t = 2.0, allow_hyphen_values = true, value_parser = crate::args::memory_gb)]
    pub max_memory: f64,
}

/// Arguments of `zoo data convert`.
#[derive(Args)]
pub struct ConvertArgs {
    /// The clip to read (`.bvh`, `.bvh.gz`, `.glb`, `.gltf`, `.fbx`).
    pub input: PathBuf,
    /// The file to write: `.bvh`, `.bvh.gz`, `.glb` or `.gltf`.
    pub output: PathBuf,
    /// The animation to read: an FBX take or a glTF animation, by name (default: the first).
    #[arg(long)]
    pub take: Option<String>,
}

/// Arguments of `zoo data stats`.
#[derive(Args)]
pub struct StatsArgs {
    /// A clip file (`.bvh`, `.bvh.gz`, `.glb`, `.gltf`, `.fbx`) or a folder searched recursively (formats
    /// may be mixed when the skeletons agree; docs/formats.md).
    pub path: PathBuf,
    /// Also write the statistics as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Only the clips whose file name matches this glob, e.g. `'synth_walk_*'`.
    #[arg(long)]
    pub glob: Option<String>,
    /// Leave out the clips that cannot join the dataset (unreadable, another skeleton or
    /// frame rate) and list them, instead of refusing the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
}

/// Arguments of `zoo data synth`.
#[derive(Args)]
pub struct SynthArgs {
    /// Output folder (created if needed).
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Minutes of motion to generate.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true, value_parser = crate::args::synth_minutes)]
    pub minutes: f64,
    /// Random seed: the same seed writes the same files.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Uneven terrain (slopes, steps, bumps) with a heightmap per clip; flat floor otherwise.
    #[arg(long)]
    pub terrain: bool,
    /// Seconds per clip.
    #[arg(long, default_value_t = 10.0, allow_hyphen_values = true, value_parser = crate::args::clip_seconds)]
    pub clip_seconds: f64,
    /// Frames per second.
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true, value_parser = crate::args::fps)]
    pub fps: f64,
}

/// Runs a `zoo data` subcommand.
pub fn run(cmd: DataCommand) -> anyhow::Result<()> {
    match cmd {
        DataCommand::Stats(a) => stats(a),
        DataCommand::Synth(a) => run_synth(a),
        DataCommand::Luxo(a) => super::data_luxo::run(a),
        DataCommand::Convert(a) => convert(a),
        DataCommand::Resample(a) => resample(a),
    }
}

/// Refuses an output clip zoo cannot write (FBX, or another extension) or may not replace.
fn check_clip_output(output: &std::path::Path) -> anyhow::Result<()> {
    use zoo_data::clip_io::ClipFormat;
    if ClipFormat::of(output).is_none_or(|f| f == ClipFormat::Fbx) {
        anyhow::bail!(
            "{}: the output's extension must be .bvh, .bvh.gz, .glb or .gltf (zoo writes BVH and glTF)",
            output.display()
        );
    }
    crate::cmd::check_output_file("output", output)
}

/// `zoo data resample`: one clip read, resampled ([`zoo_motion::Clip::resampled`]) and written
/// through `zoo_data::clip_io`, after its size is checked against `--max-memory`.
fn resample(a: ResampleArgs) -> anyhow::Result<()> {
    use zoo_data::clip_io;
    check_clip_output(&a.output)?;
    let opts = clip_io::ReadOptions { drop_dummy_root: false, take: a.take.clone() };
    let clip = clip_io::read(&a.input, &opts)?;
    if clip.frames() == 0 {
        anyhow::bail!("{}: the clip has no frame; there is nothing to resample", a.input.display());
    }
    let frames = clip.resampled_frames(a.fps);
    let bound = (a.max_memory * 1e9) as u64;
    clip_io::check_clip_size(frames, clip.joints(), bound, "--max-memory")
        .map_err(|e| anyhow::anyhow!("--fps {}: {e}", a.fps))?;
    let out = clip.resampled(a.fps);
    clip_io::write(&out, &a.output)?;
    println!(
        "wrote {}: {} frames at {} fps, resampled from {} frames at {:.3} fps ({})",
        a.output.display(),
        out.frames(),
        a.fps,
        clip.frames(),
        clip.fps(),
        a.input.display()
    );
    Ok(())
}

/// `zoo data convert`: one clip read and written through `zoo_data::clip_io` (units and axes
/// converted to zoo's on reading and to the output format's on writing).
fn convert(a: ConvertArgs) -> anyhow::Result<()> {
    use zoo_data::clip_io;
    check_clip_output(&a.output)?;
    let opts = clip_io::ReadOptions { drop_dummy_root: false, take: a.take.clone() };
    let (clip, source) = clip_io::read_with_source(&a.input, &opts)?;
    clip_io::write(&clip, &a.output)?;
    println!(
        "wrote {}: {} frames of {} joints at {:.3} fps, read from {} ({})",
        a.output.display(),
        clip.frames(),
        clip.joints(),
        1.0 / clip.frame_time,
        a.input.display(),
        source.describe()
    );
    Ok(())
}

/// `zoo data stats` ([`zoo_data::stats`]).
fn stats(a: StatsArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    let clips = crate::cmd::load_dataset(&a.path, a.glob.as_deref(), a.skip_invalid)?;
    let out = zoo_data::stats::stats(&clips)?;
    print!("{}", out.text(&clips[0].clip.skeleton));
    if let Some(path) = &a.json {
        crate::cmd::write_json(path, &out)?;
    }
    Ok(())
}

fn run_synth(a: SynthArgs) -> anyhow::Result<()> {
    if !(a.minutes > 0.0 && a.clip_seconds > 0.0 && a.fps > 0.0) {
        anyhow::bail!("--minutes, --clip-seconds and --fps must be positive");
    }
    crate::args::check_synth_size(("--minutes", a.minutes), a.clip_seconds, a.fps).map_err(anyhow::Error::msg)?;
    // The clips are held until written: 1.4 KB a frame measured (58 MB peak at 10 minutes, 133
    // MB at 40), 2 KB counted.
    zoo_nn::args::check_synth_memory(("--minutes", a.minutes), a.clip_seconds, a.fps, 2048.0)
        .map_err(anyhow::Error::msg)?;
    crate::cmd::check_output_dir("--out", &a.out)?;
    let cfg =
        SynthConfig { minutes: a.minutes, seed: a.seed, terrain: a.terrain, fps: a.fps, clip_seconds: a.clip_seconds };
    let start = std::time::Instant::now();
    let n = cfg.clip_count();
    let bar = ProgressBar::new(2 * n as u64);
    bar.set_style(ProgressStyle::with_template("{msg:10} [{bar:40}] {pos}/{len} {elapsed}").expect("template"));
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
