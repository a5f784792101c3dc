//! Configuration of the ARNN: sizes of section 6, training settings of section 7.

use serde::{Deserialize, Serialize};
use zoo_data::luxo::{DOF_NAMES, LampParams};

/// The largest layer width or number of degrees of freedom a configuration may name, so that
/// a corrupt `config.json` is refused instead of aborting on an allocation.
pub const MAX_WIDTH: usize = 4096;

/// The curriculum of section 7.2 as functions of training progress `u = step / total_steps`.
///
/// Teacher forcing (scheduled sampling, Bengio et al. 2015): in the first half the probability
/// of feeding the ground-truth previous frame falls along an inverse sigmoid,
/// `1 / (1 + exp((u - 0.25) / width))`, from about 1 to about 0; it is 0 in the second half.
/// Key importance `omega`: 0 in the first half, then a sigmoid ramp
/// `1 / (1 + exp(-(u - 0.75) / width))` from about 0 to about 1 (Figure 7's curves).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Curriculum {
    /// Optimiser steps over which the schedules run (the whole training run).
    pub total_steps: u64,
    /// Width of both sigmoids in units of `u` (0.05: each ramp takes about a fifth of the run).
    pub width: f64,
    /// Off: no teacher forcing and `omega = 1` from the start (Table 1's "no omega annealing").
    pub enabled: bool,
}

impl Curriculum {
    fn progress(&self, step: u64) -> f64 {
        (step as f64 / self.total_steps.max(1) as f64).min(1.0)
    }

    /// Probability of feeding the ground truth at `step`.
    pub fn teacher_forcing(&self, step: u64) -> f64 {
        let u = self.progress(step);
        if !self.enabled || u >= 0.5 { 0.0 } else { 1.0 / (1.0 + ((u - 0.25) / self.width).exp()) }
    }

    /// Key importance weight `omega` at `step`.
    pub fn omega(&self, step: u64) -> f64 {
        let u = self.progress(step);
        if !self.enabled {
            1.0
        } else if u < 0.5 {
            0.0
        } else {
            1.0 / (1.0 + (-(u - 0.75) / self.width).exp())
        }
    }
}

/// Sizes and training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArnnConfig {
    /// Always `"arnn"` (names the model in `config.json`).
    pub model: String,
    /// Degrees of freedom per frame (6 for the lamp).
    pub dofs: usize,
    /// Names of the degrees of freedom, in pose order (the lamp's
    /// [`zoo_data::luxo::DOF_NAMES`]); a keys file naming others is refused.
    #[serde(default)]
    pub dof_names: Vec<String>,
    /// The lamp the training data came from: its geometry draws the completed motion as BVH.
    #[serde(default)]
    pub lamp: Option<LampParams>,
    /// Width of the two layers of each pose feature net (the paper does not give it).
    pub feature: usize,
    /// Hidden units of each of the two GRU layers (paper: 100).
    pub hidden: usize,
    /// Width of the two linear layers after the GRUs (paper: 10).
    pub decoder: usize,
    /// Dropout (drop probabilities) after GRU layers 1 and 2: the paper's keep probabilities
    /// 0.9 and 0.95 (section 7.3).
    pub gru_dropout: [f64; 2],
    /// Dropout after the two linear layers: the paper's keep probabilities 0.8 and 0.9.
    pub linear_dropout: [f64; 2],
    /// Weight of the key loss at omega = 1 (paper: 100).
    pub key_weight: f64,
    /// Adam learning rate (paper: 1e-3).
    pub learning_rate: f64,
    /// Sequences per batch.
    pub batch_size: usize,
    /// Curriculum.
    pub curriculum: Curriculum,
    /// Seed of the weights and of the trainer's random numbers.
    pub seed: u64,
}

impl ArnnConfig {
    /// The paper's sizes for the lamp.
    pub fn paper() -> Self {
        ArnnConfig {
            model: "arnn".into(),
            dofs: 6,
            dof_names: DOF_NAMES.iter().map(|s| s.to_string()).collect(),
            lamp: Some(LampParams::default()),
            feature: 32,
            hidden: 100,
            decoder: 10,
            gru_dropout: [0.1, 0.05],
            linear_dropout: [0.2, 0.1],
            key_weight: 100.0,
            learning_rate: 1e-3,
            batch_size: 16,
            curriculum: Curriculum { total_steps: 10_000, width: 0.05, enabled: true },
            seed: 0,
        }
    }

    /// A small model for tests.
    pub fn tiny() -> Self {
        ArnnConfig {
            feature: 8,
            hidden: 16,
            decoder: 8,
            gru_dropout: [0.0, 0.0],
            linear_dropout: [0.0, 0.0],
            batch_size: 4,
            ..Self::paper()
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), String> {
        if self.model != "arnn" {
            return Err(format!("config.json names model {:?}, expected \"arnn\"", self.model));
        }
        if self.dofs == 0 || self.feature == 0 || self.hidden == 0 || self.decoder == 0 || self.batch_size == 0 {
            return Err("dofs, feature, hidden, decoder and batch_size must be at least 1".into());
        }
        if [self.dofs, self.feature, self.hidden, self.decoder].iter().any(|&w| w > MAX_WIDTH) {
            return Err(format!("dofs, feature, hidden and decoder must be at most {MAX_WIDTH}"));
        }
        if !self.dof_names.is_empty() && self.dof_names.len() != self.dofs {
            return Err(format!("dof_names has {} names for {} degrees of freedom", self.dof_names.len(), self.dofs));
        }
        let drops = self.gru_dropout.iter().chain(&self.linear_dropout);
        if drops.clone().any(|p| !(0.0..1.0).contains(p)) {
            return Err("dropout probabilities must be in [0, 1)".into());
        }
        if !(self.learning_rate > 0.0 && self.key_weight >= 0.0 && self.curriculum.width > 0.0) {
            return Err("learning_rate and curriculum width must be > 0, key_weight >= 0".into());
        }
        Ok(())
    }
}
