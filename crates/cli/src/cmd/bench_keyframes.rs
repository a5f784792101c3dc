//! `zoo bench keyframes --model arnn.onnx`: the exported ARNN's per-frame step through tract
//! (`zoo-runtime`) and onnxruntime, latency at batch 1 and throughput at batch 64, side by side
//! in one run; and whole completions through the runtime's keyframes task
//! (`zoo_runtime::keyframes::KeyframeRunner`, tract).
//!
//! Each backend runs on one thread (onnxruntime with one intra-op thread; tract is
//! single-threaded); the backends take turns round by round so that machine noise hits them
//! alike. The figure per backend is the median over rounds of the mean step time. Inputs are
//! the lamp's rest pose with small deterministic offsets, keys a hop apart.

use crate::cmd::bench_runtime::onnxruntime_library;
use anyhow::{Context, anyhow, bail};
use std::borrow::Cow;
use std::time::Instant;
use zoo_runtime::keyframes::MotionKeys;
use zoo_runtime::{MotionState, MotionTaskKind};

/// Figures of one backend at one batch size (`backend`: `tract step`, `onnxruntime step` or
/// `tract completion`).
pub use crate::cmd::bench_runtime::BackendFigure as KeyframesFigure;
/// Arguments of `zoo bench keyframes`: those of `zoo bench runtime` (`--model` names an
/// exported ARNN here).
pub use crate::cmd::bench_runtime::RuntimeArgs as KeyframesBenchArgs;

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

trait Backend {
    fn step(&mut self) -> anyhow::Result<()>;
    fn output(&self) -> &[f32];
}

struct Tract {
    runner: zoo_runtime::MotionRunner,
    states: Vec<MotionState>,
    inputs: Vec<Vec<f32>>,
    out: Vec<f32>,
}

impl Backend for Tract {
    fn step(&mut self) -> anyhow::Result<()> {
        let inputs: Vec<&[f32]> = self.inputs.iter().map(Vec::as_slice).collect();
        self.runner.step_batch(&mut self.states, &inputs, &mut [&mut self.out])?;
        Ok(())
    }
    fn output(&self) -> &[f32] {
        &self.out
    }
}

struct Ort {
    session: ort::session::Session,
    batch: usize,
    names: Vec<String>,
    inputs: Vec<Vec<f32>>,
    states: Vec<(String, String, Vec<f32>)>,
    out: Vec<f32>,
}

impl Backend for Ort {
    fn step(&mut self) -> anyhow::Result<()> {
        let b = self.batch;
        let tensor = |data: &[f32]| {
            ort::value::Tensor::from_array((vec![b as i64, (data.len() / b) as i64], data.to_vec()))
                .map_err(|e| anyhow!("onnxruntime tensor: {e}"))
        };
        let mut values: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = Vec::new();
        for (name, data) in self.names.iter().zip(&self.inputs) {
            values.push((Cow::Owned(name.clone()), tensor(data)?.into()));
        }
        for (input, _, data) in &self.states {
            values.push((Cow::Owned(input.clone()), tensor(data)?.into()));
        }
        let out = self.session.run(values).map_err(|e| anyhow!("onnxruntime run: {e}"))?;
        let extract = |name: &str| -> anyhow::Result<Vec<f32>> {
            Ok(out[name]
                .try_extract_tensor::<f32>()
                .map_err(|e| anyhow!("onnxruntime output `{name}`: {e}"))?
                .1
                .to_vec())
        };
        let pose = extract("pose")?;
        let next: Vec<Vec<f32>> = self.states.iter().map(|(_, o, _)| extract(o)).collect::<anyhow::Result<_>>()?;
        drop(out);
        self.out = pose;
        for (slot, v) in self.states.iter_mut().zip(next) {
            slot.2 = v;
        }
        Ok(())
    }
    fn output(&self) -> &[f32] {
        &self.out
    }
}

/// Whole completions of [`KEY_FRAMES`] through the keyframes runner; one "step" is one frame of
/// every character (the completion's time divided by its frames).
struct Completion {
    runner: zoo_runtime::keyframes::KeyframeRunner,
    keys: Vec<Vec<f32>>,
    out: Vec<Vec<f32>>,
}

impl Completion {
    fn run(&mut self) -> anyhow::Result<()> {
        let keys: Vec<MotionKeys> = self.keys.iter().map(|p| MotionKeys::whole(&KEY_FRAMES, p)).collect();
        let mut outs: Vec<&mut [f32]> = self.out.iter_mut().map(|o| o.as_mut_slice()).collect();
        self.runner.complete_batch(&keys, &mut outs)?;
        Ok(())
    }
}

fn median(v: &[f64]) -> f64 {
    zoo_data::dataset::percentile(&mut v.to_vec(), 50.0)
}

/// Runs `zoo bench keyframes`.
pub fn run(a: KeyframesBenchArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.json {
        crate::cmd::check_output_file("--json", path)?;
    }
    let bytes = std::fs::read(&a.model).with_context(|| format!("reading {}", a.model.display()))?;
    let km =
        crate::exported::load(&a.model, &[MotionTaskKind::Keyframes], "`zoo bench keyframes`")?.into_keyframes()?;
    let model = km.model().clone();
    let d = km.dofs();
    let lib = onnxruntime_library(&a.onnxruntime)?;
    let env = ort::init_from(&lib)
        .map_err(|e| anyhow!("cannot load onnxruntime from {}: {e}", lib.display()))?
        .build()
        .map_err(|e| anyhow!("onnxruntime environment: {e}"))?;
    println!(
        "{}: ARNN step graph, {d} degrees of freedom; onnxruntime {}; one thread per backend",
        a.model.display(),
        lib.display()
    );
    let mut figures = Vec::new();
    for &batch in &a.batch {
        let names: Vec<String> = model.inputs().iter().map(|i| i.name.clone()).collect();
        let t_rel: Vec<f32> = offsets(batch, 9, 0.5).iter().map(|v| v + 0.5).collect();
        let inputs = vec![poses(batch, d, 1), poses(batch, d, 2), poses(batch, d, 3), t_rel];
        let states: Vec<Vec<f32>> =
            model.states().iter().enumerate().map(|(k, s)| offsets(batch * s.width, 20 + k as u64, 0.3)).collect();
        let mut tract_states: Vec<MotionState> = (0..batch).map(|_| model.new_state()).collect();
        for (c, s) in tract_states.iter_mut().enumerate() {
            for (k, info) in model.states().iter().enumerate() {
                s.slot_mut(k).copy_from_slice(&states[k][c * info.width..(c + 1) * info.width]);
            }
        }
        let session = ort::session::Session::builder(&env)
            .map_err(|e| anyhow!("onnxruntime session: {e}"))?
            .with_intra_threads(1)
            .map_err(|e| anyhow!("onnxruntime session options: {e}"))?
            .with_inter_threads(1)
            .map_err(|e| anyhow!("onnxruntime session options: {e}"))?
            .commit_from_memory(&bytes)
            .map_err(|e| anyhow!("onnxruntime cannot load the model: {e}"))?;
        let mut backends: Vec<(&str, Box<dyn Backend>)> = vec![
            (
                "tract step",
                Box::new(Tract {
                    runner: model.runner()?,
                    states: tract_states,
                    inputs: inputs.clone(),
                    out: vec![0.0; batch * d],
                }),
            ),
            (
                "onnxruntime step",
                Box::new(Ort {
                    session,
                    batch,
                    names,
                    inputs,
                    states: model
                        .states()
                        .iter()
                        .zip(states)
                        .map(|(s, v)| (s.input.clone(), s.output.clone(), v))
                        .collect(),
                    out: vec![],
                }),
            ),
        ];
        // Agreement on the first step (same inputs and state), then a warm-up.
        for (name, b) in backends.iter_mut() {
            b.step().with_context(|| name.to_string())?;
        }
        let diff = backends[0]
            .1
            .output()
            .iter()
            .zip(backends[1].1.output())
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max);
        if backends[0].1.output().len() != backends[1].1.output().len() || diff > 1e-3 {
            bail!("onnxruntime disagrees with tract on the first step (max abs diff {diff})");
        }
        for (_, b) in backends.iter_mut() {
            for _ in 0..5 {
                b.step()?;
            }
        }
        let mut completion = Completion {
            runner: km.runner(batch)?,
            keys: (0..batch).map(|c| poses(KEY_FRAMES.len(), d, 100 + c as u64)).collect(),
            out: vec![vec![0.0; (KEY_FRAMES[8] + 1) * d]; batch],
        };
        completion.run()?;
        let steps = (a.work / batch).max(5);
        let completions = (a.work / (batch * KEY_FRAMES[8])).max(1);
        let mut times: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(a.rounds)).collect();
        for _ in 0..a.rounds {
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
        for (name, t) in ["tract step", "onnxruntime step", "tract completion"].iter().zip(times) {
            let step_ms = median(&t);
            figures.push(KeyframesFigure {
                backend: name.to_string(),
                batch,
                step_ms,
                frames_per_second: batch as f64 * 1e3 / step_ms,
                rounds_ms: t,
            });
        }
    }
    println!(
        "median of {} rounds, ~{} character-steps per backend per round (completion: 86 frames per call)",
        a.rounds, a.work
    );
    println!("{:<6} {:<18} {:>12} {:>16} {:>10}", "batch", "backend", "step (ms)", "frames/s", "time/ort");
    for f in &figures {
        let ort = figures
            .iter()
            .find(|g| g.batch == f.batch && g.backend == "onnxruntime step")
            .map_or(f64::NAN, |o| o.step_ms);
        println!(
            "{:<6} {:<18} {:>12.4} {:>16.0} {:>9.2}x",
            f.batch,
            f.backend,
            f.step_ms,
            f.frames_per_second,
            f.step_ms / ort
        );
    }
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&figures)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
