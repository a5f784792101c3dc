//! Path following (sec. 5.2) and online control (sec. 5.3) on a tiny generator trained on
//! synthetic locomotion: the unrolled generator is the generator, its root trajectory is where
//! the decoded clip's root goes, following is seeded and reports distances that match the decoded
//! motion, and online control is seeded, steers and refuses bad settings.

use candle_core::{DType, Device, Tensor};
use zoo_data::synth::{SynthConfig, generate_clip};
use zoo_motion::Clip;
use zoo_rnngmm::checkpoint::LoadedGenerator;
use zoo_rnngmm::control::{ControlStart, rollout, world_root};
use zoo_rnngmm::controls::{ControlKey, ControlScript};
use zoo_rnngmm::fk::TensorFk;
use zoo_rnngmm::path::GroundPath;
use zoo_rnngmm::prelude::*;
use zoo_rnngmm::{FollowOptions, OnlineOptions, TrainingData, follow};

fn clips(n: usize) -> Vec<Clip> {
    let cfg = SynthConfig { minutes: 1.0, seed: 3, terrain: false, fps: 30.0, clip_seconds: 6.0 };
    (0..n).map(|i| generate_clip(&cfg, i).clip).collect()
}

/// A tiny generator trained for 40 steps and the clips it saw.
fn model() -> (LoadedGenerator, Vec<Clip>) {
    let config = Config::tiny();
    let clips = clips(6);
    let refs: Vec<&Clip> = clips.iter().collect();
    let data = TrainingData::from_clips(&config, 30.0, &refs[..5], &refs[5..]).unwrap();
    let config = config.with_dim(data.spec.dim());
    let mut trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    for k in 0..40 {
        let batch: Vec<&[f32]> = (0..8).map(|i| data.train.get((k * 8 + i) % data.train.len())).collect();
        trainer.train_step(&batch).unwrap();
    }
    (LoadedGenerator { generator: trainer.model().clone(), spec: data.spec.clone(), norm: data.norm.clone() }, clips)
}

#[test]
fn the_rollout_draws_from_the_top_component_and_its_root_is_the_decoded_root() {
    let (m, clips) = model();
    let (d, t) = (m.spec.dim(), 12);
    let placement = RootPlacement { x: 120.0, z: -40.0, yaw: 0.7 };
    let start = ControlStart::from_clip(&m, &clips[0], 29, 2, 0, placement).unwrap();
    let eps: Vec<f32> = (0..t * d).map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) * 0.6).collect();
    let eps = Tensor::from_vec(eps, (1, t, d), &Device::Cpu).unwrap();
    let r = rollout(&m, &start, &eps, &eps.zeros_like().unwrap(), None).unwrap();
    // Frame 0: the start's mixture, its most probable component, mu + sigma * e.
    let head = start.head.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let mix = m.generator.mixture_of(&head).unwrap();
    let k = (0..mix.components()).max_by(|a, b| mix.weights[*a].total_cmp(&mix.weights[*b])).unwrap();
    let s0 = r.states.narrow(1, 0, 1).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let e0 = eps.narrow(1, 0, 1).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    for j in 0..d {
        let want = mix.means[k * d + j] + mix.stds[k * d + j] * e0[j] as f64;
        assert!((s0[j] as f64 - want).abs() < 1e-4, "value {j}: {} vs {want}", s0[j]);
    }
    // Its NLL is the mixture's.
    let nll0 = r.nll.narrow(1, 0, 1).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap()[0] as f64;
    assert!((nll0 - mix.nll(&s0)).abs() < 1e-2 * (1.0 + nll0.abs()), "{nll0} vs {}", mix.nll(&s0));
    // The world root of the states is where decoding them from the placement puts the root.
    let feet: Vec<usize> = m.spec.left_foot.iter().chain(&m.spec.right_foot).copied().collect();
    let fk = TensorFk::new(&m.spec, &m.norm, &feet, &Device::Cpu).unwrap();
    let root = world_root(&fk, &r.states, &placement).unwrap().flatten_all().unwrap().to_dtype(DType::F64).unwrap();
    let root = root.to_vec1::<f64>().unwrap();
    let mut raw = r.states.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    m.norm.denormalize(&mut raw);
    let motion = m.spec.decode(&raw, placement).unwrap();
    let (_, gp) = motion.clip.global();
    let joints = motion.clip.joints();
    for f in 0..t {
        let p = gp[f * joints];
        assert!((p.x - root[2 * f]).abs() < 1e-2 && (p.z - root[2 * f + 1]).abs() < 1e-2, "frame {f}: {p:?}");
    }
}

#[test]
fn following_is_seeded_and_its_distances_are_the_decoded_roots() {
    let (m, clips) = model();
    // Three metres straight ahead of the start clip's direction of travel.
    let path = GroundPath::new(vec![[0.0, 0.0], [30.0, 150.0], [0.0, 300.0]]).unwrap();
    let opts = FollowOptions { particles: 4, swarm_iterations: 1, iterations: 4, ..FollowOptions::default() };
    let run = || follow(&m, &clips[1], 40, &path, &opts, &mut |_| {}).unwrap();
    let (a, b) = (run(), run());
    assert_eq!(a.motion.clip.local_rotations, b.motion.clip.local_rotations);
    assert_eq!(a.distance, b.distance);
    let frames = a.motion.clip.frames();
    assert!(frames > 0 && a.distance.len() == frames && a.progress.len() == frames);
    let (_, gp) = a.motion.clip.global();
    let joints = a.motion.clip.joints();
    let mut s_lo = -100.0;
    for f in 0..frames {
        let p = gp[f * joints];
        let n = path.nearest([p.x, p.z], s_lo, s_lo + 10_000.0);
        assert!((n.distance - a.distance[f]).abs() < 0.5, "frame {f}: {} vs {}", n.distance, a.distance[f]);
        s_lo = s_lo.max(n.s - 100.0);
    }
    let mean = a.distance.iter().sum::<f64>() / frames as f64;
    assert!(mean < 30.0, "mean distance {mean}");
    // Bad settings are refused.
    let bad = FollowOptions { overlap: 34, ..opts.clone() };
    assert!(follow(&m, &clips[1], 40, &path, &bad, &mut |_| {}).is_err());
    let bad = FollowOptions { sigma_fit: f64::NAN, ..opts };
    assert!(follow(&m, &clips[1], 40, &path, &bad, &mut |_| {}).unwrap_err().to_string().contains("sigma_fit"));
}

#[test]
fn the_rollouts_gradient_matches_finite_differences() {
    let (m, clips) = model();
    let (d, t) = (m.spec.dim(), 6);
    let start = ControlStart::from_clip(&m, &clips[0], 29, 2, 0, RootPlacement::default()).unwrap();
    let base: Vec<f32> = (0..2 * t * d).map(|i| ((i * 53 % 97) as f32 / 97.0 - 0.5) * 0.4).collect();
    let comps = {
        let e = Tensor::from_slice(&base[..t * d], (1, t, d), &Device::Cpu).unwrap();
        rollout(&m, &start, &e, &e.zeros_like().unwrap(), None).unwrap().components
    };
    let energy = |v: &[f32]| -> (f64, Vec<f32>) {
        let e = candle_core::Var::from_slice(&v[..t * d], (1, t, d), &Device::Cpu).unwrap();
        let n = candle_core::Var::from_slice(&v[t * d..], (1, t, d), &Device::Cpu).unwrap();
        let r = rollout(&m, &start, e.as_tensor(), &(n.as_tensor() * 0.05).unwrap(), Some(&comps)).unwrap();
        let total = r.nll.sum_all().unwrap();
        let g = total.backward().unwrap();
        let mut grad = g.get(&e).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        grad.extend(g.get(&n).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap());
        (total.to_dtype(DType::F64).unwrap().to_scalar::<f64>().unwrap(), grad)
    };
    let (_, grad) = energy(&base);
    // A few draws and noise values of the first frames (their effect runs through the LSTM).
    for &i in &[0, 3, d + 1, 2 * d + 5, t * d, t * d + 2, t * d + d + 7] {
        let h = 1e-2f32;
        let (mut up, mut down) = (base.clone(), base.clone());
        up[i] += h;
        down[i] -= h;
        let fd = (energy(&up).0 - energy(&down).0) / (2.0 * h as f64);
        let g = grad[i] as f64;
        assert!(
            (fd - g).abs() <= 0.05 * fd.abs().max(g.abs()) + 0.05,
            "unknown {i}: finite differences {fd}, gradient {g}"
        );
    }
}

/// A script of `seconds` at `speed` (cm/s) facing `heading` (radians) from 0.5 s on (0 before).
fn turn_script(speed: f64, heading: f64, seconds: f64) -> ControlScript {
    ControlScript::new(
        vec![ControlKey { time: 0.0, speed, heading: 0.0 }, ControlKey { time: 0.5, speed, heading }],
        seconds,
    )
    .unwrap()
}

#[test]
fn online_control_is_seeded_and_turns_towards_the_heading() {
    let (m, clips) = model();
    let opts = OnlineOptions { init_steps: 0, ..OnlineOptions::default() };
    let run = |heading: f64, opts: &OnlineOptions| {
        let mut batches = 0;
        let c = zoo_rnngmm::online::control(&m, &clips[0], 29, &turn_script(100.0, heading, 2.5), opts, &mut |_| {
            batches += 1
        })
        .unwrap();
        (c, batches)
    };
    let (left, batches) = run(1.2, &opts);
    // 2.5 s at 30 fps in batches of 3: every frame, one progress call per batch.
    assert_eq!(left.speed.len(), 75);
    assert_eq!(left.yaw.len(), 75);
    assert_eq!(left.motion.clip.frames(), 75);
    assert_eq!(batches, 25);
    assert_eq!(left.batch_seconds.len(), 25);
    assert!(left.seconds_per_frame() > 0.0);
    // The same seed gives the same motion; another seed another.
    let (again, _) = run(1.2, &opts);
    assert_eq!(left.speed, again.speed);
    assert_eq!(left.yaw, again.yaw);
    let (other, _) = run(1.2, &OnlineOptions { seed: 9, ..opts.clone() });
    assert_ne!(left.yaw, other.yaw);
    // Turning left and right: each run ends closer to its own heading than the other does.
    let (right, _) = run(-1.2, &opts);
    let (l, r) = (*left.yaw.last().unwrap(), *right.yaw.last().unwrap());
    assert!(l > r + 0.5, "left {l}, right {r}");
    assert!((l - 1.2).abs() < (r - 1.2).abs() && (r + 1.2).abs() < (l + 1.2).abs(), "left {l}, right {r}");
    // The yaw reported is the decoded root's facing: the last frame's turn accumulated.
    let d = m.spec.dim();
    let enc = m.spec.encode(&left.motion.clip).unwrap();
    let total: f64 = (1..75).map(|f| enc.values[f * d + 2] as f64).sum();
    assert!((total - (left.yaw[74] - left.yaw[0])).abs() < 1e-3, "{total} vs {}", left.yaw[74] - left.yaw[0]);
    // Without gradient steps the proposals alone steer too.
    let (plain, _) = run(1.2, &OnlineOptions { steps: 0, ..opts.clone() });
    assert!(*plain.yaw.last().unwrap() > r + 0.5);
}

#[test]
fn online_control_refuses_bad_settings() {
    let (m, clips) = model();
    let script = turn_script(100.0, 0.0, 1.0);
    for (opts, want) in [
        (OnlineOptions { batch: 0, ..OnlineOptions::default() }, "at least 1 frame"),
        (OnlineOptions { sigma_speed: f64::NAN, ..OnlineOptions::default() }, "sigma_speed"),
        (OnlineOptions { sigma_heading: 0.0, ..OnlineOptions::default() }, "sigma_heading"),
        (OnlineOptions { temperature: -1.0, ..OnlineOptions::default() }, "temperature"),
        (OnlineOptions { turn_offsets: vec![], ..OnlineOptions::default() }, "at least one"),
        (OnlineOptions { speed_offsets: vec![f64::INFINITY], ..OnlineOptions::default() }, "finite"),
    ] {
        let e = zoo_rnngmm::online::control(&m, &clips[0], 29, &script, &opts, &mut |_| {}).unwrap_err().to_string();
        assert!(e.contains(want), "{opts:?}: {e}");
    }
    // A start frame outside the clip.
    let e = zoo_rnngmm::online::control(&m, &clips[0], 10_000, &script, &OnlineOptions::default(), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("seed frames"), "{e}");
}
