//! Errors of the RNN-GMM crate.

/// What went wrong while encoding motion, building, training, sampling, saving or loading an
/// RNN-GMM.
#[derive(Debug, thiserror::Error)]
pub enum RnnGmmError {
    /// A clip cannot be turned into state features (or features back into a clip).
    #[error("motion: {0}")]
    Motion(String),
    /// A buffer has the wrong size.
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
    /// The configuration and the other inputs do not agree, or a setting is out of range.
    #[error("configuration: {0}")]
    Config(String),
    /// The loss was NaN or infinite; the step was not applied.
    #[error(
        "training loss became {loss} at step {step}; the parameters were not updated and the last good \
         checkpoint is kept: lower the learning rate or look for NaN/inf in the training clips"
    )]
    NonFiniteLoss {
        /// Training step (0-based).
        step: u64,
        /// The loss value.
        loss: f64,
    },
    /// Adversarial training diverged (discriminator collapse); the step's updates were made but
    /// the last good checkpoint is kept by the training loop.
    #[error("adversarial training diverged: {0}")]
    Diverged(String),
    /// A tensor operation, a file, a JSON file, a non-finite parameter, or the shared toolkit
    /// (a checkpoint file, an optimiser state) failed.
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

impl From<zoo_nn::NnError> for RnnGmmError {
    fn from(e: zoo_nn::NnError) -> Self {
        match e {
            zoo_nn::NnError::Config(m) => RnnGmmError::Config(m),
            e => RnnGmmError::Nn(e),
        }
    }
}

impl From<candle_core::Error> for RnnGmmError {
    fn from(e: candle_core::Error) -> Self {
        RnnGmmError::Nn(zoo_nn::NnError::Candle(e))
    }
}

impl From<RnnGmmError> for zoo_nn::TrainError {
    fn from(e: RnnGmmError) -> Self {
        zoo_nn::TrainError::model(e)
    }
}

/// Result with [`RnnGmmError`].
pub type RnnGmmResult<T> = std::result::Result<T, RnnGmmError>;
