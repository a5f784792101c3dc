//! Random motion synthesis (sec. 4.1.4, 4.2.3, 5.1): seed the generator with frames of a clip,
//! estimate its initial state (eq. 26), sample frames from the mixture, refine them (optional),
//! and decode them into a clip that continues the seed clip where it stands.

use crate::checkpoint::LoadedGenerator;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{DecodedMotion, RootPlacement};
use crate::initial_state::estimate_initial_state;
use crate::refiner::RefinerNets;
use candle_core::Tensor;
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// How to synthesise.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthesisOptions {
    /// Frames to generate after the seed.
    pub frames: usize,
    /// Seed of the sampling.
    pub seed: u64,
    /// Scale on the mixture's standard deviations (1: the model's own spread).
    pub temperature: f64,
    /// Frames of the clip fed to the generator, ending at the chosen frame (at least 2: eq. 26
    /// needs `x_1` and `x_2`).
    pub seed_frames: usize,
    /// Adam steps of the initial state estimation (0: zero state, as the paper's baseline).
    pub init_steps: usize,
    /// Their learning rate.
    pub init_lr: f64,
}

impl Default for SynthesisOptions {
    /// 60 s at 30 fps, seed 1, temperature 1, 2 seed frames, 50 steps of 0.05.
    fn default() -> Self {
        SynthesisOptions { frames: 1800, seed: 1, temperature: 1.0, seed_frames: 2, init_steps: 50, init_lr: 0.05 }
    }
}

/// A synthesised motion.
#[derive(Clone, Debug)]
pub struct Synthesis {
    /// The generated frames as a clip (placed where the seed clip stands at the chosen frame)
    /// and their contact bits.
    pub motion: DecodedMotion,
    /// The generated features, in clip units (`frames * D`).
    pub features: Vec<f32>,
    /// NLL of the seed frames from the zero state and from the estimated state (eq. 26).
    pub seed_nll: (f64, f64),
}

/// Generates `opts.frames` frames continuing `clip` from frame `frame` (the last seed frame),
/// refined by `refiner` when given. Deterministic for `opts.seed`.
pub fn synthesize(
    model: &LoadedGenerator,
    refiner: Option<&RefinerNets>,
    clip: &Clip,
    frame: usize,
    opts: &SynthesisOptions,
) -> RnnGmmResult<Synthesis> {
    let (spec, norm, g) = (&model.spec, &model.norm, &model.generator);
    let d = spec.dim();
    if opts.seed_frames < 2 || frame + 1 < opts.seed_frames || frame >= clip.frames() || opts.frames == 0 {
        return Err(RnnGmmError::Config(format!(
            "synthesis needs at least 2 seed frames ending at a frame of the clip and at least 1 frame to generate: \
             {} seed frames ending at frame {frame} of a {}-frame clip, {} frames to generate",
            opts.seed_frames,
            clip.frames(),
            opts.frames
        )));
    }
    let enc = spec.encode(clip)?;
    let first = frame + 1 - opts.seed_frames;
    let mut seed = enc.values[first * d..(frame + 1) * d].to_vec();
    norm.normalize(&mut seed);
    let (state, seed_nll) = if opts.init_steps > 0 {
        let est = estimate_initial_state(g, &seed, opts.init_steps, opts.init_lr)?;
        (est.state, (est.nll_zero, est.nll))
    } else {
        (g.zero_state(1)?, (f64::NAN, f64::NAN))
    };
    let mut rng = SplitMix64::new(opts.seed);
    let (mut frames, _) = g.sample(&seed, &state, opts.frames, &mut rng, opts.temperature)?;
    if let Some(r) = refiner {
        let x = Tensor::from_slice(&frames, (1, opts.frames, d), g.device())?;
        frames = r.refine(&x)?.flatten_all()?.to_vec1::<f32>()?;
    }
    norm.denormalize(&mut frames);
    // The placement at the last seed frame: the clip's origin advanced through frames 0..=frame.
    let mut placement: RootPlacement = enc.origin;
    for f in 0..=frame {
        let x = enc.frame(f);
        placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
    }
    let motion = spec.decode(&frames, placement)?;
    Ok(Synthesis { motion, features: frames, seed_nll })
}
