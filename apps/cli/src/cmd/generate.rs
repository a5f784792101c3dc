//! `zoo generate`: random motion synthesis of any length with a trained RNN-GMM (and its
//! refiner), streamed to BVH with the contact labels in a JSON file beside it
//! ([`zoo_rnngmm::run::generate_files`]).

use anyhow::{Context, bail};
use clap::Args;
use std::path::{Path, PathBuf};
use zoo_data::Progress;
use zoo_rnngmm::SynthesisOptions;
use zoo_rnngmm::run::{generate_files, load_run, start_clip};

/// Arguments of `zoo generate`.
#[derive(Args)]
pub struct GenerateArgs {
    /// Run folder of `zoo train rnn-gmm` (or one of its stage folders).
    #[arg(long)]
    pub model: PathBuf,
    /// Start clip and frame, `CLIP.bvh:FRAME`: the motion continues this clip after FRAME
    /// [default: the run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Option<String>,
    /// Frames to generate (any number: the motion is streamed to the file).
    #[arg(long, conflicts_with = "seconds", allow_hyphen_values = true, value_parser = crate::args::long_frame_count)]
    pub frames: Option<usize>,
    /// Seconds to generate (at the model's frame rate) instead of --frames.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::duration_seconds)]
    pub seconds: Option<f64>,
    /// Sequences to generate, with seeds SEED, SEED + 1, ...
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::sequences)]
    pub count: usize,
    /// Seed of the sampling: the same seed gives the same file, byte for byte.
    #[arg(long, default_value_t = 1, allow_hyphen_values = true, value_parser = crate::args::seed)]
    pub seed: u64,
    /// Output: a `.bvh` file (one sequence), or a folder that receives `seed<S>.bvh` files.
    /// Contact labels go to `<name>.contacts.json` beside each BVH.
    #[arg(long)]
    pub out: PathBuf,
    /// Scale on the mixture's standard deviations (1: the model's own spread; lower is
    /// calmer, 0 takes the chosen component's mean).
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = crate::args::temperature)]
    pub temperature: f64,
    /// Generate with the generator alone (also for a folder of the generator stage).
    #[arg(long)]
    pub no_refiner: bool,
    /// Steps of the initial state estimation (eq. 26, `0..=10000`); 0 starts from the zero state.
    #[arg(long, default_value_t = 50, value_parser = init_steps)]
    pub init_steps: usize,
    /// Also write the global joint positions of every generated frame (forward kinematics of
    /// the decoded frames) to this JSON file (docs/runtime-protocol.md, "Positions files"); for
    /// one sequence (`--count 1`).
    #[arg(long, value_name = "FILE.json")]
    pub positions: Option<PathBuf>,
}

/// The most Adam steps `--init-steps` takes (each is a forward and backward pass over the seed).
const MAX_INIT_STEPS: usize = 10_000;

fn init_steps(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(n) if n <= MAX_INIT_STEPS => Ok(n),
        _ => Err(format!("`{s}` is not a step count in the valid range 0..={MAX_INIT_STEPS}")),
    }
}

/// Output paths (BVH, contacts JSON) of sequence `seed`.
fn outputs(out: &Path, single: bool, seed: u64) -> (PathBuf, PathBuf) {
    let bvh = if single { out.to_path_buf() } else { out.join(format!("seed{seed}.bvh")) };
    let stem = bvh.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let json = bvh.with_file_name(format!("{stem}.contacts.json"));
    (bvh, json)
}

/// Checks the outputs before the long work; whether `--out` is one BVH file (else a folder).
fn check_outputs(a: &GenerateArgs) -> anyhow::Result<bool> {
    if zoo_data::clip_io::ClipFormat::of(&a.out).is_some_and(|f| f != zoo_data::clip_io::ClipFormat::Bvh) {
        bail!(
            "--out {}: `zoo generate` streams BVH of any length (a glTF file is written whole, at the end); write \
             a .bvh and convert it with `zoo data convert OUT.bvh OUT.glb`",
            a.out.display()
        );
    }
    let single = a.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh"));
    if single && a.count > 1 {
        bail!(
            "--out {} is one BVH file but --count {} asks for several sequences: give a folder as --out",
            a.out.display(),
            a.count
        );
    }
    if let Some(p) = &a.positions {
        if a.count > 1 {
            bail!(
                "--positions {} is one file but --count {} asks for several sequences: generate them one at a time",
                p.display(),
                a.count
            );
        }
        crate::cmd::check_output_file("--positions", p)?;
    }
    if single {
        crate::cmd::check_output_file("--out", &a.out)?;
    } else {
        crate::cmd::check_output_dir("--out", &a.out)?;
    }
    Ok(single)
}

/// Frames to generate: `--frames`, or `--seconds` at the model's frame rate.
fn frame_count(a: &GenerateArgs, fps: f64) -> anyhow::Result<usize> {
    Ok(match (a.frames, a.seconds) {
        (Some(f), _) => f,
        (None, Some(s)) => {
            let f = (s * fps).round();
            if !(1.0..=u32::MAX as f64).contains(&f) {
                bail!("--seconds {s} is {f} frames at {fps} fps: give at least one frame");
            }
            f as usize
        }
        (None, None) => bail!("say how long: --frames N or --seconds S"),
    })
}

/// Runs `zoo generate`.
pub fn run(a: GenerateArgs) -> anyhow::Result<()> {
    let single = check_outputs(&a)?;
    let (g, refiner) = load_run(&a.model, a.no_refiner)?;
    let frames = frame_count(&a, g.spec.fps)?;
    let from = a.from.as_deref().map(crate::args::clip_and_frame).transpose()?;
    let (clip, frame, from) = start_clip(&a.model, from.as_ref().map(|(p, f)| (p.as_path(), *f)), &g)?;
    let bar = zoo_nn::progress::Bar::new();
    bar.start((frames as u64).saturating_mul(a.count as u64), "generating (frames)");
    for i in 0..a.count as u64 {
        let seed = a.seed.wrapping_add(i);
        let opts = SynthesisOptions {
            frames,
            seed,
            temperature: a.temperature,
            init_steps: a.init_steps,
            ..SynthesisOptions::default()
        };
        let (bvh, json) = outputs(&a.out, single, seed);
        let positions = a.positions.is_some();
        let context = || format!("generating sequence {} (seed {seed})", i + 1);
        let xyz = generate_files(&g, refiner.as_ref(), (&clip, frame), &opts, (&bvh, &json), positions, &bar)
            .with_context(context)?;
        if let Some(p) = &a.positions {
            let v = serde_json::json!({
                "format": zoo_data::positions::POSITIONS_FORMAT,
                "version": 1,
                "command": "generate",
                "joints": clip.skeleton.names,
                "fps": g.spec.fps,
                "seed": opts.seed,
                "frames": xyz,
            });
            crate::cmd::write_positions(p, &v).with_context(context)?;
        }
    }
    bar.finish();
    let (first, _) = outputs(&a.out, single, a.seed);
    println!(
        "wrote {} sequence(s) of {frames} frames ({:.1} s) from {from}, {}, temperature {}: {}{}",
        a.count,
        frames as f64 / g.spec.fps,
        if refiner.is_some() { "refined" } else { "generator only" },
        a.temperature,
        first.display(),
        if a.count > 1 { " ..." } else { "" }
    );
    Ok(())
}
