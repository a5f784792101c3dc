//! From a scene graph's joint transforms to a [`Clip`]: what the glTF and FBX readers share.
//!
//! A reader gives, for the rest pose and for every sampled frame, each joint's *world*
//! transform in its file's units and axes (rotation, translation and a uniform scale: the
//! scale of the nodes above and on a joint only resizes the skeleton). [`build_clip`] converts
//! them to zoo's frame (centimetres, Y up, right-handed) and expresses every rotation relative
//! to the joint's rest rotation, so that, as in BVH, the rest pose is the identity rotation on
//! every joint and the offsets are the rest bones in world axes. The global joint positions are
//! kept exactly (up to float rounding); the local rotation frames of the file (bone
//! orientations, pre-rotations) are not.

use glam::{DMat3, DQuat, DVec3};
use zoo_motion::{Clip, JointChannels, Skeleton};

/// A world transform with a uniform scale: `x -> t + s * (r * x)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Xform {
    /// Rotation.
    pub r: DQuat,
    /// Translation.
    pub t: DVec3,
    /// Uniform scale (positive).
    pub s: f64,
}

impl Xform {
    /// The identity.
    pub const IDENTITY: Xform = Xform { r: DQuat::IDENTITY, t: DVec3::ZERO, s: 1.0 };

    /// `self * local`: the world transform of a child whose local transform is `local`.
    pub fn then(&self, local: &Xform) -> Xform {
        Xform { r: (self.r * local.r).normalize(), t: self.t + self.s * (self.r * local.t), s: self.s * local.s }
    }
}

/// A local transform with a per-axis scale, as files store it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Trs {
    /// Translation.
    pub t: DVec3,
    /// Rotation (not necessarily normalized).
    pub r: DQuat,
    /// Scale per axis.
    pub s: DVec3,
}

impl Trs {
    /// As an [`Xform`], or why not: a scale that is not uniform and positive (to 1e-4), or a
    /// rotation that is not finite.
    pub fn uniform(&self) -> Result<Xform, String> {
        let s = self.s;
        let m = s.x;
        if !(s.is_finite() && m > 0.0 && (s.y - m).abs() <= 1e-4 * m && (s.z - m).abs() <= 1e-4 * m) {
            return Err(format!(
                "scale ({:.6}, {:.6}, {:.6}) is not uniform and positive; zoo reads rigid skeletons with at most \
                 one uniform scale per node (apply the scale in your DCC tool before exporting)",
                s.x, s.y, s.z
            ));
        }
        let len = self.r.length();
        if !(self.r.is_finite() && self.t.is_finite() && len > 1e-6) {
            return Err("its transform is not finite (or has a zero rotation quaternion)".into());
        }
        Ok(Xform { r: self.r / len, t: self.t, s: (s.x + s.y + s.z) / 3.0 })
    }
}

/// A signed axis permutation and a length scale: `p' = k * m * p`, rotations `m r m^T`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AxisConversion {
    m: DMat3,
    det: f64,
    k: f64,
}

impl AxisConversion {
    /// From a file whose right, up and front axes (zoo's +X, +Y and +Z: a right-handed Y-up
    /// frame) are the given signed file axes (`0..3` = +X, +Y, +Z; `3..6` = -X, -Y, -Z), with
    /// `metres_per_unit`, to zoo's centimetres.
    pub fn from_axes(right: usize, up: usize, front: usize, metres_per_unit: f64) -> Result<Self, String> {
        let e = |a: usize| {
            let mut v = DVec3::ZERO;
            v[a % 3] = if a < 3 { 1.0 } else { -1.0 };
            v
        };
        if right % 3 == up % 3 || up % 3 == front % 3 || right % 3 == front % 3 {
            return Err("its axes repeat one axis (right, up and front must be three different axes)".into());
        }
        // Rows: zoo's x, y, z as combinations of the file's axes.
        let m = DMat3::from_cols(e(right), e(up), e(front)).transpose();
        Self::new(m, metres_per_unit)
    }

    /// glTF's frame (metres, Y up, right-handed) to zoo's centimetres.
    pub fn gltf() -> Self {
        Self { m: DMat3::IDENTITY, det: 1.0, k: 100.0 }
    }

    /// zoo's `frame` to zoo's centimetres (the module table of [`zoo_motion::frame`]).
    #[cfg(test)]
    pub fn from_frame(frame: &zoo_motion::frame::CoordinateFrame) -> Result<Self, String> {
        use zoo_motion::frame::{Handedness, UpAxis};
        // Images of zoo's x, y, z in `frame` (columns), inverted below.
        let to = match (frame.up_axis, frame.handedness) {
            (UpAxis::Y, Handedness::Right) => DMat3::IDENTITY,
            (UpAxis::Y, Handedness::Left) => DMat3::from_cols(-DVec3::X, DVec3::Y, DVec3::Z),
            (UpAxis::Z, Handedness::Right) => DMat3::from_cols(DVec3::X, DVec3::Z, -DVec3::Y),
            (UpAxis::Z, Handedness::Left) => DMat3::from_cols(-DVec3::Y, DVec3::Z, DVec3::X),
        };
        Self::new(to.transpose(), frame.metres_per_unit as f64)
    }

    fn new(m: DMat3, metres_per_unit: f64) -> Result<Self, String> {
        if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
            return Err(format!("its unit ({metres_per_unit} metres) is not a positive length"));
        }
        Ok(Self { m, det: m.determinant().signum(), k: metres_per_unit / 0.01 })
    }

    /// The inverse conversion (zoo's centimetres to the file's frame).
    #[cfg(test)]
    pub fn inverse(&self) -> Self {
        Self { m: self.m.transpose(), det: self.det, k: 1.0 / self.k }
    }

    /// A position.
    pub fn position(&self, p: DVec3) -> DVec3 {
        self.k * (self.m * p)
    }

    /// A rotation: `m r m^T` (a reflection reverses the sense of rotation).
    pub fn rotation(&self, q: DQuat) -> DQuat {
        let v = self.det * (self.m * DVec3::new(q.x, q.y, q.z));
        DQuat::from_xyzw(v.x, v.y, v.z, q.w)
    }
}

/// Joints of a scene, in an order where parents come first, and their end sites.
#[derive(Clone, Debug)]
pub(crate) struct SceneRig {
    /// Joint names.
    pub names: Vec<String>,
    /// Parents (`None` for the root only), before their children.
    pub parents: Vec<Option<usize>>,
    /// Rest world transform of every joint (file frame).
    pub rest: Vec<Xform>,
    /// End sites: (joint, rest world position of the tip), file frame.
    pub end_sites: Vec<(usize, DVec3)>,
}

/// Tolerance (cm) under which a joint's per-frame translation is its rest offset: what is left
/// is float rounding of the file (f32) and of the world-to-local conversion.
const OFFSET_SNAP_CM: f64 = 1e-3;

/// Builds a clip from world transforms: `frames[f * J + j]` is joint `j`'s world transform at
/// frame `f` (file frame), converted by `conv`. See the module documentation.
pub(crate) fn build_clip(rig: &SceneRig, frames: &[Xform], frame_time: f64, conv: &AxisConversion) -> Clip {
    let nj = rig.names.len();
    let n = frames.len() / nj.max(1);
    // Rest, converted: positions and inverse rotations.
    let rest_p: Vec<DVec3> = rig.rest.iter().map(|x| conv.position(x.t)).collect();
    let rest_inv: Vec<DQuat> = rig.rest.iter().map(|x| conv.rotation(x.r).inverse()).collect();
    let offsets: Vec<DVec3> = (0..nj).map(|j| rig.parents[j].map_or(rest_p[j], |p| rest_p[j] - rest_p[p])).collect();
    let mut end_sites = vec![None; nj];
    for &(j, tip) in &rig.end_sites {
        end_sites[j] = Some(conv.position(tip) - rest_p[j]);
    }
    let mut rot = vec![DQuat::IDENTITY; n * nj];
    let mut pos = vec![DVec3::ZERO; n * nj];
    let mut world_r = vec![DQuat::IDENTITY; nj];
    let mut world_p = vec![DVec3::ZERO; nj];
    for f in 0..n {
        for j in 0..nj {
            let x = &frames[f * nj + j];
            world_r[j] = (conv.rotation(x.r) * rest_inv[j]).normalize();
            world_p[j] = conv.position(x.t);
        }
        for j in 0..nj {
            let (r, p) = match rig.parents[j] {
                None => (world_r[j], world_p[j]),
                Some(q) => {
                    let inv = world_r[q].inverse();
                    ((inv * world_r[j]).normalize(), inv * (world_p[j] - world_p[q]))
                }
            };
            rot[f * nj + j] = r;
            pos[f * nj + j] = p;
        }
    }
    let mut channels = vec![JointChannels::default(); nj];
    for j in 0..nj {
        if rig.parents[j].is_none() {
            channels[j].position = true;
            continue;
        }
        let moves = (0..n).any(|f| (pos[f * nj + j] - offsets[j]).abs().max_element() > OFFSET_SNAP_CM);
        if moves {
            channels[j].position = true;
        } else {
            for f in 0..n {
                pos[f * nj + j] = offsets[j];
            }
        }
    }
    let skeleton = Skeleton { names: rig.names.clone(), parents: rig.parents.clone(), offsets, end_sites, channels };
    Clip { skeleton, frame_time, local_rotations: rot, local_positions: pos }
}

/// Whether a leaf joint's name marks it as the tip of its parent's bone rather than a joint:
/// Blender's leaf bones (`*_end`), Mixamo's (`HeadTop_End`), 3ds Max's (`*Nub`), and the
/// `*_end` joints zoo's glTF writer adds for BVH end sites.
pub(crate) fn is_tip_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n.ends_with("end") || n.ends_with("nub")
}

/// Drops a dummy root like [`crate::bvh::ReadOptions::drop_dummy_root`] does for BVH: a root
/// with one child, a zero offset and no motion (to `1e-4` cm and `1e-6` of a quaternion).
/// Returns whether it did.
pub(crate) fn drop_still_dummy_root(clip: &mut Clip) -> bool {
    let nj = clip.joints();
    let s = &clip.skeleton;
    if nj < 2 || s.children(0) != [1] || s.offsets[0].length() > 1e-4 {
        return false;
    }
    let still = (0..clip.frames()).all(|f| {
        let (r, p) = (clip.local_rotations[f * nj], clip.local_positions[f * nj]);
        p.length() <= 1e-4 && (r.w.abs() - 1.0).abs() <= 1e-6
    });
    if still {
        clip.skeleton.offsets[0] = DVec3::ZERO;
        clip.drop_root()
    } else {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::frame::{CoordinateFrame, Handedness, UpAxis};

    #[test]
    fn axis_conversions_match_zoo_frames() {
        // Blender: Z up, right-handed, metres: zoo (x, y, z) is Blender (x, -z, y).
        let blender = AxisConversion::from_axes(0, 2, 4, 1.0).unwrap();
        let f = CoordinateFrame::metres(UpAxis::Z, Handedness::Right);
        let same = AxisConversion::from_frame(&f).unwrap();
        let p = DVec3::new(1.0, 2.0, 3.0);
        // Blender's (1, 2, 3) m is zoo's (100, 300, -200) cm.
        assert!((blender.position(p) - DVec3::new(100.0, 300.0, -200.0)).length() < 1e-12);
        assert!((same.position(p) - blender.position(p)).length() < 1e-12);
        let q = DQuat::from_axis_angle(DVec3::new(0.3, -0.5, 0.8).normalize(), 1.1);
        for c in [blender, AxisConversion::from_axes(3, 1, 2, 0.01).unwrap()] {
            let a = c.position(q * p);
            let b = c.rotation(q) * c.position(p);
            assert!((a - b).length() < 1e-9, "{a} vs {b}");
            let back = c.inverse();
            assert!((back.position(c.position(p)) - p).length() < 1e-12);
        }
        assert!(AxisConversion::from_axes(0, 0, 4, 1.0).is_err());
    }

    #[test]
    fn rest_rotations_are_baked_and_positions_kept() {
        // Two joints; the rest has rotated bone frames (as FBX bones do).
        let r0 = DQuat::from_rotation_z(0.7);
        let rig = SceneRig {
            names: vec!["a".into(), "b".into()],
            parents: vec![None, Some(0)],
            rest: vec![
                Xform { r: r0, t: DVec3::new(0.0, 1.0, 0.0), s: 1.0 },
                Xform { r: r0, t: DVec3::new(0.0, 1.0, 0.0) + r0 * DVec3::X, s: 1.0 },
            ],
            end_sites: vec![],
        };
        let turn = DQuat::from_rotation_y(0.4);
        let a = Xform { r: turn * r0, t: DVec3::new(0.5, 1.0, 0.0), s: 1.0 };
        let b = a.then(&Xform { r: DQuat::IDENTITY, t: DVec3::X, s: 1.0 });
        let clip = build_clip(&rig, &[rig.rest[0], rig.rest[1], a, b], 0.1, &AxisConversion::gltf());
        assert!(clip.local_rotations[0].angle_between(DQuat::IDENTITY) < 1e-12);
        assert!(clip.local_rotations[2].angle_between(turn) < 1e-12);
        let (_, gp) = clip.global();
        assert!((gp[3] - 100.0 * b.t).length() < 1e-9);
        assert!((clip.skeleton.offsets[1] - 100.0 * (r0 * DVec3::X)).length() < 1e-9);
        assert!(!clip.skeleton.channels[1].position);
    }
}
