//! Stage 3: the leg cycle (gait blend, phase, stance fraction per frame).

use super::Style;
use super::geometry::{lerp, smoothstep};
use super::trajectory::Trajectory;
use zoo_motion::rng::SplitMix64;

/// The leg cycle, per frame.
pub(super) struct Cycle {
    /// Gait blend, 0 walk .. 1 run, from the speed.
    pub blend: Vec<f64>,
    /// Cycle phase (one unit per two steps; the right foot is half a cycle behind the left).
    pub phase: Vec<f64>,
    /// Fraction of the cycle a foot is planted (60% walking, 32% running).
    pub stance_frac: Vec<f64>,
}

/// The leg cycle along a trajectory: cadence from the speed and the style, a random start phase.
pub(super) fn plan_cycle(rng: &mut SplitMix64, traj: &Trajectory, style: &Style, fps: f64) -> Cycle {
    let n = traj.speed.len();
    let dt = 1.0 / fps;
    let blend: Vec<f64> = traj.speed.iter().map(|&v| smoothstep(1.9, 2.9, v)).collect();
    let mut phase = vec![0.0; n];
    let mut stance_frac = vec![0.0; n];
    let mut ph = rng.next_f64();
    for f in 0..n {
        let v = traj.speed[f];
        let b = blend[f];
        let walk_steps = 1.6 + 0.45 * v.min(2.2);
        let run_steps = 2.3 + 0.18 * v;
        let steps_per_s = lerp(walk_steps, run_steps, b) * style.cadence;
        stance_frac[f] = lerp(0.6, 0.32, b);
        phase[f] = ph;
        ph += steps_per_s * 0.5 * dt;
    }
    Cycle { blend, phase, stance_frac }
}
