//! The one loader: any exported file, dispatched on its task (`zoo.task`) to the type that runs
//! it.
//!
//! Adding a task: a variant of [`LoadedModel`] and an arm in [`LoadedModel::from_bytes_named`],
//! a module with the task's type (like [`crate::stitch`]), and its section in the format crate
//! (docs/adding-a-model.md).

use crate::error::MotionError;
use crate::keyframes::KeyframeModel;
use crate::metadata::{MotionModelMetadata, MotionTaskKind};
use crate::model::MotionModel;
use crate::stitch::StitchRefiner;
use crate::synthesis::SynthesisModel;
use crate::transition::TransitionModel;
use std::path::Path;

/// A loaded model of any task, as the type that runs its task wraps it. Each variant is cheap
/// to clone and `Send + Sync`: load a file once and share it between characters and threads.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum LoadedModel {
    /// A `transition` model (RTN).
    Transition(TransitionModel),
    /// A `keyframes` model (ARNN step graph, or the in-betweening design's whole-shot graph).
    Keyframes(KeyframeModel),
    /// A `stitch` model (RMR).
    Stitch(StitchRefiner),
    /// A `synthesis` model (RNN-GMM), which also runs speed / facing control
    /// ([`crate::control`]).
    Synthesis(SynthesisModel),
}

/// The type that runs a task, for messages.
pub(crate) fn runner_of(task: MotionTaskKind) -> &'static str {
    match task {
        MotionTaskKind::Transition => "a `transition` model runs with TransitionModel",
        MotionTaskKind::Keyframes => "a `keyframes` model runs with KeyframeModel",
        MotionTaskKind::Stitch => "a `stitch` model runs with StitchRefiner",
        MotionTaskKind::Synthesis => "a `synthesis` model runs with SynthesisModel and ControlledCharacter",
        MotionTaskKind::Step => "a bare `step` graph runs with MotionModel",
    }
}

/// Reads a model file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, MotionError> {
    std::fs::read(path).map_err(|source| MotionError::Io { path: path.display().to_string(), source })
}

impl LoadedModel {
    /// Loads an exported `.onnx` file of any task.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        let path = path.as_ref();
        Self::from_bytes_named(&read_file(path)?, &path.display().to_string())
    }

    /// [`LoadedModel::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        Self::from_bytes_named(bytes, "the given bytes")
    }

    /// Reads the metadata (checked by the format crate: version, keys, the task's section),
    /// then loads the graph with the type of the file's task.
    pub(crate) fn from_bytes_named(bytes: &[u8], origin: &str) -> Result<Self, MotionError> {
        let metadata = MotionModelMetadata::read(bytes, origin)?;
        match metadata.task.kind() {
            MotionTaskKind::Transition => {
                TransitionModel::new(MotionModel::from_parts(bytes, origin, metadata)?).map(LoadedModel::Transition)
            }
            MotionTaskKind::Keyframes => KeyframeModel::from_parts(bytes, origin, metadata).map(LoadedModel::Keyframes),
            MotionTaskKind::Synthesis => {
                SynthesisModel::from_parts(bytes, origin, metadata).map(LoadedModel::Synthesis)
            }
            MotionTaskKind::Stitch => StitchRefiner::from_parts(bytes, origin, metadata).map(LoadedModel::Stitch),
            MotionTaskKind::Step => Err(MotionError::NoTask { kind: metadata.model_kind }),
        }
    }

    /// The model's metadata (task section, skeleton, frame, fps, normalization).
    pub fn metadata(&self) -> &MotionModelMetadata {
        match self {
            LoadedModel::Transition(t) => t.model().metadata(),
            LoadedModel::Keyframes(k) => k.metadata(),
            LoadedModel::Stitch(s) => s.metadata(),
            LoadedModel::Synthesis(s) => s.model().metadata(),
        }
    }

    /// The model kind (`zoo.model_kind`: `rtn`, `arnn`, `rmr`, `rnn-gmm`).
    pub fn kind(&self) -> &str {
        &self.metadata().model_kind
    }

    /// The model's task.
    pub fn task(&self) -> MotionTaskKind {
        self.metadata().task.kind()
    }

    /// The transition model, if this is one.
    pub fn as_transition(&self) -> Option<&TransitionModel> {
        match self {
            LoadedModel::Transition(t) => Some(t),
            _ => None,
        }
    }

    /// The keyframe model, if this is one.
    pub fn as_keyframes(&self) -> Option<&KeyframeModel> {
        match self {
            LoadedModel::Keyframes(k) => Some(k),
            _ => None,
        }
    }

    /// The stitching refiner, if this is one.
    pub fn as_stitch(&self) -> Option<&StitchRefiner> {
        match self {
            LoadedModel::Stitch(s) => Some(s),
            _ => None,
        }
    }

    /// The synthesis model, if this is one.
    pub fn as_synthesis(&self) -> Option<&SynthesisModel> {
        match self {
            LoadedModel::Synthesis(s) => Some(s),
            _ => None,
        }
    }

    /// The transition model, or [`MotionError::WrongTask`] naming the type that runs the file.
    pub fn into_transition(self) -> Result<TransitionModel, MotionError> {
        match self {
            LoadedModel::Transition(t) => Ok(t),
            other => Err(MotionError::wrong_task(other.metadata(), "transition", "TransitionModel")),
        }
    }

    /// The keyframe model, or [`MotionError::WrongTask`].
    pub fn into_keyframes(self) -> Result<KeyframeModel, MotionError> {
        match self {
            LoadedModel::Keyframes(k) => Ok(k),
            other => Err(MotionError::wrong_task(other.metadata(), "keyframes", "KeyframeModel")),
        }
    }

    /// The stitching refiner, or [`MotionError::WrongTask`].
    pub fn into_stitch(self) -> Result<StitchRefiner, MotionError> {
        match self {
            LoadedModel::Stitch(s) => Ok(s),
            other => Err(MotionError::wrong_task(other.metadata(), "stitch", "StitchRefiner")),
        }
    }

    /// The synthesis model, or [`MotionError::WrongTask`].
    pub fn into_synthesis(self) -> Result<SynthesisModel, MotionError> {
        match self {
            LoadedModel::Synthesis(s) => Ok(s),
            other => Err(MotionError::wrong_task(other.metadata(), "synthesis", "SynthesisModel")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_task_names_its_type() {
        for task in MotionTaskKind::ALL {
            assert!(runner_of(task).contains(task.name()), "{task}");
        }
    }

    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<LoadedModel>();
    }
}
