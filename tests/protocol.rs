//! docs/runtime-protocol.md (and its task pages) is enough to run every exported task with another
//! inference engine: `scripts/runtime_protocol.py`, written from those pages alone (numpy and the
//! onnxruntime Python wheel, which `bash scripts/onnxruntime.sh` installs into
//! `.onnxruntime/venv`), reproduces the reference vectors of tiny models of each kind
//! (`zoo_runtime::reference`, what `zoo export --reference` writes) within the documented bound
//! (`1e-3 + 2e-5 S` model units per field, `S` its largest value) at every step: RTN (the paper's, an interpolation-residual one with a calibrated
//! fallback, a terrain-aware one), keyframes (the lamp ARNN, humanoid ARNNs with partial keys,
//! one with legs whose feet are locked between the keys, and the in-betweening design with its
//! Bezier curves, features and foot lock), RMR (the file's settings, and a pre-blend model with
//! a seam and a fallback), RNN-GMM with its refiner. The expected numbers come from the Rust
//! runtime (tract); the Python side recomputes them from each case's inputs with onnxruntime. A
//! missing venv fails the tests with the command that provisions it.
//!
//! The CLI tests at the end need the `zoo` binary (`cargo build --bin zoo`, which
//! `scripts/test.sh` runs first).

use std::path::{Path, PathBuf};
use std::process::Command;
use zoo_runtime::LoadedModel;
use zoo_runtime::reference::{REFERENCE_SEED, ReferenceVectors, reference_vectors};

/// Model units (cm for the RTN files here): how close the raw and blended positions of `zoo
/// transition` are to the runtime's, and what the trained tiny RTN's reference meets. The
/// protocol's bound, which the script checks, is `1e-3 + 2e-5 S` per field (`S` the field's
/// largest value; docs/runtime-protocol.md, section 10).
const TOLERANCE: f64 = 1e-3;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn python() -> PathBuf {
    let python = workspace().join(".onnxruntime/venv/bin/python");
    assert!(
        python.is_file(),
        "{} is missing: run `bash scripts/onnxruntime.sh` in the zoo workspace (it installs the onnxruntime \
         Python wheel and numpy into .onnxruntime/venv for this test)",
        python.display()
    );
    python
}

/// What `runtime_protocol.py --report` says about one reference file.
struct Report {
    /// The whole report (per case and field: the largest difference).
    json: serde_json::Value,
    /// Largest difference over every compared value (model units).
    worst: f64,
    /// Output of the script (its table), for messages.
    stdout: String,
}

impl Report {
    /// The largest difference of `field` in each case that compared it.
    fn fields(&self, field: &str) -> Vec<f64> {
        self.json["cases"].as_array().unwrap().iter().filter_map(|c| c["fields"][field]["max_diff"].as_f64()).collect()
    }

    /// Asserts that every case compared each of `fields`, with at least one value each.
    fn assert_compared(&self, fields: &[&str]) {
        for case in self.json["cases"].as_array().unwrap() {
            for f in fields {
                let n = case["fields"][f]["values"].as_u64().unwrap_or(0);
                assert!(n > 0, "case `{}` did not compare `{f}`:\n{}", case["name"], self.stdout);
            }
        }
    }
}

/// Runs the Python implementation on `model` and `reference`; `Err(stderr)` when it fails.
fn run_python(model: &Path, reference: &Path) -> Result<Report, String> {
    let report = reference.with_extension("report.json");
    let out = Command::new(python())
        .arg(workspace().join("scripts/runtime_protocol.py"))
        .args([model, reference])
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    if !out.status.success() {
        return Err(format!("{stdout}\n{}", String::from_utf8_lossy(&out.stderr)));
    }
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let worst = json["max_diff"].as_f64().unwrap();
    assert_eq!(json["failed"].as_bool(), Some(false), "the script passed but its report says it failed:\n{stdout}");
    Ok(Report { json, worst, stdout })
}

/// A folder kept after the test (`target/tmp/protocol/NAME`), to look at the files of a failure.
fn kept_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("protocol").join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `model` and its reference vectors into `dir`, runs the Python implementation on them
/// and asserts the documented bound (the script fails a field beyond it); returns the vectors
/// and the report.
fn check(dir: &Path, name: &str, model: &zoo_export::OnnxModel) -> (ReferenceVectors, Report) {
    let path = dir.join(format!("{name}.onnx"));
    model.write(&path).unwrap();
    let loaded = LoadedModel::load(&path).unwrap();
    let vectors = reference_vectors(&loaded, REFERENCE_SEED).unwrap();
    let reference = dir.join(format!("{name}.reference.json"));
    std::fs::write(&reference, serde_json::to_string(&vectors).unwrap()).unwrap();
    let report = run_python(&path, &reference).unwrap_or_else(|e| panic!("{name}: runtime_protocol.py failed:\n{e}"));
    eprintln!("{name}: python vs reference, largest difference {:.2e} (model units)\n{}", report.worst, report.stdout);
    (vectors, report)
}

/// The tiny RTN of [`zoo_tests::tiny_rtn_onnx_with_std`] (std 1, seed 7) with `change` applied
/// to its configuration, on the toy skeleton with its leg moved off the spine's line (so that
/// positions define every rotation of the posed transition's fit).
fn tiny_rtn(change: impl Fn(&mut zoo_rtn::Config)) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_rtn::features::{FeatureStats, MeanStd};
    let mut skeleton = zoo_tests::toy_skeleton();
    skeleton.offsets[2] = glam::DVec3::new(12.0, -40.0, 3.0);
    let mut config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents);
    change(&mut config);
    let varmap = candle_nn::VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let unit = || MeanStd { mean: vec![0.0; d], std: vec![1.0; d] };
    let stats = FeatureStats { joints: skeleton.len(), x: unit(), velocity: unit(), offset: unit(), terrain: None };
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(skeleton.names.clone()),
        offsets: Some(skeleton.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(zoo_runtime::CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).unwrap()
}

#[test]
fn transitions_reproduce_from_the_page() {
    let dir = kept_dir("transition");
    let (paper, report) = check(&dir, "rtn", &zoo_tests::tiny_rtn_onnx_with_std(1.0));
    report.assert_compared(&["past", "raw", "blended", "miss", "fallback_weight", "frames"]);
    // The toy skeleton's spine and leg leave the hips on one line: no posed frames.
    assert!(paper.transition.iter().all(|c| c.posed.is_empty()));
    // The network moved: its raw first frame is not the target, nor the last context frame.
    let case = &paper.transition[0];
    let gap = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(gap(&case.raw[0], &case.target) > 1.0 && gap(&case.raw[0], case.past.last().unwrap()) > 1e-2);
    // Raw and blended frames differ in the blend window only, and the blend lands on the target.
    let n = case.length;
    assert!(gap(&case.blended[n], &case.target) < 1e-4, "the blend lands on the target");
    assert!(gap(&case.raw[n], &case.target) > 1e-2, "the raw target frame is the network's own");
    // The second case's fallback thresholds straddle its miss: weight 1/3, frames moved.
    let second = &paper.transition[1];
    assert!((second.fallback_weight - 1.0 / 3.0).abs() < 1e-4, "weight {}", second.fallback_weight);
    assert!(second.frames[0].iter().zip(&second.blended[0]).any(|(a, b)| (a - b).abs() > 1e-3));

    // An interpolation-residual RTN (the `base` input) with a fallback in its file.
    let fallback = zoo_rtn::fallback::Fallback { start: 0.5, full: 1.0 };
    let (residual, report) = check(
        &dir,
        "rtn_residual",
        &tiny_rtn(|c| {
            c.interp_residual = true;
            c.fallback = Some(fallback);
        }),
    );
    assert_eq!(residual.transition[0].fallback.map(|f| (f.start, f.full)), Some((0.5, 1.0)));
    report.assert_compared(&["past", "raw", "blended", "miss", "fallback_weight", "frames", "posed"]);
    assert!(residual.transition.iter().all(|c| c.posed.len() == c.length + 1));
    // An RTN trained over several lengths (the `tta` input, section 5e), clamped before the end.
    let (_, report) = check(
        &dir,
        "rtn_tta",
        &tiny_rtn(|c| {
            c.interp_residual = true;
            c.time_to_arrival = Some(zoo_runtime::TimeToArrival { dims: 6, max: 4 });
        }),
    );
    report.assert_compared(&["past", "raw", "blended", "miss", "fallback_weight", "frames"]);
    // A terrain-aware RTN: its heightmap travels in the reference.
    let (terrain, report) = check(&dir, "rtn_terrain", &zoo_tests::tiny_terrain_rtn_onnx());
    assert!(terrain.transition.iter().all(|c| c.heightmap.is_some()));
    report.assert_compared(&["raw", "frames"]);
}

/// A tiny humanoid ARNN with key groups (partial keys) on a 3-joint chain, seeded weights.
fn tiny_humanoid_arnn() -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_arnn::ArnnConfig;
    let names: Vec<String> = ["Hips", "Spine", "Head"].iter().map(|s| s.to_string()).collect();
    let skeleton = zoo_arnn::HumanoidSkeleton {
        names: names.clone(),
        parents: vec![-1, 0, 1],
        offsets: vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 20.0, 0.0]],
        fps: 30.0,
    };
    let (dof_names, groups) = zoo_arnn::humanoid::pose_layout(&names);
    let config = ArnnConfig::humanoid(skeleton, dof_names, groups).sized_like(&ArnnConfig::tiny());
    let varmap = candle_nn::VarMap::new();
    zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 11, DType::F32, &Device::Cpu)).unwrap();
    let mut mean = vec![0.0, 90.0, 0.0];
    mean.extend([0.9, 0.1, 0.0, 0.0].repeat(3));
    let mut std = vec![40.0, 5.0, 40.0];
    std.extend([0.1, 0.2, 0.3, 0.2].repeat(3));
    zoo_arnn::export::export_arnn(&config, &zoo_arnn::Normalization { mean, std }, &varmap).unwrap()
}

/// A humanoid skeleton with two legs (hips, spine, and per side upper leg, lower leg, foot and
/// toes; joint names with `Foot` are the ankles the foot lock finds), 30 fps.
fn legged_skeleton() -> zoo_arnn::HumanoidSkeleton {
    let legs = ["UpperLeg", "LowerLeg", "Foot", "Toes"];
    let side = |s: &'static str| legs.iter().map(move |j| format!("{j}_{s}"));
    let names: Vec<String> =
        ["Hips".to_string(), "Spine".to_string()].into_iter().chain(side("L")).chain(side("R")).collect();
    zoo_arnn::HumanoidSkeleton {
        names,
        parents: vec![-1, 0, 0, 2, 3, 4, 0, 6, 7, 8],
        offsets: vec![
            [0.0; 3],
            [0.0, 10.0, 0.0],
            [10.0, -5.0, 0.0],
            [0.0, -40.0, 0.0],
            [0.0, -37.0, 0.0],
            [0.0, -5.0, 12.0],
            [-10.0, -5.0, 0.0],
            [0.0, -40.0, 0.0],
            [0.0, -37.0, 0.0],
            [0.0, -5.0, 12.0],
        ],
        fps: 30.0,
    }
}

/// Pose statistics of a humanoid of `joints` joints: the hips 87 cm up, every joint's mean
/// rotation a small bend about X.
fn humanoid_normalization(joints: usize) -> zoo_arnn::Normalization {
    let mut mean = vec![0.0, 87.0, 0.0];
    mean.extend([0.9, 0.1, 0.0, 0.0].repeat(joints));
    let mut std = vec![40.0, 5.0, 40.0];
    std.extend([0.1, 0.2, 0.3, 0.2].repeat(joints));
    zoo_arnn::Normalization { mean, std }
}

/// A tiny humanoid ARNN with key groups (partial keys) on `skeleton`, seeded weights.
fn tiny_humanoid_arnn_on(skeleton: zoo_arnn::HumanoidSkeleton) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_arnn::ArnnConfig;
    let names = skeleton.names.clone();
    let (dof_names, groups) = zoo_arnn::humanoid::pose_layout(&names);
    let config = ArnnConfig::humanoid(skeleton, dof_names, groups).sized_like(&ArnnConfig::tiny());
    let varmap = candle_nn::VarMap::new();
    zoo_arnn::Arnn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 11, DType::F32, &Device::Cpu)).unwrap();
    zoo_arnn::export::export_arnn(&config, &humanoid_normalization(names.len()), &varmap).unwrap()
}

/// A tiny in-betweening network (`zoo train arnn --design inbetween`) on `skeleton`, Euler
/// channels ZXY, seeded weights.
fn tiny_inbetween_on(skeleton: zoo_arnn::HumanoidSkeleton) -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_arnn::inbetween::{Inbetween, InbetweenConfig};
    let joints = skeleton.names.len();
    let config = InbetweenConfig::tiny(skeleton, vec![[2, 0, 1]; joints]);
    let varmap = candle_nn::VarMap::new();
    Inbetween::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 13, DType::F32, &Device::Cpu)).unwrap();
    zoo_arnn::inbetween_export::export_inbetween(&config, &humanoid_normalization(joints), &varmap).unwrap()
}

/// The largest difference between two lists of frames.
fn frames_gap(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
    a.iter().flatten().zip(b.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn keyframes_reproduce_from_the_page() {
    let dir = kept_dir("keyframes");
    let (lamp, report) = check(&dir, "arnn", &zoo_tests::tiny_arnn_onnx());
    report.assert_compared(&["intervals", "t_rel", "network", "hit", "poses"]);
    assert!(lamp.keyframes.iter().all(|c| c.fixed.is_empty() && !c.foot_lock));
    // The hit moved the network's own frames.
    assert!(lamp.keyframes.iter().any(|c| frames_gap(&c.network, &c.hit) > 1e-3));
    let (humanoid, report) = check(&dir, "arnn_humanoid", &tiny_humanoid_arnn());
    report.assert_compared(&["intervals", "network", "hit", "poses"]);
    let partial = humanoid.keyframes.iter().find(|c| !c.fixed.is_empty()).expect("a case of partial keys");
    assert!(partial.fixed[1..].iter().flatten().any(|f| *f == 0.0), "a key leaves a group free");
    assert!(humanoid.keyframes.iter().all(|c| !c.foot_lock), "a skeleton without legs has nothing to lock");
}

/// The foot lock between the keys of a humanoid completion: the step graph's and the
/// in-betweening design's, each on a skeleton with legs.
#[test]
fn humanoid_foot_locks_reproduce_from_the_page() {
    let dir = kept_dir("keyframes_legs");
    for (name, model) in [
        ("arnn_legs", tiny_humanoid_arnn_on(legged_skeleton())),
        ("inbetween_legs", tiny_inbetween_on(legged_skeleton())),
    ] {
        let (vectors, report) = check(&dir, name, &model);
        report.assert_compared(&["network", "hit", "foot_lock", "poses"]);
        assert!(vectors.keyframes.iter().all(|c| c.foot_lock), "{name}: the legs are locked");
        // The lock moved the legs between the keys and left every key frame as it was.
        let moved = vectors.keyframes.iter().map(|c| frames_gap(&c.hit, &c.poses)).fold(0.0, f32::max);
        assert!(moved > 1e-3, "{name}: the foot lock changed nothing ({moved})");
        for c in &vectors.keyframes {
            for &k in &c.key_frames {
                assert_eq!(c.hit[k], c.poses[k], "{name} `{}`: key frame {k} unchanged", c.name);
            }
        }
    }
}

/// The in-betweening design: its features, the keys' Bezier curves (Blender's default F-curves),
/// the graph's correction composed on them, the hit and the foot lock.
#[test]
fn inbetweening_reproduces_from_the_page() {
    let dir = kept_dir("inbetween");
    let (vectors, report) = check(&dir, "inbetween", &zoo_tests::tiny_inbetween_onnx());
    report.assert_compared(&["features", "bezier", "network", "hit", "poses"]);
    assert!(vectors.keyframes.iter().all(|c| c.intervals.is_empty() && !c.features.is_empty()));
    let partial = vectors.keyframes.iter().find(|c| !c.fixed.is_empty()).expect("a case of partial keys");
    assert!(partial.fixed[1..].iter().flatten().any(|f| *f == 0.0), "a key leaves a group free");
    for c in &vectors.keyframes {
        // The correction moved the curves between the keys, and the keys are met by construction.
        let bezier: Vec<Vec<f32>> = c.bezier.iter().map(|r| r.iter().map(|v| *v as f32).collect()).collect();
        assert!(frames_gap(&bezier, &c.network) > 1e-2, "`{}`: the graph's correction is zero", c.name);
        assert!(frames_gap(&c.network, &c.hit) < 1e-4, "`{}`: the design meets its keys", c.name);
    }
}

/// The in-betweening design's fallback towards the curves, from the page: keys up to 10 frames
/// apart fall back fully, further ones keep the network's correction, with the ramps between.
#[test]
fn the_inbetweening_fallback_reproduces_from_the_page() {
    use zoo_protocol::inbetween::{Fallback, GapFallback};
    let dir = kept_dir("inbetween_fallback");
    let fallback = Fallback {
        gaps: vec![GapFallback { up_to: 10, start: 0.0, full: 1e-6 }, GapFallback { up_to: 60, start: 1e5, full: 2e5 }],
    };
    let (vectors, report) = check(&dir, "inbetween_fallback", &zoo_tests::tiny_inbetween_onnx_with(Some(fallback)));
    report.assert_compared(&["features", "bezier", "network", "hit", "poses"]);
    let case = vectors.keyframes.iter().find(|c| c.key_frames == [0, 8, 20, 33]).expect("the four whole keys");
    let gap =
        |t: usize| case.bezier[t].iter().zip(&case.network[t]).map(|(b, n)| (*b as f32 - n).abs()).fold(0.0, f32::max);
    // Keys 0 and 8 are the curves between them; keys 20 and 33 keep the correction in the middle.
    assert!((1..8).all(|t| gap(t) < 1e-4), "{:?}", (1..8).map(gap).collect::<Vec<_>>());
    assert!(gap(26) > 1e-2, "{}", gap(26));
}

/// [`zoo_tests::tiny_rmr_onnx`]'s model trained on sequences inertialized at their seams
/// (`zoo train rmr --pre-blend`), with a fallback in its file.
fn tiny_pre_blend_rmr() -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_rmr::features::{FeatureLayout, FeatureStats, encode_clip};
    let mut config = zoo_rmr::Config::tiny();
    config.pre_blend = true;
    config.fallback = Some(zoo_rmr::fallback::Fallback { start: 0.05, full: 0.2 });
    let varmap = candle_nn::VarMap::new();
    zoo_rmr::Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let synth = zoo_data::synth::SynthConfig { minutes: 0.2, seed: 5, clip_seconds: 4.0, ..Default::default() };
    let clip = zoo_data::synth::generate_clip(&synth, 0).clip;
    let x = encode_clip(&clip, &config.layout).unwrap();
    let stats = FeatureStats::fit([x.as_slice()], FeatureLayout::new(config.joints, config.layout.lower_body.len()));
    zoo_rmr::export::export_rmr(&config, &stats, &varmap).unwrap()
}

#[test]
fn stitching_reproduces_from_the_page() {
    let dir = kept_dir("stitch");
    let fields = ["pre_blend", "sequence", "window_starts", "windows", "first_window", "refined", "poses", "contacts"];
    let (rmr, report) = check(&dir, "rmr", &zoo_tests::tiny_rmr_onnx());
    report.assert_compared(&fields);
    let case = &rmr.stitch[0];
    // Two regular windows and the one ending on the last frame, whose first frames were refined.
    assert_eq!(case.window_starts.len(), 3, "{:?}", case.window_starts);
    assert_eq!(*case.window_starts.last().unwrap(), case.sequence.len() - case.window);
    // Refining changed the sequence.
    let moved = case.sequence.iter().flatten().zip(case.refined.iter().flatten()).any(|(a, b)| (a - b).abs() > 1e-2);
    assert!(moved, "the refiner left the sequence as it was");
    // The seam case: the seam given is inertialized (whatever the file's `pre_blend`), a
    // fallback whose weights lie between 0 and 1.
    let seam = &rmr.stitch[1];
    assert!(!seam.seams.is_empty() && seam.pre_blend && seam.fallback.is_some());
    assert!(seam.windows.iter().any(|w| w.weight > 0.0 && w.weight < 1.0), "{:?}", seam.windows);

    // A model trained on inertialized seams: likewise, the seam case's input inertialized there.
    let (blended, report) = check(&dir, "rmr_pre_blend", &tiny_pre_blend_rmr());
    report.assert_compared(&fields);
    let (plain, seam) = (&blended.stitch[0], &blended.stitch[1]);
    assert!(!plain.pre_blend && seam.pre_blend);
    let at = seam.seams[0];
    assert!(frames_gap(&plain.sequence[at..at + 1], &seam.sequence[at..at + 1]) > 1e-2, "the seam was inertialized");
    assert_eq!(plain.sequence[..at - 1], seam.sequence[..at - 1], "frames before the seam are as they were");
    assert!(plain.fallback.is_some() && seam.windows.iter().any(|w| w.weight > 0.0));
}

/// A tiny RNN-GMM generator ([`zoo_tests::rnngmm_fixture`]) with its adversarial refiner
/// trained for 3 updates, exported from the refiner-stage run folder as `zoo export --onnx`
/// does: the file embeds the refiner's step graph.
fn tiny_rnngmm_refined_onnx(dir: &Path) -> zoo_export::OnnxModel {
    use zoo_rnngmm::prelude::*;
    let (config, data, trainer) = zoo_tests::rnngmm_fixture(Config::tiny());
    let gen_dir = dir.join("generator");
    trainer.save(&gen_dir).unwrap();
    let device = candle_core::Device::Cpu;
    let mut adv = AdversarialTrainer::new(&gen_dir, &config.refiner, &data.train, &data.valid, &device).unwrap();
    for _ in 0..3 {
        adv.refiner_update().unwrap();
    }
    let run = dir.join("refined");
    adv.save(&run).unwrap();
    zoo_rnngmm::export::export_run(&run, &Default::default()).unwrap()
}

#[test]
fn synthesis_with_its_refiner_reproduces_from_the_page() {
    let dir = kept_dir("synthesis");
    let model = tiny_rnngmm_refined_onnx(&dir);
    let (rnngmm, report) = check(&dir, "rnngmm", &model);
    report.assert_compared(&["weights", "means", "stds", "sampled", "rng_state", "poses", "contacts"]);
    let refined: Vec<_> = rnngmm.synthesis.iter().filter(|c| c.refined).collect();
    assert_eq!(refined.len(), 1, "one case through the refiner, one without");
    assert!(refined[0].steps.iter().all(|s| s.refined.is_some()));
    assert!(!report.fields("refined").is_empty(), "the refined frames were compared");
    // The refiner moved the frames it refined.
    let s = &refined[0].steps[3];
    let r = s.refined.as_ref().unwrap();
    assert!(s.sampled.iter().zip(r).any(|(a, b)| (a - b).abs() > 1e-4));
}

/// The check can fail: a reference off by 0.01 in one value of one frame is refused, naming
/// the field.
#[test]
fn a_reference_off_by_a_hundredth_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    zoo_tests::tiny_rtn_onnx_with_std(1.0).write(&path).unwrap();
    let mut vectors = reference_vectors(&LoadedModel::load(&path).unwrap(), REFERENCE_SEED).unwrap();
    vectors.transition[0].raw[2][4] += 0.01;
    let reference = dir.path().join("bad.reference.json");
    std::fs::write(&reference, serde_json::to_string(&vectors).unwrap()).unwrap();
    let err = run_python(&path, &reference).err().expect("a wrong reference must fail the check");
    assert!(err.contains("raw") && err.contains("FAIL"), "{err}");
}

/// The generator is deterministic, its seed matters, and the JSON reads back the same.
#[test]
fn reference_vectors_are_deterministic_and_round_trip() {
    let model = LoadedModel::from_bytes(&zoo_tests::tiny_arnn_onnx().to_bytes()).unwrap();
    let a = reference_vectors(&model, 5).unwrap();
    assert_eq!(a, reference_vectors(&model, 5).unwrap());
    assert_ne!(a.keyframes[0].key_poses, reference_vectors(&model, 6).unwrap().keyframes[0].key_poses);
    let back: ReferenceVectors = serde_json::from_str(&serde_json::to_string(&a).unwrap()).unwrap();
    assert_eq!(a, back);
    assert_eq!((a.format.as_str(), a.version), ("zoo-reference-vectors", 2));
}

fn zoo(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_tests::zoo_bin()).args(args).env("RAYON_NUM_THREADS", "1").output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// `zoo data synth` clips of the synthetic skeleton, sorted.
fn synth_clips(dir: &Path, seed: &str) -> Vec<PathBuf> {
    let (ok, _, stderr) = zoo(&["data", "synth", "--out", s(dir), "--minutes", "0.5", "--seed", seed]);
    assert!(ok, "{stderr}");
    let mut clips: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    clips.sort();
    clips
}

/// `frames` of a `--positions` file against the forward kinematics of the BVH written beside it.
fn assert_positions_match_clip(positions: &serde_json::Value, clip: &Path) {
    let clip = zoo_data::clip_io::read_model_clip(clip).unwrap();
    let (_, global) = clip.global();
    let frames = positions["frames"].as_array().unwrap();
    assert_eq!(frames.len(), clip.frames());
    assert_eq!(positions["joints"].as_array().unwrap().len(), clip.joints());
    let mut worst = 0f64;
    for (f, frame) in frames.iter().enumerate() {
        for (j, p) in frame.as_array().unwrap().iter().enumerate() {
            let g = global[f * clip.joints() + j];
            for (a, v) in p.as_array().unwrap().iter().enumerate() {
                worst = worst.max((v.as_f64().unwrap() - g[a]).abs());
            }
        }
    }
    // BVH text keeps 6 decimals of the rotations: a few thousandths of a unit at the feet.
    assert!(worst < 1e-2, "positions and the written clip differ by {worst}");
}

/// `zoo export --reference` on a trained tiny RTN run, checked by the Python implementation;
/// `zoo transition --positions` writes the inputs and the network's raw and blended frames,
/// which the runtime reproduces from the exported file (candle and tract agree within 1e-3 cm).
#[test]
fn export_writes_reference_vectors_and_transition_writes_raw_positions() {
    use zoo_runtime::TransitionModel;
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (ok, stdout, stderr) = zoo(&[
        "train",
        "rtn",
        "--preset",
        "tiny",
        "--synth-minutes",
        "1",
        "--seed",
        "5",
        "--epochs",
        "1",
        "--out",
        s(&run),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let (onnx, reference) = (dir.path().join("rtn.onnx"), dir.path().join("rtn.reference.json"));
    let (ok, stdout, stderr) = zoo(&["export", "--onnx", s(&run), "--out", s(&onnx), "--reference", s(&reference)]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("reference vectors") && stdout.contains("runtime_protocol.py"), "{stdout}");
    let report = run_python(&onnx, &reference).unwrap();
    assert!(report.worst <= TOLERANCE, "{}", report.stdout);
    eprintln!("zoo export --reference (trained tiny RTN): largest difference {:.2e}", report.worst);
    // A reference of a folder that cannot be written is refused before the export.
    let (ok, _, stderr) = zoo(&["export", "--onnx", s(&run), "--out", s(&onnx), "--reference", s(dir.path())]);
    assert!(!ok && stderr.contains("--reference") && stderr.contains("is a folder"), "{stderr}");

    let clip = synth_clips(&dir.path().join("synth"), "3").swap_remove(0);
    let (out, positions) = (dir.path().join("t.bvh"), dir.path().join("t.positions.json"));
    let (from, to) = (format!("{}:20", s(&clip)), format!("{}:60", s(&clip)));
    let args = ["transition", "--model", s(&run), "--from", &from, "--to", &to, "--frames", "12", "--out", s(&out)];
    let (ok, stdout, stderr) = zoo(&[&args[..], &["--positions", s(&positions)]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let v = read_json(&positions);
    assert_eq!((v["format"].as_str(), v["command"].as_str()), (Some("zoo-positions"), Some("transition")));
    let flat = |key: &str| -> Vec<f32> {
        let rows = v[key].as_array().unwrap();
        rows.iter()
            .flat_map(|r| match r {
                serde_json::Value::Array(a) => a.iter().map(|x| x.as_f64().unwrap() as f32).collect::<Vec<_>>(),
                x => vec![x.as_f64().unwrap() as f32],
            })
            .collect()
    };
    let (past, target, next, raw, frames) = (flat("past"), flat("target"), flat("next"), flat("raw"), flat("frames"));
    let model = TransitionModel::load(&onnx).unwrap();
    let d = 3 * model.joints();
    assert_eq!((raw.len(), frames.len(), target.len()), (13 * d, 13 * d, d));
    let mut runner = model.runner().unwrap();
    runner.allow_beyond_trained(true);
    let mut state = model.new_transition();
    runner.start_for(&mut state, &past, &target, &next, 12).unwrap();
    let mut frame = vec![0f32; d];
    let mut worst = 0f32;
    for f in 0..13 {
        runner.step_raw(&mut state, &mut frame).unwrap();
        worst = worst.max(frame.iter().zip(&raw[f * d..]).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max));
    }
    assert!(worst <= 1e-3, "the raw positions of `zoo transition` and the runtime differ by {worst}");
    runner.set_fallback(model.default_fallback());
    let mut out_frames = vec![0f32; 13 * d];
    runner.generate(&mut model.new_transition(), &past, &target, &next, &mut out_frames).unwrap();
    let worst = out_frames.iter().zip(&frames).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst <= 1e-3, "the blended positions of `zoo transition` and the runtime differ by {worst}");
    // The raw frames are the network's own: its target frame misses the target.
    assert!(raw[12 * d..].iter().zip(&target).any(|(a, b)| (a - b).abs() > 1e-3));
}

/// Windows of a 3-joint chain swinging (hips, spine, hand; Euler channels ZXY): the training
/// data of an in-betweening run folder.
fn chain_windows(count: usize, frames: usize) -> zoo_data::dataset::Windows {
    use glam::{DQuat, DVec3};
    use zoo_motion::{EulerOrder, JointChannels, Skeleton};
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
            let a = 0.3 * (f as f64 * 0.4 + w as f64).sin();
            local_rot.extend([DQuat::from_rotation_y(a), DQuat::from_rotation_x(2.0 * a), DQuat::from_rotation_z(a)]);
            local_pos.extend([DVec3::new(f as f64, 90.0 + 5.0 * a, 0.0), skeleton.offsets[1], skeleton.offsets[2]]);
        }
    }
    let source = (0..count).map(|w| (w, 0)).collect();
    zoo_data::dataset::Windows { skeleton, window: frames, count, local_rot, local_pos, source }
}

/// `zoo export --onnx RUN --reference` for the run folders of the other kinds (the RTN's is
/// above): an ARNN trained one epoch, an in-betweening network's folder, an RMR's and an
/// RNN-GMM's; the Python implementation reproduces each reference within the documented bound.
#[test]
fn export_writes_reference_vectors_of_every_kind() {
    let dir = tempfile::tempdir().unwrap();
    let arnn = dir.path().join("arnn");
    let train =
        ["train", "arnn", "--preset", "tiny", "--epochs", "1", "--sequences", "5", "--k-max", "2", "--seed", "3"];
    let (ok, stdout, stderr) = zoo(&[&train[..], &["--out", s(&arnn)]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let inbetween = dir.path().join("inbetween");
    {
        use zoo_arnn::inbetween::{InbetweenConfig, config_for};
        use zoo_arnn::inbetween_train::{InbetweenTrainer, window_normalization};
        let (train, valid) = (chain_windows(8, 66), chain_windows(4, 66));
        let c = config_for(&train.skeleton, 30.0);
        let config = InbetweenConfig { seed: 3, ..InbetweenConfig::tiny(c.skeleton, c.euler_axes) };
        let norm = window_normalization(&train);
        let mut trainer = InbetweenTrainer::new(&config, norm, train, &valid).unwrap();
        trainer.train_on(&[0, 1, 2, 3]).unwrap();
        trainer.save(&inbetween).unwrap();
    }
    let rmr = dir.path().join("rmr");
    {
        use zoo_rmr::{Config, RmrTrainer, features::FeatureStats};
        let config = Config::tiny();
        let d = config.dim();
        let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
        RmrTrainer::new(&config, stats, &candle_core::Device::Cpu).unwrap().save(&rmr).unwrap();
    }
    let rnngmm = dir.path().join("rnngmm");
    let (_, _, trainer) = zoo_tests::rnngmm_fixture(zoo_rnngmm::prelude::Config::tiny());
    trainer.save(&rnngmm).unwrap();
    for (name, run, task) in [
        ("arnn", &arnn, "keyframes"),
        ("inbetween", &inbetween, "keyframes"),
        ("rmr", &rmr, "stitch"),
        ("rnngmm", &rnngmm, "synthesis"),
    ] {
        let (onnx, reference) =
            (dir.path().join(format!("{name}.onnx")), dir.path().join(format!("{name}.reference.json")));
        let (ok, stdout, stderr) = zoo(&["export", "--onnx", s(run), "--out", s(&onnx), "--reference", s(&reference)]);
        assert!(ok, "{name}: {stdout}\n{stderr}");
        let v = read_json(&reference);
        assert_eq!((v["version"].as_u64(), v["task"].as_str()), (Some(2), Some(task)), "{name}");
        assert!(v[task].as_array().is_some_and(|c| !c.is_empty()), "{name}: no case");
        let report =
            run_python(&onnx, &reference).unwrap_or_else(|e| panic!("{name}: runtime_protocol.py failed:\n{e}"));
        eprintln!("zoo export --reference ({name}): largest difference {:.2e}", report.worst);
    }
}

/// `zoo stitch`, `zoo generate` and `zoo complete` write the global positions of what they
/// wrote; `zoo stitch --method rmr` adds its predicted ankles; bad combinations are refused.
#[test]
fn task_commands_write_positions() {
    let dir = tempfile::tempdir().unwrap();
    let clips = synth_clips(&dir.path().join("synth"), "4");
    let (a, b) = (format!("{}:0:40", s(&clips[0])), format!("{}:0:40", s(&clips[1])));

    // Stitching without a model, then with an untrained RMR.
    let (out, positions) = (dir.path().join("concat.bvh"), dir.path().join("concat.positions.json"));
    let (ok, stdout, stderr) =
        zoo(&["stitch", &a, &b, "--method", "concat", "--out", s(&out), "--positions", s(&positions)]);
    assert!(ok, "{stdout}\n{stderr}");
    let v = read_json(&positions);
    assert_eq!(v["command"], "stitch");
    assert!(v["predicted_ankles"].is_null());
    assert_positions_match_clip(&v, &out);
    let rmr = dir.path().join("rmr");
    {
        use zoo_rmr::{Config, RmrTrainer, features::FeatureStats};
        let config = Config::tiny();
        let d = config.dim();
        let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
        RmrTrainer::new(&config, stats, &candle_core::Device::Cpu).unwrap().save(&rmr).unwrap();
    }
    let (out, positions) = (dir.path().join("rmr.bvh"), dir.path().join("rmr.positions.json"));
    let (ok, stdout, stderr) =
        zoo(&["stitch", &a, &b, "--model", s(&rmr), "--out", s(&out), "--positions", s(&positions)]);
    assert!(ok, "{stdout}\n{stderr}");
    let v = read_json(&positions);
    assert_eq!(v["predicted_ankles"].as_array().unwrap().len(), 80);
    assert_positions_match_clip(&v, &out);

    // Generation: an untrained generator's run folder, 40 frames from a synthetic clip.
    let gen_dir = dir.path().join("rnngmm");
    let (_, _, trainer) = zoo_tests::rnngmm_fixture(zoo_rnngmm::prelude::Config::tiny());
    trainer.save(&gen_dir).unwrap();
    let (out, positions) = (dir.path().join("g.bvh"), dir.path().join("g.positions.json"));
    let from = format!("{}:20", s(&clips[0]));
    let gen_args = ["generate", "--model", s(&gen_dir), "--from", &from, "--frames", "40", "--no-refiner"];
    let (ok, stdout, stderr) =
        zoo(&[&gen_args[..], &["--init-steps", "0", "--out", s(&out), "--positions", s(&positions)]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    let v = read_json(&positions);
    assert_eq!((v["command"].as_str(), v["seed"].as_u64()), (Some("generate"), Some(1)));
    assert_positions_match_clip(&v, &out);
    let folder = dir.path().join("many");
    let (ok, _, stderr) =
        zoo(&[&gen_args[..], &["--count", "2", "--out", s(&folder), "--positions", s(&positions)]].concat());
    assert!(!ok && stderr.contains("--positions") && stderr.contains("--count 2"), "{stderr}");

    // Completion: a tiny lamp ARNN trained for one epoch, three keys.
    let arnn = dir.path().join("arnn");
    let (ok, stdout, stderr) = zoo(&[
        "train",
        "arnn",
        "--preset",
        "tiny",
        "--epochs",
        "1",
        "--sequences",
        "5",
        "--k-max",
        "2",
        "--seed",
        "3",
        "--out",
        s(&arnn),
    ]);
    assert!(ok, "{stdout}\n{stderr}");
    let keys = dir.path().join("keys.json");
    std::fs::write(
        &keys,
        r#"{"format": "zoo-arnn-keys", "version": 1, "keys": [
            {"frame": 4, "pose": [0, 0.02, 0, 0.5, -1.1, -1.2]}, {"frame": 16, "pose": [0.25, 0.25, 0, 0.7, -1.5, -1.3]},
            {"frame": 28, "pose": [0.5, 0.02, 0, 0.5, -1.1, -1.2]}]}"#,
    )
    .unwrap();
    let (out, positions) = (dir.path().join("c.bvh"), dir.path().join("c.positions.json"));
    let (ok, stdout, stderr) =
        zoo(&["complete", "--model", s(&arnn), "--keys", s(&keys), "--out", s(&out), "--positions", s(&positions)]);
    assert!(ok, "{stdout}\n{stderr}");
    let v = read_json(&positions);
    assert_eq!((v["command"].as_str(), v["first_frame"].as_u64()), (Some("complete"), Some(4)));
    assert_positions_match_clip(&v, &out);
}
