//! Keyframe completion (ARNN): raw pose vectors, and humanoid keys given as BVH-style poses
//! (the canonical frame the humanoid ARNN was trained in is handled here).

use crate::arrays::{Array, array, values};
use crate::error::{OrPy, shape};
use glam::{DQuat, DVec3};
use numpy::{PyArrayDyn, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Mutex;
use zoo_motion::facing::yaw_between;
use zoo_runtime::{KeyframeModel, KeyframeRunner, MotionError, MotionKeys};

/// The forward axis of the hips in the humanoid ARNN's training windows
/// (`zoo_arnn::humanoid::WINDOW.forward_axis`).
const HIPS_FORWARD: DVec3 = DVec3::Y;

/// A loaded keyframe model and its runner.
#[pyclass(module = "zoo._native", name = "Keyframes")]
pub struct Keyframes {
    model: KeyframeModel,
    runner: Mutex<KeyframeRunner>,
}

impl Keyframes {
    /// Wraps a loaded model.
    pub fn new(model: KeyframeModel) -> Result<Self, MotionError> {
        let runner = model.runner(1)?;
        Ok(Keyframes { model, runner: Mutex::new(runner) })
    }

    fn joints(&self) -> usize {
        self.model.metadata().skeleton.len()
    }

    /// Whether the pose vector is the humanoid one (`zoo_arnn::humanoid`): the root position,
    /// then a `(w, x, y, z)` quaternion per joint of the skeleton, one key group per joint.
    fn is_humanoid(&self) -> bool {
        let k = self.joints();
        k > 0 && self.model.dofs() == 3 + 4 * k && self.model.groups() == 1 + k
    }

    /// Checked key frames (integers, strictly increasing) relative to the first.
    fn key_frames(frames: &PyReadonlyArrayDyn<'_, i64>) -> PyResult<Vec<usize>> {
        crate::arrays::check_shape("frames", frames.shape(), &[("n", None)])?;
        let f = frames.as_slice().map_err(|_| shape("`frames` must be a contiguous int64 array"))?;
        let first = f[0];
        if f.windows(2).any(|w| w[0] >= w[1]) {
            return Err(shape(format!("key frames {f:?} must strictly increase")));
        }
        Ok(f.iter().map(|v| (v - first) as usize).collect())
    }

    /// Runs the completion of one character's keys.
    fn run(&self, frames: &[usize], poses: &[f32], fixed: &[f32]) -> PyResult<Vec<f32>> {
        let keys = MotionKeys { frames, poses, fixed };
        let mut out = vec![0.0f32; keys.len() * self.model.dofs()];
        let mut runner = self.runner.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        runner.complete(keys, &mut out).or_py()?;
        Ok(out)
    }
}

/// Appends a pose vector (root, then `(w, x, y, z)` per joint), each quaternion's sign chosen
/// nearest to `prev` (the previous key's pose vector), the first with `w >= 0`
/// (`zoo_arnn::humanoid::poses`).
fn push_pose(root: DVec3, rot: &[DQuat], prev: Option<&[f32]>, out: &mut Vec<f32>) {
    out.extend([root.x as f32, root.y as f32, root.z as f32]);
    for (j, q) in rot.iter().enumerate() {
        let mut v = [q.w, q.x, q.y, q.z];
        let flip = match prev {
            Some(p) => v.iter().zip(&p[3 + 4 * j..7 + 4 * j]).map(|(a, b)| a * *b as f64).sum::<f64>() < 0.0,
            None => q.w < 0.0,
        };
        if flip {
            v = v.map(|x| -x);
        }
        out.extend(v.map(|x| x as f32));
    }
}

#[pymethods]
impl Keyframes {
    /// The model's metadata.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::info::metadata_dict(py, self.model.metadata())
    }

    /// Values per pose vector.
    #[getter]
    fn dofs(&self) -> usize {
        self.model.dofs()
    }

    /// Key groups a partial key can fix or leave free (0: whole keys only).
    #[getter]
    fn groups(&self) -> usize {
        self.model.groups()
    }

    /// Whether the model completes humanoid poses of its skeleton (else raw pose vectors, e.g.
    /// the lamp's 6 values).
    #[getter]
    fn humanoid(&self) -> bool {
        self.is_humanoid()
    }

    /// Completes keys given as raw pose vectors: `frames` `(n,)` int64 strictly increasing,
    /// `poses` `(n, D)`, `fixed` `(n, G)` 0/1 flags or `None` (whole keys). Returns
    /// `(frames[-1] - frames[0] + 1, D)`.
    #[pyo3(signature = (frames, poses, fixed=None))]
    fn complete<'py>(
        &self,
        py: Python<'py>,
        frames: PyReadonlyArrayDyn<'py, i64>,
        poses: PyReadonlyArrayDyn<'py, f32>,
        fixed: Option<PyReadonlyArrayDyn<'py, f32>>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let f = Self::key_frames(&frames)?;
        let (d, g) = (self.model.dofs(), self.model.groups());
        let (poses, _) = values("poses", &poses, &[("n", Some(f.len())), ("D", Some(d))])?;
        let fixed = match &fixed {
            Some(a) => values("fixed", a, &[("n", Some(f.len())), ("G", Some(g))])?.0.to_vec(),
            None => Vec::new(),
        };
        let out = self.run(&f, poses, &fixed)?;
        let t = f.last().copied().unwrap_or(0) + 1;
        array(py, out, &[t, d])
    }

    /// Completes humanoid keys given as BVH-style poses of the model's skeleton: `frames`
    /// `(n,)`, `hips` `(n, 3)` world positions, `rotations` `(n, K, 4)` (the hips' world
    /// rotation, then local rotations, `(x, y, z, w)`), `fixed` `(n, 1 + K)` flags or `None`.
    /// The keys are put in the canonical frame of training (centred on the keys' roots, facing
    /// +X at the first key), completed, and put back, as `zoo complete` does
    /// (`zoo_arnn::humanoid::complete_clip`). Returns `(hips, rotations)` for every frame from
    /// the first key to the last, rotations continuous from the first key's signs.
    #[pyo3(signature = (frames, hips, rotations, fixed=None))]
    fn complete_poses<'py>(
        &self,
        py: Python<'py>,
        frames: PyReadonlyArrayDyn<'py, i64>,
        hips: PyReadonlyArrayDyn<'py, f32>,
        rotations: PyReadonlyArrayDyn<'py, f32>,
        fixed: Option<PyReadonlyArrayDyn<'py, f32>>,
    ) -> PyResult<(Array<'py, f32>, Array<'py, f32>)> {
        let k = self.joints();
        if !self.is_humanoid() {
            return Err(shape(format!(
                "this keyframe model completes {} values per pose with {} key groups, not the humanoid poses of its \
                 {k}-joint skeleton: call complete() with its raw pose vectors",
                self.model.dofs(),
                self.model.groups()
            )));
        }
        let f = Self::key_frames(&frames)?;
        let n = f.len();
        let (hips, _) = values("hips", &hips, &[("n", Some(n)), ("", Some(3))])?;
        let (rot, _) = values("rotations", &rotations, &[("n", Some(n)), ("K", Some(k)), ("", Some(4))])?;
        let g = self.model.groups();
        let fixed = match &fixed {
            Some(a) => values("fixed", a, &[("n", Some(n)), ("G", Some(g))])?.0.to_vec(),
            None => Vec::new(),
        };
        let quat = |i: usize, j: usize| -> DQuat {
            let s = &rot[(i * k + j) * 4..(i * k + j + 1) * 4];
            let q = DQuat::from_xyzw(s[0] as f64, s[1] as f64, s[2] as f64, s[3] as f64);
            if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY }
        };
        let root = |i: usize| DVec3::new(hips[3 * i] as f64, hips[3 * i + 1] as f64, hips[3 * i + 2] as f64);
        // The canonical frame (`complete_clip`): centred on the keys that fix the root, facing +X
        // at the first key.
        let fixes_root = |i: usize| fixed.is_empty() || fixed[i * g] != 0.0;
        let fixing: Vec<DVec3> = (0..n).filter(|&i| fixes_root(i)).map(root).collect();
        let centre = fixing.iter().fold(DVec3::ZERO, |a, r| a + *r) / fixing.len().max(1) as f64;
        let centre = DVec3::new(centre.x, 0.0, centre.z);
        let fwd = quat(0, 0) * HIPS_FORWARD;
        let fwd = DVec3::new(fwd.x, 0.0, fwd.z);
        let fwd = if fwd.length_squared() > 1e-12 { fwd.normalize() } else { DVec3::X };
        let to_canon = yaw_between(DVec3::X, fwd).inverse();
        let mut key_poses: Vec<f32> = Vec::with_capacity(n * self.model.dofs());
        let mut frame_rot = vec![DQuat::IDENTITY; k];
        for i in 0..n {
            for (j, q) in frame_rot.iter_mut().enumerate() {
                *q = quat(i, j);
            }
            frame_rot[0] = to_canon * frame_rot[0];
            let prev = (i > 0).then(|| key_poses[(i - 1) * self.model.dofs()..i * self.model.dofs()].to_vec());
            push_pose(to_canon * (root(i) - centre), &frame_rot, prev.as_deref(), &mut key_poses);
        }
        let out = self.run(&f, &key_poses, &fixed)?;
        let t = f.last().copied().unwrap_or(0) + 1;
        let from_canon = to_canon.inverse();
        let mut last: Vec<DQuat> = (0..k).map(|j| quat(0, j)).collect();
        let (mut hips_out, mut rot_out) = (Vec::with_capacity(t * 3), Vec::with_capacity(t * k * 4));
        let d = self.model.dofs();
        for p in out.chunks_exact(d) {
            let r = from_canon * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64) + centre;
            hips_out.extend([r.x as f32, r.y as f32, r.z as f32]);
            for j in 0..k {
                let v = &p[3 + 4 * j..7 + 4 * j];
                let q = DQuat::from_xyzw(v[1] as f64, v[2] as f64, v[3] as f64, v[0] as f64);
                let mut q = if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY };
                if j == 0 {
                    q = from_canon * q;
                }
                if q.dot(last[j]) < 0.0 {
                    q = -q;
                }
                last[j] = q;
                rot_out.extend([q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
            }
        }
        Ok((array(py, hips_out, &[t, 3])?, array(py, rot_out, &[t, k, 4])?))
    }
}
