//! Keyframe completion (task `keyframes`, `zoo_runtime::keyframes`): a `keyframes` model fills
//! in every frame between an animator's keys with a `ZooKeyframesRunner`, one character or a
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
    Failure, ZOO_MAX_FRAMES, ZooModel, ZooStatus, check_count, check_size, free_handle, guard, handle_mut, new_handle,
    optional_slice, runtime_failure, slice, slice_mut, write_out,
};
use zoo_runtime::keyframes::{KeyframeRunner, MotionKeys};

/// Scratch space for completing keys (opaque), for up to the batch size it was made for. One
/// thread at a time.
pub struct ZooKeyframesRunner {
    runner: KeyframeRunner,
    frame_values: usize,
    groups: usize,
    /// The `fixed` flags as the runtime takes them (1.0 or 0.0), grown to the largest call.
    fixed: Vec<f32>,
}

/// What a keyframes model expects besides `ZooModelInfo` (whose `fps` the completed
/// frames play at).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooKeyframesInfo {
    /// Values per pose `D`: a key and a completed frame are `D` floats (6 for the lamp).
    pub frame_values: usize,
    /// Key groups `G` a partial key fixes or leaves free (a humanoid's group 0 is the root
    /// position, group `1 + j` joint `j`'s rotation); 0: keys are whole poses.
    pub groups: usize,
}

const INFO: &str = "zoo_keyframes_info";

/// Writes what a keyframes model expects into `*out`. Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_info(model: *const ZooModel, out: *mut ZooKeyframesInfo) -> ZooStatus {
    guard("zoo_keyframes_info", || {
        let m = unsafe { self::model(model) }?.keyframes()?;
        unsafe { write_out(out, ZooKeyframesInfo { frame_values: m.dofs(), groups: m.groups() }, "out") }
    })
}

/// Creates scratch space for completing the keys of up to `max_batch` characters per call, on
/// one thread at a time, into `*out`; free it with `zoo_keyframes_runner_free`. Thread-safe
/// (the model is shared); the runner keeps what it needs of the model.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
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
                check_count("max_batch", max_batch)?;
                let runner = m.runner(max_batch).map_err(runtime_failure)?;
                Ok(ZooKeyframesRunner { runner, frame_values: m.dofs(), groups: m.groups(), fixed: Vec::new() })
            })
        }
    })
}

/// Frees a runner (NULL is ignored).
///
/// Safety: `runner` is NULL or a pointer from `zoo_keyframes_runner_new` not freed before and not in
/// use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_runner_free(runner: *mut ZooKeyframesRunner) {
    unsafe { free_handle(runner) }
}

/// Completes one character's keys into `out`: `key_frames` holds the key frames (strictly
/// increasing, the first 0, below `ZOO_MAX_FRAMES`), `poses` `key_frames_len * D` floats (one
/// pose per key; `D` is `ZooKeyframesInfo`'s `frame_values`), `fixed` NULL
/// and 0 for whole keys or `key_frames_len * G` flags (`uint8_t`, 1 or 0) for partial keys (a model with key groups
/// only; the first key fixes every group), `out` `(key_frames[key_frames_len - 1] + 1) * D` floats. Keys
/// and buffers are checked before anything is written. Every key frame of `out` equals its key
/// (in the groups it fixes): the network's miss is spread over the frames before it. A humanoid
/// model's completion (key groups, a skeleton with joints named `foot`) then has its feet locked
/// between the keys, key frames unchanged, as `zoo complete` does. The runner: one thread at a
/// time.
///
/// Safety: `runner` is NULL or live and used by this thread only; each buffer is NULL or holds its given
/// length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_complete(
    runner: *mut ZooKeyframesRunner,
    key_frames: *const usize,
    key_frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const u8,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> ZooStatus {
    guard("zoo_keyframes_complete", || unsafe {
        complete(
            runner,
            &[key_frames_len],
            key_frames,
            key_frames_len,
            poses,
            poses_len,
            fixed,
            fixed_len,
            out,
            out_len,
        )
    })
}

/// Completes the keys of `count` characters together (at most the runner's `max_batch`; an
/// ARNN step graph runs one graph call per frame, the in-betweening design one call per
/// character): character `c` has `key_counts[c]` keys, and `key_frames`, `poses`, `fixed` and
/// `out` hold the characters' buffers of `zoo_keyframes_complete` one after the other
/// (character-major; `fixed` NULL and 0 when every key is whole). A character's frames are
/// those it gets alone. The runner: one thread at a time.
///
/// Safety: `runner` is NULL or live and used by this thread only; each buffer is NULL or holds its given
/// length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_keyframes_complete_batch(
    runner: *mut ZooKeyframesRunner,
    key_counts: *const usize,
    count: usize,
    key_frames: *const usize,
    key_frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const u8,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> ZooStatus {
    guard("zoo_keyframes_complete_batch", || {
        let counts = unsafe { slice(key_counts, count, "key_counts") }?;
        check_count("count", count)?;
        unsafe {
            complete(runner, counts, key_frames, key_frames_len, poses, poses_len, fixed, fixed_len, out, out_len)
        }
    })
}

/// The completion of `zoo_keyframes_complete_batch`, `counts` keys per character.
///
/// Safety: As `zoo_keyframes_complete_batch`.
unsafe fn complete(
    runner: *mut ZooKeyframesRunner,
    counts: &[usize],
    key_frames: *const usize,
    key_frames_len: usize,
    poses: *const f32,
    poses_len: usize,
    fixed: *const u8,
    fixed_len: usize,
    out: *mut f32,
    out_len: usize,
) -> Result<(), Failure> {
    let r = unsafe { handle_mut(runner, "runner") }?;
    let frames = unsafe { slice(key_frames, key_frames_len, "key_frames") }?;
    let poses = unsafe { slice(poses, poses_len, "poses") }?;
    let fixed = unsafe { optional_slice(fixed, fixed_len, "fixed") }?;
    let out = unsafe { slice_mut(out, out_len, "out") }?;
    let (d, g, n) = (r.frame_values, r.groups, frames.len());
    let info = INFO;
    let keys = counts.iter().try_fold(0usize, |a, c| a.checked_add(*c));
    if keys != Some(n) {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "`key_counts` add up to {} keys but `key_frames` holds {n}: give every character's key frames one after \
                 the other",
                keys.map_or("more than SIZE_MAX".to_string(), |k| k.to_string())
            ),
        ));
    }
    // The keys themselves first (their order, their range), then the buffers sized from them: a
    // key-order mistake is reported as one, not as the wrong output size it implies.
    let mut at = 0;
    for (c, &k) in counts.iter().enumerate() {
        let own = &frames[at..at + k];
        let who = if counts.len() == 1 { String::new() } else { format!(" (character {c})") };
        if own.len() < 2 {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`key_frames`{who} holds {} keys; completion needs at least 2 (the first at frame 0)",
                    own.len()
                ),
            ));
        }
        if own[0] != 0 {
            return Err((
                ZooStatus::InvalidArgument,
                format!("`key_frames`{who} starts at frame {}; the first key is frame 0 (shift the keys)", own[0]),
            ));
        }
        if let Some(i) = own.windows(2).position(|w| w[1] <= w[0]) {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`key_frames`{who}[{}] is {} after {}; key frames must be strictly increasing",
                    i + 1,
                    own[i + 1],
                    own[i]
                ),
            ));
        }
        let last = own[own.len() - 1];
        if last >= ZOO_MAX_FRAMES {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`key_frames`{who} ends at frame {last}; a completion has at most ZOO_MAX_FRAMES \
                     ({ZOO_MAX_FRAMES}) frames"
                ),
            ));
        }
        at += k;
    }
    check_size("poses", poses.len(), n * d, "floats", format_args!("{info} (`frame_values` floats per key)"))?;
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
        if let Some(i) = fixed.iter().position(|&f| f > 1) {
            return Err((
                ZooStatus::InvalidArgument,
                format!("`fixed`[{i}] is {}; a flag is 1 (the key fixes the group) or 0 (it leaves it free)", fixed[i]),
            ));
        }
    }
    r.fixed.clear();
    r.fixed.extend(fixed.iter().map(|&f| f32::from(f)));
    let fixed = &r.fixed[..];
    let mut keys = Vec::with_capacity(counts.len());
    let (mut at, mut total) = (0, 0usize);
    for &k in counts {
        let key = MotionKeys {
            frames: &frames[at..at + k],
            poses: &poses[at * d..(at + k) * d],
            fixed: if fixed.is_empty() { &[] } else { &fixed[at * g..(at + k) * g] },
        };
        // Bounded by ZOO_MAX_FRAMES and ZOO_MAX_BATCH above: no overflow.
        total += (key.frames[k - 1] + 1) * d;
        keys.push(key);
        at += k;
    }
    check_size(
        "out",
        out.len(),
        total,
        "floats",
        format_args!("each character's last key frame + 1, times `frame_values` ({info})"),
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
