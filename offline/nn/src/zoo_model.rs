//! The one table of models: every model crate implements [`ZooModel`] once, and the commands
//! (`zoo train`, `zoo export`, `zoo bench`, the task commands), the run folders' kinds and
//! the messages that name a model's purpose are derived from the list of them
//! (`zoo_models::MODELS`), as tract-onnx registers each of its operators in one place.
//!
//! A model is trained in candle and used through the file it exports: every command that makes
//! motion exports the run folder (in memory) and runs the file through the engine runtime, by
//! the file's task. So an entry says what it trains, how it exports, and which task its files
//! hold; nothing else of the model is needed to run it.

use std::error::Error;
use std::path::Path;
use zoo_export::{ExportError, OnnxModel};
use zoo_format::MotionTaskKind;

/// An error of a model's training or export, with its message for the user.
pub type BoxError = Box<dyn Error + Send + Sync>;

/// What `zoo export` may set beside the run folder (each model uses what applies to it).
#[derive(Clone, Copy, Debug, Default)]
pub struct ExportOptions<'a> {
    /// A clip of the training skeleton whose joint names, parents, rest offsets and fps the
    /// file records (default: the run folder's skeleton.json).
    pub skeleton: Option<&'a Path>,
    /// Frames per second of the training data (default: the run folder's, else the skeleton
    /// clip's).
    pub fps: Option<f32>,
    /// Length unit of the training data: `cm`, `m`, `mm` or `in` (default: the run folder's,
    /// else `cm`).
    pub units: Option<&'a str>,
}

impl ExportOptions<'_> {
    /// Refuses the options for a model whose run folders always record their skeleton, frame
    /// rate and units (`model`: its name in the message).
    pub fn from_the_run_folder(&self, model: &str) -> Result<(), ExportError> {
        let given: Vec<&str> =
            [(self.skeleton.is_some(), "--skeleton"), (self.fps.is_some(), "--fps"), (self.units.is_some(), "--units")]
                .iter()
                .filter(|(g, _)| *g)
                .map(|(_, n)| *n)
                .collect();
        if given.is_empty() {
            return Ok(());
        }
        Err(ExportError::model(format!(
            "{}: {model} run folders record their skeleton, frame rate and units, and the file takes them from \
             there; drop {}",
            given.join(", "),
            given.join(" and ")
        )))
    }
}

/// How a model's file goes to the portable profile (`zoo export --portable`).
#[derive(Clone, Debug, PartialEq)]
pub enum Portable {
    /// Step graphs: one frame per call.
    Step,
    /// A window graph whose recurrent layers are unrolled over a fixed number of frames:
    /// `(frames, where the number comes from)`.
    Window(usize, String),
    /// Not possible, and why (the message for the user).
    Refused(String),
}

/// A run folder exported as one file.
#[derive(Clone, Debug)]
pub struct Exported {
    /// The file (the model's graphs and metadata, f32 weights).
    pub model: OnnxModel,
    /// What the main graph is, in a few words (`RTN step graph`).
    pub what: &'static str,
    /// What the file holds beside it, for the line `zoo export` prints (`with its start graph
    /// and metadata`).
    pub with: String,
}

/// One model of the zoo.
pub trait ZooModel: Sync {
    /// The kind its run folders record (`config.json`'s `"model"`) and its files carry
    /// (`zoo.model_kind`): `rtn`.
    fn kind(&self) -> &'static str;

    /// The model in one line, with its paper (`zoo train --help`).
    fn about(&self) -> &'static str;

    /// What the model is for, in a few words (said when its folder or file is given to a
    /// command of another task).
    fn purpose(&self) -> &'static str;

    /// The runtime task its files hold.
    fn task(&self) -> MotionTaskKind;

    /// `zoo train KIND`'s options (`clap::Args::augment_args` of the model's arguments).
    fn train_command(&self) -> clap::Command;

    /// Trains from the parsed options of [`ZooModel::train_command`]; `command`: the options the
    /// command line gave, to record in a fresh run's folder (`zoo train --resume` reads them).
    fn train(&self, options: &clap::ArgMatches, command: Vec<(String, Vec<String>)>) -> Result<(), BoxError>;

    /// The run folder `run` as one file (f32 weights; `zoo export --weights` narrows them).
    fn export(&self, run: &Path, options: &ExportOptions) -> Result<Exported, ExportError>;

    /// How the file of `run` goes to the portable profile; `frames`: `zoo export --frames`.
    fn portable(&self, _run: &Path, frames: Option<u32>) -> Result<Portable, ExportError> {
        match frames {
            Some(_) => Err(ExportError::model(
                "--frames applies to window graphs (RMR); this model's graphs run one frame per call",
            )),
            None => Ok(Portable::Step),
        }
    }
}
