//! Parity of the exported RTN: candle (`zoo-rtn`), tract (through `zoo-runtime`) and
//! onnxruntime (through `ort`, `load-dynamic`) run the same transitions of a tiny RTN.
//!
//! Where the expected numbers come from: candle's `Rtn::begin` / `initial_state` / `step`,
//! driven exactly like `zoo_rtn::transition::generate` (context frames fed as ground truth, then
//! each generated frame fed back, its root integrated and its offset to the target recomputed),
//! and checked against `Rtn::unroll`. The exported graphs are driven the same way, the offset and
//! root being recomputed on the host from the generated frame. Weights are fixed LCG draws
//! (`Config::tiny`, 4 joints), statistics fixed. Every pair must agree within 1e-4 in normalized
//! units on every frame. The snapshots hold candle's outputs rounded to 4 decimals and the graph
//! summaries.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use std::collections::HashMap;
use std::sync::Arc;
use zoo_export::OnnxModel;
use zoo_rtn::export::{RtnExportOptions, export_rtn, export_rtn_dir};
use zoo_rtn::features::{self, FeatureStats, MeanStd};
use zoo_rtn::model::{OffsetTensors, RtnInputs, RtnState};
use zoo_rtn::{Config, InitState, Rtn};
use zoo_runtime::Heightmap;
use zoo_runtime::glam::{Quat, Vec3};
use zoo_runtime::metadata::{FormatError, TransitionTask, keys};
use zoo_runtime::{
    EnginePose, LoadedModel, MotionError, MotionModel, MotionState, MotionTask, MotionTaskKind, TransitionModel,
};
use zoo_tests::onnxruntime::OrtSession;
use zoo_tests::toy_onnx::{Cell, ToyModel, lcg};

const BATCH: usize = 3;
const PAST: usize = 4;
const FRAMES: usize = 30;
const TOLERANCE: f32 = 1e-4;
const PARENTS: [Option<usize>; 4] = [None, Some(0), Some(0), Some(2)];

/// Normalized per-step outputs `x_(t+1)` of every character, `[step][character * D + k]`.
type Trace = Vec<Vec<f32>>;

struct Fixture {
    config: Config,
    varmap: VarMap,
    model: Rtn,
    stats: FeatureStats,
    /// The ground of every character (read only by a terrain-aware config).
    ground: Heightmap,
}

/// Rolling ground under the characters' paths (bumps of about 10 clip units, several per
/// terrain patch).
fn ground() -> Heightmap {
    Heightmap::from_fn(-300.0, -300.0, 400.0, 400.0, 7.0, |x, z| {
        8.0 * (0.05 * x).sin() + 6.0 * (0.07 * z + 0.3 * x).cos()
    })
}

/// Normalized terrain patches `p_t` of every character under `roots` (empty without terrain):
/// the host side of the `terrain` input, as `zoo_rtn` samples it in training.
fn host_patches(f: &Fixture, roots: &[[f32; 3]]) -> Vec<f32> {
    let (Some(ts), true) = (&f.stats.terrain, f.config.terrain) else { return Vec::new() };
    let n = f.config.terrain_dim();
    let mut out = vec![0.0; roots.len() * n];
    for (r, p) in roots.iter().zip(out.chunks_exact_mut(n)) {
        features::terrain_patch(&f.ground, *r, f.config.terrain_extent, f.config.terrain_side, None, p);
        ts.normalize(p);
    }
    out
}

fn fixture(config: Config) -> Fixture {
    let mut varmap = VarMap::new();
    let model = Rtn::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu)).unwrap();
    let mut vars: Vec<(String, Vec<usize>)> =
        varmap.data().lock().unwrap().iter().map(|(n, v)| (n.clone(), v.dims().to_vec())).collect();
    vars.sort();
    for (k, (name, dims)) in vars.iter().enumerate() {
        let fan_in = if dims.len() == 2 { dims[1] } else { config.lstm };
        let n = dims.iter().product();
        let t = Tensor::from_vec(lcg(1000 + k as u64, n, 1.5 / (fan_in as f32).sqrt()), dims.as_slice(), &Device::Cpu)
            .unwrap();
        varmap.set_one(name, &t).unwrap();
    }
    let d = config.dim();
    let ms = |seed: u64, mean: f32, std: f32, root_std: f32| MeanStd {
        mean: lcg(seed, d, mean),
        std: lcg(seed + 1, d, 0.3)
            .iter()
            .enumerate()
            .map(|(i, v)| (1.0 + v) * if i < 3 { root_std } else { std })
            .collect(),
    };
    let stats = FeatureStats {
        joints: config.joints,
        x: ms(1, 5.0, 20.0, 2.0),
        velocity: ms(3, 0.5, 2.0, 2.0),
        offset: ms(5, 20.0, 60.0, 60.0),
        terrain: config
            .terrain
            .then(|| MeanStd { mean: vec![-85.0; config.terrain_dim()], std: vec![7.0; config.terrain_dim()] }),
    };
    Fixture { config, varmap, model, stats, ground: ground() }
}

fn tiny() -> Config {
    Config::tiny().with_parents(&PARENTS)
}

fn export(f: &Fixture) -> OnnxModel {
    let options = RtnExportOptions {
        names: Some(["Hips", "Spine", "Leg", "Foot_L"].iter().map(|s| s.to_string()).collect()),
        offsets: Some(vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, -40.0, 0.0], [0.0, -40.0, 0.0]]),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    export_rtn(&f.config, None, &f.stats, &f.varmap, &options).expect("the RTN exports")
}

/// Global positions of frame `f` of character `c` (4 joints, clip units).
fn pose(c: usize, f: usize) -> Vec<f32> {
    let (t, p) = (f as f32, c as f32);
    let root = [2.0 * t + 10.0 * p, 90.0 + 3.0 * (0.3 * t + p).sin(), 0.5 * t * p];
    let rel = [
        [0.0, 0.0, 0.0],
        [0.0, 20.0 + 2.0 * (0.2 * t).sin(), 0.0],
        [5.0 * (0.4 * t + p).sin(), -40.0, 3.0 * (0.4 * t).cos()],
        [8.0 * (0.4 * t + p + 1.0).sin(), -75.0, 4.0 * (0.4 * t + p).cos()],
    ];
    rel.iter().flat_map(|r| (0..3).map(move |a| root[a] + r[a])).collect()
}

/// One character's transition inputs, as `generate` encodes them.
struct Character {
    past: Vec<f32>,
    target_pose: Vec<f32>,
    next_pose: Vec<f32>,
    /// Normalized context features, one frame each.
    x: Vec<Vec<f32>>,
    roots: Vec<[f32; 3]>,
    /// Normalized target vector (2D).
    target: Vec<f32>,
}

fn character(stats: &FeatureStats, c: usize) -> Character {
    let d = stats.dim();
    let past: Vec<f32> = (0..PAST).flat_map(|f| pose(c, f)).collect();
    let target_frame = PAST + FRAMES - 1;
    let (target_pose, next_pose) = (pose(c, target_frame), pose(c, target_frame + 1));
    let mut feats = vec![0.0; past.len()];
    features::encode_positions(&past, stats.joints, &mut feats);
    stats.x.normalize(&mut feats);
    let mut target = vec![0.0; 2 * d];
    features::target_vector(&target_pose, &next_pose, &mut target);
    stats.normalize_target(&mut target);
    Character {
        x: feats.chunks(d).map(<[f32]>::to_vec).collect(),
        roots: past.chunks(d).map(features::root_of).collect(),
        past,
        target_pose,
        next_pose,
        target,
    }
}

fn characters(stats: &FeatureStats) -> Vec<Character> {
    (0..BATCH).map(|c| character(stats, c)).collect()
}

fn cat<'a>(chars: &'a [&Character], part: impl Fn(&'a Character) -> &'a [f32]) -> Vec<f32> {
    chars.iter().flat_map(|c| part(c).iter().copied()).collect()
}

/// Candle, batched, exactly like `zoo_rtn::transition::generate` with no teacher forcing.
fn candle_loop(f: &Fixture, chars: &[Character], n_out: usize) -> Trace {
    let dev = Device::Cpu;
    let d = f.config.dim();
    let refs: Vec<&Character> = chars.iter().collect();
    let b = chars.len();
    let t = |v: Vec<f32>, w: usize| Tensor::from_vec(v, (b, w), &dev).unwrap();
    let offsets = OffsetTensors::new(&f.stats, &dev).unwrap();
    let seq = f.model.begin(&t(cat(&refs, |c| &c.target), 2 * d)).unwrap();
    let mut state = f.model.initial_state(&t(cat(&refs, |c| &c.x[0]), d)).unwrap();
    let target_term =
        f.config.future_conditioning.then(|| offsets.target_term(&t(cat(&refs, |c| &c.target_pose), d)).unwrap());
    let bases = offsets
        .interpolation_frames(
            &t(cat(&refs, |c| &c.x[PAST - 1]), d),
            &t(cat(&refs, |c| &c.roots[PAST - 1]), 3),
            &t(cat(&refs, |c| &c.target), 2 * d),
            &t(cat(&refs, |c| &c.target_pose), d),
            n_out - 1,
        )
        .unwrap();
    let mut x = t(cat(&refs, |c| &c.x[0]), d);
    let mut root = t(cat(&refs, |c| &c.roots[0]), 3);
    let mut trace = Vec::new();
    for step in 0..PAST - 1 + n_out {
        let offset = target_term.as_ref().map(|tt| offsets.offset(tt, &x, &root).unwrap());
        let known = (step + 1 < PAST).then(|| t(cat(&refs, |c| &c.x[step + 1]), d));
        let base = f.config.interp_residual.then(|| known.as_ref().unwrap_or_else(|| &bases[step + 1 - PAST]));
        let roots: Vec<[f32; 3]> = root.to_vec2::<f32>().unwrap().iter().map(|r| [r[0], r[1], r[2]]).collect();
        let patches = f.config.terrain.then(|| t(host_patches(f, &roots), f.config.terrain_dim()));
        // The time to arrival of the frame this step predicts (`step + 1`; the target is `PAST + n_out - 1`).
        let tta = f.config.time_to_arrival.map(|z| {
            let mut e = vec![0f32; z.dims];
            z.embed(PAST + n_out - 2 - step, &mut e);
            t(e.repeat(b), z.dims)
        });
        let inputs = RtnInputs {
            sequence: &seq,
            x: &x,
            offset: offset.as_ref(),
            terrain: patches.as_ref(),
            base,
            tta: tta.as_ref(),
        };
        let (next, st) = f.model.step(&inputs, &state).unwrap();
        state = st;
        trace.push(next.flatten_all().unwrap().to_vec1::<f32>().unwrap());
        let nt = step + 1;
        if nt < PAST {
            x = t(cat(&refs, |c| &c.x[nt]), d);
            root = t(cat(&refs, |c| &c.roots[nt]), 3);
        } else {
            root = offsets.next_root(&root, &next).unwrap();
            x = next;
        }
    }
    trace
}

/// Normalized offset `o_t = ((y_T - y_t) - mu_o) / sigma_o` of a frame with normalized
/// features `x` and global root `root` (host side, what an engine computes).
fn host_offset(stats: &FeatureStats, x: &[f32], root: [f32; 3], target_pose: &[f32]) -> Vec<f32> {
    let mut feat = x.to_vec();
    stats.x.denormalize(&mut feat);
    let mut o: Vec<f32> =
        (0..x.len()).map(|i| target_pose[i] - if i < 3 { root[i] } else { feat[i] + root[i % 3] }).collect();
    stats.offset.normalize(&mut o);
    o
}

/// Named graph inputs of one run.
type Feed<'a> = HashMap<&'a str, Vec<f32>>;

/// A configuration switch under test and its name.
type Variant = (&'static str, fn(&mut Config));

/// Normalized interpolation frame `i` of `0..=n` (the `base` input of an interpolation-residual
/// RTN) on the host, from the last context pose and the target pose.
fn host_base(stats: &FeatureStats, last: &[f32], target_pose: &[f32], i: usize, n: usize) -> Vec<f32> {
    let mut b = vec![0.0; last.len()];
    features::interpolation_frame(last, target_pose, i, n, &mut b);
    stats.x.normalize(&mut b);
    b
}

/// The generate loop on the host around an exported graph. `start` gets the named start inputs
/// (`target`, `x0`); `step` gets the named frame inputs (`x`, `offset`, `base`, `terrain`, `tta`) and
/// returns `x_next`.
fn host_loop(
    f: &Fixture,
    chars: &[&Character],
    n_out: usize,
    start: &mut dyn FnMut(&Feed),
    step: &mut dyn FnMut(&Feed) -> Vec<f32>,
) -> Trace {
    let d = f.config.dim();
    start(&HashMap::from([("target", cat(chars, |c| &c.target)), ("x0", cat(chars, |c| &c.x[0]))]));
    let mut x = cat(chars, |c| &c.x[0]);
    let mut roots: Vec<[f32; 3]> = chars.iter().map(|c| c.roots[0]).collect();
    let mut trace = Vec::new();
    for s in 0..PAST - 1 + n_out {
        let offset: Vec<f32> = chars
            .iter()
            .enumerate()
            .flat_map(|(k, c)| host_offset(&f.stats, &x[k * d..(k + 1) * d], roots[k], &c.target_pose))
            .collect();
        let nt = s + 1;
        let base: Vec<f32> = if nt < PAST {
            cat(chars, |c| &c.x[nt])
        } else {
            chars
                .iter()
                .flat_map(|c| host_base(&f.stats, &c.past[(PAST - 1) * d..], &c.target_pose, nt - PAST, n_out - 1))
                .collect()
        };
        let terrain = host_patches(f, &roots);
        // The time to arrival as docs/runtime-protocol-transition.md 5e says: frames from the
        // predicted frame `nt` to the target `PAST + n_out - 1`.
        let tta = f.config.time_to_arrival.map_or(Vec::new(), |z| {
            let mut e = vec![0f32; z.dims];
            z.embed(PAST + n_out - 1 - nt, &mut e);
            e.repeat(chars.len())
        });
        let next = step(&HashMap::from([
            ("x", x.clone()),
            ("offset", offset),
            ("base", base),
            ("terrain", terrain),
            ("tta", tta),
        ]));
        trace.push(next.clone());
        if nt < PAST {
            x = cat(chars, |c| &c.x[nt]);
            roots = chars.iter().map(|c| c.roots[nt]).collect();
        } else {
            for (k, r) in roots.iter_mut().enumerate() {
                for a in 0..3 {
                    r[a] += next[k * d + a] * f.stats.x.std[a] + f.stats.x.mean[a];
                }
            }
            x = next;
        }
    }
    trace
}

fn named<'a>(map: &'a HashMap<&str, Vec<f32>>, name: &str) -> &'a [f32] {
    map.get(name).unwrap_or_else(|| panic!("the exported graph asks for unknown input `{name}`"))
}

fn tract_loop(f: &Fixture, onnx: &OnnxModel, chars: &[&Character], n_out: usize) -> Trace {
    let model = MotionModel::from_bytes(&onnx.to_bytes()).expect("zoo-runtime loads the exported RTN");
    let mut runner = model.runner().unwrap();
    let mut states: Vec<MotionState> = chars.iter().map(|_| model.new_state()).collect();
    let d = f.config.dim();
    // Both closures drive the same runner and states.
    let cell = std::cell::RefCell::new((&mut runner, &mut states));
    host_loop(
        f,
        chars,
        n_out,
        &mut |inputs| {
            let mut g = cell.borrow_mut();
            let (runner, states) = &mut *g;
            let ins: Vec<&[f32]> = model.start_inputs().iter().map(|i| named(inputs, &i.name)).collect();
            runner.start_batch(states, &ins).unwrap();
        },
        &mut |inputs| {
            let mut g = cell.borrow_mut();
            let (runner, states) = &mut *g;
            let ins: Vec<&[f32]> = model.inputs().iter().map(|i| named(inputs, &i.name)).collect();
            let mut y = vec![0.0; states.len() * d];
            runner.step_batch(states, &ins, &mut [&mut y]).unwrap();
            y
        },
    )
}

/// The start graph as an engine would read it: decoded from the step file's metadata.
fn embedded_start_graph(onnx: &OnnxModel) -> Option<OnnxModel> {
    use base64::Engine;
    let encoded = onnx.proto().metadata_props.iter().find(|p| p.key == "zoo.start_graph")?.value.clone();
    let bytes = base64::engine::general_purpose::STANDARD.decode(encoded).unwrap();
    Some(OnnxModel::from_proto(prost::Message::decode(bytes.as_slice()).unwrap()))
}

fn io_names(onnx: &OnnxModel) -> (Vec<String>, Vec<String>) {
    let g = onnx.proto().graph.as_ref().unwrap();
    (g.input.iter().map(|v| v.name.clone()).collect(), g.output.iter().map(|v| v.name.clone()).collect())
}

fn ort_loop(f: &Fixture, onnx: &OnnxModel, chars: &[&Character], n_out: usize) -> Trace {
    let b = chars.len();
    let hu = f.config.lstm;
    let mut session = OrtSession::new(onnx);
    assert_eq!(session.metadata("zoo.model_kind").as_deref(), Some("rtn"), "metadata_props reach onnxruntime");
    let (step_in, step_out) = io_names(onnx);
    let mut state: HashMap<String, Vec<f32>> =
        HashMap::from([("h".into(), vec![0.0; b * hu]), ("c".into(), vec![0.0; b * hu])]);
    if f.config.future_conditioning {
        state.insert("gate_bias".into(), vec![0.0; b * 4 * hu]);
    }
    let start_graph = embedded_start_graph(onnx);
    let state_cell = std::cell::RefCell::new(state);
    host_loop(
        f,
        chars,
        n_out,
        &mut |inputs| {
            let Some(sg) = &start_graph else { return };
            let (ins, outs) = io_names(sg);
            let feed: Vec<(&str, usize, &[f32])> = ins.iter().map(|n| (n.as_str(), b, named(inputs, n))).collect();
            let out_refs: Vec<&str> = outs.iter().map(String::as_str).collect();
            let values = OrtSession::new(sg).run(&feed, &out_refs);
            let mut state = state_cell.borrow_mut();
            for (name, v) in outs.iter().zip(values) {
                state.insert(name.clone(), v);
            }
        },
        &mut |inputs| {
            let mut state = state_cell.borrow_mut();
            let feed: Vec<(&str, usize, &[f32])> = step_in
                .iter()
                .map(|n| match state.get(n) {
                    Some(s) => (n.as_str(), b, s.as_slice()),
                    None => (n.as_str(), b, named(inputs, n)),
                })
                .collect();
            let out_refs: Vec<&str> = step_out.iter().map(String::as_str).collect();
            let values = session.run(&feed, &out_refs);
            let mut x_next = Vec::new();
            for (name, v) in step_out.iter().zip(values) {
                match name.strip_suffix("_next").filter(|s| *s != "x") {
                    Some(slot) => {
                        state.insert(slot.to_string(), v);
                    }
                    None => x_next = v,
                }
            }
            x_next
        },
    )
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

fn trace_diff(a: &Trace, b: &Trace) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(a, b)| max_abs_diff(a, b)).fold(0.0, f32::max)
}

/// Runs candle, tract (batched and batch 1) and onnxruntime; asserts every pair; returns candle's trace.
fn check_transition(name: &str, f: &Fixture, onnx: &OnnxModel, n_out: usize) -> Trace {
    check_transition_within(name, f, onnx, n_out, Tolerance { from_candle: TOLERANCE, between_runtimes: TOLERANCE })
}

/// How far apart the backends may be: candle f32 from each runtime (what a width's rounding
/// of the weights costs), and the runtimes from each other at the same width (tract batched,
/// tract one character at a time, onnxruntime: the same computation, summed in other orders).
#[derive(Clone, Copy)]
struct Tolerance {
    from_candle: f32,
    between_runtimes: f32,
}

/// [`check_transition`] with every pair within its `tolerance`.
fn check_transition_within(name: &str, f: &Fixture, onnx: &OnnxModel, n_out: usize, tolerance: Tolerance) -> Trace {
    let chars = characters(&f.stats);
    let refs: Vec<&Character> = chars.iter().collect();
    let candle = candle_loop(f, &chars, n_out);
    let tract = tract_loop(f, onnx, &refs, n_out);
    let mut tract1: Trace = vec![Vec::new(); candle.len()];
    for c in &refs {
        for (frame, v) in tract1.iter_mut().zip(tract_loop(f, onnx, std::slice::from_ref(c), n_out)) {
            frame.extend(v);
        }
    }
    let ort = ort_loop(f, onnx, &refs, n_out);
    let pairs = [
        ("candle-tract", trace_diff(&candle, &tract)),
        ("candle-tract_batch1", trace_diff(&candle, &tract1)),
        ("candle-onnxruntime", trace_diff(&candle, &ort)),
        ("tract-onnxruntime", trace_diff(&tract, &ort)),
        ("tract-tract_batch1", trace_diff(&tract, &tract1)),
    ];
    for (pair, diff) in pairs {
        eprintln!("{name}: max |{pair}| over {} steps x {BATCH} characters = {diff:.3e}", candle.len());
        let tolerance = if pair.starts_with("candle") { tolerance.from_candle } else { tolerance.between_runtimes };
        assert!(diff <= tolerance, "{name}: {pair} differ by {diff:e} > {tolerance:e}");
    }
    let moved = max_abs_diff(&candle[PAST], &candle[candle.len() - 1]);
    assert!(moved > 1e-2, "{name}: the transition should move (moved {moved})");
    candle
}

/// Candle's outputs of character `c` on every 5th generated frame, rounded to 4 decimals.
fn rounded(trace: &Trace, d: usize) -> Vec<Vec<Vec<f64>>> {
    (0..BATCH)
        .map(|c| {
            (PAST - 1..trace.len())
                .step_by(5)
                .chain([trace.len() - 1])
                .map(|s| trace[s][c * d..(c + 1) * d].iter().map(|v| (*v as f64 * 1e4).round() / 1e4).collect())
                .collect()
        })
        .collect()
}

#[test]
fn rtn_transition_parity() {
    let f = fixture(tiny());
    let onnx = export(&f);
    let trace = check_transition("rtn", &f, &onnx, FRAMES);
    insta::assert_json_snapshot!("rtn_step_graph", onnx.summary());
    insta::assert_json_snapshot!("rtn_start_graph", embedded_start_graph(&onnx).unwrap().summary());
    insta::assert_json_snapshot!("rtn_transition_outputs", rounded(&trace, f.config.dim()));
}

/// Parity tolerances per weight width (`zoo export --weights`; normalized units, over the
/// 30-frame transitions of [`rtn_transition_parity`], batched and one by one). From candle f32:
/// the exact graph at f32 (1e-4 above), about twice the largest difference measured at f16
/// and int8, rounded up. Between the runtimes at one width: 1e-4 at every width (each
/// character's activations are quantized on their own, and the u8 x u8 integer products are
/// exact on every CPU). Measured 2026-11-29 on an AMD EPYC with AVX-512 VNNI and on the same
/// binary under `qemu-x86_64 -cpu Haswell-v4` (AVX2, FMA, F16C; no AVX-512, no VNNI): f16
/// 1.96e-3 from candle, 1.9e-6 between runtimes, on both; int8 1.005e-1 from candle on both,
/// tract against onnxruntime 2.4e-7 (AVX-512) and 9.5e-7 (AVX2), tract batched against one by
/// one 0 on both. (The earlier int8 export, one activation scale per call and u8 x s8
/// products, gave 2.1 from candle through onnxruntime on AVX2, where its u8 x s8 products
/// saturate, and 3.5e-2 between batched and one by one.) The fixture's tiny LCG weights
/// quantize coarsely and the 30 steps feed their errors back; what the widths cost on a
/// trained model is measured by `zoo bench` (docs/runtime.md).
const WIDTH_TOLERANCE: [(zoo_export::WeightWidth, Tolerance); 3] = [
    (zoo_export::WeightWidth::F32, Tolerance { from_candle: TOLERANCE, between_runtimes: TOLERANCE }),
    (zoo_export::WeightWidth::F16, Tolerance { from_candle: 4e-3, between_runtimes: TOLERANCE }),
    (zoo_export::WeightWidth::Int8, Tolerance { from_candle: 0.25, between_runtimes: TOLERANCE }),
];

#[test]
fn rtn_transition_parity_at_every_width() {
    let f = fixture(tiny());
    let onnx = export(&f);
    for (width, tolerance) in WIDTH_TOLERANCE {
        let at_width = zoo_export::with_weights(&onnx, width).unwrap();
        let meta = MotionModel::from_bytes(&at_width.to_bytes()).unwrap().metadata().weights;
        assert_eq!(meta, width, "the file records its width and the runtime reads it");
        check_transition_within(&format!("rtn {width}"), &f, &at_width, FRAMES, tolerance);
        let ops = at_width.summary().op_counts;
        let integer = ops.get("MatMulInteger").copied().unwrap_or(0);
        assert_eq!(integer > 0, width == zoo_export::WeightWidth::Int8, "{width}: {ops:?}");
    }
}

#[test]
fn candle_loop_matches_unroll() {
    // The candle reference of these tests is `Rtn::unroll`'s loop: decode its generated frames.
    let f = fixture(tiny());
    let d = f.config.dim();
    let chars = characters(&f.stats);
    let trace = candle_loop(&f, &chars, FRAMES);
    for (k, c) in chars.iter().enumerate() {
        let mut feats: Vec<f32> = trace[PAST - 1..].iter().flat_map(|s| s[k * d..(k + 1) * d].to_vec()).collect();
        f.stats.x.denormalize(&mut feats);
        let mut ours = vec![0.0; feats.len()];
        features::decode_features(features::root_of(&c.past[(PAST - 1) * d..]), &feats, f.config.joints, &mut ours);
        let unroll = f.model.unroll(&f.stats, &c.past, &c.target_pose, &c.next_pose, FRAMES - 1, None).unwrap();
        let diff = max_abs_diff(&ours, &unroll);
        assert!(diff <= 1e-3, "character {k}: candle loop vs Rtn::unroll differ by {diff:e} (clip units)");
    }
}

#[test]
fn rtn_single_step_parity() {
    // One step from an arbitrary state: start graph (gate bias) + step graph vs candle.
    let f = fixture(tiny());
    let onnx = export(&f);
    let (d, hu) = (f.config.dim(), f.config.lstm);
    let chars = characters(&f.stats);
    let refs: Vec<&Character> = chars.iter().collect();
    let (h, c) = (lcg(41, BATCH * hu, 0.8), lcg(42, BATCH * hu, 1.5));
    let x = lcg(43, BATCH * d, 1.5);
    let offset = lcg(44, BATCH * d, 1.5);
    let target = cat(&refs, |c| &c.target);
    let dev = Device::Cpu;
    let t = |v: &[f32], w: usize| Tensor::from_slice(v, (BATCH, w), &dev).unwrap();
    let seq = f.model.begin(&t(&target, 2 * d)).unwrap();
    let state = RtnState { h: t(&h, hu), c: t(&c, hu) };
    let (xt, ot) = (t(&x, d), t(&offset, d));
    let inputs = RtnInputs { sequence: &seq, x: &xt, offset: Some(&ot), terrain: None, base: None, tta: None };
    let (next, st) = f.model.step(&inputs, &state).unwrap();
    let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let candle = [flat(&next), flat(&st.h), flat(&st.c)];

    let model = MotionModel::from_bytes(&onnx.to_bytes()).unwrap();
    let mut runner = model.runner().unwrap();
    let mut states: Vec<MotionState> = (0..BATCH).map(|_| model.new_state()).collect();
    let x0 = cat(&refs, |c| &c.x[0]);
    runner.start_batch(&mut states, &[&target, &x0]).unwrap();
    let slot = |name: &str| model.states().iter().position(|s| s.input == name).unwrap();
    for (k, s) in states.iter_mut().enumerate() {
        s.slot_mut(slot("h")).copy_from_slice(&h[k * hu..(k + 1) * hu]);
        s.slot_mut(slot("c")).copy_from_slice(&c[k * hu..(k + 1) * hu]);
    }
    let mut y = vec![0.0; BATCH * d];
    runner.step_batch(&mut states, &[&x, &offset], &mut [&mut y]).unwrap();
    let gather = |name: &str| -> Vec<f32> { states.iter().flat_map(|s| s.slot(slot(name)).to_vec()).collect() };
    let tract = [y, gather("h"), gather("c")];

    let gate_bias = OrtSession::new(&embedded_start_graph(&onnx).unwrap())
        .run(&[("target", BATCH, &target), ("x0", BATCH, &x0)], &["gate_bias"])
        .remove(0);
    let ort = OrtSession::new(&onnx).run(
        &[
            ("x", BATCH, &x),
            ("offset", BATCH, &offset),
            ("h", BATCH, &h),
            ("c", BATCH, &c),
            ("gate_bias", BATCH, &gate_bias),
        ],
        &["x_next", "h_next", "c_next"],
    );
    for (i, what) in ["x_next", "h_next", "c_next"].iter().enumerate() {
        for (pair, diff) in [
            ("candle-tract", max_abs_diff(&candle[i], &tract[i])),
            ("candle-onnxruntime", max_abs_diff(&candle[i], &ort[i])),
            ("tract-onnxruntime", max_abs_diff(&tract[i], &ort[i])),
        ] {
            eprintln!("one step, {what}: max |{pair}| = {diff:.3e}");
            assert!(diff <= TOLERANCE, "one step, {what}: {pair} differ by {diff:e}");
        }
    }
}

#[test]
fn rtn_ablation_variants_parity() {
    // Every config switch the exporter respects: no future conditioning, zero / common initial
    // state, no residual output, the residual on the interpolation (`base` input), the
    // terrain-aware RTN (`terrain` input, patches sampled on the host under each root).
    let variants: [Variant; 11] = [
        ("interp_residual_tta", |c: &mut Config| {
            c.interp_residual = true;
            c.time_to_arrival = Some(zoo_runtime::TimeToArrival { dims: 6, max: 9 });
        }),
        ("terrain_tta", |c: &mut Config| {
            c.terrain = true;
            c.time_to_arrival = Some(zoo_runtime::TimeToArrival { dims: 2, max: 40 });
        }),
        ("terrain", |c: &mut Config| c.terrain = true),
        ("terrain_interp_residual", |c: &mut Config| {
            c.terrain = true;
            c.interp_residual = true;
        }),
        ("interp_residual", |c: &mut Config| c.interp_residual = true),
        ("interp_residual_no_future", |c: &mut Config| {
            c.interp_residual = true;
            c.future_conditioning = false;
        }),
        ("no_future", |c: &mut Config| c.future_conditioning = false),
        ("h0", |c: &mut Config| c.init_state = InitState::Zero),
        ("hcommon", |c: &mut Config| c.init_state = InitState::Common),
        ("no_residual", |c: &mut Config| c.residual = false),
        ("no_future_h0", |c: &mut Config| {
            c.future_conditioning = false;
            c.init_state = InitState::Zero;
        }),
    ];
    for (name, change) in variants {
        let mut config = tiny();
        change(&mut config);
        let f = fixture(config);
        let onnx = export(&f);
        let has_start = embedded_start_graph(&onnx).is_some();
        assert_eq!(has_start, name != "no_future_h0", "{name}: start graph present only when it computes something");
        check_transition(name, &f, &onnx, 12);
    }
}

#[test]
fn exported_metadata_reaches_the_runtime() {
    let f = fixture(tiny());
    let model = MotionModel::from_bytes(&export(&f).to_bytes()).unwrap();
    let m = model.metadata();
    assert_eq!(m.model_kind, "rtn");
    assert_eq!(m.skeleton.names, ["Hips", "Spine", "Leg", "Foot_L"]);
    assert_eq!(m.skeleton.parents, [-1, 0, 0, 2]);
    assert_eq!(m.fps, 30.0);
    assert_eq!(m.normalization["x"].mean, f.stats.x.mean);
    assert_eq!(m.normalization["offset"].std, f.stats.offset.std);
    let task = TransitionTask {
        past_frames: f.config.past_frames,
        transition_frames: f.config.transition_frames,
        target_blend: f.config.target_blend,
        frame_dim: f.config.dim(),
        offset_input: true,
        terrain: None,
        fallback: f.config.fallback.map(|b| zoo_runtime::TransitionFallback { start: b.start, full: b.full }),
        time_to_arrival: None,
        fallback_lengths: Vec::new(),
    };
    assert_eq!(m.task, MotionTask::Transition(task));
    // The config travels as an informational copy (read back by `import_rtn`, not the runtime).
    let config: Config = serde_json::from_str(&m.config_json).unwrap();
    assert_eq!(config, f.config);
    let names: Vec<&str> = model.inputs().iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["x", "offset"]);
    let start: Vec<&str> = model.start_inputs().iter().map(|i| i.name.as_str()).collect();
    assert_eq!(start, ["target", "x0"]);
}

#[test]
fn export_without_skeleton_parents_is_refused() {
    let f = fixture(Config::tiny());
    let err = export_rtn(&f.config, None, &f.stats, &f.varmap, &RtnExportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no skeleton parents"), "{err}");
}

#[test]
fn run_folder_and_cli_export() {
    // A checkpoint folder exports to the same bytes as the in-memory model, and `zoo export`
    // writes a file the runtime loads.
    let f = fixture(tiny());
    let dir = tempfile::tempdir().unwrap();
    zoo_rtn::checkpoint::save(dir.path(), &f.config, &f.varmap, &f.stats).unwrap();
    let out = dir.path().join("rtn.onnx");
    let export_cli = |extra: &[&str]| {
        std::process::Command::new(zoo_tests::zoo_bin())
            .args(["export", "--onnx"])
            .arg(dir.path())
            .arg("--out")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    // Without a skeleton (no --skeleton, no skeleton.json) the file would not say what it
    // animates: refused, by the library and by `zoo export`.
    let err = export_rtn_dir(dir.path(), &RtnExportOptions::default()).unwrap_err();
    assert!(err.to_string().contains("joint names is required"), "{err}");
    let refused = export_cli(&[]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(stderr.contains("no skeleton.json") && stderr.contains("--skeleton FILE.bvh"), "{stderr}");
    // A run folder of `zoo train` keeps its skeleton: the export needs nothing else.
    let options = RtnExportOptions {
        names: Some(["Hips", "Spine", "Leg", "Foot_L"].iter().map(|s| s.to_string()).collect()),
        offsets: Some(vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, -40.0, 0.0], [0.0, -40.0, 0.0]]),
        parents: Some(vec![-1, 0, 0, 2]),
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_nn::checkpoint::RunSkeleton {
        names: options.names.clone().unwrap(),
        parents: options.parents.clone().unwrap(),
        offsets: options.offsets.clone().unwrap(),
        fps: 30.0,
        frame: zoo_runtime::CoordinateFrame::ZOO_CM,
    }
    .write(dir.path())
    .unwrap();
    let from_dir = export_rtn_dir(dir.path(), &RtnExportOptions::default()).unwrap();
    let in_memory = export_rtn(&f.config, None, &f.stats, &f.varmap, &options).unwrap();
    assert!(from_dir.to_bytes() == in_memory.to_bytes(), "run-folder export differs from the in-memory export");
    let status = export_cli(&[]);
    assert!(status.status.success(), "zoo export failed: {}", String::from_utf8_lossy(&status.stderr));
    let model = MotionModel::load(&out).unwrap();
    assert_eq!(model.metadata().skeleton.names, ["Hips", "Spine", "Leg", "Foot_L"]);
    assert_eq!(model.metadata().frame, zoo_runtime::CoordinateFrame::ZOO_CM);
    assert_eq!(model.metadata().skeleton.offsets[2], [0.0, -40.0, 0.0]);
    // --units overrides the run folder's unit.
    let status = export_cli(&["--units", "m"]);
    assert!(status.status.success(), "zoo export --units m failed: {}", String::from_utf8_lossy(&status.stderr));
    assert_eq!(MotionModel::load(&out).unwrap().metadata().frame.metres_per_unit, 1.0);
    let err = std::process::Command::new(zoo_tests::zoo_bin())
        .args(["export", "--onnx", "/nonexistent/run", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!err.status.success());
    assert!(String::from_utf8_lossy(&err.stderr).contains("not a run folder"));
    // A run folder of a model `zoo export` does not know.
    let other = tempfile::tempdir().unwrap();
    std::fs::write(other.path().join("config.json"), r#"{"model": "nope"}"#).unwrap();
    let err = std::process::Command::new(zoo_tests::zoo_bin())
        .args(["export", "--onnx"])
        .arg(other.path())
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!err.status.success());
    let stderr = String::from_utf8_lossy(&err.stderr);
    assert!(stderr.contains("unknown model kind `nope`") && stderr.contains("knows rtn, rmr"), "{stderr}");
}

/// The engine-facing API (`zoo_runtime::TransitionRunner`) against candle's `Rtn::transition`:
/// whole target-blended transitions in global positions, one character at a time and batched.
#[test]
fn runtime_transition_api_matches_candle() {
    runtime_transition_api_matches_candle_for(tiny());
}

/// [`runtime_transition_api_matches_candle`] for an interpolation-residual RTN: the runtime
/// computes the `base` input itself.
#[test]
fn runtime_transition_api_matches_candle_interp_residual() {
    runtime_transition_api_matches_candle_for(Config { interp_residual: true, ..tiny() });
}

#[test]
fn runtime_transition_api_matches_candle_time_to_arrival() {
    // `max` below the transition: the first frames' embeddings are clamped, the last count down.
    let tta = Some(zoo_runtime::TimeToArrival { dims: 8, max: 4 });
    runtime_transition_api_matches_candle_for(Config { interp_residual: true, time_to_arrival: tta, ..tiny() });
}

fn runtime_transition_api_matches_candle_for(config: Config) {
    let f = fixture(config);
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    assert_eq!(model.joints(), 4);
    assert_eq!(model.target_blend(), f.config.target_blend);
    let chars = characters(&f.stats);
    let d = f.config.dim();
    let mut runner = model.runner().unwrap();
    // FRAMES is longer than the tiny model's trained length: refused unless allowed.
    let c = &chars[0];
    let mut out = vec![0.0; (FRAMES + 1) * d];
    let err =
        runner.generate(&mut model.new_transition(), &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap_err();
    assert!(matches!(err, MotionError::BeyondTrainedLength { requested: FRAMES, trained: 6 }), "{err}");
    assert!(err.to_string().contains("allow_beyond_trained"), "{err}");
    runner.allow_beyond_trained(true);
    let mut single = Vec::new();
    for c in &chars {
        let want = f.model.transition(&f.stats, &c.past, &c.target_pose, &c.next_pose, FRAMES, None).unwrap();
        let mut state = model.new_transition();
        let mut out = vec![0.0; want.len()];
        runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
        assert_eq!(state.frames_generated(), FRAMES + 1);
        // Positions are in clip units (~100): 1e-4 relative.
        let diff = max_abs_diff(&want, &out);
        assert!(diff <= 1e-2, "runtime vs candle transition: max abs diff {diff} (clip units)");
        let end = max_abs_diff(&out[FRAMES * d..], &c.target_pose);
        assert!(end <= 1e-3, "the blended transition ends on the target (max abs diff {end})");
        single.push(out);
    }
    // Batched: all characters in one graph run per frame give the same frames.
    let refs: Vec<&Character> = chars.iter().collect();
    let mut states: Vec<_> = chars.iter().map(|_| model.new_transition()).collect();
    let mut out = vec![0.0; BATCH * (FRAMES + 1) * d];
    runner
        .generate_batch(
            &mut states,
            &cat(&refs, |c| &c.past),
            &cat(&refs, |c| &c.target_pose),
            &cat(&refs, |c| &c.next_pose),
            &mut out,
        )
        .unwrap();
    let flat: Vec<f32> = single.concat();
    let diff = max_abs_diff(&flat, &out);
    assert!(diff <= 1e-3, "batched vs one-by-one: max abs diff {diff}");
    // Raw stepping frame by frame gives the unblended frames of candle's unroll.
    let c = &chars[1];
    let want = f.model.unroll(&f.stats, &c.past, &c.target_pose, &c.next_pose, FRAMES, None).unwrap();
    let mut state = model.new_transition();
    runner.start_for(&mut state, &c.past, &c.target_pose, &c.next_pose, FRAMES).unwrap();
    let mut pose = vec![0.0; d];
    for (t, frame) in want.chunks_exact(d).enumerate() {
        runner.step_raw(&mut state, &mut pose).unwrap();
        let diff = max_abs_diff(frame, &pose);
        assert!(diff <= 1e-2, "step {t}: runtime vs candle unroll max abs diff {diff}");
    }
    // Blended stepping as glam vectors: the frames of `generate`.
    let mut state = model.new_transition();
    runner.start_for(&mut state, &c.past, &c.target_pose, &c.next_pose, FRAMES).unwrap();
    let mut joints = vec![zoo_runtime::glam::Vec3::ZERO; 4];
    for frame in single[1].chunks_exact(d).take(3) {
        runner.step_vec3(&mut state, &mut joints).unwrap();
        let flat: Vec<f32> = joints.iter().flat_map(|p| p.to_array()).collect();
        assert!(max_abs_diff(frame, &flat) <= 1e-2);
    }
    assert!(runner.step_vec3(&mut state, &mut joints[..3]).is_err());
}

#[test]
fn runtime_transition_api_rejects_bad_input() {
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let mut runner = model.runner().unwrap();
    let c = character(&f.stats, 0);
    let d = f.config.dim();
    let mut state = model.new_transition();
    let mut pose = vec![0.0; d];
    // Stepping before starting.
    let err = runner.step(&mut state, &mut pose).unwrap_err();
    assert!(err.to_string().contains("start the transition"), "{err}");
    // Wrong joint count (a 5-joint pose for a 4-joint model).
    let err = runner.start(&mut state, &c.past, &[0.0; 15], &c.next_pose).unwrap_err();
    assert!(matches!(err, MotionError::BufferLength { .. }), "{err}");
    assert!(err.to_string().contains("target"), "{err}");
    let err = runner.start(&mut state, &c.past[..c.past.len() - 1], &c.target_pose, &c.next_pose).unwrap_err();
    assert!(err.to_string().contains("past"), "{err}");
    // NaN in the context.
    let mut past = c.past.clone();
    past[7] = f32::NAN;
    let err = runner.start(&mut state, &past, &c.target_pose, &c.next_pose).unwrap_err();
    assert!(matches!(err, MotionError::NonFinite { index: 7, .. }), "{err}");
    assert!(!state.is_started());
    // Output buffer of the wrong size.
    runner.start(&mut state, &c.past, &c.target_pose, &c.next_pose).unwrap();
    let err = runner.step(&mut state, &mut pose[..d - 1]).unwrap_err();
    assert!(matches!(err, MotionError::BufferLength { .. }), "{err}");
    // A step graph of another task.
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5).cell_graph();
    let err = TransitionModel::new(MotionModel::from_bytes(&toy.to_bytes()).unwrap()).unwrap_err();
    assert!(matches!(err, MotionError::WrongTask { .. }), "{err}");
    assert!(err.to_string().contains("`step` model (kind `toy_lstm`)"), "{err}");
}

/// Per-frame stepping is `generate` frame by frame: the target blend applied as the frames
/// come, the trained length enforced, the miss of the network's own target frame exposed.
#[test]
fn runtime_stepping_is_generate_frame_by_frame() {
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let (d, p, blend) = (f.config.dim(), f.config.transition_frames, f.config.target_blend);
    assert!(blend >= 1 && p > blend, "the fixture has a blend window inside the transition");
    let mut runner = model.runner().unwrap();
    let c = character(&f.stats, 0);
    let mut generated = vec![0.0; (p + 1) * d];
    let mut state = model.new_transition();
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut generated).unwrap();
    let generated_miss = state.target_miss().expect("generate measures the miss");
    // The same frames, bit for bit, one step at a time; the miss appears with the blend window.
    let mut state = model.new_transition();
    runner.start(&mut state, &c.past, &c.target_pose, &c.next_pose).unwrap();
    assert_eq!((state.length(), state.frames_left()), (p, p + 1));
    let mut pose = vec![0.0; d];
    for (t, frame) in generated.chunks_exact(d).enumerate() {
        runner.step(&mut state, &mut pose).unwrap();
        assert_eq!(pose, frame, "step {t} differs from generate");
        assert_eq!(state.target_miss().is_some(), t + blend > p, "miss known at step {t}");
    }
    assert!(state.is_finished() && state.frames_left() == 0);
    assert!(max_abs_diff(&pose, &c.target_pose) <= 1e-3, "the last frame is the target");
    assert_eq!(state.target_miss(), Some(generated_miss));
    let err = runner.step(&mut state, &mut pose).unwrap_err();
    assert!(matches!(err, MotionError::TransitionSequence { character: 0, .. }), "{err}");
    assert!(err.to_string().contains("already returned its target frame"), "{err}");
    // The miss is the distance of the raw (unblended) target frame to the target.
    let mut state = model.new_transition();
    runner.start(&mut state, &c.past, &c.target_pose, &c.next_pose).unwrap();
    for _ in 0..=p {
        runner.step_raw(&mut state, &mut pose).unwrap();
    }
    let dists: Vec<f32> = pose
        .chunks_exact(3)
        .zip(c.target_pose.chunks_exact(3))
        .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
        .collect();
    let mean = dists.iter().sum::<f32>() / dists.len() as f32;
    let max = dists.iter().copied().fold(0.0, f32::max);
    assert!((generated_miss.mean - mean).abs() <= 1e-4 && (generated_miss.max - max).abs() <= 1e-4);
    assert!(generated_miss.max > 0.0 && generated_miss.mean <= generated_miss.max);
    // Raw and blended stepping do not mix.
    let err = runner.step(&mut state, &mut pose).unwrap_err();
    assert!(err.to_string().contains("do not mix"), "{err}");
    let mut state = model.new_transition();
    runner.start(&mut state, &c.past, &c.target_pose, &c.next_pose).unwrap();
    runner.step(&mut state, &mut pose).unwrap();
    let err = runner.step_raw(&mut state, &mut pose).unwrap_err();
    assert!(err.to_string().contains("do not mix"), "{err}");
    // Longer than trained: refused, then allowed on request.
    let err = runner.start_for(&mut state, &c.past, &c.target_pose, &c.next_pose, p + 1).unwrap_err();
    assert!(
        matches!(err, MotionError::BeyondTrainedLength { requested, trained } if requested == p + 1 && trained == p)
    );
    runner.allow_beyond_trained(true);
    runner.start_for(&mut state, &c.past, &c.target_pose, &c.next_pose, p + 1).unwrap();
    // Shorter than the blend window: the whole transition is blended from its first frame.
    let mut short = vec![0.0; 2 * d];
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut short).unwrap();
    runner.start_for(&mut state, &c.past, &c.target_pose, &c.next_pose, 1).unwrap();
    for frame in short.chunks_exact(d) {
        runner.step(&mut state, &mut pose).unwrap();
        assert_eq!(pose, frame);
    }
    assert!(max_abs_diff(&pose, &c.target_pose) <= 1e-3);
}

/// Characters at different frames of their transitions step together in one batch and get
/// the frames they get one by one (up to tract's batched float rounding).
#[test]
fn runtime_batched_stepping_at_different_frames_matches_one_by_one() {
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let (d, p) = (f.config.dim(), f.config.transition_frames);
    let mut runner = model.runner().unwrap();
    let chars = [character(&f.stats, 1), character(&f.stats, 2), character(&f.stats, 3)];
    // One by one: each character's whole transition.
    let alone: Vec<Vec<f32>> = chars
        .iter()
        .map(|c| {
            let mut out = vec![0.0; (p + 1) * d];
            runner.generate(&mut model.new_transition(), &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
            out
        })
        .collect();
    // Together: character i starts 2 * i frames after character 0.
    let mut states: Vec<_> = chars.iter().map(|_| model.new_transition()).collect();
    let mut got: Vec<Vec<f32>> = vec![Vec::new(); chars.len()];
    let mut pose = vec![0.0; d];
    let mut poses = Vec::new();
    let mut tick = 0;
    while got.iter().any(|g| g.len() < (p + 1) * d) {
        let mut active = Vec::new();
        for (i, c) in chars.iter().enumerate() {
            if tick == 2 * i {
                runner.start(&mut states[i], &c.past, &c.target_pose, &c.next_pose).unwrap();
            }
            if tick >= 2 * i && !states[i].is_finished() {
                active.push(i);
            }
        }
        if active.len() == chars.len() {
            poses.resize(chars.len() * d, 0.0);
            runner.step_batch(&mut states, &mut poses).unwrap();
            for i in 0..chars.len() {
                got[i].extend_from_slice(&poses[i * d..(i + 1) * d]);
            }
        } else {
            for i in active {
                runner.step(&mut states[i], &mut pose).unwrap();
                got[i].extend_from_slice(&pose);
            }
        }
        tick += 1;
    }
    for (i, (a, g)) in alone.iter().zip(&got).enumerate() {
        let diff = max_abs_diff(a, g);
        assert!(diff <= 1e-3, "character {i}: batched vs one-by-one max abs diff {diff}");
    }
}

/// Engine poses of character `c` at frame `f` on the fixture skeleton: the hips walk along
/// +Z and turn slowly, the other joints swing.
fn engine_pose(c: usize, f: usize) -> EnginePose {
    let (t, p) = (f as f32, c as f32);
    let hips = Vec3::new(10.0 * p + 0.3 * t, 90.0 + 2.0 * (0.3 * t).sin(), 2.0 * t);
    let rotations = [
        Quat::from_rotation_y(0.05 * t + 0.2 * p) * Quat::from_rotation_x(0.1 * (0.2 * t).sin()),
        Quat::from_rotation_z(0.2 * (0.3 * t + p).sin()),
        Quat::from_rotation_x(0.5 * (0.4 * t + p).sin()),
        Quat::from_rotation_x(-0.3 * (0.4 * t).cos().abs()) * Quat::from_rotation_y(0.1 * p),
    ];
    EnginePose::from_world(hips, &rotations)
}

/// A whole transition as engine poses: local rotations that a skinned character can use, root
/// motion that integrates to the root positions, the target reached, and a BVH written from
/// the local rotations alone reproducing the runtime's global positions.
#[test]
fn runtime_engine_poses_are_skinnable() {
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let info = model.model().metadata().skeleton.clone();
    let (k, p) = (model.joints(), model.transition_frames());
    let mut runner = model.runner().unwrap();
    let past: Vec<EnginePose> = (0..f.config.past_frames).map(|t| engine_pose(0, t)).collect();
    let at = f.config.past_frames + p;
    let (target, next) = (engine_pose(0, at), engine_pose(0, at + 1));
    let mut state = model.new_transition();
    runner.start_posed(&mut state, &past, &target, &next).unwrap();
    // The same transition in positions: its hips are the engine poses' hips.
    let mut positions = Vec::new();
    let mut pos_state = model.new_transition();
    let flat = |poses: &[EnginePose]| -> Vec<f32> { poses.iter().flat_map(|q| global_positions(&info, q)).collect() };
    let mut out = vec![0.0; (p + 1) * 3 * k];
    runner
        .generate(
            &mut pos_state,
            &flat(&past),
            &flat(std::slice::from_ref(&target)),
            &flat(std::slice::from_ref(&next)),
            &mut out,
        )
        .unwrap();
    positions.extend_from_slice(&out);
    let mut frames = Vec::new();
    let mut pose = EnginePose::with_global_positions(k);
    let last = &past[past.len() - 1];
    let (mut root, mut yaw) = (last.root_position, last.root_rotation);
    for t in 0..=p {
        runner.step_posed(&mut state, &mut pose).unwrap();
        // Root motion integrates to the root transform.
        root += yaw * pose.root_delta_position;
        yaw = (yaw * Quat::from_rotation_y(pose.root_delta_yaw)).normalize();
        assert!(
            root.abs_diff_eq(pose.root_position, 1e-3),
            "frame {t}: integrated root {root} vs {}",
            pose.root_position
        );
        assert!(yaw.dot(pose.root_rotation).abs() > 1.0 - 1e-6, "frame {t}: integrated facing");
        assert_eq!(pose.root_position.y, 0.0);
        // The hips are the network's; the bones have the skeleton's lengths exactly.
        let hips = Vec3::from_slice(&positions[t * 3 * k..t * 3 * k + 3]);
        assert!(pose.hips_world().abs_diff_eq(hips, 1e-3), "frame {t}: hips {} vs {hips}", pose.hips_world());
        assert!(pose.global_positions[0].abs_diff_eq(hips, 1e-3));
        for j in 1..k {
            let parent = info.parents[j] as usize;
            let bone = pose.global_positions[j].distance(pose.global_positions[parent]);
            assert!((bone - info.offset(j).length()).abs() < 1e-3, "frame {t} joint {j}: bone {bone}");
        }
        // The pose's global positions are forward kinematics of its own rotations (f32 here).
        let fk: Vec<f32> = global_positions(&info, &pose);
        let given: Vec<f32> = pose.global_positions.iter().flat_map(|v| v.to_array()).collect();
        assert!(max_abs_diff(&fk, &given) <= 1e-3, "frame {t}: global positions are not the FK of the rotations");
        frames.push(pose.clone());
    }
    // The last frame is the target pose.
    let end = &frames[p];
    assert!(end.hips_world().abs_diff_eq(target.hips_world(), 1e-2));
    for (a, b) in end.local_rotations.iter().zip(&target.local_rotations) {
        assert!(a.dot(*b).abs() > 1.0 - 1e-4, "target rotation {a} vs {b}");
    }
    // A BVH of the local rotations alone re-reads to the runtime's global positions.
    let mut skeleton = info.to_skeleton();
    skeleton.channels[0].position = true;
    let mut clip =
        zoo_motion::Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations: Vec::new(), local_positions: Vec::new() };
    for q in &frames {
        clip.local_positions.push(q.hips_world().as_dvec3());
        clip.local_positions.extend((1..k).map(|j| info.offset(j).as_dvec3()));
        clip.local_rotations.push(q.hips_world_rotation().as_dquat());
        clip.local_rotations.extend(q.local_rotations[1..].iter().map(|r| r.as_dquat()));
    }
    let text = zoo_data::bvh::to_string(&clip);
    let back = zoo_data::bvh::parse(&text, std::path::Path::new("transition.bvh"), &Default::default()).unwrap();
    let (_, global) = back.global();
    let mut worst = 0.0f64;
    for (t, q) in frames.iter().enumerate() {
        for j in 0..k {
            worst = worst.max(global[t * k + j].distance(q.global_positions[j].as_dvec3()));
        }
    }
    assert!(worst <= 0.1, "BVH round trip: worst joint error {worst} cm");
    // Bad input.
    let err = runner.start_posed(&mut state, &past, &EnginePose::new(k + 1), &next).unwrap_err();
    assert!(err.to_string().contains("target[0].local_rotations"), "{err}");
    let mut small = EnginePose::new(k - 1);
    runner.start_posed(&mut state, &past, &target, &next).unwrap();
    assert!(runner.step_posed(&mut state, &mut small).is_err());
    let c = character(&f.stats, 0);
    runner.start(&mut state, &c.past, &c.target_pose, &c.next_pose).unwrap();
    let err = runner.step_posed(&mut state, &mut pose).unwrap_err();
    assert!(err.to_string().contains("start_posed"), "{err}");
}

/// Global joint positions of `pose` by forward kinematics over `info` (flat, joint-major).
fn global_positions(info: &zoo_runtime::MotionSkeletonInfo, pose: &EnginePose) -> Vec<f32> {
    let k = info.len();
    let (mut rot, mut pos) = (vec![Quat::IDENTITY; k], vec![Vec3::ZERO; k]);
    for j in 0..k {
        if j == 0 {
            rot[0] = pose.hips_world_rotation().normalize();
            pos[0] = pose.hips_world();
        } else {
            let p = info.parents[j] as usize;
            pos[j] = rot[p] * info.offset(j) + pos[p];
            rot[j] = rot[p] * pose.local_rotations[j];
        }
    }
    pos.iter().flat_map(|v| v.to_array()).collect()
}

/// The runtime's foot lock is the one `zoo transition --foot-lock` and the benchmark's `+lock`
/// ran before they moved to the runtime (`zoo_protocol::pipeline::foot_lock_fitted`: the frames
/// on the skeleton, locked, fitted again), here on the file's skeleton.
#[test]
fn runtime_foot_lock_is_the_fitted_post_process() {
    use zoo_protocol::pipeline::{fit_frames, foot_lock_fitted, skeleton_positions_f32};
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let lock = model.default_foot_lock().expect("the fixture skeleton has a Foot_L joint");
    assert_eq!(lock.legs.len(), 1);
    assert_eq!((lock.legs[0].hip, lock.legs[0].knee, lock.legs[0].ankle), (0, 2, 3));
    let c = character(&f.stats, 2);
    let d = f.config.dim();
    let k = d / 3;
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true);
    let mut state = model.new_transition();
    let mut plain = vec![0.0; (FRAMES + 1) * d];
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut plain).unwrap();
    runner.set_foot_lock(Some(lock.clone()));
    assert!(runner.foot_lock().is_some());
    let mut locked = vec![0.0; (FRAMES + 1) * d];
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut locked).unwrap();
    let skeleton = model.model().metadata().skeleton.to_skeleton();
    let offsets: Vec<glam::DVec3> =
        skeleton.offsets.iter().enumerate().map(|(j, o)| if j == 0 { glam::DVec3::ZERO } else { *o }).collect();
    let reference = vec![glam::DQuat::IDENTITY; FRAMES * k];
    let fitted = fit_frames(&skeleton, &offsets, &plain[..FRAMES * d], &reference);
    let prev = &c.past[c.past.len() - d..];
    let (rot, root) = foot_lock_fitted(&skeleton, &offsets, fitted, prev, &plain[FRAMES * d..], &reference);
    let mut want = Vec::new();
    skeleton_positions_f32(&skeleton, &offsets, &rot, &root, &mut want);
    want.extend_from_slice(&plain[FRAMES * d..]);
    let diff = max_abs_diff(&locked, &want);
    assert!(diff < 1e-3, "the runtime's lock is the fitted lock (max abs diff {diff})");
    assert_eq!(&locked[FRAMES * d..], &plain[FRAMES * d..], "the target frame is kept");
    assert!(max_abs_diff(&locked, &plain) > 1e-2, "the lock moves the feet");
}

/// The exported RTN with metadata entry `key` replaced by `value` (`None`: removed).
fn with_prop(f: &Fixture, key: &str, value: Option<&str>) -> Vec<u8> {
    let mut proto = export(f).proto().clone();
    match value {
        Some(v) => proto.metadata_props.iter_mut().find(|p| p.key == key).unwrap().value = v.to_string(),
        None => proto.metadata_props.retain(|p| p.key != key),
    }
    OnnxModel::from_proto(proto).to_bytes()
}

#[test]
fn loaded_model_dispatches_an_rtn_to_the_transition_loader() {
    let f = fixture(tiny());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    export(&f).write(&path).unwrap();
    let loaded = LoadedModel::load(&path).unwrap();
    assert_eq!((loaded.kind(), loaded.task()), ("rtn", MotionTaskKind::Transition));
    let LoadedModel::Transition(model) = loaded else { panic!("an RTN loads as a transition model") };
    assert_eq!(model.past_frames(), f.config.past_frames);
    assert_eq!(model.transition_frames(), f.config.transition_frames);
}

#[test]
fn a_missing_transition_section_is_refused() {
    let f = fixture(tiny());
    let err = LoadedModel::from_bytes(&with_prop(&f, keys::TRANSITION, None)).unwrap_err();
    assert!(
        matches!(&err, MotionError::Format(FormatError::MissingMetadata { key }) if key == keys::TRANSITION),
        "{err}"
    );
    assert!(err.to_string().contains("re-export"), "{err}");
}

#[test]
fn a_malformed_transition_section_is_refused() {
    let f = fixture(tiny());
    for bad in ["{\"past_frames\": 4", "{\"past_frames\": 4}", "[]"] {
        let err = MotionModel::from_bytes(&with_prop(&f, keys::TRANSITION, Some(bad))).unwrap_err();
        assert!(
            matches!(&err, MotionError::Format(FormatError::BadMetadata { key, .. }) if key == keys::TRANSITION),
            "{bad}: {err}"
        );
    }
}

#[test]
fn a_transition_section_that_does_not_match_the_graph_is_refused() {
    let f = fixture(tiny());
    let mut task = zoo_rtn::export::transition_task(&f.config);
    task.offset_input = false;
    let json = serde_json::to_string(&task).unwrap();
    let err = TransitionModel::new(MotionModel::from_bytes(&with_prop(&f, keys::TRANSITION, Some(&json))).unwrap())
        .unwrap_err();
    assert!(matches!(&err, MotionError::BadGraphIo { name, .. } if name == "offset"), "{err}");
    task = zoo_rtn::export::transition_task(&f.config);
    task.frame_dim = 15;
    let json = serde_json::to_string(&task).unwrap();
    let err = LoadedModel::from_bytes(&with_prop(&f, keys::TRANSITION, Some(&json))).unwrap_err();
    assert!(err.to_string().contains("frame_dim is 15"), "{err}");
}

#[test]
fn an_rtn_file_of_another_task_is_refused_by_the_transition_loader() {
    let f = fixture(tiny());
    let step = with_prop(&f, keys::TASK, Some("step"));
    let err = TransitionModel::new(MotionModel::from_bytes(&step).unwrap()).unwrap_err();
    assert!(matches!(err, MotionError::WrongTask { expected: "transition", .. }), "{err}");
    assert!(err.to_string().contains("`step` model (kind `rtn`)"), "{err}");
    // The one loader has no task to give a bare step graph.
    let err = LoadedModel::from_bytes(&step).unwrap_err();
    assert!(matches!(&err, MotionError::NoTask { kind } if kind == "rtn"), "{err}");
}

#[test]
fn import_rtn_reads_back_the_exported_weights() {
    let f = fixture(tiny());
    let (config, weights) = zoo_rtn::export::import_rtn(&export(&f).to_bytes()).unwrap();
    assert_eq!(config, f.config);
    let data = f.varmap.data().lock().unwrap();
    assert_eq!(weights.len(), data.len());
    for (name, var) in data.iter() {
        let want = var.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let got = weights[name].flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(want, got, "weight `{name}`");
    }
    let toy = ToyModel::new(Cell::Lstm, 6, 8, 5).cell_graph();
    let err = zoo_rtn::export::import_rtn(&toy.to_bytes()).unwrap_err();
    assert!(err.to_string().contains("not an RTN export"), "{err}");
}

/// The fallback towards interpolation: the runtime's `generate` (thresholds read back from the
/// exported file) and candle's `Rtn::transition_checked` blend the same way, and a weight of 1
/// gives the linear interpolation of positions exactly.
#[test]
fn runtime_fallback_matches_candle_and_reaches_the_interpolation() {
    use zoo_rtn::fallback::Fallback;
    let always = Fallback { start: 0.0, full: 0.0 };
    let f = fixture(Config { interp_residual: true, fallback: Some(always), ..tiny() });
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let fb = model.default_fallback().expect("the exported config carries the thresholds");
    assert_eq!((fb.start, fb.full), (0.0, 0.0));
    let (d, n) = (f.config.dim(), f.config.transition_frames);
    let c = &characters(&f.stats)[0];
    let mut runner = model.runner().unwrap();
    let mut state = model.new_transition();
    let mut out = vec![0.0; (n + 1) * d];
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
    assert_eq!(state.fallback_weight(), 0.0, "off until set");
    runner.set_fallback(Some(fb));
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
    assert_eq!(state.fallback_weight(), 1.0);
    let last = &c.past[(PAST - 1) * d..];
    for (i, frame) in out.chunks_exact(d).enumerate() {
        let a = (i + 1) as f32 / (n + 1) as f32;
        for j in 0..d {
            let want = last[j] + a * (c.target_pose[j] - last[j]);
            assert!((frame[j] - want).abs() < 1e-3, "frame {i} value {j}: {} vs the interpolation {want}", frame[j]);
        }
    }
    // A weight strictly between 0 and 1: thresholds around candle's own miss.
    let plain = f.model.transition_checked(&f.stats, &c.past, &c.target_pose, &c.next_pose, n, None, None).unwrap();
    let partial = Fallback { start: 0.5 * plain.miss, full: 2.0 * plain.miss };
    let ours =
        f.model.transition_checked(&f.stats, &c.past, &c.target_pose, &c.next_pose, n, None, Some(&partial)).unwrap();
    assert!((ours.weight - 1.0 / 3.0).abs() < 1e-4, "{}", ours.weight);
    runner.set_fallback(Some(zoo_runtime::TransitionFallback { start: partial.start, full: partial.full }));
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
    assert!((state.fallback_weight() - ours.weight).abs() < 1e-3, "{} vs {}", state.fallback_weight(), ours.weight);
    let diff = max_abs_diff(&ours.frames, &out);
    assert!(diff <= 1e-2, "runtime vs candle with the fallback: max abs diff {diff} (clip units)");
}

/// Thresholds calibrated per length travel in the exported file, and the runtime's
/// `set_model_fallback` applies the ones candle's `Config::fallback_for` gives at each length:
/// the same weight at the trained length, and a weight strictly between 0 and 1 at a shorter
/// one where the interpolated thresholds straddle the miss.
#[test]
fn runtime_applies_the_fallback_calibrated_for_each_length() {
    use zoo_runtime::metadata::TransitionFallbackAt;
    let base = fixture(Config { interp_residual: true, ..tiny() });
    let c = &characters(&base.stats)[0];
    let n = base.config.transition_frames;
    let miss = |len: usize| {
        base.model.transition_checked(&base.stats, &c.past, &c.target_pose, &c.next_pose, len, None, None).unwrap().miss
    };
    let (short, long) = (miss(2), miss(n));
    // At 2 frames the table straddles the miss (weight 1/3); at the trained length it is far above it.
    let table = vec![
        TransitionFallbackAt { length: 2, start: 0.5 * short, full: 2.0 * short },
        TransitionFallbackAt { length: n, start: 10.0 * long, full: 20.0 * long },
    ];
    let fallback = zoo_rtn::fallback::Fallback { start: 0.0, full: 0.0 };
    let f =
        Fixture { config: Config { fallback: Some(fallback), fallback_lengths: table, ..base.config.clone() }, ..base };
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let mut runner = model.runner().unwrap();
    runner.set_model_fallback();
    for len in [2, n] {
        let want = f.config.fallback_for(len).unwrap();
        let got = model.default_fallback_for(len).unwrap();
        assert_eq!((got.start, got.full), (want.start, want.full), "thresholds at {len} frames");
        let ours = f
            .model
            .transition_checked(&f.stats, &c.past, &c.target_pose, &c.next_pose, len, None, Some(&want))
            .unwrap();
        let mut state = model.new_transition();
        let mut out = vec![0.0; (len + 1) * f.config.dim()];
        runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
        assert!(
            (state.fallback_weight() - ours.weight).abs() < 1e-3,
            "{len}: {} vs {}",
            state.fallback_weight(),
            ours.weight
        );
        let diff = max_abs_diff(&ours.frames, &out);
        assert!(diff <= 1e-2, "{len} frames: runtime vs candle with the fallback: max abs diff {diff}");
    }
    let ours = f.config.fallback_for(2).unwrap();
    let w = f.model.transition_checked(&f.stats, &c.past, &c.target_pose, &c.next_pose, 2, None, Some(&ours)).unwrap();
    assert!((w.weight - 1.0 / 3.0).abs() < 1e-4, "{}", w.weight);
    // The file's single `fallback` (always) would give 1 at every length: the table replaced it.
    assert_eq!(model.default_fallback().map(|f| f.start), Some(0.0));
}

/// A terrain-aware RTN through the engine-facing API: each character's heightmap
/// (`TransitionState::set_heightmap`) gives the same transitions as candle's `Rtn::transition`
/// with that map (same tolerance as [`runtime_transition_api_matches_candle`]), one by one and
/// batched with a different ground per character; the ground changes the transition.
#[test]
fn runtime_terrain_transition_matches_candle() {
    let f = fixture(tiny().with_terrain(true));
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    assert_eq!(model.terrain(), Some((5, f.config.terrain_extent)));
    let names: Vec<&str> = model.model().inputs().iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["x", "offset", "terrain"]);
    let chars = characters(&f.stats);
    let d = f.config.dim();
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true);
    let rolling = Arc::new(f.ground.clone());
    let flat = Arc::new(Heightmap::flat(0.0));
    let grounds = [&rolling, &flat, &rolling];
    let mut want_all = Vec::new();
    for (c, ground) in chars.iter().zip(grounds) {
        let want = f.model.transition(&f.stats, &c.past, &c.target_pose, &c.next_pose, FRAMES, Some(ground)).unwrap();
        let mut state = model.new_transition();
        state.set_heightmap(Some(Arc::clone(ground)));
        let mut out = vec![0.0; want.len()];
        runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut out).unwrap();
        let diff = max_abs_diff(&want, &out);
        assert!(diff <= 1e-2, "runtime vs candle terrain transition: max abs diff {diff} (clip units)");
        want_all.extend(want);
    }
    let c = &chars[0];
    let on_flat = f.model.transition(&f.stats, &c.past, &c.target_pose, &c.next_pose, FRAMES, Some(&flat)).unwrap();
    let moved = max_abs_diff(&on_flat, &want_all[..on_flat.len()]);
    assert!(moved > 1e-1, "the ground should change the transition (max abs diff {moved})");
    let refs: Vec<&Character> = chars.iter().collect();
    let mut states: Vec<_> = grounds
        .iter()
        .map(|g| {
            let mut s = model.new_transition();
            s.set_heightmap(Some(Arc::clone(g)));
            s
        })
        .collect();
    let mut out = vec![0.0; BATCH * (FRAMES + 1) * d];
    let (past, target, next) = (cat(&refs, |c| &c.past), cat(&refs, |c| &c.target_pose), cat(&refs, |c| &c.next_pose));
    runner.generate_batch(&mut states, &past, &target, &next, &mut out).unwrap();
    let diff = max_abs_diff(&want_all, &out);
    assert!(diff <= 1e-2, "batched terrain transitions vs candle: max abs diff {diff}");
}

/// A terrain-aware model refuses to start a character without a heightmap and names the fix;
/// a model without terrain input ignores one.
#[test]
fn runtime_terrain_model_without_heightmap_is_refused() {
    let f = fixture(tiny().with_terrain(true));
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let mut runner = model.runner().unwrap();
    let c = character(&f.stats, 0);
    let mut states = [model.new_transition(), model.new_transition()];
    states[0].set_heightmap(Some(Arc::new(f.ground.clone())));
    let two = |v: &[f32]| [v, v].concat();
    let err = runner.start_batch(&mut states, &two(&c.past), &two(&c.target_pose), &two(&c.next_pose)).unwrap_err();
    assert!(matches!(err, MotionError::TransitionSequence { character: 1, .. }), "{err}");
    assert!(err.to_string().contains("terrain-aware") && err.to_string().contains("set_heightmap"), "{err}");
    assert!(!states[0].is_started() && !states[1].is_started());
    // The model without terrain input: a heightmap changes nothing.
    let flat_model = fixture(tiny());
    let flat = TransitionModel::new(MotionModel::from_bytes(&export(&flat_model).to_bytes()).unwrap()).unwrap();
    assert_eq!(flat.terrain(), None);
    let mut runner = flat.runner().unwrap();
    let d = f.config.dim();
    let (mut a, mut b) = (vec![0.0; 7 * d], vec![0.0; 7 * d]);
    let mut state = flat.new_transition();
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut a).unwrap();
    state.set_heightmap(Some(Arc::new(f.ground.clone())));
    runner.generate(&mut state, &c.past, &c.target_pose, &c.next_pose, &mut b).unwrap();
    assert_eq!(a, b);
}

/// A terrain-aware file whose metadata does not fit its `terrain` input is refused with the
/// reason: no `terrain` normalization group, a patch side that is not the graph's, an empty patch.
#[test]
fn a_terrain_section_that_does_not_match_the_graph_is_refused() {
    let f = fixture(tiny().with_terrain(true));
    let onnx = export(&f);
    let norm = &onnx.proto().metadata_props.iter().find(|p| p.key == keys::NORMALIZATION).unwrap().value;
    let mut groups: serde_json::Value = serde_json::from_str(norm).unwrap();
    groups.as_object_mut().unwrap().remove("terrain");
    let bytes = with_prop(&f, keys::NORMALIZATION, Some(&groups.to_string()));
    let err = TransitionModel::new(MotionModel::from_bytes(&bytes).unwrap()).unwrap_err();
    assert!(err.to_string().contains("no group `terrain`"), "{err}");
    let mut task = zoo_rtn::export::transition_task(&f.config);
    task.terrain.as_mut().unwrap().side = 4;
    let bytes = with_prop(&f, keys::TRANSITION, Some(&serde_json::to_string(&task).unwrap()));
    let err = TransitionModel::new(MotionModel::from_bytes(&bytes).unwrap()).unwrap_err();
    assert!(err.to_string().contains("group `terrain` has 25 values, expected 16"), "{err}");
    task.terrain.as_mut().unwrap().side = 0;
    let bytes = with_prop(&f, keys::TRANSITION, Some(&serde_json::to_string(&task).unwrap()));
    let err = LoadedModel::from_bytes(&bytes).unwrap_err();
    assert!(err.to_string().contains("terrain patch of side 0 (1..=1024)"), "{err}");
}

/// Temporal super-resolution (`zoo decompress`) on the runtime: every keyframe is met, and the
/// chain of transitions is candle's (`Rtn::transition` chained the same way).
#[test]
fn super_resolution_on_the_runtime_hits_every_key_and_matches_candle() {
    let f = fixture(tiny());
    let model = TransitionModel::new(MotionModel::from_bytes(&export(&f).to_bytes()).unwrap()).unwrap();
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true);
    let d = f.config.dim();
    let interval = 5;
    let clip: Vec<f32> = (0..PAST + 2 * interval + 1).flat_map(|t| pose(1, t)).collect();
    let context = &clip[..PAST * d];
    let mut keys = Vec::new();
    for k in 1..=2 {
        let t = PAST - 1 + interval * k;
        keys.extend_from_slice(&clip[t * d..(t + 2) * d]);
    }
    let out = zoo_tasks::transition::super_resolve(&model, &mut runner, context, &keys, interval).unwrap();
    assert_eq!(out.len(), (PAST + 2 * interval) * d);
    for k in 1..=2 {
        let t = PAST - 1 + interval * k;
        assert!(max_abs_diff(&out[t * d..(t + 1) * d], &clip[t * d..(t + 1) * d]) < 1e-3, "key {k} is met");
    }
    // The same chain in candle: the first segment from the context, the second from the
    // frames generated so far with the stored frame after the first key at its end.
    let first = f.model.transition(&f.stats, context, &keys[..d], &keys[d..2 * d], interval - 1, None).unwrap();
    let mut want = context.to_vec();
    want.extend_from_slice(&first);
    let mut ctx = want[want.len() - (PAST - 1) * d..].to_vec();
    ctx.extend_from_slice(&keys[d..2 * d]);
    let second = f.model.transition(&f.stats, &ctx, &keys[2 * d..3 * d], &keys[3 * d..], interval - 2, None).unwrap();
    want.extend_from_slice(&keys[d..2 * d]);
    want.extend_from_slice(&second);
    let diff = max_abs_diff(&out, &want);
    assert!(diff < 1e-3, "runtime and candle chains differ by {diff}");
}
