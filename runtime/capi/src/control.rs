//! Speed and facing control of a `synthesis` model (`zoo_runtime::control`): characters of a
//! synthesis model that walk at a target speed and turn to a target facing
//! (`ZooControl`, one per character and frame), stepped one frame per `zoo_control_step` of a
//! `ZooControlRunner`. A control shows in the motion 1 to `batch` frames after it is given
//! (see `zoo_runtime::control`). A character's frames depend only on its model, settings, seed,
//! seed frames, placement and controls, bit for bit.

use crate::model::{Family, model};
use crate::synthesis::{Shape, check_shape, not_started, shape, start_all, step_out};
use crate::{
    Failure, ZooModel, ZooRootMotion, ZooStatus, check_batch, check_count, check_size, free_handle, guard, handle_mut,
    new_handle, optional_slice, runtime_failure, slice, write_out,
};
use zoo_runtime::EnginePose;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::synthesis::SynthesisModel;

/// How controlled characters plan (docs/rnn-gmm-control.md);
/// `zoo_control_settings_default` fills the defaults.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZooControlSettings {
    /// Frames per planned batch (also the control's latency in frames); at least 1.
    pub batch: usize,
    /// Standard deviation of the speed term, clip units per second; positive.
    pub sigma_speed: f32,
    /// Standard deviation of the facing term, radians; positive.
    pub sigma_heading: f32,
    /// Scale of the mixture's standard deviations when drawing (1: the model's, 0: its means).
    pub temperature: f32,
    /// Offsets of a candidate's forward step, in data standard deviations; NULL and 0: the
    /// defaults (-3, -1.5, 0, 1.5, 3).
    pub speed_offsets: *const f32,
    /// Number of `speed_offsets`.
    pub speed_offsets_len: usize,
    /// Offsets of a candidate's turn, in data standard deviations; NULL and 0: the defaults.
    pub turn_offsets: *const f32,
    /// Number of `turn_offsets`.
    pub turn_offsets_len: usize,
}

/// A control target of one character.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooControl {
    /// Target root speed over the ground, clip units per second; finite, >= 0.
    pub speed: f32,
    /// Target facing yaw, radians about +Y (0 faces +Z, positive turns +Z towards +X); finite.
    pub heading: f32,
}

/// Scratch space for stepping controlled characters (opaque). One thread at a time.
pub struct ZooControlRunner {
    runner: ControlRunner,
    shape: Shape,
    max_batch: usize,
}

/// A batch of controlled characters (opaque). One thread at a time.
pub struct ZooControlCharacters {
    model: SynthesisModel,
    characters: Vec<ControlledCharacter>,
    pose: EnginePose,
    started: bool,
}

/// Writes the default settings into `*out` (batches of 3 frames, 5 x 5 candidates, the default
/// offsets as NULL). Thread-safe.
///
/// Safety: `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_settings_default(out: *mut ZooControlSettings) -> ZooStatus {
    guard("zoo_control_settings_default", || {
        let d = ControlSettings::default();
        let settings = ZooControlSettings {
            batch: d.batch,
            sigma_speed: d.sigma_speed,
            sigma_heading: d.sigma_heading,
            temperature: d.temperature,
            speed_offsets: std::ptr::null(),
            speed_offsets_len: 0,
            turn_offsets: std::ptr::null(),
            turn_offsets_len: 0,
        };
        unsafe { write_out(out, settings, "out") }
    })
}

/// Creates scratch space for stepping up to `max_batch` controlled characters of `model` per call
/// (1..`ZOO_MAX_BATCH`; a larger batch is refused) on one thread at a time
/// into `*out`; free it with `zoo_control_runner_free`. Thread-safe (the model is shared).
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_runner_new(
    model: *const ZooModel,
    max_batch: usize,
    out: *mut *mut ZooControlRunner,
) -> ZooStatus {
    guard("zoo_control_runner_new", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Control)?;
        check_count("max_batch", max_batch)?;
        unsafe {
            new_handle(out, || {
                Ok(ZooControlRunner {
                    runner: ControlRunner::new(m).map_err(runtime_failure)?,
                    shape: shape(m),
                    max_batch,
                })
            })
        }
    })
}

/// Frees a runner (NULL is ignored).
///
/// Safety: `runner` is NULL or a pointer from `zoo_control_runner_new` not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_runner_free(runner: *mut ZooControlRunner) {
    unsafe { free_handle(runner) }
}

/// The runtime's settings from the C struct (NULL offsets: the defaults).
///
/// Safety: The offsets pointers are NULL or hold their given lengths.
unsafe fn settings_of(s: &ZooControlSettings) -> Result<ControlSettings, Failure> {
    let d = ControlSettings::default();
    let offsets = |ptr, len, what, default: Vec<f32>| -> Result<Vec<f32>, Failure> {
        let given = unsafe { optional_slice(ptr, len, what) }?;
        Ok(if given.is_empty() { default } else { given.to_vec() })
    };
    Ok(ControlSettings {
        batch: s.batch,
        speed_offsets: offsets(s.speed_offsets, s.speed_offsets_len, "settings.speed_offsets", d.speed_offsets)?,
        turn_offsets: offsets(s.turn_offsets, s.turn_offsets_len, "settings.turn_offsets", d.turn_offsets)?,
        side_offsets: d.side_offsets,
        sigma_speed: s.sigma_speed,
        sigma_heading: s.sigma_heading,
        temperature: s.temperature,
    })
}

/// Creates `count` controlled characters of `model`, character `c` seeded with `seeds[c]`,
/// planning with `settings` (NULL: the defaults; checked) into `*out`; start them with
/// `zoo_control_start`, free them with `zoo_control_characters_free`. Thread-safe (the model
/// is shared).
///
/// Safety: `model` is NULL or a live model; `seeds` is NULL or holds `count` values; `settings` is NULL
/// or readable (its offsets NULL or holding their lengths); `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_characters_new(
    model: *const ZooModel,
    seeds: *const u64,
    count: usize,
    settings: *const ZooControlSettings,
    out: *mut *mut ZooControlCharacters,
) -> ZooStatus {
    guard("zoo_control_characters_new", || {
        let m = unsafe { self::model(model) }?.synthesis(Family::Control)?;
        check_count("count", count)?;
        let seeds = unsafe { slice(seeds, count, "seeds") }?;
        let settings = match unsafe { settings.as_ref() } {
            Some(s) => unsafe { settings_of(s) }?,
            None => ControlSettings::default(),
        };
        unsafe {
            new_handle(out, || {
                let characters = seeds
                    .iter()
                    .map(|&s| ControlledCharacter::new(m, s, settings.clone()))
                    .collect::<Result<_, _>>()
                    .map_err(runtime_failure)?;
                Ok(ZooControlCharacters {
                    model: m.clone(),
                    characters,
                    pose: EnginePose::new(m.joints()),
                    started: false,
                })
            })
        }
    })
}

/// Frees controlled characters (NULL is ignored).
///
/// Safety: `characters` is NULL or a pointer from `zoo_control_characters_new` not freed before and
/// not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_characters_free(characters: *mut ZooControlCharacters) {
    unsafe { free_handle(characters) }
}

/// Starts every character from its seed frames: `frames` holds `N * F * D` floats (`F >= 1`
/// feature frames per character, the same `F` for all, oldest first, clip units,
/// character-major), the last one the current frame, with the root at `(x, z)` facing `yaw`
/// (`placements`: `x z yaw` per character). Drops any plan; the random numbers are not reset.
/// Everything is checked before any character changes. One thread at a time.
///
/// Safety: `characters` is NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_start(
    characters: *mut ZooControlCharacters,
    frames: *const f32,
    frames_len: usize,
    placements: *const f32,
    placements_len: usize,
) -> ZooStatus {
    guard("zoo_control_start", || {
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let frames = unsafe { slice(frames, frames_len, "frames") }?;
        let placements = unsafe { slice(placements, placements_len, "placements") }?;
        let (n, d) = (chars.characters.len(), chars.model.frame_dim());
        if frames.is_empty() || !frames.len().is_multiple_of(n * d) {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`frames` holds {} floats; it needs the same number of seed frames (at least one) of {d} floats (zoo_synthesis_info's `frame_values`) for each of the {n} characters",
                    frames.len()
                ),
            ));
        }
        let model = &chars.model;
        let start = |ch: &mut ControlledCharacter, f: &[f32], [x, z, yaw]: [f32; 3]| ch.start(model, f, x, z, yaw);
        start_all(&mut chars.characters, frames, frames.len() / n, placements, start)?;
        chars.started = true;
        Ok(())
    })
}

/// Plays every character's next frame under its control (`controls`: one per character) into
/// `roots` (`N`), `rotations` (`N * 4K` floats) and `contacts` (`N * 2` bytes: left, right
/// foot). Stepping before `zoo_control_start` is `ZOO_STATUS_INVALID_STATE`; a bad control is
/// refused before any character moves. Runner and characters: one thread at a time each.
///
/// Safety: Handles are NULL or live and used by this thread only; each buffer is NULL or holds its
/// given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_control_step(
    runner: *mut ZooControlRunner,
    characters: *mut ZooControlCharacters,
    controls: *const ZooControl,
    controls_len: usize,
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
    contacts: *mut u8,
    contacts_len: usize,
) -> ZooStatus {
    guard("zoo_control_step", || {
        let r = unsafe { handle_mut(runner, "runner") }?;
        let chars = unsafe { handle_mut(characters, "characters") }?;
        let controls = unsafe { slice(controls, controls_len, "controls") }?;
        let mut out = unsafe { step_out(roots, roots_len, rotations, rotations_len, contacts, contacts_len) }?;
        check_shape(r.shape, shape(&chars.model))?;
        let n = chars.characters.len();
        check_batch(n, r.max_batch, "zoo_control_runner_new")?;
        check_size("controls", controls.len(), n, "controls", "the batch, one per character")?;
        out.check(n, chars.model.joints(), 2, "character")?;
        let control = |c: &ZooControl| Control::new(c.speed, c.heading);
        for (c, z) in controls.iter().enumerate() {
            control(z).check().map_err(runtime_failure).map_err(|(s, m)| (s, format!("character {c}: {m}")))?;
        }
        if !chars.started {
            return Err(not_started("zoo_control_start"));
        }
        for (c, (ch, z)) in chars.characters.iter_mut().zip(controls).enumerate() {
            let feet = r.runner.step(ch, control(z), &mut chars.pose).map_err(runtime_failure)?;
            out.write(c, &chars.pose, &feet);
        }
        Ok(())
    })
}
