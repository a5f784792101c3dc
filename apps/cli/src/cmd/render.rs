//! `zoo render`: stick-figure GIFs and PNG contact sheets of BVH clips.

use anyhow::{Context, Result, bail};
use clap::Args;
use std::path::{Path, PathBuf};
use zoo_data::clip_io::{ReadOptions, read as read_file};
use zoo_data::render::{RenderClip, RenderOptions, render_gif, render_sheet};

/// Arguments of `zoo render`.
#[derive(Args)]
pub struct RenderArgs {
    /// The clip (`.bvh` / `.bvh.gz`); a `NAME.terrain.json` beside it is used as its ground.
    pub clip: PathBuf,
    /// More clips drawn over the first one in other colours (e.g. a method's output).
    #[arg(long, num_args = 1..)]
    pub compare: Vec<PathBuf>,
    /// First frame.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true, value_parser = crate::args::frame_index)]
    pub from: usize,
    /// One past the last frame (default: the end of the shortest clip).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_end)]
    pub to: Option<usize>,
    /// Draw every k-th frame (GIF default: about 15 fps; PNG default: 2 per second).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub every: Option<usize>,
    /// Print frame numbers.
    #[arg(long)]
    pub frame_numbers: bool,
    /// Heightmap header (`.json`, see `zoo_data::terrain`) of the ground under the clips.
    #[arg(long)]
    pub terrain: Option<PathBuf>,
    /// Draw the clips side by side, this far apart (clip units, e.g. 75 for cm) along the
    /// direction of travel, instead of over each other: the first clip in the middle (the camera
    /// follows it), the others alternately behind and ahead of it.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::spacing)]
    pub side_by_side: Option<f64>,
    /// Output file: `.gif` (animation) or `.png` (contact sheet).
    #[arg(long)]
    pub out: PathBuf,
}

fn label(path: &Path) -> String {
    let name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    name.trim_end_matches(".gz").trim_end_matches(".bvh").to_string()
}

/// Runs `zoo render`.
pub fn run(a: RenderArgs) -> Result<()> {
    let ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "gif" && ext != "png" {
        bail!("--out {}: expected a .gif or .png file name", a.out.display());
    }
    crate::cmd::check_output_file("--out", &a.out)?;
    let terrain_path = a.terrain.clone().or_else(|| zoo_data::terrain::sibling_of(&a.clip));
    let terrain = match &terrain_path {
        Some(p) => Some(zoo_data::terrain::read(p)?),
        None => None,
    };
    let read = ReadOptions { drop_dummy_root: true, take: None };
    let mut clips = Vec::new();
    for path in std::iter::once(&a.clip).chain(&a.compare) {
        let clip = read_file(path, &read).with_context(|| format!("reading {}", path.display()))?;
        clips.push(RenderClip { label: label(path), clip, terrain: terrain.clone() });
    }
    if let Some(spacing) = a.side_by_side {
        let c0 = &clips[0].clip;
        let last = c0.frames().saturating_sub(1);
        let d = c0.root_position(last) - c0.root_position(0);
        let along = glam::DVec3::new(d.x, 0.0, d.z).normalize_or(glam::DVec3::X);
        for (k, rc) in clips.iter_mut().enumerate().skip(1) {
            let j = rc.clip.joints();
            let slot = k.div_ceil(2) as f64 * if k % 2 == 1 { -1.0 } else { 1.0 };
            let shift = along * (slot * spacing);
            for f in 0..rc.clip.frames() {
                rc.clip.local_positions[f * j] += shift;
            }
        }
    }
    let opts = RenderOptions { from: a.from, to: a.to, every: a.every, frame_numbers: a.frame_numbers };
    let n = if ext == "gif" { render_gif(&clips, &opts, &a.out)? } else { render_sheet(&clips, &opts, &a.out)? };
    let size = std::fs::metadata(&a.out).map(|m| m.len()).unwrap_or(0);
    println!("{}: {n} frames of {} clip(s), {:.0} kB", a.out.display(), clips.len(), size as f64 / 1024.0);
    Ok(())
}
