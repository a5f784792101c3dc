//! Following a ground path in real time with an exported RNN-GMM generator: the online
//! controller of [`crate::control`] with a path goal instead of a speed and a heading.
//!
//! The offline path follower of the paper (sec. 5.2, `zoo_rnngmm::follow`, `zoo bench follow`)
//! optimises whole windows of frames with gradients through the network; tract gives none, so
//! the runtime plans as its speed / heading controller does: every `n` frames
//! ([`ControlSettings::batch`]) it rolls `K` candidates out from the plan's end, one batched
//! generator step per frame, and keeps the one of least cost. Under a [`PathGoal`] a
//! candidate's cost is its prior (as under a [`crate::control::Control`]) plus three terms, all
//! on the ground (`x`, `z`, clip units):
//! - fit (the curve term of eq. 17): the sum over its `n` frames of the squared distance of the
//!   root to the path, over `sigma_fit^2`;
//! - progress: `(s - s_goal)^2 / sigma_progress^2`, `s` the arc length of the path point
//!   nearest to the candidate's last root, `s_goal` the plan end's plus `speed` times the
//!   batch's duration: walking backwards or stopping costs as much as straying;
//! - heading: the facing yaw after the candidate against the direction from its last root to
//!   the path point `lookahead` seconds of walking further along (pure pursuit), over
//!   `sigma_heading^2`: it turns the character before a bend rather than after.
//!
//! The nearest point is searched from a second of walking behind the progress so far to four
//! seconds ahead of it (a path that comes back near itself is not cut short), and past the
//! path's end along its last direction, so the character walks through the end; the walk is
//! over when the progress reaches the path's length ([`PathGoal::reached_end`]).
//!
//! The planner's candidates ([`PathSettings::control`]) add sideways offsets to the
//! controller's forward and turn offsets: the character steps back onto the path rather than
//! only turning towards it.
//!
//! Costs per frame are those of the controller plus `O(K n)` nearest-point searches over the
//! segments within that window every `n` frames; nothing is allocated after the first step.

use crate::control::{ControlRunner, ControlSettings, ControlledCharacter, Goal, wrap};
use crate::error::MotionError;
use crate::pose::EnginePose;

/// Weights of a [`PathGoal`]'s cost terms (see the module's doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSettings {
    /// Standard deviation of a root's distance to the path, clip units.
    pub sigma_fit: f64,
    /// Standard deviation of the progress along the path against its goal, clip units.
    pub sigma_progress: f64,
    /// Standard deviation of the facing against the pursuit direction, radians.
    pub sigma_heading: f64,
    /// How far ahead the pursuit point is, in seconds of walking at the goal's speed.
    pub lookahead: f64,
}

impl Default for PathSettings {
    /// `sigma_fit` 1.5 clip units, `sigma_progress` 5 clip units, `sigma_heading` 0.05 rad, a
    /// lookahead of 0.35 s: chosen on the path-following benchmark's five test paths with a
    /// tiny generator trained on synthetic data (docs/rnn-gmm-control.md, "Following a path in
    /// the runtime"), with [`PathSettings::control`]'s candidates.
    fn default() -> Self {
        PathSettings { sigma_fit: 1.5, sigma_progress: 5.0, sigma_heading: 0.05, lookahead: 0.35 }
    }
}

impl PathSettings {
    /// The planner's settings for following a path: the speed / heading controller's defaults
    /// with sideways offsets `-1.5, 0, 1.5` (75 candidates): a path is held by stepping onto
    /// it as well as by turning (without them the same model strays 2 to 4 times as far on
    /// the benchmark's paths and stalls at the corner's 120-degree turn).
    pub fn control() -> ControlSettings {
        ControlSettings { side_offsets: vec![-1.5, 0.0, 1.5], ..ControlSettings::default() }
    }
}

/// A ground path to follow at a speed, and the progress along it so far.
#[derive(Clone, Debug, PartialEq)]
pub struct PathGoal {
    points: Vec<[f64; 2]>,
    /// Arc length at each point.
    lengths: Vec<f64>,
    speed: f64,
    settings: PathSettings,
    progress: f64,
}

fn path_error(reason: String) -> MotionError {
    MotionError::Control { reason: format!("path: {reason}") }
}

impl PathGoal {
    /// A path through ground `points` (`x`, `z`, clip units; consecutive duplicates dropped) to
    /// walk at `speed` clip units per second. Refused: fewer than 2 distinct points, a
    /// non-finite coordinate, a speed that is not positive and finite, settings that are not
    /// positive and finite (the lookahead may be 0).
    pub fn new(points: &[[f64; 2]], speed: f64, settings: PathSettings) -> Result<Self, MotionError> {
        if let Some((i, p)) = points.iter().enumerate().find(|(_, p)| !(p[0].is_finite() && p[1].is_finite())) {
            return Err(path_error(format!("point {i} is ({}, {}); give finite ground coordinates x, z", p[0], p[1])));
        }
        let mut kept: Vec<[f64; 2]> = Vec::with_capacity(points.len());
        for p in points {
            if kept.last() != Some(p) {
                kept.push(*p);
            }
        }
        if kept.len() < 2 {
            return Err(path_error(format!(
                "{} distinct point(s); a path needs at least 2 (the ground points x, z it runs through)",
                kept.len()
            )));
        }
        if !(speed.is_finite() && speed > 0.0) {
            return Err(path_error(format!(
                "the speed is {speed}; give a positive finite speed in clip units per second (cm/s for the zoo's data)"
            )));
        }
        for (name, v) in [
            ("sigma_fit", settings.sigma_fit),
            ("sigma_progress", settings.sigma_progress),
            ("sigma_heading", settings.sigma_heading),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(path_error(format!("{name} is {v}; give a positive finite value")));
            }
        }
        if !(settings.lookahead.is_finite() && settings.lookahead >= 0.0) {
            return Err(path_error(format!(
                "lookahead is {}; give a finite number of seconds >= 0",
                settings.lookahead
            )));
        }
        let mut lengths = Vec::with_capacity(kept.len());
        let mut s = 0.0;
        for (i, p) in kept.iter().enumerate() {
            if i > 0 {
                s += dist(kept[i - 1], *p);
            }
            lengths.push(s);
        }
        Ok(PathGoal { points: kept, lengths, speed, settings, progress: 0.0 })
    }

    /// The path's length, clip units.
    pub fn length(&self) -> f64 {
        *self.lengths.last().expect("at least 2 points")
    }

    /// Arc length of the path point nearest to the plan's end so far, clip units.
    pub fn progress(&self) -> f64 {
        self.progress
    }

    /// Whether the progress has reached the path's end.
    pub fn reached_end(&self) -> bool {
        self.progress >= self.length()
    }

    /// The speed walked at, clip units per second.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The placement at the path's start facing along its first segment: `x`, `z`, facing yaw
    /// (radians about +Y, 0 facing +Z), for [`ControlledCharacter::start`].
    pub fn start_placement(&self) -> [f64; 3] {
        let ([x0, z0], [x1, z1]) = (self.points[0], self.points[1]);
        [x0, z0, (x1 - x0).atan2(z1 - z0)]
    }

    /// The distance of ground point `p` to the path (its nearest point anywhere on it).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        (0..self.points.len() - 1).map(|i| self.on_segment(i, p, false).1).fold(f64::INFINITY, f64::min)
    }

    /// Arc length and distance of the point of segment `i` nearest to `p`; the last segment
    /// runs on past the path's end when `extend`.
    fn on_segment(&self, i: usize, p: [f64; 2], extend: bool) -> (f64, f64) {
        let (a, b) = (self.points[i], self.points[i + 1]);
        let ab = [b[0] - a[0], b[1] - a[1]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1];
        let mut w = ((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2;
        let last = i + 2 == self.points.len();
        w = if extend && last { w.max(0.0) } else { w.clamp(0.0, 1.0) };
        let q = [a[0] + w * ab[0], a[1] + w * ab[1]];
        (self.lengths[i] + w * len2.sqrt(), dist(p, q))
    }

    /// Arc length and distance of the path point nearest to `p` within the search window
    /// (a second of walking behind the progress to four ahead, the end extended).
    fn project(&self, p: [f64; 2]) -> (f64, f64) {
        let (from, to) = (self.progress - self.speed, self.progress + 4.0 * self.speed);
        let mut best = (self.progress, f64::INFINITY);
        let segments = self.points.len() - 1;
        // The first segment that reaches `from` (the last one at least: it runs on past the end).
        let first = self.lengths[1..].partition_point(|&l| l < from).min(segments - 1);
        for i in first..segments {
            if self.lengths[i] > to {
                break;
            }
            let found = self.on_segment(i, p, true);
            if found.1 < best.1 {
                best = found;
            }
        }
        best
    }

    /// The path point at arc length `s` (past the end, along the last segment's direction).
    fn point_at(&self, s: f64) -> [f64; 2] {
        let last = self.points.len() - 2;
        let i = self.lengths.partition_point(|&l| l <= s).saturating_sub(1).min(last);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let w = (s - self.lengths[i]) / (self.lengths[i + 1] - self.lengths[i]);
        [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])]
    }

    /// The cost terms `(progress, heading, fit)` of a candidate whose root goes through
    /// `ground` (one point per frame of a batch of `seconds`) and faces `yaw` after it.
    pub(crate) fn costs(&self, ground: &[[f64; 2]], yaw: f64, seconds: f64) -> (f64, f64, f64) {
        let st = &self.settings;
        let mut fit = 0.0;
        let mut end = (self.progress, 0.0);
        for p in ground {
            end = self.project(*p);
            fit += (end.1 / st.sigma_fit).powi(2);
        }
        let goal = self.progress + self.speed * seconds;
        let progress = ((end.0 - goal) / st.sigma_progress).powi(2);
        let last = *ground.last().expect("a batch has frames");
        let ahead = self.point_at(end.0 + self.speed * st.lookahead);
        let (dx, dz) = (ahead[0] - last[0], ahead[1] - last[1]);
        let heading = if dx.hypot(dz) > 1e-9 { (wrap(yaw - dx.atan2(dz)) / st.sigma_heading).powi(2) } else { 0.0 };
        (progress, heading, fit)
    }

    /// Moves the progress to the plan's new end.
    pub(crate) fn advance(&mut self, end: [f64; 2]) {
        self.progress = self.project(end).0;
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl ControlRunner {
    /// Plays the character's next frame into `pose` as [`ControlRunner::step`] does, planning
    /// its batches to follow `path` (see the module's doc) instead of a speed and a heading.
    /// Start the character at [`PathGoal::start_placement`] and step until
    /// [`PathGoal::reached_end`]. Returns the frame's contact bits `[left, right]`.
    pub fn step_along(
        &mut self,
        character: &mut ControlledCharacter,
        path: &mut PathGoal,
        pose: &mut EnginePose,
    ) -> Result<[bool; 2], MotionError> {
        self.step_goal(character, Goal::Path(path), pose)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn corner() -> PathGoal {
        PathGoal::new(&[[0.0, 0.0], [0.0, 100.0], [100.0, 100.0]], 50.0, PathSettings::default()).unwrap()
    }

    #[test]
    fn points_are_projected_and_placed_along_the_path() {
        let mut p = corner();
        assert_eq!(p.length(), 200.0);
        assert_eq!(p.start_placement(), [0.0, 0.0, 0.0]);
        assert_eq!(p.point_at(150.0), [50.0, 100.0]);
        assert_eq!(p.point_at(250.0), [150.0, 100.0]);
        assert_eq!(p.distance([3.0, 40.0]), 3.0);
        p.advance([2.0, 60.0]);
        assert_eq!(p.progress(), 60.0);
        assert!(!p.reached_end());
        p.advance([130.0, 104.0]);
        assert_eq!(p.progress(), 230.0);
        assert!(p.reached_end());
    }

    #[test]
    fn a_candidate_off_the_path_or_walking_back_costs_more() {
        let p = corner();
        let on: Vec<[f64; 2]> = (1..=3).map(|f| [0.0, 50.0 / 30.0 * f as f64]).collect();
        let off: Vec<[f64; 2]> = on.iter().map(|q| [q[0] + 10.0, q[1]]).collect();
        let back: Vec<[f64; 2]> = on.iter().map(|q| [q[0], -q[1]]).collect();
        let total = |c: (f64, f64, f64)| c.0 + c.1 + c.2;
        let (good, stray, reverse) =
            (total(p.costs(&on, 0.0, 0.1)), total(p.costs(&off, 0.0, 0.1)), total(p.costs(&back, 0.0, 0.1)));
        assert!(good < 1e-9, "{good}");
        assert!(stray > 10.0 && reverse > 0.5, "{stray} {reverse}");
        // Facing away from the pursuit point costs.
        assert!(p.costs(&on, 1.0, 0.1).1 > 50.0);
    }

    #[test]
    fn bad_paths_are_refused_with_the_fix() {
        let err = |r: Result<PathGoal, MotionError>| r.unwrap_err().to_string();
        let s = PathSettings::default();
        assert!(
            err(PathGoal::new(&[[0.0, 0.0], [0.0, 0.0]], 1.0, s))
                .contains("1 distinct point(s); a path needs at least 2")
        );
        assert!(err(PathGoal::new(&[[0.0, 0.0], [f64::NAN, 1.0]], 1.0, s)).contains("point 1 is (NaN, 1)"));
        assert!(err(PathGoal::new(&[[0.0, 0.0], [0.0, 1.0]], 0.0, s)).contains("the speed is 0"));
        let bad = PathSettings { lookahead: -1.0, ..s };
        assert!(err(PathGoal::new(&[[0.0, 0.0], [0.0, 1.0]], 1.0, bad)).contains("lookahead is -1"));
    }
}
