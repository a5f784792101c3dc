//! Errors of the RTN crate.

/// What went wrong while building, running, training, saving or loading an RTN.
#[derive(Debug, thiserror::Error)]
pub enum RtnError {
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
    /// A tensor operation, a file, a JSON file, a non-finite parameter, or the shared toolkit
    /// (a checkpoint file, an optimiser or moving-average state) failed.
    #[error(transparent)]
    Nn(zoo_nn::NnError),
    /// A command's input was refused or one of its steps failed (a clip, a dataset, an option),
    /// said in words with the fix.
    #[error(transparent)]
    Message(#[from] zoo_data::Message),
    /// The training loop stopped.
    #[error(transparent)]
    Train(#[from] zoo_nn::TrainError),
}

impl From<zoo_nn::NnError> for RtnError {
    fn from(e: zoo_nn::NnError) -> Self {
        match e {
            // RTN's configuration errors keep their `configuration: ` prefix.
            zoo_nn::NnError::Config(m) => RtnError::Config(m),
            e => RtnError::Nn(e),
        }
    }
}

impl From<candle_core::Error> for RtnError {
    fn from(e: candle_core::Error) -> Self {
        RtnError::Nn(zoo_nn::NnError::Candle(e))
    }
}

impl From<RtnError> for zoo_nn::TrainError {
    fn from(e: RtnError) -> Self {
        zoo_nn::TrainError::model(e)
    }
}

/// Result with [`RtnError`].
pub type RtnResult<T> = std::result::Result<T, RtnError>;
