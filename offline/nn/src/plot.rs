//! PNG plots rasterised with tiny-skia: a run's loss curve, and plain line plots.

use crate::checkpoint::io;
use crate::error::{NnError, NnResult};
use std::path::Path;
use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Stroke, Transform};

/// Plots training (blue) and validation (orange) loss per epoch on a log scale (one grey line
/// per decade), 640 x 360 pixels; writes `path` atomically. Non-finite and non-positive values
/// are skipped; nothing is written when no value is left.
pub fn loss_curve(path: &Path, train: &[f64], valid: &[f64]) -> NnResult<()> {
    let (w, h, m) = (640.0f32, 360.0f32, 30.0f32);
    let mut pm = Pixmap::new(w as u32, h as u32).ok_or_else(|| NnError::Config("cannot allocate the plot".into()))?;
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
    save_png(path, &pm)
}

/// One line of a line plot: values (x = index) and colour.
pub type LineSeries<'a> = (&'a [f64], (u8, u8, u8));

/// Plots `series` (each `(values, rgb)`, x = index) as lines on a linear scale from 0 to the
/// largest value, with a light grey line at every multiple of `grid` on the y axis, 800 x 360
/// pixels; writes `path` atomically. Non-finite values break a line.
pub fn lines(path: &Path, series: &[LineSeries], grid: f64) -> NnResult<()> {
    let hi = series.iter().flat_map(|(v, _)| v.iter()).copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
    line_panels(path, &[(series.to_vec(), 0.0, if hi > 0.0 { hi } else { 1.0 }, grid)])
}

/// One panel of [`line_panels`]: its series, the y range `lo..hi` and the grid step.
pub type LinePanel<'a> = (Vec<LineSeries<'a>>, f64, f64, f64);

/// Line plots stacked top to bottom, each 800 x 360 pixels with its own y range (values outside
/// it are clamped) and a light grey line at every multiple of its grid step; writes `path`
/// atomically. Non-finite values break a line.
pub fn line_panels(path: &Path, panels: &[LinePanel]) -> NnResult<()> {
    let (w, h) = (800.0f32, 360.0f32);
    let rows = panels.len().max(1) as u32;
    let mut pm =
        Pixmap::new(w as u32, rows * h as u32).ok_or_else(|| NnError::Config("cannot allocate the plot".into()))?;
    pm.fill(Color::WHITE);
    for (r, (series, lo, hi, grid)) in panels.iter().enumerate() {
        draw_lines(&mut pm, series, *lo, *hi, *grid, (w, h), r as f32 * h);
    }
    save_png(path, &pm)
}

/// Draws one line panel (`size` pixels) at height `top` of `pm`.
fn draw_lines(pm: &mut Pixmap, series: &[LineSeries], lo: f64, hi: f64, grid: f64, size: (f32, f32), top: f32) {
    let ((w, h), m) = (size, 20.0f32);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let n = series.iter().map(|(v, _)| v.len()).max().unwrap_or(0).max(2);
    let x = |i: usize| m + (w - 2.0 * m) * i as f32 / (n - 1) as f32;
    let y = |v: f64| top + h - m - (h - 2.0 * m) * ((v.clamp(lo, lo + span) - lo) / span) as f32;
    let mut stroke = Stroke { width: 1.0, ..Stroke::default() };
    let mut paint = Paint::default();
    paint.set_color_rgba8(210, 210, 210, 255);
    if grid > 0.0 && span / grid < 100.0 {
        for g in zoo_motion::ticks::multiples(lo, lo + span, grid, 100) {
            let mut pb = PathBuilder::new();
            pb.move_to(m, y(g));
            pb.line_to(w - m, y(g));
            if let Some(p) = pb.finish() {
                pm.stroke_path(&p, &paint, &stroke, Transform::identity(), None);
            }
        }
    }
    stroke.width = 2.0;
    for (values, rgb) in series {
        let mut pb = PathBuilder::new();
        let mut pen_down = false;
        for (i, v) in values.iter().enumerate() {
            if !v.is_finite() {
                pen_down = false;
                continue;
            }
            if pen_down {
                pb.line_to(x(i), y(*v))
            } else {
                pb.move_to(x(i), y(*v))
            }
            pen_down = true;
        }
        paint.set_color_rgba8(rgb.0, rgb.1, rgb.2, 255);
        if let Some(p) = pb.finish() {
            pm.stroke_path(&p, &paint, &stroke, Transform::identity(), None);
        }
    }
}

/// One polyline of a top view: points, colour, width in pixels.
pub type TopSeries<'a> = (&'a [[f64; 2]], (u8, u8, u8), f32);

/// Plots 2-D polylines `series` seen from above with equal scales on both axes (a top view: the
/// first coordinate to the right, the second down the image), a light grey grid every `grid`
/// units, `size` pixels square; writes `path` atomically. Non-finite points break a line.
pub fn top_view(path: &Path, series: &[TopSeries], grid: f64, size: u32) -> NnResult<()> {
    top_view_grid(path, &[vec![series.to_vec()]], grid, size)
}

/// Several top views (see [`top_view`]) in a grid: `cells[row][column]` are the series of one
/// view, each view `size` pixels square, each scaled on its own.
pub fn top_view_grid(path: &Path, cells: &[Vec<Vec<TopSeries>>], grid: f64, size: u32) -> NnResult<()> {
    let rows = cells.len().max(1) as u32;
    let cols = cells.iter().map(Vec::len).max().unwrap_or(1).max(1) as u32;
    let mut pm =
        Pixmap::new(cols * size, rows * size).ok_or_else(|| NnError::Config("cannot allocate the plot".into()))?;
    pm.fill(Color::WHITE);
    for (r, row) in cells.iter().enumerate() {
        for (c, series) in row.iter().enumerate() {
            draw_top_view(&mut pm, series, grid, size as f32, (c as f32 * size as f32, r as f32 * size as f32));
        }
    }
    save_png(path, &pm)
}

/// Draws one top view into the `size`-pixel square of `pm` at `origin`.
fn draw_top_view(pm: &mut Pixmap, series: &[TopSeries], grid: f64, w: f32, origin: (f32, f32)) {
    let m = 20.0f32;
    let finite = || series.iter().flat_map(|(p, _, _)| p.iter()).filter(|p| p[0].is_finite() && p[1].is_finite());
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in finite() {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if !lo[0].is_finite() {
        (lo, hi) = ([0.0; 2], [1.0; 2]);
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let scale = (w - 2.0 * m) as f64 / span;
    let px = |p: [f64; 2]| -> (f32, f32) {
        (
            origin.0 + w / 2.0 + ((p[0] - centre[0]) * scale) as f32,
            origin.1 + w / 2.0 + ((p[1] - centre[1]) * scale) as f32,
        )
    };
    let mut paint = Paint::default();
    let mut stroke = Stroke { width: 1.0, ..Stroke::default() };
    paint.set_color_rgba8(225, 225, 225, 255);
    let clip = tiny_skia::Rect::from_xywh(origin.0, origin.1, w, w).and_then(|r| {
        let mut mask = tiny_skia::Mask::new(pm.width(), pm.height())?;
        mask.fill_path(&PathBuilder::from_rect(r), tiny_skia::FillRule::Winding, false, Transform::identity());
        Some(mask)
    });
    if grid > 0.0 && span / grid < 200.0 {
        let half = span / 2.0 + (m as f64) / scale;
        for k in 0..2 {
            for g in zoo_motion::ticks::multiples(centre[k] - half, centre[k] + half, grid, 200) {
                let mut pb = PathBuilder::new();
                let (a, b) = if k == 0 {
                    ([g, centre[1] - half], [g, centre[1] + half])
                } else {
                    ([centre[0] - half, g], [centre[0] + half, g])
                };
                let (a, b) = (px(a), px(b));
                pb.move_to(a.0, a.1);
                pb.line_to(b.0, b.1);
                if let Some(p) = pb.finish() {
                    pm.stroke_path(&p, &paint, &stroke, Transform::identity(), clip.as_ref());
                }
            }
        }
    }
    for (points, rgb, width) in series {
        stroke.width = *width;
        paint.set_color_rgba8(rgb.0, rgb.1, rgb.2, 255);
        let mut pb = PathBuilder::new();
        let mut pen_down = false;
        for p in points.iter() {
            if !(p[0].is_finite() && p[1].is_finite()) {
                pen_down = false;
                continue;
            }
            let (x, y) = px(*p);
            if pen_down {
                pb.line_to(x, y)
            } else {
                pb.move_to(x, y)
            }
            pen_down = true;
        }
        if let Some(p) = pb.finish() {
            pm.stroke_path(&p, &paint, &stroke, Transform::identity(), clip.as_ref());
        }
    }
}

/// Encodes `pm` and writes it to `path` atomically.
fn save_png(path: &Path, pm: &Pixmap) -> NnResult<()> {
    let png =
        pm.encode_png().map_err(|e| NnError::Config(format!("{}: cannot encode the PNG: {e}", path.display())))?;
    zoo_format::atomic::write(path, png).map_err(io(path))
}

#[cfg(test)]
mod tests {
    #[test]
    fn writes_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("loss.png");
        super::loss_curve(&p, &[1.0, 0.5, 0.2], &[1.2, f64::NAN, 0.3]).unwrap();
        assert_eq!(&std::fs::read(&p).unwrap()[1..4], b"PNG");
        let q = dir.path().join("top.png");
        let pts = [[0.0, 0.0], [100.0, 50.0], [f64::NAN, 0.0], [20.0, 300.0]];
        super::top_view(&q, &[(&pts, (200, 0, 0), 2.0)], 100.0, 300).unwrap();
        assert_eq!(&std::fs::read(&q).unwrap()[1..4], b"PNG");
        let cell: Vec<super::TopSeries> = vec![(&pts, (0, 0, 200), 1.0)];
        super::top_view_grid(&q, &[vec![cell.clone(), cell.clone()], vec![cell]], 100.0, 100).unwrap();
        assert_eq!(&std::fs::read(&q).unwrap()[1..4], b"PNG");
    }
}
