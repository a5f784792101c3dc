//! End-to-end tests of `zoo train rtn`, `zoo transition` and `zoo decompress` on the embedded
//! synthetic data (a paper-size RTN trained for one or two short epochs).

use std::process::Command;
use zoo_tests::zoo_bin;

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_bin()).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn train_resume_transition_and_decompress() {
    let dir = tempfile::tempdir().unwrap();
    let runp = dir.path().join("run");
    let run_dir = runp.to_str().unwrap();
    let (ok, stdout, stderr) = run(&["train", "rtn", "--synth-minutes", "2", "--epochs", "1", "--out", run_dir]);
    assert!(ok, "{stdout}\n{stderr}");
    for f in [
        "config.json",
        "model.safetensors",
        "normalization.json",
        "loss_curve.png",
        "summary.json",
        "train_state.json",
        "last/model.safetensors",
    ] {
        assert!(runp.join(f).is_file(), "{f} missing in the run folder");
    }
    let size = std::fs::metadata(runp.join("model.safetensors")).unwrap().len();
    assert!(size <= 15 * 1024 * 1024, "parameter file is {size} bytes");
    let (ok, stdout, stderr) = run(&["train", "rtn", "--synth-minutes", "2", "--epochs", "2", "--resume", run_dir]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("epoch   2:") && !stdout.contains("epoch   1:"), "{stdout}");
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("train_state.json")).unwrap()).unwrap();
    assert_eq!(state["epoch"], 2);
    assert_eq!(state["valid_loss"].as_array().unwrap().len(), 2);
    // The last checkpoint carries the optimiser state, so the resume continued it exactly.
    assert!(runp.join("last/optimizer.safetensors").is_file());
    assert!(!stdout.contains("no optimiser state"), "{stdout}");
    // The moving average of the weights (on by default) is validated every epoch and resumed.
    assert!(runp.join("last/ema.safetensors").is_file());
    assert_eq!(state["valid_loss_ema"].as_array().unwrap().len(), 2);
    assert!(stdout.contains("averaged"), "{stdout}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["ema_decay"], 0.999);
    assert!(summary["best_is_moving_average"].is_boolean());

    // Transition and super-resolution on synthetic BVH clips.
    let data = dir.path().join("synth");
    let (ok, _, stderr) = run(&["data", "synth", "--out", data.to_str().unwrap(), "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{stderr}");
    let mut clips: Vec<_> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    clips.sort();
    let (a, b) = (clips[0].to_str().unwrap(), clips[1].to_str().unwrap());
    let out = dir.path().join("t.bvh");
    let (ok, stdout, stderr) = run(&[
        "transition",
        "--model",
        run_dir,
        "--from",
        &format!("{a}:60"),
        "--to",
        &format!("{b}:40"),
        "--frames",
        "20",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let ca = zoo_data::bvh::read_file(&clips[0], &Default::default()).unwrap();
    let cb = zoo_data::bvh::read_file(&clips[1], &Default::default()).unwrap();
    let t = zoo_data::bvh::read_file(&out, &Default::default()).unwrap();
    assert_eq!(t.frames(), 60 + 20 + (cb.frames() - 40));
    assert_eq!(t.skeleton.names, ca.skeleton.names);
    // The output plays A unchanged before the transition.
    for f in [0, 30, 59] {
        assert!((t.root_position(f) - ca.root_position(f)).length() < 1e-3);
    }
    // The same with the foot lock: same frames, A and B untouched, every value finite.
    let locked = dir.path().join("t_lock.bvh");
    let args = ["transition", "--model", run_dir, "--from", &format!("{a}:60"), "--to", &format!("{b}:40")];
    let (ok, stdout, stderr) =
        run(&[&args[..], &["--frames", "20", "--foot-lock", "--out", locked.to_str().unwrap()]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let tl = zoo_data::bvh::read_file(&locked, &Default::default()).unwrap();
    assert_eq!(tl.frames(), t.frames());
    assert!(tl.local_rotations.iter().all(|q| q.is_finite()));
    for f in (0..60).chain(80..tl.frames()) {
        assert!((tl.root_position(f) - t.root_position(f)).length() < 1e-3, "frame {f}");
    }
    let rebuilt = dir.path().join("r.bvh");
    let (ok, stdout, stderr) = run(&["decompress", "--model", run_dir, a, "--out", rebuilt.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("mean joint position error"), "{stdout}");
    let r = zoo_data::bvh::read_file(&rebuilt, &Default::default()).unwrap();
    assert_eq!(r.frames(), 10 + (ca.frames() - 11) / 30 * 30);
    assert!(r.local_rotations.iter().all(|q| q.is_finite()));

    // Export, then the benchmark through candle (`rtn:`) and through the runtime (`onnx:`),
    // with and without the foot lock: every metric agrees within 1e-3.
    let onnx = dir.path().join("rtn.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", run_dir, "--out", onnx.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    let onnx = onnx.to_str().unwrap();
    let json = dir.path().join("bench.json");
    let methods = format!("interp,rtn:{run_dir},onnx:{onnx},rtn+lock:{run_dir},onnx+lock:{onnx}");
    let (ok, stdout, stderr) = run(&[
        "bench",
        "--data",
        data.to_str().unwrap(),
        "--valid-glob",
        "*_0001*",
        "--lengths",
        "5,15",
        "--methods",
        &methods,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = result["methods"].as_object().unwrap();
    let mut compared = 0;
    for (candle, runtime) in [
        (format!("rtn:{run_dir}"), format!("onnx:{onnx}")),
        (format!("rtn+lock:{run_dir}"), format!("onnx+lock:{onnx}")),
    ] {
        let (a, b) = (rows[&candle].as_object().unwrap(), rows[&runtime].as_object().unwrap());
        for (key, value) in a {
            let (Some(x), Some(y)) = (value.as_f64(), b.get(key).and_then(|v| v.as_f64())) else { continue };
            if key.starts_with("ms") {
                continue;
            }
            assert!((x - y).abs() <= 1e-3, "{key}: {candle} {x} vs {runtime} {y}");
            compared += 1;
        }
    }
    assert!(compared >= 20, "compared only {compared} metrics: {rows:?}");

    // Step latency and throughput through candle, tract and onnxruntime.
    let (ok, stdout, stderr) =
        run(&["bench", "runtime", "--model", onnx, "--rounds", "1", "--work", "8", "--batch", "1,4"]);
    assert!(ok, "{stdout}\n{stderr}");
    for backend in ["candle", "tract", "onnxruntime"] {
        let rows = stdout.lines().filter(|l| l.split_whitespace().nth(1) == Some(backend)).count();
        assert_eq!(rows, 2, "one row per batch size for {backend}:\n{stdout}");
    }
}

#[test]
fn diverging_training_stops_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let runp = dir.path().join("run");
    let (ok, stdout, stderr) =
        run(&["train", "rtn", "--synth-minutes", "2", "--epochs", "1", "--lr", "1e8", "--out", runp.to_str().unwrap()]);
    assert!(!ok, "{stdout}");
    assert!(stderr.contains("training stopped") && stderr.contains("NaN"), "{stderr}");
    assert!(!runp.join("model.safetensors").exists(), "a diverged run must not write weights");
}

#[test]
fn transition_rejects_bad_frame_references() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, _, stderr) = run(&[
        "transition",
        "--model",
        dir.path().to_str().unwrap(),
        "--from",
        "nofile.bvh",
        "--to",
        "x.bvh:3",
        "--out",
        "o.bvh",
    ]);
    assert!(!ok);
    assert!(stderr.contains("expected CLIP.bvh:FRAME"), "{stderr}");
}
