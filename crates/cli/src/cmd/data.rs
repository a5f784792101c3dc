//! `zoo data ...`: dataset statistics and synthetic data.

use clap::{Args, Subcommand};

/// `zoo data` subcommands.
#[derive(Subcommand)]
pub enum DataCommand {
    /// Statistics of a BVH file or folder: clips, frames, fps, joints, root speed, foot skate.
    Stats(StatsArgs),
}

/// Arguments of `zoo data stats`.
#[derive(Args)]
pub struct StatsArgs {
    /// A `.bvh`/`.bvh.gz` file or a folder searched recursively.
    pub path: std::path::PathBuf,
    /// Also write the statistics as JSON to this file.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

/// Runs a `zoo data` subcommand.
pub fn run(cmd: DataCommand) -> anyhow::Result<()> {
    match cmd {
        DataCommand::Stats(_a) => anyhow::bail!("not yet"),
    }
}
