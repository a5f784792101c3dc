//! Quaternion helpers with the conventions of the in-betweening benchmark.

use glam::{DQuat, DVec3};

/// Spherical interpolation from `a` to `b` at `t` in [0, 1], as the benchmark defines it:
/// inputs are normalized, `b` is flipped into `a`'s hemisphere, plain LERP is used when
/// `1 - |dot| < 0.01`, and the output is normalized.
pub fn slerp(a: DQuat, b: DQuat, t: f64) -> DQuat {
    let a = a.normalize();
    let mut b = b.normalize();
    let mut dot = a.dot(b);
    if dot < 0.0 {
        b = -b;
        dot = -dot;
    }
    let (wa, wb) = if 1.0 - dot < 0.01 {
        (1.0 - t, t)
    } else {
        let omega = dot.clamp(-1.0, 1.0).acos();
        let s = omega.sin();
        (((1.0 - t) * omega).sin() / s, (t * omega).sin() / s)
    };
    DQuat::from_xyzw(wa * a.x + wb * b.x, wa * a.y + wb * b.y, wa * a.z + wb * b.z, wa * a.w + wb * b.w).normalize()
}

/// `q` or `-q`, whichever lies in the hemisphere of `reference` (dot >= 0).
#[inline]
pub fn to_hemisphere(q: DQuat, reference: DQuat) -> DQuat {
    if q.dot(reference) < 0.0 { -q } else { q }
}

/// Removes quaternion sign flips over time, per joint: for t >= 1, `q[t]` becomes `-q[t]`
/// when `dot(q[t-1], -q[t]) > dot(q[t-1], q[t])`. `rotations` is frame-major with `joints`
/// entries per frame.
pub fn remove_sign_flips(rotations: &mut [DQuat], joints: usize) {
    for i in joints..rotations.len() {
        let prev = rotations[i - joints];
        if prev.dot(rotations[i]) < 0.0 {
            rotations[i] = -rotations[i];
        }
    }
}

/// The (unnormalized) quaternion turning direction `a` into `b`: `(|a||b| + a.b, a x b)`.
/// Normalize it before use; it is undefined for opposite vectors.
pub fn quat_between(a: DVec3, b: DVec3) -> DQuat {
    let c = a.cross(b);
    let w = (a.length_squared() * b.length_squared()).sqrt() + a.dot(b);
    DQuat::from_xyzw(c.x, c.y, c.z, w)
}

/// Shortest-arc unit rotation from direction `a` to direction `b`, robust for opposite
/// vectors (then a half turn about any axis perpendicular to `a`).
pub fn shortest_arc(a: DVec3, b: DVec3) -> DQuat {
    let (a, b) = (a.normalize_or_zero(), b.normalize_or_zero());
    if a == DVec3::ZERO || b == DVec3::ZERO {
        return DQuat::IDENTITY;
    }
    let d = a.dot(b);
    if d < -1.0 + 1e-12 {
        let axis = a.any_orthonormal_vector();
        return DQuat::from_axis_angle(axis, std::f64::consts::PI);
    }
    quat_between(a, b).normalize()
}

/// Rotation vector (axis * angle, radians) of a unit quaternion, taking the short way.
pub fn to_scaled_axis(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let v = DVec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s < 1e-12 {
        return v * 2.0;
    }
    v * (2.0 * s.atan2(q.w) / s)
}

/// Unit quaternion of a rotation vector (axis * angle, radians).
pub fn from_scaled_axis(v: DVec3) -> DQuat {
    let angle = v.length();
    if angle < 1e-12 {
        return DQuat::from_xyzw(v.x * 0.5, v.y * 0.5, v.z * 0.5, 1.0).normalize();
    }
    DQuat::from_axis_angle(v / angle, angle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn slerp_end_points_and_midpoint() {
        let a = DQuat::IDENTITY;
        let b = DQuat::from_rotation_y(PI / 2.0);
        assert!(slerp(a, b, 0.0).dot(a) > 1.0 - 1e-12);
        assert!(slerp(a, b, 1.0).dot(b) > 1.0 - 1e-12);
        let mid = slerp(a, b, 0.5);
        assert!(mid.dot(DQuat::from_rotation_y(PI / 4.0)) > 1.0 - 1e-12);
    }

    #[test]
    fn slerp_takes_the_short_way() {
        let a = DQuat::from_rotation_z(0.1);
        let b = -DQuat::from_rotation_z(0.5); // same rotation as +, other hemisphere
        let mid = slerp(a, b, 0.5);
        assert!(mid.dot(DQuat::from_rotation_z(0.3)).abs() > 1.0 - 1e-9);
    }

    #[test]
    fn sign_flips_removed() {
        let q = DQuat::from_rotation_x(0.3);
        let mut seq = vec![q, -q, q, -q];
        remove_sign_flips(&mut seq, 1);
        for s in &seq {
            assert!(s.dot(q) > 0.0);
        }
    }

    #[test]
    fn quat_between_turns_a_into_b() {
        let a = DVec3::new(1.0, 0.0, 0.0);
        let b = DVec3::new(0.0, 0.0, 2.0);
        let q = quat_between(a, b).normalize();
        assert!((q * a - b.normalize()).length() < 1e-12);
        let opp = shortest_arc(a, -a);
        assert!((opp * a + a).length() < 1e-12);
    }

    #[test]
    fn scaled_axis_round_trip() {
        let v = DVec3::new(0.3, -1.2, 0.5);
        assert!((to_scaled_axis(from_scaled_axis(v)) - v).length() < 1e-12);
    }
}
