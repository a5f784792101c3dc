//! The one model handle: `zoo_model_load` loads any exported file (through
//! `zoo_runtime::LoadedModel`) into a `ZooModel`, `zoo_model_task` says its task, and
//! `zoo_model_info` / `zoo_model_skeleton` / `zoo_model_joint_name` describe it, whatever
//! its task. The task's own
//! functions (`zoo_transition_*`, `zoo_keyframes_*`, `zoo_stitch_*`, `zoo_synthesis_*`,
//! `zoo_control_*`) take the handle and refuse a model of another task with
//! `ZOO_STATUS_WRONG_MODEL`.

use crate::error::functions_of;
use crate::{
    Failure, ZooStatus, c_str, check_size, free_handle, guard, handle, new_handle, runtime_failure, slice, slice_mut,
    write_out,
};
use std::ffi::c_char;
use std::sync::Arc;
use zoo_runtime::metadata::{MotionModelMetadata, MotionTaskKind};
use zoo_runtime::{Handedness, KeyframeModel, LoadedModel, StitchRefiner, SynthesisModel, TransitionModel, UpAxis};

/// What a model does: the `zoo.task` of its file.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZooTask {
    /// No model (what `zoo_model_task` returns for a NULL handle).
    #[default]
    None = 0,
    /// Transitions between poses (RTN): `zoo_transition_*`.
    Transition = 1,
    /// Keyframe completion (ARNN): `zoo_keyframes_*`.
    Keyframes = 2,
    /// Refining stitched locomotion (RMR): `zoo_stitch_*`.
    Stitch = 3,
    /// Random motion synthesis (RNN-GMM): `zoo_synthesis_*`, and its speed / facing control
    /// `zoo_control_*`.
    Synthesis = 4,
}

/// The up axis of a model's positions and rotations.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZooUpAxis {
    /// +Y up (zoo, BVH, Unity, Maya).
    #[default]
    Y = 0,
    /// +Z up (Blender, Unreal).
    Z = 1,
}

/// The handedness of a model's axes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZooHandedness {
    /// Right-handed (zoo, BVH, Blender, Maya, Godot).
    #[default]
    Right = 0,
    /// Left-handed (Unity, Unreal).
    Left = 1,
}

/// What every model is, whatever its task (`zoo_model_info`); each task's info function
/// gives the rest (`zoo_transition_info`, `zoo_keyframes_info`, `zoo_stitch_info`,
/// `zoo_synthesis_info`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ZooModelInfo {
    /// The model's task.
    pub task: ZooTask,
    /// Number of joints `K` of the model's skeleton (`zoo_model_skeleton`): a pose in
    /// positions is `3K` floats, an engine pose a root and `4K` rotation values.
    pub joints: usize,
    /// Frames per second of the model's motion (its training data's).
    pub fps: f32,
    /// Metres per model unit of every position (0.01: centimetres).
    pub metres_per_unit: f32,
    /// The up axis of positions and rotations.
    pub up_axis: ZooUpAxis,
    /// The handedness of the axes.
    pub handedness: ZooHandedness,
    /// The format version of the file (`zoo.format_version`).
    pub format_version: u32,
}

/// A loaded model of any task (opaque). Thread-safe: share it between threads (except
/// `zoo_stitch_set_window` and `zoo_synthesis_set_refine`, which change it).
pub struct ZooModel {
    model: TaskModel,
}

/// The runtime's type of each task.
// One per model handle, which boxes it: the size of the largest variant costs nothing per frame.
#[allow(clippy::large_enum_variant)]
enum TaskModel {
    Transition(TransitionModel),
    Keyframes(KeyframeModel),
    /// Shared with the streams made from it; `zoo_stitch_set_window` changes it while none is.
    Stitch(Arc<StitchRefiner>),
    /// `file`: as loaded; `active`: what runners and characters are made from (`file` without
    /// its refiner after `zoo_synthesis_set_refine(model, false)`).
    Synthesis {
        file: SynthesisModel,
        active: SynthesisModel,
    },
}

/// A family of C functions: the functions of one task (control: of the `synthesis` task).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Family {
    Transition,
    Keyframes,
    Stitch,
    Synthesis,
    Control,
}

impl Family {
    /// The family's functions, for messages.
    fn functions(self) -> &'static str {
        match self {
            Family::Transition => "zoo_transition_*",
            Family::Keyframes => "zoo_keyframes_*",
            Family::Stitch => "zoo_stitch_*",
            Family::Synthesis => "zoo_synthesis_*",
            Family::Control => "zoo_control_*",
        }
    }

    /// The task of the models the family takes.
    fn task(self) -> MotionTaskKind {
        match self {
            Family::Transition => MotionTaskKind::Transition,
            Family::Keyframes => MotionTaskKind::Keyframes,
            Family::Stitch => MotionTaskKind::Stitch,
            Family::Synthesis | Family::Control => MotionTaskKind::Synthesis,
        }
    }
}

impl ZooModel {
    /// Loads `path` (a portable main file with its companions) with the runtime's one loader.
    fn load(path: &str) -> Result<Self, Failure> {
        let bytes = zoo_runtime::portable::assemble(path).map_err(runtime_failure)?;
        Self::from_bytes(&bytes, path)
    }

    /// Loads a model from the bytes of its file; `origin` names them in messages.
    fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, Failure> {
        let in_file = |(status, message): Failure| (status, format!("{origin}: {message}"));
        let loaded = LoadedModel::from_bytes(bytes).map_err(runtime_failure).map_err(in_file)?;
        let model = match loaded {
            LoadedModel::Transition(t) => TaskModel::Transition(t),
            LoadedModel::Keyframes(k) => TaskModel::Keyframes(k),
            LoadedModel::Stitch(s) => TaskModel::Stitch(Arc::new(s)),
            LoadedModel::Synthesis(s) => TaskModel::Synthesis { active: s.clone(), file: s },
            other => {
                return Err(in_file((
                    ZooStatus::LoadFailed,
                    format!(
                        "the model is a `{}` model (kind `{}`), a task this C ABI does not run yet",
                        other.task(),
                        other.kind()
                    ),
                )));
            }
        };
        Ok(ZooModel { model })
    }

    /// The file's metadata.
    pub(crate) fn metadata(&self) -> &MotionModelMetadata {
        match &self.model {
            TaskModel::Transition(t) => t.model().metadata(),
            TaskModel::Keyframes(k) => k.metadata(),
            TaskModel::Stitch(s) => s.metadata(),
            TaskModel::Synthesis { file, .. } => file.model().metadata(),
        }
    }

    /// The model's task.
    pub(crate) fn task(&self) -> ZooTask {
        match &self.model {
            TaskModel::Transition(_) => ZooTask::Transition,
            TaskModel::Keyframes(_) => ZooTask::Keyframes,
            TaskModel::Stitch(_) => ZooTask::Stitch,
            TaskModel::Synthesis { .. } => ZooTask::Synthesis,
        }
    }

    /// The refusal of this model by a function of `family`: what the model is, what the family
    /// takes, and the functions that run the model.
    fn wrong_model(&self, family: Family) -> Failure {
        let m = self.metadata();
        (
            ZooStatus::WrongModel,
            format!(
                "the model is a `{}` model (kind `{}`); {} functions take `{}` models; use {} with this model",
                m.task.name(),
                m.model_kind,
                family.functions(),
                family.task(),
                functions_of(m.task.kind()),
            ),
        )
    }

    /// The transition model, or the refusal of a `zoo_transition_*` function.
    pub(crate) fn transition(&self) -> Result<&TransitionModel, Failure> {
        match &self.model {
            TaskModel::Transition(t) => Ok(t),
            _ => Err(self.wrong_model(Family::Transition)),
        }
    }

    /// The keyframe model, or the refusal of a `zoo_keyframes_*` function.
    pub(crate) fn keyframes(&self) -> Result<&KeyframeModel, Failure> {
        match &self.model {
            TaskModel::Keyframes(k) => Ok(k),
            _ => Err(self.wrong_model(Family::Keyframes)),
        }
    }

    /// The stitching refiner, or the refusal of a `zoo_stitch_*` function.
    pub(crate) fn stitch(&self) -> Result<&Arc<StitchRefiner>, Failure> {
        match &self.model {
            TaskModel::Stitch(s) => Ok(s),
            _ => Err(self.wrong_model(Family::Stitch)),
        }
    }

    /// `ZooModel::stitch` to change.
    pub(crate) fn stitch_mut(&mut self) -> Result<&mut Arc<StitchRefiner>, Failure> {
        if !matches!(self.model, TaskModel::Stitch(_)) {
            return Err(self.wrong_model(Family::Stitch));
        }
        match &mut self.model {
            TaskModel::Stitch(s) => Ok(s),
            _ => unreachable!("checked above"),
        }
    }

    /// The synthesis model runners and characters are made from, or the refusal of a function
    /// of `family` (`zoo_synthesis_*` or `zoo_control_*`).
    pub(crate) fn synthesis(&self, family: Family) -> Result<&SynthesisModel, Failure> {
        match &self.model {
            TaskModel::Synthesis { active, .. } => Ok(active),
            _ => Err(self.wrong_model(family)),
        }
    }

    /// Makes runners and characters made from now on run the file's refiner (when it has one)
    /// or not; the refusal of `zoo_synthesis_set_refine` for another task.
    pub(crate) fn set_refine(&mut self, refine: bool) -> Result<(), Failure> {
        match &mut self.model {
            TaskModel::Synthesis { file, active } => {
                *active = if refine { file.clone() } else { file.clone().without_refiner() };
                Ok(())
            }
            _ => Err(self.wrong_model(Family::Synthesis)),
        }
    }
}

/// The model behind a handle.
///
/// Safety: `model` is NULL or a live model.
pub(crate) unsafe fn model<'a>(model: *const ZooModel) -> Result<&'a ZooModel, Failure> {
    unsafe { handle(model, "model") }
}

/// Loads a model exported by `zoo export --onnx` (any task: transition, keyframes, stitch,
/// synthesis) from the file `path` (UTF-8, NUL-terminated) into `*out`; a `zoo export --portable`
/// main file is loaded with the companion files beside it. `zoo_model_task` says what it does.
/// A file that is not an exported model, of a format version this library does not read, or a
/// bare step graph with no task is `ZOO_STATUS_LOAD_FAILED` with a message naming the fix. Free
/// the model with `zoo_model_free`. Thread-safe.
///
/// Safety: `path` is NULL or a NUL-terminated string; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_load(path: *const c_char, out: *mut *mut ZooModel) -> ZooStatus {
    guard("zoo_model_load", || {
        let path = unsafe { c_str(path, "path") }?;
        unsafe { new_handle(out, || ZooModel::load(path)) }
    })
}

/// Loads a model from memory: `bytes` holds the `bytes_len` bytes of a file written by `zoo export
/// --onnx` (read from an archive, an APK's assets, a resource pack...), with the same checks as
/// `zoo_model_load` and the same model as loading that file (a `--portable` export, whose
/// weights are in companion files, loads from its files only). The library keeps no pointer to
/// `bytes`: free or reuse them when the call returns. Thread-safe.
///
/// Safety: `bytes` is NULL or holds `bytes_len` readable bytes; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_load_memory(
    bytes: *const u8,
    bytes_len: usize,
    out: *mut *mut ZooModel,
) -> ZooStatus {
    guard("zoo_model_load_memory", || {
        let bytes = unsafe { slice(bytes, bytes_len, "bytes") }?;
        if bytes.is_empty() {
            return Err((
                ZooStatus::LoadFailed,
                "`bytes_len` is 0; pass the bytes of a file written by `zoo export --onnx`".into(),
            ));
        }
        unsafe { new_handle(out, || ZooModel::from_bytes(bytes, "the model in memory")) }
    })
}

/// Frees a model from `zoo_model_load` (NULL is ignored). Runners, characters and streams made
/// from it keep what they need, so they may be freed before or after it.
///
/// Safety: `model` is NULL or a pointer from `zoo_model_load` not freed before and not in use.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_free(model: *mut ZooModel) {
    unsafe { free_handle(model) }
}

/// The task of `model`: which functions run it. `ZOO_TASK_NONE` for a NULL handle (the last
/// error says so). Thread-safe.
///
/// Safety: `model` is NULL or a live model.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_task(model: *const ZooModel) -> ZooTask {
    let mut task = ZooTask::None;
    guard("zoo_model_task", || {
        task = unsafe { self::model(model) }?.task();
        Ok(())
    });
    task
}

/// Writes what every model is (task, joints, frame rate, units and axes) into `*out`.
/// Thread-safe.
///
/// Safety: `model` is NULL or a live model; `out` is NULL or valid for a write.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_info(model: *const ZooModel, out: *mut ZooModelInfo) -> ZooStatus {
    guard("zoo_model_info", || {
        let m = unsafe { self::model(model) }?;
        let meta = m.metadata();
        let info = ZooModelInfo {
            task: m.task(),
            joints: meta.skeleton.len(),
            fps: meta.fps,
            metres_per_unit: meta.frame.metres_per_unit,
            up_axis: match meta.frame.up_axis {
                UpAxis::Y => ZooUpAxis::Y,
                UpAxis::Z => ZooUpAxis::Z,
            },
            handedness: match meta.frame.handedness {
                Handedness::Right => ZooHandedness::Right,
                Handedness::Left => ZooHandedness::Left,
            },
            format_version: meta.format_version,
        };
        unsafe { write_out(out, info, "out") }
    })
}

/// Writes the model's skeleton: `parents` receives `K` parent indices (-1 for the root, every
/// parent before its child) and `offsets` `3K` rest offsets from the parent (model units), both
/// in the joint order of every pose (`K`: `zoo_model_info`'s `joints`). Poses given to a
/// stitching model must have these bone lengths. Thread-safe.
///
/// Safety: `model` is NULL or a live model; each buffer is NULL or holds its given length.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_skeleton(
    model: *const ZooModel,
    parents: *mut i32,
    parents_len: usize,
    offsets: *mut f32,
    offsets_len: usize,
) -> ZooStatus {
    guard("zoo_model_skeleton", || {
        let skeleton = &unsafe { self::model(model) }?.metadata().skeleton;
        let k = skeleton.len();
        let parents = unsafe { slice_mut(parents, parents_len, "parents") }?;
        let offsets = unsafe { slice_mut(offsets, offsets_len, "offsets") }?;
        check_size("parents", parents.len(), k, "values", crate::JOINTS)?;
        check_size("offsets", offsets.len(), 3 * k, "floats", format_args!("3 * {}", crate::JOINTS))?;
        parents.copy_from_slice(&skeleton.parents);
        for (j, out) in offsets.chunks_exact_mut(3).enumerate() {
            out.copy_from_slice(&skeleton.offset(j).to_array());
        }
        Ok(())
    })
}

/// Copies the name of joint `joint` of the model's skeleton (UTF-8, the training clips' joint
/// name) into `buffer` (at most `capacity` bytes, NUL-terminated, truncated if needed) and writes
/// its full length in bytes without the NUL into `*length`; `buffer` NULL with `capacity` 0 asks
/// for the length. Joints are in the order of every pose (`joint` < `zoo_model_info`'s
/// `joints`): an engine maps its bones to them by name. Thread-safe.
///
/// Safety: `model` is NULL or a live model; `buffer` is NULL or valid for `capacity` bytes of writes;
/// `length` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_model_joint_name(
    model: *const ZooModel,
    joint: usize,
    buffer: *mut c_char,
    capacity: usize,
    length: *mut usize,
) -> ZooStatus {
    guard("zoo_model_joint_name", || {
        let names = &unsafe { self::model(model) }?.metadata().skeleton.names;
        let name = names.get(joint).ok_or_else(|| {
            (
                ZooStatus::InvalidArgument,
                format!(
                    "joint {joint} (`joint`) does not exist: the skeleton has {} joints (0-based; {})",
                    names.len(),
                    crate::JOINTS
                ),
            )
        })?;
        let bytes = unsafe { crate::optional_slice_mut(buffer.cast::<u8>(), capacity, "buffer") }?;
        if length.is_null() {
            return Err(crate::null("length"));
        }
        if let Some((nul, text)) = bytes.split_last_mut() {
            let n = name.len().min(text.len());
            text[..n].copy_from_slice(&name.as_bytes()[..n]);
            if n < text.len() {
                text[n] = 0;
            } else {
                *nul = 0;
            }
        }
        unsafe { write_out(length, name.len(), "length") }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the crate's docs promise: a model is shared between threads; runners, characters and
    /// streams move between threads.
    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        fn send<T: Send>() {}
        send_sync::<ZooModel>();
        send::<crate::ZooTransitionRunner>();
        send::<crate::ZooTransitionCharacters>();
        send::<crate::ZooKeyframesRunner>();
        send::<crate::ZooStitchStream>();
        send::<crate::ZooSynthesisRunner>();
        send::<crate::ZooSynthesisCharacters>();
        send::<crate::ZooControlRunner>();
        send::<crate::ZooControlCharacters>();
    }
}
