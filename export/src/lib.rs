//! ONNX writer of zoo.
//!
//! Builds ONNX models (IR 8, default-domain opset 17) from Rust on the prost types that
//! tract-onnx ships as [`tract_onnx::pb`], and encodes them with prost. Graphs built this way
//! load in tract 0.23 and onnxruntime 1.31 (checked by `tests/parity.rs` of the workspace).
//!
//! Only the ops that tract, onnxruntime, Unity Sentis and Unreal NNE all run have helpers
//! (see `export/README.md` for the limits of each runtime). Node, value and initializer names
//! are the readable paths the caller gives (the candle variable paths for weights), so a
//! graph viewer shows `frame_encoder.linear0.weight`, not `onnx::MatMul_17`.
//!
//! Building never panics: a mistake (a duplicate name, an initializer whose data does not
//! match its shape, a reference to an unknown value) is recorded and [`GraphBuilder::finish`]
//! returns it as an [`ExportError`].
//!
//! ```
//! use zoo_export::{Dim, GraphBuilder};
//! let mut g = GraphBuilder::new("toy");
//! let x = g.input("x", &[Dim::batch(), Dim::Fixed(2)]);
//! let w = g.initializer_f32("dense.weight", &[2, 3], &[1., 0., 0., 0., 1., 0.]);
//! let b = g.initializer_f32("dense.bias", &[3], &[0.1, 0.2, 0.3]);
//! let y = g.matmul("dense.matmul", &x, &w);
//! let y = g.add("dense.add", &y, &b);
//! g.output("y", &y, &[Dim::batch(), Dim::Fixed(3)]);
//! g.metadata("zoo.format_version", "1");
//! let model = g.finish().unwrap();
//! assert_eq!(model.summary().op_counts["MatMul"], 1);
//! let bytes = model.to_bytes();
//! assert!(!bytes.is_empty());
//! ```

pub mod rtn;

use prost::Message;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

/// The prost ONNX types (`ModelProto`, `NodeProto`, ...), re-exported from tract-onnx.
pub use tract_onnx::pb;

/// ONNX IR version written into every model.
pub const IR_VERSION: i64 = 8;
/// Opset of the default ONNX domain every model imports.
pub const OPSET: i64 = 17;
/// Name of the symbolic batch dimension of graph inputs and outputs.
pub const BATCH_DIM: &str = "batch";

/// Why a graph could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Two values, nodes or initializers were given the same name.
    #[error(
        "the name `{0}` is used twice in the graph; give every node and initializer its own name (e.g. a candle variable path)"
    )]
    DuplicateName(String),
    /// A node refers to a value no input, initializer or earlier node produces.
    #[error(
        "node `{node}` reads `{value}`, which no graph input, initializer or earlier node produces; create values before using them"
    )]
    UnknownValue {
        /// The node that reads the value.
        node: String,
        /// The missing value.
        value: String,
    },
    /// Initializer data length does not match its shape.
    #[error("initializer `{name}` has shape {dims:?} ({expected} values) but {found} values were given")]
    ShapeMismatch {
        /// Initializer name.
        name: String,
        /// Declared shape.
        dims: Vec<usize>,
        /// Product of the shape.
        expected: usize,
        /// Length of the data.
        found: usize,
    },
    /// An argument of an op helper is invalid (the message says which and why).
    #[error("node `{node}`: {message}")]
    InvalidOp {
        /// The node being built.
        node: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// The graph has no outputs.
    #[error("graph `{0}` has no outputs; declare at least one with GraphBuilder::output")]
    NoOutputs(String),
    /// A model cannot be exported (missing weight, skeleton, inconsistent checkpoint).
    #[error("cannot export the model: {0}")]
    Model(String),
    /// Writing the file failed.
    #[error("cannot write ONNX file {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

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
pub struct Value(String);

impl Value {
    /// The value's name in the ONNX graph.
    pub fn name(&self) -> &str {
        &self.0
    }
}

/// Direction of an ONNX recurrent op. `reverse` is not offered: tract 0.23 ignores the
/// `direction` attribute and takes the number of directions from `W` (DEPENDENCY-FACTS),
/// so a single reverse RNN would silently run forward there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RnnDirection {
    /// One forward direction; weights have a leading dimension of 1.
    Forward,
    /// Forward and reverse; weights have a leading dimension of 2.
    Bidirectional,
}

impl RnnDirection {
    fn attr(self) -> &'static str {
        match self {
            RnnDirection::Forward => "forward",
            RnnDirection::Bidirectional => "bidirectional",
        }
    }

    /// Leading dimension of `W`, `R`, `B` and of the states.
    pub fn num_directions(self) -> usize {
        match self {
            RnnDirection::Forward => 1,
            RnnDirection::Bidirectional => 2,
        }
    }
}

/// Inputs of an ONNX `LSTM` or `GRU` node (layout 0: `X` is `[seq, batch, input]`).
#[derive(Clone, Debug)]
pub struct RnnInputs<'a> {
    /// `X`, `[seq, batch, input]`.
    pub x: &'a Value,
    /// `W`, `[dirs, gates * hidden, input]`, ONNX gate order (LSTM i,o,f,c; GRU z,r,h).
    pub w: &'a Value,
    /// `R`, `[dirs, gates * hidden, hidden]`.
    pub r: &'a Value,
    /// `B`, `[dirs, 2 * gates * hidden]` (`Wb` then `Rb`), or none for zero biases.
    pub b: Option<&'a Value>,
    /// `initial_h`, `[dirs, batch, hidden]`, or none for zeros.
    pub initial_h: Option<&'a Value>,
    /// Hidden size.
    pub hidden_size: usize,
    /// Direction.
    pub direction: RnnDirection,
}

/// Outputs of an ONNX `LSTM` or `GRU` node.
#[derive(Clone, Debug)]
pub struct RnnOutputs {
    /// `Y`, `[seq, dirs, batch, hidden]`.
    pub y: Value,
    /// `Y_h`, `[dirs, batch, hidden]`.
    pub y_h: Value,
    /// `Y_c`, `[dirs, batch, hidden]` (LSTM only; `None` for GRU).
    pub y_c: Option<Value>,
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
    init_shapes: HashMap<String, Vec<usize>>,
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

    fn fail(&mut self, e: ExportError) {
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
        let expected: usize = dims.iter().product();
        if expected != data.len() {
            self.fail(ExportError::ShapeMismatch {
                name: name.to_string(),
                dims: dims.to_vec(),
                expected,
                found: data.len(),
            });
        }
        let v = self.new_value(name);
        let raw: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.initializers.push(pb::TensorProto {
            name: name.to_string(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: pb::tensor_proto::DataType::Float as i32,
            raw_data: raw,
            ..Default::default()
        });
        self.init_shapes.insert(name.to_string(), dims.to_vec());
        v
    }

    /// An i64 initializer (indices, axes, shapes) of shape `dims` from row-major `data`.
    pub fn initializer_i64(&mut self, name: &str, dims: &[usize], data: &[i64]) -> Value {
        let expected: usize = dims.iter().product();
        if expected != data.len() {
            self.fail(ExportError::ShapeMismatch {
                name: name.to_string(),
                dims: dims.to_vec(),
                expected,
                found: data.len(),
            });
        }
        let v = self.new_value(name);
        let raw: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.initializers.push(pb::TensorProto {
            name: name.to_string(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: pb::tensor_proto::DataType::Int64 as i32,
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

    fn i64_vector(&mut self, node: &str, suffix: &str, data: &[i64]) -> Value {
        self.initializer_i64(&format!("{node}.{suffix}"), &[data.len()], data)
    }

    /// A node with one output named like the node.
    fn node(&mut self, op: &str, name: &str, inputs: &[&Value], attrs: Vec<pb::AttributeProto>) -> Value {
        let outs = self.node_multi(op, name, inputs, &[name.to_string()], attrs);
        outs.into_iter().next().expect("one output")
    }

    /// A node with the given input names (an empty name is an omitted optional input) and
    /// output value names.
    fn node_multi(
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

    /// `MatMul(a, b)` (numpy-style batched matrix product).
    pub fn matmul(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("MatMul", name, &[a, b], vec![])
    }

    /// `Gemm(a, b, c)`: `alpha * a' @ b' + beta * c`, where `'` transposes when asked.
    /// `a` and `b` are 2-D; `c` broadcasts (unidirectionally) to the result.
    pub fn gemm(&mut self, name: &str, a: &Value, b: &Value, c: Option<&Value>, trans_b: bool) -> Value {
        let mut attrs = vec![attr_float("alpha", 1.0), attr_float("beta", 1.0)];
        if trans_b {
            attrs.push(attr_int("transB", 1));
        }
        match c {
            Some(c) => self.node("Gemm", name, &[a, b, c], attrs),
            None => self.node("Gemm", name, &[a, b], attrs),
        }
    }

    /// `Add(a, b)` with numpy broadcasting.
    pub fn add(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Add", name, &[a, b], vec![])
    }

    /// `Sub(a, b)` with numpy broadcasting.
    pub fn sub(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Sub", name, &[a, b], vec![])
    }

    /// `Mul(a, b)` with numpy broadcasting.
    pub fn mul(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Mul", name, &[a, b], vec![])
    }

    /// `Div(a, b)` with numpy broadcasting.
    pub fn div(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Div", name, &[a, b], vec![])
    }

    /// `Sigmoid(x)`.
    pub fn sigmoid(&mut self, name: &str, x: &Value) -> Value {
        self.node("Sigmoid", name, &[x], vec![])
    }

    /// `Tanh(x)`.
    pub fn tanh(&mut self, name: &str, x: &Value) -> Value {
        self.node("Tanh", name, &[x], vec![])
    }

    /// `LeakyRelu(x)` with slope `alpha` for negative inputs.
    pub fn leaky_relu(&mut self, name: &str, x: &Value, alpha: f32) -> Value {
        self.node("LeakyRelu", name, &[x], vec![attr_float("alpha", alpha)])
    }

    /// `Identity(x)`.
    pub fn identity(&mut self, name: &str, x: &Value) -> Value {
        self.node("Identity", name, &[x], vec![])
    }

    /// `Concat(values, axis)`.
    pub fn concat(&mut self, name: &str, values: &[&Value], axis: i64) -> Value {
        if values.is_empty() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: "Concat needs at least one input".into(),
            });
        }
        self.node("Concat", name, values, vec![attr_int("axis", axis)])
    }

    /// `Slice(x, starts, ends, axes)` with unit steps; the index vectors become initializers
    /// `<name>.starts`, `<name>.ends`, `<name>.axes`.
    pub fn slice(&mut self, name: &str, x: &Value, axes: &[i64], starts: &[i64], ends: &[i64]) -> Value {
        if axes.len() != starts.len() || axes.len() != ends.len() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: format!(
                    "Slice needs as many starts ({}) and ends ({}) as axes ({})",
                    starts.len(),
                    ends.len(),
                    axes.len()
                ),
            });
        }
        let s = self.i64_vector(name, "starts", starts);
        let e = self.i64_vector(name, "ends", ends);
        let a = self.i64_vector(name, "axes", axes);
        self.node("Slice", name, &[x, &s, &e, &a], vec![])
    }

    /// `Gather(x, indices, axis)` with constant indices (initializer `<name>.indices`).
    pub fn gather(&mut self, name: &str, x: &Value, indices: &[i64], axis: i64) -> Value {
        let i = self.i64_vector(name, "indices", indices);
        self.node("Gather", name, &[x, &i], vec![attr_int("axis", axis)])
    }

    /// `Split(x, split, axis)` into pieces of the given sizes (initializer `<name>.split`).
    /// Outputs are named `<name>.0`, `<name>.1`, ...
    pub fn split(&mut self, name: &str, x: &Value, sizes: &[usize], axis: i64) -> Vec<Value> {
        if sizes.is_empty() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: "Split needs at least one size".into(),
            });
        }
        let sizes: Vec<i64> = sizes.iter().map(|&s| s as i64).collect();
        let s = self.i64_vector(name, "split", &sizes);
        let outs: Vec<String> = (0..sizes.len()).map(|i| format!("{name}.{i}")).collect();
        self.node_multi("Split", name, &[x, &s], &outs, vec![attr_int("axis", axis)])
    }

    /// `Reshape(x, shape)` (initializer `<name>.shape`; `0` copies a dimension, `-1` infers one).
    pub fn reshape(&mut self, name: &str, x: &Value, shape: &[i64]) -> Value {
        let s = self.i64_vector(name, "shape", shape);
        self.node("Reshape", name, &[x, &s], vec![])
    }

    /// `Unsqueeze(x, axes)` (initializer `<name>.axes`).
    pub fn unsqueeze(&mut self, name: &str, x: &Value, axes: &[i64]) -> Value {
        let a = self.i64_vector(name, "axes", axes);
        self.node("Unsqueeze", name, &[x, &a], vec![])
    }

    /// `Squeeze(x, axes)` (initializer `<name>.axes`).
    pub fn squeeze(&mut self, name: &str, x: &Value, axes: &[i64]) -> Value {
        let a = self.i64_vector(name, "axes", axes);
        self.node("Squeeze", name, &[x, &a], vec![])
    }

    /// `Transpose(x, perm)`.
    pub fn transpose(&mut self, name: &str, x: &Value, perm: &[i64]) -> Value {
        self.node("Transpose", name, &[x], vec![attr_ints("perm", perm)])
    }

    fn check_rnn(&mut self, name: &str, op: &str, gates: usize, rnn: &RnnInputs) {
        let dirs = rnn.direction.num_directions();
        let h = rnn.hidden_size;
        let checks: [(&str, Option<&Value>, usize, usize); 3] =
            [("W", Some(rnn.w), gates * h, 0), ("R", Some(rnn.r), gates * h, h), ("B", rnn.b, 2 * gates * h, 0)];
        for (label, v, rows, cols) in checks {
            let Some(shape) = v.and_then(|v| self.init_shapes.get(&v.0)).cloned() else { continue };
            let ok = shape.first() == Some(&dirs)
                && shape.get(1) == Some(&rows)
                && (cols == 0 || shape.get(2) == Some(&cols))
                && shape.len() == if label == "B" { 2 } else { 3 };
            if !ok {
                let want = match label {
                    "W" => format!("[{dirs}, {rows}, input]"),
                    "R" => format!("[{dirs}, {rows}, {cols}]"),
                    _ => format!("[{dirs}, {rows}]"),
                };
                self.fail(ExportError::InvalidOp {
                    node: name.to_string(),
                    message: format!(
                        "{op} {label} has shape {shape:?}, expected {want} for hidden size {h} and direction {} (tract takes the number of directions from W's first dimension)",
                        rnn.direction.attr()
                    ),
                });
            }
        }
    }

    /// An ONNX `LSTM` node (layout 0, gate order i,o,f,c; see [`reorder_gates`] to convert from
    /// candle/PyTorch's i,f,g,o). Outputs are `<name>.y`, `<name>.y_h`, `<name>.y_c`.
    pub fn lstm(&mut self, name: &str, rnn: &RnnInputs, initial_c: Option<&Value>) -> RnnOutputs {
        self.check_rnn(name, "LSTM", 4, rnn);
        let empty = Value(String::new());
        let inputs = [
            rnn.x,
            rnn.w,
            rnn.r,
            rnn.b.unwrap_or(&empty),
            &empty,
            rnn.initial_h.unwrap_or(&empty),
            initial_c.unwrap_or(&empty),
        ];
        let n = trailing_used(&inputs);
        let outs = [format!("{name}.y"), format!("{name}.y_h"), format!("{name}.y_c")];
        let attrs = vec![
            attr_int("hidden_size", rnn.hidden_size as i64),
            attr_string("direction", rnn.direction.attr()),
            attr_int("layout", 0),
        ];
        let mut v = self.node_multi("LSTM", name, &inputs[..n], &outs, attrs).into_iter();
        RnnOutputs { y: v.next().expect("y"), y_h: v.next().expect("y_h"), y_c: v.next() }
    }

    /// An ONNX `GRU` node (layout 0, gate order z,r,h). `linear_before_reset = true` matches
    /// candle's and PyTorch's GRU. Outputs are `<name>.y` and `<name>.y_h`.
    pub fn gru(&mut self, name: &str, rnn: &RnnInputs, linear_before_reset: bool) -> RnnOutputs {
        self.check_rnn(name, "GRU", 3, rnn);
        let empty = Value(String::new());
        let inputs = [rnn.x, rnn.w, rnn.r, rnn.b.unwrap_or(&empty), &empty, rnn.initial_h.unwrap_or(&empty)];
        let n = trailing_used(&inputs);
        let outs = [format!("{name}.y"), format!("{name}.y_h")];
        let attrs = vec![
            attr_int("hidden_size", rnn.hidden_size as i64),
            attr_string("direction", rnn.direction.attr()),
            attr_int("layout", 0),
            attr_int("linear_before_reset", linear_before_reset as i64),
        ];
        let mut v = self.node_multi("GRU", name, &inputs[..n], &outs, attrs).into_iter();
        RnnOutputs { y: v.next().expect("y"), y_h: v.next().expect("y_h"), y_c: None }
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

/// Number of leading entries to keep so that trailing omitted optional inputs are dropped.
fn trailing_used(inputs: &[&Value]) -> usize {
    inputs.iter().rposition(|v| !v.0.is_empty()).map_or(0, |i| i + 1)
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

fn attr(name: &str, ty: pb::attribute_proto::AttributeType) -> pb::AttributeProto {
    pb::AttributeProto { name: name.to_string(), r#type: ty as i32, ..Default::default() }
}

/// A float attribute (its `type` field set, which tract requires).
pub fn attr_float(name: &str, f: f32) -> pb::AttributeProto {
    pb::AttributeProto { f, ..attr(name, pb::attribute_proto::AttributeType::Float) }
}

/// An int attribute.
pub fn attr_int(name: &str, i: i64) -> pb::AttributeProto {
    pb::AttributeProto { i, ..attr(name, pb::attribute_proto::AttributeType::Int) }
}

/// An ints attribute.
pub fn attr_ints(name: &str, ints: &[i64]) -> pb::AttributeProto {
    pb::AttributeProto { ints: ints.to_vec(), ..attr(name, pb::attribute_proto::AttributeType::Ints) }
}

/// A string attribute.
pub fn attr_string(name: &str, s: &str) -> pb::AttributeProto {
    pb::AttributeProto { s: s.as_bytes().to_vec(), ..attr(name, pb::attribute_proto::AttributeType::String) }
}

/// Reorders the gate blocks of a stacked recurrent weight or bias.
///
/// `data` is `[gates * hidden, cols]` row-major (use `cols = 1` for a bias); block `k` of the
/// result is block `order[k]` of the input. Conversions from candle/PyTorch to ONNX:
/// LSTM i,f,g,o -> i,o,f,c is `order = [0, 3, 1, 2]`; GRU r,z,n -> z,r,h is `order = [1, 0, 2]`
/// (DEPENDENCY-FACTS, candle 0.11.1).
pub fn reorder_gates(data: &[f32], hidden: usize, cols: usize, order: &[usize]) -> Vec<f32> {
    let block = hidden * cols;
    let mut out = Vec::with_capacity(data.len());
    for &k in order {
        out.extend_from_slice(&data[k * block..(k + 1) * block]);
    }
    out
}

/// Gate order conversion of an LSTM from candle/PyTorch (i,f,g,o) to ONNX (i,o,f,c).
pub const LSTM_TORCH_TO_ONNX: [usize; 4] = [0, 3, 1, 2];
/// Gate order conversion of a GRU from candle/PyTorch (r,z,n) to ONNX (z,r,h).
pub const GRU_TORCH_TO_ONNX: [usize; 3] = [1, 0, 2];

/// A finished ONNX model.
#[derive(Clone, Debug)]
pub struct OnnxModel {
    proto: pb::ModelProto,
}

impl OnnxModel {
    /// Wraps a model proto (e.g. one edited after building).
    pub fn from_proto(proto: pb::ModelProto) -> Self {
        OnnxModel { proto }
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

    /// Writes the encoded model to `path`.
    pub fn write(&self, path: &Path) -> Result<(), ExportError> {
        std::fs::write(path, self.to_bytes())
            .map_err(|source| ExportError::Io { path: path.display().to_string(), source })
    }

    /// Inputs, outputs and op counts, for snapshots and logs.
    pub fn summary(&self) -> GraphSummary {
        summarize(&self.proto)
    }
}

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
    /// Number of f32 weights over all f32 initializers.
    pub parameters: usize,
    /// metadata_props keys.
    pub metadata_keys: Vec<String>,
}

/// Summarises any ONNX model proto (also ones not built by this crate).
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
    let parameters = graph
        .initializer
        .iter()
        .filter(|t| t.data_type == pb::tensor_proto::DataType::Float as i32)
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

#[cfg(test)]
mod tests {
    use super::*;

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
    fn rnn_weight_shapes_are_checked_against_direction() {
        let mut g = GraphBuilder::new("rnn");
        let x = g.input("x", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(2)]);
        let w = g.initializer_f32("w", &[1, 12, 2], &[0.0; 24]);
        let r = g.initializer_f32("r", &[1, 12, 3], &[0.0; 36]);
        let rnn = RnnInputs {
            x: &x,
            w: &w,
            r: &r,
            b: None,
            initial_h: None,
            hidden_size: 3,
            direction: RnnDirection::Bidirectional,
        };
        let o = g.lstm("lstm", &rnn, None);
        g.output("h", &o.y_h, &[Dim::Fixed(2), Dim::batch(), Dim::Fixed(3)]);
        let err = g.finish().unwrap_err().to_string();
        assert!(err.contains("LSTM W") && err.contains("bidirectional"), "{err}");
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

    #[test]
    fn omitted_optional_rnn_inputs_are_trimmed_or_blank() {
        let mut g = GraphBuilder::new("gru");
        let x = g.input("x", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(2)]);
        let h0 = g.input("h0", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(3)]);
        let w = g.initializer_f32("w", &[1, 9, 2], &[0.0; 18]);
        let r = g.initializer_f32("r", &[1, 9, 3], &[0.0; 27]);
        let rnn = RnnInputs {
            x: &x,
            w: &w,
            r: &r,
            b: None,
            initial_h: Some(&h0),
            hidden_size: 3,
            direction: RnnDirection::Forward,
        };
        let o = g.gru("gru", &rnn, true);
        g.output("h", &o.y_h, &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(3)]);
        let m = g.finish().unwrap();
        let node = &m.proto().graph.as_ref().unwrap().node[0];
        assert_eq!(node.input, vec!["x", "w", "r", "", "", "h0"]);
    }

    #[test]
    fn gate_reordering() {
        // 4 gates of hidden 1, one column: i f g o -> i o f g
        let v = reorder_gates(&[0., 1., 2., 3.], 1, 1, &LSTM_TORCH_TO_ONNX);
        assert_eq!(v, vec![0., 3., 1., 2.]);
        let v = reorder_gates(&[0., 0., 1., 1., 2., 2.], 1, 2, &GRU_TORCH_TO_ONNX);
        assert_eq!(v, vec![1., 1., 0., 0., 2., 2.]);
    }
}
