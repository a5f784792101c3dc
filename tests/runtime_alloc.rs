//! Allocations per frame of `MotionRunner::step` and `step_batch`, counted by a global
//! allocator wrapper in this test binary (its own process, so other tests cannot interfere), on
//! the measuring thread only (the test harness's own thread allocates now and then while it
//! waits; tract runs a step on the calling thread).
//!
//! Our side (validation, copies into the preallocated input tensors, copies out) allocates
//! nothing (checked on an identity graph). The plan's nodes write into tensors their state
//! keeps (`zoo_runtime`'s kept outputs), so a step of the graphs zoo exports allocates nothing
//! either: RTN's at every weight width, batch 1 and 64, its terrain variant, the ARNN's and a
//! stitching stream's windows (which reuse one state); the test fails if one allocates. Graphs
//! with ops the runtime does not run itself (tract's ONNX LSTM) are only checked not to grow
//! with the frames played.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use zoo_export::{Dim, GraphBuilder};
use zoo_runtime::prelude::*;
use zoo_tests::toy_onnx::{Cell, ToyModel};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Whether this thread's allocations are counted (a const initialiser: reading it never
    /// allocates, as the allocator needs).
    static COUNTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if COUNTED.with(|c| c.get()) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards every call to the system allocator unchanged; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn per_frame(frames: usize, mut step: impl FnMut()) -> f64 {
    // Warm-up: the first calls may size caches.
    for _ in 0..3 {
        step();
    }
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    COUNTED.with(|c| c.set(true));
    for _ in 0..frames {
        step();
    }
    COUNTED.with(|c| c.set(false));
    (ALLOCATIONS.load(Ordering::Relaxed) - before) as f64 / frames as f64
}

/// `y = Identity(x)` with no state: tract's fixed cost of one run.
fn identity_graph() -> zoo_export::OnnxModel {
    let mut g = GraphBuilder::new("identity");
    let mut meta = ToyModel::new(Cell::Gru, 6, 2, 2).metadata();
    meta.state.clear();
    for (k, v) in meta.to_props() {
        g.metadata(&k, &v);
    }
    let x = g.input("x", &[Dim::batch(), Dim::Fixed(6)]);
    g.output("y", &x, &[Dim::batch(), Dim::Fixed(6)]);
    let y = g.identity("copy", &x);
    g.output("y2", &y, &[Dim::batch(), Dim::Fixed(6)]);
    g.finish().unwrap()
}

/// Our side of a step (validation, copies into the preallocated inputs, copies out) allocates
/// nothing: with a graph tract reduces to no work, a step allocates nothing at all.
fn identity_allocations() {
    let model = MotionModel::from_bytes(&identity_graph().to_bytes()).unwrap();
    let mut runner = model.runner().unwrap();
    let mut state = model.new_state();
    let x = vec![0.2; 6];
    let (mut y, mut y2) = (vec![0.0; 6], vec![0.0; 6]);
    let a = per_frame(100, || runner.step(&mut state, &[&x], &mut [&mut y, &mut y2]).unwrap());
    eprintln!("identity graph (1 ONNX node, no state): {a:.1} allocations per step at batch 1");
    assert_eq!(a, 0.0, "the runtime's own per-step work must not allocate");
}

/// Sets an environment variable: this binary runs one test, on one thread.
#[allow(unsafe_code)]
fn set_env(key: &str, value: &str) {
    // Safety: no other thread of this binary reads or writes the environment meanwhile.
    unsafe { std::env::set_var(key, value) };
}

// One test function: the counter is process-wide, so measurements must not run in parallel.
#[test]
fn allocations_per_step() {
    identity_allocations();
    for (name, graph) in [
        ("lstm_cell_graph", ToyModel::new(Cell::Lstm, 6, 8, 5).cell_graph()),
        ("lstm_op_graph", ToyModel::new(Cell::Lstm, 6, 8, 5).rnn_op_graph()),
    ] {
        let model = MotionModel::from_bytes(&graph.to_bytes()).unwrap();
        let nodes = graph.proto().graph.as_ref().unwrap().node.len();
        let mut runner = model.runner().unwrap();
        let mut state = model.new_state();
        let mut x = vec![0.2; 6];
        let mut y = vec![0.0; 6];
        let mut step1 = || {
            runner.step(&mut state, &[&x], &mut [&mut y]).unwrap();
            std::mem::swap(&mut x, &mut y);
        };
        let a100 = per_frame(100, &mut step1);
        let a1000 = per_frame(1000, &mut step1);
        let mut states = vec![model.new_state(); 64];
        let xb = vec![0.2; 64 * 6];
        let mut yb = vec![0.0; 64 * 6];
        let b64 = per_frame(100, || runner.step_batch(&mut states, &[&xb], &mut [&mut yb]).unwrap());
        eprintln!(
            "{name} ({nodes} ONNX nodes): {a100:.1} allocations per step at batch 1 (over 100 frames), \
             {a1000:.1} (over 1000), {b64:.1} per batch-64 step"
        );
        assert!((a1000 - a100).abs() < 0.5, "allocations per step should not grow with frames played");
        if name == "lstm_cell_graph" {
            assert_eq!((a100, b64), (0.0, 0.0), "an LSTM cell graph's step allocates");
        }
    }
    transition_allocations();
    width_allocations();
    terrain_transition_allocations();
    stitch_allocations();
    keyframes_allocations();
    synthesis_allocations();
}

/// The synthesis task: a step of `SynthesisRunner` (the generator's symbolic-batch plan, the
/// mixture sampled, the pose decoded) allocates nothing, for one character and for eight.
fn synthesis_allocations() {
    use zoo_runtime::SynthesisModel;
    let model = SynthesisModel::from_bytes(&zoo_tests::tiny_rnngmm_onnx().to_bytes()).unwrap();
    let frame = vec![0.0f32; model.frame_dim()];
    for n in [1usize, 8] {
        let mut characters: Vec<_> = (0..n as u64).map(|seed| model.new_character(seed)).collect();
        for c in &mut characters {
            c.start(&model, &frame, 0.0, 0.0, 0.0).unwrap();
        }
        let mut runner = model.runner(n).unwrap();
        let mut poses = vec![EnginePose::new(model.joints()); n];
        let mut contacts = vec![[false; 2]; n];
        let per_step = per_frame(100, || runner.step_batch(&mut characters, 1.0, &mut poses, &mut contacts).unwrap());
        eprintln!("tiny RNN-GMM synthesis: {per_step:.1} allocations per step of {n} characters");
        assert_eq!(per_step, 0.0, "a synthesis step of {n} characters allocates");
    }
    // Control: every frame rolls the candidates out by one step (one batch), and the frame that
    // ends a plan selects the next; 100 frames cover several plans.
    use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
    let mut ch = ControlledCharacter::new(&model, 3, ControlSettings::default()).unwrap();
    ch.start(&model, &frame, 0.0, 0.0, 0.0).unwrap();
    let mut runner = ControlRunner::new(&model).unwrap();
    let mut pose = EnginePose::new(model.joints());
    let control = Control::new(1.0, 0.5);
    let per_frame_control = per_frame(100, || {
        runner.step(&mut ch, control, &mut pose).unwrap();
    });
    eprintln!("tiny RNN-GMM control: {per_frame_control:.1} allocations per frame");
    assert_eq!(per_frame_control, 0.0, "a control frame allocates");
}

/// The keyframes task: a completion of `KeyframeRunner::complete` (picking the keys
/// around each frame, copies in and out) allocates what its graph runs do, for whole keys and
/// for partial keys (a humanoid-shaped ARNN with key groups).
fn keyframes_allocations() {
    use candle_core::{DType, Device};
    use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
    let names: Vec<String> = ["Hips", "Spine"].iter().map(|s| s.to_string()).collect();
    let skeleton = zoo_arnn::HumanoidSkeleton {
        names: names.clone(),
        parents: vec![-1, 0],
        offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
        fps: 30.0,
    };
    let (dof_names, groups) = zoo_arnn::humanoid::pose_layout(&names);
    let tiny = zoo_arnn::ArnnConfig::tiny();
    for config in [tiny.clone(), zoo_arnn::ArnnConfig::humanoid(skeleton, dof_names, groups).sized_like(&tiny)] {
        let varmap = candle_nn::VarMap::new();
        zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 5, DType::F32, &Device::Cpu)).unwrap();
        let d = config.dofs;
        let norm = zoo_arnn::Normalization { mean: vec![0.0; d], std: vec![1.0; d] };
        let onnx = zoo_arnn::export::export_arnn(&config, &norm, &varmap).unwrap();
        let model = KeyframeModel::new(MotionModel::from_bytes(&onnx.to_bytes()).unwrap()).unwrap();
        let g = model.groups();
        let frames = [0usize, 9, 24, 39];
        let poses: Vec<f32> = (0..4 * d).map(|i| (i as f32 * 0.37).sin()).collect();
        let mut fixed = vec![1.0f32; 4 * g];
        if g > 0 {
            fixed[g + 1] = 0.0;
        }
        let mut runner = model.runner(1).unwrap();
        let mut out = vec![0.0f32; 40 * d];
        let per_completion = per_frame(10, || {
            runner.complete(MotionKeys { frames: &frames, poses: &poses, fixed: &fixed }, &mut out).unwrap()
        });
        // The same 39 graph runs through the bare runner.
        let raw = model.step_model().expect("an ARNN step graph");
        let mut raw_runner = raw.runner().unwrap();
        let mut state = raw.new_state();
        let inputs: Vec<Vec<f32>> = raw.inputs().iter().map(|i| vec![0.5; i.width]).collect();
        let refs: Vec<&[f32]> = inputs.iter().map(|v| v.as_slice()).collect();
        let mut y = vec![0.0f32; d];
        let per_run = per_frame(100, || raw_runner.step(&mut state, &refs, &mut [&mut y]).unwrap());
        eprintln!(
            "tiny ARNN ({d} values, {g} key groups): {per_completion:.1} allocations per completion of 40 frames, \
             {per_run:.1} per graph run (x 39 = {:.1})",
            39.0 * per_run
        );
        assert_eq!(per_run, 0.0, "an ARNN graph run allocates");
        assert_eq!(per_completion, 0.0, "a completion of 40 frames allocates");
    }
}

/// The stitching task: heap allocations per window of
/// the chunked window graph on a fresh state (printed) and of a `StitchStream` (pushes, pops
/// and the window they trigger), on the tiny seeded RMR. A stream allocates nothing: its
/// windows reuse one graph state and its tensors, and its own work (encoding, normalising,
/// blending, decoding, inertializing marked seams, and the ankle IK, seam guard and foot lock
/// on their preallocated scratch) none either.
fn stitch_allocations() {
    use candle_core::{DType, Device};
    let config = zoo_rmr::Config::tiny();
    let varmap = candle_nn::VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let stats = zoo_rmr::features::FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let onnx = zoo_rmr::export::export_rmr(&config, &stats, &varmap).unwrap();
    let refiner = zoo_runtime::StitchRefiner::from_bytes(&onnx.to_bytes()).unwrap();
    let (w, s) = (refiner.window(), refiner.stride());
    let x = vec![0.1f32; w * d];
    let mut y = vec![0.0f32; w * d];
    // A stream runs each window through the chunked graph, node by node over its pushes: what
    // tract allocates for that window is the baseline.
    let per_window = per_frame(20, || match refiner.refine_window_chunked(&x, &mut y) {
        Some(r) => r.unwrap(),
        None => refiner.refine_window_normalized(&x, &mut y).unwrap(),
    });
    // Synthetic walking and running, aligned, as engine poses.
    let synth = zoo_data::synth::SynthConfig { minutes: 0.5, seed: 3, clip_seconds: 10.0, ..Default::default() };
    let clips: Vec<zoo_motion::Clip> = zoo_data::synth::generate(&synth).into_iter().map(|c| c.clip).collect();
    let aligned = zoo_rmr::pairs::align_clips(&clips, &config.layout, 10).unwrap().clip;
    let poses: Vec<EnginePose> = (0..aligned.frames())
        .map(|f| {
            let r: Vec<glam::Quat> = aligned.rotations_at(f).iter().map(|q| q.as_quat()).collect();
            EnginePose::from_world(aligned.root_position(f).as_vec3(), &r)
        })
        .collect();
    // The schedule alone (`ZOO_STREAM_AHEAD=0`): a push runs no window node ahead of it, so the
    // counted pushes end on the same node on every run.
    set_env("ZOO_STREAM_AHEAD", "0");
    // The refiner alone (no ankle IK, guard or lock), then `zoo stitch`'s cleanup.
    for cleanup in [zoo_runtime::FootCleanup::NONE, zoo_runtime::FootCleanup::default()] {
        let bare = cleanup == zoo_runtime::FootCleanup::NONE;
        let mut stream = refiner.stream();
        stream.set_cleanup(cleanup).unwrap();
        stream.set_seam_guard(!bare).unwrap();
        let mut out = EnginePose::new(refiner.joints());
        let mut frames = poses.iter();
        // Up to the first pop: the stream sizes its buffers, and a first marked seam its blend's.
        for (f, p) in frames.by_ref().take(stream.latency() + 1).enumerate() {
            if f == w / 2 {
                stream.mark_seam();
            }
            stream.push(p).unwrap();
            while stream.pop(&mut out).unwrap().is_some() {}
        }
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        let mut pushed = 0;
        COUNTED.with(|c| c.set(true));
        for p in frames.by_ref().take(20 * s) {
            // A seam every 25 frames (`zoo stitch --pre-blend` in a stream): no allocation either.
            if pushed % 25 == 7 {
                stream.mark_seam();
            }
            stream.push(p).unwrap();
            while stream.pop(&mut out).unwrap().is_some() {}
            pushed += 1;
        }
        COUNTED.with(|c| c.set(false));
        assert_eq!(pushed, 20 * s, "the synthetic motion is long enough for 20 more windows");
        let stream_per_window = (ALLOCATIONS.load(Ordering::Relaxed) - before) as f64 / 20.0;
        eprintln!(
            "tiny RMR (window {w}, stride {s}): {per_window:.1} allocations per window of the chunked graph on a \
             fresh state, {stream_per_window:.1} per window of a StitchStream with {cleanup:?}, guard {} (its {s} pushes and pops \
             included)",
            !bare
        );
        assert_eq!(stream_per_window, 0.0, "a stream's window allocates ({cleanup:?})");
    }
}

/// `TransitionRunner::step_raw` (feature decoding, offsets, root integration around the graph
/// run) adds no allocation to the graph run itself, and blended stepping none to raw stepping.
fn transition_allocations() {
    let config = zoo_rtn::Config::tiny();
    let d = 3 * 4;
    let onnx = zoo_tests::tiny_rtn_onnx();
    let model = TransitionModel::new(MotionModel::from_bytes(&onnx.to_bytes()).unwrap()).unwrap();
    let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| (i as f32 * 7.0 + f as f32 * 3.0).sin() * 20.0).collect() };
    let past: Vec<f32> = (0..config.past_frames).flat_map(pose).collect();
    let (target, next) = (pose(40), pose(41));
    let mut runner = model.runner().unwrap();
    let mut state = model.new_transition();
    runner.start(&mut state, &past, &target, &next).unwrap();
    let mut out = vec![0.0; d];
    let t = per_frame(100, || runner.step_raw(&mut state, &mut out).unwrap());
    // Whole blended transitions (start, the trained length, the target frame; the blend
    // window computed ahead) allocate what raw stepping of the same frames does.
    let frames = model.transition_frames() + 1;
    let mut transition = |blended: bool| {
        runner.start(&mut state, &past, &target, &next).unwrap();
        for _ in 0..frames {
            if blended {
                runner.step(&mut state, &mut out).unwrap();
            } else {
                runner.step_raw(&mut state, &mut out).unwrap();
            }
        }
    };
    let blended = per_frame(20, || transition(true));
    let unblended = per_frame(20, || transition(false));
    eprintln!("tiny RTN: {blended:.1} allocations per blended transition of {frames} frames, {unblended:.1} raw");
    assert!(blended <= unblended + 0.01, "blended stepping allocates {blended} per transition, raw {unblended}");
    // Engine poses: forward kinematics of the inputs, the rotation fit and root motion of
    // every frame add nothing once the runner's and the state's buffers exist.
    let posed = |f: usize| {
        let rotations: Vec<zoo_runtime::glam::Quat> =
            (0..4).map(|j| zoo_runtime::glam::Quat::from_rotation_x(0.1 * (j + f) as f32)).collect();
        EnginePose::from_world(zoo_runtime::glam::Vec3::new(0.0, 90.0, 3.0 * f as f32), &rotations)
    };
    let past_poses: Vec<EnginePose> = (0..config.past_frames).map(posed).collect();
    let (target_pose, next_pose) = (posed(40), posed(41));
    let mut pose = EnginePose::with_global_positions(4);
    let mut posed_transition = || {
        runner.start_posed(&mut state, &past_poses, &target_pose, &next_pose).unwrap();
        for _ in 0..frames {
            runner.step_posed(&mut state, &mut pose).unwrap();
        }
    };
    let with_poses = per_frame(20, &mut posed_transition);
    eprintln!("tiny RTN: {with_poses:.1} allocations per transition of {frames} engine poses");
    assert!(
        with_poses <= unblended + 0.01,
        "engine-pose stepping allocates {with_poses} per transition, raw positions {unblended}"
    );
    // The same graph through the raw MotionRunner.
    let raw = model.model();
    let mut raw_runner = raw.runner().unwrap();
    let mut raw_state = raw.new_state();
    let x = vec![0.1; d];
    let mut y = vec![0.0; d];
    let g = per_frame(100, || raw_runner.step(&mut raw_state, &[&x, &x], &mut [&mut y]).unwrap());
    eprintln!("tiny RTN: {t:.1} allocations per TransitionRunner::step_raw, {g:.1} per raw graph step");
    assert!(t <= g + 0.01, "TransitionRunner::step_raw allocates {t} per frame, the graph run alone {g}");
    assert_eq!(g, 0.0, "an RTN graph step allocates");
}

/// The tiny RTN's step graph at every weight width (`zoo export --weights`): a step allocates
/// nothing, at batch 1 and 64.
fn width_allocations() {
    let d = 3 * 4;
    let onnx = zoo_tests::tiny_rtn_onnx();
    for width in zoo_export::WeightWidth::ALL {
        let model = MotionModel::from_bytes(&zoo_export::with_weights(&onnx, width).unwrap().to_bytes()).unwrap();
        assert_eq!(model.metadata().weights, width);
        let mut runner = model.runner().unwrap();
        let mut state = model.new_state();
        let x = vec![0.1; d];
        let mut y = vec![0.0; d];
        let mut step = || runner.step(&mut state, &[&x, &x], &mut [&mut y]).unwrap();
        let a100 = per_frame(100, &mut step);
        let a1000 = per_frame(1000, &mut step);
        let mut states = vec![model.new_state(); 64];
        let xb = vec![0.1; 64 * d];
        let mut yb = vec![0.0; 64 * d];
        let mut batch = || runner.step_batch(&mut states, &[&xb, &xb], &mut [&mut yb]).unwrap();
        let b100 = per_frame(100, &mut batch);
        let b1000 = per_frame(1000, &mut batch);
        eprintln!(
            "tiny RTN, {width} weights: {a100:.1} allocations per step at batch 1 (over 100 frames), {a1000:.1} \
             (over 1000); {b100:.1} / {b1000:.1} per batch-64 step"
        );
        assert_eq!((a100, a1000), (0.0, 0.0), "{width}: a step for one character allocates");
        assert_eq!((b100, b1000), (0.0, 0.0), "{width}: a step for 64 characters allocates");
    }
}

/// A terrain-aware RTN: sampling and normalizing the terrain patch of every step (from the
/// character's shared heightmap) adds no allocation to the graph run itself.
fn terrain_transition_allocations() {
    let d = 3 * 4;
    let onnx = zoo_tests::tiny_terrain_rtn_onnx();
    let model = TransitionModel::new(MotionModel::from_bytes(&onnx.to_bytes()).unwrap()).unwrap();
    let (side, _) = model.terrain().expect("a terrain-aware model");
    let pose = |f: usize| -> Vec<f32> { (0..d).map(|i| (i as f32 * 7.0 + f as f32 * 3.0).sin() * 20.0).collect() };
    let past: Vec<f32> = (0..4).flat_map(pose).collect();
    let (target, next) = (pose(40), pose(41));
    let ground =
        zoo_runtime::Heightmap::from_fn(-500.0, -500.0, 500.0, 500.0, 10.0, |x, z| 5.0 * (0.03 * x + 0.02 * z).sin());
    let mut runner = model.runner().unwrap();
    let mut state = model.new_transition();
    state.set_heightmap(Some(std::sync::Arc::new(ground)));
    runner.start(&mut state, &past, &target, &next).unwrap();
    let mut out = vec![0.0; d];
    let t = per_frame(100, || runner.step_raw(&mut state, &mut out).unwrap());
    let raw = model.model();
    let mut raw_runner = raw.runner().unwrap();
    let mut raw_state = raw.new_state();
    let (x, patch) = (vec![0.1; d], vec![0.1; side * side]);
    let mut y = vec![0.0; d];
    let g = per_frame(100, || raw_runner.step(&mut raw_state, &[&x, &x, &patch], &mut [&mut y]).unwrap());
    eprintln!("tiny terrain RTN: {t:.1} allocations per TransitionRunner::step_raw, {g:.1} per raw graph step");
    assert_eq!((t, g), (0.0, 0.0), "a terrain step allocates: step_raw {t}, the graph run alone {g}");
}
