//! `zoo bench`: the in-betweening benchmark.

use clap::Args;

/// Arguments of `zoo bench`.
#[derive(Args)]
pub struct BenchArgs {
    /// Dataset folder (training split gives statistics; validation split gives test windows).
    #[arg(long)]
    pub data: std::path::PathBuf,
}

/// Runs the benchmark.
pub fn run(_a: BenchArgs) -> anyhow::Result<()> {
    anyhow::bail!("not yet")
}
