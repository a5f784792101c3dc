//! Sanity run of the generator on synthetic locomotion: trains a small RNN-GMM for a time
//! budget, synthesises sequences continuing validation clips, and prints motion statistics of the
//! generated and the real frames (root speed, frozen fraction, joint speed, foot skate).
//!
//! `cargo run --example synth_sanity -- [MINUTES_OF_DATA] [TRAIN_SECONDS] [OUT_DIR]`
//! (defaults 4, 180, a temporary folder).

use candle_core::Device;
use zoo_data::synth::{SynthConfig, generate};
use zoo_motion::Clip;
use zoo_nn::train_loop::{TrainOptions, train};
use zoo_rnngmm::prelude::*;
use zoo_rnngmm::{DecodedMotion, TrainingData};

/// Mean root speed (cm/s), fraction of frames with a root speed below 10 cm/s and a joint
/// rotation change below 0.01 rad, mean joint rotation change (rad/frame), foot skate (cm/frame:
/// horizontal foot speed on frames whose contact bit is set).
fn stats(spec: &FeatureSpec, m: &DecodedMotion) -> [f64; 4] {
    let clip = &m.clip;
    let (n, j) = (clip.frames(), clip.joints());
    let (_, gp) = clip.global();
    let fps = clip.fps();
    let (mut speed, mut frozen, mut turn, mut skate, mut planted) = (0.0, 0usize, 0.0, 0.0, 0usize);
    for f in 1..n {
        let d = clip.root_position(f) - clip.root_position(f - 1);
        let v = d.x.hypot(d.z) * fps;
        let mut rot = 0.0;
        for k in 1..j {
            let (a, b) = (clip.local_rotations[f * j + k], clip.local_rotations[(f - 1) * j + k]);
            rot += a.angle_between(b);
        }
        rot /= (j - 1) as f64;
        speed += v;
        turn += rot;
        frozen += usize::from(v < 10.0 && rot < 0.01);
        for (side, foot) in [&spec.left_foot, &spec.right_foot].iter().enumerate() {
            if m.contacts[f][side] {
                let a = foot[0];
                let d = gp[f * j + a] - gp[(f - 1) * j + a];
                skate += d.x.hypot(d.z);
                planted += 1;
            }
        }
    }
    let k = (n - 1) as f64;
    [speed / k, frozen as f64 / k, turn / k, if planted > 0 { skate / planted as f64 } else { 0.0 }]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let minutes: f64 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(4.0);
    let seconds: u64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(180);
    let tmp = tempfile_dir();
    let out = args.get(3).map(std::path::PathBuf::from).unwrap_or(tmp);
    let synth = generate(&SynthConfig { minutes, seed: 1, terrain: false, fps: 30.0, clip_seconds: 10.0 });
    let clips: Vec<&Clip> = synth.iter().map(|s| &s.clip).collect();
    let n_valid = (clips.len() / 8).max(1);
    let (train_clips, valid_clips) = clips.split_at(clips.len() - n_valid);
    let mut config = Config::paper();
    config.fc = vec![128, 128, 128];
    config.lstm = 256;
    let data = TrainingData::from_clips(&config, 30.0, train_clips, valid_clips)?;
    let config = config.with_dim(data.spec.dim());
    println!(
        "{} training / {} validation windows of {} frames; generator {} x3 FC, 2 x {} LSTM",
        data.train.len(),
        data.valid.len(),
        config.train.window,
        config.fc[0],
        config.lstm
    );
    let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu)?;
    let mut training = GeneratorTraining::new(trainer, &data.train, &data.valid)?;
    let opts = TrainOptions {
        time_limit: Some(std::time::Duration::from_secs(seconds)),
        progress: false,
        ..TrainOptions::new(&out, 1000, 1)
    };
    train(&mut training, &opts)?;
    let model = checkpoint::load(&out, &Device::Cpu)?;
    println!("sequence      root cm/s  frozen  joint rad/frame  skate cm/frame");
    for (i, clip) in valid_clips.iter().enumerate() {
        let real = model.spec.decode(&model.spec.encode(clip)?.values, RootPlacement::default())?;
        let r = stats(&model.spec, &real);
        println!("real {i}       {:9.1}  {:6.3}  {:15.4}  {:14.3}", r[0], r[1], r[2], r[3]);
        let o = SynthesisOptions { frames: 600, seed: i as u64 + 1, ..SynthesisOptions::default() };
        let s = synthesize(&model, None, clip, 10, &o)?;
        let g = stats(&model.spec, &s.motion);
        println!("generated {i}  {:9.1}  {:6.3}  {:15.4}  {:14.3}", g[0], g[1], g[2], g[3]);
        let last = s.motion.clip.slice(450, 600);
        let tail = DecodedMotion { clip: last, contacts: s.motion.contacts[450..].to_vec() };
        let t = stats(&model.spec, &tail);
        println!("  last 5 s    {:9.1}  {:6.3}  {:15.4}  {:14.3}", t[0], t[1], t[2], t[3]);
    }
    Ok(())
}

fn tempfile_dir() -> std::path::PathBuf {
    std::env::temp_dir().join(format!("rnngmm-sanity-{}", std::process::id()))
}
