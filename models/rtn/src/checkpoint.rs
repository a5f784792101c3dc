//! RTN checkpoint folders: `config.json`, `model.safetensors`, `normalization.json`, and for
//! training `optimizer.safetensors`, `ema.safetensors` and `rng.json` (file names and atomic
//! writes from [`zoo_nn::checkpoint`]).
//!
//! Every file is written to a temporary name in the same folder and renamed into place, so an
//! interrupted save never leaves a truncated checkpoint, and a model holding NaN/inf is never
//! saved over the last good one.

use crate::config::Config;
use crate::error::RtnResult;
use crate::features::FeatureStats;
use crate::model::Rtn;
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;

pub use zoo_nn::checkpoint::{CONFIG_FILE, EMA_FILE, OPTIMIZER_FILE, RNG_FILE, STATS_FILE, WEIGHTS_FILE, check_finite};

/// Writes a checkpoint folder atomically (created if missing): the weights (refused when one
/// holds NaN/inf), the statistics, then the configuration.
pub fn save(dir: &Path, config: &Config, varmap: &VarMap, stats: &FeatureStats) -> RtnResult<()> {
    let weights = ck::stage_varmap(&dir.join(WEIGHTS_FILE), varmap)?;
    let st = ck::stage_json(&dir.join(STATS_FILE), stats)?;
    let cfg = ck::stage_json(&dir.join(CONFIG_FILE), config)?;
    ck::commit([weights, st, cfg])?;
    Ok(())
}

/// Reads the configuration and statistics of a checkpoint folder.
pub fn read_meta(dir: &Path) -> RtnResult<(Config, FeatureStats)> {
    Ok((ck::read_json(&dir.join(CONFIG_FILE))?, ck::read_json(&dir.join(STATS_FILE))?))
}

/// Fills the variables of `varmap` from the folder's weights (every variable must be present).
pub fn load_weights(dir: &Path, varmap: &VarMap) -> RtnResult<()> {
    Ok(ck::read_varmap(&dir.join(WEIGHTS_FILE), varmap)?)
}

/// Loads a model for inference from a checkpoint folder: the model, its configuration is
/// [`Rtn::config`], and the normalisation statistics.
pub fn load(dir: &Path, device: &Device) -> RtnResult<(Rtn, FeatureStats)> {
    let (config, stats) = read_meta(dir)?;
    let varmap = VarMap::new();
    let model = Rtn::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
    load_weights(dir, &varmap)?;
    Ok((model, stats))
}
