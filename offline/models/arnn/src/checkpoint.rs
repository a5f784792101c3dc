//! Loading a trained ARNN from its run folder: `config.json`, `model.safetensors` and
//! `normalization.json`, as [`crate::ArnnTrainer::save`] writes them.

use crate::config::ArnnConfig;
use crate::model::Arnn;
use crate::train::Normalization;
use crate::{ArnnError, ArnnResult};
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_nn::checkpoint as ck;

/// Reads and checks the configuration and the normalisation statistics of a run folder.
pub fn read_meta(dir: &Path) -> ArnnResult<(ArnnConfig, Normalization)> {
    if crate::inbetween::is_inbetween_run(dir) {
        return Err(ArnnError::Config(format!(
            "{} holds the in-betweening design (`zoo train arnn --design inbetween`), which runs in `zoo complete`, \
             `zoo bench` (both layouts) and `zoo export` only (no lamp evaluation)",
            dir.display()
        )));
    }
    let config: ArnnConfig = ck::read_json(&dir.join(ck::CONFIG_FILE))?;
    config.validate().map_err(|e| ArnnError::Config(format!("{}: {e}", dir.join(ck::CONFIG_FILE).display())))?;
    let norm: Normalization = ck::read_json(&dir.join(ck::STATS_FILE))?;
    let d = config.dofs;
    let finite = norm.mean.iter().chain(&norm.std).all(|v| v.is_finite()) && norm.std.iter().all(|s| *s > 0.0);
    if norm.mean.len() != d || norm.std.len() != d || !finite {
        return Err(ArnnError::Config(format!(
            "{}: expected {d} finite means and {d} positive standard deviations, found {} and {}",
            dir.join(ck::STATS_FILE).display(),
            norm.mean.len(),
            norm.std.len()
        )));
    }
    Ok((config, norm))
}

/// Loads the model of a run folder for inference, with its normalisation statistics.
pub fn load(dir: &Path, device: &Device) -> ArnnResult<(Arnn, Normalization)> {
    let (config, norm) = read_meta(dir)?;
    let varmap = VarMap::new();
    let model = Arnn::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
    ck::read_varmap(&dir.join(ck::WEIGHTS_FILE), &varmap)?;
    ck::check_finite(&varmap)?;
    Ok((model, norm))
}
