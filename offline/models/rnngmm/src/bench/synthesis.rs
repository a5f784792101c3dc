//! The synthesis benchmark (`zoo bench synthesis`, protocol in docs/rnn-gmm.md).
//!
//! N seeded sequences of L seconds, each continuing a held-out real clip from a start frame
//! drawn with the seed, generated once by the RNN; the same samples refined give the "RNN +
//! refiner" row, so both rows see the same random draws. Every measure is also computed on the
//! held-out real clips (the floor).

use crate::checkpoint::LoadedGenerator;
use crate::error::RnnGmmResult;
use crate::features::{CONTACT_DIMS, ROOT_DIMS};
use crate::refiner::RefinerNets;
use crate::{DecodedMotion, SynthesisOptions, SynthesisStream};
use glam::{DQuat, DVec3};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::dataset::NamedClip;
use zoo_data::metrics::{FootSkate, foot_joints, npss};
use zoo_data::{Context, Progress, bail};
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// The benchmark's settings and inputs.
#[derive(Clone, Debug)]
pub struct SynthesisBenchOptions {
    /// Run folder of `zoo train rnn-gmm` (with its refiner, unless `no_refiner`).
    pub model: PathBuf,
    /// BVH file or folder of real motion on the model's skeleton.
    pub data: PathBuf,
    /// Glob on file names choosing the held-out real clips of `data`.
    pub glob: String,
    /// Sequences to generate.
    pub sequences: usize,
    /// Length of each sequence in seconds.
    pub seconds: f64,
    /// Seed: sequence i uses seed + i for its sampling; the start frames are drawn with the seed.
    pub seed: u64,
    /// Sampling temperature.
    pub temperature: f64,
    /// Benchmark the generator alone.
    pub no_refiner: bool,
    /// Glob on file names of `data` choosing the clips whose joint-angle range a sequence must
    /// stay in (`None`: the held-out clips).
    pub range_glob: Option<String>,
    /// Widening of the range by this fraction of its span on each side.
    pub range_margin: f64,
    /// Leave out the clips of `data` that cannot be read or do not join the dataset.
    pub skip_invalid: bool,
    /// Worker threads generating sequences (`None`: the cores available); the figures do not
    /// depend on it.
    pub threads: Option<usize>,
}

/// One row of the table.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Row {
    /// `real`, `rnn` or `rnn+refiner`.
    pub name: String,
    /// Foot skate, cm per frame (`BENCHMARK.md`).
    pub foot_skate: f64,
    /// 1-D Wasserstein distance of root speed (cm/s) to the real clips'.
    pub root_speed_w1: f64,
    /// Mean root speed, cm/s.
    pub root_speed_mean: f64,
    /// 1-D Wasserstein distance of turning rate (rad/s) to the real clips'.
    pub turning_w1: f64,
    /// Fraction of sequences that freeze.
    pub frozen: f64,
    /// Fraction of sequences leaving the joint-angle range.
    pub out_of_range: f64,
    /// Mean jerk of global joint positions over the real clips' (1 for real).
    pub jerk_ratio: f64,
    /// NPSS of local joint rotations against real windows.
    pub npss: f64,
    /// Agreement of the predicted contact bits with contacts detected from the feet (none for real).
    pub contact_accuracy: Option<f64>,
    /// The feature values that left the range most often (up to 5): name, fraction of
    /// sequences, largest excursion beyond the widened range as a fraction of the real span.
    pub range_exits: Vec<(String, f64, f64)>,
}

/// What the benchmark measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Run folder.
    pub model: String,
    /// Held-out clips.
    pub data: String,
    /// Sequences per row.
    pub sequences: usize,
    /// Seconds per sequence.
    pub seconds: f64,
    /// Seed.
    pub seed: u64,
    /// Temperature.
    pub temperature: f64,
    /// The clips defining the joint-angle range (glob and count).
    pub range_data: String,
    /// Range clips other than the held-out ones that leave the held-out clips' widened range,
    /// and how many there are (`None` without --range-glob).
    pub range_clips_outside_held_out_range: Option<(usize, usize)>,
    /// Rows: real, rnn, rnn+refiner.
    pub rows: Vec<Row>,
    /// Mean joint displacement (cm) from the last seed frame to the first generated frame, with
    /// the initial state estimated (eq. 26).
    pub first_frame_jump_eq26: f64,
    /// The same from the zero state.
    pub first_frame_jump_zero_state: f64,
    /// Mean joint displacement per frame of the real clips (cm), for scale.
    pub real_joint_speed: f64,
    /// Seconds of generation and refinement per sequence.
    pub seconds_per_sequence: f64,
}

/// Per-clip measures gathered for a row.
#[derive(Default)]
struct Acc {
    speeds: Vec<f64>,
    turns: Vec<f64>,
    skate: (f64, usize),
    jerk: (f64, usize),
    frozen: usize,
    out_of_range: usize,
    /// Per feature value: sequences in which it left the range, and its largest excursion
    /// beyond the widened range as a fraction of the real span.
    exits: Vec<(usize, f64)>,
    contacts: (usize, usize),
    quats: Vec<DQuat>,
    windows: usize,
    clips: usize,
}

/// Frames per NPSS window (2 s at 30 fps), and windows taken per clip (at most).
const NPSS_FRAMES: usize = 60;
const NPSS_PER_CLIP: usize = 4;

struct Measure<'a> {
    g: &'a LoadedGenerator,
    skate: FootSkate,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Measure<'_> {
    /// Adds one clip (with its predicted contact bits, for generated clips).
    fn add(&self, acc: &mut Acc, clip: &Clip, predicted: Option<&[[bool; 2]]>) -> RnnGmmResult<()> {
        let spec = &self.g.spec;
        let (d, fps, frames, joints) = (spec.dim(), spec.fps, clip.frames(), clip.joints());
        let enc = spec.encode(clip)?;
        let x = |f: usize, i: usize| enc.values[f * d + i] as f64;
        let speeds: Vec<f64> = (0..frames).map(|f| x(f, 0).hypot(x(f, 1)) * fps).collect();
        acc.speeds.extend(&speeds[1..]);
        acc.turns.extend((1..frames).map(|f| x(f, 2) * fps));
        // Freeze: mean root speed over the last 5 s below 10 % of the first 5 s (halves of a
        // clip shorter than 10 s).
        let w = ((5.0 * fps) as usize).min(frames / 2).max(1);
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len().max(1) as f64;
        if mean(&speeds[frames - w..]) < 0.1 * mean(&speeds[1..=w.min(frames - 1)]) {
            acc.frozen += 1;
        }
        acc.exits.resize(d, (0, 0.0));
        let mut out = false;
        for i in range_values(d) {
            let span = (self.hi[i] - self.lo[i]).max(1e-9);
            let worst = (0..frames).map(|f| (self.lo[i] - x(f, i)).max(x(f, i) - self.hi[i])).fold(f64::MIN, f64::max);
            if worst > 0.0 {
                out = true;
                acc.exits[i].0 += 1;
                acc.exits[i].1 = acc.exits[i].1.max(worst / span);
            }
        }
        acc.out_of_range += usize::from(out);
        let (_, gp) = clip.global();
        let s = self.skate.skate(&gp, frames, joints);
        if s.is_finite() {
            acc.skate.0 += s * (frames - 1) as f64;
            acc.skate.1 += frames - 1;
        }
        for f in 0..frames.saturating_sub(3) {
            for j in 0..joints {
                let p = |k: usize| gp[(f + k) * joints + j];
                let jerk: DVec3 = p(3) - 3.0 * p(2) + 3.0 * p(1) - p(0);
                acc.jerk.0 += jerk.length() * fps * fps * fps;
                acc.jerk.1 += 1;
            }
        }
        if let Some(pred) = predicted {
            let c = spec.contact_index();
            for (f, p) in pred.iter().enumerate() {
                for k in 0..2 {
                    acc.contacts.0 += usize::from((x(f, c + k) > 0.5) == p[k]);
                    acc.contacts.1 += 1;
                }
            }
        }
        // NPSS windows of local rotations of the joints other than the root, sign-continuous.
        let n = (frames / NPSS_FRAMES).min(NPSS_PER_CLIP);
        for k in 0..n {
            let start = k * (frames - NPSS_FRAMES) / n.max(1);
            let mut prev: Vec<DQuat> = clip.rotations_at(start)[1..].to_vec();
            for f in start..start + NPSS_FRAMES {
                for (j, q) in clip.rotations_at(f)[1..].iter().enumerate() {
                    let q = if q.dot(prev[j]) < 0.0 { -*q } else { *q };
                    prev[j] = q;
                    acc.quats.push(q);
                }
            }
            acc.windows += 1;
        }
        acc.clips += 1;
        Ok(())
    }
}

/// The feature values whose range is checked: root tilt and every joint's rotation vector.
fn range_values(d: usize) -> std::ops::Range<usize> {
    ROOT_DIMS - 2..d - CONTACT_DIMS
}

/// Every feature value's [min, max] over `clips`, widened by `margin` of its span on each side.
fn widened_range(clips: &[crate::features::EncodedClip], d: usize, margin: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut lo, mut hi) = (vec![f64::INFINITY; d], vec![f64::NEG_INFINITY; d]);
    for e in clips {
        for f in 0..e.frames() {
            for (i, v) in e.frame(f).iter().enumerate() {
                lo[i] = lo[i].min(*v as f64);
                hi[i] = hi[i].max(*v as f64);
            }
        }
    }
    for i in 0..d {
        let m = margin * (hi[i] - lo[i]);
        (lo[i], hi[i]) = (lo[i] - m, hi[i] + m);
    }
    (lo, hi)
}

/// 1-D Wasserstein distance between two empirical distributions: the integral of the
/// absolute difference of their cumulative distribution functions.
pub fn wasserstein1(a: &[f64], b: &[f64]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::NAN;
    }
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let mut all: Vec<f64> = a.iter().chain(&b).copied().collect();
    all.sort_by(f64::total_cmp);
    let (mut ia, mut ib, mut w) = (0, 0, 0.0);
    for k in 0..all.len() - 1 {
        let x = all[k];
        while ia < a.len() && a[ia] <= x {
            ia += 1;
        }
        while ib < b.len() && b[ib] <= x {
            ib += 1;
        }
        w += (ia as f64 / a.len() as f64 - ib as f64 / b.len() as f64).abs() * (all[k + 1] - x);
    }
    w
}

/// The name of feature value `i` (root tilt `hips.rx`/`hips.rz`, joint rotation vectors
/// `JOINT.x|y|z`).
fn value_name(spec: &crate::FeatureSpec, i: usize) -> String {
    match i {
        4 => format!("{}.rx", spec.skeleton.names[0]),
        5 => format!("{}.rz", spec.skeleton.names[0]),
        i if i >= ROOT_DIMS => {
            let k = i - ROOT_DIMS;
            format!("{}.{}", spec.skeleton.names[1 + k / 3], ["x", "y", "z"][k % 3])
        }
        i => format!("value {i}"),
    }
}

fn row(name: &str, acc: &Acc, real: &Acc, real_jerk: f64, joints: usize, spec: &crate::FeatureSpec) -> Row {
    let npss = {
        let k = acc.windows.min(real.windows);
        let per = NPSS_FRAMES * joints;
        if k == 0 {
            f64::NAN
        } else if std::ptr::eq(acc, real) {
            // Real against real: each window against the next one (a different clip or part).
            let shifted: Vec<DQuat> = (0..k).flat_map(|i| real.quats[((i + 1) % k) * per..][..per].to_vec()).collect();
            npss(&shifted, &real.quats[..k * per], k, NPSS_FRAMES, joints)
        } else {
            npss(&acc.quats[..k * per], &real.quats[..k * per], k, NPSS_FRAMES, joints)
        }
    };
    let jerk = acc.jerk.0 / acc.jerk.1.max(1) as f64;
    Row {
        name: name.to_string(),
        foot_skate: acc.skate.0 / acc.skate.1.max(1) as f64,
        root_speed_w1: wasserstein1(&acc.speeds, &real.speeds),
        root_speed_mean: acc.speeds.iter().sum::<f64>() / acc.speeds.len().max(1) as f64,
        turning_w1: wasserstein1(&acc.turns, &real.turns),
        frozen: acc.frozen as f64 / acc.clips.max(1) as f64,
        out_of_range: acc.out_of_range as f64 / acc.clips.max(1) as f64,
        jerk_ratio: jerk / real_jerk,
        npss,
        contact_accuracy: (acc.contacts.1 > 0).then(|| acc.contacts.0 as f64 / acc.contacts.1 as f64),
        range_exits: {
            let mut e: Vec<(usize, (usize, f64))> =
                acc.exits.iter().copied().enumerate().filter(|(_, (n, _))| *n > 0).collect();
            e.sort_by(|a, b| b.1.0.cmp(&a.1.0).then(b.1.1.total_cmp(&a.1.1)));
            e.iter()
                .take(5)
                .map(|(i, (n, x))| (value_name(spec, *i), *n as f64 / acc.clips.max(1) as f64, *x))
                .collect()
        },
    }
}

/// Mean joint displacement (global positions, cm) between frame `f` of `a` and frame `g` of `b`.
fn joint_jump(a: &[DVec3], b: &[DVec3], joints: usize) -> f64 {
    a.iter().zip(b).map(|(p, q)| (*p - *q).length()).sum::<f64>() / joints as f64
}

/// One generated sequence: the chunk (refined, with the unrefined frames kept) and its first
/// frame from the zero state.
struct Generated {
    /// The refined motion (`None` without a refiner).
    refined: Option<DecodedMotion>,
    /// The generator's own motion.
    raw: DecodedMotion,
    /// The first frame from the zero state (same seed), for the first-frame jump.
    first: DecodedMotion,
}

/// What generates the benchmark's sequences: the exported model through the engine runtime
/// (`zoo_tasks::generate`, what `zoo generate` and engines run; the default) or the training
/// model in candle ([`CandleSynthesizer`], `zoo bench synthesis --candle`).
pub trait Synthesizer: Sync {
    /// `opts.frames` frames continuing frame `frame` of `clip` (the seed frames' state estimated
    /// by `opts.init_steps`, sampling with `opts.seed`): the refined motion (`None` without a
    /// refiner) and the generator's own, from the same draws.
    fn synthesize(
        &self,
        clip: &Clip,
        frame: usize,
        opts: &SynthesisOptions,
    ) -> RnnGmmResult<(Option<DecodedMotion>, DecodedMotion)>;
}

/// The training model in candle as the benchmark's [`Synthesizer`].
pub struct CandleSynthesizer<'a> {
    /// The generator.
    pub g: &'a LoadedGenerator,
    /// Its refiner, when benchmarked.
    pub refiner: Option<&'a RefinerNets>,
}

impl Synthesizer for CandleSynthesizer<'_> {
    fn synthesize(
        &self,
        clip: &Clip,
        frame: usize,
        opts: &SynthesisOptions,
    ) -> RnnGmmResult<(Option<DecodedMotion>, DecodedMotion)> {
        let mut stream = SynthesisStream::new(self.g, self.refiner, clip, frame, opts)?.keep_unrefined();
        let chunk = stream.next_chunk(opts.frames)?;
        Ok(match chunk.unrefined {
            Some(raw) => (Some(chunk.motion), raw),
            None => (None, chunk.motion),
        })
    }
}

/// The held-out clips and the joint-angle range the sequences are measured against.
struct Reals {
    clips: Vec<NamedClip>,
    range_data: String,
    outside: Option<(usize, usize)>,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

/// Refuses a clip on another skeleton than the model's (`what` names its option).
fn check_skeleton(g: &LoadedGenerator, o: &SynthesisBenchOptions, c: &NamedClip, what: &str) -> RnnGmmResult<()> {
    if let Some(d) = g.spec.skeleton.topology_difference(&c.clip.skeleton) {
        bail!(
            "{}{what} is on another skeleton than the model in {} ({d}); {}",
            c.path.display(),
            o.model.display(),
            if what.is_empty() {
                "benchmark with clips of the training skeleton"
            } else {
                "choose clips of the training skeleton"
            }
        );
    }
    Ok(())
}

/// The held-out clips long enough to start from, and the data's range of every feature value,
/// widened by the margin: the held-out clips', and the range clips' when `range_glob` chooses
/// others.
fn reals(o: &SynthesisBenchOptions, g: &LoadedGenerator, p: &dyn Progress) -> RnnGmmResult<Reals> {
    let spec = &g.spec;
    let seed_frames = SynthesisOptions::default().seed_frames;
    let mut real_clips = Vec::new();
    for c in zoo_data::dataset::load_reporting(&o.data, Some(o.glob.as_str()), o.skip_invalid, p)? {
        check_skeleton(g, o, &c, "")?;
        if c.clip.frames() > seed_frames + 3 {
            real_clips.push(c);
        }
    }
    if real_clips.is_empty() {
        bail!("no clip of {} matching `{}` has more than {} frames", o.data.display(), o.glob, seed_frames + 3);
    }
    let d = spec.dim();
    let encode = |c: &NamedClip| spec.encode(&c.clip).with_context(|| format!("encoding {}", c.path.display()));
    let held_out: Vec<_> = real_clips.iter().map(encode).collect::<Result<_, _>>()?;
    let held_out_range = widened_range(&held_out, d, o.range_margin);
    let Some(glob) = &o.range_glob else {
        let (lo, hi) = held_out_range;
        let range_data = format!("the held-out clips ({})", real_clips.len());
        return Ok(Reals { clips: real_clips, range_data, outside: None, lo, hi });
    };
    let clips = zoo_data::dataset::load_reporting(&o.data, Some(glob.as_str()), o.skip_invalid, p)?;
    let mut encoded = Vec::with_capacity(clips.len());
    let mut others = (0, 0);
    for c in &clips {
        check_skeleton(g, o, c, " (--range-glob)")?;
        let e = encode(c)?;
        if !real_clips.iter().any(|r| r.path == c.path) {
            others.1 += 1;
            let (lo, hi) = &held_out_range;
            others.0 += usize::from(
                (0..e.frames()).any(|f| range_values(d).any(|i| !(lo[i]..=hi[i]).contains(&(e.frame(f)[i] as f64)))),
            );
        }
        encoded.push(e);
    }
    encoded.extend(held_out);
    let (lo, hi) = widened_range(&encoded, d, o.range_margin);
    let range_data = format!("{glob} ({} clips) and the held-out clips", clips.len());
    Ok(Reals { clips: real_clips, range_data, outside: Some(others), lo, hi })
}

/// The generated sequences' measures: the RNN's, the refined ones', and the first-frame jumps
/// summed over sequences.
#[derive(Default)]
struct Generation {
    rnn: Acc,
    refined: Acc,
    jump26: f64,
    jump0: f64,
}

/// Generates `sequences` sequences of `frames` frames on worker threads and measures them in
/// sequence order, as results arrive: the figures do not depend on the thread count.
fn generate(
    o: &SynthesisBenchOptions,
    g: &LoadedGenerator,
    synth: &dyn Synthesizer,
    reals: &Reals,
    m: &Measure,
    frames: usize,
    p: &dyn Progress,
) -> RnnGmmResult<Generation> {
    let seed_frames = SynthesisOptions::default().seed_frames;
    let joints = g.spec.skeleton.len();
    // The start frames, drawn in sequence order (independent of the thread count).
    let mut draw = SplitMix64::new(o.seed);
    let starts: Vec<(usize, usize)> = (0..o.sequences)
        .map(|i| {
            let c = i % reals.clips.len();
            (c, seed_frames - 1 + draw.below((reals.clips[c].clip.frames() - seed_frames) as u64) as usize)
        })
        .collect();
    let threads = super::worker_threads(o.threads);
    p.start((o.sequences * frames) as u64, "generating");
    // Sequence i is generated by worker i mod threads (candle on that worker's thread alone).
    let generate = |i: usize| -> RnnGmmResult<Generated> {
        let (c, frame) = starts[i];
        let clip = &reals.clips[c].clip;
        let opts = SynthesisOptions {
            frames,
            seed: o.seed.wrapping_add(i as u64),
            temperature: o.temperature,
            ..SynthesisOptions::default()
        };
        let (refined, raw) = synth.synthesize(clip, frame, &opts)?;
        // First frame from the zero state (same seed), for the first-frame jump.
        let zero = SynthesisOptions { init_steps: 0, frames: 1, ..opts };
        let (_, first) = synth.synthesize(clip, frame, &zero)?;
        Ok(Generated { refined, raw, first })
    };
    let mut out = Generation::default();
    std::thread::scope(|scope| -> RnnGmmResult<()> {
        let (tx, rx) = std::sync::mpsc::channel::<(usize, RnnGmmResult<Generated>)>();
        for w in 0..threads.min(o.sequences) {
            let (tx, generate) = (tx.clone(), &generate);
            scope.spawn(move || {
                let pool = match super::one_thread_pool() {
                    Ok(p) => p,
                    Err(e) => {
                        let _ = tx.send((w, Err(e)));
                        return;
                    }
                };
                for i in (w..o.sequences).step_by(threads) {
                    let out = pool.install(|| generate(i));
                    let failed = out.is_err();
                    if tx.send((i, out)).is_err() || failed {
                        return;
                    }
                }
            });
        }
        drop(tx);
        // Measure in sequence order: keep early arrivals until their turn.
        let mut pending: std::collections::BTreeMap<usize, Generated> = std::collections::BTreeMap::new();
        let mut next = 0;
        for (i, done) in rx {
            pending.insert(i, done.with_context(|| format!("sequence {i}"))?);
            while let Some(done) = pending.remove(&next) {
                let (c, frame) = starts[next];
                let raw = &done.raw;
                m.add(&mut out.rnn, &raw.clip, Some(raw.contacts.as_slice()))?;
                if let Some(refined) = &done.refined {
                    m.add(&mut out.refined, &refined.clip, Some(refined.contacts.as_slice()))?;
                }
                let (_, seed_gp) = reals.clips[c].clip.global();
                let last_seed = &seed_gp[frame * joints..(frame + 1) * joints];
                let (_, gp) = raw.clip.global();
                out.jump26 += joint_jump(&gp[..joints], last_seed, joints);
                let (_, gp0) = done.first.clip.global();
                out.jump0 += joint_jump(&gp0[..joints], last_seed, joints);
                next += 1;
                p.advance(frames as u64);
                p.note(&format!("sequence {next}/{}", o.sequences));
            }
        }
        if next < o.sequences {
            bail!("a worker stopped after {next} of {} sequences", o.sequences);
        }
        Ok(())
    })?;
    p.finish();
    Ok(out)
}

/// Runs the benchmark, its sequences generated by `synth` (the training model in candle when
/// `None`).
pub fn run(o: &SynthesisBenchOptions, synth: Option<&dyn Synthesizer>, p: &dyn Progress) -> RnnGmmResult<Report> {
    let (g, refiner) = crate::run::load_run(&o.model, o.no_refiner)?;
    let reals = reals(o, &g, p)?;
    let spec = &g.spec;
    let frames = (o.seconds * spec.fps).round().max(4.0) as usize;
    let joints = spec.skeleton.len();
    // Planted height of each foot joint: 5th percentile of its height over the real clips.
    let feet = foot_joints(&spec.skeleton.names);
    let real_refs: Vec<&Clip> = reals.clips.iter().map(|c| &c.clip).collect();
    let m = Measure { g: &g, skate: FootSkate::fit(feet, &real_refs), lo: reals.lo.clone(), hi: reals.hi.clone() };
    let mut real = Acc::default();
    let mut real_step = (0.0, 0usize);
    for c in &reals.clips {
        m.add(&mut real, &c.clip, None).with_context(|| format!("measuring {}", c.path.display()))?;
        let (_, gp) = c.clip.global();
        for f in 1..c.clip.frames() {
            real_step.0 += joint_jump(&gp[f * joints..(f + 1) * joints], &gp[(f - 1) * joints..f * joints], joints);
            real_step.1 += 1;
        }
    }
    let started = Instant::now();
    let candle = CandleSynthesizer { g: &g, refiner: refiner.as_ref() };
    let gen_ = generate(o, &g, synth.unwrap_or(&candle), &reals, &m, frames, p)?;
    let per_seq = started.elapsed().as_secs_f64() / o.sequences as f64;
    let real_jerk = real.jerk.0 / real.jerk.1.max(1) as f64;
    let rot_joints = joints - 1;
    let mut rows = vec![
        row("real", &real, &real, real_jerk, rot_joints, spec),
        row("rnn", &gen_.rnn, &real, real_jerk, rot_joints, spec),
    ];
    if refiner.is_some() {
        rows.push(row("rnn+refiner", &gen_.refined, &real, real_jerk, rot_joints, spec));
    }
    Ok(Report {
        model: o.model.display().to_string(),
        data: format!("{} ({}: {} clips)", o.data.display(), o.glob, reals.clips.len()),
        sequences: o.sequences,
        seconds: frames as f64 / spec.fps,
        seed: o.seed,
        temperature: o.temperature,
        range_data: reals.range_data,
        range_clips_outside_held_out_range: reals.outside,
        rows,
        first_frame_jump_eq26: gen_.jump26 / o.sequences as f64,
        first_frame_jump_zero_state: gen_.jump0 / o.sequences as f64,
        real_joint_speed: real_step.0 / real_step.1.max(1) as f64,
        seconds_per_sequence: per_seq,
    })
}

impl Report {
    /// The report as the command prints it (`range_margin`: the widening of the range).
    pub fn text(&self, range_margin: f64) -> String {
        let mut s = format!(
            "synthesis benchmark: {} sequences of {:.1} s from {}, seed {}, temperature {}\n",
            self.sequences, self.seconds, self.data, self.seed, self.temperature
        );
        s += &format!("joint-angle range: {}, widened by {range_margin} of each span\n", self.range_data);
        if let Some((n, of)) = self.range_clips_outside_held_out_range {
            s += &format!("real range clips (not held out) leaving the held-out clips' widened range: {n} of {of}\n");
        }
        s += "| | foot skate (cm/frame) | root speed W1 (cm/s) | mean root speed (cm/s) | turning W1 (rad/s) | frozen | \
              out of range | jerk / real | NPSS | contact accuracy |\n";
        s += "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
        for r in &self.rows {
            let contact = r.contact_accuracy.map_or_else(|| "-".into(), |a| format!("{:.1} %", 100.0 * a));
            s += &format!(
                "| {} | {:.3} | {:.2} | {:.1} | {:.4} | {:.0} % | {:.0} % | {:.3} | {:.4} | {contact} |\n",
                r.name,
                r.foot_skate,
                r.root_speed_w1,
                r.root_speed_mean,
                r.turning_w1,
                100.0 * r.frozen,
                100.0 * r.out_of_range,
                r.jerk_ratio,
                r.npss,
            );
        }
        for r in self.rows.iter().filter(|r| !r.range_exits.is_empty()) {
            let list: Vec<String> = r
                .range_exits
                .iter()
                .map(|(n, f, x)| format!("{n} ({:.0} % of sequences, up to {:.0} % of its span)", 100.0 * f, 100.0 * x))
                .collect();
            s += &format!("{}: values leaving the range most often: {}\n", r.name, list.join(", "));
        }
        s += &format!(
            "first-frame jump (mean joint displacement, last seed frame -> first generated frame): {:.2} cm with eq. \
             26, {:.2} cm from the zero state; real motion moves a joint {:.2} cm per frame on average\n",
            self.first_frame_jump_eq26, self.first_frame_jump_zero_state, self.real_joint_speed
        );
        s + &format!("{:.2} s per sequence (generation, refinement and measures)", self.seconds_per_sequence)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wasserstein_of_shifted_samples_is_the_shift() {
        let a: Vec<f64> = (0..100).map(|i| i as f64).collect();
        let b: Vec<f64> = a.iter().map(|v| v + 2.5).collect();
        assert!((wasserstein1(&a, &b) - 2.5).abs() < 1e-9, "{}", wasserstein1(&a, &b));
        assert_eq!(wasserstein1(&a, &a), 0.0);
        // Two point masses: |0 - 1| = 1; unequal sizes weigh by frequency.
        assert!((wasserstein1(&[0.0], &[1.0, 1.0, 1.0]) - 1.0).abs() < 1e-12);
        assert!((wasserstein1(&[0.0, 1.0], &[1.0]) - 0.5).abs() < 1e-12);
        assert!(wasserstein1(&[], &[1.0]).is_nan());
    }
}
