//! Round trips through Blender (Debian's package, Blender 3.4), headless: Blender's glTF
//! importer on zoo's `.glb`, Blender's FBX exporter read back by zoo, and the benchmark on a
//! folder of such FBX files against the BVH originals (issue 44).
//!
//! These tests are ignored by default (a machine without Blender still passes the suite);
//! `.ci/run` installs Blender (`apt-get install -y blender`) and runs them with
//! `cargo test -p zoo-data --test blender -- --ignored`. Run where Blender is missing, they
//! fail with the command that installs it. Each Blender run takes a few seconds.

use std::path::{Path, PathBuf};
use std::process::Command;
use zoo_data::benchmark::{Benchmark, Interpolation, TransitionMethod, ZeroVelocity};
use zoo_data::clip_io::{self, ReadOptions};
use zoo_data::dataset::{self, LoadOptions};
use zoo_data::synth::{SynthConfig, generate_clip};
use zoo_motion::Clip;

const INSTALL: &str =
    "Blender is not installed: apt-get install -y blender python3-numpy (Debian's packages; .ci/run installs them)";

/// The Blender side. `glb2json IN OUT`: imports a glb with Blender's glTF importer and writes
/// every bone head's world position (Blender's frame: metres, Z up) at every frame of the
/// action. `bvh2fbx OUT_DIR IN...`: imports each BVH (centimetres: scale 0.01) and exports it
/// with Blender's FBX exporter (animation baked at every frame, leaf bones added).
const SCRIPT: &str = r#"
import builtins, bpy, json, os, sys
args = sys.argv[sys.argv.index("--") + 1:]

# Debian's Blender 3.4 runs on Python 3.11, where the BVH importer's open(path, 'rU') fails.
_open = builtins.open
builtins.open = lambda f, mode="r", *a, **k: _open(f, mode.replace("U", ""), *a, **k)
# Its glTF importer uses numpy's `bool` alias, gone from the numpy Debian ships beside it.
import numpy
if "bool" not in numpy.__dict__:
    numpy.bool = numpy.bool_

def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)

if args[0] == "glb2json":
    clear()
    bpy.context.scene.render.fps = int(args[3])
    bpy.ops.import_scene.gltf(filepath=args[1])
    arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
    action = arm.animation_data.action
    first, last = [int(round(f)) for f in action.frame_range]
    mesh = [o for o in bpy.context.scene.objects if o.type == "MESH"][0]
    out = {"first": first, "frames": [], "mesh": {}}
    for f in range(first, last + 1):
        bpy.context.scene.frame_set(f)
        out["frames"].append({pb.name: list(arm.matrix_world @ pb.head) for pb in arm.pose.bones})
        if (f - first) % 20 == 0:
            ev = mesh.evaluated_get(bpy.context.evaluated_depsgraph_get())
            me = ev.to_mesh()
            out["mesh"][f - first] = [list(ev.matrix_world @ v.co) for v in me.vertices]
            ev.to_mesh_clear()
    json.dump(out, open(args[2], "w"))
elif args[0] == "glb2glb":
    clear()
    bpy.context.scene.render.fps = int(args[3])
    bpy.ops.import_scene.gltf(filepath=args[1])
    arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
    first, last = [int(round(f)) for f in arm.animation_data.action.frame_range]
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = first, last
    bpy.ops.export_scene.gltf(filepath=args[2], export_format="GLB", export_animations=True)
elif args[0] == "glb2fbx":
    for path in args[2:]:
        clear()
        bpy.context.scene.render.fps = int(args[1].split(":")[0])
        bpy.ops.import_scene.gltf(filepath=path)
        arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
        first, last = [int(round(f)) for f in arm.animation_data.action.frame_range]
        bpy.context.scene.frame_start, bpy.context.scene.frame_end = first, last
        name = os.path.basename(path).rsplit(".glb", 1)[0]
        bpy.ops.export_scene.fbx(filepath=os.path.join(args[1].split(":", 1)[1], name + ".fbx"),
                                 object_types={"ARMATURE", "MESH"}, add_leaf_bones=False, bake_anim=True,
                                 bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
                                 bake_anim_simplify_factor=0.0)
elif args[0] == "bvh2fbx":
    for path in args[2:]:
        clear()
        bpy.ops.import_anim.bvh(filepath=path, global_scale=0.01, frame_start=1, use_fps_scale=False,
                                update_scene_fps=True, update_scene_duration=True)
        arm = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"][0]
        first, last = [int(round(f)) for f in arm.animation_data.action.frame_range]
        bpy.context.scene.frame_start, bpy.context.scene.frame_end = first, last
        name = os.path.basename(path).rsplit(".bvh", 1)[0]
        bpy.ops.export_scene.fbx(filepath=os.path.join(args[1], name + ".fbx"), object_types={"ARMATURE"},
                                 add_leaf_bones=True, bake_anim=True, bake_anim_use_all_actions=False,
                                 bake_anim_use_nla_strips=False, bake_anim_simplify_factor=0.0)
"#;

/// Runs the script in Blender (headless, factory settings).
fn blender(dir: &Path, args: &[&str]) {
    let script = dir.join("zoo_blender.py");
    std::fs::write(&script, SCRIPT).unwrap();
    let mut cmd = Command::new("blender");
    cmd.args(["-b", "--factory-startup", "--python-exit-code", "1", "--python"]).arg(&script).arg("--").args(args);
    let out = match cmd.output() {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => panic!("{INSTALL}"),
        Err(e) => panic!("cannot run blender: {e}"),
    };
    assert!(
        out.status.success(),
        "blender {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn synth(index: usize, seconds: f64) -> Clip {
    generate_clip(&SynthConfig { clip_seconds: seconds, ..Default::default() }, index).clip
}

/// Largest distance between the global joint positions of two clips of the same joints.
fn max_position_error(a: &Clip, b: &Clip) -> f64 {
    assert_eq!(a.skeleton.names, b.skeleton.names);
    assert_eq!(a.frames(), b.frames(), "frame counts");
    let (_, pa) = a.global();
    let (_, pb) = b.global();
    pa.iter().zip(&pb).map(|(x, y)| (*x - *y).length()).fold(0.0, f64::max)
}

#[test]
#[ignore = "needs Blender (apt-get install -y blender); .ci/run runs it"]
fn blender_imports_the_written_glb_at_the_same_joint_positions() {
    let dir = tempfile::tempdir().unwrap();
    let clip = synth(0, 2.0);
    let glb = dir.path().join("walk.glb");
    clip_io::write(&clip, &glb).unwrap();
    let json = dir.path().join("heads.json");
    blender(dir.path(), &["glb2json", glb.to_str().unwrap(), json.to_str().unwrap(), "30"]);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), clip.frames(), "Blender's action covers every frame");
    let (_, gp) = clip.global();
    let nj = clip.joints();
    let mut worst = 0.0f64;
    for (f, heads) in frames.iter().enumerate() {
        for (j, name) in clip.skeleton.names.iter().enumerate() {
            let h = heads[name].as_array().unwrap_or_else(|| panic!("no bone `{name}` in Blender"));
            let b: Vec<f64> = h.iter().map(|x| x.as_f64().unwrap()).collect();
            // Blender (x, y, z) metres, Z up = glTF (x, z, -y) = zoo / 100.
            let p = glam::DVec3::new(b[0], b[2], -b[1]) * 100.0;
            worst = worst.max((p - gp[f * nj + j]).length());
        }
    }
    println!("Blender glTF import of zoo's glb: largest joint position difference {worst:.2e} cm");
    assert!(worst < 0.1, "{worst} cm");
    // The stick figure follows the skeleton: each bone's double pyramid has its tips at the two
    // joints, so every joint but the root has a deformed mesh vertex on it.
    let blender_to_zoo = |b: &serde_json::Value| {
        let b: Vec<f64> = b.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
        glam::DVec3::new(b[0], b[2], -b[1]) * 100.0
    };
    let mut mesh_worst = 0.0f64;
    for (f, verts) in v["mesh"].as_object().unwrap() {
        let f: usize = f.parse().unwrap();
        let verts: Vec<glam::DVec3> = verts.as_array().unwrap().iter().map(blender_to_zoo).collect();
        for j in 1..nj {
            let p = gp[f * nj + j];
            let d = verts.iter().map(|v| (*v - p).length()).fold(f64::INFINITY, f64::min);
            mesh_worst = mesh_worst.max(d);
        }
    }
    println!("Blender's skinned stick figure: every joint within {mesh_worst:.2e} cm of a mesh vertex");
    assert!(mesh_worst < 0.1, "{mesh_worst} cm");
}

#[test]
#[ignore = "needs Blender (apt-get install -y blender); .ci/run runs it"]
fn a_glb_from_blenders_exporter_reads_back_to_the_same_positions() {
    // Another writer's glTF: Blender's bones have their own rest orientations and no zoo extras.
    let dir = tempfile::tempdir().unwrap();
    let clip = synth(2, 2.0);
    let (ours, theirs) = (dir.path().join("ours.glb"), dir.path().join("theirs.glb"));
    clip_io::write(&clip, &ours).unwrap();
    blender(dir.path(), &["glb2glb", ours.to_str().unwrap(), theirs.to_str().unwrap(), "30"]);
    let (back, source) = clip_io::read_with_source(&theirs, &ReadOptions::default()).unwrap();
    println!(
        "Blender's glb: take `{}`, notes {:?}, {} frames at {} fps",
        source.take,
        source.notes,
        back.frames(),
        back.fps()
    );
    assert_eq!(back.fps(), 30.0);
    let worst = max_position_error(&clip, &back);
    println!("Blender glTF export read back: largest joint position difference {worst:.2e} cm");
    assert!(worst < 0.1, "{worst} cm");
}

#[test]
#[ignore = "needs Blender (apt-get install -y blender); .ci/run runs it"]
fn an_fbx_from_blenders_exporter_reads_back_to_the_bvh_positions() {
    let dir = tempfile::tempdir().unwrap();
    let clip = synth(1, 2.0);
    let bvh = dir.path().join("walk.bvh");
    clip_io::write(&clip, &bvh).unwrap();
    blender(dir.path(), &["bvh2fbx", dir.path().to_str().unwrap(), bvh.to_str().unwrap()]);
    let (fbx, source) = clip_io::read_with_source(&dir.path().join("walk.fbx"), &ReadOptions::default()).unwrap();
    println!("Blender's FBX: {}, take `{}`, notes {:?}", source.describe(), source.take, source.notes);
    let worst = max_position_error(&clip_io::read(&bvh, &ReadOptions::default()).unwrap(), &fbx);
    println!("Blender FBX export read back: largest joint position difference {worst:.2e} cm");
    assert!(worst < 0.1, "{worst} cm");
}

/// Clips converted to FBX in `out` by Blender in one run: each written as zoo's glb, imported
/// with Blender's glTF importer (armature and skinned stick figure) and exported with its FBX
/// exporter (animation baked at every frame, with the bind pose of the mesh).
fn convert_to_fbx(work: &Path, clips: &[(String, Clip)], out: &Path) {
    std::fs::create_dir_all(out).unwrap();
    let glb_dir = work.join("glb");
    std::fs::create_dir_all(&glb_dir).unwrap();
    let fps = clips[0].1.fps().round() as usize;
    let mut args = vec!["glb2fbx".to_string(), format!("{fps}:{}", out.to_str().unwrap())];
    for (stem, clip) in clips {
        let glb = glb_dir.join(format!("{stem}.glb"));
        clip_io::write(clip, &glb).unwrap();
        args.push(glb.to_str().unwrap().to_string());
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    blender(work, &args);
}

/// The zero-velocity and interpolation figures of the benchmark on a folder.
fn baselines(
    data: &Path,
    valid_glob: &str,
) -> (usize, std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>>) {
    let clips = dataset::load_with(data, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}")).clips;
    let (train, test) = dataset::split(clips, valid_glob).unwrap();
    let bench = Benchmark::new(&train, &test).unwrap();
    let methods: [&dyn TransitionMethod; 2] = [&ZeroVelocity, &Interpolation];
    let r = bench.run(&methods, &[5, 15, 30, 45]).unwrap();
    (r.windows, r.methods)
}

/// Every figure of `b` within `tol` (relative) of `a`'s; the largest relative difference.
fn compare(
    a: &std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>>,
    b: &std::collections::BTreeMap<String, std::collections::BTreeMap<String, f64>>,
) -> f64 {
    let mut worst = 0.0f64;
    for (method, figures) in a {
        for (k, &x) in figures {
            if k.starts_with("ms_per") {
                continue;
            }
            let y = b[method][k];
            let rel = (x - y).abs() / x.abs().max(1e-12);
            println!("{method} {k}: BVH {x:.6} FBX {y:.6} (relative {rel:.1e})");
            worst = worst.max(rel);
        }
    }
    worst
}

#[test]
#[ignore = "needs Blender (apt-get install -y blender); .ci/run runs it"]
fn the_benchmark_on_blender_fbx_files_gives_the_bvh_figures() {
    let dir = tempfile::tempdir().unwrap();
    let bvh_dir = dir.path().join("bvh");
    std::fs::create_dir_all(&bvh_dir).unwrap();
    let cfg = SynthConfig { minutes: 2.0, seed: 7, ..Default::default() };
    let mut clips = Vec::new();
    for c in zoo_data::synth::generate(&cfg) {
        clip_io::write(&c.clip, &bvh_dir.join(format!("{}.bvh", c.name))).unwrap();
        clips.push((c.name, c.clip));
    }
    let fbx_dir = dir.path().join("fbx");
    convert_to_fbx(dir.path(), &clips, &fbx_dir);
    let mut worst = 0.0f64;
    for (stem, clip) in &clips {
        let fbx = clip_io::read(&fbx_dir.join(format!("{stem}.fbx")), &ReadOptions::default()).unwrap();
        worst = worst.max(max_position_error(clip, &fbx));
    }
    println!(
        "{} synthetic clips through Blender FBX (glb import): largest joint position difference {worst:.2e} cm",
        clips.len()
    );
    assert!(worst < 0.1, "{worst} cm");
    let (wa, a) = baselines(&bvh_dir, "*_0001*");
    let (wb, b) = baselines(&fbx_dir, "*_0001*");
    assert_eq!(wa, wb);
    let worst = compare(&a, &b);
    println!(
        "benchmark baselines on {} Blender FBX files vs the BVH: largest relative difference {worst:.1e}",
        clips.len()
    );
    assert!(worst < 1e-3, "{worst}");
}

fn bandai2() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bandai2");
    p.is_dir().then_some(p)
}

/// bandai2 clips (every 16th training clip and every 8th test clip) through Blender's glTF
/// importer and FBX exporter: the FBX clips read back within 0.1 cm and give the BVH's
/// benchmark figures.
#[test]
#[ignore = "needs Blender and ../shared/data/bandai2; .ci/run runs it when both are there"]
fn bandai2_through_blender_fbx_gives_the_bvh_figures() {
    let Some(root) = bandai2() else { panic!("../shared/data/bandai2 is missing") };
    let dir = tempfile::tempdir().unwrap();
    // ZOO_KEEP_FBX=DIR keeps the two folders there (for `zoo bench` on them, docs/formats.md).
    let keep = std::env::var_os("ZOO_KEEP_FBX").map(PathBuf::from);
    let base = keep.clone().unwrap_or_else(|| dir.path().to_path_buf());
    let all = dataset::find_clip_files(&root).unwrap();
    let (bvh_dir, fbx_dir) = (base.join("bvh"), base.join("fbx"));
    std::fs::create_dir_all(&bvh_dir).unwrap();
    let mut picked = Vec::new();
    let (mut train, mut test) = (0, 0);
    for f in &all {
        let name = f.file_name().unwrap().to_str().unwrap().to_string();
        let keep = if name.contains("_youthful_") {
            test += 1;
            test % 8 == 1
        } else {
            train += 1;
            train % 16 == 1
        };
        if keep {
            std::fs::copy(f, bvh_dir.join(&name)).unwrap();
            let stem = name.trim_end_matches(".bvh.gz").to_string();
            picked.push((stem, zoo_data::bvh::read_file(f, &Default::default()).unwrap()));
        }
    }
    convert_to_fbx(dir.path(), &picked, &fbx_dir);
    let mut worst = 0.0f64;
    for (stem, _) in &picked {
        let a = clip_io::read_model_clip(&bvh_dir.join(format!("{stem}.bvh.gz"))).unwrap();
        let b = clip_io::read_model_clip(&fbx_dir.join(format!("{stem}.fbx"))).unwrap();
        worst = worst.max(max_position_error(&a, &b));
    }
    println!("bandai2 ({} clips) through Blender FBX: largest joint position difference {worst:.2e} cm", picked.len());
    assert!(worst < 0.1, "{worst} cm");
    let (wa, a) = baselines(&bvh_dir, "*_youthful_*");
    let (wb, b) = baselines(&fbx_dir, "*_youthful_*");
    assert_eq!(wa, wb);
    let rel = compare(&a, &b);
    println!("bandai2 benchmark baselines on {wa} test windows, FBX vs BVH: largest relative difference {rel:.1e}");
    assert!(rel < 1e-3, "{rel}");
}
