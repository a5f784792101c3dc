//! Weight-gradient tapes for weights used at every frame of a recurrent loop.
//!
//! A recurrent training step multiplies the same weight matrix at every frame (`h_t W^T` in an
//! LSTM, the fused gate matmul of the RTN). candle's backward pass computes each frame's weight
//! gradient `x_t^T dy_t` as its own matmul (inner dimension: the batch rows, 16-32 in the zoo)
//! and adds it into a fresh weight-sized tensor: per frame, a full write of the weight's
//! gradient and a full read-and-write to accumulate it, whatever the batch size. At the zoo's
//! shapes that is a large fixed cost per step (issue 18: it is why a worker with half the
//! batch is not twice as fast).
//!
//! With a tape, the frame's matmul runs as a custom op whose backward returns only the input's
//! gradient and records the output's gradient `dy_t`; after the backward pass,
//! [`WeightTape::finish`] computes the weight gradient of every frame at once,
//! `sum_t x_t^T dy_t = [x_1; ...; x_T]^T [dy_1; ...; dy_T]` (one matmul with the frames stacked
//! along the inner dimension), and adds it to the gradient store. The result equals candle's up
//! to float summation order.
//!
//! Tapes are opt-in and scoped: [`collect`] runs a closure with a tape collection active on the
//! current thread (the data-parallel workers of [`crate::parallel`] do this around each shard's
//! loss), and [`matmul_weight`] tapes a weight only while a collection is active; elsewhere
//! (inference, validation, export) it is a plain matmul.

use candle_core::backend::BackendStorage;
use candle_core::backprop::GradStore;
use candle_core::{CpuStorage, CustomOp2, Layout, Result, Shape, Tensor, TensorId, Var};
use std::cell::RefCell;
use std::sync::{Arc, Mutex};

#[derive(Default)]
struct Entries {
    inputs: Vec<Tensor>,
    grads: Vec<Option<Tensor>>,
}

/// The frames' inputs and output gradients of one weight (see the module documentation).
#[derive(Clone)]
pub struct WeightTape {
    /// The weight as the model holds it (a variable or a tensor computed from variables).
    weight: Tensor,
    /// The custom op's second argument: a leaf variable with the weight's values.
    leaf: Tensor,
    /// Whether frames compute `x W^T` (a weight stored `(out, in)`) rather than `x W`.
    transposed: bool,
    entries: Arc<Mutex<Entries>>,
}

impl std::fmt::Debug for WeightTape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.entries.lock().map(|e| e.inputs.len()).unwrap_or(0);
        f.debug_struct("WeightTape").field("weight", &self.weight.shape()).field("frames", &n).finish()
    }
}

struct TapedMatMul {
    entries: Arc<Mutex<Entries>>,
    index: usize,
    transposed: bool,
}

impl CustomOp2 for TapedMatMul {
    fn name(&self) -> &'static str {
        "zoo-taped-matmul"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let l2 = if self.transposed { l2.transpose(0, 1)? } else { l2.clone() };
        let (m, k) = l1.shape().dims2()?;
        let (k2, n) = l2.shape().dims2()?;
        if k != k2 {
            candle_core::bail!("taped matmul: ({m}, {k}) x ({k2}, {n}) do not match");
        }
        Ok((s1.matmul(s2, (1, m, n, k), l1, &l2)?, Shape::from((m, n))))
    }

    fn bwd(&self, x: &Tensor, w: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // The weight's own gradient is left to `WeightTape::finish` (None here); the input's is
        // needed only where the input depends on something trained.
        let dx = if !x.track_op() {
            None
        } else if self.transposed {
            Some(grad.matmul(w)?)
        } else {
            Some(grad.matmul(&w.t()?)?)
        };
        let mut e = self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
        if let Some(slot) = e.grads.get_mut(self.index) {
            *slot = Some(grad.detach());
        }
        Ok((dx, None))
    }
}

impl WeightTape {
    /// A tape for `weight`, `(k, n)` used as `x W`, or `(n, k)` used as `x W^T` when
    /// `transposed`.
    pub fn new(weight: &Tensor, transposed: bool) -> Result<Self> {
        weight.dims2()?;
        // The op's second argument must be a leaf that candle's backward walks through but
        // never asks a gradient of: the variable itself, or a variable copy of a computed
        // weight (one copy per tape, that is per training step and worker).
        let leaf = if weight.is_variable() { weight.clone() } else { Var::from_tensor(weight)?.as_tensor().clone() };
        Ok(WeightTape { weight: weight.clone(), leaf, transposed, entries: Arc::new(Mutex::new(Entries::default())) })
    }

    /// `x (m, k)` times the weight, its weight gradient left to [`WeightTape::finish`].
    pub fn matmul(&self, x: &Tensor) -> Result<Tensor> {
        let index = {
            let mut e =
                self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
            e.inputs.push(x.detach());
            e.grads.push(None);
            e.inputs.len() - 1
        };
        let op = TapedMatMul { entries: self.entries.clone(), index, transposed: self.transposed };
        x.apply_op2_arc(&self.leaf, Arc::new(Box::new(op)))
    }

    /// After the backward pass that produced `grads`: the weight's gradient over every frame
    /// recorded, added to `grads` for the variables among `vars` it depends on (directly when
    /// the weight is one of them, else through one more backward pass over the small graph
    /// that computes the weight from them). Frames whose output did not reach the loss are
    /// skipped. Returns whether anything was added.
    pub fn finish(&self, grads: &mut GradStore, vars: &[Var]) -> Result<bool> {
        let (xs, dys): (Vec<Tensor>, Vec<Tensor>) = {
            let e = self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
            e.inputs.iter().zip(&e.grads).filter_map(|(x, g)| g.as_ref().map(|g| (x.clone(), g.clone()))).unzip()
        };
        let direct = vars.iter().find(|v| v.as_tensor().id() == self.weight.id());
        if xs.is_empty() || (direct.is_none() && self.weight.is_variable()) {
            // Nothing recorded, or a variable that is not being trained by this step.
            return Ok(false);
        }
        let x = Tensor::cat(&xs, 0)?;
        let dy = Tensor::cat(&dys, 0)?;
        // sum_t x_t^T dy_t, or its transpose for a weight stored (out, in).
        let g = if self.transposed { dy.t()?.matmul(&x)? } else { x.t()?.matmul(&dy)? };
        if let Some(v) = direct {
            add_grad(grads, v.as_tensor(), g)?;
            return Ok(true);
        }
        // Through the weight's own graph: d/dvars of sum(weight * g) is J^T g.
        let through = (&self.weight * g)?.sum_all()?.backward()?;
        let mut any = false;
        for v in vars {
            if let Some(gv) = through.get(v.as_tensor()) {
                add_grad(grads, v.as_tensor(), gv.clone())?;
                any = true;
            }
        }
        Ok(any)
    }
}

fn add_grad(grads: &mut GradStore, t: &Tensor, g: Tensor) -> Result<()> {
    let sum = match grads.get(t) {
        Some(old) => (old + g)?,
        None => g,
    };
    grads.insert(t, sum);
    Ok(())
}

thread_local! {
    static ACTIVE: RefCell<Option<Vec<(TensorId, WeightTape)>>> = const { RefCell::new(None) };
}

/// Runs `f` with a tape collection active on this thread; returns its result and the tapes
/// that [`matmul_weight`] made meanwhile (one per weight). Collections do not nest: an inner
/// `collect` gets the inner tapes only and the outer one resumes afterwards.
pub fn collect<R>(f: impl FnOnce() -> R) -> (R, Vec<WeightTape>) {
    let outer = ACTIVE.with(|a| a.borrow_mut().replace(Vec::new()));
    let r = f();
    let tapes = ACTIVE.with(|a| std::mem::replace(&mut *a.borrow_mut(), outer)).unwrap_or_default();
    (r, tapes.into_iter().map(|(_, t)| t).collect())
}

/// `x W` (or `x W^T` when `transposed`, for a weight stored `(out, in)`) for a 2-D `x`. While a
/// [`collect`] is active on this thread the weight's gradient is taped (one tape per weight
/// tensor); otherwise a plain matmul.
pub fn matmul_weight(x: &Tensor, w: &Tensor, transposed: bool) -> Result<Tensor> {
    let tape = ACTIVE.with(|a| -> Result<Option<WeightTape>> {
        let mut a = a.borrow_mut();
        let Some(list) = a.as_mut() else { return Ok(None) };
        if let Some((_, t)) = list.iter().find(|(id, t)| *id == w.id() && t.transposed == transposed) {
            return Ok(Some(t.clone()));
        }
        let t = WeightTape::new(w, transposed)?;
        list.push((w.id(), t.clone()));
        Ok(Some(t))
    })?;
    match tape {
        Some(t) if x.rank() == 2 => t.matmul(x),
        _ if transposed => x.broadcast_matmul(&w.t()?),
        _ => x.broadcast_matmul(w),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    /// An RNN-like loop `h = tanh(x_t A + h W^T)` whose loss depends on every frame.
    fn run(a: &Var, w: &Var, xs: &[Tensor]) -> Result<Tensor> {
        let b = xs[0].dim(0)?;
        let mut h = Tensor::zeros((b, 5), DType::F32, &Device::Cpu)?;
        let mut loss = Tensor::zeros((), DType::F32, &Device::Cpu)?;
        // A weight computed from a variable (like the RTN's fused gate matrix).
        let a2 = (a.as_tensor() * 0.5)?.contiguous()?;
        for x in xs {
            h = (matmul_weight(x, &a2, false)? + matmul_weight(&h, w.as_tensor(), true)?)?.tanh()?;
            loss = (loss + h.sqr()?.mean_all()?)?;
        }
        Ok(loss)
    }

    #[test]
    fn taped_gradients_equal_candles() {
        let dev = Device::Cpu;
        let a = Var::from_tensor(
            &Tensor::arange(0f32, 20.0, &dev).unwrap().reshape((4, 5)).unwrap().affine(0.05, -0.4).unwrap(),
        )
        .unwrap();
        let w = Var::from_tensor(
            &Tensor::arange(0f32, 25.0, &dev)
                .unwrap()
                .reshape((5, 5))
                .unwrap()
                .sin()
                .unwrap()
                .affine(0.3, 0.0)
                .unwrap(),
        )
        .unwrap();
        let xs: Vec<Tensor> = (0..6)
            .map(|t| {
                Tensor::arange(0f32, 12.0, &dev)
                    .unwrap()
                    .reshape((3, 4))
                    .unwrap()
                    .affine(0.1, t as f64 * 0.2 - 0.5)
                    .unwrap()
                    .cos()
                    .unwrap()
            })
            .collect();
        let vars = [a.clone(), w.clone()];
        let plain = run(&a, &w, &xs).unwrap().backward().unwrap();
        let (loss, tapes) = collect(|| run(&a, &w, &xs));
        assert_eq!(tapes.len(), 2, "one tape per weight");
        let mut taped = loss.unwrap().backward().unwrap();
        // candle computed no gradient for the taped weights themselves.
        assert!(taped.get(w.as_tensor()).is_none() && taped.get(a.as_tensor()).is_none());
        for t in &tapes {
            assert!(t.finish(&mut taped, &vars).unwrap());
        }
        for v in &vars {
            let p = plain.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
            let q = taped.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
            let scale = p.iter().fold(0f32, |m, x| m.max(x.abs()));
            assert!(scale > 0.0);
            for (x, y) in p.iter().zip(&q) {
                assert!((x - y).abs() <= 1e-5 * scale, "{x} vs {y}");
            }
        }
        // Outside a collection, matmul_weight is a plain matmul (candle's own gradients).
        let again = run(&a, &w, &xs).unwrap().backward().unwrap();
        assert!(again.get(w.as_tensor()).is_some());
    }
}
