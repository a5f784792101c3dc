//! The C ABI's tasks besides transitions (`crates/capi`): keyframe completion (ARNN),
//! stitching (RMR: the whole sequence and the stream), synthesis (RNN-GMM) and its controller.
//!
//! Where the expected numbers come from: the Rust runtime API (`zoo_runtime::keyframes`,
//! `stitch`, `synthesis`, `control`) run on the same tiny exported models (`zoo_tests::tiny_*`)
//! and the same inputs. Through the C ABI in this process the outputs must be bit-identical (the
//! same code runs underneath); the C example `examples/tasks.c`, compiled with the system C
//! compiler, prints 9 significant digits and must agree within 1e-5 (relative above 1). Every
//! malformed call (NULL handle or buffer, wrong size, NaN, garbage or other-kind file, call out
//! of order) returns its status and a message naming the problem.
// Calling the C ABI from Rust needs raw pointers, as a C caller has.
#![allow(unsafe_code)]

use std::ffi::c_char;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::ptr::{null, null_mut};
use std::sync::OnceLock;
use zoo_capi::*;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
use zoo_runtime::stitch::FootCleanup;
use zoo_runtime::synthesis::SynthesisModel;
use zoo_runtime::{EnginePose, StitchRefiner};
use zoo_tests::capi::{assert_error, assert_ok, c_path, compile_example, pose_values};

/// The model files of these tests, written once per run.
struct Files {
    rtn: PathBuf,
    arnn: PathBuf,
    rmr: PathBuf,
    rnngmm: PathBuf,
    toy: PathBuf,
    garbage: PathBuf,
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
            rmr: write("rmr.onnx", zoo_tests::tiny_rmr_onnx()),
            rnngmm: write("rnngmm.onnx", zoo_tests::tiny_rnngmm_onnx()),
            toy: write("toy.onnx", toy),
            garbage,
        }
    })
}

/// A loader of the C ABI as a closure: the status of loading `path` (into a handle, freed at
/// once, or into a NULL `out` when `with_out` is false).
type Loader = fn(*const c_char, bool) -> ZooStatus;

fn load_with<T>(
    load: unsafe extern "C" fn(*const c_char, *mut *mut T) -> ZooStatus,
    free: unsafe extern "C" fn(*mut T),
    path: *const c_char,
    with_out: bool,
) -> ZooStatus {
    let mut handle = null_mut();
    let status = unsafe { load(path, if with_out { &mut handle } else { null_mut() }) };
    assert_eq!(status == ZooStatus::Ok, !handle.is_null(), "a handle exactly on success");
    unsafe { free(handle) };
    status
}

/// Loads a synthesis model with its refiner (the file's).
unsafe extern "C" fn synthesis_load(path: *const c_char, out: *mut *mut ZooSynthesisModel) -> ZooStatus {
    unsafe { zoo_synthesis_model_load(path, true, out) }
}

/// `load` (the loader of model kind `own`) loads its own kind, refuses every other kind this C
/// ABI loads with `ZOO_STATUS_WRONG_MODEL` and the function that loads it, and refuses missing,
/// garbage and unknown-kind files, a NULL or non-UTF-8 path and a NULL `out`.
fn check_loader(own: &str, load: Loader) {
    let f = files();
    let kinds = [
        ("rtn", &f.rtn, "zoo_model_load"),
        ("arnn", &f.arnn, "zoo_keyframe_model_load"),
        ("rmr", &f.rmr, "zoo_stitch_model_load"),
        ("rnn-gmm", &f.rnngmm, "zoo_synthesis_model_load"),
    ];
    for (kind, path, function) in kinds {
        let status = load(c_path(path).as_ptr(), true);
        if kind == own {
            assert_ok(status);
            assert_error(load(c_path(path).as_ptr(), false), ZooStatus::NullPointer, "`out` is NULL");
        } else {
            assert_error(status, ZooStatus::WrongModel, &format!("(kind `{kind}`), not a"));
            assert_error(status, ZooStatus::WrongModel, &format!("load it with {function}"));
        }
    }
    let missing = f.garbage.with_file_name("missing.onnx");
    assert_error(load(c_path(&missing).as_ptr(), true), ZooStatus::LoadFailed, "missing.onnx");
    assert_error(load(c_path(&f.garbage).as_ptr(), true), ZooStatus::LoadFailed, "not an ONNX model");
    assert_error(load(c_path(&f.toy).as_ptr(), true), ZooStatus::LoadFailed, "unknown model kind `toy_lstm`");
    assert_error(load(null(), true), ZooStatus::NullPointer, "`path` is NULL");
    let bad_utf8 = [0xffu8, 0xfe, 0];
    assert_error(load(bad_utf8.as_ptr().cast::<c_char>(), true), ZooStatus::InvalidArgument, "UTF-8");
}

#[test]
fn the_transition_loader_names_the_loader_of_every_other_kind() {
    check_loader("rtn", |p, o| load_with(zoo_model_load, zoo_model_free, p, o));
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

fn keyframe_model() -> *mut ZooKeyframeModel {
    let mut model = null_mut();
    assert_ok(unsafe { zoo_keyframe_model_load(c_path(&files().arnn).as_ptr(), &mut model) });
    model
}

fn keyframe_runner(model: *const ZooKeyframeModel, max_batch: usize) -> *mut ZooKeyframeRunner {
    let mut runner = null_mut();
    assert_ok(unsafe { zoo_keyframe_runner_new(model, max_batch, &mut runner) });
    runner
}

/// A keyframe model and a runner for batches of up to `max_batch`, freed on drop, and an output
/// buffer of the example's first character (240 floats of 7).
struct Keyframes {
    model: *mut ZooKeyframeModel,
    runner: *mut ZooKeyframeRunner,
    out: Vec<f32>,
}

impl Keyframes {
    fn new(max_batch: usize) -> Self {
        let model = keyframe_model();
        Keyframes { model, runner: keyframe_runner(model, max_batch), out: vec![7.0; 40 * 6] }
    }

    fn untouched(&self) -> bool {
        self.out.iter().all(|v| *v == 7.0)
    }
}

impl Drop for Keyframes {
    fn drop(&mut self) {
        unsafe {
            zoo_keyframe_runner_free(self.runner);
            zoo_keyframe_model_free(self.model);
        }
    }
}

#[test]
fn keyframes_through_the_c_abi_match_the_rust_api() {
    let expected = rust_completion(&KeyframeModel::load(&files().arnn).unwrap());
    unsafe {
        let model = keyframe_model();
        let mut info = ZooKeyframeInfo::default();
        assert_ok(zoo_keyframe_model_info(model, &mut info));
        assert_eq!(info, ZooKeyframeInfo { dofs: 6, groups: 0, fps: zoo_arnn::export::FPS });
        let d = info.dofs;
        let (counts, frames, poses) = example_keys(d);
        let runner = keyframe_runner(model, 2);
        zoo_keyframe_model_free(model); // the runner keeps what it needs
        let mut out = vec![f32::NAN; 71 * d];
        assert_ok(zoo_keyframe_complete_batch(
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
        assert_ok(zoo_keyframe_complete(
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
        zoo_keyframe_runner_free(runner);
    }
}

#[test]
fn keyframe_loader_refuses_garbage_and_other_kinds() {
    check_loader("arnn", |p, o| load_with(zoo_keyframe_model_load, zoo_keyframe_model_free, p, o));
}

impl Keyframes {
    /// [`zoo_keyframe_complete`] of one character's keys into the first `out_len` floats of the
    /// output buffer, `fixed` a pointer and length.
    unsafe fn complete(
        &mut self,
        frames: &[usize],
        poses: &[f32],
        fixed: (*const f32, usize),
        out_len: usize,
    ) -> ZooStatus {
        let out = &mut self.out[..out_len];
        unsafe {
            zoo_keyframe_complete(
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
        let mut info = ZooKeyframeInfo::default();
        assert_error(zoo_keyframe_model_info(null(), &mut info), ZooStatus::NullPointer, "`model` is NULL");
        assert_error(zoo_keyframe_model_info(h.model, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let mut runner = null_mut();
        assert_error(zoo_keyframe_runner_new(null(), 1, &mut runner), ZooStatus::NullPointer, "`model` is NULL");
        assert_error(zoo_keyframe_runner_new(h.model, 1, null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let status = zoo_keyframe_complete(null_mut(), f, 4, p, 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`runner` is NULL");
        let status = zoo_keyframe_complete(h.runner, null(), 4, p, 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`frames` is NULL");
        let status = zoo_keyframe_complete(h.runner, f, 4, null(), 24, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`poses` is NULL");
        let status = zoo_keyframe_complete(h.runner, f, 4, p, 24, null(), 0, null_mut(), 240);
        assert_error(status, ZooStatus::NullPointer, "`out` is NULL");
        // `fixed` may be NULL only with a length of 0.
        let status = h.complete(&frames[..4], &poses[..24], (null(), 4), 240);
        assert_error(status, ZooStatus::NullPointer, "`fixed` is NULL");
        let status = zoo_keyframe_complete_batch(h.runner, null(), 2, f, 7, p, 42, null(), 0, o, 240);
        assert_error(status, ZooStatus::NullPointer, "`key_counts` is NULL");
        zoo_keyframe_runner_free(null_mut());
        zoo_keyframe_model_free(null_mut());
    }
}

#[test]
fn keyframes_refuse_wrong_sizes() {
    let mut h = Keyframes::new(1);
    let (counts, frames, poses) = example_keys(6);
    let (f, p) = (&frames[..4], &poses[..24]);
    unsafe {
        let mut runner = null_mut();
        let status = zoo_keyframe_runner_new(h.model, 0, &mut runner);
        assert_error(status, ZooStatus::InvalidArgument, "`max_batch` is 0");
        let status = h.complete(f, &p[..23], (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "`poses` holds 23 floats, this call needs 24");
        let status = h.complete(f, p, (null(), 0), 239);
        assert_error(status, ZooStatus::InvalidArgument, "`out` holds 239 floats, this call needs 240");
        let flags = [1.0f32; 4];
        assert_error(h.complete(f, p, (flags.as_ptr(), 4), 240), ZooStatus::InvalidArgument, "whole keys only");
        // A batch: key counts that do not add up, none, more characters than the runner takes.
        let mut out = vec![7.0f32; 71 * 6];
        let mut batch = |counts: &[usize], n: usize, len: usize| {
            let (f, p, o) = (frames.as_ptr(), poses.as_ptr(), out.as_mut_ptr());
            zoo_keyframe_complete_batch(h.runner, counts.as_ptr(), n, f, 7, p, 42, null(), 0, o, len)
        };
        let status = batch(&[4, 2], 2, 426);
        assert_error(status, ZooStatus::InvalidArgument, "`key_counts` add up to 6 keys but `frames` holds 7");
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
        assert_error(status, ZooStatus::InvalidArgument, "key 2 is at frame 9 but key 1 is at frame 24");
        let status = h.complete(&[3, 9, 24, 39], p, (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "key frames start at 0");
        let status = h.complete(&[0], &p[..6], (null(), 0), 6);
        assert_error(status, ZooStatus::InvalidArgument, "completion needs at least 2");
        let status = h.complete(&[0, 9, 24, usize::MAX], p, (null(), 0), 240);
        assert_error(status, ZooStatus::InvalidArgument, "too large");
    }
    assert!(h.untouched(), "a refused call writes nothing");
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
    let mut out = vec![EnginePose::new(refiner.joints()); poses.len()];
    let mut contacts = vec![[false; 4]; poses.len()];
    refiner.refine_poses(poses, cleanup, &mut out, &mut contacts).unwrap();
    out.iter().zip(&contacts).map(|(p, c)| (pose_values(p), bytes(c))).collect()
}

/// The Rust API's stream over `poses`: pushing each, popping what is ready, then finishing.
fn rust_stream(refiner: &StitchRefiner, poses: &[EnginePose]) -> Vec<(Vec<f32>, Vec<u8>)> {
    let mut stream = refiner.stream();
    let mut pose = EnginePose::new(refiner.joints());
    let mut got = Vec::new();
    for f in 0..=poses.len() {
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

fn stitch_model() -> *mut ZooStitchModel {
    let mut model = null_mut();
    assert_ok(unsafe { zoo_stitch_model_load(c_path(&files().rmr).as_ptr(), &mut model) });
    model
}

fn stitch_stream(model: *const ZooStitchModel) -> *mut ZooStitchStream {
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
        model: *const ZooStitchModel,
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
        assert_ok(zoo_stitch_model_info(model, &mut info));
        assert_eq!(
            info,
            ZooStitchInfo { joints: 21, window: 30, stride: 15, blend_frames: 10, latency: 29, fps: 30.0 }
        );
        let (mut parents, mut offsets) = (vec![0i32; k], vec![0.0f32; 3 * k]);
        assert_ok(zoo_stitch_model_skeleton(model, parents.as_mut_ptr(), k, offsets.as_mut_ptr(), 3 * k));
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
        zoo_stitch_model_free(model); // the stream keeps what it needs
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
        zoo_stitch_stream_free(stream);
    }
}

#[test]
fn stitch_loader_refuses_garbage_and_other_kinds() {
    check_loader("rmr", |p, o| load_with(zoo_stitch_model_load, zoo_stitch_model_free, p, o));
}

/// A stitching model (freed on drop) and the example's walk as the C ABI takes it: `n` roots
/// and `4K` rotations each.
struct Stitching {
    model: *mut ZooStitchModel,
    roots: Vec<ZooRootMotion>,
    rotations: Vec<f32>,
    n: usize,
    k: usize,
}

impl Stitching {
    fn new() -> Self {
        let refiner = StitchRefiner::load(&files().rmr).unwrap();
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
        unsafe { zoo_stitch_model_free(self.model) };
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
        assert_error(zoo_stitch_model_info(null(), &mut info), ZooStatus::NullPointer, "`model` is NULL");
        let status = zoo_stitch_model_skeleton(model, null_mut(), k, null_mut(), 3 * k);
        assert_error(status, ZooStatus::NullPointer, "`parents` is NULL");
        assert_error(zoo_stitch_model_set_window(null_mut(), 30, 15), ZooStatus::NullPointer, "`model` is NULL");
        let mut out = Refined::new(n, k);
        let status = out.refine(null(), &h.roots, &h.rotations, FootCleanup::default());
        assert_error(status, ZooStatus::NullPointer, "`model` is NULL");
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
        zoo_stitch_model_free(null_mut());
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
        let status = zoo_stitch_model_skeleton(model, p, k - 1, o, 3 * k);
        assert_error(status, ZooStatus::InvalidArgument, "`parents` holds 20 values, this call needs 21");
        assert_error(zoo_stitch_model_skeleton(model, p, k, o, 3 * k + 1), ZooStatus::InvalidArgument, "`offsets`");
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
        let mut pop = Pop::new(k, 1);
        assert_error(pop.pop_with(stream, 4 * k + 1, 4), ZooStatus::InvalidArgument, "`rotations`");
        assert_error(pop.pop_with(stream, 4 * k, 5), ZooStatus::InvalidArgument, "`contacts`");
        assert_ok(pop.pop_with(stream, 4 * k, 4));
        // Planning another window: a stride longer than the window.
        zoo_stitch_stream_free(stream);
        let status = zoo_stitch_model_set_window(model, 20, 30);
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
            "the refined pose of frame 0 is not ready: it is once frame 29 is pushed",
        );
        for f in 0..10 {
            assert_ok(h.push(stream, f));
        }
        assert_error(pop(), ZooStatus::NotAvailable, "zoo_stitch_stream_ready");
        let status = zoo_stitch_stream_finish(stream);
        assert_error(status, ZooStatus::InvalidState, "ends after 10 frames, fewer than the window of 30");
        // Another window while a stream is alive.
        assert_error(zoo_stitch_model_set_window(model, 20, 10), ZooStatus::InvalidState, "free them");
        for f in 10..30 {
            assert_ok(h.push(stream, f));
        }
        assert_ok(zoo_stitch_stream_finish(stream));
        // Pushing after the finish.
        assert_error(h.push(stream, 30), ZooStatus::InvalidState, "the stream is finished");
        for _ in 0..30 {
            assert_ok(pop());
        }
        assert_error(pop(), ZooStatus::NotAvailable, "the finished stream's 30 frames were all popped");
        zoo_stitch_stream_free(stream);
        // Without streams the model plans another window: a shorter latency.
        assert_ok(zoo_stitch_model_set_window(model, 20, 10));
        let mut info = ZooStitchInfo::default();
        assert_ok(zoo_stitch_model_info(model, &mut info));
        assert_eq!((info.window, info.stride, info.latency), (20, 10, 19));
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

fn synthesis_model() -> *mut ZooSynthesisModel {
    let mut model = null_mut();
    assert_ok(unsafe { zoo_synthesis_model_load(c_path(&files().rnngmm).as_ptr(), true, &mut model) });
    model
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
    model: *mut ZooSynthesisModel,
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
            assert_ok(zoo_control_runner_new(model, &mut crunner));
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
            zoo_synthesis_model_free(self.model);
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
        assert_ok(zoo_synthesis_model_info(model, &mut info));
        assert_eq!(info, ZooSynthesisInfo { joints: k, frame_dim: rust.frame_dim(), has_refiner: false, fps: 30.0 });
        let mut mean = vec![0.0f32; info.frame_dim];
        assert_ok(zoo_synthesis_model_mean_frame(model, mean.as_mut_ptr(), mean.len()));
        assert_eq!(mean, start.0[..info.frame_dim]);
        let (mut parents, mut offsets) = (vec![0i32; k], vec![0.0f32; 3 * k]);
        assert_ok(zoo_synthesis_model_skeleton(model, parents.as_mut_ptr(), k, offsets.as_mut_ptr(), 3 * k));
        assert_eq!(parents, rust.model().metadata().skeleton.parents);
        let (mut runner, mut chars) = (null_mut(), null_mut());
        assert_ok(zoo_synthesis_runner_new(model, n, &mut runner));
        assert_ok(zoo_synthesis_characters_new(model, SEEDS.as_ptr(), n, &mut chars));
        zoo_synthesis_model_free(model); // runner and characters keep what they need
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
        assert_ok(zoo_control_runner_new(model, &mut runner));
        assert_ok(zoo_control_characters_new(model, SEEDS.as_ptr(), n, &settings, &mut chars));
        zoo_synthesis_model_free(model);
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
fn synthesis_loader_refuses_garbage_and_other_kinds() {
    check_loader("rnn-gmm", |p, o| load_with(synthesis_load, zoo_synthesis_model_free, p, o));
}

#[test]
fn synthesis_refuses_null_pointers() {
    let h = Handles::new(true);
    let (start, k) = (&h.start, h.k);
    unsafe {
        let mut info = ZooSynthesisInfo::default();
        assert_error(zoo_synthesis_model_info(null(), &mut info), ZooStatus::NullPointer, "`model` is NULL");
        assert_error(zoo_synthesis_model_mean_frame(h.model, null_mut(), 3), ZooStatus::NullPointer, "`frame` is NULL");
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
        assert_error(zoo_control_settings_default(null_mut()), ZooStatus::NullPointer, "`out` is NULL");
        let mut crunner = null_mut();
        assert_error(zoo_control_runner_new(null(), &mut crunner), ZooStatus::NullPointer, "`model` is NULL");
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
        zoo_synthesis_model_free(null_mut());
    }
}

#[test]
fn synthesis_refuses_wrong_sizes() {
    let h = Handles::new(true);
    let (f, p) = (&h.start.0, &h.start.1);
    unsafe {
        let mut mean = vec![0.0f32; h.d + 1];
        let status = zoo_synthesis_model_mean_frame(h.model, mean.as_mut_ptr(), h.d + 1);
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
fn c_example_of_the_other_tasks_matches_the_rust_api() {
    let f = files();
    let tmp = tempfile::tempdir().unwrap();
    let exe = compile_example("tasks", tmp.path());
    let (n, frames) = (3usize, 300usize);
    let run = Command::new(&exe)
        .args([&f.arnn, &f.rmr, &f.rnngmm])
        .arg(n.to_string())
        .arg(frames.to_string())
        .output()
        .unwrap();
    assert!(run.status.success(), "the C example failed:\n{}", String::from_utf8_lossy(&run.stderr));
    let text = String::from_utf8(run.stdout).unwrap();

    // Keys: character 0's 40 frames, then character 1's 31.
    let keyframes = KeyframeModel::load(&f.arnn).unwrap();
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

    let refiner = StitchRefiner::load(&f.rmr).unwrap();
    let walk = example_walk(&refiner);
    let one_per_frame = |v: Vec<(Vec<f32>, Vec<u8>)>| v.into_iter().map(|x| vec![x]).collect::<Vec<_>>();
    let stitched = compare(&text, "stitch", 1, &one_per_frame(rust_refine(&refiner, &walk, FootCleanup::default())));
    let streamed = compare(&text, "stream", 1, &one_per_frame(rust_stream(&refiner, &walk)));
    let model = SynthesisModel::load(&f.rnngmm).unwrap();
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
