//! `zoo follow`: offline path following with a trained RNN-GMM (paper sec. 5.2): a ground path
//! (JSON points, JSON or SVG path data) in, a BVH whose root walks along it out, with its
//! contact labels and a top-view plot of the path and the root's trajectory.

use anyhow::{Context, bail};
use clap::Args;
use std::path::PathBuf;
use zoo_rnngmm::FollowOptions;
use zoo_rnngmm::path::GroundPath;
use zoo_rnngmm::run::{follow_with_progress, load_run, plot_path, root_track, start_clip, write_motion};

/// Arguments of `zoo follow`.
#[derive(Args)]
pub struct FollowArgs {
    /// Run folder of `zoo train rnn-gmm` (the generator is the prior).
    #[arg(long)]
    pub model: PathBuf,
    /// The ground path: `.json` (`{"units": "m", "points": [[x, z], ...]}` or `{"units": "m",
    /// "svg": "M ..."}`) or `.svg` (the first `<path d="...">`; see --svg-scale).
    #[arg(long)]
    pub path: PathBuf,
    /// Centimetres per SVG user unit (for `.svg` paths).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = crate::args::svg_scale)]
    pub svg_scale: f64,
    /// Start clip and frame, `CLIP.bvh:FRAME`: its gait (walk, run) and pose start the motion
    /// [default: the run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Option<String>,
    /// Output BVH; the contact labels go to `<name>.contacts.json` beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Top-view PNG of the path (grey) and the generated root trajectory (red).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// The optimiser's settings.
    #[command(flatten)]
    pub optimiser: OptimiserArgs,
}

/// The path-following optimiser's options (`zoo follow`, `zoo bench follow`).
#[derive(Args)]
pub struct OptimiserArgs {
    /// Standard deviation of the curve term (eq. 17) in clip units (cm for bandai2).
    #[arg(long, default_value_t = FollowOptions::default().sigma_fit, allow_hyphen_values = true, value_parser = crate::args::sigma_units)]
    pub sigma_fit: f64,
    /// Particles of each window's swarm.
    #[arg(long, default_value_t = FollowOptions::default().particles, allow_hyphen_values = true, value_parser = crate::args::particles)]
    pub particles: usize,
    /// Swarm iterations per window.
    #[arg(long, default_value_t = FollowOptions::default().swarm_iterations, allow_hyphen_values = true, value_parser = crate::args::optimiser_iterations)]
    pub swarm_iterations: u64,
    /// L-BFGS iterations per window at most.
    #[arg(long, default_value_t = FollowOptions::default().iterations, allow_hyphen_values = true, value_parser = crate::args::optimiser_iterations)]
    pub iterations: u64,
    /// Seed of the swarm: the same seed (and thread count) gives the same file.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
}

impl OptimiserArgs {
    /// The optimiser's settings.
    pub fn options(&self) -> FollowOptions {
        FollowOptions {
            sigma_fit: self.sigma_fit,
            particles: self.particles,
            swarm_iterations: self.swarm_iterations,
            iterations: self.iterations,
            seed: self.seed,
            ..FollowOptions::default()
        }
    }
}

/// Runs `zoo follow`.
pub fn run(a: FollowArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if let Some(p) = &a.plot {
        crate::cmd::check_output_file("--plot", p)?;
    }
    let path =
        GroundPath::load(&a.path, a.svg_scale).with_context(|| format!("reading the path {}", a.path.display()))?;
    let (g, _) = load_run(&a.model, true)?;
    let from = a.from.as_deref().map(crate::args::clip_and_frame).transpose()?;
    let (clip, frame, from) = start_clip(&a.model, from.as_ref().map(|(p, f)| (p.as_path(), *f)), &g)?;
    let started = std::time::Instant::now();
    let bar = zoo_nn::progress::Bar::new();
    let f = follow_with_progress(&g, &clip, frame, &path, &a.optimiser.options(), "following", &bar)
        .with_context(|| format!("following {} from {from}", a.path.display()))?;
    let seconds = started.elapsed().as_secs_f64();
    let json = write_motion(&a.out, &f.motion, &clip.skeleton, g.spec.fps)?;
    if let Some(p) = &a.plot {
        plot_path(p, &path, &root_track(&f))?;
    }
    let n = f.distance.len().max(1) as f64;
    let mean = f.distance.iter().sum::<f64>() / n;
    let max = f.distance.iter().copied().fold(0.0, f64::max);
    let frames = f.motion.clip.frames();
    let motion_s = frames as f64 / g.spec.fps;
    println!(
        "followed {:.1} m of path in {frames} frames ({motion_s:.1} s of motion, {} windows) in {seconds:.1} s ({:.1} s \
         per generated second); root to path: mean {mean:.1}, max {max:.1} clip units{}",
        path.length() / 100.0,
        f.windows,
        seconds / motion_s.max(1e-9),
        if f.reached_end { "" } else { "; stopped before the path's end (frame limit)" }
    );
    if !f.reached_end {
        eprintln!("warning: the motion did not reach the path's end within the frame limit");
    }
    crate::cmd::say_written(&a.out, &json, a.plot.as_deref());
    if frames == 0 {
        bail!("no frame was generated");
    }
    Ok(())
}
