//! Online speed and direction control (sec. 5.3, eq. 20-23): the character follows a target
//! speed and facing that change over time, optimised batch by batch with the trained generator
//! as the prior.
//!
//! **A batch.** The motion is made `batch` frames (the paper's `n`) at a time, each batch
//! continuing from the frames before it. Its energy is eq. 20: the prior (eq. 15-16, the exact
//! mixture NLL of each state and the network noise prior, as in path following, see
//! [`crate::control`]), the speed term (eq. 22: the batch's mean root speed against the control
//! speed, over `sigma_speed^2`), the direction term (eq. 23: the facing yaw of the batch's last
//! frame against the control heading, wrapped to [-pi, pi], over `sigma_heading^2`; the paper
//! leaves its scale at 1 radian, which lets the prior win a 180-degree turn) and the contact
//! term (eq. 18).
//!
//! **Optimisation.** The batch starts from the best of a grid of proposals: each proposal draws
//! its frames from the mixture (normal draws `e` scaled by `temperature`, each frame's most
//! probable component) and adds a constant offset to the forward root step (`dtz`, dim 1) and
//! the turn (`dry`, dim 2), in normalised units, one offset pair per proposal (`speed_offsets`
//! x `turn_offsets`); all proposals unroll in one batch. The best then takes `steps` gradient
//! steps over all its draws and the network noise (gradients by backpropagation through the
//! unrolled generator; components and contact bits fixed, offsets kept, as in path following):
//! each step tries the step sizes 1, 1/3, 1/9 and 1/27 along the negative gradient, unrolled in
//! one batch, and keeps the lowest energy if it is below the current one. A fixed number of
//! evaluations per batch, unlike L-BFGS with its line search (which the path follower uses):
//! a real-time controller must finish each batch in time, and a wall-clock limit would make
//! runs depend on the machine. The runtime's controller (`zoo_runtime::control`, no
//! gradients) is this without the gradient steps (and without the contact term).
//!
//! **Latency.** Real time: a batch must be computed before it plays, so it is optimised while
//! the batch before it plays, with the controls in force when that one started. A control
//! change therefore reaches the motion `batch` to `2 batch` frames later (3 to 6 frames, 0.1
//! to 0.2 s at 30 fps, by default). This module simulates exactly that: batch `j` (frames
//! `j n ..`) reads the controls at frame `(j - 1) n` (the first batch those at frame 0).
//!
//! **Compute.** Per batch: the proposals' rollout (`K` rows), per step one backward pass (1 row)
//! and the step sizes' rollout (4 rows), and the step that keeps the batch (1 row).

use crate::checkpoint::LoadedGenerator;
use crate::control::{ControlStart, contact_bits, contact_energy, ground_heights, rollout_shifted};
use crate::controls::{ControlKey, ControlScript};
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{DecodedMotion, RootPlacement};
use crate::fk::TensorFk;
use candle_core::{DType, Device, IndexOp, Tensor, Var};
use std::time::Instant;
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// Step sizes tried along the gradient, all in one batched rollout.
const STEP_SIZES: [f64; 4] = [1.0, 1.0 / 3.0, 1.0 / 9.0, 1.0 / 27.0];

/// How many copies of a proposal row's per-frame values the energy holds at once (inputs,
/// layer outputs, the mixture's terms, the decoded features and their sums): measured with
/// `zoo control` on the tiny preset (1,600 and 6,400 proposals of 3 frames: 91 and 260 MB peak,
/// 35.4 KB a proposal, 2.06 copies of its 1,435 values a frame), rounded up.
const UNROLL_COPIES: u64 = 3;

/// Settings of [`control`].
#[derive(Clone, Debug, PartialEq)]
pub struct OnlineOptions {
    /// Frames per batch (the paper's `n`).
    pub batch: usize,
    /// Offsets of the proposals' forward root step (dim 1), normalised units.
    pub speed_offsets: Vec<f64>,
    /// Offsets of the proposals' turn (dim 2), normalised units.
    pub turn_offsets: Vec<f64>,
    /// Standard deviation of the speed term (eq. 22), clip units per second.
    pub sigma_speed: f64,
    /// Standard deviation of the direction term (eq. 23), radians.
    pub sigma_heading: f64,
    /// Standard deviation of the network noise prior (eq. 16), normalised units.
    pub sigma_noise: f64,
    /// Standard deviation of a planted foot joint's displacement per frame (eq. 18), clip units.
    pub sigma_contact: f64,
    /// Standard deviation of a planted foot joint's height above its ground (eq. 18), clip units.
    pub sigma_plane: f64,
    /// Scale of the proposals' draws (1: the model's spread, 0: each component's mean).
    pub temperature: f64,
    /// Gradient steps per batch at most (0: the best proposal as it is).
    pub steps: usize,
    /// Seed of the proposals' draws.
    pub seed: u64,
    /// Seed frames of the start clip (at least 2).
    pub seed_frames: usize,
    /// Adam steps of the initial state estimation (eq. 26).
    pub init_steps: usize,
}

impl Default for OnlineOptions {
    /// Batches of 3 frames, 25 proposals (forward and turn offsets -3, -1.5, 0, 1.5, 3 each),
    /// `sigma_speed` 2 cm/s, `sigma_heading` 0.02 rad, draws at temperature 0.3, the denoiser's
    /// noise and contact levels, 1 gradient step (tuned on bandai2: docs/rnn-gmm-control.md).
    fn default() -> Self {
        OnlineOptions {
            batch: 3,
            speed_offsets: vec![-3.0, -1.5, 0.0, 1.5, 3.0],
            turn_offsets: vec![-3.0, -1.5, 0.0, 1.5, 3.0],
            sigma_speed: 2.0,
            sigma_heading: 0.02,
            sigma_noise: 0.05,
            sigma_contact: 1.0,
            sigma_plane: 2.0,
            temperature: 0.3,
            steps: 1,
            seed: 1,
            seed_frames: 2,
            init_steps: 50,
        }
    }
}

impl OnlineOptions {
    fn validate(&self) -> RnnGmmResult<()> {
        for (name, v) in [
            ("sigma_speed", self.sigma_speed),
            ("sigma_heading", self.sigma_heading),
            ("sigma_noise", self.sigma_noise),
            ("sigma_contact", self.sigma_contact),
            ("sigma_plane", self.sigma_plane),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RnnGmmError::Config(format!("{name} must be positive and finite, found {v}")));
            }
        }
        if !(self.temperature.is_finite() && self.temperature >= 0.0) {
            return Err(RnnGmmError::Config(format!(
                "the proposals' temperature must be finite and not negative, found {}",
                self.temperature
            )));
        }
        if self.batch == 0 {
            return Err(RnnGmmError::Config("online control needs batches of at least 1 frame".into()));
        }
        if self.speed_offsets.is_empty() || self.turn_offsets.is_empty() {
            return Err(RnnGmmError::Config(
                "online control needs at least one speed offset and one turn offset (0 is the plain draw)".into(),
            ));
        }
        if let Some(v) = self.speed_offsets.iter().chain(&self.turn_offsets).find(|v| !v.is_finite()) {
            return Err(RnnGmmError::Config(format!("proposal offsets must be finite, found {v}")));
        }
        Ok(())
    }

    /// Bytes the proposals of one batch hold while they are unrolled together (`K` rows of
    /// `batch` frames through a generator of `config`'s sizes): per row and frame its layers'
    /// activations, the LSTM's gates and states, the mixture's parameters and the state-sized
    /// draws, offsets and decoded features, f32 each, times [`UNROLL_COPIES`] for the
    /// intermediate tensors of the energy.
    pub fn proposal_bytes(&self, config: &crate::Config) -> u64 {
        let dim = config.dim as u64;
        let per_frame = config.fc.iter().map(|&w| w as u64).sum::<u64>()
            + 6 * (config.lstm * config.lstm_layers) as u64
            + config.components as u64 * (2 * dim + 1)
            + 8 * dim;
        (self.speed_offsets.len() as u64)
            .saturating_mul(self.turn_offsets.len() as u64)
            .saturating_mul(self.batch as u64)
            .saturating_mul(per_frame)
            .saturating_mul(4 * UNROLL_COPIES)
    }

    /// Refuses proposals whose unrolled batch ([`Self::proposal_bytes`]) would pass the memory
    /// bound (`zoo_data::limits::memory_bound`), before anything is allocated: their number is
    /// the product of the two offset lists, so it grows with the square of their lengths.
    pub fn check_memory(&self, config: &crate::Config) -> RnnGmmResult<()> {
        let need = self.proposal_bytes(config);
        let bound = zoo_data::limits::memory_bound();
        if need > bound {
            return Err(RnnGmmError::Message(zoo_data::Message(format!(
                "{} proposals ({} speed offsets x {} turn offsets) of {} frames each need {:.2} GB, past the memory \
                 bound of {:.2} GB: give fewer --speed-offsets or --turn-offsets (the default is 5 of each), or raise \
                 the bound with the environment variable ZOO_MEMORY_GB=N",
                self.speed_offsets.len() * self.turn_offsets.len(),
                self.speed_offsets.len(),
                self.turn_offsets.len(),
                self.batch,
                need as f64 / 1e9,
                bound as f64 / 1e9
            ))));
        }
        Ok(())
    }

    /// The proposals' (forward, turn) offsets.
    pub fn proposals(&self) -> Vec<(f64, f64)> {
        self.speed_offsets.iter().flat_map(|&s| self.turn_offsets.iter().map(move |&t| (s, t))).collect()
    }
}

/// A controlled motion.
#[derive(Clone, Debug)]
pub struct Controlled {
    /// The generated frames and their contact bits (placed from the origin).
    pub motion: DecodedMotion,
    /// Per frame: the root's ground speed (clip units per second) and facing yaw (radians).
    pub speed: Vec<f64>,
    /// See `speed`.
    pub yaw: Vec<f64>,
    /// Per batch: compute seconds (proposals, L-BFGS and the step that keeps it).
    pub batch_seconds: Vec<f64>,
    /// Per batch: the chosen proposal's (forward, turn) offsets.
    pub chosen: Vec<(f64, f64)>,
}

impl Controlled {
    /// Compute seconds per generated frame (all batches).
    pub fn seconds_per_frame(&self) -> f64 {
        self.batch_seconds.iter().sum::<f64>() / self.speed.len().max(1) as f64
    }
}

/// One batch's energy (eq. 20).
struct Batch<'a> {
    model: &'a LoadedGenerator,
    fk: &'a TensorFk,
    start: &'a ControlStart,
    opts: &'a OnlineOptions,
    control: ControlKey,
    left: usize,
    ground: &'a Tensor,
    fps: f64,
}

impl Batch<'_> {
    /// Energy per row `(B)` of draws and noise `(B, T, D)` (noise in prior standard
    /// deviations), proposal offsets `shift` `(B, T, D)`, and `fixed` components and contact
    /// bits when given.
    fn energy(
        &self,
        eps: &Tensor,
        d: &Tensor,
        shift: &Tensor,
        fixed: Option<&(Tensor, Tensor)>,
    ) -> RnnGmmResult<(Tensor, crate::control::Rollout)> {
        let o = self.opts;
        let r = rollout_shifted(self.model, self.start, eps, &(d * o.sigma_noise)?, fixed.map(|f| &f.0), Some(shift))?;
        let prior = (r.nll.sum(1)? + (d.sqr()?.sum(2)?.sum(1)? / 2.0)?)?;
        let raw = self.fk.denormalize(&r.states)?; // (B, T, D), clip units
        let step = raw.narrow(2, 0, 2)?;
        let speed = ((step.sqr()?.sum(2)? + 1e-6)?.sqrt()? * self.fps)?.mean(1)?; // (B)
        let speed_term = ((speed - self.control.speed)? / o.sigma_speed)?.sqr()?;
        let yaw = (raw.narrow(2, 2, 1)?.squeeze(2)?.sum(1)? + self.start.placement.yaw)?; // (B)
        // Wrapped to [-pi, pi] by a constant multiple of 2 pi (not differentiated).
        let tau = std::f64::consts::TAU;
        let diff = (yaw - self.control.heading)?;
        let wraps: Vec<f32> =
            diff.to_dtype(DType::F64)?.to_vec1::<f64>()?.iter().map(|v| (tau * (v / tau).round()) as f32).collect();
        let wraps = Tensor::from_vec(wraps, diff.dims1()?, diff.device())?;
        let heading_term = ((diff - wraps)? / o.sigma_heading)?.sqr()?;
        let contact = contact_energy(
            self.fk,
            &self.start.last,
            &r.states,
            fixed.map(|f| &f.1),
            self.left,
            self.ground,
            o.sigma_contact,
            o.sigma_plane,
        )?;
        let total = (((prior + speed_term)? + heading_term)? + contact)?.contiguous()?;
        Ok((total, r))
    }
}

/// Generates motion under `script` (speed and heading over time) for its duration,
/// continuing the seed frames of `clip` ending at `frame`, placed at the origin facing the
/// script's first heading. `progress` is called after each batch with the frames made.
/// Deterministic for a seed (and a thread count).
pub fn control(
    model: &LoadedGenerator,
    clip: &Clip,
    frame: usize,
    script: &ControlScript,
    opts: &OnlineOptions,
    progress: &mut dyn FnMut(usize),
) -> RnnGmmResult<Controlled> {
    opts.validate()?;
    opts.check_memory(model.generator.config())?;
    let (spec, norm) = (&model.spec, &model.norm);
    let (dim, fps, n) = (spec.dim(), spec.fps, opts.batch);
    let dev = Device::Cpu;
    let placement = RootPlacement { x: 0.0, z: 0.0, yaw: script.keys()[0].heading };
    let mut start = ControlStart::from_clip(model, clip, frame, opts.seed_frames, opts.init_steps, placement)?;
    let feet: Vec<usize> = spec.left_foot.iter().chain(&spec.right_foot).copied().collect();
    let fk = TensorFk::new(spec, norm, &feet, &dev)?;
    let ground = ground_heights(model, clip, &feet, &dev)?;
    let total = (script.duration() * fps).round() as usize;
    let proposals = opts.proposals();
    let k = proposals.len();
    let mut shift = vec![0f32; k * n * dim];
    for (c, &(s, t)) in proposals.iter().enumerate() {
        for f in 0..n {
            shift[(c * n + f) * dim + 1] = s as f32;
            shift[(c * n + f) * dim + 2] = t as f32;
        }
    }
    let shift = Tensor::from_vec(shift, (k, n, dim), &dev)?;
    let mut rng = SplitMix64::new(opts.seed);
    let (mut kept, mut speed, mut yaw) = (Vec::<f32>::new(), Vec::new(), Vec::new());
    let (mut batch_seconds, mut chosen) = (Vec::new(), Vec::new());
    let mut facing = placement.yaw;
    while speed.len() < total {
        let clock = Instant::now();
        let f0 = speed.len();
        let control = script.at(f0.saturating_sub(n) as f64 / fps);
        let batch =
            Batch { model, fk: &fk, start: &start, opts, control, left: spec.left_foot.len(), ground: &ground, fps };
        // The proposals, unrolled in one batch.
        let draws: Vec<f32> = (0..k * n * dim).map(|_| (opts.temperature * rng.normal()) as f32).collect();
        let eps = Tensor::from_vec(draws, (k, n, dim), &dev)?;
        let (energy, r) = batch.energy(&eps, &eps.zeros_like()?, &shift, None)?;
        let energy = energy.to_dtype(DType::F64)?.to_vec1::<f64>()?;
        let best = (0..k)
            .filter(|&i| energy[i].is_finite())
            .min_by(|&a, &b| energy[a].total_cmp(&energy[b]))
            .ok_or_else(|| RnnGmmError::Config("online control: every proposal's energy is not finite".into()))?;
        chosen.push(proposals[best]);
        let shift_best = shift.i(best..best + 1)?;
        let states_best = r.states.i(best..best + 1)?;
        let fixed = (r.components.i(best..best + 1)?, contact_bits(&fk, &states_best)?);
        let (mut e, mut d) = (eps.i(best..best + 1)?, eps.i(best..best + 1)?.zeros_like()?);
        let (mut states, mut inputs) = (states_best, r.inputs.i(best..best + 1)?);
        let mut current = energy[best];
        for _ in 0..opts.steps {
            // The gradient at the current point (one backward pass) ...
            let (ev, dv) = (Var::from_tensor(&e)?, Var::from_tensor(&d)?);
            let (en, _) = batch.energy(ev.as_tensor(), dv.as_tensor(), &shift_best, Some(&fixed))?;
            let grads = en.sum_all()?.backward()?;
            let (Some(ge), Some(gd)) = (grads.get(&ev), grads.get(&dv)) else { break };
            // ... and the steps along it, unrolled in one batch: the lowest wins if it is lower.
            let (te, td): (Vec<Tensor>, Vec<Tensor>) = STEP_SIZES
                .iter()
                .map(|a| Ok(((&e - (ge * *a)?)?, (&d - (gd * *a)?)?)))
                .collect::<RnnGmmResult<Vec<_>>>()?
                .into_iter()
                .unzip();
            let j = STEP_SIZES.len();
            let (te, td) = (Tensor::cat(&te, 0)?, Tensor::cat(&td, 0)?);
            let trial_fixed = (fixed.0.repeat((j, 1))?, fixed.1.repeat((j, 1, 1))?);
            let (values, r) = batch.energy(&te, &td, &shift_best.repeat((j, 1, 1))?, Some(&trial_fixed))?;
            let values = values.to_dtype(DType::F64)?.to_vec1::<f64>()?;
            let Some(i) = (0..j).filter(|&i| values[i].is_finite()).min_by(|&a, &b| values[a].total_cmp(&values[b]))
            else {
                break;
            };
            if values[i] >= current {
                break;
            }
            current = values[i];
            (e, d) = (te.i(i..i + 1)?, td.i(i..i + 1)?);
            (states, inputs) = (r.states.i(i..i + 1)?, r.inputs.i(i..i + 1)?);
        }
        let keep = n.min(total - f0);
        let (frames, inputs) = (states.narrow(1, 0, keep)?, inputs.narrow(1, 0, keep)?);
        let mut raw = frames.flatten_all()?.to_vec1::<f32>()?;
        norm.denormalize(&mut raw);
        start = start.advance(model, &inputs, &frames, &raw)?;
        batch_seconds.push(clock.elapsed().as_secs_f64());
        for x in raw.chunks_exact(dim) {
            speed.push((x[0] as f64).hypot(x[1] as f64) * fps);
            facing += x[2] as f64;
            yaw.push(facing);
        }
        kept.extend(raw);
        progress(speed.len());
    }
    let motion = spec.decode(&kept, placement)?;
    Ok(Controlled { motion, speed, yaw, batch_seconds, chosen })
}
