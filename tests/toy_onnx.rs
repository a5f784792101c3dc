//! Toy recurrent step graphs written with `zoo-export`, and their plain-Rust references.
//!
//! The toy model mirrors the shape of RTN's step (a frame encoder, a recurrent cell, a
//! decoder predicting an offset added to the input frame) at tiny sizes. Weights are in
//! candle/PyTorch layout (`Linear` weight `[out, in]`, LSTM gates i,f,g,o, GRU gates r,z,n)
//! and are converted to ONNX layout by the graph builders, so the reference also checks the
//! gate reordering of `zoo_export::reorder_gates`.

use zoo_export::{Dim, GRU_TORCH_TO_ONNX, GraphBuilder, LSTM_TORCH_TO_ONNX, OnnxModel, RnnDirection, RnnInputs, Value};
use zoo_runtime::metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
    MotionTask,
};

/// Slope of the encoder's LeakyRelu.
pub const LEAKY_ALPHA: f32 = 0.2;

/// Deterministic values in [-scale, scale) from a 64-bit LCG (Knuth's MMIX constants).
pub fn lcg(seed: u64, n: usize, scale: f32) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(1);
    (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * scale
        })
        .collect()
}

/// Which recurrent cell the toy uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cell {
    /// LSTM (state h, c).
    Lstm,
    /// GRU with candle's `linear_before_reset = 1` math (state h).
    Gru,
}

impl Cell {
    fn gates(self) -> usize {
        match self {
            Cell::Lstm => 4,
            Cell::Gru => 3,
        }
    }
}

/// Weights of the toy step model, PyTorch layout.
#[derive(Clone, Debug)]
pub struct ToyModel {
    /// Cell type.
    pub cell: Cell,
    /// Frame width (input and output).
    pub frame: usize,
    /// Encoder width.
    pub enc: usize,
    /// Hidden size.
    pub hidden: usize,
    /// Encoder weight `[enc, frame]`.
    pub enc_w: Vec<f32>,
    /// Encoder bias `[enc]`.
    pub enc_b: Vec<f32>,
    /// `weight_ih_l0`, `[gates * hidden, enc]`.
    pub w_ih: Vec<f32>,
    /// `weight_hh_l0`, `[gates * hidden, hidden]`.
    pub w_hh: Vec<f32>,
    /// `bias_ih_l0`, `[gates * hidden]`.
    pub b_ih: Vec<f32>,
    /// `bias_hh_l0`, `[gates * hidden]`.
    pub b_hh: Vec<f32>,
    /// Decoder weight `[frame, hidden]`.
    pub dec_w: Vec<f32>,
    /// Decoder bias `[frame]`.
    pub dec_b: Vec<f32>,
}

impl ToyModel {
    /// Fixed weights for a toy of the given sizes.
    pub fn new(cell: Cell, frame: usize, enc: usize, hidden: usize) -> Self {
        let g = cell.gates() * hidden;
        let s = |n: usize| 1.0 / (n as f32).sqrt();
        ToyModel {
            cell,
            frame,
            enc,
            hidden,
            enc_w: lcg(1, enc * frame, s(frame)),
            enc_b: lcg(2, enc, 0.1),
            w_ih: lcg(3, g * enc, s(enc)),
            w_hh: lcg(4, g * hidden, s(hidden)),
            b_ih: lcg(5, g, 0.1),
            b_hh: lcg(6, g, 0.1),
            dec_w: lcg(7, frame * hidden, 0.5 * s(hidden)),
            dec_b: lcg(8, frame, 0.05),
        }
    }

    /// State slot widths: `[h, c]` for LSTM, `[h]` for GRU.
    pub fn state_widths(&self) -> Vec<usize> {
        match self.cell {
            Cell::Lstm => vec![self.hidden, self.hidden],
            Cell::Gru => vec![self.hidden],
        }
    }

    /// One step of one character in plain Rust (f64 accumulation): returns the next frame and
    /// replaces `state` (`[h]` or `[h, c]`).
    pub fn step(&self, x: &[f32], state: &mut [Vec<f32>]) -> Vec<f32> {
        let linear = |w: &[f32], b: &[f32], v: &[f32], rows: usize| -> Vec<f64> {
            (0..rows)
                .map(|r| {
                    b[r] as f64
                        + w[r * v.len()..(r + 1) * v.len()]
                            .iter()
                            .zip(v)
                            .map(|(a, b)| *a as f64 * *b as f64)
                            .sum::<f64>()
                })
                .collect()
        };
        let sig = |v: f64| 1.0 / (1.0 + (-v).exp());
        let e: Vec<f32> = linear(&self.enc_w, &self.enc_b, x, self.enc)
            .into_iter()
            .map(|v| (if v < 0.0 { LEAKY_ALPHA as f64 * v } else { v }) as f32)
            .collect();
        let g = self.cell.gates() * self.hidden;
        let gi = linear(&self.w_ih, &self.b_ih, &e, g);
        let gh = linear(&self.w_hh, &self.b_hh, &state[0], g);
        let h = self.hidden;
        let h_next: Vec<f32> = match self.cell {
            Cell::Lstm => {
                // PyTorch LSTM: gates i, f, g, o.
                let mut h_next = vec![0.0; h];
                for k in 0..h {
                    let a = |q: usize| gi[q * h + k] + gh[q * h + k];
                    let (i, f, gg, o) = (sig(a(0)), sig(a(1)), a(2).tanh(), sig(a(3)));
                    let c = f * state[1][k] as f64 + i * gg;
                    state[1][k] = c as f32;
                    h_next[k] = (o * c.tanh()) as f32;
                }
                h_next
            }
            Cell::Gru => {
                // PyTorch GRU: gates r, z, n; n = tanh(W_in e + b_in + r * (W_hn h + b_hn)).
                (0..h)
                    .map(|k| {
                        let r = sig(gi[k] + gh[k]);
                        let z = sig(gi[h + k] + gh[h + k]);
                        let n = (gi[2 * h + k] + r * gh[2 * h + k]).tanh();
                        ((1.0 - z) * n + z * state[0][k] as f64) as f32
                    })
                    .collect()
            }
        };
        state[0].copy_from_slice(&h_next);
        let d = linear(&self.dec_w, &self.dec_b, &h_next, self.frame);
        x.iter().zip(d).map(|(x, d)| (*x as f64 + d) as f32).collect()
    }

    /// Start-graph weight `[hidden, frame]` (fixed).
    fn start_w(&self) -> Vec<f32> {
        lcg(9, self.hidden * self.frame, 1.0 / (self.frame as f32).sqrt())
    }

    /// Initial state from the first frame, as the start graph computes it:
    /// `h = tanh(W_s x0)`, `c = 0.5 h` (LSTM only).
    pub fn start_state(&self, x0: &[f32]) -> Vec<Vec<f32>> {
        let w = self.start_w();
        let h: Vec<f32> = (0..self.hidden)
            .map(|r| {
                let z: f64 =
                    w[r * self.frame..(r + 1) * self.frame].iter().zip(x0).map(|(a, b)| *a as f64 * *b as f64).sum();
                z.tanh() as f32
            })
            .collect();
        match self.cell {
            Cell::Lstm => vec![h.clone(), h.iter().map(|v| 0.5 * v).collect()],
            Cell::Gru => vec![h],
        }
    }

    /// The transition-start graph: `x0` `[batch, frame]` -> the state inputs `h` (and `c`).
    pub fn start_graph(&self) -> OnnxModel {
        let mut g = GraphBuilder::new("toy_start");
        let b = Dim::batch;
        let x0 = g.input("x0", &[b(), Dim::Fixed(self.frame)]);
        let w = g.initializer_f32("state_init.weight", &[self.hidden, self.frame], &self.start_w());
        let z = g.gemm("state_init.gemm", &x0, &w, None, true);
        let h = g.tanh("h", &z);
        g.output("h", &h, &[b(), Dim::Fixed(self.hidden)]);
        if self.cell == Cell::Lstm {
            let half = g.initializer_f32("state_init.c_scale", &[1], &[0.5]);
            let c = g.mul("c", &h, &half);
            g.output("c", &c, &[b(), Dim::Fixed(self.hidden)]);
        }
        g.finish().expect("toy start graph")
    }

    /// `step` with the start graph embedded in its metadata_props (`zoo.start_graph`).
    pub fn with_start(&self, step: &OnnxModel) -> OnnxModel {
        let mut proto = step.proto().clone();
        proto.metadata_props.push(zoo_export::pb::StringStringEntryProto {
            key: zoo_runtime::metadata::keys::START_GRAPH.into(),
            value: self.start_graph().to_base64(),
        });
        OnnxModel::from_proto(proto)
    }

    /// Metadata of the toy's step graphs: task `step` (no task section), kind `toy_lstm` or
    /// `toy_gru`, which no task loader knows.
    pub fn metadata(&self) -> MotionModelMetadata {
        let state = match self.cell {
            Cell::Lstm => vec![
                MotionStatePair { input: "h".into(), output: "h_next".into() },
                MotionStatePair { input: "c".into(), output: "c_next".into() },
            ],
            Cell::Gru => vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        };
        MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind: format!("toy_{:?}", self.cell).to_lowercase(),
            task: MotionTask::Step,
            config_json: format!("{{\"frame\": {}, \"enc\": {}, \"hidden\": {}}}", self.frame, self.enc, self.hidden),
            normalization: [(
                "x".to_string(),
                MotionMeanStd { mean: vec![0.0; self.frame], std: vec![1.0; self.frame] },
            )]
            .into(),
            skeleton: MotionSkeletonInfo {
                names: vec!["Hips".into(), "Spine".into()],
                parents: vec![-1, 0],
                offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
            },
            feature_layout: vec![MotionFeatureSegment { name: "frame".into(), start: 0, len: self.frame }],
            fps: 30.0,
            frame: zoo_runtime::metadata::CoordinateFrame::ZOO_CM,
            state,
            weights: zoo_runtime::metadata::WeightWidth::F32,
        }
    }

    fn begin(&self, g: &mut GraphBuilder) -> (Value, Value, Vec<Value>) {
        for (k, v) in self.metadata().to_props() {
            g.metadata(&k, &v);
        }
        let b = Dim::batch;
        let x = g.input("x", &[b(), Dim::Fixed(self.frame)]);
        let states: Vec<Value> = ["h", "c"][..self.state_widths().len()]
            .iter()
            .map(|n| g.input(n, &[b(), Dim::Fixed(self.hidden)]))
            .collect();
        let w = g.initializer_f32("frame_encoder.weight", &[self.enc, self.frame], &self.enc_w);
        let bias = g.initializer_f32("frame_encoder.bias", &[self.enc], &self.enc_b);
        let e = g.gemm("frame_encoder.gemm", &x, &w, Some(&bias), true);
        let e = g.leaky_relu("frame_encoder.leaky_relu", &e, LEAKY_ALPHA);
        (x, e, states)
    }

    fn end(&self, g: &mut GraphBuilder, x: &Value, h_next: &Value, c_next: Option<&Value>) {
        let w = g.initializer_f32("decoder.weight", &[self.frame, self.hidden], &self.dec_w);
        let bias = g.initializer_f32("decoder.bias", &[self.frame], &self.dec_b);
        let d = g.gemm("decoder.gemm", h_next, &w, Some(&bias), true);
        let y = g.add("decoder.residual", x, &d);
        let b = Dim::batch;
        g.output("y", &y, &[b(), Dim::Fixed(self.frame)]);
        g.output("h_next", h_next, &[b(), Dim::Fixed(self.hidden)]);
        if let Some(c) = c_next {
            g.output("c_next", c, &[b(), Dim::Fixed(self.hidden)]);
        }
    }

    /// The LSTM step written with MatMul, Concat, Split, Sigmoid, Tanh, Mul and Add.
    pub fn cell_graph(&self) -> OnnxModel {
        assert_eq!(self.cell, Cell::Lstm, "cell_graph writes an LSTM");
        let mut g = GraphBuilder::new("toy_lstm_cell_step");
        let (x, e, s) = self.begin(&mut g);
        let (h, e_w) = (self.hidden, self.enc);
        // [e, h] @ [W_ih^T; W_hh^T]: one matmul for all four gates.
        let mut w = vec![0.0; (e_w + h) * 4 * h];
        for r in 0..4 * h {
            for k in 0..e_w {
                w[k * 4 * h + r] = self.w_ih[r * e_w + k];
            }
            for k in 0..h {
                w[(e_w + k) * 4 * h + r] = self.w_hh[r * h + k];
            }
        }
        let bias: Vec<f32> = self.b_ih.iter().zip(&self.b_hh).map(|(a, b)| a + b).collect();
        let w = g.initializer_f32("lstm.weight_cat", &[e_w + h, 4 * h], &w);
        let bias = g.initializer_f32("lstm.bias_sum", &[4 * h], &bias);
        let cat = g.concat("lstm.concat", &[&e, &s[0]], 1);
        let z = g.matmul("lstm.matmul", &cat, &w);
        let z = g.add("lstm.add_bias", &z, &bias);
        let parts = g.split("lstm.gates", &z, &[h; 4], 1);
        let i = g.sigmoid("lstm.input_gate", &parts[0]);
        let f = g.sigmoid("lstm.forget_gate", &parts[1]);
        let c_in = g.tanh("lstm.cell_gate", &parts[2]);
        let o = g.sigmoid("lstm.output_gate", &parts[3]);
        let fc = g.mul("lstm.forget_mul", &f, &s[1]);
        let ig = g.mul("lstm.input_mul", &i, &c_in);
        let c_next = g.add("c_next", &fc, &ig);
        let tc = g.tanh("lstm.cell_tanh", &c_next);
        let h_next = g.mul("h_next", &o, &tc);
        self.end(&mut g, &x, &h_next, Some(&c_next));
        g.finish().expect("toy cell graph")
    }

    /// The step written with the ONNX `LSTM` or `GRU` op over a sequence of length 1.
    pub fn rnn_op_graph(&self) -> OnnxModel {
        let name = match self.cell {
            Cell::Lstm => "toy_lstm_op_step",
            Cell::Gru => "toy_gru_op_step",
        };
        let mut g = GraphBuilder::new(name);
        let (x, e, s) = self.begin(&mut g);
        let (h, gates) = (self.hidden, self.cell.gates());
        let order: &[usize] = match self.cell {
            Cell::Lstm => &LSTM_TORCH_TO_ONNX,
            Cell::Gru => &GRU_TORCH_TO_ONNX,
        };
        let reorder = |d: &[f32], cols| zoo_export::reorder_gates(d, h, cols, order);
        let w = g.initializer_f32("rnn.weight_ih_l0", &[1, gates * h, self.enc], &reorder(&self.w_ih, self.enc));
        let r = g.initializer_f32("rnn.weight_hh_l0", &[1, gates * h, h], &reorder(&self.w_hh, h));
        let mut b = reorder(&self.b_ih, 1);
        b.extend(reorder(&self.b_hh, 1));
        let b = g.initializer_f32("rnn.bias", &[1, 2 * gates * h], &b);
        let seq = g.unsqueeze("rnn.x_seq", &e, &[0]);
        let h0 = g.unsqueeze("rnn.h0", &s[0], &[0]);
        let rnn = RnnInputs {
            x: &seq,
            w: &w,
            r: &r,
            b: Some(&b),
            initial_h: Some(&h0),
            hidden_size: h,
            direction: RnnDirection::Forward,
        };
        let (h_next, c_next) = match self.cell {
            Cell::Lstm => {
                let c0 = g.unsqueeze("rnn.c0", &s[1], &[0]);
                let out = g.lstm("rnn.lstm", &rnn, Some(&c0));
                let c = g.squeeze("c_next", out.y_c.as_ref().expect("LSTM has Y_c"), &[0]);
                (g.squeeze("h_next", &out.y_h, &[0]), Some(c))
            }
            Cell::Gru => {
                let out = g.gru("rnn.gru", &rnn, true);
                (g.squeeze("h_next", &out.y_h, &[0]), None)
            }
        };
        self.end(&mut g, &x, &h_next, c_next.as_ref());
        g.finish().expect("toy rnn graph")
    }
}

/// A one-shot graph through the remaining writer ops (Sub, Div, Slice, Gather, Reshape,
/// Transpose, Identity, Concat): `x` `[batch, 6]` -> `y` `[batch, 6]`, with its reference.
pub fn ops_graph() -> OnnxModel {
    let mut g = GraphBuilder::new("toy_ops");
    let mut meta = ToyModel::new(Cell::Gru, 6, 2, 2).metadata();
    meta.model_kind = "toy_ops".into();
    meta.state.clear();
    for (k, v) in meta.to_props() {
        g.metadata(&k, &v);
    }
    let b = Dim::batch;
    let x = g.input("x", &[b(), Dim::Fixed(6)]);
    let mean = g.initializer_f32("norm.mean", &[6], &[0.5, -0.5, 1.0, 0.0, 2.0, -1.0]);
    let std = g.initializer_f32("norm.std", &[6], &[1.0, 2.0, 0.5, 4.0, 1.5, 3.0]);
    let n = g.sub("norm.sub", &x, &mean);
    let n = g.div("norm.div", &n, &std);
    let head = g.slice("head", &n, &[1], &[0], &[2]);
    let tail = g.gather("tail", &n, &[5, 4, 3, 2], 1);
    let cat = g.concat("cat", &[&tail, &head], 1);
    let r = g.reshape("pairs", &cat, &[-1, 3, 2]);
    let t = g.transpose("pairs_t", &r, &[0, 2, 1]);
    let flat = g.reshape("flat", &t, &[0, 6]);
    let y = g.identity("identity", &flat);
    g.output("y", &y, &[b(), Dim::Fixed(6)]);
    g.finish().expect("toy ops graph")
}

/// Plain-Rust reference of [`ops_graph`] for one row.
pub fn ops_reference(x: &[f32]) -> Vec<f32> {
    let mean = [0.5, -0.5, 1.0, 0.0, 2.0, -1.0];
    let std = [1.0, 2.0, 0.5, 4.0, 1.5, 3.0];
    let n: Vec<f32> = (0..6).map(|i| (x[i] - mean[i]) / std[i]).collect();
    let cat = [n[5], n[4], n[3], n[2], n[0], n[1]];
    // [3, 2] transposed to [2, 3]
    (0..2).flat_map(|j| (0..3).map(move |i| cat[i * 2 + j])).collect()
}
