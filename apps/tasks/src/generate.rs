//! `zoo generate` on the runtime's synthesis task (`zoo_runtime::SynthesisModel`): the run
//! folder's generator (and refiner) exported in memory and run by the runtime, started from the
//! seed frames of a clip. The initial state of the paper's eq. 26 is estimated on the training
//! model in candle (a gradient descent through the network, which an inference engine does not
//! do) and given to the runtime's character; sampling, the refiner and the decoding are the
//! runtime's, as every engine runs them.

use crate::{ModelSource, TaskResult};
use std::path::Path;
use zoo_data::{Message, Progress, bail};
use zoo_format::MotionTaskKind;
use zoo_motion::Clip;
use zoo_rnngmm::checkpoint::LoadedGenerator;
use zoo_rnngmm::run::MotionChunks;
use zoo_rnngmm::{DecodedMotion, RnnGmmResult, SynthesisOptions};
use zoo_runtime::{EnginePose, SynthesisCharacter, SynthesisModel, SynthesisRunner};

/// A trained RNN-GMM as `zoo generate` runs it: the training model (its features, and the
/// generator for the eq. 26 estimate) and the exported model in the runtime.
pub struct Generator {
    /// The run folder's generator in candle.
    pub candle: LoadedGenerator,
    model: SynthesisModel,
    /// The generator alone (the refined model's own draws, without its refiner).
    plain: SynthesisModel,
}

impl Generator {
    /// The model of the run folder `dir`: the generator, and the refiner unless `no_refiner`
    /// (refused, with what to do, when the folder has none).
    pub fn load(dir: &Path, no_refiner: bool) -> TaskResult<Generator> {
        Self::load_at(dir, no_refiner, zoo_format::WeightWidth::F32)
    }

    /// [`Generator::load`] with the exported model's weights stored at `width` (what `zoo export
    /// --weights` writes), for the quality of each width.
    pub fn load_at(dir: &Path, no_refiner: bool, width: zoo_format::WeightWidth) -> TaskResult<Generator> {
        if dir.is_file() {
            bail!(
                "--model {} is a file; `zoo generate` takes the run folder of `zoo train rnn-gmm`: the generator's \
                 state before the seed frames is fitted on the training model (eq. 26), which the exported file does \
                 not hold (engines start it from the zero state)",
                dir.display()
            );
        }
        let (candle, _) = zoo_rnngmm::run::load_run(dir, true).map_err(|e| Message(e.to_string()))?;
        if !no_refiner && !dir.join(zoo_rnngmm::refiner::REFINER_FILE).is_file() {
            // load_run says what to do.
            zoo_rnngmm::run::load_run(dir, false).map_err(|e| Message(e.to_string()))?;
        }
        let mut source = ModelSource::open(dir, MotionTaskKind::Synthesis, "generate")?;
        if width != zoo_format::WeightWidth::F32 {
            let onnx = zoo_export::OnnxModel::from_bytes(&source.bytes, "the exported run folder")
                .and_then(|m| zoo_export::with_weights(&m, width))
                .map_err(|e| Message(format!("storing the weights as {width}: {e}")))?;
            source.bytes = onnx.to_bytes();
        }
        let model = source.load()?.into_synthesis()?;
        let model = if no_refiner { model.without_refiner() } else { model };
        let plain = model.clone().without_refiner();
        Ok(Generator { candle, model, plain })
    }

    /// Whether the runtime refines the sampled frames.
    pub fn refined(&self) -> bool {
        self.model.has_refiner()
    }
}

/// A synthesis in the runtime, chunk by chunk, decoded onto the model's skeleton.
struct RuntimeSynthesis<'a> {
    candle: &'a LoadedGenerator,
    runner: SynthesisRunner,
    character: SynthesisCharacter,
    pose: EnginePose,
    temperature: f32,
}

impl<'a> RuntimeSynthesis<'a> {
    /// Seeds a character with `opts.seed_frames` frames of `clip` ending at `frame`: the
    /// generator's state before them estimated (eq. 26, `opts.init_steps`, in candle), the first
    /// started, the others fed, the motion placed where the clip stands at `frame`; sampling
    /// with `opts.seed`.
    fn new(
        candle: &'a LoadedGenerator,
        model: &SynthesisModel,
        clip: &Clip,
        frame: usize,
        opts: &SynthesisOptions,
    ) -> TaskResult<Self> {
        let (spec, norm) = (&candle.spec, &candle.norm);
        let d = spec.dim();
        if opts.seed_frames < 2 || frame + 1 < opts.seed_frames || frame >= clip.frames() {
            bail!(
                "synthesis needs at least 2 seed frames ending at a frame of the clip: {} seed frames ending at frame \
                 {frame} of a {}-frame clip",
                opts.seed_frames,
                clip.frames()
            );
        }
        if !(opts.temperature.is_finite() && opts.temperature >= 0.0) {
            bail!("temperature must be finite and not negative, found {}", opts.temperature);
        }
        let rnn = |e: zoo_rnngmm::RnnGmmError| Message(e.to_string());
        let enc = spec.encode(clip).map_err(rnn)?;
        let first = frame + 1 - opts.seed_frames;
        let seed = &enc.values[first * d..(frame + 1) * d];
        // Where the clip stands at the last seed frame (the first generated frame moves on from
        // there): its origin advanced through frames 0..=frame.
        let mut placement = enc.origin;
        for f in 0..=frame {
            let x = enc.frame(f);
            placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
        }
        let mut character = model.new_character(opts.seed);
        character.start(model, &seed[..d], placement.x as f32, placement.z as f32, placement.yaw as f32)?;
        if opts.init_steps > 0 {
            let mut normalized = seed.to_vec();
            norm.normalize(&mut normalized);
            let est = zoo_rnngmm::initial_state::estimate_initial_state(
                &candle.generator,
                &normalized,
                opts.init_steps,
                opts.init_lr,
            )
            .map_err(rnn)?;
            let infos = model.model().states().to_vec();
            let state = character.generator_state_mut();
            for (slot, info) in infos.iter().enumerate() {
                let (layer, cell) = match (info.input.strip_prefix('h'), info.input.strip_prefix('c')) {
                    (Some(k), _) => (k.parse::<usize>().ok(), false),
                    (_, Some(k)) => (k.parse::<usize>().ok(), true),
                    _ => (None, false),
                };
                let tensors = if cell { &est.state.c } else { &est.state.h };
                let Some(t) = layer.and_then(|k| tensors.get(k)) else {
                    bail!("the exported generator's state `{}` is not an LSTM layer's h or c", info.input);
                };
                let values = t.flatten_all().and_then(|t| t.to_vec1::<f32>()).map_err(|e| Message(e.to_string()))?;
                if values.len() != info.width {
                    bail!(
                        "the estimated state of `{}` has {} values, the graph {}",
                        info.input,
                        values.len(),
                        info.width
                    );
                }
                state.slot_mut(slot).copy_from_slice(&values);
            }
        }
        let mut runner = model.runner(1)?;
        for x in seed[d..].chunks_exact(d) {
            runner.feed(&mut character, x)?;
        }
        let mut pose = EnginePose::new(model.joints());
        pose.global_positions.clear();
        Ok(RuntimeSynthesis { candle, runner, character, pose, temperature: opts.temperature as f32 })
    }
}

impl MotionChunks for RuntimeSynthesis<'_> {
    fn next_motion(&mut self, frames: usize) -> RnnGmmResult<DecodedMotion> {
        let skeleton = &self.candle.spec.skeleton;
        let j = skeleton.len();
        let mut clip = Clip {
            skeleton: skeleton.clone(),
            frame_time: 1.0 / self.candle.spec.fps,
            local_rotations: Vec::with_capacity(frames * j),
            local_positions: Vec::with_capacity(frames * j),
        };
        let mut contacts = Vec::with_capacity(frames);
        for _ in 0..frames {
            let c = self
                .runner
                .step(&mut self.character, self.temperature, &mut self.pose)
                .map_err(|e| zoo_rnngmm::RnnGmmError::Motion(e.to_string()))?;
            let p = &self.pose;
            let root = p.root_rotation.as_dquat();
            clip.local_rotations.push((root * p.local_rotations[0].as_dquat()).normalize());
            clip.local_rotations.extend(p.local_rotations[1..].iter().map(|q| q.as_dquat()));
            clip.local_positions.push(p.root_position.as_dvec3() + root * p.hips_position.as_dvec3());
            clip.local_positions.extend_from_slice(&skeleton.offsets[1..]);
            contacts.push(c);
        }
        Ok(DecodedMotion { clip, contacts })
    }
}

/// Generates one sequence continuing `frame` of `clip` through the runtime into the BVH file
/// `bvh` and its contact labels `json`; returns the global joint positions of every frame when
/// `positions` asks for them.
pub fn generate_files(
    g: &Generator,
    (clip, frame): (&Clip, usize),
    opts: &SynthesisOptions,
    (bvh, json): (&Path, &Path),
    positions: bool,
    p: &dyn Progress,
) -> TaskResult<Vec<Vec<[f32; 3]>>> {
    let mut stream = RuntimeSynthesis::new(&g.candle, &g.model, clip, frame, opts)?;
    let fps = g.candle.spec.fps;
    Ok(zoo_rnngmm::run::write_generated(&mut stream, fps, opts.frames, (bvh, json), positions, p)
        .map_err(|e| Message(e.to_string()))?)
}

impl zoo_rnngmm::bench::synthesis::Synthesizer for Generator {
    fn synthesize(
        &self,
        clip: &Clip,
        frame: usize,
        opts: &SynthesisOptions,
    ) -> RnnGmmResult<(Option<DecodedMotion>, DecodedMotion)> {
        let err = |e: crate::TaskError| zoo_rnngmm::RnnGmmError::Motion(e.to_string());
        // The generator reads its own samples: without its refiner, the same seed draws the same
        // frames, which the refined run refines.
        let raw = RuntimeSynthesis::new(&self.candle, &self.plain, clip, frame, opts)
            .map_err(err)?
            .next_motion(opts.frames)?;
        let refined = match self.model.has_refiner() {
            true => Some(
                RuntimeSynthesis::new(&self.candle, &self.model, clip, frame, opts)
                    .map_err(err)?
                    .next_motion(opts.frames)?,
            ),
            false => None,
        };
        Ok((refined, raw))
    }
}
