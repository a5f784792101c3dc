//! The commands that make motion: `zoo transition`, `zoo decompress`, `zoo stitch`, `zoo
//! complete`, `zoo generate`. Each reads clips, runs the model through the engine runtime
//! (`zoo-runtime`, the code every engine, Python script and Blender add-on runs) and writes
//! clips: a run folder of `zoo train` is exported in memory first ([`model`]), an exported file
//! is run as it is. No command runs a second implementation of a model.

pub mod model;
pub mod transition;

pub use model::ModelSource;

/// Why a command could not finish: a refused input (said with its fix) or a failed step.
#[derive(Debug, thiserror::Error)]
pub enum TaskError {
    /// An input was refused or a step failed, said in words with the fix.
    #[error(transparent)]
    Message(#[from] zoo_data::Message),
    /// The engine runtime refused an input or failed.
    #[error(transparent)]
    Runtime(#[from] zoo_runtime::MotionError),
}

/// Result with [`TaskError`].
pub type TaskResult<T> = Result<T, TaskError>;
