//! RTN as a benchmark method (`zoo bench --methods rtn:DIR`, `rtn+lock:DIR`): a trained run
//! folder generating global joint positions through candle, fitted and optionally foot-locked
//! by [`zoo_data::position_method`]. A run whose `config.json` holds calibrated fallback
//! thresholds ([`crate::fallback`]) falls back towards interpolation on a large target miss,
//! unless [`set_fallback_enabled`] turned that off (`zoo bench --no-fallback`); the method is
//! then named with a `+fallback` suffix, and how often the fallback triggered is counted.

use crate::error::RtnResult;
use crate::fallback::Fallback;
use crate::features::FeatureStats;
use crate::model::Rtn;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use zoo_data::position_method::{PositionGenerator, PositionMethod};

static FALLBACK_ENABLED: AtomicBool = AtomicBool::new(true);

/// Whether methods loaded from now on apply their run's fallback (on by default).
pub fn set_fallback_enabled(enabled: bool) {
    FALLBACK_ENABLED.store(enabled, Ordering::Relaxed);
}

/// Whether methods apply their run's fallback ([`set_fallback_enabled`]).
pub fn fallback_enabled() -> bool {
    FALLBACK_ENABLED.load(Ordering::Relaxed)
}

/// How often the fallback acted, per transition length.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FallbackCount {
    /// Transitions generated.
    pub transitions: usize,
    /// Transitions with a fallback weight above 0.
    pub triggered: usize,
    /// Transitions with weight 1 (the interpolation alone).
    pub full: usize,
    /// Sum of the weights.
    pub weight_sum: f64,
    /// The thresholds applied at this length.
    pub thresholds: Fallback,
}

/// A trained RTN and its normalization statistics, generating transitions on the CPU
/// ([`Rtn::transition_checked`]: unrolled, target-blended, then the fallback when set).
pub struct RtnGenerator {
    /// The model.
    pub model: Rtn,
    /// Its normalization statistics.
    pub stats: FeatureStats,
    /// Whether the run's fallback applies (its thresholds for each transition's length,
    /// [`crate::Config::fallback_for`]).
    pub fallback: bool,
    /// Counts per transition length.
    pub counts: Mutex<BTreeMap<usize, FallbackCount>>,
}

impl RtnGenerator {
    /// The counts so far, per transition length.
    pub fn counts(&self) -> BTreeMap<usize, FallbackCount> {
        self.counts.lock().map(|c| c.clone()).unwrap_or_default()
    }
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
        let fallback = self.model.config().fallback_for(frames).filter(|_| self.fallback);
        let t = self
            .model
            .transition_checked(&self.stats, past, target, next, frames, None, fallback.as_ref())
            .map_err(|e| e.to_string())?;
        if let Some(f) = fallback
            && let Ok(mut counts) = self.counts.lock()
        {
            counts.entry(frames).or_default().count(f, t.weight);
        }
        Ok(t.frames)
    }
}

impl FallbackCount {
    /// Counts one transition blended with weight `weight` under `thresholds`.
    pub fn count(&mut self, thresholds: Fallback, weight: f32) {
        self.thresholds = thresholds;
        self.transitions += 1;
        self.triggered += usize::from(weight > 0.0);
        self.full += usize::from(weight >= 1.0);
        self.weight_sum += weight as f64;
    }
}

/// Says on stderr how often the fallback acted at each transition length.
pub fn report_fallback(counts: &BTreeMap<usize, FallbackCount>) {
    for (n, c) in counts {
        let f = c.thresholds;
        eprintln!(
            "fallback (start {:.2}, full {:.2}) at n = {n}: triggered on {} of {} transitions ({:.1}%), full on {}, \
             mean weight {:.3}",
            f.start,
            f.full,
            c.triggered,
            c.transitions,
            100.0 * c.triggered as f64 / c.transitions.max(1) as f64,
            c.full,
            c.weight_sum / c.transitions.max(1) as f64
        );
    }
}

impl Drop for RtnGenerator {
    fn drop(&mut self) {
        if self.fallback {
            report_fallback(&self.counts());
        }
    }
}

/// The benchmark method `rtn:DIR` (or `rtn+lock:DIR` with `foot_lock`) named `name`, from a
/// run folder written by `zoo train rtn`; `name + "+fallback"` when the run's fallback applies.
pub fn load(dir: &Path, name: String, foot_lock: bool) -> RtnResult<PositionMethod<RtnGenerator>> {
    let (model, stats) = crate::checkpoint::load(dir, &candle_core::Device::Cpu)?;
    let fallback = model.config().fallback.is_some() && FALLBACK_ENABLED.load(Ordering::Relaxed);
    let name = if fallback { format!("{name}+fallback") } else { name };
    Ok(PositionMethod::new(name, RtnGenerator { model, stats, fallback, counts: Mutex::default() }, foot_lock))
}
