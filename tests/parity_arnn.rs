//! Parity of the exported ARNN: candle (`zoo_arnn::complete`), tract (through `zoo-runtime`'s
//! `MotionRunner`) and onnxruntime (through `ort`, `load-dynamic`) complete the same keys with a
//! tiny ARNN, two characters in one batch.
//!
//! Where the expected numbers come from: candle's `zoo_arnn::complete`, the function `zoo
//! complete` runs (frame 0 is the first key, each later frame from the keys around it and the
//! previous output). The exported step graph is driven the same way on the host, the previous
//! output fed back as `prev`. Weights are fixed LCG draws (`ArnnConfig::tiny`), statistics and
//! keys fixed. Every pair must agree within 1e-4 (metres and radians) on every frame of the
//! whole completed sequences (40 frames).
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use zoo_arnn::luxo::preprocess::KeyedSequence;
use zoo_arnn::{Arnn, ArnnConfig, Normalization};
use zoo_runtime::{MotionModel, MotionTask};
use zoo_tests::onnxruntime::OrtSession;
use zoo_tests::toy_onnx::lcg;

const TOLERANCE: f64 = 1e-4;
const KEY_FRAMES: [usize; 4] = [0, 9, 24, 39];

/// A model of `config` with fixed LCG weights (stream `seed + k` for the k-th variable by name).
fn lcg_model(config: &ArnnConfig, seed: u64) -> (VarMap, Arnn) {
    let mut varmap = VarMap::new();
    let model = Arnn::new(config, VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu)).unwrap();
    let mut vars: Vec<(String, Vec<usize>)> =
        varmap.data().lock().unwrap().iter().map(|(n, v)| (n.clone(), v.dims().to_vec())).collect();
    vars.sort();
    for (k, (name, dims)) in vars.iter().enumerate() {
        let fan_in = if dims.len() == 2 { dims[1] } else { config.hidden };
        let t = Tensor::from_vec(
            lcg(seed + k as u64, dims.iter().product(), 1.5 / (fan_in as f32).sqrt()),
            dims.as_slice(),
            &Device::Cpu,
        )
        .unwrap();
        varmap.set_one(name, &t).unwrap();
    }
    (varmap, model)
}

fn fixture() -> (ArnnConfig, VarMap, Arnn, Normalization) {
    let config = ArnnConfig::tiny();
    let (varmap, model) = lcg_model(&config, 500);
    let norm = Normalization { mean: vec![0.5, 0.1, 0.0, 0.5, -1.1, -1.2], std: vec![0.4, 0.06, 0.3, 0.2, 0.5, 0.3] };
    (config, varmap, model, norm)
}

/// The keys of character `c`: a hop-like sequence, different per character.
fn keys(c: usize) -> Vec<Vec<f64>> {
    let r = lcg(40 + c as u64, KEY_FRAMES.len() * 6, 0.2);
    KEY_FRAMES
        .iter()
        .enumerate()
        .map(|(k, &f)| {
            let base = [0.02 * f as f64, 0.02 + 0.1 * (k % 2) as f64, 0.0, 0.5, -1.1, -1.2];
            (0..6).map(|j| base[j] + r[k * 6 + j] as f64).collect()
        })
        .collect()
}

/// Inputs of frame `t` for one character: `key_a`, `key_b`, `t_rel`.
fn step_inputs(poses: &[Vec<f64>], t: usize) -> (Vec<f32>, Vec<f32>, f32) {
    let (a, b, rel) = KeyedSequence::interval(&KEY_FRAMES, t);
    let f = |p: &[f64]| p.iter().map(|v| *v as f32).collect::<Vec<f32>>();
    (f(&poses[a]), f(&poses[b]), rel as f32)
}

fn max_diff(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().flatten().zip(b.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn candle_tract_and_onnxruntime_complete_the_same_keys() {
    let (config, varmap, model, norm) = fixture();
    let chars = 2;
    let last = *KEY_FRAMES.last().unwrap();
    let all_keys: Vec<Vec<Vec<f64>>> = (0..chars).map(keys).collect();
    let candle: Vec<Vec<Vec<f64>>> =
        all_keys.iter().map(|k| zoo_arnn::complete_raw(&model, &norm, &KEY_FRAMES, k).unwrap()).collect();
    assert_eq!(candle[0].len(), last + 1);
    // The completion moves: not the keys held still.
    assert!(max_diff(&candle[0][..1], &candle[0][20..21]) > 0.05);

    let onnx = zoo_arnn::export::export_arnn(&config, &norm, &varmap).unwrap();
    let summary = onnx.summary();
    // SELU after both layers of each feature net, after each GRU and between the decoder layers.
    assert_eq!(summary.op_counts["Exp"], 10, "{:?}", summary.op_counts);
    // Three feature nets of 2 layers, two GRU cells of 2 projections, a decoder of 3.
    assert_eq!(summary.op_counts["Gemm"], 13, "{:?}", summary.op_counts);

    // tract through the runtime: both characters in one batch.
    let tract_model = MotionModel::from_bytes(&onnx.to_bytes()).unwrap();
    assert_eq!(tract_model.metadata().model_kind, "arnn");
    assert_eq!(
        tract_model.metadata().task,
        MotionTask::Keyframes(zoo_format::KeyframesTask {
            dofs: config.dofs,
            groups: 0,
            key_groups: vec![],
            inbetween: None
        })
    );
    let names: Vec<&str> = tract_model.inputs().iter().map(|i| i.name.as_str()).collect();
    assert_eq!(names, ["prev", "key_a", "key_b", "t_rel"]);
    let mut runner = tract_model.runner().unwrap();
    let mut states: Vec<_> = (0..chars).map(|_| tract_model.new_state()).collect();
    let mut tract: Vec<Vec<Vec<f64>>> = all_keys.iter().map(|k| vec![k[0].clone()]).collect();
    // onnxruntime: the state passed by hand.
    let mut ort = OrtSession::new(&onnx);
    let h = config.hidden;
    let (mut h1, mut h2) = (vec![0f32; chars * h], vec![0f32; chars * h]);
    let mut ort_out: Vec<Vec<Vec<f64>>> = all_keys.iter().map(|k| vec![k[0].clone()]).collect();
    for t in 1..=last {
        let (mut prev, mut ka, mut kb, mut tr, mut prev_ort) = (vec![], vec![], vec![], vec![], vec![]);
        for c in 0..chars {
            let (a, b, rel) = step_inputs(&all_keys[c], t);
            prev.extend(tract[c][t - 1].iter().map(|v| *v as f32));
            prev_ort.extend(ort_out[c][t - 1].iter().map(|v| *v as f32));
            ka.extend(a);
            kb.extend(b);
            tr.push(rel);
        }
        let mut pose = vec![0f32; chars * 6];
        runner.step_batch(&mut states, &[&prev, &ka, &kb, &tr], &mut [&mut pose]).unwrap();
        let out = ort.run(
            &[
                ("prev", chars, &prev_ort),
                ("key_a", chars, &ka),
                ("key_b", chars, &kb),
                ("t_rel", chars, &tr),
                ("h1", chars, &h1),
                ("h2", chars, &h2),
            ],
            &["pose", "h1_next", "h2_next"],
        );
        (h1, h2) = (out[1].clone(), out[2].clone());
        for c in 0..chars {
            tract[c].push(pose[c * 6..(c + 1) * 6].iter().map(|v| *v as f64).collect());
            ort_out[c].push(out[0][c * 6..(c + 1) * 6].iter().map(|v| *v as f64).collect());
        }
    }
    for c in 0..chars {
        let (ct, co, to) =
            (max_diff(&candle[c], &tract[c]), max_diff(&candle[c], &ort_out[c]), max_diff(&tract[c], &ort_out[c]));
        eprintln!("character {c}: largest difference candle-tract {ct:e}, candle-ort {co:e}, tract-ort {to:e}");
        assert!(
            ct <= TOLERANCE && co <= TOLERANCE && to <= TOLERANCE,
            "character {c}: candle-tract {ct:e}, candle-ort {co:e}, tract-ort {to:e}"
        );
    }
}

/// The runtime's keyframes task (`zoo_runtime::keyframes`, tract) against candle's
/// `zoo_arnn::complete`: two characters of different lengths in one batch, and one alone.
#[test]
fn keyframe_runner_matches_candle() {
    use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
    let (config, varmap, model, norm) = fixture();
    let onnx = zoo_arnn::export::export_arnn(&config, &norm, &varmap).unwrap();
    let km = KeyframeModel::new(MotionModel::from_bytes(&onnx.to_bytes()).unwrap()).unwrap();
    assert_eq!(km.dofs(), 6);
    // Character 0: every key (40 frames); character 1: its first three keys (25 frames).
    let frames: [&[usize]; 2] = [&KEY_FRAMES, &KEY_FRAMES[..3]];
    let poses: Vec<Vec<Vec<f64>>> = (0..2).map(|c| keys(c)[..frames[c].len()].to_vec()).collect();
    let flat: Vec<Vec<f32>> = poses.iter().map(|p| p.iter().flatten().map(|v| *v as f32).collect()).collect();
    let candle: Vec<Vec<Vec<f64>>> =
        (0..2).map(|c| zoo_arnn::complete(&model, &norm, frames[c], &poses[c]).unwrap()).collect();
    let mut runner = km.runner(2).unwrap();
    let mut out: Vec<Vec<f32>> = (0..2).map(|c| vec![f32::NAN; (frames[c].last().unwrap() + 1) * 6]).collect();
    let keys_of = |c: usize| MotionKeys::whole(frames[c], &flat[c]);
    {
        let (a, b) = out.split_at_mut(1);
        runner.complete_batch(&[keys_of(0), keys_of(1)], &mut [&mut a[0], &mut b[0]]).unwrap();
    }
    let as_frames = |o: &[f32]| o.chunks(6).map(|f| f.iter().map(|v| *v as f64).collect()).collect::<Vec<Vec<f64>>>();
    for c in 0..2 {
        let diff = max_diff(&candle[c], &as_frames(&out[c]));
        eprintln!(
            "keyframes runner, character {c} ({} frames): largest difference from candle {diff:e}",
            out[c].len() / 6
        );
        assert!(diff <= TOLERANCE, "character {c}: {diff:e}");
    }
    // Alone, the second character gives the same frames as in the batch.
    let mut alone = vec![0f32; out[1].len()];
    runner.complete(keys_of(1), &mut alone).unwrap();
    let diff = alone.iter().zip(&out[1]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(diff <= 1e-5, "batch of 2 vs alone: {diff:e}");

    // Every key is hit to float precision; the network's own output (no correction) misses
    // them, and is candle's `complete_raw`.
    let flat_ref = &flat;
    let miss = |o: &[f32], c: usize| {
        frames[c]
            .iter()
            .enumerate()
            .flat_map(|(k, &f)| (0..6).map(move |i| (o[f * 6 + i] - flat_ref[c][k * 6 + i]).abs()))
            .fold(0.0f32, f32::max)
    };
    for c in 0..2 {
        assert!(miss(&out[c], c) <= 1e-6, "character {c}: a key missed by {:e}", miss(&out[c], c));
    }
    runner.set_hit_keys(false);
    let mut raw = vec![0f32; out[0].len()];
    runner.complete(keys_of(0), &mut raw).unwrap();
    runner.set_hit_keys(true);
    let raw_candle = zoo_arnn::complete_raw(&model, &norm, frames[0], &poses[0]).unwrap();
    let diff = max_diff(&raw_candle, &as_frames(&raw));
    eprintln!("network's own key miss {:e}, after the correction {:e}", miss(&raw, 0), miss(&out[0], 0));
    assert!(diff <= TOLERANCE, "raw: {diff:e}");
    assert!(miss(&raw, 0) > 1e-3, "the tiny network hits every key by itself: the correction is not tested");

    // Bad keys and buffers: clear errors, the output untouched.
    let mut buf = vec![7f32; 40 * 6];
    let err = |runner: &mut zoo_runtime::keyframes::KeyframeRunner, k: MotionKeys, buf: &mut [f32]| {
        runner.complete(k, buf).expect_err("accepted").to_string()
    };
    let e = err(&mut runner, MotionKeys::whole(&[0, 24, 9, 39], &flat[0]), &mut buf);
    assert!(e.contains("character 0: key 2 is at frame 9 but key 1 is at frame 24"), "{e}");
    let mut nan = flat[0].clone();
    nan[8] = f32::NAN;
    let e = err(&mut runner, MotionKeys::whole(&KEY_FRAMES, &nan), &mut buf);
    assert!(e.contains("key 1 value 2 is NaN, not a finite number"), "{e}");
    let e = err(&mut runner, MotionKeys::whole(&KEY_FRAMES, &flat[0][..18]), &mut buf);
    assert!(e.contains("18 pose values for 4 keys of 6 values"), "{e}");
    let e = err(&mut runner, MotionKeys::whole(&[0, 9, 24, 50], &flat[0]), &mut buf);
    assert!(e.contains("expected 306 values (51 x 6), found 240"), "{e}");
    let e = err(&mut runner, MotionKeys::whole(&[3, 9, 24, 39], &flat[0]), &mut buf);
    assert!(e.contains("key frames start at 0"), "{e}");
    assert!(buf.iter().all(|v| *v == 7.0), "a refused completion wrote its output");
    let e = runner
        .complete_batch(&[keys_of(0), keys_of(0), keys_of(0)], &mut [&mut buf[..], &mut [], &mut []])
        .unwrap_err()
        .to_string();
    assert!(e.contains("3 characters, but the runner was made for at most 2"), "{e}");
}

/// Issue 13, the humanoid: an ARNN with key groups (partial keys) exported with its `fixed_a`,
/// `fixed_b` inputs; candle's `complete_partial`, the runtime's keyframes task (tract) and
/// onnxruntime complete the same partial keys (two of four keys partial).
#[test]
fn partial_keys_complete_the_same_in_candle_tract_and_onnxruntime() {
    use zoo_runtime::keyframes::{KeyframeModel, MotionKeys};
    let names: Vec<String> = ["Hips", "Spine", "Head"].iter().map(|s| s.to_string()).collect();
    let skeleton = zoo_arnn::HumanoidSkeleton {
        names: names.clone(),
        parents: vec![-1, 0, 1],
        offsets: vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 20.0, 0.0]],
        fps: 30.0,
    };
    let (dof_names, groups) = zoo_arnn::humanoid::pose_layout(&names);
    let config = ArnnConfig::humanoid(skeleton, dof_names, groups).sized_like(&ArnnConfig::tiny());
    let (d, g) = (config.dofs, config.groups());
    assert_eq!((d, g, config.key_width()), (15, 4, 19));
    let (varmap, model) = lcg_model(&config, 900);
    let mut mean = vec![0.0, 90.0, 0.0];
    mean.extend([0.9, 0.1, 0.0, 0.0].repeat(3));
    let mut std = vec![40.0, 5.0, 40.0];
    std.extend([0.1, 0.2, 0.3, 0.2].repeat(3));
    let norm = Normalization { mean, std };
    let r = lcg(77, KEY_FRAMES.len() * d, 1.0);
    let poses: Vec<Vec<f64>> = (0..KEY_FRAMES.len())
        .map(|k| (0..d).map(|i| norm.mean[i] + norm.std[i] * r[k * d + i] as f64).collect())
        .collect();
    let fixed: Vec<Vec<bool>> =
        vec![vec![true; 4], vec![true, false, true, false], vec![false, true, false, false], vec![true; 4]];
    let candle = zoo_arnn::complete_partial_raw(&model, &norm, &KEY_FRAMES, &poses, &fixed).unwrap();
    // The flags matter: whole keys complete differently.
    let whole = zoo_arnn::complete_raw(&model, &norm, &KEY_FRAMES, &poses).unwrap();
    assert!(max_diff(&candle, &whole) > 1e-3, "partial keys changed nothing");

    let onnx = zoo_arnn::export::export_arnn(&config, &norm, &varmap).unwrap();
    let km = KeyframeModel::new(MotionModel::from_bytes(&onnx.to_bytes()).unwrap()).unwrap();
    assert_eq!((km.dofs(), km.groups()), (d, g));
    assert_eq!(km.metadata().skeleton.names, names);
    let flat: Vec<f32> = poses.iter().flatten().map(|v| *v as f32).collect();
    let flags: Vec<f32> = fixed.iter().flatten().map(|&f| if f { 1.0 } else { 0.0 }).collect();
    let mut runner = km.runner(1).unwrap();
    let mut out = vec![0f32; (KEY_FRAMES[3] + 1) * d];
    runner.set_hit_keys(false);
    runner.complete(MotionKeys { frames: &KEY_FRAMES, poses: &flat, fixed: &flags }, &mut out).unwrap();
    runner.set_hit_keys(true);
    let tract: Vec<Vec<f64>> = out.chunks(d).map(|f| f.iter().map(|v| *v as f64).collect()).collect();
    // onnxruntime, stepped by hand.
    let mut ort = OrtSession::new(&onnx);
    let h = config.hidden;
    let (mut h1, mut h2) = (vec![0f32; h], vec![0f32; h]);
    let mut ort_out = vec![poses[0].clone()];
    for t in 1..=KEY_FRAMES[3] {
        let (a, b, rel) = KeyedSequence::interval(&KEY_FRAMES, t);
        let prev: Vec<f32> = ort_out[t - 1].iter().map(|v| *v as f32).collect();
        let out = ort.run(
            &[
                ("prev", 1, &prev),
                ("key_a", 1, &flat[a * d..(a + 1) * d]),
                ("key_b", 1, &flat[b * d..(b + 1) * d]),
                ("t_rel", 1, &[rel as f32]),
                ("fixed_a", 1, &flags[a * g..(a + 1) * g]),
                ("fixed_b", 1, &flags[b * g..(b + 1) * g]),
                ("h1", 1, &h1),
                ("h2", 1, &h2),
            ],
            &["pose", "h1_next", "h2_next"],
        );
        (h1, h2) = (out[1].clone(), out[2].clone());
        ort_out.push(out[0].iter().map(|v| *v as f64).collect());
    }
    let (ct, co, to) = (max_diff(&candle, &tract), max_diff(&candle, &ort_out), max_diff(&tract, &ort_out));
    eprintln!("partial keys: largest difference candle-tract {ct:e}, candle-ort {co:e}, tract-ort {to:e}");
    // Root positions are in centimetres here: the tolerance is relative to the values' scale.
    let scale = 1.0 + candle.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(ct <= TOLERANCE * scale && co <= TOLERANCE * scale && to <= TOLERANCE * scale, "{ct:e} {co:e} {to:e}");
    // With the keys hit: candle and tract agree, and every fixed group of every key is its key
    // (a rotation up to its sign).
    let hit = zoo_arnn::complete_partial(&model, &norm, &KEY_FRAMES, &poses, &fixed).unwrap();
    let mut hit_tract = vec![0f32; out.len()];
    runner.complete(MotionKeys { frames: &KEY_FRAMES, poses: &flat, fixed: &flags }, &mut hit_tract).unwrap();
    let hit_tract: Vec<Vec<f64>> = hit_tract.chunks(d).map(|f| f.iter().map(|v| *v as f64).collect()).collect();
    assert!(max_diff(&hit, &hit_tract) <= TOLERANCE * scale, "{:e}", max_diff(&hit, &hit_tract));
    let group_miss = |o: &[Vec<f64>], k: usize, gr: usize| {
        let dofs: Vec<usize> = (0..d).filter(|&i| config.key_groups[i] == gr).collect();
        let err = |s: f64| dofs.iter().map(|&i| (o[KEY_FRAMES[k]][i] - s * poses[k][i]).abs()).fold(0.0, f64::max);
        if gr == 0 { err(1.0) } else { err(1.0).min(err(-1.0)) }
    };
    let (mut raw_miss, mut hit_miss) = (0.0f64, 0.0f64);
    for k in 0..KEY_FRAMES.len() {
        for gr in (0..g).filter(|&gr| fixed[k][gr]) {
            raw_miss = raw_miss.max(group_miss(&candle, k, gr));
            hit_miss = hit_miss.max(group_miss(&hit, k, gr).max(group_miss(&hit_tract, k, gr)));
        }
    }
    eprintln!("partial keys: network's own key miss {raw_miss:e}, after the correction {hit_miss:e}");
    assert!(raw_miss > 1e-3 && hit_miss <= 1e-5 * scale, "{raw_miss:e} {hit_miss:e}");
    // Bad flags: clear errors.
    let mut bad = flags.clone();
    bad[0] = 0.0;
    let e = runner
        .complete(MotionKeys { frames: &KEY_FRAMES, poses: &flat, fixed: &bad }, &mut out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("the first key is the start pose"), "{e}");
    let e = runner
        .complete(MotionKeys { frames: &KEY_FRAMES, poses: &flat, fixed: &flags[..5] }, &mut out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("5 key flags for 4 keys of 4 groups"), "{e}");
    // The lamp's model has no groups: flags are refused.
    let (lc, lv, _, ln) = fixture();
    let lamp = KeyframeModel::new(
        MotionModel::from_bytes(&zoo_arnn::export::export_arnn(&lc, &ln, &lv).unwrap().to_bytes()).unwrap(),
    )
    .unwrap();
    let mut lr = lamp.runner(1).unwrap();
    let lamp_keys = vec![0f32; 4 * 6];
    let e = lr
        .complete(MotionKeys { frames: &KEY_FRAMES, poses: &lamp_keys, fixed: &[1.0; 4] }, &mut vec![0f32; 40 * 6])
        .unwrap_err();
    assert!(e.to_string().contains("trained on whole keys only"), "{e}");
}
