//! The runtime's model loader on hostile files: an exported model must load or fail with an
//! error, never panic or abort. Three ways in, chosen by the first byte:
//! 0: the bytes as an ONNX file; 1: a valid transition model whose metadata entry (one of the
//! `zoo.*` keys, or a new one) is replaced by the input text; 2: byte edits of that valid
//! model's encoding.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;
use zoo_export::{Dim, GraphBuilder, OnnxModel, pb};
use zoo_runtime::LoadedModel;
use zoo_runtime::metadata::{
    FORMAT_VERSION, MotionFeatureSegment, MotionMeanStd, MotionModelMetadata, MotionSkeletonInfo, MotionStatePair,
    MotionTask, TransitionTask, keys,
};

const D: usize = 6;
const H: usize = 4;

/// A valid `rtn` transition model of 2 joints: `x_next = x + W h_next`, `h_next = tanh(V x + h)`.
fn valid() -> &'static (pb::ModelProto, Vec<(String, String)>) {
    static VALID: OnceLock<(pb::ModelProto, Vec<(String, String)>)> = OnceLock::new();
    VALID.get_or_init(|| {
        let group = || MotionMeanStd { mean: vec![0.0; D], std: vec![1.0; D] };
        let meta = MotionModelMetadata {
            format_version: FORMAT_VERSION,
            model_kind: "rtn".into(),
            task: MotionTask::Transition(TransitionTask {
                past_frames: 2,
                transition_frames: 4,
                target_blend: 1,
                frame_dim: D,
                offset_input: false,
                terrain: None,
                fallback: None,
                time_to_arrival: None,
                fallback_lengths: Vec::new(),
            }),
            config_json: "{}".into(),
            normalization: [
                ("x".to_string(), group()),
                ("velocity".to_string(), group()),
                ("offset".to_string(), group()),
            ]
            .into(),
            skeleton: MotionSkeletonInfo {
                names: vec!["Hips".into(), "Spine".into()],
                parents: vec![-1, 0],
                offsets: vec![[0.0; 3], [0.0, 10.0, 0.0]],
            },
            feature_layout: vec![MotionFeatureSegment { name: "x".into(), start: 0, len: D }],
            fps: 30.0,
            frame: zoo_runtime::metadata::CoordinateFrame::ZOO_CM,
            state: vec![MotionStatePair { input: "h".into(), output: "h_next".into() }],
        };
        let mut g = GraphBuilder::new("fuzz_step");
        let b = Dim::batch;
        let x = g.input("x", &[b(), Dim::Fixed(D)]);
        let h = g.input("h", &[b(), Dim::Fixed(H)]);
        let v = g.initializer_f32("v", &[H, D], &[0.1; H * D]);
        let z = g.gemm("enc", &x, &v, None, true);
        let z = g.add("sum", &z, &h);
        let h_next = g.tanh("h_next", &z);
        let w = g.initializer_f32("w", &[D, H], &[0.2; D * H]);
        let d = g.gemm("dec", &h_next, &w, None, true);
        let y = g.add("x_next", &x, &d);
        g.output("x_next", &y, &[b(), Dim::Fixed(D)]);
        g.output("h_next", &h_next, &[b(), Dim::Fixed(H)]);
        let model = g.finish().expect("the fuzz model builds");
        let props = meta.to_props();
        let proto = model.proto().clone();
        assert!(LoadedModel::from_bytes(&with_props(&proto, &props)).is_ok(), "the seed model loads");
        (proto, props)
    })
}

fn with_props(proto: &pb::ModelProto, props: &[(String, String)]) -> Vec<u8> {
    let mut p = proto.clone();
    p.metadata_props =
        props.iter().map(|(k, v)| pb::StringStringEntryProto { key: k.clone(), value: v.clone() }).collect();
    OnnxModel::from_proto(p).to_bytes()
}

const KEYS: [&str; 12] = [
    keys::FORMAT_VERSION,
    keys::MODEL_KIND,
    keys::TASK,
    keys::CONFIG,
    keys::NORMALIZATION,
    keys::SKELETON,
    keys::FEATURE_LAYOUT,
    keys::FPS,
    keys::FRAME,
    keys::STATE,
    keys::TRANSITION,
    keys::START_GRAPH,
    "zoo.unknown",
];

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let (proto, props) = valid();
    let bytes = match mode % 3 {
        0 => rest.to_vec(),
        1 => {
            let Some((&k, value)) = rest.split_first() else { return };
            let key = KEYS[k as usize % KEYS.len()];
            let value = String::from_utf8_lossy(value).into_owned();
            let mut props = props.clone();
            match props.iter_mut().find(|(pk, _)| pk == key) {
                Some(p) => p.1 = value,
                None => props.push((key.to_string(), value)),
            }
            with_props(proto, &props)
        }
        _ => {
            let mut bytes = with_props(proto, props);
            for edit in rest.chunks_exact(3) {
                let pos = u16::from_le_bytes([edit[0], edit[1]]) as usize % bytes.len();
                bytes[pos] = edit[2];
            }
            bytes
        }
    };
    let _ = LoadedModel::from_bytes(&bytes);
});
