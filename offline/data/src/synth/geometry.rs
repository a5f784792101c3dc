//! Geometry helpers of the synthetic motion: look rotations, two-bone IK, easing curves,
//! angles about +Y.

use glam::{DMat3, DQuat, DVec3};
use std::f64::consts::{PI, TAU};

/// Rotation taking local direction `p_l` to world direction `p_w` exactly and local `s_l` as
/// close as possible to world `s_w` (both pairs orthogonalised against their primary).
pub fn look_rotation(p_l: DVec3, s_l: DVec3, p_w: DVec3, s_w: DVec3) -> DQuat {
    fn frame(p: DVec3, s: DVec3) -> DMat3 {
        let p = p.normalize();
        let mut s = s - p * s.dot(p);
        if s.length_squared() < 1e-12 {
            s = p.any_orthonormal_vector();
        }
        let s = s.normalize();
        DMat3::from_cols(p, s, p.cross(s))
    }
    let ml = frame(p_l, s_l);
    let mw = frame(p_w, s_w);
    DQuat::from_mat3(&(mw * ml.transpose())).normalize()
}

/// Two-bone IK (hip-knee-ankle). Returns `(knee, ankle)`: the ankle equals `target` when
/// `|l1 - l2| <= |target - root| <= l1 + l2`; beyond reach the chain is fully extended
/// toward the target; too close, it folds toward it. The knee bends toward `pole`
/// (any vector not parallel to `target - root`; a perpendicular is chosen otherwise).
pub fn two_bone_ik(root: DVec3, target: DVec3, pole: DVec3, l1: f64, l2: f64) -> (DVec3, DVec3) {
    let to = target - root;
    let dist = to.length();
    let dir = if dist > 1e-9 { to / dist } else { DVec3::NEG_Y };
    let mut perp = pole - dir * pole.dot(dir);
    if perp.length_squared() < 1e-12 {
        perp = dir.any_orthonormal_vector();
    }
    let perp = perp.normalize();
    let d = dist.clamp((l1 - l2).abs(), l1 + l2);
    // Law of cosines: distance along `dir` of the knee's projection.
    let a = ((l1 * l1 - l2 * l2 + d * d) / (2.0 * d.max(1e-9))).clamp(-l1, l1);
    let h = (l1 * l1 - a * a).max(0.0).sqrt();
    let knee = root + dir * a + perp * h;
    let ankle = root + dir * d;
    (knee, ankle)
}

pub(super) fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

pub(super) fn smootherstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * t * (t * (6.0 * t - 15.0) + 10.0)
}

pub(super) fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

pub(super) fn yaw_dir(angle: f64) -> DVec3 {
    DVec3::new(angle.sin(), 0.0, angle.cos())
}

/// Wraps an angle to (-pi, pi].
pub(super) fn wrap(a: f64) -> f64 {
    let mut a = a % TAU;
    if a > PI {
        a -= TAU;
    } else if a <= -PI {
        a += TAU;
    }
    a
}

/// Rotates `v` about unit `axis` by `angle`.
pub(super) fn rot(axis: DVec3, angle: f64, v: DVec3) -> DVec3 {
    DQuat::from_axis_angle(axis, angle) * v
}
