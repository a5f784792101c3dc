//! End-to-end tests of `zoo train rnn-gmm`, `zoo generate` and `zoo bench synthesis` on the
//! embedded synthetic data with the tiny preset (a few seconds each).

use std::path::Path;
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

fn ok(args: &[&str]) -> String {
    let (ok, stdout, stderr) = run(args);
    assert!(ok, "zoo {}\n{stdout}\n{stderr}", args.join(" "));
    stdout
}

fn fails(args: &[&str]) -> String {
    let (ok, stdout, stderr) = run(args);
    assert!(!ok, "zoo {} should fail\n{stdout}", args.join(" "));
    stderr
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// `zoo train rnn-gmm` with the tiny preset on one minute of synthetic motion, plus `extra`.
fn train(extra: &[&str]) -> (bool, String, String) {
    let mut args =
        vec!["train", "rnn-gmm", "--preset", "tiny", "--synth-minutes", "1", "--refiner-rounds", "2", "--seed", "5"];
    args.extend_from_slice(extra);
    run(&args)
}

/// A run folder with both stages trained (generator 1 epoch, refiner 1 epoch).
fn trained(dir: &Path) -> String {
    let run_dir = dir.join("run");
    let r = run_dir.to_str().unwrap().to_string();
    let (ok, stdout, stderr) = train(&["--epochs", "1", "--refiner-epochs", "1", "--out", &r]);
    assert!(ok, "{stdout}\n{stderr}");
    r
}

#[test]
fn two_stages_train_resume_and_refuse_to_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let runp = dir.path().join("run");
    let r = runp.to_str().unwrap();
    // The generator stage alone, then resumed to a second epoch.
    let (ok, stdout, stderr) = train(&["--stage", "generator", "--epochs", "1", "--out", r]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("epoch   1:") && stdout.contains("generator: 1 epochs"), "{stdout}");
    for f in ["config.json", "model.safetensors", "features.json", "normalization.json", "start.bvh"] {
        assert!(runp.join(f).is_file(), "{f} missing in the run folder");
        assert!(runp.join("generator").join(f).is_file(), "{f} missing in the generator stage");
    }
    assert!(runp.join("generator/last/optimizer.safetensors").is_file());
    assert!(!runp.join("refiner.safetensors").exists());
    let (ok, stdout, stderr) = train(&["--stage", "generator", "--epochs", "2", "--resume", r]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("epoch   2:") && !stdout.contains("epoch   1:"), "{stdout}");
    assert_eq!(json(&runp.join("generator/train_state.json"))["epoch"], 2);
    // A fresh run on it is refused; the refiner stage trains on the generator, then resumes.
    let (ok, _, stderr) = train(&["--epochs", "1", "--out", r]);
    assert!(!ok && stderr.contains("already holds a run") && stderr.contains("--resume"), "{stderr}");
    let (ok, stdout, stderr) =
        train(&["--stage", "refiner", "--refiner-epochs", "1", "--refiner-warmup", "2", "--out", r]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("refiner: 1 epochs (2 rounds)") && stdout.contains("warm-up: 2 refiner + 2"), "{stdout}");
    assert_eq!(json(&runp.join("refiner/config.json"))["refiner"]["warmup_discriminator"], 2);
    for f in ["refiner.safetensors", "discriminator.safetensors", "effectors.json"] {
        assert!(runp.join(f).is_file(), "{f} missing in the run folder");
    }
    // New refiners have joint limits (min <= max over the training windows); eq. 13 holds their
    // root to the RNN's unsmoothed.
    let refiner = &json(&runp.join("config.json"))["refiner"];
    assert_eq!((refiner["joint_limits"].as_bool(), refiner["root_smoothing"].as_f64()), (Some(true), Some(0.0)));
    let limits = &json(&runp.join("effectors.json"))["limits"];
    let (lo, hi) = (limits["lo"].as_array().unwrap(), limits["hi"].as_array().unwrap());
    assert_eq!((limits["first"].as_u64(), lo.len()), (Some(4), hi.len()));
    assert!(lo.iter().zip(hi).all(|(l, h)| l.as_f64().unwrap() <= h.as_f64().unwrap()), "{limits}");
    let (ok, _, stderr) = train(&["--stage", "refiner", "--out", r]);
    assert!(!ok && stderr.contains("already holds a refiner stage"), "{stderr}");
    let (ok, stdout, stderr) = train(&["--stage", "refiner", "--refiner-epochs", "2", "--resume", r]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("refiner: 2 epochs (4 rounds)"), "{stdout}");
    let state = json(&runp.join("refiner/train_state.json"));
    assert_eq!(state["epoch"], 2);
    assert!(runp.join("refiner/last/history.safetensors").is_file());
    // Continuing the generator under a trained refiner would leave the refiner stale.
    let (ok, _, stderr) = train(&["--stage", "generator", "--epochs", "3", "--resume", r]);
    assert!(!ok && stderr.contains("trained on the older generator"), "{stderr}");
    assert_eq!(json(&runp.join("config.json"))["model"], "rnn-gmm");
}

#[test]
fn a_refiner_needs_a_generator_and_options_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty");
    let (ok, _, stderr) = train(&["--stage", "refiner", "--out", empty.to_str().unwrap()]);
    assert!(!ok && stderr.contains("holds no trained generator") && stderr.contains("--stage generator"), "{stderr}");
    let (ok, _, stderr) = train(&["--epochs", "0", "--out", empty.to_str().unwrap()]);
    assert!(!ok && stderr.contains("--epochs"), "{stderr}");
    let (ok, _, stderr) = train(&["--valid-glob", "*x*", "--out", empty.to_str().unwrap()]);
    assert!(!ok && stderr.contains("give --data PATH"), "{stderr}");
    let (ok, _, stderr) = train(&["--resume", dir.path().join("nothing").to_str().unwrap()]);
    assert!(!ok && stderr.contains("no such folder"), "{stderr}");
    let (ok, _, stderr) = train(&["--refiner-root-smoothing", "-1", "--out", empty.to_str().unwrap()]);
    assert!(!ok && stderr.contains("--refiner-root-smoothing") && stderr.contains("negative"), "{stderr}");
    let (ok, _, stderr) = train(&["--refiner-joint-limits", "maybe", "--out", empty.to_str().unwrap()]);
    assert!(!ok && stderr.contains("--refiner-joint-limits"), "{stderr}");
}

/// Copies the BVH file `src` to `dst` with the first value of its third frame replaced by `nan`.
fn write_with_nan(src: &Path, dst: &Path) {
    let text = std::fs::read_to_string(src).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let row = lines.iter().position(|l| l.starts_with("Frame Time")).unwrap() + 3;
    let first = lines[row].split(' ').next().unwrap().len();
    lines[row].replace_range(..first, "nan");
    std::fs::write(dst, lines.join("\n") + "\n").unwrap();
}

#[test]
fn generate_is_deterministic_streams_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let r = trained(dir.path());
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    // 700 frames: three chunks of the stream.
    let gen_args = |o: &str, seed: &str| -> Vec<String> {
        ["generate", "--model", &r, "--frames", "700", "--seed", seed, "--out", o, "--init-steps", "5"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    };
    let call = |args: Vec<String>| ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    call(gen_args(&out("a.bvh"), "3"));
    call(gen_args(&out("b.bvh"), "3"));
    call(gen_args(&out("c.bvh"), "4"));
    let bytes = |n: &str| std::fs::read(dir.path().join(n)).unwrap();
    assert_eq!(bytes("a.bvh"), bytes("b.bvh"), "same seed, different files");
    assert_eq!(bytes("a.contacts.json"), bytes("b.contacts.json"));
    assert_ne!(bytes("a.bvh"), bytes("c.bvh"), "another seed, same file");
    let clip = zoo_data::bvh::read_file(&dir.path().join("a.bvh"), &Default::default()).unwrap();
    assert_eq!(clip.frames(), 700);
    assert!(clip.local_rotations.iter().all(|q| q.is_finite()));
    let contacts = json(&dir.path().join("a.contacts.json"));
    assert_eq!(contacts["contacts"].as_array().unwrap().len(), 700);
    assert_eq!(contacts["frames"], 700);
    // Several sequences into a folder: seeds 3 and 4 are the single files above.
    let mut many = gen_args(&out("many"), "3");
    many.extend(["--count".to_string(), "2".to_string()]);
    call(many);
    assert_eq!(bytes("many/seed3.bvh"), bytes("a.bvh"));
    assert_eq!(bytes("many/seed4.bvh"), bytes("c.bvh"));
    // The generator alone gives other motion; the generator stage folder has no refiner.
    let mut raw = gen_args(&out("raw.bvh"), "3");
    raw.push("--no-refiner".into());
    call(raw);
    assert_ne!(bytes("raw.bvh"), bytes("a.bvh"));
    let gen_dir = format!("{r}/generator");
    let e = fails(&["generate", "--model", &gen_dir, "--frames", "10", "--out", &out("x.bvh")]);
    assert!(e.contains("holds no refiner") && e.contains("--no-refiner"), "{e}");
    ok(&["generate", "--model", &gen_dir, "--frames", "10", "--out", &out("x.bvh"), "--no-refiner"]);

    // A start clip of another skeleton.
    let toy = dir.path().join("toy.bvh");
    zoo_data::bvh::write_file(&zoo_tests::toy_clip(40, 0.0), &toy).unwrap();
    let from = format!("{}:20", toy.display());
    let e = fails(&["generate", "--model", &r, "--frames", "10", "--from", &from, "--out", &out("y.bvh")]);
    assert!(e.contains("another skeleton"), "{e}");
    // A start clip whose dummy root carries motion is folded into its child, as a dataset's.
    let moving = dir.path().join("moving.bvh");
    let start = zoo_data::bvh::read_file(&Path::new(&r).join("start.bvh"), &Default::default()).unwrap();
    std::fs::write(&moving, zoo_tests::under_dummy_root(&start, true)).unwrap();
    let from = format!("{}:20", moving.display());
    let (okay, _, e) = run(&["generate", "--model", &r, "--frames", "10", "--from", &from, "--out", &out("m.bvh")]);
    assert!(okay && e.contains("its dummy root `joint_Root` carries motion; folded into"), "{e}");
    // NaN in the start clip.
    let nan = dir.path().join("nan.bvh");
    write_with_nan(&Path::new(&r).join("start.bvh"), &nan);
    let from = format!("{}:20", nan.display());
    let e = fails(&["generate", "--model", &r, "--frames", "10", "--from", &from, "--out", &out("y.bvh")]);
    assert!(e.contains("expected a number") && e.contains("nan"), "{e}");
    // A frame past the clip's end, and several sequences into one file.
    let from = format!("{}:5000", Path::new(&r).join("start.bvh").display());
    let e = fails(&["generate", "--model", &r, "--frames", "10", "--from", &from, "--out", &out("y.bvh")]);
    assert!(e.contains("frame 5000 is past the clip's last frame"), "{e}");
    let e = fails(&["generate", "--model", &r, "--frames", "10", "--count", "2", "--out", &out("y.bvh")]);
    assert!(e.contains("give a folder as --out"), "{e}");
    let e = fails(&["generate", "--model", &r, "--frames", "10", "--init-steps", "99999999", "--out", &out("y.bvh")]);
    assert!(e.contains("--init-steps") && e.contains("0..=10000"), "{e}");
    let e = fails(&["generate", "--model", &r, "--out", &out("y.bvh")]);
    assert!(e.contains("--frames N or --seconds S"), "{e}");
    // A refiner without its generator.
    let broken = dir.path().join("broken");
    std::fs::create_dir(&broken).unwrap();
    for f in ["config.json", "features.json", "normalization.json", "refiner.safetensors", "effectors.json"] {
        std::fs::copy(Path::new(&r).join(f), broken.join(f)).unwrap();
    }
    let e = fails(&["generate", "--model", broken.to_str().unwrap(), "--frames", "10", "--out", &out("z.bvh")]);
    assert!(e.contains("no generator weights") && e.contains("it has a refiner"), "{e}");
    assert!(!dir.path().join("z.bvh").exists() && !dir.path().join("y.bvh").exists());

    // The generator's export loads as a synthesis model of the runtime.
    let onnx = out("gmm.onnx");
    let stdout = ok(&["export", "--onnx", &r, "--out", &onnx]);
    assert!(stdout.contains("RNN-GMM generator step graph") && stdout.contains("and the refiner's step"), "{stdout}");
    let model = zoo_runtime::synthesis::SynthesisModel::load(&onnx).unwrap();
    assert_eq!(model.model().metadata().model_kind, "rnn-gmm");
    assert!(model.has_refiner());
    // Refiner weights past f32's sums (or NaN) are refused at export, naming the file and the tensor.
    let damaged = dir.path().join("damaged");
    std::fs::create_dir(&damaged).unwrap();
    for e in std::fs::read_dir(&r).unwrap().map(|e| e.unwrap()).filter(|e| e.path().is_file()) {
        std::fs::copy(e.path(), damaged.join(e.file_name())).unwrap();
    }
    for value in [3e38f32, f32::NAN] {
        let weights = damaged.join("refiner.safetensors");
        let mut bytes = std::fs::read(&weights).unwrap();
        let n = bytes.len();
        bytes[n - 4..].copy_from_slice(&value.to_le_bytes());
        std::fs::write(&weights, bytes).unwrap();
        let e = fails(&["export", "--onnx", damaged.to_str().unwrap(), "--out", &out("damaged.onnx")]);
        assert!(e.contains("refiner.safetensors: tensor `") && e.contains("outside the weights' range"), "{e}");
        assert!(!dir.path().join("damaged.onnx").exists());
    }
    // `zoo generate` fits the seed frames' state on the training model: the run folder, not the file.
    let e = fails(&["generate", "--model", &onnx, "--frames", "10", "--out", &out("f.bvh")]);
    assert!(e.contains("is a file") && e.contains("takes the run folder of `zoo train rnn-gmm`"), "{e}");
    let stdout = ok(&["export", "--onnx", &gen_dir, "--out", &onnx]);
    assert!(stdout.contains("without a refiner"), "{stdout}");
    assert!(!zoo_runtime::synthesis::SynthesisModel::load(&onnx).unwrap().has_refiner());

    // The synthesis benchmark on synthetic clips written as BVH.
    let data = out("synth");
    ok(&["data", "synth", "--out", &data, "--minutes", "0.5", "--seed", "9"]);
    let report = out("bench.json");
    let bench = |threads: &str, report: &str| {
        ok(&[
            "bench",
            "synthesis",
            "--model",
            &r,
            "--data",
            &data,
            "--glob",
            "*",
            "--sequences",
            "3",
            "--seconds",
            "3",
            "--threads",
            threads,
            "--json",
            report,
        ])
    };
    let stdout = bench("2", &report);
    assert!(stdout.contains("| rnn+refiner |") && stdout.contains("first-frame jump"), "{stdout}");
    let j = json(Path::new(&report));
    let rows = j["rows"].as_array().unwrap();
    assert_eq!(rows.iter().map(|r| r["name"].as_str().unwrap()).collect::<Vec<_>>(), ["real", "rnn", "rnn+refiner"]);
    assert_eq!(rows[0]["root_speed_w1"], 0.0);
    assert_eq!(rows[0]["jerk_ratio"], 1.0);
    assert!(rows[1]["foot_skate"].as_f64().unwrap() > 0.0);
    assert!(rows[2]["contact_accuracy"].as_f64().unwrap() >= 0.0);
    assert!(j["first_frame_jump_eq26"].as_f64().unwrap().is_finite());
    // The figures do not depend on the number of worker threads.
    let one = out("bench1.json");
    bench("1", &one);
    let mut k = json(Path::new(&one));
    let mut j = j;
    for r in [&mut j, &mut k] {
        r.as_object_mut().unwrap().remove("seconds_per_sequence");
    }
    assert_eq!(j, k, "bench synthesis with 1 and 2 threads");
    // Each width's quality: the exported model's weights stored as `zoo export --weights` does.
    let f16 = out("bench_f16.json");
    let mut args = vec!["bench", "synthesis", "--model", &r, "--data", &data, "--glob", "*", "--sequences", "3"];
    args.extend(["--seconds", "3", "--threads", "1", "--weights", "f16", "--json", &f16]);
    ok(&args);
    let h = json(Path::new(&f16));
    for (a, b) in h["rows"].as_array().unwrap().iter().zip(k["rows"].as_array().unwrap()).skip(1) {
        let (a, b) = (a["foot_skate"].as_f64().unwrap(), b["foot_skate"].as_f64().unwrap());
        assert!(a.is_finite() && a > 0.0 && (a - b).abs() < 0.5 * b, "f16 skate {a}, f32 {b}");
    }
    // The range from more clips than the held-out ones: never narrower, so no row leaves it
    // more often; the other clips are checked against the held-out clips' own range.
    let range = |extra: &[&str], report: &str| {
        let mut args = vec![
            "bench",
            "synthesis",
            "--model",
            &r,
            "--data",
            &data,
            "--glob",
            "*_0001.bvh",
            "--sequences",
            "3",
            "--seconds",
            "3",
            "--json",
            report,
        ];
        args.extend_from_slice(extra);
        ok(&args);
        json(Path::new(report))
    };
    let held_out = range(&[], &out("held.json"));
    let wide = range(&["--range-glob", "*"], &out("wide.json"));
    assert!(held_out["range_clips_outside_held_out_range"].is_null());
    let [n, of] = [0, 1].map(|i| wide["range_clips_outside_held_out_range"][i].as_u64().unwrap());
    let all = std::fs::read_dir(&data)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "bvh"))
        .count();
    let held = std::fs::read_dir(&data)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().ends_with("_0001.bvh"))
        .count();
    assert!(held > 0 && of as usize == all - held && n <= of, "{wide}");
    for k in 0..3 {
        let (h, w) = (&held_out["rows"][k], &wide["rows"][k]);
        assert!(w["out_of_range"].as_f64().unwrap() <= h["out_of_range"].as_f64().unwrap(), "{h} {w}");
        assert_eq!(h["foot_skate"], w["foot_skate"]);
    }
    let e = fails(&["bench-synthesis", "--model", &r, "--data", &data, "--glob", "nothing*"]);
    assert!(e.contains("nothing*") || e.contains("no clip"), "{e}");
}

#[test]
fn denoise_writes_a_clip_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let r = trained(dir.path());
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let start = Path::new(&r).join("start.bvh");
    let input = zoo_data::bvh::read_file(&start, &Default::default()).unwrap();
    let stdout = ok(&["denoise", "--model", &r, start.to_str().unwrap(), "--out", &out("d.bvh"), "--iterations", "3"]);
    assert!(stdout.contains("estimated") && stdout.contains("L-BFGS"), "{stdout}");
    let clip = zoo_data::bvh::read_file(&dir.path().join("d.bvh"), &Default::default()).unwrap();
    assert_eq!(clip.frames(), input.frames());
    assert!(clip.local_rotations.iter().all(|q| q.is_finite()));
    assert_eq!(json(&dir.path().join("d.contacts.json"))["contacts"].as_array().unwrap().len(), input.frames());
    // Another skeleton, NaN in the clip, a bad noise level.
    let toy = dir.path().join("toy.bvh");
    zoo_data::bvh::write_file(&zoo_tests::toy_clip(40, 0.0), &toy).unwrap();
    let e = fails(&["denoise", "--model", &r, toy.to_str().unwrap(), "--out", &out("e.bvh")]);
    assert!(e.contains("another skeleton"), "{e}");
    let nan = dir.path().join("nan.bvh");
    write_with_nan(&start, &nan);
    let e = fails(&["denoise", "--model", &r, nan.to_str().unwrap(), "--out", &out("e.bvh")]);
    assert!(e.contains("nan"), "{e}");
    let e = fails(&["denoise", "--model", &r, start.to_str().unwrap(), "--out", &out("e.bvh"), "--sigma-angle", "-1"]);
    assert!(e.contains("--sigma-angle"), "{e}");
    assert!(!dir.path().join("e.bvh").exists());
    // The benchmark: the Savitzky-Golay baseline removes part of the noise.
    let report = out("dn.json");
    let data = start.to_str().unwrap();
    ok(&[
        "bench",
        "denoise",
        "--model",
        &r,
        "--data",
        data,
        "--glob",
        "*",
        "--clips",
        "1",
        "--seconds",
        "2",
        "--angle-noise",
        "3",
        "--iterations",
        "2",
        "--savgol-windows",
        "5",
        "--json",
        &report,
    ]);
    let j = json(Path::new(&report));
    let rows = j["levels"][0]["rows"].as_array().unwrap();
    let get = |m: &str| rows.iter().find(|r| r["method"] == m).unwrap()["l2q"].as_f64().unwrap();
    assert!(get("noisy") > 0.0 && get("savgol(5)") < get("noisy"), "{j}");
    assert!(get("denoised").is_finite());
    let e = fails(&["bench", "denoise", "--model", &r, "--data", data, "--glob", "*", "--savgol-windows", "8"]);
    assert!(e.contains("--savgol-windows"), "{e}");
}

#[test]
fn follow_walks_a_path_writes_a_plot_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let r = trained(dir.path());
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let write = |name: &str, text: &str| {
        std::fs::write(dir.path().join(name), text).unwrap();
        out(name)
    };
    let path = write("p.json", r#"{"units": "m", "points": [[0, 0], [0, 1.5]]}"#);
    let fast = ["--particles", "3", "--swarm-iterations", "1", "--iterations", "2"];
    let (f_bvh, f_png, g_bvh) = (out("f.bvh"), out("f.png"), out("g.bvh"));
    let mut args = vec!["follow", "--model", &r, "--path", &path, "--out", &f_bvh, "--plot", &f_png];
    args.extend_from_slice(&fast);
    let stdout = ok(&args);
    assert!(stdout.contains("root to path: mean") && stdout.contains("per generated second"), "{stdout}");
    let clip = zoo_data::bvh::read_file(&dir.path().join("f.bvh"), &Default::default()).unwrap();
    assert!(clip.frames() > 0 && clip.local_rotations.iter().all(|q| q.is_finite()));
    assert_eq!(json(&dir.path().join("f.contacts.json"))["contacts"].as_array().unwrap().len(), clip.frames());
    assert_eq!(&std::fs::read(dir.path().join("f.png")).unwrap()[1..4], b"PNG");
    // A start clip at 60 fps is resampled to the model's 30 fps with a note; the output is at 30 fps.
    let start60 = out("start60.bvh");
    let start = Path::new(&r).join("start.bvh");
    ok(&["data", "resample", start.to_str().unwrap(), &start60, "--fps", "60"]);
    let from = format!("{start60}:58");
    let mut args = vec!["follow", "--model", &r, "--path", &path, "--from", &from];
    let f60 = out("f60.bvh");
    args.extend_from_slice(&["--out", &f60]);
    args.extend_from_slice(&fast);
    let (ok60, stdout, stderr) = run(&args);
    assert!(ok60, "{stdout}\n{stderr}");
    assert!(stderr.contains("is at 60.000 fps, the model at 30.000 fps: resampled to 30.000 fps"), "{stderr}");
    let clip60 = zoo_data::bvh::read_file(Path::new(&f60), &Default::default()).unwrap();
    assert!((clip60.fps() - 30.0).abs() < 1e-3, "written at {} fps", clip60.fps());
    // SVG path data are read too.
    let svg = write("p.svg", r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M 0 0 C 0 50 20 100 0 150"/></svg>"#);
    let mut args = vec!["follow", "--model", &r, "--path", &svg, "--out", &g_bvh];
    args.extend_from_slice(&fast);
    ok(&args);
    // Bad input: one point, a point off the ground plane, another skeleton, a bad option.
    let e = fails(&[
        "follow",
        "--model",
        &r,
        "--path",
        &write("one.json", r#"{"points": [[0, 0]]}"#),
        "--out",
        &out("e.bvh"),
    ]);
    assert!(e.contains("at least 2 distinct points"), "{e}");
    let up = write("up.json", r#"{"points": [[0, 0, 0], [0, 1, 2]]}"#);
    let e = fails(&["follow", "--model", &r, "--path", &up, "--out", &out("e.bvh")]);
    assert!(e.contains("ground plane"), "{e}");
    let toy = dir.path().join("toy.bvh");
    zoo_data::bvh::write_file(&zoo_tests::toy_clip(40, 0.0), &toy).unwrap();
    let from = format!("{}:10", toy.display());
    let e = fails(&["follow", "--model", &r, "--path", &path, "--from", &from, "--out", &out("e.bvh")]);
    assert!(e.contains("another skeleton"), "{e}");
    let e = fails(&["follow", "--model", &r, "--path", &path, "--out", &out("e.bvh"), "--particles", "1"]);
    assert!(e.contains("--particles"), "{e}");
    let e = fails(&["follow", "--model", &r, "--path", &out("missing.json"), "--out", &out("e.bvh")]);
    assert!(e.contains("missing.json"), "{e}");
    assert!(!dir.path().join("e.bvh").exists());
    // The benchmark on one test path.
    let (report, plots) = (out("bf.json"), out("plots"));
    let mut args = vec!["bench", "follow", "--model", &r, "--paths", "straight", "--json", &report, "--plots", &plots];
    args.extend_from_slice(&fast);
    let stdout = ok(&args);
    assert!(stdout.contains("| straight |"), "{stdout}");
    let j = json(Path::new(&report));
    assert_eq!(j["rows"].as_array().unwrap().len(), 1);
    assert!(j["rows"][0]["mean_distance"].as_f64().unwrap().is_finite());
    for f in ["all.png", "straight-start0.png", "straight-start0.bvh"] {
        assert!(Path::new(&plots).join(f).is_file(), "{f}");
    }
    // The runtime's real-time follower on the exported generator: to the path's end, close to
    // it, measured as the offline follower is.
    let onnx = out("g.onnx");
    ok(&["export", "--onnx", &r, "--out", &onnx]);
    let rt = out("bf-runtime.json");
    let args =
        ["bench", "follow", "--model", &r, "--onnx", &onnx, "--followers", "runtime", "--paths", "straight,corner"];
    let stdout = ok(&[&args[..], &["--json", rt.as_str()]].concat());
    assert!(stdout.contains("| runtime |"), "{stdout}");
    let j = json(Path::new(&rt));
    let rows = j["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for row in rows {
        assert_eq!(row["follower"], "runtime");
        let (mean, max) = (row["mean_distance"].as_f64().unwrap(), row["max_distance"].as_f64().unwrap());
        assert!(mean.is_finite() && max >= mean && row["foot_skate"].as_f64().unwrap().is_finite(), "{row}");
    }
    let e = fails(&["bench", "follow", "--model", &r, "--followers", "runtime"]);
    assert!(e.contains("--followers runtime needs --onnx FILE"), "{e}");
    let e = fails(&["bench", "follow", "--model", &r, "--followers", "walk"]);
    assert!(e.contains("unknown method `walk` in --followers"), "{e}");
}

#[test]
fn control_follows_a_script_in_candle_and_the_runtime_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let r = trained(dir.path());
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let write = |name: &str, text: &str| {
        std::fs::write(dir.path().join(name), text).unwrap();
        out(name)
    };
    let script = write(
        "s.json",
        r#"{"units": "m", "duration": 3, "keys": [{"time": 0, "speed": 1.2, "heading": 0}, {"time": 1.5, "heading": 120}]}"#,
    );
    let (c_bvh, c_png) = (out("c.bvh"), out("c.png"));
    let stdout = ok(&["control", "--model", &r, "--script", &script, "--out", &c_bvh, "--plot", &c_png]);
    assert!(stdout.contains("ms per frame") && stdout.contains("0.0 s: speed"), "{stdout}");
    let clip = zoo_data::bvh::read_file(Path::new(&c_bvh), &Default::default()).unwrap();
    assert_eq!(clip.frames(), 90);
    assert!(clip.local_rotations.iter().all(|q| q.is_finite()));
    assert_eq!(json(&dir.path().join("c.contacts.json"))["contacts"].as_array().unwrap().len(), 90);
    assert_eq!(&std::fs::read(&c_png).unwrap()[1..4], b"PNG");
    // A start clip at 60 fps is resampled to the model's 30 fps with a note (its frame carried
    // over); the script is in seconds, so the motion is the same 90 frames at the model's rate.
    let start60 = out("start60.bvh");
    let start = Path::new(&r).join("start.bvh");
    ok(&["data", "resample", start.to_str().unwrap(), &start60, "--fps", "60"]);
    let from = format!("{start60}:58");
    let (ok60, stdout, stderr) =
        run(&["control", "--model", &r, "--script", &script, "--from", &from, "--out", &out("c60.bvh")]);
    assert!(ok60, "{stdout}\n{stderr}");
    assert!(stderr.contains("is at 60.000 fps, the model at 30.000 fps: resampled to 30.000 fps"), "{stderr}");
    let c60 = zoo_data::bvh::read_file(&dir.path().join("c60.bvh"), &Default::default()).unwrap();
    assert!(c60.frames() == 90 && (c60.fps() - 30.0).abs() < 1e-3, "{} frames at {} fps", c60.frames(), c60.fps());
    // 300 speed and 300 turn offsets (90,000 proposals held 2.7 GB) are refused before any
    // proposal is made, under a 2 GB address-space limit, with the size and the options.
    let offsets: Vec<String> = (0..300).map(|i| format!("{:.2}", -1.5 + 0.01 * i as f64)).collect();
    let offsets = offsets.join(",");
    let script_line = format!(
        "ulimit -v 2000000; exec {} control --model {r} --script {script} --out {} --speed-offsets={offsets} \
         --turn-offsets={offsets}",
        zoo_tests::zoo_bin().display(),
        out("big.bvh")
    );
    let o = std::process::Command::new("bash").args(["-c", &script_line]).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("90000 proposals (300 speed offsets x 300 turn offsets)")
            && e.contains("past the memory bound of 2.00 GB")
            && e.contains("ZOO_MEMORY_GB"),
        "{e}"
    );
    assert!(!dir.path().join("big.bvh").exists());
    // Bad input: a negative speed, a speed that is not a number, a heading that is not finite,
    // another skeleton, a bad option, a missing script; nothing is written.
    for (text, want) in [
        (r#"{"duration": 2, "keys": [{"time": 0, "speed": -1, "heading": 0}]}"#, "from 0 to"),
        (r#"{"duration": 2, "keys": [{"time": 0, "speed": "NaN", "heading": 0}]}"#, "must be a number"),
        (r#"{"duration": 2, "keys": [{"time": 0, "speed": 1, "heading": 1e999}]}"#, "does not parse"),
    ] {
        let bad = write("bad.json", text);
        let e = fails(&["control", "--model", &r, "--script", &bad, "--out", &out("e.bvh")]);
        assert!(e.contains(want), "{text}: {e}");
    }
    let toy = dir.path().join("toy.bvh");
    zoo_data::bvh::write_file(&zoo_tests::toy_clip(40, 0.0), &toy).unwrap();
    let from = format!("{}:10", toy.display());
    let e = fails(&["control", "--model", &r, "--script", &script, "--from", &from, "--out", &out("e.bvh")]);
    assert!(e.contains("another skeleton"), "{e}");
    let e = fails(&["control", "--model", &r, "--script", &script, "--out", &out("e.bvh"), "--batch", "0"]);
    assert!(e.contains("--batch"), "{e}");
    let e = fails(&["control", "--model", &r, "--script", &out("missing.json"), "--out", &out("e.bvh")]);
    assert!(e.contains("missing.json"), "{e}");
    assert!(!dir.path().join("e.bvh").exists());
    // The benchmark: the candle and the runtime controller on the same script.
    let onnx = out("g.onnx");
    ok(&["export", "--onnx", &r, "--out", &onnx]);
    let (report, plots) = (out("bc.json"), out("plots"));
    let stdout = ok(&[
        "bench", "control", "--model", &r, "--onnx", &onnx, "--script", &script, "--seeds", "1", "--json", &report,
        "--plots", &plots,
    ]);
    assert!(stdout.contains("| candle | 1 |") && stdout.contains("| runtime | 1 |"), "{stdout}");
    let j = json(Path::new(&report));
    let runs = j["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for run in runs {
        assert_eq!(run["frames"].as_u64(), Some(90));
        // Each key measured from 1 s after it to the next.
        assert_eq!(run["segments"].as_array().unwrap().len(), 2);
        assert!(run["ms_per_frame_median"].as_f64().unwrap() > 0.0);
    }
    for f in ["candle-seed1.png", "candle-seed1.bvh", "runtime-seed1.png"] {
        assert!(Path::new(&plots).join(f).is_file(), "{f}");
    }
    let e = fails(&["bench", "control", "--model", &r, "--controllers", "runtime", "--script", &script]);
    assert!(e.contains("--onnx"), "{e}");
}
