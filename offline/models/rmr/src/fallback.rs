//! The fallback towards the refiner's input (not in the paper): a window that the
//! refiner corrects far more than it corrected the validation seams is blended back towards
//! what it was given.
//!
//! The confidence signal is the size of the window's correction, computed from the inputs
//! only: the root mean square over the window's frames and pose values (`r, p, q, v`, not the
//! contacts) of the refined window minus its input, in normalised units. On motion like its
//! training data the refiner moves a window by about what it moved the validation pairs; on
//! moves it never saw it can move it much further (docs/rmr.md, "On moves it never saw").
//! [`Fallback`] turns the size into a weight `w` in `[0, 1]` (0 below `start`, 1 from `full`
//! on, linear between) and the window's pose values become `(1 - w) * refined + w * input`
//! (contacts stay the refiner's). With [`crate::Config::pre_blend`] the input is the sequence
//! inertialized at its seams, so a full fallback is inertialization; with the raw
//! concatenation as input it is the concatenation, seams included.
//!
//! `zoo train rmr` calibrates the thresholds on the validation pairs of the best model and
//! stores them in `config.json` (field `fallback`); `zoo train rmr --resume RUN --epochs N`
//! with `N` the epochs done calibrates an older run without training it.

use crate::error::RmrResult;
use crate::features::{FeatureLayout, PairFeatures};
use crate::model::Rmr;
use std::sync::atomic::{AtomicU64, Ordering};

pub use zoo_format::StitchFallback as Fallback;

/// Quantile of the validation windows' correction sizes that `start` is set to: windows like
/// the training data's trigger the fallback about 5 % of the time.
pub const START_QUANTILE: f64 = 0.95;
/// `full` is this multiple of `start`.
pub const FULL_FACTOR: f32 = 2.0;

/// Thresholds from the correction sizes of in-distribution windows: `start` at their
/// [`START_QUANTILE`], `full` at [`FULL_FACTOR`] times it; `None` without a finite size.
pub fn calibrate(sizes: &[f32]) -> Option<Fallback> {
    zoo_nn::calibrate::fallback_thresholds(sizes, START_QUANTILE, FULL_FACTOR)
        .map(|(start, full)| Fallback { start, full })
}

/// A refined window's correction size in `fl`'s layout ([`zoo_format::stitch::correction_size`]).
pub fn correction_size(input: &[f32], output: &[f32], fl: FeatureLayout) -> f32 {
    zoo_format::stitch::correction_size(input, output, fl.dim(), fl.contacts())
}

/// How often a model's fallback acted (shared by its clones): windows refined, windows whose
/// weight was above 0, and the sum of the weights.
#[derive(Debug, Default)]
pub struct FallbackCounts {
    windows: AtomicU64,
    triggered: AtomicU64,
    weight_millionths: AtomicU64,
}

impl FallbackCounts {
    /// Counts one window refined with the fallback's weight `w`.
    pub fn count(&self, w: f32) {
        self.windows.fetch_add(1, Ordering::Relaxed);
        if w > 0.0 {
            self.triggered.fetch_add(1, Ordering::Relaxed);
            self.weight_millionths.fetch_add((w as f64 * 1e6).round() as u64, Ordering::Relaxed);
        }
    }

    /// Windows counted, the fraction of them where the fallback acted and its mean weight
    /// over all of them.
    pub fn summary(&self) -> (u64, f64, f64) {
        let n = self.windows.load(Ordering::Relaxed);
        let t = self.triggered.load(Ordering::Relaxed);
        let w = self.weight_millionths.load(Ordering::Relaxed) as f64 * 1e-6;
        let d = n.max(1) as f64;
        (n, t as f64 / d, w / d)
    }
}

/// The correction size of every pair of `pairs` (normalised inputs) refined by `model`.
pub fn correction_sizes(model: &Rmr, pairs: &PairFeatures) -> RmrResult<Vec<f32>> {
    let c = model.config();
    let fl = FeatureLayout::new(c.joints, c.layout.lower_body.len());
    (0..pairs.count)
        .map(|i| {
            let x = pairs.input(i);
            let y = model.refine(x)?;
            Ok(correction_size(x, &y, fl))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> FeatureLayout {
        FeatureLayout::new(2, 1)
    }

    #[test]
    fn calibration_puts_start_at_the_95th_percentile() {
        let sizes: Vec<f32> = (0..=100).map(|i| i as f32).collect();
        let f = calibrate(&sizes).unwrap();
        assert!((f.start - 95.0).abs() <= 1.0, "{f:?}");
        assert_eq!(f.full, 2.0 * f.start);
        assert_eq!(calibrate(&[f32::NAN]), None);
    }

    #[test]
    fn a_full_fallback_gives_the_input_and_keeps_the_contacts() {
        let fl = layout();
        let d = fl.dim();
        let input: Vec<f32> = (0..3 * d).map(|i| i as f32 * 0.1).collect();
        let mut output: Vec<f32> = input.iter().map(|v| v + 2.0).collect();
        assert!((correction_size(&input, &output, fl) - 2.0).abs() < 1e-5);
        let f = Fallback { start: 0.5, full: 1.0 };
        assert_eq!(f.apply(&input, &mut output, fl.dim(), fl.contacts()), 1.0);
        for (t, (x, y)) in input.chunks_exact(d).zip(output.chunks_exact(d)).enumerate() {
            assert_eq!(&x[..fl.contacts()], &y[..fl.contacts()], "frame {t}");
            assert!(y[fl.contacts()..].iter().zip(&x[fl.contacts()..]).all(|(a, b)| (a - b - 2.0).abs() < 1e-6));
        }
        // Halfway between the thresholds the pose values move halfway back.
        let mut half: Vec<f32> = input.iter().map(|v| v + 0.75).collect();
        let w = f.apply(&input, &mut half, fl.dim(), fl.contacts());
        assert!((w - 0.5).abs() < 1e-5, "{w}");
        assert!((half[0] - input[0] - 0.375).abs() < 1e-5);
        // A small correction is kept.
        let mut small: Vec<f32> = input.iter().map(|v| v + 0.1).collect();
        let before = small.clone();
        assert_eq!(f.apply(&input, &mut small, fl.dim(), fl.contacts()), 0.0);
        assert_eq!(small, before);
    }
}
