//! Engine-facing RTN transitions: start from past poses and a target pose, then step one frame
//! at a time (global joint positions in and out), generate a whole target-blended transition
//! into a caller-owned buffer, or do either for N characters in one graph run.
//!
//! Feature encoding, offsets and the target blend come from `zoo_motion::features`, the code
//! the training uses. The step and start graphs are those of `zoo export --onnx` for an RTN
//! (`zoo.model_kind = "rtn"`, `zoo.task = "transition"`): frame inputs `x` and (with future
//! conditioning) `offset`, frame output `x_next`, start inputs `target` and/or `x0`. How to drive
//! them (context length, blend length, which inputs exist) comes from the typed task section
//! [`crate::metadata::TransitionTask`], never from the model's config.
//!
//! Poses are flat `f32` buffers of global joint positions, joint-major (`[x0, y0, z0, x1, ...]`,
//! `3K` values for `K` joints, the model's skeleton order); [`crate::pose`] converts glam
//! vectors. Batched calls take character-major buffers (character `c` at `c * 3K`).

use crate::error::MotionError;
use crate::metadata::{MotionMeanStd, MotionTask, keys};
use crate::model::{MotionModel, MotionState};
use crate::runner::{MotionRunner, check_finite, check_len};
use std::path::Path;
use zoo_motion::features;
use zoo_motion::footlock::FootLock;

/// What a frame input of the step graph is fed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameInput {
    X,
    Offset,
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
    /// For each start-graph input: `true` for the target vector, `false` for `x0`.
    start_target: Vec<bool>,
    target_blend: usize,
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
    started: bool,
    frames: usize,
}

impl TransitionState {
    /// Whether [`TransitionRunner::start`] was called for this state.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// Frames generated since the transition started.
    pub fn frames_generated(&self) -> usize {
        self.frames
    }

    /// The target pose of the transition (`3K` global positions).
    pub fn target(&self) -> &[f32] {
        &self.target
    }
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
    next: Vec<f32>,
    /// Generated poses of a batched `generate`, character-major.
    poses: Vec<f32>,
    /// Recurrent states swapped in from the characters for a batched run.
    motion: Vec<MotionState>,
    /// Foot-lock post-process of `generate`, off unless set.
    foot_lock: Option<FootLock>,
}

fn bad(key: &str, reason: String) -> MotionError {
    MotionError::BadMetadata { key: key.to_string(), reason }
}

fn wrong_len(name: &str, width: usize, batch: usize, found: usize) -> MotionError {
    MotionError::BufferLength { name: name.to_string(), expected: batch * width, batch, width, found }
}

/// Checks a character-major buffer of `batch` rows of `width` finite values.
fn check_rows(name: &str, data: &[f32], batch: usize, width: usize) -> Result<(), MotionError> {
    check_len(name, data.len(), batch, width)?;
    check_finite(name, data, width)
}

/// The model kinds that run the `transition` task with [`TransitionModel`].
pub const TRANSITION_KINDS: [&str; 1] = ["rtn"];

impl TransitionModel {
    /// Loads an RTN exported by `zoo export --onnx`; refuses a file of another task or kind
    /// (load any exported file with [`crate::LoadedModel::load`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        Self::new(MotionModel::load(path)?)
    }

    /// Wraps a loaded model; refuses models of another task or kind, and step graphs that do
    /// not match their `zoo.transition` section.
    pub fn new(model: MotionModel) -> Result<Self, MotionError> {
        let m = model.metadata();
        let MotionTask::Transition(task) = &m.task else {
            return Err(MotionError::WrongTask {
                task: m.task.name().to_string(),
                kind: m.model_kind.clone(),
                expected: "transition",
                loader: "TransitionModel",
            });
        };
        if !TRANSITION_KINDS.contains(&m.model_kind.as_str()) {
            return Err(MotionError::UnknownModelKind {
                kind: m.model_kind.clone(),
                task: m.task.name().to_string(),
                known: format!("transition models of kind {}", TRANSITION_KINDS.join(", ")),
            });
        }
        let joints = m.skeleton.parents.len();
        let d = 3 * joints;
        if task.frame_dim != d {
            return Err(bad(
                keys::TRANSITION,
                format!("frame_dim is {} but the skeleton has {joints} joints ({d} values)", task.frame_dim),
            ));
        }
        if task.terrain.is_some() {
            return Err(MotionError::BadGraphIo {
                what: "input",
                name: "terrain".into(),
                reason: "is not supported by TransitionModel (terrain-aware RTNs need the raw MotionRunner)".into(),
            });
        }
        let group = |name: &str| -> Result<MotionMeanStd, MotionError> {
            let g = m.normalization.get(name).ok_or_else(|| bad(keys::NORMALIZATION, format!("no group `{name}`")))?;
            if g.mean.len() != d || g.std.len() != d {
                return Err(bad(
                    keys::NORMALIZATION,
                    format!("group `{name}` has {} means and {} deviations, expected {d}", g.mean.len(), g.std.len()),
                ));
            }
            Ok(g.clone())
        };
        let frame_inputs = model
            .inputs()
            .iter()
            .map(|i| match i.name.as_str() {
                "x" if i.width == d => Ok(FrameInput::X),
                "offset" if i.width == d && task.offset_input => Ok(FrameInput::Offset),
                other => Err(MotionError::BadGraphIo {
                    what: "input",
                    name: other.to_string(),
                    reason: format!(
                        "is not an input of this transition model (`x`{} of {d} values, from `{}`)",
                        if task.offset_input { " and `offset`" } else { "" },
                        keys::TRANSITION
                    ),
                }),
            })
            .collect::<Result<Vec<_>, _>>()?;
        for (name, want) in [("x", FrameInput::X), ("offset", FrameInput::Offset)] {
            if (want == FrameInput::X || task.offset_input) && !frame_inputs.contains(&want) {
                return Err(MotionError::BadGraphIo {
                    what: "input",
                    name: name.into(),
                    reason: format!("a transition step graph takes `{name}` of {d} values (`{}`)", keys::TRANSITION),
                });
            }
        }
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
            x: group("x")?,
            velocity: group("velocity")?,
            offset: group("offset")?,
            frame_inputs,
            start_target,
            target_blend: task.target_blend,
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

    /// The foot-lock post-process for this model's skeleton (legs found by joint name, defaults
    /// for centimetres), `None` when the skeleton has no `foot` joints. Enable it on a runner
    /// with [`TransitionRunner::set_foot_lock`].
    pub fn default_foot_lock(&self) -> Option<FootLock> {
        let sk = &self.model.metadata().skeleton;
        let parents: Vec<Option<usize>> = sk.parents.iter().map(|&p| usize::try_from(p).ok()).collect();
        FootLock::from_skeleton(&sk.names, &parents)
    }

    /// A fresh transition state for one character.
    pub fn new_transition(&self) -> TransitionState {
        let d = 3 * self.joints;
        TransitionState {
            motion: self.model.new_state(),
            x: vec![0.0; d],
            root: [0.0; 3],
            target: vec![0.0; d],
            started: false,
            frames: 0,
        }
    }

    /// Scratch space for one thread.
    pub fn runner(&self) -> Result<TransitionRunner, MotionError> {
        Ok(TransitionRunner {
            model: self.clone(),
            runner: self.model.runner()?,
            feats: Vec::new(),
            target_vec: Vec::new(),
            x0: Vec::new(),
            xb: Vec::new(),
            offset: Vec::new(),
            next: Vec::new(),
            poses: Vec::new(),
            motion: Vec::new(),
            foot_lock: None,
        })
    }
}

impl TransitionRunner {
    /// The model this runner steps.
    pub fn model(&self) -> &TransitionModel {
        &self.model
    }

    /// Sets the foot-lock post-process that [`TransitionRunner::generate`] applies after the
    /// target blend (`None`: off, the default). See `zoo_motion::footlock`.
    pub fn set_foot_lock(&mut self, lock: Option<FootLock>) {
        self.foot_lock = lock;
    }

    /// Starts a transition: `past` holds the context frames (global positions, `frames * 3K`,
    /// at least one; the model was trained with [`TransitionModel::past_frames`] of them),
    /// `target` the target pose and `next` the pose after it (`3K` each, for the target
    /// velocity). The context is fed through the model as in training; the next
    /// [`TransitionRunner::step`] returns the first new frame.
    pub fn start(
        &mut self,
        state: &mut TransitionState,
        past: &[f32],
        target: &[f32],
        next: &[f32],
    ) -> Result<(), MotionError> {
        self.start_batch(std::slice::from_mut(state), past, target, next)
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
        let n = states.len();
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        let (k, d) = (self.model.joints, 3 * self.model.joints);
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
        let result = with_motion_states(&mut self.motion, states, &m.model, |runner_states| {
            self.runner.start_batch(runner_states, &inputs)
        });
        result?;
        for (c, s) in states.iter_mut().enumerate() {
            s.target.copy_from_slice(&target[c * d..(c + 1) * d]);
            s.x.copy_from_slice(&self.feats[c * per..c * per + d]);
            s.root = features::root_of(&past[c * per..]);
            s.started = true;
            s.frames = 0;
        }
        for f in 1..frames {
            self.advance(states)?;
            for (c, s) in states.iter_mut().enumerate() {
                let at = c * per + f * d;
                s.x.copy_from_slice(&self.feats[at..at + d]);
                s.root = features::root_of(&past[at..]);
            }
        }
        Ok(())
    }

    /// Runs the step graph on every state's `x` into `self.next` (character-major) and
    /// advances the recurrent states.
    fn advance(&mut self, states: &mut [TransitionState]) -> Result<(), MotionError> {
        let m = &self.model;
        let (n, d) = (states.len(), 3 * m.joints);
        self.xb.resize(n * d, 0.0);
        self.offset.resize(n * d, 0.0);
        self.next.resize(n * d, 0.0);
        for (c, s) in states.iter().enumerate() {
            let (xb, ob) = (&mut self.xb[c * d..(c + 1) * d], &mut self.offset[c * d..(c + 1) * d]);
            xb.copy_from_slice(&s.x);
            // o_t = ((y_T - y_t) - mu_o) / sigma_o, y_t decoded from the normalized x_t and its root.
            for i in 0..d {
                let f = s.x[i] * m.x.std[i] + m.x.mean[i];
                let y = if i < 3 { s.root[i] } else { f + s.root[i % 3] };
                ob[i] = s.target[i] - y;
            }
            m.offset.normalize(ob);
        }
        let (x, offset) = (&self.xb[..], &self.offset[..]);
        let mut inputs: [&[f32]; 2] = [&[], &[]];
        for (slot, which) in inputs.iter_mut().zip(&m.frame_inputs) {
            *slot = match which {
                FrameInput::X => x,
                FrameInput::Offset => offset,
            };
        }
        let inputs = &inputs[..m.frame_inputs.len()];
        let next = &mut self.next[..];
        let runner = &mut self.runner;
        with_motion_states(&mut self.motion, states, &m.model, |s| runner.step_batch(s, inputs, &mut [next]))
    }

    /// Generates the next frame of one character's transition into `pose` (`3K` global
    /// positions), without the target blend (it needs the predicted target frame: see
    /// [`TransitionRunner::generate`]).
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

    /// [`TransitionRunner::step`] for `states.len()` characters in one graph run: `poses`
    /// receives `N * 3K` values, character-major.
    pub fn step_batch(&mut self, states: &mut [TransitionState], poses: &mut [f32]) -> Result<(), MotionError> {
        let (n, d) = (states.len(), 3 * self.model.joints);
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        if poses.len() != n * d {
            return Err(wrong_len("poses", d, n, poses.len()));
        }
        if let Some(c) = states.iter().position(|s| !s.started) {
            return Err(MotionError::Run {
                reason: format!("character {c}: start the transition (TransitionRunner::start) before stepping it"),
            });
        }
        self.advance(states)?;
        let m = &self.model;
        for (c, (s, pose)) in states.iter_mut().zip(poses.chunks_exact_mut(d)).enumerate() {
            let next = &self.next[c * d..(c + 1) * d];
            s.x.copy_from_slice(next);
            pose.copy_from_slice(next);
            m.x.denormalize(pose);
            s.root = features::decode_frame_in_place(s.root, pose);
            s.frames += 1;
        }
        Ok(())
    }

    /// A whole transition of `frames` new frames into `out` (`(frames + 1) * 3K` values: the
    /// transition, then the target frame), target-blended (RTN eq. 15-16) so that the last
    /// frame equals `target` and the motion reaches it without a pop, then foot-locked when
    /// [`TransitionRunner::set_foot_lock`] enabled it.
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
        self.start_batch(states, past, target, next)?;
        let steps = per / d;
        // Step all characters frame by frame through a contiguous scratch row, then scatter.
        let mut poses = std::mem::take(&mut self.poses);
        poses.resize(n * d, 0.0);
        let mut result = Ok(());
        for f in 0..steps {
            result = self.step_batch(states, &mut poses);
            if result.is_err() {
                break;
            }
            for c in 0..n {
                out[c * per + f * d..c * per + (f + 1) * d].copy_from_slice(&poses[c * d..(c + 1) * d]);
            }
        }
        self.poses = poses;
        result?;
        let past_per = past.len() / n;
        for c in 0..n {
            let row = &mut out[c * per..(c + 1) * per];
            features::target_blend(row, &target[c * d..(c + 1) * d], self.model.target_blend);
            if let Some(lock) = &self.foot_lock {
                lock.apply(&past[(c + 1) * past_per - d..(c + 1) * past_per], row);
            }
        }
        Ok(())
    }
}

/// Runs `f` on the characters' recurrent states gathered into `scratch` (swapped, not copied),
/// and swaps them back whatever `f` returns.
fn with_motion_states<R>(
    scratch: &mut Vec<MotionState>,
    states: &mut [TransitionState],
    model: &MotionModel,
    f: impl FnOnce(&mut [MotionState]) -> R,
) -> R {
    let n = states.len();
    while scratch.len() < n {
        scratch.push(model.new_state());
    }
    for (s, t) in scratch.iter_mut().zip(states.iter_mut()) {
        std::mem::swap(s, &mut t.motion);
    }
    let r = f(&mut scratch[..n]);
    for (s, t) in scratch.iter_mut().zip(states.iter_mut()) {
        std::mem::swap(s, &mut t.motion);
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
