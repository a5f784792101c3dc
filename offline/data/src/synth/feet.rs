//! Stage 4: the feet: stance intervals from the cycle, foot plants placed ahead on the
//! ground (a planted toe stays fixed), heel-off, and swing arcs clearing the ground.

use super::Style;
use super::cycle::Cycle;
use super::geometry::{lerp, rot, smootherstep, wrap, yaw_dir};
use super::skeleton::{ANKLE_HEIGHT, TOE_HEIGHT, foot_length};
use super::trajectory::Trajectory;
use glam::{DQuat, DVec3};
use std::f64::consts::PI;

/// A planned foot plant: flat-foot ankle and toe positions.
#[derive(Clone, Copy, Debug)]
struct Plant {
    ankle: DVec3,
    toe: DVec3,
    yaw: f64,
}

/// Foot geometry on the ground: given the ankle's ground XZ and the foot's yaw, ankle and toe
/// at their planted heights above the local surface (the foot pitches with the ground).
fn place_foot(ground: &dyn Fn(f64, f64) -> f64, xz: DVec3, yaw: f64) -> Plant {
    let foot_len = foot_length();
    let fwd = yaw_dir(yaw);
    // Prefer a spot where ankle and toe are on the same level (not across a step edge).
    let mut best = (f64::MAX, xz);
    for shift in [0.0, 8.0, -8.0, 16.0, -16.0, 24.0, -24.0, 32.0] {
        let a = xz + fwd * shift;
        let flat_h = (foot_len * foot_len - (ANKLE_HEIGHT - TOE_HEIGHT).powi(2)).sqrt();
        let mut worst: f64 = 0.0;
        let ga = ground(a.x, a.z);
        for s in [-6.0, 0.0, flat_h * 0.5, flat_h, flat_h + 5.0] {
            let p = a + fwd * s;
            worst = worst.max((ground(p.x, p.z) - ga).abs());
        }
        let cost = worst + 0.01 * shift.abs();
        if cost < best.0 {
            best = (cost, a);
        }
        if worst < 2.0 {
            break;
        }
    }
    let a = best.1;
    let ga = ground(a.x, a.z);
    let ankle = DVec3::new(a.x, ga + ANKLE_HEIGHT, a.z);
    // Toe on its surface: solve the horizontal reach for the drop (two fixed-point steps).
    let mut horiz = (foot_len * foot_len - (ANKLE_HEIGHT - TOE_HEIGHT).powi(2)).sqrt();
    let mut toe = ankle;
    for _ in 0..3 {
        let t = a + fwd * horiz;
        let ty = ground(t.x, t.z) + TOE_HEIGHT;
        let drop = (ankle.y - ty).clamp(-foot_len * 0.95, foot_len * 0.95);
        horiz = (foot_len * foot_len - drop * drop).sqrt();
        toe = DVec3::new(a.x, ankle.y - drop, a.z) + fwd * horiz;
    }
    Plant { ankle, toe, yaw }
}

/// Per frame state of one foot.
#[derive(Clone, Copy, Debug)]
pub(super) struct FootPose {
    /// Ankle position (cm).
    pub ankle: DVec3,
    /// Toe position (cm).
    pub toe: DVec3,
    /// Yaw of the foot (radians about +Y, 0 = +Z).
    pub yaw: f64,
    /// Planted (stance) or not (swing).
    pub contact: bool,
}

/// The pose of both feet (left, right) on every frame of the trajectory.
pub(super) fn plan_feet(
    traj: &Trajectory,
    cycle: &Cycle,
    style: &Style,
    ground: &dyn Fn(f64, f64) -> f64,
) -> [Vec<FootPose>; 2] {
    [plan_foot(0, traj, cycle, style, ground), plan_foot(1, traj, cycle, style, ground)]
}

/// The pose of one foot (`side` 0: left, 1: right) on every frame.
// One function: a frame-by-frame walk of the foot's gait cycle (stance, lift, swing, landing)
// whose state carries from one frame to the next; its steps are that loop's body.
fn plan_foot(
    side: usize,
    traj: &Trajectory,
    cycle: &Cycle,
    style: &Style,
    ground: &dyn Fn(f64, f64) -> f64,
) -> Vec<FootPose> {
    let n = traj.pos.len();
    let (blend, phase, stance_frac) = (&cycle.blend, &cycle.phase, &cycle.stance_frac);
    let foot_len = foot_length();
    let mut out = Vec::with_capacity(n);
    let offset = side as f64 * 0.5;
    let local = |f: usize| (phase[f] - offset).rem_euclid(1.0);
    let in_stance: Vec<bool> = (0..n).map(|f| local(f) < stance_frac[f]).collect();
    // Stance intervals [s, e).
    let mut stances: Vec<(usize, usize)> = Vec::new();
    let mut f = 0;
    while f < n {
        if in_stance[f] {
            let s = f;
            while f < n && in_stance[f] {
                f += 1;
            }
            stances.push((s, f));
        } else {
            f += 1;
        }
    }
    // The plant of each stance: under the hip at the middle of the flat-foot part.
    let lateral = if side == 0 { 1.0 } else { -1.0 };
    let mut plants: Vec<Plant> = Vec::with_capacity(stances.len());
    let mut moved: Vec<bool> = Vec::with_capacity(stances.len());
    for &(s, e) in &stances {
        let tm = s as f64 + lerp(0.3, 0.38, blend[s]) * (e - s) as f64;
        let i = (tm.floor() as usize).min(n - 2);
        let w = (tm - i as f64).clamp(0.0, 1.0);
        let root = traj.pos[i].lerp(traj.pos[i + 1], w);
        let heading = lerp(traj.heading[i], traj.heading[i + 1], w);
        let width = style.step_half_width * lerp(1.0, 0.6, blend[i]);
        let right = yaw_dir(heading - PI / 2.0);
        let xz = root - right * (lateral * width) - yaw_dir(heading) * 4.0;
        let yaw = heading + lateral * style.toe_out_deg.to_radians();
        let candidate = place_foot(ground, xz, yaw);
        match plants.last() {
            Some(prev)
                if (prev.ankle - candidate.ankle).with_y(0.0).length() < 4.0
                    && wrap(prev.yaw - candidate.yaw).abs() < 8f64.to_radians() =>
            {
                plants.push(*prev);
                moved.push(false);
            }
            _ => {
                moved.push(!plants.is_empty());
                plants.push(candidate);
            }
        }
    }
    // Heel-off amplitude of each stance, from the next step's length.
    let heel_off: Vec<f64> = (0..stances.len())
        .map(|i| match (moved.get(i + 1), plants.get(i + 1)) {
            (Some(true), Some(next)) => {
                let dist = (next.ankle - plants[i].ankle).with_y(0.0).length();
                let b = blend[stances[i].0];
                lerp(55.0, 50.0, b).to_radians() * (dist / 40.0).clamp(0.2, 1.0)
            }
            _ => 0.0,
        })
        .collect();
    // Ankle and toe at the end of stance `i` (heel lifted about the planted toe).
    let lift_pose = |i: usize| -> (DVec3, DVec3) {
        let p = plants[i];
        let axis = yaw_dir(p.yaw + PI / 2.0);
        (p.toe + rot(axis, heel_off[i], p.ankle - p.toe), p.toe)
    };
    let mut si = 0usize; // index of the next / current stance
    for f in 0..n {
        while si < stances.len() && stances[si].1 <= f {
            si += 1;
        }
        let u = local(f);
        let st = stance_frac[f];
        let pose = if si < stances.len() && stances[si].0 <= f {
            // Stance: flat, then the heel lifts about the toe.
            let p = plants[si];
            let h0 = lerp(0.45, 0.5, blend[f]);
            let k = ((u / st - h0) / (1.0 - h0)).clamp(0.0, 1.0);
            let alpha = heel_off[si] * k * k;
            let axis = yaw_dir(p.yaw + PI / 2.0);
            FootPose { ankle: p.toe + rot(axis, alpha, p.ankle - p.toe), toe: p.toe, yaw: p.yaw, contact: true }
        } else if si == 0 || si >= stances.len() || !moved[si] {
            // Before the first or after the last planned stance, or no step needed:
            // the foot stays where it is.
            let p = if si == 0 { plants[0] } else { plants[si - 1] };
            FootPose { ankle: p.ankle, toe: p.toe, yaw: p.yaw, contact: true }
        } else {
            // Swing from the previous stance's lift-off to this stance's plant.
            let w = ((u - st) / (1.0 - st)).clamp(0.0, 1.0);
            let (a0, t0) = lift_pose(si - 1);
            let p1 = plants[si];
            let s = smootherstep(w);
            let mut ankle = a0.lerp(p1.ankle, s);
            let dist = (p1.ankle - a0).with_y(0.0).length();
            let b = blend[f];
            let base_h = lerp(12.0, 28.0, b) * style.swing_height * (dist / 30.0).clamp(0.15, 1.0);
            // Clearance over the ground between lift-off and landing.
            let mut need: f64 = 0.0;
            for q in 1..10 {
                let wq = q as f64 / 10.0;
                let pq = a0.lerp(p1.ankle, smootherstep(wq));
                let lift = ground(pq.x, pq.z) + ANKLE_HEIGHT + 4.0 - pq.y;
                need = need.max(lift / (PI * wq).sin().max(0.3));
            }
            let arc = base_h.max(need) * (PI * w.powf(0.75)).sin();
            ankle.y += arc;
            // Foot direction: from lift-off to landing, toes up a little mid-swing.
            let d0 = (t0 - a0).normalize();
            let d1 = (p1.toe - p1.ankle).normalize();
            let yaw = lerp(plants[si - 1].yaw, plants[si - 1].yaw + wrap(p1.yaw - plants[si - 1].yaw), s);
            let axis = yaw_dir(yaw + PI / 2.0);
            let dq = zoo_motion::quat::shortest_arc(d0, d1);
            let d = zoo_motion::quat::slerp(DQuat::IDENTITY, dq, s) * d0;
            let d = rot(axis, -0.25 * (PI * w).sin() * (dist / 30.0).clamp(0.0, 1.0), d);
            let mut toe = ankle + d * foot_len;
            let raise = (ground(ankle.x, ankle.z) + ANKLE_HEIGHT - ankle.y)
                .max(ground(toe.x, toe.z) + TOE_HEIGHT - toe.y)
                .max(0.0);
            ankle.y += raise;
            toe.y += raise;
            FootPose { ankle, toe, yaw, contact: false }
        };
        out.push(pose);
    }
    out
}
