//! The Recurrent Motion Refiner (Kim, Cho, Hong & Noh, "Recurrent Motion Refiner for
//! Locomotion Stitching", Computer Graphics Forum 2023) in candle: the pose vector of sec. 4,
//! the encoder / recurrent refiner / decoder of sec. 5 with the ablation switches of Tables 1
//! and 2 and Figure 9, the loss of sec. 5.1, and a training core for the shared loop
//! ([`zoo_nn::train_loop`]) via [`RmrTraining`].
//!
//! Training pairs come from [`pairs`] (sec. 4); [`data::make_pairs`] turns clips into
//! encoded pairs.
//!
//! ```no_run
//! use zoo_rmr::prelude::*;
//! # fn main() -> Result<(), RmrError> {
//! let synth = zoo_data::synth::SynthConfig { minutes: 2.0, ..Default::default() };
//! let clips: Vec<_> = zoo_data::synth::generate(&synth).into_iter().map(|c| c.clip).collect();
//! let (train, valid) = clips.split_at(10);
//! let config = Config::tiny();
//! let data = zoo_rmr::data::make_pairs(&config, train.to_vec(), valid.to_vec())?;
//! let trainer = RmrTrainer::new(&data.config, data.stats.clone(), &candle_core::Device::Cpu)?;
//! let mut training = RmrTraining::new(trainer, &data.train, &data.valid)?;
//! # Ok(()) }
//! ```

pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod data;
pub mod entry;
pub mod error;
pub mod export;
pub mod fallback;
pub mod features;
pub mod footlock;
pub mod loss;
pub mod model;
pub mod pairs;
pub mod speed;
pub mod stitch;
pub mod train;
pub mod train_run;

pub use config::{Config, ModelName, RefinerCell, TrainConfig};
pub use entry::RmrModel;
pub use error::{RmrError, RmrResult};
pub use model::Rmr;
pub use train::{RmrTrainer, RmrTraining};

/// The common imports.
pub mod prelude {
    pub use crate::checkpoint;
    pub use crate::config::{Config, RefinerCell, TrainConfig};
    pub use crate::error::{RmrError, RmrResult};
    pub use crate::features::{FeatureLayout, FeatureStats, PairFeatures};
    pub use crate::loss::LossTerms;
    pub use crate::model::Rmr;
    pub use crate::train::{RmrTrainer, RmrTraining};
}
