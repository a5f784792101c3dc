//! Export of a trained RMR to ONNX: the refiner over one window (RMR sec. 5, Figure 5), beside
//! the candle forward pass of [`crate::model`] (same equations), written with `zoo-export`.
//!
//! Graph (layout 0, time-major like ONNX's recurrent ops; `frames` and `batch` symbolic):
//!
//! | input | output |
//! |---|---|
//! | `x`: normalised pose vectors `[frames, batch, dim]` | `y`: refined normalised pose vectors `[frames, batch, dim]` (contacts as logits) |
//!
//! With `config.residual`, `y` is the decoder's output plus `x` masked to the pose values
//! (`Mul` by a 0/1 initializer, `Add`).
//!
//! Encoder and decoder are `MatMul` + `Add` (+ `LeakyRelu` with slope 0, i.e. ReLU) with the
//! candle weights transposed by a `Transpose` node, so initializers keep the candle paths
//! (`encoder.0.weight`, ...; [`zoo_nn::export::mlp_matmul`]). Each recurrent layer is one ONNX
//! `LSTM` or `GRU` node ([`zoo_nn::export::recurrent_layers`])
//! (`bidirectional` for BLSTM/BGRU, `linear_before_reset = 1` for the GRU), gates reordered from
//! candle's order (LSTM i,f,g,o -> i,o,f,c; GRU r,z,n -> z,r,h); a bidirectional layer's
//! `Y [frames, 2, batch, H]` becomes `[frames, batch, 2H]` (forward then backward, as candle
//! concatenates) by `Transpose` + `Reshape`.
//!
//! Metadata (`metadata_props`, the format crate `zoo_format`): model kind `rmr`, task `stitch`
//! with its section `zoo.stitch` (window, stride, blend, the stitching layout), the skeleton,
//! fps, the statistics as normalization group `x`, the pose vector's parts as the feature layout,
//! no recurrent state (the graph is a whole window); the run's `config.json` rides along in
//! `zoo.config`, which the runtime never reads.

use crate::config::{Config, RefinerCell};
use crate::features::FeatureStats;
use candle_nn::VarMap;
use std::path::Path;
use zoo_export::{Dim, ExportError, GraphBuilder, OnnxModel, RnnDirection};
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo,
    MotionTask, StitchTask,
};
use zoo_nn::ExportWeights as Weights;
use zoo_nn::export::{RecurrentStack, mlp_matmul, recurrent_layers};

/// `zoo.model_kind` of an exported RMR.
pub const MODEL_KIND: &str = "rmr";

/// The frames the portable profile fixes the window graph of run folder `dir` to: `frames`
/// when given, else the model's runtime window; and where the number comes from, in words.
pub fn portable_window(dir: &Path, frames: Option<u32>) -> Result<(usize, &'static str), ExportError> {
    let (config, _) = crate::checkpoint::read_meta(dir)
        .map_err(|e| ExportError::model(format!("exporting {}: {e}", dir.display())))?;
    Ok(match frames {
        Some(f) => (f as usize, "--frames"),
        None => (config.window, "the model's runtime window; --frames N to change"),
    })
}

/// Loads a `zoo train rmr` run folder and exports it (see [`export_rmr`]; the one export
/// signature of every model, [`zoo_nn::ZooModel::export`]: the run folder records its skeleton,
/// frame rate and units, so `options` sets none of them).
pub fn export_run(dir: &Path, options: &zoo_nn::ExportOptions<'_>) -> Result<OnnxModel, ExportError> {
    options.from_the_run_folder("RMR")?;
    let (config, stats) =
        crate::checkpoint::read_meta(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let varmap = zoo_nn::export::load_run_varmap(dir, "RMR", |vb| crate::Rmr::new(&config, vb))?;
    export_rmr(&config, &stats, &varmap)
}

/// Exports the refiner of `config` with the weights in `varmap` (as built by [`crate::Rmr::new`]).
pub fn export_rmr(config: &Config, stats: &FeatureStats, varmap: &VarMap) -> Result<OnnxModel, ExportError> {
    config.validate().map_err(|e| ExportError::model(e.to_string()))?;
    let d = config.dim();
    if stats.dim() != d {
        return Err(ExportError::model(format!("statistics have {} values per frame, the model {d}", stats.dim())));
    }
    let w = Weights::from_varmap(varmap)?;
    let mut g = GraphBuilder::new("rmr_refiner");
    g.doc("Recurrent Motion Refiner (Kim et al. 2023): refines one window of normalised pose vectors.");
    let dims = [Dim::Symbol("frames".into()), Dim::batch(), Dim::Fixed(d)];
    let x = g.input("x", &dims);
    let h = mlp_matmul(&mut g, &w, ("encoder", config.encoder.len()), &x, true)?;
    let (lstm, direction) = match config.cell {
        RefinerCell::Lstm => (true, RnnDirection::Forward),
        RefinerCell::Gru => (false, RnnDirection::Forward),
        RefinerCell::Blstm => (true, RnnDirection::Bidirectional),
        RefinerCell::Bgru => (false, RnnDirection::Bidirectional),
    };
    let stack = RecurrentStack { prefix: "refiner", lstm, direction, layers: config.layers, hidden: config.hidden };
    let h = recurrent_layers(&mut g, &w, &stack, &h)?;
    let mut y = mlp_matmul(&mut g, &w, ("decoder", config.decoder.len() + 1), &h, false)?;
    if config.residual {
        // y += x * mask (1 on the pose values, 0 on the contacts), as in `Rmr::forward`.
        let pose = crate::features::FeatureLayout::new(config.joints, config.layout.lower_body.len()).contacts();
        let mask: Vec<f32> = (0..d).map(|i| if i < pose { 1.0 } else { 0.0 }).collect();
        let mask = g.initializer_f32("residual_mask", &[d], &mask);
        let kept = g.mul("residual.mask", &x, &mask);
        y = g.add("residual.add", &y, &kept);
    }
    g.output("y", &y, &dims);
    for (k, v) in metadata(config, stats)?.to_props() {
        g.metadata(&k, &v);
    }
    g.finish()
}

/// The metadata of an exported RMR, checked like the runtime checks it on load.
pub fn metadata(config: &Config, stats: &FeatureStats) -> Result<MotionModelMetadata, ExportError> {
    let config_json =
        serde_json::to_string(config).map_err(|e| ExportError::model(format!("configuration to JSON: {e}")))?;
    let pl = crate::features::FeatureLayout::new(config.joints, config.layout.lower_body.len());
    let segment =
        |name: &str, start: usize, end: usize| MotionFeatureSegment { name: name.into(), start, len: end - start };
    let metadata = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: MODEL_KIND.to_string(),
        task: MotionTask::Stitch(StitchTask {
            window: config.window,
            stride: config.stride,
            blend_frames: config.blend_frames,
            layout: config.layout.clone(),
            pre_blend: config.pre_blend,
            fallback: config.fallback,
        }),
        config_json,
        normalization: [("x".to_string(), MotionMeanStd { mean: stats.mean.clone(), std: stats.std.clone() })].into(),
        skeleton: MotionSkeletonInfo {
            names: config.names.clone(),
            parents: config.parents.clone(),
            offsets: config.offsets.clone(),
        },
        feature_layout: vec![
            segment("root_motion_r", 0, pl.positions()),
            segment("lower_body_positions_p", pl.positions(), pl.rotations()),
            segment("local_rotations_q", pl.rotations(), pl.velocities()),
            segment("lower_body_velocities_v", pl.velocities(), pl.contacts()),
            segment("contacts_c", pl.contacts(), pl.dim()),
        ],
        fps: config.fps as f32,
        frame: CoordinateFrame::ZOO_CM,
        state: vec![],
        weights: zoo_format::WeightWidth::F32,
    };
    metadata.check().map_err(|e| ExportError::model(format!("the metadata would not load: {e}")))?;
    Ok(metadata)
}
