//! Engine-side runtime of zoo.
//!
//! Loads a model exported by `zoo export --onnx` once ([`MotionModel`], `Send + Sync`), keeps
//! one small [`MotionState`] per character, and advances characters one frame per call with a
//! per-thread [`MotionRunner`] (state in, state out, preallocated buffers). The graph runs on
//! tract; the public API takes and returns plain `f32` slices and glam types only.
//!
//! Depends on tract-onnx and the motion core only: never on candle, the dataset tooling or
//! the CLI (checked with `cargo tree -p zoo-runtime -e normal`).
//!
//! ```no_run
//! use zoo_runtime::prelude::*;
//! let model = MotionModel::load("rtn.onnx")?;
//! let mut runner = model.runner()?;
//! let mut state = model.new_state();
//! let input = vec![0.0; model.inputs()[0].width];
//! let mut output = vec![0.0; model.outputs()[0].width];
//! runner.step(&mut state, &[&input], &mut [&mut output])?;
//! # Ok::<(), MotionError>(())
//! ```

pub mod error;
pub mod metadata;
pub mod model;
pub mod pose;
pub mod transition;

pub use error::MotionError;
pub use metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
};
pub use model::{MotionModel, MotionRunner, MotionState, MotionStateInfo, MotionTensorInfo};
pub use transition::{TransitionModel, TransitionRunner, TransitionState};

/// Re-exported so callers use the same glam version as the runtime.
pub use glam;

/// The common imports of engine code.
pub mod prelude {
    pub use crate::error::MotionError;
    pub use crate::metadata::{MotionModelMetadata, MotionSkeletonInfo};
    pub use crate::model::{MotionModel, MotionRunner, MotionState};
    pub use crate::transition::{TransitionModel, TransitionRunner, TransitionState};
}
