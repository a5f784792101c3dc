//! Summaries of ONNX models: inputs, outputs, op counts, parameters and metadata keys.

use crate::pb;
use serde::Serialize;
use std::collections::BTreeMap;

/// A summary of an ONNX graph: what an engine binds, and what it runs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct GraphSummary {
    /// Graph name.
    pub name: String,
    /// IR version.
    pub ir_version: i64,
    /// Default-domain opset.
    pub opset: i64,
    /// Graph inputs as `name: [dims]`.
    pub inputs: Vec<String>,
    /// Graph outputs as `name: [dims]`.
    pub outputs: Vec<String>,
    /// Number of nodes of each op type.
    pub op_counts: BTreeMap<String, usize>,
    /// Number of initializers.
    pub initializers: usize,
    /// Number of weights over all f32, f16 and int8 initializers (an int8 weight's scales and
    /// the int8 products' shared constants not counted).
    pub parameters: usize,
    /// metadata_props keys.
    pub metadata_keys: Vec<String>,
}

/// Summarizes any ONNX model proto (also ones not built by this crate).
pub fn summarize(proto: &pb::ModelProto) -> GraphSummary {
    let graph = proto.graph.clone().unwrap_or_default();
    let describe = |v: &pb::ValueInfoProto| {
        use pb::tensor_shape_proto::dimension;
        let dims: Vec<String> = match &v.r#type {
            Some(pb::TypeProto { value: Some(pb::type_proto::Value::TensorType(t)), .. }) => t
                .shape
                .as_ref()
                .map(|s| {
                    s.dim
                        .iter()
                        .map(|d| match &d.value {
                            Some(dimension::Value::DimValue(n)) => n.to_string(),
                            Some(dimension::Value::DimParam(p)) => p.clone(),
                            None => "?".to_string(),
                        })
                        .collect()
                })
                .unwrap_or_default(),
            _ => vec![],
        };
        format!("{}: [{}]", v.name, dims.join(", "))
    };
    let mut op_counts = BTreeMap::new();
    for n in &graph.node {
        *op_counts.entry(n.op_type.clone()).or_insert(0) += 1;
    }
    use pb::tensor_proto::DataType;
    let widths = [DataType::Float as i32, DataType::Float16 as i32, DataType::Int8 as i32, DataType::Uint8 as i32];
    let int8 = |name: &str| graph.initializer.iter().any(|t| t.name == format!("{name}.int8"));
    let parameters = graph
        .initializer
        .iter()
        .filter(|t| widths.contains(&t.data_type))
        .filter(|t| {
            !t.name.strip_suffix(".scale").is_some_and(int8) && !t.name.starts_with(crate::width::SHARED_PREFIX)
        })
        .map(|t| t.dims.iter().product::<i64>() as usize)
        .sum();
    GraphSummary {
        name: graph.name.clone(),
        ir_version: proto.ir_version,
        opset: proto.opset_import.iter().find(|o| o.domain.is_empty()).map_or(0, |o| o.version),
        inputs: graph.input.iter().map(describe).collect(),
        outputs: graph.output.iter().map(describe).collect(),
        op_counts,
        initializers: graph.initializer.len(),
        parameters,
        metadata_keys: proto.metadata_props.iter().map(|p| p.key.clone()).collect(),
    }
}
