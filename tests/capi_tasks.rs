//! One model file format and one runtime for every task, through the C ABI (`runtime/capi`):
//! `zoo_model_load` loads a tiny exported model of each kind (RTN, ARNN, RMR, RNN-GMM with and
//! without its refiner), `zoo_model_task` says its task, its task's functions run it as the Rust
//! API does, and every other task's functions refuse it with `ZOO_STATUS_WRONG_MODEL` and a
//! message naming the functions that run it (`every_task_loads_runs_and_is_refused_by_the_other_families`,
//! the acceptance test of issue 40). Then the tasks besides transitions (`tests/capi.rs`) in
//! detail: keyframe completion (`zoo_keyframes_*`), stitching (`zoo_stitch_*`: the whole sequence
//! and the stream), synthesis (`zoo_synthesis_*`) and its controller (`zoo_control_*`).
//!
//! Where the expected numbers come from: the Rust runtime API (`zoo_runtime::LoadedModel` and
//! each task's type) run on the same tiny exported models (`zoo_tests::tiny_*`) and the same
//! inputs. Through the C ABI in this process the outputs must be bit-identical (the same code
//! runs underneath); the C example `examples/tasks.c`, compiled with the system C compiler as
//! C99 and with the system C++ compiler as C++17, prints 9 significant digits and must agree
//! within 1e-5 (relative above 1). Every malformed call (NULL handle or buffer, wrong size, NaN,
//! garbage file, a model of another task, call out of order) returns its status and a message
//! that starts with the C function's name and names the problem in C terms.
// Calling the C ABI from Rust needs raw pointers, as a C caller has.
#![allow(unsafe_code)]

mod capi_examples;

use std::ffi::c_char;
use std::path::{Path, PathBuf};
use std::ptr::{null, null_mut};
use std::sync::OnceLock;
use zoo_capi::*;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
use zoo_runtime::metadata::MotionTaskKind;
use zoo_runtime::stitch::{FootCleanup, STREAM_CHUNK, STREAM_LOOKAHEAD, StitchStream};
use zoo_runtime::synthesis::SynthesisModel;
use zoo_runtime::{EnginePose, LoadedModel, StitchRefiner, TransitionModel};
use zoo_tests::capi::{assert_error, assert_ok, c_path, last_error, pose_values};

/// The model files of these tests, written once per run.
struct Files {
    rtn: PathBuf,
    arnn: PathBuf,
    /// The in-betweening design of the keyframes task ([`zoo_tests::tiny_inbetween_onnx`]).
    inbetween: PathBuf,
    rmr: PathBuf,
    rnngmm: PathBuf,
    /// An RNN-GMM exported from a refiner-stage run (3 refiner updates): the file embeds the
    /// refiner's step graph.
    rnngmm_refined: PathBuf,
    toy: PathBuf,
    garbage: PathBuf,
}

/// A tiny RNN-GMM generator ([`zoo_tests::rnngmm_fixture`]) with its adversarial refiner
/// trained for 3 updates, exported from the refiner-stage run folder as `zoo export --onnx`
/// does (as `tests/parity_rnngmm.rs` builds it).
fn tiny_rnngmm_refined_onnx(dir: &Path) -> zoo_export::OnnxModel {
    use zoo_rnngmm::prelude::*;
    let (config, data, trainer) = zoo_tests::rnngmm_fixture(Config::tiny());
    let gen_dir = dir.join("generator");
    trainer.save(&gen_dir).unwrap();
    let device = candle_core::Device::Cpu;
    let mut adv = AdversarialTrainer::new(&gen_dir, &config.refiner, &data.train, &data.valid, &device).unwrap();
    for _ in 0..3 {
        adv.refiner_update().unwrap();
    }
    let run = dir.join("refined");
    adv.save(&run).unwrap();
    zoo_rnngmm::export::export_run(&run, &Default::default()).unwrap()
}

fn files() -> &'static Files {
    static FILES: OnceLock<Files> = OnceLock::new();
    FILES.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("capi_tasks");
        std::fs::create_dir_all(&dir).unwrap();
        let write = |name: &str, model: zoo_export::OnnxModel| {
            let path = dir.join(name);
            model.write(&path).unwrap();
            path
        };
        let toy = zoo_tests::toy_onnx::ToyModel::new(zoo_tests::toy_onnx::Cell::Lstm, 6, 8, 5).cell_graph();
        let garbage = dir.join("notes.onnx");
        std::fs::write(&garbage, "not a model").unwrap();
        Files {
            rtn: write("rtn.onnx", zoo_tests::tiny_rtn_onnx()),
            arnn: write("arnn.onnx", zoo_tests::tiny_arnn_onnx()),
            inbetween: write("inbetween.onnx", zoo_tests::tiny_inbetween_onnx()),
            rmr: write("rmr.onnx", zoo_tests::tiny_rmr_onnx()),
            rnngmm: write("rnngmm.onnx", zoo_tests::tiny_rnngmm_onnx()),
            rnngmm_refined: write("rnngmm_refined.onnx", tiny_rnngmm_refined_onnx(&dir)),
            toy: write("toy.onnx", toy),
            garbage,
        }
    })
}

/// Loads `path` through the C ABI.
fn load(path: &Path) -> *mut ZooModel {
    let mut model = null_mut();
    assert_ok(unsafe { zoo_model_load(c_path(path).as_ptr(), &mut model) });
    assert!(!model.is_null());
    model
}

/// A model loaded through the C ABI, freed on drop.
struct Model(*mut ZooModel);

impl Model {
    fn load(path: &Path) -> Self {
        Model(load(path))
    }
}

impl Drop for Model {
    fn drop(&mut self) {
        unsafe { zoo_model_free(self.0) };
    }
}

/// `zoo_model_load`'s status on `path` (the handle, made exactly on success, freed at once).
fn load_status(path: *const c_char) -> ZooStatus {
    let mut handle = null_mut();
    let status = unsafe { zoo_model_load(path, &mut handle) };
    assert_eq!(status == ZooStatus::Ok, !handle.is_null(), "a handle exactly on success");
    unsafe { zoo_model_free(handle) };
    status
}

#[test]
fn the_one_loader_refuses_garbage_bare_graphs_and_bad_paths() {
    let f = files();
    let missing = f.garbage.with_file_name("missing.onnx");
    assert_error(
        load_status(c_path(&missing).as_ptr()),
        ZooStatus::LoadFailed,
        "zoo_model_load: cannot read model file",
    );
    assert_error(load_status(c_path(&missing).as_ptr()), ZooStatus::LoadFailed, "missing.onnx");
    assert_error(load_status(c_path(&f.garbage).as_ptr()), ZooStatus::LoadFailed, "not an ONNX model");
    let status = load_status(c_path(&f.toy).as_ptr());
    assert_error(status, ZooStatus::LoadFailed, "(kind `toy_lstm`) is a bare step graph with no task");
    assert_error(status, ZooStatus::LoadFailed, "zoo export --onnx RUN_DIR");
    assert!(!last_error().contains("::"), "{}", last_error());
    assert_error(load_status(null()), ZooStatus::NullPointer, "`path` is NULL");
    let bad_utf8 = [0xffu8, 0xfe, 0];
    assert_error(load_status(bad_utf8.as_ptr().cast::<c_char>()), ZooStatus::InvalidArgument, "UTF-8");
    let mut model = null_mut::<ZooModel>();
    let status = unsafe { zoo_model_load(c_path(&f.rtn).as_ptr(), null_mut()) };
    assert_error(status, ZooStatus::NullPointer, "zoo_model_load: `out` is NULL");
    assert_eq!(unsafe { zoo_model_load(null(), &mut model) }, ZooStatus::NullPointer);
    assert!(model.is_null());
}

/// A file of a format version older than this release's is refused with the command that
/// re-exports it.
#[test]
fn the_one_loader_refuses_an_older_format_with_the_fix() {
    let f = files();
    let mut onnx = zoo_export::OnnxModel::from_bytes(&std::fs::read(&f.rtn).unwrap(), "rtn.onnx").unwrap();
    onnx.set_metadata(zoo_runtime::metadata::keys::FORMAT_VERSION, "3");
    let path = f.garbage.with_file_name("rtn_v3.onnx");
    onnx.write(&path).unwrap();
    let status = load_status(c_path(&path).as_ptr());
    assert_error(status, ZooStatus::LoadFailed, "format version 3");
    assert_error(status, ZooStatus::LoadFailed, "zoo export --onnx RUN_DIR");
}

// One runtime for every task.

/// A C function that takes a model handle: its name, its family and the task the family takes,
/// and a call of it on a model with plausible arguments (what it makes is freed).
struct Call {
    function: &'static str,
    family: &'static str,
    task: MotionTaskKind,
    call: fn(*mut ZooModel) -> ZooStatus,
}

/// Every function of the C ABI that takes a model handle, but those of every task
/// (`zoo_model_*`).
fn model_calls() -> Vec<Call> {
    use MotionTaskKind::{Keyframes, Stitch, Synthesis, Transition};
    let call = |function, family, task, call| Call { function, family, task, call };
    vec![
        call("zoo_transition_info", "zoo_transition_*", Transition, |m| unsafe {
            zoo_transition_info(m, &mut ZooTransitionInfo::default())
        }),
        call("zoo_transition_terrain", "zoo_transition_*", Transition, |m| unsafe {
            let (mut side, mut extent) = (0usize, 0.0f32);
            zoo_transition_terrain(m, &mut side, &mut extent)
        }),
        call("zoo_transition_runner_new", "zoo_transition_*", Transition, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_transition_runner_new(m, 1, &mut out);
            zoo_transition_runner_free(out);
            status
        }),
        call("zoo_transition_characters_new", "zoo_transition_*", Transition, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_transition_characters_new(m, 2, &mut out);
            zoo_transition_characters_free(out);
            status
        }),
        call("zoo_keyframes_info", "zoo_keyframes_*", Keyframes, |m| unsafe {
            zoo_keyframes_info(m, &mut ZooKeyframesInfo::default())
        }),
        call("zoo_keyframes_runner_new", "zoo_keyframes_*", Keyframes, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_keyframes_runner_new(m, 2, &mut out);
            zoo_keyframes_runner_free(out);
            status
        }),
        call("zoo_stitch_info", "zoo_stitch_*", Stitch, |m| unsafe {
            zoo_stitch_info(m, &mut ZooStitchInfo::default())
        }),
        call("zoo_stitch_set_window", "zoo_stitch_*", Stitch, |m| unsafe { zoo_stitch_set_window(m, 30, 15) }),
        call("zoo_stitch_pre_blend", "zoo_stitch_*", Stitch, |m| unsafe { zoo_stitch_pre_blend(m, &mut false) }),
        call("zoo_stitch_set_seam_guard", "zoo_stitch_*", Stitch, |m| unsafe { zoo_stitch_set_seam_guard(m, true) }),
        call("zoo_stitch_set_seam_reach", "zoo_stitch_*", Stitch, |m| unsafe { zoo_stitch_set_seam_reach(m, 30) }),
        call("zoo_stitch_seam_reach", "zoo_stitch_*", Stitch, |m| unsafe { zoo_stitch_seam_reach(m, &mut 0) }),
        call("zoo_stitch_refine", "zoo_stitch_*", Stitch, |m| unsafe {
            let roots = [ZooRootMotion::default(); 2];
            let rotations = [0.0f32; 8];
            let (mut out_roots, mut out_rotations, mut contacts) =
                ([ZooRootMotion::default(); 2], [0.0f32; 8], [0u8; 8]);
            zoo_stitch_refine(
                m,
                roots.as_ptr(),
                2,
                rotations.as_ptr(),
                8,
                true,
                true,
                out_roots.as_mut_ptr(),
                2,
                out_rotations.as_mut_ptr(),
                8,
                contacts.as_mut_ptr(),
                8,
            )
        }),
        call("zoo_stitch_stream_new", "zoo_stitch_*", Stitch, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_stitch_stream_new(m, &mut out);
            zoo_stitch_stream_free(out);
            status
        }),
        call("zoo_synthesis_info", "zoo_synthesis_*", Synthesis, |m| unsafe {
            zoo_synthesis_info(m, &mut ZooSynthesisInfo::default())
        }),
        call("zoo_synthesis_set_refine", "zoo_synthesis_*", Synthesis, |m| unsafe {
            zoo_synthesis_set_refine(m, true)
        }),
        call("zoo_synthesis_mean_frame", "zoo_synthesis_*", Synthesis, |m| unsafe {
            let mut frame = [0.0f32; 4];
            zoo_synthesis_mean_frame(m, frame.as_mut_ptr(), frame.len())
        }),
        call("zoo_synthesis_runner_new", "zoo_synthesis_*", Synthesis, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_synthesis_runner_new(m, 2, &mut out);
            zoo_synthesis_runner_free(out);
            status
        }),
        call("zoo_synthesis_characters_new", "zoo_synthesis_*", Synthesis, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_synthesis_characters_new(m, SEEDS.as_ptr(), 2, &mut out);
            zoo_synthesis_characters_free(out);
            status
        }),
        call("zoo_control_runner_new", "zoo_control_*", Synthesis, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_control_runner_new(m, 1, &mut out);
            zoo_control_runner_free(out);
            status
        }),
        call("zoo_control_characters_new", "zoo_control_*", Synthesis, |m| unsafe {
            let mut out = null_mut();
            let status = zoo_control_characters_new(m, SEEDS.as_ptr(), 2, null(), &mut out);
            zoo_control_characters_free(out);
            status
        }),
    ]
}

/// The C task of the runtime's.
fn c_task(task: MotionTaskKind) -> ZooTask {
    match task {
        MotionTaskKind::Transition => ZooTask::Transition,
        MotionTaskKind::Keyframes => ZooTask::Keyframes,
        MotionTaskKind::Stitch => ZooTask::Stitch,
        MotionTaskKind::Synthesis => ZooTask::Synthesis,
        other => panic!("no C task for {other}"),
    }
}

/// The functions that run a model of `task`, as the C ABI's messages name them.
fn functions_of(task: MotionTaskKind) -> &'static str {
    match task {
        MotionTaskKind::Transition => "zoo_transition_*",
        MotionTaskKind::Keyframes => "zoo_keyframes_*",
        MotionTaskKind::Stitch => "zoo_stitch_*",
        MotionTaskKind::Synthesis => "zoo_synthesis_* (and zoo_control_*)",
        other => panic!("no C functions for {other}"),
    }
}

/// A transition of the tiny RTN from positions through the C ABI, frame by frame, against the
/// Rust API's.
unsafe fn run_transition(model: *mut ZooModel, rust: &TransitionModel) {
    let (mut info, mut common) = (ZooTransitionInfo::default(), ZooModelInfo::default());
    unsafe {
        assert_ok(zoo_transition_info(model, &mut info));
        assert_ok(zoo_model_info(model, &mut common));
    }
    let (d, n, length) = (3 * common.joints, 2usize, info.transition_frames);
    let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| ((i * 7 + f * 3) as f32).sin() * 20.0).collect() };
    let past: Vec<f32> = (0..n).flat_map(|c| (0..info.past_frames).flat_map(move |f| pose(f + c))).collect();
    let target: Vec<f32> = (0..n).flat_map(|c| pose(40 + c)).collect();
    let next: Vec<f32> = (0..n).flat_map(|c| pose(41 + c)).collect();
    let mut runner = rust.runner().unwrap();
    let mut states: Vec<_> = (0..n).map(|_| rust.new_transition()).collect();
    runner.start_batch_for(&mut states, &past, &target, &next, length).unwrap();
    let (mut c_runner, mut chars) = (null_mut(), null_mut());
    unsafe {
        assert_ok(zoo_transition_runner_new(model, 64, &mut c_runner));
        assert_ok(zoo_transition_characters_new(model, n, &mut chars));
        assert_ok(zoo_transition_start(
            c_runner,
            chars,
            past.as_ptr(),
            past.len(),
            target.as_ptr(),
            target.len(),
            next.as_ptr(),
            next.len(),
            length,
        ));
    }
    let (mut got, mut want) = (vec![0.0f32; n * d], vec![0.0f32; n * d]);
    for f in 0..=length {
        unsafe { assert_ok(zoo_transition_step(c_runner, chars, got.as_mut_ptr(), got.len())) };
        runner.step_batch(&mut states, &mut want).unwrap();
        assert!(got == want, "transition frame {f}: the C ABI differs from the Rust API");
    }
    unsafe {
        zoo_transition_characters_free(chars);
        zoo_transition_runner_free(c_runner);
    }
}

/// The example keys of character 1 completed through the C ABI against the Rust API.
unsafe fn run_keyframes(model: *mut ZooModel, rust: &KeyframeModel) {
    let d = rust.dofs();
    let expected = rust_completion(rust);
    let (_, frames, poses) = example_keys(d);
    let runner = keyframe_runner(model, 1);
    let mut out = vec![f32::NAN; 31 * d];
    unsafe {
        let status = zoo_keyframes_complete(
            runner,
            frames[4..].as_ptr(),
            3,
            poses[4 * d..].as_ptr(),
            3 * d,
            null(),
            0,
            out.as_mut_ptr(),
            out.len(),
        );
        assert_ok(status);
        zoo_keyframes_runner_free(runner);
    }
    let worst = out.iter().zip(&expected[40 * d..]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst <= 1e-5, "keyframes: the C ABI's completion differs from the Rust API's by {worst:e}");
}

/// The example walk refined through the C ABI against the Rust API.
unsafe fn run_stitch(model: *mut ZooModel, rust: &StitchRefiner) {
    let poses = example_walk(rust);
    let (roots, rotations) = as_roots(&poses);
    let mut out = Refined::new(poses.len(), rust.joints());
    unsafe { assert_ok(out.refine(model, &roots, &rotations, FootCleanup::default())) };
    let want = rust_refine(rust, &poses, FootCleanup::default());
    assert!(out.frames(rust.joints()) == want, "stitch: the C ABI differs from the Rust API");
}

/// Synthesis and control of the example's characters through the C ABI against the Rust API.
unsafe fn run_synthesis(model: *mut ZooModel, rust: &SynthesisModel) {
    let (n, k, frames) = (SEEDS.len(), rust.joints(), 10);
    let start = example_start(rust, n);
    let (mut runner, mut chars, mut crunner, mut cchars) = (null_mut(), null_mut(), null_mut(), null_mut());
    let mut step = Step::new(n, k);
    unsafe {
        assert_ok(zoo_synthesis_runner_new(model, n, &mut runner));
        assert_ok(zoo_synthesis_characters_new(model, SEEDS.as_ptr(), n, &mut chars));
        assert_ok(zoo_synthesis_start(chars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        for (t, want) in rust_synthesis(rust, n, frames).iter().enumerate() {
            assert_ok(step.synthesis(runner, chars, 1.0));
            assert!(step.frame() == *want, "synthesis frame {t}: the C ABI differs from the Rust API");
        }
        assert_ok(zoo_control_runner_new(model, 64, &mut crunner));
        assert_ok(zoo_control_characters_new(model, SEEDS.as_ptr(), n, null(), &mut cchars));
        assert_ok(zoo_control_start(cchars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        for (t, want) in rust_control(rust, n, frames).iter().enumerate() {
            let z = example_control(t, frames);
            assert_ok(step.control(crunner, cchars, &[z; 3]));
            assert!(step.frame() == *want, "control frame {t}: the C ABI differs from the Rust API");
        }
        zoo_control_characters_free(cchars);
        zoo_control_runner_free(crunner);
        zoo_synthesis_characters_free(chars);
        zoo_synthesis_runner_free(runner);
    }
}

/// Issue 40's acceptance test of the one loader and the symmetric C ABI: a tiny exported model
/// of each kind (RTN, ARNN, RMR, RNN-GMM with and without its refiner) loads through
/// `LoadedModel` and through `zoo_model_load`, whose `zoo_model_task` and `zoo_model_info` say
/// its task; its task's functions run it as the Rust API does (bit for bit; keyframes within
/// 1e-5); and every function of every other task refuses it with `ZOO_STATUS_WRONG_MODEL` and
/// the message `FUNCTION: the model is a `TASK` model (kind `KIND`); FAMILY_* functions take
/// `OTHER` models; use OWN_* with this model`, as the Rust API's typed loaders refuse it.
#[test]
fn every_task_loads_runs_and_is_refused_by_the_other_families() {
    let f = files();
    let cases = [
        (&f.rtn, "rtn", MotionTaskKind::Transition),
        (&f.arnn, "arnn", MotionTaskKind::Keyframes),
        (&f.rmr, "rmr", MotionTaskKind::Stitch),
        (&f.rnngmm, "rnn-gmm", MotionTaskKind::Synthesis),
        (&f.rnngmm_refined, "rnn-gmm", MotionTaskKind::Synthesis),
    ];
    let calls = model_calls();
    let mut refusals = 0;
    for (path, kind, task) in cases {
        // The Rust API: one loader, the task's type, the other types refused.
        let rust = LoadedModel::load(path).unwrap();
        assert_eq!((rust.task(), rust.kind()), (task, kind), "{}", path.display());
        let wrong = |r: Result<(), zoo_runtime::MotionError>| {
            matches!(r, Err(zoo_runtime::MotionError::WrongTask { .. })) as usize
        };
        let refused = wrong(rust.clone().into_transition().map(drop))
            + wrong(rust.clone().into_keyframes().map(drop))
            + wrong(rust.clone().into_stitch().map(drop))
            + wrong(rust.clone().into_synthesis().map(drop));
        assert_eq!(refused, 3, "{kind}: the other three typed loaders refuse it");

        // The C ABI: the same file, the same task.
        let model = Model::load(path);
        assert_eq!(unsafe { zoo_model_task(model.0) }, c_task(task), "{kind}");
        let mut info = ZooModelInfo::default();
        unsafe { assert_ok(zoo_model_info(model.0, &mut info)) };
        let meta = rust.metadata();
        assert_eq!(info.task, c_task(task));
        assert_eq!((info.joints, info.fps, info.format_version), (meta.skeleton.len(), meta.fps, meta.format_version));
        assert_eq!((info.metres_per_unit, info.up_axis, info.handedness), (0.01, ZooUpAxis::Y, ZooHandedness::Right));

        // Its task runs as the Rust API runs it.
        unsafe {
            match &rust {
                LoadedModel::Transition(t) => run_transition(model.0, t),
                LoadedModel::Keyframes(k) => run_keyframes(model.0, k),
                LoadedModel::Stitch(s) => run_stitch(model.0, s),
                LoadedModel::Synthesis(s) => run_synthesis(model.0, s),
                _ => unreachable!("every task is listed"),
            }
        }

        // Every other family refuses it, naming the functions that run it; its own family does
        // not refuse it as a model of another task.
        for c in &calls {
            let status = (c.call)(model.0);
            if c.task == task {
                assert_ne!(status, ZooStatus::WrongModel, "{}: {}", c.function, last_error());
                continue;
            }
            let want = format!(
                "{}: the model is a `{task}` model (kind `{kind}`); {} functions take `{}` models; use {} with this model",
                c.function,
                c.family,
                c.task,
                functions_of(task)
            );
            assert_eq!(status, ZooStatus::WrongModel, "{} on a {kind} model: {}", c.function, last_error());
            assert_eq!(last_error(), want);
            refusals += 1;
        }
    }
    // 21 functions: 4 transition, 2 keyframes, 8 stitch, 5 synthesis, 2 control.
    assert_eq!(calls.len(), 21);
    assert_eq!(refusals, 17 + 19 + 13 + 2 * 14, "every other family's functions were called on every model");
}

/// `zoo_synthesis_set_refine` on a file with a refiner: runners and characters made after
/// `false` step the generator's own frames (the Rust API's `without_refiner`), which the
/// refiner changes; those made on the two sides of the call do not mix; `true` brings the
/// refiner back.
#[test]
fn synthesis_refines_unless_set_refine_turns_it_off() {
    let rust = LoadedModel::load(&files().rnngmm_refined).unwrap().into_synthesis().unwrap();
    assert!(rust.has_refiner());
    let (n, k, frames) = (SEEDS.len(), rust.joints(), 5);
    let refined = rust_synthesis(&rust, n, frames);
    let raw = rust_synthesis(&rust.clone().without_refiner(), n, frames);
    assert!(refined != raw, "the trained refiner changes the frames");
    let start = example_start(&rust, n);
    let model = Model::load(&files().rnngmm_refined);
    let m = model.0;
    unsafe {
        let mut info = ZooSynthesisInfo::default();
        assert_ok(zoo_synthesis_info(m, &mut info));
        assert!(info.has_refiner);
        let (mut refining_runner, mut raw_runner, mut chars) = (null_mut(), null_mut(), null_mut());
        assert_ok(zoo_synthesis_runner_new(m, n, &mut refining_runner));
        assert_ok(zoo_synthesis_set_refine(m, false));
        assert_ok(zoo_synthesis_info(m, &mut info));
        assert!(!info.has_refiner);
        assert_ok(zoo_synthesis_runner_new(m, n, &mut raw_runner));
        assert_ok(zoo_synthesis_characters_new(m, SEEDS.as_ptr(), n, &mut chars));
        assert_ok(zoo_synthesis_start(chars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        let mut step = Step::new(n, k);
        let status = step.synthesis(refining_runner, chars, 1.0);
        assert_error(status, ZooStatus::InvalidArgument, "zoo_synthesis_set_refine");
        for (t, want) in raw.iter().enumerate() {
            assert_ok(step.synthesis(raw_runner, chars, 1.0));
            assert!(step.frame() == *want, "frame {t}: without the refiner, the C ABI differs from the Rust API");
        }
        assert_ok(zoo_synthesis_set_refine(m, true));
        assert_ok(zoo_synthesis_info(m, &mut info));
        assert!(info.has_refiner);
        zoo_synthesis_characters_free(chars);
        zoo_synthesis_runner_free(raw_runner);
        zoo_synthesis_runner_free(refining_runner);
    }
}

// Allocations per frame.

/// Counts the allocations of each thread (tests run in parallel threads of this binary).
struct Counting;

thread_local! {
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn count_one() {
    let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
}

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl std::alloc::GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_one();
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: std::alloc::Layout) -> *mut u8 {
        count_one();
        unsafe { std::alloc::System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: std::alloc::Layout, new_size: usize) -> *mut u8 {
        count_one();
        unsafe { std::alloc::System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The allocations of the calling thread while `f` runs.
fn allocations(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.with(|a| a.get());
    f();
    ALLOCATIONS.with(|a| a.get()) - before
}

/// Every per-frame call of the C ABI (a transition step from positions and as engine poses, a
/// synthesis step, a control step, a stitching stream's push and pop) allocates no more than
/// the Rust API's call underneath: the C layer adds no allocation per frame (what remains is
/// the runtime's, which `tests/runtime_alloc.rs` bounds). Counted after a warm-up transition /
/// a few warm-up frames, over the same frames through both.
#[test]
fn per_frame_calls_allocate_no_more_than_the_rust_api() {
    let f = files();
    let mut report = Vec::new();
    unsafe {
        // Transitions: two whole transitions, the second one counted.
        let rust = LoadedModel::load(&f.rtn).unwrap().into_transition().unwrap();
        let model = Model::load(&f.rtn);
        let (k, n, length) = (rust.joints(), 2usize, rust.transition_frames());
        let d = 3 * k;
        let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| ((i * 7 + f * 3) as f32).sin() * 20.0).collect() };
        let past: Vec<f32> = (0..n).flat_map(|_| (0..rust.past_frames()).flat_map(pose)).collect();
        let (target, next): (Vec<f32>, Vec<f32>) = ([pose(40), pose(40)].concat(), [pose(41), pose(41)].concat());
        let (mut runner, mut chars) = (null_mut(), null_mut());
        assert_ok(zoo_transition_runner_new(model.0, 64, &mut runner));
        assert_ok(zoo_transition_characters_new(model.0, n, &mut chars));
        let mut rust_runner = rust.runner().unwrap();
        let mut states: Vec<_> = (0..n).map(|_| rust.new_transition()).collect();
        let mut frame = vec![0.0f32; n * d];
        let (mut c_count, mut rust_count) = (0, 0);
        for pass in 0..2 {
            let start = |chars| {
                let (p, t, x) = (past.as_ptr(), target.as_ptr(), next.as_ptr());
                zoo_transition_start(runner, chars, p, past.len(), t, target.len(), x, next.len(), length)
            };
            assert_ok(start(chars));
            rust_runner.start_batch_for(&mut states, &past, &target, &next, length).unwrap();
            let c = allocations(|| {
                for _ in 0..=length {
                    assert_ok(zoo_transition_step(runner, chars, frame.as_mut_ptr(), frame.len()));
                }
            });
            let r = allocations(|| {
                for _ in 0..=length {
                    rust_runner.step_batch(&mut states, &mut frame).unwrap();
                }
            });
            if pass == 1 {
                (c_count, rust_count) = (c, r);
            }
        }
        report.push(("zoo_transition_step", c_count, rust_count));

        // The same transitions as engine poses.
        let identity: Vec<f32> = (0..n * rust.past_frames() * k).flat_map(|_| [0.0, 0.0, 0.0, 1.0]).collect();
        let roots = vec![
            ZooRootMotion {
                root_rotation: [0.0, 0.0, 0.0, 1.0],
                hips_position: [0.0, 90.0, 0.0],
                ..Default::default()
            };
            n * rust.past_frames()
        ];
        let rust_past: Vec<EnginePose> = (0..roots.len())
            .map(|_| {
                let mut p = EnginePose::new(k);
                p.hips_position = Vec3::new(0.0, 90.0, 0.0);
                p
            })
            .collect();
        let (mut out_roots, mut out_rotations) = (vec![ZooRootMotion::default(); n], vec![0.0f32; n * 4 * k]);
        let mut rust_poses = vec![EnginePose::new(k); n];
        for pass in 0..2 {
            let status = zoo_transition_start_posed(
                runner,
                chars,
                roots.as_ptr(),
                roots.len(),
                identity.as_ptr(),
                identity.len(),
                roots.as_ptr(),
                n,
                identity.as_ptr(),
                n * 4 * k,
                roots.as_ptr(),
                n,
                identity.as_ptr(),
                n * 4 * k,
                length,
            );
            assert_ok(status);
            let (target, next) = (&rust_past[..n], &rust_past[..n]);
            rust_runner.start_posed_batch_for(&mut states, &rust_past, target, next, length).unwrap();
            let c = allocations(|| {
                for _ in 0..=length {
                    let (r, q) = (out_roots.as_mut_ptr(), out_rotations.as_mut_ptr());
                    assert_ok(zoo_transition_step_posed(runner, chars, r, n, q, n * 4 * k));
                }
            });
            let r = allocations(|| {
                for _ in 0..=length {
                    rust_runner.step_posed_batch(&mut states, &mut rust_poses).unwrap();
                }
            });
            if pass == 1 {
                report.push(("zoo_transition_step_posed", c, r));
            }
        }
        zoo_transition_characters_free(chars);
        zoo_transition_runner_free(runner);

        // Synthesis and control: 3 warm-up frames, 10 counted.
        let rust = LoadedModel::load(&f.rnngmm).unwrap().into_synthesis().unwrap();
        let h = Handles::new(true);
        let (n, start) = (SEEDS.len(), &h.start);
        assert_ok(zoo_control_start(h.cchars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        let d = rust.frame_dim();
        let mut rust_runner = rust.runner(n).unwrap();
        let mut rust_chars: Vec<_> = SEEDS.iter().map(|&s| rust.new_character(s)).collect();
        let mut controlled: Vec<_> =
            SEEDS.iter().map(|&s| ControlledCharacter::new(&rust, s, ControlSettings::default()).unwrap()).collect();
        for (c, (ch, cc)) in rust_chars.iter_mut().zip(&mut controlled).enumerate() {
            let p = &start.1[3 * c..3 * c + 3];
            ch.start(&rust, &start.0[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
            cc.start(&rust, &start.0[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
        }
        let mut control_runner = ControlRunner::new(&rust).unwrap();
        let (mut poses, mut contacts) = (vec![EnginePose::new(rust.joints()); n], vec![[false; 2]; n]);
        let mut pose = EnginePose::new(rust.joints());
        let mut step = h.step();
        let controls = [example_control(0, 10); 3];
        let mut counted = |name, mut c_frame: Box<dyn FnMut() + '_>, mut rust_frame: Box<dyn FnMut() + '_>| {
            for _ in 0..3 {
                c_frame();
                rust_frame();
            }
            let c = allocations(|| (0..10).for_each(|_| c_frame()));
            let r = allocations(|| (0..10).for_each(|_| rust_frame()));
            report.push((name, c, r));
        };
        let step_ptr: *mut Step = &mut step;
        counted(
            "zoo_synthesis_step",
            Box::new(|| assert_ok((*step_ptr).synthesis(h.runner, h.chars, 1.0))),
            Box::new(|| rust_runner.step_batch(&mut rust_chars, 1.0, &mut poses, &mut contacts).unwrap()),
        );
        counted(
            "zoo_control_step",
            Box::new(|| assert_ok((*step_ptr).control(h.crunner, h.cchars, &controls))),
            Box::new(|| {
                let z = Control::new(controls[0].speed, controls[0].heading);
                for ch in &mut controlled {
                    control_runner.step(ch, z, &mut pose).unwrap();
                }
            }),
        );

        // A stitching stream: push a frame and pop what is ready, over the example walk after
        // its first window (the stream runs a window every `stride` frames in both).
        let refiner = std::sync::Arc::new(LoadedModel::load(&f.rmr).unwrap().into_stitch().unwrap());
        let walk = example_walk(&refiner);
        let (roots, rotations) = as_roots(&walk);
        let k = refiner.joints();
        let model = Model::load(&f.rmr);
        // Safety: the other tests of this binary read no environment variable of zoo's but this
        // one, whose only effect is when a window's nodes run.
        std::env::set_var("ZOO_STREAM_AHEAD", "0");
        let stream = stitch_stream(model.0);
        let mut rust_stream = refiner.clone().shared_stream();
        let mut pop = Pop::new(k, 0);
        let mut out = EnginePose::new(k);
        let warm = refiner.window() + 1;
        // One frame each: push it, then pop what is ready.
        let c_push = |f: usize, pop: &mut Pop| {
            assert_ok(zoo_stitch_stream_push(stream, &roots[f], rotations[f * 4 * k..].as_ptr(), 4 * k));
            let mut ready = false;
            assert_ok(zoo_stitch_stream_ready(stream, &mut ready));
            if ready {
                assert_ok(pop.pop_with(stream, 4 * k, 4));
            }
        };
        (0..warm).for_each(|f| c_push(f, &mut pop));
        for f in 0..warm {
            rust_stream.push(&walk[f]).unwrap();
            rust_stream.pop(&mut out).unwrap();
        }
        // Counted to the end of the motion (the finish and every pose left). A push runs its
        // window ahead of schedule while it has time, which would put two streams a few nodes
        // apart: here the schedule alone (`ZOO_STREAM_AHEAD=0`, read when a stream is made), the
        // same nodes in the same pushes in both.
        let c = allocations(|| {
            (warm..walk.len()).for_each(|f| c_push(f, &mut pop));
            assert_ok(zoo_stitch_stream_finish(stream));
            let mut ready = true;
            while ready {
                assert_ok(zoo_stitch_stream_ready(stream, &mut ready));
                if ready {
                    assert_ok(pop.pop_with(stream, 4 * k, 4));
                }
            }
        });
        let r = allocations(|| {
            for f in warm..walk.len() {
                rust_stream.push(&walk[f]).unwrap();
                rust_stream.pop(&mut out).unwrap();
            }
            rust_stream.finish().unwrap();
            while rust_stream.pop(&mut out).unwrap().is_some() {}
        });
        report.push(("zoo_stitch_stream_push + pop", c, r));
        zoo_stitch_stream_free(stream);
    }
    eprintln!("allocations (C ABI, Rust API) over the counted frames: {report:?}");
    for (name, c, rust) in report {
        // The two streams' schedules come from each loaded model's own measurement of its
        // window's nodes, so when counting starts one may have run a node or two more of the
        // window in progress (two tensors each, seen under an emulated CPU); an allocation per
        // frame would be hundreds more.
        let slack = if name.starts_with("zoo_stitch_stream") { 8 } else { 0 };
        assert!(c <= rust + slack, "{name}: the C ABI allocates {c} times where the Rust API allocates {rust}");
    }
}

/// The same values of a pose from the C ABI.
fn root_values(r: &ZooRootMotion, rotations: &[f32]) -> Vec<f32> {
    let mut v = Vec::new();
    v.extend(r.root_position);
    v.extend(r.root_rotation);
    v.extend(r.delta_position);
    v.push(r.delta_yaw);
    v.extend(r.hips_position);
    v.extend_from_slice(rotations);
    v
}

fn bytes(bits: &[bool]) -> Vec<u8> {
    bits.iter().map(|b| u8::from(*b)).collect()
}

// Keyframes.

/// The C example's keys: character 0 at frames 0, 9, 24, 39; character 1 at 0, 12, 30
/// (`key_value` in `examples/tasks.c`).
fn example_keys(d: usize) -> ([usize; 2], Vec<usize>, Vec<f32>) {
    let counts = [4, 3];
    let frames = vec![0, 9, 24, 39, 0, 12, 30];
    let mut poses = Vec::new();
    let mut at = 0;
    for (c, &n) in counts.iter().enumerate() {
        for k in 0..n {
            for j in 0..d {
                let v = 0.3 * (0.7 * k as f64 + 1.3 * j as f64 + 0.5 * c as f64).sin() + 0.01 * frames[at] as f64;
                poses.push(v as f32);
            }
            at += 1;
        }
    }
    (counts, frames, poses)
}

/// The Rust API's completion of the example keys, both characters one after the other.
fn rust_completion(model: &KeyframeModel) -> Vec<f32> {
    let d = model.dofs();
    let (_, frames, poses) = example_keys(d);
    let keys = [MotionKeys::whole(&frames[..4], &poses[..4 * d]), MotionKeys::whole(&frames[4..], &poses[4 * d..])];
    let (mut a, mut b) = (vec![0.0; 40 * d], vec![0.0; 31 * d]);
    model.runner(2).unwrap().complete_batch(&keys, &mut [&mut a, &mut b]).unwrap();
    [a, b].concat()
}

fn keyframe_runner(model: *const ZooModel, max_batch: usize) -> *mut ZooKeyframesRunner {
    let mut runner = null_mut();
    assert_ok(unsafe { zoo_keyframes_runner_new(model, max_batch, &mut runner) });
    runner
}

/// A keyframe model and a runner for batches of up to `max_batch`, freed on drop, and an output
/// buffer of the example's first character (240 floats of 7).
struct Keyframes {
    model: *mut ZooModel,
    runner: *mut ZooKeyframesRunner,
    out: Vec<f32>,
}

impl Keyframes {
    fn new(max_batch: usize) -> Self {
        let model = load(&files().arnn);
        Keyframes { model, runner: keyframe_runner(model, max_batch), out: vec![7.0; 40 * 6] }
    }

    fn untouched(&self) -> bool {
        self.out.iter().all(|v| *v == 7.0)
    }
}

impl Drop for Keyframes {
    fn drop(&mut self) {
        unsafe {
            zoo_keyframes_runner_free(self.runner);
            zoo_model_free(self.model);
        }
    }
}

#[test]
fn keyframes_through_the_c_abi_match_the_rust_api() {
    let expected = rust_completion(&LoadedModel::load(&files().arnn).unwrap().into_keyframes().unwrap());
    unsafe {
        let model = load(&files().arnn);
        let mut info = ZooKeyframesInfo::default();
        assert_ok(zoo_keyframes_info(model, &mut info));
        assert_eq!(info, ZooKeyframesInfo { frame_values: 6, groups: 0 });
        let mut common = ZooModelInfo::default();
        assert_ok(zoo_model_info(model, &mut common));
        assert_eq!((common.task, common.fps), (ZooTask::Keyframes, zoo_arnn::export::FPS));
        let d = info.frame_values;
        let (counts, frames, poses) = example_keys(d);
        let runner = keyframe_runner(model, 2);
        zoo_model_free(model); // the runner keeps what it needs
        let mut out = vec![f32::NAN; 71 * d];
        assert_ok(zoo_keyframes_complete_batch(
            runner,
            counts.as_ptr(),
            2,
            frames.as_ptr(),
            frames.len(),
            poses.as_ptr(),
            poses.len(),
            null(),
            0,
            out.as_mut_ptr(),
            out.len(),
        ));
        assert!(out == expected, "the C ABI's completion differs from the Rust API's");
        // One character alone: the frames it gets in the batch.
        let mut alone = vec![f32::NAN; 31 * d];
        assert_ok(zoo_keyframes_complete(
            runner,
            frames[4..].as_ptr(),
            3,
            poses[4 * d..].as_ptr(),
            3 * d,
            null(),
            0,
            alone.as_mut_ptr(),
            alone.len(),
        ));
        let worst = alone.iter().zip(&expected[40 * d..]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-5, "alone vs in a batch: {worst:e}");
        zoo_keyframes_runner_free(runner);
    }
}

impl Keyframes {
    /// [`zoo_keyframes_complete`] of one character's keys into the first `out_len` floats of the
    /// output buffer, `fixed` a pointer and length.
    unsafe fn complete(
        &mut self,
        frames: &[usize],
        poses: &[f32],
        fixed: (*const u8, usize),
        out_len: usize,
    ) -> ZooStatus {
        let out = &mut self.out[..out_len];
        unsafe {
            zoo_keyframes_complete(
                self.runner,
                frames.as_ptr(),
                frames.len(),
                poses.as_ptr(),
                poses.len(),
                fixed.0,
                fixed.1,
                out.as_mut_ptr(),
                out.len(),
            )
        }
    }
}

#[test]
fn keyframes_refuse_null_pointers() {
    let mut h = Keyframes::new(2);
    let (_, frames, poses) = example_keys(6);
    let (f, p, o) = (frames.as_ptr(), poses.as_ptr(), h.out.as_mut_ptr());
    unsafe {
        let mut info = ZooKeyframesInfo::default();
        let status = zoo_keyframes_info(null(), &mut info);
        assert_error(status, ZooStatus::NullPointer, "zoo_keyframes_info: `model` is NULL");
        assert_error(zoo_keyframes_info(h.model, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let mut runner = null_mut();
        let status = zoo_keyframes_runner_new(null(), 1, &mut runner);
        assert_error(status, ZooStatus::NullPointer, "zoo_keyframes_runner_new: `model` is NULL");
        assert_error(zoo_keyframes_runner_new(h.model, 1, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let status = zoo_keyframes_complete(null_mut(), f, 4, p, 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "zoo_keyframes_complete: `runner` is NULL");
        let status = zoo_keyframes_complete(h.runner, null(), 4, p, 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`key_frames` is NULL");
        let status = zoo_keyframes_complete(h.runner, f, 4, null(), 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`poses` is NULL");
        let status = zoo_keyframes_complete(h.runner, f, 4, p, 24, null(), 0, null_mut(), 240);
        assert_error(status, ZooStatus::NullPointer, "`out` is NULL");
        // `fixed` may be NULL only with a length of 0.
        let status = h.complete(&frames[..4], &poses[..24], (null(), 4), 240);
        assert_error(status, ZooStatus::NullPointer, "`fixed` is NULL");
        let status = zoo_keyframes_complete_batch(h.runner, null(), 2, f, 7, p, 42, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "zoo_keyframes_complete_batch: `key_counts` is NULL");
        zoo_keyframes_runner_free(null_mut());
        zoo_model_free(null_mut());
    }
}

#[test]
fn keyframes_refuse_wrong_sizes() {
    let mut h = Keyframes::new(1);
    let (counts, frames, poses) = example_keys(6);
    let (f, p) = (&frames[..4], &poses[..24]);
    unsafe {
        let mut runner = null_mut();
        let status = zoo_keyframes_runner_new(h.model, 0, &mut runner);
        assert_error(status, ZooStatus::InvalidArgument, "`max_batch` is 0");
        let status = h.complete(f, &p[..23], (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "`poses` holds 23 floats, this call needs 24");
        let status = h.complete(f, p, (null(), 0), 239);
        assert_error(status, ZooStatus::InvalidArgument, "`out` holds 239 floats, this call needs 240");
        let flags = [1u8; 4];
        assert_error(h.complete(f, p, (flags.as_ptr(), 4), 240), ZooStatus::InvalidArgument, "whole keys only");
        // A batch: key counts that do not add up, none, more characters than the runner takes.
        let mut out = vec![7.0f32; 71 * 6];
        let mut batch = |counts: &[usize], n: usize, len: usize| {
            let (f, p, o) = (frames.as_ptr(), poses.as_ptr(), out.as_mut_ptr());
            zoo_keyframes_complete_batch(h.runner, counts.as_ptr(), n, f, 7, p, 42, null(), 0, o, len)
        };
        let status = batch(&[4, 2], 2, 426);
        assert_error(status, ZooStatus::InvalidArgument, "`key_counts` add up to 6 keys but `key_frames` holds 7");
        assert_error(batch(&[], 0, 426), ZooStatus::InvalidArgument, "`count` is 0");
        assert_error(batch(&counts, 2, 426), ZooStatus::InvalidArgument, "the runner was made for at most 1");
        let status = batch(&counts, 2, 420);
        assert_error(status, ZooStatus::InvalidArgument, "`out` holds 420 floats, this call needs 426");
        assert!(out.iter().all(|v| *v == 7.0), "a refused call writes nothing");
    }
    assert!(h.untouched(), "a refused call writes nothing");
}

#[test]
fn keyframes_refuse_non_finite_keys() {
    let mut h = Keyframes::new(1);
    let (_, frames, mut poses) = example_keys(6);
    poses[8] = f32::NAN;
    let status = unsafe { h.complete(&frames[..4], &poses[..24], (null(), 0), 240) };
    assert_error(status, ZooStatus::InvalidArgument, "key 1 value 2 is NaN, not a finite number");
    poses[8] = f32::INFINITY;
    let status = unsafe { h.complete(&frames[..4], &poses[..24], (null(), 0), 240) };
    assert_error(status, ZooStatus::InvalidArgument, "not a finite number");
    assert!(h.untouched(), "a refused call writes nothing");
}

#[test]
fn keyframes_refuse_keys_out_of_order() {
    let mut h = Keyframes::new(1);
    let (_, _, poses) = example_keys(6);
    let p = &poses[..24];
    unsafe {
        let status = h.complete(&[0, 24, 9, 39], p, (null(), 0), 240);
        assert_error(
            status,
            ZooStatus::InvalidArgument,
            "`key_frames`[2] is 9 after 24; key frames must be strictly increasing",
        );
        // A key-order mistake is reported as one, not as the output size the keys would imply.
        let status = h.complete(&[0, 50, 9, 39], p, (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "`key_frames`[2] is 9 after 50");
        let status = h.complete(&[3, 9, 24, 39], p, (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "`key_frames` starts at frame 3; the first key is frame 0");
        let status = h.complete(&[0], &p[..6], (null(), 0), 6);
        assert_error(status, ZooStatus::InvalidArgument, "completion needs at least 2");
        let status = h.complete(&[0, 9, 24, usize::MAX], p, (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "a completion has at most ZOO_MAX_FRAMES (1048576) frames");
    }
    assert!(h.untouched(), "a refused call writes nothing");
}

/// Issue 46: the in-betweening design runs through the same functions. `zoo_keyframes_info`
/// reports its humanoid pose (3 joints: 15 values, 4 groups); whole and partial keys of two
/// characters complete as the Rust API completes them, bit for bit, in a batch and alone; bad
/// partial keys are refused with their C message, the output untouched.
#[test]
fn inbetween_keyframes_through_the_c_abi_match_the_rust_api() {
    let (d, g) = (15, 4);
    let path = &files().inbetween;
    let rust = LoadedModel::load(path).unwrap().into_keyframes().unwrap();
    assert!(rust.is_inbetween());
    let frames = [0usize, 9, 24, 39, 0, 8, 17, 30];
    let poses = [zoo_tests::humanoid_keys(&frames[..4], 0.0), zoo_tests::humanoid_keys(&frames[4..], 0.7)].concat();
    // Character 0's keys are whole, character 1's middle keys partial.
    let fixed = [[1.0f32; 16].as_slice(), &[1.0; 4], &[1.0, 0.0, 1.0, 0.0], &[0.0, 1.0, 0.0, 0.0], &[1.0; 4]].concat();
    let keys = [
        MotionKeys { frames: &frames[..4], poses: &poses[..4 * d], fixed: &fixed[..4 * g] },
        MotionKeys { frames: &frames[4..], poses: &poses[4 * d..], fixed: &fixed[4 * g..] },
    ];
    // The C ABI's flags are bytes.
    let fixed: Vec<u8> = fixed.iter().map(|&f| f as u8).collect();
    let (mut a, mut b) = (vec![0.0; 40 * d], vec![0.0; 31 * d]);
    rust.runner(2).unwrap().complete_batch(&keys, &mut [&mut a, &mut b]).unwrap();
    let expected = [a, b].concat();
    unsafe {
        let model = load(path);
        let mut info = ZooKeyframesInfo::default();
        assert_ok(zoo_keyframes_info(model, &mut info));
        assert_eq!(info, ZooKeyframesInfo { frame_values: d, groups: g });
        let mut common = ZooModelInfo::default();
        assert_ok(zoo_model_info(model, &mut common));
        assert_eq!((common.task, common.fps, common.joints), (ZooTask::Keyframes, 30.0, 3));
        let runner = keyframe_runner(model, 2);
        zoo_model_free(model); // the runner keeps what it needs
        let counts = [4usize, 4];
        let mut out = vec![f32::NAN; 71 * d];
        let (f, p, m) = (frames.as_ptr(), poses.as_ptr(), fixed.as_ptr());
        let status = zoo_keyframes_complete_batch(
            runner,
            counts.as_ptr(),
            2,
            f,
            8,
            p,
            8 * d,
            m,
            8 * g,
            out.as_mut_ptr(),
            71 * d,
        );
        assert_ok(status);
        assert!(out == expected, "the C ABI's completion differs from the Rust API's");
        let mut alone = vec![f32::NAN; 31 * d];
        let status = zoo_keyframes_complete(
            runner,
            f.add(4),
            4,
            p.add(4 * d),
            4 * d,
            m.add(4 * g),
            4 * g,
            alone.as_mut_ptr(),
            31 * d,
        );
        assert_ok(status);
        assert!(alone[..] == expected[40 * d..], "alone vs in a batch");
        // The first key must fix every group; the output is left as it was.
        let mut bad = fixed[16..].to_vec();
        bad[0] = 0;
        let mut untouched = vec![7.0f32; 31 * d];
        let status = zoo_keyframes_complete(
            runner,
            f.add(4),
            4,
            p.add(4 * d),
            4 * d,
            bad.as_ptr(),
            4 * g,
            untouched.as_mut_ptr(),
            31 * d,
        );
        assert_error(status, ZooStatus::InvalidArgument, "the first key is the start pose");
        assert!(untouched.iter().all(|v| *v == 7.0), "a refused call writes nothing");
        zoo_keyframes_runner_free(runner);
    }
}

// Stitching.

/// The C example's hips height and walking speed for a stitching model's skeleton (offsets
/// read as the C ABI gives them, in f32).
fn walk_scale(refiner: &StitchRefiner) -> (f64, f64) {
    let skeleton = refiner.skeleton();
    let mut rest_y = vec![0.0f64; skeleton.len()];
    let mut lowest = 0.0f64;
    for j in 0..skeleton.len() {
        rest_y[j] = skeleton.parents[j].map_or(0.0, |p| rest_y[p] + skeleton.offsets[j].y as f32 as f64);
        lowest = lowest.min(rest_y[j]);
    }
    (-lowest, 120.0 / refiner.fps() as f32 as f64)
}

/// Frame `f` of the C example's walk (`walk_pose` in `examples/tasks.c`).
fn walk_pose(k: usize, height: f64, speed: f64, f: usize) -> EnginePose {
    let mut pose = EnginePose::new(k);
    let (t, yaw) = (f as f64, 0.01 * f as f64);
    pose.root_position = Vec3::new((10.0 * (0.05 * t).sin()) as f32, 0.0, (speed * t) as f32);
    pose.root_rotation = Quat::from_xyzw(0.0, (0.5 * yaw).sin() as f32, 0.0, (0.5 * yaw).cos() as f32);
    pose.hips_position = Vec3::new(0.0, height as f32, 0.0);
    for (j, q) in pose.local_rotations.iter_mut().enumerate() {
        let angle = 0.3 * (0.2 * t + j as f64).sin();
        *q = Quat::from_xyzw((0.5 * angle).sin() as f32, 0.0, 0.0, (0.5 * angle).cos() as f32);
    }
    pose
}

/// The C example's walk for `refiner`: `window + 2 stride + 5` frames.
fn example_walk(refiner: &StitchRefiner) -> Vec<EnginePose> {
    let (height, speed) = walk_scale(refiner);
    let frames = refiner.window() + 2 * refiner.stride() + 5;
    (0..frames).map(|f| walk_pose(refiner.joints(), height, speed, f)).collect()
}

/// Poses as the C ABI takes them: roots and `4K` rotations each.
fn as_roots(poses: &[EnginePose]) -> (Vec<ZooRootMotion>, Vec<f32>) {
    let roots = poses
        .iter()
        .map(|p| ZooRootMotion {
            root_position: p.root_position.to_array(),
            root_rotation: p.root_rotation.to_array(),
            hips_position: p.hips_position.to_array(),
            ..Default::default()
        })
        .collect();
    (roots, poses.iter().flat_map(|p| p.local_rotations.iter().flat_map(|q| q.to_array())).collect())
}

/// The Rust API's whole-sequence refinement: pose values and contacts per frame.
fn rust_refine(refiner: &StitchRefiner, poses: &[EnginePose], cleanup: FootCleanup) -> Vec<(Vec<f32>, Vec<u8>)> {
    rust_refine_at(refiner, poses, &[], cleanup)
}

/// [`rust_refine`] inertialized at `seams` first.
fn rust_refine_at(
    refiner: &StitchRefiner,
    poses: &[EnginePose],
    seams: &[usize],
    cleanup: FootCleanup,
) -> Vec<(Vec<f32>, Vec<u8>)> {
    let mut out = vec![EnginePose::new(refiner.joints()); poses.len()];
    let mut contacts = vec![[false; 4]; poses.len()];
    refiner.refine_poses_at_seams(poses, seams, cleanup, &mut out, &mut contacts).unwrap();
    out.iter().zip(&contacts).map(|(p, c)| (pose_values(p), bytes(c))).collect()
}

/// The Rust API's stream over `poses`: pushing each, popping what is ready, then finishing.
fn rust_stream(refiner: &StitchRefiner, poses: &[EnginePose]) -> Vec<(Vec<f32>, Vec<u8>)> {
    rust_stream_at(refiner, poses, &[])
}

/// [`rust_stream`] with `seams` marked before their frames.
fn rust_stream_at(refiner: &StitchRefiner, poses: &[EnginePose], seams: &[usize]) -> Vec<(Vec<f32>, Vec<u8>)> {
    rust_stream_of(refiner.stream(), poses, seams)
}

/// [`rust_stream_at`] through `stream`.
fn rust_stream_of(mut stream: StitchStream<'_>, poses: &[EnginePose], seams: &[usize]) -> Vec<(Vec<f32>, Vec<u8>)> {
    let mut pose = EnginePose::new(poses[0].joints());
    let mut got = Vec::new();
    for f in 0..=poses.len() {
        if seams.contains(&f) {
            stream.mark_seam();
        }
        match poses.get(f) {
            Some(p) => stream.push(p).unwrap(),
            None => stream.finish().unwrap(),
        }
        while let Some(c) = stream.pop(&mut pose).unwrap() {
            got.push((pose_values(&pose), bytes(&c)));
        }
    }
    got
}

fn stitch_model() -> *mut ZooModel {
    load(&files().rmr)
}

fn stitch_stream(model: *const ZooModel) -> *mut ZooStitchStream {
    let mut stream = null_mut();
    assert_ok(unsafe { zoo_stitch_stream_new(model, &mut stream) });
    stream
}

/// Output buffers of a whole-sequence refinement of `frames` poses of `k` joints.
struct Refined {
    roots: Vec<ZooRootMotion>,
    rotations: Vec<f32>,
    contacts: Vec<u8>,
}

impl Refined {
    fn new(frames: usize, k: usize) -> Self {
        Refined {
            roots: vec![ZooRootMotion::default(); frames],
            rotations: vec![0.0; frames * 4 * k],
            contacts: vec![9; frames * 4],
        }
    }

    /// [`zoo_stitch_refine`] of `roots` / `rotations` into these buffers.
    unsafe fn refine(
        &mut self,
        model: *const ZooModel,
        roots: &[ZooRootMotion],
        rotations: &[f32],
        cleanup: FootCleanup,
    ) -> ZooStatus {
        unsafe {
            zoo_stitch_refine(
                model,
                roots.as_ptr(),
                roots.len(),
                rotations.as_ptr(),
                rotations.len(),
                cleanup.place_ankles,
                cleanup.lock_feet,
                self.roots.as_mut_ptr(),
                self.roots.len(),
                self.rotations.as_mut_ptr(),
                self.rotations.len(),
                self.contacts.as_mut_ptr(),
                self.contacts.len(),
            )
        }
    }

    fn frames(&self, k: usize) -> Vec<(Vec<f32>, Vec<u8>)> {
        (0..self.roots.len())
            .map(|f| {
                (
                    root_values(&self.roots[f], &self.rotations[f * 4 * k..(f + 1) * 4 * k]),
                    self.contacts[f * 4..f * 4 + 4].to_vec(),
                )
            })
            .collect()
    }
}

/// Pops every ready pose of `stream` (`k` joints).
unsafe fn pop_ready(stream: *mut ZooStitchStream, k: usize, got: &mut Vec<(Vec<f32>, Vec<u8>)>) {
    let mut pop = Pop::new(k, 0);
    loop {
        let mut ready = false;
        assert_ok(unsafe { zoo_stitch_stream_ready(stream, &mut ready) });
        if !ready {
            return;
        }
        assert_ok(unsafe { pop.pop_with(stream, 4 * k, 4) });
        got.push((root_values(&pop.root, &pop.rotations), pop.contacts.clone()));
    }
}

#[test]
fn stitching_through_the_c_abi_matches_the_rust_api() {
    let refiner = StitchRefiner::load(&files().rmr).unwrap();
    let poses = example_walk(&refiner);
    let (roots, rotations) = as_roots(&poses);
    let k = refiner.joints();
    unsafe {
        let model = stitch_model();
        let mut info = ZooStitchInfo::default();
        assert_ok(zoo_stitch_info(model, &mut info));
        // The default stream's latency: the window, the pushes each window is spread over
        // (`s - 1`) less one, the lookahead of the guard and the lock, and the frames they
        // release at once.
        let latency = 30 + (15 - 1) + STREAM_LOOKAHEAD + STREAM_CHUNK - 1;
        assert_eq!(info, ZooStitchInfo { window: 30, stride: 15, blend_frames: 10, latency });
        // The fixture refines the raw concatenation (its file's `stitch.pre_blend` is false).
        let mut pre_blend = true;
        assert_ok(zoo_stitch_pre_blend(model, &mut pre_blend));
        assert_eq!(pre_blend, refiner.pre_blend());
        assert!(!pre_blend);
        assert_error(zoo_stitch_pre_blend(model, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let mut common = ZooModelInfo::default();
        assert_ok(zoo_model_info(model, &mut common));
        assert_eq!((common.task, common.joints, common.fps), (ZooTask::Stitch, 21, 30.0));
        let (mut parents, mut offsets) = (vec![0i32; k], vec![0.0f32; 3 * k]);
        assert_ok(zoo_model_skeleton(model, parents.as_mut_ptr(), k, offsets.as_mut_ptr(), 3 * k));
        let skeleton = refiner.skeleton();
        assert!(parents.iter().zip(&skeleton.parents).all(|(a, b)| *a == b.map_or(-1, |p| p as i32)));
        assert_eq!(offsets[3 * 2 + 1], skeleton.offsets[2].y as f32);
        // The whole sequence, with and without the foot cleanup.
        for cleanup in [FootCleanup::default(), FootCleanup::NONE] {
            let mut out = Refined::new(poses.len(), k);
            assert_ok(out.refine(model, &roots, &rotations, cleanup));
            assert!(
                out.frames(k) == rust_refine(&refiner, &poses, cleanup),
                "{cleanup:?}: the C ABI differs from the Rust API"
            );
        }
        // The stream.
        let stream = stitch_stream(model);
        zoo_model_free(model); // the stream keeps what it needs
        let mut got = Vec::new();
        for f in 0..poses.len() {
            assert_ok(zoo_stitch_stream_push(stream, &roots[f], rotations[f * 4 * k..].as_ptr(), 4 * k));
            pop_ready(stream, k, &mut got);
            assert_eq!(got.len(), (f + 1).saturating_sub(info.latency), "ready `latency` frames after the push");
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        assert_ok(zoo_stitch_stream_finish(stream)); // twice: nothing more
        pop_ready(stream, k, &mut got);
        assert!(got == rust_stream(&refiner, &poses), "the C ABI's stream differs from the Rust API's");
        let mut n = 0;
        assert_ok(zoo_stitch_stream_latency(stream, &mut n));
        assert_eq!(n, info.latency);
        assert_error(
            zoo_stitch_stream_set_cleanup(stream, false, false),
            ZooStatus::InvalidState,
            "zoo_stitch_stream_set_cleanup: stitching: the foot cleanup of a stream is set before its first push",
        );
        zoo_stitch_stream_free(stream);
        // A stream without the ankle IK and the lock (the guard, on, has no seams to guard here).
        let model = stitch_model();
        let stream = stitch_stream(model);
        zoo_model_free(model);
        assert_ok(zoo_stitch_stream_set_cleanup(stream, false, false));
        assert_ok(zoo_stitch_stream_latency(stream, &mut n));
        assert_eq!(n, info.latency, "the guard keeps its lookahead");
        let mut got = Vec::new();
        for f in 0..poses.len() {
            assert_ok(zoo_stitch_stream_push(stream, &roots[f], rotations[f * 4 * k..].as_ptr(), 4 * k));
            pop_ready(stream, k, &mut got);
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        pop_ready(stream, k, &mut got);
        let mut rust = refiner.stream();
        rust.set_cleanup(FootCleanup::NONE).unwrap();
        assert!(
            got == rust_stream_of(rust, &poses, &[]),
            "the C ABI's stream without cleanup differs from the Rust API's"
        );
        assert_error(zoo_stitch_stream_set_cleanup(null_mut(), true, true), ZooStatus::NullPointer, "`stream` is NULL");
        zoo_stitch_stream_free(stream);
    }
}

/// The seams inertialized first (`zoo stitch --pre-blend`): `zoo_stitch_refine_at_seams` and a
/// stream with `zoo_stitch_stream_mark_seam` give the Rust API's poses, and differ from the
/// plain ones; bad seams are refused.
#[test]
fn stitching_at_seams_through_the_c_abi_matches_the_rust_api() {
    let refiner = StitchRefiner::load(&files().rmr).unwrap();
    let poses = example_walk(&refiner);
    let (roots, rotations) = as_roots(&poses);
    let (n, k) = (poses.len(), refiner.joints());
    let seams = [n / 3, n / 3 + 1, 2 * n / 3];
    let cleanup = FootCleanup::default();
    unsafe {
        let model = stitch_model();
        let mut out = Refined::new(n, k);
        let call = |out: &mut Refined, seams: *const usize, seams_len: usize| {
            zoo_stitch_refine_at_seams(
                model,
                roots.as_ptr(),
                n,
                rotations.as_ptr(),
                rotations.len(),
                seams,
                seams_len,
                cleanup.place_ankles,
                cleanup.lock_feet,
                out.roots.as_mut_ptr(),
                out.roots.len(),
                out.rotations.as_mut_ptr(),
                out.rotations.len(),
                out.contacts.as_mut_ptr(),
                out.contacts.len(),
            )
        };
        assert_ok(call(&mut out, seams.as_ptr(), seams.len()));
        let want = rust_refine_at(&refiner, &poses, &seams, cleanup);
        assert!(out.frames(k) == want, "the C ABI differs from the Rust API");
        assert!(want != rust_refine(&refiner, &poses, cleanup), "the seams changed nothing");
        // No seams (NULL, 0) is zoo_stitch_refine.
        assert_ok(call(&mut out, null(), 0));
        assert!(out.frames(k) == rust_refine(&refiner, &poses, cleanup));
        assert_error(call(&mut out, null(), 2), ZooStatus::NullPointer, "zoo_stitch_refine_at_seams: `seams` is NULL");
        let past = [n];
        let status = call(&mut out, past.as_ptr(), 1);
        assert_error(status, ZooStatus::InvalidArgument, &format!("seam at frame {n} of a sequence of {n} frames"));

        let stream = stitch_stream(model);
        let mut got = Vec::new();
        for f in 0..n {
            if seams.contains(&f) {
                assert_ok(zoo_stitch_stream_mark_seam(stream));
            }
            assert_ok(zoo_stitch_stream_push(stream, &roots[f], rotations[f * 4 * k..].as_ptr(), 4 * k));
            pop_ready(stream, k, &mut got);
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        pop_ready(stream, k, &mut got);
        assert!(got == rust_stream_at(&refiner, &poses, &seams), "the C ABI's stream differs from the Rust API's");
        assert_error(
            zoo_stitch_stream_mark_seam(stream),
            ZooStatus::InvalidState,
            "zoo_stitch_stream_mark_seam: the stream is finished",
        );
        assert_error(zoo_stitch_stream_mark_seam(null_mut()), ZooStatus::NullPointer, "`stream` is NULL");
        // The seam guard is switched while no stream lives: off, the Rust API's unguarded poses.
        let status = zoo_stitch_set_seam_guard(model, false);
        assert_error(
            status,
            ZooStatus::InvalidState,
            "free them (zoo_stitch_stream_free) before switching the seam guard",
        );
        zoo_stitch_stream_free(stream);
        assert_ok(zoo_stitch_set_seam_guard(model, false));
        assert_ok(call(&mut out, seams.as_ptr(), seams.len()));
        let mut unguarded = refiner.clone();
        unguarded.set_seam_guard(false);
        assert!(out.frames(k) == rust_refine_at(&unguarded, &poses, &seams, cleanup), "the C ABI's guard is off");
        assert_error(zoo_stitch_set_seam_guard(null_mut(), true), ZooStatus::NullPointer, "`model` is NULL");
        // The seams' reach: the window by default, 0 refines everywhere, past the maximum refused.
        let mut reach = 0usize;
        assert_ok(zoo_stitch_seam_reach(model, &mut reach));
        assert_eq!(reach, refiner.window(), "the reach is the window by default, as in zoo stitch");
        assert_ok(zoo_stitch_set_seam_reach(model, 0));
        assert_ok(zoo_stitch_seam_reach(model, &mut reach));
        assert_eq!(reach, 0);
        assert_ok(call(&mut out, seams.as_ptr(), seams.len()));
        let mut everywhere = unguarded.clone();
        everywhere.set_seam_reach(None).unwrap();
        let refined_everywhere = rust_refine_at(&everywhere, &poses, &seams, cleanup);
        assert!(out.frames(k) == refined_everywhere, "the C ABI refines everywhere");
        assert!(refined_everywhere != rust_refine_at(&unguarded, &poses, &seams, cleanup), "the reach changed nothing");
        let status = zoo_stitch_set_seam_reach(model, 1 << 40);
        assert_error(status, ZooStatus::InvalidArgument, "more than 3600");
        zoo_model_free(model);
    }
}

/// A stitching model (freed on drop) and the example's walk as the C ABI takes it: `n` roots
/// and `4K` rotations each.
struct Stitching {
    model: *mut ZooModel,
    roots: Vec<ZooRootMotion>,
    rotations: Vec<f32>,
    n: usize,
    k: usize,
}

impl Stitching {
    fn new() -> Self {
        let refiner = LoadedModel::load(&files().rmr).unwrap().into_stitch().unwrap();
        let (roots, rotations) = as_roots(&example_walk(&refiner));
        Stitching { model: stitch_model(), n: roots.len(), k: refiner.joints(), roots, rotations }
    }

    /// Pushes frame `f` of the walk.
    unsafe fn push(&self, stream: *mut ZooStitchStream, f: usize) -> ZooStatus {
        let k = self.k;
        unsafe { zoo_stitch_stream_push(stream, &self.roots[f], self.rotations[f * 4 * k..].as_ptr(), 4 * k) }
    }
}

impl Drop for Stitching {
    fn drop(&mut self) {
        unsafe { zoo_model_free(self.model) };
    }
}

/// Output buffers of one stream pop of `k` joints (`extra` more rotation floats and contact
/// bytes than needed).
struct Pop {
    root: ZooRootMotion,
    rotations: Vec<f32>,
    contacts: Vec<u8>,
}

impl Pop {
    fn new(k: usize, extra: usize) -> Self {
        Pop { root: ZooRootMotion::default(), rotations: vec![0.0; 4 * k + extra], contacts: vec![9; 4 + extra] }
    }

    /// [`zoo_stitch_stream_pop`] with `rotations_len` and `contacts_len` given.
    unsafe fn pop_with(
        &mut self,
        stream: *mut ZooStitchStream,
        rotations_len: usize,
        contacts_len: usize,
    ) -> ZooStatus {
        let (r, c) = (self.rotations.as_mut_ptr(), self.contacts.as_mut_ptr());
        unsafe { zoo_stitch_stream_pop(stream, &mut self.root, r, rotations_len, c, contacts_len) }
    }
}

#[test]
fn stitching_refuses_null_pointers() {
    let h = Stitching::new();
    let (model, n, k) = (h.model, h.n, h.k);
    let (roots, rotations) = (h.roots.as_ptr(), h.rotations.as_ptr());
    unsafe {
        let mut info = ZooStitchInfo::default();
        let status = zoo_stitch_info(null(), &mut info);
        assert_error(status, ZooStatus::NullPointer, "zoo_stitch_info: `model` is NULL");
        let status = zoo_model_skeleton(model, null_mut(), k, null_mut(), 3 * k);
        assert_error(status, ZooStatus::NullPointer, "`parents` is NULL");
        let status = zoo_stitch_set_window(null_mut(), 30, 15);
        assert_error(status, ZooStatus::NullPointer, "zoo_stitch_set_window: `model` is NULL");
        let mut out = Refined::new(n, k);
        let status = out.refine(null(), &h.roots, &h.rotations, FootCleanup::default());
        assert_error(status, ZooStatus::NullPointer, "zoo_stitch_refine: `model` is NULL");
        let (o_roots, o_rot, o_c) = (out.roots.as_mut_ptr(), out.rotations.as_mut_ptr(), out.contacts.as_mut_ptr());
        let refine = |roots: *const ZooRootMotion, rotations: *const f32, o_roots, o_rot, o_c| {
            zoo_stitch_refine(
                model,
                roots,
                n,
                rotations,
                n * 4 * k,
                true,
                true,
                o_roots,
                n,
                o_rot,
                n * 4 * k,
                o_c,
                n * 4,
            )
        };
        assert_error(refine(null(), rotations, o_roots, o_rot, o_c), ZooStatus::NullPointer, "`roots` is NULL");
        assert_error(refine(roots, null(), o_roots, o_rot, o_c), ZooStatus::NullPointer, "`rotations` is NULL");
        assert_error(refine(roots, rotations, null_mut(), o_rot, o_c), ZooStatus::NullPointer, "`out_roots` is NULL");
        let status = refine(roots, rotations, o_roots, null_mut(), o_c);
        assert_error(status, ZooStatus::NullPointer, "`out_rotations` is NULL");
        let status = refine(roots, rotations, o_roots, o_rot, null_mut());
        assert_error(status, ZooStatus::NullPointer, "`contacts` is NULL");
        // The stream.
        let mut stream = null_mut();
        assert_error(zoo_stitch_stream_new(null(), &mut stream), ZooStatus::NullPointer, "`model` is NULL");
        assert_error(zoo_stitch_stream_new(model, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let stream = stitch_stream(model);
        let status = zoo_stitch_stream_push(null_mut(), roots, rotations, 4 * k);
        assert_error(status, ZooStatus::NullPointer, "`stream` is NULL");
        assert_error(
            zoo_stitch_stream_push(stream, null(), rotations, 4 * k),
            ZooStatus::NullPointer,
            "`root` is NULL",
        );
        let status = zoo_stitch_stream_push(stream, roots, null(), 4 * k);
        assert_error(status, ZooStatus::NullPointer, "`rotations` is NULL");
        let mut ready = true;
        assert_error(zoo_stitch_stream_ready(null(), &mut ready), ZooStatus::NullPointer, "`stream` is NULL");
        assert_error(zoo_stitch_stream_ready(stream, null_mut()), ZooStatus::NullPointer, "`ready` is NULL");
        let mut pop = Pop::new(k, 0);
        assert_error(pop.pop_with(null_mut(), 4 * k, 4), ZooStatus::NullPointer, "`stream` is NULL");
        let (r, c) = (pop.rotations.as_mut_ptr(), pop.contacts.as_mut_ptr());
        let status = zoo_stitch_stream_pop(stream, null_mut(), r, 4 * k, c, 4);
        assert_error(status, ZooStatus::NullPointer, "`root` is NULL");
        let status = zoo_stitch_stream_pop(stream, &mut pop.root, null_mut(), 4 * k, c, 4);
        assert_error(status, ZooStatus::NullPointer, "`rotations` is NULL");
        let status = zoo_stitch_stream_pop(stream, &mut pop.root, r, 4 * k, null_mut(), 4);
        assert_error(status, ZooStatus::NullPointer, "`contacts` is NULL");
        assert_error(zoo_stitch_stream_finish(null_mut()), ZooStatus::NullPointer, "`stream` is NULL");
        zoo_stitch_stream_free(null_mut());
        zoo_model_free(null_mut());
        zoo_stitch_stream_free(stream);
    }
}

#[test]
fn stitching_refuses_wrong_sizes() {
    let h = Stitching::new();
    let (model, n, k) = (h.model, h.n, h.k);
    let (roots, rotations) = (&h.roots, &h.rotations);
    unsafe {
        let (mut parents, mut offsets) = (vec![0i32; k], vec![0.0f32; 3 * k]);
        let (p, o) = (parents.as_mut_ptr(), offsets.as_mut_ptr());
        let status = zoo_model_skeleton(model, p, k - 1, o, 3 * k);
        assert_error(status, ZooStatus::InvalidArgument, "`parents` holds 20 values, this call needs 21");
        assert_error(zoo_model_skeleton(model, p, k, o, 3 * k + 1), ZooStatus::InvalidArgument, "`offsets`");
        let cleanup = FootCleanup::default();
        let mut out = Refined::new(n, k);
        let status = out.refine(model, roots, &rotations[..rotations.len() - 4], cleanup);
        assert_error(status, ZooStatus::InvalidArgument, "`rotations`");
        let status = Refined::new(n - 1, k).refine(model, roots, rotations, cleanup);
        assert_error(status, ZooStatus::InvalidArgument, "`out_roots`");
        out.contacts.pop();
        assert_error(out.refine(model, roots, rotations, cleanup), ZooStatus::InvalidArgument, "`contacts`");
        // Fewer frames than the window.
        let status = Refined::new(20, k).refine(model, &roots[..20], &rotations[..20 * 4 * k], cleanup);
        assert_error(
            status,
            ZooStatus::InvalidArgument,
            "the window of 30 frames is longer than the sequence (20 frames)",
        );
        // The stream.
        let stream = stitch_stream(model);
        let status = zoo_stitch_stream_push(stream, &roots[0], rotations.as_ptr(), 4 * k - 1);
        assert_error(status, ZooStatus::InvalidArgument, "`rotations`");
        for f in 0..n {
            assert_ok(h.push(stream, f));
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        let mut pop = Pop::new(k, 1);
        assert_error(pop.pop_with(stream, 4 * k + 1, 4), ZooStatus::InvalidArgument, "`rotations`");
        assert_error(pop.pop_with(stream, 4 * k, 5), ZooStatus::InvalidArgument, "`contacts`");
        assert_ok(pop.pop_with(stream, 4 * k, 4));
        // Planning another window: a stride longer than the window.
        zoo_stitch_stream_free(stream);
        let status = zoo_stitch_set_window(model, 20, 30);
        assert_error(status, ZooStatus::InvalidArgument, "zoo_stitch_set_window: stitching: a window of 20 frames");
        assert_error(status, ZooStatus::InvalidArgument, "stride must be in 1..=window");
    }
}

#[test]
fn stitching_refuses_non_finite_poses() {
    let mut h = Stitching::new();
    let k = h.k;
    h.rotations[3 * 4 * k + 5] = f32::NAN;
    unsafe {
        let mut out = Refined::new(h.n, k);
        let status = out.refine(h.model, &h.roots, &h.rotations, FootCleanup::default());
        assert_error(status, ZooStatus::InvalidArgument, "input `pose 3` holds a non-finite value (NaN)");
        assert!(out.contacts.iter().all(|c| *c == 9), "a refused call writes nothing");
        let stream = stitch_stream(h.model);
        assert_error(h.push(stream, 3), ZooStatus::InvalidArgument, "non-finite");
        h.roots[0].root_position[0] = f32::INFINITY;
        assert_error(h.push(stream, 0), ZooStatus::InvalidArgument, "non-finite");
        zoo_stitch_stream_free(stream);
    }
}

#[test]
fn stitch_streams_refuse_calls_out_of_order() {
    let h = Stitching::new();
    let (model, k) = (h.model, h.k);
    unsafe {
        let stream = stitch_stream(model);
        let mut out = Pop::new(k, 0);
        let mut pop = || out.pop_with(stream, 4 * k, 4);
        // Popping before anything is ready, finishing too early.
        let status = pop();
        assert_error(
            status,
            ZooStatus::NotAvailable,
            &format!(
                "the refined pose of frame 0 is not ready: it is once frame {} is pushed",
                30 + (15 - 1) + STREAM_LOOKAHEAD + STREAM_CHUNK - 1
            ),
        );
        for f in 0..10 {
            assert_ok(h.push(stream, f));
        }
        assert_error(pop(), ZooStatus::NotAvailable, "zoo_stitch_stream_ready");
        let status = zoo_stitch_stream_finish(stream);
        assert_error(status, ZooStatus::InvalidState, "ends after 10 frames, fewer than the window of 30");
        // The fix names the C function, not the runtime's method.
        assert_error(status, ZooStatus::InvalidState, "plan a shorter window with zoo_stitch_set_window");
        // Another window while a stream is alive.
        assert_error(zoo_stitch_set_window(model, 20, 10), ZooStatus::InvalidState, "free them");
        for f in 10..30 {
            assert_ok(h.push(stream, f));
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        // Pushing after the finish.
        assert_error(h.push(stream, 30), ZooStatus::InvalidState, "the stream is finished");
        assert_error(h.push(stream, 30), ZooStatus::InvalidState, "start another with zoo_stitch_stream_new");
        for _ in 0..30 {
            assert_ok(pop());
        }
        assert_error(pop(), ZooStatus::NotAvailable, "the finished stream's 30 frames were all popped");
        zoo_stitch_stream_free(stream);
        // Without streams the model plans another window: a shorter latency.
        assert_ok(zoo_stitch_set_window(model, 20, 10));
        let mut info = ZooStitchInfo::default();
        assert_ok(zoo_stitch_info(model, &mut info));
        assert_eq!(
            (info.window, info.stride, info.latency),
            (20, 10, 20 + (10 - 1) + STREAM_LOOKAHEAD + STREAM_CHUNK - 1)
        );
    }
}

// Synthesis and control.

const SEEDS: [u64; 3] = [100, 101, 102];

/// The C example's start: the data's mean frame for every character, side by side.
fn example_start(model: &SynthesisModel, n: usize) -> (Vec<f32>, Vec<f32>) {
    let mean = &model.model().metadata().normalization["x"].mean;
    let frames = (0..n).flat_map(|_| mean.iter().copied()).collect();
    let placements = (0..n).flat_map(|c| [(200.0 * c as f64) as f32, 0.0, (0.1 * c as f64) as f32]).collect();
    (frames, placements)
}

/// The C example's control of frame `t` out of `frames`.
fn example_control(t: usize, frames: usize) -> ZooControl {
    ZooControl { speed: 150.0, heading: if t < frames / 2 { 0.0 } else { 1.570_796_4 } }
}

/// The Rust API's `frames` frames of `n` synthesis characters: per frame and character, the
/// pose values and contacts.
fn rust_synthesis(model: &SynthesisModel, n: usize, frames: usize) -> Vec<Vec<(Vec<f32>, Vec<u8>)>> {
    let (start, placements) = example_start(model, n);
    let d = model.frame_dim();
    let mut runner = model.runner(n).unwrap();
    let mut chars: Vec<_> = SEEDS[..n].iter().map(|&s| model.new_character(s)).collect();
    for (c, ch) in chars.iter_mut().enumerate() {
        let p = &placements[3 * c..3 * c + 3];
        ch.start(model, &start[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
    }
    let mut poses = vec![EnginePose::new(model.joints()); n];
    let mut contacts = vec![[false; 2]; n];
    (0..frames)
        .map(|_| {
            runner.step_batch(&mut chars, 1.0, &mut poses, &mut contacts).unwrap();
            poses.iter().zip(&contacts).map(|(p, c)| (pose_values(p), bytes(c))).collect()
        })
        .collect()
}

/// The Rust API's `frames` controlled frames of `n` characters under the example's controls.
fn rust_control(model: &SynthesisModel, n: usize, frames: usize) -> Vec<Vec<(Vec<f32>, Vec<u8>)>> {
    let (start, placements) = example_start(model, n);
    let d = model.frame_dim();
    let mut runner = ControlRunner::new(model).unwrap();
    let mut chars: Vec<_> =
        SEEDS[..n].iter().map(|&s| ControlledCharacter::new(model, s, ControlSettings::default()).unwrap()).collect();
    for (c, ch) in chars.iter_mut().enumerate() {
        let p = &placements[3 * c..3 * c + 3];
        ch.start(model, &start[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
    }
    let mut pose = EnginePose::new(model.joints());
    (0..frames)
        .map(|t| {
            let z = example_control(t, frames);
            chars
                .iter_mut()
                .map(|ch| {
                    let c = runner.step(ch, Control::new(z.speed, z.heading), &mut pose).unwrap();
                    (pose_values(&pose), bytes(&c))
                })
                .collect()
        })
        .collect()
}

fn synthesis_model() -> *mut ZooModel {
    load(&files().rnngmm)
}

/// Output buffers of a step of `n` characters of `k` joints.
struct Step {
    roots: Vec<ZooRootMotion>,
    rotations: Vec<f32>,
    contacts: Vec<u8>,
    k: usize,
}

impl Step {
    fn new(n: usize, k: usize) -> Self {
        Step { roots: vec![ZooRootMotion::default(); n], rotations: vec![0.0; n * 4 * k], contacts: vec![9; 2 * n], k }
    }

    fn frame(&self) -> Vec<(Vec<f32>, Vec<u8>)> {
        let k = self.k;
        (0..self.roots.len())
            .map(|c| {
                (
                    root_values(&self.roots[c], &self.rotations[c * 4 * k..(c + 1) * 4 * k]),
                    self.contacts[2 * c..2 * c + 2].to_vec(),
                )
            })
            .collect()
    }

    unsafe fn synthesis(
        &mut self,
        runner: *mut ZooSynthesisRunner,
        chars: *mut ZooSynthesisCharacters,
        temperature: f32,
    ) -> ZooStatus {
        unsafe {
            zoo_synthesis_step(
                runner,
                chars,
                temperature,
                self.roots.as_mut_ptr(),
                self.roots.len(),
                self.rotations.as_mut_ptr(),
                self.rotations.len(),
                self.contacts.as_mut_ptr(),
                self.contacts.len(),
            )
        }
    }

    unsafe fn control(
        &mut self,
        runner: *mut ZooControlRunner,
        chars: *mut ZooControlCharacters,
        controls: &[ZooControl],
    ) -> ZooStatus {
        unsafe {
            zoo_control_step(
                runner,
                chars,
                controls.as_ptr(),
                controls.len(),
                self.roots.as_mut_ptr(),
                self.roots.len(),
                self.rotations.as_mut_ptr(),
                self.rotations.len(),
                self.contacts.as_mut_ptr(),
                self.contacts.len(),
            )
        }
    }
}

/// A synthesis model, a runner and characters of [`SEEDS`] (started from the example's start
/// when `started`), the controller's runner and characters (not started), the model's joints
/// `k` and frame size `d`, and the example's start: the handles are freed on drop.
struct Handles {
    model: *mut ZooModel,
    runner: *mut ZooSynthesisRunner,
    chars: *mut ZooSynthesisCharacters,
    crunner: *mut ZooControlRunner,
    cchars: *mut ZooControlCharacters,
    k: usize,
    d: usize,
    start: (Vec<f32>, Vec<f32>),
}

impl Handles {
    fn new(started: bool) -> Self {
        let rust = SynthesisModel::load(&files().rnngmm).unwrap();
        let (n, start) = (SEEDS.len(), example_start(&rust, SEEDS.len()));
        let model = synthesis_model();
        let (mut runner, mut chars, mut crunner, mut cchars) = (null_mut(), null_mut(), null_mut(), null_mut());
        unsafe {
            assert_ok(zoo_synthesis_runner_new(model, n, &mut runner));
            assert_ok(zoo_synthesis_characters_new(model, SEEDS.as_ptr(), n, &mut chars));
            assert_ok(zoo_control_runner_new(model, 64, &mut crunner));
            assert_ok(zoo_control_characters_new(model, SEEDS.as_ptr(), n, null(), &mut cchars));
            if started {
                assert_ok(zoo_synthesis_start(chars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
            }
        }
        Handles { model, runner, chars, crunner, cchars, k: rust.joints(), d: rust.frame_dim(), start }
    }

    /// Output buffers of a step of the batch.
    fn step(&self) -> Step {
        Step::new(SEEDS.len(), self.k)
    }
}

impl Drop for Handles {
    fn drop(&mut self) {
        unsafe {
            zoo_control_characters_free(self.cchars);
            zoo_control_runner_free(self.crunner);
            zoo_synthesis_characters_free(self.chars);
            zoo_synthesis_runner_free(self.runner);
            zoo_model_free(self.model);
        }
    }
}

/// The default control settings.
fn default_settings() -> ZooControlSettings {
    let mut settings = unsafe { std::mem::zeroed::<ZooControlSettings>() };
    assert_ok(unsafe { zoo_control_settings_default(&mut settings) });
    settings
}

#[test]
fn synthesis_through_the_c_abi_matches_the_rust_api() {
    let rust = SynthesisModel::load(&files().rnngmm).unwrap();
    let (n, k, frames) = (SEEDS.len(), rust.joints(), 100);
    let expected = rust_synthesis(&rust, n, frames);
    let start = example_start(&rust, n);
    unsafe {
        let model = synthesis_model();
        let mut info = ZooSynthesisInfo::default();
        assert_ok(zoo_synthesis_info(model, &mut info));
        assert_eq!(info, ZooSynthesisInfo { frame_values: rust.frame_dim(), has_refiner: false });
        let mut common = ZooModelInfo::default();
        assert_ok(zoo_model_info(model, &mut common));
        assert_eq!((common.task, common.joints, common.fps), (ZooTask::Synthesis, k, 30.0));
        let mut mean = vec![0.0f32; info.frame_values];
        assert_ok(zoo_synthesis_mean_frame(model, mean.as_mut_ptr(), mean.len()));
        assert_eq!(mean, start.0[..info.frame_values]);
        let (mut parents, mut offsets) = (vec![0i32; k], vec![0.0f32; 3 * k]);
        assert_ok(zoo_model_skeleton(model, parents.as_mut_ptr(), k, offsets.as_mut_ptr(), 3 * k));
        assert_eq!(parents, rust.model().metadata().skeleton.parents);
        let (mut runner, mut chars) = (null_mut(), null_mut());
        assert_ok(zoo_synthesis_runner_new(model, n, &mut runner));
        assert_ok(zoo_synthesis_characters_new(model, SEEDS.as_ptr(), n, &mut chars));
        zoo_model_free(model); // runner and characters keep what they need
        assert_ok(zoo_synthesis_start(chars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        let mut step = Step::new(n, k);
        for (t, want) in expected.iter().enumerate() {
            assert_ok(step.synthesis(runner, chars, 1.0));
            assert!(step.frame() == *want, "frame {t}: the C ABI differs from the Rust API");
        }
        zoo_synthesis_characters_free(chars);
        zoo_synthesis_runner_free(runner);
    }
}

#[test]
fn control_through_the_c_abi_matches_the_rust_api() {
    let rust = SynthesisModel::load(&files().rnngmm).unwrap();
    let (n, k, frames) = (2, rust.joints(), 30);
    let expected = rust_control(&rust, n, frames);
    let start = example_start(&rust, n);
    unsafe {
        let model = synthesis_model();
        let settings = default_settings();
        let d = ControlSettings::default();
        assert_eq!(
            (settings.batch, settings.sigma_speed, settings.temperature),
            (d.batch, d.sigma_speed, d.temperature)
        );
        assert!(settings.speed_offsets.is_null() && settings.turn_offsets_len == 0);
        let (mut runner, mut chars) = (null_mut(), null_mut());
        assert_ok(zoo_control_runner_new(model, 64, &mut runner));
        assert_ok(zoo_control_characters_new(model, SEEDS.as_ptr(), n, &settings, &mut chars));
        zoo_model_free(model);
        assert_ok(zoo_control_start(chars, start.0.as_ptr(), start.0.len(), start.1.as_ptr(), start.1.len()));
        let mut step = Step::new(n, k);
        for (t, want) in expected.iter().enumerate() {
            let z = example_control(t, frames);
            assert_ok(step.control(runner, chars, &[z, z]));
            assert!(step.frame() == *want, "frame {t}: the C ABI differs from the Rust API");
        }
        zoo_control_characters_free(chars);
        zoo_control_runner_free(runner);
    }
}

#[test]
fn synthesis_refuses_null_pointers() {
    let h = Handles::new(true);
    let (start, k) = (&h.start, h.k);
    unsafe {
        let mut info = ZooSynthesisInfo::default();
        let status = zoo_synthesis_info(null(), &mut info);
        assert_error(status, ZooStatus::NullPointer, "zoo_synthesis_info: `model` is NULL");
        let status = zoo_synthesis_mean_frame(h.model, null_mut(), 3);
        assert_error(status, ZooStatus::NullPointer, "zoo_synthesis_mean_frame: `frame` is NULL");
        let status = zoo_synthesis_set_refine(null_mut(), true);
        assert_error(status, ZooStatus::NullPointer, "zoo_synthesis_set_refine: `model` is NULL");
        let mut out = null_mut();
        assert_error(zoo_synthesis_runner_new(null(), 3, &mut out), ZooStatus::NullPointer, "`model` is NULL");
        let mut chars = null_mut();
        let status = zoo_synthesis_characters_new(h.model, null(), 3, &mut chars);
        assert_error(status, ZooStatus::NullPointer, "`seeds` is NULL");
        let status = zoo_synthesis_characters_new(h.model, SEEDS.as_ptr(), 3, null_mut());
        assert_error(status, ZooStatus::NullPointer, "`out` is NULL");
        let (f, p) = (start.0.as_ptr(), start.1.as_ptr());
        let status = zoo_synthesis_start(null_mut(), f, start.0.len(), p, 9);
        assert_error(status, ZooStatus::NullPointer, "`characters` is NULL");
        let status = zoo_synthesis_start(h.chars, null(), start.0.len(), p, 9);
        assert_error(status, ZooStatus::NullPointer, "`frames` is NULL");
        let status = zoo_synthesis_start(h.chars, f, start.0.len(), null(), 9);
        assert_error(status, ZooStatus::NullPointer, "`placements` is NULL");
        let mut step = h.step();
        assert_error(step.synthesis(null_mut(), h.chars, 1.0), ZooStatus::NullPointer, "`runner` is NULL");
        assert_error(step.synthesis(h.runner, null_mut(), 1.0), ZooStatus::NullPointer, "`characters` is NULL");
        let (roots, r, c) = (step.roots.as_mut_ptr(), step.rotations.as_mut_ptr(), step.contacts.as_mut_ptr());
        let status = zoo_synthesis_step(h.runner, h.chars, 1.0, null_mut(), 3, r, 12 * k, c, 6);
        assert_error(status, ZooStatus::NullPointer, "`roots` is NULL");
        let status = zoo_synthesis_step(h.runner, h.chars, 1.0, roots, 3, null_mut(), 12 * k, c, 6);
        assert_error(status, ZooStatus::NullPointer, "`rotations` is NULL");
        let status = zoo_synthesis_step(h.runner, h.chars, 1.0, roots, 3, r, 12 * k, null_mut(), 6);
        assert_error(status, ZooStatus::NullPointer, "`contacts` is NULL");
        // The controller.
        let status = zoo_control_settings_default(null_mut());
        assert_error(status, ZooStatus::NullPointer, "zoo_control_settings_default: `out` is NULL");
        let mut crunner = null_mut();
        let status = zoo_control_runner_new(null(), 1, &mut crunner);
        assert_error(status, ZooStatus::NullPointer, "zoo_control_runner_new: `model` is NULL");
        let settings = ZooControlSettings { speed_offsets_len: 3, ..default_settings() };
        let mut cchars = null_mut();
        let status = zoo_control_characters_new(h.model, SEEDS.as_ptr(), 3, &settings, &mut cchars);
        assert_error(status, ZooStatus::NullPointer, "`settings.speed_offsets` is NULL");
        let status = zoo_control_start(h.cchars, null(), 3, p, 9);
        assert_error(status, ZooStatus::NullPointer, "`frames` is NULL");
        let controls = [ZooControl::default(); 3];
        assert_error(step.control(null_mut(), h.cchars, &controls), ZooStatus::NullPointer, "`runner` is NULL");
        let status = zoo_control_step(h.crunner, h.cchars, null(), 3, roots, 3, r, 12 * k, c, 6);
        assert_error(status, ZooStatus::NullPointer, "`controls` is NULL");
        zoo_control_characters_free(null_mut());
        zoo_control_runner_free(null_mut());
        zoo_synthesis_characters_free(null_mut());
        zoo_synthesis_runner_free(null_mut());
        zoo_model_free(null_mut());
    }
}

#[test]
fn synthesis_refuses_wrong_sizes() {
    let h = Handles::new(true);
    let (f, p) = (&h.start.0, &h.start.1);
    unsafe {
        let mut mean = vec![0.0f32; h.d + 1];
        let status = zoo_synthesis_mean_frame(h.model, mean.as_mut_ptr(), h.d + 1);
        assert_error(status, ZooStatus::InvalidArgument, "`frame`");
        let mut chars = null_mut();
        let status = zoo_synthesis_characters_new(h.model, SEEDS.as_ptr(), 0, &mut chars);
        assert_error(status, ZooStatus::InvalidArgument, "`count` is 0");
        let status = zoo_synthesis_start(h.chars, f.as_ptr(), f.len() - 1, p.as_ptr(), 9);
        assert_error(status, ZooStatus::InvalidArgument, "`frames`");
        let status = zoo_synthesis_start(h.chars, f.as_ptr(), f.len(), p.as_ptr(), 8);
        assert_error(status, ZooStatus::InvalidArgument, "`placements` holds 8 floats, this call needs 9");
        let mut step = h.step();
        step.roots.pop();
        assert_error(step.synthesis(h.runner, h.chars, 1.0), ZooStatus::InvalidArgument, "`roots`");
        let mut step = h.step();
        step.rotations.pop();
        assert_error(step.synthesis(h.runner, h.chars, 1.0), ZooStatus::InvalidArgument, "`rotations`");
        let mut step = h.step();
        step.contacts.push(0);
        assert_error(step.synthesis(h.runner, h.chars, 1.0), ZooStatus::InvalidArgument, "`contacts`");
        // The controller: settings, seed frames and controls of the wrong size.
        let mut cchars = null_mut();
        let settings = ZooControlSettings { batch: 0, ..default_settings() };
        let status = zoo_control_characters_new(h.model, SEEDS.as_ptr(), 3, &settings, &mut cchars);
        assert_error(status, ZooStatus::InvalidArgument, "batch is 0");
        let one = [2.0f32];
        let settings = ZooControlSettings {
            speed_offsets: one.as_ptr(),
            speed_offsets_len: 1,
            turn_offsets: one.as_ptr(),
            turn_offsets_len: 1,
            ..default_settings()
        };
        let status = zoo_control_characters_new(h.model, SEEDS.as_ptr(), 3, &settings, &mut cchars);
        assert_error(status, ZooStatus::InvalidArgument, "1 candidates");
        let status = zoo_control_start(h.cchars, f.as_ptr(), f.len() - 1, p.as_ptr(), 9);
        assert_error(status, ZooStatus::InvalidArgument, "the same number of seed frames");
        assert_ok(zoo_control_start(h.cchars, f.as_ptr(), f.len(), p.as_ptr(), 9));
        let status = h.step().control(h.crunner, h.cchars, &[ZooControl::default(); 2]);
        assert_error(status, ZooStatus::InvalidArgument, "`controls` holds 2 controls, this call needs 3");
    }
}

#[test]
fn synthesis_refuses_non_finite_input() {
    let h = Handles::new(true);
    let start = &h.start;
    let (mut f, mut p) = start.clone();
    f[7] = f32::NAN;
    p[4] = f32::INFINITY;
    unsafe {
        let status = zoo_synthesis_start(h.chars, f.as_ptr(), f.len(), start.1.as_ptr(), 9);
        assert_error(
            status,
            ZooStatus::InvalidArgument,
            "`frames` holds a non-finite value (NaN) at index 7 (character 0)",
        );
        let status = zoo_synthesis_start(h.chars, start.0.as_ptr(), f.len(), p.as_ptr(), 9);
        assert_error(
            status,
            ZooStatus::InvalidArgument,
            "`placements` holds a non-finite value (inf) at index 4 (character 1)",
        );
        let mut step = h.step();
        assert_error(step.synthesis(h.runner, h.chars, f32::NAN), ZooStatus::InvalidArgument, "temperature");
        assert_error(step.synthesis(h.runner, h.chars, -1.0), ZooStatus::InvalidArgument, "temperature");
        assert!(step.contacts.iter().all(|c| *c == 9), "a refused call writes nothing");
        // The controller: seed frames, a control, settings.
        let status = zoo_control_start(h.cchars, f.as_ptr(), f.len(), start.1.as_ptr(), 9);
        assert_error(status, ZooStatus::InvalidArgument, "non-finite");
        assert_ok(zoo_control_start(h.cchars, start.0.as_ptr(), f.len(), start.1.as_ptr(), 9));
        let nan_speed = ZooControl { speed: f32::NAN, heading: 0.0 };
        let status = step.control(h.crunner, h.cchars, &[ZooControl::default(), nan_speed, ZooControl::default()]);
        assert_error(status, ZooStatus::InvalidArgument, "character 1: control: the target speed is NaN");
        let settings = ZooControlSettings { sigma_heading: f32::NAN, ..default_settings() };
        let mut other = null_mut();
        let status = zoo_control_characters_new(h.model, SEEDS.as_ptr(), 3, &settings, &mut other);
        assert_error(status, ZooStatus::InvalidArgument, "sigma_heading is NaN");
    }
}

#[test]
fn synthesis_and_control_refuse_steps_before_the_start() {
    let h = Handles::new(false);
    let mut step = h.step();
    unsafe {
        let status = step.synthesis(h.runner, h.chars, 1.0);
        assert_error(status, ZooStatus::InvalidState, "call zoo_synthesis_start first");
        let status = step.control(h.crunner, h.cchars, &[ZooControl::default(); 3]);
        assert_error(status, ZooStatus::InvalidState, "call zoo_control_start first");
    }
    assert!(step.contacts.iter().all(|c| *c == 9), "a refused call writes nothing");
}

// The C example.

/// The values of the printed lines tagged `tag`, keyed by their leading indices.
fn tagged<'a>(text: &'a str, tag: &'a str, indices: usize) -> impl Iterator<Item = (Vec<usize>, Vec<f32>)> + 'a {
    text.lines().filter_map(move |line| {
        let mut words = line.split_whitespace();
        (words.next() == Some(tag)).then(|| {
            let index: Vec<usize> = words.by_ref().take(indices).map(|w| w.parse().unwrap()).collect();
            (index, words.map(|w| w.parse().unwrap()).collect())
        })
    })
}

/// The largest difference of `got` from `want`, relative above 1.
fn worst(got: &[f32], want: &[f32]) -> f32 {
    assert_eq!(got.len(), want.len(), "values per line");
    assert!(got.iter().all(|v| v.is_finite()), "the C example printed a non-finite value");
    got.iter().zip(want).map(|(a, b)| (a - b).abs() / b.abs().max(1.0)).fold(0.0, f32::max)
}

/// Compares the lines tagged `tag` (index `[i]` or `[t, c]`) with `want[t][c]` (pose values
/// and contacts); returns the worst difference.
fn compare(text: &str, tag: &str, indices: usize, want: &[Vec<(Vec<f32>, Vec<u8>)>]) -> f32 {
    let mut n = 0;
    let mut w = 0.0f32;
    for (index, values) in tagged(text, tag, indices) {
        let (t, c) = (index[0], index.get(1).copied().unwrap_or(0));
        let (pose, contacts) = &want[t][c];
        let (p, q) = values.split_at(pose.len());
        w = w.max(worst(p, pose));
        assert_eq!(q.iter().map(|v| *v as u8).collect::<Vec<_>>(), *contacts, "{tag} {t} {c}: contacts");
        n += 1;
    }
    assert_eq!(n, want.iter().map(Vec::len).sum::<usize>(), "{tag}: lines printed");
    w
}

#[test]
fn c_example_of_the_other_tasks_matches_the_rust_api_as_c99_and_cpp17() {
    let f = files();
    let tmp = tempfile::tempdir().unwrap();
    let (n, frames) = (3usize, 300usize);
    // The files in any order: the example runs each by its task (and skips the transition model).
    let mut args = vec![n.to_string(), frames.to_string()];
    args.extend([&f.rnngmm, &f.rtn, &f.rmr, &f.arnn].map(|p| p.to_str().unwrap().to_string()));
    let text = capi_examples::run_as_c99_and_cpp17("tasks", tmp.path(), &args);

    // Keys: character 0's 40 frames, then character 1's 31.
    let keyframes = LoadedModel::load(&f.arnn).unwrap().into_keyframes().unwrap();
    let completion = rust_completion(&keyframes);
    let d = keyframes.dofs();
    let mut lines = 0;
    let mut w = 0.0f32;
    for (index, values) in tagged(&text, "keys", 2) {
        let at = if index[0] == 0 { index[1] } else { 40 + index[1] };
        w = w.max(worst(&values, &completion[at * d..(at + 1) * d]));
        lines += 1;
    }
    assert_eq!(lines, 71, "keys: lines printed");
    eprintln!("C example vs Rust API: keys within {w:e}");
    assert!(w <= 1e-5, "keys: worst relative difference {w}");

    let refiner = LoadedModel::load(&f.rmr).unwrap().into_stitch().unwrap();
    let walk = example_walk(&refiner);
    let one_per_frame = |v: Vec<(Vec<f32>, Vec<u8>)>| v.into_iter().map(|x| vec![x]).collect::<Vec<_>>();
    let stitched = compare(&text, "stitch", 1, &one_per_frame(rust_refine(&refiner, &walk, FootCleanup::default())));
    let streamed = compare(&text, "stream", 1, &one_per_frame(rust_stream(&refiner, &walk)));
    let model = LoadedModel::load(&f.rnngmm).unwrap().into_synthesis().unwrap();
    let synthesised = compare(&text, "synth", 2, &rust_synthesis(&model, n, frames));
    let controlled = compare(&text, "control", 2, &rust_control(&model, n, 60));
    eprintln!(
        "C example vs Rust API: stitch {stitched:e}, stream {streamed:e}, {frames} frames x {n} characters synthesised \
         {synthesised:e}, controlled {controlled:e}"
    );
    for (what, w) in [("stitch", stitched), ("stream", streamed), ("synth", synthesised), ("control", controlled)] {
        assert!(w <= 1e-5, "{what}: worst relative difference {w}");
    }
}
