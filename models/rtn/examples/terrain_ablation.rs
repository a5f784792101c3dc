//! Terrain-aware vs terrain-unaware RTN on synthetic terrain (RTN paper, Table 3 setting).
//!
//! `MIMALLOC_PURGE_DELAY=-1 RAYON_NUM_THREADS=1 cargo run --release -p zoo-rtn --example terrain_ablation -- VARIANT [STEPS] [MINUTES]`
//!
//! `VARIANT` is `aware` or `unaware`. Generates `MINUTES` (default 20) of synthetic locomotion
//! over uneven terrain (slopes, steps, bumps; seed 7), every tenth clip held out, trains a
//! paper-size RTN for `STEPS` (default 300) AMSGrad steps of batch 32 on 50-frame windows
//! (offset 20) in world coordinates with their heightmaps, then generates transitions of 30
//! and 60 frames on the held-out clips (10 context frames, target frame and the one after it,
//! windows at offset 40) and prints, per length:
//!
//! - MPJPE: mean joint position error over the transition frames (cm);
//! - foot clearance error: mean |(foot height - terrain height under it) - the same for the
//!   ground truth| over the foot joints and transition frames (cm): feet should neither float
//!   above the terrain nor sink into it.
//!
//! Run both variants with the same `STEPS` for an equal budget.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use candle_core::Device;
use zoo_data::synth::{self, SynthConfig};
use zoo_rtn::features::Heightmap;
use zoo_rtn::prelude::*;

struct Sequence {
    positions: Vec<f32>,
    frames: usize,
    map: Heightmap,
}

fn sequences(clips: &[synth::SynthClip]) -> Vec<Sequence> {
    clips
        .iter()
        .map(|c| {
            let (_, gp) = c.clip.global();
            Sequence {
                positions: gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect(),
                frames: c.clip.frames(),
                map: c.terrain.as_ref().expect("terrain clips").clone(),
            }
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let aware = match args.get(1).map(String::as_str) {
        Some("aware") => true,
        Some("unaware") => false,
        _ => return Err("usage: terrain_ablation aware|unaware [STEPS] [MINUTES]".into()),
    };
    let steps: usize = args.get(2).map_or(Ok(300), |s| s.parse())?;
    let minutes: f64 = args.get(3).map_or(Ok(20.0), |s| s.parse())?;
    let cfg = SynthConfig { minutes, seed: 7, terrain: true, ..SynthConfig::default() };
    let clips = synth::generate(&cfg);
    let skeleton = clips[0].clip.skeleton.clone();
    let feet = zoo_data::metrics::foot_joints(&skeleton.names);
    let (train_clips, test_clips): (Vec<_>, Vec<_>) = clips.into_iter().enumerate().partition(|(i, _)| i % 10 != 9);
    let train = sequences(&train_clips.into_iter().map(|(_, c)| c).collect::<Vec<_>>());
    let test = sequences(&test_clips.into_iter().map(|(_, c)| c).collect::<Vec<_>>());

    let mut config = Config::paper().with_parents(&skeleton.parents);
    config.terrain = aware;
    let k = config.joints;
    let d = 3 * k;
    let window = config.window_frames();
    let mut windows = Vec::new();
    for s in &train {
        let mut f = 0;
        while f + window <= s.frames {
            windows.push(MotionWindow { positions: &s.positions[f * d..(f + window) * d], terrain: Some(&s.map) });
            f += 20;
        }
    }
    let stats = fit_stats(&config, &windows)?;
    let mut trainer = RtnTrainer::new(&config, stats, &Device::Cpu)?;
    println!(
        "terrain-{}: {} training windows from {} clips, {} test clips, {} steps of batch 32",
        if aware { "aware" } else { "unaware" },
        windows.len(),
        train.len(),
        test.len(),
        steps
    );
    let mut order: Vec<usize> = (0..windows.len()).collect();
    let mut rng = zoo_nn::rng::SplitMix64::new(7);
    let started = std::time::Instant::now();
    let mut pos = order.len();
    for step in 0..steps {
        if pos + 32 > order.len() {
            for i in (1..order.len()).rev() {
                order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
            }
            pos = 0;
        }
        let batch: Vec<MotionWindow> = order[pos..pos + 32]
            .iter()
            .map(|&i| MotionWindow { positions: windows[i].positions, terrain: windows[i].terrain })
            .collect();
        pos += 32;
        let loss = trainer.train_step(&batch)?;
        if step % 50 == 49 {
            println!("step {:4}: loss {loss:.4}  {:.0} s", step + 1, started.elapsed().as_secs_f64());
        }
    }
    let model = trainer.model();
    let stats = trainer.stats();
    for n in [30usize, 60] {
        let (mut err, mut count) = (0f64, 0usize);
        let (mut ground, mut gcount) = (0f64, 0usize);
        for s in &test {
            let mut f = 0;
            while f + 10 + n + 2 <= s.frames {
                let w = &s.positions[f * d..];
                let past = &w[..10 * d];
                let (target, next) = (&w[(10 + n) * d..(11 + n) * d], &w[(11 + n) * d..(12 + n) * d]);
                let y = model.transition(stats, past, target, next, n, aware.then_some(&s.map))?;
                for t in 0..n {
                    let (p, g) = (&y[t * d..(t + 1) * d], &w[(10 + t) * d..(11 + t) * d]);
                    for j in 0..k {
                        let e = (0..3).map(|a| (p[3 * j + a] - g[3 * j + a]).powi(2)).sum::<f32>().sqrt();
                        err += e as f64;
                        count += 1;
                    }
                    for &j in &feet {
                        let clear_g = g[3 * j + 1] - s.map.sample(g[3 * j], g[3 * j + 2]);
                        let clear_p = p[3 * j + 1] - s.map.sample(p[3 * j], p[3 * j + 2]);
                        ground += (clear_p - clear_g).abs() as f64;
                        gcount += 1;
                    }
                }
                f += 40;
            }
        }
        println!(
            "n = {n}: MPJPE {:.2} cm, foot clearance error {:.2} cm ({} frames)",
            err / count.max(1) as f64,
            ground / gcount.max(1) as f64,
            count / k.max(1)
        );
    }
    Ok(())
}
