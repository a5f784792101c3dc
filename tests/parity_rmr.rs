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
use zoo_rmr::export::{CONFIG_KEY, MODEL_KIND, NORMALIZATION_KEY, export_rmr, export_rmr_dir};
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
    let mut model = tract_onnx::onnx().model_for_proto_model(exported.proto()).expect("tract reads the RMR graph");
    model.set_input_fact(0, f32::fact([FRAMES, BATCH, d]).into()).unwrap();
    let plan = model.into_optimized().expect("tract optimises the RMR graph").into_runnable().unwrap();
    let x = Tensor::from_shape::<f32>(&[FRAMES, BATCH, d], x_tm).unwrap();
    let inputs: TVec<TValue> = std::iter::once(TValue::from_const(std::sync::Arc::new(x))).collect();
    let out = plan.run(inputs).expect("tract runs the RMR graph");
    out[0].try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec()
}

fn ort_run(onnx: &OnnxModel, x_tm: &[f32], d: usize) -> Vec<f32> {
    let mut session = ort::session::Session::builder(ort_environment())
        .unwrap()
        .with_intra_threads(1)
        .unwrap()
        .commit_from_memory(&onnx.to_bytes())
        .expect("onnxruntime loads the RMR graph");
    let t = ort::value::Tensor::from_array((vec![FRAMES as i64, BATCH as i64, d as i64], x_tm.to_vec())).unwrap();
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
    let config: Config = serde_json::from_str(onnx.metadata_value(CONFIG_KEY).unwrap()).unwrap();
    assert_eq!(config, f.config);
    let stats: FeatureStats = serde_json::from_str(onnx.metadata_value(NORMALIZATION_KEY).unwrap()).unwrap();
    assert_eq!(stats, f.stats);
    let dir = tempfile::tempdir().unwrap();
    zoo_rmr::checkpoint::save(dir.path(), &f.config, &f.varmap, &f.stats).unwrap();
    let from_dir = export_rmr_dir(dir.path()).unwrap();
    assert_eq!(from_dir.to_bytes(), onnx.to_bytes(), "a run folder exports the same file");
    let bad = FeatureStats { mean: vec![0.0; 3], std: vec![1.0; 3] };
    let err = export_rmr(&f.config, &bad, &f.varmap).unwrap_err().to_string();
    assert!(err.contains("statistics have 3 values"), "{err}");
    let err = export_rmr_dir(&dir.path().join("nope")).unwrap_err().to_string();
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

/// Bad input to the runtime's stitching task: clear errors, no panic.
#[test]
fn runtime_stitch_refiner_refuses_bad_input() {
    use zoo_runtime::StitchRefiner;
    let f = fixture(RefinerCell::Gru);
    let d = f.config.dim();
    let onnx = export_rmr(&f.config, &f.stats, &f.varmap).unwrap();
    let mut refiner = StitchRefiner::from_bytes(&onnx.to_bytes()).unwrap();
    // An RTN (a `transition` model) where an RMR is expected.
    let mut g = zoo_export::GraphBuilder::new("rtn_like");
    let dims = [zoo_export::Dim::batch(), zoo_export::Dim::Fixed(4)];
    let x = g.input("x", &dims);
    let y = g.identity("y_id", &x);
    g.output("y", &y, &dims);
    g.metadata("zoo.model_kind", "rtn").metadata("zoo.task", "transition");
    let rtn = g.finish().unwrap();
    let err = StitchRefiner::from_bytes(&rtn.to_bytes()).unwrap_err().to_string();
    assert!(err.contains("`transition` model (kind `rtn`), not a `stitch` model"), "{err}");
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
