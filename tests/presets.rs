//! The presets to try in minutes: `zoo train rmr --preset quick` and `zoo train arnn --design
//! inbetween --preset quick` parse and have the sizes the docs give (docs/rmr.md, "Quick
//! start"; docs/keys-only.md, "Try it in minutes"). Nothing is trained here.

use std::process::Command;
use zoo_tests::zoo_bin;

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(zoo_bin()).args(args).env("RAYON_NUM_THREADS", "1").output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_quick_rmr_has_the_papers_windows_at_half_width() {
    use zoo_rmr::{Config, RmrTrainer, features::FeatureStats};
    let c = Config::preset("quick").unwrap();
    assert_eq!(c, Config::quick());
    assert_eq!((c.encoder.as_slice(), c.hidden, c.layers, c.decoder.as_slice()), (&[128, 128][..], 128, 2, &[128][..]));
    assert_eq!((c.window, c.stride, c.pairs.window, c.pairs.database_stride), (60, 30, 60, 2));
    assert_eq!((c.train.learning_rate, c.train.batch_size), (1e-4, 8));
    assert_eq!(zoo_rmr::train_run::QUICK_EPOCHS, 80);
    c.validate().unwrap();
    let d = c.dim();
    let stats = FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] };
    let trainer = RmrTrainer::new(&c, stats, &candle_core::Device::Cpu).unwrap();
    assert_eq!(zoo_rmr::model::parameter_count(trainer.varmap()), 581_393);
    let paper = Config::paper();
    assert!(c.hidden * 2 == paper.hidden && c.window == paper.window);
    let e = Config::preset("huge").unwrap_err().to_string();
    assert!(e.contains("paper, quick or tiny"), "{e}");
}

#[test]
fn the_quick_inbetweening_network_is_the_humanoid_design_at_half_width() {
    use candle_nn::{VarBuilder, VarMap};
    use zoo_arnn::inbetween::{Inbetween, InbetweenConfig, config_for};
    let skeleton = zoo_data::synth::skeleton();
    let full = config_for(&skeleton, 30.0);
    let c = InbetweenConfig::quick(full.skeleton.clone(), full.euler_axes.clone());
    assert_eq!((c.encoder, c.hidden, c.layers, c.decoder), (128, 128, 1, 128));
    assert_eq!((c.batch_size, c.learning_rate), (32, 2e-3));
    assert_eq!((c.lambda_fk, c.lambda_vel, c.residual), (full.lambda_fk, full.lambda_vel, full.residual));
    assert_eq!(zoo_arnn::train_run::QUICK_INBETWEEN_EPOCHS, 30);
    assert_eq!(zoo_arnn::train_run::QUICK_SYNTH_MINUTES, 20.0);
    c.validate().unwrap();
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, candle_core::DType::F32, &candle_core::Device::Cpu);
    Inbetween::new(&c, vb).unwrap();
    let params: usize = varmap.all_vars().iter().map(|v| v.elem_count()).sum();
    assert_eq!(params, 281_687);
}

#[test]
fn the_command_line_takes_the_quick_presets_where_they_apply() {
    for cmd in [&["train", "rmr", "--help"][..], &["train", "arnn", "--help"][..]] {
        let (ok, stdout, stderr) = run(cmd);
        assert!(ok, "{stderr}");
        assert!(stdout.contains("quick"), "{cmd:?}: {stdout}");
    }
    // The autoregressive ARNN has no quick preset: refused before any data is made.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let (ok, _, stderr) = run(&["train", "arnn", "--preset", "quick", "--out", out.to_str().unwrap()]);
    assert!(!ok);
    assert!(stderr.contains("--preset quick is the in-betweening design's"), "{stderr}");
    let (ok, _, stderr) = run(&["train", "arnn", "--synth-minutes", "2", "--out", out.to_str().unwrap()]);
    assert!(!ok);
    assert!(stderr.contains("--synth-minutes gives the in-betweening design"), "{stderr}");
    assert!(!out.exists());
}

#[test]
fn the_inbetweening_design_trains_on_synthetic_locomotion_without_data_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ib");
    let r = out.to_str().unwrap();
    let args = ["train", "arnn", "--design", "inbetween", "--preset", "tiny", "--synth-minutes", "1"];
    let (ok, stdout, stderr) = run(&[&args[..], &["--epochs", "1", "--threads", "1", "--out", r]].concat());
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("synthetic locomotion, 1 min, seed 1"), "{stdout}");
    assert!(stdout.contains("zoo data synth --out synth-test --seed 1001"), "{stdout}");
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("config.json")).unwrap()).unwrap();
    assert_eq!((config["design"].as_str(), config["encoder"].as_u64()), (Some("inbetween"), Some(16)));
    // Resumed on the same synthetic clips; --data is refused for it (the recorded command).
    let (ok, stdout, stderr) = run(&["train", "arnn", "--epochs", "2", "--threads", "1", "--resume", r]);
    assert!(ok && stdout.contains("epoch   2"), "{stdout}\n{stderr}");
    let (ok, _, stderr) =
        run(&["train", "arnn", "--epochs", "3", "--resume", r, "--data", dir.path().to_str().unwrap()]);
    assert!(!ok && stderr.contains("was started with no --data"), "{stderr}");
}
