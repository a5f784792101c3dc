//! The benchmarks of zoo that span models or run the engine runtime, each a function with a
//! typed result that serialises to the JSON of its command (the models' own benchmarks live
//! with them: `zoo_rmr::bench`, `zoo_rnngmm::bench`):
//!
//! - [`inbetween`]: the in-betweening benchmark (`zoo bench`, LaFAN1 protocol) over the
//!   baselines, run folders of every kind that generates transitions ([`registry`]) and
//!   exported files run by the engine runtime ([`onnx`]);
//! - [`runtime`]: a step's latency and throughput through candle, tract and onnxruntime (`zoo
//!   bench runtime`), and [`keyframes`], the exported ARNN's (`zoo bench keyframes`);
//! - [`keys`]: the keys-only in-betweening benchmark (`zoo bench --layout keys`): key poses
//!   every K frames, the linear and Blender Bezier ([`fcurve`]) baselines and keyframe models;
//! - [`train`]: the training step's speed per thread count (`zoo bench train`);
//! - [`whole_shot`]: whole transitions of the in-betweening design through the runtime, beside
//!   an RTN's start and steps (`zoo bench keyframes --against`);
//! - [`control`] and [`follow`]: RNN-GMM online control (`zoo bench control`) and path
//!   following (`zoo bench follow`) by the candle controllers and the runtime's.

pub mod control;
pub mod exported;
pub use zoo_protocol::fcurve;
pub mod follow;
pub mod frame_budget;
pub mod inbetween;
pub mod keyframes;
pub mod keys;
pub mod onnx;
pub mod registry;
pub mod runtime;
pub mod train;
pub mod whole_shot;

pub use zoo_data::Message;

/// A [`Message`] made by `format!`.
macro_rules! msg {
    ($($arg:tt)*) => {
        zoo_data::Message(format!($($arg)*))
    };
}
pub(crate) use msg;

/// Why a benchmark could not run: a refused input or a failed step, with its cause.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// An input was refused or a step failed, said in words with the fix.
    #[error(transparent)]
    Message(#[from] Message),
    /// The engine runtime failed (loading or running an exported file).
    #[error(transparent)]
    Runtime(#[from] zoo_runtime::MotionError),
    /// A tensor operation failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// The shared toolkit failed.
    #[error(transparent)]
    Nn(#[from] zoo_nn::NnError),
    /// A training step failed.
    #[error(transparent)]
    Train(#[from] zoo_nn::TrainError),
    /// An RTN failed.
    #[error(transparent)]
    Rtn(#[from] zoo_rtn::RtnError),
    /// An RMR failed.
    #[error(transparent)]
    Rmr(#[from] zoo_rmr::RmrError),
    /// An RNN-GMM failed.
    #[error(transparent)]
    RnnGmm(#[from] zoo_rnngmm::RnnGmmError),
    /// An ARNN failed.
    #[error(transparent)]
    Arnn(#[from] zoo_arnn::ArnnError),
    /// A dataset could not be read or split.
    #[error(transparent)]
    Data(#[from] zoo_data::dataset::DataError),
}

/// Result with [`BenchError`].
pub type Result<T> = std::result::Result<T, BenchError>;
