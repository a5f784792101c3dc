//! Optimisers whose state is saved and restored by checkpoints as named tensors: AMSGrad, Adam
//! and RMSProp (candle-nn has only SGD and AdamW), and gradient clipping by value and by norm.
//!
//! Each optimiser also implements [`candle_nn::Optimizer`] (`backward_step`, learning rate).
//! Variables are named (e.g. by their `VarMap` name) so that a saved state is matched by name:
//! `NAME.m`, `NAME.v`, ... plus scalar entries starting with `__`.

use crate::error::{NnError, NnResult};
use candle_core::backprop::GradStore;
use candle_core::{Device, Result, Tensor, Var};
use candle_nn::Optimizer;
use std::collections::HashMap;

/// An optimiser whose whole state can be saved and restored, so that a resumed run continues
/// exactly.
pub trait StatefulOptimizer: Optimizer {
    /// The state as named tensors (for a safetensors file).
    fn state(&self) -> NnResult<HashMap<String, Tensor>>;
    /// Restores a state written by [`StatefulOptimizer::state`]: every variable must be present
    /// with its shape.
    fn set_state(&mut self, state: &HashMap<String, Tensor>) -> NnResult<()>;
    /// Optimiser steps taken.
    fn steps(&self) -> u64;
}

/// Named variables and their per-variable moment tensors.
#[derive(Debug)]
struct Slots {
    names: Vec<String>,
    vars: Vec<Var>,
    /// `moments[k][i]`: moment `kinds[k]` of variable `i`.
    moments: Vec<Vec<Var>>,
    kinds: &'static [&'static str],
}

impl Slots {
    fn new(vars: Vec<(String, Var)>, kinds: &'static [&'static str]) -> Result<Self> {
        let vars: Vec<(String, Var)> = vars.into_iter().filter(|(_, v)| v.dtype().is_float()).collect();
        let moments = kinds
            .iter()
            .map(|_| vars.iter().map(|(_, v)| Var::zeros(v.shape(), v.dtype(), v.device())).collect::<Result<Vec<_>>>())
            .collect::<Result<Vec<_>>>()?;
        let (names, vars): (Vec<String>, Vec<Var>) = vars.into_iter().unzip();
        Ok(Slots { names, vars, moments, kinds })
    }

    fn device(&self) -> Device {
        self.vars.first().map_or(Device::Cpu, |v| v.device().clone())
    }

    fn state(&self, scalars: &[(&str, f64)]) -> NnResult<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        for (i, name) in self.names.iter().enumerate() {
            if name.is_empty() {
                return Err(NnError::State(
                    "this optimiser was built without variable names (`Optimizer::new`): build it with `new_named` to save its state".into(),
                ));
            }
            for (k, kind) in self.kinds.iter().enumerate() {
                out.insert(format!("{name}.{kind}"), self.moments[k][i].as_tensor().clone());
            }
        }
        let device = self.device();
        for (key, value) in scalars {
            out.insert(key.to_string(), Tensor::new(&[*value], &device)?);
        }
        Ok(out)
    }

    fn set_state(&mut self, state: &HashMap<String, Tensor>) -> NnResult<()> {
        for (i, name) in self.names.iter().enumerate() {
            for (k, kind) in self.kinds.iter().enumerate() {
                let key = format!("{name}.{kind}");
                let var = &self.moments[k][i];
                let Some(t) = state.get(&key) else {
                    return Err(NnError::State(format!(
                        "the optimiser state has no `{key}`: it was saved for another model"
                    )));
                };
                if t.dims() != var.dims() {
                    return Err(NnError::State(format!(
                        "optimiser state `{key}` has shape {:?}, the variable {:?}",
                        t.dims(),
                        var.dims()
                    )));
                }
                var.set(&t.to_dtype(var.dtype())?.to_device(var.device())?)?;
            }
        }
        Ok(())
    }
}

fn scalar(state: &HashMap<String, Tensor>, key: &str) -> NnResult<f64> {
    let Some(t) = state.get(key) else {
        return Err(NnError::State(format!("the optimiser state has no `{key}`: it was saved by another optimiser")));
    };
    t.to_vec1::<f64>()?.first().copied().ok_or_else(|| NnError::State(format!("optimiser state `{key}` is empty")))
}

/// Unnamed variables (for [`Optimizer::new`]: such an optimiser cannot save its state).
fn unnamed(vars: Vec<Var>) -> Vec<(String, Var)> {
    vars.into_iter().map(|v| (String::new(), v)).collect()
}

/// The f32 values of a contiguous CPU tensor's storage (`None` for any other tensor).
pub(crate) fn f32_slice<'a>(storage: &'a candle_core::Storage, layout: &candle_core::Layout) -> Option<&'a [f32]> {
    match (storage, layout.contiguous_offsets()) {
        (candle_core::Storage::Cpu(cpu), Some((a, b))) => cpu.as_slice::<f32>().ok().map(|v| &v[a..b]),
        _ => None,
    }
}

/// Sets `var` to `values` (its shape).
fn set_values(var: &Var, values: Vec<f32>) -> Result<()> {
    var.set(&Tensor::from_vec(values, var.shape(), var.device())?)
}

/// The step of [`Adam`] and, with `amsgrad` (the slots then also hold `v_max`), of [`AmsGrad`]:
/// `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`, (`v_max = max(v_max, v)`),
/// `theta -= lr / (1 - b1^t) * m / (sqrt(v or v_max) / sqrt(1 - b2^t) + eps)`.
///
/// f32 variables on the CPU are updated by one loop over each variable (one read of the
/// gradient, weights and moments, one write of each), performing the same f32 operations in
/// the same order as the tensor ops of [`adam_step_ops`], so the result is the same bit for bit
/// (test `fused_steps_equal_the_tensor_op_steps`) without a dozen weight-sized temporaries.
#[allow(clippy::too_many_arguments)]
fn adam_step(
    slots: &Slots,
    grads: &GradStore,
    t: u64,
    lr: f64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    amsgrad: bool,
) -> Result<()> {
    let ti = t as i32;
    let step_size = lr / (1.0 - beta1.powi(ti));
    let inv_sqrt_bc2 = 1.0 / (1.0 - beta2.powi(ti)).sqrt();
    // The constants as candle's affine ops see them (`T::from_f64`).
    let (b1, ob1, b2, ob2) = (beta1 as f32, (1.0 - beta1) as f32, beta2 as f32, (1.0 - beta2) as f32);
    let (isb, epsf, ss) = (inv_sqrt_bc2 as f32, eps as f32, step_size as f32);
    for (i, var) in slots.vars.iter().enumerate() {
        let Some(g) = grads.get(var) else { continue };
        let n = var.elem_count();
        let (mut m2, mut v2, mut w2) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
        let mut vm2 = if amsgrad { vec![0f32; n] } else { Vec::new() };
        let done = {
            let (gs, gl) = g.storage_and_layout();
            let (ms, ml) = slots.moments[0][i].storage_and_layout();
            let (vs, vl) = slots.moments[1][i].storage_and_layout();
            let (ws, wl) = var.storage_and_layout();
            let vmax = amsgrad.then(|| slots.moments[2][i].storage_and_layout());
            let slices = (
                f32_slice(&gs, gl),
                f32_slice(&ms, ml),
                f32_slice(&vs, vl),
                f32_slice(&ws, wl),
                vmax.as_ref().map(|(s, l)| f32_slice(s, l)),
            );
            match slices {
                (Some(g), Some(m), Some(v), Some(w), vmax) if g.len() == n && vmax != Some(None) => {
                    let vmax = vmax.flatten();
                    for k in 0..n {
                        let gk = g[k];
                        let mk = (m[k] * b1 + 0.0) + (gk * ob1 + 0.0);
                        let vk = (v[k] * b2 + 0.0) + ((gk * gk) * ob2 + 0.0);
                        let d = match vmax {
                            Some(vm) => {
                                // candle's `maximum`
                                let x = if vm[k] < vk { vk } else { vm[k] };
                                vm2[k] = x;
                                x
                            }
                            None => vk,
                        };
                        let denom = (d.sqrt() * isb + 0.0) * 1.0 + epsf;
                        w2[k] = w[k] - ((mk / denom) * ss + 0.0);
                        m2[k] = mk;
                        v2[k] = vk;
                    }
                    true
                }
                _ => false,
            }
        };
        if !done {
            adam_step_ops(slots, i, g, t, lr, beta1, beta2, eps, amsgrad)?;
            continue;
        }
        set_values(var, w2)?;
        set_values(&slots.moments[0][i], m2)?;
        set_values(&slots.moments[1][i], v2)?;
        if amsgrad {
            set_values(&slots.moments[2][i], vm2)?;
        }
    }
    Ok(())
}

/// [`adam_step`] for one variable with tensor ops (any dtype and device; the reference of the
/// fused loop).
#[allow(clippy::too_many_arguments)]
fn adam_step_ops(
    slots: &Slots,
    i: usize,
    g: &Tensor,
    t: u64,
    lr: f64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    amsgrad: bool,
) -> Result<()> {
    let t = t as i32;
    let step_size = lr / (1.0 - beta1.powi(t));
    let inv_sqrt_bc2 = 1.0 / (1.0 - beta2.powi(t)).sqrt();
    let var = &slots.vars[i];
    let (sm, sv) = (&slots.moments[0][i], &slots.moments[1][i]);
    let m = ((sm.as_tensor() * beta1)? + (g * (1.0 - beta1))?)?;
    let v = ((sv.as_tensor() * beta2)? + (g.sqr()? * (1.0 - beta2))?)?;
    let v_max = if amsgrad { Some(slots.moments[2][i].as_tensor().maximum(&v)?) } else { None };
    let denom = ((v_max.as_ref().unwrap_or(&v).sqrt()? * inv_sqrt_bc2)? + eps)?;
    let update = ((&m / denom)? * step_size)?;
    var.set(&var.as_tensor().sub(&update)?)?;
    sm.set(&m)?;
    sv.set(&v)?;
    if let Some(v_max) = v_max {
        slots.moments[2][i].set(&v_max)?;
    }
    Ok(())
}

/// `Optimizer` and `StatefulOptimizer` for an optimiser of the Adam family (fields `slots`, `t`,
/// `params` with `lr`, `beta1`, `beta2`, `eps`), its step counter saved as `$step`.
macro_rules! adam_family {
    ($name:ident, $params:ident, $step:ident, $amsgrad:expr) => {
        impl Optimizer for $name {
            type Config = $params;

            fn new(vars: Vec<Var>, params: $params) -> Result<Self> {
                $name::new_named(unnamed(vars), params)
            }

            fn step(&mut self, grads: &GradStore) -> Result<()> {
                self.t += 1;
                let p = self.params;
                adam_step(&self.slots, grads, self.t, p.lr, p.beta1, p.beta2, p.eps, $amsgrad)
            }

            fn learning_rate(&self) -> f64 {
                self.params.lr
            }

            fn set_learning_rate(&mut self, lr: f64) {
                self.params.lr = lr;
            }
        }

        impl StatefulOptimizer for $name {
            fn state(&self) -> NnResult<HashMap<String, Tensor>> {
                self.slots.state(&[($step, self.t as f64)])
            }

            fn set_state(&mut self, state: &HashMap<String, Tensor>) -> NnResult<()> {
                self.slots.set_state(state)?;
                self.t = scalar(state, $step)? as u64;
                Ok(())
            }

            fn steps(&self) -> u64 {
                self.t
            }
        }
    };
}

/// AMSGrad hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamsAmsGrad {
    /// Learning rate.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Added to the denominator.
    pub eps: f64,
}

impl Default for ParamsAmsGrad {
    /// RTN's settings (sec. 6.3): lr 5e-4, Adam's default betas, eps 1e-8.
    fn default() -> Self {
        ParamsAmsGrad { lr: 5e-4, beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// AMSGrad (Reddi, Kale & Kumar, ICLR 2018, Alg. 2 with bias correction), the optimiser of
/// RTN sec. 6.3. Same update as PyTorch's `Adam(amsgrad=True)` without weight decay:
/// `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`, `v_max = max(v_max, v)`,
/// `theta -= lr / (1 - b1^t) * m / (sqrt(v_max) / sqrt(1 - b2^t) + eps)`.
///
/// State: `NAME.m`, `NAME.v`, `NAME.v_max`, `__amsgrad_step`.
#[derive(Debug)]
pub struct AmsGrad {
    slots: Slots,
    t: u64,
    params: ParamsAmsGrad,
}

const AMSGRAD_STEP: &str = "__amsgrad_step";

impl AmsGrad {
    /// An optimiser over named variables (non-float variables are skipped).
    pub fn new_named(vars: Vec<(String, Var)>, params: ParamsAmsGrad) -> Result<Self> {
        Ok(AmsGrad { slots: Slots::new(vars, &["m", "v", "v_max"])?, t: 0, params })
    }
}

adam_family!(AmsGrad, ParamsAmsGrad, AMSGRAD_STEP, true);

/// Adam hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamsAdam {
    /// Learning rate.
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Added to the denominator.
    pub eps: f64,
}

impl Default for ParamsAdam {
    /// Kingma & Ba's defaults: lr 1e-3, betas (0.9, 0.999), eps 1e-8.
    fn default() -> Self {
        ParamsAdam { lr: 1e-3, beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// Adam (Kingma & Ba, ICLR 2015, Alg. 1), as PyTorch's `Adam` without weight decay:
/// `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`,
/// `theta -= lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)`.
///
/// State: `NAME.m`, `NAME.v`, `__adam_step`.
#[derive(Debug)]
pub struct Adam {
    slots: Slots,
    t: u64,
    params: ParamsAdam,
}

const ADAM_STEP: &str = "__adam_step";

impl Adam {
    /// An optimiser over named variables (non-float variables are skipped).
    pub fn new_named(vars: Vec<(String, Var)>, params: ParamsAdam) -> Result<Self> {
        Ok(Adam { slots: Slots::new(vars, &["m", "v"])?, t: 0, params })
    }
}

adam_family!(Adam, ParamsAdam, ADAM_STEP, false);

/// RMSProp hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamsRmsProp {
    /// Learning rate of the first epoch.
    pub lr: f64,
    /// Decay `rho` of the mean square (PyTorch's `alpha`: 0.99; Keras and many papers: 0.9).
    pub rho: f64,
    /// Added to the denominator.
    pub eps: f64,
    /// Factor applied to the learning rate at the end of every epoch ([`RmsProp::end_epoch`];
    /// 1 keeps it constant, e.g. 0.95).
    pub lr_decay: f64,
}

impl Default for ParamsRmsProp {
    /// PyTorch's defaults (lr 1e-2, rho 0.99, eps 1e-8), no decay.
    fn default() -> Self {
        ParamsRmsProp { lr: 1e-2, rho: 0.99, eps: 1e-8, lr_decay: 1.0 }
    }
}

/// RMSProp (Tieleman & Hinton 2012, lecture 6.5), as PyTorch's `RMSprop` without momentum:
/// `v = rho v + (1 - rho) g^2`, `theta -= lr * g / (sqrt(v) + eps)`, with the learning rate
/// multiplied by `lr_decay` after every epoch.
///
/// State: `NAME.v`, `__rmsprop_step`, `__rmsprop_lr` (the decayed learning rate).
#[derive(Debug)]
pub struct RmsProp {
    slots: Slots,
    t: u64,
    params: ParamsRmsProp,
}

const RMSPROP_STEP: &str = "__rmsprop_step";
const RMSPROP_LR: &str = "__rmsprop_lr";

impl RmsProp {
    /// An optimiser over named variables (non-float variables are skipped).
    pub fn new_named(vars: Vec<(String, Var)>, params: ParamsRmsProp) -> Result<Self> {
        Ok(RmsProp { slots: Slots::new(vars, &["v"])?, t: 0, params })
    }

    /// Applies the per-epoch learning-rate decay: `lr *= lr_decay`.
    pub fn end_epoch(&mut self) {
        self.params.lr *= self.params.lr_decay;
    }
}

impl Optimizer for RmsProp {
    type Config = ParamsRmsProp;

    fn new(vars: Vec<Var>, params: ParamsRmsProp) -> Result<Self> {
        RmsProp::new_named(unnamed(vars), params)
    }

    fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.t += 1;
        let p = self.params;
        let s = &self.slots;
        let (rho, orho, epsf, lr) = (p.rho as f32, (1.0 - p.rho) as f32, p.eps as f32, p.lr as f32);
        for (i, var) in s.vars.iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            let sv = &s.moments[0][i];
            // One loop doing the f32 operations of the tensor ops below, in their order (the
            // same bits; see `adam_step`).
            let n = var.elem_count();
            let fused = {
                let (gs, gl) = g.storage_and_layout();
                let (vs, vl) = sv.storage_and_layout();
                let (ws, wl) = var.storage_and_layout();
                match (f32_slice(&gs, gl), f32_slice(&vs, vl), f32_slice(&ws, wl)) {
                    (Some(g), Some(v), Some(w)) if g.len() == n => {
                        let (mut v2, mut w2) = (vec![0f32; n], vec![0f32; n]);
                        for k in 0..n {
                            let vk = (v[k] * rho + 0.0) + ((g[k] * g[k]) * orho + 0.0);
                            w2[k] = w[k] - ((g[k] / (vk.sqrt() * 1.0 + epsf)) * lr + 0.0);
                            v2[k] = vk;
                        }
                        Some((v2, w2))
                    }
                    _ => None,
                }
            };
            match fused {
                Some((v2, w2)) => {
                    set_values(var, w2)?;
                    set_values(sv, v2)?;
                }
                None => {
                    let v = ((sv.as_tensor() * p.rho)? + (g.sqr()? * (1.0 - p.rho))?)?;
                    let update = ((g / (v.sqrt()? + p.eps)?)? * p.lr)?;
                    var.set(&var.as_tensor().sub(&update)?)?;
                    sv.set(&v)?;
                }
            }
        }
        Ok(())
    }

    fn learning_rate(&self) -> f64 {
        self.params.lr
    }

    fn set_learning_rate(&mut self, lr: f64) {
        self.params.lr = lr;
    }
}

impl StatefulOptimizer for RmsProp {
    fn state(&self) -> NnResult<HashMap<String, Tensor>> {
        self.slots.state(&[(RMSPROP_STEP, self.t as f64), (RMSPROP_LR, self.params.lr)])
    }

    fn set_state(&mut self, state: &HashMap<String, Tensor>) -> NnResult<()> {
        self.slots.set_state(state)?;
        self.t = scalar(state, RMSPROP_STEP)? as u64;
        self.params.lr = scalar(state, RMSPROP_LR)?;
        Ok(())
    }

    fn steps(&self) -> u64 {
        self.t
    }
}

/// Clips every gradient component of `vars` to `[-clip, clip]`.
pub fn clip_grad_value(grads: &mut GradStore, vars: &[Var], clip: f64) -> Result<()> {
    for var in vars {
        if let Some(g) = grads.get(var) {
            let clipped = g.clamp(-clip, clip)?;
            grads.insert(var, clipped);
        }
    }
    Ok(())
}

/// Scales the gradients of `vars` so that their global L2 norm is at most `max_norm`
/// (PyTorch's `clip_grad_norm_`: factor `max_norm / (norm + 1e-6)` when `norm > max_norm`);
/// returns the norm before clipping.
pub fn clip_grad_norm(grads: &mut GradStore, vars: &[Var], max_norm: f64) -> Result<f64> {
    let mut sq = 0.0;
    for var in vars {
        if let Some(g) = grads.get(var) {
            sq += g.sqr()?.sum_all()?.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
        }
    }
    let norm = sq.sqrt();
    if norm > max_norm {
        let factor = max_norm / (norm + 1e-6);
        for var in vars {
            if let Some(g) = grads.get(var) {
                let scaled = (g * factor)?;
                grads.insert(var, scaled);
            }
        }
    }
    Ok(norm)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GRADS: [[f64; 2]; 2] = [[10.0, 1.0], [0.1, -1.0]];

    /// Runs two steps on `theta = [1, -2]` (f64) with the gradients [`GRADS`] (losses
    /// `sum(g * theta)`), calling `between` after the first step.
    fn run<O: Optimizer>(opt: &mut O, theta: &Var, between: impl FnOnce(&mut O)) -> Vec<f64> {
        let mut between = Some(between);
        for g in GRADS {
            let loss = theta.as_tensor().mul(&Tensor::new(&g, &Device::Cpu).unwrap()).unwrap().sum_all().unwrap();
            opt.backward_step(&loss).unwrap();
            if let Some(f) = between.take() {
                f(&mut *opt);
            }
        }
        theta.as_tensor().to_vec1::<f64>().unwrap()
    }

    fn theta() -> Var {
        Var::new(&[1.0f64, -2.0], &Device::Cpu).unwrap()
    }

    fn close(got: &[f64], want: &[f64]) {
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "got {got:?}, want {want:?}");
        }
    }

    /// The hand computation in plain f64: Adam, or AMSGrad when `amsgrad`.
    fn adam_by_hand(lr: f64, amsgrad: bool) -> Vec<f64> {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8);
        let mut th = [1.0f64, -2.0];
        let (mut m, mut v, mut vmax) = ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2]);
        for (t, g) in GRADS.iter().enumerate() {
            let t = t as i32 + 1;
            for j in 0..2 {
                m[j] = b1 * m[j] + (1.0 - b1) * g[j];
                v[j] = b2 * v[j] + (1.0 - b2) * g[j] * g[j];
                vmax[j] = vmax[j].max(v[j]);
                let second = if amsgrad { vmax[j] } else { v[j] };
                th[j] -= lr / (1.0 - b1.powi(t)) * m[j] / (second.sqrt() / (1.0 - b2.powi(t)).sqrt() + eps);
            }
        }
        th.to_vec()
    }

    /// Two steps on `theta = [1, -2]` with gradients `[10, 1]` then `[0.1, -1]`, lr 0.1, betas
    /// (0.9, 0.999), eps 1e-8, by hand:
    ///
    /// step 1: m = [1, 0.1], v = v_max = [0.1, 0.001], bc1 = 0.1, bc2 = 0.001,
    ///   update = 0.1 / 0.1 * m / (sqrt(v_max / 0.001) + eps) = [0.1, 0.1] -> theta = [0.9, -2.1].
    /// step 2: m = [0.91, -0.01], v = [0.09991, 0.001999], v_max = [0.1 (kept: v fell), 0.001999],
    ///   bc1 = 0.19, bc2 = 0.001999, update_0 = 0.1 / 0.19 * 0.91 / sqrt(0.1 / 0.001999)
    ///   = 0.0677165 -> theta_0 = 0.8322835 (Adam, using v instead of v_max, would give 0.8322530);
    ///   update_1 = 0.1 / 0.19 * -0.01 / 1 = -0.0052632 -> theta_1 = -2.0947368.
    #[test]
    fn amsgrad_matches_two_hand_computed_steps() {
        let th = theta();
        let mut opt = AmsGrad::new(vec![th.clone()], ParamsAmsGrad { lr: 0.1, ..ParamsAmsGrad::default() }).unwrap();
        let got = run(&mut opt, &th, |_| {});
        close(&got, &adam_by_hand(0.1, true));
        assert!((got[0] - 0.832_283_5).abs() < 1e-7 && (got[1] + 2.094_736_8).abs() < 1e-7, "{got:?}");
        assert!((got[0] - 0.832_253).abs() > 1e-5, "the max of the second moments must be kept");
        assert_eq!(opt.steps(), 2);
    }

    #[test]
    fn adam_matches_two_hand_computed_steps() {
        let th = theta();
        let mut opt = Adam::new(vec![th.clone()], ParamsAdam { lr: 0.1, ..ParamsAdam::default() }).unwrap();
        let got = run(&mut opt, &th, |_| {});
        close(&got, &adam_by_hand(0.1, false));
        assert!((got[0] - 0.832_253).abs() < 1e-6, "{got:?}");
    }

    #[test]
    fn rmsprop_with_decay_matches_two_hand_computed_steps() {
        let th = theta();
        let params = ParamsRmsProp { lr: 0.1, rho: 0.9, eps: 1e-8, lr_decay: 0.95 };
        let mut opt = RmsProp::new(vec![th.clone()], params).unwrap();
        let got = run(&mut opt, &th, |o| o.end_epoch());
        // step 1 (lr 0.1): v = 0.1 g^2 = [10, 0.1]; theta -= 0.1 g / sqrt(v).
        // end of epoch: lr = 0.095.
        // step 2 (lr 0.095): v = 0.9 v + 0.1 g^2; theta -= 0.095 g / sqrt(v).
        let mut th = [1.0f64, -2.0];
        let mut v = [0.0f64; 2];
        for (g, lr) in GRADS.iter().zip([0.1, 0.1 * 0.95]) {
            for j in 0..2 {
                v[j] = 0.9 * v[j] + 0.1 * g[j] * g[j];
                th[j] -= lr * g[j] / (v[j].sqrt() + 1e-8);
            }
        }
        close(&got, &th);
        assert!((opt.learning_rate() - 0.095).abs() < 1e-15);
    }

    /// The fused f32 loops give the bits of the tensor-op formulas they replace.
    #[test]
    fn fused_steps_equal_the_tensor_op_steps() {
        let dev = Device::Cpu;
        let init = Tensor::arange(0f32, 997.0, &dev).unwrap().affine(0.37, -11.0).unwrap().sin().unwrap();
        let grad_at = |step: usize| {
            Tensor::arange(0f32, 997.0, &dev).unwrap().affine(0.011 * (step + 1) as f64, 0.3).unwrap().cos().unwrap()
        };
        for amsgrad in [false, true] {
            let (a, b) = (Var::from_tensor(&init).unwrap(), Var::from_tensor(&init).unwrap());
            let kinds: &'static [&'static str] = if amsgrad { &["m", "v", "v_max"] } else { &["m", "v"] };
            let fused_slots = Slots::new(vec![("w".into(), a.clone())], kinds).unwrap();
            let ops_slots = Slots::new(vec![("w".into(), b.clone())], kinds).unwrap();
            for step in 0..4 {
                let g = grad_at(step);
                let mut ga = GradStore::default();
                ga.insert(a.as_tensor(), g.clone());
                adam_step(&fused_slots, &ga, step as u64 + 1, 5e-3, 0.9, 0.999, 1e-8, amsgrad).unwrap();
                adam_step_ops(&ops_slots, 0, &g, step as u64 + 1, 5e-3, 0.9, 0.999, 1e-8, amsgrad).unwrap();
            }
            let bits = |t: &Tensor| t.to_vec1::<f32>().unwrap().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a.as_tensor()), bits(b.as_tensor()), "weights, amsgrad {amsgrad}");
            for k in 0..kinds.len() {
                assert_eq!(
                    bits(fused_slots.moments[k][0].as_tensor()),
                    bits(ops_slots.moments[k][0].as_tensor()),
                    "moment {}",
                    kinds[k]
                );
            }
        }
        // RMSProp against its tensor-op formula.
        let w = Var::from_tensor(&init).unwrap();
        let mut opt = RmsProp::new_named(
            vec![("w".into(), w.clone())],
            ParamsRmsProp { lr: 2e-3, rho: 0.9, ..Default::default() },
        )
        .unwrap();
        let (mut wr, mut vr) = (init.clone(), init.zeros_like().unwrap());
        for step in 0..3 {
            let g = grad_at(step);
            let mut gs = GradStore::default();
            gs.insert(w.as_tensor(), g.clone());
            opt.step(&gs).unwrap();
            vr = ((&vr * 0.9).unwrap() + (g.sqr().unwrap() * (1.0 - 0.9)).unwrap()).unwrap();
            let update = ((&g / (vr.sqrt().unwrap() + 1e-8).unwrap()).unwrap() * 2e-3).unwrap();
            wr = wr.sub(&update).unwrap();
        }
        let bits = |t: &Tensor| t.to_vec1::<f32>().unwrap().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(w.as_tensor()), bits(&wr));
    }

    /// A state saved after one step and loaded into a fresh optimiser continues exactly.
    #[test]
    fn saved_state_continues_exactly() {
        let named = |th: &Var| vec![("theta".to_string(), th.clone())];
        let (a, b) = (theta(), theta());
        let params = ParamsRmsProp { lr: 0.1, rho: 0.9, eps: 1e-8, lr_decay: 0.5 };
        let mut whole = RmsProp::new_named(named(&a), params).unwrap();
        let want = run(&mut whole, &a, |o| o.end_epoch());
        let mut first = RmsProp::new_named(named(&b), params).unwrap();
        let g = Tensor::new(&GRADS[0], &Device::Cpu).unwrap();
        first.backward_step(&b.as_tensor().mul(&g).unwrap().sum_all().unwrap()).unwrap();
        first.end_epoch();
        let state = first.state().unwrap();
        assert!(state.contains_key("theta.v") && state.contains_key("__rmsprop_lr"));
        let mut resumed = RmsProp::new_named(named(&b), params).unwrap();
        resumed.set_state(&state).unwrap();
        assert_eq!(resumed.steps(), 1);
        let g = Tensor::new(&GRADS[1], &Device::Cpu).unwrap();
        resumed.backward_step(&b.as_tensor().mul(&g).unwrap().sum_all().unwrap()).unwrap();
        assert_eq!(b.as_tensor().to_vec1::<f64>().unwrap(), want);
        let mut other = Adam::new_named(named(&b), ParamsAdam::default()).unwrap();
        let err = other.set_state(&state).unwrap_err().to_string();
        assert!(err.contains("theta.m") && err.contains("another model"), "{err}");
        let unnamed = Adam::new(vec![b.clone()], ParamsAdam::default()).unwrap();
        assert!(unnamed.state().unwrap_err().to_string().contains("new_named"));
    }

    #[test]
    fn clipping_by_value_and_by_norm() {
        let (a, b) = (Var::new(&[3.0f64, -4.0], &Device::Cpu).unwrap(), Var::new(&[0.5f64], &Device::Cpu).unwrap());
        let loss = || {
            let ga = Tensor::new(&[3.0f64, -4.0], &Device::Cpu).unwrap();
            (a.as_tensor().mul(&ga).unwrap().sum_all().unwrap() + b.as_tensor().sum_all().unwrap()).unwrap()
        };
        let vars = [a.clone(), b.clone()];
        let mut grads = loss().backward().unwrap();
        clip_grad_value(&mut grads, &vars, 2.0).unwrap();
        assert_eq!(grads.get(&a).unwrap().to_vec1::<f64>().unwrap(), [2.0, -2.0]);
        assert_eq!(grads.get(&b).unwrap().to_vec1::<f64>().unwrap(), [1.0]);
        let mut grads = loss().backward().unwrap();
        // norm = sqrt(9 + 16 + 1) = 5.0990; scaled to 1.
        let norm = clip_grad_norm(&mut grads, &vars, 1.0).unwrap();
        assert!((norm - 26f64.sqrt()).abs() < 1e-12);
        let f = 1.0 / (norm + 1e-6);
        close(&grads.get(&a).unwrap().to_vec1::<f64>().unwrap(), &[3.0 * f, -4.0 * f]);
        close(&grads.get(&b).unwrap().to_vec1::<f64>().unwrap(), &[f]);
        let mut grads = loss().backward().unwrap();
        clip_grad_norm(&mut grads, &vars, 10.0).unwrap();
        assert_eq!(grads.get(&a).unwrap().to_vec1::<f64>().unwrap(), [3.0, -4.0], "below the limit: unchanged");
    }
}
