//! Helpers shared by the workspace-level tests.

pub mod onnxruntime;
pub mod toy_onnx;

use glam::{DQuat, DVec3};
use std::path::{Path, PathBuf};
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

/// Path of the `zoo` binary built for these tests (the CLI crate's binary, built by cargo
/// before the tests run because the `zoo-cli` package is a workspace member).
pub fn zoo_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(|d| d.parent()).expect("target dir");
    let bin = dir.join(format!("zoo{}", std::env::consts::EXE_SUFFIX));
    assert!(bin.exists(), "{} is missing: build it with `cargo build --bin zoo` (scripts/test.sh does)", bin.display());
    bin
}

/// The real dataset folder, when this checkout sits beside `shared/`.
pub fn bandai2() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/bandai2");
    p.is_dir().then_some(p)
}

/// A small 4-joint chain skeleton (root, spine, leg, foot).
pub fn toy_skeleton() -> Skeleton {
    let ch = |position| JointChannels { position, order: EulerOrder::Zxy };
    Skeleton {
        names: ["Hips", "Spine", "Leg", "Foot_L"].iter().map(|s| s.to_string()).collect(),
        parents: vec![None, Some(0), Some(0), Some(2)],
        offsets: vec![
            DVec3::ZERO,
            DVec3::new(0.0, 10.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
        ],
        end_sites: vec![None, Some(DVec3::new(0.0, 5.0, 0.0)), None, Some(DVec3::new(0.0, 0.0, 10.0))],
        channels: vec![ch(true), ch(false), ch(false), ch(false)],
    }
}

/// A walking-like toy clip: the root moves along a curve, joints swing with a phase.
pub fn toy_clip(frames: usize, phase: f64) -> Clip {
    let skeleton = toy_skeleton();
    let j = skeleton.len();
    let mut rot = Vec::with_capacity(frames * j);
    let mut pos = Vec::with_capacity(frames * j);
    for f in 0..frames {
        let t = f as f64 / 30.0 + phase;
        let root = DVec3::new(100.0 * t, 85.0 + 2.0 * (6.0 * t).sin(), 20.0 * (0.5 * t).sin());
        rot.push(DQuat::from_rotation_y(0.3 * t) * DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2));
        rot.push(DQuat::from_rotation_x(0.1 * (3.0 * t).sin()));
        rot.push(DQuat::from_rotation_x(0.5 * (6.0 * t).sin()));
        rot.push(DQuat::from_rotation_x(0.2 * (6.0 * t).cos()));
        pos.push(root);
        pos.extend_from_slice(&skeleton.offsets[1..]);
    }
    Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations: rot, local_positions: pos }
}

/// A tiny RTN (`zoo_rtn::Config::tiny`) on the 4-joint [`toy_skeleton`] with unit statistics,
/// exported as `zoo export --onnx` would (its weights are candle's random initialization): the
/// engine tests' model file.
pub fn tiny_rtn_onnx() -> zoo_export::OnnxModel {
    tiny_rtn_onnx_with_std(10.0)
}

/// [`tiny_rtn_onnx`] with every normalization standard deviation `std`: the step's random
/// outputs become motion of about `std` cm per frame (1: a walk; 10: metres per second). The
/// weights are seeded ([`zoo_nn::SeededVarMap`], seed 7): the same model every run.
pub fn tiny_rtn_onnx_with_std(std: f32) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;
    use zoo_rtn::features::{FeatureStats, MeanStd};
    let skeleton = toy_skeleton();
    let config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents);
    let varmap = VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).expect("tiny RTN");
    let d = config.dim();
    let unit = || MeanStd { mean: vec![0.0; d], std: vec![std; d] };
    let stats = FeatureStats { joints: skeleton.len(), x: unit(), velocity: unit(), offset: unit(), terrain: None };
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(skeleton.names.clone()),
        offsets: Some(skeleton.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).expect("the tiny RTN exports")
}

/// An untrained RNN-GMM generator trainer of `config`'s sizes on two 6-second clips of the
/// synthetic locomotion (seed 3; the first clip trains, the second validates), with its data.
pub fn rnngmm_fixture(
    config: zoo_rnngmm::prelude::Config,
) -> (zoo_rnngmm::prelude::Config, zoo_rnngmm::TrainingData, zoo_rnngmm::prelude::GeneratorTrainer) {
    use zoo_data::synth::{SynthConfig, generate_clip};
    let cfg = SynthConfig { minutes: 0.2, seed: 3, terrain: false, fps: 30.0, clip_seconds: 6.0 };
    let clips: Vec<Clip> = (0..2).map(|i| generate_clip(&cfg, i).clip).collect();
    let refs: Vec<&Clip> = clips.iter().collect();
    let data = zoo_rnngmm::TrainingData::from_clips(&config, 30.0, &refs[..1], &refs[1..]).unwrap();
    let config = config.with_dim(data.spec.dim());
    let trainer = zoo_rnngmm::prelude::GeneratorTrainer::new(
        &config,
        data.spec.clone(),
        data.norm.clone(),
        &candle_core::Device::Cpu,
    )
    .unwrap();
    (config, data, trainer)
}
