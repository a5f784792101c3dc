//! The exported ARNN's per-frame step through tract (`zoo-runtime`) and onnxruntime, latency
//! at batch 1 and throughput at batch 64, side by side in one run; and whole completions
//! through the runtime's keyframes task (`zoo_runtime::keyframes::KeyframeRunner`, tract):
//! `zoo bench keyframes --model arnn.onnx`.
//!
//! Each backend runs on one thread (onnxruntime with one intra-op thread; tract is
//! single-threaded); the backends take turns round by round so that machine noise hits them
//! alike. The figure per backend is the median over rounds of the mean step time. Inputs are
//! the lamp's rest pose with small deterministic offsets, keys a hop apart.

use crate::Result;
use crate::runtime::{
    BackendFigure, Frame, RuntimeOptions, StepBackend, onnxruntime_env, onnxruntime_library, ort_backend, tract_backend,
};
use std::time::Instant;
use zoo_data::{Context, bail};
use zoo_runtime::MotionModel;
use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};

/// Rest pose of the lamp (base x, y, angle, three joint angles).
const REST: [f32; 6] = [0.0, 0.02, 0.0, 0.5, -1.1, -1.2];
/// Key frames of the whole-completion figure: three hops of the training data's layout.
const KEY_FRAMES: [usize; 9] = [0, 12, 24, 31, 43, 55, 62, 74, 86];

fn offsets(n: usize, seed: u64, scale: f32) -> Vec<f32> {
    let mut rng = zoo_motion::rng::SplitMix64::new(seed);
    (0..n).map(|_| scale * (2.0 * rng.next_f64() - 1.0) as f32).collect()
}

/// Poses around the rest pose, `batch` rows of `d`.
fn poses(batch: usize, d: usize, seed: u64) -> Vec<f32> {
    offsets(batch * d, seed, 0.1).iter().enumerate().map(|(i, o)| REST.get(i % d).copied().unwrap_or(0.0) + o).collect()
}

/// Whole completions of [`KEY_FRAMES`] through the keyframes runner; one "step" is one frame of
/// every character (the completion's time divided by its frames).
struct Completion {
    runner: zoo_runtime::keyframes::KeyframeRunner,
    keys: Vec<Vec<f32>>,
    out: Vec<Vec<f32>>,
}

impl Completion {
    fn run(&mut self) -> Result<()> {
        let keys: Vec<MotionKeys> = self.keys.iter().map(|p| MotionKeys::whole(&KEY_FRAMES, p)).collect();
        let mut outs: Vec<&mut [f32]> = self.out.iter_mut().map(|o| o.as_mut_slice()).collect();
        self.runner.complete_batch(&keys, &mut outs)?;
        Ok(())
    }
}

/// The step backends at batch `batch`, from the same inputs and state.
fn backends(
    model: &MotionModel,
    d: usize,
    bytes: &[u8],
    env: &ort::environment::Environment,
    batch: usize,
) -> Result<Vec<(&'static str, Box<dyn StepBackend>)>> {
    let names: Vec<String> = model.inputs().iter().map(|i| i.name.clone()).collect();
    let t_rel: Vec<f32> = offsets(batch, 9, 0.5).iter().map(|v| v + 0.5).collect();
    let frame = Frame { names, data: vec![poses(batch, d, 1), poses(batch, d, 2), poses(batch, d, 3), t_rel] };
    let states: Vec<Vec<f32>> =
        model.states().iter().enumerate().map(|(k, s)| offsets(batch * s.width, 20 + k as u64, 0.3)).collect();
    let tract = tract_backend(model, &frame, &states, batch)?;
    let ort = ort_backend(env, bytes, model, frame, states, batch)?;
    Ok(vec![("tract step", Box::new(tract)), ("onnxruntime step", Box::new(ort))])
}

/// Agreement on the first step (same inputs and state), then a warm-up.
fn check_agreement(backends: &mut [(&'static str, Box<dyn StepBackend>)]) -> Result<()> {
    for (name, b) in backends.iter_mut() {
        b.step().context(name.to_string())?;
    }
    let (a, b) = (backends[0].1.output(), backends[1].1.output());
    let diff = a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
    if a.len() != b.len() || diff > 1e-3 {
        bail!("onnxruntime disagrees with tract on the first step (max abs diff {diff})");
    }
    for (_, b) in backends.iter_mut() {
        for _ in 0..5 {
            b.step()?;
        }
    }
    Ok(())
}

/// The figures of the step backends and the whole completions at batch `batch`.
fn measure(
    o: &RuntimeOptions,
    km: &KeyframeModel,
    bytes: &[u8],
    env: &ort::environment::Environment,
    batch: usize,
) -> Result<Vec<BackendFigure>> {
    let d = km.dofs();
    let Some(step) = km.step_model() else { bail!("{}: no per-frame step graph", o.model.display()) };
    let mut backends = backends(step, d, bytes, env, batch)?;
    check_agreement(&mut backends)?;
    let mut completion = Completion {
        runner: km.runner(batch)?,
        keys: (0..batch).map(|c| poses(KEY_FRAMES.len(), d, 100 + c as u64)).collect(),
        out: vec![vec![0.0; (KEY_FRAMES[8] + 1) * d]; batch],
    };
    completion.run()?;
    let steps = (o.work / batch).max(5);
    let completions = (o.work / (batch * KEY_FRAMES[8])).max(1);
    let mut times: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(o.rounds)).collect();
    for _ in 0..o.rounds {
        for (k, (_, b)) in backends.iter_mut().enumerate() {
            let t = Instant::now();
            for _ in 0..steps {
                b.step()?;
            }
            times[k].push(t.elapsed().as_secs_f64() * 1e3 / steps as f64);
        }
        let t = Instant::now();
        for _ in 0..completions {
            completion.run()?;
        }
        times[2].push(t.elapsed().as_secs_f64() * 1e3 / (completions * KEY_FRAMES[8]) as f64);
    }
    Ok(["tract step", "onnxruntime step", "tract completion"]
        .iter()
        .zip(times)
        .map(|(name, t)| BackendFigure::new(name, batch, t))
        .collect())
}

/// Runs `zoo bench keyframes` on `km`, the ARNN step-graph export loaded from `o.model` (the
/// in-betweening design is timed by `crate::whole_shot`): the header line and the figures.
pub fn run(o: &RuntimeOptions, km: &KeyframeModel) -> Result<(String, Vec<BackendFigure>)> {
    let bytes = std::fs::read(&o.model).with_context(|| format!("reading {}", o.model.display()))?;
    let lib = onnxruntime_library(o.onnxruntime.as_deref())?;
    let env = onnxruntime_env(&lib)?;
    let header = format!(
        "{}: ARNN step graph, {} degrees of freedom; onnxruntime {}; one thread per backend",
        o.model.display(),
        km.dofs(),
        lib.display()
    );
    let mut figures = Vec::new();
    for &batch in &o.batch {
        figures.extend(measure(o, km, &bytes, &env, batch)?);
    }
    Ok((header, figures))
}

/// The figures as a text table with the time ratio to onnxruntime's step.
pub fn table(figures: &[BackendFigure], rounds: usize, work: usize) -> String {
    let mut s = format!(
        "median of {rounds} rounds, ~{work} character-steps per backend per round (completion: 86 frames per call)\n"
    );
    s += &format!("{:<6} {:<18} {:>12} {:>16} {:>10}\n", "batch", "backend", "step (ms)", "frames/s", "time/ort");
    for f in figures {
        let ort = figures
            .iter()
            .find(|g| g.batch == f.batch && g.backend == "onnxruntime step")
            .map_or(f64::NAN, |o| o.step_ms);
        s += &format!(
            "{:<6} {:<18} {:>12.4} {:>16.0} {:>9.2}x\n",
            f.batch,
            f.backend,
            f.step_ms,
            f.frames_per_second,
            f.step_ms / ort
        );
    }
    s.trim_end().to_string()
}
