//! Parity of the exported RMR refiner: candle (`zoo-rmr`), tract and onnxruntime (through
//! `ort`, `load-dynamic`) refine the same windows with every refiner cell.
//!
//! Where the expected numbers come from: candle's `Rmr::forward` in evaluation mode (no
//! dropout) on batch-first windows; the ONNX graph takes the same windows time-major (layout 0).
//! Weights are the seeded initial weights of `Config::tiny()` (residual decoder; its output
//! layer is not zeroed here, so the correction is not 0; the absolute decoder is checked too) (`zoo_nn::SeededVarMap`, seed
//! 7), inputs fixed LCG draws. Every pair of runtimes must agree within 1e-4 (normalised units)
//! on every value. The snapshots hold the BGRU graph summary and candle's outputs for the
//! first frames, rounded to 4 decimals.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use std::borrow::Cow;
use zoo_export::OnnxModel;
use zoo_rmr::export::{MODEL_KIND, export_rmr, export_run};
use zoo_rmr::features::FeatureStats;
use zoo_rmr::{Config, RefinerCell, Rmr};
use zoo_tests::onnxruntime::ort_environment;
use zoo_tests::toy_onnx::lcg;

const BATCH: usize = 3;
const FRAMES: usize = 12;
const TOLERANCE: f32 = 1e-4;

struct Fixture {
    config: Config,
    varmap: VarMap,
    model: Rmr,
    stats: FeatureStats,
}

fn fixture(cell: RefinerCell) -> Fixture {
    fixture_of(Config::tiny().with_cell(cell))
}

fn fixture_of(config: Config) -> Fixture {
    let varmap = VarMap::new();
    let vb = zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu);
    let model = Rmr::new(&config, vb).unwrap();
    let d = config.dim();
    let stats = FeatureStats { mean: lcg(3, d, 1.0), std: lcg(4, d, 1.0).iter().map(|v| 1.5 + v).collect() };
    Fixture { config, varmap, model, stats }
}

/// Batch-first input `[batch][frame][value]`, flattened.
fn input(d: usize) -> Vec<f32> {
    lcg(11, BATCH * FRAMES * d, 2.0)
}

/// `[a][b][v]` -> `[b][a][v]`.
fn swap01(x: &[f32], a: usize, b: usize, d: usize) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    for i in 0..a {
        for j in 0..b {
            out[(j * a + i) * d..(j * a + i + 1) * d].copy_from_slice(&x[(i * b + j) * d..(i * b + j + 1) * d]);
        }
    }
    out
}

/// Candle's output, time-major.
fn candle_run(f: &Fixture, x: &[f32]) -> Vec<f32> {
    let d = f.config.dim();
    let xs = Tensor::from_slice(x, (BATCH, FRAMES, d), &Device::Cpu).unwrap();
    let y: Vec<f32> = f.model.forward(&xs, None).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    swap01(&y, BATCH, FRAMES, d)
}

fn tract_run(exported: &OnnxModel, x_tm: &[f32], d: usize) -> Vec<f32> {
    use tract_onnx::prelude::*;
    let mut model =
        tract_onnx::onnx().model_for_read(&mut exported.to_bytes().as_slice()).expect("tract reads the RMR graph");
    model.set_input_fact(0, f32::fact([FRAMES, BATCH, d]).into()).unwrap();
    let plan = model.into_optimized().expect("tract optimises the RMR graph").into_runnable().unwrap();
    let x = Tensor::from_shape::<f32>(&[FRAMES, BATCH, d], x_tm).unwrap();
    let inputs: TVec<TValue> = std::iter::once(TValue::from_const(std::sync::Arc::new(x))).collect();
    let out = plan.run(inputs).expect("tract runs the RMR graph");
    out[0].try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec()
}

fn ort_run(onnx: &OnnxModel, x_tm: &[f32], d: usize) -> Vec<f32> {
    ort_run_batch(onnx, x_tm, d, BATCH)
}

/// onnxruntime's output for `batch` time-major windows `x_tm` (`[FRAMES, batch, d]`).
fn ort_run_batch(onnx: &OnnxModel, x_tm: &[f32], d: usize, batch: usize) -> Vec<f32> {
    let mut session = ort::session::Session::builder(ort_environment())
        .unwrap()
        .with_intra_threads(1)
        .unwrap()
        .commit_from_memory(&onnx.to_bytes())
        .expect("onnxruntime loads the RMR graph");
    let t = ort::value::Tensor::from_array((vec![FRAMES as i64, batch as i64, d as i64], x_tm.to_vec())).unwrap();
    let inputs: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = vec![(Cow::Borrowed("x"), t.into())];
    let out = session.run(inputs).expect("onnxruntime runs the RMR graph");
    out["y"].try_extract_tensor::<f32>().unwrap().1.to_vec()
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn check(cell: RefinerCell) -> (Fixture, OnnxModel, Vec<f32>) {
    check_config(Config::tiny().with_cell(cell))
}

/// Exports `config`'s seeded model and compares candle, tract and onnxruntime.
fn check_config(config: Config) -> (Fixture, OnnxModel, Vec<f32>) {
    let cell = config.cell;
    let f = fixture_of(config);
    let d = f.config.dim();
    let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
    let x = input(d);
    let x_tm = swap01(&x, BATCH, FRAMES, d);
    let c = candle_run(&f, &x);
    let t = tract_run(&onnx, &x_tm, d);
    let o = ort_run(&onnx, &x_tm, d);
    for (pair, diff) in [
        ("candle-tract", max_abs_diff(&c, &t)),
        ("candle-ort", max_abs_diff(&c, &o)),
        ("tract-ort", max_abs_diff(&t, &o)),
    ] {
        println!("{cell:?} {pair}: max |diff| {diff:e}");
        assert!(diff <= TOLERANCE, "{cell:?} {pair}: max |diff| {diff} > {TOLERANCE}");
    }
    (f, onnx, c)
}

#[test]
fn rmr_bgru_refiner_parity() {
    let (f, onnx, c) = check(RefinerCell::Bgru);
    insta::assert_json_snapshot!("rmr_bgru_graph", onnx.summary());
    let d = f.config.dim();
    let rounded: Vec<Vec<f64>> = (0..2)
        .map(|t| c[t * BATCH * d..t * BATCH * d + 12].iter().map(|v| (*v as f64 * 1e4).round() / 1e4).collect())
        .collect();
    insta::assert_json_snapshot!("rmr_bgru_outputs", rounded);
}

#[test]
fn rmr_other_cells_parity() {
    for cell in [RefinerCell::Lstm, RefinerCell::Gru, RefinerCell::Blstm] {
        let (_, onnx, _) = check(cell);
        let ops = &onnx.summary().op_counts;
        let want = if matches!(cell, RefinerCell::Lstm | RefinerCell::Blstm) { "LSTM" } else { "GRU" };
        assert_eq!(ops.get(want), Some(&2), "{cell:?}: {ops:?}");
    }
    // The paper's absolute decoder: no residual Mul/Add.
    let (_, onnx, _) = check_config(Config::tiny().with_residual(false));
    assert_eq!(onnx.summary().op_counts.get("Mul"), None);
}

#[test]
fn rmr_metadata_and_run_folder_export() {
    let f = fixture(RefinerCell::Bgru);
    let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
    assert_eq!(onnx.metadata_value("zoo.model_kind"), Some(MODEL_KIND));
    let config: Config = serde_json::from_str(onnx.metadata_value("zoo.config").unwrap()).unwrap();
    assert_eq!(config, f.config);
    // The runtime reads the typed stitch section, never the training config.
    let m = zoo_format::MotionModelMetadata::read(&onnx.to_bytes(), "rmr.onnx").unwrap();
    let task = m.task.as_stitch().expect("an RMR is a stitch model");
    assert_eq!(
        (task.window, task.stride, task.blend_frames),
        (f.config.window, f.config.stride, f.config.blend_frames)
    );
    assert_eq!(task.layout, f.config.layout);
    assert_eq!(
        m.normalization["x"],
        zoo_format::MotionMeanStd { mean: f.stats.mean.clone(), std: f.stats.std.clone() }
    );
    assert_eq!(m.skeleton.offsets, f.config.offsets);
    assert!(m.state.is_empty());
    let dir = tempfile::tempdir().unwrap();
    zoo_rmr::checkpoint::save(dir.path(), &f.config, &f.varmap, &f.stats).unwrap();
    let from_dir = export_run(dir.path(), &Default::default()).unwrap();
    assert_eq!(from_dir.to_bytes(), onnx.to_bytes(), "a run folder exports the same file");
    let bad = FeatureStats { mean: vec![0.0; 3], std: vec![1.0; 3] };
    let err = export_rmr(&f.config, &bad, &f.varmap).unwrap_err().to_string();
    assert!(err.contains("statistics have 3 values"), "{err}");
    let err = export_run(&dir.path().join("nope"), &Default::default()).unwrap_err().to_string();
    assert!(err.contains("nope"), "{err}");
}

/// The runtime's stitching task (`zoo_runtime::StitchRefiner`, tract) refines a whole sequence
/// like the offline `zoo_rmr::stitch::refine_sequence` (candle): several windows with the
/// blend, the same seeded weights and statistics, raw pose vectors in and out.
#[test]
fn runtime_stitch_refiner_matches_candle() {
    use zoo_rmr::stitch::{RefineOptions, refine_sequence};
    use zoo_runtime::StitchRefiner;
    let f = fixture(RefinerCell::Bgru);
    let d = f.config.dim();
    let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
    let refiner = StitchRefiner::from_bytes(&onnx.to_bytes()).unwrap();
    assert_eq!((refiner.window(), refiner.stride(), refiner.blend_frames()), (30, 15, 10));
    assert_eq!((refiner.dim(), refiner.joints(), refiner.fps()), (d, 21, 30.0));
    let frames = 77; // windows at 0, 15, 30, 45 and 47
    assert_eq!(refiner.window_starts(frames), vec![0, 15, 30, 45, 47]);
    let pose = d - 4;
    let mut x = lcg(21, frames * d, 3.0);
    for (i, v) in x.iter_mut().enumerate() {
        if i % d >= pose {
            *v = (*v > 0.0) as u8 as f32;
        }
    }
    let offline = refine_sequence(&f.model, &f.stats, &x, RefineOptions::of(&f.config)).unwrap();
    let mut runtime = vec![0.0; x.len()];
    refiner.refine_sequence(&x, &mut runtime).unwrap();
    let worst = offline
        .iter()
        .zip(&runtime)
        .enumerate()
        .filter(|(i, _)| i % d < pose)
        .map(|(i, (a, b))| (a - b).abs() / f.stats.std[i % d])
        .fold(0.0, f32::max);
    println!("runtime stitch vs candle: max |diff| {worst:e} (normalised units, {frames} frames)");
    assert!(worst <= TOLERANCE, "max |diff| {worst} in normalised units");
    let flips = (0..x.len()).filter(|i| i % d >= pose && offline[*i] != runtime[*i]).count();
    assert_eq!(flips, 0, "contacts agree");
    // Another window.
    let mut wide = refiner.clone();
    wide.set_window(60, 30).unwrap();
    let offline =
        refine_sequence(&f.model, &f.stats, &x, RefineOptions { window: 60, stride: 30, blend_frames: 10 }).unwrap();
    wide.refine_sequence(&x, &mut runtime).unwrap();
    let worst = (0..x.len())
        .filter(|i| i % d < pose)
        .map(|i| (offline[i] - runtime[i]).abs() / f.stats.std[i % d])
        .fold(0.0, f32::max);
    assert!(worst <= TOLERANCE, "window 60: max |diff| {worst}");
}

/// The fallback towards the refiner's input (`stitch.fallback`, calibrated by `zoo train rmr`)
/// acts in the runtime as in candle's `refine_sequence`: thresholds around the seeded model's
/// own correction sizes so that windows are partly blended back, whole sequence and without it.
#[test]
fn runtime_stitch_fallback_matches_candle() {
    use zoo_rmr::fallback::{Fallback, correction_size};
    use zoo_rmr::features::FeatureLayout;
    use zoo_rmr::stitch::{RefineOptions, refine_sequence};
    use zoo_runtime::StitchRefiner;
    let plain = fixture(RefinerCell::Bgru);
    let d = plain.config.dim();
    let fl = FeatureLayout::new(plain.config.joints, plain.config.layout.lower_body.len());
    let frames = 77;
    let pose = d - 4;
    let mut x = lcg(23, frames * d, 3.0);
    for (i, v) in x.iter_mut().enumerate() {
        if i % d >= pose {
            *v = (*v > 0.0) as u8 as f32;
        }
    }
    // The correction size of the first window (normalised), and thresholds around it.
    let mut first = x[..30 * d].to_vec();
    plain.stats.normalize(&mut first);
    let size = correction_size(&first, &plain.model.refine(&first).unwrap(), fl);
    assert!(size > 0.0);
    let fallback = Fallback { start: 0.5 * size, full: 1.5 * size };
    let mut config = plain.config.clone();
    config.fallback = Some(fallback);
    let f = fixture_of(config);
    let refiner = StitchRefiner::from_bytes(&export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes()).unwrap();
    assert_eq!(refiner.fallback(), Some(fallback));
    assert!(!refiner.pre_blend());
    let worst = |a: &[f32], b: &[f32]| {
        (0..a.len()).filter(|i| i % d < pose).map(|i| (a[i] - b[i]).abs() / f.stats.std[i % d]).fold(0.0, f32::max)
    };
    let offline = refine_sequence(&f.model, &f.stats, &x, RefineOptions::of(&f.config)).unwrap();
    let mut runtime = vec![0.0; x.len()];
    refiner.refine_sequence(&x, &mut runtime).unwrap();
    let diff = worst(&offline, &runtime);
    println!("runtime stitch with the fallback vs candle: max |diff| {diff:e}");
    assert!(diff <= TOLERANCE, "max |diff| {diff}");
    // The fallback changed the output, and without it both are the network alone again.
    let mut alone = f.model.clone();
    alone.set_fallback(None);
    let offline_alone = refine_sequence(&alone, &f.stats, &x, RefineOptions::of(&f.config)).unwrap();
    assert!(worst(&offline, &offline_alone) > 1e-2, "the fallback acted");
    let mut runtime_alone = refiner.clone();
    runtime_alone.set_fallback(None).unwrap();
    runtime_alone.refine_sequence(&x, &mut runtime).unwrap();
    assert!(worst(&offline_alone, &runtime) <= TOLERANCE);
    // Thresholds that are not thresholds are refused.
    let err = runtime_alone.set_fallback(Some(Fallback { start: 2.0, full: 1.0 })).unwrap_err().to_string();
    assert!(err.contains("start <= full"), "{err}");
}

/// Bad input to the runtime's stitching task: clear errors, no panic.
#[test]
fn runtime_stitch_refiner_refuses_bad_input() {
    use zoo_runtime::StitchRefiner;
    let f = fixture(RefinerCell::Gru);
    let d = f.config.dim();
    let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
    let mut refiner = StitchRefiner::from_bytes(&onnx.to_bytes()).unwrap();
    // An RTN (a `transition` model) where an RMR is expected.
    let rtn = zoo_tests::tiny_rtn_onnx();
    let err = StitchRefiner::from_bytes(&rtn.to_bytes()).unwrap_err().to_string();
    assert!(err.contains("`transition` model (kind `rtn`), not a `stitch` model"), "{err}");
    assert!(err.contains("runs with TransitionModel"), "{err}");
    let err = StitchRefiner::from_bytes(b"\x01\x02garbage").unwrap_err().to_string();
    assert!(err.contains("not an ONNX model"), "{err}");
    // A sequence shorter than the window, a partial frame, a short output buffer, NaN.
    let x = vec![0.5f32; 20 * d];
    let mut out = vec![0.0; x.len()];
    let err = refiner.refine_sequence(&x, &mut out).unwrap_err().to_string();
    assert!(err.contains("the window of 30 frames is longer than the sequence (20 frames)"), "{err}");
    let err = refiner.refine_sequence(&x[..d + 3], &mut out[..d + 3]).unwrap_err().to_string();
    assert!(err.contains(&format!("{d}")), "{err}");
    let x = vec![0.5f32; 40 * d];
    let err = refiner.refine_sequence(&x, &mut out).unwrap_err().to_string();
    assert!(err.contains("expected"), "{err}");
    let mut nan = x.clone();
    nan[7] = f32::NAN;
    let mut out = vec![0.0; x.len()];
    let err = refiner.refine_sequence(&nan, &mut out).unwrap_err().to_string();
    assert!(err.contains("non-finite"), "{err}");
    let err = refiner.set_window(20, 30).unwrap_err().to_string();
    assert!(err.contains("stride must be in 1..=window"), "{err}");
    refiner.refine_sequence(&x, &mut out).unwrap();
}

/// Two synthetic clips (walk and run of the default synthetic data) aligned end to start, as
/// engine poses, and the same motion as a clip rebuilt from those `f32` poses (so that the
/// offline path and the runtime read identical input).
fn aligned_poses(frames: usize) -> (Vec<zoo_runtime::EnginePose>, zoo_motion::Clip) {
    use zoo_rmr::pairs::{StitchLayout, align_clips};
    let cfg = zoo_data::synth::SynthConfig { minutes: 0.5, seed: 5, clip_seconds: 4.0, ..Default::default() };
    let clips: Vec<zoo_motion::Clip> = zoo_data::synth::generate(&cfg).into_iter().map(|c| c.clip).collect();
    let layout = StitchLayout::bandai2(&clips[0].skeleton).unwrap();
    // Two clips; more after them for longer sequences (the first 130 frames are the same).
    let parts = [clips[0].slice(10, 70), clips[3].slice(20, 90), clips[1].slice(0, 110), clips[2].slice(5, 115)];
    let aligned = align_clips(&parts, &layout, 10).unwrap().clip;
    let clip = aligned.slice(0, frames);
    let j = clip.joints();
    let poses: Vec<zoo_runtime::EnginePose> = (0..frames)
        .map(|f| {
            let rotations: Vec<glam::Quat> = clip.rotations_at(f).iter().map(|q| q.as_quat()).collect();
            zoo_runtime::EnginePose::from_world(clip.root_position(f).as_vec3(), &rotations)
        })
        .collect();
    let mut rebuilt = clip.clone();
    for (f, p) in poses.iter().enumerate() {
        rebuilt.local_rotations[f * j] = p.hips_world_rotation().as_dquat();
        for k in 1..j {
            rebuilt.local_rotations[f * j + k] = p.local_rotations[k].normalize().as_dquat();
        }
        rebuilt.local_positions[f * j] = p.hips_world().as_dvec3();
    }
    (poses, rebuilt)
}

/// Global joint positions of engine poses on `skeleton`.
fn world_positions(poses: &[zoo_runtime::EnginePose], skeleton: &zoo_motion::Skeleton) -> Vec<glam::DVec3> {
    let j = skeleton.len();
    let mut clip = zoo_motion::Clip {
        skeleton: skeleton.clone(),
        frame_time: 1.0 / 30.0,
        local_rotations: Vec::new(),
        local_positions: Vec::new(),
    };
    for p in poses {
        clip.local_rotations.push(p.hips_world_rotation().as_dquat());
        clip.local_rotations.extend(p.local_rotations[1..].iter().map(|q| q.normalize().as_dquat()));
        clip.local_positions.push(p.hips_world().as_dvec3());
        clip.local_positions.extend_from_slice(&skeleton.offsets[1..j]);
    }
    clip.global().1
}

fn max_distance(a: &[glam::DVec3], b: &[glam::DVec3]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| (*p - *q).length()).fold(0.0, f64::max)
}

/// The runtime's pose path (`StitchRefiner::encode_poses`, `refine_poses`: encoding, tract,
/// decoding, ankles placed and feet locked) against the offline one (`zoo_rmr::features`,
/// candle's `refine_clip_full`, `place_ankles`, `lock_feet`: what `zoo stitch` writes).
#[test]
fn runtime_refines_engine_poses_like_zoo_stitch() {
    use zoo_rmr::footlock::{lock_feet, place_ankles};
    use zoo_rmr::stitch::{RefineOptions, refine_clip_full};
    use zoo_runtime::stitch::FootCleanup;
    use zoo_runtime::{EnginePose, StitchRefiner};
    let mut f = fixture(RefinerCell::Bgru);
    let (poses, clip) = aligned_poses(100);
    let layout = &f.config.layout;
    // Statistics of real pose vectors (the fixture's random ones decode to quaternions far
    // from unit length, whose normalisation magnifies float differences).
    let offline_x = zoo_rmr::features::encode_clip(&clip, layout).unwrap();
    f.stats = FeatureStats::fit([offline_x.as_slice()], zoo_rmr::features::FeatureLayout::new(21, 9));
    let refiner = StitchRefiner::from_bytes(&export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes()).unwrap();
    // Encoding.
    let d = refiner.dim();
    let mut x = vec![0.0f32; poses.len() * d];
    refiner.encode_poses(&poses, &mut x).unwrap();
    let worst = x.iter().zip(&offline_x).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    println!("encode_poses vs zoo_rmr encode_clip: max |diff| {worst:e}");
    assert!(worst <= 1e-4, "encoding differs by {worst}");
    // Refinement alone, then with the foot cleanup of `zoo stitch`.
    let mut refined = refine_clip_full(&f.model, &f.stats, &clip, RefineOptions::of(&f.config)).unwrap();
    let mut out = vec![EnginePose::new(refiner.joints()); poses.len()];
    let mut contacts = vec![[false; 4]; poses.len()];
    refiner.refine_poses(&poses, FootCleanup::NONE, &mut out, &mut contacts).unwrap();
    let worst = max_distance(&world_positions(&out, refiner.skeleton()), &refined.clip.global().1);
    println!("refine_poses vs zoo_rmr (candle, no cleanup): max joint distance {worst:e} cm over 100 frames");
    assert!(worst <= 1e-3, "joint positions differ by {worst} cm");
    let plain = world_positions(&out, refiner.skeleton());
    place_ankles(&mut refined.clip, &refined.ankles, layout);
    lock_feet(&mut refined.clip, &refined.contacts, layout);
    refiner.refine_poses(&poses, FootCleanup::default(), &mut out, &mut contacts).unwrap();
    let worst = max_distance(&world_positions(&out, refiner.skeleton()), &refined.clip.global().1);
    let moved = max_distance(&world_positions(&out, refiner.skeleton()), &plain);
    println!(
        "refine_poses vs zoo_rmr (candle, ankles and lock): max joint distance {worst:e} cm over 100 frames (the \
         cleanup moved joints by up to {moved:.2} cm)"
    );
    // Two-bone IK of a nearly straight leg (in f32) magnifies the 1e-4 cm above: 0.1 cm, far
    // below what the cleanup itself moves.
    assert!(worst <= 0.1, "joint positions differ by {worst} cm");
    assert!(moved > 1.0, "the cleanup moved joints by only {moved} cm");
    assert_eq!(contacts, refined.contacts, "predicted contacts agree");
    // Root deltas chain the root transforms.
    for w in out.windows(2) {
        let (p, yaw) = zoo_runtime::pose::root_delta(
            w[0].root_position,
            w[0].root_rotation,
            w[1].root_position,
            w[1].root_rotation,
        );
        assert!((p - w[1].root_delta_position).length() < 1e-4 && (yaw - w[1].root_delta_yaw).abs() < 1e-5);
    }
}

/// Streams `poses` (seams marked before the frames in `seams`) through a stream with `cleanup`
/// and the seam guard `guard`, popping every frame as soon as it is ready; checks the fixed
/// latency on every push and returns the poses and contacts.
fn stream_all(
    refiner: &zoo_runtime::StitchRefiner,
    poses: &[zoo_runtime::EnginePose],
    seams: &[usize],
    cleanup: zoo_runtime::stitch::FootCleanup,
    guard: bool,
) -> (Vec<zoo_runtime::EnginePose>, Vec<[bool; 4]>) {
    let mut stream = refiner.stream();
    // Each window on the schedule alone, as a loaded machine runs it: the latest its frames are
    // refined (a window run ahead of schedule only makes them ready sooner).
    stream.set_run_ahead(false);
    stream.set_cleanup(cleanup).unwrap();
    stream.set_seam_guard(guard).unwrap();
    let latency = stream.latency();
    let (mut got, mut contacts) = (Vec::new(), Vec::new());
    let mut pose = zoo_runtime::EnginePose::new(refiner.joints());
    for (t, p) in poses.iter().enumerate() {
        if seams.contains(&t) {
            stream.mark_seam();
        }
        stream.push(p).unwrap();
        // Ready exactly `latency` frames after: frame t - latency once frame t is pushed.
        while let Some(c) = stream.pop(&mut pose).unwrap() {
            got.push(pose.clone());
            contacts.push(c);
        }
        assert_eq!(got.len(), (t + 1).saturating_sub(latency), "after pushing frame {t}");
    }
    stream.finish().unwrap();
    while let Some(c) = stream.pop(&mut pose).unwrap() {
        got.push(pose.clone());
        contacts.push(c);
    }
    assert_eq!(got.len(), poses.len());
    (got, contacts)
}

/// The streaming form gives the whole-sequence form's poses with a fixed latency: `w` frames
/// for the refiner alone (value for value: no later window revisits a popped frame), `w +`
/// lookahead `+` chunk `- 1` with the ankle IK and the foot lock of `zoo stitch`. Without
/// seams, with the seams' reach off (a stream with a reach passes motion without seams through).
#[test]
fn stitch_stream_matches_the_whole_sequence_with_fixed_latency() {
    use zoo_runtime::stitch::{FootCleanup, STREAM_CHUNK, STREAM_LOOKAHEAD};
    use zoo_runtime::{EnginePose, StitchRefiner};
    let f = fixture(RefinerCell::Bgru);
    let mut refiner =
        StitchRefiner::from_bytes(&export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes()).unwrap();
    let (w, s) = (refiner.window(), refiner.stride());
    assert_eq!(refiner.seam_reach(), Some(w), "the seams' reach is on by default, as in `zoo stitch`");
    refiner.set_seam_reach(None).unwrap();
    let mut stream = refiner.stream();
    // Each window's network work is spread over the `s - 1` pushes after it is due, one push
    // more for a marked seam's frame, encoded one push late.
    let spread = s - 1;
    assert_eq!(stream.latency(), w + spread + STREAM_LOOKAHEAD + STREAM_CHUNK - 1, "the default: IK, guard and lock");
    stream.set_cleanup(FootCleanup::NONE).unwrap();
    stream.set_seam_guard(false).unwrap();
    assert_eq!(stream.latency(), w + spread, "the refiner alone");
    let j = refiner.joints();
    let skeleton = refiner.skeleton();
    for frames in [w + 4 * s, w + 4 * s + 7, 120, 340] {
        let (poses, _) = aligned_poses(frames);
        for cleanup in [FootCleanup::NONE, FootCleanup { place_ankles: true, lock_feet: false }, FootCleanup::default()]
        {
            let mut whole = vec![EnginePose::new(j); frames];
            let mut whole_contacts = vec![[false; 4]; frames];
            refiner.refine_poses(&poses, cleanup, &mut whole, &mut whole_contacts).unwrap();
            let (got, contacts) = stream_all(&refiner, &poses, &[], cleanup, cleanup.lock_feet);
            let (a, b) = (world_positions(&got, skeleton), world_positions(&whole, skeleton));
            let frame = |t: usize| max_distance(&a[t * j..(t + 1) * j], &b[t * j..(t + 1) * j]);
            let worst = (0..frames).map(frame).fold(0.0, f64::max);
            println!("stream vs whole sequence, {frames} frames, {cleanup:?}: max joint distance {worst:e} cm");
            assert_eq!(contacts, whole_contacts, "contacts agree");
            // The lock of a frame reads the frames within its reach, which the stream holds.
            assert!(worst <= 1e-4, "{frames} frames, {cleanup:?}: the stream differs by {worst} cm");
        }
    }
}

/// The BGRU fixture with statistics of 100 aligned frames (two synthetic clips), those frames
/// as engine poses and as a clip, and its exported refiner.
fn seam_fixture() -> (Fixture, Vec<zoo_runtime::EnginePose>, zoo_motion::Clip, zoo_runtime::StitchRefiner) {
    let mut f = fixture(RefinerCell::Bgru);
    let (poses, clip) = aligned_poses(100);
    let offline_x = zoo_rmr::features::encode_clip(&clip, &f.config.layout).unwrap();
    f.stats = FeatureStats::fit([offline_x.as_slice()], zoo_rmr::features::FeatureLayout::new(21, 9));
    let bytes = export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes();
    let refiner = zoo_runtime::StitchRefiner::from_bytes(&bytes).unwrap();
    (f, poses, clip, refiner)
}

/// `zoo stitch --pre-blend`: the runtime inertializes the seams it is given before refining,
/// as the offline tools do, in the whole-sequence form and in the stream (`mark_seam`). The
/// seams: the real one at frame 60 where the second clip starts, two adjacent ones and one
/// near the end.
#[test]
fn runtime_inertializes_the_seams_like_zoo_stitch_pre_blend() {
    use zoo_rmr::stitch::{PostProcess, RefineOptions, refine_seams};
    use zoo_runtime::EnginePose;
    use zoo_runtime::stitch::FootCleanup;
    let (f, poses, clip, mut refiner) = seam_fixture();
    // The refiner alone here (the stream has no guard); the guard's parity is the next test's.
    assert!(refiner.seam_guard(), "the guard is on by default, as in `zoo stitch`");
    refiner.set_seam_guard(false);
    let seams = [30, 31, 60, 97];
    let post = PostProcess {
        ankle_ik: false,
        foot_lock: false,
        pre_blend: true,
        seam_guard: false,
        keep_untouched: true,
        reach: None,
    };
    let want = refine_seams(&f.model, &f.stats, &clip, &seams, RefineOptions::of(&f.config), post).unwrap();
    let (n, j) = (poses.len(), refiner.joints());
    let mut out = vec![EnginePose::new(j); n];
    let mut contacts = vec![[false; 4]; n];
    refiner.refine_poses_at_seams(&poses, &seams, FootCleanup::NONE, &mut out, &mut contacts).unwrap();
    let skeleton = refiner.skeleton();
    let whole = world_positions(&out, skeleton);
    let worst = max_distance(&whole, &want.clip.global().1);
    println!("refine_poses_at_seams vs zoo_rmr refine_seams (pre-blend): max joint distance {worst:e} cm");
    assert!(worst <= 1e-3, "joint positions differ by {worst} cm");
    // The seams took effect: without them the refined motion is another.
    let mut plain = vec![EnginePose::new(j); n];
    refiner.refine_poses(&poses, FootCleanup::NONE, &mut plain, &mut contacts).unwrap();
    let moved = max_distance(&world_positions(&plain, skeleton), &whole);
    assert!(moved > 0.1, "the pre-blend moved joints by only {moved} cm");
    // A seam out of the sequence is refused.
    let err = refiner.refine_poses_at_seams(&poses, &[100], FootCleanup::NONE, &mut out, &mut contacts).unwrap_err();
    assert!(err.to_string().contains("seam at frame 100 of a sequence of 100 frames"), "{err}");

    // The stream with the same seams marked: the whole sequence's poses on every frame.
    let (got, _) = stream_all(&refiner, &poses, &seams, FootCleanup::NONE, false);
    let worst = max_distance(&world_positions(&got, skeleton), &whole);
    println!("stream with marked seams vs the whole sequence: max joint distance {worst:e} cm on {n} frames");
    assert!(worst <= 1e-4, "the stream differs by {worst} cm");
}

/// What `zoo stitch` writes for a `--pre-blend` model by default (seams inertialized, refined,
/// ankles by IK, seams guarded against pops, feet locked): the runtime's whole-sequence form
/// gives the same motion as the offline path.
#[test]
fn runtime_guards_the_seams_like_zoo_stitch() {
    use zoo_rmr::stitch::{PostProcess, RefineOptions, refine_seams};
    use zoo_runtime::EnginePose;
    use zoo_runtime::stitch::FootCleanup;
    let (f, poses, clip, mut refiner) = seam_fixture();
    let seams = [30, 60];
    let post = PostProcess {
        ankle_ik: true,
        foot_lock: true,
        pre_blend: true,
        seam_guard: true,
        keep_untouched: true,
        reach: None,
    };
    let want = refine_seams(&f.model, &f.stats, &clip, &seams, RefineOptions::of(&f.config), post).unwrap();
    let guarded = want.guarded.as_ref().expect("the guard ran");
    assert!(guarded.iter().any(|g| g.weight > 0.0), "the guard acted on a seam: {guarded:?}");
    let (n, j) = (poses.len(), refiner.joints());
    let mut out = vec![EnginePose::new(j); n];
    let mut contacts = vec![[false; 4]; n];
    refiner.refine_poses_at_seams(&poses, &seams, FootCleanup::default(), &mut out, &mut contacts).unwrap();
    let skeleton = refiner.skeleton().clone();
    let whole = world_positions(&out, &skeleton);
    let worst = max_distance(&whole, &want.clip.global().1);
    // Without the guard the motion is another: the comparison above covers it.
    refiner.set_seam_guard(false);
    let mut plain = vec![EnginePose::new(j); n];
    refiner.refine_poses_at_seams(&poses, &seams, FootCleanup::default(), &mut plain, &mut contacts).unwrap();
    let moved = max_distance(&world_positions(&plain, &skeleton), &whole);
    println!(
        "refine_poses_at_seams vs zoo_rmr refine_seams (pre-blend, IK, guard, lock): max joint distance {worst:e} cm; \
         the guard moved joints by up to {moved:.3} cm ({guarded:?})"
    );
    // As in `runtime_refines_engine_poses_like_zoo_stitch`: the leg IK magnifies float differences.
    assert!(worst <= 0.1, "joint positions differ by {worst} cm");
    assert!(moved > 10.0 * worst.max(1e-3), "the guard moved joints by only {moved} cm");
    // The stream with the seams marked and its guard: the whole sequence's poses on every frame,
    // with the seams' reach (the default) and without.
    refiner.set_seam_guard(true);
    for reach in [Some(refiner.window()), None] {
        refiner.set_seam_reach(reach).unwrap();
        for cleanup in [FootCleanup { place_ankles: true, lock_feet: false }, FootCleanup::default()] {
            refiner.refine_poses_at_seams(&poses, &seams, cleanup, &mut out, &mut contacts).unwrap();
            let (got, _) = stream_all(&refiner, &poses, &seams, cleanup, true);
            let worst = max_distance(&world_positions(&got, &skeleton), &world_positions(&out, &skeleton));
            println!(
                "stream with marked seams, {cleanup:?}, guard, reach {reach:?} vs the whole sequence: max joint \
                 distance {worst:e} cm"
            );
            assert!(worst <= 1e-4, "the stream differs by {worst} cm");
        }
    }
}

/// Seams as dense as stitching takes them (a clip every 10 frames, the shortest it stitches):
/// the stream keeps its latency (each seam's guard weighed before the lock reads the frames it
/// blends) and gives the whole sequence's poses, lock and reach included.
#[test]
fn a_stream_with_a_seam_every_ten_frames_keeps_its_latency() {
    use zoo_runtime::EnginePose;
    use zoo_runtime::stitch::FootCleanup;
    let f = fixture(RefinerCell::Bgru);
    let mut refiner =
        zoo_runtime::StitchRefiner::from_bytes(&export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes())
            .unwrap();
    let (poses, _) = aligned_poses(340);
    let j = refiner.joints();
    let ik = FootCleanup { place_ankles: true, lock_feet: false };
    for (cleanup, guard, reach) in [
        (FootCleanup::NONE, false, None),
        (FootCleanup::NONE, false, Some(60)),
        (ik, false, None),
        (ik, true, None),
        (FootCleanup::default(), false, None),
        (FootCleanup::default(), true, Some(60)),
    ] {
        refiner.set_seam_guard(guard);
        refiner.set_seam_reach(reach).unwrap();
        for first in [10, 13, 17, 19] {
            let seams: Vec<usize> = (first..330).step_by(10).collect();
            let mut out = vec![EnginePose::new(j); poses.len()];
            let mut contacts = vec![[false; 4]; poses.len()];
            refiner.refine_poses_at_seams(&poses, &seams, cleanup, &mut out, &mut contacts).unwrap();
            let (got, _) = stream_all(&refiner, &poses, &seams, cleanup, guard);
            let skeleton = refiner.skeleton();
            let (a, b) = (world_positions(&got, skeleton), world_positions(&out, skeleton));
            let per: Vec<f64> =
                (0..poses.len()).map(|t| max_distance(&a[t * j..(t + 1) * j], &b[t * j..(t + 1) * j])).collect();
            let worst = per.iter().copied().fold(0.0, f64::max);
            let at = per.iter().position(|&d| d == worst).unwrap();
            println!(
                "stream with {} seams 10 frames apart ({cleanup:?}, guard {guard}, reach {reach:?}) vs the whole \
                 sequence: max joint distance {worst:e} cm at frame {at}",
                seams.len()
            );
            assert!(worst <= 1e-4, "the stream differs by {worst} cm at frame {at}");
        }
    }
}

/// Bad input to the pose and streaming forms: clear errors, no panic.
#[test]
fn runtime_stitch_poses_and_stream_refuse_bad_input() {
    use zoo_runtime::stitch::FootCleanup;
    use zoo_runtime::{EnginePose, StitchRefiner};
    let f = fixture(RefinerCell::Gru);
    let refiner = StitchRefiner::from_bytes(&export_rmr(&f.config, &f.stats, &f.varmap).unwrap().to_bytes()).unwrap();
    let (poses, _) = aligned_poses(40);
    let j = refiner.joints();
    // Another skeleton (fewer joints).
    let wrong = vec![EnginePose::new(j - 2); 40];
    let mut out = vec![EnginePose::new(j); 40];
    let mut contacts = vec![[false; 4]; 40];
    let err = refiner.refine_poses(&wrong, FootCleanup::default(), &mut out, &mut contacts).unwrap_err().to_string();
    assert!(err.contains("pose 0 has 19 joint rotations but the model's skeleton has 21 joints"), "{err}");
    // Fewer poses than the window, mismatched buffers, NaN.
    let err = refiner
        .refine_poses(&poses[..20], FootCleanup::default(), &mut out[..20], &mut contacts[..20])
        .unwrap_err()
        .to_string();
    assert!(err.contains("the window of 30 frames is longer than the sequence (20 frames)"), "{err}");
    let err =
        refiner.refine_poses(&poses, FootCleanup::default(), &mut out[..39], &mut contacts).unwrap_err().to_string();
    assert!(err.contains("40 input poses but 39 output poses"), "{err}");
    let mut nan = poses.clone();
    nan[3].local_rotations[5].x = f32::NAN;
    let err = refiner.refine_poses(&nan, FootCleanup::default(), &mut out, &mut contacts).unwrap_err().to_string();
    assert!(err.contains("pose 3") && err.contains("non-finite"), "{err}");
    let err = refiner.encode_poses(&poses[..1], &mut [0.0; 1000]).unwrap_err().to_string();
    assert!(err.contains("at least 2 frames"), "{err}");
    // The stream: a wrong pose, NaN, too short a motion, a wrong output pose, push after finish.
    let mut stream = refiner.stream();
    let err = stream.push(&EnginePose::new(j + 1)).unwrap_err().to_string();
    assert!(err.contains("22 joint rotations"), "{err}");
    let err = stream.push(&nan[3]).unwrap_err().to_string();
    assert!(err.contains("non-finite"), "{err}");
    for p in &poses[..10] {
        stream.push(p).unwrap();
    }
    let err = stream.finish().unwrap_err().to_string();
    assert!(err.contains("ends after 10 frames, fewer than the window of 30"), "{err}");
    for p in &poses[10..] {
        stream.push(p).unwrap();
    }
    let err = stream.pop(&mut EnginePose::new(3)).unwrap_err().to_string();
    assert!(err.contains("the output pose has 3 joints"), "{err}");
    stream.finish().unwrap();
    let err = stream.push(&poses[0]).unwrap_err().to_string();
    assert!(err.contains("the stream is finished"), "{err}");
    let mut pose = EnginePose::new(j);
    let mut n = 0;
    while stream.pop(&mut pose).unwrap().is_some() {
        n += 1;
    }
    assert_eq!(n, 40);
}

/// `StitchStream` against `zoo stitch`'s default output (seams inertialized, refined with the
/// fallback, ankles by IK, seams guarded, feet locked) on bandai2's youthful stitching cases:
/// every sixth validation clip with the next one (pairs) and the next two (triples), each cut to
/// 60 to 150 frames and aligned end to start as `zoo stitch` aligns them, refined by the RMR of
/// the run folder `ZOO_RMR_RUN` (default `../runs/rmr20`, trained with `--valid-glob
/// '*_youthful_*'`) exported through `zoo_models`. Prints the largest joint-position difference
/// in cm (and the mean and 99th percentile of each frame's largest) with the latency, for the
/// refiner with its ankle IK and seam guard and for `zoo stitch`'s whole default (the foot lock
/// and the seams' reach included); both must be within 0.05 cm.
#[test]
#[ignore = "needs ../shared/data/bandai2"]
fn stitch_stream_matches_zoo_stitch_on_bandai2() {
    use zoo_rmr::pairs::{MIN_CLIP_FRAMES, align_clips};
    use zoo_runtime::stitch::FootCleanup;
    use zoo_runtime::{EnginePose, StitchRefiner};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let data = std::env::var("ZOO_BANDAI2").map_or_else(|_| root.join("../shared/data/bandai2"), Into::into);
    let run = std::env::var("ZOO_RMR_RUN").map_or_else(|_| root.join("../runs/rmr20"), Into::into);
    let exported = zoo_models::export_run(&run, &Default::default()).unwrap();
    let refiner = StitchRefiner::from_bytes(&exported.model.to_bytes()).unwrap();
    let mut names: Vec<std::path::PathBuf> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().contains("_youthful_")))
        .collect();
    names.sort();
    let clips: Vec<zoo_motion::Clip> = names.iter().map(|p| zoo_data::clip_io::read_model_clip(p).unwrap()).collect();
    let j = refiner.joints();
    assert!(clips.iter().all(|c| c.joints() == j), "the clips are on the model's rig");
    let skeleton = refiner.skeleton().clone();
    let mut cases = Vec::new();
    for k in (0..clips.len().saturating_sub(2)).step_by(6) {
        for n in [2, 3] {
            let parts: Vec<zoo_motion::Clip> = (0..n)
                .map(|i| {
                    let c = &clips[k + i];
                    let len = (60 + 37 * (k + i) % 91).min(c.frames());
                    let from = (c.frames() - len) / 3;
                    c.slice(from, from + len)
                })
                .collect();
            let aligned = align_clips(&parts, refiner.layout(), MIN_CLIP_FRAMES).unwrap();
            let seams = aligned.starts[1..].to_vec();
            let clip = aligned.clip;
            let poses: Vec<EnginePose> = (0..clip.frames())
                .map(|f| {
                    let rotations: Vec<glam::Quat> = clip.rotations_at(f).iter().map(|q| q.as_quat()).collect();
                    EnginePose::from_world(clip.root_position(f).as_vec3(), &rotations)
                })
                .collect();
            cases.push((clip, seams, poses));
        }
    }
    let ik = FootCleanup { place_ankles: true, lock_feet: false };
    let mut worst_all: f64 = 0.0;
    for (name, cleanup) in [("ankle IK and seam guard", ik), ("zoo stitch's default", FootCleanup::default())] {
        let (mut per_frame, mut worst_zoo, mut latency) = (Vec::new(), 0.0f64, 0);
        for (clip, seams, poses) in &cases {
            // The whole sequence, on the poses as the engine has them and on the aligned clip itself.
            let mut whole = vec![EnginePose::new(j); poses.len()];
            let mut contacts = vec![[false; 4]; poses.len()];
            refiner.refine_poses_at_seams(poses, seams, cleanup, &mut whole, &mut contacts).unwrap();
            let zoo = refiner.refine_clip(clip, seams, cleanup).unwrap().clip.global().1;
            let mut stream = refiner.stream();
            stream.set_cleanup(cleanup).unwrap();
            latency = stream.latency();
            let (got, streamed_contacts) = stream_all(&refiner, poses, seams, cleanup, true);
            assert_eq!(streamed_contacts, contacts, "contacts agree");
            let (a, b) = (world_positions(&got, &skeleton), world_positions(&whole, &skeleton));
            per_frame.extend((0..poses.len()).map(|t| max_distance(&a[t * j..(t + 1) * j], &b[t * j..(t + 1) * j])));
            worst_zoo = worst_zoo.max(max_distance(&a, &zoo));
        }
        let mean = per_frame.iter().sum::<f64>() / per_frame.len() as f64;
        let p99 = zoo_protocol::stitch::percentile(&mut per_frame, 99.0);
        let worst = per_frame.iter().copied().fold(0.0, f64::max);
        println!(
            "StitchStream ({name}, latency {latency} frames) vs the whole sequence on {} bandai2 youthful cases ({} \
             frames): largest joint difference {worst:.2e} cm (mean {mean:.2e}, 99th percentile {p99:.2e}) against \
             refine_poses_at_seams, {worst_zoo:.2e} cm against refine_clip on the aligned clip (zoo stitch)",
            cases.len(),
            per_frame.len()
        );
        worst_all = worst_all.max(worst.max(worst_zoo));
    }
    assert!(worst_all <= 0.05, "the stream differs from the whole sequence by {worst_all} cm");
}

/// The runtime refines a window of one character at every weight width as onnxruntime does on
/// the same file: at f16 and int8 the GRU's recurrence runs on the file's own 16- or 8-bit
/// weights (a character alone), at f32 on tract-linalg's kernel.
#[test]
fn the_runtime_window_agrees_with_onnxruntime_at_every_width() {
    for cell in [RefinerCell::Bgru, RefinerCell::Gru] {
        let f = fixture(cell);
        let d = f.config.dim();
        let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
        let x = lcg(12, FRAMES * d, 2.0);
        for width in [zoo_export::WeightWidth::F32, zoo_export::WeightWidth::F16, zoo_export::WeightWidth::Int8] {
            let narrow = zoo_export::with_weights(&onnx, width).unwrap();
            let mut refiner = zoo_runtime::StitchRefiner::from_bytes(&narrow.to_bytes()).unwrap();
            refiner.set_window(FRAMES, FRAMES / 2).unwrap();
            let mut y = vec![f32::NAN; FRAMES * d];
            refiner.refine_window_normalized(&x, &mut y).unwrap();
            let o = ort_run_batch(&narrow, &x, d, 1);
            let diff = max_abs_diff(&y, &o);
            println!("{cell:?} {width}: runtime-ort max |diff| {diff:e}");
            assert!(diff <= 1e-5, "{cell:?} {width}: runtime-ort max |diff| {diff}");
        }
    }
}
