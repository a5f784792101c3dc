//! RNN-GMM checkpoint folders: `config.json`, `model.safetensors`, `features.json` (the
//! [`FeatureSpec`]: skeleton, frame rate, reference rotations, feet), `normalization.json`, and
//! for training `optimizer.safetensors` and `rng.json` (file names and atomic writes from
//! [`zoo_nn::checkpoint`]).

use crate::config::Config;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{FeatureSpec, Normalization};
use crate::model::Generator;
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;

pub use zoo_nn::checkpoint::{CONFIG_FILE, OPTIMIZER_FILE, RNG_FILE, STATS_FILE, WEIGHTS_FILE};

/// The feature definition of a run folder.
pub const FEATURES_FILE: &str = "features.json";

/// The run folder's start clip (`zoo generate` without `--from` continues it).
pub const START_FILE: &str = "start.bvh";

/// Writes a checkpoint folder atomically (created if missing): weights (refused when one holds
/// NaN/inf), feature definition, statistics, then the configuration.
pub fn save(
    dir: &Path,
    config: &Config,
    varmap: &VarMap,
    spec: &FeatureSpec,
    norm: &Normalization,
) -> RnnGmmResult<()> {
    std::fs::create_dir_all(dir).map_err(ck::io(dir))?;
    let weights = ck::stage_varmap(&dir.join(WEIGHTS_FILE), varmap)?;
    let features = ck::stage_json(&dir.join(FEATURES_FILE), spec)?;
    let stats = ck::stage_json(&dir.join(STATS_FILE), norm)?;
    let cfg = ck::stage_json(&dir.join(CONFIG_FILE), config)?;
    ck::commit([weights, features, stats, cfg])?;
    Ok(())
}

/// Reads the configuration, feature definition and statistics of a checkpoint folder, and
/// checks that they agree.
pub fn read_meta(dir: &Path) -> RnnGmmResult<(Config, FeatureSpec, Normalization)> {
    let config_path = dir.join(CONFIG_FILE);
    let value: serde_json::Value = ck::read_json(&config_path)?;
    if let Some(model) = value.get("model").and_then(|m| m.as_str()).filter(|m| *m != "rnn-gmm") {
        return Err(RnnGmmError::Config(format!(
            "{} is a `{model}` checkpoint, not an `rnn-gmm` one",
            config_path.display()
        )));
    }
    let config: Config = serde_json::from_value(value)
        .map_err(|e| RnnGmmError::Config(format!("{}: not an RNN-GMM configuration: {e}", config_path.display())))?;
    let spec_path = dir.join(FEATURES_FILE);
    let spec: FeatureSpec = ck::read_json(&spec_path)?;
    spec.validate().map_err(|e| RnnGmmError::Config(format!("{}: {e}", spec_path.display())))?;
    let norm: Normalization = ck::read_json(&dir.join(STATS_FILE))?;
    check_agree(&config, &spec, &norm)?;
    Ok((config, spec, norm))
}

/// Checks that the configuration, the feature and the statistics have the same frame size.
pub fn check_agree(config: &Config, spec: &FeatureSpec, norm: &Normalization) -> RnnGmmResult<()> {
    if config.dim != spec.dim() || norm.dim() != spec.dim() || norm.std.len() != spec.dim() {
        return Err(RnnGmmError::Config(format!(
            "the configuration has D = {}, the feature of {} joints D = {}, the statistics {} means and {} stds",
            config.dim,
            spec.skeleton.len(),
            spec.dim(),
            norm.mean.len(),
            norm.std.len()
        )));
    }
    Ok(())
}

/// Fills the variables of `varmap` from the folder's weights (every variable must be present).
pub fn load_weights(dir: &Path, varmap: &VarMap) -> RnnGmmResult<()> {
    Ok(ck::read_varmap(&dir.join(WEIGHTS_FILE), varmap)?)
}

/// A trained generator with its feature definition and statistics.
#[derive(Clone, Debug)]
pub struct LoadedGenerator {
    /// The generator (its configuration: [`Generator::config`]).
    pub generator: Generator,
    /// The state feature.
    pub spec: FeatureSpec,
    /// The normalisation statistics.
    pub norm: Normalization,
}

/// Loads a generator for inference from a checkpoint folder. Its weights are constants, not
/// variables: a backward pass through it (control, denoising, the initial state) computes the
/// gradients of its inputs only, not of its 5 million weights at every frame.
pub fn load(dir: &Path, device: &Device) -> RnnGmmResult<LoadedGenerator> {
    let (config, spec, norm) = read_meta(dir)?;
    let varmap = VarMap::new();
    Generator::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
    load_weights(dir, &varmap)?;
    let generator = Generator::new(&config, frozen(&varmap, device)?)?;
    Ok(LoadedGenerator { generator, spec, norm })
}

/// A builder of `varmap`'s weights as constants (detached tensors): networks built from it
/// record no operation for backpropagation, so a forward pass over any number of frames keeps
/// no graph alive (memory independent of the length, no recursive drop of a long graph).
pub fn frozen(varmap: &VarMap, device: &Device) -> RnnGmmResult<VarBuilder<'static>> {
    let data = varmap.data().lock().map_err(|_| RnnGmmError::Config("the weight map's lock is poisoned".into()))?;
    let tensors: std::collections::HashMap<String, candle_core::Tensor> =
        data.iter().map(|(name, var)| (name.clone(), var.as_tensor().detach())).collect();
    Ok(VarBuilder::from_tensors(tensors, DType::F32, device))
}
