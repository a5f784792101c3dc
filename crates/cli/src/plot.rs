//! Small PNG plots (loss curves) rasterised with tiny-skia.

use anyhow::Context;
use std::path::Path;
use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Stroke, Transform};

/// Plots training (blue) and validation (orange) loss per epoch on a log scale.
pub fn loss_curve(path: &Path, train: &[f64], valid: &[f64]) -> anyhow::Result<()> {
    let (w, h, m) = (640.0f32, 360.0f32, 30.0f32);
    let mut pm = Pixmap::new(w as u32, h as u32).context("pixmap")?;
    pm.fill(Color::WHITE);
    let all: Vec<f64> = train.iter().chain(valid).copied().filter(|v| v.is_finite() && *v > 0.0).collect();
    if all.is_empty() {
        return Ok(());
    }
    let lo = all.iter().copied().fold(f64::INFINITY, f64::min).log10();
    let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max).log10().max(lo + 1e-6);
    let n = train.len().max(valid.len()).max(2);
    let x = |i: usize| m + (w - 2.0 * m) * i as f32 / (n - 1) as f32;
    let y = |v: f64| h - m - (h - 2.0 * m) * ((v.log10() - lo) / (hi - lo)) as f32;
    let mut stroke = Stroke { width: 1.0, ..Stroke::default() };
    let mut paint = Paint::default();
    paint.set_color_rgba8(200, 200, 200, 255);
    // grid: one line per decade
    for d in (lo.floor() as i32)..=(hi.ceil() as i32) {
        let yy = y(10f64.powi(d));
        if (m..=h - m).contains(&yy) {
            let mut pb = PathBuilder::new();
            pb.move_to(m, yy);
            pb.line_to(w - m, yy);
            if let Some(p) = pb.finish() {
                pm.stroke_path(&p, &paint, &stroke, Transform::identity(), None);
            }
        }
    }
    stroke.width = 2.0;
    for (series, rgb) in [(train, (31, 119, 180)), (valid, (255, 127, 14))] {
        let mut pb = PathBuilder::new();
        for (i, v) in series.iter().enumerate().filter(|(_, v)| v.is_finite() && **v > 0.0) {
            if pb.is_empty() { pb.move_to(x(i), y(*v)) } else { pb.line_to(x(i), y(*v)) }
        }
        paint.set_color_rgba8(rgb.0, rgb.1, rgb.2, 255);
        if let Some(p) = pb.finish() {
            pm.stroke_path(&p, &paint, &stroke, Transform::identity(), None);
        }
    }
    let tmp = path.with_extension("png.tmp");
    pm.save_png(&tmp).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
