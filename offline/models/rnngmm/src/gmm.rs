//! The Gaussian mixture over the next frame (sec. 4.1.2, eq. 6-8): mixture parameters from the
//! network output, the negative log-likelihood by log-sum-exp, and seeded sampling with a
//! temperature.
//!
//! Head layout (per frame, `M` components, `D` values): `M` weight logits `w^`, then `M * D`
//! means `mu` (component-major), then `M * D` log standard deviations `sigma^`. Eq. 7:
//! `w = softmax(w^)`, `mu = mu^`, `sigma = exp(sigma^)`, with `sigma^` clamped to
//! `[min_log_std, max_log_std]` (see [`crate::Config::min_log_std`]).
//!
//! NLL of a frame `x` (eq. 8): `-log sum_i exp(log w_i + sum_j log N(x_j | mu_ij, sigma_ij))`,
//! `log N = -((x - mu) / sigma)^2 / 2 - log sigma - log(2 pi) / 2`, computed as a log-sum-exp
//! (the largest term taken out), so neither huge logits nor far-away components overflow.

use crate::error::{RnnGmmError, RnnGmmResult};
use candle_core::{D, Result, Tensor};
use zoo_motion::rng::SplitMix64;

/// `log(2 pi) / 2`.
const HALF_LOG_TAU: f64 = 0.918_938_533_204_672_8;

/// The mixture parameters of a batch of frames as tensors: `log_weights` `(.., M)`, `means` and
/// `log_stds` `(.., M, D)`.
#[derive(Clone, Debug)]
pub struct MixtureTensors {
    /// `log w` (log-softmax of the logits).
    pub log_weights: Tensor,
    /// `mu`.
    pub means: Tensor,
    /// `log sigma`, clamped.
    pub log_stds: Tensor,
}

/// Splits head outputs `(.., M (1 + 2 D))` into mixture parameters (eq. 7).
pub fn split_head(raw: &Tensor, m: usize, d: usize, min_log_std: f64, max_log_std: f64) -> Result<MixtureTensors> {
    let last = raw.dims().len() - 1;
    let lead: Vec<usize> = raw.dims()[..last].to_vec();
    if raw.dim(last)? != m * (1 + 2 * d) {
        candle_core::bail!(
            "mixture head: expected {} values per frame (M = {m}, D = {d}), found {}",
            m * (1 + 2 * d),
            raw.dim(last)?
        )
    }
    let shape_md: Vec<usize> = lead.iter().copied().chain([m, d]).collect();
    let logits = raw.narrow(last, 0, m)?;
    let log_weights = candle_nn::ops::log_softmax(&logits, D::Minus1)?;
    let means = raw.narrow(last, m, m * d)?.reshape(shape_md.as_slice())?;
    let log_stds = raw.narrow(last, m + m * d, m * d)?.reshape(shape_md.as_slice())?.clamp(min_log_std, max_log_std)?;
    Ok(MixtureTensors { log_weights, means, log_stds })
}

/// Log-sum-exp over the last dimension (the maximum taken out first; it is detached, which does
/// not change the gradient).
pub fn log_sum_exp(x: &Tensor) -> Result<Tensor> {
    let max = x.max_keepdim(D::Minus1)?.detach();
    let shifted = x.broadcast_sub(&max)?;
    shifted.exp()?.sum_keepdim(D::Minus1)?.log()?.add(&max)?.squeeze(D::Minus1)
}

/// Negative log-likelihood (eq. 8) of `target` `(.., D)` under the mixture: `(..)`, one value per frame.
pub fn nll(mix: &MixtureTensors, target: &Tensor) -> Result<Tensor> {
    let z = target.unsqueeze(D::Minus2)?.broadcast_sub(&mix.means)?.broadcast_mul(&mix.log_stds.neg()?.exp()?)?;
    let log_n = ((z.sqr()? * -0.5)? - &mix.log_stds)?.sum(D::Minus1)?; // (.., M), without the constant
    let d = target.dim(D::Minus1)? as f64;
    let lse = log_sum_exp(&(mix.log_weights.clone() + log_n)?)?;
    (lse.neg()? + d * HALF_LOG_TAU)?.contiguous()
}

/// One frame's mixture, in plain numbers (for sampling and for checks): `M` weights summing to
/// 1, `M * D` means and standard deviations, component-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Mixture {
    /// Values per frame `D`.
    pub dim: usize,
    /// Component weights `w` (eq. 7).
    pub weights: Vec<f64>,
    /// Means `mu`, `M * D`.
    pub means: Vec<f64>,
    /// Standard deviations `sigma`, `M * D`.
    pub stds: Vec<f64>,
}

impl Mixture {
    /// The mixture of one frame's head outputs (`M (1 + 2 D)` values, see the module docs).
    pub fn from_head(raw: &[f32], m: usize, d: usize, min_log_std: f64, max_log_std: f64) -> RnnGmmResult<Self> {
        if m == 0 || raw.len() != m * (1 + 2 * d) {
            return Err(RnnGmmError::Size {
                what: "mixture head outputs".into(),
                expected: m * (1 + 2 * d),
                detail: format!("M (1 + 2 D) with M = {m}, D = {d}"),
                found: raw.len(),
            });
        }
        if let Some(i) = raw.iter().position(|v| !v.is_finite()) {
            return Err(RnnGmmError::Config(format!(
                "mixture head output {i} is {}: the network produced NaN/inf (diverged weights?)",
                raw[i]
            )));
        }
        let logits: Vec<f64> = raw[..m].iter().map(|&v| v as f64).collect();
        let max = logits.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let e: Vec<f64> = logits.iter().map(|l| (l - max).exp()).collect();
        let total: f64 = e.iter().sum();
        Ok(Mixture {
            dim: d,
            weights: e.iter().map(|v| v / total).collect(),
            means: raw[m..m + m * d].iter().map(|&v| v as f64).collect(),
            stds: raw[m + m * d..].iter().map(|&v| (v as f64).clamp(min_log_std, max_log_std).exp()).collect(),
        })
    }

    /// Number of components.
    pub fn components(&self) -> usize {
        self.weights.len()
    }

    /// `-log p(x)` by log-sum-exp, in f64.
    pub fn nll(&self, x: &[f32]) -> f64 {
        let d = self.dim;
        let terms: Vec<f64> = (0..self.components())
            .map(|i| {
                let mut s = self.weights[i].ln();
                for j in 0..d {
                    let (mu, sd) = (self.means[i * d + j], self.stds[i * d + j]);
                    let z = (x[j] as f64 - mu) / sd;
                    s += -0.5 * z * z - sd.ln() - HALF_LOG_TAU;
                }
                s
            })
            .collect();
        let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        -(max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln())
    }

    /// Mean of each value: `sum_i w_i mu_i`.
    pub fn mean(&self) -> Vec<f64> {
        let d = self.dim;
        (0..d).map(|j| (0..self.components()).map(|i| self.weights[i] * self.means[i * d + j]).sum()).collect()
    }

    /// Standard deviation of each value with the component deviations scaled by `temperature`:
    /// `sqrt(sum_i w_i ((t sigma_i)^2 + mu_i^2) - mean^2)`.
    pub fn std(&self, temperature: f64) -> Vec<f64> {
        let d = self.dim;
        let mean = self.mean();
        (0..d)
            .map(|j| {
                let second: f64 = (0..self.components())
                    .map(|i| {
                        let (mu, sd) = (self.means[i * d + j], temperature * self.stds[i * d + j]);
                        self.weights[i] * (sd * sd + mu * mu)
                    })
                    .sum();
                (second - mean[j] * mean[j]).max(0.0).sqrt()
            })
            .collect()
    }

    /// Draws one frame into `out` (`D` values): a component by its weight, then
    /// `mu + temperature * sigma * n` with `n` standard normal (temperature 0: the chosen
    /// component's mean). Draws `1 + D` numbers from `rng`.
    pub fn sample(&self, rng: &mut SplitMix64, temperature: f64, out: &mut [f32]) {
        let d = self.dim;
        let u = rng.next_f64();
        let mut acc = 0.0;
        let mut k = self.components() - 1;
        for (i, w) in self.weights.iter().enumerate() {
            acc += w;
            if u < acc {
                k = i;
                break;
            }
        }
        for j in 0..d {
            let n = rng.normal();
            out[j] = (self.means[k * d + j] + temperature * self.stds[k * d + j] * n) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    /// Head outputs of a 2-component mixture in 2 dimensions.
    fn head(logits: [f32; 2], means: [f32; 4], log_stds: [f32; 4]) -> Vec<f32> {
        logits.iter().chain(&means).chain(&log_stds).copied().collect()
    }

    fn candle_nll(raw: &[f32], m: usize, d: usize, x: &[f32]) -> f32 {
        let dev = Device::Cpu;
        let raw = Tensor::from_slice(raw, (1, raw.len()), &dev).unwrap();
        let x = Tensor::from_slice(x, (1, d), &dev).unwrap();
        let mix = split_head(&raw, m, d, -5.0, 5.0).unwrap();
        nll(&mix, &x).unwrap().to_vec1::<f32>().unwrap()[0]
    }

    #[test]
    fn nll_matches_a_hand_computation() {
        // w = softmax(0, ln 3) = (1/4, 3/4); component 0: N(0, 1) x N(1, 2); component 1:
        // N(2, 1/2) x N(0, 1); x = (1, 1).
        let raw = head([0.0, 3f32.ln()], [0.0, 1.0, 2.0, 0.0], [0.0, 2f32.ln(), 0.5f32.ln(), 0.0]);
        let x = [1.0f32, 1.0];
        let n =
            |x: f64, mu: f64, s: f64| (-(x - mu).powi(2) / (2.0 * s * s)).exp() / (s * std::f64::consts::TAU.sqrt());
        let p = 0.25 * n(1.0, 0.0, 1.0) * n(1.0, 1.0, 2.0) + 0.75 * n(1.0, 2.0, 0.5) * n(1.0, 0.0, 1.0);
        let expected = -p.ln(); // 2.9470...
        let mix = Mixture::from_head(&raw, 2, 2, -5.0, 5.0).unwrap();
        assert!((mix.weights[0] - 0.25).abs() < 1e-7 && (mix.stds[1] - 2.0).abs() < 1e-6);
        assert!((mix.nll(&x) - expected).abs() < 1e-6, "{} vs {expected}", mix.nll(&x));
        assert!((candle_nll(&raw, 2, 2, &x) as f64 - expected).abs() < 1e-5);
    }

    #[test]
    fn extreme_values_stay_finite() {
        // Logits far beyond exp's f32 range, log stds far below the floor, and a target 200
        // floored standard deviations from every mean in every dimension: exp of each
        // component's log-density underflows to 0, so a direct sum would give -log 0 = inf.
        let d = 8;
        let m = 3;
        let mut raw = vec![500.0f32, -500.0, 499.0];
        raw.extend(std::iter::repeat_n(0.0f32, m * d));
        raw.extend(std::iter::repeat_n(-1e4f32, m * d));
        let x = vec![200.0 * (-5f32).exp(); d];
        let mix = Mixture::from_head(&raw, m, d, -5.0, 5.0).unwrap();
        let expected = mix.nll(&x);
        assert!(expected.is_finite() && expected > 1e4, "{expected}");
        // Every component has the same density and the weights sum to 1, so
        // NLL = D (z^2 / 2 + log sigma + log(2 pi) / 2) with z = 200, log sigma = -5.
        let by_hand = d as f64 * (0.5 * 200.0 * 200.0 - 5.0 + HALF_LOG_TAU);
        assert!((expected - by_hand).abs() / by_hand < 1e-6, "{expected} vs {by_hand}");
        let got = candle_nll(&raw, m, d, &x);
        assert!(got.is_finite() && ((got as f64 - expected) / expected).abs() < 1e-5, "{got} vs {expected}");
        // Huge log stds are clamped too.
        let mut raw2 = raw.clone();
        for v in &mut raw2[m + m * d..] {
            *v = 1e4;
        }
        assert!(candle_nll(&raw2, m, d, &x).is_finite());
        assert!(Mixture::from_head(&[f32::NAN; 3 * 17], 3, 8, -5.0, 5.0).is_err());
        assert!(Mixture::from_head(&[0.0; 10], 3, 8, -5.0, 5.0).is_err());
    }

    #[test]
    fn gradients_of_the_nll_are_finite_for_extreme_values() {
        let dev = Device::Cpu;
        let raw = candle_core::Var::from_vec(vec![500.0f32, -500.0, 30.0, -40.0, -1e4, 1e4], (1, 6), &dev).unwrap();
        let x = Tensor::new(&[[1e3f32]], &dev).unwrap();
        let mix = split_head(raw.as_tensor(), 2, 1, -5.0, 5.0).unwrap();
        let loss = nll(&mix, &x).unwrap().sum_all().unwrap();
        let grads = loss.backward().unwrap();
        let g = grads.get(&raw).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(g.iter().all(|v| v.is_finite()), "{g:?}");
    }

    #[test]
    fn the_same_seed_gives_the_same_samples() {
        let raw = head([0.3, -0.2], [0.0, 1.0, 2.0, -1.0], [0.0, -1.0, -0.5, 0.2]);
        let mix = Mixture::from_head(&raw, 2, 2, -5.0, 5.0).unwrap();
        let draw = |seed: u64| {
            let mut rng = SplitMix64::new(seed);
            let mut out = vec![0f32; 2 * 50];
            for f in out.chunks_exact_mut(2) {
                mix.sample(&mut rng, 1.0, f);
            }
            out
        };
        assert_eq!(draw(11), draw(11));
        assert_ne!(draw(11), draw(12));
    }

    #[test]
    fn sample_moments_match_the_mixture() {
        let raw = head([0.0, 1.0], [0.0, 1.0, 3.0, -2.0], [0.0, -1.0, -0.5, 0.5]);
        let mix = Mixture::from_head(&raw, 2, 2, -5.0, 5.0).unwrap();
        for temperature in [1.0, 0.5] {
            let mut rng = SplitMix64::new(5);
            let n = 200_000;
            let (mut s, mut sq) = ([0f64; 2], [0f64; 2]);
            let mut out = [0f32; 2];
            for _ in 0..n {
                mix.sample(&mut rng, temperature, &mut out);
                for j in 0..2 {
                    s[j] += out[j] as f64;
                    sq[j] += (out[j] as f64).powi(2);
                }
            }
            let (mean, std) = (mix.mean(), mix.std(temperature));
            for j in 0..2 {
                let m = s[j] / n as f64;
                let sd = (sq[j] / n as f64 - m * m).sqrt();
                // Standard error of the mean: std / sqrt(n) ~ 0.004; allow 5 of them.
                assert!(
                    (m - mean[j]).abs() < 5.0 * std[j] / (n as f64).sqrt(),
                    "t {temperature} dim {j}: mean {m} vs {}",
                    mean[j]
                );
                assert!((sd - std[j]).abs() < 0.01 * std[j], "t {temperature} dim {j}: std {sd} vs {}", std[j]);
            }
        }
        // Temperature 0 gives component means only.
        let mut rng = SplitMix64::new(1);
        let mut out = [0f32; 2];
        mix.sample(&mut rng, 0.0, &mut out);
        assert!(out == [0.0, 1.0] || out == [3.0, -2.0], "{out:?}");
    }
}
