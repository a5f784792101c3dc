//! Errors of the runtime: what was wrong, and how to fix it.

/// Why a model could not be loaded or a step could not run.
#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    /// The model file could not be read.
    #[error("cannot read model file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file's metadata is missing, of another format version, or malformed (the format
    /// crate's check, naming the key and the fix).
    #[error(transparent)]
    Format(#[from] zoo_format::FormatError),
    /// The bytes are not an ONNX graph tract can read.
    #[error("{origin} is not an ONNX model ({reason}); pass the .onnx file written by `zoo export --onnx`")]
    NotOnnx {
        /// File path or "bytes".
        origin: String,
        /// What the decoder saw.
        reason: String,
    },
    /// A task's loader, or a function of one task, was given a model of another task.
    #[error(
        "this file is a `{task}` model (kind `{kind}`), not a `{expected}` model: {loader} takes only `{expected}` models; load any file with `zoo_runtime::LoadedModel::load` and run it with its task's type ({hint})"
    )]
    WrongTask {
        /// Task in the file.
        task: String,
        /// Model kind in the file.
        kind: String,
        /// The task the loader runs.
        expected: &'static str,
        /// The loader (e.g. `TransitionModel`).
        loader: &'static str,
        /// The type that runs the file's task.
        hint: &'static str,
    },
    /// A bare step graph (`zoo.task` = `step`) has no task to run.
    #[error(
        "the model (kind `{kind}`) is a bare step graph with no task: drive it with `zoo_runtime::MotionModel::load` and a `MotionRunner`, or export a trained model with `zoo export --onnx RUN_DIR`"
    )]
    NoTask {
        /// Model kind in the file.
        kind: String,
    },
    /// The graph's inputs or outputs do not follow the step-graph convention.
    #[error("graph {what} `{name}`: {reason}")]
    BadGraphIo {
        /// "input" or "output".
        what: &'static str,
        /// Its name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// tract could not load, optimize or plan the graph.
    #[error("tract cannot run this graph: {reason}; export only the ops listed in offline/export/README.md")]
    Unsupported {
        /// tract's error chain.
        reason: String,
    },
    /// A step was given the wrong number of input or output buffers.
    #[error("{what}: expected {expected} buffers (one per graph {what}, in model order), found {found}")]
    BufferCount {
        /// "inputs" or "outputs".
        what: &'static str,
        /// Expected count.
        expected: usize,
        /// Given count.
        found: usize,
    },
    /// A buffer has the wrong length.
    #[error("`{name}`: expected {expected} values ({batch} x {width}), found {found}")]
    BufferLength {
        /// Input, output or state name.
        name: String,
        /// Expected length.
        expected: usize,
        /// Batch size of the call.
        batch: usize,
        /// Values per character.
        width: usize,
        /// Given length.
        found: usize,
    },
    /// An input holds NaN or infinity.
    #[error(
        "input `{name}` holds a non-finite value ({value}) at index {index} (character {character}); fix the caller's data, the model would spread it into every later frame"
    )]
    NonFinite {
        /// Input name.
        name: String,
        /// Flat index in the buffer.
        index: usize,
        /// Character (batch row).
        character: usize,
        /// The value.
        value: f32,
    },
    /// A state does not belong to this model.
    #[error(
        "the character state does not fit this model (state `{name}`: expected {expected} values, found {found}); create it with MotionModel::new_state of the same model"
    )]
    StateMismatch {
        /// State name.
        name: String,
        /// Expected length.
        expected: usize,
        /// Found length.
        found: usize,
    },
    /// A batch call with no characters.
    #[error("a batch step needs at least one character state")]
    EmptyBatch,
    /// tract failed while running the graph.
    #[error("tract failed to run the step graph: {reason}")]
    Run {
        /// tract's error chain.
        reason: String,
    },
    /// A transition longer than the model was trained for, refused unless the runner allows it.
    #[error(
        "a transition of {requested} frames is longer than the {trained} frames this model was trained for (beyond its training length the network drifts from the target); request at most {trained} frames, or opt in with TransitionRunner::allow_beyond_trained(true)"
    )]
    BeyondTrainedLength {
        /// Frames requested (before the target frame).
        requested: usize,
        /// Transition length the model was trained on.
        trained: usize,
    },
    /// Keys that cannot be completed (see [`crate::keyframes::MotionKeys`]).
    #[error("character {character}: {reason}")]
    Keys {
        /// Character (batch row).
        character: usize,
        /// What is wrong and how to fix it.
        reason: String,
    },
    /// A stitching call that does not fit the loaded refiner (window, sequence length).
    #[error("stitching: {reason}")]
    Stitch {
        /// What is wrong and how to fix it.
        reason: String,
    },
    /// A call that does not fit where a character's transition or synthesised sequence stands
    /// (not started, finished, or raw and blended stepping mixed).
    #[error("character {character}: {reason}")]
    TransitionSequence {
        /// Character (batch row).
        character: usize,
        /// What is wrong and what to do.
        reason: String,
    },
    /// A speed / direction control target or controller setting out of range, or a call that
    /// does not fit where a controlled character stands (see [`crate::control`]).
    #[error("control: {reason}")]
    Control {
        /// What is wrong (the value) and how to fix it.
        reason: String,
    },
}

/// Formats an anyhow-style error chain on one line.
pub(crate) fn chain(e: &tract_onnx::prelude::TractError) -> String {
    format!("{e:#}")
}

impl MotionError {
    /// The [`MotionError::WrongTask`] of a model of task `task` given to `loader` of `expected`.
    pub(crate) fn wrong_task(
        metadata: &crate::metadata::MotionModelMetadata,
        expected: &'static str,
        loader: &'static str,
    ) -> Self {
        MotionError::WrongTask {
            task: metadata.task.name().to_string(),
            kind: metadata.model_kind.clone(),
            expected,
            loader,
            hint: crate::loaded::runner_of(metadata.task.kind()),
        }
    }
}
