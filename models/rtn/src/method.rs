//! RTN as a benchmark method (`zoo bench --methods rtn:DIR`, `rtn+lock:DIR`): a trained run
//! folder generating global joint positions through candle, fitted and optionally foot-locked
//! by [`zoo_data::position_method`].

use crate::error::RtnResult;
use crate::features::FeatureStats;
use crate::model::Rtn;
use std::path::Path;
use zoo_data::position_method::{PositionGenerator, PositionMethod};

/// A trained RTN and its normalization statistics, generating transitions on the CPU
/// ([`Rtn::transition`]: unrolled, then target-blended).
pub struct RtnGenerator {
    /// The model.
    pub model: Rtn,
    /// Its normalization statistics.
    pub stats: FeatureStats,
}

impl PositionGenerator for RtnGenerator {
    type Scratch = ();

    fn joints(&self) -> usize {
        self.model.config().joints
    }

    fn scratch(&self) -> Result<(), String> {
        Ok(())
    }

    fn generate(
        &self,
        _: &mut (),
        past: &[f32],
        target: &[f32],
        next: &[f32],
        frames: usize,
    ) -> Result<Vec<f32>, String> {
        self.model.transition(&self.stats, past, target, next, frames, None).map_err(|e| e.to_string())
    }
}

/// The benchmark method `rtn:DIR` (or `rtn+lock:DIR` with `foot_lock`) named `name`, from a
/// run folder written by `zoo train rtn`.
pub fn load(dir: &Path, name: String, foot_lock: bool) -> RtnResult<PositionMethod<RtnGenerator>> {
    let (model, stats) = crate::checkpoint::load(dir, &candle_core::Device::Cpu)?;
    Ok(PositionMethod::new(name, RtnGenerator { model, stats }, foot_lock))
}
