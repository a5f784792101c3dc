//! Checkpoint folders: `config.json`, `model.safetensors`, `normalization.json`.
//!
//! Every file is written to a temporary name in the same folder and renamed into place, so an
//! interrupted save never leaves a truncated checkpoint, and a model holding NaN/inf is never
//! saved over the last good one.

use crate::config::Config;
use crate::error::{RtnError, RtnResult};
use crate::model::Rtn;
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::{Path, PathBuf};
use crate::features::FeatureStats;

/// File name of the configuration.
pub const CONFIG_FILE: &str = "config.json";
/// File name of the weights.
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// File name of the normalisation statistics.
pub const STATS_FILE: &str = "normalization.json";

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> RtnError + '_ {
    move |source| RtnError::Io { path: path.to_path_buf(), source }
}

fn tmp_path(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!(".{name}.tmp"))
}

fn write_json_tmp<T: serde::Serialize>(dir: &Path, name: &str, value: &T) -> RtnResult<PathBuf> {
    let tmp = tmp_path(dir, name);
    let text = serde_json::to_string_pretty(value).map_err(|source| RtnError::Json { path: tmp.clone(), source })?;
    std::fs::write(&tmp, text).map_err(io(&tmp))?;
    Ok(tmp)
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> RtnResult<T> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|source| RtnError::Json { path: path.to_path_buf(), source })
}

/// Checks that every variable is finite.
pub fn check_finite(varmap: &VarMap) -> RtnResult<()> {
    let data = varmap.data().lock().expect("the VarMap lock is not poisoned");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for name in names {
        let s = data[name].as_tensor().abs()?.sum_all()?.to_dtype(DType::F32)?.to_scalar::<f32>()?;
        if !s.is_finite() {
            return Err(RtnError::NonFiniteParameter { name: name.clone() });
        }
    }
    Ok(())
}

/// Writes a checkpoint folder atomically (created if missing).
pub fn save(dir: &Path, config: &Config, varmap: &VarMap, stats: &FeatureStats) -> RtnResult<()> {
    check_finite(varmap)?;
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let cfg = write_json_tmp(dir, CONFIG_FILE, config)?;
    let st = write_json_tmp(dir, STATS_FILE, stats)?;
    let w = tmp_path(dir, WEIGHTS_FILE);
    varmap.save(&w)?;
    for (tmp, name) in [(w, WEIGHTS_FILE), (st, STATS_FILE), (cfg, CONFIG_FILE)] {
        let dst = dir.join(name);
        std::fs::rename(&tmp, &dst).map_err(io(&dst))?;
    }
    Ok(())
}

/// Optimiser state of a training checkpoint (`RtnTrainer::save_with_optimizer`).
pub const OPTIMIZER_FILE: &str = "optimizer.safetensors";
/// Moving average of the weights of a training checkpoint (when the run keeps one).
pub const EMA_FILE: &str = "ema.safetensors";

/// Writes named tensors to `dir/name` atomically (a temporary file renamed into place).
pub fn save_tensors(
    dir: &Path,
    name: &str,
    tensors: &std::collections::HashMap<String, candle_core::Tensor>,
) -> RtnResult<()> {
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let tmp = tmp_path(dir, name);
    candle_core::safetensors::save(tensors, &tmp)?;
    let dst = dir.join(name);
    std::fs::rename(&tmp, &dst).map_err(io(&dst))?;
    Ok(())
}

/// Reads the configuration and statistics of a checkpoint folder.
pub fn read_meta(dir: &Path) -> RtnResult<(Config, FeatureStats)> {
    Ok((read_json(&dir.join(CONFIG_FILE))?, read_json(&dir.join(STATS_FILE))?))
}

/// Fills the variables of `varmap` from the folder's weights (every variable must be present).
pub fn load_weights(dir: &Path, varmap: &VarMap) -> RtnResult<()> {
    let path = dir.join(WEIGHTS_FILE);
    if !path.is_file() {
        return Err(RtnError::Io {
            path,
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no weights file"),
        });
    }
    let mut vm = varmap.clone();
    vm.load(&path).map_err(|e| RtnError::Config(format!("{}: {e}", path.display())))?;
    Ok(())
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
