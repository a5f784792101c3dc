//! Terrain as a heightmap: the ground under a clip, read by synthetic data, rendering, and the
//! terrain patches RTN reads in training and in the engine runtime ([`terrain_patch`]).
//!
//! Units are the clip's (cm for bandai2 and the synthetic data), Y up. A [`Heightmap`] stores
//! `cols * rows` heights on a regular grid in the XZ plane: sample `(i, k)` lies at
//! `(origin[0] + i * cell, origin[1] + k * cell)` and is stored at `heights[k * cols + i]`.
//! Between samples the surface is bilinear; outside the grid the border value is extended.
//! The file format lives with the dataset tooling (`zoo_data::terrain`).

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// A regular grid of terrain heights (see the module docs for the layout).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Heightmap {
    /// Number of samples along X.
    pub cols: usize,
    /// Number of samples along Z.
    pub rows: usize,
    /// Distance between neighbouring samples (clip units).
    pub cell: f64,
    /// World (x, z) of sample (0, 0) (clip units).
    pub origin: [f64; 2],
    /// Heights (clip units), row-major: `heights[k * cols + i]`.
    pub heights: Vec<f32>,
}

impl Heightmap {
    /// A flat heightmap at height `h` everywhere (one sample).
    pub fn flat(h: f32) -> Self {
        Heightmap { cols: 1, rows: 1, cell: 1.0, origin: [0.0, 0.0], heights: vec![h] }
    }

    /// A flat grid of height `h` covering `[x0, x1] x [z0, z1]` with samples `cell` apart.
    pub fn flat_area(x0: f64, z0: f64, x1: f64, z1: f64, cell: f64, h: f32) -> Self {
        let cols = ((x1 - x0) / cell).ceil() as usize + 1;
        let rows = ((z1 - z0) / cell).ceil() as usize + 1;
        Heightmap { cols, rows, cell, origin: [x0, z0], heights: vec![h; cols * rows] }
    }

    /// A grid covering `[x0, x1] x [z0, z1]` with heights `f(x, z)` at the samples.
    pub fn from_fn(x0: f64, z0: f64, x1: f64, z1: f64, cell: f64, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut map = Heightmap::flat_area(x0, z0, x1, z1, cell, 0.0);
        for k in 0..map.rows {
            for i in 0..map.cols {
                let (x, z) = (x0 + i as f64 * cell, z0 + k as f64 * cell);
                map.heights[k * map.cols + i] = f(x, z) as f32;
            }
        }
        map
    }

    /// Height of sample `(i, k)`, indices clamped to the grid.
    #[inline]
    pub fn at(&self, i: isize, k: isize) -> f64 {
        let i = i.clamp(0, self.cols as isize - 1) as usize;
        let k = k.clamp(0, self.rows as isize - 1) as usize;
        self.heights[k * self.cols + i] as f64
    }

    /// Bilinear height of the surface at world `(x, z)` in `f64` (border extended outside the
    /// grid): what synthetic motion, rendering and the plausibility metrics read.
    pub fn height(&self, x: f64, z: f64) -> f64 {
        let u = (x - self.origin[0]) / self.cell;
        let v = (z - self.origin[1]) / self.cell;
        let (i, k) = (u.floor(), v.floor());
        let (fu, fv) = (u - i, v - k);
        let (i, k) = (i as isize, k as isize);
        let h00 = self.at(i, k);
        let h10 = self.at(i + 1, k);
        let h01 = self.at(i, k + 1);
        let h11 = self.at(i + 1, k + 1);
        let a = h00 + (h10 - h00) * fu;
        let b = h01 + (h11 - h01) * fu;
        a + (b - a) * fv
    }

    /// Height at the XZ of a point (its Y is ignored), as [`Heightmap::height`].
    pub fn height_at(&self, p: DVec3) -> f64 {
        self.height(p.x, p.z)
    }

    /// Bilinear height at world `(x, z)` in `f32`, clamped at the border: the sampling of the
    /// models' terrain patches (cell and origin rounded to `f32` first), so that training and an
    /// engine computing the same patch agree bit for bit.
    pub fn sample(&self, x: f32, z: f32) -> f32 {
        let (cell, ox, oz) = (self.cell as f32, self.origin[0] as f32, self.origin[1] as f32);
        let fx = ((x - ox) / cell).clamp(0.0, (self.cols - 1) as f32);
        let fz = ((z - oz) / cell).clamp(0.0, (self.rows - 1) as f32);
        let (x0, z0) = (fx.floor() as usize, fz.floor() as usize);
        let (x1, z1) = ((x0 + 1).min(self.cols - 1), (z0 + 1).min(self.rows - 1));
        let (tx, tz) = (fx - x0 as f32, fz - z0 as f32);
        let h = |x: usize, z: usize| self.heights[z * self.cols + x];
        let a = h(x0, z0) * (1.0 - tx) + h(x1, z0) * tx;
        let b = h(x0, z1) * (1.0 - tx) + h(x1, z1) * tx;
        a * (1.0 - tz) + b * tz
    }
}

/// Rotates global positions (`... x 3`) by `angle` radians about the vertical (+Y) axis
/// through `center = (x, z)` (the augmentation of RTN sec. 3.3).
pub fn rotate_about_y(positions: &mut [f32], angle: f32, center: [f32; 2]) {
    let (s, c) = angle.sin_cos();
    for p in positions.chunks_exact_mut(3) {
        let (x, z) = (p[0] - center[0], p[2] - center[1]);
        p[0] = c * x + s * z + center[0];
        p[2] = -s * x + c * z + center[1];
    }
}

/// A rotation of the world about the vertical axis through `center` (x, z), applied to the
/// positions of a training window; terrain is sampled through its inverse (RTN sec. 3.3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawAbout {
    /// Angle in radians (as in [`rotate_about_y`]).
    pub angle: f32,
    /// Vertical axis position (x, z).
    pub center: [f32; 2],
}

/// Local terrain patch `p_t` (RTN sec. 3.2): a `side x side` grid spanning `extent` around the
/// root's (x, z), world-axis aligned, holding terrain height minus root height (`f32`
/// sampling, [`Heightmap::sample`]); `rotation` is the augmentation applied to the positions
/// (the terrain is rotated with them; `None` outside training). Entry `[i * side + j]` lies at
/// `(root.x - extent / 2 + j * step, root.z - extent / 2 + i * step)`, `step = extent / (side - 1)`.
/// Training (`zoo_rtn`) and the engine runtime both call this function. Allocates nothing.
pub fn terrain_patch(
    map: &Heightmap,
    root: [f32; 3],
    extent: f32,
    side: usize,
    rotation: Option<YawAbout>,
    out: &mut [f32],
) {
    assert_eq!(out.len(), side * side, "a terrain patch has side * side values");
    let step = if side > 1 { extent / (side - 1) as f32 } else { 0.0 };
    let half = extent * 0.5;
    for i in 0..side {
        for j in 0..side {
            let mut p = [root[0] - half + j as f32 * step, 0.0, root[2] - half + i as f32 * step];
            if let Some(r) = rotation {
                rotate_about_y(&mut p, -r.angle, r.center);
            }
            out[i * side + j] = map.sample(p[0], p[2]) - root[1];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_and_f64_sampling_agree() {
        let map = Heightmap::from_fn(-100.0, -50.0, 100.0, 150.0, 10.0, |x, z| 0.1 * x - 0.05 * z + (0.03 * x).sin());
        for (x, z) in [(-95.0, -45.0), (0.0, 0.0), (33.3, 77.7), (99.0, 149.0), (500.0, -300.0)] {
            let (a, b) = (map.height(x, z), map.sample(x as f32, z as f32) as f64);
            assert!((a - b).abs() < 1e-3, "({x}, {z}): f64 {a}, f32 {b}");
        }
    }

    #[test]
    fn bilinear_sampling_is_exact_on_a_plane() {
        let map = Heightmap::from_fn(-100.0, -50.0, 100.0, 80.0, 10.0, |x, z| 0.1 * x - 0.05 * z + 3.0);
        for (x, z) in [(0.0, 0.0), (13.7, -22.1), (-99.0, 79.0), (55.5, 5.5)] {
            assert!((map.height(x, z) - (0.1 * x - 0.05 * z + 3.0)).abs() < 1e-4);
        }
        assert!((map.height(500.0, 0.0) - map.height(100.0, 0.0)).abs() < 1e-9, "border extended");
    }

    #[test]
    fn flat_maps_are_flat() {
        assert_eq!(Heightmap::flat(2.5).sample(-40.0, 7.0), 2.5);
        let m = Heightmap::flat_area(-10.0, 0.0, 10.0, 5.0, 2.0, 1.0);
        assert_eq!((m.cols, m.rows), (11, 4));
        assert_eq!(m.height(3.3, 2.2), 1.0);
    }

    #[test]
    fn terrain_patch_is_relative_to_the_root_and_world_aligned() {
        // A ramp rising 0.5 per unit along +X.
        let map = Heightmap::from_fn(-50.0, -50.0, 50.0, 50.0, 5.0, |x, _| 0.5 * x);
        let mut patch = [0.0; 9];
        terrain_patch(&map, [10.0, 30.0, -5.0], 20.0, 3, None, &mut patch);
        // Row 1, column 0 lies at x = 0; column 2 at x = 20; rows run along +Z (flat here).
        assert!((patch[3] - (0.0 - 30.0)).abs() < 1e-5, "{patch:?}");
        assert!((patch[5] - (10.0 - 30.0)).abs() < 1e-5, "{patch:?}");
        assert!((patch[0] - patch[6]).abs() < 1e-5, "{patch:?}");
    }
}
