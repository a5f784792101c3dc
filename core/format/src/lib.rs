//! The exported model file of zoo: what a model carries in its ONNX `metadata_props` (format
//! version 5), one format for every task. This crate is its one owner: exporters build a
//! [`MotionModelMetadata`] and write [`MotionModelMetadata::to_props`]; the runtime reads it back
//! with [`MotionModelMetadata::read`] (or [`MotionModelMetadata::from_props`]) and refuses files
//! without it. No tract, no candle: [`pb`] holds the ONNX protobuf messages. The one way files
//! are written in the workspace ([`atomic`]: a temporary file renamed into place) lives here too,
//! so that every crate, the BVH writer the Python package compiles in included, shares it.
//!
//! Every entry is a string; structured entries are JSON, parsed strictly (a missing or malformed
//! entry is an error naming the key and the fix, never a silent default).
//!
//! | key                   | value                                                        |
//! |-----------------------|--------------------------------------------------------------|
//! | `zoo.format_version`  | `"5"`                                                        |
//! | `zoo.model_kind`      | the model: `"rtn"`, `"arnn"`, `"rmr"`, `"rnn-gmm"`           |
//! | `zoo.task`            | what the model does, [`MotionTask`]: `"transition"`, `"keyframes"`, `"stitch"`, `"synthesis"` (`"step"`: a bare step graph) |
//! | `zoo.config`          | the run's `config.json`, verbatim: informational, for tools that rebuild the candle model; the runtime never reads it |
//! | `zoo.normalization`   | `{"x": {"mean": [..], "std": [..]}, ...}` named groups       |
//! | `zoo.skeleton`        | `{"names": [..], "parents": [-1, 0, ..], "offsets": [[x,y,z]..]}` |
//! | `zoo.feature_layout`  | `[{"name": "..", "start": 0, "len": 3}, ..]`: the named ranges of the model's frame vector |
//! | `zoo.fps`             | frames per second of the training data, e.g. `"30"`          |
//! | `zoo.frame`           | units and axes of positions and rotations: `{"metres_per_unit": 0.01, "up_axis": "y", "handedness": "right"}` ([`CoordinateFrame`]) |
//! | `zoo.weights`         | the width the weights are stored in: `"f32"`, `"f16"` or `"int8"` ([`WeightWidth`]) |
//! | `zoo.state`           | `[{"input": "h", "output": "h_next"}, ..]`: the step graph's recurrent state (empty for `stitch`) |
//! | `zoo.transition`      | task `transition`: [`TransitionTask`]                        |
//! | `zoo.start_graph`     | task `transition`, optional: base64 ONNX of the transition-start graph (below) |
//! | `zoo.keyframes`       | task `keyframes`: [`KeyframesTask`]                          |
//! | `zoo.stitch`          | task `stitch`: [`StitchTask`]                                |
//! | `zoo.synthesis`       | task `synthesis`: [`SynthesisTask`]                          |
//! | `zoo.synthesis.refiner_graph` | task `synthesis`, exactly when the section has a refiner: base64 ONNX of the refiner's step graph |
//!
//! The start graph runs once when a transition starts (e.g. target encoding, hidden-state
//! initializer). Its inputs are `[batch, ...]` f32; each of its outputs is named like a state
//! *input* of the step graph and sets that state slot; slots it does not produce start at zero.
//!
//! Older files are refused with the command that re-exports them: version 4 (no `zoo.weights`:
//! every weight was f32), version 3 (RMR files had a
//! format of their own, `zoo.rmr.*`, and ARNN and RNN-GMM files were bare `step` tasks),
//! version 2 (no `zoo.frame`) and version 1.
//!
//! Adding a task: a section type in a new module (like [`stitch`]), an arm of [`MotionTask`],
//! its key in [`keys`], and its check in [`MotionModelMetadata::check`]
//! (docs/adding-a-model.md).

pub mod atomic;
mod error;
pub mod keyframes;
pub mod pb;
pub mod stitch;
pub mod synthesis;
pub mod transition;

pub use error::{FormatError, REEXPORT};
use glam::Vec3;
pub use keyframes::{InbetweenSection, KeyframesTask};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
pub use stitch::{StitchFallback, StitchLayout, StitchTask};
pub use synthesis::{SynthesisRefiner, SynthesisTask};
pub use transition::{
    TimeToArrival, TransitionFallback, TransitionFallbackAt, TransitionTask, TransitionTerrain, fallback_for,
};
pub use zoo_motion::frame::CoordinateFrame;

/// The format version this release reads and writes.
pub const FORMAT_VERSION: u32 = 5;

/// metadata_props keys.
pub mod keys {
    /// Format version, an integer.
    pub const FORMAT_VERSION: &str = "zoo.format_version";
    /// Model kind (`rtn`, `arnn`, `rmr`, `rnn-gmm`).
    pub const MODEL_KIND: &str = "zoo.model_kind";
    /// Task of the model.
    pub const TASK: &str = "zoo.task";
    /// The model's configuration JSON, informational.
    pub const CONFIG: &str = "zoo.config";
    /// Normalization statistics JSON.
    pub const NORMALIZATION: &str = "zoo.normalization";
    /// Skeleton JSON.
    pub const SKELETON: &str = "zoo.skeleton";
    /// Feature layout JSON.
    pub const FEATURE_LAYOUT: &str = "zoo.feature_layout";
    /// Frames per second.
    pub const FPS: &str = "zoo.fps";
    /// Recurrent state pairs of the step graph, JSON.
    pub const STATE: &str = "zoo.state";
    /// Units, up axis and handedness, JSON ([`zoo_motion::frame::CoordinateFrame`]).
    pub const FRAME: &str = "zoo.frame";
    /// Optional base64 ONNX of the transition-start graph.
    pub const START_GRAPH: &str = "zoo.start_graph";
    /// The `transition` task section, JSON.
    pub const TRANSITION: &str = super::transition::KEY;
    /// The `keyframes` task section, JSON.
    pub const KEYFRAMES: &str = super::keyframes::KEY;
    /// The `stitch` task section, JSON.
    pub const STITCH: &str = super::stitch::KEY;
    /// The `synthesis` task section, JSON.
    pub const SYNTHESIS: &str = super::synthesis::KEY;
    /// Base64 ONNX of a synthesis model's refiner step graph.
    pub const SYNTHESIS_REFINER_GRAPH: &str = super::synthesis::REFINER_GRAPH_KEY;
    /// The width the weights are stored in ([`super::WeightWidth`]).
    pub const WEIGHTS: &str = "zoo.weights";
    /// All keys every model carries (its task requires its section besides).
    pub const REQUIRED: [&str; 11] =
        [FORMAT_VERSION, MODEL_KIND, TASK, CONFIG, NORMALIZATION, SKELETON, FEATURE_LAYOUT, FPS, FRAME, STATE, WEIGHTS];
    /// The keys whose value is a whole ONNX model (base64) embedded beside the main graph.
    pub const EMBEDDED_GRAPHS: [&str; 2] = [START_GRAPH, SYNTHESIS_REFINER_GRAPH];
    /// The version key of the RMR files written before one format served every task.
    pub const OLD_RMR_FORMAT_VERSION: &str = "zoo.rmr.format_version";
}

/// The width a model file's weights are stored in (`zoo.weights`; `zoo export --weights`).
///
/// Every graph input and output is f32 at every width; only the weight matrices change:
/// `f16` stores them as IEEE half floats widened by a `Cast` when the model loads, `int8` as
/// signed bytes with one f32 scale per output channel (symmetric, zero point 0), the matrix
/// products of fully-connected layers run as `MatMulInteger` on activations quantized per call
/// to int8, and recurrent ops' weights widened by `DequantizeLinear` (zoo_export's
/// `with_weights` writes both).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WeightWidth {
    /// 32-bit floats (the default).
    #[default]
    F32,
    /// 16-bit floats.
    F16,
    /// 8-bit integers with per-output-channel scales.
    Int8,
}

impl WeightWidth {
    /// Every width, narrowest last.
    pub const ALL: [WeightWidth; 3] = [WeightWidth::F32, WeightWidth::F16, WeightWidth::Int8];

    /// The name written in `zoo.weights` and taken by `zoo export --weights`.
    pub fn name(self) -> &'static str {
        match self {
            WeightWidth::F32 => "f32",
            WeightWidth::F16 => "f16",
            WeightWidth::Int8 => "int8",
        }
    }

    /// The width called `name` (`f32`, `f16`, `int8`), or an error listing them.
    pub fn parse(name: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|w| w.name() == name.trim())
            .ok_or_else(|| format!("`{name}` is not a weight width (f32, f16, int8)"))
    }
}

impl std::fmt::Display for WeightWidth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Mean and standard deviation of a group of features (normalized = (x - mean) / std).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionMeanStd {
    /// Per-feature mean.
    pub mean: Vec<f32>,
    /// Per-feature standard deviation (>= [`MotionMeanStd::MIN_STD`]).
    pub std: Vec<f32>,
}

impl MotionMeanStd {
    /// The smallest standard deviation [`MotionMeanStd::check`] accepts: every trainer floors
    /// its deviations at or above it (1e-6 .. 1e-4, or 1 for a constant feature).
    pub const MIN_STD: f32 = 1e-6;

    /// Normalizes `v` in place. `v.len()` must equal the number of features.
    pub fn normalize(&self, v: &mut [f32]) {
        for ((x, m), s) in v.iter_mut().zip(&self.mean).zip(&self.std) {
            *x = (*x - m) / s;
        }
    }

    /// Undoes [`MotionMeanStd::normalize`] in place.
    pub fn denormalize(&self, v: &mut [f32]) {
        for ((x, m), s) in v.iter_mut().zip(&self.mean).zip(&self.std) {
            *x = *x * s + m;
        }
    }

    /// The one check of a normalization group, shared by the runtime loader, the exporters and
    /// the candle models' run-folder loaders: as many means as deviations (`len` of each when
    /// given), every mean finite, every deviation finite and at least
    /// [`MotionMeanStd::MIN_STD`]. The error names `group` and
    /// the first bad index.
    pub fn check(&self, group: &str, len: Option<usize>) -> Result<(), String> {
        if self.mean.len() != self.std.len() {
            return Err(format!("group `{group}` has {} means but {} stds", self.mean.len(), self.std.len()));
        }
        if let Some(n) = len
            && self.mean.len() != n
        {
            return Err(format!("group `{group}` has {} values, expected {n}", self.mean.len()));
        }
        if let Some(i) = self.mean.iter().position(|m| !m.is_finite()) {
            return Err(format!("group `{group}` has mean {} at index {i}; every mean must be finite", self.mean[i]));
        }
        if let Some(i) = self.std.iter().position(|s| !(s.is_finite() && *s >= Self::MIN_STD)) {
            return Err(format!(
                "group `{group}` has std {:?} at index {i}; every std must be at least {:e} (a smaller one \
                 turns normalized values into inf and NaN; training writes 1 for a constant feature)",
                self.std[i],
                Self::MIN_STD
            ));
        }
        Ok(())
    }
}

/// The one check of a skeleton's parent list (`-1` for the root), shared like
/// [`MotionMeanStd::check`]: the root is joint 0 and every parent comes before its child.
/// `name(j)` names joint `j` in the message.
pub fn check_parents(parents: &[i32], name: impl Fn(usize) -> String) -> Result<(), String> {
    for (j, &p) in parents.iter().enumerate() {
        if (j == 0 && p != -1) || (j > 0 && !(0..j as i32).contains(&p)) {
            return Err(format!(
                "joint {j} ({}) has parent {p}; the root must be joint 0 with parent -1 and every parent must come before its child",
                name(j)
            ));
        }
    }
    Ok(())
}

/// The skeleton a model was trained on.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionSkeletonInfo {
    /// Joint names.
    pub names: Vec<String>,
    /// Parent index of each joint, `-1` for the root.
    pub parents: Vec<i32>,
    /// Rest offset of each joint from its parent (clip units), as the training skeleton has it.
    pub offsets: Vec<[f64; 3]>,
}

impl MotionSkeletonInfo {
    /// Number of joints.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Whether the skeleton has no joints.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Rest offset of joint `j` in single precision.
    pub fn offset(&self, j: usize) -> Vec3 {
        glam::DVec3::from_array(self.offsets[j]).as_vec3()
    }

    /// The motion core's skeleton (channels default, no end sites).
    pub fn to_skeleton(&self) -> zoo_motion::Skeleton {
        let n = self.names.len();
        zoo_motion::Skeleton {
            names: self.names.clone(),
            parents: self.parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
            offsets: self.offsets.iter().map(|o| glam::DVec3::from_array(*o)).collect(),
            end_sites: vec![None; n],
            channels: vec![zoo_motion::JointChannels::default(); n],
        }
    }

    /// The skeleton info of a motion-core skeleton.
    pub fn from_skeleton(s: &zoo_motion::Skeleton) -> Self {
        MotionSkeletonInfo {
            names: s.names.clone(),
            parents: s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect(),
            offsets: s.offsets.iter().map(|o| o.to_array()).collect(),
        }
    }

    /// Checks the skeleton: as many parents and offsets as names, finite offsets, parents
    /// before children.
    pub fn check(&self) -> Result<(), String> {
        let n = self.names.len();
        if n == 0 {
            return Err("the skeleton has no joints".into());
        }
        if self.parents.len() != n || self.offsets.len() != n {
            return Err(format!("{n} names but {} parents and {} offsets", self.parents.len(), self.offsets.len()));
        }
        if let Some(j) = self.offsets.iter().position(|o| o.iter().any(|v| !v.is_finite())) {
            return Err(format!("joint {j} (`{}`) has a non-finite offset {:?}", self.names[j], self.offsets[j]));
        }
        check_parents(&self.parents, |j| format!("`{}`", self.names[j]))
    }
}

/// A named, contiguous range of a feature vector.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MotionFeatureSegment {
    /// Segment name (e.g. `"root_velocity"`).
    pub name: String,
    /// First index.
    pub start: usize,
    /// Number of values.
    pub len: usize,
}

/// One recurrent state of the step graph: the graph reads it from `input` and writes the
/// next frame's value to `output`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MotionStatePair {
    /// Graph input holding the state before the step.
    pub input: String,
    /// Graph output holding the state after the step.
    pub output: String,
}

/// What an exported model does, with the task's own typed section.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum MotionTask {
    /// A transition from context frames to a target pose (RTN); section `zoo.transition`.
    Transition(TransitionTask),
    /// Keyframe completion (ARNN); section `zoo.keyframes`.
    Keyframes(KeyframesTask),
    /// Refining a stitched sequence (RMR); section `zoo.stitch`.
    Stitch(StitchTask),
    /// Random motion synthesis and its control (RNN-GMM); section `zoo.synthesis`.
    Synthesis(SynthesisTask),
    /// A bare recurrent step graph with no task-level API and no section: the engine drives
    /// it through the runtime's `MotionRunner` (test fixtures, hand-written graphs).
    Step,
}

/// The task of a model without its section: what `zoo_model_task` and `LoadedModel::task`
/// report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionTaskKind {
    /// [`MotionTask::Transition`].
    Transition,
    /// [`MotionTask::Keyframes`].
    Keyframes,
    /// [`MotionTask::Stitch`].
    Stitch,
    /// [`MotionTask::Synthesis`].
    Synthesis,
    /// [`MotionTask::Step`].
    Step,
}

impl MotionTaskKind {
    /// Every task, in the order of [`MotionTask::NAMES`].
    pub const ALL: [MotionTaskKind; 5] = [
        MotionTaskKind::Transition,
        MotionTaskKind::Keyframes,
        MotionTaskKind::Stitch,
        MotionTaskKind::Synthesis,
        MotionTaskKind::Step,
    ];

    /// The task's name, as written in `zoo.task`.
    pub fn name(self) -> &'static str {
        match self {
            MotionTaskKind::Transition => "transition",
            MotionTaskKind::Keyframes => "keyframes",
            MotionTaskKind::Stitch => "stitch",
            MotionTaskKind::Synthesis => "synthesis",
            MotionTaskKind::Step => "step",
        }
    }

    /// The task of a name written in `zoo.task`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The metadata key of the task's section, if it has one.
    pub fn section_key(self) -> Option<&'static str> {
        match self {
            MotionTaskKind::Transition => Some(keys::TRANSITION),
            MotionTaskKind::Keyframes => Some(keys::KEYFRAMES),
            MotionTaskKind::Stitch => Some(keys::STITCH),
            MotionTaskKind::Synthesis => Some(keys::SYNTHESIS),
            MotionTaskKind::Step => None,
        }
    }
}

impl std::fmt::Display for MotionTaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl MotionTask {
    /// Task names this release knows, as written in `zoo.task`.
    pub const NAMES: [&'static str; 5] = ["transition", "keyframes", "stitch", "synthesis", "step"];

    /// The task without its section.
    pub fn kind(&self) -> MotionTaskKind {
        match self {
            MotionTask::Transition(_) => MotionTaskKind::Transition,
            MotionTask::Keyframes(_) => MotionTaskKind::Keyframes,
            MotionTask::Stitch(_) => MotionTaskKind::Stitch,
            MotionTask::Synthesis(_) => MotionTaskKind::Synthesis,
            MotionTask::Step => MotionTaskKind::Step,
        }
    }

    /// The task's name, as written in `zoo.task`.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The metadata key of the task's section, if it has one.
    pub fn section_key(&self) -> Option<&'static str> {
        self.kind().section_key()
    }

    /// The transition section, when this is a `transition` model.
    pub fn as_transition(&self) -> Option<&TransitionTask> {
        match self {
            MotionTask::Transition(t) => Some(t),
            _ => None,
        }
    }

    /// The keyframes section, when this is a `keyframes` model.
    pub fn as_keyframes(&self) -> Option<&KeyframesTask> {
        match self {
            MotionTask::Keyframes(t) => Some(t),
            _ => None,
        }
    }

    /// The stitch section, when this is a `stitch` model.
    pub fn as_stitch(&self) -> Option<&StitchTask> {
        match self {
            MotionTask::Stitch(t) => Some(t),
            _ => None,
        }
    }

    /// The synthesis section, when this is a `synthesis` model.
    pub fn as_synthesis(&self) -> Option<&SynthesisTask> {
        match self {
            MotionTask::Synthesis(t) => Some(t),
            _ => None,
        }
    }

    fn section_json(&self) -> Option<String> {
        match self {
            MotionTask::Transition(t) => Some(json(t)),
            MotionTask::Keyframes(t) => Some(json(t)),
            MotionTask::Stitch(t) => Some(json(t)),
            MotionTask::Synthesis(t) => Some(json(t)),
            MotionTask::Step => None,
        }
    }

    /// Parses task `name` (of a model of kind `kind`) and its section.
    fn from_props(name: &str, kind: &str, get: &impl Fn(&str) -> Option<String>) -> Result<Self, FormatError> {
        let Some(task) = MotionTaskKind::from_name(name) else {
            return Err(FormatError::UnknownTask {
                task: name.to_string(),
                kind: kind.to_string(),
                known: MotionTask::NAMES.join(", "),
            });
        };
        let Some(key) = task.section_key() else { return Ok(MotionTask::Step) };
        let text = get(key).ok_or_else(|| FormatError::MissingMetadata { key: key.to_string() })?;
        Ok(match task {
            MotionTaskKind::Transition => MotionTask::Transition(parse(key, &text)?),
            MotionTaskKind::Keyframes => MotionTask::Keyframes(parse(key, &text)?),
            MotionTaskKind::Stitch => MotionTask::Stitch(parse(key, &text)?),
            MotionTaskKind::Synthesis => MotionTask::Synthesis(parse(key, &text)?),
            MotionTaskKind::Step => MotionTask::Step,
        })
    }
}

/// Everything a model file carries besides its graph (and the graphs embedded as base64).
#[derive(Clone, Debug, PartialEq)]
pub struct MotionModelMetadata {
    /// Format version ([`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Model kind (`rtn`, `arnn`, `rmr`, `rnn-gmm`).
    pub model_kind: String,
    /// The task and its typed section.
    pub task: MotionTask,
    /// The model's configuration JSON, verbatim: informational (tools that rebuild the model
    /// read it, e.g. `zoo bench runtime`); the runtime never reads it.
    pub config_json: String,
    /// Named normalization groups.
    pub normalization: BTreeMap<String, MotionMeanStd>,
    /// Skeleton.
    pub skeleton: MotionSkeletonInfo,
    /// Layout of the model's per-frame feature vector.
    pub feature_layout: Vec<MotionFeatureSegment>,
    /// Frames per second of the training data.
    pub fps: f32,
    /// Units, up axis and handedness of the model's positions and rotations (the training
    /// data's; [`zoo_motion::frame::Conversion`] converts the runtime's poses for an engine).
    pub frame: CoordinateFrame,
    /// Recurrent state pairs of the step graph (empty for a `stitch` window graph).
    pub state: Vec<MotionStatePair>,
    /// The width the file's weights are stored in.
    pub weights: WeightWidth,
}

fn parse<T: serde::de::DeserializeOwned>(key: &str, s: &str) -> Result<T, FormatError> {
    serde_json::from_str(s).map_err(|e| FormatError::bad(key, e.to_string()))
}

impl MotionModelMetadata {
    /// The metadata_props entries, in a fixed order (the task section last). Embedded graphs
    /// (`zoo.start_graph`, `zoo.synthesis.refiner_graph`) are written beside them by the
    /// exporter.
    pub fn to_props(&self) -> Vec<(String, String)> {
        let mut props = vec![
            (keys::FORMAT_VERSION.into(), self.format_version.to_string()),
            (keys::MODEL_KIND.into(), self.model_kind.clone()),
            (keys::TASK.into(), self.task.name().to_string()),
            (keys::CONFIG.into(), self.config_json.clone()),
            (keys::NORMALIZATION.into(), json(&self.normalization)),
            (keys::SKELETON.into(), json(&self.skeleton)),
            (keys::FEATURE_LAYOUT.into(), json(&self.feature_layout)),
            (keys::FPS.into(), self.fps.to_string()),
            (keys::FRAME.into(), json(&self.frame)),
            (keys::STATE.into(), json(&self.state)),
            (keys::WEIGHTS.into(), self.weights.name().to_string()),
        ];
        if let (Some(key), Some(section)) = (self.task.section_key(), self.task.section_json()) {
            props.push((key.to_string(), section));
        }
        props
    }

    /// The normalization group `name` with `len` values, or an error naming the key.
    pub fn group(&self, name: &str, len: usize) -> Result<&MotionMeanStd, FormatError> {
        let g = self
            .normalization
            .get(name)
            .ok_or_else(|| FormatError::bad(keys::NORMALIZATION, format!("no group `{name}` of {len} values")))?;
        g.check(name, Some(len)).map_err(|r| FormatError::bad(keys::NORMALIZATION, r))?;
        Ok(g)
    }

    /// Checks what [`MotionModelMetadata::from_props`] checks, so that an exporter refuses to
    /// write a file the runtime would refuse to load.
    pub fn check(&self) -> Result<(), FormatError> {
        let bad = |key: &str, reason: String| FormatError::bad(key, reason);
        if self.format_version != FORMAT_VERSION {
            return Err(bad(
                keys::FORMAT_VERSION,
                format!("version {} given, this zoo writes {FORMAT_VERSION}", self.format_version),
            ));
        }
        if self.model_kind.trim().is_empty() {
            return Err(bad(keys::MODEL_KIND, "the model kind is empty".into()));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(bad(keys::FPS, format!("`{}` is not a positive number", self.fps)));
        }
        self.frame.check().map_err(|r| bad(keys::FRAME, r))?;
        serde_json::from_str::<serde_json::Value>(&self.config_json).map_err(|e| bad(keys::CONFIG, e.to_string()))?;
        for (name, g) in &self.normalization {
            g.check(name, None).map_err(|r| bad(keys::NORMALIZATION, r))?;
        }
        self.skeleton.check().map_err(|reason| bad(keys::SKELETON, reason))?;
        let joints = self.skeleton.len();
        match &self.task {
            MotionTask::Transition(t) => t.check(joints).map_err(|r| bad(keys::TRANSITION, r))?,
            MotionTask::Keyframes(t) => t.check(joints).map_err(|r| bad(keys::KEYFRAMES, r))?,
            MotionTask::Stitch(t) => {
                t.check(&self.skeleton.to_skeleton()).map_err(|r| bad(keys::STITCH, r))?;
                self.group("x", t.dim(joints))?;
                if !self.state.is_empty() {
                    return Err(bad(keys::STATE, "a stitch model's window graph has no recurrent state: `[]`".into()));
                }
            }
            MotionTask::Synthesis(t) => {
                t.check(joints).map_err(|r| bad(keys::SYNTHESIS, r))?;
                self.group("x", t.frame_dim)?;
            }
            MotionTask::Step => {}
        }
        Ok(())
    }

    /// Reads and checks the metadata; `get` returns the value of a key, if present.
    /// The format version is checked first, so an older or newer file says so instead of
    /// failing on an entry that was renamed.
    pub fn from_props(get: impl Fn(&str) -> Option<String>) -> Result<Self, FormatError> {
        let req = |key: &str| get(key).ok_or_else(|| FormatError::MissingMetadata { key: key.to_string() });
        let Some(version) = get(keys::FORMAT_VERSION) else {
            if let Some(v) = get(keys::OLD_RMR_FORMAT_VERSION) {
                return Err(FormatError::FormatTooOld {
                    found: format!("rmr {}", v.trim()),
                    supported: FORMAT_VERSION,
                });
            }
            return Err(FormatError::MissingMetadata { key: keys::FORMAT_VERSION.into() });
        };
        match version.trim().parse::<u32>() {
            Ok(FORMAT_VERSION) => {}
            Ok(found) if found < FORMAT_VERSION => {
                return Err(FormatError::FormatTooOld { found: found.to_string(), supported: FORMAT_VERSION });
            }
            _ => return Err(FormatError::UnknownFormatVersion { found: version, supported: FORMAT_VERSION }),
        }
        for key in keys::REQUIRED {
            req(key)?;
        }
        let model_kind = req(keys::MODEL_KIND)?;
        let task = MotionTask::from_props(&req(keys::TASK)?, &model_kind, &get)?;
        let fps_s = req(keys::FPS)?;
        let fps = fps_s
            .trim()
            .parse::<f32>()
            .map_err(|_| FormatError::bad(keys::FPS, format!("`{fps_s}` is not a positive number")))?;
        let metadata = MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind,
            task,
            config_json: req(keys::CONFIG)?,
            normalization: parse(keys::NORMALIZATION, &req(keys::NORMALIZATION)?)?,
            skeleton: parse(keys::SKELETON, &req(keys::SKELETON)?)?,
            feature_layout: parse(keys::FEATURE_LAYOUT, &req(keys::FEATURE_LAYOUT)?)?,
            fps,
            frame: parse(keys::FRAME, &req(keys::FRAME)?)?,
            state: parse(keys::STATE, &req(keys::STATE)?)?,
            weights: WeightWidth::parse(&req(keys::WEIGHTS)?).map_err(|r| FormatError::bad(keys::WEIGHTS, r))?,
        };
        metadata.check()?;
        if let MotionTask::Synthesis(t) = &metadata.task
            && t.refiner.is_some() != get(keys::SYNTHESIS_REFINER_GRAPH).is_some()
        {
            return Err(FormatError::bad(
                keys::SYNTHESIS_REFINER_GRAPH,
                "the refiner's graph and the section's `refiner` must both be present or both absent",
            ));
        }
        Ok(metadata)
    }

    /// Reads and checks the metadata of an ONNX file's bytes (`origin` names them in errors),
    /// without decoding its graph.
    pub fn read(bytes: &[u8], origin: &str) -> Result<Self, FormatError> {
        let props = read_props(bytes, origin)?;
        Self::from_props(|k| props.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone()))
    }
}

fn json<T: Serialize>(v: &T) -> String {
    // Plain structs of strings, numbers and vectors: serialization cannot fail.
    serde_json::to_string(v).unwrap_or_default()
}

/// The `metadata_props` of an ONNX file's bytes, read without decoding its graph.
pub fn read_props(bytes: &[u8], origin: &str) -> Result<Vec<(String, String)>, FormatError> {
    use prost::Message as _;
    if bytes.is_empty() {
        return Err(FormatError::NotOnnx { origin: origin.to_string(), reason: "the file is empty".into() });
    }
    let props = ModelProps::decode(bytes)
        .map_err(|e| FormatError::NotOnnx { origin: origin.to_string(), reason: e.to_string() })?;
    Ok(props.metadata_props.into_iter().map(|p| (p.key, p.value)).collect())
}

/// The model kind (`zoo.model_kind`) of an ONNX file's bytes, read without decoding its graph
/// (`None`: not ONNX, or no kind).
pub fn model_kind(bytes: &[u8]) -> Option<String> {
    read_props(bytes, "").ok()?.into_iter().find(|(k, _)| k == keys::MODEL_KIND).map(|(_, v)| v)
}

/// The `metadata_props` of an ONNX model (field 14 of `ModelProto`; the graph is skipped).
#[derive(Clone, PartialEq, prost::Message)]
struct ModelProps {
    #[prost(message, repeated, tag = "14")]
    metadata_props: Vec<pb::StringStringEntryProto>,
}

#[cfg(test)]
mod tests;
