//! Transitions (RTN): from context frames to a target, in global positions or engine poses,
//! for one character or a batch.

use crate::arrays::{Dim, PoseArrays, array, poses_from_world, values};
use crate::error::OrPy;
use numpy::{PyArrayDyn, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Mutex;
use zoo_runtime::{EnginePose, MotionError, TransitionModel, TransitionRunner};

/// A loaded transition model and the scratch space of the thread that runs it.
#[pyclass(module = "zoo._native", name = "Transition")]
pub struct Transition {
    model: TransitionModel,
    runner: Mutex<TransitionRunner>,
}

impl Transition {
    /// Wraps a loaded model.
    pub fn new(model: TransitionModel) -> Result<Self, MotionError> {
        let runner = model.runner()?;
        Ok(Transition { model, runner: Mutex::new(runner) })
    }

    fn runner(&self) -> std::sync::MutexGuard<'_, TransitionRunner> {
        self.runner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Sets a call's post-processes on its runner (nothing carries over to the next call): the
    /// model's calibrated fallback and the model's default foot lock, each when asked.
    fn set_post(&self, runner: &mut TransitionRunner, foot_lock: bool, fallback: bool) {
        runner.set_foot_lock(if foot_lock { self.model.default_foot_lock() } else { None });
        if fallback {
            runner.set_model_fallback();
        } else {
            runner.set_fallback(None);
        }
    }

    /// The transition length of a call: `frames`, or the trained length.
    fn length(&self, frames: Option<usize>) -> usize {
        frames.unwrap_or(self.model.transition_frames())
    }
}

#[pymethods]
impl Transition {
    /// The model's metadata (see `info::metadata_dict`).
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::info::metadata_dict(py, self.model.model().metadata())
    }

    /// Context frames the model was trained with.
    #[getter]
    fn past_frames(&self) -> usize {
        self.model.past_frames()
    }

    /// Transition length the model was trained on, frames.
    #[getter]
    fn transition_frames(&self) -> usize {
        self.model.transition_frames()
    }

    /// Frames of the target blend (RTN eq. 15-16).
    #[getter]
    fn target_blend(&self) -> usize {
        self.model.target_blend()
    }

    /// Joints of the skeleton.
    #[getter]
    fn joints(&self) -> usize {
        self.model.joints()
    }

    /// Whether the model is terrain-aware (it then needs a heightmap, which this package does
    /// not pass yet).
    #[getter]
    fn terrain(&self) -> bool {
        self.model.terrain().is_some()
    }

    /// A transition of `N` characters in global positions: `past` `(N, P, K, 3)`, `target`
    /// and `next` `(N, K, 3)`; returns `(N, L + 1, K, 3)`, the last frame the target. Every
    /// setting is the call's own (the runner is set afresh each call, nothing carries over to the
    /// next); the defaults are `zoo transition`'s: the model's calibrated fallback on, the foot
    /// lock off.
    #[pyo3(signature = (past, target, next, frames=None, allow_beyond_trained=false, foot_lock=false, fallback=true))]
    #[allow(clippy::too_many_arguments)]
    fn positions<'py>(
        &self,
        py: Python<'py>,
        past: PyReadonlyArrayDyn<'py, f32>,
        target: PyReadonlyArrayDyn<'py, f32>,
        next: PyReadonlyArrayDyn<'py, f32>,
        frames: Option<usize>,
        allow_beyond_trained: bool,
        foot_lock: bool,
        fallback: bool,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let k = self.model.joints();
        let (past, pd) = values("past", &past, &[("N", None), ("P", None), ("K", Some(k)), ("", Some(3))])?;
        let n = pd[0];
        let pose: [Dim; 3] = [("N", Some(n)), ("K", Some(k)), ("", Some(3))];
        let (target, _) = values("target", &target, &pose)?;
        let (next, _) = values("next", &next, &pose)?;
        let length = self.length(frames);
        let mut out = vec![0.0f32; n * (length + 1) * 3 * k];
        let mut states: Vec<_> = (0..n).map(|_| self.model.new_transition()).collect();
        let mut runner = self.runner();
        runner.allow_beyond_trained(allow_beyond_trained);
        self.set_post(&mut runner, foot_lock, fallback);
        runner.generate_batch(&mut states, past, target, next, &mut out).or_py()?;
        drop(runner);
        array(py, out, &[n, length + 1, k, 3])
    }

    /// A transition of `N` characters in engine poses: the context `(N, P)` poses, the target
    /// and the pose after it `(N,)`, each given as BVH-style arrays (`*_hips` the hips' world
    /// positions, `*_rotations` the hips' world rotation then every other joint's local
    /// rotation, `(x, y, z, w)`). Returns the fields of `zoo.Poses` with shape prefix
    /// `(N, L + 1)`: root motion, local rotations fitted to the network's positions, and the
    /// global positions of those rotations (the skeleton's bone lengths). The fallback and the
    /// foot lock as in `positions` (and `zoo transition --in-place`).
    #[pyo3(signature = (past_hips, past_rotations, target_hips, target_rotations, next_hips, next_rotations, frames=None, allow_beyond_trained=false, foot_lock=false, fallback=true))]
    #[allow(clippy::too_many_arguments)]
    fn poses<'py>(
        &self,
        py: Python<'py>,
        past_hips: PyReadonlyArrayDyn<'py, f32>,
        past_rotations: PyReadonlyArrayDyn<'py, f32>,
        target_hips: PyReadonlyArrayDyn<'py, f32>,
        target_rotations: PyReadonlyArrayDyn<'py, f32>,
        next_hips: PyReadonlyArrayDyn<'py, f32>,
        next_rotations: PyReadonlyArrayDyn<'py, f32>,
        frames: Option<usize>,
        allow_beyond_trained: bool,
        foot_lock: bool,
        fallback: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let k = self.model.joints();
        let (ph, pd) = values("past_hips", &past_hips, &[("N", None), ("P", None), ("", Some(3))])?;
        let (n, p) = (pd[0], pd[1]);
        let (pr, _) = values(
            "past_rotations",
            &past_rotations,
            &[("N", Some(n)), ("P", Some(p)), ("K", Some(k)), ("", Some(4))],
        )?;
        let hips: [Dim; 2] = [("N", Some(n)), ("", Some(3))];
        let rots: [Dim; 3] = [("N", Some(n)), ("K", Some(k)), ("", Some(4))];
        let (th, _) = values("target_hips", &target_hips, &hips)?;
        let (tr, _) = values("target_rotations", &target_rotations, &rots)?;
        let (nh, _) = values("next_hips", &next_hips, &hips)?;
        let (nr, _) = values("next_rotations", &next_rotations, &rots)?;
        let past = poses_from_world("past_rotations", ph, pr, n * p, k)?;
        let target = poses_from_world("target_rotations", th, tr, n, k)?;
        let next = poses_from_world("next_rotations", nh, nr, n, k)?;
        let length = self.length(frames);
        let mut states: Vec<_> = (0..n).map(|_| self.model.new_transition()).collect();
        let mut poses: Vec<EnginePose> = (0..n * (length + 1)).map(|_| EnginePose::with_global_positions(k)).collect();
        let mut out = PoseArrays::new(k, n * (length + 1));
        let mut runner = self.runner();
        runner.allow_beyond_trained(allow_beyond_trained);
        self.set_post(&mut runner, foot_lock, fallback);
        runner.generate_posed_batch(&mut states, &past, &target, &next, length, &mut poses).or_py()?;
        drop(runner);
        for pose in &poses {
            out.push(pose);
        }
        out.into_dict(py, &[n, length + 1])
    }
}
