//! Euler angles <-> quaternions for the six rotation orders used by BVH files.

use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// The order of three rotation channels, as written in a BVH `CHANNELS` line.
///
/// `Zxy` means the channels read `Zrotation Xrotation Yrotation` and the joint's rotation is
/// `q = qz(a) * qx(b) * qy(c)` (intrinsic Z, then X, then Y), which is how BVH files and the
/// LaFAN1 tooling interpret them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EulerOrder {
    /// `q = qx * qy * qz`
    Xyz,
    /// `q = qx * qz * qy`
    Xzy,
    /// `q = qy * qx * qz`
    Yxz,
    /// `q = qy * qz * qx`
    Yzx,
    /// `q = qz * qx * qy`
    Zxy,
    /// `q = qz * qy * qx`
    Zyx,
}

impl EulerOrder {
    /// All six orders.
    pub const ALL: [EulerOrder; 6] =
        [EulerOrder::Xyz, EulerOrder::Xzy, EulerOrder::Yxz, EulerOrder::Yzx, EulerOrder::Zxy, EulerOrder::Zyx];

    /// Axis indices (0 = X, 1 = Y, 2 = Z) in channel order.
    pub fn axes(self) -> [usize; 3] {
        match self {
            EulerOrder::Xyz => [0, 1, 2],
            EulerOrder::Xzy => [0, 2, 1],
            EulerOrder::Yxz => [1, 0, 2],
            EulerOrder::Yzx => [1, 2, 0],
            EulerOrder::Zxy => [2, 0, 1],
            EulerOrder::Zyx => [2, 1, 0],
        }
    }

    /// The order whose channel axes are `axes` (each of 0, 1, 2 once).
    pub fn from_axes(axes: [usize; 3]) -> Option<EulerOrder> {
        EulerOrder::ALL.into_iter().find(|o| o.axes() == axes)
    }

    /// Lower-case name such as `"zxy"`.
    pub fn name(self) -> &'static str {
        match self {
            EulerOrder::Xyz => "xyz",
            EulerOrder::Xzy => "xzy",
            EulerOrder::Yxz => "yxz",
            EulerOrder::Yzx => "yzx",
            EulerOrder::Zxy => "zxy",
            EulerOrder::Zyx => "zyx",
        }
    }

    /// Quaternion from three angles in **degrees**, given in channel order.
    pub fn to_quat_deg(self, angles: [f64; 3]) -> DQuat {
        self.to_quat_rad(angles.map(f64::to_radians))
    }

    /// Quaternion from three angles in radians, given in channel order.
    pub fn to_quat_rad(self, angles: [f64; 3]) -> DQuat {
        let ax = self.axes();
        axis_quat(ax[0], angles[0]) * axis_quat(ax[1], angles[1]) * axis_quat(ax[2], angles[2])
    }

    /// Angles in **degrees**, in channel order, of a unit quaternion.
    ///
    /// The middle angle lies in [-90, 90]; at gimbal lock the third angle is set to 0.
    pub fn from_quat_deg(self, q: DQuat) -> [f64; 3] {
        self.from_quat_rad(q).map(f64::to_degrees)
    }

    /// Angles in radians, in channel order, of a unit quaternion (see [`Self::from_quat_deg`]).
    pub fn from_quat_rad(self, q: DQuat) -> [f64; 3] {
        // R = R_i(a) R_j(b) R_k(c) with (i, j, k) the channel axes. Standard decomposition for
        // Tait-Bryan angles; `sign` is +1 for cyclic (i, j, k) orders and -1 otherwise.
        let [i, j, k] = self.axes();
        let m = DMat3::from_quat(q.normalize());
        let r = |row: usize, col: usize| m.col(col)[row];
        let sign = if (j + 3 - i) % 3 == 1 { 1.0 } else { -1.0 };
        let sb = (sign * r(i, k)).clamp(-1.0, 1.0);
        let b = sb.asin();
        if sb.abs() < 1.0 - 1e-12 {
            let a = (-sign * r(j, k)).atan2(r(k, k));
            let c = (-sign * r(i, j)).atan2(r(i, i));
            [a, b, c]
        } else {
            // Gimbal lock: only a +/- c is defined; put it all in a.
            let a = (sign * r(k, j)).atan2(r(j, j));
            [a, b, 0.0]
        }
    }
}

impl std::str::FromStr for EulerOrder {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        EulerOrder::ALL
            .into_iter()
            .find(|o| o.name() == lower)
            .ok_or_else(|| format!("unknown rotation order `{s}`: expected one of xyz, xzy, yxz, yzx, zxy, zyx"))
    }
}

/// Rotation of `angle` radians about coordinate axis `axis` (0 = X, 1 = Y, 2 = Z).
pub fn axis_quat(axis: usize, angle: f64) -> DQuat {
    let v = match axis {
        0 => DVec3::X,
        1 => DVec3::Y,
        _ => DVec3::Z,
    };
    DQuat::from_axis_angle(v, angle)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DQuat, b: DQuat) -> bool {
        // same rotation: q or -q
        (a.dot(b).abs() - 1.0).abs() < 1e-12
    }

    #[test]
    fn zxy_is_z_then_x_then_y() {
        // Hand-computed: 90 deg about Z, then (intrinsic) 90 deg about X.
        // Rz(90) maps X->Y; the composite Rz Rx maps local Y to Rz(Z) = Z... check on vectors.
        let q = EulerOrder::Zxy.to_quat_deg([90.0, 90.0, 0.0]);
        // Rz(90) Rx(90) applied to Y: Rx(90) Y = Z, Rz(90) Z = Z.
        assert!((q * DVec3::Y - DVec3::Z).length() < 1e-12);
        // applied to Z: Rx(90) Z = -Y, Rz(90) (-Y) = X.
        assert!((q * DVec3::Z - DVec3::X).length() < 1e-12);
        // applied to X: Rx X = X, Rz(90) X = Y.
        assert!((q * DVec3::X - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn single_axis_angles_match_axis_angle() {
        for order in EulerOrder::ALL {
            let ax = order.axes();
            for slot in 0..3 {
                let mut angles = [0.0; 3];
                angles[slot] = 30.0;
                let q = order.to_quat_deg(angles);
                assert!(close(q, axis_quat(ax[slot], 30f64.to_radians())), "{order:?} slot {slot}");
            }
        }
    }

    #[test]
    fn xyz_hand_computed() {
        // Rx(90) Ry(90): Y -> Ry Y = Y -> Rx Y = Z.  X -> Ry X = -Z -> Rx(-Z) = Y.
        let q = EulerOrder::Xyz.to_quat_deg([90.0, 90.0, 0.0]);
        assert!((q * DVec3::Y - DVec3::Z).length() < 1e-12);
        assert!((q * DVec3::X - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn round_trip_every_order() {
        let samples =
            [[10.0, 20.0, 30.0], [-170.0, 80.0, 5.0], [45.0, -60.0, 179.0], [0.0, 0.0, 0.0], [123.0, -1.0, -77.0]];
        for order in EulerOrder::ALL {
            for s in samples {
                let q = order.to_quat_deg(s);
                let back = order.from_quat_deg(q);
                for k in 0..3 {
                    assert!((back[k] - s[k]).abs() < 1e-9, "{order:?} {s:?} -> {back:?}");
                }
            }
        }
    }

    #[test]
    fn gimbal_lock_keeps_rotation() {
        for order in EulerOrder::ALL {
            let q = order.to_quat_deg([30.0, 90.0, 20.0]);
            let back = order.to_quat_deg(order.from_quat_deg(q));
            assert!(close(q, back), "{order:?}");
        }
    }
}
