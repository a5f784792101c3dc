//! Ground paths (`zoo follow --path`): the first byte picks the reader of the rest, JSON
//! (`GroundPath::from_json`, points or SVG data), SVG path data at a scale the second byte
//! picks (`from_svg_data`) or an SVG document (`from_svg_document`). Each must parse or fail
//! with an error, never panic, and finish in bounded time and memory (no flattening of a
//! huge curve); a parsed path must be within the bounds (finite points within +-10 km, at most
//! `MAX_POINTS` of them, at most 10 km long) and its queries finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use zoo_rnngmm::path::{GroundPath, MAX_COORD, MAX_LENGTH, MAX_POINTS};

const SCALES: [f64; 8] = [1.0, 100.0, 0.01, 1e-300, 1e4, 1e5, 0.5, 3.0];

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let path = match mode % 3 {
        0 => GroundPath::from_json(&String::from_utf8_lossy(rest)),
        1 => {
            let Some((&s, d)) = rest.split_first() else { return };
            GroundPath::from_svg_data(&String::from_utf8_lossy(d), SCALES[s as usize % SCALES.len()])
        }
        _ => {
            let Some((&s, d)) = rest.split_first() else { return };
            GroundPath::from_svg_document(&String::from_utf8_lossy(d), SCALES[s as usize % SCALES.len()])
        }
    };
    let Ok(p) = path else { return };
    let pts = p.points();
    assert!(pts.len() >= 2 && pts.len() <= MAX_POINTS, "{} points", pts.len());
    assert!(pts.iter().flatten().all(|c| c.is_finite() && c.abs() <= MAX_COORD), "a point out of range");
    let len = p.length();
    assert!(len.is_finite() && len > 0.0 && len <= MAX_LENGTH, "length {len}");
    for s in [-100.0, 0.0, 0.5 * len, len, len + 100.0] {
        let q = p.point_at(s);
        assert!(q[0].is_finite() && q[1].is_finite(), "point at {s}: {q:?}");
        let t = p.tangent_at(s);
        assert!(t[0].is_finite() && t[1].is_finite(), "tangent at {s}: {t:?}");
        let n = p.nearest([q[0] + 3.0, q[1] - 2.0], s - 50.0, s + 50.0);
        assert!(n.distance.is_finite() && n.s.is_finite(), "{n:?}");
    }
});
