//! Bad values of every numeric option of every subcommand, and the benchmark's skeleton check
//! of exported models (`docs/reliability.md`).

use std::process::Command;
use zoo_data::bvh;
use zoo_tests::{toy_clip, zoo_bin};

/// Runs `zoo ARGS`, which clap must refuse as a usage error (exit status 2, no panic), and
/// returns its standard error.
fn refused(args: &[&str]) -> String {
    let out = Command::new(zoo_bin()).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "`zoo {}` must be refused as a usage error: {err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Each case: the command, the option as clap names it and what the message must say (the
/// valid range, and why the value is not in it).
#[test]
fn every_numeric_option_of_every_subcommand_refuses_bad_values_with_its_range() {
    let tr = ["transition", "--model", "m", "--from", "a.bvh:20", "--to", "b.bvh:40", "--out", "o.bvh"];
    let dc = ["decompress", "--model", "m", "c.bvh", "--out", "o.bvh"];
    let ex = ["export", "--onnx", "m", "--out", "o.onnx"];
    let rd = ["render", "c.bvh", "--out", "o.gif"];
    let be = ["bench", "--data", "d"];
    let br = ["bench", "runtime", "--model", "m.onnx"];
    let rtn = ["train", "rtn"];
    let bt = ["bench", "train"];
    let rmr = ["train", "rmr"];
    let rg = ["train", "rnn-gmm"];
    let ta = ["train", "arnn"];
    let cp = ["complete", "--model", "m", "--keys", "k.json", "--out", "o.bvh"];
    let ge = ["generate", "--model", "m", "--out", "o.bvh"];
    let bsy = ["bench-synthesis", "--model", "m", "--data", "d"];
    let st = ["stitch", "--method", "concat", "a.bvh", "b.bvh", "--out", "o.bvh"];
    let bs = ["bench", "stitch", "--data", "d", "--valid-glob", "*x*"];
    let sy = ["data", "synth", "--out", "d"];
    let lx = ["data", "luxo", "--out", "d"];
    let rs = ["data", "resample", "a.bvh", "b.bvh"];
    let with = |base: &[&'static str], more: [&'static str; 2]| [base, &more[..]].concat();
    let frames = "valid range 1..=100000";
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (with(&tr, ["--frames", "0"]), "--frames <FRAMES>", "0 frames is outside the valid range 1..=100000"),
        (with(&tr, ["--frames", "100001"]), "--frames <FRAMES>", "(must be <= 100000)"),
        (with(&tr, ["--frames", "-3"]), "--frames <FRAMES>", "not a whole number (valid range 1..=100000)"),
        (with(&tr, ["--frames", "NaN"]), "--frames <FRAMES>", frames),
        (
            with(&tr[..3], ["--from", "a.bvh:-1"]),
            "--from <FROM>",
            "frame `-1` is not a whole number (valid range 0..=10000000)",
        ),
        (
            with(&tr[..3], ["--from", "a.bvh"]),
            "--from <FROM>",
            "expected CLIP.bvh:FRAME, e.g. walk.bvh:120 (FRAME in 0..=10000000)",
        ),
        (with(&tr[..5], ["--to", "b.bvh:18446744073709551615"]), "--to <TO>", "outside the valid range 0..=10000000"),
        (with(&dc, ["--interval", "0"]), "--interval <INTERVAL>", frames),
        (with(&dc, ["--interval", "1e9"]), "--interval <INTERVAL>", frames),
        (with(&ex, ["--fps", "0"]), "--fps <FPS>", "not a positive number (valid range [1, 1000])"),
        (with(&ex, ["--fps", "-30"]), "--fps <FPS>", "not a positive number (valid range [1, 1000])"),
        (with(&ex, ["--fps", "NaN"]), "--fps <FPS>", "not a finite number (valid range [1, 1000])"),
        (with(&ex, ["--fps", "1e40"]), "--fps <FPS>", "fps is outside the valid range [1, 1000]"),
        (with(&rd, ["--from", "-1"]), "--from <FROM>", "not a whole number (valid range 0..=10000000)"),
        (with(&rd, ["--from", "10000001"]), "--from <FROM>", "outside the valid range 0..=10000000"),
        (with(&rd, ["--to", "0"]), "--to <TO>", "outside the valid range 1..=10000000 (must be >= 1)"),
        (with(&rd, ["--to", "1e3"]), "--to <TO>", "not a whole number (valid range 1..=10000000)"),
        (with(&rd, ["--every", "0"]), "--every <EVERY>", frames),
        (with(&rd, ["--every", "100001"]), "--every <EVERY>", frames),
        (with(&rd, ["--side-by-side", "-75"]), "--side-by-side", "not a positive number (valid range (0, 1000000])"),
        (with(&rd, ["--side-by-side", "inf"]), "--side-by-side", "not a finite number (valid range (0, 1000000])"),
        (with(&rd, ["--side-by-side", "1e7"]), "--side-by-side", "outside the valid range (0, 1000000]"),
        (with(&be, ["--lengths", "5,0"]), "--lengths <LENGTHS>", frames),
        (with(&be, ["--lengths", "30,200000"]), "--lengths <LENGTHS>", frames),
        (with(&be, ["--tolerance", "-1"]), "--tolerance <TOLERANCE>", "negative (valid range [0, 100])"),
        (with(&be, ["--tolerance", "NaN"]), "--tolerance <TOLERANCE>", "not a finite number (valid range [0, 100])"),
        (with(&be, ["--tolerance", "101"]), "--tolerance <TOLERANCE>", "outside the valid range [0, 100]"),
        (with(&be, ["--save-count", "0"]), "--save-count <SAVE_COUNT>", "valid range 1..=10000"),
        (with(&be, ["--save-count", "10001"]), "--save-count <SAVE_COUNT>", "valid range 1..=10000"),
        (with(&br, ["--batch", "0"]), "--batch <BATCH>", "valid range 1..=16384"),
        (with(&br, ["--batch", "1,16385"]), "--batch <BATCH>", "valid range 1..=16384"),
        (with(&br, ["--rounds", "0"]), "--rounds <ROUNDS>", "valid range 1..=10000"),
        (with(&br, ["--rounds", "10001"]), "--rounds <ROUNDS>", "valid range 1..=10000"),
        (with(&br, ["--work", "0"]), "--work <WORK>", "valid range 1..=10000000"),
        (with(&br, ["--work", "-5"]), "--work <WORK>", "valid range 1..=10000000"),
        (with(&rtn, ["--epochs", "0"]), "--epochs <EPOCHS>", "0 epochs is outside the valid range 1..=100000"),
        (with(&rtn, ["--epochs", "100001"]), "--epochs <EPOCHS>", "valid range 1..=100000"),
        (
            with(&rtn, ["--time-limit", "0"]),
            "--time-limit <TIME_LIMIT>",
            "not a positive number (valid range (0, 43200])",
        ),
        (with(&rtn, ["--time-limit", "NaN"]), "--time-limit <TIME_LIMIT>", "not a finite number"),
        (
            with(&rtn, ["--time-limit", "1e9"]),
            "--time-limit <TIME_LIMIT>",
            "minutes is outside the valid range (0, 43200]",
        ),
        (with(&rtn, ["--batch-size", "0"]), "--batch-size <BATCH_SIZE>", "valid range 1..=65536"),
        (with(&rtn, ["--batch-size", "65537"]), "--batch-size <BATCH_SIZE>", "valid range 1..=65536"),
        (with(&rtn, ["--lr", "0"]), "--lr <LR>", "not a positive number (valid range (0, 1000000000])"),
        (with(&rtn, ["--lr", "-1e-3"]), "--lr <LR>", "not a positive number (valid range (0, 1000000000])"),
        (with(&rtn, ["--lr", "inf"]), "--lr <LR>", "not a finite number (valid range (0, 1000000000])"),
        (with(&rtn, ["--lr", "1e10"]), "--lr <LR>", "10000000000 is outside the valid range (0, 1000000000]"),
        (with(&rtn, ["--synth-minutes", "0"]), "--synth-minutes <SYNTH_MINUTES>", "not a positive number"),
        (with(&rtn, ["--synth-minutes", "NaN"]), "--synth-minutes <SYNTH_MINUTES>", "not a finite number"),
        (with(&rtn, ["--seed", "-1"]), "--seed <SEED>", "not a seed: a whole number in 0..=18446744073709551615"),
        (with(&rtn, ["--seed", "18446744073709551616"]), "--seed <SEED>", "0..=18446744073709551615"),
        (with(&rtn, ["--ema", "1"]), "--ema <EMA>", "not a decay in [0, 1)"),
        (with(&rtn, ["--ema", "-0.5"]), "--ema <EMA>", "not a decay in [0, 1)"),
        (with(&rtn, ["--ema", "NaN"]), "--ema <EMA>", "not a finite number (valid range [0, 1))"),
        (with(&rmr, ["--epochs", "0"]), "--epochs <EPOCHS>", "0 epochs is outside the valid range 1..=100000"),
        (
            with(&rmr, ["--time-limit", "0"]),
            "--time-limit <TIME_LIMIT>",
            "not a positive number (valid range (0, 43200])",
        ),
        (with(&rmr, ["--t-begin", "100001"]), "--t-begin <T_BEGIN>", "outside the valid range 0..=100000"),
        (with(&rmr, ["--hidden", "0"]), "--hidden <HIDDEN>", "0 units is outside the valid range 1..=65536"),
        (with(&rmr, ["--seam-weight", "-1"]), "--seam-weight <SEAM_WEIGHT>", "negative (valid range [0, 1000])"),
        (with(&rmr, ["--seam-weight", "1e4"]), "--seam-weight <SEAM_WEIGHT>", "outside the valid range [0, 1000]"),
        (with(&rmr, ["--batch-size", "65537"]), "--batch-size <BATCH_SIZE>", "valid range 1..=65536"),
        (with(&rmr, ["--lr", "-1"]), "--lr <LR>", "not a positive number (valid range (0, 1000000000])"),
        (with(&rmr, ["--database-stride", "0"]), "--database-stride <DATABASE_STRIDE>", frames),
        (with(&rmr, ["--synth-minutes", "0"]), "--synth-minutes <SYNTH_MINUTES>", "not a positive number"),
        (with(&rmr, ["--seed", "-1"]), "--seed <SEED>", "not a seed: a whole number in 0..=18446744073709551615"),
        (with(&st, ["--window", "0"]), "--window <WINDOW>", frames),
        (with(&st, ["--stride", "100001"]), "--stride <STRIDE>", frames),
        (with(&st, ["--blend-frames", "-2"]), "--blend-frames <BLEND_FRAMES>", frames),
        (with(&bs, ["--blend-frames", "0"]), "--blend-frames <BLEND_FRAMES>", frames),
        (
            with(&bs, ["--free-cases", "100001"]),
            "--free-cases <FREE_CASES>",
            "cases is outside the valid range 0..=100000",
        ),
        (with(&bs, ["--seed", "x"]), "--seed <SEED>", "not a seed"),
        (with(&bs, ["--database-stride", "0"]), "--database-stride <DATABASE_STRIDE>", frames),
        (with(&rg, ["--epochs", "0"]), "--epochs <EPOCHS>", "0 epochs is outside the valid range 1..=100000"),
        (with(&rg, ["--refiner-epochs", "100001"]), "--refiner-epochs <REFINER_EPOCHS>", "valid range 1..=100000"),
        (with(&rg, ["--refiner-rounds", "0"]), "--refiner-rounds <REFINER_ROUNDS>", "valid range 1..=10000"),
        (with(&rg, ["--refiner-warmup", "-1"]), "--refiner-warmup <REFINER_WARMUP>", "valid range 1..=10000"),
        (
            with(&rg, ["--time-limit", "0"]),
            "--time-limit <TIME_LIMIT>",
            "not a positive number (valid range (0, 43200])",
        ),
        (
            with(&rg, ["--refiner-time-limit", "1e9"]),
            "--refiner-time-limit <REFINER_TIME_LIMIT>",
            "minutes is outside the valid range (0, 43200]",
        ),
        (with(&rg, ["--synth-minutes", "0"]), "--synth-minutes <SYNTH_MINUTES>", "not a positive number"),
        (with(&rg, ["--seed", "-1"]), "--seed <SEED>", "not a seed"),
        (with(&rg, ["--threads", "0"]), "--threads <THREADS>", "not a thread count: valid range 1..=256"),
        (with(&ge, ["--frames", "0"]), "--frames <FRAMES>", "valid range 1..=10000000"),
        (with(&ge, ["--seconds", "0"]), "--seconds <SECONDS>", "not a positive number (valid range (0, 360000])"),
        (with(&ge, ["--count", "0"]), "--count <COUNT>", "valid range 1..=100000"),
        (with(&ge, ["--seed", "x"]), "--seed <SEED>", "not a seed"),
        (with(&ge, ["--temperature", "-1"]), "--temperature <TEMPERATURE>", "valid range [0, 100]"),
        (with(&ge, ["--init-steps", "10001"]), "--init-steps <INIT_STEPS>", "valid range 0..=10000"),
        (with(&bsy, ["--sequences", "0"]), "--sequences <SEQUENCES>", "valid range 1..=100000"),
        (
            with(&bsy, ["--seconds", "1e9"]),
            "--seconds <SECONDS>",
            "valid range (0, 3600]: the benchmark holds each sequence whole",
        ),
        (with(&bsy, ["--seed", "x"]), "--seed <SEED>", "not a seed"),
        (with(&bsy, ["--temperature", "101"]), "--temperature <TEMPERATURE>", "valid range [0, 100]"),
        (with(&bsy, ["--range-margin", "11"]), "--range-margin <RANGE_MARGIN>", "valid range [0, 10]"),
        (with(&ta, ["--sequences", "0"]), "--sequences <SEQUENCES>", "valid range 1..=100000"),
        (with(&ta, ["--k-max", "1000001"]), "--k-max <K_MAX>", "valid range 1..=1000000"),
        (with(&ta, ["--test-fraction", "1"]), "--test-fraction <TEST_FRACTION>", "valid range (0, 1)"),
        (with(&ta, ["--epochs", "0"]), "--epochs <EPOCHS>", "0 epochs is outside the valid range 1..=100000"),
        (with(&ta, ["--time-limit", "-1"]), "--time-limit <TIME_LIMIT>", "valid range (0, 43200]"),
        (with(&ta, ["--batch-size", "0"]), "--batch-size <BATCH_SIZE>", "valid range 1..=65536"),
        (with(&ta, ["--lr", "NaN"]), "--lr <LR>", "not a finite number"),
        (with(&ta, ["--seed", "x"]), "--seed <SEED>", "not a seed"),
        (with(&cp, ["--fps", "0"]), "--fps <FPS>", "valid range [1, 1000]"),
        (with(&rtn, ["--threads", "0"]), "--threads <THREADS>", "not a thread count: valid range 1..=256"),
        (with(&rtn, ["--threads", "257"]), "--threads <THREADS>", "not a thread count: valid range 1..=256"),
        (with(&bt, ["--threads", "0"]), "--threads <THREADS>", "outside the valid range 1..=256"),
        (with(&bt, ["--threads", "1,-2"]), "--threads <THREADS>", "not a whole number (valid range 1..=256)"),
        (with(&bt, ["--steps", "0"]), "--steps <STEPS>", "outside the valid range 1..=100000"),
        (with(&bt, ["--repeats", "1001"]), "--repeats <REPEATS>", "outside the valid range 1..=1000"),
        (with(&sy, ["--minutes", "0"]), "--minutes <MINUTES>", "not a positive number"),
        (with(&sy, ["--minutes", "inf"]), "--minutes <MINUTES>", "not a finite number"),
        (with(&sy, ["--seed", "1.5"]), "--seed <SEED>", "not a seed: a whole number in 0..=18446744073709551615"),
        (
            with(&sy, ["--clip-seconds", "-1"]),
            "--clip-seconds <CLIP_SECONDS>",
            "not a positive number (valid range (0, 3600])",
        ),
        (with(&sy, ["--clip-seconds", "1e9"]), "--clip-seconds <CLIP_SECONDS>", "outside the valid range (0, 3600]"),
        (with(&sy, ["--fps", "NaN"]), "--fps <FPS>", "not a finite number (valid range [1, 1000])"),
        (with(&sy, ["--fps", "0"]), "--fps <FPS>", "not a positive number (valid range [1, 1000])"),
        (with(&sy, ["--fps", "1001"]), "--fps <FPS>", "1001 fps is outside the valid range [1, 1000]"),
        (
            with(&lx, ["--sequences", "0"]),
            "--sequences <SEQUENCES>",
            "0 sequences is outside the valid range 1..=100000",
        ),
        (with(&lx, ["--sequences", "100001"]), "--sequences <SEQUENCES>", "valid range 1..=100000"),
        (with(&lx, ["--seed", "-7"]), "--seed <SEED>", "not a seed: a whole number in 0..=18446744073709551615"),
        (with(&lx, ["--k-max", "0"]), "--k-max <K_MAX>", "valid range 1..=1000000"),
        (with(&lx, ["--k-max", "1000001"]), "--k-max <K_MAX>", "valid range 1..=1000000"),
        (with(&lx, ["--max-attempts", "0"]), "--max-attempts <MAX_ATTEMPTS>", "valid range 1..=1000"),
        (with(&lx, ["--max-attempts", "1001"]), "--max-attempts <MAX_ATTEMPTS>", "valid range 1..=1000"),
        (with(&rs, ["--fps", "0"]), "--fps <FPS>", "not a positive number (valid range [1, 1000])"),
        (with(&rs, ["--max-memory", "0"]), "--max-memory <MAX_MEMORY>", "valid range (0, 1000000]"),
        (with(&rs, ["--max-memory", "NaN"]), "--max-memory <MAX_MEMORY>", "not a finite number"),
    ];
    for (args, option, says) in cases {
        let err = refused(&args);
        assert!(err.contains(&format!("for '{option}")) && err.contains(says), "`zoo {}`: {err}", args.join(" "));
    }
}

/// Runs `zoo ARGS`, which must fail (not as a usage error: a check after parsing) without a
/// panic; returns standard error.
fn failed(args: &[&str]) -> String {
    let out = Command::new(zoo_bin()).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "`zoo {}`: {err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Options valid alone but too much together (synthetic data larger than memory) are refused
/// before any work, with the range at that frame rate, and nothing is written.
#[test]
fn synthetic_data_options_valid_alone_but_not_together_are_refused_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("synth");
    let o = out.to_str().unwrap();
    // One clip is generated whole: 0.01 minutes in one 3600-second clip at 1000 fps is 3.6 M frames.
    let err = failed(&["data", "synth", "--out", o, "--minutes", "0.01", "--clip-seconds", "3600", "--fps", "1000"]);
    assert!(err.contains("is 3600000 frames (in clips of 3600 s)") && err.contains("(0, 33] minutes"), "{err}");
    let err = failed(&["data", "synth", "--out", o, "--minutes", "2000"]);
    assert!(err.contains("--minutes 2000 at 30 fps is 3600000 frames") && err.contains("(0, 1111] minutes"), "{err}");
    let err = failed(&["data", "synth", "--out", o, "--clip-seconds", "0.01"]);
    assert!(err.contains("--clip-seconds 0.01 at 30 fps is less than 2 frames per clip"), "{err}");
    // Clips so short that the generator would plan no foot plant (it panicked at 1000 fps).
    let err = failed(&["data", "synth", "--out", o, "--clip-seconds", "0.3", "--fps", "1000"]);
    assert!(
        err.contains("--clip-seconds 0.3 at 1000 fps is too short for the motion generator (at least 0.910 s"),
        "{err}"
    );
    assert!(!out.exists(), "a refused command created its output folder");
    let err = failed(&["train", "rtn", "--synth-minutes", "1e5", "--out", o]);
    assert!(err.contains("--synth-minutes 100000 at 30 fps is 180000000 frames"), "{err}");
    assert!(!out.exists(), "a refused training created its run folder");
}

/// Writes four toy clips (4 joints) of `skeleton` into `dir`, one of them matching
/// `*_youthful_*` (the test split).
fn toy_dataset(dir: &std::path::Path, skeleton: &zoo_motion::Skeleton) {
    std::fs::create_dir_all(dir).unwrap();
    for (i, style) in ["normal", "normal", "youthful", "active"].iter().enumerate() {
        let mut clip = toy_clip(140 + 10 * i, i as f64 * 0.7);
        clip.skeleton = skeleton.clone();
        bvh::write_file(&clip, &dir.join(format!("toy_walk_{style}_{i:03}.bvh"))).unwrap();
    }
}

/// `zoo bench --methods onnx:FILE` refuses an exported model whose skeleton (recorded in the
/// file) is not the dataset's: another hierarchy with the same joint count, or the same
/// hierarchy with other joint names. The model's own skeleton passes the check and runs.
#[test]
fn bench_refuses_an_exported_model_of_another_hierarchy() {
    let dir = tempfile::tempdir().unwrap();
    let onnx = dir.path().join("tiny.onnx");
    zoo_tests::tiny_rtn_onnx().write(&onnx).unwrap();
    let method = format!("onnx:{}", onnx.display());
    let bench = |data: &std::path::Path| {
        let args = ["bench", "--data", data.to_str().unwrap(), "--valid-glob", "*_youthful_*", "--lengths", "5"];
        let out = Command::new(zoo_bin()).args(args).args(["--methods", &method]).output().unwrap();
        let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(!stderr.contains("panicked"), "{stderr}");
        (out.status.success(), stdout.into_owned(), stderr.into_owned())
    };

    let same = dir.path().join("same");
    toy_dataset(&same, &zoo_tests::toy_skeleton());
    let (ok, stdout, stderr) = bench(&same);
    assert!(ok && stdout.contains(&method), "{stdout}\n{stderr}");

    // The leg hangs from the spine instead of the hips: 4 joints, another hierarchy.
    let mut skeleton = zoo_tests::toy_skeleton();
    skeleton.parents[2] = Some(1);
    let other = dir.path().join("other");
    toy_dataset(&other, &skeleton);
    let (ok, _, stderr) = bench(&other);
    assert!(!ok, "a dataset of another hierarchy was benchmarked");
    assert!(
        stderr.contains(&format!("method `{method}`: the model was trained on another skeleton"))
            && stderr.contains("parents [-1, 0, 0, 2]")
            && stderr.contains("parents [-1, 0, 1, 2]"),
        "{stderr}"
    );

    let mut skeleton = zoo_tests::toy_skeleton();
    skeleton.names[3] = "Foot_R".into();
    let renamed = dir.path().join("renamed");
    toy_dataset(&renamed, &skeleton);
    let (ok, _, stderr) = bench(&renamed);
    assert!(!ok && stderr.contains("its joint 3 is `Foot_L`, the dataset's is `Foot_R`"), "{stderr}");
}

/// Runs `zoo ARGS` (no panic, no abort); returns (success, stdout, stderr).
fn zoo(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_bin()).args(args).env("RAYON_NUM_THREADS", "1").output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.code().is_some(), "`zoo {}` was killed by a signal: {stderr}", args.join(" "));
    assert!(!stderr.contains("panicked") && !stderr.contains("overflow"), "{stderr}");
    (out.status.success(), stdout.into_owned(), stderr.into_owned())
}

/// Class 2: `zoo data stats` of a clip whose root jumps by 2e308 cm a frame (speeds beyond
/// the range of numbers) says in words which figures cannot be computed, prints no NaN or inf,
/// and writes `null` for them in `--json`; the other figures are still there.
#[test]
fn data_stats_says_in_words_which_figures_cannot_be_computed() {
    let dir = tempfile::tempdir().unwrap();
    let mut clip = toy_clip(10, 0.0);
    let j = clip.joints();
    for f in 0..clip.frames() {
        clip.local_positions[f * j].x = if f % 2 == 0 { 1e308 } else { -1e308 };
    }
    let path = dir.path().join("huge.bvh");
    bvh::write_file(&clip, &path).unwrap();
    let json = dir.path().join("stats.json");
    let (ok, stdout, stderr) = zoo(&["data", "stats", path.to_str().unwrap(), "--json", json.to_str().unwrap()]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("root speed: cannot be computed (the clips' positions"), "{stdout}");
    assert!(stdout.contains("foot skate: cannot be computed"), "{stdout}");
    assert!(stdout.contains("frames     10"), "{stdout}");
    for bad in ["NaN", " inf ", "inf\n"] {
        assert!(!stdout.contains(bad), "{bad} printed: {stdout}");
    }
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["root_speed"].is_null(), "{v}");
    assert!(v["not_computed"][0].as_str().unwrap().starts_with("root speed"), "{v}");
}

/// Class 1 and 4: a hierarchy nested deeper than the limit and a frame time out of range are
/// refused at parse time, with the file, the line and the limit (a 100,000-level hierarchy
/// overflowed the stack of `zoo data stats` before, after printing gigabytes of indentation).
#[test]
fn deep_hierarchies_and_frame_times_out_of_range_are_refused_at_parse_time() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let mut text = String::from("HIERARCHY\n");
    for i in 0..n {
        let kw = if i == 0 { "ROOT" } else { "JOINT" };
        text += &format!("{kw} J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n");
    }
    text += &"}\n".repeat(n);
    text += &format!("MOTION\nFrames: 1\nFrame Time: 0.033\n{}\n", vec!["0"; 3 * n].join(" "));
    let deep = dir.path().join("deep.bvh");
    std::fs::write(&deep, text).unwrap();
    let (ok, stdout, stderr) = zoo(&["data", "stats", deep.to_str().unwrap()]);
    assert!(!ok && stdout.len() < 1000, "{}", &stdout[..stdout.len().min(1000)]);
    assert!(stderr.contains("deep.bvh:") && stderr.contains("nested 1001 levels below the root"), "{stderr}");

    let mut clip = toy_clip(10, 0.0);
    for (t, says) in [(1e-30, "frame time 1e-30 s is outside"), (1e30, "frame time 1e30 s is outside")] {
        clip.frame_time = t;
        let p = dir.path().join("t.bvh");
        bvh::write_file(&clip, &p).unwrap();
        let (ok, _, stderr) = zoo(&["data", "stats", p.to_str().unwrap()]);
        assert!(!ok && stderr.contains(says) && stderr.contains("[0.0001, 10] s"), "{stderr}");
    }
}

/// Class 2: a model whose normalization std underflows (1e-45 passes "finite and positive")
/// is refused when loaded, so `zoo bench` writes no report of NaN (`null`) and exits 1.
#[test]
fn a_model_with_an_underflowing_std_is_refused_not_benchmarked_as_nan() {
    let dir = tempfile::tempdir().unwrap();
    let onnx = dir.path().join("tiny.onnx");
    // The exporter refuses such statistics itself, so the file is edited after export.
    let mut model = zoo_tests::tiny_rtn_onnx();
    let mut stats: serde_json::Value =
        serde_json::from_str(model.metadata_value("zoo.normalization").unwrap()).unwrap();
    stats["offset"]["std"][0] = 1e-45.into();
    model.set_metadata("zoo.normalization", &stats.to_string());
    model.write(&onnx).unwrap();
    let data = dir.path().join("data");
    toy_dataset(&data, &zoo_tests::toy_skeleton());
    let report = dir.path().join("report.json");
    let method = format!("onnx:{}", onnx.display());
    let (ok, _, stderr) = zoo(&[
        "bench",
        "--data",
        data.to_str().unwrap(),
        "--valid-glob",
        "*_youthful_*",
        "--lengths",
        "5",
        "--methods",
        &method,
        "--json",
        report.to_str().unwrap(),
    ]);
    assert!(!ok && stderr.contains("every std must be at least 1e-6"), "{stderr}");
    assert!(!report.exists(), "a report was written");
}

/// The arguments of a tiny RTN run into `folder` (`flag`: `--out` or `--resume`).
fn tiny_rtn<'a>(flag: &'a str, folder: &'a str, epochs: &'a str) -> Vec<&'a str> {
    vec!["train", "rtn", "--preset", "tiny", "--synth-minutes", "0.5", "--seed", "5", "--epochs", epochs, flag, folder]
}

/// Class 3: `--overwrite` keeps the old run until the new one has finished its first epoch (a
/// new run that fails first, here on a data folder that does not exist, puts it back); a lock
/// file refuses a second training into the folder with the first one's pid and start time, the
/// lock of a process that no longer runs is taken over, and the leftovers of an interrupted
/// write (a zero-byte temporary file, a `.last.tmp/` folder) do not block the next command.
#[test]
fn overwrite_locks_and_interrupted_writes_never_lose_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let s = run.to_str().unwrap();
    let (ok, _, stderr) = zoo(&tiny_rtn("--out", s, "1"));
    assert!(ok, "{stderr}");
    assert!(!run.join(zoo_nn::run_folder::LOCK_FILE).exists(), "the lock outlived the command");
    let weights = std::fs::read(run.join("model.safetensors")).unwrap();

    let missing = dir.path().join("no-such-data");
    let mut args = vec!["train", "rtn", "--preset", "tiny", "--data", missing.to_str().unwrap()];
    args.extend(["--valid-glob", "*x*", "--epochs", "1", "--out", s, "--overwrite"]);
    let (ok, _, stderr) = zoo(&args);
    assert!(!ok && stderr.contains("the new run failed before its first epoch; the old run in"), "{stderr}");
    assert_eq!(std::fs::read(run.join("model.safetensors")).unwrap(), weights, "the old run was lost");
    assert!(!run.join(zoo_nn::run_folder::ASIDE_DIR).exists());

    // Process 1 always runs: its lock refuses.
    let lock = run.join(zoo_nn::run_folder::LOCK_FILE);
    std::fs::write(&lock, "pid 1\nstarted 2026-11-27 05:00:00 UTC\n").unwrap();
    let (ok, _, stderr) = zoo(&tiny_rtn("--resume", s, "2"));
    assert!(
        !ok && stderr.contains("is in use by another training: process 1, started 2026-11-27 05:00:00 UTC"),
        "{stderr}"
    );
    // A pid above the kernel's limit never runs: taken over, and the leftovers are cleared.
    std::fs::write(&lock, "pid 4294967\nstarted 2026-11-27 05:00:00 UTC\n").unwrap();
    std::fs::write(run.join(".train_state.json.4294967.tmp"), "").unwrap();
    std::fs::create_dir_all(run.join(".last.tmp")).unwrap();
    let (ok, _, stderr) = zoo(&tiny_rtn("--resume", s, "2"));
    assert!(ok, "{stderr}");
    assert!(stderr.contains("taking over the lock of process 4294967"), "{stderr}");
    assert!(stderr.contains("removed 2 leftover(s) of an interrupted write"), "{stderr}");
    assert!(!run.join(".last.tmp").exists() && !lock.exists());

    let mut args = tiny_rtn("--out", s, "1");
    args.push("--overwrite");
    let (ok, stdout, stderr) = zoo(&args);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("the new run finished its first epoch; the old run is deleted"), "{stdout}");
    assert!(!run.join(zoo_nn::run_folder::ASIDE_DIR).exists());
}

/// Class 4: `--resume DIR` continues with the options the run was started with (recorded in its
/// folder): the docs' `zoo train rtn --resume runs/rtn-b2 --epochs 500` runs as written, with
/// no data option repeated; an option given with another value than the run's (here `--lr`,
/// `--batch-size`, the data) is refused with both values instead of being ignored.
#[test]
fn resume_keeps_the_runs_options_and_refuses_others() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let s = run.to_str().unwrap();
    let mut args = tiny_rtn("--out", s, "1");
    args.extend(["--lr", "0.002", "--batch-size", "8"]);
    let (ok, _, stderr) = zoo(&args);
    assert!(ok, "{stderr}");
    let recorded = std::fs::read_to_string(run.join(zoo_nn::run_folder::COMMAND_FILE)).unwrap();
    assert!(recorded.contains("\"synth-minutes\"") && recorded.contains("\"0.002\""), "{recorded}");
    let state = std::fs::read(run.join("train_state.json")).unwrap();
    for (flag, value, was) in [
        ("--lr", "0.01", "--lr 0.002"),
        ("--batch-size", "16", "--batch-size 8"),
        ("--synth-minutes", "1", "--synth-minutes 0.5"),
    ] {
        let (ok, _, stderr) = zoo(&["train", "rtn", "--resume", s, "--epochs", "2", flag, value]);
        assert!(!ok && stderr.contains(&format!("{flag} {value}: the run in {s} was started with {was}")), "{stderr}");
        assert!(stderr.contains("a resumed run keeps the options it was started with"), "{stderr}");
    }
    assert_eq!(std::fs::read(run.join("train_state.json")).unwrap(), state, "a refused resume changed the run");
    // As the docs write it: the folder and the new total only (and the same values are fine).
    let (ok, stdout, stderr) = zoo(&["train", "rtn", "--resume", s, "--epochs", "2"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("epoch   2:") && !stdout.contains("epoch   1:"), "{stdout}");
    let (ok, stdout, stderr) = zoo(&["train", "rtn", "--resume", s, "--epochs", "3", "--lr", "2e-3", "--seed", "5"]);
    assert!(ok && stdout.contains("epoch   3:"), "{stderr}");
    let docs =
        std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/rtn.md")).unwrap();
    assert!(docs.contains("zoo train rtn --resume runs/rtn-b2 --epochs 500"), "the docs' resume example changed");
}

/// The README's commands run as written: every `zoo ...` line of its shell blocks, with its
/// data folders (bandai2, LaFAN1, your own capture) replaced by one minute of synthetic clips
/// named so that the line's globs choose some, and `runs/rtn` by a tiny model; the main job
/// (`cargo run --release --bin zoo -- train rtn`) runs with tiny settings added.
#[test]
fn the_readmes_commands_run_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (ok, _, stderr) = zoo(&["data", "synth", "--out", data.to_str().unwrap(), "--minutes", "1", "--seed", "2"]);
    assert!(ok, "{stderr}");
    let mut clips: Vec<_> = std::fs::read_dir(&data).unwrap().map(|e| e.unwrap().path()).collect();
    clips.retain(|p| p.extension().is_some_and(|e| e == "bvh"));
    clips.sort();
    for (i, c) in clips.iter().enumerate().filter(|(i, _)| i % 3 == 2) {
        std::fs::rename(c, data.join(format!("clip_youthful_subject5_{i}.bvh"))).unwrap();
    }
    let run = dir.path().join("runs/rtn");
    let readme =
        std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md")).unwrap();
    let mut blocks = readme.split("```");
    blocks.next();
    let lines: Vec<String> = blocks
        .step_by(2)
        .filter_map(|b| b.strip_prefix("sh\n"))
        .flat_map(|b| b.lines())
        .map(|l| l.split(" #").next().unwrap().trim().to_string())
        .filter(|l| l.starts_with("zoo ") || l.starts_with("cargo run"))
        .collect();
    assert!(lines.len() >= 4, "{lines:?}");
    // The main job first: it makes the model the others use.
    let main = lines.iter().find(|l| l.starts_with("cargo run")).expect("the README's main job");
    let words = main.split_once(" -- ").unwrap().1;
    let mut args: Vec<&str> = words.split_whitespace().collect();
    args.extend(["--preset", "tiny", "--synth-minutes", "0.5", "--epochs", "1", "--out", run.to_str().unwrap()]);
    let (ok, _, stderr) = zoo(&args);
    assert!(ok, "{main}: {stderr}");
    let d = data.to_str().unwrap();
    for line in lines.iter().filter(|l| l.starts_with("zoo ")) {
        let line = line
            .replace("../shared/data/bandai2", d)
            .replace("~/data/lafan1", d)
            .replace("~/mocap/train", d)
            .replace("~/mocap/heldout", d)
            .replace("runs/rtn", run.to_str().unwrap())
            .replace("out.json", dir.path().join("out.json").to_str().unwrap());
        let args: Vec<String> = line[4..].split_whitespace().map(|w| w.trim_matches('\'').to_string()).collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, _, stderr) = zoo(&args);
        assert!(ok, "`{line}` failed: {stderr}");
    }
}
