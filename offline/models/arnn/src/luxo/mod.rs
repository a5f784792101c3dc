//! The hopping lamp of "Data-driven Autocompletion for Keyframe Animation" (Zhang and van de
//! Panne 2018, sections 4 and 5): a planar articulated lamp simulated with rapier2d
//! ([`lamp`]), its hop controller ([`controller`]), simulated annealing over hop policies
//! ([`anneal`]), the generated sequences and their files ([`sequence`]), and the preprocessing
//! into training sequences with keys ([`preprocess`]).
//!
//! [`generate`] writes a data set: per sequence `luxo_NNNN.bvh` (opens in Blender) and
//! `luxo_NNNN.json` ([`LuxoSequence`]), and `luxo.json`, a manifest with the settings.
//! Sequence `i` draws all its random numbers from `SplitMix64::with_stream(seed, i)`, so the
//! files do not depend on the number of threads or the order in which sequences finish.

pub mod anneal;
pub mod controller;
pub mod lamp;
pub mod preprocess;
pub mod sequence;

pub use anneal::{AnnealConfig, AnnealStats, Evaluation};
pub use controller::{HopPolicy, RolloutOptions};
pub use lamp::{DOF_NAMES, DOFS, LampParams, LampPose};
pub use sequence::{KeyKind, LuxoKey, LuxoSequence};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use zoo_motion::rng::SplitMix64;

/// Format name of the data set manifest `luxo.json`.
pub const MANIFEST_FORMAT: &str = "zoo-luxo";
/// File name of the manifest.
pub const MANIFEST_FILE: &str = "luxo.json";

/// An error of the lamp data tools.
#[derive(Debug, thiserror::Error)]
pub enum LuxoError {
    /// A file or folder could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// File or folder.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A JSON file could not be written or parsed.
    #[error("{path}: invalid JSON: {message}")]
    Json {
        /// File.
        path: PathBuf,
        /// What serde reported.
        message: String,
    },
    /// A sequence file is well-formed JSON but not a usable sequence.
    #[error("{path}: {message}")]
    BadSequence {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The settings are not usable.
    #[error("invalid lamp data settings: {0}")]
    Config(String),
    /// No annealing run produced a satisfactory hop sequence.
    #[error(
        "sequence {index}: none of {attempts} simulated annealing runs made {hops} hops of at least {min_distance} m \
         in total and {min_height} m high; raise max_attempts or lower min_distance/min_height"
    )]
    NoHops {
        /// Sequence index.
        index: usize,
        /// Runs tried.
        attempts: usize,
        /// Hops required.
        hops: usize,
        /// Required distance (metres).
        min_distance: f64,
        /// Required height (metres).
        min_height: f64,
    },
    /// A data set folder holds no sequence.
    #[error("{0}: no luxo_*.json sequence found; generate some with `zoo data luxo --out {0}`")]
    Empty(PathBuf),
}

/// The most sequences of a data set (the command line's `--sequences` range; the paper uses 300).
pub const MAX_SEQUENCES: usize = 100_000;
/// The most annealing runs per sequence (the command line's `--max-attempts` range).
pub const MAX_ATTEMPTS: usize = 1_000;
/// The most integration steps per recorded frame.
pub const MAX_RECORD_EVERY: usize = 1_000;
/// The most frames of all sequences of a data set together (training keeps them in memory;
/// 100,000 sequences of the paper's settings are 45 million).
pub const MAX_TOTAL_FRAMES: usize = 50_000_000;

/// Settings of a generated data set (written to the manifest).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GenerateOptions {
    /// Number of sequences.
    pub sequences: usize,
    /// Seed: the same seed writes the same files.
    pub seed: u64,
    /// The lamp.
    pub lamp: LampParams,
    /// Simulated annealing (section 4.4).
    pub anneal: AnnealConfig,
    /// Where every annealing run starts (section 4.4's `INIT()`).
    #[serde(default = "HopPolicy::hand_set")]
    pub init: HopPolicy,
    /// Annealing runs tried per sequence before giving up.
    pub max_attempts: usize,
    /// One frame is recorded every `record_every` integration steps.
    pub record_every: usize,
}

impl GenerateOptions {
    /// The paper's settings (K_max = 1000) for `sequences` sequences from `seed`.
    pub fn new(sequences: usize, seed: u64) -> GenerateOptions {
        GenerateOptions {
            sequences,
            seed,
            lamp: LampParams::default(),
            anneal: AnnealConfig::default(),
            init: HopPolicy::hand_set(),
            max_attempts: 20,
            record_every: 4,
        }
    }

    /// Frames per second of the recorded tracks.
    pub fn fps(&self) -> f64 {
        1.0 / (self.lamp.dt * self.record_every as f64)
    }

    /// Checks every setting, each in its range like the command line's options (`sequences` in
    /// 1..=[`MAX_SEQUENCES`], `max_attempts` in 1..=[`MAX_ATTEMPTS`], `record_every` in
    /// 1..=[`MAX_RECORD_EVERY`], the lamp's, the annealing's and the initial policy's own
    /// checks), and what they ask for together before any work: the longest rollout annealing
    /// can simulate at most [`controller::MAX_ROLLOUT_STEPS`] integration steps, the frames
    /// of all sequences at most [`MAX_TOTAL_FRAMES`].
    pub fn validate(&self) -> Result<(), LuxoError> {
        self.lamp.validate().map_err(LuxoError::Config)?;
        self.anneal.validate().map_err(LuxoError::Config)?;
        self.init.validate().map_err(LuxoError::Config)?;
        for (name, v, most) in [
            ("sequences", self.sequences, MAX_SEQUENCES),
            ("max_attempts", self.max_attempts, MAX_ATTEMPTS),
            ("record_every", self.record_every, MAX_RECORD_EVERY),
        ] {
            if !(1..=most).contains(&v) {
                return Err(LuxoError::Config(format!("{name} is {v}: give a whole number in 1..={most}")));
            }
        }
        // Annealing moves each duration within `duration_range`; the start may lie outside it.
        let longest_cycle = self.init.cycle_duration().max(4.0 * self.anneal.duration_range[1]);
        let run_s = longest_cycle * self.anneal.rollout.cycles as f64;
        let steps = controller::rollout_steps(run_s, self.anneal.rollout.settle_s, self.lamp.dt).map_err(|e| {
            LuxoError::Config(format!("{e} (the longest cycle annealing may try is {longest_cycle:?} s)"))
        })?;
        let frames = (steps / self.record_every + 1).saturating_mul(self.sequences);
        if frames > MAX_TOTAL_FRAMES {
            return Err(LuxoError::Config(format!(
                "{} sequences of up to {} frames (one every {} steps of {} s) are up to {frames} frames, more than the \
                 {MAX_TOTAL_FRAMES} zoo keeps in memory: lower sequences or raise record_every",
                self.sequences,
                steps / self.record_every + 1,
                self.record_every,
                self.lamp.dt
            )));
        }
        Ok(())
    }
}

/// What [`generate`] did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GenerateSummary {
    /// Sequences written.
    pub sequences: usize,
    /// Annealing runs in all (successful or not).
    pub attempts: usize,
    /// Frames written in all.
    pub frames: usize,
    /// What happened to the annealing candidates of all runs.
    #[serde(default)]
    pub anneal: AnnealStats,
    /// Seconds taken.
    pub seconds: f64,
}

#[derive(Serialize, Deserialize)]
struct Manifest {
    format: String,
    version: u32,
    options: GenerateOptions,
    sequences: Vec<String>,
}

/// Simulates sequence `index` of a data set: annealing runs from `options.init`, each with
/// a fresh `w_e` uniform in [0, 1), until one is satisfactory.
pub fn generate_sequence(options: &GenerateOptions, index: usize) -> Result<LuxoSequence, LuxoError> {
    options.validate()?;
    let mut rng = SplitMix64::with_stream(options.seed, index as u64);
    let cfg = &options.anneal;
    let mut stats = AnnealStats::default();
    for attempt in 1..=options.max_attempts {
        let w_e = rng.next_f64();
        let outcome = anneal::anneal(&options.lamp, cfg, &options.init, w_e, &mut rng).map_err(LuxoError::Config)?;
        stats.add(&outcome.stats);
        if !outcome.evaluation.satisfactory {
            continue;
        }
        let (rollout, hops, evaluation) =
            anneal::score(&options.lamp, &outcome.best, w_e, cfg).map_err(LuxoError::Config)?;
        let in_air: Vec<usize> =
            hops.iter().map(|_| 1 + rng.below((sequence::HOP_SAMPLES - 2) as u64) as usize).collect();
        let mut seq = LuxoSequence::from_rollout(
            sequence_name(index),
            index,
            options.seed,
            &rollout,
            options.record_every,
            &hops,
            &in_air,
            outcome.best,
            w_e,
            evaluation,
            attempt,
        );
        seq.anneal = stats;
        return Ok(seq);
    }
    Err(LuxoError::NoHops {
        index,
        attempts: options.max_attempts,
        hops: cfg.rollout.cycles,
        min_distance: cfg.min_distance,
        min_height: cfg.min_height,
    })
}

/// File stem of sequence `index`.
pub fn sequence_name(index: usize) -> String {
    format!("luxo_{index:04}")
}

/// Generates `sequences` sequences from `seed` with the paper's settings into `out_dir`; see
/// [`generate_with`].
pub fn generate(
    out_dir: &Path,
    sequences: usize,
    seed: u64,
    progress: &(dyn Fn() + Sync),
) -> Result<GenerateSummary, LuxoError> {
    generate_with(out_dir, &GenerateOptions::new(sequences, seed), progress)
}

/// Generates a data set into `out_dir` (created if needed), in parallel on rayon's pool:
/// `luxo_NNNN.bvh` and `luxo_NNNN.json` per sequence, then the manifest `luxo.json`.
/// `progress` is called once per sequence written.
pub fn generate_with(
    out_dir: &Path,
    options: &GenerateOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<GenerateSummary, LuxoError> {
    options.validate()?;
    let start = std::time::Instant::now();
    std::fs::create_dir_all(out_dir).map_err(|source| LuxoError::Io { path: out_dir.to_path_buf(), source })?;
    let done: Vec<(usize, usize, AnnealStats)> = (0..options.sequences)
        .into_par_iter()
        .map(|i| {
            let seq = generate_sequence(options, i)?;
            let bvh = out_dir.join(format!("{}.bvh", seq.name));
            zoo_data::bvh::write_file(&seq.to_clip(&options.lamp), &bvh)
                .map_err(|source| LuxoError::Io { path: bvh, source })?;
            seq.write_json(&out_dir.join(format!("{}.json", seq.name)))?;
            progress();
            Ok((seq.attempts, seq.frames.len(), seq.anneal))
        })
        .collect::<Result<_, LuxoError>>()?;
    let mut anneal = AnnealStats::default();
    for d in &done {
        anneal.add(&d.2);
    }
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        version: sequence::VERSION,
        options: options.clone(),
        sequences: (0..options.sequences).map(sequence_name).collect(),
    };
    let path = out_dir.join(MANIFEST_FILE);
    zoo_motion::finite::check_serialize("the lamp data's manifest", &manifest)
        .map_err(|e| LuxoError::Json { path: path.clone(), message: e.to_string() })?;
    let text = serde_json::to_string_pretty(&manifest)
        .map_err(|e| LuxoError::Json { path: path.clone(), message: e.to_string() })?;
    sequence::write_atomic(&path, text.as_bytes())?;
    Ok(GenerateSummary {
        sequences: done.len(),
        attempts: done.iter().map(|d| d.0).sum(),
        frames: done.iter().map(|d| d.1).sum(),
        anneal,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Reads the settings a data set was generated with, from its manifest `luxo.json`.
pub fn read_options(dir: &Path) -> Result<GenerateOptions, LuxoError> {
    let path = dir.join(MANIFEST_FILE);
    let text = std::fs::read_to_string(&path).map_err(|source| LuxoError::Io { path: path.clone(), source })?;
    let manifest: Manifest =
        serde_json::from_str(&text).map_err(|e| LuxoError::Json { path: path.clone(), message: e.to_string() })?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(LuxoError::BadSequence {
            path,
            message: format!("not a {MANIFEST_FORMAT} manifest (format {:?})", manifest.format),
        });
    }
    // The settings' errors name the manifest: its values are range-checked like the options.
    manifest.options.validate().map_err(|e| match e {
        LuxoError::Config(message) => LuxoError::BadSequence { path, message: format!("invalid settings: {message}") },
        e => e,
    })?;
    Ok(manifest.options)
}

/// Generates sequences `0..options.sequences` in memory, in parallel on rayon's pool (the
/// same sequences [`generate_with`] writes); `progress` is called once per sequence.
pub fn generate_in_memory(
    options: &GenerateOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<Vec<LuxoSequence>, LuxoError> {
    options.validate()?;
    (0..options.sequences)
        .into_par_iter()
        .map(|i| {
            let seq = generate_sequence(options, i);
            progress();
            seq
        })
        .collect()
}

/// Reads every `luxo_*.json` sequence of a folder, in name order.
pub fn load_dir(dir: &Path) -> Result<Vec<LuxoSequence>, LuxoError> {
    let entries = std::fs::read_dir(dir).map_err(|source| LuxoError::Io { path: dir.to_path_buf(), source })?;
    let mut paths = Vec::new();
    for e in entries {
        let p = e.map_err(|source| LuxoError::Io { path: dir.to_path_buf(), source })?.path();
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if name.starts_with("luxo_") && name.ends_with(".json") {
            paths.push(p);
        }
    }
    if paths.is_empty() {
        return Err(LuxoError::Empty(dir.to_path_buf()));
    }
    paths.sort();
    paths.iter().map(|p| LuxoSequence::read_json(p)).collect()
}

#[cfg(test)]
mod tests;
