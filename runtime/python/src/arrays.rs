//! numpy arrays in and out: shape checks with clear messages, flat buffers to shaped arrays,
//! and engine poses to and from arrays (one array per field for every frame; no Python object
//! per joint or per frame).
//!
//! Quaternions are `(x, y, z, w)`, as the runtime's glam types store them.

use crate::error::shape;
use glam::{Quat, Vec3};
use numpy::{Element, PyArray1, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use zoo_runtime::EnginePose;

/// A numpy array of any shape, as the package returns them.
pub type Array<'py, T> = Bound<'py, PyArrayDyn<T>>;

/// One dimension of an expected shape: its name in messages and its size, `None` when any
/// size (at least 1) is accepted.
pub type Dim = (&'static str, Option<usize>);

fn show(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    format!("({}{})", parts.join(", "), if shape.len() == 1 { "," } else { "" })
}

fn show_spec(spec: &[Dim]) -> String {
    let parts: Vec<String> = spec
        .iter()
        .map(|(n, s)| match s {
            Some(s) if n.is_empty() => s.to_string(),
            Some(s) => format!("{n}={s}"),
            None => n.to_string(),
        })
        .collect();
    format!("({}{})", parts.join(", "), if spec.len() == 1 { "," } else { "" })
}

/// Checks `shape` against `spec`; returns the sizes.
pub fn check_shape(name: &str, shape: &[usize], spec: &[Dim]) -> PyResult<Vec<usize>> {
    let fits = shape.len() == spec.len() && shape.iter().zip(spec).all(|(d, (_, s))| s.is_none_or(|s| *d == s));
    if !fits || shape.contains(&0) && spec.iter().any(|(_, s)| s.is_none()) {
        return Err(shape_err(name, shape, spec));
    }
    Ok(shape.to_vec())
}

fn shape_err(name: &str, found: &[usize], spec: &[Dim]) -> PyErr {
    shape(format!("`{name}` must have shape {}, found {}", show_spec(spec), show(found)))
}

/// The values of a float32 array of shape `spec` (C-contiguous: the Python layer passes
/// `np.ascontiguousarray(x, dtype=np.float32)`), every value finite.
pub fn values<'a>(name: &str, a: &'a PyReadonlyArrayDyn<'_, f32>, spec: &[Dim]) -> PyResult<(&'a [f32], Vec<usize>)> {
    let dims = check_shape(name, a.shape(), spec)?;
    let v = a.as_slice().map_err(|_| shape(format!("`{name}` must be a C-contiguous float32 array")))?;
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(crate::error::non_finite(format!(
            "`{name}` holds {} at flat index {i}; every value must be finite",
            v[i]
        )));
    }
    Ok((v, dims))
}

/// A flat buffer as a numpy array of `shape`.
pub fn array<'py, T: Element>(py: Python<'py>, data: Vec<T>, shape: &[usize]) -> PyResult<Bound<'py, PyArrayDyn<T>>> {
    PyArray1::from_vec(py, data).reshape(shape.to_vec())
}

/// Engine poses from BVH-style arrays: `hips` (`n * 3`: the hips' world positions) and
/// `rotations` (`n * k * 4`: the hips' world rotation, then every other joint's local
/// rotation), normalised. A zero quaternion is refused.
pub fn poses_from_world(name: &str, hips: &[f32], rotations: &[f32], n: usize, k: usize) -> PyResult<Vec<EnginePose>> {
    let mut out = Vec::with_capacity(n);
    let mut rot = vec![Quat::IDENTITY; k];
    for f in 0..n {
        for j in 0..k {
            let q = Quat::from_slice(&rotations[(f * k + j) * 4..(f * k + j + 1) * 4]);
            if q.length_squared() < 1e-12 {
                return Err(shape(format!(
                    "`{name}` rotation [{f}, {j}] is the zero quaternion; rotations are unit quaternions (x, y, z, w)"
                )));
            }
            rot[j] = q.normalize();
        }
        out.push(EnginePose::from_world(Vec3::from_slice(&hips[f * 3..f * 3 + 3]), &rot));
    }
    Ok(out)
}

/// Global joint positions of `pose` by forward kinematics over a skeleton (`parents`, `-1`
/// for the root; rest `offsets`), into its `global_positions`.
pub fn forward_kinematics(pose: &mut EnginePose, parents: &[i32], offsets: &[Vec3]) {
    let k = pose.joints();
    pose.global_positions.resize(k, Vec3::ZERO);
    let mut world = vec![Quat::IDENTITY; k];
    for j in 0..k {
        match usize::try_from(parents[j]) {
            Err(_) => {
                world[j] = pose.hips_world_rotation();
                pose.global_positions[j] = pose.hips_world();
            }
            Ok(p) => {
                pose.global_positions[j] = pose.global_positions[p] + world[p] * offsets[j];
                world[j] = (world[p] * pose.local_rotations[j]).normalize();
            }
        }
    }
}

/// Poses gathered into one array per field.
pub struct PoseArrays {
    k: usize,
    count: usize,
    root_position: Vec<f32>,
    root_rotation: Vec<f32>,
    root_delta_position: Vec<f32>,
    root_delta_yaw: Vec<f32>,
    hips_position: Vec<f32>,
    local_rotations: Vec<f32>,
    global_positions: Vec<f32>,
    hips: Vec<f32>,
    rotations: Vec<f32>,
}

impl PoseArrays {
    /// Room for `capacity` poses of `k` joints.
    pub fn new(k: usize, capacity: usize) -> Self {
        PoseArrays {
            k,
            count: 0,
            root_position: Vec::with_capacity(capacity * 3),
            root_rotation: Vec::with_capacity(capacity * 4),
            root_delta_position: Vec::with_capacity(capacity * 3),
            root_delta_yaw: Vec::with_capacity(capacity),
            hips_position: Vec::with_capacity(capacity * 3),
            local_rotations: Vec::with_capacity(capacity * k * 4),
            global_positions: Vec::with_capacity(capacity * k * 3),
            hips: Vec::with_capacity(capacity * 3),
            rotations: Vec::with_capacity(capacity * k * 4),
        }
    }

    /// Appends a pose; its global positions must be filled (one per joint).
    pub fn push(&mut self, p: &EnginePose) {
        self.push_fields(p);
        self.hips.extend(p.hips_world().to_array());
        self.rotations.extend(p.hips_world_rotation().to_array());
        for q in &p.local_rotations[1..] {
            self.rotations.extend(q.to_array());
        }
    }

    /// Appends a pose made from the BVH-style `hips` and `rotations` (the hips' world rotation
    /// first, normalised), keeping those values as they are rather than recomputing them from
    /// the root transform (which rounds).
    pub fn push_world(&mut self, p: &EnginePose, hips: &[f32], rotations: &[f32]) {
        self.push_fields(p);
        self.hips.extend_from_slice(hips);
        for q in rotations.chunks_exact(4) {
            self.rotations.extend(Quat::from_slice(q).normalize().to_array());
        }
    }

    fn push_fields(&mut self, p: &EnginePose) {
        debug_assert_eq!(p.global_positions.len(), self.k);
        self.count += 1;
        self.root_position.extend(p.root_position.to_array());
        self.root_rotation.extend(p.root_rotation.to_array());
        self.root_delta_position.extend(p.root_delta_position.to_array());
        self.root_delta_yaw.push(p.root_delta_yaw);
        self.hips_position.extend(p.hips_position.to_array());
        for q in &p.local_rotations {
            self.local_rotations.extend(q.to_array());
        }
        for g in &p.global_positions {
            self.global_positions.extend(g.to_array());
        }
    }

    /// The arrays, each of shape `prefix + field shape` (`prefix` multiplies to the number of
    /// poses pushed), as a dict of the fields of `zoo.Poses`.
    pub fn into_dict<'py>(self, py: Python<'py>, prefix: &[usize]) -> PyResult<Bound<'py, PyDict>> {
        debug_assert_eq!(prefix.iter().product::<usize>(), self.count);
        let k = self.k;
        let with = |tail: &[usize]| -> Vec<usize> { prefix.iter().chain(tail).copied().collect() };
        let d = PyDict::new(py);
        d.set_item("root_position", array(py, self.root_position, &with(&[3]))?)?;
        d.set_item("root_rotation", array(py, self.root_rotation, &with(&[4]))?)?;
        d.set_item("root_delta_position", array(py, self.root_delta_position, &with(&[3]))?)?;
        d.set_item("root_delta_yaw", array(py, self.root_delta_yaw, &with(&[]))?)?;
        d.set_item("hips_position", array(py, self.hips_position, &with(&[3]))?)?;
        d.set_item("local_rotations", array(py, self.local_rotations, &with(&[k, 4]))?)?;
        d.set_item("global_positions", array(py, self.global_positions, &with(&[k, 3]))?)?;
        d.set_item("hips", array(py, self.hips, &with(&[3]))?)?;
        d.set_item("rotations", array(py, self.rotations, &with(&[k, 4]))?)?;
        Ok(d)
    }
}
