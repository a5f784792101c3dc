//! `zoo train arnn --data BVH_FOLDER --valid-glob GLOB`: the keyframe autocompletion network on
//! humanoid motion (issue 13, beyond the paper): 66-frame windows of the training split, keys
//! drawn afresh each time a window is fed (every 5-30 frames, half the time in the
//! in-betweening benchmark's layout), a fifth of the keys partial. Scored afterwards by
//! `zoo bench --methods interp,arnn:DIR`.

use crate::cmd::train_arnn::{ArnnArgs, ArnnPreset};
use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;
use zoo_arnn::{ArnnConfig, ArnnTrainer, humanoid};
use zoo_data::dataset;
use zoo_nn::train_loop::{self, TrainOptions};

/// The data of a humanoid run, recorded in `train_state.json` so that `--resume` rebuilds it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HumanoidData {
    /// The BVH folder or file.
    pub dir: PathBuf,
    /// Glob of the validation split.
    pub valid_glob: String,
    /// Seed of the validation keys.
    pub seed: u64,
}

const STATE_KEY: &str = "humanoid_data";

/// Whether `dir` holds a humanoid ARNN run (its `train_state.json` records [`HumanoidData`]).
pub fn is_humanoid_run(dir: &Path) -> bool {
    train_loop::read_state(dir).is_ok_and(|s| s.extra.contains_key(STATE_KEY))
}

/// Runs `zoo train arnn` on humanoid BVH.
pub fn run(a: ArnnArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    if a.variant != crate::cmd::train_arnn::ArnnVariant::Arnn {
        bail!(
            "--variant {:?} is a comparison of the paper's tables on the lamp; humanoid runs train the ARNN",
            a.variant
        );
    }
    let out = crate::cmd::train_arnn::prepare_run_folder(&a)?;
    let mut extra = serde_json::Map::new();
    let (settings, resumed) = match &a.resume {
        Some(dir) => {
            let state = train_loop::read_state(dir)?;
            let stored = state.extra.get(STATE_KEY).cloned().with_context(|| {
                format!(
                    "{}: train_state.json records no humanoid data (a lamp run: resume it without --valid-glob)",
                    dir.display()
                )
            })?;
            let mut s: HumanoidData = serde_json::from_value(stored)?;
            if let Some(d) = &a.data {
                s.dir = d.clone();
            }
            if let Some(g) = &a.valid_glob
                && *g != s.valid_glob
            {
                bail!("--resume {}: the run validates on `{}`, not `{g}`", dir.display(), s.valid_glob);
            }
            (s, true)
        }
        None => {
            let s = HumanoidData {
                dir: a.data.clone().context("pass --data BVH_FOLDER")?,
                valid_glob: a.valid_glob.clone().context("pass --valid-glob GLOB")?,
                seed: a.seed,
            };
            extra.insert(STATE_KEY.into(), serde_json::to_value(&s)?);
            (s, false)
        }
    };
    let clips = crate::cmd::load_dataset(&settings.dir, None, false)?;
    let (train_clips, valid_clips) = dataset::split(clips, &settings.valid_glob)?;
    let skeleton = train_clips[0].clip.skeleton.clone();
    let train_w = dataset::windows(&train_clips, &humanoid::WINDOW);
    let valid_w = dataset::windows(&valid_clips, &humanoid::WINDOW);
    if train_w.count == 0 || valid_w.count == 0 {
        bail!(
            "{}: {} training and {} validation windows of {} frames: both splits need clips longer than {} frames",
            settings.dir.display(),
            train_w.count,
            valid_w.count,
            humanoid::WINDOW.window,
            humanoid::WINDOW.window
        );
    }
    let trainer = if resumed {
        let from = train_loop::resume_dir(&out);
        let (config, norm) = zoo_arnn::checkpoint::read_meta(&from)
            .with_context(|| format!("resuming from {}: it holds no ARNN checkpoint", from.display()))?;
        humanoid::check_skeleton(&config, &skeleton)?;
        let train = humanoid::sequences(&train_w, &config.key_sampling, settings.seed);
        let valid = humanoid::sequences(&valid_w, &config.key_sampling, settings.seed ^ 0x5EED);
        ArnnTrainer::with_normalization(&config, norm, train, valid, &device)?
    } else {
        let mut config = humanoid::config_for(&skeleton, 1.0 / train_clips[0].clip.frame_time);
        if a.preset == ArnnPreset::Tiny {
            config = config.sized_like(&ArnnConfig::tiny());
        }
        if let Some(b) = a.batch_size {
            config.batch_size = b;
        }
        if let Some(lr) = a.lr {
            config.learning_rate = lr;
        }
        if a.ground_weight.is_some() {
            bail!("--ground-weight is the lamp's base penalty; humanoid runs have none");
        }
        config.seed = a.seed;
        config.curriculum.total_steps = train_w.count.div_ceil(config.batch_size) as u64 * a.epochs as u64;
        crate::cmd::train_arnn::set_frame_phase(&a, &mut config, false)?;
        let train = humanoid::sequences(&train_w, &config.key_sampling, settings.seed);
        let valid = humanoid::sequences(&valid_w, &config.key_sampling, settings.seed ^ 0x5EED);
        let norm = humanoid::normalization(&train);
        ArnnTrainer::with_normalization(&config, norm, train, valid, &device)?
    };
    let source = format!(
        "{} ({} training clips, {} validation clips matching `{}`)",
        settings.dir.display(),
        train_clips.len(),
        valid_clips.len(),
        settings.valid_glob
    );
    println!(
        "training the humanoid ARNN on {source}: {} training / {} validation windows of {} frames, {} joints, {} \
         parameters, curriculum over {} steps, run folder {}",
        train_w.count,
        valid_w.count,
        humanoid::WINDOW.window,
        skeleton.len(),
        trainer.parameter_count(),
        trainer.config().curriculum.total_steps,
        out.display()
    );
    let mut trainer = trainer;
    let threads = crate::cmd::train::default_threads(a.threads);
    trainer.set_threads(threads)?;
    println!("training threads: {threads} (data-parallel; --threads to change)");
    extra.insert("threads".into(), threads.into());
    let seed = trainer.config().seed;
    let opts = TrainOptions {
        time_limit: a.time_limit.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok()),
        resume: resumed,
        data: source,
        extra,
        ..TrainOptions::new(&out, a.epochs, seed)
    };
    let state = train_loop::train(&mut trainer, &opts)?;
    println!(
        "done: {} epochs ({} steps) in {:.1} min, best validation loss {:.5} at epoch {}; model in {}\nscore it: zoo \
         bench --data {} --valid-glob '{}' --methods interp,arnn:{}",
        state.epoch,
        state.steps,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        out.display(),
        settings.dir.display(),
        settings.valid_glob,
        out.display()
    );
    Ok(())
}
