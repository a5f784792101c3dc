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
        (with(&bsy, ["--seconds", "1e9"]), "--seconds <SECONDS>", "valid range (0, 360000]"),
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
