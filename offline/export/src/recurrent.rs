//! Recurrent ops: ONNX `LSTM` and `GRU` nodes (layout 0) and the gate reordering from
//! candle/PyTorch to ONNX order.

use crate::error::ExportError;
use crate::graph::{GraphBuilder, Value};
use crate::ops::{attr_int, attr_string};

/// Direction of an ONNX recurrent op. `reverse` is not offered: tract 0.23 ignores the
/// `direction` attribute and takes the number of directions from `W` (DEPENDENCY-FACTS),
/// so a single reverse RNN would silently run forward there.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RnnDirection {
    /// One forward direction; weights have a leading dimension of 1.
    Forward,
    /// Forward and reverse; weights have a leading dimension of 2.
    Bidirectional,
}

impl RnnDirection {
    fn attr(self) -> &'static str {
        match self {
            RnnDirection::Forward => "forward",
            RnnDirection::Bidirectional => "bidirectional",
        }
    }

    /// Leading dimension of `W`, `R`, `B` and of the states.
    pub fn num_directions(self) -> usize {
        match self {
            RnnDirection::Forward => 1,
            RnnDirection::Bidirectional => 2,
        }
    }
}

/// Inputs of an ONNX `LSTM` or `GRU` node (layout 0: `X` is `[seq, batch, input]`).
#[derive(Clone, Debug)]
pub struct RnnInputs<'a> {
    /// `X`, `[seq, batch, input]`.
    pub x: &'a Value,
    /// `W`, `[dirs, gates * hidden, input]`, ONNX gate order (LSTM i,o,f,c; GRU z,r,h).
    pub w: &'a Value,
    /// `R`, `[dirs, gates * hidden, hidden]`.
    pub r: &'a Value,
    /// `B`, `[dirs, 2 * gates * hidden]` (`Wb` then `Rb`), or none for zero biases.
    pub b: Option<&'a Value>,
    /// `initial_h`, `[dirs, batch, hidden]`, or none for zeros.
    pub initial_h: Option<&'a Value>,
    /// Hidden size.
    pub hidden_size: usize,
    /// Direction.
    pub direction: RnnDirection,
}

/// Outputs of an ONNX `LSTM` or `GRU` node.
#[derive(Clone, Debug)]
pub struct RnnOutputs {
    /// `Y`, `[seq, dirs, batch, hidden]`.
    pub y: Value,
    /// `Y_h`, `[dirs, batch, hidden]`.
    pub y_h: Value,
    /// `Y_c`, `[dirs, batch, hidden]` (LSTM only; `None` for GRU).
    pub y_c: Option<Value>,
}

impl GraphBuilder {
    fn check_rnn(&mut self, name: &str, op: &str, gates: usize, rnn: &RnnInputs) {
        let dirs = rnn.direction.num_directions();
        let h = rnn.hidden_size;
        let checks: [(&str, Option<&Value>, usize, usize); 3] =
            [("W", Some(rnn.w), gates * h, 0), ("R", Some(rnn.r), gates * h, h), ("B", rnn.b, 2 * gates * h, 0)];
        for (label, v, rows, cols) in checks {
            let Some(shape) = v.and_then(|v| self.init_shapes.get(&v.0)).cloned() else { continue };
            let ok = shape.first() == Some(&dirs)
                && shape.get(1) == Some(&rows)
                && (cols == 0 || shape.get(2) == Some(&cols))
                && shape.len() == if label == "B" { 2 } else { 3 };
            if !ok {
                let want = match label {
                    "W" => format!("[{dirs}, {rows}, input]"),
                    "R" => format!("[{dirs}, {rows}, {cols}]"),
                    _ => format!("[{dirs}, {rows}]"),
                };
                self.fail(ExportError::InvalidOp {
                    node: name.to_string(),
                    message: format!(
                        "{op} {label} has shape {shape:?}, expected {want} for hidden size {h} and direction {} (tract takes the number of directions from W's first dimension)",
                        rnn.direction.attr()
                    ),
                });
            }
        }
    }

    /// An ONNX `LSTM` node (layout 0, gate order i,o,f,c; see [`reorder_gates`] to convert from
    /// candle/PyTorch's i,f,g,o). Outputs are `<name>.y`, `<name>.y_h`, `<name>.y_c`.
    pub fn lstm(&mut self, name: &str, rnn: &RnnInputs, initial_c: Option<&Value>) -> RnnOutputs {
        self.check_rnn(name, "LSTM", 4, rnn);
        let empty = Value(String::new());
        let inputs = [
            rnn.x,
            rnn.w,
            rnn.r,
            rnn.b.unwrap_or(&empty),
            &empty,
            rnn.initial_h.unwrap_or(&empty),
            initial_c.unwrap_or(&empty),
        ];
        let n = trailing_used(&inputs);
        let outs = [format!("{name}.y"), format!("{name}.y_h"), format!("{name}.y_c")];
        let attrs = vec![
            attr_int("hidden_size", rnn.hidden_size as i64),
            attr_string("direction", rnn.direction.attr()),
            attr_int("layout", 0),
        ];
        let mut v = self.node_multi("LSTM", name, &inputs[..n], &outs, attrs).into_iter();
        RnnOutputs { y: v.next().expect("y"), y_h: v.next().expect("y_h"), y_c: v.next() }
    }

    /// An ONNX `GRU` node (layout 0, gate order z,r,h). `linear_before_reset = true` matches
    /// candle's and PyTorch's GRU. Outputs are `<name>.y` and `<name>.y_h`.
    pub fn gru(&mut self, name: &str, rnn: &RnnInputs, linear_before_reset: bool) -> RnnOutputs {
        self.check_rnn(name, "GRU", 3, rnn);
        let empty = Value(String::new());
        let inputs = [rnn.x, rnn.w, rnn.r, rnn.b.unwrap_or(&empty), &empty, rnn.initial_h.unwrap_or(&empty)];
        let n = trailing_used(&inputs);
        let outs = [format!("{name}.y"), format!("{name}.y_h")];
        let attrs = vec![
            attr_int("hidden_size", rnn.hidden_size as i64),
            attr_string("direction", rnn.direction.attr()),
            attr_int("layout", 0),
            attr_int("linear_before_reset", linear_before_reset as i64),
        ];
        let mut v = self.node_multi("GRU", name, &inputs[..n], &outs, attrs).into_iter();
        RnnOutputs { y: v.next().expect("y"), y_h: v.next().expect("y_h"), y_c: None }
    }
}

/// Number of leading entries to keep so that trailing omitted optional inputs are dropped.
fn trailing_used(inputs: &[&Value]) -> usize {
    inputs.iter().rposition(|v| !v.0.is_empty()).map_or(0, |i| i + 1)
}

/// Reorders the gate blocks of a stacked recurrent weight or bias.
///
/// `data` is `[gates * hidden, cols]` row-major (use `cols = 1` for a bias); block `k` of the
/// result is block `order[k]` of the input. Conversions from candle/PyTorch to ONNX:
/// LSTM i,f,g,o -> i,o,f,c is `order = [0, 3, 1, 2]`; GRU r,z,n -> z,r,h is `order = [1, 0, 2]`
/// (DEPENDENCY-FACTS, candle 0.11.1).
pub fn reorder_gates(data: &[f32], hidden: usize, cols: usize, order: &[usize]) -> Vec<f32> {
    let block = hidden * cols;
    let mut out = Vec::with_capacity(data.len());
    for &k in order {
        out.extend_from_slice(&data[k * block..(k + 1) * block]);
    }
    out
}

/// Gate order conversion of an LSTM from candle/PyTorch (i,f,g,o) to ONNX (i,o,f,c).
pub const LSTM_TORCH_TO_ONNX: [usize; 4] = [0, 3, 1, 2];
/// Gate order conversion of a GRU from candle/PyTorch (r,z,n) to ONNX (z,r,h).
pub const GRU_TORCH_TO_ONNX: [usize; 3] = [1, 0, 2];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Dim;

    /// A graph with input `x` `(1, batch, 2)` and zero single-direction weights `w`
    /// `(1, gates * 3, 2)` and `r` `(1, gates * 3, 3)`: hidden size 3.
    fn one_step_graph(name: &str, gates: usize) -> (GraphBuilder, Value, Value, Value) {
        let mut g = GraphBuilder::new(name);
        let x = g.input("x", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(2)]);
        let w = g.initializer_f32("w", &[1, gates * 3, 2], &vec![0.0; gates * 6]);
        let r = g.initializer_f32("r", &[1, gates * 3, 3], &vec![0.0; gates * 9]);
        (g, x, w, r)
    }

    /// The inputs of [`one_step_graph`]'s recurrent op without biases.
    fn one_step_inputs<'a>(
        (x, w, r): (&'a Value, &'a Value, &'a Value),
        initial_h: Option<&'a Value>,
        direction: RnnDirection,
    ) -> RnnInputs<'a> {
        RnnInputs { x, w, r, b: None, initial_h, hidden_size: 3, direction }
    }

    #[test]
    fn rnn_weight_shapes_are_checked_against_direction() {
        let (mut g, x, w, r) = one_step_graph("rnn", 4);
        let rnn = one_step_inputs((&x, &w, &r), None, RnnDirection::Bidirectional);
        let o = g.lstm("lstm", &rnn, None);
        g.output("h", &o.y_h, &[Dim::Fixed(2), Dim::batch(), Dim::Fixed(3)]);
        let err = g.finish().unwrap_err().to_string();
        assert!(err.contains("LSTM W") && err.contains("bidirectional"), "{err}");
    }

    #[test]
    fn omitted_optional_rnn_inputs_are_trimmed_or_blank() {
        let (mut g, x, w, r) = one_step_graph("gru", 3);
        let h0 = g.input("h0", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(3)]);
        let rnn = one_step_inputs((&x, &w, &r), Some(&h0), RnnDirection::Forward);
        let o = g.gru("gru", &rnn, true);
        g.output("h", &o.y_h, &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(3)]);
        let m = g.finish().unwrap();
        let node = &m.proto().graph.as_ref().unwrap().node[0];
        assert_eq!(node.input, vec!["x", "w", "r", "", "", "h0"]);
    }

    #[test]
    fn gate_reordering() {
        // 4 gates of hidden 1, one column: i f g o -> i o f g
        let v = reorder_gates(&[0., 1., 2., 3.], 1, 1, &LSTM_TORCH_TO_ONNX);
        assert_eq!(v, vec![0., 3., 1., 2.]);
        let v = reorder_gates(&[0., 0., 1., 1., 2., 2.], 1, 2, &GRU_TORCH_TO_ONNX);
        assert_eq!(v, vec![1., 1., 0., 0., 2., 2.]);
    }
}
