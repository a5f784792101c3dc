//! `zoo data ...`: dataset statistics and synthetic data.

use anyhow::Context;
use clap::{Args, Subcommand};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::synth::{self, SynthConfig};
use zoo_data::{dataset, metrics};
use zoo_motion::Skeleton;

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
    }
}

/// `zoo data convert`: one clip read and written through `zoo_data::clip_io` (units and axes
/// converted to zoo's on reading and to the output format's on writing).
fn convert(a: ConvertArgs) -> anyhow::Result<()> {
    use zoo_data::clip_io;
    if clip_io::ClipFormat::of(&a.output).is_none_or(|f| f == clip_io::ClipFormat::Fbx) {
        anyhow::bail!(
            "{}: the output's extension must be .bvh, .bvh.gz, .glb or .gltf (zoo writes BVH and glTF)",
            a.output.display()
        );
    }
    crate::cmd::check_output_file("output", &a.output)?;
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

/// Statistics printed by `zoo data stats` (and written with `--json`).
#[derive(Serialize)]
pub struct DataStats {
    /// Number of clips.
    pub clips: usize,
    /// Total frames.
    pub frames: usize,
    /// Total duration in seconds.
    pub duration_s: f64,
    /// Distinct frame rates found.
    pub fps: Vec<f64>,
    /// Joints per frame (after dropping a dummy root).
    pub joints: usize,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Parent index per joint (-1 for the root).
    pub parents: Vec<i32>,
    /// Horizontal root speed percentiles over all frames (units/s): p5, p25, p50, p75, p95;
    /// `null` when no clip has two frames.
    pub root_speed: Option<RootSpeed>,
    /// Foot joints used for the skate measure (empty: none found, no foot figures).
    pub foot_joints: Vec<String>,
    /// Planted height of each foot joint (5th percentile of its height).
    pub planted_heights: Vec<f64>,
    /// The data's own foot skate (units per frame, `BENCHMARK.md` definition, all frames; heights
    /// above the clip's terrain when a `NAME.terrain.json` lies beside it); `null` without feet
    /// or without two consecutive frames.
    pub foot_skate: Option<f64>,
    /// Lowest foot-joint height over all frames (above the terrain when there is one): how far
    /// feet sink below the ground if negative; `null` without feet or frames.
    pub min_foot_height: Option<f64>,
    /// Largest change of a bone's length within a clip (0 for rigid skeletons).
    pub max_bone_length_change: f64,
    /// Seconds taken.
    pub seconds: f64,
}

/// Percentiles of the horizontal root speed.
#[derive(Serialize)]
pub struct RootSpeed {
    /// 5th percentile.
    pub p5: f64,
    /// 25th percentile.
    pub p25: f64,
    /// Median.
    pub p50: f64,
    /// 75th percentile.
    pub p75: f64,
    /// 95th percentile.
    pub p95: f64,
}

fn stats(a: StatsArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    let start = Instant::now();
    let clips = crate::cmd::load_dataset(&a.path, a.glob.as_deref(), a.skip_invalid)?;
    let skeleton = clips[0].clip.skeleton.clone();
    let j = skeleton.len();
    let feet = metrics::foot_joints(&skeleton.names);
    // Per clip: global positions of the feet and the root's horizontal speed.
    struct PerClip {
        feet: Vec<DVec3>,
        speed: Vec<f64>,
        bone_drift: f64,
    }
    let per: Vec<PerClip> = clips
        .par_iter()
        .map(|c| {
            let (_, gp) = c.clip.global();
            let frames = c.clip.frames();
            // Heights are measured above the clip's own terrain when it has a heightmap.
            let ground = match zoo_data::terrain::sibling_of(&c.path) {
                Some(t) => Some(zoo_data::terrain::read(&t)?),
                None => None,
            };
            let mut fp = Vec::with_capacity(frames * feet.len());
            for f in 0..frames {
                fp.extend(feet.iter().map(|&k| {
                    let p = gp[f * j + k];
                    DVec3::new(p.x, p.y - ground.as_ref().map_or(0.0, |g| g.height(p.x, p.z)), p.z)
                }));
            }
            let speed = (1..frames)
                .map(|f| {
                    let d = gp[f * j] - gp[(f - 1) * j];
                    (d.x * d.x + d.z * d.z).sqrt() / c.clip.frame_time
                })
                .collect();
            // Largest change of any bone's length (global joint distance) from frame 0.
            let mut bone_drift: f64 = 0.0;
            for k in (1..j).filter(|_| frames > 0) {
                let p = c.clip.skeleton.parents[k].unwrap_or(0);
                let len0 = (gp[k] - gp[p]).length();
                for f in 1..frames {
                    bone_drift = bone_drift.max(((gp[f * j + k] - gp[f * j + p]).length() - len0).abs());
                }
            }
            Ok(PerClip { feet: fp, speed, bone_drift })
        })
        .collect::<anyhow::Result<_>>()?;
    let planted: Vec<f64> = (0..feet.len())
        .map(|k| {
            let mut h: Vec<f64> =
                per.iter().flat_map(|p| p.feet.iter().skip(k).step_by(feet.len()).map(|v| v.y)).collect();
            dataset::percentile(&mut h, 5.0)
        })
        .collect();
    let fs = metrics::FootSkate { joints: (0..feet.len()).collect(), planted: planted.clone(), scale: 2.5 };
    let (mut skate_sum, mut skate_n) = (0.0, 0usize);
    for (p, c) in per.iter().zip(&clips) {
        let frames = c.clip.frames();
        if frames > 1 && !feet.is_empty() {
            skate_sum += fs.skate(&p.feet, frames, feet.len()) * ((frames - 1) * feet.len()) as f64;
            skate_n += (frames - 1) * feet.len();
        }
    }
    let mut speeds: Vec<f64> = per.iter().flat_map(|p| p.speed.iter().copied()).collect();
    let root_speed = (!speeds.is_empty()).then(|| {
        let mut pct = |q| dataset::percentile(&mut speeds, q);
        RootSpeed { p5: pct(5.0), p25: pct(25.0), p50: pct(50.0), p75: pct(75.0), p95: pct(95.0) }
    });
    let mut fps: Vec<f64> = clips.iter().map(|c| (c.clip.fps() * 1000.0).round() / 1000.0).collect();
    fps.sort_by(f64::total_cmp);
    fps.dedup();
    let frames: usize = clips.iter().map(|c| c.clip.frames()).sum();
    let out = DataStats {
        clips: clips.len(),
        frames,
        duration_s: clips.iter().map(|c| c.clip.duration()).sum(),
        fps,
        joints: j,
        joint_names: skeleton.names.clone(),
        parents: skeleton.parents_i32(),
        root_speed,
        foot_joints: feet.iter().map(|&k| skeleton.names[k].clone()).collect(),
        planted_heights: planted,
        foot_skate: (skate_n > 0).then(|| skate_sum / skate_n as f64),
        min_foot_height: per.iter().flat_map(|p| p.feet.iter().map(|v| v.y)).reduce(f64::min),
        max_bone_length_change: per.iter().map(|p| p.bone_drift).fold(0.0, f64::max),
        seconds: start.elapsed().as_secs_f64(),
    };
    print_stats(&out, &skeleton);
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&out)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn print_stats(s: &DataStats, skeleton: &Skeleton) {
    println!("clips      {}", s.clips);
    println!("frames     {}", s.frames);
    println!("duration   {:.1} s ({:.1} min)", s.duration_s, s.duration_s / 60.0);
    println!("fps        {}", s.fps.iter().map(|f| format!("{f}")).collect::<Vec<_>>().join(", "));
    println!("joints     {}", s.joints);
    print_tree(skeleton, 0, 1);
    match &s.root_speed {
        Some(r) => println!(
            "root speed (units/s)  p5 {:.1}  p25 {:.1}  median {:.1}  p75 {:.1}  p95 {:.1}",
            r.p5, r.p25, r.p50, r.p75, r.p95
        ),
        None => println!("root speed            not measured: no clip has two frames"),
    }
    for (n, h) in s.foot_joints.iter().zip(&s.planted_heights) {
        println!("planted height  {n:<10} {h:.2}");
    }
    if s.foot_joints.is_empty() {
        println!("foot skate            not measured: no joint name contains `foot` or `toe`");
    } else {
        match s.foot_skate {
            Some(v) => println!("foot skate (units/frame, all frames)  {v:.4}"),
            None => println!("foot skate            not measured: no clip has two frames"),
        }
        if let Some(h) = s.min_foot_height {
            println!("lowest foot joint height              {h:.2}");
        }
    }
    println!("largest bone length change            {:.2e}", s.max_bone_length_change);
    println!("done in {:.2} s", s.seconds);
}

fn print_tree(s: &Skeleton, j: usize, depth: usize) {
    println!("{}{}", "  ".repeat(depth), s.names[j]);
    for c in s.children(j) {
        print_tree(s, c, depth + 1);
    }
}

fn run_synth(a: SynthArgs) -> anyhow::Result<()> {
    if !(a.minutes > 0.0 && a.clip_seconds > 0.0 && a.fps > 0.0) {
        anyhow::bail!("--minutes, --clip-seconds and --fps must be positive");
    }
    crate::args::check_synth_size(("--minutes", a.minutes), a.clip_seconds, a.fps).map_err(anyhow::Error::msg)?;
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
