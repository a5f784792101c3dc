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

/// The network of a configuration: the paper's ARNN or one of the architectures it is compared
/// with in section 9 (Table 2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Architecture {
    /// The ARNN of section 6: feature nets of `Y'_(t-1)`, `X_K`, `X_(K+1)` and `t_rel` into two
    /// GRU layers, a decoder, a residual on `Y'_(t-1)`.
    #[default]
    Arnn,
    /// Section 9's "keyframe conditioned feed-forward network with no memory": feature nets of
    /// `X_K` and `X_(K+1)` with `t_rel` into two feed-forward layers of `hidden` units (SELU) in
    /// place of the GRUs, the decoder, and the pose itself as output (no previous pose, no
    /// state: each frame is a function of its two keys and `t_rel`).
    NoMemory,
    /// Section 9's segregated net (Figure 14): a motion pattern network, an RNN with no
    /// keyframe conditioning (feature net of `Y'_(t-1)`, two GRU layers of `hidden`, the
    /// decoder, a residual on `Y'_(t-1)`), plus a residual "correction" from a keyframe
    /// conditioned feed-forward interpolation network (feature nets of `X_K`, `X_(K+1)` with
    /// `t_rel`, two layers of `correction` units, a linear layer to the pose).
    Segregated,
}

/// Sizes and training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArnnConfig {
    /// Always `"arnn"` (names the model in `config.json`).
    pub model: String,
    /// The network (the ARNN unless a Table 2 comparison).
    #[serde(default)]
    pub architecture: Architecture,
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
    /// Hidden units of each of the two GRU layers (paper: 100); for
    /// [`Architecture::NoMemory`], of the two feed-forward layers in their place.
    pub hidden: usize,
    /// Units of the two layers of the segregated net's interpolation network (0 otherwise).
    #[serde(default)]
    pub correction: usize,
    /// Width of the two linear layers after the GRUs (paper: 10).
    pub decoder: usize,
    /// Dropout (drop probabilities) after GRU layers 1 and 2: the paper's keep probabilities
    /// 0.9 and 0.95 (section 7.3).
    pub gru_dropout: [f64; 2],
    /// Dropout after the two linear layers: the paper's keep probabilities 0.8 and 0.9.
    pub linear_dropout: [f64; 2],
    /// Weight of the key loss at omega = 1 (paper: 100).
    pub key_weight: f64,
    /// Weight of the ground penalty: the mean over predicted frames of the squared depth of the
    /// base plate's lowest point below the ground, in units of the base height's standard
    /// deviation (0: off, the default; needs `lamp` and the lamp's degrees of freedom). Not in
    /// the paper. Off by default: at 10 it cost accuracy without bounding the depth on the lamp
    /// (docs/arnn.md, "The ground"); completion projects the base onto the ground instead.
    #[serde(default)]
    pub ground_weight: f64,
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
            architecture: Architecture::Arnn,
            dofs: 6,
            dof_names: DOF_NAMES.iter().map(|s| s.to_string()).collect(),
            lamp: Some(LampParams::default()),
            feature: 32,
            hidden: 100,
            correction: 0,
            decoder: 10,
            gru_dropout: [0.1, 0.05],
            linear_dropout: [0.2, 0.1],
            key_weight: 100.0,
            ground_weight: 0.0,
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

    /// This configuration with another architecture whose widths are chosen so that its
    /// parameter count is the nearest to this (ARNN) configuration's, as section 9 compares
    /// them ("the number of layers and hidden units ... adjusted to produce a fair
    /// comparison"): `hidden` for the no-memory net; `hidden` and `correction` (within a factor
    /// 2 of each other) for the segregated net.
    pub fn with_matched_architecture(&self, architecture: Architecture) -> Self {
        let arnn = ArnnConfig { architecture: Architecture::Arnn, correction: 0, ..self.clone() };
        let target = arnn.parameter_count() as i64;
        let mut best = (i64::MAX, arnn.clone());
        let mut consider = |c: ArnnConfig| {
            let diff = (c.parameter_count() as i64 - target).abs();
            if diff < best.0 {
                best = (diff, c);
            }
        };
        match architecture {
            Architecture::Arnn => return arnn,
            Architecture::NoMemory => {
                for w in 1..=MAX_WIDTH {
                    consider(ArnnConfig { architecture, hidden: w, ..arnn.clone() });
                }
            }
            // The GRUs' and the correction's widths within a factor 2 of each other.
            Architecture::Segregated => {
                for w in 1..=MAX_WIDTH {
                    let smallest = ArnnConfig { architecture, hidden: w, correction: w.div_ceil(2), ..arnn.clone() };
                    if smallest.parameter_count() as i64 > target + target / 10 {
                        break;
                    }
                    for c in w.div_ceil(2)..=(2 * w).min(MAX_WIDTH) {
                        consider(ArnnConfig { architecture, hidden: w, correction: c, ..arnn.clone() });
                    }
                }
            }
        }
        best.1
    }

    /// Number of trainable values of the model this configuration builds.
    pub fn parameter_count(&self) -> usize {
        let (d, f, h, w, c) = (self.dofs, self.feature, self.hidden, self.decoder, self.correction);
        let linear = |i: usize, o: usize| i * o + o;
        let features = linear(d, f) + linear(f, f);
        let gru = |i: usize, h: usize| 3 * h * (i + h + 2);
        let decoder = linear(h, w) + linear(w, w) + linear(w, d);
        match self.architecture {
            Architecture::Arnn => 3 * features + gru(3 * f + 1, h) + gru(h, h) + decoder,
            Architecture::NoMemory => 2 * features + linear(2 * f + 1, h) + linear(h, h) + decoder,
            Architecture::Segregated => {
                features
                    + gru(f, h)
                    + gru(h, h)
                    + decoder
                    + 2 * features
                    + linear(2 * f + 1, c)
                    + linear(c, c)
                    + linear(c, d)
            }
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
        if [self.dofs, self.feature, self.hidden, self.decoder, self.correction].iter().any(|&w| w > MAX_WIDTH) {
            return Err(format!("dofs, feature, hidden, decoder and correction must be at most {MAX_WIDTH}"));
        }
        if (self.architecture == Architecture::Segregated) != (self.correction > 0) {
            return Err(format!(
                "correction is {} for the {:?} architecture: it must be at least 1 for the segregated net and 0 \
                 otherwise",
                self.correction, self.architecture
            ));
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
        if !(self.ground_weight >= 0.0 && self.ground_weight.is_finite()) {
            return Err(format!("ground_weight {} must be a finite number >= 0", self.ground_weight));
        }
        Ok(())
    }
}
