//! The Unity package (`runtime/unity`, issue 43) without Unity: its bindings and safe wrappers
//! (everything that does not touch `UnityEngine`) compiled with Mono's C# compiler into a console
//! test program (`runtime/unity/Tests~`) that runs against the C ABI library cargo built for these
//! tests (`libzoo_capi.so`).
//!
//! - `bindings_match_zoo_h`: the binding check passes on `runtime/capi/include/zoo.h` and fails on
//!   copies of it with a function removed, a function added, a parameter changed, the log
//!   callback's typedef changed and a `#define` (`ZOO_MAX_BATCH`) changed.
//! - `console_test_matches_the_rust_runtime`: each task on a tiny exported model of each kind
//!   (RTN, ARNN, RMR, RNN-GMM with its control) through C#, compared with what the Rust runtime
//!   API computes here for the same inputs (written to a vectors file: every `f32` as its bits,
//!   so both sides read the same numbers) within 1e-5 model units, in the model's frame and in
//!   Unity's; a 30-frame transition ends on its target; every bad call (disposed handles, wrong
//!   lengths, NaN, another task's model, missing bones) raises a managed exception with the
//!   runtime's message; no managed allocation over 1000 steps of every per-frame call; and the
//!   per-frame cost through C# against the same C ABI called from C (`Tests~/cbench.c`), batch 1 and
//!   64, medians of 11 interleaved rounds, within 10%. Then the named cases of C ABI 3 ([`CASES`],
//!   each printed `case NAME: passed`): a count of `int.MaxValue` (above `ZOO_MAX_BATCH`) refused
//!   by the runtime with its message and a negative one by the wrapper, for every constructor that
//!   takes a count; a runner's `max_batch` a hard limit; a coordinate frame's up axis or handedness
//!   outside its enum refused by name; `Model.FromBytes` the same model as `Model.Load`, bit for
//!   bit, for each task; the library's version, status names, empty last error after a success and
//!   log callback; disposed wrappers' cached properties. The program exits 0 with nothing on
//!   stderr (the library never prints, no managed exception escapes).
//! - `samples_compile_against_the_unity_api_they_use`: the Unity glue (`Runtime/Unity`) and the
//!   samples type-check against a stub of the few `UnityEngine` members they use
//!   (`Tests~/UnityStub.cs`; this checks their C#, not their behaviour in Unity).
//! - `package_layout`: `package.json`, the assembly definitions, and a `.meta` with a unique GUID
//!   for every file and folder Unity imports.
//!
//! Needs Mono (`mcs`, `mono`: Debian's `mono-complete`, which `.ci/run` installs) and a C compiler;
//! without Mono these tests fail and say how to install it.

use glam::{Quat, Vec3};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use zoo_runtime::control::{Control, ControlRunner, ControlSettings, ControlledCharacter};
use zoo_runtime::keyframes::MotionKeys;
use zoo_runtime::stitch::{FootCleanup, StitchRefiner};
use zoo_runtime::synthesis::SynthesisModel;
use zoo_runtime::{Conversion, CoordinateFrame, EnginePose, Handedness, LoadedModel, UpAxis};

/// Unity's frame: metres, Y up, left-handed.
const UNITY: CoordinateFrame =
    CoordinateFrame { metres_per_unit: 1.0, up_axis: UpAxis::Y, handedness: Handedness::Left };

fn package() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime/unity")
}

fn header() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../runtime/capi/include/zoo.h")
}

/// The tool `name` on the PATH.
fn which(name: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?.to_str()?.split(':').map(|d| Path::new(d).join(name)).find(|p| p.is_file())
}

/// Mono's C# compiler and runtime, or a failure that says how to install them.
fn mono() -> (PathBuf, PathBuf) {
    match (which("mcs"), which("mono")) {
        (Some(mcs), Some(mono)) => (mcs, mono),
        _ => panic!(
            "Mono is missing (`mcs` and `mono`): install it with `apt-get install -y mono-complete` \
             (.ci/run does when it is missing); the Unity package's tests compile its C# with Mono"
        ),
    }
}

/// The folder of the libraries cargo built for these tests (`target/<profile>/deps`).
fn deps_dir() -> PathBuf {
    std::env::current_exe().unwrap().parent().unwrap().to_path_buf()
}

/// The C ABI's shared library cargo built for these tests.
fn capi_library() -> PathBuf {
    let deps = deps_dir();
    [deps.join("libzoo_capi.so"), deps.parent().unwrap().join("libzoo_capi.so")]
        .into_iter()
        .filter(|p| p.exists())
        .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
        .expect("libzoo_capi.so: build the workspace first (`cargo build --workspace`)")
}

#[track_caller]
fn check(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The C# sources under `dir` (recursively), but those of the folders `skip`.
fn sources(dir: &Path, skip: &[PathBuf], out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            if !skip.contains(&p) {
                sources(&p, skip, out);
            }
        } else if p.extension().is_some_and(|e| e == "cs") {
            out.push(p);
        }
    }
}

/// The package's C# built with Mono (once per test run): `Zoo.Runtime.dll` from `Runtime/` but
/// its Unity glue `Runtime/Unity` (C# 7.2, warnings as errors, documentation of every public item),
/// `zoo-tests.exe` from `Tests~/`, and the C side of the timing (`libzoo_cbench.so`, linked against
/// `libzoo_capi.so`).
struct Built {
    dir: PathBuf,
    runtime: PathBuf,
    tests: PathBuf,
}

fn built() -> &'static Built {
    static BUILT: OnceLock<Built> = OnceLock::new();
    BUILT.get_or_init(|| {
        let (mcs, _) = mono();
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("unity");
        std::fs::create_dir_all(&dir).unwrap();
        let pkg = package();
        let runtime = dir.join("Zoo.Runtime.dll");
        let mut runtime_sources = Vec::new();
        sources(&pkg.join("Runtime"), &[pkg.join("Runtime/Unity")], &mut runtime_sources);
        let out = Command::new(&mcs)
            .args(["-langversion:7.2", "-unsafe", "-target:library", "-warnaserror+", "-nologo"])
            .arg(format!("-doc:{}", dir.join("Zoo.Runtime.xml").display()))
            .arg(format!("-out:{}", runtime.display()))
            .args(&runtime_sources)
            .output()
            .unwrap();
        check(&out, "mcs (the package's Runtime/)");
        let tests = dir.join("zoo-tests.exe");
        let test_sources: Vec<PathBuf> =
            ["Program.cs", "Header.cs", "BindingCheck.cs", "Vectors.cs", "ConsoleTests.cs"]
                .iter()
                .map(|f| pkg.join("Tests~").join(f))
                .collect();
        let out = Command::new(&mcs)
            .args(["-langversion:7.2", "-unsafe", "-nologo", "-warnaserror+"])
            .arg(format!("-r:{}", runtime.display()))
            .arg(format!("-out:{}", tests.display()))
            .args(&test_sources)
            .output()
            .unwrap();
        check(&out, "mcs (Tests~)");
        let capi = capi_library();
        let lib_dir = capi.parent().unwrap();
        let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
        let out = Command::new(&cc)
            .args(["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC", "-I"])
            .arg(header().parent().unwrap())
            .arg(pkg.join("Tests~/cbench.c"))
            .arg(format!("-L{}", lib_dir.display()))
            .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
            .args(["-lzoo_capi", "-o"])
            .arg(dir.join("libzoo_cbench.so"))
            .output()
            .unwrap_or_else(|e| panic!("cannot run the C compiler `{cc}` ({e}); install gcc or set CC"));
        check(&out, "cc (Tests~/cbench.c)");
        Built { dir, runtime, tests }
    })
}

/// Runs `zoo-tests.exe` with `args`, finding `libzoo_capi.so` and `libzoo_cbench.so`.
fn run_tests_exe(args: &[&str]) -> Output {
    let (_, mono) = mono();
    let b = built();
    let capi = capi_library();
    let path = format!(
        "{}:{}:{}",
        b.dir.display(),
        capi.parent().unwrap().display(),
        std::env::var("LD_LIBRARY_PATH").unwrap_or_default()
    );
    Command::new(mono)
        .arg("--debug")
        .arg(&b.tests)
        .args(args)
        .env("LD_LIBRARY_PATH", path)
        .current_dir(&b.dir)
        .output()
        .unwrap()
}

#[test]
fn bindings_match_zoo_h() {
    let out = run_tests_exe(&["check-bindings", header().to_str().unwrap()]);
    check(&out, "the binding check on runtime/capi/include/zoo.h");
    eprintln!("{}", String::from_utf8_lossy(&out.stdout).trim());

    // The generated functions are what Tools~/update-bindings.sh writes from the header now.
    let (mcs, mono) = mono();
    let dir = built().dir.join("generate");
    std::fs::create_dir_all(&dir).unwrap();
    let pkg = package();
    let exe = dir.join("generate-bindings.exe");
    let out = Command::new(mcs)
        .args(["-langversion:7.2", "-nologo"])
        .arg(format!("-out:{}", exe.display()))
        .arg(pkg.join("Tools~/GenerateBindings.cs"))
        .arg(pkg.join("Tests~/Header.cs"))
        .output()
        .unwrap();
    check(&out, "mcs (Tools~/GenerateBindings.cs)");
    let generated = dir.join("ZooNative.Functions.cs");
    check(&Command::new(mono).arg(&exe).arg(header()).arg(&generated).output().unwrap(), "generate-bindings.exe");
    let committed = std::fs::read_to_string(pkg.join("Runtime/Native/ZooNative.Functions.cs")).unwrap();
    assert!(
        std::fs::read_to_string(&generated).unwrap() == committed,
        "runtime/unity/Runtime/Native/ZooNative.Functions.cs is not what zoo.h generates: run runtime/unity/Tools~/update-bindings.sh"
    );

    // The check fails on a header that drifted from the bindings: a function removed, one added,
    // a parameter's type changed, a callback's parameter changed, a constant changed.
    let text = std::fs::read_to_string(header()).unwrap();
    let start = text.find("enum ZooStatus zoo_transition_frames_left(").unwrap();
    let end = start + text[start..].find(';').unwrap() + 1;
    let removed = format!("{}{}", &text[..start], &text[end..]);
    let added = text.replace(
        "#ifdef __cplusplus\n}",
        "enum ZooStatus zoo_pose_blend(const struct ZooModel *model, float *weights, size_t weights_len);\n\n#ifdef __cplusplus\n}",
    );
    let changed = text.replace(
        "size_t index,\n                                          size_t *out);",
        "uint32_t index,\n                                          size_t *out);",
    );
    assert_ne!(changed, text, "zoo_transition_frames_left's declaration moved: update this test");
    let callback =
        text.replace("typedef void (*ZooLogCallback)(int32_t level,", "typedef void (*ZooLogCallback)(uint32_t level,");
    assert_ne!(callback, text, "ZooLogCallback's typedef moved: update this test");
    let constant = text.replace("#define ZOO_MAX_BATCH 65536", "#define ZOO_MAX_BATCH 4096");
    assert_ne!(constant, text, "ZOO_MAX_BATCH's #define changed: update this test");
    let dir = built().dir.join("drifted");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, header, needle) in [
        (
            "removed.h",
            removed,
            "ZooNative.zoo_transition_frames_left binds `zoo_transition_frames_left`, which zoo.h does not declare",
        ),
        ("added.h", added, "zoo_pose_blend has no binding in ZooNative"),
        ("changed.h", changed, "parameter `index` is System.UIntPtr, zoo.h uint32_t"),
        (
            "callback.h",
            callback,
            "delegate Zoo.Native.ZooLogCallback differs from zoo.h's ZooLogCallback: parameter `level` is System.Int32, zoo.h uint32_t",
        ),
        ("constant.h", constant, "ZooNative.ZOO_MAX_BATCH is 65536, zoo.h's is 4096"),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, header).unwrap();
        let out = run_tests_exe(&["check-bindings", path.to_str().unwrap()]);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(!out.status.success(), "the binding check passes on {name}:\n{text}");
        assert!(text.contains(needle), "the binding check on {name} should say `{needle}`:\n{text}");
        eprintln!("binding check on a drifted header ({name}): fails as it should:\n{}", text.trim());
    }
}

/// `zoo_model_joint_name`, which the package maps bones with: the length asked with a NULL buffer,
/// a truncated copy still NUL-terminated, a joint out of range and a NULL length refused.
#[test]
#[allow(unsafe_code)]
fn joint_names_through_the_c_abi() {
    use zoo_capi::*;
    use zoo_tests::capi::{assert_error, assert_ok, c_path};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rtn.onnx");
    rtn30_onnx().write(&path).unwrap();
    let mut model = std::ptr::null_mut();
    assert_ok(unsafe { zoo_model_load(c_path(&path).as_ptr(), &mut model) });
    let names = humanoid_skeleton().names;
    for (j, name) in names.iter().enumerate() {
        let mut length = 0usize;
        assert_ok(unsafe { zoo_model_joint_name(model, j, std::ptr::null_mut(), 0, &mut length) });
        assert_eq!(length, name.len());
        let mut buffer = vec![7u8; length + 1];
        assert_ok(unsafe { zoo_model_joint_name(model, j, buffer.as_mut_ptr().cast(), buffer.len(), &mut length) });
        assert_eq!(&buffer[..length], name.as_bytes());
        assert_eq!(buffer[length], 0);
    }
    let mut short = [7u8; 4];
    let mut length = 0usize;
    assert_ok(unsafe { zoo_model_joint_name(model, 3, short.as_mut_ptr().cast(), short.len(), &mut length) });
    assert_eq!((&short, length), (b"Lef\0", "LeftUpLeg".len()), "truncated, NUL-terminated, the full length");
    let status = unsafe { zoo_model_joint_name(model, names.len(), short.as_mut_ptr().cast(), 4, &mut length) };
    assert_error(
        status,
        ZooStatus::InvalidArgument,
        "zoo_model_joint_name: joint 9 (`joint`) does not exist: the skeleton has 9 joints",
    );
    let status = unsafe { zoo_model_joint_name(model, 0, short.as_mut_ptr().cast(), 4, std::ptr::null_mut()) };
    assert_error(status, ZooStatus::NullPointer, "zoo_model_joint_name: `length` is NULL");
    let status = unsafe { zoo_model_joint_name(model, 0, std::ptr::null_mut(), 4, &mut length) };
    assert_error(status, ZooStatus::NullPointer, "`buffer` is NULL");
    unsafe { zoo_model_free(model) };
}

// The expected outputs, computed with the Rust runtime API.

/// The vectors file: one line per array, `name f|i|s values...` (floats as their bits in hex, so
/// that C# reads exactly the numbers Rust wrote).
#[derive(Default)]
struct Vectors(String);

impl Vectors {
    fn f(&mut self, name: &str, values: &[f32]) {
        write!(self.0, "{name} f").unwrap();
        for v in values {
            write!(self.0, " {:08x}", v.to_bits()).unwrap();
        }
        self.0.push('\n');
    }

    fn i(&mut self, name: &str, values: &[i64]) {
        write!(self.0, "{name} i").unwrap();
        for v in values {
            write!(self.0, " {v}").unwrap();
        }
        self.0.push('\n');
    }

    fn s(&mut self, name: &str, values: &[String]) {
        write!(self.0, "{name} s").unwrap();
        for v in values {
            assert!(!v.contains(char::is_whitespace), "{v}");
            write!(self.0, " {v}").unwrap();
        }
        self.0.push('\n');
    }

    /// Engine poses as the C ABI lays them out: `name.roots` 14 floats per pose (`ZooRootMotion`)
    /// and `name.rot` 4K per pose.
    fn poses<'a>(&mut self, name: &str, poses: impl IntoIterator<Item = &'a EnginePose>) {
        let (mut roots, mut rotations) = (Vec::new(), Vec::new());
        for p in poses {
            roots.extend(p.root_position.to_array());
            roots.extend(p.root_rotation.to_array());
            roots.extend(p.root_delta_position.to_array());
            roots.push(p.root_delta_yaw);
            roots.extend(p.hips_position.to_array());
            rotations.extend(p.local_rotations.iter().flat_map(|q| q.to_array()));
        }
        self.f(&format!("{name}.roots"), &roots);
        self.f(&format!("{name}.rot"), &rotations);
    }

    fn contacts(&mut self, name: &str, contacts: &[Vec<bool>]) {
        self.i(name, &contacts.iter().flatten().map(|&c| i64::from(c)).collect::<Vec<_>>());
    }
}

fn converted(poses: &[EnginePose], c: &Conversion) -> Vec<EnginePose> {
    poses
        .iter()
        .map(|p| {
            let mut p = p.clone();
            p.convert(c);
            p
        })
        .collect()
}

fn converted_positions(values: &[f32], c: &Conversion) -> Vec<f32> {
    values.chunks_exact(3).flat_map(|p| c.position(Vec3::from_slice(p)).to_array()).collect()
}

/// A small humanoid: hips, a spine and a head, two legs of three joints. Unlike
/// `zoo_tests::toy_skeleton` (every bone on the Y axis), its hips' yaw shows in the joint
/// positions (the legs sit apart), so a posed transition can land on the target's rotations.
fn humanoid_skeleton() -> zoo_motion::Skeleton {
    use glam::DVec3;
    let ch = |position| zoo_motion::JointChannels { position, order: zoo_motion::EulerOrder::Zxy };
    let names = ["Hips", "Spine", "Head", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot"];
    let offsets = [
        DVec3::ZERO,
        DVec3::new(0.0, 10.0, 0.0),
        DVec3::new(0.0, 25.0, 2.0),
        DVec3::new(10.0, -5.0, 0.0),
        DVec3::new(0.0, -40.0, 0.0),
        DVec3::new(0.0, -40.0, 0.0),
        DVec3::new(-10.0, -5.0, 0.0),
        DVec3::new(0.0, -40.0, 0.0),
        DVec3::new(0.0, -40.0, 0.0),
    ];
    zoo_motion::Skeleton {
        names: names.iter().map(|s| s.to_string()).collect(),
        parents: vec![None, Some(0), Some(1), Some(0), Some(3), Some(4), Some(0), Some(6), Some(7)],
        offsets: offsets.to_vec(),
        end_sites: vec![
            None,
            None,
            Some(DVec3::new(0.0, 10.0, 0.0)),
            None,
            None,
            Some(DVec3::new(0.0, -5.0, 12.0)),
            None,
            None,
            Some(DVec3::new(0.0, -5.0, 12.0)),
        ],
        channels: (0..9).map(|j| ch(j == 0)).collect(),
    }
}

/// A tiny RTN (`zoo_rtn::Config::tiny`'s sizes, seeded weights) on [`humanoid_skeleton`], exported
/// as `zoo export --onnx` would, with the paper's windows (10 context frames, transitions of 30):
/// the 30-frame transition runs at its trained length.
fn rtn30_onnx() -> zoo_export::OnnxModel {
    use candle_core::{DType, Device};
    use zoo_rtn::features::{FeatureStats, MeanStd};
    let skeleton = humanoid_skeleton();
    let mut config = zoo_rtn::Config::tiny().with_parents(&skeleton.parents);
    config.past_frames = 10;
    config.transition_frames = 30;
    let varmap = candle_nn::VarMap::new();
    zoo_rtn::Rtn::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu)).unwrap();
    let d = config.dim();
    let unit = || MeanStd { mean: vec![0.0; d], std: vec![2.0; d] };
    let stats = FeatureStats { joints: skeleton.len(), x: unit(), velocity: unit(), offset: unit(), terrain: None };
    let options = zoo_rtn::export::RtnExportOptions {
        names: Some(skeleton.names.clone()),
        offsets: Some(skeleton.offsets.iter().map(|o| o.as_vec3().to_array()).collect()),
        parents: None,
        fps: Some(30.0),
        frame: Some(CoordinateFrame::ZOO_CM),
    };
    zoo_rtn::export::export_rtn(&config, None, &stats, &varmap, &options).unwrap()
}

/// Frame `f` of character `c`'s walk (the C example's `walk_pose` of `tests/capi.rs`, turning).
fn walk_pose(k: usize, hips_height: f32, c: usize, f: usize) -> EnginePose {
    let mut pose = EnginePose::new(k);
    let t = f as f32;
    pose.root_position = Vec3::new(200.0 * c as f32 + 10.0 * (0.05 * t).sin(), 0.0, 4.0 * t);
    pose.root_rotation = Quat::from_rotation_y(0.02 * t + 0.3 * c as f32);
    pose.hips_position = Vec3::new(0.0, hips_height, 0.0);
    for (j, q) in pose.local_rotations.iter_mut().enumerate() {
        *q = Quat::from_rotation_x(0.2 * (0.3 * t + j as f32 + 0.5 * c as f32).sin());
    }
    pose
}

/// Global joint positions of a pose over `model`'s skeleton (f32 forward kinematics).
fn positions(pose: &EnginePose, parents: &[i32], offsets: &[[f32; 3]]) -> Vec<f32> {
    let k = parents.len();
    let (mut rot, mut pos) = (vec![Quat::IDENTITY; k], vec![Vec3::ZERO; k]);
    for j in 0..k {
        if parents[j] < 0 {
            rot[j] = pose.hips_world_rotation();
            pos[j] = pose.hips_world();
        } else {
            let p = parents[j] as usize;
            pos[j] = pos[p] + rot[p] * Vec3::from_array(offsets[j]);
            rot[j] = rot[p] * pose.local_rotations[j];
        }
    }
    pos.iter().flat_map(|p| p.to_array()).collect()
}

fn transition_vectors(v: &mut Vectors, path: &Path) {
    let model = LoadedModel::load(path).unwrap().into_transition().unwrap();
    let meta = model.model().metadata();
    let (k, n, past_frames, length) = (model.joints(), 2usize, model.past_frames(), model.transition_frames());
    assert_eq!((past_frames, length), (10, 30));
    let model_frame = meta.frame;
    let (to_unity, to_model) = (Conversion::between(&model_frame, &UNITY), Conversion::between(&UNITY, &model_frame));
    let offsets: Vec<[f32; 3]> = (0..k).map(|j| meta.skeleton.offset(j).to_array()).collect();
    v.i("tr.n", &[n as i64]);
    v.i("tr.length", &[length as i64]);
    v.s("tr.names", &meta.skeleton.names);
    v.i("tr.parents", &meta.skeleton.parents.iter().map(|&p| i64::from(p)).collect::<Vec<_>>());
    let flat: Vec<f32> = offsets.iter().flatten().copied().collect();
    v.f("tr.offsets", &flat);
    v.f("tr.offsets.unity", &converted_positions(&flat, &to_unity));

    let past: Vec<EnginePose> =
        (0..n).flat_map(|c| (0..past_frames).map(move |f| (c, f))).map(|(c, f)| walk_pose(k, 90.0, c, f)).collect();
    let t = past_frames + length;
    let target: Vec<EnginePose> = (0..n).map(|c| walk_pose(k, 90.0, c, t)).collect();
    let next: Vec<EnginePose> = (0..n).map(|c| walk_pose(k, 90.0, c, t + 1)).collect();
    let run_posed = |past: &[EnginePose], target: &[EnginePose], next: &[EnginePose]| {
        let mut runner = model.runner().unwrap();
        let mut states: Vec<_> = (0..n).map(|_| model.new_transition()).collect();
        runner.start_posed_batch_for(&mut states, past, target, next, length).unwrap();
        let mut poses = vec![EnginePose::new(k); n];
        let mut out = Vec::new();
        for _ in 0..=length {
            runner.step_posed_batch(&mut states, &mut poses).unwrap();
            out.extend(poses.iter().cloned());
        }
        let miss: Vec<f32> = states.iter().flat_map(|s| s.target_miss().map(|m| [m.mean, m.max]).unwrap()).collect();
        (out, miss)
    };
    // The model's frame.
    v.poses("tr.posed.past", &past);
    v.poses("tr.posed.target", &target);
    v.poses("tr.posed.next", &next);
    let (out, miss) = run_posed(&past, &target, &next);
    v.poses("tr.posed.out", &out);
    v.f("tr.miss", &miss);
    // Unity's: the engine's poses go in converted (by the runtime's conversion, as the wrapper
    // does), the model's come out converted.
    let (pu, tu, nu) = (converted(&past, &to_unity), converted(&target, &to_unity), converted(&next, &to_unity));
    v.poses("tr.unity.past", &pu);
    v.poses("tr.unity.target", &tu);
    v.poses("tr.unity.next", &nu);
    let (out, _) = run_posed(&converted(&pu, &to_model), &converted(&tu, &to_model), &converted(&nu, &to_model));
    v.poses("tr.unity.out", &converted(&out, &to_unity));

    // Global positions, the same motion.
    let parents = &meta.skeleton.parents;
    let pos = |poses: &[EnginePose]| poses.iter().flat_map(|p| positions(p, parents, &offsets)).collect::<Vec<f32>>();
    let (pp, tp, np) = (pos(&past), pos(&target), pos(&next));
    let run_positions = |past: &[f32], target: &[f32], next: &[f32]| {
        let mut runner = model.runner().unwrap();
        let mut states: Vec<_> = (0..n).map(|_| model.new_transition()).collect();
        runner.start_batch_for(&mut states, past, target, next, length).unwrap();
        let mut frame = vec![0.0f32; n * 3 * k];
        let mut out = Vec::new();
        for _ in 0..=length {
            runner.step_batch(&mut states, &mut frame).unwrap();
            out.extend_from_slice(&frame);
        }
        out
    };
    v.f("tr.pos.past", &pp);
    v.f("tr.pos.target", &tp);
    v.f("tr.pos.next", &np);
    v.f("tr.pos.out", &run_positions(&pp, &tp, &np));
    let (ppu, tpu, npu) =
        (converted_positions(&pp, &to_unity), converted_positions(&tp, &to_unity), converted_positions(&np, &to_unity));
    v.f("tr.unity.pos.past", &ppu);
    v.f("tr.unity.pos.target", &tpu);
    v.f("tr.unity.pos.next", &npu);
    let out = run_positions(
        &converted_positions(&ppu, &to_model),
        &converted_positions(&tpu, &to_model),
        &converted_positions(&npu, &to_model),
    );
    v.f("tr.unity.pos.out", &converted_positions(&out, &to_unity));

    // Poses from the hips' world transform in Unity's frame (EnginePose::set_world), what the
    // character sample reads from its Transforms.
    let mut hips = Vec::new();
    let mut hips_rot = Vec::new();
    let mut want = Vec::new();
    for (c, f) in [(0, 0), (1, 7), (0, 23), (1, 40)] {
        let mut p = walk_pose(k, 90.0, c, f);
        p.local_rotations[0] = Quat::from_rotation_z(0.3) * Quat::from_rotation_x(-0.2 + 0.01 * f as f32);
        p.convert(&to_unity);
        let (h, r) = (p.hips_world(), p.hips_world_rotation());
        hips.extend(h.to_array());
        hips_rot.extend(r.to_array());
        let mut rotations = p.local_rotations.clone();
        rotations[0] = r;
        want.push(EnginePose::from_world(h, &rotations));
    }
    v.f("world.hips", &hips);
    v.f("world.hipsrot", &hips_rot);
    v.poses("world.want", &want);
}

fn keyframes_vectors(v: &mut Vectors, path: &Path) {
    let model = LoadedModel::load(path).unwrap().into_keyframes().unwrap();
    let d = model.dofs();
    // Two characters: keys at 0, 9, 24, 39 and 0, 12, 30 (tests/capi_tasks.rs's example).
    let counts = [4usize, 3];
    let frames = [0usize, 9, 24, 39, 0, 12, 30];
    let mut poses = Vec::new();
    for (c, &n) in counts.iter().enumerate() {
        let first = if c == 0 { 0 } else { 4 };
        for key in 0..n {
            for j in 0..d {
                let x = 0.3 * (0.7 * key as f64 + 1.3 * j as f64 + 0.5 * c as f64).sin()
                    + 0.01 * frames[first + key] as f64;
                poses.push(x as f32);
            }
        }
    }
    let keys = [MotionKeys::whole(&frames[..4], &poses[..4 * d]), MotionKeys::whole(&frames[4..], &poses[4 * d..])];
    let (mut a, mut b) = (vec![0.0; 40 * d], vec![0.0; 31 * d]);
    model.runner(2).unwrap().complete_batch(&keys, &mut [&mut a, &mut b]).unwrap();
    let mut single = vec![0.0; 40 * d];
    model.runner(1).unwrap().complete(keys[0], &mut single).unwrap();
    v.i("kf.counts", &counts.map(|c| c as i64));
    v.i("kf.frames", &frames.map(|f| f as i64));
    v.f("kf.poses", &poses);
    v.f("kf.single", &single);
    v.f("kf.batch", &[a, b].concat());
    v.s("kf.names", &model.metadata().skeleton.names);
}

fn stitch_vectors(v: &mut Vectors, path: &Path) {
    let refiner = StitchRefiner::load(path).unwrap();
    let skeleton = refiner.skeleton();
    let k = refiner.joints();
    let mut rest_y = vec![0.0f32; k];
    let mut lowest = 0.0f32;
    for j in 0..k {
        rest_y[j] = skeleton.parents[j].map_or(0.0, |p| rest_y[p] + skeleton.offsets[j].y as f32);
        lowest = lowest.min(rest_y[j]);
    }
    let speed = 120.0 / refiner.fps() as f32;
    let frames = refiner.window() + 2 * refiner.stride() + 5;
    let poses: Vec<EnginePose> = (0..frames)
        .map(|f| {
            let mut p = EnginePose::new(k);
            let t = f as f32;
            p.root_position = Vec3::new(10.0 * (0.05 * t).sin(), 0.0, speed * t);
            p.root_rotation = Quat::from_rotation_y(0.01 * t);
            p.hips_position = Vec3::new(0.0, -lowest, 0.0);
            for (j, q) in p.local_rotations.iter_mut().enumerate() {
                *q = Quat::from_rotation_x(0.3 * (0.2 * t + j as f32).sin());
            }
            p
        })
        .collect();
    v.poses("st.in", &poses);
    let mut refined = vec![EnginePose::new(k); frames];
    let mut contacts = vec![[false; 4]; frames];
    refiner
        .refine_poses(&poses, FootCleanup { place_ankles: true, lock_feet: true }, &mut refined, &mut contacts)
        .unwrap();
    v.poses("st.refine", &refined);
    v.contacts("st.refine.contacts", &contacts.iter().map(|c| c.to_vec()).collect::<Vec<_>>());
    let mut stream = refiner.stream();
    let mut pose = EnginePose::new(k);
    let (mut popped, mut popped_contacts) = (Vec::new(), Vec::new());
    for f in 0..=frames {
        match poses.get(f) {
            Some(p) => stream.push(p).unwrap(),
            None => stream.finish().unwrap(),
        }
        while let Some(c) = stream.pop(&mut pose).unwrap() {
            popped.push(pose.clone());
            popped_contacts.push(c.to_vec());
        }
    }
    v.poses("st.stream", &popped);
    v.contacts("st.stream.contacts", &popped_contacts);
    v.s("st.names", &refiner.metadata().skeleton.names);
    // The same sequence inertialized at two seams first (`zoo stitch --pre-blend`), whole and
    // streamed with the seams marked.
    let seams = [frames / 3, frames / 3 + 1];
    v.i("st.seams", &seams.map(|s| s as i64));
    let cleanup = FootCleanup { place_ankles: true, lock_feet: true };
    refiner.refine_poses_at_seams(&poses, &seams, cleanup, &mut refined, &mut contacts).unwrap();
    v.poses("st.seams.refine", &refined);
    let mut stream = refiner.stream();
    let mut popped = Vec::new();
    for f in 0..=frames {
        if seams.contains(&f) {
            stream.mark_seam();
        }
        match poses.get(f) {
            Some(p) => stream.push(p).unwrap(),
            None => stream.finish().unwrap(),
        }
        while stream.pop(&mut pose).unwrap().is_some() {
            popped.push(pose.clone());
        }
    }
    v.poses("st.seams.stream", &popped);
}

const SEEDS: [u64; 3] = [100, 101, 102];
const SYNTH_FRAMES: usize = 20;

fn control_of(t: usize) -> Control {
    Control::new(150.0, if t < SYNTH_FRAMES / 2 { 0.0 } else { 1.570_796_4 })
}

fn synthesis_vectors(v: &mut Vectors, path: &Path) {
    let model: SynthesisModel = LoadedModel::load(path).unwrap().into_synthesis().unwrap();
    let (n, d, k) = (SEEDS.len(), model.frame_dim(), model.joints());
    let mean = &model.model().metadata().normalization["x"].mean;
    let frames: Vec<f32> = (0..n).flat_map(|_| mean.iter().copied()).collect();
    let placements: Vec<f32> = (0..n).flat_map(|c| [200.0 * c as f32, 0.0, 0.1 * c as f32]).collect();
    v.i("sy.seeds", &SEEDS.map(|s| s as i64));
    v.f("sy.frames", &frames);
    v.f("sy.placements", &placements);
    v.i("sy.steps", &[SYNTH_FRAMES as i64]);
    let mut runner = model.runner(n).unwrap();
    let mut chars: Vec<_> = SEEDS.iter().map(|&s| model.new_character(s)).collect();
    for (c, ch) in chars.iter_mut().enumerate() {
        let p = &placements[3 * c..3 * c + 3];
        ch.start(&model, &frames[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
    }
    let mut poses = vec![EnginePose::new(k); n];
    let mut contacts = vec![[false; 2]; n];
    let (mut out, mut out_contacts) = (Vec::new(), Vec::new());
    for _ in 0..SYNTH_FRAMES {
        runner.step_batch(&mut chars, 1.0, &mut poses, &mut contacts).unwrap();
        out.extend(poses.iter().cloned());
        out_contacts.extend(contacts.iter().map(|c| c.to_vec()));
    }
    v.poses("sy.out", &out);
    v.poses("sy.unity", &converted(&out, &Conversion::between(&model.model().metadata().frame, &UNITY)));
    v.contacts("sy.out.contacts", &out_contacts);

    let mut runner = ControlRunner::new(&model).unwrap();
    let mut chars: Vec<_> =
        SEEDS.iter().map(|&s| ControlledCharacter::new(&model, s, ControlSettings::default()).unwrap()).collect();
    for (c, ch) in chars.iter_mut().enumerate() {
        let p = &placements[3 * c..3 * c + 3];
        ch.start(&model, &frames[c * d..(c + 1) * d], p[0], p[1], p[2]).unwrap();
    }
    let mut pose = EnginePose::new(k);
    let (mut out, mut out_contacts, mut controls) = (Vec::new(), Vec::new(), Vec::new());
    for t in 0..SYNTH_FRAMES {
        let z = control_of(t);
        controls.extend([z.speed, z.heading]);
        for ch in chars.iter_mut() {
            let c = runner.step(ch, z, &mut pose).unwrap();
            out.push(pose.clone());
            out_contacts.push(c.to_vec());
        }
    }
    v.f("ct.controls", &controls);
    v.poses("ct.out", &out);
    v.contacts("ct.out.contacts", &out_contacts);
    v.s("sy.names", &model.model().metadata().skeleton.names);
}

/// The models and the vectors file of the console test.
fn write_inputs(dir: &Path) -> PathBuf {
    let write = |name: &str, model: zoo_export::OnnxModel| {
        let path = dir.join(name);
        model.write(&path).unwrap();
        path
    };
    let rtn = write("rtn.onnx", rtn30_onnx());
    let arnn = write("arnn.onnx", zoo_tests::tiny_arnn_onnx());
    let rmr = write("rmr.onnx", zoo_tests::tiny_rmr_onnx());
    let rnngmm = write("rnngmm.onnx", zoo_tests::tiny_rnngmm_onnx());
    let mut v = Vectors::default();
    transition_vectors(&mut v, &rtn);
    keyframes_vectors(&mut v, &arnn);
    stitch_vectors(&mut v, &rmr);
    synthesis_vectors(&mut v, &rnngmm);
    let path = dir.join("vectors.txt");
    std::fs::write(&path, v.0).unwrap();
    path
}

/// The value of `key=value` on the summary line starting with `tag`.
fn figure(text: &str, tag: &str, key: &str) -> f64 {
    let line = text.lines().find(|l| l.starts_with(tag)).unwrap_or_else(|| panic!("no `{tag}` line in:\n{text}"));
    let at = line.find(&format!("{key}=")).unwrap_or_else(|| panic!("no `{key}=` in `{line}`"));
    let value = line[at + key.len() + 1..].split(|c: char| c.is_whitespace() || c == ',').next().unwrap();
    value.parse().unwrap_or_else(|_| panic!("`{value}` in `{line}` is not a number"))
}

/// The named cases of the console test (`Tests~/ConsoleTests.cs`, `Cases`), each of which must
/// print `case NAME: passed`.
const CASES: &[&str] = &[
    "transition_fed_per_frame",
    "transition_generate_posed",
    "count_int_max.transition_runner",
    "count_negative.transition_runner",
    "count_int_max.transition_characters",
    "count_negative.transition_characters",
    "count_int_max.keyframes_runner",
    "count_negative.keyframes_runner",
    "count_int_max.synthesis_runner",
    "count_negative.synthesis_runner",
    "count_int_max.control_runner",
    "count_negative.control_runner",
    "count_above_max_batch.synthesis_characters",
    "count_above_max_batch.control_characters",
    "count_int_max.pose_buffer",
    "count_negative.pose_buffer",
    "count_negative.other_sizes",
    "max_batch_is_a_limit",
    "frame_bad_up_axis",
    "frame_bad_handedness",
    "frame_enum_values",
    "from_bytes.transition",
    "from_bytes.keyframes",
    "from_bytes.stitch",
    "from_bytes.synthesis",
    "from_bytes.control",
    "from_bytes.refused",
    "library_version",
    "library_status_names",
    "library_last_error_empty_after_success",
    "library_log_callback",
    "disposed_properties",
];

#[test]
fn console_test_matches_the_rust_runtime() {
    let dir = built().dir.join("models");
    std::fs::create_dir_all(&dir).unwrap();
    let vectors = write_inputs(&dir);
    let out = run_tests_exe(&["run", vectors.to_str().unwrap(), dir.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    eprintln!("{text}{}", String::from_utf8_lossy(&out.stderr));
    check(&out, "the console test (mono zoo-tests.exe run)");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.trim().is_empty(), "the console test wrote to stderr (the library never prints):\n{stderr}");
    for case in CASES {
        assert!(text.lines().any(|l| l == format!("case {case}: passed")), "case `{case}` did not pass:\n{text}");
    }
    for tag in ["parity transition", "parity keyframes", "parity stitch", "parity synthesis", "parity control"] {
        let worst = figure(&text, tag, "worst");
        assert!(worst <= 1e-5, "{tag}: worst difference {worst} > 1e-5");
    }
    // The target blend lands on the target up to float rounding (of positions of a few metres in
    // centimetres: 1e-5 relative, a tenth of a micrometre).
    assert!(figure(&text, "last frame", "target") <= 1e-4);
    let refused = figure(&text, "bad calls", "refused");
    assert_eq!(figure(&text, "bad calls", "unexpected"), 0.0);
    assert!(refused >= 60.0, "{refused} bad calls checked");
    assert_eq!(figure(&text, "allocation", "bytes"), 0.0, "managed allocation over the counted steps");
    for batch in ["1", "64"] {
        let ratio = figure(&text, &format!("timing batch {batch}"), "ratio");
        assert!((0.9..=1.1).contains(&ratio), "batch {batch}: C# / C per-frame cost {ratio}, not within 10%");
    }
}

#[test]
fn samples_compile_against_the_unity_api_they_use() {
    let (mcs, _) = mono();
    let b = built();
    let pkg = package();
    let mut samples = Vec::new();
    sources(&pkg.join("Runtime/Unity"), &[], &mut samples);
    sources(&pkg.join("Samples~"), &[], &mut samples);
    assert!(samples.len() >= 4, "the Unity glue and the samples: {samples:?}");
    let out = Command::new(mcs)
        .args(["-langversion:7.2", "-target:library", "-nologo", "-warnaserror+"])
        .arg(format!("-r:{}", b.runtime.display()))
        .arg(format!("-out:{}", b.dir.join("Samples.dll").display()))
        .arg(pkg.join("Tests~/UnityStub.cs"))
        .args(&samples)
        .output()
        .unwrap();
    check(&out, "mcs (Samples~ against Tests~/UnityStub.cs)");
}

#[test]
fn package_layout() {
    let pkg = package();
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pkg.join("package.json")).unwrap()).unwrap();
    for key in ["name", "version", "displayName", "unity", "description"] {
        assert!(manifest[key].is_string(), "package.json needs `{key}`");
    }
    let samples = manifest["samples"].as_array().expect("package.json lists its samples");
    for s in samples {
        let path = s["path"].as_str().unwrap();
        assert!(pkg.join(path).is_dir(), "sample folder {path}");
    }
    let asmdef: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(pkg.join("Runtime/Zoo.Runtime.asmdef")).unwrap()).unwrap();
    assert_eq!(asmdef["allowUnsafeCode"], true);
    assert_eq!(asmdef["noEngineReferences"], true, "the runtime assembly does not reference UnityEngine");
    assert!(pkg.join("Documentation~/zoo.md").is_file());
    // Every file and folder Unity imports from the package has a .meta with a unique GUID.
    let mut guids = std::collections::HashSet::new();
    let mut stack = vec![pkg.join("Runtime")];
    let mut assets = vec![pkg.join("Runtime"), pkg.join("package.json"), pkg.join("README.md")];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if name.ends_with(".meta") || name.starts_with('.') || p.starts_with(pkg.join("Runtime/Plugins")) {
                continue;
            }
            if p.is_dir() {
                stack.push(p.clone());
            }
            assets.push(p);
        }
    }
    for a in assets {
        let meta = PathBuf::from(format!("{}.meta", a.display()));
        let text = std::fs::read_to_string(&meta).unwrap_or_else(|_| panic!("{} has no .meta", a.display()));
        let guid = text.lines().find_map(|l| l.strip_prefix("guid: ")).expect("a guid line").to_string();
        assert!(guid.len() == 32 && guids.insert(guid), "{}: a unique 32-digit guid", meta.display());
    }
}
