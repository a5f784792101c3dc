//! What the control applications (sec. 5.2-5.3) share: where the generated motion continues
//! from, and the generator unrolled as a differentiable function of its noise.
//!
//! **Unknowns.** The paper's MAP problems (eq. 14-19) are over the states `s_i` and the
//! network noise `d_i`. Here each state is written through the mixture it is drawn from:
//! `s_i = mu_k + sigma_k * e_i`, `k` the most probable component of frame `i`'s mixture (chosen
//! anew at every evaluation, not differentiated), so the unknowns are the standardised draws
//! `e_i` and the input noise `d_i` (the generator reads `s_i + d_i`, as in training). Every
//! candidate is then a motion the network generates, and the prior of eq. 15 is the exact mixture
//! NLL of each `s_i` given the frames before it (which, with this parametrisation, is `|e_i|^2 / 2`
//! plus the component's log-weight and log-standard-deviations); eq. 16 adds `|d_i|^2 / (2
//! sigma_noise^2)`.
//!
//! **Contact term (eq. 18).** For each foot joint on a frame whose generated contact bit says
//! planted: its displacement since the previous frame (world, root motion included) over
//! `sigma_contact^2`, and its height above its ground level over `sigma_plane^2`.

use crate::checkpoint::LoadedGenerator;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{CONTACT_DIMS, RootPlacement};
use crate::fk::TensorFk;
use crate::gmm;
use crate::initial_state::estimate_initial_state;
use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use candle_core::{D, DType, Device, Tensor, Var};
use std::cell::RefCell;
use zoo_motion::Clip;
use zoo_nn::LstmState;

/// Where generated motion continues from: the generator's state after the last frame, the
/// mixture of the next frame, the last frame itself and the root placement after it.
#[derive(Clone, Debug)]
pub struct ControlStart {
    /// LSTM state (batch 1).
    pub state: LstmState,
    /// Head outputs of the next frame's mixture `(1, M (1 + 2 D))`.
    pub head: Tensor,
    /// The last frame, normalised `(1, 1, D)`.
    pub last: Tensor,
    /// The root placement after the last frame.
    pub placement: RootPlacement,
}

impl ControlStart {
    /// Seeds the generator with `seed_frames` frames of `clip` ending at `frame` (initial state
    /// by eq. 26 with `init_steps` Adam steps, as in synthesis); the motion is placed at
    /// `placement` (the clip's own placement is not kept: control decides where the character
    /// stands).
    pub fn from_clip(
        model: &LoadedGenerator,
        clip: &Clip,
        frame: usize,
        seed_frames: usize,
        init_steps: usize,
        placement: RootPlacement,
    ) -> RnnGmmResult<Self> {
        let (spec, norm, g) = (&model.spec, &model.norm, &model.generator);
        let d = spec.dim();
        if seed_frames < 2 || frame + 1 < seed_frames || frame >= clip.frames() {
            return Err(RnnGmmError::Config(format!(
                "control needs at least 2 seed frames ending at a frame of the start clip: {seed_frames} seed frames \
                 ending at frame {frame} of a {}-frame clip",
                clip.frames()
            )));
        }
        let enc = spec.encode(clip)?;
        let mut seed = enc.values[(frame + 1 - seed_frames) * d..(frame + 1) * d].to_vec();
        norm.normalize(&mut seed);
        let state =
            if init_steps > 0 { estimate_initial_state(g, &seed, init_steps, 0.05)?.state } else { g.zero_state(1)? };
        let xs = Tensor::from_slice(&seed, (1, seed_frames, d), g.device())?;
        let (raw, state) = g.forward_seq(&xs, &state)?;
        Ok(ControlStart {
            state,
            head: raw.narrow(1, seed_frames - 1, 1)?.squeeze(1)?,
            last: xs.narrow(1, seed_frames - 1, 1)?,
            placement,
        })
    }

    /// The start after feeding the generator `inputs` (what it reads, `s + d`, `(1, n, D)`),
    /// whose states are `frames` (`(1, n, D)`, normalised; `raw`: the same in clip units, for the
    /// root placement).
    pub fn advance(
        &self,
        model: &LoadedGenerator,
        inputs: &Tensor,
        frames: &Tensor,
        raw: &[f32],
    ) -> RnnGmmResult<ControlStart> {
        let g = &model.generator;
        let n = inputs.dim(1)?;
        let (out, state) = g.forward_seq(&inputs.detach(), &self.state)?;
        let mut placement = self.placement;
        for x in raw.chunks_exact(model.spec.dim()) {
            placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
        }
        Ok(ControlStart {
            state,
            head: out.narrow(1, n - 1, 1)?.squeeze(1)?.detach(),
            last: frames.narrow(1, n - 1, 1)?.detach(),
            placement,
        })
    }

    /// The mean root displacement per frame of the seed's direction of travel, as the heading
    /// angle (radians, from +z towards +x, in the character's heading frame) and speed (clip
    /// units per frame) of `values` (clip units, frames of `D`).
    pub fn travel_direction(values: &[f32], dim: usize) -> (f64, f64) {
        let n = (values.len() / dim).max(1) as f64;
        let (mut x, mut z) = (0.0, 0.0);
        for f in values.chunks_exact(dim) {
            x += f[0] as f64;
            z += f[1] as f64;
        }
        let (x, z) = (x / n, z / n);
        if x.hypot(z) < 1e-3 { (0.0, 0.0) } else { (x.atan2(z), x.hypot(z)) }
    }
}

/// Frames unrolled from a start: the states `(B, T, D)` (normalised), what the generator read
/// (`s + d`), each frame's mixture NLL `(B, T)` and the components drawn from.
pub struct Rollout {
    /// `s_i`.
    pub states: Tensor,
    /// `s_i + d_i`.
    pub inputs: Tensor,
    /// `-log p(s_i | s_<i)` (eq. 8 with the constant).
    pub nll: Tensor,
    /// The component of each frame `(B, T)` (u32).
    pub components: Tensor,
}

/// Unrolls the generator from `start` for `T` frames: `eps` and `d` `(B, T, D)` (see the module
/// docs). Each frame draws from `components` `(B, T)` (u32) when given, else from its most
/// probable component. Differentiable in `eps` and `d`; with fixed components it is smooth
/// (for L-BFGS: a component that changes between evaluations makes the energy jump).
pub fn rollout(
    model: &LoadedGenerator,
    start: &ControlStart,
    eps: &Tensor,
    d: &Tensor,
    components: Option<&Tensor>,
) -> RnnGmmResult<Rollout> {
    rollout_shifted(model, start, eps, d, components, None)
}

/// [`rollout`] with each state moved by a constant `shift` `(B, T, D)` (normalised units):
/// `s_i = mu_k + sigma_k e_i + shift_i`, the online controller's proposals (its prior is still
/// the exact mixture NLL of the shifted state).
pub fn rollout_shifted(
    model: &LoadedGenerator,
    start: &ControlStart,
    eps: &Tensor,
    d: &Tensor,
    components: Option<&Tensor>,
    shift: Option<&Tensor>,
) -> RnnGmmResult<Rollout> {
    let g = &model.generator;
    let (b, t, dim) = eps.dims3()?;
    let m = g.config().components;
    let mut state = LstmState {
        h: start.state.h.iter().map(|h| h.repeat((b, 1))).collect::<candle_core::Result<_>>()?,
        c: start.state.c.iter().map(|c| c.repeat((b, 1))).collect::<candle_core::Result<_>>()?,
    };
    let mut head = start.head.repeat((b, 1))?;
    let (mut states, mut inputs, mut nlls) = (Vec::with_capacity(t), Vec::with_capacity(t), Vec::with_capacity(t));
    let mut chosen = Vec::with_capacity(t);
    for i in 0..t {
        let mix = g.mixture(&head)?;
        // The component of each row, as a one-hot mask (not differentiated).
        let best = match components {
            Some(c) => c.narrow(1, i, 1)?,
            None => mix.log_weights.argmax_keepdim(D::Minus1)?, // (B, 1)
        };
        let ids = Tensor::arange(0u32, m as u32, g.device())?.unsqueeze(0)?.broadcast_as((b, m))?;
        let onehot = ids.broadcast_eq(&best)?.to_dtype(DType::F32)?.unsqueeze(2)?; // (B, M, 1)
        let mu = mix.means.broadcast_mul(&onehot)?.sum(1)?; // (B, D)
        let sigma = mix.log_stds.exp()?.broadcast_mul(&onehot)?.sum(1)?;
        let e = eps.narrow(1, i, 1)?.squeeze(1)?;
        let mut s = (mu + (sigma * e)?)?;
        if let Some(shift) = shift {
            s = (s + shift.narrow(1, i, 1)?.squeeze(1)?)?;
        }
        nlls.push(gmm::nll(&mix, &s)?); // (B)
        let input = (&s + d.narrow(1, i, 1)?.squeeze(1)?)?;
        if i + 1 < t {
            let (r, st) = g.step(&input, &state)?;
            (head, state) = (r, st);
        }
        states.push(s);
        inputs.push(input);
        chosen.push(best);
    }
    debug_assert_eq!(dim, model.spec.dim());
    Ok(Rollout {
        states: Tensor::stack(&states, 1)?,
        inputs: Tensor::stack(&inputs, 1)?,
        nll: Tensor::stack(&nlls, 1)?,
        components: Tensor::cat(&chosen, 1)?,
    })
}

/// The world root positions `(B, T, 2)` (x, z, clip units) of states `(B, T, D)` generated from
/// `placement`.
pub fn world_root(fk: &TensorFk, states: &Tensor, placement: &RootPlacement) -> RnnGmmResult<Tensor> {
    let local = fk.root_trajectory(states)?; // (B, T, 3): x, height, z from the origin, heading 0
    let (lx, lz) = (local.narrow(2, 0, 1)?, local.narrow(2, 2, 1)?);
    let (c, s) = (placement.yaw.cos(), placement.yaw.sin());
    let wx = (((&lx * c)? + (&lz * s)?)? + placement.x)?;
    let wz = (((&lz * c)? - (&lx * s)?)? + placement.z)?;
    Ok(Tensor::cat(&[&wx, &wz], 2)?)
}

/// The generated contact bits of states `(B, T, D)`: `(B, T, 2)`, 1 where the value (clip
/// units) is at least 0.5 (not differentiated).
pub fn contact_bits(fk: &TensorFk, states: &Tensor) -> RnnGmmResult<Tensor> {
    let c = states.dim(2)? - CONTACT_DIMS;
    Ok(fk.denormalize(&states.detach())?.narrow(2, c, CONTACT_DIMS)?.ge(0.5)?.to_dtype(DType::F32)?)
}

/// The contact term (eq. 18) of states `(B, T, D)` following `last` `(1, 1, D)`, per row `(B)`:
/// the foot joints of `fk` (left ones first, `left` of them) with ground heights `ground` `(F)`,
/// planted where `bits` `(B, T, 2)` say (default: [`contact_bits`] of the states; an optimiser
/// fixes them, since a bit that flips between evaluations makes the energy jump).
#[allow(clippy::too_many_arguments)]
pub fn contact_energy(
    fk: &TensorFk,
    last: &Tensor,
    states: &Tensor,
    bits: Option<&Tensor>,
    left: usize,
    ground: &Tensor,
    sigma_contact: f64,
    sigma_plane: f64,
) -> RnnGmmResult<Tensor> {
    let (b, t, _) = states.dims3()?;
    let f = fk.effector_count();
    let all = Tensor::cat(&[&last.repeat((b, 1, 1))?, states], 1)?; // (B, T + 1, D)
    let feet = fk.effector_features(&all)?.narrow(1, 1, t)?; // (B, T, 6F)
    let pos = feet.narrow(2, 0, 3 * f)?.reshape((b, t, f, 3))?;
    let vel = feet.narrow(2, 3 * f, 3 * f)?.reshape((b, t, f, 3))?;
    let bits = match bits {
        Some(b) => b.clone(),
        None => contact_bits(fk, states)?,
    };
    let planted = Tensor::cat(
        &[
            &bits.narrow(2, 0, 1)?.broadcast_as((b, t, left))?.contiguous()?,
            &bits.narrow(2, 1, 1)?.broadcast_as((b, t, f - left))?.contiguous()?,
        ],
        2,
    )?; // (B, T, F)
    let slide = (vel.sqr()?.sum(3)? * &planted)?.sum(2)?.sum(1)? / (sigma_contact * sigma_contact);
    let height = pos.narrow(3, 1, 1)?.squeeze(3)?.broadcast_sub(ground)?;
    let plane = (height.sqr()? * &planted)?.sum(2)?.sum(1)? / (sigma_plane * sigma_plane);
    Ok((slide? + plane?)?)
}

/// Ground heights of the foot joints `feet` in `clip` (the contact rule's percentile of each
/// joint's height), `(F)`.
pub fn ground_heights(model: &LoadedGenerator, clip: &Clip, feet: &[usize], device: &Device) -> RnnGmmResult<Tensor> {
    let (_, gp) = clip.global();
    let joints = clip.joints();
    let ground: Vec<f32> = feet
        .iter()
        .map(|&j| {
            let mut h: Vec<f64> = (0..clip.frames()).map(|f| gp[f * joints + j].y).collect();
            zoo_data::dataset::percentile(&mut h, model.spec.contact.ground_percentile) as f32
        })
        .collect();
    Ok(Tensor::from_vec(ground, feet.len(), device)?)
}

/// Draws and noise `(1, T, D)` each from the flat unknowns `[e; d]`.
pub(crate) fn split(p: &[f64], t: usize, dim: usize, dev: &Device) -> RnnGmmResult<(Tensor, Tensor)> {
    let to = |v: &[f64]| -> RnnGmmResult<Tensor> {
        let v: Vec<f32> = v.iter().map(|x| *x as f32).collect();
        Ok(Tensor::from_vec(v, (1, t, dim), dev)?)
    };
    Ok((to(&p[..t * dim])?, to(&p[t * dim..])?))
}

/// An energy over the flat unknowns `[e; d]` of `t` frames, with its gradient by
/// backpropagation, for argmin (the last evaluation is cached: L-BFGS asks for the cost and
/// the gradient of the same point).
/// An energy of draws and noise.
type Energy<'a> = &'a dyn Fn(&Tensor, &Tensor) -> RnnGmmResult<Tensor>;

/// The last point evaluated: unknowns, energy, gradient.
type Evaluated = Option<(Vec<f64>, f64, Vec<f64>)>;

struct Problem<'a> {
    energy: Energy<'a>,
    t: usize,
    dim: usize,
    device: Device,
    what: &'a str,
    cache: RefCell<Evaluated>,
}

impl Problem<'_> {
    fn evaluate(&self, p: &[f64]) -> Result<(f64, Vec<f64>), argmin::core::Error> {
        if let Some((q, e, g)) = self.cache.borrow().as_ref()
            && q.as_slice() == p
        {
            return Ok((*e, g.clone()));
        }
        let (e, d) = split(p, self.t, self.dim, &self.device)?;
        let (ev, dv) = (Var::from_tensor(&e)?, Var::from_tensor(&d)?);
        let energy = (self.energy)(ev.as_tensor(), dv.as_tensor())?.sum_all()?;
        let grads = energy.backward()?;
        let value = energy.to_dtype(DType::F64)?.to_scalar::<f64>()?;
        let mut grad = Vec::with_capacity(p.len());
        for v in [&ev, &dv] {
            match grads.get(v) {
                Some(g) => grad.extend(g.flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?),
                None => grad.extend(std::iter::repeat_n(0.0, p.len() / 2)),
            }
        }
        if grad.iter().any(|v| !v.is_finite()) {
            return Err(argmin::core::Error::msg(format!("the {} gradient is not finite", self.what)));
        }
        *self.cache.borrow_mut() = Some((p.to_vec(), value, grad.clone()));
        Ok((value, grad))
    }
}

impl CostFunction for Problem<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.evaluate(p)?.0)
    }
}

impl Gradient for Problem<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, p: &Vec<f64>) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(self.evaluate(p)?.1)
    }
}

/// Minimises `energy(e, d)` (draws and noise `(1, t, dim)` each) by L-BFGS (argmin, memory 7,
/// More-Thuente line search) from the flat unknowns `init` (`[e; d]`), `iterations` at most;
/// returns the best point and the iterations made. `what` names the problem in errors.
pub(crate) fn minimise(
    energy: &dyn Fn(&Tensor, &Tensor) -> RnnGmmResult<Tensor>,
    init: Vec<f64>,
    t: usize,
    dim: usize,
    device: &Device,
    iterations: u64,
    what: &str,
) -> RnnGmmResult<(Vec<f64>, u64)> {
    let failed = |e: argmin::core::Error| RnnGmmError::Config(format!("{what}: L-BFGS failed: {e}"));
    let problem = Problem { energy, t, dim, device: device.clone(), what, cache: RefCell::new(None) };
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), 7)
        .with_tolerance_grad(1e-6)
        .and_then(|s| s.with_tolerance_cost(1e-9))
        .map_err(failed)?;
    let res = Executor::new(problem, solver)
        .configure(|s| s.param(init.clone()).max_iters(iterations))
        .run()
        .map_err(failed)?;
    let iterations = res.state().get_iter();
    Ok((res.state().get_best_param().cloned().unwrap_or(init), iterations))
}
