//! Helpers shared by the workspace-level tests.

pub mod onnxruntime;
pub mod toy_onnx;

use glam::{DQuat, DVec3};
use std::path::{Path, PathBuf};
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

/// Path of the `zoo` binary built for these tests (the CLI crate's binary, built by cargo
/// before the tests run because the `zoo-cli` package is a workspace member).
/// `ZOO_BIN`, when set, names another build of the binary (a copy taken right after building,
/// where several checkouts share one target folder).
pub fn zoo_bin() -> PathBuf {
    if let Some(bin) = std::env::var_os("ZOO_BIN") {
        return PathBuf::from(bin);
    }
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(|d| d.parent()).expect("target dir");
    let bin = dir.join(format!("zoo{}", std::env::consts::EXE_SUFFIX));
    assert!(bin.exists(), "{} is missing: build it with `cargo build --bin zoo` (scripts/test.sh does)", bin.display());
    bin
}

/// The synthetic locomotion clip `index` (8 s at 30 fps, the 21-joint skeleton).
pub fn synth_biped_clip(index: usize) -> Clip {
    let cfg = zoo_data::synth::SynthConfig {
        minutes: 0.5,
        seed: 11,
        clip_seconds: 8.0,
        ..zoo_data::synth::SynthConfig::default()
    };
    zoo_data::synth::generate_clip(&cfg, index).clip
}

/// A tiny RTN (`Config::tiny` widths, the paper's 10 context and 30 transition frames, the
/// interpolation residual) on `clip`'s skeleton, or the paper's sizes with `paper`; seeded
/// weights, statistics of `clip`'s windows; calibrated fallback thresholds in its file when
/// given (as `zoo train rtn` writes them).
pub fn biped_rtn_onnx(clip: &Clip, paper: bool, fallback: Option<zoo_rtn::fallback::Fallback>) -> Vec<u8> {
    let sk = &clip.skeleton;
    let base = if paper { zoo_rtn::Config::paper() } else { zoo_rtn::Config::tiny() };
    let mut config = base.with_parents(&sk.parents);
    config.past_frames = 10;
    config.transition_frames = 30;
    config.interp_residual = true;
    config.fallback = fallback;
    let varmap = candle_nn::VarMap::new();
    zoo_rtn::Rtn::new(
        &config,
        zoo_nn::SeededVarMap::builder(&varmap, 7, candle_core::DType::F32, &candle_core::Device::Cpu),
    )
    .expect("RTN");
    let (_, global) = clip.global();
    let k = sk.len();
    let flat: Vec<f32> = global.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
    let w = config.target_frame() + 2;
    let windows: Vec<&[f32]> = (0..clip.frames() - w).step_by(10).map(|s| &flat[s * 3 * k..(s + w) * 3 * k]).collect();
    let stats = zoo_rtn::features::FeatureStats::fit(windows, k, config.target_frame(), true);
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(sk.names.clone()),
        offsets: Some(sk.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).expect("the RTN exports").to_bytes()
}

/// The real dataset folder, when this checkout sits beside `shared/`.
pub fn bandai2() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/bandai2");
    p.is_dir().then_some(p)
}

/// A small 4-joint chain skeleton (root, spine, leg, foot).
pub fn toy_skeleton() -> Skeleton {
    let ch = |position| JointChannels { position, order: EulerOrder::Zxy };
    Skeleton {
        names: ["Hips", "Spine", "Leg", "Foot_L"].iter().map(|s| s.to_string()).collect(),
        parents: vec![None, Some(0), Some(0), Some(2)],
        offsets: vec![
            DVec3::ZERO,
            DVec3::new(0.0, 10.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
        ],
        end_sites: vec![None, Some(DVec3::new(0.0, 5.0, 0.0)), None, Some(DVec3::new(0.0, 0.0, 10.0))],
        channels: vec![ch(true), ch(false), ch(false), ch(false)],
    }
}

/// A walking-like toy clip: the root moves along a curve, joints swing with a phase.
pub fn toy_clip(frames: usize, phase: f64) -> Clip {
    let skeleton = toy_skeleton();
    let j = skeleton.len();
    let mut rot = Vec::with_capacity(frames * j);
    let mut pos = Vec::with_capacity(frames * j);
    for f in 0..frames {
        let t = f as f64 / 30.0 + phase;
        let root = DVec3::new(100.0 * t, 85.0 + 2.0 * (6.0 * t).sin(), 20.0 * (0.5 * t).sin());
        rot.push(DQuat::from_rotation_y(0.3 * t) * DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2));
        rot.push(DQuat::from_rotation_x(0.1 * (3.0 * t).sin()));
        rot.push(DQuat::from_rotation_x(0.5 * (6.0 * t).sin()));
        rot.push(DQuat::from_rotation_x(0.2 * (6.0 * t).cos()));
        pos.push(root);
        pos.extend_from_slice(&skeleton.offsets[1..]);
    }
    Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations: rot, local_positions: pos }
}

/// A tiny RTN (`zoo_rtn::Config::tiny`) on the 4-joint [`toy_skeleton`] with unit statistics,
/// exported as `zoo export --onnx` would (its weights are candle's random initialization): the
/// engine tests' model file.
pub fn tiny_rtn_onnx() -> zoo_export::OnnxModel {
    tiny_rtn_onnx_with_std(10.0)
}

/// [`tiny_rtn_onnx`] with every normalization standard deviation `std`: the step's random
/// outputs become motion of about `std` cm per frame (1: a walk; 10: metres per second). The
/// weights are seeded ([`zoo_nn::SeededVarMap`], seed 7): the same model every run.
pub fn tiny_rtn_onnx_with_std(std: f32) -> zoo_export::OnnxModel {
    tiny_rtn_export(std, false)
}

/// [`tiny_rtn_onnx`] made terrain-aware (`Config::tiny`'s 5 x 5 patch, `terrain` statistics
/// mean -90, std 10: the patch under a root about 90 cm above the ground).
pub fn tiny_terrain_rtn_onnx() -> zoo_export::OnnxModel {
    tiny_rtn_export(10.0, true)
}

fn tiny_rtn_export(std: f32, terrain: bool) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;
    use zoo_rtn::features::{FeatureStats, MeanStd};
    let skeleton = toy_skeleton();
    let config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents).with_terrain(terrain);
    let varmap = VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).expect("tiny RTN");
    let d = config.dim();
    let unit = || MeanStd { mean: vec![0.0; d], std: vec![std; d] };
    let n = config.terrain_dim();
    let terrain = terrain.then(|| MeanStd { mean: vec![-90.0; n], std: vec![10.0; n] });
    let stats = FeatureStats { joints: skeleton.len(), x: unit(), velocity: unit(), offset: unit(), terrain };
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(skeleton.names.clone()),
        offsets: Some(skeleton.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).expect("the tiny RTN exports")
}

/// An untrained RNN-GMM generator trainer of `config`'s sizes on two 6-second clips of the
/// synthetic locomotion (seed 3; the first clip trains, the second validates), with its data.
pub fn rnngmm_fixture(
    config: zoo_rnngmm::prelude::Config,
) -> (zoo_rnngmm::prelude::Config, zoo_rnngmm::TrainingData, zoo_rnngmm::prelude::GeneratorTrainer) {
    use zoo_data::synth::{SynthConfig, generate_clip};
    let cfg = SynthConfig { minutes: 0.2, seed: 3, terrain: false, fps: 30.0, clip_seconds: 6.0 };
    let clips: Vec<Clip> = (0..2).map(|i| generate_clip(&cfg, i).clip).collect();
    let refs: Vec<&Clip> = clips.iter().collect();
    let data = zoo_rnngmm::TrainingData::from_clips(&config, 30.0, &refs[..1], &refs[1..]).unwrap();
    let config = config.with_dim(data.spec.dim());
    let trainer = zoo_rnngmm::prelude::GeneratorTrainer::new(
        &config,
        data.spec.clone(),
        data.norm.clone(),
        &candle_core::Device::Cpu,
    )
    .unwrap();
    (config, data, trainer)
}

/// A tiny ARNN (`zoo_arnn::ArnnConfig::tiny`, the lamp's 6 values per pose) with seeded weights
/// ([`zoo_nn::SeededVarMap`], seed 7) and fixed statistics, exported as `zoo export --onnx`
/// would: the keyframes task's test model.
pub fn tiny_arnn_onnx() -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    let config = zoo_arnn::ArnnConfig::tiny();
    let varmap = candle_nn::VarMap::new();
    zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))
        .expect("tiny ARNN");
    let norm = zoo_arnn::Normalization {
        mean: vec![0.5, 0.1, 0.0, 0.5, -1.1, -1.2],
        std: vec![0.4, 0.06, 0.3, 0.2, 0.5, 0.3],
    };
    zoo_arnn::export::export_arnn(&config, &norm, &varmap).expect("the tiny ARNN exports")
}

/// The skeleton of the in-betweening tests: hips, spine and hand in a chain, Euler channels
/// ZXY (bandai2's), 30 fps.
pub fn inbetween_skeleton() -> zoo_arnn::HumanoidSkeleton {
    zoo_arnn::HumanoidSkeleton {
        names: ["Hips", "Spine", "Hand"].iter().map(|s| s.to_string()).collect(),
        parents: vec![-1, 0, 1],
        offsets: vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 10.0, 0.0]],
        fps: 30.0,
    }
}

/// A tiny in-betweening network (`zoo_arnn::inbetween::InbetweenConfig::tiny` on
/// [`inbetween_skeleton`]) with seeded weights ([`zoo_nn::SeededVarMap`], seed 7) and fixed
/// statistics (cm and quaternion components), exported as `zoo export --onnx` would: the
/// keyframes task's in-betweening test model.
pub fn tiny_inbetween_onnx() -> zoo_export::OnnxModel {
    tiny_inbetween_onnx_with(None)
}

/// [`tiny_inbetween_onnx`] with a fallback towards the curves in its file.
pub fn tiny_inbetween_onnx_with(fallback: Option<zoo_protocol::inbetween::Fallback>) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_arnn::inbetween::{Inbetween, InbetweenConfig};
    let config = InbetweenConfig { fallback, ..InbetweenConfig::tiny(inbetween_skeleton(), vec![[2, 0, 1]; 3]) };
    let varmap = candle_nn::VarMap::new();
    Inbetween::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))
        .expect("tiny in-betweening network");
    let mut mean = vec![0.0, 90.0, 0.0];
    mean.extend([0.9, 0.1, 0.0, 0.0].repeat(3));
    let mut std = vec![40.0, 5.0, 40.0];
    std.extend([0.1, 0.2, 0.3, 0.2].repeat(3));
    let norm = zoo_arnn::Normalization { mean, std };
    zoo_arnn::inbetween_export::export_inbetween(&config, &norm, &varmap)
        .expect("the tiny in-betweening network exports")
}

/// Humanoid key poses on [`inbetween_skeleton`] at `frames` (f32, key-major, `3 + 4 * 3`
/// values each): the root walking forward at 1 cm a frame with a bounce, the joints swinging
/// (`phase` shifts the swing).
pub fn humanoid_keys(frames: &[usize], phase: f64) -> Vec<f32> {
    frames
        .iter()
        .flat_map(|&f| {
            let a = 0.08 * f as f64 + phase;
            let rot = [
                DQuat::from_rotation_y(0.6 * a.sin()),
                DQuat::from_rotation_x(0.5 * (1.3 * a).cos()) * DQuat::from_rotation_z(0.2 * a.sin()),
                DQuat::from_rotation_z(0.8 * (0.7 * a).sin()),
            ];
            let root = DVec3::new(f as f64, 90.0 + 3.0 * (2.0 * a).sin(), 0.3 * f as f64);
            let pose = zoo_protocol::inbetween::pose_values(root, &rot);
            pose.into_iter().map(|v| v as f32).collect::<Vec<f32>>()
        })
        .collect()
}

/// A tiny RMR (`zoo_rmr::Config::tiny`, the synthetic data's 21-joint skeleton, a window of
/// 30 frames every 15) with seeded weights (seed 7) and the statistics of a synthetic clip's
/// pose vectors, exported as `zoo export --onnx` would: the stitching task's test model.
pub fn tiny_rmr_onnx() -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_rmr::features::{FeatureLayout, FeatureStats, encode_clip};
    let config = zoo_rmr::Config::tiny();
    let varmap = candle_nn::VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).expect("tiny RMR");
    let synth = zoo_data::synth::SynthConfig { minutes: 0.2, seed: 5, clip_seconds: 4.0, ..Default::default() };
    let clip = zoo_data::synth::generate_clip(&synth, 0).clip;
    let x = encode_clip(&clip, &config.layout).expect("the synthetic clip encodes");
    let stats = FeatureStats::fit([x.as_slice()], FeatureLayout::new(config.joints, config.layout.lower_body.len()));
    zoo_rmr::export::export_rmr(&config, &stats, &varmap).expect("the tiny RMR exports")
}

/// An untrained RNN-GMM generator (`zoo_rnngmm::prelude::Config::tiny`, [`rnngmm_fixture`])
/// exported as `zoo export --onnx` would: the synthesis task's test model.
pub fn tiny_rnngmm_onnx() -> zoo_export::OnnxModel {
    let (config, _, trainer) = rnngmm_fixture(zoo_rnngmm::prelude::Config::tiny());
    zoo_rnngmm::export::export_generator(&config, None, trainer.spec(), trainer.norm(), trainer.varmap())
        .expect("the tiny RNN-GMM exports")
}

/// Helpers of the C ABI tests (`tests/capi.rs`, `tests/capi_tasks.rs`): the calling thread's
/// last error, status assertions, C paths, and C examples compiled against the static library.
// Calling the C ABI needs raw pointers, as a C caller has.
#[allow(unsafe_code)]
pub mod capi {
    use std::ffi::{CString, c_char};
    use std::path::{Path, PathBuf};
    use std::process::Command;
    use zoo_capi::{ZooStatus, zoo_last_error};

    /// The C ABI crate's folder.
    pub fn capi_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime/capi")
    }

    /// The calling thread's last error message.
    pub fn last_error() -> String {
        let len = unsafe { zoo_last_error(std::ptr::null_mut(), 0) };
        let mut buf = vec![0u8; len + 1];
        unsafe { zoo_last_error(buf.as_mut_ptr().cast::<c_char>(), buf.len()) };
        String::from_utf8_lossy(&buf[..len]).into_owned()
    }

    /// Asserts `status` and that the thread's last error mentions `needle`.
    #[track_caller]
    pub fn assert_error(status: ZooStatus, expected: ZooStatus, needle: &str) {
        assert_eq!(status, expected, "status (message: {})", last_error());
        let message = last_error();
        assert!(message.contains(needle), "message `{message}` should mention `{needle}`");
    }

    /// Asserts `ZOO_STATUS_OK`, showing the last error otherwise.
    #[track_caller]
    pub fn assert_ok(status: ZooStatus) {
        assert_eq!(status, ZooStatus::Ok, "{}", last_error());
    }

    /// The values of an engine pose in the C examples' order: root position, root rotation, root
    /// delta, delta yaw, hips position, local rotations.
    pub fn pose_values(p: &zoo_runtime::EnginePose) -> Vec<f32> {
        let mut v = Vec::new();
        v.extend(p.root_position.to_array());
        v.extend(p.root_rotation.to_array());
        v.extend(p.root_delta_position.to_array());
        v.push(p.root_delta_yaw);
        v.extend(p.hips_position.to_array());
        v.extend(p.local_rotations.iter().flat_map(|q| q.to_array()));
        v
    }

    /// `path` as a C string.
    pub fn c_path(path: &Path) -> CString {
        CString::new(path.to_str().expect("a UTF-8 path")).expect("no NUL in the path")
    }

    /// The static library cargo built for these tests.
    pub fn static_lib() -> PathBuf {
        let exe = std::env::current_exe().unwrap();
        let deps = exe.parent().unwrap();
        let mut candidates: Vec<PathBuf> = std::fs::read_dir(deps)
            .unwrap()
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let name = p.file_name().unwrap().to_string_lossy();
                name.starts_with("libzoo_capi") && name.ends_with(".a")
            })
            .collect();
        candidates.push(deps.parent().unwrap().join("libzoo_capi.a"));
        candidates
            .into_iter()
            .filter(|p| p.exists())
            .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
            .expect("libzoo_capi.a: build the workspace first (`cargo build --workspace`)")
    }

    /// Compiles `examples/NAME.c` with the system C compiler (`CC`, else `cc`; C99, every
    /// warning an error) against the static library into `dir/NAME`.
    pub fn compile_example(name: &str, dir: &Path) -> PathBuf {
        compile_c(&capi_dir().join(format!("examples/{name}.c")), dir)
    }

    /// Compiles the C99 program `source` (every warning an error) against the static library
    /// into `dir`, named after the source.
    pub fn compile_c(source: &Path, dir: &Path) -> PathBuf {
        let name = source.file_stem().unwrap().to_string_lossy().into_owned();
        let exe = dir.join(&name);
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let capi = capi_dir();
        let out = Command::new(&cc)
            .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-I"])
            .arg(capi.join("include"))
            .arg(source)
            .arg(static_lib())
            .args(["-lm", "-lpthread", "-ldl", "-lrt", "-lgcc_s", "-lc", "-o"])
            .arg(&exe)
            .output()
            .unwrap_or_else(|e| panic!("cannot run the C compiler `{cc}` ({e}); install gcc or set CC"));
        assert!(
            out.status.success(),
            "the C example {name}.c does not compile:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        exe
    }
}

/// The toy clip under a bandai2-style dummy root `joint_Root` (zero offset, six channels),
/// whose channels are zero, or carry a translation and a yaw when `moving`.
pub fn under_dummy_root(clip: &Clip, moving: bool) -> String {
    let text = zoo_data::bvh::to_string(clip);
    let (head, motion) = text.split_once("MOTION\n").unwrap();
    let body = head.strip_prefix("HIERARCHY\nROOT ").unwrap();
    let mut out = String::from(
        "HIERARCHY\nROOT joint_Root\n{\n\tOFFSET 0 0 0\n\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\tJOINT ",
    );
    out.push_str(body);
    out.push_str("}\nMOTION\n");
    for (i, line) in motion.lines().enumerate() {
        if i < 2 {
            out.push_str(line);
        } else if moving {
            out.push_str(&format!("{} 0 -7 0 0 {} {line}", 3.0 + i as f64, 20.0 + i as f64));
        } else {
            out.push_str(&format!("0 0 0 0 0 0 {line}"));
        }
        out.push('\n');
    }
    out
}
