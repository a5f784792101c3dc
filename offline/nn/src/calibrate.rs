//! Thresholds of the models' fallbacks (RTN towards interpolation, RMR towards its input),
//! calibrated on a confidence signal measured over in-distribution validation data.

/// `start` at the `quantile` (`0..=1`, nearest rank) of the finite `values`, at least 1e-6, and
/// `full` at `factor` times it; `None` without a finite value.
pub fn fallback_thresholds(values: &[f32], quantile: f64, factor: f32) -> Option<(f32, f32)> {
    let mut v: Vec<f32> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    let i = ((v.len() - 1) as f64 * quantile.clamp(0.0, 1.0)).round() as usize;
    let start = v[i].max(1e-6);
    Some((start, start * factor))
}
