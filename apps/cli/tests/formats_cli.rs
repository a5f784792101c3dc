//! The CLI on glTF and FBX clips and on another rig (issue 44): `zoo transition` with a
//! joint-name map on a renamed, 1.1x larger rig against the plain run, glb in and out, mixed
//! datasets in `zoo data stats`, and bad files refused with their name.
//!
//! They live beside the CLI (not in `tests/`) because they need only the `zoo` binary and
//! zoo-data.

use std::path::{Path, PathBuf};
use std::process::Command;
use zoo_data::clip_io::{self, ReadOptions};
use zoo_motion::Clip;

fn zoo(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_zoo")).args(args).output().expect("run zoo");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A tiny RTN trained on 2 synthetic minutes, and a folder of synthetic clips it did not see.
fn setup(dir: &Path) -> (PathBuf, PathBuf) {
    let (run, data) = (dir.join("rtn"), dir.join("synth"));
    let (ok, _, err) =
        zoo(&["train", "rtn", "--preset", "tiny", "--synth-minutes", "2", "--epochs", "2", "--out", s(&run)]);
    assert!(ok, "{err}");
    let (ok, _, err) = zoo(&["data", "synth", "--out", s(&data), "--minutes", "1", "--seed", "3"]);
    assert!(ok, "{err}");
    (run, data)
}

fn read(p: &Path) -> Clip {
    clip_io::read(p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// The clip on a rig whose joints carry `prefix` and whose bones and root motion are `scale`
/// times larger.
fn renamed_and_scaled(clip: &Clip, prefix: &str, scale: f64) -> Clip {
    let mut c = clip.clone();
    c.skeleton.names = c.skeleton.names.iter().map(|n| format!("{prefix}{n}")).collect();
    c.skeleton.offsets.iter_mut().for_each(|o| *o *= scale);
    c.skeleton.end_sites.iter_mut().flatten().for_each(|o| *o *= scale);
    c.local_positions.iter_mut().for_each(|p| *p *= scale);
    c
}

#[test]
fn transition_on_a_renamed_scaled_rig_matches_the_plain_run() {
    let dir = tempfile::tempdir().unwrap();
    let (run, data) = setup(dir.path());
    let (a, b) = (data.join("synth_walk_0002.bvh"), data.join("synth_run_0001.bvh"));
    let plain = dir.path().join("plain.bvh");
    let (ok, _, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:60", s(&a)),
        "--to",
        &format!("{}:40", s(&b)),
        "--out",
        s(&plain),
    ]);
    assert!(ok, "{err}");
    // The same clips on a Mixamo-style rig 1.1x larger, as glb.
    let (ra, rb) = (dir.path().join("a_rig.glb"), dir.path().join("b_rig.glb"));
    clip_io::write(&renamed_and_scaled(&read(&a), "mixamorig:", 1.1), &ra).unwrap();
    clip_io::write(&renamed_and_scaled(&read(&b), "mixamorig:", 1.1), &rb).unwrap();
    let map = dir.path().join("map.json");
    std::fs::write(&map, "{}").unwrap();
    let mapped = dir.path().join("mapped.glb");
    let (ok, stdout, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:60", s(&ra)),
        "--to",
        &format!("{}:40", s(&rb)),
        "--rig-map",
        s(&map),
        "--out",
        s(&mapped),
    ]);
    assert!(ok, "{err}");
    assert!(
        stdout.contains("--rig-map: 21 joints mapped onto the model's skeleton, root translation x0.9091"),
        "{stdout}"
    );
    let (p, m) = (clip_io::read_model_clip(&plain).unwrap(), clip_io::read_model_clip(&mapped).unwrap());
    assert!(m.skeleton.names.iter().all(|n| n.starts_with("mixamorig:")), "written back on the clip's rig");
    assert_eq!(p.frames(), m.frames());
    let (_, pp) = p.global();
    let (_, pm) = m.global();
    let worst = pp.iter().zip(&pm).map(|(x, y)| (*x - *y / 1.1).length()).fold(0.0, f64::max);
    println!("renamed 1.1x rig through zoo transition --rig-map: largest joint position difference {worst:.2e} cm");
    assert!(worst < 1.0, "{worst} cm");
    // Without the map the renamed rig runs on its joint count and hierarchy alone, with a note.
    let (ok, _, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:60", s(&ra)),
        "--to",
        &format!("{}:40", s(&rb)),
        "--out",
        s(&dir.path().join("unmapped.bvh")),
    ]);
    assert!(ok && err.contains("joint names differ from the model's") && err.contains("--rig-map"), "{err}");
    // A rig missing the feet: the list of what is missing.
    let mut footless = renamed_and_scaled(&read(&a), "mixamorig:", 1.1);
    for n in footless.skeleton.names.iter_mut().filter(|n| n.to_lowercase().contains("foot")) {
        *n = n.replace("Foot", "Stump").replace("foot", "stump");
    }
    let fl = dir.path().join("footless.glb");
    clip_io::write(&footless, &fl).unwrap();
    let (ok, _, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:60", s(&fl)),
        "--to",
        &format!("{}:40", s(&rb)),
        "--rig-map",
        s(&map),
        "--out",
        s(&dir.path().join("footless_out.glb")),
    ]);
    assert!(!ok && err.contains("the rig lacks") && err.contains("the model needs") && err.contains("Foot"), "{err}");
}

#[test]
fn decompress_writes_glb_and_data_stats_reads_a_mixed_folder() {
    let dir = tempfile::tempdir().unwrap();
    let (run, data) = setup(dir.path());
    let clip = data.join("synth_walk_0003.bvh");
    let (glb, bvh) = (dir.path().join("rebuilt.glb"), dir.path().join("rebuilt.bvh"));
    for out in [&glb, &bvh] {
        let (ok, _, err) = zoo(&["decompress", "--model", s(&run), s(&clip), "--out", s(out)]);
        assert!(ok, "{err}");
    }
    assert!(std::fs::read(&glb).unwrap().starts_with(b"glTF"));
    let (g, b) = (read(&glb), read(&bvh));
    assert!(g.frames() > 0 && g.frames() == b.frames());
    let (_, pg) = g.global();
    let (_, pb) = b.global();
    let worst = pg.iter().zip(&pb).map(|(x, y)| (*x - *y).length()).fold(0.0, f64::max);
    assert!(worst < 1e-3, "the .glb and .bvh outputs differ by {worst} cm");
    // Two clips as glb beside the BVH originals of the others.
    for name in ["synth_run_0004", "synth_walk_0005"] {
        let bvh = data.join(format!("{name}.bvh"));
        clip_io::write(&read(&bvh), &data.join(format!("{name}.glb"))).unwrap();
        std::fs::remove_file(bvh).unwrap();
    }
    let (ok, stdout, err) = zoo(&["data", "stats", s(&data)]);
    assert!(ok, "{err}");
    assert!(stdout.contains("clips      6"), "{stdout}");
    assert!(err.contains("2 clip(s) read from glTF, metres, Y up, right-handed"), "{err}");
}

#[test]
fn bad_clip_files_are_refused_with_their_name() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = zoo_data::gltf::to_glb(&zoo_data::synth::generate_clip(&Default::default(), 0).clip);
    let cut = dir.path().join("cut.glb");
    std::fs::write(&cut, &bytes[..bytes.len() / 3]).unwrap();
    let (ok, _, err) = zoo(&["data", "stats", s(&cut)]);
    assert!(!ok && err.contains("cut.glb: glTF: truncated .glb") && !err.contains("panicked"), "{err}");
    let fbx = dir.path().join("empty.fbx");
    std::fs::write(&fbx, b"").unwrap();
    let (ok, _, err) = zoo(&["data", "stats", s(&fbx)]);
    assert!(!ok && err.contains("empty.fbx: FBX: empty file"), "{err}");
}

/// Issue 44's rig acceptance on real data: two bandai2 clips on a renamed (`mixamorig:`) rig
/// 1.1x larger, as glb, through `zoo transition --rig-map` with a bandai2-trained RTN, against
/// the plain run. The model: `ZOO_BANDAI2_RTN=RUN_DIR` (e.g. a `zoo train rtn --data bandai2`
/// run), else a tiny one trained here for one epoch (the comparison needs no good model).
#[test]
#[ignore = "needs ../shared/data/bandai2 (CI runs it with --ignored when present)"]
fn bandai2_transition_on_a_renamed_scaled_rig_matches_the_plain_run() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/bandai2");
    assert!(data.is_dir(), "../shared/data/bandai2 is missing");
    let dir = tempfile::tempdir().unwrap();
    let run = match std::env::var_os("ZOO_BANDAI2_RTN") {
        Some(r) => PathBuf::from(r),
        None => {
            let run = dir.path().join("rtn");
            let (ok, _, err) = zoo(&[
                "train",
                "rtn",
                "--preset",
                "tiny",
                "--data",
                s(&data),
                "--valid-glob",
                "*_youthful_*",
                "--epochs",
                "1",
                "--out",
                s(&run),
            ]);
            assert!(ok, "{err}");
            run
        }
    };
    let (a, b) = (data.join("dataset-2_walk_youthful_010.bvh.gz"), data.join("dataset-2_run_youthful_001.bvh.gz"));
    let plain = dir.path().join("plain.bvh");
    let (ok, _, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:40", s(&a)),
        "--to",
        &format!("{}:30", s(&b)),
        "--out",
        s(&plain),
    ]);
    assert!(ok, "{err}");
    let (ra, rb) = (dir.path().join("a_rig.glb"), dir.path().join("b_rig.glb"));
    let raw = |p: &Path| zoo_data::bvh::read_file(p, &Default::default()).unwrap();
    clip_io::write(&renamed_and_scaled(&raw(&a), "mixamorig:", 1.1), &ra).unwrap();
    clip_io::write(&renamed_and_scaled(&raw(&b), "mixamorig:", 1.1), &rb).unwrap();
    let map = dir.path().join("map.json");
    std::fs::write(&map, "{}").unwrap();
    let mapped = dir.path().join("mapped.glb");
    let (ok, stdout, err) = zoo(&[
        "transition",
        "--model",
        s(&run),
        "--from",
        &format!("{}:40", s(&ra)),
        "--to",
        &format!("{}:30", s(&rb)),
        "--rig-map",
        s(&map),
        "--out",
        s(&mapped),
    ]);
    assert!(ok, "{err}");
    println!("{stdout}");
    let (p, m) = (clip_io::read_model_clip(&plain).unwrap(), clip_io::read_model_clip(&mapped).unwrap());
    assert!(m.skeleton.names.iter().all(|n| n.starts_with("mixamorig:")));
    let (_, pp) = p.global();
    let (_, pm) = m.global();
    let worst = pp.iter().zip(&pm).map(|(x, y)| (*x - *y / 1.1).length()).fold(0.0, f64::max);
    println!(
        "bandai2, renamed 1.1x rig through zoo transition --rig-map ({}): largest joint position difference {worst:.2e} cm \
         over {} frames",
        run.display(),
        p.frames()
    );
    assert!(worst < 1.0, "{worst} cm");
}

#[test]
fn data_convert_round_trips_a_clip_through_glb_and_refuses_fbx_out() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let (ok, _, err) = zoo(&["data", "synth", "--out", s(&data), "--minutes", "1", "--seed", "4"]);
    assert!(ok, "{err}");
    let bvh = data.join("synth_walk_0002.bvh");
    let (glb, back) = (dir.path().join("walk.glb"), dir.path().join("back.bvh"));
    let (ok, out, err) = zoo(&["data", "convert", s(&bvh), s(&glb)]);
    assert!(ok && out.contains("wrote"), "{out}\n{err}");
    let (ok, _, err) = zoo(&["data", "convert", s(&glb), s(&back)]);
    assert!(ok, "{err}");
    let (a, b) = (read(&bvh).global().1, read(&back).global().1);
    assert_eq!(a.len(), b.len());
    let worst = a.iter().zip(&b).map(|(p, q)| p.distance(*q)).fold(0.0, f64::max);
    assert!(worst < 0.01, "BVH -> glb -> BVH moved a joint by {worst} cm");
    let (ok, _, err) = zoo(&["data", "convert", s(&bvh), s(&dir.path().join("walk.fbx"))]);
    assert!(!ok && err.contains("must be .bvh, .bvh.gz, .glb or .gltf"), "{err}");
    // `zoo generate` streams BVH: a glTF output is refused before any work, with the way round.
    let (ok, _, err) = zoo(&["generate", "--model", s(dir.path()), "--frames", "10", "--out", s(&glb)]);
    assert!(!ok && err.contains("zoo data convert"), "{err}");
}
