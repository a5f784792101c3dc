//! Tests of the metadata: round trips, and every refusal naming its key and fix.

use super::*;

fn transition() -> TransitionTask {
    TransitionTask {
        past_frames: 10,
        transition_frames: 30,
        target_blend: 5,
        frame_dim: 6,
        offset_input: true,
        terrain: None,
        fallback: None,
        time_to_arrival: None,
        fallback_lengths: Vec::new(),
    }
}

fn sample() -> MotionModelMetadata {
    MotionModelMetadata {
        format_version: FORMAT_VERSION,
        model_kind: "toy".into(),
        task: MotionTask::Transition(transition()),
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
        weights: crate::WeightWidth::F32,
    }
}

fn lookup(props: &[(String, String)]) -> impl Fn(&str) -> Option<String> + '_ {
    |k| props.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone())
}

fn edited(edit: impl FnOnce(&mut Vec<(String, String)>)) -> Result<MotionModelMetadata, FormatError> {
    let mut props = sample().to_props();
    edit(&mut props);
    MotionModelMetadata::from_props(lookup(&props))
}

fn set(props: &mut [(String, String)], key: &str, value: &str) {
    props.iter_mut().find(|(k, _)| k == key).unwrap().1 = value.to_string();
}

#[test]
fn model_kind_is_read_without_the_graph() {
    use prost::Message as _;
    let entry = |key: &str, value: &str| pb::StringStringEntryProto { key: key.into(), value: value.into() };
    let proto = pb::ModelProto {
        metadata_props: vec![entry(keys::TASK, "stitch"), entry(keys::MODEL_KIND, "rmr")],
        ..Default::default()
    };
    assert_eq!(model_kind(&proto.encode_to_vec()).as_deref(), Some("rmr"));
    let bare = pb::ModelProto { metadata_props: vec![entry(keys::TASK, "stitch")], ..Default::default() };
    assert_eq!(model_kind(&bare.encode_to_vec()), None);
    assert_eq!(model_kind(b"not an onnx file \xff\xff"), None);
}

#[test]
fn the_frame_is_required_and_checked() {
    let err = edited(|p| p.retain(|(k, _)| k != keys::FRAME)).unwrap_err();
    assert!(matches!(&err, FormatError::MissingMetadata { key } if key == keys::FRAME), "{err}");
    let err = edited(|p| set(p, keys::FRAME, r#"{"metres_per_unit": 0, "up_axis": "y", "handedness": "right"}"#))
        .unwrap_err();
    assert!(err.to_string().contains("metres_per_unit must be a positive number"), "{err}");
    let err = edited(|p| set(p, keys::FRAME, r#"{"metres_per_unit": 1, "up_axis": "x", "handedness": "right"}"#))
        .unwrap_err();
    assert!(err.to_string().contains(keys::FRAME), "{err}");
}

#[test]
fn the_weight_width_is_required_and_checked() {
    for width in crate::WeightWidth::ALL {
        let m = edited(|p| set(p, keys::WEIGHTS, width.name())).unwrap();
        assert_eq!(m.weights, width);
    }
    let err = edited(|p| p.retain(|(k, _)| k != keys::WEIGHTS)).unwrap_err();
    assert!(matches!(&err, FormatError::MissingMetadata { key } if key == keys::WEIGHTS), "{err}");
    let err = edited(|p| set(p, keys::WEIGHTS, "int4")).unwrap_err();
    assert!(err.to_string().contains("`int4` is not a weight width (f32, f16, int8)"), "{err}");
    // A version-4 file (every weight f32, no `zoo.weights`) is asked to re-export.
    let err = edited(|p| {
        p.retain(|(k, _)| k != keys::WEIGHTS);
        set(p, keys::FORMAT_VERSION, "4");
    })
    .unwrap_err();
    assert!(matches!(&err, FormatError::FormatTooOld { found, .. } if found == "4"), "{err}");
    assert!(err.to_string().contains("zoo export --onnx RUN_DIR"), "{err}");
}

#[test]
fn round_trip() {
    let m = sample();
    let props = m.to_props();
    assert_eq!(props.last().unwrap().0, keys::TRANSITION);
    assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m);
    let step = MotionModelMetadata { task: MotionTask::Step, ..sample() };
    let props = step.to_props();
    assert!(props.iter().all(|(k, _)| k != keys::TRANSITION), "a step model has no section");
    assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), step);
}

#[test]
fn unknown_version_is_refused_before_other_keys() {
    let props = vec![(keys::FORMAT_VERSION.to_string(), "7".to_string())];
    let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
    assert!(matches!(err, FormatError::UnknownFormatVersion { .. }), "{err}");
    assert!(err.to_string().contains("version 7"), "{err}");
}

#[test]
fn a_version_1_file_is_asked_to_re_export() {
    let props = vec![(keys::FORMAT_VERSION.to_string(), "1".to_string())];
    let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
    assert!(matches!(&err, FormatError::FormatTooOld { found, supported: FORMAT_VERSION } if found == "1"), "{err}");
    assert!(err.to_string().contains("re-export") && err.to_string().contains("zoo export --onnx"), "{err}");
}

#[test]
fn missing_key_is_named() {
    let err = edited(|p| p.retain(|(k, _)| k != keys::SKELETON)).unwrap_err();
    assert!(err.to_string().contains("zoo.skeleton"), "{err}");
}

#[test]
fn a_missing_task_section_is_named() {
    let err = edited(|p| p.retain(|(k, _)| k != keys::TRANSITION)).unwrap_err();
    assert!(matches!(&err, FormatError::MissingMetadata { key } if key == keys::TRANSITION), "{err}");
    assert!(err.to_string().contains("re-export"), "{err}");
}

#[test]
fn a_task_section_missing_a_field_is_refused() {
    let err = edited(|p| set(p, keys::TRANSITION, r#"{"past_frames": 10, "target_blend": 5}"#)).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::TRANSITION), "{err}");
    assert!(err.to_string().contains("transition_frames"), "{err}");
}

#[test]
fn a_malformed_task_section_is_refused() {
    let err = edited(|p| set(p, keys::TRANSITION, "{past_frames: 10")).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::TRANSITION), "{err}");
    let err = edited(|p| {
        let t = json(&transition()).replace("\"past_frames\":10", "\"past_frames\":\"ten\"");
        set(p, keys::TRANSITION, &t)
    })
    .unwrap_err();
    assert!(err.to_string().contains("zoo.transition"), "{err}");
    let err = edited(|p| {
        let t = json(&transition()).replace("}", ",\"blend\":3}");
        set(p, keys::TRANSITION, &t)
    })
    .unwrap_err();
    assert!(err.to_string().contains("unknown field `blend`"), "{err}");
}

#[test]
fn a_bad_task_section_value_is_refused() {
    let err = edited(|p| {
        let t = json(&TransitionTask { frame_dim: 7, ..transition() });
        set(p, keys::TRANSITION, &t)
    })
    .unwrap_err();
    assert!(err.to_string().contains("frame_dim 7"), "{err}");
}

#[test]
fn an_unknown_task_is_refused_with_the_known_ones() {
    let err = edited(|p| set(p, keys::TASK, "dance")).unwrap_err();
    assert!(matches!(&err, FormatError::UnknownTask { task, .. } if task == "dance"), "{err}");
    assert!(
        err.to_string().contains("transition, keyframes, stitch, synthesis, step") && err.to_string().contains("`toy`"),
        "{err}"
    );
}

#[test]
fn bad_skeleton_and_std_are_refused() {
    let mut m = sample();
    m.skeleton.parents = vec![-1, 5];
    let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
    assert!(err.to_string().contains("`Spine`"), "{err}");
    assert!(m.check().is_err(), "exporters run the same check");
    let mut m = sample();
    m.normalization.get_mut("x").unwrap().std[1] = 0.0;
    let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
    assert!(err.to_string().contains("std 0"), "{err}");
    let mut m = sample();
    m.normalization.get_mut("x").unwrap().mean[0] = f32::NAN;
    let err = m.check().unwrap_err();
    assert!(err.to_string().contains("group `x` has mean NaN at index 0"), "{err}");
    // The skeleton must be the one the transition section's frames are for.
    let mut m = sample();
    m.skeleton.names.push("Head".into());
    m.skeleton.parents.push(1);
    m.skeleton.offsets.push([0.0, 5.0, 0.0]);
    let err = MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap_err();
    assert!(err.to_string().contains("frame_dim is 6 but the skeleton has 3 joints (9 values)"), "{err}");
}

#[test]
fn bad_fps_and_config_are_refused() {
    let err = edited(|p| set(p, keys::FPS, "fast")).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::FPS), "{err}");
    let err = edited(|p| set(p, keys::FPS, "-30")).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::FPS), "{err}");
    let err = edited(|p| set(p, keys::CONFIG, "{oops")).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::CONFIG), "{err}");
}

#[test]
fn normalize_round_trip_and_skeleton_conversion() {
    let m = sample();
    let g = &m.normalization["x"];
    let mut v = [3.0, 5.0];
    g.normalize(&mut v);
    assert_eq!(v, [3.0, 2.0]);
    g.denormalize(&mut v);
    assert_eq!(v, [3.0, 5.0]);
    let s = m.skeleton.to_skeleton();
    assert_eq!(s.parents, vec![None, Some(0)]);
    assert_eq!(MotionSkeletonInfo::from_skeleton(&s), m.skeleton);
}

fn stitch_sample() -> MotionModelMetadata {
    // A 3-joint chain: hips (lower body), two "feet" as the contact joints.
    let skeleton = MotionSkeletonInfo {
        names: vec!["Hips".into(), "LeftFoot".into(), "RightFoot".into()],
        parents: vec![-1, 0, 0],
        offsets: vec![[0.0; 3], [10.0, -40.0, 0.0], [-10.0, -40.0, 0.0]],
    };
    let task = StitchTask {
        window: 8,
        stride: 4,
        blend_frames: 3,
        pre_blend: false,
        fallback: None,
        layout: StitchLayout {
            lower_body: vec![0, 1, 2],
            contacts: [1, 1, 2, 2],
            contact_thresholds: [2.0; 4],
            planted: [4.0; 4],
            forward_axis: glam::DVec3::Z,
        },
    };
    let dim = task.dim(3);
    assert_eq!(dim, 7 + 6 * 3 + 4 * 3);
    MotionModelMetadata {
        model_kind: "rmr".into(),
        task: MotionTask::Stitch(task),
        normalization: [("x".to_string(), MotionMeanStd { mean: vec![0.0; dim], std: vec![1.0; dim] })].into(),
        skeleton,
        feature_layout: vec![MotionFeatureSegment { name: "pose".into(), start: 0, len: dim }],
        state: vec![],
        ..sample()
    }
}

#[test]
fn every_task_round_trips_through_its_section() {
    let stitch = stitch_sample();
    let keyframes = MotionModelMetadata {
        model_kind: "arnn".into(),
        task: MotionTask::Keyframes(KeyframesTask { dofs: 2, groups: 2, key_groups: vec![0, 1], inbetween: None }),
        ..sample()
    };
    let synthesis = MotionModelMetadata {
        model_kind: "rnn-gmm".into(),
        task: MotionTask::Synthesis(SynthesisTask {
            frame_dim: 11,
            components: 2,
            references: vec![[0.0, 0.0, 0.0, 1.0]; 2],
            refiner: Some(SynthesisRefiner { effectors: vec![1], mean: vec![0.0; 6], std: vec![1.0; 6] }),
        }),
        normalization: [("x".to_string(), MotionMeanStd { mean: vec![0.0; 11], std: vec![1.0; 11] })].into(),
        ..sample()
    };
    for m in [sample(), stitch, keyframes, synthesis.clone()] {
        let mut props = m.to_props();
        assert_eq!(props.last().unwrap().0, m.task.section_key().unwrap());
        if m.task.kind() == MotionTaskKind::Synthesis {
            props.push((keys::SYNTHESIS_REFINER_GRAPH.into(), "AAAA".into()));
        }
        assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m, "{}", m.task.name());
        assert_eq!(MotionTaskKind::from_name(m.task.name()), Some(m.task.kind()));
    }
    // A refiner section without its graph (or the reverse) is refused.
    let err = MotionModelMetadata::from_props(lookup(&synthesis.to_props())).unwrap_err();
    assert!(err.to_string().contains(keys::SYNTHESIS_REFINER_GRAPH), "{err}");
}

/// An in-betweening keyframes model on `sample()`'s skeleton of 2 joints: poses of 11 values in
/// 3 groups, 3 * 11 + 2 + 2 * 3 = 41 features per frame.
fn inbetween_sample() -> MotionModelMetadata {
    let section = InbetweenSection {
        euler_axes: vec![[2, 0, 1]; 2],
        gap_unit: 30.0,
        mean: vec![0.25; 11],
        std: vec![0.5; 11],
        input_width: 41,
        residual: zoo_protocol::inbetween::Residual::KeyLerp,
        fallback: Some(zoo_protocol::inbetween::Fallback {
            gaps: vec![
                zoo_protocol::inbetween::GapFallback { up_to: 12, start: 0.1, full: 0.2 },
                zoo_protocol::inbetween::GapFallback { up_to: usize::MAX, start: 0.3, full: 0.6 },
            ],
        }),
    };
    MotionModelMetadata {
        model_kind: "arnn".into(),
        task: MotionTask::Keyframes(KeyframesTask {
            dofs: 11,
            groups: 3,
            key_groups: zoo_protocol::inbetween::key_groups(2),
            inbetween: Some(section),
        }),
        state: vec![],
        ..sample()
    }
}

#[test]
fn an_inbetween_keyframes_section_round_trips_and_is_checked() {
    let m = inbetween_sample();
    let props = m.to_props();
    assert!(props.last().unwrap().1.contains("\"inbetween\":{\"euler_axes\":[[2,0,1],[2,0,1]]"));
    assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m);
    let edit = |f: &dyn Fn(&mut KeyframesTask)| {
        let mut m = inbetween_sample();
        if let MotionTask::Keyframes(t) = &mut m.task {
            f(t);
        }
        m.check().unwrap_err().to_string()
    };
    let section = |f: &dyn Fn(&mut InbetweenSection)| edit(&|t| f(t.inbetween.as_mut().unwrap()));
    let err = section(&|s| s.input_width = 40);
    assert!(err.contains("inbetween.input_width is 40 but 2 joints make 41"), "{err}");
    let err = section(&|s| s.std[3] = 0.0);
    assert!(err.contains(keys::KEYFRAMES) && err.contains("standard deviation 3 is 0"), "{err}");
    let err = section(&|s| s.euler_axes[1] = [0, 0, 2]);
    assert!(err.contains("euler_axes of joint 1 is [0, 0, 2]"), "{err}");
    let err = section(&|s| s.euler_axes.push([2, 0, 1]));
    assert!(err.contains("inbetween.euler_axes has 3 joints but the skeleton has 2"), "{err}");
    let err = edit(&|t| t.groups = 2);
    assert!(err.contains("the section says dofs 11 and groups 2"), "{err}");
    let err = section(&|s| {
        s.mean.pop();
    });
    assert!(err.contains("10 means and 11 standard deviations"), "{err}");
    let err = section(&|s| s.fallback.as_mut().unwrap().gaps[1].full = 0.3);
    assert!(err.contains("inbetween.fallback: fallback thresholds start 0.3 and full 0.3"), "{err}");
    let err = section(&|s| s.fallback.as_mut().unwrap().gaps[1].up_to = 12);
    assert!(err.contains("up_to strictly increasing"), "{err}");
}

#[test]
fn a_keyframes_section_written_before_the_inbetween_design_loads_as_a_step_graph() {
    // The section of a file exported before the field existed, verbatim.
    let old = r#"{"dofs":2,"groups":2,"key_groups":[0,1]}"#;
    let m = edited(|p| {
        set(p, keys::TASK, "keyframes");
        p.retain(|(k, _)| k != keys::TRANSITION);
        p.push((keys::KEYFRAMES.to_string(), old.to_string()));
    })
    .unwrap();
    let want = KeyframesTask { dofs: 2, groups: 2, key_groups: vec![0, 1], inbetween: None };
    assert_eq!(m.task, MotionTask::Keyframes(want));
    // And a step graph's section is written as before: no `inbetween` field.
    assert_eq!(m.to_props().last().unwrap().1, old);
}

#[test]
fn a_stitch_section_missing_a_field_is_refused_with_the_fix() {
    let m = stitch_sample();
    let mut props = m.to_props();
    let mut section: serde_json::Value = serde_json::from_str(&props.last().unwrap().1).unwrap();
    section.as_object_mut().unwrap().remove("blend_frames");
    props.last_mut().unwrap().1 = section.to_string();
    let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
    assert!(matches!(&err, FormatError::BadMetadata { key, .. } if key == keys::STITCH), "{err}");
    let text = err.to_string();
    assert!(text.contains("missing field `blend_frames`") && text.contains("zoo export --onnx RUN_DIR"), "{text}");
    // A layout that does not fit the skeleton, and statistics of the wrong width.
    let mut bad = stitch_sample();
    if let MotionTask::Stitch(t) = &mut bad.task {
        t.layout.contacts[0] = 9;
    }
    assert!(bad.check().unwrap_err().to_string().contains("out of range"));
    let mut bad = stitch_sample();
    bad.normalization.get_mut("x").unwrap().mean.pop();
    assert!(bad.check().unwrap_err().to_string().contains("group `x`"));
}

#[test]
fn the_stitch_fallback_and_pre_blend_round_trip_default_to_off_and_are_checked() {
    // Files written before the fields existed load with neither.
    let m = stitch_sample();
    let mut props = m.to_props();
    let mut section: serde_json::Value = serde_json::from_str(&props.last().unwrap().1).unwrap();
    let fields = section.as_object_mut().unwrap();
    assert!(fields.remove("pre_blend").is_some() && fields.remove("fallback").is_some());
    props.last_mut().unwrap().1 = section.to_string();
    assert_eq!(MotionModelMetadata::from_props(lookup(&props)).unwrap(), m);
    let mut with = stitch_sample();
    if let MotionTask::Stitch(t) = &mut with.task {
        t.pre_blend = true;
        t.fallback = Some(StitchFallback { start: 0.5, full: 1.0 });
    }
    assert_eq!(MotionModelMetadata::from_props(lookup(&with.to_props())).unwrap(), with);
    if let MotionTask::Stitch(t) = &mut with.task {
        t.fallback = Some(StitchFallback { start: 1.0, full: f32::NAN });
    }
    assert!(with.check().unwrap_err().to_string().contains("start <= full"));
}

#[test]
fn the_stitch_fallback_blends_pose_values_towards_the_input() {
    // Frames of 3 values: 2 pose values, 1 contact.
    let input = [0.0, 0.0, 1.0, 0.0, 0.0, 1.0];
    let output = [3.0, 4.0, 0.0, 3.0, 4.0, 0.0];
    assert_eq!(crate::stitch::correction_size(&input, &output, 3, 2), (12.5f32).sqrt());
    let f = StitchFallback { start: 2.0, full: 5.0 };
    let mut y = output;
    let w = f.apply(&input, &mut y, 3, 2);
    let expected = ((12.5f32).sqrt() - 2.0) / 3.0;
    assert!((w - expected).abs() < 1e-6, "{w}");
    assert!((y[0] - 3.0 * (1.0 - w)).abs() < 1e-6 && y[2] == 0.0 && y[5] == 0.0);
    let mut small = [0.1, 0.0, 0.0, 0.1, 0.0, 0.0];
    assert_eq!(f.apply(&[0.0; 6], &mut small, 3, 2), 0.0);
    assert_eq!(small, [0.1, 0.0, 0.0, 0.1, 0.0, 0.0]);
}

#[test]
fn a_required_optional_field_must_be_written_as_null() {
    // `terrain: null` and `fallback: null` are the way to say "none": a missing field is refused.
    let err = edited(|p| {
        let t = json(&transition()).replace(",\"fallback\":null", "");
        set(p, keys::TRANSITION, &t)
    })
    .unwrap_err();
    assert!(err.to_string().contains("missing field `fallback`"), "{err}");
    let with = TransitionTask { fallback: Some(TransitionFallback { start: 1.0, full: 3.0 }), ..transition() };
    let m = MotionModelMetadata { task: MotionTask::Transition(with), ..sample() };
    assert_eq!(MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap(), m);
    let bad = TransitionTask { fallback: Some(TransitionFallback { start: 3.0, full: 1.0 }), ..transition() };
    let err = MotionModelMetadata { task: MotionTask::Transition(bad), ..sample() }.check().unwrap_err();
    assert!(err.to_string().contains("start <= full"), "{err}");
}

#[test]
fn time_to_arrival_round_trips_defaults_to_none_and_is_checked() {
    let tta = TimeToArrival { dims: 8, max: 45 };
    let with = TransitionTask { time_to_arrival: Some(tta), ..transition() };
    let m = MotionModelMetadata { task: MotionTask::Transition(with), ..sample() };
    assert_eq!(MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap(), m);
    // A file written before the field existed loads without it.
    let old = edited(|p| {
        let t = json(&transition()).replace(",\"time_to_arrival\":null", "");
        assert!(!t.contains("time_to_arrival"));
        set(p, keys::TRANSITION, &t)
    })
    .unwrap();
    assert!(matches!(old.task, MotionTask::Transition(TransitionTask { time_to_arrival: None, .. })));
    for (bad, what) in [((7, 45), "even"), ((0, 45), "even"), ((8, 0), "max 0")] {
        let t = TimeToArrival { dims: bad.0, max: bad.1 };
        let task = TransitionTask { time_to_arrival: Some(t), ..transition() };
        let err = MotionModelMetadata { task: MotionTask::Transition(task), ..sample() }.check().unwrap_err();
        assert!(err.to_string().contains(what), "{err}");
    }
}

#[test]
fn fallback_thresholds_per_length_interpolate_and_are_checked() {
    let at = |length, start| TransitionFallbackAt { length, start, full: 2.0 * start };
    let task = TransitionTask {
        fallback: Some(TransitionFallback { start: 9.0, full: 18.0 }),
        fallback_lengths: vec![at(5, 1.0), at(15, 3.0), at(45, 6.0)],
        ..transition()
    };
    let start = |n| task.fallback_for(n).unwrap().start;
    assert_eq!(
        (start(1), start(5), start(10), start(15), start(30), start(45), start(90)),
        (1.0, 1.0, 2.0, 3.0, 4.5, 6.0, 6.0)
    );
    assert_eq!(task.fallback_for(10).unwrap().full, 4.0);
    // Without a table every length gets `fallback`.
    let plain = TransitionTask { fallback_lengths: Vec::new(), ..task.clone() };
    assert_eq!(plain.fallback_for(10), plain.fallback);
    let m = MotionModelMetadata { task: MotionTask::Transition(task.clone()), ..sample() };
    assert_eq!(MotionModelMetadata::from_props(lookup(&m.to_props())).unwrap(), m);
    let unsorted = TransitionTask { fallback_lengths: vec![at(15, 1.0), at(5, 1.0)], ..task.clone() };
    let err = MotionModelMetadata { task: MotionTask::Transition(unsorted), ..sample() }.check().unwrap_err();
    assert!(err.to_string().contains("strictly increase"), "{err}");
    let bad =
        TransitionTask { fallback_lengths: vec![TransitionFallbackAt { length: 5, start: 2.0, full: 1.0 }], ..task };
    let err = MotionModelMetadata { task: MotionTask::Transition(bad), ..sample() }.check().unwrap_err();
    assert!(err.to_string().contains("start <= full"), "{err}");
}

#[test]
fn time_to_arrival_embedding_counts_down_and_stays_constant_past_max() {
    let tta = TimeToArrival { dims: 8, max: 45 };
    let e = |t: usize| {
        let mut out = [0f32; 8];
        tta.embed(t, &mut out);
        out
    };
    // The target (0 frames left): every sine 0 and every cosine 1.
    assert_eq!(e(0), [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0]);
    // The slowest pair is a quarter turn over `max`: sin rises monotonically to 1 at 45.
    let slow: Vec<f32> = (0..=45).map(|t| e(t)[0]).collect();
    assert!(slow.windows(2).all(|w| w[1] > w[0]), "{slow:?}");
    assert!((slow[45] - 1.0).abs() < 1e-6);
    // The fastest pair turns one radian a frame.
    assert!((e(1)[6] - 1f32.sin()).abs() < 1e-6 && (e(1)[7] - 1f32.cos()).abs() < 1e-6);
    // Clamped: every length past `max` looks like `max`; distinct frames within it differ.
    assert_eq!(e(45), e(46));
    assert_eq!(e(45), e(1000));
    assert_ne!(e(29), e(30));
}

#[test]
fn an_rmr_file_of_the_old_format_is_asked_to_re_export() {
    let props = vec![
        (keys::MODEL_KIND.to_string(), "rmr".to_string()),
        (keys::OLD_RMR_FORMAT_VERSION.to_string(), "1".to_string()),
        ("zoo.rmr.config".to_string(), "{}".to_string()),
    ];
    let err = MotionModelMetadata::from_props(lookup(&props)).unwrap_err();
    assert!(matches!(&err, FormatError::FormatTooOld { found, .. } if found == "rmr 1"), "{err}");
    assert!(err.to_string().contains("zoo export --onnx RUN_DIR"), "{err}");
}

#[test]
fn the_fallback_weight_ramps_between_its_thresholds() {
    let f = TransitionFallback { start: 1.0, full: 3.0 };
    assert_eq!(f.weight(0.5), 0.0);
    assert_eq!(f.weight(2.0), 0.5);
    assert_eq!(f.weight(4.0), 1.0);
    assert_eq!(f.weight(f32::NAN), 1.0);
}

#[test]
fn metadata_is_read_from_onnx_bytes_without_the_graph() {
    use prost::Message as _;
    let m = sample();
    let proto = pb::ModelProto {
        ir_version: 8,
        metadata_props: m
            .to_props()
            .into_iter()
            .map(|(key, value)| pb::StringStringEntryProto { key, value })
            .collect(),
        graph: Some(pb::GraphProto { name: "g".into(), ..Default::default() }),
        ..Default::default()
    };
    assert_eq!(MotionModelMetadata::read(&proto.encode_to_vec(), "toy.onnx").unwrap(), m);
    let err = MotionModelMetadata::read(b"\xff\xff\xff not onnx", "junk.onnx").unwrap_err();
    assert!(matches!(&err, FormatError::NotOnnx { origin, .. } if origin == "junk.onnx"), "{err}");
}
