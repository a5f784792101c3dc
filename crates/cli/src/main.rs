//! `zoo`: train, evaluate, export and inspect learned motion-transition models.

mod args;
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
    /// Complete an animator's keys into a whole motion with a trained ARNN (`zoo complete --model DIR --keys K.json --out F.bvh`).
    Complete(cmd::complete::CompleteArgs),
}

/// Whether a panic is `println!` failing on a closed pipe (`zoo data stats ... | head`).
fn is_broken_pipe(info: &std::panic::PanicHookInfo) -> bool {
    let payload = info.payload();
    let text = payload.downcast_ref::<String>().map(String::as_str).or_else(|| payload.downcast_ref::<&str>().copied());
    text.is_some_and(|t| t.contains("failed printing to stdout") && t.contains("Broken pipe"))
}

fn main() -> anyhow::Result<()> {
    // Rust ignores SIGPIPE, so printing to a pipe whose reader has gone makes `println!` panic:
    // end quietly instead, like a tool killed by SIGPIPE would, without a panic message.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if is_broken_pipe(info) {
            std::process::exit(0);
        }
        default_hook(info)
    }));
    let cli = Cli::parse();
    match cli.command {
        Command::Data(c) => cmd::data::run(c),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Train(c) => cmd::train::run(c),
        Command::Transition(a) => cmd::transition::run(a),
        Command::Decompress(a) => cmd::decompress::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Complete(a) => cmd::complete::run(a),
    }
}
