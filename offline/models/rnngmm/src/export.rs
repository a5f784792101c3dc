//! Export of a trained RNN-GMM generator to one ONNX file: its per-frame step graph (sec. 4.1.2,
//! eq. 5-7), state in and state out, written with the generic `zoo-export` writer beside the
//! candle forward pass of [`crate::model`] (same equations), metadata through the format crate
//! `zoo_format` (model kind `rnn-gmm`, task `synthesis`: the runtime's `SynthesisModel` samples
//! the mixture and decodes poses).
//!
//! Step graph (all tensors `[batch, n]` f32, normalised units):
//!
//! | inputs | outputs |
//! |---|---|
//! | `x`: normalised frame `x_t` (D) | `weights`: mixture weights `w` (M, softmax, eq. 7) |
//! | | `means`: `mu` (M D, component-major) |
//! | | `stds`: `sigma = exp(clamp(sigma^))` (M D) |
//! | `h{k}`, `c{k}`: LSTM state of layer `k` (H each) | `h{k}_next`, `c{k}_next` |
//!
//! The `zoo.synthesis` section ([`zoo_format::SynthesisTask`]) holds the mixture size, the
//! reference rotations and the refiner's end effectors, so `zoo_runtime::SynthesisModel` samples,
//! refines and decodes poses.
//!
//! Initializers keep the candle variable paths (`fc.0.weight`, `lstm.weight_ih_l0`,
//! `head.weight`, ...); the LSTM is written with Gemm/Split/Sigmoid/Tanh/Mul/Add in candle's gate
//! order i, f, g, o; ReLU is `LeakyRelu` with slope 0 (the same function, in every runtime).
//!
//! With a refiner in the run folder, its step graph is embedded in the metadata (base64 ONNX
//! under [`REFINER_GRAPH_KEY`], its end-effector statistics in the section's `refiner`): inputs `x`
//! (the generator's normalised frame, D), `effectors` (the normalised end-effector positions and
//! velocities of that frame, 6 E, computed by the caller with the forward kinematics of
//! [`crate::fk`]: the previous frame is needed for the velocities), `h`, `c` (its LSTM state);
//! outputs `x_refined` (D, eq. 11: `W2 lstm(relu(W1 [x; e] + b1)) + b2 + x`, then clamped to the
//! joint limits by `Max`/`Min` when the refiner has them), `h_next`, `c_next`.
//! `zoo_runtime::synthesis` runs it behind the generator (with its own forward kinematics);
//! the discriminator is training-only.

use crate::config::Config;
use crate::features::{CONTACT_DIMS, FeatureSpec, Normalization, ROOT_DIMS};
use candle_nn::VarMap;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use zoo_export::{Dim, ExportError, GraphBuilder, OnnxModel, Value, attr_int};
pub use zoo_format::synthesis::REFINER_GRAPH_KEY;
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo,
    MotionStatePair, MotionTask, SynthesisRefiner, SynthesisTask, keys,
};
use zoo_nn::ExportWeights as Weights;

/// `zoo.model_kind` of an exported RNN-GMM.
pub const MODEL_KIND: &str = "rnn-gmm";

/// Loads the generator of a run folder (`config.json`, `model.safetensors`, `features.json`,
/// `normalization.json`) and exports its step graph (see [`export_generator`]), with the
/// refiner's step graph when the folder has one (the one export signature of every model,
/// [`zoo_nn::ZooModel::export`]: the run folder records its skeleton, frame rate and units).
pub fn export_run(dir: &Path, options: &zoo_nn::ExportOptions<'_>) -> Result<OnnxModel, ExportError> {
    options.from_the_run_folder("RNN-GMM")?;
    let (config, spec, norm) =
        crate::checkpoint::read_meta(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let config_json = zoo_nn::export::config_text(dir)?;
    let varmap = zoo_nn::export::load_run_varmap(dir, "generator", |vb| crate::Generator::new(&config, vb))?;
    let generator = export_generator(&config, Some(&config_json), &spec, &norm, &varmap)?;
    if !dir.join(crate::refiner::REFINER_FILE).is_file() {
        return Ok(generator);
    }
    let eff: crate::EffectorNorm = zoo_nn::checkpoint::read_json(&dir.join(crate::refiner::EFFECTORS_FILE))
        .map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let path = dir.join(crate::refiner::REFINER_FILE);
    let tensors = zoo_nn::checkpoint::read_weight_tensors(&path, &candle_core::Device::Cpu)
        .map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let refiner = export_refiner(&config, &eff, &tensors)?;
    // The generator's file with the refiner in its section and its graph beside it.
    let mut task = synthesis_task(&config, &spec)?;
    task.refiner =
        Some(SynthesisRefiner { effectors: eff.effectors.clone(), mean: eff.mean.clone(), std: eff.std.clone() });
    task.check(spec.skeleton.len())
        .map_err(|e| ExportError::model(format!("the synthesis section would not load: {e}")))?;
    let mut proto = generator.proto().clone();
    let section = serde_json::to_string(&task).map_err(|e| ExportError::model(e.to_string()))?;
    match proto.metadata_props.iter_mut().find(|p| p.key == keys::SYNTHESIS) {
        Some(p) => p.value = section,
        None => return Err(ExportError::model("the generator's file has no synthesis section")),
    }
    proto
        .metadata_props
        .push(zoo_export::pb::StringStringEntryProto { key: REFINER_GRAPH_KEY.into(), value: refiner.to_base64() });
    Ok(OnnxModel::from_proto(proto))
}

/// The refiner's step graph (eq. 11) from its weights (`fc1.*`, `lstm.*_l0`, `fc2.*`, as in
/// `refiner.safetensors`). See the module docs for its inputs and outputs.
pub fn export_refiner(
    config: &Config,
    eff: &crate::EffectorNorm,
    tensors: &HashMap<String, candle_core::Tensor>,
) -> Result<OnnxModel, ExportError> {
    let w = Weights::from_tensors(tensors)?;
    let (d, e, hu) = (config.dim, 6 * eff.effectors.len(), config.refiner.refiner_lstm);
    let mut g = GraphBuilder::new("rnngmm_refiner_step");
    g.doc("RNN-GMM refiner (eq. 11), per-frame step graph; see zoo_rnngmm::export");
    let x = g.input("x", &batch(d));
    let effectors = g.input("effectors", &batch(e));
    let h = g.input("h", &batch(hu));
    let c = g.input("c", &batch(hu));
    let input = g.concat("fc1.input", &[&x, &effectors], 1);
    let (w1, b1) = (w.init(&mut g, "fc1.weight")?, w.init(&mut g, "fc1.bias")?);
    let z = g.gemm("fc1", &input, &w1, Some(&b1), true);
    let z = g.leaky_relu("fc1.relu", &z, 0.0);
    let (h_next, c_next) = lstm_cell(&mut g, &w, 0, &z, &h, &c, hu)?;
    let (w2, b2) = (w.init(&mut g, "fc2.weight")?, w.init(&mut g, "fc2.bias")?);
    let dx = g.gemm("fc2", &h_next, &w2, Some(&b2), true);
    let mut refined = g.add("residual", &x, &dx);
    if let Some(limits) = &eff.limits {
        let (lo, hi) = limits.full(d).map_err(|e| ExportError::model(e.to_string()))?;
        let lo = g.initializer_f32("joint_limits.lo", &[d], &lo);
        let hi = g.initializer_f32("joint_limits.hi", &[d], &hi);
        let floor = g.custom_op("Max", "joint_limits.floor", &[&refined, &lo], vec![]);
        refined = g.custom_op("Min", "joint_limits.ceiling", &[&floor, &hi], vec![]);
    }
    g.output("x_refined", &refined, &batch(d));
    g.output("h_next", &h_next, &batch(hu));
    g.output("c_next", &c_next, &batch(hu));
    g.finish()
}

/// One step of layer `k` of a candle LSTM (`lstm.{weight,bias}_{ih,hh}_l{k}`, gates i, f, g, o):
/// returns `(h_next, c_next)`.
fn lstm_cell(
    g: &mut GraphBuilder,
    w: &Weights,
    k: usize,
    x: &Value,
    hk: &Value,
    ck: &Value,
    hu: usize,
) -> Result<(Value, Value), ExportError> {
    let p = |s: &str| format!("lstm.{s}_l{k}");
    let (w_ih, b_ih) = (w.init(g, &p("weight_ih"))?, w.init(g, &p("bias_ih"))?);
    let (w_hh, b_hh) = (w.init(g, &p("weight_hh"))?, w.init(g, &p("bias_hh"))?);
    let zx = g.gemm(&p("input_gates"), x, &w_ih, Some(&b_ih), true);
    let zh = g.gemm(&p("hidden_gates"), hk, &w_hh, Some(&b_hh), true);
    let z = g.add(&p("gates"), &zx, &zh);
    let parts = g.split(&p("split"), &z, &[hu; 4], 1);
    let i = g.sigmoid(&p("i"), &parts[0]);
    let f = g.sigmoid(&p("f"), &parts[1]);
    let gg = g.tanh(&p("g"), &parts[2]);
    let o = g.sigmoid(&p("o"), &parts[3]);
    let fc = g.mul(&p("f_c"), &f, ck);
    let ig = g.mul(&p("i_g"), &i, &gg);
    let c_next = g.add(&p("c"), &fc, &ig);
    let tc = g.tanh(&p("tanh_c"), &c_next);
    let h_next = g.mul(&p("h"), &o, &tc);
    Ok((h_next, c_next))
}

fn batch(n: usize) -> [Dim; 2] {
    [Dim::batch(), Dim::Fixed(n)]
}

/// The metadata of an exported generator, checked like the runtime checks it on load.
pub fn metadata(
    config: &Config,
    config_json: &str,
    spec: &FeatureSpec,
    norm: &Normalization,
) -> Result<MotionModelMetadata, ExportError> {
    let d = config.dim;
    let mut normalization = BTreeMap::new();
    normalization.insert("x".to_string(), MotionMeanStd { mean: norm.mean.clone(), std: norm.std.clone() });
    let segment = |name: &str, start, len| MotionFeatureSegment { name: name.to_string(), start, len };
    let pair = |input: String, output: String| MotionStatePair { input, output };
    let state = (0..config.lstm_layers)
        .flat_map(|k| [pair(format!("h{k}"), format!("h{k}_next")), pair(format!("c{k}"), format!("c{k}_next"))])
        .collect();
    let metadata = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: MODEL_KIND.to_string(),
        task: MotionTask::Synthesis(synthesis_task(config, spec)?),
        config_json: config_json.to_string(),
        normalization,
        skeleton: MotionSkeletonInfo::from_skeleton(&spec.skeleton),
        feature_layout: vec![
            segment("root_dtx_dtz_dry_ty_rx_rz", 0, ROOT_DIMS),
            segment("joint_rotation_vectors_about_references", ROOT_DIMS, d - ROOT_DIMS - CONTACT_DIMS),
            segment("contacts_left_right", d - CONTACT_DIMS, CONTACT_DIMS),
        ],
        fps: spec.fps as f32,
        frame: CoordinateFrame::ZOO_CM,
        state,
        weights: zoo_format::WeightWidth::F32,
    };
    metadata.check().map_err(|e| ExportError::model(format!("the metadata would not load: {e}")))?;
    Ok(metadata)
}

/// The `zoo.synthesis` section: mixture size and the reference rotations that decode a frame.
pub fn synthesis_task(config: &Config, spec: &FeatureSpec) -> Result<SynthesisTask, ExportError> {
    let task = SynthesisTask {
        frame_dim: config.dim,
        components: config.components,
        references: spec.reference.iter().map(|q| [q.x, q.y, q.z, q.w]).collect(),
        refiner: None,
    };
    task.check(spec.skeleton.len())
        .map_err(|e| ExportError::model(format!("the synthesis section would not load: {e}")))?;
    Ok(task)
}

/// Exports the generator of `config` with the weights of `varmap` (filled by
/// [`crate::Generator::new`]). `config_json`: the run folder's `config.json` verbatim (default:
/// the config serialised).
pub fn export_generator(
    config: &Config,
    config_json: Option<&str>,
    spec: &FeatureSpec,
    norm: &Normalization,
    varmap: &VarMap,
) -> Result<OnnxModel, ExportError> {
    crate::checkpoint::check_agree(config, spec, norm).map_err(|e| ExportError::model(e.to_string()))?;
    let w = Weights::from_varmap(varmap)?;
    let config_json = zoo_nn::export::config_json(config_json, config)?;
    let config_json = config_json.as_ref();
    let mut g = step_graph(config, &w)?;
    g.doc("RNN-GMM generator (Wang, Chai & Xia 2019), per-frame step graph; see zoo_rnngmm::export");
    for (k, v) in metadata(config, config_json, spec, norm)?.to_props() {
        g.metadata(&k, &v);
    }
    g.finish()
}

/// The generator's step (sec. 4.1.2, eq. 5-7).
fn step_graph(config: &Config, w: &Weights) -> Result<GraphBuilder, ExportError> {
    let (d, hu, m) = (config.dim, config.lstm, config.components);
    let mut g = GraphBuilder::new("rnngmm_generator_step");
    let x = g.input("x", &batch(d));
    let states: Vec<(Value, Value)> = (0..config.lstm_layers)
        .map(|k| (g.input(&format!("h{k}"), &batch(hu)), g.input(&format!("c{k}"), &batch(hu))))
        .collect();
    // FC1-FC3 with ReLU.
    let mut h = x;
    for i in 0..config.fc.len() {
        let wt = w.init(&mut g, &format!("fc.{i}.weight"))?;
        let b = w.init(&mut g, &format!("fc.{i}.bias"))?;
        h = g.gemm(&format!("fc.{i}"), &h, &wt, Some(&b), true);
        h = g.leaky_relu(&format!("fc.{i}.relu"), &h, 0.0);
    }
    // The 2-layer LSTM, gates in candle's order i, f, g, o.
    let mut outputs = Vec::new();
    for (k, (hk, ck)) in states.iter().enumerate() {
        let (h_next, c_next) = lstm_cell(&mut g, w, k, &h, hk, ck, hu)?;
        outputs.push((h_next.clone(), c_next));
        h = h_next;
    }
    // The mixture head (eq. 7): softmax weights, means, exp of the clamped log stds.
    let wt = w.init(&mut g, "head.weight")?;
    let b = w.init(&mut g, "head.bias")?;
    let raw = g.gemm("head", &h, &wt, Some(&b), true);
    let parts = g.split("head.split", &raw, &[m, m * d, m * d], 1);
    let weights = g.custom_op("Softmax", "mixture.weights", &[&parts[0]], vec![attr_int("axis", 1)]);
    let lo = g.initializer_f32("mixture.min_log_std", &[1], &[config.min_log_std as f32]);
    let hi = g.initializer_f32("mixture.max_log_std", &[1], &[config.max_log_std as f32]);
    let clamped = g.custom_op("Max", "mixture.log_std_floor", &[&parts[2], &lo], vec![]);
    let clamped = g.custom_op("Min", "mixture.log_std_ceiling", &[&clamped, &hi], vec![]);
    let stds = g.custom_op("Exp", "mixture.stds", &[&clamped], vec![]);
    g.output("weights", &weights, &batch(m));
    g.output("means", &parts[1], &batch(m * d));
    g.output("stds", &stds, &batch(m * d));
    for (k, (h_next, c_next)) in outputs.iter().enumerate() {
        g.output(&format!("h{k}_next"), h_next, &batch(hu));
        g.output(&format!("c{k}_next"), c_next, &batch(hu));
    }
    Ok(g)
}
