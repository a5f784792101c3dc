//! Where tract spends a window: the exported paper-size RMR (seeded, BGRU 2 x 256) run node by
//! node on one thread, the time of each node summed over `--reps` windows.
//!
//! ```text
//! cargo build -p zoo-bench --example rmr_tract_profile
//! RAYON_NUM_THREADS=1 target/debug/examples/rmr_tract_profile [--window 60] [--reps 200]
//! ```

use candle_core::{DType, Device};
use candle_nn::VarMap;
use std::collections::HashMap;
use std::time::Instant;
use tract_onnx::prelude::*;
use zoo_rmr::features::FeatureStats;
use zoo_rmr::{Config, Rmr};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).map(|s| s.parse::<usize>());
    let window = opt("--window").transpose()?.unwrap_or(60);
    let reps = opt("--reps").transpose()?.unwrap_or(200);
    let config = Config::paper();
    let d = config.dim();
    let varmap = VarMap::new();
    Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))?;
    let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let bytes = zoo_rmr::export::export_rmr(&config, &stats, &varmap)?.to_bytes();
    if let Some(path) = args.iter().position(|a| a == "--save").and_then(|i| args.get(i + 1)) {
        std::fs::write(path, &bytes)?;
    }
    let mut model = tract_onnx::onnx().model_for_read(&mut bytes.as_slice())?;
    model.set_input_fact(0, f32::fact([window, 1, d]).into())?;
    let plan = model.into_optimized()?.into_runnable()?;
    for node in plan.model().nodes() {
        println!("node {:3} {:40} {}", node.id, node.name, node.op().name());
    }
    let x: Vec<f32> = (0..window * d).map(|i| ((i * 7919 % 1000) as f32 / 500.0) - 1.0).collect();
    let input = tract_ndarray::Array3::from_shape_vec((window, 1, d), x)?.into_tensor();
    let mut state = tract_onnx::tract_core::plan::SimpleState::new(&plan)?;
    let mut times: HashMap<usize, f64> = HashMap::new();
    let mut total = 0.0;
    for _ in 0..reps {
        let t0 = Instant::now();
        state.run_plan_with_eval(tvec!(input.clone().into()), |ctx, st, node, inputs| {
            let t = Instant::now();
            let r = tract_onnx::tract_core::plan::eval(ctx, st, node, inputs);
            *times.entry(node.id).or_default() += t.elapsed().as_secs_f64();
            r
        })?;
        total += t0.elapsed().as_secs_f64();
    }
    let mut rows: Vec<_> = times.into_iter().collect();
    rows.sort_by(|a, b| b.1.total_cmp(&a.1));
    println!("total {:.3} ms per window", 1e3 * total / reps as f64);
    for (id, t) in rows {
        let node = &plan.model().nodes()[id];
        println!(
            "{:8.4} ms {:5.1}%  {:3} {:40} {:?}",
            1e3 * t / reps as f64,
            100.0 * t / total,
            id,
            node.name,
            node.op().info()?
        );
    }
    Ok(())
}
