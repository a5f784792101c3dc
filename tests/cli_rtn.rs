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
    // The default trains over the benchmark's lengths 5-45 with the time-to-arrival input.
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(runp.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["train"]["lengths"], serde_json::json!([5, 45]), "{config}");
    assert_eq!(
        (config["transition_frames"].as_u64(), config["time_to_arrival"]["dims"].as_u64()),
        (Some(45), Some(16))
    );
    // Resuming on other data (here more synthetic minutes) is refused and changes nothing.
    let state_before = std::fs::read(runp.join("train_state.json")).unwrap();
    let (ok, stdout, stderr) = run(&["train", "rtn", "--synth-minutes", "3", "--epochs", "2", "--resume", run_dir]);
    assert!(
        !ok && stderr.contains("--synth-minutes 3: the run in")
            && stderr.contains("was started with --synth-minutes 2"),
        "{stdout}\n{stderr}"
    );
    assert_eq!(std::fs::read(runp.join("train_state.json")).unwrap(), state_before);
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
    let clips = synth_clips(&data, &["--minutes", "1", "--seed", "3"]);
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
    // A skeleton without foot joints has nothing to lock: --foot-lock is refused, not ignored.
    let mut footless = ca.clone();
    for n in &mut footless.skeleton.names {
        *n = n.replace("Foot", "Ankle");
    }
    let footless_path = dir.path().join("footless.bvh");
    zoo_data::bvh::write_file(&footless, &footless_path).unwrap();
    let nolock = dir.path().join("t_nolock.bvh");
    let from = format!("{}:60", footless_path.display());
    let args = ["transition", "--model", run_dir, "--from", &from, "--to", &format!("{b}:40"), "--foot-lock"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--out", nolock.to_str().unwrap()]].concat());
    assert!(
        !ok && stderr.contains("--foot-lock: the skeleton of") && stderr.contains("has no foot joint"),
        "{stdout}\n{stderr}"
    );
    assert!(!nolock.exists());
    let rebuilt = dir.path().join("r.bvh");
    let (ok, stdout, stderr) = run(&["decompress", "--model", run_dir, a, "--out", rebuilt.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("mean joint position error"), "{stdout}");
    let r = zoo_data::bvh::read_file(&rebuilt, &Default::default()).unwrap();
    // Every frame comes back: those after the last keyframe in-betweened to the clip's last one.
    assert_eq!(r.frames(), ca.frames(), "{stdout}");
    assert!(stdout.contains("after the last keyframe in-betweened"), "{stdout}");
    assert!((r.root_position(r.frames() - 1) - ca.root_position(ca.frames() - 1)).length() < 1e-3);
    assert!(r.local_rotations.iter().all(|q| q.is_finite()));
    let (ok, stdout, stderr) =
        run(&["decompress", "--model", run_dir, a, "--interval", "1", "--out", rebuilt.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    assert_eq!(zoo_data::bvh::read_file(&rebuilt, &Default::default()).unwrap().frames(), ca.frames(), "{stdout}");
    // A clip whose dummy root carries motion is folded into its child by every command, as a
    // folder's clips are: the same file works for transition and decompress.
    let moving = dir.path().join("moving.bvh");
    std::fs::write(&moving, zoo_tests::under_dummy_root(&ca, true)).unwrap();
    let from = format!("{}:60", moving.display());
    let folded = dir.path().join("t_folded.bvh");
    let (ok, stdout, stderr) = run(&[
        "transition",
        "--model",
        run_dir,
        "--from",
        &from,
        "--to",
        &format!("{b}:40"),
        "--out",
        folded.to_str().unwrap(),
    ]);
    assert!(ok && stderr.contains("its dummy root `joint_Root` carries motion; folded into"), "{stdout}\n{stderr}");
    let (ok, stdout, stderr) =
        run(&["decompress", "--model", run_dir, moving.to_str().unwrap(), "--out", rebuilt.to_str().unwrap()]);
    assert!(ok && stderr.contains("carries motion; folded"), "{stdout}\n{stderr}");

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
    // The run calibrated its fallback, which both paths apply (names suffixed `+fallback`).
    for (candle, runtime) in [
        (format!("rtn:{run_dir}+fallback"), format!("onnx:{onnx}+fallback")),
        (format!("rtn+lock:{run_dir}+fallback"), format!("onnx+lock:{onnx}+fallback")),
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
    assert!(!stdout.contains("note:"), "every backend agrees with tract f32 on the first step:\n{stdout}");
    for backend in ["candle", "tract", "onnxruntime"] {
        let rows = stdout.lines().filter(|l| l.split_whitespace().nth(1) == Some(backend)).count();
        assert_eq!(rows, 2, "one row per batch size for {backend}:\n{stdout}");
    }
}

/// `--lengths` trains with the time-to-arrival input unless `--time-to-arrival 0` says otherwise;
/// its size is checked before any training.
#[test]
fn training_over_lengths_reads_the_time_to_arrival() {
    let dir = tempfile::tempdir().unwrap();
    let config = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["train", "rtn", "--preset", "tiny", "--synth-minutes", "0.5", "--epochs", "1"];
        args.extend(["--lengths", "3-8", "--out", out.to_str().unwrap()]);
        args.extend(extra);
        let (ok, stdout, stderr) = run(&args);
        assert!(ok, "{stdout}\n{stderr}");
        let c: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("config.json")).unwrap()).unwrap();
        c["time_to_arrival"].clone()
    };
    assert_eq!(config("default", &[]), serde_json::json!({"dims": 16, "max": 8}));
    assert_eq!(config("off", &["--time-to-arrival", "0"]), serde_json::Value::Null);
    assert_eq!(config("four", &["--time-to-arrival", "4"]), serde_json::json!({"dims": 4, "max": 8}));
    // Over lengths that hold two validation lengths (5 and 15) the fallback is calibrated at each.
    let out = dir.path().join("wide");
    let args = ["train", "rtn", "--preset", "tiny", "--synth-minutes", "0.5", "--epochs", "1", "--lengths", "3-16"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("fallback at 5 frames") && stdout.contains("fallback at 15 frames"), "{stdout}");
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("config.json")).unwrap()).unwrap();
    let table = c["fallback_lengths"].as_array().unwrap();
    assert_eq!(table.iter().map(|e| e["length"].as_u64().unwrap()).collect::<Vec<_>>(), [5, 15]);
    assert!(table.iter().all(|e| e["start"].as_f64().unwrap() > 0.0 && e["full"].as_f64() > e["start"].as_f64()));
    let out = dir.path().join("odd");
    let (ok, _, stderr) = run(&[
        "train",
        "rtn",
        "--preset",
        "tiny",
        "--synth-minutes",
        "0.5",
        "--lengths",
        "3-8",
        "--time-to-arrival",
        "7",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("--time-to-arrival 7") && stderr.contains("even number"), "{stderr}");
}

/// `--lengths N-N` trains one length without the time input; `--speed-range` needs `--augment
/// speed`, and a range faster than the standard one trains (on continued windows) and is
/// recorded; `--synth-runs` mixes synthetic running into the training split.
#[test]
fn one_length_speed_ranges_and_synthetic_running() {
    let dir = tempfile::tempdir().unwrap();
    let train = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args = vec!["train", "rtn", "--preset", "tiny", "--synth-minutes", "0.5", "--epochs", "1"];
        args.extend(["--out", out.to_str().unwrap()]);
        args.extend(extra);
        let (ok, stdout, stderr) = run(&args);
        let config = ok.then(|| {
            serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(out.join("config.json")).unwrap())
                .unwrap()
        });
        (config, stdout, stderr)
    };
    let (c, out, err) = train("one", &["--lengths", "9-9"]);
    let c = c.unwrap_or_else(|| panic!("{out}\n{err}"));
    assert_eq!((c["transition_frames"].as_u64(), &c["time_to_arrival"]), (Some(9), &serde_json::Value::Null));
    assert_eq!(c["train"]["lengths"], serde_json::Value::Null);
    let (c, _, err) = train("no-aug", &["--speed-range", "0.7-2.0"]);
    assert!(c.is_none() && err.contains("--speed-range sets the factors of --augment speed"), "{err}");
    let (c, out, err) = train("fast", &["--augment", "speed", "--speed-range", "0.8-2.5", "--lengths", "3-8"]);
    let c = c.unwrap_or_else(|| panic!("{out}\n{err}"));
    assert_eq!(c["train"]["augment"]["speed_range"], serde_json::json!([0.8, 2.5]));
    let (c, out, err) = train("runs", &["--synth-runs", "0.5"]);
    assert!(c.is_some() && out.contains("--synth-runs 0.5: 3 clips"), "{out}\n{err}");
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

/// The arguments of a tiny RTN run on one minute of synthetic motion.
fn tiny_run<'a>(folder_flag: &'a str, folder: &'a str, epochs: &'a str) -> Vec<&'a str> {
    let mut args = vec!["train", "rtn", "--preset", "tiny", "--synth-minutes", "1", "--seed", "5"];
    args.extend(["--epochs", epochs, folder_flag, folder]);
    args
}

/// `zoo data synth --out DIR ARGS`: the BVH clips it wrote, sorted.
fn synth_clips(dir: &std::path::Path, args: &[&str]) -> Vec<std::path::PathBuf> {
    let mut all = vec!["data", "synth", "--out", dir.to_str().unwrap()];
    all.extend(args);
    let (ok, _, stderr) = run(&all);
    assert!(ok, "{stderr}");
    let mut clips: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    clips.sort();
    clips
}

fn tiny_command(args: &[&str]) -> Command {
    let mut c = Command::new(zoo_bin());
    // One thread: the same arithmetic in every process, and no barrier spinning on a busy machine.
    c.args(args).env("RAYON_NUM_THREADS", "1");
    c
}

fn read_state(folder: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(folder.join("train_state.json")).unwrap()).unwrap()
}

/// A run killed (SIGKILL) during epoch 2 and resumed ends with the same per-epoch losses and
/// the same weights, bit for bit, as the same run left alone: the shuffle generator, the
/// trainer's generator (rotations, teacher forcing), AMSGrad and the moving average are all
/// restored from `last/`.
#[test]
fn resume_after_sigkill_continues_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let (whole, killed) = (dir.path().join("whole"), dir.path().join("killed"));
    let (whole_s, killed_s) = (whole.to_str().unwrap(), killed.to_str().unwrap());
    let out = tiny_command(&tiny_run("--out", whole_s, "3")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let reference = read_state(&whole);
    let epoch_secs = reference["seconds"].as_f64().unwrap() / 3.0;

    let mut child = tiny_command(&tiny_run("--out", killed_s, "3"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    loop {
        let epoch = std::fs::read_to_string(killed.join("train_state.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|v| v["epoch"].as_u64());
        if epoch == Some(1) {
            break;
        }
        assert!(child.try_wait().unwrap().is_none(), "the run ended before it could be interrupted");
        assert!(std::time::Instant::now() < deadline, "epoch 1 never finished");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    // A little into epoch 2, not a third of it: epochs of the tiny run take about 0.1 s, and
    // with other tests beside it a third of one was sometimes enough for epoch 2 to end first.
    std::thread::sleep(std::time::Duration::from_secs_f64(epoch_secs / 10.0));
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(read_state(&killed)["epoch"], 1, "the kill landed after epoch 2 (epochs take {epoch_secs:.2} s)");

    let out = tiny_command(&tiny_run("--resume", killed_s, "3")).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        stdout.contains("epoch   2:") && stdout.contains("epoch   3:") && !stdout.contains("epoch   1:"),
        "{stdout}"
    );
    let resumed = read_state(&killed);
    for key in ["epoch", "steps", "train_loss", "valid_loss", "valid_loss_ema", "best_epoch", "shuffle_rng"] {
        assert_eq!(resumed[key], reference[key], "{key}");
    }
    for f in ["model.safetensors", "last/model.safetensors", "last/optimizer.safetensors", "last/ema.safetensors"] {
        assert!(std::fs::read(whole.join(f)).unwrap() == std::fs::read(killed.join(f)).unwrap(), "{f} differs");
    }
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["model"], "rtn");
}

/// A tiny RTN trained for one epoch on one minute of synthetic motion, and a synthetic BVH
/// clip of its skeleton: `(run folder, clip)`.
fn tiny_model(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let run_dir = dir.join("run");
    let out = tiny_command(&tiny_run("--out", run_dir.to_str().unwrap(), "1")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let clip = synth_clips(&dir.join("synth"), &["--minutes", "0.5", "--seed", "3"]).swap_remove(0);
    (run_dir, clip)
}

fn transition_args(
    model: &std::path::Path,
    clip: &std::path::Path,
    frames: &str,
    out: &std::path::Path,
) -> Vec<String> {
    let c = clip.display();
    ["transition", "--model", &model.display().to_string(), "--from", &format!("{c}:20"), "--to", &format!("{c}:60")]
        .iter()
        .map(|s| s.to_string())
        .chain(["--frames".into(), frames.into(), "--out".into(), out.display().to_string()])
        .collect()
}

fn zoo(args: &[String]) -> (bool, String, String) {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    run(&refs)
}

/// `--out` on a folder that holds a trained run refuses (the run is untouched) unless
/// `--resume` or `--overwrite` says what to do.
#[test]
fn train_refuses_to_replace_a_trained_run_without_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let s = run_dir.to_str().unwrap();
    let out = tiny_command(&tiny_run("--out", s, "1")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let weights = std::fs::read(run_dir.join("model.safetensors")).unwrap();
    let out = tiny_command(&tiny_run("--out", s, "1")).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "a second run into the same folder must be refused");
    assert!(
        err.contains("already holds a run trained for 1 epochs")
            && err.contains("--resume")
            && err.contains("--overwrite"),
        "{err}"
    );
    assert!(std::fs::read(run_dir.join("model.safetensors")).unwrap() == weights, "the trained model was touched");
    let mut args = tiny_run("--out", s, "1");
    args.push("--overwrite");
    let out = tiny_command(&args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("the new run finished its first epoch; the old run is deleted"), "{stdout}");
    assert_eq!(read_state(&run_dir)["epoch"], 1);
}

/// The candle path (transition), the exporter and a resume refuse a run folder whose
/// statistics or configuration the runtime would refuse, with the file and the problem.
#[test]
fn broken_run_folders_are_refused_by_transition_export_and_resume() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clip) = tiny_model(dir.path());
    let stats_path = model.join("normalization.json");
    let good_stats = std::fs::read_to_string(&stats_path).unwrap();
    let config_path = model.join("config.json");
    let good_config = std::fs::read_to_string(&config_path).unwrap();
    let out = dir.path().join("t.bvh");
    // The same edit in the best checkpoint (what transition and export load) and in `last/`
    // (what a resume loads).
    let put = |path: &std::path::Path, text: String| {
        std::fs::write(path, &text).unwrap();
        std::fs::write(model.join("last").join(path.file_name().unwrap()), &text).unwrap();
    };
    let check = |what: &str, expected: &str| {
        let (ok, _, err) = zoo(&transition_args(&model, &clip, "30", &out));
        assert!(!ok && err.contains(expected) && !err.contains("panicked"), "{what}, transition: {err}");
        assert!(!out.exists(), "{what}: transition wrote a file");
        let (ok, _, err) =
            run(&["export", "--onnx", model.to_str().unwrap(), "--out", dir.path().join("m.onnx").to_str().unwrap()]);
        assert!(!ok && err.contains(expected), "{what}, export: {err}");
        let out = tiny_command(&tiny_run("--resume", model.to_str().unwrap(), "2")).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(expected), "{what}, resume: {err}");
    };
    let mut stats: serde_json::Value = serde_json::from_str(&good_stats).unwrap();
    stats["x"]["std"][4] = 0.0.into();
    put(&stats_path, stats.to_string());
    check("zero std", "normalization.json: group `x` has std 0.0 at index 4; every std must be at least 1e-6");
    let mut stats: serde_json::Value = serde_json::from_str(&good_stats).unwrap();
    stats["velocity"]["mean"].as_array_mut().unwrap().truncate(5);
    stats["velocity"]["std"].as_array_mut().unwrap().truncate(5);
    put(&stats_path, stats.to_string());
    check("short mean", "group `velocity` has 5 values, expected");
    let mut stats: serde_json::Value = serde_json::from_str(&good_stats).unwrap();
    stats["offset"]["std"].as_array_mut().unwrap().pop();
    put(&stats_path, stats.to_string());
    check("short std", "group `offset` has");
    put(&stats_path, good_stats.clone());
    let mut config: serde_json::Value = serde_json::from_str(&good_config).unwrap();
    config["parents"][2] = 7.into();
    put(&config_path, config.to_string());
    check("bad parent", "config.json: joint 2 (in `parents`) has parent 7");
    let mut config: serde_json::Value = serde_json::from_str(&good_config).unwrap();
    config["lstm"] = 0.into();
    put(&config_path, config.to_string());
    check("zero size", "config.json: lstm is 0");
}

/// `zoo transition` with a clip that has the model's joint count but another hierarchy.
#[test]
fn transition_refuses_a_clip_with_another_hierarchy() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clip) = tiny_model(dir.path());
    let mut c = zoo_data::bvh::read_model_clip(&clip).unwrap();
    let j = (2..c.joints()).find(|&j| c.skeleton.parents[j] != Some(j - 1)).unwrap();
    c.skeleton.parents[j] = Some(j - 1);
    let other = dir.path().join("other.bvh");
    zoo_data::bvh::write_file(&c, &other).unwrap();
    let (ok, _, err) = zoo(&transition_args(&model, &other, "30", &dir.path().join("t.bvh")));
    assert!(!ok && err.contains("has the model's") && err.contains("but another hierarchy"), "{err}");
    let onnx = dir.path().join("m.onnx");
    let (ok, _, err) = run(&[
        "export",
        "--onnx",
        model.to_str().unwrap(),
        "--skeleton",
        other.to_str().unwrap(),
        "--out",
        onnx.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("is not the one the model in") && !onnx.exists(), "{err}");
    let data = dir.path().join("other_data");
    std::fs::create_dir(&data).unwrap();
    for name in ["a_train.bvh", "b_test.bvh"] {
        std::fs::copy(&other, data.join(name)).unwrap();
    }
    let method = format!("rtn:{}", model.display());
    let (ok, _, err) = run(&[
        "bench",
        "--data",
        data.to_str().unwrap(),
        "--valid-glob",
        "b_*",
        "--lengths",
        "5",
        "--methods",
        &method,
    ]);
    assert!(!ok && err.contains("the model was trained on another skeleton"), "{err}");
}

/// Inference memory does not grow with the transition length: thousands of frames complete
/// (a candle graph kept over every step overflowed the stack at 4500).
#[test]
fn a_transition_of_4500_frames_completes() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clip) = tiny_model(dir.path());
    let out = dir.path().join("long.bvh");
    let (ok, stdout, err) = zoo(&transition_args(&model, &clip, "4500", &out));
    assert!(ok, "{stdout}\n{err}");
    assert!(stdout.contains("4500 generated"), "{stdout}");
    let c = zoo_data::bvh::read_file(&out, &Default::default()).unwrap();
    assert!(c.frames() > 4500 && c.local_positions.iter().all(|p| p.is_finite()));
}

/// Two runs of the same command (seed, one thread) give the same losses epoch by epoch and
/// the same weights, byte for byte.
#[test]
fn two_runs_with_the_same_seed_and_one_thread_are_bit_identical() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for run_dir in [&a, &b] {
        let out = tiny_command(&tiny_run("--out", run_dir.to_str().unwrap(), "2")).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let (sa, sb) = (read_state(&a), read_state(&b));
    for key in ["train_loss", "valid_loss", "valid_loss_ema", "best_epoch", "steps"] {
        assert_eq!(sa[key], sb[key], "{key}");
    }
    assert_eq!(sa["train_loss"].as_array().unwrap().len(), 2);
    for f in ["model.safetensors", "last/model.safetensors", "last/optimizer.safetensors", "last/ema.safetensors"] {
        assert!(std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(), "{f} differs");
    }
}

/// `zoo decompress` with a 5000-frame keyframe interval: one transition of about 5000 frames
/// (the stack overflow), which now completes.
#[test]
fn decompress_with_a_5000_frame_gap_completes() {
    let dir = tempfile::tempdir().unwrap();
    let (model, _) = tiny_model(dir.path());
    let data = dir.path().join("long");
    let (ok, _, err) = run(&[
        "data",
        "synth",
        "--out",
        data.to_str().unwrap(),
        "--minutes",
        "3",
        "--clip-seconds",
        "180",
        "--seed",
        "4",
    ]);
    assert!(ok, "{err}");
    let clip = data.join("synth_walk_0000.bvh");
    let clip = if clip.is_file() {
        clip
    } else {
        std::fs::read_dir(&data)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.extension().is_some_and(|e| e == "bvh"))
            .unwrap()
    };
    let out = dir.path().join("rebuilt.bvh");
    let (ok, stdout, err) = run(&[
        "decompress",
        "--model",
        model.to_str().unwrap(),
        clip.to_str().unwrap(),
        "--interval",
        "5000",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stdout}\n{err}");
    assert!(stdout.contains("rebuilt 5010 frames") && stdout.contains("1 keyframes (every 5000)"), "{stdout}");
}

/// `zoo bench train` (issue 18): one timed step per thread count at the paper's sizes, in the
/// training environment, with its JSON; RMR and ARNN (data-parallel since issue 18) measured too.
#[test]
fn bench_train_measures_every_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("train.json");
    let json_s = json.to_str().unwrap();
    let (ok, stdout, stderr) =
        run(&["bench", "train", "--threads", "1,2", "--steps", "1", "--repeats", "1", "--json", json_s]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("environment: CANDLE_NUM_THREADS=1 MIMALLOC_PURGE_DELAY=-1"), "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = v["results"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for (row, threads) in rows.iter().zip([1, 2]) {
        assert_eq!(row["threads"], threads);
        assert!(row["windows_per_s_median"].as_f64().unwrap() > 0.0, "{row}");
        assert!(row["gflops"].as_f64().unwrap() > 0.0, "{row}");
    }
    assert!(v["matmul_gflops_one_thread"].as_f64().unwrap() > 0.0);
    let (ok, _, stderr) = run(&["bench", "train", "--model", "rnn-gmm", "--batch", "8"]);
    assert!(!ok && stderr.contains("--batch: only the RTN and ARNN benches"), "{stderr}");
    for model in ["rmr", "arnn"] {
        let (ok, stdout, stderr) =
            run(&["bench", "train", "--model", model, "--threads", "2", "--steps", "1", "--repeats", "1"]);
        assert!(ok, "{model}: {stdout}\n{stderr}");
        assert!(stdout.contains("zoo   2 thread(s):") && stdout.contains("paper sizes"), "{model}: {stdout}");
    }
}

/// Issue 19's switches end to end on a tiny model: the residual on the interpolation, the
/// augmentations and the synthetic stepping clips go into the run, the fallback is calibrated
/// at the end of training, and `zoo transition`, `zoo export` and the runtime use them.
#[test]
fn interp_residual_augmented_run_with_fallback() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = dir.path().join("run");
    let mut args = tiny_run("--out", run_dir.to_str().unwrap(), "1");
    args.extend(["--interp-residual", "--augment", "reverse,mirror,speed", "--synth-steps", "0.5"]);
    let out = tiny_command(&args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("--synth-steps 0.5: 3 clips"), "{stdout}");
    assert!(stdout.contains("fallback calibrated on"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["interp_residual"], true);
    let aug = &config["train"]["augment"];
    assert_eq!(
        (aug["reverse"].as_f64(), aug["mirror"].as_f64(), aug["speed"].as_f64()),
        (Some(0.3), Some(0.5), Some(0.3))
    );
    // bandai2's skeleton: Shoulder_L (5) pairs with Shoulder_R (9), the spine with itself.
    assert_eq!(aug["mirror_pairs"][5], 9);
    assert_eq!(aug["mirror_pairs"][2], 2);
    let (start, full) = (config["fallback"]["start"].as_f64().unwrap(), config["fallback"]["full"].as_f64().unwrap());
    assert!(start > 0.0 && full > start, "{config}");

    let clip = synth_clips(&dir.path().join("synth"), &["--minutes", "0.5", "--seed", "3"]).swap_remove(0);
    let bvh = dir.path().join("t.bvh");
    let (ok, stdout, stderr) = zoo(&transition_args(&run_dir, &clip, "6", &bvh));
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("target miss") && stdout.contains("interpolation weight"), "{stdout}");
    let mut no_fb = transition_args(&run_dir, &clip, "6", &dir.path().join("t2.bvh"));
    no_fb.push("--no-fallback".into());
    let (ok, stdout, stderr) = zoo(&no_fb);
    assert!(ok && stdout.contains("(no fallback)"), "{stdout}\n{stderr}");

    let onnx = dir.path().join("m.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", run_dir.to_str().unwrap(), "--out", onnx.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    let model = zoo_runtime::TransitionModel::load(&onnx).unwrap();
    assert!(model.model().inputs().iter().any(|i| i.name == "base"), "the step graph takes the interpolation base");
    let fb = model.default_fallback().expect("the exported file carries the calibrated fallback");
    assert!((fb.start as f64 - start).abs() < 1e-4 && (fb.full as f64 - full).abs() < 1e-4, "{fb:?}");
}

/// The residual on the interpolation is the default (issue 19's chosen configuration);
/// `--interp-residual false` trains the paper's RTN.
#[test]
fn interp_residual_is_the_default_and_can_be_turned_off() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, expect) in [(None, true), (Some("false"), false)] {
        let run_dir = dir.path().join(format!("run-{expect}"));
        let mut args = tiny_run("--out", run_dir.to_str().unwrap(), "1");
        if let Some(v) = extra {
            args.extend(["--interp-residual", v]);
        }
        let out = tiny_command(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let config: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(run_dir.join("config.json")).unwrap()).unwrap();
        assert_eq!(config["interp_residual"], expect, "{extra:?}");
    }
    let mut args = tiny_run("--out", dir.path().to_str().unwrap(), "1");
    args.extend(["--interp-residual", "maybe"]);
    let out = tiny_command(&args).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("--interp-residual"), "{stderr}");
}

/// `zoo train rtn --terrain` end to end: a tiny terrain-aware RTN trained for one epoch on
/// `zoo data synth --terrain` clips, `zoo transition --heightmap` (required by the model,
/// refused by a flat one), and `zoo export --onnx` giving a file whose transitions in the
/// runtime, on the clip's heightmap, are candle's (`Rtn::transition` of the run folder; the
/// tolerance of `parity_rtn::runtime_transition_api_matches_candle`).
#[test]
fn terrain_run_trains_transitions_and_exports_for_the_runtime() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let data_s = data.to_str().unwrap();
    let clips = synth_clips(&data, &["--minutes", "1.5", "--seed", "3", "--terrain"]);
    let clip = clips.last().unwrap().clone();
    let valid_glob = format!("*{}", clip.file_name().unwrap().to_str().unwrap());
    let run_dir = dir.path().join("run");
    let mut args = tiny_run("--out", run_dir.to_str().unwrap(), "1");
    args.extend(["--terrain", "--data", data_s, "--valid-glob", &valid_glob]);
    let out = tiny_command(&args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("with terrain"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["terrain"], true);

    let heightmap = zoo_data::terrain::sibling_of(&clip).expect("zoo data synth --terrain writes the heightmap");
    let bvh = dir.path().join("t.bvh");
    let (ok, stdout, stderr) = zoo(&transition_args(&run_dir, &clip, "6", &bvh));
    assert!(!ok && stderr.contains("terrain-aware") && stderr.contains("--heightmap"), "{stdout}\n{stderr}");
    assert!(stderr.contains(heightmap.to_str().unwrap()), "the error names the clip's heightmap: {stderr}");
    let mut with_map = transition_args(&run_dir, &clip, "6", &bvh);
    with_map.extend(["--heightmap".into(), heightmap.display().to_string()]);
    let (ok, stdout, stderr) = zoo(&with_map);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("wrote") && bvh.is_file(), "{stdout}");
    // On terrain the --to clip is not moved: after the transition (frames 20..26) the output is
    // the clip from frame 60 on, where it stands on its heightmap.
    let (_, spliced) = zoo_data::bvh::read_model_clip(&bvh).unwrap().global();
    let (_, source) = zoo_data::bvh::read_model_clip(&clip).unwrap().global();
    let joints = spliced.len() / zoo_data::bvh::read_model_clip(&bvh).unwrap().frames();
    let moved = (0..joints).map(|k| (spliced[26 * joints + k] - source[60 * joints + k]).length()).fold(0.0, f64::max);
    assert!(moved < 1e-2, "the target clip moved by {moved} cm on terrain");

    let onnx = dir.path().join("m.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", run_dir.to_str().unwrap(), "--out", onnx.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    let model = zoo_runtime::TransitionModel::load(&onnx).unwrap();
    assert_eq!(model.terrain(), Some((5, 206.0)));
    // `zoo bench runtime` feeds candle the graph's own terrain and base inputs: the backends agree.
    let (ok, stdout, stderr) =
        run(&["bench", "runtime", "--model", onnx.to_str().unwrap(), "--rounds", "1", "--work", "2", "--batch", "1"]);
    assert!(ok && stdout.lines().any(|l| l.split_whitespace().nth(1) == Some("candle")), "{stdout}\n{stderr}");
    assert!(stdout.contains("from tract f32") && !stdout.contains("note:"), "the backends agree:\n{stdout}");
    let map = zoo_data::terrain::read(&heightmap).unwrap();
    let c = zoo_data::bvh::read_model_clip(&clip).unwrap();
    let (_, gp) = c.global();
    let j = c.joints();
    let frame = |f: usize| -> Vec<f32> { gp[f * j..(f + 1) * j].iter().flat_map(|p| p.as_vec3().to_array()).collect() };
    let past: Vec<f32> = (16..20).flat_map(frame).collect();
    let (target, next) = (frame(27), frame(28));
    let (candle, stats) = zoo_rtn::checkpoint::load(&run_dir, &candle_core::Device::Cpu).unwrap();
    let want = candle.transition(&stats, &past, &target, &next, 6, Some(&map)).unwrap();
    let mut runner = model.runner().unwrap();
    let mut state = model.new_transition();
    let mut got = vec![0.0; want.len()];
    let err = runner.generate(&mut state, &past, &target, &next, &mut got).unwrap_err();
    assert!(err.to_string().contains("set_heightmap"), "{err}");
    state.set_heightmap(Some(std::sync::Arc::new(map)));
    runner.generate(&mut state, &past, &target, &next, &mut got).unwrap();
    let diff = want.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    assert!(diff <= 1e-2, "runtime vs candle on the trained terrain run: max abs diff {diff} (cm)");

    // Without --data: synthetic locomotion over terrain generated in memory.
    let r4 = dir.path().join("r4");
    let mut args = tiny_run("--out", r4.to_str().unwrap(), "1");
    args.push("--terrain");
    let out = tiny_command(&args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && stdout.contains("synthetic locomotion over terrain"), "{stdout}");

    // A flat model refuses --heightmap; --terrain refuses data without heightmaps.
    let flat_dir = dir.path().join("flat");
    let out = tiny_command(&tiny_run("--out", flat_dir.to_str().unwrap(), "1")).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut flat_args = transition_args(&flat_dir, &clip, "6", &dir.path().join("f.bvh"));
    flat_args.extend(["--heightmap".into(), heightmap.display().to_string()]);
    let (ok, _, stderr) = zoo(&flat_args);
    assert!(!ok && stderr.contains("no terrain input") && stderr.contains("drop --heightmap"), "{stderr}");
    let bare = dir.path().join("bare");
    std::fs::create_dir(&bare).unwrap();
    for c in &clips {
        std::fs::copy(c, bare.join(c.file_name().unwrap())).unwrap();
    }
    let (r2, r3) = (dir.path().join("r2"), dir.path().join("r3"));
    let mut args = tiny_run("--out", r2.to_str().unwrap(), "1");
    args.extend(["--terrain", "--data", bare.to_str().unwrap(), "--valid-glob", &valid_glob]);
    let (ok, _, stderr) = run(&args);
    assert!(
        !ok && stderr.contains("has no heightmap beside it") && stderr.contains("zoo data synth --terrain"),
        "{stderr}"
    );
    let mut args = tiny_run("--out", r3.to_str().unwrap(), "1");
    args.extend(["--terrain", "--augment", "mirror"]);
    let (ok, _, stderr) = run(&args);
    assert!(!ok && stderr.contains("leave mirror out of --augment"), "{stderr}");
}
