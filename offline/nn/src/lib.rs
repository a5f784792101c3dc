//! The shared candle toolkit of the zoo's models: what two or more models need, tested once here.
//!
//! - [`rng`]: the one seeded generator ([`SplitMix64`]);
//! - [`init`]: seeded weight initialisation (weights depend on the seed and the variable name only);
//! - [`layers`]: [`Mlp`] with a chosen activation, seeded [`Dropout`];
//! - [`ops`]: fused CPU kernels (the leaky ReLU);
//! - [`act`]: a layer's bias, activation and dropout as one fused op;
//! - [`recurrent`]: multi-layer [`Gru`] and [`Lstm`] with the state outside the layer, and
//!   bidirectional [`BiGru`] / [`BiLstm`] over a sequence;
//! - [`optim`]: [`AmsGrad`], [`Adam`], [`RmsProp`] with their state saved by name, gradient clipping;
//! - [`ema`]: the moving average of the weights;
//! - [`checkpoint`]: atomic writes of JSON, weights and named tensors;
//! - [`export`]: the trained weights as ONNX initializers, for every model's exporter;
//! - [`parallel`]: data-parallel training steps ([`DataParallel`]: one worker thread per
//!   share of the batch, gradients summed before the one optimiser step);
//! - [`train_loop`]: the one training loop, driving any model that implements [`Trainable`];
//! - [`plot`]: the loss-curve PNG;
//! - [`zoo_model`]: the one table of models ([`ZooModel`], each model crate's entry);
//! - [`train_args`], [`args`]: the options of `zoo train` every model shares, and the value
//!   parsers of every numeric option;
//! - [`progress`]: progress on the terminal.

pub mod act;
pub mod args;
pub mod calibrate;
pub mod cells;
pub mod checkpoint;
pub mod ema;
pub mod error;
pub mod export;
pub mod init;
pub mod layers;
pub mod ops;
pub mod optim;
pub mod parallel;
pub mod plot;
pub mod progress;
pub mod recurrent;
pub mod rng;
pub mod run_folder;
pub mod speed;
pub mod tape;
pub mod train_args;
pub mod train_loop;
pub mod zoo_model;

pub use ema::Ema;
pub use error::{NnError, NnResult, TrainError};
pub use export::ExportWeights;
pub use init::SeededVarMap;
pub use layers::{Activation, Dropout, Mlp, RowRngs};
pub use optim::{Adam, AmsGrad, ParamsAdam, ParamsAmsGrad, ParamsRmsProp, RmsProp, StatefulOptimizer};
pub use parallel::DataParallel;
pub use recurrent::{BiGru, BiLstm, Gru, GruState, Lstm, LstmState};
pub use rng::SplitMix64;
pub use train_loop::{TrainOptions, TrainState, Trainable, Validation};
pub use zoo_model::{ExportOptions, Exported, Portable, ZooModel};
