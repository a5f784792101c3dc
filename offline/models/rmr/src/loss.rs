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
//!
//! Two terms of ours, off in the paper's loss (weights [`Config::lambda_fk`],
//! [`Config::lambda_slide`]), on the motion the decoded output is made of (its rotations):
//! - `L_fk`: `|norm(FK(q_out, p_out,hips)) - p_gt|_1` over the lower-body joints but the hips:
//!   their positions in the frame's ground root by forward kinematics of the output's
//!   (normalised) local rotations from its hips position, normalised like `p`, against the
//!   ground truth's `p`;
//! - `L_slide`: on the frames `t >= 1` where the ground truth has a contact at `t - 1` and `t`,
//!   the horizontal displacement (cm) of that contact joint from `t - 1` to `t`, by forward
//!   kinematics and the output's root displacement `r_t`, summed over the four contacts and
//!   averaged over frames and the batch.
//!
//! And one on the normalised pose values (weight [`Config::lambda_velocity`], 0 in the paper's):
//! - `L_vel`: `|(x_out,t - x_out,t-1) - (x_gt,t - x_gt,t-1)|_1` over `r, p, q, v` for `t >= 1`,
//!   weighted per frame like `L_pose` (the seam weights), averaged over frames and the batch.

use crate::config::Config;
use crate::error::RmrResult;
use crate::features::{FeatureLayout, FeatureStats};
use candle_core::{D, Device, Tensor};

/// `|x|` whose gradient at `x = 0` is 0 (the subgradient PyTorch's `abs` takes), where
/// candle's `abs` takes +1. A residual model starts with its output equal to the input, so
/// exactly equal to the ground truth on the copied segment A, on the root displacements copied
/// from the ground truth, and to the input in `L_begin`: with candle's `abs` every such value
/// pushes its output down at every step, with this one the identity is a stationary point
/// there. (`sign` has no gradient in candle, so the product's gradient is `sign(x)`.)
pub fn abs0(x: &Tensor) -> candle_core::Result<Tensor> {
    x * x.sign()?.detach()
}

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
    /// `L_fk` (0 unless its weight is positive).
    pub fk: Tensor,
    /// `L_slide` (0 unless its weight is positive).
    pub slide: Tensor,
    /// `L_vel` (0 unless its weight is positive).
    pub velocity: Tensor,
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
    /// `L_fk`.
    pub fk: f64,
    /// `L_slide`.
    pub slide: f64,
    /// `L_vel`.
    pub velocity: f64,
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
            fk: v(&self.fk)?,
            slide: v(&self.slide)?,
            velocity: v(&self.velocity)?,
        })
    }
}

/// What the loss needs besides the batches: the feature layout, the statistics of the root
/// displacement and the accumulation matrices.
#[derive(Clone, Debug)]
pub struct Loss {
    fl: FeatureLayout,
    lambda: [f64; 4],
    lambda_velocity: f64,
    t_begin: usize,
    unit: f64,
    root_mean: Tensor,
    root_std: Tensor,
    begin_w: Option<Tensor>,
    kinematics: Option<Kinematics>,
}

/// What `L_fk` and `L_slide` need: the lower body's chain and bone vectors, where each joint's
/// values sit in the pose vector, and the statistics to denormalise them.
#[derive(Clone, Debug)]
struct Kinematics {
    lambda: [f64; 2],
    /// Lower-body joints, parents first: (joint, its `p` slot, parent joint, bone vector `(3)`).
    chain: Vec<(usize, usize, Option<usize>, Tensor)>,
    /// `p` slot of each contact joint.
    contacts: [usize; 4],
    mean: Tensor,
    std: Tensor,
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
        let kinematics = (config.lambda_fk > 0.0 || config.lambda_slide > 0.0)
            .then(|| Kinematics::new(config, stats, device))
            .transpose()?;
        Ok(Loss {
            fl,
            lambda: [config.lambda_pose, config.lambda_trajectory, config.lambda_foot, config.lambda_begin],
            lambda_velocity: config.lambda_velocity,
            t_begin: config.t_begin,
            unit: config.trajectory_unit,
            root_mean,
            root_std,
            begin_w,
            kinematics,
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
            Ok(abs0(&(a - b)?)?.sum(D::Minus1)?.mean_all()?)
        };
        let pose = match frame_weights {
            None => l1(&out.narrow(2, 0, n_pose)?, &target.narrow(2, 0, n_pose)?)?,
            Some(w) => {
                let per_frame = abs0(&(out.narrow(2, 0, n_pose)? - target.narrow(2, 0, n_pose)?)?)?.sum(D::Minus1)?;
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
                let per_frame = abs0(&diff)?.sum_keepdim(D::Minus1)?.broadcast_mul(&w.narrow(1, 0, tb)?)?;
                // (1 / T_begin) sum over frames, mean over the batch
                (per_frame.sum(1)?.mean_all()? / self.t_begin as f64)?
            }
            None => pose.zeros_like()?,
        };
        let [lp, lt, lf, lb] = self.lambda;
        let mut total = ((((&pose * lp)? + (&trajectory * lt)?)? + (&foot * lf)?)? + (&begin * lb)?)?;
        let (fk, slide) = match &self.kinematics {
            Some(k) => {
                let (fk, slide) = k.terms(out, target, self.fl)?;
                total = ((total + (&fk * k.lambda[0])?)? + (&slide * k.lambda[1])?)?;
                (fk, slide)
            }
            None => (pose.zeros_like()?, pose.zeros_like()?),
        };
        let velocity = if self.lambda_velocity > 0.0 {
            let v = velocity_term(&out.narrow(2, 0, n_pose)?, &target.narrow(2, 0, n_pose)?, frame_weights)?;
            total = (total + (&v * self.lambda_velocity)?)?;
            v
        } else {
            pose.zeros_like()?
        };
        Ok(LossTerms { total, pose, trajectory, foot, begin, fk, slide, velocity })
    }
}

/// `L_vel` of pose values `out` and `target` `(batch, frames, values)`: the L1 norm of the
/// difference of their per-frame changes, summed over values, weighted by `frame_weights`
/// `(batch, frames)` at the later frame of each pair (`None`: 1), averaged over the `frames - 1`
/// changes and the batch. 0 for a single frame.
pub fn velocity_term(out: &Tensor, target: &Tensor, frame_weights: Option<&Tensor>) -> RmrResult<Tensor> {
    let frames = out.dim(1)?;
    if frames < 2 {
        return Ok(out.sum_all()?.zeros_like()?);
    }
    let change =
        |x: &Tensor| -> candle_core::Result<Tensor> { x.narrow(1, 1, frames - 1)? - x.narrow(1, 0, frames - 1)? };
    let per_frame = abs0(&(change(out)? - change(target)?)?)?.sum(D::Minus1)?;
    Ok(match frame_weights {
        None => per_frame.mean_all()?,
        Some(w) => (per_frame * w.narrow(1, 1, frames - 1)?)?.mean_all()?,
    })
}

/// Hamilton product of quaternions `(.., 4)` stored `x, y, z, w`.
fn quat_mul(a: &Tensor, b: &Tensor) -> RmrResult<Tensor> {
    let c = |q: &Tensor, i: usize| q.narrow(D::Minus1, i, 1);
    let (ax, ay, az, aw) = (c(a, 0)?, c(a, 1)?, c(a, 2)?, c(a, 3)?);
    let (bx, by, bz, bw) = (c(b, 0)?, c(b, 1)?, c(b, 2)?, c(b, 3)?);
    let x = ((((&aw * &bx)? + (&ax * &bw)?)? + (&ay * &bz)?)? - (&az * &by)?)?;
    let y = ((((&aw * &by)? - (&ax * &bz)?)? + (&ay * &bw)?)? + (&az * &bx)?)?;
    let z = ((((&aw * &bz)? + (&ax * &by)?)? - (&ay * &bx)?)? + (&az * &bw)?)?;
    let w = ((((&aw * &bw)? - (&ax * &bx)?)? - (&ay * &by)?)? - (&az * &bz)?)?;
    Ok(Tensor::cat(&[x, y, z, w], D::Minus1)?)
}

/// A constant vector `v` `(3)` rotated by unit quaternions `q` `(.., 4)`: `(.., 3)`.
fn rotate(q: &Tensor, v: &Tensor) -> RmrResult<Tensor> {
    let u = q.narrow(D::Minus1, 0, 3)?;
    let w = q.narrow(D::Minus1, 3, 1)?;
    let cross = |a: &Tensor, b: &Tensor| -> RmrResult<Tensor> {
        let c = |t: &Tensor, i: usize| t.narrow(D::Minus1, i, 1);
        let (a0, a1, a2, b0, b1, b2) = (c(a, 0)?, c(a, 1)?, c(a, 2)?, c(b, 0)?, c(b, 1)?, c(b, 2)?);
        Ok(Tensor::cat(
            &[((&a1 * &b2)? - (&a2 * &b1)?)?, ((&a2 * &b0)? - (&a0 * &b2)?)?, ((&a0 * &b1)? - (&a1 * &b0)?)?],
            D::Minus1,
        )?)
    };
    let v = v.broadcast_as(u.shape())?.contiguous()?;
    // v' = v + w t + u x t, t = 2 u x v
    let t = (cross(&u, &v)? * 2.0)?;
    Ok(((&v + t.broadcast_mul(&w)?)? + cross(&u, &t)?)?)
}

impl Kinematics {
    fn new(config: &Config, stats: &FeatureStats, device: &Device) -> RmrResult<Kinematics> {
        let lower = &config.layout.lower_body;
        if config.offsets.len() != config.joints {
            return Err(crate::RmrError::Config(format!(
                "the forward-kinematics loss terms need the skeleton's {} offsets, the configuration has {}",
                config.joints,
                config.offsets.len()
            )));
        }
        let slot = |j: usize| lower.iter().position(|&k| k == j);
        // Parents first: the root, then each joint once its parent is placed.
        let mut order: Vec<usize> = Vec::new();
        while order.len() < lower.len() {
            let before = order.len();
            for &j in lower {
                let parent = (config.parents[j] >= 0).then(|| config.parents[j] as usize);
                let ready = match parent {
                    None => true,
                    Some(p) => order.contains(&p),
                };
                if !order.contains(&j) && ready && (parent.is_none() || slot(parent.unwrap_or(0)).is_some()) {
                    order.push(j);
                }
            }
            if order.len() == before {
                return Err(crate::RmrError::Config(
                    "every lower-body joint's parent must be in the lower body (the forward-kinematics loss walks it from the hips)".into(),
                ));
            }
        }
        let chain = order
            .iter()
            .map(|&j| {
                let o = config.offsets[j];
                let bone = Tensor::from_vec(vec![o[0] as f32, o[1] as f32, o[2] as f32], 3, device)?;
                let parent = (config.parents[j] >= 0).then(|| config.parents[j] as usize);
                Ok((j, slot(j).unwrap_or(0), parent, bone))
            })
            .collect::<RmrResult<Vec<_>>>()?;
        let mut contacts = [0; 4];
        for (c, &j) in contacts.iter_mut().zip(&config.layout.contacts) {
            *c = slot(j).ok_or_else(|| {
                crate::RmrError::Config(format!(
                    "contact joint {j} is not in the lower body (L_slide needs its position)"
                ))
            })?;
        }
        let d = stats.dim();
        Ok(Kinematics {
            lambda: [config.lambda_fk, config.lambda_slide],
            chain,
            contacts,
            mean: Tensor::from_slice(&stats.mean, d, device)?,
            std: Tensor::from_slice(&stats.std, d, device)?,
        })
    }

    /// `(L_fk, L_slide)` of output `out` against ground truth `target` (normalised).
    fn terms(&self, out: &Tensor, target: &Tensor, fl: FeatureLayout) -> RmrResult<(Tensor, Tensor)> {
        let raw = out.broadcast_mul(&self.std)?.broadcast_add(&self.mean)?;
        // Forward kinematics in each frame's ground root: global rotation and position per joint.
        let mut placed: Vec<(usize, Tensor, Tensor)> = Vec::with_capacity(self.chain.len());
        for (j, s, parent, bone) in &self.chain {
            let q = raw.narrow(D::Minus1, fl.rotations() + 4 * j, 4)?;
            let q = q.broadcast_div(&(q.sqr()?.sum_keepdim(D::Minus1)? + 1e-12)?.sqrt()?)?;
            let found = parent.and_then(|p| placed.iter().find(|(k, _, _)| *k == p));
            let (rot, pos) = match found {
                None => (q, raw.narrow(D::Minus1, fl.positions() + 3 * s, 3)?),
                Some((_, prot, ppos)) => (quat_mul(prot, &q)?, (ppos + rotate(prot, bone)?)?),
            };
            placed.push((*j, rot, pos));
        }
        let pos_of = |s: usize| -> RmrResult<&Tensor> {
            let j = self.chain.iter().find(|(_, k, _, _)| *k == s).map(|c| c.0).unwrap_or(usize::MAX);
            placed
                .iter()
                .find(|(k, _, _)| *k == j)
                .map(|(_, _, p)| p)
                .ok_or_else(|| crate::RmrError::Config("internal: joint not placed".into()))
        };
        // L_fk over every lower-body joint but the root, in p's normalisation.
        let mut fk_parts = Vec::new();
        for (_, s, parent, _) in &self.chain {
            if parent.is_none() {
                continue;
            }
            let off = fl.positions() + 3 * s;
            let p = pos_of(*s)?;
            let pn = p.broadcast_sub(&self.mean.narrow(0, off, 3)?)?.broadcast_div(&self.std.narrow(0, off, 3)?)?;
            fk_parts.push(abs0(&(pn - target.narrow(D::Minus1, off, 3)?)?)?.sum(D::Minus1)?);
        }
        let fk = Tensor::stack(&fk_parts, D::Minus1)?.sum(D::Minus1)?.mean_all()?;
        // L_slide: a contact joint's horizontal move from t - 1 to t in root t - 1's frame.
        let frames = out.dim(1)?;
        let r = raw.narrow(D::Minus1, 0, 3)?.narrow(1, 1, frames - 1)?;
        let (dx, dth, dz) = (r.narrow(D::Minus1, 0, 1)?, r.narrow(D::Minus1, 1, 1)?, r.narrow(D::Minus1, 2, 1)?);
        let (c, sn) = (dth.cos()?, dth.sin()?);
        let mut slides = Vec::new();
        for (k, &s) in self.contacts.iter().enumerate() {
            let p = pos_of(s)?;
            let (now, before) = (p.narrow(1, 1, frames - 1)?, p.narrow(1, 0, frames - 1)?);
            let (x, z) = (now.narrow(D::Minus1, 0, 1)?, now.narrow(D::Minus1, 2, 1)?);
            // R(dtheta) p_t + (dx, dz) - p_(t-1), horizontal components
            let mx = ((((&c * &x)? + (&sn * &z)?)? + &dx)? - before.narrow(D::Minus1, 0, 1)?)?;
            let mz = ((((&c * &z)? - (&sn * &x)?)? + &dz)? - before.narrow(D::Minus1, 2, 1)?)?;
            let dist = ((mx.sqr()? + mz.sqr()?)? + 1e-6)?.sqrt()?;
            let ci = fl.contacts() + k;
            let on = (target.narrow(D::Minus1, ci, 1)?.narrow(1, 1, frames - 1)?
                * target.narrow(D::Minus1, ci, 1)?.narrow(1, 0, frames - 1)?)?;
            slides.push((dist * on)?);
        }
        let slide = Tensor::cat(&slides, D::Minus1)?.sum(D::Minus1)?.mean_all()?;
        Ok((fk, slide))
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
