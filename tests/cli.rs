//! End-to-end tests of the `zoo` command line on small generated datasets.

use std::process::Command;
use zoo_data::bvh;
use zoo_tests::{toy_clip, zoo_bin};

fn toy_dataset(dir: &std::path::Path) {
    for (i, style) in ["normal", "normal", "youthful", "active"].iter().enumerate() {
        let clip = toy_clip(140 + 10 * i, i as f64 * 0.7);
        bvh::write_file(&clip, &dir.join(format!("toy_walk_{style}_{i:03}.bvh"))).unwrap();
    }
}

/// Runs a `zoo` command that must fail and returns its standard error.
fn failure(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(!out.status.success(), "expected a failure, got: {}", String::from_utf8_lossy(&out.stdout));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bench_prints_table_and_writes_json() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let json = dir.path().join("out.json");
    let out = Command::new(zoo_bin())
        .args(["bench", "--data"])
        .arg(dir.path())
        .args(["--valid-glob", "*_youthful_*", "--lengths", "5,30", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("L2Q") && stdout.contains("NPSS") && stdout.contains("interp"), "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // youthful clip: 160 frames -> windows start at 0, 40, 80 (80 + 65 < 160), 120 is out.
    assert_eq!(v["windows"], 3);
    for m in ["zerovel", "interp"] {
        for k in ["l2q", "l2p", "npss", "aco", "skate", "ms_per_transition"] {
            for n in [5, 30] {
                assert!(v["methods"][m][format!("{k}@{n}")].is_number(), "{m} {k}@{n}");
            }
        }
    }
    assert!(v["gt"]["skate@30"].is_number());
    // Interpolation beats zero velocity on this smooth motion.
    assert!(v["methods"]["interp"]["l2p@30"].as_f64() < v["methods"]["zerovel"]["l2p@30"].as_f64());
}

#[test]
fn bench_rejects_a_glob_matching_nothing() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let err =
        failure(Command::new(zoo_bin()).args(["bench", "--data"]).arg(dir.path()).args(["--valid-glob", "*subject5*"]));
    assert!(err.contains("no clip file name matches --valid-glob `*subject5*`"), "{err}");
}

#[test]
fn stats_reads_a_folder_and_writes_json() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let json = dir.path().join("stats.json");
    let out =
        Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()).arg("--json").arg(&json).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["clips"], 4);
    assert_eq!(v["frames"], 140 + 150 + 160 + 170);
    assert_eq!(v["joints"], 4);
    assert_eq!(v["foot_joints"][0], "Foot_L");
    // root moves 100 units/s along x plus a slow z sway
    let median = v["root_speed"]["p50"].as_f64().unwrap();
    assert!((95.0..115.0).contains(&median), "{median}");
}

#[test]
fn malformed_bvh_error_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let bad = dir.path().join("broken_walk_normal_009.bvh");
    let good = std::fs::read_to_string(dir.path().join("toy_walk_normal_000.bvh")).unwrap();
    // Cut the last value of the first frame row.
    let mut lines: Vec<String> = good.lines().map(str::to_string).collect();
    let row = lines.iter().position(|l| l.starts_with("Frame Time")).unwrap() + 1;
    let mut vals: Vec<&str> = lines[row].split_whitespace().collect();
    vals.pop();
    lines[row] = vals.join(" ");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let err = failure(Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()));
    assert!(err.contains("broken_walk_normal_009.bvh") && err.contains(&format!(":{}:", row + 1)), "{err}");
}

#[test]
fn stats_glob_selects_clips_and_reports_rigid_bones() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let json = dir.path().join("stats.json");
    let out = Command::new(zoo_bin())
        .args(["data", "stats"])
        .arg(dir.path())
        .args(["--glob", "*_youthful_*", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["clips"], 1);
    assert_eq!(v["frames"], 160);
    // BVH text keeps 6 decimals: bone lengths stay constant to well under a micrometre-scale unit.
    assert!(v["max_bone_length_change"].as_f64().unwrap() < 1e-4);
    let none =
        Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()).args(["--glob", "*nothing*"]).output().unwrap();
    assert!(!none.status.success());
    assert!(String::from_utf8_lossy(&none.stderr).contains("matches `*nothing*`"));
}

#[test]
fn bench_lists_the_known_methods_for_an_unknown_one() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let err = failure(Command::new(zoo_bin()).args(["bench", "--data"]).arg(dir.path()).args([
        "--valid-glob",
        "*_youthful_*",
        "--methods",
        "interp,nearest",
    ]));
    assert!(err.contains("unknown method `nearest`") && err.contains("rtn+lock:RUN_DIR"), "{err}");
}

#[test]
fn bench_refuses_a_run_folder_of_another_model() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let run = dir.path().join("run");
    std::fs::create_dir(&run).unwrap();
    std::fs::write(run.join("config.json"), r#"{"model": "arnn"}"#).unwrap();
    let err = failure(
        Command::new(zoo_bin())
            .args(["bench", "--data"])
            .arg(dir.path())
            .args(["--valid-glob", "*_youthful_*", "--methods"])
            .arg(format!("rtn:{}", run.display())),
    );
    assert!(err.contains("names model `arnn`, not `rtn`"), "{err}");
}

#[test]
fn transition_refuses_an_unknown_model_kind_and_lists_the_known_ones() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let run = dir.path().join("run");
    std::fs::create_dir(&run).unwrap();
    std::fs::write(run.join("config.json"), r#"{"model": "rmr"}"#).unwrap();
    let clip = dir.path().join("toy_walk_normal_000.bvh");
    let err = failure(
        Command::new(zoo_bin())
            .args(["transition", "--model"])
            .arg(&run)
            .arg("--from")
            .arg(format!("{}:20", clip.display()))
            .arg("--to")
            .arg(format!("{}:60", clip.display()))
            .arg("--out")
            .arg(dir.path().join("out.bvh")),
    );
    assert!(err.contains("unknown model kind `rmr`: this zoo knows rtn"), "{err}");
}

#[test]
fn transition_refuses_a_source_frame_without_context() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let clip = dir.path().join("toy_walk_normal_000.bvh");
    let err = failure(
        Command::new(zoo_bin())
            .args(["transition", "--model"])
            .arg(dir.path().join("no-run"))
            .arg("--from")
            .arg(format!("{}:3", clip.display()))
            .arg("--to")
            .arg(format!("{}:60", clip.display()))
            .arg("--out")
            .arg(dir.path().join("out.bvh")),
    );
    assert!(err.contains("source frame 3: needs 10 context frames"), "{err}");
}
