//! Export of a trained ARNN to one ONNX file: the per-frame step graph of section 6 (the same
//! equations as [`crate::Arnn::step`]), written with the generic `zoo-export` writer; metadata
//! through the format crate `zoo_format` (model kind `arnn`, task `keyframes`, its section
//! `zoo.keyframes` with the pose width and the key groups; the runtime's `KeyframeModel` runs it).
//! A run folder of the in-betweening design exports its whole-shot graph instead
//! ([`crate::inbetween_export`]).
//!
//! Step graph (one call per frame; every tensor `[batch, n]` f32, poses in physical units,
//! metres and radians, the normalisation inside the graph):
//!
//! | inputs | outputs |
//! |---|---|
//! | `prev`: the previous pose `Y'_(t-1)` (D) | `pose`: `Y'_t` (D) |
//! | `key_a`, `key_b`: the keys `X_K`, `X_(K+1)` around frame t (D each) | |
//! | `t_rel`: `(t - T_K) / (T_(K+1) - T_K)` (1) | |
//! | `fixed_a`, `fixed_b`: with key groups only (a humanoid), 1 for each group the key fixes, 0 for a free one (G each) | |
//! | `h1`, `h2`: the GRU states (H each), zero at frame 0 | `h1_next`, `h2_next` |
//!
//! Completing keys: frame 0 is the first key; for t = 1..=last key, pick the keys around t
//! (`crate::luxo::preprocess::KeyedSequence::interval`), feed the previous output as `prev`.
//! The GRUs are written as cells (Gemm, Sigmoid, Tanh, Mul, Add) in candle's gate order r, z, n
//! with the reset gate applied after the hidden projection (ONNX `linear_before_reset = 1`),
//! so no gate reordering is needed; SELU is the ONNX `Selu` op with its default constants,
//! which are candle's. Initializers keep the candle variable paths.

use crate::checkpoint;
use crate::config::ArnnConfig;
use crate::train::Normalization;
use candle_nn::VarMap;
use std::collections::BTreeMap;
use std::path::Path;
use zoo_export::{Dim, ExportError, GraphBuilder, OnnxModel, Value};
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, KeyframesTask, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata,
    MotionSkeletonInfo, MotionStatePair, MotionTask,
};
use zoo_nn::ExportWeights as Weights;

/// `zoo.model_kind` of an exported ARNN.
pub const MODEL_KIND: &str = "arnn";

/// Frames per second recorded in the metadata: the rate `zoo complete` plays completions at.
pub const FPS: f32 = 50.0;

/// Loads a `zoo train arnn` run folder and exports it: the step graph of [`export_arnn`], or
/// for the in-betweening design (`--design inbetween`) its whole-shot graph
/// ([`crate::inbetween_export`]). The one export signature of every model
/// ([`zoo_nn::ZooModel::export`]): the run folder records its skeleton and frame rate.
pub fn export_run(dir: &Path, options: &zoo_nn::ExportOptions<'_>) -> Result<OnnxModel, ExportError> {
    options.from_the_run_folder("ARNN")?;
    if crate::inbetween::is_inbetween_run(dir) {
        return crate::inbetween_export::export_inbetween_run(dir);
    }
    let (config, norm) =
        checkpoint::read_meta(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let varmap = zoo_nn::export::load_run_varmap(dir, "ARNN", |vb| crate::Arnn::new(&config, vb))?;
    export_arnn(&config, &norm, &varmap)
}

fn batch(n: usize) -> [Dim; 2] {
    [Dim::batch(), Dim::Fixed(n)]
}

/// SELU as `scale * (relu(x) + alpha * (exp(min(x, 0)) - 1))`: tract's `Selu` kernel differs
/// from candle and onnxruntime by about 1e-6 per call, which the residual accumulates over a
/// sequence; `Exp` agrees to float rounding.
fn selu(g: &mut GraphBuilder, name: &str, x: &Value) -> Value {
    let pos = g.custom_op("Relu", &format!("{name}.relu"), &[x], vec![]);
    let neg = g.sub(&format!("{name}.neg"), x, &pos);
    let e = g.custom_op("Exp", &format!("{name}.exp"), &[&neg], vec![]);
    let one = g.initializer_f32(&format!("{name}.one"), &[], &[1.0]);
    let em1 = g.sub(&format!("{name}.expm1"), &e, &one);
    let alpha = g.initializer_f32(&format!("{name}.alpha"), &[], &[zoo_nn::layers::SELU_ALPHA as f32]);
    let scale = g.initializer_f32(&format!("{name}.scale"), &[], &[zoo_nn::layers::SELU_SCALE as f32]);
    let a = g.mul(&format!("{name}.alpha_mul"), &em1, &alpha);
    let sum = g.add(&format!("{name}.sum"), &pos, &a);
    g.mul(&format!("{name}.scale_mul"), &sum, &scale)
}

/// SELU after a layer of [`zoo_nn::export::mlp`] (node `LAYER.selu`).
fn selu_after(g: &mut GraphBuilder, layer: &str, h: &Value) -> Value {
    selu(g, &format!("{layer}.selu"), h)
}

/// One step of a 1-layer `zoo_nn::Gru` (`prefix.weight_ih_l0`, ...): the next `h`.
fn gru_cell(
    g: &mut GraphBuilder,
    w: &Weights,
    prefix: &str,
    hidden: usize,
    x: &Value,
    h: &Value,
) -> Result<Value, ExportError> {
    let w_ih = w.init(g, &format!("{prefix}.weight_ih_l0"))?;
    let w_hh = w.init(g, &format!("{prefix}.weight_hh_l0"))?;
    let b_ih = w.init(g, &format!("{prefix}.bias_ih_l0"))?;
    let b_hh = w.init(g, &format!("{prefix}.bias_hh_l0"))?;
    let gx = g.gemm(&format!("{prefix}.input_gates"), x, &w_ih, Some(&b_ih), true);
    let gh = g.gemm(&format!("{prefix}.hidden_gates"), h, &w_hh, Some(&b_hh), true);
    let xs = g.split(&format!("{prefix}.split_x"), &gx, &[hidden; 3], 1);
    let hs = g.split(&format!("{prefix}.split_h"), &gh, &[hidden; 3], 1);
    let r = g.add(&format!("{prefix}.r_sum"), &xs[0], &hs[0]);
    let r = g.sigmoid(&format!("{prefix}.r"), &r);
    let z = g.add(&format!("{prefix}.z_sum"), &xs[1], &hs[1]);
    let z = g.sigmoid(&format!("{prefix}.z"), &z);
    let rn = g.mul(&format!("{prefix}.r_hn"), &r, &hs[2]);
    let n = g.add(&format!("{prefix}.n_sum"), &xs[2], &rn);
    let n = g.tanh(&format!("{prefix}.n"), &n);
    // h' = (1 - z) n + z h = n + z (h - n)
    let d = g.sub(&format!("{prefix}.h_minus_n"), h, &n);
    let zd = g.mul(&format!("{prefix}.z_d"), &z, &d);
    Ok(g.add(&format!("{prefix}.h"), &n, &zd))
}

/// The metadata of an exported ARNN: of the lamp (its skeleton, degrees of freedom in metres
/// and radians) or of a humanoid (its skeleton, the pose of `zoo_arnn::humanoid` in the clips'
/// centimetres, Y up).
pub fn metadata(config: &ArnnConfig, norm: &Normalization) -> Result<MotionModelMetadata, ExportError> {
    let d = config.dofs;
    let (skeleton, fps) = match (&config.skeleton, &config.lamp) {
        (Some(s), _) => (
            MotionSkeletonInfo { names: s.names.clone(), parents: s.parents.clone(), offsets: s.offsets.clone() },
            s.fps as f32,
        ),
        (None, Some(lamp)) => (MotionSkeletonInfo::from_skeleton(&crate::luxo::sequence::lamp_skeleton(lamp)), FPS),
        (None, None) => {
            return Err(ExportError::model(
                "config.json has neither a lamp nor a humanoid skeleton: retrain with `zoo train arnn`",
            ));
        }
    };
    let f32s = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<_>>();
    let mut normalization = BTreeMap::new();
    normalization.insert("pose".to_string(), MotionMeanStd { mean: f32s(&norm.mean), std: f32s(&norm.std) });
    let names = if config.dof_names.len() == d {
        config.dof_names.clone()
    } else {
        (0..d).map(|i| format!("dof{i}")).collect()
    };
    let feature_layout =
        names.iter().enumerate().map(|(i, n)| MotionFeatureSegment { name: n.clone(), start: i, len: 1 }).collect();
    let pair = |input: &str, output: &str| MotionStatePair { input: input.to_string(), output: output.to_string() };
    let config_json = serde_json::to_string_pretty(config).map_err(|e| ExportError::model(e.to_string()))?;
    let metadata = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: MODEL_KIND.to_string(),
        task: MotionTask::Keyframes(KeyframesTask {
            dofs: d,
            groups: config.groups(),
            key_groups: config.key_groups.clone(),
            inbetween: None,
        }),
        config_json,
        normalization,
        skeleton,
        feature_layout,
        fps,
        // The lamp's skeleton (its BVH) is in centimetres, Y up, right-handed; the step graph's
        // degrees of freedom are metres and radians (feature_layout names them).
        frame: CoordinateFrame::ZOO_CM,
        state: vec![pair("h1", "h1_next"), pair("h2", "h2_next")],
        weights: zoo_format::WeightWidth::F32,
    };
    metadata.check().map_err(|e| ExportError::model(format!("the metadata would not load: {e}")))?;
    Ok(metadata)
}

/// Exports an ARNN from its configuration, statistics and weights (a VarMap filled by
/// [`crate::Arnn::new`]).
pub fn export_arnn(config: &ArnnConfig, norm: &Normalization, varmap: &VarMap) -> Result<OnnxModel, ExportError> {
    config.validate().map_err(ExportError::model)?;
    if config.architecture != crate::config::Architecture::Arnn {
        return Err(ExportError::model(format!(
            "the {:?} architecture is a Table 2 comparison, not exported: export an ARNN run (`zoo train arnn \
             --variant arnn`)",
            config.architecture
        )));
    }
    let (d, h) = (config.dofs, config.hidden);
    if norm.mean.len() != d || norm.std.len() != d {
        return Err(ExportError::model(format!(
            "the statistics are for {} values, the model for {d}",
            norm.mean.len()
        )));
    }
    let w = Weights::from_varmap(varmap)?;
    let mut g = GraphBuilder::new("arnn_step");
    g.doc("ARNN keyframe autocompletion (Zhang & van de Panne 2018), per-frame step graph; see zoo_arnn::export");
    let prev = g.input("prev", &batch(d));
    let key_a = g.input("key_a", &batch(d));
    let key_b = g.input("key_b", &batch(d));
    let t_rel = g.input("t_rel", &batch(1));
    // Partial keys: one 0/1 flag per group and key (`Normalization::key_input`).
    let groups = config.groups();
    let fixed = (groups > 0).then(|| (g.input("fixed_a", &batch(groups)), g.input("fixed_b", &batch(groups))));
    let h1 = g.input("h1", &batch(h));
    let h2 = g.input("h2", &batch(h));
    let mean = g.initializer_f32("normalization.mean", &[d], &norm.mean.iter().map(|v| *v as f32).collect::<Vec<_>>());
    let std = g.initializer_f32("normalization.std", &[d], &norm.std.iter().map(|v| *v as f32).collect::<Vec<_>>());
    let mut normalized = Vec::new();
    for (name, x) in [("prev", &prev), ("key_a", &key_a), ("key_b", &key_b)] {
        let c = g.sub(&format!("{name}.centre"), x, &mean);
        normalized.push(g.div(&format!("{name}.normalize"), &c, &std));
    }
    // With key groups, a key's input is its normalised pose with the free groups' values set to
    // 0 (the flags expanded to the degrees of freedom by a 0/1 matrix), then the flags.
    let (key_a_in, key_b_in) = match &fixed {
        None => (normalized[1].clone(), normalized[2].clone()),
        Some((fa, fb)) => {
            let mut expand = vec![0f32; groups * d];
            for (i, &grp) in config.key_groups.iter().enumerate() {
                expand[grp * d + i] = 1.0;
            }
            let e = g.initializer_f32("key_groups.expand", &[groups, d], &expand);
            let mut inputs = Vec::new();
            for (name, key, flags) in [("key_a", &normalized[1], fa), ("key_b", &normalized[2], fb)] {
                let m = g.matmul(&format!("{name}.mask"), flags, &e);
                let masked = g.mul(&format!("{name}.masked"), key, &m);
                inputs.push(g.concat(&format!("{name}.with_flags"), &[&masked, flags], 1));
            }
            let b = inputs.pop().expect("two keys");
            (inputs.pop().expect("two keys"), b)
        }
    };
    // Section 6: feature nets of Y'_(t-1), X_K, X_(K+1), concatenated with t_rel.
    let fp = zoo_nn::export::mlp(&mut g, &w, ("prev_features", 2), &normalized[0], true, selu_after)?;
    let fa = zoo_nn::export::mlp(&mut g, &w, ("key_a_features", 2), &key_a_in, true, selu_after)?;
    let fb = zoo_nn::export::mlp(&mut g, &w, ("key_b_features", 2), &key_b_in, true, selu_after)?;
    let x = g.concat("features", &[&fp, &fa, &fb, &t_rel], 1);
    let h1_next = gru_cell(&mut g, &w, "gru1", h, &x, &h1)?;
    let o1 = selu(&mut g, "gru1.selu", &h1_next);
    let h2_next = gru_cell(&mut g, &w, "gru2", h, &o1, &h2)?;
    let o2 = selu(&mut g, "gru2.selu", &h2_next);
    let dy = zoo_nn::export::mlp(&mut g, &w, ("decoder", 3), &o2, false, selu_after)?;
    // The residual on the normalised previous pose, then back to physical units.
    let y = g.add("residual", &normalized[0], &dy);
    let ys = g.mul("denormalize.scale", &y, &std);
    let pose = g.add("denormalize", &ys, &mean);
    g.output("pose", &pose, &batch(d));
    g.output("h1_next", &h1_next, &batch(h));
    g.output("h2_next", &h2_next, &batch(h));
    for (k, v) in metadata(config, norm)?.to_props() {
        g.metadata(&k, &v);
    }
    g.finish()
}
