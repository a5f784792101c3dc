//! Parity of the exported in-betweening network (issue 46, `zoo train arnn --design inbetween`):
//! candle (`zoo_arnn::inbetween::complete_shots`, what `zoo complete` and `zoo bench --layout
//! keys` run), tract (the runtime's keyframes task, `KeyframeRunner`) and onnxruntime (through
//! `ort`, on the exported whole-shot graph) complete the same keys with a tiny network trained
//! 3 steps and saved as a run folder, exported from the folder as `zoo export --onnx` does:
//! whole and partial keys and a transition's keys, four characters of two lengths in one batch;
//! with the bidirectional GRU and with the transformer backbone.
//!
//! Where the expected numbers come from: candle's `complete_shots` on the run folder's weights.
//! The keys are f32 values (the runtime's `MotionKeys` are f32), given to candle as f64, so both
//! build bit-identical features ([`zoo_protocol::inbetween`], one implementation); onnxruntime
//! runs the exported graph on those features and its correction is composed the same way
//! (`b + e * correction * std`, f64). Every pair must agree within 1e-4 on the quaternion
//! components and within 1e-4 of the roots' scale on the root positions (1 + the largest
//! absolute value; centimetres here), as the humanoid ARNN's parity test (`tests/parity_arnn.rs`)
//! scales its tolerance; the graphs' own corrections (normalised units) within 1e-4.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{Device, Tensor};
use glam::{DQuat, DVec3};
use std::path::Path;
use std::sync::OnceLock;
use zoo_arnn::Normalization;
use zoo_arnn::inbetween::{Backbone, Inbetween, InbetweenConfig, ShotInputs};
use zoo_arnn::inbetween_train::{InbetweenTrainer, window_normalization};
use zoo_data::dataset::Windows;
use zoo_export::OnnxModel;
use zoo_motion::{EulerOrder, JointChannels, Skeleton};
use zoo_runtime::keyframes::{KeyframeModel, KeyframeRunner, MotionKeys};
use zoo_runtime::{LoadedModel, MotionModel};
use zoo_tests::humanoid_keys;
use zoo_tests::onnxruntime::OrtSession;

const TOLERANCE: f64 = 1e-4;
const D: usize = 15;
const G: usize = 4;

/// Windows of a 3-joint chain swinging (as `zoo_arnn::inbetween_train`'s tests make them).
fn windows(count: usize, frames: usize, phase: f64) -> Windows {
    let skeleton = Skeleton {
        names: vec!["Hips".into(), "Spine".into(), "Hand".into()],
        parents: vec![None, Some(0), Some(1)],
        offsets: vec![DVec3::ZERO, DVec3::new(0.0, 10.0, 0.0), DVec3::new(0.0, 10.0, 0.0)],
        end_sites: vec![None; 3],
        channels: (0..3).map(|j| JointChannels { position: j == 0, order: EulerOrder::Zxy }).collect(),
    };
    let (mut local_rot, mut local_pos) = (Vec::new(), Vec::new());
    for w in 0..count {
        for f in 0..frames {
            let a = 0.3 * (f as f64 * 0.4 + w as f64 + phase).sin();
            local_rot.extend([DQuat::from_rotation_y(a), DQuat::from_rotation_x(2.0 * a), DQuat::from_rotation_z(a)]);
            local_pos.extend([DVec3::new(f as f64, 90.0 + 5.0 * a, 0.0), skeleton.offsets[1], skeleton.offsets[2]]);
        }
    }
    let source = (0..count).map(|w| (w, 0)).collect();
    Windows { skeleton, window: frames, count, local_rot, local_pos, source }
}

/// The trained run folder, its network and statistics as `zoo complete` loads them, and its
/// export.
struct Fixture {
    model: Inbetween,
    norm: Normalization,
    onnx: OnnxModel,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| trained(Backbone::Bgru, "parity_inbetween"))
}

/// The fixture with the transformer backbone.
fn transformer_fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| trained(Backbone::Transformer, "parity_inbetween_transformer"))
}

fn trained(backbone: Backbone, folder: &str) -> Fixture {
    {
        let (train, valid) = (windows(8, 66, 0.0), windows(4, 66, 0.5));
        let c = zoo_arnn::inbetween::config_for(&train.skeleton, 30.0);
        let config =
            InbetweenConfig { seed: 3, ..InbetweenConfig::tiny(c.skeleton, c.euler_axes) }.with_backbone(backbone);
        let norm = window_normalization(&train);
        let mut trainer = InbetweenTrainer::new(&config, norm, train, &valid).unwrap();
        for _ in 0..3 {
            trainer.train_on(&[0, 1, 2, 3, 4, 5, 6, 7]).unwrap();
        }
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(folder);
        std::fs::create_dir_all(&dir).unwrap();
        trainer.save(&dir).unwrap();
        let (model, norm) = zoo_arnn::inbetween::load(&dir, &Device::Cpu).unwrap();
        let onnx = zoo_arnn::export::export_run(&dir, &Default::default()).unwrap();
        Fixture { model, norm, onnx }
    }
}

/// One character's keys: frames, f32 poses and 0/1 flags (empty: whole keys).
struct Keys {
    frames: Vec<usize>,
    poses: Vec<f32>,
    fixed: Vec<f32>,
}

impl Keys {
    fn motion(&self) -> MotionKeys<'_> {
        MotionKeys { frames: &self.frames, poses: &self.poses, fixed: &self.fixed }
    }

    fn poses_f64(&self) -> Vec<Vec<f64>> {
        self.poses.chunks(D).map(|p| p.iter().map(|v| *v as f64).collect()).collect()
    }

    fn fixed_bool(&self) -> Vec<Vec<bool>> {
        self.fixed.chunks(G).map(|m| m.iter().map(|v| *v == 1.0).collect()).collect()
    }

    fn len(&self) -> usize {
        self.frames.last().unwrap() + 1
    }
}

/// Character 0: four whole keys over 40 frames; 1: four keys over 31 frames, the middle two
/// partial; 2: four whole keys over 40 frames; 3: the in-betweening benchmark's transition layout
/// (`zoo bench`'s `arnn:`): ten context frames as keys and the target after a 29-frame gap.
fn characters() -> Vec<Keys> {
    let partial = [[1.0; G], [1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [1.0; G]].concat();
    let keys =
        |frames: Vec<usize>, phase, fixed: Vec<f32>| Keys { poses: humanoid_keys(&frames, phase), frames, fixed };
    vec![
        keys(vec![0, 9, 24, 39], 0.0, vec![]),
        keys(vec![0, 8, 17, 30], 0.7, partial),
        keys(vec![0, 7, 20, 39], 1.9, vec![]),
        keys(zoo_arnn::inbetween_train::transition_keys(29), 2.6, vec![]),
    ]
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// The largest differences of two completions (frames x 15 values): root positions (cm), and
/// quaternion components.
fn diffs(a: &[f64], b: &[f64]) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let d = |root: bool| (0..a.len()).filter(|x| (x % D < 3) == root).map(|x| (a[x] - b[x]).abs()).fold(0.0, f64::max);
    (d(true), d(false))
}

fn scale(v: &[f64]) -> f64 {
    1.0 + v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// Whether two completions agree: root positions within [`TOLERANCE`] of the roots' scale (1 +
/// the largest absolute value, cm), quaternion components within [`TOLERANCE`].
fn agree(a: &[f64], b: &[f64]) -> bool {
    let roots: Vec<f64> = (0..a.len()).filter(|x| x % D < 3).map(|x| a[x]).collect();
    let (root, rot) = diffs(a, b);
    root <= TOLERANCE * scale(&roots) && rot <= TOLERANCE
}

/// The runtime's completions of `chars` in one batch.
fn runtime_completion(runner: &mut KeyframeRunner, chars: &[Keys]) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f32>> = chars.iter().map(|k| vec![f32::NAN; k.len() * D]).collect();
    let keys: Vec<MotionKeys> = chars.iter().map(Keys::motion).collect();
    let mut outs: Vec<&mut [f32]> = out.iter_mut().map(|o| o.as_mut_slice()).collect();
    runner.complete_batch(&keys, &mut outs).unwrap();
    out.iter().map(|o| o.iter().map(|v| *v as f64).collect()).collect()
}

/// Each character's features, and onnxruntime's completion and correction, one graph call per
/// length as the runtime groups them.
fn onnxruntime_completion(f: &Fixture, chars: &[Keys]) -> (Vec<ShotInputs>, Vec<Vec<f64>>, Vec<Vec<f32>>) {
    let config = f.model.config();
    let features = zoo_arnn::inbetween::features(config, &f.norm).unwrap();
    let shots: Vec<ShotInputs> = chars
        .iter()
        .map(|k| zoo_arnn::inbetween::shot_inputs(config, &f.norm, &k.frames, &k.poses_f64(), &k.fixed_bool()).unwrap())
        .collect();
    let mut ort = OrtSession::new(&f.onnx);
    let w = config.input_width();
    let (mut out, mut corrections) = (vec![Vec::new(); chars.len()], vec![Vec::new(); chars.len()]);
    for n in [40, 31] {
        let group: Vec<usize> = (0..chars.len()).filter(|&c| shots[c].frames == n).collect();
        let x: Vec<f32> = group.iter().flat_map(|&c| shots[c].features.iter().copied()).collect();
        let y = ort.run_shaped(&[("features", &[group.len(), n, w], &x)], &["correction"]).remove(0);
        for (k, &c) in group.iter().enumerate() {
            let dl = &y[k * n * D..(k + 1) * n * D];
            out[c] = (0..n * D).map(|x| features.compose(&shots[c], dl, x)).collect();
            corrections[c] = dl.to_vec();
        }
    }
    (shots, out, corrections)
}

#[test]
fn candle_tract_and_onnxruntime_complete_the_same_keys() {
    complete_alike(fixture());
}

/// The transformer backbone: the same parity, and its graph (no recurrent node; per block one
/// softmax and two layer normalisations, one more before the decoder).
#[test]
fn the_transformer_backbone_completes_alike_in_candle_tract_and_onnxruntime() {
    let f = transformer_fixture();
    let ops = &f.onnx.summary().op_counts;
    assert!(!ops.contains_key("GRU"), "{ops:?}");
    assert_eq!((ops["Softmax"], ops["LayerNormalization"], ops["Range"]), (2, 5, 1), "{ops:?}");
    complete_alike(f);
}

/// Candle, tract and onnxruntime complete [`characters`] alike with the network of `f`, keys hit
/// or not, in a batch or alone.
fn complete_alike(f: &Fixture) {
    let chars = characters();
    let (poses, fixed): (Vec<_>, Vec<_>) = chars.iter().map(|k| (k.poses_f64(), k.fixed_bool())).unzip();
    let shots: Vec<zoo_arnn::inbetween::ShotKeyRefs> =
        (0..chars.len()).map(|c| (chars[c].frames.as_slice(), poses[c].as_slice(), fixed[c].as_slice())).collect();
    let candle: Vec<Vec<f64>> = zoo_arnn::inbetween::complete_shots(&f.model, &f.norm, &shots)
        .unwrap()
        .into_iter()
        .map(|c| c.concat())
        .collect();

    let km = KeyframeModel::from_bytes(&f.onnx.to_bytes()).unwrap();
    assert!(km.is_inbetween() && km.step_model().is_none());
    assert_eq!((km.dofs(), km.groups(), km.metadata().model_kind.as_str()), (D, G, "arnn"));
    let mut runner = km.runner(4).unwrap();
    runner.set_hit_keys(false);
    let tract = runtime_completion(&mut runner, &chars);
    let (inputs, ort, ort_correction) = onnxruntime_completion(f, &chars);

    for c in 0..chars.len() {
        let (ct, co, to) = (diffs(&candle[c], &tract[c]), diffs(&candle[c], &ort[c]), diffs(&tract[c], &ort[c]));
        eprintln!(
            "character {c} ({} frames): largest difference root (cm) / quaternion: candle-tract {:.1e} / {:.1e}, \
             candle-ort {:.1e} / {:.1e}, tract-ort {:.1e} / {:.1e}",
            chars[c].len(),
            ct.0,
            ct.1,
            co.0,
            co.1,
            to.0,
            to.1
        );
        assert!(agree(&candle[c], &tract[c]) && agree(&candle[c], &ort[c]) && agree(&tract[c], &ort[c]));
        // The network moves the poses away from the keys' Bezier curves: the parity is not that of
        // the curves alone.
        let moved = max_diff(&candle[c], &inputs[c].bezier);
        assert!(moved > 1e-3, "character {c}: the correction moves nothing ({moved:e})");
        // The graphs' own corrections, normalised units: candle against onnxruntime.
        let n = chars[c].len();
        let x = Tensor::from_slice(&inputs[c].features, (1, n, f.model.config().input_width()), &Device::Cpu).unwrap();
        let cc: Vec<f32> = f.model.correction(&x, None).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let tc = tract_correction(&f.onnx, &inputs[c].features, n);
        let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max) as f64;
        let (ct, co, to) = (diff(&cc, &tc), diff(&cc, &ort_correction[c]), diff(&tc, &ort_correction[c]));
        eprintln!(
            "character {c}: largest correction difference (normalised units) candle-tract {ct:.1e}, candle-ort \
             {co:.1e}, tract-ort {to:.1e}"
        );
        assert!(ct <= TOLERANCE && co <= TOLERANCE && to <= TOLERANCE, "{ct:e} {co:e} {to:e}");
    }

    // With the keys hit (the default): candle's completion with the same correction, every fixed
    // group of every key its key (a rotation up to its sign).
    runner.set_hit_keys(true);
    let hit = runtime_completion(&mut runner, &chars);
    let key_groups = zoo_protocol::inbetween::key_groups(3);
    for (c, k) in chars.iter().enumerate() {
        let mut want = candle[c].clone();
        let layout =
            zoo_protocol::keyhit::KeyLayout { dofs: D, frames: &k.frames, key_groups: &key_groups, quaternions: true };
        let poses: Vec<f64> = k.poses.iter().map(|v| *v as f64).collect();
        let fixes = |key: usize, g: usize| k.fixed.is_empty() || k.fixed[key * G + g] == 1.0;
        zoo_protocol::keyhit::hit_keys(layout, &poses, fixes, &mut want, &mut [0.0; D]);
        let s = scale(&want);
        let diff = diffs(&want, &hit[c]);
        let raw_miss = key_miss(k, &tract[c]);
        let miss = key_miss(k, &hit[c]);
        eprintln!(
            "character {c}: hit keys, candle-tract {:.1e} / {:.1e}; key miss {raw_miss:e} raw, {miss:e} hit",
            diff.0, diff.1
        );
        assert!(agree(&want, &hit[c]) && miss <= 1e-5 * s && raw_miss <= 1e-4 * s, "{miss:e} {raw_miss:e}");
    }

    // Alone, a character gives the frames it gets in the batch (the graph runs once per
    // character).
    let alone = runtime_completion(&mut runner, &chars[2..]);
    assert!(alone[0] == hit[2], "character 2 alone differs from its completion in the batch");
}

/// The fallback towards the curves: calibrated on validation windows as `zoo train arnn` does,
/// stored in the run folder's config, carried by the export, and applied alike by candle and the
/// runtime; `set_fallback(None)` gives the network alone, and a fallback that always acts gives
/// the keys' Bezier curves.
#[test]
fn the_fallback_towards_the_curves_runs_alike_in_candle_and_the_runtime() {
    let f = fixture();
    let valid = windows(4, 66, 0.5);
    let cal = zoo_arnn::inbetween_train::calibrate_fallback(&f.model, &f.norm, &valid).unwrap();
    let (calibrated, sizes) = (cal.fallback.expect("4 windows of 9 shots make enough intervals"), cal.sizes);
    assert_eq!(cal.ranges.len(), calibrated.gaps.len());
    for (r, g) in cal.ranges.iter().zip(&calibrated.gaps) {
        assert!(r.pose.is_finite() && r.change.is_finite() && r.up_to == g.up_to, "{r:?}");
        // A range where the network gains too little is the curves.
        assert_eq!(r.curves, *g == zoo_protocol::inbetween::GapFallback::curves(g.up_to), "{r:?} {g:?}");
    }
    // 4 windows keyed every 5/10/15/20/30 frames (12 + 6 + 4 + 3 + 2 intervals) and in the
    // transition layout (one interval each, 4 lengths).
    assert_eq!(sizes.len(), 4 * (27 + 4));
    calibrated.check().unwrap();
    // Thresholds at the median, so that the test's characters fall back in part.
    let median = zoo_protocol::inbetween::Fallback::calibrate(&sizes, 0.5, 2.0).unwrap();
    let src = Path::new(env!("CARGO_TARGET_TMPDIR")).join("parity_inbetween");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("parity_inbetween_fallback");
    std::fs::create_dir_all(&dir).unwrap();
    for file in ["model.safetensors", "normalization.json"] {
        std::fs::copy(src.join(file), dir.join(file)).unwrap();
    }
    let config = InbetweenConfig { fallback: Some(median.clone()), ..f.model.config().clone() };
    std::fs::write(dir.join("config.json"), serde_json::to_string_pretty(&config).unwrap()).unwrap();
    let (model, norm) = zoo_arnn::inbetween::load(&dir, &Device::Cpu).unwrap();
    assert_eq!(model.config().fallback.as_ref(), Some(&median));
    let onnx = zoo_arnn::export::export_run(&dir, &Default::default()).unwrap();

    let chars = characters();
    let (poses, fixed): (Vec<_>, Vec<_>) = chars.iter().map(|k| (k.poses_f64(), k.fixed_bool())).unzip();
    let shots: Vec<zoo_arnn::inbetween::ShotKeyRefs> =
        (0..chars.len()).map(|c| (chars[c].frames.as_slice(), poses[c].as_slice(), fixed[c].as_slice())).collect();
    let candle: Vec<Vec<f64>> =
        zoo_arnn::inbetween::complete_shots(&model, &norm, &shots).unwrap().into_iter().map(|c| c.concat()).collect();
    let km = KeyframeModel::from_bytes(&onnx.to_bytes()).unwrap();
    assert_eq!(km.default_fallback(), Some(&median));
    let mut runner = km.runner(4).unwrap();
    assert_eq!(runner.fallback(), Some(&median));
    runner.set_hit_keys(false);
    runner.set_foot_lock(false);
    let tract = runtime_completion(&mut runner, &chars);
    let weights = runner.fallback_weights().to_vec();
    eprintln!("fallback weights at the median thresholds: {weights:?}");
    assert_eq!(weights.len(), 4);
    assert!(weights.iter().any(|&w| w > 0.0), "{weights:?}");
    runner.set_fallback(None).unwrap();
    let alone = runtime_completion(&mut runner, &chars);
    assert!(runner.fallback_weights().is_empty());
    let inputs: Vec<ShotInputs> = chars
        .iter()
        .map(|k| zoo_arnn::inbetween::shot_inputs(&config, &norm, &k.frames, &k.poses_f64(), &k.fixed_bool()).unwrap())
        .collect();
    for c in 0..chars.len() {
        assert!(agree(&candle[c], &tract[c]), "character {c}: candle and tract differ with the fallback");
        // A character the fallback acted on moved towards its curves, the others are the network's.
        let (to_curves, alone_to_curves) =
            (max_diff(&tract[c], &inputs[c].bezier), max_diff(&alone[c], &inputs[c].bezier));
        if weights[c] > 0.0 {
            assert!(to_curves < alone_to_curves, "character {c}: {to_curves:e} >= {alone_to_curves:e}");
        } else {
            assert_eq!(tract[c], alone[c], "character {c}");
        }
        // The keys are still met as the network alone meets them.
        assert!(key_miss(&chars[c], &tract[c]) <= 1e-4 * scale(&tract[c]));
    }
    // A fallback that always acts: the curves themselves (f32 output).
    let always = zoo_protocol::inbetween::Fallback {
        gaps: vec![zoo_protocol::inbetween::GapFallback { up_to: 60, start: 0.0, full: 1e-9 }],
    };
    runner.set_fallback(Some(always)).unwrap();
    let curves = runtime_completion(&mut runner, &chars);
    for c in 0..chars.len() {
        if chars[c].fixed.is_empty() {
            let diff = max_diff(&curves[c], &inputs[c].bezier);
            assert!(diff <= 1e-5 * scale(&inputs[c].bezier), "character {c}: {diff:e} from the curves");
        } else {
            // Character 1's middle keys are partial: every interval touches one, and the
            // fallback (calibrated on whole keys) leaves them to the network.
            assert_eq!(curves[c], alone[c], "character {c}");
        }
    }
    assert_eq!(runner.fallback_weights(), &[1.0, 0.0, 1.0, 1.0]);
    let bad = zoo_protocol::inbetween::Fallback {
        gaps: vec![zoo_protocol::inbetween::GapFallback { up_to: 60, start: 0.5, full: 0.5 }],
    };
    let err = runner.set_fallback(Some(bad)).unwrap_err().to_string();
    assert!(err.contains("full above start"), "{err}");
}

/// tract's correction of one shot's features (`[1, n, width]`), the exported graph run directly.
fn tract_correction(exported: &OnnxModel, features: &[f32], n: usize) -> Vec<f32> {
    use tract_onnx::prelude::*;
    let w = features.len() / n;
    let mut model = tract_onnx::onnx().model_for_read(&mut exported.to_bytes().as_slice()).unwrap();
    model.set_input_fact(0, f32::fact([1, n, w]).into()).unwrap();
    let plan = model.into_optimized().unwrap().into_runnable().unwrap();
    let x = Tensor::from_shape::<f32>(&[1, n, w], features).unwrap();
    let out = plan.run(tvec![x.into()]).unwrap();
    out[0].try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec()
}

/// The largest difference of a completion from its keys in the groups they fix (a rotation up to
/// its sign).
fn key_miss(k: &Keys, out: &[f64]) -> f64 {
    let key_groups = zoo_protocol::inbetween::key_groups(3);
    let mut worst = 0.0f64;
    for (key, &frame) in k.frames.iter().enumerate() {
        for g in (0..G).filter(|&g| k.fixed.is_empty() || k.fixed[key * G + g] == 1.0) {
            let dofs: Vec<usize> = (0..D).filter(|&i| key_groups[i] == g).collect();
            let err = |s: f64| {
                dofs.iter().map(|&i| (out[frame * D + i] - s * k.poses[key * D + i] as f64).abs()).fold(0.0, f64::max)
            };
            worst = worst.max(if g == 0 { err(1.0) } else { err(1.0).min(err(-1.0)) });
        }
    }
    worst
}

/// The exported graph: the encoder, one bidirectional GRU node with `linear_before_reset = 1`
/// and the decoder, `features [batch, frames, 55]` to `correction [batch, frames, 15]`, the
/// in-betweening settings in the `zoo.keyframes` section.
#[test]
fn the_export_is_a_whole_shot_graph_with_its_section() {
    let f = fixture();
    let summary = f.onnx.summary();
    assert_eq!((summary.op_counts["GRU"], summary.op_counts["MatMul"]), (1, 3), "{:?}", summary.op_counts);
    let graph = f.onnx.proto().graph.as_ref().unwrap();
    let gru = graph.node.iter().find(|n| n.op_type == "GRU").unwrap();
    let attr = |name: &str| gru.attribute.iter().find(|a| a.name == name).unwrap();
    assert_eq!((attr("direction").s.as_slice(), attr("linear_before_reset").i), (&b"bidirectional"[..], 1));
    let w = graph.initializer.iter().find(|t| t.name == "bgru.l0.W").unwrap();
    assert_eq!(w.dims, [2, 3 * 16, 16]);
    let names: Vec<&str> = graph.input.iter().chain(&graph.output).map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["features", "correction"]);
    let m = zoo_format::MotionModelMetadata::read(&f.onnx.to_bytes(), "inbetween.onnx").unwrap();
    let task = m.task.as_keyframes().unwrap();
    let section = task.inbetween.as_ref().unwrap();
    assert_eq!((section.input_width, section.euler_axes.as_slice()), (3 * D + 2 + 2 * G, &[[2, 0, 1]; 3][..]));
    assert_eq!((section.mean.as_slice(), section.std.as_slice()), (f.norm.mean.as_slice(), f.norm.std.as_slice()));
    assert!(m.state.is_empty());
}

/// Bad keys and buffers: clear errors, the output untouched; a file whose graph does not fit
/// its section, and the step-graph loader given the whole-shot graph, are refused by name.
#[test]
fn bad_keys_buffers_and_graphs_are_refused() {
    let f = fixture();
    let km = KeyframeModel::from_bytes(&f.onnx.to_bytes()).unwrap();
    let mut runner = km.runner(1).unwrap();
    let chars = characters();
    let k = &chars[1];
    let mut out = vec![7f32; k.len() * D];
    let mut err = |keys: MotionKeys, out: &mut [f32]| runner.complete(keys, out).unwrap_err().to_string();
    let mut bad = k.fixed.clone();
    bad[1] = 0.0;
    let e = err(MotionKeys { fixed: &bad, ..k.motion() }, &mut out);
    assert!(e.contains("the first key is the start pose: it must fix every group"), "{e}");
    let e = err(MotionKeys { fixed: &k.fixed[..7], ..k.motion() }, &mut out);
    assert!(e.contains("7 key flags for 4 keys of 4 groups: expected 16"), "{e}");
    let mut nan = k.poses.clone();
    nan[D + 2] = f32::NAN;
    let e = err(MotionKeys { poses: &nan, ..k.motion() }, &mut out);
    assert!(e.contains("key 1 value 2 is NaN, not a finite number"), "{e}");
    let e = err(MotionKeys { frames: &[0, 8, 8, 30], ..k.motion() }, &mut out);
    assert!(e.contains("key frames must strictly increase"), "{e}");
    let e = err(k.motion(), &mut out[..30 * D]);
    assert!(e.contains(&format!("expected {} values (31 x 15), found 450", 31 * D)), "{e}");
    assert!(out.iter().all(|v| *v == 7.0), "a refused completion wrote its output");
    let e = runner.complete_batch(&[k.motion(), k.motion()], &mut [&mut out[..], &mut []]).unwrap_err().to_string();
    assert!(e.contains("2 characters, but the runner was made for at most 1"), "{e}");

    // The whole-shot graph is not a step graph.
    let e = MotionModel::from_bytes(&f.onnx.to_bytes()).unwrap_err().to_string();
    assert!(e.contains("whose whole-shot graph is not a step graph"), "{e}");
    // A humanoid ARNN step graph under an in-betweening section: its inputs are named.
    let (names, groups) = zoo_arnn::humanoid::pose_layout(&zoo_tests::inbetween_skeleton().names);
    let config = zoo_arnn::ArnnConfig::humanoid(zoo_tests::inbetween_skeleton(), names, groups)
        .sized_like(&zoo_arnn::ArnnConfig::tiny());
    let varmap = candle_nn::VarMap::new();
    let vb = zoo_nn::SeededVarMap::builder(&varmap, 3, candle_core::DType::F32, &Device::Cpu);
    zoo_arnn::Arnn::new(&config, vb).unwrap();
    let mut step = zoo_arnn::export::export_arnn(&config, &f.norm, &varmap).unwrap();
    let section = f.onnx.metadata_value(zoo_format::keys::KEYFRAMES).unwrap().to_string();
    step.set_metadata(zoo_format::keys::KEYFRAMES, &section);
    let e = LoadedModel::from_bytes(&step.to_bytes()).unwrap_err().to_string();
    assert!(e.contains("the in-betweening keyframes graph takes [(\"prev\""), "{e}");
    assert!(e.contains("one f32 input `features` [batch, frames, 55]"), "{e}");
}

/// A keyframes section written before the in-betweening design (no `inbetween` field) loads as
/// an ARNN step graph, and a step graph is still exported without the field.
#[test]
fn a_step_graph_file_without_the_inbetween_field_still_loads() {
    let onnx = zoo_tests::tiny_arnn_onnx();
    let section = onnx.metadata_value(zoo_format::keys::KEYFRAMES).unwrap();
    assert_eq!(section, r#"{"dofs":6,"groups":0,"key_groups":[]}"#);
    let km = KeyframeModel::from_bytes(&onnx.to_bytes()).unwrap();
    assert!(!km.is_inbetween() && km.step_model().is_some());
    let mut out = vec![0f32; 13 * 6];
    km.runner(1).unwrap().complete(MotionKeys::whole(&[0, 12], &[0.1; 12]), &mut out).unwrap();
    assert!(out.iter().all(|v| v.is_finite()));
}

/// `zoo export --weights f16|int8` files of the in-betweening design load and complete: finite
/// poses, every key hit (their distance from the f32 file is printed, not bounded here).
#[test]
fn narrow_weight_files_load_and_complete() {
    let f = fixture();
    let chars = characters();
    let f32_file = KeyframeModel::from_bytes(&f.onnx.to_bytes()).unwrap();
    let base = runtime_completion(&mut f32_file.runner(chars.len()).unwrap(), &chars);
    for width in [zoo_export::WeightWidth::F16, zoo_export::WeightWidth::Int8] {
        let narrow = zoo_export::with_weights(&f.onnx, width).unwrap();
        let km = KeyframeModel::from_bytes(&narrow.to_bytes()).unwrap();
        assert_eq!(km.metadata().weights, width);
        let out = runtime_completion(&mut km.runner(chars.len()).unwrap(), &chars);
        for (c, k) in chars.iter().enumerate() {
            assert!(out[c].iter().all(|v| v.is_finite()));
            assert!(key_miss(k, &out[c]) <= 1e-5 * scale(&out[c]), "{width}: character {c} misses a key");
            let (root, rot) = diffs(&base[c], &out[c]);
            eprintln!(
                "{width} weights, character {c}: largest difference from f32 root {root:.1e} cm, quaternion {rot:.1e}"
            );
        }
    }
}
