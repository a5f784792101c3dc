//! Checkpoint files, written atomically: each file goes to a temporary name in its folder
//! (`.NAME.tmp`) and is renamed into place, so an interrupted save never leaves a truncated file
//! and a model holding NaN/inf is never saved over the last good one.
//!
//! A run folder holds the best checkpoint ([`CONFIG_FILE`] naming the model, [`WEIGHTS_FILE`],
//! the model's statistics such as [`STATS_FILE`]), [`TRAIN_STATE_FILE`], [`SUMMARY_FILE`],
//! [`LOSS_CURVE_FILE`], and [`LAST_DIR`] with the last epoch's weights and training state
//! ([`OPTIMIZER_FILE`], [`EMA_FILE`], [`RNG_FILE`]).

use crate::error::{NnError, NnResult};
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The model's configuration; its top-level `"model"` field names the model.
pub const CONFIG_FILE: &str = "config.json";
/// The weights.
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// The normalisation statistics.
pub const STATS_FILE: &str = "normalization.json";
/// Optimiser state(s).
pub const OPTIMIZER_FILE: &str = "optimizer.safetensors";
/// The moving average of the weights.
pub const EMA_FILE: &str = "ema.safetensors";
/// The states of the model's random generators.
pub const RNG_FILE: &str = "rng.json";
/// Progress of the run.
pub const TRAIN_STATE_FILE: &str = "train_state.json";
/// The run's summary.
pub const SUMMARY_FILE: &str = "summary.json";
/// The loss curve.
pub const LOSS_CURVE_FILE: &str = "loss_curve.png";
/// Sub-folder of the last epoch's checkpoint.
pub const LAST_DIR: &str = "last";

/// The run folder's skeleton ([`RunSkeleton`]): what an export needs beyond the config.
pub const SKELETON_FILE: &str = "skeleton.json";

/// The skeleton a model was trained on, kept in its run folder ([`SKELETON_FILE`]) so that
/// `zoo export` writes the names, rest offsets, frame rate and units without being told.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunSkeleton {
    /// Joint names.
    pub names: Vec<String>,
    /// Parent of each joint (-1 for the root).
    pub parents: Vec<i32>,
    /// Rest offset of each joint from its parent, in the data's unit.
    pub offsets: Vec<[f32; 3]>,
    /// Frames per second of the training data.
    pub fps: f32,
    /// Units and axes of the training data.
    pub frame: zoo_motion::frame::CoordinateFrame,
}

impl RunSkeleton {
    /// The skeleton of `s` at `fps` frames per second, in `frame`.
    pub fn new(s: &zoo_motion::Skeleton, fps: f32, frame: zoo_motion::frame::CoordinateFrame) -> Self {
        RunSkeleton {
            names: s.names.clone(),
            parents: s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect(),
            offsets: s.offsets.iter().map(|o| o.as_vec3().to_array()).collect(),
            fps,
            frame,
        }
    }

    /// Writes it into run folder `dir` (atomically).
    pub fn write(&self, dir: &Path) -> NnResult<()> {
        write_json(&dir.join(SKELETON_FILE), self)
    }

    /// The skeleton of run folder `dir`, `None` when it has none (folders of older versions).
    pub fn read(dir: &Path) -> NnResult<Option<Self>> {
        let path = dir.join(SKELETON_FILE);
        if path.is_file() { read_json(&path).map(Some) } else { Ok(None) }
    }
}

/// The kind assumed when `config.json` has no `"model"` field (folders written before the
/// field existed hold an RTN).
pub const DEFAULT_KIND: &str = "rtn";

/// The model kind named by the `"model"` field of `config` (the text of a run folder's
/// `config.json` at `path`); [`DEFAULT_KIND`] when the field is absent.
pub fn kind_of_config(config: &str, path: &Path) -> NnResult<String> {
    let v: serde_json::Value = serde_json::from_str(config)
        .map_err(|e| NnError::Config(format!("{}: not valid JSON ({e})", path.display())))?;
    match v.get("model") {
        None => Ok(DEFAULT_KIND.to_string()),
        Some(serde_json::Value::String(s)) => Ok(s.clone()),
        Some(other) => Err(NnError::Config(format!(
            "{}: `\"model\"` must be a model kind such as \"rtn\", found {other}",
            path.display()
        ))),
    }
}

/// The model kind of the run folder `dir` (see [`kind_of_config`]).
pub fn model_kind(dir: &Path) -> NnResult<String> {
    let path = dir.join(CONFIG_FILE);
    if !path.is_file() {
        return Err(NnError::Config(format!(
            "{} is not a run folder of `zoo train` (no {CONFIG_FILE})",
            dir.display()
        )));
    }
    let text = std::fs::read_to_string(&path).map_err(io(&path))?;
    kind_of_config(&text, &path)
}

/// An error mapper for I/O on `path`.
pub fn io(path: &Path) -> impl FnOnce(std::io::Error) -> NnError + '_ {
    move |source| NnError::Io { path: path.to_path_buf(), source }
}

/// A file written under a temporary name, waiting for [`commit`].
#[derive(Debug)]
#[must_use = "rename it into place with `commit`"]
pub struct Staged {
    tmp: PathBuf,
    dst: PathBuf,
}

/// Writes `dst` under a temporary name in its folder (created if missing) with `write`.
pub fn stage(dst: &Path, write: impl FnOnce(&Path) -> NnResult<()>) -> NnResult<Staged> {
    let dir = dst.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    zoo_format::atomic::check_destination(dst).map_err(io(dst))?;
    let tmp = zoo_format::atomic::temp_path(dst).map_err(io(dst))?;
    write(&tmp)?;
    Ok(Staged { tmp, dst: dst.to_path_buf() })
}

/// Renames staged files into place, in order.
pub fn commit(staged: impl IntoIterator<Item = Staged>) -> NnResult<()> {
    for s in staged {
        std::fs::rename(&s.tmp, &s.dst).map_err(io(&s.dst))?;
    }
    Ok(())
}

/// Stages `value` as pretty JSON, after checking that its numbers are finite.
pub fn stage_json<T: serde::Serialize + ?Sized>(dst: &Path, value: &T) -> NnResult<Staged> {
    zoo_motion::finite::check_serialize(&dst.display().to_string(), value)?;
    stage(dst, |tmp| {
        let text = serde_json::to_string_pretty(value).map_err(|source| NnError::Json { path: tmp.into(), source })?;
        std::fs::write(tmp, text).map_err(io(tmp))
    })
}

/// Stages the variables of `varmap` as safetensors, after checking that they are finite.
pub fn stage_varmap(dst: &Path, varmap: &VarMap) -> NnResult<Staged> {
    check_finite(varmap)?;
    stage(dst, |tmp| varmap.save(tmp).map_err(|e| NnError::Tensors { path: tmp.into(), message: e.to_string() }))
}

/// Stages named tensors as safetensors, after checking that they are finite.
pub fn stage_tensors(dst: &Path, tensors: &HashMap<String, Tensor>) -> NnResult<Staged> {
    for (name, t) in tensors {
        check_tensor(name, t)?;
    }
    stage(dst, |tmp| {
        candle_core::safetensors::save(tensors, tmp)
            .map_err(|e| NnError::Tensors { path: tmp.into(), message: e.to_string() })
    })
}

/// Writes `value` as JSON to `path` atomically.
pub fn write_json<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> NnResult<()> {
    commit([stage_json(path, value)?])
}

/// Writes the (finite) variables of `varmap` to `path` atomically.
pub fn write_varmap(path: &Path, varmap: &VarMap) -> NnResult<()> {
    commit([stage_varmap(path, varmap)?])
}

/// Writes named tensors to `path` atomically.
pub fn write_tensors(path: &Path, tensors: &HashMap<String, Tensor>) -> NnResult<()> {
    commit([stage_tensors(path, tensors)?])
}

/// Reads a JSON file; errors name the file.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> NnResult<T> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text).map_err(|source| NnError::Json { path: path.to_path_buf(), source })
}

/// Reads named tensors; errors name the file.
pub fn read_tensors(path: &Path, device: &Device) -> NnResult<HashMap<String, Tensor>> {
    if !path.is_file() {
        return Err(NnError::Io {
            path: path.into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        });
    }
    candle_core::safetensors::load(path, device)
        .map_err(|e| NnError::Tensors { path: path.into(), message: e.to_string() })
}

/// Fills every variable of `varmap` from the safetensors file `path` (each must be present
/// with its shape).
pub fn read_varmap(path: &Path, varmap: &VarMap) -> NnResult<()> {
    if !path.is_file() {
        return Err(NnError::Io {
            path: path.into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no weights file"),
        });
    }
    let mut vm = varmap.clone();
    vm.load(path).map_err(|e| NnError::Tensors {
        path: path.into(),
        message: format!("{e} (the file was written for another model or configuration)"),
    })?;
    check_weights(path, varmap)
}

/// The largest weight magnitude a weights file may hold. Trained weights stay far below
/// (under 100 in zoo's runs); a larger value overflows f32 in the network's sums.
pub const MAX_WEIGHT: f32 = 1e6;

/// Checks the weights read from `path` where they enter: every value finite and within
/// [`MAX_WEIGHT`]; the error names the file and the tensor, not a later stage.
fn check_weights(path: &Path, varmap: &VarMap) -> NnResult<()> {
    let data = varmap.data().lock().expect("the VarMap lock is not poisoned");
    check_weight_tensors(path, data.iter().map(|(name, v)| (name, v.as_tensor())))
}

/// Reads the named tensors of the weights file `path` ([`read_tensors`]) and checks them as
/// [`read_varmap`] does: for weights read without a model built around them (e.g. the RNN-GMM
/// refiner's, read by its export).
pub fn read_weight_tensors(path: &Path, device: &Device) -> NnResult<HashMap<String, Tensor>> {
    let tensors = read_tensors(path, device)?;
    check_weight_tensors(path, tensors.iter())?;
    Ok(tensors)
}

/// [`check_weights`] on named tensors, in name order.
fn check_weight_tensors<'a>(path: &Path, tensors: impl Iterator<Item = (&'a String, &'a Tensor)>) -> NnResult<()> {
    let mut tensors: Vec<(&String, &Tensor)> = tensors.collect();
    tensors.sort_by(|a, b| a.0.cmp(b.0));
    for (name, t) in tensors {
        if t.elem_count() == 0 {
            continue;
        }
        let bad = |e: candle_core::Error| NnError::Tensors { path: path.into(), message: e.to_string() };
        let abs = t.abs().map_err(bad)?.flatten_all().map_err(bad)?;
        let sum = abs.sum_all().map_err(bad)?.to_dtype(DType::F32).map_err(bad)?.to_scalar::<f32>().map_err(bad)?;
        let max = abs.max(0).map_err(bad)?.to_dtype(DType::F32).map_err(bad)?.to_scalar::<f32>().map_err(bad)?;
        if !sum.is_finite() || !(max <= MAX_WEIGHT) {
            let what =
                if sum.is_nan() || max.is_nan() { "NaN".to_string() } else { format!("a value of magnitude {max:e}") };
            return Err(NnError::Tensors {
                path: path.into(),
                message: format!(
                    "tensor `{name}` holds {what}, outside the weights' range [-{MAX_WEIGHT:e}, {MAX_WEIGHT:e}]: the \
                     weights file is damaged (or its training diverged); use an earlier checkpoint or train again"
                ),
            });
        }
    }
    Ok(())
}

/// Checks that every variable is finite; the error names the first bad one (in name order).
pub fn check_finite(varmap: &VarMap) -> NnResult<()> {
    let data = varmap.data().lock().expect("the VarMap lock is not poisoned");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for name in names {
        check_tensor(name, data[name].as_tensor())?;
    }
    Ok(())
}

/// Checks that tensor `name` holds no NaN or infinity (the sum of its absolute values is finite).
pub fn check_tensor(name: &str, t: &Tensor) -> NnResult<()> {
    let s = t.abs()?.sum_all()?.to_dtype(DType::F32)?.to_scalar::<f32>()?;
    if !s.is_finite() {
        return Err(NnError::NonFiniteParameter { name: name.to_string() });
    }
    Ok(())
}

/// Replaces the folder `dst` by a complete folder written with `write` (into a sibling
/// `.NAME.tmp` folder, then swapped in by two renames), so that `dst` is always either the old
/// or the new checkpoint, never a mix. If the process dies between the two renames, the old
/// folder is at `.NAME.old` ([`resolve_dir`] finds it).
pub fn replace_dir<E: From<NnError>>(dst: &Path, write: impl FnOnce(&Path) -> Result<(), E>) -> Result<(), E> {
    let (tmp, old) = (sibling(dst, "tmp"), sibling(dst, "old"));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(io(&tmp))?;
    }
    std::fs::create_dir_all(&tmp).map_err(io(&tmp))?;
    write(&tmp)?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(io(&old))?;
    }
    if dst.exists() {
        std::fs::rename(dst, &old).map_err(io(dst))?;
    }
    std::fs::rename(&tmp, dst).map_err(io(dst))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(io(&old))?;
    }
    Ok(())
}

/// `dst`, or the previous version left by an interrupted [`replace_dir`] when `dst` is missing.
pub fn resolve_dir(dst: &Path) -> PathBuf {
    let old = sibling(dst, "old");
    if !dst.exists() && old.is_dir() { old } else { dst.to_path_buf() }
}

fn sibling(dst: &Path, what: &str) -> PathBuf {
    let name = dst.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    dst.with_file_name(format!(".{name}.{what}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_nn::Init;

    #[test]
    fn atomic_writes_leave_no_temporary_files_and_refuse_nan() -> NnResult<()> {
        let dir = tempfile::tempdir().unwrap();
        let vm = VarMap::new();
        vm.get((2, 3), "w", Init::Const(1.5), DType::F32, &Device::Cpu)?;
        write_varmap(&dir.path().join(WEIGHTS_FILE), &vm)?;
        write_json(&dir.path().join(CONFIG_FILE), &serde_json::json!({"model": "toy"}))?;
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 2, "{names:?}");
        let before = std::fs::read(dir.path().join(WEIGHTS_FILE)).unwrap();
        let mut bad = vm.clone();
        bad.set_one("w", Tensor::full(f32::NAN, (2, 3), &Device::Cpu)?)?;
        let err = write_varmap(&dir.path().join(WEIGHTS_FILE), &vm).unwrap_err();
        assert!(matches!(&err, NnError::NonFiniteParameter { name } if name == "w"), "{err}");
        assert_eq!(std::fs::read(dir.path().join(WEIGHTS_FILE)).unwrap(), before);
        let loaded = VarMap::new();
        loaded.get((2, 3), "w", Init::Const(0.0), DType::F32, &Device::Cpu)?;
        read_varmap(&dir.path().join(WEIGHTS_FILE), &loaded)?;
        assert_eq!(loaded.data().lock().unwrap()["w"].as_tensor().sum_all()?.to_scalar::<f32>()?, 9.0);
        Ok(())
    }

    #[test]
    fn read_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("broken.json");
        std::fs::write(&p, "{").unwrap();
        let err = read_json::<serde_json::Value>(&p).unwrap_err().to_string();
        assert!(err.contains("broken.json") && err.contains("invalid JSON"), "{err}");
        let err = read_tensors(&dir.path().join("none.safetensors"), &Device::Cpu).unwrap_err().to_string();
        assert!(err.contains("none.safetensors"), "{err}");
        std::fs::write(dir.path().join("bad.safetensors"), "not tensors").unwrap();
        let err = read_tensors(&dir.path().join("bad.safetensors"), &Device::Cpu).unwrap_err().to_string();
        assert!(err.contains("bad.safetensors"), "{err}");
        let vm = VarMap::new();
        vm.get(2, "other", Init::Const(0.0), DType::F32, &Device::Cpu).unwrap();
        let mut t = HashMap::new();
        t.insert("w".to_string(), Tensor::zeros(2, DType::F32, &Device::Cpu).unwrap());
        write_tensors(&dir.path().join("w.safetensors"), &t).unwrap();
        let err = read_varmap(&dir.path().join("w.safetensors"), &vm).unwrap_err().to_string();
        assert!(err.contains("w.safetensors") && err.contains("another model"), "{err}");
    }

    /// Weights are checked where they enter: NaN or a value past f32's sums (3e38 exported with
    /// exit 0 and the runtime blamed the caller's data) names the file and the tensor.
    #[test]
    fn weights_that_are_nan_or_too_large_are_refused_where_they_are_read() -> NnResult<()> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(WEIGHTS_FILE);
        for (value, says) in [(f32::NAN, "holds NaN"), (3e38, "holds a value of magnitude 3e38")] {
            let t = Tensor::new(&[0.5f32, value, 1.0], &Device::Cpu)?;
            candle_core::safetensors::save(&HashMap::from([("layer.w".to_string(), t)]), &p)
                .map_err(|e| NnError::Config(e.to_string()))?;
            let vm = VarMap::new();
            vm.get(3, "layer.w", Init::Const(0.0), DType::F32, &Device::Cpu)?;
            let err = read_varmap(&p, &vm).unwrap_err().to_string();
            assert!(err.contains("model.safetensors: tensor `layer.w`") && err.contains(says), "{err}");
            // Weights read without a model around them (the RNN-GMM refiner's, by its export).
            let err = read_weight_tensors(&p, &Device::Cpu).unwrap_err().to_string();
            assert!(err.contains("model.safetensors: tensor `layer.w`") && err.contains(says), "{err}");
        }
        let t = Tensor::new(&[0.5f32, -2.0, 1.0], &Device::Cpu)?;
        candle_core::safetensors::save(&HashMap::from([("layer.w".to_string(), t)]), &p)
            .map_err(|e| NnError::Config(e.to_string()))?;
        assert_eq!(read_weight_tensors(&p, &Device::Cpu)?.len(), 1);
        Ok(())
    }

    #[test]
    fn replaced_folders_are_whole() -> NnResult<()> {
        let dir = tempfile::tempdir().unwrap();
        let last = dir.path().join(LAST_DIR);
        replace_dir::<NnError>(&last, |d| write_json(&d.join("a.json"), &1))?;
        replace_dir::<NnError>(&last, |d| write_json(&d.join("b.json"), &2))?;
        assert!(!last.join("a.json").exists() && last.join("b.json").is_file());
        let failed: NnResult<()> = replace_dir(&last, |_| Err(NnError::Config("disk full".into())));
        assert!(failed.is_err());
        assert!(last.join("b.json").is_file(), "a failed write keeps the previous folder");
        assert_eq!(resolve_dir(&last), last);
        std::fs::rename(&last, dir.path().join(".last.old")).unwrap();
        assert_eq!(resolve_dir(&last), dir.path().join(".last.old"));
        Ok(())
    }
}
