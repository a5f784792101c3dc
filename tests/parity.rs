//! Parity of exported step graphs: a plain-Rust reference, tract (through `zoo-runtime`) and
//! onnxruntime (through `ort`, `load-dynamic`) run the same 30-frame autoregressive loop.
//!
//! Where the expected numbers come from: the reference is `zoo_tests::toy_onnx::ToyModel::step`,
//! written from the PyTorch LSTM/GRU equations with f64 accumulation; the toy's weights are
//! fixed LCG draws. Every pair of implementations must agree within 1e-4 on every frame.
//! The snapshots hold the reference outputs rounded to 4 decimals and the graph summaries.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` provisions `.onnxruntime/libonnxruntime.so.1.31.1`
//! (or set `ORT_DYLIB_PATH`). A missing library fails these tests; they do not skip.

use zoo_export::OnnxModel;
use zoo_runtime::{MotionModel, MotionState};
use zoo_tests::onnxruntime::OrtSession;
use zoo_tests::toy_onnx::{Cell, ToyModel, lcg, ops_graph, ops_reference};

const FRAMES: usize = 30;
const BATCH: usize = 3;
const TOLERANCE: f32 = 1e-4;

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Frames of every character over the loop, `[frame][character * width + k]`.
type Trace = Vec<Vec<f32>>;

fn initial_frames(toy: &ToyModel) -> Vec<f32> {
    lcg(99, BATCH * toy.frame, 1.0)
}

fn reference_loop(toy: &ToyModel, start: bool) -> Trace {
    let x0 = initial_frames(toy);
    let mut per_char: Vec<(Vec<f32>, Vec<Vec<f32>>)> = (0..BATCH)
        .map(|c| {
            let x = x0[c * toy.frame..(c + 1) * toy.frame].to_vec();
            let state =
                if start { toy.start_state(&x) } else { toy.state_widths().iter().map(|&w| vec![0.0; w]).collect() };
            (x, state)
        })
        .collect();
    (0..FRAMES)
        .map(|_| {
            let mut frame = Vec::with_capacity(BATCH * toy.frame);
            for (x, state) in &mut per_char {
                *x = toy.step(x, state);
                frame.extend_from_slice(x);
            }
            frame
        })
        .collect()
}

fn tract_loop(toy: &ToyModel, model: &OnnxModel) -> (Trace, Trace) {
    let model = MotionModel::from_bytes(&model.to_bytes()).expect("zoo-runtime loads the exported model");
    let mut runner = model.runner().unwrap();
    let mut states: Vec<MotionState> = (0..BATCH).map(|_| model.new_state()).collect();
    let mut x = initial_frames(toy);
    let start_inputs: Vec<&[f32]> = if model.has_start_graph() { vec![&x] } else { vec![] };
    runner.start_batch(&mut states, &start_inputs).unwrap();
    let mut y = vec![0.0; x.len()];
    let mut batched = Vec::new();
    for _ in 0..FRAMES {
        runner.step_batch(&mut states, &[&x], &mut [&mut y]).unwrap();
        std::mem::swap(&mut x, &mut y);
        batched.push(x.clone());
    }
    // The batch-1 plan, one character after the other.
    let x0 = initial_frames(toy);
    let mut singles = vec![Vec::new(); FRAMES];
    for c in 0..BATCH {
        let mut state = model.new_state();
        let mut x = x0[c * toy.frame..(c + 1) * toy.frame].to_vec();
        let start_inputs: Vec<&[f32]> = if model.has_start_graph() { vec![&x] } else { vec![] };
        runner.start(&mut state, &start_inputs).unwrap();
        let mut y = vec![0.0; toy.frame];
        for frame in singles.iter_mut() {
            runner.step(&mut state, &[&x], &mut [&mut y]).unwrap();
            std::mem::swap(&mut x, &mut y);
            frame.extend_from_slice(&x);
        }
    }
    (batched, singles)
}

fn ort_loop(toy: &ToyModel, model: &OnnxModel, start: bool) -> Trace {
    let mut session = OrtSession::new(model);
    let version = zoo_runtime::FORMAT_VERSION.to_string();
    assert_eq!(session.metadata("zoo.format_version"), Some(version), "metadata_props reach onnxruntime");
    let mut x = initial_frames(toy);
    let mut states: Vec<Vec<f32>> = toy.state_widths().iter().map(|&w| vec![0.0; BATCH * w]).collect();
    let (state_in, state_out): (&[&str], &[&str]) = match toy.cell {
        Cell::Lstm => (&["h", "c"], &["h_next", "c_next"]),
        Cell::Gru => (&["h"], &["h_next"]),
    };
    if start {
        // The start graph as an engine would read it: decoded from the step file's metadata.
        use base64::Engine;
        let encoded = session.metadata(zoo_runtime::metadata::keys::START_GRAPH).expect("embedded start graph");
        let bytes = base64::engine::general_purpose::STANDARD.decode(encoded).unwrap();
        let start_graph = zoo_export::OnnxModel::from_proto(prost::Message::decode(bytes.as_slice()).unwrap());
        states = OrtSession::new(&start_graph).run(&[("x0", BATCH, &x)], state_in);
    }
    let mut trace = Vec::new();
    for _ in 0..FRAMES {
        let mut inputs = vec![("x", BATCH, x.as_slice())];
        inputs.extend(state_in.iter().zip(&states).map(|(n, s)| (*n, BATCH, s.as_slice())));
        let mut out_names = vec!["y"];
        out_names.extend_from_slice(state_out);
        let mut out = session.run(&inputs, &out_names).into_iter();
        x = out.next().unwrap();
        states = out.collect();
        trace.push(x.clone());
    }
    trace
}

fn trace_diff(a: &Trace, b: &Trace) -> f32 {
    a.iter().zip(b).map(|(a, b)| max_abs_diff(a, b)).fold(0.0, f32::max)
}

/// Reference outputs of character `c` on every 5th frame, rounded to 4 decimals.
fn rounded(trace: &Trace, frame: usize) -> Vec<Vec<Vec<f64>>> {
    (0..BATCH)
        .map(|c| {
            (0..FRAMES)
                .step_by(5)
                .chain([FRAMES - 1])
                .map(|f| trace[f][c * frame..(c + 1) * frame].iter().map(|v| (*v as f64 * 1e4).round() / 1e4).collect())
                .collect()
        })
        .collect()
}

fn check_parity(name: &str, toy: &ToyModel, model: &OnnxModel) {
    let start = model.proto().metadata_props.iter().any(|p| p.key == zoo_runtime::metadata::keys::START_GRAPH);
    let reference = reference_loop(toy, start);
    let (tract_batched, tract_single) = tract_loop(toy, model);
    let ort = ort_loop(toy, model, start);
    let pairs = [
        ("reference-tract", trace_diff(&reference, &tract_batched)),
        ("reference-tract_batch1", trace_diff(&reference, &tract_single)),
        ("reference-onnxruntime", trace_diff(&reference, &ort)),
        ("tract-onnxruntime", trace_diff(&tract_batched, &ort)),
        ("tract-tract_batch1", trace_diff(&tract_batched, &tract_single)),
    ];
    for (pair, diff) in pairs {
        eprintln!("{name}: max |{pair}| over {FRAMES} frames x {BATCH} characters = {diff:.3e}");
        assert!(diff <= TOLERANCE, "{name}: {pair} differ by {diff:e} > {TOLERANCE:e}");
    }
    let moved = max_abs_diff(&reference[0], &reference[FRAMES - 1]);
    assert!(moved > 1e-2, "{name}: the loop should move the frames (moved {moved})");
    insta::assert_json_snapshot!(format!("{name}_graph"), model.summary());
    insta::assert_json_snapshot!(format!("{name}_outputs"), rounded(&reference, toy.frame));
}

#[test]
fn lstm_cell_graph_parity() {
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5);
    check_parity("lstm_cell", &toy, &toy.cell_graph());
}

#[test]
fn lstm_op_graph_parity() {
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5);
    check_parity("lstm_op", &toy, &toy.rnn_op_graph());
}

#[test]
fn gru_op_graph_parity() {
    let toy = ToyModel::new(Cell::Gru, 6, 8, 5);
    check_parity("gru_op", &toy, &toy.rnn_op_graph());
}

#[test]
fn lstm_op_graph_with_start_graph_parity() {
    // A whole transition: the embedded start graph sets (h, c) from the first frame, then 30 steps.
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5);
    check_parity("lstm_op_start", &toy, &toy.with_start(&toy.rnn_op_graph()));
}

#[test]
fn gru_op_graph_with_start_graph_parity() {
    let toy = ToyModel::new(Cell::Gru, 6, 8, 5);
    check_parity("gru_op_start", &toy, &toy.with_start(&toy.rnn_op_graph()));
}

#[test]
fn lstm_cell_and_op_graphs_agree() {
    // The same weights written two ways (ops vs the ONNX LSTM op) must give the same frames.
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5);
    let (a, _) = tract_loop(&toy, &toy.cell_graph());
    let (b, _) = tract_loop(&toy, &toy.rnn_op_graph());
    let diff = trace_diff(&a, &b);
    assert!(diff <= TOLERANCE, "cell vs op graph: {diff:e}");
}

#[test]
fn ops_graph_parity() {
    let graph = ops_graph();
    let x = lcg(7, BATCH * 6, 3.0);
    let reference: Vec<f32> = x.chunks(6).flat_map(ops_reference).collect();
    let model = MotionModel::from_bytes(&graph.to_bytes()).unwrap();
    let mut runner = model.runner().unwrap();
    let mut states: Vec<MotionState> = (0..BATCH).map(|_| model.new_state()).collect();
    let mut tract = vec![0.0; x.len()];
    runner.step_batch(&mut states, &[&x], &mut [&mut tract]).unwrap();
    let ort = OrtSession::new(&graph).run(&[("x", BATCH, &x)], &["y"]).remove(0);
    assert!(max_abs_diff(&reference, &tract) <= 1e-6, "tract: {:e}", max_abs_diff(&reference, &tract));
    assert!(max_abs_diff(&reference, &ort) <= 1e-6, "onnxruntime: {:e}", max_abs_diff(&reference, &ort));
    insta::assert_json_snapshot!("ops_graph", graph.summary());
}
