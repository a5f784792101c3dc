//! `zoo`: train, evaluate, export and inspect learned motion-transition models.

mod cmd;
mod methods;
mod registry;
mod render;

use clap::{Parser, Subcommand};

// candle allocates a fresh buffer per op; glibc's malloc returns large ones to the kernel and
// page-faults them back in every training step (about 30% of a step), mimalloc does not.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// zoo: neural motion transitions from training to game engine.
#[derive(Parser)]
#[command(name = "zoo", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inspect and generate motion data.
    #[command(subcommand)]
    Data(cmd::data::DataCommand),
    /// Run the in-betweening benchmark (LaFAN1 protocol) on a BVH dataset.
    Bench(cmd::bench::BenchArgs),
    /// Train a model of the zoo.
    #[command(subcommand)]
    Train(cmd::train::TrainCommand),
    /// Generate a transition between two clips with a trained RTN.
    Transition(cmd::transition::TransitionArgs),
    /// Rebuild a clip from sparse keyframes with a trained RTN (temporal super-resolution).
    Decompress(cmd::decompress::DecompressArgs),
    /// Export a trained model as one ONNX file for the engine runtime (`zoo export --onnx DIR --out F.onnx`).
    Export(cmd::export::ExportArgs),
    /// Draw clips as stick figures: an animated GIF or a PNG contact sheet.
    Render(cmd::render::RenderArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Data(c) => cmd::data::run(c),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Train(c) => cmd::train::run(c),
        Command::Transition(a) => cmd::transition::run(a),
        Command::Decompress(a) => cmd::decompress::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Render(a) => cmd::render::run(a),
    }
}
