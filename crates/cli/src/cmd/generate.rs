//! `zoo generate`: random motion synthesis of any length with a trained RNN-GMM (and its
//! refiner), streamed to BVH with the contact labels in a JSON file beside it.

use crate::cmd::train_rnngmm::START_FILE;
use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;
use std::path::{Path, PathBuf};
use zoo_motion::Clip;
use zoo_rnngmm::checkpoint::LoadedGenerator;
use zoo_rnngmm::refiner::{REFINER_FILE, RefinerNets};
use zoo_rnngmm::{SynthesisOptions, SynthesisStream};

/// Frames generated per chunk (memory holds one chunk).
const CHUNK: usize = 300;

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

/// The model of a run folder: the generator, and the refiner unless `no_refiner`. A folder of
/// another kind, a refiner without its generator and a generator stage without a refiner (when
/// one is wanted) are refused with what to do.
pub fn load_model(dir: &Path, no_refiner: bool) -> anyhow::Result<(LoadedGenerator, Option<RefinerNets>)> {
    let kind = crate::registry::model_kind(dir)?;
    if kind != "rnn-gmm" {
        bail!("{} holds a `{kind}` model; `zoo generate` runs an `rnn-gmm` run folder", dir.display());
    }
    let weights = dir.join(zoo_rnngmm::checkpoint::WEIGHTS_FILE);
    if !weights.is_file() {
        let refiner = if dir.join(REFINER_FILE).is_file() {
            " (it has a refiner, but a refiner only runs on the generator it was trained with)"
        } else {
            ""
        };
        bail!(
            "{} has no generator weights ({} is missing){refiner}: copy the whole run folder",
            dir.display(),
            weights.display()
        );
    }
    let device = candle_core::Device::Cpu;
    if no_refiner {
        let g = zoo_rnngmm::checkpoint::load(dir, &device)
            .with_context(|| format!("loading the generator in {}", dir.display()))?;
        return Ok((g, None));
    }
    if !dir.join(REFINER_FILE).is_file() {
        bail!(
            "{} holds no refiner ({REFINER_FILE}): train it with `zoo train rnn-gmm --stage refiner --out {}`, or \
             generate with --no-refiner",
            dir.display(),
            dir.display()
        );
    }
    let m = zoo_rnngmm::refiner::load(dir, &device)
        .with_context(|| format!("loading the generator and refiner in {}", dir.display()))?;
    Ok((m.generator, Some(m.nets)))
}

/// The start clip and frame: `--from CLIP.bvh:FRAME`, or the run folder's start clip.
pub fn start_clip(dir: &Path, from: Option<&str>, g: &LoadedGenerator) -> anyhow::Result<(Clip, usize, String)> {
    let (path, frame) = match from {
        Some(s) => crate::cmd::transition::clip_and_frame(s)?,
        None => {
            let p = dir.join(START_FILE);
            if !p.is_file() {
                bail!("{} has no {START_FILE}: give a start clip with --from CLIP.bvh:FRAME", dir.display());
            }
            (p, usize::MAX)
        }
    };
    let clip = crate::cmd::transition::read_clip(&path)?;
    let frame = if frame == usize::MAX { clip.frames().saturating_sub(1).min(29) } else { frame };
    if let Some(d) = g.spec.skeleton.topology_difference(&clip.skeleton) {
        bail!(
            "{} is on another skeleton than the model's ({d}); start from a clip of the training skeleton",
            path.display()
        );
    }
    if frame >= clip.frames() {
        bail!("{}: frame {frame} is past the clip's last frame {}", path.display(), clip.frames().saturating_sub(1));
    }
    Ok((clip, frame, format!("{}:{frame}", path.display())))
}

/// Writes a clip stream as BVH: the hierarchy and the frame count first, then chunk after chunk.
struct BvhStream {
    w: std::io::BufWriter<std::fs::File>,
    header: Option<String>,
}

impl BvhStream {
    fn create(path: &Path) -> anyhow::Result<Self> {
        let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(BvhStream { w: std::io::BufWriter::new(f), header: None })
    }

    /// Appends `clip`'s frames (`total`: the frame count of the whole file, written with the
    /// first chunk).
    fn write(&mut self, clip: &Clip, total: usize) -> anyhow::Result<()> {
        let text = zoo_data::bvh::to_string(clip);
        let (hierarchy, motion) = text.split_once("MOTION\n").context("BVH text without MOTION")?;
        // "Frames: N\nFrame Time: T\n" then one line per frame.
        let mut lines = motion.splitn(3, '\n');
        let (_, time, rows) = (lines.next(), lines.next().unwrap_or_default(), lines.next().unwrap_or_default());
        match &self.header {
            None => {
                write!(self.w, "{hierarchy}MOTION\nFrames: {total}\n{time}\n")?;
                self.header = Some(hierarchy.to_string());
            }
            Some(h) if h != hierarchy => bail!("the hierarchy changed between chunks (a joint gained channels)"),
            Some(_) => {}
        }
        self.w.write_all(rows.as_bytes())?;
        Ok(())
    }

    fn finish(self) -> anyhow::Result<()> {
        let f = self.w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        Ok(())
    }
}

/// Output paths (BVH, contacts JSON) of sequence `seed`.
fn outputs(out: &Path, single: bool, seed: u64) -> (PathBuf, PathBuf) {
    let bvh = if single { out.to_path_buf() } else { out.join(format!("seed{seed}.bvh")) };
    let stem = bvh.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let json = bvh.with_file_name(format!("{stem}.contacts.json"));
    (bvh, json)
}

/// Generates one sequence into `bvh` and `json` (written to temporary names, renamed at the end).
fn generate_one(
    g: &LoadedGenerator,
    refiner: Option<&RefinerNets>,
    clip: &Clip,
    frame: usize,
    opts: &SynthesisOptions,
    (bvh, json): (&Path, &Path),
    positions: Option<&Path>,
    pb: &ProgressBar,
) -> anyhow::Result<()> {
    let tmp = |p: &Path| p.with_file_name(format!(".{}.tmp", p.file_name().unwrap_or_default().to_string_lossy()));
    let (bvh_tmp, json_tmp) = (tmp(bvh), tmp(json));
    let result = (|| -> anyhow::Result<()> {
        let mut stream = SynthesisStream::new(g, refiner, clip, frame, opts)?;
        // The root always carries position channels, so every chunk has the same hierarchy.
        let mut out = BvhStream::create(&bvh_tmp)?;
        let mut cj = std::io::BufWriter::new(
            std::fs::File::create(&json_tmp).with_context(|| format!("creating {}", json_tmp.display()))?,
        );
        write!(
            cj,
            "{{\n\"fps\": {},\n\"frames\": {},\n\"feet\": [\"left\", \"right\"],\n\"contacts\": [",
            g.spec.fps, opts.frames
        )?;
        let mut done = 0;
        let mut frames_xyz = Vec::new();
        while done < opts.frames {
            let n = CHUNK.min(opts.frames - done);
            let mut chunk = stream.next_chunk(n)?;
            chunk.motion.clip.skeleton.channels[0].position = true;
            out.write(&chunk.motion.clip, opts.frames)?;
            if positions.is_some() {
                frames_xyz.extend(zoo_data::positions::clip_positions(&chunk.motion.clip));
            }
            for (i, c) in chunk.motion.contacts.iter().enumerate() {
                let sep = if done + i == 0 { "\n" } else { ",\n" };
                write!(cj, "{sep}[{}, {}]", c[0] as u8, c[1] as u8)?;
            }
            done += n;
            pb.inc(n as u64);
        }
        writeln!(cj, "\n]\n}}")?;
        out.finish()?;
        cj.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&bvh_tmp, bvh).with_context(|| format!("writing {}", bvh.display()))?;
        std::fs::rename(&json_tmp, json).with_context(|| format!("writing {}", json.display()))?;
        if let Some(p) = positions {
            let v = serde_json::json!({
                "format": zoo_data::positions::POSITIONS_FORMAT,
                "version": 1,
                "command": "generate",
                "joints": clip.skeleton.names,
                "fps": g.spec.fps,
                "seed": opts.seed,
                "frames": frames_xyz,
            });
            crate::cmd::write_positions(p, &v)?;
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&bvh_tmp);
        let _ = std::fs::remove_file(&json_tmp);
    }
    result
}

/// Runs `zoo generate`.
pub fn run(a: GenerateArgs) -> anyhow::Result<()> {
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
    let (g, refiner) = load_model(&a.model, a.no_refiner)?;
    let frames = match (a.frames, a.seconds) {
        (Some(f), _) => f,
        (None, Some(s)) => {
            let f = (s * g.spec.fps).round();
            if !(1.0..=u32::MAX as f64).contains(&f) {
                bail!("--seconds {s} is {f} frames at {} fps: give at least one frame", g.spec.fps);
            }
            f as usize
        }
        (None, None) => bail!("say how long: --frames N or --seconds S"),
    };
    let (clip, frame, from) = start_clip(&a.model, a.from.as_deref(), &g)?;
    let pb = ProgressBar::new((frames as u64).saturating_mul(a.count as u64));
    pb.set_style(
        ProgressStyle::with_template("generating [{bar:30}] {pos}/{len} frames  {per_sec}  {elapsed}<{eta}")
            .context("progress bar template")?,
    );
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
        generate_one(&g, refiner.as_ref(), &clip, frame, &opts, (&bvh, &json), a.positions.as_deref(), &pb)
            .with_context(|| format!("generating sequence {} (seed {seed})", i + 1))?;
    }
    pb.finish_and_clear();
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
