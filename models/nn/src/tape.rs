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
use std::collections::HashMap;
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
    /// The custom op's second argument: a leaf variable holding the matrix the forward pass
    /// multiplies by, `(k, n)` and contiguous (the weight itself, or a copy of its transpose).
    forward: Tensor,
    /// The `(n, k)` contiguous matrix the input gradient multiplies by (detached).
    backward: Tensor,
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
    backward: Tensor,
}

impl CustomOp2 for TapedMatMul {
    fn name(&self) -> &'static str {
        "zoo-taped-matmul"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (m, k) = l1.shape().dims2()?;
        let (k2, n) = l2.shape().dims2()?;
        if k != k2 {
            candle_core::bail!("taped matmul: ({m}, {k}) x ({k2}, {n}) do not match");
        }
        Ok((s1.matmul(s2, (1, m, n, k), l1, l2)?, Shape::from((m, n))))
    }

    fn bwd(&self, x: &Tensor, _w: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        // The weight's own gradient is left to `WeightTape::finish` (None here); the input's is
        // needed only where the input depends on something trained.
        let dx = if x.track_op() { Some(grad.matmul(&self.backward)?) } else { None };
        let mut e = self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
        if let Some(slot) = e.grads.get_mut(self.index) {
            *slot = Some(grad.detach());
        }
        Ok((dx, None))
    }
}

/// A contiguous copy of the transpose of a 2-D tensor, detached: blocked, so that both the reads
/// and the writes stay within a few cache lines (candle's strided copy walks one of them a
/// whole row apart per element).
fn transposed_copy(w: &Tensor) -> Result<Tensor> {
    let (r, c) = w.dims2()?;
    let src = w.flatten_all()?.to_vec1::<f32>()?;
    let mut dst = vec![0f32; r * c];
    const B: usize = 32;
    for i0 in (0..r).step_by(B) {
        let i1 = (i0 + B).min(r);
        for j0 in (0..c).step_by(B) {
            let j1 = (j0 + B).min(c);
            for i in i0..i1 {
                let row = &src[i * c..i * c + c];
                for j in j0..j1 {
                    dst[j * r + i] = row[j];
                }
            }
        }
    }
    Tensor::from_vec(dst, (c, r), w.device())
}

impl WeightTape {
    /// A tape for `weight`, `(k, n)` used as `x W`, or `(n, k)` used as `x W^T` when
    /// `transposed`.
    ///
    /// Both products of a frame (the forward `x W` and the input gradient `dy W^T`) multiply by
    /// a contiguous row-major right-hand side, the layout gemm runs fastest on (a transposed
    /// view makes it pack the whole weight at every frame, several times slower at the zoo's
    /// 16-64 rows): the tape keeps the weight in both orientations, one of them a copy made
    /// once per tape (per training step and worker).
    pub fn new(weight: &Tensor, transposed: bool) -> Result<Self> {
        weight.dims2()?;
        if weight.dtype() != candle_core::DType::F32 {
            candle_core::bail!("weight tapes take f32 weights, got {:?}", weight.dtype());
        }
        // The op's second argument must be a leaf that candle's backward walks through but
        // never asks a gradient of: the variable itself when it is already the forward matrix,
        // else a variable copy (one per tape).
        let (forward, backward) = if transposed {
            let t = shared_copy(weight, || Ok(Var::from_tensor(&transposed_copy(weight)?)?.as_tensor().clone()))?;
            (t, weight.detach().contiguous()?)
        } else {
            let f = if weight.is_variable() && weight.is_contiguous() {
                weight.clone()
            } else {
                Var::from_tensor(&weight.contiguous()?)?.as_tensor().clone()
            };
            (f, shared_copy(weight, || transposed_copy(weight))?)
        };
        Ok(WeightTape {
            weight: weight.clone(),
            forward,
            backward,
            transposed,
            entries: Arc::new(Mutex::new(Entries::default())),
        })
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
        let op = TapedMatMul { entries: self.entries.clone(), index, backward: self.backward.clone() };
        x.apply_op2_arc(&self.forward, Arc::new(Box::new(op)))
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
    static SHARED: RefCell<Option<Arc<SharedCopies>>> = const { RefCell::new(None) };
}

/// The transposed copies of variable weights made during one data-parallel step, shared by its
/// workers: the variables do not change within a step, so each copy is made once (by the first
/// worker that needs it) and every worker's gemm reads the same memory, which keeps the two
/// orientations of the weights of both workers within the shared cache.
#[derive(Default)]
pub struct SharedCopies(Mutex<HashMap<TensorId, Arc<Mutex<Option<Tensor>>>>>);

impl std::fmt::Debug for SharedCopies {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.lock().map(|m| m.len()).unwrap_or(0);
        f.debug_struct("SharedCopies").field("weights", &n).finish()
    }
}

/// The copy of `weight` that `make` computes, made once per [`SharedCopies`] for a variable
/// weight while one is active on this thread ([`collect_shared`]); computed weights (a new
/// tensor per worker) get their own copy.
fn shared_copy(weight: &Tensor, make: impl FnOnce() -> Result<Tensor>) -> Result<Tensor> {
    let shared = SHARED.with(|s| s.borrow().clone());
    let Some(shared) = shared.filter(|_| weight.is_variable()) else { return make() };
    let slot = {
        let mut m =
            shared.0.lock().map_err(|_| candle_core::Error::Msg("shared weight copies were poisoned".into()))?;
        m.entry(weight.id()).or_default().clone()
    };
    let mut slot = slot.lock().map_err(|_| candle_core::Error::Msg("a shared weight copy was poisoned".into()))?;
    if let Some(t) = slot.as_ref() {
        return Ok(t.clone());
    }
    let t = make()?;
    *slot = Some(t.clone());
    Ok(t)
}

/// Whether a tape collection is active on this thread (inside a data-parallel training step).
pub fn active() -> bool {
    ACTIVE.with(|a| a.borrow().is_some())
}

/// [`collect`] with the weight copies of `shared` (one data-parallel step's, see
/// [`SharedCopies`]) available to the tapes made on this thread.
pub fn collect_shared<R>(shared: &Arc<SharedCopies>, f: impl FnOnce() -> R) -> (R, Vec<WeightTape>) {
    let outer = SHARED.with(|s| s.borrow_mut().replace(shared.clone()));
    let r = collect(f);
    SHARED.with(|s| *s.borrow_mut() = outer);
    r
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
