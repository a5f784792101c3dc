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

#[test]
fn the_documented_protocol_reproduces_the_runtime() {
    let python = workspace().join(".onnxruntime/venv/bin/python");
    assert!(
        python.is_file(),
        "{} is missing: run `bash scripts/onnxruntime.sh` in the zoo workspace (it installs the onnxruntime \
         Python wheel and numpy into .onnxruntime/venv for this test)",
        python.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    // Statistics that make the random tiny network move about as fast as a walk, so that the
    // coordinates stay at a character's scale (metres, not tens of metres) over 31 frames.
    zoo_tests::tiny_rtn_onnx_with_std(1.0).write(&path).unwrap();
    let model = TransitionModel::load(&path).unwrap();
    let (p, d, n) = (model.past_frames(), 3 * model.joints(), 30);
    let pos = toy_positions(p + n + 2);
    let (past, target, next) = (&pos[..p * d], &pos[(p + n) * d..(p + n + 1) * d], &pos[(p + n + 1) * d..]);
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true); // the tiny model is trained for 6 frames
    let mut state = model.new_transition();
    let mut out = vec![0f32; (n + 1) * d];
    runner.generate(&mut state, past, target, next, &mut out).unwrap();
    let miss = state.target_miss().expect("a finished transition knows its miss");

    let rows = |v: &[f32]| v.chunks_exact(d).map(|c| c.to_vec()).collect::<Vec<_>>();
    let input = serde_json::json!({"past": rows(past), "target": target, "next": next, "frames": n});
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
    assert!(worst <= 1e-3, "the documented protocol differs from the runtime by {worst} cm");
    // The transition moved: a protocol that returned the context would not pass.
    assert!(out[..d].iter().zip(target).any(|(a, b)| (a - b).abs() > 1.0));
    let (mean, max) = (result["miss_mean"].as_f64().unwrap() as f32, result["miss_max"].as_f64().unwrap() as f32);
    assert!((mean - miss.mean).abs() <= 1e-3 && (max - miss.max).abs() <= 1e-3, "miss {mean}/{max} vs {miss:?}");
}
