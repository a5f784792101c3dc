//! The options every trainer takes (`zoo train MODEL`), one clap group ([`RunArgs`];
//! [`DataArgs`] for the trainers that read clips), each model's defaults given by
//! [`TrainDefaults`].

use crate::run_folder::RunSpec;
use clap::Args;
use std::marker::PhantomData;
use std::path::PathBuf;
use zoo_data::dataset::TrainingClips;

/// A trainer's defaults of the shared options, as the command line writes them (clap's
/// `default_value_t` keeps one static per field across the generic group's instances, so the
/// defaults are given as text).
pub trait TrainDefaults: Clone + Send + Sync + 'static {
    /// `--epochs`.
    const EPOCHS: &'static str;
    /// `--out`.
    const OUT: &'static str;
    /// `--synth-minutes`.
    const SYNTH_MINUTES: &'static str = "10";
    /// Bytes the trainer holds per frame of synthetic motion (its clips, windows and features),
    /// measured and rounded up: the size [`crate::args::check_synth_memory`] bounds. The default
    /// covers the largest measured (`zoo train rmr`, 8.9 KB).
    const BYTES_PER_SYNTH_FRAME: f64 = 10_000.0;
}

/// The options every trainer takes: the run folder, the length of the run, the seed, the threads.
#[derive(Args, Clone)]
pub struct RunArgs<M: TrainDefaults> {
    /// Epochs to train (an epoch visits every training window, pair or sequence once; a resumed
    /// run continues up to this total).
    #[arg(long, default_value = M::EPOCHS, allow_hyphen_values = true, value_parser = crate::args::epochs)]
    pub epochs: usize,
    /// Stop after this many minutes of training (the epoch in progress finishes first).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::time_limit_minutes)]
    pub time_limit: Option<f64>,
    /// Run folder: config, weights, statistics, loss curve and summary.
    #[arg(long, default_value = M::OUT)]
    pub out: PathBuf,
    /// Continue the run in this folder (its config is kept; `--epochs` is the new total).
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Replace the run already in `--out`: its files are deleted before training. Without it,
    /// `--out` on a folder that holds a run is refused.
    #[arg(long, conflicts_with = "resume")]
    pub overwrite: bool,
    /// Seed of the data made in memory (synthetic clips, lamp hops), of the weights and of the
    /// trainer (dropout, shuffles).
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Data-parallel training threads (`1..=256`) [default: the cores available]. Each thread
    /// trains on its share of every batch and the gradients are summed before the one update:
    /// the same update as one thread up to float summation order. Results are reproducible
    /// for a fixed seed and thread count, not across thread counts.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::training_threads)]
    pub threads: Option<usize>,
    /// The command's options, recorded in a fresh run's folder (`zoo train --resume` takes them
    /// from there).
    #[arg(skip)]
    pub command: Vec<(String, Vec<String>)>,
    #[arg(skip)]
    _model: PhantomData<M>,
}

impl<M: TrainDefaults> RunArgs<M> {
    /// The library's run options.
    pub fn spec(&self) -> RunSpec {
        RunSpec {
            out: self.out.clone(),
            resume: self.resume.clone(),
            overwrite: self.overwrite,
            epochs: self.epochs,
            time_limit_minutes: self.time_limit,
            seed: self.seed,
            threads: self.threads,
            command: self.command.clone(),
        }
    }
}

/// The clips of the trainers that read BVH data (RTN, RMR, RNN-GMM).
#[derive(Args, Clone)]
pub struct DataArgs<M: TrainDefaults> {
    /// BVH file or folder to train on; without it, synthetic locomotion generated in memory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the validation split of `--data` (best checkpoint;
    /// bandai2: `'*_youthful_*'`).
    #[arg(long)]
    pub valid_glob: Option<String>,
    /// Leave out the clips of `--data` that cannot join the dataset (unreadable, another
    /// skeleton or frame rate) and list them, instead of refusing the dataset.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Minutes of synthetic motion when `--data` is not given (every tenth clip validates).
    #[arg(long, default_value = M::SYNTH_MINUTES, allow_hyphen_values = true, value_parser = crate::args::synth_minutes)]
    pub synth_minutes: f64,
    #[arg(skip)]
    _model: PhantomData<M>,
}

impl<M: TrainDefaults> DataArgs<M> {
    /// The library's data options (`exclude_glob`: the RTN's `--exclude-glob`), after checking
    /// that the synthetic data gives clips.
    pub fn spec(&self, exclude_glob: Option<String>, seed: u64) -> Result<TrainingClips, String> {
        if self.data.is_none() {
            let cfg = zoo_data::synth::SynthConfig::default();
            crate::args::check_synth_size(("--synth-minutes", self.synth_minutes), cfg.clip_seconds, cfg.fps)?;
            let minutes = ("--synth-minutes", self.synth_minutes);
            crate::args::check_synth_memory(minutes, cfg.clip_seconds, cfg.fps, M::BYTES_PER_SYNTH_FRAME)?;
        }
        Ok(TrainingClips {
            data: self.data.clone(),
            valid_glob: self.valid_glob.clone(),
            exclude_glob,
            skip_invalid: self.skip_invalid,
            synth_minutes: self.synth_minutes,
            seed,
        })
    }
}

/// The library's run and data options of a trainer that reads clips (`exclude_glob`: the RTN's
/// `--exclude-glob`).
pub fn specs<M: TrainDefaults>(
    run: &RunArgs<M>,
    data: &DataArgs<M>,
    exclude_glob: Option<String>,
) -> Result<(RunSpec, TrainingClips), String> {
    Ok((run.spec(), data.spec(exclude_glob, run.seed)?))
}
