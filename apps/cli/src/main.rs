//! `zoo`: train, evaluate, export and inspect learned motion-transition models.

mod args;
mod cmd;

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
    /// Join locomotion clips into one with a trained RMR (or inertialization, interpolation).
    Stitch(cmd::stitch::StitchArgs),
    /// Random motion synthesis of any length with a trained RNN-GMM (BVH + contact labels).
    Generate(cmd::generate::GenerateArgs),
    /// Clean a noisy clip by MAP optimisation through a trained RNN-GMM (`zoo denoise --model DIR IN.bvh --out OUT.bvh`).
    Denoise(cmd::denoise::DenoiseArgs),
    /// Walk a ground path (JSON or SVG) with a trained RNN-GMM by MAP optimisation (`zoo follow --model DIR --path PATH.json --out OUT.bvh`).
    Follow(cmd::follow::FollowArgs),
    /// Steer speed and heading over time with a trained RNN-GMM, batch by batch (`zoo control --model DIR --script CONTROLS.json --out OUT.bvh`).
    Control(cmd::control::ControlArgs),
    /// The synthesis benchmark (the same as `zoo bench synthesis`, kept for earlier scripts).
    #[command(hide = true)]
    BenchSynthesis(cmd::bench_synthesis::BenchSynthesisArgs),
    /// Complete an animator's keys into a whole motion with a trained ARNN (`zoo complete --model DIR --keys K.json --out F.bvh`).
    Complete(cmd::complete::CompleteArgs),
    /// Evaluate a `zoo train arnn` run on its held-out lamp sequences against interpolation (`zoo eval-arnn --model DIR`).
    EvalArnn(cmd::eval_arnn::EvalArnnArgs),
}

/// Environment of the training commands (`zoo train`, `zoo bench train`) and of path following
/// and online control (`zoo follow`, `zoo control` and their benchmarks: one core,
/// `RAYON_NUM_THREADS=1`), which must be in place
/// before candle and mimalloc read it, at their first use:
///
/// - `CANDLE_NUM_THREADS=1`: candle runs large elementwise ops on its own pool of threads
///   sized from this variable; data-parallel training already gives every core a worker of its
///   own (`--threads`), and those workers would queue on that one pool (measured: 2 workers
///   slower than 1);
/// - `MIMALLOC_PURGE_DELAY=-1`: mimalloc keeps freed pages instead of returning them to the
///   kernel, which zeroes them again when the next step allocates (a quarter of a training
///   step in a profile);
/// - for `zoo bench runtime --per-call`, only `MIMALLOC_PURGE_DELAY=-1` and `MIMALLOC_ALLOW_THP=0`: an
///   engine's allocator keeps the pages it was given, and mimalloc's transparent huge pages
///   make the first use of each 2 MB of memory a call of its own to clear it (up to 8 ms in
///   one push of a stitching stream at 64 streams, in a profile), which is the allocator's
///   cost, not the runtime's; the system allocator's figures come from
///   `apps/bench/examples/frame_budget.rs`;
/// - `RAYON_NUM_THREADS=<the cores available>` (the size rayon gives its pool anyway): candle
///   asks for its thread count at every matmul, and without this variable it counts the
///   physical cores by reading `/proc/cpuinfo` each time (2-3% of a training step in a
///   profile, more with two workers).
///
/// Setting the environment of a running program is `unsafe` in Rust 2024 (other threads may
/// read it), so the process replaces itself once (`exec`, same process id, same arguments)
/// with these variables set. Variables the user set are kept; setting `ZOO_TRAINING_ENV` (to
/// anything) turns this off.
fn training_environment() {
    let args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    let sub: Vec<&str> = args.iter().skip(1).take(2).filter_map(|a| a.to_str()).collect();
    // `zoo bench synthesis` runs candle on worker threads too (one sequence per worker).
    let training = sub.first() == Some(&"train")
        || sub == ["bench", "train"]
        || sub == ["bench", "synthesis"]
        || sub.first() == Some(&"bench-synthesis");
    // Path following and online control run on one core (their benchmarks report time on one).
    let one_core = matches!(sub.first(), Some(&"follow") | Some(&"control"))
        || sub == ["bench", "follow"]
        || sub == ["bench", "control"];
    // The runtime's per-call benchmark: only the allocator's settings (below).
    let runtime =
        sub == ["bench", "runtime"] && args.iter().any(|a| a.to_str().is_some_and(|a| a.starts_with("--per-call")));
    if !(training || one_core || runtime) || std::env::var_os("ZOO_TRAINING_ENV").is_some() {
        return;
    }
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        let Ok(exe) = std::env::current_exe() else { return };
        let mut cmd = std::process::Command::new(exe);
        cmd.args(&args[1..]).env("ZOO_TRAINING_ENV", "1");
        let cores = if one_core { 1 } else { std::thread::available_parallelism().map_or(1, |n| n.get()) }.to_string();
        let vars: &[(&str, &str)] = if runtime {
            &[("MIMALLOC_PURGE_DELAY", "-1"), ("MIMALLOC_ALLOW_THP", "0")]
        } else {
            &[("CANDLE_NUM_THREADS", "1"), ("MIMALLOC_PURGE_DELAY", "-1"), ("RAYON_NUM_THREADS", &cores)]
        };
        for &(key, value) in vars {
            if std::env::var_os(key).is_none() {
                cmd.env(key, value);
            }
        }
        let err = cmd.exec(); // returns only on failure
        eprintln!("note: could not set up the training environment ({err}); training goes on without it");
    }
}

/// The error of a panic that is `println!` failing (`failed printing to stdout: ...`): a closed
/// pipe (`zoo data stats ... | head`) or a full device (`> /dev/full`).
fn stdout_failure(info: &std::panic::PanicHookInfo) -> Option<String> {
    let payload = info.payload();
    let text = payload.downcast_ref::<String>().map(String::as_str).or_else(|| payload.downcast_ref::<&str>().copied());
    text.and_then(|t| t.strip_prefix("failed printing to stdout: ")).map(str::to_string)
}

/// Whether this command line trains (`zoo train ...`, `zoo bench train`).
fn is_training() -> bool {
    let args: Vec<String> = std::env::args().skip(1).take(2).collect();
    args.first().is_some_and(|a| a == "train") || args == ["bench", "train"]
}

fn main() -> anyhow::Result<()> {
    // Rust ignores SIGPIPE, so printing to a pipe whose reader has gone makes `println!` panic.
    // A command that only prints ends quietly (exit 0), like a tool killed by SIGPIPE would,
    // without a panic message. A training has not finished: it says so and exits 1, its last
    // checkpoint kept, its lock released (an old run an `--overwrite` kept aside comes back if
    // the new run never finished an epoch). Any other failure to print (a full device) is an
    // error that names it, exit 1.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let Some(error) = stdout_failure(info) else { return default_hook(info) };
        let closed = error.contains("Broken pipe");
        if is_training() {
            eprintln!(
                "zoo: standard output failed ({error}); the training stops here: its last checkpoint is kept, \
                 continue it with --resume"
            );
            zoo_nn::run_folder::end_of_command(false);
            std::process::exit(1);
        }
        if closed {
            std::process::exit(0);
        }
        eprintln!("zoo: cannot write to standard output: {error}");
        std::process::exit(1);
    }));
    training_environment();
    if is_training() {
        stop_training_on_signals();
    }
    let result = parse().and_then(run);
    // A training that failed puts back the run its --overwrite kept aside; locks are released.
    zoo_nn::run_folder::end_of_command(result.is_ok());
    result
}

/// A training stopped by SIGINT (Ctrl-C) or SIGTERM has not finished: a thread receives the
/// signal, waits for a checkpoint write in progress to end, says that the training stopped and
/// which checkpoint is kept, releases the lock (and puts back an old run an `--overwrite` kept
/// aside, when the new run never finished an epoch) and exits with 128 + the signal's number.
#[cfg(unix)]
fn stop_training_on_signals() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    match signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) {
        Ok(mut signals) => {
            std::thread::spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    let name = if signal == SIGINT { "SIGINT" } else { "SIGTERM" };
                    zoo_nn::run_folder::stop_on_signal(name, signal);
                }
            });
        }
        Err(e) => eprintln!("note: cannot watch for SIGINT and SIGTERM ({e}); a signal ends the training at once"),
    }
}

#[cfg(not(unix))]
fn stop_training_on_signals() {}

/// The command line; `zoo train ... --resume DIR` with the options the run was started with
/// (`cmd::train_resume`).
fn parse() -> anyhow::Result<Cli> {
    use clap::{CommandFactory, FromArgMatches};
    let matches = Cli::command().get_matches();
    let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    let (Some(train), Some(def)) =
        (matches.subcommand_matches("train"), Cli::command().find_subcommand("train").cloned())
    else {
        return Ok(cli);
    };
    match cmd::train_resume::resolve(train, &def)? {
        cmd::train_resume::Resolved::Fresh(command) => {
            if let Command::Train(t) = &mut cli.command {
                t.record(command);
            }
        }
        cmd::train_resume::Resolved::Resume(argv) => cli = Cli::try_parse_from(argv)?,
        cmd::train_resume::Resolved::Restart(argv, command) => {
            cli = Cli::try_parse_from(argv)?;
            if let Command::Train(t) = &mut cli.command {
                t.record(command);
            }
        }
        cmd::train_resume::Resolved::AsGiven => {}
    }
    Ok(cli)
}

/// Every path of a command line, by role (inputs, run folders, datasets, outputs), for the one
/// check of `cmd::io_check` that every command goes through before its work.
fn io_of(command: &Command) -> cmd::io_check::Io {
    use cmd::bench::BenchCommand as B;
    use cmd::data::DataCommand as D;
    let io = cmd::io_check::Io::default();
    match command {
        Command::Data(D::Stats(a)) => io.data("the dataset", Some(&a.path)).output("--json", a.json.as_deref()),
        Command::Data(D::Synth(a)) => io.output_dir("--out", Some(&a.out)),
        Command::Data(D::Luxo(a)) => {
            io.input("--lamp", a.lamp.as_deref()).input("--init", a.init.as_deref()).output_dir("--out", Some(&a.out))
        }
        Command::Data(D::Convert(a)) => {
            io.input("the input clip", Some(&a.input)).output("the output clip", Some(&a.output))
        }
        Command::Data(D::Resample(a)) => {
            io.input("the input clip", Some(&a.input)).output("the output clip", Some(&a.output))
        }
        Command::Bench(a) => match &a.command {
            None => io
                .data("--data", a.data.as_deref())
                .data("--test-data", a.test_data.as_deref())
                .input("--reference", a.reference.as_deref())
                .output("--json", a.json.as_deref())
                .output_dir("--save-bvh", a.save_bvh.as_deref()),
            Some(B::Runtime(r)) => io
                .input("--model", Some(&r.model))
                .input("--onnxruntime", r.onnxruntime.as_deref())
                .output("--json", r.json.as_deref()),
            Some(B::Keyframes(k)) => io
                .input("--model", Some(&k.runtime.model))
                .input("--against", k.against.as_deref())
                .input("--onnxruntime", k.runtime.onnxruntime.as_deref())
                .output("--json", k.runtime.json.as_deref()),
            Some(B::Train(t)) => io.output("--json", t.json.as_deref()),
            Some(B::Stitch(s)) => io
                .data("--data", Some(&s.data))
                .data("--test-data", s.test_data.as_deref())
                .output("--json", s.json.as_deref()),
            Some(B::Synthesis(s)) => {
                io.model("--model", Some(&s.model)).data("--data", Some(&s.data)).output("--json", s.json.as_deref())
            }
            Some(B::Denoise(s)) => {
                io.model("--model", Some(&s.model)).data("--data", Some(&s.data)).output("--json", s.json.as_deref())
            }
            Some(B::Follow(s)) => s
                .from
                .iter()
                .fold(io, |io, f| io.clip_spec("--from", Some(f)))
                .model("--model", Some(&s.model))
                .input("--onnx", s.onnx.as_deref())
                .data("--data", s.data.as_deref())
                .output_dir("--plots", s.plots.as_deref())
                .output("--json", s.json.as_deref()),
            Some(B::Control(s)) => io
                .clip_spec("--from", s.from.as_deref())
                .model("--model", Some(&s.model))
                .input("--onnx", s.onnx.as_deref())
                .input("--script", s.script.as_deref())
                .data("--data", s.data.as_deref())
                .output_dir("--plots", s.plots.as_deref())
                .output("--json", s.json.as_deref()),
        },
        Command::Train(t) => {
            let m = t.options();
            let path = |id: &str| m.try_get_one::<std::path::PathBuf>(id).ok().flatten().cloned();
            io.data("--data", path("data").as_deref()).output_dir("--out", path("out").as_deref())
        }
        Command::Transition(a) => io
            .model("--model", Some(&a.model))
            .clip_spec("--from", Some(&a.from))
            .clip_spec("--to", Some(&a.to))
            .input("--rig-map", a.rig_map.as_deref())
            .input("--heightmap", a.heightmap.as_deref())
            .output("--out", Some(&a.out))
            .output("--positions", a.positions.as_deref()),
        Command::Decompress(a) => {
            io.model("--model", Some(&a.model)).input("the input clip", Some(&a.input)).output("--out", Some(&a.out))
        }
        Command::Export(a) => io
            .model("--onnx", Some(&a.onnx))
            .input("--skeleton", a.skeleton.as_deref())
            .output("--out", Some(&a.out))
            .output("--reference", a.reference.as_deref()),
        Command::Render(a) => a
            .compare
            .iter()
            .fold(io.input("the clip", Some(&a.clip)), |io, c| io.input("--compare", Some(c)))
            .input("--terrain", a.terrain.as_deref())
            .output("--out", Some(&a.out)),
        Command::Stitch(a) => {
            let io = a.clips.iter().fold(io, |io, c| io.clip_spec("the clip", Some(c)));
            let saved = a.save_input.then(|| cmd::stitch::input_path(&a.out));
            io.model("--model", a.model.as_deref())
                .output("--out", Some(&a.out))
                .output("--save-input", saved.as_deref())
                .output("--positions", a.positions.as_deref())
        }
        Command::Generate(a) => {
            let io = io.model("--model", Some(&a.model)).clip_spec("--from", a.from.as_deref());
            let io = if a.out.is_dir() {
                io.output_dir("--out", Some(&a.out))
            } else {
                io.output_with_contacts("--out", &a.out)
            };
            io.output("--positions", a.positions.as_deref())
        }
        Command::Denoise(a) => io
            .model("--model", Some(&a.model))
            .input("the input clip", Some(&a.input))
            .output_with_contacts("--out", &a.out),
        Command::Follow(a) => io
            .model("--model", Some(&a.model))
            .input("--path", Some(&a.path))
            .output_with_contacts("--out", &a.out)
            .output("--plot", a.plot.as_deref()),
        Command::Control(a) => io
            .model("--model", Some(&a.model))
            .input("--script", Some(&a.script))
            .output_with_contacts("--out", &a.out)
            .output("--plot", a.plot.as_deref()),
        Command::BenchSynthesis(s) => {
            io.model("--model", Some(&s.model)).data("--data", Some(&s.data)).output("--json", s.json.as_deref())
        }
        Command::Complete(a) => io
            .model("--model", Some(&a.model))
            .input("--keys", a.keys.as_deref())
            .input("--poses", a.poses.as_deref())
            .output("--out", Some(&a.out))
            .output("--json", a.json.as_deref())
            .output("--plot", a.plot.as_deref())
            .output("--positions", a.positions.as_deref()),
        Command::EvalArnn(a) => {
            io.model("--model", Some(&a.model)).data("--data", a.data.as_deref()).output("--json", a.json.as_deref())
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    io_of(&cli.command).check()?;
    match cli.command {
        Command::Data(c) => cmd::data::run(c),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Train(c) => cmd::train::run(c),
        Command::Transition(a) => cmd::transition::run(a),
        Command::Decompress(a) => cmd::decompress::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Stitch(a) => cmd::stitch::run(a),
        Command::Generate(a) => cmd::generate::run(a),
        Command::Denoise(a) => cmd::denoise::run(a),
        Command::Follow(a) => cmd::follow::run(a),
        Command::Control(a) => cmd::control::run(a),
        Command::BenchSynthesis(a) => cmd::bench_synthesis::run(a),
        Command::Complete(a) => cmd::complete::run(a),
        Command::EvalArnn(a) => cmd::eval_arnn::run(a),
    }
}
