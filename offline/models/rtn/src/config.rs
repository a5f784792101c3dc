//! Configuration of the RTN: architecture, the ablation switches of Table 4 and training.

use serde::{Deserialize, Serialize};

/// How the LSTM state is initialised at the start of a sequence (RTN sec. 4.6, Table 4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitState {
    /// The hidden-state initialiser H maps the first frame `x_0` to `(h, c)` (eq. 14; the paper's RTN).
    Learned,
    /// Zero `(h, c)` (ablation `RTN\H0`).
    Zero,
    /// One learned `(h, c)` shared by all sequences (ablation `RTN\HCOMMON`).
    Common,
}

/// Probability of feeding the ground-truth previous frame instead of the prediction during
/// training (RTN sec. 6.2, Table 4). One draw per time step, shared by the whole mini-batch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TeacherForcing {
    /// Fixed probability `p` (the paper's RTN uses 0.2; ablations 0 and 1).
    Fixed(f64),
    /// Scheduled sampling: `p` falls linearly from 1 to 0 over `steps` training steps
    /// (ablation `RTN\PTF=Delta`).
    Scheduled {
        /// Number of training steps over which `p` goes from 1 to 0.
        steps: u64,
    },
}

impl TeacherForcing {
    /// Probability of using the ground truth at training step `step`.
    pub fn probability(&self, step: u64) -> f64 {
        match *self {
            TeacherForcing::Fixed(p) => p,
            TeacherForcing::Scheduled { steps } => (1.0 - step as f64 / steps.max(1) as f64).max(0.0),
        }
    }
}

/// Training hyper-parameters (RTN sec. 6.3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// AMSGrad learning rate (paper: 5e-4).
    pub learning_rate: f64,
    /// AMSGrad first-moment decay (Adam default 0.9).
    pub beta1: f64,
    /// AMSGrad second-moment decay (Adam default 0.999).
    pub beta2: f64,
    /// AMSGrad epsilon (1e-8).
    pub eps: f64,
    /// Windows per mini-batch (paper: 32).
    pub batch_size: usize,
    /// Teacher forcing (paper: fixed 0.2).
    pub teacher_forcing: TeacherForcing,
    /// Randomly rotate each training window about the vertical axis in [-pi, pi] (sec. 3.3).
    pub random_rotation: bool,
    /// Seed of the trainer's random numbers (teacher forcing draws, rotations).
    pub seed: u64,
    /// Decay of an exponential moving average of the weights (Polyak averaging), kept beside
    /// the trained weights; `None` keeps none (the paper's recipe). Not in the paper: the
    /// averaged weights are a second candidate for the best checkpoint (see `RtnTrainer`).
    #[serde(default)]
    pub ema_decay: Option<f64>,
    /// On-the-fly augmentation of the training windows (time reversal, mirroring, speed;
    /// [`crate::augment::Augment`]), drawn from the trainer's generator; `None`: none (the
    /// paper's recipe, and folders written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub augment: Option<crate::augment::Augment>,
    /// Transition lengths drawn in training, `[shortest, longest]` frames (one length per
    /// mini-batch, uniform; the longest is the window's `transition_frames`), as Harvey et al.
    /// 2020 train for every length the benchmark asks for; validation averages the lengths 5,
    /// 15, 30 and 45 within the range. `None`: every window at `transition_frames` (the paper's
    /// RTN, and folders written before it existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lengths: Option<[usize; 2]>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            learning_rate: 5e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            batch_size: 32,
            teacher_forcing: TeacherForcing::Fixed(0.2),
            random_rotation: true,
            seed: 0x5eed,
            ema_decay: None,
            augment: None,
            lengths: None,
        }
    }
}

/// The model a configuration is for: `config.json`'s top-level `"model"` field, which names the
/// model of a run folder (the registry key of `zoo train`, `zoo export` and `zoo bench`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelName {
    /// The Recurrent Transition Network.
    #[default]
    #[serde(rename = "rtn")]
    Rtn,
}

/// The RTN's configuration: sizes, ablation switches and training settings.
///
/// Layer sizes follow Fig. 3 of the paper in [`Config::paper`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Always `"rtn"`; folders written before the field existed load as `"rtn"`, a
    /// configuration of another model is refused with its name.
    #[serde(default)]
    pub model: ModelName,
    /// Number of joints K of the skeleton; a feature frame has `D = 3K` values.
    pub joints: usize,
    /// Parent of each joint (-1 for the root), kept for export and evaluation; empty when unknown.
    #[serde(default)]
    pub parents: Vec<i32>,
    /// Frames of past context fed before the transition (paper: 10).
    pub past_frames: usize,
    /// Transition length P in frames (paper: 30); the model predicts P + 1 frames (incl. the target).
    pub transition_frames: usize,
    /// Hidden sizes of the frame encoder E (eq. 2; paper: 512, 512).
    pub frame_encoder: Vec<usize>,
    /// Hidden sizes of the target encoder F (eq. 3; paper: 128, 128).
    pub target_encoder: Vec<usize>,
    /// Hidden sizes of the offset encoder O (eq. 4; paper: 128, 128).
    pub offset_encoder: Vec<usize>,
    /// Units of the recurrent generator R (eq. 5-11; paper: 512).
    pub lstm: usize,
    /// Hidden sizes of the frame decoder D before its linear output (eq. 12; paper: 256, 128).
    pub decoder: Vec<usize>,
    /// Hidden size of the state initialiser H (eq. 14; not given in the paper, 512 here).
    pub init_hidden: usize,
    /// Negative slope of the leaky ReLUs.
    pub leaky_slope: f64,
    /// Condition the LSTM on the future context `[h_F, h_O]` (false: ablation `RTN\FUTURE`).
    pub future_conditioning: bool,
    /// LSTM state initialisation (paper: learned H).
    pub init_state: InitState,
    /// Residual output `x_(t+1) = x_t + D(h_t)` (eq. 13; false: ablation `RTN\RESNET`).
    pub residual: bool,
    /// Predict a correction on top of the interpolation of context and target instead of the
    /// next frame (not in the paper; the Delta-interpolator of Oreshkin et al. 2022): step `t`
    /// also takes the normalised interpolation frame `b_(t+1)` (the LERP of the last context
    /// frame and the target in feature space, see [`crate::features::interpolation_frame`]), the
    /// frame encoder reads `[x_t, p_t, b_(t+1)]` and the output is `x_(t+1) = b_(t+1) + D(h_t)`
    /// (replacing eq. 13's `x_t + D(h_t)`). An untrained decoder's near-zero output is the
    /// interpolation itself. Folders written before the field existed load as `false`.
    #[serde(default)]
    pub interp_residual: bool,
    /// Feed the frames left to the target (the time to arrival, Harvey et al. 2020) to the frame
    /// encoder as an embedding of `dims` values, constant from `max` frames on
    /// ([`zoo_format::TimeToArrival::embed`]): the frame encoder reads `[x_t, p_t, b_(t+1),
    /// z_tta]`. What lets one network place its motion in time for every transition length of
    /// [`TrainConfig::lengths`]. `None` (the paper's RTN, and folders written before it
    /// existed): no time input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_to_arrival: Option<zoo_format::TimeToArrival>,
    /// Feed a local terrain patch `p_t` to the frame encoder (sec. 3.2, the terrain-aware RTN).
    pub terrain: bool,
    /// Terrain patch side in samples (paper: 13).
    pub terrain_side: usize,
    /// Terrain patch extent in clip units (paper: 2.06 m; 206 for data in cm).
    pub terrain_extent: f32,
    /// Target-blend length in frames of the post-process (eq. 15-16); 0 disables it.
    pub target_blend: usize,
    /// Training settings.
    pub train: TrainConfig,
    /// Thresholds of the fallback towards interpolation on the network's target miss
    /// ([`crate::fallback`]), calibrated on the validation windows at the end of training;
    /// `None` (folders trained before it existed, or not calibrated): no fallback.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback: Option<crate::fallback::Fallback>,
    /// The fallback's thresholds calibrated at each validation length of a run over several
    /// lengths ([`TrainConfig::lengths`]), shortest first: a transition of `n` frames uses them
    /// interpolated at `n` ([`Config::fallback_for`]). Empty: [`Config::fallback`] for every
    /// length (runs over one length, and folders written before it existed).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fallback_lengths: Vec<zoo_format::TransitionFallbackAt>,
}

impl Config {
    /// The paper's RTN (sec. 4 and 6.3) without terrain, for the paper's K = 22 joints; set the
    /// skeleton with [`Config::with_parents`].
    pub fn paper() -> Self {
        Config {
            model: ModelName::Rtn,
            joints: 22,
            parents: Vec::new(),
            past_frames: 10,
            transition_frames: 30,
            frame_encoder: vec![512, 512],
            target_encoder: vec![128, 128],
            offset_encoder: vec![128, 128],
            lstm: 512,
            decoder: vec![256, 128],
            init_hidden: 512,
            leaky_slope: 0.01,
            future_conditioning: true,
            init_state: InitState::Learned,
            residual: true,
            interp_residual: false,
            time_to_arrival: None,
            terrain: false,
            terrain_side: 13,
            terrain_extent: 206.0,
            target_blend: 5,
            train: TrainConfig::default(),
            fallback: None,
            fallback_lengths: Vec::new(),
        }
    }

    /// A small model for tests: same structure, tiny sizes, short windows (12 frames: 4 past,
    /// 6 transition, target and the frame after it, so it trains on the 50-frame windows of
    /// the data too), 4 joints until [`Config::with_parents`] sets the skeleton.
    pub fn tiny() -> Self {
        Config {
            joints: 4,
            past_frames: 4,
            transition_frames: 6,
            frame_encoder: vec![32, 32],
            target_encoder: vec![16, 16],
            offset_encoder: vec![16, 16],
            lstm: 32,
            decoder: vec![32, 16],
            init_hidden: 32,
            terrain_side: 5,
            target_blend: 2,
            train: TrainConfig { learning_rate: 3e-3, batch_size: 8, ..TrainConfig::default() },
            ..Config::paper()
        }
    }

    /// Sets the skeleton: `joints` and `parents` from the parent of each joint (`None` for the root).
    pub fn with_parents(mut self, parents: &[Option<usize>]) -> Self {
        self.joints = parents.len();
        self.parents = parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect();
        self
    }

    /// Sets the terrain-aware variant on or off.
    pub fn with_terrain(mut self, terrain: bool) -> Self {
        self.terrain = terrain;
        self
    }

    /// The fallback's thresholds for a transition of `n` frames: [`Config::fallback_lengths`]
    /// interpolated at `n` when the run calibrated them, else [`Config::fallback`].
    pub fn fallback_for(&self, n: usize) -> Option<crate::fallback::Fallback> {
        let at_longest = self.fallback.map(|f| zoo_format::TransitionFallback { start: f.start, full: f.full });
        zoo_format::fallback_for(at_longest, &self.fallback_lengths, n)
            .map(|f| crate::fallback::Fallback { start: f.start, full: f.full })
    }

    /// The transition lengths a run validates at: 5, 15, 30 and 45 frames within
    /// [`TrainConfig::lengths`] (its longest when none is), else [`Config::transition_frames`].
    pub fn validation_lengths(&self) -> Vec<usize> {
        match self.train.lengths {
            Some([lo, hi]) => {
                let v: Vec<usize> = [5, 15, 30, 45].into_iter().filter(|n| (lo..=hi).contains(n)).collect();
                if v.is_empty() { vec![hi] } else { v }
            }
            None => vec![self.transition_frames],
        }
    }

    /// Feature frame size `D = 3K`.
    pub fn dim(&self) -> usize {
        3 * self.joints
    }

    /// Values the frame encoder reads: the frame, the terrain patch, with
    /// [`Config::interp_residual`] the interpolation frame and with [`Config::time_to_arrival`]
    /// its embedding.
    pub fn frame_encoder_input(&self) -> usize {
        self.dim() + self.terrain_dim() + if self.interp_residual { self.dim() } else { 0 } + self.tta_dim()
    }

    /// Values of the time-to-arrival embedding (0 without it).
    pub fn tta_dim(&self) -> usize {
        self.time_to_arrival.map_or(0, |t| t.dims)
    }

    /// Terrain patch size (0 without terrain).
    pub fn terrain_dim(&self) -> usize {
        if self.terrain { self.terrain_side * self.terrain_side } else { 0 }
    }

    /// Index of the target frame in a training window (`past_frames + transition_frames`).
    pub fn target_frame(&self) -> usize {
        self.past_frames + self.transition_frames
    }

    /// Frames a training window needs: past, transition, target and the frame after it.
    pub fn window_frames(&self) -> usize {
        self.target_frame() + 2
    }
}
