//! What each per-frame call of the runtime costs, call by call (`zoo bench runtime --per-call N`):
//! a game budgets every frame, so the figure is the distribution of single calls (median, 99th
//! percentile, maximum), not a mean. For the model's task, `N` calls at each batch size on one
//! thread, in the order a game makes them:
//!
//! - `transition`: transitions of the model's trained length, one after the other; each
//!   transition's start (`TransitionRunner::start_batch`, every past frame at once) or, with the
//!   context fed frame by frame, its `begin` and `feed` calls, then its steps;
//! - `keyframes`: one completion of a 40-frame shot of 4 keys per character per call;
//! - `stitch`: one frame per stream per call (push, then pop what is ready) on `batch` streams of
//!   a synthetic walk with a seam every 45 frames;
//! - `synthesis`: one `SynthesisRunner::step_batch` per call;
//! - `control` (the same file): one `ControlRunner::step` per character per call, speed and
//!   heading changing every 60 frames.
//!
//! Each call is timed alone, on the wall clock (`Instant`) and in the thread's CPU time (what a
//! core dedicated to the game would see: on a shared machine the wall clock's slowest calls are
//! often the system running other work); the first calls (one transition, or 3 calls) warm the
//! caches and are not counted. Calls that repeat a cycle (a transition's begin, feeds and steps;
//! a stream's windows and seams) are also grouped by their place in it: the slowest place's
//! median is what the schedule costs, which another process's work at random moments does not
//! reach.

use crate::Result;
use serde::Serialize;
use std::time::Instant;
use zoo_data::{Context, bail};
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
use zoo_runtime::synthesis::SynthesisModel;
use zoo_runtime::{EnginePose, LoadedModel, StitchRefiner, TransitionModel};

/// The per-call times of one kind of call sequence at one batch size.
#[derive(Clone, Debug, Serialize)]
pub struct CallFigure {
    /// `transition (start)`, `transition (fed)`, `keyframes`, `stitch stream`, `synthesis`,
    /// `control`.
    pub calls: String,
    /// Characters (or streams) per call.
    pub batch: usize,
    /// Calls timed.
    pub count: usize,
    /// Median call, milliseconds.
    pub median_ms: f64,
    /// 99th percentile, milliseconds.
    pub p99_ms: f64,
    /// Slowest call, milliseconds.
    pub max_ms: f64,
    /// `max_ms / median_ms`.
    pub max_over_median: f64,
    /// The slowest call's kind (`start`, `step`, `feed`, `push+pop`...) and its index.
    pub slowest: String,
    /// Median call in the thread's CPU time, milliseconds: what the call computed, without the
    /// time the system gave the core to other work (on a shared machine the wall clock's
    /// slowest calls are often another process's).
    pub cpu_median_ms: f64,
    /// 99th percentile in the thread's CPU time, milliseconds.
    pub cpu_p99_ms: f64,
    /// Slowest call in the thread's CPU time, milliseconds.
    pub cpu_max_ms: f64,
    /// `cpu_max_ms / cpu_median_ms`.
    pub cpu_max_over_median: f64,
    /// Calls in the sequence's cycle (a transition's begin, feeds and steps; a stitch stream's
    /// windows and seams), or 1 for calls that all do the same work.
    pub period: usize,
    /// The slowest place of the cycle: the largest median thread CPU time of the calls at one
    /// place of the cycle over `cpu_median_ms`. What the calls' schedule costs, which another
    /// process's work at random moments does not reach (1 without a cycle).
    pub cpu_slowest_place_over_median: f64,
    /// That place's call kind and its index in the cycle (from the first call timed).
    pub slowest_place: String,
}

/// Times `calls` calls of `next` (which runs one call and names its kind) after `warm` calls.
fn time_calls(
    label: &str,
    batch: usize,
    warm: usize,
    calls: usize,
    period: usize,
    mut next: impl FnMut() -> Result<&'static str>,
) -> Result<CallFigure> {
    for _ in 0..warm {
        next()?;
    }
    let mut times = Vec::with_capacity(calls);
    let mut cpu = Vec::with_capacity(calls);
    let mut kinds = Vec::with_capacity(calls);
    for _ in 0..calls {
        let (t, c) = (Instant::now(), cpu_time::ThreadTime::now());
        let kind = next()?;
        cpu.push(c.elapsed().as_secs_f64() * 1e3);
        times.push(t.elapsed().as_secs_f64() * 1e3);
        kinds.push(kind);
    }
    let slowest = (0..calls).max_by(|&a, &b| times[a].total_cmp(&times[b])).unwrap_or(0);
    // Median, p99 and max of `v`.
    let stats = |v: &[f64]| {
        let mut sorted = v.to_vec();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((q * (calls - 1) as f64).round() as usize).min(calls - 1)];
        (at(0.5), at(0.99), sorted[calls - 1])
    };
    let ((median, p99, max), (cpu_median, cpu_p99, cpu_max)) = (stats(&times), stats(&cpu));
    // The median of each place of the cycle, the slowest of them.
    let period = period.clamp(1, calls);
    let mut place = (0usize, cpu_median);
    if period > 1 {
        for at in 0..period {
            let mut v: Vec<f64> = cpu.iter().skip(at).step_by(period).copied().collect();
            v.sort_by(f64::total_cmp);
            let m = v[v.len() / 2];
            if m > place.1 {
                place = (at, m);
            }
        }
    }
    Ok(CallFigure {
        calls: label.to_string(),
        batch,
        count: calls,
        median_ms: median,
        p99_ms: p99,
        max_ms: max,
        max_over_median: max / median,
        slowest: format!("{} (call {slowest})", kinds[slowest]),
        cpu_median_ms: cpu_median,
        cpu_p99_ms: cpu_p99,
        cpu_max_ms: cpu_max,
        cpu_max_over_median: cpu_max / cpu_median,
        period,
        cpu_slowest_place_over_median: place.1 / cpu_median,
        slowest_place: if period > 1 {
            format!("{} (place {} of {period})", kinds[place.0], place.0)
        } else {
            "-".into()
        },
    })
}

/// The per-call figures of the model in `bytes` at each batch size, `calls` calls each.
pub fn run(bytes: &[u8], batches: &[usize], calls: usize) -> Result<Vec<CallFigure>> {
    if calls < 10 {
        bail!("--per-call {calls}: time at least 10 calls (1000 gives a 99th percentile of 10 calls)");
    }
    let model = LoadedModel::from_bytes(bytes).context("cannot load the model")?;
    let mut out = Vec::new();
    for &batch in batches {
        match &model {
            LoadedModel::Transition(m) => {
                out.push(transition(m, batch, calls, false)?);
                out.push(transition(m, batch, calls, true)?);
            }
            LoadedModel::Keyframes(m) => out.push(keyframes(m, batch, calls)?),
            LoadedModel::Stitch(r) => out.push(stitch(r, batch, calls)?),
            LoadedModel::Synthesis(m) => {
                out.push(synthesis(m, batch, calls)?);
                out.push(control(m, batch, calls)?);
            }
            other => bail!("--per-call: a `{}` model has no per-frame calls", other.task()),
        }
    }
    Ok(out)
}

/// A walking pose in global positions: joint `j` of character `c` at frame `f`.
pub(crate) fn walk_positions(k: usize, c: usize, f: usize, out: &mut [f32]) {
    for j in 0..k {
        let phase = 0.3 * f as f32 + j as f32 + 0.5 * c as f32;
        out[3 * j] = 50.0 * c as f32 + 4.0 * j as f32 + 2.0 * phase.sin();
        out[3 * j + 1] = 90.0 - 8.0 * j as f32;
        out[3 * j + 2] = 4.0 * f as f32 + 3.0 * phase.cos();
    }
}

fn transition(m: &TransitionModel, batch: usize, calls: usize, fed: bool) -> Result<CallFigure> {
    let (k, past, length) = (m.joints(), m.past_frames(), m.transition_frames());
    let d = 3 * k;
    let mut runner = m.runner()?;
    let mut states: Vec<_> = (0..batch).map(|_| m.new_transition()).collect();
    let mut past_buf = vec![0.0f32; batch * past * d];
    let (mut target, mut next) = (vec![0.0f32; batch * d], vec![0.0f32; batch * d]);
    for c in 0..batch {
        for f in 0..past {
            walk_positions(k, c, f, &mut past_buf[(c * past + f) * d..(c * past + f + 1) * d]);
        }
        walk_positions(k, c, past + length, &mut target[c * d..(c + 1) * d]);
        walk_positions(k, c, past + length + 1, &mut next[c * d..(c + 1) * d]);
    }
    let mut frame = vec![0.0f32; batch * d];
    let mut poses = vec![0.0f32; batch * d];
    // Where the transition stands: `fed` context frames, then `stepped` frames of 0..=length.
    let (mut fed_frames, mut stepped) = (past, length + 1);
    let next_call = || -> Result<&'static str> {
        if stepped > length {
            if !fed {
                runner.start_batch(&mut states, &past_buf, &target, &next)?;
                stepped = 0;
                return Ok("start");
            }
            // The context fed as the game plays it: the first frame with the target, then one
            // frame per call.
            if fed_frames >= past {
                for c in 0..batch {
                    frame[c * d..(c + 1) * d].copy_from_slice(&past_buf[c * past * d..c * past * d + d]);
                }
                runner.begin_batch(&mut states, &frame, &target, &next, past, length)?;
                fed_frames = 1;
                return Ok("begin");
            }
            for c in 0..batch {
                let at = (c * past + fed_frames) * d;
                frame[c * d..(c + 1) * d].copy_from_slice(&past_buf[at..at + d]);
            }
            runner.feed_batch(&mut states, &frame)?;
            fed_frames += 1;
            if fed_frames == past {
                stepped = 0;
            }
            return Ok("feed");
        }
        runner.step_batch(&mut states, &mut poses)?;
        stepped += 1;
        Ok("step")
    };
    let label = if fed { "transition (context fed per frame)" } else { "transition (start)" };
    let period = if fed { past + length + 1 } else { length + 2 };
    time_calls(label, batch, length + past + 1, calls, period, next_call)
}

fn keyframes(m: &KeyframeModel, batch: usize, calls: usize) -> Result<CallFigure> {
    let d = m.dofs();
    let frames = [0usize, 9, 24, 39];
    let poses: Vec<Vec<f32>> =
        (0..batch).map(|c| (0..4 * d).map(|i| ((i + 7 * c) as f32 * 0.37).sin() * 0.5).collect()).collect();
    let mut runner = m.runner(batch)?;
    let mut outs: Vec<Vec<f32>> = vec![vec![0.0; 40 * d]; batch];
    time_calls("keyframes (one 40-frame shot per character)", batch, 3, calls, 1, || {
        let keys: Vec<MotionKeys> = poses.iter().map(|p| MotionKeys::whole(&frames, p)).collect();
        let mut out: Vec<&mut [f32]> = outs.iter_mut().map(|o| o.as_mut_slice()).collect();
        runner.complete_batch(&keys, &mut out)?;
        Ok("complete")
    })
}

fn stitch(r: &StitchRefiner, batch: usize, calls: usize) -> Result<CallFigure> {
    let k = r.joints();
    let walk = |c: usize, f: usize| {
        let rotations: Vec<Quat> =
            (0..k).map(|j| Quat::from_rotation_x(0.2 * (0.3 * f as f32 + j as f32 + c as f32).sin())).collect();
        EnginePose::from_world(Vec3::new(40.0 * c as f32, 90.0, 4.0 * f as f32), &rotations)
    };
    let mut streams: Vec<_> = (0..batch).map(|_| r.stream()).collect();
    let mut out = EnginePose::new(k);
    let mut f = 0usize;
    // Windows every `stride` frames, a seam every 45.
    let period = num_lcm(r.stride(), 45);
    time_calls("stitch stream (one frame per stream: push, then pop)", batch, 3, calls, period, || {
        for (c, s) in streams.iter_mut().enumerate() {
            if f > 0 && f % 45 == 0 {
                s.mark_seam();
            }
            s.push(&walk(c, f))?;
            while s.pop(&mut out)?.is_some() {}
        }
        f += 1;
        Ok("push+pop")
    })
}

fn start_frame(m: &SynthesisModel) -> Result<Vec<f32>> {
    let mean = m.model().metadata().normalization.get("x").map(|n| n.mean.clone()).unwrap_or_default();
    if mean.len() != m.frame_dim() {
        bail!("the synthesis model has no mean frame to start from; re-export it");
    }
    Ok(mean)
}

fn synthesis(m: &SynthesisModel, batch: usize, calls: usize) -> Result<CallFigure> {
    let frame = start_frame(m)?;
    let mut characters: Vec<_> = (0..batch as u64).map(|s| m.new_character(s)).collect();
    for (c, ch) in characters.iter_mut().enumerate() {
        ch.start(m, &frame, 100.0 * c as f32, 0.0, 0.0)?;
    }
    let mut runner = m.runner(batch)?;
    let mut poses = vec![EnginePose::new(m.joints()); batch];
    let mut contacts = vec![[false; 2]; batch];
    time_calls("synthesis", batch, 3, calls, 1, || {
        runner.step_batch(&mut characters, 1.0, &mut poses, &mut contacts)?;
        Ok("step")
    })
}

fn control(m: &SynthesisModel, batch: usize, calls: usize) -> Result<CallFigure> {
    let frame = start_frame(m)?;
    let mut characters = Vec::with_capacity(batch);
    for c in 0..batch {
        let mut ch = ControlledCharacter::new(m, c as u64, ControlSettings::default())?;
        ch.start(m, &frame, 100.0 * c as f32, 0.0, 0.0)?;
        characters.push(ch);
    }
    let mut runner = ControlRunner::new(m)?;
    let mut pose = EnginePose::new(m.joints());
    let mut f = 0usize;
    time_calls("control", batch, 3, calls, 1, || {
        let control = Control::new(if (f / 60) % 2 == 0 { 1.2 } else { 0.6 }, 0.5 * (f / 60) as f32);
        for ch in characters.iter_mut() {
            runner.step(ch, control, &mut pose)?;
        }
        f += 1;
        Ok("step")
    })
}

/// The figures as a table.
pub fn table(figures: &[CallFigure]) -> String {
    let mut s = String::from(
        "| calls | batch | count | median ms | p99 ms | max ms | max / median | slowest | CPU median / p99 / max ms | CPU max / median | CPU slowest place / median |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for f in figures {
        s.push_str(&format!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.2} | {} | {:.3} / {:.3} / {:.3} | {:.2} | {:.2} {} |\n",
            f.calls,
            f.batch,
            f.count,
            f.median_ms,
            f.p99_ms,
            f.max_ms,
            f.max_over_median,
            f.slowest,
            f.cpu_median_ms,
            f.cpu_p99_ms,
            f.cpu_max_ms,
            f.cpu_max_over_median,
            f.cpu_slowest_place_over_median,
            f.slowest_place
        ));
    }
    s
}

/// The least common multiple of `a` and `b` (both at least 1).
fn num_lcm(a: usize, b: usize) -> usize {
    let (mut x, mut y) = (a.max(1), b.max(1));
    while y != 0 {
        (x, y) = (y, x % y);
    }
    a.max(1) / x * b.max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Busy for `ms` milliseconds of this thread's CPU time.
    fn spin(ms: f64) {
        let t = cpu_time::ThreadTime::now();
        while t.elapsed().as_secs_f64() * 1e3 < ms {
            std::hint::black_box(0u64);
        }
    }

    /// A cycle of five calls whose fourth does three times the work: the slowest place is that
    /// one, at about 3x the median, whatever a single call elsewhere costs.
    #[test]
    fn the_slowest_place_of_a_cycle_is_found() {
        let mut i = 0usize;
        let f = time_calls("cycle", 1, 0, 60, 5, || {
            let heavy = i % 5 == 3;
            // One call at another place, once, as another process's work would.
            spin(if heavy {
                0.6
            } else if i == 7 {
                2.0
            } else {
                0.2
            });
            i += 1;
            Ok(if heavy { "heavy" } else { "light" })
        })
        .unwrap();
        assert_eq!(f.slowest_place, "heavy (place 3 of 5)");
        assert!((2.5..3.6).contains(&f.cpu_slowest_place_over_median), "{}", f.cpu_slowest_place_over_median);
        assert!(f.cpu_max_over_median > 8.0, "{}", f.cpu_max_over_median);
        assert_eq!((num_lcm(30, 45), num_lcm(5, 1), num_lcm(7, 7)), (90, 5, 7));
    }
}
