//! End-to-end tests of `zoo train arnn` and `zoo complete`: a tiny ARNN trained for an epoch or
//! two on a few lamp sequences generated in memory with a short annealing (`--k-max 2`).

use std::path::Path;
use std::process::Command;
use std::sync::OnceLock;
use zoo_tests::zoo_bin;

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_bin()).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Trains a tiny ARNN into `dir` for `epochs` epochs (or resumes it).
fn train(dir: &Path, epochs: usize, resume: bool) -> (bool, String, String) {
    let d = dir.to_str().unwrap();
    let e = epochs.to_string();
    let base = ["train", "arnn", "--preset", "tiny", "--epochs", &e];
    if resume {
        run(&[&base[..], &["--resume", d]].concat())
    } else {
        run(&[&base[..], &["--sequences", "5", "--k-max", "2", "--seed", "3", "--out", d]].concat())
    }
}

const REST: [f64; 6] = [0.0, 0.02, 0.0, 0.5, -1.1, -1.2];

fn pose_json(p: &[f64]) -> String {
    format!("[{}]", p.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", "))
}

/// A keys file: a hop forward, its apex and the landing.
fn hop_keys() -> String {
    let apex = [0.25, 0.25, 0.0, 0.7, -1.5, -1.3];
    let land = [0.5, 0.02, 0.0, 0.5, -1.1, -1.2];
    format!(
        r#"{{"format": "zoo-arnn-keys", "version": 1, "fps": 40,
            "dof_names": ["base_x", "base_y", "base_angle", "theta1", "theta2", "theta3"],
            "keys": [{{"frame": 0, "pose": {}}}, {{"frame": 12, "pose": {}}}, {{"frame": 24, "pose": {}}}]}}"#,
        pose_json(&REST),
        pose_json(&apex),
        pose_json(&land)
    )
}

#[test]
fn train_resume_and_complete() {
    let dir = tempfile::tempdir().unwrap();
    let runp = dir.path().join("run");
    let (ok, stdout, stderr) = train(&runp, 1, false);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("4 training / 1 test sequences of 87 frames"), "{stdout}");
    assert!(stdout.contains("(the last 25% a frame phase with omega 0.01)"), "{stdout}");
    for f in [
        "config.json",
        "model.safetensors",
        "normalization.json",
        "summary.json",
        "last/optimizer.safetensors",
        "completion_test.png",
    ] {
        assert!(runp.join(f).is_file(), "{f} missing in the run folder");
    }
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["model"], "arnn");
    // A lamp run with the curriculum ends in the frame phase by default.
    let phase = (config["curriculum"]["frame_phase"].as_f64(), config["curriculum"]["frame_phase_omega"].as_f64());
    assert_eq!(phase, (Some(0.25), Some(0.01)), "{config}");
    // The test-set comparison with interpolation is in the summary.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("summary.json")).unwrap()).unwrap();
    for m in ["arnn", "linear", "spline"] {
        assert!(summary["completion"][m]["frame"].as_f64().unwrap().is_finite(), "{summary}");
    }
    assert!(stdout.contains("network frame error / spline frame error"), "{stdout}");

    // A second fresh run into the same folder is refused; resuming continues it.
    let (ok, _, stderr) = train(&runp, 1, false);
    assert!(
        !ok && stderr.contains("already holds a run trained for 1 epochs") && stderr.contains("--resume"),
        "{stderr}"
    );
    let (ok, stdout, stderr) = train(&runp, 2, true);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("epoch   2:") && !stdout.contains("epoch   1:"), "{stdout}");
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("train_state.json")).unwrap()).unwrap();
    assert_eq!(state["epoch"], 2);
    assert_eq!(state["data_settings"]["sequences"], 5);

    // The evaluation of the run folder on its test sequence, best and last weights.
    let jpath = dir.path().join("eval.json");
    for (checkpoint, epoch) in [("best", None), ("last", Some(2))] {
        let (ok, stdout, stderr) = run(&[
            "eval-arnn",
            "--model",
            runp.to_str().unwrap(),
            "--checkpoint",
            checkpoint,
            "--json",
            jpath.to_str().unwrap(),
        ]);
        assert!(ok, "{stdout}\n{stderr}");
        assert!(
            stdout.contains("1 sequences completed") && stdout.contains("network frame error / spline"),
            "{stdout}"
        );
        let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&jpath).unwrap()).unwrap();
        assert_eq!(r["checkpoint"], checkpoint);
        if let Some(e) = epoch {
            assert_eq!(r["epoch"], e);
        }
        // The grounded output never sinks (the lamp's tolerance of rounding only).
        assert!(r["arnn_grounded"]["lowest_base"].as_f64().unwrap() > -1e-9, "{r}");
    }

    // Completion: a BVH of the lamp with one frame per network frame, starting on the first key.
    let keys = dir.path().join("keys.json");
    std::fs::write(&keys, hop_keys()).unwrap();
    let (bvh, json, png) = (dir.path().join("hop.bvh"), dir.path().join("hop.json"), dir.path().join("hop.png"));
    let (ok, stdout, stderr) = run(&[
        "complete",
        "--model",
        runp.to_str().unwrap(),
        "--keys",
        keys.to_str().unwrap(),
        "--out",
        bvh.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("completed 25 frames from 3 keys (40 fps)") && stdout.contains("largest key miss"),
        "{stdout}"
    );
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    let clip = zoo_data::bvh::read_file(&bvh, &Default::default()).unwrap();
    assert_eq!(clip.frames(), 25);
    assert_eq!(clip.skeleton.names, ["base", "leg", "neck", "head"]);
    assert!((clip.frame_time - 1.0 / 40.0).abs() < 1e-6);
    let poses = zoo_arnn::luxo::sequence::clip_to_poses(&clip).unwrap();
    for d in 0..6 {
        assert!((poses[0][d] - REST[d]).abs() < 1e-4, "frame 0 is not the first key: {:?}", poses[0]);
    }
    // Export: the step graph loads in the runtime, an ARNN driven as a bare step model.
    let onnx = dir.path().join("arnn.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", runp.to_str().unwrap(), "--out", onnx.to_str().unwrap()]);
    assert!(ok && stdout.contains("ARNN step graph"), "{stdout}\n{stderr}");
    let m = zoo_runtime::MotionModel::load(&onnx).unwrap();
    assert_eq!((m.metadata().model_kind.as_str(), m.states().len()), ("arnn", 2));
    // `zoo complete` runs the exported file as it runs the run folder (exported in memory).
    let from_file = dir.path().join("hop_file.bvh");
    let keys_arg = keys.to_str().unwrap();
    let (ok, _, stderr) =
        run(&["complete", "--model", onnx.to_str().unwrap(), "--keys", keys_arg, "--out", from_file.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read(&from_file).unwrap(),
        std::fs::read(&bvh).unwrap(),
        "the exported file completes otherwise"
    );
    // The step through tract and onnxruntime and whole completions, timed (figures not checked).
    let (ok, stdout, stderr) = run(&[
        "bench",
        "keyframes",
        "--model",
        onnx.to_str().unwrap(),
        "--batch",
        "1,3",
        "--rounds",
        "1",
        "--work",
        "6",
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    for row in ["1      tract step", "1      onnxruntime step", "3      tract completion"] {
        assert!(stdout.contains(row), "no `{row}` row: {stdout}");
    }
    let out: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(out["frames"].as_array().unwrap().len(), 25);
    assert_eq!(out["key_misses"].as_array().unwrap().len(), 3);
    assert!(out["frames"].as_array().unwrap().iter().flat_map(|f| f.as_array().unwrap()).all(|v| v.is_f64()));
}

/// A tiny ARNN trained once for the bad-input tests of this file (one epoch).
fn shared_model() -> &'static Path {
    static MODEL: OnceLock<tempfile::TempDir> = OnceLock::new();
    MODEL
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let (ok, stdout, stderr) = train(&dir.path().join("run"), 1, false);
            assert!(ok, "{stdout}\n{stderr}");
            dir
        })
        .path()
}

/// Runs `zoo complete` on the shared model with a keys file holding `keys`; it must fail
/// without a panic and write nothing. Returns stderr.
fn refused(keys: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let (path, out) = (dir.path().join("k.json"), dir.path().join("o.bvh"));
    std::fs::write(&path, keys).unwrap();
    let model = shared_model().join("run");
    let (ok, stdout, stderr) = run(&[
        "complete",
        "--model",
        model.to_str().unwrap(),
        "--keys",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "accepted {keys}: {stdout}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains(path.to_str().unwrap()), "the error does not name the keys file: {stderr}");
    assert!(!out.exists(), "a refused completion wrote its output");
    stderr
}

fn key(frame: usize, pose: &str) -> String {
    format!(r#"{{"frame": {frame}, "pose": {pose}}}"#)
}

fn keys_file(keys: &[String]) -> String {
    format!(r#"{{"format": "zoo-arnn-keys", "version": 1, "keys": [{}]}}"#, keys.join(", "))
}

#[test]
fn keys_out_of_order_are_refused() {
    let rest = pose_json(&REST);
    let e = refused(&keys_file(&[key(0, &rest), key(20, &rest), key(10, &rest)]));
    assert!(e.contains("key 2 is at frame 10 but key 1 is at frame 20: keys must be in increasing frame order"), "{e}");
    // Two keys on one frame.
    let e = refused(&keys_file(&[key(0, &rest), key(10, &rest), key(10, &rest)]));
    assert!(e.contains("key 2 is at frame 10 but key 1 is at frame 10") && e.contains("one key per frame"), "{e}");
}

#[test]
fn keys_past_the_sequence_are_refused() {
    let rest = pose_json(&REST);
    let with_len = |len: usize, keys: &[String]| {
        format!(r#"{{"format": "zoo-arnn-keys", "version": 1, "frames": {len}, "keys": [{}]}}"#, keys.join(", "))
    };
    let e = refused(&with_len(25, &[key(0, &rest), key(12, &rest), key(30, &rest)]));
    assert!(e.contains("key 2 is at frame 30, past the sequence of 25 frames (frames 0 to 24)"), "{e}");
    let e = refused(&with_len(40, &[key(0, &rest), key(24, &rest)]));
    assert!(e.contains("the sequence has 40 frames but its last key is at frame 24") && e.contains("frame 39"), "{e}");
    // Past what zoo complete generates, and a frame number that is not one.
    let e = refused(&keys_file(&[key(0, &rest), key(1_000_000, &rest)]));
    assert!(e.contains("past the 100000 frames zoo complete generates"), "{e}");
    let e = refused(&keys_file(&[key(0, &rest), r#"{"frame": -3, "pose": [0, 0, 0, 0, 0, 0]}"#.into()]));
    assert!(e.contains("not a keys file") && e.contains("invalid value: integer `-3`"), "{e}");
}

#[test]
fn keys_for_another_skeleton_are_refused() {
    let other =
        r#"{"dof_names": ["Hips", "Spine"], "keys": [{"frame": 0, "pose": [0, 0]}, {"frame": 5, "pose": [1, 1]}]}"#;
    let e = refused(other);
    assert!(e.contains("this keys file is for another character") && e.contains("base_x"), "{e}");
    // No names, but poses of another size.
    let e = refused(&keys_file(&[key(0, &pose_json(&REST)), key(10, "[0.1, 0.02, 0.0]")]));
    assert!(e.contains("key 1 (frame 10) has 3 values; the model completes 6 degrees of freedom"), "{e}");
    // Another file format (a lamp sequence).
    let e = refused(r#"{"format": "zoo-luxo-sequence", "keys": []}"#);
    assert!(e.contains("format is \"zoo-luxo-sequence\", expected \"zoo-arnn-keys\""), "{e}");
}

#[test]
fn nan_in_a_key_is_refused() {
    let rest = pose_json(&REST);
    for bad in ["NaN", "nan", "Infinity", "1e999"] {
        let e = refused(&keys_file(&[key(0, &rest), key(10, &format!("[{bad}, 0.02, 0.0, 0.5, -1.1, -1.2]"))]));
        assert!(e.contains("not a keys file") && e.contains("every value must be finite"), "{bad}: {e}");
    }
    let e = refused(&keys_file(&[key(0, &rest), key(10, "[0.1, null, 0.0, 0.5, -1.1, -1.2]")]));
    assert!(e.contains("not a keys file") && e.contains("invalid type: null"), "{e}");
    // A string that parses to NaN is not a number either.
    let e = refused(&keys_file(&[key(0, &rest), key(10, r#"["NaN", 0.02, 0.0, 0.5, -1.1, -1.2]"#)]));
    assert!(e.contains("not a keys file") && e.contains("invalid type: string"), "{e}");
}

/// The Table 2 architectures train, evaluate and complete; they are not exported.
#[test]
fn table_2_variants_train_and_evaluate() {
    let dir = tempfile::tempdir().unwrap();
    for variant in ["no-memory", "segregated"] {
        let runp = dir.path().join(variant);
        let (ok, stdout, stderr) = run(&[
            "train",
            "arnn",
            "--preset",
            "tiny",
            "--epochs",
            "1",
            "--sequences",
            "5",
            "--k-max",
            "2",
            "--seed",
            "3",
            "--variant",
            variant,
            "--frame-phase",
            "0.5",
            "--frame-phase-omega",
            "0.2",
            "--out",
            runp.to_str().unwrap(),
        ]);
        assert!(ok, "{stdout}\n{stderr}");
        let config: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
        assert_eq!(config["architecture"], variant);
        assert_eq!(config["no_memory_output"], "interpolation");
        assert_eq!(
            (config["curriculum"]["frame_phase"].as_f64(), config["curriculum"]["frame_phase_omega"].as_f64()),
            (Some(0.5), Some(0.2))
        );
        let (ok, stdout, stderr) = run(&["eval-arnn", "--model", runp.to_str().unwrap()]);
        assert!(
            ok && stdout.contains(if variant == "no-memory" {
                "NoMemory architecture (Interpolation output)"
            } else {
                "Segregated architecture"
            }),
            "{stdout}\n{stderr}"
        );
        let onnx = dir.path().join("x.onnx");
        let (ok, _, e) = run(&["export", "--onnx", runp.to_str().unwrap(), "--out", onnx.to_str().unwrap()]);
        assert!(!ok && e.contains("is a Table 2 comparison, not exported"), "{e}");
    }
    // Table 1's run without the curriculum has no frame phase; `--frame-phase 0` says so.
    let runp = dir.path().join("no-curriculum");
    let r = runp.to_str().unwrap();
    let tiny = ["train", "arnn", "--preset", "tiny", "--epochs", "1", "--sequences", "5", "--k-max", "2"];
    let (ok, stdout, stderr) =
        run(&[&tiny[..], &["--variant", "no-curriculum", "--frame-phase", "0", "--out", r]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    let c = &config["curriculum"];
    assert_eq!((c["enabled"].as_bool(), c["frame_phase"].as_f64()), (Some(false), Some(0.0)), "{config}");
}

#[test]
fn bad_keys_and_folders_are_refused_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.bvh");
    let e = refused(&keys_file(&[key(0, &pose_json(&REST))]));
    assert!(e.contains("1 key(s) given: completion needs at least 2"), "{e}");

    // A run folder of another model, and a folder that is not a run.
    let rtn = dir.path().join("rtn");
    std::fs::create_dir(&rtn).unwrap();
    std::fs::write(rtn.join("config.json"), r#"{"joints": 4}"#).unwrap();
    let keys = dir.path().join("keys.json");
    std::fs::write(&keys, hop_keys()).unwrap();
    let args = |m: &Path| {
        run(&[
            "complete",
            "--model",
            m.to_str().unwrap(),
            "--keys",
            keys.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let (ok, _, e) = args(&rtn);
    assert!(!ok && e.contains("`zoo complete` runs a run folder of model `arnn`") && e.contains("`rtn` model"), "{e}");
    let (ok, _, e) = args(dir.path());
    assert!(!ok && e.contains("is not a run folder of `zoo train` (no config.json)"), "{e}");
    let (ok, _, e) = run(&["eval-arnn", "--model", rtn.to_str().unwrap()]);
    assert!(!ok && e.contains("holds a `rtn` run, not an ARNN"), "{e}");
    // Data options that do not fit are refused before any work.
    // (The run folder outside the data folder: an output inside a dataset folder is refused.)
    let elsewhere = tempfile::tempdir().unwrap();
    let y = elsewhere.path().join("y");
    let (ok, _, e) = run(&["train", "arnn", "--data", dir.path().to_str().unwrap(), "--out", y.to_str().unwrap()]);
    assert!(!ok && e.contains("no luxo_*.json sequence found"), "{e}");
    let (ok, _, e) = run(&["train", "arnn", "--test-fraction", "1", "--out", dir.path().join("x").to_str().unwrap()]);
    assert!(!ok && e.contains("--test-fraction <TEST_FRACTION>': 1 is outside the valid range (0, 1)"), "{e}");
    let (ok, _, e) =
        run(&["train", "arnn", "--no-memory-output", "pose", "--out", dir.path().join("z").to_str().unwrap()]);
    assert!(!ok && e.contains("--no-memory-output is a setting of a new `--variant no-memory` lamp run"), "{e}");
    let z = dir.path().join("z");
    let (ok, _, e) =
        run(&["train", "arnn", "--frame-phase", "0.2", "--variant", "no-curriculum", "--out", z.to_str().unwrap()]);
    assert!(!ok && e.contains("--frame-phase and --frame-phase-omega are settings of a new run's curriculum"), "{e}");
    let (ok, _, e) = run(&["train", "arnn", "--frame-phase", "0.2", "--resume", dir.path().to_str().unwrap()]);
    assert!(!ok && e.contains("--frame-phase and --frame-phase-omega are settings of a new run's curriculum"), "{e}");
    let (ok, _, e) = run(&["train", "arnn", "--frame-phase", "1", "--out", z.to_str().unwrap()]);
    assert!(!ok && e.contains("1 is outside the valid range [0, 1)"), "{e}");
    let (ok, _, e) =
        run(&["train", "arnn", "--frame-phase", "0", "--frame-phase-omega", "0.5", "--out", z.to_str().unwrap()]);
    assert!(!ok && e.contains("--frame-phase-omega sets omega in the frame phase, and this run has none"), "{e}");
}

/// Issue 13, the humanoid: a tiny ARNN trained on synthetic BVH clips with `--valid-glob`, then
/// scored by the in-betweening benchmark beside interpolation (`zoo bench --methods
/// interp,arnn:DIR`); a lamp run is refused there with a message saying why.
#[test]
fn humanoid_arnn_trains_on_bvh_and_runs_in_the_benchmark() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let d = data.to_str().unwrap();
    let (ok, _, stderr) = run(&["data", "synth", "--out", d, "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{stderr}");
    let runp = dir.path().join("h");
    let r = runp.to_str().unwrap();
    let base = ["train", "arnn", "--data", d, "--valid-glob", "*_0005.bvh", "--preset", "tiny", "--threads", "1"];
    let (ok, stdout, stderr) = run(&[&base[..], &["--epochs", "1", "--seed", "2", "--out", r]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("training the humanoid ARNN") && stdout.contains("windows of 66 frames"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    let joints = config["skeleton"]["names"].as_array().unwrap().len();
    assert_eq!(config["dofs"].as_u64().unwrap() as usize, 3 + 4 * joints);
    assert_eq!(config["key_groups"].as_array().unwrap().len(), 3 + 4 * joints);
    // No frame phase by default on humanoid clips (not measured there).
    assert_eq!(config["curriculum"]["frame_phase"].as_f64(), Some(0.0), "{config}");
    // Resuming continues the humanoid run (its data recorded in train_state.json).
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", r]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("epoch   2"), "{stdout}");
    // A content held out of both splits: left out of the run, kept by its resumption, and
    // refused without humanoid clips or with another glob on resuming.
    let held = dir.path().join("held");
    let hr = held.to_str().unwrap();
    let exclude = ["--exclude-glob", "*_0003.bvh"];
    let (ok, stdout, stderr) = run(&[&base[..], &exclude[..], &["--epochs", "1", "--seed", "2", "--out", hr]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let all = std::fs::read_dir(&data)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "bvh"))
        .count();
    let notice = format!("--exclude-glob *_0003.bvh: left out 1 of {all} clips");
    assert!(stdout.contains(&notice) || stderr.contains(&notice), "{stdout}\n{stderr}");
    let state = std::fs::read_to_string(held.join("train_state.json")).unwrap();
    assert!(
        state.contains("\"exclude_glob\": \"*_0003.bvh\"") || state.contains("\"exclude_glob\":\"*_0003.bvh\""),
        "{state}"
    );
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", hr]);
    assert!(ok && (stdout.contains(&notice) || stderr.contains(&notice)), "{stdout}\n{stderr}");
    let (ok, _, stderr) =
        run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", hr, "--exclude-glob", "*_0004.bvh"]);
    assert!(!ok && stderr.contains("was started with --exclude-glob *_0003.bvh"), "{stderr}");
    let (ok, _, stderr) = run(&["train", "arnn", "--preset", "tiny", "--epochs", "1", "--exclude-glob", "*_0003.bvh"]);
    assert!(!ok && stderr.contains("--exclude-glob leaves humanoid clips of --data out"), "{stderr}");
    let method = format!("arnn:{r}");
    let bench = ["bench", "--data", d, "--valid-glob", "*_0005.bvh", "--lengths", "5,15"];
    let (ok, stdout, stderr) = run(&[&bench[..], &["--methods", &format!("interp,{method}")]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let row = stdout.lines().find(|l| l.trim_start().starts_with(&method)).unwrap_or_else(|| panic!("{stdout}"));
    let values: Vec<f64> = row.split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
    assert!(values.len() == 2 && values.iter().all(|v| v.is_finite() && *v >= 0.0), "{row}");
    let (ok, _, stderr) = run(&[&bench[..], &["--methods", &format!("arnn+lock:{r}")]].concat());
    assert!(!ok && stderr.contains("the ARNN in candle has no foot lock on transitions"), "{stderr}");
    // Completion of humanoid keys taken from a clip, one of them partial (the root and one
    // joint), written as a BVH on the clip's skeleton.
    let names: Vec<String> =
        config["skeleton"]["names"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
    let clip = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_str().unwrap().ends_with("_0005.bvh"))
        .unwrap();
    let keys_path = dir.path().join("keys.json");
    let write_keys = |joint: &str| {
        let text = format!(
            r#"{{"format": "zoo-arnn-keys", "version": 1, "bvh": "{}",
                "keys": [{{"frame": 0, "source_frame": 30}}, {{"frame": 12, "source_frame": 42, "joints": ["root", "{joint}"]}},
                         {{"frame": 30, "source_frame": 60}}]}}"#,
            clip.display()
        );
        std::fs::write(&keys_path, text).unwrap();
    };
    write_keys(&names[3]);
    let out = dir.path().join("done.bvh");
    let complete = |out: &Path| {
        run(&["complete", "--model", r, "--keys", keys_path.to_str().unwrap(), "--out", out.to_str().unwrap()])
    };
    let (ok, stdout, stderr) = complete(&out);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("completed 31 frames from 3 keys (1 partial)"), "{stdout}");
    let bvh = std::fs::read_to_string(&out).unwrap();
    assert!(bvh.contains(&names[3]) && bvh.contains("Frames: 31"), "{}", &bvh[..200.min(bvh.len())]);
    // Issue 46: the keys hit, the network's own miss reported beside.
    assert!(
        stdout.contains("the network's largest key miss") && stdout.contains("corrected towards the keys"),
        "{stdout}"
    );
    // A clip holding only the key poses (frames 30, 42, 60 of the clip), their frames given.
    let text = std::fs::read_to_string(&clip).unwrap();
    let (head, motion) = text.split_once("MOTION").unwrap();
    let lines: Vec<&str> = motion.lines().filter(|l| !l.trim().is_empty()).collect();
    let poses = [30, 42, 60].map(|f| lines[2 + f]).join("\n");
    let keys_bvh = dir.path().join("key_poses.bvh");
    std::fs::write(&keys_bvh, format!("{head}MOTION\nFrames: 3\n{}\n{poses}\n", lines[1])).unwrap();
    let kb = keys_bvh.to_str().unwrap();
    let from_poses = dir.path().join("from_poses.bvh");
    let fp = from_poses.to_str().unwrap();
    let (ok, stdout, stderr) = run(&["complete", "--model", r, "--poses", kb, "--key-frames", "0,12,30", "--out", fp]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("completed 31 frames from 3 keys (0 partial)"), "{stdout}");
    // The same keys sampled from the whole clip give the same motion.
    let sampled = dir.path().join("sampled.bvh");
    let args = ["complete", "--model", r, "--poses", clip.to_str().unwrap(), "--key-frames", "30,42,60", "--sample"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--out", sampled.to_str().unwrap()]].concat());
    assert!(ok && stdout.contains("completed 31 frames from 3 keys"), "{stdout}\n{stderr}");
    let motion_of = |p: &Path| std::fs::read_to_string(p).unwrap().split_once("MOTION").unwrap().1.to_string();
    assert_eq!(motion_of(&from_poses), motion_of(&sampled));
    // The whole clip at 60 fps: resampled to the model's 30 fps with a note, its key frames
    // carried over (60, 84, 120 are 30, 42, 60 at 30 fps), the output at the model's rate.
    let c60 = dir.path().join("c60.bvh");
    let (ok, _, stderr) = run(&["data", "resample", clip.to_str().unwrap(), c60.to_str().unwrap(), "--fps", "60"]);
    assert!(ok, "{stderr}");
    let sampled60 = dir.path().join("sampled60.bvh");
    let args = ["complete", "--model", r, "--poses", c60.to_str().unwrap(), "--key-frames", "60,84,120", "--sample"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--out", sampled60.to_str().unwrap()]].concat());
    assert!(ok && stdout.contains("completed 31 frames from 3 keys"), "{stdout}\n{stderr}");
    assert!(stderr.contains("is at 60.000 fps, the model at 30.000 fps: resampled to 30.000 fps"), "{stderr}");
    let (a, b) = (
        zoo_data::bvh::read_file(&sampled60, &Default::default()).unwrap(),
        zoo_data::bvh::read_file(&sampled, &Default::default()).unwrap(),
    );
    assert!((a.fps() - 30.0).abs() < 1e-3, "written at {} fps", a.fps());
    for f in [0, 12, 30] {
        assert!((a.root_position(f) - b.root_position(f)).length() < 1e-2, "frame {f}");
    }
    // A clip of key poses only says nothing by its frame rate: taken at the model's.
    let keys_bvh60 = dir.path().join("key_poses60.bvh");
    std::fs::write(&keys_bvh60, format!("{head}MOTION\nFrames: 3\nFrame Time: 0.0166667\n{poses}\n")).unwrap();
    let from60 = dir.path().join("from_poses60.bvh");
    let args = ["complete", "--model", r, "--poses", keys_bvh60.to_str().unwrap(), "--key-frames", "0,12,30"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--out", from60.to_str().unwrap()]].concat());
    assert!(ok && stdout.contains("completed 31 frames from 3 keys"), "{stdout}\n{stderr}");
    assert_eq!(motion_of(&from60), motion_of(&from_poses));
    let (ok, _, stderr) = run(&["complete", "--model", r, "--poses", kb, "--key-frames", "0,12", "--out", fp]);
    assert!(!ok && stderr.contains("2 key frames for a clip of 3 poses"), "{stderr}");
    let (ok, _, stderr) = run(&["complete", "--model", r, "--poses", kb, "--out", fp]);
    assert!(!ok && stderr.contains("give the key frames") && stderr.contains("only a glTF file"), "{stderr}");
    // A glTF file holding only the keys, at 0, 0.4 and 1 s: its key times give frames 0, 12, 30
    // at 30 fps, so it completes as the BVH of the same poses with --key-frames 0,12,30 does.
    let key_clip = zoo_data::clip_io::read_model_clip(&keys_bvh).unwrap();
    let gltf = keys_only_gltf(&key_clip, &[0.0, 0.4, 1.0]);
    let kg = dir.path().join("key_poses.gltf");
    std::fs::write(&kg, gltf).unwrap();
    let from_gltf = dir.path().join("from_gltf.bvh");
    let (ok, stdout, stderr) =
        run(&["complete", "--model", r, "--poses", kg.to_str().unwrap(), "--out", from_gltf.to_str().unwrap()]);
    assert!(ok && stdout.contains("completed 31 frames from 3 keys (0 partial)"), "{stdout}\n{stderr}");
    let (a, b) = (
        zoo_data::bvh::read_file(&from_gltf, &Default::default()).unwrap(),
        zoo_data::bvh::read_file(&from_poses, &Default::default()).unwrap(),
    );
    for f in [0, 12, 30] {
        assert!((a.root_position(f) - b.root_position(f)).length() < 1e-2, "frame {f}");
    }
    // The keys-only benchmark: the baselines and the run, whose keys are hit after its own misses.
    let json = dir.path().join("keys.json");
    let keys_bench = ["bench", "--data", d, "--valid-glob", "*_0005.bvh", "--layout", "keys", "--every", "10,30"];
    let methods = format!("linear,bezier,{method}");
    let (ok, stdout, stderr) =
        run(&[&keys_bench[..], &["--methods", &methods, "--json", json.to_str().unwrap()]].concat());
    assert!(ok && stdout.contains("keys every K frames (whole keys)"), "{stdout}\n{stderr}");
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for m in ["linear", "bezier", method.as_str()] {
        let row = &result["methods"][m];
        for k in [10, 30] {
            let l2p = row[format!("l2p@{k}")].as_f64().unwrap();
            assert!(l2p.is_finite() && l2p > 0.0, "{m} {k}: {row}");
            assert!(row[format!("keymiss_cm@{k}")].as_f64().unwrap() < 1e-3, "{m} {k}: {row}");
            assert!(row[format!("keymiss_deg@{k}")].as_f64().unwrap() < 1e-2, "{m} {k}: {row}");
        }
    }
    assert!(result["methods"][&method]["keymiss_raw_cm@30"].as_f64().unwrap() > 1e-3, "{result}");
    // A joint the skeleton does not have: refused, nothing written.
    write_keys("Tail");
    let refused_out = dir.path().join("refused.bvh");
    let (ok, _, stderr) = complete(&refused_out);
    assert!(!ok && stderr.contains("\"Tail\", which the model's skeleton does not have"), "{stderr}");
    assert!(!stderr.contains("panicked") && !refused_out.exists(), "{stderr}");
    // A lamp ARNN has no humanoid skeleton.
    let lamp = shared_model().join("run");
    let (ok, _, stderr) = run(&[&bench[..], &["--methods", &format!("arnn:{}", lamp.display())]].concat());
    assert!(!ok && stderr.contains("holds a lamp ARNN"), "{stderr}");
}

/// `clip` (one pose per key) as a glTF file whose animation keys the poses at `times` (seconds):
/// zoo's glTF writer with its key times replaced, as an animator's blocking pass exports them.
fn keys_only_gltf(clip: &zoo_motion::Clip, times: &[f32]) -> String {
    use base64::Engine;
    let text = zoo_data::gltf::to_gltf_json(clip);
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let engine = base64::engine::general_purpose::STANDARD;
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let (prefix, data) = uri.split_once("base64,").unwrap();
    let mut bytes = engine.decode(data).unwrap();
    let inputs: std::collections::BTreeSet<u64> =
        doc["animations"][0]["samplers"].as_array().unwrap().iter().map(|s| s["input"].as_u64().unwrap()).collect();
    for a in inputs {
        let acc = doc["accessors"][a as usize].clone();
        let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
        let start = (view["byteOffset"].as_u64().unwrap_or(0) + acc["byteOffset"].as_u64().unwrap_or(0)) as usize;
        assert_eq!(acc["count"].as_u64(), Some(times.len() as u64));
        for (i, t) in times.iter().enumerate() {
            bytes[start + 4 * i..start + 4 * i + 4].copy_from_slice(&t.to_le_bytes());
        }
        doc["accessors"][a as usize]["min"] = serde_json::json!([times[0]]);
        doc["accessors"][a as usize]["max"] = serde_json::json!([times[times.len() - 1]]);
    }
    doc["buffers"][0]["uri"] = serde_json::Value::String(format!("{prefix}base64,{}", engine.encode(&bytes)));
    if let Some(extras) = doc["animations"][0].get_mut("extras") {
        *extras = serde_json::json!({});
    }
    serde_json::to_string(&doc).unwrap()
}

/// Issue 46: the in-betweening design trains on BVH clips, resumes, scores in the keys-only
/// benchmark beside the baselines with every key met by the network itself, completes a keys
/// file with a partial key, and is refused where only the autoregressive ARNN runs.
#[test]
fn inbetween_design_trains_resumes_scores_keys_and_completes() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let d = data.to_str().unwrap();
    let (ok, _, stderr) = run(&["data", "synth", "--out", d, "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{stderr}");
    let runp = dir.path().join("ib");
    let r = runp.to_str().unwrap();
    let base = ["train", "arnn", "--design", "inbetween", "--data", d, "--valid-glob", "*_0005.bvh"];
    let (ok, stdout, stderr) =
        run(&[&base[..], &["--preset", "tiny", "--threads", "1", "--epochs", "1", "--seed", "2", "--out", r]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("training the in-betweening network"), "{stdout}");
    // The fallback towards the curves is calibrated on the validation windows at the end.
    assert!(stdout.contains("fallback calibrated on") && stdout.contains("stored in config.json"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    assert_eq!((config["model"].as_str(), config["design"].as_str()), (Some("arnn"), Some("inbetween")));
    assert_eq!(config["transition_fraction"].as_f64(), Some(0.0));
    assert!(config["fallback"]["gaps"][0]["start"].as_f64().is_some(), "{}", config["fallback"]);
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", r]);
    assert!(ok && stdout.contains("epoch   2") && stdout.contains("fallback calibrated"), "{stdout}\n{stderr}");
    // Methods of runs with a fallback are named with a `+fallback` suffix, as the RTN's.
    let method = format!("arnn:{r}+fallback");
    let json = dir.path().join("keys.json");
    let bench = ["bench", "--data", d, "--valid-glob", "*_0005.bvh", "--layout", "keys", "--every", "10,30"];
    let locked = format!("arnn+lock:{r}+fallback");
    let methods = format!("bezier,bezier+lock,arnn:{r},arnn+lock:{r}");
    let (ok, stdout, stderr) = run(&[&bench[..], &["--methods", &methods, "--json", json.to_str().unwrap()]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stderr.contains(&format!("{method}: the fallback towards the curves acted on")), "{stderr}");
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let row = &result["methods"][method.as_str()];
    for k in [10, 30] {
        assert!(row[format!("l2p@{k}")].as_f64().unwrap().is_finite(), "{row}");
        // Met by construction: the network's own miss is float rounding (the runtime's f32
        // poses, about 1e-7 of the root's distance from the origin).
        assert!(row[format!("keymiss_raw_cm@{k}")].as_f64().unwrap() < 1e-4, "{row}");
        assert!(row[format!("keymiss_raw_deg@{k}")].as_f64().unwrap() < 1e-3, "{row}");
        // The foot lock between the keys leaves every key hit.
        for m in [locked.as_str(), "bezier+lock"] {
            let row = &result["methods"][m];
            assert!(row[format!("skate@{k}")].as_f64().unwrap().is_finite(), "{m}: {row}");
            // The run through the runtime: its f32 poses (see above).
            let bound = if m == locked { 1e-4 } else { 1e-6 };
            assert!(row[format!("keymiss_cm@{k}")].as_f64().unwrap() < bound, "{m}: {row}");
            assert!(row[format!("keymiss_deg@{k}")].as_f64().unwrap() < 1e-3, "{m}: {row}");
        }
    }
    let (ok, _, stderr) = run(&[&bench[..], &["--methods", "cubic+lock"]].concat());
    assert!(!ok && stderr.contains("method `cubic` is not one of"), "{stderr}");
    let names: Vec<String> =
        config["skeleton"]["names"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
    let clip = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_str().unwrap().ends_with("_0005.bvh"))
        .unwrap();
    let keys_path = dir.path().join("keys.json");
    let text = format!(
        r#"{{"format": "zoo-arnn-keys", "version": 1, "bvh": "{}",
            "keys": [{{"frame": 0, "source_frame": 30}}, {{"frame": 12, "source_frame": 42, "joints": ["root", "{}"]}},
                     {{"frame": 30, "source_frame": 60}}]}}"#,
        clip.display(),
        names[3]
    );
    std::fs::write(&keys_path, text).unwrap();
    let out = dir.path().join("done.bvh");
    let (json, raw_json, raw_out) =
        (dir.path().join("done.json"), dir.path().join("raw.json"), dir.path().join("raw.bvh"));
    let kp = keys_path.to_str().unwrap();
    let (ok, stdout, stderr) = run(&[
        "complete",
        "--model",
        r,
        "--keys",
        kp,
        "--out",
        out.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok && stdout.contains("completed 31 frames from 3 keys (1 partial)"), "{stdout}\n{stderr}");
    assert!(stdout.contains("the network's largest key miss: root 0.00"), "{stdout}");
    assert!(stdout.contains("feet locked between the keys on 28 frames"), "{stdout}");
    let args = ["--out", raw_out.to_str().unwrap(), "--json", raw_json.to_str().unwrap(), "--no-foot-lock"];
    let (ok, stdout, stderr) = run(&[&["complete", "--model", r, "--keys", kp][..], &args].concat());
    assert!(ok && stdout.contains("no foot lock (--no-foot-lock)"), "{stdout}\n{stderr}");
    let lock_frames = |p: &Path| {
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
        v["foot_lock_frames"].as_u64()
    };
    assert_eq!((lock_frames(&json), lock_frames(&raw_json)), (Some(28), Some(0)));
    // The lock changes frames between the keys only: the key frames are written alike.
    let motion = |p: &Path| -> Vec<String> {
        let text = std::fs::read_to_string(p).unwrap();
        text.lines().skip_while(|l| !l.starts_with("Frame Time")).skip(1).map(str::to_string).collect()
    };
    let (locked_rows, raw_rows) = (motion(&out), motion(&raw_out));
    assert_eq!(locked_rows.len(), 31);
    for key in [0, 12, 30] {
        assert_eq!(locked_rows[key], raw_rows[key], "key frame {key}");
    }
    // `--no-fallback`: the network alone, as the same run folder without its fallback completes.
    let whole_keys = dir.path().join("whole_keys.json");
    let text = format!(
        r#"{{"format": "zoo-arnn-keys", "version": 1, "bvh": "{}",
            "keys": [{{"frame": 0, "source_frame": 30}}, {{"frame": 12, "source_frame": 42}},
                     {{"frame": 30, "source_frame": 60}}]}}"#,
        clip.display()
    );
    std::fs::write(&whole_keys, text).unwrap();
    let bare = dir.path().join("ib_bare");
    std::fs::create_dir_all(&bare).unwrap();
    for f in ["model.safetensors", "normalization.json"] {
        std::fs::copy(runp.join(f), bare.join(f)).unwrap();
    }
    let mut bare_config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    assert!(bare_config["fallback"].is_object(), "{bare_config}");
    bare_config.as_object_mut().unwrap().remove("fallback");
    std::fs::write(bare.join("config.json"), bare_config.to_string()).unwrap();
    let (alone, from_bare) = (dir.path().join("alone.bvh"), dir.path().join("bare.bvh"));
    let wk = whole_keys.to_str().unwrap();
    let (ok, stdout, stderr) =
        run(&["complete", "--model", r, "--keys", wk, "--out", alone.to_str().unwrap(), "--no-fallback"]);
    assert!(ok, "{stdout}\n{stderr}");
    let (ok, stdout, stderr) =
        run(&["complete", "--model", bare.to_str().unwrap(), "--keys", wk, "--out", from_bare.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    assert_eq!(
        std::fs::read(&alone).unwrap(),
        std::fs::read(&from_bare).unwrap(),
        "--no-fallback is not the network alone"
    );
    // A fallback that hands every interval to the curves: the foot lock follows it and leaves
    // them as the curves draw them (the same folder without a fallback locks the feet).
    let curves = dir.path().join("ib_curves");
    std::fs::create_dir_all(&curves).unwrap();
    for f in ["model.safetensors", "normalization.json"] {
        std::fs::copy(runp.join(f), curves.join(f)).unwrap();
    }
    let mut curves_config = bare_config.clone();
    curves_config["fallback"] = serde_json::json!({"gaps": [{"up_to": 100, "start": 0.0, "full": 1e-6}]});
    std::fs::write(curves.join("config.json"), curves_config.to_string()).unwrap();
    for (model, frames) in [(&curves, 0), (&bare, 28)] {
        let j = dir.path().join("lock.json");
        let o = dir.path().join("lock.bvh");
        let m = model.to_str().unwrap();
        let (ok, stdout, stderr) =
            run(&["complete", "--model", m, "--keys", wk, "--out", o.to_str().unwrap(), "--json", j.to_str().unwrap()]);
        assert!(ok, "{stdout}\n{stderr}");
        assert_eq!(lock_frames(&j), Some(frames), "{m}: {stdout}");
    }
    // The in-betweening benchmark's transitions: the context and the target as keys, the whole
    // gap in one pass; trained with a share of its batches in that layout.
    let tr = dir.path().join("ib_transitions");
    let trs = tr.to_str().unwrap();
    let args = ["--preset", "tiny", "--threads", "1", "--epochs", "1", "--transition-fraction", "0.5", "--out", trs];
    let (ok, stdout, stderr) = run(&[&base[..], &args].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let tconfig: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tr.join("config.json")).unwrap()).unwrap();
    assert_eq!(tconfig["transition_fraction"].as_f64(), Some(0.5));
    let tjson = dir.path().join("transitions.json");
    let tmethod = format!("arnn:{trs}+fallback");
    let (tlocked, tcandle) = (format!("arnn+lock:{trs}+fallback"), format!("candle-arnn:{trs}"));
    let (ok, stdout, stderr) = run(&[
        "bench",
        "--data",
        d,
        "--valid-glob",
        "*_0005.bvh",
        "--lengths",
        "5,15",
        "--methods",
        &format!("interp,arnn:{r},arnn:{trs},arnn+lock:{trs},{tcandle}"),
        "--json",
        tjson.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&tjson).unwrap()).unwrap();
    let value = |m: &str, key: &str| result["methods"][m][key].as_f64().unwrap_or(f64::NAN);
    for n in [5, 15] {
        for m in [method.as_str(), tmethod.as_str(), tlocked.as_str(), tcandle.as_str()] {
            assert!(value(m, &format!("l2p@{n}")).is_finite(), "{m} at {n}: {}", result["methods"][m]);
        }
        // `arnn:` runs the runtime's keyframes task (tract), `candle-arnn:` the training model:
        // the same transitions up to f32 rounding.
        for key in [format!("l2p@{n}"), format!("l2q@{n}")] {
            let (runtime, candle) = (value(&tmethod, &key), value(&tcandle, &key));
            assert!((runtime - candle).abs() < 1e-3, "{key}: runtime {runtime}, candle {candle}");
        }
    }
    let (ok, _, stderr) =
        run(&["bench", "--data", d, "--valid-glob", "*_0005.bvh", "--methods", &format!("candle-arnn+lock:{trs}")]);
    assert!(!ok && stderr.contains("the ARNN in candle has no foot lock on transitions"), "{stderr}");
    let (ok, _, stderr) = run(&["train", "arnn", "--transition-fraction", "0.5", "--epochs", "1", "--out", trs]);
    assert!(!ok && stderr.contains("--transition-fraction sets the in-betweening design's"), "{stderr}");
    // `zoo export` writes its whole-shot graph, which the runtime's keyframes task loads (the
    // portable profile and reference vectors are refused by name, before anything is written).
    let onnx = dir.path().join("ib.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", r, "--out", onnx.to_str().unwrap()]);
    assert!(ok && stdout.contains("ARNN in-betweening whole-shot graph"), "{stdout}\n{stderr}");
    let km = zoo_runtime::KeyframeModel::load(&onnx).unwrap();
    assert!(km.is_inbetween() && km.groups() == names.len() + 1, "{} groups", km.groups());
    // `zoo complete` runs the exported file as it runs the run folder (exported in memory).
    let from_file = dir.path().join("done_file.bvh");
    let (ok, _, stderr) =
        run(&["complete", "--model", onnx.to_str().unwrap(), "--keys", kp, "--out", from_file.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert_eq!(
        std::fs::read(&from_file).unwrap(),
        std::fs::read(&out).unwrap(),
        "the exported file completes otherwise"
    );
    // `zoo transition` runs the design on a transition's layout (the context frames and the
    // target are its keys): the --from clip up to its frame, the gap, then the --to clip, the
    // target frame's joint rotations as the clip's.
    let c = clip.to_str().unwrap();
    let tr = dir.path().join("tr.bvh");
    let transition = |extra: &[&str]| {
        let (from, to) = (format!("{c}:40"), format!("{c}:60"));
        let base = ["transition", "--model", r, "--from", &from, "--to", &to, "--frames", "12"];
        run(&[&base[..], &["--out", tr.to_str().unwrap()], extra].concat())
    };
    let (ok, stdout, stderr) = transition(&["--foot-lock"]);
    assert!(
        ok && stdout.contains("the gap filled in one call") && stdout.contains("12 generated"),
        "{stdout}\n{stderr}"
    );
    let src = zoo_data::bvh::read_file(&clip, &Default::default()).unwrap();
    let got = zoo_data::bvh::read_file(&tr, &Default::default()).unwrap();
    assert_eq!(got.frames(), 40 + 12 + src.frames() - 60);
    let j = src.joints();
    for (f, g) in [(39, 39), (60, 52)] {
        for k in 1..j {
            let (a, b) = (src.local_rotations[f * j + k], got.local_rotations[g * j + k]);
            assert!(a.dot(b).abs() > 1.0 - 1e-6, "frame {g}, joint {k}: {a:?} vs {b:?}");
        }
    }
    assert!(got.local_rotations.iter().all(|q| q.is_finite()));
    let (ok, _, stderr) = transition(&["--positions", dir.path().join("p.json").to_str().unwrap()]);
    assert!(!ok && stderr.contains("--positions: the in-betweening network"), "{stderr}");
    let arnn = dir.path().join("lamp.onnx");
    zoo_tests::tiny_arnn_onnx().write(&arnn).unwrap();
    let (from, to) = (format!("{c}:40"), format!("{c}:60"));
    let (ok, _, stderr) = run(&[
        "transition",
        "--model",
        arnn.to_str().unwrap(),
        "--from",
        &from,
        "--to",
        &to,
        "--out",
        tr.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("is an ARNN step graph"), "{stderr}");
    let portable = dir.path().join("ib_portable.onnx");
    let (ok, _, stderr) = run(&["export", "--onnx", r, "--out", portable.to_str().unwrap(), "--portable"]);
    assert!(!ok && stderr.contains("does not hold; export it without --portable") && !portable.exists(), "{stderr}");
    // The export through the runtime scores as the training model in candle does in the
    // keys-only benchmark, with its own foot lock as with the benchmark's.
    // Both apply the run's fallback (the file carries it); the runtime's methods say so in
    // their names.
    let (o, ol) = (format!("onnx:{}", onnx.display()), format!("onnx+lock:{}", onnx.display()));
    let (method, locked) = (format!("candle-arnn:{r}"), format!("candle-arnn+lock:{r}"));
    let json = dir.path().join("keys_onnx.json");
    let methods = format!("{method},{locked},{o},{ol}");
    let (ok, stdout, stderr) = run(&[&bench[..], &["--methods", &methods, "--json", json.to_str().unwrap()]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let (o, ol) = (format!("{o}+fallback"), format!("{ol}+fallback"));
    let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for (candle, runtime) in [(&method, &o), (&locked, &ol)] {
        for k in [10, 30] {
            for m in ["l2p", "l2q", "npss", "skate"] {
                let key = format!("{m}@{k}");
                let (a, b) = (&result["methods"][candle.as_str()][&key], &result["methods"][runtime.as_str()][&key]);
                let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
                assert!((a - b).abs() <= 1e-4 * a.abs().max(1e-3), "{key}: {candle} {a}, {runtime} {b}");
            }
            assert!(result["methods"][runtime.as_str()][format!("keymiss_cm@{k}")].as_f64().unwrap() < 1e-2);
        }
    }
}

/// `--synth-mix MINUTES` mixes the synthetic generator's locomotion into an in-betweening run's
/// training split (recorded, kept on resume), and is refused with the fix on data of another
/// skeleton, on a resume that asks for another amount, and outside the in-betweening design.
#[test]
fn inbetween_synth_mix_adds_synthetic_locomotion_and_is_refused_where_it_cannot_apply() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let d = data.to_str().unwrap();
    let (ok, _, stderr) = run(&["data", "synth", "--out", d, "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{stderr}");
    let runp = dir.path().join("mix");
    let r = runp.to_str().unwrap();
    let base = ["train", "arnn", "--design", "inbetween", "--data", d, "--valid-glob", "*_0005.bvh"];
    let tiny = ["--preset", "tiny", "--threads", "1", "--epochs", "1", "--seed", "2"];
    let (ok, stdout, stderr) = run(&[&base[..], &tiny[..], &["--synth-mix", "0.5", "--out", r]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    // 30 seconds of clips of 10 seconds.
    assert!(stdout.contains("--synth-mix 0.5: 3 synthetic clips"), "{stdout}");
    assert!(stdout.contains("training clips with 0.5 min of synthetic locomotion"), "{stdout}");
    let windows = |s: &str| -> usize {
        let (head, _) = s.split_once(" training / ").unwrap();
        head.rsplit(' ').next().unwrap().parse().unwrap()
    };
    let plain = dir.path().join("plain");
    let (ok, plain_out, stderr) = run(&[&base[..], &tiny[..], &["--out", plain.to_str().unwrap()]].concat());
    assert!(ok, "{plain_out}\n{stderr}");
    assert!(windows(&stdout) > windows(&plain_out), "{stdout}\n{plain_out}");
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("train_state.json")).unwrap()).unwrap();
    assert_eq!(state["humanoid_data"]["synth_mix"].as_f64(), Some(0.5), "{state}");
    // A resume keeps the recorded mix; asking for another one is refused.
    let (ok, _, stderr) = run(&["train", "arnn", "--epochs", "2", "--resume", r, "--data", d, "--synth-mix", "1"]);
    assert!(
        !ok && stderr.contains("was started with --synth-mix 0.5") && stderr.contains("drop --synth-mix"),
        "{stderr}"
    );
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", r]);
    assert!(
        ok && stdout.contains("epoch   2") && stdout.contains("--synth-mix 0.5: 3 synthetic clips"),
        "{stdout}\n{stderr}"
    );
    // Data on another skeleton: named, with the fix.
    let other = dir.path().join("other");
    std::fs::create_dir(&other).unwrap();
    for (name, phase) in [("a.bvh", 0.0), ("b.bvh", 1.0)] {
        std::fs::write(other.join(name), zoo_data::bvh::to_string(&zoo_tests::toy_clip(90, phase))).unwrap();
    }
    let o = other.to_str().unwrap();
    let args = ["train", "arnn", "--design", "inbetween", "--data", o, "--valid-glob", "b.bvh", "--synth-mix", "1"];
    let (ok, _, stderr) = run(&[&args[..], &tiny[..], &["--out", dir.path().join("o").to_str().unwrap()]].concat());
    assert!(!ok && stderr.contains("bandai2's skeleton") && stderr.contains("leave --synth-mix out"), "{stderr}");
    // The autoregressive ARNN has no use for it.
    let ar = ["train", "arnn", "--data", d, "--valid-glob", "*_0005.bvh", "--synth-mix", "1", "--preset", "tiny"];
    let (ok, _, stderr) = run(&[&ar[..], &["--out", dir.path().join("ar").to_str().unwrap()]].concat());
    assert!(!ok && stderr.contains("add --design inbetween"), "{stderr}");
}
/// `--backbone transformer`: the in-betweening design with a transformer encoder over the shot
/// trains (recorded in `config.json`), resumes with its own backbone (another refused), runs in
/// `zoo bench` through the runtime on both layouts, and is refused outside the design.
#[test]
fn inbetween_transformer_backbone_trains_resumes_and_runs_in_the_benchmark() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let d = data.to_str().unwrap();
    let (ok, _, stderr) = run(&["data", "synth", "--out", d, "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{stderr}");
    let runp = dir.path().join("tf");
    let r = runp.to_str().unwrap();
    let base = ["train", "arnn", "--design", "inbetween", "--data", d, "--valid-glob", "*_0005.bvh"];
    let tiny = ["--preset", "tiny", "--threads", "1", "--epochs", "1", "--seed", "2", "--transition-fraction", "0.5"];
    let transformer = ["--backbone", "transformer", "--dropout", "0.1", "--out", r];
    let (ok, stdout, stderr) = run(&[&base[..], &tiny[..], &transformer[..]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("training the in-betweening network (transformer)"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    assert_eq!((config["backbone"].as_str(), config["heads"].as_u64()), (Some("transformer"), Some(2)), "{config}");
    assert_eq!(config["dropout"].as_f64(), Some(0.1), "{config}");
    let (ok, _, stderr) = run(&["train", "arnn", "--epochs", "2", "--resume", r, "--backbone", "bgru"]);
    assert!(!ok && stderr.contains("drop --backbone"), "{stderr}");
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", r]);
    assert!(ok && stdout.contains("epoch   2") && stdout.contains("(transformer)"), "{stdout}\n{stderr}");
    for layout in [&["--layout", "keys", "--every", "10"][..], &["--lengths", "15"][..]] {
        let json = dir.path().join("bench.json");
        let bench = ["bench", "--data", d, "--valid-glob", "*_0005.bvh", "--methods"];
        let methods = format!("arnn:{r}");
        let args = [&bench[..], &[methods.as_str(), "--json", json.to_str().unwrap()], layout].concat();
        let (ok, stdout, stderr) = run(&args);
        assert!(ok, "{stdout}\n{stderr}");
        let result: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let row = &result["methods"][format!("arnn:{r}+fallback").as_str()];
        let l2p = row.as_object().unwrap().iter().find(|(k, _)| k.starts_with("l2p@")).map(|(_, v)| v.as_f64());
        assert!(l2p.flatten().is_some_and(f64::is_finite), "{row}");
    }
    let ar = ["train", "arnn", "--data", d, "--valid-glob", "*_0005.bvh", "--backbone", "transformer"];
    let (ok, _, stderr) =
        run(&[&ar[..], &["--preset", "tiny", "--out", dir.path().join("ar").to_str().unwrap()]].concat());
    assert!(!ok && stderr.contains("add --design inbetween"), "{stderr}");
    let ar = ["train", "arnn", "--data", d, "--valid-glob", "*_0005.bvh", "--dropout", "0.1"];
    let (ok, _, stderr) =
        run(&[&ar[..], &["--preset", "tiny", "--out", dir.path().join("ar").to_str().unwrap()]].concat());
    assert!(!ok && stderr.contains("--dropout sets the in-betweening design's dropout"), "{stderr}");
    let (ok, _, stderr) = run(&[&base[..], &tiny[..], &["--dropout", "1", "--out", r]].concat());
    assert!(!ok && stderr.contains("--dropout") && stderr.contains("valid range [0, 1)"), "{stderr}");
}

/// `zoo bench keyframes` on an in-betweening file times whole transitions in one call, beside an
/// RTN's start and steps on the same gap (`--against`), and writes both per batch size; an RTN
/// where the in-betweener belongs, and `--against` beside an ARNN step graph, are refused by name.
#[test]
fn keyframes_bench_times_whole_transitions_beside_the_rtn() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, model: zoo_export::OnnxModel| {
        let path = dir.path().join(name);
        model.write(&path).unwrap();
        path.to_str().unwrap().to_string()
    };
    let (ib, rtn, arnn) = (
        write("ib.onnx", zoo_tests::tiny_inbetween_onnx()),
        write("rtn.onnx", zoo_tests::tiny_rtn_onnx()),
        write("arnn.onnx", zoo_tests::tiny_arnn_onnx()),
    );
    let json = dir.path().join("cost.json");
    let base = ["bench", "keyframes", "--batch", "1,3", "--rounds", "2", "--work", "10", "--gap", "7"];
    let (ok, stdout, stderr) =
        run(&[&base[..], &["--model", &ib, "--against", &rtn, "--json", json.to_str().unwrap()]].concat());
    assert!(
        ok && stdout.contains("whole shot (one call)") && stdout.contains("RTN (start + 8 steps)"),
        "{stdout}\n{stderr}"
    );
    let figures: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let figures = figures.as_array().unwrap();
    assert_eq!(figures.len(), 4, "{figures:?}");
    for (f, (batch, method)) in figures.iter().zip([(1, "whole"), (1, "RTN"), (3, "whole"), (3, "RTN")]) {
        assert_eq!(f["batch"].as_u64(), Some(batch));
        assert!(f["method"].as_str().unwrap().starts_with(method), "{f}");
        assert_eq!(f["gap"].as_u64(), Some(7));
        assert_eq!(f["rounds_cpu_ms"].as_array().unwrap().len(), 2);
        assert!(f["wall_ms"].as_f64().unwrap() > 0.0 && f["cpu_ms"].as_f64().unwrap() >= 0.0, "{f}");
    }
    let (ok, _, stderr) = run(&[&base[..], &["--model", &ib, "--against", &arnn]].concat());
    assert!(!ok && stderr.contains("it takes an RTN written by `zoo export --onnx`"), "{stderr}");
    let (ok, _, stderr) = run(&[&base[..], &["--model", &arnn, "--against", &rtn]].concat());
    assert!(!ok && stderr.contains("is an ARNN step graph"), "{stderr}");
}
