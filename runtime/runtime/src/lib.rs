//! Engine-side runtime of zoo.
//!
//! The file format (version, keys, a typed section per task) is the `zoo-format` crate's,
//! re-exported here as [`metadata`]; exporters write through it. [`LoadedModel::load`] is the one
//! loader: it loads any exported file and returns its task, each with its typed API:
//! [`TransitionModel`] (transitions, RTN), [`KeyframeModel`] (keyframe completion, ARNN),
//! [`StitchRefiner`] (stitching, RMR), [`SynthesisModel`] (synthesis and its speed / facing
//! control, RNN-GMM). Every error is a [`MotionError`]. Underneath, [`MotionModel`] is the raw step graph
//! (loaded once, `Send + Sync`), one small [`MotionState`] per character, advanced one frame
//! per call by a per-thread [`MotionRunner`] (state in, state out, preallocated buffers). The
//! graph runs on tract; the public API takes and returns plain `f32` slices and glam types only.
//!
//! Depends on tract-onnx and the core crates only (the motion core, the task protocol
//! `zoo_protocol` and the model file `zoo_format`): never on candle, the dataset tooling or
//! the CLI (checked with `cargo tree -p zoo-runtime -e normal`).
//!
//! ```no_run
//! use zoo_runtime::prelude::*;
//! let model = LoadedModel::load("rtn.onnx")?.into_transition()?;
//! let mut runner = model.runner()?;
//! let mut state = model.new_transition();
//! let k = model.joints();
//! let past = vec![0.0; model.past_frames() * 3 * k];
//! let (target, next) = (vec![0.0; 3 * k], vec![0.0; 3 * k]);
//! runner.start(&mut state, &past, &target, &next)?;
//! let mut pose = vec![0.0; 3 * k];
//! runner.step(&mut state, &mut pose)?;
//! # Ok::<(), MotionError>(())
//! ```

pub mod control;
pub mod error;
pub mod follow;
pub mod keyframes;
pub mod loaded;
/// The exported file format: the `zoo-format` crate.
pub use zoo_format as metadata;
pub mod model;
mod ops;
pub mod portable;
pub mod pose;
pub mod reference;
pub mod runner;
pub mod stitch;
pub mod synthesis;
pub mod transition;

/// The runtime's own f32 product tiles, for `examples/mmm_kernels` (not a stable API).
#[doc(hidden)]
pub mod tiles {
    pub use crate::ops::tiles::{Epilogue, TileIsa, Tiles};
}

pub use error::MotionError;
pub use keyframes::{KeyframeModel, KeyframeRunner, MotionKeys};
pub use loaded::LoadedModel;
pub use metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
    MotionTask, MotionTaskKind, TimeToArrival, TransitionFallback, TransitionTask, TransitionTerrain, WeightWidth,
};
pub use model::{MotionModel, MotionState, MotionStateInfo, MotionTensorInfo};
pub use pose::{Conversion, CoordinateFrame, EnginePose, Handedness, UpAxis};
pub use runner::MotionRunner;
pub use stitch::{FootCleanup, StitchRefiner, StitchStream, StitchStreamOf};
pub use synthesis::{SynthesisCharacter, SynthesisModel, SynthesisRunner};
pub use transition::{Heightmap, TargetMiss, TransitionModel, TransitionRunner, TransitionState};

/// Re-exported so callers use the same glam version as the runtime.
pub use glam;

/// The common imports of engine code.
pub mod prelude {
    pub use crate::error::MotionError;
    pub use crate::keyframes::{KeyframeModel, MotionKeys};
    pub use crate::loaded::LoadedModel;
    pub use crate::metadata::{MotionModelMetadata, MotionSkeletonInfo, MotionTask, MotionTaskKind};
    pub use crate::model::{MotionModel, MotionState};
    pub use crate::pose::{Conversion, CoordinateFrame, EnginePose, Handedness, UpAxis};
    pub use crate::runner::MotionRunner;
    pub use crate::stitch::StitchRefiner;
    pub use crate::synthesis::SynthesisModel;
    pub use crate::transition::{TransitionModel, TransitionRunner, TransitionState};
}
