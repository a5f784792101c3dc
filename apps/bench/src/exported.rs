//! Every command that takes a file written by `zoo export --onnx` loads it here, through the
//! runtime's one loader, and refuses a file of another task with the command that runs it.

use crate::Result;
use std::path::Path;
use zoo_data::{Context, bail};
use zoo_runtime::{LoadedModel, MotionTaskKind};

/// The commands that take an exported file of `task`, for messages.
pub fn commands_for(task: MotionTaskKind) -> &'static str {
    match task {
        MotionTaskKind::Transition => "`zoo bench --methods onnx:FILE` and `zoo bench runtime --model FILE`",
        MotionTaskKind::Keyframes => "`zoo complete --model FILE` and `zoo bench keyframes --model FILE`",
        MotionTaskKind::Stitch => "`zoo stitch --model FILE` and `zoo bench stitch --methods rmr:FILE`",
        MotionTaskKind::Synthesis => "`zoo bench runtime --model FILE` and `zoo bench control --onnx FILE`",
        MotionTaskKind::Step => "the raw step-graph API (`zoo_runtime::MotionModel`)",
    }
}

/// Loads the exported file `path` for `command` (e.g. "`zoo bench runtime`"), which runs the
/// tasks `accepted`; a file of another task is refused with what runs it.
pub fn load(path: &Path, accepted: &[MotionTaskKind], command: &str) -> Result<LoadedModel> {
    let model = LoadedModel::load(path).with_context(|| format!("loading the exported model {}", path.display()))?;
    let task = model.task();
    if !accepted.contains(&task) {
        let takes: Vec<&str> = accepted.iter().map(|t| t.name()).collect();
        bail!(
            "{} is a `{task}` model (kind `{}`): {command} takes {} models; a `{task}` model is used by {}",
            path.display(),
            model.kind(),
            takes.join(" or "),
            commands_for(task)
        );
    }
    Ok(model)
}
