//! Portable exports (`zoo export --portable`): the main (step) graph in one `.onnx` file and the
//! graphs a regular file embeds as base64 metadata (the transition start graph, the RNN-GMM
//! refiner) in files of their own beside it, every graph written with the operators Unity
//! Inference Engine 2.3 documents (see `docs/portable-export.md`).
//!
//! The main file names each companion file under a `<key>.file` metadata entry (a bare file
//! name, resolved against the main file's folder), e.g. `zoo.start_graph.file` =
//! `rtn.start.onnx`. [`assemble`] puts the companions back into the metadata, giving the
//! bytes of the equivalent one-file model, which every loader of this crate reads
//! ([`load`] for [`LoadedModel`]; `SynthesisModel::from_bytes`, `MotionModel::from_bytes`).

use crate::error::MotionError;
use crate::loaded::LoadedModel;
use crate::metadata::keys;
use crate::metadata::synthesis::REFINER_GRAPH_KEY;
use std::path::Path;

/// Metadata key of the portable main file describing the profile (informational JSON:
/// operator list, version, opset, fixed dimensions).
pub const PORTABLE_KEY: &str = "zoo.portable";

/// Key of the start graph's file name in a portable main file.
pub const START_GRAPH_FILE_KEY: &str = "zoo.start_graph.file";
/// Key of the RNN-GMM refiner graph's file name in a portable main file.
pub const REFINER_GRAPH_FILE_KEY: &str = "zoo.rnngmm.refiner_graph.file";

/// A graph a regular file embeds and a portable export writes as its own file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortableGraph {
    /// The metadata key of the base64 graph in a regular file.
    pub key: &'static str,
    /// The metadata key of its file name in a portable main file.
    pub file_key: &'static str,
    /// The file name's infix: main `NAME.onnx`, companion `NAME.<suffix>.onnx`.
    pub suffix: &'static str,
}

/// Every embedded graph of the format, with its portable file key and infix.
pub const PORTABLE_GRAPHS: [PortableGraph; 2] = [
    PortableGraph { key: keys::START_GRAPH, file_key: START_GRAPH_FILE_KEY, suffix: "start" },
    PortableGraph { key: REFINER_GRAPH_KEY, file_key: REFINER_GRAPH_FILE_KEY, suffix: "refiner" },
];

/// Reads a portable main file and the companion files it names; returns the bytes of the
/// equivalent one-file model (each companion base64-encoded under its regular key). A regular
/// file comes back unchanged.
pub fn assemble(path: impl AsRef<Path>) -> Result<Vec<u8>, MotionError> {
    use base64::Engine as _;
    use prost::Message as _;
    let path = path.as_ref();
    let io = |p: &Path| {
        let p = p.display().to_string();
        move |source| MotionError::Io { path: p, source }
    };
    let bytes = std::fs::read(path).map_err(io(path))?;
    let mut proto = tract_onnx::pb::ModelProto::decode(&bytes[..])
        .map_err(|e| MotionError::NotOnnx { origin: path.display().to_string(), reason: e.to_string() })?;
    let mut changed = false;
    for g in PORTABLE_GRAPHS {
        let Some(i) = proto.metadata_props.iter().position(|p| p.key == g.file_key) else { continue };
        let name = proto.metadata_props.remove(i).value;
        let bad = |reason: String| MotionError::from(crate::metadata::FormatError::bad(g.file_key, reason));
        if Path::new(&name).file_name().is_none_or(|n| n != name.as_str()) {
            return Err(bad(format!("`{name}` is not a bare file name beside the main file")));
        }
        if proto.metadata_props.iter().any(|p| p.key == g.key) {
            return Err(bad(format!("the file also embeds `{}`; keep one of the two", g.key)));
        }
        let companion_path = path.with_file_name(&name);
        let companion = std::fs::read(&companion_path).map_err(|source| {
            bad(format!(
                "cannot read {} ({source}); keep the files `zoo export --portable` wrote together",
                companion_path.display()
            ))
        })?;
        tract_onnx::pb::ModelProto::decode(&companion[..]).map_err(|e| MotionError::NotOnnx {
            origin: companion_path.display().to_string(),
            reason: e.to_string(),
        })?;
        proto.metadata_props.push(tract_onnx::pb::StringStringEntryProto {
            key: g.key.to_string(),
            value: base64::engine::general_purpose::STANDARD.encode(&companion),
        });
        changed = true;
    }
    Ok(if changed { proto.encode_to_vec() } else { bytes })
}

/// Loads a portable export (or a regular file) with [`LoadedModel`].
pub fn load(path: impl AsRef<Path>) -> Result<LoadedModel, MotionError> {
    LoadedModel::from_bytes(&assemble(path)?)
}
