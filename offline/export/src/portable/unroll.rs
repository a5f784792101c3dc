//! The unrolling of ONNX `LSTM`, `GRU` and `RNN` nodes into their cell equations (see the
//! parent module for what is lowered and what is refused).

use super::node_name;
use crate::graph::{GraphBuilder, Value};
use crate::ops::attr_int;
use crate::pb;
use std::collections::{HashMap, HashSet};

/// The recurrent ops the pass lowers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Cell {
    Lstm,
    Gru,
    Rnn,
}

impl Cell {
    pub(super) fn of(n: &pb::NodeProto) -> Option<Cell> {
        if !n.domain.is_empty() && n.domain != "ai.onnx" {
            return None;
        }
        match n.op_type.as_str() {
            "LSTM" => Some(Cell::Lstm),
            "GRU" => Some(Cell::Gru),
            "RNN" => Some(Cell::Rnn),
            _ => None,
        }
    }

    /// Whether an `activations` attribute spells out the defaults (one list per direction).
    fn activations_are_default(self, given: &[Vec<u8>]) -> bool {
        let one: &[&[u8]] = match self {
            Cell::Lstm => &[b"Sigmoid", b"Tanh", b"Tanh"],
            Cell::Gru => &[b"Sigmoid", b"Tanh"],
            Cell::Rnn => &[b"Tanh"],
        };
        (given.len() == one.len() || given.len() == 2 * one.len())
            && given.iter().zip(one.iter().cycle()).all(|(g, d)| g.as_slice() == *d)
    }

    fn gates(self) -> usize {
        match self {
            Cell::Lstm => 4,
            Cell::Gru => 3,
            Cell::Rnn => 1,
        }
    }
}

/// One direction's weights: `W` `[G H, I]`, `R` `[G H, H]`, biases `Wb`, `Rb` `[G H]`.
struct DirectionWeights {
    w: Vec<f32>,
    r: Vec<f32>,
    wb: Vec<f32>,
    rb: Vec<f32>,
}

/// A recurrent node read for lowering.
pub(super) struct RecurrentNode {
    name: String,
    cell: Cell,
    hidden: usize,
    input: usize,
    steps: usize,
    /// Per direction: whether it runs backwards in time.
    reverse: Vec<bool>,
    weights: Vec<DirectionWeights>,
    linear_before_reset: bool,
    x: String,
    initial_h: Option<String>,
    initial_c: Option<String>,
    /// `Y`, `Y_h`, `Y_c` output names (empty: not produced).
    outputs: [String; 3],
}

fn f32_data(t: &pb::TensorProto) -> Result<Vec<f32>, String> {
    if t.data_type != pb::tensor_proto::DataType::Float as i32 {
        return Err(format!("initializer `{}` is not float32", t.name));
    }
    if !t.raw_data.is_empty() {
        Ok(t.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    } else {
        Ok(t.float_data.clone())
    }
}

impl RecurrentNode {
    // One function: the checks of one ONNX recurrent node's attributes and inputs, each refusal
    // naming what is unsupported; they read the same node, one after the other.
    pub(super) fn read(
        node: &pb::NodeProto,
        cell: Cell,
        inits: &HashMap<&str, &pb::TensorProto>,
        steps: usize,
    ) -> Result<Self, String> {
        let name = node_name(node).to_string();
        let op = node.op_type.as_str();
        let at = |i: usize| node.input.get(i).filter(|s| !s.is_empty()).cloned();
        let mut hidden = None;
        let mut direction = "forward".to_string();
        let mut linear_before_reset = false;
        for a in &node.attribute {
            match a.name.as_str() {
                "hidden_size" => hidden = Some(a.i as usize),
                "direction" => direction = String::from_utf8_lossy(&a.s).into_owned(),
                "layout" if a.i != 0 => {
                    return Err(format!("{op} `{name}` has layout {}; only layout 0 is lowered", a.i));
                }
                "linear_before_reset" => linear_before_reset = a.i != 0,
                "input_forget" if a.i != 0 => {
                    return Err(format!("{op} `{name}` couples input and forget gates; not lowered"));
                }
                // Exporters often spell the defaults out (PyTorch writes Sigmoid, Tanh, Tanh).
                "activations" if cell.activations_are_default(&a.strings) => {}
                "activations" | "activation_alpha" | "activation_beta" | "clip" => {
                    return Err(format!(
                        "{op} `{name}` sets `{}`; only default activations without clip are lowered",
                        a.name
                    ));
                }
                _ => {}
            }
        }
        let hidden = hidden.ok_or_else(|| format!("{op} `{name}` has no hidden_size"))?;
        if at(4).is_some() {
            return Err(format!(
                "{op} `{name}` has sequence_lens; every sequence must run the full length to be unrolled"
            ));
        }
        if cell == Cell::Lstm && at(7).is_some() {
            return Err(format!("LSTM `{name}` has peepholes (P); not lowered"));
        }
        let reverse = match direction.as_str() {
            "forward" => vec![false],
            "reverse" => vec![true],
            "bidirectional" => vec![false, true],
            other => return Err(format!("{op} `{name}` has direction `{other}`")),
        };
        let dirs = reverse.len();
        let g = cell.gates();
        let weight = |i: usize, label: &str| -> Result<(Vec<usize>, Vec<f32>), String> {
            let v = at(i).ok_or_else(|| format!("{op} `{name}` has no {label}"))?;
            let t = inits.get(v.as_str()).ok_or_else(|| {
                format!("{op} `{name}`: {label} (`{v}`) is not an initializer; only constant weights are lowered")
            })?;
            let dims: Vec<usize> = t.dims.iter().map(|&d| d.max(0) as usize).collect();
            let data = f32_data(t)?;
            if data.len() != dims.iter().product::<usize>() {
                return Err(format!("{op} `{name}`: {label} has shape {dims:?} but {} values", data.len()));
            }
            Ok((dims, data))
        };
        let (wd, w) = weight(1, "W")?;
        let (rd, r) = weight(2, "R")?;
        let input = wd.get(2).copied().unwrap_or(0);
        if wd != [dirs, g * hidden, input] || rd != [dirs, g * hidden, hidden] {
            return Err(format!(
                "{op} `{name}`: W {wd:?} and R {rd:?} do not match {dirs} direction(s), {g} gate(s), hidden size {hidden}"
            ));
        }
        let b = match at(3) {
            Some(_) => {
                let (bd, b) = weight(3, "B")?;
                if bd != [dirs, 2 * g * hidden] {
                    return Err(format!("{op} `{name}`: B {bd:?} is not [{dirs}, {}]", 2 * g * hidden));
                }
                b
            }
            None => vec![0.0; dirs * 2 * g * hidden],
        };
        let gh = g * hidden;
        let weights = (0..dirs)
            .map(|d| DirectionWeights {
                w: w[d * gh * input..(d + 1) * gh * input].to_vec(),
                r: r[d * gh * hidden..(d + 1) * gh * hidden].to_vec(),
                wb: b[d * 2 * gh..d * 2 * gh + gh].to_vec(),
                rb: b[d * 2 * gh + gh..(d + 1) * 2 * gh].to_vec(),
            })
            .collect();
        let out = |i: usize| node.output.get(i).cloned().unwrap_or_default();
        Ok(RecurrentNode {
            name,
            cell,
            hidden,
            input,
            steps,
            reverse,
            weights,
            linear_before_reset,
            x: node.input[0].clone(),
            initial_h: at(5),
            initial_c: if cell == Cell::Lstm { at(6) } else { None },
            outputs: [out(0), out(1), if cell == Cell::Lstm { out(2) } else { String::new() }],
        })
    }

    /// Writes the unrolled cell; the outputs keep the node's output names (only those read).
    // One function: the cell equations of one unrolled step, written in the order of the
    // LSTM/GRU definitions (ONNX operator docs) so that they can be read side by side.
    pub(super) fn emit(&self, g: &mut GraphBuilder, used: &HashSet<String>) {
        let (n, h) = (&self.name, self.hidden);
        let x = Value(self.x.clone());
        let frame: Vec<Value> =
            (0..self.steps).map(|t| g.initializer_i64(&format!("{n}.frame{t}"), &[], &[t as i64])).collect();
        let mut ys: Vec<Vec<Value>> = Vec::new();
        let mut last_h = Vec::new();
        let mut last_c = Vec::new();
        for (d, wd) in self.weights.iter().enumerate() {
            let p = format!("{n}.d{d}");
            let gh = self.cell.gates() * h;
            // Input projection of every frame at once: X [T, B, I] @ W^T [I, G H] + bias.
            let w_t = g.initializer_f32(&format!("{p}.W_t"), &[self.input, gh], &transpose(&wd.w, gh, self.input));
            let bias: Vec<f32> = match self.cell {
                // LSTM and RNN add both biases outside any gate product: fold Rb in.
                Cell::Lstm | Cell::Rnn => wd.wb.iter().zip(&wd.rb).map(|(a, b)| a + b).collect(),
                Cell::Gru => wd.wb.clone(),
            };
            let b = g.initializer_f32(&format!("{p}.x_bias"), &[gh], &bias);
            let xw = g.matmul(&format!("{p}.x_matmul"), &x, &w_t);
            let xw = g.add(&format!("{p}.x_gates"), &xw, &b);
            let r = g.initializer_f32(&format!("{p}.R"), &[gh, h], &wd.r);
            let direction = (self.initial_h.is_some() || self.initial_c.is_some())
                .then(|| g.initializer_i64(&format!("{p}.direction"), &[], &[d as i64]));
            let mut initial = |v: &Option<String>, label: &str| {
                let (v, i) = (v.as_ref()?, direction.as_ref()?);
                Some(g.custom_op("Gather", &format!("{p}.{label}"), &[&Value(v.clone()), i], vec![attr_int("axis", 0)]))
            };
            let mut state_h = initial(&self.initial_h, "h0");
            let mut state_c = initial(&self.initial_c, "c0");
            let gru = GruWeights::new(g, &p, wd, h, self.linear_before_reset, self.cell == Cell::Gru);
            let mut y = vec![None; self.steps];
            let order: Vec<usize> =
                if self.reverse[d] { (0..self.steps).rev().collect() } else { (0..self.steps).collect() };
            for t in order {
                let s = format!("{p}.t{t}");
                let xt = g.custom_op("Gather", &format!("{s}.x"), &[&xw, &frame[t]], vec![attr_int("axis", 0)]);
                let (h_new, c_new) = match self.cell {
                    Cell::Lstm => {
                        let z = gates_plus_hidden(g, &s, xt, state_h.as_ref(), &r);
                        // ONNX gate order i, o, f, c.
                        let parts = g.split(&format!("{s}.split"), &z, &[h; 4], 1);
                        let i = g.sigmoid(&format!("{s}.i"), &parts[0]);
                        let o = g.sigmoid(&format!("{s}.o"), &parts[1]);
                        let f = g.sigmoid(&format!("{s}.f"), &parts[2]);
                        let c_in = g.tanh(&format!("{s}.c_in"), &parts[3]);
                        let ic = g.mul(&format!("{s}.i_c"), &i, &c_in);
                        let c = match &state_c {
                            Some(cp) => {
                                let fc = g.mul(&format!("{s}.f_c"), &f, cp);
                                g.add(&format!("{s}.c"), &fc, &ic)
                            }
                            None => ic,
                        };
                        let tc = g.tanh(&format!("{s}.tanh_c"), &c);
                        (g.mul(&format!("{s}.h"), &o, &tc), Some(c))
                    }
                    Cell::Rnn => {
                        let z = gates_plus_hidden(g, &s, xt, state_h.as_ref(), &r);
                        (g.tanh(&format!("{s}.h"), &z), None)
                    }
                    Cell::Gru => (gru.step(g, &s, &xt, state_h.as_ref(), &r, h), None),
                };
                y[t] = Some(h_new.clone());
                state_h = Some(h_new);
                if c_new.is_some() {
                    state_c = c_new;
                }
            }
            ys.push(y.into_iter().map(|v| v.expect("every frame ran")).collect());
            last_h.push(state_h.expect("at least one frame"));
            last_c.push(state_c);
        }
        let [y_name, yh_name, yc_name] = &self.outputs;
        if !y_name.is_empty() && used.contains(y_name) {
            // Y [T, D, B, H]: each h [B, H] -> [1, 1, B, H], directions on axis 1, frames on axis 0.
            let frames: Vec<Value> = (0..self.steps)
                .map(|t| {
                    let per_dir: Vec<Value> = ys
                        .iter()
                        .enumerate()
                        .map(|(d, y)| g.unsqueeze(&format!("{n}.y.t{t}.d{d}"), &y[t], &[0, 1]))
                        .collect();
                    concat_or_single(g, &format!("{n}.y.t{t}"), &per_dir, 1, None)
                })
                .collect();
            concat_or_single(g, &format!("{n}.y"), &frames, 0, Some(y_name.as_str()));
        }
        for (last, out, label) in
            [(last_h.iter().map(|v| Some(v.clone())).collect::<Vec<_>>(), yh_name, "y_h"), (last_c, yc_name, "y_c")]
        {
            if out.is_empty() || !used.contains(out) {
                continue;
            }
            let parts: Vec<Value> = last
                .iter()
                .enumerate()
                .map(|(d, v)| {
                    let v = v.clone().expect("LSTM cell state");
                    g.unsqueeze(&format!("{n}.{label}.d{d}"), &v, &[0])
                })
                .collect();
            concat_or_single(g, &format!("{n}.{label}"), &parts, 0, Some(out.as_str()));
        }
    }
}

/// The gate pre-activations of a frame: `xt` (input projection with the biases) plus `h R^T`,
/// or `xt` alone at a zero state.
fn gates_plus_hidden(g: &mut GraphBuilder, s: &str, xt: Value, h: Option<&Value>, r: &Value) -> Value {
    match h {
        Some(hp) => {
            let hr = g.gemm(&format!("{s}.h_gates"), hp, r, None, true);
            g.add(&format!("{s}.gates"), &xt, &hr)
        }
        None => xt,
    }
}

/// `Concat(values, axis)`, or the single value; named `out` when given (through `Identity` for
/// a single value).
fn concat_or_single(g: &mut GraphBuilder, name: &str, values: &[Value], axis: i64, out: Option<&str>) -> Value {
    match (values, out) {
        ([one], None) => one.clone(),
        ([one], Some(out)) => g.node_multi("Identity", name, &[one], &[out.to_string()], vec![]).remove(0),
        (many, None) => g.concat(name, &many.iter().collect::<Vec<_>>(), axis),
        (many, Some(out)) => g
            .node_multi(
                "Concat",
                name,
                &many.iter().collect::<Vec<_>>(),
                &[out.to_string()],
                vec![attr_int("axis", axis)],
            )
            .remove(0),
    }
}

/// GRU weights beside `R` (gate order z, r, h): the hidden biases per gate, and for
/// `linear_before_reset = 0` the split of `R` into its z/r rows and its h rows.
struct GruWeights {
    linear_before_reset: bool,
    /// `Rb` of gates z, r, h, `[H]` each.
    rb: Vec<Value>,
    /// Full `Rb` `[3H]`.
    rb_all: Option<Value>,
    /// `R` rows of z and r `[2H, H]` with their bias `[2H]`, and of h `[H, H]`.
    r_zr: Option<(Value, Value)>,
    r_h: Option<Value>,
}

impl GruWeights {
    fn new(g: &mut GraphBuilder, p: &str, wd: &DirectionWeights, h: usize, lbr: bool, is_gru: bool) -> Self {
        if !is_gru {
            return GruWeights { linear_before_reset: lbr, rb: vec![], rb_all: None, r_zr: None, r_h: None };
        }
        let rb: Vec<Value> = ["z", "r", "h"]
            .iter()
            .enumerate()
            .map(|(k, gate)| g.initializer_f32(&format!("{p}.Rb_{gate}"), &[h], &wd.rb[k * h..(k + 1) * h]))
            .collect();
        if lbr {
            let rb_all = g.initializer_f32(&format!("{p}.Rb"), &[3 * h], &wd.rb);
            GruWeights { linear_before_reset: lbr, rb, rb_all: Some(rb_all), r_zr: None, r_h: None }
        } else {
            let r_zr = g.initializer_f32(&format!("{p}.R_zr"), &[2 * h, h], &wd.r[..2 * h * h]);
            let rb_zr = g.initializer_f32(&format!("{p}.Rb_zr"), &[2 * h], &wd.rb[..2 * h]);
            let r_h = g.initializer_f32(&format!("{p}.R_h"), &[h, h], &wd.r[2 * h * h..]);
            GruWeights { linear_before_reset: lbr, rb, rb_all: None, r_zr: Some((r_zr, rb_zr)), r_h: Some(r_h) }
        }
    }

    /// One GRU step (ONNX GRU equations, `f = sigmoid`, `g = tanh`): the next `h`. `xt` holds
    /// `x W^T + Wb` of the frame, `[B, 3H]`.
    fn step(&self, g: &mut GraphBuilder, s: &str, xt: &Value, hp: Option<&Value>, r: &Value, h: usize) -> Value {
        let xs = g.split(&format!("{s}.x_split"), xt, &[h; 3], 1);
        // Hidden terms of z and r (and of h with linear_before_reset): from h_prev, or the bias alone at h = 0.
        let (hz, hr, hh_lbr) = match (hp, self.linear_before_reset) {
            (Some(hp), true) => {
                let all = g.gemm(&format!("{s}.h_gates"), hp, r, self.rb_all.as_ref(), true);
                let parts = g.split(&format!("{s}.h_split"), &all, &[h; 3], 1);
                (parts[0].clone(), parts[1].clone(), Some(parts[2].clone()))
            }
            (Some(hp), false) => {
                let (r_zr, rb_zr) = self.r_zr.as_ref().expect("R_zr");
                let zr = g.gemm(&format!("{s}.h_gates"), hp, r_zr, Some(rb_zr), true);
                let parts = g.split(&format!("{s}.h_split"), &zr, &[h; 2], 1);
                (parts[0].clone(), parts[1].clone(), None)
            }
            (None, _) => (self.rb[0].clone(), self.rb[1].clone(), Some(self.rb[2].clone())),
        };
        let z = g.add(&format!("{s}.z_sum"), &xs[0], &hz);
        let z = g.sigmoid(&format!("{s}.z"), &z);
        let rg = g.add(&format!("{s}.r_sum"), &xs[1], &hr);
        let rg = g.sigmoid(&format!("{s}.r"), &rg);
        let hh = match (hp, self.linear_before_reset) {
            // linear_before_reset = 1: r * (h Rh^T + Rbh); at h = 0 it is r * Rbh.
            (_, true) => g.mul(&format!("{s}.r_hh"), &rg, &hh_lbr.expect("hidden h term")),
            // linear_before_reset = 0: (r * h) Rh^T + Rbh; at h = 0 it is Rbh.
            (Some(hp), false) => {
                let rh = g.mul(&format!("{s}.r_h"), &rg, hp);
                g.gemm(&format!("{s}.hh"), &rh, self.r_h.as_ref().expect("R_h"), Some(&self.rb[2]), true)
            }
            (None, false) => self.rb[2].clone(),
        };
        let n = g.add(&format!("{s}.n_sum"), &xs[2], &hh);
        let n = g.tanh(&format!("{s}.n"), &n);
        // h' = (1 - z) n + z h = n + z (h - n); at h = 0: n - z n.
        match hp {
            Some(hp) => {
                let d = g.sub(&format!("{s}.h_minus_n"), hp, &n);
                let zd = g.mul(&format!("{s}.z_d"), &z, &d);
                g.add(&format!("{s}.h"), &n, &zd)
            }
            None => {
                let zn = g.mul(&format!("{s}.z_n"), &z, &n);
                g.sub(&format!("{s}.h"), &n, &zn)
            }
        }
    }
}

/// `[rows, cols]` row-major -> `[cols, rows]`.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0; m.len()];
    for i in 0..rows {
        for j in 0..cols {
            out[j * rows + i] = m[i * cols + j];
        }
    }
    out
}
