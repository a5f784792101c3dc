//! `zoo bench synthesis` (also `zoo bench-synthesis`): the synthesis benchmark
//! ([`zoo_rnngmm::bench::synthesis`], protocol in docs/rnn-gmm.md).

use clap::Args;
use std::path::PathBuf;
use zoo_rnngmm::bench::synthesis::SynthesisBenchOptions;

/// Arguments of `zoo bench synthesis`.
#[derive(Args)]
pub struct BenchSynthesisArgs {
    /// Run folder of `zoo train rnn-gmm` (with its refiner, unless --no-refiner).
    #[arg(long)]
    pub model: PathBuf,
    /// BVH file or folder of real motion on the model's skeleton.
    #[arg(long)]
    pub data: PathBuf,
    /// Glob on file names choosing the held-out real clips of --data (the start frames and
    /// the real reference), e.g. '*_youthful_*' for a model trained with that validation glob.
    #[arg(long)]
    pub glob: String,
    /// Sequences to generate.
    #[arg(long, default_value_t = 100, allow_hyphen_values = true, value_parser = crate::args::sequences)]
    pub sequences: usize,
    /// Length of each sequence in seconds, at most 3600 (each sequence is held whole while it is measured).
    #[arg(long, default_value_t = 60.0, allow_hyphen_values = true, value_parser = crate::args::bench_sequence_seconds)]
    pub seconds: f64,
    /// Seed: sequence i uses seed + i for its sampling; the start frames are drawn with the seed.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Sampling temperature.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = crate::args::temperature)]
    pub temperature: f64,
    /// Benchmark the generator alone (a folder without a refiner).
    #[arg(long)]
    pub no_refiner: bool,
    /// Glob on file names of --data choosing the clips whose joint-angle range a sequence must
    /// stay in [default: --glob, the held-out clips]; '*' takes the whole dataset (the training
    /// and the held-out clips). Each range clip outside the held-out clips' range is counted.
    #[arg(long)]
    pub range_glob: Option<String>,
    /// A sequence leaves the data's range when a joint-angle value falls outside the range
    /// clips' [min, max] widened by this fraction of its span on each side.
    #[arg(long, default_value_t = 0.1, allow_hyphen_values = true, value_parser = crate::args::margin_fraction)]
    pub range_margin: f64,
    /// Leave out the clips of --data that cannot be read or do not join the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Worker threads generating sequences (each runs candle on its own thread) [default: the
    /// cores available]. The figures do not depend on it.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::training_threads)]
    pub threads: Option<usize>,
}

/// Runs `zoo bench synthesis`.
pub fn run(a: BenchSynthesisArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    let o = SynthesisBenchOptions {
        model: a.model,
        data: a.data,
        glob: a.glob,
        sequences: a.sequences,
        seconds: a.seconds,
        seed: a.seed,
        temperature: a.temperature,
        no_refiner: a.no_refiner,
        range_glob: a.range_glob,
        range_margin: a.range_margin,
        skip_invalid: a.skip_invalid,
        threads: a.threads,
    };
    let report = zoo_rnngmm::bench::synthesis::run(&o, &zoo_nn::progress::Bar::new())?;
    println!("{}", report.text(o.range_margin));
    crate::cmd::write_report(a.json.as_deref(), &report)
}
