//! The ARNN's entry in the table of models ([`zoo_nn::ZooModel`]): `zoo train arnn`'s options
//! (hop sequences of the simulated lamp, or humanoid clips with `--valid-glob`, in either
//! design), its training and its export.

use crate::train_run::{ArnnDesign, ArnnPreset, ArnnRunOptions, ArnnVariant, NoMemoryOutputArg};
use clap::{Args, FromArgMatches};
use std::path::{Path, PathBuf};
use zoo_data::benchmark::TransitionMethod;
use zoo_export::ExportError;
use zoo_format::MotionTaskKind;
use zoo_nn::train_args::{RunArgs, TrainDefaults};
use zoo_nn::zoo_model::{BoxError, CandleTransitions, ExportOptions, Exported, Portable, ZooModel};

/// The ARNN (both designs) in the table of models.
pub struct ArnnModel;

impl ZooModel for ArnnModel {
    fn kind(&self) -> &'static str {
        crate::export::MODEL_KIND
    }

    fn about(&self) -> &'static str {
        "The keyframe autocompletion network ARNN (Zhang & van de Panne 2018) on the simulated lamp, or the \
         in-betweening design on humanoid clips"
    }

    fn purpose(&self) -> &'static str {
        "completing an animator's keys (`zoo complete`, `zoo bench --layout keys`)"
    }

    fn task(&self) -> MotionTaskKind {
        MotionTaskKind::Keyframes
    }

    fn train_command(&self) -> clap::Command {
        ArnnArgs::augment_args(clap::Command::new(self.kind()).about(self.about()))
    }

    fn train(&self, options: &clap::ArgMatches, command: Vec<(String, Vec<String>)>) -> Result<(), BoxError> {
        let mut a = ArnnArgs::from_arg_matches(options)?;
        a.run.command = command;
        let epochs_given = options.value_source("epochs") == Some(clap::parser::ValueSource::CommandLine);
        train(a, epochs_given)
    }

    fn export(&self, run: &Path, options: &ExportOptions) -> Result<Exported, ExportError> {
        let model = crate::export::export_run(run, options)?;
        let with = "with its metadata".to_string();
        let what = if crate::inbetween::is_inbetween_run(run) {
            "ARNN in-betweening whole-shot graph"
        } else {
            "ARNN step graph"
        };
        Ok(Exported { model, what, with })
    }

    fn candle_transitions(&self) -> Option<CandleTransitions> {
        // The humanoid ARNN, either design, on the context layout (its keys: the context and
        // the target).
        fn load(run: &Path, name: String, foot_lock: bool) -> Result<Box<dyn TransitionMethod>, BoxError> {
            if foot_lock {
                return Err(format!(
                    "method `{name}`: the ARNN in candle has no foot lock on transitions; the in-betweening design's \
                     is the runtime's (`arnn+lock:RUN_DIR`)"
                )
                .into());
            }
            if crate::inbetween::is_inbetween_run(run) {
                return Ok(Box::new(crate::humanoid::InbetweenTransitions::load(run, name)?));
            }
            Ok(Box::new(crate::humanoid::ArnnMethod::load(run, name)?))
        }
        Some(CandleTransitions { load, foot_lock: false })
    }

    fn portable(&self, run: &Path, frames: Option<u32>) -> Result<Portable, ExportError> {
        if crate::inbetween::is_inbetween_run(run) {
            return Ok(Portable::Refused(
                "--portable: the in-betweening design's graph runs whole shots of any length through a bidirectional \
                 GRU, which the portable profile (recurrent layers unrolled over a fixed number of frames) does not \
                 hold; export it without --portable"
                    .to_string(),
            ));
        }
        match frames {
            Some(_) => Err(ExportError::model(
                "--frames applies to window graphs (RMR); this model's graphs run one frame per call",
            )),
            None => Ok(Portable::Step),
        }
    }
}

/// The ARNN's defaults.
#[derive(Clone)]
pub struct ArnnDefaults;

impl TrainDefaults for ArnnDefaults {
    const EPOCHS: &'static str = "300";
    const OUT: &'static str = "runs/arnn";
}

/// Arguments of `zoo train arnn`.
#[derive(Args)]
pub struct ArnnArgs {
    /// The run folder, its length (the curriculum spans the epochs: with `--time-limit`,
    /// choose epochs that fit in it), seed and threads.
    #[command(flatten)]
    pub run: RunArgs<ArnnDefaults>,
    /// Folder written by `zoo data luxo`; without it, lamp hops are generated in memory
    /// (`--sequences`, `--k-max`, deterministic for `--seed`). With `--valid-glob`: a folder
    /// (or file) of humanoid BVH clips instead (docs/arnn.md, "Humanoid keys").
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Train on humanoid BVH clips in `--data` (not the lamp): clips whose file name matches
    /// this glob are the validation split (bandai2: `'*_youthful_*'`), the others the training
    /// split; keys are drawn every 5-30 frames and in the in-betweening benchmark's layout.
    #[arg(long, requires = "data")]
    pub valid_glob: Option<String>,
    /// With `--valid-glob`: leave out of both splits every clip of `--data` whose file name
    /// matches this glob (a content held out for the out-of-distribution protocol of
    /// docs/ood.md, so that no checkpoint is chosen on it). A resumed run keeps its own.
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Sequences generated when `--data` is not given.
    #[arg(long, default_value_t = 24, conflicts_with = "data", allow_hyphen_values = true, value_parser = zoo_nn::args::sequences)]
    pub sequences: usize,
    /// Simulated annealing iterations per run for the generated sequences (the paper's
    /// K_max = 1000; fewer is faster and gives hops closer to the hand-set one).
    #[arg(long, default_value_t = 100, conflicts_with = "data", allow_hyphen_values = true, value_parser = zoo_nn::args::anneal_iterations)]
    pub k_max: usize,
    /// Fraction of the sequences held out as the test set (whole sequences, fixed by `--seed`;
    /// 0.2 gives the paper's 240/60 of 300). The test set also picks the best checkpoint.
    #[arg(long, default_value_t = 0.2, allow_hyphen_values = true, value_parser = zoo_nn::args::unit_fraction, conflicts_with = "valid_glob")]
    pub test_fraction: f64,
    /// Model variant: the ARNN, or a comparison of Table 1 (no curriculum) or Table 2
    /// (no-memory, segregated; parameter counts matched to the ARNN's).
    #[arg(long, value_enum, default_value_t = ArnnVariant::Arnn)]
    pub variant: ArnnVariant,
    /// Which network: the paper's autoregressive ARNN, or (humanoid clips, with `--data` and
    /// `--valid-glob`, or synthetic locomotion without them) the in-betweening design, a
    /// bidirectional GRU correcting Blender's Bezier curves through the keys, every key met by
    /// construction (docs/keys-only.md). A resumed run keeps its own.
    #[arg(long, value_enum, default_value_t = ArnnDesign::Autoregressive)]
    pub design: ArnnDesign,
    /// With `--variant no-memory`: what the net's output is added to [default: interpolation]
    /// (docs/arnn.md, "Table 2 and the no-memory net's output")
    #[arg(long, value_enum)]
    pub no_memory_output: Option<NoMemoryOutputArg>,
    /// Model sizes (`quick`: the in-betweening design to try in minutes, its own epochs unless
    /// `--epochs` is given; docs/keys-only.md).
    #[arg(long, value_enum, default_value_t = ArnnPreset::Paper)]
    pub preset: ArnnPreset,
    /// With `--design inbetween` and no `--data`: minutes of synthetic locomotion to train on
    /// (every tenth clip validates) [default: 10; with --preset quick: 20].
    #[arg(long, conflicts_with = "data", allow_hyphen_values = true, value_parser = zoo_nn::args::synth_minutes)]
    pub synth_minutes: Option<f64>,
    /// With `--design inbetween --data`: minutes of the synthetic generator's locomotion (walks
    /// with turns, jogging, running; on bandai2's skeleton, which the data must be on) mixed into
    /// the training split, for moves the capture lacks (docs/ood.md); validation stays on the
    /// data's clips. A resumed run keeps its own [default: 0].
    #[arg(long, requires = "data", allow_hyphen_values = true, value_parser = zoo_nn::args::synth_minutes)]
    pub synth_mix: Option<f64>,
    /// With `--design inbetween`: the network over the shot, a bidirectional GRU or a
    /// transformer encoder (frames as tokens, positions by a distance bias; docs/keys-only.md).
    /// A resumed run keeps its own [default: bgru].
    #[arg(long, value_enum)]
    pub backbone: Option<crate::inbetween::Backbone>,
    /// With `--design inbetween`: fraction of training batches in the in-betweening benchmark's
    /// transition layout (the first 10 frames all keys, then the target 5 to 45 frames after
    /// them), for a network that also makes transitions (`zoo bench --methods arnn:RUN`); the
    /// others keep the keys' layouts [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::unit_fraction)]
    pub transition_fraction: Option<f64>,
    /// With `--design inbetween`: dropout in training, the transformer's on each block's
    /// attention and feed-forward outputs (the GRU's between its layers: none with the one layer
    /// of the default sizes). A resumed run keeps its own [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::fraction_or_zero)]
    pub dropout: Option<f64>,
    /// Sequences per batch [default: the preset's].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::batch_size)]
    pub batch_size: Option<usize>,
    /// Adam learning rate [default: the preset's; paper: 1e-3].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::learning_rate)]
    pub lr: Option<f64>,
    /// Weight of the ground penalty on the base plate sinking below the ground [default: 0,
    /// off] (docs/arnn.md, "The ground"; `zoo complete` lifts a sunken base onto the ground).
    #[arg(long, allow_hyphen_values = true, value_parser = ground_weight)]
    pub ground_weight: Option<f64>,
    /// Fraction of the epochs, at the end, trained after the curriculum with the key weight at
    /// `--frame-phase-omega` (section 9's extra training that weights the frame loss more; the
    /// curriculum's ramps then run over the other epochs; 0: the paper's schedule alone)
    /// [default: 0.25 for lamp runs, 0 for humanoid clips] (docs/arnn.md, "The frame phase")
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::fraction_or_zero)]
    pub frame_phase: Option<f64>,
    /// Key importance omega in the frame phase (the key loss weighs `100 omega` there)
    /// [default: 0.01]
    #[arg(long, allow_hyphen_values = true, value_parser = frame_phase_omega)]
    pub frame_phase_omega: Option<f64>,
}

/// `--frame-phase-omega`: a weight in [0, 1].
fn frame_phase_omega(s: &str) -> Result<f64, String> {
    zoo_nn::args::real_in(s, zoo_nn::args::Interval::closed(0.0, 1.0), "")
}

/// `--ground-weight`: a weight in [0, 1e6].
fn ground_weight(s: &str) -> Result<f64, String> {
    zoo_nn::args::real_in(s, zoo_nn::args::Interval::closed(0.0, 1e6), "")
}

/// Runs `zoo train arnn`.
fn train(a: ArnnArgs, epochs_given: bool) -> Result<(), BoxError> {
    let o = ArnnRunOptions {
        run: a.run.spec(),
        data: a.data,
        valid_glob: a.valid_glob,
        exclude_glob: a.exclude_glob,
        sequences: a.sequences,
        k_max: a.k_max,
        test_fraction: a.test_fraction,
        variant: a.variant,
        design: a.design,
        no_memory_output: a.no_memory_output,
        preset: a.preset,
        epochs_given,
        synth_minutes: a.synth_minutes,
        synth_mix: a.synth_mix,
        transition_fraction: a.transition_fraction,
        dropout: a.dropout,
        backbone: a.backbone,
        batch_size: a.batch_size,
        lr: a.lr,
        ground_weight: a.ground_weight,
        frame_phase: a.frame_phase,
        frame_phase_omega: a.frame_phase_omega,
    };
    Ok(crate::train_run::run(&o, &zoo_nn::progress::Bar::new())?)
}
