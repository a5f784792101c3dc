//! BVH reader and writer.

use std::path::{Path, PathBuf};
use zoo_motion::Clip;

/// Options for reading BVH.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Drop a dummy root (a first joint with a single child whose channels are all zero in
    /// every frame, like bandai2's `joint_Root`), so its child becomes the root.
    pub drop_dummy_root: bool,
}

/// A BVH error: the file, the line (1-based, 0 when not tied to a line) and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The text is not valid BVH.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was found and what was expected.
        message: String,
    },
}

/// Reads a `.bvh` or `.bvh.gz` file (gzip detected by its magic bytes).
pub fn read_file(path: &Path, opts: &ReadOptions) -> Result<Clip, BvhError> {
    let _ = (path, opts);
    todo!("helper")
}

/// Parses BVH text; `path` is only used in error messages.
pub fn parse(text: &str, path: &Path, opts: &ReadOptions) -> Result<Clip, BvhError> {
    let _ = (text, path, opts);
    todo!("helper")
}

/// Writes a clip as BVH text.
pub fn to_string(clip: &Clip) -> String {
    let _ = clip;
    todo!("helper")
}

/// Writes a clip to a `.bvh` file (or gzip-compressed when the name ends in `.gz`).
pub fn write_file(clip: &Clip, path: &Path) -> std::io::Result<()> {
    let _ = (clip, path);
    todo!("helper")
}
