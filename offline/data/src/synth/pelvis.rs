//! Stage 5: the pelvis: height from the ground and the feet, bob, sway, twist, banking, lean,
//! then lowered where a leg cannot reach its foot.

use super::Style;
use super::cycle::Cycle;
use super::feet::FootPose;
use super::geometry::{lerp, yaw_dir};
use super::skeleton::{JOINT_OFFSETS, TOE_HEIGHT, hip_offsets, hips_frame, leg_lengths};
use super::trajectory::Trajectory;
use glam::{DQuat, DVec3};
use std::f64::consts::{PI, TAU};

/// The pelvis, per frame.
pub(super) struct Pelvis {
    /// Root (hips) position (cm).
    pub root_pos: Vec<DVec3>,
    /// Pelvis rotation (applied to the hips' rest frame).
    pub pelvis_rot: Vec<DQuat>,
    /// (twist, pitch, roll, lean) angles, radians.
    pub frame_rot: Vec<(f64, f64, f64, f64)>,
}

/// The pelvis along a trajectory over planned feet.
pub(super) fn plan_pelvis(
    traj: &Trajectory,
    cycle: &Cycle,
    style: &Style,
    feet: &[Vec<FootPose>; 2],
    ground: &dyn Fn(f64, f64) -> f64,
    fps: f64,
) -> Pelvis {
    let n = traj.pos.len();
    let (blend, phase, stance_frac) = (&cycle.blend, &cycle.phase, &cycle.stance_frac);
    let (l1, l2) = leg_lengths();
    let ground_root: Vec<f64> = traj.pos.iter().map(|p| ground(p.x, p.z)).collect();
    let radius = (0.35 * fps) as isize;
    let ground_ref: Vec<f64> = (0..n as isize)
        .map(|f| {
            let (a, b) = ((f - radius).max(0) as usize, ((f + radius) as usize).min(n - 1));
            let feet_avg = 0.5 * (feet[0][f as usize].toe.y + feet[1][f as usize].toe.y) - TOE_HEIGHT;
            let box_avg = ground_root[a..=b].iter().sum::<f64>() / (b - a + 1) as f64;
            0.5 * (box_avg + feet_avg)
        })
        .collect();
    let mut root_pos = vec![DVec3::ZERO; n];
    let mut pelvis_rot = vec![DQuat::IDENTITY; n];
    let mut frame_rot = vec![(0.0, 0.0, 0.0, 0.0); n]; // (twist, pitch, roll, lean) per frame
    let m_hips = hips_frame();
    let hip_off = hip_offsets();
    let mut need_drop = vec![0.0; n];
    for f in 0..n {
        let v = traj.speed[f];
        let b = blend[f];
        let moving = (v / 0.8).min(1.0);
        let st = stance_frac[f];
        let mid = 0.3 * st;
        let c = (TAU * (phase[f] - mid)).cos();
        let c2 = (2.0 * TAU * (phase[f] - mid)).cos();
        let heading = traj.heading[f];
        let bob = lerp(1.2, -2.5, b) * moving * c2;
        let sway = style.sway * lerp(1.0, 0.4, b) * (0.3 + 0.7 * moving) * c;
        let left = yaw_dir(heading + PI / 2.0);
        let crouch = style.crouch + lerp(1.0, 6.0, b);
        let y = ground_ref[f] + JOINT_OFFSETS[0][1] - 1.5 - crouch + bob;
        root_pos[f] = traj.pos[f].with_y(y) + left * sway;
        let twist = -(lerp(5.0, 8.0, b) * moving).to_radians() * (TAU * phase[f]).cos();
        let centripetal = v * traj.turn[f]; // m/s^2
        let bank = -0.5 * (centripetal / 9.81).atan();
        let roll = (3.0 * moving * (1.0 - b)).to_radians() * c + bank;
        let lean = (style.lean_deg + 7.0 * b * v / 4.0 + 2.0 * traj.accel[f].clamp(-2.0, 2.0)).to_radians();
        let pitch = 0.5 * lean;
        frame_rot[f] = (twist, pitch, roll, lean);
        let q = DQuat::from_rotation_y(heading + twist) * DQuat::from_rotation_x(pitch) * DQuat::from_rotation_z(roll);
        pelvis_rot[f] = q;
        let g_hips = q * m_hips;
        let reach = 0.995 * (l1 + l2);
        for side in 0..2 {
            let hip = root_pos[f] + g_hips * hip_off[side];
            let ankle = feet[side][f].ankle;
            let horiz = (hip - ankle).with_y(0.0).length().min(reach * 0.999);
            let max_dy = (reach * reach - horiz * horiz).sqrt();
            need_drop[f] = f64::max(need_drop[f], hip.y - ankle.y - max_dy);
        }
    }
    // Smooth the drop without going below what each frame needs: max filter, then box mean.
    let r = 4isize;
    let maxed: Vec<f64> = (0..n as isize)
        .map(|f| {
            ((f - r).max(0)..=(f + r).min(n as isize - 1)).map(|k| need_drop[k as usize].max(0.0)).fold(0.0, f64::max)
        })
        .collect();
    for f in 0..n as isize {
        let (a, b) = ((f - r).max(0) as usize, ((f + r) as usize).min(n - 1));
        let mean = maxed[a..=b].iter().sum::<f64>() / (b - a + 1) as f64;
        // Near the ends the window is cut, so keep the frame's own need as a floor too.
        root_pos[f as usize].y -= mean.max(need_drop[f as usize]);
    }
    Pelvis { root_pos, pelvis_rot, frame_rot }
}
