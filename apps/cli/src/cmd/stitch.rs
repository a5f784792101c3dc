//! `zoo stitch`: join locomotion clips into one ([`zoo_tasks::stitch`], run by the engine
//! runtime): the clips aligned end to start (RMR sec. 6), the seams smoothed by the RMR (ankles
//! placed at its predicted positions, seams guarded, feet locked by its predicted contacts),
//! inertialization, interpolation, or nothing (`concat`).

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use zoo_tasks::stitch::{ClipRange, PostProcess, SeamMethod, StitchOptions};

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
    /// Run folder of `zoo train rmr`, or its exported file (`zoo export --onnx`): needed by
    /// `--method rmr`; with another method its skeleton, frame rate and planted foot heights
    /// are used for the checks.
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
    /// Do not guard the seams: by default, where the RMR's output moves a joint faster within 5
    /// frames of a seam than inertialization does there, it is blended towards itself smoothed
    /// until it does not (after the ankle IK, before the foot lock; docs/rmr-benchmarks.md, "The
    /// seam guard: how it works").
    #[arg(long)]
    pub no_seam_guard: bool,
    /// Inertialize each seam over `--blend-frames` frames before the RMR refines the sequence
    /// (not in the paper). For clips cut anywhere, whose seams are larger than those of the
    /// retrieved neighbours RMR trained on: on bandai2's free cases it brings the pops from
    /// 2.29 to 1.06 (inertialization alone: 1.03) for 11% more pose error on the cases with a
    /// ground truth (docs/rmr.md).
    #[arg(long)]
    pub pre_blend: bool,
    /// Frames from the nearest seam beyond which the clips are kept exactly as they are (the
    /// RMR's output is eased back to them from half of it on) [default: the model's window]
    /// (docs/rmr.md, "The seams' reach").
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::frame_count, conflicts_with = "refine_everywhere")]
    pub seam_reach: Option<usize>,
    /// Let the RMR change the whole sequence, however far from a seam (as before the seams'
    /// reach existed; `zoo bench stitch`'s methods without `+reach`).
    #[arg(long)]
    pub refine_everywhere: bool,
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

/// Parses `CLIP.bvh` or `CLIP.bvh:FROM:TO` (`TO` may be empty).
pub fn parse_clip_spec(s: &str) -> anyhow::Result<ClipRange> {
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
        return Ok(ClipRange { path: PathBuf::from(path), from, to });
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
    Ok(ClipRange { path: PathBuf::from(s), from: 0, to: None })
}

/// `OUT.input.bvh` beside `OUT.bvh`.
pub(crate) fn input_path(out: &Path) -> PathBuf {
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
    let names: Vec<String> = specs.iter().map(|s| s.path.display().to_string()).collect();
    let method = match a.method {
        StitchMethod::Rmr => SeamMethod::Rmr(PostProcess {
            ankle_ik: !a.no_ankle_ik,
            foot_lock: !a.no_foot_lock,
            pre_blend: a.pre_blend,
            seam_guard: !a.no_seam_guard,
            keep_untouched: !a.refine_everywhere,
            reach: a.seam_reach,
        }),
        StitchMethod::Inertialize => SeamMethod::Inertialize,
        StitchMethod::Interp => SeamMethod::Interp,
        StitchMethod::Concat => SeamMethod::Concat,
    };
    let opts = StitchOptions {
        clips: specs,
        model: a.model.clone(),
        method,
        window: a.window,
        stride: a.stride,
        blend_frames: a.blend_frames,
    };
    let done = zoo_tasks::stitch::stitch(&opts, &names)?;
    zoo_data::clip_io::write(&done.output, &a.out)?;
    if let Some(p) = &a.positions {
        let ankles = done
            .predicted_ankles
            .as_ref()
            .map(|v| v.iter().map(|f| f.map(|p| [p.x as f32, p.y as f32, p.z as f32])).collect::<Vec<_>>());
        // Checked before `json!`, which would write a NaN as `null`.
        zoo_motion::finite::check_serialize("the RMR's predicted ankles", &ankles)?;
        let extra = serde_json::json!({ "seams": done.seams, "method": format!("{:?}", a.method).to_lowercase(),
            "predicted_ankles": ankles });
        crate::cmd::write_positions(p, &zoo_data::positions::clip_positions_json("stitch", &done.output, extra)?)?;
    }
    if a.save_input {
        let p = input_path(&a.out);
        zoo_data::bvh::write_file(&done.aligned, &p).with_context(|| format!("writing {}", p.display()))?;
        println!("aligned input: {}", p.display());
    }
    println!(
        "stitched {} clips ({} frames, seams at {:?}) with {:?} in {:.3} s{}: {}",
        names.len(),
        done.output.frames(),
        done.seams,
        a.method,
        done.seconds,
        done.note,
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
