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
use crate::graph::GraphBuilder;
use crate::model::OnnxModel;
use crate::pb;
use crate::unity::{UNITY_OPERATORS_URL, UNITY_OPSET_MAX, UNITY_OPSET_MIN, UNITY_VERSION, unity_op};
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};
use unroll::{Cell, RecurrentNode};

mod unroll;

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
    /// The bytes the lowering may hold (`None`: unbounded): the unrolled size
    /// ([`BYTES_PER_UNROLLED_STEP`] per frame and direction of each recurrent node) is computed
    /// before unrolling, and a graph past it is refused with the size and how to lower it.
    pub memory_bound: Option<u64>,
}

/// Bytes a portable export holds per unrolled frame of one direction of a recurrent node: its
/// dozen cell nodes with their names, in the built graph, its copies and the written bytes
/// (measured with `zoo export --portable --frames N` on a tiny RMR, 4 cell steps a frame: 97 MB
/// peak at 500 frames, 259 MB at 2000, 27.6 KB a step; rounded up).
pub const BYTES_PER_UNROLLED_STEP: u64 = 32_000;

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
    if let Some(bound) = options.memory_bound {
        check_unrolled_size(&graph, &lengths, bound)?;
    }
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

/// Refuses a graph whose recurrent nodes, unrolled over `lengths` frames, would hold more than
/// `bound` bytes ([`BYTES_PER_UNROLLED_STEP`] per frame and direction), before unrolling.
fn check_unrolled_size(
    graph: &pb::GraphProto,
    lengths: &HashMap<String, usize>,
    bound: u64,
) -> Result<(), ExportError> {
    let mut steps = 0u64;
    let mut frames = 0usize;
    for node in graph.node.iter().filter(|n| Cell::of(n).is_some()) {
        let bidirectional = node.attribute.iter().any(|a| a.name == "direction" && a.s == b"bidirectional");
        let n = lengths.get(node_name(node)).copied().unwrap_or(0);
        frames = frames.max(n);
        steps = steps.saturating_add((n as u64).saturating_mul(if bidirectional { 2 } else { 1 }));
    }
    let need = steps.saturating_mul(BYTES_PER_UNROLLED_STEP);
    if need > bound {
        return Err(ExportError::NotPortable {
            graph: graph.name.clone(),
            message: format!(
                "unrolling its recurrent nodes over {frames} frames makes {steps} cell steps, about {:.2} GB to \
                 build and write, past the memory bound of {:.2} GB: fix fewer frames (zoo export --portable \
                 --frames N), or raise the bound with the environment variable ZOO_MEMORY_GB=N",
                need as f64 / 1e9,
                bound as f64 / 1e9
            ),
        });
    }
    Ok(())
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
    // tract has its own copy of the ONNX messages: hand it the encoded bytes.
    let tract_proto = {
        use prost::Message as _;
        tract_onnx::pb::ModelProto::decode(proto.encode_to_vec().as_slice())
            .map_err(|e| fail(format!("the graph does not re-decode as ONNX: {e}")))?
    };
    let mut model = tract_onnx::onnx()
        .model_for_proto_model(&tract_proto)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ops::attr_int;
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

    /// The unrolled size is computed from the frame count before unrolling, and a graph past
    /// the bound is refused with the size and the option that lowers it.
    #[test]
    fn an_unrolled_size_past_the_memory_bound_is_refused_before_unrolling() {
        let within = PortableOptions { memory_bound: Some(3 * BYTES_PER_UNROLLED_STEP), ..Default::default() };
        lower(&lstm_model(vec![]), &within).unwrap();
        let past = PortableOptions { memory_bound: Some(3 * BYTES_PER_UNROLLED_STEP - 1), ..Default::default() };
        let err = lower(&lstm_model(vec![]), &past).unwrap_err().to_string();
        assert!(
            err.contains("over 3 frames makes 3 cell steps")
                && err.contains("--frames N")
                && err.contains("ZOO_MEMORY_GB"),
            "{err}"
        );
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
