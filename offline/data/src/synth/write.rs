//! Writing synthetic clips: BVH, terrain files and the `synth.json` manifest.

use super::{Gait, Style, SynthClip, SynthConfig, TerrainKind};
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

#[derive(Serialize)]
struct ManifestEntry<'a> {
    name: &'a str,
    bvh: String,
    gait: Gait,
    terrain_kind: TerrainKind,
    terrain: Option<String>,
    frames: usize,
    /// One character per frame, `1` when the left foot is planted.
    contacts_left: String,
    /// One character per frame, `1` when the right foot is planted.
    contacts_right: String,
    style: &'a Style,
}

#[derive(Serialize)]
struct Manifest<'a> {
    format: &'static str,
    version: u32,
    config: &'a SynthConfig,
    clips: Vec<ManifestEntry<'a>>,
}

/// Writes `clips` into `dir` (created if needed): `NAME.bvh` per clip, `NAME.terrain.json` +
/// `NAME.terrain.f32` when it has terrain (see [`crate::terrain`] for the format), and
/// `synth.json`, a manifest with each clip's gait, terrain, style and per-frame contacts.
/// Files are written in parallel; `progress` is called once per clip written.
pub fn write_dir(
    clips: &[SynthClip],
    cfg: &SynthConfig,
    dir: &Path,
    progress: &(dyn Fn() + Sync),
) -> Result<(), SynthWriteError> {
    std::fs::create_dir_all(dir).map_err(|source| SynthWriteError::Io { path: dir.to_path_buf(), source })?;
    clips.par_iter().try_for_each(|c| -> Result<(), SynthWriteError> {
        let path = dir.join(format!("{}.bvh", c.name));
        crate::bvh::write_file(&c.clip, &path).map_err(|source| SynthWriteError::Io { path, source })?;
        if let Some(t) = &c.terrain {
            crate::terrain::write(t, &dir.join(format!("{}.terrain.json", c.name)))?;
        }
        progress();
        Ok(())
    })?;
    let bits = |c: &SynthClip, side: usize| c.contacts.iter().map(|k| if k[side] { '1' } else { '0' }).collect();
    let manifest = Manifest {
        format: "zoo-synth",
        version: 1,
        config: cfg,
        clips: clips
            .iter()
            .map(|c| ManifestEntry {
                name: &c.name,
                bvh: format!("{}.bvh", c.name),
                gait: c.gait,
                terrain_kind: c.terrain_kind,
                terrain: c.terrain.as_ref().map(|_| format!("{}.terrain.json", c.name)),
                frames: c.clip.frames(),
                contacts_left: bits(c, 0),
                contacts_right: bits(c, 1),
                style: &c.style,
            })
            .collect(),
    };
    let path = dir.join("synth.json");
    let invalid =
        |path: &Path, e: String| SynthWriteError::Io { path: path.to_path_buf(), source: std::io::Error::other(e) };
    zoo_motion::finite::check_serialize("the synthetic data's manifest", &manifest)
        .map_err(|e| invalid(&path, e.to_string()))?;
    let text = serde_json::to_string(&manifest).map_err(|e| invalid(&path, e.to_string()))?;
    zoo_format::atomic::write(&path, text).map_err(|source| SynthWriteError::Io { path, source })
}

/// Why synthetic data could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SynthWriteError {
    /// A file or folder could not be written.
    #[error("{path}: cannot write: {source}")]
    Io {
        /// File or folder.
        path: std::path::PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A heightmap could not be written.
    #[error(transparent)]
    Terrain(#[from] crate::terrain::TerrainFileError),
}
