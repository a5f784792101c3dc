//! `zoo stitch`: join locomotion clips into one. The clips are aligned end to start (each
//! clip's first ground root on the previous clip's last one, RMR sec. 6), then the seams are
//! smoothed by the chosen method: the RMR refining window by window, its ankles placed at its
//! predicted positions and its feet locked by its predicted contacts, inertialization or interpolation at each seam, or nothing (`concat`).

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use std::time::Instant;
use zoo_data::bvh;
use zoo_motion::Clip;
use zoo_rmr::pairs::baselines::{inertialize_seams, interpolate_seams};
use zoo_rmr::pairs::{MIN_CLIP_FRAMES, StitchLayout, align_clips};
use zoo_rmr::stitch::{RefineOptions, refine_clip_full};

/// How the seams are smoothed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum StitchMethod {
    /// The Recurrent Motion Refiner of `--model` (foot lock by its predicted contacts unless
    /// `--no-foot-lock`).
    Rmr,
    /// Inertialization at each seam over `--blend-frames` frames.
    Inertialize,
    /// Interpolation across each seam over `--blend-frames` frames.
    Interp,
    /// The aligned concatenation as it is.
    Concat,
}

/// Arguments of `zoo stitch`.
#[derive(Args)]
pub struct StitchArgs {
    /// Clips to join, in order: `CLIP.bvh` or `CLIP.bvh:FROM:TO` (frames FROM..TO, TO excluded;
    /// an empty TO means the clip's end). At least two, each at least 10 frames.
    #[arg(required = true, num_args = 2.., value_name = "CLIP.bvh[:FROM:TO]")]
    pub clips: Vec<String>,
    /// Run folder of `zoo train rmr` (needed by `--method rmr`; with another method its
    /// planted foot heights and frame rate are used for the checks).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output BVH.
    #[arg(long)]
    pub out: PathBuf,
    /// How the seams are smoothed.
    #[arg(long, value_enum, default_value_t = StitchMethod::Rmr)]
    pub method: StitchMethod,
    /// RMR window `w` in frames [default: the model's, 60].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub window: Option<usize>,
    /// RMR window step `s` in frames, at most the window [default: the model's, 30; half the
    /// window when `--window` is given].
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub stride: Option<usize>,
    /// Frames of the blend at each seam (inertialize, interp) or after each RMR window.
    #[arg(long, default_value_t = 10, allow_hyphen_values = true, value_parser = crate::args::frame_count)]
    pub blend_frames: usize,
    /// Do not lock the feet by the RMR's predicted contacts.
    #[arg(long)]
    pub no_foot_lock: bool,
    /// Do not place the ankles at the RMR's predicted lower-body positions by IK (RMR sec. 5's
    /// output processing; done before the foot lock).
    #[arg(long)]
    pub no_ankle_ik: bool,
    /// Inertialize each seam over `--blend-frames` frames before the RMR refines the sequence
    /// (not in the paper). For clips cut anywhere, whose seams are larger than those of the
    /// retrieved neighbours RMR trained on: on bandai2's free cases it brings the pops from
    /// 2.29 to 1.06 (inertialization alone: 1.03) for 11% more pose error on the cases with a
    /// ground truth (docs/rmr.md).
    #[arg(long)]
    pub pre_blend: bool,
    /// Also write the raw aligned concatenation beside `--out` (`OUT.input.bvh`).
    #[arg(long)]
    pub save_input: bool,
    /// Also write the global joint positions of every output frame (forward kinematics) to this
    /// JSON file, with the RMR's predicted ankle positions (its raw lower-body positions placed
    /// in its accumulated ground roots) for `--method rmr` (docs/runtime-protocol.md, "Positions
    /// files").
    #[arg(long, value_name = "FILE.json")]
    pub positions: Option<PathBuf>,
}

/// A clip argument: path and optional frame range.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClipSpec {
    /// The BVH file.
    pub path: PathBuf,
    /// First frame (0 when not given).
    pub from: usize,
    /// End frame, excluded (`None`: the clip's end).
    pub to: Option<usize>,
}

/// Parses `CLIP.bvh` or `CLIP.bvh:FROM:TO` (`TO` may be empty).
pub fn parse_clip_spec(s: &str) -> anyhow::Result<ClipSpec> {
    let mut parts = s.rsplitn(3, ':');
    let (last, mid, head) = (parts.next(), parts.next(), parts.next());
    let frame = |v: &str| v.trim().parse::<usize>().ok();
    if let (Some(to), Some(from), Some(path)) = (last, mid, head)
        && let Some(from) = frame(from)
        && (to.is_empty() || frame(to).is_some())
    {
        if path.is_empty() {
            bail!("`{s}`: the file name before `:{from}:{to}` is empty");
        }
        let to = frame(to);
        if let Some(t) = to
            && t <= from
        {
            bail!("`{s}`: the range {from}:{t} is empty (write CLIP.bvh:FROM:TO with FROM < TO)");
        }
        return Ok(ClipSpec { path: PathBuf::from(path), from, to });
    }
    if s.is_empty() {
        bail!("an empty clip argument: expected CLIP.bvh or CLIP.bvh:FROM:TO");
    }
    // `CLIP.bvh:FROM:TO` whose numbers are not frame numbers (negative, too large): say so
    // instead of looking for a file of that name.
    let numeric = |v: &str| !v.is_empty() && v.trim().chars().all(|c| c.is_ascii_digit() || c == '-' || c == '+');
    if let (Some(to), Some(from), Some(path)) = (last, mid, head)
        && numeric(from)
        && (to.is_empty() || numeric(to))
        && !std::path::Path::new(s).exists()
    {
        bail!(
            "`{s}`: FROM and TO of {path}:FROM:TO must be frame numbers in 0..={} (found `{from}` and `{to}`)",
            crate::args::MAX_FRAME_INDEX
        );
    }
    Ok(ClipSpec { path: PathBuf::from(s), from: 0, to: None })
}

/// Reads the clips of `specs` (dummy root dropped, sign flips removed) and cuts their ranges.
pub fn read_clips(specs: &[ClipSpec]) -> anyhow::Result<Vec<Clip>> {
    specs
        .iter()
        .map(|spec| {
            let clip = zoo_data::clip_io::read_model_clip(&spec.path)
                .with_context(|| format!("reading {}", spec.path.display()))?;
            let frames = clip.frames();
            let to = spec.to.unwrap_or(frames);
            if to > frames || spec.from >= to {
                bail!(
                    "{}: the range {}:{} is outside the clip's {frames} frames (frames are 0..{frames})",
                    spec.path.display(),
                    spec.from,
                    to
                );
            }
            let clip = clip.slice(spec.from, to);
            if clip.frames() < MIN_CLIP_FRAMES {
                bail!(
                    "{} ({}..{to}) has {} frames; stitching needs at least {MIN_CLIP_FRAMES} frames per clip: give a \
                     longer range",
                    spec.path.display(),
                    spec.from,
                    clip.frames()
                );
            }
            Ok(clip)
        })
        .collect()
}

/// Why a file given as `--model` is refused, naming the model kind of an exported ONNX file.
fn model_file_message(path: &Path) -> String {
    let kind = std::fs::read(path)
        .ok()
        .and_then(|bytes| zoo_export::OnnxModel::from_bytes(&bytes, &path.display().to_string()).ok())
        .and_then(|m| m.metadata_value("zoo.model_kind").map(str::to_string));
    let what = match kind {
        Some(k) => format!("an exported `{k}` ONNX model"),
        None => "not a folder".to_string(),
    };
    format!(
        "--model {} is a file ({what}); `zoo stitch` takes the run folder of `zoo train rmr` (the folder holding \
         config.json and model.safetensors)",
        path.display()
    )
}

/// `OUT.input.bvh` beside `OUT.bvh`.
fn input_path(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "stitched".into());
    out.with_file_name(format!("{stem}.input.bvh"))
}

/// Runs `zoo stitch`.
pub fn run(a: StitchArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if a.save_input {
        crate::cmd::check_output_file("--save-input", &input_path(&a.out))?;
    }
    if let Some(p) = &a.positions {
        crate::cmd::check_output_file("--positions", p)?;
    }
    let specs = a.clips.iter().map(|s| parse_clip_spec(s)).collect::<anyhow::Result<Vec<_>>>()?;
    let model = match (&a.model, a.method) {
        (Some(dir), _) => {
            if dir.is_file() {
                bail!("{}", model_file_message(dir));
            }
            let kind = crate::registry::model_kind(dir)?;
            if kind != "rmr" {
                bail!(
                    "--model {}: the folder holds a `{kind}` model; `zoo stitch` runs an RMR run folder of `zoo train \
                     rmr`",
                    dir.display()
                );
            }
            Some(
                zoo_rmr::checkpoint::load(dir, &candle_core::Device::Cpu)
                    .with_context(|| format!("loading the RMR in {}", dir.display()))?,
            )
        }
        (None, StitchMethod::Rmr) => {
            bail!("--method rmr needs --model RUN_DIR (a folder of `zoo train rmr`); or use --method inertialize")
        }
        (None, _) => None,
    };
    let clips = read_clips(&specs)?;
    for (i, (c, spec)) in clips.iter().zip(&specs).enumerate().skip(1) {
        if let Some(why) = clips[0].skeleton.topology_difference(&c.skeleton) {
            bail!(
                "{} has another skeleton than {} ({why}): every clip must use the same rig",
                spec.path.display(),
                specs[0].path.display()
            );
        }
        if (c.fps() - clips[0].fps()).abs() > 1e-6 * clips[0].fps() {
            bail!(
                "{} is {} fps, {} is {} fps: resample clip {i} first",
                spec.path.display(),
                c.fps(),
                specs[0].path.display(),
                clips[0].fps()
            );
        }
    }
    let layout = match &model {
        Some((m, _)) => {
            let config = m.config();
            for (c, spec) in clips.iter().zip(&specs) {
                config.check_skeleton(&c.skeleton).with_context(|| format!("{}", spec.path.display()))?;
                if (c.fps() - config.fps).abs() > 1e-6 * config.fps {
                    bail!(
                        "{} is {} fps but the model was trained at {} fps: resample it first",
                        spec.path.display(),
                        c.fps(),
                        config.fps
                    );
                }
            }
            config.layout.clone()
        }
        None => StitchLayout::bandai2(&clips[0].skeleton)
            .with_context(|| format!("{}: a joint stitching reads is missing", specs[0].path.display()))?,
    };
    let aligned = align_clips(&clips, &layout, MIN_CLIP_FRAMES)?;
    let seams = aligned.starts[1..].to_vec();
    let t0 = Instant::now();
    let mut note = String::new();
    let mut predicted_ankles = None;
    let output = match a.method {
        StitchMethod::Concat => aligned.clip.clone(),
        StitchMethod::Inertialize => inertialize_seams(&aligned.clip, &seams, a.blend_frames),
        StitchMethod::Interp => interpolate_seams(&aligned.clip, &seams, a.blend_frames),
        StitchMethod::Rmr => {
            let (m, stats) = model.as_ref().expect("checked above: --method rmr has a model");
            let c = m.config();
            let window = a.window.unwrap_or(c.window);
            let stride = a.stride.unwrap_or(if a.window.is_some() { window / 2 } else { c.stride }).max(1);
            if stride > window {
                bail!("--stride {stride} is longer than the window {window}: use a stride of at most {window}");
            }
            let frames = aligned.clip.frames();
            if window > frames {
                bail!(
                    "the window of {window} frames is longer than the stitched sequence ({frames} frames): pass \
                     --window {} or longer clips",
                    frames.min(c.window)
                );
            }
            let opts = RefineOptions { window, stride, blend_frames: a.blend_frames };
            let refined = if a.pre_blend {
                note = format!(", seams inertialized over {} frames first", a.blend_frames);
                refine_clip_full(m, stats, &inertialize_seams(&aligned.clip, &seams, a.blend_frames), opts)?
            } else {
                refine_clip_full(m, stats, &aligned.clip, opts)?
            };
            predicted_ankles = Some(refined.ankles.clone());
            let mut out = refined.clip;
            if !a.no_ankle_ik {
                let moved = zoo_rmr::footlock::place_ankles(&mut out, &refined.ankles, &c.layout);
                note += &format!(", ankles placed at the predicted positions (mean move {moved:.2} units)");
            }
            if !a.no_foot_lock {
                let moved = zoo_rmr::footlock::lock_feet(&mut out, &refined.contacts, &c.layout);
                note += &format!(", feet locked by the predicted contacts (mean ankle correction {moved:.2} units)");
            }
            out
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    zoo_data::clip_io::write(&output, &a.out)?;
    if let Some(p) = &a.positions {
        let ankles = predicted_ankles.map(|v: Vec<[glam::DVec3; 2]>| {
            v.iter().map(|f| f.map(|p| [p.x as f32, p.y as f32, p.z as f32])).collect::<Vec<_>>()
        });
        let extra = serde_json::json!({ "seams": seams, "method": format!("{:?}", a.method).to_lowercase(),
            "predicted_ankles": ankles });
        crate::cmd::transition::write_json_atomically(
            p,
            &crate::cmd::transition::clip_positions_json("stitch", &output, extra),
        )?;
    }
    if a.save_input {
        let p = input_path(&a.out);
        bvh::write_file(&aligned.clip, &p).with_context(|| format!("writing {}", p.display()))?;
        println!("aligned input: {}", p.display());
    }
    println!(
        "stitched {} clips ({} frames, seams at {:?}) with {:?} in {:.3} s{note}: {}",
        clips.len(),
        output.frames(),
        seams,
        a.method,
        seconds,
        a.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_specs_parse_with_and_without_ranges() {
        let s = parse_clip_spec("a/walk.bvh").unwrap();
        assert_eq!((s.path, s.from, s.to), (PathBuf::from("a/walk.bvh"), 0, None));
        let s = parse_clip_spec("walk.bvh:10:70").unwrap();
        assert_eq!((s.path, s.from, s.to), (PathBuf::from("walk.bvh"), 10, Some(70)));
        let s = parse_clip_spec("C:/data/walk.bvh:5:").unwrap();
        assert_eq!((s.path, s.from, s.to), (PathBuf::from("C:/data/walk.bvh"), 5, None));
        let e = parse_clip_spec("walk.bvh:70:10").unwrap_err().to_string();
        assert!(e.contains("the range 70:10 is empty"), "{e}");
        // Not a range: kept as a file name.
        assert_eq!(parse_clip_spec("odd:name.bvh").unwrap().path, PathBuf::from("odd:name.bvh"));
        // Numbers that are not frame numbers: said so, not looked up as a file.
        for bad in ["walk.bvh:-1:5", "walk.bvh:0:99999999999999999999999"] {
            let e = parse_clip_spec(bad).unwrap_err().to_string();
            assert!(e.contains("must be frame numbers in 0..=10000000"), "{e}");
        }
    }
}
