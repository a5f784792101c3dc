//! The `keyframes` section (`zoo.keyframes`): what the runtime needs to complete keys with an
//! exported ARNN (Zhang & van de Panne 2018) beyond its step graph.
//!
//! The step graph takes `prev`, `key_a`, `key_b` (`dofs` values each, the pose units of the
//! model's `zoo.feature_layout`), `t_rel` (1) and, for a model with key groups, `fixed_a` and
//! `fixed_b` (`groups` flags each), besides its recurrent state, and gives `pose` (`dofs`).

use serde::{Deserialize, Serialize};

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
}

impl KeyframesTask {
    /// Checks the section.
    pub fn check(&self) -> Result<(), String> {
        if self.dofs == 0 {
            return Err("dofs is 0; a pose has at least one value".into());
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
