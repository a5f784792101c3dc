//! The one table of the zoo's models. Each model crate implements [`ZooModel`] once (its kind,
//! task, training options and training, export); this list is the only place that names them
//! all. `zoo train`'s subcommands, `zoo export`, the run folders' kinds and the messages that
//! say what a model is for come from it, and every command that makes motion runs a model by
//! the task of the file it exports.
//!
//! Adding a model: its crate under `offline/models/`, one line in [`MODELS`]
//! (docs/adding-a-model.md).

use std::path::Path;
use zoo_format::MotionTaskKind;
pub use zoo_nn::zoo_model::{BoxError, ExportOptions, Exported, Portable, ZooModel};

/// Every model of the zoo, in the order `zoo train --help` lists them.
pub static MODELS: [&dyn ZooModel; 4] =
    [&zoo_rtn::RtnModel, &zoo_rmr::RmrModel, &zoo_rnngmm::RnnGmmModel, &zoo_arnn::ArnnModel];

/// The model of kind `kind` (`config.json`'s `"model"`, a file's `zoo.model_kind`).
pub fn find(kind: &str) -> Option<&'static dyn ZooModel> {
    MODELS.iter().copied().find(|m| m.kind() == kind)
}

/// The kinds of the table, comma-separated (for messages).
pub fn kinds() -> String {
    MODELS.iter().map(|m| m.kind()).collect::<Vec<_>>().join(", ")
}

/// The model of run folder `dir` (its `config.json` names the kind; folders written before the
/// field existed hold an RTN), or a message saying what is wrong with the folder.
pub fn of_run(dir: &Path) -> Result<&'static dyn ZooModel, String> {
    let kind = zoo_nn::checkpoint::model_kind(dir).map_err(|e| e.to_string())?;
    find(&kind).ok_or_else(|| {
        format!(
            "{}: unknown model kind `{kind}`: this zoo knows {} (update zoo for newer models)",
            dir.display(),
            kinds()
        )
    })
}

/// The model of run folder `dir` when it serves `task`; otherwise a message for `zoo COMMAND`
/// that says what the folder's model is for.
pub fn require_task(dir: &Path, task: MotionTaskKind, command: &str) -> Result<&'static dyn ZooModel, String> {
    let model = of_run(dir)?;
    if model.task() == task {
        return Ok(model);
    }
    let serving: Vec<&str> = MODELS.iter().filter(|m| m.task() == task).map(|m| m.kind()).collect();
    Err(format!(
        "`zoo {command}` runs a run folder of {}; {} holds a `{}` model, which is for {}",
        match serving.as_slice() {
            [] => format!("a `{task}` model"),
            [one] => format!("model `{one}` (`zoo train {one}`)"),
            many => format!("model `{}`", many.join("` or `")),
        },
        dir.display(),
        model.kind(),
        model.purpose()
    ))
}

/// Exports run folder `dir` by its model (see [`ZooModel::export`]).
pub fn export_run(dir: &Path, options: &ExportOptions) -> Result<Exported, BoxError> {
    Ok(of_run(dir)?.export(dir, options)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_are_unique_and_every_task_has_a_model() {
        let mut kinds: Vec<&str> = MODELS.iter().map(|m| m.kind()).collect();
        kinds.sort();
        kinds.dedup();
        assert_eq!(kinds.len(), MODELS.len(), "{kinds:?}");
        for task in
            [MotionTaskKind::Transition, MotionTaskKind::Stitch, MotionTaskKind::Keyframes, MotionTaskKind::Synthesis]
        {
            assert!(MODELS.iter().any(|m| m.task() == task), "no model for {task}");
        }
        for m in MODELS {
            assert_eq!(m.train_command().get_name(), m.kind(), "`zoo train {}`", m.kind());
            assert!(!m.about().is_empty() && !m.purpose().is_empty());
        }
    }

    /// Each trainer keeps its own defaults of the shared options (one generic group, one set of
    /// defaults per model).
    #[test]
    fn each_trainer_keeps_its_defaults() {
        let parse = |kind: &str, args: &[&str]| {
            let m = find(kind).unwrap().train_command().try_get_matches_from([&[kind], args].concat()).unwrap();
            let out = m.get_one::<std::path::PathBuf>("out").unwrap().to_str().unwrap().to_string();
            (*m.get_one::<usize>("epochs").unwrap(), out, m.try_get_one::<f64>("synth_minutes").ok().flatten().copied())
        };
        assert_eq!(parse("rtn", &[]), (20, "runs/rtn".into(), Some(30.0)));
        assert_eq!(parse("rmr", &[]), (10, "runs/rmr".into(), Some(10.0)));
        assert_eq!(parse("rnn-gmm", &[]), (10, "runs/rnn-gmm".into(), Some(10.0)));
        assert_eq!(parse("arnn", &["--epochs", "7"]), (7, "runs/arnn".into(), None));
        assert_eq!(parse("arnn", &[]).0, 300);
    }

    #[test]
    fn a_folder_of_another_task_is_refused_with_its_purpose() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("config.json"), r#"{"model": "rmr"}"#).unwrap();
        let err = require_task(dir.path(), MotionTaskKind::Transition, "transition").err().unwrap();
        assert!(
            err.contains("runs a run folder of model `rtn` (`zoo train rtn`)")
                && err.contains("`rmr` model, which is for stitching"),
            "{err}"
        );
        assert_eq!(require_task(dir.path(), MotionTaskKind::Stitch, "stitch").unwrap().kind(), "rmr");
        std::fs::write(dir.path().join("config.json"), r#"{"model": "gan"}"#).unwrap();
        let err = of_run(dir.path()).err().unwrap();
        assert!(err.contains("unknown model kind `gan`") && err.contains("rtn, rmr, rnn-gmm, arnn"), "{err}");
        let err = of_run(&dir.path().join("missing")).err().unwrap();
        assert!(err.contains("not a run folder"), "{err}");
    }
}
