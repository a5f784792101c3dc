//! The RNN-GMM generator end to end on synthetic locomotion: shapes, a short training run whose
//! NLL falls, checkpoints, an exact resume, seeded synthesis and the initial state (eq. 26).

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_data::synth::{SynthConfig, generate_clip};
use zoo_motion::Clip;
use zoo_nn::train_loop::{TrainOptions, train};
use zoo_rnngmm::prelude::*;
use zoo_rnngmm::{GeneratorTraining, TrainingData};

/// `n` synthetic clips of 6 s (seed 3), flat floor, 30 fps.
fn clips(n: usize) -> Vec<Clip> {
    let cfg = SynthConfig { minutes: 1.0, seed: 3, terrain: false, fps: 30.0, clip_seconds: 6.0 };
    (0..n).map(|i| generate_clip(&cfg, i).clip).collect()
}

fn data(config: &Config) -> TrainingData {
    let clips = clips(6);
    let refs: Vec<&Clip> = clips.iter().collect();
    TrainingData::from_clips(config, 30.0, &refs[..5], &refs[5..]).unwrap()
}

fn opts(out: &Path, epochs: usize) -> TrainOptions {
    TrainOptions { progress: false, print: false, ..TrainOptions::new(out, epochs, 9) }
}

fn bytes(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn shapes_of_the_generator_and_its_mixture() {
    let config = Config::tiny();
    let varmap = VarMap::new();
    let g = Generator::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu)).unwrap();
    let (b, t, d, m) = (3, 7, config.dim, config.components);
    let state = g.zero_state(b).unwrap();
    assert_eq!((state.h.len(), state.h[0].dims()), (2, &[b, config.lstm][..]));
    let x = Tensor::zeros((b, d), DType::F32, &Device::Cpu).unwrap();
    let (raw, next) = g.step(&x, &state).unwrap();
    assert_eq!(raw.dims(), &[b, m * (1 + 2 * d)]);
    assert_eq!(next.c[1].dims(), &[b, config.lstm]);
    let xs = Tensor::zeros((b, t, d), DType::F32, &Device::Cpu).unwrap();
    let (raw_seq, _) = g.forward_seq(&xs, &state).unwrap();
    assert_eq!(raw_seq.dims(), &[b, t, m * (1 + 2 * d)]);
    // The first output of the sequence is the step's output.
    let first = raw_seq.narrow(1, 0, 1).unwrap().squeeze(1).unwrap();
    let diff = (first - &raw).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
    assert!(diff < 1e-5, "{diff}");
    let mix = g.mixture(&raw_seq).unwrap();
    assert_eq!(mix.log_weights.dims(), &[b, t, m]);
    assert_eq!(mix.means.dims(), &[b, t, m, d]);
    assert_eq!(mix.log_stds.dims(), &[b, t, m, d]);
    let counted: usize = varmap.all_vars().iter().map(|v| v.elem_count()).sum();
    assert_eq!(g.parameter_count(), counted);
    // The paper preset, for the record in docs/rnn-gmm.md.
    let paper = Config::paper();
    let varmap = VarMap::new();
    let g = Generator::new(&paper, VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu)).unwrap();
    assert_eq!(g.parameter_count(), varmap.all_vars().iter().map(|v| v.elem_count()).sum::<usize>());
}

#[test]
fn training_lowers_the_nll_and_resumes_exactly() {
    let config = Config::tiny();
    let data = data(&config);
    assert_eq!(data.spec.dim(), config.dim);
    assert!(data.train.len() >= 40 && !data.valid.is_empty(), "{} windows", data.train.len());
    let dir = tempfile::tempdir().unwrap();
    let (whole, part) = (dir.path().join("whole"), dir.path().join("part"));
    let run = |out: &Path, epochs: usize, resume: bool| {
        let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
        let mut training = GeneratorTraining::new(trainer, &data.train, &data.valid).unwrap();
        let state = train(&mut training, &TrainOptions { resume, ..opts(out, epochs) }).unwrap();
        (state, training.into_trainer())
    };
    let (a, trainer) = run(&whole, 4, false);
    assert!(
        a.valid_loss[3] < a.valid_loss[0] - 5.0 && a.train_loss[3] < a.train_loss[0],
        "valid {:?} train {:?}",
        a.valid_loss,
        a.train_loss
    );
    // RMSProp's learning rate decays by 0.95 per epoch.
    let lr = candle_nn::Optimizer::learning_rate(trainer.optimizer());
    assert!((lr - 3e-3 * 0.95f64.powi(4)).abs() < 1e-12, "{lr}");
    run(&part, 2, false);
    let (b, _) = run(&part, 4, true);
    // Epochs 3-4 of the resumed run are computed again: bit for bit the same. Epochs 1-2 come
    // back from `train_state.json`, which serde_json may parse 1 ULP off.
    assert_eq!((&a.train_loss[2..], &a.valid_loss[2..]), (&b.train_loss[2..], &b.valid_loss[2..]));
    for (x, y) in a.train_loss.iter().chain(&a.valid_loss).zip(b.train_loss.iter().chain(&b.valid_loss)) {
        assert!((x - y).abs() <= 1e-12 * x.abs(), "{x} vs {y}");
    }
    for f in ["model.safetensors", "last/model.safetensors", "last/optimizer.safetensors", "last/rng.json"] {
        assert_eq!(bytes(&whole.join(f)), bytes(&part.join(f)), "{f}");
    }
    let summary: serde_json::Value = serde_json::from_slice(&bytes(&whole.join("summary.json"))).unwrap();
    assert_eq!(summary["model"], "rnn-gmm");
}

#[test]
fn checkpoints_round_trip_and_refuse_other_models() {
    let config = Config::tiny();
    let data = data(&config);
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let batch: Vec<&[f32]> = (0..4).map(|i| data.train.get(i)).collect();
    trainer.train_step(&batch).unwrap();
    let dir = tempfile::tempdir().unwrap();
    trainer.save(dir.path()).unwrap();
    trainer.save_training_state(dir.path()).unwrap();
    let config_json: serde_json::Value = serde_json::from_slice(&bytes(&dir.path().join("config.json"))).unwrap();
    assert_eq!(config_json["model"], "rnn-gmm");
    let loaded = checkpoint::load(dir.path(), &Device::Cpu).unwrap();
    assert_eq!((&loaded.spec, &loaded.norm), (&data.spec, &data.norm));
    let before = trainer.eval_loss(&batch).unwrap();
    let mut resumed = GeneratorTrainer::load(dir.path(), &Device::Cpu).unwrap();
    assert_eq!(resumed.eval_loss(&batch).unwrap(), before);
    assert_eq!(resumed.steps(), 1);
    // The next steps are the same for the original and the resumed trainer.
    assert_eq!(trainer.train_step(&batch).unwrap(), resumed.train_step(&batch).unwrap());
    let x = Tensor::from_slice(&data.valid.get(0)[..config.dim], (1, config.dim), &Device::Cpu).unwrap();
    let s = loaded.generator.zero_state(1).unwrap();
    let (r1, _) = loaded.generator.step(&x, &s).unwrap();
    let (r2, _) = GeneratorTrainer::load(dir.path(), &Device::Cpu).unwrap().model().step(&x, &s).unwrap();
    assert_eq!(r1.to_vec2::<f32>().unwrap(), r2.to_vec2::<f32>().unwrap());
    // Another model's folder is refused by name.
    std::fs::write(dir.path().join("config.json"), r#"{"model": "rtn"}"#).unwrap();
    let err = checkpoint::load(dir.path(), &Device::Cpu).unwrap_err().to_string();
    assert!(err.contains("`rtn` checkpoint"), "{err}");
}

#[test]
fn bad_training_input_is_refused() {
    let config = Config::tiny();
    let data = data(&config);
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let short = &data.train.get(0)[..config.dim * 3];
    let err = trainer.train_step(&[short]).unwrap_err().to_string();
    assert!(err.contains("training window 0") && err.contains("20 frames"), "{err}");
    let mut nan = data.train.get(0).to_vec();
    nan[5] = f32::NAN;
    assert!(trainer.train_step(&[&nan]).unwrap_err().to_string().contains("NaN"));
    assert_eq!(trainer.steps(), 0);
    let wrong = config.clone().with_dim(config.dim + 3);
    assert!(GeneratorTrainer::new(&wrong, data.spec.clone(), data.norm.clone(), &Device::Cpu).is_err());
    let long = Config { train: TrainConfig { window: 400, ..config.train.clone() }, ..config.clone() };
    let clips = clips(2);
    let refs: Vec<&Clip> = clips.iter().collect();
    let err = TrainingData::from_clips(&long, 30.0, &refs[..1], &refs[1..]).unwrap_err().to_string();
    assert!(err.contains("too short"), "{err}");
}

#[test]
fn synthesis_is_seeded_and_decodes_to_motion() {
    let config = Config::tiny();
    let data = data(&config);
    let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let g = trainer.model();
    let d = config.dim;
    let seed = &data.valid.get(0)[..2 * d];
    let sample = |s: u64, t: f64| {
        let mut rng = SplitMix64::new(s);
        g.sample(seed, &g.zero_state(1).unwrap(), 30, &mut rng, t).unwrap().0
    };
    let (a, b, c) = (sample(1, 1.0), sample(1, 1.0), sample(2, 1.0));
    assert_eq!(a, b);
    assert_ne!(a, c);
    let cold = sample(1, 0.1);
    assert_ne!(a, cold);
    let mut frames = a.clone();
    data.norm.denormalize(&mut frames);
    let motion = data.spec.decode(&frames, RootPlacement::default()).unwrap();
    assert_eq!((motion.clip.frames(), motion.contacts.len()), (30, 30));
    assert!(motion.clip.global().1.iter().all(|p| p.is_finite()));
    assert!(g.sample(&seed[..d - 1], &g.zero_state(1).unwrap(), 3, &mut SplitMix64::new(1), 1.0).is_err());
    assert!(g.sample(seed, &g.zero_state(1).unwrap(), 3, &mut SplitMix64::new(1), f64::NAN).is_err());
}

#[test]
fn the_estimated_initial_state_makes_the_seed_frames_more_likely() {
    let config = Config::tiny();
    let data = data(&config);
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let batch: Vec<&[f32]> = (0..8).map(|i| data.train.get(i)).collect();
    for _ in 0..5 {
        trainer.train_step(&batch).unwrap();
    }
    let d = config.dim;
    let frames = &data.valid.get(0)[..2 * d];
    let est = estimate_initial_state(trainer.model(), frames, 30, 0.05).unwrap();
    assert!(est.nll < est.nll_zero - 1.0, "{} vs {}", est.nll, est.nll_zero);
    let again = estimate_initial_state(trainer.model(), frames, 30, 0.05).unwrap();
    assert_eq!(est.nll, again.nll);
    assert!(estimate_initial_state(trainer.model(), &frames[..d], 30, 0.05).is_err());
}

/// A tiny generator trained for a few steps, saved in `dir`; the first 24 training windows.
fn generator_run(dir: &Path) -> (Config, TrainingData, Windows) {
    let config = Config::tiny();
    let data = data(&config);
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let batch: Vec<&[f32]> = (0..8).map(|i| data.train.get(i)).collect();
    for _ in 0..3 {
        trainer.train_step(&batch).unwrap();
    }
    trainer.save(dir).unwrap();
    let n = 24 * config.train.window * config.dim;
    let real = Windows { data: data.train.data[..n].to_vec(), ..data.train.clone() };
    (config, data, real)
}

#[test]
fn adversarial_rounds_run_with_finite_losses_and_resume_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let make = || AdversarialTrainer::new(&gen_dir, &config.refiner, &real, &data.valid, &Device::Cpu).unwrap();
    let (whole, part) = (dir.path().join("whole"), dir.path().join("part"));
    let run = |out: &Path, epochs: usize, resume: bool| {
        let mut training = AdversarialTraining::new(make(), &real);
        let state = train(&mut training, &TrainOptions { resume, ..opts(out, epochs) }).unwrap();
        (state, training.trainer().last_discriminator_loss(), training.trainer().refiner_updates())
    };
    let (a, d_loss, k) = run(&whole, 2, false);
    assert!(a.train_loss.iter().chain(&a.valid_loss).all(|l| l.is_finite()), "{a:?}");
    let d_loss = d_loss.unwrap();
    assert!(d_loss.is_finite() && d_loss > 0.0, "{d_loss}");
    assert!((1..=config.refiner.max_refiner_updates).contains(&k));
    // Warm-up (3) plus k refiner updates per round (3 rounds of 8 of the 24 windows per epoch).
    assert!(a.steps >= 3 + 6, "{} refiner steps", a.steps);
    for f in
        ["refiner.safetensors", "discriminator.safetensors", "effectors.json", "model.safetensors", "features.json"]
    {
        assert!(whole.join(f).is_file(), "{f}");
    }
    for f in [
        "refiner_optimizer.safetensors",
        "discriminator_optimizer.safetensors",
        "history.safetensors",
        "adversarial.json",
    ] {
        assert!(whole.join("last").join(f).is_file(), "{f}");
    }
    run(&part, 1, false);
    let (b, _, _) = run(&part, 2, true);
    assert_eq!((a.train_loss[1], a.valid_loss[1], a.steps), (b.train_loss[1], b.valid_loss[1], b.steps));
    for f in ["last/refiner.safetensors", "last/discriminator.safetensors", "last/history.safetensors"] {
        assert_eq!(bytes(&whole.join(f)), bytes(&part.join(f)), "{f}");
    }
    let summary: serde_json::Value = serde_json::from_slice(&bytes(&whole.join("summary.json"))).unwrap();
    assert_eq!((summary["model"].as_str(), summary["stage"].as_str()), (Some("rnn-gmm"), Some("refiner")));
    // The run folder loads for inference; the refiner changes the motion but keeps its shape.
    let last = whole.join("last");
    let model = zoo_rnngmm::refiner::load(&last, &Device::Cpu).unwrap();
    let x = Tensor::from_slice(data.valid.get(0), (1, config.train.window, config.dim), &Device::Cpu).unwrap();
    let r = model.nets.refine(&x).unwrap();
    assert_eq!(r.dims(), x.dims());
    // Loaded for inference the weights are constants: refining records no operation for
    // backpropagation, so a stream of chunks keeps no graph of the motion alive (memory
    // independent of the length, no recursive drop of a long graph).
    assert!(!r.track_op(), "the refiner's output records its operations: its weights are variables");
    let state = model.nets.refiner_zero_state(1).unwrap();
    let (chunk, state) = model.nets.refine_chunk(&x, None, &state).unwrap();
    assert!(!chunk.track_op() && state.h.iter().chain(&state.c).all(|t| !t.track_op()));
    let moved = (r - &x).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
    assert!(moved > 0.0 && moved.is_finite(), "{moved}");
    let err = zoo_rnngmm::refiner::load(&gen_dir, &Device::Cpu).unwrap_err().to_string();
    assert!(err.contains("generator run"), "{err}");
    // Synthesis continues a clip where it stands, seeded, with and without the refiner.
    let clip = &clips(7)[6];
    let o = SynthesisOptions { frames: 40, init_steps: 10, seed_frames: 3, ..SynthesisOptions::default() };
    let s1 = synthesize(&model.generator, Some(&model.nets), clip, 10, &o).unwrap();
    let s2 = synthesize(&model.generator, Some(&model.nets), clip, 10, &o).unwrap();
    let raw = synthesize(&model.generator, None, clip, 10, &o).unwrap();
    let other =
        synthesize(&model.generator, Some(&model.nets), clip, 10, &SynthesisOptions { seed: 2, ..o.clone() }).unwrap();
    assert_eq!(s1.features, s2.features);
    assert_ne!(s1.features, raw.features);
    assert_ne!(s1.features, other.features);
    assert_eq!((s1.motion.clip.frames(), s1.motion.contacts.len()), (40, 40));
    assert!(s1.seed_nll.1 <= s1.seed_nll.0, "{:?}", s1.seed_nll);
    let (start, first) = (clip.root_position(10), s1.motion.clip.root_position(0));
    let hop = ((start.x - first.x).powi(2) + (start.z - first.z).powi(2)).sqrt();
    assert!(hop < 60.0, "the first generated frame is {hop} cm from the seed frame");
    assert!(s1.motion.clip.global().1.iter().all(|p| p.is_finite()));
    let err = synthesize(&model.generator, None, clip, 1, &o).unwrap_err().to_string();
    assert!(err.contains("seed frames"), "{err}");
}

#[test]
fn the_refiners_skate_term_is_the_benchmarks_measure_and_its_range_term_counts_excess() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let whole_range = RefinerConfig { range_percentile: 0.0, ..config.refiner.clone() };
    let t = AdversarialTrainer::new(&gen_dir, &whole_range, &real, &data.valid, &Device::Cpu).unwrap();
    let priors = t.priors().unwrap();
    let (w, d) = (real.window, real.dim);
    // The skate term of a real window against zoo_data's skate measure on the decoded clip.
    let x = Tensor::from_slice(real.get(5), (1, w, d), &Device::Cpu).unwrap();
    let term = priors.skate(t.nets(), &x).unwrap().to_scalar::<f32>().unwrap() as f64;
    let mut values = real.get(5).to_vec();
    data.norm.denormalize(&mut values);
    let clip = data.spec.decode(&values, RootPlacement::default()).unwrap().clip;
    let (_, gp) = clip.global();
    let effectors = zoo_rnngmm::fk::end_effectors(&data.spec);
    let joints: Vec<usize> = priors.feet().iter().map(|&k| effectors[k]).collect();
    assert_eq!(joints.len(), 4, "ankles and toes: {joints:?}");
    let planted = priors.planted().unwrap().iter().map(|&g| g as f64).collect();
    let measure = zoo_data::metrics::FootSkate { joints, planted, scale: 2.5 }.skate(&gp, w, clip.joints());
    assert!(measure > 0.01, "{measure}");
    assert!((term - measure).abs() < 1e-3 * measure.max(1.0), "term {term} vs measure {measure}");
    // Range: nothing on a training window, the excess (mean over frames) beyond its min / max.
    assert_eq!(priors.range(&x).unwrap().to_scalar::<f32>().unwrap(), 0.0);
    let (lo, hi) = (0..real.len())
        .flat_map(|i| real.get(i).chunks(d).map(|f| f[8]))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let mut out = real.get(5).to_vec();
    out[3 * d + 8] = hi + 2.0;
    out[4 * d + 8] = lo - 1.0;
    let y = Tensor::from_vec(out, (1, w, d), &Device::Cpu).unwrap();
    let excess = priors.range(&y).unwrap().to_scalar::<f32>().unwrap();
    assert!((excess - 3.0 / w as f32).abs() < 1e-5, "{excess}");
    // The validation measure leaves the adversarial term out.
    let v = t.validation_terms().unwrap();
    let want = v.skate + v.range + whole_range.lambda * v.regularisation;
    assert!((t.validation_loss().unwrap() - want).abs() < 1e-9 && v.skate > 0.0, "{v:?}");
    // Fakes that start 6 frames past the seed are other windows of the same generator.
    let lead = RefinerConfig { fake_lead_frames: 6, ..whole_range.clone() };
    let led = AdversarialTrainer::new(&gen_dir, &lead, &real, &data.valid, &Device::Cpu).unwrap();
    let (a, b) = (t.training_terms().unwrap(), led.training_terms().unwrap());
    assert!(b.skate.is_finite() && b.skate != a.skate, "{a:?} {b:?}");
}

#[test]
fn joint_limits_clamp_the_refined_frames_and_root_smoothing_frees_the_jitter() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let (w, d) = (real.window, real.dim);
    let (lo, hi) = (0..real.len())
        .flat_map(|i| real.get(i).chunks(d).map(|f| f[8]))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
    let mut out = real.get(5).to_vec();
    (out[3 * d + 8], out[4 * d + 8], out[5 * d]) = (hi + 2.0, lo - 1.0, 1e3);
    let x = Tensor::from_vec(out.clone(), (1, w, d), &Device::Cpu).unwrap();
    // The new refiner is the identity (eq. 11's W2, b2 start at zero), so it returns its input
    // clamped to the limits: the training windows' min and max; dtx is not limited.
    let limited = AdversarialTrainer::new(&gen_dir, &config.refiner, &real, &data.valid, &Device::Cpu).unwrap();
    let r = limited.nets().refine(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert_eq!((r[3 * d + 8], r[4 * d + 8], r[5 * d]), (hi, lo, 1e3));
    assert!(r.iter().zip(&out).enumerate().all(|(i, (a, b))| a == b || [3 * d + 8, 4 * d + 8].contains(&i)));
    // Streaming in chunks clamps the same way.
    let state = limited.nets().refiner_zero_state(1).unwrap();
    let (chunk, _) = limited.nets().refine_chunk(&x.narrow(1, 0, 4).unwrap(), None, &state).unwrap();
    assert_eq!(chunk.flatten_all().unwrap().to_vec1::<f32>().unwrap()[3 * d + 8], hi);
    let free = RefinerConfig { joint_limits: false, root_smoothing: 0.0, ..config.refiner.clone() };
    let unlimited = AdversarialTrainer::new(&gen_dir, &free, &real, &data.valid, &Device::Cpu).unwrap();
    let r = unlimited.nets().refine(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert_eq!(r, out);
    // Eq. 13 holds the identity refiner to an unsmoothed root exactly, and to the smoothed one
    // only where the root is not steady: the jittered dtx of frame 5 costs.
    let reg = |c: &RefinerConfig, x: &Tensor| unlimited.nets().refiner_loss(x, c, None).unwrap().regularisation;
    assert_eq!(reg(&free, &x), 0.0);
    let smooth = RefinerConfig { root_smoothing: 2.0, ..free.clone() };
    assert!(reg(&smooth, &x) > 1.0, "{}", reg(&smooth, &x));
    let steady =
        Tensor::from_vec((0..w).flat_map(|_| real.get(5)[..d].to_vec()).collect::<Vec<f32>>(), (1, w, d), &Device::Cpu)
            .unwrap();
    assert!(reg(&smooth, &steady) < 1e-9, "{}", reg(&smooth, &steady));
}

#[test]
fn the_smoothing_matrix_keeps_constants_and_lines_and_damps_jitter() {
    let t = 30;
    let m = zoo_rnngmm::refiner::smoothing_matrix(t, 2.0);
    let apply = |v: &[f64]| -> Vec<f64> { (0..t).map(|i| (0..t).map(|j| m[i * t + j] as f64 * v[j]).sum()).collect() };
    assert!(apply(&vec![3.0; t]).iter().all(|v| (v - 3.0).abs() < 1e-5));
    // A line is kept where the filter is whole (6 frames from either end).
    let line: Vec<f64> = (0..t).map(|i| 0.5 * i as f64).collect();
    let l = apply(&line);
    assert!((6..t - 6).all(|i| (l[i] - line[i]).abs() < 1e-4), "{l:?}");
    let jitter: Vec<f64> = (0..t).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
    assert!(apply(&jitter)[6..t - 6].iter().all(|v| v.abs() < 1e-3));
}

#[test]
fn discriminator_collapse_stops_training_and_keeps_the_last_good_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let out = dir.path().join("run");
    let good = AdversarialTrainer::new(&gen_dir, &config.refiner, &real, &data.valid, &Device::Cpu).unwrap();
    train(&mut AdversarialTraining::new(good, &real), &opts(&out, 1)).unwrap();
    let kept = bytes(&out.join("refiner.safetensors"));
    // Every loss counts as collapsed: the refiner already gets its most updates, and two such
    // rounds in a row stop the run.
    let collapsing = RefinerConfig {
        collapse_loss: f64::INFINITY,
        collapse_rounds: 2,
        max_refiner_updates: config.refiner.refiner_updates,
        ..config.refiner.clone()
    };
    let bad = AdversarialTrainer::new(&gen_dir, &collapsing, &real, &data.valid, &Device::Cpu).unwrap();
    let err = train(&mut AdversarialTraining::new(bad, &real), &TrainOptions { resume: true, ..opts(&out, 3) })
        .unwrap_err()
        .to_string();
    assert!(err.contains("discriminator collapse") && err.contains("last good checkpoint is kept"), "{err}");
    assert_eq!(bytes(&out.join("refiner.safetensors")), kept);
    // Bad settings are refused before anything runs.
    let wrong = RefinerConfig { history: 2, ..config.refiner.clone() };
    let err = AdversarialTrainer::new(&gen_dir, &wrong, &real, &data.valid, &Device::Cpu).err().unwrap().to_string();
    assert!(err.contains("history"), "{err}");
}

/// Throughput of one generator training step and one adversarial round at the paper's sizes on
/// synthetic locomotion (for the training budget; run with `--ignored --nocapture`).
#[test]
#[ignore = "timing: prints windows/s of the paper preset"]
fn paper_preset_throughput() {
    let config = Config::paper();
    let clips = clips(12);
    let refs: Vec<&Clip> = clips.iter().collect();
    let data = TrainingData::from_clips(&config, 30.0, &refs[..10], &refs[10..]).unwrap();
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    let b = config.train.batch_size;
    let batch: Vec<&[f32]> = (0..b).map(|i| data.train.get(i)).collect();
    trainer.train_step(&batch).unwrap();
    let steps = 5;
    let t = std::time::Instant::now();
    for _ in 0..steps {
        trainer.train_step(&batch).unwrap();
    }
    let secs = t.elapsed().as_secs_f64();
    eprintln!(
        "generator (paper, batch {b}, window {}): {:.1} windows/s",
        config.train.window,
        (steps * b) as f64 / secs
    );
    let dir = tempfile::tempdir().unwrap();
    trainer.save(dir.path()).unwrap();
    let mut adv = AdversarialTrainer::new(dir.path(), &config.refiner, &data.train, &data.valid, &Device::Cpu).unwrap();
    let t = std::time::Instant::now();
    for _ in 0..3 {
        adv.refiner_update().unwrap();
    }
    eprintln!("refiner update (batch {}): {:.2} s", config.refiner.batch, t.elapsed().as_secs_f64() / 3.0);
}

/// The feature on real motion: bandai2's walks and runs round-trip, both feet are found, the
/// joint rotation vectors stay away from pi, contact bits are neither always on nor always off.
#[test]
#[ignore = "needs ../shared/data/bandai2 (run with --ignored --nocapture)"]
fn bandai2_clips_round_trip_through_the_feature() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../../shared/data/bandai2");
    let clips = zoo_data::dataset::load_matching(&root, Some("dataset-2_*_00[1-3].bvh*")).unwrap();
    let refs: Vec<&Clip> = clips.iter().map(|c| &c.clip).collect();
    let spec = FeatureSpec::fit(&refs[0].skeleton, 30.0, &refs).unwrap();
    assert_eq!(spec.dim(), 68);
    let (mut worst, mut largest_angle, mut on, mut total) = (0f64, 0f32, 0usize, 0usize);
    for c in &clips {
        let enc = spec.encode(&c.clip).unwrap();
        let dec = spec.decode(&enc.values, enc.origin).unwrap();
        let (_, a) = c.clip.global();
        let (_, b) = dec.clip.global();
        let err = a.iter().zip(&b).map(|(p, q)| (*p - *q).length()).fold(0.0, f64::max);
        worst = worst.max(err);
        for f in 0..enc.frames() {
            let x = enc.frame(f);
            for j in 1..spec.skeleton.len() {
                let i = spec.joint_index(j);
                largest_angle = largest_angle.max((x[i] * x[i] + x[i + 1] * x[i + 1] + x[i + 2] * x[i + 2]).sqrt());
            }
            on += (x[66] > 0.5) as usize + (x[67] > 0.5) as usize;
            total += 2;
        }
    }
    let frac = on as f64 / total as f64;
    eprintln!(
        "bandai2: {} clips, largest position error {worst:.2e} cm, largest joint rotation from its reference \
         {largest_angle:.2} rad, feet planted {:.1}% of foot-frames",
        clips.len(),
        100.0 * frac
    );
    assert!(worst < 1e-3, "{worst}");
    assert!(largest_angle < 2.5, "{largest_angle}");
    assert!((0.2..0.9).contains(&frac), "{frac}");
}

#[test]
fn refiner_updates_per_round_follow_the_discriminator_loss() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let idx: Vec<usize> = (0..config.refiner.batch).collect();
    // Every discriminator loss counts as "too strong": the refiner's updates double up to the cap.
    let strong = RefinerConfig { low_loss: f64::MAX / 2.0, high_loss: f64::MAX, ..config.refiner.clone() };
    let mut t = AdversarialTrainer::new(&gen_dir, &strong, &real, &data.valid, &Device::Cpu).unwrap();
    assert_eq!(t.refiner_updates(), 2);
    let ks: Vec<usize> = (0..3).map(|_| t.round(&real, &idx).map(|_| t.refiner_updates()).unwrap()).collect();
    assert_eq!(ks, [4, 8, 8]);
    // Every loss counts as "too weak": they halve down to 1.
    let weak = RefinerConfig { low_loss: -2.0, high_loss: -1.0, refiner_updates: 4, ..config.refiner.clone() };
    let mut t = AdversarialTrainer::new(&gen_dir, &weak, &real, &data.valid, &Device::Cpu).unwrap();
    let ks: Vec<usize> = (0..3).map(|_| t.round(&real, &idx).map(|_| t.refiner_updates()).unwrap()).collect();
    assert_eq!(ks, [2, 1, 1]);
    assert!(t.last_discriminator_loss().is_some_and(f64::is_finite));
}

#[test]
fn streaming_synthesis_does_not_depend_on_the_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let mut adv = AdversarialTrainer::new(&gen_dir, &config.refiner, &real, &data.valid, &Device::Cpu).unwrap();
    // A few updates move the refiner off the identity it starts as.
    for _ in 0..3 {
        adv.refiner_update().unwrap();
    }
    let model = zoo_rnngmm::checkpoint::load(&gen_dir, &Device::Cpu).unwrap();
    let clip = &clips(7)[6];
    let o = SynthesisOptions { frames: 45, init_steps: 3, ..SynthesisOptions::default() };
    let stream = || SynthesisStream::new(&model, Some(adv.nets()), clip, 10, &o).unwrap().keep_unrefined();
    let whole = stream().next_chunk(45).unwrap();
    let mut s = stream();
    let parts: Vec<_> = [1, 7, 30, 7].iter().map(|&n| s.next_chunk(n).unwrap()).collect();
    assert_eq!(s.generated(), 45);
    // The generator's frames are the same draws, decoded to the same poses and places.
    let raw = whole.unrefined.as_ref().unwrap();
    let raw_parts: Vec<_> =
        parts.iter().flat_map(|p| p.unrefined.as_ref().unwrap().clip.local_rotations.clone()).collect();
    assert_eq!(raw.clip.local_rotations, raw_parts);
    let roots: Vec<_> =
        parts.iter().flat_map(|p| (0..p.motion.clip.frames()).map(|f| p.motion.clip.root_position(f))).collect();
    let refined: Vec<f32> = parts.iter().flat_map(|p| p.features.clone()).collect();
    assert_eq!(refined.len(), whole.features.len());
    let worst = refined.iter().zip(&whole.features).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0f32, f32::max);
    assert!(worst < 1e-4, "chunked refinement differs by {worst}");
    for (f, r) in roots.iter().enumerate() {
        assert!((*r - whole.motion.clip.root_position(f)).length() < 1e-3, "frame {f}");
    }
    // The refiner changed the motion.
    assert_ne!(whole.motion.clip.local_rotations, raw.clip.local_rotations);
}

fn all_weights(t: &GeneratorTrainer) -> Vec<(String, Vec<f32>)> {
    let data = t.varmap().data().lock().unwrap();
    let mut v: Vec<(String, Vec<f32>)> =
        data.iter().map(|(n, v)| (n.clone(), v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap())).collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

/// Data-parallel generator training (issue 18): two workers give the one-worker loss and,
/// after the RMSProp step, the same weights to 1e-5 relative for all but float-noise-level
/// gradient components (RMSProp's first step divides each component by its own magnitude);
/// the same thread count repeats bit for bit.
#[test]
fn two_thread_generator_step_matches_the_one_thread_step() {
    let config = Config::tiny();
    let data = data(&config);
    let batch: Vec<&[f32]> = (0..5).map(|i| data.train.get(i)).collect();
    let trainer = |threads: usize| {
        let mut t = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
        t.set_threads(threads).unwrap();
        t
    };
    let (mut one, mut two) = (trainer(1), trainer(2));
    let before = all_weights(&one);
    let (l1, l2) = (one.train_step(&batch).unwrap(), two.train_step(&batch).unwrap());
    assert!((l1 - l2).abs() <= 1e-5 * l1.abs(), "loss {l1} vs {l2}");
    let (w1, w2) = (all_weights(&one), all_weights(&two));
    let (mut noisy, mut total, mut moved) = (0, 0, 0);
    for (((n, a), (_, b)), (_, w0)) in w1.iter().zip(&w2).zip(&before) {
        let scale = w0.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-3);
        for ((x, y), z) in a.iter().zip(b).zip(w0) {
            assert!((x - y).abs() <= 0.1 * scale, "{n}: {x} vs {y}");
            noisy += usize::from((x - y).abs() > 1e-5 * scale);
            moved += usize::from(x != z);
            total += 1;
        }
    }
    assert!(moved > 0);
    assert!(noisy * 1000 <= total, "{noisy} of {total} weights differ by more than 1e-5 relative");
    let mut again = trainer(2);
    assert_eq!(again.train_step(&batch).unwrap().to_bits(), l2.to_bits());
    assert_eq!(all_weights(&again), w2);
}

fn varmap_weights(v: &VarMap) -> Vec<(String, Vec<f32>)> {
    let data = v.data().lock().unwrap();
    let mut w: Vec<(String, Vec<f32>)> =
        data.iter().map(|(n, v)| (n.clone(), v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap())).collect();
    w.sort_by(|a, b| a.0.cmp(&b.0));
    w
}

/// Data-parallel adversarial training (issue 18): with two workers, a round (warm-up, refiner
/// updates, a discriminator update) gives the one-worker losses and weights up to float
/// summation order, and the same bits for the same thread count.
#[test]
fn two_thread_adversarial_round_matches_the_one_thread_round() {
    let dir = tempfile::tempdir().unwrap();
    let gen_dir = dir.path().join("generator");
    let (config, data, real) = generator_run(&gen_dir);
    let make = |threads: usize| {
        let mut t = AdversarialTrainer::new(&gen_dir, &config.refiner, &real, &data.valid, &Device::Cpu).unwrap();
        t.set_threads(threads).unwrap();
        assert_eq!(t.threads(), threads);
        t
    };
    let (mut one, mut two) = (make(1), make(2));
    let idx: Vec<usize> = (0..config.refiner.batch.min(real.len())).collect();
    let (l1, l2) = (one.round(&real, &idx).unwrap(), two.round(&real, &idx).unwrap());
    assert!((l1 - l2).abs() <= 1e-5 * l1.abs(), "refiner loss {l1} vs {l2}");
    let (d1, d2) = (one.last_discriminator_loss().unwrap(), two.last_discriminator_loss().unwrap());
    assert!((d1 - d2).abs() <= 1e-5 * d1.abs(), "discriminator loss {d1} vs {d2}");
    for (m1, m2) in [(one.varmaps().0, two.varmaps().0), (one.varmaps().1, two.varmaps().1)] {
        let (w1, w2) = (varmap_weights(m1), varmap_weights(m2));
        let (mut noisy, mut total) = (0, 0);
        for ((n, a), (_, b)) in w1.iter().zip(&w2) {
            let scale = a.iter().fold(0f32, |m, v| m.max(v.abs())).max(1e-3);
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= 0.1 * scale, "{n}: {x} vs {y}");
                noisy += usize::from((x - y).abs() > 1e-5 * scale);
                total += 1;
            }
        }
        assert!(noisy * 100 <= total, "{noisy} of {total} weights differ by more than 1e-5 relative");
    }
    let mut again = make(2);
    assert_eq!(again.round(&real, &idx).unwrap().to_bits(), l2.to_bits());
    assert_eq!(varmap_weights(again.varmaps().0), varmap_weights(two.varmaps().0));
    assert_eq!(varmap_weights(again.varmaps().1), varmap_weights(two.varmaps().1));
}
