//! Stage 2: the terrain under the planned path.

use super::TerrainKind;
use super::geometry::yaw_dir;
use super::trajectory::Trajectory;
use crate::terrain::Heightmap;
use glam::DVec3;
use std::f64::consts::{PI, TAU};
use zoo_motion::rng::SplitMix64;

/// The step edges between `s_min` and `s_max` along the steps' direction (cm): (position,
/// height change), 90-320 cm apart, the level kept within 60 cm of the start.
fn step_edges(rng: &mut SplitMix64, s_min: f64, s_max: f64) -> Vec<(f64, f64)> {
    let mut edges: Vec<(f64, f64)> = Vec::new();
    let mut level = 0.0;
    let mut s = s_min + rng.range(50.0, 250.0);
    // Edges are at least 90 cm apart: the count is bounded up front (and by 90,000 km of
    // terrain), so a huge coordinate, where adding 90 cm no longer changes `s`, cannot loop for
    // ever.
    let most_edges = (((s_max - s_min) / 90.0).ceil().max(0.0) as usize).min(1_000_000) + 1;
    while s < s_max && edges.len() < most_edges {
        let mut jump = rng.sign() * rng.range(8.0, 18.0);
        if (level + jump).abs() > 60.0 {
            jump = -jump;
        }
        level += jump;
        edges.push((s, jump));
        s += rng.range(90.0, 320.0);
    }
    edges
}

/// The ground around a trajectory (180 cm margin, 10 cm cells) for a terrain kind: slope with
/// waves, Gaussian bumps along the path, step edges, or all three.
pub(super) fn make_terrain(rng: &mut SplitMix64, kind: TerrainKind, traj: &Trajectory) -> Heightmap {
    let (mut x0, mut z0, mut x1, mut z1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in &traj.pos {
        x0 = x0.min(p.x);
        z0 = z0.min(p.z);
        x1 = x1.max(p.x);
        z1 = z1.max(p.z);
    }
    let m = 180.0;
    let (x0, z0, x1, z1) = (x0 - m, z0 - m, x1 + m, z1 + m);
    let cell = 10.0;
    let start = traj.pos[0];
    // Slope: plane through the start point plus gentle waves.
    let slope_dir = yaw_dir(rng.range(-PI, PI));
    let slope = rng.sign() * rng.range(3.0, 9.0f64).to_radians().tan();
    let wave_amp = rng.range(0.0, 6.0);
    let wave_len = rng.range(300.0, 800.0);
    // Bumps: Gaussians placed along the path.
    let nb = 6 + (rng.next_f64() * 8.0) as usize;
    let bumps: Vec<(DVec3, f64, f64)> = (0..nb)
        .map(|_| {
            let p = traj.pos[(rng.next_f64() * traj.pos.len() as f64) as usize % traj.pos.len()];
            let c = p + DVec3::new(rng.range(-80.0, 80.0), 0.0, rng.range(-80.0, 80.0));
            (c, rng.sign() * rng.range(5.0, 16.0), rng.range(70.0, 160.0))
        })
        .collect();
    // Steps: edges perpendicular to one direction, heights summed along it.
    let step_dir = yaw_dir(rng.range(-PI, PI));
    let (mut s_min, mut s_max) = (f64::MAX, f64::MIN);
    for p in [DVec3::new(x0, 0.0, z0), DVec3::new(x1, 0.0, z0), DVec3::new(x0, 0.0, z1), DVec3::new(x1, 0.0, z1)] {
        let s = (p - start).dot(step_dir);
        s_min = s_min.min(s);
        s_max = s_max.max(s);
    }
    let edges = step_edges(rng, s_min, s_max);
    let use_slope = matches!(kind, TerrainKind::Slope | TerrainKind::Mixed);
    let use_bumps = matches!(kind, TerrainKind::Bumps | TerrainKind::Mixed);
    let use_steps = matches!(kind, TerrainKind::Steps | TerrainKind::Mixed);
    let scale = if kind == TerrainKind::Mixed { 0.6 } else { 1.0 };
    let height = move |x: f64, z: f64| {
        let p = DVec3::new(x, 0.0, z) - start;
        let mut h = 0.0;
        if use_slope {
            let u = p.dot(slope_dir);
            h += scale * (slope * u + wave_amp * (u / wave_len * TAU).sin());
        }
        if use_bumps {
            for (c, a, r) in &bumps {
                let d2 = (x - c.x).powi(2) + (z - c.z).powi(2);
                h += scale * a * (-d2 / (r * r)).exp();
            }
        }
        if use_steps {
            let u = p.dot(step_dir);
            for (e, jump) in &edges {
                if u >= *e {
                    h += jump;
                }
            }
        }
        h
    };
    match kind {
        TerrainKind::Flat => Heightmap::flat_area(x0, z0, x1, z1, cell, 0.0),
        _ => Heightmap::from_fn(x0, z0, x1, z1, cell, height),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_edges_end_at_huge_coordinates_where_a_step_no_longer_moves() {
        let mut rng = SplitMix64::new(3);
        let e = step_edges(&mut rng, 0.0, 1000.0);
        assert!(!e.is_empty() && e.len() <= 12 && e.windows(2).all(|w| w[1].0 - w[0].0 >= 90.0), "{e:?}");
        // At 1e20 cm adding 320 cm leaves `s` unchanged: a loop on `s < s_max` never ended.
        let e = step_edges(&mut rng, 1e20, 1e20 + 1e6);
        assert!(e.len() <= 12_000, "{}", e.len());
        // No span: no edge past one.
        assert!(step_edges(&mut rng, f64::NAN, f64::NAN).is_empty());
        assert!(step_edges(&mut rng, -f64::MAX, f64::MAX).len() <= 1_000_001);
    }
}
