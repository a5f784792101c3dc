//! The RMR's entry in the table of models ([`zoo_nn::ZooModel`]): `zoo train rmr`'s options,
//! its training and its export.

use crate::train_run::{CellArg, RmrPreset, RmrRunOptions};
use clap::{Args, FromArgMatches};
use std::path::Path;
use zoo_export::ExportError;
use zoo_format::MotionTaskKind;
use zoo_nn::train_args::{DataArgs, RunArgs, TrainDefaults};
use zoo_nn::zoo_model::{BoxError, ExportOptions, Exported, Portable, ZooModel};

/// The RMR in the table of models.
pub struct RmrModel;

impl ZooModel for RmrModel {
    fn kind(&self) -> &'static str {
        crate::export::MODEL_KIND
    }

    fn about(&self) -> &'static str {
        "The Recurrent Motion Refiner for locomotion stitching (Kim et al. 2023)"
    }

    fn purpose(&self) -> &'static str {
        "stitching locomotion clips (`zoo stitch`, `zoo bench stitch`)"
    }

    fn task(&self) -> MotionTaskKind {
        MotionTaskKind::Stitch
    }

    fn train_command(&self) -> clap::Command {
        RmrArgs::augment_args(clap::Command::new(self.kind()).about(self.about()))
    }

    fn train(&self, options: &clap::ArgMatches, command: Vec<(String, Vec<String>)>) -> Result<(), BoxError> {
        let mut a = RmrArgs::from_arg_matches(options)?;
        a.run.command = command;
        let epochs_given = options.value_source("epochs") == Some(clap::parser::ValueSource::CommandLine);
        train(a, epochs_given)
    }

    fn export(&self, run: &Path, options: &ExportOptions) -> Result<Exported, ExportError> {
        let model = crate::export::export_run(run, options)?;
        let what = "RMR window refiner";
        Ok(Exported { model, what, with: "with its configuration and statistics".to_string() })
    }

    fn portable(&self, run: &Path, frames: Option<u32>) -> Result<Portable, ExportError> {
        let (frames, source) = crate::export::portable_window(run, frames)?;
        Ok(Portable::Window(frames, source.to_string()))
    }
}

/// The RMR's defaults.
#[derive(Clone)]
pub struct RmrDefaults;

impl TrainDefaults for RmrDefaults {
    const EPOCHS: &'static str = "10";
    const OUT: &'static str = "runs/rmr";
}

/// Arguments of `zoo train rmr`.
#[derive(Args)]
pub struct RmrArgs {
    /// The run folder, its length, seed and threads.
    #[command(flatten)]
    pub run: RunArgs<RmrDefaults>,
    /// The clips.
    #[command(flatten)]
    pub data: DataArgs<RmrDefaults>,
    /// Leave out of `--data` every clip whose file name matches this glob (e.g. a content type
    /// held out to test stitching on moves the model never saw, as docs/ood.md does for the RTN).
    #[arg(long)]
    pub exclude_glob: Option<String>,
    /// Model sizes (`quick`: to try the tools in minutes, its own epochs unless `--epochs` is
    /// given; docs/rmr.md).
    #[arg(long, value_enum, default_value_t = RmrPreset::Paper)]
    pub preset: RmrPreset,
    /// Refiner cell (Table 1 ablation) [default: the preset's, bgru].
    #[arg(long, value_enum)]
    pub cell: Option<CellArg>,
    /// Frames of the beginning loss, `T_begin` (Table 2: 3, 5, 10; 0 turns it off) [default: 5].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::frames_or_zero)]
    pub t_begin: Option<usize>,
    /// Train without the root trajectory loss (the Figure 9 ablation).
    #[arg(long)]
    pub no_trajectory_loss: bool,
    /// The paper's decoder, predicting the pose itself, instead of our default residual
    /// decoder (a correction added to the input, starting at zero; docs/rmr.md).
    #[arg(long)]
    pub no_residual: bool,
    /// The paper's training: the raw concatenation of the clips as the refiner's input and the
    /// paper's loss alone (seam and velocity weights 0 unless given). Without it the refiner
    /// learns to refine the clips inertialized at their seams, with seam weight 4 and velocity
    /// weight 1: fewer pops and less sliding on motion it never saw (docs/rmr.md).
    #[arg(long, conflicts_with = "pre_blend")]
    pub paper: bool,
    /// Train on the aligned clips inertialized at their seams (the default; `--paper` trains on
    /// the raw concatenation). `zoo stitch` and the benchmark always inertialize the seams of
    /// what such a model refines.
    #[arg(long)]
    pub pre_blend: bool,
    /// Extra weight of the pose loss within 5 frames of each seam of the training pairs
    /// (0: the paper's loss) [default: 4; with --paper: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub seam_weight: Option<f64>,
    /// Weight of our forward-kinematics term: the lower-body positions the output's rotations
    /// give, against the ground truth's (0: the paper's loss) [default: 0; docs/rmr.md].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub fk_weight: Option<f64>,
    /// Weight of our foot-slide term: the contact joints' horizontal motion (cm per frame) on
    /// the ground truth's contact frames, by forward kinematics (0: the paper's loss) [default: 0].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub slide_weight: Option<f64>,
    /// Weight of our velocity term: each frame's change of the output's pose values against
    /// the ground truth's, weighted like the pose loss (so `--seam-weight` stresses the seams):
    /// fewer pops at the seams (0: the paper's loss) [default: 1; with --paper: 0; docs/rmr.md].
    #[arg(long, allow_hyphen_values = true, value_parser = seam_weight)]
    pub velocity_weight: Option<f64>,
    /// Units of each recurrent layer, per direction [default: the preset's; paper: 256].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::layer_width)]
    pub hidden: Option<usize>,
    /// Mini-batch size [default: the preset's; paper: 32].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::batch_size)]
    pub batch_size: Option<usize>,
    /// Adam learning rate [default: the preset's; paper: 1e-4].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::learning_rate)]
    pub lr: Option<f64>,
    /// Database segments start every this many frames (1: every frame, the exact search over
    /// every segment; 2 halves the databases and the planning time) [default: the preset's].
    #[arg(long, allow_hyphen_values = true, value_parser = zoo_nn::args::frame_count)]
    pub database_stride: Option<usize>,
}

/// `--seam-weight`, `--fk-weight`, `--slide-weight`, `--velocity-weight`: a weight in `[0, 1000]`.
fn seam_weight(s: &str) -> Result<f64, String> {
    zoo_nn::args::real_in(s, zoo_nn::args::Interval::closed(0.0, 1000.0), "")
}

/// Runs `zoo train rmr`.
fn train(a: RmrArgs, epochs_given: bool) -> Result<(), BoxError> {
    let (run, data) = zoo_nn::train_args::specs(&a.run, &a.data, a.exclude_glob.clone())?;
    let o = RmrRunOptions {
        preset: a.preset,
        epochs_given,
        cell: a.cell,
        t_begin: a.t_begin,
        no_trajectory_loss: a.no_trajectory_loss,
        no_residual: a.no_residual,
        paper: a.paper && !a.pre_blend,
        seam_weight: a.seam_weight,
        fk_weight: a.fk_weight,
        slide_weight: a.slide_weight,
        velocity_weight: a.velocity_weight,
        hidden: a.hidden,
        batch_size: a.batch_size,
        lr: a.lr,
        database_stride: a.database_stride,
        run,
        data,
    };
    Ok(crate::train_run::run(&o, &zoo_nn::progress::Bar::new())?)
}
