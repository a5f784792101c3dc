//! The stitching task: refines an aligned sequence of RMR pose vectors with an exported
//! Recurrent Motion Refiner (Kim et al. 2023, sec. 6) on tract, window by window.
//!
//! The file is what `zoo export --onnx RMR_DIR` writes: the refiner over one window
//! (`x [frames, batch, dim] -> y [frames, batch, dim]`, normalised, contacts as logits) with
//! its `stitch` section (window, stride, blend, layout; `zoo_format::StitchTask`), skeleton,
//! fps and normalisation (group `x`) in `metadata_props`. [`StitchRefiner`] plans the graph once for a window of `w` frames at batch 1
//! and refines raw pose vectors (the layout of `zoo_rmr::features`: `r, p, q, v, c` per frame)
//! exactly as the offline `zoo_rmr::stitch::refine_sequence` does: windows every `s` frames
//! plus one ending on the last frame, each window's input holding the frames already refined,
//! the difference at each window's first frame blended away over `blend_frames` frames,
//! contacts returned as 0/1.
//!
//! Poses in and out: [`StitchRefiner::refine_poses`] takes a whole aligned sequence of
//! [`EnginePose`]s (root transform plus local joint rotations), encodes it with the task
//! protocol's pose vector ([`zoo_protocol::stitch`], the code the offline tools use), refines it,
//! decodes it from the input's first ground root and, as `zoo stitch` does by default, puts the
//! ankles where the refiner predicts them and locks the planted feet by the predicted contacts
//! ([`zoo_protocol::stitch::lock`]), writing into the caller's poses. Given the seams
//! ([`StitchRefiner::refine_poses_at_seams`]) it also guards them against pops between the two
//! ([`zoo_protocol::stitch::guard`]), as `zoo stitch` does.
//!
//! Streaming for motion matching: [`StitchStream`] (from [`StitchRefiner::stream`]) takes one
//! pose per frame as the engine decides it and gives refined poses back with a fixed latency
//! ([`StitchStream::latency`]: `w + s - 1` frames for the refiner alone, as it spreads each
//! window's network work over the `s - 1` pushes after it; `+` [`STREAM_LOOKAHEAD`] `+`
//! [`STREAM_CHUNK`] `- 1` with the foot lock, the seam guard or the seams' reach). It runs the
//! same windows as [`StitchRefiner::refine_sequence`], so its refined pose vectors are the whole
//! sequence's, then the ankle IK, the guard of the marked seams, the foot lock and the seams'
//! reach of `zoo stitch` over a lookahead: its poses are
//! [`StitchRefiner::refine_poses_at_seams`]'s up to float rounding.

use crate::error::{MotionError, chain};
use crate::metadata::MotionModelMetadata;
use crate::pose::{EnginePose, root_delta};
use glam::{DQuat, DVec3, Quat, Vec3};
use std::ops::Deref;
use std::path::Path;
use std::sync::Arc;
use tract_onnx::prelude::*;
use zoo_format::StitchFallback;
use zoo_motion::blend::SeamInertializer;
use zoo_motion::{Clip, Skeleton};
use zoo_protocol::stitch::{GroundRoot, PoseFrame, StitchLayout, decode_pose, encode_pose, next_root};

type Plan = Arc<TypedRunnableModel>;

/// Frames per node of the window graph a stream runs over several pushes ([`SpreadPlan`]): each
/// recurrence in chunks of this many frames, each product over the window too. Nodes of a
/// third of a push's share or less at the default stride (finer ones re-read the products'
/// weights more often: 5 frames made a window 1.3x slower).
const SPREAD_CHUNK: usize = 10;

/// A push's time for its window's share: the window's measured time over the pushes it is spread
/// over, times this (the rest of the stream's work, the lock and the guard, takes the margin).
const SPREAD_SLACK: f64 = 1.4;

/// A window a stream is running node by node: the graph's state, the next node (an index in
/// [`SpreadPlan`]'s order) and the pushes that worked on it.
struct WindowJob {
    state: TypedSimpleState,
    at: usize,
    worked: usize,
    /// The window's input tensor (reused by the next window's state).
    input: Arc<Tensor>,
    /// The node inputs of a run (reused: `crate::ops::kept::compute`).
    scratch: Vec<TValue>,
}

impl std::fmt::Debug for WindowJob {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WindowJob").field("at", &self.at).field("worked", &self.worked).finish()
    }
}

/// The refiner's window graph with its recurrences in chunks of [`SPREAD_CHUNK`] frames
/// (`crate::ops::chunk`), run node by node so that a stream spreads a window over the pushes
/// before its result is needed: the plan, its nodes in evaluation order and the share of a
/// window's time spent up to the end of each node (measured when the plan is made, on this
/// machine; it only decides how many nodes a push runs, never what they compute).
#[derive(Debug)]
pub(crate) struct SpreadPlan {
    plan: Plan,
    order: Vec<usize>,
    done_after: Vec<f64>,
    /// A window's measured time, node by node.
    window_time: std::time::Duration,
}

impl SpreadPlan {
    /// A job for the window `x` (`window * dim` normalised values), set as its graph's input,
    /// ready to run node by node: on `done`'s state and tensors (a finished window's) when its
    /// nodes keep nothing between runs but their outputs, else on a fresh state (tract's
    /// recurrences keep their state across turns).
    fn start(&self, x: &[f32], window: usize, dim: usize, done: Option<WindowJob>) -> Result<WindowJob, MotionError> {
        let run = |e: TractError| MotionError::Run { reason: chain(&e) };
        let mut job = match done.filter(|j| crate::ops::kept::keeps_only_outputs(&j.state)) {
            Some(mut j) => {
                j.state.reset_turn().map_err(run)?;
                j.at = 0;
                j.worked = 0;
                j
            }
            None => WindowJob {
                state: self.plan.spawn().map_err(run)?,
                at: 0,
                worked: 0,
                input: Arc::new(Tensor::zero::<f32>(&[window, 1, dim]).map_err(run)?),
                scratch: Vec::new(),
            },
        };
        {
            // Exclusive again once the last window's values were cleared; else this copies once.
            let input = Arc::make_mut(&mut job.input);
            let mut view = input.try_as_plain_ram_mut().map_err(run)?;
            let v = view.as_slice_mut::<f32>().map_err(run)?;
            if v.len() != x.len() {
                return Err(MotionError::Run { reason: format!("a window of {} values for {}", x.len(), v.len()) });
            }
            v.copy_from_slice(x);
        }
        let input = TValue::from_const(job.input.clone());
        crate::ops::kept::set_inputs(&mut job.state, std::iter::once(input)).map_err(run)?;
        Ok(job)
    }

    /// A finished job of a window of zeros, for a stream to start its first window on.
    fn warm(&self, window: usize, dim: usize) -> Result<WindowJob, MotionError> {
        let mut job = self.start(&vec![0.0; window * dim], window, dim, None)?;
        while job.at < self.order.len() {
            self.step(&mut job).map_err(|e| MotionError::Run { reason: chain(&e) })?;
        }
        Ok(job)
    }

    /// Runs the job's next node.
    fn step(&self, job: &mut WindowJob) -> TractResult<()> {
        crate::ops::kept::compute(&mut job.state, self.order[job.at], &mut job.scratch)?;
        job.at += 1;
        Ok(())
    }

    /// The chunked plan of `proto` for windows of `window` frames of `dim` values, or `None`
    /// when the graph has no recurrence to chunk or the chunked graph does not plan.
    fn new(proto: &tract_onnx::pb::ModelProto, window: usize, dim: usize) -> Option<SpreadPlan> {
        let mut chunked = crate::ops::chunk::chunk_recurrences(proto, window, SPREAD_CHUNK)?;
        // The products as zoo nodes, those over the whole window in chunks of frames too.
        if let Some(mut fused) = crate::ops::enabled().then(|| crate::ops::fuse(&chunked)).flatten() {
            crate::ops::chunk::chunk_dense(&mut fused, SPREAD_CHUNK);
            chunked = fused;
        }
        let model = crate::model::read_proto(&chunked, "the chunked window graph").ok()?;
        let plan = plan_for(&model, window, dim).ok()?;
        let order = plan.order_without_consts().to_vec();
        let input = || Tensor::zero::<f32>(&[window, 1, dim]).map(|t| tvec![t.into_tvalue()]);
        // Four runs node by node (a fresh state each, as every window gets: the recurrences'
        // ops keep their state across turns), the fastest of the last three for each node.
        let mut best = vec![f64::INFINITY; order.len()];
        for run in 0..4 {
            let mut state = plan.spawn().ok()?;
            state.set_inputs(input().ok()?).ok()?;
            for (i, &node) in order.iter().enumerate() {
                let t = std::time::Instant::now();
                state.compute_one(node).ok()?;
                if run > 0 {
                    best[i] = best[i].min(t.elapsed().as_secs_f64());
                }
            }
        }
        let total: f64 = best.iter().sum();
        let mut done = 0.0;
        let done_after = best
            .iter()
            .map(|t| {
                done += t;
                done / total
            })
            .collect();
        let window_time = std::time::Duration::from_secs_f64(total);
        Some(SpreadPlan { plan, order, done_after, window_time })
    }
}

/// An exported RMR, planned for one window size, ready to refine sequences. `Send + Sync`: one
/// loaded refiner serves every thread.
#[derive(Clone, Debug)]
pub struct StitchRefiner {
    metadata: Arc<MotionModelMetadata>,
    model: InferenceModel,
    plan: Plan,
    /// The decoded file, for the chunked plan of streams ([`SpreadPlan`]), made on first use.
    proto: Arc<tract_onnx::pb::ModelProto>,
    spread: Arc<std::sync::OnceLock<Option<Arc<SpreadPlan>>>>,
    window: usize,
    stride: usize,
    blend_frames: usize,
    dim: usize,
    pose: usize,
    joints: usize,
    fps: f64,
    mean: Vec<f32>,
    std: Vec<f32>,
    skeleton: Skeleton,
    layout: StitchLayout,
    pre_blend: bool,
    fallback: Option<StitchFallback>,
    seam_guard: bool,
    seam_reach: SeamReach,
}

/// The longest seams' reach a refiner or a stream takes, frames (2 minutes at 30 fps: a stream
/// holds about twice its reach of frames).
pub const MAX_SEAM_REACH: usize = 3600;

/// Refuses a seams' reach of 0 frames or more than [`MAX_SEAM_REACH`].
fn check_reach(frames: Option<usize>) -> Result<(), MotionError> {
    match frames {
        Some(0) => Err(stitch_err("a seam reach of 0 frames: give at least 1, or None to refine the whole sequence")),
        Some(n) if n > MAX_SEAM_REACH => Err(stitch_err(format!(
            "a seam reach of {n} frames, more than {MAX_SEAM_REACH}: give the frames around a seam that the stitch may \
             change (the window by default), or None to refine the whole sequence"
        ))),
        _ => Ok(()),
    }
}

/// The seams' reach a refiner applies ([`StitchRefiner::seam_reach`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SeamReach {
    /// The window's ([`zoo_protocol::stitch::reach::default_reach`]), following
    /// [`StitchRefiner::set_window`]: the default.
    Window,
    Frames(usize),
    /// None: the whole sequence is refined.
    Everywhere,
}

fn stitch_err(reason: impl Into<String>) -> MotionError {
    MotionError::Stitch { reason: reason.into() }
}

fn plan_for(model: &InferenceModel, window: usize, dim: usize) -> Result<Plan, MotionError> {
    let mut m = model.clone();
    let planned = (|| -> TractResult<Plan> {
        m.set_input_fact(0, f32::fact([window, 1, dim]).into())?;
        crate::model::planned(m)
    })();
    planned.map_err(|e| MotionError::Unsupported { reason: chain(&e) })
}

/// What follows the refiner in [`StitchRefiner::refine_poses`] (RMR secs. 5 and 6). `zoo stitch`
/// does both by default, and so does [`FootCleanup::default`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FootCleanup {
    /// Put the ankles where the refiner predicts them (its lower-body positions) by two-bone IK.
    pub place_ankles: bool,
    /// Lock the feet by the predicted contacts (two-bone IK towards each contact's pin).
    pub lock_feet: bool,
}

impl Default for FootCleanup {
    fn default() -> Self {
        FootCleanup { place_ankles: true, lock_feet: true }
    }
}

impl FootCleanup {
    /// The refiner's output as it is.
    pub const NONE: FootCleanup = FootCleanup { place_ankles: false, lock_feet: false };
}

/// A stitched sequence ([`StitchRefiner::refine_clip`]) and what each step did.
#[derive(Clone, Debug)]
pub struct StitchedClip {
    /// The stitched motion, on the model's skeleton.
    pub clip: Clip,
    /// Predicted contacts per frame (heel L, toe L, heel R, toe R).
    pub contacts: Vec<[bool; 4]>,
    /// The ankles' global positions the refiner predicts (left, right) per frame: its raw
    /// lower-body positions placed in its accumulated ground roots (empty when the layout's
    /// heel joints are not lower body).
    pub ankles: Vec<[DVec3; 2]>,
    /// Mean move of the ankles by the IK (clip units), when it ran.
    pub ankle_move: Option<f64>,
    /// Mean ankle correction of the foot lock (clip units), when it ran.
    pub lock_move: Option<f64>,
    /// What the seam guard did at each seam, when it ran.
    pub guarded: Option<Vec<zoo_protocol::stitch::guard::GuardedSeam>>,
    /// The fallback's weight on each window (empty without a fallback).
    pub fallback_weights: Vec<f32>,
    /// Frames set back to the input beyond the seams' reach, when a reach was set
    /// ([`StitchRefiner::seam_reach`]).
    pub untouched: Option<usize>,
}

impl StitchRefiner {
    /// Loads an exported RMR (`.onnx`), planned for its section's window; a file of another
    /// task is refused ([`MotionError::WrongTask`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        crate::LoadedModel::load(path)?.into_stitch()
    }

    /// [`StitchRefiner::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        crate::LoadedModel::from_bytes(bytes)?.into_stitch()
    }

    /// Loads the window graph of a `stitch` file whose metadata was read and checked.
    pub(crate) fn from_parts(bytes: &[u8], origin: &str, metadata: MotionModelMetadata) -> Result<Self, MotionError> {
        let Some(task) = metadata.task.as_stitch() else {
            return Err(MotionError::wrong_task(&metadata, "stitch", "StitchRefiner"));
        };
        let (proto, model) = crate::model::read_graph(bytes, origin)?;
        let skeleton = metadata.skeleton.to_skeleton();
        let joints = skeleton.len();
        let dim = task.dim(joints);
        // The format crate checked the group's width and values.
        let stats = metadata.group("x", dim)?;
        let (mean, std) = (stats.mean.clone(), stats.std.clone());
        let (window, stride, blend_frames, layout) = (task.window, task.stride, task.blend_frames, task.layout.clone());
        let (pre_blend, fallback) = (task.pre_blend, task.fallback);
        let fps = metadata.fps as f64;
        let plan = plan_for(&model, window, dim)?;
        Ok(StitchRefiner {
            metadata: Arc::new(metadata),
            model,
            plan,
            proto: Arc::new(proto),
            spread: Arc::default(),
            window,
            stride,
            blend_frames,
            dim,
            pose: dim - 4,
            joints,
            fps,
            mean,
            std,
            skeleton,
            layout,
            pre_blend,
            fallback,
            seam_guard: true,
            seam_reach: SeamReach::Window,
        })
    }

    /// The file's metadata (its `stitch` section, skeleton, frame and statistics).
    pub fn metadata(&self) -> &MotionModelMetadata {
        &self.metadata
    }

    /// Plans the refiner for another window `w` and stride `s` (`1 <= s <= w`; the paper uses
    /// 60/30 and 180/90).
    pub fn set_window(&mut self, window: usize, stride: usize) -> Result<(), MotionError> {
        if window == 0 || stride == 0 || stride > window {
            return Err(stitch_err(format!(
                "a window of {window} frames with a stride of {stride}: the stride must be in 1..=window"
            )));
        }
        self.plan = plan_for(&self.model, window, self.dim)?;
        self.spread = Arc::default();
        self.window = window;
        self.stride = stride;
        Ok(())
    }

    /// Window `w`, frames.
    pub fn window(&self) -> usize {
        self.window
    }

    /// Stride `s` between windows, frames.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Frames over which each window's first-frame difference is blended away.
    pub fn blend_frames(&self) -> usize {
        self.blend_frames
    }

    /// Values per pose vector (`7 + 6 J_lower + 4 J`).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Joints of the model's skeleton.
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Frames per second of the training clips (sequences must have it).
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// The model's skeleton: poses must have its joints, in its order, and the bone lengths of
    /// its offsets.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Which joints are the lower body and the feet, and the contact thresholds.
    pub fn layout(&self) -> &StitchLayout {
        &self.layout
    }

    /// Whether the model was trained on sequences inertialized at their seams (`zoo train rmr
    /// --pre-blend`; the file's `stitch.pre_blend`): give it the seams
    /// ([`StitchRefiner::refine_poses_at_seams`], [`StitchStream::mark_seam`]) as `zoo stitch`
    /// does.
    pub fn pre_blend(&self) -> bool {
        self.pre_blend
    }

    /// The fallback towards the refiner's input that every window gets (the file's calibrated
    /// `stitch.fallback`, as `zoo stitch` applies it; `None`: the network alone).
    pub fn fallback(&self) -> Option<StitchFallback> {
        self.fallback
    }

    /// Sets the fallback of [`StitchRefiner::fallback`]: `None` for the network alone (`zoo
    /// bench stitch --no-fallback`), or thresholds of your own (checked: finite, `0 <= start <=
    /// full`).
    pub fn set_fallback(&mut self, fallback: Option<StitchFallback>) -> Result<(), MotionError> {
        if let Some(f) = &fallback {
            f.check().map_err(stitch_err)?;
        }
        self.fallback = fallback;
        Ok(())
    }

    /// Whether [`StitchRefiner::refine_poses_at_seams`] guards the seams (on unless switched
    /// off): where the refined motion, after the ankle IK, moves a joint faster within 5 frames
    /// of a seam than the inertialized input does there, it is blended towards itself smoothed
    /// until it does not, before the foot lock ([`zoo_protocol::stitch::guard`], what `zoo stitch`
    /// does unless given `--no-seam-guard`).
    pub fn seam_guard(&self) -> bool {
        self.seam_guard
    }

    /// Switches the seam guard of [`StitchRefiner::seam_guard`] on or off.
    pub fn set_seam_guard(&mut self, on: bool) {
        self.seam_guard = on;
    }

    /// The seams' reach of [`StitchRefiner::refine_clip`], [`StitchRefiner::refine_poses_at_seams`]
    /// and the streams made afterwards, when set: every frame this many frames or more from the
    /// nearest seam is the input's exactly, the output is eased back to the input from half of
    /// it on, and each stretch near seams starts on the input's ground root
    /// ([`zoo_protocol::stitch::reach`], after the foot lock). Default: the window (as `zoo
    /// stitch`; it follows [`StitchRefiner::set_window`]). `None`: the whole sequence is refined
    /// (`zoo stitch --refine-everywhere`). Without seams nothing is kept.
    pub fn seam_reach(&self) -> Option<usize> {
        match self.seam_reach {
            SeamReach::Window => Some(zoo_protocol::stitch::reach::default_reach(self.window)),
            SeamReach::Frames(n) => Some(n),
            SeamReach::Everywhere => None,
        }
    }

    /// Sets [`StitchRefiner::seam_reach`] (`None` refines everywhere; 0 frames and more than
    /// [`MAX_SEAM_REACH`] are refused).
    pub fn set_seam_reach(&mut self, frames: Option<usize>) -> Result<(), MotionError> {
        check_reach(frames)?;
        self.seam_reach = frames.map_or(SeamReach::Everywhere, SeamReach::Frames);
        Ok(())
    }

    /// Sets whether the seams given to [`StitchRefiner::refine_clip`] and
    /// [`StitchRefiner::refine_poses_at_seams`] are inertialized before the refiner sees them
    /// (default: the file's [`StitchRefiner::pre_blend`], the input its model was trained on;
    /// `zoo stitch --pre-blend` turns it on for a model trained without it).
    pub fn set_pre_blend(&mut self, on: bool) {
        self.pre_blend = on;
    }

    /// Sets the frames over which each window's first-frame difference is blended away, which
    /// are also the frames of the seams' inertialization (the pre-blend and the seam guard's
    /// reference; default: the file's; `zoo stitch --blend-frames`).
    pub fn set_blend_frames(&mut self, frames: usize) -> Result<(), MotionError> {
        if frames == 0 {
            return Err(stitch_err("a blend of 0 frames: blend over at least 1 frame"));
        }
        self.blend_frames = frames;
        Ok(())
    }

    /// Window starts over `frames` frames: every stride while the window fits, plus one ending
    /// on the last frame when the stride does not land there.
    pub fn window_starts(&self, frames: usize) -> Vec<usize> {
        if self.window > frames {
            return Vec::new();
        }
        let mut starts: Vec<usize> = (0..=frames - self.window).step_by(self.stride).collect();
        if starts.last() != Some(&(frames - self.window)) {
            starts.push(frames - self.window);
        }
        starts
    }

    /// Refines one normalised window (`window * dim` values) into `out` (same size; contacts as
    /// logits).
    pub fn refine_window_normalized(&self, x: &[f32], out: &mut [f32]) -> Result<(), MotionError> {
        let n = self.window * self.dim;
        for (name, len) in [("window", x.len()), ("refined window", out.len())] {
            if len != n {
                return Err(MotionError::BufferLength {
                    name: name.into(),
                    expected: n,
                    batch: self.window,
                    width: self.dim,
                    found: len,
                });
            }
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(MotionError::NonFinite { name: "window".into(), index: i, character: 0, value: x[i] });
        }
        let input = Tensor::from_shape::<f32>(&[self.window, 1, self.dim], x)
            .map_err(|e| MotionError::Run { reason: chain(&e) })?;
        let result = self.plan.run(tvec![input.into()]).map_err(|e| MotionError::Run { reason: chain(&e) })?;
        let y = result[0]
            .try_as_plain_ram()
            .and_then(|t| t.as_slice::<f32>())
            .map_err(|e| MotionError::Run { reason: chain(&e) })?;
        if y.len() != n {
            return Err(MotionError::Run {
                reason: format!("the graph returned {} values for a window of {n}", y.len()),
            });
        }
        out.copy_from_slice(y);
        Ok(())
    }

    /// The chunked plan of this window size, made on first use (`None`: the graph has no
    /// recurrence to chunk, and streams run each window in one push).
    fn spread_plan(&self) -> Option<Arc<SpreadPlan>> {
        // `ZOO_STREAM_SPREAD=0` runs each window whole (for comparisons).
        if std::env::var("ZOO_STREAM_SPREAD").is_ok_and(|v| v == "0") {
            return None;
        }
        self.spread.get_or_init(|| SpreadPlan::new(&self.proto, self.window, self.dim).map(Arc::new)).clone()
    }

    /// [`StitchRefiner::refine_window_normalized`] through the chunked graph a stream spreads
    /// over its pushes, node by node (for tests: the two give the same values); `None` when
    /// the graph has nothing to chunk.
    #[doc(hidden)]
    pub fn refine_window_chunked(&self, x: &[f32], out: &mut [f32]) -> Option<Result<(), MotionError>> {
        let spread = self.spread_plan()?;
        let run = |e: TractError| MotionError::Run { reason: chain(&e) };
        Some((|| {
            let mut job = spread.start(x, self.window, self.dim, None)?;
            while job.at < spread.order.len() {
                spread.step(&mut job).map_err(run)?;
            }
            let y = job.state.output(0).map_err(run)?;
            let y = y.try_as_plain_ram().and_then(|t| t.as_slice::<f32>()).map_err(run)?;
            out.copy_from_slice(y);
            Ok(())
        })())
    }

    /// Refines a whole aligned sequence of raw pose vectors (`frames * dim`, `frames >= w`)
    /// into `out` (same size): raw pose vectors, contacts 0/1. Windows every `s` frames plus
    /// one ending on the last frame; each window's input holds the frames already refined;
    /// each window gets the fallback ([`StitchRefiner::fallback`]), and the difference at each
    /// window's first frame is blended away over [`StitchRefiner::blend_frames`] frames.
    pub fn refine_sequence(&self, features: &[f32], out: &mut [f32]) -> Result<(), MotionError> {
        self.refine_sequence_weights(features, out).map(|_| ())
    }

    /// [`StitchRefiner::refine_sequence`], returning the fallback's weight on each window (0:
    /// the refined window kept; empty without a fallback).
    pub fn refine_sequence_weights(&self, features: &[f32], out: &mut [f32]) -> Result<Vec<f32>, MotionError> {
        let d = self.dim;
        if features.is_empty() || !features.len().is_multiple_of(d) || out.len() != features.len() {
            return Err(MotionError::BufferLength {
                name: "sequence".into(),
                expected: features.len().div_ceil(d).max(1) * d,
                batch: features.len() / d,
                width: d,
                found: if out.len() != features.len() { out.len() } else { features.len() },
            });
        }
        let frames = features.len() / d;
        if self.window > frames {
            return Err(stitch_err(format!(
                "the window of {} frames is longer than the sequence ({frames} frames): plan a window of at most \
                 {frames} with StitchRefiner::set_window, or stitch longer clips",
                self.window
            )));
        }
        if let Some(i) = features.iter().position(|v| !v.is_finite()) {
            return Err(MotionError::NonFinite { name: "sequence".into(), index: i, character: 0, value: features[i] });
        }
        out.copy_from_slice(features);
        for f in out.chunks_exact_mut(d) {
            self.normalize_frame(f);
        }
        let mut y = vec![0.0f32; self.window * d];
        let mut offset = vec![0.0f32; self.pose];
        let mut weights = Vec::new();
        for ws in self.window_starts(frames) {
            let w =
                self.refine_window_in_place(&mut out[ws * d..(ws + self.window) * d], ws == 0, &mut y, &mut offset)?;
            if self.fallback.is_some() {
                weights.push(w);
            }
        }
        for f in out.chunks_exact_mut(d) {
            self.denormalize_frame(f);
        }
        Ok(weights)
    }

    fn normalize_frame(&self, f: &mut [f32]) {
        for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
            *v = (*v - m) / s;
        }
    }

    /// Raw values and contacts 0/1 of a refined normalised frame.
    fn denormalize_frame(&self, f: &mut [f32]) {
        for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
            *v = *v * s + m;
        }
        for c in &mut f[self.pose..] {
            *c = if *c > 0.5 { 1.0 } else { 0.0 };
        }
    }

    /// Refines one window of normalised frames in place (RMR sec. 6): the model over the
    /// window (whose first frames hold the previous window's output) and the fallback towards
    /// that input ([`StitchRefiner::fallback`]), then, unless it is the
    /// sequence's first window, the difference between the previous output at the window's
    /// first frame and the new one blended away over `blend_frames` frames; contacts to 0/1.
    /// `y` (`w * dim`) and `offset` (`dim - 4`) are scratch. Returns the fallback's weight.
    fn refine_window_in_place(
        &self,
        frames: &mut [f32],
        first: bool,
        y: &mut [f32],
        offset: &mut [f32],
    ) -> Result<f32, MotionError> {
        self.refine_window_normalized(frames, y)?;
        Ok(self.finish_window(frames, first, y, offset))
    }

    /// The rest of [`StitchRefiner::refine_window_in_place`] once the network's output `y` of
    /// the window `frames` is at hand: the fallback, the blend at the window's first frame, the
    /// contacts to 0/1, written into `frames`. Returns the fallback's weight.
    fn finish_window(&self, frames: &mut [f32], first: bool, y: &mut [f32], offset: &mut [f32]) -> f32 {
        let (d, pose) = (self.dim, self.pose);
        let weight = match &self.fallback {
            Some(f) => f.apply(frames, y, d, pose),
            None => 0.0,
        };
        if !first {
            // frames[0] is the previous output at the window's first frame (RMR sec. 6).
            for (i, o) in offset.iter_mut().enumerate() {
                *o = frames[i] - y[i];
            }
            for k in 0..self.blend_frames.min(self.window) {
                let w = 1.0 - k as f32 / self.blend_frames as f32;
                for (v, o) in y[k * d..k * d + pose].iter_mut().zip(offset.iter()) {
                    *v += w * o;
                }
            }
        }
        for f in y.chunks_exact_mut(d) {
            for c in &mut f[pose..] {
                *c = if *c > 0.0 { 1.0 } else { 0.0 }; // sigmoid(logit) > 0.5
            }
        }
        frames.copy_from_slice(y);
        weight
    }

    /// Checks that pose `index` fits the model (its joint count, finite values).
    fn check_pose(&self, pose: &EnginePose, index: usize) -> Result<(), MotionError> {
        if pose.joints() != self.joints {
            return Err(stitch_err(format!(
                "pose {index} has {} joint rotations but the model's skeleton has {} joints; retarget the motion to the \
                 model's rig (StitchRefiner::skeleton) or export a model trained on this rig",
                pose.joints(),
                self.joints
            )));
        }
        let values = pose.root_position.to_array().into_iter().chain(pose.root_rotation.to_array()).chain(
            pose.hips_position.to_array().into_iter().chain(pose.local_rotations.iter().flat_map(|q| q.to_array())),
        );
        for (i, value) in values.enumerate() {
            if !value.is_finite() {
                return Err(MotionError::NonFinite { name: format!("pose {index}"), index: i, character: 0, value });
            }
        }
        Ok(())
    }

    /// The model-space rotations of `pose` (joint 0: the hips' world rotation) into `out`, and
    /// the hips' world position.
    fn model_space(pose: &EnginePose, out: &mut Vec<DQuat>) -> DVec3 {
        out.clear();
        out.push(pose.hips_world_rotation().as_dquat());
        out.extend(pose.local_rotations[1..].iter().map(|q| q.normalize().as_dquat()));
        pose.hips_world().as_dvec3()
    }

    /// Encodes a whole sequence of poses (at least 2, at the model's frame rate, on its
    /// skeleton) into raw pose vectors (`frames * dim`, the input of
    /// [`StitchRefiner::refine_sequence`]).
    pub fn encode_poses(&self, poses: &[EnginePose], out: &mut [f32]) -> Result<(), MotionError> {
        self.encode_poses_at_seams(poses, &[], out)
    }

    /// [`StitchRefiner::encode_poses`] with the sequence inertialized at `seams` first (the
    /// frames where a clip starts, `zoo stitch --pre-blend`): from each seam on, the jump to the
    /// previous clip decays over [`StitchRefiner::blend_frames`] frames
    /// ([`zoo_motion::blend::inertialize_seams`], what the offline tools run). Seams out of
    /// `2..frames - 1` change nothing.
    pub fn encode_poses_at_seams(
        &self,
        poses: &[EnginePose],
        seams: &[usize],
        out: &mut [f32],
    ) -> Result<(), MotionError> {
        let d = self.dim;
        let mut clip = self.poses_to_clip(poses)?;
        if out.len() != poses.len() * d {
            return Err(MotionError::BufferLength {
                name: "pose vectors".into(),
                expected: poses.len() * d,
                batch: poses.len(),
                width: d,
                found: out.len(),
            });
        }
        if let Some(&s) = seams.iter().find(|&&s| s >= poses.len()) {
            return Err(stitch_err(format!(
                "seam at frame {s} of a sequence of {} poses: give the frames where a clip starts, within the sequence",
                poses.len()
            )));
        }
        if !seams.is_empty() {
            clip = zoo_motion::blend::inertialize_seams(&clip, seams, self.blend_frames);
        }
        let x = zoo_protocol::stitch::encode_clip(&clip, &self.layout).map_err(|e| stitch_err(e.to_string()))?;
        out.copy_from_slice(&x);
        Ok(())
    }

    /// Refines a whole aligned sequence of poses (the clips already put end to start, at the
    /// model's frame rate, on its skeleton, at least `w` frames) into `out` (one pose per input
    /// pose, each of the model's joint count) and the predicted contacts per frame (heel L, toe
    /// L, heel R, toe R) into `contacts`: encoding, [`StitchRefiner::refine_sequence`],
    /// decoding from the input's first ground root, then `cleanup` (RMR secs. 5-6; what
    /// `zoo stitch` writes with [`FootCleanup::default`]). Root deltas are filled (zero on the
    /// first frame).
    pub fn refine_poses(
        &self,
        input: &[EnginePose],
        cleanup: FootCleanup,
        out: &mut [EnginePose],
        contacts: &mut [[bool; 4]],
    ) -> Result<(), MotionError> {
        self.refine_poses_at_seams(input, &[], cleanup, out, contacts)
    }

    /// [`StitchRefiner::refine_poses`] of a sequence whose clips start at `seams`: the seams
    /// inertialized before the refiner sees them (as the stream's `mark_seam` does; give seams to
    /// a model trained so, [`StitchRefiner::pre_blend`]), and guarded against pops after the
    /// ankle IK and before the foot lock ([`StitchRefiner::seam_guard`]): what `zoo stitch`
    /// writes for such a model ([`StitchRefiner::refine_clip`]).
    pub fn refine_poses_at_seams(
        &self,
        input: &[EnginePose],
        seams: &[usize],
        cleanup: FootCleanup,
        out: &mut [EnginePose],
        contacts: &mut [[bool; 4]],
    ) -> Result<(), MotionError> {
        self.refine_poses_reaching(input, seams, (cleanup, self.seam_reach()), out, contacts)
    }

    /// [`StitchRefiner::refine_poses_at_seams`] with another seams' reach for this call
    /// (`None`: refine everywhere), the refiner's own left as it is (for callers that share the
    /// refiner, such as the Python package).
    pub fn refine_poses_reaching(
        &self,
        input: &[EnginePose],
        seams: &[usize],
        (cleanup, reach): (FootCleanup, Option<usize>),
        out: &mut [EnginePose],
        contacts: &mut [[bool; 4]],
    ) -> Result<(), MotionError> {
        check_reach(reach)?;
        let frames = input.len();
        if out.len() != frames || contacts.len() != frames {
            return Err(stitch_err(format!(
                "{frames} input poses but {} output poses and {} contact slots: give one of each per input pose",
                out.len(),
                contacts.len()
            )));
        }
        if let Some(f) = out.iter().position(|p| p.joints() != self.joints) {
            return Err(stitch_err(format!(
                "output pose {f} has {} joints, the model {}: allocate the poses with EnginePose::new(refiner.joints())",
                out[f].joints(),
                self.joints
            )));
        }
        let clip = self.poses_to_clip(input)?;
        // The seams an engine gives are inertialized (the stream's `mark_seam` does the same).
        let stitched = self.refine_clip_with(&clip, seams, (cleanup, reach), true)?;
        contacts.copy_from_slice(&stitched.contacts);
        write_poses(&stitched.clip, out);
        Ok(())
    }

    /// The poses as a clip on the model's skeleton (joint 0: the hips' world rotation and
    /// position), checked.
    fn poses_to_clip(&self, poses: &[EnginePose]) -> Result<Clip, MotionError> {
        if poses.len() < 2 {
            return Err(stitch_err(format!(
                "{} pose(s): a sequence needs at least 2 frames (the root motion is a difference of frames)",
                poses.len()
            )));
        }
        let j = self.joints;
        let mut clip = Clip {
            skeleton: self.skeleton.clone(),
            frame_time: 1.0 / self.fps,
            local_rotations: Vec::with_capacity(poses.len() * j),
            local_positions: Vec::with_capacity(poses.len() * j),
        };
        let mut rotations = Vec::with_capacity(j);
        for (f, pose) in poses.iter().enumerate() {
            self.check_pose(pose, f)?;
            let hips = Self::model_space(pose, &mut rotations);
            clip.local_rotations.extend_from_slice(&rotations);
            clip.local_positions.push(hips);
            clip.local_positions.extend_from_slice(&self.skeleton.offsets[1..]);
        }
        Ok(clip)
    }

    /// Stitches `aligned`, a sequence of clips already put end to start on the model's skeleton
    /// at its frame rate (joint 0 holding the hips' world transform, at least `w` frames), whose
    /// clips start at `seams`: the seams inertialized first when [`StitchRefiner::pre_blend`],
    /// the refiner window by window ([`StitchRefiner::refine_sequence`], with its fallback),
    /// the output decoded from the input's first ground root, then `cleanup`'s ankle IK, the
    /// seam guard ([`StitchRefiner::seam_guard`], against the input inertialized at the seams)
    /// and `cleanup`'s foot lock, in that order (RMR secs. 5-6): what `zoo stitch` writes and
    /// `zoo bench stitch` measures. Without seams there is nothing to pre-blend or guard.
    pub fn refine_clip(
        &self,
        aligned: &Clip,
        seams: &[usize],
        cleanup: FootCleanup,
    ) -> Result<StitchedClip, MotionError> {
        self.refine_clip_with(aligned, seams, (cleanup, self.seam_reach()), self.pre_blend)
    }

    /// [`StitchRefiner::refine_clip`] with the seams' reach `reach`, the seams inertialized before
    /// the refiner when `pre_blend`.
    fn refine_clip_with(
        &self,
        aligned: &Clip,
        seams: &[usize],
        (cleanup, reach): (FootCleanup, Option<usize>),
        pre_blend: bool,
    ) -> Result<StitchedClip, MotionError> {
        if aligned.joints() != self.joints {
            return Err(stitch_err(format!(
                "the sequence has {} joints, the model's skeleton {}: retarget it to the model's rig",
                aligned.joints(),
                self.joints
            )));
        }
        if let Some(&s) = seams.iter().find(|&&s| s >= aligned.frames()) {
            return Err(stitch_err(format!(
                "seam at frame {s} of a sequence of {} frames: give the frames where a clip starts, within the sequence",
                aligned.frames()
            )));
        }
        let inertialized = (!seams.is_empty() && (pre_blend || self.seam_guard))
            .then(|| zoo_motion::blend::inertialize_seams(aligned, seams, self.blend_frames));
        let input = match (&inertialized, pre_blend) {
            (Some(blended), true) => blended,
            _ => aligned,
        };
        let x = zoo_protocol::stitch::encode_clip(input, &self.layout).map_err(|e| stitch_err(e.to_string()))?;
        let mut y = vec![0.0f32; x.len()];
        let fallback_weights = self.refine_sequence_weights(&x, &mut y)?;
        let start = zoo_protocol::stitch::ground_roots(input, &self.layout)[0];
        let ankles =
            zoo_protocol::stitch::predicted_ankles(&y, self.layout.pose_layout(self.joints), &self.layout, start);
        let (mut clip, contacts) =
            zoo_protocol::stitch::decode(&y, &self.skeleton, &self.layout, aligned.frame_time, start)
                .map_err(|e| stitch_err(e.to_string()))?;
        let ankle_move =
            cleanup.place_ankles.then(|| zoo_protocol::stitch::lock::place_ankles(&mut clip, &ankles, &self.layout));
        let guarded = match (&inertialized, self.seam_guard) {
            (Some(reference), true) => {
                Some(zoo_protocol::stitch::guard::guard_seams(&mut clip, reference, seams, &self.layout))
            }
            _ => None,
        };
        let lock_move =
            cleanup.lock_feet.then(|| zoo_protocol::stitch::lock::lock_feet(&mut clip, &contacts, &self.layout));
        let untouched = match reach {
            Some(reach) if !seams.is_empty() => {
                Some(zoo_protocol::stitch::reach::keep_untouched(&mut clip, input, seams, reach, &self.layout))
            }
            _ => None,
        };
        Ok(StitchedClip { clip, contacts, ankles, ankle_move, lock_move, guarded, fallback_weights, untouched })
    }

    /// A stream over this refiner for motion matching: push poses as they are decided, pop
    /// refined ones [`StitchStream::latency`] frames later (see [`StitchStream`]). Making one
    /// runs a window of zeros (about a window's time), so that no push makes the graph's tensors.
    pub fn stream(&self) -> StitchStream<'_> {
        StitchStreamOf::new(self, self.seam_reach())
    }

    /// [`StitchRefiner::stream`] over a shared refiner: the stream holds the `Arc` (no borrow),
    /// so it can live as long as the caller needs.
    pub fn shared_stream(self: Arc<Self>) -> StitchStreamOf<Arc<StitchRefiner>> {
        let reach = self.seam_reach();
        StitchStreamOf::new(self, reach)
    }
}

/// Writes the frames of `clip` (hips' world transform in joint 0) into engine poses, with root
/// deltas from frame to frame.
fn write_poses(clip: &Clip, out: &mut [EnginePose]) {
    let j = clip.joints();
    let mut rotations = vec![Quat::IDENTITY; j];
    for f in 0..clip.frames() {
        for (r, q) in rotations.iter_mut().zip(clip.rotations_at(f)) {
            *r = q.as_quat();
        }
        let (before, rest) = out.split_at_mut(f);
        let pose = &mut rest[0];
        pose.set_world(clip.root_position(f).as_vec3(), &rotations);
        (pose.root_delta_position, pose.root_delta_yaw) = match before.last() {
            Some(prev) => root_delta(prev.root_position, prev.root_rotation, pose.root_position, pose.root_rotation),
            None => (Vec3::ZERO, 0.0),
        };
    }
}

/// Frames of lookahead the stream's foot lock, seam guard and seams' reach take beyond the
/// refiner's window ([`StitchStream::latency`]): the lock of a frame reads the
/// [`zoo_protocol::stitch::lock::LOCK_REACH`] frames after it, each guarded with its neighbours,
/// and those must be past the guard of every seam that may blend them: a seam's guard reads
/// the 17 frames after it once they have the ankle IK, and its weight takes a few pushes to
/// compute. 72 frames is the least with which a stream of bandai2's stitching cases and one with
/// a seam every 10 frames kept their latency (`tests/parity_rmr.rs`); this is 8 more.
pub const STREAM_LOOKAHEAD: usize =
    zoo_protocol::stitch::lock::LOCK_REACH + zoo_protocol::stitch::guard::SMOOTH_RADIUS + 2 * ZONE;

/// Frames of already popped motion the stream's foot lock reads again: the lock of a frame
/// reads the [`zoo_protocol::stitch::lock::LOCK_REACH`] frames before it (guarded when they
/// became final).
pub const STREAM_HISTORY: usize = zoo_protocol::stitch::lock::LOCK_REACH;

/// Frames a stream puts the ankles of per push (a window decodes `s` frames every `s` pushes).
const IK_FRAMES: usize = 6;

/// Evaluations of a seam's guard weight a stream runs per push (a seam takes 11).
const WEIGH_EVALUATIONS: usize = 2;

/// Frames on each side of a seam the stream's guard weighs it from (all it reads and weighs).
const ZONE: usize = zoo_protocol::stitch::guard::GUARD_FRAMES + zoo_protocol::stitch::guard::GUARD_RAMP + 2;

/// Frames the stream's foot lock and seam guard release at once (they run once per this many
/// pushes; the latency grows by this less one).
pub const STREAM_CHUNK: usize = 10;

/// Stitching as a stream, for motion matching (RMR sec. 6 online): the engine pushes the aligned
/// motion one pose per frame as it decides it ([`StitchStream::push`]) and pops the refined
/// motion ([`StitchStream::pop`]) with a fixed latency of [`StitchStream::latency`] frames: the
/// refined pose of frame `t` is ready once frame `t + latency()` has been pushed.
///
/// Every `s` frames the stream runs one window over the last `w` frames, the windows of
/// [`StitchRefiner::refine_sequence`]; [`StitchStream::finish`] runs the last window, the one
/// ending on the last frame. So that no push does a whole window's work (a frame budget), a
/// window runs through the refiner's graph with its recurrences in chunks of a few frames
/// (the same function: equal for small models, within 1e-6 normalised units for the paper's),
/// a share of it per push over the `s - 1` pushes after it is due. Frame `t` is refined for
/// good once frame `t + w + s - 1` is pushed (no later window, the last one included, reaches
/// back to it; a marked seam's frame is encoded one push late). A graph without recurrences to
/// chunk runs each window whole in the push that completes it, and frame `t` is final at
/// `t + w + 1`.
///
/// What follows the refiner is what `zoo stitch` does by default: [`StitchStream::cleanup`]
/// (default: [`FootCleanup::default`]), the seam guard of the marked seams
/// ([`StitchRefiner::seam_guard`], on by default) and the seams' reach
/// ([`StitchStream::seam_reach`], the refiner's: the window by default). The ankle IK is per
/// frame, run once per frame; the guard weighs each seam once, when the frames it reads are
/// refined; the blend of the guarded frames and the foot lock run over the refined frames at
/// hand, [`STREAM_HISTORY`] frames already popped included, and release [`STREAM_CHUNK`] frames
/// at a time (at most one chunk per push), at least [`STREAM_LOOKAHEAD`] frames from the newest
/// one; the reach keeps each released frame as `zoo stitch` does. The latency is then
/// `w + s - 1 + STREAM_LOOKAHEAD + STREAM_CHUNK - 1` frames (178 for `w` = 60, `s` = 30: 5.9 s at 30 fps);
/// with [`FootCleanup::NONE`], the guard and the reach off it is `w + s - 1`. Every frame's lock
/// reads the frames within [`zoo_protocol::stitch::lock::LOCK_REACH`] of it, all at hand, so the
/// stream gives the whole sequence's poses ([`StitchRefiner::refine_poses_at_seams`]) up to the
/// chunked graph's rounding (on bandai2's stitching cases within 7.4e-3 cm of `zoo stitch`,
/// docs/rmr.md). A stream with a reach passes the frames away from every marked seam through as
/// they were pushed (every frame, while no seam is marked).
/// Each pose comes with the predicted contacts (heel L, toe L, heel R, toe R).
///
/// After its first pop (and its first marked seam), pushing and popping allocate nothing on our
/// side as long as the engine pops every frame it can: the buffers, and the scratch of the
/// guard and the lock ([`zoo_protocol::stitch::lock::LockScratch`],
/// [`zoo_protocol::stitch::guard::GuardScratch`]), are sized when the stream is made. What tract
/// allocates per window is counted by `examples/rmr_window_latency` (docs/rmr.md).
///
/// The stream borrows its refiner ([`StitchRefiner::stream`]) or shares it through an `Arc`
/// ([`StitchRefiner::shared_stream`], for a stream that must own what it runs, such as a handle
/// held by a C caller): [`StitchStreamOf`] is the same stream over either.
pub type StitchStream<'a> = StitchStreamOf<&'a StitchRefiner>;

/// A [`StitchStream`] over any shared handle `R` of its refiner (a reference or an `Arc`).
#[derive(Debug)]
pub struct StitchStreamOf<R> {
    refiner: R,
    /// Normalised pose vectors of frames `base..encoded` (refined where a window covered them).
    buf: Vec<f32>,
    base: usize,
    /// Frames encoded so far (frame 0 is encoded when frame 1 arrives).
    encoded: usize,
    /// Poses pushed so far.
    pushed: usize,
    /// Frames final after the seam blend (all pushed ones but a seam frame waiting for the next).
    finals: usize,
    /// The seam blend (`mark_seam`), and whether the next pushed pose starts a clip.
    blend: SeamInertializer,
    seam_next: bool,
    /// Start of the next regular window (the one in `job` while it runs).
    next_window: usize,
    /// The chunked window graph this stream spreads each window over (`None`: each window runs
    /// whole in the push that completes it), and the window it is running.
    spread: Option<Arc<SpreadPlan>>,
    job: Option<WindowJob>,
    /// The last window's finished job, whose state and tensors the next window reuses.
    done: Option<WindowJob>,
    /// Whether a push runs its window ahead of schedule while it has time (off with
    /// `ZOO_STREAM_AHEAD=0`: the schedule alone, the same nodes in the same pushes on every run,
    /// for comparisons).
    ahead: bool,
    /// Frames refined for good and decoded so far.
    refined: usize,
    /// Frames whose rotations in `dec_rot` have the ankle IK (`FootCleanup::place_ankles`).
    ik_done: usize,
    /// The seam guard's weight of each decoded frame (`dec_base..refined`), and the first frame
    /// from which seams are still to be weighed.
    guard_w: Vec<f64>,
    guard_next: usize,
    /// The seam being weighed a few evaluations per push (its first frame in the sequence is the
    /// zone clips' frame 0), the zone of output and reference it reads and the weights there.
    weighing: Option<(zoo_protocol::stitch::guard::SeamWeighing, usize)>,
    zone_out: Clip,
    zone_ref: Clip,
    zone_w: Vec<f64>,
    weigh_scratch: zoo_protocol::stitch::guard::GuardScratch,
    /// Frames popped so far.
    read: usize,
    finished: bool,
    prev: PoseFrame,
    cur: PoseFrame,
    continuity: Option<Vec<DQuat>>,
    rotations: Vec<DQuat>,
    x: Vec<f32>,
    y: Vec<f32>,
    offset: Vec<f32>,
    /// Ground root of the last decoded frame (the first: the input's).
    root: GroundRoot,
    start_root: GroundRoot,
    last_out: Option<(Vec3, Quat)>,
    cleanup: FootCleanup,
    guard: bool,
    /// The seams' reach ([`StitchRefiner::seam_reach`]) and the stretch of the frames released
    /// last.
    reach: Option<usize>,
    keep: zoo_protocol::stitch::reach::KeepUntouched,
    /// Frames the marked seams start on.
    seams: Vec<usize>,
    /// Decoded frames `dec_base..refined`: model-space rotations, hips, contacts, predicted
    /// ankles; the input inertialized at the seams (the guard's reference), `dec_base..finals`.
    dec_base: usize,
    dec_rot: Vec<DQuat>,
    dec_hips: Vec<DVec3>,
    dec_contacts: Vec<[bool; 4]>,
    dec_ankles: Vec<[DVec3; 2]>,
    ref_rot: Vec<DQuat>,
    ref_hips: Vec<DVec3>,
    /// Slots of the heel joints in the lower body, when both are in it.
    ankle_slots: Option<(usize, usize)>,
    /// Refined poses ready to pop, frames `out_base..released`.
    out_base: usize,
    released: usize,
    out_rot: Vec<Quat>,
    out_hips: Vec<Vec3>,
    out_contacts: Vec<[bool; 4]>,
    /// Decoded frames from `dec_base` on with the seam guard applied (each once, when its
    /// weight is final and the frame after it has the ankle IK), and their global rotations and
    /// positions (each frame's forward kinematics once), for the lock ([`StitchStream::guarded`]).
    gd_rot: Vec<DQuat>,
    gd_hips: Vec<DVec3>,
    gd_gr: Vec<DQuat>,
    gd_gp: Vec<DVec3>,
    /// Scratch of one frame's guard (the frame and its neighbours) and forward kinematics.
    tri: Clip,
    tri_w: Vec<f64>,
    fk_pos: Vec<DVec3>,
    /// Scratch of the lock: the frames it runs over.
    work: Clip,
    lock_scratch: zoo_protocol::stitch::lock::LockScratch,
    guard_scratch: zoo_protocol::stitch::guard::GuardScratch,
}

impl<R: Deref<Target = StitchRefiner> + Clone> StitchStreamOf<R> {
    /// A stream over `refiner` with the seams' reach `reach`, its buffers sized for it.
    fn new(refiner: R, reach: Option<usize>) -> Self {
        let (w, d, j) = (refiner.window, refiner.dim, refiner.joints);
        let blend = SeamInertializer::new(j, refiner.blend_frames, 1.0 / refiner.fps);
        let slot = |joint: usize| refiner.layout.lower_body.iter().position(|&k| k == joint);
        let ankle_slots = slot(refiner.layout.contacts[0]).zip(slot(refiner.layout.contacts[2]));
        let frames = 2 * (w + STREAM_HISTORY + STREAM_LOOKAHEAD.max(reach.unwrap_or(0)) + STREAM_CHUNK) + 4;
        let clip = || Clip {
            skeleton: refiner.skeleton.clone(),
            frame_time: 1.0 / refiner.fps,
            local_rotations: Vec::with_capacity(frames * j),
            local_positions: Vec::with_capacity(frames * j),
        };
        let work = clip();
        let guard = refiner.seam_guard;
        let mut lock_scratch = zoo_protocol::stitch::lock::LockScratch::default();
        lock_scratch.reserve(frames, j);
        let mut guard_scratch = zoo_protocol::stitch::guard::GuardScratch::default();
        guard_scratch.reserve(3, j);
        let spread = refiner.spread_plan();
        // The stream's graph state, its nodes' tensors made now by a window of zeros: the first
        // window a push runs then costs what every other one does (it made them, 1.8-3x a
        // median call for 64 streams). `None` if that run fails: the first window makes them.
        let done = spread.as_ref().and_then(|spread| spread.warm(w, d).ok());
        StitchStreamOf {
            // At most w frames waiting to be dropped, w + 1 still needed.
            buf: Vec::with_capacity((2 * w + 2) * d),
            base: 0,
            encoded: 0,
            pushed: 0,
            finals: 0,
            blend,
            seam_next: false,
            next_window: 0,
            spread,
            job: None,
            done,
            ahead: std::env::var("ZOO_STREAM_AHEAD").map_or(true, |v| v != "0"),
            refined: 0,
            ik_done: 0,
            guard_w: Vec::with_capacity(frames),
            guard_next: 0,
            weighing: None,
            zone_out: clip(),
            zone_ref: clip(),
            zone_w: Vec::with_capacity(4 * ZONE),
            weigh_scratch: {
                let mut g = zoo_protocol::stitch::guard::GuardScratch::default();
                g.reserve(4 * ZONE, j);
                g
            },
            read: 0,
            finished: false,
            prev: PoseFrame::default(),
            cur: PoseFrame::default(),
            continuity: None,
            rotations: Vec::with_capacity(j),
            x: vec![0.0; d],
            y: vec![0.0; w * d],
            offset: vec![0.0; d - 4],
            root: GroundRoot::IDENTITY,
            start_root: GroundRoot::IDENTITY,
            last_out: None,
            cleanup: FootCleanup::default(),
            guard,
            reach,
            keep: Default::default(),
            seams: Vec::with_capacity(64),
            dec_base: 0,
            dec_rot: Vec::with_capacity(frames * j),
            dec_hips: Vec::with_capacity(frames),
            dec_contacts: Vec::with_capacity(frames),
            dec_ankles: Vec::with_capacity(frames),
            ref_rot: Vec::with_capacity(frames * j),
            ref_hips: Vec::with_capacity(frames),
            ankle_slots,
            out_base: 0,
            released: 0,
            out_rot: Vec::with_capacity(frames * j),
            out_hips: Vec::with_capacity(frames),
            out_contacts: Vec::with_capacity(frames),
            gd_rot: Vec::with_capacity(frames * j),
            gd_hips: Vec::with_capacity(frames),
            gd_gr: Vec::with_capacity(frames * j),
            gd_gp: Vec::with_capacity(frames * j),
            tri: clip(),
            tri_w: Vec::with_capacity(3),
            fk_pos: Vec::with_capacity(j),
            work,
            lock_scratch,
            guard_scratch,
            refiner,
        }
    }

    /// What follows the refiner: the ankle IK and the foot lock ([`FootCleanup`]; default
    /// [`FootCleanup::default`], as `zoo stitch`).
    pub fn cleanup(&self) -> FootCleanup {
        self.cleanup
    }

    /// Sets [`StitchStream::cleanup`]; only before the first push (it sets the latency).
    pub fn set_cleanup(&mut self, cleanup: FootCleanup) -> Result<(), MotionError> {
        if self.pushed > 0 {
            return Err(stitch_err(
                "the foot cleanup of a stream is set before its first push: set it on a new stream",
            ));
        }
        self.cleanup = cleanup;
        Ok(())
    }

    /// Whether the stream guards its marked seams (the refiner's [`StitchRefiner::seam_guard`]
    /// when the stream was made).
    pub fn seam_guard(&self) -> bool {
        self.guard
    }

    /// Switches the seam guard on or off; only before the first push (it sets the latency).
    pub fn set_seam_guard(&mut self, on: bool) -> Result<(), MotionError> {
        if self.pushed > 0 {
            return Err(stitch_err("the seam guard of a stream is set before its first push: set it on a new stream"));
        }
        self.guard = on;
        Ok(())
    }

    /// Whether a push runs its window's network work ahead of schedule while the push is
    /// within the window's measured time per push (default: on, unless the environment sets
    /// `ZOO_STREAM_AHEAD=0`). Off, each window runs on its schedule alone: the same nodes in the
    /// same pushes on every run, whatever the machine's load (for comparisons and tests).
    pub fn set_run_ahead(&mut self, on: bool) {
        self.ahead = on;
    }

    /// The seams' reach of the stream ([`StitchRefiner::seam_reach`] when it was made).
    pub fn seam_reach(&self) -> Option<usize> {
        self.reach
    }

    /// Sets [`StitchStream::seam_reach`] (`None`: refine everywhere); only before the first push
    /// (it may set the latency). A stream with a reach passes the frames `reach` or more from
    /// every marked seam through as they were pushed (all of them while no seam is marked).
    pub fn set_seam_reach(&mut self, frames: Option<usize>) -> Result<(), MotionError> {
        if self.pushed > 0 {
            return Err(stitch_err("the seam reach of a stream is set before its first push: set it on a new stream"));
        }
        check_reach(frames)?;
        // Made again with buffers for the reach (nothing was pushed).
        let (cleanup, guard, ahead) = (self.cleanup, self.guard, self.ahead);
        *self = Self::new(self.refiner.clone(), frames);
        (self.cleanup, self.guard, self.ahead) = (cleanup, guard, ahead);
        Ok(())
    }

    /// Frames the guard, the lock and the seams' reach look ahead ([`STREAM_LOOKAHEAD`], more
    /// for a reach longer than the window and the lookahead together); 1 for the ankle IK alone
    /// (a window's frames are decoded at the end of a push, their IK starts in the next); 0
    /// without any of them.
    fn lookahead(&self) -> usize {
        let own = self.refiner.window.max(2) + self.spread_pushes();
        let reach = self.reach.map_or(0, |r| r.saturating_sub(own));
        if self.releases_in_chunks() { STREAM_LOOKAHEAD.max(reach) } else { usize::from(self.cleanup.place_ankles) }
    }

    /// Whether the lock, the guard or the seams' reach run: frames are then released
    /// [`STREAM_CHUNK`] at a time.
    fn releases_in_chunks(&self) -> bool {
        self.cleanup.lock_feet || self.guard || self.reach.is_some()
    }

    /// Frames released at once (1 without the guard, the lock and the reach).
    fn chunk(&self) -> usize {
        if self.releases_in_chunks() { STREAM_CHUNK } else { 1 }
    }

    /// Frames between pushing frame `t` and popping its refined pose: the refined pose of frame
    /// `t` is ready right after frame `t + latency()` is pushed. `w + s - 1` for the refiner
    /// alone (`w + 1` for a graph without recurrences to chunk; the 1: a marked seam's frame is
    /// encoded one push late, [`StitchStream::mark_seam`]); `+ 1` with the ankle IK alone; `+`
    /// [`STREAM_LOOKAHEAD`] `+` [`STREAM_CHUNK`] `- 1` with the foot lock, the seam guard or the
    /// seams' reach (a longer lookahead for a reach longer than `w + s - 1 +`
    /// [`STREAM_LOOKAHEAD`]).
    pub fn latency(&self) -> usize {
        self.refiner.window.max(2) + self.spread_pushes() + self.lookahead() + self.chunk() - 1
    }

    /// Pushes a window's network work is spread over: `s - 1` (at least 1) with the chunked
    /// graph, so that a window is done one push before the next one can be due; 1 without.
    fn spread_pushes(&self) -> usize {
        if self.spread.is_some() { self.refiner.stride.saturating_sub(1).max(1) } else { 1 }
    }

    /// Poses pushed so far.
    pub fn pushed(&self) -> usize {
        self.pushed
    }

    /// Refined poses popped so far (the index of the next one).
    pub fn popped(&self) -> usize {
        self.read
    }

    /// Marks the next pushed pose as the first frame of a new clip: the stream inertializes the
    /// seam before refining ([`zoo_motion::blend::SeamInertializer`] over the model's
    /// [`StitchRefiner::blend_frames`]), as [`StitchRefiner::refine_poses_at_seams`] and `zoo
    /// stitch --pre-blend` do, and guards it ([`StitchStream::seam_guard`]). The seam frame is
    /// encoded once the frame after it is pushed, so the windows over it run one push later. A
    /// seam on frame 0 or 1 is not inertialized.
    pub fn mark_seam(&mut self) {
        self.seam_next = true;
    }

    /// Pushes the next frame of the aligned motion (at the model's frame rate, on its
    /// skeleton). Runs a window when one is due, and the guard and the lock when a chunk of
    /// frames is due.
    pub fn push(&mut self, pose: &EnginePose) -> Result<(), MotionError> {
        if self.finished {
            return Err(stitch_err("the stream is finished: start another with StitchRefiner::stream"));
        }
        let r = self.refiner.clone();
        r.check_pose(pose, self.pushed)?;
        let hips = StitchRefiner::model_space(pose, &mut self.rotations);
        let seam = std::mem::take(&mut self.seam_next);
        if seam {
            self.seams.push(self.pushed);
        }
        self.pushed += 1;
        let n = self.blend.push(&self.rotations, hips, seam);
        for i in 0..n {
            self.take_final(i);
        }
        // The cleanup first, then the window's share with what is left of this push's time (at
        // least its share of the schedule), then what that window made final.
        let start = std::time::Instant::now();
        self.decode_final();
        self.place_new_ankles(false);
        self.weigh_seams(false);
        self.guard_new_frames(false);
        self.release(false);
        self.compact();
        self.run_due_windows(false, self.ahead.then_some(start))?;
        self.decode_final();
        Ok(())
    }

    /// Decodes the frames refined for good: once the regular windows over them ran and the frame
    /// `w` after them is pushed (the last window, at finish, then starts after it).
    fn decode_final(&mut self) {
        let upto = self.next_window.min(self.pushed.saturating_sub(self.refiner.window)).min(self.encoded);
        self.decode_upto(upto);
    }

    /// Encodes final frame `i` of the seam blend's last release.
    fn take_final(&mut self, i: usize) {
        let r = self.refiner.clone();
        let (rotations, hips) = self.blend.released(i);
        self.ref_rot.extend_from_slice(rotations);
        self.ref_hips.push(hips);
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.cur.set(&r.skeleton, &r.layout, rotations, hips);
        self.finals += 1;
        if self.finals == 1 {
            self.start_root = self.cur.root;
            self.root = self.cur.root;
            return;
        }
        if self.finals == 2 {
            // Frame 0 takes frame 1's root motion and velocities.
            self.encode(true);
        }
        self.encode(false);
    }

    /// Runs the regular windows that the encoded frames cover: whole, or with the chunked
    /// graph a share of each per push (every remaining node with `all`, at the finish). A push
    /// that began at `push_start` runs its window's share of the schedule, and more nodes while
    /// the push is within the window's measured time per push (a window ahead of schedule lets
    /// a push busy with the cleanup run fewer); the last of its pushes finishes it.
    fn run_due_windows(&mut self, all: bool, push_start: Option<std::time::Instant>) -> Result<(), MotionError> {
        let (w, s) = (self.refiner.window, self.refiner.stride);
        let Some(spread) = self.spread.clone() else {
            while self.next_window + w <= self.encoded {
                let ws = self.next_window;
                self.run_window(ws)?;
                self.next_window += s;
            }
            return Ok(());
        };
        let run = |e: TractError| MotionError::Run { reason: chain(&e) };
        let pushes = self.spread_pushes();
        loop {
            if self.job.is_none() {
                if self.next_window + w > self.encoded {
                    return Ok(());
                }
                let from = (self.next_window - self.base) * self.refiner.dim;
                let x = &self.buf[from..from + w * self.refiner.dim];
                if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                    return Err(MotionError::NonFinite { name: "window".into(), index: i, character: 0, value: x[i] });
                }
                self.job = Some(spread.start(x, w, self.refiner.dim, self.done.take())?);
            }
            let job = self.job.as_mut().expect("a window runs");
            // The least this push runs: the window on a schedule that starts a quarter of its
            // pushes late (the first pushes of a window are the ones that lock and guard the frames
            // the last window made final) and is done by the end of its last push; a node counts
            // as run when most of it falls within that. More while the push's budget allows
            // (`SPREAD_SLACK`): the next node runs when its measured time fits in what is left.
            job.worked += 1;
            let late = pushes / 4;
            let floor = if all || job.worked >= pushes {
                f64::INFINITY
            } else {
                job.worked.saturating_sub(late) as f64 / (pushes - late) as f64
            };
            let deadline = push_start.map(|t| t + spread.window_time.mul_f64(SPREAD_SLACK / pushes as f64));
            while job.at < spread.order.len() {
                let before = if job.at == 0 { 0.0 } else { spread.done_after[job.at - 1] };
                let behind = 0.5 * (before + spread.done_after[job.at]) <= floor;
                let cost = spread.window_time.mul_f64(spread.done_after[job.at] - before);
                if !behind && deadline.is_none_or(|d| std::time::Instant::now() + cost > d) {
                    break;
                }
                spread.step(job).map_err(run)?;
            }
            if job.at < spread.order.len() {
                return Ok(());
            }
            let y = job.state.output(0).map_err(run)?;
            let y = y.try_as_plain_ram().and_then(|t| t.as_slice::<f32>()).map_err(run)?;
            if y.len() != self.y.len() {
                return Err(MotionError::Run {
                    reason: format!("the graph returned {} values for a window of {}", y.len(), self.y.len()),
                });
            }
            self.y.copy_from_slice(y);
            // Kept for the next window (its state's values are cleared when that starts).
            self.done = self.job.take();
            let (ws, d) = (self.next_window, self.refiner.dim);
            let from = (ws - self.base) * d;
            let r = self.refiner.clone();
            r.finish_window(&mut self.buf[from..from + w * d], ws == 0, &mut self.y, &mut self.offset);
            self.next_window += s;
        }
    }

    /// Appends the normalised pose vector of `prev` (frame 0, `first`) or `cur`.
    fn encode(&mut self, first: bool) {
        let r = self.refiner.clone();
        let d = r.dim;
        let at = self.buf.len();
        self.buf.resize(at + d, 0.0);
        let frame = if first { &self.prev } else { &self.cur };
        encode_pose(&r.layout, frame, &self.prev, &self.cur, &mut self.continuity, &mut self.buf[at..]);
        r.normalize_frame(&mut self.buf[at..]);
        self.encoded += 1;
    }

    fn run_window(&mut self, ws: usize) -> Result<(), MotionError> {
        let r = self.refiner.clone();
        let d = r.dim;
        let from = (ws - self.base) * d;
        r.refine_window_in_place(&mut self.buf[from..from + r.window * d], ws == 0, &mut self.y, &mut self.offset)
            .map(|_| ())
    }

    /// Decodes the frames refined for good up to `upto` (from the input's first ground root, as
    /// the whole-sequence form): rotations, hips, contacts and the ankles the refiner predicts.
    fn decode_upto(&mut self, upto: usize) {
        let r = self.refiner.clone();
        let (d, j) = (r.dim, r.joints);
        let fl = r.layout.pose_layout(j);
        self.rotations.resize(j, DQuat::IDENTITY);
        while self.refined < upto {
            let t = self.refined;
            let from = (t - self.base) * d;
            self.x.copy_from_slice(&self.buf[from..from + d]);
            r.denormalize_frame(&mut self.x);
            self.root = if t == 0 { self.start_root } else { next_root(&self.root, &self.x) };
            let (hips, contacts) = decode_pose(&r.layout, &self.x, &self.root, &mut self.rotations);
            self.dec_rot.extend_from_slice(&self.rotations);
            self.dec_hips.push(hips);
            self.dec_contacts.push(contacts);
            let at = |k: usize| {
                let v = &self.x[fl.positions() + 3 * k..][..3];
                self.root.to_world(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
            };
            let ankles = self.ankle_slots.map(|(a, b)| [at(a), at(b)]).unwrap_or_default();
            self.dec_ankles.push(ankles);
            self.guard_w.push(0.0);
            self.refined += 1;
        }
    }

    /// Puts the ankles of decoded frames where the refiner predicts them ([`FootCleanup`]'s
    /// `place_ankles`), [`IK_FRAMES`] frames per push (all with `all`): each frame's IK reads that
    /// frame alone, and its rotations are kept in `dec_rot`.
    fn place_new_ankles(&mut self, all: bool) {
        if !self.cleanup.place_ankles || self.ik_done >= self.refined {
            self.ik_done = self.ik_done.max(self.dec_base);
            return;
        }
        let r = self.refiner.clone();
        let j = r.joints;
        let from = self.ik_done.max(self.dec_base);
        let to = if all { self.refined } else { self.refined.min(from + IK_FRAMES) };
        let (i0, i1) = (from - self.dec_base, to - self.dec_base);
        // `work` is refilled by every release: a scratch clip here.
        fill_clip(&mut self.work, &self.dec_rot[i0 * j..i1 * j], &self.dec_hips[i0..i1], &r.skeleton);
        let ankles = if self.ankle_slots.is_some() { &self.dec_ankles[i0..i1] } else { &[][..] };
        zoo_protocol::stitch::lock::place_ankles_into(&mut self.work, ankles, &r.layout, &mut self.lock_scratch);
        self.dec_rot[i0 * j..i1 * j].copy_from_slice(&self.work.local_rotations);
        self.ik_done = to;
    }

    /// The first frame the guard of a seam not weighed yet may blend (none without the guard).
    fn unweighed_from(&self) -> usize {
        use zoo_protocol::stitch::guard::{GUARD_FRAMES, GUARD_RAMP};
        if !self.guard {
            return usize::MAX;
        }
        let next = match &self.weighing {
            Some((w, z0)) => Some(z0 + w.seam()),
            None => self.seams.iter().copied().find(|&s| s >= self.guard_next),
        };
        next.map_or(usize::MAX, |s| s.saturating_sub(GUARD_FRAMES + GUARD_RAMP + 1))
    }

    /// Weighs the marked seams for the guard, [`WEIGH_EVALUATIONS`] evaluations per push (all of
    /// them with `all`, at the finish), one seam at a time in order, each from a clip of the
    /// frames it reads and weighs once those have the ankle IK: the whole sequence's weights.
    fn weigh_seams(&mut self, all: bool) {
        use zoo_protocol::stitch::guard::SeamWeighing;
        if !self.guard {
            return;
        }
        let r = self.refiner.clone();
        let j = r.joints;
        let mut budget = if all { usize::MAX } else { WEIGH_EVALUATIONS };
        while budget > 0 {
            if self.weighing.is_none() {
                // The next seam, once the frames within its reach have the ankle IK.
                let ready = if self.cleanup.place_ankles { self.ik_done } else { self.refined };
                let Some(s) = self.seams.iter().copied().find(|&s| s >= self.guard_next) else { return };
                if !all && s + ZONE > ready {
                    return;
                }
                let (z0, z1) = (s.saturating_sub(ZONE).max(self.dec_base), (s + ZONE).min(ready));
                let (i0, i1) = (z0 - self.dec_base, z1 - self.dec_base);
                let placed = &self.dec_rot[i0 * j..i1 * j];
                fill_clip(&mut self.zone_out, placed, &self.dec_hips[i0..i1], &r.skeleton);
                fill_clip(&mut self.zone_ref, &self.ref_rot[i0 * j..i1 * j], &self.ref_hips[i0..i1], &r.skeleton);
                self.zone_w.clear();
                self.zone_w.extend_from_slice(&self.guard_w[i0..i1]);
                self.guard_next = s + 1;
                let started = SeamWeighing::start(
                    &self.zone_out,
                    &self.zone_ref,
                    s - z0,
                    &r.layout,
                    &mut self.weigh_scratch,
                    &self.zone_w,
                );
                budget -= 1;
                match started {
                    Some(w) => self.weighing = Some((w, z0)),
                    None => continue,
                }
            }
            let (w, z0) = self.weighing.as_mut().expect("a seam is being weighed");
            let done = w.run(budget, &self.zone_out, &r.layout, &mut self.weigh_scratch, &self.zone_w);
            if done.is_none() {
                return;
            }
            w.apply(&mut self.zone_w);
            let at = *z0 - self.dec_base;
            self.guard_w[at..at + self.zone_w.len()].copy_from_slice(&self.zone_w);
            self.weighing = None;
            if !all {
                return;
            }
        }
    }

    /// Guards the decoded frames whose guard is final (their seam weighed, the frame after them
    /// with the ankle IK; all of them with `all`, at the finish) and computes their forward
    /// kinematics, each frame once: what the lock of the released frames reads.
    fn guard_new_frames(&mut self, all: bool) {
        if !self.releases_in_chunks() {
            return;
        }
        let r = self.refiner.clone();
        let j = r.joints;
        let b = if self.cleanup.place_ankles { self.refined.min(self.ik_done) } else { self.refined };
        let radius = zoo_protocol::stitch::guard::SMOOTH_RADIUS;
        let limit = if all { b } else { b.saturating_sub(radius).min(self.unweighed_from()) };
        for g in self.guarded()..limit {
            let i = g - self.dec_base;
            let w = if self.guard { self.guard_w[i] } else { 0.0 };
            if w > 0.0 {
                // The frame blended towards itself smoothed with its neighbours, as the guard of
                // the whole sequence blends it.
                let (t0, t1) = (g.saturating_sub(radius).max(self.dec_base), (g + radius + 1).min(b));
                let (k0, k1) = (t0 - self.dec_base, t1 - self.dec_base);
                fill_clip(&mut self.tri, &self.dec_rot[k0 * j..k1 * j], &self.dec_hips[k0..k1], &r.skeleton);
                self.tri_w.clear();
                self.tri_w.extend((t0..t1).map(|h| if h == g { w } else { 0.0 }));
                zoo_protocol::stitch::guard::apply_guard_weights(
                    &mut self.tri,
                    &self.tri_w,
                    &r.layout,
                    &mut self.guard_scratch,
                );
                let m = g - t0;
                self.gd_rot.extend_from_slice(&self.tri.local_rotations[m * j..(m + 1) * j]);
                self.gd_hips.push(self.tri.local_positions[m * j]);
            } else {
                self.gd_rot.extend_from_slice(&self.dec_rot[i * j..(i + 1) * j]);
                self.gd_hips.push(self.dec_hips[i]);
            }
            self.fk_pos.clear();
            self.fk_pos.push(self.gd_hips[i]);
            self.fk_pos.extend_from_slice(&r.skeleton.offsets[1..]);
            let n = i * j;
            self.gd_gr.resize(n + j, DQuat::IDENTITY);
            self.gd_gp.resize(n + j, DVec3::ZERO);
            zoo_motion::fk::forward_kinematics_frame(
                &r.skeleton.parents,
                &self.gd_rot[n..n + j],
                &self.fk_pos,
                &mut self.gd_gr[n..n + j],
                &mut self.gd_gp[n..n + j],
            );
        }
    }

    /// The frames guarded so far ([`StitchStream::guard_new_frames`]; without the guard, the
    /// lock and the reach none is, and this is `dec_base`).
    fn guarded(&self) -> usize {
        self.dec_base + self.gd_hips.len()
    }

    /// Moves decoded frames to the poses ready to pop: as they are (with the ankle IK) without
    /// the guard, the lock and the reach; with them, once [`StitchStream::chunk`] frames lie
    /// [`STREAM_LOOKAHEAD`] frames before the newest decoded one and the frames their lock reads
    /// are guarded (all of them at the finish): the guarded frames, locked with the
    /// [`zoo_protocol::stitch::lock::LOCK_REACH`] frames on each side, then kept by the reach.
    fn release(&mut self, at_finish: bool) {
        let (look, chunk) = (self.lookahead(), self.chunk());
        // The frames at hand: decoded, with the ankle IK when it runs.
        let b = if self.cleanup.place_ankles { self.refined.min(self.ik_done) } else { self.refined };
        let to = if at_finish { b } else { b.saturating_sub(look) };
        if to < self.released + chunk && !(at_finish && to > self.released) {
            return;
        }
        // One chunk per push (a window's decoded frames arrive at once): the same frames, the
        // work spread over the pushes after it; never a frame whose lock reads a frame not guarded
        // yet (`guard_new_frames`), nor one a seam not pushed yet may reach.
        let chunked = self.releases_in_chunks();
        let lock_reach = if self.cleanup.lock_feet { zoo_protocol::stitch::lock::LOCK_REACH } else { 0 };
        let to = if at_finish {
            to
        } else {
            let seams_known = self.reach.map_or(usize::MAX, |r| self.pushed.saturating_sub(r));
            let guarded = if chunked { self.guarded().saturating_sub(lock_reach) } else { usize::MAX };
            to.min(self.released + chunk).min(guarded).min(seams_known)
        };
        if to <= self.released {
            return;
        }
        let r = self.refiner.clone();
        let j = r.joints;
        if look == 0 && !self.cleanup.place_ankles {
            for f in self.released..to {
                let i = f - self.dec_base;
                self.out_rot.extend(self.dec_rot[i * j..(i + 1) * j].iter().map(|q| q.as_quat()));
                self.out_hips.push(self.dec_hips[i].as_vec3());
                self.out_contacts.push(self.dec_contacts[i]);
            }
            self.released = to;
            return;
        }
        // The frames the lock of the released ones reads: the guarded ones, with their forward
        // kinematics (the ankle IK alone: the decoded frames).
        let (a, e) = if chunked {
            (self.released.saturating_sub(lock_reach), b.min(to + lock_reach).min(self.guarded()))
        } else {
            (self.released, to)
        };
        let a = a.max(self.dec_base);
        let (i0, i1) = (a - self.dec_base, e - self.dec_base);
        let (rot, hips) = if chunked { (&self.gd_rot, &self.gd_hips) } else { (&self.dec_rot, &self.dec_hips) };
        fill_clip(&mut self.work, &rot[i0 * j..i1 * j], &hips[i0..i1], &r.skeleton);
        if self.cleanup.lock_feet {
            let (gr, gp) = self.lock_scratch.globals_mut();
            gr.extend_from_slice(&self.gd_gr[i0 * j..i1 * j]);
            gp.extend_from_slice(&self.gd_gp[i0 * j..i1 * j]);
            // Only the frames released now are kept: only their legs are bent.
            zoo_protocol::stitch::lock::lock_feet_given_globals(
                &mut self.work,
                &self.dec_contacts[i0..i1],
                &r.layout,
                zoo_protocol::stitch::lock::LOCK_MAX_STEP,
                &mut self.lock_scratch,
                self.released - a..to - a,
            );
        }
        for f in self.released..to {
            let i = f - a;
            if let Some(reach) = self.reach {
                // The seams' reach; no marked seam within reach: the frame as pushed.
                let w = match zoo_protocol::stitch::reach::seam_distance(f, &self.seams) {
                    Some(_) => zoo_protocol::stitch::reach::weight(f, &self.seams, reach),
                    None => 0.0,
                };
                let mut hips = self.work.local_positions[i * j];
                let d = f - self.dec_base;
                let input = (&self.ref_rot[d * j..(d + 1) * j], self.ref_hips[d]);
                let rotations = &mut self.work.local_rotations[i * j..(i + 1) * j];
                self.keep.frame((f, w), (rotations, &mut hips), input, &r.layout);
                self.work.local_positions[i * j] = hips;
            }
            let prev = self.out_rot.len().checked_sub(j);
            for k in 0..j {
                let mut q = self.work.local_rotations[i * j + k].as_quat();
                // Continuous with the frame before, as the whole sequence's.
                if prev.is_some_and(|p| self.out_rot[p + k].dot(q) < 0.0) {
                    q = -q;
                }
                self.out_rot.push(q);
            }
            self.out_hips.push(self.work.local_positions[i * j].as_vec3());
            self.out_contacts.push(self.dec_contacts[f - self.dec_base]);
        }
        self.released = to;
    }

    /// Drops the frames no later window, decoding, guard, lock or pop needs, once a window's
    /// worth of them has piled up (one move of at most `w` frames every `w` frames, not one per
    /// frame).
    fn compact(&mut self) {
        let (w, d, j) = (self.refiner.window, self.refiner.dim, self.refiner.joints);
        let keep = self.refined.min(self.pushed.saturating_sub(w)).min(self.next_window);
        if keep >= self.base + w {
            let n = (keep - self.base) * d;
            self.buf.copy_within(n.., 0);
            self.buf.truncate(self.buf.len() - n);
            self.base = keep;
        }
        let keep = self.released.saturating_sub(STREAM_HISTORY);
        if keep >= self.dec_base + w {
            let n = keep - self.dec_base;
            self.dec_rot.drain(..n * j);
            self.dec_hips.drain(..n);
            self.dec_contacts.drain(..n);
            self.dec_ankles.drain(..n);
            self.guard_w.drain(..n);
            self.ref_rot.drain(..n * j);
            self.ref_hips.drain(..n);
            // Empty without the guard, the lock and the reach.
            let g = n.min(self.gd_hips.len());
            self.gd_rot.drain(..g * j);
            self.gd_hips.drain(..g);
            self.gd_gr.drain(..g * j);
            self.gd_gp.drain(..g * j);
            self.dec_base = keep;
            // The seams a released frame may still be within reach of stay.
            let reach = self.reach.unwrap_or(0);
            let first = self.seams.partition_point(|&s| s < keep.min(self.released.saturating_sub(reach)));
            self.seams.drain(..first);
        }
        if self.read >= self.out_base + w {
            let n = self.read - self.out_base;
            self.out_rot.drain(..n * j);
            self.out_hips.drain(..n);
            self.out_contacts.drain(..n);
            self.out_base = self.read;
        }
    }

    /// Whether [`StitchStream::finish`] has run (pushing is then refused; the rest can be popped).
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Whether the next refined pose is ready.
    pub fn ready(&self) -> bool {
        self.read < self.released && (self.finished || self.read + self.latency() < self.pushed)
    }

    /// The next refined pose (frame [`StitchStream::popped`]) into `pose` (the model's joint
    /// count: `EnginePose::new(refiner.joints())`) with its predicted contacts, or `None` while
    /// it is not ready (fewer than `latency()` frames pushed after it, and not finished).
    pub fn pop(&mut self, pose: &mut EnginePose) -> Result<Option<[bool; 4]>, MotionError> {
        let j = self.refiner.joints;
        if pose.joints() != j {
            return Err(stitch_err(format!(
                "the output pose has {} joints, the model {j}: allocate it with EnginePose::new(refiner.joints())",
                pose.joints(),
            )));
        }
        if !self.ready() {
            return Ok(None);
        }
        let i = self.read - self.out_base;
        pose.set_world(self.out_hips[i], &self.out_rot[i * j..(i + 1) * j]);
        (pose.root_delta_position, pose.root_delta_yaw) = match self.last_out {
            Some((p, q)) => root_delta(p, q, pose.root_position, pose.root_rotation),
            None => (Vec3::ZERO, 0.0),
        };
        self.last_out = Some((pose.root_position, pose.root_rotation));
        let contacts = self.out_contacts[i];
        self.read += 1;
        self.compact();
        Ok(Some(contacts))
    }

    /// Ends the motion: runs the window ending on the last frame (unless a regular window
    /// ended there), then the guard and the lock over the rest, and makes every remaining frame
    /// ready. Needs at least `w` frames pushed.
    pub fn finish(&mut self) -> Result<(), MotionError> {
        if self.finished {
            return Ok(());
        }
        let (w, s) = (self.refiner.window, self.refiner.stride);
        if self.pushed < w.max(2) {
            return Err(stitch_err(format!(
                "the stream ends after {} frames, fewer than the window of {w}: push at least {w} frames, or plan a \
                 shorter window with StitchRefiner::set_window",
                self.pushed
            )));
        }
        // A seam on the last frame has no frame after it: it stays as it is.
        let n = self.blend.finish();
        for i in 0..n {
            self.take_final(i);
        }
        self.run_due_windows(true, None)?;
        let last = self.pushed - w;
        // The regular windows ran at 0, s, ..., next_window - s; the last of them ends on the
        // last frame exactly when next_window - s == last.
        if self.next_window == 0 || self.next_window - s != last {
            if last < self.base || last < self.refined {
                return Err(stitch_err(format!(
                    "frame {last} was dropped or decoded before finish (the buffer starts at frame {}, {} decoded); \
                     this is a bug, please report it",
                    self.base, self.refined
                )));
            }
            self.run_window(last)?;
        }
        self.decode_upto(self.encoded);
        self.place_new_ankles(true);
        self.weigh_seams(true);
        self.guard_new_frames(true);
        self.release(true);
        self.finished = true;
        Ok(())
    }
}

/// Refills `clip` (on `skeleton`) with the frames of model-space `rotations` and `hips`.
fn fill_clip(clip: &mut Clip, rotations: &[DQuat], hips: &[DVec3], skeleton: &Skeleton) {
    clip.local_rotations.clear();
    clip.local_rotations.extend_from_slice(rotations);
    clip.local_positions.clear();
    for &h in hips {
        clip.local_positions.push(h);
        clip.local_positions.extend_from_slice(&skeleton.offsets[1..]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<StitchRefiner>();
    }

    #[test]
    fn bytes_that_are_no_model_are_refused() {
        let err = StitchRefiner::from_bytes(b"not a model").unwrap_err().to_string();
        assert!(err.contains("is not an ONNX model"), "{err}");
    }
}
