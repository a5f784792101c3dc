//! Coordinate frames (`ZooCoordinateFrame`): an engine whose units and axes differ from the
//! model's (`ZooModelInfo`'s `metres_per_unit`, `up_axis`, `handedness`) converts engine poses
//! with `zoo_pose_convert` and joint positions with `zoo_positions_convert`, in place, with
//! the runtime's conversion (`zoo_runtime::Conversion`, `EnginePose::convert`): model to engine
//! after a call that writes poses, engine to model before a call that reads them.

use crate::{Failure, ZooHandedness, ZooRootMotion, ZooStatus, ZooUpAxis, guard, handle, optional_slice_mut};
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::{Conversion, CoordinateFrame, Handedness, UpAxis};

/// A coordinate frame: the length unit, the up axis and the handedness in which positions and
/// rotations are expressed. A model's is in `ZooModelInfo`; Unity's is `{1, ZOO_UP_AXIS_Y,
/// ZOO_HANDEDNESS_LEFT}` (metres, Y up, left-handed), Unreal's `{0.01, ZOO_UP_AXIS_Z,
/// ZOO_HANDEDNESS_LEFT}`, Godot's `{1, ZOO_UP_AXIS_Y, ZOO_HANDEDNESS_RIGHT}`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZooCoordinateFrame {
    /// Metres per length unit (0.01: centimetres, 1: metres); finite and positive.
    pub metres_per_unit: f32,
    /// The up axis: a `ZooUpAxis` value (`ZOO_UP_AXIS_Y` or `ZOO_UP_AXIS_Z`); any other value is
    /// refused. Stored as an integer so that a value from outside the enum is read and refused,
    /// not misread.
    pub up_axis: u32,
    /// The handedness of the axes: a `ZooHandedness` value (`ZOO_HANDEDNESS_RIGHT` or
    /// `ZOO_HANDEDNESS_LEFT`); any other value is refused.
    pub handedness: u32,
}

impl ZooCoordinateFrame {
    /// The runtime's frame, checked.
    fn runtime(&self, what: &str) -> Result<CoordinateFrame, Failure> {
        let frame = CoordinateFrame {
            metres_per_unit: self.metres_per_unit,
            up_axis: match self.up_axis {
                v if v == ZooUpAxis::Y as u32 => UpAxis::Y,
                v if v == ZooUpAxis::Z as u32 => UpAxis::Z,
                v => {
                    return Err((
                        ZooStatus::InvalidArgument,
                        format!(
                            "`{what}.up_axis` is {v}, not a ZooUpAxis; use ZOO_UP_AXIS_Y ({}) or ZOO_UP_AXIS_Z ({})",
                            ZooUpAxis::Y as u32,
                            ZooUpAxis::Z as u32
                        ),
                    ));
                }
            },
            handedness: match self.handedness {
                v if v == ZooHandedness::Right as u32 => Handedness::Right,
                v if v == ZooHandedness::Left as u32 => Handedness::Left,
                v => {
                    return Err((
                        ZooStatus::InvalidArgument,
                        format!(
                            "`{what}.handedness` is {v}, not a ZooHandedness; use ZOO_HANDEDNESS_RIGHT ({}) or \
                             ZOO_HANDEDNESS_LEFT ({})",
                            ZooHandedness::Right as u32,
                            ZooHandedness::Left as u32
                        ),
                    ));
                }
            },
        };
        frame.check().map_err(|e| (ZooStatus::InvalidArgument, format!("`{what}`: {e}")))?;
        Ok(frame)
    }
}

/// The conversion from `*from` to `*to`.
///
/// Safety: Each pointer is NULL or readable.
unsafe fn conversion(from: *const ZooCoordinateFrame, to: *const ZooCoordinateFrame) -> Result<Conversion, Failure> {
    let from = unsafe { handle(from, "from") }?.runtime("from")?;
    let to = unsafe { handle(to, "to") }?.runtime("to")?;
    Ok(Conversion::between(&from, &to))
}

/// Converts engine poses in place from frame `from` to frame `to`, as the runtime's
/// `EnginePose::convert` does: in each of the `roots_len` roots, `root_position`,
/// `delta_position` and `hips_position` are scaled and re-axed, `root_rotation` is conjugated by
/// the change of axes and `delta_yaw` is reversed by a change of handedness; each rotation of
/// `rotations` (`x y z w`, `rotations_len` a multiple of 4: `4K` per root) is conjugated too.
/// `roots` NULL with `roots_len` 0 converts rotations only, `rotations` NULL with
/// `rotations_len` 0 roots only. Convert a model's poses to the engine's after a call that
/// writes them (`from`: the model's frame from `zoo_model_info`) and the engine's to the model's
/// before a call that reads them. Allocates nothing. Thread-safe.
///
/// Safety: `from` and `to` are NULL or readable; each buffer is NULL or holds its given length of
/// writable values.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_pose_convert(
    from: *const ZooCoordinateFrame,
    to: *const ZooCoordinateFrame,
    roots: *mut ZooRootMotion,
    roots_len: usize,
    rotations: *mut f32,
    rotations_len: usize,
) -> ZooStatus {
    guard("zoo_pose_convert", || {
        let c = unsafe { conversion(from, to) }?;
        let roots = unsafe { optional_slice_mut(roots, roots_len, "roots") }?;
        let rotations = unsafe { optional_slice_mut(rotations, rotations_len, "rotations") }?;
        if !rotations.len().is_multiple_of(4) || (!roots.is_empty() && !rotations.len().is_multiple_of(4 * roots.len()))
        {
            return Err((
                ZooStatus::InvalidArgument,
                format!(
                    "`rotations` holds {} floats for {} roots; it needs 4 floats (x y z w) per joint, the same \
                     number of joints per root (4 * zoo_model_info's `joints` per root)",
                    rotations.len(),
                    roots.len()
                ),
            ));
        }
        let position = |p: &mut [f32; 3]| *p = c.position(Vec3::from_array(*p)).to_array();
        for root in roots {
            position(&mut root.root_position);
            root.root_rotation = c.rotation(Quat::from_array(root.root_rotation)).to_array();
            position(&mut root.delta_position);
            root.delta_yaw = c.yaw(root.delta_yaw);
            position(&mut root.hips_position);
        }
        for q in rotations.chunks_exact_mut(4) {
            q.copy_from_slice(&c.rotation(Quat::from_slice(q)).to_array());
        }
        Ok(())
    })
}

/// Converts positions in place from frame `from` to frame `to`: `positions` holds `x y z`
/// triples (`positions_len` a multiple of 3), each scaled and re-axed as the runtime's
/// `Conversion::position` does: global joint positions of `zoo_transition_start` /
/// `zoo_transition_step`, the rest offsets of `zoo_model_skeleton`. Allocates nothing.
/// Thread-safe.
///
/// Safety: `from` and `to` are NULL or readable; `positions` is NULL or holds `positions_len` writable
/// floats.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_positions_convert(
    from: *const ZooCoordinateFrame,
    to: *const ZooCoordinateFrame,
    positions: *mut f32,
    positions_len: usize,
) -> ZooStatus {
    guard("zoo_positions_convert", || {
        let c = unsafe { conversion(from, to) }?;
        let positions = unsafe { optional_slice_mut(positions, positions_len, "positions") }?;
        if !positions.len().is_multiple_of(3) {
            return Err((
                ZooStatus::InvalidArgument,
                format!("`positions` holds {} floats; it needs 3 (x y z) per position", positions.len()),
            ));
        }
        for p in positions.chunks_exact_mut(3) {
            p.copy_from_slice(&c.position(Vec3::from_slice(p)).to_array());
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::with_last_error;
    use std::ptr::{null, null_mut};
    use zoo_runtime::EnginePose;

    const ZOO_CM: ZooCoordinateFrame = ZooCoordinateFrame {
        metres_per_unit: 0.01,
        up_axis: ZooUpAxis::Y as u32,
        handedness: ZooHandedness::Right as u32,
    };
    const UNITY: ZooCoordinateFrame = ZooCoordinateFrame {
        metres_per_unit: 1.0,
        up_axis: ZooUpAxis::Y as u32,
        handedness: ZooHandedness::Left as u32,
    };
    const UNREAL: ZooCoordinateFrame = ZooCoordinateFrame {
        metres_per_unit: 0.01,
        up_axis: ZooUpAxis::Z as u32,
        handedness: ZooHandedness::Left as u32,
    };

    fn pose() -> EnginePose {
        let mut p = EnginePose::with_global_positions(3);
        p.root_position = Vec3::new(12.0, 0.0, -40.5);
        p.root_rotation = Quat::from_rotation_y(0.7);
        p.root_delta_position = Vec3::new(0.5, 0.0, 2.0);
        p.root_delta_yaw = 0.03;
        p.hips_position = Vec3::new(1.0, 90.0, -2.0);
        p.local_rotations = vec![
            Quat::from_axis_angle(Vec3::new(0.3, -0.5, 0.8).normalize(), 1.1),
            Quat::from_rotation_x(0.4),
            Quat::from_rotation_z(-0.2),
        ];
        p.global_positions = vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-4.0, 5.5, 6.0), Vec3::new(7.0, -8.0, 9.0)];
        p
    }

    fn message() -> String {
        with_last_error(|m| m.to_string())
    }

    /// The C conversion is the runtime's `EnginePose::convert`, bit for bit, for every pair of
    /// frames (and positions its `Conversion::position`).
    #[test]
    fn converts_as_the_runtime_does() {
        for (from, to) in [(ZOO_CM, UNITY), (UNITY, ZOO_CM), (ZOO_CM, UNREAL), (UNREAL, UNITY)] {
            let p = pose();
            let mut root = ZooRootMotion::default();
            let mut rotations = vec![0.0; 12];
            crate::write_pose(&p, &mut root, &mut rotations);
            let mut positions: Vec<f32> = p.global_positions.iter().flat_map(|v| v.to_array()).collect();
            let status = unsafe { zoo_pose_convert(&from, &to, &mut root, 1, rotations.as_mut_ptr(), 12) };
            assert_eq!(status, ZooStatus::Ok, "{}", message());
            let status = unsafe { zoo_positions_convert(&from, &to, positions.as_mut_ptr(), 9) };
            assert_eq!(status, ZooStatus::Ok, "{}", message());
            let mut want = p.clone();
            want.convert(&Conversion::between(&from.runtime("from").unwrap(), &to.runtime("to").unwrap()));
            let mut want_root = ZooRootMotion::default();
            let mut want_rotations = vec![0.0; 12];
            crate::write_pose(&want, &mut want_root, &mut want_rotations);
            assert_eq!(root, want_root);
            assert_eq!(rotations, want_rotations);
            let want_positions: Vec<f32> = want.global_positions.iter().flat_map(|v| v.to_array()).collect();
            assert_eq!(positions, want_positions);
        }
        // Unity: centimetres to metres, x mirrored, rotations and turns reversed.
        let mut root = ZooRootMotion { root_position: [100.0, 0.0, 250.0], delta_yaw: 0.5, ..Default::default() };
        let mut q = Quat::from_rotation_y(0.5).to_array();
        assert_eq!(unsafe { zoo_pose_convert(&ZOO_CM, &UNITY, &mut root, 1, q.as_mut_ptr(), 4) }, ZooStatus::Ok);
        assert_eq!(root.root_position, [-1.0, 0.0, 2.5]);
        assert_eq!(root.delta_yaw, -0.5);
        assert!(Quat::from_array(q).abs_diff_eq(Quat::from_rotation_y(-0.5), 1e-7));
    }

    #[test]
    fn optional_buffers_and_round_trips() {
        let mut q = Quat::from_rotation_x(0.3).to_array();
        let before = q;
        unsafe {
            assert_eq!(zoo_pose_convert(&ZOO_CM, &UNREAL, null_mut(), 0, q.as_mut_ptr(), 4), ZooStatus::Ok);
            assert_eq!(zoo_pose_convert(&UNREAL, &ZOO_CM, null_mut(), 0, q.as_mut_ptr(), 4), ZooStatus::Ok);
            assert_eq!(zoo_pose_convert(&ZOO_CM, &UNITY, null_mut(), 0, null_mut(), 0), ZooStatus::Ok);
            assert_eq!(zoo_positions_convert(&ZOO_CM, &UNITY, null_mut(), 0), ZooStatus::Ok);
        }
        assert_eq!(q, before);
    }

    #[track_caller]
    fn refused(status: ZooStatus, want: ZooStatus, needle: &str) {
        assert_eq!(status, want, "{}", message());
        assert!(message().contains(needle), "`{}` should contain `{needle}`", message());
    }

    #[test]
    fn refuses_bad_frames_and_lengths() {
        let mut root = ZooRootMotion::default();
        let mut r = [0.0f32; 12];
        let bad = ZooCoordinateFrame { metres_per_unit: 0.0, ..UNITY };
        let nan = ZooCoordinateFrame { metres_per_unit: f32::NAN, ..UNITY };
        let (invalid, null_pointer) = (ZooStatus::InvalidArgument, ZooStatus::NullPointer);
        unsafe {
            let status = zoo_pose_convert(null(), &UNITY, &mut root, 1, r.as_mut_ptr(), 4);
            refused(status, null_pointer, "zoo_pose_convert: `from` is NULL");
            let status = zoo_pose_convert(&ZOO_CM, &bad, &mut root, 1, r.as_mut_ptr(), 4);
            refused(status, invalid, "zoo_pose_convert: `to`: metres_per_unit must be a positive number, got 0");
            let status = zoo_positions_convert(&nan, &UNITY, r.as_mut_ptr(), 3);
            refused(
                status,
                invalid,
                "zoo_positions_convert: `from`: metres_per_unit must be a positive number, got NaN",
            );
            let status = zoo_pose_convert(&ZOO_CM, &UNITY, &mut root, 1, r.as_mut_ptr(), 6);
            refused(status, invalid, "zoo_pose_convert: `rotations` holds 6 floats for 1 roots");
            let status = zoo_pose_convert(&ZOO_CM, &UNITY, &mut root, 2, r.as_mut_ptr(), 12);
            refused(status, invalid, "`rotations` holds 12 floats for 2 roots");
            let status = zoo_pose_convert(&ZOO_CM, &UNITY, null_mut(), 1, r.as_mut_ptr(), 4);
            refused(status, null_pointer, "zoo_pose_convert: `roots` is NULL");
            let status = zoo_positions_convert(&ZOO_CM, &UNITY, r.as_mut_ptr(), 4);
            refused(
                status,
                invalid,
                "zoo_positions_convert: `positions` holds 4 floats; it needs 3 (x y z) per position",
            );
        }
        assert_eq!(r, [0.0; 12], "a refused call writes nothing");
        assert_eq!(root, ZooRootMotion::default());
    }

    /// An enum value from outside the enum (what C lets a caller store) is refused by name, not
    /// read as another value.
    #[test]
    fn refuses_values_outside_the_enums() {
        let mut q = Quat::IDENTITY.to_array();
        let up7 = ZooCoordinateFrame { up_axis: 7, ..UNITY };
        let hand2 = ZooCoordinateFrame { handedness: 2, ..UNITY };
        unsafe {
            let status = zoo_pose_convert(&up7, &UNITY, null_mut(), 0, q.as_mut_ptr(), 4);
            refused(status, ZooStatus::InvalidArgument, "zoo_pose_convert: `from.up_axis` is 7, not a ZooUpAxis");
            let status = zoo_positions_convert(&UNITY, &hand2, q.as_mut_ptr(), 3);
            refused(
                status,
                ZooStatus::InvalidArgument,
                "zoo_positions_convert: `to.handedness` is 2, not a ZooHandedness; use ZOO_HANDEDNESS_RIGHT (0)",
            );
        }
        assert_eq!(q, Quat::IDENTITY.to_array());
    }
}
