//! Configuration of the RMR: architecture (sec. 5), the ablation switches of Table 1 (refiner
//! cell), Table 2 (`T_begin`) and Figure 9 (trajectory loss), loss weights, data generation
//! (sec. 4) and training (sec. 7.1).

use crate::error::{RmrError, RmrResult};
use crate::pairs::{PairConfig, StitchLayout};
use serde::{Deserialize, Serialize};
use zoo_motion::Skeleton;

/// The model a configuration is for: `config.json`'s top-level `"model"` field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelName {
    /// The Recurrent Motion Refiner.
    #[default]
    #[serde(rename = "rmr")]
    Rmr,
}

/// The recurrent cell of the refiner (Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RefinerCell {
    /// Unidirectional LSTM.
    Lstm,
    /// Unidirectional GRU.
    Gru,
    /// Bidirectional LSTM.
    Blstm,
    /// Bidirectional GRU (the paper's choice).
    Bgru,
}

impl RefinerCell {
    /// Whether the cell runs in both directions.
    pub fn bidirectional(self) -> bool {
        matches!(self, RefinerCell::Blstm | RefinerCell::Bgru)
    }

    /// Parses `lstm`, `gru`, `blstm` or `bgru`.
    pub fn parse(s: &str) -> RmrResult<RefinerCell> {
        match s.to_ascii_lowercase().as_str() {
            "lstm" => Ok(RefinerCell::Lstm),
            "gru" => Ok(RefinerCell::Gru),
            "blstm" => Ok(RefinerCell::Blstm),
            "bgru" => Ok(RefinerCell::Bgru),
            _ => Err(RmrError::Config(format!("unknown refiner cell `{s}`: use lstm, gru, blstm or bgru"))),
        }
    }
}

/// Training hyper-parameters (RMR sec. 7.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Adam learning rate (paper: 1e-4).
    pub learning_rate: f64,
    /// Adam first-moment decay.
    pub beta1: f64,
    /// Adam second-moment decay.
    pub beta2: f64,
    /// Adam epsilon.
    pub eps: f64,
    /// Pairs per mini-batch (paper: 32).
    pub batch_size: usize,
    /// Seed of the weights and of the dropout masks.
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig { learning_rate: 1e-4, beta1: 0.9, beta2: 0.999, eps: 1e-8, batch_size: 32, seed: 0x5eed }
    }
}

fn default_fps() -> f64 {
    30.0
}

/// Frames on each side of a seam that [`Config::seam_weight`] weights (as the pops measure of
/// the stitching benchmark looks 5 frames around each seam).
pub const SEAM_FRAMES: usize = 5;

/// The RMR's configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Always `"rmr"`.
    pub model: ModelName,
    /// Joints of the skeleton (J).
    pub joints: usize,
    /// Joint names (clips must use this rig).
    pub names: Vec<String>,
    /// Parent of each joint (-1 for the root).
    pub parents: Vec<i32>,
    /// Rest offset of each joint from its parent (clip units; the root's is unused): the
    /// bone vectors of the forward kinematics in the loss's `L_fk` and `L_slide` and in the
    /// runtime's decoding. Empty in configurations saved before it was recorded.
    #[serde(default)]
    pub offsets: Vec<[f64; 3]>,
    /// Lower body, contact joints and thresholds, planted heights, forward axis.
    pub layout: StitchLayout,
    /// Frames per second of the training clips (clips to stitch must have it).
    #[serde(default = "default_fps")]
    pub fps: f64,
    /// Hidden sizes of the encoder E (paper: 256, 256; ReLU after each).
    pub encoder: Vec<usize>,
    /// Units of each recurrent layer (per direction; paper: 256).
    pub hidden: usize,
    /// Recurrent layers (paper: 2).
    pub layers: usize,
    /// Recurrent cell (Table 1; paper: bidirectional GRU).
    pub cell: RefinerCell,
    /// Dropout on the input of every recurrent layer but the first (paper: 0.5 on the second).
    pub dropout: f64,
    /// Hidden sizes of the decoder D before its linear output layer (paper: 256).
    pub decoder: Vec<usize>,
    /// The decoder predicts a correction added to the input's pose values (`r, p, q, v`;
    /// contacts stay logits), and its output layer starts at zero, so an untrained model
    /// returns its input. The paper's decoder predicts the pose itself (`false`, the default of
    /// configurations saved before the switch existed); see docs/rmr.md for why we add it.
    #[serde(default)]
    pub residual: bool,
    /// Train on, and refine, the sequence inertialized at its seams over `blend_frames` (not in
    /// the paper): each training pair's input is inertialized at its seams before encoding, and
    /// `zoo stitch`, the benchmark and [`crate::stitch::refine_seams`] inertialize the seams of
    /// what such a model refines (`--pre-blend`, which any model takes at inference, then always
    /// applies). `false` (the paper's input, and configurations saved before it existed): the
    /// raw aligned concatenation.
    #[serde(default)]
    pub pre_blend: bool,
    /// The fallback towards the refiner's input on windows it corrects far more than the
    /// validation pairs ([`crate::fallback`]), calibrated at the end of `zoo train rmr`; `None`
    /// for runs calibrated before it existed and before training ends.
    #[serde(default)]
    pub fallback: Option<crate::fallback::Fallback>,
    /// Frames of the beginning loss (Table 2; paper: 5; 0 disables the loss).
    pub t_begin: usize,
    /// Weight of the pose loss (paper: 1).
    pub lambda_pose: f64,
    /// Weight of the root trajectory loss (paper: 1; Figure 9 trains without it).
    pub lambda_trajectory: f64,
    /// Weight of the contact loss (paper: 0.5).
    pub lambda_foot: f64,
    /// Weight of the beginning loss (paper: 1).
    pub lambda_begin: f64,
    /// Weight of the forward-kinematics term (ours, 0 in the paper's loss): the lower-body
    /// positions that the output's rotations and hips position give by forward kinematics,
    /// against the ground truth's (normalised like `p`); it ties the rotations, which the
    /// decoded motion is made of, to the positions. See docs/rmr.md.
    #[serde(default)]
    pub lambda_fk: f64,
    /// Weight of the foot-slide term (ours, 0 in the paper's loss): the horizontal displacement
    /// (cm per frame) of each contact joint, by forward kinematics and the output's root
    /// displacement, on the frames where the ground truth has that contact.
    #[serde(default)]
    pub lambda_slide: f64,
    /// Weight of the velocity term (ours, 0 in the paper's loss): the per-frame change of the
    /// output's pose values against the ground truth's, `|(x_out,t - x_out,t-1) - (x_gt,t -
    /// x_gt,t-1)|_1` over `r, p, q, v`, weighted per frame like the pose loss (so
    /// [`Config::seam_weight`] stresses the seams): a refiner that moves a joint faster than the
    /// ground truth near a seam makes a pop that the pose loss barely sees (the seam guard's recipe).
    #[serde(default)]
    pub lambda_velocity: f64,
    /// Extra weight of the pose loss on the frames within [`SEAM_FRAMES`] of a seam of the
    /// training pair (their per-frame L1 counts `1 + seam_weight` times). 0: the paper's loss
    /// (the default, and that of configurations saved before the switch); see docs/rmr.md.
    #[serde(default)]
    pub seam_weight: f64,
    /// Root trajectory positions are divided by this many clip units in the trajectory loss
    /// (100: metres for data in cm), so that centimetres do not swamp the heading (radians).
    pub trajectory_unit: f64,
    /// Runtime window `w` in frames (sec. 6; 60 or 180).
    pub window: usize,
    /// Runtime window step `s` in frames (30 or 90).
    pub stride: usize,
    /// Frames over which the difference at each window start is blended away (sec. 6: 10).
    pub blend_frames: usize,
    /// Data generation (sec. 4): window `T`, segment unit, k range, seeds.
    pub pairs: PairConfig,
    /// Training settings.
    pub train: TrainConfig,
}

/// `zoo train rmr`'s default [`Config::seam_weight`] (the default recipe: with the pre-blend and the
/// velocity term, the recipe that stitches moves the model never saw; `--paper` sets 0).
pub const RECIPE_SEAM_WEIGHT: f64 = 4.0;
/// `zoo train rmr`'s default [`Config::lambda_velocity`] (`--paper` sets 0).
pub const RECIPE_VELOCITY_WEIGHT: f64 = 1.0;

impl Config {
    /// The paper's RMR for bandai2's skeleton (also the synthetic skeleton): `T = 60` frames,
    /// BGRU, `T_begin = 5`, trajectory loss on, runtime window 60 / stride 30.
    pub fn paper() -> Self {
        let skeleton = zoo_data::synth::skeleton();
        let layout = StitchLayout::bandai2(&skeleton).expect("the synthetic skeleton has bandai2's joints");
        Config {
            model: ModelName::Rmr,
            joints: skeleton.len(),
            names: skeleton.names.clone(),
            parents: skeleton.parents_i32(),
            offsets: skeleton.offsets.iter().map(|o| [o.x, o.y, o.z]).collect(),
            layout,
            fps: 30.0,
            encoder: vec![256, 256],
            hidden: 256,
            layers: 2,
            cell: RefinerCell::Bgru,
            dropout: 0.5,
            decoder: vec![256],
            residual: true,
            t_begin: 5,
            lambda_pose: 1.0,
            lambda_trajectory: 1.0,
            lambda_foot: 0.5,
            lambda_begin: 1.0,
            lambda_fk: 0.0,
            lambda_slide: 0.0,
            lambda_velocity: 0.0,
            pre_blend: false,
            fallback: None,
            seam_weight: 0.0,
            trajectory_unit: 100.0,
            window: 60,
            stride: 30,
            blend_frames: 10,
            pairs: PairConfig::default(),
            train: TrainConfig::default(),
        }
    }

    /// A small model for tests (it trains in seconds and learns little; `quick` is the one to
    /// try): tiny layers, `T = 30` frames in units of 10, batch 8, lr 3e-3,
    /// database segments every 2 frames.
    pub fn tiny() -> Self {
        let mut c = Config::paper();
        c.encoder = vec![64, 64];
        c.hidden = 32;
        c.decoder = vec![64];
        c.window = 30;
        c.stride = 15;
        c.pairs = PairConfig { window: 30, window_step: 15, database_stride: 2, ..PairConfig::default() };
        c.train = TrainConfig { learning_rate: 3e-3, batch_size: 8, ..TrainConfig::default() };
        c
    }

    /// The quick model, to try the tools in minutes (`zoo train rmr --preset quick`): the paper's
    /// windows (`T = 60`, runtime 60/30) and layers at half width (encoder 128, 128; BGRU 2 x
    /// 128; decoder 128), batch 8, the paper's lr 1e-4 (at 3e-4 with batch 16 the decoder's units
    /// died in the first epochs), database segments every 2 frames. On the default synthetic data
    /// its 80 epochs take about 5 minutes of one thread (docs/rmr.md, "Quick start").
    pub fn quick() -> Self {
        let mut c = Config::paper();
        c.encoder = vec![128, 128];
        c.hidden = 128;
        c.decoder = vec![128];
        c.pairs = PairConfig { database_stride: 2, ..PairConfig::default() };
        c.train = TrainConfig { learning_rate: 1e-4, batch_size: 8, ..TrainConfig::default() };
        c
    }

    /// A preset by name: `paper`, `quick` or `tiny`.
    pub fn preset(name: &str) -> RmrResult<Config> {
        match name {
            "paper" => Ok(Config::paper()),
            "quick" => Ok(Config::quick()),
            "tiny" => Ok(Config::tiny()),
            _ => Err(RmrError::Config(format!("unknown preset `{name}`: use paper, quick or tiny"))),
        }
    }

    /// Sets the skeleton and its layout.
    pub fn with_skeleton(mut self, skeleton: &Skeleton, layout: StitchLayout) -> RmrResult<Self> {
        layout.validate(skeleton)?;
        self.joints = skeleton.len();
        self.names = skeleton.names.clone();
        self.parents = skeleton.parents_i32();
        self.offsets = skeleton.offsets.iter().map(|o| [o.x, o.y, o.z]).collect();
        self.layout = layout;
        Ok(self)
    }

    /// Sets the refiner cell (Table 1).
    pub fn with_cell(mut self, cell: RefinerCell) -> Self {
        self.cell = cell;
        self
    }

    /// Residual decoder (`true`, our default) or the paper's absolute output (`false`).
    pub fn with_residual(mut self, on: bool) -> Self {
        self.residual = on;
        self
    }

    /// Sets `T_begin` (Table 2).
    pub fn with_t_begin(mut self, t_begin: usize) -> Self {
        self.t_begin = t_begin;
        self
    }

    /// Turns the root trajectory loss on (weight 1) or off (Figure 9).
    pub fn with_trajectory_loss(mut self, on: bool) -> Self {
        self.lambda_trajectory = if on { 1.0 } else { 0.0 };
        self
    }

    /// Sets the runtime window and stride (e.g. 60/30 or 180/90).
    pub fn with_window(mut self, window: usize, stride: usize) -> Self {
        self.window = window;
        self.stride = stride;
        self
    }

    /// Errors unless `skeleton` is the configuration's rig (same joint names and parents).
    pub fn check_skeleton(&self, skeleton: &Skeleton) -> RmrResult<()> {
        let parents = skeleton.parents_i32();
        if skeleton.names != self.names || parents != self.parents {
            let why = if skeleton.len() != self.joints {
                format!("expected {} joints, found {}", self.joints, skeleton.len())
            } else {
                (0..self.joints)
                    .find(|&j| skeleton.names[j] != self.names[j] || parents[j] != self.parents[j])
                    .map(|j| format!("joint {j}: expected `{}`, found `{}`", self.names[j], skeleton.names[j]))
                    .unwrap_or_default()
            };
            return Err(RmrError::Config(format!(
                "the clips' skeleton is not the model's ({why}); retarget the clips to the model's rig, or \
                 configure the model for this rig with Config::with_skeleton"
            )));
        }
        Ok(())
    }

    /// Size of the pose vector (see [`crate::features::FeatureLayout`]).
    pub fn dim(&self) -> usize {
        crate::features::FeatureLayout::new(self.joints, self.layout.lower_body.len()).dim()
    }

    /// Checks sizes and ranges.
    pub fn validate(&self) -> RmrResult<()> {
        let bad = |m: String| Err(RmrError::Config(m));
        if self.parents.len() != self.joints || self.names.len() != self.joints || self.joints == 0 {
            return bad(format!(
                "{} parents and {} names for {} joints",
                self.parents.len(),
                self.names.len(),
                self.joints
            ));
        }
        if self.layout.lower_body.iter().chain(&self.layout.contacts).any(|&j| j >= self.joints) {
            return bad(format!("the layout names a joint beyond the skeleton's {}", self.joints));
        }
        if self.hidden == 0 || self.layers == 0 || self.encoder.is_empty() || self.encoder.contains(&0) {
            return bad("encoder sizes, hidden units and layers must be positive".into());
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad(format!("dropout must be in [0, 1), got {}", self.dropout));
        }
        if self.t_begin > self.pairs.window {
            return bad(format!("t_begin {} is longer than the training window {}", self.t_begin, self.pairs.window));
        }
        if self.stride == 0 || self.stride > self.window {
            return bad(format!("the runtime stride {} must be in 1..={} (the window)", self.stride, self.window));
        }
        if !(0.0..=1000.0).contains(&self.seam_weight) {
            return bad(format!("seam_weight must be in 0..=1000, got {}", self.seam_weight));
        }
        for (name, w) in [
            ("lambda_fk", self.lambda_fk),
            ("lambda_slide", self.lambda_slide),
            ("lambda_velocity", self.lambda_velocity),
        ] {
            if !(0.0..=1000.0).contains(&w) {
                return bad(format!("{name} must be in 0..=1000, got {w}"));
            }
        }
        if (self.lambda_fk > 0.0 || self.lambda_slide > 0.0) && self.offsets.len() != self.joints {
            return bad(format!(
                "the forward-kinematics loss terms need the skeleton's {} offsets, the configuration has {}: \
                 set the skeleton with Config::with_skeleton",
                self.joints,
                self.offsets.len()
            ));
        }
        if self.trajectory_unit <= 0.0 {
            return bad("trajectory_unit must be positive".into());
        }
        if self.train.batch_size == 0 {
            return bad("batch_size must be at least 1".into());
        }
        self.pairs.validate()?;
        Ok(())
    }
}
