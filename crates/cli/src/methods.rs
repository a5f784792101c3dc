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
    model: Rtn,
    stats: FeatureStats,
}

impl RtnMethod {
    /// Loads a run folder written by `zoo train rtn`.
    pub fn load(dir: &Path, name: String) -> anyhow::Result<Self> {
        let (model, stats) = zoo_rtn::checkpoint::load(dir, &candle_core::Device::Cpu)
            .with_context(|| format!("loading the RTN in {}", dir.display()))?;
        Ok(RtnMethod { name, model, stats })
    }
}

/// Global positions (f32, joint-major xyz) of frames given local rotations and root positions,
/// with `offsets` for joints `1..`.
pub fn global_positions_f32(task: &TransitionTask<'_>, rot: &[DQuat], roots: &[DVec3], out: &mut Vec<f32>) {
    let j = task.skeleton.len();
    let mut lp = vec![DVec3::ZERO; j];
    lp[1..].copy_from_slice(task.offsets);
    let (mut gr, mut gp) = (vec![DQuat::IDENTITY; j], vec![DVec3::ZERO; j]);
    for (f, root) in roots.iter().enumerate() {
        lp[0] = *root;
        forward_kinematics_frame(&task.skeleton.parents, &rot[f * j..(f + 1) * j], &lp, &mut gr, &mut gp);
        out.extend(gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]));
    }
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
                let (mut past, mut tgt) = (Vec::new(), Vec::new());
                global_positions_f32(t, t.past_rot, &t.past_root[..N_PAST], &mut past);
                global_positions_f32(t, t.target_rot, t.target_root, &mut tgt);
                let d = 3 * j;
                let y = self
                    .model
                    .transition(&self.stats, &past, &tgt[..d], &tgt[d..2 * d], t.frames, None)
                    .map_err(|e| e.to_string())?;
                let interp = benchmark::interpolate(t);
                let mut offsets = vec![DVec3::ZERO; j];
                offsets[1..].copy_from_slice(t.offsets);
                let mut raw = Vec::with_capacity(t.frames * j);
                let mut rot = vec![DQuat::IDENTITY; t.frames * j];
                let mut root = Vec::with_capacity(t.frames);
                for f in 0..t.frames {
                    let pos: Vec<DVec3> = y[f * d..(f + 1) * d]
                        .chunks_exact(3)
                        .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
                        .collect();
                    fit_rotations(
                        &t.skeleton.parents,
                        &offsets,
                        &pos,
                        &interp.rot[f * j..(f + 1) * j],
                        &mut rot[f * j..(f + 1) * j],
                    );
                    root.push(pos[0]);
                    raw.extend_from_slice(&pos);
                }
                Ok(Transition { root, rot, raw_positions: Some(raw) })
            })
            .collect()
    }
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
