//! Running a loaded model one frame at a time: per-thread sessions with preallocated input
//! tensors, buffer and state checks, and the copies between caller buffers, character states
//! and tract tensors.

use crate::error::{MotionError, chain};
use crate::model::{Inner, MotionModel, MotionState, Plan, Source};
use std::sync::Arc;
use tract_onnx::prelude::*;

/// A spawned tract state with preallocated input tensors for one batch size.
#[derive(Debug)]
struct Session {
    batch: usize,
    state: TypedSimpleState,
    /// One tensor per graph input, reused every call (exclusive again once tract returns).
    inputs: Vec<Arc<Tensor>>,
    /// Made from the symbolic-batch plan (see [`MotionRunner::step_batch_invariant`]).
    symbolic: bool,
    /// A run's node inputs and outputs, reused (`crate::ops::kept::run`).
    scratch: Vec<TValue>,
    results: Vec<TValue>,
    /// Whether `crate::ops::kept::run` runs the plan itself.
    itself: bool,
}

impl Session {
    fn new(plan: &Plan, batch: usize, widths: &[usize]) -> Result<Self, MotionError> {
        let run = |e: TractError| MotionError::Run { reason: chain(&e) };
        let state = plan.spawn().map_err(run)?;
        let inputs = widths
            .iter()
            .map(|&w| Tensor::zero::<f32>(&[batch, w]).map(Arc::new))
            .collect::<TractResult<Vec<_>>>()
            .map_err(run)?;
        let itself = crate::ops::kept::runs_itself(plan);
        Ok(Session { batch, state, inputs, symbolic: false, scratch: Vec::new(), results: Vec::new(), itself })
    }
}

/// Scratch space for stepping a [`MotionModel`] on one thread (not shared: `Send`, not `Sync`).
#[derive(Debug)]
pub struct MotionRunner {
    model: MotionModel,
    single: Session,
    batched: Option<Session>,
    /// Start-graph session, created on the first `start` (and when the batch size changes).
    start: Option<Session>,
    /// The one-character plan's node costs, for runs spread over calls (measured on first use).
    costs: Option<Arc<PassCosts>>,
}

fn check_states(inner: &Inner, states: &[MotionState]) -> Result<(), MotionError> {
    for state in states {
        if state.slots.len() != inner.states.len() {
            return Err(MotionError::StateMismatch {
                name: "(number of slots)".into(),
                expected: inner.states.len(),
                found: state.slots.len(),
            });
        }
        for (info, slot) in inner.states.iter().zip(&state.slots) {
            if slot.len() != info.width {
                return Err(MotionError::StateMismatch {
                    name: info.input.clone(),
                    expected: info.width,
                    found: slot.len(),
                });
            }
        }
    }
    Ok(())
}

pub(crate) fn check_len(name: &str, found: usize, batch: usize, width: usize) -> Result<(), MotionError> {
    if found != batch * width {
        return Err(MotionError::BufferLength { name: name.to_string(), expected: batch * width, batch, width, found });
    }
    Ok(())
}

pub(crate) fn check_finite(name: &str, data: &[f32], width: usize) -> Result<(), MotionError> {
    if let Some(index) = data.iter().position(|v| !v.is_finite()) {
        return Err(MotionError::NonFinite {
            name: name.to_string(),
            index,
            character: index / width.max(1),
            value: data[index],
        });
    }
    Ok(())
}

impl MotionRunner {
    pub(crate) fn new(model: MotionModel) -> Result<Self, MotionError> {
        let single = Session::new(&model.inner.single, 1, &model.inner.graph_input_widths)?;
        Ok(MotionRunner { model, single, batched: None, start: None, costs: None })
    }

    /// The model this runner steps.
    pub fn model(&self) -> &MotionModel {
        &self.model
    }

    /// Advances one character by one frame.
    ///
    /// `inputs[i]` holds `model.inputs()[i].width` values; `outputs[i]` receives
    /// `model.outputs()[i].width` values; `state` is read and replaced by the next state.
    /// Invalid sizes or non-finite inputs return an error and leave `state` unchanged.
    pub fn step(
        &mut self,
        state: &mut MotionState,
        inputs: &[&[f32]],
        outputs: &mut [&mut [f32]],
    ) -> Result<(), MotionError> {
        self.run(std::slice::from_mut(state), inputs, outputs, false)
    }

    /// Advances `states.len()` characters by one frame in one graph run.
    ///
    /// Buffers are character-major: `inputs[i]` holds `states.len() * model.inputs()[i].width`
    /// values, row `c` for character `c`; outputs likewise.
    pub fn step_batch(
        &mut self,
        states: &mut [MotionState],
        inputs: &[&[f32]],
        outputs: &mut [&mut [f32]],
    ) -> Result<(), MotionError> {
        self.run(states, inputs, outputs, false)
    }

    /// [`MotionRunner::step_batch`] with the symbolic-batch plan for every batch size, so that
    /// a character's results do not depend on the batch it is in, bit for bit, for batches of
    /// two or more: the concrete plans pick kernels by batch size (and tract picks a
    /// matrix-vector kernel for a batch of one), whose float rounding differs on some CPUs
    /// (AVX-512 ones). Callers that need this pad a single character to two.
    pub(crate) fn step_batch_invariant(
        &mut self,
        states: &mut [MotionState],
        inputs: &[&[f32]],
        outputs: &mut [&mut [f32]],
    ) -> Result<(), MotionError> {
        self.run(states, inputs, outputs, true)
    }

    /// Starts a transition for one character: runs the start graph on `inputs`
    /// (`inputs[i]` holds `model.start_inputs()[i].width` values) and sets `state` from its
    /// outputs; slots the start graph does not produce are zeroed. Without a start graph it
    /// zeroes `state` and takes no inputs.
    pub fn start(&mut self, state: &mut MotionState, inputs: &[&[f32]]) -> Result<(), MotionError> {
        self.start_batch(std::slice::from_mut(state), inputs)
    }

    /// [`MotionRunner::start`] for `states.len()` characters in one run (character-major buffers).
    pub fn start_batch(&mut self, states: &mut [MotionState], inputs: &[&[f32]]) -> Result<(), MotionError> {
        let inner = &*self.model.inner;
        let batch = states.len();
        if batch == 0 {
            return Err(MotionError::EmptyBatch);
        }
        check_states(inner, states)?;
        let Some(start) = &inner.start else {
            if !inputs.is_empty() {
                return Err(MotionError::BufferCount { what: "start inputs", expected: 0, found: inputs.len() });
            }
            states.iter_mut().for_each(MotionState::reset);
            return Ok(());
        };
        check_start_inputs(start, inputs.iter().map(|d| Some(*d)), batch)?;
        if self.start.as_ref().is_none_or(|s| s.batch != batch) {
            let plan = if batch == 1 { &start.single } else { &start.batched };
            self.start = Some(Session::new(plan, batch, &start.widths)?);
        }
        let session = self.start.as_mut().expect("start session set above");
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
        for (g, data) in inputs.iter().enumerate() {
            let tensor = Arc::make_mut(&mut session.inputs[g]);
            let mut view = tensor.try_as_plain_ram_mut().map_err(run_err)?;
            view.as_slice_mut::<f32>().map_err(run_err)?.copy_from_slice(data);
        }
        let values = session.inputs.iter().map(|t| TValue::from_const(t.clone()));
        crate::ops::kept::run(&mut session.state, session.itself, values, &mut session.scratch, &mut session.results)
            .map_err(run_err)?;
        let read = read_start_outputs(inner, &start.out_slots, &session.results, states);
        session.results.clear();
        read
    }

    fn run(
        &mut self,
        states: &mut [MotionState],
        inputs: &[&[f32]],
        outputs: &mut [&mut [f32]],
        symbolic: bool,
    ) -> Result<(), MotionError> {
        let inner = &*self.model.inner;
        let batch = states.len();
        if batch == 0 {
            return Err(MotionError::EmptyBatch);
        }
        check_inputs(inner, inputs, batch)?;
        check_outputs(inner, outputs, batch)?;
        check_states(inner, states)?;

        let session = if batch == 1 && !symbolic {
            &mut self.single
        } else {
            if self.batched.as_ref().is_none_or(|s| s.batch != batch || s.symbolic != symbolic) {
                let plan = if symbolic { inner.batched.clone() } else { inner.plan_for(batch) };
                let session = Session::new(&plan, batch, &inner.graph_input_widths)?;
                self.batched = Some(Session { symbolic, ..session });
            }
            self.batched.as_mut().expect("batched session set above")
        };
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };

        fill_inputs(inner, session, states, inputs)?;
        let values = session.inputs.iter().map(|t| TValue::from_const(t.clone()));
        crate::ops::kept::run(&mut session.state, session.itself, values, &mut session.scratch, &mut session.results)
            .map_err(run_err)?;
        let read = read_outputs(inner, &session.results, states, outputs);
        // Let go of the outputs, so that the next run writes into the same tensors.
        session.results.clear();
        read
    }
}

/// Checks a step's inputs for `batch` characters: their count, then each one's size and values.
fn check_inputs(inner: &Inner, inputs: &[&[f32]], batch: usize) -> Result<(), MotionError> {
    if inputs.len() != inner.inputs.len() {
        return Err(MotionError::BufferCount { what: "inputs", expected: inner.inputs.len(), found: inputs.len() });
    }
    for (info, data) in inner.inputs.iter().zip(inputs) {
        check_len(&info.name, data.len(), batch, info.width)?;
        check_finite(&info.name, data, info.width)?;
    }
    Ok(())
}

/// Checks a step's output buffers for `batch` characters: their count, then each one's size.
fn check_outputs(inner: &Inner, outputs: &[&mut [f32]], batch: usize) -> Result<(), MotionError> {
    if outputs.len() != inner.outputs.len() {
        return Err(MotionError::BufferCount { what: "outputs", expected: inner.outputs.len(), found: outputs.len() });
    }
    for (info, data) in inner.outputs.iter().zip(outputs) {
        check_len(&info.name, data.len(), batch, info.width)?;
    }
    Ok(())
}

/// Checks the start graph's inputs for `batch` characters: their count, then each given one's
/// size and values (`None`: an input given later).
fn check_start_inputs<'a>(
    start: &crate::model::StartGraph,
    inputs: impl ExactSizeIterator<Item = Option<&'a [f32]>>,
    batch: usize,
) -> Result<(), MotionError> {
    if inputs.len() != start.inputs.len() {
        return Err(MotionError::BufferCount {
            what: "start inputs",
            expected: start.inputs.len(),
            found: inputs.len(),
        });
    }
    for (info, data) in start.inputs.iter().zip(inputs) {
        if let Some(data) = data {
            check_len(&info.name, data.len(), batch, info.width)?;
            check_finite(&info.name, data, info.width)?;
        }
    }
    Ok(())
}

/// Resets the characters' states and sets them from a start-graph run's results (output `o`
/// into state slot `out_slots[o]`); slots the start graph does not produce stay zero.
fn read_start_outputs(
    inner: &Inner,
    out_slots: &[usize],
    results: &[TValue],
    states: &mut [MotionState],
) -> Result<(), MotionError> {
    let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
    states.iter_mut().for_each(MotionState::reset);
    for (o, &k) in out_slots.iter().enumerate() {
        let view = results[o].try_as_plain_ram().map_err(run_err)?;
        let src = view.as_slice::<f32>().map_err(run_err)?;
        write_slot(inner, k, src, states, "start output for state", &inner.states[k].input)?;
    }
    Ok(())
}

/// Sets state slot `k` of every character from `src` (character-major), or names the graph's
/// output (`what` `name`) that has the wrong size.
fn write_slot(
    inner: &Inner,
    k: usize,
    src: &[f32],
    states: &mut [MotionState],
    what: &str,
    name: &str,
) -> Result<(), MotionError> {
    let (batch, width) = (states.len(), inner.states[k].width);
    if src.len() != batch * width {
        return Err(MotionError::Run {
            reason: format!("{what} `{name}` has {} values, expected {}", src.len(), batch * width),
        });
    }
    for (c, state) in states.iter_mut().enumerate() {
        state.slots[k].copy_from_slice(&src[c * width..(c + 1) * width]);
    }
    Ok(())
}

/// Copies the frame inputs and the characters' states into the session's preallocated input
/// tensors.
fn fill_inputs(
    inner: &Inner,
    session: &mut Session,
    states: &[MotionState],
    inputs: &[&[f32]],
) -> Result<(), MotionError> {
    let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
    for (g, source) in inner.graph_inputs.iter().enumerate() {
        let width = inner.graph_input_widths[g];
        // Exclusive unless tract kept a reference; then this copies once.
        let tensor = Arc::make_mut(&mut session.inputs[g]);
        let mut view = tensor.try_as_plain_ram_mut().map_err(run_err)?;
        let dst = view.as_slice_mut::<f32>().map_err(run_err)?;
        match *source {
            Source::Frame(i) => dst.copy_from_slice(inputs[i]),
            Source::State(k) => {
                for (c, state) in states.iter().enumerate() {
                    dst[c * width..(c + 1) * width].copy_from_slice(&state.slots[k]);
                }
            }
        }
    }
    Ok(())
}

/// Copies a graph run's results into the frame outputs and the characters' states.
fn read_outputs(
    inner: &Inner,
    results: &[TValue],
    states: &mut [MotionState],
    outputs: &mut [&mut [f32]],
) -> Result<(), MotionError> {
    let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
    for (o, source) in inner.graph_outputs.iter().enumerate() {
        let view = results[o].try_as_plain_ram().map_err(run_err)?;
        let src = view.as_slice::<f32>().map_err(run_err)?;
        match *source {
            Source::Frame(i) => {
                if src.len() != outputs[i].len() {
                    return Err(MotionError::Run {
                        reason: format!(
                            "output `{}` has {} values, expected {}",
                            inner.outputs[i].name,
                            src.len(),
                            outputs[i].len()
                        ),
                    });
                }
                outputs[i].copy_from_slice(src);
            }
            Source::State(k) => write_slot(inner, k, src, states, "state output", &inner.states[k].output)?,
        }
    }
    Ok(())
}

/// One character's graph run in progress, node by node, on a tract state of its own (the
/// one-character plan, the same arithmetic as [`MotionRunner::step`]): so that a caller with a
/// frame budget can spread a run over calls ([`MotionRunner::partial_begin`]).
#[derive(Debug)]
pub(crate) struct PartialRun {
    session: Session,
    /// The next node, an index in [`PassCosts::order`].
    at: usize,
    /// Whether the tract state holds a run's values (cleared before the next run).
    begun: bool,
}

/// The nodes of the one-character plan in evaluation order and the share of a run's time spent
/// up to the end of each (measured once per runner; it decides how many nodes a call runs,
/// never what they compute), and a whole run's time, seconds.
#[derive(Debug)]
pub(crate) struct PassCosts {
    pub(crate) order: Vec<usize>,
    pub(crate) done_after: Vec<f64>,
    pub(crate) run_time: f64,
}

impl PartialRun {
    /// The share of the run done (0 when begun, 1 when every node ran).
    pub(crate) fn done(&self, costs: &PassCosts) -> f64 {
        if self.at == 0 { 0.0 } else { costs.done_after[self.at - 1] }
    }

    /// The share of the run its next node takes (0 when every node ran).
    pub(crate) fn next_cost(&self, costs: &PassCosts) -> f64 {
        costs.done_after.get(self.at).map_or(0.0, |d| d - self.done(costs))
    }

    /// Whether every node ran.
    pub(crate) fn complete(&self, costs: &PassCosts) -> bool {
        self.at >= costs.order.len()
    }
}

impl MotionRunner {
    /// The node costs of the one-character plan ([`PassCosts`]), measured on the first call.
    pub(crate) fn pass_costs(&mut self) -> Result<Arc<PassCosts>, MotionError> {
        if let Some(c) = &self.costs {
            return Ok(c.clone());
        }
        let run = |e: TractError| MotionError::Run { reason: chain(&e) };
        let inner = self.model.inner.clone();
        let order = inner.single.order_without_consts().to_vec();
        let zeros = || -> Result<TVec<TValue>, MotionError> {
            inner
                .graph_input_widths
                .iter()
                .map(|&w| Tensor::zero::<f32>(&[1, w]).map(|t| t.into_tvalue()).map_err(run))
                .collect()
        };
        // Four runs node by node, the fastest of the last three for each node.
        let mut best = vec![f64::INFINITY; order.len()];
        let mut state = inner.single.spawn().map_err(run)?;
        for round in 0..4 {
            state.set_inputs(zeros()?).map_err(run)?;
            for (i, &node) in order.iter().enumerate() {
                let t = std::time::Instant::now();
                state.compute_one(node).map_err(run)?;
                if round > 0 {
                    best[i] = best[i].min(t.elapsed().as_secs_f64());
                }
            }
            state.reset_turn().map_err(run)?;
        }
        let total: f64 = best.iter().sum::<f64>().max(1e-9);
        let mut done = 0.0;
        let done_after: Vec<f64> = best
            .iter()
            .map(|t| {
                done += t;
                done / total
            })
            .collect();
        let costs = Arc::new(PassCosts { order, done_after, run_time: total });
        self.costs = Some(costs.clone());
        Ok(costs)
    }

    /// A fresh [`PartialRun`] (a tract state of the one-character plan and its input tensors).
    pub(crate) fn partial(&self) -> Result<PartialRun, MotionError> {
        let inner = &*self.model.inner;
        Ok(PartialRun { session: Session::new(&inner.single, 1, &inner.graph_input_widths)?, at: 0, begun: false })
    }

    /// Begins one character's graph run on `p`: checks and copies the inputs as
    /// [`MotionRunner::step`] does; nothing runs yet ([`MotionRunner::partial_node`]).
    pub(crate) fn partial_begin(
        &self,
        p: &mut PartialRun,
        state: &MotionState,
        inputs: &[&[f32]],
    ) -> Result<(), MotionError> {
        let inner = &*self.model.inner;
        check_inputs(inner, inputs, 1)?;
        check_states(inner, std::slice::from_ref(state))?;
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
        if p.begun {
            p.session.state.reset_turn().map_err(run_err)?;
        }
        fill_inputs(inner, &mut p.session, std::slice::from_ref(state), inputs)?;
        let values = p.session.inputs.iter().map(|t| TValue::from_const(t.clone()));
        crate::ops::kept::set_inputs(&mut p.session.state, values).map_err(run_err)?;
        p.at = 0;
        p.begun = true;
        Ok(())
    }

    /// Runs the next node of `p`.
    pub(crate) fn partial_node(&self, p: &mut PartialRun, costs: &PassCosts) -> Result<(), MotionError> {
        if let Some(&node) = costs.order.get(p.at) {
            let s = &mut p.session;
            crate::ops::kept::compute(&mut s.state, node, &mut s.scratch)
                .map_err(|e| MotionError::Run { reason: chain(&e) })?;
            p.at += 1;
        }
        Ok(())
    }

    /// Runs what is left of `p` and writes its outputs, as [`MotionRunner::step`] does.
    pub(crate) fn partial_finish(
        &self,
        p: &mut PartialRun,
        costs: &PassCosts,
        state: &mut MotionState,
        outputs: &mut [&mut [f32]],
    ) -> Result<(), MotionError> {
        let inner = &*self.model.inner;
        check_outputs(inner, outputs, 1)?;
        while !p.complete(costs) {
            self.partial_node(p, costs)?;
        }
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
        let s = &mut p.session;
        crate::ops::kept::read_outputs(&s.state, &mut s.results).map_err(run_err)?;
        s.state.reset_turn().map_err(run_err)?;
        p.begun = false;
        let read = read_outputs(inner, &s.results, std::slice::from_mut(state), outputs);
        s.results.clear();
        read
    }
}

/// A one-character run of the start graph begun before all its inputs are known: the nodes that
/// need only the known ones ran ([`MotionRunner::start_begin`]; a transition's target is known
/// before its context's second frame, which the first frame's features need).
#[derive(Debug)]
pub(crate) struct PartialStart {
    session: Session,
    /// Per graph input: whether it comes at [`MotionRunner::start_finish`].
    late: Vec<bool>,
    /// Per node of the plan: whether it needs a late input.
    waits: Vec<bool>,
}

impl MotionRunner {
    /// Begins the start graph for one character with the inputs known now (`None`: comes at
    /// [`MotionRunner::start_finish`]) and runs every node that needs only those; `None` without
    /// a start graph.
    /// `reuse`: a [`PartialStart`] this runner finished, whose tract state and tensors it takes.
    pub(crate) fn start_begin(
        &self,
        inputs: &[Option<&[f32]>],
        reuse: Option<PartialStart>,
    ) -> Result<Option<PartialStart>, MotionError> {
        let inner = &*self.model.inner;
        let Some(start) = &inner.start else { return Ok(None) };
        check_start_inputs(start, inputs.iter().copied(), 1)?;
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
        // A finished run's tract state and input tensors, cleared, else new ones.
        let mut session = match reuse {
            Some(mut p) => {
                p.session.state.reset_turn().map_err(run_err)?;
                p.session
            }
            None => Session::new(&start.single, 1, &start.widths)?,
        };
        for (g, data) in inputs.iter().enumerate() {
            if let Some(data) = data {
                let tensor = Arc::make_mut(&mut session.inputs[g]);
                let mut view = tensor.try_as_plain_ram_mut().map_err(run_err)?;
                view.as_slice_mut::<f32>().map_err(run_err)?.copy_from_slice(data);
            }
        }
        let values = session.inputs.iter().map(|t| TValue::from_const(t.clone()));
        crate::ops::kept::set_inputs(&mut session.state, values).map_err(run_err)?;
        let model = start.single.model();
        let late: Vec<bool> = inputs.iter().map(Option::is_none).collect();
        let mut waits = vec![false; model.nodes().len()];
        for (g, outlet) in model.input_outlets().map_err(run_err)?.iter().enumerate() {
            waits[outlet.node] = late[g];
        }
        for &node in start.single.order_without_consts() {
            waits[node] |= model.nodes()[node].inputs.iter().any(|i| waits[i.node]);
            if !waits[node] {
                crate::ops::kept::compute(&mut session.state, node, &mut session.scratch).map_err(run_err)?;
            }
        }
        Ok(Some(PartialStart { session, late, waits }))
    }

    /// Finishes `p` with the late inputs (`inputs` as [`MotionRunner::start`] takes them; the
    /// others were given to [`MotionRunner::start_begin`]) and sets `state` as
    /// [`MotionRunner::start`] does.
    pub(crate) fn start_finish(
        &self,
        p: &mut PartialStart,
        state: &mut MotionState,
        inputs: &[&[f32]],
    ) -> Result<(), MotionError> {
        let inner = &*self.model.inner;
        let start =
            inner.start.as_ref().ok_or_else(|| MotionError::Run { reason: "the model has no start graph".into() })?;
        check_states(inner, std::slice::from_ref(state))?;
        check_start_inputs(start, inputs.iter().zip(&p.late).map(|(d, &late)| late.then_some(*d)), 1)?;
        let run_err = |e: TractError| MotionError::Run { reason: chain(&e) };
        for (g, (info, data)) in start.inputs.iter().zip(inputs).enumerate() {
            if !p.late[g] {
                continue;
            }
            let tensor = Tensor::from_shape::<f32>(&[1, info.width], data).map_err(run_err)?;
            p.session.state.set_input(g, tensor.into_tvalue()).map_err(run_err)?;
        }
        for &node in start.single.order_without_consts() {
            if p.waits[node] {
                let s = &mut p.session;
                crate::ops::kept::compute(&mut s.state, node, &mut s.scratch).map_err(run_err)?;
            }
        }
        let s = &mut p.session;
        crate::ops::kept::read_outputs(&s.state, &mut s.results).map_err(run_err)?;
        let read = read_start_outputs(inner, &start.out_slots, &s.results, std::slice::from_mut(state));
        s.results.clear();
        read
    }
}
