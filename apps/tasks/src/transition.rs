//! `zoo transition` and `zoo decompress` on the runtime's transition task
//! (`zoo_runtime::TransitionModel`): the clips read (mapped onto the model's rig with a
//! joint-name map), the skeleton and terrain checked against the model, the transition
//! generated (with its fallback and foot lock, as the runtime applies them for every engine)
//! and spliced between the clips, and its positions file. With the in-betweening design (`zoo
//! train arnn --design inbetween`), the ten context frames and the target are its keys and the
//! runtime's keyframes task fills the whole gap in one call ([`run_inbetween`]).

use crate::{ModelSource, TaskResult};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use zoo_data::clip_io;
use zoo_data::{Context, Message, Progress, bail};
use zoo_format::MotionTaskKind;
use zoo_motion::{Clip, Skeleton};
use zoo_protocol::pipeline;
use zoo_runtime::{TransitionModel, TransitionRunner, TransitionState};

/// The options of `zoo transition`.
#[derive(Clone, Debug)]
pub struct TransitionOptions {
    /// Run folder of `zoo train rtn`, or its exported file.
    pub model: PathBuf,
    /// Source clip and frame: the transition starts after the 10 frames before it.
    pub from: (PathBuf, usize),
    /// `--from` as the user wrote it, for messages.
    pub from_label: String,
    /// Target clip and frame: the transition ends in this pose.
    pub to: (PathBuf, usize),
    /// `--to` as the user wrote it, for messages.
    pub to_label: String,
    /// Transition length in frames.
    pub frames: usize,
    /// Output clip.
    pub out: PathBuf,
    /// The FBX take or glTF animation of the clips.
    pub take: Option<String>,
    /// A joint-name map from the clips' rig to the model's.
    pub rig_map: Option<PathBuf>,
    /// Foot-lock the transition.
    pub foot_lock: bool,
    /// Keep the network's transition even on a large miss at the target.
    pub no_fallback: bool,
    /// The ground for a terrain-aware model.
    pub heightmap: Option<PathBuf>,
    /// The network's global joint positions (a positions file).
    pub positions: Option<PathBuf>,
    /// Leave the target clip where it is (both clips share one world frame) instead of moving
    /// it to follow on from the source.
    pub in_place: bool,
}

/// The heightmap of `zoo transition` and `--heightmap`'s checks against the model: required by
/// a terrain-aware model (the error names the --from clip's sibling heightmap when there is
/// one), refused by a model without terrain input.
fn read_heightmap(
    heightmap: Option<&Path>,
    model_path: &Path,
    terrain: bool,
    from_clip: &Path,
) -> TaskResult<Option<zoo_data::terrain::Heightmap>> {
    match (heightmap, terrain) {
        (Some(p), true) => {
            Ok(Some(zoo_data::terrain::read(p).with_context(|| format!("--heightmap {}", p.display()))?))
        }
        (None, true) => {
            let hint = zoo_data::terrain::sibling_of(from_clip).map_or(String::new(), |t| {
                format!(" (the --from clip has one beside it: --heightmap {})", t.display())
            });
            bail!(
                "the model in {} is terrain-aware (trained with --terrain): pass the ground under the --from clip \
                 with --heightmap FILE.terrain.json{hint}",
                model_path.display()
            )
        }
        (Some(p), false) => bail!(
            "--heightmap {}: the model in {} has no terrain input (trained without --terrain); drop --heightmap \
             or use a model trained with `zoo train rtn --terrain`",
            p.display(),
            model_path.display()
        ),
        (None, false) => Ok(None),
    }
}

/// Says so (a notice) when the clip's joint names are not the model's: another rig with the
/// model's hierarchy runs, but `--rig-map` maps it onto the model's proportions.
fn note_other_names(model: &Skeleton, clip: &Clip, p: &dyn Progress) {
    if model.names == clip.skeleton.names {
        return;
    }
    let (k, (theirs, mine)) = model
        .names
        .iter()
        .zip(&clip.skeleton.names)
        .enumerate()
        .find(|(_, (m, c))| m != c)
        .unwrap_or((0, (&model.names[0], &clip.skeleton.names[0])));
    p.notice(&format!(
        "note: the clip's joint names differ from the model's (joint {k}: `{mine}`, the model's `{theirs}`); if it \
         is another rig, pass --rig-map MAP.json to map it onto the model's skeleton (docs/formats.md)"
    ));
}

/// The --from and --to clips on the model's skeleton (with --rig-map), and what maps the
/// result back onto the --from clip's rig.
type RigBack = Option<(Skeleton, zoo_data::retarget::RigMatch)>;
fn map_rig(a: &TransitionOptions, model: &Skeleton, ca: Clip, cb: Clip) -> TaskResult<(Clip, Clip, RigBack)> {
    let Some(map_path) = &a.rig_map else { return Ok((ca, cb, None)) };
    let map = zoo_data::retarget::RigMap::read(map_path).map_err(Message::new)?;
    let ma = map.match_rigs(&ca.skeleton, model, true).with_context(|| format!("--rig-map --from {}", a.from_label))?;
    let mb = map.match_rigs(&cb.skeleton, model, true).with_context(|| format!("--rig-map --to {}", a.to_label))?;
    let (ra, rb) = (zoo_data::retarget::retarget(&ca, model, &ma), zoo_data::retarget::retarget(&cb, model, &mb));
    println!(
        "--rig-map: {} joints mapped onto the model's skeleton, root translation x{:.4}",
        model.len(),
        ma.root_scale
    );
    let back = ma.inverse(ca.joints());
    Ok((ra, rb, Some((ca.skeleton, back))))
}

/// Brings `clip` (read from `path`) to the model's skeleton by the one rule of
/// [`zoo_data::clip_io::conform`] (a moving dummy root folded, said on stderr), then refuses it
/// when it is still on another one: another joint count, or the same count in another
/// hierarchy.
pub fn check_skeleton(model: &ModelSource, clip: &mut Clip, path: &Path) -> TaskResult<()> {
    let want = &model.metadata.skeleton;
    let fits = |s: &Skeleton| s.len() == want.len() && s.parents_i32() == want.parents;
    if let Some(clip_io::Conformed::Folded(how)) = clip_io::conform(clip, &fits, None) {
        eprintln!("{}: {how}", path.display());
    }
    if want.len() != clip.joints() {
        bail!(
            "the model in {} was trained on {} joints, {} has {}",
            model.path.display(),
            want.len(),
            path.display(),
            clip.joints()
        );
    }
    let parents = clip.skeleton.parents_i32();
    if want.parents != parents {
        let j = (0..parents.len()).find(|&j| want.parents[j] != parents[j]).unwrap_or(0);
        bail!(
            "{} has the model's {} joints but another hierarchy: joint {j} (`{}`) has parent {}, the model in {} \
             was trained with parent {}; use a clip of the training skeleton",
            path.display(),
            want.len(),
            clip.skeleton.names[j],
            parents[j],
            model.path.display(),
            want.parents[j]
        );
    }
    Ok(())
}

/// The transition model of `source` and a runner set up as the commands run it: lengths
/// beyond the trained one allowed (the command's user chose the length), the model's
/// calibrated fallback unless `no_fallback`, the foot lock when asked.
pub fn runner(
    source: &ModelSource,
    no_fallback: bool,
    foot_lock: bool,
) -> TaskResult<(TransitionModel, TransitionRunner)> {
    let model = source.load()?.into_transition()?;
    let mut runner = model.runner()?;
    runner.allow_beyond_trained(true);
    if no_fallback {
        runner.set_fallback(None);
    } else {
        runner.set_model_fallback();
    }
    runner.set_foot_lock(if foot_lock { model.default_foot_lock() } else { None });
    Ok((model, runner))
}

/// Writes the `--positions` file of a transition: inputs, raw and blended frames (`3K` global
/// positions each, joint-major, model units).
#[allow(clippy::too_many_arguments)]
fn write_transition_positions(
    path: &Path,
    model: &ModelSource,
    from: &Clip,
    from_frame: usize,
    inputs: &pipeline::TransitionInputs,
    raw: &[f32],
    blended: &[f32],
    state: &TransitionState,
) -> TaskResult<()> {
    let d = inputs.target.len();
    let rows = |v: &[f32]| v.chunks_exact(d).map(<[f32]>::to_vec).collect::<Vec<_>>();
    if let Some(i) = raw.iter().chain(blended).position(|v| !v.is_finite()) {
        bail!("--positions {}: the network gave a non-finite position (value {i}); nothing written", path.display());
    }
    let v = serde_json::json!({
        "format": zoo_data::positions::POSITIONS_FORMAT,
        "version": 1,
        "command": "transition",
        "joints": model.metadata.skeleton.names,
        "fps": from.fps(),
        "first_frame": from_frame,
        "past": rows(&inputs.past),
        "target": inputs.target,
        "next": inputs.next,
        "raw": rows(raw),
        "frames": rows(blended),
        "miss": state.target_miss().map_or(0.0, |m| m.mean),
        "fallback_weight": state.fallback_weight(),
    });
    zoo_data::positions::write(path, &v).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Runs `zoo transition`: the transition written with the clips around it; returns what the
/// command says.
pub fn run(a: &TransitionOptions, p: &dyn Progress) -> TaskResult<String> {
    let ((pa, fa), (pb, fb)) = (a.from.clone(), a.to.clone());
    let opts = clip_io::ReadOptions { drop_dummy_root: true, take: a.take.clone() };
    let ca = clip_io::read_model_clip_with(&pa, &opts).map_err(Message::new)?;
    let cb = clip_io::read_model_clip_with(&pb, &opts).map_err(Message::new)?;
    // The model's skeleton is needed first only to map another rig onto it.
    let mut source = None;
    if a.rig_map.is_some() {
        source = Some(ModelSource::open_for(&a.model, TASKS, "transition")?);
    }
    let model_skeleton = source.as_ref().map(ModelSource::skeleton);
    let (mut ca, mut cb, rig_back) = match &model_skeleton {
        Some(s) => map_rig(a, s, ca, cb)?,
        None => (ca, cb, None),
    };
    if a.foot_lock
        && zoo_protocol::footlock::FootLock::from_skeleton(&ca.skeleton.names, &ca.skeleton.parents).is_none()
    {
        bail!(
            "--foot-lock: the skeleton of {} has no foot joint (a joint named like `foot` with a parent and a \
             grandparent), so there is nothing to lock; drop --foot-lock, or rename the ankles (e.g. LeftFoot)",
            pa.display()
        );
    }
    // A clip whose dummy root moves while the other's does not is folded to the other's
    // skeleton (as in a dataset); then the frames asked for, before any model is read.
    let (sa, sb) = (ca.skeleton.clone(), cb.skeleton.clone());
    for (clip, other, path) in [(&mut ca, &sb, &pa), (&mut cb, &sa, &pb)] {
        if let Some(clip_io::Conformed::Folded(how)) =
            clip_io::conform(clip, &|s| other.topology_difference(s).is_none(), None)
        {
            eprintln!("{}: {how}", path.display());
        }
    }
    pipeline::check_transition(&ca, fa, &cb, fb, a.frames)
        .with_context(|| format!("--from {} --to {} --frames {}", a.from_label, a.to_label, a.frames))?;
    let source = match source {
        Some(s) => s,
        None => ModelSource::open_for(&a.model, TASKS, "transition")?,
    };
    let inbetween = source.metadata.task.kind() == MotionTaskKind::Keyframes;
    if inbetween {
        refuse_for_inbetween(a, &source)?;
    }
    check_skeleton(&source, &mut ca, &pa)?;
    if rig_back.is_none() {
        note_other_names(&source.skeleton(), &ca, p);
    }
    check_skeleton(&source, &mut cb, &pb)?;
    // Clips at another frame rate than the model's are resampled to it (a note says so), their
    // frame numbers carried to the new rate; the output is at the model's rate.
    let fps = f64::from(source.metadata.fps);
    let (mut fa, mut fb) = (fa, fb);
    for (clip, frame, path) in [(&mut ca, &mut fa, &pa), (&mut cb, &mut fb, &pb)] {
        if let Some((note, ratio)) = clip_io::to_frame_rate(clip, fps, path).map_err(Message)? {
            eprintln!("{note}");
            *frame = ((*frame as f64 * ratio).round() as usize).min(clip.frames().saturating_sub(1));
        }
    }
    pipeline::check_transition(&ca, fa, &cb, fb, a.frames).with_context(|| {
        format!("--from {} --to {} --frames {} (at the model's {fps} fps)", a.from_label, a.to_label, a.frames)
    })?;
    if inbetween {
        return run_inbetween(a, &source, (&ca, fa), (cb, fb), rig_back.as_ref());
    }
    // On terrain both clips stand in the heightmap's world frame: the target stays on its
    // ground instead of being moved to where the source's last speed would take it. With
    // `--in-place` the user says the clips share one world frame.
    let inputs = if a.heightmap.is_some() || a.in_place {
        pipeline::transition_inputs_in_place(&ca, fa, &cb, fb, a.frames)
    } else {
        pipeline::transition_inputs(&ca, fa, &mut cb, fb, a.frames)
    }
    .with_context(|| format!("--from {} --to {} --frames {}", a.from_label, a.to_label, a.frames))?;
    let (model, mut runner) = runner(&source, a.no_fallback, a.foot_lock)?;
    let terrain = read_heightmap(a.heightmap.as_deref(), &a.model, model.terrain().is_some(), &pa)?.map(Arc::new);
    let d = 3 * model.joints();
    let mut state = model.new_transition();
    state.set_heightmap(terrain.clone());
    let mut y = vec![0f32; (a.frames + 1) * d];
    runner
        .generate(&mut state, &inputs.past, &inputs.target, &inputs.next, &mut y)
        .context("generating the transition")?;
    if let Some(path) = &a.positions {
        let mut raw_state = model.new_transition();
        raw_state.set_heightmap(terrain);
        let mut raw = vec![0f32; y.len()];
        runner
            .start_for(&mut raw_state, &inputs.past, &inputs.target, &inputs.next, a.frames)
            .context("generating the raw transition for --positions")?;
        for frame in raw.chunks_exact_mut(d) {
            runner.step_raw(&mut raw_state, frame).context("generating the raw transition for --positions")?;
        }
        // The raw file records the unlocked, unblended network: the blended frames are the
        // ones the output's rotations are fitted to.
        write_transition_positions(path, &source, &ca, fa, &inputs, &raw, &y, &state)?;
    }
    let miss = state.target_miss().map_or(0.0, |m| m.mean);
    let mut said = match model.default_fallback_for(a.frames).filter(|_| !a.no_fallback) {
        Some(f) => format!(
            "target miss {miss:.2} (fallback from {:.2}, fully at {:.2}): interpolation weight {:.2}\n",
            f.start,
            f.full,
            state.fallback_weight()
        ),
        None => format!("target miss {miss:.2} (no fallback)\n"),
    };
    let mut out = pipeline::splice_transition(&ca, fa, &cb, fb, &inputs, &y, false);
    if let Some((rig, back)) = &rig_back {
        out = zoo_data::retarget::retarget(&out, rig, back);
    }
    clip_io::write(&out, &a.out).map_err(Message::new)?;
    if let Some(p) = &a.positions {
        said += &format!("positions: {} (raw and blended network frames, model units)\n", p.display());
    }
    Ok(said
        + &format!(
            "wrote {}: {} frames of {}, {} generated, {} of {} (transition frames {}..{})",
            a.out.display(),
            fa,
            pa.display(),
            a.frames,
            cb.frames() - fb,
            pb.display(),
            fa,
            fa + a.frames
        ))
}

/// The tasks `zoo transition` runs: the RTN's, and the in-betweening design's whole shots.
const TASKS: &[MotionTaskKind] = &[MotionTaskKind::Transition, MotionTaskKind::Keyframes];

/// Refuses what the in-betweening design cannot do (an ARNN step graph, a heightmap, a
/// positions file), before the clips are prepared.
fn refuse_for_inbetween(a: &TransitionOptions, source: &ModelSource) -> TaskResult<()> {
    let model = source.path.display();
    if source.metadata.task.as_keyframes().and_then(|k| k.inbetween.as_ref()).is_none() {
        bail!(
            "{model} is an ARNN step graph (`zoo train arnn` without --design inbetween): it completes keys (`zoo              complete`); `zoo transition` runs an RTN or the in-betweening design"
        );
    }
    if a.heightmap.is_some() {
        bail!(
            "--heightmap: the in-betweening network in {model} has no terrain input; drop --heightmap, or use a model              trained with `zoo train rtn --terrain`"
        );
    }
    if a.positions.is_some() {
        bail!(
            "--positions: the in-betweening network in {model} works on joint rotations, not global positions, so              there is no positions file; drop --positions (the output clip holds its frames)"
        );
    }
    Ok(())
}

/// `zoo transition` with the in-betweening design: the `CONTEXT_FRAMES` frames before the --from
/// frame and the (aligned) --to frame are its keys, and the runtime's keyframes task fills the
/// gap in one call, as `zoo bench` scores it (`arnn:`); the keys are met exactly, and
/// `--foot-lock` locks the feet between them as `zoo complete` does.
fn run_inbetween(
    a: &TransitionOptions,
    source: &ModelSource,
    (ca, fa): (&Clip, usize),
    (mut cb, fb): (Clip, usize),
    rig_back: Option<&(Skeleton, zoo_data::retarget::RigMatch)>,
) -> TaskResult<String> {
    let context = || format!("--from {} --to {} --frames {}", a.from_label, a.to_label, a.frames);
    if !a.in_place {
        // The --to clip moved and turned to follow on from the --from clip, as for the RTN.
        pipeline::transition_inputs(ca, fa, &mut cb, fb, a.frames).with_context(context)?;
    }
    let (j, n, past) = (ca.joints(), a.frames, pipeline::CONTEXT_FRAMES);
    // The shot: the context, `n` frames the network fills (their values are never read), the
    // target.
    let mut shot = ca.slice(fa - past, fa);
    for _ in 0..n {
        shot.local_rotations.extend_from_slice(&ca.local_rotations[(fa - 1) * j..fa * j]);
        shot.local_positions.extend_from_slice(&ca.local_positions[(fa - 1) * j..fa * j]);
    }
    shot.local_rotations.extend_from_slice(&cb.local_rotations[fb * j..(fb + 1) * j]);
    shot.local_positions.extend_from_slice(&cb.local_positions[fb * j..(fb + 1) * j]);
    let key = |f: usize| zoo_arnn::humanoid::HumanoidKey { frame: f, source: f, fixed: None };
    let keys: Vec<_> = (0..past).chain([past + n]).map(key).collect();
    let net = crate::complete::RuntimeKeyNet::new(source)?;
    if a.no_fallback {
        net.runner.borrow_mut().set_fallback(None)?;
    }
    let fps = f64::from(source.metadata.fps);
    let mut done = zoo_arnn::humanoid::complete_clip_with(&shot, &keys, Some(fps), |frames, poses, fixed| {
        zoo_arnn::completion::KeyNet::complete(&net, frames, poses, fixed)
    })
    .map_err(|e| Message(format!("{}: {e}", context())))?;
    if a.foot_lock {
        let frames: Vec<usize> = keys.iter().map(|k| k.frame).collect();
        zoo_arnn::completion::lock_feet(&mut done.clip, &frames, &zoo_arnn::completion::KeyNet::kept(&net));
    }
    let mut out = ca.slice(0, fa);
    out.local_rotations.extend_from_slice(&done.clip.local_rotations[past * j..(past + n) * j]);
    out.local_positions.extend_from_slice(&done.clip.local_positions[past * j..(past + n) * j]);
    out.local_rotations.extend_from_slice(&cb.local_rotations[fb * j..]);
    out.local_positions.extend_from_slice(&cb.local_positions[fb * j..]);
    out.remove_sign_flips();
    if let Some((rig, back)) = rig_back {
        out = zoo_data::retarget::retarget(&out, rig, back);
    }
    clip_io::write(&out, &a.out).map_err(Message::new)?;
    Ok(format!(
        "in-betweening design: the gap filled in one call, keys met within {:.1e} cm and {:.1e} deg\n\
         wrote {}: {} frames of {}, {} generated, {} of {} (transition frames {}..{})",
        done.root_miss,
        done.angle_miss.0,
        a.out.display(),
        fa,
        a.from.0.display(),
        n,
        cb.frames() - fb,
        a.to.0.display(),
        fa,
        fa + n
    ))
}

/// Temporal super-resolution (RTN sec. 7.4) on the runtime: rebuilds a clip from its `context`
/// frames (`past * 3K`) and one keyframe pair (the keyframe and the frame after it, `2 * 3K`
/// each in `keys`) every `interval` frames by chaining transitions, each fed the last `past`
/// frames generated so far and target-blended; from the second segment on, the context ends
/// on the stored frame after the previous keyframe. Returns `past + keys * interval` frames.
pub fn super_resolve(
    model: &TransitionModel,
    runner: &mut TransitionRunner,
    context: &[f32],
    keys: &[f32],
    interval: usize,
) -> TaskResult<Vec<f32>> {
    let d = 3 * model.joints();
    if context.is_empty() || !context.len().is_multiple_of(d) || interval == 0 || !keys.len().is_multiple_of(2 * d) {
        bail!("super-resolution needs whole context frames, interval >= 1 and whole (key, next) frame pairs");
    }
    let past = context.len() / d;
    let mut state = model.new_transition();
    let mut transition = |ctx: &[f32], key: &[f32], n: usize| -> TaskResult<Vec<f32>> {
        // A transition of no frame is its target frame, which the target blend meets.
        if n == 0 {
            return Ok(key[..d].to_vec());
        }
        let mut y = vec![0f32; (n + 1) * d];
        runner.generate(&mut state, ctx, &key[..d], &key[d..], &mut y)?;
        Ok(y)
    };
    let mut clip = context.to_vec();
    let mut prev_next: Option<&[f32]> = None;
    for key in keys.chunks_exact(2 * d) {
        // After the first keyframe, the stored frame after it is known motion: the next
        // segment's context ends on it, so the segment starts with the true velocity at the
        // key instead of the target blend's slowdown (which chained transitions amplify).
        match prev_next {
            Some(next) if interval >= 3 => {
                let mut ctx = clip[clip.len() - (past - 1) * d..].to_vec();
                ctx.extend_from_slice(next);
                let y = transition(&ctx, key, interval - 2)?;
                clip.extend_from_slice(next);
                clip.extend_from_slice(&y);
            }
            _ => {
                let ctx = clip[clip.len() - past * d..].to_vec();
                let y = transition(&ctx, key, interval - 1)?;
                clip.extend_from_slice(&y);
            }
        }
        prev_next = Some(&key[d..]);
    }
    Ok(clip)
}

/// The options of `zoo decompress`.
#[derive(Clone, Debug)]
pub struct DecompressOptions {
    /// Run folder of `zoo train rtn`, or its exported file.
    pub model: PathBuf,
    /// Clip to compress and rebuild.
    pub input: PathBuf,
    /// Frames between keyframes (default: one keyframe per second).
    pub interval: Option<usize>,
    /// Output clip.
    pub out: PathBuf,
}

/// Runs `zoo decompress`: the clip rebuilt from its first frames and one keyframe per
/// interval; returns what the command says.
pub fn decompress(a: &DecompressOptions) -> TaskResult<String> {
    let mut clip = clip_io::read_model_clip(&a.input).map_err(Message::new)?;
    let source = ModelSource::open(&a.model, MotionTaskKind::Transition, "decompress")?;
    check_skeleton(&source, &mut clip, &a.input)?;
    if let Some((note, _)) =
        clip_io::to_frame_rate(&mut clip, f64::from(source.metadata.fps), &a.input).map_err(Message)?
    {
        eprintln!("{note}");
    }
    let (model, mut runner) = runner(&source, true, false)?;
    let interval = a.interval.unwrap_or_else(|| clip.fps().round() as usize).max(1);
    let j = clip.joints();
    let keys = pipeline::keyframe_inputs(&clip, interval).with_context(|| format!("{}", a.input.display()))?;
    let y = super_resolve(&model, &mut runner, &keys.context, &keys.keys, interval).context("rebuilding the clip")?;
    let frames = y.len() / (3 * j);
    let mut out = pipeline::rebuild_from_keyframes(&clip, interval, &y);
    let tail = pipeline::fill_tail(&mut out, &clip);
    clip_io::write(&out, &a.out).map_err(Message::new)?;
    let err = pipeline::mean_position_error(&clip, &y);
    let tail = match tail {
        0 => String::new(),
        n => format!(", and the last {n} frame(s) after the last keyframe in-betweened to the clip's last frame"),
    };
    Ok(format!(
        "rebuilt {frames} frames of {} from {} context frames and {} keyframes (every {interval}){tail}; mean joint \
         position error {err:.2} (clip units, network frames); wrote {} ({} frames)",
        a.input.display(),
        pipeline::CONTEXT_FRAMES,
        keys.key_count,
        a.out.display(),
        out.frames()
    ))
}
