//! Keyframe completion in the engine: an exported keyframe model (model kind `arnn`) fills in
//! every frame between an animator's keys, into a buffer the caller owns. Two designs share the
//! task and this API; the file's `zoo.keyframes` section says which one it holds:
//!
//! - the ARNN's per-frame step graph (`zoo_arnn::export`): frame 0 of the output is the first
//!   key; every later frame `t` is one step of the graph from the previous output, the keys
//!   around `t` and `t_rel = (t - T_K) / (T_(K+1) - T_K)` (a frame on a key belongs to the
//!   interval that ends there), exactly as `zoo_arnn::complete` and `zoo complete` run it. A
//!   batch of characters runs in one graph call per frame; characters whose keys end earlier
//!   are stepped on (their outputs discarded) until the longest one ends;
//! - the in-betweening network's whole-shot graph (`zoo train arnn --design inbetween`,
//!   `zoo_arnn::inbetween_export`): the features of each character's keys are built by
//!   [`zoo_protocol::inbetween`] (the code training uses), the graph corrects the keys' Bezier
//!   curves over the whole shot in one call per character, and the completion is `bezier +
//!   residual * std`, the residual made from the correction zero on the keys as the file's
//!   `residual` says ([`zoo_protocol::inbetween::Residual`]), composed in f64 as
//!   `zoo_arnn::inbetween::complete_shots` does. Its poses are the humanoid pose vector (root
//!   position, then a `(w, x, y, z)` quaternion per joint, the clips' units).
//!
//! The keys of a character are frames (strictly increasing, the first one 0) and one pose per
//! key (`dofs` values each, the units of the export: metres and radians for the lamp).
//!
//! Every key is hit: after the network has run, each key frame is set to its key (in the
//! groups it fixes) and the network's miss is spread over the frames before it
//! ([`zoo_protocol::keyhit`], like RTN's target blend), so the motion stays continuous. A
//! humanoid's rotations are compared up to sign. [`KeyframeRunner::set_hit_keys`] turns this
//! off to read the network's own output (the in-betweening design meets its keys by
//! construction, to float rounding).
//!
//! A humanoid's completion then has its feet locked between the keys, as `zoo complete` does
//! ([`zoo_protocol::keylock`]: planted feet held, the legs refitted, the key frames unchanged;
//! the model's skeleton and bone offsets from its file, legs found by joint name).
//! [`KeyframeRunner::set_foot_lock`] turns this off.
//!
//! ```no_run
//! use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
//! let model = KeyframeModel::load("arnn.onnx")?;
//! let mut runner = model.runner(1)?;
//! let d = model.dofs();
//! let frames = [0, 12, 24];
//! let poses = vec![0.0f32; frames.len() * d];
//! let mut out = vec![0.0f32; (24 + 1) * d];
//! runner.complete(MotionKeys::whole(&frames, &poses), &mut out)?;
//! # Ok::<(), zoo_runtime::MotionError>(())
//! ```

mod shot;

use crate::error::MotionError;
use crate::metadata::MotionModelMetadata;
use crate::model::{MotionModel, MotionState};
use crate::runner::MotionRunner;
use glam::{DQuat, DVec3};
use shot::ShotGraph;
use std::path::Path;
use std::sync::Arc;
pub use zoo_protocol::inbetween::{Fallback, GapFallback};

/// One character's keys: `frames` strictly increasing from 0, `poses` `frames.len() * dofs`
/// values (key-major); for a model with key groups (a humanoid model, either design), optionally
/// which groups each key fixes.
#[derive(Clone, Copy, Debug)]
pub struct MotionKeys<'a> {
    /// Key frames, strictly increasing, the first 0.
    pub frames: &'a [usize],
    /// One pose per key, `dofs` values each (a free group's values are ignored).
    pub poses: &'a [f32],
    /// Partial keys: `frames.len() * groups` flags (key-major), 1 where the key fixes the group
    /// (a humanoid's group 0 is the root position, group `1 + j` joint `j`'s rotation), 0 where
    /// it leaves it free; the first key fixes every group. Empty: every key is a whole pose.
    pub fixed: &'a [f32],
}

impl<'a> MotionKeys<'a> {
    /// Keys that are whole poses.
    pub fn whole(frames: &'a [usize], poses: &'a [f32]) -> Self {
        MotionKeys { frames, poses, fixed: &[] }
    }
}

impl MotionKeys<'_> {
    /// Frames of the completed motion: the last key frame + 1.
    pub fn len(&self) -> usize {
        self.frames.last().map_or(0, |f| f + 1)
    }

    /// Whether there are no keys.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The keys around frame `t >= 1` and `t_rel` (`zoo_arnn::luxo::preprocess::KeyedSequence::interval`).
    pub(crate) fn interval(&self, t: usize) -> (usize, usize, f32) {
        let n = self.frames.len();
        let mut k = 0;
        while k + 2 < n && self.frames[k + 1] < t {
            k += 1;
        }
        let (a, b) = (self.frames[k], self.frames[k + 1]);
        (k, k + 1, ((t as f64 - a as f64) / (b - a).max(1) as f64) as f32)
    }

    fn check(&self, character: usize, dofs: usize, groups: usize) -> Result<(), MotionError> {
        let bad = |reason: String| Err(MotionError::Keys { character, reason });
        let n = self.frames.len();
        if n < 2 {
            return bad(format!("{n} key(s): completion needs at least 2"));
        }
        if self.frames[0] != 0 {
            return bad(format!("the first key is at frame {}: key frames start at 0 (subtract it)", self.frames[0]));
        }
        if let Some(i) = self.frames.windows(2).position(|w| w[0] >= w[1]) {
            return bad(format!(
                "key {} is at frame {} but key {i} is at frame {}: key frames must strictly increase",
                i + 1,
                self.frames[i + 1],
                self.frames[i]
            ));
        }
        if self.poses.len() != n * dofs {
            return bad(format!(
                "{} pose values for {n} keys of {dofs} values: expected {}",
                self.poses.len(),
                n * dofs
            ));
        }
        if let Some(i) = self.poses.iter().position(|v| !v.is_finite()) {
            return bad(format!("key {} value {} is {}, not a finite number", i / dofs, i % dofs, self.poses[i]));
        }
        if !self.fixed.is_empty() {
            if groups == 0 {
                return bad(
                    "partial keys given, but the model was trained on whole keys only: pass `fixed: &[]`".into()
                );
            }
            if self.fixed.len() != n * groups {
                return bad(format!(
                    "{} key flags for {n} keys of {groups} groups: expected {}",
                    self.fixed.len(),
                    n * groups
                ));
            }
            if let Some(i) = self.fixed.iter().position(|v| *v != 0.0 && *v != 1.0) {
                return bad(format!(
                    "key {} group {} flag is {}: flags are 0 (free) or 1 (fixed)",
                    i / groups,
                    i % groups,
                    self.fixed[i]
                ));
            }
            if self.fixed[..groups].contains(&0.0) {
                return bad("the first key is the start pose: it must fix every group".into());
            }
            if let Some(k) = (0..n).find(|k| !self.fixed[k * groups..(k + 1) * groups].contains(&1.0)) {
                return bad(format!("key {k} fixes no group: fix at least one, or drop the key"));
            }
        }
        Ok(())
    }
}

/// The graph of a keyframe model.
#[derive(Clone, Debug)]
enum KeyframeGraph {
    /// The ARNN's per-frame step graph.
    Step(MotionModel),
    /// The in-betweening design's whole-shot graph.
    Shot(Arc<ShotGraph>),
}

/// An exported keyframe model, checked: an ARNN step graph (inputs `prev`, `key_a`, `key_b`
/// (`dofs` each), `t_rel` (1), with key groups `fixed_a` and `fixed_b` (`groups` each); output
/// `pose` (`dofs`) besides the recurrent state), or the in-betweening design's whole-shot graph
/// (input `features` `[batch, frames, width]`, output `correction` `[batch, frames, dofs]`).
/// Cheap to clone, `Send + Sync`.
#[derive(Clone, Debug)]
pub struct KeyframeModel {
    graph: KeyframeGraph,
    dofs: usize,
    groups: usize,
    key_groups: Vec<usize>,
}

impl KeyframeModel {
    /// Loads an exported keyframe model (`zoo export --onnx RUN --out model.onnx` of a `zoo train
    /// arnn` run, either design); a file of another task is refused ([`MotionError::WrongTask`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        crate::LoadedModel::load(path)?.into_keyframes()
    }

    /// [`KeyframeModel::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        crate::LoadedModel::from_bytes(bytes)?.into_keyframes()
    }

    /// Loads the graph of a `keyframes` file whose metadata was read and checked, by its design.
    pub(crate) fn from_parts(bytes: &[u8], origin: &str, metadata: MotionModelMetadata) -> Result<Self, MotionError> {
        let Some(task) = metadata.task.as_keyframes() else {
            return Err(MotionError::wrong_task(&metadata, "keyframes", "KeyframeModel"));
        };
        if task.inbetween.is_none() {
            return Self::new(MotionModel::from_parts(bytes, origin, metadata)?);
        }
        let (dofs, groups, key_groups) = (task.dofs, task.groups, task.key_groups.clone());
        let graph = ShotGraph::load(bytes, origin, metadata)?;
        Ok(KeyframeModel { graph: KeyframeGraph::Shot(Arc::new(graph)), dofs, groups, key_groups })
    }

    /// Checks that `model` is a `keyframes` ARNN step graph matching its section (an
    /// in-betweening file is a whole-shot graph, which [`MotionModel`] does not load: load it
    /// with [`KeyframeModel::load`] or [`crate::LoadedModel::load`]).
    pub fn new(model: MotionModel) -> Result<Self, MotionError> {
        let m = model.metadata();
        let Some(task) = m.task.as_keyframes() else {
            return Err(MotionError::wrong_task(m, "keyframes", "KeyframeModel"));
        };
        let (dofs, groups, key_groups) = (task.dofs, task.groups, task.key_groups.clone());
        let names: Vec<&str> = model.inputs().iter().map(|i| i.name.as_str()).collect();
        let widths: Vec<usize> = model.inputs().iter().map(|i| i.width).collect();
        let outputs: Vec<(&str, usize)> = model.outputs().iter().map(|o| (o.name.as_str(), o.width)).collect();
        let (want_names, want_widths): (&[&str], Vec<usize>) = if groups == 0 {
            (&["prev", "key_a", "key_b", "t_rel"], vec![dofs, dofs, dofs, 1])
        } else {
            (&["prev", "key_a", "key_b", "t_rel", "fixed_a", "fixed_b"], vec![dofs, dofs, dofs, 1, groups, groups])
        };
        if task.inbetween.is_some() || names != want_names || widths != want_widths || outputs != [("pose", dofs)] {
            return Err(MotionError::BadGraphIo {
                what: "input",
                name: names.first().unwrap_or(&"").to_string(),
                reason: format!(
                    "the keyframes step graph takes {names:?} of widths {widths:?} and gives {outputs:?}; its section \
                     (dofs {dofs}, groups {groups}) needs {want_names:?} of widths {want_widths:?} and one output \
                     `pose` ({dofs}) besides the recurrent state: re-export the model"
                ),
            });
        }
        Ok(KeyframeModel { graph: KeyframeGraph::Step(model), dofs, groups, key_groups })
    }

    /// Values per pose (6 for the lamp; `3 + 4 J` for a humanoid).
    pub fn dofs(&self) -> usize {
        self.dofs
    }

    /// Key groups a partial key can fix or leave free (0: keys are whole poses).
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// The file's metadata (its `keyframes` section, skeleton, frame, fps and statistics).
    pub fn metadata(&self) -> &MotionModelMetadata {
        match &self.graph {
            KeyframeGraph::Step(m) => m.metadata(),
            KeyframeGraph::Shot(s) => &s.metadata,
        }
    }

    /// Whether the file holds the in-betweening design's whole-shot graph (else the ARNN's
    /// step graph).
    pub fn is_inbetween(&self) -> bool {
        matches!(self.graph, KeyframeGraph::Shot(_))
    }

    /// The ARNN's step graph (`None` for the in-betweening design, which has none).
    pub fn step_model(&self) -> Option<&MotionModel> {
        match &self.graph {
            KeyframeGraph::Step(m) => Some(m),
            KeyframeGraph::Shot(_) => None,
        }
    }

    /// The in-betweening design's calibrated fallback towards the curves, as the file carries it
    /// (`inbetween.fallback`), which every runner starts with; `None` without one.
    pub fn default_fallback(&self) -> Option<&Fallback> {
        self.metadata().task.as_keyframes().and_then(|t| t.inbetween.as_ref()).and_then(|s| s.fallback.as_ref())
    }

    /// A runner for up to `max_batch` characters per call (the step graph's buffers sized once
    /// here).
    pub fn runner(&self, max_batch: usize) -> Result<KeyframeRunner, MotionError> {
        if max_batch == 0 {
            return Err(MotionError::EmptyBatch);
        }
        let d = self.dofs;
        let graph = match &self.graph {
            KeyframeGraph::Step(model) => RunnerGraph::Step(Box::new(StepBuffers {
                runner: model.runner()?,
                states: (0..max_batch).map(|_| model.new_state()).collect(),
                prev: vec![0.0; max_batch * d],
                key_a: vec![0.0; max_batch * d],
                key_b: vec![0.0; max_batch * d],
                t_rel: vec![0.0; max_batch],
                fixed_a: vec![1.0; max_batch * self.groups],
                fixed_b: vec![1.0; max_batch * self.groups],
                pose: vec![0.0; max_batch * d],
            })),
            KeyframeGraph::Shot(shot) => RunnerGraph::Shot(shot.clone()),
        };
        Ok(KeyframeRunner {
            fallback: self.default_fallback().cloned(),
            fallback_weights: Vec::with_capacity(max_batch),
            fallback_kept: Vec::with_capacity(max_batch),
            graph,
            max_batch,
            scratch: vec![0.0; d],
            dofs: d,
            groups: self.groups,
            key_groups: self.key_groups.clone(),
            hit_keys: true,
            feet: if self.groups > 0 { KeyFeet::new(&self.metadata().skeleton, d) } else { None },
            foot_lock: true,
        })
    }
}

/// The foot lock between the keys of a humanoid completion ([`zoo_protocol::keylock`], as `zoo
/// complete` applies it): the model's skeleton, its legs, and buffers.
#[derive(Clone, Debug)]
struct KeyFeet {
    lock: zoo_protocol::footlock::FootLock,
    skeleton: zoo_motion::Skeleton,
    root: Vec<DVec3>,
    rot: Vec<DQuat>,
    before: Vec<DQuat>,
}

impl KeyFeet {
    /// The lock of a skeleton with legs whose humanoid poses have `dofs` values; `None` otherwise.
    fn new(info: &crate::metadata::MotionSkeletonInfo, dofs: usize) -> Option<Self> {
        let j = info.names.len();
        if j == 0 || info.parents.len() != j || info.offsets.len() != j || dofs != zoo_protocol::inbetween::dofs(j) {
            return None;
        }
        let skeleton = zoo_motion::Skeleton {
            names: info.names.clone(),
            parents: info.parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
            offsets: info.offsets.iter().map(|o| DVec3::from_array(*o)).collect(),
            end_sites: vec![None; j],
            channels: vec![zoo_motion::JointChannels::default(); j],
        };
        let lock = zoo_protocol::keylock::key_foot_lock(&skeleton)?;
        Some(KeyFeet { lock, skeleton, root: vec![], rot: vec![], before: vec![] })
    }

    /// Locks the feet of one completion (`keys.len() * dofs` humanoid pose values) between its
    /// key frames, scaled by the share of the correction the fallback `kept` per frame (empty:
    /// none); writes back the rotations the lock changed (with the sign of the old ones).
    fn apply(&mut self, frames: &[usize], kept: &[f64], out: &mut [f32]) {
        let j = self.skeleton.len();
        let d = zoo_protocol::inbetween::dofs(j);
        self.root.clear();
        self.rot.clear();
        for p in out.chunks_exact(d) {
            self.root.push(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            self.rot.extend(p[3..].chunks_exact(4).map(|q| {
                let q = DQuat::from_xyzw(q[1] as f64, q[2] as f64, q[3] as f64, q[0] as f64);
                if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY }
            }));
        }
        self.before.clone_from(&self.rot);
        let s = &self.skeleton;
        zoo_protocol::keylock::lock_feet_between_keys(
            &self.lock,
            s,
            &s.offsets,
            frames,
            kept,
            &self.root,
            &mut self.rot,
        );
        for (i, (new, old)) in self.rot.iter().zip(&self.before).enumerate() {
            if new != old {
                let q = if new.dot(*old) < 0.0 { -*new } else { *new };
                let at = (i / j) * d + 3 + 4 * (i % j);
                out[at..at + 4].copy_from_slice(&[q.w as f32, q.x as f32, q.y as f32, q.z as f32]);
            }
        }
    }
}

/// What a runner runs: the step graph with its per-character buffers, or the whole-shot graph.
#[derive(Debug)]
enum RunnerGraph {
    Step(Box<StepBuffers>),
    Shot(Arc<ShotGraph>),
}

/// The step graph's runner and its buffers for `max_batch` characters.
#[derive(Debug)]
struct StepBuffers {
    runner: MotionRunner,
    states: Vec<MotionState>,
    prev: Vec<f32>,
    key_a: Vec<f32>,
    key_b: Vec<f32>,
    t_rel: Vec<f32>,
    fixed_a: Vec<f32>,
    fixed_b: Vec<f32>,
    pose: Vec<f32>,
}

impl StepBuffers {
    /// Steps checked keys into checked buffers, one graph call per frame (`d` values per pose,
    /// `g` groups).
    fn complete(
        &mut self,
        keys: &[MotionKeys<'_>],
        out: &mut [&mut [f32]],
        d: usize,
        g: usize,
    ) -> Result<(), MotionError> {
        let b = keys.len();
        let last = keys.iter().map(|k| k.len()).max().unwrap_or(0);
        for (k, o) in keys.iter().zip(out.iter_mut()) {
            o[..d].copy_from_slice(&k.poses[..d]);
        }
        for (c, k) in keys.iter().enumerate() {
            self.prev[c * d..(c + 1) * d].copy_from_slice(&k.poses[..d]);
            self.states[c].reset();
        }
        for t in 1..last {
            for (c, k) in keys.iter().enumerate() {
                // A character whose keys have ended holds its last interval at t_rel 1.
                let (a, z, rel) =
                    if t < k.len() { k.interval(t) } else { (k.frames.len() - 2, k.frames.len() - 1, 1.0) };
                self.key_a[c * d..(c + 1) * d].copy_from_slice(&k.poses[a * d..(a + 1) * d]);
                self.key_b[c * d..(c + 1) * d].copy_from_slice(&k.poses[z * d..(z + 1) * d]);
                self.t_rel[c] = rel;
                if g > 0 {
                    let (fa, fb) = (&mut self.fixed_a[c * g..(c + 1) * g], &mut self.fixed_b[c * g..(c + 1) * g]);
                    if k.fixed.is_empty() {
                        fa.fill(1.0);
                        fb.fill(1.0);
                    } else {
                        fa.copy_from_slice(&k.fixed[a * g..(a + 1) * g]);
                        fb.copy_from_slice(&k.fixed[z * g..(z + 1) * g]);
                    }
                }
            }
            let (prev, ka, kb, tr) =
                (&self.prev[..b * d], &self.key_a[..b * d], &self.key_b[..b * d], &self.t_rel[..b]);
            let (fa, fb) = (&self.fixed_a[..b * g], &self.fixed_b[..b * g]);
            let whole: [&[f32]; 4] = [prev, ka, kb, tr];
            let partial: [&[f32]; 6] = [prev, ka, kb, tr, fa, fb];
            let inputs: &[&[f32]] = if g > 0 { &partial } else { &whole };
            self.runner.step_batch(&mut self.states[..b], inputs, &mut [&mut self.pose[..b * d]])?;
            let pose = &self.pose[..b * d];
            for (c, k) in keys.iter().enumerate() {
                let p = &pose[c * d..(c + 1) * d];
                if t < k.len() {
                    out[c][t * d..(t + 1) * d].copy_from_slice(p);
                }
                self.prev[c * d..(c + 1) * d].copy_from_slice(p);
            }
        }
        Ok(())
    }
}

/// Scratch space to complete keys on one thread (`Send`, not `Sync`). With the ARNN's step
/// graph no allocation per call once the graph sessions for the batch sizes used exist; the
/// in-betweening design allocates each shot's features and tensors per call.
#[derive(Debug)]
pub struct KeyframeRunner {
    graph: RunnerGraph,
    max_batch: usize,
    scratch: Vec<f32>,
    dofs: usize,
    groups: usize,
    key_groups: Vec<usize>,
    hit_keys: bool,
    feet: Option<KeyFeet>,
    foot_lock: bool,
    fallback: Option<Fallback>,
    fallback_weights: Vec<f32>,
    fallback_kept: Vec<Vec<f64>>,
}

impl KeyframeRunner {
    /// The in-betweening design's fallback towards the curves through the keys: the file's
    /// ([`KeyframeModel::default_fallback`], as `zoo complete` applies it) unless
    /// [`KeyframeRunner::set_fallback`] changed it; `None`: the network alone (and always for
    /// the ARNN's step graph).
    pub fn fallback(&self) -> Option<&Fallback> {
        self.fallback.as_ref()
    }

    /// Sets the fallback of [`KeyframeRunner::fallback`]: `None` for the network alone (`zoo
    /// bench --no-fallback`), or thresholds of your own (checked). The ARNN's step graph has no
    /// fallback and refuses one.
    pub fn set_fallback(&mut self, fallback: Option<Fallback>) -> Result<(), MotionError> {
        if let Some(f) = &fallback {
            if matches!(self.graph, RunnerGraph::Step(_)) {
                return Err(MotionError::Unsupported {
                    reason: "the ARNN's step graph has no fallback towards the curves: only the in-betweening design \
                             (`zoo train arnn --design inbetween`) has one"
                        .into(),
                });
            }
            f.check().map_err(|e| MotionError::Unsupported { reason: format!("fallback: {e}") })?;
        }
        self.fallback = fallback;
        Ok(())
    }

    /// The fallback's weight towards the curves of each character of the last completion (0:
    /// the network's completion kept, 1: the curves); empty without a fallback.
    pub fn fallback_weights(&self) -> &[f32] {
        &self.fallback_weights
    }

    /// The share of the network's correction the fallback kept on each frame of `character`'s
    /// last completion (1: the network's, 0: the curves); empty without a fallback. The foot
    /// lock between the keys is scaled by it (an interval handed to the curves is not locked);
    /// an application that locks the feet itself passes it to
    /// `zoo_protocol::keylock::lock_feet_between_keys`.
    pub fn fallback_kept(&self, character: usize) -> &[f64] {
        self.fallback_kept.get(character).map_or(&[], Vec::as_slice)
    }

    /// Most characters per call.
    pub fn max_batch(&self) -> usize {
        self.max_batch
    }

    /// Whether completions are corrected to hit every key exactly (the default) or are the
    /// network's own output (`false`: its key misses measure the network).
    pub fn set_hit_keys(&mut self, on: bool) {
        self.hit_keys = on;
    }

    /// Whether a humanoid's completions have their feet locked between the keys (the default,
    /// as `zoo complete`; nothing to lock for a model without legs) or are left as the network
    /// and the key correction made them (`false`).
    pub fn set_foot_lock(&mut self, on: bool) {
        self.foot_lock = on;
    }

    /// Sets each key frame of a completion to its key and spreads the network's miss over the
    /// frames before it ([`zoo_protocol::keyhit::hit_keys`]).
    fn hit(&mut self, keys: &MotionKeys<'_>, out: &mut [f32]) {
        let g = self.groups;
        let layout = zoo_protocol::keyhit::KeyLayout {
            dofs: self.dofs,
            frames: keys.frames,
            key_groups: &self.key_groups,
            quaternions: g > 0,
        };
        let fixes = |k: usize, group: usize| keys.fixed.is_empty() || keys.fixed[k * g + group] == 1.0;
        zoo_protocol::keyhit::hit_keys(layout, keys.poses, fixes, out, &mut self.scratch);
    }

    /// Completes one character's keys into `out` (`keys.len() * dofs` values, frame-major).
    pub fn complete(&mut self, keys: MotionKeys<'_>, out: &mut [f32]) -> Result<(), MotionError> {
        self.complete_batch(&[keys], &mut [out])
    }

    /// Completes the keys of `keys.len()` characters: `out[c]` receives `keys[c].len() * dofs`
    /// values. The step graph runs one graph call per frame for the whole batch; the
    /// in-betweening design one call per character. Every buffer and key is checked before
    /// anything is written (a bad key or buffer leaves `out` unchanged).
    pub fn complete_batch(&mut self, keys: &[MotionKeys<'_>], out: &mut [&mut [f32]]) -> Result<(), MotionError> {
        let (b, d, g) = (keys.len(), self.dofs, self.groups);
        if b == 0 {
            return Err(MotionError::EmptyBatch);
        }
        if b > self.max_batch() {
            return Err(MotionError::Keys {
                character: b - 1,
                reason: format!("{b} characters, but the runner was made for at most {}", self.max_batch()),
            });
        }
        if out.len() != b {
            return Err(MotionError::BufferCount { what: "completion outputs", expected: b, found: out.len() });
        }
        for (c, (k, o)) in keys.iter().zip(out.iter()).enumerate() {
            k.check(c, d, g)?;
            // The name is formatted only on a mismatch: no allocation per call.
            if o.len() != k.len() * d {
                crate::runner::check_len(&format!("completion output of character {c}"), o.len(), k.len(), d)?;
            }
        }
        match &mut self.graph {
            RunnerGraph::Step(step) => step.complete(keys, out, d, g)?,
            RunnerGraph::Shot(shot) => {
                self.fallback_weights.clear();
                self.fallback_kept.clear();
                let fallback = self.fallback.as_ref();
                shot.complete(keys, out, fallback, &mut self.fallback_weights, &mut self.fallback_kept)?
            }
        }
        if self.hit_keys {
            for (k, o) in keys.iter().zip(out.iter_mut()) {
                self.hit(k, o);
            }
        }
        if let (Some(feet), true) = (&mut self.feet, self.foot_lock) {
            for (c, (k, o)) in keys.iter().zip(out.iter_mut()).enumerate() {
                feet.apply(k.frames, self.fallback_kept.get(c).map_or(&[], Vec::as_slice), o);
            }
        }
        Ok(())
    }
}
