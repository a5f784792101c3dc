//! Random motion synthesis with an exported RNN-GMM generator (Wang, Chai & Xia 2019): one
//! [`SynthesisModel`] shared by many characters, one [`SynthesisCharacter`] per character (its
//! generator state, its seeded random numbers, its current frame and where it stands), and a
//! [`SynthesisRunner`] per thread that steps one character or a batch of them.
//!
//! Each step runs the generator's step graph (mixture weights, means and standard deviations
//! of the next frame), samples the next frame from the mixture with the character's own
//! `SplitMix64` (a component by its weight, then `mu + temperature * sigma * n` per value, as
//! `zoo_rnngmm::Mixture::sample` does), feeds it back, and decodes it into an [`EnginePose`]
//! (root motion accumulated as in the paper's eq. 4) plus the left / right contact bits. A
//! character's frames depend only on its seed and start frame: the same in any batch, on any
//! thread, in any run, bit for bit. For that, the generator's and the refiner's steps run with
//! their symbolic-batch plans at every batch size and a batch of one is padded to two rows
//! (the extra row's outputs are discarded): tract picks other kernels for a batch of one (matrix-vector) and for
//! concrete batch sizes, and on some CPUs (AVX-512) they round differently, which changes the
//! sampled mixture component and from then on the motion.
//!
//! When the file embeds the refiner's step graph (`zoo.rnngmm.refiner_graph`, written by
//! `zoo_rnngmm::export` for a run folder with a refiner), each sampled frame is refined behind
//! the generator (eq. 11): the runtime computes its end-effector positions and velocities (the
//! forward kinematics of `zoo_rnngmm::fk`, in f64), runs the refiner step (its LSTM state is the
//! character's), and decodes the refined frame; the generator still reads its own samples. The
//! refiner adds no latency in frames (it is causal: frame `t` needs frames up to `t`). The
//! refiner graph runs once per step for the whole batch; tract allocates its tensors per call
//! there (the generator's batched step does not). A character starts from the zero state (the
//! paper's baseline) or from a state estimated elsewhere
//! ([`SynthesisCharacter::generator_state_mut`]: `zoo generate` fits it to the seed frames, eq.
//! 26, on the training model), and takes more seed frames with [`SynthesisRunner::feed`].

use crate::error::MotionError;
use crate::metadata::MotionModelMetadata;
use crate::metadata::synthesis::{KEY, REFINER_GRAPH_KEY, SynthesisTask};
use crate::model::{MotionModel, MotionState};
use crate::pose::EnginePose;
use crate::runner::{MotionRunner, check_finite, check_len};
use glam::{DQuat, DVec3, Quat, Vec3};
use std::path::Path;
use zoo_motion::quat::from_scaled_axis;
use zoo_motion::rng::SplitMix64;

/// The refiner's end effectors and their statistics (the section's `refiner`).
type EffectorStats = crate::metadata::SynthesisRefiner;

type Plan = std::sync::Arc<tract_onnx::prelude::TypedRunnableModel>;

/// The refiner step graph and what its input needs. It runs once per step for the whole
/// batch of characters, with one plan for every batch size (the graph's symbolic batch), so
/// that a character's refined frames do not depend on its batch (see
/// [`SynthesisRunner::step_batch`]).
#[derive(Clone, Debug)]
struct Refiner {
    plan: Plan,
    stats: EffectorStats,
    hidden: usize,
}

/// A loaded synthesis model (the step graph, its `zoo.synthesis` section, and the refiner's
/// step when the file has one). Cheap to clone, `Send + Sync`.
#[derive(Clone, Debug)]
pub struct SynthesisModel {
    model: MotionModel,
    pub(crate) task: SynthesisTask,
    references: Vec<DQuat>,
    pub(crate) mean: Vec<f32>,
    pub(crate) std: Vec<f32>,
    refiner: Option<Refiner>,
}

/// The refiner of a file, if it embeds one.
fn load_refiner(bytes: &[u8], origin: &str, task: &SynthesisTask) -> Result<Option<Refiner>, MotionError> {
    use base64::Engine as _;
    let Some(stats) = task.refiner.clone() else { return Ok(None) };
    let props = crate::metadata::read_props(bytes, origin)?;
    // The format crate checked that the graph is there exactly when the section has a refiner.
    let Some((_, graph)) = props.iter().find(|(k, _)| k == REFINER_GRAPH_KEY) else {
        return Err(bad(REFINER_GRAPH_KEY, "missing: the `refiner` of the synthesis section has no graph"));
    };
    let d = task.frame_dim;
    let e = 6 * stats.effectors.len();
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(graph)
        .map_err(|err| bad(REFINER_GRAPH_KEY, err.to_string()))?;
    // Read through the runtime's one graph reader (IR version, dangling names, tract's panics).
    let (graph_proto, source) = crate::model::read_graph(&bytes, "the embedded refiner graph")?;
    let width = |i: usize| {
        graph_proto.graph.as_ref().and_then(|g| g.input.get(i)).and_then(|v| match &v.r#type {
            Some(tract_onnx::pb::TypeProto {
                value: Some(tract_onnx::pb::type_proto::Value::TensorType(t)), ..
            }) => t.shape.as_ref().and_then(|s| s.dim.get(1)).and_then(|d| match d.value {
                Some(tract_onnx::pb::tensor_shape_proto::dimension::Value::DimValue(n)) if n > 0 => Some(n as usize),
                _ => None,
            }),
            _ => None,
        })
    };
    let h = width(2).ok_or_else(|| bad(REFINER_GRAPH_KEY, "input 2 (`h`) has no fixed width"))?;
    // The inputs' widths, checked here: the plan's batch is symbolic, so tract would only
    // find a mismatch at the first step.
    for (i, name, want) in [(0, "x", d), (1, "effectors", e), (3, "c", h)] {
        if width(i) != Some(want) {
            return Err(bad(REFINER_GRAPH_KEY, format!("input {i} (`{name}`) must be {want} wide")));
        }
    }
    // Planned now, so that a graph tract cannot run is refused at load.
    use tract_onnx::prelude::*;
    let run = |err: TractError| MotionError::Run { reason: format!("{err:#}") };
    let plan = crate::model::planned(source).map_err(run)?;
    Ok(Some(Refiner { plan, stats, hidden: h }))
}

fn bad(key: &str, reason: impl Into<String>) -> MotionError {
    crate::metadata::FormatError::bad(key, reason).into()
}

impl SynthesisModel {
    /// Loads an exported RNN-GMM generator (`zoo export --onnx RUN_DIR --out FILE.onnx`); a
    /// file of another task is refused ([`MotionError::WrongTask`]).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        crate::LoadedModel::load(path)?.into_synthesis()
    }

    /// Loads an exported RNN-GMM generator from the bytes of its file.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        crate::LoadedModel::from_bytes(bytes)?.into_synthesis()
    }

    /// Loads the step graph (and the refiner's) of a `synthesis` file whose metadata was read
    /// and checked.
    pub(crate) fn from_parts(bytes: &[u8], origin: &str, metadata: MotionModelMetadata) -> Result<Self, MotionError> {
        let Some(task) = metadata.task.as_synthesis().cloned() else {
            return Err(MotionError::wrong_task(&metadata, "synthesis", "SynthesisModel"));
        };
        let model = MotionModel::from_parts(bytes, origin, metadata)?;
        let meta = model.metadata();
        let (d, m) = (task.frame_dim, task.components);
        let widths = |infos: &[crate::model::MotionTensorInfo]| -> Vec<(String, usize)> {
            infos.iter().map(|i| (i.name.clone(), i.width)).collect()
        };
        let want_in = vec![("x".to_string(), d)];
        let want_out = vec![("weights".to_string(), m), ("means".to_string(), m * d), ("stds".to_string(), m * d)];
        if widths(model.inputs()) != want_in || widths(model.outputs()) != want_out {
            return Err(bad(
                KEY,
                format!(
                    "the step graph takes {:?} and gives {:?}; a synthesis model takes {want_in:?} and gives {want_out:?}",
                    widths(model.inputs()),
                    widths(model.outputs())
                ),
            ));
        }
        let norm = meta.group("x", d)?;
        let (mean, std) = (norm.mean.clone(), norm.std.clone());
        let references = task.references.iter().map(|q| DQuat::from_xyzw(q[0], q[1], q[2], q[3]).normalize()).collect();
        let refiner = load_refiner(bytes, origin, &task)?;
        Ok(SynthesisModel { model, task, references, mean, std, refiner })
    }

    /// Whether frames are refined (the file embeds the refiner's step).
    pub fn has_refiner(&self) -> bool {
        self.refiner.is_some()
    }

    /// The same model without its refiner (the generator's own frames).
    pub fn without_refiner(mut self) -> Self {
        self.refiner = None;
        self
    }

    /// End-effector positions of a frame (normalised) in the heading frame: the forward
    /// kinematics of `zoo_rnngmm::fk` (root tilt at height `ty`, heading and ground position
    /// removed), in f64.
    fn effector_positions(
        &self,
        x: &[f32],
        stats: &EffectorStats,
        out: &mut [DVec3],
        rot: &mut [DQuat],
        pos: &mut [DVec3],
    ) {
        let v = |i: usize| (x[i] * self.std[i] + self.mean[i]) as f64;
        let skeleton = &self.model.metadata().skeleton;
        rot[0] = from_scaled_axis(DVec3::new(v(4), 0.0, v(5)));
        pos[0] = DVec3::new(0.0, v(3), 0.0);
        for j in 1..self.joints() {
            let p = skeleton.parents[j] as usize;
            let i = 6 + 3 * (j - 1);
            let local = self.references[j] * from_scaled_axis(DVec3::new(v(i), v(i + 1), v(i + 2)));
            pos[j] = pos[p] + rot[p] * skeleton.offset(j).as_dvec3();
            rot[j] = rot[p] * local;
        }
        for (k, &j) in stats.effectors.iter().enumerate() {
            out[k] = pos[j];
        }
    }

    /// The step graph.
    pub fn model(&self) -> &MotionModel {
        &self.model
    }

    /// Values per feature frame.
    pub fn frame_dim(&self) -> usize {
        self.task.frame_dim
    }

    /// Joints of the skeleton.
    pub fn joints(&self) -> usize {
        self.references.len()
    }

    /// A character standing at the origin facing +Z, seeded with `seed`; give it a start frame
    /// with [`SynthesisCharacter::start`] before stepping it.
    pub fn new_character(&self, seed: u64) -> SynthesisCharacter {
        let (hu, e) = self.refiner.as_ref().map_or((0, 0), |r| (r.hidden, r.stats.effectors.len()));
        SynthesisCharacter {
            state: self.model.new_state(),
            rng: SplitMix64::new(seed),
            x: vec![0.0; self.task.frame_dim],
            placement: [0.0; 3],
            started: false,
            refiner_h: vec![0.0; hu],
            refiner_c: vec![0.0; hu],
            effectors: vec![DVec3::ZERO; e],
        }
    }

    /// A runner for one thread, with scratch space for batches of up to `max_batch` characters.
    pub fn runner(&self, max_batch: usize) -> Result<SynthesisRunner, MotionError> {
        let n = max_batch.max(1);
        let (d, m) = (self.task.frame_dim, self.task.components);
        let (hu, e) = self.refiner.as_ref().map_or((0, 0), |r| (r.hidden, 6 * r.stats.effectors.len()));
        Ok(SynthesisRunner {
            model: self.clone(),
            runner: self.model.runner()?,
            x: vec![0.0; n.max(2) * d],
            weights: vec![0.0; n.max(2) * m],
            means: vec![0.0; n.max(2) * m * d],
            stds: vec![0.0; n.max(2) * m * d],
            states: Vec::with_capacity(n.max(2)),
            pad: self.model.new_state(),
            world: vec![Quat::IDENTITY; self.references.len()],
            refined: vec![0.0; n * d],
            refiner_x: Vec::with_capacity(n.max(2) * d),
            refiner_e: Vec::with_capacity(n.max(2) * e),
            refiner_h: Vec::with_capacity(n.max(2) * hu),
            refiner_c: Vec::with_capacity(n.max(2) * hu),
            effectors: vec![DVec3::ZERO; self.refiner.as_ref().map_or(0, |r| r.stats.effectors.len())],
            fk_rot: vec![DQuat::IDENTITY; self.references.len()],
            fk_pos: vec![DVec3::ZERO; self.references.len()],
        })
    }
}

/// One character: its generator state, random numbers, current frame and placement.
#[derive(Clone, Debug)]
pub struct SynthesisCharacter {
    state: MotionState,
    rng: SplitMix64,
    /// The current frame, normalised (the next step's input).
    x: Vec<f32>,
    /// Ground position x, z and heading of the root.
    placement: [f64; 3],
    started: bool,
    /// The refiner's LSTM state.
    refiner_h: Vec<f32>,
    refiner_c: Vec<f32>,
    /// End-effector positions of the previous (unrefined) frame, for the velocities.
    effectors: Vec<DVec3>,
}

impl SynthesisCharacter {
    /// Starts from a feature frame in clip units (`frame_dim` values, e.g. a frame of a clip
    /// encoded by `zoo_rnngmm::FeatureSpec::encode`) with the root at `(x, z)` facing `yaw`
    /// (radians about +Y), from the zero generator state. The random numbers are not reset.
    pub fn start(
        &mut self,
        model: &SynthesisModel,
        frame: &[f32],
        x: f32,
        z: f32,
        yaw: f32,
    ) -> Result<(), MotionError> {
        check_len("start frame", frame.len(), 1, model.task.frame_dim)?;
        check_finite("start frame", frame, model.task.frame_dim)?;
        for (i, v) in frame.iter().enumerate() {
            self.x[i] = (v - model.mean[i]) / model.std[i];
        }
        self.state.reset();
        self.placement = [x as f64, z as f64, yaw as f64];
        self.started = true;
        if let Some(r) = &model.refiner {
            self.refiner_h.fill(0.0);
            self.refiner_c.fill(0.0);
            let j = model.joints();
            let (mut rot, mut pos) = (vec![DQuat::IDENTITY; j], vec![DVec3::ZERO; j]);
            model.effector_positions(&self.x, &r.stats, &mut self.effectors, &mut rot, &mut pos);
        }
        Ok(())
    }

    /// The generator's recurrent state, to start from a state estimated elsewhere (e.g. `zoo
    /// generate`'s fit of the seed frames, the paper's eq. 26): slot `k` holds the values of
    /// [`MotionModel::states`]`()[k]` (`h{l}` and `c{l}`, the LSTM's output and cell state of layer
    /// `l`). Set it after [`SynthesisCharacter::start`], which zeroes it.
    pub fn generator_state_mut(&mut self) -> &mut MotionState {
        &mut self.state
    }

    /// The state of the character's random numbers (`SplitMix64::from_state` restores it).
    pub fn rng_state(&self) -> u64 {
        self.rng.state()
    }

    /// The current frame, normalised: the start frame, then the last sampled frame (the next
    /// step's input). For reference vectors ([`crate::reference`]).
    pub(crate) fn frame(&self) -> &[f32] {
        &self.x
    }
}

/// Draws a frame `x` (`D` values) from a mixture (`w`: `M` weights, `mu`, `sd`: `M D` each) as
/// `zoo_rnngmm::Mixture::sample` does: a component by its weight (one uniform draw), then
/// `mu + temperature * sigma * n` per value (one normal draw each).
pub(crate) fn draw_frame(rng: &mut SplitMix64, w: &[f32], mu: &[f32], sd: &[f32], temperature: f64, x: &mut [f32]) {
    let (m, d) = (w.len(), x.len());
    let u = rng.next_f64();
    let (mut acc, mut k) = (0.0, m - 1);
    for (i, wi) in w.iter().enumerate() {
        acc += *wi as f64;
        if u < acc {
            k = i;
            break;
        }
    }
    for j in 0..d {
        let z = rng.normal();
        x[j] = (mu[k * d + j] as f64 + temperature * sd[k * d + j] as f64 * z) as f32;
    }
}

/// One character's view of the last step of a [`SynthesisRunner`].
pub(crate) struct LastStep<'a> {
    /// The mixture's weights (`M`).
    pub(crate) weights: &'a [f32],
    /// Its means (`M D`, normalised).
    pub(crate) means: &'a [f32],
    /// Its standard deviations (`M D`, normalised).
    pub(crate) stds: &'a [f32],
    /// The refined frame (`D`, normalised; `None` without a refiner).
    pub(crate) refined: Option<&'a [f32]>,
}

/// Steps characters on one thread. The generator's step, the sampling and the decoding
/// allocate nothing per frame (up to the batch size the runner was made for; a larger batch
/// grows the scratch space once); with a refiner, tract allocates the refiner step's tensors.
#[derive(Debug)]
pub struct SynthesisRunner {
    model: SynthesisModel,
    runner: MotionRunner,
    x: Vec<f32>,
    weights: Vec<f32>,
    means: Vec<f32>,
    stds: Vec<f32>,
    states: Vec<MotionState>,
    /// The generator state of the row that pads a batch of one to two (see `step_batch`).
    pad: MotionState,
    world: Vec<Quat>,
    /// Refined frames, one row per character of the batch.
    refined: Vec<f32>,
    /// The refiner's batched inputs: frames, end-effector features, LSTM states.
    refiner_x: Vec<f32>,
    refiner_e: Vec<f32>,
    refiner_h: Vec<f32>,
    refiner_c: Vec<f32>,
    effectors: Vec<DVec3>,
    fk_rot: Vec<DQuat>,
    fk_pos: Vec<DVec3>,
}

impl SynthesisRunner {
    /// Generates the next frame of one character into `pose`; returns its contact bits
    /// `[left, right]`. `temperature` scales the mixture's standard deviations (1: the model's).
    pub fn step(
        &mut self,
        character: &mut SynthesisCharacter,
        temperature: f32,
        pose: &mut EnginePose,
    ) -> Result<[bool; 2], MotionError> {
        let mut contacts = [[false; 2]];
        self.step_batch(std::slice::from_mut(character), temperature, std::slice::from_mut(pose), &mut contacts)?;
        Ok(contacts[0])
    }

    /// Feeds `frame` (a feature frame in clip units) to a started character as if it had been
    /// sampled: the generator steps on the character's current frame (its state advances, the
    /// mixture is not drawn from, no random number is used) and `frame` becomes the current
    /// frame, the next step's input; with a refiner, its end effectors are the new frame's
    /// (the refiner's own state is left as it is). Seeds a character with more than one frame
    /// of a clip: [`SynthesisCharacter::start`] with the first, then `feed` each later one.
    pub fn feed(&mut self, character: &mut SynthesisCharacter, frame: &[f32]) -> Result<(), MotionError> {
        let (d, m) = (self.model.task.frame_dim, self.model.task.components);
        if !character.started {
            return Err(MotionError::TransitionSequence {
                character: 0,
                reason: "it was not started: call SynthesisCharacter::start first".into(),
            });
        }
        check_len("fed frame", frame.len(), 1, d)?;
        check_finite("fed frame", frame, d)?;
        // A batch of one padded to two, as `step_batch` runs it (the module's doc).
        if self.x.len() < 2 * d {
            self.x.resize(2 * d, 0.0);
            self.weights.resize(2 * m, 0.0);
            self.means.resize(2 * m * d, 0.0);
            self.stds.resize(2 * m * d, 0.0);
        }
        self.x[..d].copy_from_slice(&character.x);
        self.x.copy_within(0..d, d);
        self.states.clear();
        self.states.push(std::mem::replace(&mut character.state, MotionState { slots: Vec::new() }));
        self.states.push(std::mem::replace(&mut self.pad, MotionState { slots: Vec::new() }));
        let run = self.runner.step_batch_invariant(
            &mut self.states,
            &[&self.x[..2 * d]],
            &mut [&mut self.weights[..2 * m], &mut self.means[..2 * m * d], &mut self.stds[..2 * m * d]],
        );
        self.pad = self.states.pop().expect("the pad pushed above");
        character.state = self.states.pop().expect("the character pushed above");
        run?;
        for (i, v) in frame.iter().enumerate() {
            character.x[i] = (v - self.model.mean[i]) / self.model.std[i];
        }
        if let Some(r) = &self.model.refiner {
            self.model.effector_positions(
                &character.x,
                &r.stats,
                &mut character.effectors,
                &mut self.fk_rot,
                &mut self.fk_pos,
            );
        }
        Ok(())
    }

    /// Generates the next frame of every character in one graph run: `poses[c]` and
    /// `contacts[c]` receive character `c`'s. Each character samples with its own random
    /// numbers, so its frames do not depend on the batch.
    pub fn step_batch(
        &mut self,
        characters: &mut [SynthesisCharacter],
        temperature: f32,
        poses: &mut [EnginePose],
        contacts: &mut [[bool; 2]],
    ) -> Result<(), MotionError> {
        let n = characters.len();
        let (d, m, joints) = (self.model.task.frame_dim, self.model.task.components, self.model.joints());
        if poses.len() != n || contacts.len() != n {
            return Err(MotionError::BufferCount {
                what: "poses and contacts",
                expected: n,
                found: poses.len().min(contacts.len()),
            });
        }
        if !(temperature.is_finite() && temperature >= 0.0) {
            return Err(MotionError::NonFinite {
                name: "temperature".into(),
                index: 0,
                character: 0,
                value: temperature,
            });
        }
        for (c, (ch, pose)) in characters.iter().zip(poses.iter()).enumerate() {
            if !ch.started {
                return Err(MotionError::TransitionSequence {
                    character: c,
                    reason: "it was not started: call SynthesisCharacter::start first".into(),
                });
            }
            check_len("pose local_rotations", pose.local_rotations.len(), 1, joints)?;
        }
        // A batch of one padded to two, stepped with the plan for every batch size (why: the
        // module's doc). The pad row reads its character's frame and keeps a state of its own;
        // its outputs are discarded.
        let rows = n.max(2);
        if self.x.len() < rows * d {
            self.x.resize(rows * d, 0.0);
            self.weights.resize(rows * m, 0.0);
            self.means.resize(rows * m * d, 0.0);
            self.stds.resize(rows * m * d, 0.0);
        }
        for (c, ch) in characters.iter().enumerate() {
            self.x[c * d..(c + 1) * d].copy_from_slice(&ch.x);
        }
        // The characters' states, moved into one slice for the batched run and back.
        self.states.clear();
        for ch in characters.iter_mut() {
            self.states.push(std::mem::replace(&mut ch.state, MotionState { slots: Vec::new() }));
        }
        if n == 1 {
            self.x.copy_within(0..d, d);
            self.states.push(std::mem::replace(&mut self.pad, MotionState { slots: Vec::new() }));
        }
        let run = self.runner.step_batch_invariant(
            &mut self.states,
            &[&self.x[..rows * d]],
            &mut [&mut self.weights[..rows * m], &mut self.means[..rows * m * d], &mut self.stds[..rows * m * d]],
        );
        if n == 1 {
            self.pad = self.states.pop().expect("the pad pushed above");
        }
        for (ch, state) in characters.iter_mut().zip(self.states.drain(..)) {
            ch.state = state;
        }
        run?;
        for (c, ch) in characters.iter_mut().enumerate() {
            let w = &self.weights[c * m..(c + 1) * m];
            let (mu, sd) = (&self.means[c * m * d..(c + 1) * m * d], &self.stds[c * m * d..(c + 1) * m * d]);
            draw_frame(&mut ch.rng, w, mu, sd, temperature as f64, &mut ch.x);
        }
        let refined = self.refine(characters)?;
        for (c, ch) in characters.iter_mut().enumerate() {
            contacts[c] = self.decode(ch, refined.then_some(c), &mut poses[c]);
        }
        Ok(())
    }

    /// The last step of character `c` (its row of the batch). For reference vectors
    /// ([`crate::reference`]).
    pub(crate) fn last_step(&self, c: usize) -> LastStep<'_> {
        let (d, m) = (self.model.task.frame_dim, self.model.task.components);
        LastStep {
            weights: &self.weights[c * m..(c + 1) * m],
            means: &self.means[c * m * d..(c + 1) * m * d],
            stds: &self.stds[c * m * d..(c + 1) * m * d],
            refined: self.model.refiner.as_ref().map(|_| &self.refined[c * d..(c + 1) * d]),
        }
    }

    /// Refines every character's new frame into row `c` of `self.refined` (eq. 11), in one run
    /// of the refiner's step for the batch; returns whether it did (the file has a refiner).
    fn refine(&mut self, characters: &mut [SynthesisCharacter]) -> Result<bool, MotionError> {
        use tract_onnx::prelude::*;
        let Some(r) = &self.model.refiner else { return Ok(false) };
        let (n, d, hu) = (characters.len(), self.model.task.frame_dim, r.hidden);
        let s = &r.stats;
        let ne = s.effectors.len();
        let e = 6 * ne;
        for buf in [&mut self.refiner_x, &mut self.refiner_e, &mut self.refiner_h, &mut self.refiner_c] {
            buf.clear();
        }
        for ch in characters.iter_mut() {
            self.model.effector_positions(&ch.x, s, &mut self.effectors, &mut self.fk_rot, &mut self.fk_pos);
            // v_t = (dtx, 0, dtz) + yaw(dry) p_t - p_(t-1), in the previous heading frame.
            let v = |i: usize| (ch.x[i] * self.model.std[i] + self.model.mean[i]) as f64;
            let step = DVec3::new(v(0), 0.0, v(1));
            let turn = DQuat::from_rotation_y(v(2));
            let row = self.refiner_e.len();
            self.refiner_e.resize(row + e, 0.0);
            for (k, p) in self.effectors.iter().enumerate() {
                let vel = step + turn * *p - ch.effectors[k];
                for a in 0..3 {
                    self.refiner_e[row + 3 * k + a] = p[a] as f32;
                    self.refiner_e[row + 3 * ne + 3 * k + a] = vel[a] as f32;
                }
            }
            for (i, v) in self.refiner_e[row..].iter_mut().enumerate() {
                *v = (*v - s.mean[i]) / s.std[i];
            }
            ch.effectors.copy_from_slice(&self.effectors);
            self.refiner_x.extend_from_slice(&ch.x);
            self.refiner_h.extend_from_slice(&ch.refiner_h);
            self.refiner_c.extend_from_slice(&ch.refiner_c);
        }
        // A batch of one padded to two, as for the generator (`step_batch`).
        let rows = n.max(2);
        if n == 1 {
            for (buf, w) in [
                (&mut self.refiner_x, d),
                (&mut self.refiner_e, e),
                (&mut self.refiner_h, hu),
                (&mut self.refiner_c, hu),
            ] {
                buf.extend_from_within(..w);
            }
        }
        let run = |err: TractError| MotionError::Run { reason: format!("{err:#}") };
        let t = |v: &[f32], w: usize| -> Result<TValue, MotionError> {
            Ok(Tensor::from_shape::<f32>(&[rows, w], v).map_err(run)?.into_tvalue())
        };
        let inputs =
            tvec![t(&self.refiner_x, d)?, t(&self.refiner_e, e)?, t(&self.refiner_h, hu)?, t(&self.refiner_c, hu)?];
        let out = r.plan.run(inputs).map_err(run)?;
        let get = |i: usize| -> Result<&[f32], MotionError> {
            out[i].try_as_plain_ram().and_then(|t| t.as_slice::<f32>()).map_err(run)
        };
        let (x, h, c) = (get(0)?, get(1)?, get(2)?);
        if self.refined.len() < n * d {
            self.refined.resize(n * d, 0.0);
        }
        self.refined[..n * d].copy_from_slice(&x[..n * d]);
        for (k, ch) in characters.iter_mut().enumerate() {
            ch.refiner_h.copy_from_slice(&h[k * hu..(k + 1) * hu]);
            ch.refiner_c.copy_from_slice(&c[k * hu..(k + 1) * hu]);
        }
        Ok(true)
    }

    /// Decodes the character's new frame (row `refined` of the refined frames, else its
    /// sampled frame) into `pose`, advancing its placement.
    fn decode(&mut self, ch: &mut SynthesisCharacter, refined: Option<usize>, pose: &mut EnginePose) -> [bool; 2] {
        let d = self.model.task.frame_dim;
        let x: &[f32] = match refined {
            Some(c) => &self.refined[c * d..(c + 1) * d],
            None => &ch.x,
        };
        decode_frame(&self.model, x, &mut ch.placement, &mut self.world, pose)
    }
}

/// Decodes a normalised feature frame `x` (`frame_dim` values) into `pose` and returns its
/// contact bits `[left, right]`: `placement` (ground x, z and heading of the root) advances by
/// the frame's root step (eq. 4); `world` is scratch space of one rotation per joint. Global
/// positions are written when `pose` has them.
pub(crate) fn decode_frame(
    model: &SynthesisModel,
    x: &[f32],
    placement: &mut [f64; 3],
    world: &mut [Quat],
    pose: &mut EnginePose,
) -> [bool; 2] {
    let d = model.task.frame_dim;
    let v = |i: usize| (x[i] * model.std[i] + model.mean[i]) as f64;
    let [px, pz, yaw] = *placement;
    let step = DQuat::from_rotation_y(yaw) * DVec3::new(v(0), 0.0, v(1));
    *placement = [px + step.x, pz + step.z, yaw + v(2)];
    pose.root_position = Vec3::new(placement[0] as f32, 0.0, placement[1] as f32);
    pose.root_rotation = Quat::from_rotation_y(placement[2] as f32);
    pose.root_delta_position = Vec3::new(v(0) as f32, 0.0, v(1) as f32);
    pose.root_delta_yaw = v(2) as f32;
    pose.hips_position = Vec3::new(0.0, v(3) as f32, 0.0);
    pose.local_rotations[0] = from_scaled_axis(DVec3::new(v(4), 0.0, v(5))).as_quat();
    for j in 1..model.joints() {
        let i = 6 + 3 * (j - 1);
        let q = model.references[j] * from_scaled_axis(DVec3::new(v(i), v(i + 1), v(i + 2)));
        pose.local_rotations[j] = q.normalize().as_quat();
    }
    let skeleton = &model.model.metadata().skeleton;
    if pose.global_positions.len() == model.joints() {
        world[0] = pose.root_rotation * pose.local_rotations[0];
        pose.global_positions[0] = pose.root_position + pose.root_rotation * pose.hips_position;
        for j in 1..model.joints() {
            let p = skeleton.parents[j] as usize;
            pose.global_positions[j] = pose.global_positions[p] + world[p] * skeleton.offset(j);
            world[j] = world[p] * pose.local_rotations[j];
        }
    }
    [v(d - 2) > 0.5, v(d - 1) > 0.5]
}
