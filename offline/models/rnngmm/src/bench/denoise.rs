//! The motion-denoising benchmark (`zoo bench denoise`, protocol in docs/rnn-gmm-control.md).
//!
//! N excerpts of held-out clean clips get seeded noise (joint angles at each angle-noise
//! level, root jitter, outlier poses; [`crate::noise::corrupt`]); the noisy input, the
//! Savitzky-Golay filter at every window width and the MAP denoiser are each compared with the
//! clean excerpt: L2P and L2Q (`BENCHMARK.md`; L2P normalised with the clean excerpts'
//! per-coordinate standard deviation), mean joint position error (clip units) and foot skate
//! (the clean excerpts' own beside it).

use crate::DenoiseOptions;
use crate::checkpoint::LoadedGenerator;
use crate::error::RnnGmmResult;
use crate::noise::{Noise, corrupt, savgol};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use zoo_data::metrics::{FootSkate, foot_joints, l2p, l2q};
use zoo_data::plausibility::percentile;
use zoo_data::{Context, Message, Progress, bail};
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// The benchmark's settings and inputs.
#[derive(Clone, Debug)]
pub struct DenoiseBenchOptions {
    /// Run folder of `zoo train rnn-gmm` (its generator is the prior).
    pub model: PathBuf,
    /// BVH file or folder of clean motion on the model's skeleton.
    pub data: PathBuf,
    /// Glob on file names choosing the held-out clips.
    pub glob: String,
    /// Excerpts to corrupt and clean.
    pub clips: usize,
    /// Length of each excerpt in seconds (shorter clips are taken whole).
    pub seconds: f64,
    /// Seed of the start frames and of the noise (excerpt i uses seed + i).
    pub seed: u64,
    /// Joint-angle noise levels, degrees (each is one row group).
    pub angle_noise: Vec<f64>,
    /// Root jitter, clip units.
    pub root_noise: f64,
    /// Fraction of frames replaced by outlier poses.
    pub outliers: f64,
    /// Joint-angle noise of an outlier pose, degrees.
    pub outlier_noise: f64,
    /// Savitzky-Golay windows (odd frame counts) tried as the baseline.
    pub savgol_windows: Vec<usize>,
    /// Polynomial order of the Savitzky-Golay filter.
    pub savgol_order: usize,
    /// The denoiser's settings (its noise levels are set per level with `known_noise`).
    pub denoiser: DenoiseOptions,
    /// Give the denoiser the true noise levels instead of letting it estimate them.
    pub known_noise: bool,
    /// Worker threads (`None`: the cores available); the figures do not depend on it.
    pub threads: Option<usize>,
    /// Leave out the clips of `data` that cannot be read or do not join the dataset.
    pub skip_invalid: bool,
}

/// Errors of one method against the clean excerpts.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Scores {
    /// Method: `noisy`, `savgol(W)`, `denoised`, or `clean` (skate only).
    pub method: String,
    /// L2P (mean over excerpts).
    pub l2p: f64,
    /// L2Q (mean over excerpts).
    pub l2q: f64,
    /// Mean joint position error, clip units.
    pub position_error: f64,
    /// Foot skate, clip units per frame.
    pub foot_skate: f64,
}

/// One noise level's results.
#[derive(Clone, Debug, Serialize)]
pub struct Level {
    /// The noise.
    pub noise: Noise,
    /// Rows: clean (skate), noisy, each Savitzky-Golay window, denoised.
    pub rows: Vec<Scores>,
    /// The Savitzky-Golay window with the lowest L2P.
    pub best_savgol: String,
    /// Mean noise levels the denoiser used (root units, degrees).
    pub sigma_used: (f64, f64),
    /// Mean energy terms (prior, noise, data, contact) of the starting point and of the result.
    pub energy_terms: ([f64; 4], [f64; 4]),
    /// Seconds of denoising per excerpt, and per second of motion.
    pub seconds_per_excerpt: f64,
    /// Seconds of denoising per second of motion.
    pub seconds_per_motion_second: f64,
}

/// What the benchmark measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Run folder.
    pub model: String,
    /// Held-out clips.
    pub data: String,
    /// Number of excerpts.
    pub excerpts: usize,
    /// Frames per excerpt (at most).
    pub frames: usize,
    /// Seed.
    pub seed: u64,
    /// Worker threads.
    pub threads: usize,
    /// One entry per angle-noise level.
    pub levels: Vec<Level>,
}

/// Per-excerpt measures of a method, summed.
#[derive(Clone, Default)]
struct Sum {
    l2p: f64,
    l2q: f64,
    pos: f64,
    skate: f64,
}

struct Measure {
    std: Vec<f64>,
    skate: FootSkate,
}

impl Measure {
    fn of(&self, clip: &Clip, clean: &Clip) -> Sum {
        let (mut gq, gp) = clip.global();
        let (cq, cp) = clean.global();
        // q and -q are one rotation: compare in the clean quaternion's hemisphere.
        for (q, c) in gq.iter_mut().zip(&cq) {
            if q.dot(*c) < 0.0 {
                *q = -*q;
            }
        }
        let joints = clip.joints();
        let frames = clip.frames();
        let err = gp.iter().zip(&cp).map(|(a, b)| (*a - *b).length()).sum::<f64>() / gp.len() as f64;
        Sum {
            l2p: l2p(&gp, &cp, joints, &self.std),
            l2q: l2q(&gq, &cq, joints),
            pos: err,
            skate: self.skate.skate(&gp, frames, joints),
        }
    }
}

/// One excerpt's results at one noise level.
struct Job {
    noisy: Sum,
    savgol: Vec<Sum>,
    denoised: Sum,
    clean_skate: f64,
    sigma: (f64, f64),
    terms: (crate::EnergyTerms, crate::EnergyTerms),
    seconds: f64,
}

/// The excerpts of the held-out clips, each from a seeded start frame, spread over the clips.
fn excerpts(o: &DenoiseBenchOptions, g: &LoadedGenerator, p: &dyn Progress) -> RnnGmmResult<(Vec<Clip>, usize, usize)> {
    let clips = zoo_data::dataset::load_reporting(&o.data, Some(o.glob.as_str()), o.skip_invalid, p)?;
    if clips.is_empty() {
        bail!("no clip of {} matches `{}`", o.data.display(), o.glob);
    }
    for c in &clips {
        if let Some(d) = g.spec.skeleton.topology_difference(&c.clip.skeleton) {
            bail!(
                "{} is on another skeleton than the model in {} ({d}); benchmark with clips of the training skeleton",
                c.path.display(),
                o.model.display()
            );
        }
    }
    let frames = (o.seconds * g.spec.fps).round().max(10.0) as usize;
    let mut draw = SplitMix64::new(o.seed);
    let excerpts = (0..o.clips)
        .map(|i| {
            let c = &clips[i * clips.len() / o.clips.max(1) % clips.len()].clip;
            let n = frames.min(c.frames());
            let start = draw.below((c.frames() - n + 1) as u64) as usize;
            let j = c.joints();
            Clip {
                skeleton: c.skeleton.clone(),
                frame_time: c.frame_time,
                local_rotations: c.local_rotations[start * j..(start + n) * j].to_vec(),
                local_positions: c.local_positions[start * j..(start + n) * j].to_vec(),
            }
        })
        .collect();
    Ok((excerpts, frames, clips.len()))
}

/// The measures: per-coordinate standard deviation of the clean global positions (L2P) and the
/// planted heights of the feet (5th percentile).
fn measure(g: &LoadedGenerator, excerpts: &[Clip]) -> Measure {
    let joints = g.spec.skeleton.len();
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); joints * 3];
    let feet = foot_joints(&g.spec.skeleton.names);
    let mut heights = vec![Vec::new(); feet.len()];
    for e in excerpts {
        let (_, gp) = e.global();
        for f in 0..e.frames() {
            for j in 0..joints {
                for k in 0..3 {
                    all[j * 3 + k].push(gp[f * joints + j][k]);
                }
            }
            for (k, &j) in feet.iter().enumerate() {
                heights[k].push(gp[f * joints + j].y);
            }
        }
    }
    let std: Vec<f64> = all
        .iter()
        .map(|v| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt().max(1e-6)
        })
        .collect();
    let planted = heights.iter().map(|h| percentile(h, 5.0)).collect();
    Measure { std, skate: FootSkate { joints: feet, planted, scale: 2.5 } }
}

impl DenoiseBenchOptions {
    /// The noise of level `l`.
    fn noise(&self, l: usize) -> Noise {
        Noise {
            angle_deg: self.angle_noise[l],
            root: self.root_noise,
            outlier_fraction: self.outliers,
            outlier_deg: self.outlier_noise,
        }
    }
}

/// Corrupts excerpt `i` at noise level `l`, cleans it with every filter and the denoiser, and
/// measures them.
fn job(
    o: &DenoiseBenchOptions,
    g: &LoadedGenerator,
    m: &Measure,
    clean: &Clip,
    (l, i): (usize, usize),
) -> RnnGmmResult<Job> {
    let noise = o.noise(l);
    let (noisy, _) = corrupt(clean, &noise, o.seed.wrapping_add(i as u64));
    let savgols = o
        .savgol_windows
        .iter()
        .map(|&w| {
            let n =
                if w <= noisy.frames() { savgol(&noisy, w, o.savgol_order).map_err(Message)? } else { noisy.clone() };
            Ok(m.of(&n, clean))
        })
        .collect::<RnnGmmResult<Vec<_>>>()?;
    let opts = DenoiseOptions {
        sigma_root: o.known_noise.then_some(noise.root),
        sigma_angle: o.known_noise.then_some(noise.angle_deg.to_radians()),
        ..o.denoiser.clone()
    };
    let started = Instant::now();
    let d = crate::denoise(g, &noisy, &opts, &mut |_| {}).with_context(|| format!("excerpt {i}"))?;
    let seconds = started.elapsed().as_secs_f64();
    Ok(Job {
        noisy: m.of(&noisy, clean),
        savgol: savgols,
        denoised: m.of(&d.motion.clip, clean),
        clean_skate: m.of(clean, clean).skate,
        sigma: (d.sigma_root, d.sigma_angle.to_degrees()),
        terms: d.energy,
        seconds,
    })
}

/// Runs `run_job` on every job with `threads` workers (one core each), in any order; the
/// results in job order.
fn run_jobs(
    jobs: &[(usize, usize)],
    threads: usize,
    run_job: &(dyn Fn((usize, usize)) -> RnnGmmResult<Job> + Sync),
    p: &dyn Progress,
) -> RnnGmmResult<Vec<Job>> {
    let next = AtomicUsize::new(0);
    let results: Vec<RnnGmmResult<(usize, Job)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| -> Vec<RnnGmmResult<(usize, Job)>> {
                    let pool = match super::one_thread_pool() {
                        Ok(p) => p,
                        Err(e) => return vec![Err(e)],
                    };
                    let mut out = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::SeqCst);
                        if k >= jobs.len() {
                            break;
                        }
                        let r = pool.install(|| run_job(jobs[k]));
                        let failed = r.is_err();
                        out.push(r.map(|j| (k, j)));
                        p.advance(1);
                        if failed {
                            next.store(jobs.len(), Ordering::SeqCst);
                            break;
                        }
                    }
                    out
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|_| vec![Err(Message::new("a worker panicked").into())]))
            .collect()
    });
    let mut done: Vec<Option<Job>> = (0..jobs.len()).map(|_| None).collect();
    for r in results {
        let (k, j) = r?;
        done[k] = Some(j);
    }
    Ok(done.into_iter().collect::<Option<_>>().context("a denoising job did not finish")?)
}

/// The rows of one noise level from its excerpts' jobs.
fn level(o: &DenoiseBenchOptions, l: usize, js: &[&Job], motion_seconds: f64) -> Level {
    let n = js.len() as f64;
    let mean = |f: &dyn Fn(&Job) -> Sum| {
        let mut s = Sum::default();
        for j in js {
            let x = f(j);
            s.l2p += x.l2p / n;
            s.l2q += x.l2q / n;
            s.pos += x.pos / n;
            s.skate += x.skate / n;
        }
        s
    };
    let row = |name: String, s: Sum| Scores {
        method: name,
        l2p: s.l2p,
        l2q: s.l2q,
        position_error: s.pos,
        foot_skate: s.skate,
    };
    let mut rows = vec![
        Scores {
            method: "clean".into(),
            foot_skate: js.iter().map(|j| j.clean_skate).sum::<f64>() / n,
            ..Scores::default()
        },
        row("noisy".into(), mean(&|j| j.noisy.clone())),
    ];
    for (k, w) in o.savgol_windows.iter().enumerate() {
        rows.push(row(format!("savgol({w})"), mean(&|j| j.savgol[k].clone())));
    }
    rows.push(row("denoised".into(), mean(&|j| j.denoised.clone())));
    let best_savgol = rows
        .iter()
        .filter(|r| r.method.starts_with("savgol"))
        .min_by(|x, y| x.l2p.total_cmp(&y.l2p))
        .map(|r| r.method.clone())
        .unwrap_or_default();
    let seconds = js.iter().map(|j| j.seconds).sum::<f64>() / n;
    let arr = |t: &crate::EnergyTerms| [t.prior, t.noise, t.data, t.contact];
    let mut energy_terms = ([0.0; 4], [0.0; 4]);
    for j in js {
        let (a0, a1) = (arr(&j.terms.0), arr(&j.terms.1));
        for k in 0..4 {
            energy_terms.0[k] += a0[k] / n;
            energy_terms.1[k] += a1[k] / n;
        }
    }
    Level {
        noise: o.noise(l),
        rows,
        best_savgol,
        sigma_used: (js.iter().map(|j| j.sigma.0).sum::<f64>() / n, js.iter().map(|j| j.sigma.1).sum::<f64>() / n),
        energy_terms,
        seconds_per_excerpt: seconds,
        seconds_per_motion_second: seconds / motion_seconds,
    }
}

/// Runs the benchmark.
pub fn run(o: &DenoiseBenchOptions, p: &dyn Progress) -> RnnGmmResult<Report> {
    for &w in &o.savgol_windows {
        if w.is_multiple_of(2) || w < o.savgol_order + 2 {
            bail!(
                "--savgol-windows: {w} is not an odd window of at least the order + 2 ({}); e.g. 5,7,9,11",
                o.savgol_order + 2
            );
        }
    }
    let (g, _) = crate::run::load_run(&o.model, true)?;
    let (excerpts, frames, clip_count) = excerpts(o, &g, p)?;
    let m = measure(&g, &excerpts);
    let jobs: Vec<(usize, usize)> =
        (0..o.angle_noise.len()).flat_map(|l| (0..excerpts.len()).map(move |i| (l, i))).collect();
    let threads = super::worker_threads(o.threads).min(jobs.len());
    p.start(jobs.len() as u64, "denoising");
    let done = run_jobs(&jobs, threads, &|(l, i)| job(o, &g, &m, &excerpts[i], (l, i)), p)?;
    p.finish();
    let motion_seconds = excerpts.iter().map(|e| e.frames() as f64 / g.spec.fps).sum::<f64>() / excerpts.len() as f64;
    let levels = (0..o.angle_noise.len())
        .map(|l| {
            let js: Vec<&Job> = jobs.iter().zip(&done).filter(|((jl, _), _)| *jl == l).map(|(_, j)| j).collect();
            level(o, l, &js, motion_seconds)
        })
        .collect();
    Ok(Report {
        model: o.model.display().to_string(),
        data: format!("{} ({}: {} clips)", o.data.display(), o.glob, clip_count),
        excerpts: excerpts.len(),
        frames,
        seed: o.seed,
        threads,
        levels,
    })
}

impl Report {
    /// The report as the command prints it (`known_noise`: the denoiser was given the levels).
    pub fn text(&self, known_noise: bool) -> String {
        let mut s = format!(
            "denoising benchmark: {} excerpts of up to {} frames from {}, seed {}, {} worker thread(s) of one core each\n",
            self.excerpts, self.frames, self.data, self.seed, self.threads
        );
        for lv in &self.levels {
            let n = &lv.noise;
            s += &format!(
                "\nnoise: joint angles {} deg, root {} units, {} % outlier poses of {} deg; denoiser's noise levels: \
                 root {:.2} units, angles {:.2} deg{}\n",
                n.angle_deg,
                n.root,
                100.0 * n.outlier_fraction,
                n.outlier_deg,
                lv.sigma_used.0,
                lv.sigma_used.1,
                if known_noise { " (given)" } else { " (estimated)" }
            );
            s += "| | L2P | L2Q | joint position error | foot skate |\n| --- | --- | --- | --- | --- |\n";
            let noisy = lv.rows.iter().find(|r| r.method == "noisy").cloned().unwrap_or_default();
            for r in &lv.rows {
                if r.method == "clean" {
                    s += &format!("| clean | - | - | - | {:.3} |\n", r.foot_skate);
                    continue;
                }
                let best = if r.method == lv.best_savgol { " (best SG)" } else { "" };
                s += &format!(
                    "| {}{best} | {:.4} ({:.2}x) | {:.4} ({:.2}x) | {:.3} | {:.3} |\n",
                    r.method,
                    r.l2p,
                    r.l2p / noisy.l2p,
                    r.l2q,
                    r.l2q / noisy.l2q,
                    r.position_error,
                    r.foot_skate
                );
            }
            let (e0, e1) = lv.energy_terms;
            s += &format!(
                "energy terms per excerpt (prior / noise / data / contact): start {:.0} / {:.0} / {:.0} / {:.0}, result \
                 {:.0} / {:.0} / {:.0} / {:.0}\n",
                e0[0], e0[1], e0[2], e0[3], e1[0], e1[1], e1[2], e1[3]
            );
            s += &format!(
                "denoising time: {:.1} s per excerpt, {:.2} s per second of motion (one core)\n",
                lv.seconds_per_excerpt, lv.seconds_per_motion_second
            );
        }
        s.trim_end().to_string()
    }
}
