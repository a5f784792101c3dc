//! The training step at the paper's sizes for `zoo bench train` ([`zoo_nn::speed`]).

use crate::prelude::*;
use candle_core::Device;
use zoo_nn::speed::{SpeedBench, Step};

/// Matmul FLOPs of one training window of the paper-size RTN: forward `2 m k n` per layer per
/// frame, backward twice that (the per-sequence target encoder and initial state are left out:
/// they run once per window, not once per frame).
fn rtn_flops_per_window(config: &Config) -> f64 {
    let d = config.dim();
    let e = *config.frame_encoder.last().unwrap_or(&d);
    let hu = config.lstm;
    let o = *config.offset_encoder.last().unwrap_or(&0);
    let mut layers = vec![];
    let mut prev = d;
    for &w in &config.frame_encoder {
        layers.push((prev, w));
        prev = w;
    }
    layers.push((e + hu + o, 4 * hu));
    prev = hu;
    for &w in config.decoder.iter().chain(std::iter::once(&d)) {
        layers.push((prev, w));
        prev = w;
    }
    prev = d;
    for &w in &config.offset_encoder {
        layers.push((prev, w));
        prev = w;
    }
    let per_frame: usize = layers.iter().map(|(i, o)| 2 * i * o).sum();
    3.0 * (per_frame * (config.past_frames + config.transition_frames)) as f64
}

/// Deterministic synthetic windows of global positions (no data needed).
pub fn window(frames: usize, joints: usize, seed: usize) -> Vec<f32> {
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

/// The RTN at the paper's sizes on deterministic synthetic windows `ws` ([`window`]), with
/// `batch` windows per step instead of the paper's 32 when given.
pub fn train_bench<'a>(threads: &[usize], ws: &'a [Vec<f32>], batch: Option<usize>) -> RtnResult<SpeedBench<'a>> {
    let parents: Vec<Option<usize>> = (0..22).map(|j| if j == 0 { None } else { Some((j - 1) / 2) }).collect();
    let mut config = Config::paper().with_parents(&parents);
    if let Some(b) = batch {
        config.train.batch_size = b;
    }
    let b = config.train.batch_size;
    let mw: Vec<MotionWindow> = ws.iter().map(|w| MotionWindow::new(w)).collect();
    let stats = fit_stats(&config, &mw)?;
    let mut steps: Vec<Step> = Vec::new();
    for &t in threads {
        let mut tr = RtnTrainer::new(&config, stats.clone(), &Device::Cpu)?;
        tr.set_threads(t)?;
        tr.train_step(&mw[..b])?; // warm-up: first-touch allocations
        let mw = mw.clone();
        steps.push(Box::new(move || {
            tr.train_step(&mw[..b])?;
            Ok(())
        }));
    }
    let e = *config.frame_encoder.last().unwrap_or(&0);
    let gate_k = e + config.lstm + config.offset_encoder.last().copied().unwrap_or(0);
    Ok(SpeedBench {
        what: format!(
            "RTN paper sizes (K = 22, batch {b}, {} + {} frames)",
            config.past_frames, config.transition_frames
        ),
        batch: b,
        flops: rtn_flops_per_window(&config),
        gate: (b, gate_k, 4 * config.lstm),
        steps,
    })
}
