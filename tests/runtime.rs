//! zoo-runtime on exported toy models: bad input of every kind returns a named error (never a
//! panic), and one loaded model serves many characters on many threads.

use std::sync::Arc;
use zoo_export::OnnxModel;
use zoo_runtime::metadata::{FormatError, keys};
use zoo_runtime::prelude::*;
use zoo_tests::toy_onnx::{Cell, ToyModel};

fn toy() -> ToyModel {
    ToyModel::new(Cell::Lstm, 6, 8, 5)
}

fn load(model: &OnnxModel) -> Result<MotionModel, MotionError> {
    MotionModel::from_bytes(&model.to_bytes())
}

/// The toy LSTM graph with its metadata_props edited by `edit`.
fn with_props(edit: impl FnOnce(&mut Vec<zoo_export::pb::StringStringEntryProto>)) -> Vec<u8> {
    let mut proto = toy().rnn_op_graph().proto().clone();
    edit(&mut proto.metadata_props);
    OnnxModel::from_proto(proto).to_bytes()
}

#[test]
fn loads_and_describes_the_step_graph() {
    let model = load(&toy().rnn_op_graph()).unwrap();
    let names = |v: &[zoo_runtime::MotionTensorInfo]| v.iter().map(|t| (t.name.clone(), t.width)).collect::<Vec<_>>();
    assert_eq!(names(model.inputs()), vec![("x".to_string(), 6)]);
    assert_eq!(names(model.outputs()), vec![("y".to_string(), 6)]);
    let states: Vec<_> = model.states().iter().map(|s| (s.input.as_str(), s.output.as_str(), s.width)).collect();
    assert_eq!(states, vec![("h", "h_next", 5), ("c", "c_next", 5)]);
    let meta = model.metadata();
    assert_eq!((meta.model_kind.as_str(), meta.fps), ("toy_lstm", 30.0));
    assert_eq!(meta.skeleton.to_skeleton().names, vec!["Hips", "Spine"]);
}

#[test]
fn a_file_path_loads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("toy.onnx");
    toy().cell_graph().write(&path).unwrap();
    assert_eq!(MotionModel::load(&path).unwrap().states().len(), 2);
}

#[test]
fn a_bvh_file_is_not_onnx() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("walk.onnx");
    std::fs::write(&path, "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n}\n").unwrap();
    for err in [MotionModel::load(&path).unwrap_err(), LoadedModel::load(&path).unwrap_err()] {
        assert!(matches!(err, MotionError::Format(FormatError::NotOnnx { .. })), "{err}");
        assert!(err.to_string().contains("walk.onnx"), "{err}");
    }
}

#[test]
fn a_truncated_file_is_not_onnx() {
    let bytes = toy().rnn_op_graph().to_bytes();
    let err = MotionModel::from_bytes(&bytes[..bytes.len() / 2]).unwrap_err();
    assert!(matches!(err, MotionError::NotOnnx { .. } | MotionError::Format(FormatError::NotOnnx { .. })), "{err}");
}

#[test]
fn a_model_without_metadata_is_refused() {
    let bytes = with_props(|p| p.clear());
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::MissingMetadata { key }) if key == keys::FORMAT_VERSION),
        "{err}"
    );
    assert!(err.to_string().contains("re-export"), "{err}");
}

fn set(props: &mut [zoo_export::pb::StringStringEntryProto], key: &str, value: &str) {
    props.iter_mut().find(|e| e.key == key).unwrap().value = value.into();
}

#[test]
fn files_of_the_previous_format_are_asked_to_re_export() {
    // A format-3 file (before one format served every task), and an RMR file of the format
    // RMR had of its own (`zoo.rmr.*`, no `zoo.format_version`), through the one loader.
    let v3 = with_props(|p| set(p, keys::FORMAT_VERSION, "3"));
    let old_rmr = with_props(|p| {
        p.retain(|e| e.key != keys::FORMAT_VERSION);
        p.push(zoo_export::pb::StringStringEntryProto { key: "zoo.rmr.format_version".into(), value: "1".into() });
    });
    for (bytes, found) in [(v3, "3"), (old_rmr, "rmr 1")] {
        let err = LoadedModel::from_bytes(&bytes).unwrap_err();
        assert!(
            matches!(&err, MotionError::Format(FormatError::FormatTooOld { found: f, supported: zoo_runtime::FORMAT_VERSION }) if f == found),
            "{err}"
        );
        assert!(err.to_string().contains("re-export it with `zoo export --onnx RUN_DIR"), "{err}");
    }
}

#[test]
fn an_unknown_format_version_is_refused() {
    let bytes = with_props(|p| set(p, keys::FORMAT_VERSION, "7"));
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(matches!(err, MotionError::Format(FormatError::UnknownFormatVersion { .. })), "{err}");
    assert!(err.to_string().contains("version 7") && err.to_string().contains("reads version 5"), "{err}");
}

#[test]
fn a_version_1_file_is_asked_to_re_export() {
    // A format-1 file: its version and the keys it had (no task, `zoo.normalisation`).
    let bytes = with_props(|p| {
        set(p, keys::FORMAT_VERSION, "1");
        p.retain(|e| e.key != keys::TASK);
        p.iter_mut().find(|e| e.key == keys::NORMALIZATION).unwrap().key = "zoo.normalisation".into();
    });
    for err in [MotionModel::from_bytes(&bytes).unwrap_err(), LoadedModel::from_bytes(&bytes).unwrap_err()] {
        assert!(
            matches!(&err, MotionError::Format(FormatError::FormatTooOld { found, supported: zoo_runtime::FORMAT_VERSION }) if found == "1"),
            "{err}"
        );
        assert!(err.to_string().contains("re-export it with `zoo export --onnx"), "{err}");
    }
}

#[test]
fn a_version_2_file_without_units_is_asked_to_re_export() {
    // A format-2 file: everything but `zoo.frame` (its units and axes).
    let bytes = with_props(|p| {
        set(p, keys::FORMAT_VERSION, "2");
        p.retain(|e| e.key != keys::FRAME);
    });
    for err in [MotionModel::from_bytes(&bytes).unwrap_err(), LoadedModel::from_bytes(&bytes).unwrap_err()] {
        assert!(
            matches!(&err, MotionError::Format(FormatError::FormatTooOld { found, supported: zoo_runtime::FORMAT_VERSION }) if found == "2"),
            "{err}"
        );
        assert!(err.to_string().contains("re-export it with `zoo export --onnx"), "{err}");
    }
}

#[test]
fn a_bare_step_graph_has_no_task_for_the_one_loader() {
    // The raw step graph loads whatever its kind; the one loader needs a task.
    assert!(load(&toy().rnn_op_graph()).is_ok());
    let err = LoadedModel::from_bytes(&toy().rnn_op_graph().to_bytes()).unwrap_err();
    assert!(matches!(&err, MotionError::NoTask { kind } if kind == "toy_lstm"), "{err}");
    assert!(err.to_string().contains("MotionModel::load"), "{err}");
}

#[test]
fn a_file_of_the_wrong_task_is_refused_naming_both() {
    // A task's own loader given a file of another task.
    let err = TransitionModel::new(load(&toy().rnn_op_graph()).unwrap()).unwrap_err();
    assert!(matches!(err, MotionError::WrongTask { expected: "transition", .. }), "{err}");
    let msg = err.to_string();
    assert!(msg.contains("`step` model (kind `toy_lstm`)") && msg.contains("TransitionModel"), "{msg}");
    assert!(msg.contains("LoadedModel::load") && msg.contains("MotionModel"), "{msg}");
}

#[test]
fn an_unknown_task_is_refused_with_the_known_tasks() {
    let bytes = with_props(|p| set(p, keys::TASK, "dance"));
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(matches!(&err, MotionError::Format(FormatError::UnknownTask { task, .. }) if task == "dance"), "{err}");
    assert!(err.to_string().contains("transition, keyframes, stitch, synthesis, step"), "{err}");
}

#[test]
fn a_missing_task_section_is_refused() {
    // Task `transition` without its `zoo.transition` section.
    let bytes = with_props(|p| set(p, keys::TASK, "transition"));
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::MissingMetadata { key }) if key == keys::TRANSITION),
        "{err}"
    );
    assert!(err.to_string().contains("re-export"), "{err}");
}

#[test]
fn a_malformed_task_section_is_refused() {
    let bytes = with_props(|p| {
        set(p, keys::TASK, "transition");
        p.push(zoo_export::pb::StringStringEntryProto {
            key: keys::TRANSITION.into(),
            value: "{\"past_frames\": 10".into(),
        });
    });
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::BadMetadata { key, .. }) if key == keys::TRANSITION),
        "{err}"
    );
    assert!(err.to_string().contains("re-export"), "{err}");
}

#[test]
fn a_state_pair_naming_a_missing_input_is_refused() {
    let bytes = with_props(|p| {
        p.iter_mut().find(|e| e.key == keys::STATE).unwrap().value =
            r#"[{"input": "hidden", "output": "h_next"}]"#.into();
    });
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(matches!(err, MotionError::BadGraphIo { .. }) && err.to_string().contains("`hidden`"), "{err}");
}

#[test]
fn malformed_metadata_json_is_refused() {
    let bytes = with_props(|p| {
        p.iter_mut().find(|e| e.key == keys::SKELETON).unwrap().value = "{not json".into();
    });
    let err = MotionModel::from_bytes(&bytes).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::BadMetadata { key, .. }) if key == keys::SKELETON),
        "{err}"
    );
}

fn ready() -> (MotionModel, MotionRunner, MotionState) {
    let model = load(&toy().rnn_op_graph()).unwrap();
    let runner = model.runner().unwrap();
    let state = model.new_state();
    (model, runner, state)
}

#[test]
fn a_wrong_input_width_is_an_error() {
    let (_, mut runner, mut state) = ready();
    let mut y = [0.0; 6];
    let err = runner.step(&mut state, &[&[0.0; 5]], &mut [&mut y]).unwrap_err();
    assert!(matches!(&err, MotionError::BufferLength { name, expected: 6, found: 5, .. } if name == "x"), "{err}");
}

#[test]
fn a_wrong_output_width_is_an_error() {
    let (_, mut runner, mut state) = ready();
    let mut y = [0.0; 7];
    let err = runner.step(&mut state, &[&[0.0; 6]], &mut [&mut y]).unwrap_err();
    assert!(matches!(&err, MotionError::BufferLength { name, .. } if name == "y"), "{err}");
}

#[test]
fn a_wrong_buffer_count_is_an_error() {
    let (_, mut runner, mut state) = ready();
    let mut y = [0.0; 6];
    let err = runner.step(&mut state, &[&[0.0; 6], &[0.0; 6]], &mut [&mut y]).unwrap_err();
    assert!(matches!(err, MotionError::BufferCount { what: "inputs", expected: 1, found: 2 }), "{err}");
}

#[test]
fn a_nan_input_is_an_error_and_leaves_the_state_alone() {
    let (_, mut runner, mut state) = ready();
    let mut y = [0.0; 6];
    runner.step(&mut state, &[&[0.5; 6]], &mut [&mut y]).unwrap();
    let before = state.clone();
    let mut x = [0.5; 6];
    x[3] = f32::NAN;
    let err = runner.step(&mut state, &[&x], &mut [&mut y]).unwrap_err();
    assert!(matches!(err, MotionError::NonFinite { index: 3, character: 0, .. }), "{err}");
    assert_eq!(state, before);
}

#[test]
fn an_infinite_input_in_a_batch_names_the_character() {
    let (model, mut runner, _) = ready();
    let mut states = vec![model.new_state(); 3];
    let mut x = vec![0.0; 18];
    x[13] = f32::INFINITY;
    let mut y = vec![0.0; 18];
    let err = runner.step_batch(&mut states, &[&x], &mut [&mut y]).unwrap_err();
    assert!(matches!(err, MotionError::NonFinite { character: 2, .. }), "{err}");
}

#[test]
fn a_state_of_another_model_is_an_error() {
    let (_, mut runner, _) = ready();
    let other = load(&ToyModel::new(Cell::Gru, 6, 8, 5).rnn_op_graph()).unwrap();
    let mut state = other.new_state();
    let mut y = [0.0; 6];
    let err = runner.step(&mut state, &[&[0.0; 6]], &mut [&mut y]).unwrap_err();
    assert!(matches!(err, MotionError::StateMismatch { .. }), "{err}");
}

#[test]
fn an_empty_batch_is_an_error() {
    let (_, mut runner, _) = ready();
    let err = runner.step_batch(&mut [], &[&[]], &mut [&mut []]).unwrap_err();
    assert!(matches!(err, MotionError::EmptyBatch), "{err}");
}

#[test]
fn one_model_serves_characters_on_many_threads() {
    let model = Arc::new(load(&toy().cell_graph()).unwrap());
    let run = |model: &MotionModel| {
        let mut runner = model.runner().unwrap();
        let mut state = model.new_state();
        let mut x = vec![0.3; 6];
        let mut y = vec![0.0; 6];
        for _ in 0..30 {
            runner.step(&mut state, &[&x], &mut [&mut y]).unwrap();
            std::mem::swap(&mut x, &mut y);
        }
        x
    };
    let expected = run(&model);
    let handles: Vec<_> = (0..4)
        .map(|_| {
            let model = Arc::clone(&model);
            std::thread::spawn(move || run(&model))
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), expected);
    }
}

#[test]
fn batch_sizes_can_change_between_calls() {
    let (model, mut runner, _) = ready();
    for n in [4, 2, 4, 1, 7] {
        let mut states = vec![model.new_state(); n];
        let x = vec![0.1; n * 6];
        let mut y = vec![0.0; n * 6];
        runner.step_batch(&mut states, &[&x], &mut [&mut y]).unwrap();
        assert!(y.iter().all(|v| v.is_finite()));
        assert!(y.chunks(6).all(|c| c == &y[..6]), "same input, same output for every character");
    }
}

#[test]
fn a_start_graph_sets_the_state() {
    let toy = toy();
    let model = load(&toy.with_start(&toy.rnn_op_graph())).unwrap();
    assert!(model.has_start_graph());
    assert_eq!(model.start_inputs()[0].name, "x0");
    let mut runner = model.runner().unwrap();
    let mut state = model.new_state();
    let x0 = [0.3, -0.2, 0.1, 0.5, -0.4, 0.2];
    runner.start(&mut state, &[&x0]).unwrap();
    let expected = toy.start_state(&x0);
    for (k, e) in expected.iter().enumerate() {
        let d = state.slot(k).iter().zip(e).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(d < 1e-6, "slot {k}: {d}");
    }
    let err = runner.start(&mut state, &[&x0[..5]]).unwrap_err();
    assert!(matches!(err, MotionError::BufferLength { .. }), "{err}");
}

#[test]
fn without_a_start_graph_start_zeroes_the_state() {
    let (_, mut runner, mut state) = ready();
    state.slot_mut(0)[0] = 1.0;
    runner.start(&mut state, &[]).unwrap();
    assert!(state.slot(0).iter().all(|v| *v == 0.0));
    let err = runner.start(&mut state, &[&[0.0; 6]]).unwrap_err();
    assert!(matches!(err, MotionError::BufferCount { expected: 0, .. }), "{err}");
}

#[test]
fn a_start_graph_writing_an_unknown_state_is_refused() {
    let gru = ToyModel::new(Cell::Gru, 6, 8, 5);
    // The LSTM start graph writes `c`, which the GRU step graph does not have.
    let mut proto = gru.rnn_op_graph().proto().clone();
    proto.metadata_props.push(zoo_export::pb::StringStringEntryProto {
        key: keys::START_GRAPH.into(),
        value: toy().start_graph().to_base64(),
    });
    let err = MotionModel::from_bytes(&OnnxModel::from_proto(proto).to_bytes()).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::BadMetadata { key, .. }) if key == keys::START_GRAPH),
        "{err}"
    );
    assert!(err.to_string().contains("`c`"), "{err}");
}

/// A transition whose context is fed frame by frame (`begin_batch`, then `feed_batch` per
/// frame, as a game plays it) is the transition `start_batch` starts from the same frames, bit
/// for bit, for a batch of characters and for context lengths of 1, 2 and the trained 10; a step
/// before the context is fed, a feed with nothing due and characters fed out of step are refused.
#[test]
fn a_transition_fed_frame_by_frame_equals_one_started_at_once() {
    use zoo_runtime::TransitionModel;
    let model = TransitionModel::new(MotionModel::from_bytes(&zoo_tests::tiny_rtn_onnx().to_bytes()).unwrap()).unwrap();
    let (k, length, n) = (model.joints(), model.transition_frames(), 3);
    let d = 3 * k;
    let pose = |c: usize, f: usize| -> Vec<f32> {
        (0..d).map(|i| (i as f32 * 0.7 + f as f32 * 0.3 + c as f32).sin() * 20.0 + 4.0 * f as f32).collect()
    };
    for past in [1usize, 2, model.past_frames()] {
        let frames: Vec<Vec<f32>> = (0..past).map(|f| (0..n).flat_map(|c| pose(c, f)).collect()).collect();
        let all: Vec<f32> = (0..n).flat_map(|c| (0..past).flat_map(move |f| pose(c, f))).collect();
        let target: Vec<f32> = (0..n).flat_map(|c| pose(c, past + length)).collect();
        let next: Vec<f32> = (0..n).flat_map(|c| pose(c, past + length + 1)).collect();
        let mut runner = model.runner().unwrap();
        let mut started: Vec<_> = (0..n).map(|_| model.new_transition()).collect();
        runner.start_batch(&mut started, &all, &target, &next).unwrap();
        let mut fed: Vec<_> = (0..n).map(|_| model.new_transition()).collect();
        runner.begin_batch(&mut fed, &frames[0], &target, &next, past, length).unwrap();
        let mut out = vec![0.0f32; n * d];
        if past > 1 {
            let err = runner.step_batch(&mut fed, &mut out).unwrap_err();
            assert!(err.to_string().contains("start the transition"), "{err}");
        }
        for frame in &frames[1..] {
            runner.feed_batch(&mut fed, frame).unwrap();
        }
        let err = runner.feed_batch(&mut fed, &frames[0]).unwrap_err();
        assert!(err.to_string().contains("no context frame is due"), "{err}");
        let (mut a, mut b) = (vec![0.0f32; n * d], vec![0.0f32; n * d]);
        for f in 0..=length {
            runner.step_batch(&mut started, &mut a).unwrap();
            runner.step_batch(&mut fed, &mut b).unwrap();
            assert!(a == b, "{past} context frames: frame {f} of the fed transition differs");
        }
    }
    // Characters at different points of their context are not fed together.
    let mut runner = model.runner().unwrap();
    let mut states: Vec<_> = (0..2).map(|_| model.new_transition()).collect();
    let two: Vec<f32> = (0..2).flat_map(|c| pose(c, 0)).collect();
    runner.begin_batch(&mut states[..1], &two[..d], &two[..d], &two[..d], 3, length).unwrap();
    runner.feed_batch(&mut states[..1], &two[..d]).unwrap();
    runner.begin_batch(&mut states[1..], &two[..d], &two[..d], &two[..d], 3, length).unwrap();
    let err = runner.feed_batch(&mut states, &two).unwrap_err();
    assert!(err.to_string().contains("feed characters at the same point"), "{err}");
}

/// One character alone, fed and stepped as a game plays it, spreads its graph runs over the
/// calls (a frame budget): some calls end with a run in progress. Its frames are those of a
/// transition started at once and generated whole, bit for bit, also when a second runner (another
/// thread's) takes every other call; when it joins a batch with a run in progress, up to the
/// batch's rounding.
#[test]
fn a_character_alone_spreads_its_runs_over_calls_with_the_same_frames() {
    use zoo_runtime::TransitionModel;
    let model = TransitionModel::new(MotionModel::from_bytes(&zoo_tests::tiny_rtn_onnx().to_bytes()).unwrap()).unwrap();
    let (k, length, past) = (model.joints(), model.transition_frames(), model.past_frames());
    let d = 3 * k;
    let pose = |c: usize, f: usize| -> Vec<f32> {
        (0..d).map(|i| (i as f32 * 0.7 + f as f32 * 0.3 + c as f32).sin() * 20.0 + 4.0 * f as f32).collect()
    };
    let all: Vec<f32> = (0..past).flat_map(|f| pose(0, f)).collect();
    let (target, next) = (pose(0, past + length), pose(0, past + length + 1));
    let mut whole = vec![0.0f32; (length + 1) * d];
    let mut reference = model.runner().unwrap();
    let mut state = model.new_transition();
    reference.generate(&mut state, &all, &target, &next, &mut whole).unwrap();
    // 0: one runner; 1: two runners taking turns; 2: stepped alone, then in a batch of two; 3:
    // the default budgets (the others run nothing by choice: every call leaves what it can in
    // progress, whatever the machine's speed).
    // 4: case 0 again on case 0's runners (their state of a finished transition reused).
    let mut kept = None;
    for case in 0..5 {
        let mut runners = match kept.take() {
            Some(r) if case == 4 => r,
            _ => [model.runner().unwrap(), model.runner().unwrap()],
        };
        if case != 3 {
            runners.iter_mut().for_each(|r| r.set_call_budgets(0.0, 0.0));
        }
        let mut states = [model.new_transition(), model.new_transition()];
        let mut call = 0usize;
        let mut pending = 0usize;
        runners[0].begin_batch(&mut states[..1], &all[..d], &target, &next, past, length).unwrap();
        for f in 1..past {
            let r = if case == 1 { call % 2 } else { 0 };
            runners[r].feed_batch(&mut states[..1], &all[f * d..(f + 1) * d]).unwrap();
            pending += states[0].has_run_in_progress() as usize;
            call += 1;
        }
        if case == 2 {
            runners[0].start(&mut states[1], &all, &target, &next).unwrap();
        }
        let mut out = vec![0.0f32; 2 * d];
        // Case 2 joins the batch with the context's last run in progress.
        let joined = case == 2 && states[0].has_run_in_progress();
        for f in 0..=length {
            let batch = joined;
            if batch {
                runners[0].step_batch(&mut states, &mut out).unwrap();
            } else {
                let r = if case == 1 { call % 2 } else { 0 };
                runners[r].step(&mut states[0], &mut out[..d]).unwrap();
                if case == 2 {
                    let mut other = vec![0.0f32; d];
                    runners[1].step(&mut states[1], &mut other).unwrap();
                }
            }
            pending += states[0].has_run_in_progress() as usize;
            call += 1;
            if batch {
                // A batch runs tract's kernels for two: the same frames up to their rounding.
                let worst = out[..d].iter().zip(&whole[f * d..]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(worst < 1e-3, "case {case}: frame {f} differs from generate by {worst}");
            } else {
                assert!(out[..d] == whole[f * d..(f + 1) * d], "case {case}: frame {f} differs from generate");
            }
        }
        assert!(case == 3 || pending > 0, "case {case}: no call left a run in progress");
        assert!(case != 2 || joined, "case 2: the context left no run in progress to join the batch with");
        if case == 0 {
            kept = Some(runners);
        }
    }
}

/// The chunked window graph a stitching stream spreads over its pushes (each GRU layer as a
/// chain of GRUs over a few frames) computes the refiner's window: value for value for the tiny
/// RMR at every weight width (the f16 and int8 files' GRU weights are widened by nodes, which
/// the chunks keep), within 1e-5 for the paper-size one of `ZOO_RMR_FILE` when given (0 for
/// rmr20 at every width).
#[test]
fn the_chunked_window_graph_is_the_window_graph() {
    let tiny = zoo_tests::tiny_rmr_onnx();
    let mut files: Vec<(Vec<u8>, bool)> =
        [zoo_export::WeightWidth::F32, zoo_export::WeightWidth::F16, zoo_export::WeightWidth::Int8]
            .into_iter()
            .map(|w| (zoo_export::with_weights(&tiny, w).unwrap().to_bytes(), true))
            .collect();
    if let Some(path) = std::env::var_os("ZOO_RMR_FILE") {
        files.push((std::fs::read(path).unwrap(), false));
    }
    for (bytes, exact) in files {
        let refiner = zoo_runtime::StitchRefiner::from_bytes(&bytes).unwrap();
        let n = refiner.window() * refiner.dim();
        let x: Vec<f32> = (0..n).map(|i| (0.37 * i as f32).sin()).collect();
        let (mut whole, mut chunked) = (vec![0.0f32; n], vec![0.0f32; n]);
        refiner.refine_window_normalized(&x, &mut whole).unwrap();
        refiner.refine_window_chunked(&x, &mut chunked).expect("a GRU refiner has recurrences to chunk").unwrap();
        let worst = whole.iter().zip(&chunked).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        eprintln!(
            "window {} x {}: chunked against whole, largest difference {worst:e}",
            refiner.window(),
            refiner.dim()
        );
        if exact {
            assert_eq!(whole, chunked);
        } else {
            assert!(worst <= 1e-5, "chunked against whole: {worst}");
        }
    }
}
