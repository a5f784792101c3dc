//! Stage 6: the pose of every output frame: hips from the pelvis, spine and head
//! counter-rotating, arms swinging opposite the legs, legs by two-bone IK to the planned feet.

use super::Style;
use super::cycle::Cycle;
use super::feet::FootPose;
use super::geometry::{lerp, look_rotation, two_bone_ik, yaw_dir};
use super::pelvis::Pelvis;
use super::skeleton::*;
use super::trajectory::Trajectory;
use glam::{DQuat, DVec3};
use std::f64::consts::{PI, TAU};
use std::ops::Range;

/// Local rotations and positions (`frames * joints`, on [`skeleton()`]) and the contacts
/// (left, right) of the trajectory frames `frames`.
// One function: the pose of each frame from its phase and the feet planned before it, one
// loop whose body is the pose's parts in the skeleton's order.
pub(super) fn pose_frames(
    traj: &Trajectory,
    cycle: &Cycle,
    pelvis: &Pelvis,
    feet: &[Vec<FootPose>; 2],
    style: &Style,
    frames: Range<usize>,
) -> (Vec<DQuat>, Vec<DVec3>, Vec<[bool; 2]>) {
    let (blend, phase) = (&cycle.blend, &cycle.phase);
    let (root_pos, pelvis_rot, frame_rot) = (&pelvis.root_pos, &pelvis.pelvis_rot, &pelvis.frame_rot);
    let (l1, l2) = leg_lengths();
    let m_hips = hips_frame();
    let hip_off = hip_offsets();
    let n_out = frames.len();
    let skel = skeleton();
    let parents: Vec<Option<usize>> = skel.parents.clone();
    let offsets: Vec<DVec3> = skel.offsets.clone();
    let m_spine = look_rotation(DVec3::X, DVec3::Y, DVec3::Y, DVec3::Z);
    let m_shoulder = [
        look_rotation(DVec3::X, DVec3::Z, DVec3::X, DVec3::Z),
        look_rotation(DVec3::NEG_X, DVec3::NEG_Z, DVec3::NEG_X, DVec3::Z),
    ];
    let nj = skel.len();
    let mut local_rotations = Vec::with_capacity(n_out * nj);
    let mut local_positions = Vec::with_capacity(n_out * nj);
    let mut contacts = Vec::with_capacity(n_out);
    let mut global = vec![DQuat::IDENTITY; nj];
    for f in frames {
        let v = traj.speed[f];
        let b = blend[f];
        let moving = (v / 0.8).min(1.0);
        let heading = traj.heading[f];
        let (twist, _pitch, roll, lean) = frame_rot[f];
        let g_hips = pelvis_rot[f] * m_hips;
        global[HIPS] = g_hips;
        // Spine chain: counter-rotates the pelvis twist, carries the lean.
        let look = (0.25 * traj.turn[f]).clamp(-0.5, 0.5);
        let chain = [
            (SPINE, -0.3 * twist, 0.8 * lean, 0.5 * roll),
            (CHEST, -twist, lean + 0.05 * b, 0.2 * roll),
            (NECK, -0.4 * twist + 0.5 * look, 0.3 * lean, 0.0),
            (HEAD, 0.8 * look, -0.3 * lean, 0.0),
        ];
        let mut chest_frame = DQuat::IDENTITY;
        for (j, yaw, pitch, rl) in chain {
            let q = DQuat::from_rotation_y(heading + yaw) * DQuat::from_rotation_x(pitch) * DQuat::from_rotation_z(rl);
            if j == CHEST {
                chest_frame = q;
            }
            global[j] = q * m_spine;
        }
        // Arms: swing opposite the legs (the left arm is back when the left foot lands).
        let swing_amp = lerp(20.0, 35.0, b) * style.arm_swing * (0.15 + 0.85 * moving);
        for side in 0..2 {
            let sign = if side == 0 { 1.0 } else { -1.0 };
            global[SHOULDER[side]] = chest_frame * m_shoulder[side];
            let swing = -sign * swing_amp.to_radians() * (TAU * phase[f]).cos();
            let abduct = sign * (8.0f64 + 4.0 * b).to_radians();
            let elbow = (style.elbow_deg + lerp(0.0, 65.0, b) + 10.0 * swing.max(0.0).to_degrees() / 30.0).to_radians();
            let down = DVec3::NEG_Y;
            let upper = DQuat::from_rotation_z(abduct) * DQuat::from_rotation_x(-swing) * down;
            let lower = DQuat::from_rotation_z(abduct * 0.5) * DQuat::from_rotation_x(-swing - elbow) * down;
            let fwd = DVec3::Z;
            let p_l = offsets[LOWER_ARM[side]].normalize();
            let s_l = if side == 0 { DVec3::Z } else { DVec3::NEG_Z };
            global[UPPER_ARM[side]] = look_rotation(p_l, s_l, chest_frame * upper, chest_frame * fwd);
            let p_l2 = offsets[HAND[side]].normalize();
            global[LOWER_ARM[side]] = look_rotation(p_l2, s_l, chest_frame * lower, chest_frame * fwd);
            global[HAND[side]] = global[LOWER_ARM[side]];
        }
        // Legs: two-bone IK to the planned ankle, foot toward the toe.
        let root = root_pos[f];
        for side in 0..2 {
            let fp = feet[side][f];
            let hip = root + g_hips * hip_off[side];
            let foot_fwd = yaw_dir(fp.yaw);
            let pole = (foot_fwd + yaw_dir(heading)).normalize_or_zero() + DVec3::Y * 0.0;
            let pole = if pole == DVec3::ZERO { yaw_dir(heading) } else { pole };
            let (knee, ankle) = two_bone_ik(hip, fp.ankle, pole, l1, l2);
            let down = ankle - hip;
            let mut hinge = pole.cross(down);
            if hinge.length_squared() < 1e-9 {
                hinge = yaw_dir(heading + PI / 2.0);
            }
            let hinge = hinge.normalize();
            global[UPPER_LEG[side]] = look_rotation(offsets[LOWER_LEG[side]].normalize(), DVec3::Y, knee - hip, hinge);
            global[LOWER_LEG[side]] = look_rotation(offsets[FOOT[side]].normalize(), DVec3::Y, ankle - knee, hinge);
            let foot_axis = yaw_dir(fp.yaw + PI / 2.0);
            global[FOOT[side]] = look_rotation(offsets[TOES[side]].normalize(), DVec3::Y, fp.toe - ankle, foot_axis);
            let toe_dir = foot_fwd + DVec3::Y * 0.0;
            global[TOES[side]] = look_rotation(offsets[TOES[side]].normalize(), DVec3::Y, toe_dir, foot_axis);
        }
        for j in 0..nj {
            let q = match parents[j] {
                None => global[j],
                Some(p) => (global[p].inverse() * global[j]).normalize(),
            };
            local_rotations.push(q);
            local_positions.push(if j == 0 { root } else { offsets[j] });
        }
        contacts.push([feet[0][f].contact, feet[1][f].contact]);
    }
    (local_rotations, local_positions, contacts)
}
