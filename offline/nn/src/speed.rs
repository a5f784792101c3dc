//! The training-speed benchmark's harness (`zoo bench train`): a model's training step at its
//! paper sizes per thread count (data-parallel training, [`crate::parallel`]), timed in turns
//! so that a change of machine load hits every thread count alike, with the achieved GFLOP/s
//! and the fraction of a one-thread candle matmul at the model's main shape. Each model crate
//! builds its own [`SpeedBench`] (`zoo_rtn::speed`, `zoo_rmr::speed`, ...).

use crate::error::{NnResult, TrainError};
use crate::parallel::DataParallel;
use candle_core::{DType, Device, Tensor};
use std::time::Instant;

/// One training step of the model under test (one thread count's trainer).
pub type Step<'a> = Box<dyn FnMut() -> Result<(), TrainError> + 'a>;

/// The model under test: what it is, the windows per step, the matmul FLOPs per window, the
/// main matmul shape `(m, k, n)` of one step, and one step per thread count.
pub struct SpeedBench<'a> {
    /// The model and its sizes, in words.
    pub what: String,
    /// Windows per step.
    pub batch: usize,
    /// Matmul FLOPs per window (forward and backward).
    pub flops: f64,
    /// The main matmul shape of a step (the recurrent gate's), for the reference GFLOP/s.
    pub gate: (usize, usize, usize),
    /// One step per thread count, in the order of the thread counts.
    pub steps: Vec<Step<'a>>,
}

/// One thread count's figures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SpeedRow {
    /// Threads.
    pub threads: usize,
    /// Windows per second, median over the repeats.
    pub windows_per_s_median: f64,
    /// Windows per second of every repeat.
    pub windows_per_s: Vec<f64>,
    /// GFLOP/s at the median.
    pub gflops: f64,
    /// Fraction of `threads` times the one-thread matmul's GFLOP/s.
    pub matmul_fraction: f64,
}

/// The median of `v` (the mean of the two middle values for an even count).
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 { s[n / 2] } else { 0.5 * (s[n / 2 - 1] + s[n / 2]) }
}

/// GFLOP/s of one candle matmul `(m, k) x (k, n)` on one thread.
pub fn matmul_gflops(m: usize, k: usize, n: usize) -> NnResult<f64> {
    let pool = DataParallel::new(1)?;
    pool.install(|| -> NnResult<f64> {
        let dev = Device::Cpu;
        let a = Tensor::randn(0f32, 1.0, (m, k), &dev)?;
        let w = Tensor::randn(0f32, 1.0, (k, n), &dev)?;
        let _ = a.matmul(&w)?;
        let reps = 100;
        let t = Instant::now();
        for _ in 0..reps {
            let _ = a.matmul(&w)?.to_dtype(DType::F32)?;
        }
        Ok(reps as f64 * 2.0 * (m * k * n) as f64 / t.elapsed().as_secs_f64() / 1e9)
    })
}

impl SpeedBench<'_> {
    /// Times `repeats` runs of `steps` steps for every thread count of `threads` (the ones the
    /// bench was built for), `tick` after each run; then the one-thread matmul reference.
    pub fn measure(
        &mut self,
        threads: &[usize],
        steps: usize,
        repeats: usize,
        tick: &mut dyn FnMut(),
    ) -> Result<(Vec<SpeedRow>, f64), TrainError> {
        let mut rates = vec![Vec::new(); threads.len()];
        for _ in 0..repeats {
            for (k, step) in self.steps.iter_mut().enumerate() {
                let t0 = Instant::now();
                for _ in 0..steps {
                    step()?;
                }
                rates[k].push((steps * self.batch) as f64 / t0.elapsed().as_secs_f64());
                tick();
            }
        }
        // The matmul reference on one thread, at the main (LSTM gate) shape of one step.
        let (gm, gk, gn) = self.gate;
        let mm = matmul_gflops(gm, gk, gn)?;
        let rows = threads
            .iter()
            .zip(rates)
            .map(|(&t, r)| {
                let m = median(&r);
                let gflops = m * self.flops / 1e9;
                SpeedRow {
                    threads: t,
                    windows_per_s_median: m,
                    windows_per_s: r,
                    gflops,
                    matmul_fraction: gflops / (t as f64 * mm),
                }
            })
            .collect();
        Ok((rows, mm))
    }
}
