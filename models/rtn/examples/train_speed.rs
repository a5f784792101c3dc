//! Training-step throughput of the paper-sized RTN (K = 22, batch 32, 10 past frames,
//! 30-frame transitions) on synthetic windows, and the FLOP/s of one candle matmul at the
//! fused LSTM gate shape for comparison.
//!
//! `MIMALLOC_PURGE_DELAY=-1 RAYON_NUM_THREADS=2 cargo run --release -p zoo-rtn --example train_speed -- [steps]`
//!
//! On a loaded machine (other builds running) one thread is faster than two: candle's parallel
//! ops spin on barriers when their second thread is descheduled.

use candle_core::{DType, Device, Tensor};

/// candle allocates a fresh buffer per op (the per-step weight gradients are MBs each); glibc's
/// malloc hands the large ones back to the OS and page-faults them in again every step (~30% of
/// a step on this machine). mimalloc with `MIMALLOC_PURGE_DELAY=-1` keeps them (measured here:
/// 19.6 -> 30.7 windows/s with one thread; glibc with `MALLOC_MMAP_THRESHOLD_=1073741824
/// MALLOC_TRIM_THRESHOLD_=4294967296` gets most of it too). Training binaries should do the same.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;
use std::time::Instant;
use zoo_rtn::prelude::*;

fn window(frames: usize, joints: usize, seed: usize) -> Vec<f32> {
    let s = seed as f32;
    let mut p = Vec::with_capacity(frames * joints * 3);
    for f in 0..frames {
        let t = f as f32 + 7.0 * s;
        let root = [2.5 * t * (0.3 * s).cos(), 90.0 + 3.0 * (0.3 * t).sin(), 2.5 * t * (0.3 * s).sin()];
        for j in 0..joints {
            let ph = 0.25 * t + j as f32 * 0.4 + s;
            p.extend_from_slice(&[
                root[0] + 10.0 * ph.sin(),
                root[1] + 5.0 * j as f32 + 4.0 * ph.cos(),
                root[2] + 8.0 * (2.0 * ph).sin(),
            ]);
        }
    }
    p
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let steps: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(5);
    let parents: Vec<Option<usize>> = (0..22).map(|j| if j == 0 { None } else { Some((j - 1) / 2) }).collect();
    let config = Config::paper().with_parents(&parents);
    let dev = Device::Cpu;
    let ws: Vec<Vec<f32>> = (0..64).map(|i| window(config.window_frames(), 22, i)).collect();
    let mw: Vec<MotionWindow> = ws.iter().map(|w| MotionWindow::new(w)).collect();
    let stats = fit_stats(&config, &mw)?;
    let mut trainer = RtnTrainer::new(&config, stats, &dev)?;
    println!("parameters: {}", trainer.model().parameter_count());
    let b = config.train.batch_size;
    trainer.train_step(&mw[..b])?; // warm-up
    let t0 = Instant::now();
    let mut loss = 0.0;
    for s in 0..steps {
        let k = (s * b) % 32;
        loss = trainer.train_step(&mw[k..k + b])?;
    }
    let dt = t0.elapsed().as_secs_f64();
    let wps = (steps * b) as f64 / dt;
    // Matmul FLOPs of one training step: forward 2*m*k*n per layer per frame, backward twice that.
    let d = config.dim();
    let e = 512;
    let per_frame: usize = [
        (d, 512),
        (512, 512),               // E
        (e + 512 + 128, 4 * 512), // fused gates
        (512, 256),
        (256, 128),
        (128, d), // D
        (d, 128),
        (128, 128), // O
    ]
    .iter()
    .map(|(i, o)| 2 * i * o)
    .sum();
    let frames = config.past_frames + config.transition_frames;
    let flops = 3.0 * (per_frame * frames * b) as f64;
    let achieved = flops * steps as f64 / dt;
    let a = Tensor::randn(0f32, 1.0, (b, e + 512 + 128), &dev)?;
    let w = Tensor::randn(0f32, 1.0, (e + 512 + 128, 4 * 512), &dev)?;
    let _ = a.matmul(&w)?;
    let reps = 200;
    let t1 = Instant::now();
    for _ in 0..reps {
        let _ = a.matmul(&w)?.to_dtype(DType::F32)?;
    }
    let mm = reps as f64 * 2.0 * (b * (e + 512 + 128) * 4 * 512) as f64 / t1.elapsed().as_secs_f64();
    println!(
        "{steps} steps of batch {b}: {dt:.2} s, {wps:.1} windows/s, {:.1} ms/step, loss {loss:.4}; \
         ~{:.1} GFLOP/s achieved vs {:.1} GFLOP/s matmul at the gate shape ({:.0}%)",
        1000.0 * dt / steps as f64,
        achieved / 1e9,
        mm / 1e9,
        100.0 * achieved / mm
    );
    Ok(())
}
