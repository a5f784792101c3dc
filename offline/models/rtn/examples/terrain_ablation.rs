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
//!   above the terrain nor sink into it;
//! - L2P (the benchmark's, `zoo_data::metrics::l2p`): global positions of the transition
//!   frames in the window's benchmark frame (facing unified at the last context frame, as
//!   `zoo_data::dataset::prepare_window` does), normalized with the position statistics of
//!   the training windows prepared the same way (`dataset::position_stats`);
//! - foot penetration: depth of the foot joints (`foot`, `toe`) below the terrain surface,
//!   `max(0, terrain - y)`, over the foot joints and transition frames (cm): mean and 99th
//!   percentile, the model's and the ground truth's (the data's own floor).
//!
//! Run both variants with the same `STEPS` for an equal budget.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

use candle_core::Device;
use zoo_data::dataset::{self, NamedClip, WindowOptions};
use zoo_data::synth::{self, SynthConfig};
use zoo_motion::glam::{DQuat, DVec3};
use zoo_rtn::features::Heightmap;
use zoo_rtn::prelude::*;

/// Global positions of frames `frames` of a flat window (`3K` per frame) rotated by `rot`.
fn rotated(w: &[f32], frames: std::ops::Range<usize>, k: usize, rot: DQuat) -> Vec<DVec3> {
    w[frames.start * 3 * k..frames.end * 3 * k]
        .chunks_exact(3)
        .map(|p| rot * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect()
}

/// Mean and 99th percentile of `v` (0 for an empty `v`).
fn mean_p99(v: &mut [f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    v.sort_by(f64::total_cmp);
    let p99 = v[((v.len() - 1) as f64 * 0.99).round() as usize];
    (v.iter().sum::<f64>() / v.len() as f64, p99)
}

struct Sequence {
    positions: Vec<f32>,
    frames: usize,
    map: Heightmap,
    /// Global root rotation of each frame (for the benchmark frame of L2P).
    root_rot: Vec<DQuat>,
}

fn sequences(clips: &[synth::SynthClip]) -> Vec<Sequence> {
    clips
        .iter()
        .map(|c| {
            let (gr, gp) = c.clip.global();
            let j = c.clip.joints();
            Sequence {
                positions: gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect(),
                frames: c.clip.frames(),
                map: c.terrain.as_ref().expect("terrain clips").clone(),
                root_rot: gr.iter().step_by(j).copied().collect(),
            }
        })
        .collect()
}

// Kept whole: an experiment script whose steps print in the order they run (data, the runs,
// the table), read top to bottom beside its output.
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
    let train_clips: Vec<_> = train_clips.into_iter().map(|(_, c)| c).collect();
    // L2P's statistics: the benchmark's, on the training clips' prepared windows.
    let named: Vec<NamedClip> = train_clips
        .iter()
        .map(|c| NamedClip { name: c.name.clone(), path: c.name.clone().into(), clip: c.clip.clone() })
        .collect();
    let tw = dataset::windows(&named, &WindowOptions::TRAIN);
    let position_std = dataset::position_stats(&tw.global().1, tw.joints()).std;
    drop((named, tw));
    let train = sequences(&train_clips);
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
        let (mut l2p, mut windows) = (0f64, 0usize);
        let (mut pen, mut pen_gt) = (Vec::new(), Vec::new());
        for s in &test {
            let mut f = 0;
            while f + 10 + n + 2 <= s.frames {
                let w = &s.positions[f * d..];
                let past = &w[..10 * d];
                let (target, next) = (&w[(10 + n) * d..(11 + n) * d], &w[(11 + n) * d..(12 + n) * d]);
                let y = model.transition(stats, past, target, next, n, aware.then_some(&s.map))?;
                let fwd = s.root_rot[f + 9] * WindowOptions::TRAIN.forward_axis;
                let inv =
                    zoo_motion::facing::yaw_between(DVec3::X, DVec3::new(fwd.x, 0.0, fwd.z).normalize()).inverse();
                l2p += zoo_data::metrics::l2p(
                    &rotated(&y, 0..n, k, inv),
                    &rotated(w, 10..10 + n, k, inv),
                    k,
                    &position_std,
                );
                windows += 1;
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
                        pen.push((-clear_p).max(0.0) as f64);
                        pen_gt.push((-clear_g).max(0.0) as f64);
                    }
                }
                f += 40;
            }
        }
        let ((pm, p99), (gm, g99)) = (mean_p99(&mut pen), mean_p99(&mut pen_gt));
        println!(
            "n = {n}: MPJPE {:.2} cm, L2P {:.4}, foot clearance error {:.2} cm, foot penetration mean {pm:.2} cm, \
             p99 {p99:.2} cm (ground truth {gm:.2}, {g99:.2}) ({} frames, {windows} windows)",
            err / count.max(1) as f64,
            l2p / windows.max(1) as f64,
            ground / gcount.max(1) as f64,
            count / k.max(1)
        );
    }
    Ok(())
}
