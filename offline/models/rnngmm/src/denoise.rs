//! Motion denoising by MAP optimisation through the trained generator (sec. 5.4, eq. 24-25, with
//! the prior of eq. 15-16 and the contact term of eq. 18).
//!
//! The unknowns are the clean state features `s` of every frame and the network noise `d` added
//! to the generator's inputs (normalised units). The energy, minimised by L-BFGS (`argmin`, More-
//! Thuente line search) with gradients by backpropagation through the unrolled generator:
//!
//! - prior (eq. 15): the mixture NLL of every frame given the frames before it, the generator
//!   reading `s + d`. The clip is cut into windows of the training length (50 frames) every half
//!   window, each run from the zero state as in training; a frame's NLL is taken from the first
//!   window that sees it with half a window of history (all frames of the first window);
//! - noise prior (eq. 16): `|d|^2 / (2 sigma_noise^2)`, `sigma_noise` = 0.05;
//! - data (eq. 25): the root position (accumulated from `dtx, dtz, dry` as in eq. 4, height
//!   `ty`) against the input's, and every joint angle (root tilt and rotation vectors) against
//!   the input's, each over `2 sigma^2`. Per frame the Gaussian term `q / 2` becomes the
//!   pseudo-Huber `2 n (sqrt(1 + q / 2n) - 1)` (`n` values in the frame), equal to `q / 2` for
//!   ordinary noise and growing like `sqrt(q)` for an outlier pose, so that a glitched frame does
//!   not pull its neighbours (the paper's Gaussian would);
//! - contact (eq. 18): for frames where the input's foot is planted (the feature's contact
//!   rule), each foot joint's displacement since the previous frame over `sigma_contact^2`, and
//!   its height above its ground level (5th percentile of its height in the input) over
//!   `sigma_plane^2`.
//!
//! Without given noise levels, `sigma_root` and `sigma_angle` are estimated from the input: the
//! median absolute second difference of the values (white noise of standard deviation `s` has
//! second differences of standard deviation `sqrt(6) s`), floored at 0.2 clip units and 0.25
//! degrees.

use crate::checkpoint::LoadedGenerator;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{CONTACT_DIMS, DecodedMotion, ROOT_DIMS};
use crate::fk::TensorFk;
use crate::gmm;
use candle_core::{DType, Device, Tensor};
use std::cell::RefCell;
use zoo_motion::Clip;

/// Settings of [`denoise`].
#[derive(Clone, Debug, PartialEq)]
pub struct DenoiseOptions {
    /// Standard deviation of the root-position noise (clip units); `None`: estimated from the input.
    pub sigma_root: Option<f64>,
    /// Standard deviation of the joint-angle noise (radians); `None`: estimated from the input.
    pub sigma_angle: Option<f64>,
    /// Standard deviation of the network noise prior (eq. 16; normalised units).
    pub sigma_noise: f64,
    /// Standard deviation of a planted foot joint's displacement per frame (clip units).
    pub sigma_contact: f64,
    /// Standard deviation of a planted foot joint's height above its ground level (clip units).
    pub sigma_plane: f64,
    /// L-BFGS iterations at most.
    pub iterations: usize,
    /// Frames per prior window (the generator's training window).
    pub window: usize,
    /// Weight of the prior terms (eq. 15-16; 1 is the paper's MAP).
    pub prior_weight: f64,
    /// Start the optimisation from the input smoothed by a Savitzky-Golay filter of this
    /// window (odd frames, order 2) instead of the raw input; `None`: the raw input.
    pub init_savgol: Option<usize>,
}

impl Default for DenoiseOptions {
    /// Noise levels estimated; the paper's `sigma_noise` 0.05; 1 cm per frame and 2 cm for the
    /// contact term; 60 iterations; windows of 50 frames.
    fn default() -> Self {
        DenoiseOptions {
            sigma_root: None,
            sigma_angle: None,
            sigma_noise: 0.05,
            sigma_contact: 1.0,
            sigma_plane: 2.0,
            iterations: 60,
            window: 50,
            prior_weight: 1.0,
            init_savgol: None,
        }
    }
}

impl DenoiseOptions {
    fn validate(&self) -> RnnGmmResult<()> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(RnnGmmError::Config(format!("{name} must be positive and finite, found {v}")))
            }
        };
        positive("the root noise level", self.sigma_root.unwrap_or(1.0))?;
        positive("the joint-angle noise level", self.sigma_angle.unwrap_or(1.0))?;
        positive("the network noise level", self.sigma_noise)?;
        positive("the contact displacement level", self.sigma_contact)?;
        positive("the contact height level", self.sigma_plane)?;
        positive("the prior weight", self.prior_weight)?;
        if let Some(w) = self.init_savgol
            && (w.is_multiple_of(2) || w < 5)
        {
            return Err(RnnGmmError::Config(format!("the starting filter's window must be odd and >= 5, found {w}")));
        }
        if self.window < 4 {
            return Err(RnnGmmError::Config(format!("prior windows need at least 4 frames, found {}", self.window)));
        }
        Ok(())
    }
}

/// The terms of the denoising energy (sums over the clip).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyTerms {
    /// Mixture NLL of the frames (eq. 15).
    pub prior: f64,
    /// Network-noise prior (eq. 16).
    pub noise: f64,
    /// Root and joint-angle fit to the input (eq. 25, robust per frame).
    pub data: f64,
    /// Planted feet: displacement and height (eq. 18).
    pub contact: f64,
}

/// What [`denoise`] made and how.
#[derive(Clone, Debug)]
pub struct Denoised {
    /// The denoised motion (placed where the input starts) and its contact labels.
    pub motion: DecodedMotion,
    /// The root noise level used (clip units).
    pub sigma_root: f64,
    /// The joint-angle noise level used (radians).
    pub sigma_angle: f64,
    /// Energy terms of the starting point (the input, or its smoothed version with
    /// `init_savgol`; `d` = 0) and of the result.
    pub energy: (EnergyTerms, EnergyTerms),
    /// L-BFGS iterations made.
    pub iterations: u64,
}

/// Median of `|x|` over `values` (NaN when empty).
fn median_abs(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.iter_mut().for_each(|v| *v = v.abs());
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Noise level of `series` (each a value over frames) from their second differences.
fn estimate_level(series: &[Vec<f64>]) -> f64 {
    let diffs: Vec<f64> = series.iter().flat_map(|s| s.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0])).collect();
    1.4826 * median_abs(diffs) / 6f64.sqrt()
}

/// The denoising energy of the states `s` and the network noise `d`.
struct Problem<'a> {
    g: &'a LoadedGenerator,
    fk: TensorFk,
    frames: usize,
    dim: usize,
    /// Window start frames and, per window, a `(window - 1)` mask of the targets it scores.
    in_index: Tensor,
    target_index: Tensor,
    target_mask: Tensor,
    windows: usize,
    window: usize,
    /// Input root trajectory `(1, T, 3)` and angle values `(1, T, n)` (clip units).
    root: Tensor,
    angles: Tensor,
    sigma_root: f64,
    sigma_angle: f64,
    sigma_noise: f64,
    prior_weight: f64,
    /// Contact weights `(1, T, F)` of the foot joints (0 or 1), and their ground heights `(F)`.
    planted: Tensor,
    ground: Tensor,
    sigma_contact: f64,
    sigma_plane: f64,
}

/// Pseudo-Huber of per-frame squared norms `q` `(1, T)` with `n` values per frame: `2n (sqrt(1 +
/// q / 2n) - 1)`, summed.
fn pseudo_huber(q: &Tensor, n: usize) -> candle_core::Result<Tensor> {
    let two_n = 2.0 * n as f64;
    ((((q / two_n)? + 1.0)?.sqrt()? - 1.0)? * two_n)?.sum_all()
}

impl Problem<'_> {
    /// The energy of `[s; d]` as a tensor, with `s` and `d` `(T, D)`.
    fn energy(&self, s: &Tensor, d: &Tensor) -> candle_core::Result<Tensor> {
        let [a, b, c, e] = self.terms(s, d)?;
        ((a + b)? * self.prior_weight)? + c + e
    }

    /// The energy's terms: prior, noise prior, data, contact.
    fn terms(&self, s: &Tensor, d: &Tensor) -> candle_core::Result<[Tensor; 4]> {
        let (t, dim, w) = (self.frames, self.dim, self.window);
        let g = &self.g.generator;
        // Prior (eq. 15) over the windows, reading s + d.
        let noisy = (s + d)?;
        let inputs = noisy.index_select(&self.in_index, 0)?.reshape((self.windows, w - 1, dim))?;
        let targets = s.index_select(&self.target_index, 0)?.reshape((self.windows, w - 1, dim))?;
        let (raw, _) = g.forward_seq(&inputs, &g.zero_state(self.windows)?)?;
        let nll = gmm::nll(&g.mixture(&raw)?, &targets)?;
        let prior = (nll * &self.target_mask)?.sum_all()?;
        // Noise prior (eq. 16).
        let noise = (d.sqr()?.sum_all()? / (2.0 * self.sigma_noise * self.sigma_noise))?;
        // Data (eq. 25), robust per frame.
        let x = s.unsqueeze(0)?; // (1, T, D)
        let root = self.fk.root_trajectory(&x)?;
        let q_root = ((root - &self.root)? / self.sigma_root)?.sqr()?.sum(2)?;
        let raw_x = self.fk.denormalize(&x)?;
        let angles = raw_x.narrow(2, ROOT_DIMS - 2, dim - CONTACT_DIMS - (ROOT_DIMS - 2))?;
        let n_angles = angles.dim(2)?;
        let q_angle = ((angles - &self.angles)? / self.sigma_angle)?.sqr()?.sum(2)?;
        let data = (pseudo_huber(&q_root, 3)? + pseudo_huber(&q_angle, n_angles)?)?;
        // Contact (eq. 18): planted feet stay put and on their ground.
        let feet = self.fk.effector_features(&x)?; // (1, T, 6F): positions, then velocities
        let f = self.fk.effector_count();
        let pos = feet.narrow(2, 0, 3 * f)?.reshape((1, t, f, 3))?;
        let vel = feet.narrow(2, 3 * f, 3 * f)?.reshape((1, t, f, 3))?;
        let slide = (vel.sqr()?.sum(3)? * &self.planted)?.sum_all()? / (self.sigma_contact * self.sigma_contact);
        let height = pos.narrow(3, 1, 1)?.squeeze(3)?.broadcast_sub(&self.ground)?;
        let plane = (height.sqr()? * &self.planted)?.sum_all()? / (self.sigma_plane * self.sigma_plane);
        Ok([prior, noise, data, (slide? + plane?)?])
    }

    /// The terms at `p` as numbers.
    fn term_values(&self, p: &[f64]) -> candle_core::Result<EnergyTerms> {
        let (s, d) = self.split(p)?;
        let t = self.terms(&s, &d)?;
        let v = |x: &Tensor| -> candle_core::Result<f64> { x.to_dtype(DType::F64)?.to_scalar::<f64>() };
        Ok(EnergyTerms { prior: v(&t[0])?, noise: v(&t[1])?, data: v(&t[2])?, contact: v(&t[3])? })
    }

    fn split(&self, p: &[f64]) -> candle_core::Result<(Tensor, Tensor)> {
        let n = self.frames * self.dim;
        let dev = self.g.generator.device();
        let s: Vec<f32> = p[..n].iter().map(|v| *v as f32).collect();
        let d: Vec<f32> = p[n..].iter().map(|v| *v as f32).collect();
        Ok((Tensor::from_vec(s, (self.frames, self.dim), dev)?, Tensor::from_vec(d, (self.frames, self.dim), dev)?))
    }
}

/// The prior's windows over `t` frames: the training length `w` every half window, the last one
/// ending at the clip's end; per window frame the input and target frame indices, and a mask
/// that scores each frame's NLL once (with enough history).
fn prior_windows(t: usize, w: usize) -> (Vec<usize>, Vec<u32>, Vec<u32>, Vec<f32>) {
    let half = (w / 2).max(1);
    let mut starts: Vec<usize> = (0..).map(|k| k * half).take_while(|s| s + w < t).collect();
    if starts.last().is_none_or(|s| s + w < t) {
        starts.push(t - w);
    }
    let (mut in_index, mut target_index, mut mask) = (Vec::new(), Vec::new(), Vec::new());
    let mut scored = 0usize; // frames 1..=scored have their NLL
    for &s in &starts {
        for k in 0..w - 1 {
            in_index.push((s + k) as u32);
            let f = s + k + 1;
            target_index.push(f as u32);
            let history_ok = s == 0 || k + 1 >= half;
            let new = f > scored && history_ok;
            mask.push(if new { 1f32 } else { 0.0 });
        }
        scored = s + w - 1;
    }
    (starts, in_index, target_index, mask)
}

/// The optimisation's start `[s; d]`: the normalised input `values` (or the input smoothed by
/// the Savitzky-Golay filter of `opts.init_savgol`; a window longer than the clip: the input),
/// and zero noise.
fn initial_values(g: &LoadedGenerator, clip: &Clip, opts: &DenoiseOptions, values: &[f32]) -> RnnGmmResult<Vec<f64>> {
    let (t, dim) = (values.len() / g.spec.dim(), g.spec.dim());
    let mut init: Vec<f64> = match opts.init_savgol.filter(|&w| w <= t) {
        None => values.iter().map(|v| *v as f64).collect(),
        Some(w) => {
            let smooth = crate::noise::savgol(clip, w, 2).map_err(RnnGmmError::Config)?;
            let mut v = g.spec.encode(&smooth)?.values;
            g.norm.normalize(&mut v);
            v.iter().map(|x| *x as f64).collect()
        }
    };
    init.extend(std::iter::repeat_n(0.0, t * dim));
    Ok(init)
}

/// Denoises `clip` (on the model's skeleton, at its frame rate, at least 2 frames) with the
/// trained generator `g`. `progress` is called with the number of energy evaluations so far.
pub fn denoise(
    g: &LoadedGenerator,
    clip: &Clip,
    opts: &DenoiseOptions,
    progress: &mut dyn FnMut(usize),
) -> RnnGmmResult<Denoised> {
    opts.validate()?;
    let (spec, norm) = (&g.spec, &g.norm);
    let enc = spec.encode(clip)?;
    let (t, dim) = (enc.frames(), spec.dim());
    let dev = Device::Cpu;
    // Noise levels: given, or estimated from the input's root trajectory and angles.
    let (_, gp) = clip.global();
    let joints = clip.joints();
    let root_series: Vec<Vec<f64>> = (0..3).map(|a| (0..t).map(|f| gp[f * joints][a]).collect()).collect();
    let angle_range = ROOT_DIMS - 2..dim - CONTACT_DIMS;
    let angle_series: Vec<Vec<f64>> =
        angle_range.clone().map(|i| (0..t).map(|f| enc.frame(f)[i] as f64).collect()).collect();
    let sigma_root = opts.sigma_root.unwrap_or_else(|| estimate_level(&root_series).max(0.2));
    let sigma_angle = opts.sigma_angle.unwrap_or_else(|| estimate_level(&angle_series).max(0.25f64.to_radians()));
    let w = opts.window.min(t);
    let (starts, in_index, target_index, mask) = prior_windows(t, w);
    // Input trajectory and angles (clip units).
    let mut values = enc.values.clone();
    norm.normalize(&mut values);
    let s0 = Tensor::from_slice(&values, (1, t, dim), &dev)?;
    let feet: Vec<usize> = spec.left_foot.iter().chain(&spec.right_foot).copied().collect();
    let fk = TensorFk::new(spec, norm, &feet, &dev)?;
    let root = fk.root_trajectory(&s0)?;
    let angles = fk.denormalize(&s0)?.narrow(2, ROOT_DIMS - 2, angle_range.len())?;
    // Planted feet (the input's contact labels) and ground heights.
    let c = spec.contact_index();
    let mut planted = Vec::with_capacity(t * feet.len());
    for f in 0..t {
        let bits = [enc.frame(f)[c] > 0.5, enc.frame(f)[c + 1] > 0.5];
        planted.extend(spec.left_foot.iter().map(|_| f32::from(u8::from(bits[0]))));
        planted.extend(spec.right_foot.iter().map(|_| f32::from(u8::from(bits[1]))));
    }
    let ground = crate::control::ground_heights(g, clip, &feet, &dev)?;
    let windows = starts.len();
    let in_n = in_index.len();
    let problem = Problem {
        g,
        fk,
        frames: t,
        dim,
        in_index: Tensor::from_vec(in_index, in_n, &dev)?,
        target_index: Tensor::from_vec(target_index, in_n, &dev)?,
        target_mask: Tensor::from_vec(mask, (windows, w - 1), &dev)?,
        windows,
        window: w,
        root,
        angles,
        sigma_root,
        sigma_angle,
        sigma_noise: opts.sigma_noise,
        prior_weight: opts.prior_weight,
        planted: Tensor::from_vec(planted, (1, t, feet.len()), &dev)?,
        ground,
        sigma_contact: opts.sigma_contact,
        sigma_plane: opts.sigma_plane,
    };
    let init = initial_values(g, clip, opts, &values)?;
    let start = problem.term_values(&init)?;
    let total = start.prior + start.noise + start.data + start.contact;
    if !total.is_finite() {
        return Err(RnnGmmError::Motion(format!("the denoising energy of the input is not finite: {start:?}")));
    }
    // L-BFGS (`control::minimise`) over `[s; d]`, `progress` told the evaluations so far.
    let evaluations = std::cell::Cell::new(0usize);
    let progress = RefCell::new(progress);
    let energy = |s: &Tensor, d: &Tensor| -> RnnGmmResult<Tensor> {
        let e = problem.energy(&s.squeeze(0)?, &d.squeeze(0)?)?;
        evaluations.set(evaluations.get() + 1);
        (progress.borrow_mut())(evaluations.get());
        Ok(e)
    };
    let (best, iterations) =
        crate::control::minimise(&energy, init, t, dim, &dev, opts.iterations as u64, "denoising")?;
    let end = problem.term_values(&best)?;
    let out: Vec<f32> = best[..t * dim].iter().map(|v| *v as f32).collect();
    let mut out = out;
    norm.denormalize(&mut out);
    let motion = spec.decode(&out, enc.origin)?;
    Ok(Denoised { motion, sigma_root, sigma_angle, energy: (start, end), iterations })
}
