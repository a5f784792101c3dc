//! The Recurrent Transition Network (Harvey & Pal, "Recurrent Transition Networks for Character
//! Locomotion", SIGGRAPH Asia 2018 technical briefs) in candle: the model, its ablations
//! (Table 4), the training core and checkpoints, built on the shared toolkit [`zoo_nn`]
//! (optimiser, moving average, checkpoints, the training loop via [`RtnTraining`]).
//!
//! Data in and out are global joint positions (`f32`, `frames * joints * 3`, frame-major, Y up,
//! clip units); the feature encoding lives in [`zoo_protocol::features`] so the runtime shares it.
//!
//! ```no_run
//! use zoo_rtn::prelude::*;
//! # fn main() -> Result<(), RtnError> {
//! # let windows: Vec<Vec<f32>> = vec![];
//! let config = Config::paper().with_parents(&[None, Some(0), Some(1)]);
//! let ws: Vec<MotionWindow> = windows.iter().map(|w| MotionWindow::new(w)).collect();
//! let stats = fit_stats(&config, &ws)?;
//! let mut trainer = RtnTrainer::new(&config, stats, &candle_core::Device::Cpu)?;
//! let loss = trainer.train_step(&ws[..32])?;
//! trainer.save(std::path::Path::new("runs/rtn"))?;
//! # Ok(()) }
//! ```

pub mod augment;
pub mod checkpoint;
pub mod config;
pub mod entry;
pub mod error;
pub mod export;
pub mod fallback;
pub mod features;
pub mod method;
pub mod model;
pub mod speed;
pub mod train;
pub mod train_run;
pub mod transition;

pub use config::{Config, InitState, ModelName, TeacherForcing, TrainConfig};
pub use entry::RtnModel;
pub use error::{RtnError, RtnResult};
pub use model::{Rtn, RtnInputs, RtnSequence, RtnState};
pub use train::{MotionWindow, RtnTrainer, RtnTraining, fit_stats};

/// The common imports.
pub mod prelude {
    pub use crate::checkpoint;
    pub use crate::config::{Config, InitState, TeacherForcing, TrainConfig};
    pub use crate::error::{RtnError, RtnResult};
    pub use crate::features::{FeatureStats, Heightmap};
    pub use crate::model::{Rtn, RtnInputs, RtnSequence, RtnState};
    pub use crate::train::{MotionWindow, RtnTrainer, RtnTraining, fit_stats};
    pub use zoo_nn::optim::StatefulOptimizer;
}
