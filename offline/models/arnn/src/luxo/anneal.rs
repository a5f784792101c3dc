//! Simulated annealing over hop policies, ARNN section 4.4 (Algorithm 1).
//!
//! The energy of a policy is `E = -(1 - w_e) D - w_e H_max` (eq. 1) over three hops, with the
//! distance `D` and the highest base height `H_max` in centimetres: the paper's temperature
//! schedule `T(K) = 2 * 0.999307^K` only cools from 2 to 1 over `K_max = 1000` iterations, so
//! the energy must be in units where a change of about 1 matters; a centimetre does.
//! A policy whose rollout falls over or does not make exactly the requested number of hops
//! gets [`INVALID_ENERGY`], which the acceptance rule never takes over a valid one.
//!
//! The loop is written here rather than with argmin's `SimulatedAnnealing`: the paper's
//! neighbour move (one duration by 7 ms and one angle of every target pose by 0.5 rad), its
//! cooling schedule and the rule that every random number comes from the project's
//! [`SplitMix64`] (so runs are reproducible and independent of thread scheduling) would each
//! have to be worked around in argmin, for a loop of a few lines.

use super::controller::{
    HopPolicy, MAX_CYCLES, MAX_SETTLE_SECONDS, MAX_STATE_SECONDS, Rollout, RolloutOptions, simulate,
};
use super::lamp::LampParams;
use super::sequence::{Hop, detect_hops};
use serde::{Deserialize, Serialize};
use zoo_motion::rng::SplitMix64;

/// The most annealing iterations per run (the command line's `--k-max` range).
pub const MAX_K: usize = 1_000_000;

/// Energy of a policy that falls over or does not hop the requested number of times.
pub const INVALID_ENERGY: f64 = 1.0e6;

/// Settings of one simulated annealing run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnnealConfig {
    /// Iterations `K_max` (paper: 1000).
    pub k_max: usize,
    /// Initial temperature `T_max` (paper: 2).
    pub t_max: f64,
    /// Cooling factor per iteration, `T(K) = t_max * cooling^K` (paper: 0.999307).
    pub cooling: f64,
    /// Step of the perturbed duration (paper: 7 ms), seconds, random sign.
    pub duration_step: f64,
    /// Step of the perturbed angle of each target pose (paper: 0.5 rad), random sign.
    pub angle_step: f64,
    /// Durations are kept in `[min, max]` seconds.
    pub duration_range: [f64; 2],
    /// The simulated rollout (three hops in the paper).
    pub rollout: RolloutOptions,
    /// Airborne phases shorter than this (seconds) are bounces, not hops.
    pub min_air_s: f64,
    /// A satisfactory run travels at least this far over all its hops (metres).
    pub min_distance: f64,
    /// A satisfactory run lifts the base at least this high above its rest height (metres).
    pub min_height: f64,
}

impl Default for AnnealConfig {
    fn default() -> Self {
        AnnealConfig {
            k_max: 1000,
            t_max: 2.0,
            cooling: 0.999307,
            duration_step: 0.007,
            angle_step: 0.5,
            duration_range: [0.04, 0.6],
            rollout: RolloutOptions::default(),
            min_air_s: 0.04,
            min_distance: 0.15,
            min_height: 0.03,
        }
    }
}

impl AnnealConfig {
    /// Temperature after iteration `k` (section 4.4.4).
    pub fn temperature(&self, k: usize) -> f64 {
        self.t_max * self.cooling.powi(k as i32)
    }

    /// Checks the settings, each in its range (the message names it, its value and the range):
    /// `k_max` in 1..=[`MAX_K`], `t_max` in (0, 1e6], `cooling` in (0, 1], `duration_step` in
    /// [0, 10] s, `angle_step` in [0, 2 pi], `duration_range` with 0 < min < max <=
    /// [`MAX_STATE_SECONDS`], `rollout.cycles` in 1..=[`MAX_CYCLES`], `rollout.settle_s` in
    /// [0, [`MAX_SETTLE_SECONDS`]], `min_air_s` in [0, 10] s, `min_distance` and `min_height` in
    /// [0, 1000] m.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=MAX_K).contains(&self.k_max) {
            return Err(format!("anneal k_max is {}: give a whole number of iterations in 1..={MAX_K}", self.k_max));
        }
        if !(self.t_max.is_finite() && self.t_max > 0.0 && self.t_max <= 1e6) {
            return Err(format!("anneal t_max is {:?}: give a temperature in (0, 1000000]", self.t_max));
        }
        if !(self.cooling > 0.0 && self.cooling <= 1.0) {
            return Err(format!("anneal cooling is {:?}: give a factor in (0, 1]", self.cooling));
        }
        let [lo, hi] = self.duration_range;
        if !(lo > 0.0 && lo < hi && hi <= MAX_STATE_SECONDS) {
            return Err(format!(
                "anneal duration_range is [{lo:?}, {hi:?}]: give 0 < min < max <= {MAX_STATE_SECONDS} seconds"
            ));
        }
        if !(1..=MAX_CYCLES).contains(&self.rollout.cycles) {
            return Err(format!(
                "rollout cycles is {}: give a whole number of hops in 1..={MAX_CYCLES}",
                self.rollout.cycles
            ));
        }
        let tau = std::f64::consts::TAU;
        for (name, v, most, unit) in [
            ("duration_step", self.duration_step, 10.0, "s"),
            ("angle_step", self.angle_step, tau, "rad"),
            ("min_air_s", self.min_air_s, 10.0, "s"),
            ("min_distance", self.min_distance, 1000.0, "m"),
            ("min_height", self.min_height, 1000.0, "m"),
            ("rollout.settle_s", self.rollout.settle_s, MAX_SETTLE_SECONDS, "s"),
        ] {
            if !(v.is_finite() && (0.0..=most).contains(&v)) {
                return Err(format!("anneal {name} is {v:?} {unit}: give a number in [0, {most}] {unit}"));
            }
        }
        Ok(())
    }
}

/// What a rollout achieved.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Base x travelled (metres).
    pub distance: f64,
    /// Highest base height above rest (metres).
    pub max_height: f64,
    /// Hops found.
    pub hops: usize,
    /// The lamp fell over.
    pub fell: bool,
    /// Energy (eq. 1, centimetres) or [`INVALID_ENERGY`].
    pub energy: f64,
    /// Not fallen, the requested number of hops, distance and height reached.
    pub satisfactory: bool,
}

/// Evaluates a rollout for the energy weight `w_e`.
pub fn evaluate(rollout: &Rollout, hops: &[Hop], w_e: f64, cfg: &AnnealConfig) -> Evaluation {
    let distance = rollout.distance();
    let max_height = rollout.max_height();
    let valid = !rollout.fell && hops.len() == cfg.rollout.cycles;
    let energy = if valid { -(1.0 - w_e) * distance * 100.0 - w_e * max_height * 100.0 } else { INVALID_ENERGY };
    Evaluation {
        distance,
        max_height,
        hops: hops.len(),
        fell: rollout.fell,
        energy,
        satisfactory: valid && distance >= cfg.min_distance && max_height >= cfg.min_height,
    }
}

/// Simulates and evaluates a policy.
pub fn score(
    params: &LampParams,
    policy: &HopPolicy,
    w_e: f64,
    cfg: &AnnealConfig,
) -> Result<(Rollout, Vec<Hop>, Evaluation), String> {
    let rollout = simulate(params, policy, &cfg.rollout)?;
    let hops = detect_hops(&rollout.touching, rollout.dt, cfg.min_air_s);
    let eval = evaluate(&rollout, &hops, w_e, cfg);
    Ok((rollout, hops, eval))
}

/// Section 4.4.2: one of the four durations moves by `duration_step` and one angle of each
/// of the four target poses by `angle_step`, each with a random sign; durations stay in
/// `duration_range` and angles within the joint limits.
pub fn neighbour(policy: &HopPolicy, params: &LampParams, cfg: &AnnealConfig, rng: &mut SplitMix64) -> HopPolicy {
    let mut next = *policy;
    let d = rng.below(4) as usize;
    next.durations[d] =
        (next.durations[d] + rng.sign() * cfg.duration_step).clamp(cfg.duration_range[0], cfg.duration_range[1]);
    for pose in &mut next.poses {
        let j = rng.below(3) as usize;
        let [lo, hi] = params.joint_limits[j];
        pose[j] = (pose[j] + rng.sign() * cfg.angle_step).clamp(lo, hi);
    }
    next
}

/// What happened to the candidates of annealing runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AnnealStats {
    /// Candidates simulated (`K_max` per run).
    pub candidates: usize,
    /// Candidates that made the requested hops without falling (finite energy).
    pub valid: usize,
    /// Candidates accepted by the Metropolis rule.
    pub accepted: usize,
    /// Candidates whose rollout fell over.
    pub fell: usize,
    /// Candidates that did not fall but made another number of hops.
    pub wrong_hops: usize,
}

impl AnnealStats {
    /// Adds another run's counts.
    pub fn add(&mut self, o: &AnnealStats) {
        self.candidates += o.candidates;
        self.valid += o.valid;
        self.accepted += o.accepted;
        self.fell += o.fell;
        self.wrong_hops += o.wrong_hops;
    }
}

/// The result of one annealing run.
#[derive(Clone, Debug, PartialEq)]
pub struct AnnealOutcome {
    /// The lowest-energy policy met during the run.
    pub best: HopPolicy,
    /// Its evaluation.
    pub evaluation: Evaluation,
    /// Candidates accepted.
    pub accepted: usize,
    /// What happened to the candidates.
    pub stats: AnnealStats,
}

/// Algorithm 1 from `init` with energy weight `w_e`: `k_max` neighbours, each accepted when
/// its energy is lower or with probability `exp(-(E' - E) / T)` (eq. 2). Returns the best
/// policy seen.
pub fn anneal(
    params: &LampParams,
    cfg: &AnnealConfig,
    init: &HopPolicy,
    w_e: f64,
    rng: &mut SplitMix64,
) -> Result<AnnealOutcome, String> {
    cfg.validate()?;
    let (_, _, mut current_eval) = score(params, init, w_e, cfg)?;
    let mut current = *init;
    let mut best = (current, current_eval.clone());
    let mut accepted = 0;
    let mut stats = AnnealStats { candidates: cfg.k_max, ..AnnealStats::default() };
    let mut temperature = cfg.t_max;
    for k in 0..cfg.k_max {
        let candidate = neighbour(&current, params, cfg, rng);
        let (_, _, eval) = score(params, &candidate, w_e, cfg)?;
        if eval.fell {
            stats.fell += 1;
        } else if eval.hops != cfg.rollout.cycles {
            stats.wrong_hops += 1;
        } else {
            stats.valid += 1;
        }
        let delta = eval.energy - current_eval.energy;
        // Draw every iteration so the random stream does not depend on the energies.
        let u = rng.next_f64();
        if delta < 0.0 || u < (-delta / temperature).exp() {
            if eval.energy < best.1.energy {
                best = (candidate, eval.clone());
            }
            current = candidate;
            current_eval = eval;
            accepted += 1;
        }
        temperature = cfg.temperature(k + 1);
    }
    stats.accepted = accepted;
    Ok(AnnealOutcome { best: best.0, evaluation: best.1, accepted, stats })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temperature_follows_the_paper() {
        let cfg = AnnealConfig::default();
        assert_eq!(cfg.temperature(0), 2.0);
        // 0.999307^1000 = 0.5: the schedule halves the temperature over a run.
        assert!((cfg.temperature(1000) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn neighbour_moves_one_duration_and_one_angle_per_pose() {
        let params = LampParams::default();
        let cfg = AnnealConfig::default();
        let init = HopPolicy::hand_set();
        let mut rng = SplitMix64::new(5);
        for _ in 0..50 {
            let n = neighbour(&init, &params, &cfg, &mut rng);
            let moved_d: Vec<f64> =
                init.durations.iter().zip(&n.durations).map(|(a, b)| (a - b).abs()).filter(|d| *d > 0.0).collect();
            assert!(moved_d.len() <= 1 && moved_d.iter().all(|d| (*d - 0.007).abs() < 1e-12), "{moved_d:?}");
            for (p, q) in init.poses.iter().zip(&n.poses) {
                let moved: Vec<f64> = p.iter().zip(q).map(|(a, b)| (a - b).abs()).filter(|d| *d > 0.0).collect();
                assert!(moved.len() <= 1 && moved.iter().all(|d| *d <= 0.5 + 1e-12), "{moved:?}");
            }
        }
    }

    #[test]
    fn invalid_rollouts_get_the_invalid_energy() {
        let cfg = AnnealConfig::default();
        let rollout = Rollout {
            dt: 0.01,
            initial: [0.0; 6],
            poses: vec![[0.5, 0.1, 0.0, 0.0, 0.0, 0.0]],
            touching: vec![true],
            clearance: vec![0.0],
            fell: true,
        };
        let e = evaluate(&rollout, &[], 0.5, &cfg);
        assert_eq!(e.energy, INVALID_ENERGY);
        assert!(!e.satisfactory);
    }
}
