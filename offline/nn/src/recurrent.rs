//! Recurrent layers with the state outside the layer: multi-layer [`Lstm`] and [`Gru`]
//! (`zero_state(batch)`, `step(x, &state) -> state`, `forward_seq`), and bidirectional
//! [`BiLstm`] / [`BiGru`] over a whole sequence.
//!
//! Weights use PyTorch's names and gate orders, under the layer's prefix: `weight_ih_l{k}`
//! `(G*H, input)`, `weight_hh_l{k}` `(G*H, H)`, `bias_ih_l{k}`, `bias_hh_l{k}` `(G*H)`, and the
//! same with `_reverse` for the backward direction. LSTM gates are i, f, g, o (G = 4; ONNX's
//! order is i, o, f, c); GRU gates are r, z, n (G = 3; ONNX's z, r, h with
//! `linear_before_reset = 1`). Initialisation as PyTorch: `U(-1/sqrt(H), 1/sqrt(H))`.
//!
//! LSTM (Hochreiter & Schmidhuber 1997, PyTorch's formulation):
//! `i, f, o = sigma(W_i x + b_i + U h + b_h)`, `g = tanh(...)`, `c' = f c + i g`, `h' = o tanh(c')`.
//! GRU (Cho et al. 2014, PyTorch's formulation): `r, z = sigma(W x + b_i + U h + b_h)`,
//! `n = tanh(W_n x + b_in + r (U_n h + b_hn))`, `h' = (1 - z) n + z h`.
//!
//! Each step is one matmul for all gates; over a sequence the input projection of every frame is
//! one matmul. Sequences are batch-first: `(batch, time, features)`.

use crate::layers::{Dropout, RowRngs};
use candle_core::{D, Result, Tensor};
use candle_nn::{Init, VarBuilder};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Cell {
    Lstm,
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

/// One direction of one layer.
#[derive(Clone, Debug)]
struct Layer {
    cell: Cell,
    hidden: usize,
    w_ih: Tensor,
    w_hh: Tensor,
    b_ih: Tensor,
    b_hh: Tensor,
}

impl Layer {
    fn new(cell: Cell, input: usize, hidden: usize, suffix: &str, vb: &VarBuilder) -> Result<Self> {
        let k = 1.0 / (hidden as f64).sqrt();
        let init = Init::Uniform { lo: -k, up: k };
        let g = cell.gates() * hidden;
        Ok(Layer {
            cell,
            hidden,
            w_ih: vb.get_with_hints((g, input), &format!("weight_ih_{suffix}"), init)?,
            w_hh: vb.get_with_hints((g, hidden), &format!("weight_hh_{suffix}"), init)?,
            b_ih: vb.get_with_hints(g, &format!("bias_ih_{suffix}"), init)?,
            b_hh: vb.get_with_hints(g, &format!("bias_hh_{suffix}"), init)?,
        })
    }

    /// Input projection `x W_ih^T + b_ih` of `(batch, in)` or `(batch, time, in)`.
    fn input_proj(&self, x: &Tensor) -> Result<Tensor> {
        if let [b, t, i] = *x.dims() {
            // Every frame at once as the rows of one matmul (taped in training).
            let y = crate::tape::matmul_weight(&x.reshape((b * t, i))?, &self.w_ih, true)?;
            return crate::act::bias_add(&y, &self.b_ih)?.reshape((b, t, ()));
        }
        crate::tape::linear(x, &self.w_ih, &self.b_ih, None, None)
    }

    /// One step from the projected input `gx` `(batch, G*H)`: the new `h` and, for the LSTM, `c`.
    fn update(&self, gx: &Tensor, h: &Tensor, c: Option<&Tensor>) -> Result<(Tensor, Option<Tensor>)> {
        let gh = crate::tape::linear(h, &self.w_hh, &self.b_hh, None, None)?;
        match self.cell {
            Cell::Lstm => {
                let c = c.ok_or_else(|| candle_core::Error::Msg("an LSTM step needs the cell state".into()))?;
                let (h, c) = crate::cells::lstm_cell(&(gx + gh)?, c)?;
                Ok((h, Some(c)))
            }
            Cell::Gru => Ok((crate::cells::gru_cell(gx, &gh, h)?, None)),
        }
    }

    /// Runs the layer over `(batch, time, in)` from `(h, c)`: outputs `(batch, time, H)` and the
    /// last state.
    fn sequence(&self, xs: &Tensor, h: &Tensor, c: Option<&Tensor>) -> Result<(Tensor, Tensor, Option<Tensor>)> {
        let gx = self.input_proj(xs)?;
        let (mut h, mut c) = (h.clone(), c.cloned());
        let mut outs = Vec::with_capacity(xs.dim(1)?);
        for gx in frames(&gx, 1)? {
            let (h2, c2) = self.update(&gx, &h, c.as_ref())?;
            outs.push(h2.clone());
            (h, c) = (h2, c2);
        }
        Ok((Tensor::stack(&outs, 1)?, h, c))
    }
}

fn zeros(batch: usize, layer: &Layer) -> Result<Tensor> {
    Tensor::zeros((batch, layer.hidden), layer.w_hh.dtype(), layer.w_hh.device())
}

/// The slices of `x` along `dim`, each with `dim` removed: `x.narrow(dim, i, 1).squeeze(dim)`
/// for every `i`, the same values.
///
/// The backward pass of a narrow builds a gradient of its whole input (zeros around the slice)
/// and adds it to the input's: slicing every frame of a `(.., T, ..)` tensor that needs a
/// gradient one by one costs `T` whole-tensor gradients (quadratic in the sequence length). Here
/// the slices are taken from about `sqrt(T)` blocks of about `sqrt(T)` frames, so the backward
/// pass writes about `2 sqrt(T)` whole-tensor gradients; the gradient values are the same
/// (the padding adds exact zeros).
pub fn frames(x: &Tensor, dim: usize) -> Result<Vec<Tensor>> {
    let n = x.dim(dim)?;
    let block = ((n as f64).sqrt().ceil() as usize).max(1);
    let mut out = Vec::with_capacity(n);
    for start in (0..n).step_by(block) {
        let len = block.min(n - start);
        let b = if len == n { x.clone() } else { x.narrow(dim, start, len)? };
        for i in 0..len {
            out.push(b.narrow(dim, i, 1)?.squeeze(dim)?);
        }
    }
    Ok(out)
}

/// Reverses a `(batch, time, ...)` sequence along time.
pub fn reverse_time(xs: &Tensor) -> Result<Tensor> {
    let t = xs.dim(1)?;
    let idx: Vec<u32> = (0..t as u32).rev().collect();
    xs.index_select(&Tensor::from_vec(idx, t, xs.device())?, 1)
}

/// The state of a multi-layer [`Lstm`]: per layer `h` and `c`, each `(batch, hidden)`.
#[derive(Clone, Debug)]
pub struct LstmState {
    /// Output state of each layer, first layer first.
    pub h: Vec<Tensor>,
    /// Cell state of each layer.
    pub c: Vec<Tensor>,
}

impl LstmState {
    /// The last layer's output `(batch, hidden)`.
    pub fn output(&self) -> &Tensor {
        self.h.last().expect("an LSTM has at least one layer")
    }
}

/// The state of a multi-layer [`Gru`]: per layer `h` `(batch, hidden)`.
#[derive(Clone, Debug)]
pub struct GruState {
    /// Output state of each layer, first layer first.
    pub h: Vec<Tensor>,
}

impl GruState {
    /// The last layer's output `(batch, hidden)`.
    pub fn output(&self) -> &Tensor {
        self.h.last().expect("a GRU has at least one layer")
    }
}

/// The layers of a unidirectional stack and the dropout between them.
#[derive(Clone, Debug)]
struct Stack {
    layers: Vec<Layer>,
    dropout: Dropout,
}

impl Stack {
    fn new(cell: Cell, input: usize, hidden: usize, layers: usize, dropout: f64, vb: &VarBuilder) -> Result<Self> {
        if layers == 0 {
            candle_core::bail!("a recurrent layer needs at least one layer")
        }
        let layers = (0..layers)
            .map(|k| Layer::new(cell, if k == 0 { input } else { hidden }, hidden, &format!("l{k}"), vb))
            .collect::<Result<_>>()?;
        Ok(Stack { layers, dropout: Dropout::new(dropout) })
    }

    fn step(
        &self,
        x: &Tensor,
        h: &[Tensor],
        c: Option<&[Tensor]>,
        mut rng: Option<&mut RowRngs>,
    ) -> Result<(Vec<Tensor>, Option<Vec<Tensor>>)> {
        if h.len() != self.layers.len() {
            candle_core::bail!("the state has {} layers, the recurrent layer {}", h.len(), self.layers.len())
        }
        let (mut hs, mut cs) = (Vec::with_capacity(h.len()), c.map(|c| Vec::with_capacity(c.len())));
        let mut inp = x.clone();
        for (k, layer) in self.layers.iter().enumerate() {
            if k > 0 {
                inp = self.dropout.forward(&inp, rng.as_deref_mut())?;
            }
            let (h2, c2) = layer.update(&layer.input_proj(&inp)?, &h[k], c.map(|c| &c[k]))?;
            inp = h2.clone();
            hs.push(h2);
            if let (Some(cs), Some(c2)) = (cs.as_mut(), c2) {
                cs.push(c2);
            }
        }
        Ok((hs, cs))
    }

    fn sequence(
        &self,
        xs: &Tensor,
        h: &[Tensor],
        c: Option<&[Tensor]>,
        mut rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, Vec<Tensor>, Option<Vec<Tensor>>)> {
        if h.len() != self.layers.len() {
            candle_core::bail!("the state has {} layers, the recurrent layer {}", h.len(), self.layers.len())
        }
        let (mut hs, mut cs) = (Vec::with_capacity(h.len()), c.map(|c| Vec::with_capacity(c.len())));
        let mut inp = xs.clone();
        for (k, layer) in self.layers.iter().enumerate() {
            if k > 0 {
                inp = self.dropout.forward(&inp, rng.as_deref_mut())?;
            }
            let (out, h2, c2) = layer.sequence(&inp, &h[k], c.map(|c| &c[k]))?;
            inp = out;
            hs.push(h2);
            if let (Some(cs), Some(c2)) = (cs.as_mut(), c2) {
                cs.push(c2);
            }
        }
        Ok((inp, hs, cs))
    }
}

/// A multi-layer LSTM (PyTorch's `nn.LSTM(batch_first=True)`), with dropout on the outputs of
/// every layer but the last in training.
#[derive(Clone, Debug)]
pub struct Lstm {
    stack: Stack,
}

impl Lstm {
    /// `layers` layers of `hidden` units over inputs of `input` features; `dropout` between layers.
    pub fn new(input: usize, hidden: usize, layers: usize, dropout: f64, vb: VarBuilder) -> Result<Self> {
        Ok(Lstm { stack: Stack::new(Cell::Lstm, input, hidden, layers, dropout, &vb)? })
    }

    /// Zero `h` and `c` for `batch` sequences.
    pub fn zero_state(&self, batch: usize) -> Result<LstmState> {
        let z = self.stack.layers.iter().map(|l| zeros(batch, l)).collect::<Result<Vec<_>>>()?;
        Ok(LstmState { h: z.clone(), c: z })
    }

    /// One step (evaluation: no dropout): `x` `(batch, input)`; the output is
    /// [`LstmState::output`] of the returned state.
    pub fn step(&self, x: &Tensor, state: &LstmState) -> Result<LstmState> {
        self.step_train(x, state, None)
    }

    /// One step with inter-layer dropout drawn from `rng` when it is `Some` (training).
    pub fn step_train(&self, x: &Tensor, state: &LstmState, rng: Option<&mut RowRngs>) -> Result<LstmState> {
        let (h, c) = self.stack.step(x, &state.h, Some(&state.c), rng)?;
        Ok(LstmState { h, c: c.unwrap_or_default() })
    }

    /// Runs `(batch, time, input)` from `state`: the last layer's outputs `(batch, time, hidden)`
    /// and the last state. Dropout masks (when `rng` is `Some`) are drawn layer by layer.
    pub fn forward_seq(
        &self,
        xs: &Tensor,
        state: &LstmState,
        rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, LstmState)> {
        let (out, h, c) = self.stack.sequence(xs, &state.h, Some(&state.c), rng)?;
        Ok((out, LstmState { h, c: c.unwrap_or_default() }))
    }
}

/// A multi-layer GRU (PyTorch's `nn.GRU(batch_first=True)`), with dropout on the outputs of
/// every layer but the last in training.
#[derive(Clone, Debug)]
pub struct Gru {
    stack: Stack,
}

impl Gru {
    /// `layers` layers of `hidden` units over inputs of `input` features; `dropout` between layers.
    pub fn new(input: usize, hidden: usize, layers: usize, dropout: f64, vb: VarBuilder) -> Result<Self> {
        Ok(Gru { stack: Stack::new(Cell::Gru, input, hidden, layers, dropout, &vb)? })
    }

    /// Zero `h` for `batch` sequences.
    pub fn zero_state(&self, batch: usize) -> Result<GruState> {
        Ok(GruState { h: self.stack.layers.iter().map(|l| zeros(batch, l)).collect::<Result<_>>()? })
    }

    /// One step (evaluation: no dropout): `x` `(batch, input)`.
    pub fn step(&self, x: &Tensor, state: &GruState) -> Result<GruState> {
        self.step_train(x, state, None)
    }

    /// One step with inter-layer dropout drawn from `rng` when it is `Some` (training).
    pub fn step_train(&self, x: &Tensor, state: &GruState, rng: Option<&mut RowRngs>) -> Result<GruState> {
        Ok(GruState { h: self.stack.step(x, &state.h, None, rng)?.0 })
    }

    /// Runs `(batch, time, input)` from `state`: the last layer's outputs `(batch, time, hidden)`
    /// and the last state. Dropout masks (when `rng` is `Some`) are drawn layer by layer.
    pub fn forward_seq(&self, xs: &Tensor, state: &GruState, rng: Option<&mut RowRngs>) -> Result<(Tensor, GruState)> {
        let (out, h, _) = self.stack.sequence(xs, &state.h, None, rng)?;
        Ok((out, GruState { h }))
    }
}

/// The layers of a bidirectional stack: per layer the forward and the reverse direction.
#[derive(Clone, Debug)]
struct BiStack {
    layers: Vec<(Layer, Layer)>,
    dropout: Dropout,
}

impl BiStack {
    fn new(cell: Cell, input: usize, hidden: usize, layers: usize, dropout: f64, vb: &VarBuilder) -> Result<Self> {
        if layers == 0 {
            candle_core::bail!("a recurrent layer needs at least one layer")
        }
        let layers = (0..layers)
            .map(|k| {
                let i = if k == 0 { input } else { 2 * hidden };
                Ok((
                    Layer::new(cell, i, hidden, &format!("l{k}"), vb)?,
                    Layer::new(cell, i, hidden, &format!("l{k}_reverse"), vb)?,
                ))
            })
            .collect::<Result<_>>()?;
        Ok(BiStack { layers, dropout: Dropout::new(dropout) })
    }

    fn forward(&self, xs: &Tensor, mut rng: Option<&mut RowRngs>) -> Result<Tensor> {
        let batch = xs.dim(0)?;
        let mut inp = xs.clone();
        for (k, (fwd, bwd)) in self.layers.iter().enumerate() {
            if k > 0 {
                inp = self.dropout.forward(&inp, rng.as_deref_mut())?;
            }
            let z = zeros(batch, fwd)?;
            let c = (fwd.cell == Cell::Lstm).then_some(&z);
            let (out_f, _, _) = fwd.sequence(&inp, &z, c)?;
            let (out_b, _, _) = bwd.sequence(&reverse_time(&inp)?, &z, c)?;
            inp = Tensor::cat(&[out_f, reverse_time(&out_b)?], D::Minus1)?;
        }
        Ok(inp)
    }
}

/// A bidirectional multi-layer LSTM over a whole sequence (PyTorch's
/// `nn.LSTM(bidirectional=True, batch_first=True)` from zero states): `(batch, time, input)` ->
/// `(batch, time, 2 * hidden)`, the forward direction's outputs then the reverse direction's
/// (which ran over the reversed sequence) at each frame.
#[derive(Clone, Debug)]
pub struct BiLstm {
    stack: BiStack,
}

impl BiLstm {
    /// `layers` bidirectional layers of `hidden` units per direction; `dropout` between layers.
    pub fn new(input: usize, hidden: usize, layers: usize, dropout: f64, vb: VarBuilder) -> Result<Self> {
        Ok(BiLstm { stack: BiStack::new(Cell::Lstm, input, hidden, layers, dropout, &vb)? })
    }

    /// Runs the sequence; inter-layer dropout when `rng` is `Some` (training).
    pub fn forward(&self, xs: &Tensor, rng: Option<&mut RowRngs>) -> Result<Tensor> {
        self.stack.forward(xs, rng)
    }
}

/// A bidirectional multi-layer GRU over a whole sequence (PyTorch's
/// `nn.GRU(bidirectional=True, batch_first=True)` from zero states): `(batch, time, input)` ->
/// `(batch, time, 2 * hidden)`, forward then reverse direction at each frame.
#[derive(Clone, Debug)]
pub struct BiGru {
    stack: BiStack,
}

impl BiGru {
    /// `layers` bidirectional layers of `hidden` units per direction; `dropout` between layers.
    pub fn new(input: usize, hidden: usize, layers: usize, dropout: f64, vb: VarBuilder) -> Result<Self> {
        Ok(BiGru { stack: BiStack::new(Cell::Gru, input, hidden, layers, dropout, &vb)? })
    }

    /// Runs the sequence; inter-layer dropout when `rng` is `Some` (training).
    pub fn forward(&self, xs: &Tensor, rng: Option<&mut RowRngs>) -> Result<Tensor> {
        self.stack.forward(xs, rng)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::SeededVarMap;
    use crate::rng::SplitMix64;
    use candle_core::{DType, Device, Var};
    use candle_nn::VarMap;
    use std::collections::HashMap;

    const B: usize = 2;
    const T: usize = 4;
    const I: usize = 3;
    const H: usize = 5;

    fn input(dtype: DType) -> Tensor {
        let mut rng = SplitMix64::new(11);
        let v: Vec<f64> = (0..B * T * I).map(|_| rng.range(-1.5, 1.5)).collect();
        Tensor::from_vec(v, (B, T, I), &Device::Cpu).unwrap().to_dtype(dtype).unwrap()
    }

    fn weights(vm: &VarMap) -> HashMap<String, Tensor> {
        vm.data().lock().unwrap().iter().map(|(k, v)| (k.clone(), v.as_tensor().clone())).collect()
    }

    fn sig(x: &Tensor) -> Tensor {
        (x.neg().unwrap().exp().unwrap() + 1.0).unwrap().recip().unwrap()
    }

    /// `x W^T + b` for gate `g` of `n`-wide gate blocks, written gate by gate.
    fn gate(w: &HashMap<String, Tensor>, name: &str, g: usize, x: &Tensor, suffix: &str) -> Tensor {
        let (wn, bn) = (format!("weight_{name}_{suffix}"), format!("bias_{name}_{suffix}"));
        let wg = w[&wn].narrow(0, g * H, H).unwrap();
        let bg = w[&bn].narrow(0, g * H, H).unwrap();
        x.matmul(&wg.t().unwrap()).unwrap().broadcast_add(&bg).unwrap()
    }

    /// The hand-unrolled reference of one direction: frame by frame, gate by gate.
    fn reference_direction(w: &HashMap<String, Tensor>, xs: &[Tensor], suffix: &str, lstm: bool) -> Vec<Tensor> {
        let mut h = Tensor::zeros((B, H), xs[0].dtype(), &Device::Cpu).unwrap();
        let mut c = h.clone();
        let mut out = Vec::new();
        for x in xs {
            if lstm {
                let pre = |g| (gate(w, "ih", g, x, suffix) + gate(w, "hh", g, &h, suffix)).unwrap();
                let (i, f, g, o) = (sig(&pre(0)), sig(&pre(1)), pre(2).tanh().unwrap(), sig(&pre(3)));
                c = ((f * &c).unwrap() + (i * g).unwrap()).unwrap();
                h = (o * c.tanh().unwrap()).unwrap();
            } else {
                let r = sig(&(gate(w, "ih", 0, x, suffix) + gate(w, "hh", 0, &h, suffix)).unwrap());
                let z = sig(&(gate(w, "ih", 1, x, suffix) + gate(w, "hh", 1, &h, suffix)).unwrap());
                let n = (gate(w, "ih", 2, x, suffix) + (r * gate(w, "hh", 2, &h, suffix)).unwrap())
                    .unwrap()
                    .tanh()
                    .unwrap();
                let one_minus_z = (z.neg().unwrap() + 1.0).unwrap();
                h = ((one_minus_z * n).unwrap() + (z * &h).unwrap()).unwrap();
            }
            out.push(h.clone());
        }
        out
    }

    /// Forward pass, plus a forward pass over the reversed sequence whose outputs are put back
    /// in frame order, concatenated per frame.
    fn reference_bidirectional(w: &HashMap<String, Tensor>, xs: &Tensor, lstm: bool) -> Tensor {
        let frames: Vec<Tensor> = (0..T).map(|t| xs.narrow(1, t, 1).unwrap().squeeze(1).unwrap()).collect();
        let fwd = reference_direction(w, &frames, "l0", lstm);
        let reversed: Vec<Tensor> = frames.iter().rev().cloned().collect();
        let mut bwd = reference_direction(w, &reversed, "l0_reverse", lstm);
        bwd.reverse();
        let per_frame: Vec<Tensor> = fwd.iter().zip(&bwd).map(|(f, b)| Tensor::cat(&[f, b], 1).unwrap()).collect();
        Tensor::stack(&per_frame, 1).unwrap()
    }

    fn max_diff(a: &Tensor, b: &Tensor) -> f64 {
        (a - b)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap()
            .max(0)
            .unwrap()
            .to_dtype(DType::F64)
            .unwrap()
            .to_scalar()
            .unwrap()
    }

    #[test]
    fn bidirectional_layers_match_the_hand_unrolled_reference() -> Result<()> {
        for lstm in [false, true] {
            let vm = VarMap::new();
            let vb = SeededVarMap::builder(&vm, 5, DType::F32, &Device::Cpu);
            let xs = input(DType::F32);
            let out = if lstm {
                BiLstm::new(I, H, 1, 0.0, vb)?.forward(&xs, None)?
            } else {
                BiGru::new(I, H, 1, 0.0, vb)?.forward(&xs, None)?
            };
            assert_eq!(out.dims(), &[B, T, 2 * H]);
            let want = reference_bidirectional(&weights(&vm), &xs, lstm);
            let d = max_diff(&out, &want);
            assert!(d < 1e-6, "lstm {lstm}: max difference {d}");
        }
        Ok(())
    }

    /// Central differences `(L(p + e) - L(p - e)) / 2e` of `L = sum(out * probe)` for every
    /// parameter and input value, against backprop, in f64.
    #[test]
    fn bidirectional_gradients_match_finite_differences() -> Result<()> {
        for lstm in [false, true] {
            let vm = VarMap::new();
            let vb = SeededVarMap::builder(&vm, 9, DType::F64, &Device::Cpu);
            let x = Var::from_tensor(&input(DType::F64))?;
            let (gru, lstm_layer) = if lstm {
                (None, Some(BiLstm::new(I, H, 2, 0.0, vb)?))
            } else {
                (Some(BiGru::new(I, H, 2, 0.0, vb)?), None)
            };
            let mut rng = SplitMix64::new(2);
            let probe: Vec<f64> = (0..B * T * 2 * H).map(|_| rng.range(-1.0, 1.0)).collect();
            let probe = Tensor::from_vec(probe, (B, T, 2 * H), &Device::Cpu)?;
            let loss = |x: &Tensor| -> Result<Tensor> {
                let out = match (&gru, &lstm_layer) {
                    (Some(g), _) => g.forward(x, None)?,
                    (_, Some(l)) => l.forward(x, None)?,
                    _ => unreachable!(),
                };
                (out * &probe)?.sum_all()
            };
            let grads = loss(x.as_tensor())?.backward()?;
            let mut vars: Vec<(String, Var)> =
                vm.data().lock().unwrap().iter().map(|(k, v)| (k.clone(), v.clone())).collect();
            vars.sort_by(|a, b| a.0.cmp(&b.0));
            vars.push(("input".into(), x.clone()));
            let eps = 1e-6;
            let mut checked = 0;
            for (name, var) in &vars {
                let analytic = grads
                    .get(var)
                    .unwrap_or_else(|| panic!("no gradient for {name}"))
                    .flatten_all()?
                    .to_vec1::<f64>()?;
                let base = var.as_tensor().flatten_all()?.to_vec1::<f64>()?;
                for j in (0..base.len()).step_by(7) {
                    let at = |delta: f64| -> Result<f64> {
                        let mut v = base.clone();
                        v[j] += delta;
                        var.set(&Tensor::from_vec(v, var.shape(), &Device::Cpu)?)?;
                        loss(x.as_tensor())?.to_scalar::<f64>()
                    };
                    let numeric = (at(eps)? - at(-eps)?) / (2.0 * eps);
                    var.set(&Tensor::from_vec(base.clone(), var.shape(), &Device::Cpu)?)?;
                    let err = (numeric - analytic[j]).abs();
                    assert!(
                        err < 1e-6 * (1.0 + numeric.abs()),
                        "lstm {lstm}, {name}[{j}]: backprop {}, finite differences {numeric}",
                        analytic[j]
                    );
                    checked += 1;
                }
            }
            assert!(checked > 50, "checked {checked} values");
        }
        Ok(())
    }

    #[test]
    fn steps_match_the_sequence_and_dropout_only_trains() -> Result<()> {
        let vm = VarMap::new();
        let vb = SeededVarMap::builder(&vm, 4, DType::F32, &Device::Cpu);
        let lstm = Lstm::new(I, H, 2, 0.5, vb.pp("lstm"))?;
        let gru = Gru::new(I, H, 3, 0.5, vb.pp("gru"))?;
        assert!(vm.data().lock().unwrap().contains_key("lstm.weight_hh_l1"));
        assert!(vm.data().lock().unwrap().contains_key("gru.bias_ih_l2"));
        let xs = input(DType::F32);
        let (seq, last) = lstm.forward_seq(&xs, &lstm.zero_state(B)?, None)?;
        let (gseq, glast) = gru.forward_seq(&xs, &gru.zero_state(B)?, None)?;
        assert_eq!(seq.dims(), &[B, T, H]);
        let (mut s, mut g) = (lstm.zero_state(B)?, gru.zero_state(B)?);
        for t in 0..T {
            let x = xs.narrow(1, t, 1)?.squeeze(1)?;
            s = lstm.step(&x, &s)?;
            g = gru.step(&x, &g)?;
            assert!(max_diff(s.output(), &seq.narrow(1, t, 1)?.squeeze(1)?) < 1e-6);
            assert!(max_diff(g.output(), &gseq.narrow(1, t, 1)?.squeeze(1)?) < 1e-6);
        }
        assert!(max_diff(&s.c[1], &last.c[1]) < 1e-6 && max_diff(&g.h[2], &glast.h[2]) < 1e-6);
        let (a, _) = lstm.forward_seq(&xs, &lstm.zero_state(B)?, Some(&mut crate::layers::RowRngs::new(1, 0..B)))?;
        let (b, _) = lstm.forward_seq(&xs, &lstm.zero_state(B)?, Some(&mut crate::layers::RowRngs::new(1, 0..B)))?;
        assert_eq!(a.flatten_all()?.to_vec1::<f32>()?, b.flatten_all()?.to_vec1::<f32>()?);
        assert!(max_diff(&a, &seq) > 1e-4, "dropout between layers changes the output in training");
        let err = lstm.step(&xs.narrow(1, 0, 1)?.squeeze(1)?, &LstmState { h: vec![], c: vec![] }).unwrap_err();
        assert!(err.to_string().contains("the state has 0 layers"), "{err}");
        Ok(())
    }
}
