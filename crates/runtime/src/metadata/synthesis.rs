//! The `synthesis` section (`zoo.synthesis`): what the runtime needs to run random motion
//! synthesis with an exported RNN-GMM generator (Wang, Chai & Xia 2019) beyond its step graph:
//! the mixture's size and how a state feature frame decodes into a pose.
//!
//! The file's `zoo.task` is `step` (the generator is a plain recurrent step graph); this section
//! makes it a synthesis model for [`crate::synthesis::SynthesisModel`].

use serde::{Deserialize, Serialize};

/// metadata_props key of the [`SynthesisTask`] section.
pub const KEY: &str = "zoo.synthesis";
/// metadata_props key of the refiner's step graph (base64 ONNX; optional): inputs `x` (D),
/// `effectors` (6 E), `h`, `c`; outputs `x_refined` (D), `h_next`, `c_next`.
pub const REFINER_GRAPH_KEY: &str = "zoo.rnngmm.refiner_graph";
/// metadata_props key of the refiner's end effectors and their statistics (JSON
/// `{"effectors": [joint, ...], "mean": [6 E], "std": [6 E]}`; with the refiner graph).
pub const REFINER_KEY: &str = "zoo.rnngmm.refiner";

/// How a synthesis model is driven and decoded. Feature frame layout (`D` values, clip units):
/// `dtx, dtz` (root step in the previous heading frame), `dry` (heading change), `ty` (root
/// height), `rx, rz` (root tilt rotation vector), 3 values per joint `j >= 1` (rotation vector of
/// `references[j]^-1 * q_j`), then the left and right contact bits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SynthesisTask {
    /// Values of one feature frame, `D = 6 + 3 (J - 1) + 2`.
    pub frame_dim: usize,
    /// Mixture components `M`: the step graph outputs `weights` (M), `means` and `stds` (M D).
    pub components: usize,
    /// Reference rotation of every joint, `(x, y, z, w)` (joint 0's is unused).
    pub references: Vec<[f64; 4]>,
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
        Ok(())
    }
}
