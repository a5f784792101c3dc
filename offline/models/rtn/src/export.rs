//! Export of a trained Recurrent Transition Network (Harvey & Pal 2018) to one ONNX file: the
//! graph definition beside the candle forward pass of [`crate::model`] (same equations), written
//! with the generic `zoo-export` writer, metadata through the format crate `zoo_format` (model kind `rtn`, task
//! `transition`).
//!
//! The file holds the per-frame **step graph** and, in its metadata_props
//! (`zoo.start_graph`, base64), the **transition-start graph**, the way `zoo-runtime` loads them.
//!
//! Step graph (state in, state out; one call per frame, all tensors `[batch, n]` f32):
//!
//! | inputs | when | outputs |
//! |---|---|---|
//! | `x`: normalized features `x_t` (D) | always | `x_next`: normalized `x_(t+1)` (D) |
//! | `offset`: normalized global offset `o_t` (D) | `future_conditioning` | |
//! | `terrain`: normalized terrain patch (side^2) | `terrain` | |
//! | `base`: normalized interpolation frame `b_(t+1)` (D) | `interp_residual` | (`x_next = base + D(h)`) |
//! | `tta`: time-to-arrival embedding of the predicted frame (dims) | `time_to_arrival` | |
//! | `h`, `c`: LSTM state (H) | always | `h_next`, `c_next` |
//! | `gate_bias`: `C_F h_F + b` (4H), constant over a transition | `future_conditioning` | `gate_bias_next` (= `gate_bias`) |
//!
//! Start graph (once per transition): inputs `target` (normalized target vector, 2D; with
//! `future_conditioning`) and `x0` (normalized first frame, D; with a learned or common initial
//! state); outputs named like the step graph's state inputs: `gate_bias` (RTN eq. 3 and the
//! target term of eq. 5-8), `h`, `c` (RTN eq. 14, or the common learned state). Slots it does
//! not produce start at zero (`init_state = zero`). A model without future conditioning and
//! with a zero initial state has no start graph.
//!
//! Initializers keep the candle variable paths (`frame_encoder.0.weight`, `lstm.weight_ih`, ...);
//! the LSTM is written with Gemm/Split/Sigmoid/Tanh/Mul/Add in candle's gate order i, f, g, o,
//! so no gate reordering is needed. The offset `o_t` is recomputed by the caller from the
//! generated frame (as candle's `generate` does), which keeps the step graph free of the root
//! integration.

use crate::features::{FeatureStats, MeanStd};
use crate::{Config, InitState};
use candle_nn::VarMap;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use zoo_export::{Dim, ExportError, GraphBuilder, OnnxModel, Value};
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo,
    MotionStatePair, MotionTask, TransitionFallback, TransitionTask, TransitionTerrain, keys,
};
use zoo_nn::ExportWeights as Weights;
use zoo_nn::checkpoint::RunSkeleton;

/// `zoo.model_kind` of an exported RTN.
pub const MODEL_KIND: &str = "rtn";

/// What the run folder may not record: joint names, rest offsets and the frame rate.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RtnExportOptions {
    /// Joint names (required).
    pub names: Option<Vec<String>>,
    /// Rest offset of each joint from its parent (clip units; required).
    pub offsets: Option<Vec<[f32; 3]>>,
    /// Parent of each joint (-1 for the root), when the config has none.
    pub parents: Option<Vec<i32>>,
    /// Frames per second of the training data (required).
    pub fps: Option<f32>,
    /// Units, up axis and handedness of the training data (required; zoo's data: centimetres,
    /// Y up, right-handed, [`CoordinateFrame::ZOO_CM`]).
    pub frame: Option<CoordinateFrame>,
}

impl RtnExportOptions {
    /// The options of a run folder's [`RunSkeleton`].
    pub fn from_run_skeleton(s: &RunSkeleton) -> Self {
        RtnExportOptions {
            names: Some(s.names.clone()),
            offsets: Some(s.offsets.clone()),
            parents: Some(s.parents.clone()),
            fps: Some(s.fps),
            frame: Some(s.frame),
        }
    }

    /// These options, with what they leave out taken from `other`.
    pub fn or(self, other: RtnExportOptions) -> Self {
        RtnExportOptions {
            names: self.names.or(other.names),
            offsets: self.offsets.or(other.offsets),
            parents: self.parents.or(other.parents),
            fps: self.fps.or(other.fps),
            frame: self.frame.or(other.frame),
        }
    }
}

/// The RTN of run folder `dir` with the skeleton, fps and units of `inputs` (`zoo export`; the
/// one export signature of every model, [`zoo_nn::ZooModel::export`]): a skeleton clip must
/// have the training hierarchy; without one, the run folder's `skeleton.json` is required; BVH
/// does not say its unit, so without `units` or a `skeleton.json` the data is taken as zoo's
/// centimetres, Y up.
pub fn export_run(dir: &Path, inputs: &zoo_nn::ExportOptions<'_>) -> Result<OnnxModel, ExportError> {
    let err = |m: String| ExportError::model(m);
    let mut options = RtnExportOptions { fps: inputs.fps, ..RtnExportOptions::default() };
    let mut clip_fps = None;
    if let Some(u) = inputs.units {
        let metres_per_unit =
            CoordinateFrame::metres_per(u).ok_or_else(|| err(format!("--units {u}: cm, m, mm or in")))?;
        options.frame = Some(CoordinateFrame { metres_per_unit, ..CoordinateFrame::ZOO_CM });
    }
    if let Some(path) = inputs.skeleton {
        let clip = zoo_data::clip_io::read_model_clip(path)
            .map_err(|e| err(format!("reading the skeleton of {}: {e}", path.display())))?;
        let s = &clip.skeleton;
        options.names = Some(s.names.clone());
        options.offsets = Some(s.offsets.iter().map(|o| o.as_vec3().to_array()).collect());
        options.parents = Some(s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect());
        clip_fps = Some(clip.fps() as f32);
    }
    let run_skeleton = RunSkeleton::read(dir).map_err(|e| err(format!("{}: {e}", dir.display())))?;
    // The model's frame rate is its training data's (the run's skeleton.json); a skeleton clip
    // at another rate gives its joints, not its rate.
    match (options.fps, run_skeleton.as_ref().map(|s| s.fps), clip_fps) {
        (None, Some(run), Some(clip)) if !zoo_motion::clip::same_frame_rate(f64::from(clip), f64::from(run)) => {
            eprintln!(
                "note: --skeleton is at {clip} fps, the model was trained at {run} fps: the file records {run} fps"
            );
        }
        (None, None, Some(clip)) => options.fps = Some(clip),
        _ => {}
    }
    if inputs.skeleton.is_none() && run_skeleton.is_none() {
        return Err(err(format!(
            "{} has no skeleton.json (trained by an older zoo): pass --skeleton FILE.bvh, a clip of the training \
             skeleton, so the model file carries joint names, rest offsets and the frame rate",
            dir.display()
        )));
    }
    let (config, _) =
        crate::checkpoint::read_meta(dir).map_err(|e| err(format!("exporting {}: {e}", dir.display())))?;
    if let (Some(path), Some(parents)) = (inputs.skeleton, &options.parents)
        && !config.parents.is_empty()
        && &config.parents != parents
    {
        return Err(err(format!(
            "--skeleton {}: its hierarchy ({} joints, parents {:?}) is not the one the model in {} was trained on \
             ({} joints, parents {:?}); pass a clip of the training skeleton",
            path.display(),
            parents.len(),
            parents,
            dir.display(),
            config.joints,
            config.parents
        )));
    }
    if options.frame.is_none() && run_skeleton.is_none() {
        options.frame = Some(CoordinateFrame::ZOO_CM);
    }
    export_rtn_dir(dir, &options)
}

/// Loads a `zoo train rtn` run folder (`config.json`, `model.safetensors`,
/// `normalization.json`, and `skeleton.json` for what `options` leave out) and exports it (see
/// [`export_rtn`]).
pub fn export_rtn_dir(dir: &Path, options: &RtnExportOptions) -> Result<OnnxModel, ExportError> {
    let run_skeleton = RunSkeleton::read(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let options = match run_skeleton {
        Some(s) => options.clone().or(RtnExportOptions::from_run_skeleton(&s)),
        None => options.clone(),
    };
    let options = &options;
    let (config, stats) =
        crate::checkpoint::read_meta(dir).map_err(|e| ExportError::model(format!("{}: {e}", dir.display())))?;
    let config_json = zoo_nn::export::config_text(dir)?;
    let varmap = zoo_nn::export::load_run_varmap(dir, "RTN", |vb| crate::Rtn::new(&config, vb))?;
    export_rtn(&config, Some(&config_json), &stats, &varmap, options)
}

/// Leaky ReLU of `slope` after a layer of [`zoo_nn::export::mlp`] (node `LAYER.act`).
fn leaky(slope: f32) -> impl Fn(&mut GraphBuilder, &str, &Value) -> Value {
    move |g, layer, h| g.leaky_relu(&format!("{layer}.act"), h, slope)
}

fn batch(n: usize) -> [Dim; 2] {
    [Dim::batch(), Dim::Fixed(n)]
}

fn mean_std(m: &MeanStd) -> MotionMeanStd {
    MotionMeanStd { mean: m.mean.clone(), std: m.std.clone() }
}

/// The `zoo.transition` section of an exported RTN: how the runtime drives it.
pub fn transition_task(config: &Config) -> TransitionTask {
    TransitionTask {
        past_frames: config.past_frames,
        transition_frames: config.transition_frames,
        target_blend: config.target_blend,
        frame_dim: config.dim(),
        offset_input: config.future_conditioning,
        terrain: config
            .terrain
            .then_some(TransitionTerrain { side: config.terrain_side, extent: config.terrain_extent }),
        fallback: config.fallback.map(|f| TransitionFallback { start: f.start, full: f.full }),
        time_to_arrival: config.time_to_arrival,
        fallback_lengths: config.fallback_lengths.clone(),
    }
}

/// The metadata of an exported RTN (format of `zoo_format`), checked like the
/// runtime checks it on load.
pub fn metadata(
    config: &Config,
    config_json: &str,
    stats: &FeatureStats,
    options: &RtnExportOptions,
) -> Result<MotionModelMetadata, ExportError> {
    let k = config.joints;
    let d = config.dim();
    let parents = match (&options.parents, config.parents.is_empty()) {
        (Some(p), _) => p.clone(),
        (None, false) => config.parents.clone(),
        (None, true) => {
            return Err(ExportError::model(
                "the config has no skeleton parents: pass them as an export option (e.g. --skeleton FILE.bvh)",
            ));
        }
    };
    let missing = |what: &str| {
        ExportError::model(format!(
            "the skeleton's {what} is required in the model file: pass --skeleton FILE.bvh (a clip of the \
             training skeleton) to `zoo export`; run folders trained by this zoo keep it in skeleton.json"
        ))
    };
    let names = options.names.clone().ok_or_else(|| missing("joint names"))?;
    let offsets = options.offsets.clone().ok_or_else(|| missing("rest offsets"))?;
    let frame = options.frame.ok_or_else(|| missing("unit and axes (CoordinateFrame)"))?;
    if parents.len() != k || names.len() != k || offsets.len() != k {
        return Err(ExportError::model(format!(
            "the model has {k} joints but the skeleton has {} parents, {} names and {} offsets",
            parents.len(),
            names.len(),
            offsets.len()
        )));
    }
    let fps = options.fps.ok_or_else(|| missing("frame rate"))?;
    if !(fps.is_finite() && fps > 0.0) {
        return Err(ExportError::model(format!("fps must be a positive number, got {fps}")));
    }
    let mut normalization = BTreeMap::new();
    normalization.insert("x".to_string(), mean_std(&stats.x));
    normalization.insert("velocity".to_string(), mean_std(&stats.velocity));
    normalization.insert("offset".to_string(), mean_std(&stats.offset));
    if let Some(t) = &stats.terrain {
        normalization.insert("terrain".to_string(), mean_std(t));
    }
    let segment = |name: &str, start, len| MotionFeatureSegment { name: name.to_string(), start, len };
    let pair = |input: &str, output: &str| MotionStatePair { input: input.to_string(), output: output.to_string() };
    let mut state = vec![pair("h", "h_next"), pair("c", "c_next")];
    if config.future_conditioning {
        state.push(pair("gate_bias", "gate_bias_next"));
    }
    let metadata = MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: MODEL_KIND.to_string(),
        task: MotionTask::Transition(transition_task(config)),
        config_json: config_json.to_string(),
        normalization,
        skeleton: MotionSkeletonInfo { names, parents, offsets: offsets.iter().map(|o| o.map(f64::from)).collect() },
        feature_layout: vec![segment("root_velocity", 0, 3), segment("joint_positions_root_relative", 3, d - 3)],
        fps,
        frame,
        state,
        weights: zoo_format::WeightWidth::F32,
    };
    metadata.check().map_err(|e| ExportError::model(format!("the metadata would not load: {e}")))?;
    Ok(metadata)
}

/// Exports an RTN from its configuration, statistics and weights (a VarMap filled by
/// [`crate::Rtn::new`]). `config_json`: the run folder's `config.json` verbatim, kept as the
/// informational `zoo.config` (default: the config serialized). Errors on a terrain-aware model mismatch, a missing weight or skeleton.
pub fn export_rtn(
    config: &Config,
    config_json: Option<&str>,
    stats: &FeatureStats,
    varmap: &VarMap,
    options: &RtnExportOptions,
) -> Result<OnnxModel, ExportError> {
    if stats.joints != config.joints {
        return Err(ExportError::model(format!(
            "the statistics are for {} joints, the model for {}",
            stats.joints, config.joints
        )));
    }
    if config.terrain && stats.terrain.is_none() {
        return Err(ExportError::model("a terrain-aware RTN needs terrain statistics in normalization.json"));
    }
    let w = Weights::from_varmap(varmap)?;
    let config_json = zoo_nn::export::config_json(config_json, config)?;
    let config_json = config_json.as_ref();
    let start = start_graph(config, &w)?;
    let mut g = step_graph(config, &w)?;
    g.doc("Recurrent Transition Network (Harvey & Pal 2018), per-frame step graph; see zoo_rtn::export");
    for (k, v) in metadata(config, config_json, stats, options)?.to_props() {
        g.metadata(&k, &v);
    }
    if let Some(start) = start {
        g.metadata(keys::START_GRAPH, &start.to_base64());
    }
    g.finish()
}

/// The per-frame step graph (RTN eq. 2, 4-13).
fn step_graph(config: &Config, w: &Weights) -> Result<GraphBuilder, ExportError> {
    let d = config.dim();
    let hu = config.lstm;
    let slope = config.leaky_slope as f32;
    let mut g = GraphBuilder::new("rtn_step");
    let x = g.input("x", &batch(d));
    let offset = config.future_conditioning.then(|| g.input("offset", &batch(d)));
    let terrain = config.terrain.then(|| g.input("terrain", &batch(config.terrain_dim())));
    let base = config.interp_residual.then(|| g.input("base", &batch(d)));
    let tta = config.time_to_arrival.map(|z| g.input("tta", &batch(z.dims)));
    let h = g.input("h", &batch(hu));
    let c = g.input("c", &batch(hu));
    let gate_bias = config.future_conditioning.then(|| g.input("gate_bias", &batch(4 * hu)));

    // RTN eq. 2: h_E = E([x_t, p_t]), with the interpolation frame and the time to arrival:
    // E([x_t, p_t, b_(t+1), z_tta])
    let parts: Vec<&Value> = [Some(&x), terrain.as_ref(), base.as_ref(), tta.as_ref()].into_iter().flatten().collect();
    let e_in = if parts.len() == 1 { x.clone() } else { g.concat("frame_encoder.input", &parts, 1) };
    let he = zoo_nn::export::mlp(&mut g, w, ("frame_encoder", config.frame_encoder.len()), &e_in, true, leaky(slope))?;
    // RTN eq. 5-8: z = W h_E + U h_(t-1) + C_O h_O + (C_F h_F + b)
    let w_ih = w.init(&mut g, "lstm.weight_ih")?;
    let w_hh = w.init(&mut g, "lstm.weight_hh")?;
    let mut z = g.gemm("lstm.input_gates", &he, &w_ih, None, true);
    let zh = g.gemm("lstm.hidden_gates", &h, &w_hh, None, true);
    z = g.add("lstm.gates_ih_hh", &z, &zh);
    z = match (&offset, &gate_bias) {
        (Some(off), Some(gb)) => {
            // RTN eq. 4: h_O = O(o_t)
            let ho = zoo_nn::export::mlp(
                &mut g,
                w,
                ("offset_encoder", config.offset_encoder.len()),
                off,
                true,
                leaky(slope),
            )?;
            let w_o = w.init(&mut g, "lstm.weight_offset")?;
            let zo = g.gemm("lstm.offset_gates", &ho, &w_o, Some(gb), true);
            g.add("lstm.gates", &z, &zo)
        }
        _ => {
            let b = w.init(&mut g, "lstm.bias")?;
            g.add("lstm.gates", &z, &b)
        }
    };
    // Gate blocks in candle's order i, f, g, o.
    let parts = g.split("lstm.split", &z, &[hu; 4], 1);
    let i = g.sigmoid("lstm.i", &parts[0]);
    let f = g.sigmoid("lstm.f", &parts[1]);
    let gg = g.tanh("lstm.g", &parts[2]);
    let o = g.sigmoid("lstm.o", &parts[3]);
    // RTN eq. 9-11
    let fc = g.mul("lstm.f_c", &f, &c);
    let ig = g.mul("lstm.i_g", &i, &gg);
    let c_next = g.add("lstm.c", &fc, &ig);
    let tc = g.tanh("lstm.tanh_c", &c_next);
    let h_next = g.mul("lstm.h", &o, &tc);
    // RTN eq. 12-13
    let dx = zoo_nn::export::mlp(&mut g, w, ("decoder", config.decoder.len() + 1), &h_next, false, leaky(slope))?;
    let x_next = match &base {
        // x_(t+1) = b_(t+1) + D(h_t) (Config::interp_residual)
        Some(b) => g.add("interpolation_residual", b, &dx),
        None if config.residual => g.add("residual", &x, &dx),
        None => dx,
    };
    g.output("x_next", &x_next, &batch(d));
    g.output("h_next", &h_next, &batch(hu));
    g.output("c_next", &c_next, &batch(hu));
    if let Some(gb) = &gate_bias {
        g.output("gate_bias_next", gb, &batch(4 * hu));
    }
    Ok(g)
}

/// The transition-start graph (RTN eq. 3 and 14), or `None` when nothing is to compute.
fn start_graph(config: &Config, w: &Weights) -> Result<Option<OnnxModel>, ExportError> {
    let d = config.dim();
    let hu = config.lstm;
    let slope = config.leaky_slope as f32;
    if !config.future_conditioning && config.init_state == InitState::Zero {
        return Ok(None);
    }
    let mut g = GraphBuilder::new("rtn_start");
    g.doc("Recurrent Transition Network, transition-start graph: target encoding and initial state");
    if config.future_conditioning {
        let target = g.input("target", &batch(2 * d));
        // RTN eq. 3: h_F = F(t); the gates' per-sequence term C_F h_F + b
        let hf = zoo_nn::export::mlp(
            &mut g,
            w,
            ("target_encoder", config.target_encoder.len()),
            &target,
            true,
            leaky(slope),
        )?;
        let wt = w.init(&mut g, "lstm.weight_target")?;
        let b = w.init(&mut g, "lstm.bias")?;
        let gb = g.gemm("lstm.target_gates", &hf, &wt, Some(&b), true);
        g.output("gate_bias", &gb, &batch(4 * hu));
    }
    match config.init_state {
        InitState::Zero => {}
        InitState::Learned => {
            let x0 = g.input("x0", &batch(d));
            // RTN eq. 14: (h_0, c_0) = H(x_0), one hidden layer, linear output
            let hc = zoo_nn::export::mlp(&mut g, w, ("state_init", 2), &x0, false, leaky(slope))?;
            let parts = g.split("state_init.split", &hc, &[hu, hu], 1);
            g.output("h", &parts[0], &batch(hu));
            g.output("c", &parts[1], &batch(hu));
        }
        InitState::Common => {
            // One learned (h, c) for every sequence, broadcast to the batch: x0[:, :1] * 0 + h.
            let x0 = g.input("x0", &batch(d));
            let col = g.slice("state_init.batch_column", &x0, &[1], &[0], &[1]);
            let zero = g.initializer_f32("state_init.zero", &[1], &[0.0]);
            let zeros = g.mul("state_init.batch_zeros", &col, &zero);
            for s in ["h", "c"] {
                let v = w.init(&mut g, &format!("state_init.{s}"))?;
                let out = g.add(&format!("state_init.{s}.broadcast"), &zeros, &v);
                g.output(s, &out, &batch(hu));
            }
        }
    }
    Ok(Some(g.finish()?))
}

/// The config and candle weights of an exported RTN, read back from the file's initializers
/// (step graph and the embedded start graph), keyed by their candle variable paths: the
/// inverse of [`export_rtn`] for the weights, so candle can run exactly the exported model
/// (`zoo bench runtime`). Initializers that are not model weights (constants the graphs
/// need) are left out.
pub fn import_rtn(bytes: &[u8]) -> Result<(Config, HashMap<String, candle_core::Tensor>), ExportError> {
    let step = OnnxModel::from_bytes(bytes, "the file")?;
    match step.metadata_value(keys::MODEL_KIND) {
        Some(MODEL_KIND) => {}
        other => {
            return Err(ExportError::model(format!(
                "not an RTN export ({} = {other:?}); write one with `zoo export --onnx RUN_DIR --out FILE.onnx`",
                keys::MODEL_KIND
            )));
        }
    }
    let config_json = step
        .metadata_value(keys::CONFIG)
        .ok_or_else(|| ExportError::model(format!("the file has no {}", keys::CONFIG)))?;
    let config: Config = serde_json::from_str(config_json)
        .map_err(|e| ExportError::model(format!("{} is not an RTN config: {e}", keys::CONFIG)))?;
    let mut graphs = vec![step.proto().graph.clone()];
    if let Some(encoded) = step.metadata_value(keys::START_GRAPH) {
        graphs.push(OnnxModel::from_base64(encoded, keys::START_GRAPH)?.proto().graph.clone());
    }
    // The variable paths candle expects, with their shapes.
    let varmap = VarMap::new();
    crate::Rtn::new(
        &config,
        candle_nn::VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &candle_core::Device::Cpu),
    )
    .map_err(|e| ExportError::model(format!("building the RTN of {}: {e}", keys::CONFIG)))?;
    let wanted: HashMap<String, Vec<usize>> = varmap
        .data()
        .lock()
        .map_err(|_| ExportError::model("the VarMap lock is poisoned"))?
        .iter()
        .map(|(n, v)| (n.clone(), v.dims().to_vec()))
        .collect();
    // The weights at whatever width the file stores them (`zoo export --weights`), widened.
    let mut weights = HashMap::new();
    for graph in graphs.iter().flatten() {
        for (name, (_, data)) in zoo_export::weight_values(graph)? {
            let Some(dims) = wanted.get(&name) else { continue };
            if weights.contains_key(&name) {
                continue;
            }
            let n: usize = dims.iter().product();
            if data.len() != n {
                return Err(ExportError::model(format!(
                    "initializer `{name}` has {} values, the RTN needs {n}",
                    data.len()
                )));
            }
            let t = candle_core::Tensor::from_vec(data, dims.as_slice(), &candle_core::Device::Cpu)
                .map_err(|e| ExportError::model(e.to_string()))?;
            weights.insert(name, t);
        }
    }
    if let Some(missing) = wanted.keys().find(|k| !weights.contains_key(*k)) {
        return Err(ExportError::model(format!("the file has no initializer `{missing}` of the RTN")));
    }
    Ok((config, weights))
}
