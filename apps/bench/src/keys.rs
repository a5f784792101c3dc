//! The keys-only in-betweening benchmark (`zoo bench --layout keys`): an animator's blocking,
//! key poses every K frames and nothing else, the frames between them predicted.
//!
//! Test windows are the in-betweening benchmark's ([`zoo_data::benchmark::Benchmark`]: 65
//! frames every 40 of the test split, centred, facing unified; the training split's statistics,
//! bone offsets and planted foot heights). Of each window, frames `0..=60` are used; frames
//! `0, K, 2K, ...` up to the last multiple of K within 60 are keys (60 is a multiple of 5, 10,
//! 15, 20 and 30). Layouts:
//!
//! - **whole**: every key is a whole pose (root position, every joint's rotation);
//! - **partial**: the first and the last key are whole; the keys between fix the root (its
//!   position and rotation) and the limbs' end joints only (the joints without children and the
//!   joints named `foot`; bandai2: Head, Hand_L/R, Foot_L/R, Toes_L/R); every other joint is
//!   free there.
//!
//! Scored frames: every frame between the first and the last key that is not a whole key (in
//! the partial layout, the partial key frames are scored). L2Q, L2P, ACO and foot skate are
//! means over the scored frames (foot skate: each scored frame against the frame before it);
//! NPSS needs a contiguous signal and is computed over frames `1..last` (keys included). The
//! ground truth's own foot skate over the same frames is the floor.
//!
//! Baselines, per channel between the keys that fix it:
//! - `linear`: root position LERP, local rotation SLERP ([`zoo_motion::quat::slerp`]);
//! - `bezier`: Blender's default F-curves ([`crate::fcurve`]) through the Euler angles of each
//!   joint in the clip's own channel order (degrees, each key's angles taken nearest the
//!   previous key's, as Blender's BVH importer keeps them continuous) and the root position.
//!
//! Models: `arnn:RUN_DIR` (a humanoid ARNN run folder, autoregressive or in-betweening design:
//! the keys are its keys, partial keys its partial keys).
//!
//! `METHOD+lock` (`bezier+lock`, `arnn+lock:RUN_DIR`, ...) runs the method, then the foot lock
//! between its keys ([`zoo_protocol::keylock`]; key frames unchanged).
//!
//! `onnx:FILE.onnx` runs an exported humanoid keyframe model (`zoo export --onnx`) through the
//! engine runtime's keyframes task on tract, with its foot lock off; `onnx+lock:FILE.onnx` with
//! the runtime's own foot lock on, as an engine gets it.

use crate::Result;
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;
use zoo_data::Context as _;
use zoo_data::benchmark::{BenchResult, Benchmark};
use zoo_data::dataset::NamedClip;
use zoo_data::{Message, Progress, bail};
use zoo_motion::Skeleton;
use zoo_motion::euler::EulerOrder;
use zoo_motion::fk::forward_kinematics_frame;
use zoo_motion::quat::slerp;

/// Frames of a test window the keys span: keys at `0, K, ...` up to this frame.
pub const SPAN: usize = 60;

/// The keys' layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyLayout {
    /// Every key is a whole pose.
    Whole,
    /// The keys between the first and the last fix the root and the limbs' end joints only.
    Partial,
}

impl KeyLayout {
    /// `whole` or `partial`.
    pub fn name(self) -> &'static str {
        match self {
            KeyLayout::Whole => "whole",
            KeyLayout::Partial => "partial",
        }
    }
}

/// One window's keys: what a method sees. Group 0 is the root position, group `1 + j` joint
/// `j`'s rotation (the ARNN's key groups).
#[derive(Clone, Debug)]
pub struct KeyTask<'a> {
    /// Skeleton (joint 0 is the root).
    pub skeleton: &'a Skeleton,
    /// Key frames, from 0, strictly increasing; the output runs to the last.
    pub frames: Vec<usize>,
    /// Root position of each key.
    pub root: Vec<DVec3>,
    /// Local rotations of each key, keys x joints (a free joint's value is the truth and must
    /// not be used).
    pub rot: Vec<DQuat>,
    /// Per key, which groups it fixes (`1 + joints` flags each).
    pub fixed: Vec<Vec<bool>>,
}

impl KeyTask<'_> {
    /// The keys that fix group `g`: (index of the key, frame).
    pub fn keys_fixing(&self, g: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.frames.iter().enumerate().filter(move |(k, _)| self.fixed[*k][g]).map(|(k, f)| (k, *f))
    }

    /// Frames of the completed motion (the last key's frame + 1).
    pub fn len(&self) -> usize {
        self.frames.last().map_or(0, |f| f + 1)
    }

    /// Whether there is no key.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

/// A completed motion: root positions and local rotations of frames `0..=last key`.
#[derive(Clone, Debug, Default)]
pub struct Filled {
    /// Root position per frame.
    pub root: Vec<DVec3>,
    /// Local rotations, frames x joints.
    pub rot: Vec<DQuat>,
    /// The largest key misses before any correction (root distance in clip units, rotation
    /// angle in degrees), for methods that can miss a key.
    pub raw_miss: Option<(f64, f64)>,
    /// The share of an in-betweening network's correction its fallback kept per frame (empty:
    /// none), which scales the foot lock of `+lock` ([`zoo_protocol::keylock`]).
    pub kept: Vec<f64>,
}

impl Filled {
    /// A motion of humanoid pose vectors (`3 + 4 J` values per frame, [`zoo_protocol::inbetween`]'s
    /// layout), each rotation taken on the side of the previous frame's (from `first`, the
    /// rotations of the first key) so that the quaternions stay continuous.
    pub fn from_poses<'p>(
        poses: impl IntoIterator<Item = &'p [f64]>,
        first: &[DQuat],
        raw_miss: Option<(f64, f64)>,
    ) -> Filled {
        let j = first.len();
        let mut f = Filled { raw_miss, ..Filled::default() };
        let mut last = first.to_vec();
        for p in poses {
            let (root, mut rot) = zoo_protocol::inbetween::decode_pose(p, j);
            for (q, l) in rot.iter_mut().zip(last.iter_mut()) {
                if q.dot(*l) < 0.0 {
                    *q = -*q;
                }
                *l = *q;
            }
            f.root.push(root);
            f.rot.extend(rot);
        }
        f
    }
}

/// A method of the keys-only benchmark.
pub trait KeyMethod: Sync {
    /// Row name in the table and key in the JSON.
    fn name(&self) -> String;
    /// Completes one motion per task.
    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String>;
}

/// Per-channel interpolation between the keys that fix each group: `linear` or `bezier`.
pub struct ChannelBaseline {
    bezier: bool,
}

impl ChannelBaseline {
    /// Root LERP and rotation SLERP.
    pub const LINEAR: ChannelBaseline = ChannelBaseline { bezier: false };
    /// Blender's default F-curves on the Euler channels.
    pub const BEZIER: ChannelBaseline = ChannelBaseline { bezier: true };
}

impl KeyMethod for ChannelBaseline {
    fn name(&self) -> String {
        if self.bezier { "bezier".into() } else { "linear".into() }
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        tasks.par_iter().map(|t| if self.bezier { bezier(t) } else { Ok(linear(t)) }).collect()
    }
}

/// The key (index) before or at frame `f` and the one after it among `keys`, with the weight.
fn bracket(keys: &[(usize, usize)], f: usize) -> (usize, usize, f64) {
    let i = keys.partition_point(|(_, kf)| *kf <= f).max(1) - 1;
    if i + 1 >= keys.len() {
        return (keys[i].0, keys[i].0, 0.0);
    }
    let ((a, fa), (b, fb)) = (keys[i], keys[i + 1]);
    (a, b, (f - fa) as f64 / (fb - fa) as f64)
}

/// Root LERP and local-rotation SLERP between the keys fixing each group.
pub fn linear(t: &KeyTask<'_>) -> Filled {
    let (n, j) = (t.len(), t.skeleton.len());
    let mut out = Filled { root: vec![DVec3::ZERO; n], rot: vec![DQuat::IDENTITY; n * j], ..Filled::default() };
    let root_keys: Vec<(usize, usize)> = t.keys_fixing(0).collect();
    for f in 0..n {
        let (a, b, w) = bracket(&root_keys, f);
        out.root[f] = t.root[a].lerp(t.root[b], w);
    }
    for jj in 0..j {
        let keys: Vec<(usize, usize)> = t.keys_fixing(1 + jj).collect();
        for f in 0..n {
            let (a, b, w) = bracket(&keys, f);
            out.rot[f * j + jj] = slerp(t.rot[a * j + jj], t.rot[b * j + jj], w);
        }
    }
    out
}

pub use zoo_protocol::fcurve::euler_near;

/// The Euler channels (degrees) of joint `jj` at the keys that fix it, continuous along them.
pub fn euler_keys(t: &KeyTask<'_>, jj: usize) -> Vec<(f64, [f64; 3])> {
    let (j, order) = (t.skeleton.len(), t.skeleton.channels[jj].order);
    let mut prev: Option<[f64; 3]> = None;
    t.keys_fixing(1 + jj)
        .map(|(k, f)| {
            let e = euler_near(order, t.rot[k * j + jj], prev);
            prev = Some(e);
            (f as f64, e)
        })
        .collect()
}

/// Blender's default F-curves through the root position channels and each joint's Euler
/// channels at the keys that fix them, evaluated at every frame
/// ([`zoo_protocol::fcurve::bezier_inbetween`]).
pub fn bezier(t: &KeyTask<'_>) -> std::result::Result<Filled, String> {
    let orders: Vec<EulerOrder> = t.skeleton.channels.iter().map(|c| c.order).collect();
    let keys = zoo_protocol::fcurve::ShotKeys { frames: &t.frames, root: &t.root, rot: &t.rot, fixed: &t.fixed };
    let (root, rot) = zoo_protocol::fcurve::bezier_inbetween(&orders, &keys)
        .ok_or_else(|| format!("keys at frames {:?} do not make F-curves (a joint no key fixes?)", t.frames))?;
    Ok(Filled { root, rot, ..Filled::default() })
}

/// A humanoid ARNN run folder as a keys-only method (candle, one completion per window).
pub struct ArnnKeys {
    name: String,
    model: zoo_arnn::Arnn,
    norm: zoo_arnn::Normalization,
}

impl ArnnKeys {
    /// Loads a `zoo train arnn --data BVH_FOLDER` run folder.
    pub fn load(dir: &Path, name: String) -> Result<Self> {
        let (model, norm) = zoo_arnn::checkpoint::load(dir, &candle_core::Device::Cpu)?;
        if model.config().skeleton.is_none() {
            bail!(
                "{} holds a lamp ARNN: the keys-only benchmark needs one trained on humanoid clips (`zoo train arnn \
                 --data BVH_FOLDER --valid-glob GLOB`)",
                dir.display()
            );
        }
        Ok(ArnnKeys { name, model, norm })
    }

    fn one(&self, t: &KeyTask<'_>) -> zoo_arnn::ArnnResult<Filled> {
        use zoo_arnn::humanoid::poses;
        zoo_arnn::humanoid::check_skeleton(self.model.config(), t.skeleton)?;
        let j = t.skeleton.len();
        let key_poses = poses(&t.root, &t.rot, j);
        let whole = t.fixed.iter().all(|m| m.iter().all(|&v| v));
        let fixed: &[Vec<bool>] = if whole { &[] } else { &t.fixed };
        let raw = zoo_arnn::complete_partial_raw(&self.model, &self.norm, &t.frames, &key_poses, fixed)?;
        let mut corrected = raw.clone();
        zoo_arnn::hit_keys(self.model.config(), &t.frames, &key_poses, fixed, &mut corrected);
        let (root_miss, (angle_miss, _, _)) = zoo_arnn::humanoid::key_misses(&raw, &t.frames, &key_poses, fixed, j);
        Ok(Filled::from_poses(corrected.iter().map(Vec::as_slice), &t.rot[..j], Some((root_miss, angle_miss))))
    }
}

impl KeyMethod for ArnnKeys {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        tasks.iter().map(|t| self.one(t).map_err(|e| format!("{}: {e}", self.name))).collect()
    }
}

/// An in-betweening run folder (`zoo train arnn --design inbetween`) as a keys-only method
/// (candle; shots of one length as one batch): the network's poses, then the keys hit
/// ([`zoo_protocol::keyhit`]; the network meets them by construction, so this changes nothing
/// beyond float rounding).
pub struct InbetweenKeys {
    name: String,
    model: zoo_arnn::inbetween::Inbetween,
    norm: zoo_arnn::Normalization,
}

impl InbetweenKeys {
    /// Loads a `zoo train arnn --design inbetween` run folder.
    pub fn load(dir: &Path, name: String) -> Result<Self> {
        let (model, norm) = zoo_arnn::inbetween::load(dir, &candle_core::Device::Cpu)?;
        Ok(InbetweenKeys { name, model, norm })
    }

    fn all(&self, tasks: &[KeyTask<'_>]) -> zoo_arnn::ArnnResult<Vec<Filled>> {
        use zoo_arnn::humanoid::poses;
        let c = self.model.config();
        let Some(first) = tasks.first() else { return Ok(vec![]) };
        let names = &first.skeleton.names;
        if *names != c.skeleton.names {
            return Err(zoo_arnn::ArnnError::Config(format!(
                "the model was trained on a skeleton of {} joints, the data has {}: use a model trained on this skeleton",
                c.skeleton.names.len(),
                names.len()
            )));
        }
        let j = c.joints();
        let key_poses: Vec<Vec<Vec<f64>>> = tasks.iter().map(|t| poses(&t.root, &t.rot, j)).collect();
        let fixed: Vec<Vec<Vec<bool>>> = tasks
            .iter()
            .map(|t| if t.fixed.iter().all(|m| m.iter().all(|&v| v)) { vec![] } else { t.fixed.clone() })
            .collect();
        let shots: Vec<zoo_arnn::inbetween::ShotKeyRefs<'_>> = tasks
            .iter()
            .zip(&key_poses)
            .zip(&fixed)
            .map(|((t, p), f)| (t.frames.as_slice(), p.as_slice(), f.as_slice()))
            .collect();
        let raw = zoo_arnn::inbetween::complete_shots_kept(&self.model, &self.norm, &shots)?;
        let groups = c.key_groups();
        let mut out = Vec::with_capacity(tasks.len());
        for (((t, kp), fx), (raw, kept)) in tasks.iter().zip(&key_poses).zip(&fixed).zip(raw) {
            let (root_miss, (angle_miss, _, _)) = zoo_arnn::humanoid::key_misses(&raw, &t.frames, kp, fx, j);
            let d = c.dofs();
            let mut flat: Vec<f64> = raw.iter().flatten().copied().collect();
            let layout =
                zoo_protocol::keyhit::KeyLayout { dofs: d, frames: &t.frames, key_groups: &groups, quaternions: true };
            let key_flat: Vec<f64> = kp.iter().flatten().copied().collect();
            let fixes = |k: usize, g: usize| fx.get(k).is_none_or(|m| m[g]);
            zoo_protocol::keyhit::hit_keys(layout, &key_flat, fixes, &mut flat, &mut vec![0.0; d]);
            let filled = Filled::from_poses(flat.chunks_exact(d), &t.rot[..j], Some((root_miss, angle_miss)));
            out.push(Filled { kept, ..filled });
        }
        Ok(out)
    }
}

impl KeyMethod for InbetweenKeys {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        self.all(tasks).map_err(|e| format!("{}: {e}", self.name))
    }
}

/// The angle between two rotations, degrees.
pub fn angle_deg(a: DQuat, b: DQuat) -> f64 {
    (2.0 * a.dot(b).abs().min(1.0).acos()).to_degrees()
}

/// The methods of `--methods` in the keys layouts: the context layout's defaults (`zerovel`,
/// `interp`) stand for the keys layouts' baselines (`linear`, `bezier`).
pub fn methods(specs: &[String]) -> Result<Vec<Box<dyn KeyMethod>>> {
    if specs == ["zerovel", "interp"] {
        return ["linear", "bezier"].iter().map(|m| method(m)).collect();
    }
    specs.iter().map(|m| method(m.trim())).collect()
}

/// The keyframe model of the run folder `dir`, exported in memory and loaded by the runtime.
pub fn exported(dir: &Path) -> Result<zoo_runtime::KeyframeModel> {
    let exported = zoo_models::export_run(dir, &Default::default())
        .with_context(|| format!("exporting the run folder {} for the runtime", dir.display()))?;
    Ok(zoo_runtime::KeyframeModel::from_bytes(&exported.model.to_bytes())?)
}

/// An exported keyframe model run by the engine runtime ([`zoo_runtime::KeyframeRunner`], one
/// character per call), its foot lock on or off, with the file's fallback towards the curves
/// unless `zoo bench --no-fallback` (the method is then named with a `+fallback` suffix, and
/// how often the fallback acted is said on stderr when the method is dropped).
pub struct RuntimeKeys {
    name: String,
    model: zoo_runtime::KeyframeModel,
    foot_lock: bool,
    fallback: bool,
    /// Per largest gap between a shot's keys: shots completed, shots with a fallback weight
    /// above 0, and the sum of the weights.
    counts: std::sync::Mutex<std::collections::BTreeMap<usize, (usize, usize, f64)>>,
}

impl Drop for RuntimeKeys {
    fn drop(&mut self) {
        let Ok(counts) = self.counts.lock() else { return };
        if !self.fallback || counts.is_empty() {
            return;
        }
        let (n, hit, sum) = counts.values().fold((0, 0, 0.0), |a, c| (a.0 + c.0, a.1 + c.1, a.2 + c.2));
        let per_gap: Vec<String> = counts
            .iter()
            .map(|(gap, (n, hit, sum))| {
                format!("{gap}: {:.0} % at {:.3}", 100.0 * *hit as f64 / *n as f64, sum / *n as f64)
            })
            .collect();
        eprintln!(
            "{}: the fallback towards the curves acted on {hit} of {n} shots ({:.1} %), mean weight {:.3}; by the \
             largest gap between keys, shots it acted on and the mean weight: {}",
            self.name,
            100.0 * hit as f64 / n as f64,
            sum / n as f64,
            per_gap.join(", ")
        );
    }
}

impl RuntimeKeys {
    /// Loads `zoo export --onnx` output of a humanoid keyframe model.
    pub fn load(path: &Path, name: String, foot_lock: bool) -> Result<Self> {
        Self::of(zoo_runtime::KeyframeModel::load(path)?, path, name, foot_lock)
    }

    /// A humanoid keyframe model's run folder `dir`, exported in memory (`arnn:RUN_DIR`).
    pub fn of_run(dir: &Path, name: String, foot_lock: bool) -> Result<Self> {
        Self::of(exported(dir)?, dir, name, foot_lock)
    }

    /// `model` (loaded from `path`) as the method `name`.
    pub fn of(model: zoo_runtime::KeyframeModel, path: &Path, name: String, foot_lock: bool) -> Result<Self> {
        if model.groups() == 0 {
            bail!("{}: a keyframe model of {} values per pose, not a humanoid one", path.display(), model.dofs());
        }
        let fallback = model.default_fallback().is_some() && zoo_rtn::method::fallback_enabled();
        let name = if fallback { format!("{name}+fallback") } else { name };
        Ok(RuntimeKeys { name, model, foot_lock, fallback, counts: Default::default() })
    }

    fn one(&self, runner: &mut zoo_runtime::KeyframeRunner, t: &KeyTask<'_>) -> Result<Filled> {
        let j = t.skeleton.len();
        let (d, g) = (self.model.dofs(), self.model.groups());
        if d != zoo_protocol::inbetween::dofs(j) || g != 1 + j {
            bail!("the model completes poses of {d} values in {g} groups, the data's skeleton has {j} joints");
        }
        let key_poses = zoo_arnn::humanoid::poses(&t.root, &t.rot, j);
        let poses: Vec<f32> = key_poses.iter().flatten().map(|&v| v as f32).collect();
        let whole = t.fixed.iter().all(|m| m.iter().all(|&v| v));
        let fixed: Vec<f32> =
            if whole { vec![] } else { t.fixed.iter().flatten().map(|&v| if v { 1.0 } else { 0.0 }).collect() };
        let keys = zoo_runtime::MotionKeys { frames: &t.frames, poses: &poses, fixed: &fixed };
        // The network's own misses (keys not hit, feet not locked), then the output.
        let mut out = vec![0.0f32; t.len() * d];
        runner.set_hit_keys(false);
        runner.set_foot_lock(false);
        runner.complete(keys, &mut out)?;
        let raw: Vec<Vec<f64>> = out.chunks_exact(d).map(|p| p.iter().map(|&v| v as f64).collect()).collect();
        let bools: &[Vec<bool>] = if whole { &[] } else { &t.fixed };
        let (root_miss, (angle_miss, _, _)) = zoo_arnn::humanoid::key_misses(&raw, &t.frames, &key_poses, bools, j);
        runner.set_hit_keys(true);
        runner.set_foot_lock(self.foot_lock);
        runner.complete(keys, &mut out)?;
        if let (Some(&w), Ok(mut counts)) = (runner.fallback_weights().first(), self.counts.lock()) {
            let gap = t.frames.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
            let c = counts.entry(gap).or_default();
            *c = (c.0 + 1, c.1 + usize::from(w > 0.0), c.2 + w as f64);
        }
        let out: Vec<f64> = out.iter().map(|&v| v as f64).collect();
        Ok(Filled::from_poses(out.chunks_exact(d), &t.rot[..j], Some((root_miss, angle_miss))))
    }
}

impl KeyMethod for RuntimeKeys {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        let err = |e: crate::BenchError| format!("{}: {e}", self.name);
        tasks
            .par_chunks(16.max(tasks.len() / 8))
            .map(|chunk| {
                let mut runner = self.model.runner(1).map_err(|e| err(e.into()))?;
                runner.set_foot_lock(self.foot_lock);
                if !self.fallback {
                    runner.set_fallback(None).map_err(|e| err(e.into()))?;
                }
                chunk.iter().map(|t| self.one(&mut runner, t).map_err(err)).collect::<std::result::Result<Vec<_>, _>>()
            })
            .collect::<std::result::Result<Vec<Vec<Filled>>, String>>()
            .map(|v| v.into_iter().flatten().collect())
    }
}

/// A key method on the in-betweening benchmark's transitions (`zoo bench --methods
/// arnn:RUN_DIR` of an in-betweening run): the context frames and the target are its keys, whole;
/// the transition is the frames between the last context frame and the target.
pub struct KeysOnTransitions {
    inner: Box<dyn KeyMethod>,
}

impl KeysOnTransitions {
    /// `inner` on the transition layout.
    pub fn new(inner: Box<dyn KeyMethod>) -> Self {
        KeysOnTransitions { inner }
    }
}

impl zoo_data::benchmark::TransitionMethod for KeysOnTransitions {
    fn name(&self) -> String {
        self.inner.name()
    }

    fn generate(
        &self,
        tasks: &[zoo_data::benchmark::TransitionTask<'_>],
    ) -> std::result::Result<Vec<zoo_data::benchmark::Transition>, String> {
        use zoo_data::benchmark::N_PAST;
        let keys: Vec<KeyTask<'_>> = tasks
            .iter()
            .map(|t| {
                let j = t.skeleton.len();
                let mut root = t.past_root[..N_PAST].to_vec();
                root.push(t.target_root[0]);
                let mut rot = t.past_rot[..N_PAST * j].to_vec();
                rot.extend_from_slice(&t.target_rot[..j]);
                let frames = zoo_arnn::inbetween_train::transition_keys(t.frames);
                let fixed = vec![vec![true; 1 + j]; frames.len()];
                KeyTask { skeleton: t.skeleton, frames, root, rot, fixed }
            })
            .collect();
        let filled = self.inner.fill(&keys)?;
        Ok(filled
            .into_iter()
            .zip(tasks)
            .map(|(f, t)| {
                let (j, n) = (t.skeleton.len(), t.frames);
                let mut rot = f.rot[N_PAST * j..(N_PAST + n) * j].to_vec();
                // Signs continuous from the last context frame's own, as the other methods'.
                let mut last = t.past_rot[(N_PAST - 1) * j..N_PAST * j].to_vec();
                for frame in rot.chunks_exact_mut(j) {
                    zoo_arnn::humanoid::continue_signs(frame, &mut last);
                }
                zoo_data::benchmark::Transition { root: f.root[N_PAST..N_PAST + n].to_vec(), rot, raw_positions: None }
            })
            .collect())
    }
}

/// A method followed by the foot lock between its keys ([`zoo_protocol::keylock::key_foot_lock`],
/// the skeleton's legs found by name and its rest offsets; key frames unchanged).
pub struct WithFootLock {
    name: String,
    inner: Box<dyn KeyMethod>,
}

impl KeyMethod for WithFootLock {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        let mut filled = self.inner.fill(tasks)?;
        filled.par_iter_mut().zip(tasks).for_each(|(f, t)| {
            let s = t.skeleton;
            if let Some(lock) = zoo_protocol::keylock::key_foot_lock(s) {
                zoo_protocol::keylock::lock_feet_between_keys(
                    &lock, s, &s.offsets, &t.frames, &f.kept, &f.root, &mut f.rot,
                );
            }
        });
        Ok(filled)
    }
}

/// A `--methods` entry of the keys-only benchmark: `linear`, `bezier` or `arnn:RUN_DIR`, each
/// optionally with `+lock` after its kind (`bezier+lock`, `arnn+lock:RUN_DIR`).
pub fn method(spec: &str) -> Result<Box<dyn KeyMethod>> {
    let (kind, rest) = spec.split_once(':').map_or((spec, None), |(k, r)| (k, Some(r)));
    if let (Some(file), "onnx" | "onnx+lock") = (rest, kind) {
        return Ok(Box::new(RuntimeKeys::load(Path::new(file), spec.to_string(), kind == "onnx+lock")?));
    }
    // A run folder runs exported through the runtime, as `zoo complete` and engines run it, with
    // the runtime's foot lock; `candle-arnn...` runs the training model with the benchmark's.
    if let (Some(dir), "arnn" | "arnn+lock") = (rest, kind) {
        return Ok(Box::new(RuntimeKeys::of_run(Path::new(dir), spec.to_string(), kind == "arnn+lock")?));
    }
    let (kind, spec_inner) = match kind.strip_prefix("candle-") {
        Some(k) => (k, rest.map_or(k.to_string(), |r| format!("{k}:{r}"))),
        None => (kind, spec.to_string()),
    };
    if spec_inner != spec {
        // `candle-arnn...:DIR`: named as given.
        let inner = candle_method(&spec_inner, kind, rest)?;
        return Ok(Box::new(Renamed { name: spec.to_string(), inner }));
    }
    candle_method(spec, kind, rest)
}

/// A method under another name (`candle-arnn:DIR` for the candle method of `arnn:DIR`).
struct Renamed {
    name: String,
    inner: Box<dyn KeyMethod>,
}

impl KeyMethod for Renamed {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn fill(&self, tasks: &[KeyTask<'_>]) -> std::result::Result<Vec<Filled>, String> {
        self.inner.fill(tasks)
    }
}

/// The keys-only methods of the training model in candle and the baselines.
fn candle_method(spec: &str, kind: &str, rest: Option<&str>) -> Result<Box<dyn KeyMethod>> {
    if let Some(base) = kind.strip_suffix("+lock") {
        let inner = candle_method(&rest.map_or(base.to_string(), |r| format!("{base}:{r}")), base, rest)?;
        return Ok(Box::new(WithFootLock { name: spec.to_string(), inner }));
    }
    match spec.split_once(':') {
        None if spec == "linear" => Ok(Box::new(ChannelBaseline::LINEAR)),
        None if spec == "bezier" => Ok(Box::new(ChannelBaseline::BEZIER)),
        Some(("arnn", dir)) if zoo_arnn::inbetween::is_inbetween_run(Path::new(dir)) => {
            Ok(Box::new(InbetweenKeys::load(Path::new(dir), spec.to_string())?))
        }
        Some(("arnn", dir)) => Ok(Box::new(ArnnKeys::load(Path::new(dir), spec.to_string())?)),
        _ => bail!(
            "method `{spec}` is not one of the keys-only benchmark's: `linear`, `bezier`, `arnn:RUN_DIR` (a humanoid \
             `zoo train arnn --data` run folder, exported and run by the engine runtime), `onnx:FILE.onnx` (its \
             export), `candle-arnn:RUN_DIR` (the training model in candle), each optionally with `+lock` after its \
             kind (`arnn+lock:RUN_DIR`)"
        ),
    }
}

/// The groups a partial key fixes: the root's position and rotation and the limbs' end joints
/// (joints without children, joints named `foot`).
pub fn partial_groups(s: &Skeleton) -> Vec<bool> {
    let mut g = vec![false; 1 + s.len()];
    g[0] = true;
    g[1] = true;
    for j in 0..s.len() {
        if s.children(j).is_empty() || s.names[j].to_ascii_lowercase().contains("foot") {
            g[1 + j] = true;
        }
    }
    g
}

/// Key frames every `every` frames within [`SPAN`].
pub fn key_frames(every: usize) -> Vec<usize> {
    (0..=SPAN / every).map(|k| k * every).collect()
}

/// The benchmark's windows prepared once; runs every method at every key spacing.
pub struct KeysBench {
    bench: Benchmark,
}

/// Global rotations and positions of frames `0..n` of local poses, with the evaluation offsets.
fn globals(s: &Skeleton, offsets: &[DVec3], root: &[DVec3], rot: &[DQuat]) -> (Vec<DQuat>, Vec<DVec3>) {
    let j = s.len();
    let n = root.len();
    let (mut gr, mut gp) = (vec![DQuat::IDENTITY; n * j], vec![DVec3::ZERO; n * j]);
    let mut lp = vec![DVec3::ZERO; j];
    lp[1..].copy_from_slice(offsets);
    for f in 0..n {
        lp[0] = root[f];
        let r = f * j..(f + 1) * j;
        forward_kinematics_frame(&s.parents, &rot[r.clone()], &lp, &mut gr[r.clone()], &mut gp[r]);
    }
    (gr, gp)
}

/// Frames `sel` of `(windows, n, joints)` arrays, flattened.
fn pick<T: Copy>(all: &[T], n: usize, j: usize, sel: &[usize]) -> Vec<T> {
    all.chunks_exact(n * j).flat_map(|w| sel.iter().flat_map(move |&f| w[f * j..(f + 1) * j].iter().copied())).collect()
}

/// Pairs (frame before, frame) of the scored frames, as two-frame sequences for the skate.
fn pairs<T: Copy>(all: &[T], n: usize, j: usize, sel: &[usize]) -> Vec<T> {
    all.chunks_exact(n * j)
        .flat_map(|w| sel.iter().flat_map(move |&f| w[(f - 1) * j..(f + 1) * j].iter().copied()))
        .collect()
}

impl KeysBench {
    /// Prepares the windows and statistics from the training and test clips.
    pub fn new(train: &[NamedClip], test: &[NamedClip]) -> Result<Self> {
        let bench = Benchmark::new(train, test).map_err(Message)?;
        if bench.test.window <= SPAN {
            bail!("test windows of {} frames: the keys-only benchmark needs more than {SPAN}", bench.test.window);
        }
        Ok(KeysBench { bench })
    }

    /// Number of test windows.
    pub fn windows(&self) -> usize {
        self.bench.windows()
    }

    /// The tasks of one key spacing and layout.
    pub fn tasks(&self, every: usize, layout: KeyLayout) -> Vec<KeyTask<'_>> {
        let t = &self.bench.test;
        let (j, sk) = (t.joints(), &t.skeleton);
        let frames = key_frames(every);
        let partial = partial_groups(sk);
        let last = frames.len() - 1;
        (0..t.count)
            .map(|w| {
                let (rot, pos) = (t.rot(w), t.pos(w));
                let fixed = (0..frames.len())
                    .map(|k| match layout {
                        KeyLayout::Partial if k > 0 && k < last => partial.clone(),
                        _ => vec![true; 1 + j],
                    })
                    .collect();
                KeyTask {
                    skeleton: sk,
                    root: frames.iter().map(|&f| pos[f * j]).collect(),
                    rot: frames.iter().flat_map(|&f| rot[f * j..(f + 1) * j].iter().copied()).collect(),
                    frames: frames.clone(),
                    fixed,
                }
            })
            .collect()
    }

    /// Runs `methods` at every key spacing in `every` with `layout`: the table's columns are the
    /// spacings; the rows `keymiss_cm` / `keymiss_deg` hold a model's largest key misses before
    /// its correction.
    pub fn run(
        &self,
        methods: &[Box<dyn KeyMethod>],
        every: &[usize],
        layout: KeyLayout,
        p: &dyn Progress,
    ) -> Result<BenchResult> {
        let t = &self.bench.test;
        let j = t.joints();
        let mut result = BenchResult { windows: t.count, gt: BTreeMap::new(), methods: BTreeMap::new() };
        for &k in every {
            if k < 2 || k > SPAN {
                bail!("keys every {k} frames: the spacing must be 2 to {SPAN} frames");
            }
            p.stage(&format!("keys every {k} frames ({})", layout.name()));
            let tasks = self.tasks(k, layout);
            let last = *tasks[0].frames.last().unwrap_or(&0);
            let n = last + 1;
            let whole: Vec<usize> = tasks[0]
                .keys_fixing(0)
                .filter(|(i, _)| tasks[0].fixed[*i].iter().all(|&v| v))
                .map(|(_, f)| f)
                .collect();
            let scored: Vec<usize> = (1..last).filter(|f| !whole.contains(f)).collect();
            let span: Vec<usize> = (1..last).collect();
            let gt = self.globals_of(&tasks, None);
            let feet = !self.bench.skate.joints.is_empty();
            if feet {
                result.gt.insert(format!("skate@{k}"), self.bench.skate.skate(&pairs(&gt.1, n, j, &scored), 2, j));
            }
            let (gq, gp) = (pick(&gt.0, n, j, &scored), pick(&gt.1, n, j, &scored));
            let gq_span = pick(&gt.0, n, j, &span);
            for m in methods {
                let start = Instant::now();
                let filled = m.fill(&tasks).map_err(Message)?;
                let ms = start.elapsed().as_secs_f64() * 1e3 / tasks.len() as f64;
                if filled.len() != tasks.len() || filled.iter().any(|f| f.root.len() != n || f.rot.len() != n * j) {
                    bail!("method {} returned motions of the wrong shape", m.name());
                }
                let (pr, pp) = self.globals_of(&tasks, Some(&filled));
                let row = result.methods.entry(m.name()).or_default();
                let std = &self.bench.stats.std;
                row.insert(format!("l2q@{k}"), zoo_data::metrics::l2q(&pick(&pr, n, j, &scored), &gq, j));
                row.insert(format!("l2p@{k}"), zoo_data::metrics::l2p(&pick(&pp, n, j, &scored), &gp, j, std));
                let npss = zoo_data::metrics::npss(&pick(&pr, n, j, &span), &gq_span, t.count, span.len(), j);
                row.insert(format!("npss@{k}"), npss);
                row.insert(format!("aco@{k}"), zoo_data::metrics::aco(&pick(&pp, n, j, &scored), &gp));
                if feet {
                    row.insert(format!("skate@{k}"), self.bench.skate.skate(&pairs(&pp, n, j, &scored), 2, j));
                }
                row.insert(format!("ms_per_transition@{k}"), ms);
                if filled.iter().all(|f| f.raw_miss.is_some()) {
                    let (cm, deg) = filled
                        .iter()
                        .filter_map(|f| f.raw_miss)
                        .fold((0.0f64, 0.0f64), |a, m| (a.0.max(m.0), a.1.max(m.1)));
                    row.insert(format!("keymiss_raw_cm@{k}"), cm);
                    row.insert(format!("keymiss_raw_deg@{k}"), deg);
                }
                let (cm, deg) = key_misses(&tasks, &filled);
                row.insert(format!("keymiss_cm@{k}"), cm);
                row.insert(format!("keymiss_deg@{k}"), deg);
            }
        }
        p.finish();
        Ok(result)
    }

    /// Global rotations and positions, `(windows, frames, joints)`, of the ground truth or of
    /// completed motions.
    fn globals_of(&self, tasks: &[KeyTask<'_>], filled: Option<&[Filled]>) -> (Vec<DQuat>, Vec<DVec3>) {
        let t = &self.bench.test;
        let j = t.joints();
        let parts: Vec<(Vec<DQuat>, Vec<DVec3>)> = (0..tasks.len())
            .into_par_iter()
            .map(|w| {
                let n = tasks[w].len();
                match filled {
                    Some(f) => globals(&t.skeleton, &self.bench.offsets, &f[w].root, &f[w].rot),
                    None => {
                        let (rot, pos) = (t.rot(w), t.pos(w));
                        let root: Vec<DVec3> = (0..n).map(|f| pos[f * j]).collect();
                        globals(&t.skeleton, &self.bench.offsets, &root, &rot[..n * j])
                    }
                }
            })
            .collect();
        let mut out = (Vec::new(), Vec::new());
        for (r, p) in parts {
            out.0.extend(r);
            out.1.extend(p);
        }
        out
    }
}

/// The largest distance between a completed root and a key fixing it, and the largest angle
/// (degrees) between a completed rotation and a key fixing it.
pub fn key_misses(tasks: &[KeyTask<'_>], filled: &[Filled]) -> (f64, f64) {
    let mut miss = (0.0f64, 0.0f64);
    for (t, f) in tasks.iter().zip(filled) {
        let j = t.skeleton.len();
        for (k, &fr) in t.frames.iter().enumerate() {
            if t.fixed[k][0] {
                miss.0 = miss.0.max((f.root[fr] - t.root[k]).length());
            }
            for jj in 0..j {
                if t.fixed[k][1 + jj] {
                    miss.1 = miss.1.max(angle_deg(f.rot[fr * j + jj], t.rot[k * j + jj]));
                }
            }
        }
    }
    miss
}

/// The result as text: the in-betweening table with the key spacings as columns, and the key
/// misses of the methods that can miss.
pub fn table(result: &BenchResult, every: &[usize], layout: KeyLayout) -> String {
    use std::fmt::Write;
    let mut s = format!("keys every K frames ({} keys), columns K\n", layout.name());
    s += &result.table(every);
    for (title, key) in [
        ("largest key miss (cm)", "keymiss_cm"),
        ("raw, before correction", "keymiss_raw_cm"),
        ("largest key miss (deg)", "keymiss_deg"),
        ("raw, before correction", "keymiss_raw_deg"),
    ] {
        let rows: Vec<_> =
            result.methods.iter().filter(|(_, m)| m.contains_key(&format!("{key}@{}", every[0]))).collect();
        if rows.is_empty() {
            continue;
        }
        let _ = writeln!(s, "\n{title}");
        for (name, m) in rows {
            let _ = write!(s, "{:<22}", format!("  {name}"));
            for k in every {
                let _ = write!(s, "{:>10.4}", m.get(&format!("{key}@{k}")).copied().unwrap_or(f64::NAN));
            }
            s.push('\n');
        }
    }
    s
}
