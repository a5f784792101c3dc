//! `zoo stitch` on the runtime's stitch task (`zoo_runtime::StitchRefiner`): the clips read and
//! cut, checked against the model's skeleton and frame rate, aligned end to start (RMR sec. 6),
//! and the seams smoothed by the refiner (with the ankle IK, the seam guard and the foot lock, as
//! the runtime applies them for every engine), by inertialization, by interpolation, or not at
//! all (`concat`).

use crate::{ModelSource, TaskResult};
use std::path::PathBuf;
use zoo_data::{Context, Message, bail};
use zoo_format::MotionTaskKind;
use zoo_motion::Clip;
use zoo_motion::glam::DVec3;
use zoo_protocol::stitch::StitchLayout;
use zoo_rmr::pairs::{MIN_CLIP_FRAMES, align_clips, baselines};
use zoo_runtime::{FootCleanup, StitchRefiner};

/// A clip argument of `zoo stitch`: a file and a frame range.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClipRange {
    /// The clip file.
    pub path: PathBuf,
    /// First frame (0 when not given).
    pub from: usize,
    /// End frame, excluded (`None`: the clip's end).
    pub to: Option<usize>,
}

pub use zoo_rmr::stitch::PostProcess;

/// How the seams of the aligned clips are smoothed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SeamMethod {
    /// The refiner of the model, with its post-processing.
    Rmr(PostProcess),
    /// Inertialization at each seam over the blend.
    Inertialize,
    /// Interpolation across each seam over the blend.
    Interp,
    /// The aligned concatenation as it is.
    Concat,
}

/// The options of `zoo stitch`.
#[derive(Clone, Debug)]
pub struct StitchOptions {
    /// The clips, in order.
    pub clips: Vec<ClipRange>,
    /// Run folder of `zoo train rmr` or its exported file: needed by [`SeamMethod::Rmr`]; with
    /// another method its skeleton, frame rate and planted foot heights are used for the checks.
    pub model: Option<PathBuf>,
    /// How the seams are smoothed.
    pub method: SeamMethod,
    /// Refiner window in frames (default: the model's).
    pub window: Option<usize>,
    /// Refiner window step in frames (default: the model's; half the window when `window` is
    /// given).
    pub stride: Option<usize>,
    /// Frames of the blend at each seam (inertialize, interp, pre-blend, the guard's reference)
    /// or after each refiner window.
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
    /// The refiner's predicted ankle positions per frame ([`SeamMethod::Rmr`] only).
    pub predicted_ankles: Option<Vec<[DVec3; 2]>>,
    /// What the method did beyond the refinement (`, feet locked by ...`), for the summary line.
    pub note: String,
    /// Seconds the method took.
    pub seconds: f64,
}

/// The model's rig and frame rate, which the clips must have.
struct ModelRig<'a> {
    source: &'a ModelSource,
    skeleton: zoo_motion::Skeleton,
}

impl ModelRig<'_> {
    fn fits(&self, s: &zoo_motion::Skeleton) -> bool {
        s.names == self.skeleton.names && s.parents_i32() == self.skeleton.parents_i32()
    }

    /// Refuses a clip on another rig, naming the first joint that differs.
    fn check(&self, clip: &Clip, name: &str) -> TaskResult<()> {
        match rig_difference(&self.skeleton, &clip.skeleton) {
            None => Ok(()),
            Some(why) => bail!(
                "{name}: the clips' skeleton is not the model's in {} ({why}); retarget the clips to the model's rig",
                self.source.path.display()
            ),
        }
    }
}

/// How skeleton `got` differs from the model's `want` (joint count, or the first joint whose name
/// or parent differs); `None` when they are the same rig.
fn rig_difference(want: &zoo_motion::Skeleton, got: &zoo_motion::Skeleton) -> Option<String> {
    let (wp, gp) = (want.parents_i32(), got.parents_i32());
    if got.names == want.names && gp == wp {
        return None;
    }
    Some(if got.len() != want.len() {
        format!("expected {} joints, found {}", want.len(), got.len())
    } else {
        (0..want.len())
            .find(|&j| got.names[j] != want.names[j] || gp[j] != wp[j])
            .map(|j| format!("joint {j}: expected `{}`, found `{}`", want.names[j], got.names[j]))
            .unwrap_or_default()
    })
}

/// Reads the clips of `ranges` (dummy root dropped, sign flips removed) and cuts their ranges;
/// a range outside its clip or shorter than [`MIN_CLIP_FRAMES`] is refused. Each clip is brought
/// to the model's skeleton or else to the first clip's by the one rule of
/// [`zoo_data::clip_io::conform`] (reordered joints, a moving dummy root folded), said on stderr.
fn read_clips(ranges: &[ClipRange], model: Option<&ModelRig>) -> TaskResult<Vec<Clip>> {
    let mut first: Option<zoo_motion::Skeleton> = None;
    let mut read = |spec: &ClipRange| -> TaskResult<Clip> {
        let mut clip = zoo_data::clip_io::read_model_clip(&spec.path)
            .with_context(|| format!("reading {}", spec.path.display()))?;
        let how = match (model, &first) {
            (Some(m), _) => zoo_data::clip_io::conform(&mut clip, &|s: &zoo_motion::Skeleton| m.fits(s), None),
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
/// and, with a model, clips on another rig or at another frame rate than the model's.
fn check_clips(clips: &[Clip], names: &[String], model: Option<(&ModelRig, f64)>) -> TaskResult<()> {
    for (i, (c, name)) in clips.iter().zip(names).enumerate().skip(1) {
        if let Some(why) = clips[0].skeleton.topology_difference(&c.skeleton) {
            bail!("{name} has another skeleton than {} ({why}): every clip must use the same rig", names[0]);
        }
        if !c.plays_at(clips[0].fps()) {
            bail!(
                "{name} is {} fps, {} is {} fps: resample clip {i} first (`zoo data resample {name} OUT.bvh --fps {}`)",
                c.fps(),
                names[0],
                clips[0].fps(),
                clips[0].fps()
            );
        }
    }
    let Some((rig, fps)) = model else { return Ok(()) };
    for (c, name) in clips.iter().zip(names) {
        rig.check(c, name)?;
        if !c.plays_at(fps) {
            bail!(
                "{name} is {} fps but the model was trained at {fps} fps: resample it first (`zoo data resample \
                 {name} OUT.bvh --fps {fps}`)",
                c.fps()
            );
        }
    }
    Ok(())
}

/// Sets `r` up for `zoo stitch` on a sequence of `frames` frames: the window and stride asked
/// for (the model's by default; half the window when only the window is given), the blend, the
/// pre-blend (asked for, or the model's) and the seam guard.
fn configure(r: &mut StitchRefiner, frames: usize, opts: &StitchOptions, post: PostProcess) -> TaskResult<()> {
    let window = opts.window.unwrap_or(r.window());
    let stride = opts.stride.unwrap_or(if opts.window.is_some() { window / 2 } else { r.stride() }).max(1);
    if stride > window {
        bail!("--stride {stride} is longer than the window {window}: use a stride of at most {window}");
    }
    if window > frames {
        bail!(
            "the window of {window} frames is longer than the stitched sequence ({frames} frames): pass --window {} or \
             longer clips",
            frames.min(r.window())
        );
    }
    if (window, stride) != (r.window(), r.stride()) {
        r.set_window(window, stride)?;
    }
    r.set_blend_frames(opts.blend_frames)?;
    let pre_blend = post.pre_blend || r.pre_blend();
    r.set_pre_blend(pre_blend);
    r.set_seam_guard(post.seam_guard);
    let reach = post.reach.unwrap_or(zoo_protocol::stitch::reach::default_reach(window));
    r.set_seam_reach(post.keep_untouched.then_some(reach))?;
    Ok(())
}

/// `zoo stitch`: reads and aligns the clips end to start and smooths the seams by
/// `opts.method`. `names` name the clips in messages.
pub fn stitch(opts: &StitchOptions, names: &[String]) -> TaskResult<StitchOutcome> {
    let source = opts.model.as_deref().map(|p| ModelSource::open(p, MotionTaskKind::Stitch, "stitch")).transpose()?;
    let rig = source.as_ref().map(|s| ModelRig { source: s, skeleton: s.skeleton() });
    let clips = read_clips(&opts.clips, rig.as_ref())?;
    check_clips(&clips, names, rig.as_ref().map(|r| (r, f64::from(r.source.metadata.fps))))?;
    let mut refiner =
        source.as_ref().map(|s| -> TaskResult<StitchRefiner> { Ok(s.load()?.into_stitch()?) }).transpose()?;
    // The model's layout (its planted foot heights) when one is given, else bandai2's joints.
    let layout = match &refiner {
        Some(r) => r.layout().clone(),
        None => StitchLayout::bandai2(&clips[0].skeleton)
            .map_err(|e| Message(format!("{}: a joint stitching reads is missing ({e})", names[0])))?,
    };
    let aligned = align_clips(&clips, &layout, MIN_CLIP_FRAMES).map_err(|e| Message(e.to_string()))?;
    let seams = aligned.starts[1..].to_vec();
    let blend = opts.blend_frames;
    let (mut note, mut predicted_ankles) = (String::new(), None);
    let t0 = std::time::Instant::now();
    let output = match opts.method {
        SeamMethod::Concat => aligned.clip.clone(),
        SeamMethod::Inertialize => baselines::inertialize_seams(&aligned.clip, &seams, blend),
        SeamMethod::Interp => baselines::interpolate_seams(&aligned.clip, &seams, blend),
        SeamMethod::Rmr(post) => {
            let Some(r) = refiner.as_mut() else {
                bail!(
                    "--method rmr needs --model (a run folder of `zoo train rmr` or its exported file); or use \
                     --method inertialize"
                )
            };
            configure(r, aligned.clip.frames(), opts, post)?;
            let cleanup = FootCleanup { place_ankles: post.ankle_ik, lock_feet: post.foot_lock };
            let done = r.refine_clip(&aligned.clip, &seams, cleanup)?;
            if r.pre_blend() {
                note = format!(", seams inertialized over {blend} frames first");
            }
            if !done.fallback_weights.is_empty() {
                let n = done.fallback_weights.iter().filter(|w| **w > 0.0).count();
                note += &format!(
                    ", {n} of {} windows blended towards their input by the model's fallback",
                    done.fallback_weights.len()
                );
            }
            if let Some(moved) = done.ankle_move {
                note += &format!(", ankles placed at the predicted positions (mean move {moved:.2} units)");
            }
            if let Some(g) = &done.guarded {
                let n = g.iter().filter(|s| s.weight > 0.0).count();
                note += &format!(", {n} of {} seams guarded against pops", g.len());
            }
            if let Some(moved) = done.lock_move {
                note += &format!(", feet locked by the predicted contacts (mean ankle correction {moved:.2} units)");
            }
            let reach = r.seam_reach().unwrap_or(zoo_protocol::stitch::reach::default_reach(r.window()));
            let moved = zoo_protocol::stitch::reach::largest_move_beyond(&done.clip, &aligned.clip, &seams, reach);
            note += &match done.untouched {
                Some(kept) => format!(", {kept} frames {reach} or more from every seam kept as they were"),
                None => ", every frame refined".to_string(),
            };
            note += &format!(" (largest joint move {reach} or more frames from every seam: {moved:.4} units)");
            predicted_ankles = Some(done.ankles);
            done.clip
        }
    };
    let seconds = t0.elapsed().as_secs_f64();
    Ok(StitchOutcome { aligned: aligned.clip, output, seams, predicted_ankles, note, seconds })
}

/// The engine runtime's refiner of an exported RMR with its post-processing, as a method of the
/// stitching benchmark (`rmr...:RUN`): what `zoo stitch` runs, sized per sequence (a sequence
/// shorter than the model's window is refined as one window).
pub struct RuntimeSeamRefiner {
    refiner: StitchRefiner,
    post: PostProcess,
    /// Refiners planned for sequences shorter than the window, by length.
    short: std::cell::RefCell<std::collections::HashMap<usize, StitchRefiner>>,
    /// Windows refined, windows the fallback acted on, and the sum of its weights.
    counts: std::cell::Cell<(u64, u64, f64)>,
}

impl RuntimeSeamRefiner {
    /// The stitch model at `path` (a run folder of `zoo train rmr`, exported in memory, or its
    /// exported file), followed (and preceded) by `post`.
    pub fn load(path: &std::path::Path, post: PostProcess) -> TaskResult<RuntimeSeamRefiner> {
        let refiner = ModelSource::open(path, MotionTaskKind::Stitch, "bench stitch")?.load()?.into_stitch()?;
        Ok(RuntimeSeamRefiner { refiner, post, short: Default::default(), counts: Default::default() })
    }

    fn run(&self, aligned: &Clip, seams: &[usize], blend: usize) -> TaskResult<Clip> {
        let frames = aligned.frames();
        let mut r = if self.refiner.window() <= frames {
            self.refiner.clone()
        } else {
            let mut short = self.short.borrow_mut();
            match short.get(&frames) {
                Some(r) => r.clone(),
                None => {
                    let mut r = self.refiner.clone();
                    r.set_window(frames, frames)?;
                    short.insert(frames, r.clone());
                    r
                }
            }
        };
        r.set_blend_frames(blend)?;
        let pre_blend = self.post.pre_blend || self.refiner.pre_blend();
        r.set_pre_blend(pre_blend);
        r.set_seam_guard(self.post.seam_guard);
        let reach = self.post.reach.unwrap_or(zoo_protocol::stitch::reach::default_reach(r.window()));
        r.set_seam_reach(self.post.keep_untouched.then_some(reach))?;
        let cleanup = FootCleanup { place_ankles: self.post.ankle_ik, lock_feet: self.post.foot_lock };
        let done = r.refine_clip(aligned, seams, cleanup)?;
        let (mut n, mut acted, mut sum) = self.counts.get();
        for w in &done.fallback_weights {
            n += 1;
            acted += u64::from(*w > 0.0);
            sum += f64::from(*w);
        }
        self.counts.set((n, acted, sum));
        Ok(done.clip)
    }
}

impl zoo_rmr::bench::SeamRefiner for RuntimeSeamRefiner {
    fn stitch(&self, aligned: &Clip, seams: &[usize], blend: usize) -> Result<Clip, Message> {
        self.run(aligned, seams, blend).map_err(|e| Message(e.to_string()))
    }

    fn check_skeleton(&self, skeleton: &zoo_motion::Skeleton) -> Result<(), Message> {
        match rig_difference(self.refiner.skeleton(), skeleton) {
            None => Ok(()),
            Some(why) => Err(Message(format!(
                "the clips' skeleton is not the model's ({why}); retarget the clips to the model's rig"
            ))),
        }
    }

    fn drop_fallback(&mut self) {
        // Setting no fallback cannot fail.
        let _ = self.refiner.set_fallback(None);
        self.short.borrow_mut().clear();
    }

    fn fallback_summary(&self) -> Option<(u64, f64, f64)> {
        self.refiner.fallback()?;
        let (n, acted, sum) = self.counts.get();
        let d = n.max(1) as f64;
        Some((n, acted as f64 / d, sum / d))
    }
}
