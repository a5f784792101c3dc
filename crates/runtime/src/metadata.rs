//! The metadata an exported model carries in its ONNX `metadata_props` (format version 1).
//!
//! Every entry is a string; structured entries are JSON. Exporters build a
//! [`MotionModelMetadata`] and write [`MotionModelMetadata::to_props`]; the runtime reads it
//! back with [`MotionModelMetadata::from_props`] and refuses files without it.
//!
//! | key                   | value                                                        |
//! |-----------------------|--------------------------------------------------------------|
//! | `zoo.format_version`  | `"1"`                                                        |
//! | `zoo.model_kind`      | e.g. `"rtn"`                                                 |
//! | `zoo.config`          | the model's `config.json`, verbatim                          |
//! | `zoo.normalisation`   | `{"x": {"mean": [..], "std": [..]}, ...}` named groups       |
//! | `zoo.skeleton`        | `{"names": [..], "parents": [-1, 0, ..], "offsets": [[x,y,z]..]}` |
//! | `zoo.feature_layout`  | `[{"name": "..", "start": 0, "len": 3}, ..]`                 |
//! | `zoo.fps`             | frames per second of the training data, e.g. `"30"`          |
//! | `zoo.state`           | `[{"input": "h", "output": "h_next"}, ..]`                   |
//! | `zoo.start_graph`     | optional: base64 ONNX of the transition-start graph (below)  |
//!
//! The start graph runs once when a transition starts (e.g. target encoding, hidden-state
//! initialiser). Its inputs are `[batch, ...]` f32; each of its outputs is named like a state
//! *input* of the step graph and sets that state slot; slots it does not produce start at zero.

use crate::error::MotionError;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The format version this runtime reads and exporters write.
pub const FORMAT_VERSION: u32 = 1;

/// metadata_props keys.
pub mod keys {
    /// Format version, an integer.
    pub const FORMAT_VERSION: &str = "zoo.format_version";
    /// Model kind (`rtn`, ...).
    pub const MODEL_KIND: &str = "zoo.model_kind";
    /// Model configuration JSON.
    pub const CONFIG: &str = "zoo.config";
    /// Normalisation statistics JSON.
    pub const NORMALISATION: &str = "zoo.normalisation";
    /// Skeleton JSON.
    pub const SKELETON: &str = "zoo.skeleton";
    /// Feature layout JSON.
    pub const FEATURE_LAYOUT: &str = "zoo.feature_layout";
    /// Frames per second.
    pub const FPS: &str = "zoo.fps";
    /// Recurrent state pairs of the step graph, JSON.
    pub const STATE: &str = "zoo.state";
    /// Optional base64 ONNX of the transition-start graph.
    pub const START_GRAPH: &str = "zoo.start_graph";
    /// All keys a format-1 model must carry.
    pub const REQUIRED: [&str; 8] =
        [FORMAT_VERSION, MODEL_KIND, CONFIG, NORMALISATION, SKELETON, FEATURE_LAYOUT, FPS, STATE];
}

/// Mean and standard deviation of a group of features (normalised = (x - mean) / std).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MotionMeanStd {
    /// Per-feature mean.
    pub mean: Vec<f32>,
    /// Per-feature standard deviation (> 0).
    pub std: Vec<f32>,
}

impl MotionMeanStd {
    /// Normalises `v` in place. `v.len()` must equal the number of features.
    pub fn normalise(&self, v: &mut [f32]) {
        for ((x, m), s) in v.iter_mut().zip(&self.mean).zip(&self.std) {
            *x = (*x - m) / s;
        }
    }

    /// Undoes [`MotionMeanStd::normalise`] in place.
    pub fn denormalise(&self, v: &mut [f32]) {
        for ((x, m), s) in v.iter_mut().zip(&self.mean).zip(&self.std) {
            *x = *x * s + m;
        }
    }
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
        for (j, &p) in self.parents.iter().enumerate() {
            if (j == 0 && p != -1) || (j > 0 && !(0..j as i32).contains(&p)) {
                return Err(format!(
                    "joint {j} (`{}`) has parent {p}; the root must be joint 0 with parent -1 and every parent must come before its child",
                    self.names[j]
                ));
            }
        }
        Ok(())
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

/// Everything a format-1 model carries besides the graph.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionModelMetadata {
    /// Format version ([`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Model kind (`rtn`, ...).
    pub model_kind: String,
    /// The model's configuration JSON, verbatim.
    pub config_json: String,
    /// Named normalisation groups.
    pub normalisation: BTreeMap<String, MotionMeanStd>,
    /// Skeleton.
    pub skeleton: MotionSkeletonInfo,
    /// Layout of the model's per-frame feature vector.
    pub feature_layout: Vec<MotionFeatureSegment>,
    /// Frames per second of the training data.
    pub fps: f32,
    /// Recurrent state pairs of the step graph.
    pub state: Vec<MotionStatePair>,
}

impl MotionModelMetadata {
    /// The metadata_props entries, in a fixed order.
    pub fn to_props(&self) -> Vec<(String, String)> {
        vec![
            (keys::FORMAT_VERSION.into(), self.format_version.to_string()),
            (keys::MODEL_KIND.into(), self.model_kind.clone()),
            (keys::CONFIG.into(), self.config_json.clone()),
            (keys::NORMALISATION.into(), json(&self.normalisation)),
            (keys::SKELETON.into(), json(&self.skeleton)),
            (keys::FEATURE_LAYOUT.into(), json(&self.feature_layout)),
            (keys::FPS.into(), self.fps.to_string()),
            (keys::STATE.into(), json(&self.state)),
        ]
    }

    /// Reads and checks the metadata; `get` returns the value of a key, if present.
    /// The format version is checked first, so a newer file says so instead of failing on
    /// an entry it renamed.
    pub fn from_props(get: impl Fn(&str) -> Option<String>) -> Result<Self, MotionError> {
        let req = |key: &str| get(key).ok_or_else(|| MotionError::MissingMetadata { key: key.to_string() });
        let version = req(keys::FORMAT_VERSION)?;
        if version.trim().parse::<u32>().ok() != Some(FORMAT_VERSION) {
            return Err(MotionError::UnknownFormatVersion { found: version, supported: FORMAT_VERSION });
        }
        for key in keys::REQUIRED {
            req(key)?;
        }
        fn parse<T: serde::de::DeserializeOwned>(key: &str, s: &str) -> Result<T, MotionError> {
            serde_json::from_str(s)
                .map_err(|e| MotionError::BadMetadata { key: key.to_string(), reason: e.to_string() })
        }
        let config_json = req(keys::CONFIG)?;
        parse::<serde_json::Value>(keys::CONFIG, &config_json)?;
        let fps_s = req(keys::FPS)?;
        let fps = fps_s.trim().parse::<f32>().ok().filter(|f| f.is_finite() && *f > 0.0).ok_or_else(|| {
            MotionError::BadMetadata { key: keys::FPS.into(), reason: format!("`{fps_s}` is not a positive number") }
        })?;
        let normalisation: BTreeMap<String, MotionMeanStd> = parse(keys::NORMALISATION, &req(keys::NORMALISATION)?)?;
        for (name, g) in &normalisation {
            if g.mean.len() != g.std.len() {
                return Err(MotionError::BadMetadata {
                    key: keys::NORMALISATION.into(),
                    reason: format!("group `{name}` has {} means but {} stds", g.mean.len(), g.std.len()),
                });
            }
            if let Some(i) = g.std.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
                return Err(MotionError::BadMetadata {
                    key: keys::NORMALISATION.into(),
                    reason: format!("group `{name}` has std {} at index {i}; every std must be > 0", g.std[i]),
                });
            }
        }
        let skeleton: MotionSkeletonInfo = parse(keys::SKELETON, &req(keys::SKELETON)?)?;
        skeleton.check().map_err(|reason| MotionError::BadMetadata { key: keys::SKELETON.into(), reason })?;
        Ok(MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind: req(keys::MODEL_KIND)?,
            config_json,
            normalisation,
            skeleton,
            feature_layout: parse(keys::FEATURE_LAYOUT, &req(keys::FEATURE_LAYOUT)?)?,
            fps,
            state: parse(keys::STATE, &req(keys::STATE)?)?,
        })
    }
}

fn json<T: Serialize>(v: &T) -> String {
    // Plain structs of strings, numbers and vectors: serialisation cannot fail.
    serde_json::to_string(v).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> MotionModelMetadata {
        MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind: "toy".into(),
            config_json: "{\"hidden\": 4}".into(),
            normalisation: [("x".to_string(), MotionMeanStd { mean: vec![0.0, 1.0], std: vec![1.0, 2.0] })].into(),
            skeleton: MotionSkeletonInfo {
                names: vec!["Hips".into(), "Spine".into()],
                parents: vec![-1, 0],
                offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
            },
            feature_layout: vec![MotionFeatureSegment { name: "x".into(), start: 0, len: 2 }],
            fps: 30.0,
            state: vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        }
    }

    fn lookup(props: &[(String, String)]) -> impl Fn(&str) -> Option<String> + '_ {
        |k| props.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone())
    }

    #[test]
    fn round_trip() {
        let m = sample();
        let props = m.to_props();
        assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m);
    }

    #[test]
    fn unknown_version_is_refused_before_other_keys() {
        let props = vec![(keys::FORMAT_VERSION.to_string(), "7".to_string())];
        let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
        assert!(matches!(err, MotionError::UnknownFormatVersion { .. }), "{err}");
        assert!(err.to_string().contains("version 7"), "{err}");
    }

    #[test]
    fn missing_key_is_named() {
        let mut props = sample().to_props();
        props.retain(|(k, _)| k != keys::SKELETON);
        let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
        assert!(err.to_string().contains("zoo.skeleton"), "{err}");
    }

    #[test]
    fn bad_skeleton_and_std_are_refused() {
        let mut m = sample();
        m.skeleton.parents = vec![-1, 5];
        let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
        assert!(err.to_string().contains("`Spine`"), "{err}");
        let mut m = sample();
        m.normalisation.get_mut("x").unwrap().std[1] = 0.0;
        let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
        assert!(err.to_string().contains("std 0"), "{err}");
    }

    #[test]
    fn normalise_round_trip_and_skeleton_conversion() {
        let m = sample();
        let g = &m.normalisation["x"];
        let mut v = [3.0, 5.0];
        g.normalise(&mut v);
        assert_eq!(v, [3.0, 2.0]);
        g.denormalise(&mut v);
        assert_eq!(v, [3.0, 5.0]);
        let s = m.skeleton.to_skeleton();
        assert_eq!(s.parents, vec![None, Some(0)]);
        assert_eq!(MotionSkeletonInfo::from_skeleton(&s), m.skeleton);
    }
}
