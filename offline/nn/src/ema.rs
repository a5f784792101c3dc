//! Exponential moving average of the weights (Polyak averaging), kept beside the trained ones.
//!
//! After optimiser step `t` (1-based) each average moves as `avg = d avg + (1 - d) w` with the
//! warmed-up decay `d = min(decay, (1 + t) / (10 + t))`, so that the initial weights fade quickly.
//! The averages are detached tensors: they never keep a graph back to earlier steps.

use crate::error::{NnError, NnResult};
use crate::optim::f32_slice;
use candle_core::{Tensor, Var};
use std::collections::HashMap;

/// One variable and its average.
#[derive(Debug)]
struct Averaged {
    name: String,
    var: Var,
    avg: Tensor,
}

/// The moving average of a set of named variables.
#[derive(Debug)]
pub struct Ema {
    decay: f64,
    slots: Vec<Averaged>,
}

/// The trained weights while the averages are swapped in ([`Ema::swap_in`]).
#[must_use = "put the trained weights back with `Ema::swap_out`"]
#[derive(Debug)]
pub struct TrainedWeights(Vec<Tensor>);

impl Ema {
    /// An average of `vars` starting at their current values; `decay` must be in (0, 1).
    pub fn new(vars: Vec<(String, Var)>, decay: f64) -> NnResult<Self> {
        if !(decay > 0.0 && decay < 1.0) {
            return Err(NnError::Config(format!(
                "EMA decay {decay} is outside (0, 1): 0.999 averages over about 1000 steps"
            )));
        }
        let slots = vars
            .into_iter()
            .map(|(name, var)| Ok(Averaged { avg: var.as_tensor().detach().copy()?, name, var }))
            .collect::<NnResult<Vec<_>>>()?;
        Ok(Ema { decay, slots })
    }

    /// The decay.
    pub fn decay(&self) -> f64 {
        self.decay
    }

    /// Folds the current weights into the average after optimiser step `step` (1-based: the
    /// number of steps taken so far).
    pub fn update(&mut self, step: u64) -> NnResult<()> {
        let t = step as f64;
        let d = self.decay.min((1.0 + t) / (10.0 + t));
        let (df, odf) = (d as f32, (1.0 - d) as f32);
        for Averaged { var, avg, .. } in self.slots.iter_mut() {
            // f32 on the CPU: one loop doing the f32 operations of the tensor ops below, in
            // their order (the same bits, without two weight-sized temporaries).
            let fused = {
                let (a_st, a_l) = avg.storage_and_layout();
                let (w_st, w_l) = var.storage_and_layout();
                match (f32_slice(&a_st, a_l), f32_slice(&w_st, w_l)) {
                    (Some(a), Some(w)) if a.len() == w.len() => {
                        Some(a.iter().zip(w).map(|(a, w)| (a * df + 0.0) + (w * odf + 0.0)).collect::<Vec<f32>>())
                    }
                    _ => None,
                }
            };
            *avg = match fused {
                Some(v) => Tensor::from_vec(v, avg.shape(), avg.device())?,
                None => (avg.affine(d, 0.0)? + var.as_tensor().detach().affine(1.0 - d, 0.0)?)?.detach(),
            };
        }
        Ok(())
    }

    /// Puts the averages in place of the trained weights; returns the trained weights for
    /// [`Ema::swap_out`].
    pub fn swap_in(&self) -> NnResult<TrainedWeights> {
        let mut saved = Vec::with_capacity(self.slots.len());
        for Averaged { var, avg, .. } in &self.slots {
            saved.push(var.as_tensor().detach().copy()?);
            var.set(avg)?;
        }
        Ok(TrainedWeights(saved))
    }

    /// Puts the trained weights back.
    pub fn swap_out(&self, trained: TrainedWeights) -> NnResult<()> {
        for (a, w) in self.slots.iter().zip(&trained.0) {
            a.var.set(w)?;
        }
        Ok(())
    }

    /// The averages by variable name, `ema.{name}` (for a checkpoint).
    pub fn state(&self) -> HashMap<String, Tensor> {
        self.slots.iter().map(|a| (format!("ema.{}", a.name), a.avg.clone())).collect()
    }

    /// Restores averages written by [`Ema::state`]: every variable must be present with its shape.
    pub fn set_state(&mut self, state: &HashMap<String, Tensor>) -> NnResult<()> {
        for a in self.slots.iter_mut() {
            let Some(saved) = state.get(&format!("ema.{}", a.name)) else {
                return Err(NnError::State(format!("the moving average has no tensor for {}", a.name)));
            };
            if saved.dims() != a.var.as_tensor().dims() {
                return Err(NnError::State(format!(
                    "the moving average of {} has shape {:?}, the variable {:?}",
                    a.name,
                    saved.dims(),
                    a.var.as_tensor().dims()
                )));
            }
            a.avg = saved.to_dtype(a.var.dtype())?.to_device(a.var.device())?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn warm_up_swap_and_state() -> NnResult<()> {
        let w = Var::new(&[0.0f64, 10.0], &Device::Cpu)?;
        let mut ema = Ema::new(vec![("w".into(), w.clone())], 0.9)?;
        w.set(&Tensor::new(&[1.0f64, 20.0], &Device::Cpu)?)?;
        ema.update(1)?;
        // step 1: d = min(0.9, 2 / 11) = 2/11; avg = 2/11 * [0, 10] + 9/11 * [1, 20].
        let d = 2.0 / 11.0;
        let want = [(1.0 - d), d * 10.0 + (1.0 - d) * 20.0];
        let trained = ema.swap_in()?;
        let got = w.as_tensor().to_vec1::<f64>()?;
        assert!((got[0] - want[0]).abs() < 1e-12 && (got[1] - want[1]).abs() < 1e-12, "{got:?}");
        ema.swap_out(trained)?;
        assert_eq!(w.as_tensor().to_vec1::<f64>()?, [1.0, 20.0]);
        // Late steps use the decay itself: d = min(0.9, 1001 / 1010).
        let before = ema.state()["ema.w"].to_vec1::<f64>()?;
        ema.update(1000)?;
        let after = ema.state()["ema.w"].to_vec1::<f64>()?;
        assert!((after[0] - (0.9 * before[0] + 0.1)).abs() < 1e-12);
        let mut other = Ema::new(vec![("w".into(), w.clone())], 0.9)?;
        other.set_state(&ema.state())?;
        assert_eq!(other.state()["ema.w"].to_vec1::<f64>()?, after);
        let mut wrong = Ema::new(vec![("v".into(), w.clone())], 0.9)?;
        assert!(wrong.set_state(&ema.state()).unwrap_err().to_string().contains("no tensor for v"));
        assert!(Ema::new(vec![], 1.0).unwrap_err().to_string().contains("EMA decay 1"));
        Ok(())
    }

    /// The fused f32 update gives the bits of the tensor-op formula.
    #[test]
    fn f32_update_equals_the_tensor_op_update() -> NnResult<()> {
        let dev = Device::Cpu;
        let w = Var::from_tensor(&Tensor::arange(0f32, 301.0, &dev)?.affine(0.13, -7.0)?.sin()?)?;
        let mut ema = Ema::new(vec![("w".into(), w.clone())], 0.999)?;
        let mut want = w.as_tensor().copy()?;
        for step in 1..=3u64 {
            w.set(&(w.as_tensor().cos()? * 1.7)?)?;
            ema.update(step)?;
            let t = step as f64;
            let d = 0.999f64.min((1.0 + t) / (10.0 + t));
            want = (want.affine(d, 0.0)? + w.as_tensor().affine(1.0 - d, 0.0)?)?;
        }
        let bits = |t: &Tensor| -> NnResult<Vec<u32>> { Ok(t.to_vec1::<f32>()?.iter().map(|x| x.to_bits()).collect()) };
        assert_eq!(bits(&ema.state()["ema.w"])?, bits(&want)?);
        Ok(())
    }
}
