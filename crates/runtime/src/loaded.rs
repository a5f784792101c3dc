//! Loading any exported file and dispatching on its model kind (`zoo.model_kind`) to the
//! loader of its task.
//!
//! Adding a model: its kind in [`MODEL_KINDS`], and an arm here. Adding a task besides: a
//! variant of [`LoadedModel`], a module with its loader (like [`crate::transition`]) and its
//! section in [`crate::metadata`].

use crate::error::MotionError;
use crate::model::MotionModel;
use crate::transition::TransitionModel;
use std::path::Path;

/// The model kinds [`LoadedModel`] loads, each with its task.
pub const MODEL_KINDS: [(&str, &str); 1] = [("rtn", "transition")];

/// A loaded model of any known kind, as the loader of its task wraps it.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum LoadedModel {
    /// A `transition` model (kind `rtn`).
    Transition(TransitionModel),
}

impl LoadedModel {
    /// Loads an exported `.onnx` file and wraps it with the loader of its kind.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        Self::from_model(MotionModel::load(path)?)
    }

    /// [`LoadedModel::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        Self::from_model(MotionModel::from_bytes(bytes)?)
    }

    /// Wraps a loaded step graph with the loader of its kind; refuses an unknown kind with the
    /// list of known ones, and a file whose task does not match its kind.
    pub fn from_model(model: MotionModel) -> Result<Self, MotionError> {
        let m = model.metadata();
        match m.model_kind.as_str() {
            "rtn" => TransitionModel::new(model).map(LoadedModel::Transition),
            other => Err(MotionError::UnknownModelKind {
                kind: other.to_string(),
                task: m.task.name().to_string(),
                known: known_kinds(),
            }),
        }
    }

    /// The underlying step-graph model (metadata, inputs, outputs, states).
    pub fn model(&self) -> &MotionModel {
        match self {
            LoadedModel::Transition(t) => t.model(),
        }
    }

    /// The model kind (`zoo.model_kind`).
    pub fn kind(&self) -> &str {
        &self.model().metadata().model_kind
    }

    /// The task name (`zoo.task`).
    pub fn task(&self) -> &'static str {
        self.model().metadata().task.name()
    }

    /// The transition model, if this is one.
    pub fn as_transition(&self) -> Option<&TransitionModel> {
        match self {
            LoadedModel::Transition(t) => Some(t),
        }
    }
}

/// The known kinds as `kind (task)`, comma-separated, for messages.
fn known_kinds() -> String {
    MODEL_KINDS.iter().map(|(k, t)| format!("`{k}` (task `{t}`)")).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_known_kind_has_a_known_task() {
        for (kind, task) in MODEL_KINDS {
            assert!(crate::metadata::MotionTask::NAMES.contains(&task), "kind `{kind}`: task `{task}`");
        }
        assert_eq!(known_kinds(), "`rtn` (task `transition`)");
    }

    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<LoadedModel>();
    }
}
