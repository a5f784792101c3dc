//! Export of a trained in-betweening network ([`crate::inbetween`], `zoo train arnn --design
//! inbetween`) to one ONNX file: the whole-shot graph (the same equations as
//! [`crate::inbetween::Inbetween::correction`]), written with the generic `zoo-export` writer;
//! metadata through the format crate (model kind `arnn`, task `keyframes`, its section
//! `zoo.keyframes` with the in-betweening settings, `zoo_format::InbetweenSection`). The
//! runtime's `KeyframeModel` runs it: it builds the features from the keys
//! (`zoo_protocol::inbetween`), runs the graph once per shot and composes `b + e * correction *
//! std` in f64, as [`crate::inbetween::complete_shots`] does.
//!
//! Graph (`batch` and `frames` symbolic; the runtime plans it for one shot at a time, as tract
//! plans a `GRU` without `initial_h` for a concrete batch only; no recurrent state: a call is a
//! whole shot):
//! - input `features`: `[batch, frames, 3 D + 2 + 2 G]`, the features of
//!   [`zoo_protocol::inbetween`];
//! - output `correction`: `[batch, frames, D]`, normalised units, before the envelope.
//!
//! `features` is made time-major by a `Transpose`; the encoder (one ReLU layer) and the decoder
//! (a ReLU layer, then a linear one) are `MatMul` + `Add` ([`zoo_nn::export::mlp_matmul`]); each
//! bidirectional GRU layer is one ONNX `GRU` node with `direction = "bidirectional"` and
//! `linear_before_reset = 1` (candle's GRU), gates reordered from candle's r,z,n to ONNX's z,r,h,
//! its `Y` concatenated forward then backward ([`zoo_nn::export::recurrent_layers`], as the RMR
//! exports its BGRU); a last `Transpose` makes the output batch-major. Initializers keep the
//! candle paths (`encoder.0.weight`, ...; the GRU's stacked weights `bgru.l0.W`, `.R`, `.B`).
//!
//! With the transformer backbone (`crate::inbetween::Backbone::Transformer`) the graph stays
//! batch-major and has no recurrent node: the velocity input (`Slice`, `Concat`, `Sub`, `Mul`),
//! the encoder, the attention's distance bias built from the shot's length (`Shape`, `Gather`,
//! `Range`, `Cast`, `Abs`: any number of frames), per block `LayerNormalization`, the heads'
//! `MatMul`s with `Reshape`/`Transpose` and a `Softmax`, the feed-forward layers, then a last
//! `LayerNormalization` and the decoder. Initializers keep the candle paths (`blocks.0.q.0.weight`,
//! `blocks.0.ln1.weight`, `ln.bias`, ...).

use crate::inbetween::{Backbone, Inbetween, InbetweenConfig};
use crate::train::Normalization;
use candle_nn::VarMap;
use std::collections::BTreeMap;
use std::path::Path;
use zoo_export::Value;
use zoo_export::{Dim, ExportError, GraphBuilder, OnnxModel, RnnDirection};
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, InbetweenSection, KeyframesTask, MotionFeatureSegment, MotionMeanStd,
    MotionModelMetadata, MotionSkeletonInfo, MotionTask,
};
use zoo_nn::ExportWeights as Weights;
use zoo_nn::export::{RecurrentStack, mlp_matmul, recurrent_layers};

/// Loads an in-betweening run folder and exports it (see [`export_inbetween`]).
pub(crate) fn export_inbetween_run(dir: &Path) -> Result<OnnxModel, ExportError> {
    let (config, norm) =
        crate::inbetween::read_meta(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let varmap = zoo_nn::export::load_run_varmap(dir, "in-betweening network", |vb| Inbetween::new(&config, vb))?;
    export_inbetween(&config, &norm, &varmap)
}

/// The metadata of an exported in-betweening network, checked like the runtime checks it.
pub fn metadata(config: &InbetweenConfig, norm: &Normalization) -> Result<MotionModelMetadata, ExportError> {
    let s = &config.skeleton;
    let (names, key_groups) = crate::humanoid::pose_layout(&s.names);
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<_>>();
    let mut normalization = BTreeMap::new();
    normalization.insert("pose".to_string(), MotionMeanStd { mean: f32s(&norm.mean), std: f32s(&norm.std) });
    let section = InbetweenSection {
        euler_axes: config.euler_axes.clone(),
        gap_unit: config.gap_unit,
        mean: norm.mean.clone(),
        std: norm.std.clone(),
        input_width: config.input_width(),
        residual: config.residual,
        fallback: config.fallback.clone(),
    };
    let metadata = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: crate::export::MODEL_KIND.to_string(),
        task: MotionTask::Keyframes(KeyframesTask {
            dofs: config.dofs(),
            groups: config.groups(),
            key_groups,
            inbetween: Some(section),
        }),
        config_json: serde_json::to_string_pretty(config).map_err(|e| ExportError::model(e.to_string()))?,
        normalization,
        skeleton: MotionSkeletonInfo { names: s.names.clone(), parents: s.parents.clone(), offsets: s.offsets.clone() },
        feature_layout: names
            .iter()
            .enumerate()
            .map(|(i, n)| MotionFeatureSegment { name: n.clone(), start: i, len: 1 })
            .collect(),
        fps: s.fps as f32,
        // The humanoid's poses are in the clips' units (bandai2 and the synthetic data: cm, Y up).
        frame: CoordinateFrame::ZOO_CM,
        state: vec![],
        weights: zoo_format::WeightWidth::F32,
    };
    metadata.check().map_err(|e| ExportError::model(format!("the metadata would not load: {e}")))?;
    Ok(metadata)
}

/// Exports the in-betweening network of `config` with the statistics `norm` and the weights in
/// `varmap` (as built by [`Inbetween::new`]).
pub fn export_inbetween(
    config: &InbetweenConfig,
    norm: &Normalization,
    varmap: &VarMap,
) -> Result<OnnxModel, ExportError> {
    config.validate().map_err(|e| ExportError::model(e.to_string()))?;
    let (d, width) = (config.dofs(), config.input_width());
    if norm.mean.len() != d || norm.std.len() != d {
        return Err(ExportError::model(format!(
            "the statistics are for {} values, the model for {d}",
            norm.mean.len()
        )));
    }
    let w = Weights::from_varmap(varmap)?;
    let mut g = GraphBuilder::new("arnn_inbetween");
    g.doc(
        "Key-to-key in-betweening network (zoo train arnn --design inbetween): the correction of the keys' Bezier \
         curves over a whole shot; see zoo_arnn::inbetween_export",
    );
    let frames = || Dim::Symbol("frames".into());
    let features = g.input("features", &[Dim::batch(), frames(), Dim::Fixed(width)]);
    let correction = match config.backbone {
        Backbone::Bgru => {
            let x = g.transpose("features.time_major", &features, &[1, 0, 2]);
            let h = mlp_matmul(&mut g, &w, ("encoder", 1), &x, true)?;
            let stack = RecurrentStack {
                prefix: "bgru",
                lstm: false,
                direction: RnnDirection::Bidirectional,
                layers: config.layers,
                hidden: config.hidden,
            };
            let h = recurrent_layers(&mut g, &w, &stack, &h)?;
            let y = mlp_matmul(&mut g, &w, ("decoder", 2), &h, false)?;
            g.transpose("correction.batch_major", &y, &[1, 0, 2])
        }
        Backbone::Transformer => {
            let h = transformer(&mut g, &w, config, &features)?;
            mlp_matmul(&mut g, &w, ("decoder", 2), &h, false)?
        }
    };
    g.output("correction", &correction, &[Dim::batch(), frames(), Dim::Fixed(d)]);
    for (k, v) in metadata(config, norm)?.to_props() {
        g.metadata(&k, &v);
    }
    g.finish()
}

/// The transformer backbone ([`Backbone::Transformer`]) of `features` `[batch, frames, width]`,
/// batch-major throughout: the velocity input (`Slice`, `Concat`, `Sub`, `Mul`), the encoder, the
/// attention bias from the frame distance (`Shape`, `Gather`, `Range`, `Cast`, `Sub`, `Abs`,
/// `Mul` by the negated slopes), the blocks (`LayerNormalization`, `MatMul`, `Reshape`,
/// `Transpose`, `Softmax`) and the last layer normalisation: `[batch, frames, encoder]`.
fn transformer(
    g: &mut GraphBuilder,
    w: &Weights,
    config: &InbetweenConfig,
    features: &Value,
) -> Result<Value, ExportError> {
    let (d, e, heads) = (config.dofs() as i64, config.encoder, config.heads);
    let dh = e / heads;
    // The Bezier pose's change, b_t - b_(t-1) with b_(-1) = b_0 (`crate::inbetween::velocity`).
    let b = g.slice("velocity.bezier", features, &[2], &[0], &[d]);
    let first = g.slice("velocity.first", &b, &[1], &[0], &[1]);
    let most = g.slice("velocity.most", &b, &[1], &[0], &[-1]);
    let prev = g.concat("velocity.prev", &[&first, &most], 1);
    let change = g.sub("velocity.change", &b, &prev);
    let scale = g.initializer_f32("velocity.scale", &[], &[crate::inbetween::VELOCITY_SCALE as f32]);
    let v = g.mul("velocity", &change, &scale);
    let x = g.concat("encoder.input", &[features, &v], 2);
    let mut h = mlp_matmul(g, w, ("encoder", 1), &x, true)?;
    // The attention bias [heads, frames, frames]: -m_h |i - j|.
    let shape = g.shape("alibi.shape", &h);
    let frames = g.gather_scalar("alibi.frames", &shape, 1, 0);
    let positions = g.range_i64("alibi.range", 0, &frames, 1);
    let positions = g.cast_f32("alibi.positions", &positions);
    let rows = g.unsqueeze("alibi.rows", &positions, &[1]);
    let cols = g.unsqueeze("alibi.cols", &positions, &[0]);
    let diff = g.sub("alibi.diff", &rows, &cols);
    let distance = g.abs("alibi.distance", &diff);
    let slopes: Vec<f32> = crate::inbetween::alibi_slopes(heads).iter().map(|m| -m).collect();
    let slopes = g.initializer_f32("alibi.slopes", &[heads, 1, 1], &slopes);
    let bias = g.mul("alibi", &distance, &slopes);
    let inv_sqrt = g.initializer_f32("attention.scale", &[], &[1.0 / (dh as f32).sqrt()]);
    let eps = crate::inbetween::LAYER_NORM_EPS as f32;
    let norm = |g: &mut GraphBuilder, p: &str, x: &Value| -> Result<Value, ExportError> {
        let (s, b) = (w.init(g, &format!("{p}.weight"))?, w.init(g, &format!("{p}.bias"))?);
        Ok(g.layer_norm(p, x, &s, &b, -1, eps))
    };
    for i in 0..config.layers {
        let p = format!("blocks.{i}");
        let a = norm(g, &format!("{p}.ln1"), &h)?;
        // [batch, frames, e] -> [batch, heads, frames, dh] (k: [batch, heads, dh, frames]).
        let split = |g: &mut GraphBuilder, m: &str, perm: &[i64]| -> Result<Value, ExportError> {
            let y = mlp_matmul(g, w, (format!("{p}.{m}").as_str(), 1), &a, false)?;
            let y = g.reshape(&format!("{p}.{m}.heads"), &y, &[0, 0, heads as i64, dh as i64]);
            Ok(g.transpose(&format!("{p}.{m}.split"), &y, perm))
        };
        let q = split(g, "q", &[0, 2, 1, 3])?;
        let k = split(g, "k", &[0, 2, 3, 1])?;
        let v = split(g, "v", &[0, 2, 1, 3])?;
        let scores = g.matmul(&format!("{p}.scores"), &q, &k);
        let scores = g.mul(&format!("{p}.scores.scaled"), &scores, &inv_sqrt);
        let scores = g.add(&format!("{p}.scores.biased"), &scores, &bias);
        let attn = g.softmax(&format!("{p}.softmax"), &scores, -1);
        let o = g.matmul(&format!("{p}.attend"), &attn, &v);
        let o = g.transpose(&format!("{p}.merge"), &o, &[0, 2, 1, 3]);
        let o = g.reshape(&format!("{p}.merged"), &o, &[0, 0, e as i64]);
        let o = mlp_matmul(g, w, (format!("{p}.o").as_str(), 1), &o, false)?;
        h = g.add(&format!("{p}.attention.residual"), &h, &o);
        let f = norm(g, &format!("{p}.ln2"), &h)?;
        let f = mlp_matmul(g, w, (format!("{p}.ffn").as_str(), 2), &f, false)?;
        h = g.add(&format!("{p}.ffn.residual"), &h, &f);
    }
    norm(g, "ln", &h)
}
