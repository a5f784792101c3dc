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

pub use zoo_protocol::stitch::predicted_ankles;

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
        if !c.plays_at(config.fps) {
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
    /// ([`zoo_protocol::stitch::guard`]; not in the paper; after the ankle IK, before the lock;
    /// `rmr+ik+guard+lock` in the benchmark).
    pub seam_guard: bool,
    /// The clips kept as they are from one window away from every seam, eased back to them
    /// from half a window on ([`zoo_protocol::stitch::reach`]; not in the paper; after the lock;
    /// `zoo stitch` by default, `+reach` at the end of a benchmark method).
    pub keep_untouched: bool,
    /// The reach in frames with `keep_untouched` (`None`:
    /// [`zoo_protocol::stitch::reach::default_reach`] of the window; `+reachN` in the benchmark).
    pub reach: Option<usize>,
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
    pub guarded: Option<Vec<zoo_protocol::stitch::guard::GuardedSeam>>,
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
        (Some(reference), true) => Some(zoo_protocol::stitch::guard::guard_seams(&mut clip, reference, seams, layout)),
        _ => None,
    };
    let lock_move = post.foot_lock.then(|| crate::footlock::lock_feet(&mut clip, &refined.contacts, layout));
    if post.keep_untouched {
        let input = if pre_blend { blended.as_ref().unwrap_or(aligned) } else { aligned };
        let reach = post.reach.unwrap_or(zoo_protocol::stitch::reach::default_reach(opts.window));
        zoo_protocol::stitch::reach::keep_untouched(&mut clip, input, seams, reach, layout);
    }
    Ok(RefinedSeams { clip, ankles: refined.ankles, ankle_move, lock_move, guarded })
}
