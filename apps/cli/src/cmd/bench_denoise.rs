//! `zoo bench denoise`: the motion-denoising benchmark ([`zoo_rnngmm::bench::denoise`],
//! protocol in docs/rnn-gmm-control.md).

use clap::Args;
use std::path::PathBuf;
use zoo_rnngmm::DenoiseOptions;
use zoo_rnngmm::bench::denoise::DenoiseBenchOptions;

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
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::training_threads)]
    pub threads: Option<usize>,
    /// Leave out the clips of --data that cannot be read or do not join the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs `zoo bench denoise`.
pub fn run(a: BenchDenoiseArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    let denoiser = DenoiseOptions {
        iterations: a.iterations,
        prior_weight: a.prior_weight,
        init_savgol: a.init_savgol,
        sigma_contact: a.sigma_contact,
        ..DenoiseOptions::default()
    };
    let o = DenoiseBenchOptions {
        model: a.model,
        data: a.data,
        glob: a.glob,
        clips: a.clips,
        seconds: a.seconds,
        seed: a.seed,
        angle_noise: a.angle_noise,
        root_noise: a.root_noise,
        outliers: a.outliers,
        outlier_noise: a.outlier_noise,
        savgol_windows: a.savgol_windows,
        savgol_order: a.savgol_order,
        denoiser,
        known_noise: a.known_noise,
        threads: a.threads,
        skip_invalid: a.skip_invalid,
    };
    let report = zoo_rnngmm::bench::denoise::run(&o, &zoo_nn::progress::Bar::new())?;
    println!("{}", report.text(o.known_noise));
    crate::cmd::write_report(a.json.as_deref(), &report)
}
