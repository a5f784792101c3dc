//! Weight widths (`zoo export --weights f32|f16|int8`): a finished model rewritten with its
//! weight matrices stored in 16 or 8 bits, in standard ONNX operators tract and onnxruntime
//! both run. One pass for every model: it works on the finished graphs (the main graph and the
//! graphs embedded in the metadata, [`zoo_format::keys::EMBEDDED_GRAPHS`]), so no exporter
//! knows about widths.
//!
//! Which initializers are weights: f32 initializers of rank 2 or more whose every use is a
//! matrix operand (`B` of `Gemm` or `MatMul`, directly or through a `Transpose`; `W` and `R`
//! of `LSTM`, `GRU`, `RNN`), except 0/1 selector matrices (kept exact). Biases, statistics and
//! constants stay f32.
//!
//! - `f16`: weight `N` becomes the half-float initializer `N.f16` and a `Cast` node whose
//!   output is `N`: the runtimes widen it once when they load the model (same speed as f32,
//!   half the bytes on disk).
//! - `int8`: weight `N` becomes the 8-bit initializer `N.int8` (same layout) and the f32
//!   scales `N.scale`, one per output channel (symmetric: `w = q * scale`, `q` in -127..=127).
//!   A `Gemm`/`MatMul` that uses it runs as a symmetric 8-bit quantization of each row of its
//!   input (one scale per character, `max|x| / 127` over the row, in elementwise ops),
//!   `MatMulInteger`, a `Cast` to f32, a `Mul` by the channel scales and one by the row's scale
//!   (then the `Gemm`'s bias). Both operands of `MatMulInteger` are u8 with zero point 128
//!   (the weights stored as `q + 128`): x86 CPUs without VNNI (AVX2, AVX-512 without VNNI)
//!   multiply u8 by s8 in pairs summed in saturating 16-bit lanes, which 8-bit weights
//!   overflow (`255 * 127 * 2 > 32767`), while u8 x u8 products are widened to 32 bits first;
//!   so every backend computes the same integers on every x86 class, at full 8-bit precision.
//!   The recurrent ops' `W`/`R` are stored as i8 and widened by `DequantizeLinear` (per
//!   channel, axis 1) to run in f32. Each character is quantized on its own: its outputs do not
//!   depend on the other characters of its call.

use crate::error::ExportError;
use crate::model::OnnxModel;
use crate::ops::{attr_int, attr_ints};
use crate::pb;
use pb::tensor_proto::DataType;
use std::collections::HashMap;
use zoo_format::{WeightWidth, keys};

/// `model` with its weights stored at `width` (see the module documentation), the embedded
/// graphs too, and `zoo.weights` set. `f32` returns the model as is (with `zoo.weights` set).
pub fn with_weights(model: &OnnxModel, width: WeightWidth) -> Result<OnnxModel, ExportError> {
    let mut out = model.clone();
    if width != WeightWidth::F32 {
        if let Some(graph) = &model.proto.graph {
            out.proto.graph = Some(rewrite_graph(graph, width)?);
        }
        for key in keys::EMBEDDED_GRAPHS {
            if let Some(encoded) = model.metadata_value(key) {
                let embedded = OnnxModel::from_base64(encoded, key)?;
                out.set_metadata(key, &with_weights(&embedded, width)?.to_base64());
            }
        }
    }
    if out.metadata_value(keys::WEIGHTS).is_some() || out.metadata_value(keys::FORMAT_VERSION).is_some() {
        out.set_metadata(keys::WEIGHTS, width.name());
    }
    Ok(out)
}

/// How a weight is used, which decides its channel axis and its rewrite.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Use {
    /// `B` of a `Gemm`/`MatMul` in `[in, out]` layout (`MatMul(x, W)`, `Gemm` with `transB = 0`).
    Linear,
    /// `B` of a `Gemm` with `transB = 1`: `[out, in]`.
    LinearTransposed,
    /// `MatMul(x, Transpose(W))`: `[out, in]` through the `Transpose` node.
    ThroughTranspose,
    /// `W` or `R` of a recurrent op: `[dirs, gates * hidden, in]`.
    Recurrent,
}

impl Use {
    /// The output-channel axis of the weight, for a weight of rank `rank`.
    fn axis(self, rank: usize) -> usize {
        match self {
            Use::Linear => rank - 1,
            Use::LinearTransposed | Use::ThroughTranspose => 0,
            Use::Recurrent => 1,
        }
    }
}

fn f32_values(t: &pb::TensorProto) -> Option<Vec<f32>> {
    if t.data_type != DataType::Float as i32 {
        return None;
    }
    Some(if t.raw_data.is_empty() {
        t.float_data.clone()
    } else {
        t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    })
}

fn int_attr(node: &pb::NodeProto, name: &str) -> Option<i64> {
    node.attribute.iter().find(|a| a.name == name).map(|a| a.i)
}

fn float_attr_is_one(node: &pb::NodeProto, name: &str) -> bool {
    node.attribute.iter().find(|a| a.name == name).is_none_or(|a| a.f == 1.0)
}

/// The use of initializer `name` by `node` at input `slot`, when it is a matrix operand.
fn use_of(graph: &pb::GraphProto, node: &pb::NodeProto, slot: usize) -> Option<Use> {
    match (node.op_type.as_str(), slot) {
        ("Gemm", 1)
            if int_attr(node, "transA").unwrap_or(0) == 0
                && float_attr_is_one(node, "alpha")
                && float_attr_is_one(node, "beta") =>
        {
            Some(if int_attr(node, "transB") == Some(1) { Use::LinearTransposed } else { Use::Linear })
        }
        ("MatMul", 1) => Some(Use::Linear),
        ("LSTM" | "GRU" | "RNN", 1 | 2) => Some(Use::Recurrent),
        ("Transpose", 0) => {
            let perm = node.attribute.iter().find(|a| a.name == "perm").map(|a| a.ints.clone());
            let out = node.output.first()?;
            let consumers: Vec<_> = graph.node.iter().filter(|n| n.input.contains(out)).collect();
            let into_matmul = consumers.len() == 1
                && consumers[0].op_type == "MatMul"
                && consumers[0].input.get(1) == Some(out)
                && consumers[0].input.first() != Some(out);
            (perm.as_deref() == Some(&[1, 0]) && into_matmul).then_some(Use::ThroughTranspose)
        }
        _ => None,
    }
}

/// The weights of `graph` and their one use (see the module documentation).
fn weights(graph: &pb::GraphProto) -> HashMap<String, (Use, usize)> {
    let mut uses: HashMap<&str, Vec<(Option<Use>, usize)>> = HashMap::new();
    for (i, node) in graph.node.iter().enumerate() {
        for (slot, input) in node.input.iter().enumerate() {
            uses.entry(input.as_str()).or_default().push((use_of(graph, node, slot), i));
        }
    }
    let mut out = HashMap::new();
    for init in &graph.initializer {
        let Some(values) = f32_values(init) else { continue };
        if init.dims.len() < 2 || values.iter().all(|v| *v == 0.0 || *v == 1.0) {
            continue;
        }
        if let Some([(Some(u), node)]) = uses.get(init.name.as_str()).map(|v| v.as_slice()) {
            out.insert(init.name.clone(), (*u, *node));
        }
    }
    out
}

/// The zero point of both operands of an integer product: activations and weights are u8,
/// `128 + q` for `q` in -127..=127.
pub const ZERO_POINT: u8 = 128;

/// Per-channel symmetric int8 quantization of `values` of shape `dims` along `axis`, `q` in
/// -127..=127: `(q, scales)` with `values ≈ q * scale[channel]`.
pub fn quantize_per_channel(values: &[f32], dims: &[usize], axis: usize) -> (Vec<i8>, Vec<f32>) {
    let channels = dims[axis];
    let inner: usize = dims[axis + 1..].iter().product();
    let channel = |i: usize| (i / inner) % channels;
    let mut max = vec![0f32; channels];
    for (i, v) in values.iter().enumerate() {
        max[channel(i)] = max[channel(i)].max(v.abs());
    }
    let q_max = 127.0;
    let scales: Vec<f32> = max.iter().map(|m| if *m > 0.0 { m / q_max } else { 1.0 }).collect();
    let q = values
        .iter()
        .enumerate()
        .map(|(i, v)| (v / scales[channel(i)]).round_ties_even().clamp(-q_max, q_max) as i8)
        .collect();
    (q, scales)
}

fn tensor(name: String, dims: &[i64], data_type: DataType, raw_data: Vec<u8>) -> pb::TensorProto {
    pb::TensorProto { name, dims: dims.to_vec(), data_type: data_type as i32, raw_data, ..Default::default() }
}

fn node(
    op: &str,
    name: String,
    inputs: &[&str],
    outputs: &[&str],
    attribute: Vec<pb::AttributeProto>,
) -> pb::NodeProto {
    pb::NodeProto {
        name,
        op_type: op.to_string(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: outputs.iter().map(|s| s.to_string()).collect(),
        attribute,
        ..Default::default()
    }
}

/// The nodes that compute `Gemm`/`MatMul` `consumer` with its int8 weight `q` (`[in, out]`)
/// and channel scales `scale`. Each row of the input (one character) is quantized on its own,
/// symmetrically: `s = max|x| / 127` over the row (at least [`MIN_INPUT_SCALE`]), `x / s` in
/// -127..=127 rounded half up
/// and stored as u8 with zero point 128: `Cast(x / s + 128.5)` (`Cast` to an integer
/// truncates, and the value lies in 1.5..=255.5, so no `Round` and no `Clip` are needed), in
/// elementwise ops rather than `DynamicQuantizeLinear`: tract 0.23.9 runs that op element by
/// element in scalar code, slower than the whole integer product it feeds at batch 64
/// (docs/runtime.md). The row scales keep the reduced axis (`[.., rows, 1]`), so they
/// broadcast over the output channels. The channel scales multiply first and the row scales
/// after: onnxruntime 1.31 fuses `MatMulInteger`, `Cast` and a `Mul` by the product of the
/// two scales into `MatMulIntegerToFloat`, which takes one input scale per call and reads a
/// per-row one wrong (0.4 off in normalized units on the test fixture's RTN).
fn integer_matmul(consumer: &pb::NodeProto, q: &str, scale: &str, shared: &SharedConstants) -> Vec<pb::NodeProto> {
    let p = &consumer.name;
    let out = &consumer.output[0];
    let v = |suffix: &str| format!("{p}.int8_{suffix}");
    let scaled = if consumer.op_type == "Gemm" && consumer.input.len() > 2 { v("scaled") } else { out.clone() };
    let x = consumer.input[0].as_str();
    let reduce = vec![attr_int("keepdims", 1), attr_ints("axes", &[-1])];
    let to = |dt: DataType| vec![attr_int("to", dt as i64)];
    let mut nodes = vec![
        node("Abs", v("input_abs"), &[x], &[&v("input_abs")], vec![]),
        node("ReduceMax", v("input_max"), &[&v("input_abs")], &[&v("input_max")], reduce),
        node("Div", v("input_range"), &[&v("input_max"), &shared.q_max], &[&v("input_range")], vec![]),
        node("Max", v("input_scale"), &[&v("input_range"), &shared.min_scale], &[&v("input_scale")], vec![]),
        node("Div", v("input_scaled"), &[x, &v("input_scale")], &[&v("input_scaled")], vec![]),
        node("Add", v("input_offset"), &[&v("input_scaled"), &shared.offset], &[&v("input_offset")], vec![]),
        node("Cast", v("input_q"), &[&v("input_offset")], &[&v("input_q")], to(DataType::Uint8)),
        node(
            "MatMulInteger",
            v("matmul_integer"),
            &[&v("input_q"), q, &shared.zero_point, &shared.zero_point],
            &[&v("accumulated")],
            vec![],
        ),
        node("Cast", v("to_f32"), &[&v("accumulated")], &[&v("accumulated_f32")], to(DataType::Float)),
        node("Mul", v("channels"), &[&v("accumulated_f32"), scale], &[&v("channels")], vec![]),
        node("Mul", v("rescale"), &[&v("channels"), &v("input_scale")], &[&scaled], vec![]),
    ];
    if scaled != *out {
        // `use_of` takes only Gemms with alpha and beta 1: the bias is added as it is.
        nodes.push(node("Add", v("bias"), &[&scaled, &consumer.input[2]], &[out], vec![]));
    }
    nodes
}

/// The smallest input scale of [`integer_matmul`]: an all-zero input quantizes to zeros instead
/// of dividing by zero.
pub const MIN_INPUT_SCALE: f32 = 1e-30;

/// The name prefix of the scalar constants of [`SharedConstants`] (not weights: graph
/// summaries leave them out of the parameter count).
pub const SHARED_PREFIX: &str = "int8.";

/// The scalar constants the integer products of one graph share.
struct SharedConstants {
    /// 127: `max|x|` maps to it.
    q_max: String,
    /// 128.5: the zero point plus the half that turns `Cast`'s truncation into rounding.
    offset: String,
    /// 128, the zero point of the activations and of the weights (`MatMulInteger`'s
    /// `a_zero_point` and `b_zero_point`, u8).
    zero_point: String,
    min_scale: String,
}

impl SharedConstants {
    fn add(graph: &mut pb::GraphProto) -> Self {
        let c = SharedConstants {
            q_max: format!("{SHARED_PREFIX}q_max"),
            offset: format!("{SHARED_PREFIX}offset"),
            zero_point: format!("{SHARED_PREFIX}zero_point"),
            min_scale: format!("{SHARED_PREFIX}min_scale"),
        };
        let floats = [(&c.q_max, 127.0f32), (&c.offset, 128.5), (&c.min_scale, MIN_INPUT_SCALE)];
        for (name, v) in floats {
            graph.initializer.push(tensor(name.clone(), &[], DataType::Float, v.to_le_bytes().to_vec()));
        }
        graph.initializer.push(tensor(c.zero_point.clone(), &[], DataType::Uint8, vec![ZERO_POINT]));
        c
    }
}

/// `graph` with its weights stored at `width`.
fn rewrite_graph(graph: &pb::GraphProto, width: WeightWidth) -> Result<pb::GraphProto, ExportError> {
    let weights = weights(graph);
    let mut out = graph.clone();
    let mut front = Vec::new();
    let mut replaced: HashMap<usize, Vec<pb::NodeProto>> = HashMap::new();
    out.initializer.clear();
    let linear = weights.values().any(|(u, _)| *u != Use::Recurrent);
    let shared = (width == WeightWidth::Int8 && linear).then(|| SharedConstants::add(&mut out));
    for init in &graph.initializer {
        let Some(&(u, consumer)) = weights.get(&init.name) else {
            out.initializer.push(init.clone());
            continue;
        };
        let values = f32_values(init).unwrap_or_default();
        let name = &init.name;
        match width {
            WeightWidth::F32 => out.initializer.push(init.clone()),
            WeightWidth::F16 => {
                let raw = values.iter().flat_map(|v| half::f16::from_f32(*v).to_le_bytes()).collect();
                out.initializer.push(tensor(format!("{name}.f16"), &init.dims, DataType::Float16, raw));
                let to = vec![attr_int("to", DataType::Float as i64)];
                front.push(node("Cast", format!("{name}.widen"), &[&format!("{name}.f16")], &[name], to));
            }
            WeightWidth::Int8 => {
                let dims: Vec<usize> = init.dims.iter().map(|d| (*d).max(0) as usize).collect();
                let axis = u.axis(dims.len());
                let (q, scales) = quantize_per_channel(&values, &dims, axis);
                let (qn, sn) = (format!("{name}.int8"), format!("{name}.scale"));
                // Recurrent weights as i8 for `DequantizeLinear`, the integer products' as u8
                // with zero point 128 (see the module documentation).
                let (data_type, bytes): (DataType, Vec<u8>) = match u {
                    Use::Recurrent => (DataType::Int8, q.iter().map(|v| *v as u8).collect()),
                    _ => (DataType::Uint8, q.iter().map(|v| (i16::from(*v) + i16::from(ZERO_POINT)) as u8).collect()),
                };
                out.initializer.push(tensor(qn.clone(), &init.dims, data_type, bytes));
                let scale_raw = scales.iter().flat_map(|v| v.to_le_bytes()).collect();
                out.initializer.push(tensor(sn.clone(), &[scales.len() as i64], DataType::Float, scale_raw));
                let c = &graph.node[consumer];
                let shared = || shared.as_ref().ok_or_else(|| ExportError::model("no shared int8 constants"));
                match u {
                    Use::Recurrent => {
                        let a = vec![attr_int("axis", axis as i64)];
                        front.push(node("DequantizeLinear", format!("{name}.dequantize"), &[&qn, &sn], &[name], a));
                    }
                    Use::Linear => {
                        replaced.insert(consumer, integer_matmul(c, &qn, &sn, shared()?));
                    }
                    Use::LinearTransposed => {
                        let t = format!("{name}.int8_t");
                        let mut nodes =
                            vec![node("Transpose", t.clone(), &[&qn], &[&t], vec![attr_ints("perm", &[1, 0])])];
                        nodes.extend(integer_matmul(c, &t, &sn, shared()?));
                        replaced.insert(consumer, nodes);
                    }
                    Use::ThroughTranspose => {
                        // The Transpose now moves the bytes; the MatMul it feeds multiplies them.
                        let t = &c.output[0];
                        let matmul = graph.node.iter().position(|n| n.input.get(1) == Some(t)).ok_or_else(|| {
                            ExportError::InvalidOp { node: c.name.clone(), message: "its MatMul is gone".into() }
                        })?;
                        let mut transpose = c.clone();
                        transpose.input[0] = qn.clone();
                        replaced.insert(consumer, vec![transpose]);
                        replaced.insert(matmul, integer_matmul(&graph.node[matmul], t, &sn, shared()?));
                    }
                }
            }
        }
    }
    out.node = front;
    for (i, n) in graph.node.iter().enumerate() {
        match replaced.remove(&i) {
            Some(nodes) => out.node.extend(nodes),
            None => out.node.push(n.clone()),
        }
    }
    let mut seen = std::collections::HashSet::new();
    let names = out.initializer.iter().map(|t| &t.name).chain(out.node.iter().flat_map(|n| &n.output));
    for name in names.chain(out.input.iter().map(|i| &i.name)) {
        if !name.is_empty() && !seen.insert(name) {
            return Err(ExportError::DuplicateName(name.clone()));
        }
    }
    Ok(out)
}

/// The f32 values of every weight of `graph` by its name, in its original layout, whatever
/// the width it is stored in (the inverse of [`with_weights`] up to rounding): f32
/// initializers as they are, `N.f16` widened, `N.int8` (i8, or u8 less 128) times `N.scale`. What tools that
/// rebuild the model elsewhere (candle in `zoo bench runtime`) read.
pub fn weight_values(graph: &pb::GraphProto) -> Result<HashMap<String, (Vec<usize>, Vec<f32>)>, ExportError> {
    let bad = |name: &str, why: &str| ExportError::model(format!("initializer `{name}`: {why}"));
    let scales: HashMap<&str, Vec<f32>> =
        graph.initializer.iter().filter_map(|t| Some((t.name.as_str(), f32_values(t)?))).collect();
    let mut out = HashMap::new();
    for t in &graph.initializer {
        let dims: Vec<usize> = t.dims.iter().map(|d| (*d).max(0) as usize).collect();
        let n: usize = dims.iter().product();
        let (name, values) = if let Some(base) = t.name.strip_suffix(".f16") {
            let v: Vec<f32> =
                t.raw_data.chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect();
            (base.to_string(), v)
        } else if let Some(base) = t.name.strip_suffix(".int8") {
            let scale = scales.get(format!("{base}.scale").as_str()).ok_or_else(|| bad(&t.name, "no scales"))?;
            // The channel axis: the one whose length is the number of scales, read from how the
            // graph uses the bytes when two axes have that length.
            let consumer = graph.node.iter().find(|n| n.input.contains(&t.name));
            let axis = match consumer.map(|c| c.op_type.as_str()) {
                Some("DequantizeLinear") => consumer.and_then(|c| int_attr(c, "axis")).unwrap_or(1) as usize,
                Some("Transpose") => 0,
                _ => dims.len() - 1,
            };
            if dims.get(axis) != Some(&scale.len()) {
                return Err(bad(&t.name, "its scales do not match its channels"));
            }
            let inner: usize = dims[axis + 1..].iter().product();
            let unsigned = t.data_type == DataType::Uint8 as i32;
            let q = |b: u8| if unsigned { f32::from(b) - f32::from(ZERO_POINT) } else { f32::from(b as i8) };
            let v = t.raw_data.iter().enumerate().map(|(i, b)| q(*b) * scale[(i / inner) % scale.len()]);
            (base.to_string(), v.collect())
        } else if let Some(v) = f32_values(t) {
            (t.name.clone(), v)
        } else {
            continue;
        };
        if values.len() != n {
            return Err(bad(&t.name, &format!("{} values for shape {dims:?}", values.len())));
        }
        out.entry(name).or_insert((dims, values));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Dim, GraphBuilder};

    /// `y = Gemm(x, W^T, b)` then `MatMul(y, Transpose(V))`, and a 0/1 selector `S`:
    /// `z = MatMul(y, S)`; the model carries `g` as an embedded start graph.
    fn tiny(embed: Option<&OnnxModel>) -> OnnxModel {
        let mut g = GraphBuilder::new("tiny");
        let x = g.input("x", &[Dim::batch(), Dim::Fixed(3)]);
        let w = g.initializer_f32("l0.weight", &[2, 3], &[0.5, -1.0, 0.25, 2.0, 0.0, -0.125]);
        let b = g.initializer_f32("l0.bias", &[2], &[0.1, -0.2]);
        let y = g.gemm("l0", &x, &w, Some(&b), true);
        let v = g.initializer_f32("l1.weight", &[2, 2], &[1.5, -0.5, 0.75, 0.3]);
        let vt = g.transpose("l1.weight_t", &v, &[1, 0]);
        let y = g.matmul("l1.matmul", &y, &vt);
        let s = g.initializer_f32("select", &[2, 2], &[0.0, 1.0, 1.0, 0.0]);
        let z = g.matmul("select.matmul", &y, &s);
        g.output("z", &z, &[Dim::batch(), Dim::Fixed(2)]);
        g.metadata(keys::WEIGHTS, "f32");
        if let Some(e) = embed {
            g.metadata(keys::START_GRAPH, &e.to_base64());
        }
        g.finish().unwrap()
    }

    fn ops(m: &OnnxModel) -> Vec<String> {
        m.summary().op_counts.into_keys().collect()
    }

    #[test]
    fn per_channel_quantization_is_within_half_a_step() {
        let values = [0.5, -1.0, 0.25, 2.0, 0.0, -0.125];
        let (q, scales) = quantize_per_channel(&values, &[2, 3], 0);
        assert_eq!(scales, vec![1.0 / 127.0, 2.0 / 127.0]);
        assert_eq!(q[1], -127);
        for (i, v) in values.iter().enumerate() {
            assert!((q[i] as f32 * scales[i / 3] - v).abs() <= scales[i / 3] / 2.0);
        }
        let (_, columns) = quantize_per_channel(&values, &[2, 3], 1);
        assert_eq!(columns, vec![2.0 / 127.0, 1.0 / 127.0, 0.25 / 127.0]);
        let (q, scales) = quantize_per_channel(&[0.0; 4], &[2, 2], 0);
        assert_eq!((q, scales), (vec![0; 4], vec![1.0, 1.0]), "an all-zero channel gets scale 1, not a division by 0");
    }

    #[test]
    fn widths_rewrite_weights_only_and_read_back() {
        let f32_model = tiny(Some(&tiny(None)));
        let original = weight_values(f32_model.proto().graph.as_ref().unwrap()).unwrap();
        for width in WeightWidth::ALL {
            let m = with_weights(&f32_model, width).unwrap();
            assert_eq!(m.metadata_value(keys::WEIGHTS), Some(width.name()));
            assert_eq!(m.summary().parameters, f32_model.summary().parameters, "{width}");
            let graph = m.proto().graph.as_ref().unwrap();
            let read = weight_values(graph).unwrap();
            for name in ["l0.weight", "l1.weight", "l0.bias", "select"] {
                let (dims, want) = &original[name];
                let (got_dims, got) = &read[name];
                assert_eq!(dims, got_dims, "{width} {name}");
                let step = match (width, name) {
                    (WeightWidth::Int8, "l0.weight" | "l1.weight") => 2.0 / 127.0 / 2.0,
                    (WeightWidth::F16, _) => 1e-3,
                    _ => 0.0,
                };
                for (a, b) in want.iter().zip(got) {
                    assert!((a - b).abs() <= step, "{width} {name}: {a} read back as {b}");
                }
            }
            let embedded = OnnxModel::from_base64(m.metadata_value(keys::START_GRAPH).unwrap(), "start").unwrap();
            assert_eq!(ops(&embedded), ops(&m), "{width}: the embedded graph is rewritten like the main one");
            let bias = graph.initializer.iter().find(|t| t.name == "l0.bias").unwrap();
            assert_eq!(bias.data_type, DataType::Float as i32, "{width}: biases stay f32");
        }
        let int8 = with_weights(&f32_model, WeightWidth::Int8).unwrap();
        assert_eq!(int8.summary().op_counts["MatMulInteger"], 2, "both linear layers run in integers");
        assert_eq!(int8.summary().op_counts["MatMul"], 1, "the 0/1 selector stays an exact f32 MatMul");
        let graph = int8.proto().graph.as_ref().unwrap();
        let bytes = graph.initializer.iter().find(|t| t.name == "l0.weight.int8").unwrap();
        assert_eq!(bytes.data_type, DataType::Uint8 as i32, "the integer products' weights are u8");
        assert_eq!(bytes.raw_data[1], 128 - 127, "-1.0, the channel's largest magnitude, is 128 - 127");
        for n in graph.node.iter().filter(|n| n.op_type == "MatMulInteger") {
            assert_eq!(n.input.len(), 4, "both zero points given: {:?}", n.input);
            assert_eq!(n.input[2], n.input[3], "activations and weights share zero point 128");
        }
        let reduce = graph.node.iter().find(|n| n.op_type == "ReduceMax").unwrap();
        let keep = reduce.attribute.iter().find(|a| a.name == "keepdims").map(|a| a.i);
        let axes = reduce.attribute.iter().find(|a| a.name == "axes").map(|a| a.ints.clone());
        assert_eq!((keep, axes), (Some(1), Some(vec![-1])), "one activation scale per row");
        let f16 = with_weights(&f32_model, WeightWidth::F16).unwrap();
        assert_eq!(f16.summary().op_counts["Cast"], 2);
        let half = f16.proto().graph.as_ref().unwrap().initializer.iter().find(|t| t.name == "l0.weight.f16").unwrap();
        assert_eq!((half.data_type, half.raw_data.len()), (DataType::Float16 as i32, 12), "2 bytes a weight");
    }

    #[test]
    fn recurrent_weights_are_dequantized_along_their_gates() {
        let mut g = GraphBuilder::new("gru");
        let x = g.input("x", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(2)]);
        let w: Vec<f32> = (0..18).map(|i| (i as f32 - 9.0) / 7.0).collect();
        let r: Vec<f32> = (0..27).map(|i| (i as f32 - 13.0) / 11.0).collect();
        let w = g.initializer_f32("gru.W", &[1, 9, 2], &w);
        let r = g.initializer_f32("gru.R", &[1, 9, 3], &r);
        let rnn = crate::RnnInputs {
            x: &x,
            w: &w,
            r: &r,
            b: None,
            initial_h: None,
            hidden_size: 3,
            direction: crate::RnnDirection::Forward,
        };
        let o = g.gru("gru", &rnn, true);
        g.output("h", &o.y_h, &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(3)]);
        let m = g.finish().unwrap();
        let q = with_weights(&m, WeightWidth::Int8).unwrap();
        assert_eq!(q.summary().op_counts["DequantizeLinear"], 2);
        let graph = q.proto().graph.as_ref().unwrap();
        let scale = graph.initializer.iter().find(|t| t.name == "gru.W.scale").unwrap();
        assert_eq!(scale.dims, vec![9], "one scale per gate row");
        let read = weight_values(graph).unwrap();
        let want = weight_values(m.proto().graph.as_ref().unwrap()).unwrap();
        for (a, b) in want["gru.R"].1.iter().zip(&read["gru.R"].1) {
            assert!((a - b).abs() <= 13.0 / 11.0 / 127.0 / 2.0 + 1e-7);
        }
    }
}
