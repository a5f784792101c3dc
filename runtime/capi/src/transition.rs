//! Transitions (RTN, task `transition`, `zoo_runtime::transition`): from a few context frames
//! to a target pose, for a batch of characters ([`ZooTransitionCharacters`]), one frame per
//! [`zoo_transition_step`] (global positions) or [`zoo_transition_step_posed`] (engine poses)
//! of a [`ZooTransitionRunner`].
//!
//! A transition of `length` frames returns `length` frames and then the target frame; the
//! model was trained for [`ZooTransitionInfo`]'s `transition_frames` (longer ones need
//! [`zoo_transition_allow_beyond_trained`]). A terrain-aware model ([`zoo_transition_terrain`])
//! needs each character's ground ([`zoo_transition_set_heightmap`]) before the start.

use crate::model::model;
use crate::{
    Failure, JOINTS, ZooModel, ZooRootMotion, ZooStatus, check_count, check_size, free_handle, guard, handle,
    handle_mut, new_handle, optional_slice, read_pose, runtime_failure, slice, slice_mut, write_out, write_pose,
};
use zoo_runtime::{EnginePose, TransitionRunner, TransitionState};

/// Scratch space for running a transition model (opaque). One thread at a time.
pub struct ZooTransitionRunner {
    runner: TransitionRunner,
}

/// The transitions of a batch of characters (opaque). One thread at a time.
pub struct ZooTransitionCharacters {
    states: Vec<TransitionState>,
    poses: Vec<EnginePose>,
    inputs: Vec<EnginePose>,
    joints: usize,
}

/// What a transition model expects besides `ZooModelInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooTransitionInfo {
    /// Context frames the model was trained with (the paper's 10).
    pub past_frames: usize,
    /// Transition length the model was trained on (the paper's 30): a transition returns this
    /// many frames and then the target frame.
    pub transition_frames: usize,
    /// Frames of the target blend at the end of a transition.
    pub target_blend: usize,
}

const INFO: &str = "zoo_transition_info";

/// Writes what a transition model expects into `*out`. Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_info(model: *const ZooModel, out: *mut ZooTransitionInfo) -> ZooStatus {
    guard("zoo_transition_info", || {
        let m = unsafe { self::model(model) }?.transition()?;
        let info = ZooTransitionInfo {
            past_frames: m.past_frames(),
            transition_frames: m.transition_frames(),
            target_blend: m.target_blend(),
        };
        unsafe { write_out(out, info, "out") }
    })
}

/// The terrain patch of a terrain-aware transition model: `*side` samples per side on a square
/// of `*extent` model units around the root. `ZOO_STATUS_NOT_AVAILABLE` for a model without
/// terrain input (a flat-ground model). Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; `side` and `extent` are NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_terrain(
    model: *const ZooModel,
    side: *mut usize,
    extent: *mut f32,
) -> ZooStatus {
    guard("zoo_transition_terrain", || {
        let m = unsafe { self::model(model) }?.transition()?;
        let Some((s, e)) = m.terrain() else {
            return Err((
                ZooStatus::NotAvailable,
                "the model has no terrain input (it was trained without `zoo train rtn --terrain`)".into(),
            ));
        };
        unsafe { write_out(side, s, "side") }?;
        unsafe { write_out(extent, e, "extent") }
    })
}

/// Creates scratch space for running `model` on one thread at a time into `*out`; free it with
/// [`zoo_transition_runner_free`]. Transitions longer than the trained length are refused unless
/// [`zoo_transition_allow_beyond_trained`]. Thread-safe (the model is shared).
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_runner_new(
    model: *const ZooModel,
    out: *mut *mut ZooTransitionRunner,
) -> ZooStatus {
    guard("zoo_transition_runner_new", || {
        let m = unsafe { self::model(model) }?.transition()?;
        unsafe { new_handle(out, || Ok(ZooTransitionRunner { runner: m.runner().map_err(runtime_failure)? })) }
    })
}

/// Frees a runner (NULL is ignored).
///
/// # Safety
/// `runner` is NULL or a pointer from [`zoo_transition_runner_new`] not freed before and not in
/// use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_runner_free(runner: *mut ZooTransitionRunner) {
    unsafe { free_handle(runner) }
}

/// Whether `runner` accepts transitions longer than the model was trained for (off by default:
/// beyond its training length the network drifts from the target).
///
/// # Safety
/// `runner` is NULL or a live runner used by this thread only.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_allow_beyond_trained(
    runner: *mut ZooTransitionRunner,
    allow: bool,
) -> ZooStatus {
    guard("zoo_transition_allow_beyond_trained", || {
        unsafe { handle_mut(runner, "runner") }?.runner.allow_beyond_trained(allow);
        Ok(())
    })
}

/// Creates the transition states of `count` characters of `model` into `*out`; free them with
/// [`zoo_transition_characters_free`]. Thread-safe (the model is shared).
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_characters_new(
    model: *const ZooModel,
    count: usize,
    out: *mut *mut ZooTransitionCharacters,
) -> ZooStatus {
    guard("zoo_transition_characters_new", || {
        let m = unsafe { self::model(model) }?.transition()?;
        unsafe {
            new_handle(out, || {
                check_count(count)?;
                let k = m.joints();
                Ok(ZooTransitionCharacters {
                    states: (0..count).map(|_| m.new_transition()).collect(),
                    poses: (0..count).map(|_| EnginePose::new(k)).collect(),
                    inputs: Vec::new(),
                    joints: k,
                })
            })
        }
    })
}

/// Frees characters (NULL is ignored).
///
/// # Safety
/// `characters` is NULL or a pointer from [`zoo_transition_characters_new`] not freed before and
/// not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_characters_free(characters: *mut ZooTransitionCharacters) {
    unsafe { free_handle(characters) }
}

/// The runner and the characters of a call, refused when made from models of different sizes.
///
/// # Safety
/// Handles are NULL or live and used by this thread only.
unsafe fn pair<'a>(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
) -> Result<(&'a mut TransitionRunner, &'a mut ZooTransitionCharacters), Failure> {
    let runner = &mut unsafe { handle_mut(runner, "runner") }?.runner;
    let chars = unsafe { handle_mut(characters, "characters") }?;
    let k = runner.model().joints();
    if k != chars.joints {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "the runner's model has {k} joints, the characters' {}: make the runner and the characters from the same model",
                chars.joints
            ),
        ));
    }
    Ok((runner, chars))
}

/// Starts a transition of `length` frames for every character from global joint positions:
/// `past` holds `N * frames * 3K` values (the same number of context frames per character, at
/// least one; the model was trained with [`ZooTransitionInfo`]'s `past_frames`), `target` and
/// `next` `N * 3K` each (the target pose and the pose after it). `length` is the number of
/// frames before the target frame; pass `transition_frames` for the trained length. Then step it
/// with [`zoo_transition_step`]. One thread at a time.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_start(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    past: *const f32,
    past_len: usize,
    target: *const f32,
    target_len: usize,
    next: *const f32,
    next_len: usize,
    length: usize,
) -> ZooStatus {
    guard("zoo_transition_start", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let past = unsafe { slice(past, past_len, "past") }?;
        let target = unsafe { slice(target, target_len, "target") }?;
        let next = unsafe { slice(next, next_len, "next") }?;
        runner.start_batch_for(&mut chars.states, past, target, next, length).map_err(runtime_failure)
    })
}

/// The next frame of every character's transition into `poses` (`N * 3K` global positions): the
/// target-blended frames, the last one the target. Stepping past the target frame is
/// `ZOO_STATUS_INVALID_STATE`. One thread at a time.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; `poses` is NULL or holds `poses_len`
/// writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_step(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    poses: *mut f32,
    poses_len: usize,
) -> ZooStatus {
    guard("zoo_transition_step", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let poses = unsafe { slice_mut(poses, poses_len, "poses") }?;
        runner.step_batch(&mut chars.states, poses).map_err(runtime_failure)
    })
}

/// Starts a transition of `length` frames for every character from engine poses: each pose is a
/// [`ZooRootMotion`] and `4K` rotation values. `past_roots` holds `N * frames` roots (the same
/// number of context frames per character, character-major) and `past_rotations` `4K` values
/// per root; `target_*` and `next_*` one pose per character (`rotations_len`: `N * 4K`, the
/// length of both rotation buffers). Then [`zoo_transition_step_posed`]. One thread at a time.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_start_posed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    past_roots: *const ZooRootMotion,
    past_roots_len: usize,
    past_rotations: *const f32,
    past_rotations_len: usize,
    target_roots: *const ZooRootMotion,
    target_rotations: *const f32,
    next_roots: *const ZooRootMotion,
    next_rotations: *const f32,
    rotations_len: usize,
    length: usize,
) -> ZooStatus {
    guard("zoo_transition_start_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let past_roots = unsafe { slice(past_roots, past_roots_len, "past_roots") }?;
        let past_rotations = unsafe { slice(past_rotations, past_rotations_len, "past_rotations") }?;
        let target_roots = unsafe { slice(target_roots, n, "target_roots") }?;
        let next_roots = unsafe { slice(next_roots, n, "next_roots") }?;
        check_size(
            "target_rotations / next_rotations (rotations_len)",
            rotations_len,
            n * 4 * k,
            "floats",
            format_args!("4 * {JOINTS} per character"),
        )?;
        let target_rotations = unsafe { slice(target_rotations, rotations_len, "target_rotations") }?;
        let next_rotations = unsafe { slice(next_rotations, rotations_len, "next_rotations") }?;
        if past_roots.is_empty() || !past_roots.len().is_multiple_of(n) {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`past_roots` holds {} roots; it needs the same number of context frames (at least one; {INFO}'s `past_frames` as trained) for each of the {n} characters",
                    past_roots.len()
                ),
            ));
        }
        check_size(
            "past_rotations",
            past_rotations.len(),
            past_roots.len() * 4 * k,
            "floats",
            format_args!("4 * {JOINTS} per root"),
        )?;
        let mut inputs = std::mem::take(&mut chars.inputs);
        inputs.resize_with(past_roots.len() + 2 * n, || EnginePose::new(k));
        for (i, root) in past_roots.iter().enumerate() {
            read_pose(root, &past_rotations[i * 4 * k..(i + 1) * 4 * k], &mut inputs[i]);
        }
        let at = past_roots.len();
        for c in 0..n {
            read_pose(&target_roots[c], &target_rotations[c * 4 * k..(c + 1) * 4 * k], &mut inputs[at + c]);
            read_pose(&next_roots[c], &next_rotations[c * 4 * k..(c + 1) * 4 * k], &mut inputs[at + n + c]);
        }
        let (past, rest) = inputs.split_at(at);
        let (target, next) = rest.split_at(n);
        let result = runner.start_posed_batch_for(&mut chars.states, past, target, next, length);
        chars.inputs = inputs;
        result.map_err(runtime_failure)
    })
}

/// The next frame of every character's transition (started with
/// [`zoo_transition_start_posed`]) as engine poses: `roots` receives `N` [`ZooRootMotion`] and
/// `rotations` `N * 4K` local rotations (the hips' relative to the root), fitted to the
/// network's frame inside the runtime. One thread at a time.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length of writable values.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_step_posed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
) -> ZooStatus {
    guard("zoo_transition_step_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let roots = unsafe { slice_mut(roots, roots_len, "roots") }?;
        let rotations = unsafe { slice_mut(rotations, rotations_len, "rotations") }?;
        check_size("roots", roots.len(), n, "roots", "the batch, one per character")?;
        check_size("rotations", rotations.len(), n * 4 * k, "floats", format_args!("4 * {JOINTS} per character"))?;
        runner.step_posed_batch(&mut chars.states, &mut chars.poses).map_err(runtime_failure)?;
        for ((pose, root), rotations) in chars.poses.iter().zip(roots).zip(rotations.chunks_exact_mut(4 * k)) {
            write_pose(pose, root, rotations);
        }
        Ok(())
    })
}

/// Sets the ground under character `index`: a heightmap of `cols * rows` heights (model units,
/// Y up) on a regular grid in the XZ plane, sample `(i, k)` at `(origin_x + i * cell, origin_z +
/// k * cell)` stored at `heights[k * cols + i]`, bilinear between samples and extended beyond
/// the border (the `zoo-heightfield` layout of `zoo data synth --terrain`). The map is copied.
/// A terrain-aware model ([`zoo_transition_terrain`]) needs it before [`zoo_transition_start`]
/// or [`zoo_transition_start_posed`]; a flat-ground model ignores it. `heights` NULL with
/// `heights_len` 0 removes the ground. Takes effect at the next step. One thread at a time.
///
/// # Safety
/// `characters` is NULL or live and used by this thread only; `heights` is NULL or holds
/// `heights_len` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_set_heightmap(
    characters: *mut ZooTransitionCharacters,
    index: usize,
    cols: usize,
    rows: usize,
    cell: f32,
    origin_x: f32,
    origin_z: f32,
    heights: *const f32,
    heights_len: usize,
) -> ZooStatus {
    guard("zoo_transition_set_heightmap", || {
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let heights = unsafe { optional_slice(heights, heights_len, "heights") }?;
        character(chars, index)?;
        if heights.is_empty() {
            chars.states[index].set_heightmap(None);
            return Ok(());
        }
        let invalid = |m: String| (ZooStatus::InvalidArgument, m);
        if cols == 0 || rows == 0 {
            return Err(invalid(format!("the heightmap is {cols} x {rows} samples; it needs at least 1 x 1")));
        }
        check_size("heights", heights.len(), cols.saturating_mul(rows), "floats (cols * rows)", "`cols` and `rows`")?;
        if !(cell.is_finite() && cell > 0.0) {
            return Err(invalid(format!("`cell` is {cell}; the distance between samples must be a positive number")));
        }
        if !(origin_x.is_finite() && origin_z.is_finite()) {
            return Err(invalid(format!("the origin (`origin_x` {origin_x}, `origin_z` {origin_z}) must be finite")));
        }
        if let Some(i) = heights.iter().position(|h| !h.is_finite()) {
            return Err(invalid(format!("height {i} is {}; every height must be finite", heights[i])));
        }
        let map = zoo_runtime::Heightmap {
            cols,
            rows,
            cell: cell as f64,
            origin: [origin_x as f64, origin_z as f64],
            heights: heights.to_vec(),
        };
        chars.states[index].set_heightmap(Some(std::sync::Arc::new(map)));
        Ok(())
    })
}

/// Frames character `index`'s transition still returns (0 once it returned its target frame).
///
/// # Safety
/// `characters` is NULL or live and used by this thread only; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_frames_left(
    characters: *const ZooTransitionCharacters,
    index: usize,
    out: *mut usize,
) -> ZooStatus {
    guard("zoo_transition_frames_left", || {
        let chars = unsafe { handle(characters, "characters") }?;
        let s = character(chars, index)?;
        unsafe { write_out(out, s.frames_left(), "out") }
    })
}

/// How far the network's own target frame for character `index` lay from the requested target
/// before the blend hid it (mean and largest joint distance, model units): a cue to fall back
/// to inertialization. `ZOO_STATUS_NOT_AVAILABLE` before stepping reaches the blend window.
///
/// # Safety
/// `characters` is NULL or live and used by this thread only; `mean` and `max` are NULL or
/// writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_target_miss(
    characters: *const ZooTransitionCharacters,
    index: usize,
    mean: *mut f32,
    max: *mut f32,
) -> ZooStatus {
    guard("zoo_transition_target_miss", || {
        let chars = unsafe { handle(characters, "characters") }?;
        let miss = character(chars, index)?.target_miss().ok_or_else(|| {
            (
                ZooStatus::NotAvailable,
                format!("character {index}: the target miss is known once stepping reaches the blend window"),
            )
        })?;
        unsafe { write_out(mean, miss.mean, "mean") }?;
        unsafe { write_out(max, miss.max, "max") }
    })
}

fn character(chars: &ZooTransitionCharacters, index: usize) -> Result<&TransitionState, Failure> {
    chars.states.get(index).ok_or_else(|| {
        (
            ZooStatus::InvalidArgument,
            format!("character {index} (`index`) does not exist: the batch has {} (0-based)", chars.states.len()),
        )
    })
}
