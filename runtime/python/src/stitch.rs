//! Stitching (RMR): clips aligned end to start and refined into one motion.

use crate::arrays::{Array, PoseArrays, array, forward_kinematics, poses_from_world, values};
use crate::error::{OrPy, shape};
use glam::{DQuat, DVec3, Vec3};
use numpy::{PyArrayDyn, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::{Arc, Mutex, MutexGuard};
use zoo_runtime::{EnginePose, FootCleanup, StitchRefiner, StitchStreamOf};

/// Shortest clip the refiner stitches: the shortest segment of its training data (RMR sec. 6;
/// `zoo_rmr::pairs::MIN_CLIP_FRAMES`, what `zoo stitch` requires).
pub const MIN_CLIP_FRAMES: usize = 10;

/// A loaded stitching model (the refiner is `Send + Sync`: no runner to lock).
#[pyclass(module = "zoo._native", name = "Stitch", frozen)]
pub struct Stitch {
    model: Arc<StitchRefiner>,
    parents: Vec<i32>,
    offsets: Vec<Vec3>,
}

impl Stitch {
    /// Wraps a loaded refiner.
    pub fn new(model: StitchRefiner) -> Self {
        let s = &model.metadata().skeleton;
        let parents = s.parents.clone();
        let offsets = (0..s.len()).map(|j| s.offset(j)).collect();
        Stitch { model: Arc::new(model), parents, offsets }
    }

    fn read_poses(
        &self,
        hips: &PyReadonlyArrayDyn<'_, f32>,
        rot: &PyReadonlyArrayDyn<'_, f32>,
        what: &str,
    ) -> PyResult<Vec<EnginePose>> {
        let k = self.model.joints();
        let (h, hd) = values(&format!("{what} hips"), hips, &[("T", None), ("", Some(3))])?;
        let (r, _) = values(&format!("{what} rotations"), rot, &[("T", Some(hd[0])), ("K", Some(k)), ("", Some(4))])?;
        poses_from_world(&format!("{what} rotations"), h, r, hd[0], k)
    }
}

#[pymethods]
impl Stitch {
    /// The model's metadata.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::info::metadata_dict(py, self.model.metadata())
    }

    /// Window of the refiner, frames (the shortest sequence it refines).
    #[getter]
    fn window(&self) -> usize {
        self.model.window()
    }

    /// Stride between windows, frames.
    #[getter]
    fn stride(&self) -> usize {
        self.model.stride()
    }

    /// Values per pose vector.
    #[getter]
    fn dim(&self) -> usize {
        self.model.dim()
    }

    /// Whether the model was trained on clips inertialized at their seams (`zoo train rmr`'s
    /// default): give it the seams, as `stitch` does for it.
    #[getter]
    fn pre_blend(&self) -> bool {
        self.model.pre_blend()
    }

    /// Shortest clip stitched.
    #[getter]
    fn min_clip_frames(&self) -> usize {
        MIN_CLIP_FRAMES
    }

    /// Encodes a sequence of BVH-style poses (`hips` `(T, 3)`, `rotations` `(T, K, 4)`) into
    /// raw pose vectors `(T, D)`.
    fn encode<'py>(
        &self,
        py: Python<'py>,
        hips: PyReadonlyArrayDyn<'py, f32>,
        rotations: PyReadonlyArrayDyn<'py, f32>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let poses = self.read_poses(&hips, &rotations, "sequence")?;
        let d = self.model.dim();
        let mut out = vec![0.0f32; poses.len() * d];
        self.model.encode_poses(&poses, &mut out).or_py()?;
        array(py, out, &[poses.len(), d])
    }

    /// Refines raw pose vectors `(T, D)`, `T >= window`; returns `(T, D)` (contacts 0/1).
    fn refine<'py>(
        &self,
        py: Python<'py>,
        features: PyReadonlyArrayDyn<'py, f32>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let d = self.model.dim();
        let (x, dims) = values("features", &features, &[("T", None), ("D", Some(d))])?;
        let mut out = vec![0.0f32; x.len()];
        self.model.refine_sequence(x, &mut out).or_py()?;
        array(py, out, &[dims[0], d])
    }

    /// Aligns clips end to start (`clips`: a list of `(hips (T_i, 3), rotations (T_i, K, 4))`):
    /// each clip is moved on the ground (translation and turn about +Y) so that its first
    /// ground root is the previous clip's last one, as `zoo stitch` aligns
    /// (`zoo_rmr::pairs::align_clips`). Returns `(hips, rotations, starts)`: the aligned
    /// sequence and the first frame of each clip in it.
    fn align<'py>(
        &self,
        py: Python<'py>,
        clips: Vec<(PyReadonlyArrayDyn<'py, f32>, PyReadonlyArrayDyn<'py, f32>)>,
    ) -> PyResult<(Array<'py, f32>, Array<'py, f32>, Vec<usize>)> {
        let k = self.model.joints();
        if clips.is_empty() {
            return Err(shape("no clips given; stitching joins at least one clip"));
        }
        let layout = self.model.layout();
        let (mut hips, mut rot): (Vec<f32>, Vec<f32>) = (Vec::new(), Vec::new());
        let mut starts = Vec::with_capacity(clips.len());
        for (i, (h, r)) in clips.iter().enumerate() {
            let (h, hd) = values(&format!("clip {i} hips"), h, &[("T", None), ("", Some(3))])?;
            let (r, _) =
                values(&format!("clip {i} rotations"), r, &[("T", Some(hd[0])), ("K", Some(k)), ("", Some(4))])?;
            let t = hd[0];
            if t < MIN_CLIP_FRAMES {
                return Err(shape(format!(
                    "clip {i} has {t} frames; stitching needs at least {MIN_CLIP_FRAMES} per clip (the shortest segment \
                     it was trained on): give a longer range"
                )));
            }
            let quat = |f: usize| {
                let s = &r[f * k * 4..f * k * 4 + 4];
                DQuat::from_xyzw(s[0] as f64, s[1] as f64, s[2] as f64, s[3] as f64).normalize()
            };
            let pos = |f: usize| DVec3::new(h[3 * f] as f64, h[3 * f + 1] as f64, h[3 * f + 2] as f64);
            starts.push(hips.len() / 3);
            if i == 0 {
                hips.extend_from_slice(h);
                rot.extend_from_slice(r);
                continue;
            }
            let last = hips.len() / 3 - 1;
            let last_rot = DQuat::from_xyzw(
                rot[last * k * 4] as f64,
                rot[last * k * 4 + 1] as f64,
                rot[last * k * 4 + 2] as f64,
                rot[last * k * 4 + 3] as f64,
            )
            .normalize();
            let last_pos = DVec3::new(hips[3 * last] as f64, hips[3 * last + 1] as f64, hips[3 * last + 2] as f64);
            let anchor = layout.root_of(last_rot, last_pos);
            let head = layout.root_of(quat(0), pos(0));
            let mv = anchor.compose(&head.inverse());
            for f in 0..t {
                let (q, p) = mv.apply(quat(f), pos(f));
                hips.extend([p.x as f32, p.y as f32, p.z as f32]);
                rot.extend([q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
                rot.extend_from_slice(&r[(f * k + 1) * 4..(f + 1) * k * 4]);
            }
        }
        let t = hips.len() / 3;
        Ok((array(py, hips, &[t, 3])?, array(py, rot, &[t, k, 4])?, starts))
    }

    /// Refines an aligned sequence of BVH-style poses (`hips` `(T, 3)`, `rotations`
    /// `(T, K, 4)`, `T >= window`) as `zoo stitch` does: encoding, the refiner, decoding from
    /// the first ground root, then the ankles placed where the refiner predicts them and the
    /// planted feet locked (each step optional). Returns `(poses, contacts)`: the fields of
    /// `zoo.Poses` with prefix `(T,)` and the predicted contacts `(T, 4)` (heel L, toe L,
    /// heel R, toe R). `seams`: frames where a clip starts, inertialized before refining
    /// (`zoo stitch --pre-blend`). `seam_reach`: frames from every seam from which the input is
    /// kept (`None`: the model's window, as `zoo stitch`; 0: refine everywhere).
    #[pyo3(signature = (hips, rotations, place_ankles=true, lock_feet=true, seams=Vec::new(), seam_reach=None))]
    #[allow(clippy::too_many_arguments)]
    fn refine_poses<'py>(
        &self,
        py: Python<'py>,
        hips: PyReadonlyArrayDyn<'py, f32>,
        rotations: PyReadonlyArrayDyn<'py, f32>,
        place_ankles: bool,
        lock_feet: bool,
        seams: Vec<usize>,
        seam_reach: Option<usize>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArrayDyn<bool>>)> {
        let input = self.read_poses(&hips, &rotations, "sequence")?;
        let (t, k) = (input.len(), self.model.joints());
        let mut out: Vec<EnginePose> = (0..t).map(|_| EnginePose::new(k)).collect();
        let mut contacts = vec![[false; 4]; t];
        let cleanup = FootCleanup { place_ankles, lock_feet };
        let reach = seam_reach.map_or(self.model.seam_reach(), |n| (n > 0).then_some(n));
        self.model.refine_poses_reaching(&input, &seams, (cleanup, reach), &mut out, &mut contacts).or_py()?;
        let mut arrays = PoseArrays::new(k, t);
        for pose in &mut out {
            forward_kinematics(pose, &self.parents, &self.offsets);
            arrays.push(pose);
        }
        let contacts: Vec<bool> = contacts.iter().flatten().copied().collect();
        Ok((arrays.into_dict(py, &[t])?, array(py, contacts, &[t, 4])?))
    }
}

/// A stitching stream for motion matching (`zoo_runtime::StitchStream`): frames pushed as they
/// are decided, refined frames popped `latency` frames later, with the ankle IK, the guard of
/// the marked seams and the foot lock of `zoo stitch` (each of the first and last optional).
#[pyclass(module = "zoo._native", name = "StitchStream")]
pub struct StitchStream {
    inner: Mutex<StitchStreamOf<Arc<StitchRefiner>>>,
    parents: Vec<i32>,
    offsets: Vec<Vec3>,
    joints: usize,
}

impl StitchStream {
    fn lock(&self) -> MutexGuard<'_, StitchStreamOf<Arc<StitchRefiner>>> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl StitchStream {
    /// A stream over `model`; `place_ankles`, `lock_feet` and `seam_reach` as in
    /// `Stitch.refine_poses` (the seam guard is on, as in `zoo stitch`, unless `seam_guard` is
    /// false).
    #[new]
    #[pyo3(signature = (model, place_ankles=true, lock_feet=true, seam_guard=true, seam_reach=None))]
    fn new(
        model: &Stitch,
        place_ankles: bool,
        lock_feet: bool,
        seam_guard: bool,
        seam_reach: Option<usize>,
    ) -> PyResult<Self> {
        let mut stream = Arc::clone(&model.model).shared_stream();
        stream.set_cleanup(FootCleanup { place_ankles, lock_feet }).or_py()?;
        stream.set_seam_guard(seam_guard).or_py()?;
        if let Some(n) = seam_reach {
            stream.set_seam_reach((n > 0).then_some(n)).or_py()?;
        }
        Ok(StitchStream {
            inner: Mutex::new(stream),
            parents: model.parents.clone(),
            offsets: model.offsets.clone(),
            joints: model.model.joints(),
        })
    }

    /// Frames between pushing frame `t` and popping it refined.
    #[getter]
    fn latency(&self) -> usize {
        self.lock().latency()
    }

    /// Frames pushed so far.
    #[getter]
    fn pushed(&self) -> usize {
        self.lock().pushed()
    }

    /// Frames popped so far.
    #[getter]
    fn popped(&self) -> usize {
        self.lock().popped()
    }

    /// Marks the next pushed frame as the first of a new clip (inertialized and guarded).
    fn mark_seam(&self) {
        self.lock().mark_seam();
    }

    /// Pushes frames of the aligned motion: BVH-style `hips` `(T, 3)` and `rotations`
    /// `(T, K, 4)`.
    fn push(&self, hips: PyReadonlyArrayDyn<'_, f32>, rotations: PyReadonlyArrayDyn<'_, f32>) -> PyResult<()> {
        let k = self.joints;
        let (h, hd) = values("pushed hips", &hips, &[("T", None), ("", Some(3))])?;
        let (r, _) = values("pushed rotations", &rotations, &[("T", Some(hd[0])), ("K", Some(k)), ("", Some(4))])?;
        let poses = poses_from_world("pushed rotations", h, r, hd[0], k)?;
        let mut stream = self.lock();
        for p in &poses {
            stream.push(p).or_py()?;
        }
        Ok(())
    }

    /// Ends the motion: every remaining frame becomes ready.
    fn finish(&self) -> PyResult<()> {
        self.lock().finish().or_py()
    }

    /// Pops every refined frame that is ready. Returns `(poses, contacts)`: the fields of
    /// `zoo.Poses` with prefix `(N,)` and the predicted contacts `(N, 4)`.
    fn pop<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArrayDyn<bool>>)> {
        let k = self.joints;
        let mut stream = self.lock();
        let mut arrays = PoseArrays::new(k, 0);
        let mut bits = Vec::new();
        let mut pose = EnginePose::new(k);
        let mut n = 0;
        while let Some(c) = stream.pop(&mut pose).or_py()? {
            forward_kinematics(&mut pose, &self.parents, &self.offsets);
            arrays.push(&pose);
            bits.extend(c);
            n += 1;
        }
        Ok((arrays.into_dict(py, &[n])?, array(py, bits, &[n, 4])?))
    }
}
