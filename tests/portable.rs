//! The portable profile (`zoo export --portable`, `zoo_export::portable`): every exported model
//! kind (RTN step and start graphs, RMR with each refiner cell, ARNN, RNN-GMM generator and
//! refiner) lowers to operators of Unity Inference Engine 2.3's supported list only, and the
//! portable graphs compute what the regular ones compute.
//!
//! Where the expected numbers come from: the regular export of the same model, run on the same
//! inputs (fixed LCG draws for every graph input, batch 3) in tract and in onnxruntime (through
//! `ort`, `load-dynamic`). Each portable graph must match its regular graph within 1e-4 in
//! both runtimes, on every output; the regular graphs' own tract-onnxruntime agreement is the
//! reference for what float rounding gives (the figures are printed). The operator check uses
//! the list as data (`zoo_export::unity::UNITY_SUPPORTED_OPS`), not `check_portable`.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use std::borrow::Cow;
use std::collections::HashMap;
use zoo_export::portable::{EmbeddedGraph, PORTABLE_OPSET, PortableOptions, check_portable, op_types, to_portable};
use zoo_export::unity::{UNITY_SUPPORTED_OPS, UNITY_VERSION};
use zoo_export::{Dim, GraphBuilder, OnnxModel, RnnDirection, RnnInputs, pb};
use zoo_runtime::portable::PORTABLE_GRAPHS;
use zoo_tests::onnxruntime::ort_environment;
use zoo_tests::toy_onnx::lcg;

const BATCH: usize = 3;
/// The fixed window of the RMR graphs.
const FRAMES: usize = 12;
const TOLERANCE: f32 = 1e-4;

fn embedded() -> Vec<EmbeddedGraph<'static>> {
    PORTABLE_GRAPHS.iter().map(|g| EmbeddedGraph { key: g.key, file_key: g.file_key, suffix: g.suffix }).collect()
}

fn frames_fixed() -> PortableOptions {
    let mut o = PortableOptions::default();
    o.fixed_dims.insert("frames".into(), FRAMES);
    o
}

/// Input name, shape and values of every graph input: `batch` is [`BATCH`], `frames` [`FRAMES`].
type Inputs = Vec<(String, Vec<usize>, Vec<f32>)>;

fn inputs_of(model: &OnnxModel, seed: u64) -> Inputs {
    use pb::tensor_shape_proto::dimension::Value as D;
    let graph = model.proto().graph.as_ref().unwrap();
    graph
        .input
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let Some(pb::type_proto::Value::TensorType(t)) = v.r#type.as_ref().and_then(|t| t.value.as_ref()) else {
                panic!("input {} has no tensor type", v.name)
            };
            let shape: Vec<usize> = t
                .shape
                .as_ref()
                .unwrap()
                .dim
                .iter()
                .map(|d| match &d.value {
                    Some(D::DimValue(n)) => *n as usize,
                    Some(D::DimParam(p)) if p == "batch" => BATCH,
                    Some(D::DimParam(p)) if p == "frames" => FRAMES,
                    other => panic!("input {}: dimension {other:?}", v.name),
                })
                .collect();
            let n = shape.iter().product();
            (v.name.clone(), shape, lcg(seed + i as u64, n, 1.0))
        })
        .collect()
}

fn output_names(model: &OnnxModel) -> Vec<String> {
    model.proto().graph.as_ref().unwrap().output.iter().map(|o| o.name.clone()).collect()
}

fn tract_run(model: &OnnxModel, inputs: &Inputs) -> Vec<Vec<f32>> {
    use tract_onnx::prelude::*;
    let mut m = tract_onnx::onnx().model_for_read(&mut model.to_bytes().as_slice()).expect("tract reads the graph");
    for (i, (_, shape, _)) in inputs.iter().enumerate() {
        m.set_input_fact(i, f32::fact(shape).into()).unwrap();
    }
    let plan = m.into_optimized().expect("tract optimises the graph").into_runnable().unwrap();
    let values: TVec<TValue> = inputs
        .iter()
        .map(|(_, shape, data)| {
            TValue::from_const(std::sync::Arc::new(Tensor::from_shape::<f32>(shape, data).unwrap()))
        })
        .collect();
    let out = plan.run(values).expect("tract runs the graph");
    out.iter().map(|t| t.try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec()).collect()
}

fn ort_run(model: &OnnxModel, inputs: &Inputs) -> Vec<Vec<f32>> {
    let mut session = ort::session::Session::builder(ort_environment())
        .unwrap()
        .with_intra_threads(1)
        .unwrap()
        .commit_from_memory(&model.to_bytes())
        .expect("onnxruntime loads the graph");
    let values: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = inputs
        .iter()
        .map(|(name, shape, data)| {
            let shape: Vec<i64> = shape.iter().map(|&d| d as i64).collect();
            let t = ort::value::Tensor::from_array((shape, data.clone())).unwrap();
            (Cow::Owned(name.clone()), t.into())
        })
        .collect();
    let out = session.run(values).expect("onnxruntime runs the graph");
    output_names(model)
        .iter()
        .map(|n| out[n.as_str()].try_extract_tensor::<f32>().expect("f32 output").1.to_vec())
        .collect()
}

fn worst(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            assert_eq!(x.len(), y.len());
            x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0, f32::max)
        })
        .fold(0.0, f32::max)
}

/// Every node of `model` uses an operator of the Inference Engine list, on every backend; the
/// opset is the portable one.
fn assert_listed(what: &str, model: &OnnxModel) {
    let ops = op_types(model);
    for op in &ops {
        let row = UNITY_SUPPORTED_OPS.iter().find(|o| o.name == op);
        assert!(
            row.is_some_and(|r| r.float_on_every_backend()),
            "{what}: `{op}` is not in Unity Inference Engine {UNITY_VERSION}'s list for every backend"
        );
    }
    assert_eq!(model.proto().opset_import.len(), 1, "{what}");
    assert_eq!(model.proto().opset_import[0].version, PORTABLE_OPSET, "{what}");
    eprintln!("{what}: {} nodes, operators {ops:?}", model.summary().op_counts.values().sum::<usize>());
}

/// Lowers `model`, checks each graph's operators, and runs each portable graph against its
/// regular graph in tract and onnxruntime.
fn check_kind(what: &str, model: &OnnxModel, options: &PortableOptions) -> zoo_export::PortableModel {
    let portable = to_portable(model, options, &embedded()).unwrap_or_else(|e| panic!("{what}: {e}"));
    let mut pairs = vec![(format!("{what} main"), model.clone(), portable.main.clone())];
    for c in &portable.companions {
        let regular = OnnxModel::from_base64(model.metadata_value(&c.key).unwrap(), &c.key).unwrap();
        pairs.push((format!("{what} {}", c.suffix), regular, c.model.clone()));
    }
    for (name, regular, lowered) in &pairs {
        // For checks with other tools (e.g. the onnx package's checker): ZOO_PORTABLE_DUMP=DIR
        // keeps every regular and portable graph there.
        if let Some(dir) = std::env::var_os("ZOO_PORTABLE_DUMP") {
            let file = name.replace(' ', "_");
            regular.write(&std::path::Path::new(&dir).join(format!("{file}.regular.onnx"))).unwrap();
            lowered.write(&std::path::Path::new(&dir).join(format!("{file}.portable.onnx"))).unwrap();
        }
        assert_listed(name, lowered);
        check_portable(lowered).unwrap();
        let inputs = inputs_of(regular, 41);
        assert_eq!(inputs_of(lowered, 41), inputs, "{name}: the portable graph takes the same inputs");
        assert_eq!(output_names(lowered), output_names(regular), "{name}: same outputs");
        let (tr, tp) = (tract_run(regular, &inputs), tract_run(lowered, &inputs));
        let (or, op) = (ort_run(regular, &inputs), ort_run(lowered, &inputs));
        let (t, o, reference, cross) = (worst(&tr, &tp), worst(&or, &op), worst(&tr, &or), worst(&tp, &op));
        eprintln!(
            "{name}: portable vs regular: tract {t:e}, onnxruntime {o:e}; tract vs onnxruntime: regular {reference:e}, portable {cross:e}"
        );
        assert!(t <= TOLERANCE && o <= TOLERANCE && cross <= TOLERANCE, "{name}: {t:e} {o:e} {cross:e}");
    }
    portable
}

#[test]
fn rtn_step_and_start_graphs_are_portable_and_match() {
    let model = zoo_tests::tiny_rtn_onnx();
    let portable = check_kind("RTN", &model, &PortableOptions::default());
    assert_eq!(portable.companions.len(), 1, "the start graph is a file of its own");
    assert!(portable.main.metadata_value(zoo_runtime::metadata::keys::START_GRAPH).is_none());
}

fn rmr(cell: zoo_rmr::RefinerCell) -> OnnxModel {
    let config = zoo_rmr::Config::tiny().with_cell(cell);
    let varmap = VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let stats = zoo_rmr::features::FeatureStats { mean: lcg(3, d, 1.0), std: vec![1.5; d] };
    zoo_rmr::export::export_rmr(&config, &stats, &varmap).unwrap()
}

#[test]
fn rmr_with_every_cell_is_portable_and_matches() {
    use zoo_rmr::RefinerCell;
    for cell in [RefinerCell::Lstm, RefinerCell::Gru, RefinerCell::Blstm, RefinerCell::Bgru] {
        let model = rmr(cell);
        let regular_ops = op_types(&model);
        assert!(regular_ops.contains("LSTM") || regular_ops.contains("GRU"), "{regular_ops:?}");
        check_kind(&format!("RMR {cell:?}"), &model, &frames_fixed());
    }
}

#[test]
fn a_window_graph_of_symbolic_length_is_refused_with_the_dimension_to_fix() {
    let err = to_portable(&rmr(zoo_rmr::RefinerCell::Bgru), &PortableOptions::default(), &embedded())
        .unwrap_err()
        .to_string();
    assert!(err.contains("frames") && err.contains("--frames N") && err.contains("refiner.l0"), "{err}");
}

#[test]
fn arnn_is_portable_and_matches() {
    let config = zoo_arnn::ArnnConfig::tiny();
    let varmap = VarMap::new();
    zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dofs;
    let norm = zoo_arnn::Normalization { mean: vec![0.1; d], std: vec![0.5; d] };
    let model = zoo_arnn::export::export_arnn(&config, &norm, &varmap).unwrap();
    check_kind("ARNN", &model, &PortableOptions::default());
}

#[test]
fn rnngmm_generator_and_refiner_are_portable_and_match() {
    use zoo_rnngmm::prelude::*;
    let (config, _, trainer) = zoo_tests::rnngmm_fixture(Config::tiny());
    let generator =
        zoo_rnngmm::export::export_generator(&config, None, trainer.spec(), trainer.norm(), trainer.varmap()).unwrap();
    // The refiner's step graph from seeded weights of its shapes (`refiner.safetensors` names).
    let (d, e, fc, hu) = (config.dim, 12, config.refiner.refiner_fc, config.refiner.refiner_lstm);
    let shapes: [(&str, Vec<usize>); 8] = [
        ("fc1.weight", vec![fc, d + e]),
        ("fc1.bias", vec![fc]),
        ("lstm.weight_ih_l0", vec![4 * hu, fc]),
        ("lstm.weight_hh_l0", vec![4 * hu, hu]),
        ("lstm.bias_ih_l0", vec![4 * hu]),
        ("lstm.bias_hh_l0", vec![4 * hu]),
        ("fc2.weight", vec![d, hu]),
        ("fc2.bias", vec![d]),
    ];
    let tensors: HashMap<String, Tensor> = shapes
        .iter()
        .enumerate()
        .map(|(k, (name, dims))| {
            let n = dims.iter().product();
            (name.to_string(), Tensor::from_vec(lcg(900 + k as u64, n, 0.3), dims.as_slice(), &Device::Cpu).unwrap())
        })
        .collect();
    // Joint limits on every value between the root's first four and the contacts.
    let limits = zoo_rnngmm::JointLimits { first: 4, lo: vec![-0.5; d - 6], hi: vec![0.5; d - 6] };
    let eff =
        zoo_rnngmm::EffectorNorm { effectors: vec![1, 2], mean: vec![0.0; e], std: vec![1.0; e], limits: Some(limits) };
    let refiner = zoo_rnngmm::export::export_refiner(&config, &eff, &tensors).unwrap();
    let mut model = generator.clone();
    model.set_metadata(zoo_rnngmm::export::REFINER_GRAPH_KEY, &refiner.to_base64());
    let mut task: zoo_format::SynthesisTask =
        serde_json::from_str(model.metadata_value(zoo_format::keys::SYNTHESIS).unwrap()).unwrap();
    task.refiner = Some(zoo_format::SynthesisRefiner {
        effectors: eff.effectors.clone(),
        mean: eff.mean.clone(),
        std: eff.std.clone(),
    });
    model.set_metadata(zoo_format::keys::SYNTHESIS, &serde_json::to_string(&task).unwrap());
    let portable = check_kind("RNN-GMM", &model, &PortableOptions::default());
    assert_eq!(portable.companions.len(), 1, "the refiner is a file of its own");
    assert_eq!(portable.companions[0].suffix, "refiner");
}

/// Recurrent forms no zoo exporter writes today but the pass lowers: a reverse LSTM with
/// initial states and all three outputs, a GRU with `linear_before_reset = 0` and an initial
/// state, a plain RNN without biases. onnxruntime runs the regular graph as the reference
/// (tract ignores `direction`, DEPENDENCY-FACTS); the lowered graph must match it in both.
#[test]
fn other_recurrent_forms_lower_to_the_onnx_equations() {
    let (t, i, h) = (5, 3, 4);
    let mut g = GraphBuilder::new("recurrent_forms");
    let x = g.input("x", &[Dim::Fixed(t), Dim::batch(), Dim::Fixed(i)]);
    let h0 = g.input("h0", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(h)]);
    let c0 = g.input("c0", &[Dim::Fixed(1), Dim::batch(), Dim::Fixed(h)]);
    let mut seed = 0;
    let mut init = |g: &mut GraphBuilder, name: &str, dims: &[usize]| {
        seed += 1;
        g.initializer_f32(name, dims, &lcg(seed, dims.iter().product(), 0.5))
    };
    let (w, r, b) = (
        init(&mut g, "lstm.W", &[1, 4 * h, i]),
        init(&mut g, "lstm.R", &[1, 4 * h, h]),
        init(&mut g, "lstm.B", &[1, 8 * h]),
    );
    let forward = RnnDirection::Forward;
    let rnn = RnnInputs { x: &x, w: &w, r: &r, b: Some(&b), initial_h: Some(&h0), hidden_size: h, direction: forward };
    let lstm = g.lstm("lstm", &rnn, Some(&c0));
    let (w, r, b) = (
        init(&mut g, "gru.W", &[1, 3 * h, i]),
        init(&mut g, "gru.R", &[1, 3 * h, h]),
        init(&mut g, "gru.B", &[1, 6 * h]),
    );
    let rnn = RnnInputs { x: &x, w: &w, r: &r, b: Some(&b), initial_h: Some(&h0), hidden_size: h, direction: forward };
    let gru = g.gru("gru", &rnn, false);
    let (w, r) = (init(&mut g, "rnn.W", &[1, h, i]), init(&mut g, "rnn.R", &[1, h, h]));
    let plain = g.custom_op("RNN", "rnn", &[&x, &w, &r], vec![zoo_export::attr_int("hidden_size", h as i64)]);
    let seq = [Dim::Fixed(t), Dim::Fixed(1), Dim::batch(), Dim::Fixed(h)];
    let last = [Dim::Fixed(1), Dim::batch(), Dim::Fixed(h)];
    g.output("lstm_y", &lstm.y, &seq);
    g.output("lstm_y_h", &lstm.y_h, &last);
    g.output("lstm_y_c", lstm.y_c.as_ref().unwrap(), &last);
    g.output("gru_y", &gru.y, &seq);
    g.output("gru_y_h", &gru.y_h, &last);
    g.output("rnn_y", &plain, &seq);
    let mut proto = g.finish().unwrap().proto().clone();
    for n in proto.graph.as_mut().unwrap().node.iter_mut().filter(|n| n.name == "lstm") {
        n.attribute.iter_mut().find(|a| a.name == "direction").unwrap().s = b"reverse".to_vec();
    }
    let model = OnnxModel::from_proto(proto);
    let lowered = zoo_export::portable::lower(&model, &PortableOptions::default()).unwrap();
    assert_listed("recurrent forms", &lowered);
    let inputs = inputs_of(&model, 5);
    let reference = ort_run(&model, &inputs);
    let (o, t) = (worst(&reference, &ort_run(&lowered, &inputs)), worst(&reference, &tract_run(&lowered, &inputs)));
    eprintln!("recurrent forms: lowered vs onnxruntime's LSTM/GRU/RNN kernels: onnxruntime {o:e}, tract {t:e}");
    assert!(o <= 1e-5 && t <= 1e-5, "{o:e} {t:e}");
}

#[test]
fn an_operator_outside_the_list_is_refused_with_its_node() {
    let mut g = GraphBuilder::new("loop");
    let x = g.input("x", &[Dim::batch(), Dim::Fixed(2)]);
    let y = g.custom_op("Loop", "a_loop", &[&x], vec![]);
    g.output("y", &y, &[Dim::batch(), Dim::Fixed(2)]);
    let err = to_portable(&g.finish().unwrap(), &PortableOptions::default(), &embedded()).unwrap_err().to_string();
    assert!(
        err.contains("`a_loop`") && err.contains("`Loop` is not in the supported list") && err.contains("2.3.0"),
        "{err}"
    );
}

/// The runtime loads the pair of files `zoo export --portable` writes and runs the same
/// transition as from the regular file; without its start file the pair is refused.
#[test]
fn the_runtime_loads_the_portable_pair_like_the_regular_file() {
    use zoo_runtime::LoadedModel;
    let model = zoo_tests::tiny_rtn_onnx();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    let written = to_portable(&model, &PortableOptions::default(), &embedded()).unwrap().write(&path).unwrap();
    assert_eq!(written, vec![path.clone(), dir.path().join("rtn.start.onnx")]);
    let run = |loaded: LoadedModel| {
        let m = loaded.as_transition().unwrap().clone();
        let mut runner = m.runner().unwrap();
        let mut state = m.new_transition();
        let k = m.joints();
        let past = lcg(1, m.past_frames() * 3 * k, 50.0);
        let (target, next) = (lcg(2, 3 * k, 50.0), lcg(3, 3 * k, 50.0));
        runner.start(&mut state, &past, &target, &next).unwrap();
        let mut poses = Vec::new();
        for _ in 0..m.transition_frames() {
            let mut pose = vec![0.0; 3 * k];
            runner.step(&mut state, &mut pose).unwrap();
            poses.push(pose);
        }
        poses
    };
    let regular = run(LoadedModel::from_bytes(&model.to_bytes()).unwrap());
    let portable = run(zoo_runtime::portable::load(&path).unwrap());
    let d = worst(&regular, &portable);
    eprintln!("runtime transition, portable pair vs regular file: {d:e} cm");
    assert!(d <= 1e-4, "{d:e}");
    // A companion named by a path, not a bare file name beside the main file, is refused.
    let mut main = OnnxModel::from_bytes(&std::fs::read(&path).unwrap(), "main").unwrap();
    main.set_metadata(zoo_runtime::portable::START_GRAPH_FILE_KEY, "../rtn.start.onnx");
    main.write(&dir.path().join("moved.onnx")).unwrap();
    let err = zoo_runtime::portable::load(dir.path().join("moved.onnx")).unwrap_err().to_string();
    assert!(err.contains("not a bare file name"), "{err}");
    std::fs::remove_file(dir.path().join("rtn.start.onnx")).unwrap();
    let err = zoo_runtime::portable::load(&path).unwrap_err().to_string();
    assert!(err.contains("rtn.start.onnx") && err.contains("zoo export --portable"), "{err}");
}

fn zoo(args: &[&str]) -> (bool, String, String) {
    let out = std::process::Command::new(zoo_tests::zoo_bin()).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `zoo export --portable` on an RTN run folder (seeded tiny weights, the toy skeleton) writes
/// the step graph and `NAME.start.onnx`, both within the list; the runtime loads the pair.
/// `--frames` is refused for a per-frame model.
#[test]
fn cli_exports_an_rtn_run_folder_portably() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let skeleton = zoo_tests::toy_skeleton();
    let config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents);
    let varmap = VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let unit = || zoo_rtn::features::MeanStd { mean: vec![0.0; d], std: vec![10.0; d] };
    let stats = zoo_rtn::features::FeatureStats {
        joints: skeleton.len(),
        x: unit(),
        velocity: unit(),
        offset: unit(),
        terrain: None,
    };
    zoo_rtn::checkpoint::save(&run, &config, &varmap, &stats).unwrap();
    zoo_nn::checkpoint::RunSkeleton::new(&skeleton, 30.0, zoo_motion::frame::CoordinateFrame::ZOO_CM)
        .write(&run)
        .unwrap();
    let out = dir.path().join("rtn.onnx");
    let (r, o) = (run.to_str().unwrap(), out.to_str().unwrap());
    let (ok, stdout, stderr) = zoo(&["export", "--onnx", r, "--out", o, "--portable", "--frames", "10"]);
    assert!(!ok && stderr.contains("--frames applies to window graphs"), "{stdout}\n{stderr}");
    assert!(!out.exists(), "a refused export wrote its file");
    let (ok, stdout, stderr) = zoo(&["export", "--onnx", r, "--out", o, "--portable"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("portable (Unity Inference Engine 2.3.0 operators, opset 15)")
            && stdout.contains("rtn.start.onnx"),
        "{stdout}"
    );
    let main = OnnxModel::from_bytes(&std::fs::read(&out).unwrap(), "main").unwrap();
    let start = OnnxModel::from_bytes(&std::fs::read(dir.path().join("rtn.start.onnx")).unwrap(), "start").unwrap();
    assert_listed("zoo export --portable rtn.onnx", &main);
    assert_listed("zoo export --portable rtn.start.onnx", &start);
    assert_eq!(main.metadata_value(zoo_runtime::portable::START_GRAPH_FILE_KEY), Some("rtn.start.onnx"));
    assert!(main.metadata_value(zoo_runtime::portable::PORTABLE_KEY).unwrap().contains("\"opset\":15"));
    let loaded = zoo_runtime::portable::load(&out).unwrap();
    assert_eq!(loaded.kind(), "rtn");
}

/// `zoo export --portable` on an RMR run folder fixes the window to the model's runtime
/// window and unrolls the refiner; `--frames N` picks another length.
#[test]
fn cli_exports_an_rmr_run_folder_portably_over_a_fixed_window() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let config = zoo_rmr::Config::tiny();
    let varmap = VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let stats = zoo_rmr::features::FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    zoo_rmr::checkpoint::save(&run, &config, &varmap, &stats).unwrap();
    let out = dir.path().join("rmr.onnx");
    let (r, o) = (run.to_str().unwrap(), out.to_str().unwrap());
    let (ok, stdout, stderr) = zoo(&["export", "--onnx", r, "--out", o, "--portable"]);
    assert!(ok, "{stdout}\n{stderr}");
    let window = config.window.to_string();
    assert!(stdout.contains(&format!("`frames` dimension to {window} (the model's runtime window")), "{stdout}");
    let main = OnnxModel::from_bytes(&std::fs::read(&out).unwrap(), "main").unwrap();
    assert_listed("zoo export --portable rmr.onnx", &main);
    assert!(main.summary().inputs[0].starts_with(&format!("x: [{window}, batch")), "{:?}", main.summary().inputs);
    let (ok, stdout, stderr) = zoo(&["export", "--onnx", r, "--out", o, "--portable", "--frames", "7"]);
    assert!(ok && stdout.contains("to 7 (--frames)"), "{stdout}\n{stderr}");
    let main = OnnxModel::from_bytes(&std::fs::read(&out).unwrap(), "main").unwrap();
    assert!(main.summary().inputs[0].starts_with("x: [7, batch"), "{:?}", main.summary().inputs);
}

/// The paper-size RMR (2-layer BGRU of 256 units) over its 60-frame runtime window: the size of
/// the unrolled graph, and parity with the regular graph at that size.
#[test]
#[ignore = "paper-size RMR: about a minute in a debug build; run with --ignored"]
fn paper_size_rmr_lowers_and_matches() {
    let config = zoo_rmr::Config::paper();
    let varmap = VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let stats = zoo_rmr::features::FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let model = zoo_rmr::export::export_rmr(&config, &stats, &varmap).unwrap();
    let mut options = PortableOptions::default();
    options.fixed_dims.insert("frames".into(), config.window);
    let start = std::time::Instant::now();
    let portable = to_portable(&model, &options, &embedded()).unwrap();
    let nodes = portable.main.summary().op_counts.values().sum::<usize>();
    eprintln!(
        "paper RMR over {} frames: {nodes} nodes, lowered in {:.2} s (debug build), {} MB",
        config.window,
        start.elapsed().as_secs_f64(),
        portable.main.to_bytes().len() / 1_000_000
    );
    assert_listed("paper RMR", &portable.main);
    let inputs: Inputs = inputs_of(&portable.main, 41);
    let (or, op, tp) = (ort_run(&model, &inputs), ort_run(&portable.main, &inputs), tract_run(&portable.main, &inputs));
    let (o, t) = (worst(&or, &op), worst(&or, &tp));
    eprintln!("paper RMR: portable vs regular (onnxruntime): onnxruntime {o:e}, tract {t:e}");
    assert!(o <= TOLERANCE && t <= TOLERANCE, "{o:e} {t:e}");
}
