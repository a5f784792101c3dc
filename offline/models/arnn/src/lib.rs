//! The autoregressive recurrent network of "Data-driven Autocompletion for Keyframe Animation"
//! (Zhang and van de Panne, MIG 2018) in candle, on the shared toolkit [`zoo_nn`]: the model
//! (section 6), the loss with its curriculum and scheduled sampling (section 7) and a
//! [`zoo_nn::Trainable`] for the shared training loop.
//!
//! Data are the lamp's preprocessed sequences ([`crate::luxo::preprocess::KeyedSequence`]):
//! six degrees of freedom per frame and the frames that are keys.

pub mod checkpoint;
pub mod completion;
pub mod config;
pub mod entry;
pub mod eval;
pub mod export;
pub mod humanoid;
pub mod inbetween;
pub mod inbetween_export;
pub mod inbetween_train;
pub mod keys;
pub mod luxo;
pub mod model;
pub mod speed;
pub mod train;
pub mod train_run;

pub use config::{Architecture, ArnnConfig, Curriculum, HumanoidSkeleton, KeySampling, NoMemoryOutput};
pub use entry::ArnnModel;
pub use eval::{CompletionError, CompletionReport};
pub use model::{Arnn, ArnnState};
pub use train::{ArnnTrainer, Normalization, complete, complete_partial, complete_partial_raw, complete_raw, hit_keys};

/// What went wrong while building, training or saving an ARNN.
#[derive(Debug, thiserror::Error)]
pub enum ArnnError {
    /// The configuration or the data do not fit.
    #[error("configuration: {0}")]
    Config(String),
    /// The loss became NaN or infinite; the weights were not updated.
    #[error("training loss became {loss} at step {step}; the weights were not updated: lower the learning rate")]
    NonFiniteLoss {
        /// Training step.
        step: u64,
        /// The loss.
        loss: f64,
    },
    /// A tensor operation, a file or the toolkit failed.
    #[error(transparent)]
    Nn(#[from] zoo_nn::NnError),
    /// The simulated lamp's data could not be made or read.
    #[error(transparent)]
    Lamp(#[from] luxo::LuxoError),
    /// A command's input was refused or one of its steps failed (a file, an option), said in
    /// words with the fix.
    #[error(transparent)]
    Message(#[from] zoo_data::Message),
    /// The training loop stopped.
    #[error(transparent)]
    Train(#[from] zoo_nn::TrainError),
}

impl From<candle_core::Error> for ArnnError {
    fn from(e: candle_core::Error) -> Self {
        ArnnError::Nn(zoo_nn::NnError::Candle(e))
    }
}

impl From<ArnnError> for zoo_nn::TrainError {
    fn from(e: ArnnError) -> Self {
        zoo_nn::TrainError::model(e)
    }
}

/// Result with [`ArnnError`].
pub type ArnnResult<T> = std::result::Result<T, ArnnError>;
