//! Heightmap files (`zoo_data::terrain::parse`: the `.json` header and the `.f32` heights).
//! The input is the header text, a NUL byte, then the data bytes (no NUL: the header alone,
//! with the heights of a valid 3 x 2 map). Each must parse or fail with an error, never panic;
//! a parsed map must be within the header's ranges, and its lookups (bilinear in f64, the
//! models' f32 sampling, the RTN terrain patch) finite anywhere within the origin's range.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use zoo_data::terrain::{MAX_CELL, MAX_ORIGIN, MAX_SAMPLES, MIN_CELL, local_patch, parse};

fuzz_target!(|data: &[u8]| {
    let (header, heights) = match data.iter().position(|b| *b == 0) {
        Some(i) => (&data[..i], data[i + 1..].to_vec()),
        None => (data, (0..6u8).flat_map(|h| (h as f32).to_le_bytes()).collect()),
    };
    let Ok(header) = std::str::from_utf8(header) else { return };
    let Ok(map) = parse(Path::new("fuzz.json"), header, &heights) else { return };
    assert!(map.cell.is_finite() && (MIN_CELL..=MAX_CELL).contains(&map.cell), "cell {}", map.cell);
    assert!(map.origin.iter().all(|o| o.is_finite() && o.abs() <= MAX_ORIGIN), "{:?}", map.origin);
    assert!(map.cols >= 1 && map.rows >= 1 && map.cols * map.rows <= MAX_SAMPLES);
    assert_eq!(map.heights.len(), map.cols * map.rows);
    assert!(map.heights.iter().all(|h| h.is_finite()));
    let far = 2.0 * MAX_ORIGIN;
    for (x, z) in [
        (0.0, 0.0),
        (far, -far),
        (-far, far),
        (map.origin[0], map.origin[1]),
        (map.origin[0] + 0.5 * map.cell, map.origin[1] + 1.5 * map.cell),
    ] {
        let h = map.height(x, z);
        assert!(h.is_finite(), "height at ({x}, {z}) is {h}");
        let s = map.sample(x as f32, z as f32);
        assert!(s.is_finite(), "f32 sample at ({x}, {z}) is {s}");
    }
    let root = glam::DVec3::new(map.origin[0], 90.0, map.origin[1]);
    let patch = local_patch(&map, root, glam::DQuat::from_rotation_y(0.7));
    assert!(patch.iter().all(|h| h.is_finite()));
});
