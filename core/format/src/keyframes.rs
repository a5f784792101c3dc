//! The `keyframes` section (`zoo.keyframes`): what the runtime needs to complete keys with an
//! exported keyframe model beyond its graph. Two designs share the task:
//!
//! - the ARNN (Zhang & van de Panne 2018), a per-frame step graph: it takes `prev`, `key_a`,
//!   `key_b` (`dofs` values each, the pose units of the model's `zoo.feature_layout`), `t_rel`
//!   (1) and, for a model with key groups, `fixed_a` and `fixed_b` (`groups` flags each),
//!   besides its recurrent state, and gives `pose` (`dofs`);
//! - the in-betweening network (`zoo train arnn --design inbetween`, the section's
//!   [`InbetweenSection`]), a whole-shot graph: it takes `features` `[batch, frames,
//!   input_width]` (built from the keys by `zoo_protocol::inbetween`) and gives `correction`
//!   `[batch, frames, dofs]`, which the runtime composes with the keys' Bezier curves.
//!
//! Files written before the in-betweening design have no `inbetween` field: they load as ARNN
//! step graphs.

use serde::{Deserialize, Serialize};
use zoo_motion::EulerOrder;

/// metadata_props key of the [`KeyframesTask`] section.
pub const KEY: &str = "zoo.keyframes";

/// How a `keyframes` model is driven.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyframesTask {
    /// Values per pose `D` (6 for the lamp; the humanoid pose of `zoo_arnn::humanoid`).
    pub dofs: usize,
    /// Key groups a partial key can fix or leave free, `G` (0: keys are whole poses). With
    /// groups, the step graph takes `fixed_a` and `fixed_b`.
    pub groups: usize,
    /// The group of each pose value (`dofs` entries in `0..groups`; empty without groups).
    pub key_groups: Vec<usize>,
    /// The in-betweening design's settings: present exactly when the graph is the whole-shot
    /// graph of `zoo train arnn --design inbetween` (absent: an ARNN step graph).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inbetween: Option<InbetweenSection>,
}

/// What the runtime needs to build the in-betweening network's features from keys and to
/// compose its output (`zoo_protocol::inbetween::InbetweenFeatures`): poses are the humanoid pose
/// vector (root position, one `(w, x, y, z)` quaternion per joint, `D = 3 + 4 J`), with one key
/// group for the root and one per joint (`G = 1 + J`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InbetweenSection {
    /// Each joint's Euler channel order as axis indices (0 = X, 1 = Y, 2 = Z; bandai2's ZXY is
    /// `[2, 0, 1]`), skeleton order: the F-curves are drawn on these channels.
    pub euler_axes: Vec<[usize; 3]>,
    /// Frames the gap feature is divided by.
    pub gap_unit: f64,
    /// Mean of each pose value (`D`, f64: the features are built in double precision, as in
    /// training).
    pub mean: Vec<f64>,
    /// Standard deviation of each pose value (`D`, positive).
    pub std: Vec<f64>,
    /// Values per frame of the graph's `features` input, `3 D + 2 + 2 G`.
    pub input_width: usize,
    /// How the graph's correction is made zero on the keys (files written before the field:
    /// the envelope).
    #[serde(default, skip_serializing_if = "is_envelope")]
    pub residual: zoo_protocol::inbetween::Residual,
    /// The fallback towards the curves that `zoo train arnn --design inbetween` calibrates
    /// (`zoo_protocol::inbetween::Fallback`; absent: the network alone, as files written before
    /// the field).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback: Option<zoo_protocol::inbetween::Fallback>,
}

fn is_envelope(r: &zoo_protocol::inbetween::Residual) -> bool {
    *r == zoo_protocol::inbetween::Residual::Envelope
}

impl InbetweenSection {
    /// Joints of the pose.
    pub fn joints(&self) -> usize {
        self.euler_axes.len()
    }

    /// The Euler orders of the joints, or the first joint whose axes are not an order.
    pub fn orders(&self) -> Result<Vec<EulerOrder>, String> {
        self.euler_axes
            .iter()
            .enumerate()
            .map(|(j, a)| {
                EulerOrder::from_axes(*a).ok_or_else(|| {
                    format!("euler_axes of joint {j} is {a:?}: three different axes 0-2 (0 = X) are needed")
                })
            })
            .collect()
    }

    /// The feature settings of the in-betweening inputs (`zoo_protocol::inbetween`).
    pub fn features(&self) -> Result<zoo_protocol::inbetween::InbetweenFeatures, String> {
        Ok(zoo_protocol::inbetween::InbetweenFeatures {
            orders: self.orders()?,
            gap_unit: self.gap_unit,
            mean: self.mean.clone(),
            std: self.std.clone(),
            residual: self.residual,
        })
    }

    /// Checks the section against the task's pose width and groups and the skeleton's joints.
    fn check(&self, task: &KeyframesTask, joints: usize) -> Result<(), String> {
        let j = self.joints();
        if j != joints {
            return Err(format!("inbetween.euler_axes has {j} joints but the skeleton has {joints}"));
        }
        let f = self.features()?;
        f.check().map_err(|e| format!("inbetween: {e}"))?;
        if let Some(fb) = &self.fallback {
            fb.check().map_err(|e| format!("inbetween.fallback: {e}"))?;
        }
        if task.dofs != f.dofs()
            || task.groups != f.groups()
            || task.key_groups != zoo_protocol::inbetween::key_groups(j)
        {
            return Err(format!(
                "the in-betweening design's pose has {} values in {} groups (root, then one per joint) for {j} joints, \
                 the section says dofs {} and groups {} (or other key_groups)",
                f.dofs(),
                f.groups(),
                task.dofs,
                task.groups
            ));
        }
        if self.input_width != f.input_width() {
            return Err(format!(
                "inbetween.input_width is {} but {j} joints make {} feature values per frame",
                self.input_width,
                f.input_width()
            ));
        }
        Ok(())
    }
}

impl KeyframesTask {
    /// Checks the section; `joints` is the skeleton's (the in-betweening design's pose is
    /// built on it).
    pub fn check(&self, joints: usize) -> Result<(), String> {
        if self.dofs == 0 {
            return Err("dofs is 0; a pose has at least one value".into());
        }
        if let Some(ib) = &self.inbetween {
            ib.check(self, joints)?;
        }
        if self.groups == 0 {
            if !self.key_groups.is_empty() {
                return Err(format!("{} key_groups entries but groups is 0", self.key_groups.len()));
            }
            return Ok(());
        }
        if self.key_groups.len() != self.dofs {
            return Err(format!(
                "{} key_groups entries for {} dofs: one group per pose value",
                self.key_groups.len(),
                self.dofs
            ));
        }
        if let Some(i) = self.key_groups.iter().position(|&g| g >= self.groups) {
            return Err(format!("key_groups[{i}] is {} but there are {} groups", self.key_groups[i], self.groups));
        }
        Ok(())
    }
}
