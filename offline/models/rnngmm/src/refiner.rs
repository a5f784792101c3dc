//! The refiner R and the discriminator D (sec. 4.2.1, eq. 9-13) and their adversarial training
//! (sec. 4.2.2): warm-up, several refiner updates per discriminator update adapted to the
//! discriminator's loss, a history buffer of refined motions, and discriminator-collapse
//! detection. [`AdversarialTraining`] plugs it into the shared training loop.
//!
//! - Refiner (eq. 11): `R(x) = W2 lstm(relu(W1 [x; p_end(x); v_end(x)] + b1)) + b2 + x` on
//!   normalised features; `W2, b2` start at zero, so R starts as the identity.
//! - Discriminator (eq. 12): `D(x) = W2 bilstm(relu(W1 [p_end(x); v_end(x); c(x)] + b1)) + b2`,
//!   one logit per frame (`c`: the contact values); a window's loss is the mean over its frames.
//! - Losses: refiner `-log D(R(x)) + lambda |root(x) - root(R(x))|^2` (eq. 13, the root values
//!   `dtx, dtz, dry, ty` normalised, squared error summed over them and averaged over frames);
//!   discriminator `-log(1 - D(R(x))) - log D(x_real)` (eq. 10); `-log sigma(l)` is computed as
//!   `softplus(-l)`.
//! - End-effector features ([`crate::fk`]) are normalised with statistics of the real training
//!   windows ([`EffectorNorm`], saved as `effectors.json`).

use crate::checkpoint as rck;
use crate::config::{Config, RefinerConfig};
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{FeatureSpec, Normalization, ROOT_DIMS};
use crate::fk::{TensorFk, end_effectors};
use crate::model::Generator;
use crate::train::Windows;
use candle_core::{D, DType, Device, Module, Result, Tensor, Var};
use candle_nn::{Init, Linear, Optimizer, VarBuilder, VarMap};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;
use zoo_motion::rng::SplitMix64;
use zoo_nn::checkpoint as ck;
use zoo_nn::optim::{ParamsRmsProp, RmsProp, StatefulOptimizer, clip_grad_value};
use zoo_nn::train_loop::{Trainable, Validation};
use zoo_nn::{BiLstm, Lstm, LstmState, SeededVarMap, TrainError};

/// The refiner's weights.
pub const REFINER_FILE: &str = "refiner.safetensors";
/// The discriminator's weights.
pub const DISCRIMINATOR_FILE: &str = "discriminator.safetensors";
/// The end-effector statistics.
pub const EFFECTORS_FILE: &str = "effectors.json";
/// The refiner's optimiser state.
pub const REFINER_OPTIMIZER_FILE: &str = "refiner_optimizer.safetensors";
/// The discriminator's optimiser state.
pub const DISCRIMINATOR_OPTIMIZER_FILE: &str = "discriminator_optimizer.safetensors";
/// The history buffer of refined motions and the pool of fake windows.
pub const HISTORY_FILE: &str = "history.safetensors";
/// Counters and the generator state of adversarial training.
pub const ADVERSARIAL_FILE: &str = "adversarial.json";

/// Root values of the self-regularisation term: `dtx, dtz, dry, ty`.
const ROOT_REG_DIMS: usize = 4;

/// Generator windows (at most) sampled once from the validation windows to pick the refiner's
/// checkpoint.
const VALID_FAKES: usize = 128;

/// End effectors and the mean / std of their features `[p_end; v_end]` (`6 E` values).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EffectorNorm {
    /// Joint index of each end effector.
    pub effectors: Vec<usize>,
    /// Mean of each feature.
    pub mean: Vec<f32>,
    /// Standard deviation of each feature (1 where it does not vary).
    pub std: Vec<f32>,
    /// The refiner's joint limits ([`crate::RefinerConfig::joint_limits`]); absent in runs
    /// written before they existed or trained without them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limits: Option<JointLimits>,
}

/// Joint limits of the refiner's output: the normalised feature values `first .. first +
/// lo.len()` (`rx, rz` and the joint angles) are clamped to `[lo, hi]`, their min and max over
/// the real training windows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointLimits {
    /// First limited feature value.
    pub first: usize,
    /// Lower limit of each value (normalised).
    pub lo: Vec<f32>,
    /// Upper limit of each value (normalised).
    pub hi: Vec<f32>,
}

impl JointLimits {
    /// The min and max of the values `ROOT_DIMS - 2 .. contact` over every frame of `windows`.
    pub fn fit(windows: &Windows, contact: usize) -> RnnGmmResult<Self> {
        let first = ROOT_DIMS - 2;
        if windows.is_empty() || contact <= first || contact > windows.dim {
            return Err(RnnGmmError::Config(format!(
                "joint limits need real windows ({}) of more than {first} values before the contacts (at {contact} of {})",
                windows.len(),
                windows.dim
            )));
        }
        let n = contact - first;
        let (mut lo, mut hi) = (vec![f32::INFINITY; n], vec![f32::NEG_INFINITY; n]);
        for frame in windows.data.chunks(windows.dim) {
            for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(&frame[first..contact]) {
                (*l, *h) = (l.min(*v), h.max(*v));
            }
        }
        Ok(JointLimits { first, lo, hi })
    }

    /// Lower and upper bounds over all `d` values of a frame (`-f32::MAX` / `f32::MAX` for the
    /// unlimited ones), as the refiner applies them and its step graph exports them.
    pub fn full(&self, d: usize) -> RnnGmmResult<(Vec<f32>, Vec<f32>)> {
        let n = self.lo.len();
        if self.hi.len() != n || self.first + n > d || self.lo.iter().zip(&self.hi).any(|(l, h)| !(l <= h)) {
            return Err(RnnGmmError::Config(format!(
                "joint limits of {} / {} values from value {} do not fit frames of {d} values with lo <= hi",
                n,
                self.hi.len(),
                self.first
            )));
        }
        let (mut lo, mut hi) = (vec![-f32::MAX; d], vec![f32::MAX; d]);
        lo[self.first..self.first + n].copy_from_slice(&self.lo);
        hi[self.first..self.first + n].copy_from_slice(&self.hi);
        Ok((lo, hi))
    }
}

impl EffectorNorm {
    /// Fits the statistics on every frame of `windows`.
    pub fn fit(fk: &TensorFk, effectors: &[usize], windows: &Windows, device: &Device) -> RnnGmmResult<Self> {
        let n = 6 * effectors.len();
        let (mut sum, mut sq, mut count) = (vec![0f64; n], vec![0f64; n], 0usize);
        for start in (0..windows.len()).step_by(64) {
            let k = (windows.len() - start).min(64);
            let data = &windows.data[start * windows.window * windows.dim..(start + k) * windows.window * windows.dim];
            let x = Tensor::from_slice(data, (k, windows.window, windows.dim), device)?;
            let f = fk.effector_features(&x)?.reshape((k * windows.window, n))?.to_vec2::<f32>()?;
            for row in f {
                for (i, v) in row.iter().enumerate() {
                    sum[i] += *v as f64;
                    sq[i] += (*v as f64).powi(2);
                }
                count += 1;
            }
        }
        if count == 0 {
            return Err(RnnGmmError::Config("no real windows to fit the end-effector statistics on".into()));
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / count as f64).collect();
        let std = sq
            .iter()
            .zip(&mean)
            .map(|(q, m)| {
                let s = (q / count as f64 - m * m).max(0.0).sqrt();
                if s < Normalization::MIN_STD { 1.0 } else { s as f32 }
            })
            .collect();
        Ok(EffectorNorm {
            effectors: effectors.to_vec(),
            mean: mean.iter().map(|&m| m as f32).collect(),
            std,
            limits: None,
        })
    }
}

/// The `(t, t)` row-major matrix of a centred Gaussian filter of standard deviation `sigma`
/// frames, cut at 3 sigma and renormalised where it meets the window's ends: row `i` holds the
/// weights of frame `i`'s smoothed value.
pub fn smoothing_matrix(t: usize, sigma: f64) -> Vec<f32> {
    let reach = (3.0 * sigma).ceil() as usize;
    let mut m = vec![0f32; t * t];
    for i in 0..t {
        let (a, b) = (i.saturating_sub(reach), (i + reach + 1).min(t));
        let w: Vec<f64> = (a..b).map(|j| (-0.5 * ((j as f64 - i as f64) / sigma).powi(2)).exp()).collect();
        let sum: f64 = w.iter().sum();
        for (j, wj) in (a..b).zip(&w) {
            m[i * t + j] = (wj / sum) as f32;
        }
    }
    m
}

/// `log(1 + e^x)`, stable for large `|x|`.
fn softplus(x: &Tensor) -> Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// The refiner's loss and its terms as numbers.
#[derive(Clone, Debug)]
pub struct RefinerLoss {
    /// The weighted sum (the value to minimise).
    pub total: Tensor,
    /// `-log D(R(x))`, mean over frames.
    pub adversarial: f64,
    /// The root regularisation of eq. 13 (unweighted).
    pub regularisation: f64,
    /// The foot skate of the refined windows (clip units per frame; 0 without priors).
    pub skate: f64,
    /// The joint-range excess of the refined windows (0 without priors).
    pub range: f64,
}

impl RefinerLoss {
    /// The measure that picks the refiner checkpoint: `skate + range + lambda * regularisation`,
    /// the loss without its adversarial term (see [`AdversarialTrainer::validation_loss`]).
    pub fn measure(&self, lambda: f64) -> f64 {
        self.skate + self.range + lambda * self.regularisation
    }
}

/// What the refiner's added loss terms know about real motion, fitted on the real training
/// windows: the planted height of each foot joint (the 5th percentile of its height, as the
/// benchmark fits it) and the range of every `rx, rz` and joint-angle value.
#[derive(Clone, Debug)]
pub struct Priors {
    /// Position of each foot joint in the end-effector list.
    feet: Vec<usize>,
    /// Planted height of each foot joint, clip units, `(F)`.
    planted: Tensor,
    /// Range of the normalised values `ROOT_DIMS - 2 .. contact`, `(n)` each.
    lo: Tensor,
    hi: Tensor,
    /// First value and count of the ranged values.
    ranged: (usize, usize),
}

/// Height scale of the skate weight (BENCHMARK.md: 2.5 cm).
const SKATE_HEIGHT_SCALE: f64 = 2.5;

impl Priors {
    /// Fits the priors on the real windows `windows` for the feet of `spec` (those of its foot
    /// joints that are end effectors of `nets`); the range of each value runs from its
    /// `percentile`-th to its `(100 - percentile)`-th percentile.
    pub fn fit(
        nets: &RefinerNets,
        spec: &FeatureSpec,
        effectors: &[usize],
        windows: &Windows,
        percentile: f64,
        device: &Device,
    ) -> RnnGmmResult<Self> {
        let feet: Vec<usize> = spec
            .left_foot
            .iter()
            .chain(&spec.right_foot)
            .filter_map(|j| effectors.iter().position(|e| e == j))
            .collect();
        if feet.is_empty() || windows.is_empty() {
            return Err(RnnGmmError::Config(format!(
                "the refiner's skate term needs foot joints among the end effectors ({:?}) and real windows ({})",
                effectors,
                windows.len()
            )));
        }
        let e = effectors.len();
        let (first, count) = (ROOT_DIMS - 2, spec.contact_index() - (ROOT_DIMS - 2));
        let mut heights = vec![Vec::new(); feet.len()];
        let mut values = vec![Vec::with_capacity(windows.len() * windows.window); count];
        for frame in windows.data.chunks(windows.dim) {
            for (v, x) in values.iter_mut().zip(&frame[first..first + count]) {
                v.push(*x as f64);
            }
        }
        let (lo, hi): (Vec<f32>, Vec<f32>) = values
            .iter()
            .map(|v| {
                let p = |q: f64| zoo_data::plausibility::percentile(v, q) as f32;
                (p(percentile), p(100.0 - percentile))
            })
            .unzip();
        for start in (0..windows.len()).step_by(64) {
            let k = (windows.len() - start).min(64);
            let data = &windows.data[start * windows.window * windows.dim..(start + k) * windows.window * windows.dim];
            let x = Tensor::from_slice(data, (k, windows.window, windows.dim), device)?;
            let f = nets.fk.effector_features(&x)?.reshape((k * windows.window, 6 * e))?.to_vec2::<f32>()?;
            for row in f {
                for (h, &foot) in heights.iter_mut().zip(&feet) {
                    h.push(row[3 * foot + 1] as f64);
                }
            }
        }
        let planted: Vec<f32> = heights.iter().map(|h| zoo_data::plausibility::percentile(h, 5.0) as f32).collect();
        Ok(Priors {
            planted: Tensor::from_vec(planted, feet.len(), device)?,
            feet,
            lo: Tensor::from_vec(lo, count, device)?,
            hi: Tensor::from_vec(hi, count, device)?,
            ranged: (first, count),
        })
    }

    /// Position of each foot joint in the end-effector list.
    pub fn feet(&self) -> &[usize] {
        &self.feet
    }

    /// Planted height of each foot joint (clip units).
    pub fn planted(&self) -> Result<Vec<f32>> {
        self.planted.to_vec1()
    }

    /// Foot skate of normalised windows `r` `(batch, time, D)` (BENCHMARK.md): horizontal speed
    /// of each foot joint times `clamp(2 - 2^(h / 2.5), 0, 1)` of its height `h` above the planted
    /// height, mean over foot joints and frames `1..`. The height weight is constant for the
    /// gradient: the term slows planted feet down, it does not lift them.
    pub fn skate(&self, nets: &RefinerNets, r: &Tensor) -> Result<Tensor> {
        let (b, t, _) = r.dims3()?;
        let e = nets.fk.effector_count();
        let f = nets.fk.effector_features(r)?.narrow(1, 1, t - 1)?.reshape((b, t - 1, 2, e, 3))?;
        let idx = Tensor::from_vec(self.feet.iter().map(|&i| i as u32).collect(), self.feet.len(), r.device())?;
        let feet = f.index_select(&idx, 3)?; // (b, t - 1, 2, F, 3)
        let (pos, vel) = (feet.narrow(2, 0, 1)?.squeeze(2)?, feet.narrow(2, 1, 1)?.squeeze(2)?);
        let h = pos.narrow(3, 1, 1)?.squeeze(3)?.broadcast_sub(&self.planted)?.detach();
        let w = ((h * (std::f64::consts::LN_2 / SKATE_HEIGHT_SCALE))?.exp()?.affine(-1.0, 2.0)?).clamp(0f32, 1f32)?;
        let speed = ((vel.narrow(3, 0, 1)?.sqr()? + vel.narrow(3, 2, 1)?.sqr()?)? + 1e-8)?.sqrt()?.squeeze(3)?;
        (speed * w)?.mean_all()
    }

    /// Excess of the normalised values `rx, rz` and joint angles of `r` beyond their range in
    /// the training windows, summed over values, mean over frames. Linear in the excess, so a
    /// value just outside is pulled in as firmly as one far outside.
    pub fn range(&self, r: &Tensor) -> Result<Tensor> {
        let v = r.narrow(2, self.ranged.0, self.ranged.1)?;
        let below = v.broadcast_sub(&self.lo)?.neg()?.relu()?;
        let above = v.broadcast_sub(&self.hi)?.relu()?;
        (below + above)?.sum(2)?.mean_all()
    }
}

fn zero_linear(input: usize, output: usize, vb: VarBuilder) -> Result<Linear> {
    let w = vb.get_with_hints((output, input), "weight", Init::Const(0.0))?;
    let b = vb.get_with_hints(output, "bias", Init::Const(0.0))?;
    Ok(Linear::new(w, Some(b)))
}

/// The refiner and the discriminator with the end-effector computation they share.
#[derive(Clone, Debug)]
pub struct RefinerNets {
    fk: TensorFk,
    eff_mean: Tensor,
    eff_std: Tensor,
    r_fc1: Linear,
    r_lstm: Lstm,
    r_fc2: Linear,
    d_fc1: Linear,
    d_bilstm: BiLstm,
    d_fc2: Linear,
    contact: usize,
    /// Joint limits over whole frames `(D)`, lower and upper.
    limits: Option<(Tensor, Tensor)>,
}

impl RefinerNets {
    /// Builds (or loads) the refiner from `rvb` (`fc1`, `lstm`, `fc2`) and the discriminator from
    /// `dvb` (`fc1`, `bilstm`, `fc2`).
    pub fn new(
        config: &Config,
        spec: &FeatureSpec,
        norm: &Normalization,
        eff: &EffectorNorm,
        rvb: VarBuilder,
        dvb: VarBuilder,
    ) -> RnnGmmResult<Self> {
        let c = &config.refiner;
        let device = rvb.device().clone();
        let fk = TensorFk::new(spec, norm, &eff.effectors, &device)?;
        let e = 6 * eff.effectors.len();
        if eff.mean.len() != e || eff.std.len() != e {
            return Err(RnnGmmError::Config(format!(
                "end-effector statistics of {} / {} values for {} effectors (6 values each)",
                eff.mean.len(),
                eff.std.len(),
                eff.effectors.len()
            )));
        }
        let d = config.dim;
        let limits = match &eff.limits {
            Some(l) => {
                let (lo, hi) = l.full(d)?;
                Some((Tensor::from_vec(lo, d, &device)?, Tensor::from_vec(hi, d, &device)?))
            }
            None => None,
        };
        Ok(RefinerNets {
            limits,
            eff_mean: Tensor::from_slice(&eff.mean, e, &device)?,
            eff_std: Tensor::from_slice(&eff.std, e, &device)?,
            r_fc1: candle_nn::linear(d + e, c.refiner_fc, rvb.pp("fc1"))?,
            r_lstm: Lstm::new(c.refiner_fc, c.refiner_lstm, 1, 0.0, rvb.pp("lstm"))?,
            r_fc2: zero_linear(c.refiner_lstm, d, rvb.pp("fc2"))?,
            d_fc1: candle_nn::linear(e + 2, c.discriminator_fc, dvb.pp("fc1"))?,
            d_bilstm: BiLstm::new(c.discriminator_fc, c.discriminator_lstm, 1, 0.0, dvb.pp("bilstm"))?,
            d_fc2: candle_nn::linear(2 * c.discriminator_lstm, 1, dvb.pp("fc2"))?,
            contact: spec.contact_index(),
            fk,
        })
    }

    /// Normalised `[p_end; v_end]` of normalised features `(batch, time, D)`: `(batch, time, 6 E)`.
    pub fn effector_input(&self, x: &Tensor) -> Result<Tensor> {
        self.fk.effector_features(x)?.broadcast_sub(&self.eff_mean)?.broadcast_div(&self.eff_std)
    }

    /// `R(x)` (eq. 11), normalised features in and out, `(batch, time, D)`.
    pub fn refine(&self, x: &Tensor) -> Result<Tensor> {
        let e = self.effector_input(x)?.detach();
        let h = self.r_fc1.forward(&Tensor::cat(&[x, &e], 2)?)?.relu()?;
        let (h, _) = self.r_lstm.forward_seq(&h, &self.r_lstm.zero_state(x.dim(0)?)?, None)?;
        self.limit((self.r_fc2.forward(&h)? + x)?)
    }

    /// The joint limits applied to refined frames (none without limits).
    fn limit(&self, r: Tensor) -> Result<Tensor> {
        match &self.limits {
            Some((lo, hi)) => r.broadcast_maximum(lo)?.broadcast_minimum(hi),
            None => Ok(r),
        }
    }

    /// `R(x)` over a long sequence in chunks (streaming synthesis): refines the chunk `x`
    /// `(batch, time, D)` that follows frame `prev` `(batch, 1, D)` (`None` for the first chunk,
    /// which needs at least 2 frames), continuing the refiner's LSTM from `state`
    /// ([`RefinerNets::refiner_zero_state`] at the start). Returns the refined chunk and the
    /// state after it. Refining a sequence chunk by chunk gives what [`RefinerNets::refine`]
    /// gives on the whole (up to float rounding): the end-effector velocities of a chunk's first
    /// frame use `prev`, as they would in the whole sequence.
    pub fn refine_chunk(&self, x: &Tensor, prev: Option<&Tensor>, state: &LstmState) -> Result<(Tensor, LstmState)> {
        let t = x.dim(1)?;
        let e = match prev {
            Some(p) => self.effector_input(&Tensor::cat(&[p, x], 1)?)?.narrow(1, 1, t)?,
            None => self.effector_input(x)?,
        };
        let h = self.r_fc1.forward(&Tensor::cat(&[x, &e.detach()], 2)?)?.relu()?;
        let (h, state) = self.r_lstm.forward_seq(&h, state, None)?;
        Ok((self.limit((self.r_fc2.forward(&h)? + x)?)?, state))
    }

    /// The refiner LSTM's zero state for `batch` sequences.
    pub fn refiner_zero_state(&self, batch: usize) -> Result<LstmState> {
        self.r_lstm.zero_state(batch)
    }

    /// Discriminator logits (eq. 12), one per frame: `(batch, time)`.
    pub fn logits(&self, x: &Tensor) -> Result<Tensor> {
        let input = Tensor::cat(&[&self.effector_input(x)?, &x.narrow(2, self.contact, 2)?], 2)?;
        let h = self.d_fc1.forward(&input)?.relu()?;
        self.d_fc2.forward(&self.d_bilstm.forward(&h, None)?)?.squeeze(D::Minus1)
    }

    /// The refiner's loss on fake windows `x`: eq. 13, plus the foot-skate and joint-range terms
    /// of `priors` weighted by `c.skate_weight` and `c.range_weight` (none without priors).
    pub fn refiner_loss(&self, x: &Tensor, c: &RefinerConfig, priors: Option<&Priors>) -> Result<RefinerLoss> {
        let r = self.refine(x)?;
        let adv = softplus(&self.logits(&r)?.neg()?)?.mean_all()?;
        let reg = self.root_regularisation(x, &r, c.root_smoothing)?;
        let mut total = (&adv + (&reg * c.lambda)?)?;
        let (mut skate, mut range) = (0.0, 0.0);
        if let Some(p) = priors {
            let (s, g) = (p.skate(self, &r)?, p.range(&r)?);
            (skate, range) = (s.to_scalar::<f32>()? as f64, g.to_scalar::<f32>()? as f64);
            total = ((total + (s * c.skate_weight)?)? + (g * c.range_weight)?)?;
        }
        let (adversarial, regularisation) = (adv.to_scalar::<f32>()? as f64, reg.to_scalar::<f32>()? as f64);
        Ok(RefinerLoss { total, adversarial, regularisation, skate, range })
    }

    /// `|root(x) - root(R(x))|^2` of eq. 13 on the normalised root values, summed over them and
    /// averaged over frames.
    /// With `smoothing` (frames, [`crate::RefinerConfig::root_smoothing`]) the generator's root
    /// values are first smoothed along time by a Gaussian of that standard deviation.
    fn root_regularisation(&self, x: &Tensor, r: &Tensor, smoothing: f64) -> Result<Tensor> {
        let target = x.narrow(2, 0, ROOT_REG_DIMS)?;
        let target = if smoothing > 0.0 {
            let t = x.dim(1)?;
            Tensor::from_vec(smoothing_matrix(t, smoothing), (t, t), x.device())?.broadcast_matmul(&target)?
        } else {
            target
        };
        (r.narrow(2, 0, ROOT_REG_DIMS)? - target.detach())?.sqr()?.sum(2)?.mean_all()
    }

    /// The discriminator's loss (eq. 10) on real and refined windows.
    pub fn discriminator_loss(&self, real: &Tensor, refined: &Tensor) -> Result<Tensor> {
        softplus(&self.logits(real)?.neg()?)?.mean_all()? + softplus(&self.logits(refined)?)?.mean_all()?
    }
}

/// A trained generator and refiner for inference, from a run folder of the refiner stage.
#[derive(Clone, Debug)]
pub struct LoadedModel {
    /// The generator with its feature and statistics.
    pub generator: rck::LoadedGenerator,
    /// The refiner and the discriminator.
    pub nets: RefinerNets,
    /// The end-effector statistics.
    pub effectors: EffectorNorm,
}

/// Loads the generator, the refiner and the discriminator of a run folder written by
/// [`AdversarialTrainer::save`]. A folder of the generator stage only (no `refiner.safetensors`)
/// is refused with a message saying so.
pub fn load(dir: &Path, device: &Device) -> RnnGmmResult<LoadedModel> {
    let generator = rck::load(dir, device)?;
    if !dir.join(REFINER_FILE).is_file() {
        return Err(RnnGmmError::Config(format!(
            "{} holds no {REFINER_FILE}: it is a generator run; train the refiner stage on it first (or generate \
             without the refiner)",
            dir.display()
        )));
    }
    let config = generator.generator.config().clone();
    let effectors: EffectorNorm = ck::read_json(&dir.join(EFFECTORS_FILE))?;
    let (r_varmap, d_varmap) = (VarMap::new(), VarMap::new());
    let build =
        |r: VarBuilder, d: VarBuilder| RefinerNets::new(&config, &generator.spec, &generator.norm, &effectors, r, d);
    build(
        VarBuilder::from_varmap(&r_varmap, DType::F32, device),
        VarBuilder::from_varmap(&d_varmap, DType::F32, device),
    )?;
    ck::read_varmap(&dir.join(REFINER_FILE), &r_varmap)?;
    ck::read_varmap(&dir.join(DISCRIMINATOR_FILE), &d_varmap)?;
    // Inference only: the weights as constants (see `rck::frozen`).
    let nets = build(rck::frozen(&r_varmap, device)?, rck::frozen(&d_varmap, device)?)?;
    Ok(LoadedModel { generator, nets, effectors })
}

/// Counters and generator state of an adversarial run (`adversarial.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct AdversarialState {
    rng: u64,
    refiner_updates: usize,
    collapse_count: usize,
    warmed_up: bool,
    rounds: u64,
    last_discriminator_loss: Option<f64>,
}

/// Trains the refiner and the discriminator against a frozen generator.
pub struct AdversarialTrainer {
    config: Config,
    spec: FeatureSpec,
    norm: Normalization,
    eff: EffectorNorm,
    gen_varmap: VarMap,
    /// The frozen generator (fresh fakes).
    generator: Generator,
    r_varmap: VarMap,
    d_varmap: VarMap,
    nets: RefinerNets,
    opt_r: RmsProp,
    opt_d: RmsProp,
    r_vars: Vec<Var>,
    d_vars: Vec<Var>,
    /// `x_RNN`: windows sampled from the generator (normalised).
    fakes: Windows,
    /// Fixed fakes for validation.
    valid_fakes: Windows,
    /// Refined windows of earlier refiners, `history * window * D`.
    history: Vec<f32>,
    /// Skate heights and joint ranges of the real training windows (the added loss terms and
    /// the validation measure).
    priors: Option<Priors>,
    rng: SplitMix64,
    k: usize,
    collapse_count: usize,
    warmed_up: bool,
    rounds: u64,
    last_d: Option<f64>,
    device: Device,
    /// Workers of the data-parallel updates ([`AdversarialTrainer::set_threads`]; one by default).
    parallel: zoo_nn::DataParallel,
}

fn sorted_vars(varmap: &VarMap) -> Vec<(String, Var)> {
    let mut named: Vec<(String, Var)> =
        varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    named
}

/// Samples `count` fake windows from the generator, each seeded with the first frames of a real
/// window (cycling through `real`).
fn sample_fakes(
    generator: &Generator,
    real: &Windows,
    count: usize,
    c: &RefinerConfig,
    rng: &mut SplitMix64,
) -> RnnGmmResult<Windows> {
    let (w, d) = (real.window, real.dim);
    let seed_len = c.seed_frames.clamp(1, w);
    let mut data = Vec::with_capacity(count * w * d);
    for start in (0..count).step_by(64) {
        let n = (count - start).min(64);
        let mut seeds = Vec::with_capacity(n * seed_len * d);
        for i in start..start + n {
            seeds.extend_from_slice(&real.get(i % real.len())[..seed_len * d]);
        }
        let lead = c.fake_lead_frames;
        let sampled = generator.sample_batch(&seeds, n, seed_len, lead + w, rng, c.temperature)?;
        for i in 0..n {
            let s = (i * (lead + w) + lead) * d;
            data.extend_from_slice(&sampled[s..s + w * d]);
        }
    }
    Ok(Windows { window: w, dim: d, data })
}

impl AdversarialTrainer {
    /// A trainer for the generator in run folder `generator_dir`: samples its fake windows
    /// (seeded from `train` and `valid`), fits the end-effector statistics on `train`, builds the
    /// refiner (near the identity) and the discriminator, and fills the history buffer with the
    /// initial refiner's output. `config.refiner` replaces the folder's refiner settings.
    pub fn new(
        generator_dir: &Path,
        refiner: &RefinerConfig,
        train: &Windows,
        valid: &Windows,
        device: &Device,
    ) -> RnnGmmResult<Self> {
        let (mut config, spec, norm) = rck::read_meta(generator_dir)?;
        config.refiner = refiner.clone();
        config.validate()?;
        let gen_varmap = VarMap::new();
        let generator = Generator::new(&config, VarBuilder::from_varmap(&gen_varmap, DType::F32, device))?;
        rck::load_weights(generator_dir, &gen_varmap)?;
        for (what, w) in [("training", train), ("validation", valid)] {
            if w.is_empty() || w.dim != config.dim || w.window < 2 {
                return Err(RnnGmmError::Config(format!(
                    "{what} windows: {} windows of {} frames of {} values; adversarial training needs at least one \
                     of at least 2 frames of {}",
                    w.len(),
                    w.window,
                    w.dim,
                    config.dim
                )));
            }
        }
        let c = &config.refiner;
        let mut rng = SplitMix64::new(c.seed);
        let fakes = sample_fakes(&generator, train, c.fake_windows, c, &mut rng)?;
        let valid_fakes = sample_fakes(&generator, valid, valid.len().clamp(1, VALID_FAKES.max(c.batch)), c, &mut rng)?;
        let effectors = end_effectors(&spec);
        let fk = TensorFk::new(&spec, &norm, &effectors, device)?;
        let mut eff = EffectorNorm::fit(&fk, &effectors, train, device)?;
        if c.joint_limits {
            eff.limits = Some(JointLimits::fit(train, spec.contact_index())?);
        }
        let mut t = Self::build(config, spec, norm, eff, (gen_varmap, generator), fakes, valid_fakes, rng, device)?;
        t.priors =
            Some(Priors::fit(&t.nets, &t.spec, &t.eff.effectors, train, t.config.refiner.range_percentile, device)?);
        Ok(t)
    }

    fn build(
        config: Config,
        spec: FeatureSpec,
        norm: Normalization,
        eff: EffectorNorm,
        (gen_varmap, generator): (VarMap, Generator),
        fakes: Windows,
        valid_fakes: Windows,
        rng: SplitMix64,
        device: &Device,
    ) -> RnnGmmResult<Self> {
        let c = &config.refiner;
        let (r_varmap, d_varmap) = (VarMap::new(), VarMap::new());
        let rvb = SeededVarMap::builder(&r_varmap, c.seed, DType::F32, device);
        let dvb = SeededVarMap::builder(&d_varmap, c.seed ^ 0xd15c, DType::F32, device);
        let nets = RefinerNets::new(&config, &spec, &norm, &eff, rvb, dvb)?;
        let (r_named, d_named) = (sorted_vars(&r_varmap), sorted_vars(&d_varmap));
        let r_vars = r_named.iter().map(|(_, v)| v.clone()).collect();
        let d_vars = d_named.iter().map(|(_, v)| v.clone()).collect();
        let params = |lr: f64| ParamsRmsProp { lr, rho: c.rho, eps: 1e-8, lr_decay: 1.0 };
        let opt_r = RmsProp::new_named(r_named, params(c.refiner_lr))?;
        let opt_d = RmsProp::new_named(d_named, params(c.discriminator_lr))?;
        let mut t = AdversarialTrainer {
            k: c.refiner_updates,
            config,
            spec,
            norm,
            eff,
            gen_varmap,
            generator,
            r_varmap,
            d_varmap,
            nets,
            opt_r,
            opt_d,
            r_vars,
            d_vars,
            fakes,
            valid_fakes,
            history: Vec::new(),
            priors: None,
            rng,
            collapse_count: 0,
            warmed_up: false,
            rounds: 0,
            last_d: None,
            device: device.clone(),
            parallel: zoo_nn::DataParallel::new(1)?,
        };
        // "We generate B fake data in the very beginning": the initial refiner's output.
        let hist: Vec<usize> = (0..t.config.refiner.history).collect();
        t.history = t.refine_windows(&hist)?.flatten_all()?.to_vec1::<f32>()?;
        Ok(t)
    }

    /// Trains with `threads` data-parallel workers (`zoo_nn::parallel`): each refiner update's
    /// batch of fakes, and each discriminator update's real and refined windows, are cut into
    /// contiguous shards whose gradients are summed before the one RMSProp step. The windows of
    /// an update are drawn before the split, so the draws do not depend on the thread count; a
    /// fixed thread count gives the same bits run to run.
    pub fn set_threads(&mut self, threads: usize) -> RnnGmmResult<()> {
        self.parallel = zoo_nn::DataParallel::new(threads)?;
        Ok(())
    }

    /// The number of data-parallel workers.
    pub fn threads(&self) -> usize {
        self.parallel.threads()
    }

    /// The variables of the refiner and of the discriminator.
    pub fn varmaps(&self) -> (&VarMap, &VarMap) {
        (&self.r_varmap, &self.d_varmap)
    }

    /// The configuration (with the refiner settings in use).
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The skate heights and joint ranges of the real training windows.
    pub fn priors(&self) -> Option<&Priors> {
        self.priors.as_ref()
    }

    /// The refiner and the discriminator.
    pub fn nets(&self) -> &RefinerNets {
        &self.nets
    }

    /// Refiner updates per discriminator update now.
    pub fn refiner_updates(&self) -> usize {
        self.k
    }

    /// The last discriminator loss.
    pub fn last_discriminator_loss(&self) -> Option<f64> {
        self.last_d
    }

    /// Adversarial rounds run (the warm-up not counted).
    pub fn rounds(&self) -> u64 {
        self.rounds
    }

    /// Fake windows `(batch, window, D)` by index into the fake pool.
    fn fake_tensor(&self, idx: &[usize]) -> Result<Tensor> {
        let mut data = Vec::with_capacity(idx.len() * self.fakes.window * self.fakes.dim);
        for &i in idx {
            data.extend_from_slice(self.fakes.get(i));
        }
        Tensor::from_vec(data, (idx.len(), self.fakes.window, self.fakes.dim), &self.device)
    }

    fn refine_windows(&self, idx: &[usize]) -> Result<Tensor> {
        Ok(self.nets.refine(&self.fake_tensor(idx)?)?.detach())
    }

    fn draw(&mut self, n: usize, below: usize) -> Vec<usize> {
        (0..n).map(|_| self.rng.below(below as u64) as usize).collect()
    }

    fn check(value: f64, what: &str, step: u64) -> RnnGmmResult<f64> {
        if value.is_finite() {
            Ok(value)
        } else {
            Err(RnnGmmError::Config(format!(
                "the {what} loss became {value} at step {step}; the update was not applied"
            )))
        }
    }

    /// One refiner update on a batch of fakes; returns its loss.
    pub fn refiner_update(&mut self) -> RnnGmmResult<f64> {
        let c = self.config.refiner.clone();
        let idx = self.draw(c.batch, self.fakes.len());
        let x = self.fake_tensor(&idx)?;
        let (nets, priors) = (&self.nets, self.priors.as_ref());
        let (value, grads) = self.parallel.backward(idx.len(), &self.r_vars, |r| {
            Ok(nets.refiner_loss(&x.narrow(0, r.start, r.len())?, &c, priors)?.total)
        })?;
        let value = Self::check(value, "refiner", self.opt_r.steps())?;
        let mut grads = grads.ok_or_else(|| RnnGmmError::Config("the refiner update computed no gradients".into()))?;
        clip_grad_value(&mut grads, &self.r_vars, c.clip)?;
        self.opt_r.step(&grads)?;
        Ok(value)
    }

    /// One discriminator update: real windows against half fresh refined windows and half from
    /// the history buffer, whose entries are then partly replaced by the fresh ones. Returns its
    /// loss.
    pub fn discriminator_update(&mut self, real: &Tensor) -> RnnGmmResult<f64> {
        let c = self.config.refiner.clone();
        let half = (c.batch / 2).max(1);
        let fresh_idx = self.draw(half, self.fakes.len());
        let fresh = self.refine_windows(&fresh_idx)?;
        let n = self.fakes.window * self.fakes.dim;
        let slots = self.draw(half, c.history);
        let mut old = Vec::with_capacity(half * n);
        for &s in &slots {
            old.extend_from_slice(&self.history[s * n..(s + 1) * n]);
        }
        let old = Tensor::from_vec(old, (half, self.fakes.window, self.fakes.dim), &self.device)?;
        let refined = Tensor::cat(&[&fresh, &old], 0)?;
        let (value, grads) = self.discriminator_gradients(real, &refined)?;
        let value = Self::check(value, "discriminator", self.opt_d.steps())?;
        let mut grads =
            grads.ok_or_else(|| RnnGmmError::Config("the discriminator update computed no gradients".into()))?;
        clip_grad_value(&mut grads, &self.d_vars, c.clip)?;
        self.opt_d.step(&grads)?;
        let fresh = fresh.flatten_all()?.to_vec1::<f32>()?;
        let replace = self.draw(half, c.history);
        for (k, &s) in replace.iter().enumerate() {
            self.history[s * n..(s + 1) * n].copy_from_slice(&fresh[k * n..(k + 1) * n]);
        }
        Ok(value)
    }

    /// The discriminator's loss (eq. 10) and gradients. Real and refined batches of the same
    /// size are cut into the same shards (each shard's `mean(real) + mean(refined)` weighted by
    /// its share is the whole batch's loss); batches of different sizes (an odd batch size) run
    /// on one worker.
    fn discriminator_gradients(
        &self,
        real: &Tensor,
        refined: &Tensor,
    ) -> Result<(f64, Option<candle_core::backprop::GradStore>)> {
        let (n, m) = (real.dim(0)?, refined.dim(0)?);
        let nets = &self.nets;
        if n == m {
            self.parallel.backward(n, &self.d_vars, |r| {
                nets.discriminator_loss(&real.narrow(0, r.start, r.len())?, &refined.narrow(0, r.start, r.len())?)
            })
        } else {
            let loss = nets.discriminator_loss(real, refined)?;
            let value = loss.to_scalar::<f32>()? as f64;
            Ok((value, if value.is_finite() { Some(loss.backward()?) } else { None }))
        }
    }

    fn real_tensor(&self, windows: &Windows, idx: &[usize]) -> Result<Tensor> {
        let mut data = Vec::with_capacity(idx.len() * windows.window * windows.dim);
        for &i in idx {
            data.extend_from_slice(windows.get(i));
        }
        Tensor::from_vec(data, (idx.len(), windows.window, windows.dim), &self.device)
    }

    /// One round (sec. 4.2.2): the warm-up first if it has not run (75 refiner and 75
    /// discriminator updates), then `k` refiner updates and one discriminator update on the real
    /// windows `real_idx` of `real`; `k` doubles when the discriminator's loss is below
    /// `low_loss` and halves above `high_loss`. Returns the refiner's mean loss of the round.
    ///
    /// Discriminator collapse (see [`RefinerConfig::collapse_loss`]) returns
    /// [`RnnGmmError::Diverged`].
    pub fn round(&mut self, real: &Windows, real_idx: &[usize]) -> RnnGmmResult<f64> {
        let c = self.config.refiner.clone();
        if !self.warmed_up {
            for _ in 0..c.warmup_refiner {
                self.refiner_update()?;
            }
            for _ in 0..c.warmup_discriminator {
                let idx = self.draw(c.batch, real.len());
                let x = self.real_tensor(real, &idx)?;
                self.discriminator_update(&x)?;
            }
            self.warmed_up = true;
        }
        let mut sum = 0.0;
        for _ in 0..self.k {
            sum += self.refiner_update()?;
        }
        let loss = sum / self.k as f64;
        let x = self.real_tensor(real, real_idx)?;
        let d = self.discriminator_update(&x)?;
        self.refresh_fakes(real)?;
        self.last_d = Some(d);
        self.rounds += 1;
        let at_max = self.k >= c.max_refiner_updates;
        if d < c.low_loss {
            self.k = (2 * self.k).min(c.max_refiner_updates);
        } else if d > c.high_loss {
            self.k = (self.k / 2).max(1);
        }
        self.collapse_count = if d < c.collapse_loss && at_max { self.collapse_count + 1 } else { 0 };
        if self.collapse_count >= c.collapse_rounds {
            return Err(RnnGmmError::Diverged(format!(
                "discriminator collapse: its loss stayed below {} for {} rounds (last {d:.3e}) with {} refiner \
                 updates per round, so the refiner no longer learns; lower discriminator_lr or raise lambda",
                c.collapse_loss, self.collapse_count, self.k
            )));
        }
        Ok(loss)
    }

    /// Replaces `fresh_fakes` random windows of the fake pool by new generator samples seeded
    /// with random windows of `real`.
    fn refresh_fakes(&mut self, real: &Windows) -> RnnGmmResult<()> {
        let c = self.config.refiner.clone();
        let n = c.fresh_fakes.min(self.fakes.len());
        if n == 0 {
            return Ok(());
        }
        let seeds = self.draw(n, real.len());
        let slots = self.draw(n, self.fakes.len());
        let picked = Windows {
            window: real.window,
            dim: real.dim,
            data: seeds.iter().flat_map(|&i| real.get(i).iter().copied()).collect(),
        };
        let fresh = sample_fakes(&self.generator, &picked, n, &c, &mut self.rng)?;
        let w = self.fakes.window * self.fakes.dim;
        for (k, &s) in slots.iter().enumerate() {
            self.fakes.data[s * w..(s + 1) * w].copy_from_slice(fresh.get(k));
        }
        Ok(())
    }

    /// The refiner's loss on the fixed validation fakes, without updating anything.
    pub fn validation_terms(&self) -> RnnGmmResult<RefinerLoss> {
        self.terms_on(&self.valid_fakes, self.valid_fakes.len())
    }

    /// The refiner's loss on the first [`VALID_FAKES`] training fakes (to compare with the
    /// validation fakes: a refiner that learns its training fakes by heart does better on them).
    pub fn training_terms(&self) -> RnnGmmResult<RefinerLoss> {
        self.terms_on(&self.fakes, self.fakes.len().min(VALID_FAKES))
    }

    fn terms_on(&self, w: &Windows, n: usize) -> RnnGmmResult<RefinerLoss> {
        let x = Tensor::from_slice(&w.data[..n * w.window * w.dim], (n, w.window, w.dim), &self.device)?;
        Ok(self.nets.refiner_loss(&x, &self.config.refiner, self.priors.as_ref())?)
    }

    /// The measure that picks the refiner checkpoint, on the fixed validation fakes:
    /// `skate + range + lambda * regularisation` of the refined windows ([`Priors`], eq. 13's
    /// root term). It leaves out the adversarial term: that one is measured against the
    /// discriminator of the moment, so it does not compare checkpoints (a refiner early in
    /// training looks best against a discriminator that has not learnt yet).
    pub fn validation_loss(&self) -> RnnGmmResult<f64> {
        Ok(self.validation_terms()?.measure(self.config.refiner.lambda))
    }

    /// Writes the generator's checkpoint files with this configuration, the refiner's and the
    /// discriminator's weights and the end-effector statistics.
    pub fn save(&self, dir: &Path) -> RnnGmmResult<()> {
        std::fs::create_dir_all(dir).map_err(ck::io(dir))?;
        let r = ck::stage_varmap(&dir.join(REFINER_FILE), &self.r_varmap)?;
        let d = ck::stage_varmap(&dir.join(DISCRIMINATOR_FILE), &self.d_varmap)?;
        let e = ck::stage_json(&dir.join(EFFECTORS_FILE), &self.eff)?;
        ck::commit([r, d, e])?;
        rck::save(dir, &self.config, &self.gen_varmap, &self.spec, &self.norm)
    }

    /// Writes both optimisers, the history buffer and the counters.
    pub fn save_training_state(&self, dir: &Path) -> RnnGmmResult<()> {
        ck::write_tensors(&dir.join(REFINER_OPTIMIZER_FILE), &self.opt_r.state()?)?;
        ck::write_tensors(&dir.join(DISCRIMINATOR_OPTIMIZER_FILE), &self.opt_d.state()?)?;
        let n = self.history.len() / (self.fakes.window * self.fakes.dim);
        let hist = Tensor::from_slice(&self.history, (n, self.fakes.window, self.fakes.dim), &Device::Cpu)?;
        let pool =
            Tensor::from_slice(&self.fakes.data, (self.fakes.len(), self.fakes.window, self.fakes.dim), &Device::Cpu)?;
        ck::write_tensors(
            &dir.join(HISTORY_FILE),
            &HashMap::from([("history".to_string(), hist), ("fakes".to_string(), pool)]),
        )?;
        let state = AdversarialState {
            rng: self.rng.state(),
            refiner_updates: self.k,
            collapse_count: self.collapse_count,
            warmed_up: self.warmed_up,
            rounds: self.rounds,
            last_discriminator_loss: self.last_d,
        };
        Ok(ck::write_json(&dir.join(ADVERSARIAL_FILE), &state)?)
    }

    /// Restores the weights and the training state written by [`AdversarialTrainer::save`] and
    /// [`AdversarialTrainer::save_training_state`].
    pub fn load_training_state(&mut self, dir: &Path) -> RnnGmmResult<()> {
        ck::read_varmap(&dir.join(REFINER_FILE), &self.r_varmap)?;
        ck::read_varmap(&dir.join(DISCRIMINATOR_FILE), &self.d_varmap)?;
        for (file, opt) in [(REFINER_OPTIMIZER_FILE, &mut self.opt_r), (DISCRIMINATOR_OPTIMIZER_FILE, &mut self.opt_d)]
        {
            let path = dir.join(file);
            opt.set_state(&ck::read_tensors(&path, &self.device)?)
                .map_err(|e| RnnGmmError::Config(format!("{}: {e}", path.display())))?;
        }
        let path = dir.join(HISTORY_FILE);
        let hist = ck::read_tensors(&path, &Device::Cpu)?;
        let history = hist
            .get("history")
            .map(|t| t.flatten_all().and_then(|t| t.to_vec1::<f32>()))
            .transpose()?
            .filter(|h| h.len() == self.history.len())
            .ok_or_else(|| {
                RnnGmmError::Config(format!(
                    "{}: no `history` tensor of {} values (another history size?)",
                    path.display(),
                    self.history.len()
                ))
            })?;
        self.history = history;
        // The fake pool changes when fresh fakes are drawn; runs written before it was saved
        // kept their pool fixed, which the constructor has sampled again.
        if let Some(pool) = hist.get("fakes") {
            let pool = pool.flatten_all()?.to_vec1::<f32>()?;
            if pool.len() != self.fakes.data.len() {
                return Err(RnnGmmError::Config(format!(
                    "{}: a fake pool of {} values, this run has {} (another fake_windows?)",
                    path.display(),
                    pool.len(),
                    self.fakes.data.len()
                )));
            }
            self.fakes.data = pool;
        }
        let s: AdversarialState = ck::read_json(&dir.join(ADVERSARIAL_FILE))?;
        self.rng = SplitMix64::from_state(s.rng);
        self.k = s.refiner_updates.clamp(1, self.config.refiner.max_refiner_updates);
        self.collapse_count = s.collapse_count;
        self.warmed_up = s.warmed_up;
        self.rounds = s.rounds;
        self.last_d = s.last_discriminator_loss;
        Ok(())
    }
}

/// An [`AdversarialTrainer`] with its real windows, for the shared training loop: each
/// `train_step` is one round ([`AdversarialTrainer::round`]) whose discriminator sees the batch's
/// real windows; the tracked loss is the refiner's; validation is the refiner's loss on fixed
/// generator samples; both optimisers, the history buffer and the counters are saved.
pub struct AdversarialTraining<'a> {
    trainer: AdversarialTrainer,
    real: &'a Windows,
    rounds_per_epoch: Option<usize>,
}

impl<'a> AdversarialTraining<'a> {
    /// Trains on the real windows `real` (those the trainer was built with); an epoch is one
    /// pass over them (`real.len() / batch` rounds).
    pub fn new(trainer: AdversarialTrainer, real: &'a Windows) -> Self {
        AdversarialTraining { trainer, real, rounds_per_epoch: None }
    }

    /// Makes an epoch `rounds` rounds (at least 1) whose real windows are drawn at random from
    /// all of `real` with the trainer's seeded generator (saved with the training state), instead
    /// of one pass over them. A round costs several refiner updates, so a pass over a large set
    /// can take longer than a time limit, which the training loop checks between epochs.
    pub fn with_rounds_per_epoch(mut self, rounds: usize) -> Self {
        self.rounds_per_epoch = Some(rounds.max(1));
        self
    }

    /// The trainer.
    pub fn trainer(&self) -> &AdversarialTrainer {
        &self.trainer
    }
}

impl Trainable for AdversarialTraining<'_> {
    fn train_len(&self) -> usize {
        match self.rounds_per_epoch {
            Some(r) => r * self.trainer.config.refiner.batch,
            None => self.real.len(),
        }
    }

    fn batch_size(&self) -> usize {
        self.trainer.config.refiner.batch
    }

    fn train_step(&mut self, samples: &[usize]) -> std::result::Result<f64, TrainError> {
        if self.rounds_per_epoch.is_some() {
            let idx = self.trainer.draw(samples.len(), self.real.len());
            return Ok(self.trainer.round(self.real, &idx)?);
        }
        Ok(self.trainer.round(self.real, samples)?)
    }

    fn steps(&self) -> u64 {
        self.trainer.opt_r.steps()
    }

    fn validate(&mut self) -> std::result::Result<Validation, TrainError> {
        let (t, f) = (self.trainer.validation_terms()?, self.trainer.training_terms()?);
        Ok(Validation {
            loss: t.measure(self.trainer.config.refiner.lambda),
            averaged: None,
            detail: Some(format!(
                "skate {:.3} range {:.4} root {:.4}, adversarial {:.3}; training fakes: skate {:.3} range {:.4}",
                t.skate, t.range, t.regularisation, t.adversarial, f.skate, f.range
            )),
        })
    }

    fn save_model(&mut self, dir: &Path, _averaged: bool) -> std::result::Result<(), TrainError> {
        Ok(self.trainer.save(dir)?)
    }

    fn save_training_state(&self, dir: &Path) -> std::result::Result<(), TrainError> {
        Ok(self.trainer.save_training_state(dir)?)
    }

    fn load_training_state(&mut self, dir: &Path) -> std::result::Result<(), TrainError> {
        Ok(self.trainer.load_training_state(dir)?)
    }

    fn summary(&self) -> serde_json::Map<String, serde_json::Value> {
        let t = &self.trainer;
        let mut m = serde_json::Map::new();
        m.insert("model".into(), "rnn-gmm".into());
        m.insert("stage".into(), "refiner".into());
        m.insert("refiner_updates_per_round".into(), serde_json::json!(t.k));
        m.insert("rounds".into(), serde_json::json!(t.rounds));
        m.insert("discriminator_updates".into(), serde_json::json!(t.opt_d.steps()));
        m.insert("last_discriminator_loss".into(), serde_json::json!(t.last_d));
        m
    }
}
