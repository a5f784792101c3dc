//! The hop controller of ARNN section 4.3: a finite state machine cycling through four timed
//! target poses (a pose control graph after van de Panne et al. 1994), and the rollout of
//! a policy on the simulated lamp.

use super::lamp::{Lamp, LampParams, LampPose};
use serde::{Deserialize, Serialize};

/// Joint angles (theta1, theta2, theta3) of the lamp standing at rest, where every rollout
/// starts: the leg leans back, the neck leans forward over the base, the head looks ahead
/// and down.
pub const REST_ANGLES: [f64; 3] = [0.5, -1.1, -1.2];

/// A hop policy: the durations t1..t4 (seconds) of the four states and each state's target
/// pose (theta1, theta2, theta3; radians). One pass through the four states is one hop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HopPolicy {
    /// Durations t1, t2, t3, t4 of the states.
    pub durations: [f64; 4],
    /// Target joint angles of each state.
    pub poses: [[f64; 3]; 4],
}

impl HopPolicy {
    /// A hand-set hop: crouch, push off (leg swings forward while the neck straightens), tuck
    /// in the air, then land and recover in the rest pose. It is where simulated annealing
    /// starts (section 4.4's `INIT()`).
    pub fn hand_set() -> HopPolicy {
        HopPolicy {
            durations: [0.25, 0.09, 0.20, 0.57],
            poses: [[0.49, -2.46, -1.43], [0.01, 0.02, -1.05], [0.74, -1.55, -1.29], REST_ANGLES],
        }
    }

    /// Duration of one pass through the four states.
    pub fn cycle_duration(&self) -> f64 {
        self.durations.iter().sum()
    }

    /// The state (0..4) active `t` seconds into a cycle-aligned run, and the target pose.
    pub fn state_at(&self, t: f64) -> usize {
        let cycle = self.cycle_duration();
        let mut u = t.rem_euclid(cycle);
        for (s, d) in self.durations.iter().enumerate() {
            if u < *d {
                return s;
            }
            u -= d;
        }
        3
    }

    /// Checks that durations are in (0, [`MAX_STATE_SECONDS`]] seconds and angles finite and
    /// within +-2 pi.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(i) = self.durations.iter().position(|d| !(d.is_finite() && *d > 0.0 && *d <= MAX_STATE_SECONDS)) {
            return Err(format!(
                "hop duration t{} is {:?} s: give durations in (0, {MAX_STATE_SECONDS}] seconds, found {:?}",
                i + 1,
                self.durations[i],
                self.durations
            ));
        }
        let tau = std::f64::consts::TAU;
        if let Some(a) = self.poses.iter().flatten().find(|a| !(a.is_finite() && a.abs() <= tau)) {
            return Err(format!("hop target poses must be finite angles within [-2 pi, 2 pi] radians, found {a:?}"));
        }
        Ok(())
    }
}

/// The longest state of a hop policy, seconds (the paper's are 0.04 to 0.6 s).
pub const MAX_STATE_SECONDS: f64 = 10.0;
/// The most hop cycles of a rollout (the paper's three).
pub const MAX_CYCLES: usize = 100;
/// The longest settling time after the last cycle, seconds.
pub const MAX_SETTLE_SECONDS: f64 = 60.0;
/// The most integration steps of one rollout (its poses, contacts and clearances are kept:
/// about 60 MB; at the default 480 steps per second, 35 minutes of simulated time).
pub const MAX_ROLLOUT_STEPS: usize = 1_000_000;

/// The integration steps of a rollout of `run_s` seconds of cycles and `settle_s` seconds of
/// settling at step `dt`, refused past [`MAX_ROLLOUT_STEPS`] before anything is simulated or
/// allocated.
pub fn rollout_steps(run_s: f64, settle_s: f64, dt: f64) -> Result<usize, String> {
    let steps = ((run_s + settle_s) / dt).round();
    if !(steps.is_finite() && steps >= 0.0 && steps <= MAX_ROLLOUT_STEPS as f64) {
        return Err(format!(
            "a rollout of {run_s:?} s of hop cycles and {settle_s:?} s of settling at dt = {dt:?} s is {steps:.0} integration \
             steps, more than the {MAX_ROLLOUT_STEPS} zoo simulates: raise dt or shorten the hop durations, cycles \
             or settle_s"
        ));
    }
    Ok(steps as usize)
}

/// How long to run a policy.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RolloutOptions {
    /// Passes through the pose control graph (hops); the paper uses three.
    pub cycles: usize,
    /// Seconds simulated after the last cycle, holding the rest pose, so that the last
    /// landing and the still phase after it are recorded.
    pub settle_s: f64,
    /// Stop as soon as the lamp falls over (the rollout is then not a hop sequence).
    pub stop_on_fall: bool,
}

impl Default for RolloutOptions {
    fn default() -> Self {
        RolloutOptions { cycles: 3, settle_s: 0.4, stop_on_fall: true }
    }
}

/// The simulated motion of a policy: the pose and ground contact after every step.
#[derive(Clone, Debug, PartialEq)]
pub struct Rollout {
    /// Integration step (seconds); `poses[i]` is the state at time `(i + 1) * dt`, and
    /// `initial` the state at time 0.
    pub dt: f64,
    /// The starting pose.
    pub initial: LampPose,
    /// Pose after each step.
    pub poses: Vec<LampPose>,
    /// Whether the lamp touched the ground after each step.
    pub touching: Vec<bool>,
    /// Lowest point of the lamp above the ground after each step (metres).
    pub clearance: Vec<f64>,
    /// The lamp fell over (a link other than the base touched the ground, or the base
    /// tipped past 60 degrees).
    pub fell: bool,
}

impl Rollout {
    /// Pose at step `i` of the full track (0 = initial, `i` = after `i` steps).
    pub fn pose_at_step(&self, i: usize) -> LampPose {
        if i == 0 { self.initial } else { self.poses[i - 1] }
    }

    /// Base x travelled from the start to the end (metres; negative when hopping back).
    pub fn distance(&self) -> f64 {
        self.poses.last().map_or(0.0, |p| p[0] - self.initial[0])
    }

    /// Highest base height reached above its starting height (metres).
    pub fn max_height(&self) -> f64 {
        self.poses.iter().map(|p| p[1] - self.initial[1]).fold(0.0, f64::max)
    }
}

/// Runs `policy` on a fresh lamp standing in [`REST_ANGLES`]. Deterministic: the same
/// parameters and policy give the same rollout, bit for bit.
pub fn simulate(params: &LampParams, policy: &HopPolicy, options: &RolloutOptions) -> Result<Rollout, String> {
    policy.validate()?;
    let mut lamp = Lamp::new(params, REST_ANGLES)?;
    let dt = params.dt;
    let run_s = policy.cycle_duration() * options.cycles as f64;
    let steps = rollout_steps(run_s, options.settle_s, dt)?;
    let mut rollout = Rollout {
        dt,
        initial: lamp.pose(),
        poses: Vec::with_capacity(steps),
        touching: Vec::with_capacity(steps),
        clearance: Vec::with_capacity(steps),
        fell: false,
    };
    let mut state = usize::MAX;
    for i in 0..steps {
        // The controller reads the clock at the start of the step.
        let t = i as f64 * dt;
        // State 4 is the settling phase after the last cycle.
        let s = if t < run_s { policy.state_at(t) } else { 4 };
        if s != state {
            let targets = if s < 4 { policy.poses[s] } else { REST_ANGLES };
            lamp.set_targets(targets);
            state = s;
        }
        lamp.step();
        let clearance = lamp.clearance();
        rollout.poses.push(lamp.pose());
        rollout.clearance.push(clearance);
        rollout.touching.push(clearance <= params.contact_tolerance);
        if lamp.has_fallen() {
            rollout.fell = true;
            if options.stop_on_fall {
                break;
            }
        }
    }
    Ok(rollout)
}
