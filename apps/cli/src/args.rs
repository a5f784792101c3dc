//! The value parsers of the numeric options (`zoo_nn::args`, shared with the model crates'
//! training options) and the `CLIP:FRAME` argument.

pub use zoo_nn::args::*;

/// Parses a clip argument `PATH:FRAME`.
pub fn clip_and_frame(s: &str) -> anyhow::Result<(std::path::PathBuf, usize)> {
    use anyhow::Context;
    let (path, frame) =
        s.rsplit_once(':').with_context(|| format!("`{s}`: expected CLIP.bvh:FRAME, e.g. walk.bvh:120"))?;
    let frame = frame.parse().with_context(|| format!("`{s}`: `{frame}` is not a frame number"))?;
    Ok((std::path::PathBuf::from(path), frame))
}

/// A memory bound in GB, `(0, 1e6]` (`--max-memory`).
pub fn memory_gb(s: &str) -> Result<f64, String> {
    real_in(s, Interval::above(0.0, 1e6), " GB")
}
