//! The C ABI of the zoo engine runtime (`zoo-runtime`), for engines that cannot link Rust:
//! Unity (P/Invoke), Unreal and Godot (C/C++), or any language with a C FFI.
//!
//! One loader, one model handle, one naming pattern per task:
//! - `zoo_model_load` loads any file written by `zoo export --onnx` (or a `--portable` main
//!   file with its companions) into a `ZooModel`; `zoo_model_task` says its task
//!   (`ZooTask`); `zoo_model_info`, `zoo_model_skeleton` and `zoo_model_joint_name`
//!   describe every model (joints, frame rate, units and axes, skeleton, joint names); `zoo_model_free` frees it (`model.rs`).
//! - Each task's functions take that handle and share a prefix:
//!   - `zoo_transition_*`: transitions (RTN, task `transition`): `ZooTransitionRunner`,
//!     `ZooTransitionCharacters`, start from positions or engine poses, one step per frame
//!     (`transition.rs`);
//!   - `zoo_keyframes_*`: keyframe completion (ARNN, task `keyframes`): `ZooKeyframesRunner`
//!     (`keyframes.rs`);
//!   - `zoo_stitch_*`: locomotion stitching (RMR, task `stitch`): the whole-sequence
//!     `zoo_stitch_refine` and the streaming `ZooStitchStream` (`stitch.rs`);
//!   - `zoo_synthesis_*`: random synthesis (RNN-GMM, task `synthesis`):
//!     `ZooSynthesisRunner`, `ZooSynthesisCharacters` (`synthesis.rs`);
//!   - `zoo_control_*`: speed / facing control of a `synthesis` model: `ZooControlRunner`,
//!     `ZooControlCharacters` (`control.rs`).
//!
//!   A function given a model of another task returns `ZOO_STATUS_WRONG_MODEL`, and its message
//!   names the task of the model and the functions that run it.
//! - `zoo_pose_convert` and `zoo_positions_convert` convert poses and positions in place
//!   between the model's units and axes and an engine's (`ZooCoordinateFrame`: Unity's metres,
//!   left-handed, Y up; Unreal's centimetres, left-handed, Z up), with the runtime's conversion
//!   (`frame.rs`).
//! - `zoo_abi_version` is the version of this ABI (`ZOO_ABI_VERSION` in the header an engine
//!   compiled against); it goes up whenever the ABI changes incompatibly.
//!
//! The header `include/zoo.h` is generated from these files by cbindgen
//! (`runtime/capi/cbindgen.toml`) and checked up to date by `tests/capi.rs`;
//! `examples/transition.c` (a transition engine loop) and `examples/tasks.c` (keyframes,
//! stitching, synthesis and control, dispatched on `zoo_model_task`) are complete programs
//! that compile as C99 and as C++17.
//!
//! # Conventions
//! - Every fallible function returns a `ZooStatus`; `ZOO_STATUS_OK` is 0. On any other status,
//!   `zoo_last_error` gives a readable message (per thread) that starts with the function's
//!   name and names the problem and the fix in C terms: C functions and C argument names.
//! - Handles are opaque (models, runners, characters, streams). Each has a `_free` function
//!   that accepts NULL.
//! - Buffers are passed as a pointer and a length in elements; the length is checked against what
//!   the call needs, and a mismatch is an error, not a read past the buffer. An optional buffer
//!   is NULL with a length of 0.
//! - No panic crosses the boundary: one is caught and reported as `ZOO_STATUS_PANIC`.
//! - A per-frame call (a step, a stream push or pop) allocates nothing once its handles exist.
//! - Poses in positions are global joint positions, joint-major (`x0 y0 z0 x1 ...`), character-major
//!   across a batch. Rotations are quaternions `x y z w`, joint-major, the model skeleton's order.
//!   An engine pose is a `ZooRootMotion` and `4K` local rotations (`K` joints); a batch or a
//!   sequence of them is an array of roots and one rotation buffer of `4K` values per root.
//!   Contacts are bytes, 1 for a foot on the ground and 0 otherwise. Units and axes are the
//!   model's (`ZooModelInfo`); `zoo_pose_convert` converts them to an engine's.
//!
//! # Thread safety
//! - A loaded model is immutable after loading: any number of threads may use it at once (create
//!   runners, characters and streams from it, read its info, refine a whole stitching
//!   sequence). Free it after everything made from it, or before: what is made from a model
//!   keeps what it needs. Two calls change a model and need it to themselves:
//!   `zoo_stitch_set_window` and `zoo_synthesis_set_refine`.
//! - Runners, characters and streams may be used by one thread at a time (move them between
//!   threads freely); a call takes one runner and one characters handle, so threads each with
//!   their own pair run in parallel.
//! - The conversions (`zoo_pose_convert`, `zoo_positions_convert`) are thread-safe.
//! - `zoo_last_error` reports the last error of the calling thread.

// The boundary itself needs raw pointers; every other crate of the workspace denies unsafe code.
#![allow(unsafe_code)]
// The doc comments are the C header's (cbindgen copies them): each unsafe function states its
// contract in a plain "Safety:" paragraph that reads well in C, not rustdoc's `# Safety` heading.
#![allow(clippy::missing_safety_doc)]

// The modules in the order a user meets them; cbindgen writes the header's functions in this
// order (one group each, so that rustfmt keeps it).
mod model;
// Tasks, in the order of the documentation.
mod transition;
//
mod keyframes;
//
mod stitch;
//
mod synthesis;
//
mod control;
// Engine coordinate frames.
mod frame;
// Errors, version, logging.
mod diagnostics;
mod error;

pub use control::*;
pub use diagnostics::*;
pub use frame::*;
pub use keyframes::*;
pub use model::*;
pub use stitch::*;
pub use synthesis::*;
pub use transition::*;

pub(crate) use error::{Failure, guard, runtime_failure};

use std::ffi::{CStr, c_char};
use zoo_runtime::EnginePose;
use zoo_runtime::glam::{Quat, Vec3};

/// The version of this C ABI. `zoo_abi_version` returns the library's; an engine compares it
/// with the value of the header it was compiled against and refuses to run on a mismatch.
/// Version 2: one loader and one model handle for every task, `zoo_<task>_*` functions (version
/// 1 had a loader and a model type per task, and unprefixed transition functions).
pub const ZOO_ABI_VERSION: u32 = 3;

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
    /// The model file cannot be read or is not an exported zoo model of a task this library
    /// runs.
    LoadFailed = 3,
    /// The model is of another task than the function's (the message names the functions that
    /// run it).
    WrongModel = 4,
    /// The call does not fit where the handle stands (a transition not started, already
    /// finished or longer than the model was trained for; characters not started; a stitching
    /// stream finished or too short to finish; a model still in use).
    InvalidState = 5,
    /// The graph failed to run.
    RunFailed = 6,
    /// The requested value is not known yet (e.g. the target miss before the blend window, a
    /// stitching stream's next pose before it is ready) or the model has no such thing (the
    /// terrain patch of a flat-ground transition model).
    NotAvailable = 7,
    /// An internal error (a caught panic): please report it with the message.
    Panic = 8,
}

/// The root of an engine pose (the runtime's `EnginePose`): the hips projected on the ground
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

/// The version of this library's C ABI: `ZOO_ABI_VERSION` of the header it was built with.
/// Thread-safe.
#[unsafe(no_mangle)]
pub extern "C" fn zoo_abi_version() -> u32 {
    ZOO_ABI_VERSION
}

pub(crate) fn null(what: &str) -> Failure {
    (ZooStatus::NullPointer, format!("`{what}` is NULL; pass a valid pointer"))
}

/// A shared reference from a handle pointer.
///
/// Safety: `ptr` is NULL or a valid pointer to a live `T`.
pub(crate) unsafe fn handle<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    unsafe { ptr.as_ref() }.ok_or_else(|| null(what))
}

/// A mutable reference from a handle pointer.
///
/// Safety: `ptr` is NULL or a valid, exclusively used pointer to a live `T`.
pub(crate) unsafe fn handle_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    unsafe { ptr.as_mut() }.ok_or_else(|| null(what))
}

/// A slice from a pointer and a length.
///
/// Safety: `ptr` is NULL or points to `len` readable values.
pub(crate) unsafe fn slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if ptr.is_null() {
        return Err(null(what));
    }
    check_length::<T>(len, what)?;
    Ok(unsafe { std::slice::from_raw_parts(ptr, len) })
}

/// A mutable slice from a pointer and a length.
///
/// Safety: `ptr` is NULL or points to `len` writable values not aliased elsewhere during the call.
pub(crate) unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize, what: &str) -> Result<&'a mut [T], Failure> {
    if ptr.is_null() {
        return Err(null(what));
    }
    check_length::<T>(len, what)?;
    Ok(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
}

/// Refuses a buffer length no buffer can have (more bytes than half the address space: a
/// negative count cast to `size_t`, or `SIZE_MAX`), before it is read.
fn check_length<T>(len: usize, what: &str) -> Result<(), Failure> {
    let bytes = len.checked_mul(std::mem::size_of::<T>().max(1));
    if bytes.is_none_or(|b| b > isize::MAX as usize) {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "the length of `{what}` is {len}, more than any buffer can hold (a negative count converted to \
                 size_t?); pass the buffer's real length in elements"
            ),
        ));
    }
    Ok(())
}

/// An optional buffer: NULL with a length of 0 is empty.
///
/// Safety: As `slice`.
pub(crate) unsafe fn optional_slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if ptr.is_null() && len == 0 {
        return Ok(&[]);
    }
    unsafe { slice(ptr, len, what) }
}

/// An optional mutable buffer: NULL with a length of 0 is empty.
///
/// Safety: As `slice_mut`.
pub(crate) unsafe fn optional_slice_mut<'a, T>(ptr: *mut T, len: usize, what: &str) -> Result<&'a mut [T], Failure> {
    if ptr.is_null() && len == 0 {
        return Ok(&mut []);
    }
    unsafe { slice_mut(ptr, len, what) }
}

/// Refuses a buffer `what` of `found` `unit` where the call needs `expected`; `info` says where
/// its size comes from (formatted only on a refusal: pass `format_args!`, not `format!`, so that a
/// per-frame call allocates nothing).
pub(crate) fn check_size(
    what: &str,
    found: usize,
    expected: usize,
    unit: &str,
    info: impl std::fmt::Display,
) -> Result<(), Failure> {
    if found != expected {
        return Err((
            ZooStatus::InvalidArgument,
            format!("`{what}` holds {found} {unit}, this call needs {expected}; size it from {info}"),
        ));
    }
    Ok(())
}

/// Where the joint count `K` of every pose buffer comes from.
pub(crate) const JOINTS: &str = "zoo_model_info's `joints`";

/// The most characters one handle holds or one call runs (`count`, `max_batch`): a larger count
/// is refused before anything is allocated. Make several handles for a larger crowd.
pub const ZOO_MAX_BATCH: usize = 65_536;

/// The most frames one call completes or refines (a sequence, a shot): about 9.7 hours at 30
/// frames per second. A longer one is refused before anything is allocated.
pub const ZOO_MAX_FRAMES: usize = 1_048_576;

/// Refuses a count of characters `name` of 0 or above `ZOO_MAX_BATCH` (before anything is
/// allocated for them).
pub(crate) fn check_count(name: &str, count: usize) -> Result<(), Failure> {
    if count == 0 {
        return Err((ZooStatus::InvalidArgument, format!("`{name}` is 0; a batch needs at least one character")));
    }
    if count > ZOO_MAX_BATCH {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "`{name}` is {count}, more than ZOO_MAX_BATCH ({ZOO_MAX_BATCH}) characters; split the crowd over \
                 several handles of at most {ZOO_MAX_BATCH}"
            ),
        ));
    }
    Ok(())
}

/// Refuses a call on `count` characters with a runner made for at most `max_batch` (the
/// runner's `max_batch`: its scratch space is sized for it, so a call allocates nothing).
pub(crate) fn check_batch(count: usize, max_batch: usize, runner_new: &str) -> Result<(), Failure> {
    if count > max_batch {
        return Err((
            ZooStatus::InvalidArgument,
            format!(
                "the characters are a batch of {count}, more than the runner's `max_batch` ({max_batch}); make the \
                 runner with {runner_new} and a `max_batch` of at least {count}"
            ),
        ));
    }
    Ok(())
}

/// A UTF-8 string from a NUL-terminated C string.
///
/// Safety: `ptr` is NULL or a NUL-terminated string.
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
/// Safety: `out` is NULL or valid for a write.
pub(crate) unsafe fn new_handle<T>(out: *mut *mut T, make: impl FnOnce() -> Result<T, Failure>) -> Result<(), Failure> {
    if out.is_null() {
        return Err(null("out"));
    }
    let boxed = Box::into_raw(Box::new(make()?));
    // SAFETY: checked non-NULL above.
    unsafe { out.write(boxed) };
    Ok(())
}

/// Frees a handle made by `new_handle` (NULL is ignored).
///
/// Safety: `ptr` is NULL or a pointer from `new_handle` not freed before and not in use.
pub(crate) unsafe fn free_handle<T>(ptr: *mut T) {
    if !ptr.is_null() {
        // SAFETY: a pointer from Box::into_raw in new_handle, freed once.
        drop(unsafe { Box::from_raw(ptr) });
    }
}

/// Writes `value` through the output pointer `out`.
///
/// Safety: `out` is NULL or valid for writes.
pub(crate) unsafe fn write_out<T>(out: *mut T, value: T, what: &str) -> Result<(), Failure> {
    if out.is_null() {
        return Err(null(what));
    }
    unsafe { out.write(value) };
    Ok(())
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
) -> Result<(), Failure> {
    check_size("rotations", rotations.len(), roots.len() * 4 * k, "floats", format_args!("4 * {JOINTS} per root"))?;
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
    /// Safety: Each pointer is NULL or holds its given length of writable values.
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
    /// what there is one pose per, for the message).
    pub(crate) fn check(&self, n: usize, k: usize, per: usize, each: &str) -> Result<(), Failure> {
        let [roots, rotations, contacts] = self.names;
        check_size(roots, self.roots.len(), n, "roots", format_args!("one per {each}"))?;
        check_size(rotations, self.rotations.len(), n * 4 * k, "floats", format_args!("4 * {JOINTS} per {each}"))?;
        check_size(contacts, self.contacts.len(), n * per, "bytes", format_args!("{per} per {each}"))
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
