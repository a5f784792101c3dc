//! Random motion synthesis (RNN-GMM, task `synthesis`, `zoo_runtime::synthesis`): a `synthesis`
//! model generates motion for a batch of seeded characters (`ZooSynthesisCharacters`), one
//! frame per `zoo_synthesis_step` of a `ZooSynthesisRunner`, as engine poses and left /
//! right foot contacts. Its speed / facing controller is `control.rs` (`zoo_control_*`).
//!
//! A character's frames depend only on its seed, its start frame and placement: the same in
//! any batch, on any thread, in any run, bit for bit. A feature frame (`D` floats, clip units)
//! is the model's own encoding of a pose (`zoo_rnngmm::FeatureSpec::encode`); engines without
//! one start from the data's mean frame (`zoo_synthesis_mean_frame`).

use crate::model::{Family, model};
use crate::{
    Failure, PoseOut, ZooModel, ZooRootMotion, ZooStatus, check_batch, check_count, check_size, free_handle, guard,
    handle_mut, new_handle, runtime_failure, slice, slice_mut, write_out,
};
use zoo_runtime::synthesis::{SynthesisCharacter, SynthesisModel, SynthesisRunner};
use zoo_runtime::{EnginePose, MotionError};

/// Scratch space for stepping characters (opaque). One thread at a time.
pub struct ZooSynthesisRunner {
    runner: SynthesisRunner,
    shape: Shape,
    max_batch: usize,
}

/// The generators of a batch of characters (opaque). One thread at a time.
pub struct ZooSynthesisCharacters {
    model: SynthesisModel,
    characters: Vec<SynthesisCharacter>,
    poses: Vec<EnginePose>,
    contacts: Vec<[bool; 2]>,
    started: bool,
}

/// What a synthesis model expects besides `ZooModelInfo` (whose `joints` every pose
/// has, and whose `fps` the generated motion).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooSynthesisInfo {
    /// Values `D` of a feature frame (a start frame): `6 + 3 (K - 1) + 2`.
    pub frame_values: usize,
    /// Whether runners and characters made now refine each generated frame (the file embeds the
    /// refiner and `zoo_synthesis_set_refine` did not turn it off).
    pub has_refiner: bool,
}

const INFO: &str = "zoo_synthesis_info";

/// What must agree between a runner and the characters it steps (`frame_values`, joints,
/// refiner).
pub(crate) type Shape = (usize, usize, bool);

pub(crate) fn shape(model: &SynthesisModel) -> Shape {
    (model.frame_dim(), model.joints(), model.has_refiner())
}

/// Refuses characters of another model than the runner's.
pub(crate) fn check_shape(runner: Shape, characters: Shape) -> Result<(), Failure> {
    if runner != characters {
        return Err((
            ZooStatus::InvalidArgument,
            "the characters were made from another model than the runner (or on the other side of \
             zoo_synthesis_set_refine): step characters with a runner made from the same model"
                .into(),
        ));
    }
    Ok(())
}

/// Writes what a synthesis model expects into `*out`. Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_info(model: *const ZooModel, out: *mut ZooSynthesisInfo) -> ZooStatus {
    guard("zoo_synthesis_info", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Synthesis)?;
        unsafe { write_out(out, ZooSynthesisInfo { frame_values: m.frame_dim(), has_refiner: m.has_refiner() }, "out") }
    })
}

/// Whether runners and characters made from `model` from now on (synthesis and control) run
/// the file's refiner behind the generator when it has one (`refine`, the default after
/// loading) or the generator's own frames. Those made before keep theirs. Not thread-safe: no
/// other thread may use the model during the call.
///
/// Safety: `model` is NULL or a live model used by no other thread during the call.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_set_refine(model: *mut ZooModel, refine: bool) -> ZooStatus {
    guard("zoo_synthesis_set_refine", || unsafe { handle_mut(model, "model") }?.set_refine(refine))
}

/// Writes the training data's mean feature frame (`D` floats, clip units) into `frame`: a
/// neutral start frame for an engine that has no encoded frame of its own. Thread-safe.
///
/// Safety: `model` is NULL or a live model; `frame` is NULL or holds `frame_len` writable floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_mean_frame(
    model: *const ZooModel,
    frame: *mut f32,
    frame_len: usize,
) -> ZooStatus {
    guard("zoo_synthesis_mean_frame", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Synthesis)?;
        let frame = unsafe { slice_mut(frame, frame_len, "frame") }?;
        check_size("frame", frame.len(), m.frame_dim(), "floats", format_args!("{INFO} (`frame_values`)"))?;
        let mean = m.model().metadata().normalization.get("x").map(|n| n.mean.as_slice()).unwrap_or_default();
        if mean.len() != frame.len() {
            return Err((ZooStatus::RunFailed, "the model has no mean frame; re-export it".into()));
        }
        frame.copy_from_slice(mean);
        Ok(())
    })
}

/// Creates scratch space for stepping up to `max_batch` characters of `model` per call
/// (1..`ZOO_MAX_BATCH`; a larger batch is refused) on one thread at a time into `*out`; free it with
/// `zoo_synthesis_runner_free`. Thread-safe (the model is shared).
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_runner_new(
    model: *const ZooModel,
    max_batch: usize,
    out: *mut *mut ZooSynthesisRunner,
) -> ZooStatus {
    guard("zoo_synthesis_runner_new", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Synthesis)?;
        check_count("max_batch", max_batch)?;
        unsafe {
            new_handle(out, || {
                Ok(ZooSynthesisRunner {
                    runner: m.runner(max_batch).map_err(runtime_failure)?,
                    shape: shape(m),
                    max_batch,
                })
            })
        }
    })
}

/// Frees a runner (NULL is ignored).
///
/// Safety: `runner` is NULL or a pointer from `zoo_synthesis_runner_new` not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_runner_free(runner: *mut ZooSynthesisRunner) {
    unsafe { free_handle(runner) }
}

/// Creates `count` characters of `model`, character `c` seeded with `seeds[c]`, into `*out`;
/// start them with `zoo_synthesis_start`, free them with `zoo_synthesis_characters_free`.
/// Thread-safe (the model is shared).
///
/// Safety: `model` is NULL or a live model; `seeds` is NULL or holds `count` values; `out` is NULL or
/// valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_characters_new(
    model: *const ZooModel,
    seeds: *const u64,
    count: usize,
    out: *mut *mut ZooSynthesisCharacters,
) -> ZooStatus {
    guard("zoo_synthesis_characters_new", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Synthesis)?;
        check_count("count", count)?;
        let seeds = unsafe { slice(seeds, count, "seeds") }?;
        unsafe {
            new_handle(out, || {
                Ok(ZooSynthesisCharacters {
                    model: m.clone(),
                    characters: seeds.iter().map(|&s| m.new_character(s)).collect(),
                    poses: (0..count).map(|_| EnginePose::new(m.joints())).collect(),
                    contacts: vec![[false; 2]; count],
                    started: false,
                })
            })
        }
    })
}

/// Frees characters (NULL is ignored).
///
/// Safety: `characters` is NULL or a pointer from `zoo_synthesis_characters_new` not freed before and
/// not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_characters_free(characters: *mut ZooSynthesisCharacters) {
    unsafe { free_handle(characters) }
}

/// Starts `characters` from `frames` (`per_character` floats each, the length checked by the
/// caller) and `placements` (`x z yaw` each) with `start`, everything checked before any
/// character changes.
pub(crate) fn start_all<C>(
    characters: &mut [C],
    frames: &[f32],
    per_character: usize,
    placements: &[f32],
    mut start: impl FnMut(&mut C, &[f32], [f32; 3]) -> Result<(), MotionError>,
) -> Result<(), Failure> {
    let non_finite = |name: &str, values: &[f32], per: usize, fix: &str| match values
        .iter()
        .position(|v| !v.is_finite())
    {
        Some(i) => Err((
            ZooStatus::InvalidArgument,
            format!("`{name}` holds a non-finite value ({}) at index {i} (character {}); {fix}", values[i], i / per),
        )),
        None => Ok(()),
    };
    let n = characters.len();
    check_size("placements", placements.len(), 3 * n, "floats", "the batch: x, z and yaw per character")?;
    non_finite("placements", placements, 3, "give each character's x, z and yaw as finite numbers")?;
    non_finite("frames", frames, per_character, "give finite feature frames in clip units")?;
    for ((ch, f), p) in characters.iter_mut().zip(frames.chunks_exact(per_character)).zip(placements.chunks_exact(3)) {
        start(ch, f, [p[0], p[1], p[2]]).map_err(runtime_failure)?;
    }
    Ok(())
}

/// Starts every character from a feature frame (`frames`: `N * D` floats, clip units,
/// character-major) with its root at `(x, z)` facing `yaw` (radians about +Y; `placements`: `N * 3`
/// floats, `x z yaw` per character), from the zero generator state. The random numbers are not
/// reset. Everything is checked before any character changes. One thread at a time.
///
/// Safety: `characters` is NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_start(
    characters: *mut ZooSynthesisCharacters,
    frames: *const f32,
    frames_len: usize,
    placements: *const f32,
    placements_len: usize,
) -> ZooStatus {
    guard("zoo_synthesis_start", || {
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let frames = unsafe { slice(frames, frames_len, "frames") }?;
        let placements = unsafe { slice(placements, placements_len, "placements") }?;
        let (n, d) = (chars.characters.len(), chars.model.frame_dim());
        check_size("frames", frames.len(), n * d, "floats", format_args!("{INFO} (`frame_values` per character)"))?;
        let model = &chars.model;
        start_all(&mut chars.characters, frames, d, placements, |ch, f, [x, z, yaw]| ch.start(model, f, x, z, yaw))?;
        chars.started = true;
        Ok(())
    })
}

/// Generates the next frame of every character in one graph run: `roots` receives `N` roots,
/// `rotations` `N * 4K` floats and `contacts` `N * 2` bytes (left, right foot). `temperature`
/// scales the mixture's standard deviations (1: the model's; finite, >= 0). Stepping before
/// `zoo_synthesis_start` is `ZOO_STATUS_INVALID_STATE`. Allocates nothing per frame (without a
/// refiner). Runner and characters: one thread at a time each.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length of writable values.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_synthesis_step(
    runner: *mut ZooSynthesisRunner,
    characters: *mut ZooSynthesisCharacters,
    temperature: f32,
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> ZooStatus {
    guard("zoo_synthesis_step", || {
        let r = unsafe { handle_mut(runner, "runner") }?;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let mut out = unsafe { step_out(roots, roots_len, rotations, rotations_len, contacts, contacts_len) }?;
        check_shape(r.shape, shape(&chars.model))?;
        check_batch(chars.characters.len(), r.max_batch, "zoo_synthesis_runner_new")?;
        out.check(chars.characters.len(), chars.model.joints(), 2, "character")?;
        if !chars.started {
            return Err(not_started("zoo_synthesis_start"));
        }
        r.runner
            .step_batch(&mut chars.characters, temperature, &mut chars.poses, &mut chars.contacts)
            .map_err(runtime_failure)?;
        for (c, (pose, feet)) in chars.poses.iter().zip(&chars.contacts).enumerate() {
            out.write(c, pose, feet);
        }
        Ok(())
    })
}

/// The output buffers of a step: a root, `4K` rotations and 2 contacts per character.
///
/// Safety: Each pointer is NULL or holds its given length of writable values.
pub(crate) unsafe fn step_out<'a>(
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> Result<PoseOut<'a>, Failure> {
    unsafe {
        PoseOut::new(
            (roots, roots_len, "roots"),
            (rotations, rotations_len, "rotations"),
            (contacts, contacts_len, "contacts"),
        )
    }
}

/// The refusal of a step before the start (`start`: the function that starts).
pub(crate) fn not_started(start: &str) -> Failure {
    (ZooStatus::InvalidState, format!("the characters were not started: call {start} first"))
}
