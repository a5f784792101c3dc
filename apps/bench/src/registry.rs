//! The model registry of the benchmarks: which model a run folder holds and which benchmark
//! method it gives.
//!
//! Every run folder's `config.json` names its model in a top-level `"model"` field (folders
//! written before the field existed hold an RTN: a missing field means `rtn`;
//! [`zoo_nn::checkpoint::model_kind`]). A kind maps to its benchmark method (`zoo bench
//! --methods KIND:DIR`, `KIND+lock:DIR` with the foot lock). An exported file is benchmarked as
//! `onnx:FILE.onnx` (`onnx+lock:FILE.onnx`), run by the engine runtime, which checks the file's
//! own model kind.

use crate::Result;
use std::path::{Path, PathBuf};
use zoo_data::benchmark::{Interpolation, TransitionMethod, ZeroVelocity};
use zoo_data::{Context, bail};

pub use zoo_nn::checkpoint::{CONFIG_FILE, DEFAULT_KIND, kind_of_config};

/// The method kind of exported ONNX files (`onnx:FILE.onnx`).
pub const ONNX_KIND: &str = "onnx";

/// Loads a benchmark method from a run folder: `(folder, method name, foot lock)`.
type BenchLoader =
    fn(&Path, String, bool) -> std::result::Result<Box<dyn TransitionMethod>, zoo_nn::zoo_model::BoxError>;

/// What the benchmarks do with one kind of model.
pub struct ModelEntry {
    /// The kind's name, as in `config.json` and `--methods KIND:DIR`.
    pub kind: &'static str,
    /// What the model is for, in a few words (said when it is used for something else).
    pub purpose: &'static str,
    /// Its benchmark method in candle (`candle-KIND:DIR`, and `KIND:DIR` when the runtime has
    /// none), for models that generate transitions.
    pub bench: Option<BenchLoader>,
    /// Its benchmark method through the engine runtime (the run folder exported in memory):
    /// what `KIND:DIR` runs, what users get.
    pub runtime: Option<BenchLoader>,
    /// Whether its benchmark method takes the foot lock (`KIND+lock:RUN_DIR`).
    pub foot_lock: bool,
}

/// The models the benchmarks know: the table of models ([`zoo_models::MODELS`]). A model of the
/// runtime's transition task runs exported through the runtime; a model with transitions in
/// candle ([`zoo_nn::ZooModel::candle_transitions`]) also runs as `candle-KIND:DIR`.
pub fn models() -> Vec<ModelEntry> {
    zoo_models::MODELS
        .iter()
        .map(|m| {
            let candle = m.candle_transitions();
            let transition = m.task() == zoo_runtime::MotionTaskKind::Transition;
            // Keyframe models with transitions in candle: the in-betweening design through the
            // runtime's keyframes task, with its foot lock.
            let keys = m.task() == zoo_runtime::MotionTaskKind::Keyframes && candle.is_some();
            let runtime = if transition {
                Some(load_runtime_transition as BenchLoader)
            } else {
                keys.then_some(load_runtime_keys as BenchLoader)
            };
            ModelEntry {
                kind: m.kind(),
                purpose: m.purpose(),
                bench: candle.map(|c| c.load),
                runtime,
                foot_lock: transition || keys || candle.is_some_and(|c| c.foot_lock),
            }
        })
        .collect()
}

/// `KIND:DIR` of a transition model: the run folder exported in memory and run by the engine
/// runtime, as `zoo transition` and engines run it.
fn load_runtime_transition(
    dir: &Path,
    name: String,
    foot_lock: bool,
) -> std::result::Result<Box<dyn TransitionMethod>, zoo_nn::zoo_model::BoxError> {
    let exported = zoo_models::export_run(dir, &Default::default())
        .with_context(|| format!("exporting the run folder {} for the runtime", dir.display()))?;
    let model = zoo_runtime::TransitionModel::from_bytes(&exported.model.to_bytes())?;
    Ok(Box::new(crate::onnx::onnx_method(model, name, foot_lock)))
}

/// `KIND:DIR` of a keyframe model on the transition layout: a whole-shot model (the
/// in-betweening design) exported in memory and run by the runtime's keyframes task (the context
/// and the target its keys; the runtime's foot lock with `+lock`), as `zoo complete` and engines
/// run it; a model that completes frame by frame (the autoregressive ARNN) keeps its own context
/// layout in candle.
fn load_runtime_keys(
    dir: &Path,
    name: String,
    foot_lock: bool,
) -> std::result::Result<Box<dyn TransitionMethod>, zoo_nn::zoo_model::BoxError> {
    let model = crate::keys::exported(dir).map_err(|e| e.to_string())?;
    if model.is_inbetween() {
        let keys = crate::keys::RuntimeKeys::of(model, dir, name, foot_lock).map_err(|e| e.to_string())?;
        return Ok(Box::new(crate::keys::KeysOnTransitions::new(Box::new(keys))));
    }
    let kind = model_kind(dir).map_err(|e| e.to_string())?;
    match zoo_models::MODELS.iter().find(|m| m.kind() == kind).and_then(|m| m.candle_transitions()) {
        Some(candle) => (candle.load)(dir, name, foot_lock),
        None => Err(format!("method `{name}`: a `{kind}` model makes no transitions").into()),
    }
}

fn known_kinds(models: &[ModelEntry]) -> String {
    models.iter().map(|m| m.kind).collect::<Vec<_>>().join(", ")
}

/// The entry of `kind` in `models`; an unknown kind is refused with the list of known ones.
fn entry_in<'a>(models: &'a [ModelEntry], kind: &str) -> Result<&'a ModelEntry> {
    Ok(models.iter().find(|m| m.kind == kind).with_context(|| {
        format!("unknown model kind `{kind}`: this zoo knows {} (update zoo for newer models)", known_kinds(models))
    })?)
}

/// The model kind of run folder `dir` ([`zoo_nn::checkpoint::model_kind`]).
pub fn model_kind(dir: &Path) -> Result<String> {
    Ok(zoo_nn::checkpoint::model_kind(dir)?)
}

/// A parsed `--methods` entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum MethodSpec {
    /// `zerovel`: the zero-velocity baseline.
    ZeroVelocity,
    /// `interp`: the interpolation baseline.
    Interpolation,
    /// `KIND:PATH` or `KIND+lock:PATH`: a trained model (a run folder, or an exported file for
    /// `onnx`).
    Model {
        /// The whole spec, the method's name in the table.
        name: String,
        /// Model kind (or `onnx`).
        kind: String,
        /// Run folder or file.
        path: PathBuf,
        /// `+lock`: foot-lock the fitted transitions.
        foot_lock: bool,
        /// `candle-KIND:DIR`: the training model in candle (for parity checks) instead of the
        /// exported one in the runtime.
        candle: bool,
    },
}

fn method_forms(models: &[ModelEntry]) -> String {
    let mut forms = vec!["zerovel".to_string(), "interp".to_string()];
    for m in models.iter().filter(|m| m.bench.is_some()) {
        forms.push(if m.foot_lock {
            format!("{0}:RUN_DIR, {0}+lock:RUN_DIR", m.kind)
        } else {
            format!("{}:RUN_DIR", m.kind)
        });
    }
    forms.push(format!("{ONNX_KIND}:FILE.onnx, {ONNX_KIND}+lock:FILE.onnx"));
    forms.push("candle-KIND:RUN_DIR (the training model in candle)".into());
    forms.join(", ")
}

fn parse_method_in(models: &[ModelEntry], spec: &str) -> Result<MethodSpec> {
    match spec {
        "zerovel" => return Ok(MethodSpec::ZeroVelocity),
        "interp" => return Ok(MethodSpec::Interpolation),
        _ => {}
    }
    let Some((head, path)) = spec.split_once(':') else {
        bail!("unknown method `{spec}`: expected {}", method_forms(models));
    };
    let (candle, head) = match head.strip_prefix("candle-") {
        Some(rest) => (true, rest),
        None => (false, head),
    };
    let (kind, foot_lock) = match head.strip_suffix("+lock") {
        Some(kind) => (kind, true),
        None => (head, false),
    };
    if candle && kind == ONNX_KIND {
        bail!(
            "method `{spec}`: `candle-` runs a run folder's training model; an exported file runs as `{ONNX_KIND}:FILE`"
        );
    }
    if path.is_empty() {
        bail!("method `{spec}`: the path after `{head}:` is empty");
    }
    if kind != ONNX_KIND {
        let entry =
            entry_in(models, kind).with_context(|| format!("method `{spec}`: expected {}", method_forms(models)))?;
        if entry.bench.is_none() {
            bail!("method `{spec}`: a `{kind}` model is for {}, not for the transition benchmark", entry.purpose);
        }
    }
    Ok(MethodSpec::Model {
        name: spec.to_string(),
        kind: kind.to_string(),
        path: PathBuf::from(path),
        foot_lock,
        candle,
    })
}

/// Parses one `--methods` entry (`zerovel`, `interp`, `KIND:PATH`, `KIND+lock:PATH`).
pub fn parse_method(spec: &str) -> Result<MethodSpec> {
    parse_method_in(&models(), spec)
}

/// Refuses a method spec whose kind is not the one the folder's `config.json` names.
fn check_folder_kind(spec: &str, kind: &str, dir: &Path, found: &str) -> Result<()> {
    if found != kind {
        bail!(
            "method `{spec}`: {} names model `{found}`, not `{kind}`: write `{found}:{}`",
            dir.join(CONFIG_FILE).display(),
            dir.display()
        );
    }
    Ok(())
}

fn load_method_in(models: &[ModelEntry], spec: &MethodSpec) -> Result<Box<dyn TransitionMethod>> {
    Ok(match spec {
        MethodSpec::ZeroVelocity => Box::new(ZeroVelocity),
        MethodSpec::Interpolation => Box::new(Interpolation),
        MethodSpec::Model { name, kind, path, foot_lock, .. } if kind == ONNX_KIND => {
            Box::new(crate::onnx::load_onnx(path, name.clone(), *foot_lock)?)
        }
        MethodSpec::Model { name, kind, path, foot_lock, candle } => {
            check_folder_kind(name, kind, path, &model_kind(path)?)?;
            let entry = entry_in(models, kind)?;
            let loader = if *candle { entry.bench } else { entry.runtime.or(entry.bench) };
            let Some(load) = loader else {
                bail!("method `{name}`: a `{kind}` model is for {}, not for the transition benchmark", entry.purpose);
            };
            load(path, name.clone(), *foot_lock).map_err(|e| zoo_data::Message(e.to_string()))?
        }
    })
}

/// Loads a parsed `--methods` entry.
pub fn load_method(spec: &MethodSpec) -> Result<Box<dyn TransitionMethod>> {
    load_method_in(&models(), spec)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_bench(
        _: &Path,
        _: String,
        _: bool,
    ) -> std::result::Result<Box<dyn TransitionMethod>, zoo_nn::zoo_model::BoxError> {
        unreachable!("the test registry's loader is never called")
    }

    /// RTN plus two made-up kinds: one for something else, one benchmarked but not a
    /// `zoo transition` model.
    const TEST_MODELS: &[ModelEntry] = &[
        ModelEntry { kind: "rtn", purpose: "transitions", bench: Some(no_bench), runtime: None, foot_lock: true },
        ModelEntry { kind: "gmm", purpose: "sampling poses", bench: None, runtime: None, foot_lock: true },
        ModelEntry { kind: "arnn", purpose: "long in-betweens", bench: Some(no_bench), runtime: None, foot_lock: true },
    ];

    fn err<T, E: std::fmt::Display>(r: std::result::Result<T, E>) -> String {
        match r {
            Ok(_) => panic!("expected an error"),
            Err(e) => format!("{e:#}"),
        }
    }

    #[test]
    fn the_known_spellings_parse() {
        assert_eq!(parse_method("zerovel").unwrap(), MethodSpec::ZeroVelocity);
        assert_eq!(parse_method("interp").unwrap(), MethodSpec::Interpolation);
        for (spec, kind, lock, on_candle) in [
            ("rtn:runs/a", "rtn", false, false),
            ("rtn+lock:runs/a", "rtn", true, false),
            ("candle-rtn+lock:runs/a", "rtn", true, true),
            ("onnx:m.onnx", "onnx", false, false),
            ("onnx+lock:m.onnx", "onnx", true, false),
        ] {
            let MethodSpec::Model { name, kind: k, path, foot_lock, candle } = parse_method(spec).unwrap() else {
                panic!("{spec}: not a model method")
            };
            assert_eq!((name.as_str(), k.as_str(), foot_lock, candle), (spec, kind, lock, on_candle));
            assert_eq!(path, PathBuf::from(spec.split_once(':').unwrap().1));
        }
    }

    #[test]
    fn an_unknown_method_lists_the_known_forms() {
        let e = err(parse_method("nearest"));
        assert!(
            e.contains("unknown method `nearest`") && e.contains("rtn+lock:RUN_DIR") && e.contains("onnx:FILE.onnx"),
            "{e}"
        );
        let e = err(parse_method_in(TEST_MODELS, "rmr:runs/x"));
        assert!(e.contains("unknown model kind `rmr`: this zoo knows rtn, gmm, arnn"), "{e}");
        let e = err(parse_method("rtn:"));
        assert!(e.contains("the path after `rtn:` is empty"), "{e}");
    }

    #[test]
    fn a_kind_without_a_benchmark_method_is_refused_with_its_purpose() {
        let e = err(parse_method_in(TEST_MODELS, "gmm:runs/g"));
        assert!(e.contains("a `gmm` model is for sampling poses, not for the transition benchmark"), "{e}");
        assert!(parse_method_in(TEST_MODELS, "arnn+lock:runs/a").is_ok());
    }

    #[test]
    fn the_config_names_the_model_and_defaults_to_rtn() {
        let p = Path::new("run/config.json");
        assert_eq!(kind_of_config(r#"{"joints": 4}"#, p).unwrap(), "rtn");
        assert_eq!(kind_of_config(r#"{"model": "arnn", "joints": 4}"#, p).unwrap(), "arnn");
        let e = err(kind_of_config(r#"{"model": 3}"#, p));
        assert!(e.contains("run/config.json: `\"model\"` must be a model kind"), "{e}");
        assert!(err(kind_of_config("{", p)).contains("run/config.json: not valid JSON"));
    }

    #[test]
    fn a_folder_of_another_kind_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(CONFIG_FILE), r#"{"model": "arnn"}"#).unwrap();
        let spec = parse_method_in(TEST_MODELS, &format!("rtn:{}", dir.path().display())).unwrap();
        let e = err(load_method_in(TEST_MODELS, &spec));
        assert!(e.contains("names model `arnn`, not `rtn`: write `arnn:"), "{e}");
        let e = err(model_kind(&dir.path().join("missing")));
        assert!(e.contains("is not a run folder of `zoo train` (no config.json)"), "{e}");
    }
}
