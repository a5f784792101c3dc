//! End-to-end tests of the `zoo` command line on small generated datasets.

use std::process::Command;
use zoo_data::bvh;
use zoo_tests::{toy_clip, under_dummy_root, zoo_bin};

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

/// `--exclude-glob` (the out-of-distribution protocol, docs/ood.md): the excluded clips are
/// neither test nor statistics, and excluding everything is refused.
#[test]
fn bench_exclude_glob_leaves_clips_out_before_the_split() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let json = dir.path().join("out.json");
    let bench = |extra: &[&str]| {
        Command::new(zoo_bin())
            .args(["bench", "--data"])
            .arg(dir.path())
            .args(["--valid-glob", "*_youthful_*", "--lengths", "5", "--json"])
            .arg(&json)
            .args(extra)
            .output()
            .unwrap()
    };
    let out = bench(&["--exclude-glob", "*_active_*"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("--exclude-glob *_active_*: left out 1 of 4 clips"), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["windows"], 3);
    // Excluding the test clips leaves no test split.
    let out = bench(&["--exclude-glob", "*_youthful_*"]);
    assert!(!out.status.success());
    let out = bench(&["--exclude-glob", "toy_*"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("every one of the 4 clips matches; nothing is left"), "{stderr}");
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
    let clip = dir.path().join("toy_walk_normal_000.bvh");
    let transition = |kind: &str| {
        std::fs::write(run.join("config.json"), format!(r#"{{"model": "{kind}"}}"#)).unwrap();
        failure(
            Command::new(zoo_bin())
                .args(["transition", "--model"])
                .arg(&run)
                .arg("--from")
                .arg(format!("{}:20", clip.display()))
                .arg("--to")
                .arg(format!("{}:60", clip.display()))
                .arg("--out")
                .arg(dir.path().join("out.bvh")),
        )
    };
    let err = transition("nope");
    assert!(err.contains("unknown model kind `nope`: this zoo knows rtn, rmr"), "{err}");
    // A kind zoo knows, for another task: said what it is for.
    let err = transition("rmr");
    assert!(err.contains("holds a `rmr` model, which is for stitching"), "{err}");
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

/// Runs `zoo ARGS` expecting clap to refuse a value; returns standard error.
fn refused(args: &[&str]) -> String {
    let out = Command::new(zoo_bin()).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "`zoo {}` must be refused as a usage error: {err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Every numeric option of every subcommand refuses zero, negative, NaN, infinite and
/// out-of-range values when the arguments are parsed, naming the option and the valid range.
#[test]
fn every_numeric_option_refuses_bad_values_with_its_name_and_range() {
    let tr = ["transition", "--model", "m", "--from", "a.bvh:20", "--to", "b.bvh:40", "--out", "o.bvh"];
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        ([&tr[..], &["--frames", "0"]].concat(), "--frames <FRAMES>", "outside the valid range 1..=100000"),
        ([&tr[..], &["--frames", "-3"]].concat(), "--frames <FRAMES>", "not a whole number"),
        ([&tr[..], &["--frames", "200000"]].concat(), "--frames <FRAMES>", "outside the valid range 1..=100000"),
        (vec!["decompress", "--model", "m", "c.bvh", "--out", "o.bvh", "--interval", "0"], "--interval", "1..=100000"),
        (vec!["export", "--onnx", "m", "--out", "o.onnx", "--fps", "0"], "--fps <FPS>", "not a positive number"),
        (vec!["export", "--onnx", "m", "--out", "o.onnx", "--fps", "NaN"], "--fps <FPS>", "not a finite number"),
        (vec!["export", "--onnx", "m", "--out", "o.onnx", "--fps", "-30"], "--fps <FPS>", "not a positive number"),
        (vec!["render", "c.bvh", "--out", "o.gif", "--every", "0"], "--every <EVERY>", ">= 1"),
        (vec!["render", "c.bvh", "--out", "o.gif", "--side-by-side", "-75"], "--side-by-side", "not a positive"),
        (vec!["render", "c.bvh", "--out", "o.gif", "--side-by-side", "inf"], "--side-by-side", "not a finite"),
        (vec!["bench", "--data", "d", "--lengths", "5,0"], "--lengths <LENGTHS>", "1..=100000"),
        (vec!["bench", "--data", "d", "--tolerance", "-1"], "--tolerance <TOLERANCE>", "negative"),
        (vec!["bench", "--data", "d", "--tolerance", "NaN"], "--tolerance <TOLERANCE>", "not a finite"),
        (vec!["bench", "--data", "d", "--save-count", "0"], "--save-count <SAVE_COUNT>", ">= 1"),
        (vec!["bench", "runtime", "--model", "m.onnx", "--batch", "0"], "--batch <BATCH>", ">= 1"),
        (vec!["bench", "runtime", "--model", "m.onnx", "--rounds", "0"], "--rounds <ROUNDS>", ">= 1"),
        (vec!["bench", "runtime", "--model", "m.onnx", "--work", "0"], "--work <WORK>", ">= 1"),
        (vec!["train", "rtn", "--epochs", "0"], "--epochs <EPOCHS>", ">= 1"),
        (vec!["train", "rtn", "--time-limit", "0"], "--time-limit <TIME_LIMIT>", "not a positive"),
        (vec!["train", "rtn", "--time-limit", "NaN"], "--time-limit <TIME_LIMIT>", "not a finite"),
        (vec!["train", "rtn", "--batch-size", "0"], "--batch-size <BATCH_SIZE>", ">= 1"),
        (vec!["train", "rtn", "--lr", "0"], "--lr <LR>", "not a positive"),
        (vec!["train", "rtn", "--lr", "-1e-3"], "--lr <LR>", "not a positive"),
        (vec!["train", "rtn", "--lr", "inf"], "--lr <LR>", "not a finite"),
        (vec!["train", "rtn", "--synth-minutes", "0"], "--synth-minutes <SYNTH_MINUTES>", "not a positive"),
        (vec!["train", "rtn", "--synth-minutes", "NaN"], "--synth-minutes <SYNTH_MINUTES>", "not a finite"),
        (vec!["train", "rtn", "--ema", "1"], "--ema <EMA>", "not a decay in [0, 1)"),
        (vec!["train", "rtn", "--ema", "-0.5"], "--ema <EMA>", "not a decay in [0, 1)"),
        (vec!["train", "rtn", "--ema", "NaN"], "--ema <EMA>", "not a finite"),
        (vec!["data", "synth", "--out", "d", "--minutes", "0"], "--minutes <MINUTES>", "not a positive"),
        (vec!["data", "synth", "--out", "d", "--minutes", "inf"], "--minutes <MINUTES>", "not a finite"),
        (
            vec!["data", "synth", "--out", "d", "--clip-seconds", "-1"],
            "--clip-seconds <CLIP_SECONDS>",
            "not a positive",
        ),
        (vec!["data", "synth", "--out", "d", "--fps", "NaN"], "--fps <FPS>", "not a finite"),
    ];
    // Values each valid alone but too much together are refused before any work.
    let out = Command::new(zoo_bin()).args(["data", "synth", "--out", "d", "--clip-seconds", "1e-9"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--clip-seconds 0.000000001 at 30 fps is less than 2 frames"),
        "{err}"
    );
    let out = Command::new(zoo_bin()).args(["train", "rtn", "--synth-minutes", "1e6"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--synth-minutes 1000000 at 30 fps is 1800000000 frames"), "{err}");
    for (args, option, range) in cases {
        let err = refused(&args);
        assert!(err.contains(option) && err.contains(range), "`zoo {}`: {err}", args.join(" "));
    }
}

/// A reader that goes away (`zoo data stats DIR | head -0`) ends the command quietly.
#[test]
fn a_closed_stdout_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    for _ in 0..3 {
        let mut child = Command::new(zoo_bin())
            .args(["data", "stats"])
            .arg(dir.path())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success() && !err.contains("panicked") && !err.contains("Broken pipe"), "{err}");
    }
}

fn write_clip(clip: &zoo_motion::Clip, path: &std::path::Path) {
    bvh::write_file(clip, path).unwrap();
}

#[test]
fn stats_without_foot_joints_says_so_instead_of_panicking() {
    let dir = tempfile::tempdir().unwrap();
    let mut clip = toy_clip(60, 0.0);
    clip.skeleton.names[3] = "Ankle_L".into();
    write_clip(&clip, &dir.path().join("nofeet.bvh"));
    let json = dir.path().join("s.json");
    let out =
        Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()).arg("--json").arg(&json).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("foot skate            not measured: no joint name contains `foot` or `toe`"), "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["foot_skate"].is_null() && v["foot_joints"].as_array().unwrap().is_empty(), "{v}");
}

#[test]
fn stats_of_a_clip_with_zero_frames_reports_instead_of_panicking() {
    let dir = tempfile::tempdir().unwrap();
    write_clip(&toy_clip(0, 0.0), &dir.path().join("empty.bvh"));
    let out = Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("frames     0") && stdout.contains("root speed            not measured"), "{stdout}");
    assert!(stdout.contains("foot skate            not measured: no clip has two frames"), "{stdout}");
}

#[test]
fn bench_without_foot_joints_reports_no_skate_instead_of_zero() {
    let dir = tempfile::tempdir().unwrap();
    for (i, style) in ["normal", "normal", "youthful"].iter().enumerate() {
        let mut clip = toy_clip(140 + 10 * i, i as f64 * 0.7);
        clip.skeleton.names[3] = "Ankle_L".into();
        write_clip(&clip, &dir.path().join(format!("toy_walk_{style}_{i:03}.bvh")));
    }
    let json = dir.path().join("b.json");
    let out = Command::new(zoo_bin())
        .args(["bench", "--data"])
        .arg(dir.path())
        .args(["--valid-glob", "*_youthful_*", "--lengths", "5", "--json"])
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("Foot skate (cm/frame): not measured: no joint name contains `foot` or `toe`"), "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["methods"]["interp"].get("skate@5").is_none() && v["gt"].get("skate@5").is_none(), "{v}");
}

#[test]
fn a_bvh_with_more_frame_rows_than_declared_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let text = bvh::to_string(&toy_clip(20, 0.0)).replace("Frames: 20", "Frames: 18");
    std::fs::write(dir.path().join("long.bvh"), text).unwrap();
    let err = failure(Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()));
    assert!(err.contains("long.bvh:") && err.contains("2 more frame row(s) than the 18 declared"), "{err}");
}

#[test]
fn a_dataset_clip_with_the_same_joint_count_but_another_hierarchy_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let mut clip = toy_clip(140, 0.3);
    clip.skeleton.parents[2] = Some(1); // the leg hangs from the spine
    write_clip(&clip, &dir.path().join("toy_walk_normal_999.bvh"));
    let err = failure(Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()));
    assert!(
        err.contains("toy_walk_normal_999.bvh: skeleton differs") && err.contains("joint `Leg`: parent differs"),
        "{err}"
    );
}

#[test]
fn a_dataset_with_two_frame_rates_is_refused_and_skip_invalid_lists_the_clip() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let mut clip = toy_clip(140, 0.3);
    clip.frame_time = 1.0 / 60.0;
    write_clip(&clip, &dir.path().join("toy_walk_normal_060fps.bvh"));
    let err = failure(Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()));
    assert!(err.contains("toy_walk_normal_060fps.bvh: 60 fps but") && err.contains("30 fps"), "{err}");
    assert!(err.contains("--skip-invalid"), "{err}");
    let out = Command::new(zoo_bin()).args(["data", "stats", "--skip-invalid"]).arg(dir.path()).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("--skip-invalid: skipped 1 of 5 clips") && stderr.contains("60 fps but"), "{stderr}");
    assert!(stdout.contains("clips      4"), "{stdout}");
}

#[test]
fn skip_invalid_leaves_out_unreadable_and_foreign_clips_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    std::fs::write(dir.path().join("broken.bvh"), "HIERARCHY\nROOT Hips\n{").unwrap();
    let mut clip = toy_clip(140, 0.3);
    clip.skeleton.names[1] = "Chest".into();
    write_clip(&clip, &dir.path().join("other_rig.bvh"));
    let out = Command::new(zoo_bin()).args(["data", "stats", "--skip-invalid"]).arg(dir.path()).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("skipped 2 of 6 clips"), "{stderr}");
    assert!(stderr.contains("broken.bvh:") && stderr.contains("other_rig.bvh: skeleton differs"), "{stderr}");
    assert!(stdout.contains("clips      4"), "{stdout}");
}

#[test]
fn a_dummy_root_that_carries_motion_is_folded_not_a_different_skeleton() {
    let dir = tempfile::tempdir().unwrap();
    for i in 0..3 {
        std::fs::write(dir.path().join(format!("still_{i}.bvh")), under_dummy_root(&toy_clip(60, i as f64), false))
            .unwrap();
    }
    std::fs::write(dir.path().join("moving.bvh"), under_dummy_root(&toy_clip(60, 0.5), true)).unwrap();
    let out = Command::new(zoo_bin()).args(["data", "stats"]).arg(dir.path()).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("moving.bvh: its dummy root `joint_Root` carries motion; folded into `Hips`"), "{stderr}");
    assert!(stdout.contains("clips      4") && stdout.contains("joints     4"), "{stdout}");
}

/// Output files and folders are checked before the long work: the error is about the output,
/// not about the (missing) inputs that would have been read first.
#[test]
fn unwritable_outputs_are_refused_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no/such/folder");
    let out_in_missing = missing.join("out.bvh");
    let err = failure(
        Command::new(zoo_bin())
            .args(["transition", "--model", "none", "--from", "a.bvh:20", "--to", "b.bvh:40", "--out"])
            .arg(&out_in_missing),
    );
    assert!(err.contains("--out") && err.contains("does not exist (create it first)"), "{err}");
    let err =
        failure(Command::new(zoo_bin()).args(["decompress", "--model", "none", "a.bvh", "--out"]).arg(dir.path()));
    assert!(err.contains("is a folder; give a file name"), "{err}");
    let err = failure(Command::new(zoo_bin()).args(["export", "--onnx", "none", "--out"]).arg(missing.join("m.onnx")));
    assert!(err.contains("--out") && err.contains("does not exist"), "{err}");
    let err = failure(Command::new(zoo_bin()).args(["bench", "--data", "none", "--json"]).arg(missing.join("b.json")));
    assert!(err.contains("--json") && err.contains("does not exist"), "{err}");
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let err = failure(Command::new(zoo_bin()).args(["train", "rtn", "--data", "none", "--out"]).arg(&file));
    assert!(err.contains("--out") && err.contains("is a file, not a folder"), "{err}");
    let err = failure(Command::new(zoo_bin()).args(["data", "stats", "none", "--json"]).arg(missing.join("s.json")));
    assert!(err.contains("--json") && err.contains("does not exist"), "{err}");
}

#[test]
fn commands_that_take_an_exported_file_refuse_another_task_with_the_command_to_use() {
    let dir = tempfile::tempdir().unwrap();
    toy_dataset(dir.path());
    let files = [
        ("rtn.onnx", zoo_tests::tiny_rtn_onnx()),
        ("arnn.onnx", zoo_tests::tiny_arnn_onnx()),
        ("rmr.onnx", zoo_tests::tiny_rmr_onnx()),
    ];
    for (name, model) in &files {
        model.write(&dir.path().join(name)).unwrap();
    }
    let path = |name: &str| dir.path().join(name);
    // An ARNN in the in-betweening benchmark's `onnx:` method.
    let err = failure(Command::new(zoo_bin()).args(["bench", "--data"]).arg(dir.path()).args([
        "--valid-glob",
        "*_youthful_*",
        "--methods",
        &format!("onnx:{}", path("arnn.onnx").display()),
    ]));
    assert!(
        err.contains("is a `keyframes` model (kind `arnn`)") && err.contains("`zoo bench keyframes --model FILE`"),
        "{err}"
    );
    // An RMR in `zoo bench runtime`, an RTN in `zoo bench keyframes`.
    let err = failure(Command::new(zoo_bin()).args(["bench", "runtime", "--model"]).arg(path("rmr.onnx")));
    assert!(err.contains("is a `stitch` model (kind `rmr`)") && err.contains("`zoo stitch --model FILE`"), "{err}");
    let err = failure(Command::new(zoo_bin()).args(["bench", "keyframes", "--model"]).arg(path("rtn.onnx")));
    assert!(
        err.contains("is a `transition` model (kind `rtn`)") && err.contains("`zoo bench runtime --model FILE`"),
        "{err}"
    );
}
