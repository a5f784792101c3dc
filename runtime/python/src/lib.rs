//! `zoo._native`: the extension module of the `zoo` Python package, zoo's engine runtime
//! (`zoo-runtime`) on numpy arrays. The public API, its documentation and its types are the
//! Python package's (`runtime/python/zoo/__init__.py`, `_native.pyi`); this module does the work:
//! one loader for every exported file, each task on float32 arrays, poses to and from arrays,
//! coordinate-frame conversion, BVH read/write, and the runtime's errors as exceptions.
//!
//! No candle and no CLI: the runtime (tract), the motion core and the BVH module only.

// No `unsafe` here: the workspace's `unsafe_code = "deny"` holds (pyo3's macros allow their own
// FFI code).

mod arrays;
mod bvh;
mod error;
mod info;
mod keyframes;
mod stitch;
mod synthesis;
mod transition;

use arrays::{PoseArrays, array, forward_kinematics, values};
use error::OrPy;
use glam::{Quat, Vec3};
use numpy::{PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use zoo_motion::frame::Conversion;
use zoo_runtime::LoadedModel;
use zoo_runtime::pose::root_delta;

/// Loads an exported model file of any task through `zoo_runtime::LoadedModel::load`.
/// Returns `(task, model)`, `model` the native object of the task (`Transition`, `Keyframes`,
/// `Stitch`, `Synthesis`). A folder (a training run) is refused with the command that exports it.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<(String, Py<PyAny>)> {
    if path.is_dir() {
        return Err(error::ModelFileError::new_err(format!(
            "{0} is a folder (a training run?), not an exported model: export it with `zoo export --onnx {0} --out \
             model.onnx` and load model.onnx",
            path.display()
        )));
    }
    let model = LoadedModel::load(&path).or_py()?;
    wrap(py, model, &path.display().to_string())
}

/// Loads an exported model from the bytes of its file (`zoo_runtime::LoadedModel::from_bytes`):
/// the same model as `load` of that file.
#[pyfunction]
fn load_bytes(py: Python<'_>, data: &[u8]) -> PyResult<(String, Py<PyAny>)> {
    let model = LoadedModel::from_bytes(data).or_py()?;
    wrap(py, model, "the model's bytes")
}

/// `(task, native object)` of a loaded model; `what` names it in errors.
fn wrap(py: Python<'_>, model: LoadedModel, what: &str) -> PyResult<(String, Py<PyAny>)> {
    let task = model.task().name().to_string();
    let object: Py<PyAny> = match model {
        LoadedModel::Transition(m) => Py::new(py, transition::Transition::new(m).or_py()?)?.into_any(),
        LoadedModel::Keyframes(m) => Py::new(py, keyframes::Keyframes::new(m).or_py()?)?.into_any(),
        LoadedModel::Stitch(m) => Py::new(py, stitch::Stitch::new(m))?.into_any(),
        LoadedModel::Synthesis(m) => Py::new(py, synthesis::Synthesis::new(m))?.into_any(),
        other => {
            return Err(error::ModelFileError::new_err(format!(
                "{what}: a `{}` model, which this package does not run yet",
                other.task()
            )));
        }
    };
    Ok((task, object))
}

/// Poses of a skeleton from BVH-style arrays: `hips` `(N, 3)` world positions and `rotations`
/// `(N, K, 4)` (the hips' world rotation, then local rotations, `(x, y, z, w)`), with the
/// skeleton's `parents` `(K,)` and rest `offsets` `(K, 3)`. Returns the fields of `zoo.Poses`
/// with prefix `(N,)`: global positions by forward kinematics, root deltas between consecutive
/// frames (zero on the first).
#[pyfunction]
fn poses_from_world<'py>(
    py: Python<'py>,
    hips: PyReadonlyArrayDyn<'py, f32>,
    rotations: PyReadonlyArrayDyn<'py, f32>,
    parents: PyReadonlyArrayDyn<'py, i32>,
    offsets: PyReadonlyArrayDyn<'py, f32>,
) -> PyResult<Bound<'py, PyDict>> {
    let k = arrays::check_shape("parents", parents.shape(), &[("K", None)])?[0];
    let parents: Vec<i32> = parents.to_owned_array().iter().copied().collect();
    let names: Vec<String> = (0..k).map(|j| format!("joint {j}")).collect();
    zoo_runtime::metadata::check_parents(&parents, |j| names[j].clone()).map_err(error::shape)?;
    let (off, _) = values("offsets", &offsets, &[("K", Some(k)), ("", Some(3))])?;
    let offsets: Vec<Vec3> = off.chunks_exact(3).map(Vec3::from_slice).collect();
    let (h, hd) = values("hips", &hips, &[("N", None), ("", Some(3))])?;
    let n = hd[0];
    let (r, _) = values("rotations", &rotations, &[("N", Some(n)), ("K", Some(k)), ("", Some(4))])?;
    let mut poses = arrays::poses_from_world("rotations", h, r, n, k)?;
    let mut out = PoseArrays::new(k, n);
    for f in 0..n {
        if f > 0 {
            let (a, b) = (&poses[f - 1], &poses[f]);
            let (d, yaw) = root_delta(a.root_position, a.root_rotation, b.root_position, b.root_rotation);
            poses[f].root_delta_position = d;
            poses[f].root_delta_yaw = yaw;
        }
        forward_kinematics(&mut poses[f], &parents, &offsets);
        out.push_world(&poses[f], &h[3 * f..3 * f + 3], &r[4 * k * f..4 * k * (f + 1)]);
    }
    out.into_dict(py, &[n])
}

/// Converts pose fields (a dict of the fields of `zoo.Poses`, any shape prefix) from one
/// coordinate frame to another (`(metres_per_unit, up_axis, handedness)` each), as
/// `zoo_runtime::EnginePose::convert` does: positions scaled and re-axed, rotations
/// conjugated, yaw deltas reversed by a change of handedness. Returns new arrays.
#[pyfunction]
fn convert_poses<'py>(
    py: Python<'py>,
    poses: Bound<'py, PyDict>,
    from_frame: (f32, String, String),
    to_frame: (f32, String, String),
) -> PyResult<Bound<'py, PyDict>> {
    let from = info::frame_of(from_frame.0, &from_frame.1, &from_frame.2)?;
    let to = info::frame_of(to_frame.0, &to_frame.1, &to_frame.2)?;
    let c = Conversion::between(&from, &to);
    let out = PyDict::new(py);
    for (key, value) in poses.iter() {
        let name: String = key.extract()?;
        let a: PyReadonlyArrayDyn<'py, f32> = value.extract()?;
        let dims = a.shape().to_vec();
        let v = a.to_owned_array().iter().copied().collect::<Vec<f32>>();
        let converted: Vec<f32> = match name.as_str() {
            "root_position" | "root_delta_position" | "hips_position" | "global_positions" | "hips" => {
                v.chunks_exact(3).flat_map(|p| c.position(Vec3::from_slice(p)).to_array()).collect()
            }
            "root_rotation" | "local_rotations" | "rotations" => {
                v.chunks_exact(4).flat_map(|q| c.rotation(Quat::from_slice(q)).to_array()).collect()
            }
            "root_delta_yaw" => v.iter().map(|y| c.yaw(*y)).collect(),
            other => return Err(error::shape(format!("`{other}` is not a field of zoo.Poses"))),
        };
        out.set_item(name, array(py, converted, &dims)?)?;
    }
    Ok(out)
}

/// The version of the package (the workspace's).
const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    error::register(m)?;
    m.add("__version__", VERSION)?;
    m.add("FORMAT_VERSION", zoo_runtime::FORMAT_VERSION)?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(load_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(poses_from_world, m)?)?;
    m.add_function(wrap_pyfunction!(convert_poses, m)?)?;
    m.add_function(wrap_pyfunction!(bvh::read_bvh, m)?)?;
    m.add_function(wrap_pyfunction!(bvh::write_bvh, m)?)?;
    m.add_function(wrap_pyfunction!(bvh::resample, m)?)?;
    m.add_class::<transition::Transition>()?;
    m.add_class::<keyframes::Keyframes>()?;
    m.add_class::<stitch::Stitch>()?;
    m.add_class::<stitch::StitchStream>()?;
    m.add_class::<synthesis::Synthesis>()?;
    m.add_class::<synthesis::Controller>()?;
    m.add_class::<synthesis::PathFollower>()?;
    Ok(())
}
