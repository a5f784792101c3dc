//! The RTN's entry in the table of models ([`zoo_nn::ZooModel`]): `zoo train rtn`'s options,
//! its training and its export.

use crate::train_run::{RtnAugment, RtnPreset, RtnRunOptions, RtnVariant};
use clap::{Args, FromArgMatches};
use std::path::Path;
use zoo_data::benchmark::TransitionMethod;
use zoo_export::ExportError;
use zoo_format::MotionTaskKind;
use zoo_nn::train_args::{DataArgs, RunArgs, TrainDefaults};
use zoo_nn::zoo_model::{BoxError, CandleTransitions, ExportOptions, Exported, ZooModel};

/// The RTN in the table of models.
pub struct RtnModel;

impl ZooModel for RtnModel {
    fn kind(&self) -> &'static str {
        crate::export::MODEL_KIND
    }

    fn about(&self) -> &'static str {
        "The Recurrent Transition Network (Harvey & Pal 2018)"
    }

    fn purpose(&self) -> &'static str {
        "transitions between a context and a target pose (`zoo transition`, `zoo bench`)"
    }

    fn task(&self) -> MotionTaskKind {
        MotionTaskKind::Transition
    }

    fn train_command(&self) -> clap::Command {
        RtnArgs::augment_args(clap::Command::new(self.kind()).about(self.about()))
    }

    fn train(&self, options: &clap::ArgMatches, command: Vec<(String, Vec<String>)>) -> Result<(), BoxError> {
        let mut a = RtnArgs::from_arg_matches(options)?;
        a.run.command = command;
        train(a)
    }

    fn export(&self, run: &Path, options: &ExportOptions) -> Result<Exported, ExportError> {
        let model = crate::export::export_run(run, options)?;
        let with = "with its start graph and metadata".to_string();
        Ok(Exported { model, what: "RTN step graph", with })
    }

    fn candle_transitions(&self) -> Option<CandleTransitions> {
        fn load(run: &Path, name: String, foot_lock: bool) -> Result<Box<dyn TransitionMethod>, BoxError> {
            Ok(Box::new(crate::method::load(run, name, foot_lock)?))
        }
        Some(CandleTransitions { load, foot_lock: true })
    }
}

/// The RTN's defaults: the README's quick model (docs/rtn.md).
#[derive(Clone)]
pub struct RtnDefaults;

impl TrainDefaults for RtnDefaults {
    const EPOCHS: &'static str = "20";
    const OUT: &'static str = "runs/rtn";
    const SYNTH_MINUTES: &'static str = "30";
    /// Measured: 5.95 KB per frame (`--preset tiny`, 10 and 40 minutes: 167 and 488 MB peak).
    const BYTES_PER_SYNTH_FRAME: f64 = 6_500.0;
}

/// Minutes of stepping clips: `0..=600`.
fn synth_steps_minutes(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(m) if (0.0..=600.0).contains(&m) => Ok(m),
        _ => Err(format!("`{s}` is not a number of minutes: valid range 0..=600")),
    }
}

/// Arguments of `zoo train rtn`.
#[derive(Args)]
pub struct RtnArgs {
    /// The run folder, its length, seed and threads.
    #[command(flatten)]
    pub run: RunArgs<RtnDefaults>,
    /// The clips.
    #[command(flatten)]
    pub data: DataArgs<RtnDefaults>,
    /// Leave out of `--data` every clip whose file name matches this glob (e.g. a content type
    /// held out for the out-of-distribution protocol of docs/ood.md).
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Model variant (Table 4 ablations).
    #[arg(long, value_enum, default_value_t = RtnVariant::Rtn)]
    pub variant: RtnVariant,
    /// Model sizes.
    #[arg(long, value_enum, default_value_t = RtnPreset::Paper)]
    pub preset: RtnPreset,
    /// Predict a correction on top of the interpolation of context and target instead of the
    /// next frame (the Delta-interpolator idea of Oreshkin et al. 2022; `interp_residual` in
    /// config.json): an untrained model is the interpolation, and what the network learns is
    /// added to it. On by default: it learns faster and stays near interpolation on motion the
    /// data lacks (docs/ood.md). `--interp-residual false` trains the paper's RTN, which
    /// predicts the next frame itself.
    #[arg(long, default_value_t = true, num_args = 0..=1, default_missing_value = "true", action = clap::ArgAction::Set)]
    pub interp_residual: bool,
    /// Train the terrain-aware RTN (RTN sec. 3.2: the local terrain patch under the root feeds
    /// the frame encoder; `terrain` in config.json). Every clip needs its heightmap: `--data`
    /// written by `zoo data synth --terrain` (`NAME.terrain.json` beside each clip), or without
    /// `--data` synthetic locomotion over uneven terrain generated in memory. The windows stay
    /// in the clips' world frame, the heightmaps'. Run the model with `zoo transition
    /// --heightmap` or the runtime's `TransitionState::set_heightmap`.
    #[arg(long)]
    pub terrain: bool,
    /// Augment the training windows on the fly with motion the data lacks (comma-separated;
    /// stored in config.json as `train.augment`): `reverse` (time reversal, 30% of the windows:
    /// forward walks become backward walks), `mirror` (left-right mirroring, 50%, joints
    /// paired by name: `_L`/`_R`, `.L`/`.R`, `Left`/`Right`), `speed` (30%, resampled at a
    /// factor drawn from 0.7-1.2, or from `--speed-range`). Epochs keep their size; validation
    /// is never augmented.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub augment: Vec<RtnAugment>,
    /// The speed factors of `--augment speed`, SLOWEST-FASTEST (e.g. `0.7-2.0`: up to twice as
    /// fast, walks towards jogging); above 1.2 the training windows are lengthened to hold the
    /// fastest [default: 0.7-1.2].
    #[arg(long, value_name = "SLOWEST-FASTEST", value_parser = zoo_nn::args::speed_range)]
    pub speed_range: Option<(f32, f32)>,
    /// Minutes of the synthetic generator's stepping clips (walks made mostly of side and back
    /// steps, `zoo_data::synth::generate_stepping`) mixed into the training split of `--data`;
    /// its skeleton is bandai2's, so the data must be on it. 0: none.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = synth_steps_minutes)]
    pub synth_steps: f64,
    /// Minutes of the synthetic generator's jogging and running clips
    /// (`zoo_data::synth::generate_running`, 2 - 4.8 m/s) mixed into the training split of
    /// `--data`, for data without running; its skeleton is bandai2's, so the data must be on
    /// it. 0: none.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true, value_parser = synth_steps_minutes)]
    pub synth_runs: f64,
    /// Mini-batch size [default: the preset's; paper: 32].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::batch_size)]
    pub batch_size: Option<usize>,
    /// AMSGrad learning rate [default: the preset's; paper: 5e-4].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::learning_rate)]
    pub lr: Option<f64>,
    /// Decay of a moving average of the weights kept beside the trained ones (not in the
    /// paper). Each epoch both are validated and the better one becomes the best checkpoint;
    /// 0 keeps no average (the paper's recipe exactly).
    #[arg(long, default_value_t = 0.999, allow_hyphen_values = true, value_parser = zoo_nn::args::decay)]
    pub ema: f64,
    /// Train over every transition length from SHORTEST to LONGEST frames, one drawn per
    /// mini-batch, validated at 5, 15, 30 and 45 within the range; the windows hold the longest.
    /// `N-N` trains one length, as the paper does (`30-30`: its 30 frames) [default: 5-45, the
    /// benchmark's lengths; the tiny preset: its one length].
    #[arg(long, value_name = "SHORTEST-LONGEST", value_parser = zoo_nn::args::length_range)]
    pub lengths: Option<[usize; 2]>,
    /// Values of the time-to-arrival embedding the frame encoder reads (the frames left to the
    /// target, Harvey et al. 2020), an even number up to 256; 0 for none [default: 16 over
    /// several lengths, none for one].
    #[arg(long, value_name = "DIMS", value_parser = clap::value_parser!(u16).range(0..=256))]
    pub time_to_arrival: Option<u16>,
}

/// Runs `zoo train rtn` ([`crate::train_run`]).
fn train(a: RtnArgs) -> Result<(), BoxError> {
    let o = RtnRunOptions {
        data: a.data.spec(a.exclude_glob.clone(), a.run.seed)?,
        run: a.run.spec(),
        variant: a.variant,
        preset: a.preset,
        interp_residual: a.interp_residual,
        terrain: a.terrain,
        augment: a.augment,
        synth_steps: a.synth_steps,
        synth_runs: a.synth_runs,
        speed_range: a.speed_range,
        batch_size: a.batch_size,
        lr: a.lr,
        ema: a.ema,
        lengths: a.lengths,
        time_to_arrival: a.time_to_arrival.map(usize::from),
    };
    Ok(crate::train_run::run(&o, &zoo_nn::progress::Stderr)?)
}
