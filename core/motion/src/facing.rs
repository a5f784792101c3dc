//! Facing and heading: the character's direction on the ground plane (Y up).

use crate::quat::quat_between;
use glam::{DQuat, DVec3};

/// Heading angle (radians, about +Y) of a direction; 0 along +Z, positive towards +X.
pub fn heading_angle(dir: DVec3) -> f64 {
    dir.x.atan2(dir.z)
}

/// The root's forward direction on the ground: `root_rotation * local_forward` with its Y
/// removed, normalized (zero when it points straight up or down).
pub fn ground_forward(root_rotation: DQuat, local_forward: DVec3) -> DVec3 {
    let f = root_rotation * local_forward;
    DVec3::new(f.x, 0.0, f.z).normalize_or_zero()
}

/// Rotation about +Y that turns `reference` into the ground direction `forward`:
/// `normalize(quat_between(reference, forward))` (benchmark step 5 uses `reference = +X`).
pub fn yaw_between(reference: DVec3, forward: DVec3) -> DQuat {
    quat_between(reference, forward).normalize()
}

/// Rotation about +Y by `angle` radians.
pub fn yaw(angle: f64) -> DQuat {
    DQuat::from_rotation_y(angle)
}

/// Removes everything but the rotation about +Y from `q` (swing-twist decomposition).
pub fn yaw_part(q: DQuat) -> DQuat {
    let t = DQuat::from_xyzw(0.0, q.y, 0.0, q.w);
    if t.length_squared() < 1e-24 { DQuat::IDENTITY } else { t.normalize() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_forward_drops_pitch() {
        let q = DQuat::from_rotation_y(0.5) * DQuat::from_rotation_x(0.4);
        let f = ground_forward(q, DVec3::Z);
        assert!((heading_angle(f) - 0.5).abs() < 1e-12);
        assert!(f.y.abs() < 1e-15);
    }

    #[test]
    fn yaw_between_is_about_y() {
        let f = DVec3::new(0.0, 0.0, -1.0);
        let q = yaw_between(DVec3::X, f);
        assert!((q * DVec3::X - f).length() < 1e-12);
        assert!((yaw_part(q).dot(q)).abs() > 1.0 - 1e-12);
    }
}
