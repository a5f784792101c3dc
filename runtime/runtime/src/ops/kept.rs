//! Node outputs a plan's state keeps from one run to the next, so that a step allocates nothing.
//!
//! tract evaluates a node into new tensors on every run. The zoo ops, and the few tract ops a
//! step graph keeps around them ([`keep_outputs`] swaps them for [`KeptTract`] when a
//! plan is made), instead write into tensors their node's state holds: tract gets a shared
//! reference to each, drops it when the run is over, and on the next run the node writes into
//! the same memory again. A tensor something still holds (a caller keeping a run's outputs) is
//! left to its holder, and the node makes a new one.
//!
//! The replaced tract ops compute exactly what tract's do (the same kernels, or copies and
//! exact arithmetic), so results do not change by a bit.

use std::sync::Arc;
use tract_onnx::tract_core::ops::array::{Gather, Slice, TypedConcat};
use tract_onnx::tract_core::ops::binary::{OptBinByScalar, OptBinChain, OptBinUnicast, TypedBinOp};
use tract_onnx::tract_core::ops::change_axes::{AxisOp, IntoShape};
use tract_onnx::tract_core::ops::element_wise::ElementWiseOp;
use tract_onnx::tract_core::ops::nn::{Softmax, SoftmaxKind};
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};
use tract_onnx::tract_hir::internal::*;
use tract_onnx::tract_hir::prelude::tract_linalg;
use tract_onnx::tract_hir::prelude::tract_linalg::Func;
use tract_onnx::tract_hir::prelude::tract_linalg::element_wise::ElementWise;
use tract_onnx::tract_hir::prelude::tract_linalg::reduce::{MapReduce, Reduce};

/// The f32 output tensors of one node, kept between runs.
#[derive(Clone, Debug, Default)]
pub(crate) struct Kept(TVec<Option<Arc<Tensor>>>);

impl Kept {
    /// The node's outputs shaped `shapes`, for the op to overwrite whole: each the tensor of the
    /// last run when nothing else holds it any more and its shape is the same, else a new one.
    pub(crate) fn outputs(&mut self, shapes: &[&[usize]]) -> TractResult<TVec<&mut Tensor>> {
        if self.0.len() < shapes.len() {
            self.0.resize(shapes.len(), None);
        }
        for (slot, shape) in self.0.iter_mut().zip(shapes) {
            if !slot.as_mut().and_then(Arc::get_mut).is_some_and(|t| t.shape() == *shape) {
                *slot = Some(Arc::new(Tensor::zero::<f32>(shape)?));
            }
        }
        self.0[..shapes.len()]
            .iter_mut()
            .map(|slot| slot.as_mut().and_then(Arc::get_mut).context("a kept output is shared"))
            .collect()
    }

    /// Writes the one output, shaped `shape` (see [`Kept::outputs`]), with `f`.
    pub(crate) fn write(&mut self, shape: &[usize], f: impl FnOnce(&mut [f32]) -> TractResult<()>) -> TractResult<()> {
        let mut out = self.outputs(&[shape])?;
        let mut view = out[0].try_as_plain_ram_mut()?;
        f(view.as_slice_mut::<f32>()?)
    }

    /// References to the outputs written last, for tract.
    pub(crate) fn values(&self) -> TractResult<TVec<TValue>> {
        self.0.iter().map(|t| t.clone().map(TValue::from_const).context("an output was not written")).collect()
    }
}

/// An op that writes its outputs into [`Kept`] tensors.
pub(crate) trait WritesKept: Op + Clone {
    /// Writes this node's outputs for `inputs` into `kept` (every output, whole).
    fn eval_kept(&self, inputs: &[TValue], kept: &mut Kept) -> TractResult<()>;
}

/// The state of a node whose op writes into kept tensors.
#[derive(Clone)]
pub(crate) struct KeptState {
    kept: Kept,
    /// The op's [`WritesKept::eval_kept`], its type checked.
    eval: fn(&dyn Op, &[TValue], &mut Kept) -> TractResult<()>,
}

impl KeptState {
    pub(crate) fn boxed<O: WritesKept>() -> Box<dyn OpState> {
        fn eval<O: WritesKept>(op: &dyn Op, inputs: &[TValue], kept: &mut Kept) -> TractResult<()> {
            op.downcast_ref::<O>().context("kept outputs on another op")?.eval_kept(inputs, kept)
        }
        Box::new(KeptState { kept: Kept::default(), eval: eval::<O> })
    }

    /// Runs `op` on `inputs` into the kept tensors; references to them.
    pub(crate) fn run(&mut self, op: &dyn Op, inputs: &[TValue]) -> TractResult<TVec<TValue>> {
        (self.eval)(op, inputs, &mut self.kept)?;
        self.kept.values()
    }
}

impl std::fmt::Debug for KeptState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "KeptState({} outputs)", self.kept.0.len())
    }
}

impl OpState for KeptState {
    fn eval(&mut self, _ctx: &EvalContext, op: &dyn Op, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        self.run(op, &inputs)
    }

    fn reset_lanes(&mut self, _lanes: &[LaneId]) -> TractResult<()> {
        Ok(())
    }
}

/// Whether [`run`] can run `plan` itself: every shape in it is concrete or made of symbols its
/// inputs' shapes give (a batch size), which the first run resolves and later runs keep.
pub(crate) fn runs_itself(plan: &TypedRunnableModel) -> bool {
    let model = plan.model();
    let Ok(inputs) = model.input_outlets() else { return false };
    let mut given = std::collections::HashSet::new();
    for &o in inputs {
        match model.outlet_fact(o) {
            Ok(f) => f.shape.iter().for_each(|d| given.extend(d.symbols())),
            Err(_) => return false,
        }
    }
    model
        .nodes()
        .iter()
        .all(|n| n.outputs.iter().all(|o| o.fact.shape.iter().all(|d| d.symbols().iter().all(|s| given.contains(s)))))
}

/// Runs a plan like tract's `SimpleState::run`, without allocating once the plan's nodes have
/// their kept tensors: tract gathers each node's inputs, and the plan's outputs, into vectors
/// that allocate past four entries, and resolves a symbolic plan's symbols anew on every run;
/// here the vectors are `scratch` and `outputs` (reused) and the symbols stay resolved between
/// runs (a state runs one batch size). A plan that does not [`runs_itself`], and a state's first
/// run (which sets up its value table), go through tract's `run`. The outputs are left in
/// `outputs` (cleared first; clear it once read, so that the next run can write into the same
/// tensors).
pub(crate) fn run(
    state: &mut TypedSimpleState,
    itself: bool,
    inputs: impl ExactSizeIterator<Item = TValue>,
    scratch: &mut Vec<TValue>,
    outputs: &mut Vec<TValue>,
) -> TractResult<()> {
    outputs.clear();
    if state.turn_state.values.is_empty() || !itself {
        let values: TVec<TValue> = inputs.collect();
        outputs.extend(state.run(values)?);
        return Ok(());
    }
    let plan = state.plan().clone();
    let ran = (|| -> TractResult<()> {
        set_inputs(state, inputs)?;
        for &n in plan.order_without_consts() {
            compute(state, n, scratch)?;
        }
        read_outputs(state, outputs)
    })();
    scratch.clear();
    // tract's `reset_turn`, less the symbols.
    for &n in plan.order_without_consts() {
        state.turn_state.values[n] = None;
    }
    if ran.is_err() {
        state.reset_turn()?;
    }
    ran
}

/// Whether `state` keeps nothing from one run to the next but its nodes' kept tensors, so that
/// it can run another input after `reset_turn` as a fresh state would.
pub(crate) fn keeps_only_outputs(state: &TypedSimpleState) -> bool {
    state.op_states.iter().flatten().all(|s| s.downcast_ref::<KeptState>().is_some())
}

/// Runs node `n` of `state`'s plan as tract's `SimpleState::compute_one` does, its inputs
/// gathered in `scratch` (reused) and handed as a slice to a node writing kept tensors; a model
/// input already set is left as it is.
pub(crate) fn compute(state: &mut TypedSimpleState, n: usize, scratch: &mut Vec<TValue>) -> TractResult<()> {
    let plan = state.plan().clone();
    let node = plan.model().node(n);
    if node.inputs.is_empty() && state.turn_state.values[n].is_some() {
        return Ok(());
    }
    scratch.clear();
    for i in &node.inputs {
        let value = state.turn_state.values[i.node].as_ref().context("a node's input was not computed")?;
        scratch.push(value[i.slot].clone());
    }
    match state.op_states[n].as_mut().and_then(|s| s.downcast_mut::<KeptState>()) {
        Some(kept) => {
            let values = kept.run(node.op(), scratch);
            scratch.clear();
            state.turn_state.values[n] = Some(values?);
            Ok(())
        }
        None => state.compute_one_with_inputs(n, scratch.drain(..).collect()),
    }
}

/// The plan's outputs of the run in `state` into `outputs` (cleared first).
pub(crate) fn read_outputs(state: &TypedSimpleState, outputs: &mut Vec<TValue>) -> TractResult<()> {
    outputs.clear();
    for o in 0..state.model().output_outlets()?.len() {
        outputs.push(state.output(o)?.clone());
    }
    Ok(())
}

/// Sets `state`'s model inputs one by one (tract's `set_inputs` takes a vector that allocates
/// past four).
pub(crate) fn set_inputs(state: &mut TypedSimpleState, inputs: impl Iterator<Item = TValue>) -> TractResult<()> {
    for (ix, t) in inputs.enumerate() {
        state.set_input(ix, t)?;
    }
    Ok(())
}

/// The `eval` and `state` of an [`EvalOp`] for a [`WritesKept`] op: out of a plan it writes
/// into new tensors; in a plan its node's state keeps them.
macro_rules! kept_eval {
    () => {
        fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
            let mut kept = $crate::ops::kept::Kept::default();
            $crate::ops::kept::WritesKept::eval_kept(self, &inputs, &mut kept)?;
            kept.values()
        }

        fn state(&self, _ctx: &EvalContext) -> TractResult<Option<Box<dyn OpState>>> {
            Ok(Some($crate::ops::kept::KeptState::boxed::<Self>()))
        }
    };
}
pub(crate) use kept_eval;

pub(crate) fn plain_f32(t: &Tensor) -> TractResult<&[f32]> {
    t.try_as_plain_ram()?.as_slice::<f32>()
}

/// An elementwise binary operation of tract's, exactly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Bin {
    Add,
    Sub,
    /// `b - a`.
    SubF,
    Mul,
    Min,
    Max,
}

impl Bin {
    fn named(name: &str) -> Option<Bin> {
        Some(match name {
            "Add" => Bin::Add,
            "Sub" => Bin::Sub,
            "SubF" => Bin::SubF,
            "Mul" => Bin::Mul,
            "Min" => Bin::Min,
            "Max" => Bin::Max,
            _ => return None,
        })
    }

    fn apply(self, a: f32, b: f32) -> f32 {
        match self {
            Bin::Add => a + b,
            Bin::Sub => a - b,
            Bin::SubF => b - a,
            Bin::Mul => a * b,
            Bin::Min => {
                if a < b {
                    a
                } else {
                    b
                }
            }
            Bin::Max => {
                if a > b {
                    a
                } else {
                    b
                }
            }
        }
    }
}

/// How a binary step's second operand lines up with the first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Share {
    /// `b` is one row that every block of `a` uses element by element.
    Row,
    /// `b` holds one scalar per block of `a`.
    PerBlock,
}

/// What a replaced tract op computes.
#[derive(Clone, Debug)]
enum Work {
    Concat {
        axis: usize,
    },
    Slice {
        axis: usize,
        start: usize,
        end: usize,
    },
    /// `a`, then each step with its operand (inputs 1, 2, ...).
    Chain(TVec<(Bin, Share)>),
    /// `a` and `b` broadcast against each other (numpy's rules).
    Broadcast(Bin),
    /// The values as they are, in another shape (axes of one added or removed, a reshape).
    Reshape(TVec<usize>),
    /// Axis `from` moved to position `to` (a transposition).
    Move {
        from: usize,
        to: usize,
    },
    /// Input 0's blocks along `axis` picked by the integers of input 1 (ONNX `Gather`).
    Gather {
        axis: usize,
    },
    /// A unary kernel of tract-linalg in place.
    Map(Arc<dyn ElementWise<f32>>),
    /// Softmax over the trailing `row` values, on tract's kernels.
    Softmax {
        max: Arc<dyn Reduce<f32>>,
        exp_sum: Arc<dyn MapReduce<f32, f32>>,
        scale: Arc<dyn ElementWise<f32, f32>>,
    },
}

/// A tract op of a step graph, run into kept tensors; `original` gives its output facts.
#[derive(Clone, Debug)]
pub(crate) struct KeptTract {
    original: Box<dyn TypedOp>,
    work: Work,
}

impl PartialEq for KeptTract {
    fn eq(&self, other: &Self) -> bool {
        // Two nodes are equal when the ops they replaced are.
        self.original == other.original
    }
}
impl Eq for KeptTract {}

impl Op for KeptTract {
    fn name(&self) -> StaticName {
        format!("Kept{}", self.original.name()).into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        self.original.info()
    }

    op_as_typed_op!();
}

impl EvalOp for KeptTract {
    op_out_of_plan!();
    kept_eval!();
}

impl TypedOp for KeptTract {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        self.original.output_facts(inputs)
    }
}

/// Whether `t`'s values lie in row-major order (the strides of its axes of one value do not
/// matter: tract leaves odd ones there after inserting an axis).
fn row_major(t: &Tensor) -> bool {
    let mut expected = 1isize;
    for (&d, &s) in t.shape().iter().zip(t.strides()).rev() {
        if d > 1 && s != expected {
            return false;
        }
        expected *= d as isize;
    }
    t.len() == t.shape().iter().product::<usize>()
}

/// The f32 data of `t`, row-major.
fn natural(t: &Tensor) -> TractResult<&[f32]> {
    ensure!(row_major(t), "a kept op got a strided tensor");
    plain_f32(t)
}

impl WritesKept for KeptTract {
    fn eval_kept(&self, inputs: &[TValue], kept: &mut Kept) -> TractResult<()> {
        let x = inputs.first().context("a kept op without inputs")?;
        if !inputs.iter().all(|t| row_major(t)) {
            // Not met in zoo's graphs: tract's own op, its results copied.
            let results = self.original.eval(&EvalContext::out_of_plan(), inputs.iter().cloned().collect())?;
            let shapes: TVec<&[usize]> = results.iter().map(|t| t.shape()).collect();
            for (out, r) in kept.outputs(&shapes)?.into_iter().zip(&results) {
                out.try_as_plain_ram_mut()?.as_slice_mut::<f32>()?.copy_from_slice(plain_f32(r)?);
            }
            return Ok(());
        }
        match &self.work {
            Work::Concat { axis } => {
                let axis = *axis;
                let mut shape: TVec<usize> = x.shape().into();
                shape[axis] = inputs.iter().map(|t| t.shape()[axis]).sum();
                let outer: usize = shape[..axis].iter().product();
                kept.write(&shape, |out| {
                    let mut at = 0;
                    for o in 0..outer {
                        for t in inputs {
                            let part: usize = t.shape()[axis..].iter().product();
                            out[at..at + part].copy_from_slice(&natural(t)?[o * part..(o + 1) * part]);
                            at += part;
                        }
                    }
                    Ok(())
                })
            }
            Work::Slice { axis, start, end } => {
                let mut shape: TVec<usize> = x.shape().into();
                let (axis, len) = (*axis, end - start);
                ensure!(*end <= shape[axis], "a slice past its axis");
                let inner: usize = shape[axis + 1..].iter().product();
                let (outer, whole): (usize, usize) = (shape[..axis].iter().product(), shape[axis] * inner);
                shape[axis] = len;
                let xs = natural(x)?;
                kept.write(&shape, |out| {
                    for o in 0..outer {
                        out[o * len * inner..(o + 1) * len * inner]
                            .copy_from_slice(&xs[o * whole + start * inner..][..len * inner]);
                    }
                    Ok(())
                })
            }
            Work::Chain(steps) => kept.write(x.shape(), |out| {
                out.copy_from_slice(natural(x)?);
                for ((bin, share), b) in steps.iter().zip(&inputs[1..]) {
                    let b = natural(b)?;
                    ensure!(!b.is_empty() && out.len() % b.len() == 0, "a binary operand that does not divide");
                    match share {
                        Share::Row => {
                            for block in out.chunks_exact_mut(b.len()) {
                                block.iter_mut().zip(b).for_each(|(a, b)| *a = bin.apply(*a, *b));
                            }
                        }
                        Share::PerBlock => {
                            let period = out.len() / b.len();
                            for (block, b) in out.chunks_exact_mut(period).zip(b) {
                                block.iter_mut().for_each(|a| *a = bin.apply(*a, *b));
                            }
                        }
                    }
                }
                Ok(())
            }),
            Work::Broadcast(bin) => {
                let (a, b) = (x, inputs.get(1).context("a binary op with one input")?);
                let rank = a.rank().max(b.rank());
                let dim = |t: &Tensor, i: usize| if i + t.rank() < rank { 1 } else { t.shape()[i + t.rank() - rank] };
                let mut shape: TVec<usize> = tvec![0; rank];
                // Each input's stride per output axis (0 where it is broadcast).
                let (mut sa, mut sb): (TVec<usize>, TVec<usize>) = (tvec![0; rank], tvec![0; rank]);
                let (mut ta, mut tb) = (1, 1);
                for i in (0..rank).rev() {
                    let (da, db) = (dim(a, i), dim(b, i));
                    ensure!(
                        da == db || da == 1 || db == 1,
                        "shapes {:?} and {:?} do not broadcast",
                        a.shape(),
                        b.shape()
                    );
                    shape[i] = da.max(db);
                    sa[i] = if da == 1 { 0 } else { ta };
                    sb[i] = if db == 1 { 0 } else { tb };
                    ta *= da;
                    tb *= db;
                }
                let (xa, xb) = (natural(a)?, natural(b)?);
                kept.write(&shape, |out| {
                    let last = shape.last().copied().unwrap_or(1).max(1);
                    let (la, lb) = (sa.last().copied().unwrap_or(0), sb.last().copied().unwrap_or(0));
                    for (row, o) in out.chunks_exact_mut(last).enumerate() {
                        // The row's offset in each input, from its index over the outer axes.
                        let (mut oa, mut ob, mut r) = (0, 0, row);
                        for i in (0..rank.saturating_sub(1)).rev() {
                            let k = r % shape[i];
                            r /= shape[i];
                            oa += k * sa[i];
                            ob += k * sb[i];
                        }
                        for (j, o) in o.iter_mut().enumerate() {
                            *o = bin.apply(xa[oa + j * la], xb[ob + j * lb]);
                        }
                    }
                    Ok(())
                })
            }
            Work::Reshape(shape) => kept.write(shape, |out| {
                let xs = natural(x)?;
                ensure!(xs.len() == out.len(), "a reshape of {} values into {}", xs.len(), out.len());
                out.copy_from_slice(xs);
                Ok(())
            }),
            Work::Move { from, to } => {
                let rank = x.rank();
                ensure!(*from < rank && *to < rank, "an axis move past the rank");
                // Output axis i is input axis perm[i].
                let mut perm: TVec<usize> = (0..rank).collect();
                let moved = perm.remove(*from);
                perm.insert(*to, moved);
                let strides = Tensor::natural_strides(x.shape());
                let shape: TVec<usize> = perm.iter().map(|&a| x.shape()[a]).collect();
                let xs = natural(x)?;
                kept.write(&shape, |out| {
                    let last = shape.last().copied().unwrap_or(1).max(1);
                    let step = perm.last().map_or(0, |&a| strides[a] as usize);
                    for (row, o) in out.chunks_exact_mut(last).enumerate() {
                        let (mut at, mut r) = (0, row);
                        for i in (0..rank.saturating_sub(1)).rev() {
                            at += (r % shape[i]) * strides[perm[i]] as usize;
                            r /= shape[i];
                        }
                        o.iter_mut().enumerate().for_each(|(j, o)| *o = xs[at + j * step]);
                    }
                    Ok(())
                })
            }
            Work::Gather { axis } => {
                let axis = *axis;
                let picks = inputs.get(1).context("a gather without indices")?;
                let dim = x.shape()[axis];
                let inner: usize = x.shape()[axis + 1..].iter().product();
                let outer: usize = x.shape()[..axis].iter().product();
                let mut shape: TVec<usize> = x.shape()[..axis].into();
                shape.extend(picks.shape().iter().copied());
                shape.extend(x.shape()[axis + 1..].iter().copied());
                let xs = natural(x)?;
                let picks = picks.try_as_plain_ram()?;
                let index = |i: usize| -> TractResult<usize> {
                    let v = match picks.datum_type() {
                        DatumType::I64 => picks.as_slice::<i64>()?[i],
                        DatumType::I32 => picks.as_slice::<i32>()?[i] as i64,
                        dt => bail!("gather indices of type {dt:?}"),
                    };
                    let v = if v < 0 { v + dim as i64 } else { v };
                    ensure!((0..dim as i64).contains(&v), "gather index {v} out of 0..{dim}");
                    Ok(v as usize)
                };
                let count: usize = picks.shape().iter().product();
                kept.write(&shape, |out| {
                    let mut at = 0;
                    for o in 0..outer {
                        for i in 0..count {
                            let from = (o * dim + index(i)?) * inner;
                            out[at..at + inner].copy_from_slice(&xs[from..from + inner]);
                            at += inner;
                        }
                    }
                    Ok(())
                })
            }
            Work::Map(kernel) => kept.write(x.shape(), |out| {
                out.copy_from_slice(natural(x)?);
                kernel.run(out)
            }),
            Work::Softmax { max, exp_sum, scale } => {
                let row = *x.shape().last().context("a softmax of a scalar")?;
                kept.write(x.shape(), |out| {
                    out.copy_from_slice(natural(x)?);
                    if row == 0 {
                        return Ok(());
                    }
                    // tract's own choice of kernels for the trailing axis (`Softmax::eval`).
                    match tract_linalg::routines::softmax_rows_f32().filter(|_| row.is_multiple_of(4)) {
                        Some(rows) => rows(out, row),
                        None => {
                            for r in out.chunks_mut(row) {
                                let m = max.run(r)?;
                                let sum = exp_sum.run_with_params(r, m)?;
                                scale.run_with_params(r, sum.recip())?;
                            }
                        }
                    }
                    Ok(())
                })
            }
        }
    }
}

/// What node `id` of `model` computes, when it is a tract op [`KeptTract`] runs: f32 in and
/// out, concrete slices, binary steps tract-linalg runs exactly, softmax over the last axis.
fn work(model: &TypedModel, id: usize) -> TractResult<Option<Work>> {
    let node = model.node(id);
    let facts = model.node_input_facts(id)?;
    let op = node.op();
    let f32_out = node.outputs.iter().all(|o| o.fact.datum_type == f32::datum_type());
    if let Some(g) = op.downcast_ref::<Gather>() {
        let ints = facts.get(1).is_some_and(|f| matches!(f.datum_type, DatumType::I64 | DatumType::I32));
        let ok = f32_out && g.output_type.is_none() && facts[0].datum_type == f32::datum_type() && ints;
        return Ok(ok.then_some(Work::Gather { axis: g.axis }));
    }
    let f32_only = facts.iter().all(|f| f.datum_type == f32::datum_type()) && f32_out;
    if !f32_only || facts.is_empty() {
        return Ok(None);
    }
    // The output's shape, when the plan fixes it.
    let out_shape = || node.outputs.first().and_then(|o| o.fact.shape.as_concrete().map(TVec::from));
    let bin = |name: &str| Bin::named(name);
    Ok(if let Some(c) = op.downcast_ref::<TypedConcat>() {
        Some(Work::Concat { axis: c.axis })
    } else if let Some(a) = op.downcast_ref::<AxisOp>() {
        match a {
            AxisOp::Add(_) | AxisOp::Rm(_) | AxisOp::Reshape(..) => out_shape().map(Work::Reshape),
            AxisOp::Move(from, to) => Some(Work::Move { from: *from, to: *to }),
        }
    } else if let Some(r) = op.downcast_ref::<IntoShape>() {
        let plain = *r.strides == *Tensor::natural_strides(&r.dims);
        if plain { out_shape().map(Work::Reshape) } else { None }
    } else if let Some(s) = op.downcast_ref::<Slice>() {
        match (s.start.to_usize(), s.end.to_usize()) {
            (Ok(start), Ok(end)) if start <= end => Some(Work::Slice { axis: s.axis, start, end }),
            _ => None,
        }
    } else if let Some(b) = op.downcast_ref::<TypedBinOp>() {
        if b.1.is_none() && facts.len() == 2 { bin(&b.0.name()).map(Work::Broadcast) } else { None }
    } else if let Some(b) = op.downcast_ref::<OptBinUnicast>() {
        bin(&b.binop.name()).map(|b| Work::Chain(tvec![(b, Share::Row)]))
    } else if let Some(b) = op.downcast_ref::<OptBinByScalar>() {
        bin(&b.binop.name()).map(|b| Work::Chain(tvec![(b, Share::PerBlock)]))
    } else if let Some(c) = op.downcast_ref::<OptBinChain>() {
        let steps: Option<TVec<(Bin, Share)>> = c
            .steps
            .iter()
            .map(|s| {
                let share = match s.share {
                    tract_linalg::multithread::BShare::Lockstep => Share::Row,
                    tract_linalg::multithread::BShare::PerBlock => Share::PerBlock,
                };
                bin(&s.binop.name()).map(|b| (b, share))
            })
            .collect();
        steps.map(Work::Chain)
    } else if let Some(e) = op.downcast_ref::<ElementWiseOp>() {
        let func = match &*e.0.name() {
            "Exp" => Some(Func::Exp),
            "Sigmoid" => Some(Func::Sigmoid),
            "Tanh" => Some(Func::Tanh),
            _ => None,
        };
        match func {
            Some(f) if e.1.is_none() => Some(Work::Map(Arc::from(f.ew_f32()?))),
            _ => None,
        }
    } else if let Some(s) = op.downcast_ref::<Softmax>() {
        let rank = facts[0].rank();
        (s.kind == SoftmaxKind::Softmax && s.quant_output_dt.is_none() && *s.axes == [rank - 1])
            .then_some(())
            .map(|()| -> TractResult<Work> {
                Ok(Work::Softmax {
                    max: Arc::from(Func::ReduceMax.reduce_f32()?),
                    exp_sum: Arc::from(Func::Softmax2.map_reduce_f32()?),
                    scale: Arc::from(Func::MulByScalar.ew_f32_param()?),
                })
            })
            .transpose()?
    } else {
        None
    })
}

/// Swaps the tract ops of `model` that [`KeptTract`] runs for it (see the module's doc).
/// `ZOO_RUNTIME_KEEP=0` leaves them (for comparisons).
pub(crate) fn keep_outputs(model: &mut TypedModel) -> TractResult<()> {
    if std::env::var("ZOO_RUNTIME_KEEP").is_ok_and(|v| v == "0") {
        return Ok(());
    }
    for id in 0..model.nodes().len() {
        if let Some(work) = work(model, id)? {
            let original = model.node(id).op.clone();
            model.node_mut(id).op = Box::new(KeptTract { original, work });
        }
    }
    Ok(())
}
