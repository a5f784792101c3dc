//! Errors of graph building and writing.

/// Why a graph could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Two values, nodes or initializers were given the same name.
    #[error(
        "the name `{0}` is used twice in the graph; give every node and initializer its own name (e.g. a candle variable path)"
    )]
    DuplicateName(String),
    /// A node refers to a value no input, initializer or earlier node produces.
    #[error(
        "node `{node}` reads `{value}`, which no graph input, initializer or earlier node produces; create values before using them"
    )]
    UnknownValue {
        /// The node that reads the value.
        node: String,
        /// The missing value.
        value: String,
    },
    /// Initializer data length does not match its shape.
    #[error("initializer `{name}` has shape {dims:?} ({expected} values) but {found} values were given")]
    ShapeMismatch {
        /// Initializer name.
        name: String,
        /// Declared shape.
        dims: Vec<usize>,
        /// Product of the shape.
        expected: usize,
        /// Length of the data.
        found: usize,
    },
    /// An argument of an op helper is invalid (the message says which and why).
    #[error("node `{node}`: {message}")]
    InvalidOp {
        /// The node being built.
        node: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// The graph has no outputs.
    #[error("graph `{0}` has no outputs; declare at least one with GraphBuilder::output")]
    NoOutputs(String),
    /// A model cannot be exported (missing weight, skeleton, inconsistent checkpoint).
    #[error("cannot export the model: {0}")]
    Model(String),
    /// Bytes given as an ONNX model do not decode as one.
    #[error("{origin} is not an ONNX model ({reason}); pass a file written by `zoo export --onnx`")]
    NotOnnx {
        /// File path or metadata key the bytes came from.
        origin: String,
        /// What the decoder saw.
        reason: String,
    },
    /// A graph cannot be written with the portable operator set (`zoo export --portable`).
    #[error("graph `{graph}` cannot be exported portably: {message}")]
    NotPortable {
        /// The graph's name.
        graph: String,
        /// What is in the way, and how to fix it.
        message: String,
    },
    /// Writing the file failed.
    #[error("cannot write ONNX file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl ExportError {
    /// An [`ExportError::Model`]: the model cannot be exported, for the reason given.
    pub fn model(message: impl Into<String>) -> Self {
        ExportError::Model(message.into())
    }
}
