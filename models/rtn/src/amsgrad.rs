//! AMSGrad (Reddi, Kale & Kumar, ICLR 2018), the optimiser of RTN sec. 6.3; candle-nn has only
//! SGD and AdamW.
//!
//! Same update as PyTorch's `Adam(amsgrad=True)` without weight decay, with bias correction:
//! `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g^2`, `v_max = max(v_max, v)`,
//! `theta -= lr / (1 - b1^t) * m / (sqrt(v_max) / sqrt(1 - b2^t) + eps)`.

use candle_core::backprop::GradStore;
use candle_core::{Result, Var};
use candle_nn::Optimizer;

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
    /// The paper's settings: lr 5e-4, Adam's default betas, eps 1e-8.
    fn default() -> Self {
        ParamsAmsGrad { lr: 5e-4, beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

#[derive(Debug)]
struct Slot {
    /// Variable name (for saving the state); empty when built through `Optimizer::new`.
    name: String,
    var: Var,
    m: Var,
    v: Var,
    v_max: Var,
}

/// The AMSGrad optimiser over a set of variables.
#[derive(Debug)]
pub struct AmsGrad {
    slots: Vec<Slot>,
    t: u64,
    params: ParamsAmsGrad,
}

/// Name of the step counter in a saved optimiser state.
const STEP_KEY: &str = "__amsgrad_step";

impl AmsGrad {
    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// An optimiser over named variables, whose state can be saved and loaded by name
    /// (`Optimizer::new` builds one without names).
    pub fn new_named(vars: Vec<(String, Var)>, params: ParamsAmsGrad) -> Result<Self> {
        let slots = vars
            .into_iter()
            .filter(|(_, v)| v.dtype().is_float())
            .map(|(name, var)| {
                let z = || Var::zeros(var.shape(), var.dtype(), var.device());
                Ok(Slot { name, m: z()?, v: z()?, v_max: z()?, var })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(AmsGrad { slots, t: 0, params })
    }

    /// The state (`NAME.m`, `NAME.v`, `NAME.v_max` and the step count) as named tensors, for
    /// a safetensors file; needs names ([`AmsGrad::new_named`]).
    pub fn state(&self) -> Result<std::collections::HashMap<String, candle_core::Tensor>> {
        let mut out = std::collections::HashMap::new();
        for s in &self.slots {
            if s.name.is_empty() {
                candle_core::bail!("this AMSGrad was built without variable names: its state cannot be saved");
            }
            out.insert(format!("{}.m", s.name), s.m.as_tensor().clone());
            out.insert(format!("{}.v", s.name), s.v.as_tensor().clone());
            out.insert(format!("{}.v_max", s.name), s.v_max.as_tensor().clone());
        }
        let device = self.slots.first().map_or(candle_core::Device::Cpu, |s| s.var.device().clone());
        out.insert(STEP_KEY.into(), candle_core::Tensor::new(&[self.t as f64], &device)?);
        Ok(out)
    }

    /// Restores a state written from [`AmsGrad::state`]: every variable must be present with
    /// its shape.
    pub fn set_state(&mut self, state: &std::collections::HashMap<String, candle_core::Tensor>) -> Result<()> {
        for s in &self.slots {
            for (suffix, var) in [("m", &s.m), ("v", &s.v), ("v_max", &s.v_max)] {
                let key = format!("{}.{suffix}", s.name);
                let Some(t) = state.get(&key) else {
                    candle_core::bail!("the optimiser state has no `{key}`: it was saved for another model")
                };
                if t.dims() != var.dims() {
                    candle_core::bail!(
                        "optimiser state `{key}` has shape {:?}, the variable {:?}",
                        t.dims(),
                        var.dims()
                    )
                }
                var.set(&t.to_dtype(var.dtype())?.to_device(var.device())?)?;
            }
        }
        let Some(step) = state.get(STEP_KEY) else { candle_core::bail!("the optimiser state has no step count") };
        self.t = step.to_vec1::<f64>()?.first().copied().unwrap_or(0.0) as u64;
        Ok(())
    }
}

impl Optimizer for AmsGrad {
    type Config = ParamsAmsGrad;

    fn new(vars: Vec<Var>, params: ParamsAmsGrad) -> Result<Self> {
        AmsGrad::new_named(vars.into_iter().map(|v| (String::new(), v)).collect(), params)
    }

    fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.t += 1;
        let p = self.params;
        let t = self.t as i32;
        let bc1 = 1.0 - p.beta1.powi(t);
        let bc2 = 1.0 - p.beta2.powi(t);
        let step_size = p.lr / bc1;
        let inv_sqrt_bc2 = 1.0 / bc2.sqrt();
        for s in &self.slots {
            let Some(g) = grads.get(&s.var) else { continue };
            let m = ((s.m.as_tensor() * p.beta1)? + (g * (1.0 - p.beta1))?)?;
            let v = ((s.v.as_tensor() * p.beta2)? + (g.sqr()? * (1.0 - p.beta2))?)?;
            let v_max = s.v_max.as_tensor().maximum(&v)?;
            let denom = ((v_max.sqrt()? * inv_sqrt_bc2)? + p.eps)?;
            let update = ((&m / denom)? * step_size)?;
            s.var.set(&s.var.as_tensor().sub(&update)?)?;
            s.m.set(&m)?;
            s.v.set(&v)?;
            s.v_max.set(&v_max)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};

    /// Two steps on `theta = [1, -2]` with gradients `[10, 1]` then `[0.1, -1]`
    /// (losses `sum(g * theta)`), lr 0.1, betas (0.9, 0.999), eps 1e-8, computed by hand:
    ///
    /// step 1: m = [1, 0.1], v = v_max = [0.1, 0.001], bc1 = 0.1, bc2 = 0.001,
    ///   update = 0.1 / 0.1 * m / (sqrt(v_max / 0.001) + eps) = [0.1, 0.1] -> theta = [0.9, -2.1].
    /// step 2: m = [0.91, -0.01], v = [0.09991, 0.001999], v_max = [0.1 (kept: v fell), 0.001999],
    ///   bc1 = 0.19, bc2 = 0.001999, update_0 = 0.1 / 0.19 * 0.91 / sqrt(0.1 / 0.001999)
    ///   = 0.0677165 -> theta_0 = 0.8322835 (Adam, using v instead of v_max, would give 0.8322530);
    ///   update_1 = 0.1 / 0.19 * -0.01 / 1 = -0.0052632 -> theta_1 = -2.0947368.
    #[test]
    fn amsgrad_matches_two_hand_computed_steps() -> Result<()> {
        let dev = Device::Cpu;
        let theta = Var::from_slice(&[1.0f32, -2.0], 2, &dev)?;
        let params = ParamsAmsGrad { lr: 0.1, ..ParamsAmsGrad::default() };
        let mut opt = AmsGrad::new(vec![theta.clone()], params)?;
        for g in [[10.0f32, 1.0], [0.1, -1.0]] {
            let loss = theta.as_tensor().mul(&Tensor::from_slice(&g, 2, &dev)?)?.sum_all()?;
            opt.backward_step(&loss)?;
        }
        let got = theta.as_tensor().to_vec1::<f32>()?;
        let want = [0.832_283_5f32, -2.094_736_8];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 2e-6, "got {got:?}, want {want:?}");
        }
        assert!((got[0] - 0.832_253).abs() > 1e-5, "the max of the second moments must be kept");
        assert_eq!(opt.steps(), 2);
        Ok(())
    }
}
