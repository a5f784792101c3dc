//! `zoo complete`: an animator's keys completed into a whole motion by a trained ARNN
//! ([`zoo_arnn::completion`]; keys file format in docs/arnn.md, "Keys file").

use anyhow::bail;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `zoo complete`.
#[derive(Args)]
pub struct CompleteArgs {
    /// Run folder of `zoo train arnn`.
    #[arg(long)]
    pub model: PathBuf,
    /// Keys file: frames and poses (format in docs/arnn.md, example in docs/arnn-keys-example.json).
    #[arg(long)]
    pub keys: PathBuf,
    /// Output BVH of the lamp (Blender opens it).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write every completed pose (and the key misses) to this JSON file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also plot each degree of freedom over the frames (blue) with the keys (circles) into this
    /// PNG, like the paper's Figure 8.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write the network's output as is, without lifting a base that sinks below the ground
    /// onto it (docs/arnn.md, "The ground").
    #[arg(long)]
    pub no_ground: bool,
    /// Frames per second of the output [default: the keys file's `fps`, else 50].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::fps)]
    pub fps: Option<f64>,
    /// Also write the global joint positions of every completed frame (forward kinematics of
    /// the written BVH's skeleton, its units) to this JSON file (docs/runtime-protocol.md,
    /// "Positions files").
    #[arg(long, value_name = "FILE.json")]
    pub positions: Option<PathBuf>,
}

/// Runs `zoo complete`.
pub fn run(a: CompleteArgs) -> anyhow::Result<()> {
    let kind = zoo_nn::checkpoint::model_kind(&a.model)?;
    if kind != "arnn" {
        bail!(
            "--model {}: `zoo complete` runs an ARNN run folder (`zoo train arnn`), this one holds a `{kind}` model",
            a.model.display()
        );
    }
    crate::cmd::check_output_file("--out", &a.out)?;
    for (option, path) in [("--json", &a.json), ("--plot", &a.plot), ("--positions", &a.positions)] {
        if let Some(p) = path {
            crate::cmd::check_output_file(option, p)?;
        }
    }
    let o = zoo_arnn::completion::CompleteOptions {
        model: a.model,
        keys: a.keys,
        out: a.out,
        json: a.json,
        plot: a.plot,
        no_ground: a.no_ground,
        fps: a.fps,
        positions: a.positions,
    };
    println!("{}", zoo_arnn::completion::complete_command(&o)?);
    Ok(())
}
