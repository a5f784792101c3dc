//! Where a run's learning signal goes: the gradient of each loss term with respect to the
//! decoder, the first encoder layer and the first refiner layer on one batch of 32 training
//! pairs, the active decoder units, and `|input - target|` per frame of the pairs.
//!
//! ```sh
//! cargo run --release -p zoo-rmr --example rmr_gradients -- --data ../shared/data/bandai2 \
//!     --valid-glob '*_youthful_*' --model RUN_DIR [--fresh]
//! ```
//!
//! `--model` is a `zoo train rmr` run folder (its configuration, statistics and cached pair
//! plans; the pairs are rebuilt from `--data`); `--fresh` replaces its weights by a new
//! model's (a residual model at the identity). A run whose decoder gradients are 0 has lost
//! every decoder unit (docs/rmr.md, "Dead decoder units").

use candle_core::{DType, Device, Tensor};
use std::path::PathBuf;
use zoo_rmr::features::FeatureLayout;
use zoo_rmr::pairs::MotionSet;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1).cloned());
    let (Some(data_dir), Some(run)) = (get("--data"), get("--model")) else {
        return Err("usage: rmr_gradients --data DIR --valid-glob GLOB --model RUN_DIR [--fresh]".into());
    };
    let run = PathBuf::from(run);
    let ds = zoo_data::dataset::load_with(std::path::Path::new(&data_dir), &Default::default())?;
    let (tr, te) = zoo_data::dataset::split(ds.clips, &get("--valid-glob").unwrap_or("*_youthful_*".into()))?;
    let (config, stats) = zoo_rmr::checkpoint::read_meta(&run)?;
    let layout = config.layout.clone();
    let train = MotionSet::from_named(tr, layout.clone())?;
    let data = zoo_rmr::data::make_pairs_cached(&config, train, MotionSet::from_named(te, layout)?, Some(&run))?;
    let dev = Device::Cpu;
    let trainer = zoo_rmr::RmrTrainer::new(&config, stats.clone(), &dev)?;
    if !args.iter().any(|a| a == "--fresh") {
        zoo_rmr::checkpoint::load_weights(&run, trainer.varmap())?;
    }
    let (model, varmap) = (trainer.model(), trainer.varmap());
    let loss = zoo_rmr::loss::Loss::new(&config, &stats, &dev)?;
    let d = &data.train;
    let (t, dim) = (d.frames, d.dim);
    let pose = FeatureLayout::new(config.joints, config.layout.lower_body.len()).contacts();
    let mut per_frame = vec![0f64; t];
    for i in 0..d.count {
        for (f, acc) in per_frame.iter_mut().enumerate() {
            let k = (i * t + f) * dim;
            *acc += (0..pose).map(|v| (d.inputs[k + v] - d.targets[k + v]).abs() as f64).sum::<f64>();
        }
    }
    println!("{} training pairs of {t} frames, {dim} values ({pose} pose values)", d.count);
    println!("sum over pose values of |input - target| (normalised), mean over pairs, every 5th frame:");
    println!(
        "  {:?}",
        per_frame.iter().step_by(5).map(|s| (s / d.count as f64 * 100.0).round() / 100.0).collect::<Vec<_>>()
    );
    let b = 32.min(d.count);
    let x = Tensor::from_slice(&d.inputs[..b * t * dim], (b, t, dim), &dev)?;
    let y = Tensor::from_slice(&d.targets[..b * t * dim], (b, t, dim), &dev)?;
    let (active, units) = model.active_decoder_units(&x)?;
    println!("decoder units active on this batch: {active}/{units}");
    let out = model.forward(&x, None)?;
    let terms = loss.terms(&out, &x, &y)?;
    println!("loss terms (no dropout): {:?}", terms.values()?);
    let mut names: Vec<_> = varmap.data().lock().expect("varmap").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
    names.sort_by(|a, b| a.0.cmp(&b.0));
    println!("rms gradient per weight:");
    for (name, term) in [
        ("total", &terms.total),
        ("pose", &terms.pose),
        ("trajectory", &terms.trajectory),
        ("foot", &terms.foot),
        ("begin", &terms.begin),
    ] {
        let g = term.backward()?;
        let mut line = format!("  {name:<10}");
        for (n, v) in &names {
            if !(n.starts_with("decoder") || n == "encoder.0.weight" || n == "refiner.weight_ih_l0") {
                continue;
            }
            let r = match g.get(v.as_tensor()) {
                Some(gr) => gr.to_dtype(DType::F32)?.sqr()?.mean_all()?.sqrt()?.to_scalar::<f32>()?,
                None => 0.0,
            };
            line += &format!(" {n} {r:.2e}");
        }
        println!("{line}");
    }
    Ok(())
}
