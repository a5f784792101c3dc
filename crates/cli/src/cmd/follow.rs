//! `zoo follow`: offline path following with a trained RNN-GMM (issue 15, paper sec. 5.2): a
//! ground path (JSON points, JSON or SVG path data) in, a BVH whose root walks along it out, with
//! its contact labels and a top-view plot of the path and the root's trajectory.

use crate::cmd::denoise::write_contacts;
use crate::cmd::generate::{load_model, start_clip};
use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use zoo_rnngmm::path::GroundPath;
use zoo_rnngmm::{FollowOptions, Followed};

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

/// Reads a path file with its error as the message.
pub fn read_path(path: &Path, svg_scale: f64) -> anyhow::Result<GroundPath> {
    GroundPath::load(path, svg_scale).with_context(|| format!("reading the path {}", path.display()))
}

/// Follows `path` with a progress bar over its length.
pub fn follow_with_progress(
    g: &zoo_rnngmm::checkpoint::LoadedGenerator,
    clip: &zoo_motion::Clip,
    frame: usize,
    path: &GroundPath,
    opts: &FollowOptions,
    label: &str,
) -> anyhow::Result<Followed> {
    let pb = ProgressBar::new(path.length().ceil() as u64);
    pb.set_style(ProgressStyle::with_template(&format!("{label} [{{bar:30}}] {{pos}}/{{len}} cm  {{elapsed}}"))?);
    let mut tick = |s: f64| pb.set_position(s.clamp(0.0, path.length()) as u64);
    let f = zoo_rnngmm::follow(g, clip, frame, path, opts, &mut tick)?;
    pb.finish_and_clear();
    Ok(f)
}

/// The generated root trajectory (x, z) of a followed motion.
pub fn root_track(f: &Followed) -> Vec<[f64; 2]> {
    let c = &f.motion.clip;
    let (_, gp) = c.global();
    (0..c.frames()).map(|i| [gp[i * c.joints()].x, gp[i * c.joints()].z]).collect()
}

/// Writes the top view of `path` and `track` to `png`.
pub fn plot(png: &Path, path: &GroundPath, track: &[[f64; 2]]) -> anyhow::Result<()> {
    let grid = if path.length() > 3000.0 { 500.0 } else { 100.0 };
    zoo_nn::plot::top_view(png, &[(path.points(), (150, 150, 150), 5.0), (track, (200, 30, 30), 1.5)], grid, 600)
        .with_context(|| format!("writing {}", png.display()))
}

/// Runs `zoo follow`.
pub fn run(a: FollowArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if let Some(p) = &a.plot {
        crate::cmd::check_output_file("--plot", p)?;
    }
    let path = read_path(&a.path, a.svg_scale)?;
    let (g, _) = load_model(&a.model, true)?;
    let (clip, frame, from) = start_clip(&a.model, a.from.as_deref(), &g)?;
    let opts = a.optimiser.options();
    let started = std::time::Instant::now();
    let f = follow_with_progress(&g, &clip, frame, &path, &opts, "following")
        .with_context(|| format!("following {} from {from}", a.path.display()))?;
    let seconds = started.elapsed().as_secs_f64();
    let mut out = f.motion.clip.clone();
    out.skeleton = clip.skeleton.clone();
    zoo_data::clip_io::write(&out, &a.out)?;
    let stem = a.out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let json = a.out.with_file_name(format!("{stem}.contacts.json"));
    write_contacts(&json, g.spec.fps, &f.motion.contacts)?;
    if let Some(p) = &a.plot {
        plot(p, &path, &root_track(&f))?;
    }
    let n = f.distance.len().max(1) as f64;
    let mean = f.distance.iter().sum::<f64>() / n;
    let max = f.distance.iter().copied().fold(0.0, f64::max);
    let motion_s = out.frames() as f64 / g.spec.fps;
    println!(
        "followed {:.1} m of path in {} frames ({motion_s:.1} s of motion, {} windows) in {seconds:.1} s ({:.1} s per \
         generated second); root to path: mean {mean:.1}, max {max:.1} clip units{}",
        path.length() / 100.0,
        out.frames(),
        f.windows,
        seconds / motion_s.max(1e-9),
        if f.reached_end { "" } else { "; stopped before the path's end (frame limit)" }
    );
    if !f.reached_end {
        eprintln!("warning: the motion did not reach the path's end within the frame limit");
    }
    println!("wrote {} and {}", a.out.display(), json.display());
    if let Some(p) = &a.plot {
        println!("wrote {}", p.display());
    }
    if out.frames() == 0 {
        bail!("no frame was generated");
    }
    Ok(())
}
