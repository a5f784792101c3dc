//! The keys-only benchmark's Bezier baseline (`zoo_bench::fcurve`) against Blender itself
//! (Debian's package, Blender 3.4), headless: the keys of one clip go into F-curves made with
//! Blender's factory settings (`keyframe_points.insert`, as keys inserted in the interface get
//! them), Blender evaluates every frame, and the poses it gives must match ours within
//! 0.01 cm at every joint of every frame (issue 46).
//!
//! Ignored by default (a machine without Blender still passes the suite); `.ci/run` installs
//! Blender and runs it with `cargo test -p zoo-bench --test blender_bezier -- --ignored`.

use glam::{DQuat, DVec3};
use std::path::Path;
use std::process::Command;
use zoo_bench::keys::{self, KeyTask};
use zoo_data::synth::{SynthConfig, generate_clip};
use zoo_motion::Clip;

/// The Blender side: `IN.json OUT.json`. Each curve of IN (`{"keys": [[frame, value], ...]}`)
/// becomes an F-curve of one action with Blender's default key insertion; OUT holds every
/// curve evaluated at frames `0..frames`, and the settings the keys got.
const SCRIPT: &str = r#"
import bpy, json, sys
src, dst = sys.argv[sys.argv.index("--") + 1:]
job = json.load(open(src))
action = bpy.data.actions.new("keys")
values, settings = [], None
for i, curve in enumerate(job["curves"]):
    fc = action.fcurves.new('["c%d"]' % i, index=0)
    for f, v in curve["keys"]:
        fc.keyframe_points.insert(f, v)
    k = fc.keyframe_points[0]
    settings = [k.interpolation, k.handle_left_type, k.handle_right_type, fc.auto_smoothing, fc.extrapolation]
    values.append([fc.evaluate(f) for f in range(job["frames"])])
json.dump({"values": values, "settings": settings, "version": bpy.app.version_string}, open(dst, "w"))
"#;

/// The curves of a task, in our order: root x, y, z, then each joint's three Euler channels.
fn curves(task: &KeyTask<'_>) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> =
        (0..3).map(|c| task.frames.iter().zip(&task.root).map(|(&f, r)| (f as f64, r[c])).collect()).collect();
    for jj in 0..task.skeleton.len() {
        let e = keys::euler_keys(task, jj);
        out.extend((0..3).map(|c| e.iter().map(|(f, v)| (*f, v[c])).collect()));
    }
    out
}

/// Global joint positions of every frame of a motion on `clip`'s skeleton.
fn positions(clip: &Clip, root: &[DVec3], rot: &[DQuat]) -> Vec<DVec3> {
    let j = clip.joints();
    let mut c = Clip {
        skeleton: clip.skeleton.clone(),
        frame_time: clip.frame_time,
        local_rotations: rot.to_vec(),
        local_positions: Vec::new(),
    };
    for r in root {
        c.local_positions.push(*r);
        c.local_positions.extend_from_slice(&clip.skeleton.offsets[1..j]);
    }
    c.global().1
}

/// Keys every `every` frames of `clip`'s first `frames` frames through Blender and through
/// `zoo_bench::keys::bezier`: the largest position difference (clip units) and channel
/// difference (cm or degrees).
fn compare(clip: &Clip, every: usize, frames: usize, dir: &Path) -> (f64, f64) {
    let j = clip.joints();
    let key_frames: Vec<usize> = (0..frames).step_by(every).collect();
    let task = KeyTask {
        skeleton: &clip.skeleton,
        root: key_frames.iter().map(|&f| clip.local_positions[f * j]).collect(),
        rot: key_frames.iter().flat_map(|&f| clip.local_rotations[f * j..(f + 1) * j].iter().copied()).collect(),
        fixed: vec![vec![true; 1 + j]; key_frames.len()],
        frames: key_frames,
    };
    let ours = keys::bezier(&task).unwrap();
    let n = task.len();
    let job = serde_json::json!({"frames": n, "curves": curves(&task).iter().map(|k| serde_json::json!({"keys": k})).collect::<Vec<_>>()});
    let (src, dst, script) = (dir.join("keys.json"), dir.join("values.json"), dir.join("fcurves.py"));
    std::fs::write(&src, job.to_string()).unwrap();
    std::fs::write(&script, SCRIPT).unwrap();
    let out = match Command::new("blender")
        .args(["-b", "--factory-startup", "--python-exit-code", "1", "--python"])
        .arg(&script)
        .arg("--")
        .arg(&src)
        .arg(&dst)
        .output()
    {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            panic!("Blender is not installed: apt-get install -y blender (Debian's package; .ci/run installs it)")
        }
        Err(e) => panic!("cannot run blender: {e}"),
    };
    assert!(out.status.success(), "blender failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let got: serde_json::Value = serde_json::from_slice(&std::fs::read(&dst).unwrap()).unwrap();
    // The curve we implement: Blender's defaults for inserted keys.
    let settings: Vec<String> = serde_json::from_value(got["settings"].clone()).unwrap();
    assert_eq!(
        settings,
        ["BEZIER", "AUTO_CLAMPED", "AUTO_CLAMPED", "CONT_ACCEL", "CONSTANT"],
        "Blender {}",
        got["version"]
    );
    let values: Vec<Vec<f64>> = serde_json::from_value(got["values"].clone()).unwrap();
    let root: Vec<DVec3> = (0..n).map(|f| DVec3::new(values[0][f], values[1][f], values[2][f])).collect();
    let rot: Vec<DQuat> = (0..n)
        .flat_map(|f| {
            let v = &values;
            (0..j).map(move |jj| {
                let e = [0, 1, 2].map(|c| v[3 + 3 * jj + c][f]);
                clip.skeleton.channels[jj].order.to_quat_deg(e)
            })
        })
        .collect();
    // Our channels, evaluated the same way, for the channel difference.
    let mut channel = 0.0f64;
    for (c, k) in curves(&task).iter().enumerate() {
        let fc = zoo_bench::fcurve::FCurve::auto_clamped(k).unwrap();
        for f in 0..n {
            channel = channel.max((fc.eval(f as f64) - values[c][f]).abs());
        }
    }
    let (a, b) = (positions(clip, &ours.root, &ours.rot), positions(clip, &root, &rot));
    let pos = a.iter().zip(&b).map(|(p, q)| (*p - *q).length()).fold(0.0f64, f64::max);
    (pos, channel)
}

#[test]
#[ignore = "needs Blender (apt-get install -y blender); .ci/run runs it"]
fn bezier_in_betweens_match_blenders_fcurves() {
    let dir = tempfile::tempdir().unwrap();
    // The synthetic biped (cm), keys every 10 frames over 61 frames.
    let clip = generate_clip(&SynthConfig { clip_seconds: 3.0, ..Default::default() }, 3).clip;
    let (pos, channel) = compare(&clip, 10, 61, dir.path());
    eprintln!("synthetic clip, keys every 10: largest joint position difference {pos:.2e} cm, channel {channel:.2e}");
    assert!(pos < 0.01, "Bezier in-betweens differ from Blender's by {pos} cm");
    // A bandai2 clip (held-out style), keys every 15 frames, where the data is.
    let b2 =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bandai2/dataset-2_walk_youthful_001.bvh.gz");
    if b2.exists() {
        let clip = zoo_data::clip_io::read_model_clip(&b2).unwrap();
        let (pos, channel) = compare(&clip, 15, 121, dir.path());
        eprintln!("{}: keys every 15: largest difference {pos:.2e} cm, channel {channel:.2e}", b2.display());
        assert!(pos < 0.01, "Bezier in-betweens differ from Blender's by {pos} cm on {}", b2.display());
    } else {
        eprintln!("{} not found: the bandai2 clip is not compared", b2.display());
    }
}
