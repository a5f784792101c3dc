//! A model as the commands take it: a run folder of `zoo train` (exported in memory by its
//! model's entry in the table of models, `zoo_models`) or a file of `zoo export --onnx`. Either
//! way the command gets the bytes of one exported file and runs them through the runtime.

use crate::TaskResult;
use std::path::{Path, PathBuf};
use zoo_data::{Context, Message, bail};
use zoo_format::{MotionModelMetadata, MotionTaskKind};
use zoo_runtime::LoadedModel;

/// An exported model, before the runtime loads it: its bytes and metadata.
#[derive(Clone, Debug)]
pub struct ModelSource {
    /// The run folder or file given.
    pub path: PathBuf,
    /// The exported file's bytes (f32 weights for a run folder).
    pub bytes: Vec<u8>,
    /// Its metadata (task, skeleton, frame rate, statistics).
    pub metadata: MotionModelMetadata,
}

impl ModelSource {
    /// The model at `path` for `zoo COMMAND`, which runs `task`: a run folder is exported (its
    /// model checked against the task first, with what a model of another task is for), a file
    /// read; either is refused when it holds another task.
    pub fn open(path: &Path, task: MotionTaskKind, command: &str) -> TaskResult<ModelSource> {
        Self::open_for(path, &[task], command)
    }

    /// [`ModelSource::open`] for a command that runs models of any of `tasks` (a run folder's
    /// refusal is the first task's).
    pub fn open_for(path: &Path, tasks: &[MotionTaskKind], command: &str) -> TaskResult<ModelSource> {
        let task = tasks[0];
        let bytes = if path.is_dir() {
            let fits = tasks.iter().find_map(|&t| zoo_models::require_task(path, t, command).ok());
            let model = match fits {
                Some(m) => m,
                None => zoo_models::require_task(path, task, command).map_err(Message)?,
            };
            let exported = model
                .export(path, &Default::default())
                .with_context(|| format!("exporting the run folder {} for the runtime", path.display()))?;
            exported.model.to_bytes()
        } else if path.is_file() {
            std::fs::read(path).with_context(|| format!("reading {}", path.display()))?
        } else {
            bail!(
                "{} is not a run folder of `zoo train` nor a file of `zoo export --onnx` (it does not exist)",
                path.display()
            );
        };
        let metadata = MotionModelMetadata::read(&bytes, &path.display().to_string())
            .with_context(|| format!("{}", path.display()))?;
        if !tasks.contains(&metadata.task.kind()) {
            let what = zoo_models::find(&metadata.model_kind)
                .map_or(String::new(), |m| format!(", which is for {}", m.purpose()));
            let runs: Vec<String> = tasks.iter().map(|t| format!("`{t}`")).collect();
            bail!(
                "`zoo {command}` runs a {} model; {} holds a `{}` model (`{}`){what}",
                runs.join(" or "),
                path.display(),
                metadata.task.kind(),
                metadata.model_kind
            );
        }
        Ok(ModelSource { path: path.to_path_buf(), bytes, metadata })
    }

    /// The model's skeleton (joint names, parents, rest offsets), as its file records it.
    pub fn skeleton(&self) -> zoo_motion::Skeleton {
        self.metadata.skeleton.to_skeleton()
    }

    /// The model loaded by the runtime.
    pub fn load(&self) -> TaskResult<LoadedModel> {
        Ok(LoadedModel::from_bytes(&self.bytes)
            .with_context(|| format!("loading {} in the runtime", self.path.display()))?)
    }
}
