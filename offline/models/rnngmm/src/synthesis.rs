//! Random motion synthesis (sec. 4.1.4, 4.2.3, 5.1): seed the generator with frames of a clip,
//! estimate its initial state (eq. 26), sample frames from the mixture, refine them (optional),
//! and decode them into a clip that continues the seed clip where it stands.

use crate::checkpoint::LoadedGenerator;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{DecodedMotion, FeatureSpec, RootPlacement};
use crate::initial_state::estimate_initial_state;
use crate::refiner::RefinerNets;
use candle_core::{DType, Tensor};
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;
use zoo_nn::LstmState;

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
/// refined by `refiner` when given. Deterministic for `opts.seed`. The whole sequence in one
/// [`SynthesisStream`] chunk.
pub fn synthesize(
    model: &LoadedGenerator,
    refiner: Option<&RefinerNets>,
    clip: &Clip,
    frame: usize,
    opts: &SynthesisOptions,
) -> RnnGmmResult<Synthesis> {
    let mut stream = SynthesisStream::new(model, refiner, clip, frame, opts)?;
    let chunk = stream.next_chunk(opts.frames)?;
    Ok(Synthesis { motion: chunk.motion, features: chunk.features, seed_nll: stream.seed_nll() })
}

/// Frames of a [`SynthesisStream`].
#[derive(Clone, Debug)]
pub struct SynthesisChunk {
    /// The frames as a clip (placed where the previous chunk ended) with their contact bits:
    /// refined when the stream has a refiner.
    pub motion: DecodedMotion,
    /// Their features in clip units (`frames * D`), refined when the stream has a refiner.
    pub features: Vec<f32>,
    /// With a refiner and [`SynthesisStream::keep_unrefined`]: the generator's own frames (the
    /// refiner's input), decoded from the same placement.
    pub unrefined: Option<DecodedMotion>,
}

/// Random synthesis of unlimited length, chunk by chunk: memory does not grow with the number
/// of frames generated. The generator's state, the pending mixture, the sampling generator, the
/// refiner's LSTM state and the root placement carry over from one chunk to the next, so the
/// frames do not depend on how the sequence is cut into chunks, except for float rounding in
/// the refiner's batched layers (the sampled frames are the same whatever the chunking).
pub struct SynthesisStream<'a> {
    model: &'a LoadedGenerator,
    refiner: Option<&'a RefinerNets>,
    temperature: f64,
    rng: SplitMix64,
    state: LstmState,
    /// Head outputs of the next frame's mixture.
    head: Vec<f32>,
    /// The refiner's LSTM state and the last normalised unrefined frame `(1, 1, D)` (the seed's
    /// last frame at the start: the first generated frame's end-effector velocities use it).
    refiner_state: Option<(LstmState, Tensor)>,
    placement: RootPlacement,
    unrefined_placement: Option<RootPlacement>,
    seed_nll: (f64, f64),
    generated: usize,
}

impl<'a> SynthesisStream<'a> {
    /// Seeds the generator with `opts.seed_frames` frames of `clip` ending at `frame`, estimates
    /// its initial state (eq. 26, `opts.init_steps`), and places the motion where the clip
    /// stands at `frame`. `opts.frames` is not used (ask [`SynthesisStream::next_chunk`]).
    pub fn new(
        model: &'a LoadedGenerator,
        refiner: Option<&'a RefinerNets>,
        clip: &Clip,
        frame: usize,
        opts: &SynthesisOptions,
    ) -> RnnGmmResult<Self> {
        let (spec, norm, g) = (&model.spec, &model.norm, &model.generator);
        let d = spec.dim();
        if opts.seed_frames < 2 || frame + 1 < opts.seed_frames || frame >= clip.frames() {
            return Err(RnnGmmError::Config(format!(
                "synthesis needs at least 2 seed frames ending at a frame of the clip: {} seed frames ending at \
                 frame {frame} of a {}-frame clip",
                opts.seed_frames,
                clip.frames()
            )));
        }
        if !(opts.temperature.is_finite() && opts.temperature >= 0.0) {
            return Err(RnnGmmError::Config(format!(
                "temperature must be finite and not negative, found {}",
                opts.temperature
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
        // Feed the seed frames: the last step's head is the mixture of the first new frame.
        let mut state = state;
        let mut head = Vec::new();
        for x in seed.chunks_exact(d) {
            let (r, s) = g.step(&Tensor::from_slice(x, (1, d), g.device())?, &state)?;
            head = r.flatten_all()?.to_dtype(DType::F32)?.to_vec1::<f32>()?;
            state = s;
        }
        let refiner_state = match refiner {
            Some(r) => {
                let last = Tensor::from_slice(&seed[seed.len() - d..], (1, 1, d), g.device())?;
                Some((r.refiner_zero_state(1)?, last))
            }
            None => None,
        };
        // The placement at the last seed frame: the clip's origin advanced through frames 0..=frame.
        let mut placement: RootPlacement = enc.origin;
        for f in 0..=frame {
            let x = enc.frame(f);
            placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
        }
        Ok(SynthesisStream {
            model,
            refiner,
            temperature: opts.temperature,
            rng: SplitMix64::new(opts.seed),
            state,
            head,
            refiner_state,
            placement,
            unrefined_placement: None,
            seed_nll,
            generated: 0,
        })
    }

    /// Also decode the generator's own frames beside the refined ones (for comparisons). Call
    /// before the first chunk.
    pub fn keep_unrefined(mut self) -> Self {
        if self.refiner.is_some() && self.generated == 0 {
            self.unrefined_placement = Some(self.placement);
        }
        self
    }

    /// NLL of the seed frames from the zero state and from the estimated state (eq. 26; NaN
    /// without the estimation).
    pub fn seed_nll(&self) -> (f64, f64) {
        self.seed_nll
    }

    /// Frames generated so far.
    pub fn generated(&self) -> usize {
        self.generated
    }

    /// The next `frames` frames (at least 1).
    pub fn next_chunk(&mut self, frames: usize) -> RnnGmmResult<SynthesisChunk> {
        let (spec, norm, g) = (&self.model.spec, &self.model.norm, &self.model.generator);
        let d = spec.dim();
        if frames == 0 {
            return Err(RnnGmmError::Config("a synthesis chunk needs at least 1 frame".into()));
        }
        let mut x = vec![0f32; frames * d];
        for f in 0..frames {
            let frame = &mut x[f * d..(f + 1) * d];
            g.mixture_of(&self.head)?.sample(&mut self.rng, self.temperature, frame);
            let (r, s) = g.step(&Tensor::from_slice(frame, (1, d), g.device())?, &self.state)?;
            self.head = r.flatten_all()?.to_dtype(DType::F32)?.to_vec1::<f32>()?;
            self.state = s;
        }
        let (mut features, unrefined) = match (self.refiner, self.refiner_state.take()) {
            (Some(r), Some((state, prev))) => {
                let xt = Tensor::from_slice(&x, (1, frames, d), g.device())?;
                let (refined, state) = r.refine_chunk(&xt, Some(&prev), &state)?;
                self.refiner_state = Some((state, xt.narrow(1, frames - 1, 1)?));
                (refined.flatten_all()?.to_vec1::<f32>()?, Some(x))
            }
            _ => (x, None),
        };
        norm.denormalize(&mut features);
        let motion = decode_chunk(spec, &features, &mut self.placement)?;
        let unrefined = match (unrefined, self.unrefined_placement.as_mut()) {
            (Some(mut raw), Some(placement)) => {
                norm.denormalize(&mut raw);
                Some(decode_chunk(spec, &raw, placement)?)
            }
            _ => None,
        };
        self.generated += frames;
        Ok(SynthesisChunk { motion, features, unrefined })
    }
}

/// Decodes frames from `placement`, advancing it past them.
fn decode_chunk(spec: &FeatureSpec, values: &[f32], placement: &mut RootPlacement) -> RnnGmmResult<DecodedMotion> {
    let motion = spec.decode(values, *placement)?;
    for x in values.chunks_exact(spec.dim()) {
        *placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
    }
    Ok(motion)
}
