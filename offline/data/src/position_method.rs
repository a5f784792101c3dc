//! Benchmark methods backed by models that generate global joint positions (RTN through candle,
//! the exported RTN through the engine runtime, ...): the model is given the global positions
//! of the context frames, of the target frame and of the one after it; joint rotations are
//! fitted to what it generates (`BENCHMARK.md`), with twist from the interpolation of the
//! context and target rotations, and optionally foot-locked. The fit and the foot lock are
//! those of [`zoo_protocol::pipeline`], shared with `zoo transition` and the engine.

use crate::benchmark::{self, N_PAST, Transition, TransitionMethod, TransitionTask};
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use zoo_protocol::pipeline::{fit_frames, foot_lock_fitted, skeleton_positions_f32};

/// A model generating a transition as global joint positions (`f32`, frame-major,
/// `3 * joints` per frame, Y up, clip units).
pub trait PositionGenerator: Sync {
    /// Per-thread working state (a runtime runner, ...; `()` when none is needed).
    type Scratch;
    /// Number of joints the model was made for.
    fn joints(&self) -> usize;
    /// A fresh working state for one thread.
    fn scratch(&self) -> Result<Self::Scratch, String>;
    /// Generates `frames` transition frames and the predicted target frame
    /// (`(frames + 1) * 3 * joints` values) from [`N_PAST`] context frames (`past`), the target
    /// frame and the frame after it.
    fn generate(
        &self,
        scratch: &mut Self::Scratch,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        frames: usize,
    ) -> Result<Vec<f32>, String>;
}

/// A [`TransitionMethod`] from a [`PositionGenerator`]: `rtn:DIR`, `onnx:FILE`, and with the
/// foot lock `rtn+lock:DIR`, `onnx+lock:FILE`.
pub struct PositionMethod<G> {
    name: String,
    /// Foot-lock post-process ([`foot_lock_fitted`]).
    pub foot_lock: bool,
    /// The model.
    pub generator: G,
}

impl<G: PositionGenerator> PositionMethod<G> {
    /// A method named `name` (its row in the table).
    pub fn new(name: String, generator: G, foot_lock: bool) -> Self {
        PositionMethod { name, foot_lock, generator }
    }
}

impl<G: PositionGenerator> TransitionMethod for PositionMethod<G> {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        let k = self.generator.joints();
        tasks
            .par_iter()
            .map_init(
                || self.generator.scratch(),
                |scratch, t| {
                    let scratch = scratch.as_mut().map_err(|e| format!("{}: {e}", self.name))?;
                    let j = t.skeleton.len();
                    if j != k {
                        return Err(format!("{}: the model was made for {k} joints, the data has {j}", self.name));
                    }
                    let (past, tgt) = task_positions(t);
                    let d = 3 * j;
                    let y = self
                        .generator
                        .generate(scratch, &past, &tgt[..d], &tgt[d..2 * d], t.frames)
                        .map_err(|e| format!("{}: {e}", self.name))?;
                    Ok(fit_transition(t, &past[past.len() - d..], &y, self.foot_lock))
                },
            )
            .collect()
    }
}

/// Global positions (`f32`, joint-major xyz) of frames of a task's skeleton given local
/// rotations and root positions, with the task's offsets for joints `1..`.
pub fn global_positions_f32(task: &TransitionTask<'_>, rot: &[DQuat], roots: &[DVec3], out: &mut Vec<f32>) {
    let mut offsets = vec![DVec3::ZERO; task.skeleton.len()];
    offsets[1..].copy_from_slice(task.offsets);
    skeleton_positions_f32(task.skeleton, &offsets, rot, roots, out);
}

/// Global positions of a task's context frames, and of its target frame and the one after it:
/// what a position-based method is given.
pub fn task_positions(t: &TransitionTask<'_>) -> (Vec<f32>, Vec<f32>) {
    let (mut past, mut target) = (Vec::new(), Vec::new());
    global_positions_f32(t, t.past_rot, &t.past_root[..N_PAST], &mut past);
    global_positions_f32(t, t.target_rot, t.target_root, &mut target);
    (past, target)
}

/// A benchmark transition from generated global positions (`(frames + 1) * 3K`: the transition
/// and the target frame): joint rotations fitted to them with twist from the interpolation of
/// the context and target rotations; the generated positions are kept as the raw output.
///
/// With `foot_lock`, the fit is foot-locked ([`foot_lock_fitted`], after the last context
/// frame `prev`).
pub fn fit_transition(t: &TransitionTask<'_>, prev: &[f32], y: &[f32], foot_lock: bool) -> Transition {
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

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::{EulerOrder, JointChannels, Skeleton};

    /// Generates the straight line from the last context frame to the target.
    struct Line(usize);

    impl PositionGenerator for Line {
        type Scratch = ();
        fn joints(&self) -> usize {
            self.0
        }
        fn scratch(&self) -> Result<(), String> {
            Ok(())
        }
        fn generate(
            &self,
            _: &mut (),
            past: &[f32],
            target: &[f32],
            _: &[f32],
            frames: usize,
        ) -> Result<Vec<f32>, String> {
            let last = &past[past.len() - target.len()..];
            Ok((1..=frames + 1)
                .flat_map(|k| {
                    let w = k as f32 / (frames + 1) as f32;
                    last.iter().zip(target).map(move |(a, b)| a + w * (b - a))
                })
                .collect())
        }
    }

    fn skeleton() -> Skeleton {
        Skeleton {
            names: vec!["Hips".into(), "Spine".into()],
            parents: vec![None, Some(0)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, 10.0, 0.0)],
            end_sites: vec![None, None],
            channels: vec![JointChannels { position: true, order: EulerOrder::Zxy }; 2],
        }
    }

    #[test]
    fn generated_positions_are_fitted_and_kept_raw() {
        let s = skeleton();
        let offsets = [DVec3::new(0.0, 10.0, 0.0)];
        let past_rot = vec![DQuat::IDENTITY; N_PAST * 2];
        let past_root: Vec<DVec3> = (0..N_PAST).map(|f| DVec3::new(f as f64, 90.0, 0.0)).collect();
        let target_rot = vec![DQuat::IDENTITY; 4];
        let target_root = [DVec3::new(20.0, 90.0, 0.0), DVec3::new(21.0, 90.0, 0.0)];
        let task = TransitionTask {
            skeleton: &s,
            offsets: &offsets,
            past_rot: &past_rot,
            past_root: &past_root,
            target_rot: &target_rot,
            target_root: &target_root,
            frames: 10,
        };
        let m = PositionMethod::new("line".into(), Line(2), false);
        let out = m.generate(&[task]).unwrap();
        assert_eq!(out[0].root.len(), 10);
        assert!(
            (out[0].root[4] - DVec3::new(9.0 + 11.0 * 5.0 / 11.0, 90.0, 0.0)).length() < 1e-4,
            "{:?}",
            out[0].root[4]
        );
        assert!(out[0].rot.iter().all(|q| q.angle_between(DQuat::IDENTITY) < 1e-4));
        assert_eq!(out[0].raw_positions.as_ref().unwrap().len(), 20);
        let e = PositionMethod::new("line".into(), Line(3), false).generate(&[task]).err().unwrap();
        assert_eq!(e, "line: the model was made for 3 joints, the data has 2");
    }
}
