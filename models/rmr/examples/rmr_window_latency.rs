//! Latency of refining one window at batch 1 on one thread: the exported RMR on tract
//! (`zoo_runtime::StitchRefiner`) and on onnxruntime, side by side, with candle for reference.
//! The backends take turns round by round so that machine noise hits them alike; the figure
//! per backend is the median over rounds of the mean time per window.
//!
//! ```text
//! cargo build --workspace --examples
//! RAYON_NUM_THREADS=1 target/debug/examples/rmr_window_latency [RUN_DIR] [--window 60] [--rounds 11] [--reps 10]
//! ```
//! Without `RUN_DIR`, the seeded paper-size model (BGRU 2 x 256) is used: latency does not
//! depend on the weights. onnxruntime: `ORT_DYLIB_PATH`, else `.onnxruntime/libonnxruntime.so.1.31.1`.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use std::borrow::Cow;
use std::path::PathBuf;
use std::time::Instant;
use zoo_rmr::features::FeatureStats;
use zoo_rmr::{Config, Rmr};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).map(|s| s.parse::<usize>());
    let window = opt("--window").transpose()?.unwrap_or(60);
    let rounds = opt("--rounds").transpose()?.unwrap_or(11);
    let reps = opt("--reps").transpose()?.unwrap_or(10);
    let run = args.first().filter(|a| !a.starts_with("--")).map(PathBuf::from);
    let (config, stats, varmap) = match &run {
        Some(dir) => {
            let (config, stats) = zoo_rmr::checkpoint::read_meta(dir)?;
            let varmap = VarMap::new();
            Rmr::new(&config, candle_nn::VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu))?;
            zoo_rmr::checkpoint::load_weights(dir, &varmap)?;
            (config, stats, varmap)
        }
        None => {
            let config = Config::paper();
            let d = config.dim();
            let varmap = VarMap::new();
            Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))?;
            (config, FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] }, varmap)
        }
    };
    let model = Rmr::new(&config, candle_nn::VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu))?;
    let d = config.dim();
    let onnx = zoo_rmr::export::export_rmr(&config, &stats, &varmap)?;
    let bytes = onnx.to_bytes();
    let mut tract = zoo_runtime::StitchRefiner::from_bytes(&bytes)?;
    tract.set_window(window, window / 2)?;
    let lib = std::env::var_os("ORT_DYLIB_PATH")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(".onnxruntime/libonnxruntime.so.1.31.1"));
    if !lib.is_file() {
        return Err(format!("onnxruntime library not found at {}: set ORT_DYLIB_PATH", lib.display()).into());
    }
    let env = ort::init_from(&lib)?.build()?;
    let mut ort_session = ort::session::Session::builder(&env)?.with_intra_threads(1)?.commit_from_memory(&bytes)?;
    let x: Vec<f32> = (0..window * d).map(|i| ((i * 7919 % 1000) as f32 / 500.0) - 1.0).collect();
    let mut y = vec![0.0f32; window * d];
    let xs = Tensor::from_slice(&x, (1, window, d), &Device::Cpu)?;
    let mut ort_once = |x: &[f32]| -> Result<Vec<f32>, Box<dyn std::error::Error>> {
        let t = ort::value::Tensor::from_array((vec![window as i64, 1, d as i64], x.to_vec()))?;
        let inputs: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = vec![(Cow::Borrowed("x"), t.into())];
        let out = ort_session.run(inputs)?;
        Ok(out["y"].try_extract_tensor::<f32>()?.1.to_vec())
    };
    // Agreement first (time-major [window, 1, d] equals batch-first [1, window, d] at batch 1).
    tract.refine_window_normalized(&x, &mut y)?;
    let o = ort_once(&x)?;
    let c: Vec<f32> = model.forward(&xs, None)?.flatten_all()?.to_vec1()?;
    let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
    println!(
        "{} (dim {d}, {:?} x {}), window {window}, batch 1: max |diff| tract-ort {:e}, tract-candle {:e}",
        run.as_ref().map_or("seeded paper-size RMR".to_string(), |p| p.display().to_string()),
        config.cell,
        config.hidden,
        diff(&y, &o),
        diff(&y, &c)
    );
    let (mut t_tract, mut t_ort, mut t_candle) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..rounds {
        let t0 = Instant::now();
        for _ in 0..reps {
            tract.refine_window_normalized(&x, &mut y)?;
        }
        t_tract.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
        let t0 = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(ort_once(&x)?);
        }
        t_ort.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
        let t0 = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(model.forward(&xs, None)?);
        }
        t_candle.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
    }
    let (a, b, c) = (median(t_tract), median(t_ort), median(t_candle));
    println!("median ms per window over {rounds} rounds of {reps}: tract {a:.3}, onnxruntime {b:.3}, candle {c:.3}");
    println!("tract / onnxruntime = {:.2}x (target <= 1.25x)", a / b);
    Ok(())
}
