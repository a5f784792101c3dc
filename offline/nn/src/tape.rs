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

use crate::act::{BiasAct, column_sums, tensor_values, values};
use candle_core::backend::BackendStorage;
use candle_core::backprop::GradStore;
use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Result, Shape, Tensor, TensorId, Var};
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

#[derive(Default)]
struct Entries {
    inputs: Vec<Tensor>,
    grads: Vec<Option<Tensor>>,
    /// Per frame: whether the tape's bias variable was added ([`WeightTape::linear`]), so that
    /// [`WeightTape::finish`] adds the column sums of that frame's gradient to the bias's.
    biased: Vec<bool>,
    /// The bias variable the tape's frames add (the first one seen).
    bias: Option<Tensor>,
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
    /// A sequence tape ([`frame_leaves`]): the leaf variables holding each frame of `weight`
    /// (then the sequence `(T, ..)`, not a weight).
    frames: Option<Vec<Var>>,
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

/// A taped linear layer in one op: `mask * act(x W + b)` (the activation and the dropout mask
/// optional), its weight gradient left to the tape like [`TapedMatMul`]'s, the bias and input
/// gradients computed in its backward pass. One graph node per layer and frame instead of a
/// matmul, a bias broadcast (whose backward is a strided reduction) and an activation.
struct TapedLinear {
    entries: Arc<Mutex<Entries>>,
    index: usize,
    backward: Tensor,
    /// The bias, activation and dropout mask after the product.
    act: BiasAct,
    /// Whether the bias's gradient is left to the tape (`WeightTape::finish`).
    bias_taped: bool,
    /// The product `x W`, kept by the forward pass when there is an activation or a mask.
    product: Mutex<Option<Vec<f32>>>,
}

/// The most rows, and the most values of the right-hand side, for [`small_matmul`]: a few rows
/// against a matrix that stays in the core's L2 cache (the ARNN's layers), where gemm's fixed
/// cost per call (packing, dispatch: about 2 us, a third of an 8 x 100 x 300 product) is
/// most of the work.
const SMALL_ROWS: usize = 16;
const SMALL_RHS: usize = 1 << 16;

/// `x (m, k) b (k, n)` for contiguous row-major `x` and `b` when `m` and `b` are small
/// ([`SMALL_ROWS`], [`SMALL_RHS`]) and the CPU has AVX2 and FMA; `None` otherwise (use gemm).
/// Each output row is accumulated over `k` in order, whatever the other rows, so a row's
/// values do not depend on the batch it is in. The loops are compiled for the CPU's vector
/// instructions through `pulp`'s dispatch (the one gemm uses).
fn small_matmul(x: &[f32], m: usize, k: usize, b: &[f32], n: usize) -> Option<Vec<f32>> {
    if m == 0 || m > SMALL_ROWS || k * n > SMALL_RHS || x.len() != m * k || b.len() != k * n {
        return None;
    }
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            let mut y = vec![0f32; m * n];
            pulp::Arch::new().dispatch(SmallMatMul { x, m, k, b, n, y: &mut y });
            return Some(y);
        }
    }
    None
}

/// The loops of [`small_matmul`], run by `pulp::Arch::dispatch`.
struct SmallMatMul<'a> {
    x: &'a [f32],
    m: usize,
    k: usize,
    b: &'a [f32],
    n: usize,
    y: &'a mut [f32],
}

impl pulp::WithSimd for SmallMatMul<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        let SmallMatMul { x, m, k, b, n, y } = self;
        // Two vectors of output columns at a time, for up to eight rows, accumulated in
        // registers over `k`; the column block of `b` stays in L1 across the row blocks.
        let cols = 2 * S::F32_LANES;
        let mut j0 = 0;
        while j0 < n {
            let w = cols.min(n - j0);
            let mut r = 0;
            while r + 8 <= m {
                block::<S, 8>(simd, x, k, b, n, y, r, j0, w);
                r += 8;
            }
            while r + 4 <= m {
                block::<S, 4>(simd, x, k, b, n, y, r, j0, w);
                r += 4;
            }
            while r < m {
                block::<S, 1>(simd, x, k, b, n, y, r, j0, w);
                r += 1;
            }
            j0 += cols;
        }
    }
}

/// Rows `r..r + R`, columns `j0..j0 + w` (`w` up to two vectors) of [`SmallMatMul`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn block<S: pulp::Simd, const R: usize>(
    simd: S,
    x: &[f32],
    k: usize,
    b: &[f32],
    n: usize,
    y: &mut [f32],
    r: usize,
    j0: usize,
    w: usize,
) {
    let lanes = S::F32_LANES;
    let (w0, w1) = (w.min(lanes), w.saturating_sub(lanes));
    let mut acc0 = [simd.splat_f32s(0.0); R];
    let mut acc1 = [simd.splat_f32s(0.0); R];
    for kk in 0..k {
        let row = &b[kk * n + j0..kk * n + j0 + w];
        let (b0, b1) = (simd.partial_load_f32s(&row[..w0]), simd.partial_load_f32s(&row[w0..w0 + w1]));
        for i in 0..R {
            let a = simd.splat_f32s(x[(r + i) * k + kk]);
            acc0[i] = simd.mul_add_f32s(a, b0, acc0[i]);
            acc1[i] = simd.mul_add_f32s(a, b1, acc1[i]);
        }
    }
    for i in 0..R {
        let out = &mut y[(r + i) * n + j0..(r + i) * n + j0 + w];
        let (o0, o1) = out.split_at_mut(w0);
        simd.partial_store_f32s(o0, acc0[i]);
        simd.partial_store_f32s(o1, acc1[i]);
    }
}

/// `a (m, k) b (k, n)` for an f32 `a` and a contiguous f32 `b`: [`small_matmul`] when it
/// applies, candle's matmul (gemm) otherwise.
fn matmul_small_or_gemm(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let ((m, k), (k2, n)) = (a.dims2()?, b.dims2()?);
    if k == k2 && m <= SMALL_ROWS && k * n <= SMALL_RHS && b.is_contiguous() {
        let av = a.flatten_all()?.to_vec1::<f32>()?;
        let (s, l) = b.storage_and_layout();
        if let (candle_core::Storage::Cpu(s), Some((o0, o1))) = (&*s, l.contiguous_offsets())
            && let Some(y) = small_matmul(&av, m, k, &s.as_slice::<f32>()?[o0..o1], n)
        {
            return Tensor::from_vec(y, (m, n), a.device());
        }
    }
    a.matmul(b)
}

impl CustomOp3 for TapedLinear {
    fn name(&self) -> &'static str {
        "zoo-taped-linear"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (m, k) = l1.shape().dims2()?;
        let (k2, n) = l2.shape().dims2()?;
        if k != k2 || l3.dims() != [n] {
            candle_core::bail!("taped linear: ({m}, {k}) x ({k2}, {n}) + {:?} do not match", l3.dims());
        }
        self.act.check(m * n)?;
        let small = match (l1.contiguous_offsets(), l2.contiguous_offsets()) {
            (Some(_), Some(_)) => small_matmul(&values(s1, l1, "input")?, m, k, &values(s2, l2, "weight")?, n),
            _ => None,
        };
        let y = match small {
            Some(y) => y,
            None => match s1.matmul(s2, (1, m, n, k), l1, l2)? {
                CpuStorage::F32(v) => v,
                _ => candle_core::bail!("taped linear: f32 only"),
            },
        };
        let bias = values(s3, l3, "bias")?;
        if self.act.is_bias_only() {
            let mut y = y;
            self.act.forward_in_place(&mut y, Some(&bias));
            return Ok((CpuStorage::F32(y), Shape::from((m, n))));
        }
        // The backward pass needs the product (the activation's derivative at `x W + b`).
        let out = self.act.forward(&y, Some(&bias));
        *self.product.lock().map_err(|_| candle_core::Error::Msg("a taped linear op was poisoned".into()))? = Some(y);
        Ok((CpuStorage::F32(out), Shape::from((m, n))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        _w: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let n = b.dim(0)?;
        let dz = if self.act.is_bias_only() {
            grad.detach()
        } else {
            let product =
                self.product.lock().map_err(|_| candle_core::Error::Msg("a taped linear op was poisoned".into()))?;
            let Some(product) = product.as_ref() else { candle_core::bail!("taped linear: backward before forward") };
            let g = self.act.backward(product, Some(&tensor_values(b)?), &tensor_values(grad)?);
            Tensor::from_vec(g, grad.shape(), grad.device())?
        };
        let db = if self.bias_taped {
            None
        } else {
            Some(Tensor::from_vec(column_sums(&tensor_values(&dz)?, n), n, b.device())?)
        };
        let dx = if x.track_op() { Some(matmul_small_or_gemm(&dz, &self.backward)?) } else { None };
        let mut e = self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
        if let Some(slot) = e.grads.get_mut(self.index) {
            *slot = Some(dz);
        }
        Ok((dx, None, db))
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
            frames: None,
        })
    }

    /// `x (m, k)` times the weight, its weight gradient left to [`WeightTape::finish`].
    pub fn matmul(&self, x: &Tensor) -> Result<Tensor> {
        let index = {
            let mut e =
                self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
            e.inputs.push(x.detach());
            e.grads.push(None);
            e.biased.push(false);
            e.inputs.len() - 1
        };
        let op = TapedMatMul { entries: self.entries.clone(), index, backward: self.backward.clone() };
        x.apply_op2_arc(&self.forward, Arc::new(Box::new(op)))
    }

    /// `mask * act(x W + b)` for `x (m, k)` in one op ([`TapedLinear`]), the weight gradient
    /// left to [`WeightTape::finish`]; `bias` `(n)` f32.
    pub fn linear(
        &self,
        x: &Tensor,
        bias: &Tensor,
        act: Option<crate::Activation>,
        mask: Option<Vec<f32>>,
    ) -> Result<Tensor> {
        let (index, bias_taped) = {
            let mut e =
                self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
            // A bias variable's gradient is summed by `finish` over all frames (one edge less
            // per frame in candle's backward pass); any other bias gets it from the op.
            if e.bias.is_none() && bias.is_variable() {
                e.bias = Some(bias.clone());
            }
            let taped = e.bias.as_ref().is_some_and(|b| b.id() == bias.id());
            e.inputs.push(x.detach());
            e.grads.push(None);
            e.biased.push(taped);
            (e.inputs.len() - 1, taped)
        };
        let op = TapedLinear {
            entries: self.entries.clone(),
            index,
            backward: self.backward.clone(),
            act: BiasAct { act, mask },
            bias_taped,
            product: Mutex::new(None),
        };
        x.contiguous()?.apply_op3_arc(&self.forward, &bias.contiguous()?, Arc::new(Box::new(op)))
    }

    /// After the backward pass that produced `grads`: the weight's gradient over every frame
    /// recorded, added to `grads` for the variables among `vars` it depends on (directly when
    /// the weight is one of them, else through one more backward pass over the small graph
    /// that computes the weight from them). Frames whose output did not reach the loss are
    /// skipped. Returns whether anything was added.
    pub fn finish(&self, grads: &mut GradStore, vars: &[Var]) -> Result<bool> {
        if let Some(frames) = &self.frames {
            return self.finish_sequence(frames, grads, vars);
        }
        let (xs, dys, bias_rows, bias): (Vec<Tensor>, Vec<Tensor>, Vec<Tensor>, Option<Tensor>) = {
            let e = self.entries.lock().map_err(|_| candle_core::Error::Msg("a weight tape was poisoned".into()))?;
            let (xs, dys) =
                e.inputs.iter().zip(&e.grads).filter_map(|(x, g)| g.as_ref().map(|g| (x.clone(), g.clone()))).unzip();
            let rows = e.grads.iter().zip(&e.biased).filter_map(|(g, b)| g.clone().filter(|_| *b)).collect();
            (xs, dys, rows, e.bias.clone())
        };
        let mut any = false;
        if let Some(b) = bias.filter(|_| !bias_rows.is_empty()) {
            // The tape's bias variable: its gradient is the column sums of its frames' gradients.
            if let Some(v) = vars.iter().find(|v| v.as_tensor().id() == b.id()) {
                let n = b.dim(0)?;
                let sums = column_sums(&tensor_values(&Tensor::cat(&bias_rows, 0)?)?, n);
                add_grad(grads, v.as_tensor(), Tensor::from_vec(sums, n, b.device())?)?;
                any = true;
            }
        }
        let direct = vars.iter().find(|v| v.as_tensor().id() == self.weight.id());
        if xs.is_empty() || (direct.is_none() && self.weight.is_variable()) {
            // Nothing recorded, or a variable that is not being trained by this step.
            return Ok(any);
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
        for v in vars {
            if let Some(gv) = through.get(v.as_tensor()) {
                add_grad(grads, v.as_tensor(), gv.clone())?;
                any = true;
            }
        }
        Ok(any)
    }
}

impl WeightTape {
    /// A sequence tape's `finish`: the frames' gradients stacked into the sequence's, then one
    /// backward pass through the graph that computed the sequence. Taped weights in that graph
    /// record their frames' gradients meanwhile, so sequence tapes finish first ([`collect`]
    /// returns them first).
    fn finish_sequence(&self, frames: &[Var], grads: &mut GradStore, vars: &[Var]) -> Result<bool> {
        if !self.weight.track_op() {
            return Ok(false);
        }
        let per_frame: Vec<Tensor> = frames
            .iter()
            .map(|f| match grads.get(f.as_tensor()) {
                Some(g) => Ok(g.detach()),
                None => f.as_tensor().zeros_like(),
            })
            .collect::<Result<_>>()?;
        let g = Tensor::stack(&per_frame, 0)?;
        let through = (&self.weight * g)?.sum_all()?.backward()?;
        let mut any = false;
        for v in vars {
            if let Some(gv) = through.get(v.as_tensor()) {
                add_grad(grads, v.as_tensor(), gv.clone())?;
                any = true;
            }
        }
        for f in frames {
            grads.remove(f.as_tensor());
        }
        Ok(any)
    }
}

/// The frames of a sequence `(T, ..)` along its first dimension (`T` tensors of its other
/// dimensions), for a recurrent loop that reads one frame per step.
///
/// While a [`collect`] is active and the sequence needs a gradient, each frame is a leaf
/// variable holding a copy of its values, and a sequence tape (returned by `collect` with the
/// weight tapes) gathers the frames' gradients after the backward pass and sends them through
/// the graph that computed the sequence in one pass: slicing frame by frame would otherwise
/// cost candle's backward pass a whole-sequence gradient per frame (or, through
/// [`crate::recurrent::frames`], a few), and two graph nodes per frame. Otherwise
/// [`crate::recurrent::frames`].
pub fn frame_leaves(seq: &Tensor) -> Result<Vec<Tensor>> {
    if !active() || !seq.track_op() {
        return crate::recurrent::frames(seq, 0);
    }
    let n = seq.dim(0)?;
    let values = seq.detach();
    let frames: Vec<Var> = (0..n).map(|t| Var::from_tensor(&values.get(t)?)).collect::<Result<_>>()?;
    let out = frames.iter().map(|v| v.as_tensor().clone()).collect();
    let tape = WeightTape {
        weight: seq.clone(),
        forward: values.clone(),
        backward: values,
        transposed: false,
        entries: Arc::new(Mutex::new(Entries::default())),
        frames: Some(frames),
    };
    ACTIVE.with(|a| {
        if let Some(list) = a.borrow_mut().as_mut() {
            list.push((seq.id(), tape));
        }
    });
    Ok(out)
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
    // Sequence tapes first, the last made first: a sequence tape's `finish` feeds the tapes of
    // the graph behind its sequence (weights, or the frames of an earlier sequence).
    let (seqs, weights): (Vec<WeightTape>, Vec<WeightTape>) =
        tapes.into_iter().map(|(_, t)| t).partition(|t| t.frames.is_some());
    (r, seqs.into_iter().rev().chain(weights).collect())
}

/// `mask * act(x W^T + b)` for a 2-D `x` and a weight stored `(out, in)`: while a [`collect`]
/// is active on this thread one taped op ([`WeightTape::linear`]) when everything is f32;
/// otherwise [`matmul_weight`] and [`crate::act`]'s ops.
pub fn linear(
    x: &Tensor,
    w: &Tensor,
    bias: &Tensor,
    act: Option<crate::Activation>,
    mask: Option<Vec<f32>>,
) -> Result<Tensor> {
    let f32s = [x, w, bias].iter().all(|t| t.dtype() == candle_core::DType::F32) && bias.rank() == 1;
    if x.rank() == 2
        && f32s
        && let Some(t) = tape_of(w, true)?
    {
        return t.linear(x, bias, act, mask);
    }
    let y = matmul_weight(x, w, true)?;
    match (act, mask) {
        (Some(a), mask) => crate::act::bias_act(&y, Some(bias), a, mask),
        (None, None) => crate::act::bias_add(&y, bias),
        (None, Some(m)) => crate::act::apply_mask(&crate::act::bias_add(&y, bias)?, m),
    }
}

/// The tape of `w` in this thread's active collection (made on first use), `None` when no
/// collection is active.
fn tape_of(w: &Tensor, transposed: bool) -> Result<Option<WeightTape>> {
    ACTIVE.with(|a| -> Result<Option<WeightTape>> {
        let mut a = a.borrow_mut();
        let Some(list) = a.as_mut() else { return Ok(None) };
        if let Some((_, t)) =
            list.iter().find(|(id, t)| *id == w.id() && t.transposed == transposed && t.frames.is_none())
        {
            return Ok(Some(t.clone()));
        }
        let t = WeightTape::new(w, transposed)?;
        list.push((w.id(), t.clone()));
        Ok(Some(t))
    })
}

/// `x W` (or `x W^T` when `transposed`, for a weight stored `(out, in)`) for a 2-D `x`. While a
/// [`collect`] is active on this thread the weight's gradient is taped (one tape per weight
/// tensor); otherwise a plain matmul.
pub fn matmul_weight(x: &Tensor, w: &Tensor, transposed: bool) -> Result<Tensor> {
    match tape_of(w, transposed)? {
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

    /// A variable of `shape` holding `sin(0.37 i + phase)`.
    fn wave(shape: (usize, usize), phase: f64) -> Var {
        let n = (shape.0 * shape.1) as f32;
        let t = Tensor::arange(0f32, n, &Device::Cpu).unwrap().affine(0.37, phase).unwrap().sin().unwrap();
        Var::from_tensor(&t.reshape(shape).unwrap()).unwrap()
    }

    /// The gradients of `vars` in `a` and `b` agree within 1e-5 of each one's largest.
    fn assert_same_grads(a: &GradStore, b: &GradStore, vars: &[Var], what: &str) {
        for v in vars {
            assert_close(a.get(v.as_tensor()).unwrap(), b.get(v.as_tensor()).unwrap(), what);
        }
    }

    /// `got` equals `want` within 1e-5 of `want`'s largest value.
    fn assert_close(want: &Tensor, got: &Tensor, what: &str) {
        let p = want.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let q = got.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(p.len(), q.len(), "{what}");
        let scale = p.iter().fold(1e-3f32, |m, x| m.max(x.abs()));
        for (x, y) in p.iter().zip(&q) {
            assert!((x - y).abs() <= 1e-5 * scale, "{what}: {x} vs {y}");
        }
    }

    /// A loop reading the frames of a sequence computed by a taped layer (`frame_leaves`), with
    /// a recurrent taped weight: the gradients equal candle's own (no tapes, sliced frames).
    #[test]
    fn sequence_tape_gradients_equal_candles() {
        let dev = Device::Cpu;
        let (a, w) = (wave((4, 3), 0.4), wave((4, 4), -0.2));
        let b = Var::from_tensor(&Tensor::new(&[0.1f32, -0.2, 0.05, 0.3], &dev).unwrap()).unwrap();
        let xs = Tensor::arange(0f32, 5.0 * 2.0 * 3.0, &dev).unwrap().affine(0.1, -1.0).unwrap().cos().unwrap();
        let xs = xs.reshape((5, 2, 3)).unwrap();
        let vars = [a.clone(), w.clone(), b.clone()];
        let run = || -> Result<Tensor> {
            // The sequence: a SELU layer over every frame at once, (5, 2, 4).
            let seq = linear(&xs.reshape((10, 3))?, a.as_tensor(), b.as_tensor(), Some(crate::Activation::Selu), None)?
                .reshape((5, 2, 4))?;
            let mut h = Tensor::zeros((2, 4), DType::F32, &dev)?;
            let mut loss = Tensor::zeros((), DType::F32, &dev)?;
            for x in frame_leaves(&seq)? {
                h = (x + matmul_weight(&h, w.as_tensor(), true)?)?.tanh()?;
                loss = (loss + h.sqr()?.mean_all()?)?;
            }
            Ok(loss)
        };
        let plain = run().unwrap().backward().unwrap();
        let (loss, tapes) = collect(run);
        assert!(tapes[0].frames.is_some(), "the sequence tape comes first");
        let mut taped = loss.unwrap().backward().unwrap();
        for t in &tapes {
            t.finish(&mut taped, &vars).unwrap();
        }
        assert_same_grads(&plain, &taped, &vars, "sequence tape");
    }

    /// The small-matmul kernel against candle's matmul, for every row count it takes (blocks of
    /// 8, 4 and single rows) and column counts with partial vectors.
    #[test]
    fn small_matmul_equals_candles() {
        for (k, n) in [(37, 70), (100, 300), (3, 5), (64, 33)] {
            let b = wave((k, n), 0.3);
            for m in 1..=SMALL_ROWS {
                let x = wave((m, k), -0.7 + m as f64);
                let want = x.as_tensor().matmul(b.as_tensor()).unwrap();
                let got = matmul_small_or_gemm(x.as_tensor(), b.as_tensor()).unwrap();
                assert_close(&want, &got, &format!("{m} x {k} x {n}"));
            }
        }
    }

    /// The taped linear op (bias, activation, dropout mask in one op) against candle's ops:
    /// the loss, and the gradients of the weight, the bias and the input.
    #[test]
    fn taped_linear_equals_candles_ops() {
        let dev = Device::Cpu;
        let (w, x) = (wave((5, 3), 0.3), wave((4, 3), -1.0));
        let b = Var::from_tensor(&Tensor::new(&[0.1f32, -0.3, 0.2, 0.0, -0.05], &dev).unwrap()).unwrap();
        let m: Vec<f32> = (0..20).map(|i| if i % 4 == 1 { 0.0 } else { 1.25 }).collect();
        let vars = [w.clone(), b.clone(), x.clone()];
        for act in [None, Some(crate::Activation::Selu), Some(crate::Activation::LeakyRelu(0.2))] {
            for mask in [None, Some(m.clone())] {
                // Two frames through the same weight (so that the tape sums them).
                let run = || -> Result<Tensor> {
                    let h = linear(x.as_tensor(), w.as_tensor(), b.as_tensor(), act, mask.clone())?;
                    let h2 = linear(&(x.as_tensor() * 0.5)?, w.as_tensor(), b.as_tensor(), act, None)?;
                    (h.sqr()?.sum_all()? + (h2 * 0.7)?.sum_all()?)? * 0.5
                };
                let plain_loss = run().unwrap();
                let plain = plain_loss.backward().unwrap();
                let (loss, tapes) = collect(run);
                let loss = loss.unwrap();
                let what = format!("{act:?}, mask {}", mask.is_some());
                assert_eq!(tapes.len(), 1, "{what}: one tape");
                let diff = (loss.to_scalar::<f32>().unwrap() - plain_loss.to_scalar::<f32>().unwrap()).abs();
                assert!(diff <= 1e-5, "{what}: loss differs by {diff}");
                let mut taped = loss.backward().unwrap();
                tapes[0].finish(&mut taped, &vars).unwrap();
                assert_same_grads(&plain, &taped, &vars, &what);
            }
        }
    }
}
