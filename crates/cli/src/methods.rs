//! Transition methods backed by trained models, for `zoo bench --methods ...`.

use anyhow::Context;
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use std::path::Path;
use zoo_data::benchmark::{self, N_PAST, Transition, TransitionMethod, TransitionTask};
use zoo_motion::features::FeatureStats;
use zoo_motion::fit::fit_rotations;
use zoo_motion::fk::forward_kinematics_frame;
use zoo_rtn::Rtn;

/// RTN (`rtn:DIR`): generates joint positions from the past frames, the target and the frame
/// after it, then fits joint rotations to them (`BENCHMARK.md`), with twist from the
/// interpolation of the context and target rotations.
pub struct RtnMethod {
    name: String,
    /// Foot-lock post-process (`rtn+lock:DIR`).
    pub foot_lock: bool,
    model: Rtn,
    stats: FeatureStats,
}

impl RtnMethod {
    /// Loads a run folder written by `zoo train rtn`.
    pub fn load(dir: &Path, name: String) -> anyhow::Result<Self> {
        let (model, stats) = zoo_rtn::checkpoint::load(dir, &candle_core::Device::Cpu)
            .with_context(|| format!("loading the RTN in {}", dir.display()))?;
        Ok(RtnMethod { name, foot_lock: false, model, stats })
    }
}

/// Global positions (f32, joint-major xyz) of frames given local rotations and root positions,
/// with `offsets` for joints `1..`.
pub fn global_positions_f32(task: &TransitionTask<'_>, rot: &[DQuat], roots: &[DVec3], out: &mut Vec<f32>) {
    let mut offsets = vec![DVec3::ZERO; task.skeleton.len()];
    offsets[1..].copy_from_slice(task.offsets);
    skeleton_positions_f32(task.skeleton, &offsets, rot, roots, out);
}

/// Global positions (f32, joint-major xyz) of frames of `skeleton` given local rotations, root
/// positions and the local `offsets` of every joint (the root's is ignored).
fn skeleton_positions_f32(
    skeleton: &zoo_motion::Skeleton,
    offsets: &[DVec3],
    rot: &[DQuat],
    roots: &[DVec3],
    out: &mut Vec<f32>,
) {
    let j = skeleton.len();
    let mut lp = offsets.to_vec();
    let (mut gr, mut gp) = (vec![DQuat::IDENTITY; j], vec![DVec3::ZERO; j]);
    for (f, root) in roots.iter().enumerate() {
        lp[0] = *root;
        forward_kinematics_frame(&skeleton.parents, &rot[f * j..(f + 1) * j], &lp, &mut gr, &mut gp);
        out.extend(gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]));
    }
}

/// Foot-locks a fitted transition ([`zoo_motion::footlock`] with the skeleton's defaults): the
/// fitted skeleton's own joint positions, after the last context frame `prev` and followed by
/// the `target` frame, are locked and fitted again. Locking the skeleton's positions (exact bone
/// lengths) rather than the network's makes the refit reproduce the locked feet exactly. A
/// skeleton without joints named `foot` is returned unchanged.
pub fn foot_lock_fitted(
    skeleton: &zoo_motion::Skeleton,
    offsets: &[DVec3],
    fitted: (Vec<DQuat>, Vec<DVec3>),
    prev: &[f32],
    target: &[f32],
    reference: &[DQuat],
) -> (Vec<DQuat>, Vec<DVec3>) {
    let Some(lock) = zoo_motion::footlock::FootLock::from_skeleton(&skeleton.names, &skeleton.parents) else {
        return fitted;
    };
    let (rot, root) = fitted;
    let mut positions = Vec::with_capacity((root.len() + 1) * target.len());
    skeleton_positions_f32(skeleton, offsets, &rot, &root, &mut positions);
    let n = positions.len();
    positions.extend_from_slice(target);
    lock.apply(prev, &mut positions);
    fit_frames(skeleton, offsets, &positions[..n], reference)
}

/// Global positions of a task's context frames and of its target frame and the one after it:
/// what a position-based method is given.
fn task_positions(t: &TransitionTask<'_>) -> (Vec<f32>, Vec<f32>) {
    let (mut past, mut target) = (Vec::new(), Vec::new());
    global_positions_f32(t, t.past_rot, &t.past_root[..N_PAST], &mut past);
    global_positions_f32(t, t.target_rot, t.target_root, &mut target);
    (past, target)
}

impl TransitionMethod for RtnMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        tasks
            .par_iter()
            .map(|t| {
                let j = t.skeleton.len();
                if j != self.model.config().joints {
                    return Err(format!(
                        "{}: the model was trained on {} joints, the data has {j}",
                        self.name,
                        self.model.config().joints
                    ));
                }
                let (past, tgt) = task_positions(t);
                let d = 3 * j;
                let y = self
                    .model
                    .transition(&self.stats, &past, &tgt[..d], &tgt[d..2 * d], t.frames, None)
                    .map_err(|e| e.to_string())?;
                Ok(fit_transition(t, &past[past.len() - d..], &y, self.foot_lock))
            })
            .collect()
    }
}

/// The exported RTN run through the engine runtime (`onnx:FILE.onnx`, `zoo-runtime` on
/// tract): the same inputs and post-processing as `rtn:DIR`.
pub struct OnnxMethod {
    name: String,
    /// Foot-lock post-process (`onnx+lock:FILE`).
    pub foot_lock: bool,
    model: zoo_runtime::TransitionModel,
}

impl OnnxMethod {
    /// Loads a file written by `zoo export --onnx`.
    pub fn load(path: &Path, name: String) -> anyhow::Result<Self> {
        let model = zoo_runtime::TransitionModel::load(path)
            .with_context(|| format!("loading the exported RTN {}", path.display()))?;
        Ok(OnnxMethod { name, foot_lock: false, model })
    }
}

impl TransitionMethod for OnnxMethod {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        let k = self.model.joints();
        tasks
            .par_iter()
            .map_init(
                || self.model.runner().map(|r| (r, self.model.new_transition())),
                |runner, t| {
                    let (runner, state) = runner.as_mut().map_err(|e| e.to_string())?;
                    let j = t.skeleton.len();
                    if j != k {
                        return Err(format!("{}: the model was exported for {k} joints, the data has {j}", self.name));
                    }
                    let (past, tgt) = task_positions(t);
                    let d = 3 * j;
                    let mut y = vec![0.0; (t.frames + 1) * d];
                    runner
                        .generate(state, &past, &tgt[..d], &tgt[d..2 * d], &mut y)
                        .map_err(|e| format!("{}: {e}", self.name))?;
                    Ok(fit_transition(t, &past[past.len() - d..], &y, self.foot_lock))
                },
            )
            .collect()
    }
}

/// A benchmark transition from generated global positions (`(frames + 1) * 3K`: the transition
/// and the target frame): joint rotations fitted to them with twist from the interpolation of
/// the context and target rotations; the network's positions are kept as the raw output.
///
/// With `foot_lock`, the fit is foot-locked ([`foot_lock_fitted`], after the last context
/// frame `prev`).
fn fit_transition(t: &TransitionTask<'_>, prev: &[f32], y: &[f32], foot_lock: bool) -> Transition {
    let j = t.skeleton.len();
    let d = 3 * j;
    let interp = benchmark::interpolate(t);
    let reference = &interp.rot[..t.frames * j];
    let mut offsets = vec![DVec3::ZERO; j];
    offsets[1..].copy_from_slice(t.offsets);
    let mut fitted = fit_frames(t.skeleton, &offsets, &y[..t.frames * d], reference);
    if foot_lock {
        let target = &y[t.frames * d..(t.frames + 1) * d];
        fitted = foot_lock_fitted(t.skeleton, &offsets, fitted, prev, target, reference);
    }
    let (rot, root) = fitted;
    let raw = y[..t.frames * d].chunks_exact(3).map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)).collect();
    Transition { root, rot, raw_positions: Some(raw) }
}

/// Global joint positions (f32, `frames * joints * 3`) of clip frames `from..to`.
pub fn clip_positions_f32(clip: &zoo_motion::Clip, from: usize, to: usize) -> Vec<f32> {
    let (_, gp) = clip.slice(from, to).global();
    gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()
}

/// Local rotations and root positions fitted to generated global positions
/// (`frames * joints * 3`), twist taken from `reference` (local rotations, frames x joints).
pub fn fit_frames(
    skeleton: &zoo_motion::Skeleton,
    offsets: &[DVec3],
    positions: &[f32],
    reference: &[DQuat],
) -> (Vec<DQuat>, Vec<DVec3>) {
    let j = skeleton.len();
    let frames = positions.len() / (3 * j);
    let mut rot = vec![DQuat::IDENTITY; frames * j];
    let mut root = Vec::with_capacity(frames);
    for f in 0..frames {
        let pos: Vec<DVec3> = positions[f * 3 * j..(f + 1) * 3 * j]
            .chunks_exact(3)
            .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .collect();
        fit_rotations(&skeleton.parents, offsets, &pos, &reference[f * j..(f + 1) * j], &mut rot[f * j..(f + 1) * j]);
        root.push(pos[0]);
    }
    (rot, root)
}
