//! `zoo eval-arnn`: the completion test of a `zoo train arnn` run folder on its held-out lamp
//! sequences against linear and spline interpolation of the same keys
//! ([`zoo_arnn::train_run::evaluate_run`]).

use anyhow::bail;
use clap::Args;
use std::path::PathBuf;
use zoo_arnn::train_run::Checkpoint;

/// Arguments of `zoo eval-arnn`.
#[derive(Args)]
pub struct EvalArnnArgs {
    /// Run folder of `zoo train arnn`.
    #[arg(long)]
    pub model: PathBuf,
    /// Which weights to evaluate.
    #[arg(long, value_enum, default_value_t = Checkpoint::Best)]
    pub checkpoint: Checkpoint,
    /// The `zoo data luxo` folder the run trained on, when it has moved since (its split is
    /// rebuilt from the run's seed and test fraction).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs `zoo eval-arnn`.
pub fn run(a: EvalArnnArgs) -> anyhow::Result<()> {
    let kind = zoo_nn::checkpoint::model_kind(&a.model)?;
    if kind != "arnn" {
        bail!("--model {}: the folder holds a `{kind}` run, not an ARNN (`zoo train arnn`)", a.model.display());
    }
    if let Some(j) = &a.json {
        crate::cmd::check_output_file("--json", j)?;
    }
    let (text, report) =
        zoo_arnn::train_run::evaluate_run(&a.model, a.checkpoint, a.data.as_deref(), &crate::cmd::Stderr)?;
    println!("{text}");
    if let Some(j) = &a.json {
        crate::cmd::write_json(j, &report)?;
    }
    Ok(())
}
