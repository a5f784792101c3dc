//! Behaviour check of RTN training through the shared loop (issue 11: "behaviour preserved").
//!
//! A tiny RTN whose every variable is set deterministically (independent of any initialiser)
//! is trained for 3 epochs on the clips of a BVH folder (every fourth clip validates) through
//! `zoo_nn::train_loop::train`, and each epoch's mean training and validation loss is printed
//! with 10 significant digits; the final weights are saved to `OUT_DIR` for `zoo bench` and
//! `zoo export`. The same program written against the code before the reshaping (the loop of
//! `zoo train rtn` then) printed the figures quoted in docs/adding-a-model.md. Run with
//! `RAYON_NUM_THREADS=1` for bit-identical results.
//!
//! Usage: `behaviour_check DATA_DIR OUT_DIR`

use candle_core::{Device, Tensor};
use zoo_data::dataset::{self, WindowOptions};
use zoo_nn::train_loop::{TrainOptions, train};
use zoo_rtn::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        return Err("usage: behaviour_check DATA_DIR OUT_DIR".into());
    }
    let (data, out) = (std::path::Path::new(&args[1]), std::path::Path::new(&args[2]));
    let clips = dataset::load(data)?;
    let (mut train_clips, mut valid_clips) = (Vec::new(), Vec::new());
    for (i, c) in clips.into_iter().enumerate() {
        if i % 4 == 3 { valid_clips.push(c) } else { train_clips.push(c) }
    }
    let tw = dataset::windows(&train_clips, &WindowOptions::TRAIN);
    let vw = dataset::windows(&valid_clips, &WindowOptions::TRAIN);
    let per = tw.window * tw.joints() * 3;
    let (tp, vp) = (tw.global_positions_f32(), vw.global_positions_f32());
    let train_w: Vec<MotionWindow> = tp.chunks_exact(per).map(MotionWindow::new).collect();
    let valid_w: Vec<MotionWindow> = vp.chunks_exact(per).map(MotionWindow::new).collect();
    let mut config = Config::tiny().with_parents(&tw.skeleton.parents);
    config.train.batch_size = 8;
    config.train.learning_rate = 1e-3;
    config.train.seed = 1;
    config.train.ema_decay = None;
    let stats = fit_stats(&config, &train_w)?;
    let trainer = RtnTrainer::new(&config, stats, &Device::Cpu)?;
    {
        let vars = trainer.varmap().data().lock().map_err(|_| "variable map lock poisoned")?;
        let mut names: Vec<&String> = vars.keys().collect();
        names.sort();
        for (k, name) in names.iter().enumerate() {
            let var = &vars[*name];
            let n = var.as_tensor().elem_count();
            let v: Vec<f32> = (0..n).map(|i| 0.1 * (0.37 * i as f32 + 1.3 * k as f32).sin()).collect();
            var.set(&Tensor::from_vec(v, var.as_tensor().dims(), &Device::Cpu)?)?;
        }
    }
    println!("{} training / {} validation windows", train_w.len(), valid_w.len());
    let mut training = RtnTraining::new(trainer, &train_w, &valid_w)?;
    let mut opts = TrainOptions::new(out.join("loop"), 3, config.train.seed);
    opts.progress = false;
    opts.print = false;
    let state = train(&mut training, &opts)?;
    for e in 0..state.epoch {
        println!(
            "epoch {}: train {:.9e} valid {:.9e} averaged {:.9e}",
            e + 1,
            state.train_loss[e],
            state.valid_loss[e],
            state.valid_loss_ema.get(e).copied().unwrap_or(state.valid_loss[e])
        );
    }
    training.into_trainer().save(out)?;
    println!("saved {}", out.display());
    Ok(())
}
