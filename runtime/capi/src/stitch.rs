//! Locomotion stitching (RMR, task `stitch`, `zoo_runtime::stitch`): a `stitch` model refines
//! motion put together from clips (aligned end to start, at the model's frame rate, on its
//! skeleton: `crate::zoo_model_skeleton`), either a whole sequence at once
//! (`zoo_stitch_refine`) or as a stream for motion matching (`ZooStitchStream`: one pose
//! pushed per frame, refined poses popped with a fixed latency: `ZooStitchInfo.latency` frames
//! with the ankle IK, the seam guard and the foot lock of `zoo stitch`, `window` frames without
//! them, `zoo_stitch_stream_set_cleanup`).
//!
//! Poses are engine poses: a `ZooRootMotion` and `4K` local rotations each. Contacts are 4
//! bytes per frame, heel left, toe left, heel right, toe right (1: on the ground).

use crate::model::model;
use crate::{
    Failure, JOINTS, PoseOut, ZooModel, ZooRootMotion, ZooStatus, check_size, free_handle, guard, handle, handle_mut,
    new_handle, read_pose, read_poses, runtime_failure, slice, write_out,
};
use std::sync::Arc;
use zoo_runtime::stitch::{FootCleanup, StitchRefiner, StitchStreamOf};
use zoo_runtime::{EnginePose, MotionError};

/// A stitching stream (opaque): poses pushed one per frame, refined poses popped `latency`
/// frames later. One thread at a time.
pub struct ZooStitchStream {
    /// Holds the model's refiner (an `Arc`), so the stream outlives nothing it needs, and
    /// `zoo_stitch_set_window` refuses to change that refiner while this handle lives.
    stream: StitchStreamOf<Arc<StitchRefiner>>,
    pose: EnginePose,
}

/// What a stitching model expects besides `ZooModelInfo` (whose `fps` the motion must
/// have, and whose `joints` every pose).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooStitchInfo {
    /// Frames per refined window `w`: a sequence needs at least this many frames.
    pub window: usize,
    /// Frames between windows `s`.
    pub stride: usize,
    /// Frames over which each window's first-frame difference is blended away.
    pub blend_frames: usize,
    /// Latency of a new stream in frames (`w`, + `s - 1` for each window's work spread over the
    /// pushes after it and a seam's frame encoded one push late, + the lookahead of its foot
    /// lock, seam guard and seams' reach + the frames they release at once - 1: 178 for `w` =
    /// 60, `s` = 30): the refined pose of frame `t` is ready once frame `t + latency` is pushed.
    /// A stream without them (`zoo_stitch_stream_set_cleanup`, the guard off, the reach 0) has
    /// `w + s - 1`: `zoo_stitch_stream_latency`.
    pub latency: usize,
}

/// Writes what a stitching model expects into `*out` (for the window it is planned for).
/// Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_info(model: *const ZooModel, out: *mut ZooStitchInfo) -> ZooStatus {
    guard("zoo_stitch_info", || {
        let r = unsafe { self::model(model) }?.stitch()?;
        let info = ZooStitchInfo {
            window: r.window(),
            stride: r.stride(),
            blend_frames: r.blend_frames(),
            latency: r.stream().latency(),
        };
        unsafe { write_out(out, info, "out") }
    })
}

/// The refiner of a model no stream uses, for a call that changes it (`doing`: what the call
/// does, for the message); `ZOO_STATUS_INVALID_STATE` while streams made from it are alive.
fn without_streams<'a>(m: &'a mut Arc<StitchRefiner>, doing: &str) -> Result<&'a mut StitchRefiner, Failure> {
    Arc::get_mut(m).ok_or_else(|| {
        (
            ZooStatus::InvalidState,
            format!("streams made from this model are alive; free them (zoo_stitch_stream_free) before {doing}"),
        )
    })
}

/// The longest window `zoo_stitch_set_window` plans (frames).
pub const ZOO_MAX_WINDOW: usize = 4096;

/// Plans the model for another window `w` and stride `s` (`1 <= s <= w`; shorter windows give
/// streams less latency, at the quality the stitching benchmark measures for them). Not
/// thread-safe: no other thread may use the model during the call, and streams made from it
/// must be freed first (`ZOO_STATUS_INVALID_STATE` otherwise).
///
/// Safety: `model` is NULL or a live model used by no other thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_set_window(model: *mut ZooModel, window: usize, stride: usize) -> ZooStatus {
    guard("zoo_stitch_set_window", || {
        let m = unsafe { handle_mut(model, "model") }?.stitch_mut()?;
        if window > ZOO_MAX_WINDOW {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`window` is {window} frames, more than ZOO_MAX_WINDOW ({ZOO_MAX_WINDOW}); the model is trained \
                     on windows of tens of frames (zoo_stitch_info's `window`)"
                ),
            ));
        }
        without_streams(m, "planning another window")?.set_window(window, stride).map_err(runtime_failure)
    })
}

/// Writes into `*out` whether the model was trained on clips inertialized at their seams
/// (`zoo train rmr`'s default since 2026-11-28; the file's `stitch.pre_blend`): refine such a
/// model's sequences with `zoo_stitch_refine_at_seams` and mark a stream's seams
/// (`zoo_stitch_stream_mark_seam`), as `zoo stitch` does. Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_pre_blend(model: *const ZooModel, out: *mut bool) -> ZooStatus {
    guard("zoo_stitch_pre_blend", || {
        let r = unsafe { self::model(model) }?.stitch()?;
        unsafe { write_out(out, r.pre_blend(), "out") }
    })
}

/// Switches the seam guard of `zoo_stitch_refine_at_seams` on (the default, as `zoo stitch`)
/// or off: where the refined motion, after the ankle IK, moves a joint faster within 5 frames
/// of a seam than the inertialized input does there, it is blended towards itself smoothed until
/// it does not, before the foot lock. Not thread-safe, as `zoo_stitch_set_window`: no other
/// thread may use the model during the call, and streams made from it must be freed first.
///
/// Safety: `model` is NULL or a live model used by no other thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_set_seam_guard(model: *mut ZooModel, on: bool) -> ZooStatus {
    guard("zoo_stitch_set_seam_guard", || {
        let m = unsafe { handle_mut(model, "model") }?.stitch_mut()?;
        without_streams(m, "switching the seam guard")?.set_seam_guard(on);
        Ok(())
    })
}

/// Sets the seams' reach of `zoo_stitch_refine_at_seams` and of the streams made afterwards:
/// frames `frames` or more from every seam are left as they were given, frames within half of
/// it are the refined output, eased from one to the other between (each stretch near seams first
/// moved on the ground to start on the input's ground root), as `zoo stitch --seam-reach` does.
/// 0 refines the whole sequence (`zoo stitch --refine-everywhere`). Default: the model's window,
/// as `zoo stitch`. A stream with a reach passes the frames away from every marked seam through
/// as they were pushed. Not thread-safe, as `zoo_stitch_set_window`.
///
/// Safety: `model` is NULL or a live model used by no other thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_set_seam_reach(model: *mut ZooModel, frames: usize) -> ZooStatus {
    guard("zoo_stitch_set_seam_reach", || {
        let m = unsafe { handle_mut(model, "model") }?.stitch_mut()?;
        without_streams(m, "setting the seams' reach")?
            .set_seam_reach((frames > 0).then_some(frames))
            .map_err(runtime_failure)
    })
}

/// Writes into `*out` the seams' reach of `zoo_stitch_set_seam_reach` (0: the whole sequence is
/// refined). Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_seam_reach(model: *const ZooModel, out: *mut usize) -> ZooStatus {
    guard("zoo_stitch_seam_reach", || {
        let r = unsafe { self::model(model) }?.stitch()?;
        unsafe { write_out(out, r.seam_reach().unwrap_or(0), "out") }
    })
}

/// Refines a whole aligned sequence of `frames` poses (`roots` holds `frames` roots, `rotations`
/// `frames * 4K` floats; at least `window` frames) into `out_roots` / `out_rotations` (the same
/// sizes, root deltas filled, zero on the first frame) and the predicted contacts into
/// `contacts` (`frames * 4` bytes). `place_ankles` puts the ankles where the refiner predicts
/// them and `lock_feet` locks the planted feet by the predicted contacts (both on: what
/// `zoo stitch` writes). Allocates the sequence's scratch space per call. Thread-safe: threads may
/// refine with one model at once.
///
/// Safety: `model` is NULL or a live model; each buffer is NULL or holds its given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_refine(
    model: *const ZooModel,
    roots: *const ZooRootMotion,
    frames: usize,
    rotations: *const f32,
    rotations_len: usize,
    place_ankles: bool,
    lock_feet: bool,
    out_roots: *mut ZooRootMotion,
    out_roots_len: usize,
    out_rotations: *mut f32,
    out_rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> ZooStatus {
    let input = (roots, frames, rotations, rotations_len, std::ptr::null(), 0);
    let outs = (out_roots, out_roots_len, out_rotations, out_rotations_len, contacts, contacts_len);
    unsafe { refine_guarded("zoo_stitch_refine", model, input, FootCleanup { place_ankles, lock_feet }, outs) }
}

/// `zoo_stitch_refine` of the sequence inertialized at `seams` first (`seams_len` frame
/// indices where a clip starts, each below `frames`): from each seam on, the jump to the
/// previous clip decays over `blend_frames` frames before the refiner runs (`zoo stitch
/// --pre-blend`; what a model trained on inertialized seams needs: `zoo_stitch_pre_blend`).
/// Seams on frames 0, 1 and the last change nothing. With seams given, the seams are also
/// guarded against pops after the ankle IK (`zoo_stitch_set_seam_guard`). Thread-safe.
///
/// Safety: `model` is NULL or a live model; each buffer is NULL or holds its given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_refine_at_seams(
    model: *const ZooModel,
    roots: *const ZooRootMotion,
    frames: usize,
    rotations: *const f32,
    rotations_len: usize,
    seams: *const usize,
    seams_len: usize,
    place_ankles: bool,
    lock_feet: bool,
    out_roots: *mut ZooRootMotion,
    out_roots_len: usize,
    out_rotations: *mut f32,
    out_rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> ZooStatus {
    let input = (roots, frames, rotations, rotations_len, seams, seams_len);
    let outs = (out_roots, out_roots_len, out_rotations, out_rotations_len, contacts, contacts_len);
    unsafe { refine_guarded("zoo_stitch_refine_at_seams", model, input, FootCleanup { place_ankles, lock_feet }, outs) }
}

/// The input buffers of `zoo_stitch_refine_at_seams`: roots (`frames` of them), rotations,
/// seams (NULL when there are none).
type RefineInput = (*const ZooRootMotion, usize, *const f32, usize, *const usize, usize);

/// The output buffers of `zoo_stitch_refine`: roots, rotations and contacts with their lengths.
type RefineOutput = (*mut ZooRootMotion, usize, *mut f32, usize, *mut u8, usize);

/// What `zoo_stitch_refine` and `zoo_stitch_refine_at_seams` do, errors named `function`.
///
/// Safety: As for `zoo_stitch_refine_at_seams`.
unsafe fn refine_guarded(
    function: &'static str,
    model: *const ZooModel,
    input: RefineInput,
    cleanup: FootCleanup,
    output: RefineOutput,
) -> ZooStatus {
    guard(function, || {
        let r = unsafe { self::model(model) }?.stitch()?;
        let (roots, frames, rotations, rotations_len, seams, seams_len) = input;
        let roots = unsafe { slice(roots, frames, "roots") }?;
        let rotations = unsafe { slice(rotations, rotations_len, "rotations") }?;
        let seams = if seams_len == 0 { &[][..] } else { unsafe { slice(seams, seams_len, "seams") }? };
        let (out_roots, out_roots_len, out_rotations, out_rotations_len, contacts, contacts_len) = output;
        let mut out = unsafe {
            PoseOut::new(
                (out_roots, out_roots_len, "out_roots"),
                (out_rotations, out_rotations_len, "out_rotations"),
                (contacts, contacts_len, "contacts"),
            )
        }?;
        let k = r.joints();
        out.check(frames, k, 4, "input pose")?;
        let mut poses = Vec::new();
        read_poses(roots, rotations, k, &mut poses)?;
        let mut refined = vec![EnginePose::new(k); frames];
        let mut predicted = vec![[false; 4]; frames];
        r.refine_poses_at_seams(&poses, seams, cleanup, &mut refined, &mut predicted).map_err(runtime_failure)?;
        for (f, (pose, c)) in refined.iter().zip(&predicted).enumerate() {
            out.write(f, pose, c);
        }
        Ok(())
    })
}

/// Creates a stitching stream over `model` into `*out`; free it with
/// `zoo_stitch_stream_free`. Thread-safe (the model is shared); the stream: one thread at a
/// time. Runs one window of the refiner on zeros (about a window's time: a few milliseconds for
/// a paper-size model), so that no per-frame call makes the stream's buffers.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_new(model: *const ZooModel, out: *mut *mut ZooStitchStream) -> ZooStatus {
    guard("zoo_stitch_stream_new", || {
        let refiner = Arc::clone(unsafe { self::model(model) }?.stitch()?);
        let pose = EnginePose::new(refiner.joints());
        unsafe { new_handle(out, || Ok(ZooStitchStream { stream: refiner.shared_stream(), pose })) }
    })
}

/// Frees a stream (NULL is ignored).
///
/// Safety: `stream` is NULL or a pointer from `zoo_stitch_stream_new` not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_free(stream: *mut ZooStitchStream) {
    unsafe { free_handle(stream) }
}

/// A stream's refusal: a call that does not fit where the stream stands (finished, too short to
/// finish) is `ZOO_STATUS_INVALID_STATE`.
fn stream_failure(e: MotionError) -> Failure {
    let out_of_order = matches!(e, MotionError::Stitch { .. });
    let (status, message) = runtime_failure(e);
    (if out_of_order { ZooStatus::InvalidState } else { status }, message)
}

/// Pushes the next frame of the aligned motion: one pose, `root` and `4K` floats of
/// `rotations`. Runs a window when one is due. Pushing after `zoo_stitch_stream_finish` is
/// `ZOO_STATUS_INVALID_STATE`. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only; `root` is NULL or readable; `rotations`
/// is NULL or holds `rotations_len` floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_push(
    stream: *mut ZooStitchStream,
    root: *const ZooRootMotion,
    rotations: *const f32,
    rotations_len: usize,
) -> ZooStatus {
    guard("zoo_stitch_stream_push", || {
        let s = unsafe { handle_mut(stream, "stream") }?;
        let root = unsafe { handle(root, "root") }?;
        let rotations = unsafe { slice(rotations, rotations_len, "rotations") }?;
        check_size("rotations", rotations.len(), 4 * s.pose.joints(), "floats", format_args!("4 * {JOINTS}"))?;
        read_pose(root, rotations, &mut s.pose);
        s.stream.push(&s.pose).map_err(stream_failure)
    })
}

/// Sets what follows the refiner in `stream`, before its first push (`ZOO_STATUS_INVALID_STATE`
/// after): `place_ankles` puts the ankles where the refiner predicts them, `lock_feet` locks the
/// planted feet by the predicted contacts (both on by default, as `zoo stitch`); the seam guard
/// and the seams' reach follow the model's (`zoo_stitch_set_seam_guard`,
/// `zoo_stitch_set_seam_reach`). Both off with the guard and the reach off: the refiner's poses
/// as they are, at a latency of `window + stride - 1` frames. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_set_cleanup(
    stream: *mut ZooStitchStream,
    place_ankles: bool,
    lock_feet: bool,
) -> ZooStatus {
    guard("zoo_stitch_stream_set_cleanup", || {
        let s = unsafe { handle_mut(stream, "stream") }?;
        s.stream.set_cleanup(FootCleanup { place_ankles, lock_feet }).map_err(stream_failure)
    })
}

/// Writes into `*out` the stream's latency in frames: the refined pose of frame `t` is ready
/// once frame `t + latency` is pushed. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_latency(stream: *const ZooStitchStream, out: *mut usize) -> ZooStatus {
    guard("zoo_stitch_stream_latency", || {
        let s = unsafe { handle(stream, "stream") }?;
        unsafe { write_out(out, s.stream.latency(), "out") }
    })
}

/// Writes into `*ready` whether the next refined pose can be popped. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only; `ready` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_ready(stream: *const ZooStitchStream, ready: *mut bool) -> ZooStatus {
    guard("zoo_stitch_stream_ready", || {
        let s = unsafe { handle(stream, "stream") }?;
        unsafe { write_out(ready, s.stream.ready(), "ready") }
    })
}

/// Pops the next refined pose into `root` and `rotations` (`4K` floats; root deltas from the
/// previous popped pose) and its predicted contacts into `contacts` (4 bytes). Before it is
/// ready (fewer than `latency` frames pushed after it, and not finished) the call is
/// `ZOO_STATUS_NOT_AVAILABLE` and writes nothing. The pose has the ankle IK, the seam guard and
/// the foot lock of `zoo stitch` unless `zoo_stitch_stream_set_cleanup` turned them off. One
/// thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only; `root` is NULL or writable; each buffer
/// is NULL or holds its given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_pop(
    stream: *mut ZooStitchStream,
    root: *mut ZooRootMotion,
    rotations: *mut f32,
    rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> ZooStatus {
    guard("zoo_stitch_stream_pop", || {
        let s = unsafe { handle_mut(stream, "stream") }?;
        let mut out = unsafe {
            PoseOut::new(
                (root, 1, "root"),
                (rotations, rotations_len, "rotations"),
                (contacts, contacts_len, "contacts"),
            )
        }?;
        out.check(1, s.pose.joints(), 4, "pop")?;
        let Some(predicted) = s.stream.pop(&mut s.pose).map_err(stream_failure)? else {
            let next = s.stream.popped();
            let message = if s.stream.is_finished() {
                format!("no refined pose left: the finished stream's {next} frames were all popped")
            } else {
                format!(
                    "the refined pose of frame {next} is not ready: it is once frame {} is pushed, or after \
                     zoo_stitch_stream_finish; ask zoo_stitch_stream_ready first",
                    next + s.stream.latency()
                )
            };
            return Err((ZooStatus::NotAvailable, message));
        };
        out.write(0, &s.pose, &predicted);
        Ok(())
    })
}

/// Marks the next pushed pose as the first frame of a new clip: the stream inertializes the seam
/// before refining and guards it, as `zoo_stitch_refine_at_seams` does (the seam frame is
/// encoded once the frame after it is pushed). A seam on frame 0 or 1 is not inertialized. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_mark_seam(stream: *mut ZooStitchStream) -> ZooStatus {
    guard("zoo_stitch_stream_mark_seam", || {
        let s = unsafe { handle_mut(stream, "stream") }?;
        if s.stream.is_finished() {
            return Err((
                ZooStatus::InvalidState,
                "the stream is finished: start another with zoo_stitch_stream_new".into(),
            ));
        }
        s.stream.mark_seam();
        Ok(())
    })
}

/// Ends the motion: runs the window ending on the last frame and makes every remaining frame
/// ready to pop. Needs at least `window` frames pushed (`ZOO_STATUS_INVALID_STATE` before);
/// finishing twice does nothing. One thread at a time.
///
/// Safety: `stream` is NULL or live and used by this thread only.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_stitch_stream_finish(stream: *mut ZooStitchStream) -> ZooStatus {
    guard("zoo_stitch_stream_finish", || {
        let s = unsafe { handle_mut(stream, "stream") }?;
        s.stream.finish().map_err(stream_failure)
    })
}
