//! Online speed and direction control of an exported RNN-GMM generator (Wang, Chai & Xia 2019,
//! sec. 5.3, eq. 20-23): a [`ControlledCharacter`] walks at a target speed and turns to a
//! target facing yaw ([`Control`]), stepped one frame per call by a per-thread
//! [`ControlRunner`].
//!
//! The paper finds each batch of `n` frames by MAP optimisation with gradients through the
//! network (the generator's likelihood as the prior, eq. 22 for the speed, eq. 23 for the
//! direction). tract gives no gradients, so the runtime runs the closest real-time controller
//! over the exported step graph: sampling-based model-predictive control, pipelined so that
//! every frame costs one batched generator step.
//!
//! # Algorithm
//! A *plan* is `n` frames ([`ControlSettings::batch`], normalised) being played, and the
//! generator state after them. While it plays, `K` candidates for the next batch are rolled out,
//! one frame per [`ControlRunner::step`], all `K` in one batched run of the step graph:
//! candidate `k = s * T + t` (speed offset `s`, turn offset `t` of
//! [`ControlSettings::speed_offsets`] x [`ControlSettings::turn_offsets`], `T` turn offsets)
//! starts from the plan's end state reading the plan's last frame; each of its frames is drawn
//! from the generator's mixture as [`crate::synthesis`] draws (a component by its weight, then
//! `mu + temperature * sigma * n` per value), then `dtz` (dim 1) gets `+ s` and `dry` (dim 2)
//! `+ t`, in normalised units (data standard deviations), and is fed back. Its cost:
//! - prior: the sum over its frames of the negative log-likelihood of the frame (offsets
//!   included) under the mixture it was drawn from (the model's standard deviations, whatever
//!   the temperature), normalised units;
//! - speed (eq. 22): `(mean over its n frames of hypot(dtx, dtz) * fps - speed)^2 / sigma_speed^2`,
//!   `dtx, dtz` in clip units, `fps` from the model's `zoo.fps`;
//! - direction (eq. 23): `wrap(yaw after its last frame - heading)^2 / sigma_heading^2`, the
//!   yaw being the plan end's plus the sum of the candidate's `dry` (clip units, radians),
//!   wrapped to `[-pi, pi)`.
//!
//! In the call that plays the plan's last frame, after the candidates' `n`-th frame, the
//! candidate of least cost under that call's [`Control`] becomes the plan and the next
//! candidates start from its end. The first step after [`ControlledCharacter::start`] has no
//! plan: it feeds the seed frames, rolls the first candidates out at once (`n` batched steps)
//! and selects with its control. The contact term of eq. 20 is not modelled; the refiner of
//! a file that has one is not run (the controller plays the generator's frames).
//!
//! The offsets are charged through the prior: a sharp mixture (small standard deviations)
//! makes offsets dear, and `sigma_speed` / `sigma_heading` weigh the control against it, as
//! the paper's sigmas do.
//!
//! # Latency
//! A control is read only when a batch is selected, once every `n` frames, and the selected
//! batch plays from the next call: a control given at some call shows in the motion 1 to `n`
//! frames later (`n` when given right after a selection; default `n = 3`, a tenth of a second
//! at 30 fps), and the batch that serves it is judged by its speed over its `n` frames and its
//! facing at their end.
//!
//! # Cost per frame
//! One run of the generator's step graph for `K` rows (default 25), the sampling and the
//! likelihoods (`O(K M D)` for `M` components of `D` values) and the decoding of one pose;
//! plus, every `n` frames, the selection (`O(K)`) and a copy of the chosen batch (`O(n D)`). The
//! first step after a start runs `L - 1 + n + 1` batched steps for `L` seed frames. After the
//! first step nothing is allocated on our side (tract allocates its node outputs per run).
//!
//! # Determinism
//! A character's frames depend only on its model, settings, seed, seed frames, placement and
//! the sequence of controls: draws are taken frame by frame, candidate by candidate, from the
//! character's own `SplitMix64`, and the step graph runs with its symbolic-batch plan (see
//! [`crate::synthesis`]), so a run gives the same poses bit for bit every time, on any thread.

use crate::error::MotionError;
use crate::model::MotionState;
use crate::pose::EnginePose;
use crate::runner::{MotionRunner, check_finite, check_len};
use crate::synthesis::{SynthesisModel, decode_frame, draw_frame};
use glam::Quat;
use std::f64::consts::{PI, TAU};
use zoo_motion::rng::SplitMix64;

/// `ln(2 pi) / 2`, the normal density's constant.
const HALF_LN_TAU: f64 = 0.918_938_533_204_672_8;

fn control_error(reason: String) -> MotionError {
    MotionError::Control { reason }
}

/// A control target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Control {
    /// Target root speed over the ground, clip units per second (cm/s for the zoo's data);
    /// finite, `>= 0`.
    pub speed: f32,
    /// Target facing yaw, radians about +Y: 0 faces +Z, positive turns +Z towards +X (the
    /// pose's `root_rotation = Quat::from_rotation_y(yaw)`). Any finite value; compared
    /// wrapped to `[-pi, pi)`.
    pub heading: f32,
}

impl Control {
    /// A target speed (clip units per second) and facing yaw (radians about +Y).
    pub fn new(speed: f32, heading: f32) -> Self {
        Control { speed, heading }
    }

    /// Checks the target: a finite speed `>= 0` and a finite heading.
    pub fn check(&self) -> Result<(), MotionError> {
        if !(self.speed.is_finite() && self.speed >= 0.0) {
            return Err(control_error(format!(
                "the target speed is {}; give a finite speed >= 0 in clip units per second (cm/s for the zoo's data)",
                self.speed
            )));
        }
        if !self.heading.is_finite() {
            return Err(control_error(format!(
                "the target heading is {}; give a finite facing yaw in radians about +Y (0 faces +Z)",
                self.heading
            )));
        }
        Ok(())
    }
}

/// How a [`ControlledCharacter`] plans.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlSettings {
    /// Frames per planned batch `n` (the paper's batch; also the control latency in frames).
    pub batch: usize,
    /// Offsets added to every frame's `dtz` (dim 1) of a candidate, in normalised units
    /// (data standard deviations).
    pub speed_offsets: Vec<f32>,
    /// Offsets added to every frame's `dry` (dim 2) of a candidate, in normalised units.
    pub turn_offsets: Vec<f32>,
    /// Offsets added to every frame's `dtx` (dim 0, the sideways step) of a candidate, in
    /// normalised units: `[0]` (none) for speed / heading control; the path follower of
    /// [`crate::follow`] steps sideways onto its path with them.
    pub side_offsets: Vec<f32>,
    /// Standard deviation of the speed term (eq. 22), clip units per second.
    pub sigma_speed: f32,
    /// Standard deviation of the direction term (eq. 23), radians.
    pub sigma_heading: f32,
    /// Scale of the mixture's standard deviations when drawing (1: the model's, 0: its means).
    pub temperature: f32,
}

impl Default for ControlSettings {
    /// Batches of 3 frames, 5 x 5 candidates (forward and turn offsets -3, -1.5, 0, 1.5, 3
    /// each), `sigma_speed` 2 clip units per second, `sigma_heading` 0.02 rad, temperature 0.3:
    /// the candle controller's defaults (`zoo_rnngmm::OnlineOptions`), tuned on bandai2
    /// (docs/rnn-gmm-control.md).
    fn default() -> Self {
        ControlSettings {
            batch: 3,
            speed_offsets: vec![-3.0, -1.5, 0.0, 1.5, 3.0],
            turn_offsets: vec![-3.0, -1.5, 0.0, 1.5, 3.0],
            side_offsets: vec![0.0],
            sigma_speed: 2.0,
            sigma_heading: 0.02,
            temperature: 0.3,
        }
    }
}

impl ControlSettings {
    /// Candidates per batch: speed offsets x turn offsets x side offsets.
    pub fn candidates(&self) -> usize {
        self.speed_offsets.len() * self.turn_offsets.len() * self.side_offsets.len()
    }

    /// The offsets `(speed, turn, side)` of candidate `k` (`k = (s * turn_offsets.len() + t)
    /// * side_offsets.len() + l`).
    pub fn offsets(&self, k: usize) -> Option<(f32, f32, f32)> {
        let (t, l) = (self.turn_offsets.len(), self.side_offsets.len());
        (k < self.candidates())
            .then(|| (self.speed_offsets[k / (t * l)], self.turn_offsets[k / l % t], self.side_offsets[k % l]))
    }

    /// Checks the settings: `batch >= 1`, at least 2 candidates, finite offsets, positive
    /// finite sigmas, a finite temperature `>= 0`.
    pub fn check(&self) -> Result<(), MotionError> {
        if self.batch == 0 {
            return Err(control_error("settings: batch is 0; plan at least 1 frame per batch (default 3)".into()));
        }
        if self.candidates() < 2 {
            return Err(control_error(format!(
                "settings: {} speed offsets x {} turn offsets x {} side offsets make {} candidates; give at least 2 to choose from (default 5 x 5 x 1)",
                self.speed_offsets.len(),
                self.turn_offsets.len(),
                self.side_offsets.len(),
                self.candidates()
            )));
        }
        for (name, offsets) in [
            ("speed_offsets", &self.speed_offsets),
            ("turn_offsets", &self.turn_offsets),
            ("side_offsets", &self.side_offsets),
        ] {
            if let Some(v) = offsets.iter().find(|v| !v.is_finite()) {
                return Err(control_error(format!(
                    "settings: {name} holds {v}; give finite offsets in data standard deviations"
                )));
            }
        }
        for (name, v, unit) in [
            ("sigma_speed", self.sigma_speed, "clip units per second (default 2)"),
            ("sigma_heading", self.sigma_heading, "radians (default 0.02)"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(control_error(format!("settings: {name} is {v}; give a positive finite value in {unit}")));
            }
        }
        if !(self.temperature.is_finite() && self.temperature >= 0.0) {
            return Err(control_error(format!(
                "settings: temperature is {}; give a finite value >= 0 (1: the model's spread)",
                self.temperature
            )));
        }
        Ok(())
    }
}

/// The candidate chosen at a selection and its cost terms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlSelection {
    /// Its index, `(s * turn_offsets.len() + t) * side_offsets.len() + l`.
    pub candidate: usize,
    /// Its offset of `dtz`, normalised units.
    pub speed_offset: f32,
    /// Its offset of `dry`, normalised units.
    pub turn_offset: f32,
    /// Its offset of `dtx`, normalised units.
    pub side_offset: f32,
    /// Its mean root speed over the batch, clip units per second.
    pub speed: f64,
    /// Its facing yaw after the batch, radians (not wrapped).
    pub heading: f64,
    /// Prior term: the negative log-likelihood of its frames.
    pub prior: f64,
    /// Speed term (eq. 22).
    pub speed_cost: f64,
    /// Direction term (eq. 23).
    pub heading_cost: f64,
    /// Path term of [`crate::follow`] (its frames' distances to the path); 0 under a [`Control`].
    pub path_cost: f64,
}

impl ControlSelection {
    /// The total cost it was chosen by.
    pub fn cost(&self) -> f64 {
        self.prior + self.speed_cost + self.heading_cost + self.path_cost
    }
}

/// What a selection aims at: a speed and heading, or a path to follow ([`crate::follow`]).
pub(crate) enum Goal<'a> {
    Control(Control),
    Path(&'a mut crate::follow::PathGoal),
}

/// One controlled character: its plan, its candidates being rolled out, its random numbers and
/// where it stands. Create it with [`ControlledCharacter::new`], give it seed frames with
/// [`ControlledCharacter::start`], step it with a [`ControlRunner`] of the same model.
#[derive(Clone, Debug)]
pub struct ControlledCharacter {
    settings: ControlSettings,
    /// `(speed, turn)` offset of every candidate.
    offsets: Vec<[f32; 3]>,
    fps: f64,
    d: usize,
    rng: SplitMix64,
    /// Ground position x, z and heading of the root after the last frame played.
    placement: [f64; 3],
    started: bool,
    /// Seed frames, normalised, oldest first.
    seed: Vec<f32>,
    /// Whether a plan is playing (false until the first step after a start).
    planned: bool,
    /// The plan's frames, normalised (`n D`).
    plan: Vec<f32>,
    /// Frames of the plan played.
    played: usize,
    /// Generator state after the plan, its last frame (the next input) and the yaw after it.
    end_state: MotionState,
    end_x: Vec<f32>,
    end_yaw: f64,
    /// Ground position x, z of the root after the plan (clip units).
    end_pos: [f64; 2],
    /// Candidates: generator states, current frames (`K D`), frames so far (`K n D`), prior
    /// costs, summed ground distances (clip units), yaws after their frames; scratch for one
    /// candidate's ground positions after each of its frames (`n`, see [`ControlRunner::ground_track`]).
    states: Vec<MotionState>,
    x: Vec<f32>,
    frames: Vec<f32>,
    prior: Vec<f64>,
    distance: Vec<f64>,
    yaw: Vec<f64>,
    ground: Vec<[f64; 2]>,
    /// Frames the candidates have rolled out.
    rolled: usize,
    last: Option<ControlSelection>,
    played_total: u64,
}

impl ControlledCharacter {
    /// A character of `model` seeded with `seed`, planning with `settings` (checked); give it
    /// seed frames with [`ControlledCharacter::start`] before stepping it.
    pub fn new(model: &SynthesisModel, seed: u64, settings: ControlSettings) -> Result<Self, MotionError> {
        settings.check()?;
        let (d, n, k) = (model.frame_dim(), settings.batch, settings.candidates());
        let offsets = (0..k)
            .map(|c| {
                let (s, t, l) = settings.offsets(c).expect("c < candidates");
                [s, t, l]
            })
            .collect();
        Ok(ControlledCharacter {
            offsets,
            fps: model.model().metadata().fps as f64,
            d,
            rng: SplitMix64::new(seed),
            placement: [0.0; 3],
            started: false,
            seed: Vec::new(),
            planned: false,
            plan: vec![0.0; n * d],
            played: 0,
            end_state: model.model().new_state(),
            end_x: vec![0.0; d],
            end_yaw: 0.0,
            end_pos: [0.0; 2],
            states: (0..k).map(|_| model.model().new_state()).collect(),
            x: vec![0.0; k * d],
            frames: vec![0.0; k * n * d],
            prior: vec![0.0; k],
            distance: vec![0.0; k],
            yaw: vec![0.0; k],
            ground: vec![[0.0; 2]; n],
            rolled: 0,
            last: None,
            played_total: 0,
            settings,
        })
    }

    /// Starts from one or more feature frames in clip units (`frames.len()` a positive
    /// multiple of `frame_dim`, oldest first, e.g. frames of a clip encoded by
    /// `zoo_rnngmm::FeatureSpec::encode`), fed in order to the generator from the zero state;
    /// the last one is the current frame, with the root at `(x, z)` facing `yaw` (radians about
    /// +Y). Drops any plan; the random numbers are not reset.
    pub fn start(
        &mut self,
        model: &SynthesisModel,
        frames: &[f32],
        x: f32,
        z: f32,
        yaw: f32,
    ) -> Result<(), MotionError> {
        let d = self.d;
        if model.frame_dim() != d {
            return Err(control_error(format!(
                "the model has {} values per frame, the character {d}; start a character of the same model",
                model.frame_dim()
            )));
        }
        check_len("seed frames", frames.len(), (frames.len() / d).max(1), d)?;
        check_finite("seed frames", frames, d)?;
        for (name, v) in [("x", x), ("z", z), ("yaw", yaw)] {
            if !v.is_finite() {
                return Err(MotionError::NonFinite { name: format!("start {name}"), index: 0, character: 0, value: v });
            }
        }
        self.seed.clear();
        self.seed.extend(frames.iter().enumerate().map(|(i, v)| (v - model.mean[i % d]) / model.std[i % d]));
        self.placement = [x as f64, z as f64, yaw as f64];
        self.started = true;
        self.planned = false;
        self.played = 0;
        self.rolled = 0;
        self.last = None;
        self.played_total = 0;
        Ok(())
    }

    /// The settings it plans with.
    pub fn settings(&self) -> &ControlSettings {
        &self.settings
    }

    /// Ground position x, z (clip units) and facing yaw (radians about +Y) of the root after
    /// the last frame played (the start placement before the first step).
    pub fn placement(&self) -> [f64; 3] {
        self.placement
    }

    /// The last selection (`None` before the first step after a start).
    pub fn last_selection(&self) -> Option<ControlSelection> {
        self.last
    }

    /// Frames played since the start.
    pub fn frames_played(&self) -> u64 {
        self.played_total
    }

    /// Frames per second the speeds are measured with (the model's `zoo.fps`).
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// The state of the character's random numbers (`SplitMix64::from_state` restores it).
    pub fn rng_state(&self) -> u64 {
        self.rng.state()
    }

    /// Starts the candidates from the plan's end: its state, its last frame, its yaw.
    fn restart_candidates(&mut self) {
        let d = self.d;
        for (c, state) in self.states.iter_mut().enumerate() {
            copy_state(state, &self.end_state);
            self.x[c * d..(c + 1) * d].copy_from_slice(&self.end_x);
        }
        self.prior.fill(0.0);
        self.distance.fill(0.0);
        self.yaw.fill(self.end_yaw);
        self.rolled = 0;
    }
}

fn copy_state(dst: &mut MotionState, src: &MotionState) {
    for (a, b) in dst.slots.iter_mut().zip(&src.slots) {
        a.copy_from_slice(b);
    }
}

/// `-ln sum_k w_k prod_j N(x_j; mu_kj, sd_kj)` (log-sum-exp over components, in f64).
fn mixture_nll(w: &[f32], mu: &[f32], sd: &[f32], x: &[f32]) -> f64 {
    let d = x.len();
    let (mut top, mut sum) = (f64::NEG_INFINITY, 0.0f64);
    for (k, wk) in w.iter().enumerate() {
        let mut l = (*wk as f64).ln();
        for j in 0..d {
            let s = sd[k * d + j] as f64;
            let z = (x[j] as f64 - mu[k * d + j] as f64) / s;
            l -= s.ln() + HALF_LN_TAU + 0.5 * z * z;
        }
        if l == f64::NEG_INFINITY {
            continue;
        }
        if l > top {
            sum = sum * (top - l).exp() + 1.0;
            top = l;
        } else {
            sum += (l - top).exp();
        }
    }
    -(top + sum.ln())
}

/// `a` wrapped to `[-pi, pi)`.
pub(crate) fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(TAU) - PI
}

/// Steps controlled characters on one thread; its scratch space is sized at the first step
/// (and grows once for a character with more candidates).
#[derive(Debug)]
pub struct ControlRunner {
    model: SynthesisModel,
    runner: MotionRunner,
    weights: Vec<f32>,
    means: Vec<f32>,
    stds: Vec<f32>,
    world: Vec<Quat>,
}

impl ControlRunner {
    /// A runner for characters of `model`.
    pub fn new(model: &SynthesisModel) -> Result<Self, MotionError> {
        let k = ControlSettings::default().candidates();
        let (d, m) = (model.frame_dim(), model.task.components);
        Ok(ControlRunner {
            model: model.clone(),
            runner: model.model().runner()?,
            weights: vec![0.0; k * m],
            means: vec![0.0; k * m * d],
            stds: vec![0.0; k * m * d],
            world: vec![Quat::IDENTITY; model.joints()],
        })
    }

    /// Plays the character's next frame into `pose` (decoded as [`crate::synthesis`] decodes
    /// a generator frame) and returns its contact bits `[left, right]`; rolls its candidates
    /// out by one frame, and selects the next batch under `control` when this frame ends the
    /// plan (see the module's doc). An invalid control or pose, or a character not started,
    /// is refused before anything changes.
    pub fn step(
        &mut self,
        character: &mut ControlledCharacter,
        control: Control,
        pose: &mut EnginePose,
    ) -> Result<[bool; 2], MotionError> {
        control.check()?;
        self.step_goal(character, Goal::Control(control), pose)
    }

    /// [`ControlRunner::step`] towards `goal`.
    pub(crate) fn step_goal(
        &mut self,
        character: &mut ControlledCharacter,
        mut goal: Goal<'_>,
        pose: &mut EnginePose,
    ) -> Result<[bool; 2], MotionError> {
        let ch = character;
        if !ch.started {
            return Err(control_error(
                "the character was not started: call ControlledCharacter::start with its seed frames first".into(),
            ));
        }
        let d = self.model.frame_dim();
        if ch.d != d {
            return Err(control_error(format!(
                "the character has {} values per frame, the runner's model {d}; step a character with a runner of its own model",
                ch.d
            )));
        }
        check_len("pose local_rotations", pose.local_rotations.len(), 1, self.model.joints())?;
        if !ch.planned {
            self.plan_first(ch, &mut goal)?;
        }
        self.roll(ch)?;
        let x = &ch.plan[ch.played * d..(ch.played + 1) * d];
        let contacts = decode_frame(&self.model, x, &mut ch.placement, &mut self.world, pose);
        ch.played += 1;
        ch.played_total += 1;
        if ch.played == ch.settings.batch {
            self.select(ch, &mut goal);
        }
        Ok(contacts)
    }

    /// Feeds the seed frames, rolls the first candidates out and selects the first plan.
    fn plan_first(&mut self, ch: &mut ControlledCharacter, goal: &mut Goal<'_>) -> Result<(), MotionError> {
        let d = ch.d;
        let seeds = ch.seed.len() / d;
        // Every row reads the seed frames (one batch size for the runner's session).
        ch.states.iter_mut().for_each(MotionState::reset);
        for f in 0..seeds - 1 {
            for row in ch.x.chunks_exact_mut(d) {
                row.copy_from_slice(&ch.seed[f * d..(f + 1) * d]);
            }
            self.run(ch)?;
        }
        copy_state(&mut ch.end_state, &ch.states[0]);
        ch.end_x.copy_from_slice(&ch.seed[(seeds - 1) * d..]);
        ch.end_yaw = ch.placement[2];
        ch.end_pos = [ch.placement[0], ch.placement[1]];
        ch.restart_candidates();
        for _ in 0..ch.settings.batch {
            self.roll(ch)?;
        }
        self.select(ch, goal);
        ch.planned = true;
        Ok(())
    }

    /// One run of the step graph for every candidate row: the mixtures of their next frames.
    fn run(&mut self, ch: &mut ControlledCharacter) -> Result<(), MotionError> {
        let (k, d, m) = (ch.states.len(), ch.d, self.model.task.components);
        if self.weights.len() < k * m {
            self.weights.resize(k * m, 0.0);
            self.means.resize(k * m * d, 0.0);
            self.stds.resize(k * m * d, 0.0);
        }
        self.runner.step_batch_invariant(
            &mut ch.states,
            &[&ch.x],
            &mut [&mut self.weights[..k * m], &mut self.means[..k * m * d], &mut self.stds[..k * m * d]],
        )
    }

    /// Rolls every candidate out by one frame: draws it, adds its offsets, charges its prior,
    /// and keeps it (the next input).
    fn roll(&mut self, ch: &mut ControlledCharacter) -> Result<(), MotionError> {
        self.run(ch)?;
        let (d, m, n) = (ch.d, self.model.task.components, ch.settings.batch);
        let (t, temperature) = (ch.rolled, ch.settings.temperature as f64);
        let (mean, std) = (&self.model.mean, &self.model.std);
        for (c, x) in ch.x.chunks_exact_mut(d).enumerate() {
            let w = &self.weights[c * m..(c + 1) * m];
            let (mu, sd) = (&self.means[c * m * d..(c + 1) * m * d], &self.stds[c * m * d..(c + 1) * m * d]);
            // A component by its weight, then mu + temperature * sigma * n (as synthesis draws).
            draw_frame(&mut ch.rng, w, mu, sd, temperature, x);
            let [so, to, lo] = ch.offsets[c];
            x[1] += so;
            x[2] += to;
            if lo != 0.0 {
                x[0] += lo;
            }
            ch.prior[c] += mixture_nll(w, mu, sd, x);
            let v = |i: usize| (x[i] * std[i] + mean[i]) as f64;
            ch.distance[c] += v(0).hypot(v(1));
            ch.yaw[c] += v(2);
            let at = (c * n + t) * d;
            ch.frames[at..at + d].copy_from_slice(x);
        }
        ch.rolled += 1;
        Ok(())
    }

    /// The ground position of candidate `c`'s root after each of its frames, into `ch.ground`:
    /// from the plan's end, each step turned by the yaw before its frame, as `decode_frame`
    /// places it (only a path goal and the plan's end need it; rolling out does not).
    fn ground_track(&self, ch: &mut ControlledCharacter, c: usize) {
        let (d, n) = (ch.d, ch.settings.batch);
        let (mean, std) = (&self.model.mean, &self.model.std);
        let (mut p, mut yaw) = (ch.end_pos, ch.end_yaw);
        for t in 0..n {
            let x = &ch.frames[(c * n + t) * d..];
            let v = |i: usize| (x[i] * std[i] + mean[i]) as f64;
            let (sin, cos) = yaw.sin_cos();
            p = [p[0] + v(0) * cos + v(1) * sin, p[1] - v(0) * sin + v(1) * cos];
            ch.ground[t] = p;
            yaw += v(2);
        }
    }

    /// Makes the candidate of least cost under `goal` the plan and restarts the candidates
    /// from its end.
    fn select(&mut self, ch: &mut ControlledCharacter, goal: &mut Goal<'_>) {
        let (d, n) = (ch.d, ch.settings.batch);
        let (sigma_speed, sigma_heading) = (ch.settings.sigma_speed as f64, ch.settings.sigma_heading as f64);
        let mut best: Option<ControlSelection> = None;
        for c in 0..ch.states.len() {
            let speed = ch.distance[c] / n as f64 * ch.fps;
            let (speed_cost, heading_cost, path_cost) = match goal {
                Goal::Control(control) => (
                    ((speed - control.speed as f64) / sigma_speed).powi(2),
                    (wrap(ch.yaw[c] - control.heading as f64) / sigma_heading).powi(2),
                    0.0,
                ),
                Goal::Path(path) => {
                    self.ground_track(ch, c);
                    path.costs(&ch.ground, ch.yaw[c], n as f64 / ch.fps)
                }
            };
            let [speed_offset, turn_offset, side_offset] = ch.offsets[c];
            let candidate = ControlSelection {
                candidate: c,
                speed_offset,
                turn_offset,
                side_offset,
                speed,
                heading: ch.yaw[c],
                prior: ch.prior[c],
                speed_cost,
                heading_cost,
                path_cost,
            };
            // NaN costs lose to everything; ties go to the first.
            let cost = candidate.cost();
            if best.is_none_or(|b| cost < b.cost() || (b.cost().is_nan() && !cost.is_nan())) {
                best = Some(candidate);
            }
        }
        let chosen = best.expect("at least 2 candidates");
        let c = chosen.candidate;
        ch.plan.copy_from_slice(&ch.frames[c * n * d..(c + 1) * n * d]);
        copy_state(&mut ch.end_state, &ch.states[c]);
        ch.end_x.copy_from_slice(&ch.plan[(n - 1) * d..]);
        self.ground_track(ch, c);
        ch.end_pos = ch.ground[n - 1];
        ch.end_yaw = ch.yaw[c];
        if let Goal::Path(path) = goal {
            path.advance(ch.end_pos);
        }
        ch.last = Some(chosen);
        ch.played = 0;
        ch.restart_candidates();
    }
}
