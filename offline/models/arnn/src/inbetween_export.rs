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

use crate::inbetween::{Inbetween, InbetweenConfig};
use crate::train::Normalization;
use candle_nn::VarMap;
use std::collections::BTreeMap;
use std::path::Path;
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
    let correction = g.transpose("correction.batch_major", &y, &[1, 0, 2]);
    g.output("correction", &correction, &[Dim::batch(), frames(), Dim::Fixed(d)]);
    for (k, v) in metadata(config, norm)?.to_props() {
        g.metadata(&k, &v);
    }
    g.finish()
}
