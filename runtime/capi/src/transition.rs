//! Transitions (RTN, task `transition`, `zoo_runtime::transition`): from a few context frames
//! to a target pose, for a batch of characters (`ZooTransitionCharacters`), one frame per
//! `zoo_transition_step` (global positions) or `zoo_transition_step_posed` (engine poses)
//! of a `ZooTransitionRunner`.
//!
//! A transition of `length` frames returns `length` frames and then the target frame; the
//! model was trained for `ZooTransitionInfo`'s `transition_frames` (longer ones need
//! `zoo_transition_allow_beyond_trained`). A terrain-aware model (`zoo_transition_terrain`)
//! needs each character's ground (`zoo_transition_set_heightmap`) before the start.

use crate::model::model;
use crate::{
    Failure, JOINTS, ZooModel, ZooRootMotion, ZooStatus, check_batch, check_count, check_size, free_handle, guard,
    handle, handle_mut, new_handle, optional_slice, read_pose, runtime_failure, slice, slice_mut, write_out,
    write_pose,
};
use zoo_runtime::{EnginePose, TransitionRunner, TransitionState};

/// Scratch space for running a transition model (opaque). One thread at a time.
pub struct ZooTransitionRunner {
    runner: TransitionRunner,
    max_batch: usize,
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
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
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
/// Safety: `model` is NULL or a live model; `side` and `extent` are NULL or writable.
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

/// Creates scratch space for running `model` for up to `max_batch` characters per call
/// (1..`ZOO_MAX_BATCH`; a larger batch is refused), on one thread at a time, into `*out`; free it with
/// `zoo_transition_runner_free`. Transitions longer than the trained length are refused unless
/// `zoo_transition_allow_beyond_trained`. Thread-safe (the model is shared).
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_runner_new(
    model: *const ZooModel,
    max_batch: usize,
    out: *mut *mut ZooTransitionRunner,
) -> ZooStatus {
    guard("zoo_transition_runner_new", || {
        let m = unsafe { self::model(model) }?.transition()?;
        check_count("max_batch", max_batch)?;
        unsafe {
            new_handle(out, || Ok(ZooTransitionRunner { runner: m.runner().map_err(runtime_failure)?, max_batch }))
        }
    })
}

/// Frees a runner (NULL is ignored).
///
/// Safety: `runner` is NULL or a pointer from `zoo_transition_runner_new` not freed before and not in
/// use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_runner_free(runner: *mut ZooTransitionRunner) {
    unsafe { free_handle(runner) }
}

/// Whether `runner` accepts transitions longer than the model was trained for (off by default:
/// beyond its training length the network drifts from the target).
///
/// Safety: `runner` is NULL or a live runner used by this thread only.
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
/// `zoo_transition_characters_free`. Thread-safe (the model is shared).
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
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
                check_count("count", count)?;
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
/// Safety: `characters` is NULL or a pointer from `zoo_transition_characters_new` not freed before and
/// not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_characters_free(characters: *mut ZooTransitionCharacters) {
    unsafe { free_handle(characters) }
}

/// The runner and the characters of a call, refused when made from models of different sizes.
///
/// Safety: Handles are NULL or live and used by this thread only.
unsafe fn pair<'a>(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
) -> Result<(&'a mut TransitionRunner, &'a mut ZooTransitionCharacters), Failure> {
    let runner = unsafe { handle_mut(runner, "runner") }?;
    let chars = unsafe { handle_mut(characters, "characters") }?;
    check_batch(chars.states.len(), runner.max_batch, "zoo_transition_runner_new")?;
    let runner = &mut runner.runner;
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
/// least one; the model was trained with `ZooTransitionInfo`'s `past_frames`), `target` and
/// `next` `N * 3K` each (the target pose and the pose after it). `length` is the number of
/// frames before the target frame; pass `transition_frames` for the trained length. Then step it
/// with `zoo_transition_step`. Cost: one graph pass per context frame, all in this call (ten
/// steps' worth for the paper's model); to spread them over the frames the game plays, use
/// `zoo_transition_begin` and `zoo_transition_feed`. One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
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

/// Begins a transition of `length` frames for every character whose context the game feeds
/// frame by frame as it plays it, so that no call encodes the whole context at once (a frame
/// budget; `zoo_transition_start` runs one graph pass per context frame in one call): `first`
/// holds each character's first context frame (`N * 3K` global positions), `target` and `next`
/// as in `zoo_transition_start`, `past_frames` the context frames in all (the model was
/// trained with `ZooTransitionInfo`'s `past_frames`). Runs no graph pass (one when
/// `past_frames` is 1; for one character, the start graph's part that needs only the target).
/// Then call `zoo_transition_feed` once per frame for the other
/// `past_frames - 1` context frames (one graph pass each, and the start graph with the first) and
/// step. For one character the runner spreads these passes over the calls, node by node.
/// The frames are those `zoo_transition_start` gives for the same context, bit for bit. One
/// thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_begin(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    first: *const f32,
    first_len: usize,
    target: *const f32,
    target_len: usize,
    next: *const f32,
    next_len: usize,
    past_frames: usize,
    length: usize,
) -> ZooStatus {
    guard("zoo_transition_begin", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let first = unsafe { slice(first, first_len, "first") }?;
        let target = unsafe { slice(target, target_len, "target") }?;
        let next = unsafe { slice(next, next_len, "next") }?;
        let n = chars.states.len();
        let d = 3 * chars.joints;
        check_size("first", first.len(), n * d, "floats", format_args!("3 * {JOINTS} per character"))?;
        check_size("target", target.len(), n * d, "floats", format_args!("3 * {JOINTS} per character"))?;
        check_size("next", next.len(), n * d, "floats", format_args!("3 * {JOINTS} per character"))?;
        check_past_frames(past_frames)?;
        runner.begin_batch(&mut chars.states, first, target, next, past_frames, length).map_err(runtime_failure)
    })
}

/// Feeds the next context frame of every character's transition begun with
/// `zoo_transition_begin`: `frame` holds `N * 3K` global positions. One graph pass (and the start
/// graph on the first context frame, with the second); for one character the pass may finish in
/// the next call (a frame budget). After the last one, step the transition. One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; `frame` is NULL or holds
/// `frame_len` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_feed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    frame: *const f32,
    frame_len: usize,
) -> ZooStatus {
    guard("zoo_transition_feed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let frame = unsafe { slice(frame, frame_len, "frame") }?;
        let d = 3 * chars.joints;
        check_size("frame", frame.len(), chars.states.len() * d, "floats", format_args!("3 * {JOINTS} per character"))?;
        runner.feed_batch(&mut chars.states, frame).map_err(runtime_failure)
    })
}

/// `zoo_transition_begin` from engine poses: `first_roots`, `target_roots` and `next_roots` hold
/// one root per character (`N`), the rotation buffers `N * 4K` values; then
/// `zoo_transition_feed_posed` per context frame and `zoo_transition_step_posed`. One thread at a
/// time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_begin_posed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    first_roots: *const ZooRootMotion,
    first_roots_len: usize,
    first_rotations: *const f32,
    first_rotations_len: usize,
    target_roots: *const ZooRootMotion,
    target_roots_len: usize,
    target_rotations: *const f32,
    target_rotations_len: usize,
    next_roots: *const ZooRootMotion,
    next_roots_len: usize,
    next_rotations: *const f32,
    next_rotations_len: usize,
    past_frames: usize,
    length: usize,
) -> ZooStatus {
    guard("zoo_transition_begin_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let buffers = [
            unsafe {
                posed_buffers(
                    first_roots,
                    first_roots_len,
                    first_rotations,
                    first_rotations_len,
                    ["first_roots", "first_rotations"],
                    n,
                    k,
                )
            }?,
            unsafe {
                posed_buffers(
                    target_roots,
                    target_roots_len,
                    target_rotations,
                    target_rotations_len,
                    ["target_roots", "target_rotations"],
                    n,
                    k,
                )
            }?,
            unsafe {
                posed_buffers(
                    next_roots,
                    next_roots_len,
                    next_rotations,
                    next_rotations_len,
                    ["next_roots", "next_rotations"],
                    n,
                    k,
                )
            }?,
        ];
        check_past_frames(past_frames)?;
        let mut inputs = std::mem::take(&mut chars.inputs);
        read_into(&mut inputs, &buffers, k);
        let (first, rest) = inputs.split_at(n);
        let (target, next) = rest.split_at(n);
        let result = runner.begin_posed_batch(&mut chars.states, first, target, next, past_frames, length);
        chars.inputs = inputs;
        result.map_err(runtime_failure)
    })
}

/// `zoo_transition_feed` from engine poses: one root per character (`N`) and `N * 4K` rotation
/// values. One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_feed_posed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    roots: *const ZooRootMotion,
    roots_len: usize,
    rotations: *const f32,
    rotations_len: usize,
) -> ZooStatus {
    guard("zoo_transition_feed_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let (roots, rotations) =
            unsafe { posed_buffers(roots, roots_len, rotations, rotations_len, ["roots", "rotations"], n, k) }?;
        let mut inputs = std::mem::take(&mut chars.inputs);
        read_into(&mut inputs, &[(roots, rotations)], k);
        let result = runner.feed_posed_batch(&mut chars.states, &inputs);
        chars.inputs = inputs;
        result.map_err(runtime_failure)
    })
}

/// The engine poses of a posed start (`zoo_transition_start_posed`,
/// `zoo_transition_generate_posed`): `buffers` holds the past, target and next roots and
/// rotations with their lengths. Checks them all (the same number of context frames per
/// character, the sizes, finite roots, non-zero quaternions), then reads them into the
/// characters' input poses, taken from them (give them back): the past (`N * frames` poses),
/// then the `N` targets, then the `N` next poses.
///
/// Safety: each buffer is NULL or holds its given length.
unsafe fn read_posed_start(
    chars: &mut ZooTransitionCharacters,
    buffers: [(*const ZooRootMotion, usize, *const f32, usize); 3],
) -> Result<Vec<EnginePose>, Failure> {
    let (n, k) = (chars.states.len(), chars.joints);
    let [(past_roots, past_roots_len, past_rotations, past_rotations_len), target, next] = buffers;
    let past_roots = unsafe { slice(past_roots, past_roots_len, "past_roots") }?;
    let past_rotations = unsafe { slice(past_rotations, past_rotations_len, "past_rotations") }?;
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
    let names = ["target_roots", "target_rotations"];
    let target = unsafe { posed_buffers(target.0, target.1, target.2, target.3, names, n, k) }?;
    let names = ["next_roots", "next_rotations"];
    let next = unsafe { posed_buffers(next.0, next.1, next.2, next.3, names, n, k) }?;
    check_poses(past_roots, past_rotations, ["past_roots", "past_rotations"])?;
    let mut inputs = std::mem::take(&mut chars.inputs);
    read_into(&mut inputs, &[(past_roots, past_rotations), target, next], k);
    Ok(inputs)
}

/// One pose per character from a roots buffer and a rotations buffer (`names`), their lengths
/// and values checked.
///
/// Safety: each pointer is NULL or holds its given length.
unsafe fn posed_buffers<'a>(
    roots: *const ZooRootMotion,
    roots_len: usize,
    rotations: *const f32,
    rotations_len: usize,
    names: [&str; 2],
    n: usize,
    k: usize,
) -> Result<(&'a [ZooRootMotion], &'a [f32]), Failure> {
    let roots = unsafe { slice(roots, roots_len, names[0]) }?;
    let rotations = unsafe { slice(rotations, rotations_len, names[1]) }?;
    check_size(names[0], roots.len(), n, "roots", "the batch, one per character")?;
    check_size(names[1], rotations.len(), n * 4 * k, "floats", format_args!("4 * {JOINTS} per character"))?;
    check_poses(roots, rotations, names)?;
    Ok((roots, rotations))
}

/// Reads the engine poses of `buffers` (roots and `4K` rotation values per root, sizes checked)
/// one buffer after the other into `inputs`, resized to all of them.
fn read_into(inputs: &mut Vec<EnginePose>, buffers: &[(&[ZooRootMotion], &[f32])], k: usize) {
    inputs.resize_with(buffers.iter().map(|(roots, _)| roots.len()).sum(), || EnginePose::new(k));
    let mut at = 0;
    for (roots, rotations) in buffers {
        for ((root, r), pose) in roots.iter().zip(rotations.chunks_exact(4 * k)).zip(&mut inputs[at..]) {
            read_pose(root, r, pose);
        }
        at += roots.len();
    }
}

/// Refuses a context of no frames or of more than `ZOO_MAX_FRAMES`.
fn check_past_frames(past_frames: usize) -> Result<(), Failure> {
    if past_frames == 0 || past_frames > crate::ZOO_MAX_FRAMES {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "`past_frames` is {past_frames}; a transition has 1..=ZOO_MAX_FRAMES context frames (the model was \
                 trained with {INFO}'s `past_frames`)"
            ),
        ));
    }
    Ok(())
}

/// The next frame of every character's transition into `poses` (`N * 3K` global positions): the
/// target-blended frames, the last one the target. Stepping past the target frame is
/// `ZOO_STATUS_INVALID_STATE`. Cost: one graph pass per character, two in the few steps before
/// the blend window (the blend needs the network's own target frame, computed ahead; staggered
/// across a batch). One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; `poses` is NULL or holds `poses_len`
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
/// `ZooRootMotion` and `4K` rotation values. `past_roots` holds `N * frames` roots (the same
/// number of context frames per character, character-major) and `past_rotations` `4K` values
/// per root; `target_roots` and `next_roots` one root per character (`N`), `target_rotations`
/// and `next_rotations` `N * 4K` values. Every root must be finite and every rotation a finite,
/// non-zero quaternion. Then `zoo_transition_step_posed`. One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
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
    target_roots_len: usize,
    target_rotations: *const f32,
    target_rotations_len: usize,
    next_roots: *const ZooRootMotion,
    next_roots_len: usize,
    next_rotations: *const f32,
    next_rotations_len: usize,
    length: usize,
) -> ZooStatus {
    guard("zoo_transition_start_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let n = chars.states.len();
        let buffers = [
            (past_roots, past_roots_len, past_rotations, past_rotations_len),
            (target_roots, target_roots_len, target_rotations, target_rotations_len),
            (next_roots, next_roots_len, next_rotations, next_rotations_len),
        ];
        let inputs = unsafe { read_posed_start(chars, buffers) }?;
        let at = inputs.len() - 2 * n;
        let (past, rest) = inputs.split_at(at);
        let (target, next) = rest.split_at(n);
        let result = runner.start_posed_batch_for(&mut chars.states, past, target, next, length);
        chars.inputs = inputs;
        result.map_err(runtime_failure)
    })
}

/// The next frame of every character's transition (started with
/// `zoo_transition_start_posed`) as engine poses: `roots` receives `N` `ZooRootMotion` and
/// `rotations` `N * 4K` local rotations (the hips' relative to the root), fitted to the
/// network's frame inside the runtime. One thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
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

/// A whole transition of `length` frames for every character from engine poses, in one call:
/// the inputs as in `zoo_transition_start_posed`, then `out_roots` receives `N * (length + 1)`
/// roots and `out_rotations` `4K` rotations per root (character-major: each character's
/// `length` frames, then its target frame). `fallback` 1 moves a transition that misses its
/// target by more than the model's calibrated thresholds towards the interpolation (the model's
/// thresholds for this length; `zoo transition`'s default), 0 keeps the network's; `foot_lock` 1
/// locks the feet (`zoo transition --foot-lock`), 0 does not. The frames are those `zoo
/// transition --in-place` writes for the same poses. Only a whole transition gets the fallback
/// and the foot lock (both look at the whole transition); with both 0 the frames are those of
/// `zoo_transition_start_posed` and `length + 1` calls of `zoo_transition_step_posed` (bit for bit
/// for one character; for several, up to the rounding of batched kernels). The
/// transitions are finished afterwards. Cost: every pass of the transition in this call. One
/// thread at a time.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length (the outputs writable).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_transition_generate_posed(
    runner: *mut ZooTransitionRunner,
    characters: *mut ZooTransitionCharacters,
    past_roots: *const ZooRootMotion,
    past_roots_len: usize,
    past_rotations: *const f32,
    past_rotations_len: usize,
    target_roots: *const ZooRootMotion,
    target_roots_len: usize,
    target_rotations: *const f32,
    target_rotations_len: usize,
    next_roots: *const ZooRootMotion,
    next_roots_len: usize,
    next_rotations: *const f32,
    next_rotations_len: usize,
    length: usize,
    fallback: u8,
    foot_lock: u8,
    out_roots: *mut ZooRootMotion,
    out_roots_len: usize,
    out_rotations: *mut f32,
    out_rotations_len: usize,
) -> ZooStatus {
    guard("zoo_transition_generate_posed", || {
        let (runner, chars) = unsafe { pair(runner, characters) }?;
        let (n, k) = (chars.states.len(), chars.joints);
        for (name, flag, what) in
            [("fallback", fallback, "the model's calibrated fallback"), ("foot_lock", foot_lock, "the foot lock")]
        {
            if flag > 1 {
                return Err((
                    ZooStatus::InvalidArgument,
                    format!("`{name}` is {flag}; a flag is 1 ({what} on) or 0 (off)"),
                ));
            }
        }
        if length == 0 || length > crate::ZOO_MAX_FRAMES {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`length` is {length}; a transition has 1..=ZOO_MAX_FRAMES frames ({INFO}'s `transition_frames` as \
                     trained)"
                ),
            ));
        }
        let buffers = [
            (past_roots, past_roots_len, past_rotations, past_rotations_len),
            (target_roots, target_roots_len, target_rotations, target_rotations_len),
            (next_roots, next_roots_len, next_rotations, next_rotations_len),
        ];
        let inputs = unsafe { read_posed_start(chars, buffers) }?;
        // The outputs' sizes after the inputs' (the inputs given back when they are wrong).
        let outputs = (|| {
            let out_roots = unsafe { slice_mut(out_roots, out_roots_len, "out_roots") }?;
            let out_rotations = unsafe { slice_mut(out_rotations, out_rotations_len, "out_rotations") }?;
            let frames = n * (length + 1);
            if frames > crate::ZOO_MAX_FRAMES {
                return Err((
                    ZooStatus::InvalidArgument,
                    format!(
                        "{n} characters of {} frames are {frames} poses, more than ZOO_MAX_FRAMES in one call: generate \
                         fewer characters per call",
                        length + 1
                    ),
                ));
            }
            check_size("out_roots", out_roots.len(), frames, "roots", "`length + 1` per character")?;
            check_size(
                "out_rotations",
                out_rotations.len(),
                frames * 4 * k,
                "floats",
                format_args!("4 * {JOINTS} per root of `out_roots`"),
            )?;
            Ok((out_roots, out_rotations, frames))
        })();
        let (out_roots, out_rotations, frames) = match outputs {
            Ok(o) => o,
            Err(e) => {
                chars.inputs = inputs;
                return Err(e);
            }
        };
        let at = inputs.len() - 2 * n;
        let (past, rest) = inputs.split_at(at);
        let (target, next) = rest.split_at(n);
        runner.set_foot_lock(if foot_lock == 1 { runner.model().default_foot_lock() } else { None });
        if fallback == 1 {
            runner.set_model_fallback();
        } else {
            runner.set_fallback(None);
        }
        let mut poses = std::mem::take(&mut chars.poses);
        poses.resize_with(frames, || EnginePose::new(k));
        let result = runner.generate_posed_batch(&mut chars.states, past, target, next, length, &mut poses);
        if result.is_ok() {
            for ((pose, root), rotations) in poses.iter().zip(out_roots).zip(out_rotations.chunks_exact_mut(4 * k)) {
                write_pose(pose, root, rotations);
            }
        }
        poses.truncate(n);
        chars.poses = poses;
        chars.inputs = inputs;
        result.map_err(runtime_failure)
    })
}

/// Sets the ground under character `index`: a heightmap of `cols * rows` heights (model units,
/// Y up) on a regular grid in the XZ plane, sample `(i, k)` at `(origin_x + i * cell, origin_z +
/// k * cell)` stored at `heights[k * cols + i]`, bilinear between samples and extended beyond
/// the border (the `zoo-heightfield` layout of `zoo data synth --terrain`). The map is copied.
/// A terrain-aware model (`zoo_transition_terrain`) needs it before `zoo_transition_start`
/// or `zoo_transition_start_posed`; a flat-ground model ignores it. `heights` NULL with
/// `heights_len` 0 removes the ground. Takes effect at the next step. One thread at a time.
///
/// Safety: `characters` is NULL or live and used by this thread only; `heights` is NULL or holds
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
/// Safety: `characters` is NULL or live and used by this thread only; `out` is NULL or writable.
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
/// Safety: `characters` is NULL or live and used by this thread only; `mean` and `max` are NULL or
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

/// Refuses a non-finite root value or a rotation that is not a finite, non-zero quaternion,
/// naming the caller's buffer and the element (`names`: the roots' and the rotations' buffers).
pub(crate) fn check_poses(roots: &[ZooRootMotion], rotations: &[f32], names: [&str; 2]) -> Result<(), Failure> {
    for (i, r) in roots.iter().enumerate() {
        let fields = [
            ("root_position", &r.root_position[..]),
            ("root_rotation", &r.root_rotation[..]),
            ("hips_position", &r.hips_position[..]),
        ];
        for (field, v) in fields {
            if v.iter().any(|x| !x.is_finite()) {
                return Err((
                    ZooStatus::InvalidArgument,
                    format!("`{}[{i}].{field}` is {v:?}, not finite; pass finite values", names[0]),
                ));
            }
        }
        let q = &r.root_rotation;
        if q.iter().map(|x| x * x).sum::<f32>() < 1e-12 {
            return Err((
                ZooStatus::InvalidArgument,
                format!("`{}[{i}].root_rotation` is a zero quaternion; pass a rotation (identity: 0 0 0 1)", names[0]),
            ));
        }
    }
    for (j, q) in rotations.chunks_exact(4).enumerate() {
        let norm2: f32 = q.iter().map(|x| x * x).sum();
        if !norm2.is_finite() || norm2 < 1e-12 {
            let what = if norm2.is_finite() { "a zero quaternion" } else { "not finite" };
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`{}` values {}..{} (rotation {j}) are {q:?}, {what}; pass a finite, non-zero quaternion x y z w \
                     (identity: 0 0 0 1)",
                    names[1],
                    4 * j,
                    4 * j + 4
                ),
            ));
        }
    }
    Ok(())
}
