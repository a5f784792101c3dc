//! Coordinate frames: the length unit, the up axis and the handedness in which positions and
//! rotations are expressed, and the conversion between two frames (for engines whose
//! convention differs from the data's).
//!
//! zoo's own frame is the BVH data's: **Y up, right-handed**, lengths in the clip's unit
//! (bandai2 and the synthetic data: centimetres), characters facing +Z (their left is +X).
//! The other frames are defined from it by a signed permutation of the axes:
//!
//! | frame                          | maps zoo's (x, y, z) to | typical user           |
//! |--------------------------------|-------------------------|------------------------|
//! | Y up, right-handed             | (x, y, z)               | zoo, BVH, Maya, Godot  |
//! | Y up, left-handed              | (-x, y, z)              | Unity                  |
//! | Z up, right-handed             | (x, -z, y)              | Blender (faces -Y)     |
//! | Z up, left-handed              | (z, -x, y)              | Unreal (faces +X)      |
//!
//! A conversion scales positions by the ratio of the units and applies `M`, the signed
//! permutation from the source frame to the target frame: `p' = s M p`. A rotation `R` becomes
//! `M R M^T`; for a quaternion `(w, v)` that is `(w, det(M) M v)` (a reflection reverses the
//! sense of every rotation).

use glam::{Mat3, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// The axis pointing up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    /// +Y up (zoo, BVH, Unity, Maya).
    Y,
    /// +Z up (Blender, Unreal).
    Z,
}

/// The handedness of the axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Handedness {
    /// Right-handed (zoo, BVH, Blender, Maya, Godot).
    Right,
    /// Left-handed (Unity, Unreal).
    Left,
}

/// How positions and rotations are expressed (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoordinateFrame {
    /// Metres per length unit (0.01 for centimetres, 1 for metres).
    pub metres_per_unit: f32,
    /// The up axis.
    pub up_axis: UpAxis,
    /// The handedness.
    pub handedness: Handedness,
}

impl CoordinateFrame {
    /// zoo's frame with centimetres: the data's (bandai2, the synthetic locomotion).
    pub const ZOO_CM: CoordinateFrame =
        CoordinateFrame { metres_per_unit: 0.01, up_axis: UpAxis::Y, handedness: Handedness::Right };

    /// A frame with these axes and metres.
    pub fn metres(up_axis: UpAxis, handedness: Handedness) -> Self {
        CoordinateFrame { metres_per_unit: 1.0, up_axis, handedness }
    }

    /// The unit's name when it is a common one (`cm`, `m`, `mm`, `in`), else `None`.
    pub fn unit_name(&self) -> Option<&'static str> {
        [(0.01, "cm"), (1.0, "m"), (0.001, "mm"), (0.0254, "in")]
            .into_iter()
            .find(|(m, _)| (self.metres_per_unit - m).abs() <= 1e-6 * m)
            .map(|(_, n)| n)
    }

    /// Metres per unit of a unit name (`cm`, `m`, `mm`, `in`).
    pub fn metres_per(unit: &str) -> Option<f32> {
        match unit {
            "cm" => Some(0.01),
            "m" => Some(1.0),
            "mm" => Some(0.001),
            "in" => Some(0.0254),
            _ => None,
        }
    }

    /// Checks the frame: a finite, positive unit.
    pub fn check(&self) -> Result<(), String> {
        if self.metres_per_unit.is_finite() && self.metres_per_unit > 0.0 {
            Ok(())
        } else {
            Err(format!("metres_per_unit must be a positive number, got {}", self.metres_per_unit))
        }
    }

    /// The signed permutation taking zoo's axes to this frame's (module table).
    fn from_zoo_axes(&self) -> Mat3 {
        // Columns are the images of zoo's x, y and z.
        match (self.up_axis, self.handedness) {
            (UpAxis::Y, Handedness::Right) => Mat3::IDENTITY,
            (UpAxis::Y, Handedness::Left) => Mat3::from_cols(-Vec3::X, Vec3::Y, Vec3::Z),
            (UpAxis::Z, Handedness::Right) => Mat3::from_cols(Vec3::X, Vec3::Z, -Vec3::Y),
            (UpAxis::Z, Handedness::Left) => Mat3::from_cols(-Vec3::Y, Vec3::Z, Vec3::X),
        }
    }
}

/// A conversion of positions and rotations from one [`CoordinateFrame`] to another.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conversion {
    scale: f32,
    axes: Mat3,
    det: f32,
}

impl Conversion {
    /// The conversion from `from` to `to`.
    pub fn between(from: &CoordinateFrame, to: &CoordinateFrame) -> Self {
        let axes = to.from_zoo_axes() * from.from_zoo_axes().transpose();
        Conversion { scale: from.metres_per_unit / to.metres_per_unit, axes, det: axes.determinant().signum() }
    }

    /// Whether the conversion changes nothing.
    pub fn is_identity(&self) -> bool {
        self.scale == 1.0 && self.axes == Mat3::IDENTITY
    }

    /// The length scale (target units per source unit).
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// A position (or displacement): scaled and re-axed.
    pub fn position(&self, p: Vec3) -> Vec3 {
        self.scale * (self.axes * p)
    }

    /// A direction: re-axed, not scaled.
    pub fn direction(&self, v: Vec3) -> Vec3 {
        self.axes * v
    }

    /// A rotation: `M R M^T`.
    pub fn rotation(&self, q: Quat) -> Quat {
        let v = self.det * (self.axes * Vec3::new(q.x, q.y, q.z));
        Quat::from_xyzw(v.x, v.y, v.z, q.w)
    }

    /// An angle about the up axis: reversed by a change of handedness.
    pub fn yaw(&self, angle: f32) -> f32 {
        self.det * angle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames() -> Vec<CoordinateFrame> {
        let mut v = vec![];
        for up in [UpAxis::Y, UpAxis::Z] {
            for h in [Handedness::Right, Handedness::Left] {
                v.push(CoordinateFrame { metres_per_unit: 0.01, up_axis: up, handedness: h });
                v.push(CoordinateFrame::metres(up, h));
            }
        }
        v
    }

    #[test]
    fn up_goes_up_and_handedness_is_the_determinant() {
        for f in frames() {
            let c = Conversion::between(&CoordinateFrame::ZOO_CM, &f);
            let up = c.direction(Vec3::Y);
            let want = if f.up_axis == UpAxis::Y { Vec3::Y } else { Vec3::Z };
            assert_eq!(up, want, "{f:?}");
            let det = c.axes.determinant();
            assert_eq!(det, if f.handedness == Handedness::Right { 1.0 } else { -1.0 }, "{f:?}");
        }
        let blender =
            Conversion::between(&CoordinateFrame::ZOO_CM, &CoordinateFrame::metres(UpAxis::Z, Handedness::Right));
        assert!((blender.position(Vec3::new(100.0, 200.0, 300.0)) - Vec3::new(1.0, -3.0, 2.0)).length() < 1e-6);
    }

    #[test]
    fn rotations_commute_with_the_conversion_and_round_trips_are_exact() {
        let q = Quat::from_axis_angle(Vec3::new(0.3, -0.5, 0.8).normalize(), 1.1);
        let p = Vec3::new(12.0, -3.0, 7.5);
        for from in frames() {
            for to in frames() {
                let c = Conversion::between(&from, &to);
                // Rotating then converting equals converting then rotating.
                let a = c.position(q * p);
                let b = c.rotation(q) * c.position(p);
                assert!((a - b).length() <= 1e-4 * a.length().max(1.0), "{from:?} -> {to:?}: {a} vs {b}");
                let back = Conversion::between(&to, &from);
                assert!((back.position(c.position(p)) - p).length() < 1e-4);
                assert!(back.rotation(c.rotation(q)).dot(q).abs() > 1.0 - 1e-6);
                assert_eq!(back.yaw(c.yaw(0.7)), 0.7);
            }
        }
        assert!(Conversion::between(&CoordinateFrame::ZOO_CM, &CoordinateFrame::ZOO_CM).is_identity());
    }

    #[test]
    fn units() {
        assert_eq!(CoordinateFrame::ZOO_CM.unit_name(), Some("cm"));
        assert_eq!(CoordinateFrame::metres_per("in"), Some(0.0254));
        assert!(CoordinateFrame { metres_per_unit: 0.0, ..CoordinateFrame::ZOO_CM }.check().is_err());
    }
}
