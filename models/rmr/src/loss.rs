//! The training loss of RMR sec. 5.1:
//! `L = l_pose L_pose + l_trj L_trj + l_foot L_foot + l_begin L_begin`.
//!
//! On batches `(batch, frames, dim)` of normalised pose vectors (the output, the input `X` and
//! the ground truth `Y`); every L1 norm sums over the values of a frame and the result is
//! averaged over frames and the batch:
//! - `L_pose`: `|x_out - x_gt|_1` over `r, p, q, v`;
//! - `L_trj`: `|g_out - g_gt|_1`, `g_t = (x, z, theta)` the ground root of frame `t` obtained by
//!   accumulating the denormalised displacements `r_1..r_t` from the identity (frame 0's
//!   displacement is not used), positions divided by [`Config::trajectory_unit`];
//! - `L_foot`: `|sigmoid(c_out) - c_gt|_1`;
//! - `L_begin`: `1/T_begin sum_{t=1..T_begin} sig(t / T_begin) |x_out,t - x_t|_1` over `r, p, q, v`,
//!   against the input, with `sig(x) = 1 - 1 / (1 + exp(5 - 10 x))` (frames counted from 1).

use crate::config::Config;
use crate::error::RmrResult;
use crate::features::{FeatureLayout, FeatureStats};
use candle_core::{D, Device, Tensor};

/// The transformed sigmoid of the beginning loss: `sig(x) = -1 / (1 + exp(5 - 10 x)) + 1`.
pub fn begin_sigmoid(x: f64) -> f64 {
    1.0 - 1.0 / (1.0 + (5.0 - 10.0 * x).exp())
}

/// Weights `sig(t / T_begin)` of frames `t = 1..T_begin`.
pub fn begin_weights(t_begin: usize) -> Vec<f64> {
    (1..=t_begin).map(|t| begin_sigmoid(t as f64 / t_begin as f64)).collect()
}

/// The terms of the loss (unweighted) and the weighted total.
#[derive(Clone, Debug)]
pub struct LossTerms {
    /// Weighted total.
    pub total: Tensor,
    /// `L_pose`.
    pub pose: Tensor,
    /// `L_trj`.
    pub trajectory: Tensor,
    /// `L_foot`.
    pub foot: Tensor,
    /// `L_begin` (0 when `T_begin = 0`).
    pub begin: Tensor,
}

/// The loss terms as numbers.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossValues {
    /// Weighted total.
    pub total: f64,
    /// `L_pose`.
    pub pose: f64,
    /// `L_trj`.
    pub trajectory: f64,
    /// `L_foot`.
    pub foot: f64,
    /// `L_begin`.
    pub begin: f64,
}

impl LossTerms {
    /// The values of the terms.
    pub fn values(&self) -> RmrResult<LossValues> {
        let v = |t: &Tensor| -> RmrResult<f64> { Ok(t.to_scalar::<f32>()? as f64) };
        Ok(LossValues {
            total: v(&self.total)?,
            pose: v(&self.pose)?,
            trajectory: v(&self.trajectory)?,
            foot: v(&self.foot)?,
            begin: v(&self.begin)?,
        })
    }
}

/// What the loss needs besides the batches: the feature layout, the statistics of the root
/// displacement and the accumulation matrices.
#[derive(Clone, Debug)]
pub struct Loss {
    fl: FeatureLayout,
    lambda: [f64; 4],
    t_begin: usize,
    unit: f64,
    root_mean: Tensor,
    root_std: Tensor,
    begin_w: Option<Tensor>,
}

impl Loss {
    /// The loss of `config` with the statistics the batches were normalised with.
    pub fn new(config: &Config, stats: &FeatureStats, device: &Device) -> RmrResult<Loss> {
        let fl = FeatureLayout::new(config.joints, config.layout.lower_body.len());
        let root_mean = Tensor::from_slice(&stats.mean[..3], 3, device)?;
        let root_std = Tensor::from_slice(&stats.std[..3], 3, device)?;
        let begin_w = (config.t_begin > 0)
            .then(|| {
                let w: Vec<f32> = begin_weights(config.t_begin).iter().map(|&w| w as f32).collect();
                Tensor::from_vec(w, (1, config.t_begin, 1), device)
            })
            .transpose()?;
        Ok(Loss {
            fl,
            lambda: [config.lambda_pose, config.lambda_trajectory, config.lambda_foot, config.lambda_begin],
            t_begin: config.t_begin,
            unit: config.trajectory_unit,
            root_mean,
            root_std,
            begin_w,
        })
    }

    /// Ground roots `(batch, frames, 3)` = `(x / unit, z / unit, theta)` accumulated from the
    /// normalised displacements in `xs[..., 0..3]` (`(dx, dtheta, dz)`), frame 0 at the identity.
    pub fn trajectory(&self, xs: &Tensor) -> RmrResult<Tensor> {
        let frames = xs.dim(1)?;
        let r = xs.narrow(D::Minus1, 0, 3)?.broadcast_mul(&self.root_std)?.broadcast_add(&self.root_mean)?;
        // incl[t][s] = 1 for 1 <= s <= t, excl[t][s] = 1 for 1 <= s < t.
        let tri = |strict: bool| -> Vec<f32> {
            (0..frames * frames)
                .map(|i| {
                    let (t, s) = (i / frames, i % frames);
                    (s >= 1 && (s < t || (!strict && s == t))) as u8 as f32
                })
                .collect()
        };
        let dev = xs.device();
        let incl = Tensor::from_vec(tri(false), (frames, frames), dev)?;
        let excl = Tensor::from_vec(tri(true), (frames, frames), dev)?;
        let (dx, dth, dz) = (r.narrow(2, 0, 1)?, r.narrow(2, 1, 1)?, r.narrow(2, 2, 1)?);
        let theta = incl.broadcast_matmul(&dth)?;
        let before = excl.broadcast_matmul(&dth)?;
        let (c, s) = (before.cos()?, before.sin()?);
        // Yaw rotation of the displacement into the world: (x cos + z sin, -x sin + z cos).
        let wx = ((&c * &dx)? + (&s * &dz)?)?;
        let wz = ((&c * &dz)? - (&s * &dx)?)?;
        let x = (incl.broadcast_matmul(&wx)? / self.unit)?;
        let z = (incl.broadcast_matmul(&wz)? / self.unit)?;
        Ok(Tensor::cat(&[x, z, theta], 2)?)
    }

    /// The loss of output `out` for input `input` and ground truth `target`, all
    /// `(batch, frames, dim)` normalised.
    pub fn terms(&self, out: &Tensor, input: &Tensor, target: &Tensor) -> RmrResult<LossTerms> {
        self.terms_weighted(out, input, target, None)
    }

    /// [`Loss::terms`] with per-frame weights `(batch, frames)` on `L_pose` (e.g. from
    /// [`seam_weights`]; `None`: every frame 1, the paper's loss).
    pub fn terms_weighted(
        &self,
        out: &Tensor,
        input: &Tensor,
        target: &Tensor,
        frame_weights: Option<&Tensor>,
    ) -> RmrResult<LossTerms> {
        let n_pose = self.fl.contacts();
        let l1 = |a: &Tensor, b: &Tensor| -> RmrResult<Tensor> {
            // sum over values, mean over frames and batch
            Ok((a - b)?.abs()?.sum(D::Minus1)?.mean_all()?)
        };
        let pose = match frame_weights {
            None => l1(&out.narrow(2, 0, n_pose)?, &target.narrow(2, 0, n_pose)?)?,
            Some(w) => {
                let per_frame = (out.narrow(2, 0, n_pose)? - target.narrow(2, 0, n_pose)?)?.abs()?.sum(D::Minus1)?;
                (per_frame * w)?.mean_all()?
            }
        };
        let trajectory = l1(&self.trajectory(out)?, &self.trajectory(target)?)?;
        let c_out = candle_nn::ops::sigmoid(&out.narrow(2, n_pose, 4)?)?;
        let foot = l1(&c_out, &target.narrow(2, n_pose, 4)?)?;
        let begin = match &self.begin_w {
            Some(w) => {
                let tb = self.t_begin.min(out.dim(1)?);
                let diff =
                    (out.narrow(1, 0, tb)?.narrow(2, 0, n_pose)? - input.narrow(1, 0, tb)?.narrow(2, 0, n_pose)?)?;
                let per_frame = diff.abs()?.sum_keepdim(D::Minus1)?.broadcast_mul(&w.narrow(1, 0, tb)?)?;
                // (1 / T_begin) sum over frames, mean over the batch
                (per_frame.sum(1)?.mean_all()? / self.t_begin as f64)?
            }
            None => pose.zeros_like()?,
        };
        let [lp, lt, lf, lb] = self.lambda;
        let total = ((((&pose * lp)? + (&trajectory * lt)?)? + (&foot * lf)?)? + (&begin * lb)?)?;
        Ok(LossTerms { total, pose, trajectory, foot, begin })
    }
}

/// Per-frame weights `[pair][frame]` of the pose loss: `1 + weight` on the frames within
/// `around` frames of a seam (`|t - s| <= around`), 1 elsewhere.
pub fn seam_weights(seams: &[Vec<usize>], frames: usize, weight: f64, around: usize) -> Vec<f32> {
    let mut w = vec![1.0f32; seams.len() * frames];
    for (p, ss) in seams.iter().enumerate() {
        for &s in ss {
            for t in s.saturating_sub(around)..(s + around + 1).min(frames) {
                w[p * frames + t] = 1.0 + weight as f32;
            }
        }
    }
    w
}
