//! Keyframe completion (task `keyframes`, `zoo_runtime::keyframes`): a `keyframes` model fills
//! in every frame between an animator's keys with a [`ZooKeyframesRunner`], one character or a
//! batch per call. Both designs `zoo export` writes for `zoo train arnn` run through the same
//! functions: the ARNN's step graph (one graph call per frame for the whole batch) and the
//! in-betweening design's whole-shot graph (`--design inbetween`: one graph call per
//! character, correcting Blender's default curves through the keys).
//!
//! Keys of a character: key frames (`size_t`, strictly increasing, the first 0) and one pose of
//! `D` floats per key (the export's units: metres and radians for the lamp; for a humanoid the
//! root position, then a `w, x, y, z` quaternion per joint, in the clips' units). The completion
//! has `last key frame + 1` frames of `D` floats, frame-major; frame 0 is the first key. A model
//! with key groups (a humanoid) also takes partial keys: `G` flags per key, 1 where the key fixes
//! the group and 0 where it leaves it free.

use crate::model::model;
use crate::{
    Failure, ZooModel, ZooStatus, check_count, check_size, free_handle, guard, handle_mut, new_handle, optional_slice,
    runtime_failure, slice, slice_mut, write_out,
};
use zoo_runtime::keyframes::{KeyframeRunner, MotionKeys};

/// Scratch space for completing keys (opaque), for up to the batch size it was made for. One
/// thread at a time.
pub struct ZooKeyframesRunner {
    runner: KeyframeRunner,
    dofs: usize,
    groups: usize,
}

/// What a keyframes model expects besides `ZooModelInfo` (whose `fps` the completed
/// frames play at).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooKeyframesInfo {
    /// Values per pose `D`: a key and a completed frame are `D` floats (6 for the lamp).
    pub dofs: usize,
    /// Key groups `G` a partial key fixes or leaves free (a humanoid's group 0 is the root
    /// position, group `1 + j` joint `j`'s rotation); 0: keys are whole poses.
    pub groups: usize,
}

const INFO: &str = "zoo_keyframes_info";

/// Writes what a keyframes model expects into `*out`. Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_info(model: *const ZooModel, out: *mut ZooKeyframesInfo) -> ZooStatus {
    guard("zoo_keyframes_info", || {
        let m = unsafe { self::model(model) }?.keyframes()?;
        unsafe { write_out(out, ZooKeyframesInfo { dofs: m.dofs(), groups: m.groups() }, "out") }
    })
}

/// Creates scratch space for completing the keys of up to `max_batch` characters per call, on
/// one thread at a time, into `*out`; free it with [`zoo_keyframes_runner_free`]. Thread-safe
/// (the model is shared); the runner keeps what it needs of the model.
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_runner_new(
    model: *const ZooModel,
    max_batch: usize,
    out: *mut *mut ZooKeyframesRunner,
) -> ZooStatus {
    guard("zoo_keyframes_runner_new", || {
        let m = unsafe { self::model(model) }?.keyframes()?;
        unsafe {
            new_handle(out, || {
                check_count(max_batch).map_err(|_| {
                    (ZooStatus::InvalidArgument, "`max_batch` is 0; a runner completes at least one character".into())
                })?;
                let runner = m.runner(max_batch).map_err(runtime_failure)?;
                Ok(ZooKeyframesRunner { runner, dofs: m.dofs(), groups: m.groups() })
            })
        }
    })
}

/// Frees a runner (NULL is ignored).
///
/// # Safety
/// `runner` is NULL or a pointer from [`zoo_keyframes_runner_new`] not freed before and not in
/// use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_runner_free(runner: *mut ZooKeyframesRunner) {
    unsafe { free_handle(runner) }
}

/// Completes one character's keys into `out`: `frames` holds the key frames (strictly
/// increasing, the first 0), `poses` `frames_len * D` floats (one pose per key), `fixed` NULL
/// and 0 for whole keys or `frames_len * G` flags for partial keys (a model with key groups
/// only; the first key fixes every group), `out` `(frames[frames_len - 1] + 1) * D` floats. Keys
/// and buffers are checked before anything is written. Every key frame of `out` equals its key
/// (in the groups it fixes): the network's miss is spread over the frames before it. A humanoid
/// model's completion (key groups, a skeleton with joints named `foot`) then has its feet locked
/// between the keys, key frames unchanged, as `zoo complete` does. The runner: one thread at a
/// time.
///
/// # Safety
/// `runner` is NULL or live and used by this thread only; each buffer is NULL or holds its given
/// length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_complete(
    runner: *mut ZooKeyframesRunner,
    frames: *const usize,
    frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const f32,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> ZooStatus {
    guard("zoo_keyframes_complete", || unsafe {
        complete(runner, &[frames_len], frames, frames_len, poses, poses_len, fixed, fixed_len, out, out_len)
    })
}

/// Completes the keys of `count` characters together (at most the runner's `max_batch`; an
/// ARNN step graph runs one graph call per frame, the in-betweening design one call per
/// character): character `c` has `key_counts[c]` keys, and `frames`, `poses`, `fixed` and
/// `out` hold the characters' buffers of [`zoo_keyframes_complete`] one after the other
/// (character-major; `fixed` NULL and 0 when every key is whole). A character's frames are
/// those it gets alone. The runner: one thread at a time.
///
/// # Safety
/// `runner` is NULL or live and used by this thread only; each buffer is NULL or holds its given
/// length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_complete_batch(
    runner: *mut ZooKeyframesRunner,
    key_counts: *const usize,
    count: usize,
    frames: *const usize,
    frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const f32,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> ZooStatus {
    guard("zoo_keyframes_complete_batch", || {
        let counts = unsafe { slice(key_counts, count, "key_counts") }?;
        check_count(count)?;
        unsafe { complete(runner, counts, frames, frames_len, poses, poses_len, fixed, fixed_len, out, out_len) }
    })
}

/// The completion of [`zoo_keyframes_complete_batch`], `counts` keys per character.
///
/// # Safety
/// As [`zoo_keyframes_complete_batch`].
unsafe fn complete(
    runner: *mut ZooKeyframesRunner,
    counts: &[usize],
    frames: *const usize,
    frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const f32,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> Result<(), Failure> {
    let r = unsafe { handle_mut(runner, "runner") }?;
    let frames = unsafe { slice(frames, frames_len, "frames") }?;
    let poses = unsafe { slice(poses, poses_len, "poses") }?;
    let fixed = unsafe { optional_slice(fixed, fixed_len, "fixed") }?;
    let out = unsafe { slice_mut(out, out_len, "out") }?;
    let (d, g, n) = (r.dofs, r.groups, frames.len());
    let info = INFO;
    let keys = counts.iter().try_fold(0usize, |a, c| a.checked_add(*c));
    if keys != Some(n) {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "`key_counts` add up to {} keys but `frames` holds {n}: give every character's key frames one after the other",
                keys.map_or("more than SIZE_MAX".to_string(), |k| k.to_string())
            ),
        ));
    }
    check_size("poses", poses.len(), n * d, "floats", format_args!("{info} (`dofs` floats per key)"))?;
    if !fixed.is_empty() {
        if g == 0 {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`fixed` holds {} flags, but the model was trained on whole keys only: pass NULL and 0",
                    fixed.len()
                ),
            ));
        }
        check_size("fixed", fixed.len(), n * g, "flags", format_args!("{info} (`groups` flags per key)"))?;
    }
    let mut keys = Vec::with_capacity(counts.len());
    let (mut at, mut total) = (0, 0usize);
    for (c, &k) in counts.iter().enumerate() {
        let key = MotionKeys {
            frames: &frames[at..at + k],
            poses: &poses[at * d..(at + k) * d],
            fixed: if fixed.is_empty() { &[] } else { &fixed[at * g..(at + k) * g] },
        };
        total = key
            .frames
            .last()
            .map_or(Some(0), |f| f.checked_add(1))
            .and_then(|f| f.checked_mul(d))
            .and_then(|v| v.checked_add(total))
            .ok_or_else(|| {
                (ZooStatus::InvalidArgument, format!("character {c}: its last key frame is too large to complete"))
            })?;
        keys.push(key);
        at += k;
    }
    check_size(
        "out",
        out.len(),
        total,
        "floats",
        format_args!("each character's last key frame + 1, times `dofs` ({info})"),
    )?;
    let mut outs = Vec::with_capacity(keys.len());
    let mut rest = out;
    for k in &keys {
        let (head, tail) = rest.split_at_mut(k.len() * d);
        outs.push(head);
        rest = tail;
    }
    r.runner.complete_batch(&keys, &mut outs).map_err(runtime_failure)
}
