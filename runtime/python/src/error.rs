//! The runtime's errors as Python exceptions, with the runtime's own messages.
//!
//! `ZooError` is the base of every exception the package raises. `MotionError` is the
//! runtime's [`zoo_runtime::MotionError`] (its variant name in the exception's `kind`
//! attribute), with two subclasses a script may want to tell apart: `WrongTaskError` (a model
//! of another task) and `ModelFileError` (a file that cannot be read or is not an exported
//! model). `ShapeError` is an array of the wrong shape or type given to the package, caught
//! before the runtime sees it; `NonFiniteError` a NaN or infinity in an array (given to the package,
//! or met by the runtime); `BvhError` a BVH file that cannot be read or written.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use zoo_runtime::MotionError as RuntimeError;

create_exception!(zoo, ZooError, PyException, "Base class of every error raised by the zoo package.");
create_exception!(
    zoo,
    MotionError,
    ZooError,
    "An error of zoo's runtime (`zoo_runtime::MotionError`): the message says what was wrong and how to fix \
     it; `kind` names the runtime's variant (e.g. `BufferLength`, `Keys`, `Control`)."
);
create_exception!(
    zoo,
    WrongTaskError,
    MotionError,
    "A model of another task than the one asked for (e.g. a stitch model given to a transition)."
);
create_exception!(
    zoo,
    ModelFileError,
    MotionError,
    "A model file that cannot be read, is not ONNX, is of another format version, or has bad metadata."
);
create_exception!(
    zoo,
    ShapeError,
    ZooError,
    "An array of the wrong shape, type or values given to the package (checked before the runtime runs)."
);
create_exception!(zoo, BvhError, ZooError, "A BVH file that cannot be read or written.");
create_exception!(
    zoo,
    NonFiniteError,
    ZooError,
    "A NaN or an infinity in an array given to the package (the message names the array and the index)."
);

/// The name of a runtime error's variant (the exception's `kind`), from its `Debug` form so
/// that a variant added to the runtime needs no change here.
fn kind(e: &RuntimeError) -> String {
    let debug = format!("{e:?}");
    debug.split(|c: char| !c.is_alphanumeric() && c != '_').next().unwrap_or_default().to_string()
}

/// A runtime error as the Python exception of its category, carrying the runtime's message.
pub fn motion(e: RuntimeError) -> PyErr {
    let message = e.to_string();
    let err = match &e {
        RuntimeError::WrongTask { .. } => WrongTaskError::new_err(message),
        RuntimeError::NonFinite { .. } => NonFiniteError::new_err(message),
        RuntimeError::Io { .. }
        | RuntimeError::Format(_)
        | RuntimeError::NotOnnx { .. }
        | RuntimeError::NoTask { .. }
        | RuntimeError::BadGraphIo { .. }
        | RuntimeError::Unsupported { .. } => ModelFileError::new_err(message),
        _ => MotionError::new_err(message),
    };
    Python::attach(|py| {
        // Setting an attribute on a fresh exception instance cannot fail in practice; if it
        // does, the exception still carries its message.
        let _ = err.value(py).setattr("kind", kind(&e));
    });
    err
}

/// A [`NonFiniteError`] with `message`.
pub fn non_finite(message: impl Into<String>) -> PyErr {
    NonFiniteError::new_err(message.into())
}

/// A [`ShapeError`] with `message`.
pub fn shape(message: impl Into<String>) -> PyErr {
    ShapeError::new_err(message.into())
}

/// Result of a runtime call, as a Python result.
pub trait OrPy<T> {
    /// Converts the runtime's error into its Python exception.
    fn or_py(self) -> PyResult<T>;
}

impl<T> OrPy<T> for Result<T, RuntimeError> {
    fn or_py(self) -> PyResult<T> {
        self.map_err(motion)
    }
}

/// Registers the exception types on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("ZooError", py.get_type::<ZooError>())?;
    m.add("MotionError", py.get_type::<MotionError>())?;
    m.add("WrongTaskError", py.get_type::<WrongTaskError>())?;
    m.add("ModelFileError", py.get_type::<ModelFileError>())?;
    m.add("ShapeError", py.get_type::<ShapeError>())?;
    m.add("BvhError", py.get_type::<BvhError>())?;
    m.add("NonFiniteError", py.get_type::<NonFiniteError>())?;
    Ok(())
}
