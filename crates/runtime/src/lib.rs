//! Engine-side runtime of zoo, and the owner of the exported file format.
//!
//! [`metadata`] defines the format (version, keys, typed metadata and per-task sections);
//! exporters write through it. [`LoadedModel::load`] loads any exported file and dispatches on
//! its model kind to the loader of its task (today [`TransitionModel`] for `rtn`); each task's
//! loader refuses files of another task. Underneath, [`MotionModel`] is the raw step graph
//! (loaded once, `Send + Sync`), one small [`MotionState`] per character, advanced one frame
//! per call by a per-thread [`MotionRunner`] (state in, state out, preallocated buffers). The
//! graph runs on tract; the public API takes and returns plain `f32` slices and glam types only.
//!
//! Depends on tract-onnx and the motion core only: never on candle, the dataset tooling or
//! the CLI (checked with `cargo tree -p zoo-runtime -e normal`).
//!
//! ```no_run
//! use zoo_runtime::prelude::*;
//! let loaded = LoadedModel::load("rtn.onnx")?;
//! let Some(model) = loaded.as_transition() else { return Ok(()) };
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
pub mod keyframes;
pub mod loaded;
pub mod metadata;
pub mod model;
pub mod portable;
pub mod pose;
pub mod runner;
pub mod stitch;
pub mod synthesis;
pub mod transition;

pub use error::MotionError;
pub use loaded::{LoadedModel, MODEL_KINDS};
pub use metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
    MotionTask, TransitionTask, TransitionTerrain,
};
pub use model::{MotionModel, MotionState, MotionStateInfo, MotionTensorInfo};
pub use pose::{Conversion, CoordinateFrame, EnginePose, Handedness, UpAxis};
pub use runner::MotionRunner;
pub use stitch::{FootCleanup, StitchRefiner, StitchStream, StitchStreamOf};
pub use transition::{Heightmap, TargetMiss, TransitionFallback, TransitionModel, TransitionRunner, TransitionState};

/// Re-exported so callers use the same glam version as the runtime.
pub use glam;

/// The common imports of engine code.
pub mod prelude {
    pub use crate::error::MotionError;
    pub use crate::loaded::LoadedModel;
    pub use crate::metadata::{MotionModelMetadata, MotionSkeletonInfo, MotionTask};
    pub use crate::model::{MotionModel, MotionState};
    pub use crate::pose::{Conversion, CoordinateFrame, EnginePose, Handedness, UpAxis};
    pub use crate::runner::MotionRunner;
    pub use crate::transition::{TransitionModel, TransitionRunner, TransitionState};
}
