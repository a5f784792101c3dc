//! The C ABI (`crates/capi`): its header is what cbindgen generates from the source, the C
//! example compiles with the system C compiler, runs a batch of characters for 300 frames and
//! prints what the Rust API computes, and every malformed call returns an error code and a
//! readable message.
// Calling the C ABI from Rust needs raw pointers, as a C caller has.
#![allow(unsafe_code)]

use std::ffi::{CString, c_char};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::ptr;
use zoo_capi::*;
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::{EnginePose, TransitionModel};
use zoo_tests::capi::{assert_error, capi_dir, compile_example, last_error, pose_values};

/// The model file of these tests: a tiny RTN on a 4-joint skeleton.
fn model_file(dir: &Path) -> PathBuf {
    let path = dir.join("rtn.onnx");
    zoo_tests::tiny_rtn_onnx().write(&path).unwrap();
    path
}

#[test]
fn header_is_up_to_date() {
    let dir = capi_dir();
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    // cbindgen follows lib.rs's `mod` declarations into the task modules.
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let header = dir.join("include/zoo.h");
    if std::env::var_os("ZOO_BLESS_HEADER").is_some() {
        std::fs::write(&header, &generated).unwrap();
    }
    let committed = std::fs::read(&header).unwrap_or_default();
    assert!(
        committed == generated,
        "crates/capi/include/zoo.h is not what cbindgen generates from crates/capi/src; regenerate it with \
         `ZOO_BLESS_HEADER=1 cargo test --workspace --test capi header_is_up_to_date` and commit it"
    );
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

#[test]
fn c_example_matches_the_rust_api() {
    let tmp = tempfile::tempdir().unwrap();
    let model_path = model_file(tmp.path());
    let exe = compile_example("transition", tmp.path());
    let (n, total) = (3usize, 300usize);
    let run = Command::new(&exe).arg(&model_path).arg(n.to_string()).arg(total.to_string()).output().unwrap();
    assert!(run.status.success(), "the C example failed:\n{}", String::from_utf8_lossy(&run.stderr));
    let text = String::from_utf8(run.stdout).unwrap();

    // The same loop through the Rust API.
    let model = TransitionModel::load(&model_path).unwrap();
    let info = &model.model().metadata().skeleton;
    let k = model.joints();
    let mut rest_y = vec![0.0f64; k];
    let mut lowest = 0.0f64;
    for j in 0..k {
        rest_y[j] =
            if info.parents[j] < 0 { 0.0 } else { rest_y[info.parents[j] as usize] + info.offsets[j][1] as f64 };
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

/// `zoo_start` with whole buffers.
///
/// # Safety
/// As `zoo_start`.
unsafe fn start_with(
    runner: *mut ZooRunner,
    chars: *mut ZooCharacters,
    past: &[f32],
    target: &[f32],
    next: &[f32],
    length: usize,
) -> ZooStatus {
    unsafe {
        zoo_start(
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

/// Loads the test model through the C ABI.
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
        // Unknown, unreadable, not-ONNX and wrong-task model files; a path that is not UTF-8.
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
        assert_error(zoo_model_load(toy.as_ptr(), &mut model), ZooStatus::LoadFailed, "unknown model kind");
        let bad_utf8 = [0xffu8, 0xfe, 0];
        assert_error(
            zoo_model_load(bad_utf8.as_ptr().cast::<c_char>(), &mut model),
            ZooStatus::InvalidArgument,
            "UTF-8",
        );
        assert_error(zoo_model_load(ptr::null(), &mut model), ZooStatus::NullPointer, "`path` is NULL");
        let c_path = CString::new(path.to_str().unwrap()).unwrap();
        assert_error(zoo_model_load(c_path.as_ptr(), ptr::null_mut()), ZooStatus::NullPointer, "`out` is NULL");

        // Null handles.
        let mut info = ZooModelInfo::default();
        assert_error(zoo_model_info(ptr::null(), &mut info), ZooStatus::NullPointer, "`model` is NULL");
        let model = load(&path);
        assert_eq!(zoo_model_info(model, &mut info), ZooStatus::Ok);
        let (k, p) = (info.joints, info.transition_frames);
        assert_eq!((k, p), (4, zoo_rtn::Config::tiny().transition_frames));
        let mut runner = ptr::null_mut();
        assert_error(zoo_runner_new(ptr::null(), &mut runner), ZooStatus::NullPointer, "`model` is NULL");
        assert_eq!(zoo_runner_new(model, &mut runner), ZooStatus::Ok);
        let mut chars = ptr::null_mut();
        assert_error(zoo_characters_new(model, 0, &mut chars), ZooStatus::InvalidArgument, "`count` is 0");
        assert_eq!(zoo_characters_new(model, 2, &mut chars), ZooStatus::Ok);
        let d = 3 * k;
        let mut poses = vec![0.0f32; 2 * d];
        assert_error(
            zoo_step(ptr::null_mut(), chars, poses.as_mut_ptr(), poses.len()),
            ZooStatus::NullPointer,
            "`runner` is NULL",
        );
        assert_error(
            zoo_step(runner, ptr::null_mut(), poses.as_mut_ptr(), poses.len()),
            ZooStatus::NullPointer,
            "`characters` is NULL",
        );
        assert_error(zoo_step(runner, chars, ptr::null_mut(), 0), ZooStatus::NullPointer, "`poses` is NULL");

        // Stepping before starting.
        assert_error(zoo_step(runner, chars, poses.as_mut_ptr(), poses.len()), ZooStatus::InvalidState, "start");

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
        // Longer than trained: refused until allowed.
        assert_error(start(&past, &target, p + 1), ZooStatus::InvalidState, "allow_beyond_trained");
        assert_eq!(zoo_runner_allow_beyond_trained(runner, true), ZooStatus::Ok);
        assert_eq!(start(&past, &target, p + 1), ZooStatus::Ok);
        assert_eq!(zoo_runner_allow_beyond_trained(runner, false), ZooStatus::Ok);
        assert_eq!(start(&past, &target, p), ZooStatus::Ok);
        assert_error(zoo_step(runner, chars, poses.as_mut_ptr(), d), ZooStatus::InvalidArgument, "`poses`");
        let (mut mean, mut max) = (0.0f32, 0.0f32);
        assert_error(zoo_target_miss(chars, 0, &mut mean, &mut max), ZooStatus::NotAvailable, "blend window");
        assert_error(zoo_target_miss(chars, 2, &mut mean, &mut max), ZooStatus::InvalidArgument, "character 2");
        let mut left = 0usize;
        assert_eq!(zoo_frames_left(chars, 1, &mut left), ZooStatus::Ok);
        assert_eq!(left, p + 1);
        for _ in 0..=p {
            assert_eq!(zoo_step(runner, chars, poses.as_mut_ptr(), poses.len()), ZooStatus::Ok, "{}", last_error());
        }
        assert_eq!(zoo_target_miss(chars, 1, &mut mean, &mut max), ZooStatus::Ok);
        assert!(mean.is_finite() && max >= mean);
        // The transition returned its target frame: another step is refused.
        assert_error(zoo_step(runner, chars, poses.as_mut_ptr(), poses.len()), ZooStatus::InvalidState, "target frame");

        // Engine poses: wrong sizes, a transition started from positions.
        let mut roots = vec![ZooRootMotion::default(); 2];
        let mut rotations = vec![0.0f32; 2 * 4 * k];
        assert_eq!(start(&past, &target, p), ZooStatus::Ok);
        assert_error(
            zoo_step_posed(runner, chars, roots.as_mut_ptr(), roots.len(), rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::InvalidState,
            "start_posed",
        );
        assert_error(
            zoo_step_posed(runner, chars, roots.as_mut_ptr(), 1, rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::InvalidArgument,
            "`roots`",
        );
        let identity: Vec<f32> = (0..2 * info.past_frames * k).flat_map(|_| [0.0, 0.0, 0.0, 1.0]).collect();
        let past_roots =
            vec![ZooRootMotion { root_rotation: [0.0, 0.0, 0.0, 1.0], ..Default::default() }; 2 * info.past_frames];
        let start_posed = |rotations_len: usize, past_rotations: &[f32]| {
            zoo_start_posed(
                runner,
                chars,
                past_roots.as_ptr(),
                past_roots.len(),
                past_rotations.as_ptr(),
                past_rotations.len(),
                past_roots.as_ptr(),
                identity.as_ptr(),
                past_roots.as_ptr(),
                identity.as_ptr(),
                rotations_len,
                p,
            )
        };
        assert_error(start_posed(2 * 4 * k - 1, &identity), ZooStatus::InvalidArgument, "rotations_len");
        assert_error(
            start_posed(2 * 4 * k, &identity[..identity.len() - 4]),
            ZooStatus::InvalidArgument,
            "past_rotations",
        );
        let mut nan = identity.clone();
        nan[3] = f32::NAN;
        assert_error(start_posed(2 * 4 * k, &nan), ZooStatus::InvalidArgument, "non-finite");
        assert_eq!(start_posed(2 * 4 * k, &identity), ZooStatus::Ok, "{}", last_error());
        assert_eq!(
            zoo_step_posed(runner, chars, roots.as_mut_ptr(), roots.len(), rotations.as_mut_ptr(), rotations.len()),
            ZooStatus::Ok
        );
        assert!(rotations.iter().all(|v| v.is_finite()));

        // The message is truncated to the buffer and NUL-terminated; its full length is returned.
        assert_error(zoo_model_info(ptr::null(), &mut info), ZooStatus::NullPointer, "NULL");
        let mut small = [1 as c_char; 8];
        let full = zoo_last_error(small.as_mut_ptr(), small.len());
        assert!(full > 7);
        assert_eq!(small[7], 0);
        assert_eq!(std::ffi::CStr::from_ptr(small.as_ptr()).to_bytes().len(), 7);

        // Null frees are no-ops; everything is freed once.
        zoo_characters_free(ptr::null_mut());
        zoo_runner_free(ptr::null_mut());
        zoo_model_free(ptr::null_mut());
        zoo_characters_free(chars);
        zoo_runner_free(runner);
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
    unsafe { zoo_model_free(model) };
    std::fs::remove_file(tmp.path().join("rtn.start.onnx")).unwrap();
    let c_path = CString::new(path.to_str().unwrap()).unwrap();
    let mut model = ptr::null_mut();
    unsafe { assert_error(zoo_model_load(c_path.as_ptr(), &mut model), ZooStatus::LoadFailed, "rtn.start.onnx") };
    assert!(model.is_null());
}

/// A terrain-aware RTN through the C ABI: `zoo_model_terrain` says so, a character needs its
/// ground before starting (`zoo_characters_set_heightmap`, named in the message), and the
/// transition over a slope equals the Rust runtime's; bad heightmaps are refused.
#[test]
fn terrain_models_take_a_heightmap_through_the_c_abi() {
    use std::sync::Arc;
    use zoo_runtime::Heightmap;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("terrain.onnx");
    zoo_tests::tiny_terrain_rtn_onnx().write(&path).unwrap();
    let rust = TransitionModel::load(&path).unwrap();
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
        assert_eq!(zoo_model_terrain(model, &mut s, &mut e), ZooStatus::Ok, "{}", last_error());
        assert_eq!((s, e), (side, extent));
        let flat = load(&model_file(tmp.path()));
        assert_error(zoo_model_terrain(flat, &mut s, &mut e), ZooStatus::NotAvailable, "no terrain input");
        zoo_model_free(flat);

        let mut info = ZooModelInfo::default();
        assert_eq!(zoo_model_info(model, &mut info), ZooStatus::Ok);
        let d = 3 * info.joints;
        let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| ((i * 7 + f * 3) as f32).sin() * 20.0 + 90.0).collect() };
        let past: Vec<f32> = (0..info.past_frames).flat_map(pose).collect();
        let (target, next) = (pose(40), pose(41));
        let length = info.transition_frames;
        let (mut runner, mut chars) = (ptr::null_mut(), ptr::null_mut());
        assert_eq!(zoo_runner_new(model, &mut runner), ZooStatus::Ok);
        assert_eq!(zoo_characters_new(model, 1, &mut chars), ZooStatus::Ok);
        let start = |chars| start_with(runner, chars, &past, &target, &next, length);
        assert_error(start(chars), ZooStatus::InvalidState, "zoo_characters_set_heightmap");

        // Bad heightmaps.
        let set = |index, cols, rows, cell, heights: &[f32]| {
            zoo_characters_set_heightmap(
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
        assert_error(set(1, cols, rows, cell, &heights), ZooStatus::InvalidArgument, "character 1 does not exist");
        assert_error(
            zoo_characters_set_heightmap(
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
            "`characters` is NULL",
        );
        assert_error(
            zoo_characters_set_heightmap(chars, 0, cols, rows, cell, 0.0, 0.0, ptr::null(), 5),
            ZooStatus::NullPointer,
            "`heights` is NULL",
        );

        // The ground set: the transition equals the Rust runtime's with the same map.
        assert_eq!(set(0, cols, rows, cell, &heights), ZooStatus::Ok, "{}", last_error());
        assert_eq!(start(chars), ZooStatus::Ok, "{}", last_error());
        let mut got = Vec::new();
        let mut frame = vec![0.0f32; d];
        for _ in 0..=length {
            assert_eq!(zoo_step(runner, chars, frame.as_mut_ptr(), frame.len()), ZooStatus::Ok, "{}", last_error());
            got.extend_from_slice(&frame);
        }
        let mut state = rust.new_transition();
        state.set_heightmap(Some(Arc::new(map)));
        let mut want = vec![0.0f32; (length + 1) * d];
        rust.runner().unwrap().generate(&mut state, &past, &target, &next, &mut want).unwrap();
        assert_eq!(got, want, "the C ABI's terrain transition differs from the Rust runtime's");
        // Removing the ground makes the next start fail again.
        assert_eq!(zoo_characters_set_heightmap(chars, 0, 0, 0, 0.0, 0.0, 0.0, ptr::null(), 0), ZooStatus::Ok);
        assert_error(start(chars), ZooStatus::InvalidState, "zoo_characters_set_heightmap");
        zoo_characters_free(chars);
        zoo_runner_free(runner);
        zoo_model_free(model);
    }
}
