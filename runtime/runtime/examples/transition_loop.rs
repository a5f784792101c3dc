//! Plays transitions in a loop the way an engine tick would.
//!
//! `cargo run -p zoo-runtime --example transition_loop [-- MODEL.onnx]`
//!
//! Without a model path it writes a small toy step graph first (a GRU that pulls two joints
//! towards a target pose; fixed weights), so the example runs from a fresh checkout. Each
//! tick advances every character by one frame in one batched call, then hands the joint
//! positions to the "engine" as glam vectors. A transition restarts every 30 frames.

use std::time::Instant;
use zoo_export::{Dim, GraphBuilder, RnnDirection, RnnInputs};
use zoo_runtime::glam::Vec3;
use zoo_runtime::metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
    MotionTask,
};
use zoo_runtime::prelude::*;

const JOINTS: usize = 2;
const FRAME: usize = JOINTS * 3;
const HIDDEN: usize = 8;
const CHARACTERS: usize = 4;
const TRANSITION: usize = 30;

/// A toy step graph: `pose_next = pose + W_out · GRU([pose, target], h)`.
fn toy_model(path: &std::path::Path) -> Result<(), Box<dyn std::error::Error>> {
    let mut g = GraphBuilder::new("toy_transition_step");
    let meta = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: "toy_transition".into(),
        task: MotionTask::Step,
        config_json: format!("{{\"hidden\": {HIDDEN}}}"),
        normalization: [("pose".to_string(), MotionMeanStd { mean: vec![0.0; FRAME], std: vec![1.0; FRAME] })].into(),
        skeleton: MotionSkeletonInfo {
            names: vec!["Hips".into(), "Head".into()],
            parents: vec![-1, 0],
            offsets: vec![[0.0; 3], [0.0, 60.0, 0.0]],
        },
        feature_layout: vec![MotionFeatureSegment { name: "positions".into(), start: 0, len: FRAME }],
        fps: 30.0,
        frame: zoo_runtime::metadata::CoordinateFrame::ZOO_CM,
        state: vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        weights: zoo_runtime::metadata::WeightWidth::F32,
    };
    for (k, v) in meta.to_props() {
        g.metadata(&k, &v);
    }
    let b = Dim::batch;
    let pose = g.input("pose", &[b(), Dim::Fixed(FRAME)]);
    let target = g.input("target", &[b(), Dim::Fixed(FRAME)]);
    let h = g.input("h", &[b(), Dim::Fixed(HIDDEN)]);
    let offset = g.sub("offset", &target, &pose);
    let x = g.concat("frame_input", &[&pose, &offset], 1);
    let x = g.unsqueeze("gru.x_seq", &x, &[0]);
    let h0 = g.unsqueeze("gru.h0", &h, &[0]);
    let wv: Vec<f32> = (0..3 * HIDDEN * 2 * FRAME).map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) * 0.3).collect();
    let rv: Vec<f32> = (0..3 * HIDDEN * HIDDEN).map(|i| ((i * 53 % 97) as f32 / 97.0 - 0.5) * 0.3).collect();
    let w = g.initializer_f32("gru.weight_ih_l0", &[1, 3 * HIDDEN, 2 * FRAME], &wv);
    let r = g.initializer_f32("gru.weight_hh_l0", &[1, 3 * HIDDEN, HIDDEN], &rv);
    let rnn = RnnInputs {
        x: &x,
        w: &w,
        r: &r,
        b: None,
        initial_h: Some(&h0),
        hidden_size: HIDDEN,
        direction: RnnDirection::Forward,
    };
    let out = g.gru("gru", &rnn, true);
    let h_next = g.squeeze("h_next", &out.y_h, &[0]);
    let dv: Vec<f32> = (0..FRAME * HIDDEN).map(|i| ((i * 29 % 89) as f32 / 89.0 - 0.5) * 0.2).collect();
    let d = g.initializer_f32("decoder.weight", &[FRAME, HIDDEN], &dv);
    let delta = g.gemm("decoder", &h_next, &d, None, true);
    // Pull towards the target: pose + 0.2 * offset + delta
    let k = g.initializer_f32("blend.rate", &[1], &[0.2]);
    let pull = g.mul("blend.pull", &offset, &k);
    let next = g.add("blend.add", &pose, &pull);
    let next = g.add("pose_next_sum", &next, &delta);
    g.output("pose_next", &next, &[b(), Dim::Fixed(FRAME)]);
    g.output("h_next", &h_next, &[b(), Dim::Fixed(HIDDEN)]);
    g.finish()?.write(path)?;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = match std::env::args().nth(1) {
        Some(p) => p.into(),
        None => {
            let p = std::env::temp_dir().join("zoo_toy_transition.onnx");
            toy_model(&p)?;
            p
        }
    };
    // Load once at level start; share `model` between threads (it is Send + Sync).
    let model = MotionModel::load(&path)?;
    let mut runner = model.runner()?; // one per worker thread
    let mut states: Vec<MotionState> = (0..CHARACTERS).map(|_| model.new_state()).collect();
    let width = model.inputs()[0].width;
    let mut pose = vec![0.0f32; CHARACTERS * width];
    let mut target = vec![0.0f32; CHARACTERS * width];
    let mut next = vec![0.0f32; CHARACTERS * width];
    let mut joints = [Vec3::ZERO; JOINTS];

    let ticks = 3 * TRANSITION;
    let start = Instant::now();
    for tick in 0..ticks {
        if tick % TRANSITION == 0 {
            // Start a transition: new targets, fresh recurrent state.
            for c in 0..CHARACTERS {
                for (j, t) in target[c * width..(c + 1) * width].iter_mut().enumerate() {
                    *t = ((tick / TRANSITION + c + j) % 5) as f32 * 10.0;
                }
                states[c].reset();
            }
        }
        runner.step_batch(&mut states, &[&pose, &target], &mut [&mut next])?;
        std::mem::swap(&mut pose, &mut next);
        // Hand character 0's pose to the engine.
        for (j, p) in joints.iter_mut().enumerate() {
            *p = Vec3::from_slice(&pose[j * 3..j * 3 + 3]);
        }
        if tick % 10 == 9 {
            let dist = joints[0].distance(Vec3::from_slice(&target[..3]));
            println!(
                "tick {:3}: hips {:>6.2?}  head {:>6.2?}  |hips - target| {dist:.2}",
                tick + 1,
                joints[0],
                joints[1]
            );
        }
    }
    let per_tick = start.elapsed().as_secs_f64() * 1e3 / ticks as f64;
    println!("{ticks} ticks of {CHARACTERS} characters: {per_tick:.3} ms per tick (one batched step each)");
    Ok(())
}
