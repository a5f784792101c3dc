//! `zoo bench denoise`: the motion-denoising benchmark of issue 15 (protocol in
//! `docs/rnn-gmm-control.md`).
//!
//! N excerpts of held-out clean clips get seeded noise (joint angles at each `--angle-noise`
//! level, root jitter, outlier poses; [`zoo_rnngmm::noise::corrupt`]); the noisy input, the
//! Savitzky-Golay filter at every `--savgol-windows` width and the MAP denoiser are each
//! compared with the clean excerpt: L2P and L2Q (`BENCHMARK.md`; L2P normalised with the clean
//! excerpts' per-coordinate standard deviation), mean joint position error (clip units) and foot
//! skate (the clean excerpts' own beside it).

use crate::cmd::generate::load_model;
use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use zoo_data::metrics::{FootSkate, foot_joints, l2p, l2q};
use zoo_data::plausibility::percentile;
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;
use zoo_rnngmm::DenoiseOptions;
use zoo_rnngmm::noise::{Noise, corrupt, savgol};

/// Arguments of `zoo bench denoise`.
#[derive(Args)]
pub struct BenchDenoiseArgs {
    /// Run folder of `zoo train rnn-gmm` (its generator is the prior).
    #[arg(long)]
    pub model: PathBuf,
    /// BVH file or folder of clean motion on the model's skeleton.
    #[arg(long)]
    pub data: PathBuf,
    /// Glob on file names choosing the held-out clips, e.g. '*_youthful_*'.
    #[arg(long)]
    pub glob: String,
    /// Excerpts to corrupt and clean (spread over the clips, one start frame each drawn with the seed).
    #[arg(long, default_value_t = 16, allow_hyphen_values = true, value_parser = crate::args::sequences)]
    pub clips: usize,
    /// Length of each excerpt in seconds (shorter clips are taken whole).
    #[arg(long, default_value_t = 8.0, allow_hyphen_values = true, value_parser = crate::args::duration_seconds)]
    pub seconds: f64,
    /// Seed of the start frames and of the noise (excerpt i uses seed + i).
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Comma-separated joint-angle noise levels, degrees (each is one row group).
    #[arg(long, default_value = "2,5", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::noise_degrees)]
    pub angle_noise: Vec<f64>,
    /// Root jitter, clip units (cm for bandai2).
    #[arg(long, default_value_t = 2.0, allow_hyphen_values = true, value_parser = crate::args::noise_units)]
    pub root_noise: f64,
    /// Fraction of frames replaced by outlier poses.
    #[arg(long, default_value_t = 0.01, allow_hyphen_values = true, value_parser = crate::args::fraction_or_zero)]
    pub outliers: f64,
    /// Joint-angle noise of an outlier pose, degrees.
    #[arg(long, default_value_t = 20.0, allow_hyphen_values = true, value_parser = crate::args::noise_degrees)]
    pub outlier_noise: f64,
    /// Comma-separated Savitzky-Golay windows (odd frame counts) tried as the baseline.
    #[arg(long, default_value = "5,7,9,11,15,21", value_delimiter = ',', allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub savgol_windows: Vec<usize>,
    /// Polynomial order of the Savitzky-Golay filter.
    #[arg(long, default_value_t = 2, allow_hyphen_values = true, value_parser = crate::args::frames_or_zero)]
    pub savgol_order: usize,
    /// L-BFGS iterations of the denoiser at most.
    #[arg(long, default_value_t = DenoiseOptions::default().iterations, allow_hyphen_values = true, value_parser = crate::args::denoise_iterations)]
    pub iterations: usize,
    /// Weight of the denoiser's prior terms (1: the paper's MAP).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = crate::args::positive)]
    pub prior_weight: f64,
    /// Start the denoiser from the input smoothed by a Savitzky-Golay filter of this window.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub init_savgol: Option<usize>,
    /// Standard deviation of a planted foot joint's displacement per frame (clip units).
    #[arg(long, default_value_t = DenoiseOptions::default().sigma_contact, allow_hyphen_values = true, value_parser = crate::args::noise_units)]
    pub sigma_contact: f64,
    /// Give the denoiser the true noise levels instead of letting it estimate them.
    #[arg(long)]
    pub known_noise: bool,
    /// Worker threads (each denoises its excerpts with candle on one thread) [default: the
    /// cores available]. The figures do not depend on it.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::cmd::train::training_threads)]
    pub threads: Option<usize>,
    /// Leave out the clips of --data that cannot be read or do not join the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
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
    terms: (zoo_rnngmm::EnergyTerms, zoo_rnngmm::EnergyTerms),
    seconds: f64,
}

/// Runs `zoo bench denoise`.
pub fn run(a: BenchDenoiseArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    for &w in &a.savgol_windows {
        if w.is_multiple_of(2) || w < a.savgol_order + 2 {
            bail!(
                "--savgol-windows: {w} is not an odd window of at least the order + 2 ({}); e.g. 5,7,9,11",
                a.savgol_order + 2
            );
        }
    }
    let (g, _) = load_model(&a.model, true)?;
    let clips = crate::cmd::load_dataset(&a.data, Some(a.glob.as_str()), a.skip_invalid)?;
    if clips.is_empty() {
        bail!("no clip of {} matches `{}`", a.data.display(), a.glob);
    }
    for c in &clips {
        if let Some(d) = g.spec.skeleton.topology_difference(&c.clip.skeleton) {
            bail!(
                "{} is on another skeleton than the model in {} ({d}); benchmark with clips of the training skeleton",
                c.path.display(),
                a.model.display()
            );
        }
    }
    let frames = (a.seconds * g.spec.fps).round().max(10.0) as usize;
    // Excerpts spread over the clips, each from a seeded start frame.
    let mut draw = SplitMix64::new(a.seed);
    let excerpts: Vec<Clip> = (0..a.clips)
        .map(|i| {
            let c = &clips[i * clips.len() / a.clips.max(1) % clips.len()].clip;
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
    // Per-coordinate standard deviation of the clean global positions (L2P), planted heights.
    let joints = g.spec.skeleton.len();
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); joints * 3];
    let feet = foot_joints(&g.spec.skeleton.names);
    let mut heights = vec![Vec::new(); feet.len()];
    for e in &excerpts {
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
    let m = Measure { std, skate: FootSkate { joints: feet, planted, scale: 2.5 } };

    let jobs: Vec<(usize, usize)> =
        (0..a.angle_noise.len()).flat_map(|l| (0..excerpts.len()).map(move |i| (l, i))).collect();
    let threads = crate::cmd::train::default_threads(a.threads).min(jobs.len());
    let pb = ProgressBar::new(jobs.len() as u64);
    pb.set_style(ProgressStyle::with_template("denoising [{bar:30}] {pos}/{len} excerpts  {elapsed}<{eta}")?);
    let next = AtomicUsize::new(0);
    let noise_of = |l: usize| Noise {
        angle_deg: a.angle_noise[l],
        root: a.root_noise,
        outlier_fraction: a.outliers,
        outlier_deg: a.outlier_noise,
    };
    let run_job = |(l, i): (usize, usize)| -> anyhow::Result<Job> {
        let clean = &excerpts[i];
        let noise = noise_of(l);
        let (noisy, _) = corrupt(clean, &noise, a.seed.wrapping_add(i as u64));
        let savgols = a
            .savgol_windows
            .iter()
            .map(|&w| {
                let n = if w <= noisy.frames() {
                    savgol(&noisy, w, a.savgol_order).map_err(anyhow::Error::msg)?
                } else {
                    noisy.clone()
                };
                Ok(m.of(&n, clean))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let opts = DenoiseOptions {
            iterations: a.iterations,
            sigma_root: a.known_noise.then_some(noise.root),
            sigma_angle: a.known_noise.then_some(noise.angle_deg.to_radians()),
            prior_weight: a.prior_weight,
            init_savgol: a.init_savgol,
            sigma_contact: a.sigma_contact,
            ..DenoiseOptions::default()
        };
        let started = Instant::now();
        let d = zoo_rnngmm::denoise(&g, &noisy, &opts, &mut |_| {}).with_context(|| format!("excerpt {i}"))?;
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
    };
    let results: Vec<anyhow::Result<(usize, Job)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| -> Vec<anyhow::Result<(usize, Job)>> {
                    let pool = match rayon::ThreadPoolBuilder::new().num_threads(1).build() {
                        Ok(p) => p,
                        Err(e) => return vec![Err(anyhow::anyhow!("worker thread pool: {e}"))],
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
                        pb.inc(1);
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
            .flat_map(|h| h.join().unwrap_or_else(|_| vec![Err(anyhow::anyhow!("a worker panicked"))]))
            .collect()
    });
    pb.finish_and_clear();
    let mut done: Vec<Option<Job>> = (0..jobs.len()).map(|_| None).collect();
    for r in results {
        let (k, j) = r?;
        done[k] = Some(j);
    }
    let done: Vec<Job> = done.into_iter().collect::<Option<_>>().context("a denoising job did not finish")?;
    let mut levels = Vec::new();
    for (l, _) in a.angle_noise.iter().enumerate() {
        let js: Vec<&Job> = jobs.iter().zip(&done).filter(|((jl, _), _)| *jl == l).map(|(_, j)| j).collect();
        let n = js.len() as f64;
        let mean = |f: &dyn Fn(&Job) -> Sum| {
            let mut s = Sum::default();
            for j in &js {
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
        for (k, w) in a.savgol_windows.iter().enumerate() {
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
        let motion_seconds =
            excerpts.iter().map(|e| e.frames() as f64 / g.spec.fps).sum::<f64>() / excerpts.len() as f64;
        levels.push(Level {
            noise: noise_of(l),
            rows,
            best_savgol,
            sigma_used: (js.iter().map(|j| j.sigma.0).sum::<f64>() / n, js.iter().map(|j| j.sigma.1).sum::<f64>() / n),
            energy_terms: {
                let arr = |t: &zoo_rnngmm::EnergyTerms| [t.prior, t.noise, t.data, t.contact];
                let mut e = ([0.0; 4], [0.0; 4]);
                for j in &js {
                    let (a0, a1) = (arr(&j.terms.0), arr(&j.terms.1));
                    for k in 0..4 {
                        e.0[k] += a0[k] / n;
                        e.1[k] += a1[k] / n;
                    }
                }
                e
            },
            seconds_per_excerpt: seconds,
            seconds_per_motion_second: seconds / motion_seconds,
        });
    }
    let report = Report {
        model: a.model.display().to_string(),
        data: format!("{} ({}: {} clips)", a.data.display(), a.glob, clips.len()),
        excerpts: excerpts.len(),
        frames,
        seed: a.seed,
        threads,
        levels,
    };
    println!(
        "denoising benchmark: {} excerpts of up to {} frames from {}, seed {}, {} worker thread(s) of one core each",
        report.excerpts, report.frames, report.data, report.seed, report.threads
    );
    for lv in &report.levels {
        let n = &lv.noise;
        println!(
            "\nnoise: joint angles {} deg, root {} units, {} % outlier poses of {} deg; denoiser's noise levels: root \
             {:.2} units, angles {:.2} deg{}",
            n.angle_deg,
            n.root,
            100.0 * n.outlier_fraction,
            n.outlier_deg,
            lv.sigma_used.0,
            lv.sigma_used.1,
            if a.known_noise { " (given)" } else { " (estimated)" }
        );
        println!("| | L2P | L2Q | joint position error | foot skate |");
        println!("| --- | --- | --- | --- | --- |");
        let noisy = lv.rows.iter().find(|r| r.method == "noisy").cloned().unwrap_or_default();
        for r in &lv.rows {
            if r.method == "clean" {
                println!("| clean | - | - | - | {:.3} |", r.foot_skate);
                continue;
            }
            let best = if r.method == lv.best_savgol { " (best SG)" } else { "" };
            println!(
                "| {}{best} | {:.4} ({:.2}x) | {:.4} ({:.2}x) | {:.3} | {:.3} |",
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
        println!(
            "energy terms per excerpt (prior / noise / data / contact): start {:.0} / {:.0} / {:.0} / {:.0}, result \
             {:.0} / {:.0} / {:.0} / {:.0}",
            e0[0], e0[1], e0[2], e0[3], e1[0], e1[1], e1[2], e1[3]
        );
        println!(
            "denoising time: {:.1} s per excerpt, {:.2} s per second of motion (one core)",
            lv.seconds_per_excerpt, lv.seconds_per_motion_second
        );
    }
    if let Some(p) = &a.json {
        std::fs::write(p, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    Ok(())
}
