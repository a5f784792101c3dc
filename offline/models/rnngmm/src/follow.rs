//! Offline path following (sec. 5.2, eq. 14-19): the character's projected root follows a ground
//! path, the trained generator being the prior.
//!
//! Sliding windows of `window` frames (the paper's 34) overlapping by `overlap` (17): each window
//! continues from where the frames kept so far end; its unknowns (see [`crate::control`]) are
//! initialised by particle swarm optimisation (`argmin`'s `ParticleSwarm`, the particles being the
//! root draws `e` of the window's frames, every particle's motion unrolled in one batch), then
//! refined by L-BFGS (`argmin`, More-Thuente line search) over all draws and the input noise,
//! with gradients by backpropagation through the unrolled generator. During L-BFGS each frame's
//! mixture component and contact bits stay those of its starting point: re-chosen at every
//! evaluation they flip under tiny steps and the energy jumps by hundreds of nats, which stalls
//! the line search (measured). The noise is optimised in units of its prior's standard
//! deviation (the network reads `s + sigma_noise d`, prior `|d|^2 / 2`), which puts its gradient
//! on the scale of the draws' (in network units it was 20 times larger and the first line search
//! step blew the energy up to 3e8). The first `window - overlap` frames are kept and the next
//! window starts after them.
//!
//! Energy of a window: the prior (eq. 15-16), the curve term (eq. 17): each frame's projected
//! root against its nearest path point, `|root - c_near|^2 / sigma_fit^2` (the nearest point is
//! searched along the path from a metre behind the window's start to six metres ahead of it, so
//! a path that comes back near itself is not cut short, and past the path's end along its last
//! direction, so the character walks through the end instead of being pulled back to it), and
//! the contact term (eq. 18). The paper's `sigma_fit^2` = 0.5 is in its own (unstated) units;
//! here `sigma_fit` is in clip units (cm for bandai2), 5 by default.
//!
//! The motion starts at the path's start, turned so that the seed clip's direction of travel
//! follows the path's first direction, and ends at the first frame whose root reaches the path's
//! end (or after `max_frames`).

use crate::checkpoint::LoadedGenerator;
use crate::control::{
    ControlStart, contact_bits, contact_energy, ground_heights, minimise, rollout, split, world_root,
};
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{DecodedMotion, RootPlacement};
use crate::fk::TensorFk;
use crate::path::GroundPath;
use argmin::core::{CostFunction, Executor, State};
use argmin::solver::particleswarm::ParticleSwarm;
use candle_core::{DType, Device, Tensor};
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// Settings of [`follow`].
#[derive(Clone, Debug, PartialEq)]
pub struct FollowOptions {
    /// Standard deviation of the curve term (eq. 17), clip units.
    pub sigma_fit: f64,
    /// Standard deviation of the network noise prior (eq. 16), normalised units.
    pub sigma_noise: f64,
    /// Standard deviation of a planted foot joint's displacement per frame (eq. 18), clip units.
    pub sigma_contact: f64,
    /// Standard deviation of a planted foot joint's height above its ground (eq. 18), clip units.
    pub sigma_plane: f64,
    /// Frames per window (the paper's 34).
    pub window: usize,
    /// Frames shared by consecutive windows (the paper's 17).
    pub overlap: usize,
    /// Particles of the swarm.
    pub particles: usize,
    /// Swarm iterations after the first evaluation.
    pub swarm_iterations: u64,
    /// Bound on the particles' root draws (standard deviations).
    pub swarm_bound: f64,
    /// L-BFGS iterations per window at most.
    pub iterations: u64,
    /// Seed of the swarm.
    pub seed: u64,
    /// Seed frames of the start clip (at least 2).
    pub seed_frames: usize,
    /// Adam steps of the initial state estimation (eq. 26).
    pub init_steps: usize,
    /// Frames generated at most (`None`: the path's length at 20 cm/s).
    pub max_frames: Option<usize>,
}

impl Default for FollowOptions {
    /// Windows of 34 overlapping by 17 (the paper's), `sigma_fit` 5 cm, the denoiser's contact
    /// levels, 16 particles for 6 iterations within 1.5 standard deviations, 20 L-BFGS iterations.
    fn default() -> Self {
        FollowOptions {
            sigma_fit: 5.0,
            sigma_noise: 0.05,
            sigma_contact: 1.0,
            sigma_plane: 2.0,
            window: 34,
            overlap: 17,
            particles: 16,
            swarm_iterations: 6,
            swarm_bound: 1.5,
            iterations: 20,
            seed: 1,
            seed_frames: 2,
            init_steps: 50,
            max_frames: None,
        }
    }
}

impl FollowOptions {
    fn validate(&self) -> RnnGmmResult<()> {
        for (name, v) in [
            ("sigma_fit", self.sigma_fit),
            ("sigma_noise", self.sigma_noise),
            ("sigma_contact", self.sigma_contact),
            ("sigma_plane", self.sigma_plane),
            ("the swarm bound", self.swarm_bound),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RnnGmmError::Config(format!("{name} must be positive and finite, found {v}")));
            }
        }
        if self.window < 2 || self.overlap >= self.window {
            return Err(RnnGmmError::Config(format!(
                "windows need at least 2 frames and an overlap below the window: window {}, overlap {}",
                self.window, self.overlap
            )));
        }
        if self.particles < 2 {
            return Err(RnnGmmError::Config(format!("the swarm needs at least 2 particles, found {}", self.particles)));
        }
        Ok(())
    }
}

/// A motion that follows a path.
#[derive(Clone, Debug)]
pub struct Followed {
    /// The generated frames (placed on the path) and their contact bits.
    pub motion: DecodedMotion,
    /// Per frame: the root's distance to the path (clip units) and the arc length of its
    /// nearest point.
    pub distance: Vec<f64>,
    /// See `distance`.
    pub progress: Vec<f64>,
    /// Whether the root reached the path's end (otherwise `max_frames` stopped it).
    pub reached_end: bool,
    /// Windows optimised.
    pub windows: usize,
}

/// The energy of one window over the unknowns, for the swarm (root draws only, batched) and
/// for L-BFGS (all draws and the noise).
struct Window<'a> {
    model: &'a LoadedGenerator,
    fk: &'a TensorFk,
    start: &'a ControlStart,
    path: &'a GroundPath,
    opts: &'a FollowOptions,
    left: usize,
    ground: &'a Tensor,
    /// Arc-length range searched for nearest points.
    s_range: (f64, f64),
}

impl Window<'_> {
    fn frames(&self) -> usize {
        self.opts.window
    }

    fn dim(&self) -> usize {
        self.model.spec.dim()
    }

    fn device(&self) -> &Device {
        self.model.generator.device()
    }

    /// Energy per row `(B)` of draws and noise `(B, T, D)`, with `fixed` components and
    /// contact bits when given (else each frame's most probable component and its own bits).
    fn energy(&self, eps: &Tensor, d: &Tensor, fixed: Option<&(Tensor, Tensor)>) -> RnnGmmResult<Tensor> {
        let o = self.opts;
        let components = fixed.map(|f| &f.0);
        // `d` is the noise in standard deviations of its prior: the network reads `s + sigma_noise d`.
        let r = rollout(self.model, self.start, eps, &(d * o.sigma_noise)?, components)?;
        let prior = (r.nll.sum(1)? + (d.sqr()?.sum(2)?.sum(1)? / 2.0)?)?;
        let root = world_root(self.fk, &r.states, &self.start.placement)?; // (B, T, 2)
        let (b, t, _) = root.dims3()?;
        let values = root.detach().flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
        let targets: Vec<f32> = values
            .chunks_exact(2)
            .flat_map(|p| {
                let n = self.path.nearest([p[0], p[1]], self.s_range.0, self.s_range.1);
                [n.point[0] as f32, n.point[1] as f32]
            })
            .collect();
        let targets = Tensor::from_vec(targets, (b, t, 2), self.device())?;
        let curve = ((root - targets)?.sqr()?.sum(2)?.sum(1)? / (o.sigma_fit * o.sigma_fit))?;
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
        Ok(((prior + curve)? + contact)?)
    }

    /// Draws with the swarm's root values `(3 T)` per particle, zero elsewhere: `(B, T, D)`.
    fn swarm_draws(&self, particles: &[&Vec<f64>]) -> RnnGmmResult<Tensor> {
        let (t, dim) = (self.frames(), self.dim());
        let mut e = vec![0f32; particles.len() * t * dim];
        for (b, p) in particles.iter().enumerate() {
            for f in 0..t {
                for k in 0..3 {
                    e[(b * t + f) * dim + k] = p[f * 3 + k] as f32;
                }
            }
        }
        Ok(Tensor::from_vec(e, (particles.len(), t, dim), self.device())?)
    }
}

/// The swarm's view of a window: root draws only, evaluated in one batch.
struct Swarm<'a, 'b>(&'b Window<'a>);

impl CostFunction for Swarm<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.bulk_cost(&[p])?[0])
    }
    fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, argmin::core::Error>
    where
        P: std::borrow::Borrow<Vec<f64>> + argmin::core::SyncAlias,
    {
        let w = self.0;
        let ps: Vec<&Vec<f64>> = params.iter().map(|p| p.borrow()).collect();
        let e = w.swarm_draws(&ps)?;
        let d = e.zeros_like()?;
        let energy = w.energy(&e, &d, None)?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
        // A non-finite energy ranks last.
        Ok(energy.into_iter().map(|v| if v.is_finite() { v } else { f64::MAX }).collect())
    }
}

/// The project's one generator ([`SplitMix64`]) behind the `rand::Rng` that argmin's particle
/// swarm takes: its API is generic over rand's trait (the one reason the crate keeps `rand`), and
/// every draw of the swarm comes from SplitMix64.
struct SwarmRng(SplitMix64);

impl rand::RngCore for SwarmRng {
    fn next_u32(&mut self) -> u32 {
        (self.0.next_u64() >> 32) as u32
    }

    fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for chunk in dst.chunks_mut(8) {
            chunk.copy_from_slice(&self.0.next_u64().to_le_bytes()[..chunk.len()]);
        }
    }
}

fn opt_err(what: &str, e: argmin::core::Error) -> RnnGmmError {
    RnnGmmError::Config(format!("path following: {what} failed: {e}"))
}

/// Generates motion that follows `path` (clip units, on the ground plane), continuing the seed
/// frames of `clip` ending at `frame` (their gait: walking seeds walk, running seeds run).
/// `progress` is called after each window with the arc length reached. Deterministic for a
/// seed (and a thread count).
pub fn follow(
    model: &LoadedGenerator,
    clip: &Clip,
    frame: usize,
    path: &GroundPath,
    opts: &FollowOptions,
    progress: &mut dyn FnMut(f64),
) -> RnnGmmResult<Followed> {
    opts.validate()?;
    let (spec, norm) = (&model.spec, &model.norm);
    let dim = spec.dim();
    let dev = Device::Cpu;
    // Place the character at the path's start, its direction of travel along the path.
    let enc = spec.encode(clip)?;
    if frame >= clip.frames() || frame + 1 < opts.seed_frames {
        return Err(RnnGmmError::Config(format!(
            "the start frame {frame} needs {} seed frames within the {}-frame start clip",
            opts.seed_frames,
            clip.frames()
        )));
    }
    let seed = &enc.values[(frame + 1 - opts.seed_frames) * dim..(frame + 1) * dim];
    let (travel, _) = ControlStart::travel_direction(seed, dim);
    let t0 = path.tangent_at(0.0);
    let p0 = path.point_at(0.0);
    let placement = RootPlacement { x: p0[0], z: p0[1], yaw: t0[0].atan2(t0[1]) - travel };
    let mut start = ControlStart::from_clip(model, clip, frame, opts.seed_frames, opts.init_steps, placement)?;
    let feet: Vec<usize> = spec.left_foot.iter().chain(&spec.right_foot).copied().collect();
    let fk = TensorFk::new(spec, norm, &feet, &dev)?;
    let ground = ground_heights(model, clip, &feet, &dev)?;
    let fps = spec.fps;
    let max_frames = opts.max_frames.unwrap_or_else(|| ((path.length() / 20.0) * fps).ceil() as usize + opts.window);
    let (t, keep) = (opts.window, opts.window - opts.overlap);
    let mut rng = SplitMix64::new(opts.seed);
    let (mut kept, mut distance, mut progress_s) = (Vec::<f32>::new(), Vec::new(), Vec::new());
    let (mut s_now, mut reached_end, mut windows) = (0.0f64, false, 0usize);
    while kept.len() / dim < max_frames && !reached_end {
        let s_range = (s_now - 100.0, s_now + 600.0);
        let window =
            Window { model, fk: &fk, start: &start, path, opts, left: spec.left_foot.len(), ground: &ground, s_range };
        // Particle swarm over the root draws.
        let n = 3 * t;
        let bounds = (vec![-opts.swarm_bound; n], vec![opts.swarm_bound; n]);
        let swarm =
            ParticleSwarm::new(bounds, opts.particles).with_rng_generator(SwarmRng(SplitMix64::new(rng.next_u64())));
        let res = Executor::new(Swarm(&window), swarm)
            .configure(|s| s.max_iters(opts.swarm_iterations))
            .run()
            .map_err(|e| opt_err("the particle swarm", e))?;
        let best_root: Vec<f64> = res.state().get_best_param().map(|p| p.position.clone()).unwrap_or(vec![0.0; n]);
        // The mode rollout (all draws 0) competes with the swarm's best.
        let zero = vec![0.0; n];
        let costs = Swarm(&window).bulk_cost(&[&best_root, &zero]).map_err(|e| opt_err("the start", e))?;
        let root = if costs[1] < costs[0] { zero } else { best_root };
        let mut init = vec![0.0; 2 * t * dim];
        for f in 0..t {
            for k in 0..3 {
                init[f * dim + k] = root[f * 3 + k];
            }
        }
        // L-BFGS over every draw and the noise, the components fixed at the start's.
        let (e0, d0) = split(&init, t, dim, &dev)?;
        let r0 = rollout(model, &start, &e0, &(d0 * opts.sigma_noise)?, None)?;
        let fixed = (r0.components, contact_bits(&fk, &r0.states)?);
        let components = fixed.0.clone();
        let energy = |e: &Tensor, d: &Tensor| window.energy(e, d, Some(&fixed));
        let (best, _) = minimise(&energy, init, t, dim, &dev, opts.iterations, "path following")?;
        let (e, d) = split(&best, t, dim, &dev)?;
        let r = rollout(model, &start, &e, &(d * opts.sigma_noise)?, Some(&components))?;
        let root =
            world_root(&fk, &r.states, &start.placement)?.flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
        // Keep the first frames (up to the end when the path ends inside this window).
        let near: Vec<_> = (0..t).map(|f| path.nearest([root[2 * f], root[2 * f + 1]], s_range.0, s_range.1)).collect();
        let mut n_keep = match near.iter().position(|n| n.s >= path.length()) {
            Some(f) => {
                reached_end = true;
                f + 1
            }
            None => keep,
        };
        n_keep = n_keep.min(max_frames - kept.len() / dim);
        for n in &near[..n_keep] {
            distance.push(n.distance);
            progress_s.push(n.s);
            s_now = s_now.max(n.s);
        }
        windows += 1;
        let frames = r.states.narrow(1, 0, n_keep)?;
        let inputs = r.inputs.narrow(1, 0, n_keep)?;
        let mut raw = frames.flatten_all()?.to_vec1::<f32>()?;
        norm.denormalize(&mut raw);
        start = start.advance(model, &inputs, &frames, &raw)?;
        kept.extend(raw);
        progress(s_now);
    }
    let motion = spec.decode(&kept, placement)?;
    Ok(Followed { motion, distance, progress: progress_s, reached_end, windows })
}
