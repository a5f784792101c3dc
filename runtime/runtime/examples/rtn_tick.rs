//! An engine tick loop with an exported RTN: characters walk, and every second each one starts
//! a transition to a new target pose, which then plays one frame per tick (target-blended, ending
//! on the target).
//!
//! `cargo run --release -p zoo-runtime --example rtn_tick -- rtn.onnx [CHARACTERS]`
//! (`rtn.onnx` from `zoo export --onnx RUN_DIR --out rtn.onnx`).
//!
//! Poses are built from the model's own skeleton (rest pose from its offsets, sliding forward)
//! so that the example needs nothing but the file. A rest pose (often a T-pose) is far from
//! the motion an RTN was trained on, so the generated frames are not meant to look good here:
//! the example shows the calls an engine makes and what a batched step costs. Each tick advances every character in one batched graph
//! run and hands the poses to the "engine" as glam vectors.

use std::time::Instant;
use zoo_runtime::glam::Vec3;
use zoo_runtime::prelude::*;

/// Global joint positions of the rest pose with the root at `root`.
fn rest_pose(skeleton: &MotionSkeletonInfo, root: Vec3) -> Vec<f32> {
    let mut global = vec![Vec3::ZERO; skeleton.len()];
    for j in 0..skeleton.len() {
        global[j] = match usize::try_from(skeleton.parents[j]) {
            Ok(p) => global[p] + skeleton.offset(j),
            Err(_) => root,
        };
    }
    global.iter().flat_map(|p| p.to_array()).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!(
            "usage: rtn_tick MODEL.onnx [CHARACTERS] (export one with `zoo export --onnx RUN_DIR --out rtn.onnx`)"
        );
        std::process::exit(2);
    };
    let characters: usize = std::env::args().nth(2).map_or(Ok(8), |s| s.parse())?;
    // Load once at level start; `model` is Send + Sync and cheap to clone.
    let model = TransitionModel::load(&path)?;
    let skeleton = model.model().metadata().skeleton.clone();
    let fps = model.model().metadata().fps;
    let (k, past_frames) = (model.joints(), model.past_frames());
    let d = 3 * k;
    // Each transition plays its trained length and ends on its target frame.
    let frames = model.transition_frames() + 1;
    let mut runner = model.runner()?; // one per worker thread
    let mut states: Vec<TransitionState> = (0..characters).map(|_| model.new_transition()).collect();
    let mut poses = vec![0.0f32; characters * d];
    let mut joints = vec![Vec3::ZERO; k];
    // Character c walks along +Z at 1.2 m/s, 2 m apart from the others.
    let speed = 120.0 / fps;
    let root_at = |c: usize, f: usize| Vec3::new(200.0 * c as f32, 90.0, speed * f as f32);

    let ticks = 3 * frames;
    let mut step_time = 0.0;
    for tick in 0..ticks {
        if tick % frames == 0 {
            // Start transitions: the last `past_frames` frames played, a target one second ahead.
            let mut past = Vec::with_capacity(characters * past_frames * d);
            let (mut target, mut next) = (Vec::new(), Vec::new());
            for c in 0..characters {
                for f in 0..past_frames {
                    past.extend(rest_pose(&skeleton, root_at(c, tick + f)));
                }
                let t = tick + past_frames + frames;
                target.extend(rest_pose(&skeleton, root_at(c, t)));
                next.extend(rest_pose(&skeleton, root_at(c, t + 1)));
            }
            runner.start_batch(&mut states, &past, &target, &next)?;
        }
        let t0 = Instant::now();
        runner.step_batch(&mut states, &mut poses)?; // one graph run for every character
        step_time += t0.elapsed().as_secs_f64();
        // Hand character 0's pose to the engine.
        zoo_runtime::pose::read_positions(&poses[..d], &mut joints);
        if tick % 10 == 9 {
            let target = Vec3::from_slice(&states[0].target()[..3]);
            println!(
                "tick {:3}: hips {:>7.1?}  |hips - target hips| {:6.1} cm",
                tick + 1,
                joints[0],
                joints[0].distance(target)
            );
        }
    }
    println!("{ticks} ticks of {characters} characters: {:.3} ms per batched step", step_time * 1e3 / ticks as f64);
    Ok(())
}
