//! RNN-GMM with an adversarial refiner (Wang, Chai & Xia, "Combining Recurrent Neural Networks
//! and Adversarial Training for Human Motion Modelling, Synthesis and Control", 2019) in candle,
//! built on the shared toolkit [`zoo_nn`].
//!
//! - [`features`]: the state feature `x` (root deltas, joint angles, contact bits; eq. 2-4), its
//!   inverse and the normalisation statistics;
//! - [`gmm`]: the Gaussian mixture over the next frame (eq. 6-8) and seeded sampling;
//! - [`model`]: the generator G (FC1-FC3, 2-layer LSTM, mixture head) with the state outside;
//! - [`initial_state`]: initial hidden state estimation (eq. 26);
//! - [`fk`]: differentiable forward kinematics of the features (end effectors, root trajectory);
//! - [`refiner`]: the refiner and the discriminator (eq. 9-13) and their adversarial training
//!   ([`AdversarialTraining`] for the shared loop);
//! - [`control`], [`follow`]: path following by MAP optimisation through the generator (sec. 5.2),
//!   on the ground paths of [`path`]; online control by the scripts of [`controls`] (sec. 5.3);
//! - [`denoise`]: motion denoising by MAP optimisation through the generator (sec. 5.4), and
//!   [`noise`], the denoising benchmark's seeded noise and its Savitzky-Golay baseline;
//! - [`synthesis`]: random synthesis continuing a clip (seed, eq. 26, sampling, refiner, decoding);
//! - [`train`]: the generator's training ([`GeneratorTraining`] for the shared loop);
//! - [`checkpoint`]: run folders;
//! - [`export`]: the generator's step graph as ONNX for the engine runtime.
//!
//! ```no_run
//! use zoo_rnngmm::prelude::*;
//! # fn main() -> Result<(), RnnGmmError> {
//! # let clips: Vec<zoo_motion::Clip> = vec![];
//! let refs: Vec<&zoo_motion::Clip> = clips.iter().collect();
//! let config = Config::paper();
//! let data = TrainingData::from_clips(&config, 30.0, &refs[1..], &refs[..1])?;
//! let config = config.with_dim(data.spec.dim());
//! let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &candle_core::Device::Cpu)?;
//! let mut training = GeneratorTraining::new(trainer, &data.train, &data.valid)?;
//! zoo_nn::train_loop::train(&mut training, &zoo_nn::TrainOptions::new("runs/rnn-gmm", 150, 1))
//!     .map_err(|e| RnnGmmError::Config(e.to_string()))?;
//! # Ok(()) }
//! ```

pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod control;
pub mod controls;
pub mod denoise;
pub mod entry;
pub mod error;
pub mod export;
pub mod features;
pub mod fk;
pub mod follow;
pub mod gmm;
pub mod initial_state;
pub mod model;
pub mod noise;
pub mod online;
pub mod path;
pub mod refiner;
pub mod run;
pub mod speed;
pub mod synthesis;
pub mod train;
pub mod train_run;

pub use config::{Config, ModelName, RefinerConfig, TrainConfig};
pub use denoise::{DenoiseOptions, Denoised, EnergyTerms, denoise};
pub use entry::RnnGmmModel;
pub use error::{RnnGmmError, RnnGmmResult};
pub use features::{ContactParams, DecodedMotion, EncodedClip, FeatureSpec, Normalization, RootPlacement};
pub use follow::{FollowOptions, Followed, follow};
pub use gmm::Mixture;
pub use initial_state::{InitialState, estimate_initial_state};
pub use model::Generator;
pub use online::{Controlled, OnlineOptions};
pub use refiner::{
    AdversarialTrainer, AdversarialTraining, EffectorNorm, JointLimits, Priors, RefinerLoss, RefinerNets,
};
pub use synthesis::{Synthesis, SynthesisChunk, SynthesisOptions, SynthesisStream, synthesize};
pub use train::{GeneratorTrainer, GeneratorTraining, TrainingData, Windows};

/// The common imports.
pub mod prelude {
    pub use crate::checkpoint;
    pub use crate::config::{Config, RefinerConfig, TrainConfig};
    pub use crate::error::{RnnGmmError, RnnGmmResult};
    pub use crate::features::{FeatureSpec, Normalization, RootPlacement};
    pub use crate::gmm::Mixture;
    pub use crate::initial_state::estimate_initial_state;
    pub use crate::model::Generator;
    pub use crate::refiner::{AdversarialTrainer, AdversarialTraining};
    pub use crate::synthesis::{SynthesisOptions, SynthesisStream, synthesize};
    pub use crate::train::{GeneratorTrainer, GeneratorTraining, TrainingData, Windows};
    pub use zoo_motion::rng::SplitMix64;
    pub use zoo_nn::LstmState;
}
