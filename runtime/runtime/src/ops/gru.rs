//! [`super::ZOO_GRU`]: one direction of a GRU layer's recurrence on tract-linalg's kernel, its
//! input products computed before it, for every frame and both directions at once, by one
//! [`super::ZOO_DENSE`] node.

use super::plain_f32;
use super::product::{Product, Recurrent, RecurrentWidth, Weights};
use std::sync::Arc;
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};
use tract_onnx::tract_hir::internal::*;
use tract_onnx::tract_hir::prelude::tract_linalg::Func;

/// A parsed [`super::ZOO_GRU`] node.
#[derive(Clone, Debug)]
pub(super) struct GruSpec {
    pub(super) hidden: usize,
    pub(super) weights: Arc<Vec<Weights>>,
    pub(super) bias: Option<Arc<Tensor>>,
    pub(super) reverse: bool,
    pub(super) h0_index: usize,
    pub(super) has_h0: bool,
    /// Which `3 hidden` block of each `xw` row is this direction's (both directions' input
    /// products come from one node).
    pub(super) xw_block: usize,
    /// The recurrent weights as the file stores them, for the product of one character.
    pub(super) compact: Option<Arc<Compact>>,
}

/// The int8 file's recurrent weights: `w = q * scale`, one scale per row.
#[derive(Clone, Debug)]
pub(super) struct Compact {
    pub(super) q: Vec<i8>,
    pub(super) scales: Vec<f32>,
}

impl Expansion for GruSpec {
    fn name(&self) -> StaticName {
        "ZooGru".into()
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
        check_input_arity(inputs, 1 + self.has_h0 as usize)?;
        check_output_arity(outputs, 2)?;
        s.equals(&inputs[0].datum_type, f32::datum_type())?;
        s.equals(&inputs[0].rank, 3)?;
        s.given(&inputs[0].shape[2], move |_, width| {
            let width = width.to_usize()?;
            ensure!(
                width % (3 * self.hidden) == 0 && width / (3 * self.hidden) > self.xw_block,
                "ZooGru: input rows of {width} values hold no gate block {}",
                self.xw_block
            );
            Ok(())
        })?;
        for o in outputs {
            s.equals(&o.datum_type, f32::datum_type())?;
        }
        let (y, h) = (&outputs[0], &outputs[1]);
        s.equals(&y.rank, 4)?;
        s.equals(&y.shape[0], &inputs[0].shape[0])?;
        s.equals(&y.shape[1], 1.to_dim())?;
        s.equals(&y.shape[2], &inputs[0].shape[1])?;
        s.equals(&y.shape[3], self.hidden.to_dim())?;
        s.equals(&h.rank, 3)?;
        s.equals(&h.shape[0], 1.to_dim())?;
        s.equals(&h.shape[1], &inputs[0].shape[1])?;
        s.equals(&h.shape[2], self.hidden.to_dim())?;
        if self.has_h0 {
            s.equals(&inputs[1].rank, 3)?;
            s.equals(&inputs[1].shape[1], &inputs[0].shape[1])?;
            s.equals(&inputs[1].shape[2], self.hidden.to_dim())?;
        }
        Ok(())
    }

    fn wire(&self, prefix: &str, model: &mut TypedModel, inputs: &[OutletId]) -> TractResult<TVec<OutletId>> {
        let batch = model.outlet_fact(inputs[0])?.shape.get(1).and_then(|d| d.to_usize().ok());
        let mut product = Product::new(3 * self.hidden, &self.weights, batch)?;
        if let (Some(c), Some(1), true) = (&self.compact, batch, Recurrent::available()) {
            let (m, k) = (3 * self.hidden, self.hidden);
            product = product.with_recurrent(Recurrent::new(m, k, RecurrentWidth::I8, &[], &c.q, &c.scales)?)?;
        }
        let op = GruOp {
            product,
            hidden: self.hidden,
            bias: self.bias.clone(),
            reverse: self.reverse,
            h0_index: self.h0_index,
            has_h0: self.has_h0,
            xw_block: self.xw_block,
        };
        model.wire_node(prefix, op, inputs)
    }
}

/// One direction of a GRU layer over a sequence: per frame the recurrent product
/// `g = h R^T + Rb` of the three gates in one kernel call, then
/// `z, r = sigmoid(xw + g)`, `n = tanh(xw_h + r * g_h)`, `h' = (1 - z) * n + z * h`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct GruOp {
    product: Product,
    hidden: usize,
    bias: Option<Arc<Tensor>>,
    reverse: bool,
    h0_index: usize,
    has_h0: bool,
    xw_block: usize,
}

thread_local! {
    /// The recurrent products and the state of the last GRU call on this thread, reused.
    static GRU_SCRATCH: std::cell::RefCell<(Tensor, Vec<f32>)> = std::cell::RefCell::new((Tensor::default(), Vec::new()));
}

impl Op for GruOp {
    fn name(&self) -> StaticName {
        "ZooGru".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!(
            "hidden {}{} on {}{}",
            self.hidden,
            if self.reverse { ", reversed" } else { "" },
            self.product.kernel_name(),
            super::one_character(&self.product)
        )])
    }

    op_as_typed_op!();
}

impl EvalOp for GruOp {
    op_out_of_plan!();
    super::kept_eval!();
}

impl super::WritesKept for GruOp {
    fn eval_kept(&self, inputs: &[TValue], kept: &mut super::Kept) -> TractResult<()> {
        let (p, h) = (&self.product, self.hidden);
        let shape = inputs[0].shape();
        let (frames, n, width) = (shape[0], shape[1], shape[2]);
        ensure!(width >= (self.xw_block + 1) * 3 * h, "ZooGru: no gate block {} in {width} values", self.xw_block);
        let xw = plain_f32(&inputs[0])?;
        let mut outs = kept.outputs(&[&[frames, 1, n, h], &[1, n, h]])?;
        let [y, last] = &mut outs[..] else { bail!("a GRU has two outputs") };
        GRU_SCRATCH.with_borrow_mut(|(gates, state)| {
            if gates.shape() != [n, 3 * h] {
                *gates = Tensor::zero::<f32>(&[n, 3 * h])?;
            }
            state.clear();
            if self.has_h0 {
                let h0 = plain_f32(&inputs[1])?;
                let at = self.h0_index * n * h;
                ensure!(h0.len() >= at + n * h, "ZooGru: no initial state {} in {} values", self.h0_index, h0.len());
                state.extend_from_slice(&h0[at..at + n * h]);
            } else {
                state.resize(n * h, 0.0);
            }
            let sigmoid = Func::Sigmoid.ew_f32()?;
            let tanh = Func::Tanh.ew_f32()?;
            let mut yv = y.try_as_plain_ram_mut()?;
            let ys = yv.as_slice_mut::<f32>()?;
            for step in 0..frames {
                let t = if self.reverse { frames - 1 - step } else { step };
                p.run_f32(&[state.as_slice()], n, self.bias.as_deref(), None, None, gates)?;
                let mut gv = gates.try_as_plain_ram_mut()?;
                let g = gv.as_slice_mut::<f32>()?;
                for r in 0..n {
                    let x = &xw[(t * n + r) * width + self.xw_block * 3 * h..][..3 * h];
                    let row = &mut g[r * 3 * h..][..3 * h];
                    let (zr, gh) = row.split_at_mut(2 * h);
                    zr.iter_mut().zip(&x[..2 * h]).for_each(|(v, x)| *v += x);
                    sigmoid.run(zr)?;
                    let (z, rr) = zr.split_at(h);
                    gh.iter_mut().zip(rr).zip(&x[2 * h..]).for_each(|((v, r), x)| *v = x + r * *v);
                    tanh.run(gh)?;
                    let hs = &mut state[r * h..][..h];
                    for j in 0..h {
                        hs[j] = (1.0 - z[j]) * gh[j] + z[j] * hs[j];
                    }
                    ys[(t * n + r) * h..][..h].copy_from_slice(hs);
                }
            }
            let mut lv = last.try_as_plain_ram_mut()?;
            lv.as_slice_mut::<f32>()?.copy_from_slice(state);
            Ok::<_, TractError>(())
        })
    }
}

impl TypedOp for GruOp {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        let s = &inputs[0].shape;
        let h = self.hidden.to_dim();
        Ok(tvec!(
            f32::fact([s[0].clone(), 1.to_dim(), s[1].clone(), h.clone()]),
            f32::fact([1.to_dim(), s[1].clone(), h])
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::super::attr;
    use tract_onnx::pb;
    use tract_onnx::prelude::*;

    type Dt = pb::tensor_proto::DataType;

    fn value(name: &str) -> pb::ValueInfoProto {
        pb::ValueInfoProto { name: name.into(), ..Default::default() }
    }

    /// A graph input of f32 values (its shape set when planned).
    fn f32_input(name: &str) -> pb::ValueInfoProto {
        let tensor = pb::type_proto::Tensor { elem_type: Dt::Float as i32, shape: None };
        let r#type = pb::TypeProto { value: Some(pb::type_proto::Value::TensorType(tensor)), ..Default::default() };
        pb::ValueInfoProto { name: name.into(), r#type: Some(r#type), ..Default::default() }
    }

    fn init(name: &str, dims: &[usize], seed: usize) -> pb::TensorProto {
        let n: usize = dims.iter().product();
        let v: Vec<f32> = (0..n).map(|i| ((((i + seed) * 7919) % 211) as f32 / 211.0 - 0.5) * 0.8).collect();
        super::super::rewrite::f32_init(name, dims, &v)
    }

    /// A graph of one ONNX `GRU` node over `x [frames, batch, 5]`, hidden 6, in `direction`,
    /// with an initial state input when `h0`; outputs `Y` and `Y_h`. Its weights at `width`, as
    /// `zoo export --weights` writes them: "f32"; "f16" (half-float initializers and a `Cast`);
    /// "int8" (integers per row of axis 1, widened by `DequantizeLinear`).
    fn gru_graph(direction: &str, h0: bool, width: &str) -> pb::ModelProto {
        let (dirs, h, k) = (if direction == "bidirectional" { 2 } else { 1 }, 6, 5);
        let mut inputs = vec!["x".to_string(), "W".into(), "R".into(), "B".into()];
        let mut graph_inputs = vec![f32_input("x")];
        if h0 {
            inputs.extend(["".to_string(), "h0".to_string()]);
            graph_inputs.push(f32_input("h0"));
        }
        let node = pb::NodeProto {
            name: "gru".into(),
            op_type: "GRU".into(),
            input: inputs,
            output: vec!["Y".into(), "Y_h".into()],
            attribute: vec![
                attr::int("hidden_size", h as i64),
                attr::string("direction", direction),
                attr::int("linear_before_reset", 1),
            ],
            ..Default::default()
        };
        let mut nodes = Vec::new();
        let mut initializer = vec![init("B", &[dirs, 6 * h], 3)];
        for (name, dims, seed) in [("W", [dirs, 3 * h, k], 1), ("R", [dirs, 3 * h, h], 2)] {
            let t = init(name, &dims, seed);
            let v = super::super::tensor_f32(&t).unwrap();
            let stored = |suffix: &str, dt: Dt, raw: Vec<u8>| pb::TensorProto {
                name: format!("{name}.{suffix}"),
                dims: dims.iter().map(|d| *d as i64).collect(),
                data_type: dt as i32,
                raw_data: raw,
                ..Default::default()
            };
            match width {
                "f32" => initializer.push(t),
                "f16" => {
                    let raw = v.iter().flat_map(|x| f16::from_f32(*x).to_le_bytes()).collect();
                    initializer.push(stored("f16", Dt::Float16, raw));
                    nodes.push(pb::NodeProto {
                        op_type: "Cast".into(),
                        input: vec![format!("{name}.f16")],
                        output: vec![name.into()],
                        attribute: vec![attr::int("to", Dt::Float as i64)],
                        ..Default::default()
                    });
                }
                "int8" => {
                    let (rows, inner) = (dims[1], dims[2]);
                    let mut scales = vec![0f32; rows];
                    for (i, x) in v.iter().enumerate() {
                        scales[(i / inner) % rows] = scales[(i / inner) % rows].max(x.abs() / 127.0);
                    }
                    let q = v.iter().enumerate().map(|(i, x)| (x / scales[(i / inner) % rows]).round() as i8 as u8);
                    initializer.push(stored("int8", Dt::Int8, q.collect()));
                    initializer.push(super::super::rewrite::f32_init(&format!("{name}.scale"), &[rows], &scales));
                    nodes.push(pb::NodeProto {
                        op_type: "DequantizeLinear".into(),
                        input: vec![format!("{name}.int8"), format!("{name}.scale")],
                        output: vec![name.into()],
                        attribute: vec![attr::int("axis", 1)],
                        ..Default::default()
                    });
                }
                other => panic!("no width {other}"),
            }
        }
        nodes.push(node);
        let graph = pb::GraphProto {
            node: nodes,
            initializer,
            input: graph_inputs,
            output: vec![value("Y"), value("Y_h")],
            ..Default::default()
        };
        pb::ModelProto {
            ir_version: 8,
            opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 17 }],
            graph: Some(graph),
            ..Default::default()
        }
    }

    /// The outputs of `model` on `inputs`, and what its `ZooGru` nodes say of themselves.
    fn run(model: InferenceModel, inputs: &[Tensor]) -> (TVec<TValue>, Vec<String>) {
        let mut model = model;
        for (i, t) in inputs.iter().enumerate() {
            model.set_input_fact(i, f32::fact(t.shape()).into()).unwrap();
        }
        let optimized = model.into_optimized().unwrap();
        let info = optimized
            .nodes
            .iter()
            .filter(|n| n.op.name() == "ZooGru")
            .map(|n| n.op.info().unwrap().join(" "))
            .collect();
        let plan = optimized.into_runnable().unwrap();
        (plan.run(inputs.iter().cloned().map(|t| t.into_tvalue()).collect()).unwrap(), info)
    }

    #[test]
    fn zoo_gru_nodes_compute_the_onnx_gru() {
        let (frames, h) = (7, 6);
        for (direction, h0, width, batch) in ["forward", "bidirectional", "reverse"]
            .into_iter()
            .flat_map(|d| [false, true].map(|h0| (d, h0)))
            .flat_map(|(d, h0)| ["f32", "f16", "int8"].map(|w| (d, h0, w)))
            .flat_map(|(d, h0, w)| [1, 3].map(|b| (d, h0, w, b)))
        {
            let case = format!("{direction}, h0 {h0}, {width} weights, batch {batch}");
            let proto = gru_graph(direction, h0, width);
            let fused = super::super::fuse(&proto).expect("the GRU is rewritten");
            let ops: Vec<&str> = fused.graph.as_ref().unwrap().node.iter().map(|n| n.op_type.as_str()).collect();
            assert!(ops.contains(&"ZooGru") && ops.contains(&"ZooDense") && !ops.contains(&"GRU"), "{case}: {ops:?}");
            let dirs = if direction == "bidirectional" { 2 } else { 1 };
            let x: Vec<f32> = (0..frames * batch * 5).map(|i| ((i as f32) * 0.37).sin()).collect();
            let mut inputs = vec![Tensor::from_shape(&[frames, batch, 5], &x).unwrap()];
            if h0 {
                let v: Vec<f32> = (0..dirs * batch * h).map(|i| ((i as f32) * 0.71).cos() * 0.5).collect();
                inputs.push(Tensor::from_shape(&[dirs, batch, h], &v).unwrap());
            }
            let (zoo, info) = run(super::super::onnx().model_for_proto_model(&fused).unwrap(), &inputs);
            // A character alone runs the recurrence on the file's own 16- or 8-bit weights.
            let compact = width != "f32" && batch == 1 && super::super::product::Recurrent::available();
            assert!(
                !info.is_empty() && info.iter().all(|i| i.contains("one character on") == compact),
                "{case}: {info:?}"
            );
            // The reference: tract's own GRU; for `reverse`, its forward GRU over the frames in
            // reverse order, the output put back in order (tract 0.23.9's `reverse` GRU
            // disagrees with onnxruntime, which agrees with this).
            let plain = if direction == "reverse" {
                let flip = |t: &Tensor| {
                    let (f, rest) = (t.shape()[0], t.len() / t.shape()[0]);
                    let v = t.try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec();
                    let r: Vec<f32> = (0..f).rev().flat_map(|i| v[i * rest..(i + 1) * rest].to_vec()).collect();
                    Tensor::from_shape(t.shape(), &r).unwrap()
                };
                let mut flipped = inputs.clone();
                flipped[0] = flip(&inputs[0]);
                let forward = gru_graph("forward", h0, width);
                let (out, _) = run(tract_onnx::onnx().model_for_proto_model(&forward).unwrap(), &flipped);
                let y = flip(&out[0].clone().into_tensor());
                tvec![y.into_tvalue(), out[1].clone()]
            } else {
                run(tract_onnx::onnx().model_for_proto_model(&proto).unwrap(), &inputs).0
            };
            for (o, (a, b)) in plain.iter().zip(&zoo).enumerate() {
                assert_eq!(a.shape(), b.shape(), "{case}: output {o}");
                let (a, b) = (super::plain_f32(a).unwrap(), super::plain_f32(b).unwrap());
                let diff = a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(diff < 1e-5, "{case}: output {o} differs by {diff}");
            }
        }
    }
}
