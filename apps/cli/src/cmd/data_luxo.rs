//! `zoo data luxo`: hop sequences of the simulated lamp (ARNN sections 4-5).

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use zoo_arnn::luxo::{self, GenerateOptions};

/// Arguments of `zoo data luxo`.
#[derive(Args)]
pub struct LuxoArgs {
    /// Output folder (created if needed): `luxo_NNNN.bvh` + `luxo_NNNN.json` per sequence and
    /// the manifest `luxo.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of hop sequences (the paper uses 300).
    #[arg(long, default_value_t = 12, allow_hyphen_values = true, value_parser = crate::args::sequences)]
    pub sequences: usize,
    /// Random seed: the same seed writes the same files, whatever the number of threads.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Simulated annealing iterations per run (the paper's K_max).
    #[arg(long, default_value_t = 1000, allow_hyphen_values = true, value_parser = crate::args::anneal_iterations)]
    pub k_max: usize,
    /// Annealing runs tried per sequence before giving up.
    #[arg(long, default_value_t = 20, allow_hyphen_values = true, value_parser = crate::args::attempts)]
    pub max_attempts: usize,
    /// Lamp parameters (JSON object of `zoo_arnn::luxo::LampParams` fields; the fields not
    /// given keep their defaults), e.g. `{"base_mass": 1.5}`.
    #[arg(long)]
    pub lamp: Option<PathBuf>,
    /// The hop every annealing run starts from (JSON `{"durations": [4 s], "poses": [4 x [3
    /// rad]]}`) [default: `HopPolicy::hand_set`].
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `zoo data luxo`.
pub fn run(a: LuxoArgs) -> anyhow::Result<()> {
    let mut options = GenerateOptions::new(a.sequences, a.seed);
    options.anneal.k_max = a.k_max;
    options.max_attempts = a.max_attempts;
    if let Some(path) = &a.lamp {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("--lamp {}: cannot read it", path.display()))?;
        options.lamp = serde_json::from_str(&text)
            .with_context(|| format!("--lamp {}: not a JSON object of lamp parameters", path.display()))?;
    }
    if let Some(path) = &a.init {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("--init {}: cannot read it", path.display()))?;
        options.init = serde_json::from_str(&text)
            .with_context(|| format!("--init {}: not a hop policy (durations and poses)", path.display()))?;
    }
    let files: Vec<String> = [("--lamp", &a.lamp), ("--init", &a.init)]
        .into_iter()
        .filter_map(|(o, p)| p.as_ref().map(|p| format!("{o} {}", p.display())))
        .collect();
    options.validate().with_context(|| match files.is_empty() {
        true => "the lamp data settings".to_string(),
        false => format!("the lamp data settings with {}", files.join(" and ")),
    })?;
    let bar = ProgressBar::new(a.sequences as u64);
    bar.set_style(
        ProgressStyle::with_template("luxo [{bar:40}] {pos}/{len} sequences {elapsed} (eta {eta})").expect("template"),
    );
    let summary = luxo::generate_with(&a.out, &options, &|| bar.inc(1))
        .with_context(|| format!("generating lamp hops into {}", a.out.display()))?;
    bar.finish_and_clear();
    let threads = rayon::current_num_threads();
    let per_minute = summary.sequences as f64 / summary.seconds.max(1e-9) * 60.0;
    let s = summary.anneal;
    let pct = |n: usize| 100.0 * n as f64 / s.candidates.max(1) as f64;
    if a.json {
        let mut v = serde_json::to_value(&summary)?;
        v["threads"] = threads.into();
        v["sequences_per_minute"] = per_minute.into();
        v["k_max"] = a.k_max.into();
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "wrote {} lamp sequences ({} frames at {} fps, {} annealing runs of K_max {}; candidates: {:.1}% valid, \
             {:.1}% accepted, {:.1}% fell, {:.1}% other hop counts) to {} in {:.1} s: {:.2} sequences/min on {} threads",
            summary.sequences,
            summary.frames,
            options.fps(),
            summary.attempts,
            a.k_max,
            pct(s.valid),
            pct(s.accepted),
            pct(s.fell),
            pct(s.wrong_hops),
            a.out.display(),
            summary.seconds,
            per_minute,
            threads
        );
    }
    Ok(())
}
