//! The time-chunked form of a window graph, for work spread over several calls: each `GRU` node
//! over a window of `frames` frames is rewritten as a chain of `GRU` nodes over `chunk` frames
//! each, the state of one chunk the initial state of the next (the backward direction of a
//! bidirectional layer runs forward over the frames in reverse order, which `Gather` makes).
//! The result is the same function, written in standard ONNX nodes: no node of the chunked
//! graph works on more than `chunk` frames of a layer, so a caller that runs it node by node
//! (`tract`'s `SimpleState::compute_one`) can stop after any chunk. Nodes it does not recognise
//! (LSTM, GRU with sequence lengths, an initial state or a used final state) are left whole.

use super::attr;
use tract_onnx::pb;

type Dt = pb::tensor_proto::DataType;

fn int64s(name: &str, values: &[i64]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims: vec![values.len() as i64],
        data_type: Dt::Int64 as i32,
        int64_data: values.to_vec(),
        ..Default::default()
    }
}

fn node(
    op: &str,
    name: String,
    inputs: Vec<String>,
    outputs: Vec<String>,
    attrs: Vec<pb::AttributeProto>,
) -> pb::NodeProto {
    pb::NodeProto { op_type: op.into(), name, input: inputs, output: outputs, attribute: attrs, ..Default::default() }
}

/// The node that widens a stored weight into `name`, as `zoo export --weights` writes them: a
/// `Cast` of an f16 initializer, or a `DequantizeLinear` of an int8 one by channels of axis 1
/// (which a slice along axis 0 keeps).
fn widened_by<'g>(graph: &'g pb::GraphProto, name: &str) -> Option<&'g pb::NodeProto> {
    let n = graph.node.iter().find(|n| n.output.first().is_some_and(|o| o == name))?;
    let axis = n.attribute.iter().find(|a| a.name == "axis").map_or(1, |a| a.i);
    let ok = match n.op_type.as_str() {
        "Cast" => n.input.len() == 1,
        "DequantizeLinear" => axis == 1 && (n.input.len() == 2 || n.input.get(2).is_some_and(|z| z.is_empty())),
        _ => false,
    };
    (ok && n.domain.is_empty() && graph.initializer.iter().any(|t| t.name == n.input[0])).then_some(n)
}

/// Direction `d` of `dirs` of a recurrent weight initializer `[dirs, ...]` as an initializer
/// `[1, ...]` named `name`, when its values are stored in a way this reads.
fn direction_of(t: &pb::TensorProto, d: usize, dirs: usize, name: &str) -> Option<pb::TensorProto> {
    if t.dims.first() != Some(&(dirs as i64)) || t.external_data.len() > 0 {
        return None;
    }
    let mut dims = t.dims.clone();
    dims[0] = 1;
    let part = |len: usize| (len % dirs == 0).then(|| (d * len / dirs, (d + 1) * len / dirs));
    let mut out = pb::TensorProto { name: name.into(), dims, data_type: t.data_type, ..Default::default() };
    if !t.raw_data.is_empty() {
        let (a, b) = part(t.raw_data.len())?;
        out.raw_data = t.raw_data[a..b].to_vec();
    } else if !t.float_data.is_empty() {
        let (a, b) = part(t.float_data.len())?;
        out.float_data = t.float_data[a..b].to_vec();
    } else if !t.int32_data.is_empty() {
        let (a, b) = part(t.int32_data.len())?;
        out.int32_data = t.int32_data[a..b].to_vec();
    } else {
        return None;
    }
    Some(out)
}

/// The graph of `proto` with its GRU nodes over `frames` frames in chunks of at most `chunk`
/// frames, or `None` when it has none to chunk.
pub(crate) fn chunk_recurrences(proto: &pb::ModelProto, frames: usize, chunk: usize) -> Option<pb::ModelProto> {
    let graph = proto.graph.as_ref()?;
    if chunk == 0 || frames <= chunk {
        return None;
    }
    let used: std::collections::HashSet<&str> = graph
        .node
        .iter()
        .flat_map(|n| n.input.iter().map(String::as_str))
        .chain(graph.output.iter().map(|o| o.name.as_str()))
        .collect();
    let mut nodes = Vec::with_capacity(graph.node.len());
    let mut inits = Vec::new();
    let mut changed = false;
    for n in &graph.node {
        let attr_i = |name: &str| n.attribute.iter().find(|a| a.name == name).map(|a| a.i);
        let direction =
            n.attribute.iter().find(|a| a.name == "direction").map(|a| a.s.as_slice()).unwrap_or(b"forward");
        let dirs = match direction {
            b"forward" => 1,
            b"bidirectional" => 2,
            _ => 0,
        };
        let plain = n.op_type == "GRU"
            && n.domain.is_empty()
            && dirs > 0
            && (3..=4).contains(&n.input.len())
            && !n.output.is_empty()
            && !n.output[0].is_empty()
            && n.output.iter().skip(1).all(|o| o.is_empty() || !used.contains(o.as_str()))
            && attr_i("layout").unwrap_or(0) == 0
            && n.attribute
                .iter()
                .all(|a| ["hidden_size", "linear_before_reset", "direction", "layout"].contains(&a.name.as_str()));
        if !plain {
            nodes.push(n.clone());
            continue;
        }
        changed = true;
        let p = format!("{}.zoo_chunk", n.name);
        let (x, w, r) = (&n.input[0], &n.input[1], &n.input[2]);
        let b = n.input.get(3).filter(|b| !b.is_empty());
        let gru_attrs: Vec<pb::AttributeProto> =
            n.attribute.iter().filter(|a| a.name != "direction").cloned().collect();
        let mut directions = Vec::with_capacity(dirs);
        for d in 0..dirs {
            // This direction's weights: `[1, ...]` slices of `[dirs, ...]`.
            let (starts, ends, axes) = (format!("{p}.d{d}.starts"), format!("{p}.d{d}.ends"), format!("{p}.axes0"));
            inits.push(int64s(&starts, &[d as i64]));
            inits.push(int64s(&ends, &[d as i64 + 1]));
            if d == 0 {
                inits.push(int64s(&axes, &[0]));
            }
            let mut weights = Vec::new();
            for (tag, input) in [("w", Some(w)), ("r", Some(r)), ("b", b)] {
                let Some(input) = input else { continue };
                let out = format!("{p}.d{d}.{tag}");
                // A constant slice of an initializer (tract runs a GRU with constant weights as
                // one fused op, as it does the whole layer), of the f16 or int8 initializer a
                // weight is widened from, else a Slice node.
                let init = |name: &str, out: &str| {
                    graph.initializer.iter().find(|t| t.name == name).and_then(|t| direction_of(t, d, dirs, out))
                };
                if let Some(t) = init(input, &out) {
                    inits.push(t);
                } else if let Some((t, widen)) = widened_by(graph, input).and_then(|w| {
                    let stored = format!("{out}.stored");
                    let mut widen = w.clone();
                    widen.name = format!("{out}.widen");
                    widen.input[0] = stored.clone();
                    widen.output = vec![out.clone()];
                    Some((init(&w.input[0], &stored)?, widen))
                }) {
                    inits.push(t);
                    nodes.push(widen);
                } else {
                    nodes.push(node(
                        "Slice",
                        out.clone(),
                        vec![input.clone(), starts.clone(), ends.clone(), axes.clone()],
                        vec![out.clone()],
                        vec![],
                    ));
                }
                weights.push(out);
            }
            // Chunk `c` covers frames `c * chunk..` of the direction's order (reversed for the
            // backward direction).
            let mut ys = Vec::new();
            let mut h: Option<String> = None;
            let count = frames.div_ceil(chunk);
            for c in 0..count {
                let (from, to) = (c * chunk, ((c + 1) * chunk).min(frames));
                let order: Vec<i64> =
                    (from..to).map(|t| if d == 0 { t as i64 } else { (frames - 1 - t) as i64 }).collect();
                let idx = format!("{p}.d{d}.c{c}.frames");
                inits.push(int64s(&idx, &order));
                let xc = format!("{p}.d{d}.c{c}.x");
                nodes.push(node(
                    "Gather",
                    xc.clone(),
                    vec![x.clone(), idx],
                    vec![xc.clone()],
                    vec![attr::int("axis", 0)],
                ));
                let mut inputs = vec![xc];
                inputs.extend(weights.iter().cloned());
                if let Some(h) = &h {
                    // No bias keeps its slot empty; no sequence lengths.
                    inputs.resize(5, String::new());
                    inputs.push(h.clone());
                }
                let (y, yh) = (format!("{p}.d{d}.c{c}.y"), format!("{p}.d{d}.c{c}.h"));
                nodes.push(node(
                    "GRU",
                    format!("{p}.d{d}.c{c}"),
                    inputs,
                    vec![y.clone(), yh.clone()],
                    gru_attrs.clone(),
                ));
                ys.push(y);
                h = Some(yh);
            }
            let cat = format!("{p}.d{d}.y");
            nodes.push(node("Concat", cat.clone(), ys, vec![cat.clone()], vec![attr::int("axis", 0)]));
            if d == 0 {
                directions.push(cat);
            } else {
                // Back to the window's frame order.
                let idx = format!("{p}.d{d}.order");
                inits.push(int64s(&idx, &(0..frames as i64).rev().collect::<Vec<_>>()));
                let back = format!("{p}.d{d}.y_ordered");
                nodes.push(node(
                    "Gather",
                    back.clone(),
                    vec![cat, idx],
                    vec![back.clone()],
                    vec![attr::int("axis", 0)],
                ));
                directions.push(back);
            }
        }
        let y = n.output[0].clone();
        if dirs == 1 {
            nodes.push(node("Identity", format!("{p}.y"), directions, vec![y], vec![]));
        } else {
            nodes.push(node("Concat", format!("{p}.y"), directions, vec![y], vec![attr::int("axis", 1)]));
        }
    }
    if !changed {
        return None;
    }
    let mut g = graph.clone();
    g.node = nodes;
    g.initializer.extend(inits);
    let mut out = proto.clone();
    out.graph = Some(g);
    Some(out)
}

/// `proto` (a graph after [`super::fuse`]) with every [`super::ZOO_DENSE`] node split into nodes
/// of at most `chunk` frames of its input's first axis when it is planned
/// ([`super::FRAME_CHUNK`]): the same function, for a caller that runs the graph node by node.
pub(crate) fn chunk_dense(proto: &mut pb::ModelProto, chunk: usize) {
    let Some(graph) = proto.graph.as_mut() else { return };
    for n in graph.node.iter_mut().filter(|n| n.op_type == super::ZOO_DENSE && n.domain == super::DOMAIN) {
        n.attribute.retain(|a| a.name != super::FRAME_CHUNK);
        n.attribute.push(attr::int(super::FRAME_CHUNK, chunk as i64));
    }
}
