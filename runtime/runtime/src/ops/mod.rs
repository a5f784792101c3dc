//! zoo's own tract ops and the load-time rewrite that uses them.
//!
//! When a file is loaded, [`rewrite::rewrite`] replaces the matrix products of its graphs
//! (f32, f16 or int8, as `zoo export` writes them) by [`ZOO_DENSE`] nodes (a product, its bias,
//! its LeakyReLU), its LSTM cells by [`ZOO_LSTM`] nodes (the gate products, the gate
//! nonlinearities and the state update) and its GRU layers by a [`ZOO_DENSE`] of every frame's
//! input products and a [`ZOO_GRU`] per direction, which [`onnx`] parses into [`DenseOp`],
//! [`LstmOp`] and `gru::GruOp`.
//! Both run their products on tract-linalg's kernels ([`product`]): one kernel call for the
//! sum of an LSTM's gate products in f32, the int8 products quantized and packed in one pass
//! and run on the integer kernels. The file itself stays standard ONNX; set
//! `ZOO_RUNTIME_FUSE=0` to run the graph as written (for comparisons).

pub(crate) mod chunk;
mod gru;
pub(crate) mod kept;
mod product;
pub(crate) mod rewrite;
pub(crate) mod tiles;
pub(crate) mod tiles_i8;

use kept::{Kept, WritesKept, kept_eval};
use product::{Product, Weights};
use std::sync::Arc;
use tract_onnx::model::ParsingContext;
use tract_onnx::pb;
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};
use tract_onnx::tract_hir::internal::*;
use tract_onnx::tract_hir::prelude::tract_linalg::Func;

/// The ONNX domain of the zoo nodes (in memory only, never written to a file).
pub(crate) const DOMAIN: &str = "zoo";
/// A product, its bias and activation: inputs `x [..., in]` (every axis but the last counts
/// rows: characters, or frames x characters) and an optional addend of the output's shape,
/// output `[..., out]`.
pub(crate) const ZOO_DENSE: &str = "ZooDense";
/// An LSTM cell: inputs `c [batch, hidden]`, the products' inputs, the addends; outputs `h`, `c`.
pub(crate) const ZOO_LSTM: &str = "ZooLstmCell";

/// One direction of a GRU layer's recurrence (`linear_before_reset = 1`, gates z, r, h in ONNX's
/// order): inputs `xw [frames, batch, blocks x 3 hidden]` (the input products with their
/// biases, this direction's in block `xw_block`) and
/// optionally the initial states `h0 [directions, batch, hidden]` (row `h0_index`); outputs
/// `y [frames, 1, batch, hidden]` and the last state `[1, batch, hidden]`.
pub(crate) const ZOO_GRU: &str = "ZooGru";

/// Whether loads rewrite graphs (`ZOO_RUNTIME_FUSE=0` turns it off).
pub(crate) fn enabled() -> bool {
    std::env::var("ZOO_RUNTIME_FUSE").map_or(true, |v| v != "0")
}

/// `proto` with its products, LSTM cells and GRU layers as zoo nodes, or `None` when it has none.
pub(crate) fn fuse(proto: &pb::ModelProto) -> Option<pb::ModelProto> {
    let graph = rewrite::rewrite(proto.graph.as_ref()?)?;
    let mut out = proto.clone();
    out.graph = Some(graph);
    out.opset_import.push(pb::OperatorSetIdProto { domain: DOMAIN.into(), version: 1 });
    Some(out)
}

/// tract's ONNX parser with the zoo ops.
pub(crate) fn onnx() -> tract_onnx::Onnx {
    let mut onnx = tract_onnx::onnx();
    onnx.op_register.insert(ZOO_DENSE, parse_dense);
    onnx.op_register.insert(ZOO_LSTM, parse_lstm);
    onnx.op_register.insert(ZOO_GRU, parse_gru);
    onnx
}

pub(crate) mod attr {
    use tract_onnx::pb;
    type T = pb::attribute_proto::AttributeType;

    fn a(name: &str, t: T) -> pb::AttributeProto {
        pb::AttributeProto { name: name.into(), r#type: t as i32, ..Default::default() }
    }
    pub(crate) fn string(name: &str, v: &str) -> pb::AttributeProto {
        pb::AttributeProto { s: v.as_bytes().to_vec(), ..a(name, T::String) }
    }
    pub(crate) fn strings<'v>(name: &str, v: impl Iterator<Item = &'v str>) -> pb::AttributeProto {
        pb::AttributeProto { strings: v.map(|s| s.as_bytes().to_vec()).collect(), ..a(name, T::Strings) }
    }
    pub(crate) fn int(name: &str, v: i64) -> pb::AttributeProto {
        pb::AttributeProto { i: v, ..a(name, T::Int) }
    }
    pub(crate) fn ints(name: &str, v: impl Iterator<Item = i64>) -> pb::AttributeProto {
        pb::AttributeProto { ints: v.collect(), ..a(name, T::Ints) }
    }
    pub(crate) fn float(name: &str, v: f32) -> pb::AttributeProto {
        pb::AttributeProto { f: v, ..a(name, T::Float) }
    }
}

/// The f32 values of an f32 or f16 initializer.
pub(crate) fn tensor_f32(t: &pb::TensorProto) -> Option<Vec<f32>> {
    type Dt = pb::tensor_proto::DataType;
    if t.data_type == Dt::Float as i32 {
        Some(if t.raw_data.is_empty() {
            t.float_data.clone()
        } else {
            t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        })
    } else if t.data_type == Dt::Float16 as i32 {
        Some(if t.raw_data.is_empty() {
            t.int32_data.iter().map(|v| f16::from_bits(*v as u16).to_f32()).collect()
        } else {
            t.raw_data.chunks_exact(2).map(|b| f16::from_le_bytes([b[0], b[1]]).to_f32()).collect()
        })
    } else {
        None
    }
}

fn node_attr<'n>(node: &'n pb::NodeProto, name: &str) -> Option<&'n pb::AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

fn init<'c>(ctx: &'c ParsingContext, name: &str) -> TractResult<&'c pb::TensorProto> {
    ctx.model
        .graph
        .as_ref()
        .and_then(|g| g.initializer.iter().find(|t| t.name == name))
        .with_context(|| format!("initializer `{name}` not found"))
}

/// The weights named by a zoo node, each `[out, in]`.
fn weights(ctx: &ParsingContext, node: &pb::NodeProto) -> TractResult<(usize, Vec<Weights>)> {
    let names = &node_attr(node, "weights").context("no weights")?.strings;
    let transposed = &node_attr(node, "transposed").context("no layouts")?.ints;
    let scales = node_attr(node, "scales").map(|a| &a.strings);
    let mut m = None;
    let mut out = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let t = init(ctx, &String::from_utf8_lossy(name))?;
        let d: Vec<usize> = t.dims.iter().map(|d| (*d).max(0) as usize).collect();
        ensure!(d.len() == 2, "weight `{}` is not a matrix", t.name);
        let (rows, cols, t_in) = if transposed[i] == 1 { (d[0], d[1], false) } else { (d[1], d[0], true) };
        ensure!(m.is_none_or(|m| m == rows), "the weights of `{}` have different outputs", node.name);
        m = Some(rows);
        // `[out, in]` from `[in, out]` when stored the other way.
        let at = |j: usize| {
            let (o, i) = (j / cols, j % cols);
            if t_in { i * rows + o } else { o * cols + i }
        };
        if let Some(scales) = scales {
            let s = tensor_f32(init(ctx, &String::from_utf8_lossy(&scales[i]))?).context("scales are not f32")?;
            ensure!(s.len() == rows, "`{}` has {} scales for {rows} channels", t.name, s.len());
            ensure!(t.raw_data.len() == rows * cols, "int8 weight `{}` is not raw u8", t.name);
            let q: Vec<i8> = t.raw_data.iter().map(|b| (i16::from(*b) - 128) as i8).collect();
            ensure!(q.iter().all(|v| *v >= -127), "int8 weight `{}` holds -128", t.name);
            out.push(Weights::I8 { q: (0..rows * cols).map(|j| q[at(j)]).collect(), scales: s });
        } else {
            let v = tensor_f32(t).context("weights are not f32 or f16")?;
            out.push(Weights::F32((0..rows * cols).map(|j| v[at(j)]).collect()));
        }
    }
    Ok((m.context("no weights")?, out))
}

fn bias(ctx: &ParsingContext, node: &pb::NodeProto, m: usize) -> TractResult<Option<Arc<Tensor>>> {
    let Some(a) = node_attr(node, "bias") else { return Ok(None) };
    let v = tensor_f32(init(ctx, &String::from_utf8_lossy(&a.s))?).context("bias is not f32")?;
    ensure!(v.len() == m, "bias of `{}` has {} values for {m} outputs", node.name, v.len());
    Ok(Some(Arc::new(tensor1(&v))))
}

fn parse_dense(ctx: &ParsingContext, node: &pb::NodeProto) -> TractResult<(Box<dyn InferenceOp>, Vec<String>)> {
    let (m, w) = weights(ctx, node)?;
    let spec = DenseSpec {
        m,
        weights: Arc::new(w),
        bias: bias(ctx, node, m)?,
        alpha: node_attr(node, "alpha").map(|a| Arc::new(tensor0(a.f))),
        addend: node.input.len() > 1,
        frame_chunk: node_attr(node, FRAME_CHUNK).map_or(0, |a| a.i.max(0) as usize),
    };
    Ok((expand(spec), vec![]))
}

fn parse_lstm(ctx: &ParsingContext, node: &pb::NodeProto) -> TractResult<(Box<dyn InferenceOp>, Vec<String>)> {
    let (m, w) = weights(ctx, node)?;
    ensure!(m % 4 == 0, "`{}`: {m} gate rows is not 4 blocks", node.name);
    let addends = node_attr(node, "addends").map_or(0, |a| a.i as usize);
    ensure!(node.input.len() == 1 + w.len() + addends, "`{}`: wrong input count", node.name);
    let spec = LstmSpec { hidden: m / 4, weights: Arc::new(w), bias: bias(ctx, node, m)?, addends };
    Ok((expand(spec), vec![]))
}

fn parse_gru(ctx: &ParsingContext, node: &pb::NodeProto) -> TractResult<(Box<dyn InferenceOp>, Vec<String>)> {
    let (m, w) = weights(ctx, node)?;
    ensure!(m % 3 == 0, "`{}`: {m} gate rows is not 3 blocks", node.name);
    ensure!(w.iter().all(|w| matches!(w, Weights::F32(_))), "`{}`: GRU weights are f32", node.name);
    let has_h0 = node.input.len() > 1 && !node.input[1].is_empty();
    let int = |name: &str| node_attr(node, name).map_or(0, |a| a.i);
    let spec = gru::GruSpec {
        hidden: m / 3,
        weights: Arc::new(w),
        bias: bias(ctx, node, m)?,
        reverse: int("reverse") != 0,
        h0_index: int("h0_index").max(0) as usize,
        has_h0,
        xw_block: int("xw_block").max(0) as usize,
        compact: compact(ctx, node, m)?,
    };
    Ok((expand(spec), vec![]))
}

/// What a product's description says of one character's weights held in 16 bits.
fn one_character(p: &Product) -> String {
    p.one_character().map_or(String::new(), |w| format!(", one character on {w:?} weights"))
}

/// A [`ZOO_GRU`]'s recurrent weights as the int8 file stores them (`recurrent_width` "int8",
/// its integers `recurrent_q` and row scales `recurrent_scales`; f16 weights need none, see
/// `product::Product`).
fn compact(ctx: &ParsingContext, node: &pb::NodeProto, m: usize) -> TractResult<Option<Arc<gru::Compact>>> {
    match node_attr(node, "recurrent_width").map(|a| a.s.as_slice()) {
        None => return Ok(None),
        Some(b"int8") => {}
        Some(other) => bail!("`{}`: unknown recurrent width {}", node.name, String::from_utf8_lossy(other)),
    }
    let name = |a: &str| node_attr(node, a).map(|a| String::from_utf8_lossy(&a.s).into_owned());
    let t = init(ctx, &name("recurrent_q").context("no recurrent_q")?)?;
    ensure!(t.data_type == pb::tensor_proto::DataType::Int8 as i32, "`{}`: recurrent_q is not int8", node.name);
    let q: Vec<i8> = t.raw_data.iter().map(|b| *b as i8).collect();
    let scales = tensor_f32(init(ctx, &name("recurrent_scales").context("no recurrent_scales")?)?)
        .context("recurrent scales are not f32")?;
    ensure!(
        scales.len() == m && q.len() % m == 0,
        "`{}`: {} scales, {} integers for {m} rows",
        node.name,
        scales.len(),
        q.len()
    );
    Ok(Some(Arc::new(gru::Compact { q, scales })))
}

/// The batch size of a plan, when it is concrete.
fn batch(model: &TypedModel, x: OutletId) -> TractResult<Option<usize>> {
    Ok(model.outlet_fact(x)?.shape.first().and_then(|d| d.to_usize().ok()))
}

/// The rows of a product's input (every axis but the last: characters, or frames x
/// characters), when they are concrete.
fn rows(model: &TypedModel, x: OutletId) -> TractResult<Option<usize>> {
    let shape = &model.outlet_fact(x)?.shape;
    Ok(shape.iter().take(shape.len().saturating_sub(1)).map(|d| d.to_usize().ok()).product())
}

/// A parsed [`ZOO_DENSE`] node: packed into a [`DenseOp`] when a plan is made (the kernel
/// depends on the batch size).
#[derive(Clone, Debug)]
struct DenseSpec {
    m: usize,
    weights: Arc<Vec<Weights>>,
    bias: Option<Arc<Tensor>>,
    alpha: Option<Arc<Tensor>>,
    addend: bool,
    /// Frames per node when a plan is made ([`FRAME_CHUNK`]; 0: one node).
    frame_chunk: usize,
}

impl Expansion for DenseSpec {
    fn name(&self) -> StaticName {
        "ZooDense".into()
    }

    fn rules<'r, 'p: 'r, 's: 'r>(
        &'s self,
        s: &mut Solver<'r>,
        inputs: &'p [TensorProxy],
        outputs: &'p [TensorProxy],
    ) -> InferenceResult {
        check_input_arity(inputs, 1 + self.addend as usize)?;
        check_output_arity(outputs, 1)?;
        s.equals(&inputs[0].datum_type, f32::datum_type())?;
        s.equals(&outputs[0].datum_type, f32::datum_type())?;
        s.equals(&outputs[0].rank, &inputs[0].rank)?;
        let m = self.m.to_dim();
        s.given(&inputs[0].rank, move |s, rank| {
            let rank = rank as usize;
            ensure!(rank >= 2, "ZooDense on a rank {rank} input");
            for axis in 0..rank - 1 {
                s.equals(&outputs[0].shape[axis], &inputs[0].shape[axis])?;
            }
            s.equals(&outputs[0].shape[rank - 1], m.clone())
        })?;
        if self.addend {
            s.equals(&inputs[1].shape, &outputs[0].shape)?;
        }
        Ok(())
    }

    fn wire(&self, prefix: &str, model: &mut TypedModel, inputs: &[OutletId]) -> TractResult<TVec<OutletId>> {
        let shape = model.outlet_fact(inputs[0])?.shape.to_tvec();
        let frames = shape.first().filter(|_| shape.len() >= 2).and_then(|d| d.to_usize().ok());
        let chunk = self.frame_chunk;
        let Some(frames) = frames.filter(|&f| chunk > 0 && f > chunk) else {
            let product = Product::new(self.m, &self.weights, rows(model, inputs[0])?)?;
            let op = DenseOp { product, bias: self.bias.clone(), alpha: self.alpha.clone(), addend: self.addend };
            return model.wire_node(prefix, op, inputs);
        };
        // The same product on every `chunk` frames of the first axis, one node each, joined; the
        // chunks of one size share one packing of the weights.
        let mut parts = tvec![];
        let mut packed: Option<(Option<usize>, Product)> = None;
        for (c, from) in (0..frames).step_by(chunk).enumerate() {
            let to = (from + chunk).min(frames);
            let mut part = tvec![];
            for (i, &input) in inputs.iter().enumerate() {
                let slice = tract_onnx::tract_core::ops::array::Slice::new(0, from, to);
                part.push(model.wire_node(format!("{prefix}.frames{c}.in{i}"), slice, &[input])?[0]);
            }
            let n = rows(model, part[0])?;
            let product = match &packed {
                Some((rows, p)) if *rows == n => p.clone(),
                _ => Product::new(self.m, &self.weights, n)?,
            };
            packed = Some((n, product.clone()));
            let op = DenseOp { product, bias: self.bias.clone(), alpha: self.alpha.clone(), addend: self.addend };
            parts.push(model.wire_node(format!("{prefix}.frames{c}"), op, &part)?[0]);
        }
        model.wire_node(prefix, tract_onnx::tract_core::ops::array::TypedConcat { axis: 0 }, &parts)
    }
}

/// The attribute of a [`ZOO_DENSE`] node that splits its product into nodes of this many frames
/// (the first axis) when a plan is made: for a caller that runs a window's graph node by node
/// (`crate::ops::chunk::chunk_dense`); the result is the same.
pub(crate) const FRAME_CHUNK: &str = "frame_chunk";

/// A product, its bias, a per-character addend and a LeakyReLU, on one tract-linalg kernel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct DenseOp {
    product: Product,
    bias: Option<Arc<Tensor>>,
    alpha: Option<Arc<Tensor>>,
    addend: bool,
}

fn plain_f32(t: &TValue) -> TractResult<&[f32]> {
    t.try_as_plain_ram()?.as_slice::<f32>()
}

impl Op for DenseOp {
    fn name(&self) -> StaticName {
        "ZooDense".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        let p = &self.product;
        Ok(vec![format!(
            "{} x {:?} {} on {}{}{}",
            p.m,
            p.ks,
            if p.int8() { "int8" } else { "f32" },
            p.kernel_name(),
            one_character(p),
            if self.alpha.is_some() { ", LeakyReLU" } else { "" }
        )])
    }

    op_as_typed_op!();
}

impl EvalOp for DenseOp {
    op_out_of_plan!();
    kept_eval!();
}

impl WritesKept for DenseOp {
    fn eval_kept(&self, inputs: &[TValue], kept: &mut Kept) -> TractResult<()> {
        let p = &self.product;
        let shape = inputs[0].shape();
        let n = shape[..shape.len() - 1].iter().product();
        let x = plain_f32(&inputs[0])?;
        let mut out_shape: TVec<usize> = shape.into();
        *out_shape.last_mut().context("ZooDense on a scalar")? = p.m;
        let mut outs = kept.outputs(&[&out_shape])?;
        let out = &mut *outs[0];
        if !p.int8() {
            let addend = if self.addend { Some(&*inputs[1]) } else { None };
            p.run_f32(&[x], n, self.bias.as_deref(), addend, self.alpha.as_deref(), out)?;
        } else {
            let mut view = out.try_as_plain_ram_mut()?;
            let o = view.as_slice_mut::<f32>()?;
            let bias = self.bias.as_ref().map(|b| b.try_as_plain_ram()?.as_slice::<f32>()).transpose()?;
            p.run_i8(&[x], n, |_, acc, rows, channels| {
                Product::dequantize(acc, rows, channels, bias, o, false);
                Ok(())
            })?;
            if self.addend {
                o.iter_mut().zip(plain_f32(&inputs[1])?).for_each(|(o, a)| *o += a);
            }
            if let Some(alpha) = &self.alpha {
                let alpha = alpha.try_as_plain_ram()?.as_slice::<f32>()?[0];
                o.iter_mut().for_each(|v| *v = if *v < 0.0 { *v * alpha } else { *v });
            }
        }
        Ok(())
    }
}

impl TypedOp for DenseOp {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let mut shape: TVec<TDim> = inputs[0].shape.iter().cloned().collect();
        *shape.last_mut().context("ZooDense on a scalar")? = self.product.m.to_dim();
        Ok(tvec!(f32::fact(shape)))
    }
}

/// A parsed [`ZOO_LSTM`] node.
#[derive(Clone, Debug)]
struct LstmSpec {
    hidden: usize,
    weights: Arc<Vec<Weights>>,
    bias: Option<Arc<Tensor>>,
    addends: usize,
}

impl Expansion for LstmSpec {
    fn name(&self) -> StaticName {
        "ZooLstmCell".into()
    }

    fn nboutputs(&self) -> TractResult<usize> {
        Ok(2)
    }

    fn rules<'r, 'p: 'r, 's: 'r>(
        &'s self,
        s: &mut Solver<'r>,
        inputs: &'p [TensorProxy],
        outputs: &'p [TensorProxy],
    ) -> InferenceResult {
        check_input_arity(inputs, 1 + self.weights.len() + self.addends)?;
        check_output_arity(outputs, 2)?;
        for o in outputs {
            s.equals(&o.datum_type, f32::datum_type())?;
            s.equals(&o.shape, &inputs[0].shape)?;
        }
        s.equals(&inputs[0].rank, 2)?;
        s.equals(&inputs[0].shape[1], self.hidden.to_dim())?;
        Ok(())
    }

    fn wire(&self, prefix: &str, model: &mut TypedModel, inputs: &[OutletId]) -> TractResult<TVec<OutletId>> {
        let (n, h) = (batch(model, inputs[0])?, self.hidden);
        if n != Some(1) || std::env::var("ZOO_LSTM_SPLIT").is_ok_and(|v| v == "0") {
            let product = Product::new(4 * h, &self.weights, n)?;
            let op = LstmOp { product, hidden: h, bias: self.bias.clone(), addends: self.addends, split: false };
            return model.wire_node(prefix, op, inputs);
        }
        // One character: the gate products in two nodes, gates i and f, then g and o with the
        // state update, so that a caller running the plan node by node can stop between the
        // halves of the cell (three quarters of a transition model's run); the same sums, the
        // same kernel over each half's rows, the addends added in the same order.
        let half = |from: usize, to: usize| -> TractResult<(Vec<Weights>, Option<Arc<Tensor>>)> {
            let w = self.weights.iter().map(|w| w.channels(4 * h, from, to)).collect();
            let b = match &self.bias {
                Some(b) => Some(Arc::new(tensor1(&b.try_as_plain_ram()?.as_slice::<f32>()?[from..to]))),
                None => None,
            };
            Ok((w, b))
        };
        let ((wa, ba), (wb, bb)) = (half(0, 2 * h)?, half(2 * h, 4 * h)?);
        let gates = LstmGatesOp { product: Product::new(2 * h, &wa, n)?, bias: ba, addends: self.addends };
        let if_ = model.wire_node(format!("{prefix}.gates_if"), gates, &inputs[1..])?[0];
        let op =
            LstmOp { product: Product::new(2 * h, &wb, n)?, hidden: h, bias: bb, addends: self.addends, split: true };
        let mut all: TVec<OutletId> = inputs.into();
        all.push(if_);
        model.wire_node(prefix, op, &all)
    }
}

/// Gate pre-activations of output channels `from..from + m` of an LSTM cell into `z` (`[n, m]`):
/// the product, the bias, then each addend's channels (`[n, 4 x hidden]`) added in turn.
fn gate_half(
    p: &Product,
    bias: Option<&Tensor>,
    xs: &[&[f32]],
    addends: &[TValue],
    n: usize,
    from: usize,
    z: &mut Tensor,
) -> TractResult<()> {
    let m = p.m;
    if !p.int8() {
        p.run_f32(xs, n, bias, None, None, z)?;
    }
    let mut view = z.try_as_plain_ram_mut()?;
    let z = view.as_slice_mut::<f32>()?;
    if p.int8() {
        let bias = bias.map(|b| b.try_as_plain_ram()?.as_slice::<f32>()).transpose()?;
        p.run_i8(xs, n, |i, acc, rows, channels| {
            Product::dequantize(acc, rows, channels, if i == 0 { bias } else { None }, z, i > 0);
            Ok(())
        })?;
    }
    for a in addends {
        let a = plain_f32(a)?;
        let width = a.len() / n.max(1);
        for (row, out) in z.chunks_exact_mut(m).enumerate() {
            out.iter_mut().zip(&a[row * width + from..]).for_each(|(o, a)| *o += a);
        }
    }
    Ok(())
}

/// Gates i and f of a one-character LSTM cell (see [`LstmSpec`]'s wiring): inputs the products'
/// inputs and the addends, output the pre-activations `[n, 2 x hidden]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct LstmGatesOp {
    product: Product,
    bias: Option<Arc<Tensor>>,
    addends: usize,
}

impl Op for LstmGatesOp {
    fn name(&self) -> StaticName {
        "ZooLstmGates".into()
    }

    op_as_typed_op!();
}

impl EvalOp for LstmGatesOp {
    op_out_of_plan!();
    kept_eval!();
}

impl WritesKept for LstmGatesOp {
    fn eval_kept(&self, inputs: &[TValue], kept: &mut Kept) -> TractResult<()> {
        let p = &self.product;
        let n = inputs[0].shape()[0];
        let terms = p.ks.len();
        let xs: TVec<&[f32]> = inputs[..terms].iter().map(plain_f32).collect::<TractResult<_>>()?;
        let mut z = kept.outputs(&[&[n, p.m]])?;
        gate_half(p, self.bias.as_deref(), &xs, &inputs[terms..], n, 0, z[0])
    }
}

impl TypedOp for LstmGatesOp {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        Ok(tvec!(f32::fact([inputs[0].shape[0].clone(), self.product.m.to_dim()])))
    }
}

/// An LSTM cell (gates in the order i, f, g, o): the sum of its gate products, biases and
/// addends, `i, f, o = sigmoid`, `g = tanh`, `c' = f * c + i * g`, `h' = o * tanh(c')`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct LstmOp {
    product: Product,
    hidden: usize,
    bias: Option<Arc<Tensor>>,
    addends: usize,
    /// Gates g and o only; gates i and f come as the last input ([`LstmGatesOp`]).
    split: bool,
}

thread_local! {
    /// The gate pre-activations of the last call on this thread, reused.
    static GATES: std::cell::RefCell<Tensor> = std::cell::RefCell::new(Tensor::default());
    /// Gates g and o of a split cell's last call on this thread, reused.
    static HALF: std::cell::RefCell<Tensor> = std::cell::RefCell::new(Tensor::default());
}

impl Op for LstmOp {
    fn name(&self) -> StaticName {
        "ZooLstmCell".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        let p = &self.product;
        Ok(vec![format!(
            "hidden {} over {:?} {} on {}{}",
            self.hidden,
            p.ks,
            if p.int8() { "int8" } else { "f32" },
            p.kernel_name(),
            one_character(p)
        )])
    }

    op_as_typed_op!();
}

impl EvalOp for LstmOp {
    op_out_of_plan!();
    kept_eval!();
}

impl WritesKept for LstmOp {
    fn eval_kept(&self, inputs: &[TValue], kept: &mut Kept) -> TractResult<()> {
        let (p, h) = (&self.product, self.hidden);
        let n = inputs[0].shape()[0];
        let terms = p.ks.len();
        let xs: TVec<&[f32]> = inputs[1..1 + terms].iter().map(plain_f32).collect::<TractResult<_>>()?;
        let addends = &inputs[1 + terms..1 + terms + self.addends];
        GATES.with_borrow_mut(|gates| {
            if gates.shape() != [n, 4 * h] {
                *gates = Tensor::zero::<f32>(&[n, 4 * h])?;
            }
            if self.split {
                let if_ = plain_f32(&inputs[1 + terms + self.addends])?;
                HALF.with_borrow_mut(|half| -> TractResult<()> {
                    if half.shape() != [n, 2 * h] {
                        *half = Tensor::zero::<f32>(&[n, 2 * h])?;
                    }
                    gate_half(p, self.bias.as_deref(), &xs, addends, n, 2 * h, half)?;
                    let mut view = gates.try_as_plain_ram_mut()?;
                    let z = view.as_slice_mut::<f32>()?;
                    let go = half.try_as_plain_ram()?;
                    let go = go.as_slice::<f32>()?;
                    for (r, row) in z.chunks_exact_mut(4 * h).enumerate() {
                        row[..2 * h].copy_from_slice(&if_[r * 2 * h..(r + 1) * 2 * h]);
                        row[2 * h..].copy_from_slice(&go[r * 2 * h..(r + 1) * 2 * h]);
                    }
                    Ok(())
                })?;
                return lstm_update(gates, &inputs[0], n, h, kept);
            }
            let mut rest = addends;
            if !p.int8() {
                let first = addends.first().map(|t| &**t);
                p.run_f32(&xs, n, self.bias.as_deref(), first, None, gates)?;
                rest = addends.get(1..).unwrap_or_default();
            }
            let mut view = gates.try_as_plain_ram_mut()?;
            let z = view.as_slice_mut::<f32>()?;
            if p.int8() {
                let bias = self.bias.as_ref().map(|b| b.try_as_plain_ram()?.as_slice::<f32>()).transpose()?;
                p.run_i8(&xs, n, |i, acc, rows, channels| {
                    Product::dequantize(acc, rows, channels, if i == 0 { bias } else { None }, z, i > 0);
                    Ok(())
                })?;
            }
            for a in rest {
                z.iter_mut().zip(plain_f32(a)?).for_each(|(o, a)| *o += a);
            }
            lstm_update(gates, &inputs[0], n, h, kept)
        })
    }
}

/// The state update of an LSTM cell from its gate pre-activations `gates` (`[n, 4 x hidden]`,
/// i, f, g, o) and the last cell state `c`: `h'`, `c'` (`kept`'s outputs).
fn lstm_update(gates: &mut Tensor, c: &TValue, n: usize, h: usize, kept: &mut Kept) -> TractResult<()> {
    let mut view = gates.try_as_plain_ram_mut()?;
    let z = view.as_slice_mut::<f32>()?;
    let sigmoid = Func::Sigmoid.ew_f32()?;
    let tanh = Func::Tanh.ew_f32()?;
    let c_prev = plain_f32(c)?;
    let mut outs = kept.outputs(&[&[n, h], &[n, h]])?;
    let [h_out, c_out] = &mut outs[..] else { bail!("an LSTM cell has two outputs") };
    {
        let mut hv = h_out.try_as_plain_ram_mut()?;
        let hs = hv.as_slice_mut::<f32>()?;
        let mut cv = c_out.try_as_plain_ram_mut()?;
        let cs = cv.as_slice_mut::<f32>()?;
        for (r, row) in z.chunks_exact_mut(4 * h).enumerate() {
            let (ifg, o) = row.split_at_mut(3 * h);
            let (if_, g) = ifg.split_at_mut(2 * h);
            sigmoid.run(if_)?;
            tanh.run(g)?;
            sigmoid.run(o)?;
            let (i, f) = if_.split_at(h);
            let (cp, c, hh) = (&c_prev[r * h..][..h], &mut cs[r * h..][..h], &mut hs[r * h..][..h]);
            for j in 0..h {
                c[j] = f[j] * cp[j] + i[j] * g[j];
            }
            hh.copy_from_slice(c);
            tanh.run(hh)?;
            hh.iter_mut().zip(o.iter()).for_each(|(v, o)| *v *= o);
        }
    }
    Ok(())
}

impl TypedOp for LstmOp {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let fact = f32::fact(inputs[0].shape.clone());
        Ok(tvec!(fact.clone(), fact))
    }
}
