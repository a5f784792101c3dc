//! Reference vectors for implementers in other languages: a few deterministic inputs for a
//! loaded model and what this runtime computes from them, step by step, as plain numbers
//! ([`ReferenceVectors`], written as JSON by `zoo export --onnx RUN --reference FILE.json`). An
//! implementation of docs/runtime-protocol.md on another inference engine reproduces every number
//! within the tolerance that page states; `scripts/runtime_protocol.py` is one, checked by
//! `tests/protocol.rs`.
//!
//! The inputs derive from the model's own metadata and [`SplitMix64`] seeded with the given seed:
//! transition poses walk at 0.8 to 1.6 m/s in the model's units (`zoo.frame`) and frame rate
//! (`zoo.fps`) on the model's skeleton with smoothly swinging joints; stitching poses move as
//! the pose-vector statistics say (mean root motion, hips height and joint rotations, the
//! rotations jittered by their deviations); keys are the normalization means plus seeded
//! multiples of the deviations (a humanoid's root walks from key to key and its rotations are
//! unit quaternions); synthesis start frames likewise. The same model and seed give the same
//! file.
//!
//! What each task's cases hold (every value in the model's units, `f32` unless said; rotations
//! are quaternions `[x, y, z, w]`; poses are [`ReferencePose`]s):
//! - transition: engine-pose inputs and their global positions, then for each of the `N + 1`
//!   frames the network's raw frame (before the target blend), the target-blended frame, the
//!   target miss, the frames of `generate` with a fallback and its weight, and the engine poses
//!   of `step_posed`;
//! - keyframes, either design: key sets (whole keys; partial keys when the model has groups);
//!   for the ARNN's step graph the key interval and `t_rel` of every frame, for the
//!   in-betweening design the whole-shot graph's features and the keys' Bezier poses (`f64`);
//!   the network's completion, the completion with every key hit, and the final poses (after
//!   the foot lock between the keys, for a humanoid with legs);
//! - stitch: an aligned sequence of engine poses with a pop in its middle, refined with the
//!   file's settings; the same sequence with the pop given as a seam (inertialized before
//!   encoding) and a fallback around the windows'
//!   corrections. Each case: its pose vectors, every window's correction size and fallback
//!   weight, the first window's normalised input and raw graph output, the refined pose
//!   vectors and the refined engine poses (no foot cleanup, no seam guard);
//! - synthesis: a seeded character's start (a full 64-bit seed), and for every step its input
//!   frame, the mixture, the sampled frame, the random generator's state, the refined frame
//!   (with a refiner), the engine pose with global positions and the contacts.

use crate::error::MotionError;
use crate::keyframes::{KeyframeModel, MotionKeys};
use crate::loaded::LoadedModel;
use crate::metadata::{MotionModelMetadata, MotionTaskKind, StitchFallback, TransitionFallback};
use crate::pose::EnginePose;
use crate::stitch::{FootCleanup, StitchRefiner};
use crate::synthesis::SynthesisModel;
use crate::transition::{Heightmap, TransitionModel};
use glam::{DQuat, DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};
use std::sync::Arc;
use zoo_motion::quat::from_scaled_axis;
use zoo_motion::rng::SplitMix64;

/// `format` of a reference file.
pub const REFERENCE_FORMAT: &str = "zoo-reference-vectors";
/// `version` of the reference files this release writes.
pub const REFERENCE_VERSION: u32 = 2;
/// The seed `zoo export --reference` uses.
pub const REFERENCE_SEED: u64 = 1;

/// Reference vectors of one model: its task's cases (the lists of the other tasks are empty
/// and left out of the JSON).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceVectors {
    /// [`REFERENCE_FORMAT`].
    pub format: String,
    /// [`REFERENCE_VERSION`].
    pub version: u32,
    /// The model's kind (`zoo.model_kind`).
    pub model_kind: String,
    /// The model's task (`zoo.task`).
    pub task: MotionTaskKind,
    /// The seed the inputs were drawn with.
    pub seed: u64,
    /// Cases of a `transition` model.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transition: Vec<TransitionCase>,
    /// Cases of a `keyframes` model.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keyframes: Vec<KeyframesCase>,
    /// Cases of a `stitch` model.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stitch: Vec<StitchCase>,
    /// Cases of a `synthesis` model.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub synthesis: Vec<SynthesisCase>,
}

/// An [`EnginePose`] as plain arrays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferencePose {
    /// [`EnginePose::root_position`].
    pub root_position: [f32; 3],
    /// [`EnginePose::root_rotation`], `[x, y, z, w]`.
    pub root_rotation: [f32; 4],
    /// [`EnginePose::root_delta_position`].
    pub root_delta_position: [f32; 3],
    /// [`EnginePose::root_delta_yaw`], radians.
    pub root_delta_yaw: f32,
    /// [`EnginePose::hips_position`].
    pub hips_position: [f32; 3],
    /// [`EnginePose::local_rotations`], `[x, y, z, w]` per joint.
    pub local_rotations: Vec<[f32; 4]>,
    /// [`EnginePose::global_positions`] (empty where the task gives none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub global_positions: Vec<[f32; 3]>,
}

impl From<&EnginePose> for ReferencePose {
    fn from(p: &EnginePose) -> Self {
        ReferencePose {
            root_position: p.root_position.to_array(),
            root_rotation: p.root_rotation.to_array(),
            root_delta_position: p.root_delta_position.to_array(),
            root_delta_yaw: p.root_delta_yaw,
            hips_position: p.hips_position.to_array(),
            local_rotations: p.local_rotations.iter().map(|q| q.to_array()).collect(),
            global_positions: p.global_positions.iter().map(|v| v.to_array()).collect(),
        }
    }
}

impl ReferencePose {
    /// The engine pose (global positions when the reference has them).
    pub fn to_engine_pose(&self) -> EnginePose {
        EnginePose {
            root_position: Vec3::from_array(self.root_position),
            root_rotation: Quat::from_array(self.root_rotation),
            root_delta_position: Vec3::from_array(self.root_delta_position),
            root_delta_yaw: self.root_delta_yaw,
            hips_position: Vec3::from_array(self.hips_position),
            local_rotations: self.local_rotations.iter().map(|q| Quat::from_array(*q)).collect(),
            global_positions: self.global_positions.iter().map(|v| Vec3::from_array(*v)).collect(),
        }
    }
}

/// The target miss of a transition (the network's target frame against the requested one).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceMiss {
    /// Mean over joints of the distance.
    pub mean: f32,
    /// Largest distance over joints.
    pub max: f32,
}

/// One transition: the inputs and every frame the runtime computes. Positions are global joint
/// positions, `3K` values per frame, joint-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransitionCase {
    /// What the case exercises.
    pub name: String,
    /// Transition length `N`: frames `0..N` lead to the target frame `N`.
    pub length: usize,
    /// The context as engine poses (the input of `start_posed`).
    pub past_poses: Vec<ReferencePose>,
    /// The target pose.
    pub target_pose: ReferencePose,
    /// The pose after the target.
    pub next_pose: ReferencePose,
    /// Global positions of `past_poses` (forward kinematics over the model's skeleton): the
    /// input of `start`.
    pub past: Vec<Vec<f32>>,
    /// Global positions of `target_pose`.
    pub target: Vec<f32>,
    /// Global positions of `next_pose`.
    pub next: Vec<f32>,
    /// The ground under the character, for a terrain-aware model (`null` otherwise).
    pub heightmap: Option<Heightmap>,
    /// The network's raw frames `p_0 ..= p_N` (`step_raw`): before the target blend.
    pub raw: Vec<Vec<f32>>,
    /// The target-blended frames (`step`): `blended[N]` is the target.
    pub blended: Vec<Vec<f32>>,
    /// How far `raw[N]` lies from the target.
    pub miss: ReferenceMiss,
    /// The fallback thresholds `generate` applied (`null`: none).
    pub fallback: Option<TransitionFallback>,
    /// The interpolation's weight in `frames` (0 without fallback).
    pub fallback_weight: f32,
    /// The frames of `generate` with `fallback` (no foot lock).
    pub frames: Vec<Vec<f32>>,
    /// The frames of `step_posed` (a transition started with `start_posed` from the poses
    /// above), with global positions; empty when the model's skeleton has a joint whose
    /// children's rest offsets lie on one line (the rotation fit leaves their twist to float
    /// rounding there, docs/runtime-protocol.md).
    pub posed: Vec<ReferencePose>,
}

/// One frame's keys: the interval around frame `t` and the time in it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceInterval {
    /// The frame, `1..=last key frame`.
    pub t: usize,
    /// Index of the key before (`key_a`).
    pub a: usize,
    /// Index of the key after (`key_b`).
    pub b: usize,
    /// `(t - T_a) / (T_b - T_a)`.
    pub t_rel: f32,
}

/// One key set completed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyframesCase {
    /// What the case exercises.
    pub name: String,
    /// Key frames, strictly increasing from 0.
    pub key_frames: Vec<usize>,
    /// One pose per key (`dofs` values each).
    pub key_poses: Vec<Vec<f32>>,
    /// Partial keys: the groups each key fixes (1) or leaves free (0); empty for whole keys.
    pub fixed: Vec<Vec<f32>>,
    /// The ARNN's step graph: the keys fed at every frame after the first (empty for the
    /// in-betweening design).
    pub intervals: Vec<ReferenceInterval>,
    /// The in-betweening design: the whole-shot graph's input `features`, one row of
    /// `input_width` values per frame `0..=last key frame` (empty for the step graph).
    pub features: Vec<Vec<f32>>,
    /// The in-betweening design: the keys' Bezier poses, `dofs` values per frame, `f64` (empty
    /// for the step graph).
    pub bezier: Vec<Vec<f64>>,
    /// The network's completion, frames `0..=last key frame` (`dofs` values each): the step
    /// graph's poses after the first key, or the in-betweening design's Bezier poses with the
    /// graph's correction composed; no key hit, no foot lock.
    pub network: Vec<Vec<f32>>,
    /// `network` with every key hit.
    pub hit: Vec<Vec<f32>>,
    /// Whether the runtime locks the feet between the keys (a humanoid pose on a skeleton
    /// with legs).
    pub foot_lock: bool,
    /// The completed poses the runtime gives: `hit`, with the feet locked between the keys
    /// when `foot_lock`.
    pub poses: Vec<Vec<f32>>,
}

/// The first window of a stitched sequence through the graph.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceWindow {
    /// First frame of the window.
    pub start: usize,
    /// The graph's input: the window's pose vectors, normalised (`window` frames).
    pub input: Vec<Vec<f32>>,
    /// The graph's output `y`, normalised, contacts as logits.
    pub output: Vec<Vec<f32>>,
}

/// One window of a stitched sequence: how much the graph changed it and the fallback's weight.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceWindowRun {
    /// First frame of the window.
    pub start: usize,
    /// The correction size of the graph's output against its input (normalised units, RMS over
    /// the pose values).
    pub correction: f32,
    /// The fallback's weight on the window (0 without a fallback).
    pub weight: f32,
}

/// One aligned sequence refined.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StitchCase {
    /// What the case exercises.
    pub name: String,
    /// Window and stride the sequence was refined with.
    pub window: usize,
    /// See `window`.
    pub stride: usize,
    /// Frames over which each window's first-frame difference is blended away, and of the
    /// seams' inertialization.
    pub blend_frames: usize,
    /// The aligned sequence as engine poses (the input of `refine_poses_at_seams`).
    pub input_poses: Vec<ReferencePose>,
    /// The frames where a clip starts (empty: none given).
    pub seams: Vec<usize>,
    /// Whether the seams were inertialized before encoding (whenever seams are given).
    pub pre_blend: bool,
    /// The fallback towards the refiner's input every window got (`null`: none).
    pub fallback: Option<StitchFallback>,
    /// The raw pose vectors of `input_poses`, inertialized at the seams when `pre_blend`
    /// (`encode_poses_at_seams`; the input of `refine_sequence`).
    pub sequence: Vec<Vec<f32>>,
    /// First frame of every window, in the order they run.
    pub window_starts: Vec<usize>,
    /// Every window, in the order they run.
    pub windows: Vec<ReferenceWindowRun>,
    /// The first window through the graph.
    pub first_window: ReferenceWindow,
    /// The refined raw pose vectors (`refine_sequence`), contacts 0 or 1.
    pub refined: Vec<Vec<f32>>,
    /// The refined engine poses (`refine_poses_at_seams` without ankle placement, seam guard,
    /// foot lock and seams' reach).
    pub poses: Vec<ReferencePose>,
    /// The predicted contacts per frame: left heel, left toe, right heel, right toe.
    pub contacts: Vec<[bool; 4]>,
}

/// One generated frame of a synthesis case.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthesisStep {
    /// The step graph's input `x`, normalised.
    pub x: Vec<f32>,
    /// The mixture: `weights` (`M`).
    pub weights: Vec<f32>,
    /// `means` (`M D`, normalised).
    pub means: Vec<f32>,
    /// `stds` (`M D`, normalised).
    pub stds: Vec<f32>,
    /// The frame drawn from the mixture, normalised (the next step's `x`).
    pub sampled: Vec<f32>,
    /// The character's random generator state after the draw.
    pub rng_state: u64,
    /// The refined frame, normalised (`null` without refiner).
    pub refined: Option<Vec<f32>>,
    /// The decoded engine pose, with global positions.
    pub pose: ReferencePose,
    /// Contacts `[left, right]`.
    pub contacts: [bool; 2],
}

/// One seeded character's frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthesisCase {
    /// What the case exercises.
    pub name: String,
    /// The character's seed (`SplitMix64::new(seed)`), any 64-bit value.
    pub seed: u64,
    /// The scale on the mixture's standard deviations.
    pub temperature: f32,
    /// Whether frames went through the file's refiner.
    pub refined: bool,
    /// The start frame, in model units (not normalised).
    pub start_frame: Vec<f32>,
    /// Start placement: ground x, z and yaw (radians about +Y).
    pub start_placement: [f32; 3],
    /// Every step.
    pub steps: Vec<SynthesisStep>,
}

/// The reference vectors of `model` from inputs drawn with `seed` (see the module doc).
pub fn reference_vectors(model: &LoadedModel, seed: u64) -> Result<ReferenceVectors, MotionError> {
    let metadata = model.metadata();
    let mut out = ReferenceVectors {
        format: REFERENCE_FORMAT.to_string(),
        version: REFERENCE_VERSION,
        model_kind: metadata.model_kind.clone(),
        task: model.task(),
        seed,
        transition: Vec::new(),
        keyframes: Vec::new(),
        stitch: Vec::new(),
        synthesis: Vec::new(),
    };
    let mut rng = SplitMix64::new(seed);
    match model {
        LoadedModel::Transition(m) => out.transition = transition_cases(m, &mut rng)?,
        LoadedModel::Keyframes(m) => out.keyframes = keyframes_cases(m, &mut rng)?,
        LoadedModel::Stitch(m) => out.stitch = stitch_cases(m, &mut rng)?,
        LoadedModel::Synthesis(m) => out.synthesis = synthesis_cases(m, &mut rng)?,
    }
    Ok(out)
}

/// Refuses a non-finite value (JSON has none; a reference of NaN checks nothing).
fn finite(what: &str, values: &[f32]) -> Result<(), MotionError> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(MotionError::Run {
            reason: format!(
                "{what}: value {i} is {}; reference vectors hold finite numbers only (the model diverges on these \
                 inputs: check its weights and normalization)",
                values[i]
            ),
        }),
    }
}

fn rows(flat: &[f32], width: usize) -> Vec<Vec<f32>> {
    flat.chunks_exact(width).map(<[f32]>::to_vec).collect()
}

fn pose_values(p: &EnginePose) -> impl Iterator<Item = f32> + '_ {
    let head = [p.root_position.to_array(), p.root_delta_position.to_array(), p.hips_position.to_array()];
    head.into_iter()
        .flatten()
        .chain(p.root_rotation.to_array())
        .chain([p.root_delta_yaw])
        .chain(p.local_rotations.iter().flat_map(|q| q.to_array()))
        .chain(p.global_positions.iter().flat_map(|v| v.to_array()))
}

fn reference_pose(what: &str, p: &EnginePose) -> Result<ReferencePose, MotionError> {
    finite(what, &pose_values(p).collect::<Vec<_>>())?;
    Ok(ReferencePose::from(p))
}

/// Model units per metre.
fn units_per_metre(m: &MotionModelMetadata) -> f64 {
    1.0 / m.frame.metres_per_unit as f64
}

/// How a seeded motion moves: root speed and turn per frame, hips height, and per joint a rest
/// rotation with two kinds of swing about it: a rotation vector of up to `amplitude` radians
/// per component, and a perturbation of the quaternion's components of up to `jitter` each
/// (then normalised).
struct MotionStyle {
    speed: DVec3,
    turn: f64,
    height: f64,
    rest: Vec<DQuat>,
    amplitude: Vec<f64>,
    jitter: Vec<[f64; 4]>,
}

impl MotionStyle {
    /// A walk at 0.8 to 1.6 m/s turning up to 0.5 rad/s in the model's units and frame rate,
    /// the hips at the rest pose's height, joints swinging up to 0.3 rad about the rest pose.
    fn walk(m: &MotionModelMetadata, rng: &mut SplitMix64) -> Self {
        let (unit, fps, joints) = (units_per_metre(m), m.fps as f64, m.skeleton.len());
        MotionStyle {
            speed: DVec3::new(0.0, 0.0, rng.range(0.8, 1.6) * unit / fps),
            turn: rng.range(-0.5, 0.5) / fps,
            height: hips_height(m),
            rest: vec![DQuat::IDENTITY; joints],
            amplitude: vec![0.3; joints],
            jitter: vec![[0.0; 4]; joints],
        }
    }

    /// The motion a stitching model was trained on, from its pose-vector statistics (group
    /// `x`): the mean root displacement per frame, the mean hips height, each joint's mean
    /// rotation with its quaternion components jittered by their deviations (at most 0.15), so
    /// that a hinge stays a hinge and the normalised inputs stay in the training range.
    fn stitch(refiner: &StitchRefiner, stats: &crate::metadata::MotionMeanStd) -> Self {
        let layout = refiner.layout();
        let fl = layout.pose_layout(refiner.joints());
        let (mean, std) = (&stats.mean, &stats.std);
        let hips = layout.lower_body.iter().position(|&j| j == 0).unwrap_or(0);
        let (rest, jitter) = (0..refiner.joints())
            .map(|j| {
                let q = &mean[fl.rotations() + 4 * j..][..4];
                let q = DQuat::from_xyzw(q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
                let q = if q.length() > 0.1 { q.normalize() } else { DQuat::IDENTITY };
                let s = &std[fl.rotations() + 4 * j..][..4];
                (q, std::array::from_fn(|c| (s[c] as f64).min(0.15)))
            })
            .unzip();
        MotionStyle {
            speed: DVec3::new(mean[0] as f64, 0.0, mean[2] as f64),
            turn: mean[1] as f64,
            height: mean[fl.positions() + 3 * hips + 1] as f64,
            rest,
            amplitude: vec![0.0; refiner.joints()],
            jitter,
        }
    }

    /// Joint `j`'s rotation for the swing value `w` (4 components in `-1.6..1.6`).
    fn rotation(&self, j: usize, w: [f64; 4]) -> DQuat {
        let a = self.amplitude[j];
        let q = self.rest[j] * from_scaled_axis(DVec3::new(a * w[0], a * w[1], a * w[2]));
        let e = &self.jitter[j];
        DQuat::from_xyzw(q.x + e[0] * w[0], q.y + e[1] * w[1], q.z + e[2] * w[2], q.w + e[3] * w[3]).normalize()
    }
}

/// The swing of the joints of a seeded motion: per joint a base, an amplitude and a phase,
/// 4 components each (in units of the style's amplitudes).
struct Swing {
    base: Vec<[f64; 4]>,
    amplitude: Vec<[f64; 4]>,
    phase: Vec<f64>,
}

impl Swing {
    fn new(rng: &mut SplitMix64, joints: usize) -> Self {
        let mut v = |a: f64| -> [f64; 4] { std::array::from_fn(|_| rng.range(-a, a)) };
        let mut base: Vec<[f64; 4]> = (0..joints).map(|_| v(0.6)).collect();
        let amplitude = (0..joints).map(|_| v(1.0)).collect();
        // The hips' own rotation leans (no yaw: the root carries the heading).
        base[0][1] = 0.0;
        let phase = (0..joints).map(|_| rng.range(0.0, TAU)).collect();
        Swing { base, amplitude, phase }
    }

    /// Joint `j`'s swing value at phase `t`.
    fn at(&self, j: usize, t: f64) -> [f64; 4] {
        let s = (t + self.phase[j]).sin();
        std::array::from_fn(|c| self.base[j][c] + self.amplitude[j][c] * s)
    }
}

/// Height of the hips above the ground in the rest pose: the depth of the lowest joint below
/// them (0.9 m when no joint hangs below the hips).
fn hips_height(m: &MotionModelMetadata) -> f64 {
    let s = &m.skeleton;
    let mut y = vec![0.0f64; s.len()];
    for j in 1..s.len() {
        y[j] = y[s.parents[j] as usize] + s.offsets[j][1];
    }
    let low = -y.iter().copied().fold(0.0, f64::min);
    if low > 0.1 * units_per_metre(m) { low } else { 0.9 * units_per_metre(m) }
}

/// A seeded motion on the model's skeleton in `style`: the root starts within a metre of the
/// origin facing a seeded heading and moves by the style's speed and turn, the hips bob by 2%,
/// every joint swings about its rest rotation at a gait frequency of 0.8 to 1.4 Hz. From frame
/// `pop` on (if given) the joints swing about other bases: a pop, as at the seam of two clips.
/// Root deltas are left zero (inputs do not read them).
fn seeded_motion(
    m: &MotionModelMetadata,
    style: &MotionStyle,
    frames: usize,
    pop: Option<usize>,
    rng: &mut SplitMix64,
) -> Vec<EnginePose> {
    let (unit, fps, joints) = (units_per_metre(m), m.fps as f64, m.skeleton.len());
    let yaw0 = rng.range(-PI, PI);
    let gait = TAU * rng.range(0.8, 1.4) / fps;
    let mut root = DVec3::new(rng.range(-1.0, 1.0) * unit, 0.0, rng.range(-1.0, 1.0) * unit);
    let before = Swing::new(rng, joints);
    let after = Swing::new(rng, joints);
    (0..frames)
        .map(|f| {
            let yaw = yaw0 + style.turn * f as f64;
            if f > 0 {
                root += DQuat::from_rotation_y(yaw) * style.speed;
            }
            let swing = if pop.is_some_and(|p| f >= p) { &after } else { &before };
            let t = gait * f as f64;
            let mut pose = EnginePose::new(joints);
            pose.root_position = root.as_vec3();
            pose.root_rotation = DQuat::from_rotation_y(yaw).as_quat();
            pose.hips_position = Vec3::new(0.0, (style.height * (1.0 + 0.02 * (2.0 * t).sin())) as f32, 0.0);
            for (j, q) in pose.local_rotations.iter_mut().enumerate() {
                *q = style.rotation(j, swing.at(j, t)).as_quat();
            }
            pose
        })
        .collect()
}

/// Global joint positions of `pose` over the model's skeleton, in `f64` from the pose's `f32`
/// values, as `TransitionRunner::start_posed` computes them.
fn pose_positions(m: &MotionModelMetadata, pose: &EnginePose) -> Vec<f32> {
    let s = &m.skeleton;
    let k = s.len();
    let (mut rot, mut pos) = (vec![DQuat::IDENTITY; k], vec![DVec3::ZERO; k]);
    for j in 0..k {
        if j == 0 {
            rot[0] = pose.hips_world_rotation().as_dquat();
            pos[0] = pose.hips_world().as_dvec3();
        } else {
            let p = s.parents[j] as usize;
            pos[j] = rot[p] * DVec3::from_array(s.offsets[j]) + pos[p];
            rot[j] = rot[p] * pose.local_rotations[j].as_dquat();
        }
    }
    pos.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()
}

/// Whether the rotation fit of posed transitions is defined by positions on this skeleton: no
/// joint has two or more children whose rest offsets all lie on one line (e.g. a spine straight
/// up and a single leg straight down from the hips). At such a joint the children's positions
/// leave the twist about that line free, and the fit's eigenvector then depends on float
/// rounding: no other implementation can reproduce it, so the reference leaves `posed` empty.
fn fit_is_defined(m: &MotionModelMetadata) -> bool {
    let s = &m.skeleton;
    (0..s.len()).all(|j| {
        let children: Vec<DVec3> = (0..s.len())
            .filter(|&c| s.parents[c] == j as i32)
            .map(|c| DVec3::from_array(s.offsets[c]))
            .filter(|o| o.length() > 1e-9)
            .collect();
        children.len() < 2
            || children.iter().any(|a| children.iter().any(|b| a.cross(*b).length() > 1e-3 * a.length() * b.length()))
    })
}

/// A seeded heightmap around a motion: a gentle slope with bumps, in the model's units.
fn seeded_heightmap(m: &MotionModelMetadata, poses: &[EnginePose], extent: f32, rng: &mut SplitMix64) -> Heightmap {
    let unit = units_per_metre(m);
    let margin = extent as f64 + 0.5 * unit;
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in poses {
        let r = p.root_position.as_dvec3();
        lo = lo.min(r);
        hi = hi.max(r);
    }
    let (sx, sz) = (rng.range(-0.05, 0.05), rng.range(-0.05, 0.05));
    let (bump, wave) = (rng.range(0.01, 0.05) * unit, TAU / (rng.range(0.5, 1.5) * unit));
    let (cx, cz) = (lo.x, lo.z);
    Heightmap::from_fn(lo.x - margin, lo.z - margin, hi.x + margin, hi.z + margin, 0.1 * unit, |x, z| {
        sx * (x - cx) + sz * (z - cz) + bump * (wave * x).sin() * (wave * z).cos()
    })
}

fn transition_cases(model: &TransitionModel, rng: &mut SplitMix64) -> Result<Vec<TransitionCase>, MotionError> {
    let m = model.model().metadata();
    let (p, trained) = (model.past_frames(), model.transition_frames());
    let mut cases = Vec::new();
    // The trained length with the file's own fallback; then half of it with a seam at the
    // target and thresholds around its miss, so that the fallback weight is 1/3.
    for (name, length, pop) in [
        ("continuous motion, the trained length, the file's fallback if any", trained, false),
        (
            "a pop at the target, half the trained length, a fallback from half to twice its miss",
            trained.div_ceil(2),
            true,
        ),
    ] {
        let style = MotionStyle::walk(m, rng);
        let poses = seeded_motion(m, &style, p + length + 2, pop.then_some(p + length), rng);
        let heightmap = model.terrain().map(|(_, extent)| seeded_heightmap(m, &poses, extent, rng));
        let case = transition_case(model, name, length, &poses, heightmap, pop)?;
        cases.push(case);
    }
    Ok(cases)
}

fn transition_case(
    model: &TransitionModel,
    name: &str,
    length: usize,
    poses: &[EnginePose],
    heightmap: Option<Heightmap>,
    thresholds_around_miss: bool,
) -> Result<TransitionCase, MotionError> {
    let m = model.model().metadata();
    let (p, d) = (model.past_frames(), 3 * model.joints());
    let (past_poses, target_pose, next_pose) = (&poses[..p], &poses[p + length], &poses[p + length + 1]);
    let past: Vec<f32> = past_poses.iter().flat_map(|q| pose_positions(m, q)).collect();
    let (target, next) = (pose_positions(m, target_pose), pose_positions(m, next_pose));
    let ground = heightmap.clone().map(Arc::new);
    let mut runner = model.runner()?;
    let new_state = || {
        let mut s = model.new_transition();
        s.set_heightmap(ground.clone());
        s
    };
    let steps = length + 1;
    let mut frame = vec![0.0f32; d];
    let (mut raw, mut blended) = (Vec::with_capacity(steps), Vec::with_capacity(steps));
    let mut state = new_state();
    runner.start_for(&mut state, &past, &target, &next, length)?;
    for _ in 0..steps {
        runner.step_raw(&mut state, &mut frame)?;
        finite("a raw transition frame", &frame)?;
        raw.push(frame.clone());
    }
    let mut state = new_state();
    runner.start_for(&mut state, &past, &target, &next, length)?;
    for _ in 0..steps {
        runner.step(&mut state, &mut frame)?;
        finite("a blended transition frame", &frame)?;
        blended.push(frame.clone());
    }
    let miss = state.target_miss().ok_or_else(|| MotionError::Run {
        reason: "the finished transition has no target miss; this is a bug, please report it".into(),
    })?;
    let fallback = if thresholds_around_miss {
        Some(TransitionFallback { start: 0.5 * miss.mean, full: 2.0 * miss.mean })
    } else {
        model.default_fallback_for(length)
    };
    runner.set_fallback(fallback);
    let mut state = new_state();
    let mut frames = vec![0.0f32; steps * d];
    runner.generate(&mut state, &past, &target, &next, &mut frames)?;
    finite("a generated transition frame", &frames)?;
    let fallback_weight = state.fallback_weight();
    let mut posed = Vec::with_capacity(steps);
    if fit_is_defined(m) {
        let mut state = new_state();
        runner.start_posed_batch_for(
            std::slice::from_mut(&mut state),
            past_poses,
            std::slice::from_ref(target_pose),
            std::slice::from_ref(next_pose),
            length,
        )?;
        let mut pose = EnginePose::with_global_positions(model.joints());
        for _ in 0..steps {
            runner.step_posed(&mut state, &mut pose)?;
            posed.push(reference_pose("a posed transition frame", &pose)?);
        }
    }
    let inputs = past_poses.iter().chain([target_pose, next_pose]);
    let inputs = inputs.map(|q| reference_pose("an input pose", q)).collect::<Result<Vec<_>, _>>()?;
    Ok(TransitionCase {
        name: name.to_string(),
        length,
        past_poses: inputs[..p].to_vec(),
        target_pose: inputs[p].clone(),
        next_pose: inputs[p + 1].clone(),
        past: rows(&past, d),
        target,
        next,
        heightmap,
        raw,
        blended,
        miss: ReferenceMiss { mean: miss.mean, max: miss.max },
        fallback,
        fallback_weight,
        frames: rows(&frames, d),
        posed,
    })
}

/// Whether a keyframe model's pose is the humanoid pose vector (root position, then one
/// quaternion per joint of its skeleton, one key group each).
fn is_humanoid(model: &KeyframeModel) -> bool {
    let j = model.metadata().skeleton.len();
    model.groups() == 1 + j && model.dofs() == zoo_protocol::inbetween::dofs(j)
}

/// Whether the runtime locks the feet of this keyframe model's completions: a humanoid pose on
/// a skeleton with legs (joints named `foot`, [`zoo_protocol::footlock::FootLock::from_skeleton`]).
fn locks_feet(model: &KeyframeModel) -> bool {
    let s = &model.metadata().skeleton;
    let parents: Vec<Option<usize>> = s.parents.iter().map(|&p| usize::try_from(p).ok()).collect();
    is_humanoid(model) && zoo_protocol::footlock::FootLock::from_skeleton(&s.names, &parents).is_some()
}

/// Seeded key poses, `keys * dofs` values: the `pose` group's means plus seeded multiples of
/// its deviations. A humanoid's root walks at 0.8 to 1.6 m/s on a seeded heading from key to
/// key (its height within 0.3 deviations of the mean), and each joint's quaternion is its mean
/// jittered by half its deviations, normalised.
fn seeded_keys(model: &KeyframeModel, frames: &[usize], rng: &mut SplitMix64) -> Vec<f32> {
    let m = model.metadata();
    let d = model.dofs();
    // Keys around the poses the model was trained on (0 and 1 for a file without the group).
    let (mean, std) = match m.normalization.get("pose").filter(|s| s.mean.len() == d && s.std.len() == d) {
        Some(s) => (s.mean.clone(), s.std.clone()),
        None => (vec![0.0; d], vec![1.0; d]),
    };
    if !is_humanoid(model) {
        let n = frames.len();
        return (0..n * d).map(|i| mean[i % d] + std[i % d] * rng.range(-1.0, 1.0) as f32).collect();
    }
    let (mean, std): (Vec<f64>, Vec<f64>) =
        (mean.iter().map(|v| *v as f64).collect(), std.iter().map(|v| *v as f64).collect());
    let heading = rng.range(-PI, PI);
    let speed = rng.range(0.8, 1.6) * units_per_metre(m) / m.fps as f64;
    let start = [mean[0] + 0.5 * std[0] * rng.range(-1.0, 1.0), mean[2] + 0.5 * std[2] * rng.range(-1.0, 1.0)];
    let mut out = Vec::with_capacity(frames.len() * d);
    for &f in frames {
        let walked = speed * f as f64;
        out.extend([
            start[0] + walked * heading.sin(),
            mean[1] + 0.3 * std[1] * rng.range(-1.0, 1.0),
            start[1] + walked * heading.cos(),
        ]);
        for q in (3..d).step_by(4) {
            let v: [f64; 4] = std::array::from_fn(|c| mean[q + c] + 0.5 * std[q + c] * rng.range(-1.0, 1.0));
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            out.extend(if n > 1e-6 { v.map(|x| x / n) } else { [1.0, 0.0, 0.0, 0.0] });
        }
    }
    out.into_iter().map(|v| v as f32).collect()
}

fn keyframes_cases(model: &KeyframeModel, rng: &mut SplitMix64) -> Result<Vec<KeyframesCase>, MotionError> {
    let (d, g) = (model.dofs(), model.groups());
    let humanoid = is_humanoid(model);
    // A humanoid's keys lie further apart: time for the feet to plant and lift between them.
    let sets: Vec<(&str, Vec<usize>, bool)> = if humanoid {
        vec![
            ("four whole keys", vec![0, 8, 20, 33], false),
            ("two whole keys", vec![0, 15], false),
            ("partial keys", vec![0, 9, 21, 30], true),
        ]
    } else {
        let mut sets = vec![("four whole keys", vec![0, 5, 12, 20], false), ("two whole keys", vec![0, 9], false)];
        if g > 0 {
            sets.push(("partial keys", vec![0, 6, 14, 22], true));
        }
        sets
    };
    let inbetween = match model.metadata().task.as_keyframes().and_then(|t| t.inbetween.as_ref()) {
        Some(section) => Some(section.features().map_err(|reason| MotionError::Run { reason })?),
        None => None,
    };
    let foot_lock = locks_feet(model);
    let mut runner = model.runner(1)?;
    let mut cases = Vec::new();
    for (name, key_frames, partial) in sets {
        let n = key_frames.len();
        let poses = seeded_keys(model, &key_frames, rng);
        let mut fixed = Vec::new();
        if partial {
            fixed = vec![1.0f32; n * g];
            for k in 1..n {
                let row = &mut fixed[k * g..(k + 1) * g];
                for v in row.iter_mut() {
                    *v = if rng.next_f64() < 0.5 { 0.0 } else { 1.0 };
                }
                if !row.contains(&1.0) {
                    row[rng.below(g as u64) as usize] = 1.0;
                }
            }
        }
        let keys = MotionKeys { frames: &key_frames, poses: &poses, fixed: &fixed };
        let len = keys.len() * d;
        let mut complete = |hit: bool, lock: bool| -> Result<Vec<f32>, MotionError> {
            runner.set_hit_keys(hit);
            runner.set_foot_lock(lock);
            let mut out = vec![0.0f32; len];
            runner.complete(keys, &mut out)?;
            finite("a completed pose", &out)?;
            Ok(out)
        };
        let (network, hit, out) = (complete(false, false)?, complete(true, false)?, complete(true, true)?);
        let (mut features, mut bezier, mut intervals) = (Vec::new(), Vec::new(), Vec::new());
        if let Some(f) = &inbetween {
            // The whole-shot graph's input, built as the runtime builds it (f32 keys as f64).
            let poses: Vec<f64> = poses.iter().map(|v| *v as f64).collect();
            let flags: Vec<bool> = fixed.iter().map(|v| *v == 1.0).collect();
            let shot = f
                .shot(&key_frames, &poses, &flags)
                .map_err(|e| MotionError::Keys { character: 0, reason: e.to_string() })?;
            features = rows(&shot.features, f.input_width());
            bezier = shot.bezier.chunks_exact(d).map(<[f64]>::to_vec).collect();
        } else {
            intervals = (1..keys.len())
                .map(|t| {
                    let (a, b, t_rel) = keys.interval(t);
                    ReferenceInterval { t, a, b, t_rel }
                })
                .collect();
        }
        cases.push(KeyframesCase {
            name: name.to_string(),
            key_frames: key_frames.clone(),
            key_poses: rows(&poses, d),
            fixed: if partial { rows(&fixed, g) } else { Vec::new() },
            intervals,
            features,
            bezier,
            network: rows(&network, d),
            hit: rows(&hit, d),
            foot_lock,
            poses: rows(&out, d),
        });
    }
    Ok(cases)
}

/// The windows of `refine_sequence` on `sequence` (raw pose vectors), run one by one as it runs
/// them: the refined sequence, every window's correction size and fallback weight, and the
/// first window's input and raw output.
type WindowRuns = (Vec<f32>, Vec<ReferenceWindowRun>, ReferenceWindow);

fn run_windows(refiner: &StitchRefiner, sequence: &[f32]) -> Result<WindowRuns, MotionError> {
    let (w, d, blend) = (refiner.window(), refiner.dim(), refiner.blend_frames());
    let pose = d - 4;
    let stats = refiner.metadata().group("x", d)?;
    let mut x = sequence.to_vec();
    for row in x.chunks_exact_mut(d) {
        stats.normalize(row);
    }
    let (mut runs, mut first) = (Vec::new(), None);
    let mut y = vec![0.0f32; w * d];
    for ws in refiner.window_starts(sequence.len() / d) {
        let input = x[ws * d..(ws + w) * d].to_vec();
        refiner.refine_window_normalized(&input, &mut y)?;
        finite("a window's output", &y)?;
        if first.is_none() {
            first = Some(ReferenceWindow { start: ws, input: rows(&input, d), output: rows(&y, d) });
        }
        let correction = crate::metadata::stitch::correction_size(&input, &y, d, pose);
        let weight = refiner.fallback().map_or(0.0, |f| f.apply(&input, &mut y, d, pose));
        if ws > 0 {
            // The previous output at the window's first frame against the new one.
            let offset: Vec<f32> = (0..pose).map(|i| input[i] - y[i]).collect();
            for k in 0..blend.min(w) {
                let a = 1.0 - k as f32 / blend as f32;
                for (v, o) in y[k * d..k * d + pose].iter_mut().zip(&offset) {
                    *v += a * o;
                }
            }
        }
        for row in y.chunks_exact_mut(d) {
            for c in &mut row[pose..] {
                *c = if *c > 0.0 { 1.0 } else { 0.0 };
            }
        }
        x[ws * d..(ws + w) * d].copy_from_slice(&y);
        runs.push(ReferenceWindowRun { start: ws, correction, weight });
    }
    for row in x.chunks_exact_mut(d) {
        for ((v, m), s) in row.iter_mut().zip(&stats.mean).zip(&stats.std) {
            *v = *v * s + m;
        }
        for c in &mut row[pose..] {
            *c = if *c > 0.5 { 1.0 } else { 0.0 };
        }
    }
    let first = first.ok_or_else(|| MotionError::Run { reason: "a sequence shorter than the window".into() })?;
    Ok((x, runs, first))
}

fn stitch_cases(refiner: &StitchRefiner, rng: &mut SplitMix64) -> Result<Vec<StitchCase>, MotionError> {
    let m = refiner.metadata();
    let (w, s, d) = (refiner.window(), refiner.stride(), refiner.dim());
    // Two regular windows and one more ending on the last frame.
    let frames = w + s + s.div_ceil(2).max(1);
    let stats = m.group("x", d)?;
    let pop = frames / 2;
    let input = seeded_motion(m, &MotionStyle::stitch(refiner, stats), frames, Some(pop), rng);
    let file = stitch_case(
        refiner,
        "an aligned sequence with a pop in its middle, the file's settings",
        &input,
        &[],
        refiner.fallback(),
    )?;
    // Thresholds around the windows' corrections of the seam case, so that the fallback's
    // weights lie between 0 and 1.
    let mut bare = refiner.clone();
    bare.set_fallback(None)?;
    let probe = stitch_case(&bare, "", &input, &[pop], None)?;
    let mean = probe.windows.iter().map(|r| r.correction).sum::<f32>() / probe.windows.len() as f32;
    let fallback = StitchFallback { start: 0.5 * mean, full: 2.0 * mean };
    let seam = stitch_case(
        refiner,
        "the pop given as a seam, a fallback from half to twice the windows' mean correction",
        &input,
        &[pop],
        Some(fallback),
    )?;
    Ok(vec![file, seam])
}

fn stitch_case(
    refiner: &StitchRefiner,
    name: &str,
    input: &[EnginePose],
    seams: &[usize],
    fallback: Option<StitchFallback>,
) -> Result<StitchCase, MotionError> {
    let mut refiner = refiner.clone();
    refiner.set_fallback(fallback)?;
    // The seam guard follows the ankle IK, and the seams' reach the foot lock: post-processes
    // the reference leaves out.
    refiner.set_seam_guard(false);
    refiner.set_seam_reach(None)?;
    let (frames, d) = (input.len(), refiner.dim());
    // Seams given to the runtime are inertialized before encoding (`refine_poses_at_seams`).
    let pre_blend = !seams.is_empty();
    let mut sequence = vec![0.0f32; frames * d];
    refiner.encode_poses_at_seams(input, if pre_blend { seams } else { &[] }, &mut sequence)?;
    finite("a pose vector", &sequence)?;
    let (refined, windows, first_window) = run_windows(&refiner, &sequence)?;
    let mut check = vec![0.0f32; frames * d];
    refiner.refine_sequence(&sequence, &mut check)?;
    if check != refined {
        return Err(MotionError::Run {
            reason: "the reference's windows differ from refine_sequence; this is a bug, please report it".into(),
        });
    }
    finite("a refined pose vector", &refined)?;
    let mut out = vec![EnginePose::new(refiner.joints()); frames];
    let mut contacts = vec![[false; 4]; frames];
    refiner.refine_poses_at_seams(input, seams, FootCleanup::NONE, &mut out, &mut contacts)?;
    Ok(StitchCase {
        name: name.into(),
        window: refiner.window(),
        stride: refiner.stride(),
        blend_frames: refiner.blend_frames(),
        input_poses: input.iter().map(|p| reference_pose("an input pose", p)).collect::<Result<_, _>>()?,
        seams: seams.to_vec(),
        pre_blend,
        fallback,
        sequence: rows(&sequence, d),
        window_starts: refiner.window_starts(frames),
        windows,
        first_window,
        refined: rows(&refined, d),
        poses: out.iter().map(|p| reference_pose("a refined pose", p)).collect::<Result<_, _>>()?,
        contacts,
    })
}

fn synthesis_cases(model: &SynthesisModel, rng: &mut SplitMix64) -> Result<Vec<SynthesisCase>, MotionError> {
    const STEPS: usize = 12;
    let m = model.model().metadata();
    let d = model.frame_dim();
    let stats = m.group("x", d)?;
    let unit = units_per_metre(m);
    let mut cases = Vec::new();
    let variants: Vec<(&str, SynthesisModel, f32)> = if model.has_refiner() {
        vec![
            ("the generator and its refiner, temperature 1", model.clone(), 1.0),
            ("the generator alone, temperature 0.5", model.clone().without_refiner(), 0.5),
        ]
    } else {
        vec![
            ("the generator, temperature 1", model.clone(), 1.0),
            ("the generator, temperature 0.5", model.clone(), 0.5),
        ]
    };
    for (name, model, temperature) in variants {
        let seed = rng.next_u64();
        // A start frame near the data's mean, contacts 0 or 1.
        let mut start: Vec<f32> =
            (0..d).map(|i| stats.mean[i] + 0.5 * stats.std[i] * rng.range(-1.0, 1.0) as f32).collect();
        for c in &mut start[d - 2..] {
            *c = if rng.next_f64() < 0.5 { 0.0 } else { 1.0 };
        }
        let placement =
            [(rng.range(-1.0, 1.0) * unit) as f32, (rng.range(-1.0, 1.0) * unit) as f32, rng.range(-PI, PI) as f32];
        let mut character = model.new_character(seed);
        character.start(&model, &start, placement[0], placement[1], placement[2])?;
        let mut runner = model.runner(1)?;
        let mut pose = EnginePose::with_global_positions(model.joints());
        let mut steps = Vec::with_capacity(STEPS);
        for _ in 0..STEPS {
            let x = character.frame().to_vec();
            let contacts = runner.step(&mut character, temperature, &mut pose)?;
            let crate::synthesis::LastStep { weights, means, stds, refined } = runner.last_step(0);
            for (what, v) in [("the mixture's weights", weights), ("its means", means), ("its stds", stds)] {
                finite(what, v)?;
            }
            finite("a sampled frame", character.frame())?;
            if let Some(r) = refined {
                finite("a refined frame", r)?;
            }
            steps.push(SynthesisStep {
                x,
                weights: weights.to_vec(),
                means: means.to_vec(),
                stds: stds.to_vec(),
                sampled: character.frame().to_vec(),
                rng_state: character.rng_state(),
                refined: refined.map(<[f32]>::to_vec),
                pose: reference_pose("a synthesised pose", &pose)?,
                contacts,
            });
        }
        cases.push(SynthesisCase {
            name: name.to_string(),
            seed,
            temperature,
            refined: model.has_refiner(),
            start_frame: start,
            start_placement: placement,
            steps,
        });
    }
    Ok(cases)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metadata::{MotionModelMetadata, MotionSkeletonInfo};

    fn metadata(offsets: Vec<[f64; 3]>, parents: Vec<i32>) -> MotionModelMetadata {
        let names = (0..parents.len()).map(|j| format!("j{j}")).collect();
        MotionModelMetadata {
            format_version: crate::metadata::FORMAT_VERSION,
            model_kind: "test".into(),
            task: crate::metadata::MotionTask::Step,
            config_json: "{}".into(),
            normalization: Default::default(),
            skeleton: MotionSkeletonInfo { names, parents, offsets },
            feature_layout: Vec::new(),
            fps: 30.0,
            frame: crate::pose::CoordinateFrame::ZOO_CM,
            state: Vec::new(),
            weights: crate::metadata::WeightWidth::F32,
        }
    }

    #[test]
    fn the_fit_is_undefined_where_children_lie_on_one_line() {
        // A spine up and one leg straight down from the hips: the twist is free.
        let line = metadata(vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, -40.0, 0.0], [0.0, -40.0, 0.0]], vec![-1, 0, 0, 2]);
        assert!(!fit_is_defined(&line));
        // The leg off the spine's line, or a chain, defines every rotation.
        let apart =
            metadata(vec![[0.0; 3], [0.0, 10.0, 0.0], [12.0, -40.0, 3.0], [0.0, -40.0, 0.0]], vec![-1, 0, 0, 2]);
        assert!(fit_is_defined(&apart));
        let chain = metadata(vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 10.0, 0.0]], vec![-1, 0, 1]);
        assert!(fit_is_defined(&chain));
    }

    #[test]
    fn seeded_walks_stand_on_the_ground_and_move() {
        let m = metadata(vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, -40.0, 0.0], [0.0, -40.0, 0.0]], vec![-1, 0, 0, 2]);
        let mut rng = SplitMix64::new(3);
        let style = MotionStyle::walk(&m, &mut rng);
        let poses = seeded_motion(&m, &style, 31, None, &mut rng);
        // The hips stand the legs' length above the ground (80 cm, bobbing by 2%).
        assert!(poses.iter().all(|p| (p.hips_position.y - 80.0).abs() <= 1.6 + 1e-3));
        // One second at 0.8 to 1.6 m/s.
        let walked = (poses[30].root_position - poses[0].root_position).length();
        assert!((75.0..=165.0).contains(&walked), "{walked} cm");
        assert!(poses.iter().flat_map(|p| &p.local_rotations).all(|q| q.is_normalized()));
    }
}
