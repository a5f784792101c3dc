//! A finished ONNX model: encoding, decoding and writing.

use crate::error::ExportError;
use crate::pb;
use crate::summary::{GraphSummary, summarize};
use prost::Message;
use std::path::Path;

/// A finished ONNX model.
#[derive(Clone, Debug)]
pub struct OnnxModel {
    pub(crate) proto: pb::ModelProto,
}

impl OnnxModel {
    /// Wraps a model proto (e.g. one edited after building).
    pub fn from_proto(proto: pb::ModelProto) -> Self {
        OnnxModel { proto }
    }

    /// Decodes an encoded ONNX model (e.g. a file written by [`OnnxModel::write`]).
    /// `origin` names the bytes in the error (a file path, a metadata key).
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, ExportError> {
        pb::ModelProto::decode(bytes)
            .map(OnnxModel::from_proto)
            .map_err(|e| ExportError::NotOnnx { origin: origin.to_string(), reason: e.to_string() })
    }

    /// Decodes a model embedded as standard base64 (the inverse of [`OnnxModel::to_base64`]).
    pub fn from_base64(encoded: &str, origin: &str) -> Result<Self, ExportError> {
        use base64::Engine;
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(encoded.trim())
            .map_err(|e| ExportError::NotOnnx { origin: origin.to_string(), reason: format!("not base64: {e}") })?;
        Self::from_bytes(&bytes, origin)
    }

    /// The value of metadata_props entry `key`, if present.
    pub fn metadata_value(&self, key: &str) -> Option<&str> {
        self.proto.metadata_props.iter().find(|p| p.key == key).map(|p| p.value.as_str())
    }

    /// Sets metadata_props entry `key` to `value` (replacing an entry of the same key).
    pub fn set_metadata(&mut self, key: &str, value: &str) {
        match self.proto.metadata_props.iter_mut().find(|p| p.key == key) {
            Some(p) => p.value = value.to_string(),
            None => self.proto.metadata_props.push(pb::StringStringEntryProto { key: key.into(), value: value.into() }),
        }
    }

    /// Removes metadata_props entry `key`; returns its value, if it was there.
    pub fn remove_metadata(&mut self, key: &str) -> Option<String> {
        let i = self.proto.metadata_props.iter().position(|p| p.key == key)?;
        Some(self.proto.metadata_props.remove(i).value)
    }

    /// The prost model.
    pub fn proto(&self) -> &pb::ModelProto {
        &self.proto
    }

    /// The model encoded as an ONNX protobuf.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.proto.encode_to_vec()
    }

    /// The encoded model as standard base64, to embed one graph in another model's
    /// metadata_props (the runtime's `zoo.start_graph`: one file carries both graphs).
    pub fn to_base64(&self) -> String {
        use base64::Engine;
        base64::engine::general_purpose::STANDARD.encode(self.to_bytes())
    }

    /// Writes the encoded model to `path` atomically: to a temporary file in the same folder,
    /// then renamed into place, so an interrupted write never leaves a truncated model. A float
    /// initializer holding NaN or infinity (any graph, subgraphs included) is refused.
    pub fn write(&self, path: &Path) -> Result<(), ExportError> {
        let io = |source| ExportError::Io { path: path.display().to_string(), source };
        if let Some(g) = &self.proto.graph {
            check_initializers(g).map_err(|e| io(e.into()))?;
        }
        zoo_format::atomic::write(path, self.to_bytes()).map_err(io)
    }

    /// Inputs, outputs and op counts, for snapshots and logs.
    pub fn summary(&self) -> GraphSummary {
        summarize(&self.proto)
    }
}

/// The float initializers of `graph` and of its subgraphs (Scan bodies) are finite.
fn check_initializers(graph: &pb::GraphProto) -> Result<(), zoo_motion::finite::NonFinite> {
    for t in graph.initializer.iter().filter(|t| t.data_type == pb::tensor_proto::DataType::Float as i32) {
        let raw = t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        let values: Vec<f32> = t.float_data.iter().copied().chain(raw).collect();
        zoo_motion::finite::check_values("the exported model", &format!("initializer `{}`", t.name), &values)?;
    }
    for a in graph.node.iter().flat_map(|n| &n.attribute) {
        for g in a.g.iter().chain(&a.graphs) {
            check_initializers(g)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Dim, GraphBuilder};

    fn tiny() -> OnnxModel {
        let mut g = GraphBuilder::new("tiny");
        let x = g.input("x", &[Dim::batch(), Dim::Fixed(2)]);
        g.output("y", &x, &[Dim::batch(), Dim::Fixed(2)]);
        g.metadata("k", "v");
        g.finish().unwrap()
    }

    #[test]
    fn bytes_base64_and_file_round_trip() {
        let m = tiny();
        assert_eq!(OnnxModel::from_bytes(&m.to_bytes(), "bytes").unwrap().proto(), m.proto());
        assert_eq!(OnnxModel::from_base64(&m.to_base64(), "b64").unwrap().proto(), m.proto());
        assert_eq!(m.metadata_value("k"), Some("v"));
        assert_eq!(m.metadata_value("missing"), None);
        let mut edited = m.clone();
        edited.set_metadata("k", "w");
        edited.set_metadata("k2", "x");
        assert_eq!((edited.metadata_value("k"), edited.metadata_value("k2")), (Some("w"), Some("x")));
        assert_eq!(edited.remove_metadata("k").as_deref(), Some("w"));
        assert_eq!(edited.metadata_value("k"), None);
        assert_eq!(edited.remove_metadata("k"), None);
        let dir = std::env::temp_dir().join(format!("zoo-export-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("tiny.onnx");
        m.write(&path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), m.to_bytes());
        assert!(!dir.join(".tiny.onnx.tmp").exists(), "the temporary file is renamed into place");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn garbage_is_not_a_model() {
        let err = OnnxModel::from_bytes(b"HIERARCHY ROOT Hips", "walk.bvh").unwrap_err();
        assert!(matches!(&err, ExportError::NotOnnx { origin, .. } if origin == "walk.bvh"), "{err}");
        let err = OnnxModel::from_base64("@@not base64@@", "zoo.start_graph").unwrap_err();
        assert!(err.to_string().contains("not base64"), "{err}");
    }

    #[test]
    fn writing_into_a_missing_folder_is_an_io_error() {
        let err = tiny().write(Path::new("/nonexistent/folder/m.onnx")).unwrap_err();
        assert!(matches!(err, ExportError::Io { .. }), "{err}");
    }
}
