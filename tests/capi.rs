//! The C ABI's transitions (`runtime/capi`, `zoo_transition_*`): the C example compiles with the
//! system C compiler as C99 and with the system C++ compiler as C++17, runs a batch of characters
//! for 300 frames and prints what the Rust API computes; every malformed call returns an error
//! code and a readable message that names the C function. (The header is checked by the capi
//! crate's own `tests/header.rs`; the other tasks and the one loader by `tests/capi_tasks.rs`.)
// Calling the C ABI from Rust needs raw pointers, as a C caller has.
#![allow(unsafe_code)]

mod capi_examples;

use std::ffi::{CString, c_char};
use std::path::{Path, PathBuf};
use std::ptr;
use zoo_capi::*;
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::{EnginePose, LoadedModel};
use zoo_tests::capi::{assert_error, last_error, pose_values};

/// The model file of these tests: a tiny RTN on a 4-joint skeleton.
fn model_file(dir: &Path) -> PathBuf {
    let path = dir.join("rtn.onnx");
    zoo_tests::tiny_rtn_onnx().write(&path).unwrap();
    path
}

/// The C example's walk pose of character `c` at frame `f`, built exactly as in C.
fn walk_pose(k: usize, hips_height: f64, speed: f64, c: usize, f: usize) -> EnginePose {
    let mut pose = EnginePose::new(k);
    pose.root_position = Vec3::new((200.0 * c as f64) as f32, 0.0, (speed * f as f64) as f32);
    pose.root_rotation = Quat::IDENTITY;
    pose.hips_position = Vec3::new(0.0, hips_height as f32, 0.0);
    for (j, q) in pose.local_rotations.iter_mut().enumerate() {
        let angle = 0.2 * (0.3 * f as f64 + j as f64 + 0.5 * c as f64).sin();
        *q = Quat::from_xyzw((0.5 * angle).sin() as f32, 0.0, 0.0, (0.5 * angle).cos() as f32);
    }
    pose
}

/// `tests/c/refusals.c`, an engine's mistakes in C: counts of 1<<40, SIZE_MAX and -1, lengths no
/// buffer has, a batch above the runner's `max_batch`, enum values outside their enums, bytes that
/// are not a model: each refused with its status and a message naming the argument, the process
/// alive, nothing on stderr (even with `RUST_BACKTRACE=1`), and a model loaded from memory runs
/// bit-identically to the same file. The program is linked statically, and its stack is not
/// executable (`readelf -lW`: the `GNU_STACK` segment is `RW`).
#[test]
fn refusals_in_c_and_a_model_from_memory() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = model_file(tmp.path());
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("c/refusals.c");
    let exe = zoo_tests::capi::compile_c(&source, tmp.path());
    let out = std::process::Command::new(&exe).arg(&model_path).env("RUST_BACKTRACE", "1").output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "refusals.c failed:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stderr.is_empty(), "the library printed on stderr:\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("memory: identical"), "{stdout}");
    assert_eq!(stdout.lines().filter(|l| l.contains(" ZOO_STATUS_")).count(), 15, "{stdout}");
    let readelf = std::process::Command::new("readelf").arg("-lW").arg(&exe).output();
    let readelf = readelf.expect("readelf is missing: install it with `apt-get install -y binutils`");
    let text = String::from_utf8_lossy(&readelf.stdout);
    let stack = text.lines().find(|l| l.contains("GNU_STACK")).unwrap_or_else(|| panic!("no GNU_STACK:\n{text}"));
    assert!(!stack.contains("RWE"), "the statically linked program has an executable stack: {stack}");
}

#[test]
fn c_example_matches_the_rust_api_as_c99_and_cpp17() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = model_file(tmp.path());
    let (n, total) = (3usize, 300usize);
    let args = [model_path.to_str().unwrap().to_string(), n.to_string(), total.to_string()];
    let text = capi_examples::run_as_c99_and_cpp17("transition", tmp.path(), &args);

    // The same loop through the Rust API.
    let model = LoadedModel::load(&model_path).unwrap().into_transition().unwrap();
    let info = &model.model().metadata().skeleton;
    let k = model.joints();
    let mut rest_y = vec![0.0f64; k];
    let mut lowest = 0.0f64;
    for j in 0..k {
        rest_y[j] =
            if info.parents[j] < 0 { 0.0 } else { rest_y[info.parents[j] as usize] + info.offsets[j][1] as f32 as f64 };
        lowest = lowest.min(rest_y[j]);
    }
    let (hips_height, speed) = (-lowest, 120.0 / model.model().metadata().fps as f64);
    let (past_frames, length) = (model.past_frames(), model.transition_frames());
    let mut runner = model.runner().unwrap();
    let mut states: Vec<_> = (0..n).map(|_| model.new_transition()).collect();
    let mut poses: Vec<EnginePose> = (0..n).map(|_| EnginePose::new(k)).collect();
    let mut lines = text.lines();
    let mut worst = 0.0f32;
    for tick in 0..total {
        if tick % (length + 1) == 0 {
            let past: Vec<EnginePose> = (0..n)
                .flat_map(|c| (0..past_frames).map(move |f| (c, f)))
                .map(|(c, f)| walk_pose(k, hips_height, speed, c, tick + f))
                .collect();
            let t = tick + past_frames + length;
            let target: Vec<EnginePose> = (0..n).map(|c| walk_pose(k, hips_height, speed, c, t)).collect();
            let next: Vec<EnginePose> = (0..n).map(|c| walk_pose(k, hips_height, speed, c, t + 1)).collect();
            runner.start_posed_batch_for(&mut states, &past, &target, &next, length).unwrap();
        }
        runner.step_posed_batch(&mut states, &mut poses).unwrap();
        for (c, p) in poses.iter().enumerate() {
            let line = lines.next().unwrap_or_else(|| panic!("the C example printed no line for frame {tick}"));
            let values: Vec<f32> = line.split_whitespace().map(|v| v.parse().unwrap()).collect();
            assert_eq!((values[0] as usize, values[1] as usize), (tick, c));
            let want = pose_values(p);
            assert_eq!(values.len() - 2, want.len(), "frame {tick} character {c}: values per line");
            for (a, b) in values[2..].iter().zip(&want) {
                worst = worst.max((a - b).abs() / b.abs().max(1.0));
            }
        }
    }
    assert!(lines.next().is_none(), "the C example printed more lines than frames x characters");
    eprintln!("C example vs Rust API: {total} frames x {n} characters, worst relative difference {worst:e}");
    assert!(worst <= 1e-5, "C example vs Rust API: worst relative difference {worst}");
}

/// `zoo_transition_start` with whole buffers.
///
/// # Safety
/// As `zoo_transition_start`.
unsafe fn start_with(
    runner: *mut ZooTransitionRunner,
    chars: *mut ZooTransitionCharacters,
    past: &[f32],
    target: &[f32],
    next: &[f32],
    length: usize,
) -> ZooStatus {
    unsafe {
        zoo_transition_start(
            runner,
            chars,
            past.as_ptr(),
            past.len(),
            target.as_ptr(),
            target.len(),
            next.as_ptr(),
            next.len(),
            length,
        )
    }
}

/// Loads a model through the C ABI.
fn load(path: &Path) -> *mut ZooModel {
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    let mut model = ptr::null_mut();
    assert_eq!(unsafe { zoo_model_load(c_path.as_ptr(), &mut model) }, ZooStatus::Ok, "{}", last_error());
    model
}

#[test]
fn malformed_calls_return_an_error_code_and_a_message() {
    let tmp = tempfile::tempdir().unwrap();
    let path = model_file(tmp.path());
    unsafe {
        // Unknown, unreadable and not-ONNX model files, a bare step graph; a path that is not UTF-8.
        let mut model = ptr::null_mut();
        let missing = CString::new(tmp.path().join("missing.onnx").to_str().unwrap()).unwrap();
        assert_error(zoo_model_load(missing.as_ptr(), &mut model), ZooStatus::LoadFailed, "missing.onnx");
        assert!(model.is_null());
        let text = tmp.path().join("notes.onnx");
        std::fs::write(&text, "not a model").unwrap();
        let text = CString::new(text.to_str().unwrap()).unwrap();
        assert_error(zoo_model_load(text.as_ptr(), &mut model), ZooStatus::LoadFailed, "not an ONNX model");
        let toy = tmp.path().join("toy.onnx");
        zoo_tests::toy_onnx::ToyModel::new(zoo_tests::toy_onnx::Cell::Lstm, 6, 8, 5).cell_graph().write(&toy).unwrap();
        let toy = CString::new(toy.to_str().unwrap()).unwrap();
        assert_error(zoo_model_load(toy.as_ptr(), &mut model), ZooStatus::LoadFailed, "bare step graph with no task");
        let bad_utf8 = [0xffu8, 0xfe, 0];
        assert_error(
            zoo_model_load(bad_utf8.as_ptr().cast::<c_char>(), &mut model),
            ZooStatus::InvalidArgument,
            "zoo_model_load: the path is not UTF-8",
        );
        assert_error(zoo_model_load(ptr::null(), &mut model), ZooStatus::NullPointer, "zoo_model_load: `path` is NULL");
        let c_path = CString::new(path.to_str().unwrap()).unwrap();
        assert_error(zoo_model_load(c_path.as_ptr(), ptr::null_mut()), ZooStatus::NullPointer, "`out` is NULL");

        // Null handles.
        let mut info = ZooTransitionInfo::default();
        let status = zoo_transition_info(ptr::null(), &mut info);
        assert_error(status, ZooStatus::NullPointer, "zoo_transition_info: `model` is NULL");
        assert_eq!(zoo_model_task(ptr::null()), ZooTask::None);
        assert_eq!(last_error(), "zoo_model_task: `model` is NULL; pass a valid pointer");
        let model = load(&path);
        assert_eq!(zoo_model_task(model), ZooTask::Transition);
        assert_eq!(zoo_transition_info(model, &mut info), ZooStatus::Ok);
        assert_error(zoo_transition_info(model, ptr::null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let mut common = ZooModelInfo::default();
        assert_eq!(zoo_model_info(model, &mut common), ZooStatus::Ok);
        let (k, p) = (common.joints, info.transition_frames);
        assert_eq!((k, p), (4, zoo_rtn::Config::tiny().transition_frames));
        let mut runner = ptr::null_mut();
        let status = zoo_transition_runner_new(ptr::null(), 1, &mut runner);
        assert_error(status, ZooStatus::NullPointer, "zoo_transition_runner_new: `model` is NULL");
        assert_eq!(zoo_transition_runner_new(model, 2, &mut runner), ZooStatus::Ok);
        let mut chars = ptr::null_mut();
        let status = zoo_transition_characters_new(model, 0, &mut chars);
        assert_error(status, ZooStatus::InvalidArgument, "zoo_transition_characters_new: `count` is 0");
        assert_eq!(zoo_transition_characters_new(model, 2, &mut chars), ZooStatus::Ok);
        let d = 3 * k;
        let mut poses = vec![0.0f32; 2 * d];
        assert_error(
            zoo_transition_step(ptr::null_mut(), chars, poses.as_mut_ptr(), poses.len()),
            ZooStatus::NullPointer,
            "zoo_transition_step: `runner` is NULL",
        );
        assert_error(
            zoo_transition_step(runner, ptr::null_mut(), poses.as_mut_ptr(), poses.len()),
            ZooStatus::NullPointer,
            "`characters` is NULL",
        );
        assert_error(zoo_transition_step(runner, chars, ptr::null_mut(), 0), ZooStatus::NullPointer, "`poses` is NULL");

        // Stepping before starting: the message names the C functions that start.
        assert_error(
            zoo_transition_step(runner, chars, poses.as_mut_ptr(), poses.len()),
            ZooStatus::InvalidState,
            "zoo_transition_step: character 0: start the transition (zoo_transition_start or zoo_transition_start_posed)",
        );

        // Wrong sizes and NaN.
        let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| ((i * 7 + f * 3) as f32).sin() * 20.0).collect() };
        let past: Vec<f32> = (0..2).flat_map(|_| (0..info.past_frames).flat_map(pose)).collect();
        let (target, next): (Vec<f32>, Vec<f32>) = ([pose(40), pose(40)].concat(), [pose(41), pose(41)].concat());
        let start =
            |past: &[f32], target: &[f32], length: usize| start_with(runner, chars, past, target, &next, length);
        assert_error(start(&past[..past.len() - 1], &target, p), ZooStatus::InvalidArgument, "`past`");
        assert_error(start(&past, &target[..d], p), ZooStatus::InvalidArgument, "`target`");
        let mut with_nan = past.clone();
        with_nan[5] = f32::NAN;
        assert_error(start(&with_nan, &target, p), ZooStatus::InvalidArgument, "non-finite");
        // Longer than trained: refused until allowed, with the C call that allows it.
        let status = start(&past, &target, p + 1);
        assert_error(status, ZooStatus::InvalidState, "zoo_transition_allow_beyond_trained(runner, true)");
        assert!(!last_error().contains("::"), "{}", last_error());
        assert_eq!(zoo_transition_allow_beyond_trained(runner, true), ZooStatus::Ok);
        assert_eq!(start(&past, &target, p + 1), ZooStatus::Ok);
        assert_eq!(zoo_transition_allow_beyond_trained(runner, false), ZooStatus::Ok);
        let status = zoo_transition_allow_beyond_trained(ptr::null_mut(), true);
        assert_error(status, ZooStatus::NullPointer, "`runner` is NULL");
        assert_eq!(start(&past, &target, p), ZooStatus::Ok);
        assert_error(zoo_transition_step(runner, chars, poses.as_mut_ptr(), d), ZooStatus::InvalidArgument, "`poses`");
        let (mut mean, mut max) = (0.0f32, 0.0f32);
        let status = zoo_transition_target_miss(chars, 0, &mut mean, &mut max);
        assert_error(status, ZooStatus::NotAvailable, "blend window");
        let status = zoo_transition_target_miss(chars, 2, &mut mean, &mut max);
        assert_error(status, ZooStatus::InvalidArgument, "character 2 (`index`) does not exist");
        let mut left = 0usize;
        assert_eq!(zoo_transition_frames_left(chars, 1, &mut left), ZooStatus::Ok);
        assert_eq!(left, p + 1);
        assert_error(zoo_transition_frames_left(chars, 1, ptr::null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        for _ in 0..=p {
            let status = zoo_transition_step(runner, chars, poses.as_mut_ptr(), poses.len());
            assert_eq!(status, ZooStatus::Ok, "{}", last_error());
        }
        assert_eq!(zoo_transition_target_miss(chars, 1, &mut mean, &mut max), ZooStatus::Ok);
        assert!(mean.is_finite() && max >= mean);
        // The transition returned its target frame: another step is refused.
        let status = zoo_transition_step(runner, chars, poses.as_mut_ptr(), poses.len());
        assert_error(status, ZooStatus::InvalidState, "target frame");

        // Engine poses: wrong sizes, a transition started from positions.
        let mut roots = vec![ZooRootMotion::default(); 2];
        let mut rotations = vec![0.0f32; 2 * 4 * k];
        assert_eq!(start(&past, &target, p), ZooStatus::Ok);
        assert_error(
            zoo_transition_step_posed(runner, chars, roots.as_mut_ptr(), 2, rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::InvalidState,
            "started from positions (zoo_transition_start); start it with zoo_transition_start_posed",
        );
        assert_error(
            zoo_transition_step_posed(runner, chars, roots.as_mut_ptr(), 1, rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::InvalidArgument,
            "`roots`",
        );
        let identity: Vec<f32> = (0..2 * info.past_frames * k).flat_map(|_| [0.0, 0.0, 0.0, 1.0]).collect();
        let past_roots =
            vec![ZooRootMotion { root_rotation: [0.0, 0.0, 0.0, 1.0], ..Default::default() }; 2 * info.past_frames];
        let start_posed = |rotations_len: usize, past_rotations: &[f32]| {
            zoo_transition_start_posed(
                runner,
                chars,
                past_roots.as_ptr(),
                past_roots.len(),
                past_rotations.as_ptr(),
                past_rotations.len(),
                past_roots.as_ptr(),
                2,
                identity.as_ptr(),
                rotations_len,
                past_roots.as_ptr(),
                2,
                identity.as_ptr(),
                2 * 4 * k,
                p,
            )
        };
        assert_error(
            start_posed(2 * 4 * k - 1, &identity),
            ZooStatus::InvalidArgument,
            "zoo_transition_start_posed: `target_rotations` holds",
        );
        assert_error(
            start_posed(2 * 4 * k, &identity[..identity.len() - 4]),
            ZooStatus::InvalidArgument,
            "`past_rotations`",
        );
        let mut nan = identity.clone();
        nan[3] = f32::NAN;
        assert_error(
            start_posed(2 * 4 * k, &nan),
            ZooStatus::InvalidArgument,
            "`past_rotations` values 0..4 (rotation 0) are [0.0, 0.0, 0.0, NaN], not finite",
        );
        // A zero quaternion is named in the caller's buffer, not reported as a NaN in an
        // internal one.
        let mut zero = identity.clone();
        zero[4 * k + 3] = 0.0;
        assert_error(
            start_posed(2 * 4 * k, &zero),
            ZooStatus::InvalidArgument,
            &format!(
                "`past_rotations` values {}..{} (rotation {k}) are [0.0, 0.0, 0.0, 0.0], a zero quaternion",
                4 * k,
                4 * k + 4
            ),
        );
        assert_eq!(start_posed(2 * 4 * k, &identity), ZooStatus::Ok, "{}", last_error());
        assert_eq!(
            zoo_transition_step_posed(runner, chars, roots.as_mut_ptr(), 2, rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::Ok
        );
        assert!(rotations.iter().all(|v| v.is_finite()));

        // Characters of another model (a terrain-aware RTN of another size would do too) cannot
        // be stepped with this runner.
        let other_path = tmp.path().join("arnn.onnx");
        zoo_tests::tiny_arnn_onnx().write(&other_path).unwrap();
        let other = load(&other_path);
        let mut other_chars = ptr::null_mut();
        let status = zoo_transition_characters_new(other, 2, &mut other_chars);
        assert_error(status, ZooStatus::WrongModel, "use zoo_keyframes_* with this model");
        assert!(other_chars.is_null());
        zoo_model_free(other);

        // The message is truncated to the buffer and NUL-terminated; its full length is returned.
        assert_error(zoo_transition_info(ptr::null(), &mut info), ZooStatus::NullPointer, "NULL");
        let mut small = [1 as c_char; 8];
        let full = zoo_last_error(small.as_mut_ptr(), small.len());
        assert!(full > 7);
        assert_eq!(small[7], 0);
        assert_eq!(std::ffi::CStr::from_ptr(small.as_ptr()).to_bytes().len(), 7);

        // Null frees are no-ops; everything is freed once.
        zoo_transition_characters_free(ptr::null_mut());
        zoo_transition_runner_free(ptr::null_mut());
        zoo_model_free(ptr::null_mut());
        zoo_transition_characters_free(chars);
        zoo_transition_runner_free(runner);
        zoo_model_free(model);
    }
}

/// Every model reports what it is through `zoo_model_info`: the tiny RTN's joints, frame rate,
/// centimetres, Y up, right-handed, format version; its skeleton through `zoo_model_skeleton`.
#[test]
fn model_info_and_skeleton_describe_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let path = model_file(tmp.path());
    let rust = LoadedModel::load(&path).unwrap();
    let meta = rust.metadata();
    assert_eq!(zoo_abi_version(), ZOO_ABI_VERSION);
    unsafe {
        let model = load(&path);
        let mut info = ZooModelInfo::default();
        assert_eq!(zoo_model_info(model, &mut info), ZooStatus::Ok, "{}", last_error());
        assert_eq!(
            info,
            ZooModelInfo {
                task: ZooTask::Transition,
                joints: 4,
                fps: 30.0,
                metres_per_unit: 0.01,
                up_axis: ZooUpAxis::Y,
                handedness: ZooHandedness::Right,
                format_version: zoo_runtime::FORMAT_VERSION,
            }
        );
        let (mut parents, mut offsets) = (vec![7i32; 4], vec![7.0f32; 12]);
        let status = zoo_model_skeleton(model, parents.as_mut_ptr(), 4, offsets.as_mut_ptr(), 12);
        assert_eq!(status, ZooStatus::Ok, "{}", last_error());
        assert_eq!(parents, meta.skeleton.parents);
        assert_eq!(offsets[3 * 2 + 1], meta.skeleton.offsets[2][1] as f32);
        let status = zoo_model_skeleton(model, parents.as_mut_ptr(), 3, offsets.as_mut_ptr(), 12);
        assert_error(status, ZooStatus::InvalidArgument, "`parents` holds 3 values, this call needs 4");
        let status = zoo_model_skeleton(model, parents.as_mut_ptr(), 4, offsets.as_mut_ptr(), 11);
        assert_error(status, ZooStatus::InvalidArgument, "zoo_model_skeleton: `offsets` holds 11 floats");
        let status = zoo_model_skeleton(model, ptr::null_mut(), 4, offsets.as_mut_ptr(), 12);
        assert_error(status, ZooStatus::NullPointer, "`parents` is NULL");
        assert_error(zoo_model_info(model, ptr::null_mut()), ZooStatus::NullPointer, "zoo_model_info: `out` is NULL");
        zoo_model_free(model);
    }
}

/// A `zoo export --portable` pair (main file and start file) loads through the C ABI and
/// reports the regular file's model; without its start file it is refused with a message.
#[test]
fn the_c_abi_loads_a_portable_pair() {
    use zoo_export::portable::{EmbeddedGraph, PortableOptions, to_portable};
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("rtn.onnx");
    let embedded: Vec<EmbeddedGraph<'static>> = zoo_runtime::portable::PORTABLE_GRAPHS
        .iter()
        .map(|g| EmbeddedGraph { key: g.key, file_key: g.file_key, suffix: g.suffix })
        .collect();
    to_portable(&zoo_tests::tiny_rtn_onnx(), &PortableOptions::default(), &embedded).unwrap().write(&path).unwrap();
    let model = load(&path);
    assert!(!model.is_null());
    assert_eq!(unsafe { zoo_model_task(model) }, ZooTask::Transition);
    unsafe { zoo_model_free(model) };
    std::fs::remove_file(tmp.path().join("rtn.start.onnx")).unwrap();
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    let mut model = ptr::null_mut();
    unsafe { assert_error(zoo_model_load(c_path.as_ptr(), &mut model), ZooStatus::LoadFailed, "rtn.start.onnx") };
    assert!(model.is_null());
}

/// A terrain-aware RTN through the C ABI: `zoo_transition_terrain` says so, a character needs
/// its ground before starting (`zoo_transition_set_heightmap`, named in the message), and the
/// transition over a slope equals the Rust runtime's; bad heightmaps are refused.
#[test]
fn terrain_models_take_a_heightmap_through_the_c_abi() {
    use std::sync::Arc;
    use zoo_runtime::Heightmap;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("terrain.onnx");
    zoo_tests::tiny_terrain_rtn_onnx().write(&path).unwrap();
    let rust = LoadedModel::load(&path).unwrap().into_transition().unwrap();
    let (side, extent) = rust.terrain().expect("a terrain-aware model");
    // A slope along x, 20 cm per metre, on a 5 cm grid.
    let (cols, rows, cell, origin) = (81usize, 81usize, 5.0f32, (-200.0f32, -200.0f32));
    let heights: Vec<f32> =
        (0..rows).flat_map(|_| (0..cols).map(move |i| 0.2 * (origin.0 + i as f32 * cell))).collect();
    let map = Heightmap {
        cols,
        rows,
        cell: cell as f64,
        origin: [origin.0 as f64, origin.1 as f64],
        heights: heights.clone(),
    };
    unsafe {
        let model = load(&path);
        let (mut s, mut e) = (0usize, 0f32);
        assert_eq!(zoo_transition_terrain(model, &mut s, &mut e), ZooStatus::Ok, "{}", last_error());
        assert_eq!((s, e), (side, extent));
        let flat = load(&model_file(tmp.path()));
        assert_error(zoo_transition_terrain(flat, &mut s, &mut e), ZooStatus::NotAvailable, "no terrain input");
        assert_error(zoo_transition_terrain(model, ptr::null_mut(), &mut e), ZooStatus::NullPointer, "`side` is NULL");
        zoo_model_free(flat);

        let (mut info, mut common) = (ZooTransitionInfo::default(), ZooModelInfo::default());
        assert_eq!(zoo_transition_info(model, &mut info), ZooStatus::Ok);
        assert_eq!(zoo_model_info(model, &mut common), ZooStatus::Ok);
        let d = 3 * common.joints;
        let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| ((i * 7 + f * 3) as f32).sin() * 20.0 + 90.0).collect() };
        let past: Vec<f32> = (0..info.past_frames).flat_map(pose).collect();
        let (target, next) = (pose(40), pose(41));
        let length = info.transition_frames;
        let (mut runner, mut chars) = (ptr::null_mut(), ptr::null_mut());
        assert_eq!(zoo_transition_runner_new(model, 2, &mut runner), ZooStatus::Ok);
        assert_eq!(zoo_transition_characters_new(model, 1, &mut chars), ZooStatus::Ok);
        let start = |chars| start_with(runner, chars, &past, &target, &next, length);
        assert_error(start(chars), ZooStatus::InvalidState, "(zoo_transition_set_heightmap) before starting");
        assert!(!last_error().contains("::"), "{}", last_error());

        // Bad heightmaps.
        let set = |index, cols, rows, cell, heights: &[f32]| {
            zoo_transition_set_heightmap(
                chars,
                index,
                cols,
                rows,
                cell,
                origin.0,
                origin.1,
                heights.as_ptr(),
                heights.len(),
            )
        };
        assert_error(set(0, 0, rows, cell, &heights), ZooStatus::InvalidArgument, "at least 1 x 1");
        assert_error(set(0, cols, rows, cell, &heights[1..]), ZooStatus::InvalidArgument, "`heights`");
        assert_error(set(0, cols, rows, 0.0, &heights), ZooStatus::InvalidArgument, "`cell`");
        let mut nan = heights.clone();
        nan[7] = f32::NAN;
        assert_error(set(0, cols, rows, cell, &nan), ZooStatus::InvalidArgument, "height 7");
        assert_error(set(1, cols, rows, cell, &heights), ZooStatus::InvalidArgument, "character 1 (`index`)");
        let status = zoo_transition_set_heightmap(chars, 0, cols, rows, cell, f32::NAN, 0.0, heights.as_ptr(), 6561);
        assert_error(status, ZooStatus::InvalidArgument, "`origin_x` NaN");
        assert_error(
            zoo_transition_set_heightmap(
                ptr::null_mut(),
                0,
                cols,
                rows,
                cell,
                0.0,
                0.0,
                heights.as_ptr(),
                heights.len(),
            ),
            ZooStatus::NullPointer,
            "zoo_transition_set_heightmap: `characters` is NULL",
        );
        assert_error(
            zoo_transition_set_heightmap(chars, 0, cols, rows, cell, 0.0, 0.0, ptr::null(), 5),
            ZooStatus::NullPointer,
            "`heights` is NULL",
        );

        // The ground set: the transition equals the Rust runtime's with the same map.
        assert_eq!(set(0, cols, rows, cell, &heights), ZooStatus::Ok, "{}", last_error());
        assert_eq!(start(chars), ZooStatus::Ok, "{}", last_error());
        let mut got = Vec::new();
        let mut frame = vec![0.0f32; d];
        for _ in 0..=length {
            let status = zoo_transition_step(runner, chars, frame.as_mut_ptr(), frame.len());
            assert_eq!(status, ZooStatus::Ok, "{}", last_error());
            got.extend_from_slice(&frame);
        }
        let mut state = rust.new_transition();
        state.set_heightmap(Some(Arc::new(map)));
        let mut want = vec![0.0f32; (length + 1) * d];
        rust.runner().unwrap().generate(&mut state, &past, &target, &next, &mut want).unwrap();
        assert_eq!(got, want, "the C ABI's terrain transition differs from the Rust runtime's");
        // Removing the ground makes the next start fail again.
        let status = zoo_transition_set_heightmap(chars, 0, 0, 0, 0.0, 0.0, 0.0, ptr::null(), 0);
        assert_eq!(status, ZooStatus::Ok);
        assert_error(start(chars), ZooStatus::InvalidState, "zoo_transition_set_heightmap");
        zoo_transition_characters_free(chars);
        zoo_transition_runner_free(runner);
        zoo_model_free(model);
    }
}

/// A transition begun and fed frame by frame through the C ABI (`zoo_transition_begin_posed`,
/// `zoo_transition_feed_posed`) gives the engine poses `zoo_transition_start_posed` gives for the
/// same context, bit for bit, at batch 3; feeding with nothing due and a context of 0 frames are
/// refused.
#[test]
fn a_transition_fed_per_frame_through_the_c_abi_equals_one_started_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let path = model_file(tmp.path());
    let (n, k) = (3usize, 4usize);
    let pose = |c: usize, f: usize| walk_pose(k, 90.0, 4.0, c, f);
    unsafe {
        let model = load(&path);
        let mut info = ZooTransitionInfo::default();
        assert_eq!(zoo_transition_info(model, &mut info), ZooStatus::Ok);
        let (past, length) = (info.past_frames, info.transition_frames);
        let (mut runner, mut a, mut b) = (ptr::null_mut(), ptr::null_mut(), ptr::null_mut());
        assert_eq!(zoo_transition_runner_new(model, n, &mut runner), ZooStatus::Ok);
        assert_eq!(zoo_transition_characters_new(model, n, &mut a), ZooStatus::Ok);
        assert_eq!(zoo_transition_characters_new(model, n, &mut b), ZooStatus::Ok);
        let buffers = |poses: &[EnginePose]| engine_buffers(poses, k);
        let context: Vec<EnginePose> = (0..n).flat_map(|c| (0..past).map(move |f| pose(c, f))).collect();
        let (target, next): (Vec<EnginePose>, Vec<EnginePose>) =
            (0..n).map(|c| (pose(c, past + length), pose(c, past + length + 1))).unzip();
        let (cr, cq) = buffers(&context);
        let (tr, tq) = buffers(&target);
        let (xr, xq) = buffers(&next);
        let status = zoo_transition_start_posed(
            runner,
            a,
            cr.as_ptr(),
            cr.len(),
            cq.as_ptr(),
            cq.len(),
            tr.as_ptr(),
            n,
            tq.as_ptr(),
            tq.len(),
            xr.as_ptr(),
            n,
            xq.as_ptr(),
            xq.len(),
            length,
        );
        assert_eq!(status, ZooStatus::Ok, "{}", last_error());
        let frame = |f: usize| buffers(&(0..n).map(|c| pose(c, f)).collect::<Vec<_>>());
        let (fr, fq) = frame(0);
        let status = zoo_transition_begin_posed(
            runner,
            b,
            fr.as_ptr(),
            n,
            fq.as_ptr(),
            fq.len(),
            tr.as_ptr(),
            n,
            tq.as_ptr(),
            tq.len(),
            xr.as_ptr(),
            n,
            xq.as_ptr(),
            xq.len(),
            0,
            length,
        );
        assert_error(status, ZooStatus::InvalidArgument, "zoo_transition_begin_posed: `past_frames` is 0");
        let status = zoo_transition_begin_posed(
            runner,
            b,
            fr.as_ptr(),
            n,
            fq.as_ptr(),
            fq.len(),
            tr.as_ptr(),
            n,
            tq.as_ptr(),
            tq.len(),
            xr.as_ptr(),
            n,
            xq.as_ptr(),
            xq.len(),
            past,
            length,
        );
        assert_eq!(status, ZooStatus::Ok, "{}", last_error());
        for f in 1..past {
            let (fr, fq) = frame(f);
            assert_eq!(zoo_transition_feed_posed(runner, b, fr.as_ptr(), n, fq.as_ptr(), fq.len()), ZooStatus::Ok);
        }
        let status = zoo_transition_feed_posed(runner, b, fr.as_ptr(), n, fq.as_ptr(), fq.len());
        assert_error(
            status,
            ZooStatus::InvalidState,
            "no context frame is due: begin a transition (zoo_transition_begin",
        );
        let (mut ra, mut qa) = (vec![ZooRootMotion::default(); n], vec![0.0f32; n * 4 * k]);
        let (mut rb, mut qb) = (vec![ZooRootMotion::default(); n], vec![0.0f32; n * 4 * k]);
        for f in 0..=length {
            assert_eq!(
                zoo_transition_step_posed(runner, a, ra.as_mut_ptr(), n, qa.as_mut_ptr(), qa.len()),
                ZooStatus::Ok
            );
            assert_eq!(
                zoo_transition_step_posed(runner, b, rb.as_mut_ptr(), n, qb.as_mut_ptr(), qb.len()),
                ZooStatus::Ok
            );
            assert!(ra == rb && qa == qb, "frame {f}: the fed transition differs from the started one");
        }
        zoo_transition_characters_free(a);
        zoo_transition_characters_free(b);
        zoo_transition_runner_free(runner);
        zoo_model_free(model);
    }
}

/// Engine poses as C roots and `4K` rotation values per root.
fn engine_buffers(poses: &[EnginePose], k: usize) -> (Vec<ZooRootMotion>, Vec<f32>) {
    let mut roots = vec![ZooRootMotion::default(); poses.len()];
    let mut rotations = vec![0.0f32; poses.len() * 4 * k];
    for (i, p) in poses.iter().enumerate() {
        write_engine_pose(p, &mut roots[i], &mut rotations[i * 4 * k..(i + 1) * 4 * k]);
    }
    (roots, rotations)
}

/// An engine pose as a C root and `4K` rotation values.
fn write_engine_pose(p: &EnginePose, root: &mut ZooRootMotion, rotations: &mut [f32]) {
    *root = ZooRootMotion {
        root_position: p.root_position.to_array(),
        root_rotation: p.root_rotation.to_array(),
        hips_position: p.hips_position.to_array(),
        ..Default::default()
    };
    for (out, q) in rotations.chunks_exact_mut(4).zip(&p.local_rotations) {
        out.copy_from_slice(&q.to_array());
    }
}

/// One behaviour wherever a transition runs: a whole transition in engine poses with the model's
/// calibrated fallback and the foot lock, through the runtime (`generate_posed_batch`, what the
/// Python package and the Blender add-on call), the C ABI (`zoo_transition_generate_posed`) and
/// `zoo transition --in-place --foot-lock` on the same clip frames. The C ABI gives the runtime's
/// poses bit for bit; the CLI's clip (written to BVH at 6 decimals) the same joint positions
/// within 0.01 cm. The fallback moves the transition (its weight strictly between 0 and 1 here),
/// and without the fallback and the lock the whole transition is the one stepped frame by frame.
#[test]
fn a_whole_posed_transition_with_fallback_and_foot_lock_is_the_same_in_the_runtime_c_and_the_cli() {
    use zoo_runtime::{TransitionRunner, TransitionState};
    let tmp = tempfile::tempdir().unwrap();
    let bvh = tmp.path().join("clip.bvh");
    zoo_data::bvh::write_file(&zoo_tests::synth_biped_clip(0), &bvh).unwrap();
    let clip = zoo_data::bvh::read_file(&bvh, &zoo_data::bvh::ReadOptions::default()).unwrap();
    let k = clip.joints();
    let pose = |f: usize| {
        let rot: Vec<Quat> = clip.rotations_at(f).iter().map(|q| q.as_quat().normalize()).collect();
        EnginePose::from_world(clip.root_position(f).as_vec3(), &rot)
    };
    let (from, to, length) = (40usize, 100usize, 30usize);
    let past: Vec<EnginePose> = (from - 10..from).map(pose).collect();
    let (target, next) = (vec![pose(to)], vec![pose(to + 1)]);
    let generate = |runner: &mut TransitionRunner, state: &mut TransitionState| {
        let mut out: Vec<EnginePose> = (0..=length).map(|_| EnginePose::with_global_positions(k)).collect();
        runner.generate_posed_batch(std::slice::from_mut(state), &past, &target, &next, length, &mut out).unwrap();
        out
    };
    // Thresholds around this seeded model's own miss, so that the fallback blends partly.
    let plain = LoadedModel::from_bytes(&zoo_tests::biped_rtn_onnx(&clip, false, None)).unwrap();
    let plain = plain.into_transition().unwrap();
    let mut state = plain.new_transition();
    let unlocked = generate(&mut plain.runner().unwrap(), &mut state);
    let miss = state.target_miss().unwrap().mean;
    let fallback = zoo_rtn::fallback::Fallback { start: 0.5 * miss, full: 1.5 * miss };
    let bytes = zoo_tests::biped_rtn_onnx(&clip, false, Some(fallback));
    let model_path = tmp.path().join("rtn.onnx");
    std::fs::write(&model_path, &bytes).unwrap();
    let model = LoadedModel::from_bytes(&bytes).unwrap().into_transition().unwrap();

    // Without the fallback and the lock: the frames of a stepped transition.
    let mut runner = model.runner().unwrap();
    let mut stepped = model.new_transition();
    runner.start_posed_batch_for(std::slice::from_mut(&mut stepped), &past, &target, &next, length).unwrap();
    let mut p = EnginePose::with_global_positions(k);
    for want in &unlocked {
        runner.step_posed(&mut stepped, &mut p).unwrap();
        assert_eq!(pose_values(&p), pose_values(want));
        assert_eq!(p.global_positions, want.global_positions);
    }

    // The runtime with the model's fallback and the default lock.
    runner.set_model_fallback();
    runner.set_foot_lock(model.default_foot_lock());
    let mut state = model.new_transition();
    let locked = generate(&mut runner, &mut state);
    let w = state.fallback_weight();
    assert!(w > 0.0 && w < 1.0, "fallback weight {w} (miss {miss})");
    let moved = unlocked
        .iter()
        .zip(&locked)
        .flat_map(|(a, b)| a.global_positions.iter().zip(&b.global_positions).map(|(p, q)| p.distance(*q)))
        .fold(0.0f32, f32::max);
    assert!(moved > 0.1, "the fallback and the lock moved the transition by {moved} cm only");

    // The C ABI, the same inputs: bit for bit.
    unsafe {
        let model = load(&model_path);
        let (mut runner, mut chars) = (ptr::null_mut(), ptr::null_mut());
        assert_eq!(zoo_transition_runner_new(model, 1, &mut runner), ZooStatus::Ok);
        assert_eq!(zoo_transition_characters_new(model, 1, &mut chars), ZooStatus::Ok);
        let buffers = |poses: &[EnginePose]| engine_buffers(poses, k);
        let ((pr, pq), (tr, tq), (xr, xq)) = (buffers(&past), buffers(&target), buffers(&next));
        let mut roots = vec![ZooRootMotion::default(); length + 1];
        let mut rotations = vec![0.0f32; (length + 1) * 4 * k];
        let call = |fallback: u8, lock: u8, roots: &mut [ZooRootMotion], rotations: &mut [f32]| {
            zoo_transition_generate_posed(
                runner,
                chars,
                pr.as_ptr(),
                pr.len(),
                pq.as_ptr(),
                pq.len(),
                tr.as_ptr(),
                1,
                tq.as_ptr(),
                tq.len(),
                xr.as_ptr(),
                1,
                xq.as_ptr(),
                xq.len(),
                length,
                fallback,
                lock,
                roots.as_mut_ptr(),
                roots.len(),
                rotations.as_mut_ptr(),
                rotations.len(),
            )
        };
        assert_error(
            call(2, 1, &mut roots, &mut rotations),
            ZooStatus::InvalidArgument,
            "zoo_transition_generate_posed: `fallback` is 2",
        );
        assert_error(
            call(1, 1, &mut roots[..length], &mut rotations),
            ZooStatus::InvalidArgument,
            "zoo_transition_generate_posed: `out_roots`",
        );
        assert_eq!(call(1, 1, &mut roots, &mut rotations), ZooStatus::Ok, "{}", last_error());
        for (f, want) in locked.iter().enumerate() {
            let (mut r, mut q) = (ZooRootMotion::default(), vec![0.0f32; 4 * k]);
            write_engine_pose(want, &mut r, &mut q);
            assert_eq!(roots[f].root_position, r.root_position, "frame {f}");
            assert_eq!(roots[f].hips_position, r.hips_position, "frame {f}");
            assert_eq!(&rotations[f * 4 * k..(f + 1) * 4 * k], &q[..], "frame {f}");
        }
        zoo_transition_characters_free(chars);
        zoo_transition_runner_free(runner);
        zoo_model_free(model);
    }

    // The CLI on the clip: the transition replaces frames `from..from + length` of the output.
    let out = tmp.path().join("out.bvh");
    let status = std::process::Command::new(zoo_tests::zoo_bin())
        .args(["transition", "--model"])
        .arg(&model_path)
        .arg("--from")
        .arg(format!("{}:{from}", bvh.display()))
        .arg("--to")
        .arg(format!("{}:{to}", bvh.display()))
        .args(["--frames", &length.to_string(), "--foot-lock", "--in-place", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let written = zoo_data::bvh::read_file(&out, &zoo_data::bvh::ReadOptions::default()).unwrap();
    let (_, global) = written.global();
    let mut worst = 0.0f64;
    for (i, want) in locked[..length].iter().enumerate() {
        for (j, q) in want.global_positions.iter().enumerate() {
            worst = worst.max(global[(from + i) * k + j].distance(q.as_dvec3()));
        }
    }
    eprintln!("zoo transition --in-place --foot-lock against the runtime's posed transition: {worst:.2e} cm");
    assert!(worst < 0.01, "the CLI's transition is {worst} cm from the runtime's");
}
