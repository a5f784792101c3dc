//! The ARNN on humanoid motion (beyond the paper, issue 13): poses, training sequences cut from
//! BVH clips, and the in-betweening benchmark's method (`zoo bench --methods arnn:DIR`).
//!
//! Pose vector (`3 + 4 J` values): the root position (x, y, z in the clip's units, the window
//! centred and its facing unified as the benchmark prepares windows), then each joint's local
//! rotation as a quaternion `(w, x, y, z)`, kept on one hemisphere along the sequence (each
//! frame's sign chosen nearest to the previous frame's, the first with `w >= 0`). Key groups: the
//! root position is group 0, joint `j`'s rotation group `1 + j`, so a partial key fixes whole
//! joints. Completed rotations are normalised before use.

use crate::config::{ArnnConfig, HumanoidSkeleton, KeySampling};
use crate::keys::choose_keys;
use crate::luxo::preprocess::KeyedSequence;
use crate::model::Arnn;
use crate::train::Normalization;
use crate::{ArnnError, ArnnResult};
use candle_core::{Device, Tensor};
use glam::{DQuat, DVec3};
use std::path::Path;
use zoo_data::benchmark::{N_PAST, Transition, TransitionMethod, TransitionTask};
use zoo_data::dataset::{WindowOptions, Windows};
use zoo_motion::Skeleton;
use zoo_nn::rng::SplitMix64;

/// Training windows: 66 frames (10 context frames, the longest benchmark transition of 45 and
/// its target, and 10 more), a new window every 20 frames, prepared as the benchmark's.
pub const WINDOW: WindowOptions = WindowOptions { window: 66, offset: 20, n_past: N_PAST, forward_axis: DVec3::Y };

/// Smallest standard deviation of a normalised value (a quaternion component that hardly moves
/// would otherwise be blown up by a tiny deviation).
pub const STD_FLOOR: f64 = 0.01;

/// The skeleton as the configuration records it, with the clips' frame rate.
pub fn skeleton_info(s: &Skeleton, fps: f64) -> HumanoidSkeleton {
    HumanoidSkeleton {
        names: s.names.clone(),
        parents: s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect(),
        offsets: s.offsets.iter().map(|o| [o.x, o.y, o.z]).collect(),
        fps,
    }
}

/// Names of the pose values and their key groups for a skeleton's joint names.
pub fn pose_layout(names: &[String]) -> (Vec<String>, Vec<usize>) {
    let mut dof_names: Vec<String> = ["root_x", "root_y", "root_z"].iter().map(|s| s.to_string()).collect();
    for n in names {
        dof_names.extend(["qw", "qx", "qy", "qz"].map(|c| format!("{n}_{c}")));
    }
    (dof_names, zoo_protocol::inbetween::key_groups(names.len()))
}

/// The humanoid configuration for a skeleton and the clips' frame rate ([`ArnnConfig::humanoid`]).
pub fn config_for(skeleton: &Skeleton, fps: f64) -> ArnnConfig {
    let (names, groups) = pose_layout(&skeleton.names);
    ArnnConfig::humanoid(skeleton_info(skeleton, fps), names, groups)
}

/// Appends one frame's pose (root position, local rotations) to `out`, each rotation's sign
/// chosen nearest to `prev` (the previous frame's pose values, if any).
fn push_pose(root: DVec3, rot: &[DQuat], prev: Option<&[f64]>, out: &mut Vec<f64>) {
    out.extend([root.x, root.y, root.z]);
    for (j, q) in rot.iter().enumerate() {
        let mut v = [q.w, q.x, q.y, q.z];
        let flip = match prev {
            Some(p) => v.iter().zip(&p[3 + 4 * j..7 + 4 * j]).map(|(a, b)| a * b).sum::<f64>() < 0.0,
            None => q.w < 0.0,
        };
        if flip {
            v = v.map(|x| -x);
        }
        out.extend(v);
    }
}

/// Flips each rotation of a frame to the sign nearest the previous frame's (`last`, updated to
/// this frame's): the pose is the same, the components continue (L2Q and BVH curves compare them).
pub fn continue_signs(rot: &mut [DQuat], last: &mut [DQuat]) {
    for (q, l) in rot.iter_mut().zip(last) {
        if q.dot(*l) < 0.0 {
            *q = -*q;
        }
        *l = *q;
    }
}

/// The transition of `task` made of humanoid pose vectors `poses` (one per transition frame),
/// its rotations signed as the data's: continuous from the last context frame's own signs (a
/// quaternion's sign does not change the pose, but the benchmark's L2Q compares components).
pub fn transition_of(poses: &[Vec<f64>], task: &TransitionTask<'_>) -> Transition {
    let j = task.skeleton.len();
    let mut tr = Transition {
        root: Vec::with_capacity(poses.len()),
        rot: Vec::with_capacity(poses.len() * j),
        raw_positions: None,
    };
    let mut last = task.past_rot[(N_PAST - 1) * j..N_PAST * j].to_vec();
    for p in poses {
        let (root, mut rot) = decode(p, j);
        continue_signs(&mut rot, &mut last);
        tr.root.push(root);
        tr.rot.extend(rot);
    }
    tr
}

/// Poses of consecutive frames: `rot` frames x joints, `root` one per frame.
pub fn poses(root: &[DVec3], rot: &[DQuat], joints: usize) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::with_capacity(root.len());
    for (f, r) in root.iter().enumerate() {
        let mut p = Vec::with_capacity(3 + 4 * joints);
        push_pose(*r, &rot[f * joints..(f + 1) * joints], out.last().map(|v| v.as_slice()), &mut p);
        out.push(p);
    }
    out
}

/// The root position and unit rotations of a pose.
pub use zoo_protocol::inbetween::decode_pose as decode;

/// Training or validation sequences from prepared windows; each gets keys drawn once with
/// `sampling` and `seed` (the fixed keys validation uses; training draws new ones each time).
pub fn sequences(windows: &Windows, sampling: &KeySampling, seed: u64) -> Vec<KeyedSequence> {
    let j = windows.joints();
    let mut rng = SplitMix64::new(seed);
    (0..windows.count)
        .map(|w| {
            let (rot, pos) = (windows.rot(w), windows.pos(w));
            let root: Vec<DVec3> = (0..windows.window).map(|f| pos[f * j]).collect();
            let frames = poses(&root, rot, j);
            let keys = choose_keys(sampling, &[0, frames.len() - 1], frames.len(), &mut rng);
            let (clip, start) = windows.source[w];
            KeyedSequence { name: format!("clip{clip}@{start}"), frames, keys }
        })
        .collect()
}

/// Normalisation statistics of humanoid sequences, standard deviations at least [`STD_FLOOR`].
pub fn normalization(seqs: &[KeyedSequence]) -> Normalization {
    let mut n = Normalization::fit(seqs);
    for s in &mut n.std {
        *s = s.max(STD_FLOOR);
    }
    n
}

/// Checks that a model is a humanoid ARNN for `skeleton` (same joint names and parents).
pub fn check_skeleton(config: &ArnnConfig, skeleton: &Skeleton) -> ArnnResult<()> {
    let Some(s) = &config.skeleton else {
        return Err(ArnnError::Config(
            "this ARNN was trained on the lamp, not on a humanoid skeleton: train one with `zoo train arnn --data \
             BVH_FOLDER --valid-glob GLOB`"
                .into(),
        ));
    };
    let info = skeleton_info(skeleton, s.fps);
    if s.names != info.names || s.parents != info.parents {
        return Err(ArnnError::Config(format!(
            "the ARNN was trained on a skeleton of {} joints ({}...), the data has {} ({}...): use a model trained on \
             this skeleton",
            s.names.len(),
            s.names.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
            info.names.len(),
            info.names.iter().take(3).cloned().collect::<Vec<_>>().join(", ")
        )));
    }
    Ok(())
}

/// A humanoid ARNN as an in-betweening method: the 10 context frames are keys (fed back as the
/// previous pose, so they warm the GRU state up), the target is the next key; the network
/// runs free over the transition. Tasks of one length run as one batch.
pub struct ArnnMethod {
    name: String,
    model: Arnn,
    norm: Normalization,
}

impl ArnnMethod {
    /// Loads a `zoo train arnn --data BVH_FOLDER` run folder; `name` is the table's row name.
    pub fn load(dir: &Path, name: String) -> ArnnResult<Self> {
        let (model, norm) = crate::checkpoint::load(dir, &Device::Cpu)?;
        if model.config().skeleton.is_none() {
            return Err(ArnnError::Config(format!(
                "{} holds a lamp ARNN: the in-betweening benchmark needs one trained on humanoid BVH (`zoo train arnn \
                 --data BVH_FOLDER --valid-glob GLOB`)",
                dir.display()
            )));
        }
        Ok(ArnnMethod { name, model, norm })
    }

    /// The configuration.
    pub fn config(&self) -> &ArnnConfig {
        self.model.config()
    }

    /// Completes a batch of tasks of one length.
    fn batch(&self, tasks: &[&TransitionTask<'_>]) -> ArnnResult<Vec<Transition>> {
        let Some(first) = tasks.first() else { return Ok(vec![]) };
        let (n, b, j) = (first.frames, tasks.len(), first.skeleton.len());
        check_skeleton(self.model.config(), first.skeleton)?;
        let cfg = self.model.config();
        let (d, kw) = (cfg.dofs, cfg.key_width());
        // Keys: the context frames 0..N_PAST and the target at N_PAST + n.
        let target = N_PAST + n;
        let mut key_frames: Vec<usize> = (0..N_PAST).collect();
        key_frames.push(target);
        let key_poses: Vec<Vec<Vec<f64>>> = tasks
            .iter()
            .map(|t| {
                let mut roots = t.past_root.to_vec();
                roots.push(t.target_root[0]);
                let mut rot = t.past_rot.to_vec();
                rot.extend_from_slice(&t.target_rot[..j]);
                poses(&roots, &rot, j)
            })
            .collect();
        let dev = self.model.device();
        let key_tensor = |k: usize| -> candle_core::Result<Tensor> {
            let v: Vec<f32> =
                key_poses.iter().flat_map(|p| self.norm.key_input(&p[k], &cfg.key_groups, None)).collect();
            Tensor::from_vec(v, (b, kw), dev)
        };
        let keys: Vec<Tensor> = (0..key_frames.len()).map(key_tensor).collect::<candle_core::Result<_>>()?;
        let pose_tensor = |k: usize| -> candle_core::Result<Tensor> {
            let v: Vec<f32> = key_poses.iter().flat_map(|p| self.norm.apply(&p[k])).collect();
            Tensor::from_vec(v, (b, d), dev)
        };
        let mut prev = pose_tensor(0)?;
        let mut state = self.model.zero_state(b)?;
        let mut out: Vec<Vec<Vec<f64>>> = vec![Vec::with_capacity(n); b];
        for t in 1..target {
            let (ka, kb, rel) = KeyedSequence::interval(&key_frames, t);
            let t_rel = Tensor::full(rel as f32, (b, 1), dev)?;
            let (y, s) = self.model.step(&prev, &keys[ka], &keys[kb], &t_rel, &state, None)?;
            state = s;
            if t < N_PAST {
                // A context frame: the truth is known, feed it back.
                prev = pose_tensor(t)?;
                continue;
            }
            let rows: Vec<Vec<f32>> = y.to_vec2()?;
            for (o, r) in out.iter_mut().zip(&rows) {
                o.push(self.norm.restore(r));
            }
            prev = y;
        }
        Ok(out.iter().zip(tasks).map(|(frames, task)| transition_of(frames, task)).collect())
    }
}

impl TransitionMethod for ArnnMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        let mut out: Vec<Option<Transition>> = vec![None; tasks.len()];
        let mut lengths: Vec<usize> = tasks.iter().map(|t| t.frames).collect();
        lengths.sort_unstable();
        lengths.dedup();
        for n in lengths {
            let idx: Vec<usize> = (0..tasks.len()).filter(|&i| tasks[i].frames == n).collect();
            for chunk in idx.chunks(256) {
                let group: Vec<&TransitionTask<'_>> = chunk.iter().map(|&i| &tasks[i]).collect();
                let done = self.batch(&group).map_err(|e| format!("{}: {e}", self.name))?;
                for (&i, t) in chunk.iter().zip(done) {
                    out[i] = Some(t);
                }
            }
        }
        Ok(out.into_iter().map(|t| t.unwrap_or_default()).collect())
    }
}

/// The in-betweening design (`zoo train arnn --design inbetween`) on the in-betweening
/// benchmark's transitions: the whole gap in one pass, the keys the context frames and the
/// target (`0..N_PAST` and `N_PAST + n`), every key met by construction.
pub struct InbetweenTransitions {
    name: String,
    model: crate::inbetween::Inbetween,
    norm: Normalization,
}

impl InbetweenTransitions {
    /// Loads a `zoo train arnn --design inbetween` run folder; `name` is the table's row name.
    pub fn load(dir: &Path, name: String) -> ArnnResult<Self> {
        let (model, norm) = crate::inbetween::load(dir, &Device::Cpu)?;
        Ok(InbetweenTransitions { name, model, norm })
    }

    /// The transitions of `tasks` (any lengths: the shots of one length run as one batch).
    fn all(&self, tasks: &[TransitionTask<'_>]) -> ArnnResult<Vec<Transition>> {
        let c = self.model.config();
        let j = c.joints();
        if let Some(t) = tasks.iter().find(|t| t.skeleton.names != c.skeleton.names) {
            return Err(ArnnError::Config(format!(
                "the model was trained on a skeleton of {} joints, the benchmark's has {}: use a model trained on \
                 this skeleton",
                j,
                t.skeleton.len()
            )));
        }
        let frames: Vec<Vec<usize>> =
            tasks.iter().map(|t| (0..N_PAST).chain(std::iter::once(N_PAST + t.frames)).collect()).collect();
        let key_poses: Vec<Vec<Vec<f64>>> = tasks
            .iter()
            .map(|t| {
                let mut roots = t.past_root[..N_PAST].to_vec();
                roots.push(t.target_root[0]);
                let mut rot = t.past_rot[..N_PAST * j].to_vec();
                rot.extend_from_slice(&t.target_rot[..j]);
                poses(&roots, &rot, j)
            })
            .collect();
        let shots: Vec<crate::inbetween::ShotKeyRefs<'_>> =
            frames.iter().zip(&key_poses).map(|(f, p)| (f.as_slice(), p.as_slice(), &[][..])).collect();
        let raw = crate::inbetween::complete_shots(&self.model, &self.norm, &shots)?;
        Ok(raw.iter().zip(tasks).map(|(shot, t)| transition_of(&shot[N_PAST..N_PAST + t.frames], t)).collect())
    }
}

impl TransitionMethod for InbetweenTransitions {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        let mut out = Vec::with_capacity(tasks.len());
        for chunk in tasks.chunks(256) {
            out.extend(self.all(chunk).map_err(|e| format!("{}: {e}", self.name))?);
        }
        Ok(out)
    }
}

/// A key of a humanoid completion ([`complete_clip`]).
#[derive(Clone, Debug, PartialEq)]
pub struct HumanoidKey {
    /// Frame of the completed motion (the first key is frame 0).
    pub frame: usize,
    /// Frame of the source clip holding the key's pose.
    pub source: usize,
    /// The groups the key fixes (group 0 the root position, `1 + j` joint `j`'s rotation);
    /// `None`: the whole pose.
    pub fixed: Option<Vec<bool>>,
}

/// A completed humanoid motion and how closely it meets its keys.
#[derive(Clone, Debug)]
pub struct HumanoidCompletion {
    /// The motion on the source clip's skeleton, frames `0..=last key`.
    pub clip: zoo_motion::Clip,
    /// Largest distance between a completed root and a key fixing it (clip units): 0 up to
    /// float precision, the keys being hit ([`crate::train::hit_keys`]).
    pub root_miss: f64,
    /// Largest angle between a completed joint rotation and a key fixing it (degrees), with the
    /// key's index and the joint's.
    pub angle_miss: (f64, usize, usize),
    /// [`Self::root_miss`] and [`Self::angle_miss`] of the network's own output, before the
    /// keys are hit: the network's quality figure.
    pub raw_miss: (f64, (f64, usize, usize)),
}

/// A humanoid keyframe network: the paper's autoregressive ARNN or the in-betweening design.
#[derive(Clone, Copy, Debug)]
pub enum HumanoidNet<'a> {
    /// The autoregressive ARNN.
    Arnn(&'a Arnn),
    /// The in-betweening network ([`crate::inbetween`]).
    Inbetween(&'a crate::inbetween::Inbetween),
}

impl HumanoidNet<'_> {
    /// The skeleton the network was trained on.
    pub fn skeleton(&self) -> Option<&HumanoidSkeleton> {
        match self {
            HumanoidNet::Arnn(m) => m.config().skeleton.as_ref(),
            HumanoidNet::Inbetween(m) => Some(&m.config().skeleton),
        }
    }

    /// Checks that the network was trained on `skeleton` (same joint names and parents).
    pub fn check_skeleton(&self, skeleton: &Skeleton) -> ArnnResult<()> {
        match self {
            HumanoidNet::Arnn(m) => check_skeleton(m.config(), skeleton),
            HumanoidNet::Inbetween(m) => check_trained_skeleton(&m.config().skeleton, skeleton),
        }
    }
}

/// Checks that a network trained on `trained` can complete keys on `skeleton` (same joint names
/// and parents).
pub fn check_trained_skeleton(trained: &HumanoidSkeleton, skeleton: &Skeleton) -> ArnnResult<()> {
    let info = skeleton_info(skeleton, trained.fps);
    if trained.names != info.names || trained.parents != info.parents {
        return Err(ArnnError::Config(format!(
            "the network was trained on a skeleton of {} joints, the clip has {}: use a model trained on this skeleton",
            trained.names.len(),
            info.names.len()
        )));
    }
    Ok(())
}

/// Hits the keys in completed humanoid poses ([`zoo_protocol::keyhit`], as [`crate::hit_keys`]):
/// each key frame equals its key on the groups it fixes, the frames before it blended towards it.
pub fn hit_humanoid_keys(
    names: &[String],
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
    out: &mut [Vec<f64>],
) {
    let (_, groups) = pose_layout(names);
    let d = groups.len();
    let layout =
        zoo_protocol::keyhit::KeyLayout { dofs: d, frames: key_frames, key_groups: &groups, quaternions: true };
    let poses: Vec<f64> = key_poses.iter().flatten().copied().collect();
    let mut flat: Vec<f64> = out.iter().flatten().copied().collect();
    let fixes = |k: usize, g: usize| fixed.get(k).is_none_or(|m| m.get(g).copied().unwrap_or(true));
    zoo_protocol::keyhit::hit_keys(layout, &poses, fixes, &mut flat, &mut vec![0.0; d]);
    for (o, f) in out.iter_mut().zip(flat.chunks_exact(d)) {
        o.copy_from_slice(f);
    }
}

/// The largest key misses of completed poses (`frames` from frame 0): the root distance (clip
/// units) over the keys fixing the root, and the rotation angle (degrees, with the key's and
/// the joint's index) over the keys fixing each joint. `fixed` empty: whole keys.
pub fn key_misses(
    out: &[Vec<f64>],
    key_frames: &[usize],
    key_poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
    joints: usize,
) -> (f64, (f64, usize, usize)) {
    let (mut root_miss, mut angle_miss) = (0.0f64, (0.0f64, 0, 0));
    for (i, (&f, key)) in key_frames.iter().zip(key_poses).enumerate() {
        let fixes = |g: usize| fixed.get(i).is_none_or(|m| m[g]);
        let (root, rot) = decode(&out[f], joints);
        let (key_root, key_rot) = decode(key, joints);
        if fixes(0) {
            root_miss = root_miss.max((root - key_root).length());
        }
        for j in (0..joints).filter(|&j| fixes(1 + j)) {
            let deg = (2.0 * rot[j].dot(key_rot[j]).abs().min(1.0).acos()).to_degrees();
            if deg > angle_miss.0 {
                angle_miss = (deg, i, j);
            }
        }
    }
    (root_miss, angle_miss)
}

/// Completes keys taken from the poses of `source` (a clip on the model's skeleton, read as the
/// models read clips: [`zoo_data::bvh::read_model_clip`]). The keys are brought into the frame
/// training windows are in (root x/z centred on the keys' mean, facing +X at the first key,
/// about +Y), completed, and brought back.
pub fn complete_clip(
    model: HumanoidNet<'_>,
    norm: &Normalization,
    source: &zoo_motion::Clip,
    keys: &[HumanoidKey],
) -> ArnnResult<HumanoidCompletion> {
    model.check_skeleton(&source.skeleton)?;
    complete_clip_with(source, keys, model.skeleton().map(|s| s.fps), |frames, key_poses, fixed| match model {
        HumanoidNet::Arnn(m) => crate::train::complete_partial_raw(m, norm, frames, key_poses, fixed),
        HumanoidNet::Inbetween(m) => {
            Ok(crate::inbetween::complete_shots(m, norm, &[(frames, key_poses, fixed)])?.remove(0))
        }
    })
}

/// [`complete_clip`] with any network: `net` completes keys in the canonical frame (key frames
/// from 0, one pose per key, partial-key flags per key and group or none) into poses of frames
/// `0..=last key` without hitting them; `fps` is the frame rate the network was trained at
/// (the clip's is refused when it differs by more than 1 %). The clip's skeleton is checked by
/// the caller.
pub fn complete_clip_with(
    source: &zoo_motion::Clip,
    keys: &[HumanoidKey],
    fps: Option<f64>,
    net: impl FnOnce(&[usize], &[Vec<f64>], &[Vec<bool>]) -> ArnnResult<Vec<Vec<f64>>>,
) -> ArnnResult<HumanoidCompletion> {
    let j = source.skeleton.len();
    let n = source.frames();
    if let Some((i, k)) = keys.iter().enumerate().find(|(_, k)| k.source >= n) {
        return Err(ArnnError::Config(format!(
            "key {i} takes frame {} of a clip of {n} frames (0 to {})",
            k.source,
            n.saturating_sub(1)
        )));
    }
    if keys.is_empty() {
        return Err(ArnnError::Config("no key given".into()));
    }
    let groups = 1 + j;
    if let Some(trained) = fps {
        let fps = 1.0 / source.frame_time;
        if (fps / trained - 1.0).abs() > 0.01 {
            return Err(ArnnError::Config(format!(
                "the clip is at {fps:.3} fps, the model was trained at {trained} fps: resample the clip to {trained} fps"
            )));
        }
    }
    // The canonical frame: centre (over the keys that fix the root) and facing as training
    // windows are prepared; the facing is the first key's (training windows face +X at their
    // frame 9, where the benchmark's context ends).
    let roots: Vec<DVec3> = keys.iter().map(|k| source.local_positions[k.source * j]).collect();
    let fixing: Vec<DVec3> =
        keys.iter().zip(&roots).filter(|(k, _)| k.fixed.as_ref().is_none_or(|f| f[0])).map(|(_, r)| *r).collect();
    let centre = fixing.iter().fold(DVec3::ZERO, |a, r| a + *r) / fixing.len().max(1) as f64;
    let centre = DVec3::new(centre.x, 0.0, centre.z);
    let fwd = source.local_rotations[keys[0].source * j] * WINDOW.forward_axis;
    let fwd = DVec3::new(fwd.x, 0.0, fwd.z);
    let fwd = if fwd.length_squared() > 1e-12 { fwd.normalize() } else { DVec3::X };
    let to_canon = zoo_motion::facing::yaw_between(DVec3::X, fwd).inverse();
    let mut rot = Vec::with_capacity(keys.len() * j);
    let mut canon_roots = Vec::with_capacity(keys.len());
    for (k, r) in keys.iter().zip(&roots) {
        let frame = &source.local_rotations[k.source * j..(k.source + 1) * j];
        rot.push(to_canon * frame[0]);
        rot.extend_from_slice(&frame[1..]);
        canon_roots.push(to_canon * (*r - centre));
    }
    let key_poses = poses(&canon_roots, &rot, j);
    let frames: Vec<usize> = keys.iter().map(|k| k.frame).collect();
    let fixed: Vec<Vec<bool>> = if keys.iter().all(|k| k.fixed.is_none()) {
        vec![]
    } else {
        keys.iter().map(|k| k.fixed.clone().unwrap_or_else(|| vec![true; groups])).collect()
    };
    let mut out = net(&frames, &key_poses, &fixed)?;
    let raw_miss = key_misses(&out, &frames, &key_poses, &fixed, j);
    hit_humanoid_keys(&source.skeleton.names, &frames, &key_poses, &fixed, &mut out);
    let (root_miss, angle_miss) = key_misses(&out, &frames, &key_poses, &fixed, j);
    // Back to the clip's frame; rotation signs continuous from the first key's.
    let from_canon = to_canon.inverse();
    let mut clip = zoo_motion::Clip {
        skeleton: source.skeleton.clone(),
        frame_time: source.frame_time,
        local_rotations: Vec::with_capacity(out.len() * j),
        local_positions: Vec::with_capacity(out.len() * j),
    };
    let mut last = source.local_rotations[keys[0].source * j..(keys[0].source + 1) * j].to_vec();
    for p in &out {
        let (root, mut r) = decode(p, j);
        r[0] = from_canon * r[0];
        continue_signs(&mut r, &mut last);
        clip.local_rotations.extend(r);
        clip.local_positions.push(from_canon * root + centre);
        clip.local_positions.extend_from_slice(&source.skeleton.offsets[1..]);
    }
    Ok(HumanoidCompletion { clip, root_miss, angle_miss, raw_miss })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_keep_one_hemisphere_and_decode_back() {
        let joints = 2;
        let q = |a: f64| DQuat::from_rotation_y(a);
        // Joint 1 rotates through 180 degrees and beyond: the sign must not jump.
        let rot: Vec<DQuat> = (0..8).flat_map(|f| [q(0.1 * f as f64), -q(0.5 * f as f64)]).collect();
        let root: Vec<DVec3> = (0..8).map(|f| DVec3::new(f as f64, 90.0, 0.0)).collect();
        let p = poses(&root, &rot, joints);
        assert_eq!(p.len(), 8);
        assert!(p.iter().all(|v| v.len() == 3 + 4 * joints));
        for w in p.windows(2) {
            let dot: f64 = (0..4).map(|c| w[0][7 + c] * w[1][7 + c]).sum();
            assert!(dot > 0.0, "sign flip between frames");
        }
        assert!(p[0][3] >= 0.0 && p[0][7] >= 0.0);
        for (f, v) in p.iter().enumerate() {
            let (r, qs) = decode(v, joints);
            assert_eq!(r, root[f]);
            for (a, b) in qs.iter().zip(&rot[f * joints..(f + 1) * joints]) {
                assert!(a.dot(*b).abs() > 1.0 - 1e-12, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn layout_groups_the_root_and_each_joint() {
        let (names, groups) = pose_layout(&["Hips".to_string(), "Spine".to_string()]);
        assert_eq!(names.len(), 11);
        assert_eq!(names[3], "Hips_qw");
        assert_eq!(groups, vec![0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2]);
    }
}
