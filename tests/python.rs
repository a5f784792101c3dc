//! The Python package (`runtime/python/`) and the Blender add-on (`apps/blender/`), run by the real
//! interpreters.
//!
//! The extension is built in this suite's profile and target dir, with the rest of the
//! workspace (`cargo build --workspace --lib`: the same features as the suite's build, so tract
//! is not compiled a second time), packed into a wheel with maturin's metadata
//! (`runtime/python/pack_wheel.py`) and installed with pip into a temporary folder. The models are
//! tiny ones of every task exported here (seeded weights, the synthetic locomotion's 21-joint
//! skeleton); the references are the Rust runtime's own outputs for the same inputs, so the
//! pytest suite (`runtime/python/tests`) checks the package against the runtime it wraps.
//!
//! `pytest_package` runs pytest with a Python virtual environment in `target/python-venv`
//! (numpy, pytest, maturin from PyPI, made on first use). `blender_addon` runs
//! `apps/blender/tests/test_addon.py` in Blender headless (`blender -b --factory-startup`): it installs
//! the add-on zip made by `apps/blender/make_addon.py` with the wheel inside, imports the clip with
//! Blender's BVH importer and runs each operator; it reports its figures (in-between error,
//! walk distance, speed) in the test log. Without Blender it says so and checks nothing, unless
//! `ZOO_REQUIRE_BLENDER=1` (set by `.ci/run`, which installs Blender) makes that a failure.

use candle_core::{DType, Device};
use glam::{DVec3, Quat};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use zoo_motion::Clip;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::follow::{PathGoal, PathSettings};
use zoo_runtime::{EnginePose, FootCleanup, LoadedModel, MotionKeys};

/// Everything the Python and Blender tests share, made once per test process.
struct Fixture {
    _dir: Option<tempfile::TempDir>,
    /// The venv's interpreter (numpy, pytest, maturin).
    python: PathBuf,
    /// The wheel packed from this build.
    wheel: PathBuf,
    /// The folder pip installed the wheel into (on `PYTHONPATH` for pytest).
    site: PathBuf,
    /// Models, clips and references.
    data: PathBuf,
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").canonicalize().expect("the repository")
}

/// The profile folder of this build (`target/debug`).
fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    exe.parent().and_then(|d| d.parent()).expect("profile dir").to_path_buf()
}

/// Runs `cmd`, panicking with its output when it fails; returns its stdout.
fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: cannot start {cmd:?}: {e}"));
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{what} failed ({}):\n--- stdout\n{stdout}\n--- stderr\n{stderr}", out.status);
    stdout.into_owned()
}

/// The extension module, built with the workspace (one feature set for every crate).
fn build_extension() -> PathBuf {
    let profile = profile_dir();
    let mut cargo = Command::new(env!("CARGO"));
    cargo.args(["build", "--workspace", "--lib"]).current_dir(repo());
    if profile.file_name().is_some_and(|n| n == "release") {
        cargo.arg("--release");
    }
    run(&mut cargo, "building the extension (cargo build --workspace --lib)");
    let lib = profile.join(format!("{}_native{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX));
    assert!(lib.is_file(), "{} was not built", lib.display());
    lib
}

/// The test venv (numpy, pytest, maturin), made on first use.
fn venv() -> PathBuf {
    let dir = profile_dir().parent().expect("target dir").join("python-venv");
    let python = dir.join("bin/python");
    let ready = dir.join(".zoo-test-ready");
    if !ready.is_file() {
        if !python.is_file() {
            run(Command::new("python3").args(["-m", "venv"]).arg(&dir), "making the test venv (python3 -m venv)");
        }
        run(
            Command::new(&python).args(["-m", "pip", "install", "-q", "numpy", "pytest", "maturin>=1.7,<2"]),
            "installing numpy, pytest and maturin into the test venv (needs PyPI)",
        );
        std::fs::write(&ready, "numpy pytest maturin\n").expect("venv marker");
    }
    python
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().expect("temp dir");
        let lib = build_extension();
        let python = venv();
        let maturin = python.with_file_name("maturin");
        let wheels = dir.path().join("wheels");
        let out = run(
            Command::new(&python)
                .arg(repo().join("runtime/python/pack_wheel.py"))
                .arg("--lib")
                .arg(&lib)
                .arg("--out")
                .arg(&wheels)
                .arg("--maturin")
                .arg(&maturin),
            "packing the wheel",
        );
        let wheel = PathBuf::from(out.trim());
        let site = dir.path().join("site");
        run(
            Command::new(&python).args(["-m", "pip", "install", "-q", "--no-deps", "--target"]).arg(&site).arg(&wheel),
            "installing the wheel",
        );
        let data = dir.path().join("data");
        std::fs::create_dir_all(&data).unwrap();
        write_models_and_references(&data);
        // ZOO_TEST_KEEP=1 keeps the folder (models, clips, wheel, add-on zip) to debug with.
        let dir = if std::env::var_os("ZOO_TEST_KEEP").is_some() {
            println!("ZOO_TEST_KEEP: the test data stays in {}", dir.keep().display());
            None
        } else {
            Some(dir)
        };
        Fixture { _dir: dir, python, wheel, site, data }
    })
}

/// A tiny humanoid ARNN on `clip`'s skeleton (seeded weights, statistics of its poses), with
/// its candle model and statistics for the reference completion.
fn humanoid_arnn(clip: &Clip) -> (Vec<u8>, zoo_arnn::Arnn, zoo_arnn::Normalization) {
    let mut config = zoo_arnn::humanoid::config_for(&clip.skeleton, 30.0);
    config.feature = 8;
    config.hidden = 16;
    config.decoder = 8;
    config.gru_dropout = [0.0, 0.0];
    config.linear_dropout = [0.0, 0.0];
    let varmap = candle_nn::VarMap::new();
    let model = zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))
        .expect("humanoid ARNN");
    let j = clip.joints();
    let roots: Vec<DVec3> = (0..clip.frames()).map(|f| clip.root_position(f)).collect();
    let poses = zoo_arnn::humanoid::poses(&roots, &clip.local_rotations, j);
    let d = config.dofs;
    let n = poses.len() as f64;
    let mean: Vec<f64> = (0..d).map(|i| poses.iter().map(|p| p[i]).sum::<f64>() / n).collect();
    let std: Vec<f64> =
        (0..d).map(|i| (poses.iter().map(|p| (p[i] - mean[i]).powi(2)).sum::<f64>() / n).sqrt().max(0.01)).collect();
    let norm = zoo_arnn::Normalization { mean, std };
    let bytes = zoo_arnn::export::export_arnn(&config, &norm, &varmap).expect("the ARNN exports").to_bytes();
    (bytes, model, norm)
}

/// BVH-style arrays of frames `range` of `clip` (hips, rotations `(x, y, z, w)`), f32.
fn world_arrays(clip: &Clip, range: std::ops::Range<usize>) -> (Vec<f32>, Vec<f32>) {
    let hips = range.clone().flat_map(|f| clip.root_position(f).as_vec3().to_array()).collect();
    let rot = range.flat_map(|f| clip.rotations_at(f).iter().flat_map(|q| q.as_quat().to_array())).collect();
    (hips, rot)
}

/// Frame `f` of `clip` as the package makes it from the clip's arrays (`Poses.from_world`:
/// f32, each rotation normalised), so that both give the runtime the same input bits.
fn engine_pose(clip: &Clip, f: usize) -> EnginePose {
    let rot: Vec<Quat> = clip.rotations_at(f).iter().map(|q| q.as_quat().normalize()).collect();
    EnginePose::from_world(clip.root_position(f).as_vec3(), &rot)
}

/// One engine pose's BVH-style arrays, appended.
fn push_world(p: &EnginePose, hips: &mut Vec<f32>, rot: &mut Vec<f32>) {
    hips.extend(p.hips_world().to_array());
    rot.extend(p.hips_world_rotation().to_array());
    for q in &p.local_rotations[1..] {
        rot.extend(q.to_array());
    }
}

/// Exports the models and writes the clip and the Rust runtime's reference outputs.
fn write_models_and_references(data: &Path) {
    // The clips as the package reads them back from the files (the writer rounds to 6 decimals).
    let read_back = |clip: &Clip, name: &str| -> Clip {
        let path = data.join(name);
        zoo_data::bvh::write_file(clip, &path).unwrap();
        zoo_data::bvh::read_file(&path, &zoo_data::bvh::ReadOptions::default()).unwrap()
    };
    let clip = read_back(&zoo_tests::synth_biped_clip(0), "clip.bvh");
    let other = read_back(&zoo_tests::synth_biped_clip(1), "clip2.bvh");
    // The glTF route into Blender: the clip as `zoo data convert clip.bvh clip.glb` writes it.
    zoo_data::clip_io::write(&clip, &data.join("clip.glb")).expect("writing clip.glb");
    let k = clip.joints();
    let mut refs = serde_json::Map::new();

    // The clip at 24 fps as `zoo data resample` makes it (`zoo_motion::Clip::resampled`).
    let at24 = clip.resampled(24.0);
    refs.insert(
        "resample".into(),
        json!({"fps": 24.0, "frames": at24.frames(),
               "rotations": at24.local_rotations.iter().flat_map(|q| q.to_array()).collect::<Vec<f64>>(),
               "positions": at24.local_positions.iter().flat_map(|p| p.to_array()).collect::<Vec<f64>>()}),
    );

    // Transition: context frames 20..30, target 60, next 61, in engine poses.
    let rtn = zoo_tests::biped_rtn_onnx(&clip, false, None);
    std::fs::write(data.join("transition.onnx"), &rtn).unwrap();
    let model = LoadedModel::from_bytes(&rtn).unwrap().into_transition().unwrap();
    let mut runner = model.runner().unwrap();
    let mut state = model.new_transition();
    let past: Vec<EnginePose> = (20..30).map(|f| engine_pose(&clip, f)).collect();
    runner.start_posed(&mut state, &past, &engine_pose(&clip, 60), &engine_pose(&clip, 61)).unwrap();
    let mut pose = EnginePose::with_global_positions(k);
    let (mut hips, mut rot, mut global) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..=30 {
        runner.step_posed(&mut state, &mut pose).unwrap();
        push_world(&pose, &mut hips, &mut rot);
        global.extend(pose.global_positions.iter().flat_map(|p| p.to_array()));
    }
    // The same transition in positions (given to the package as they are here).
    let (_, gp) = clip.global();
    let pos = |f: usize| -> Vec<f32> { gp[f * k..(f + 1) * k].iter().flat_map(|p| p.as_vec3().to_array()).collect() };
    let past_pos: Vec<f32> = (20..30).flat_map(pos).collect();
    let mut out = vec![0.0f32; 31 * 3 * k];
    let mut s2 = model.new_transition();
    runner.generate(&mut s2, &past_pos, &pos(60), &pos(61), &mut out).unwrap();
    refs.insert(
        "transition".into(),
        json!({"past": [20, 30], "target": 60, "next": 61, "hips": hips, "rotations": rot,
               "global_positions": global, "positions": out,
               "past_positions": past_pos, "target_positions": pos(60), "next_positions": pos(61)}),
    );

    // The same RTN with fallback thresholds (in centimetres of target miss) that a target lifted
    // a metre exceeds: the fallback's default and its settings not carrying over between calls.
    let fallback = zoo_rtn::fallback::Fallback { start: 0.5, full: 2.0 };
    let rtn_fallback = zoo_tests::biped_rtn_onnx(&clip, false, Some(fallback));
    std::fs::write(data.join("transition_fallback.onnx"), &rtn_fallback).unwrap();
    // The runtime's whole posed transition with that fallback and the foot lock (what
    // `zoo transition --in-place --foot-lock` writes), frames 20..30 to 60.
    let model = LoadedModel::from_bytes(&rtn_fallback).unwrap().into_transition().unwrap();
    let mut runner = model.runner().unwrap();
    runner.set_model_fallback();
    runner.set_foot_lock(model.default_foot_lock());
    let mut out: Vec<EnginePose> = (0..=30).map(|_| EnginePose::with_global_positions(k)).collect();
    let mut state = model.new_transition();
    let (target, next) = ([engine_pose(&clip, 60)], [engine_pose(&clip, 61)]);
    runner.generate_posed_batch(std::slice::from_mut(&mut state), &past, &target, &next, 30, &mut out).unwrap();
    let (mut hips, mut rot, mut global) = (Vec::new(), Vec::new(), Vec::new());
    for pose in &out {
        push_world(pose, &mut hips, &mut rot);
        global.extend(pose.global_positions.iter().flat_map(|p| p.to_array()));
    }
    refs.insert(
        "transition_locked".into(),
        json!({"hips": hips, "rotations": rot, "global_positions": global,
               "fallback_weight": state.fallback_weight()}),
    );

    // The paper-sized RTN (Blender's speed figure).
    std::fs::write(data.join("transition_paper.onnx"), zoo_tests::biped_rtn_onnx(&clip, true, None)).unwrap();

    // Keyframes: the lamp (raw pose vectors) and a humanoid model.
    let lamp = zoo_tests::tiny_arnn_onnx().to_bytes();
    std::fs::write(data.join("keyframes_lamp.onnx"), &lamp).unwrap();
    let lamp_model = LoadedModel::from_bytes(&lamp).unwrap().into_keyframes().unwrap();
    let frames = [0usize, 12, 24];
    let poses: Vec<f32> =
        [[0.5, 0.1, 0.0, 0.5, -1.1, -1.2], [0.7, 0.15, 0.2, 0.4, -1.0, -1.3], [0.9, 0.1, 0.5, 0.6, -1.2, -1.1]]
            .concat();
    let mut completed = vec![0.0f32; 25 * lamp_model.dofs()];
    lamp_model.runner(1).unwrap().complete(MotionKeys::whole(&frames, &poses), &mut completed).unwrap();
    refs.insert("keyframes_lamp".into(), json!({"frames": frames, "poses": poses, "completed": completed}));

    let (arnn, arnn_model, arnn_norm) = humanoid_arnn(&clip);
    std::fs::write(data.join("keyframes.onnx"), &arnn).unwrap();
    let keys: Vec<zoo_arnn::humanoid::HumanoidKey> = [(0, 30), (15, 45), (30, 60)]
        .iter()
        .map(|&(frame, source)| zoo_arnn::humanoid::HumanoidKey { frame, source, fixed: None })
        .collect();
    let done =
        zoo_arnn::humanoid::complete_clip(zoo_arnn::humanoid::HumanoidNet::Arnn(&arnn_model), &arnn_norm, &clip, &keys)
            .expect("candle completes");
    // The runtime locks a humanoid's feet between the keys, as `zoo complete` does.
    let mut done = done;
    assert!(zoo_arnn::completion::lock_feet(&mut done.clip, &[0, 15, 30], &[]) > 0, "the test skeleton has legs");
    let (h, r) = world_arrays(&done.clip, 0..done.clip.frames());
    refs.insert(
        "keyframes".into(),
        json!({"source_frames": [30, 45, 60], "frames": [0, 15, 30], "hips": h, "rotations": r}),
    );

    // Stitch: two clips aligned (zoo-data's alignment) and refined.
    let rmr = zoo_tests::tiny_rmr_onnx().to_bytes();
    std::fs::write(data.join("stitch.onnx"), &rmr).unwrap();
    let refiner = LoadedModel::from_bytes(&rmr).unwrap().into_stitch().unwrap();
    let (a, b) = (clip.slice(0, 45), other.slice(100, 150));
    let aligned = zoo_rmr::pairs::align_clips(&[a, b], refiner.layout(), zoo_rmr::pairs::MIN_CLIP_FRAMES).unwrap();
    let t = aligned.clip.frames();
    let input: Vec<EnginePose> = (0..t).map(|f| engine_pose(&aligned.clip, f)).collect();
    let mut out_poses: Vec<EnginePose> = (0..t).map(|_| EnginePose::new(k)).collect();
    let mut contacts = vec![[false; 4]; t];
    refiner.refine_poses(&input, FootCleanup::default(), &mut out_poses, &mut contacts).unwrap();
    let (ah, ar) = world_arrays(&aligned.clip, 0..t);
    let (mut sh, mut sr) = (Vec::new(), Vec::new());
    for p in &out_poses {
        push_world(p, &mut sh, &mut sr);
    }
    let contacts: Vec<bool> = contacts.iter().flatten().copied().collect();
    // With the seam inertialized first (`zoo stitch --pre-blend`).
    let mut seam_contacts = vec![[false; 4]; t];
    refiner
        .refine_poses_at_seams(&input, &aligned.starts[1..], FootCleanup::default(), &mut out_poses, &mut seam_contacts)
        .unwrap();
    let (mut bh, mut br) = (Vec::new(), Vec::new());
    for p in &out_poses {
        push_world(p, &mut bh, &mut br);
    }
    refs.insert(
        "stitch".into(),
        json!({"a": [0, 45], "b": [100, 150], "starts": aligned.starts, "aligned_hips": ah, "aligned_rotations": ar,
               "hips": sh, "rotations": sr, "contacts": contacts, "pre_blend_hips": bh, "pre_blend_rotations": br}),
    );

    // Synthesis: two seeded characters from the mean frame; control of one; the encoding of
    // clip frames as zoo_rnngmm encodes them.
    let (config, _, trainer) = zoo_tests::rnngmm_fixture(zoo_rnngmm::prelude::Config::tiny());
    let gen_bytes =
        zoo_rnngmm::export::export_generator(&config, None, trainer.spec(), trainer.norm(), trainer.varmap())
            .expect("the RNN-GMM exports")
            .to_bytes();
    std::fs::write(data.join("synthesis.onnx"), &gen_bytes).unwrap();
    let synth = LoadedModel::from_bytes(&gen_bytes).unwrap().into_synthesis().unwrap();
    let d = synth.frame_dim();
    let mean = synth.model().metadata().group("x", d).unwrap().mean.clone();
    let mut chars: Vec<_> = [1u64, 2].iter().map(|&s| synth.new_character(s)).collect();
    for ch in &mut chars {
        ch.start(&synth, &mean, 0.0, 0.0, 0.0).unwrap();
    }
    let mut srunner = synth.runner(2).unwrap();
    let mut poses2: Vec<EnginePose> = (0..2).map(|_| EnginePose::new(k)).collect();
    let mut bits = vec![[false; 2]; 2];
    let mut per: Vec<(Vec<f32>, Vec<f32>)> = vec![(Vec::new(), Vec::new()); 2];
    for _ in 0..20 {
        srunner.step_batch(&mut chars, 1.0, &mut poses2, &mut bits).unwrap();
        for (c, p) in poses2.iter().enumerate() {
            let (h, r) = &mut per[c];
            push_world(p, h, r);
        }
    }
    let mut ch = ControlledCharacter::new(&synth, 5, ControlSettings::default()).unwrap();
    ch.start(&synth, &mean, 10.0, -20.0, 0.3).unwrap();
    let mut crunner = ControlRunner::new(&synth).unwrap();
    let (mut chips, mut crot) = (Vec::new(), Vec::new());
    let mut cpose = EnginePose::new(k);
    for _ in 0..12 {
        crunner.step(&mut ch, Control::new(150.0, 0.5), &mut cpose).unwrap();
        push_world(&cpose, &mut chips, &mut crot);
    }
    // Path following: the runtime's follower along a bend, 30 frames.
    let bend = [[0.0, 0.0], [0.0, 100.0], [80.0, 160.0]];
    let mut goal = PathGoal::new(&bend, 120.0, PathSettings::default()).unwrap();
    let mut fch = ControlledCharacter::new(&synth, 7, PathSettings::control()).unwrap();
    let [fx, fz, fyaw] = goal.start_placement();
    fch.start(&synth, &mean, fx as f32, fz as f32, fyaw as f32).unwrap();
    let (mut fhips, mut frot) = (Vec::new(), Vec::new());
    let mut frames = 0;
    while frames < 30 && !goal.reached_end() {
        crunner.step_along(&mut fch, &mut goal, &mut cpose).unwrap();
        push_world(&cpose, &mut fhips, &mut frot);
        frames += 1;
    }
    let follow = json!({"points": bend, "speed": 120.0, "seed": 7, "max_frames": 30, "frames": frames,
                        "reached_end": goal.reached_end(), "hips": fhips, "rotations": frot});
    // A tiny generator trained for 30 epochs on 3 synthetic minutes (about 12 s on one core),
    // as a user would make one: the model the Blender test walks along a curve with.
    let run_dir = data.join("rnngmm_run");
    let zoo = zoo_tests::zoo_bin();
    run(
        Command::new(&zoo)
            .args(["train", "rnn-gmm", "--stage", "generator", "--preset", "tiny", "--epochs", "30"])
            .args(["--synth-minutes", "3", "--threads", "1", "--out"])
            .arg(&run_dir),
        "training the tiny RNN-GMM (zoo train rnn-gmm --preset tiny)",
    );
    run(
        Command::new(&zoo)
            .args(["export", "--onnx"])
            .arg(&run_dir)
            .arg("--out")
            .arg(data.join("synthesis_trained.onnx")),
        "exporting it (zoo export --onnx)",
    );
    let contacts10: Vec<[bool; 2]> = (0..10).map(|f| [f % 2 == 0, f % 3 == 0]).collect();
    let enc = trainer.spec().encode_with_contacts(&clip.slice(0, 10), &contacts10).unwrap();
    let (eh, er) = world_arrays(&clip, 0..10);
    refs.insert(
        "synthesis".into(),
        json!({"seeds": [1, 2], "frames": 20, "hips": [per[0].0, per[1].0], "rotations": [per[0].1, per[1].1],
               "control": {"seed": 5, "placement": [10.0, -20.0, 0.3], "speed": 150.0, "heading": 0.5,
                           "hips": chips, "rotations": crot},
               "follow": follow,
               "encode": {"hips": eh, "rotations": er,
                          "contacts": contacts10.iter().flat_map(|c| c.map(|b| if b { 1.0 } else { 0.0 })).collect::<Vec<f32>>(),
                          "features": enc.values}}),
    );
    let text = serde_json::to_string(&Value::Object(refs)).unwrap();
    std::fs::write(data.join("reference.json"), text).unwrap();
}

#[test]
fn pytest_package() {
    let f = fixture();
    let out = Command::new(&f.python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(repo().join("runtime/python/tests"))
        .env("PYTHONPATH", &f.site)
        .env("ZOO_TEST_DATA", &f.data)
        .env("ZOO_TEST_WHEEL", &f.wheel)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .current_dir(&f.site)
        .output()
        .expect("running pytest");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    println!("{text}");
    assert!(out.status.success(), "pytest failed:\n{text}");
}

/// Blender's executable: `$BLENDER`, else `blender` on the PATH.
fn blender() -> Option<PathBuf> {
    if let Some(b) = std::env::var_os("BLENDER") {
        return Some(PathBuf::from(b));
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join("blender")).find(|p| p.is_file())
}

/// The add-on zip made by `apps/blender/make_addon.py` with the test's wheel inside (made once).
fn addon_zip() -> &'static Path {
    static Z: OnceLock<PathBuf> = OnceLock::new();
    Z.get_or_init(|| {
        let f = fixture();
        let zip = f.data.join("zoo_blender.zip");
        run(
            Command::new(&f.python)
                .arg(repo().join("apps/blender/make_addon.py"))
                .arg("--wheel")
                .arg(&f.wheel)
                .arg("--out")
                .arg(&zip),
            "making the add-on zip (apps/blender/make_addon.py)",
        );
        zip
    })
}

/// Blender 4.2 as a Python module (`bpy` from PyPI, CPython 3.11 only) in its own venv, made
/// on first use: the add-on installed as an extension, as Blender 4.2+ installs it.
fn bpy_venv() -> PathBuf {
    let dir = profile_dir().parent().expect("target dir").join("bpy-venv");
    let python = dir.join("bin/python");
    let ready = dir.join(".zoo-test-ready");
    if !ready.is_file() {
        let version = run(Command::new("python3").args(["-c", "import sys; print(sys.version_info[:2])"]), "python3");
        assert!(
            version.trim() == "(3, 11)",
            "Blender 4.2's bpy module needs CPython 3.11, python3 is {}: install python3.11",
            version.trim()
        );
        if !python.is_file() {
            run(Command::new("python3").args(["-m", "venv"]).arg(&dir), "making the bpy venv (python3 -m venv)");
        }
        run(
            Command::new(&python).args(["-m", "pip", "install", "-q", "bpy==4.2.0", "numpy"]),
            "installing Blender 4.2 as a module into the bpy venv (pip install bpy==4.2.0; needs PyPI, 350 MB)",
        );
        std::fs::write(&ready, "bpy==4.2.0 numpy\n").expect("venv marker");
    }
    python
}

/// With the real data beside the checkout: a bandai2 clip (its dummy root `joint_Root` kept in
/// the file Blender imports, dropped from the model's skeleton) and an RTN on its skeleton
/// (made once).
fn bandai2_inputs() -> &'static Option<(PathBuf, PathBuf)> {
    static B: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    B.get_or_init(|| {
        let f = fixture();
        zoo_tests::bandai2().map(|dir| {
            let src = dir.join("dataset-2_walk_normal_001.bvh.gz");
            let opts = zoo_data::bvh::ReadOptions { drop_dummy_root: false };
            let file = zoo_data::bvh::read_file(&src, &opts).expect("the bandai2 clip").slice(0, 150);
            let bvh = f.data.join("bandai2_walk.bvh");
            zoo_data::bvh::write_file(&file, &bvh).unwrap();
            let mut model_clip = file.clone();
            assert!(model_clip.drop_root(), "bandai2's clip has its dummy root");
            let model = f.data.join("transition_bandai2.onnx");
            std::fs::write(&model, zoo_tests::biped_rtn_onnx(&model_clip, false, None)).unwrap();
            (bvh, model)
        })
    })
}

/// Runs `apps/blender/tests/test_addon.py` with `cmd` (Blender, or Python with `bpy`) on the test's
/// models and clips, its user folders under `user`, and prints the figures it reports.
fn run_addon_test(cmd: Command, user: &str, report: &str) -> String {
    run_addon_test_with(cmd, user, report, &[])
}

/// [`run_addon_test`] with more arguments for the script; returns its report (JSON).
fn run_addon_test_with(mut cmd: Command, user: &str, report: &str, more: &[&std::ffi::OsStr]) -> String {
    let f = fixture();
    let zip = addon_zip();
    let report = f.data.join(report);
    let bandai2 = bandai2_inputs();
    cmd.arg(repo().join("apps/blender/tests/test_addon.py"))
        .arg("--")
        .arg("--addon-zip")
        .arg(zip)
        .arg("--data")
        .arg(&f.data)
        .arg("--report")
        .arg(&report)
        .env("PYTHONNOUSERSITE", "1")
        .env("PYTHONDONTWRITEBYTECODE", "1")
        // The add-on installs into a temporary user folder, not the user's own.
        .env("BLENDER_USER_RESOURCES", f.data.join(user))
        .env("BLENDER_USER_SCRIPTS", f.data.join(user).join("scripts"))
        .env("BLENDER_USER_CONFIG", f.data.join(user).join("config"));
    if let Some((bvh, model)) = bandai2 {
        cmd.arg("--bandai2-clip").arg(bvh).arg("--bandai2-model").arg(model);
    }
    cmd.args(more);
    let out = cmd.output().expect("running Blender");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    let figures = std::fs::read_to_string(&report).unwrap_or_default();
    println!("{text}\nfigures: {figures}");
    assert!(out.status.success(), "the Blender tests failed ({}):\n{text}", out.status);
    assert!(!figures.is_empty(), "the Blender tests wrote no report:\n{text}");
    figures
}

#[test]
fn blender_addon() {
    let Some(blender) = blender() else {
        assert!(
            std::env::var("ZOO_REQUIRE_BLENDER").as_deref() != Ok("1"),
            "Blender is not installed (ZOO_REQUIRE_BLENDER=1): apt-get install -y blender"
        );
        println!(
            "blender_addon: Blender not found (set BLENDER or install it: apt-get install -y blender); nothing checked"
        );
        return;
    };
    let mut cmd = Command::new(&blender);
    // One thread: the speed figure is for one core.
    cmd.args(["-b", "--factory-startup", "-noaudio", "-t", "1", "--python-exit-code", "1", "--python"]);
    run_addon_test(cmd, "blender-user", "blender_report.json");
}

/// The add-on with a model trained on bandai2: a humanoid keyframe model (`ZOO_INB_ONNX`,
/// default `../runs/inb20.onnx`, exported by `zoo export --onnx ../runs/inb20 --out
/// ../runs/inb20.onnx`) in-betweens bandai2's walk on a Mixamo-named rig with another rest pose
/// and on zoo's skeleton, in Debian's Blender; keys every 4 frames with fitted handles on it.
/// The figures are in the test log (`--nocapture`) and docs/blender.md.
#[test]
#[ignore = "needs ../shared/data/bandai2 and a keyframe model trained on it (ZOO_INB_ONNX, default ../runs/inb20.onnx)"]
fn blender_addon_bandai2_model() {
    let model = std::env::var_os("ZOO_INB_ONNX").map_or_else(|| repo().join("../runs/inb20.onnx"), PathBuf::from);
    assert!(
        model.is_file(),
        "{} is missing: train a keyframe model on bandai2 (`zoo train arnn --design inbetween --data \
         ../shared/data/bandai2 --valid-glob '*_youthful_*' --time-limit 20 --out ../runs/inb20`) and export it (`zoo export --onnx ../runs/inb20 --out \
         ../runs/inb20.onnx`), or set ZOO_INB_ONNX",
        model.display()
    );
    assert!(bandai2_inputs().is_some(), "../shared/data/bandai2 is missing");
    let blender = blender().expect("Blender is not installed: apt-get install -y blender");
    let mut cmd = Command::new(&blender);
    cmd.args(["-b", "--factory-startup", "-noaudio", "-t", "1", "--python-exit-code", "1", "--python"]);
    let report = run_addon_test_with(
        cmd,
        "blender-user-bandai2",
        "blender_bandai2_report.json",
        &["--bandai2-keyframes-model".as_ref(), model.as_os_str()],
    );
    let report: Value = serde_json::from_str(&report).expect("the report is JSON");
    assert!(report["bandai2_model"].is_object(), "the bandai2 model's test did not run: {report}");
}

/// The add-on as a Blender 4.2+ extension (`blender_manifest.toml`, the wheel installed by
/// Blender), in Blender 4.2 as a Python module.
#[test]
fn blender_extension() {
    let mut cmd = Command::new(bpy_venv());
    cmd.env("OMP_NUM_THREADS", "1");
    run_addon_test(cmd, "blender42-user", "blender42_report.json");
}
