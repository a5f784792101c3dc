//! Engine-facing RTN transitions: start from past poses and a target pose, then step one frame
//! at a time (global joint positions in and out), generate a whole target-blended transition
//! into a caller-owned buffer, or do either for N characters in one graph run.
//!
//! Feature encoding, offsets and the target blend come from `zoo_protocol::features`, the code
//! the training uses. The step and start graphs are those of `zoo export --onnx` for an RTN
//! (`zoo.model_kind = "rtn"`, `zoo.task = "transition"`): frame inputs `x` and (with future
//! conditioning) `offset`, frame output `x_next`, start inputs `target` and/or `x0`. How to drive
//! them (context length, blend length, which inputs exist) comes from the typed task section
//! [`crate::metadata::TransitionTask`], never from the model's config.
//!
//! A terrain-aware RTN (`zoo train rtn --terrain`, `zoo.transition`'s `terrain` section) also
//! takes the step input `terrain`: the local patch under the root of the frame fed, sampled from
//! the character's heightmap ([`TransitionState::set_heightmap`]) by
//! [`zoo_protocol::terrain::terrain_patch`], the function training calls, and normalized with the
//! file's `terrain` group (docs/runtime-protocol.md).
//!
//! Poses are flat `f32` buffers of global joint positions, joint-major (`[x0, y0, z0, x1, ...]`,
//! `3K` values for `K` joints, the model's skeleton order); [`crate::pose`] converts glam
//! vectors. Batched calls take character-major buffers (character `c` at `c * 3K`).

mod lock;
mod posed;

use crate::error::MotionError;
use crate::metadata::{MotionMeanStd, MotionTask, TransitionFallback, keys};
use crate::model::{MotionModel, MotionState};
use crate::runner::{MotionRunner, PartialRun, PartialStart, PassCosts, check_finite, check_len};
use glam::DVec3;
use posed::{PosedScratch, PosedState};
use std::path::Path;
use std::sync::Arc;
use zoo_protocol::features;
use zoo_protocol::footlock::FootLock;
pub use zoo_protocol::terrain::Heightmap;
use zoo_protocol::terrain::terrain_patch;

/// What a frame input of the step graph is fed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameInput {
    X,
    Offset,
    /// The interpolation frame of an interpolation-residual RTN (`x_next = base + D(h)`).
    Base,
    /// The normalized terrain patch under the root of `x` (terrain-aware RTN).
    Terrain,
    /// The time-to-arrival embedding of the frame the step predicts.
    Tta,
}

/// The terrain input of a terrain-aware RTN: patch geometry and normalization.
#[derive(Clone, Debug)]
struct TerrainInput {
    /// Samples per side (the patch has `side * side` values).
    side: usize,
    /// Side length of the patch in model units.
    extent: f32,
    /// The file's `terrain` normalization group (`side * side` values).
    norm: MotionMeanStd,
}

/// A loaded RTN for transitions: cheap to clone (the graph is shared), `Send + Sync`.
#[derive(Clone, Debug)]
pub struct TransitionModel {
    model: MotionModel,
    joints: usize,
    past_frames: usize,
    transition_frames: usize,
    x: MotionMeanStd,
    velocity: MotionMeanStd,
    offset: MotionMeanStd,
    frame_inputs: Vec<FrameInput>,
    /// The terrain input of a terrain-aware model.
    terrain: Option<TerrainInput>,
    /// The time-to-arrival input of a model trained over several lengths.
    time_to_arrival: Option<crate::metadata::TimeToArrival>,
    /// For each start-graph input: `true` for the target vector, `false` for `x0`.
    start_target: Vec<bool>,
    target_blend: usize,
    /// The skeleton: parents and rest offsets (for engine poses).
    parents: Vec<Option<usize>>,
    offsets: Vec<DVec3>,
}

/// One character's transition in progress (from [`TransitionModel::new_transition`]); a few
/// kilobytes, reused across transitions without allocating.
#[derive(Clone, Debug)]
pub struct TransitionState {
    motion: MotionState,
    /// Normalized features of the frame fed next.
    x: Vec<f32>,
    /// Global root position of that frame.
    root: [f32; 3],
    /// Global target pose.
    target: Vec<f32>,
    /// Global pose of the last context frame (the start of the interpolation base).
    last: Vec<f32>,
    /// Raw frames generated since the context (the index of the next interpolation frame).
    generated: usize,
    started: bool,
    /// Context frames of the transition (`start`: all of them at once; `begin`: fed one by one).
    context_total: usize,
    /// Context frames fed so far; the transition can be stepped once all are.
    context_fed: usize,
    /// The normalized target vector (target pose, target velocity) of a transition begun with
    /// `begin_batch`, until its first graph run.
    target_vec: Vec<f32>,
    /// Frames returned since the transition started (blended or raw).
    frames: usize,
    /// Transition length `L` of this transition: frames `0..L` lead to the target frame `L`.
    length: usize,
    /// The first frame the target blend moves (its weight above 0), from `length`.
    blend_from: usize,
    /// Frames of the blend window computed ahead (global positions, blended), capacity
    /// `(target_blend + 1) * 3K`, allocated once by `new_transition`.
    ahead: Vec<f32>,
    /// Frame index of `ahead`'s first frame.
    ahead_from: usize,
    /// Whether `step_raw` was used since the start (raw and blended stepping do not mix).
    raw: bool,
    miss: Option<TargetMiss>,
    /// The interpolation's weight in the frames of the last `generate` (0 without fallback).
    fallback_weight: f32,
    /// Rotations of a transition started from engine poses.
    posed: PosedState,
    /// The ground under this character (terrain-aware models).
    heightmap: Option<Arc<Heightmap>>,
    /// A graph run begun and not finished ([`TransitionRunner::step`] and `feed` for one
    /// character spread runs over calls, a frame budget): what it is for. Its frame inputs are
    /// in `pending_inputs` and its recurrent state is `motion`, unchanged until it ends, so any
    /// runner can finish it; the runner that began it continues it (`pending_key`).
    pending: Option<PassKind>,
    pending_inputs: Vec<f32>,
    pending_key: u64,
}

/// What a graph run in progress is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PassKind {
    /// A context frame's: it only moves the recurrent state.
    Context,
    /// The next raw frame's: it goes to the frames computed ahead.
    Generation,
}

/// Keys of the graph runs in progress (unique in the process).
static PENDING_KEYS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// The most one step of a character stepped alone does by choice, in the time of a run of the
/// step graph (measured once per runner, without the call's own work, so about 1.6x a step's
/// median): enough to add half of an LSTM cell (a node of its own at batch 1) to a step's run,
/// which is how the frames the target blend needs are computed ahead, a fraction per step.
const CALL_BUDGET: f64 = 2.0;

/// The same for a context frame's call. The second one runs the start graph, which leaves the
/// step graph's weights out of the cache, so the calls after it run slower than measured and
/// finish what the start left behind a part per call; the context is caught up before the
/// first step.
const CONTEXT_BUDGET: f64 = 1.6;

/// Graph runs in progress one runner keeps (characters stepped one at a time); beyond, the
/// oldest is dropped and its character runs it again whole.
const MAX_PARTIALS: usize = 256;

impl TransitionState {
    /// Sets the ground under this character: the heightmap a terrain-aware model
    /// ([`TransitionModel::terrain`]) samples its terrain patch from at every step, in the
    /// model's units and coordinate frame (Y up, the frame of the poses given to the runner).
    /// Shared, not copied: many characters may hold the same map. Required before
    /// [`TransitionRunner::start`] for a terrain-aware model (starting without one is a
    /// [`MotionError::TransitionSequence`] error); a model without terrain input ignores it, so an
    /// engine may give every character its ground whatever model it runs. Changing it during a
    /// transition takes effect at the next step.
    pub fn set_heightmap(&mut self, heightmap: Option<Arc<Heightmap>>) {
        self.heightmap = heightmap;
    }

    /// The heightmap set with [`TransitionState::set_heightmap`].
    pub fn heightmap(&self) -> Option<&Arc<Heightmap>> {
        self.heightmap.as_ref()
    }

    /// Sets up a new transition of `length` frames towards `target` (global positions) after the
    /// last context frame `last`, with `context` frames of context, whose target blend starts
    /// at frame `blend_from`: nothing generated, nothing computed ahead, no miss, no fallback,
    /// not posed. The caller sets the start's own fields (`x`, `root`, `started`,
    /// `context_fed`).
    fn reset(&mut self, target: &[f32], last: &[f32], context: usize, length: usize, blend_from: usize) {
        self.target.copy_from_slice(target);
        self.last.copy_from_slice(last);
        self.context_total = context;
        self.frames = 0;
        self.length = length;
        self.blend_from = blend_from;
        self.generated = 0;
        self.ahead.clear();
        self.ahead_from = 0;
        self.raw = false;
        self.miss = None;
        self.fallback_weight = 0.0;
        self.posed.active = false;
        self.pending = None;
    }

    /// Whether a graph run of this character is in progress (a call for one character spread
    /// it over calls, a frame budget): any runner finishes it when the character is next fed or
    /// stepped. For tests.
    #[doc(hidden)]
    pub fn has_run_in_progress(&self) -> bool {
        self.pending.is_some()
    }

    /// Whether [`TransitionRunner::start`] was called for this state.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// Frames generated since the transition started.
    pub fn frames_generated(&self) -> usize {
        self.frames
    }

    /// The transition length `L` given at the start: [`TransitionRunner::step`] returns frames
    /// `0..=L`, the last one the target frame.
    pub fn length(&self) -> usize {
        self.length
    }

    /// Frames [`TransitionRunner::step`] still returns before the transition is finished.
    pub fn frames_left(&self) -> usize {
        (self.length + 1).saturating_sub(self.frames)
    }

    /// Whether the target frame was returned (a further step is an error).
    pub fn is_finished(&self) -> bool {
        self.started && self.frames > self.length
    }

    /// The target pose of the transition (`3K` global positions).
    pub fn target(&self) -> &[f32] {
        &self.target
    }

    /// How far the network's own prediction of the target frame lies from the requested
    /// target, before the target blend hides it: the engine's cue to fall back (e.g. to
    /// inertialization) when the network is far off. Known once stepping reaches the blend
    /// window (the last [`TransitionModel::target_blend`] frames, whose network frames the
    /// runner has computed ahead by then) and after [`TransitionRunner::generate`]; `None`
    /// before.
    pub fn target_miss(&self) -> Option<TargetMiss> {
        self.miss
    }

    /// The weight of the interpolation in the frames of the last [`TransitionRunner::generate`]
    /// (0: the network's transition; 1: the interpolation alone), from the fallback set with
    /// [`TransitionRunner::set_fallback`]; 0 without one and before `generate`.
    pub fn fallback_weight(&self) -> f32 {
        self.fallback_weight
    }
}

/// The distance between the network's predicted target frame and the requested target, per
/// joint, in the model's units (see [`TransitionState::target_miss`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetMiss {
    /// Mean over joints of the distance.
    pub mean: f32,
    /// Largest distance over joints.
    pub max: f32,
}

/// Per-thread scratch space for transitions (`Send`, not `Sync`). Buffers grow to the largest
/// batch and context seen, then steps allocate nothing of their own.
#[derive(Debug)]
pub struct TransitionRunner {
    model: TransitionModel,
    runner: MotionRunner,
    /// Normalized features of the context frames, character-major.
    feats: Vec<f32>,
    target_vec: Vec<f32>,
    x0: Vec<f32>,
    xb: Vec<f32>,
    offset: Vec<f32>,
    /// Interpolation frames of the characters of a graph run (interpolation-residual models).
    base: Vec<f32>,
    /// Time-to-arrival embeddings of the characters of a graph run.
    tta: Vec<f32>,
    next: Vec<f32>,
    /// Generated poses of a batched `generate`, character-major.
    poses: Vec<f32>,
    /// Recurrent states swapped in from the characters for a batched run.
    motion: Vec<MotionState>,
    /// Characters of the current graph run (indices into the states of the call).
    sel: Vec<usize>,
    /// Network frames each character of a step call has computed by the end of the call.
    need: Vec<usize>,
    /// Whether `step_batch` spreads the frames it computes ahead over the steps before the
    /// blend (a frame budget); `generate` turns it off, computing them in one step (fewer graph
    /// runs in all).
    spread_ahead: bool,
    /// Graph runs in progress of characters stepped one at a time, by `pending_key`, oldest
    /// first; `spare`: finished ones, reused.
    partials: Vec<(u64, PartialRun)>,
    spare: Vec<PartialRun>,
    /// Start-graph runs begun by `begin` for one character (its target part), by `pending_key`.
    starts: Vec<(u64, PartialStart)>,
    /// A finished one, reused by the next `begin`.
    spare_start: Option<PartialStart>,
    /// [`CALL_BUDGET`] and [`CONTEXT_BUDGET`] (tests set them).
    budgets: (f64, f64),
    /// Foot-lock post-process of `generate`, off unless set.
    foot_lock: Option<lock::FittedLock>,
    /// Whether transitions longer than the trained length are accepted.
    beyond_trained: bool,
    /// Fallback towards interpolation of `generate`, off unless set.
    fallback: Option<TransitionFallback>,
    /// Fallback from the model's thresholds for each transition's length (`set_model_fallback`).
    model_fallback: bool,
    /// Buffers of posed transitions.
    posed: PosedScratch,
    /// Normalized terrain patches of the characters of a graph run (terrain-aware models).
    patch: Vec<f32>,
}

fn bad(key: &str, reason: String) -> MotionError {
    crate::metadata::FormatError::bad(key, reason).into()
}

fn wrong_len(name: &str, width: usize, batch: usize, found: usize) -> MotionError {
    MotionError::BufferLength { name: name.to_string(), expected: batch * width, batch, width, found }
}

/// Checks a character-major buffer of `batch` rows of `width` finite values.
fn check_rows(name: &str, data: &[f32], batch: usize, width: usize) -> Result<(), MotionError> {
    check_len(name, data.len(), batch, width)?;
    check_finite(name, data, width)
}

/// What each frame input of a transition step graph is, checked against its section: `x`,
/// `offset` (when the section says so), `base` (optional) of `D` values, `terrain` of `S^2`
/// values (`patch_dim`, when the section has terrain), `tta` of the embedding's values (when the
/// section has a time to arrival); the required ones must be there.
fn frame_inputs(
    model: &MotionModel,
    task: &crate::metadata::TransitionTask,
    patch_dim: Option<usize>,
) -> Result<Vec<FrameInput>, MotionError> {
    let d = task.frame_dim;
    let patch = patch_dim.unwrap_or(0);
    let tta = task.time_to_arrival.map_or(0, |t| t.dims);
    let frame_inputs = model
        .inputs()
        .iter()
        .map(|i| match i.name.as_str() {
            "x" if i.width == d => Ok(FrameInput::X),
            "offset" if i.width == d && task.offset_input => Ok(FrameInput::Offset),
            "base" if i.width == d => Ok(FrameInput::Base),
            "terrain" if patch_dim.is_some() && i.width == patch => Ok(FrameInput::Terrain),
            "tta" if task.time_to_arrival.is_some() && i.width == tta => Ok(FrameInput::Tta),
            other => Err(MotionError::BadGraphIo {
                what: "input",
                name: other.to_string(),
                reason: format!(
                    "is not an input of this transition model (`x`{}, optionally `base`, of {d} values{}{}, from `{}`)",
                    if task.offset_input { ", `offset`" } else { "" },
                    if patch_dim.is_some() { format!(", `terrain` of {patch} values") } else { String::new() },
                    if tta > 0 { format!(", `tta` of {tta} values") } else { String::new() },
                    keys::TRANSITION
                ),
            }),
        })
        .collect::<Result<Vec<_>, _>>()?;
    for (name, want, width, required) in [
        ("x", FrameInput::X, d, true),
        ("offset", FrameInput::Offset, d, task.offset_input),
        ("terrain", FrameInput::Terrain, patch, patch_dim.is_some()),
        ("tta", FrameInput::Tta, tta, task.time_to_arrival.is_some()),
    ] {
        if required && !frame_inputs.contains(&want) {
            return Err(MotionError::BadGraphIo {
                what: "input",
                name: name.into(),
                reason: format!("a transition step graph takes `{name}` of {width} values (`{}`)", keys::TRANSITION),
            });
        }
    }
    Ok(frame_inputs)
}

impl TransitionModel {
    /// Loads an RTN exported by `zoo export --onnx`; refuses a file of another task or kind
    /// (load any exported file with [`crate::LoadedModel::load`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        crate::LoadedModel::load(path)?.into_transition()
    }

    /// [`TransitionModel::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        crate::LoadedModel::from_bytes(bytes)?.into_transition()
    }

    /// Wraps a loaded model; refuses models of another task, and step graphs that do not match
    /// their `zoo.transition` section.
    pub fn new(model: MotionModel) -> Result<Self, MotionError> {
        let m = model.metadata();
        let MotionTask::Transition(task) = &m.task else {
            return Err(MotionError::wrong_task(m, "transition", "TransitionModel"));
        };
        // The format crate checked `frame_dim` against the skeleton and every group's values.
        let joints = m.skeleton.parents.len();
        let d = 3 * joints;
        let group = |name: &str, len: usize| -> Result<MotionMeanStd, MotionError> { Ok(m.group(name, len)?.clone()) };
        let terrain = match &task.terrain {
            Some(t) => Some(TerrainInput { side: t.side, extent: t.extent, norm: group("terrain", t.side * t.side)? }),
            None => None,
        };
        let frame_inputs = frame_inputs(&model, task, terrain.as_ref().map(|t| t.side * t.side))?;
        if model.outputs().len() != 1 || model.outputs()[0].width != d {
            return Err(MotionError::BadGraphIo {
                what: "output",
                name: model.outputs().first().map_or(String::new(), |o| o.name.clone()),
                reason: format!("a transition step graph has one frame output `x_next` of {d} values"),
            });
        }
        let start_target = model
            .start_inputs()
            .iter()
            .map(|i| match i.name.as_str() {
                "target" if i.width == 2 * d => Ok(true),
                "x0" if i.width == d => Ok(false),
                other => Err(bad(keys::START_GRAPH, format!("unexpected start input `{other}`"))),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(TransitionModel {
            joints,
            past_frames: task.past_frames,
            transition_frames: task.transition_frames,
            x: group("x", d)?,
            velocity: group("velocity", d)?,
            offset: group("offset", d)?,
            frame_inputs,
            terrain,
            time_to_arrival: task.time_to_arrival,
            start_target,
            target_blend: task.target_blend,
            parents: m.skeleton.parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
            offsets: m.skeleton.offsets.iter().map(|o| glam::DVec3::from_array(*o)).collect(),
            model,
        })
    }

    /// Number of joints K (poses are `3K` values: joint-major global positions).
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Context frames the model was trained with (the paper's 10).
    pub fn past_frames(&self) -> usize {
        self.past_frames
    }

    /// Transition length P the model was trained on, in frames (the paper's 30).
    pub fn transition_frames(&self) -> usize {
        self.transition_frames
    }

    /// The underlying step-graph model (metadata, skeleton, fps).
    pub fn model(&self) -> &MotionModel {
        &self.model
    }

    /// Target-blend length of the post-process (RTN eq. 15-16), from `zoo.transition`.
    pub fn target_blend(&self) -> usize {
        self.target_blend
    }

    /// The terrain patch of a terrain-aware model, `(side, extent)`: `side * side` heights on
    /// a square of `extent` model units around the root; `None` for a model without terrain
    /// input. A terrain-aware model needs a heightmap per character
    /// ([`TransitionState::set_heightmap`]).
    pub fn terrain(&self) -> Option<(usize, f32)> {
        self.terrain.as_ref().map(|t| (t.side, t.extent))
    }

    /// The foot-lock post-process for this model's skeleton (legs found by joint name, defaults
    /// for centimetres), `None` when the skeleton has no `foot` joints. Enable it on a runner
    /// with [`TransitionRunner::set_foot_lock`].
    pub fn default_foot_lock(&self) -> Option<FootLock> {
        let sk = &self.model.metadata().skeleton;
        let parents: Vec<Option<usize>> = sk.parents.iter().map(|&p| usize::try_from(p).ok()).collect();
        FootLock::from_skeleton(&sk.names, &parents)
    }

    /// The fallback thresholds calibrated by `zoo train rtn` (the `fallback` of the
    /// `transition` section), or `None` for a model without them. Enable them on a runner with
    /// [`TransitionRunner::set_fallback`].
    pub fn default_fallback(&self) -> Option<TransitionFallback> {
        self.model.metadata().task.as_transition()?.fallback
    }

    /// The calibrated thresholds for a transition of `length` frames: for a model trained over
    /// several lengths, those calibrated at each validation length interpolated at `length`
    /// (`fallback_lengths` of the section), else [`TransitionModel::default_fallback`]. A runner
    /// applies them per transition with [`TransitionRunner::set_model_fallback`].
    pub fn default_fallback_for(&self, length: usize) -> Option<TransitionFallback> {
        self.model.metadata().task.as_transition()?.fallback_for(length)
    }

    /// A fresh transition state for one character.
    pub fn new_transition(&self) -> TransitionState {
        let d = 3 * self.joints;
        TransitionState {
            motion: self.model.new_state(),
            x: vec![0.0; d],
            root: [0.0; 3],
            target: vec![0.0; d],
            last: vec![0.0; d],
            generated: 0,
            started: false,
            context_total: 0,
            context_fed: 0,
            target_vec: vec![0.0; 2 * d],
            frames: 0,
            length: 0,
            blend_from: 0,
            ahead: Vec::with_capacity((self.target_blend + 2) * d),
            ahead_from: 0,
            raw: false,
            miss: None,
            fallback_weight: 0.0,
            posed: PosedState::new(self.joints),
            heightmap: None,
            pending: None,
            pending_inputs: Vec::new(),
            pending_key: 0,
        }
    }

    /// Scratch space for one thread (measures the cost of the step graph's nodes once: a few runs).
    pub fn runner(&self) -> Result<TransitionRunner, MotionError> {
        let mut runner = self.model.runner()?;
        // The node costs of a run, measured now (a few runs) rather than in a frame's call.
        runner.pass_costs()?;
        Ok(TransitionRunner {
            model: self.clone(),
            runner,
            feats: Vec::new(),
            target_vec: Vec::new(),
            x0: Vec::new(),
            xb: Vec::new(),
            offset: Vec::new(),
            base: Vec::new(),
            tta: Vec::new(),
            next: Vec::new(),
            poses: Vec::new(),
            motion: Vec::new(),
            sel: Vec::new(),
            need: Vec::new(),
            spread_ahead: true,
            partials: Vec::new(),
            spare: Vec::new(),
            starts: Vec::new(),
            spare_start: None,
            budgets: (CALL_BUDGET, CONTEXT_BUDGET),
            foot_lock: None,
            beyond_trained: false,
            fallback: None,
            model_fallback: false,
            posed: PosedScratch::default(),
            patch: Vec::new(),
        })
    }
}

impl TransitionRunner {
    /// The model this runner steps.
    pub fn model(&self) -> &TransitionModel {
        &self.model
    }

    /// Sets the foot-lock post-process that [`TransitionRunner::generate`] applies after the
    /// target blend and the fallback (`None`: off, the default): the frames are put on the
    /// model's skeleton (rotations fitted, bones at their rest lengths), locked, and fitted
    /// again, so the locked feet are the skeleton's (see `zoo_protocol::footlock`). Per-frame
    /// stepping never applies it: it needs the whole transition.
    pub fn set_foot_lock(&mut self, lock: Option<FootLock>) {
        self.foot_lock = lock.map(|lock| {
            let sk = &self.model.model.metadata().skeleton;
            let parents = sk.parents.iter().map(|&p| usize::try_from(p).ok()).collect();
            let offsets = sk.offsets.iter().map(|o| glam::DVec3::from_array(*o)).collect();
            lock::FittedLock::new(lock, parents, offsets)
        });
    }

    /// The foot lock [`TransitionRunner::generate`] applies, if any.
    pub fn foot_lock(&self) -> Option<&FootLock> {
        self.foot_lock.as_ref().map(lock::FittedLock::lock)
    }

    /// Sets the fallback that [`TransitionRunner::generate`] applies after the target blend
    /// and before the foot lock (`None`: off, the default). Per-frame stepping does not apply
    /// it (it needs the target miss, known once the blend window is computed): the engine
    /// reads [`TransitionState::target_miss`] and decides. See [`TransitionFallback`].
    pub fn set_fallback(&mut self, fallback: Option<TransitionFallback>) {
        self.fallback = fallback;
        self.model_fallback = false;
    }

    /// Applies the model's calibrated fallback in [`TransitionRunner::generate`], with the
    /// thresholds for each transition's length ([`TransitionModel::default_fallback_for`]); a
    /// model without calibrated thresholds gets none. [`TransitionRunner::set_fallback`] replaces it.
    pub fn set_model_fallback(&mut self) {
        self.fallback = None;
        self.model_fallback = true;
    }

    /// Whether this runner accepts transitions longer than the model was trained for
    /// ([`TransitionModel::transition_frames`]). Off by default: such a request is refused
    /// with [`MotionError::BeyondTrainedLength`], because beyond its training length the
    /// network drifts from the target and the target blend has to hide a larger miss. Turn
    /// it on to measure that (the benchmark does) or when the engine checks
    /// [`TransitionState::target_miss`] itself.
    pub fn allow_beyond_trained(&mut self, allow: bool) {
        self.beyond_trained = allow;
    }

    /// Starts a transition of the trained length ([`TransitionModel::transition_frames`]):
    /// `past` holds the context frames (global positions, `frames * 3K`, at least one; the
    /// model was trained with [`TransitionModel::past_frames`] of them), `target` the target
    /// pose and `next` the pose after it (`3K` each, for the target velocity). The context is
    /// fed through the model as in training; [`TransitionRunner::step`] then returns the
    /// frames of the transition one by one, the last one the target.
    pub fn start(
        &mut self,
        state: &mut TransitionState,
        past: &[f32],
        target: &[f32],
        next: &[f32],
    ) -> Result<(), MotionError> {
        let length = self.model.transition_frames;
        self.start_batch_for(std::slice::from_mut(state), past, target, next, length)
    }

    /// [`TransitionRunner::start`] with a transition of `length` frames before the target
    /// frame (`length + 1` steps in all); longer than the trained length only when
    /// [`TransitionRunner::allow_beyond_trained`] is on.
    pub fn start_for(
        &mut self,
        state: &mut TransitionState,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        length: usize,
    ) -> Result<(), MotionError> {
        self.start_batch_for(std::slice::from_mut(state), past, target, next, length)
    }

    /// [`TransitionRunner::start`] for `states.len()` characters in one run per context frame:
    /// `past` holds the same number of context frames for every character (`N * frames * 3K`,
    /// character-major), `target` and `next` `N * 3K` each.
    pub fn start_batch(
        &mut self,
        states: &mut [TransitionState],
        past: &[f32],
        target: &[f32],
        next: &[f32],
    ) -> Result<(), MotionError> {
        let length = self.model.transition_frames;
        self.start_batch_for(states, past, target, next, length)
    }

    /// [`TransitionRunner::start_batch`] with a transition of `length` frames (see
    /// [`TransitionRunner::start_for`]).
    pub fn start_batch_for(
        &mut self,
        states: &mut [TransitionState],
        past: &[f32],
        target: &[f32],
        next: &[f32],
        length: usize,
    ) -> Result<(), MotionError> {
        let per = self.check_start(states, past, target, next, length)?;
        let blend_from = self.blend_from(length);
        let n = states.len();
        let (k, d) = (self.model.joints, 3 * self.model.joints);
        let frames = per / d;
        let m = &self.model;
        // Context features and target vectors, normalized like in training.
        self.feats.resize(past.len(), 0.0);
        for (p, f) in past.chunks_exact(per).zip(self.feats.chunks_exact_mut(per)) {
            features::encode_positions(p, k, f);
            for frame in f.chunks_exact_mut(d) {
                m.x.normalize(frame);
            }
        }
        self.target_vec.resize(n * 2 * d, 0.0);
        self.x0.resize(n * d, 0.0);
        for c in 0..n {
            let tv = &mut self.target_vec[c * 2 * d..(c + 1) * 2 * d];
            features::target_vector(&target[c * d..(c + 1) * d], &next[c * d..(c + 1) * d], tv);
            m.x.normalize(&mut tv[..d]);
            m.velocity.normalize(&mut tv[d..]);
            self.x0[c * d..(c + 1) * d].copy_from_slice(&self.feats[c * per..c * per + d]);
        }
        let inputs: Vec<&[f32]> =
            m.start_target.iter().map(|&t| if t { &self.target_vec[..] } else { &self.x0[..] }).collect();
        let result = with_motion_states(&mut self.motion, states, 0..n, &m.model, |runner_states| {
            self.runner.start_batch(runner_states, &inputs)
        });
        result?;
        for (c, s) in states.iter_mut().enumerate() {
            s.reset(&target[c * d..(c + 1) * d], &past[(c + 1) * per - d..(c + 1) * per], frames, length, blend_from);
            s.x.copy_from_slice(&self.feats[c * per..c * per + d]);
            s.root = features::root_of(&past[c * per..]);
            s.started = true;
            s.context_fed = 1;
        }
        let mut sel = std::mem::take(&mut self.sel);
        sel.clear();
        sel.extend(0..n);
        let mut result = Ok(());
        for f in 1..frames {
            result = self.advance(states, &sel, Some((per, f)));
            if result.is_err() {
                break;
            }
            for (c, s) in states.iter_mut().enumerate() {
                let at = c * per + f * d;
                s.x.copy_from_slice(&self.feats[at..at + d]);
                s.root = features::root_of(&past[at..]);
                s.context_fed = f + 1;
            }
        }
        self.sel = sel;
        if result.is_err() {
            states.iter_mut().for_each(|s| s.started = false);
        }
        result
    }

    /// Begins a transition whose context the game feeds as it plays it, so that no call does
    /// the whole context's work at once (a frame budget): `first` holds each character's first
    /// context frame (`N * 3K` global positions), `target` and `next` as in
    /// [`TransitionRunner::start_batch_for`], `past_frames` the context frames in all (at
    /// least one; the model was trained with [`TransitionModel::past_frames`]) and `length` the
    /// transition's length. Runs no graph (one graph run when `past_frames` is 1); then
    /// [`TransitionRunner::feed_batch`] the other `past_frames - 1` frames, one per call (the
    /// first feed runs two graph runs, the others one), and step. The transition is the one
    /// [`TransitionRunner::start_batch_for`] starts from the same frames, bit for bit.
    pub fn begin_batch(
        &mut self,
        states: &mut [TransitionState],
        first: &[f32],
        target: &[f32],
        next: &[f32],
        past_frames: usize,
        length: usize,
    ) -> Result<(), MotionError> {
        let per = self.check_start(states, first, target, next, length)?;
        let blend_from = self.blend_from(length);
        let d = 3 * self.model.joints;
        if per != d {
            return Err(wrong_len("first", d, states.len(), first.len()));
        }
        if past_frames == 0 {
            return Err(MotionError::TransitionSequence {
                character: 0,
                reason: "a transition needs at least one context frame (past_frames >= 1)".into(),
            });
        }
        for (c, s) in states.iter_mut().enumerate() {
            let first = &first[c * d..(c + 1) * d];
            s.reset(&target[c * d..(c + 1) * d], first, past_frames, length, blend_from);
            s.root = features::root_of(first);
            s.started = false;
            s.context_fed = 0;
        }
        // The target vectors, kept by each character until its first graph run.
        for (c, s) in states.iter_mut().enumerate() {
            let tv = &mut s.target_vec;
            features::target_vector(&target[c * d..(c + 1) * d], &next[c * d..(c + 1) * d], tv);
            self.model.x.normalize(&mut tv[..d]);
            self.model.velocity.normalize(&mut tv[d..]);
        }
        if past_frames == 1 {
            // The first frame's features need no second frame: start now.
            self.first_pass(states, first, None)?;
        } else if states.len() == 1 {
            // One character: the start graph's target part now (a frame budget), the rest with
            // the second frame.
            let s = &mut states[0];
            let given: Vec<Option<&[f32]>> =
                self.model.start_target.iter().map(|&t| t.then_some(&s.target_vec[..])).collect();
            if let Some(p) = self.runner.start_begin(&given, self.spare_start.take())? {
                s.pending_key = PENDING_KEYS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if self.starts.len() >= MAX_PARTIALS {
                    self.spare_start = Some(self.starts.remove(0).1);
                }
                self.starts.push((s.pending_key, p));
            }
        }
        Ok(())
    }

    /// Feeds the next context frame of transitions begun with
    /// [`TransitionRunner::begin_batch`]: `frame` holds `N * 3K` global positions (every
    /// character of the call at the same point of its context). One graph run (and the start
    /// graph on the first context frame with the second, whose arrival lets the first be
    /// encoded); for one character alone the run goes node by node within a budget per call and
    /// may finish in the next call (a frame budget). After the last one the transitions can be
    /// stepped.
    pub fn feed_batch(&mut self, states: &mut [TransitionState], frame: &[f32]) -> Result<(), MotionError> {
        let (n, k) = (states.len(), self.model.joints);
        let d = 3 * k;
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        check_rows("frame", frame, n, d)?;
        let fed = states[0].context_fed;
        for (c, s) in states.iter().enumerate() {
            if s.started || s.context_total == 0 || s.context_fed >= s.context_total {
                return Err(MotionError::TransitionSequence {
                    character: c,
                    reason: "no context frame is due: begin a transition (TransitionRunner::begin_batch) and feed \
                             its context frames, then step it"
                        .into(),
                });
            }
            if s.context_fed != fed {
                return Err(MotionError::TransitionSequence {
                    character: c,
                    reason: format!(
                        "it has {} context frames fed, character 0 {fed}: feed characters at the same point of \
                         their context together",
                        s.context_fed
                    ),
                });
            }
        }
        // One character alone: the last frame's run, if left in progress, then this frame's
        // run node by node within the call's budget (the rest in the next call).
        let began = std::time::Instant::now();
        let costs = if n == 1 { Some(self.runner.pass_costs()?) } else { None };
        let settled = match &costs {
            Some(costs) => self.finish_pending(states, 0, costs),
            None => self.settle(states),
        };
        if let Err(e) = settled {
            states.iter_mut().for_each(|s| s.context_total = 0);
            return Err(e);
        }
        if fed == 0 {
            // The second context frame: the first one's features (its root velocity comes from
            // this frame) and the first graph run, then this frame's run.
            self.first_pass(states, frame, Some(frame))?;
        }
        // This frame's features, its previous root in `s.root`.
        self.feats.resize(n * d, 0.0);
        for (c, s) in states.iter().enumerate() {
            let f = &mut self.feats[c * d..(c + 1) * d];
            features::encode_frame(s.root, &frame[c * d..(c + 1) * d], f);
            self.model.x.normalize(f);
        }
        let result = match &costs {
            Some(costs) => self
                .begin_pending(states, 0, PassKind::Context, Some((d, 0)))
                .and_then(|()| self.run_pending(states, costs, began, self.budgets.1, f64::INFINITY).map(|_| ())),
            None => {
                let mut sel = std::mem::take(&mut self.sel);
                sel.clear();
                sel.extend(0..n);
                let result = self.advance(states, &sel, Some((d, 0)));
                self.sel = sel;
                result
            }
        };
        if let Err(e) = result {
            states.iter_mut().for_each(|s| s.context_total = 0);
            return Err(e);
        }
        for (c, s) in states.iter_mut().enumerate() {
            s.x.copy_from_slice(&self.feats[c * d..(c + 1) * d]);
            s.root = features::root_of(&frame[c * d..]);
            s.context_fed += 1;
            if s.context_fed == s.context_total {
                s.last.copy_from_slice(&frame[c * d..(c + 1) * d]);
                s.started = true;
            }
        }
        Ok(())
    }

    /// The first graph run of begun transitions: the first context frame (in `s.last`) encoded
    /// with the root velocity towards `second` (or none when there is no second frame), the
    /// start graph run on it and the target vectors of `begin_batch`.
    fn first_pass(
        &mut self,
        states: &mut [TransitionState],
        first: &[f32],
        second: Option<&[f32]>,
    ) -> Result<(), MotionError> {
        let (n, d) = (states.len(), 3 * self.model.joints);
        self.x0.resize(n * d, 0.0);
        self.target_vec.resize(n * 2 * d, 0.0);
        for (c, s) in states.iter().enumerate() {
            self.target_vec[c * 2 * d..(c + 1) * 2 * d].copy_from_slice(&s.target_vec);
            let f0 = &s.last;
            let prev = match second {
                Some(second) => {
                    let (r0, r1) = (features::root_of(f0), features::root_of(&second[c * d..]));
                    [2.0 * r0[0] - r1[0], 2.0 * r0[1] - r1[1], 2.0 * r0[2] - r1[2]]
                }
                None => features::root_of(&first[c * d..]),
            };
            let x0 = &mut self.x0[c * d..(c + 1) * d];
            features::encode_frame(prev, f0, x0);
            self.model.x.normalize(x0);
        }
        let m = &self.model;
        let (target_vec, x0) = (&self.target_vec[..], &self.x0[..]);
        let inputs: Vec<&[f32]> = m.start_target.iter().map(|&t| if t { target_vec } else { x0 }).collect();
        let begun = match n {
            1 => self.starts.iter().position(|(k, _)| *k == states[0].pending_key),
            _ => None,
        };
        let result = match begun {
            Some(i) => {
                let (_, mut p) = self.starts.remove(i);
                let r = self.runner.start_finish(&mut p, &mut states[0].motion, &inputs);
                self.spare_start = Some(p);
                r
            }
            None => with_motion_states(&mut self.motion, states, 0..n, &m.model, |runner_states| {
                self.runner.start_batch(runner_states, &inputs)
            }),
        };
        if let Err(e) = result {
            states.iter_mut().for_each(|s| s.context_total = 0);
            return Err(e);
        }
        for (c, s) in states.iter_mut().enumerate() {
            s.x.copy_from_slice(&self.x0[c * d..(c + 1) * d]);
            s.root = features::root_of(&s.last);
            s.context_fed = 1;
            if s.context_total == 1 {
                s.started = true;
            }
        }
        Ok(())
    }

    /// The first frame of a transition of `length` frames that the target blend moves.
    fn blend_from(&self, length: usize) -> usize {
        let blend = self.model.target_blend;
        (0..=length).find(|&t| features_blend_weight(t, length, blend) > 0.0).unwrap_or(length)
    }

    /// The checks of [`TransitionRunner::start_batch_for`] before any work: a batch, a length the
    /// runner allows, buffers of the right lengths with finite values, a heightmap per
    /// character for a terrain-aware model. Returns the values of context per character.
    fn check_start(
        &self,
        states: &[TransitionState],
        past: &[f32],
        target: &[f32],
        next: &[f32],
        length: usize,
    ) -> Result<usize, MotionError> {
        let n = states.len();
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        let trained = self.model.transition_frames;
        if length > trained && !self.beyond_trained {
            return Err(MotionError::BeyondTrainedLength { requested: length, trained });
        }
        let d = 3 * self.model.joints;
        let per = past.len() / n;
        if past.is_empty() || !past.len().is_multiple_of(n) || per == 0 || !per.is_multiple_of(d) {
            return Err(MotionError::BufferLength {
                name: "past".into(),
                expected: n * d * self.model.past_frames,
                batch: n,
                width: d * self.model.past_frames,
                found: past.len(),
            });
        }
        check_rows("past", past, n, per)?;
        check_rows("target", target, n, d)?;
        check_rows("next", next, n, d)?;
        if self.model.terrain.is_some()
            && let Some(c) = states.iter().position(|s| s.heightmap.is_none())
        {
            return Err(MotionError::TransitionSequence {
                character: c,
                reason: "this model is terrain-aware: give the character the ground it stands on \
                         (TransitionState::set_heightmap) before starting the transition"
                    .into(),
            });
        }
        Ok(per)
    }

    /// Runs the step graph on the `x` of the characters in `sel` into `self.next` (row `i` for
    /// character `sel[i]`) and advances their recurrent states. `context`: `(values per
    /// character, frame)` while feeding the context, whose frame `frame` of `self.feats` is then
    /// the interpolation base; `None` in the transition, whose base is the interpolation frame.
    fn advance(
        &mut self,
        states: &mut [TransitionState],
        sel: &[usize],
        context: Option<(usize, usize)>,
    ) -> Result<(), MotionError> {
        self.pass_inputs(states, sel, context)?;
        let inputs =
            frame_input_slices(&self.model.frame_inputs, [&self.xb, &self.offset, &self.base, &self.patch, &self.tta]);
        let inputs = &inputs[..self.model.frame_inputs.len()];
        let next = &mut self.next[..];
        let runner = &mut self.runner;
        with_motion_states(&mut self.motion, states, sel.iter().copied(), &self.model.model, |s| {
            runner.step_batch(s, inputs, &mut [next])
        })
    }

    /// The frame inputs of a graph run of the characters `sel` (see [`TransitionRunner::advance`])
    /// into the runner's buffers ([`TransitionRunner::frame_inputs`]).
    fn pass_inputs(
        &mut self,
        states: &[TransitionState],
        sel: &[usize],
        context: Option<(usize, usize)>,
    ) -> Result<(), MotionError> {
        let m = &self.model;
        let (n, d) = (sel.len(), 3 * m.joints);
        self.xb.resize(n * d, 0.0);
        self.offset.resize(n * d, 0.0);
        self.next.resize(n * d, 0.0);
        if m.frame_inputs.contains(&FrameInput::Base) {
            self.base.resize(n * d, 0.0);
            for (row, &c) in sel.iter().enumerate() {
                let s = &states[c];
                let b = &mut self.base[row * d..(row + 1) * d];
                match context {
                    Some((per, f)) => b.copy_from_slice(&self.feats[c * per + f * d..c * per + (f + 1) * d]),
                    None => {
                        interpolation_frame(&s.last, &s.target, s.generated, s.length, b);
                        m.x.normalize(b);
                    }
                }
            }
        }
        if let Some(z) = &m.time_to_arrival {
            self.tta.resize(n * z.dims, 0.0);
            for (row, &c) in sel.iter().enumerate() {
                let s = &states[c];
                // Frames from the predicted frame to the target: context frame `f` of `per / d`
                // predicts frame `f`, the target is `length` frames after the context.
                let left = match context {
                    Some(_) => s.context_total + s.length - s.context_fed,
                    None => s.length.saturating_sub(s.generated),
                };
                z.embed(left, &mut self.tta[row * z.dims..(row + 1) * z.dims]);
            }
        }
        if let Some(t) = &m.terrain {
            let p = t.side * t.side;
            self.patch.resize(n * p, 0.0);
            for (row, &c) in sel.iter().enumerate() {
                let s = &states[c];
                let out = &mut self.patch[row * p..(row + 1) * p];
                let Some(map) = &s.heightmap else {
                    return Err(MotionError::TransitionSequence {
                        character: c,
                        reason: "this model is terrain-aware and the character's heightmap was removed \
                                 (TransitionState::set_heightmap(None)) during the transition"
                            .into(),
                    });
                };
                // RTN sec. 3.2: p_t under the root of the frame fed, as `zoo_rtn` trains it.
                terrain_patch(map, s.root, t.extent, t.side, None, out);
                t.norm.normalize(out);
            }
        }
        for (row, &c) in sel.iter().enumerate() {
            let s = &states[c];
            let (xb, ob) = (&mut self.xb[row * d..(row + 1) * d], &mut self.offset[row * d..(row + 1) * d]);
            xb.copy_from_slice(&s.x);
            // o_t = ((y_T - y_t) - mu_o) / sigma_o, y_t decoded from the normalized x_t and its root.
            for i in 0..d {
                let f = s.x[i] * m.x.std[i] + m.x.mean[i];
                let y = if i < 3 { s.root[i] } else { f + s.root[i % 3] };
                ob[i] = s.target[i] - y;
            }
            m.offset.normalize(ob);
        }
        Ok(())
    }

    /// The frame inputs [`TransitionRunner::pass_inputs`] wrote, in the graph's order (the
    /// first `frame_inputs.len()`).
    fn frame_inputs(&self) -> [&[f32]; 5] {
        frame_input_slices(&self.model.frame_inputs, [&self.xb, &self.offset, &self.base, &self.patch, &self.tta])
    }

    /// Begins character `c`'s next graph run without running it (a frame budget spreads it
    /// over calls): its frame inputs now (kept in the state), its recurrent state when it ends.
    fn begin_pending(
        &mut self,
        states: &mut [TransitionState],
        c: usize,
        kind: PassKind,
        context: Option<(usize, usize)>,
    ) -> Result<(), MotionError> {
        debug_assert!(states[c].pending.is_none());
        self.pass_inputs(states, &[c], context)?;
        let mut stored = std::mem::take(&mut states[c].pending_inputs);
        stored.clear();
        let inputs = self.frame_inputs();
        for i in &inputs[..self.model.frame_inputs.len()] {
            stored.extend_from_slice(i);
        }
        let s = &mut states[c];
        s.pending_inputs = stored;
        s.pending = Some(kind);
        s.pending_key = PENDING_KEYS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.resume(s).map(|_| ())
    }

    /// The index in `partials` of the run `s` has in progress, begun again from its stored
    /// inputs when this runner does not hold it.
    fn resume(&mut self, s: &TransitionState) -> Result<usize, MotionError> {
        if let Some(i) = self.partials.iter().position(|(k, _)| *k == s.pending_key) {
            return Ok(i);
        }
        let mut run = match self.spare.pop() {
            Some(r) => r,
            None => self.runner.partial()?,
        };
        let mut slices: [&[f32]; 5] = [&[], &[], &[], &[], &[]];
        let (mut at, mut count) = (0, 0);
        for (slot, info) in slices.iter_mut().zip(self.runner.model().inputs()) {
            *slot = &s.pending_inputs[at..at + info.width];
            at += info.width;
            count += 1;
        }
        self.runner.partial_begin(&mut run, &s.motion, &slices[..count])?;
        if self.partials.len() >= MAX_PARTIALS {
            let (_, old) = self.partials.remove(0);
            self.spare.push(old);
        }
        self.partials.push((s.pending_key, run));
        Ok(self.partials.len() - 1)
    }

    /// Finishes character `c`'s run in progress, if any: the recurrent state and, for a
    /// generated frame, the frame computed ahead.
    fn finish_pending(
        &mut self,
        states: &mut [TransitionState],
        c: usize,
        costs: &PassCosts,
    ) -> Result<(), MotionError> {
        let Some(kind) = states[c].pending else { return Ok(()) };
        let d = 3 * self.model.joints;
        let i = self.resume(&states[c])?;
        let (_, mut run) = self.partials.remove(i);
        if self.next.len() < d {
            self.next.resize(d, 0.0);
        }
        let s = &mut states[c];
        let result = self.runner.partial_finish(&mut run, costs, &mut s.motion, &mut [&mut self.next[..d]]);
        self.spare.push(run);
        s.pending = None;
        result?;
        if kind == PassKind::Generation {
            self.keep_ahead(s, 0);
        }
        Ok(())
    }

    /// Runs the next nodes of the one character's run in progress while the call (`began`)
    /// stays within `budget` runs of the step graph ([`PassCosts::run_time`], with the next
    /// node's measured share) and the character's frames generated, in runs, within `cap`;
    /// finishes the run when its last node ran. Whether it ran a node.
    fn run_pending(
        &mut self,
        states: &mut [TransitionState],
        costs: &PassCosts,
        began: std::time::Instant,
        budget: f64,
        cap: f64,
    ) -> Result<bool, MotionError> {
        if states[0].pending.is_none() {
            return Ok(false);
        }
        let i = self.resume(&states[0])?;
        let mut ran = false;
        loop {
            let run = &mut self.partials[i].1;
            if run.complete(costs) {
                self.finish_pending(states, 0, costs)?;
                return Ok(true);
            }
            let next = run.next_cost(costs);
            let spent = began.elapsed().as_secs_f64() / costs.run_time;
            if spent + next > budget || states[0].generated as f64 + run.done(costs) + next > cap + 1e-9 {
                return Ok(ran);
            }
            self.runner.partial_node(run, costs)?;
            ran = true;
        }
    }

    /// Finishes every run in progress of `states` (before a call that runs them together).
    fn settle(&mut self, states: &mut [TransitionState]) -> Result<(), MotionError> {
        if states.iter().all(|s| s.pending.is_none()) {
            return Ok(());
        }
        let costs = self.runner.pass_costs()?;
        for c in 0..states.len() {
            self.finish_pending(states, c, &costs)?;
        }
        Ok(())
    }

    /// Row `row` of the last graph run as `s`'s next raw frame, kept in its frames computed
    /// ahead.
    fn keep_ahead(&self, s: &mut TransitionState, row: usize) {
        let d = 3 * self.model.joints;
        if s.ahead.is_empty() {
            s.ahead_from = s.generated;
        }
        let at = s.ahead.len();
        s.ahead.resize(at + d, 0.0);
        let mut frames = std::mem::take(&mut s.ahead);
        self.take_raw(s, row, &mut frames[at..at + d]);
        s.ahead = frames;
    }

    /// Takes row `row` of the last graph run as character `s`'s next raw frame: feeds it back
    /// and writes its global positions into `pose`.
    fn take_raw(&self, s: &mut TransitionState, row: usize, pose: &mut [f32]) {
        let d = pose.len();
        let next = &self.next[row * d..(row + 1) * d];
        s.x.copy_from_slice(next);
        pose.copy_from_slice(next);
        self.model.x.denormalize(pose);
        s.root = features::decode_frame_in_place(s.root, pose);
        s.generated += 1;
    }

    /// The next frame of one character's transition into `pose` (`3K` global positions):
    /// frame `i` of `0..=L` of the target-blended transition (RTN eq. 15-16), the same frames
    /// [`TransitionRunner::generate`] writes (without its optional foot lock). The blend over
    /// the last [`TransitionModel::target_blend`] frames needs the network's predicted target
    /// frame, so the steps before the blend window compute the network's frames ahead, one
    /// extra graph run per step at most ([`TransitionRunner::step_batch`]);
    /// [`TransitionState::target_miss`] is known once stepping reaches the window. Stepping past
    /// the target frame is an error.
    pub fn step(&mut self, state: &mut TransitionState, pose: &mut [f32]) -> Result<(), MotionError> {
        self.step_batch(std::slice::from_mut(state), pose)
    }

    /// [`TransitionRunner::step`] into glam vectors, one per joint (`K` of them).
    pub fn step_vec3(&mut self, state: &mut TransitionState, joints: &mut [glam::Vec3]) -> Result<(), MotionError> {
        let d = 3 * self.model.joints;
        if joints.len() != self.model.joints {
            return Err(wrong_len("joints", self.model.joints, 1, joints.len()));
        }
        let mut pose = std::mem::take(&mut self.poses);
        pose.resize(d, 0.0);
        let r = self.step_batch(std::slice::from_mut(state), &mut pose[..d]);
        if r.is_ok() {
            crate::pose::read_positions(&pose[..d], joints);
        }
        self.poses = pose;
        r
    }

    /// Checks that every character can take a step; `raw` for [`TransitionRunner::step_raw`].
    fn check_steppable(&self, states: &[TransitionState], poses: usize, raw: bool) -> Result<(), MotionError> {
        let (n, d) = (states.len(), 3 * self.model.joints);
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        if poses != n * d {
            return Err(wrong_len("poses", d, n, poses));
        }
        let sequence = |character: usize, reason: String| MotionError::TransitionSequence { character, reason };
        for (c, s) in states.iter().enumerate() {
            if !s.started {
                return Err(sequence(c, "start the transition (TransitionRunner::start) before stepping it".into()));
            }
            if raw && s.frames > 0 && !s.raw {
                return Err(sequence(
                    c,
                    "this transition is stepped with the target blend (step); raw and blended stepping do not mix: start a new transition for step_raw".into(),
                ));
            }
            if !raw && s.raw {
                return Err(sequence(
                    c,
                    "this transition is stepped raw (step_raw); raw and blended stepping do not mix: start a new transition for step".into(),
                ));
            }
            if !raw && s.frames > s.length {
                return Err(sequence(
                    c,
                    format!(
                        "the transition already returned its target frame (frame {} of 0..={}); start a new transition",
                        s.frames, s.length
                    ),
                ));
            }
        }
        Ok(())
    }

    /// [`TransitionRunner::step`] for `states.len()` characters in one graph run: `poses`
    /// receives `N * 3K` values, character-major. Characters may be at different frames of
    /// their transitions. Results match one-by-one stepping up to float rounding of tract's
    /// batched kernels (below 1e-3 clip units over a 30-frame transition in the tests).
    ///
    /// The target blend needs the network's predicted target frame before the first blended
    /// frame (RTN eq. 15-16), so the runner computes the network's frames ahead of the ones it
    /// returns: one extra graph run per character per step, spread so that no step runs more
    /// than two per character (a frame budget), and across a batch so that few characters run
    /// their extra one in the same step. Transitions shorter than about twice the blend
    /// window compute the rest of the window in the step that enters it.
    pub fn step_batch(&mut self, states: &mut [TransitionState], poses: &mut [f32]) -> Result<(), MotionError> {
        self.check_steppable(states, poses.len(), false)?;
        if states.len() == 1 && self.spread_ahead {
            return self.step_one(&mut states[0], poses);
        }
        self.settle(states)?;
        let (d, blend) = (3 * self.model.joints, self.model.target_blend);
        let n = states.len();
        // How many network frames each character has computed by the end of this step.
        let mut need = std::mem::take(&mut self.need);
        need.clear();
        let mut rounds = 0;
        for (c, s) in states.iter().enumerate() {
            let (f, length, b) = (s.frames, s.length, s.blend_from);
            let extra = length - b;
            // This character's extra runs start at `first` (staggered across the batch) and
            // bring it `extra` frames ahead by frame `b`. Without spreading (`generate`, where
            // no frame is budgeted), all of them run in the step that enters the blend.
            let slack = b.saturating_sub(extra);
            let first = if self.spread_ahead { slack - c * slack / n } else { b + 1 };
            let lead = if f >= first { (f - first + 1).min(extra) } else { 0 };
            let mut k = (f + 1 + lead).min(length + 1);
            if f >= b {
                k = length + 1;
            }
            let k = k.max(s.generated);
            rounds = rounds.max(k - s.generated);
            need.push(k);
        }
        let mut sel = std::mem::take(&mut self.sel);
        let mut result = Ok(());
        for _ in 0..rounds {
            sel.clear();
            sel.extend((0..n).filter(|&c| states[c].generated < need[c]));
            result = self.advance(states, &sel, None);
            if result.is_err() {
                break;
            }
            for (row, &c) in sel.iter().enumerate() {
                self.keep_ahead(&mut states[c], row);
            }
        }
        self.sel = sel;
        self.need = need;
        result?;
        for (s, pose) in states.iter_mut().zip(poses.chunks_exact_mut(d)) {
            if s.generated == s.length + 1 && s.miss.is_none() {
                s.miss = Some(blend_window(&mut s.ahead, s.ahead_from, s.length, &s.target, blend));
            }
            debug_assert_eq!(s.ahead_from, s.frames);
            pose.copy_from_slice(&s.ahead[..d]);
            s.ahead.drain(..d);
            s.ahead_from += 1;
            s.frames += 1;
        }
        Ok(())
    }

    /// [`TransitionRunner::step_batch`] for one character, with a frame budget: the runs its
    /// frame needs (its own, the context's last one if left in progress), then its next runs
    /// node by node while the call stays within [`CALL_BUDGET`] runs and the frames computed
    /// ahead within a schedule that brings them to the blend window by its first frame (a
    /// share of a run per step, where `step_batch` spreads whole runs over a batch). The same
    /// frames, bit for bit: every run is the one-character plan's, on the same inputs.
    fn step_one(&mut self, s: &mut TransitionState, pose: &mut [f32]) -> Result<(), MotionError> {
        let began = std::time::Instant::now();
        let costs = self.runner.pass_costs()?;
        let states = std::slice::from_mut(s);
        let (f, length, b) = (states[0].frames, states[0].length, states[0].blend_from);
        // What the step needs first: the context's last run, then its own frame (every frame
        // from the blend window on).
        if states[0].pending == Some(PassKind::Context) {
            self.finish_pending(states, 0, &costs)?;
        }
        let must = if f >= b { length + 1 } else { f + 1 };
        while states[0].generated < must {
            if states[0].pending.is_none() {
                self.begin_pending(states, 0, PassKind::Generation, None)?;
            }
            self.finish_pending(states, 0, &costs)?;
        }
        // Then the next runs as far as the call's budget and the schedule of the frames computed
        // ahead allow: `length - b` more than the step's own by step `b - 1`, growing evenly.
        let extra = (length - b) as f64;
        let cap = ((f + 1) as f64 + extra * (f + 1) as f64 / b.max(1) as f64).min((length + 1) as f64);
        while states[0].generated < length + 1 {
            if states[0].pending.is_none() {
                if states[0].generated as f64 >= cap {
                    break;
                }
                self.begin_pending(states, 0, PassKind::Generation, None)?;
            }
            let ran = self.run_pending(states, &costs, began, self.budgets.0, cap)?;
            if !ran || states[0].pending.is_some() {
                break;
            }
        }
        let s = &mut states[0];
        let (d, blend) = (3 * self.model.joints, self.model.target_blend);
        if s.generated == s.length + 1 && s.miss.is_none() {
            s.miss = Some(blend_window(&mut s.ahead, s.ahead_from, s.length, &s.target, blend));
        }
        debug_assert_eq!(s.ahead_from, s.frames);
        pose[..d].copy_from_slice(&s.ahead[..d]);
        s.ahead.drain(..d);
        s.ahead_from += 1;
        s.frames += 1;
        Ok(())
    }

    /// Sets the budgets of a step and of a context frame's call for one character, in runs of the
    /// step graph (defaults 2.0 and 1.6): 0 runs only what each call needs, leaving every run it
    /// can in progress, whatever the machine's speed. For tests.
    #[doc(hidden)]
    pub fn set_call_budgets(&mut self, step: f64, context: f64) {
        self.budgets = (step, context);
    }

    /// The network's next frame, without the target blend and without a length limit: the
    /// frames of the raw unroll (what the model predicts, as candle's `Rtn::unroll`), for
    /// callers that post-process themselves. A transition is stepped either raw or blended.
    pub fn step_raw(&mut self, state: &mut TransitionState, pose: &mut [f32]) -> Result<(), MotionError> {
        self.step_raw_batch(std::slice::from_mut(state), pose)
    }

    /// [`TransitionRunner::step_raw`] for `states.len()` characters in one graph run.
    pub fn step_raw_batch(&mut self, states: &mut [TransitionState], poses: &mut [f32]) -> Result<(), MotionError> {
        self.check_steppable(states, poses.len(), true)?;
        self.settle(states)?;
        let d = 3 * self.model.joints;
        let mut sel = std::mem::take(&mut self.sel);
        sel.clear();
        sel.extend(0..states.len());
        let result = self.advance(states, &sel, None);
        self.sel = sel;
        result?;
        for (c, (s, pose)) in states.iter_mut().zip(poses.chunks_exact_mut(d)).enumerate() {
            self.take_raw(s, c, pose);
            s.raw = true;
            s.frames += 1;
        }
        Ok(())
    }

    /// A whole transition of `frames` new frames into `out` (`(frames + 1) * 3K` values: the
    /// transition, then the target frame), target-blended (RTN eq. 15-16) so that the last
    /// frame equals `target` and the motion reaches it without a pop, then foot-locked when
    /// [`TransitionRunner::set_foot_lock`] enabled it. The same frames as starting with
    /// [`TransitionRunner::start_for`] and stepping `frames + 1` times; `frames` beyond the
    /// trained length needs [`TransitionRunner::allow_beyond_trained`].
    pub fn generate(
        &mut self,
        state: &mut TransitionState,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        out: &mut [f32],
    ) -> Result<(), MotionError> {
        self.generate_batch(std::slice::from_mut(state), past, target, next, out)
    }

    /// [`TransitionRunner::generate`] for `states.len()` characters (character-major buffers;
    /// `out` holds `N * (frames + 1) * 3K` values).
    pub fn generate_batch(
        &mut self,
        states: &mut [TransitionState],
        past: &[f32],
        target: &[f32],
        next: &[f32],
        out: &mut [f32],
    ) -> Result<(), MotionError> {
        let (n, d) = (states.len(), 3 * self.model.joints);
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        let per = out.len() / n;
        if out.is_empty() || !out.len().is_multiple_of(n) || per < d || !per.is_multiple_of(d) {
            return Err(MotionError::BufferLength {
                name: "out".into(),
                expected: n * d * (self.model.transition_frames + 1),
                batch: n,
                width: d * (per / d).max(1),
                found: out.len(),
            });
        }
        let steps = per / d;
        self.start_batch_for(states, past, target, next, steps - 1)?;
        // Step all characters frame by frame through a contiguous scratch row, then scatter.
        let mut poses = std::mem::take(&mut self.poses);
        poses.resize(n * d, 0.0);
        let mut result = Ok(());
        // A whole transition in one call: the frames ahead in one step each (fewest graph runs).
        self.spread_ahead = false;
        for f in 0..steps {
            result = self.step_batch(states, &mut poses);
            if result.is_err() {
                break;
            }
            for c in 0..n {
                out[c * per + f * d..c * per + (f + 1) * d].copy_from_slice(&poses[c * d..(c + 1) * d]);
            }
        }
        self.spread_ahead = true;
        self.poses = poses;
        result?;
        let past_per = past.len() / n;
        for (c, s) in states.iter_mut().enumerate() {
            let fallback = if self.model_fallback { self.model.default_fallback_for(s.length) } else { self.fallback };
            let w = match (fallback, s.miss) {
                (Some(f), Some(miss)) => f.weight(miss.mean),
                _ => 0.0,
            };
            s.fallback_weight = w;
            if w > 0.0 {
                let last = &past[(c + 1) * past_per - d..(c + 1) * past_per];
                blend_towards_interpolation(&mut out[c * per..(c + 1) * per], last, &target[c * d..(c + 1) * d], w);
            }
        }
        if let Some(lock) = &mut self.foot_lock {
            for c in 0..n {
                lock.apply(&past[(c + 1) * past_per - d..(c + 1) * past_per], &mut out[c * per..(c + 1) * per]);
            }
        }
        Ok(())
    }
}

/// Unnormalized features of frame `i` (`0..=n`) of the linear interpolation of global
/// positions from the last context frame `last` to `target` over `n` frames before the target
/// (weight `(i + 1) / (n + 1)`): the interpolation base of an interpolation-residual RTN, as
/// `zoo_rtn::features::interpolation_frame` computes it in training (docs/runtime-protocol.md).
fn interpolation_frame(last: &[f32], target: &[f32], i: usize, n: usize, out: &mut [f32]) {
    let steps = (n + 1) as f32;
    let w = (i + 1) as f32 / steps;
    for a in 0..3 {
        out[a] = (target[a] - last[a]) / steps;
    }
    for j in 3..out.len() {
        let a = j % 3;
        out[j] = (1.0 - w) * (last[j] - last[a]) + w * (target[j] - target[a]);
    }
}

/// Moves each of the `n + 1` poses of `frames` (the last one the target) a share `w` of the way
/// to the linear interpolation of positions from `last` to `target`, weight `(i + 1) / (n + 1)`
/// for frame `i` (the same blend as `zoo_rtn::fallback::blend_towards_interpolation`).
fn blend_towards_interpolation(frames: &mut [f32], last: &[f32], target: &[f32], w: f32) {
    let d = target.len();
    let steps = (frames.len() / d) as f32;
    for (i, f) in frames.chunks_exact_mut(d).enumerate() {
        let a = (i + 1) as f32 / steps;
        for ((y, l), t) in f.iter_mut().zip(last).zip(target) {
            let lerp = l + a * (t - l);
            *y += w * (lerp - *y);
        }
    }
}

/// The offset weight of frame `f` of a transition whose target frame is `length`.
fn features_blend_weight(f: usize, length: usize, blend: usize) -> f64 {
    zoo_motion::blend::target_blend_offset_weight(f, length, blend)
}

/// Blends the raw frames `ahead` (frames `from..=length`, global positions, the last one the
/// network's target frame) towards `target` as [`features::target_blend`] does over a whole
/// transition, and returns the miss of the raw target frame.
fn blend_window(ahead: &mut [f32], from: usize, length: usize, target: &[f32], blend: usize) -> TargetMiss {
    let d = target.len();
    let last = ahead.len() - d;
    let (mut sum, mut max) = (0.0f32, 0.0f32);
    for (t, y) in target.chunks_exact(3).zip(ahead[last..].chunks_exact(3)) {
        let dist = ((t[0] - y[0]).powi(2) + (t[1] - y[1]).powi(2) + (t[2] - y[2]).powi(2)).sqrt();
        sum += dist;
        max = max.max(dist);
    }
    let miss = TargetMiss { mean: sum / (d / 3) as f32, max };
    for i in 0..ahead.len() / d {
        let w = features_blend_weight(from + i, length, blend) as f32;
        if w > 0.0 {
            for j in 0..d {
                let e = target[j] - ahead[last + j];
                ahead[i * d + j] += w * e;
            }
        }
    }
    miss
}

/// Runs `f` on the recurrent states of the characters `which` (indices into `states`)
/// gathered into `scratch` (swapped, not copied), and swaps them back whatever `f` returns.
/// `[x, offset, base, patch, tta]` in the order of the graph's frame inputs `which`.
fn frame_input_slices<'a>(which: &[FrameInput], [x, offset, base, patch, tta]: [&'a [f32]; 5]) -> [&'a [f32]; 5] {
    let mut inputs: [&[f32]; 5] = [&[], &[], &[], &[], &[]];
    for (slot, which) in inputs.iter_mut().zip(which) {
        *slot = match which {
            FrameInput::X => x,
            FrameInput::Offset => offset,
            FrameInput::Base => base,
            FrameInput::Terrain => patch,
            FrameInput::Tta => tta,
        };
    }
    inputs
}

fn with_motion_states<R>(
    scratch: &mut Vec<MotionState>,
    states: &mut [TransitionState],
    which: impl Iterator<Item = usize> + Clone,
    model: &MotionModel,
    f: impl FnOnce(&mut [MotionState]) -> R,
) -> R {
    let n = which.clone().count();
    while scratch.len() < n {
        scratch.push(model.new_state());
    }
    for (s, c) in scratch.iter_mut().zip(which.clone()) {
        std::mem::swap(s, &mut states[c].motion);
    }
    let r = f(&mut scratch[..n]);
    for (s, c) in scratch.iter_mut().zip(which) {
        std::mem::swap(s, &mut states[c].motion);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        fn send<T: Send>() {}
        send_sync::<TransitionModel>();
        send_sync::<TransitionState>();
        send::<TransitionRunner>();
    }

    #[test]
    fn rows_are_checked() {
        assert!(check_rows("a", &[1.0, 2.0, 3.0], 1, 3).is_ok());
        assert!(matches!(check_rows("a", &[1.0, 2.0], 1, 3), Err(MotionError::BufferLength { .. })));
        let err = check_rows("a", &[1.0, 2.0, 3.0, f32::NAN, 0.0, 0.0], 2, 3).unwrap_err();
        assert!(matches!(err, MotionError::NonFinite { character: 1, index: 3, .. }), "{err}");
    }
}
