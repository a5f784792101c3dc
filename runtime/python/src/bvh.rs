//! BVH read/write for scripts: zoo's own reader and writer (`zoo_data::bvh`), compiled in from
//! its source file. Linking `zoo-data` would pull its dataset tooling (rapier2d, ufbx's C
//! library, glTF, FFT) into the wheel; the BVH module itself needs only the motion core, the
//! model file's crate (its atomic write), `fast-float2` and `flate2`, so the package builds
//! that one file.

use crate::arrays::{array, check_shape};
use crate::error::{BvhError, shape};
use glam::{DQuat, DVec3};
use numpy::{PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

#[allow(dead_code, missing_docs)]
#[path = "../../../offline/data/src/bvh.rs"]
mod source;

/// Reads a `.bvh` or `.bvh.gz` file into a dict of arrays: `names`, `parents` (int32, `-1`
/// for the root), `offsets` `(J, 3)`, `end_sites` `(J, 3)` (NaN where a joint has none),
/// `position_channels` `(J,)` bool, `euler_orders` (channel order per joint, e.g. `"zxy"`),
/// `frame_time` (seconds), `rotations` `(F, J, 4)` local rotations `(x, y, z, w)` (the root's
/// in world space), `positions` `(F, J, 3)` local translations (the root's world position),
/// all float64 in the file's units. `drop_dummy_root` drops an all-zero root joint as zoo's
/// datasets do (bandai2's `joint_Root`).
#[pyfunction]
#[pyo3(signature = (path, drop_dummy_root=false))]
pub fn read_bvh<'py>(py: Python<'py>, path: PathBuf, drop_dummy_root: bool) -> PyResult<Bound<'py, PyDict>> {
    let clip = source::read_file(&path, &source::ReadOptions { drop_dummy_root })
        .map_err(|e| BvhError::new_err(e.to_string()))?;
    let s = &clip.skeleton;
    let (j, f) = (s.len(), clip.frames());
    let d = PyDict::new(py);
    d.set_item("names", s.names.clone())?;
    d.set_item("parents", array(py, s.parents_i32(), &[j])?)?;
    d.set_item("offsets", array(py, s.offsets.iter().flat_map(|o| o.to_array()).collect(), &[j, 3])?)?;
    let ends: Vec<f64> = s.end_sites.iter().flat_map(|e| e.map_or([f64::NAN; 3], |e| e.to_array())).collect();
    d.set_item("end_sites", array(py, ends, &[j, 3])?)?;
    d.set_item("position_channels", array(py, s.channels.iter().map(|c| c.position).collect(), &[j])?)?;
    d.set_item("euler_orders", s.channels.iter().map(|c| c.order.name()).collect::<Vec<_>>())?;
    d.set_item("frame_time", clip.frame_time)?;
    d.set_item("rotations", array(py, clip.local_rotations.iter().flat_map(|q| q.to_array()).collect(), &[f, j, 4])?)?;
    d.set_item("positions", array(py, clip.local_positions.iter().flat_map(|p| p.to_array()).collect(), &[f, j, 3])?)?;
    Ok(d)
}

fn order(name: &str) -> PyResult<EulerOrder> {
    EulerOrder::ALL.into_iter().find(|o| o.name().eq_ignore_ascii_case(name)).ok_or_else(|| {
        shape(format!("Euler order {name:?}: give one of xyz, xzy, yxz, yzx, zxy, zyx (the channel order)"))
    })
}

/// Writes a clip given as the arrays of [`read_bvh`] to a `.bvh` file (`.bvh.gz`
/// compressed), through a temporary file and a rename. Rotations are normalised; motion values
/// are written with 6 decimals.
#[pyfunction]
#[pyo3(signature = (path, names, parents, offsets, rotations, positions, frame_time, euler_orders=None, end_sites=None, position_channels=None))]
#[allow(clippy::too_many_arguments)]
pub fn write_bvh(
    path: PathBuf,
    names: Vec<String>,
    parents: PyReadonlyArrayDyn<'_, i32>,
    offsets: PyReadonlyArrayDyn<'_, f64>,
    rotations: PyReadonlyArrayDyn<'_, f64>,
    positions: PyReadonlyArrayDyn<'_, f64>,
    frame_time: f64,
    euler_orders: Option<Vec<String>>,
    end_sites: Option<PyReadonlyArrayDyn<'_, f64>>,
    position_channels: Option<PyReadonlyArrayDyn<'_, bool>>,
) -> PyResult<()> {
    let j = names.len();
    if j == 0 {
        return Err(shape("a BVH clip needs at least one joint"));
    }
    let slice = |name: &str, a: &PyReadonlyArrayDyn<'_, f64>, spec: &[crate::arrays::Dim]| -> PyResult<Vec<f64>> {
        check_shape(name, a.shape(), spec)?;
        Ok(a.to_owned_array().iter().copied().collect())
    };
    check_shape("parents", parents.shape(), &[("J", Some(j))])?;
    let parents: Vec<i32> = parents.to_owned_array().iter().copied().collect();
    let offsets = slice("offsets", &offsets, &[("J", Some(j)), ("", Some(3))])?;
    let f = check_shape("rotations", rotations.shape(), &[("F", None), ("J", Some(j)), ("", Some(4))])?[0];
    let rot = slice("rotations", &rotations, &[("F", Some(f)), ("J", Some(j)), ("", Some(4))])?;
    let pos = slice("positions", &positions, &[("F", Some(f)), ("J", Some(j)), ("", Some(3))])?;
    if !(frame_time.is_finite() && frame_time > 0.0) {
        return Err(shape(format!("frame_time is {frame_time}; give the seconds per frame (> 0)")));
    }
    if let Some(i) = rot.iter().chain(&pos).chain(&offsets).position(|v| !v.is_finite()) {
        return Err(shape(format!("value {i} of the rotations, positions or offsets is not finite")));
    }
    if let Some(i) = rot.chunks_exact(4).position(|q| q.iter().map(|v| v * v).sum::<f64>() < 1e-24) {
        return Err(shape(format!("rotation {i} (frame {}, joint {}) is the zero quaternion", i / j, i % j)));
    }
    let orders = match euler_orders {
        Some(o) if o.len() != j => return Err(shape(format!("{} Euler orders for {j} joints", o.len()))),
        Some(o) => o.iter().map(|s| order(s)).collect::<PyResult<Vec<_>>>()?,
        None => vec![EulerOrder::Zxy; j],
    };
    let ends = match &end_sites {
        Some(e) => slice("end_sites", e, &[("J", Some(j)), ("", Some(3))])?,
        None => vec![f64::NAN; 3 * j],
    };
    let with_pos: Vec<bool> = match &position_channels {
        Some(p) => {
            check_shape("position_channels", p.shape(), &[("J", Some(j))])?;
            p.to_owned_array().iter().copied().collect()
        }
        None => (0..j).map(|i| i == 0).collect(),
    };
    let v3 = |v: &[f64], i: usize| DVec3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    let skeleton = Skeleton {
        names,
        parents: parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
        offsets: (0..j).map(|i| v3(&offsets, i)).collect(),
        end_sites: (0..j).map(|i| Some(v3(&ends, i)).filter(|e| e.is_finite())).collect(),
        channels: (0..j).map(|i| JointChannels { position: with_pos[i], order: orders[i] }).collect(),
    };
    skeleton.validate().map_err(|e| shape(format!("skeleton: {e}")))?;
    let clip = Clip {
        skeleton,
        frame_time,
        local_rotations: rot.chunks_exact(4).map(|q| DQuat::from_xyzw(q[0], q[1], q[2], q[3]).normalize()).collect(),
        local_positions: pos.chunks_exact(3).map(|p| DVec3::new(p[0], p[1], p[2])).collect(),
    };
    source::write_file(&clip, &path).map_err(|e| BvhError::new_err(format!("{}: cannot write: {e}", path.display())))
}

/// A clip's local `rotations` `(F, J, 4)` and `positions` `(F, J, 3)` (float64, one frame every
/// `frame_time` seconds) at `fps` frames per second over the same span: `zoo_motion`'s
/// `Clip::resampled`, the resampling of `zoo data resample` (rotations by slerp on the shortest
/// path, positions linearly, between the two source frames around each new frame). Returns
/// `(rotations, positions)` with `resampled_frames(fps)` frames.
#[pyfunction]
pub fn resample<'py>(
    py: Python<'py>,
    rotations: PyReadonlyArrayDyn<'_, f64>,
    positions: PyReadonlyArrayDyn<'_, f64>,
    frame_time: f64,
    fps: f64,
) -> PyResult<(Bound<'py, PyArrayDyn<f64>>, Bound<'py, PyArrayDyn<f64>>)> {
    let dims = check_shape("rotations", rotations.shape(), &[("F", None), ("J", None), ("", Some(4))])?;
    let (f, j) = (dims[0], dims[1]);
    check_shape("positions", positions.shape(), &[("F", Some(f)), ("J", Some(j)), ("", Some(3))])?;
    if f == 0 || j == 0 {
        return Err(shape("resample: the clip has no frame or no joint"));
    }
    if !(frame_time.is_finite() && frame_time > 0.0) {
        return Err(shape(format!("resample: frame_time is {frame_time}; give the seconds per frame (> 0)")));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(shape(format!("resample: the frame rate must be positive, found {fps}")));
    }
    let rot: Vec<f64> = rotations.to_owned_array().iter().copied().collect();
    let pos: Vec<f64> = positions.to_owned_array().iter().copied().collect();
    if let Some(i) = rot.iter().chain(&pos).position(|v| !v.is_finite()) {
        return Err(crate::error::non_finite(format!(
            "resample: value {i} of the rotations or positions is not finite"
        )));
    }
    // The resampling reads only the frames and the frame time; the skeleton is a placeholder.
    let skeleton = Skeleton {
        names: (0..j).map(|i| format!("j{i}")).collect(),
        parents: (0..j).map(|i| i.checked_sub(1)).collect(),
        offsets: vec![DVec3::ZERO; j],
        end_sites: vec![None; j],
        channels: vec![JointChannels { position: false, order: EulerOrder::Zxy }; j],
    };
    let clip = Clip {
        skeleton,
        frame_time,
        local_rotations: rot.chunks_exact(4).map(|q| DQuat::from_xyzw(q[0], q[1], q[2], q[3])).collect(),
        local_positions: pos.chunks_exact(3).map(|p| DVec3::new(p[0], p[1], p[2])).collect(),
    };
    // A bound on what one call may allocate (100 million joint-frames, 5.6 GB).
    let m = clip.resampled_frames(fps);
    if m.saturating_mul(j) > 100_000_000 {
        return Err(shape(format!(
            "resample: {f} frames at {:.3} fps are {m} frames at {fps} fps; resample a shorter clip",
            1.0 / frame_time
        )));
    }
    let out = clip.resampled(fps);
    let r = array(py, out.local_rotations.iter().flat_map(|q| q.to_array()).collect(), &[m, j, 4])?;
    let p = array(py, out.local_positions.iter().flat_map(|v| v.to_array()).collect(), &[m, j, 3])?;
    Ok((r, p))
}
