//! `zoo control`: online speed and direction control with a trained RNN-GMM (paper sec. 5.3): a
//! control script (speed and heading over time) in, a BVH that follows it out, with its contact
//! labels and a plot of speed and heading against the controls.

use anyhow::{Context, bail};
use clap::Args;
use std::path::PathBuf;
use zoo_rnngmm::OnlineOptions;
use zoo_rnngmm::controls::ControlScript;
use zoo_rnngmm::run::{control_with_progress, load_run, plot_controls, start_clip, write_motion};

/// Arguments of `zoo control`.
#[derive(Args)]
pub struct ControlArgs {
    /// Run folder of `zoo train rnn-gmm` (the generator is the prior).
    #[arg(long)]
    pub model: PathBuf,
    /// The control script (`.json`: `{"units": "m", "duration": 20, "keys": [{"time": 0,
    /// "speed": 1.2, "heading": 0}, {"time": 4, "heading": 180}, ...]}`, speeds per second,
    /// headings in degrees, 0 facing +z, 90 facing +x).
    #[arg(long)]
    pub script: PathBuf,
    /// Start clip and frame, `CLIP.bvh:FRAME`: its gait and pose start the motion [default: the
    /// run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Option<String>,
    /// Output BVH; the contact labels go to `<name>.contacts.json` beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// PNG of speed (top) and heading (bottom) over time: the motion's (red) against the
    /// controls (grey).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// The controller's settings.
    #[command(flatten)]
    pub online: OnlineArgs,
}

/// The online controller's options (`zoo control`, `zoo bench control`).
#[derive(Args)]
pub struct OnlineArgs {
    /// Frames per optimised batch (the paper's n); the controls reach the motion 1 to 2 batches later.
    #[arg(long, default_value_t = OnlineOptions::default().batch, value_parser = crate::args::control_batch)]
    pub batch: usize,
    /// Standard deviation of the speed term (eq. 22) in clip units per second (cm/s for bandai2).
    #[arg(long, default_value_t = OnlineOptions::default().sigma_speed, allow_hyphen_values = true, value_parser = crate::args::sigma_units)]
    pub sigma_speed: f64,
    /// Standard deviation of the direction term (eq. 23) in radians.
    #[arg(long, default_value_t = OnlineOptions::default().sigma_heading, allow_hyphen_values = true, value_parser = crate::args::sigma_radians)]
    pub sigma_heading: f64,
    /// Offsets of the proposals' forward step (normalised units), comma-separated.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = OnlineOptions::default().speed_offsets, value_parser = crate::args::proposal_offset)]
    pub speed_offsets: Vec<f64>,
    /// Offsets of the proposals' turn (normalised units), comma-separated.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = OnlineOptions::default().turn_offsets, value_parser = crate::args::proposal_offset)]
    pub turn_offsets: Vec<f64>,
    /// Scale of the proposals' draws (1: the model's spread, 0: each component's mean).
    #[arg(long, default_value_t = OnlineOptions::default().temperature, allow_hyphen_values = true, value_parser = crate::args::temperature)]
    pub temperature: f64,
    /// Gradient steps per batch at most (0: the best proposal as it is).
    #[arg(long, default_value_t = OnlineOptions::default().steps, allow_hyphen_values = true, value_parser = crate::args::gradient_steps)]
    pub steps: usize,
    /// Seed of the proposals: the same seed (and thread count) gives the same file.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
}

impl OnlineArgs {
    /// The controller's settings.
    pub fn options(&self) -> OnlineOptions {
        OnlineOptions {
            batch: self.batch,
            sigma_speed: self.sigma_speed,
            sigma_heading: self.sigma_heading,
            speed_offsets: self.speed_offsets.clone(),
            turn_offsets: self.turn_offsets.clone(),
            temperature: self.temperature,
            steps: self.steps,
            seed: self.seed,
            ..OnlineOptions::default()
        }
    }
}

/// Reads a control script with its error as the message.
pub fn read_script(path: &std::path::Path) -> anyhow::Result<ControlScript> {
    ControlScript::load(path).with_context(|| format!("reading the control script {}", path.display()))
}

/// Runs `zoo control`.
pub fn run(a: ControlArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if let Some(p) = &a.plot {
        crate::cmd::check_output_file("--plot", p)?;
    }
    let script = read_script(&a.script)?;
    let (g, _) = load_run(&a.model, true)?;
    let from = a.from.as_deref().map(crate::args::clip_and_frame).transpose()?;
    let (clip, frame, from) = start_clip(&a.model, from.as_ref().map(|(p, f)| (p.as_path(), *f)), &g)?;
    let opts = a.online.options();
    let c = control_with_progress(&g, &clip, frame, &script, &opts, "controlling", &zoo_nn::progress::Bar::new())
        .with_context(|| format!("following the controls of {} from {from}", a.script.display()))?;
    let json = write_motion(&a.out, &c.motion, &clip.skeleton, g.spec.fps)?;
    if let Some(p) = &a.plot {
        plot_controls(p, &script, g.spec.fps, &c.speed, &c.yaw)?;
    }
    for s in &zoo_rnngmm::controls::score(&script, g.spec.fps, &c.speed, &c.yaw, 1.0) {
        println!(
            "{:>5.1} s: speed {:>5.0} -> {:>5.0} ({:>4.1}% off), heading {:>5.0} deg: {:>5.1} deg off 1 s after, mean {:.1}",
            s.time,
            s.target_speed,
            s.speed_after,
            100.0 * s.speed_error,
            s.target_heading_deg,
            s.heading_at_settle_deg,
            s.heading_mean_deg
        );
    }
    let frames = c.motion.clip.frames();
    println!(
        "{frames} frames ({:.1} s of motion, batches of {}) in {:.1} s: {:.1} ms per frame",
        frames as f64 / g.spec.fps,
        opts.batch,
        c.batch_seconds.iter().sum::<f64>(),
        1e3 * c.seconds_per_frame()
    );
    crate::cmd::say_written(&a.out, &json, a.plot.as_deref());
    if frames == 0 {
        bail!("no frame was generated");
    }
    Ok(())
}
