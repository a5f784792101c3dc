//! `zoo transition`: generate a transition between two clips with a trained RTN.

use crate::methods::{clip_positions_f32, fit_frames, foot_lock_fitted};
use anyhow::{Context, bail};
use clap::Args;
use glam::{DQuat, DVec3};
use std::path::{Path, PathBuf};
use zoo_data::bvh::{self, ReadOptions};
use zoo_motion::Clip;
use zoo_motion::facing::{ground_forward, heading_angle};
use zoo_motion::quat::slerp;

/// Context frames the RTN reads before the transition.
const PAST: usize = 10;

/// Arguments of `zoo transition`.
#[derive(Args)]
pub struct TransitionArgs {
    /// Run folder of `zoo train rtn`.
    #[arg(long)]
    pub model: PathBuf,
    /// Source clip and frame, `A.bvh:FRAME`: the transition starts after the 10 frames before FRAME.
    #[arg(long)]
    pub from: String,
    /// Target clip and frame, `B.bvh:FRAME`: the transition ends in this pose.
    #[arg(long)]
    pub to: String,
    /// Transition length in frames.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Output BVH: A up to FRAME, the transition, then B from its FRAME on, aligned in space.
    #[arg(long)]
    pub out: PathBuf,
    /// Foot-lock the transition (`zoo_motion::footlock`: planted feet slide less, dragged feet
    /// are lifted); legs are found by joints named `foot`.
    #[arg(long)]
    pub foot_lock: bool,
}

/// Parses `PATH:FRAME`.
pub fn clip_and_frame(s: &str) -> anyhow::Result<(PathBuf, usize)> {
    let (path, frame) =
        s.rsplit_once(':').with_context(|| format!("`{s}`: expected CLIP.bvh:FRAME, e.g. walk.bvh:120"))?;
    let frame = frame.parse().with_context(|| format!("`{s}`: `{frame}` is not a frame number"))?;
    Ok((PathBuf::from(path), frame))
}

/// Reads a clip for the models: dummy root dropped, sign flips removed.
pub fn read_clip(path: &Path) -> anyhow::Result<Clip> {
    let mut clip = bvh::read_file(path, &ReadOptions { drop_dummy_root: true })?;
    clip.remove_sign_flips();
    Ok(clip)
}

/// Rotates clip `b` about +Y and moves it on the ground so that its root at `frame` sits at
/// `position` (x, z) facing `heading` (radians); heights stay as they are.
fn align(b: &mut Clip, frame: usize, position: DVec3, forward_axis: DVec3, heading: f64) {
    let j = b.joints();
    let r = b.local_rotations[frame * j];
    let current = heading_angle(ground_forward(r, forward_axis));
    let yaw = DQuat::from_rotation_y(heading - current);
    let pivot = b.local_positions[frame * j];
    for f in 0..b.frames() {
        let p = b.local_positions[f * j] - DVec3::new(pivot.x, 0.0, pivot.z);
        b.local_positions[f * j] = yaw * p + DVec3::new(position.x, 0.0, position.z);
        b.local_rotations[f * j] = yaw * b.local_rotations[f * j];
    }
}

/// Runs `zoo transition`.
pub fn run(a: TransitionArgs) -> anyhow::Result<()> {
    let (pa, fa) = clip_and_frame(&a.from)?;
    let (pb, fb) = clip_and_frame(&a.to)?;
    let ca = read_clip(&pa)?;
    let mut cb = read_clip(&pb)?;
    if let Some(why) = ca.skeleton.topology_difference(&cb.skeleton) {
        bail!("{} and {} use different skeletons ({why})", pa.display(), pb.display());
    }
    if fa < PAST || fa > ca.frames() {
        bail!("--from frame {fa}: needs {PAST} frames before it in {} ({} frames)", pa.display(), ca.frames());
    }
    if fb + 1 >= cb.frames() {
        bail!("--to frame {fb}: needs the frame after it in {} ({} frames)", pb.display(), cb.frames());
    }
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    let (model, stats) = zoo_rtn::checkpoint::load(&a.model, &candle_core::Device::Cpu)
        .with_context(|| format!("loading the RTN in {}", a.model.display()))?;
    if model.config().joints != ca.joints() {
        bail!(
            "the model in {} was trained on {} joints, {} has {}",
            a.model.display(),
            model.config().joints,
            pa.display(),
            ca.joints()
        );
    }
    let j = ca.joints();
    // Place B where A's root would be after the transition at its last speed, facing A's way.
    let last = ca.root_position(fa - 1);
    let vel = last - ca.root_position(fa - 2);
    let dest = last + DVec3::new(vel.x, 0.0, vel.z) * (a.frames + 1) as f64;
    let heading = heading_angle(ground_forward(ca.local_rotations[(fa - 1) * j], DVec3::Y));
    align(&mut cb, fb, dest, DVec3::Y, heading);

    let past = clip_positions_f32(&ca, fa - PAST, fa);
    let tgt = clip_positions_f32(&cb, fb, fb + 2);
    let d = 3 * j;
    let y = model
        .transition(&stats, &past, &tgt[..d], &tgt[d..], a.frames, None)
        .with_context(|| "generating the transition")?;
    let generated = &y[..a.frames * d];
    let (q0, q1) = (ca.rotations_at(fa - 1), cb.rotations_at(fb));
    let reference: Vec<DQuat> = (1..=a.frames)
        .flat_map(|k| {
            let w = k as f64 / (a.frames + 1) as f64;
            (0..j).map(move |i| slerp(q0[i], q1[i], w))
        })
        .collect();
    let offsets: Vec<DVec3> =
        ca.positions_at(0).iter().enumerate().map(|(i, p)| if i == 0 { DVec3::ZERO } else { *p }).collect();
    let mut fitted = fit_frames(&ca.skeleton, &offsets, generated, &reference);
    if a.foot_lock {
        let prev = &past[past.len() - d..];
        fitted =
            foot_lock_fitted(&ca.skeleton, &offsets, fitted, prev, &y[a.frames * d..(a.frames + 1) * d], &reference);
    }
    let (rot, root) = fitted;

    let mut out = ca.slice(0, fa);
    for f in 0..a.frames {
        out.local_rotations.extend_from_slice(&rot[f * j..(f + 1) * j]);
        out.local_positions.push(root[f]);
        out.local_positions.extend_from_slice(&offsets[1..]);
    }
    out.local_rotations.extend_from_slice(&cb.local_rotations[fb * j..]);
    out.local_positions.extend_from_slice(&cb.local_positions[fb * j..]);
    out.remove_sign_flips();
    bvh::write_file(&out, &a.out).with_context(|| format!("writing {}", a.out.display()))?;
    println!(
        "wrote {}: {} frames of {}, {} generated, {} of {} (transition frames {}..{})",
        a.out.display(),
        fa,
        pa.display(),
        a.frames,
        cb.frames() - fb,
        pb.display(),
        fa,
        fa + a.frames
    );
    Ok(())
}
