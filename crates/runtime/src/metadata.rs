//! The exported file format: what a model carries in its ONNX `metadata_props` (format
//! version 3). This module is its one owner: exporters build a [`MotionModelMetadata`] and
//! write [`MotionModelMetadata::to_props`]; the runtime reads it back with
//! [`MotionModelMetadata::from_props`] and refuses files without it.
//!
//! Every entry is a string; structured entries are JSON, parsed strictly (a missing or
//! malformed entry is an error naming the key, never a silent default).
//!
//! | key                   | value                                                        |
//! |-----------------------|--------------------------------------------------------------|
//! | `zoo.format_version`  | `"3"`                                                        |
//! | `zoo.model_kind`      | the model, e.g. `"rtn"`                                      |
//! | `zoo.task`            | what the model does, [`MotionTask`]: `"transition"`, `"step"` |
//! | `zoo.config`          | the model's `config.json`, verbatim: informational, for tools that rebuild the model; the runtime never reads it |
//! | `zoo.normalization`   | `{"x": {"mean": [..], "std": [..]}, ...}` named groups       |
//! | `zoo.skeleton`        | `{"names": [..], "parents": [-1, 0, ..], "offsets": [[x,y,z]..]}` |
//! | `zoo.feature_layout`  | `[{"name": "..", "start": 0, "len": 3}, ..]`                 |
//! | `zoo.fps`             | frames per second of the training data, e.g. `"30"`          |
//! | `zoo.frame`           | units and axes of positions and rotations: `{"metres_per_unit": 0.01, "up_axis": "y", "handedness": "right"}` ([`CoordinateFrame`]) |
//! | `zoo.state`           | `[{"input": "h", "output": "h_next"}, ..]`                   |
//! | `zoo.transition`      | task `transition` only: [`TransitionTask`] JSON              |
//! | `zoo.start_graph`     | optional: base64 ONNX of the transition-start graph (below)  |
//!
//! The start graph runs once when a transition starts (e.g. target encoding, hidden-state
//! initializer). Its inputs are `[batch, ...]` f32; each of its outputs is named like a state
//! *input* of the step graph and sets that state slot; slots it does not produce start at zero.
//!
//! Version 2 had no `zoo.frame` (its files are centimetres, Y up, right-handed, like the data);
//! this runtime refuses it and asks for a re-export, so that every file says its units.
//! Version 1 (before the task section) kept the model's config in `zoo.config` and the
//! statistics in `zoo.normalisation`; this runtime refuses it and asks for a re-export.
//!
//! Adding a task: a section type in a new submodule (like [`transition`]), an arm of
//! [`MotionTask`], and its key in [`keys`].

pub mod synthesis;
pub mod transition;

use crate::error::MotionError;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
pub use transition::{TransitionTask, TransitionTerrain};
pub use zoo_motion::frame::CoordinateFrame;

/// The format version this runtime reads and exporters write.
pub const FORMAT_VERSION: u32 = 3;

/// metadata_props keys.
pub mod keys {
    /// Format version, an integer.
    pub const FORMAT_VERSION: &str = "zoo.format_version";
    /// Model kind (`rtn`, ...).
    pub const MODEL_KIND: &str = "zoo.model_kind";
    /// Task of the model (`transition`, `step`).
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
    /// All keys every format-3 model carries (a task may require its section besides).
    pub const REQUIRED: [&str; 10] =
        [FORMAT_VERSION, MODEL_KIND, TASK, CONFIG, NORMALIZATION, SKELETON, FEATURE_LAYOUT, FPS, FRAME, STATE];
}

/// Mean and standard deviation of a group of features (normalized = (x - mean) / std).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionMeanStd {
    /// Per-feature mean.
    pub mean: Vec<f32>,
    /// Per-feature standard deviation (> 0).
    pub std: Vec<f32>,
}

impl MotionMeanStd {
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
    /// given), every mean finite, every deviation finite and > 0. The error names `group` and
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
        if let Some(i) = self.std.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(format!("group `{group}` has std {} at index {i}; every std must be > 0", self.std[i]));
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
    /// Rest offset of each joint from its parent (clip units).
    pub offsets: Vec<[f32; 3]>,
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

    /// Rest offset of joint `j` as a glam vector.
    pub fn offset(&self, j: usize) -> Vec3 {
        Vec3::from_array(self.offsets[j])
    }

    /// The motion core's skeleton (channels default, no end sites).
    pub fn to_skeleton(&self) -> zoo_motion::Skeleton {
        let n = self.names.len();
        zoo_motion::Skeleton {
            names: self.names.clone(),
            parents: self.parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
            offsets: self.offsets.iter().map(|o| Vec3::from_array(*o).as_dvec3()).collect(),
            end_sites: vec![None; n],
            channels: vec![zoo_motion::JointChannels::default(); n],
        }
    }

    /// The skeleton info of a motion-core skeleton.
    pub fn from_skeleton(s: &zoo_motion::Skeleton) -> Self {
        MotionSkeletonInfo {
            names: s.names.clone(),
            parents: s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect(),
            offsets: s.offsets.iter().map(|o| o.as_vec3().to_array()).collect(),
        }
    }

    fn check(&self) -> Result<(), String> {
        let n = self.names.len();
        if self.parents.len() != n || self.offsets.len() != n {
            return Err(format!("{n} names but {} parents and {} offsets", self.parents.len(), self.offsets.len()));
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
    /// Runs with [`crate::TransitionModel`].
    Transition(TransitionTask),
    /// A bare recurrent step graph with no task-level API and no section: the engine drives
    /// it through [`crate::MotionRunner`] (test fixtures, hand-written graphs).
    Step,
}

impl MotionTask {
    /// Task names this runtime knows, as written in `zoo.task`.
    pub const NAMES: [&'static str; 2] = ["transition", "step"];

    /// The task's name, as written in `zoo.task`.
    pub fn name(&self) -> &'static str {
        match self {
            MotionTask::Transition(_) => "transition",
            MotionTask::Step => "step",
        }
    }

    /// The metadata key of the task's section, if it has one.
    pub fn section_key(&self) -> Option<&'static str> {
        match self {
            MotionTask::Transition(_) => Some(keys::TRANSITION),
            MotionTask::Step => None,
        }
    }

    /// The transition section, when this is a `transition` model.
    pub fn as_transition(&self) -> Option<&TransitionTask> {
        match self {
            MotionTask::Transition(t) => Some(t),
            _ => None,
        }
    }

    fn section_json(&self) -> Option<String> {
        match self {
            MotionTask::Transition(t) => Some(json(t)),
            MotionTask::Step => None,
        }
    }

    fn check(&self) -> Result<(), MotionError> {
        let bad = |key: &str, reason: String| MotionError::BadMetadata { key: key.to_string(), reason };
        match self {
            MotionTask::Transition(t) => t.check().map_err(|r| bad(keys::TRANSITION, r)),
            MotionTask::Step => Ok(()),
        }
    }

    /// Parses task `name` (of a model of kind `kind`) and its section.
    fn from_props(name: &str, kind: &str, get: &impl Fn(&str) -> Option<String>) -> Result<Self, MotionError> {
        match name {
            "transition" => {
                let text = get(keys::TRANSITION)
                    .ok_or_else(|| MotionError::MissingMetadata { key: keys::TRANSITION.to_string() })?;
                Ok(MotionTask::Transition(parse(keys::TRANSITION, &text)?))
            }
            "step" => Ok(MotionTask::Step),
            other => Err(MotionError::UnknownTask {
                task: other.to_string(),
                kind: kind.to_string(),
                known: MotionTask::NAMES.join(", "),
            }),
        }
    }
}

/// Everything a format-3 model carries besides the graph.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionModelMetadata {
    /// Format version ([`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Model kind (`rtn`, ...).
    pub model_kind: String,
    /// The task and its typed section.
    pub task: MotionTask,
    /// The model's configuration JSON, verbatim: informational (tools that rebuild the model
    /// read it, e.g. `zoo bench runtime`); the runtime never reads it for behavior.
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
    /// Recurrent state pairs of the step graph.
    pub state: Vec<MotionStatePair>,
}

fn parse<T: serde::de::DeserializeOwned>(key: &str, s: &str) -> Result<T, MotionError> {
    serde_json::from_str(s).map_err(|e| MotionError::BadMetadata { key: key.to_string(), reason: e.to_string() })
}

impl MotionModelMetadata {
    /// The metadata_props entries, in a fixed order (the task section last).
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
        ];
        if let (Some(key), Some(section)) = (self.task.section_key(), self.task.section_json()) {
            props.push((key.to_string(), section));
        }
        props
    }

    /// Checks what [`MotionModelMetadata::from_props`] checks, so that an exporter refuses to
    /// write a file the runtime would refuse to load.
    pub fn check(&self) -> Result<(), MotionError> {
        let bad = |key: &str, reason: String| MotionError::BadMetadata { key: key.to_string(), reason };
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
        self.task.check()?;
        if let MotionTask::Transition(t) = &self.task {
            let d = 3 * self.skeleton.len();
            if t.frame_dim != d {
                return Err(bad(
                    keys::TRANSITION,
                    format!(
                        "frame_dim is {} but the skeleton has {} joints ({d} values)",
                        t.frame_dim,
                        self.skeleton.len()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Reads and checks the metadata; `get` returns the value of a key, if present.
    /// The format version is checked first, so an older or newer file says so instead of
    /// failing on an entry that was renamed.
    pub fn from_props(get: impl Fn(&str) -> Option<String>) -> Result<Self, MotionError> {
        let req = |key: &str| get(key).ok_or_else(|| MotionError::MissingMetadata { key: key.to_string() });
        let version = req(keys::FORMAT_VERSION)?;
        match version.trim().parse::<u32>() {
            Ok(FORMAT_VERSION) => {}
            Ok(found) if found < FORMAT_VERSION => {
                return Err(MotionError::FormatTooOld { found, supported: FORMAT_VERSION });
            }
            _ => return Err(MotionError::UnknownFormatVersion { found: version, supported: FORMAT_VERSION }),
        }
        for key in keys::REQUIRED {
            req(key)?;
        }
        let model_kind = req(keys::MODEL_KIND)?;
        let task = MotionTask::from_props(&req(keys::TASK)?, &model_kind, &get)?;
        let fps_s = req(keys::FPS)?;
        let fps = fps_s.trim().parse::<f32>().map_err(|_| MotionError::BadMetadata {
            key: keys::FPS.into(),
            reason: format!("`{fps_s}` is not a positive number"),
        })?;
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
        };
        metadata.check()?;
        Ok(metadata)
    }
}

fn json<T: Serialize>(v: &T) -> String {
    // Plain structs of strings, numbers and vectors: serialization cannot fail.
    serde_json::to_string(v).unwrap_or_default()
}

/// The model kind (`zoo.model_kind`) of an ONNX file's bytes, read without decoding its graph
/// (`None`: not ONNX, or no kind), so that a loader can name the right one for another kind.
pub fn model_kind(bytes: &[u8]) -> Option<String> {
    use prost::Message as _;
    ModelProps::decode(bytes).ok()?.metadata_props.into_iter().find(|p| p.key == keys::MODEL_KIND).map(|p| p.value)
}

/// The `metadata_props` of an ONNX model (field 14 of `ModelProto`; the graph is skipped).
#[derive(Clone, PartialEq, prost::Message)]
struct ModelProps {
    #[prost(message, repeated, tag = "14")]
    metadata_props: Vec<ModelProp>,
}

/// A `StringStringEntryProto`.
#[derive(Clone, PartialEq, prost::Message)]
struct ModelProp {
    #[prost(string, tag = "1")]
    key: String,
    #[prost(string, tag = "2")]
    value: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transition() -> TransitionTask {
        TransitionTask {
            past_frames: 10,
            transition_frames: 30,
            target_blend: 5,
            frame_dim: 6,
            offset_input: true,
            terrain: None,
        }
    }

    fn sample() -> MotionModelMetadata {
        MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind: "toy".into(),
            task: MotionTask::Transition(transition()),
            config_json: "{\"hidden\": 4}".into(),
            normalization: [("x".to_string(), MotionMeanStd { mean: vec![0.0, 1.0], std: vec![1.0, 2.0] })].into(),
            skeleton: MotionSkeletonInfo {
                names: vec!["Hips".into(), "Spine".into()],
                parents: vec![-1, 0],
                offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
            },
            feature_layout: vec![MotionFeatureSegment { name: "x".into(), start: 0, len: 2 }],
            fps: 30.0,
            frame: CoordinateFrame::ZOO_CM,
            state: vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        }
    }

    fn lookup(props: &[(String, String)]) -> impl Fn(&str) -> Option<String> + '_ {
        |k| props.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone())
    }

    fn edited(edit: impl FnOnce(&mut Vec<(String, String)>)) -> Result<MotionModelMetadata, MotionError> {
        let mut props = sample().to_props();
        edit(&mut props);
        MotionModelMetadata::from_props(lookup(&props))
    }

    fn set(props: &mut [(String, String)], key: &str, value: &str) {
        props.iter_mut().find(|(k, _)| k == key).unwrap().1 = value.to_string();
    }

    #[test]
    fn model_kind_is_read_without_the_graph() {
        use prost::Message as _;
        let entry =
            |key: &str, value: &str| tract_onnx::pb::StringStringEntryProto { key: key.into(), value: value.into() };
        let proto = tract_onnx::pb::ModelProto {
            metadata_props: vec![entry(keys::TASK, "stitch"), entry(keys::MODEL_KIND, "rmr")],
            ..Default::default()
        };
        assert_eq!(model_kind(&proto.encode_to_vec()).as_deref(), Some("rmr"));
        let bare =
            tract_onnx::pb::ModelProto { metadata_props: vec![entry(keys::TASK, "stitch")], ..Default::default() };
        assert_eq!(model_kind(&bare.encode_to_vec()), None);
        assert_eq!(model_kind(b"not an onnx file \xff\xff"), None);
    }

    #[test]
    fn the_frame_is_required_and_checked() {
        let err = edited(|p| p.retain(|(k, _)| k != keys::FRAME)).unwrap_err();
        assert!(matches!(&err, MotionError::MissingMetadata { key } if key == keys::FRAME), "{err}");
        let err = edited(|p| set(p, keys::FRAME, r#"{"metres_per_unit": 0, "up_axis": "y", "handedness": "right"}"#))
            .unwrap_err();
        assert!(err.to_string().contains("metres_per_unit must be a positive number"), "{err}");
        let err = edited(|p| set(p, keys::FRAME, r#"{"metres_per_unit": 1, "up_axis": "x", "handedness": "right"}"#))
            .unwrap_err();
        assert!(err.to_string().contains(keys::FRAME), "{err}");
    }

    #[test]
    fn round_trip() {
        let m = sample();
        let props = m.to_props();
        assert_eq!(props.last().unwrap().0, keys::TRANSITION);
        assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m);
        let step = MotionModelMetadata { task: MotionTask::Step, ..sample() };
        let props = step.to_props();
        assert!(props.iter().all(|(k, _)| k != keys::TRANSITION), "a step model has no section");
        assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), step);
    }

    #[test]
    fn unknown_version_is_refused_before_other_keys() {
        let props = vec![(keys::FORMAT_VERSION.to_string(), "7".to_string())];
        let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
        assert!(matches!(err, MotionError::UnknownFormatVersion { .. }), "{err}");
        assert!(err.to_string().contains("version 7"), "{err}");
    }

    #[test]
    fn a_version_1_file_is_asked_to_re_export() {
        let props = vec![(keys::FORMAT_VERSION.to_string(), "1".to_string())];
        let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
        assert!(matches!(err, MotionError::FormatTooOld { found: 1, supported: FORMAT_VERSION }), "{err}");
        assert!(err.to_string().contains("re-export") && err.to_string().contains("zoo export --onnx"), "{err}");
    }

    #[test]
    fn missing_key_is_named() {
        let err = edited(|p| p.retain(|(k, _)| k != keys::SKELETON)).unwrap_err();
        assert!(err.to_string().contains("zoo.skeleton"), "{err}");
    }

    #[test]
    fn a_missing_task_section_is_named() {
        let err = edited(|p| p.retain(|(k, _)| k != keys::TRANSITION)).unwrap_err();
        assert!(matches!(&err, MotionError::MissingMetadata { key } if key == keys::TRANSITION), "{err}");
        assert!(err.to_string().contains("re-export"), "{err}");
    }

    #[test]
    fn a_task_section_missing_a_field_is_refused() {
        let err = edited(|p| set(p, keys::TRANSITION, r#"{"past_frames": 10, "target_blend": 5}"#)).unwrap_err();
        assert!(matches!(&err, MotionError::BadMetadata { key, .. } if key == keys::TRANSITION), "{err}");
        assert!(err.to_string().contains("transition_frames"), "{err}");
    }

    #[test]
    fn a_malformed_task_section_is_refused() {
        let err = edited(|p| set(p, keys::TRANSITION, "{past_frames: 10")).unwrap_err();
        assert!(matches!(&err, MotionError::BadMetadata { key, .. } if key == keys::TRANSITION), "{err}");
        let err = edited(|p| {
            let t = json(&transition()).replace("\"past_frames\":10", "\"past_frames\":\"ten\"");
            set(p, keys::TRANSITION, &t)
        })
        .unwrap_err();
        assert!(err.to_string().contains("zoo.transition"), "{err}");
        let err = edited(|p| {
            let t = json(&transition()).replace("}", ",\"blend\":3}");
            set(p, keys::TRANSITION, &t)
        })
        .unwrap_err();
        assert!(err.to_string().contains("unknown field `blend`"), "{err}");
    }

    #[test]
    fn a_bad_task_section_value_is_refused() {
        let err = edited(|p| {
            let t = json(&TransitionTask { frame_dim: 7, ..transition() });
            set(p, keys::TRANSITION, &t)
        })
        .unwrap_err();
        assert!(err.to_string().contains("frame_dim 7"), "{err}");
    }

    #[test]
    fn an_unknown_task_is_refused_with_the_known_ones() {
        let err = edited(|p| set(p, keys::TASK, "stitch")).unwrap_err();
        assert!(matches!(&err, MotionError::UnknownTask { task, .. } if task == "stitch"), "{err}");
        assert!(err.to_string().contains("transition, step") && err.to_string().contains("`toy`"), "{err}");
    }

    #[test]
    fn bad_skeleton_and_std_are_refused() {
        let mut m = sample();
        m.skeleton.parents = vec![-1, 5];
        let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
        assert!(err.to_string().contains("`Spine`"), "{err}");
        assert!(m.check().is_err(), "exporters run the same check");
        let mut m = sample();
        m.normalization.get_mut("x").unwrap().std[1] = 0.0;
        let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
        assert!(err.to_string().contains("std 0"), "{err}");
        let mut m = sample();
        m.normalization.get_mut("x").unwrap().mean[0] = f32::NAN;
        let err = m.check().unwrap_err();
        assert!(err.to_string().contains("group `x` has mean NaN at index 0"), "{err}");
        // The skeleton must be the one the transition section's frames are for.
        let mut m = sample();
        m.skeleton.names.push("Head".into());
        m.skeleton.parents.push(1);
        m.skeleton.offsets.push([0.0, 5.0, 0.0]);
        let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
        assert!(err.to_string().contains("frame_dim is 6 but the skeleton has 3 joints (9 values)"), "{err}");
    }

    #[test]
    fn bad_fps_and_config_are_refused() {
        let err = edited(|p| set(p, keys::FPS, "fast")).unwrap_err();
        assert!(matches!(&err, MotionError::BadMetadata { key, .. } if key == keys::FPS), "{err}");
        let err = edited(|p| set(p, keys::FPS, "-30")).unwrap_err();
        assert!(matches!(&err, MotionError::BadMetadata { key, .. } if key == keys::FPS), "{err}");
        let err = edited(|p| set(p, keys::CONFIG, "{oops")).unwrap_err();
        assert!(matches!(&err, MotionError::BadMetadata { key, .. } if key == keys::CONFIG), "{err}");
    }

    #[test]
    fn normalize_round_trip_and_skeleton_conversion() {
        let m = sample();
        let g = &m.normalization["x"];
        let mut v = [3.0, 5.0];
        g.normalize(&mut v);
        assert_eq!(v, [3.0, 2.0]);
        g.denormalize(&mut v);
        assert_eq!(v, [3.0, 5.0]);
        let s = m.skeleton.to_skeleton();
        assert_eq!(s.parents, vec![None, Some(0)]);
        assert_eq!(MotionSkeletonInfo::from_skeleton(&s), m.skeleton);
    }
}
