//! What every model's exporter (`export.rs`) shares: the trained weights read out of a candle
//! `VarMap` by variable path, checked finite, and written as ONNX initializers of the same
//! name, so a graph viewer shows `frame_encoder.linear0.weight`.

use candle_nn::VarMap;
use std::collections::HashMap;
use zoo_export::{
    ExportError, GRU_TORCH_TO_ONNX, GraphBuilder, LSTM_TORCH_TO_ONNX, RnnDirection, RnnInputs, Value, reorder_gates,
};

/// Weights by candle variable path: shape and row-major f32 values.
#[derive(Clone, Debug, Default)]
pub struct ExportWeights(HashMap<String, (Vec<usize>, Vec<f32>)>);

impl ExportWeights {
    /// Reads every variable of `varmap`; refuses a weight holding NaN or infinity (naming it).
    pub fn from_varmap(varmap: &VarMap) -> Result<Self, ExportError> {
        let data = varmap.data().lock().map_err(|_| ExportError::model("the VarMap lock is poisoned"))?;
        Self::from_tensors(data.iter().map(|(name, var)| (name, var.as_tensor())))
    }

    /// Reads named tensors (e.g. a safetensors file's); refuses non-finite values like
    /// [`ExportWeights::from_varmap`].
    pub fn from_tensors<'a>(
        tensors: impl IntoIterator<Item = (&'a String, &'a candle_core::Tensor)>,
    ) -> Result<Self, ExportError> {
        let mut out = HashMap::new();
        for (name, t) in tensors {
            let values = t
                .to_dtype(candle_core::DType::F32)
                .and_then(|t| t.flatten_all())
                .and_then(|t| t.to_vec1::<f32>())
                .map_err(|e| ExportError::model(format!("reading weight `{name}`: {e}")))?;
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(ExportError::model(format!("weight `{name}` holds {} at index {i}", values[i])));
            }
            out.insert(name.clone(), (t.dims().to_vec(), values));
        }
        Ok(ExportWeights(out))
    }

    /// The shape and values of weight `name`, or an error naming it.
    pub fn get(&self, name: &str) -> Result<&(Vec<usize>, Vec<f32>), ExportError> {
        self.0.get(name).ok_or_else(|| ExportError::model(format!("the checkpoint has no weight `{name}`")))
    }

    /// Adds weight `name` to `g` as an initializer of the same name.
    pub fn init(&self, g: &mut GraphBuilder, name: &str) -> Result<Value, ExportError> {
        let (dims, data) = self.get(name)?;
        Ok(g.initializer_f32(name, dims, data))
    }
}

/// The variables of a run folder's model for its exporter: `build` declares them (the model's
/// constructor on a fresh `VarMap`, `what` naming it in errors), then they are filled from the
/// folder's weights (`model.safetensors`). Errors name the folder.
pub fn load_run_varmap<T, E: std::fmt::Display>(
    dir: &std::path::Path,
    what: &str,
    build: impl FnOnce(candle_nn::VarBuilder) -> Result<T, E>,
) -> Result<VarMap, ExportError> {
    let varmap = VarMap::new();
    let vb = candle_nn::VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &candle_core::Device::Cpu);
    build(vb).map_err(|e| ExportError::model(format!("building the {what} of {}: {e}", dir.display())))?;
    crate::checkpoint::read_varmap(&dir.join(crate::checkpoint::WEIGHTS_FILE), &varmap)
        .map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    Ok(varmap)
}

/// The text of a run folder's `config.json`, which the exported file embeds.
pub fn config_text(dir: &std::path::Path) -> Result<String, ExportError> {
    let path = dir.join(crate::checkpoint::CONFIG_FILE);
    std::fs::read_to_string(&path).map_err(|source| ExportError::Io { path: path.display().to_string(), source })
}

/// The configuration text an exported file embeds: the run folder's `config.json` when given,
/// else `config` serialised.
pub fn config_json<'a>(
    given: Option<&'a str>,
    config: &impl serde::Serialize,
) -> Result<std::borrow::Cow<'a, str>, ExportError> {
    Ok(match given {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => serde_json::to_string_pretty(config).map_err(|e| ExportError::model(e.to_string()))?.into(),
    })
}

/// An MLP of `layers` linear layers named `prefix.{i}` (candle `[out, in]` weights as Gemm with
/// the weight transposed): `activation(g, "prefix.{i}", h)` after every layer but the last, and
/// after the last when `activate_last`.
pub fn mlp(
    g: &mut GraphBuilder,
    w: &ExportWeights,
    (prefix, layers): (&str, usize),
    x: &Value,
    activate_last: bool,
    activation: impl Fn(&mut GraphBuilder, &str, &Value) -> Value,
) -> Result<Value, ExportError> {
    let mut h = x.clone();
    for i in 0..layers {
        let wt = w.init(g, &format!("{prefix}.{i}.weight"))?;
        let b = w.init(g, &format!("{prefix}.{i}.bias"))?;
        h = g.gemm(&format!("{prefix}.{i}"), &h, &wt, Some(&b), true);
        if i + 1 < layers || activate_last {
            h = activation(g, &format!("{prefix}.{i}"), &h);
        }
    }
    Ok(h)
}

/// An MLP over the last axis of a tensor of any rank (`[frames, batch, n]` of a whole-sequence
/// graph): `h = relu(h W^T + b)` per layer named `prefix.{i}`, as `MatMul` + `Add` with the candle
/// `[out, in]` weight transposed by a `Transpose` node (so initializers keep the candle paths)
/// and ReLU as `LeakyRelu` with slope 0; the last layer linear unless `activate_last`.
pub fn mlp_matmul(
    g: &mut GraphBuilder,
    w: &ExportWeights,
    (prefix, layers): (&str, usize),
    x: &Value,
    activate_last: bool,
) -> Result<Value, ExportError> {
    let mut h = x.clone();
    for i in 0..layers {
        let p = format!("{prefix}.{i}");
        let wt = w.init(g, &format!("{p}.weight"))?;
        let b = w.init(g, &format!("{p}.bias"))?;
        let wt = g.transpose(&format!("{p}.weight_t"), &wt, &[1, 0]);
        h = g.matmul(&format!("{p}.matmul"), &h, &wt);
        h = g.add(&format!("{p}.add"), &h, &b);
        if i + 1 < layers || activate_last {
            h = g.leaky_relu(&format!("{p}.relu"), &h, 0.0);
        }
    }
    Ok(h)
}

/// A stack of recurrent layers of `zoo_nn` (`crate::Lstm`, `crate::Gru`, `crate::BiLstm`,
/// `crate::BiGru`: PyTorch's names under `prefix`) for [`recurrent_layers`].
#[derive(Clone, Copy, Debug)]
pub struct RecurrentStack<'a> {
    /// The candle variable path of the layers (`prefix.weight_ih_l0`, ...).
    pub prefix: &'a str,
    /// LSTM (true) or GRU (false).
    pub lstm: bool,
    /// Forward, or bidirectional (`_reverse` weights).
    pub direction: RnnDirection,
    /// Layers.
    pub layers: usize,
    /// Units per direction.
    pub hidden: usize,
}

/// Stacks the candle weights of layer `layer`'s directions in ONNX gate order (`order`):
/// `W [dirs, G*H, in]`, `R [dirs, G*H, H]`, `B [dirs, 2*G*H]`, named `prefix.l{layer}.W`, ...
fn rnn_weights(
    g: &mut GraphBuilder,
    w: &ExportWeights,
    stack: &RecurrentStack<'_>,
    layer: usize,
    order: &[usize],
) -> Result<(Value, Value, Value), ExportError> {
    let (prefix, hidden, dirs) = (stack.prefix, stack.hidden, stack.direction.num_directions());
    let gates = order.len();
    let (mut wd, mut rd, mut bd) = (Vec::new(), Vec::new(), Vec::new());
    let mut input = 0;
    for d in 0..dirs {
        let suffix = if d == 0 { format!("l{layer}") } else { format!("l{layer}_reverse") };
        let (wdims, wih) = w.get(&format!("{prefix}.weight_ih_{suffix}"))?;
        let (_, whh) = w.get(&format!("{prefix}.weight_hh_{suffix}"))?;
        let (_, bih) = w.get(&format!("{prefix}.bias_ih_{suffix}"))?;
        let (_, bhh) = w.get(&format!("{prefix}.bias_hh_{suffix}"))?;
        if wdims.first() != Some(&(gates * hidden)) {
            return Err(ExportError::model(format!(
                "{prefix}.weight_ih_{suffix} has shape {wdims:?}, expected [{}, in]",
                gates * hidden
            )));
        }
        input = wdims[1];
        wd.extend(reorder_gates(wih, hidden, input, order));
        rd.extend(reorder_gates(whh, hidden, hidden, order));
        bd.extend(reorder_gates(bih, hidden, 1, order));
        bd.extend(reorder_gates(bhh, hidden, 1, order));
    }
    let name = format!("{prefix}.l{layer}");
    Ok((
        g.initializer_f32(&format!("{name}.W"), &[dirs, gates * hidden, input], &wd),
        g.initializer_f32(&format!("{name}.R"), &[dirs, gates * hidden, hidden], &rd),
        g.initializer_f32(&format!("{name}.B"), &[dirs, 2 * gates * hidden], &bd),
    ))
}

/// Recurrent layers over a time-major sequence `x [frames, batch, in]` from zero states: one
/// ONNX `LSTM` or `GRU` node per layer (layout 0; `bidirectional` for a bidirectional stack;
/// `linear_before_reset = 1` for the GRU, which is candle's GRU), gates reordered from candle's
/// order (LSTM i,f,g,o -> i,o,f,c; GRU r,z,n -> z,r,h). Each layer's `Y [frames, dirs, batch, H]`
/// becomes `[frames, batch, dirs * H]` (forward then backward, as candle concatenates) by
/// `Transpose` + `Reshape`; the last layer's is returned.
pub fn recurrent_layers(
    g: &mut GraphBuilder,
    w: &ExportWeights,
    stack: &RecurrentStack<'_>,
    x: &Value,
) -> Result<Value, ExportError> {
    let (dirs, hid) = (stack.direction.num_directions(), stack.hidden);
    let order: &[usize] = if stack.lstm { &LSTM_TORCH_TO_ONNX } else { &GRU_TORCH_TO_ONNX };
    let mut h = x.clone();
    for layer in 0..stack.layers {
        let (wv, rv, bv) = rnn_weights(g, w, stack, layer, order)?;
        let direction = stack.direction;
        let rnn = RnnInputs { x: &h, w: &wv, r: &rv, b: Some(&bv), initial_h: None, hidden_size: hid, direction };
        let name = format!("{}.l{layer}", stack.prefix);
        let out = if stack.lstm { g.lstm(&name, &rnn, None) } else { g.gru(&name, &rnn, true) };
        // Y [frames, dirs, batch, H] -> [frames, batch, dirs * H]
        let y = g.transpose(&format!("{name}.y_t"), &out.y, &[0, 2, 1, 3]);
        h = g.reshape(&format!("{name}.y_cat"), &y, &[0, 0, (dirs * hid) as i64]);
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device, Tensor};

    #[test]
    fn weights_are_read_by_path_and_non_finite_ones_refused() {
        let mut varmap = VarMap::new();
        let vb = candle_nn::VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        vb.pp("layer").get_with_hints((2, 3), "weight", candle_nn::Init::Const(0.5)).unwrap();
        let w = ExportWeights::from_varmap(&varmap).unwrap();
        assert_eq!(w.get("layer.weight").unwrap(), &(vec![2, 3], vec![0.5; 6]));
        assert!(w.get("layer.bias").unwrap_err().to_string().contains("no weight `layer.bias`"));
        let mut g = GraphBuilder::new("g");
        let v = w.init(&mut g, "layer.weight").unwrap();
        assert_eq!(v.name(), "layer.weight");
        varmap.set_one("layer.weight", Tensor::new(&[[f32::NAN, 0.0, 0.0], [0.0; 3]], &Device::Cpu).unwrap()).unwrap();
        let err = ExportWeights::from_varmap(&varmap).unwrap_err().to_string();
        assert!(err.contains("weight `layer.weight` holds NaN at index 0"), "{err}");
    }
}
