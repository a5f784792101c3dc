//! Initial hidden state estimation (sec. 5.4, eq. 26): instead of starting the generator from
//! zero `h` and `c` (a state it never saw in training, which makes the first generated frames
//! hop), optimise the state by gradient descent so that the seed frames are likely:
//! `min_(h_1) -log p(x_2 | x_1, h_1)`. With more than two seed frames the NLL of every frame
//! after the first is summed (the state is the one before the first frame).

use crate::error::{RnnGmmError, RnnGmmResult};
use crate::gmm;
use crate::model::Generator;
use candle_core::{Tensor, Var};
use candle_nn::Optimizer;
use zoo_nn::LstmState;
use zoo_nn::optim::{Adam, ParamsAdam};

/// The estimated state and how likely the seed frames are from it.
#[derive(Clone, Debug)]
pub struct InitialState {
    /// The state before the first seed frame.
    pub state: LstmState,
    /// NLL of the seed frames (after the first) from the zero state.
    pub nll_zero: f64,
    /// NLL of the seed frames from the estimated state.
    pub nll: f64,
}

/// Estimates the state before `frames` (normalised, `n * D` values, `n >= 2`) by `steps` Adam
/// steps of learning rate `lr` on `(h, c)` of every layer, starting from zero (eq. 26; the paper
/// says gradient descent, Adam is its scale-free form). Deterministic: no random numbers.
pub fn estimate_initial_state(model: &Generator, frames: &[f32], steps: usize, lr: f64) -> RnnGmmResult<InitialState> {
    let d = model.config().dim;
    if frames.len() < 2 * d || !frames.len().is_multiple_of(d) {
        return Err(RnnGmmError::Size {
            what: "seed frames for the initial state".into(),
            expected: 2 * d,
            detail: format!("at least 2 frames of D = {d} values (eq. 26 needs x_1 and x_2)"),
            found: frames.len(),
        });
    }
    if !(lr.is_finite() && lr > 0.0) {
        return Err(RnnGmmError::Config(format!("the learning rate must be positive, found {lr}")));
    }
    let n = frames.len() / d;
    let dev = model.device();
    let xs = Tensor::from_slice(frames, (1, n, d), dev)?;
    let (inputs, targets) = (xs.narrow(1, 0, n - 1)?, xs.narrow(1, 1, n - 1)?);
    let zero = model.zero_state(1)?;
    let vars: Vec<Var> = zero.h.iter().chain(&zero.c).map(Var::from_tensor).collect::<candle_core::Result<_>>()?;
    let layers = zero.h.len();
    let state_of = |vars: &[Var]| LstmState {
        h: vars[..layers].iter().map(|v| v.as_tensor().clone()).collect(),
        c: vars[layers..].iter().map(|v| v.as_tensor().clone()).collect(),
    };
    let loss_of = |state: &LstmState| -> RnnGmmResult<Tensor> {
        let (raw, _) = model.forward_seq(&inputs, state)?;
        Ok(gmm::nll(&model.mixture(&raw)?, &targets)?.sum_all()?)
    };
    let nll_zero = loss_of(&zero)?.to_scalar::<f32>()? as f64;
    let named = vars.iter().enumerate().map(|(i, v)| (format!("state.{i}"), v.clone())).collect();
    let mut opt = Adam::new_named(named, ParamsAdam { lr, ..ParamsAdam::default() })?;
    let (mut best, mut best_state) = (nll_zero, zero);
    for _ in 0..steps {
        let state = state_of(&vars);
        let loss = loss_of(&state)?;
        let value = loss.to_scalar::<f32>()? as f64;
        if !value.is_finite() {
            break;
        }
        if value < best {
            best = value;
            best_state = LstmState {
                h: state.h.iter().map(|t| t.detach()).collect(),
                c: state.c.iter().map(|t| t.detach()).collect(),
            };
        }
        opt.backward_step(&loss)?;
    }
    let last = state_of(&vars);
    let value = loss_of(&last)?.to_scalar::<f32>()? as f64;
    if value.is_finite() && value < best {
        best = value;
        best_state = LstmState {
            h: last.h.iter().map(|t| t.detach()).collect(),
            c: last.c.iter().map(|t| t.detach()).collect(),
        };
    }
    Ok(InitialState { state: best_state, nll_zero, nll: best })
}
