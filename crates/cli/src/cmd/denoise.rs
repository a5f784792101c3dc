//! `zoo denoise`: motion denoising by MAP optimisation through a trained RNN-GMM (issue 15,
//! paper sec. 5.4): a noisy BVH in, a clean one (and its contact labels) out.

use crate::cmd::generate::load_model;
use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use zoo_rnngmm::{DenoiseOptions, Denoised};

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

/// Denoises `clip` with a progress bar counting energy evaluations.
pub fn denoise_with_progress(
    g: &zoo_rnngmm::checkpoint::LoadedGenerator,
    clip: &zoo_motion::Clip,
    opts: &DenoiseOptions,
    pb: &ProgressBar,
) -> anyhow::Result<Denoised> {
    let mut tick = |n: usize| pb.set_position(n as u64);
    Ok(zoo_rnngmm::denoise(g, clip, opts, &mut tick)?)
}

/// Writes the contact labels of `d` as JSON to `path` (atomically).
pub fn write_contacts(path: &Path, fps: f64, contacts: &[[bool; 2]]) -> anyhow::Result<()> {
    let rows: Vec<[u8; 2]> = contacts.iter().map(|c| [u8::from(c[0]), u8::from(c[1])]).collect();
    let json = serde_json::json!({ "fps": fps, "frames": contacts.len(), "feet": ["left", "right"], "contacts": rows });
    let tmp = path.with_file_name(format!(".{}.tmp", path.file_name().unwrap_or_default().to_string_lossy()));
    std::fs::write(&tmp, serde_json::to_string(&json)?).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// Runs `zoo denoise`.
pub fn run(a: DenoiseArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    let (g, _) = load_model(&a.model, true)?;
    let clip = crate::cmd::transition::read_clip(&a.input)?;
    if let Some(d) = g.spec.skeleton.topology_difference(&clip.skeleton) {
        bail!(
            "{} is on another skeleton than the model in {} ({d}); denoise clips of the training skeleton",
            a.input.display(),
            a.model.display()
        );
    }
    let opts = a.options();
    let pb = ProgressBar::new(opts.iterations as u64);
    pb.set_style(ProgressStyle::with_template("denoising [{bar:30}] {pos} energy evaluations  {elapsed}")?);
    let started = std::time::Instant::now();
    let d = denoise_with_progress(&g, &clip, &opts, &pb).with_context(|| format!("denoising {}", a.input.display()))?;
    pb.finish_and_clear();
    let mut out = d.motion.clip.clone();
    out.skeleton = clip.skeleton.clone();
    zoo_data::clip_io::write(&out, &a.out)?;
    let stem = a.out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let json = a.out.with_file_name(format!("{stem}.contacts.json"));
    write_contacts(&json, g.spec.fps, &d.motion.contacts)?;
    println!(
        "denoised {} frames in {:.1} s ({} L-BFGS iterations; energy terms prior/noise/data/contact {:.0}/{:.0}/{:.0}/{:.0} \
         -> {:.0}/{:.0}/{:.0}/{:.0}); noise levels: root {:.2} units{}, joint angles {:.2} degrees{}",
        out.frames(),
        started.elapsed().as_secs_f64(),
        d.iterations,
        d.energy.0.prior,
        d.energy.0.noise,
        d.energy.0.data,
        d.energy.0.contact,
        d.energy.1.prior,
        d.energy.1.noise,
        d.energy.1.data,
        d.energy.1.contact,
        d.sigma_root,
        if a.sigma_root.is_some() { "" } else { " (estimated)" },
        d.sigma_angle.to_degrees(),
        if a.sigma_angle.is_some() { "" } else { " (estimated)" },
    );
    println!("wrote {} and {}", a.out.display(), json.display());
    Ok(())
}
