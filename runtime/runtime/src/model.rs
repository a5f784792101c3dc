//! Loading an exported file: decoding the ONNX protobuf, reading and checking the metadata,
//! binding state pairs and frame inputs/outputs, and planning the step and start graphs.
//! Running them is [`crate::runner`]'s.

use crate::error::{MotionError, chain};
use crate::metadata::{MotionModelMetadata, keys};
use crate::runner::MotionRunner;
use prost::Message;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use tract_onnx::pb;
use tract_onnx::prelude::*;

pub(crate) type Plan = Arc<TypedRunnableModel>;

/// Name and per-character width of one graph input or output (`[batch, width]`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MotionTensorInfo {
    /// Graph name.
    pub name: String,
    /// Values per character (product of the non-batch dimensions).
    pub width: usize,
    /// Dimensions after the batch dimension.
    pub dims: Vec<usize>,
}

/// One recurrent state slot: read from graph input `input`, replaced by graph output `output`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MotionStateInfo {
    /// Graph input name.
    pub input: String,
    /// Graph output name.
    pub output: String,
    /// Values per character.
    pub width: usize,
}

#[derive(Debug)]
pub(crate) struct Inner {
    pub(crate) metadata: MotionModelMetadata,
    /// Frame inputs (graph inputs that are not state), in graph order.
    pub(crate) inputs: Vec<MotionTensorInfo>,
    /// Frame outputs (graph outputs that are not state), in graph order.
    pub(crate) outputs: Vec<MotionTensorInfo>,
    pub(crate) states: Vec<MotionStateInfo>,
    /// For each graph input, in graph order: where its value comes from.
    pub(crate) graph_inputs: Vec<Source>,
    /// For each graph output, in graph order: where its value goes.
    pub(crate) graph_outputs: Vec<Source>,
    pub(crate) graph_input_widths: Vec<usize>,
    /// Plan with every batch dimension set to 1 (lowest latency for one character).
    pub(crate) single: Plan,
    /// Plan with a symbolic batch dimension (checked at load; used when a concrete plan fails).
    pub(crate) batched: Plan,
    /// The step graph before planning and its per-character input dims, to plan concrete batch
    /// sizes: tract picks faster kernels for a known batch than for a symbolic one.
    pub(crate) source: InferenceModel,
    pub(crate) in_dims: Vec<Vec<usize>>,
    /// Plans for concrete batch sizes, made on first use and shared by every runner.
    pub(crate) concrete: Mutex<HashMap<usize, Plan>>,
    /// The transition-start graph, when the model has one.
    pub(crate) start: Option<StartGraph>,
}

impl Inner {
    /// The plan for `batch` characters: concrete (made once per batch size), else symbolic.
    pub(crate) fn plan_for(&self, batch: usize) -> Plan {
        let mut cache = self.concrete.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(p) = cache.get(&batch) {
            return p.clone();
        }
        match plan(&self.source, Some(batch), &self.in_dims) {
            Ok(p) => {
                cache.insert(batch, p.clone());
                p
            }
            Err(_) => self.batched.clone(),
        }
    }
}

/// The transition-start graph (`zoo.start_graph`): all inputs are caller buffers, every output
/// sets one state slot.
#[derive(Debug)]
pub(crate) struct StartGraph {
    pub(crate) inputs: Vec<MotionTensorInfo>,
    pub(crate) widths: Vec<usize>,
    /// State slot of each graph output, in graph order.
    pub(crate) out_slots: Vec<usize>,
    pub(crate) single: Plan,
    pub(crate) batched: Plan,
}

#[derive(Clone, Copy, Debug)]
pub(crate) enum Source {
    Frame(usize),
    State(usize),
}

/// A loaded model. Cheap to clone (one shared allocation), `Send + Sync`: load it once and
/// share it between characters and threads.
#[derive(Clone, Debug)]
pub struct MotionModel {
    pub(crate) inner: Arc<Inner>,
}

/// The recurrent state of one character, created by [`MotionModel::new_state`].
#[derive(Clone, Debug, PartialEq)]
pub struct MotionState {
    pub(crate) slots: Vec<Vec<f32>>,
}

impl MotionState {
    /// Values of state slot `slot` (see [`MotionModel::states`]).
    pub fn slot(&self, slot: usize) -> &[f32] {
        &self.slots[slot]
    }

    /// Mutable values of state slot `slot`, e.g. to set a transition's initial state.
    pub fn slot_mut(&mut self, slot: usize) -> &mut [f32] {
        &mut self.slots[slot]
    }

    /// Number of state slots.
    pub fn slots(&self) -> usize {
        self.slots.len()
    }

    /// Sets every state value to zero.
    pub fn reset(&mut self) {
        for s in &mut self.slots {
            s.fill(0.0);
        }
    }
}

fn read_dims(v: &pb::ValueInfoProto, what: &'static str) -> Result<Vec<usize>, MotionError> {
    use pb::tensor_shape_proto::dimension::Value as D;
    let bad = |reason: String| MotionError::BadGraphIo { what, name: v.name.clone(), reason };
    let Some(pb::TypeProto { value: Some(pb::type_proto::Value::TensorType(t)), .. }) = &v.r#type else {
        return Err(bad("has no tensor type".into()));
    };
    if t.elem_type != pb::tensor_proto::DataType::Float as i32 {
        return Err(bad(format!("has element type {} but step graphs take f32 (1)", t.elem_type)));
    }
    let dims = t.shape.as_ref().map(|s| s.dim.as_slice()).unwrap_or_default();
    let mut out = Vec::new();
    for (i, d) in dims.iter().enumerate() {
        match (i, &d.value) {
            (0, Some(D::DimParam(_))) => {}
            (0, _) => return Err(bad("the first dimension must be the symbolic batch dimension".into())),
            (_, Some(D::DimValue(n))) if *n > 0 => out.push(*n as usize),
            _ => return Err(bad(format!("dimension {i} must be a fixed positive size"))),
        }
    }
    if dims.is_empty() {
        return Err(bad("has no shape; declare [batch, ...]".into()));
    }
    Ok(out)
}

fn plan(model: &InferenceModel, concrete_batch: Option<usize>, dims: &[Vec<usize>]) -> TractResult<Plan> {
    let mut model = model.clone();
    if let Some(b) = concrete_batch {
        for (i, d) in dims.iter().enumerate() {
            let shape: TVec<usize> = std::iter::once(b).chain(d.iter().copied()).collect();
            model.set_input_fact(i, f32::fact(&shape).into())?;
        }
    }
    planned(model)
}

/// A decoded ONNX model, its tract model and the per-character dims of its inputs and outputs.
struct Parsed {
    proto: pb::ModelProto,
    model: InferenceModel,
    in_dims: Vec<Vec<usize>>,
    out_dims: Vec<Vec<usize>>,
}

fn parse(bytes: &[u8], origin: &str) -> Result<Parsed, MotionError> {
    let (proto, model) = read_graph(bytes, origin)?;
    let graph = proto.graph.as_ref().expect("read_graph checked the graph");
    let in_dims = graph.input.iter().map(|v| read_dims(v, "input")).collect::<Result<_, _>>()?;
    let out_dims = graph.output.iter().map(|v| read_dims(v, "output")).collect::<Result<_, _>>()?;
    Ok(Parsed { proto, model, in_dims, out_dims })
}

/// Decodes `bytes` and reads the graph with tract, refusing malformed graphs (and tract's
/// panics on them) with an error naming `origin`. Every loader of the runtime reads through it.
pub(crate) fn read_graph(bytes: &[u8], origin: &str) -> Result<(pb::ModelProto, InferenceModel), MotionError> {
    let not_onnx = |reason: String| MotionError::NotOnnx { origin: origin.to_string(), reason };
    let proto = pb::ModelProto::decode(bytes).map_err(|e| not_onnx(format!("protobuf decoding failed: {e}")))?;
    let model = read_proto(&proto, origin)?;
    Ok((proto, model))
}

/// The tract model of a decoded graph ([`read_graph`] after decoding).
pub(crate) fn read_proto(proto: &pb::ModelProto, origin: &str) -> Result<InferenceModel, MotionError> {
    let not_onnx = |reason: String| MotionError::NotOnnx { origin: origin.to_string(), reason };
    let graph = match &proto.graph {
        Some(g) if proto.ir_version > 0 && !g.node.is_empty() => g,
        _ => return Err(not_onnx("no IR version or no graph nodes".into())),
    };
    check_names(graph).map_err(not_onnx)?;
    // tract 0.23.9 panics on some malformed graphs (found by `fuzz/fuzz_targets/model_load.rs`);
    // `check_names` refuses the known ones first, and a panic left is reported as an error.
    let read = |p: &pb::ModelProto| {
        std::panic::catch_unwind(|| crate::ops::onnx().model_for_proto_model(p))
            .map_err(|_| not_onnx("tract could not read the graph (it panicked on it)".into()))?
            .map_err(|e| MotionError::Unsupported { reason: chain(&e) })
    };
    // The products, LSTM cells and GRU layers as zoo ops (`crate::ops`); the graph as written
    // when the rewrite is off or its result does not read.
    let fused = crate::ops::enabled().then(|| crate::ops::fuse(proto)).flatten();
    match fused.as_ref().map(read) {
        Some(Ok(model)) => Ok(model),
        _ => read(proto),
    }
}

/// The tract model the runtime plans for an exported file's main graph (after the load-time
/// rewrite of [`crate::ops`]): for tools that profile a step graph (`examples/profile_step.rs`),
/// not part of the engine API.
#[doc(hidden)]
pub fn tract_graph(bytes: &[u8]) -> Result<InferenceModel, MotionError> {
    Ok(read_graph(bytes, "the given bytes")?.1)
}

/// `model` optimized and planned as the runtime runs it: its tract ops that the runtime runs
/// into kept tensors swapped for them (`crate::ops::kept`). Public for tools that profile a
/// plan (`examples/profile_step.rs`), not part of the engine API.
#[doc(hidden)]
pub fn planned(model: InferenceModel) -> TractResult<Plan> {
    let mut typed = model.into_optimized()?;
    crate::ops::kept::keep_outputs(&mut typed)?;
    typed.into_runnable()
}

/// Refuses a graph whose outputs or node inputs name a value that no graph input,
/// initializer or node output defines (tract indexes them without checking).
fn check_names(graph: &pb::GraphProto) -> Result<(), String> {
    let mut defined: std::collections::HashSet<&str> = graph.input.iter().map(|v| v.name.as_str()).collect();
    defined.extend(graph.initializer.iter().map(|t| t.name.as_str()));
    for node in &graph.node {
        if let Some(missing) = node.input.iter().find(|i| !i.is_empty() && !defined.contains(i.as_str())) {
            return Err(format!(
                "node `{}` reads `{missing}`, which no input, initializer or earlier node defines",
                node.name
            ));
        }
        defined.extend(node.output.iter().map(String::as_str));
    }
    // tract's raw-data reader has no arm for strings (an `unimplemented!`).
    let attr_tensors = graph.node.iter().flat_map(|n| &n.attribute).flat_map(|a| a.t.iter().chain(&a.tensors));
    if let Some(t) = graph.initializer.iter().chain(attr_tensors).find(|t| !t.raw_data.is_empty() && t.data_type == 8) {
        return Err(format!("tensor `{}` holds strings as raw data, which tract cannot read", t.name));
    }
    match graph.output.iter().find(|o| !defined.contains(o.name.as_str())) {
        Some(o) => Err(format!("graph output `{}` is produced by no node", o.name)),
        None => Ok(()),
    }
}

pub(crate) fn width(d: &[usize]) -> usize {
    d.iter().product()
}

fn plans(p: &Parsed) -> Result<(Plan, Plan), MotionError> {
    let unsupported = |e: TractError| MotionError::Unsupported { reason: chain(&e) };
    let single = plan(&p.model, Some(1), &p.in_dims).map_err(unsupported)?;
    let batched = plan(&p.model, None, &p.in_dims).map_err(unsupported)?;
    Ok((single, batched))
}

fn start_graph(encoded: &str, states: &[MotionStateInfo]) -> Result<StartGraph, MotionError> {
    use base64::Engine;
    let bad = |reason: String| MotionError::from(zoo_format::FormatError::bad(keys::START_GRAPH, reason));
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(encoded.trim())
        .map_err(|e| bad(format!("not base64: {e}")))?;
    let p = parse(&bytes, "the start graph (metadata_props `zoo.start_graph`)")?;
    let graph = p.proto.graph.as_ref().expect("parse checked the graph");
    let mut out_slots = Vec::new();
    for (o, v) in graph.output.iter().enumerate() {
        let Some(k) = states.iter().position(|s| s.input == v.name) else {
            return Err(bad(format!(
                "start graph output `{}` is not a state input of the step graph (states: {})",
                v.name,
                states.iter().map(|s| s.input.as_str()).collect::<Vec<_>>().join(", ")
            )));
        };
        if width(&p.out_dims[o]) != states[k].width || out_slots.contains(&k) {
            return Err(bad(format!(
                "start graph output `{}` has {} values per character, its state has {} (or it appears twice)",
                v.name,
                width(&p.out_dims[o]),
                states[k].width
            )));
        }
        out_slots.push(k);
    }
    let inputs: Vec<MotionTensorInfo> = graph
        .input
        .iter()
        .zip(&p.in_dims)
        .map(|(v, d)| MotionTensorInfo { name: v.name.clone(), width: width(d), dims: d.clone() })
        .collect();
    let (single, batched) = plans(&p)?;
    Ok(StartGraph { widths: inputs.iter().map(|i| i.width).collect(), inputs, out_slots, single, batched })
}

impl MotionModel {
    /// Loads an exported `.onnx` file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, MotionError> {
        let path = path.as_ref();
        Self::from_bytes_named(&crate::loaded::read_file(path)?, &path.display().to_string())
    }

    /// Loads an exported model from its bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MotionError> {
        Self::from_bytes_named(bytes, "the given bytes")
    }

    fn from_bytes_named(bytes: &[u8], origin: &str) -> Result<Self, MotionError> {
        Self::from_parts(bytes, origin, MotionModelMetadata::read(bytes, origin)?)
    }

    /// Loads the step graph of a file whose metadata was read and checked. A `stitch` model is
    /// a window graph, and an in-betweening `keyframes` model a whole-shot graph, not step
    /// graphs: refused with the type that runs them.
    pub(crate) fn from_parts(bytes: &[u8], origin: &str, metadata: MotionModelMetadata) -> Result<Self, MotionError> {
        if metadata.task.kind() == crate::metadata::MotionTaskKind::Stitch {
            return Err(MotionError::wrong_task(&metadata, "step-graph", "MotionModel"));
        }
        if metadata.task.as_keyframes().is_some_and(|t| t.inbetween.is_some()) {
            return Err(MotionError::BadGraphIo {
                what: "input",
                name: "features".into(),
                reason: "the file holds the in-betweening keyframes design, whose whole-shot graph is not a step \
                         graph: load it as a keyframes model"
                    .into(),
            });
        }
        let parsed = parse(bytes, origin)?;
        let Parsed { proto, model, in_dims, out_dims } = &parsed;
        let graph = proto.graph.as_ref().expect("parse checked the graph");
        let get = |key: &str| proto.metadata_props.iter().find(|p| p.key == key).map(|p| p.value.clone());

        let in_pos = |name: &str| graph.input.iter().position(|v| v.name == name);
        let out_pos = |name: &str| graph.output.iter().position(|v| v.name == name);

        let mut graph_inputs: Vec<Option<Source>> = vec![None; graph.input.len()];
        let mut graph_outputs: Vec<Option<Source>> = vec![None; graph.output.len()];
        let mut states = Vec::new();
        for (k, pair) in metadata.state.iter().enumerate() {
            let bad =
                |what, name: &str, reason: String| MotionError::BadGraphIo { what, name: name.to_string(), reason };
            let i = in_pos(&pair.input).ok_or_else(|| {
                bad(
                    "input",
                    &pair.input,
                    format!("is named as a state in `{}` but the graph has no such input", keys::STATE),
                )
            })?;
            let o = out_pos(&pair.output).ok_or_else(|| {
                bad(
                    "output",
                    &pair.output,
                    format!("is named as a state in `{}` but the graph has no such output", keys::STATE),
                )
            })?;
            if in_dims[i] != out_dims[o] {
                return Err(bad(
                    "output",
                    &pair.output,
                    format!("has dims {:?} but its state input `{}` has {:?}", out_dims[o], pair.input, in_dims[i]),
                ));
            }
            if graph_inputs[i].is_some() || graph_outputs[o].is_some() {
                return Err(bad("input", &pair.input, "appears in two state pairs".into()));
            }
            graph_inputs[i] = Some(Source::State(k));
            graph_outputs[o] = Some(Source::State(k));
            states.push(MotionStateInfo {
                input: pair.input.clone(),
                output: pair.output.clone(),
                width: width(&in_dims[i]),
            });
        }
        let mut inputs = Vec::new();
        for (i, v) in graph.input.iter().enumerate() {
            if graph_inputs[i].is_none() {
                graph_inputs[i] = Some(Source::Frame(inputs.len()));
                inputs.push(MotionTensorInfo {
                    name: v.name.clone(),
                    width: width(&in_dims[i]),
                    dims: in_dims[i].clone(),
                });
            }
        }
        let mut outputs = Vec::new();
        for (o, v) in graph.output.iter().enumerate() {
            if graph_outputs[o].is_none() {
                graph_outputs[o] = Some(Source::Frame(outputs.len()));
                outputs.push(MotionTensorInfo {
                    name: v.name.clone(),
                    width: width(&out_dims[o]),
                    dims: out_dims[o].clone(),
                });
            }
        }
        let start = get(keys::START_GRAPH).map(|s| start_graph(&s, &states)).transpose()?;
        let (single, batched) = plans(&parsed)?;
        Ok(MotionModel {
            inner: Arc::new(Inner {
                metadata,
                inputs,
                outputs,
                states,
                graph_inputs: graph_inputs.into_iter().flatten().collect(),
                graph_outputs: graph_outputs.into_iter().flatten().collect(),
                graph_input_widths: in_dims.iter().map(|d| width(d)).collect(),
                single,
                batched,
                source: model.clone(),
                in_dims: in_dims.clone(),
                concrete: Mutex::new(HashMap::new()),
                start,
            }),
        })
    }

    /// The metadata the model was exported with.
    pub fn metadata(&self) -> &MotionModelMetadata {
        &self.inner.metadata
    }

    /// Per-frame inputs (graph inputs that are not state), in the order `step` takes them.
    pub fn inputs(&self) -> &[MotionTensorInfo] {
        &self.inner.inputs
    }

    /// Per-frame outputs (graph outputs that are not state), in the order `step` fills them.
    pub fn outputs(&self) -> &[MotionTensorInfo] {
        &self.inner.outputs
    }

    /// Recurrent state slots, in the order of [`MotionState::slot`].
    pub fn states(&self) -> &[MotionStateInfo] {
        &self.inner.states
    }

    /// Inputs of the transition-start graph, in the order `start` takes them (empty when the
    /// model has no start graph).
    pub fn start_inputs(&self) -> &[MotionTensorInfo] {
        self.inner.start.as_ref().map_or(&[], |s| &s.inputs)
    }

    /// Whether the model carries a transition-start graph (`zoo.start_graph`).
    pub fn has_start_graph(&self) -> bool {
        self.inner.start.is_some()
    }

    /// A zero state for one character.
    pub fn new_state(&self) -> MotionState {
        MotionState { slots: self.inner.states.iter().map(|s| vec![0.0; s.width]).collect() }
    }

    /// A runner: the scratch space of one thread. Keep one per worker thread and reuse it
    /// every frame; it allocates its buffers here and when the batch size changes.
    pub fn runner(&self) -> Result<MotionRunner, MotionError> {
        MotionRunner::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send_sync<T: Send + Sync>() {}
    fn assert_send<T: Send>() {}

    #[test]
    fn thread_safety() {
        assert_send_sync::<MotionModel>();
        assert_send_sync::<MotionState>();
        assert_send::<MotionRunner>();
    }

    #[test]
    fn garbage_is_not_onnx() {
        let not_onnx = |e: &MotionError| matches!(e, MotionError::Format(zoo_format::FormatError::NotOnnx { .. }));
        let err = MotionModel::from_bytes(b"BVH HIERARCHY ROOT Hips { OFFSET 0 0 0 }").unwrap_err();
        assert!(not_onnx(&err), "{err}");
        assert!(err.to_string().contains("zoo export"), "{err}");
        let err = MotionModel::from_bytes(&[]).unwrap_err();
        assert!(not_onnx(&err) && err.to_string().contains("empty"), "{err}");
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let err = MotionModel::load("/nonexistent/model.onnx").unwrap_err();
        assert!(matches!(err, MotionError::Io { .. }), "{err}");
    }
}

#[cfg(test)]
mod name_tests {
    use super::*;

    fn value(name: &str) -> pb::ValueInfoProto {
        pb::ValueInfoProto { name: name.into(), ..Default::default() }
    }

    /// The fuzzer's first find: an output name no node produces made tract panic.
    #[test]
    fn undefined_value_names_are_refused_before_tract_sees_them() {
        let node = pb::NodeProto {
            name: "add".into(),
            input: vec!["x".into(), "x".into()],
            output: vec!["y".into()],
            ..Default::default()
        };
        let mut g = pb::GraphProto {
            node: vec![node],
            input: vec![value("x")],
            output: vec![value("y")],
            ..Default::default()
        };
        assert!(check_names(&g).is_ok());
        g.output[0].name = "\0".into();
        assert!(check_names(&g).unwrap_err().contains("graph output `\0` is produced by no node"));
        g.output[0].name = "y".into();
        g.node[0].input[1] = "z".into();
        assert!(check_names(&g).unwrap_err().contains("node `add` reads `z`"));
        // The second find: string raw data reached an `unimplemented!` in tract.
        g.node[0].input[1] = "x".into();
        g.initializer.push(pb::TensorProto { name: "s".into(), data_type: 8, raw_data: vec![1], ..Default::default() });
        assert!(check_names(&g).unwrap_err().contains("tensor `s` holds strings as raw data"));
    }
}
