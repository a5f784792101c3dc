//! Errors of the RTN crate.

use std::path::PathBuf;

/// What went wrong while building, running, training, saving or loading an RTN.
#[derive(Debug, thiserror::Error)]
pub enum RtnError {
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
    /// A motion window or frame buffer has the wrong size.
    #[error("{what}: expected {expected} values ({detail}), found {found}")]
    Size {
        /// Which input.
        what: String,
        /// Expected number of values.
        expected: usize,
        /// How the expected size is made up.
        detail: String,
        /// Number of values found.
        found: usize,
    },
    /// The configuration and the other inputs do not agree.
    #[error("configuration: {0}")]
    Config(String),
    /// The loss was NaN or infinite; the step was not applied.
    #[error(
        "training loss became {loss} at step {step}; the parameters were not updated and the last good \
         checkpoint is kept: lower the learning rate or look for NaN/inf in the training windows"
    )]
    NonFiniteLoss {
        /// Training step (0-based).
        step: u64,
        /// The loss value.
        loss: f32,
    },
    /// The shared toolkit failed (a checkpoint file, an optimiser or moving-average state).
    #[error(transparent)]
    Nn(zoo_nn::NnError),
    /// A parameter holds NaN or inf, so it is not saved.
    #[error("parameter `{name}` holds NaN or inf; refusing to overwrite the last good checkpoint")]
    NonFiniteParameter {
        /// Tensor name.
        name: String,
    },
}

impl From<zoo_nn::NnError> for RtnError {
    fn from(e: zoo_nn::NnError) -> Self {
        use zoo_nn::NnError as N;
        match e {
            N::Candle(e) => RtnError::Candle(e),
            N::Io { path, source } => RtnError::Io { path, source },
            N::Json { path, source } => RtnError::Json { path, source },
            N::NonFiniteParameter { name } => RtnError::NonFiniteParameter { name },
            N::Config(m) => RtnError::Config(m),
            e => RtnError::Nn(e),
        }
    }
}

impl From<RtnError> for zoo_nn::TrainError {
    fn from(e: RtnError) -> Self {
        zoo_nn::TrainError::model(e)
    }
}

/// Result with [`RtnError`].
pub type RtnResult<T> = std::result::Result<T, RtnError>;
