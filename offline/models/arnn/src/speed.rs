//! The training step at the paper's sizes for `zoo bench train` ([`zoo_nn::speed`]).

use crate::ArnnResult;
use candle_core::Device;
use zoo_nn::speed::{SpeedBench, Step};

/// The paper-size ARNN (GRU 2 x 100, batch 16) on simulated lamp sequences (a small annealing
/// budget: the step's cost does not depend on how good the hops are).
pub fn train_bench(threads: &[usize], batch: Option<usize>) -> ArnnResult<SpeedBench<'static>> {
    use crate::luxo::{GenerateOptions, generate_sequence, preprocess::preprocess};
    use crate::{ArnnConfig, ArnnTrainer};
    let mut config = ArnnConfig::paper();
    config.batch_size = batch.unwrap_or(config.batch_size);
    let b = config.batch_size;
    let mut o = GenerateOptions::new(b, 17);
    o.anneal.k_max = 2;
    let seqs = (0..b).map(|i| Ok(preprocess(&generate_sequence(&o, i)?)?)).collect::<ArnnResult<Vec<_>>>()?;
    let frames = seqs[0].frames.len();
    let samples: Vec<usize> = (0..b).collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut params = 0;
    for &t in threads {
        let mut tr = ArnnTrainer::new(&config, seqs.clone(), seqs[..2].to_vec(), &Device::Cpu)?;
        tr.set_threads(t)?;
        params = tr.parameter_count();
        tr.train_on(&samples)?; // warm-up
        let samples = samples.clone();
        steps.push(Box::new(move || {
            tr.train_on(&samples)?;
            Ok(())
        }));
    }
    Ok(SpeedBench {
        what: format!("ARNN paper sizes ({params} parameters, GRU 2 x {}, batch {b}, {frames} frames)", config.hidden),
        batch: b,
        flops: 6.0 * params as f64 * (frames - 1) as f64,
        gate: (b, config.hidden, 3 * config.hidden),
        steps,
    })
}
