//! End-to-end tests of `zoo train rmr`, `zoo stitch` and `zoo bench stitch` on the embedded
//! synthetic data (a tiny RMR trained for one or two short epochs), and their bad-input errors.

use std::path::{Path, PathBuf};
use std::process::Command;
use zoo_tests::zoo_bin;

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_bin()).args(args).env("RAYON_NUM_THREADS", "1").output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A tiny RMR trained on 1.5 minutes of synthetic motion into `dir/run` (the default recipe).
fn train_tiny(dir: &Path, epochs: &str) -> PathBuf {
    train_tiny_with(dir, "run", epochs, &[])
}

/// [`train_tiny`] into `dir/name` with more arguments.
fn train_tiny_with(dir: &Path, name: &str, epochs: &str, more: &[&str]) -> PathBuf {
    let run_dir = dir.join(name);
    let mut args = vec!["train", "rmr", "--preset", "tiny", "--synth-minutes", "1.5", "--epochs", epochs];
    args.extend(["--seed", "3", "--out", s(&run_dir)]);
    args.extend(more);
    let (ok, stdout, stderr) = run(&args);
    assert!(ok, "{stdout}\n{stderr}");
    run_dir
}

/// Synthetic BVH clips in `dir/synth`, sorted by name.
fn synth_clips(dir: &Path, minutes: &str) -> (PathBuf, Vec<PathBuf>) {
    let data = dir.join("synth");
    let (ok, _, stderr) = run(&["data", "synth", "--out", s(&data), "--minutes", minutes, "--seed", "7"]);
    assert!(ok, "{stderr}");
    let mut clips: Vec<PathBuf> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    clips.sort();
    (data, clips)
}

fn read(p: &Path) -> zoo_motion::Clip {
    zoo_data::bvh::read_model_clip(p).unwrap()
}

#[test]
fn train_resume_and_stitch() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = train_tiny(dir.path(), "1");
    for f in ["config.json", "model.safetensors", "normalization.json", "train_state.json", "pairs_train.json"] {
        assert!(run_dir.join(f).is_file(), "{f} missing in the run folder");
    }
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["model"], "rmr");
    // The default recipe: trained on inertialized seams, seam weight 4, velocity weight 1.
    assert_eq!((config["pre_blend"].as_bool(), config["seam_weight"].as_f64()), (Some(true), Some(4.0)));
    assert_eq!(config["lambda_velocity"].as_f64(), Some(1.0));
    // The fallback is calibrated on the validation pairs at the end of training.
    let (start, full) = (config["fallback"]["start"].as_f64().unwrap(), config["fallback"]["full"].as_f64().unwrap());
    assert!(start > 0.0 && (full - 2.0 * start).abs() < 1e-6 * full, "{}", config["fallback"]);
    // Resume: the cached pair plans are reused and only epoch 2 runs.
    let (ok, stdout, stderr) = run(&[
        "train",
        "rmr",
        "--preset",
        "tiny",
        "--synth-minutes",
        "1.5",
        "--epochs",
        "2",
        "--seed",
        "3",
        "--resume",
        s(&run_dir),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("pair plans reused"), "{stdout}");
    assert!(stdout.contains("epoch   2:") && !stdout.contains("epoch   1:"), "{stdout}");
    assert!(stdout.contains("fallback calibrated on") && stdout.contains("stored in config.json"), "{stdout}");
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("train_state.json")).unwrap()).unwrap();
    assert_eq!(state["epoch"], 2);
    // A fresh run on the folder is refused.
    let (ok, _, stderr) =
        run(&["train", "rmr", "--preset", "tiny", "--synth-minutes", "1.5", "--epochs", "1", "--out", s(&run_dir)]);
    assert!(!ok);
    assert!(stderr.contains("already holds a run trained for 2 epochs") && stderr.contains("--resume"), "{stderr}");

    // Export: the window refiner with its metadata.
    let onnx = dir.path().join("rmr.onnx");
    let (ok, stdout, stderr) = run(&["export", "--onnx", s(&run_dir), "--out", s(&onnx)]);
    assert!(ok, "{stdout}\n{stderr}");
    let exported = zoo_export::OnnxModel::from_bytes(&std::fs::read(&onnx).unwrap(), "rmr.onnx").unwrap();
    assert_eq!(exported.metadata_value("zoo.model_kind"), Some("rmr"));
    assert_eq!(exported.metadata_value("zoo.task"), Some("stitch"));
    assert!(exported.metadata_value("zoo.config").is_some_and(|c| c.contains("\"bgru\"")));

    // Stitch three ranges of synthetic clips with every method.
    let (_, clips) = synth_clips(dir.path(), "1");
    let (a, b, c) = (s(&clips[0]), s(&clips[1]), s(&clips[2]));
    let (la, lc) = (read(&clips[0]), read(&clips[2]));
    let out = dir.path().join("stitched.bvh");
    let ranges = [format!("{a}:0:50"), format!("{b}:20:90"), format!("{c}:100:")];
    let (ok, stdout, stderr) =
        run(&["stitch", "--model", s(&run_dir), &ranges[0], &ranges[1], &ranges[2], "--out", s(&out), "--save-input"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("seams at [50, 120]") && stdout.contains("feet locked"), "{stdout}");
    let frames = 50 + 70 + lc.frames() - 100;
    let (stitched, input) = (read(&out), read(&dir.path().join("stitched.input.bvh")));
    assert_eq!((stitched.frames(), input.frames()), (frames, frames));
    assert!(stitched.local_rotations.iter().all(|q| q.is_finite()));
    // The exported file is what the run folder runs (the folder is exported in memory): the
    // same stitch to the bit.
    let from_file = dir.path().join("from_file.bvh");
    let (ok, stdout_file, stderr) =
        run(&["stitch", "--model", s(&onnx), &ranges[0], &ranges[1], &ranges[2], "--out", s(&from_file)]);
    assert!(ok, "{stdout_file}\n{stderr}");
    assert_eq!(
        std::fs::read(&from_file).unwrap(),
        std::fs::read(&out).unwrap(),
        "the exported file stitches otherwise"
    );
    // The input is the aligned concatenation: the first clip unchanged.
    for f in [0, 25, 49] {
        assert!((input.root_position(f) - la.root_position(f)).length() < 1e-3, "frame {f}");
    }
    // The seam guard is on by default; --no-seam-guard leaves the guarded seams as refined.
    let guarded: usize = stdout
        .split(" seams guarded against pops")
        .next()
        .and_then(|head| head.rsplit(", ").next())
        .and_then(|n| n.split(" of ").next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no guard in the summary: {stdout}"));
    let unguarded = dir.path().join("unguarded.bvh");
    let (ok, stdout, stderr) = run(&[
        "stitch",
        "--model",
        s(&run_dir),
        &ranges[0],
        &ranges[1],
        &ranges[2],
        "--out",
        s(&unguarded),
        "--no-seam-guard",
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(!stdout.contains("seams guarded"), "{stdout}");
    let unguarded = read(&unguarded);
    let differs = (0..frames).any(|f| unguarded.rotations_at(f) != stitched.rotations_at(f));
    assert_eq!(differs, guarded > 0, "{guarded} seams guarded, outputs differ: {differs}");
    assert!(stdout.contains("seams inertialized over 10 frames first"), "{stdout}");
    for method in ["inertialize", "interp", "concat"] {
        let o = dir.path().join(format!("{method}.bvh"));
        let (ok, stdout, stderr) = run(&["stitch", &ranges[0], &ranges[1], "--method", method, "--out", s(&o)]);
        assert!(ok, "{method}: {stdout}\n{stderr}");
        let clip = read(&o);
        assert_eq!(clip.frames(), 120, "{method}");
        // Before the seam region every method plays the first clip as it is.
        assert!((clip.root_position(30) - la.root_position(30)).length() < 1e-3, "{method}");
    }
}

/// An untrained tiny RMR run folder (`dir/untrained`) on the synthetic skeleton at 30 fps, and
/// synthetic clips: enough for the checks `zoo stitch` makes before refining.
fn untrained_rmr(dir: &Path) -> (PathBuf, Vec<PathBuf>) {
    use zoo_rmr::{Config, RmrTrainer, features::FeatureStats};
    let run_dir = dir.join("untrained");
    let config = Config::tiny();
    let d = config.dim();
    let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    RmrTrainer::new(&config, stats, &candle_core::Device::Cpu).unwrap().save(&run_dir).unwrap();
    let (_, clips) = synth_clips(dir, "0.5");
    (run_dir, clips)
}

/// Runs `zoo stitch --model MODEL --out dir/o.bvh ARGS`, which must fail without a panic and
/// without an output file; returns its stderr.
fn refused(model: &Path, dir: &Path, args: &[&str]) -> String {
    let out = dir.join("o.bvh");
    let mut all = vec!["stitch", "--model", s(model), "--out", s(&out)];
    all.extend_from_slice(args);
    let (ok, stdout, stderr) = run(&all);
    assert!(!ok, "expected a refusal of {args:?}: {stdout}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out.exists(), "no output after a refusal");
    stderr
}

#[test]
fn stitch_refuses_clips_shorter_than_10_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clips) = untrained_rmr(dir.path());
    let (a, b) = (s(&clips[0]), s(&clips[1]));
    let e = refused(&model, dir.path(), &[&format!("{a}:0:8"), b]);
    assert!(e.contains("has 8 frames; stitching needs at least 10 frames per clip"), "{e}");
    // A whole file of 9 frames.
    let short = dir.path().join("short.bvh");
    zoo_data::bvh::write_file(&read(&clips[1]).slice(0, 9), &short).unwrap();
    let e = refused(&model, dir.path(), &[a, s(&short)]);
    assert!(e.contains("short.bvh") && e.contains("has 9 frames") && e.contains("at least 10"), "{e}");
    // The same check without a model (the baselines).
    let (ok, _, e) = run(&["stitch", "--method", "concat", a, s(&short), "--out", s(&dir.path().join("c.bvh"))]);
    assert!(!ok && e.contains("has 9 frames"), "{e}");
}

#[test]
fn stitch_refuses_a_window_longer_than_the_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clips) = untrained_rmr(dir.path());
    let (a, b) = (s(&clips[0]), s(&clips[1]));
    let e = refused(&model, dir.path(), &[&format!("{a}:0:20"), &format!("{b}:0:20"), "--window", "60"]);
    assert!(e.contains("the window of 60 frames is longer than the stitched sequence (40 frames)"), "{e}");
    assert!(e.contains("--window 30"), "names the fix: {e}");
    // The model's own window (30 for the tiny preset) on 20 frames.
    let e = refused(&model, dir.path(), &[&format!("{a}:0:10"), &format!("{b}:0:10")]);
    assert!(e.contains("longer than the stitched sequence (20 frames)"), "{e}");
    let e = refused(&model, dir.path(), &[a, b, "--window", "20", "--stride", "30"]);
    assert!(e.contains("--stride 30 is longer than the window 20"), "{e}");
    let e = refused(&model, dir.path(), &[&format!("{a}:0:99999"), b]);
    assert!(e.contains("is outside the clip's"), "{e}");
}

#[test]
fn stitch_refuses_clips_of_another_skeleton() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clips) = untrained_rmr(dir.path());
    let a = s(&clips[0]);
    let mut other = read(&clips[1]);
    other.skeleton.names[15] = "LeftFoot".into();
    let other_path = dir.path().join("other.bvh");
    zoo_data::bvh::write_file(&other, &other_path).unwrap();
    // Against the first clip.
    let e = refused(&model, dir.path(), &[a, s(&other_path)]);
    assert!(e.contains("another skeleton") && e.contains("LeftFoot") && e.contains("same rig"), "{e}");
    // Both clips on the other rig: against the model's.
    let e = refused(&model, dir.path(), &[s(&other_path), s(&other_path)]);
    assert!(e.contains("not the model's") && e.contains("found `LeftFoot`") && e.contains("retarget"), "{e}");
}

/// A clip whose dummy root carries motion is folded into its child by `zoo stitch` as by a
/// dataset (the same file given alone was refused as another skeleton), with and without a model.
#[test]
fn stitch_folds_a_moving_dummy_root() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clips) = untrained_rmr(dir.path());
    let moving = dir.path().join("moving.bvh");
    std::fs::write(&moving, zoo_tests::under_dummy_root(&read(&clips[1]), true)).unwrap();
    for with_model in [false, true] {
        let out = dir.path().join(format!("o{with_model}.bvh"));
        let mut args = vec!["stitch", s(&clips[0]), s(&moving), "--out", s(&out)];
        if with_model {
            args.extend(["--model", s(&model)]);
        } else {
            args.extend(["--method", "inertialize"]);
        }
        let (ok, stdout, stderr) = run(&args);
        assert!(ok, "{stdout}\n{stderr}");
        assert!(stderr.contains("its dummy root `joint_Root` carries motion; folded into"), "{stderr}");
        assert_eq!(read(&out).joints(), read(&clips[0]).joints());
    }
}

#[test]
fn stitch_refuses_clips_of_another_frame_rate() {
    let dir = tempfile::tempdir().unwrap();
    let (model, clips) = untrained_rmr(dir.path());
    let a = s(&clips[0]);
    let mut fast = read(&clips[1]);
    fast.frame_time = 1.0 / 60.0;
    let fast_path = dir.path().join("fast.bvh");
    zoo_data::bvh::write_file(&fast, &fast_path).unwrap();
    // Against the first clip.
    let e = refused(&model, dir.path(), &[a, s(&fast_path)]);
    assert!(e.contains("is 60 fps") && e.contains("is 30 fps") && e.contains("resample"), "{e}");
    // Both at 60 fps: against the model's 30.
    let e = refused(&model, dir.path(), &[s(&fast_path), s(&fast_path)]);
    assert!(e.contains("60 fps but the model was trained at 30 fps") && e.contains("resample"), "{e}");
    // A frame time stored rounded (bandai2's 0.0333333 s, 30.00003 fps) is the model's rate.
    let mut rounded = read(&clips[1]);
    rounded.frame_time = 0.0333333;
    let rounded_path = dir.path().join("rounded.bvh");
    zoo_data::bvh::write_file(&rounded, &rounded_path).unwrap();
    let out = dir.path().join("rounded_out.bvh");
    let (ok, _, stderr) =
        run(&["stitch", "--model", s(&model), "--method", "inertialize", a, s(&rounded_path), "--out", s(&out)]);
    assert!(ok, "{stderr}");
}

#[test]
fn stitch_refuses_an_rtn_where_an_rmr_is_expected() {
    let dir = tempfile::tempdir().unwrap();
    let (_, clips) = synth_clips(dir.path(), "0.5");
    let (a, b) = (s(&clips[0]), s(&clips[1]));
    let rtn = dir.path().join("rtn");
    let (ok, stdout, stderr) =
        run(&["train", "rtn", "--preset", "tiny", "--synth-minutes", "1", "--epochs", "1", "--out", s(&rtn)]);
    assert!(ok, "{stdout}\n{stderr}");
    // Its run folder.
    let e = refused(&rtn, dir.path(), &[a, b]);
    assert!(e.contains("holds a `rtn` model") && e.contains("zoo train rmr"), "{e}");
    // Its exported ONNX file.
    let onnx = dir.path().join("rtn.onnx");
    let (ok, _, stderr) = run(&["export", "--onnx", s(&rtn), "--out", s(&onnx)]);
    assert!(ok, "{stderr}");
    let e = refused(&onnx, dir.path(), &[a, b]);
    assert!(e.contains("rtn.onnx holds a `transition` model (`rtn`)") && e.contains("zoo transition"), "{e}");
    // A folder that is no run at all.
    let e = refused(&dir.path().join("missing"), dir.path(), &[a, b]);
    assert!(e.contains("missing") && e.contains("not a run folder"), "{e}");
}

#[test]
fn stitch_refuses_a_missing_model_or_a_single_clip() {
    let dir = tempfile::tempdir().unwrap();
    let (_, clips) = synth_clips(dir.path(), "0.5");
    let (a, b) = (s(&clips[0]), s(&clips[1]));
    let out = dir.path().join("o.bvh");
    let (ok, _, e) = run(&["stitch", a, b, "--out", s(&out)]);
    assert!(!ok && e.contains("--method rmr needs --model"), "{e}");
    let (ok, _, e) = run(&["stitch", a, "--out", s(&out)]);
    assert!(!ok && e.contains("CLIP.bvh"), "{e}");
    assert!(!out.exists());
}

#[test]
fn the_stitching_benchmark_measures_every_method() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = train_tiny(dir.path(), "1");
    let (data, _) = synth_clips(dir.path(), "2");
    let json = dir.path().join("bench.json");
    // A tiny RTN in-betweens across the seams.
    let rtn = dir.path().join("rtn");
    let (ok, stdout, stderr) =
        run(&["train", "rtn", "--preset", "tiny", "--synth-minutes", "1", "--epochs", "1", "--out", s(&rtn)]);
    assert!(ok, "{stdout}\n{stderr}");
    let methods = format!(
        "concat,inertialize,interp,rmr:{0},rmr+ik:{0},rmr+lock:{0},rmr+ik+lock:{0},rmr+ik+guard+lock:{0},\
         inert+rmr+ik+lock:{0},candle-rmr+ik+guard+lock:{0},rtn:{1}",
        s(&run_dir),
        s(&rtn)
    );
    let (ok, stdout, stderr) = run(&[
        "bench",
        "stitch",
        "--data",
        s(&data),
        "--valid-glob",
        "*_001[0-2].bvh",
        "--methods",
        &methods,
        "--free-cases",
        "3",
        "--database-stride",
        "2",
        "--json",
        s(&json),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("cases with ground truth") && stdout.contains("free cases"), "{stdout}");
    // Each RMR method applies the run's calibrated fallback and says how often it acted.
    let acted = |out: &str| out.matches("the fallback towards the refiner's input acted on").count();
    assert_eq!(acted(&stdout), 7, "{stdout}");
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let cases = r["cases"].as_u64().unwrap();
    assert!(cases >= 10, "{cases} cases");
    assert_eq!(r["free_cases"], 6);
    let rows = r["methods"].as_object().unwrap();
    assert_eq!(rows.len(), 11);
    // The RMR methods run the exported model in the engine runtime; the training model in candle
    // (`candle-...`) measures the same within float rounding.
    let (runtime, candle) = (
        &rows[&format!("rmr+ik+guard+lock:{}", s(&run_dir))],
        &rows[&format!("candle-rmr+ik+guard+lock:{}", s(&run_dir))],
    );
    for m in ["l2p", "l2q", "root_deviation", "pops_mean"] {
        let (a, b) = (runtime[m].as_f64().unwrap(), candle[m].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-3 * b.abs().max(1.0), "{m}: runtime {a}, candle {b}");
    }
    // The seam guard takes pops out (an untrained model's output is far from inertialization's, so
    // not down to it here).
    let pops = |m: String| rows[&m]["pops_mean"].as_f64().unwrap();
    let (guarded, unguarded) =
        (pops(format!("rmr+ik+guard+lock:{}", s(&run_dir))), pops(format!("rmr+ik+lock:{}", s(&run_dir))));
    assert!(guarded < unguarded, "pops {guarded} with the guard, {unguarded} without");
    // Concatenation keeps the input's root path and has a pose error (the retrieved segments).
    assert_eq!(rows["concat"]["root_deviation"].as_f64(), Some(0.0));
    assert!(rows["concat"]["l2p"].as_f64().unwrap() > 0.0);
    assert!(r["ground_truth"]["l2p"].is_null());
    // --no-fallback: the network alone.
    let rmr = format!("rmr:{}", s(&run_dir));
    let (ok, stdout, stderr) = run(&[
        "bench",
        "stitch",
        "--data",
        s(&data),
        "--valid-glob",
        "*_0010.bvh",
        "--methods",
        &rmr,
        "--free-cases",
        "1",
        "--database-stride",
        "2",
        "--no-fallback",
    ]);
    assert!(ok && acted(&stdout) == 0, "{stdout}\n{stderr}");
    // Unknown and non-stitching methods are refused.
    let (ok, _, e) =
        run(&["bench", "stitch", "--data", s(&data), "--valid-glob", "*_0010.bvh", "--methods", "gmm:runs/x"]);
    assert!(!ok && e.contains("unknown method `gmm:runs/x`"), "{e}");
}

/// `--exclude-glob` (a content held out, as docs/ood.md does for the RTN): training and the
/// stitching benchmark leave the matching clips out before the split and say how many.
#[test]
fn training_and_the_benchmark_leave_out_excluded_clips() {
    let dir = tempfile::tempdir().unwrap();
    let (data, clips) = synth_clips(dir.path(), "2");
    let run_dir = dir.path().join("run");
    let mut args = vec!["train", "rmr", "--preset", "tiny", "--epochs", "1", "--data", s(&data)];
    args.extend(["--valid-glob", "*_001[0-2].bvh", "--exclude-glob", "*_000[1-4].bvh", "--out", s(&run_dir)]);
    let (ok, stdout, stderr) = run(&args);
    assert!(ok, "{stdout}\n{stderr}");
    let left = format!("--exclude-glob *_000[1-4].bvh: left out 4 of {} clips", clips.len());
    assert!(stderr.contains(&left), "{stderr}");
    let (ok, stdout, stderr) = run(&[
        "bench",
        "stitch",
        "--data",
        s(&data),
        "--valid-glob",
        "*_001[0-2].bvh",
        "--exclude-glob",
        "*_000[1-4].bvh",
        "--methods",
        "concat,inertialize",
        "--free-cases",
        "2",
        "--database-stride",
        "2",
    ]);
    assert!(ok && stderr.contains(&left), "{stdout}\n{stderr}");
    // Without --data there is nothing to leave out.
    let other = dir.path().join("other");
    let (ok, _, stderr) = run(&["train", "rmr", "--preset", "tiny", "--exclude-glob", "*_run_*", "--out", s(&other)]);
    assert!(!ok && stderr.contains("--exclude-glob leaves clips of --data out: pass --data too"), "{stderr}");
}

/// `zoo train rmr` (and `--pre-blend`, the default): the run trains on inertialized seams, says so in its
/// configuration, and `zoo stitch` inertializes the seams of what it refines without being told.
#[test]
fn a_model_trained_on_inertialized_seams_stitches_them_so() {
    let dir = tempfile::tempdir().unwrap();
    // `--pre-blend` is the default (kept for scripts); `--paper` trains on the raw concatenation
    // with the paper's loss.
    let run_dir = train_tiny_with(dir.path(), "pre", "1", &["--pre-blend"]);
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["pre_blend"], true);
    let plain = train_tiny_with(dir.path(), "paper", "1", &["--paper"]);
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(plain.join("config.json")).unwrap()).unwrap();
    assert_eq!((config["pre_blend"].as_bool(), config["seam_weight"].as_f64()), (Some(false), Some(0.0)));
    assert_eq!(config["lambda_velocity"].as_f64(), Some(0.0));
    let (ok, _, stderr) = run(&["train", "rmr", "--paper", "--pre-blend", "--out", s(&dir.path().join("both"))]);
    assert!(!ok && stderr.contains("cannot be used with"), "{stderr}");
    // The two trained on other inputs: another validation loss.
    let loss = |d: &Path| {
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
        s["best_valid_loss"].as_f64().unwrap()
    };
    assert_ne!(loss(&run_dir), loss(&plain), "--pre-blend changed nothing in training");
    let (_, clips) = synth_clips(dir.path(), "1");
    let ranges = [format!("{}:0:50", s(&clips[0])), format!("{}:10:80", s(&clips[1]))];
    let out = dir.path().join("stitched.bvh");
    let (ok, stdout, stderr) = run(&["stitch", "--model", s(&run_dir), &ranges[0], &ranges[1], "--out", s(&out)]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("seams inertialized over 10 frames first"), "{stdout}");
    // The paper's model refines the raw concatenation unless `zoo stitch --pre-blend` says
    // otherwise: then the frames after the seam are refined from another input.
    let raw = dir.path().join("raw.bvh");
    let (ok, stdout, stderr) = run(&["stitch", "--model", s(&plain), &ranges[0], &ranges[1], "--out", s(&raw)]);
    assert!(ok && !stdout.contains("inertialized"), "{stdout}\n{stderr}");
    let pre = dir.path().join("pre.bvh");
    let (ok, stdout, stderr) =
        run(&["stitch", "--model", s(&plain), &ranges[0], &ranges[1], "--out", s(&pre), "--pre-blend"]);
    assert!(ok && stdout.contains("seams inertialized over 10 frames first"), "{stdout}\n{stderr}");
    let (raw, pre) = (read(&raw), read(&pre));
    let moved = (50..60).map(|f| (pre.root_position(f) - raw.root_position(f)).length()).fold(0.0, f64::max);
    assert!(moved > 1e-3, "--pre-blend changed nothing after the seam ({moved})");
}

/// The largest distance (cm) between a joint of `a` and of `b` over the frames `reach` or more
/// frames from every seam.
fn largest_move_beyond(a: &zoo_motion::Clip, b: &zoo_motion::Clip, seams: &[usize], reach: usize) -> f64 {
    zoo_protocol::stitch::reach::largest_move_beyond(a, b, seams, reach)
}

#[test]
fn a_stitch_leaves_the_clips_alone_beyond_the_seams_reach() {
    let dir = tempfile::tempdir().unwrap();
    let run_dir = train_tiny(dir.path(), "1");
    let (_, clips) = synth_clips(dir.path(), "1");
    let ranges = [0, 1, 2].map(|i| format!("{}:0:120", s(&clips[i])));
    let stitch = |name: &str, more: &[&str]| {
        let out = dir.path().join(format!("{name}.bvh"));
        let mut args = vec!["stitch", "--model", s(&run_dir), &ranges[0], &ranges[1], &ranges[2]];
        args.extend(["--out", s(&out), "--save-input"]);
        args.extend(more);
        let (ok, stdout, stderr) = run(&args);
        assert!(ok, "{stdout}\n{stderr}");
        assert!(stdout.contains("seams at [120, 240]"), "{stdout}");
        let input = read(&dir.path().join(format!("{name}.input.bvh")));
        (read(&out), input, stdout)
    };
    // The tiny model's window is 30 frames: by default nothing 30 or more frames from a seam
    // moves (frames 0-89, 150-209 and 270-359), up to the BVH's rounding.
    let (out, input, stdout) = stitch("kept", &[]);
    let seams = [120, 240];
    let moved = largest_move_beyond(&out, &input, &seams, 30);
    assert!(moved < 0.01, "moved {moved} cm beyond the seams' reach");
    assert!(stdout.contains("240 frames 30 or more from every seam kept as they were"), "{stdout}");
    // Near the seams the model still acts.
    assert!(largest_move_beyond(&out, &input, &seams, 0) > moved);
    // A reach given in frames, and the whole sequence refined as before.
    let (out, input, stdout) = stitch("reach50", &["--seam-reach", "50"]);
    assert!(largest_move_beyond(&out, &input, &seams, 50) < 0.01);
    assert!(stdout.contains("frames 50 or more from every seam kept"), "{stdout}");
    let (out, input, stdout) = stitch("everywhere", &["--refine-everywhere"]);
    assert!(stdout.contains("every frame refined"), "{stdout}");
    let everywhere = largest_move_beyond(&out, &input, &seams, 30);
    println!(
        "a tiny RMR of one epoch: largest joint move beyond the reach {everywhere:.2} cm refining everywhere, {moved:.4} cm kept"
    );
    assert!(everywhere > 1.0, "refining everywhere moved the far frames by {everywhere} cm only");
}
