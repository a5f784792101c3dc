//! The `synthesis` section (`zoo.synthesis`): what the runtime needs to run random motion
//! synthesis (and its speed / facing control) with an exported RNN-GMM generator (Wang, Chai &
//! Xia 2019) beyond its step graph: the mixture's size, how a feature frame decodes into a pose,
//! and the refiner when the file embeds one.
//!
//! The step graph takes `x` (`frame_dim`) and gives `weights` (`M`), `means` and `stds`
//! (`M D` each) besides its recurrent state. Control is synthesis plus the engine's controller
//! settings: it needs nothing more in the file.

use serde::{Deserialize, Serialize};

/// metadata_props key of the [`SynthesisTask`] section.
pub const KEY: &str = "zoo.synthesis";
/// metadata_props key of the refiner's step graph (base64 ONNX), present exactly when
/// [`SynthesisTask::refiner`] is: inputs `x` (D), `effectors` (6 E), `h`, `c` (its LSTM state);
/// outputs `x_refined` (D), `h_next`, `c_next`.
pub const REFINER_GRAPH_KEY: &str = "zoo.synthesis.refiner_graph";

/// How a synthesis model is driven and decoded. Feature frame layout (`D` values, clip units):
/// `dtx, dtz` (root step in the previous heading frame), `dry` (heading change), `ty` (root
/// height), `rx, rz` (root tilt rotation vector), 3 values per joint `j >= 1` (rotation vector of
/// `references[j]^-1 * q_j`), then the left and right contact bits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthesisTask {
    /// Values of one feature frame, `D = 6 + 3 (J - 1) + 2`.
    pub frame_dim: usize,
    /// Mixture components `M`.
    pub components: usize,
    /// Reference rotation of every joint, `(x, y, z, w)` (joint 0's is unused).
    pub references: Vec<[f64; 4]>,
    /// The refiner behind the generator (eq. 11), `null` when the file has none.
    #[serde(deserialize_with = "Option::deserialize")]
    pub refiner: Option<SynthesisRefiner>,
}

/// The refiner's end effectors and the statistics of its `effectors` input: per effector its
/// position and velocity in the heading frame (6 values), normalised by `mean` and `std`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthesisRefiner {
    /// Joint index of each end effector.
    pub effectors: Vec<usize>,
    /// Mean of the `6 E` effector values.
    pub mean: Vec<f32>,
    /// Standard deviation of the `6 E` effector values (> 0).
    pub std: Vec<f32>,
}

impl SynthesisTask {
    /// Checks the section against a skeleton of `joints` joints.
    pub fn check(&self, joints: usize) -> Result<(), String> {
        if joints < 2 || self.frame_dim != 6 + 3 * (joints - 1) + 2 {
            return Err(format!(
                "frame_dim is {} but a skeleton of {joints} joints has 6 + 3 ({joints} - 1) + 2 values per frame",
                self.frame_dim
            ));
        }
        if self.components == 0 {
            return Err("components must be at least 1".into());
        }
        if self.references.len() != joints {
            return Err(format!("{} reference rotations for {joints} joints", self.references.len()));
        }
        if let Some(j) = self.references.iter().position(|q| {
            let n = q.iter().map(|v| v * v).sum::<f64>();
            !(n.is_finite() && (n - 1.0).abs() < 1e-3)
        }) {
            return Err(format!("reference rotation {j} is not a unit quaternion: {:?}", self.references[j]));
        }
        if let Some(r) = &self.refiner {
            let e = 6 * r.effectors.len();
            if r.effectors.is_empty() {
                return Err("the refiner has no end effectors".into());
            }
            if let Some(&j) = r.effectors.iter().find(|&&j| j >= joints) {
                return Err(format!("refiner effector joint {j} is out of range for {joints} joints"));
            }
            if r.mean.len() != e || r.std.len() != e {
                return Err(format!(
                    "the refiner's {} effectors need {e} means and stds, found {} and {}",
                    r.effectors.len(),
                    r.mean.len(),
                    r.std.len()
                ));
            }
            if r.mean.iter().any(|m| !m.is_finite()) || r.std.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
                return Err("the refiner's effector means must be finite and its stds positive".into());
            }
        }
        Ok(())
    }
}
