//! docs/runtime-protocol.md is enough to run an exported model with another inference engine:
//! `scripts/runtime_protocol.py`, written from that page alone (numpy and the onnxruntime
//! Python wheel, which `bash scripts/onnxruntime.sh` installs into `.onnxruntime/venv`), gives
//! the Rust runtime's 30-frame transition within 1e-3 cm. A missing venv fails the test with
//! the command that provisions it.

use glam::{DQuat, DVec3};
use std::path::PathBuf;
use std::process::Command;
use zoo_runtime::prelude::*;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Global positions of every frame of the toy clip, frame-major, `3K` per frame.
fn toy_positions(frames: usize) -> Vec<f32> {
    let clip = zoo_tests::toy_clip(frames, 0.0);
    let k = clip.skeleton.len();
    let (mut gr, mut gp) = (vec![DQuat::IDENTITY; k], vec![DVec3::ZERO; k]);
    let mut out = Vec::with_capacity(frames * 3 * k);
    for f in 0..frames {
        let (r, p) = (&clip.local_rotations[f * k..(f + 1) * k], &clip.local_positions[f * k..(f + 1) * k]);
        zoo_motion::fk::forward_kinematics(&clip.skeleton.parents, r, p, &mut gr, &mut gp);
        out.extend(gp.iter().flat_map(|v| [v.x as f32, v.y as f32, v.z as f32]));
    }
    out
}

/// The tiny RTN of [`zoo_tests::tiny_rtn_onnx_with_std`] (std 1, seed 7) with `change` applied
/// to its configuration.
fn tiny_rtn(change: impl Fn(&mut zoo_rtn::Config)) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_rtn::features::{FeatureStats, MeanStd};
    let skeleton = zoo_tests::toy_skeleton();
    let mut config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents);
    change(&mut config);
    let varmap = candle_nn::VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let unit = || MeanStd { mean: vec![0.0; d], std: vec![1.0; d] };
    let stats = FeatureStats { joints: skeleton.len(), x: unit(), velocity: unit(), offset: unit(), terrain: None };
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(skeleton.names.clone()),
        offsets: Some(skeleton.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).unwrap()
}

/// What the runtime and the Python protocol did on one 30-frame transition.
struct Compared {
    /// Largest difference of a coordinate, cm.
    worst: f32,
    /// The runtime's frames.
    out: Vec<f32>,
    target: Vec<f32>,
    miss: zoo_runtime::TargetMiss,
    fallback_weight: f32,
}

/// Runs the 30-frame transition of the toy clip through the runtime (with the file's own
/// fallback when `fallback`) and through `scripts/runtime_protocol.py`, and compares them.
fn compare(model: &zoo_export::OnnxModel, fallback: bool) -> Compared {
    let python = workspace().join(".onnxruntime/venv/bin/python");
    assert!(
        python.is_file(),
        "{} is missing: run `bash scripts/onnxruntime.sh` in the zoo workspace (it installs the onnxruntime \
         Python wheel and numpy into .onnxruntime/venv for this test)",
        python.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    model.write(&path).unwrap();
    let model = TransitionModel::load(&path).unwrap();
    let (p, d, n) = (model.past_frames(), 3 * model.joints(), 30);
    let pos = toy_positions(p + n + 2);
    let (past, target, next) = (&pos[..p * d], &pos[(p + n) * d..(p + n + 1) * d], &pos[(p + n + 1) * d..]);
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true); // the tiny model is trained for 6 frames
    if fallback {
        runner.set_fallback(Some(model.default_fallback().expect("the file carries fallback thresholds")));
    }
    let mut state = model.new_transition();
    let mut out = vec![0f32; (n + 1) * d];
    runner.generate(&mut state, past, target, next, &mut out).unwrap();
    let miss = state.target_miss().expect("a finished transition knows its miss");

    let rows = |v: &[f32]| v.chunks_exact(d).map(|c| c.to_vec()).collect::<Vec<_>>();
    let input =
        serde_json::json!({"past": rows(past), "target": target, "next": next, "frames": n, "fallback": fallback});
    let (input_path, output_path) = (dir.path().join("input.json"), dir.path().join("output.json"));
    std::fs::write(&input_path, input.to_string()).unwrap();
    let run = Command::new(&python)
        .arg(workspace().join("scripts/runtime_protocol.py"))
        .args([&path, &input_path, &output_path])
        .output()
        .unwrap();
    assert!(run.status.success(), "runtime_protocol.py failed:\n{}", String::from_utf8_lossy(&run.stderr));
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&output_path).unwrap()).unwrap();
    let frames = result["frames"].as_array().unwrap();
    assert_eq!(frames.len(), n + 1);
    let mut worst = 0f32;
    for (f, frame) in frames.iter().enumerate() {
        for (i, v) in frame.as_array().unwrap().iter().enumerate() {
            worst = worst.max((v.as_f64().unwrap() as f32 - out[f * d + i]).abs());
        }
    }
    let largest = out.iter().fold(0f32, |m, v| m.max(v.abs()));
    eprintln!(
        "python protocol vs runtime: worst difference {worst:.2e} cm over {} frames (largest coordinate {largest:.0} cm)",
        n + 1
    );
    let (mean, max) = (result["miss_mean"].as_f64().unwrap() as f32, result["miss_max"].as_f64().unwrap() as f32);
    assert!((mean - miss.mean).abs() <= 1e-3 && (max - miss.max).abs() <= 1e-3, "miss {mean}/{max} vs {miss:?}");
    let weight = result["fallback_weight"].as_f64().unwrap() as f32;
    assert!((weight - state.fallback_weight()).abs() <= 1e-4, "weight {weight} vs {}", state.fallback_weight());
    Compared { worst, out, target: target.to_vec(), miss, fallback_weight: state.fallback_weight() }
}

#[test]
fn the_documented_protocol_reproduces_the_runtime() {
    // Statistics that make the random tiny network move about as fast as a walk, so that the
    // coordinates stay at a character's scale (metres, not tens of metres) over 31 frames.
    let c = compare(&zoo_tests::tiny_rtn_onnx_with_std(1.0), false);
    assert!(c.worst <= 1e-3, "the documented protocol differs from the runtime by {} cm", c.worst);
    // The transition moved: a protocol that returned the context would not pass.
    let d = c.target.len();
    assert!(c.out[..d].iter().zip(&c.target).any(|(a, b)| (a - b).abs() > 1.0));
}

/// The interpolation-residual RTN (the step graph's `base` input, computed by the caller) and
/// the fallback towards interpolation, both from the page alone.
#[test]
fn the_documented_protocol_covers_the_interpolation_base_and_the_fallback() {
    let plain = compare(&tiny_rtn(|c| c.interp_residual = true), false);
    assert!(plain.worst <= 1e-3, "interpolation base: the protocol differs from the runtime by {} cm", plain.worst);
    assert_eq!(plain.fallback_weight, 0.0);
    // Thresholds around this transition's own miss, so the weight is strictly between 0 and 1.
    let m = plain.miss.mean;
    let fb = zoo_rtn::fallback::Fallback { start: 0.5 * m, full: 2.0 * m };
    let with = compare(
        &tiny_rtn(|c| {
            c.interp_residual = true;
            c.fallback = Some(fb);
        }),
        true,
    );
    assert!(with.worst <= 1e-3, "fallback: the protocol differs from the runtime by {} cm", with.worst);
    assert!((with.fallback_weight - 1.0 / 3.0).abs() < 1e-3, "weight {}", with.fallback_weight);
    // The fallback moved the frames (towards the interpolation), not the target frame.
    let d = plain.target.len();
    assert!(plain.out.iter().zip(&with.out).any(|(a, b)| (a - b).abs() > 1e-2));
    let end = plain.out.len() - d;
    assert!(with.out[end..].iter().zip(&plain.target).all(|(a, b)| (a - b).abs() < 1e-3));
}
