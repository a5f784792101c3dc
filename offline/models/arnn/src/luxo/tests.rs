//! Simulation tests of the lamp data: they run rapier2d, with small annealing budgets.

use super::anneal::{AnnealConfig, score};
use super::controller::{HopPolicy, REST_ANGLES, RolloutOptions, simulate};
use super::lamp::{Lamp, LampParams};
use super::preprocess::{HOP_SAMPLES, STILL_SAMPLES, preprocess};
use super::sequence::{KeyKind, LuxoSequence, clip_to_poses, detect_hops};
use super::*;

/// Settings for fast tests: a few annealing iterations.
fn quick(sequences: usize, seed: u64) -> GenerateOptions {
    let mut o = GenerateOptions::new(sequences, seed);
    o.anneal.k_max = 4;
    o
}

#[test]
fn lamp_stands_still_under_pd_control_at_rest() {
    let params = LampParams::default();
    let mut lamp = Lamp::new(&params, REST_ANGLES).unwrap();
    let start = lamp.pose();
    let steps = |lamp: &mut Lamp, s: f64| (0..(s / params.dt) as usize).for_each(|_| lamp.step());
    // Gravity bends the joints until the PD torques balance it (at most about 0.08 rad, the
    // neck joint, which holds the neck and the head out over the base).
    steps(&mut lamp, 0.5);
    let settled = lamp.pose();
    steps(&mut lamp, 1.0);
    let end = lamp.pose();
    for d in 0..6 {
        assert!((end[d] - settled[d]).abs() < 1e-3, "dof {d} still moves: {} then {}", settled[d], end[d]);
        assert!((end[d] - start[d]).abs() < 0.1, "dof {d} sagged from {} to {}", start[d], end[d]);
    }
    assert!(lamp.touches_ground() && !lamp.has_fallen());
    // Resting on the ground, not sinking into it.
    assert!(lamp.clearance() > -0.005, "clearance {}", lamp.clearance());
}

#[test]
fn hand_set_hop_leaves_the_ground_and_lands() {
    let params = LampParams::default();
    let options = RolloutOptions { cycles: 1, settle_s: 0.4, stop_on_fall: true };
    let r = simulate(&params, &HopPolicy::hand_set(), &options).unwrap();
    assert!(!r.fell, "the hand-set hop falls over");
    let hops = detect_hops(&r.touching, r.dt, 0.04);
    assert_eq!(hops.len(), 1, "{hops:?}");
    assert!(r.clearance.iter().cloned().fold(0.0, f64::max) > 0.01, "the lamp never rose 1 cm");
    assert!(*r.touching.last().unwrap(), "the lamp did not land");
    assert!(r.distance() > 0.02, "the hop went {} m", r.distance());
}

#[test]
fn hand_set_policy_makes_three_satisfactory_hops() {
    let params = LampParams::default();
    let (_, hops, e) = score(&params, &HopPolicy::hand_set(), 0.5, &AnnealConfig::default()).unwrap();
    assert_eq!(hops.len(), 3);
    assert!(e.satisfactory, "{e:?}");
}

#[test]
fn simulation_is_deterministic() {
    let params = LampParams::default();
    let p = HopPolicy::hand_set();
    let a = simulate(&params, &p, &RolloutOptions::default()).unwrap();
    let b = simulate(&params, &p, &RolloutOptions::default()).unwrap();
    assert_eq!(a, b);
    assert_eq!(generate_sequence(&quick(1, 3), 0).unwrap(), generate_sequence(&quick(1, 3), 0).unwrap());
}

#[test]
fn sequence_has_events_and_keys_in_order() {
    let seq = generate_sequence(&quick(1, 11), 0).unwrap();
    seq.validate().unwrap();
    assert_eq!(seq.hops.len(), 3);
    assert_eq!(seq.keys.len(), 9);
    let kinds: Vec<KeyKind> = seq.keys.iter().take(3).map(|k| k.kind).collect();
    assert_eq!(kinds, [KeyKind::Liftoff, KeyKind::InAir, KeyKind::Landing]);
    for e in &seq.hops {
        // In the air between liftoff and landing: the base is above its rest height.
        let mid = seq.pose_at(0.5 * (e.hop.liftoff_s + e.hop.landing_s));
        assert!(mid[1] > LampParams::default().rest_height(), "mid-hop base height {}", mid[1]);
    }
    assert!(seq.evaluation.satisfactory);
}

#[test]
fn bvh_rereads_with_the_project_reader() {
    let params = LampParams::default();
    let seq = generate_sequence(&quick(1, 5), 0).unwrap();
    let text = zoo_data::bvh::to_string(&seq.to_clip(&params));
    let clip = zoo_data::bvh::parse(&text, std::path::Path::new("luxo.bvh"), &Default::default()).unwrap();
    assert_eq!(clip.frames(), seq.frames.len());
    assert!((clip.fps() - seq.fps).abs() < 1e-9);
    let back = clip_to_poses(&clip).unwrap();
    for (a, b) in seq.frames.iter().zip(&back) {
        for d in 0..6 {
            let diff = if d >= 2 { lamp::wrap_angle(a[d] - b[d]) } else { a[d] - b[d] };
            assert!(diff.abs() < 1e-6, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn parallel_generation_writes_the_same_files_as_serial() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let opts = quick(3, 21);
    let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
    pool(1).install(|| generate_with(&a, &opts, &|| {})).unwrap();
    let count = std::sync::atomic::AtomicUsize::new(0);
    let s = pool(2)
        .install(|| {
            generate_with(&b, &opts, &|| {
                count.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            })
        })
        .unwrap();
    assert_eq!((s.sequences, count.into_inner()), (3, 3));
    for i in 0..3 {
        for ext in ["bvh", "json"] {
            let name = format!("{}.{ext}", sequence_name(i));
            assert_eq!(std::fs::read(a.join(&name)).unwrap(), std::fs::read(b.join(&name)).unwrap(), "{name}");
        }
    }
    let seqs = load_dir(&a).unwrap();
    assert_eq!(seqs.len(), 3);
    // Each sequence has its own random stream (with 4 iterations the policies may still agree).
    assert!(seqs[0].w_e != seqs[1].w_e && seqs[1].w_e != seqs[2].w_e);
}

#[test]
fn preprocessing_resamples_hops_and_keeps_the_keys() {
    let seq = generate_sequence(&quick(1, 8), 0).unwrap();
    let k = preprocess(&seq).unwrap();
    assert_eq!(k.frames.len(), 3 * HOP_SAMPLES + 2 * STILL_SAMPLES);
    assert_eq!(k.keys.len(), 9);
    assert_eq!((k.keys[0], k.keys[2], k.keys[8]), (0, HOP_SAMPLES - 1, k.frames.len() - 1));
    // The keys of the preprocessed sequence are the generated keys, exactly.
    for (key, pose) in seq.keys.iter().zip(k.key_poses()) {
        assert_eq!(key.pose.to_vec(), pose);
    }
}

#[test]
fn unreachable_criteria_give_a_clear_error() {
    let mut o = quick(1, 0);
    o.anneal.k_max = 1;
    o.max_attempts = 2;
    o.anneal.min_distance = 100.0;
    let e = generate_sequence(&o, 0).unwrap_err().to_string();
    assert!(e.contains("none of 2 simulated annealing runs") && e.contains("min_distance"), "{e}");
}

#[test]
fn bad_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let e = load_dir(dir.path()).unwrap_err().to_string();
    assert!(e.contains("no luxo_*.json") && e.contains("zoo data luxo"), "{e}");
    let path = dir.path().join("luxo_0000.json");
    std::fs::write(&path, "{\"format\": 3}").unwrap();
    assert!(LuxoSequence::read_json(&path).unwrap_err().to_string().contains("invalid JSON"));
    let mut seq = generate_sequence(&quick(1, 2), 0).unwrap();
    seq.keys.swap(0, 1);
    seq.write_json(&path).unwrap();
    let e = LuxoSequence::read_json(&path).unwrap_err().to_string();
    assert!(e.contains("keys are not in increasing time order"), "{e}");
    seq.keys.swap(0, 1);
    seq.frames[3][1] = f64::NAN;
    // Never written (serde_json would write `null`): refused with where the NaN is.
    let e = seq.write_json(&path).unwrap_err().to_string();
    assert!(e.contains("NaN at .frames[3][1]") && e.contains("nothing was written"), "{e}");
}

#[test]
fn manifest_values_past_their_ranges_are_refused_with_the_key_the_value_and_the_range() {
    let dir = tempfile::tempdir().unwrap();
    let options = GenerateOptions::new(3, 1);
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        version: sequence::VERSION,
        options: options.clone(),
        sequences: (0..3).map(sequence_name).collect(),
    };
    let good = serde_json::to_value(&manifest).unwrap();
    std::fs::write(dir.path().join(MANIFEST_FILE), good.to_string()).unwrap();
    assert_eq!(read_options(dir.path()).unwrap(), options);
    let with = |edits: &[(&str, serde_json::Value)]| -> String {
        let mut v = good.clone();
        for (pointer, value) in edits {
            *v.pointer_mut(pointer).unwrap_or_else(|| panic!("{pointer}")) = value.clone();
        }
        std::fs::write(dir.path().join(MANIFEST_FILE), v.to_string()).unwrap();
        read_options(dir.path()).unwrap_err().to_string()
    };
    use serde_json::json;
    for (edits, want) in [
        // The physics step: 1e-300 s would be 1e300 steps per rollout.
        (vec![("/options/lamp/dt", json!(1e-300))], "dt is 1e-300 s: give an integration step in [0.00001, 0.01]"),
        (vec![("/options/lamp/dt", json!(0.05))], "too coarse"),
        (vec![("/options/lamp/solver_iterations", json!(1_000_000_000u64))], "solver_iterations is 1000000000"),
        (vec![("/options/lamp/leg_mass", json!(1e300))], "leg_mass is 1e300 kg: give a mass in (0, 1000]"),
        (vec![("/options/lamp/leg_length", json!(1e9))], "leg_length is 1000000000.0 m"),
        (vec![("/options/lamp/kp", json!([1e300, 20.0, 5.0]))], "kp[0] is 1e300"),
        (vec![("/options/lamp/gravity", json!(-1e300))], "gravity is -1e300 m/s^2"),
        (vec![("/options/lamp/friction", json!(1e9))], "friction is 1000000000.0"),
        (vec![("/options/lamp/contact_tolerance", json!(5.0))], "contact_tolerance is 5.0 m"),
        (vec![("/options/lamp/joint_limits", json!([[-100.0, 1.6], [-2.7, 2.7], [-2.7, 2.7]]))], "joint_limits[0]"),
        // Phase durations, cycles, settle time: each bounded, and their product too.
        (vec![("/options/init/durations", json!([1e300, 0.09, 0.2, 0.57]))], "hop duration t1 is 1e300 s"),
        (vec![("/options/anneal/duration_range", json!([0.04, 1e300]))], "duration_range is [0.04, 1e300]"),
        (vec![("/options/anneal/rollout/settle_s", json!(1e300))], "rollout.settle_s is 1e300 s"),
        (vec![("/options/anneal/rollout/cycles", json!(1_000_000u64))], "rollout cycles is 1000000"),
        (vec![("/options/anneal/k_max", json!(1_000_000_000_000u64))], "k_max is 1000000000000"),
        (vec![("/options/anneal/t_max", json!(0.0))], "t_max is 0.0"),
        (vec![("/options/anneal/min_air_s", json!(-1.0))], "min_air_s is -1.0 s"),
        (
            vec![
                ("/options/lamp/dt", json!(0.0001)),
                ("/options/anneal/duration_range", json!([0.04, 10.0])),
                ("/options/anneal/rollout/cycles", json!(100)),
            ],
            "integration steps, more than the 1000000",
        ),
        (vec![("/options/sequences", json!(0))], "sequences is 0: give a whole number in 1..=100000"),
        (vec![("/options/max_attempts", json!(5000))], "max_attempts is 5000"),
        (vec![("/options/record_every", json!(0))], "record_every is 0"),
        (
            vec![("/options/sequences", json!(100_000)), ("/options/record_every", json!(1))],
            "more than the 50000000 zoo keeps in memory",
        ),
    ] {
        let e = with(&edits);
        assert!(e.contains(want) && e.contains("luxo.json: invalid settings: "), "{edits:?}: {e}");
    }
    // The rollout itself refuses a step count past the limit before allocating.
    let params = LampParams { dt: 1e-5, ..LampParams::default() };
    let long = HopPolicy { durations: [10.0; 4], ..HopPolicy::hand_set() };
    let e = simulate(&params, &long, &RolloutOptions { cycles: 100, settle_s: 0.0, stop_on_fall: true }).unwrap_err();
    assert!(e.contains("400000000 integration steps"), "{e}");
}
