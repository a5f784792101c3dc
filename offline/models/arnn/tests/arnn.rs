//! ARNN: shapes, the curriculum, a short training run on simulated lamp hops, bad input.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use zoo_arnn::luxo::preprocess::{KeyedSequence, preprocess};
use zoo_arnn::luxo::{GenerateOptions, generate_sequence};
use zoo_arnn::{Architecture, Arnn, ArnnConfig, ArnnTrainer, Curriculum, NoMemoryOutput, complete};
use zoo_nn::SeededVarMap;
use zoo_nn::train_loop::Trainable;

/// A few simulated, preprocessed lamp sequences (small annealing budget: seconds).
fn lamp_sequences(n: usize) -> Vec<KeyedSequence> {
    let mut o = GenerateOptions::new(n, 17);
    o.anneal.k_max = 2;
    (0..n).map(|i| preprocess(&generate_sequence(&o, i).unwrap()).unwrap()).collect()
}

#[test]
fn step_shapes_and_residual() {
    let config = ArnnConfig::tiny();
    let varmap = VarMap::new();
    let model = Arnn::new(&config, SeededVarMap::builder(&varmap, 1, DType::F32, &Device::Cpu)).unwrap();
    let pose = Tensor::zeros((3, 6), DType::F32, &Device::Cpu).unwrap();
    let t_rel = Tensor::full(0.5f32, (3, 1), &Device::Cpu).unwrap();
    let state = model.zero_state(3).unwrap();
    let (y, s) = model.step(&pose, &pose, &pose, &t_rel, &state, None).unwrap();
    assert_eq!(y.dims(), &[3, 6]);
    assert_eq!(s.gru[0].output().dims(), &[3, config.hidden]);
    assert_eq!(s.gru[1].output().dims(), &[3, config.hidden]);
    // The paper's sizes: GRUs of 100 units, decoder of 10.
    let paper = ArnnConfig::paper();
    assert_eq!((paper.hidden, paper.decoder, paper.key_weight), (100, 10, 100.0));
}

#[test]
fn curriculum_follows_section_7_2() {
    let c = Curriculum::paper(1000);
    assert!(c.teacher_forcing(0) > 0.99 && c.teacher_forcing(499) < 0.01 && c.teacher_forcing(700) == 0.0);
    assert!(c.teacher_forcing(100) > c.teacher_forcing(300));
    assert_eq!(c.omega(0), 0.0);
    assert_eq!(c.omega(499), 0.0);
    assert!(c.omega(500) < 0.01 && c.omega(1000) > 0.99 && c.omega(800) > c.omega(700));
    let off = Curriculum { enabled: false, ..c };
    assert_eq!((off.teacher_forcing(0), off.omega(0)), (0.0, 1.0));
}

/// A frame phase of a quarter: the paper's ramps over the first 750 steps, then `omega` at
/// `frame_phase_omega`; a file without the fields reads as the paper's schedule.
#[test]
fn frame_phase_follows_the_ramps() {
    let c = Curriculum { frame_phase: 0.25, frame_phase_omega: 0.1, ..Curriculum::paper(1000) };
    let ramps = Curriculum::paper(750);
    for step in [0, 100, 300, 374, 375, 500, 600, 700, 749] {
        assert_eq!(
            (c.teacher_forcing(step), c.omega(step)),
            (ramps.teacher_forcing(step), ramps.omega(step)),
            "{step}"
        );
        assert!(!c.in_frame_phase(step));
    }
    assert!(c.omega(749) > 0.99);
    for step in [750, 900, 1000, 5000] {
        assert!(c.in_frame_phase(step));
        assert_eq!((c.teacher_forcing(step), c.omega(step)), (0.0, 0.1), "{step}");
    }
    let old: Curriculum = serde_json::from_str(r#"{"total_steps": 1000, "width": 0.05, "enabled": true}"#).unwrap();
    assert_eq!(old, Curriculum::paper(1000));
    let mut bad = ArnnConfig::paper();
    bad.curriculum.frame_phase = 1.0;
    assert!(bad.validate().unwrap_err().contains("frame_phase"));
    bad.curriculum = Curriculum { frame_phase_omega: 2.0, ..Curriculum::paper(10) };
    assert!(bad.validate().unwrap_err().contains("frame_phase_omega"));
}

#[test]
fn loss_falls_on_lamp_sequences() {
    let seqs = lamp_sequences(4);
    assert!(seqs.iter().all(|s| s.frames.len() == 87 && s.keys.len() == 9));
    let mut config = ArnnConfig::tiny();
    config.learning_rate = 3e-3;
    config.curriculum = Curriculum { enabled: false, ..Curriculum::paper(60) };
    let mut t = ArnnTrainer::new(&config, seqs.clone(), seqs[..2].to_vec(), &Device::Cpu).unwrap();
    let before = t.evaluate().unwrap();
    let mut losses = vec![];
    for _ in 0..40 {
        losses.push(t.train_step(&[0, 1, 2, 3]).unwrap());
    }
    let after = t.evaluate().unwrap();
    assert!(losses.iter().all(|l| l.is_finite()));
    assert!(after.0 + after.1 < 0.7 * (before.0 + before.1), "validation {before:?} -> {after:?}");
    assert_eq!(t.steps(), 40);
    let dir = tempfile::tempdir().unwrap();
    t.save(dir.path()).unwrap();
    for f in ["config.json", "model.safetensors", "normalization.json"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
}

#[test]
fn bad_keys_are_rejected() {
    let mut seqs = lamp_sequences(1);
    seqs[0].keys.swap(1, 2);
    let e = ArnnTrainer::new(&ArnnConfig::tiny(), seqs.clone(), vec![], &Device::Cpu).err().unwrap().to_string();
    assert!(e.contains("keys must increase"), "{e}");
    seqs[0].keys.swap(1, 2);
    seqs[0].keys.push(200);
    assert!(ArnnTrainer::new(&ArnnConfig::tiny(), seqs.clone(), vec![], &Device::Cpu).is_err());
    seqs[0].keys.pop();
    seqs[0].frames[5][2] = f64::NAN;
    let e = ArnnTrainer::new(&ArnnConfig::tiny(), seqs, vec![], &Device::Cpu).err().unwrap().to_string();
    assert!(e.contains("finite"), "{e}");
}

#[test]
fn complete_fills_every_frame_and_rejects_bad_keys() {
    let seqs = lamp_sequences(2);
    let t = ArnnTrainer::new(&ArnnConfig::tiny(), seqs.clone(), vec![], &Device::Cpu).unwrap();
    let s = &seqs[0];
    let poses: Vec<Vec<f64>> = s.key_poses().iter().map(|p| p.to_vec()).collect();
    let out = complete(t.model(), t.normalization(), &s.keys, &poses).unwrap();
    assert_eq!(out.len(), s.frames.len());
    assert_eq!(out[0], poses[0]);
    assert!(out.iter().flatten().all(|v| v.is_finite()));
    let err = |keys: &[usize], poses: &[Vec<f64>]| {
        complete(t.model(), t.normalization(), keys, poses).expect_err("bad keys accepted").to_string()
    };
    // Keys out of order.
    let mut k = s.keys.clone();
    k.swap(1, 2);
    assert!(err(&k, &poses).contains("strictly increase"));
    // A key that does not start the sequence.
    let mut k = s.keys.clone();
    k[0] = 1;
    assert!(err(&k, &poses).contains("start at 0"));
    // NaN in a key.
    let mut p = poses.clone();
    p[3][1] = f64::NAN;
    assert!(err(&s.keys, &p).contains("finite"));
    // Another skeleton: keys with the wrong number of values.
    let mut p = poses.clone();
    p[2].push(0.0);
    assert!(err(&s.keys, &p).contains("6 finite values"));
    // Fewer poses than keys.
    assert!(err(&s.keys, &poses[..3]).contains("one pose per key"));
}

/// The analytic parameter count is the built model's, for every architecture, and the Table 2
/// architectures are matched to the ARNN's count (section 9) within 1%.
#[test]
fn parameter_counts_are_exact_and_matched() {
    for base in [ArnnConfig::tiny(), ArnnConfig::paper()] {
        let target = base.parameter_count();
        for arch in [Architecture::Arnn, Architecture::NoMemory, Architecture::Segregated] {
            let config = base.with_matched_architecture(arch);
            assert_eq!(config.architecture, arch);
            let varmap = VarMap::new();
            Arnn::new(&config, SeededVarMap::builder(&varmap, 1, DType::F32, &Device::Cpu)).unwrap();
            let built: usize = varmap.all_vars().iter().map(|v| v.elem_count()).sum();
            assert_eq!(built, config.parameter_count(), "{arch:?}");
            println!("{arch:?}: hidden {}, correction {}, {built} parameters", config.hidden, config.correction);
            let off = (built as f64 - target as f64).abs() / target as f64;
            assert!(off < 0.01, "{arch:?}: {built} parameters against the ARNN's {target}");
        }
    }
    assert_eq!(ArnnConfig::paper().parameter_count(), 125_326);
}

/// Each architecture steps with its own state (none for the no-memory net), and the no-memory
/// net ignores the previous pose.
#[test]
fn table_2_architectures_step() {
    let dev = Device::Cpu;
    for arch in [Architecture::NoMemory, Architecture::Segregated] {
        let config = ArnnConfig::tiny().with_matched_architecture(arch);
        let varmap = VarMap::new();
        let model = Arnn::new(&config, SeededVarMap::builder(&varmap, 1, DType::F32, &dev)).unwrap();
        let a = Tensor::zeros((2, 6), DType::F32, &dev).unwrap();
        let b = Tensor::ones((2, 6), DType::F32, &dev).unwrap();
        let t_rel = Tensor::full(0.3f32, (2, 1), &dev).unwrap();
        let state = model.zero_state(2).unwrap();
        assert_eq!(state.gru.len(), if arch == Architecture::NoMemory { 0 } else { 2 });
        let (y0, _) = model.step(&a, &a, &b, &t_rel, &state, None).unwrap();
        let (y1, _) = model.step(&b, &a, &b, &t_rel, &state, None).unwrap();
        assert_eq!(y0.dims(), &[2, 6]);
        let diff = (y0 - y1).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
        if arch == Architecture::NoMemory {
            assert_eq!(diff, 0.0, "the no-memory net depends on the previous pose");
        } else {
            assert!(diff > 0.0);
        }
    }
}

/// The no-memory net's output is added to what its configuration says: with the decoder's last
/// layer zeroed, nothing (the pose is 0), the last key, or the keys' interpolation at t_rel.
/// A configuration file without the setting is read as the first design (pose output).
#[test]
fn no_memory_output_is_added_to_what_the_config_says() {
    let dev = Device::Cpu;
    assert_eq!(ArnnConfig::paper().no_memory_output, NoMemoryOutput::Interpolation);
    let mut json = serde_json::to_value(ArnnConfig::paper()).unwrap();
    json.as_object_mut().unwrap().remove("no_memory_output");
    let old: ArnnConfig = serde_json::from_value(json).unwrap();
    assert_eq!(old.no_memory_output, NoMemoryOutput::Pose);
    let a = Tensor::full(0.5f32, (2, 6), &dev).unwrap();
    let b = Tensor::ones((2, 6), DType::F32, &dev).unwrap();
    let t_rel = Tensor::full(0.3f32, (2, 1), &dev).unwrap();
    for (output, want) in
        [(NoMemoryOutput::Pose, 0.0), (NoMemoryOutput::KeyResidual, 0.5), (NoMemoryOutput::Interpolation, 0.65)]
    {
        let config = ArnnConfig { no_memory_output: output, ..ArnnConfig::tiny() }
            .with_matched_architecture(Architecture::NoMemory);
        let varmap = VarMap::new();
        let model = Arnn::new(&config, SeededVarMap::builder(&varmap, 1, DType::F32, &dev)).unwrap();
        let data = varmap.data().lock().unwrap();
        for name in ["decoder.2.weight", "decoder.2.bias"] {
            let v = data.get(name).expect("the decoder's last layer");
            v.set(&v.zeros_like().unwrap()).unwrap();
        }
        drop(data);
        let (y, _) = model.step(&b, &a, &b, &t_rel, &model.zero_state(2).unwrap(), None).unwrap();
        let got: Vec<f32> = y.flatten_all().unwrap().to_vec1().unwrap();
        assert!(got.iter().all(|v| (v - want).abs() < 1e-6), "{output:?}: {got:?}");
    }
}

/// The ground penalty is zero for poses on or above the ground and the squared depth of the
/// base plate's lowest point (in base-height standard deviations) below it.
#[test]
fn ground_penalty_measures_the_depth_below_the_ground() {
    let seqs = lamp_sequences(2);
    let config = ArnnConfig { ground_weight: 10.0, ..ArnnConfig::tiny() };
    let t = ArnnTrainer::new(&config, seqs, vec![], &Device::Cpu).unwrap();
    let norm = t.normalization().clone();
    let lamp = t.config().lamp.clone().unwrap();
    let tensor = |poses: &[[f64; 6]]| {
        let v: Vec<f32> =
            poses.iter().flat_map(|p| (0..6).map(|j| ((p[j] - norm.mean[j]) / norm.std[j]) as f32)).collect::<Vec<_>>();
        Tensor::from_vec(v, (poses.len(), 6), &Device::Cpu).unwrap()
    };
    let penalty = |poses: &[[f64; 6]]| t.ground_penalty(&tensor(poses)).unwrap().to_scalar::<f32>().unwrap() as f64;
    let h = lamp.base_half_height;
    let standing = [0.1, h + 0.001, 0.0, 0.5, -1.1, -1.2];
    let flying = [0.3, 0.2, 0.3, 0.5, -1.1, -1.2];
    assert!(penalty(&[standing, flying]) < 1e-9);
    // Flat, 2 cm into the ground, in one of two poses.
    let sunk = [0.1, h - 0.02, 0.0, 0.5, -1.1, -1.2];
    let expected = (0.02 / norm.std[1]).powi(2) / 2.0;
    let got = penalty(&[standing, sunk]);
    assert!((got - expected).abs() < 1e-3 * expected, "{got} vs {expected}");
    // Tilted: its corner is below the ground although its centre is at rest height.
    let tilted = [0.1, h, 0.2, 0.5, -1.1, -1.2];
    let depth = -zoo_arnn::eval::base_clearance(&lamp, &tilted);
    let got = penalty(&[tilted]);
    assert!(depth > 0.0 && (got - (depth / norm.std[1]).powi(2)).abs() < 1e-3 * got, "{got}");
    // Off without a weight (the default).
    assert_eq!(ArnnConfig::paper().ground_weight, 0.0);
    let t0 = ArnnTrainer::new(&ArnnConfig::tiny(), lamp_sequences(2), vec![], &Device::Cpu).unwrap();
    assert_eq!(t0.ground_penalty(&tensor(&[sunk])).unwrap().to_scalar::<f32>().unwrap(), 0.0);
}
