//! RNN-GMM with an adversarial refiner (Wang, Chai & Xia, "Combining Recurrent Neural Networks
//! and Adversarial Training for Human Motion Modelling, Synthesis and Control", 2019) in candle,
//! built on the shared toolkit [`zoo_nn`].
//!
//! - [`features`]: the state feature `x` (root deltas, joint angles, contact bits; eq. 2-4), its
//!   inverse and the normalisation statistics;
//! - [`config`]: sizes and training settings, presets `paper` and `tiny`.

pub mod config;
pub mod error;
pub mod features;

pub use config::{Config, ModelName, TrainConfig};
pub use error::{RnnGmmError, RnnGmmResult};
pub use features::{ContactParams, DecodedMotion, EncodedClip, FeatureSpec, Normalization, RootPlacement};
