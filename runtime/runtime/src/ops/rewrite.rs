//! The load-time rewrite: finds, in a decoded ONNX graph, the products zoo's exporters write
//! (in f32, f16 or int8), the LSTM cells built from them and the `GRU` nodes, and replaces each
//! by zoo nodes ([`super::ZOO_DENSE`], [`super::ZOO_LSTM`], [`super::ZOO_GRU`]) that name their
//! weights by initializer. Nodes it
//! does not recognise are left as they are; so is the file on disk (standard ONNX).
//!
//! A product is, with `W` an initializer (f32, or f16 widened by a `Cast`):
//! `Gemm(x, W, C)` (alpha = beta = 1, transA = 0; `C` a constant bias or a per-character
//! tensor), `MatMul(x, W)`, `MatMul(x, Transpose(W))`, optionally followed by `Add` of a
//! constant bias; or the int8 chain of `zoo_export::with_weights` (per-row quantization,
//! `MatMulInteger` on u8 weights with zero point 128, `Cast`, `Mul` by the channel scales, `Mul`
//! by the row scale, optionally the bias `Add`). A dense node is a product optionally followed
//! by `LeakyRelu`/`Relu`. An LSTM cell is `Split` in 4 equal blocks of a sum of products,
//! constant biases and per-character tensors, then `i, f, o = sigmoid`, `g = tanh` (blocks in
//! the order i, f, g, o), `c' = f * c + i * g`, `h' = o * tanh(c')`.

use super::attr;
use std::collections::{HashMap, HashSet};
use tract_onnx::pb;

type Dt = pb::tensor_proto::DataType;

/// A product found in the graph.
#[derive(Clone, Debug)]
struct Product {
    x: String,
    /// Initializer holding the weights.
    weight: String,
    /// Whether it is stored `[out, in]` (else `[in, out]`).
    transposed: bool,
    /// int8: the channel scales' initializer.
    scale: Option<String>,
    /// A constant bias (initializer name).
    bias: Option<String>,
    /// A per-character addend (tensor name).
    addend: Option<String>,
    out: String,
    /// Output channels.
    m: usize,
    nodes: Vec<usize>,
}

struct Index<'g> {
    g: &'g pb::GraphProto,
    inits: HashMap<&'g str, &'g pb::TensorProto>,
    producer: HashMap<&'g str, usize>,
    consumers: HashMap<&'g str, Vec<usize>>,
    outputs: HashSet<&'g str>,
}

fn get_attr<'n>(node: &'n pb::NodeProto, name: &str) -> Option<&'n pb::AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

fn int_attr(node: &pb::NodeProto, name: &str, default: i64) -> i64 {
    get_attr(node, name).map_or(default, |a| a.i)
}

fn float_attr(node: &pb::NodeProto, name: &str, default: f32) -> f32 {
    get_attr(node, name).map_or(default, |a| a.f)
}

impl<'g> Index<'g> {
    fn new(g: &'g pb::GraphProto) -> Self {
        let mut producer = HashMap::new();
        let mut consumers: HashMap<&str, Vec<usize>> = HashMap::new();
        for (i, n) in g.node.iter().enumerate() {
            for o in &n.output {
                producer.insert(o.as_str(), i);
            }
            for input in &n.input {
                consumers.entry(input.as_str()).or_default().push(i);
            }
        }
        Index {
            g,
            inits: g.initializer.iter().map(|t| (t.name.as_str(), t)).collect(),
            producer,
            consumers,
            outputs: g.output.iter().map(|o| o.name.as_str()).collect(),
        }
    }

    fn node(&self, tensor: &str) -> Option<(usize, &'g pb::NodeProto)> {
        self.producer.get(tensor).map(|&i| (i, &self.g.node[i]))
    }

    fn node_op(&self, tensor: &str, op: &str) -> Option<(usize, &'g pb::NodeProto)> {
        self.node(tensor).filter(|(_, n)| n.op_type == op)
    }

    /// The one node reading `tensor`, when it is not also a graph output.
    fn only_consumer(&self, tensor: &str) -> Option<usize> {
        match self.consumers.get(tensor).map(Vec::as_slice) {
            Some([one]) if !self.outputs.contains(tensor) => Some(*one),
            _ => None,
        }
    }

    fn elements(t: &pb::TensorProto) -> usize {
        t.dims.iter().product::<i64>().max(0) as usize
    }

    /// The f32 values of a constant: an initializer, f32 or f16 (as `zoo export --weights f16`
    /// writes them: a `Cast` to f32 of an f16 initializer).
    fn float_init(&self, name: &str) -> Option<&'g pb::TensorProto> {
        if let Some(t) = self.inits.get(name) {
            return (t.data_type == Dt::Float as i32).then_some(*t);
        }
        let (_, cast) = self.node_op(name, "Cast")?;
        let t = self.inits.get(cast.input.first()?.as_str())?;
        (int_attr(cast, "to", 0) == Dt::Float as i64 && t.data_type == Dt::Float16 as i32).then_some(*t)
    }

    /// The f32 values of a recurrent op's weight and how the file stores them: an f32 or f16
    /// constant ([`Self::float_init`]), or int8 widened by `DequantizeLinear` per channel of
    /// axis 1 without a zero point (as `zoo export --weights int8` writes a `GRU`'s), whose
    /// values are `q * scale` in f32, as `DequantizeLinear` computes them.
    fn recurrent_values(&self, name: &str) -> Option<(Vec<i64>, Vec<f32>, Stored)> {
        if let Some(t) = self.float_init(name) {
            return Some((t.dims.clone(), super::tensor_f32(t)?, Stored::Float));
        }
        let (_, dq) = self.node_op(name, "DequantizeLinear")?;
        if dq.input.get(2).is_some_and(|z| !z.is_empty()) || int_attr(dq, "axis", 1) != 1 {
            return None;
        }
        let q = self.inits.get(dq.input.first()?.as_str())?;
        let s = self.inits.get(dq.input.get(1)?.as_str())?;
        let dims: Vec<usize> = q.dims.iter().map(|d| (*d).max(0) as usize).collect();
        if q.data_type != Dt::Int8 as i32 || dims.len() != 3 || q.raw_data.len() != Self::elements(q) {
            return None;
        }
        let scales = (s.data_type == Dt::Float as i32).then(|| super::tensor_f32(s)).flatten()?;
        if scales.len() != dims[1] {
            return None;
        }
        let q: Vec<i8> = q.raw_data.iter().map(|b| *b as i8).collect();
        let values = q.iter().enumerate().map(|(i, v)| f32::from(*v) * scales[(i / dims[2]) % dims[1]]).collect();
        Some((dims.iter().map(|d| *d as i64).collect(), values, Stored::I8 { q, scales }))
    }

    fn scalar(&self, name: &str) -> Option<f32> {
        let t = self.inits.get(name)?;
        if Self::elements(t) != 1 || t.data_type != Dt::Float as i32 {
            return None;
        }
        Some(match t.raw_data.as_slice() {
            [a, b, c, d] => f32::from_le_bytes([*a, *b, *c, *d]),
            _ => *t.float_data.first()?,
        })
    }

    fn is_u8_128(&self, name: &str) -> bool {
        self.inits.get(name).is_some_and(|t| {
            t.data_type == Dt::Uint8 as i32
                && Self::elements(t) == 1
                && (t.raw_data == [128] || t.int32_data.first() == Some(&128))
        })
    }

    /// A rank-2 weight behind `name`: the initializer's name, whether it is `[out, in]` and the
    /// `Transpose` node passed through, if any.
    fn weight(&self, name: &str, int8: bool) -> Option<(String, bool, Option<usize>)> {
        let direct = |n: &str| -> Option<String> {
            if int8 {
                let t = self.inits.get(n)?;
                (t.data_type == Dt::Uint8 as i32 && t.dims.len() == 2).then(|| t.name.clone())
            } else {
                let t = self.float_init(n)?;
                (t.dims.len() == 2).then(|| t.name.clone())
            }
        };
        if let Some(w) = direct(name) {
            return Some((w, false, None));
        }
        let (i, t) = self.node_op(name, "Transpose")?;
        let perm = get_attr(t, "perm").map(|a| a.ints.clone());
        if perm.as_deref() != Some(&[1, 0]) || self.only_consumer(name).is_none() {
            return None;
        }
        Some((direct(t.input.first()?)?, true, Some(i)))
    }

    fn dims(&self, init: &str) -> Vec<usize> {
        self.inits[init].dims.iter().map(|d| (*d).max(0) as usize).collect()
    }

    /// The product whose result is `out`.
    fn product(&self, out: &str) -> Option<Product> {
        let (i, node) = self.node(out)?;
        match node.op_type.as_str() {
            "Gemm" => {
                let ok = int_attr(node, "transA", 0) == 0
                    && float_attr(node, "alpha", 1.0) == 1.0
                    && float_attr(node, "beta", 1.0) == 1.0;
                if !ok || node.input.len() < 2 {
                    return None;
                }
                let (weight, _, _) = self.weight(&node.input[1], false)?;
                let transposed = int_attr(node, "transB", 0) == 1;
                let d = self.dims(&weight);
                let m = if transposed { d[0] } else { d[1] };
                let (mut bias, mut addend) = (None, None);
                if let Some(c) = node.input.get(2).filter(|c| !c.is_empty()) {
                    match self.float_init(c) {
                        Some(t) if Self::elements(t) == m && t.dims.len() <= 2 => bias = Some(t.name.clone()),
                        Some(_) => return None,
                        None => addend = Some(c.clone()),
                    }
                }
                Some(Product {
                    x: node.input[0].clone(),
                    weight,
                    transposed,
                    scale: None,
                    bias,
                    addend,
                    out: out.to_string(),
                    m,
                    nodes: vec![i],
                })
            }
            "MatMul" => {
                let (weight, transposed, t) = self.weight(&node.input[1], false)?;
                let d = self.dims(&weight);
                let m = if transposed { d[0] } else { d[1] };
                Some(Product {
                    x: node.input[0].clone(),
                    weight,
                    transposed,
                    scale: None,
                    bias: None,
                    addend: None,
                    out: out.to_string(),
                    m,
                    nodes: std::iter::once(i).chain(t).collect(),
                })
            }
            "Add" => {
                // A product then a constant bias.
                for (p, b) in [(0, 1), (1, 0)] {
                    let (Some(pn), Some(bn)) = (node.input.get(p), node.input.get(b)) else { return None };
                    let Some(bias) = self.float_init(bn) else { continue };
                    if self.only_consumer(pn) != Some(i) {
                        continue;
                    }
                    let Some(mut prod) = self.product(pn) else { continue };
                    if prod.bias.is_some()
                        || prod.addend.is_some()
                        || Self::elements(bias) != prod.m
                        || bias.dims.len() > 2
                    {
                        continue;
                    }
                    prod.bias = Some(bias.name.clone());
                    prod.out = out.to_string();
                    prod.nodes.push(i);
                    return Some(prod);
                }
                None
            }
            "Mul" => self.int8_product(out),
            _ => None,
        }
    }

    /// The int8 chain of `zoo_export::with_weights` ending with the `Mul` by the row scale.
    fn int8_product(&self, out: &str) -> Option<Product> {
        let (rescale_i, rescale) = self.node_op(out, "Mul")?;
        let (channels_i, channels) = self.node_op(&rescale.input[0], "Mul")?;
        let row_scale = rescale.input.get(1)?;
        let scale = self.inits.get(channels.input.get(1)?.as_str())?;
        let (to_f32_i, to_f32) = self.node_op(&channels.input[0], "Cast")?;
        let (mmi_i, mmi) = self.node_op(&to_f32.input[0], "MatMulInteger")?;
        if mmi.input.len() != 4 || !self.is_u8_128(&mmi.input[2]) || !self.is_u8_128(&mmi.input[3]) {
            return None;
        }
        let (q_i, q) = self.node_op(&mmi.input[0], "Cast")?;
        let (offset_i, offset) = self.node_op(&q.input[0], "Add")?;
        let (scaled_i, scaled) = self.node_op(&offset.input[0], "Div")?;
        let x = scaled.input.first()?;
        if scaled.input.get(1) != Some(row_scale)
            || self.scalar(offset.input.get(1)?) != Some(128.5)
            || int_attr(q, "to", 0) != Dt::Uint8 as i64
            || int_attr(to_f32, "to", 0) != Dt::Float as i64
        {
            return None;
        }
        let (floor_i, floor) = self.node_op(row_scale, "Max")?;
        let (range_i, range) = self.node_op(&floor.input[0], "Div")?;
        let (max_i, max) = self.node_op(&range.input[0], "ReduceMax")?;
        let (abs_i, abs) = self.node_op(&max.input[0], "Abs")?;
        let axes = get_attr(max, "axes").map(|a| a.ints.clone());
        if abs.input.first() != Some(x)
            || max.input.len() != 1
            || int_attr(max, "keepdims", 1) != 1
            || axes.as_deref() != Some(&[-1])
            || self.scalar(range.input.get(1)?) != Some(127.0)
            || self.scalar(floor.input.get(1)?) != Some(1e-30)
        {
            return None;
        }
        let (weight, transposed, t) = self.weight(&mmi.input[1], true)?;
        let d = self.dims(&weight);
        let m = if transposed { d[0] } else { d[1] };
        if scale.data_type != Dt::Float as i32 || Self::elements(scale) != m {
            return None;
        }
        let nodes = [rescale_i, channels_i, to_f32_i, mmi_i, q_i, offset_i, scaled_i, floor_i, range_i, max_i, abs_i];
        Some(Product {
            x: x.clone(),
            weight,
            transposed,
            scale: Some(scale.name.clone()),
            bias: None,
            addend: None,
            out: out.to_string(),
            m,
            nodes: nodes.into_iter().chain(t).collect(),
        })
    }

    /// Whether every output of `nodes` but those in `keep` is read only inside `nodes`.
    fn closed(&self, nodes: &[usize], keep: &[&str]) -> bool {
        let set: HashSet<usize> = nodes.iter().copied().collect();
        nodes.iter().flat_map(|&i| &self.g.node[i].output).all(|o| {
            keep.contains(&o.as_str())
                || (!self.outputs.contains(o.as_str())
                    && self.consumers.get(o.as_str()).is_none_or(|c| c.iter().all(|c| set.contains(c))))
        })
    }
}

/// A node of the rewritten graph.
struct Replacement {
    /// Position: that of the first node it replaces whose output is read elsewhere.
    at: usize,
    nodes: Vec<usize>,
    node: pb::NodeProto,
}

fn weight_attrs(prefix: &str, p: &[&Product]) -> Vec<pb::AttributeProto> {
    let mut a = vec![
        attr::strings(&format!("{prefix}weights"), p.iter().map(|p| p.weight.as_str())),
        attr::ints(&format!("{prefix}transposed"), p.iter().map(|p| p.transposed as i64)),
    ];
    if p.iter().all(|p| p.scale.is_some()) {
        a.push(attr::strings(&format!("{prefix}scales"), p.iter().map(|p| p.scale.as_deref().unwrap_or(""))));
    }
    a
}

fn dense(idx: &Index, i: usize) -> Option<Replacement> {
    let node = &idx.g.node[i];
    let (p, alpha, out) = match node.op_type.as_str() {
        "LeakyRelu" | "Relu" => {
            let alpha = if node.op_type == "Relu" { 0.0 } else { float_attr(node, "alpha", 0.01) };
            let x = node.input.first()?;
            idx.only_consumer(x)?;
            (idx.product(x)?, Some(alpha), node.output.first()?.clone())
        }
        _ => {
            let out = node.output.first()?;
            (idx.product(out)?, None, out.clone())
        }
    };
    let mut nodes = p.nodes.clone();
    if alpha.is_some() {
        nodes.push(i);
    }
    if !idx.closed(&nodes, &[&out]) {
        return None;
    }
    let mut attribute = weight_attrs("", &[&p]);
    if let Some(b) = &p.bias {
        attribute.push(attr::string("bias", b));
    }
    if let Some(a) = alpha {
        attribute.push(attr::float("alpha", a));
    }
    let inputs = std::iter::once(p.x.clone()).chain(p.addend.clone()).collect();
    let node = pb::NodeProto {
        name: format!("{}.zoo", node.name),
        op_type: super::ZOO_DENSE.into(),
        domain: super::DOMAIN.into(),
        input: inputs,
        output: vec![out],
        attribute,
        ..Default::default()
    };
    Some(Replacement { at: nodes.iter().copied().max()?, nodes, node })
}

/// The terms of the sum `tensor`: products, constant biases, per-character addends; and the
/// `Add` nodes of the sum.
fn terms(
    idx: &Index,
    tensor: &str,
    products: &mut Vec<Product>,
    biases: &mut Vec<String>,
    addends: &mut Vec<String>,
    adds: &mut Vec<usize>,
) -> Option<()> {
    if let Some(p) = idx.product(tensor) {
        if let Some(a) = &p.addend {
            addends.push(a.clone());
        }
        if let Some(b) = &p.bias {
            biases.push(b.clone());
        }
        products.push(p);
        return Some(());
    }
    if let Some((i, add)) = idx.node_op(tensor, "Add") {
        adds.push(i);
        // Whether each operand is read only here is checked on the whole cell (`closed`).
        for input in &add.input {
            terms(idx, input, products, biases, addends, adds)?;
        }
        return Some(());
    }
    if idx.float_init(tensor).is_some() {
        biases.push(tensor.to_string());
    } else {
        addends.push(tensor.to_string());
    }
    Some(())
}

fn lstm(idx: &Index, i: usize, new_inits: &mut Vec<pb::TensorProto>) -> Option<Replacement> {
    let split = &idx.g.node[i];
    if split.op_type != "Split" || split.output.len() != 4 || int_attr(split, "axis", 0) != 1 {
        return None;
    }
    let one = |tensor: &str, op: &str| -> Option<(usize, &pb::NodeProto)> {
        let c = idx.only_consumer(tensor)?;
        (idx.g.node[c].op_type == op).then(|| (c, &idx.g.node[c]))
    };
    let (ii, gi) = one(&split.output[0], "Sigmoid")?;
    let (fi, gf) = one(&split.output[1], "Sigmoid")?;
    let (gg_i, gg) = one(&split.output[2], "Tanh")?;
    let (oi, go) = one(&split.output[3], "Sigmoid")?;
    let (fc_i, fc) = one(&gf.output[0], "Mul")?;
    let c_prev = fc.input.iter().find(|t| **t != gf.output[0])?.clone();
    let (ig_i, ig) = one(&gi.output[0], "Mul")?;
    if !ig.input.contains(&gg.output[0]) || idx.only_consumer(&gg.output[0]) != Some(ig_i) {
        return None;
    }
    let (c_i, c) = one(&fc.output[0], "Add")?;
    if !c.input.contains(&ig.output[0]) || idx.only_consumer(&ig.output[0]) != Some(c_i) {
        return None;
    }
    let c_next = c.output[0].clone();
    let tc_i = *idx.consumers.get(c_next.as_str())?.iter().find(|&&k| idx.g.node[k].op_type == "Tanh")?;
    let tc = &idx.g.node[tc_i];
    let (h_i, h) = one(&tc.output[0], "Mul")?;
    if !h.input.contains(&go.output[0]) || idx.only_consumer(&go.output[0]) != Some(h_i) {
        return None;
    }
    let h_next = h.output[0].clone();
    let (mut products, mut biases, mut addends, mut adds) = (vec![], vec![], vec![], vec![]);
    terms(idx, split.input.first()?, &mut products, &mut biases, &mut addends, &mut adds)?;
    let m = products.first()?.m;
    let int8 = products[0].scale.is_some();
    if m % 4 != 0 || products.iter().any(|p| p.m != m || p.scale.is_some() != int8) {
        return None;
    }
    if split.input.len() > 1 && !split.input[1].is_empty() {
        let t = idx.inits.get(split.input[1].as_str())?;
        let parts: Vec<i64> = if t.raw_data.is_empty() {
            t.int64_data.clone()
        } else {
            t.raw_data.chunks_exact(8).map(|b| i64::from_le_bytes(b.try_into().unwrap_or_default())).collect()
        };
        if parts != [m as i64 / 4; 4] {
            return None;
        }
    } else if let Some(a) = get_attr(split, "split") {
        if a.ints != [m as i64 / 4; 4] {
            return None;
        }
    }
    let mut nodes: Vec<usize> = vec![i, ii, fi, gg_i, oi, fc_i, ig_i, c_i, tc_i, h_i];
    nodes.extend(adds);
    nodes.extend(products.iter().flat_map(|p| p.nodes.iter().copied()));
    if !idx.closed(&nodes, &[&c_next, &h_next]) {
        return None;
    }
    let refs: Vec<&Product> = products.iter().collect();
    let mut attribute = weight_attrs("", &refs);
    attribute.push(attr::int("addends", addends.len() as i64));
    if !biases.is_empty() {
        // One bias: the sum of the constant terms.
        let mut sum = vec![0f32; m];
        for b in &biases {
            let t = idx.float_init(b)?;
            let values = super::tensor_f32(t)?;
            if values.len() != m {
                return None;
            }
            sum.iter_mut().zip(values).for_each(|(s, v)| *s += v);
        }
        let name = format!("{}.zoo_bias", split.name);
        new_inits.push(pb::TensorProto {
            name: name.clone(),
            dims: vec![m as i64],
            data_type: Dt::Float as i32,
            raw_data: sum.iter().flat_map(|v| v.to_le_bytes()).collect(),
            ..Default::default()
        });
        attribute.push(attr::string("bias", &name));
    }
    let input = std::iter::once(c_prev).chain(products.iter().map(|p| p.x.clone())).chain(addends).collect();
    let node = pb::NodeProto {
        name: format!("{}.zoo", split.name),
        op_type: super::ZOO_LSTM.into(),
        domain: super::DOMAIN.into(),
        input,
        output: vec![h_next, c_next],
        attribute,
        ..Default::default()
    };
    // Where `c'` is computed: every input of the cell is known there, and no reader of its
    // outputs comes before.
    Some(Replacement { at: c_i.min(h_i), nodes, node })
}

/// An f32 initializer `name` of shape `dims`.
pub(crate) fn f32_init(name: &str, dims: &[usize], values: &[f32]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: Dt::Float as i32,
        raw_data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        ..Default::default()
    }
}

/// How a file stores a recurrent weight ([`Index::recurrent_values`]).
enum Stored {
    /// f32, or f16 widened by a `Cast`.
    Float,
    /// The integers (`[dirs, rows, in]`) and the scales of the rows, shared by the directions.
    I8 { q: Vec<i8>, scales: Vec<f32> },
}

/// The zoo nodes of an ONNX `GRU` node (`linear_before_reset = 1`, the default activations, no
/// sequence lengths, constant weights in f32, f16 or int8 ([`Index::recurrent_values`])): one
/// [`super::ZOO_DENSE`] of every frame's input products for every direction with their biases,
/// then per direction a [`super::ZOO_GRU`] of the recurrence, naming the int8 form of its
/// weights too (`recurrent_width`, `recurrent_q`, `recurrent_scales`); both
/// directions' outputs concatenated as the `GRU` node's. `None` for any other form.
fn gru(idx: &Index, node: &pb::NodeProto, inits: &mut Vec<pb::TensorProto>) -> Option<Vec<pb::NodeProto>> {
    let allowed = ["hidden_size", "direction", "linear_before_reset", "layout"];
    if node.op_type != "GRU"
        || !node.domain.is_empty()
        || int_attr(node, "linear_before_reset", 0) != 1
        || int_attr(node, "layout", 0) != 0
        || node.attribute.iter().any(|a| !allowed.contains(&a.name.as_str()))
        || node.input.len() < 3
        || node.input.get(4).is_some_and(|l| !l.is_empty())
    {
        return None;
    }
    let dirs = match get_attr(node, "direction").map_or(&b"forward"[..], |a| a.s.as_slice()) {
        b"forward" | b"reverse" => 1,
        b"bidirectional" => 2,
        _ => return None,
    };
    let backward = get_attr(node, "direction").is_some_and(|a| a.s == b"reverse");
    let values = |name: &str| idx.float_init(name).and_then(|t| Some((t.dims.clone(), super::tensor_f32(t)?)));
    let (wd, w, _) = idx.recurrent_values(&node.input[1])?;
    let (rd, r, stored) = idx.recurrent_values(&node.input[2])?;
    let h = int_attr(node, "hidden_size", 0).max(0) as usize;
    if wd.len() != 3 || rd != [dirs as i64, 3 * h as i64, h as i64] || wd[0] != dirs as i64 || wd[1] != 3 * h as i64 {
        return None;
    }
    let k = wd[2].max(0) as usize;
    if h == 0 || k == 0 || w.len() != dirs * 3 * h * k || r.len() != dirs * 3 * h * h {
        return None;
    }
    let b = match node.input.get(3).filter(|b| !b.is_empty()) {
        Some(name) => {
            let (bd, b) = values(name)?;
            (bd == [dirs as i64, 6 * h as i64] && b.len() == dirs * 6 * h).then_some(Some(b))?
        }
        None => None,
    };
    let h0 = node.input.get(5).filter(|t| !t.is_empty());
    let p = format!("{}.zoo_gru", node.name);
    let out = |i: usize| node.output.get(i).filter(|o| !o.is_empty()).cloned();
    // Every direction's input products in one node: `W` is `[dirs, 3H, in]`, so `[dirs x 3H, in]`
    // as stored, its bias the first `3H` of each direction's `6H`.
    inits.push(f32_init(&format!("{p}.w"), &[dirs * 3 * h, k], &w));
    let mut dense_attrs = vec![
        attr::strings("weights", std::iter::once(format!("{p}.w").as_str())),
        attr::ints("transposed", [1].into_iter()),
    ];
    if let Some(b) = &b {
        let wb: Vec<f32> = b.chunks_exact(6 * h).flat_map(|d| d[..3 * h].iter().copied()).collect();
        inits.push(f32_init(&format!("{p}.wb"), &[dirs * 3 * h], &wb));
        dense_attrs.push(attr::string("bias", &format!("{p}.wb")));
    }
    let xw = format!("{p}.xw");
    let mut nodes = vec![pb::NodeProto {
        name: xw.clone(),
        op_type: super::ZOO_DENSE.into(),
        domain: super::DOMAIN.into(),
        input: vec![node.input[0].clone()],
        output: vec![xw.clone()],
        attribute: dense_attrs,
        ..Default::default()
    }];
    let (mut ys, mut hs) = (Vec::new(), Vec::new());
    for d in 0..dirs {
        let q = format!("{p}.d{d}");
        inits.push(f32_init(&format!("{q}.r"), &[3 * h, h], &r[d * 3 * h * h..(d + 1) * 3 * h * h]));
        let mut gru_attrs = vec![
            attr::strings("weights", std::iter::once(format!("{q}.r").as_str())),
            attr::ints("transposed", [1].into_iter()),
        ];
        if let Some(b) = &b {
            inits.push(f32_init(&format!("{q}.rb"), &[3 * h], &b[d * 6 * h + 3 * h..(d + 1) * 6 * h]));
            gru_attrs.push(attr::string("bias", &format!("{q}.rb")));
        }
        // The int8 file's recurrent weights also as it stores them: a character alone
        // multiplies them every frame, faster from a compact copy (`super::gru`; f16 weights
        // are found by the product itself).
        match &stored {
            Stored::Float => {}
            Stored::I8 { q: ints, scales } => {
                let raw = ints[d * 3 * h * h..(d + 1) * 3 * h * h].iter().map(|v| *v as u8).collect();
                let dims = vec![3 * h as i64, h as i64];
                let data_type = Dt::Int8 as i32;
                inits.push(pb::TensorProto {
                    name: format!("{q}.rq"),
                    dims,
                    data_type,
                    raw_data: raw,
                    ..Default::default()
                });
                inits.push(f32_init(&format!("{q}.rs"), &[3 * h], scales));
                gru_attrs.push(attr::string("recurrent_width", "int8"));
                gru_attrs.push(attr::string("recurrent_q", &format!("{q}.rq")));
                gru_attrs.push(attr::string("recurrent_scales", &format!("{q}.rs")));
            }
        }
        gru_attrs.push(attr::int("reverse", i64::from(d == 1 || backward)));
        gru_attrs.push(attr::int("h0_index", d as i64));
        gru_attrs.push(attr::int("xw_block", d as i64));
        let (y, hl) = if dirs == 1 {
            (out(0).unwrap_or(format!("{q}.y")), out(1).unwrap_or(format!("{q}.h")))
        } else {
            (format!("{q}.y"), format!("{q}.h"))
        };
        nodes.push(pb::NodeProto {
            name: q.clone(),
            op_type: super::ZOO_GRU.into(),
            domain: super::DOMAIN.into(),
            input: std::iter::once(xw.clone()).chain(h0.cloned()).collect(),
            output: vec![y.clone(), hl.clone()],
            attribute: gru_attrs,
            ..Default::default()
        });
        ys.push(y);
        hs.push(hl);
    }
    if dirs == 2 {
        for (i, parts, axis) in [(0, ys, 1), (1, hs, 0)] {
            if let Some(o) = out(i) {
                nodes.push(pb::NodeProto {
                    name: format!("{p}.out{i}"),
                    op_type: "Concat".into(),
                    input: parts,
                    output: vec![o],
                    attribute: vec![attr::int("axis", axis)],
                    ..Default::default()
                });
            }
        }
    }
    Some(nodes)
}

/// `graph` with its `GRU` nodes as zoo nodes ([`gru`]), or `None` when it has none.
fn expand_grus(graph: &pb::GraphProto) -> Option<pb::GraphProto> {
    let idx = Index::new(graph);
    let mut inits = Vec::new();
    let mut out = graph.clone();
    out.node.clear();
    let mut changed = false;
    for n in &graph.node {
        match gru(&idx, n, &mut inits) {
            Some(nodes) => {
                changed = true;
                out.node.extend(nodes);
            }
            None => out.node.push(n.clone()),
        }
    }
    out.initializer.extend(inits);
    changed.then_some(out)
}

/// `graph` with its products, LSTM cells and GRU layers as zoo nodes; `None` when it has none.
pub(crate) fn rewrite(graph: &pb::GraphProto) -> Option<pb::GraphProto> {
    let grus = expand_grus(graph);
    let graph = grus.as_ref().unwrap_or(graph);
    let idx = Index::new(graph);
    let mut taken = HashSet::new();
    let mut replacements = Vec::new();
    let mut new_inits = Vec::new();
    let mut take = |r: Replacement, taken: &mut HashSet<usize>| {
        if r.nodes.iter().all(|n| !taken.contains(n)) {
            taken.extend(r.nodes.iter().copied());
            replacements.push(r);
        }
    };
    for i in 0..graph.node.len() {
        if let Some(r) = lstm(&idx, i, &mut new_inits) {
            take(r, &mut taken);
        }
    }
    // Last node first: a product followed by its activation is taken whole.
    for i in (0..graph.node.len()).rev() {
        if taken.contains(&i) {
            continue;
        }
        if let Some(r) = dense(&idx, i) {
            take(r, &mut taken);
        }
    }
    if replacements.is_empty() {
        return grus;
    }
    let mut at: HashMap<usize, pb::NodeProto> = replacements.into_iter().map(|r| (r.at, r.node)).collect();
    let mut out = graph.clone();
    out.node.clear();
    for (i, n) in graph.node.iter().enumerate() {
        if let Some(z) = at.remove(&i) {
            out.node.push(z);
        } else if !taken.contains(&i) {
            out.node.push(n.clone());
        }
    }
    out.initializer.extend(new_inits);
    Some(out)
}
