//! Terrain files and the facing-aligned terrain patch around a clip's root.
//!
//! The grid itself is the core layer's [`Heightmap`] (units are the clip's, cm, Y up; see
//! [`zoo_protocol::terrain`] for the layout). File format (written by [`write`]): `NAME.json`, a
//! small header `{"format": "zoo-heightfield", "version": 1, "nx", "nz", "cell", "origin_x",
//! "origin_z", "units": "cm", "data": "NAME.f32"}` (`nx`, `nz`: the map's `cols`, `rows`), and
//! beside it `NAME.f32`, the `nx * nz` heights as little-endian `f32`, row `k = 0` first (the
//! layout of [`Heightmap::heights`]).

use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
pub use zoo_protocol::terrain::Heightmap;

/// Side of the RTN terrain patch, in samples (RTN section 3.3: 13 x 13).
pub const PATCH_SAMPLES: usize = 13;
/// Width of the RTN terrain patch in cm (2.06 m, centred on the root).
pub const PATCH_WIDTH_CM: f64 = 206.0;

/// Why a terrain file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum TerrainFileError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The header is not a zoo terrain header.
    #[error("{path}: not a zoo terrain header: {message}")]
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

fn io_err(p: &Path) -> impl FnOnce(std::io::Error) -> TerrainFileError + '_ {
    move |source| TerrainFileError::Io { path: p.to_path_buf(), source }
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

/// The RTN-style local terrain patch (RTN section 3.3) of a map: `PATCH_SAMPLES x PATCH_SAMPLES`
/// heights over `PATCH_WIDTH_CM` centred on `root`, each relative to the root's height
/// (`terrain - root.y`, cm). The grid is rotated with `facing` (a rotation about +Y whose
/// image of +Z is the character's forward): entry `[r * 13 + c]` lies at
/// `root + facing * (x_c, 0, z_r)` with `x_c, z_r` running from -103 cm to +103 cm
/// (`r` from back to front, `c` from the character's right (-X) to its left (+X)).
pub fn local_patch(map: &Heightmap, root: DVec3, facing: DQuat) -> [f64; PATCH_SAMPLES * PATCH_SAMPLES] {
    let mut out = [0.0; PATCH_SAMPLES * PATCH_SAMPLES];
    let step = PATCH_WIDTH_CM / (PATCH_SAMPLES - 1) as f64;
    let half = PATCH_WIDTH_CM / 2.0;
    for r in 0..PATCH_SAMPLES {
        for c in 0..PATCH_SAMPLES {
            let local = DVec3::new(-half + c as f64 * step, 0.0, -half + r as f64 * step);
            let p = root + facing * local;
            out[r * PATCH_SAMPLES + c] = map.height(p.x, p.z) - root.y;
        }
    }
    out
}

/// Writes `map` to `path` (the JSON header) and the raw `f32` data beside it (`path` with
/// extension `f32`).
pub fn write(map: &Heightmap, path: &Path) -> Result<(), TerrainFileError> {
    let data_path = path.with_extension("f32");
    let header = Header {
        format: "zoo-heightfield".into(),
        version: 1,
        nx: map.cols,
        nz: map.rows,
        cell: map.cell,
        origin_x: map.origin[0],
        origin_z: map.origin[1],
        units: "cm".into(),
        data: data_path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    };
    let text = serde_json::to_string_pretty(&header).expect("header serialises");
    zoo_motion::finite::check_values(&path.display().to_string(), "heights", &map.heights)
        .map_err(|e| io_err(path)(e.into()))?;
    let mut bytes = Vec::with_capacity(map.heights.len() * 4);
    for h in &map.heights {
        bytes.extend_from_slice(&h.to_le_bytes());
    }
    // The heights before the header that names them: a reader never finds a header without them.
    zoo_format::atomic::write(&data_path, bytes).map_err(io_err(&data_path))?;
    zoo_format::atomic::write(path, text).map_err(io_err(path))
}

/// The largest sample spacing of a heightmap file, clip units (10 km in cm).
pub const MAX_CELL: f64 = 1e6;
/// The smallest sample spacing of a heightmap file, clip units (0.01 mm in cm): below it a
/// lookup's cell index overflows and the height is NaN.
pub const MIN_CELL: f64 = 1e-3;
/// The largest origin coordinate of a heightmap file, clip units either way (10,000 km in cm).
pub const MAX_ORIGIN: f64 = 1e9;
/// The most samples of a heightmap file (1 GB of heights).
pub const MAX_SAMPLES: usize = 1 << 28;

/// Reads a heightmap written by [`write`] (give the `.json` header): the cell, origin and
/// heights range-checked (finite, a cell in [[`MIN_CELL`], [`MAX_CELL`]], an origin within
/// +-[`MAX_ORIGIN`], at most [`MAX_SAMPLES`] samples); the data file's size is checked before
/// it is read.
pub fn read(path: &Path) -> Result<Heightmap, TerrainFileError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let (header, expected) = parse_header(path, &text)?;
    let data_path = path.with_file_name(&header.data);
    let found = std::fs::metadata(&data_path).map_err(io_err(&data_path))?.len();
    if found != expected as u64 {
        return Err(size_error(&header, data_path, expected, usize::try_from(found).unwrap_or(usize::MAX)));
    }
    let bytes = std::fs::read(&data_path).map_err(io_err(&data_path))?;
    heightmap(header, expected, data_path, &bytes)
}

/// A heightmap from the text of its `.json` header (`path`, named in errors) and the bytes of
/// its data file, with the checks of [`read`].
pub fn parse(path: &Path, header: &str, data: &[u8]) -> Result<Heightmap, TerrainFileError> {
    let (header, expected) = parse_header(path, header)?;
    let data_path = path.with_file_name(&header.data);
    heightmap(header, expected, data_path, data)
}

/// The checked header and the size of its data file in bytes.
fn parse_header(path: &Path, text: &str) -> Result<(Header, usize), TerrainFileError> {
    let header: Header = serde_json::from_str(text)
        .map_err(|e| TerrainFileError::Header { path: path.to_path_buf(), message: e.to_string() })?;
    if header.format != "zoo-heightfield" || header.version != 1 {
        return Err(TerrainFileError::Header {
            path: path.to_path_buf(),
            message: format!(
                "format `{}` version {}, expected `zoo-heightfield` version 1",
                header.format, header.version
            ),
        });
    }
    let bad = |message: String| TerrainFileError::Header { path: path.to_path_buf(), message };
    // Range checks like the command line's: a cell of 0 or NaN makes every lookup NaN or
    // infinite, a huge grid asks for terabytes.
    if !(header.cell.is_finite() && (MIN_CELL..=MAX_CELL).contains(&header.cell)) {
        return Err(bad(format!(
            "`cell` is {:?}; give the sample spacing in clip units, in [{MIN_CELL}, {MAX_CELL}]",
            header.cell
        )));
    }
    for (key, v) in [("origin_x", header.origin_x), ("origin_z", header.origin_z)] {
        if !(v.is_finite() && v.abs() <= MAX_ORIGIN) {
            return Err(bad(format!(
                "`{key}` is {v:?}; give the origin in clip units, in [-{MAX_ORIGIN}, {MAX_ORIGIN}]"
            )));
        }
    }
    if header.nx == 0 || header.nz == 0 {
        return Err(bad(format!(
            "a grid of {} x {} samples holds no height: give at least 1 sample in each direction",
            header.nx, header.nz
        )));
    }
    let expected =
        header.nx.checked_mul(header.nz).filter(|n| *n <= MAX_SAMPLES).map(|n| n * 4).ok_or_else(|| {
            bad(format!("{} x {} samples: at most {MAX_SAMPLES} samples in all", header.nx, header.nz))
        })?;
    Ok((header, expected))
}

fn size_error(header: &Header, path: PathBuf, expected: usize, found: usize) -> TerrainFileError {
    TerrainFileError::Size { path, expected, found, nx: header.nx, nz: header.nz }
}

/// The heights of a checked header from its data file's bytes.
fn heightmap(header: Header, expected: usize, data_path: PathBuf, bytes: &[u8]) -> Result<Heightmap, TerrainFileError> {
    if bytes.len() != expected || expected == 0 {
        return Err(size_error(&header, data_path, expected, bytes.len()));
    }
    let heights: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    if let Some(i) = heights.iter().position(|h| !h.is_finite()) {
        return Err(TerrainFileError::Header {
            path: data_path,
            message: format!(
                "height {i} (column {}, row {}) is {}; every height must be a finite number",
                i % header.nx,
                i / header.nx,
                heights[i]
            ),
        });
    }
    Ok(Heightmap {
        cols: header.nx,
        rows: header.nz,
        cell: header.cell,
        origin: [header.origin_x, header.origin_z],
        heights,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_patch_is_relative_and_rotated() {
        let map = Heightmap::from_fn(-300.0, -300.0, 300.0, 300.0, 5.0, |x, _| 0.2 * x);
        let root = DVec3::new(0.0, 90.0, 0.0);
        let p = local_patch(&map, root, DQuat::IDENTITY);
        // Centre sample: 0 - 90. Column 12 is +103 cm along +X.
        assert!((p[6 * 13 + 6] + 90.0).abs() < 1e-4);
        assert!((p[6 * 13 + 12] - (0.2 * 103.0 - 90.0)).abs() < 1e-3);
        // Facing +X (yaw 90 deg): local +Z points along world +X, so rows now climb.
        let q = DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2);
        let p = local_patch(&map, root, q);
        assert!((p[12 * 13 + 6] - (0.2 * 103.0 - 90.0)).abs() < 1e-3);
    }

    #[test]
    fn file_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let map = Heightmap::from_fn(-20.0, 10.0, 30.0, 40.0, 10.0, |x, z| x * z * 0.01);
        let path = dir.path().join("t.json");
        write(&map, &path).unwrap();
        assert_eq!(read(&path).unwrap(), map);
    }

    #[test]
    fn bad_cells_grids_and_heights_are_refused_with_the_range() {
        let dir = tempfile::tempdir().unwrap();
        let map = Heightmap::flat_area(0.0, 0.0, 20.0, 10.0, 10.0, 1.0);
        let path = dir.path().join("t.json");
        write(&map, &path).unwrap();
        let header = std::fs::read_to_string(&path).unwrap();
        let with = |from: &str, to: &str| {
            let p = dir.path().join("bad.json");
            let text = header.replace(from, to);
            assert_ne!(text, header, "{from}");
            std::fs::write(&p, text).unwrap();
            read(&p).unwrap_err().to_string()
        };
        for cell in ["0.0", "-10.0", "1e300", "1e-300", "0.0009"] {
            assert!(with("\"cell\": 10.0", &format!("\"cell\": {cell}")).contains("give the sample spacing"), "{cell}");
        }
        assert!(with("\"nx\": 3", "\"nx\": 18446744073709551615").contains("at most 268435456 samples"));
        let e = with("\"cell\": 10.0", "\"cell\": 1e-300");
        assert!(e.contains("`cell` is 1e-300; give the sample spacing in clip units, in [0.001, 1000000]"), "{e}");
        let e = with("\"origin_x\": 0.0", "\"origin_x\": -1e300");
        assert!(e.contains("`origin_x` is -1e300; give the origin in clip units, in [-1000000000, 1000000000]"), "{e}");
        let e = with("\"origin_z\": 0.0", "\"origin_z\": 2e9");
        assert!(e.contains("`origin_z` is 2000000000.0"), "{e}");
        // At the bounds: reads, and a lookup anywhere within the origin's range is finite.
        let p = dir.path().join("edge.json");
        std::fs::write(
            &p,
            header.replace("\"cell\": 10.0", "\"cell\": 0.001").replace("\"origin_x\": 0.0", "\"origin_x\": 1e9"),
        )
        .unwrap();
        std::fs::copy(path.with_extension("f32"), p.with_extension("f32")).unwrap();
        let m = read(&p).unwrap();
        for x in [-1e9, 0.0, 1e9, 3e9] {
            assert!(m.height(x, -1e9).is_finite() && m.sample(x as f32, 1e9).is_finite(), "{x}");
        }
        let mut heights = vec![0u8; 24];
        heights[8..12].copy_from_slice(&f32::NAN.to_le_bytes());
        std::fs::write(path.with_extension("f32"), heights).unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(e.contains("height 2 (column 2, row 0) is NaN"), "{e}");
    }

    #[test]
    fn parse_reads_a_header_and_its_bytes_with_the_checks_of_read() {
        let dir = tempfile::tempdir().unwrap();
        let map = Heightmap::from_fn(-20.0, 10.0, 30.0, 40.0, 10.0, |x, z| x * z * 0.01);
        let path = dir.path().join("t.json");
        write(&map, &path).unwrap();
        let (header, data) =
            (std::fs::read_to_string(&path).unwrap(), std::fs::read(path.with_extension("f32")).unwrap());
        assert_eq!(parse(&path, &header, &data).unwrap(), map);
        let e = parse(&path, &header, &data[..data.len() - 1]).unwrap_err().to_string();
        assert!(e.contains("t.f32: expected 96 bytes (6 x 4 little-endian f32), found 95"), "{e}");
    }

    #[test]
    fn truncated_data_file_is_refused_with_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let map = Heightmap::flat_area(0.0, 0.0, 20.0, 10.0, 10.0, 1.0);
        let path = dir.path().join("t.json");
        write(&map, &path).unwrap();
        std::fs::write(path.with_extension("f32"), [0u8; 5]).unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(e.contains("expected 24 bytes (3 x 2 little-endian f32), found 5"), "{e}");
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
