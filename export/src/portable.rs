//! The portable profile (`zoo export --portable`): a generic lowering pass that rewrites a
//! finished model into operators Unity Inference Engine documents as supported on every backend
//! ([`crate::unity`]), stamped with the highest opset it documents (15), and the graphs that
//! the regular file embeds as base64 metadata written as files of their own.
//!
//! What the pass rewrites (any exporter's graph, no model crate involved):
//! - ONNX `LSTM`, `GRU` (both `linear_before_reset` values) and `RNN` nodes, forward, reverse
//!   or bidirectional, become their cell equations unrolled over the sequence: one `MatMul` +
//!   `Add` for the input projection of every frame, then per frame `Gather` (the frame), `Gemm`
//!   (the hidden projection), `Split`, `Sigmoid`, `Tanh`, `Mul`, `Add`, `Sub`, and `Unsqueeze` +
//!   `Concat` to assemble `Y`, `Y_h`, `Y_c`. The sequence length must be a fixed number: symbolic
//!   dimensions of graph inputs and outputs are fixed by [`PortableOptions::fixed_dims`], and tract's
//!   shape inference finds each recurrent node's length; a length still symbolic is refused with
//!   the name of the dimension to fix.
//! - Nothing else is rewritten: any other operator must already be in the list, or the pass
//!   refuses the graph naming the node and the operator (`Scan`, `Loop` and `If`, which no zoo
//!   exporter writes, are refused this way).
//!
//! Limits of the recurrent lowering (refused with a message, never silently changed): weights
//! `W`, `R`, `B` and peepholes must be initializers, `sequence_lens` and peepholes `P` must be
//! absent, `layout` 0, default activations, no `clip`, no `input_forget`.

use crate::error::ExportError;
use crate::graph::{GraphBuilder, Value};
use crate::model::OnnxModel;
use crate::ops::attr_int;
use crate::pb;
use crate::unity::{UNITY_OPERATORS_URL, UNITY_OPSET_MAX, UNITY_OPSET_MIN, UNITY_VERSION, unity_op};
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};

/// The opset a portable model imports: the highest Inference Engine 2.3 documents.
pub const PORTABLE_OPSET: i64 = UNITY_OPSET_MAX;

/// Operators whose definition in the default domain is newer than opset 15 (so not valid, or
/// not the same operator, in a portable file): new in 16 or 17, or given new attributes or
/// defaults there. The float semantics of every other operator in the list are the same in
/// opsets 15 and 17 (ONNX `Operators.md` change log).
const NEWER_THAN_OPSET_15: [&str; 6] =
    ["GridSample", "LayerNormalization", "RoiAlign", "ScatterElements", "ScatterND", "SequenceMap"];

/// Options of the portable pass.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PortableOptions {
    /// Sizes given to symbolic dimensions of graph inputs and outputs (e.g. `frames` -> 60),
    /// needed where a recurrent op runs over a symbolic sequence length. The batch dimension
    /// can stay symbolic.
    pub fixed_dims: BTreeMap<String, usize>,
}

/// A graph the regular file embeds in its metadata (base64 ONNX) and the portable export
/// writes as a file of its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EmbeddedGraph<'a> {
    /// The metadata key holding the base64 graph in the regular file (e.g. `zoo.start_graph`).
    pub key: &'a str,
    /// The metadata key naming the graph's file in the portable main file.
    pub file_key: &'a str,
    /// The file name's infix: `rtn.onnx` -> `rtn.<suffix>.onnx`.
    pub suffix: &'a str,
}

/// A graph of a portable export written beside the main file.
#[derive(Clone, Debug)]
pub struct CompanionGraph {
    /// The metadata key of the regular file it came from.
    pub key: String,
    /// The metadata key that names its file in the main file.
    pub file_key: String,
    /// The file name's infix.
    pub suffix: String,
    /// The lowered graph.
    pub model: OnnxModel,
}

/// A portable export: the main (step) graph and the graphs written beside it.
#[derive(Clone, Debug)]
pub struct PortableModel {
    /// The main graph, with the regular file's metadata less the embedded graphs.
    pub main: OnnxModel,
    /// The formerly embedded graphs, lowered too.
    pub companions: Vec<CompanionGraph>,
}

impl PortableModel {
    /// Where a companion of the main file `path` is written: `dir/stem.<suffix>.onnx`.
    pub fn companion_path(path: &Path, suffix: &str) -> PathBuf {
        let stem = path.file_stem().map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
        path.with_file_name(format!("{stem}.{suffix}.onnx"))
    }

    /// Writes the companions, then the main file (each atomically), the main file naming each
    /// companion's file (relative to its own folder) under the companion's `file_key`. Returns the
    /// paths written, main first.
    pub fn write(&self, path: &Path) -> Result<Vec<PathBuf>, ExportError> {
        let mut main = self.main.clone();
        let mut written = vec![path.to_path_buf()];
        for c in &self.companions {
            let p = Self::companion_path(path, &c.suffix);
            c.model.write(&p)?;
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            main.set_metadata(&c.file_key, &name);
            written.push(p);
        }
        main.write(path)?;
        Ok(written)
    }

    /// The main graph and the companions, each lowered model with a name (`main` or the suffix).
    pub fn graphs(&self) -> Vec<(&str, &OnnxModel)> {
        std::iter::once(("main", &self.main))
            .chain(self.companions.iter().map(|c| (c.suffix.as_str(), &c.model)))
            .collect()
    }
}

/// Lowers `model` and the graphs it embeds (`embedded`, those present) to the portable profile;
/// each graph is checked with [`check_portable`].
pub fn to_portable(
    model: &OnnxModel,
    options: &PortableOptions,
    embedded: &[EmbeddedGraph],
) -> Result<PortableModel, ExportError> {
    let mut main = model.clone();
    let mut companions = Vec::new();
    for e in embedded {
        let Some(encoded) = main.remove_metadata(e.key) else { continue };
        let graph = OnnxModel::from_base64(&encoded, e.key)?;
        let lowered = lower(&graph, options)?;
        check_portable(&lowered)?;
        companions.push(CompanionGraph {
            key: e.key.to_string(),
            file_key: e.file_key.to_string(),
            suffix: e.suffix.to_string(),
            model: lowered,
        });
    }
    let main = lower(&main, options)?;
    check_portable(&main)?;
    Ok(PortableModel { main, companions })
}

/// The operator types a model's main graph uses.
pub fn op_types(model: &OnnxModel) -> BTreeSet<String> {
    model.proto().graph.iter().flat_map(|g| &g.node).map(|n| n.op_type.clone()).collect()
}

/// Checks that `model` is portable: opset 7 to 15 of the default domain only, and every node's
/// operator listed by Inference Engine 2.3 as running float tensors on every backend (CPU,
/// GPUCompute, GPUPixel). The error lists every offending node.
pub fn check_portable(model: &OnnxModel) -> Result<(), ExportError> {
    let graph = model.proto().graph.clone().unwrap_or_default();
    let fail = |message: String| ExportError::NotPortable { graph: graph.name.clone(), message };
    for o in &model.proto().opset_import {
        if !o.domain.is_empty() && o.domain != "ai.onnx" {
            return Err(fail(format!(
                "it imports the operator domain `{}`; only the default ONNX domain is portable",
                o.domain
            )));
        }
        if !(UNITY_OPSET_MIN..=UNITY_OPSET_MAX).contains(&o.version) {
            return Err(fail(format!(
                "it imports opset {}; Unity Inference Engine {UNITY_VERSION} documents opsets {UNITY_OPSET_MIN} to {UNITY_OPSET_MAX}",
                o.version
            )));
        }
    }
    let mut problems = Vec::new();
    for n in &graph.node {
        let why = if !n.domain.is_empty() && n.domain != "ai.onnx" {
            Some(format!("domain `{}`", n.domain))
        } else if NEWER_THAN_OPSET_15.contains(&n.op_type.as_str()) {
            Some(format!("`{}` is defined differently after opset 15", n.op_type))
        } else {
            match unity_op(&n.op_type) {
                None => Some(format!("`{}` is not in the supported list", n.op_type)),
                Some(op) if !op.float_on_every_backend() => Some(format!(
                    "`{}` does not run float tensors on every backend (CPU: {}, GPUCompute: {}, GPUPixel: {})",
                    n.op_type, op.cpu, op.gpu_compute, op.gpu_pixel
                )),
                Some(_) => None,
            }
        };
        if let Some(why) = why {
            problems.push(format!("node `{}`: {why}", n.name));
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    let shown = problems.iter().take(5).cloned().collect::<Vec<_>>().join("; ");
    let more = if problems.len() > 5 { format!(" (and {} more)", problems.len() - 5) } else { String::new() };
    Err(fail(format!(
        "{shown}{more}; the portable profile writes only operators of Unity Inference Engine {UNITY_VERSION} ({UNITY_OPERATORS_URL}) \
         and lowers only LSTM, GRU and RNN: write such ops with the typed helpers of zoo-export, or export without --portable"
    )))
}

/// Lowers one model (its main graph): fixes the symbolic dimensions of `options`, unrolls the
/// recurrent nodes, drops initializers no node reads any more, and stamps opset
/// [`PORTABLE_OPSET`]. Metadata and doc string are kept. Does not check the result (see
/// [`check_portable`]).
pub fn lower(model: &OnnxModel, options: &PortableOptions) -> Result<OnnxModel, ExportError> {
    let mut proto = model.proto().clone();
    let mut graph = proto.graph.take().unwrap_or_default();
    for v in graph.input.iter_mut().chain(graph.output.iter_mut()) {
        fix_dims(v, &options.fixed_dims);
    }
    let recurrent: Vec<String> =
        graph.node.iter().filter(|n| Cell::of(n).is_some()).map(|n| node_name(n).to_string()).collect();
    let lengths = if recurrent.is_empty() {
        HashMap::new()
    } else {
        let mut fixed = proto.clone();
        fixed.graph = Some(graph.clone());
        sequence_lengths(&fixed, &graph.name, &recurrent, options)?
    };
    let used: HashSet<String> = graph
        .node
        .iter()
        .flat_map(|n| n.input.iter().cloned())
        .chain(graph.output.iter().map(|o| o.name.clone()))
        .collect();
    let inits: HashMap<&str, &pb::TensorProto> = graph.initializer.iter().map(|t| (t.name.as_str(), t)).collect();
    let mut g = GraphBuilder::from_graph(&graph);
    for node in &graph.node {
        match Cell::of(node) {
            None => g.push_node(node.clone()),
            Some(cell) => {
                let name = node_name(node);
                let steps = lengths[name];
                let lowering = RecurrentNode::read(node, cell, &inits, steps)
                    .map_err(|message| ExportError::NotPortable { graph: graph.name.clone(), message })?;
                lowering.emit(&mut g, &used);
            }
        }
    }
    let built = g.finish()?;
    let mut lowered = built.proto().graph.clone().unwrap_or_default();
    let read: HashSet<&str> = lowered
        .node
        .iter()
        .flat_map(|n| n.input.iter().map(String::as_str))
        .chain(lowered.output.iter().map(|o| o.name.as_str()))
        .collect();
    let keep: Vec<pb::TensorProto> =
        lowered.initializer.iter().filter(|t| read.contains(t.name.as_str())).cloned().collect();
    lowered.initializer = keep;
    lowered.value_info.clear();
    proto.graph = Some(lowered);
    proto.opset_import = vec![pb::OperatorSetIdProto { domain: String::new(), version: PORTABLE_OPSET }];
    Ok(OnnxModel::from_proto(proto))
}

fn node_name(n: &pb::NodeProto) -> &str {
    if n.name.is_empty() { n.output.first().map_or("", String::as_str) } else { &n.name }
}

fn fix_dims(v: &mut pb::ValueInfoProto, fixed: &BTreeMap<String, usize>) {
    use pb::tensor_shape_proto::dimension::Value as D;
    let Some(pb::TypeProto { value: Some(pb::type_proto::Value::TensorType(t)), .. }) = v.r#type.as_mut() else {
        return;
    };
    for d in t.shape.iter_mut().flat_map(|s| s.dim.iter_mut()) {
        if let Some(D::DimParam(p)) = &d.value
            && let Some(&n) = fixed.get(p)
        {
            d.value = Some(D::DimValue(n as i64));
        }
    }
}

/// The sequence length (first dimension of `X`) of each recurrent node, from tract's shape
/// inference on the graph with its fixed dimensions.
fn sequence_lengths(
    proto: &pb::ModelProto,
    graph: &str,
    nodes: &[String],
    options: &PortableOptions,
) -> Result<HashMap<String, usize>, ExportError> {
    use tract_onnx::prelude::*;
    use tract_onnx::tract_hir::infer::{Factoid, InferenceModelExt};
    let fail = |message: String| ExportError::NotPortable { graph: graph.to_string(), message };
    let mut model = tract_onnx::onnx()
        .model_for_proto_model(proto)
        .map_err(|e| fail(format!("tract cannot read the graph to infer its shapes: {e}")))?;
    // Obstinate: a node tract cannot type (none in zoo's graphs) must not hide the others' shapes.
    let _ = model.analyse(true);
    let fixed = if options.fixed_dims.is_empty() {
        "none".to_string()
    } else {
        options.fixed_dims.iter().map(|(k, v)| format!("{k} = {v}")).collect::<Vec<_>>().join(", ")
    };
    let mut out = HashMap::new();
    for name in nodes {
        let node = model.node_by_name(name).map_err(|e| fail(format!("node `{name}`: {e}")))?;
        let fact = node.inputs.first().and_then(|&o| model.outlet_fact(o).ok());
        let dim = fact.and_then(|f| f.shape.dims().next().cloned()).and_then(|d| d.concretize());
        let steps = match dim.as_ref().map(|d| d.to_i64()) {
            Some(Ok(n)) if n > 0 => n as usize,
            Some(Ok(n)) => return Err(fail(format!("recurrent node `{name}` runs over {n} frames"))),
            Some(Err(_)) | None => {
                let what =
                    dim.map_or_else(|| "an unknown length".to_string(), |d| format!("the symbolic length `{d}`"));
                return Err(fail(format!(
                    "recurrent node `{name}` runs over {what}; the portable profile unrolls recurrent ops over a fixed \
                     number of frames: fix the dimension (zoo export --portable --frames N; fixed now: {fixed})"
                )));
            }
        };
        out.insert(name.clone(), steps);
    }
    Ok(out)
}

/// The recurrent ops the pass lowers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cell {
    Lstm,
    Gru,
    Rnn,
}

impl Cell {
    fn of(n: &pb::NodeProto) -> Option<Cell> {
        if !n.domain.is_empty() && n.domain != "ai.onnx" {
            return None;
        }
        match n.op_type.as_str() {
            "LSTM" => Some(Cell::Lstm),
            "GRU" => Some(Cell::Gru),
            "RNN" => Some(Cell::Rnn),
            _ => None,
        }
    }

    /// Whether an `activations` attribute spells out the defaults (one list per direction).
    fn activations_are_default(self, given: &[Vec<u8>]) -> bool {
        let one: &[&[u8]] = match self {
            Cell::Lstm => &[b"Sigmoid", b"Tanh", b"Tanh"],
            Cell::Gru => &[b"Sigmoid", b"Tanh"],
            Cell::Rnn => &[b"Tanh"],
        };
        (given.len() == one.len() || given.len() == 2 * one.len())
            && given.iter().zip(one.iter().cycle()).all(|(g, d)| g.as_slice() == *d)
    }

    fn gates(self) -> usize {
        match self {
            Cell::Lstm => 4,
            Cell::Gru => 3,
            Cell::Rnn => 1,
        }
    }
}

/// One direction's weights: `W` `[G H, I]`, `R` `[G H, H]`, biases `Wb`, `Rb` `[G H]`.
struct DirectionWeights {
    w: Vec<f32>,
    r: Vec<f32>,
    wb: Vec<f32>,
    rb: Vec<f32>,
}

/// A recurrent node read for lowering.
struct RecurrentNode {
    name: String,
    cell: Cell,
    hidden: usize,
    input: usize,
    steps: usize,
    /// Per direction: whether it runs backwards in time.
    reverse: Vec<bool>,
    weights: Vec<DirectionWeights>,
    linear_before_reset: bool,
    x: String,
    initial_h: Option<String>,
    initial_c: Option<String>,
    /// `Y`, `Y_h`, `Y_c` output names (empty: not produced).
    outputs: [String; 3],
}

fn f32_data(t: &pb::TensorProto) -> Result<Vec<f32>, String> {
    if t.data_type != pb::tensor_proto::DataType::Float as i32 {
        return Err(format!("initializer `{}` is not float32", t.name));
    }
    if !t.raw_data.is_empty() {
        Ok(t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    } else {
        Ok(t.float_data.clone())
    }
}

impl RecurrentNode {
    fn read(
        node: &pb::NodeProto,
        cell: Cell,
        inits: &HashMap<&str, &pb::TensorProto>,
        steps: usize,
    ) -> Result<Self, String> {
        let name = node_name(node).to_string();
        let op = node.op_type.as_str();
        let at = |i: usize| node.input.get(i).filter(|s| !s.is_empty()).cloned();
        let mut hidden = None;
        let mut direction = "forward".to_string();
        let mut linear_before_reset = false;
        for a in &node.attribute {
            match a.name.as_str() {
                "hidden_size" => hidden = Some(a.i as usize),
                "direction" => direction = String::from_utf8_lossy(&a.s).into_owned(),
                "layout" if a.i != 0 => {
                    return Err(format!("{op} `{name}` has layout {}; only layout 0 is lowered", a.i));
                }
                "linear_before_reset" => linear_before_reset = a.i != 0,
                "input_forget" if a.i != 0 => {
                    return Err(format!("{op} `{name}` couples input and forget gates; not lowered"));
                }
                // Exporters often spell the defaults out (PyTorch writes Sigmoid, Tanh, Tanh).
                "activations" if cell.activations_are_default(&a.strings) => {}
                "activations" | "activation_alpha" | "activation_beta" | "clip" => {
                    return Err(format!(
                        "{op} `{name}` sets `{}`; only default activations without clip are lowered",
                        a.name
                    ));
                }
                _ => {}
            }
        }
        let hidden = hidden.ok_or_else(|| format!("{op} `{name}` has no hidden_size"))?;
        if at(4).is_some() {
            return Err(format!(
                "{op} `{name}` has sequence_lens; every sequence must run the full length to be unrolled"
            ));
        }
        if cell == Cell::Lstm && at(7).is_some() {
            return Err(format!("LSTM `{name}` has peepholes (P); not lowered"));
        }
        let reverse = match direction.as_str() {
            "forward" => vec![false],
            "reverse" => vec![true],
            "bidirectional" => vec![false, true],
            other => return Err(format!("{op} `{name}` has direction `{other}`")),
        };
        let dirs = reverse.len();
        let g = cell.gates();
        let weight = |i: usize, label: &str| -> Result<(Vec<usize>, Vec<f32>), String> {
            let v = at(i).ok_or_else(|| format!("{op} `{name}` has no {label}"))?;
            let t = inits.get(v.as_str()).ok_or_else(|| {
                format!("{op} `{name}`: {label} (`{v}`) is not an initializer; only constant weights are lowered")
            })?;
            let dims: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
            let data = f32_data(t)?;
            if data.len() != dims.iter().product::<usize>() {
                return Err(format!("{op} `{name}`: {label} has shape {dims:?} but {} values", data.len()));
            }
            Ok((dims, data))
        };
        let (wd, w) = weight(1, "W")?;
        let (rd, r) = weight(2, "R")?;
        let input = wd.get(2).copied().unwrap_or(0);
        if wd != [dirs, g * hidden, input] || rd != [dirs, g * hidden, hidden] {
            return Err(format!(
                "{op} `{name}`: W {wd:?} and R {rd:?} do not match {dirs} direction(s), {g} gate(s), hidden size {hidden}"
            ));
        }
        let b = match at(3) {
            Some(_) => {
                let (bd, b) = weight(3, "B")?;
                if bd != [dirs, 2 * g * hidden] {
                    return Err(format!("{op} `{name}`: B {bd:?} is not [{dirs}, {}]", 2 * g * hidden));
                }
                b
            }
            None => vec![0.0; dirs * 2 * g * hidden],
        };
        let gh = g * hidden;
        let weights = (0..dirs)
            .map(|d| DirectionWeights {
                w: w[d * gh * input..(d + 1) * gh * input].to_vec(),
                r: r[d * gh * hidden..(d + 1) * gh * hidden].to_vec(),
                wb: b[d * 2 * gh..d * 2 * gh + gh].to_vec(),
                rb: b[d * 2 * gh + gh..(d + 1) * 2 * gh].to_vec(),
            })
            .collect();
        let out = |i: usize| node.output.get(i).cloned().unwrap_or_default();
        Ok(RecurrentNode {
            name,
            cell,
            hidden,
            input,
            steps,
            reverse,
            weights,
            linear_before_reset,
            x: node.input[0].clone(),
            initial_h: at(5),
            initial_c: if cell == Cell::Lstm { at(6) } else { None },
            outputs: [out(0), out(1), if cell == Cell::Lstm { out(2) } else { String::new() }],
        })
    }

    /// Writes the unrolled cell; the outputs keep the node's output names (only those read).
    fn emit(&self, g: &mut GraphBuilder, used: &HashSet<String>) {
        let (n, h) = (&self.name, self.hidden);
        let x = Value(self.x.clone());
        let frame: Vec<Value> =
            (0..self.steps).map(|t| g.initializer_i64(&format!("{n}.frame{t}"), &[], &[t as i64])).collect();
        let mut ys: Vec<Vec<Value>> = Vec::new();
        let mut last_h = Vec::new();
        let mut last_c = Vec::new();
        for (d, wd) in self.weights.iter().enumerate() {
            let p = format!("{n}.d{d}");
            let gh = self.cell.gates() * h;
            // Input projection of every frame at once: X [T, B, I] @ W^T [I, G H] + bias.
            let w_t = g.initializer_f32(&format!("{p}.W_t"), &[self.input, gh], &transpose(&wd.w, gh, self.input));
            let bias: Vec<f32> = match self.cell {
                // LSTM and RNN add both biases outside any gate product: fold Rb in.
                Cell::Lstm | Cell::Rnn => wd.wb.iter().zip(&wd.rb).map(|(a, b)| a + b).collect(),
                Cell::Gru => wd.wb.clone(),
            };
            let b = g.initializer_f32(&format!("{p}.x_bias"), &[gh], &bias);
            let xw = g.matmul(&format!("{p}.x_matmul"), &x, &w_t);
            let xw = g.add(&format!("{p}.x_gates"), &xw, &b);
            let r = g.initializer_f32(&format!("{p}.R"), &[gh, h], &wd.r);
            let direction = (self.initial_h.is_some() || self.initial_c.is_some())
                .then(|| g.initializer_i64(&format!("{p}.direction"), &[], &[d as i64]));
            let mut initial = |v: &Option<String>, label: &str| {
                let (v, i) = (v.as_ref()?, direction.as_ref()?);
                Some(g.custom_op("Gather", &format!("{p}.{label}"), &[&Value(v.clone()), i], vec![attr_int("axis", 0)]))
            };
            let mut state_h = initial(&self.initial_h, "h0");
            let mut state_c = initial(&self.initial_c, "c0");
            let gru = GruWeights::new(g, &p, wd, h, self.linear_before_reset, self.cell == Cell::Gru);
            let mut y = vec![None; self.steps];
            let order: Vec<usize> =
                if self.reverse[d] { (0..self.steps).rev().collect() } else { (0..self.steps).collect() };
            for t in order {
                let s = format!("{p}.t{t}");
                let xt = g.custom_op("Gather", &format!("{s}.x"), &[&xw, &frame[t]], vec![attr_int("axis", 0)]);
                let (h_new, c_new) = match self.cell {
                    Cell::Lstm => {
                        let z = gates_plus_hidden(g, &s, xt, state_h.as_ref(), &r);
                        // ONNX gate order i, o, f, c.
                        let parts = g.split(&format!("{s}.split"), &z, &[h; 4], 1);
                        let i = g.sigmoid(&format!("{s}.i"), &parts[0]);
                        let o = g.sigmoid(&format!("{s}.o"), &parts[1]);
                        let f = g.sigmoid(&format!("{s}.f"), &parts[2]);
                        let c_in = g.tanh(&format!("{s}.c_in"), &parts[3]);
                        let ic = g.mul(&format!("{s}.i_c"), &i, &c_in);
                        let c = match &state_c {
                            Some(cp) => {
                                let fc = g.mul(&format!("{s}.f_c"), &f, cp);
                                g.add(&format!("{s}.c"), &fc, &ic)
                            }
                            None => ic,
                        };
                        let tc = g.tanh(&format!("{s}.tanh_c"), &c);
                        (g.mul(&format!("{s}.h"), &o, &tc), Some(c))
                    }
                    Cell::Rnn => {
                        let z = gates_plus_hidden(g, &s, xt, state_h.as_ref(), &r);
                        (g.tanh(&format!("{s}.h"), &z), None)
                    }
                    Cell::Gru => (gru.step(g, &s, &xt, state_h.as_ref(), &r, h), None),
                };
                y[t] = Some(h_new.clone());
                state_h = Some(h_new);
                if c_new.is_some() {
                    state_c = c_new;
                }
            }
            ys.push(y.into_iter().map(|v| v.expect("every frame ran")).collect());
            last_h.push(state_h.expect("at least one frame"));
            last_c.push(state_c);
        }
        let [y_name, yh_name, yc_name] = &self.outputs;
        if !y_name.is_empty() && used.contains(y_name) {
            // Y [T, D, B, H]: each h [B, H] -> [1, 1, B, H], directions on axis 1, frames on axis 0.
            let frames: Vec<Value> = (0..self.steps)
                .map(|t| {
                    let per_dir: Vec<Value> = ys
                        .iter()
                        .enumerate()
                        .map(|(d, y)| g.unsqueeze(&format!("{n}.y.t{t}.d{d}"), &y[t], &[0, 1]))
                        .collect();
                    concat_or_single(g, &format!("{n}.y.t{t}"), &per_dir, 1, None)
                })
                .collect();
            concat_or_single(g, &format!("{n}.y"), &frames, 0, Some(y_name.as_str()));
        }
        for (last, out, label) in
            [(last_h.iter().map(|v| Some(v.clone())).collect::<Vec<_>>(), yh_name, "y_h"), (last_c, yc_name, "y_c")]
        {
            if out.is_empty() || !used.contains(out) {
                continue;
            }
            let parts: Vec<Value> = last
                .iter()
                .enumerate()
                .map(|(d, v)| {
                    let v = v.clone().expect("LSTM cell state");
                    g.unsqueeze(&format!("{n}.{label}.d{d}"), &v, &[0])
                })
                .collect();
            concat_or_single(g, &format!("{n}.{label}"), &parts, 0, Some(out.as_str()));
        }
    }
}

/// The gate pre-activations of a frame: `xt` (input projection with the biases) plus `h R^T`,
/// or `xt` alone at a zero state.
fn gates_plus_hidden(g: &mut GraphBuilder, s: &str, xt: Value, h: Option<&Value>, r: &Value) -> Value {
    match h {
        Some(hp) => {
            let hr = g.gemm(&format!("{s}.h_gates"), hp, r, None, true);
            g.add(&format!("{s}.gates"), &xt, &hr)
        }
        None => xt,
    }
}

/// `Concat(values, axis)`, or the single value; named `out` when given (through `Identity` for
/// a single value).
fn concat_or_single(g: &mut GraphBuilder, name: &str, values: &[Value], axis: i64, out: Option<&str>) -> Value {
    match (values, out) {
        ([one], None) => one.clone(),
        ([one], Some(out)) => g.node_multi("Identity", name, &[one], &[out.to_string()], vec![]).remove(0),
        (many, None) => g.concat(name, &many.iter().collect::<Vec<_>>(), axis),
        (many, Some(out)) => g
            .node_multi(
                "Concat",
                name,
                &many.iter().collect::<Vec<_>>(),
                &[out.to_string()],
                vec![attr_int("axis", axis)],
            )
            .remove(0),
    }
}

/// GRU weights beside `R` (gate order z, r, h): the hidden biases per gate, and for
/// `linear_before_reset = 0` the split of `R` into its z/r rows and its h rows.
struct GruWeights {
    linear_before_reset: bool,
    /// `Rb` of gates z, r, h, `[H]` each.
    rb: Vec<Value>,
    /// Full `Rb` `[3H]`.
    rb_all: Option<Value>,
    /// `R` rows of z and r `[2H, H]` with their bias `[2H]`, and of h `[H, H]`.
    r_zr: Option<(Value, Value)>,
    r_h: Option<Value>,
}

impl GruWeights {
    fn new(g: &mut GraphBuilder, p: &str, wd: &DirectionWeights, h: usize, lbr: bool, is_gru: bool) -> Self {
        if !is_gru {
            return GruWeights { linear_before_reset: lbr, rb: vec![], rb_all: None, r_zr: None, r_h: None };
        }
        let rb: Vec<Value> = ["z", "r", "h"]
            .iter()
            .enumerate()
            .map(|(k, gate)| g.initializer_f32(&format!("{p}.Rb_{gate}"), &[h], &wd.rb[k * h..(k + 1) * h]))
            .collect();
        if lbr {
            let rb_all = g.initializer_f32(&format!("{p}.Rb"), &[3 * h], &wd.rb);
            GruWeights { linear_before_reset: lbr, rb, rb_all: Some(rb_all), r_zr: None, r_h: None }
        } else {
            let r_zr = g.initializer_f32(&format!("{p}.R_zr"), &[2 * h, h], &wd.r[..2 * h * h]);
            let rb_zr = g.initializer_f32(&format!("{p}.Rb_zr"), &[2 * h], &wd.rb[..2 * h]);
            let r_h = g.initializer_f32(&format!("{p}.R_h"), &[h, h], &wd.r[2 * h * h..]);
            GruWeights { linear_before_reset: lbr, rb, rb_all: None, r_zr: Some((r_zr, rb_zr)), r_h: Some(r_h) }
        }
    }

    /// One GRU step (ONNX GRU equations, `f = sigmoid`, `g = tanh`): the next `h`. `xt` holds
    /// `x W^T + Wb` of the frame, `[B, 3H]`.
    fn step(&self, g: &mut GraphBuilder, s: &str, xt: &Value, hp: Option<&Value>, r: &Value, h: usize) -> Value {
        let xs = g.split(&format!("{s}.x_split"), xt, &[h; 3], 1);
        // Hidden terms of z and r (and of h with linear_before_reset): from h_prev, or the bias alone at h = 0.
        let (hz, hr, hh_lbr) = match (hp, self.linear_before_reset) {
            (Some(hp), true) => {
                let all = g.gemm(&format!("{s}.h_gates"), hp, r, self.rb_all.as_ref(), true);
                let parts = g.split(&format!("{s}.h_split"), &all, &[h; 3], 1);
                (parts[0].clone(), parts[1].clone(), Some(parts[2].clone()))
            }
            (Some(hp), false) => {
                let (r_zr, rb_zr) = self.r_zr.as_ref().expect("R_zr");
                let zr = g.gemm(&format!("{s}.h_gates"), hp, r_zr, Some(rb_zr), true);
                let parts = g.split(&format!("{s}.h_split"), &zr, &[h; 2], 1);
                (parts[0].clone(), parts[1].clone(), None)
            }
            (None, _) => (self.rb[0].clone(), self.rb[1].clone(), Some(self.rb[2].clone())),
        };
        let z = g.add(&format!("{s}.z_sum"), &xs[0], &hz);
        let z = g.sigmoid(&format!("{s}.z"), &z);
        let rg = g.add(&format!("{s}.r_sum"), &xs[1], &hr);
        let rg = g.sigmoid(&format!("{s}.r"), &rg);
        let hh = match (hp, self.linear_before_reset) {
            // linear_before_reset = 1: r * (h Rh^T + Rbh); at h = 0 it is r * Rbh.
            (_, true) => g.mul(&format!("{s}.r_hh"), &rg, &hh_lbr.expect("hidden h term")),
            // linear_before_reset = 0: (r * h) Rh^T + Rbh; at h = 0 it is Rbh.
            (Some(hp), false) => {
                let rh = g.mul(&format!("{s}.r_h"), &rg, hp);
                g.gemm(&format!("{s}.hh"), &rh, self.r_h.as_ref().expect("R_h"), Some(&self.rb[2]), true)
            }
            (None, false) => self.rb[2].clone(),
        };
        let n = g.add(&format!("{s}.n_sum"), &xs[2], &hh);
        let n = g.tanh(&format!("{s}.n"), &n);
        // h' = (1 - z) n + z h = n + z (h - n); at h = 0: n - z n.
        match hp {
            Some(hp) => {
                let d = g.sub(&format!("{s}.h_minus_n"), hp, &n);
                let zd = g.mul(&format!("{s}.z_d"), &z, &d);
                g.add(&format!("{s}.h"), &n, &zd)
            }
            None => {
                let zn = g.mul(&format!("{s}.z_n"), &z, &n);
                g.sub(&format!("{s}.h"), &n, &zn)
            }
        }
    }
}

/// `[rows, cols]` row-major -> `[cols, rows]`.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0; m.len()];
    for i in 0..rows {
        for j in 0..cols {
            out[j * rows + i] = m[i * cols + j];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Dim, RnnDirection, RnnInputs};

    /// A forward LSTM over 3 frames (input 2, hidden 2) with `extra` attributes.
    fn lstm_model(extra: Vec<pb::AttributeProto>) -> OnnxModel {
        let mut g = GraphBuilder::new("lstm");
        let x = g.input("x", &[Dim::Fixed(3), Dim::batch(), Dim::Fixed(2)]);
        let w = g.initializer_f32("W", &[1, 8, 2], &[0.1; 16]);
        let r = g.initializer_f32("R", &[1, 8, 2], &[0.2; 16]);
        let rnn = RnnInputs {
            x: &x,
            w: &w,
            r: &r,
            b: None,
            initial_h: None,
            hidden_size: 2,
            direction: RnnDirection::Forward,
        };
        let o = g.lstm("cell", &rnn, None);
        g.output("y", &o.y, &[Dim::Fixed(3), Dim::Fixed(1), Dim::batch(), Dim::Fixed(2)]);
        let mut proto = g.finish().unwrap().proto().clone();
        proto.graph.as_mut().unwrap().node[0].attribute.extend(extra);
        OnnxModel::from_proto(proto)
    }

    fn attr_strings(name: &str, v: &[&str]) -> pb::AttributeProto {
        pb::AttributeProto {
            name: name.into(),
            r#type: pb::attribute_proto::AttributeType::Strings as i32,
            strings: v.iter().map(|s| s.as_bytes().to_vec()).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn an_lstm_becomes_listed_ops_at_opset_15() {
        let lowered = lower(&lstm_model(vec![]), &PortableOptions::default()).unwrap();
        check_portable(&lowered).unwrap();
        let ops = op_types(&lowered);
        assert!(!ops.contains("LSTM") && ops.contains("Gemm") && ops.contains("Sigmoid"), "{ops:?}");
        assert_eq!(lowered.proto().opset_import[0].version, 15);
        let inits: Vec<_> =
            lowered.proto().graph.as_ref().unwrap().initializer.iter().map(|t| t.name.clone()).collect();
        assert!(!inits.contains(&"W".to_string()), "the LSTM's own weights are dropped: {inits:?}");
    }

    #[test]
    fn spelled_out_default_activations_are_lowered_others_refused() {
        let defaults = attr_strings("activations", &["Sigmoid", "Tanh", "Tanh"]);
        lower(&lstm_model(vec![defaults]), &PortableOptions::default()).unwrap();
        let relu = attr_strings("activations", &["Relu", "Tanh", "Tanh"]);
        let err = lower(&lstm_model(vec![relu]), &PortableOptions::default()).unwrap_err().to_string();
        assert!(err.contains("`cell`") && err.contains("activations"), "{err}");
        let clip = crate::attr_float("clip", 3.0);
        let err = lower(&lstm_model(vec![clip]), &PortableOptions::default()).unwrap_err().to_string();
        assert!(err.contains("clip"), "{err}");
        let layout = attr_int("layout", 1);
        assert!(lower(&lstm_model(vec![layout]), &PortableOptions::default()).is_err());
    }

    #[test]
    fn a_regular_opset_17_file_is_not_portable() {
        let err = check_portable(&lstm_model(vec![])).unwrap_err().to_string();
        assert!(err.contains("opset 17") && err.contains("7 to 15"), "{err}");
    }

    #[test]
    fn companions_are_named_after_the_main_file() {
        let p = PortableModel::companion_path(Path::new("out/rtn.onnx"), "start");
        assert_eq!(p, Path::new("out/rtn.start.onnx"));
    }
}
