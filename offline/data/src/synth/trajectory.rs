//! Stage 1: the root's path on the ground (speed, heading, turn rate per frame).

use super::geometry::{wrap, yaw_dir};
use super::{Gait, Style};
use glam::DVec3;
use std::f64::consts::PI;
use zoo_motion::rng::SplitMix64;

/// The root's planned motion on the ground, per frame.
pub(super) struct Trajectory {
    /// Root ground position (cm, y = 0).
    pub pos: Vec<DVec3>,
    /// Facing angle (radians about +Y, 0 = +Z).
    pub heading: Vec<f64>,
    /// Turn rate, rad/s.
    pub turn: Vec<f64>,
    /// Speed, m/s.
    pub speed: Vec<f64>,
    /// Forward acceleration, m/s^2.
    pub accel: Vec<f64>,
}

/// Share of a walk's segments that step sideways or backwards in the default data.
pub(super) const WALK_STRAFE_SHARE: f64 = 0.07;

/// Plans the root trajectory of `frames` frames: per segment of 1.5-4 s a target speed, turn
/// rate and strafe angle drawn for `gait`, followed with bounded acceleration and smoothing.
/// `strafe_share`: the share of a walk's segments that step sideways or backwards
/// ([`WALK_STRAFE_SHARE`] in the default data; the stepping clips of
/// [`super::generate_stepping`] raise it).
// One function: a frame-by-frame integration of the root (segment targets, bounded
// acceleration, smoothing) whose state carries from one frame to the next.
pub(super) fn plan_trajectory(
    rng: &mut SplitMix64,
    gait: Gait,
    style: &Style,
    frames: usize,
    fps: f64,
    strafe_share: f64,
) -> Trajectory {
    let dt = 1.0 / fps;
    let total = frames as f64 * dt;
    // Segment targets: (start time, speed m/s, turn rate rad/s, strafe angle rad).
    let mut segs: Vec<(f64, f64, f64, f64)> = Vec::new();
    let mut t = 0.0;
    // Each segment lasts at least 1.5 s: the count is bounded up front (no loop whose end
    // depends on floating-point progress).
    let most_segments = (total / 1.5).ceil().max(0.0) as usize + 1;
    while t < total && segs.len() < most_segments {
        let u = rng.next_f64();
        let (speed, strafe) = match gait {
            Gait::Idle => {
                if u < 0.7 {
                    (0.0, 0.0)
                } else {
                    let s = [0.0, PI / 2.0, -PI / 2.0, PI][(rng.next_f64() * 4.0) as usize % 4];
                    (rng.range(0.2, 0.6), s)
                }
            }
            Gait::Walk => {
                if u < 0.08 {
                    (0.0, 0.0)
                } else if u < 0.08 + strafe_share {
                    let s = [PI / 2.0, -PI / 2.0, PI][(rng.next_f64() * 3.0) as usize % 3];
                    (rng.range(0.5, 0.9), s)
                } else {
                    (rng.range(1.0, 1.65) * style.stride, 0.0)
                }
            }
            Gait::Jog => {
                if u < 0.06 {
                    (rng.range(1.3, 1.7), 0.0)
                } else {
                    (rng.range(2.1, 2.9) * style.stride, 0.0)
                }
            }
            Gait::Run => {
                if u < 0.08 {
                    (rng.range(2.4, 2.9), 0.0)
                } else {
                    (rng.range(3.4, 4.7) * style.stride, 0.0)
                }
            }
        };
        let r = rng.next_f64();
        let mut turn_deg = if r < 0.45 {
            rng.range(-8.0, 8.0)
        } else if r < 0.85 {
            rng.sign() * rng.range(15.0, 50.0)
        } else {
            rng.sign() * rng.range(60.0, 150.0)
        };
        if gait == Gait::Idle && speed == 0.0 && rng.next_f64() < 0.5 {
            turn_deg = 0.0;
        }
        // Faster motion turns slower (bounded centripetal acceleration).
        let max_turn = 420.0 / (speed + 1.5);
        let turn = turn_deg.clamp(-max_turn, max_turn).to_radians();
        segs.push((t, speed, turn, strafe));
        t += rng.range(1.5, 4.0);
    }
    let start_from_rest = gait == Gait::Walk && rng.next_f64() < 0.25;
    let (amax, k) = match gait {
        Gait::Idle | Gait::Walk => (1.2, 2.5),
        Gait::Jog => (2.0, 2.5),
        Gait::Run => (3.0, 2.5),
    };
    let mut speed = if start_from_rest { 0.0 } else { segs[0].1 };
    let mut turn = segs[0].2 * 0.5;
    let mut strafe = segs[0].3;
    let mut heading = rng.range(-PI, PI);
    let mut pos = DVec3::ZERO;
    let mut out = Trajectory {
        pos: Vec::with_capacity(frames),
        heading: Vec::with_capacity(frames),
        turn: Vec::with_capacity(frames),
        speed: Vec::with_capacity(frames),
        accel: Vec::with_capacity(frames),
    };
    let mut seg = 0;
    for f in 0..frames {
        let time = f as f64 * dt;
        while seg + 1 < segs.len() && segs[seg + 1].0 <= time {
            seg += 1;
        }
        let (_, ts, tt, tsf) = segs[seg];
        // Strafing changes direction only at low speed.
        let tsf = if speed > 1.0 && (wrap(tsf - strafe)).abs() > 0.1 { strafe } else { tsf };
        let target_speed = if wrap(tsf - strafe).abs() > 0.3 { ts.min(0.2) } else { ts };
        let dv = (k * (target_speed - speed)).clamp(-amax, amax) * dt;
        speed = (speed + dv).max(0.0);
        turn += (tt - turn) * (1.0 - (-dt / 0.35).exp());
        if speed < 0.4 {
            strafe += wrap(tsf - strafe) * (1.0 - (-dt / 0.25).exp());
        }
        heading += turn * dt;
        pos += yaw_dir(heading + strafe) * (speed * 100.0 * dt);
        out.pos.push(pos);
        out.heading.push(heading);
        out.turn.push(turn);
        out.speed.push(speed);
        out.accel.push(dv / dt);
    }
    out
}
