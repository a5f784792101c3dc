//! Heightfields: terrain under synthetic motion, and the local height patches of RTN.
//!
//! Units are the clip's (cm), Y up. A [`Heightfield`] stores `nx * nz` heights on a regular
//! grid in the XZ plane: sample `(i, k)` lies at `(origin_x + i * cell, origin_z + k * cell)`
//! and is stored at `heights[k * nx + i]`. Between samples the surface is bilinear; outside
//! the grid the border value is extended.
//!
//! File format (written by [`Heightfield::write`]): `NAME.json`, a small header
//! `{"format": "zoo-heightfield", "version": 1, "nx", "nz", "cell", "origin_x", "origin_z",
//! "units": "cm", "data": "NAME.f32"}`, and beside it `NAME.f32`, the `nx * nz` heights as
//! little-endian `f32`, row `k = 0` first (the layout of `heights`).

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Side of the RTN terrain patch, in samples (RTN section 3.3: 13 x 13).
pub const PATCH_SAMPLES: usize = 13;
/// Width of the RTN terrain patch in cm (2.06 m, centred on the root).
pub const PATCH_WIDTH_CM: f64 = 206.0;

/// A regular grid of terrain heights (see the module docs for the layout).
#[derive(Clone, Debug, PartialEq)]
pub struct Heightfield {
    /// Samples along X.
    pub nx: usize,
    /// Samples along Z.
    pub nz: usize,
    /// Distance between neighbouring samples (cm).
    pub cell: f64,
    /// World X of sample column 0 (cm).
    pub origin_x: f64,
    /// World Z of sample row 0 (cm).
    pub origin_z: f64,
    /// Heights (cm), `heights[k * nx + i]`.
    pub heights: Vec<f32>,
}

/// Why a heightfield file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum HeightfieldError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The header is not a zoo heightfield header.
    #[error("{path}: not a zoo heightfield header: {message}")]
    Header {
        /// File.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
    /// The data file has the wrong size.
    #[error("{path}: expected {expected} bytes ({nx} x {nz} little-endian f32), found {found}")]
    Size {
        /// Data file.
        path: PathBuf,
        /// Expected size in bytes.
        expected: usize,
        /// Actual size in bytes.
        found: usize,
        /// Samples along X.
        nx: usize,
        /// Samples along Z.
        nz: usize,
    },
}

fn io_err(p: &Path) -> impl FnOnce(std::io::Error) -> HeightfieldError + '_ {
    move |source| HeightfieldError::Io { path: p.to_path_buf(), source }
}

#[derive(Serialize, Deserialize)]
struct Header {
    format: String,
    version: u32,
    nx: usize,
    nz: usize,
    cell: f64,
    origin_x: f64,
    origin_z: f64,
    units: String,
    data: String,
}

impl Heightfield {
    /// A flat field of height `h` covering `[x0, x1] x [z0, z1]`.
    pub fn flat(x0: f64, z0: f64, x1: f64, z1: f64, cell: f64, h: f32) -> Heightfield {
        let nx = ((x1 - x0) / cell).ceil() as usize + 1;
        let nz = ((z1 - z0) / cell).ceil() as usize + 1;
        Heightfield { nx, nz, cell, origin_x: x0, origin_z: z0, heights: vec![h; nx * nz] }
    }

    /// A field covering `[x0, x1] x [z0, z1]` with heights `f(x, z)` at the samples.
    pub fn from_fn(x0: f64, z0: f64, x1: f64, z1: f64, cell: f64, f: impl Fn(f64, f64) -> f64) -> Heightfield {
        let mut hf = Heightfield::flat(x0, z0, x1, z1, cell, 0.0);
        for k in 0..hf.nz {
            for i in 0..hf.nx {
                let (x, z) = (x0 + i as f64 * cell, z0 + k as f64 * cell);
                hf.heights[k * hf.nx + i] = f(x, z) as f32;
            }
        }
        hf
    }

    /// The same grid as the motion core's [`zoo_motion::features::Heightmap`] (what RTN's
    /// terrain patches sample).
    pub fn to_heightmap(&self) -> zoo_motion::features::Heightmap {
        zoo_motion::features::Heightmap {
            cols: self.nx,
            rows: self.nz,
            cell: self.cell as f32,
            origin: [self.origin_x as f32, self.origin_z as f32],
            heights: self.heights.clone(),
        }
    }

    /// Height of sample `(i, k)`, indices clamped to the grid.
    #[inline]
    pub fn at(&self, i: isize, k: isize) -> f64 {
        let i = i.clamp(0, self.nx as isize - 1) as usize;
        let k = k.clamp(0, self.nz as isize - 1) as usize;
        self.heights[k * self.nx + i] as f64
    }

    /// Bilinear height of the surface at world `(x, z)` (border extended outside the grid).
    pub fn height(&self, x: f64, z: f64) -> f64 {
        let u = (x - self.origin_x) / self.cell;
        let v = (z - self.origin_z) / self.cell;
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

    /// Height at the XZ of a point (its Y is ignored).
    pub fn height_at(&self, p: DVec3) -> f64 {
        self.height(p.x, p.z)
    }

    /// The RTN local terrain patch (section 3.3): `PATCH_SAMPLES x PATCH_SAMPLES` heights over
    /// `PATCH_WIDTH_CM` centred on `root`, each relative to the root's height
    /// (`terrain - root.y`, cm). The grid is rotated with `facing` (a rotation about +Y whose
    /// image of +Z is the character's forward): entry `[r * 13 + c]` lies at
    /// `root + facing * (x_c, 0, z_r)` with `x_c, z_r` running from -103 cm to +103 cm
    /// (`r` from back to front, `c` from the character's right (-X) to its left (+X)).
    pub fn local_patch(&self, root: DVec3, facing: DQuat) -> [f64; PATCH_SAMPLES * PATCH_SAMPLES] {
        let mut out = [0.0; PATCH_SAMPLES * PATCH_SAMPLES];
        let step = PATCH_WIDTH_CM / (PATCH_SAMPLES - 1) as f64;
        let half = PATCH_WIDTH_CM / 2.0;
        for r in 0..PATCH_SAMPLES {
            for c in 0..PATCH_SAMPLES {
                let local = DVec3::new(-half + c as f64 * step, 0.0, -half + r as f64 * step);
                let p = root + facing * local;
                out[r * PATCH_SAMPLES + c] = self.height(p.x, p.z) - root.y;
            }
        }
        out
    }

    /// Writes `path` (the JSON header) and the raw `f32` data beside it (`path` with
    /// extension `f32`).
    pub fn write(&self, path: &Path) -> Result<(), HeightfieldError> {
        let data_path = path.with_extension("f32");
        let header = Header {
            format: "zoo-heightfield".into(),
            version: 1,
            nx: self.nx,
            nz: self.nz,
            cell: self.cell,
            origin_x: self.origin_x,
            origin_z: self.origin_z,
            units: "cm".into(),
            data: data_path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        };
        let text = serde_json::to_string_pretty(&header).expect("header serialises");
        std::fs::write(path, text).map_err(io_err(path))?;
        let mut bytes = Vec::with_capacity(self.heights.len() * 4);
        for h in &self.heights {
            bytes.extend_from_slice(&h.to_le_bytes());
        }
        std::fs::write(&data_path, bytes).map_err(io_err(&data_path))
    }

    /// Reads a heightfield written by [`Heightfield::write`] (give the `.json` header).
    pub fn read(path: &Path) -> Result<Heightfield, HeightfieldError> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        let header: Header = serde_json::from_str(&text)
            .map_err(|e| HeightfieldError::Header { path: path.to_path_buf(), message: e.to_string() })?;
        if header.format != "zoo-heightfield" || header.version != 1 {
            return Err(HeightfieldError::Header {
                path: path.to_path_buf(),
                message: format!(
                    "format `{}` version {}, expected `zoo-heightfield` version 1",
                    header.format, header.version
                ),
            });
        }
        let data_path = path.with_file_name(&header.data);
        let bytes = std::fs::read(&data_path).map_err(io_err(&data_path))?;
        let expected = header.nx * header.nz * 4;
        if bytes.len() != expected || expected == 0 {
            return Err(HeightfieldError::Size {
                path: data_path,
                expected,
                found: bytes.len(),
                nx: header.nx,
                nz: header.nz,
            });
        }
        let heights = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        Ok(Heightfield {
            nx: header.nx,
            nz: header.nz,
            cell: header.cell,
            origin_x: header.origin_x,
            origin_z: header.origin_z,
            heights,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heightmap_samples_the_same_terrain() {
        let hf = Heightfield::from_fn(-100.0, -50.0, 100.0, 150.0, 10.0, |x, z| 0.1 * x - 0.05 * z + (0.03 * x).sin());
        let map = hf.to_heightmap();
        for (x, z) in [(-95.0, -45.0), (0.0, 0.0), (33.3, 77.7), (99.0, 149.0)] {
            let (a, b) = (hf.height(x, z), map.sample(x as f32, z as f32) as f64);
            assert!((a - b).abs() < 1e-3, "({x}, {z}): heightfield {a}, heightmap {b}");
        }
    }

    #[test]
    fn bilinear_sampling_is_exact_on_a_plane() {
        let hf = Heightfield::from_fn(-100.0, -50.0, 100.0, 80.0, 10.0, |x, z| 0.1 * x - 0.05 * z + 3.0);
        for (x, z) in [(0.0, 0.0), (13.7, -22.1), (-99.0, 79.0), (55.5, 5.5)] {
            assert!((hf.height(x, z) - (0.1 * x - 0.05 * z + 3.0)).abs() < 1e-4);
        }
        // Outside: border extended.
        assert!((hf.height(500.0, 0.0) - hf.height(100.0, 0.0)).abs() < 1e-9);
    }

    #[test]
    fn local_patch_is_relative_and_rotated() {
        let hf = Heightfield::from_fn(-300.0, -300.0, 300.0, 300.0, 5.0, |x, _| 0.2 * x);
        let root = DVec3::new(0.0, 90.0, 0.0);
        let p = hf.local_patch(root, DQuat::IDENTITY);
        // Centre sample: 0 - 90. Column 12 is +103 cm along +X.
        assert!((p[6 * 13 + 6] + 90.0).abs() < 1e-4);
        assert!((p[6 * 13 + 12] - (0.2 * 103.0 - 90.0)).abs() < 1e-3);
        // Facing +X (yaw 90 deg): local +Z points along world +X, so rows now climb.
        let q = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let p = hf.local_patch(root, q);
        assert!((p[12 * 13 + 6] - (0.2 * 103.0 - 90.0)).abs() < 1e-3);
    }

    #[test]
    fn file_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let hf = Heightfield::from_fn(-20.0, 10.0, 30.0, 40.0, 10.0, |x, z| x * z * 0.01);
        let path = dir.path().join("t.json");
        hf.write(&path).unwrap();
        assert_eq!(Heightfield::read(&path).unwrap(), hf);
    }
}

/// The heightmap header `NAME.terrain.json` beside a clip `NAME.bvh[.gz]`, if there is one
/// (the layout `zoo data synth` writes).
pub fn sibling_of(clip_path: &Path) -> Option<std::path::PathBuf> {
    let name = clip_path.file_name()?.to_string_lossy().into_owned();
    let stem = name.trim_end_matches(".gz").trim_end_matches(".bvh");
    let t = clip_path.with_file_name(format!("{stem}.terrain.json"));
    t.exists().then_some(t)
}
