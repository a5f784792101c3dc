//! The C ABI of the zoo engine runtime (`zoo-runtime`), for engines that cannot link Rust:
//! Unity (P/Invoke), Unreal and Godot (C/C++), or any language with a C FFI.
//!
//! Every task of the runtime has its loader and its calls, each model kind its own handle:
//! - transitions (RTN, kind `rtn`): [`ZooModel`], [`ZooRunner`], [`ZooCharacters`] (this file);
//! - keyframe completion (ARNN, kind `arnn`): [`ZooKeyframeModel`], [`ZooKeyframeRunner`]
//!   (`keyframes.rs`);
//! - locomotion stitching (RMR, kind `rmr`): [`ZooStitchModel`], the whole-sequence
//!   [`zoo_stitch_refine`] and the streaming [`ZooStitchStream`] (`stitch.rs`);
//! - random synthesis (RNN-GMM, kind `rnn-gmm`): [`ZooSynthesisModel`], [`ZooSynthesisRunner`],
//!   [`ZooSynthesisCharacters`] (`synthesis.rs`), and its speed / facing controller
//!   [`ZooControlRunner`], [`ZooControlCharacters`] (`control.rs`).
//!
//! A loader given a file of another kind refuses it with `ZOO_STATUS_WRONG_MODEL` and names the
//! function that loads it.
//!
//! The header `include/zoo.h` is generated from these files by cbindgen
//! (`crates/capi/cbindgen.toml`) and checked up to date by `tests/capi.rs`;
//! `examples/transition.c` and `examples/tasks.c` are complete programs.
//!
//! # Conventions
//! - Every fallible function returns a [`ZooStatus`]; `ZOO_STATUS_OK` is 0. On any other status,
//!   [`zoo_last_error`] gives a readable message naming the problem and the fix (per thread).
//! - Handles are opaque (models, runners, characters, streams). Each has a `_free` function
//!   that accepts NULL.
//! - Buffers are passed as a pointer and a length in elements; the length is checked against what
//!   the call needs, and a mismatch is an error, not a read past the buffer. An optional buffer
//!   is NULL with a length of 0.
//! - No panic crosses the boundary: one is caught and reported as `ZOO_STATUS_PANIC`.
//! - Poses in positions are global joint positions, joint-major (`x0 y0 z0 x1 ...`), character-major
//!   across a batch. Rotations are quaternions `x y z w`, joint-major, the model skeleton's order.
//!   An engine pose is a [`ZooRootMotion`] and `4K` local rotations (`K` joints); a batch or a
//!   sequence of them is an array of roots and one rotation buffer of `4K` values per root.
//!   Contacts are bytes, 1 for a foot on the ground and 0 otherwise.
//!
//! # Thread safety
//! - A loaded model is immutable after loading: any number of threads may use it at once (create
//!   runners, characters and streams from it, read its info, refine a whole stitching
//!   sequence). Free it after everything made from it, or before: what is made from a model
//!   keeps what it needs. (One exception: [`zoo_stitch_model_set_window`] changes a stitching
//!   model and needs it to itself.)
//! - Runners, characters and streams may be used by one thread at a time (move them between
//!   threads freely); a call takes one runner and one characters handle, so threads each with
//!   their own pair run in parallel.
//! - [`zoo_last_error`] reports the last error of the calling thread.

// The boundary itself needs raw pointers; every other crate of the workspace denies unsafe code.
#![allow(unsafe_code)]

mod control;
mod keyframes;
mod stitch;
mod synthesis;

pub use control::*;
pub use keyframes::*;
pub use stitch::*;
pub use synthesis::*;

use std::cell::RefCell;
use std::ffi::{CStr, c_char};
use std::panic::{AssertUnwindSafe, catch_unwind};
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::{EnginePose, LoadedModel, MotionError, TransitionModel, TransitionRunner, TransitionState};

/// Result of a call.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZooStatus {
    /// Success.
    Ok = 0,
    /// A required pointer (handle, buffer or output) was NULL.
    NullPointer = 1,
    /// An argument is wrong: a buffer of the wrong length, a non-finite value, a count of zero,
    /// a path that is not UTF-8.
    InvalidArgument = 2,
    /// The model file cannot be read or is not an exported zoo model.
    LoadFailed = 3,
    /// The model file is of another task than the loader's (the message names the function
    /// that loads it).
    WrongModel = 4,
    /// The call does not fit where the handle stands (a transition not started, already
    /// finished or longer than the model was trained for; characters not started; a stitching
    /// stream finished or too short to finish; a model still in use).
    InvalidState = 5,
    /// The graph failed to run.
    RunFailed = 6,
    /// The requested value is not known yet (e.g. the target miss before the blend window, a
    /// stitching stream's next pose before it is ready).
    NotAvailable = 7,
    /// An internal error (a caught panic): please report it with the message.
    Panic = 8,
}

/// A loaded transition model (opaque). Thread-safe: share it between threads.
pub struct ZooModel {
    model: TransitionModel,
}

/// Per-thread scratch space for running a model (opaque). One thread at a time.
pub struct ZooRunner {
    runner: TransitionRunner,
}

/// The transitions of a batch of characters (opaque). One thread at a time.
pub struct ZooCharacters {
    states: Vec<TransitionState>,
    poses: Vec<EnginePose>,
    inputs: Vec<EnginePose>,
    joints: usize,
}

/// What a model expects.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooModelInfo {
    /// Number of joints K: a pose is `3K` positions or `4K` rotation values.
    pub joints: usize,
    /// Context frames the model was trained with (the paper's 10).
    pub past_frames: usize,
    /// Transition length the model was trained on (the paper's 30): a transition returns this
    /// many frames and then the target frame.
    pub transition_frames: usize,
    /// Frames of the target blend at the end of a transition.
    pub target_blend: usize,
    /// Frames per second of the training data.
    pub fps: f32,
}

/// The root of an engine pose (see `zoo_runtime::EnginePose`): the hips projected on the ground
/// and their facing, the root motion since the previous frame, and the hips in root space. The
/// joints' local rotations travel in a separate `4K` float buffer per pose (the hips' relative to
/// the root). On input only `root_position`, `root_rotation` and `hips_position` are read.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooRootMotion {
    /// Hips on the ground (`y = 0`, Y up), model units.
    pub root_position: [f32; 3],
    /// Facing: a rotation about +Y, quaternion `x y z w`.
    pub root_rotation: [f32; 4],
    /// Root displacement since the previous frame, in the previous frame's root space.
    pub delta_position: [f32; 3],
    /// Turn since the previous frame about +Y, radians.
    pub delta_yaw: f32,
    /// The hips' position in root space.
    pub hips_position: [f32; 3],
}

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

/// An error status and its message.
pub(crate) type Failure = (ZooStatus, String);

fn set_error(message: String) {
    LAST_ERROR.with(|e| *e.borrow_mut() = message);
}

/// Runs `f`, records its error message, and turns a panic into `ZooStatus::Panic`.
pub(crate) fn guard(f: impl FnOnce() -> Result<(), Failure>) -> ZooStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => ZooStatus::Ok,
        Ok(Err((status, message))) => {
            set_error(message);
            status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            set_error(format!("internal error in the zoo runtime ({what}); please report it"));
            ZooStatus::Panic
        }
    }
}

/// The status of a runtime error.
pub(crate) fn runtime_failure(e: MotionError) -> Failure {
    let status = match &e {
        MotionError::Io { .. }
        | MotionError::NotOnnx { .. }
        | MotionError::UnknownFormatVersion { .. }
        | MotionError::BadGraphIo { .. }
        | MotionError::Unsupported { .. }
        | MotionError::FormatTooOld { .. }
        | MotionError::MissingMetadata { .. }
        | MotionError::BadMetadata { .. }
        | MotionError::UnknownTask { .. }
        | MotionError::UnknownModelKind { .. } => ZooStatus::LoadFailed,
        MotionError::WrongTask { .. } => ZooStatus::WrongModel,
        MotionError::BufferLength { .. }
        | MotionError::BufferCount { .. }
        | MotionError::NonFinite { .. }
        | MotionError::StateMismatch { .. }
        | MotionError::EmptyBatch
        | MotionError::Stitch { .. }
        | MotionError::Control { .. } => ZooStatus::InvalidArgument,
        MotionError::TransitionSequence { .. } | MotionError::BeyondTrainedLength { .. } => ZooStatus::InvalidState,
        _ => ZooStatus::RunFailed,
    };
    (status, e.to_string())
}

/// [`runtime_failure`] of starting transitions, naming the C call that gives a character its
/// ground where the runtime names its Rust method.
fn start_failure(e: MotionError) -> Failure {
    let (status, message) = runtime_failure(e);
    (status, message.replace("TransitionState::set_heightmap", "zoo_characters_set_heightmap"))
}

pub(crate) fn null(what: &str) -> Failure {
    (ZooStatus::NullPointer, format!("`{what}` is NULL; pass a valid pointer"))
}

/// A shared reference from a handle pointer.
///
/// # Safety
/// `ptr` is NULL or a valid pointer to a live `T`.
pub(crate) unsafe fn handle<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    unsafe { ptr.as_ref() }.ok_or_else(|| null(what))
}

/// A mutable reference from a handle pointer.
///
/// # Safety
/// `ptr` is NULL or a valid, exclusively used pointer to a live `T`.
pub(crate) unsafe fn handle_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    unsafe { ptr.as_mut() }.ok_or_else(|| null(what))
}

/// A slice from a pointer and a length.
///
/// # Safety
/// `ptr` is NULL or points to `len` readable values.
pub(crate) unsafe fn slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if ptr.is_null() {
        return Err(null(what));
    }
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// A mutable slice from a pointer and a length.
///
/// # Safety
/// `ptr` is NULL or points to `len` writable values not aliased elsewhere during the call.
pub(crate) unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize, what: &str) -> Result<&'a mut [T], Failure> {
    if ptr.is_null() {
        return Err(null(what));
    }
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

pub(crate) fn check_len(what: &str, found: usize, expected: usize, unit: &str) -> Result<(), Failure> {
    check_size(what, found, expected, unit, "zoo_model_info")
}

/// [`check_len`] for a buffer sized from what `info` reports.
pub(crate) fn check_size(what: &str, found: usize, expected: usize, unit: &str, info: &str) -> Result<(), Failure> {
    if found != expected {
        return Err((
            ZooStatus::InvalidArgument,
            format!("`{what}` holds {found} {unit}, this call needs {expected}; size it from {info}"),
        ));
    }
    Ok(())
}

/// Refuses a batch of no characters.
pub(crate) fn check_count(count: usize) -> Result<(), Failure> {
    if count == 0 {
        return Err((ZooStatus::InvalidArgument, "`count` is 0; a batch needs at least one character".into()));
    }
    Ok(())
}

/// An optional buffer: NULL with a length of 0 is empty.
///
/// # Safety
/// As [`slice`].
pub(crate) unsafe fn optional_slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if ptr.is_null() && len == 0 {
        return Ok(&[]);
    }
    unsafe { slice(ptr, len, what) }
}

/// A UTF-8 string from a NUL-terminated C string.
///
/// # Safety
/// `ptr` is NULL or a NUL-terminated string.
pub(crate) unsafe fn c_str<'a>(ptr: *const c_char, what: &str) -> Result<&'a str, Failure> {
    if ptr.is_null() {
        return Err(null(what));
    }
    // SAFETY: the caller gives a NUL-terminated string.
    unsafe { CStr::from_ptr(ptr) }
        .to_str()
        .map_err(|_| (ZooStatus::InvalidArgument, format!("the {what} is not UTF-8")))
}

/// Makes a handle with `make` and writes it through `out` (checked before `make` runs).
///
/// # Safety
/// `out` is NULL or valid for a write.
pub(crate) unsafe fn new_handle<T>(out: *mut *mut T, make: impl FnOnce() -> Result<T, Failure>) -> Result<(), Failure> {
    if out.is_null() {
        return Err(null("out"));
    }
    let boxed = Box::into_raw(Box::new(make()?));
    // SAFETY: checked non-NULL above.
    unsafe { out.write(boxed) };
    Ok(())
}

/// Frees a handle made by [`new_handle`] (NULL is ignored).
///
/// # Safety
/// `ptr` is NULL or a pointer from [`new_handle`] not freed before and not in use.
pub(crate) unsafe fn free_handle<T>(ptr: *mut T) {
    if !ptr.is_null() {
        // SAFETY: a pointer from Box::into_raw in new_handle, freed once.
        drop(unsafe { Box::from_raw(ptr) });
    }
}

/// The model kinds this C ABI loads: kind, task, and the function that loads it.
const LOADERS: [(&str, &str, &str); 4] = [
    ("rtn", "transition", "zoo_model_load"),
    ("arnn", "keyframes", "zoo_keyframe_model_load"),
    ("rmr", "stitch", "zoo_stitch_model_load"),
    ("rnn-gmm", "synthesis", "zoo_synthesis_model_load"),
];

/// The bytes of the model file `path` (a portable export's companion files put back) for the
/// loader of model kind `kind`. A file of another kind this C ABI loads is refused with the
/// function that loads it, one of a kind it does not know with the list; a file without a kind
/// goes to the loader, which says what is missing.
pub(crate) fn read_model(path: &str, kind: &str) -> Result<Vec<u8>, Failure> {
    let bytes = zoo_runtime::portable::assemble(path).map_err(runtime_failure)?;
    let found = zoo_runtime::metadata::model_kind(&bytes);
    let Some(found) = found.filter(|f| f != kind) else { return Ok(bytes) };
    let task = LOADERS.iter().find(|l| l.0 == kind).map_or("", |l| l.1);
    match LOADERS.iter().find(|l| l.0 == found) {
        Some((_, other, function)) => Err((
            ZooStatus::WrongModel,
            format!(
                "{path} is a `{other}` model (kind `{found}`), not a `{task}` model (kind `{kind}`): load it with {function}"
            ),
        )),
        None => {
            let known: Vec<String> = LOADERS.iter().map(|(k, _, f)| format!("`{k}` ({f})")).collect();
            Err((
                ZooStatus::LoadFailed,
                format!(
                    "{path}: unknown model kind `{found}`; this C ABI loads the kinds {} written by `zoo export --onnx`",
                    known.join(", ")
                ),
            ))
        }
    }
}

/// Prefixes a loader's error message with the file it read.
pub(crate) fn in_file(path: &str) -> impl Fn(Failure) -> Failure + '_ {
    move |(status, message)| (status, format!("{path}: {message}"))
}

/// Writes a skeleton: `K` parent indices (-1 for the root) into `parents` and `3K` rest offsets
/// into `offsets`, both checked against `K`.
///
/// # Safety
/// Each buffer is NULL or holds its given length of writable values.
pub(crate) unsafe fn write_skeleton(
    skeleton: (&[i32], &[[f32; 3]]),
    parents: *mut i32,
    parents_len: usize,
    offsets: *mut f32,
    offsets_len: usize,
) -> Result<(), Failure> {
    let k = skeleton.0.len();
    let parents = unsafe { slice_mut(parents, parents_len, "parents") }?;
    let offsets = unsafe { slice_mut(offsets, offsets_len, "offsets") }?;
    check_size("parents", parents.len(), k, "values", "the model's info (`joints`)")?;
    check_size("offsets", offsets.len(), 3 * k, "floats", "the model's info (`joints`)")?;
    parents.copy_from_slice(skeleton.0);
    for (out, o) in offsets.chunks_exact_mut(3).zip(skeleton.1) {
        out.copy_from_slice(o);
    }
    Ok(())
}

/// Writes `value` through the output pointer `out`.
///
/// # Safety
/// `out` is NULL or valid for writes.
pub(crate) unsafe fn write_out<T>(out: *mut T, value: T, what: &str) -> Result<(), Failure> {
    if out.is_null() {
        return Err(null(what));
    }
    unsafe { out.write(value) };
    Ok(())
}

/// Copies the calling thread's last error message into `buffer` (at most `capacity` bytes,
/// NUL-terminated, truncated if needed) and returns the message's full length in bytes without
/// the NUL (0 when the thread has no error). `buffer` may be NULL to ask for the length.
/// Thread-safe.
///
/// # Safety
/// `buffer` is NULL or valid for `capacity` bytes of writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_last_error(buffer: *mut c_char, capacity: usize) -> usize {
    LAST_ERROR.with(|e| {
        let message = e.borrow();
        if !buffer.is_null() && capacity > 0 {
            let n = message.len().min(capacity - 1);
            // SAFETY: the caller gives `capacity` writable bytes; n + 1 <= capacity.
            unsafe {
                std::ptr::copy_nonoverlapping(message.as_ptr(), buffer.cast::<u8>(), n);
                buffer.add(n).write(0);
            }
        }
        message.len()
    })
}

/// Loads a transition model exported by `zoo export --onnx` from the file `path` (UTF-8,
/// NUL-terminated) into `*out`; a `zoo export --portable` main file is loaded with the
/// companion files beside it. Free it with [`zoo_model_free`]. A model of another task is
/// refused with `ZOO_STATUS_WRONG_MODEL` and the function that loads it. Thread-safe.
///
/// # Safety
/// `path` is NULL or a NUL-terminated string; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_load(path: *const c_char, out: *mut *mut ZooModel) -> ZooStatus {
    guard(|| {
        let path = unsafe { c_str(path, "path") }?;
        unsafe {
            new_handle(out, || {
                let loaded = LoadedModel::from_bytes(&read_model(path, "rtn")?).map_err(runtime_failure)?;
                let (kind, task) = (loaded.kind().to_string(), loaded.task());
                let model = loaded.as_transition().cloned().ok_or_else(|| {
                    (
                        ZooStatus::WrongModel,
                        format!(
                            "{path} is a `{task}` model (kind `{kind}`); this C ABI runs transition models (kind rtn): export one with `zoo export --onnx RUN_DIR`"
                        ),
                    )
                })?;
                Ok(ZooModel { model })
            })
        }
    })
}

/// Frees a model from [`zoo_model_load`] (NULL is ignored). Runners and characters made from it
/// keep what they need, so they may be freed before or after it.
///
/// # Safety
/// `model` is NULL or a pointer from [`zoo_model_load`] not freed before.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_free(model: *mut ZooModel) {
    unsafe { free_handle(model) }
}

/// Writes what `model` expects into `*out`. Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_info(model: *const ZooModel, out: *mut ZooModelInfo) -> ZooStatus {
    guard(|| {
        let m = &unsafe { handle(model, "model") }?.model;
        let info = ZooModelInfo {
            joints: m.joints(),
            past_frames: m.past_frames(),
            transition_frames: m.transition_frames(),
            target_blend: m.target_blend(),
            fps: m.model().metadata().fps,
        };
        unsafe { write_out(out, info, "out") }
    })
}

/// Writes the model's skeleton: `parents` receives `K` parent indices (-1 for the root, every
/// parent before its child) and `offsets` `3K` rest offsets from the parent (model units), both
/// in the joint order of every pose. Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; each buffer is NULL or holds its given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_skeleton(
    model: *const ZooModel,
    parents: *mut i32,
    parents_len: usize,
    offsets: *mut f32,
    offsets_len: usize,
) -> ZooStatus {
    guard(|| {
        let skeleton = &unsafe { handle(model, "model") }?.model.model().metadata().skeleton;
        unsafe { write_skeleton((&skeleton.parents, &skeleton.offsets), parents, parents_len, offsets, offsets_len) }
    })
}

/// Creates scratch space for running `model` on one thread at a time into `*out`; free it with
/// [`zoo_runner_free`]. Transitions longer than the trained length are refused unless
/// [`zoo_runner_allow_beyond_trained`].
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_runner_new(model: *const ZooModel, out: *mut *mut ZooRunner) -> ZooStatus {
    guard(|| {
        let m = &unsafe { handle(model, "model") }?.model;
        unsafe { new_handle(out, || Ok(ZooRunner { runner: m.runner().map_err(runtime_failure)? })) }
    })
}

/// Frees a runner (NULL is ignored).
///
/// # Safety
/// `runner` is NULL or a pointer from [`zoo_runner_new`] not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_runner_free(runner: *mut ZooRunner) {
    unsafe { free_handle(runner) }
}

/// Whether `runner` accepts transitions longer than the model was trained for (off by default:
/// beyond its training length the network drifts from the target).
///
/// # Safety
/// `runner` is NULL or a live runner used by this thread only.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_runner_allow_beyond_trained(runner: *mut ZooRunner, allow: bool) -> ZooStatus {
    guard(|| {
        unsafe { handle_mut(runner, "runner") }?.runner.allow_beyond_trained(allow);
        Ok(())
    })
}

/// Creates the transition states of `count` characters of `model` into `*out`; free them with
/// [`zoo_characters_free`].
///
/// # Safety
/// `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_characters_new(
    model: *const ZooModel,
    count: usize,
    out: *mut *mut ZooCharacters,
) -> ZooStatus {
    guard(|| {
        let m = &unsafe { handle(model, "model") }?.model;
        unsafe {
            new_handle(out, || {
                check_count(count)?;
                let k = m.joints();
                Ok(ZooCharacters {
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
/// `characters` is NULL or a pointer from [`zoo_characters_new`] not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_characters_free(characters: *mut ZooCharacters) {
    unsafe { free_handle(characters) }
}

/// Starts a transition of `length` frames for every character from global joint positions:
/// `past` holds `N * frames * 3K` values (the same number of context frames per character),
/// `target` and `next` `N * 3K` each (the target pose and the pose after it). `length` is the
/// number of frames before the target frame; pass the model's `transition_frames` for the
/// trained length. Then step it with [`zoo_step`].
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_start(
    runner: *mut ZooRunner,
    characters: *mut ZooCharacters,
    past: *const f32,
    past_len: usize,
    target: *const f32,
    target_len: usize,
    next: *const f32,
    next_len: usize,
    length: usize,
) -> ZooStatus {
    guard(|| {
        let runner = &mut unsafe { handle_mut(runner, "runner") }?.runner;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let past = unsafe { slice(past, past_len, "past") }?;
        let target = unsafe { slice(target, target_len, "target") }?;
        let next = unsafe { slice(next, next_len, "next") }?;
        runner.start_batch_for(&mut chars.states, past, target, next, length).map_err(start_failure)
    })
}

/// The next frame of every character's transition into `poses` (`N * 3K` global positions): the
/// target-blended frames, the last one the target. Stepping past the target frame is
/// `ZOO_STATUS_INVALID_STATE`.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; `poses` is NULL or holds `poses_len`
/// writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_step(
    runner: *mut ZooRunner,
    characters: *mut ZooCharacters,
    poses: *mut f32,
    poses_len: usize,
) -> ZooStatus {
    guard(|| {
        let runner = &mut unsafe { handle_mut(runner, "runner") }?.runner;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let poses = unsafe { slice_mut(poses, poses_len, "poses") }?;
        runner.step_batch(&mut chars.states, poses).map_err(runtime_failure)
    })
}

/// Reads an engine pose from its root and `4K` rotation values (the deltas are not read).
pub(crate) fn read_pose(root: &ZooRootMotion, rotations: &[f32], pose: &mut EnginePose) {
    pose.root_position = Vec3::from_array(root.root_position);
    pose.root_rotation = Quat::from_array(root.root_rotation);
    pose.hips_position = Vec3::from_array(root.hips_position);
    for (q, r) in pose.local_rotations.iter_mut().zip(rotations.chunks_exact(4)) {
        *q = Quat::from_xyzw(r[0], r[1], r[2], r[3]);
    }
}

/// Writes an engine pose as its root and `4K` rotation values.
pub(crate) fn write_pose(pose: &EnginePose, root: &mut ZooRootMotion, rotations: &mut [f32]) {
    *root = ZooRootMotion {
        root_position: pose.root_position.to_array(),
        root_rotation: pose.root_rotation.to_array(),
        delta_position: pose.root_delta_position.to_array(),
        delta_yaw: pose.root_delta_yaw,
        hips_position: pose.hips_position.to_array(),
    };
    for (out, q) in rotations.chunks_exact_mut(4).zip(&pose.local_rotations) {
        out.copy_from_slice(&q.to_array());
    }
}

/// Reads engine poses from `roots` (one per pose) and `rotations` (`4K` values per root, its
/// length checked) into `poses`, resized to one per root.
pub(crate) fn read_poses(
    roots: &[ZooRootMotion],
    rotations: &[f32],
    k: usize,
    poses: &mut Vec<EnginePose>,
    info: &str,
) -> Result<(), Failure> {
    check_size("rotations", rotations.len(), roots.len() * 4 * k, "floats", info)?;
    poses.resize_with(roots.len(), || EnginePose::new(k));
    for ((root, rotations), pose) in roots.iter().zip(rotations.chunks_exact(4 * k)).zip(poses.iter_mut()) {
        read_pose(root, rotations, pose);
    }
    Ok(())
}

/// The output buffers of a call that writes engine poses: a root, `4K` rotation values and
/// some contact bytes per pose.
pub(crate) struct PoseOut<'a> {
    roots: &'a mut [ZooRootMotion],
    rotations: &'a mut [f32],
    contacts: &'a mut [u8],
    names: [&'a str; 3],
}

/// A buffer argument: pointer, length and name.
pub(crate) type Buffer<'a, T> = (*mut T, usize, &'a str);

impl<'a> PoseOut<'a> {
    /// The buffers, each non-NULL.
    ///
    /// # Safety
    /// Each pointer is NULL or holds its given length of writable values.
    pub(crate) unsafe fn new(
        roots: Buffer<'a, ZooRootMotion>,
        rotations: Buffer<'a, f32>,
        contacts: Buffer<'a, u8>,
    ) -> Result<Self, Failure> {
        Ok(PoseOut {
            roots: unsafe { slice_mut(roots.0, roots.1, roots.2) }?,
            rotations: unsafe { slice_mut(rotations.0, rotations.1, rotations.2) }?,
            contacts: unsafe { slice_mut(contacts.0, contacts.1, contacts.2) }?,
            names: [roots.2, rotations.2, contacts.2],
        })
    }

    /// Checks that the buffers hold `n` poses of `k` joints and `per` contacts each (`each`:
    /// what there is one pose per, for the message; `info`: where `K` comes from).
    pub(crate) fn check(&self, n: usize, k: usize, per: usize, each: &str, info: &str) -> Result<(), Failure> {
        let [roots, rotations, contacts] = self.names;
        check_size(roots, self.roots.len(), n, "roots", &format!("one per {each}"))?;
        check_size(rotations, self.rotations.len(), n * 4 * k, "floats", &format!("4 `joints` per {each}, {info}"))?;
        check_size(contacts, self.contacts.len(), n * per, "bytes", &format!("{per} per {each}"))
    }

    /// Writes pose `i` and its contacts (checked sizes).
    pub(crate) fn write(&mut self, i: usize, pose: &EnginePose, contacts: &[bool]) {
        let (k, per) = (pose.joints(), contacts.len());
        write_pose(pose, &mut self.roots[i], &mut self.rotations[i * 4 * k..(i + 1) * 4 * k]);
        for (o, c) in self.contacts[i * per..(i + 1) * per].iter_mut().zip(contacts) {
            *o = u8::from(*c);
        }
    }
}

/// Starts a transition of `length` frames for every character from engine poses: each pose is a
/// [`ZooRootMotion`] and `4K` rotation values. `past_roots` holds `N * frames` roots (the same
/// number of context frames per character, character-major) and `past_rotations` `4K` values
/// per root; `target_*` and `next_*` one pose per character. Then [`zoo_step_posed`].
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_start_posed(
    runner: *mut ZooRunner,
    characters: *mut ZooCharacters,
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
    guard(|| {
        let runner = &mut unsafe { handle_mut(runner, "runner") }?.runner;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let past_roots = unsafe { slice(past_roots, past_roots_len, "past_roots") }?;
        let past_rotations = unsafe { slice(past_rotations, past_rotations_len, "past_rotations") }?;
        let target_roots = unsafe { slice(target_roots, n, "target_roots") }?;
        let next_roots = unsafe { slice(next_roots, n, "next_roots") }?;
        check_len("target_rotations / next_rotations (rotations_len)", rotations_len, n * 4 * k, "floats")?;
        let target_rotations = unsafe { slice(target_rotations, rotations_len, "target_rotations") }?;
        let next_rotations = unsafe { slice(next_rotations, rotations_len, "next_rotations") }?;
        if past_roots.is_empty() || !past_roots.len().is_multiple_of(n) {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`past_roots` holds {} roots; it needs the same number of context frames (at least one) for each of the {n} characters",
                    past_roots.len()
                ),
            ));
        }
        check_len("past_rotations", past_rotations.len(), past_roots.len() * 4 * k, "floats")?;
        let frames = past_roots.len() / n;
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
        debug_assert_eq!(past.len(), n * frames);
        let result = runner.start_posed_batch_for(&mut chars.states, past, target, next, length);
        chars.inputs = inputs;
        result.map_err(start_failure)
    })
}

/// The next frame of every character's transition (started with [`zoo_start_posed`]) as engine
/// poses: `roots` receives `N` [`ZooRootMotion`] and `rotations` `N * 4K` local rotations (the
/// hips' relative to the root), fitted to the network's frame inside the runtime.
///
/// # Safety
/// Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length of writable values.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_step_posed(
    runner: *mut ZooRunner,
    characters: *mut ZooCharacters,
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
) -> ZooStatus {
    guard(|| {
        let runner = &mut unsafe { handle_mut(runner, "runner") }?.runner;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let (n, k) = (chars.states.len(), chars.joints);
        let roots = unsafe { slice_mut(roots, roots_len, "roots") }?;
        let rotations = unsafe { slice_mut(rotations, rotations_len, "rotations") }?;
        check_len("roots", roots.len(), n, "roots")?;
        check_len("rotations", rotations.len(), n * 4 * k, "floats")?;
        runner.step_posed_batch(&mut chars.states, &mut chars.poses).map_err(runtime_failure)?;
        for ((pose, root), rotations) in chars.poses.iter().zip(roots).zip(rotations.chunks_exact_mut(4 * k)) {
            write_pose(pose, root, rotations);
        }
        Ok(())
    })
}

/// The terrain patch of a terrain-aware transition model: `*side` samples per side on a square
/// of `*extent` model units around the root. `ZOO_STATUS_NOT_AVAILABLE` for a model without
/// terrain input (a flat-ground model). Thread-safe.
///
/// # Safety
/// `model` is NULL or a live model; `side` and `extent` are NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_terrain(model: *const ZooModel, side: *mut usize, extent: *mut f32) -> ZooStatus {
    guard(|| {
        let m = &unsafe { handle(model, "model") }?.model;
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

/// Sets the ground under character `index`: a heightmap of `cols * rows` heights (model units,
/// Y up) on a regular grid in the XZ plane, sample `(i, k)` at `(origin_x + i * cell, origin_z +
/// k * cell)` stored at `heights[k * cols + i]`, bilinear between samples and extended beyond
/// the border (the `zoo-heightfield` layout of `zoo data synth --terrain`). The map is copied.
/// A terrain-aware model ([`zoo_model_terrain`]) needs it before [`zoo_start`] or
/// [`zoo_start_posed`]; a flat-ground model ignores it. `heights` NULL with `heights_len` 0
/// removes the ground. Takes effect at the next step. One thread at a time.
///
/// # Safety
/// `characters` is NULL or live and used by this thread only; `heights` is NULL or holds
/// `heights_len` floats.
#[unsafe(no_mangle)]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn zoo_characters_set_heightmap(
    characters: *mut ZooCharacters,
    index: usize,
    cols: usize,
    rows: usize,
    cell: f32,
    origin_x: f32,
    origin_z: f32,
    heights: *const f32,
    heights_len: usize,
) -> ZooStatus {
    guard(|| {
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
        check_size("heights", heights.len(), cols.saturating_mul(rows), "floats (cols * rows)", "its cols and rows")?;
        if !(cell.is_finite() && cell > 0.0) {
            return Err(invalid(format!("`cell` is {cell}; the distance between samples must be a positive number")));
        }
        if !(origin_x.is_finite() && origin_z.is_finite()) {
            return Err(invalid(format!("the origin ({origin_x}, {origin_z}) must be finite")));
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
pub unsafe extern "C" fn zoo_frames_left(characters: *const ZooCharacters, index: usize, out: *mut usize) -> ZooStatus {
    guard(|| {
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
pub unsafe extern "C" fn zoo_target_miss(
    characters: *const ZooCharacters,
    index: usize,
    mean: *mut f32,
    max: *mut f32,
) -> ZooStatus {
    guard(|| {
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

fn character(chars: &ZooCharacters, index: usize) -> Result<&TransitionState, Failure> {
    chars.states.get(index).ok_or_else(|| {
        (
            ZooStatus::InvalidArgument,
            format!("character {index} does not exist: the batch has {} (0-based)", chars.states.len()),
        )
    })
}
