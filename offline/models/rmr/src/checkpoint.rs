//! RMR checkpoint folders: `config.json`, `model.safetensors`, `normalization.json`, and for
//! training `optimizer.safetensors` and `rng.json` (atomic writes from [`zoo_nn::checkpoint`]).

use crate::config::{Config, ModelName};
use crate::error::{RmrError, RmrResult};
use crate::features::FeatureStats;
use crate::model::Rmr;
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;

pub use zoo_nn::checkpoint::{CONFIG_FILE, OPTIMIZER_FILE, RNG_FILE, STATS_FILE, WEIGHTS_FILE};

/// Writes a checkpoint folder atomically: weights (refused when one holds NaN/inf), statistics,
/// configuration.
pub fn save(dir: &Path, config: &Config, varmap: &VarMap, stats: &FeatureStats) -> RmrResult<()> {
    let weights = ck::stage_varmap(&dir.join(WEIGHTS_FILE), varmap)?;
    let st = ck::stage_json(&dir.join(STATS_FILE), stats)?;
    let cfg = ck::stage_json(&dir.join(CONFIG_FILE), config)?;
    ck::commit([weights, st, cfg])?;
    Ok(())
}

/// Reads the configuration and statistics of a checkpoint folder, refusing another model's folder.
pub fn read_meta(dir: &Path) -> RmrResult<(Config, FeatureStats)> {
    let path = dir.join(CONFIG_FILE);
    let raw: serde_json::Value = ck::read_json(&path)?;
    match raw.get("model").and_then(|m| m.as_str()) {
        Some("rmr") => {}
        Some(other) => {
            return Err(RmrError::Config(format!(
                "{}: this folder holds a `{other}` model, not an RMR; pass a folder written by `zoo train rmr`",
                path.display()
            )));
        }
        None => return Err(RmrError::Config(format!("{}: no \"model\" field; not an RMR run folder", path.display()))),
    }
    let config: Config = serde_json::from_value(raw)
        .map_err(|e| RmrError::Config(format!("{}: not a valid RMR configuration: {e}", path.display())))?;
    debug_assert_eq!(config.model, ModelName::Rmr);
    let stats: FeatureStats = ck::read_json(&dir.join(STATS_FILE))?;
    if stats.dim() != config.dim() || stats.std.len() != stats.mean.len() {
        return Err(RmrError::Config(format!(
            "{}: statistics of {} values, the configuration's pose vector has {}",
            dir.join(STATS_FILE).display(),
            stats.dim(),
            config.dim()
        )));
    }
    Ok((config, stats))
}

/// Fills the variables of `varmap` from the folder's weights.
pub fn load_weights(dir: &Path, varmap: &VarMap) -> RmrResult<()> {
    Ok(ck::read_varmap(&dir.join(WEIGHTS_FILE), varmap)?)
}

/// Loads a model for inference: the model (its configuration is [`Rmr::config`]) and the statistics.
pub fn load(dir: &Path, device: &Device) -> RmrResult<(Rmr, FeatureStats)> {
    let (config, stats) = read_meta(dir)?;
    let varmap = VarMap::new();
    let model = Rmr::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
    load_weights(dir, &varmap)?;
    Ok((model, stats))
}
