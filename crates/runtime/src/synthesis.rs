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
//! thread, in any run.
//!
//! Not here yet: the refiner (its export needs the end-effector forward kinematics in the
//! graph) and the initial state estimation of eq. 26 (a start from the zero state, as the
//! paper's baseline).

use crate::error::MotionError;
use crate::metadata::synthesis::{KEY, SynthesisTask};
use crate::model::{MotionModel, MotionState};
use crate::pose::EnginePose;
use crate::runner::{MotionRunner, check_finite, check_len};
use glam::{DQuat, DVec3, Quat, Vec3};
use prost::Message;
use std::path::Path;
use zoo_motion::quat::from_scaled_axis;
use zoo_motion::rng::SplitMix64;

/// A loaded synthesis model (the step graph and its `zoo.synthesis` section). Cheap to clone,
/// `Send + Sync`.
#[derive(Clone, Debug)]
pub struct SynthesisModel {
    model: MotionModel,
    task: SynthesisTask,
    references: Vec<DQuat>,
    mean: Vec<f32>,
    std: Vec<f32>,
}

fn bad(key: &str, reason: impl Into<String>) -> MotionError {
    MotionError::BadMetadata { key: key.to_string(), reason: reason.into() }
}

impl SynthesisModel {
    /// Loads an exported RNN-GMM generator (`zoo export --onnx RUN_DIR --out FILE.onnx`).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        let path = path.as_ref();
        let bytes =
            std::fs::read(path).map_err(|source| MotionError::Io { path: path.display().to_string(), source })?;
        Self::from_bytes(&bytes)
    }

    /// Loads an exported RNN-GMM generator from the bytes of its file.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        let model = MotionModel::from_bytes(bytes)?;
        let proto = tract_onnx::pb::ModelProto::decode(bytes)
            .map_err(|e| MotionError::NotOnnx { origin: "the model bytes".into(), reason: e.to_string() })?;
        let meta = model.metadata();
        let Some(section) = proto.metadata_props.iter().find(|p| p.key == KEY) else {
            return Err(MotionError::WrongTask {
                task: meta.task.name().to_string(),
                kind: meta.model_kind.clone(),
                expected: "synthesis",
                loader: "SynthesisModel",
            });
        };
        let task: SynthesisTask = serde_json::from_str(&section.value).map_err(|e| bad(KEY, e.to_string()))?;
        task.check(meta.skeleton.len()).map_err(|r| bad(KEY, r))?;
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
        let Some(norm) = meta.normalization.get("x").filter(|n| n.mean.len() == d) else {
            return Err(bad(crate::metadata::keys::NORMALIZATION, format!("no group `x` of {d} values")));
        };
        let (mean, std) = (norm.mean.clone(), norm.std.clone());
        let references = task.references.iter().map(|q| DQuat::from_xyzw(q[0], q[1], q[2], q[3]).normalize()).collect();
        Ok(SynthesisModel { model, task, references, mean, std })
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
        SynthesisCharacter {
            state: self.model.new_state(),
            rng: SplitMix64::new(seed),
            x: vec![0.0; self.task.frame_dim],
            placement: [0.0; 3],
            started: false,
        }
    }

    /// A runner for one thread, with scratch space for batches of up to `max_batch` characters.
    pub fn runner(&self, max_batch: usize) -> Result<SynthesisRunner, MotionError> {
        let n = max_batch.max(1);
        let (d, m) = (self.task.frame_dim, self.task.components);
        Ok(SynthesisRunner {
            model: self.clone(),
            runner: self.model.runner()?,
            x: vec![0.0; n * d],
            weights: vec![0.0; n * m],
            means: vec![0.0; n * m * d],
            stds: vec![0.0; n * m * d],
            states: Vec::with_capacity(n),
            world: vec![Quat::IDENTITY; self.references.len()],
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
        Ok(())
    }

    /// The state of the character's random numbers (`SplitMix64::from_state` restores it).
    pub fn rng_state(&self) -> u64 {
        self.rng.state()
    }
}

/// Steps characters on one thread; allocates nothing per frame (up to the batch size it was
/// made for; a larger batch grows the scratch space once).
#[derive(Debug)]
pub struct SynthesisRunner {
    model: SynthesisModel,
    runner: MotionRunner,
    x: Vec<f32>,
    weights: Vec<f32>,
    means: Vec<f32>,
    stds: Vec<f32>,
    states: Vec<MotionState>,
    world: Vec<Quat>,
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
                return Err(bad(KEY, format!("character {c} was not started: call SynthesisCharacter::start first")));
            }
            check_len("pose local_rotations", pose.local_rotations.len(), 1, joints)?;
        }
        if self.x.len() < n * d {
            self.x.resize(n * d, 0.0);
            self.weights.resize(n * m, 0.0);
            self.means.resize(n * m * d, 0.0);
            self.stds.resize(n * m * d, 0.0);
        }
        for (c, ch) in characters.iter().enumerate() {
            self.x[c * d..(c + 1) * d].copy_from_slice(&ch.x);
        }
        // The characters' states, moved into one slice for the batched run and back.
        self.states.clear();
        for ch in characters.iter_mut() {
            self.states.push(std::mem::replace(&mut ch.state, MotionState { slots: Vec::new() }));
        }
        let run = self.runner.step_batch(
            &mut self.states,
            &[&self.x[..n * d]],
            &mut [&mut self.weights[..n * m], &mut self.means[..n * m * d], &mut self.stds[..n * m * d]],
        );
        for (ch, state) in characters.iter_mut().zip(self.states.drain(..)) {
            ch.state = state;
        }
        run?;
        for (c, ch) in characters.iter_mut().enumerate() {
            let w = &self.weights[c * m..(c + 1) * m];
            let (mu, sd) = (&self.means[c * m * d..(c + 1) * m * d], &self.stds[c * m * d..(c + 1) * m * d]);
            // A component by its weight, then mu + temperature * sigma * n (Mixture::sample).
            let u = ch.rng.next_f64();
            let (mut acc, mut k) = (0.0, m - 1);
            for (i, wi) in w.iter().enumerate() {
                acc += *wi as f64;
                if u < acc {
                    k = i;
                    break;
                }
            }
            for j in 0..d {
                let z = ch.rng.normal();
                ch.x[j] = (mu[k * d + j] as f64 + temperature as f64 * sd[k * d + j] as f64 * z) as f32;
            }
            contacts[c] = self.decode(ch, &mut poses[c]);
        }
        Ok(())
    }

    /// Decodes the character's (new) current frame into `pose`, advancing its placement.
    fn decode(&mut self, ch: &mut SynthesisCharacter, pose: &mut EnginePose) -> [bool; 2] {
        let model = &self.model;
        let d = model.task.frame_dim;
        let v = |i: usize| (ch.x[i] * model.std[i] + model.mean[i]) as f64;
        let [px, pz, yaw] = ch.placement;
        let step = DQuat::from_rotation_y(yaw) * DVec3::new(v(0), 0.0, v(1));
        ch.placement = [px + step.x, pz + step.z, yaw + v(2)];
        pose.root_position = Vec3::new(ch.placement[0] as f32, 0.0, ch.placement[1] as f32);
        pose.root_rotation = Quat::from_rotation_y(ch.placement[2] as f32);
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
            self.world[0] = pose.root_rotation * pose.local_rotations[0];
            pose.global_positions[0] = pose.root_position + pose.root_rotation * pose.hips_position;
            for j in 1..model.joints() {
                let p = skeleton.parents[j] as usize;
                pose.global_positions[j] = pose.global_positions[p] + self.world[p] * skeleton.offset(j);
                self.world[j] = self.world[p] * pose.local_rotations[j];
            }
        }
        [v(d - 2) > 0.5, v(d - 1) > 0.5]
    }
}
