//! Errors of the RMR crate.

/// What went wrong while building, training, saving or loading an RMR.
#[derive(Debug, thiserror::Error)]
pub enum RmrError {
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
    /// The configuration and the other inputs do not agree.
    #[error("configuration: {0}")]
    Config(String),
    /// Making the stitching pairs failed (rig, frame rate, clip lengths, databases).
    #[error(transparent)]
    Stitch(#[from] crate::pairs::StitchError),
    /// The loss was NaN or infinite; the step was not applied.
    #[error(
        "training loss became {loss} at step {step}; the parameters were not updated and the last good \
         checkpoint is kept: lower the learning rate or look for NaN/inf in the training clips"
    )]
    NonFiniteLoss {
        /// Training step (0-based).
        step: u64,
        /// The loss value.
        loss: f32,
    },
    /// A tensor operation, a file, a JSON file, a non-finite parameter, or the shared toolkit failed.
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

impl From<zoo_nn::NnError> for RmrError {
    fn from(e: zoo_nn::NnError) -> Self {
        match e {
            zoo_nn::NnError::Config(m) => RmrError::Config(m),
            e => RmrError::Nn(e),
        }
    }
}

impl From<zoo_protocol::stitch::LayoutError> for RmrError {
    fn from(e: zoo_protocol::stitch::LayoutError) -> Self {
        RmrError::Stitch(e.into())
    }
}

impl From<candle_core::Error> for RmrError {
    fn from(e: candle_core::Error) -> Self {
        RmrError::Nn(zoo_nn::NnError::Candle(e))
    }
}

impl From<RmrError> for zoo_nn::TrainError {
    fn from(e: RmrError) -> Self {
        zoo_nn::TrainError::model(e)
    }
}

/// Result with [`RmrError`].
pub type RmrResult<T> = std::result::Result<T, RmrError>;
