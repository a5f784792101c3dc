//! The training step at the paper's sizes for `zoo bench train` ([`zoo_nn::speed`]).

use crate::error::RmrResult;
use candle_core::{Device, Tensor};
use zoo_nn::speed::{SpeedBench, Step};

/// The paper-size RMR (BGRU 2 x 256, batch 32 pairs of 60 frames, 145 values per frame) on
/// seeded random normalised pairs (the step's cost does not depend on the values).
pub fn train_bench(threads: &[usize]) -> RmrResult<SpeedBench<'static>> {
    use crate::{Config, RmrTrainer, features::FeatureStats};
    let config = Config::paper();
    let d = config.dim();
    let (b, frames) = (config.train.batch_size, config.pairs.window);
    let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let dev = Device::Cpu;
    let x = Tensor::randn(0f32, 1.0, (b, frames, d), &dev)?;
    let y = Tensor::randn(0f32, 1.0, (b, frames, d), &dev)?;
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = RmrTrainer::new(&config, stats.clone(), &dev)?;
        tr.set_threads(t)?;
        params = crate::model::parameter_count(tr.varmap());
        tr.train_step(&x, &y)?; // warm-up
        let (x, y) = (x.clone(), y.clone());
        steps.push(Box::new(move || {
            tr.train_step(&x, &y)?;
            Ok(())
        }));
    }
    Ok(SpeedBench {
        what: format!("RMR paper sizes ({params} parameters, BGRU 2 x {}, batch {b}, {frames} frames)", config.hidden),
        batch: b,
        // Every weight is used once per frame: forward 2 flops per weight, backward twice that.
        flops: 6.0 * params as f64 * frames as f64,
        gate: (b, config.hidden, 3 * config.hidden),
        steps,
    })
}
