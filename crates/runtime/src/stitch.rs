//! The stitching task: refines an aligned sequence of RMR pose vectors with an exported
//! Recurrent Motion Refiner (Kim et al. 2023, sec. 6) on tract, window by window.
//!
//! The file is what `zoo export --onnx RMR_DIR` writes: the refiner over one window
//! (`x [frames, batch, dim] -> y [frames, batch, dim]`, normalised, contacts as logits) with
//! its configuration (`zoo.rmr.config`) and normalisation (`zoo.rmr.normalization`) in
//! `metadata_props`. [`StitchRefiner`] plans the graph once for a window of `w` frames at batch 1
//! and refines raw pose vectors (the layout of `zoo_rmr::features`: `r, p, q, v, c` per frame)
//! exactly as the offline `zoo_rmr::stitch::refine_sequence` does: windows every `s` frames
//! plus one ending on the last frame, each window's input holding the frames already refined,
//! the difference at each window's first frame blended away over `blend_frames` frames,
//! contacts returned as 0/1.
//!
//! Not here yet: encoding clips into pose vectors and decoding them back (forward kinematics
//! and ground roots live in the offline `zoo_data::stitch` and `zoo_rmr::features`), and the
//! streaming form for motion matching.

use crate::error::{MotionError, chain};
use std::path::Path;
use std::sync::Arc;
use tract_onnx::prelude::*;

/// `zoo.model_kind` of an exported RMR.
pub const RMR_KIND: &str = "rmr";
/// The version of the `zoo.rmr.*` metadata this runtime reads.
pub const RMR_FORMAT_VERSION: u32 = 1;

type Plan = Arc<TypedRunnableModel>;

/// An exported RMR, planned for one window size, ready to refine sequences. `Send + Sync`: one
/// loaded refiner serves every thread.
#[derive(Clone, Debug)]
pub struct StitchRefiner {
    model: InferenceModel,
    plan: Plan,
    window: usize,
    stride: usize,
    blend_frames: usize,
    dim: usize,
    pose: usize,
    joints: usize,
    fps: f64,
    mean: Vec<f32>,
    std: Vec<f32>,
}

fn stitch_err(reason: impl Into<String>) -> MotionError {
    MotionError::Stitch { reason: reason.into() }
}

fn plan_for(model: &InferenceModel, window: usize, dim: usize) -> Result<Plan, MotionError> {
    let mut m = model.clone();
    let planned = (|| -> TractResult<Plan> {
        m.set_input_fact(0, f32::fact([window, 1, dim]).into())?;
        m.into_optimized()?.into_runnable()
    })();
    planned.map_err(|e| MotionError::Unsupported { reason: chain(&e) })
}

impl StitchRefiner {
    /// Loads an exported RMR (`.onnx`), planned for its configuration's window.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        let path = path.as_ref();
        let bytes =
            std::fs::read(path).map_err(|source| MotionError::Io { path: path.display().to_string(), source })?;
        Self::from_bytes_named(&bytes, &path.display().to_string())
    }

    /// [`StitchRefiner::load`] from the file's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        Self::from_bytes_named(bytes, "the given bytes")
    }

    fn from_bytes_named(bytes: &[u8], origin: &str) -> Result<Self, MotionError> {
        let (proto, model) = crate::model::read_graph(bytes, origin)?;
        let meta = |key: &str| proto.metadata_props.iter().find(|p| p.key == key).map(|p| p.value.clone());
        let kind = meta("zoo.model_kind").ok_or(MotionError::MissingMetadata { key: "zoo.model_kind".into() })?;
        if kind != RMR_KIND {
            return Err(MotionError::WrongTask {
                task: meta("zoo.task").unwrap_or_else(|| "unknown".into()),
                kind,
                expected: "stitch",
                loader: "StitchRefiner",
            });
        }
        let version_key = "zoo.rmr.format_version";
        let version = meta(version_key).ok_or(MotionError::MissingMetadata { key: version_key.into() })?;
        if version.trim() != RMR_FORMAT_VERSION.to_string() {
            return Err(MotionError::UnknownFormatVersion { found: version, supported: RMR_FORMAT_VERSION });
        }
        let json = |key: &str| -> Result<serde_json::Value, MotionError> {
            let text = meta(key).ok_or(MotionError::MissingMetadata { key: key.into() })?;
            serde_json::from_str(&text).map_err(|e| MotionError::BadMetadata { key: key.into(), reason: e.to_string() })
        };
        let config = json("zoo.rmr.config")?;
        let bad_config = |what: &str| MotionError::BadMetadata {
            key: "zoo.rmr.config".into(),
            reason: format!("`{what}` is missing or not a positive number"),
        };
        let count = |what: &str| -> Result<usize, MotionError> {
            config[what].as_u64().filter(|&v| v > 0).map(|v| v as usize).ok_or_else(|| bad_config(what))
        };
        let joints = count("joints")?;
        let lower =
            config["layout"]["lower_body"].as_array().map(Vec::len).ok_or_else(|| bad_config("layout.lower_body"))?;
        let (window, stride, blend_frames) = (count("window")?, count("stride")?, count("blend_frames")?);
        let fps = config["fps"].as_f64().filter(|&f| f > 0.0).ok_or_else(|| bad_config("fps"))?;
        let dim = 7 + 6 * lower + 4 * joints;
        let stats = json("zoo.rmr.normalization")?;
        let values = |what: &str| -> Result<Vec<f32>, MotionError> {
            let v: Option<Vec<f32>> = stats[what]
                .as_array()
                .map(|a| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect::<Option<_>>())
                .and_then(|v| v);
            v.filter(|v: &Vec<f32>| v.len() == dim).ok_or_else(|| MotionError::BadMetadata {
                key: "zoo.rmr.normalization".into(),
                reason: format!(
                    "`{what}` must hold {dim} numbers (the pose vector of {joints} joints, {lower} lower body)"
                ),
            })
        };
        let (mean, std) = (values("mean")?, values("std")?);
        if std.iter().any(|&s| s.is_nan() || s <= 0.0) {
            return Err(MotionError::BadMetadata {
                key: "zoo.rmr.normalization".into(),
                reason: "a standard deviation is not positive".into(),
            });
        }
        let plan = plan_for(&model, window, dim)?;
        Ok(StitchRefiner { model, plan, window, stride, blend_frames, dim, pose: dim - 4, joints, fps, mean, std })
    }

    /// Plans the refiner for another window `w` and stride `s` (`1 <= s <= w`; the paper uses
    /// 60/30 and 180/90).
    pub fn set_window(&mut self, window: usize, stride: usize) -> Result<(), MotionError> {
        if window == 0 || stride == 0 || stride > window {
            return Err(stitch_err(format!(
                "a window of {window} frames with a stride of {stride}: the stride must be in 1..=window"
            )));
        }
        self.plan = plan_for(&self.model, window, self.dim)?;
        self.window = window;
        self.stride = stride;
        Ok(())
    }

    /// Window `w`, frames.
    pub fn window(&self) -> usize {
        self.window
    }

    /// Stride `s` between windows, frames.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Frames over which each window's first-frame difference is blended away.
    pub fn blend_frames(&self) -> usize {
        self.blend_frames
    }

    /// Values per pose vector (`7 + 6 J_lower + 4 J`).
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Joints of the model's skeleton.
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Frames per second of the training clips (sequences must have it).
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Window starts over `frames` frames: every stride while the window fits, plus one ending
    /// on the last frame when the stride does not land there.
    pub fn window_starts(&self, frames: usize) -> Vec<usize> {
        if self.window > frames {
            return Vec::new();
        }
        let mut starts: Vec<usize> = (0..=frames - self.window).step_by(self.stride).collect();
        if starts.last() != Some(&(frames - self.window)) {
            starts.push(frames - self.window);
        }
        starts
    }

    /// Refines one normalised window (`window * dim` values) into `out` (same size; contacts as
    /// logits).
    pub fn refine_window_normalized(&self, x: &[f32], out: &mut [f32]) -> Result<(), MotionError> {
        let n = self.window * self.dim;
        for (name, len) in [("window", x.len()), ("refined window", out.len())] {
            if len != n {
                return Err(MotionError::BufferLength {
                    name: name.into(),
                    expected: n,
                    batch: self.window,
                    width: self.dim,
                    found: len,
                });
            }
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(MotionError::NonFinite { name: "window".into(), index: i, character: 0, value: x[i] });
        }
        let input = Tensor::from_shape::<f32>(&[self.window, 1, self.dim], x)
            .map_err(|e| MotionError::Run { reason: chain(&e) })?;
        let result = self.plan.run(tvec![input.into()]).map_err(|e| MotionError::Run { reason: chain(&e) })?;
        let y = result[0]
            .try_as_plain_ram()
            .and_then(|t| t.as_slice::<f32>())
            .map_err(|e| MotionError::Run { reason: chain(&e) })?;
        if y.len() != n {
            return Err(MotionError::Run {
                reason: format!("the graph returned {} values for a window of {n}", y.len()),
            });
        }
        out.copy_from_slice(y);
        Ok(())
    }

    /// Refines a whole aligned sequence of raw pose vectors (`frames * dim`, `frames >= w`)
    /// into `out` (same size): raw pose vectors, contacts 0/1. The same computation as the
    /// offline `zoo_rmr::stitch::refine_sequence`.
    pub fn refine_sequence(&self, features: &[f32], out: &mut [f32]) -> Result<(), MotionError> {
        let d = self.dim;
        if features.is_empty() || !features.len().is_multiple_of(d) || out.len() != features.len() {
            return Err(MotionError::BufferLength {
                name: "sequence".into(),
                expected: features.len().div_ceil(d).max(1) * d,
                batch: features.len() / d,
                width: d,
                found: if out.len() != features.len() { out.len() } else { features.len() },
            });
        }
        let frames = features.len() / d;
        if self.window > frames {
            return Err(stitch_err(format!(
                "the window of {} frames is longer than the sequence ({frames} frames): plan a window of at most \
                 {frames} with StitchRefiner::set_window, or stitch longer clips",
                self.window
            )));
        }
        if let Some(i) = features.iter().position(|v| !v.is_finite()) {
            return Err(MotionError::NonFinite { name: "sequence".into(), index: i, character: 0, value: features[i] });
        }
        out.copy_from_slice(features);
        for f in out.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / s;
            }
        }
        let pose = self.pose;
        let mut y = vec![0.0f32; self.window * d];
        let mut offset = vec![0.0f32; pose];
        for ws in self.window_starts(frames) {
            let span = ws * d..(ws + self.window) * d;
            self.refine_window_normalized(&out[span.clone()], &mut y)?;
            if ws > 0 {
                // out[ws] is the previous output at the window's first frame (RMR sec. 6).
                for (i, o) in offset.iter_mut().enumerate() {
                    *o = out[ws * d + i] - y[i];
                }
                for k in 0..self.blend_frames.min(self.window) {
                    let w = 1.0 - k as f32 / self.blend_frames as f32;
                    for (v, o) in y[k * d..k * d + pose].iter_mut().zip(&offset) {
                        *v += w * o;
                    }
                }
            }
            for f in y.chunks_exact_mut(d) {
                for c in &mut f[pose..] {
                    *c = if *c > 0.0 { 1.0 } else { 0.0 }; // sigmoid(logit) > 0.5
                }
            }
            out[span].copy_from_slice(&y);
        }
        for f in out.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = *v * s + m;
            }
            for c in &mut f[pose..] {
                *c = if *c > 0.5 { 1.0 } else { 0.0 };
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_safety() {
        fn send_sync<T: Send + Sync>() {}
        send_sync::<StitchRefiner>();
    }

    #[test]
    fn bytes_that_are_no_model_are_refused() {
        let err = StitchRefiner::from_bytes(b"not a model").unwrap_err().to_string();
        assert!(err.contains("is not an ONNX model"), "{err}");
    }
}
