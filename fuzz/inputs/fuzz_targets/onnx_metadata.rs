//! The metadata of exported model files (`zoo_format::MotionModelMetadata::read`, which every
//! loader and `zoo bench` use before the graph, and `read_props` / `model_kind`). The first
//! byte picks the way in:
//! - 0: the rest as the bytes of an ONNX file;
//! - 1: a valid transition model's metadata (built here) with edits: the rest split at NUL
//!   bytes, each piece's first byte picking a key (an existing one, a task section, a new one,
//!   or, past them, a key to remove) and the remaining bytes its new value;
//! - 2: byte edits of that valid model's encoding (pairs of position, value).
//!
//! Each must be read or refused with an error, never panic. Metadata that is read must pass
//! its own check and survive a write (`to_props`) and re-read unchanged.
#![no_main]

use libfuzzer_sys::fuzz_target;
use prost::Message as _;
use zoo_format::pb::{ModelProto, StringStringEntryProto};
use zoo_format::{
    CoordinateFrame, FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo,
    MotionStatePair, MotionTask, TransitionTask, WeightWidth, keys, model_kind, read_props,
};

fn sample() -> MotionModelMetadata {
    MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: "rtn".into(),
        task: MotionTask::Transition(TransitionTask {
            past_frames: 10,
            transition_frames: 30,
            target_blend: 5,
            frame_dim: 6,
            offset_input: true,
            terrain: None,
            fallback: None,
            time_to_arrival: None,
            fallback_lengths: Vec::new(),
        }),
        config_json: "{\"hidden\": 4}".into(),
        normalization: [("x".to_string(), MotionMeanStd { mean: vec![0.0, 1.0], std: vec![1.0, 2.0] })].into(),
        skeleton: MotionSkeletonInfo {
            names: vec!["Hips".into(), "Spine".into()],
            parents: vec![-1, 0],
            offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
        },
        feature_layout: vec![MotionFeatureSegment { name: "x".into(), start: 0, len: 2 }],
        fps: 30.0,
        frame: CoordinateFrame::ZOO_CM,
        state: vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        weights: WeightWidth::F32,
    }
}

fn encode(props: &[(String, String)]) -> Vec<u8> {
    ModelProto {
        metadata_props: props
            .iter()
            .map(|(k, v)| StringStringEntryProto { key: k.clone(), value: v.clone() })
            .collect(),
        ..Default::default()
    }
    .encode_to_vec()
}

fn check(bytes: &[u8]) {
    let kind = model_kind(bytes);
    let props = read_props(bytes, "fuzz.onnx");
    assert!(kind.is_none() || props.is_ok());
    let Ok(m) = MotionModelMetadata::read(bytes, "fuzz.onnx") else { return };
    assert_eq!(kind.as_deref(), Some(m.model_kind.as_str()));
    m.check().expect("metadata that is read passes its check");
    assert!(m.fps.is_finite() && m.fps > 0.0, "fps {}", m.fps);
    let props = m.to_props();
    let back = MotionModelMetadata::read(&encode(&props), "fuzz-rewritten.onnx").expect("written metadata re-reads");
    assert_eq!(back, m);
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let valid = sample().to_props();
    match mode % 3 {
        0 => check(rest),
        1 => {
            let mut names: Vec<String> = valid.iter().map(|(k, _)| k.clone()).collect();
            for k in [keys::KEYFRAMES, keys::STITCH, keys::SYNTHESIS, keys::SYNTHESIS_REFINER_GRAPH, keys::START_GRAPH]
            {
                if !names.iter().any(|n| n == k) {
                    names.push(k.to_string());
                }
            }
            names.push("zoo.unknown".into());
            let mut props = valid.clone();
            for piece in rest.split(|b| *b == 0) {
                let Some((&k, value)) = piece.split_first() else { continue };
                let k = k as usize % (2 * names.len());
                let value = String::from_utf8_lossy(value).into_owned();
                if k < names.len() {
                    match props.iter_mut().find(|(n, _)| *n == names[k]) {
                        Some(p) => p.1 = value,
                        None => props.push((names[k].clone(), value)),
                    }
                } else {
                    props.retain(|(n, _)| *n != names[k - names.len()]);
                }
            }
            check(&encode(&props));
        }
        _ => {
            let mut bytes = encode(&valid);
            for pair in rest.chunks_exact(3) {
                let at = u16::from_le_bytes([pair[0], pair[1]]) as usize % bytes.len();
                bytes[at] = pair[2];
            }
            check(&bytes);
        }
    }
});
