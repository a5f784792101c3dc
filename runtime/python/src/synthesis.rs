//! Synthesis (RNN-GMM): random motion of seeded characters, the feature frames that start
//! them, and speed / heading control.

use crate::arrays::{Array, PoseArrays, array, check_shape, values};
use crate::error::{OrPy, shape};
use glam::{DQuat, DVec3};
use numpy::{PyArrayDyn, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Mutex;
use zoo_motion::quat::to_scaled_axis;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::follow::{PathGoal, PathSettings};
use zoo_runtime::{EnginePose, MotionError, SynthesisModel};

/// A loaded synthesis model.
#[pyclass(module = "zoo._native", name = "Synthesis", frozen)]
pub struct Synthesis {
    model: SynthesisModel,
}

impl Synthesis {
    /// Wraps a loaded model.
    pub fn new(model: SynthesisModel) -> Self {
        Synthesis { model }
    }

    /// The `x` normalization group (the feature frame's mean and deviation, clip units).
    fn mean(&self) -> Result<Vec<f32>, MotionError> {
        Ok(self.model.model().metadata().group("x", self.model.frame_dim())?.mean.clone())
    }

    fn seeds(seeds: &PyReadonlyArrayDyn<'_, u64>, n: usize) -> PyResult<Vec<u64>> {
        check_shape("seeds", seeds.shape(), &[("N", Some(n))])?;
        Ok(seeds.as_slice().map_err(|_| shape("`seeds` must be a contiguous uint64 array"))?.to_vec())
    }
}

/// The heading (radians about +Y) and tilt of a root rotation (`zoo_rnngmm`'s `split_root`).
fn split_root(q: DQuat, frame: usize) -> PyResult<(f64, DQuat)> {
    let norm = (q.y * q.y + q.w * q.w).sqrt();
    if norm < 1e-6 {
        return Err(shape(format!(
            "frame {frame}: the root is turned half-way round a horizontal axis, so its heading about +Y is undefined; \
             the feature frame needs an upright root (a heading times a tilt below 180 degrees)"
        )));
    }
    let heading = 2.0 * q.y.atan2(q.w);
    Ok((heading, DQuat::from_rotation_y(-heading) * q))
}

/// An angle wrapped to (-pi, pi].
fn wrap(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let w = a - tau * (a / tau).round();
    if w <= -std::f64::consts::PI { w + tau } else { w }
}

#[pymethods]
impl Synthesis {
    /// The model's metadata.
    #[getter]
    fn metadata<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        crate::info::metadata_dict(py, self.model.model().metadata())
    }

    /// Values per feature frame `D`.
    #[getter]
    fn frame_dim(&self) -> usize {
        self.model.frame_dim()
    }

    /// Whether the file embeds the refiner (frames are refined behind the generator).
    #[getter]
    fn has_refiner(&self) -> bool {
        self.model.has_refiner()
    }

    /// The data's mean feature frame `(D,)`, clip units: a neutral start frame.
    #[getter]
    fn mean_frame<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let m = self.mean().or_py()?;
        let d = m.len();
        array(py, m, &[d])
    }

    /// Feature frames of a sequence of BVH-style poses (`hips` `(T, 3)`, `rotations`
    /// `(T, K, 4)`, `T >= 2`, at the model's frame rate) as `zoo_rnngmm::FeatureSpec` encodes
    /// a clip: root step in the previous heading frame, heading change, root height and tilt,
    /// each joint's rotation vector relative to the model's reference rotation, and the
    /// contacts `(T, 2)` (left, right; `None`: the data's mean). Returns `(features (T, D),
    /// placements (T, 3))`, the placement of frame `t` its ground root `(x, z, heading)`: the
    /// `start` placement of a character seeded with frames `..=t`.
    #[pyo3(signature = (hips, rotations, contacts=None))]
    fn encode<'py>(
        &self,
        py: Python<'py>,
        hips: PyReadonlyArrayDyn<'py, f32>,
        rotations: PyReadonlyArrayDyn<'py, f32>,
        contacts: Option<PyReadonlyArrayDyn<'py, f32>>,
    ) -> PyResult<(Array<'py, f32>, Array<'py, f32>)> {
        let meta = self.model.model().metadata();
        let k = meta.skeleton.len();
        let d = self.model.frame_dim();
        let (h, hd) = values("hips", &hips, &[("T", None), ("", Some(3))])?;
        let t = hd[0];
        if t < 2 {
            return Err(shape("a feature frame needs 2 frames (the root step is a difference of frames): give T >= 2"));
        }
        let (r, _) = values("rotations", &rotations, &[("T", Some(t)), ("K", Some(k)), ("", Some(4))])?;
        let mean = self.mean().or_py()?;
        let contacts = match &contacts {
            Some(c) => Some(values("contacts", c, &[("T", Some(t)), ("", Some(2))])?.0.to_vec()),
            None => None,
        };
        let references: Vec<DQuat> = meta
            .task
            .as_synthesis()
            .map(|s| s.references.iter().map(|q| DQuat::from_xyzw(q[0], q[1], q[2], q[3]).normalize()).collect())
            .unwrap_or_default();
        let quat = |f: usize, j: usize| {
            let s = &r[(f * k + j) * 4..(f * k + j + 1) * 4];
            DQuat::from_xyzw(s[0] as f64, s[1] as f64, s[2] as f64, s[3] as f64).normalize()
        };
        let pos = |f: usize| DVec3::new(h[3 * f] as f64, h[3 * f + 1] as f64, h[3 * f + 2] as f64);
        let mut heading = Vec::with_capacity(t);
        let mut tilt = Vec::with_capacity(t);
        for f in 0..t {
            let (a, b) = split_root(quat(f, 0), f)?;
            heading.push(a);
            tilt.push(b);
        }
        let mut out = vec![0.0f32; t * d];
        let mut placements = Vec::with_capacity(t * 3);
        for f in 0..t {
            let x = &mut out[f * d..(f + 1) * d];
            // Root motion of frame f relative to frame f - 1 (frame 0 repeats frame 1's).
            let g = f.max(1);
            let step = DQuat::from_rotation_y(-heading[g - 1]) * (pos(g) - pos(g - 1));
            let tl = to_scaled_axis(tilt[f]);
            let root = [step.x, step.z, wrap(heading[g] - heading[g - 1]), pos(f).y, tl.x, tl.z];
            for (v, r) in x[..6].iter_mut().zip(root) {
                *v = r as f32;
            }
            for j in 1..k {
                let a = to_scaled_axis(references[j].inverse() * quat(f, j));
                x[6 + 3 * (j - 1)..9 + 3 * (j - 1)].copy_from_slice(&[a.x as f32, a.y as f32, a.z as f32]);
            }
            match &contacts {
                Some(c) => x[d - 2..].copy_from_slice(&c[2 * f..2 * f + 2]),
                None => x[d - 2..].copy_from_slice(&mean[d - 2..]),
            }
            placements.extend([pos(f).x as f32, pos(f).z as f32, heading[f] as f32]);
        }
        Ok((array(py, out, &[t, d])?, array(py, placements, &[t, 3])?))
    }

    /// Generates `frames` frames for `N` characters: `start` `(N, D)` feature frames (clip
    /// units), `placements` `(N, 3)` (`x`, `z`, heading about +Y of each start), `seeds`
    /// `(N,)` uint64. Returns `(poses, contacts)`: the fields of `zoo.Poses` with prefix
    /// `(N, frames)` and the contact bits `(N, frames, 2)`. A character's frames depend only on
    /// its seed, start frame and placement.
    #[pyo3(signature = (frames, start, placements, seeds, temperature=1.0, refine=true))]
    #[allow(clippy::too_many_arguments)]
    fn generate<'py>(
        &self,
        py: Python<'py>,
        frames: usize,
        start: PyReadonlyArrayDyn<'py, f32>,
        placements: PyReadonlyArrayDyn<'py, f32>,
        seeds: PyReadonlyArrayDyn<'py, u64>,
        temperature: f32,
        refine: bool,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArrayDyn<bool>>)> {
        let d = self.model.frame_dim();
        let (x0, sd) = values("start", &start, &[("N", None), ("D", Some(d))])?;
        let n = sd[0];
        let (pl, _) = values("placements", &placements, &[("N", Some(n)), ("", Some(3))])?;
        let seeds = Self::seeds(&seeds, n)?;
        let model = if refine { self.model.clone() } else { self.model.clone().without_refiner() };
        let k = model.joints();
        let mut characters: Vec<_> = seeds.iter().map(|&s| model.new_character(s)).collect();
        for (c, ch) in characters.iter_mut().enumerate() {
            ch.start(&model, &x0[c * d..(c + 1) * d], pl[3 * c], pl[3 * c + 1], pl[3 * c + 2]).or_py()?;
        }
        let mut runner = model.runner(n).or_py()?;
        let mut poses: Vec<EnginePose> = (0..n).map(|_| EnginePose::with_global_positions(k)).collect();
        let mut contacts = vec![[false; 2]; n];
        let mut per: Vec<Vec<EnginePose>> = vec![Vec::with_capacity(frames); n];
        let mut bits: Vec<Vec<bool>> = vec![Vec::with_capacity(frames * 2); n];
        for _ in 0..frames {
            runner.step_batch(&mut characters, temperature, &mut poses, &mut contacts).or_py()?;
            for c in 0..n {
                per[c].push(poses[c].clone());
                bits[c].extend(contacts[c]);
            }
        }
        let mut arrays = PoseArrays::new(k, n * frames);
        for p in per.iter().flatten() {
            arrays.push(p);
        }
        let bits: Vec<bool> = bits.into_iter().flatten().collect();
        Ok((arrays.into_dict(py, &[n, frames])?, array(py, bits, &[n, frames, 2])?))
    }
}

/// Speed / heading control of `N` characters of a synthesis model (`zoo_runtime::control`).
#[pyclass(module = "zoo._native", name = "Controller")]
pub struct Controller {
    model: SynthesisModel,
    inner: Mutex<(ControlRunner, Vec<ControlledCharacter>)>,
}

#[pymethods]
impl Controller {
    /// `N = len(seeds)` characters of `model`, planning with the runtime's settings (defaults:
    /// `zoo_runtime::control::ControlSettings::default()`).
    #[new]
    #[pyo3(signature = (model, seeds, batch=None, speed_offsets=None, turn_offsets=None, sigma_speed=None, sigma_heading=None, temperature=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: &Synthesis,
        seeds: PyReadonlyArrayDyn<'_, u64>,
        batch: Option<usize>,
        speed_offsets: Option<Vec<f32>>,
        turn_offsets: Option<Vec<f32>>,
        sigma_speed: Option<f32>,
        sigma_heading: Option<f32>,
        temperature: Option<f32>,
    ) -> PyResult<Self> {
        let n = check_shape("seeds", seeds.shape(), &[("N", None)])?[0];
        let seeds = Synthesis::seeds(&seeds, n)?;
        let d = ControlSettings::default();
        let settings = ControlSettings {
            batch: batch.unwrap_or(d.batch),
            speed_offsets: speed_offsets.unwrap_or(d.speed_offsets),
            turn_offsets: turn_offsets.unwrap_or(d.turn_offsets),
            side_offsets: d.side_offsets,
            sigma_speed: sigma_speed.unwrap_or(d.sigma_speed),
            sigma_heading: sigma_heading.unwrap_or(d.sigma_heading),
            temperature: temperature.unwrap_or(d.temperature),
        };
        let m = model.model.clone();
        let characters = seeds
            .iter()
            .map(|&s| ControlledCharacter::new(&m, s, settings.clone()))
            .collect::<Result<Vec<_>, _>>()
            .or_py()?;
        let runner = ControlRunner::new(&m).or_py()?;
        Ok(Controller { model: m, inner: Mutex::new((runner, characters)) })
    }

    /// Characters controlled.
    #[getter]
    fn characters(&self) -> usize {
        self.lock().1.len()
    }

    /// Starts every character from seed feature frames `(N, S, D)` (clip units, oldest first)
    /// with the last one placed at `placements` `(N, 3)` (`x`, `z`, heading).
    fn start(&self, frames: PyReadonlyArrayDyn<'_, f32>, placements: PyReadonlyArrayDyn<'_, f32>) -> PyResult<()> {
        let d = self.model.frame_dim();
        let mut inner = self.lock();
        let n = inner.1.len();
        let (f, fd) = values("frames", &frames, &[("N", Some(n)), ("S", None), ("D", Some(d))])?;
        let (pl, _) = values("placements", &placements, &[("N", Some(n)), ("", Some(3))])?;
        let per = fd[1] * d;
        for (c, ch) in inner.1.iter_mut().enumerate() {
            ch.start(&self.model, &f[c * per..(c + 1) * per], pl[3 * c], pl[3 * c + 1], pl[3 * c + 2]).or_py()?;
        }
        Ok(())
    }

    /// Plays every character's next frame under its control: `speeds` `(N,)` (clip units per
    /// second), `headings` `(N,)` (facing yaw, radians about +Y, 0 facing +Z). Returns
    /// `(poses, contacts)`: the fields of `zoo.Poses` with prefix `(N,)` and `(N, 2)` bits.
    fn step<'py>(
        &self,
        py: Python<'py>,
        speeds: PyReadonlyArrayDyn<'py, f32>,
        headings: PyReadonlyArrayDyn<'py, f32>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArrayDyn<bool>>)> {
        let k = self.model.joints();
        let mut inner = self.lock();
        let n = inner.1.len();
        let (s, _) = values("speeds", &speeds, &[("N", Some(n))])?;
        let (h, _) = values("headings", &headings, &[("N", Some(n))])?;
        let (runner, characters) = &mut *inner;
        let mut arrays = PoseArrays::new(k, n);
        let mut bits = Vec::with_capacity(2 * n);
        let mut pose = EnginePose::with_global_positions(k);
        for (c, ch) in characters.iter_mut().enumerate() {
            let contact = runner.step(ch, Control::new(s[c], h[c]), &mut pose).or_py()?;
            arrays.push(&pose);
            bits.extend(contact);
        }
        Ok((arrays.into_dict(py, &[n])?, array(py, bits, &[n, 2])?))
    }

    /// Each character's ground position and facing `(N, 3)` (`x`, `z`, heading) after the
    /// last frame played.
    #[getter]
    fn placements<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f32>>> {
        let inner = self.lock();
        let v: Vec<f32> = inner.1.iter().flat_map(|c| c.placement().map(|v| v as f32)).collect();
        let n = inner.1.len();
        array(py, v, &[n, 3])
    }
}

impl Controller {
    fn lock(&self) -> std::sync::MutexGuard<'_, (ControlRunner, Vec<ControlledCharacter>)> {
        self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// One character of a synthesis model following a ground path (`zoo_runtime::follow`: the
/// online controller planning towards the path instead of a speed and a heading).
#[pyclass(module = "zoo._native", name = "PathFollower")]
pub struct PathFollower {
    model: SynthesisModel,
    inner: Mutex<(ControlRunner, ControlledCharacter, PathGoal)>,
}

#[pymethods]
impl PathFollower {
    /// A character of `model` seeded with `seed` to walk along `points` `(M, 2)` (ground `x`,
    /// `z`, clip units) at `speed` clip units per second; the path's weights default to
    /// `zoo_runtime::follow::PathSettings::default()`, the planner's to
    /// `PathSettings::control()`.
    #[new]
    #[pyo3(signature = (model, points, speed, seed=0, sigma_fit=None, sigma_progress=None, sigma_heading=None, lookahead=None, batch=None, speed_offsets=None, turn_offsets=None, side_offsets=None, temperature=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        model: &Synthesis,
        points: PyReadonlyArrayDyn<'_, f32>,
        speed: f64,
        seed: u64,
        sigma_fit: Option<f64>,
        sigma_progress: Option<f64>,
        sigma_heading: Option<f64>,
        lookahead: Option<f64>,
        batch: Option<usize>,
        speed_offsets: Option<Vec<f32>>,
        turn_offsets: Option<Vec<f32>>,
        side_offsets: Option<Vec<f32>>,
        temperature: Option<f32>,
    ) -> PyResult<Self> {
        let (p, _) = values("points", &points, &[("M", None), ("", Some(2))])?;
        let points: Vec<[f64; 2]> = p.chunks_exact(2).map(|q| [q[0] as f64, q[1] as f64]).collect();
        let d = PathSettings::default();
        let settings = PathSettings {
            sigma_fit: sigma_fit.unwrap_or(d.sigma_fit),
            sigma_progress: sigma_progress.unwrap_or(d.sigma_progress),
            sigma_heading: sigma_heading.unwrap_or(d.sigma_heading),
            lookahead: lookahead.unwrap_or(d.lookahead),
        };
        let goal = PathGoal::new(&points, speed, settings).or_py()?;
        let m = model.model.clone();
        let c = PathSettings::control();
        let control = ControlSettings {
            batch: batch.unwrap_or(c.batch),
            speed_offsets: speed_offsets.unwrap_or(c.speed_offsets),
            turn_offsets: turn_offsets.unwrap_or(c.turn_offsets),
            side_offsets: side_offsets.unwrap_or(c.side_offsets),
            temperature: temperature.unwrap_or(c.temperature),
            ..c
        };
        let character = ControlledCharacter::new(&m, seed, control).or_py()?;
        let runner = ControlRunner::new(&m).or_py()?;
        Ok(PathFollower { model: m, inner: Mutex::new((runner, character, goal)) })
    }

    /// Starts the character from seed feature frames `(S, D)` (clip units, oldest first), the
    /// last one placed on the path's first point facing along its first segment.
    fn start(&self, frames: PyReadonlyArrayDyn<'_, f32>) -> PyResult<()> {
        let d = self.model.frame_dim();
        let (f, _) = values("frames", &frames, &[("S", None), ("D", Some(d))])?;
        let mut inner = self.lock();
        let (_, character, goal) = &mut *inner;
        let [x, z, yaw] = goal.start_placement();
        character.start(&self.model, &f, x as f32, z as f32, yaw as f32).or_py()
    }

    /// Plays up to `frames` frames, fewer when the path's end is reached. Returns `(poses,
    /// contacts)`: the fields of `zoo.Poses` with prefix `(T,)` and `(T, 2)` bits.
    fn step<'py>(
        &self,
        py: Python<'py>,
        frames: usize,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyArrayDyn<bool>>)> {
        let k = self.model.joints();
        let mut inner = self.lock();
        let (runner, character, goal) = &mut *inner;
        let mut arrays = PoseArrays::new(k, frames);
        let mut bits = Vec::with_capacity(2 * frames);
        let mut pose = EnginePose::with_global_positions(k);
        let mut played = 0;
        while played < frames && !goal.reached_end() {
            bits.extend(runner.step_along(character, goal, &mut pose).or_py()?);
            arrays.push(&pose);
            played += 1;
        }
        Ok((arrays.into_dict(py, &[played])?, array(py, bits, &[played, 2])?))
    }

    /// Arc length of the path point nearest to the planned motion's end, clip units.
    #[getter]
    fn progress(&self) -> f64 {
        self.lock().2.progress()
    }

    /// The path's length, clip units.
    #[getter]
    fn length(&self) -> f64 {
        self.lock().2.length()
    }

    /// Whether the planned motion has reached the path's end.
    #[getter]
    fn reached_end(&self) -> bool {
        self.lock().2.reached_end()
    }

    /// The distance of each ground point `(T, 2)` to the path, clip units.
    fn distances<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArrayDyn<'py, f32>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let (p, _) = values("points", &points, &[("T", None), ("", Some(2))])?;
        let inner = self.lock();
        let d: Vec<f64> = p.chunks_exact(2).map(|q| inner.2.distance([q[0] as f64, q[1] as f64])).collect();
        let t = d.len();
        array(py, d, &[t])
    }
}

impl PathFollower {
    fn lock(&self) -> std::sync::MutexGuard<'_, (ControlRunner, ControlledCharacter, PathGoal)> {
        self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}
