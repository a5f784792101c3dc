//! `zoo denoise`: motion denoising by MAP optimisation through a trained RNN-GMM (paper sec.
//! 5.4): a noisy BVH in, a clean one (and its contact labels) out.

use anyhow::{Context, bail};
use clap::Args;
use std::path::PathBuf;
use zoo_data::Progress;
use zoo_rnngmm::DenoiseOptions;

/// Arguments of `zoo denoise`.
#[derive(Args)]
pub struct DenoiseArgs {
    /// Run folder of `zoo train rnn-gmm` (the generator is the prior; a refiner is not used).
    #[arg(long)]
    pub model: PathBuf,
    /// The noisy clip (BVH, `.bvh.gz` too) on the model's skeleton and frame rate.
    pub input: PathBuf,
    /// Output BVH; the contact labels go to `<name>.contacts.json` beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Standard deviation of the root-position noise in clip units (cm for bandai2)
    /// [default: estimated from the input].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::noise_units)]
    pub sigma_root: Option<f64>,
    /// Standard deviation of the joint-angle noise in degrees [default: estimated from the input].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::noise_degrees)]
    pub sigma_angle: Option<f64>,
    /// L-BFGS iterations at most.
    #[arg(long, default_value_t = DenoiseOptions::default().iterations, allow_hyphen_values = true, value_parser = crate::args::denoise_iterations)]
    pub iterations: usize,
}

impl DenoiseArgs {
    /// The denoiser's settings.
    pub fn options(&self) -> DenoiseOptions {
        DenoiseOptions {
            sigma_root: self.sigma_root,
            sigma_angle: self.sigma_angle.map(f64::to_radians),
            iterations: self.iterations,
            ..DenoiseOptions::default()
        }
    }
}

/// Runs `zoo denoise`.
pub fn run(a: DenoiseArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    let (g, _) = zoo_rnngmm::run::load_run(&a.model, true)?;
    let mut clip = zoo_data::clip_io::read_model_clip(&a.input)?;
    if let Some(zoo_data::clip_io::Conformed::Folded(how)) = zoo_data::clip_io::conform_to(&mut clip, &g.spec.skeleton)
    {
        eprintln!("{}: {how}", a.input.display());
    }
    if let Some(d) = g.spec.skeleton.topology_difference(&clip.skeleton) {
        bail!(
            "{} is on another skeleton than the model in {} ({d}); denoise clips of the training skeleton",
            a.input.display(),
            a.model.display()
        );
    }
    if let Some((note, _)) =
        zoo_data::clip_io::to_frame_rate(&mut clip, g.spec.fps, &a.input).map_err(anyhow::Error::msg)?
    {
        eprintln!("{note}");
    }
    let opts = a.options();
    let bar = zoo_nn::progress::Bar::new();
    bar.start(opts.iterations as u64, "denoising (energy evaluations)");
    let started = std::time::Instant::now();
    let mut done = 0;
    let mut tick = |n: usize| {
        bar.advance((n as u64).saturating_sub(done));
        done = done.max(n as u64);
    };
    let d =
        zoo_rnngmm::denoise(&g, &clip, &opts, &mut tick).with_context(|| format!("denoising {}", a.input.display()))?;
    bar.finish();
    let json = zoo_rnngmm::run::write_motion(&a.out, &d.motion, &clip.skeleton, g.spec.fps)?;
    let (e0, e1) = &d.energy;
    println!(
        "denoised {} frames in {:.1} s ({} L-BFGS iterations; energy terms prior/noise/data/contact {:.0}/{:.0}/{:.0}/{:.0} \
         -> {:.0}/{:.0}/{:.0}/{:.0}); noise levels: root {:.2} units{}, joint angles {:.2} degrees{}",
        d.motion.clip.frames(),
        started.elapsed().as_secs_f64(),
        d.iterations,
        e0.prior,
        e0.noise,
        e0.data,
        e0.contact,
        e1.prior,
        e1.noise,
        e1.data,
        e1.contact,
        d.sigma_root,
        if a.sigma_root.is_some() { "" } else { " (estimated)" },
        d.sigma_angle.to_degrees(),
        if a.sigma_angle.is_some() { "" } else { " (estimated)" },
    );
    crate::cmd::say_written(&a.out, &json, None);
    Ok(())
}
