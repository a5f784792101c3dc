//! The exported model as a benchmark method (`onnx:FILE.onnx`, `onnx+lock:FILE.onnx`): the
//! file run by the engine runtime (`zoo-runtime` on tract), with the same inputs, fit and foot
//! lock as `rtn:DIR` ([`zoo_data::position_method`]), and the same fallback (the thresholds
//! calibrated in training, carried by the file; off with `zoo bench --no-fallback`).

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use zoo_data::position_method::{PositionGenerator, PositionMethod};
use zoo_rtn::method::FallbackCount;
use zoo_runtime::metadata::MotionSkeletonInfo;
use zoo_runtime::{MotionTaskKind, TransitionModel, TransitionRunner, TransitionState};

/// An exported transition model run by the engine runtime; one runner and state per thread.
pub struct OnnxGenerator {
    model: TransitionModel,
    /// Whether the model's calibrated fallback applies (its thresholds for each transition's
    /// length), unless `zoo bench --no-fallback`.
    fallback: bool,
    /// How often it acted, per transition length (said on stderr when the method is dropped).
    counts: Mutex<BTreeMap<usize, FallbackCount>>,
}

impl Drop for OnnxGenerator {
    fn drop(&mut self) {
        if let (true, Ok(counts)) = (self.fallback, self.counts.lock()) {
            zoo_rtn::method::report_fallback(&counts);
        }
    }
}

impl PositionGenerator for OnnxGenerator {
    type Scratch = (TransitionRunner, TransitionState);

    fn joints(&self) -> usize {
        self.model.joints()
    }

    fn scratch(&self) -> Result<Self::Scratch, String> {
        let mut runner = self.model.runner().map_err(|e| e.to_string())?;
        // The benchmark measures transitions beyond the trained length on purpose (n = 45).
        runner.allow_beyond_trained(true);
        if self.fallback {
            runner.set_model_fallback();
        }
        Ok((runner, self.model.new_transition()))
    }

    fn generate(
        &self,
        (runner, state): &mut Self::Scratch,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        frames: usize,
    ) -> Result<Vec<f32>, String> {
        let mut y = vec![0.0; (frames + 1) * target.len()];
        runner.generate(state, past, target, next, &mut y).map_err(|e| e.to_string())?;
        if let (true, Some(f)) = (self.fallback, self.model.default_fallback_for(frames))
            && let Ok(mut counts) = self.counts.lock()
        {
            let thresholds = zoo_rtn::fallback::Fallback { start: f.start, full: f.full };
            counts.entry(frames).or_default().count(thresholds, state.fallback_weight());
        }
        Ok(y)
    }
}

/// The benchmark method `onnx:FILE` (or `onnx+lock:FILE` with `foot_lock`) named `name`, from a
/// file written by `zoo export --onnx`.
pub fn load_onnx(path: &Path, name: String, foot_lock: bool) -> crate::Result<PositionMethod<OnnxGenerator>> {
    Ok(load_onnx_with_skeleton(path, name, foot_lock)?.0)
}

/// [`load_onnx`], and the skeleton the model was trained on (from the file's metadata), for
/// checking it against a dataset's.
pub fn load_onnx_with_skeleton(
    path: &Path,
    name: String,
    foot_lock: bool,
) -> crate::Result<(PositionMethod<OnnxGenerator>, MotionSkeletonInfo)> {
    let model = crate::exported::load(path, &[MotionTaskKind::Transition], "`zoo bench --methods onnx:FILE`")?
        .into_transition()?;
    let skeleton = model.model().metadata().skeleton.clone();
    Ok((onnx_method(model, name, foot_lock), skeleton))
}

/// The benchmark method of a loaded transition model named `name` (`+fallback` appended when
/// its calibrated fallback applies), foot-locked when `foot_lock`.
pub fn onnx_method(model: TransitionModel, name: String, foot_lock: bool) -> PositionMethod<OnnxGenerator> {
    let fallback = model.default_fallback().is_some() && zoo_rtn::method::fallback_enabled();
    let name = if fallback { format!("{name}+fallback") } else { name };
    PositionMethod::new(name, OnnxGenerator { model, fallback, counts: Mutex::default() }, foot_lock)
}
