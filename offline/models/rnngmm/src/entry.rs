//! The RNN-GMM's entry in the table of models ([`zoo_nn::ZooModel`]): `zoo train rnn-gmm`'s
//! options (two stages, the generator and then the refiner against a discriminator; run
//! folder layout in docs/rnn-gmm.md), its training and its export.

use crate::train_run::{RefinerOverrides, RnnGmmPreset, RnnGmmRunOptions, Stage};
use clap::{Args, FromArgMatches};
use std::path::Path;
use zoo_export::ExportError;
use zoo_format::MotionTaskKind;
use zoo_nn::train_args::{DataArgs, RunArgs, TrainDefaults};
use zoo_nn::zoo_model::{BoxError, ExportOptions, Exported, ZooModel};

/// The RNN-GMM in the table of models.
pub struct RnnGmmModel;

impl ZooModel for RnnGmmModel {
    fn kind(&self) -> &'static str {
        crate::export::MODEL_KIND
    }

    fn about(&self) -> &'static str {
        "RNN-GMM with an adversarial refiner (Wang, Chai & Xia 2019): random motion synthesis"
    }

    fn purpose(&self) -> &'static str {
        "random motion synthesis and its control (`zoo generate`, `zoo control`, `zoo follow`, `zoo bench synthesis`)"
    }

    fn task(&self) -> MotionTaskKind {
        MotionTaskKind::Synthesis
    }

    fn train_command(&self) -> clap::Command {
        RnnGmmArgs::augment_args(clap::Command::new(self.kind()).about(self.about()))
    }

    fn train(&self, options: &clap::ArgMatches, command: Vec<(String, Vec<String>)>) -> Result<(), BoxError> {
        let mut a = RnnGmmArgs::from_arg_matches(options)?;
        a.run.command = command;
        train(a)
    }

    fn export(&self, run: &Path, options: &ExportOptions) -> Result<Exported, ExportError> {
        let model = crate::export::export_run(run, options)?;
        let with = match model.metadata_value(crate::export::REFINER_GRAPH_KEY) {
            Some(_) => "with its metadata and the refiner's step graph",
            None => "with its metadata, without a refiner (generator stage only)",
        }
        .to_string();
        Ok(Exported { model, what: "RNN-GMM generator step graph", with })
    }
}

/// The RNN-GMM's defaults.
#[derive(Clone)]
pub struct RnnGmmDefaults;

impl TrainDefaults for RnnGmmDefaults {
    const EPOCHS: &'static str = "10";
    const OUT: &'static str = "runs/rnn-gmm";
}

/// Arguments of `zoo train rnn-gmm`.
#[derive(Args)]
pub struct RnnGmmArgs {
    /// The run folder, the generator's epochs and time limit, the seed and threads.
    #[command(flatten)]
    pub run: RunArgs<RnnGmmDefaults>,
    /// The clips.
    #[command(flatten)]
    pub data: DataArgs<RnnGmmDefaults>,
    /// Glob on file names selecting the clips of `--data` to use (e.g. `'*_00[1-3].bvh*'`).
    #[arg(long)]
    pub glob: Option<String>,
    /// Stage(s) to train: `both` (generator, then refiner), `generator`, or `refiner` (on the
    /// generator of the run folder).
    #[arg(long, value_enum, default_value_t = Stage::Both)]
    pub stage: Stage,
    /// Refiner epochs (an epoch is `--refiner-rounds` adversarial rounds; a resumed run
    /// continues up to this total).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = zoo_nn::args::epochs)]
    pub refiner_epochs: usize,
    /// Adversarial rounds per refiner epoch (a round: k refiner updates and one discriminator
    /// update; the first also runs the warm-up).
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = zoo_nn::args::rounds)]
    pub refiner_rounds: usize,
    /// Warm-up updates of the refiner stage, refiner and discriminator each [default: the
    /// preset's; paper: 75]. Ignored when a refiner stage is resumed (its own setting is kept).
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::rounds)]
    pub refiner_warmup: Option<usize>,
    /// Weight of the refiner's root regularisation (eq. 13's lambda; paper: 20) [default: the
    /// generator run's setting]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::loss_weight)]
    pub refiner_lambda: Option<f64>,
    /// Weight of the refiner's foot-skate term (not in the paper's eq. 13; see
    /// `docs/rnn-gmm.md`) [default: the generator run's setting; 300 in new runs, 0 means eq.
    /// 13 alone]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::loss_weight)]
    pub refiner_skate_weight: Option<f64>,
    /// Weight of the refiner's joint-range term (not in the paper) [default: the generator
    /// run's setting; 500 in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::loss_weight)]
    pub refiner_range_weight: Option<f64>,
    /// Percentile of the joint-range term's bounds: each value's range runs from this
    /// percentile to 100 minus it in the training windows [default: the generator run's
    /// setting; 1 in new runs, 0 for min to max]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::range_percentile)]
    pub refiner_range_percentile: Option<f64>,
    /// Frames the generator runs past its seed before each of the refiner's training windows
    /// starts, so the refiner also sees the generator's drift [default: the generator run's
    /// setting; 0 in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::frames_or_zero)]
    pub refiner_fake_lead: Option<usize>,
    /// Fake windows sampled afresh from the generator after every adversarial round, replacing
    /// as many in the refiner's pool [default: the generator run's setting; 16 in new runs, 0
    /// keeps the pool sampled at the start]. Ignored when a refiner stage is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::count_or_zero)]
    pub refiner_fresh_fakes: Option<usize>,
    /// Clamp the refiner's output joint angles (and root tilt) to their min and max over the
    /// real training windows (not in the paper; `false` for the paper's refiner) [default: true
    /// in new runs]. Ignored when a refiner stage is resumed.
    #[arg(long, num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    pub refiner_joint_limits: Option<bool>,
    /// Standard deviation, in frames, of the Gaussian that smooths the generator's root before
    /// eq. 13 holds the refined root to it, so the refiner may remove the root's frame-to-frame
    /// jitter (not in the paper) [default: 0, eq. 13 as written]. Ignored when a refiner stage
    /// is resumed.
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::smoothing_frames)]
    pub refiner_root_smoothing: Option<f64>,
    /// Stop the refiner stage after this many minutes [default: --time-limit].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::time_limit_minutes)]
    pub refiner_time_limit: Option<f64>,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = RnnGmmPreset::Paper)]
    pub preset: RnnGmmPreset,
}

/// Runs `zoo train rnn-gmm`.
fn train(a: RnnGmmArgs) -> Result<(), BoxError> {
    let refiner = RefinerOverrides {
        warmup: a.refiner_warmup,
        lambda: a.refiner_lambda,
        skate_weight: a.refiner_skate_weight,
        range_weight: a.refiner_range_weight,
        range_percentile: a.refiner_range_percentile,
        fake_lead: a.refiner_fake_lead,
        fresh_fakes: a.refiner_fresh_fakes,
        joint_limits: a.refiner_joint_limits,
        root_smoothing: a.refiner_root_smoothing,
    };
    let (run, data) = zoo_nn::train_args::specs(&a.run, &a.data, None)?;
    let o = RnnGmmRunOptions {
        run,
        data,
        glob: a.glob,
        stage: a.stage,
        refiner_epochs: a.refiner_epochs,
        refiner_rounds: a.refiner_rounds,
        refiner,
        refiner_time_limit: a.refiner_time_limit,
        preset: a.preset,
    };
    Ok(crate::train_run::run(&o, &zoo_nn::progress::Stderr)?)
}
