//! The graph builder: values, inputs, outputs, initializers, metadata and the finished model.

use crate::error::ExportError;
use crate::model::OnnxModel;
use crate::{BATCH_DIM, IR_VERSION, OPSET, pb};
use std::collections::{HashMap, HashSet};

/// One dimension of a graph input or output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Dim {
    /// A fixed size.
    Fixed(usize),
    /// A named symbolic size (the same name means the same size everywhere).
    Symbol(String),
}

impl Dim {
    /// The symbolic batch dimension [`BATCH_DIM`].
    pub fn batch() -> Dim {
        Dim::Symbol(BATCH_DIM.to_string())
    }
}

impl std::fmt::Display for Dim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Dim::Fixed(n) => write!(f, "{n}"),
            Dim::Symbol(s) => write!(f, "{s}"),
        }
    }
}

/// A value of the graph under construction (a graph input, an initializer or a node output).
///
/// Values are referred to by name; cloning one is cheap enough for graph building.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Value(pub(crate) String);

impl Value {
    /// The value's name in the ONNX graph.
    pub fn name(&self) -> &str {
        &self.0
    }
}

/// Builds one ONNX graph and model. See the crate documentation for an example.
#[derive(Debug)]
pub struct GraphBuilder {
    name: String,
    nodes: Vec<pb::NodeProto>,
    initializers: Vec<pb::TensorProto>,
    inputs: Vec<pb::ValueInfoProto>,
    outputs: Vec<pb::ValueInfoProto>,
    metadata: Vec<(String, String)>,
    doc: String,
    /// Every value name produced so far (inputs, initializers, node outputs).
    values: HashSet<String>,
    node_names: HashSet<String>,
    /// Shapes of initializers, for argument checks of op helpers.
    pub(crate) init_shapes: HashMap<String, Vec<usize>>,
    error: Option<ExportError>,
}

impl GraphBuilder {
    /// An empty graph called `name`.
    pub fn new(name: &str) -> Self {
        GraphBuilder {
            name: name.to_string(),
            nodes: Vec::new(),
            initializers: Vec::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            metadata: Vec::new(),
            doc: String::new(),
            values: HashSet::new(),
            node_names: HashSet::new(),
            init_shapes: HashMap::new(),
            error: None,
        }
    }

    /// A builder holding the inputs, outputs and initializers of an existing graph, but none of
    /// its nodes: the portable pass replays them with [`GraphBuilder::push_node`].
    #[cfg_attr(not(feature = "portable"), allow(dead_code))]
    pub(crate) fn from_graph(graph: &pb::GraphProto) -> Self {
        let mut g = GraphBuilder::new(&graph.name);
        g.doc = graph.doc_string.clone();
        for input in &graph.input {
            g.new_value(&input.name);
            g.inputs.push(input.clone());
        }
        for init in &graph.initializer {
            if !g.values.contains(&init.name) {
                g.new_value(&init.name);
            }
            g.init_shapes.insert(init.name.clone(), init.dims.iter().map(|&d| d.max(0) as usize).collect());
            g.initializers.push(init.clone());
        }
        g.outputs = graph.output.clone();
        g
    }

    /// Appends an existing node as is (its inputs must exist; its outputs become values).
    #[cfg_attr(not(feature = "portable"), allow(dead_code))]
    pub(crate) fn push_node(&mut self, node: pb::NodeProto) {
        if !node.name.is_empty() && !self.node_names.insert(node.name.clone()) {
            self.fail(ExportError::DuplicateName(node.name.clone()));
        }
        for input in node.input.iter().filter(|i| !i.is_empty()) {
            if !self.values.contains(input) {
                self.fail(ExportError::UnknownValue { node: node.name.clone(), value: input.clone() });
            }
        }
        for output in node.output.iter().filter(|o| !o.is_empty()) {
            self.new_value(output);
        }
        self.nodes.push(node);
    }

    pub(crate) fn fail(&mut self, e: ExportError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
    }

    fn new_value(&mut self, name: &str) -> Value {
        if !self.values.insert(name.to_string()) {
            self.fail(ExportError::DuplicateName(name.to_string()));
        }
        Value(name.to_string())
    }

    /// Sets the model's doc string.
    pub fn doc(&mut self, doc: &str) -> &mut Self {
        self.doc = doc.to_string();
        self
    }

    /// Adds a string key/value pair to the model's `metadata_props`.
    pub fn metadata(&mut self, key: &str, value: &str) -> &mut Self {
        if let Some(entry) = self.metadata.iter_mut().find(|(k, _)| k == key) {
            entry.1 = value.to_string();
        } else {
            self.metadata.push((key.to_string(), value.to_string()));
        }
        self
    }

    /// Declares an f32 graph input of the given dimensions.
    pub fn input(&mut self, name: &str, dims: &[Dim]) -> Value {
        let v = self.new_value(name);
        self.inputs.push(value_info(name, dims));
        v
    }

    /// Declares `value` as an f32 graph output called `name` with the given dimensions.
    /// When `value` has another name an `Identity` node renames it.
    pub fn output(&mut self, name: &str, value: &Value, dims: &[Dim]) -> Value {
        let out = if value.0 == name { value.clone() } else { self.node("Identity", name, &[value], vec![]) };
        self.outputs.push(value_info(name, dims));
        out
    }

    /// An f32 initializer (a constant weight) of shape `dims` from row-major `data`.
    pub fn initializer_f32(&mut self, name: &str, dims: &[usize], data: &[f32]) -> Value {
        let raw: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.initializer(name, dims, data.len(), pb::tensor_proto::DataType::Float, raw)
    }

    /// An i64 initializer (indices, axes, shapes) of shape `dims` from row-major `data`.
    pub fn initializer_i64(&mut self, name: &str, dims: &[usize], data: &[i64]) -> Value {
        let raw: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.initializer(name, dims, data.len(), pb::tensor_proto::DataType::Int64, raw)
    }

    /// An initializer of `len` values of type `data_type`, little-endian in `raw`.
    fn initializer(
        &mut self,
        name: &str,
        dims: &[usize],
        len: usize,
        data_type: pb::tensor_proto::DataType,
        raw: Vec<u8>,
    ) -> Value {
        let expected: usize = dims.iter().product();
        if expected != len {
            self.fail(ExportError::ShapeMismatch { name: name.to_string(), dims: dims.to_vec(), expected, found: len });
        }
        let v = self.new_value(name);
        self.initializers.push(pb::TensorProto {
            name: name.to_string(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: data_type as i32,
            raw_data: raw,
            ..Default::default()
        });
        self.init_shapes.insert(name.to_string(), dims.to_vec());
        v
    }

    /// Shape of an initializer created by this builder.
    pub fn initializer_shape(&self, value: &Value) -> Option<&[usize]> {
        self.init_shapes.get(&value.0).map(|s| s.as_slice())
    }

    pub(crate) fn i64_vector(&mut self, node: &str, suffix: &str, data: &[i64]) -> Value {
        self.initializer_i64(&format!("{node}.{suffix}"), &[data.len()], data)
    }

    /// A node with one output named like the node.
    pub(crate) fn node(&mut self, op: &str, name: &str, inputs: &[&Value], attrs: Vec<pb::AttributeProto>) -> Value {
        let outs = self.node_multi(op, name, inputs, &[name.to_string()], attrs);
        outs.into_iter().next().expect("one output")
    }

    /// A node with the given input names (an empty name is an omitted optional input) and
    /// output value names.
    pub(crate) fn node_multi(
        &mut self,
        op: &str,
        name: &str,
        inputs: &[&Value],
        outputs: &[String],
        attrs: Vec<pb::AttributeProto>,
    ) -> Vec<Value> {
        if !self.node_names.insert(name.to_string()) {
            self.fail(ExportError::DuplicateName(name.to_string()));
        }
        for input in inputs {
            if !input.0.is_empty() && !self.values.contains(&input.0) {
                self.fail(ExportError::UnknownValue { node: name.to_string(), value: input.0.clone() });
            }
        }
        let outs: Vec<Value> = outputs.iter().map(|o| self.new_value(o)).collect();
        self.nodes.push(pb::NodeProto {
            name: name.to_string(),
            op_type: op.to_string(),
            input: inputs.iter().map(|v| v.0.clone()).collect(),
            output: outputs.to_vec(),
            attribute: attrs,
            ..Default::default()
        });
        outs
    }

    /// Any default-domain op with one output, for ops without a typed helper. Prefer the
    /// typed helpers: they only cover ops every target runtime runs.
    pub fn custom_op(&mut self, op: &str, name: &str, inputs: &[&Value], attrs: Vec<pb::AttributeProto>) -> Value {
        self.node(op, name, inputs, attrs)
    }

    /// Checks the graph and returns the model. Every recorded mistake is reported here.
    pub fn finish(self) -> Result<OnnxModel, ExportError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if self.outputs.is_empty() {
            return Err(ExportError::NoOutputs(self.name));
        }
        let graph = pb::GraphProto {
            name: self.name,
            node: self.nodes,
            initializer: self.initializers,
            input: self.inputs,
            output: self.outputs,
            ..Default::default()
        };
        let proto = pb::ModelProto {
            ir_version: IR_VERSION,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: OPSET }],
            producer_name: "zoo-export".to_string(),
            producer_version: env!("CARGO_PKG_VERSION").to_string(),
            doc_string: self.doc,
            graph: Some(graph),
            metadata_props: self
                .metadata
                .into_iter()
                .map(|(key, value)| pb::StringStringEntryProto { key, value })
                .collect(),
            ..Default::default()
        };
        Ok(OnnxModel { proto })
    }
}

fn value_info(name: &str, dims: &[Dim]) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{Dimension, dimension};
    let dim = dims
        .iter()
        .map(|d| Dimension {
            denotation: String::new(),
            value: Some(match d {
                Dim::Fixed(n) => dimension::Value::DimValue(*n as i64),
                Dim::Symbol(s) => dimension::Value::DimParam(s.clone()),
            }),
        })
        .collect();
    pb::ValueInfoProto {
        name: name.to_string(),
        r#type: Some(pb::TypeProto {
            denotation: String::new(),
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: pb::tensor_proto::DataType::Float as i32,
                shape: Some(pb::TensorShapeProto { dim }),
            })),
        }),
        doc_string: String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prost::Message;

    fn tiny() -> GraphBuilder {
        let mut g = GraphBuilder::new("tiny");
        let x = g.input("x", &[Dim::batch(), Dim::Fixed(2)]);
        let w = g.initializer_f32("w", &[2, 2], &[1., 2., 3., 4.]);
        let y = g.matmul("mm", &x, &w);
        g.output("y", &y, &[Dim::batch(), Dim::Fixed(2)]);
        g
    }

    #[test]
    fn duplicate_names_are_reported() {
        let mut g = tiny();
        let x = Value("x".into());
        g.tanh("mm", &x);
        assert!(matches!(g.finish(), Err(ExportError::DuplicateName(n)) if n == "mm"));
    }

    #[test]
    fn unknown_values_are_reported() {
        let mut g = tiny();
        let ghost = Value("ghost".into());
        g.tanh("t", &ghost);
        let err = g.finish().unwrap_err();
        assert!(matches!(&err, ExportError::UnknownValue { value, .. } if value == "ghost"), "{err}");
    }

    #[test]
    fn initializer_shape_mismatch_is_reported() {
        let mut g = tiny();
        g.initializer_f32("bad", &[3, 2], &[0.0; 5]);
        let err = g.finish().unwrap_err();
        assert!(err.to_string().contains("bad") && err.to_string().contains("6 values"), "{err}");
    }

    #[test]
    fn a_graph_without_outputs_is_refused() {
        let mut g = GraphBuilder::new("empty");
        g.input("x", &[Dim::Fixed(1)]);
        assert!(matches!(g.finish(), Err(ExportError::NoOutputs(_))));
    }

    #[test]
    fn model_header_and_summary() {
        let mut g = tiny();
        g.metadata("k", "v").metadata("k", "v2");
        let m = g.finish().unwrap();
        assert_eq!(m.proto().ir_version, 8);
        assert_eq!(m.proto().opset_import[0].version, 17);
        assert_eq!(m.proto().metadata_props.len(), 1);
        assert_eq!(m.proto().metadata_props[0].value, "v2");
        let s = m.summary();
        assert_eq!(s.inputs, vec!["x: [batch, 2]".to_string()]);
        assert_eq!(s.outputs, vec!["y: [batch, 2]".to_string()]);
        assert_eq!(s.op_counts.get("Identity"), Some(&1));
        assert_eq!(s.parameters, 4);
        let decoded = pb::ModelProto::decode(m.to_bytes().as_slice()).unwrap();
        assert_eq!(&decoded, m.proto());
    }
}
