//! Ground paths for path following (RNN-GMM control, paper sec. 5.2): a polyline on the ground
//! plane (x, z) in centimetres, read from JSON points or SVG path data (curves are flattened by
//! `kurbo`), with arc length, nearest-point queries and the built-in test paths of the
//! path-following benchmark.
//!
//! Axes: y is up, so a path lies in the x-z plane. An SVG drawing maps its x to x and its y (down
//! the page) to z: seen from above (+y), with x to the right, z points down the page, so the
//! drawing is not mirrored.
//!
//! JSON: `{"units": "cm" | "m", "points": [[x, z], ...]}` (points may also be `[x, y, z]` with
//! y = 0), or `{"units": ..., "svg": "M 0 0 C ..."}` (SVG path data in those units). Units
//! default to metres.
//!
//! Every value is range-checked like the command line's options: coordinates finite and within
//! +-[`MAX_COORD`] cm (10 km) of the origin, at most [`MAX_POINTS`] points, at most
//! [`MAX_LENGTH`] cm (10 km) long. SVG path data is checked before its curves are flattened: its
//! coordinates within +-[`MAX_SVG_UNITS`] user units and, scaled, within +-10 km, and its control
//! polygon (which is at least as long as the curve) at most 10 km, so that no drawing makes the
//! flattening emit more than a bounded number of points.

use std::path::Path;
use thiserror::Error;

/// A path that cannot be used, with what to do about it.
#[derive(Debug, Error)]
pub enum PathError {
    /// The file could not be read.
    #[error("cannot read the path file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The description is malformed or unusable.
    #[error("{0}")]
    Invalid(String),
}

/// The largest coordinate of a path point, cm either way (10 km).
pub const MAX_COORD: f64 = 1e6;
/// The longest path, cm (10 km).
pub const MAX_LENGTH: f64 = 1e6;
/// The most points of a path, given or flattened from curves (10 km at one point per 10 cm).
pub const MAX_POINTS: usize = 100_000;
/// The largest coordinate of SVG path data, user units either way (before the scale).
pub const MAX_SVG_UNITS: f64 = 1e9;
/// The largest SVG scale, centimetres per user unit (the command line's `--svg-scale` range).
pub const MAX_SVG_SCALE: f64 = 10_000.0;

fn invalid(message: impl Into<String>) -> PathError {
    PathError::Invalid(message.into())
}

/// A polyline on the ground plane, in centimetres, with its cumulative arc length.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundPath {
    points: Vec<[f64; 2]>,
    /// Arc length at each point (`cum[0]` = 0).
    cum: Vec<f64>,
}

/// The nearest point of a path to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nearest {
    /// The point (cm).
    pub point: [f64; 2],
    /// Its arc length (cm; below 0 or beyond [`GroundPath::length`] on the straight extensions).
    pub s: f64,
    /// Distance from the query point (cm).
    pub distance: f64,
}

/// The closest point of segment `a`-`b` to `p`: (point, fraction along the segment).
fn closest_on_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> ([f64; 2], f64) {
    let (dx, dz) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dz * dz;
    let t = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dz) / len2).clamp(0.0, 1.0) } else { 0.0 };
    ([a[0] + t * dx, a[1] + t * dz], t)
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl GroundPath {
    /// A path through `points` (cm). Consecutive duplicates are dropped; at least 2 distinct
    /// finite points are needed, at most [`MAX_POINTS`], each coordinate within
    /// +-[`MAX_COORD`], the whole at most [`MAX_LENGTH`] long.
    pub fn new(points: Vec<[f64; 2]>) -> Result<Self, PathError> {
        check_point_count(points.len())?;
        if let Some(i) = points.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
            return Err(invalid(format!(
                "path point {i} is not a finite number ({:?}): give finite coordinates",
                points[i]
            )));
        }
        if let Some(i) = points.iter().position(|p| p[0].abs() > MAX_COORD || p[1].abs() > MAX_COORD) {
            return Err(invalid(format!(
                "path point {i} is at ({:?} cm, {:?} cm): coordinates are in [-{MAX_COORD}, {MAX_COORD}] cm (10 km \
                 from the origin); move the path closer to the origin",
                points[i][0], points[i][1]
            )));
        }
        let mut pts: Vec<[f64; 2]> = Vec::with_capacity(points.len());
        for p in points {
            if pts.last().is_none_or(|q| dist(*q, p) > 1e-9) {
                pts.push(p);
            }
        }
        if pts.len() < 2 {
            return Err(invalid(format!(
                "a path needs at least 2 distinct points, found {}: give the start and at least one more point",
                pts.len()
            )));
        }
        let mut cum = vec![0.0; pts.len()];
        for i in 1..pts.len() {
            cum[i] = cum[i - 1] + dist(pts[i - 1], pts[i]);
        }
        let length = cum[pts.len() - 1];
        if length > MAX_LENGTH {
            return Err(invalid(format!(
                "the path is {length:.0} cm long: a path is at most {MAX_LENGTH} cm (10 km) long; shorten it"
            )));
        }
        Ok(GroundPath { points: pts, cum })
    }

    /// The path of a JSON description (see the module docs).
    pub fn from_json(text: &str) -> Result<Self, PathError> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| invalid(format!("the path JSON does not parse: {e}")))?;
        let scale = match v.get("units").and_then(|u| u.as_str()).unwrap_or("m") {
            "m" => 100.0,
            "cm" => 1.0,
            other => return Err(invalid(format!("unknown path units `{other}`: use \"m\" or \"cm\""))),
        };
        if let Some(d) = v.get("svg") {
            let d = d.as_str().ok_or_else(|| invalid("`svg` must be a string of SVG path data"))?;
            return Self::from_svg_data(d, scale);
        }
        let points = v.get("points").and_then(|p| p.as_array()).ok_or_else(|| {
            invalid("the path JSON needs `points` (a list of [x, z] or [x, y, z]) or `svg` (path data)")
        })?;
        check_point_count(points.len())?;
        let mut out = Vec::with_capacity(points.len());
        for (i, p) in points.iter().enumerate() {
            let c: Vec<f64> = p
                .as_array()
                .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
                .filter(|c: &Vec<f64>| c.len() == p.as_array().map_or(0, Vec::len))
                .ok_or_else(|| invalid(format!("path point {i} is not a list of numbers: {p}")))?;
            match c.as_slice() {
                [x, z] => out.push([x * scale, z * scale]),
                [x, y, z] => {
                    if y.abs() > 1e-6 {
                        return Err(invalid(format!(
                            "path point {i} is at height y = {y}: a path lies on the ground plane (y = 0); give [x, z] \
                             or [x, 0, z]"
                        )));
                    }
                    out.push([x * scale, z * scale])
                }
                _ => {
                    return Err(invalid(format!(
                        "path point {i} has {} coordinates: give [x, z] or [x, 0, z]",
                        c.len()
                    )));
                }
            }
        }
        Self::new(out)
    }

    /// The path of SVG path data (`d`), `cm_per_unit` centimetres per SVG unit (in
    /// (0, [`MAX_SVG_SCALE`]]); curves are flattened to within 0.5 cm. Only the first subpath
    /// is used. The coordinates and the control polygon's length are checked before flattening.
    pub fn from_svg_data(d: &str, cm_per_unit: f64) -> Result<Self, PathError> {
        use kurbo::PathEl;
        if !(cm_per_unit.is_finite() && cm_per_unit > 0.0 && cm_per_unit <= MAX_SVG_SCALE) {
            return Err(invalid(format!(
                "the SVG scale is {cm_per_unit:?} cm per unit: give a number in (0, {MAX_SVG_SCALE}]"
            )));
        }
        // Every number before kurbo reads them: an arc's radius sets how many curves kurbo makes
        // of it (about radius^(1/6): 1e300 units would be 1e50 curves).
        for n in svg_numbers(d) {
            if let Ok(v) = n.parse::<f64>()
                && !(v.is_finite() && v.abs() <= MAX_SVG_UNITS)
            {
                return Err(invalid(format!(
                    "the SVG path data has the number {n}: coordinates and radii are finite and in \
                     [-{MAX_SVG_UNITS}, {MAX_SVG_UNITS}] units"
                )));
            }
        }
        let bez = kurbo::BezPath::from_svg(d).map_err(|e| invalid(format!("the SVG path data does not parse: {e}")))?;
        let els = bez.elements();
        if !matches!(els.first(), Some(PathEl::MoveTo(_))) {
            return Err(invalid("the SVG path data must start with a move-to (`M x y`)"));
        }
        // The first subpath, the only one used: the others are not flattened either.
        let end = els.iter().skip(1).position(|e| matches!(e, PathEl::MoveTo(_))).map_or(els.len(), |i| i + 1);
        let first: kurbo::BezPath = els[..end].iter().copied().collect();
        // Range checks before flattening: flattening a curve of huge coordinates or length (or
        // at a tiny scale, where 0.5 cm is a tiny fraction of a unit) emits that many points.
        let (mut polygon, mut prev, mut start) = (0.0, kurbo::Point::ZERO, kurbo::Point::ZERO);
        for (i, el) in first.elements().iter().enumerate() {
            let points: &[kurbo::Point] = match el {
                PathEl::MoveTo(p) | PathEl::LineTo(p) => std::slice::from_ref(p),
                PathEl::QuadTo(a, b) => &[*a, *b],
                PathEl::CurveTo(a, b, c) => &[*a, *b, *c],
                PathEl::ClosePath => std::slice::from_ref(&start),
            };
            for p in points {
                if !(p.x.is_finite() && p.y.is_finite() && p.x.abs() <= MAX_SVG_UNITS && p.y.abs() <= MAX_SVG_UNITS) {
                    return Err(invalid(format!(
                        "SVG path element {i} has the point ({:?}, {:?}): coordinates are finite and in \
                         [-{MAX_SVG_UNITS}, {MAX_SVG_UNITS}] units",
                        p.x, p.y
                    )));
                }
                let (x, z) = (p.x * cm_per_unit, p.y * cm_per_unit);
                if x.abs() > MAX_COORD || z.abs() > MAX_COORD {
                    return Err(invalid(format!(
                        "SVG path element {i} has the point ({:?}, {:?}), ({x:?} cm, {z:?} cm) at {cm_per_unit:?} cm per unit: \
                         coordinates are in [-{MAX_COORD}, {MAX_COORD}] cm (10 km from the origin); move the path or \
                         lower the scale",
                        p.x, p.y
                    )));
                }
                if !matches!(el, PathEl::MoveTo(_)) {
                    polygon += (*p - prev).hypot() * cm_per_unit;
                }
                prev = *p;
            }
            if let PathEl::MoveTo(p) = el {
                start = *p;
            }
        }
        if polygon > MAX_LENGTH {
            return Err(invalid(format!(
                "the SVG path's control polygon is {polygon:.0} cm long at {cm_per_unit:?} cm per unit: a path is at \
                 most {MAX_LENGTH} cm (10 km) long; shorten it or lower the scale"
            )));
        }
        // Flattening: each curve into chords of equal parameter steps, as many as keep every chord
        // within 0.5 cm of the curve (a chord over a parameter step h is within h^2/8 max|B''| of
        // it), counted up front from the control points, so the point count is refused before
        // any point is made. (kurbo's adaptive `flatten` loops for ever on some curves when the
        // tolerance is huge, as at a tiny scale: its subdivision count overflows.)
        let tolerance = 0.5 / cm_per_unit;
        let chords = |second_derivative: f64| -> usize {
            ((second_derivative / (8.0 * tolerance)).sqrt().ceil().min(MAX_POINTS as f64) as usize).max(1)
        };
        let segments: Vec<(kurbo::PathSeg, usize)> = first
            .segments()
            .map(|seg| {
                let n = match seg {
                    kurbo::PathSeg::Line(_) => 1,
                    kurbo::PathSeg::Quad(q) => {
                        chords(2.0 * (q.p0 - 2.0 * q.p1.to_vec2() + q.p2.to_vec2()).to_vec2().hypot())
                    }
                    kurbo::PathSeg::Cubic(c) => {
                        let a = (c.p0 - 2.0 * c.p1.to_vec2() + c.p2.to_vec2()).to_vec2().hypot();
                        let b = (c.p1 - 2.0 * c.p2.to_vec2() + c.p3.to_vec2()).to_vec2().hypot();
                        chords(6.0 * a.max(b))
                    }
                };
                (seg, n)
            })
            .collect();
        let count = 1 + segments.iter().map(|(_, n)| n).sum::<usize>();
        if count > MAX_POINTS {
            return Err(invalid(format!(
                "the SVG path flattens to {count} points (its curves in chords within 0.5 cm), more than the \
                 {MAX_POINTS} zoo reads: simplify the drawing or lower the scale"
            )));
        }
        let mut pts: Vec<[f64; 2]> = Vec::with_capacity(count);
        pts.push([start.x * cm_per_unit, start.y * cm_per_unit]);
        for (seg, n) in segments {
            for k in 1..=n {
                let p = kurbo::ParamCurve::eval(&seg, k as f64 / n as f64);
                pts.push([p.x * cm_per_unit, p.y * cm_per_unit]);
            }
        }
        Self::new(pts)
    }

    /// The path of the first `<path d="...">` of an SVG document, `cm_per_unit` centimetres per
    /// user unit (transforms are not applied).
    pub fn from_svg_document(text: &str, cm_per_unit: f64) -> Result<Self, PathError> {
        let doc = roxmltree::Document::parse(text).map_err(|e| invalid(format!("the SVG file does not parse: {e}")))?;
        let d = doc
            .descendants()
            .find(|n| n.has_tag_name("path") && n.attribute("d").is_some())
            .and_then(|n| n.attribute("d"))
            .ok_or_else(|| invalid("the SVG file has no <path d=\"...\"> element: draw the path as an SVG path"))?;
        Self::from_svg_data(d, cm_per_unit)
    }

    /// Reads a `.json` or `.svg` file (`svg_cm_per_unit` for SVG files).
    pub fn load(path: &Path, svg_cm_per_unit: f64) -> Result<Self, PathError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| PathError::Io { path: path.display().to_string(), source })?;
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("json") => Self::from_json(&text),
            Some("svg") => Self::from_svg_document(&text, svg_cm_per_unit),
            _ => Err(invalid(format!("{}: a path file is .json or .svg", path.display()))),
        }
    }

    /// The points (cm).
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Total arc length (cm).
    pub fn length(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    /// The point at arc length `s`, on the straight extensions beyond either end.
    pub fn point_at(&self, s: f64) -> [f64; 2] {
        let n = self.points.len();
        let (i, t) = if s <= 0.0 {
            (0, s / self.cum[1])
        } else if s >= self.length() {
            (n - 2, (s - self.cum[n - 2]) / (self.cum[n - 1] - self.cum[n - 2]))
        } else {
            let i = self.cum.partition_point(|&c| c <= s).saturating_sub(1).min(n - 2);
            (i, (s - self.cum[i]) / (self.cum[i + 1] - self.cum[i]))
        };
        let (a, b) = (self.points[i], self.points[i + 1]);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }

    /// The unit tangent at arc length `s` (the segment's direction).
    pub fn tangent_at(&self, s: f64) -> [f64; 2] {
        let n = self.points.len();
        let i = self.cum.partition_point(|&c| c <= s).saturating_sub(1).min(n - 2);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let l = dist(a, b);
        [(b[0] - a[0]) / l, (b[1] - a[1]) / l]
    }

    /// The nearest point to `p` among the path's points with arc length in `[s_lo, s_hi]`,
    /// the path extended straight beyond both ends (so a query past the end is pulled along the
    /// end's direction, not back to the end point).
    pub fn nearest(&self, p: [f64; 2], s_lo: f64, s_hi: f64) -> Nearest {
        let n = self.points.len();
        let mut best = Nearest { point: self.point_at(s_lo), s: s_lo, distance: f64::INFINITY };
        let mut consider = |a: [f64; 2], sa: f64, b: [f64; 2], sb: f64| {
            let (q, t) = closest_on_segment(p, a, b);
            let d = dist(p, q);
            if d < best.distance {
                best = Nearest { point: q, s: sa + t * (sb - sa), distance: d };
            }
        };
        let len = self.length();
        if s_lo < 0.0 {
            consider(self.point_at(s_lo), s_lo, self.points[0], 0.0);
        }
        for i in 0..n - 1 {
            let (sa, sb) = (self.cum[i], self.cum[i + 1]);
            if sb < s_lo || sa > s_hi {
                continue;
            }
            let (ca, cb) = (sa.max(s_lo), sb.min(s_hi));
            consider(self.point_at(ca), ca, self.point_at(cb), cb);
        }
        if s_hi > len {
            consider(self.points[n - 1], len, self.point_at(s_hi), s_hi);
        }
        best
    }

    /// The benchmark's test paths by name (cm): `straight` (10 m), `circle` (radius 2 m, one
    /// loop), `s-curve` (two opposite half circles of radius 2 m), `corner` (a hand-drawn
    /// polyline: 5 m, a 120-degree turn, 4 m) and `spiral` (20 m of an Archimedean spiral
    /// opening from a radius of 1.5 m).
    pub fn test_path(name: &str) -> Result<Self, PathError> {
        let arc = |cx: f64, cz: f64, r: f64, a0: f64, a1: f64, out: &mut Vec<[f64; 2]>| {
            let steps = ((a1 - a0).abs() * r / 5.0).ceil().max(2.0) as usize;
            for k in 0..=steps {
                let a = a0 + (a1 - a0) * k as f64 / steps as f64;
                out.push([cx + r * a.cos(), cz + r * a.sin()]);
            }
        };
        let pi = std::f64::consts::PI;
        let pts = match name {
            "straight" => vec![[0.0, 0.0], [0.0, 1000.0]],
            "circle" => {
                let mut v = Vec::new();
                arc(-200.0, 0.0, 200.0, 0.0, 2.0 * pi, &mut v);
                v
            }
            "s-curve" => {
                let mut v = Vec::new();
                arc(-200.0, 0.0, 200.0, 0.0, pi, &mut v);
                arc(-600.0, 0.0, 200.0, 0.0, -pi, &mut v);
                v
            }
            "corner" => {
                // Drawn by hand (slightly uneven spacing and wobble), turning by 120 degrees at (0, 500).
                let t = 120f64.to_radians();
                let (dx, dz) = (t.sin(), t.cos());
                vec![
                    [0.0, 0.0],
                    [3.0, 118.0],
                    [-4.0, 251.0],
                    [2.0, 379.0],
                    [0.0, 500.0],
                    [dx * 97.0 + 4.0, 500.0 + dz * 97.0],
                    [dx * 215.0 - 3.0, 500.0 + dz * 215.0 + 2.0],
                    [dx * 300.0 + 2.0, 500.0 + dz * 300.0],
                    [dx * 400.0, 500.0 + dz * 400.0],
                ]
            }
            "spiral" => {
                // r = r0 + b a: from 1.5 m, arms 60 cm apart, until 20 m of arc.
                let (r0, b) = (150.0, 60.0 / (2.0 * pi));
                let mut v = vec![[r0, 0.0]];
                let (mut a, mut len) = (0.0f64, 0.0);
                while len < 2000.0 {
                    a += 0.01;
                    let r = r0 + b * a;
                    let p = [r * a.cos(), r * a.sin()];
                    len += dist(v[v.len() - 1], p);
                    v.push(p);
                }
                v
            }
            other => {
                return Err(invalid(format!("unknown test path `{other}`: one of {}", TEST_PATHS.join(", "))));
            }
        };
        Self::new(pts)
    }
}

/// The numbers of SVG path data, as kurbo's lexer reads them: a sign, digits with at most one
/// period, an exponent (`1.5.5` is `1.5` and `.5`, `1-2` is `1` and `-2`).
fn svg_numbers(d: &str) -> impl Iterator<Item = &str> {
    let b = d.as_bytes();
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < b.len() {
            let start = i;
            let mut j = i;
            if b[j] == b'-' || b[j] == b'+' {
                j += 1;
            }
            let (mut digits, mut period) = (0, false);
            while j < b.len() && (b[j].is_ascii_digit() || (b[j] == b'.' && !period)) {
                if b[j] == b'.' {
                    period = true;
                } else {
                    digits += 1;
                }
                j += 1;
            }
            if digits == 0 {
                i = start + 1;
                continue;
            }
            if j < b.len() && (b[j] == b'e' || b[j] == b'E') {
                let mut k = j + 1;
                if k < b.len() && (b[k] == b'-' || b[k] == b'+') {
                    k += 1;
                }
                if k < b.len() && b[k].is_ascii_digit() {
                    while k < b.len() && b[k].is_ascii_digit() {
                        k += 1;
                    }
                    j = k;
                }
            }
            i = j;
            return Some(&d[start..j]);
        }
        None
    })
}

fn check_point_count(n: usize) -> Result<(), PathError> {
    if n > MAX_POINTS {
        return Err(invalid(format!(
            "the path has {n} points, more than the {MAX_POINTS} zoo reads: give fewer points (one every 10 cm or \
             more is plenty)"
        )));
    }
    Ok(())
}

/// The names of [`GroundPath::test_path`].
pub const TEST_PATHS: [&str; 5] = ["straight", "circle", "s-curve", "corner", "spiral"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_points_and_svg_data_give_the_same_polyline() {
        let a = GroundPath::from_json(r#"{"units": "m", "points": [[0, 0], [0, 2], [1, 2]]}"#).unwrap();
        let b = GroundPath::from_json(r#"{"units": "cm", "svg": "M 0 0 L 0 200 L 100 200"}"#).unwrap();
        assert_eq!(a, b);
        assert!((a.length() - 300.0).abs() < 1e-9);
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg"><g><path d="M0,0 L0,2 L1,2"/></g></svg>"#;
        assert_eq!(GroundPath::from_svg_document(svg, 100.0).unwrap(), a);
    }

    #[test]
    fn curves_are_flattened_close_to_the_curve() {
        // A quarter circle of radius 100 as one cubic: every flattened point within 0.5 cm (+ the
        // cubic's own 0.03 % error) of the circle.
        let k = 0.5522847498 * 100.0;
        let p = GroundPath::from_svg_data(&format!("M 100 0 C 100 {k} {k} 100 0 100"), 1.0).unwrap();
        assert!(p.points().len() > 5);
        for q in p.points() {
            assert!((q[0].hypot(q[1]) - 100.0).abs() < 0.6, "{q:?}");
        }
        assert!((p.length() - 50.0 * std::f64::consts::PI).abs() < 1.0);
    }

    #[test]
    fn nearest_points_respect_the_arc_length_range_and_the_extensions() {
        let p = GroundPath::new(vec![[0.0, 0.0], [0.0, 100.0], [100.0, 100.0]]).unwrap();
        let n = p.nearest([10.0, 50.0], 0.0, 200.0);
        assert!((n.distance - 10.0).abs() < 1e-9 && (n.s - 50.0).abs() < 1e-9);
        // Restricted to the second segment.
        let n = p.nearest([10.0, 50.0], 100.0, 200.0);
        assert!((n.s - 110.0).abs() < 1e-9 && (n.distance - 50.0).abs() < 1e-9);
        // Past the end, along the end's direction.
        let n = p.nearest([150.0, 103.0], 0.0, 300.0);
        assert!((n.s - 250.0).abs() < 1e-9 && (n.distance - 3.0).abs() < 1e-9);
        assert_eq!(p.point_at(-10.0), [0.0, -10.0]);
        assert_eq!(p.tangent_at(150.0), [1.0, 0.0]);
    }

    #[test]
    fn bad_paths_are_refused_with_the_fix() {
        let e = GroundPath::from_json(r#"{"points": [[0, 0]]}"#).unwrap_err().to_string();
        assert!(e.contains("at least 2 distinct points"), "{e}");
        let e = GroundPath::from_json(r#"{"points": [[0, 0], [0, 0]]}"#).unwrap_err().to_string();
        assert!(e.contains("at least 2 distinct points"), "{e}");
        let e = GroundPath::from_json(r#"{"points": [[0, 0, 0], [1, 0.5, 1]]}"#).unwrap_err().to_string();
        assert!(e.contains("ground plane"), "{e}");
        let e = GroundPath::from_json(r#"{"points": [[0, 0], [1, "a"]]}"#).unwrap_err().to_string();
        assert!(e.contains("point 1"), "{e}");
        let e = GroundPath::from_json(r#"{"units": "ft", "points": [[0, 0], [1, 1]]}"#).unwrap_err().to_string();
        assert!(e.contains("units"), "{e}");
        let e = GroundPath::from_svg_document("<svg/>", 1.0).unwrap_err().to_string();
        assert!(e.contains("no <path"), "{e}");
        let e = GroundPath::new(vec![[0.0, f64::NAN], [1.0, 1.0]]).unwrap_err().to_string();
        assert!(e.contains("finite"), "{e}");
    }

    #[test]
    fn coordinates_lengths_point_counts_and_svg_scales_past_their_bounds_are_refused_with_the_range() {
        // At the bounds: loads (10 km straight, from -5 km to +5 km; 100,000 points).
        let p = GroundPath::from_json(r#"{"units": "m", "points": [[0, -5000], [0, 5000]]}"#).unwrap();
        assert_eq!(p.length(), MAX_LENGTH);
        let pts: Vec<[f64; 2]> = (0..MAX_POINTS).map(|i| [0.0, i as f64 * 0.01]).collect();
        assert_eq!(GroundPath::new(pts).unwrap().points().len(), MAX_POINTS);
        let b = GroundPath::from_svg_data("M 0 0 L 1e6 0", 1.0).unwrap();
        assert_eq!(b.length(), MAX_LENGTH);
        for (json, want) in [
            (r#"{"units": "m", "points": [[0, 0], [10001, 0]]}"#, "path point 1 is at (1000100.0 cm, 0.0 cm)"),
            (r#"{"units": "cm", "points": [[0, 0], [0, 1e300]]}"#, "in [-1000000, 1000000] cm"),
            (r#"{"units": "m", "points": [[-5000, 0], [5000, 0], [5000, 1]]}"#, "at most 1000000 cm (10 km) long"),
            (r#"{"units": "m", "svg": "M 0 0 L 0 1e7"}"#, "(0.0 cm, 1000000000.0 cm) at 100.0 cm per unit"),
            (r#"{"units": "cm", "svg": "M 0 0 L 1e300 0"}"#, "in [-1000000000, 1000000000] units"),
        ] {
            let e = GroundPath::from_json(json).unwrap_err().to_string();
            assert!(e.contains(want), "{json}: {e}");
        }
        let many: Vec<String> = (0..=MAX_POINTS).map(|i| format!("[0, {i}]")).collect();
        let e = GroundPath::from_json(&format!(r#"{{"units": "cm", "points": [{}]}}"#, many.join(",")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("100001 points, more than the 100000"), "{e}");
        // A curve whose control polygon is long: refused before flattening.
        let e = GroundPath::from_svg_data("M 0 0 C 0 400000 0 -400000 0 0", 1.0).unwrap_err().to_string();
        assert!(e.contains("control polygon is 1600000 cm long"), "{e}");
        // Tight loops within 10 km that would flatten to more than 100,000 points: counted, refused.
        let loops: String = (0..15_000).map(|_| "c 0 10 10 10 10 0 c 0 -10 -10 -10 -10 0 ").collect();
        let e = GroundPath::from_svg_data(&format!("M 0 0 {loops}"), 1.0).unwrap_err().to_string();
        assert!(
            e.contains("flattens to 150001 points (its curves in chords within 0.5 cm), more than the 100000"),
            "{e}"
        );
        // Arcs and a smooth quadratic at a tiny scale (a tolerance of 5e299 units): kurbo's
        // `flatten` never ended on this drawing (found by the `ground_path` fuzz target).
        let e = GroundPath::from_svg_data(
            "M0,0 A 2 1 0 0 1 0 2 T0,4 A 2 1 2 1 0 0 1 02 1 0 0 1 0,4A 2 1 21  0 1 0 2777",
            1e-300,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("at least 2 distinct points"), "{e}");
        let p = GroundPath::from_svg_data(
            "M0,0 A 2 1 0 0 1 0 2 T0,4 A 2 1 2 1 0 0 1 02 1 0 0 1 0,4A 2 1 21  0 1 0 2777",
            1.0,
        )
        .unwrap();
        assert!(p.points().len() > 20 && p.length() > 2777.0, "{} {}", p.points().len(), p.length());
        // A huge second subpath is neither used nor flattened; a huge first one is refused.
        let p = GroundPath::from_svg_data("M 0 0 L 0 100 M 0 0 C 1e9 0 0 1e9 1 1", 1.0).unwrap();
        assert_eq!(p.length(), 100.0);
        for (scale, want) in [(0.0, "(0, 10000]"), (1e5, "100000.0 cm per unit"), (f64::NAN, "NaN cm per unit")] {
            let e = GroundPath::from_svg_data("M 0 0 L 0 1", scale).unwrap_err().to_string();
            assert!(e.contains(want), "{scale}: {e}");
        }
        // An arc of a huge radius: refused before kurbo turns it into 1e50 curves.
        let e = GroundPath::from_svg_data("M 0 0 A 1e300 1e300 0 1 1 1 0", 1.0).unwrap_err().to_string();
        assert!(e.contains("has the number 1e300"), "{e}");
        let e = GroundPath::from_svg_data("M0,0L1.5.5-2e999", 1.0).unwrap_err().to_string();
        assert!(e.contains("has the number -2e999"), "{e}");
        assert_eq!(svg_numbers("M1.5.5-2e3,+4E-1 e5 1e").collect::<Vec<_>>(), ["1.5", ".5", "-2e3", "+4E-1", "5", "1"]);
        let e = GroundPath::from_svg_data("M 0 0 L 0 1e9", 1e-300).unwrap_err().to_string();
        assert!(e.contains("at least 2 distinct points"), "{e}");
    }

    #[test]
    fn the_example_files_in_docs_are_the_test_paths() {
        let corner = GroundPath::from_json(include_str!("../../../../docs/paths/corner.json")).unwrap();
        let want = GroundPath::test_path("corner").unwrap();
        assert_eq!(corner.points().len(), want.points().len());
        for (a, b) in corner.points().iter().zip(want.points()) {
            assert!(dist(*a, *b) < 0.1, "{a:?} vs {b:?}");
        }
        let s = GroundPath::from_svg_document(include_str!("../../../../docs/paths/s-curve.svg"), 1.0).unwrap();
        assert!((s.length() - GroundPath::test_path("s-curve").unwrap().length()).abs() < 3.0, "{}", s.length());
    }

    #[test]
    fn test_paths_have_their_lengths() {
        let len = |n: &str| GroundPath::test_path(n).unwrap().length();
        assert!((len("straight") - 1000.0).abs() < 1e-9);
        assert!((len("circle") - 400.0 * std::f64::consts::PI).abs() < 2.0);
        assert!((len("s-curve") - 400.0 * std::f64::consts::PI).abs() < 4.0);
        assert!((len("spiral") - 2000.0).abs() < 5.0);
        let c = GroundPath::test_path("corner").unwrap();
        let (a, b) = (c.tangent_at(450.0), c.tangent_at(560.0));
        let turn = (a[0] * b[0] + a[1] * b[1]).acos().to_degrees();
        assert!((turn - 120.0).abs() < 5.0, "{turn}");
    }
}
