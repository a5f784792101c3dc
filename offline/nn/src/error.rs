//! Errors of the toolkit and of the training loop.

use std::path::PathBuf;

/// What went wrong in a layer, an optimiser, the moving average or a checkpoint.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// A tensor operation failed (usually a shape bug or an unsupported device).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A JSON file could not be read or written.
    #[error("{path}: invalid JSON: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: serde_json::Error,
    },
    /// A tensor file could not be read, or does not hold what the model needs.
    #[error("{path}: {message}")]
    Tensors {
        /// The file.
        path: PathBuf,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// A saved state (optimiser, moving average) does not fit the variables it is loaded into.
    #[error("{0}")]
    State(String),
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
    /// A value to write is NaN or infinite (the file is not written).
    #[error(transparent)]
    NonFinite(#[from] zoo_motion::finite::NonFinite),
    /// A parameter holds NaN or inf, so it is not saved.
    #[error("parameter `{name}` holds NaN or inf; refusing to overwrite the last good checkpoint")]
    NonFiniteParameter {
        /// Tensor name.
        name: String,
    },
}

/// Result with [`NnError`].
pub type NnResult<T> = std::result::Result<T, NnError>;

/// Why the training loop stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The toolkit failed (checkpoint, optimiser, moving average).
    #[error(transparent)]
    Nn(#[from] NnError),
    /// The model failed.
    #[error("{0}")]
    Model(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// A training step failed or its loss was NaN/inf, or the validation loss was NaN/inf.
    /// Nothing of the failing epoch was saved.
    #[error("training stopped in epoch {epoch} at step {step}: {reason} ({kept})")]
    Stopped {
        /// The epoch that failed (1-based).
        epoch: usize,
        /// Optimiser steps taken before the failure.
        step: u64,
        /// What went wrong.
        reason: String,
        /// Which checkpoints are kept.
        kept: String,
    },
    /// The run folder or the options do not allow the run.
    #[error("{0}")]
    Config(String),
}

impl TrainError {
    /// Wraps a model's own error.
    pub fn model(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        TrainError::Model(Box::new(e))
    }
}
