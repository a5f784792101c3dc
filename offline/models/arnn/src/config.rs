//! Configuration of the ARNN: sizes of section 6, training settings of section 7.

use crate::luxo::{DOF_NAMES, LampParams};
use serde::{Deserialize, Serialize};

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
///
/// An optional frame phase (`frame_phase > 0`, not in the paper's schedule) follows the ramps:
/// they then run over the first `1 - frame_phase` of the steps, and in the last `frame_phase`
/// of them `omega` is `frame_phase_omega` (below 1: the frame loss weighs more against the
/// keys), section 9's "additional training that further weights the frame prediction loss
/// after omega has been annealed".
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Curriculum {
    /// Optimiser steps over which the schedules run (the whole training run).
    pub total_steps: u64,
    /// Width of both sigmoids in units of `u` (0.05: each ramp takes about a fifth of the run).
    pub width: f64,
    /// Off: no teacher forcing and `omega = 1` from the start (Table 1's "no omega annealing").
    pub enabled: bool,
    /// Fraction of `total_steps`, at the end, spent in the frame phase (0: none, the paper's
    /// schedule and what a file without the field reads as).
    #[serde(default)]
    pub frame_phase: f64,
    /// `omega` during the frame phase.
    #[serde(default = "one")]
    pub frame_phase_omega: f64,
}

fn one() -> f64 {
    1.0
}

impl Curriculum {
    /// The paper's curriculum over `total_steps` (ramp width 0.05, no frame phase).
    pub fn paper(total_steps: u64) -> Self {
        Curriculum { total_steps, width: 0.05, enabled: true, frame_phase: 0.0, frame_phase_omega: 1.0 }
    }

    /// The steps over which the ramps run (all of them without a frame phase).
    fn ramp_steps(&self) -> f64 {
        (self.total_steps.max(1) as f64 * (1.0 - self.frame_phase)).max(1.0)
    }

    /// Whether `step` is in the frame phase.
    pub fn in_frame_phase(&self, step: u64) -> bool {
        self.enabled && self.frame_phase > 0.0 && step as f64 >= self.ramp_steps()
    }

    fn progress(&self, step: u64) -> f64 {
        (step as f64 / self.ramp_steps()).min(1.0)
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
        } else if self.in_frame_phase(step) {
            self.frame_phase_omega
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
    /// place of the GRUs, the decoder, and by default a residual added to the linear
    /// interpolation of the two keys at `t_rel` ([`NoMemoryOutput`]; no previous pose, no
    /// state: each frame is a function of its two keys and `t_rel`). With partial keys the
    /// free groups of a key hold 0 (the mean), so the interpolation pulls them to the mean and
    /// the residual must undo it from the flags; the comparison of Table 2 uses whole keys.
    NoMemory,
    /// Section 9's segregated net (Figure 14): a motion pattern network, an RNN with no
    /// keyframe conditioning (feature net of `Y'_(t-1)`, two GRU layers of `hidden`, the
    /// decoder, a residual on `Y'_(t-1)`), plus a residual "correction" from a keyframe
    /// conditioned feed-forward interpolation network (feature nets of `X_K`, `X_(K+1)` with
    /// `t_rel`, two layers of `correction` units, a linear layer to the pose).
    Segregated,
}

/// What the no-memory net's decoder output is added to. The paper does not say; section 9's
/// Table 2 gives this net the lowest key loss of the three, which only the interpolation
/// residual reproduced here (docs/arnn.md, "Table 2 and the no-memory net's output").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoMemoryOutput {
    /// Nothing: the decoder's output is the pose (the first design; what a run written before
    /// this setting existed was trained with).
    Pose,
    /// A residual on the pose of `X_K`, the last key (as the ARNN's residual is on the last pose).
    KeyResidual,
    /// A residual on the keys' linear interpolation `X_K + t_rel (X_(K+1) - X_K)`.
    #[default]
    Interpolation,
}

impl NoMemoryOutput {
    /// The design of a configuration file that does not name one.
    fn legacy() -> Self {
        NoMemoryOutput::Pose
    }
}

/// How training chooses the keys of a sequence each time it feeds it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum KeySampling {
    /// The sequence's own keys with 0-2 interior keys dropped at random (the paper's lamp,
    /// section 5).
    #[default]
    Given,
    /// Keys drawn afresh from the sequence's frames (humanoid motion, which has no keys of its
    /// own): frame 0; with probability `context_probability` the in-betweening benchmark's
    /// layout first (frames `1..context` are keys too, then a gap of `min_gap + 1 ..=
    /// max_first_gap + 1` frames to the next key, so `min_gap..=max_first_gap` frames between
    /// them); then gaps of `min_gap..=max_gap` frames up to the last frame, always a key (a
    /// remainder shorter than `min_gap` joins the gap before it).
    Sampled {
        /// Shortest gap between keys (frames).
        min_gap: usize,
        /// Longest gap between keys after the first (frames).
        max_gap: usize,
        /// Keys at frames `0..context` in the benchmark's layout (its 10 context frames).
        context: usize,
        /// Longest number of frames between the last context key and the next one (the
        /// benchmark's longest transition, 45).
        max_first_gap: usize,
        /// Probability of the benchmark's layout.
        context_probability: f64,
    },
}

/// The skeleton of a humanoid ARNN (BVH joint order, the dataset's units): the network's pose
/// is `[root x, y, z, then each joint's local rotation quaternion (w, x, y, z)]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HumanoidSkeleton {
    /// Joint names.
    pub names: Vec<String>,
    /// Parent of each joint, -1 for the root.
    pub parents: Vec<i32>,
    /// Bone offsets from the parent, `[x, y, z]` per joint.
    pub offsets: Vec<[f64; 3]>,
    /// Frames per second of the training clips (runs written before the field existed trained
    /// on bandai2, 30 fps).
    #[serde(default = "thirty")]
    pub fps: f64,
}

fn thirty() -> f64 {
    30.0
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
    /// [`crate::luxo::DOF_NAMES`]); a keys file naming others is refused.
    #[serde(default)]
    pub dof_names: Vec<String>,
    /// The lamp the training data came from: its geometry draws the completed motion as BVH.
    #[serde(default)]
    pub lamp: Option<LampParams>,
    /// The skeleton of a humanoid ARNN (`None` for the lamp).
    #[serde(default)]
    pub skeleton: Option<HumanoidSkeleton>,
    /// Partial keys: the group of each degree of freedom (a key fixes whole groups, e.g. the
    /// root position or one joint's rotation). Empty: keys are whole poses and the key feature
    /// nets see the pose only (the paper, the lamp); otherwise they see the normalised pose with
    /// the free groups' values set to 0 followed by one 0/1 flag per group.
    #[serde(default)]
    pub key_groups: Vec<usize>,
    /// Probability that training makes a key after the first partial (with `key_groups`): each
    /// group is then kept with probability 1/2, at least one; the key loss counts only kept
    /// groups.
    #[serde(default)]
    pub partial_keys: f64,
    /// How training chooses keys.
    #[serde(default)]
    pub key_sampling: KeySampling,
    /// Width of the two layers of each pose feature net (the paper does not give it).
    pub feature: usize,
    /// Hidden units of each of the two GRU layers (paper: 100); for
    /// [`Architecture::NoMemory`], of the two feed-forward layers in their place.
    pub hidden: usize,
    /// Units of the two layers of the segregated net's interpolation network (0 otherwise).
    #[serde(default)]
    pub correction: usize,
    /// What the no-memory net adds its output to (read by [`Architecture::NoMemory`] only).
    #[serde(default = "NoMemoryOutput::legacy")]
    pub no_memory_output: NoMemoryOutput,
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
    /// Largest global L2 norm of a step's gradient (PyTorch's `clip_grad_norm_`); 0: no
    /// clipping (the paper, the lamp).
    #[serde(default)]
    pub max_grad_norm: f64,
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
            skeleton: None,
            key_groups: vec![],
            partial_keys: 0.0,
            key_sampling: KeySampling::Given,
            feature: 32,
            hidden: 100,
            correction: 0,
            no_memory_output: NoMemoryOutput::Interpolation,
            decoder: 10,
            gru_dropout: [0.1, 0.05],
            linear_dropout: [0.2, 0.1],
            key_weight: 100.0,
            ground_weight: 0.0,
            learning_rate: 1e-3,
            max_grad_norm: 0.0,
            batch_size: 16,
            curriculum: Curriculum::paper(10_000),
            seed: 0,
        }
    }

    /// Sizes for humanoid motion (not in the paper, whose 6 degrees of freedom fit through a
    /// decoder of 10): `dofs` values per frame in `key_groups`' groups, feature nets of 128, GRUs
    /// of 256 and a decoder of 256; keys sampled every 5-30 frames, half the time in the
    /// in-betweening benchmark's layout (10 context keys, then 5-45 frames to the target); a
    /// fifth of the keys after the first partial; Adam 5e-4 with gradients clipped to norm 1 (the
    /// free-running humanoid net diverged at 1e-3, with and without clipping: docs/arnn.md).
    pub fn humanoid(skeleton: HumanoidSkeleton, dof_names: Vec<String>, key_groups: Vec<usize>) -> Self {
        ArnnConfig {
            dofs: key_groups.len(),
            dof_names,
            lamp: None,
            skeleton: Some(skeleton),
            key_groups,
            partial_keys: 0.2,
            key_sampling: KeySampling::Sampled {
                min_gap: 5,
                max_gap: 30,
                context: 10,
                max_first_gap: 45,
                context_probability: 0.5,
            },
            feature: 128,
            hidden: 256,
            decoder: 256,
            batch_size: 32,
            learning_rate: 5e-4,
            max_grad_norm: 1.0,
            ..Self::paper()
        }
    }

    /// This configuration with the layer widths, batch size and dropout of `sizes` (e.g. a
    /// humanoid configuration at [`ArnnConfig::tiny`]'s sizes for tests).
    pub fn sized_like(self, sizes: &ArnnConfig) -> Self {
        ArnnConfig {
            feature: sizes.feature,
            hidden: sizes.hidden,
            decoder: sizes.decoder,
            batch_size: sizes.batch_size,
            gru_dropout: sizes.gru_dropout,
            linear_dropout: sizes.linear_dropout,
            ..self
        }
    }

    /// Number of key groups (0 without partial keys).
    pub fn groups(&self) -> usize {
        self.key_groups.iter().max().map_or(0, |g| g + 1)
    }

    /// Width of a key's input to its feature net: the pose, then one flag per group.
    pub fn key_width(&self) -> usize {
        self.dofs + self.groups()
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
        let pose_features = linear(d, f) + linear(f, f);
        let features = linear(self.key_width(), f) + linear(f, f);
        let gru = |i: usize, h: usize| 3 * h * (i + h + 2);
        let decoder = linear(h, w) + linear(w, w) + linear(w, d);
        match self.architecture {
            Architecture::Arnn => pose_features + 2 * features + gru(3 * f + 1, h) + gru(h, h) + decoder,
            Architecture::NoMemory => 2 * features + linear(2 * f + 1, h) + linear(h, h) + decoder,
            Architecture::Segregated => {
                pose_features
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
        if !self.key_groups.is_empty() {
            if self.key_groups.len() != self.dofs {
                return Err(format!(
                    "key_groups has {} entries for {} degrees of freedom",
                    self.key_groups.len(),
                    self.dofs
                ));
            }
            if let Some(g) = (0..self.groups()).find(|g| !self.key_groups.contains(g)) {
                return Err(format!("key group {g} holds no degree of freedom (number the groups 0, 1, 2, ...)"));
            }
        }
        if !(0.0..=1.0).contains(&self.partial_keys) || (self.partial_keys > 0.0 && self.key_groups.is_empty()) {
            return Err(format!("partial_keys {} must be in [0, 1], and 0 without key_groups", self.partial_keys));
        }
        if let KeySampling::Sampled { min_gap, max_gap, context, max_first_gap, context_probability } =
            self.key_sampling
        {
            if min_gap == 0
                || max_gap < min_gap
                || max_first_gap < min_gap
                || !(0.0..=1.0).contains(&context_probability)
            {
                return Err(format!(
                    "key sampling needs 1 <= min_gap <= max_gap, min_gap <= max_first_gap and a probability in [0, 1], \
                     found {:?}",
                    self.key_sampling
                ));
            }
            if context > MAX_WIDTH {
                return Err(format!("key sampling context {context} is larger than {MAX_WIDTH}"));
            }
        }
        if let Some(s) = &self.skeleton {
            let j = s.names.len();
            if !(s.fps.is_finite() && s.fps > 0.0) {
                return Err(format!("the skeleton's fps {} must be a positive number", s.fps));
            }
            if s.parents.len() != j || s.offsets.len() != j || self.dofs != 3 + 4 * j {
                return Err(format!(
                    "the skeleton has {j} names, {} parents and {} offsets for {} degrees of freedom (3 + 4 per joint)",
                    s.parents.len(),
                    s.offsets.len(),
                    self.dofs
                ));
            }
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
        let c = &self.curriculum;
        if !((0.0..1.0).contains(&c.frame_phase) && (0.0..=1.0).contains(&c.frame_phase_omega)) {
            return Err(format!(
                "curriculum frame_phase {} must be in [0, 1) and frame_phase_omega {} in [0, 1]",
                c.frame_phase, c.frame_phase_omega
            ));
        }
        if !(self.max_grad_norm >= 0.0 && self.max_grad_norm.is_finite()) {
            return Err(format!("max_grad_norm {} must be a finite number >= 0 (0: no clipping)", self.max_grad_norm));
        }
        if !(self.ground_weight >= 0.0 && self.ground_weight.is_finite()) {
            return Err(format!("ground_weight {} must be a finite number >= 0", self.ground_weight));
        }
        Ok(())
    }
}
