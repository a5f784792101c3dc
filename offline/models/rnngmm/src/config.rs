//! Configuration of the RNN-GMM: generator sizes, the mixture, and the generator's training.

use crate::error::{RnnGmmError, RnnGmmResult};
use serde::{Deserialize, Serialize};

/// The model a configuration is for: `config.json`'s top-level `"model"` field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ModelName {
    /// RNN-GMM with an adversarial refiner (Wang, Chai & Xia).
    #[default]
    #[serde(rename = "rnn-gmm")]
    RnnGmm,
}

/// Training settings of the generator (sec. 4.1.2-4.1.3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// RMSProp learning rate of the first epoch (paper: 1e-3).
    pub learning_rate: f64,
    /// Factor on the learning rate after every epoch (paper: 0.95).
    pub lr_decay: f64,
    /// RMSProp decay of the mean square (not given for the generator; the paper's 0.9 of the
    /// refiner and Tieleman & Hinton's value).
    pub rho: f64,
    /// RMSProp epsilon.
    pub eps: f64,
    /// Every gradient component is clipped to `[-clip, clip]` (paper: 5).
    pub clip: f64,
    /// Standard deviation of the Gaussian noise added to the normalised input features (paper: 0.05).
    pub input_noise: f64,
    /// Windows per mini-batch (paper: 20).
    pub batch_size: usize,
    /// Frames per training window (paper: 50): the generator reads frames `0..window - 1` and
    /// predicts frames `1..window`.
    pub window: usize,
    /// Frames between the starts of consecutive windows of a clip (not in the paper; 25, half a
    /// window, gives about the paper's 200 iterations per epoch on 58 minutes of data).
    pub window_stride: usize,
    /// Seed of the weights and of the trainer's random numbers (input noise).
    pub seed: u64,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            learning_rate: 1e-3,
            lr_decay: 0.95,
            rho: 0.9,
            eps: 1e-8,
            clip: 5.0,
            input_noise: 0.05,
            batch_size: 20,
            window: 50,
            window_stride: 25,
            seed: 0x5eed,
        }
    }
}

/// The refiner R, the discriminator D and their adversarial training (sec. 4.2). The paper
/// gives the widths only in its Fig. 4-5; [`RefinerConfig::default`] takes 256 (refiner) and 128
/// (discriminator, per direction).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RefinerConfig {
    /// Width of the refiner's first fully connected layer (FC1, ReLU).
    pub refiner_fc: usize,
    /// Units of the refiner's LSTM.
    pub refiner_lstm: usize,
    /// Width of the discriminator's first fully connected layer (ReLU).
    pub discriminator_fc: usize,
    /// Units per direction of the discriminator's bidirectional LSTM.
    pub discriminator_lstm: usize,
    /// Weight of the self-regularisation term (eq. 13; paper: 20), on the normalised root
    /// values `dtx, dtz, dry, ty`.
    pub lambda: f64,
    /// RMSProp learning rate of the refiner (paper: 0.002).
    pub refiner_lr: f64,
    /// RMSProp learning rate of the discriminator (paper: 0.005).
    pub discriminator_lr: f64,
    /// RMSProp decay of both (paper: 0.9).
    pub rho: f64,
    /// Every gradient component is clipped to `[-clip, clip]` (the generator's 5; not stated
    /// for the refiner).
    pub clip: f64,
    /// Refiner updates before adversarial rounds start (paper: 75).
    pub warmup_refiner: usize,
    /// Discriminator updates before adversarial rounds start (paper: 75).
    pub warmup_discriminator: usize,
    /// Refiner updates per discriminator update at the start (paper: 5).
    pub refiner_updates: usize,
    /// The most refiner updates per discriminator update the adaptation may reach.
    pub max_refiner_updates: usize,
    /// Discriminator loss below which the refiner's updates are doubled (paper: 0.01).
    pub low_loss: f64,
    /// Discriminator loss above which they are halved (paper: 1).
    pub high_loss: f64,
    /// Refined motions kept in the history buffer (paper: B = 320).
    pub history: usize,
    /// Windows per batch (paper: b = 32); half the discriminator's fakes come from the buffer.
    pub batch: usize,
    /// Generator sequences sampled once as the refiner's training input (`x_RNN`).
    pub fake_windows: usize,
    /// Real frames fed to the generator before it samples a fake window.
    pub seed_frames: usize,
    /// Temperature of that sampling.
    pub temperature: f64,
    /// Discriminator collapse: its loss stays below `collapse_loss` for `collapse_rounds`
    /// consecutive rounds while the refiner already gets `max_refiner_updates`: training stops
    /// with an error and the last good checkpoint is kept.
    pub collapse_loss: f64,
    /// See `collapse_loss`.
    pub collapse_rounds: usize,
    /// Seed of the refiner's and discriminator's weights and of the sampling and batch draws.
    pub seed: u64,
    /// Weight of the foot-skate term added to the refiner's loss (not in the paper's eq. 13):
    /// the benchmark's skate measure (`../shared/BENCHMARK.md`) of the refined feet, in clip
    /// units per frame, its height weight held constant so that lifting a foot is not a way out.
    /// 0 in runs written before it existed.
    #[serde(default)]
    pub skate_weight: f64,
    /// Weight of the joint-range term added to the refiner's loss (not in the paper): the
    /// excess of each refined value `rx, rz` and joint angle beyond its range in the training
    /// windows (normalised units, summed over values, mean over frames). 0 in runs written
    /// before it existed.
    #[serde(default)]
    pub range_weight: f64,
    /// The range of the joint-range term: from this percentile to `100 -` it of each value in
    /// the training windows (0: min to max).
    #[serde(default)]
    pub range_percentile: f64,
    /// Frames the generator runs past its seed before a fake window starts, so that the
    /// refiner also learns on the generator's own drift (the seed frames plus this many plus a
    /// window are sampled; the last window is kept). 0 in runs written before it existed.
    #[serde(default)]
    pub fake_lead_frames: usize,
    /// Fake windows sampled afresh from the generator after every round, replacing as many
    /// random windows of the pool of `fake_windows` (0: the pool sampled at the start is used
    /// throughout, as in runs written before it existed). A fixed pool of a few hundred windows
    /// is learnt by heart: the refiner's skate falls on it and rises on fresh samples.
    #[serde(default)]
    pub fresh_fakes: usize,
    /// Joint limits on the refiner's output: every refined `rx, rz` and joint-angle value is
    /// clamped to its [min, max] over the real training windows (saved in `effectors.json`,
    /// exported in the refiner's step graph). Not in the paper. `false` in runs written before it
    /// existed (their refiners have no limits).
    #[serde(default)]
    pub joint_limits: bool,
    /// Standard deviation, in frames, of the Gaussian that smooths the generator's root values
    /// before eq. 13 compares the refined root with them: the refined root is held to the RNN's
    /// trajectory but not to its frame-to-frame jitter. 0 (the default): eq. 13 as in the paper.
    /// Smoothing brings the RNN's root roughness to real motion's but moves its root-speed
    /// distribution away from real (docs/rnn-gmm.md, "Root smoothing": measured 2026-11-26,
    /// commit 12bb67a), so it is off by default.
    #[serde(default)]
    pub root_smoothing: f64,
}

impl Default for RefinerConfig {
    fn default() -> Self {
        RefinerConfig {
            refiner_fc: 256,
            refiner_lstm: 256,
            discriminator_fc: 128,
            discriminator_lstm: 128,
            lambda: 20.0,
            refiner_lr: 0.002,
            discriminator_lr: 0.005,
            rho: 0.9,
            clip: 5.0,
            warmup_refiner: 75,
            warmup_discriminator: 75,
            refiner_updates: 5,
            max_refiner_updates: 40,
            low_loss: 0.01,
            high_loss: 1.0,
            history: 320,
            batch: 32,
            fake_windows: 640,
            seed_frames: 10,
            temperature: 1.0,
            collapse_loss: 1e-3,
            collapse_rounds: 50,
            seed: 0xad5e,
            skate_weight: 300.0,
            range_weight: 500.0,
            range_percentile: 1.0,
            fake_lead_frames: 0,
            fresh_fakes: 16,
            joint_limits: true,
            root_smoothing: 0.0,
        }
    }
}

impl RefinerConfig {
    /// Small sizes for tests.
    pub fn tiny() -> Self {
        RefinerConfig {
            refiner_fc: 16,
            refiner_lstm: 16,
            discriminator_fc: 16,
            discriminator_lstm: 8,
            warmup_refiner: 3,
            warmup_discriminator: 3,
            refiner_updates: 2,
            max_refiner_updates: 8,
            history: 16,
            batch: 8,
            fake_windows: 24,
            seed_frames: 4,
            collapse_rounds: 5,
            ..RefinerConfig::default()
        }
    }

    /// Checks sizes and settings.
    pub fn validate(&self) -> RnnGmmResult<()> {
        let sizes = [self.refiner_fc, self.refiner_lstm, self.discriminator_fc, self.discriminator_lstm];
        if sizes.contains(&0) || self.refiner_updates == 0 || self.max_refiner_updates < self.refiner_updates {
            return Err(RnnGmmError::Config(format!(
                "refiner: widths {sizes:?} must be positive, refiner_updates ({}) positive and at most \
                 max_refiner_updates ({})",
                self.refiner_updates, self.max_refiner_updates
            )));
        }
        if self.batch < 2 || self.history < self.batch / 2 || self.fake_windows < self.history.max(self.batch) {
            return Err(RnnGmmError::Config(format!(
                "refiner: batch ({}) must be at least 2, history ({}) at least half a batch, fake_windows ({}) at \
                 least the history and a batch",
                self.batch, self.history, self.fake_windows
            )));
        }
        if !(self.refiner_lr > 0.0 && self.discriminator_lr > 0.0 && (0.0..1.0).contains(&self.rho) && self.clip > 0.0)
        {
            return Err(RnnGmmError::Config(format!(
                "refiner: learning rates ({}, {}) and clip ({}) must be positive, rho ({}) in [0, 1)",
                self.refiner_lr, self.discriminator_lr, self.clip, self.rho
            )));
        }
        if !(self.skate_weight >= 0.0 && self.range_weight >= 0.0 && (0.0..50.0).contains(&self.range_percentile)) {
            return Err(RnnGmmError::Config(format!(
                "refiner: skate_weight ({}) and range_weight ({}) must not be negative, range_percentile ({}) in [0, \
                 50)",
                self.skate_weight, self.range_weight, self.range_percentile
            )));
        }
        if !(0.0..=50.0).contains(&self.root_smoothing) {
            return Err(RnnGmmError::Config(format!(
                "refiner: root_smoothing ({}) must be in [0, 50] frames (0: eq. 13 without smoothing)",
                self.root_smoothing
            )));
        }
        if !(self.lambda >= 0.0 && self.temperature >= 0.0 && self.low_loss < self.high_loss) {
            return Err(RnnGmmError::Config(format!(
                "refiner: lambda ({}) and temperature ({}) must not be negative, low_loss ({}) below high_loss ({})",
                self.lambda, self.temperature, self.low_loss, self.high_loss
            )));
        }
        Ok(())
    }
}

/// The RNN-GMM's configuration.
///
/// The paper gives the layer widths only in its Fig. 3 (not in the text); [`Config::paper`]
/// takes 512 for every layer (see `docs/rnn-gmm.md`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Always `"rnn-gmm"`.
    pub model: ModelName,
    /// State feature size `D` (`6 + 3 (J - 1) + 2`; 68 for bandai2's 21 joints), set from the
    /// feature ([`Config::with_dim`]).
    pub dim: usize,
    /// Widths of the fully connected layers before the LSTM (paper: 3 layers, FC1-FC3), each
    /// followed by a ReLU.
    pub fc: Vec<usize>,
    /// Units of each LSTM layer.
    pub lstm: usize,
    /// LSTM layers (paper: 2).
    pub lstm_layers: usize,
    /// Mixture components `M` (paper: 5).
    pub components: usize,
    /// Lower bound on the log standard deviations of the mixture (normalised units). Not in the
    /// paper: the contact bits take two values only, and without a floor the likelihood of a
    /// component collapsing onto one of them grows without bound.
    pub min_log_std: f64,
    /// Upper bound on the log standard deviations (normalised units).
    pub max_log_std: f64,
    /// Generator training.
    pub train: TrainConfig,
    /// Refiner, discriminator and adversarial training.
    #[serde(default)]
    pub refiner: RefinerConfig,
}

impl Config {
    /// The paper's generator (sec. 4.1) for bandai2's 21 joints (`D = 68`).
    pub fn paper() -> Self {
        Config {
            model: ModelName::RnnGmm,
            dim: crate::features::feature_dim(21),
            fc: vec![512, 512, 512],
            lstm: 512,
            lstm_layers: 2,
            components: 5,
            min_log_std: -5.0,
            max_log_std: 5.0,
            train: TrainConfig::default(),
            refiner: RefinerConfig::default(),
        }
    }

    /// A small model for tests: same structure, tiny widths, windows of 20 frames, batch 8.
    pub fn tiny() -> Self {
        Config {
            fc: vec![32, 32, 32],
            lstm: 32,
            components: 3,
            train: TrainConfig {
                learning_rate: 3e-3,
                batch_size: 8,
                window: 20,
                window_stride: 10,
                ..TrainConfig::default()
            },
            refiner: RefinerConfig::tiny(),
            ..Config::paper()
        }
    }

    /// A named preset: `paper` or `tiny`.
    pub fn preset(name: &str) -> RnnGmmResult<Self> {
        match name {
            "paper" => Ok(Config::paper()),
            "tiny" => Ok(Config::tiny()),
            other => Err(RnnGmmError::Config(format!("unknown preset `{other}`: use `paper` or `tiny`"))),
        }
    }

    /// Sets the state feature size.
    pub fn with_dim(mut self, dim: usize) -> Self {
        self.dim = dim;
        self
    }

    /// Values of the mixture head per frame: `M` weight logits, `M * D` means, `M * D` log stds.
    pub fn head_dim(&self) -> usize {
        self.components * (1 + 2 * self.dim)
    }

    /// Checks every size and setting; the message names the field and the allowed range.
    pub fn validate(&self) -> RnnGmmResult<()> {
        let t = &self.train;
        let bad = |m: String| Err(RnnGmmError::Config(m));
        if self.dim <= crate::features::ROOT_DIMS + crate::features::CONTACT_DIMS {
            return bad(format!("dim must be at least 9 (root, one joint, contacts), found {}", self.dim));
        }
        if self.fc.is_empty() || self.fc.contains(&0) {
            return bad(format!("fc needs at least one layer and no zero width, found {:?}", self.fc));
        }
        if self.lstm == 0 || self.lstm_layers == 0 || self.components == 0 {
            return bad(format!(
                "lstm ({}), lstm_layers ({}) and components ({}) must be positive",
                self.lstm, self.lstm_layers, self.components
            ));
        }
        if !(self.min_log_std < self.max_log_std && self.min_log_std.is_finite() && self.max_log_std.is_finite()) {
            return bad(format!(
                "min_log_std ({}) must be below max_log_std ({}), both finite",
                self.min_log_std, self.max_log_std
            ));
        }
        if !(t.learning_rate > 0.0 && t.lr_decay > 0.0 && t.lr_decay <= 1.0 && (0.0..1.0).contains(&t.rho)) {
            return bad(format!(
                "train: learning_rate ({}) must be positive, lr_decay ({}) in (0, 1], rho ({}) in [0, 1)",
                t.learning_rate, t.lr_decay, t.rho
            ));
        }
        if !(t.clip > 0.0 && t.input_noise >= 0.0 && t.eps > 0.0) {
            return bad(format!(
                "train: clip ({}) and eps ({}) must be positive, input_noise ({}) not negative",
                t.clip, t.eps, t.input_noise
            ));
        }
        if t.batch_size == 0 || t.window < 2 || t.window_stride == 0 {
            return bad(format!(
                "train: batch_size ({}) and window_stride ({}) must be positive, window ({}) at least 2",
                t.batch_size, t.window_stride, t.window
            ));
        }
        self.refiner.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_name_the_model() {
        for name in ["paper", "tiny"] {
            let c = Config::preset(name).unwrap();
            c.validate().unwrap();
            let json = serde_json::to_value(&c).unwrap();
            assert_eq!(json["model"], "rnn-gmm");
            let back: Config = serde_json::from_value(json).unwrap();
            assert_eq!(back, c);
        }
        assert_eq!(Config::paper().head_dim(), 5 * (1 + 2 * 68));
        assert!(Config::preset("huge").unwrap_err().to_string().contains("paper"));
    }

    #[test]
    fn bad_settings_are_refused() {
        let mut c = Config::tiny();
        c.components = 0;
        assert!(c.validate().unwrap_err().to_string().contains("components"));
        let mut c = Config::tiny();
        c.train.window = 1;
        assert!(c.validate().unwrap_err().to_string().contains("window"));
        let mut c = Config::tiny();
        c.min_log_std = 6.0;
        assert!(c.validate().unwrap_err().to_string().contains("min_log_std"));
        let other = serde_json::json!({"model": "rtn"});
        assert!(serde_json::from_value::<ModelName>(other["model"].clone()).is_err());
    }
}
