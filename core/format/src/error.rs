//! Why a model file's metadata was refused: the key, what was wrong, and the fix.

/// The command that writes a file of this format, named in every message that asks for one.
pub const REEXPORT: &str = "re-export it with `zoo export --onnx RUN_DIR --out FILE.onnx` of this release";

/// A model file whose metadata cannot be read or is not of this format.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormatError {
    /// The bytes are not an ONNX model.
    #[error("{origin} is not an ONNX model ({reason}); pass the .onnx file written by `zoo export --onnx`")]
    NotOnnx {
        /// File path or "the given bytes".
        origin: String,
        /// What the decoder saw.
        reason: String,
    },
    /// A metadata_props entry the format requires is absent.
    #[error(
        "the model has no metadata_props entry `{key}`; it was not written by `zoo export` (or by an older one): re-export it with `zoo export --onnx RUN_DIR --out FILE.onnx` of this release"
    )]
    MissingMetadata {
        /// The key.
        key: String,
    },
    /// A format version newer than this release's, or not a number.
    #[error(
        "model format version {found} is not supported by this runtime (it reads version {supported}); re-export the model with the `zoo export` of this release, or upgrade the runtime"
    )]
    UnknownFormatVersion {
        /// Version in the file.
        found: String,
        /// Version this release reads.
        supported: u32,
    },
    /// A file of an older format version (or of the RMR format that came before one format for
    /// every task).
    #[error(
        "the model has format version {found}, written by an older `zoo export`; this runtime reads version {supported}: re-export it with `zoo export --onnx RUN_DIR --out FILE.onnx` of this release"
    )]
    FormatTooOld {
        /// Version in the file (e.g. `2`, or `rmr 1`).
        found: String,
        /// Version this release reads.
        supported: u32,
    },
    /// The model's task (`zoo.task`) is not one this release knows.
    #[error(
        "the model (kind `{kind}`) has task `{task}`, which this runtime does not know (it knows: {known}); upgrade the runtime or re-export the model with the `zoo export` of this release"
    )]
    UnknownTask {
        /// Task in the file.
        task: String,
        /// Model kind in the file.
        kind: String,
        /// The tasks this release knows, comma-separated.
        known: String,
    },
    /// A metadata entry is present but malformed or inconsistent.
    #[error(
        "metadata_props entry `{key}` is malformed: {reason}; re-export the model with `zoo export --onnx RUN_DIR`"
    )]
    BadMetadata {
        /// The key.
        key: String,
        /// What is wrong.
        reason: String,
    },
}

impl FormatError {
    /// A [`FormatError::BadMetadata`] for `key`.
    pub fn bad(key: &str, reason: impl Into<String>) -> Self {
        FormatError::BadMetadata { key: key.to_string(), reason: reason.into() }
    }
}
