//! The motion pipeline around a model that generates global joint positions: the model's
//! inputs taken from clips (aligned in space), joint rotations fitted to its output, the foot
//! lock on the fitted frames, and the clips written from them. `zoo transition`,
//! `zoo decompress`, the benchmark's learned methods and an engine share this one
//! implementation; nothing here reads files.
//!
//! Positions are `f32`, frame-major, `frames * joints * 3` (Y up, clip units), as in
//! [`crate::features`]; rotations are local joint rotations, `frames * joints`.

use crate::fit::fit_rotations;
use crate::footlock::FootLock;
use glam::{DQuat, DVec3};
use zoo_motion::Clip;
use zoo_motion::facing::{ground_forward, heading_angle};
use zoo_motion::fk::forward_kinematics_frame;
use zoo_motion::quat::slerp;
use zoo_motion::skeleton::Skeleton;

/// Context frames a transition model reads before the transition (RTN sec. 5: 10 frames).
pub const CONTEXT_FRAMES: usize = 10;

/// Why clips and frames cannot feed a transition or a keyframe rebuild.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PipelineError {
    /// The source frame has too few frames before it.
    #[error(
        "source frame {frame}: needs {CONTEXT_FRAMES} context frames before it in a clip of {frames} frames ({})",
        if *frames >= CONTEXT_FRAMES { format!("pick a frame in {CONTEXT_FRAMES}..={frames}") } else { format!("the clip is shorter than that: give a clip of at least {CONTEXT_FRAMES} frames") }
    )]
    SourceFrame {
        /// The frame asked for.
        frame: usize,
        /// Frames of the source clip.
        frames: usize,
    },
    /// The target frame has no frame after it.
    #[error(
        "target frame {frame}: needs the frame after it in a clip of {frames} frames (pick a frame below {})",
        frames.saturating_sub(1)
    )]
    TargetFrame {
        /// The frame asked for.
        frame: usize,
        /// Frames of the target clip.
        frames: usize,
    },
    /// A transition of zero frames.
    #[error("a transition needs at least 1 frame")]
    NoFrames,
    /// The two clips do not share a skeleton.
    #[error("the clips use different skeletons ({0}); use clips of one skeleton")]
    Skeletons(String),
    /// A clip too short for the context frames and one keyframe.
    #[error(
        "{frames} frames is too short for {CONTEXT_FRAMES} context frames and one keyframe every {interval} (use a longer clip or a shorter interval)"
    )]
    TooShort {
        /// Frames of the clip.
        frames: usize,
        /// Frames between keyframes.
        interval: usize,
    },
}

/// Global joint positions (`f32`, `frames * joints * 3`) of clip frames `from..to`.
pub fn clip_positions_f32(clip: &Clip, from: usize, to: usize) -> Vec<f32> {
    let (_, gp) = clip.slice(from, to).global();
    gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()
}

/// Appends to `out` the global positions (`f32`, joint-major xyz per frame) of frames of
/// `skeleton` given local rotations (`frames * joints`), root positions (one per frame) and
/// the local `offsets` of every joint (the root's is ignored).
pub fn skeleton_positions_f32(
    skeleton: &Skeleton,
    offsets: &[DVec3],
    rot: &[DQuat],
    roots: &[DVec3],
    out: &mut Vec<f32>,
) {
    let j = skeleton.len();
    let mut lp = offsets.to_vec();
    let (mut gr, mut gp) = (vec![DQuat::IDENTITY; j], vec![DVec3::ZERO; j]);
    for (f, root) in roots.iter().enumerate() {
        lp[0] = *root;
        forward_kinematics_frame(&skeleton.parents, &rot[f * j..(f + 1) * j], &lp, &mut gr, &mut gp);
        out.extend(gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]));
    }
}

/// Local rotations and root positions fitted to generated global positions
/// (`frames * joints * 3`), twist taken from `reference` (local rotations, frames x joints);
/// `offsets` are the local joint offsets (the root's is ignored). See [`crate::fit`].
pub fn fit_frames(
    skeleton: &Skeleton,
    offsets: &[DVec3],
    positions: &[f32],
    reference: &[DQuat],
) -> (Vec<DQuat>, Vec<DVec3>) {
    let j = skeleton.len();
    let frames = positions.len() / (3 * j);
    let mut rot = vec![DQuat::IDENTITY; frames * j];
    let mut root = Vec::with_capacity(frames);
    for f in 0..frames {
        let pos: Vec<DVec3> = positions[f * 3 * j..(f + 1) * 3 * j]
            .chunks_exact(3)
            .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .collect();
        fit_rotations(&skeleton.parents, offsets, &pos, &reference[f * j..(f + 1) * j], &mut rot[f * j..(f + 1) * j]);
        root.push(pos[0]);
    }
    (rot, root)
}

/// Foot-locks a fitted transition ([`crate::footlock`] with the skeleton's defaults): the
/// fitted skeleton's own joint positions, after the last context frame `prev` and followed by
/// the `target` frame (global positions, `3 * joints` each), are locked and fitted again.
/// Locking the skeleton's positions (exact bone lengths) rather than the network's makes the
/// refit reproduce the locked feet exactly. A skeleton without joints named `foot` is returned
/// unchanged.
pub fn foot_lock_fitted(
    skeleton: &Skeleton,
    offsets: &[DVec3],
    fitted: (Vec<DQuat>, Vec<DVec3>),
    prev: &[f32],
    target: &[f32],
    reference: &[DQuat],
) -> (Vec<DQuat>, Vec<DVec3>) {
    let Some(lock) = FootLock::from_skeleton(&skeleton.names, &skeleton.parents) else {
        return fitted;
    };
    let (rot, root) = fitted;
    let mut positions = Vec::with_capacity((root.len() + 1) * target.len());
    skeleton_positions_f32(skeleton, offsets, &rot, &root, &mut positions);
    let n = positions.len();
    positions.extend_from_slice(target);
    lock.apply(prev, &mut positions);
    fit_frames(skeleton, offsets, &positions[..n], reference)
}

/// Rotates clip `clip` about +Y and moves it on the ground so that its root at `frame` sits at
/// `position` (x, z) facing `heading` (radians, [`heading_angle`] of the root's
/// `forward_axis`); heights stay as they are.
pub fn align_on_ground(clip: &mut Clip, frame: usize, position: DVec3, forward_axis: DVec3, heading: f64) {
    let j = clip.joints();
    let r = clip.local_rotations[frame * j];
    let current = heading_angle(ground_forward(r, forward_axis));
    let yaw = DQuat::from_rotation_y(heading - current);
    let pivot = clip.local_positions[frame * j];
    for f in 0..clip.frames() {
        let p = clip.local_positions[f * j] - DVec3::new(pivot.x, 0.0, pivot.z);
        clip.local_positions[f * j] = yaw * p + DVec3::new(position.x, 0.0, position.z);
        clip.local_rotations[f * j] = yaw * clip.local_rotations[f * j];
    }
}

/// Rest offsets of a clip's joints (local positions of frame 0, the root's set to zero).
pub fn rest_offsets(clip: &Clip) -> Vec<DVec3> {
    clip.positions_at(0).iter().enumerate().map(|(i, p)| if i == 0 { DVec3::ZERO } else { *p }).collect()
}

/// What a position-based transition model is given: [`CONTEXT_FRAMES`] context frames, the
/// target frame and the one after it (global positions, `3 * joints` per frame).
#[derive(Clone, Debug, PartialEq)]
pub struct TransitionInputs {
    /// The context frames before the transition.
    pub past: Vec<f32>,
    /// The target frame.
    pub target: Vec<f32>,
    /// The frame after the target.
    pub next: Vec<f32>,
}

/// Prepares a transition of `frames` frames from clip `from` (after the context frames
/// before `from_frame`) to clip `to` at `to_frame`: `to` is aligned on the ground
/// ([`align_on_ground`], root forward axis +Y as in bandai2) where `from`'s root would be after
/// the transition at its last speed, facing `from`'s way. Returns the model's inputs.
pub fn transition_inputs(
    from: &Clip,
    from_frame: usize,
    to: &mut Clip,
    to_frame: usize,
    frames: usize,
) -> Result<TransitionInputs, PipelineError> {
    check_transition(from, from_frame, to, to_frame, frames)?;
    let j = from.joints();
    let last = from.root_position(from_frame - 1);
    let vel = last - from.root_position(from_frame - 2);
    let dest = last + DVec3::new(vel.x, 0.0, vel.z) * (frames + 1) as f64;
    let heading = heading_angle(ground_forward(from.local_rotations[(from_frame - 1) * j], DVec3::Y));
    align_on_ground(to, to_frame, dest, DVec3::Y, heading);
    Ok(inputs_of(from, from_frame, to, to_frame))
}

/// [`transition_inputs`] with `to` left where it is: both clips already share one world frame
/// (the transition of a terrain-aware model, whose target stands on the terrain of that frame;
/// moving it would lift it off its ground or sink it into it).
pub fn transition_inputs_in_place(
    from: &Clip,
    from_frame: usize,
    to: &Clip,
    to_frame: usize,
    frames: usize,
) -> Result<TransitionInputs, PipelineError> {
    check_transition(from, from_frame, to, to_frame, frames)?;
    Ok(inputs_of(from, from_frame, to, to_frame))
}

/// Refuses clips and frames a transition cannot be made from.
pub fn check_transition(
    from: &Clip,
    from_frame: usize,
    to: &Clip,
    to_frame: usize,
    frames: usize,
) -> Result<(), PipelineError> {
    if let Some(why) = from.skeleton.topology_difference(&to.skeleton) {
        return Err(PipelineError::Skeletons(why));
    }
    if from_frame < CONTEXT_FRAMES || from_frame > from.frames() {
        return Err(PipelineError::SourceFrame { frame: from_frame, frames: from.frames() });
    }
    if to_frame + 1 >= to.frames() {
        return Err(PipelineError::TargetFrame { frame: to_frame, frames: to.frames() });
    }
    if frames == 0 {
        return Err(PipelineError::NoFrames);
    }
    Ok(())
}

/// The model's inputs: the context frames before `from_frame`, `to`'s target frame and the next.
fn inputs_of(from: &Clip, from_frame: usize, to: &Clip, to_frame: usize) -> TransitionInputs {
    let past = clip_positions_f32(from, from_frame - CONTEXT_FRAMES, from_frame);
    let tgt = clip_positions_f32(to, to_frame, to_frame + 2);
    let d = 3 * from.joints();
    TransitionInputs { past, target: tgt[..d].to_vec(), next: tgt[d..].to_vec() }
}

/// The clip `from` up to `from_frame`, the generated transition, then `to` (as aligned by
/// [`transition_inputs`]) from `to_frame` on. `generated` holds the model's output,
/// `(frames + 1) * 3 * joints` values (the transition and its predicted target frame); joint
/// rotations are fitted to it ([`fit_frames`]) with twist from the slerp between the last
/// context rotations and the target's; `foot_lock` locks the fitted feet ([`foot_lock_fitted`]).
pub fn splice_transition(
    from: &Clip,
    from_frame: usize,
    to: &Clip,
    to_frame: usize,
    inputs: &TransitionInputs,
    generated: &[f32],
    foot_lock: bool,
) -> Clip {
    let j = from.joints();
    let d = 3 * j;
    let frames = generated.len() / d - 1;
    let (q0, q1) = (from.rotations_at(from_frame - 1), to.rotations_at(to_frame));
    let reference: Vec<DQuat> = (1..=frames)
        .flat_map(|k| {
            let w = k as f64 / (frames + 1) as f64;
            (0..j).map(move |i| slerp(q0[i], q1[i], w))
        })
        .collect();
    let offsets = rest_offsets(from);
    let mut fitted = fit_frames(&from.skeleton, &offsets, &generated[..frames * d], &reference);
    if foot_lock {
        let prev = &inputs.past[inputs.past.len() - d..];
        fitted = foot_lock_fitted(
            &from.skeleton,
            &offsets,
            fitted,
            prev,
            &generated[frames * d..(frames + 1) * d],
            &reference,
        );
    }
    let (rot, root) = fitted;
    let mut out = from.slice(0, from_frame);
    for f in 0..frames {
        out.local_rotations.extend_from_slice(&rot[f * j..(f + 1) * j]);
        out.local_positions.push(root[f]);
        out.local_positions.extend_from_slice(&offsets[1..]);
    }
    out.local_rotations.extend_from_slice(&to.local_rotations[to_frame * j..]);
    out.local_positions.extend_from_slice(&to.local_positions[to_frame * j..]);
    out.remove_sign_flips();
    out
}

/// What a keyframe rebuild (temporal super-resolution, RTN sec. 7.4) is given: the first
/// [`CONTEXT_FRAMES`] frames, then per keyframe the keyframe and the frame after it.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyframeInputs {
    /// Global positions of the context frames.
    pub context: Vec<f32>,
    /// Global positions of each keyframe and the frame after it (`2 * 3 * joints` per key).
    pub keys: Vec<f32>,
    /// Number of keyframes.
    pub key_count: usize,
}

/// The keyframes of `clip`, one every `interval` frames after the context frames.
pub fn keyframe_inputs(clip: &Clip, interval: usize) -> Result<KeyframeInputs, PipelineError> {
    let keys = (clip.frames().saturating_sub(CONTEXT_FRAMES + 1)) / interval.max(1);
    if keys == 0 || interval == 0 {
        return Err(PipelineError::TooShort { frames: clip.frames(), interval });
    }
    let d = 3 * clip.joints();
    let context = clip_positions_f32(clip, 0, CONTEXT_FRAMES);
    let mut key_pos = Vec::with_capacity(keys * 2 * d);
    for k in 1..=keys {
        let f = CONTEXT_FRAMES - 1 + k * interval;
        key_pos.extend(clip_positions_f32(clip, f, f + 2));
    }
    Ok(KeyframeInputs { context, keys: key_pos, key_count: keys })
}

/// The clip rebuilt from generated global positions (`frames * 3 * joints`, from frame 0):
/// rotations fitted with twist from the local rotations of `clip` interpolated between
/// consecutive keyframes (`interval` apart), on `clip`'s skeleton.
pub fn rebuild_from_keyframes(clip: &Clip, interval: usize, generated: &[f32]) -> Clip {
    let j = clip.joints();
    let d = 3 * j;
    let frames = generated.len() / d;
    let mut reference = Vec::with_capacity(frames * j);
    for f in 0..frames {
        if f < CONTEXT_FRAMES {
            reference.extend_from_slice(clip.rotations_at(f));
            continue;
        }
        let k = (f - CONTEXT_FRAMES) / interval;
        let a0 = CONTEXT_FRAMES - 1 + k * interval;
        let a1 = a0 + interval;
        let w = (f - a0) as f64 / interval as f64;
        let (q0, q1) = (clip.rotations_at(a0), clip.rotations_at(a1.min(clip.frames() - 1)));
        reference.extend((0..j).map(|i| slerp(q0[i], q1[i], w)));
    }
    let offsets = rest_offsets(clip);
    let (rot, root) = fit_frames(&clip.skeleton, &offsets, generated, &reference);
    let mut out = clip.slice(0, 0);
    for f in 0..frames {
        out.local_rotations.extend_from_slice(&rot[f * j..(f + 1) * j]);
        out.local_positions.push(root[f]);
        out.local_positions.extend_from_slice(&offsets[1..]);
    }
    out.remove_sign_flips();
    out
}

/// Completes `rebuilt` (the first frames of `clip`, rebuilt from keyframes) to `clip`'s length:
/// the frames after the last keyframe, which no keyframe pair spans, are in-betweened from the
/// rebuilt last frame to `clip`'s last frame (kept as a final key, as a compressed stream keeps
/// its last pose): rotations slerped, the root lerped. Nothing is dropped; returns how many
/// frames were filled this way.
pub fn fill_tail(rebuilt: &mut Clip, clip: &Clip) -> usize {
    let (have, want, j) = (rebuilt.frames(), clip.frames(), clip.joints());
    if have == 0 || have >= want || rebuilt.joints() != j {
        return 0;
    }
    let (q0, p0) = (rebuilt.rotations_at(have - 1).to_vec(), rebuilt.positions_at(have - 1).to_vec());
    let (q1, p1) = (clip.rotations_at(want - 1), clip.positions_at(want - 1));
    let span = (want - have) as f64;
    for f in have..want {
        let w = (f + 1 - have) as f64 / span;
        rebuilt.local_rotations.extend((0..j).map(|i| slerp(q0[i], q1[i], w)));
        rebuilt.local_positions.push(p0[0].lerp(p1[0], w));
        rebuilt.local_positions.extend_from_slice(&p0[1..]);
    }
    rebuilt.remove_sign_flips();
    want - have
}

/// Mean distance (clip units) between the joints of `clip`'s first frames and global
/// positions `positions` (`frames * 3 * joints`, from frame 0).
pub fn mean_position_error(clip: &Clip, positions: &[f32]) -> f64 {
    let j = clip.joints();
    let frames = positions.len() / (3 * j);
    let orig = clip_positions_f32(clip, 0, frames);
    orig.chunks_exact(3)
        .zip(positions.chunks_exact(3))
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt() as f64)
        .sum::<f64>()
        / (frames * j) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::{EulerOrder, JointChannels};

    fn chain_clip(frames: usize, shift: f64) -> Clip {
        let skeleton = Skeleton {
            names: ["Hips", "Spine", "Leg", "Foot_L"].iter().map(|s| s.to_string()).collect(),
            parents: vec![None, Some(0), Some(0), Some(2)],
            offsets: vec![
                DVec3::ZERO,
                DVec3::new(0.0, 10.0, 0.0),
                DVec3::new(0.0, -40.0, 0.0),
                DVec3::new(0.0, -40.0, 0.0),
            ],
            end_sites: vec![None; 4],
            channels: vec![JointChannels { position: true, order: EulerOrder::Zxy }; 4],
        };
        let mut local_rotations = Vec::new();
        let mut local_positions = Vec::new();
        for f in 0..frames {
            let t = f as f64 / 30.0;
            local_rotations
                .push(DQuat::from_rotation_y(0.2 * t) * DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2));
            local_rotations.push(DQuat::from_rotation_x(0.1 * t.sin()));
            local_rotations.push(DQuat::from_rotation_x(0.4 * (5.0 * t).sin()));
            local_rotations.push(DQuat::IDENTITY);
            local_positions.push(DVec3::new(100.0 * t + shift, 85.0, 0.0));
            local_positions.extend_from_slice(&skeleton.offsets[1..]);
        }
        Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations, local_positions }
    }

    #[test]
    fn fitting_a_clips_own_positions_gives_its_positions_back() {
        let clip = chain_clip(5, 0.0);
        let p = clip_positions_f32(&clip, 0, 5);
        let offsets = rest_offsets(&clip);
        let (rot, root) = fit_frames(&clip.skeleton, &offsets, &p, &clip.local_rotations);
        let mut back = Vec::new();
        skeleton_positions_f32(&clip.skeleton, &offsets, &rot, &root, &mut back);
        assert_eq!(back.len(), p.len());
        assert!(back.iter().zip(&p).all(|(a, b)| (a - b).abs() < 1e-3), "{back:?} vs {p:?}");
    }

    #[test]
    fn transition_inputs_refuse_bad_frames() {
        let a = chain_clip(40, 0.0);
        let mut b = chain_clip(40, 500.0);
        let e = transition_inputs(&a, 5, &mut b, 10, 20).unwrap_err();
        assert_eq!(e, PipelineError::SourceFrame { frame: 5, frames: 40 });
        assert!(e.to_string().contains("needs 10 context frames"), "{e}");
        let e = transition_inputs(&a, 20, &mut b, 39, 20).unwrap_err();
        assert!(e.to_string().contains("needs the frame after it"), "{e}");
        assert_eq!(transition_inputs(&a, 20, &mut b, 10, 0).unwrap_err(), PipelineError::NoFrames);
        let mut short = chain_clip(40, 0.0);
        short.skeleton.parents[3] = Some(0);
        assert!(matches!(transition_inputs(&a, 20, &mut short, 10, 5), Err(PipelineError::Skeletons(_))));
    }

    #[test]
    fn in_place_inputs_leave_the_target_where_it_is() {
        let a = chain_clip(40, 0.0);
        let b = chain_clip(40, 500.0);
        let inputs = transition_inputs_in_place(&a, 20, &b, 10, 3).unwrap();
        assert_eq!(inputs.target, clip_positions_f32(&b, 10, 11));
        assert_eq!(inputs.next, clip_positions_f32(&b, 11, 12));
        assert_eq!(inputs.past, clip_positions_f32(&a, 10, 20));
        assert_eq!(transition_inputs_in_place(&a, 20, &b, 10, 0).unwrap_err(), PipelineError::NoFrames);
    }

    #[test]
    fn a_spliced_transition_keeps_both_clips_around_it() {
        let a = chain_clip(40, 0.0);
        let mut b = chain_clip(40, 500.0);
        let inputs = transition_inputs(&a, 20, &mut b, 10, 3).unwrap();
        assert_eq!(inputs.past.len(), CONTEXT_FRAMES * 12);
        // B's target root lands where A's root gets at its last speed: 4 frames on.
        let step = a.root_position(19) - a.root_position(18);
        let want = a.root_position(19) + step * 4.0;
        assert!((inputs.target[0] as f64 - want.x).abs() < 1e-3 && (inputs.target[2] as f64 - want.z).abs() < 1e-3);
        let generated: Vec<f32> = (1..=4)
            .flat_map(|k| {
                let w = k as f32 / 4.0;
                let last = &inputs.past[inputs.past.len() - 12..];
                last.iter().zip(&inputs.target).map(move |(p, t)| p + w * (t - p)).collect::<Vec<_>>()
            })
            .collect();
        let out = splice_transition(&a, 20, &b, 10, &inputs, &generated, false);
        assert_eq!(out.frames(), 20 + 3 + 30);
        assert_eq!(out.rotations_at(5), a.rotations_at(5));
        assert!((out.root_position(23) - b.root_position(10)).length() < 1e-9);
    }

    #[test]
    fn keyframes_refuse_a_short_clip_and_rebuild_a_long_one() {
        let clip = chain_clip(15, 0.0);
        assert_eq!(keyframe_inputs(&clip, 30).unwrap_err(), PipelineError::TooShort { frames: 15, interval: 30 });
        let clip = chain_clip(41, 0.0);
        let k = keyframe_inputs(&clip, 10).unwrap();
        assert_eq!(k.key_count, 3);
        assert_eq!(k.keys.len(), 3 * 2 * 12);
        let y = clip_positions_f32(&clip, 0, 39);
        let rebuilt = rebuild_from_keyframes(&clip, 10, &y);
        assert_eq!(rebuilt.frames(), 39);
        assert!(mean_position_error(&clip, &y) < 1e-9);
        assert!(mean_position_error(&rebuilt, &y) < 1e-3);
    }
}
