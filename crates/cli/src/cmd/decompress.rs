//! `zoo decompress`: temporal super-resolution (RTN sec. 7.4), rebuilding a clip from its
//! first 10 frames and one keyframe per interval by chaining RTN transitions.

use crate::cmd::transition::read_clip;
use crate::methods::{clip_positions_f32, fit_frames};
use anyhow::{Context, bail};
use clap::Args;
use glam::DVec3;
use std::path::PathBuf;
use zoo_data::bvh;
use zoo_motion::quat::slerp;

/// Arguments of `zoo decompress`.
#[derive(Args)]
pub struct DecompressArgs {
    /// Run folder of `zoo train rtn`.
    #[arg(long)]
    pub model: PathBuf,
    /// Clip to compress and rebuild.
    pub input: PathBuf,
    /// Frames between keyframes (default: one keyframe per second).
    #[arg(long)]
    pub interval: Option<usize>,
    /// Output BVH of the rebuilt clip.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `zoo decompress`.
pub fn run(a: DecompressArgs) -> anyhow::Result<()> {
    const PAST: usize = 10;
    let clip = read_clip(&a.input)?;
    let interval = a.interval.unwrap_or_else(|| clip.fps().round() as usize).max(1);
    let j = clip.joints();
    let keys = (clip.frames().saturating_sub(PAST + 1)) / interval;
    if keys == 0 {
        bail!(
            "{}: {} frames is too short for 10 context frames and one keyframe every {interval}",
            a.input.display(),
            clip.frames()
        );
    }
    let (model, stats) = zoo_rtn::checkpoint::load(&a.model, &candle_core::Device::Cpu)
        .with_context(|| format!("loading the RTN in {}", a.model.display()))?;
    if model.config().joints != j {
        bail!("the model was trained on {} joints, {} has {j}", model.config().joints, a.input.display());
    }
    let d = 3 * j;
    let context = clip_positions_f32(&clip, 0, PAST);
    let mut key_pos = Vec::with_capacity(keys * 2 * d);
    for k in 1..=keys {
        let f = PAST - 1 + k * interval;
        key_pos.extend(clip_positions_f32(&clip, f, f + 2));
    }
    let y = model.super_resolve(&stats, &context, &key_pos, interval).context("rebuilding the clip")?;
    let frames = y.len() / d;
    // Twist reference: local rotations interpolated between consecutive keyframes.
    let mut reference = Vec::with_capacity(frames * j);
    for f in 0..frames {
        if f < PAST {
            reference.extend_from_slice(clip.rotations_at(f));
            continue;
        }
        let k = (f - PAST) / interval;
        let a0 = PAST - 1 + k * interval;
        let a1 = a0 + interval;
        let w = (f - a0) as f64 / interval as f64;
        let (q0, q1) = (clip.rotations_at(a0), clip.rotations_at(a1.min(clip.frames() - 1)));
        reference.extend((0..j).map(|i| slerp(q0[i], q1[i], w)));
    }
    let offsets: Vec<DVec3> =
        clip.positions_at(0).iter().enumerate().map(|(i, p)| if i == 0 { DVec3::ZERO } else { *p }).collect();
    let (rot, root) = fit_frames(&clip.skeleton, &offsets, &y, &reference);
    let mut out = clip.slice(0, 0);
    for f in 0..frames {
        out.local_rotations.extend_from_slice(&rot[f * j..(f + 1) * j]);
        out.local_positions.push(root[f]);
        out.local_positions.extend_from_slice(&offsets[1..]);
    }
    out.remove_sign_flips();
    bvh::write_file(&out, &a.out).with_context(|| format!("writing {}", a.out.display()))?;
    // Mean joint position error of the rebuilt frames against the original.
    let orig = clip_positions_f32(&clip, 0, frames);
    let err: f64 = orig
        .chunks_exact(3)
        .zip(y.chunks_exact(3))
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt() as f64)
        .sum::<f64>()
        / (frames * j) as f64;
    println!(
        "rebuilt {frames} frames of {} from {PAST} context frames and {keys} keyframes (every {interval}); \
         mean joint position error {err:.2} (clip units); wrote {}",
        a.input.display(),
        a.out.display()
    );
    Ok(())
}
