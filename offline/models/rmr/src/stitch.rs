//! Stitching with a trained RMR (sec. 6): align the clips end to start, slide a window of `w`
//! frames by `s` frames over the aligned sequence, refine each window with the model (its
//! input holds the frames earlier windows already refined), and blend the difference between
//! the previous output and each new window's first pose away over `blend_frames` frames.
//!
//! The blend is a linear decay of the offset in pose-vector space (RMR sec. 6 cites
//! inertialization; the offset here is the small one the beginning loss leaves, and the
//! pose vector is decoded afterwards, renormalising the quaternions). The foot lock by the
//! predicted contacts is a separate step ([`crate::footlock::lock_feet`]).

use crate::config::Config;
use crate::error::{RmrError, RmrResult};
use crate::features::{FeatureLayout, FeatureStats, decode, encode_clip};
use crate::model::Rmr;
use crate::pairs::{MIN_CLIP_FRAMES, StitchLayout, align_clips, ground_roots};
use zoo_motion::Clip;
use zoo_motion::glam::DVec3;

pub use zoo_motion::stitch::predicted_ankles;

/// How a sequence is refined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RefineOptions {
    /// Window `w`, frames.
    pub window: usize,
    /// Step `s` between windows, frames (`1..=w`).
    pub stride: usize,
    /// Frames over which each window's first-frame difference is blended away.
    pub blend_frames: usize,
}

impl RefineOptions {
    /// The configuration's runtime window, stride and blend.
    pub fn of(config: &Config) -> RefineOptions {
        RefineOptions { window: config.window, stride: config.stride, blend_frames: config.blend_frames }
    }
}

/// Window starts: every `stride` frames while the window fits, plus a last window ending on
/// the last frame when the stride does not land there.
pub fn window_starts(frames: usize, window: usize, stride: usize) -> Vec<usize> {
    if window > frames || stride == 0 {
        return Vec::new();
    }
    let mut starts: Vec<usize> = (0..=frames - window).step_by(stride).collect();
    if starts.last() != Some(&(frames - window)) {
        starts.push(frames - window);
    }
    starts
}

/// Refines a sequence of raw pose vectors (`frames * dim`, [`encode_clip`]'s layout) window by
/// window; returns raw pose vectors with contacts as 0/1.
pub fn refine_sequence(
    model: &Rmr,
    stats: &FeatureStats,
    features: &[f32],
    opts: RefineOptions,
) -> RmrResult<Vec<f32>> {
    let config = model.config();
    let fl = FeatureLayout::new(config.joints, config.layout.lower_body.len());
    refine_sequence_with(|w| model.refine_window(w), fl, stats, features, opts)
}

/// [`refine_sequence`] with any window refiner: `refine` maps a normalised window
/// (`window * dim`) to normalised pose vectors of the same size (contacts as logits). The
/// identity refines a sequence into itself (tests, and the runtime's reference).
pub fn refine_sequence_with(
    mut refine: impl FnMut(&[f32]) -> RmrResult<Vec<f32>>,
    fl: FeatureLayout,
    stats: &FeatureStats,
    features: &[f32],
    opts: RefineOptions,
) -> RmrResult<Vec<f32>> {
    let d = fl.dim();
    if stats.dim() != d || features.is_empty() || !features.len().is_multiple_of(d) {
        return Err(RmrError::Size {
            what: "sequence to refine".into(),
            expected: d,
            detail: format!("whole frames of {d} values and statistics of {d} (found {})", stats.dim()),
            found: features.len(),
        });
    }
    let frames = features.len() / d;
    if opts.window > frames {
        return Err(RmrError::Config(format!(
            "the window of {} frames is longer than the sequence ({frames} frames): use a window of at most {frames}",
            opts.window
        )));
    }
    if opts.stride == 0 || opts.stride > opts.window {
        return Err(RmrError::Config(format!(
            "the stride {} must be in 1..={} (the window)",
            opts.stride, opts.window
        )));
    }
    let pose = fl.contacts();
    let mut out = features.to_vec();
    stats.normalize(&mut out);
    for ws in window_starts(frames, opts.window, opts.stride) {
        let span = ws * d..(ws + opts.window) * d;
        let mut y = refine(&out[span.clone()])?;
        if y.len() != span.len() {
            return Err(RmrError::Size {
                what: "refined window".into(),
                expected: span.len(),
                detail: format!("{} frames of {d} values", opts.window),
                found: y.len(),
            });
        }
        if ws > 0 {
            // out[ws] is the previous output at the window's first frame.
            let offset: Vec<f32> = (0..pose).map(|i| out[ws * d + i] - y[i]).collect();
            for k in 0..opts.blend_frames.min(opts.window) {
                let w = 1.0 - k as f32 / opts.blend_frames as f32;
                for (v, o) in y[k * d..k * d + pose].iter_mut().zip(&offset) {
                    *v += w * o;
                }
            }
        }
        for f in y.chunks_exact_mut(d) {
            for c in &mut f[pose..] {
                *c = if *c > 0.0 { 1.0 } else { 0.0 }; // sigmoid(logit) > 0.5
            }
        }
        out[span].copy_from_slice(&y);
    }
    stats.denormalize(&mut out);
    for f in out.chunks_exact_mut(d) {
        for c in &mut f[pose..] {
            *c = if *c > 0.5 { 1.0 } else { 0.0 };
        }
    }
    Ok(out)
}

/// A stitched sequence.
#[derive(Clone, Debug)]
pub struct Stitched {
    /// The aligned input (what plain concatenation gives).
    pub input: Clip,
    /// The refined motion.
    pub output: Clip,
    /// Predicted contacts per frame (heel L, toe L, heel R, toe R).
    pub contacts: Vec<[bool; 4]>,
    /// First frame of each clip.
    pub starts: Vec<usize>,
}

/// Aligns `clips`, refines them and decodes the result. Refuses clips of another rig or frame
/// rate than the model's, clips shorter than 10 frames and a window longer than the sequence.
pub fn stitch_clips(model: &Rmr, stats: &FeatureStats, clips: &[Clip], opts: RefineOptions) -> RmrResult<Stitched> {
    let config = model.config();
    for (i, c) in clips.iter().enumerate() {
        config.check_skeleton(&c.skeleton).map_err(|e| RmrError::Config(format!("clip {i}: {e}")))?;
        if (c.fps() - config.fps).abs() > 1e-6 * config.fps {
            return Err(RmrError::Config(format!(
                "clip {i} is {} fps but the model was trained at {} fps; resample it first",
                c.fps(),
                config.fps
            )));
        }
    }
    let aligned = align_clips(clips, &config.layout, MIN_CLIP_FRAMES)?;
    let (output, contacts) = refine_clip(model, stats, &aligned.clip, opts)?;
    Ok(Stitched { input: aligned.clip, output, contacts, starts: aligned.starts })
}

/// Refines an already aligned sequence (e.g. a test case of the stitching benchmark): encodes
/// it, refines it window by window and decodes it from its first ground root. Returns the
/// refined clip and the predicted contacts per frame (heel L, toe L, heel R, toe R).
pub fn refine_clip(
    model: &Rmr,
    stats: &FeatureStats,
    aligned: &Clip,
    opts: RefineOptions,
) -> RmrResult<(Clip, Vec<[bool; 4]>)> {
    let config = model.config();
    config.check_skeleton(&aligned.skeleton)?;
    refine_clip_with(|w| model.refine_window(w), &config.layout, stats, aligned, opts)
}

/// [`refine_clip`] with any window refiner (see [`refine_sequence_with`]).
pub fn refine_clip_with(
    refine: impl FnMut(&[f32]) -> RmrResult<Vec<f32>>,
    layout: &StitchLayout,
    stats: &FeatureStats,
    aligned: &Clip,
    opts: RefineOptions,
) -> RmrResult<(Clip, Vec<[bool; 4]>)> {
    let r = refine_clip_full_with(refine, layout, stats, aligned, opts)?;
    Ok((r.clip, r.contacts))
}

/// A refined sequence, decoded.
#[derive(Clone, Debug)]
pub struct Refined {
    /// The decoded motion (rotations `q`, root from `r`, hips position from `p`).
    pub clip: Clip,
    /// Predicted contacts per frame (heel L, toe L, heel R, toe R).
    pub contacts: Vec<[bool; 4]>,
    /// The ankles' global positions the refiner predicts in `p` (left, right), for
    /// [`crate::footlock::place_ankles`]; empty when the layout's heel joints are not lower body.
    pub ankles: Vec<[DVec3; 2]>,
}

/// [`refine_clip_with`], also returning the predicted ankle positions.
pub fn refine_clip_full_with(
    refine: impl FnMut(&[f32]) -> RmrResult<Vec<f32>>,
    layout: &StitchLayout,
    stats: &FeatureStats,
    aligned: &Clip,
    opts: RefineOptions,
) -> RmrResult<Refined> {
    let fl = FeatureLayout::new(aligned.joints(), layout.lower_body.len());
    let x = encode_clip(aligned, layout)?;
    let y = refine_sequence_with(refine, fl, stats, &x, opts)?;
    let start = ground_roots(aligned, layout)[0];
    let ankles = predicted_ankles(&y, fl, layout, start);
    let (clip, contacts) = decode(&y, &aligned.skeleton, layout, aligned.frame_time, start)?;
    Ok(Refined { clip, contacts, ankles })
}

/// [`refine_clip_full_with`] with the model.
pub fn refine_clip_full(model: &Rmr, stats: &FeatureStats, aligned: &Clip, opts: RefineOptions) -> RmrResult<Refined> {
    let config = model.config();
    config.check_skeleton(&aligned.skeleton)?;
    refine_clip_full_with(|w| model.refine_window(w), &config.layout, stats, aligned, opts)
}

/// What follows the refiner (`zoo stitch` by default: both, in this order) and what comes
/// before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PostProcess {
    /// The ankles placed at the refiner's predicted positions by IK (RMR sec. 5's output
    /// processing; before the foot lock).
    pub ankle_ik: bool,
    /// The feet locked by the predicted contacts.
    pub foot_lock: bool,
    /// The seams inertialized over the blend before the RMR refines (not in the paper; `zoo
    /// stitch --pre-blend`, `inert+rmr...` in the benchmark).
    pub pre_blend: bool,
    /// No seam moves a joint faster than the inertialized clips do there
    /// ([`zoo_motion::stitch::guard`]; not in the paper; after the ankle IK, before the lock;
    /// `rmr+ik+guard+lock` in the benchmark).
    pub seam_guard: bool,
}

/// An RMR's stitch of an aligned sequence, with what the post-processing did.
#[derive(Clone, Debug)]
pub struct RefinedSeams {
    /// The stitched motion.
    pub clip: Clip,
    /// The ankles' global positions the refiner predicted (left, right) per frame.
    pub ankles: Vec<[DVec3; 2]>,
    /// Mean move of the ankles by the IK (clip units), when it ran.
    pub ankle_move: Option<f64>,
    /// Mean ankle correction of the foot lock (clip units), when it ran.
    pub lock_move: Option<f64>,
    /// What the seam guard did at each seam, when it ran.
    pub guarded: Option<Vec<zoo_motion::stitch::guard::GuardedSeam>>,
}

/// Refines the aligned sequence `aligned` (seams at `seams`) with `model`, then applies `post`
/// (ankle IK, seam guard, foot lock, in that order); `opts.blend_frames` is also the length of
/// the pre-blend and of the guard's inertialized reference.
pub fn refine_seams(
    model: &Rmr,
    stats: &FeatureStats,
    aligned: &Clip,
    seams: &[usize],
    opts: RefineOptions,
    post: PostProcess,
) -> RmrResult<RefinedSeams> {
    let layout = &model.config().layout;
    let pre_blend = post.pre_blend || model.config().pre_blend;
    let blended = (pre_blend || post.seam_guard)
        .then(|| crate::pairs::baselines::inertialize_seams(aligned, seams, opts.blend_frames));
    let refined = match (&blended, pre_blend) {
        (Some(b), true) => refine_clip_full(model, stats, b, opts)?,
        _ => refine_clip_full(model, stats, aligned, opts)?,
    };
    let mut clip = refined.clip;
    let ankle_move = post.ankle_ik.then(|| crate::footlock::place_ankles(&mut clip, &refined.ankles, layout));
    let guarded = match (&blended, post.seam_guard) {
        (Some(reference), true) => Some(zoo_motion::stitch::guard::guard_seams(&mut clip, reference, seams, layout)),
        _ => None,
    };
    let lock_move = post.foot_lock.then(|| crate::footlock::lock_feet(&mut clip, &refined.contacts, layout));
    Ok(RefinedSeams { clip, ankles: refined.ankles, ankle_move, lock_move, guarded })
}

/// How `zoo stitch` smooths the seams of the aligned clips.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeamMethod {
    /// The RMR, with its post-processing.
    Rmr(PostProcess),
    /// Inertialization at each seam over the blend.
    Inertialize,
    /// Interpolation across each seam over the blend.
    Interp,
    /// The aligned concatenation as it is.
    Concat,
}

/// The options of `zoo stitch`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StitchOptions {
    /// How the seams are smoothed.
    pub method: SeamMethod,
    /// RMR window `w` in frames (default: the model's).
    pub window: Option<usize>,
    /// RMR window step in frames (default: the model's; half the window when `window` is given).
    pub stride: Option<usize>,
    /// Frames of the blend at each seam (inertialize, interp) or after each RMR window.
    pub blend_frames: usize,
}

/// What `zoo stitch` made.
#[derive(Clone, Debug)]
pub struct StitchOutcome {
    /// The aligned concatenation.
    pub aligned: Clip,
    /// The stitched motion.
    pub output: Clip,
    /// First frame of each clip after the first.
    pub seams: Vec<usize>,
    /// The RMR's predicted ankle positions (`SeamMethod::Rmr` only).
    pub predicted_ankles: Option<Vec<[DVec3; 2]>>,
    /// What the method did beyond the refinement (`, feet locked by ...`), for the summary line.
    pub note: String,
    /// Seconds the method took.
    pub seconds: f64,
}

/// A clip argument of `zoo stitch`: a file and a frame range.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClipRange {
    /// The clip file.
    pub path: std::path::PathBuf,
    /// First frame (0 when not given).
    pub from: usize,
    /// End frame, excluded (`None`: the clip's end).
    pub to: Option<usize>,
}

/// Reads the clips of `ranges` (dummy root dropped, sign flips removed) and cuts their ranges;
/// a range outside its clip or shorter than [`MIN_CLIP_FRAMES`] is refused. Each clip is brought
/// to `config`'s skeleton (a model's) or else to the first clip's by the one rule of
/// [`zoo_data::clip_io::conform`] (reordered joints, a moving dummy root folded), said on stderr.
pub fn read_clips(ranges: &[ClipRange], config: Option<&Config>) -> RmrResult<Vec<Clip>> {
    use zoo_data::{Context, bail};
    let mut first: Option<zoo_motion::Skeleton> = None;
    let mut read = |spec: &ClipRange| -> RmrResult<Clip> {
        let mut clip = zoo_data::clip_io::read_model_clip(&spec.path)
            .with_context(|| format!("reading {}", spec.path.display()))?;
        let how = match (config, &first) {
            (Some(c), _) => zoo_data::clip_io::conform(
                &mut clip,
                &|s: &zoo_motion::Skeleton| s.names == c.names && s.parents_i32() == c.parents,
                None,
            ),
            (None, Some(f)) => zoo_data::clip_io::conform_to(&mut clip, f),
            (None, None) => None,
        };
        if let Some(zoo_data::clip_io::Conformed::Folded(how)) = how {
            eprintln!("{}: {how}", spec.path.display());
        }
        first.get_or_insert_with(|| clip.skeleton.clone());
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
    };
    ranges.iter().map(&mut read).collect()
}

/// Refuses clips on another rig or at another frame rate than the first (`names` name them),
/// and, with a model, clips its configuration does not fit.
pub fn check_clips(clips: &[Clip], names: &[String], config: Option<&Config>) -> RmrResult<()> {
    use zoo_data::{Context, bail};
    for (i, (c, name)) in clips.iter().zip(names).enumerate().skip(1) {
        if let Some(why) = clips[0].skeleton.topology_difference(&c.skeleton) {
            bail!("{name} has another skeleton than {} ({why}): every clip must use the same rig", names[0]);
        }
        if (c.fps() - clips[0].fps()).abs() > 1e-6 * clips[0].fps() {
            bail!("{name} is {} fps, {} is {} fps: resample clip {i} first", c.fps(), names[0], clips[0].fps());
        }
    }
    let Some(config) = config else { return Ok(()) };
    for (c, name) in clips.iter().zip(names) {
        config.check_skeleton(&c.skeleton).context(name)?;
        if (c.fps() - config.fps).abs() > 1e-6 * config.fps {
            bail!("{name} is {} fps but the model was trained at {} fps: resample it first", c.fps(), config.fps);
        }
    }
    Ok(())
}

/// `zoo stitch`: aligns `clips` end to start and smooths the seams by `opts.method`, which
/// needs `model` for the RMR (with another method its layout is used when given). `names`
/// name the clips in messages.
pub fn stitch_command(
    model: Option<&(Rmr, FeatureStats)>,
    clips: &[Clip],
    names: &[String],
    opts: StitchOptions,
) -> RmrResult<StitchOutcome> {
    use zoo_data::{Context, bail};
    check_clips(clips, names, model.map(|(m, _)| m.config()))?;
    let layout = match model {
        Some((m, _)) => m.config().layout.clone(),
        None => StitchLayout::bandai2(&clips[0].skeleton)
            .with_context(|| format!("{}: a joint stitching reads is missing", names[0]))?,
    };
    let aligned = align_clips(clips, &layout, MIN_CLIP_FRAMES)?;
    let seams = aligned.starts[1..].to_vec();
    let t0 = std::time::Instant::now();
    let (mut note, mut predicted_ankles) = (String::new(), None);
    let blend = opts.blend_frames;
    let output = match opts.method {
        SeamMethod::Concat => aligned.clip.clone(),
        SeamMethod::Inertialize => crate::pairs::baselines::inertialize_seams(&aligned.clip, &seams, blend),
        SeamMethod::Interp => crate::pairs::baselines::interpolate_seams(&aligned.clip, &seams, blend),
        SeamMethod::Rmr(post) => {
            let Some((m, stats)) = model else {
                bail!("--method rmr needs --model RUN_DIR (a folder of `zoo train rmr`); or use --method inertialize")
            };
            let refine = command_refine_options(m.config(), aligned.clip.frames(), &opts)?;
            let r = refine_seams(m, stats, &aligned.clip, &seams, refine, post)?;
            if post.pre_blend || m.config().pre_blend {
                note = format!(", seams inertialized over {blend} frames first");
            }
            if let Some(moved) = r.ankle_move {
                note += &format!(", ankles placed at the predicted positions (mean move {moved:.2} units)");
            }
            if let Some(g) = &r.guarded {
                let n = g.iter().filter(|s| s.weight > 0.0).count();
                note += &format!(", {n} of {} seams guarded against pops", g.len());
            }
            if let Some(moved) = r.lock_move {
                note += &format!(", feet locked by the predicted contacts (mean ankle correction {moved:.2} units)");
            }
            predicted_ankles = Some(r.ankles);
            r.clip
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    Ok(StitchOutcome { aligned: aligned.clip, output, seams, predicted_ankles, note, seconds })
}

/// The window and stride of `zoo stitch --window --stride` on a sequence of `frames` frames.
fn command_refine_options(c: &Config, frames: usize, opts: &StitchOptions) -> RmrResult<RefineOptions> {
    use zoo_data::bail;
    let window = opts.window.unwrap_or(c.window);
    let stride = opts.stride.unwrap_or(if opts.window.is_some() { window / 2 } else { c.stride }).max(1);
    if stride > window {
        bail!("--stride {stride} is longer than the window {window}: use a stride of at most {window}");
    }
    if window > frames {
        bail!(
            "the window of {window} frames is longer than the stitched sequence ({frames} frames): pass --window {} or \
             longer clips",
            frames.min(c.window)
        );
    }
    Ok(RefineOptions { window, stride, blend_frames: opts.blend_frames })
}
