//! The engine pose ([`EnginePose`]: root motion plus local joint rotations, what a skinned
//! character is posed with) and conversions between glam types and the flat `f32` buffers the
//! runner takes.
//!
//! Flat layout: joint-major, `[x0, y0, z0, x1, y1, z1, ...]` (3 values per joint).

use glam::{DQuat, DVec3, Quat, Vec3};
use zoo_motion::facing::yaw_part;
pub use zoo_motion::frame::{Conversion, CoordinateFrame, Handedness, UpAxis};

/// A character pose as a game engine consumes it: a root transform on the ground that carries
/// the character (root motion), the hips relative to it, and every joint's local rotation in
/// the model skeleton's order. Y is up, right-handed; units are the model's (its file's
/// `frame`); [`EnginePose::convert`] converts to an engine's units and axes.
///
/// World space: `hips = root_position + root_rotation * hips_position`, the hips' world
/// rotation is `root_rotation * local_rotations[0]`, and every other joint `j` is its parent's
/// world transform times (`local_rotations[j]`, the skeleton's rest offset of `j`): the bone
/// lengths are the skeleton's, exactly.
///
/// Allocate one per character with [`EnginePose::new`] and reuse it: the runtime writes into
/// its buffers without allocating.
#[derive(Clone, Debug, PartialEq)]
pub struct EnginePose {
    /// The hips projected on the ground (`y = 0`).
    pub root_position: Vec3,
    /// The character's facing: the rotation about +Y of the hips' world rotation.
    pub root_rotation: Quat,
    /// Root displacement since the previous frame, in the previous frame's root space (zero
    /// on input and on a transition's first frame before the context).
    pub root_delta_position: Vec3,
    /// Root turn since the previous frame about +Y, radians (positive: counter-clockwise seen
    /// from above, towards +X from +Z).
    pub root_delta_yaw: f32,
    /// The hips' position in root space.
    pub hips_position: Vec3,
    /// Local rotation of every joint; the hips' (joint 0) is relative to the root transform.
    pub local_rotations: Vec<Quat>,
    /// Global joint positions, filled when this buffer has one entry per joint (from
    /// [`EnginePose::with_global_positions`]); left empty otherwise.
    pub global_positions: Vec<Vec3>,
}

impl EnginePose {
    /// A rest pose of `joints` joints at the origin, without global positions.
    pub fn new(joints: usize) -> Self {
        EnginePose {
            root_position: Vec3::ZERO,
            root_rotation: Quat::IDENTITY,
            root_delta_position: Vec3::ZERO,
            root_delta_yaw: 0.0,
            hips_position: Vec3::ZERO,
            local_rotations: vec![Quat::IDENTITY; joints],
            global_positions: Vec::new(),
        }
    }

    /// [`EnginePose::new`] that also receives global joint positions.
    pub fn with_global_positions(joints: usize) -> Self {
        EnginePose { global_positions: vec![Vec3::ZERO; joints], ..Self::new(joints) }
    }

    /// Number of joints.
    pub fn joints(&self) -> usize {
        self.local_rotations.len()
    }

    /// Converts the pose in place from the model's coordinate frame (its file's
    /// [`crate::metadata::MotionModelMetadata::frame`]) to an engine's: positions scaled and
    /// re-axed, rotations conjugated, the yaw delta reversed by a change of handedness (see
    /// [`zoo_motion::frame`]). Build the conversion once with
    /// `Conversion::between(&model.metadata().frame, &engine_frame)` and convert the
    /// skeleton's rest offsets with [`Conversion::position`] too. No allocation.
    ///
    /// After the conversion the pose is in the engine's frame: its root still sits on the
    /// ground plane and turns about the (new) up axis; the relations of [`EnginePose`] hold with
    /// the converted offsets.
    pub fn convert(&mut self, c: &Conversion) {
        self.root_position = c.position(self.root_position);
        self.root_rotation = c.rotation(self.root_rotation);
        self.root_delta_position = c.position(self.root_delta_position);
        self.root_delta_yaw = c.yaw(self.root_delta_yaw);
        self.hips_position = c.position(self.hips_position);
        for q in &mut self.local_rotations {
            *q = c.rotation(*q);
        }
        for p in &mut self.global_positions {
            *p = c.position(*p);
        }
    }

    /// The pose of a character given in world space, as BVH stores it: the hips' world
    /// position and rotation (`rotations[0]`) and every other joint's local rotation.
    pub fn from_world(hips: Vec3, rotations: &[Quat]) -> Self {
        let mut pose = Self::new(rotations.len());
        pose.set_world(hips, rotations);
        pose
    }

    /// Sets the pose from the hips' world position and rotations as in
    /// [`EnginePose::from_world`] (`rotations.len()` must equal [`EnginePose::joints`]); the
    /// deltas are left as they are.
    pub fn set_world(&mut self, hips: Vec3, rotations: &[Quat]) {
        let hips_rotation = rotations.first().copied().unwrap_or(Quat::IDENTITY).normalize();
        let (root_position, root_rotation) = root_of(hips, hips_rotation);
        let inverse = root_rotation.inverse();
        self.root_position = root_position;
        self.root_rotation = root_rotation;
        self.hips_position = inverse * (hips - root_position);
        self.local_rotations.copy_from_slice(rotations);
        if let Some(q) = self.local_rotations.first_mut() {
            *q = (inverse * hips_rotation).normalize();
        }
    }

    /// The hips' world position.
    pub fn hips_world(&self) -> Vec3 {
        self.root_position + self.root_rotation * self.hips_position
    }

    /// The hips' world rotation.
    pub fn hips_world_rotation(&self) -> Quat {
        (self.root_rotation * self.local_rotations.first().copied().unwrap_or(Quat::IDENTITY)).normalize()
    }
}

/// The root transform of a character whose hips are at `hips` with world rotation
/// `hips_rotation`: the hips projected on the ground and the yaw of their rotation.
pub fn root_of(hips: Vec3, hips_rotation: Quat) -> (Vec3, Quat) {
    let yaw = yaw_part(hips_rotation.as_dquat()).as_quat();
    (Vec3::new(hips.x, 0.0, hips.z), yaw)
}

/// The root motion from root transform `(p0, q0)` to `(p1, q1)`: the displacement in `q0`'s
/// space and the turn about +Y in radians.
pub fn root_delta(p0: Vec3, q0: Quat, p1: Vec3, q1: Quat) -> (Vec3, f32) {
    let inverse = q0.inverse();
    let turn = (inverse * q1).normalize();
    // A rotation about +Y by a: (0, sin(a/2), 0, cos(a/2)).
    let yaw = 2.0 * turn.y.atan2(turn.w);
    let yaw = if yaw > std::f32::consts::PI { yaw - std::f32::consts::TAU } else { yaw };
    let yaw = if yaw < -std::f32::consts::PI { yaw + std::f32::consts::TAU } else { yaw };
    (inverse * (p1 - p0), yaw)
}

/// Converts between f32 glam values and the motion core's f64 ones.
pub(crate) fn to_dvec3(v: Vec3) -> DVec3 {
    v.as_dvec3()
}

/// See [`to_dvec3`].
pub(crate) fn to_dquat(q: Quat) -> DQuat {
    q.as_dquat()
}

/// Writes joint positions into a flat buffer. `dst.len()` must be `3 * src.len()`.
/// Returns `false` (writing nothing) when the lengths do not match.
pub fn write_positions(src: &[Vec3], dst: &mut [f32]) -> bool {
    if dst.len() != 3 * src.len() {
        return false;
    }
    for (p, d) in src.iter().zip(dst.chunks_exact_mut(3)) {
        d.copy_from_slice(&p.to_array());
    }
    true
}

/// Reads joint positions from a flat buffer. `src.len()` must be `3 * dst.len()`.
/// Returns `false` (reading nothing) when the lengths do not match.
pub fn read_positions(src: &[f32], dst: &mut [Vec3]) -> bool {
    if src.len() != 3 * dst.len() {
        return false;
    }
    for (s, p) in src.chunks_exact(3).zip(dst.iter_mut()) {
        *p = Vec3::from_slice(s);
    }
    true
}

/// Writes joint rotations into a flat buffer, 4 values per joint in glam order `x, y, z, w`.
/// Returns `false` (writing nothing) when `dst.len() != 4 * src.len()`.
pub fn write_rotations(src: &[Quat], dst: &mut [f32]) -> bool {
    if dst.len() != 4 * src.len() {
        return false;
    }
    for (q, d) in src.iter().zip(dst.chunks_exact_mut(4)) {
        d.copy_from_slice(&q.to_array());
    }
    true
}

/// Reads joint rotations (`x, y, z, w` per joint) and normalizes them.
/// Returns `false` (reading nothing) when `src.len() != 4 * dst.len()`.
pub fn read_rotations(src: &[f32], dst: &mut [Quat]) -> bool {
    if src.len() != 4 * dst.len() {
        return false;
    }
    for (s, q) in src.chunks_exact(4).zip(dst.iter_mut()) {
        *q = Quat::from_slice(s).normalize();
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_length_checks() {
        let p = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)];
        let mut flat = [0.0; 6];
        assert!(write_positions(&p, &mut flat));
        assert_eq!(flat, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let mut back = [Vec3::ZERO; 2];
        assert!(read_positions(&flat, &mut back));
        assert_eq!(back, p);
        assert!(!read_positions(&flat[..5], &mut back));
        let q = [Quat::from_rotation_y(0.5)];
        let mut flat = [0.0; 4];
        assert!(write_rotations(&q, &mut flat));
        let mut back = [Quat::IDENTITY];
        assert!(read_rotations(&flat, &mut back));
        assert!(back[0].abs_diff_eq(q[0], 1e-6));
    }

    #[test]
    fn engine_pose_splits_the_hips_into_root_and_hips() {
        let hips = Vec3::new(10.0, 90.0, -4.0);
        let rot = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.2);
        let spine = Quat::from_rotation_z(0.3);
        let pose = EnginePose::from_world(hips, &[rot, spine]);
        assert_eq!(pose.root_position, Vec3::new(10.0, 0.0, -4.0));
        assert!(pose.root_rotation.abs_diff_eq(Quat::from_rotation_y(0.7), 1e-6));
        assert!(pose.hips_world().abs_diff_eq(hips, 1e-5));
        assert!(pose.hips_world_rotation().abs_diff_eq(rot, 1e-6));
        assert!(pose.local_rotations[0].abs_diff_eq(Quat::from_rotation_x(0.2), 1e-6));
        assert_eq!(pose.local_rotations[1], spine);
        assert!(pose.hips_position.abs_diff_eq(Vec3::new(0.0, 90.0, 0.0), 1e-5));
    }

    #[test]
    fn root_delta_is_in_the_previous_root_space() {
        let (p0, q0) = (Vec3::new(1.0, 0.0, 2.0), Quat::from_rotation_y(std::f32::consts::FRAC_PI_2));
        // Facing +X (yaw 90 degrees), one unit forward along +X is +Z in root space.
        let (p1, q1) = (Vec3::new(2.0, 0.0, 2.0), Quat::from_rotation_y(std::f32::consts::FRAC_PI_2 + 0.1));
        let (d, yaw) = root_delta(p0, q0, p1, q1);
        assert!(d.abs_diff_eq(Vec3::new(0.0, 0.0, 1.0), 1e-6), "{d}");
        assert!((yaw - 0.1).abs() < 1e-6, "{yaw}");
        let (_, yaw) = root_delta(p0, Quat::from_rotation_y(3.1), p1, Quat::from_rotation_y(-3.1));
        assert!((yaw - (std::f32::consts::TAU - 6.2)).abs() < 1e-5, "{yaw}");
    }

    /// World positions of a 3-joint chain posed by `pose` with rest `offsets` (the relations
    /// documented on [`EnginePose`]).
    fn chain_world(pose: &EnginePose, offsets: &[Vec3]) -> Vec<Vec3> {
        let mut pos = vec![pose.hips_world()];
        let mut rot = pose.hips_world_rotation();
        for j in 1..offsets.len() {
            let p = pos[j - 1] + rot * offsets[j];
            rot *= pose.local_rotations[j];
            pos.push(p);
        }
        pos
    }

    #[test]
    fn converted_poses_skin_to_the_converted_positions() {
        let hips = Vec3::new(10.0, 90.0, -4.0);
        let rots = [
            Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.2),
            Quat::from_rotation_z(0.3),
            Quat::from_rotation_x(-0.8),
        ];
        let offsets = [Vec3::ZERO, Vec3::new(0.0, 20.0, 2.0), Vec3::new(5.0, 30.0, 0.0)];
        let mut pose = EnginePose::from_world(hips, &rots);
        pose.root_delta_position = Vec3::new(1.0, 0.0, 2.0);
        pose.root_delta_yaw = 0.1;
        let world = chain_world(&pose, &offsets);
        for to in [
            CoordinateFrame::metres(UpAxis::Z, Handedness::Right),
            CoordinateFrame::metres(UpAxis::Y, Handedness::Left),
            CoordinateFrame { metres_per_unit: 0.01, up_axis: UpAxis::Z, handedness: Handedness::Left },
        ] {
            let c = Conversion::between(&CoordinateFrame::ZOO_CM, &to);
            let mut converted = pose.clone();
            converted.convert(&c);
            let offs: Vec<Vec3> = offsets.iter().map(|o| c.position(*o)).collect();
            let got = chain_world(&converted, &offs);
            for (g, w) in got.iter().zip(&world) {
                let want = c.position(*w);
                assert!((*g - want).length() <= 1e-4 * want.length().max(1.0), "{to:?}: {g} vs {want}");
            }
            // The root stays on the ground plane of the new up axis and turns about it.
            let up = c.direction(Vec3::Y);
            assert!(converted.root_position.dot(up).abs() < 1e-5, "{to:?}");
            let axis = converted.root_rotation.to_axis_angle().0;
            assert!(axis.cross(up).length() < 1e-4, "{to:?}: root turns about {axis}");
            assert_eq!(converted.root_delta_yaw, c.yaw(0.1));
        }
    }
}
