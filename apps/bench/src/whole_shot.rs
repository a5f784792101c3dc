//! What a whole transition costs through the runtime (`zoo bench keyframes --model INB.onnx
//! [--against RTN.onnx] --gap N`): the in-betweening design fills a transition's gap in one call
//! of the keyframes task (`KeyframeRunner::complete_batch`, keys: the ten context frames and
//! the target), where the RTN starts a transition (`TransitionRunner::start_batch_for`, the
//! context through the network) and then steps once per frame, `N + 1` steps to the target.
//!
//! Both run through tract on one thread at each batch size; they take turns round by round so
//! that machine noise hits them alike. The figure per method is the median over rounds of the
//! mean time of one transition of the whole batch, on the wall clock and in the thread's CPU
//! time (on a shared machine, the wall clock also counts other work). Inputs are synthetic (the
//! benchmark times the computation, which does not depend on the values): poses near the rest
//! pose with small offsets for the keys, a walk in global positions for the RTN.

use crate::Result;
use crate::frame_budget::walk_positions;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;
use zoo_data::benchmark::N_PAST;
use zoo_data::{Context, bail};
use zoo_runtime::keyframes::{KeyframeModel, KeyframeRunner, MotionKeys};
use zoo_runtime::{LoadedModel, TransitionRunner, TransitionState};

/// One method's transitions at one batch size.
#[derive(Clone, Debug, Serialize)]
pub struct TransitionCost {
    /// `whole shot (one call)` or `RTN (start + steps)`.
    pub method: String,
    /// Characters per call.
    pub batch: usize,
    /// Frames generated between the last context frame and the target.
    pub gap: usize,
    /// Median over rounds of the mean wall time of one transition of the whole batch, ms.
    pub wall_ms: f64,
    /// The same in the thread's CPU time, ms.
    pub cpu_ms: f64,
    /// Every round's mean wall time, ms.
    pub rounds_wall_ms: Vec<f64>,
    /// Every round's mean CPU time, ms.
    pub rounds_cpu_ms: Vec<f64>,
}

/// A method that runs whole transitions of a batch.
trait Transitions {
    fn name(&self) -> String;
    fn run(&mut self) -> Result<()>;
}

/// The in-betweening design: one completion per transition.
struct WholeShot {
    runner: KeyframeRunner,
    frames: Vec<usize>,
    keys: Vec<Vec<f32>>,
    out: Vec<Vec<f32>>,
}

impl Transitions for WholeShot {
    fn name(&self) -> String {
        "whole shot (one call)".into()
    }

    fn run(&mut self) -> Result<()> {
        let keys: Vec<MotionKeys> = self.keys.iter().map(|p| MotionKeys::whole(&self.frames, p)).collect();
        let mut outs: Vec<&mut [f32]> = self.out.iter_mut().map(|o| o.as_mut_slice()).collect();
        self.runner.complete_batch(&keys, &mut outs)?;
        Ok(())
    }
}

/// The RTN: a start, then a step per frame to the target.
struct Recurrent {
    runner: TransitionRunner,
    states: Vec<TransitionState>,
    past: Vec<f32>,
    target: Vec<f32>,
    next: Vec<f32>,
    poses: Vec<f32>,
    gap: usize,
}

impl Transitions for Recurrent {
    fn name(&self) -> String {
        format!("RTN (start + {} steps)", self.gap + 1)
    }

    fn run(&mut self) -> Result<()> {
        self.runner.start_batch_for(&mut self.states, &self.past, &self.target, &self.next, self.gap)?;
        for _ in 0..=self.gap {
            self.runner.step_batch(&mut self.states, &mut self.poses)?;
        }
        Ok(())
    }
}

/// Key poses of a humanoid keyframe model (`3 + 4 J` values: root position, then unit
/// quaternions near identity) or, for other layouts, small values around zero.
fn key_poses(d: usize, keys: usize, character: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(keys * d);
    for k in 0..keys {
        let wave = |i: usize| (0.37 * (i + 7 * character + 13 * k) as f32).sin();
        if d > 3 && (d - 3) % 4 == 0 {
            out.extend_from_slice(&[40.0 * character as f32, 90.0, 4.0 * k as f32]);
            for j in 0..(d - 3) / 4 {
                let (x, y, z) = (0.1 * wave(3 * j), 0.1 * wave(3 * j + 1), 0.1 * wave(3 * j + 2));
                let n = (1.0 + x * x + y * y + z * z).sqrt();
                out.extend_from_slice(&[1.0 / n, x / n, y / n, z / n]);
            }
        } else {
            out.extend((0..d).map(|i| 0.5 * wave(i)));
        }
    }
    out
}

fn whole_shot(km: &KeyframeModel, batch: usize, gap: usize) -> Result<WholeShot> {
    let d = km.dofs();
    let frames = zoo_arnn::inbetween_train::transition_keys(gap);
    let span = frames[frames.len() - 1] + 1;
    Ok(WholeShot {
        runner: km.runner(batch)?,
        keys: (0..batch).map(|c| key_poses(d, frames.len(), c)).collect(),
        frames,
        out: vec![vec![0.0; span * d]; batch],
    })
}

fn recurrent(path: &Path, batch: usize, gap: usize) -> Result<Recurrent> {
    let m = match LoadedModel::load(path).with_context(|| format!("--against {}", path.display()))? {
        LoadedModel::Transition(m) => m,
        other => bail!(
            "--against {}: a `{}` model; it takes an RTN written by `zoo export --onnx` (a transition model)",
            path.display(),
            other.task()
        ),
    };
    let (k, past) = (m.joints(), m.past_frames());
    let d = 3 * k;
    let mut runner = m.runner()?;
    runner.allow_beyond_trained(true);
    let mut r = Recurrent {
        runner,
        states: (0..batch).map(|_| m.new_transition()).collect(),
        past: vec![0.0; batch * past * d],
        target: vec![0.0; batch * d],
        next: vec![0.0; batch * d],
        poses: vec![0.0; batch * d],
        gap,
    };
    for c in 0..batch {
        for f in 0..past {
            walk_positions(k, c, f, &mut r.past[(c * past + f) * d..(c * past + f + 1) * d]);
        }
        walk_positions(k, c, past + gap, &mut r.target[c * d..(c + 1) * d]);
        walk_positions(k, c, past + gap + 1, &mut r.next[c * d..(c + 1) * d]);
    }
    Ok(r)
}

/// The figures of the in-betweening model `km` (and the RTN in `against`) at each batch size:
/// `rounds` rounds of at least 3 transitions each (`work` character-frames per method and round).
pub fn run(
    km: &KeyframeModel,
    against: Option<&Path>,
    gap: usize,
    batches: &[usize],
    rounds: usize,
    work: usize,
) -> Result<Vec<TransitionCost>> {
    if !km.is_inbetween() {
        bail!(
            "--against and --gap time whole transitions of the in-betweening design; this file is an ARNN step graph"
        );
    }
    if gap == 0 {
        bail!("--gap 0: a transition needs at least one frame between the context and the target");
    }
    let mut out = Vec::new();
    for &batch in batches {
        let mut methods: Vec<Box<dyn Transitions>> = vec![Box::new(whole_shot(km, batch, gap)?)];
        if let Some(path) = against {
            methods.push(Box::new(recurrent(path, batch, gap)?));
        }
        let per_round = (work / (batch * gap)).max(3);
        for m in methods.iter_mut() {
            m.run().with_context(|| m.name())?;
        }
        let mut wall: Vec<Vec<f64>> = vec![Vec::with_capacity(rounds); methods.len()];
        let mut cpu: Vec<Vec<f64>> = vec![Vec::with_capacity(rounds); methods.len()];
        for _ in 0..rounds {
            for (i, m) in methods.iter_mut().enumerate() {
                let (t, c) = (Instant::now(), cpu_time::ThreadTime::now());
                for _ in 0..per_round {
                    m.run()?;
                }
                cpu[i].push(c.elapsed().as_secs_f64() * 1e3 / per_round as f64);
                wall[i].push(t.elapsed().as_secs_f64() * 1e3 / per_round as f64);
            }
        }
        for ((m, w), c) in methods.iter().zip(wall).zip(cpu) {
            out.push(TransitionCost {
                method: m.name(),
                batch,
                gap,
                wall_ms: zoo_data::dataset::percentile(&mut w.clone(), 50.0),
                cpu_ms: zoo_data::dataset::percentile(&mut c.clone(), 50.0),
                rounds_wall_ms: w,
                rounds_cpu_ms: c,
            });
        }
    }
    Ok(out)
}

/// The figures as a table, each method's time against the first's at the same batch.
pub fn table(figures: &[TransitionCost], rounds: usize) -> String {
    let mut s = format!(
        "one transition of {} frames between {N_PAST} context frames and the target, tract, one thread; median of {rounds} rounds\n",
        figures.first().map_or(0, |f| f.gap)
    );
    s += "| batch | method | wall ms | CPU ms | CPU ms per character | CPU time / whole shot's |\n| --- | --- | --- | --- | --- | --- |\n";
    for f in figures {
        let first = figures.iter().find(|g| g.batch == f.batch).map_or(f64::NAN, |g| g.cpu_ms);
        s += &format!(
            "| {} | {} | {:.3} | {:.3} | {:.4} | {:.2}x |\n",
            f.batch,
            f.method,
            f.wall_ms,
            f.cpu_ms,
            f.cpu_ms / f.batch as f64,
            f.cpu_ms / first
        );
    }
    s.trim_end().to_string()
}
