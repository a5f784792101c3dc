//! Training throughput of the paper-size RMR (batch 32, T = 60, BGRU 2 x 256) on random
//! normalised pairs: the time per Adam step and pairs per second, for each refiner cell.
//!
//! ```text
//! cargo build --workspace --examples
//! RAYON_NUM_THREADS=2 target/debug/examples/rmr_train_speed [STEPS]
//! ```

use candle_core::{Device, Tensor};
use std::time::Instant;
use zoo_rmr::features::FeatureStats;
use zoo_rmr::{Config, RefinerCell, RmrTrainer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let steps: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(5);
    for cell in [RefinerCell::Bgru, RefinerCell::Gru] {
        let config = Config::paper().with_cell(cell);
        let d = config.dim();
        let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
        let mut trainer = RmrTrainer::new(&config, stats, &Device::Cpu)?;
        let (b, t) = (config.train.batch_size, config.pairs.window);
        let x = Tensor::randn(0f32, 1.0, (b, t, d), &Device::Cpu)?;
        let y = Tensor::randn(0f32, 1.0, (b, t, d), &Device::Cpu)?;
        trainer.train_step(&x, &y)?; // warm-up
        let t0 = Instant::now();
        for _ in 0..steps {
            trainer.train_step(&x, &y)?;
        }
        let s = t0.elapsed().as_secs_f64() / steps as f64;
        println!(
            "{cell:?}: {:.3} s per step of {b} pairs x {t} frames, {:.1} pairs/s; an epoch of 3,089 bandai2 pairs: {:.0} s",
            s,
            b as f64 / s,
            3089.0 / b as f64 * s
        );
    }
    Ok(())
}
