//! The training step at the paper's sizes for `zoo bench train` ([`zoo_nn::speed`]).

use crate::error::RnnGmmResult;
use candle_core::{Device, Tensor};
use zoo_data::{Context, bail};
use zoo_nn::speed::{SpeedBench, Step};

/// The paper-size RNN-GMM configuration and its training windows from two minutes of the
/// embedded synthetic locomotion.
fn rnn_gmm_data() -> RnnGmmResult<(crate::prelude::Config, crate::TrainingData)> {
    let cfg = zoo_data::synth::SynthConfig { minutes: 2.0, seed: 1, terrain: false, ..Default::default() };
    let clips = zoo_data::synth::generate(&cfg);
    let refs: Vec<&zoo_motion::Clip> = clips.iter().map(|c| &c.clip).collect();
    let config = crate::prelude::Config::paper();
    let data = crate::TrainingData::from_clips(&config, cfg.fps, &refs[1..], &refs[..1])?;
    Ok((config.with_dim(data.spec.dim()), data))
}

/// Refuses synthetic data with fewer training windows than a batch of `b`.
fn enough_windows(data: &crate::TrainingData, b: usize) -> RnnGmmResult<()> {
    if data.train.len() < b {
        bail!("the synthetic data gave {} windows, fewer than a batch of {b}", data.train.len());
    }
    Ok(())
}

/// The RNN-GMM generator at the paper's sizes (3 x 512 dense, 2 x 512 LSTM, M = 5, windows of
/// 50 frames, batch 20) on the embedded synthetic locomotion.
pub fn generator_bench(threads: &[usize]) -> RnnGmmResult<SpeedBench<'static>> {
    use crate::prelude::*;
    let (config, data) = rnn_gmm_data()?;
    let b = config.train.batch_size;
    enough_windows(&data, b)?;
    let windows: Vec<Vec<f32>> = (0..b).map(|i| data.train.get(i).to_vec()).collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu)?;
        tr.set_threads(t)?;
        params = tr.model().parameter_count();
        let windows = windows.clone();
        let refs: Vec<&[f32]> = windows.iter().map(|w| w.as_slice()).collect();
        tr.train_step(&refs)?; // warm-up
        steps.push(Box::new(move || {
            let refs: Vec<&[f32]> = windows.iter().map(|w| w.as_slice()).collect();
            tr.train_step(&refs)?;
            Ok(())
        }));
    }
    let w = config.train.window;
    Ok(SpeedBench {
        what: format!("RNN-GMM generator, paper sizes ({params} parameters, batch {b}, windows of {w} frames)"),
        batch: b,
        // Forward 2 flops per weight per frame, backward twice that.
        flops: 6.0 * params as f64 * (w - 1) as f64,
        gate: (b, 2 * config.lstm, 4 * config.lstm),
        steps,
    })
}

/// The RNN-GMM refiner stage at the paper's sizes (refiner FC 256 + LSTM 256, discriminator FC
/// 128 + bidirectional LSTM 128, batch 32, windows of 50 frames): a step is one refiner update
/// and one discriminator update (half fresh refined windows, half from the history buffer).
pub fn refiner_bench(threads: &[usize]) -> RnnGmmResult<SpeedBench<'static>> {
    use crate::prelude::*;
    let (config, data) = rnn_gmm_data()?;
    let rc = config.refiner.clone();
    let b = rc.batch;
    enough_windows(&data, b)?;
    let dir = tempfile::tempdir().context("a temporary folder for the generator")?;
    GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu)?.save(dir.path())?;
    let w = config.train.window;
    let real: Vec<f32> = (0..b).flat_map(|i| data.train.get(i).to_vec()).collect();
    let real = Tensor::from_vec(real, (b, w, config.dim), &Device::Cpu)?;
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = AdversarialTrainer::new(dir.path(), &rc, &data.train, &data.valid, &Device::Cpu)?;
        tr.set_threads(t)?;
        let (r, d) = tr.varmaps();
        params = [r, d].iter().map(|v| v.all_vars().iter().map(|x| x.elem_count()).sum::<usize>()).sum();
        let real = real.clone();
        tr.refiner_update()?; // warm-up
        tr.discriminator_update(&real)?;
        steps.push(Box::new(move || {
            tr.refiner_update()?;
            tr.discriminator_update(&real)?;
            Ok(())
        }));
    }
    // Per window and frame: the refiner update runs refiner + discriminator forward and
    // backward; the discriminator update runs the refiner forward once (fresh half) and the
    // discriminator forward and backward on real and refined windows. Counted as 6 flops per
    // parameter per frame for each of the two updates (an estimate; the FK of the effector
    // features is left out).
    Ok(SpeedBench {
        what: format!(
            "RNN-GMM refiner stage, paper sizes ({params} refiner + discriminator parameters, batch {b}, windows of \
             {w} frames; a step = one refiner update + one discriminator update)"
        ),
        batch: b,
        flops: 2.0 * 6.0 * params as f64 * w as f64,
        gate: (b, rc.refiner_fc + rc.refiner_lstm, 4 * rc.refiner_lstm),
        steps,
    })
}
