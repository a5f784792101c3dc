//! What every model tells about itself (task, kind, skeleton, frame rate, units and axes), as
//! one dict that the Python layer turns into `zoo.Skeleton` and `zoo.CoordinateFrame`.

use crate::arrays::array;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use zoo_motion::frame::{CoordinateFrame, Handedness, UpAxis};
use zoo_runtime::MotionModelMetadata;

/// An `f32` as the Python float it was written as (`0.01`, not `0.009999999776482582`): its
/// shortest round-trip decimal form.
fn shortest(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

/// A coordinate frame as a dict `{"metres_per_unit", "up_axis", "handedness"}`.
pub fn frame_dict<'py>(py: Python<'py>, f: &CoordinateFrame) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("metres_per_unit", shortest(f.metres_per_unit))?;
    d.set_item("up_axis", if f.up_axis == UpAxis::Y { "y" } else { "z" })?;
    d.set_item("handedness", if f.handedness == Handedness::Right { "right" } else { "left" })?;
    Ok(d)
}

/// A coordinate frame from its parts, checked.
pub fn frame_of(metres_per_unit: f32, up_axis: &str, handedness: &str) -> PyResult<CoordinateFrame> {
    let up_axis = match up_axis.to_ascii_lowercase().as_str() {
        "y" => UpAxis::Y,
        "z" => UpAxis::Z,
        other => return Err(crate::error::shape(format!("up_axis is {other:?}; give \"y\" or \"z\""))),
    };
    let handedness = match handedness.to_ascii_lowercase().as_str() {
        "right" => Handedness::Right,
        "left" => Handedness::Left,
        other => return Err(crate::error::shape(format!("handedness is {other:?}; give \"right\" or \"left\""))),
    };
    let f = CoordinateFrame { metres_per_unit, up_axis, handedness };
    f.check().map_err(crate::error::shape)?;
    Ok(f)
}

/// The metadata of a model as a dict: `task`, `kind`, `fps`, `frame` (see [`frame_dict`]),
/// `skeleton` (`names`, `parents` int32 `(K,)`, `offsets` float32 `(K, 3)`, model units),
/// `feature_layout` (a list of `(name, start, len)`), `format_version`.
pub fn metadata_dict<'py>(py: Python<'py>, m: &MotionModelMetadata) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("task", m.task.name())?;
    d.set_item("kind", &m.model_kind)?;
    d.set_item("fps", shortest(m.fps))?;
    d.set_item("format_version", m.format_version)?;
    d.set_item("frame", frame_dict(py, &m.frame)?)?;
    let s = &m.skeleton;
    let k = s.len();
    let sk = PyDict::new(py);
    sk.set_item("names", PyList::new(py, &s.names)?)?;
    sk.set_item("parents", array(py, s.parents.clone(), &[k])?)?;
    let offsets: Vec<f32> = s.offsets.iter().flat_map(|o| o.map(|v| v as f32)).collect();
    sk.set_item("offsets", array(py, offsets, &[k, 3])?)?;
    d.set_item("skeleton", sk)?;
    let layout: Vec<(String, usize, usize)> =
        m.feature_layout.iter().map(|s| (s.name.clone(), s.start, s.len)).collect();
    d.set_item("feature_layout", layout)?;
    Ok(d)
}
