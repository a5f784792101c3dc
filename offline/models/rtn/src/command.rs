//! The commands of a trained RTN (`zoo transition`, `zoo decompress`'s checks): the clips read
//! (mapped onto the model's rig with a joint-name map), the skeleton and terrain checked
//! against the model, the transition generated (with its fallback) and spliced between the
//! clips, and its positions file.

use crate::RtnResult;
use std::path::{Path, PathBuf};
use zoo_data::clip_io;
use zoo_data::{Context, Message, Progress, bail};
use zoo_motion::Clip;
use zoo_motion::pipeline;

/// The options of `zoo transition`.
#[derive(Clone, Debug)]
pub struct TransitionOptions {
    /// Run folder of `zoo train rtn`.
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
}

/// The heightmap of `zoo transition` and `--heightmap`'s checks against the model: required by
/// a terrain-aware model (the error names the --from clip's sibling heightmap when there is
/// one), refused by a model without terrain input.
pub fn read_heightmap(
    heightmap: Option<&Path>,
    model_dir: &Path,
    config: &crate::Config,
    from_clip: &Path,
) -> RtnResult<Option<zoo_data::terrain::Heightmap>> {
    match (heightmap, config.terrain) {
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
                model_dir.display()
            )
        }
        (Some(p), false) => bail!(
            "--heightmap {}: the model in {} has no terrain input (trained without --terrain); drop --heightmap \
             or use a model trained with `zoo train rtn --terrain`",
            p.display(),
            model_dir.display()
        ),
        (None, false) => Ok(None),
    }
}

/// The model's skeleton from its run folder's skeleton.json (what --rig-map maps onto).
fn run_skeleton(model_dir: &Path) -> RtnResult<zoo_motion::Skeleton> {
    let s = zoo_nn::checkpoint::RunSkeleton::read(model_dir)?.with_context(|| {
        format!(
            "--rig-map: the run folder {} has no skeleton.json (trained by an older zoo), so the model's joint names \
             are unknown; retrain, or rename the clips' joints to the training skeleton's",
            model_dir.display()
        )
    })?;
    let n = s.names.len();
    Ok(zoo_motion::Skeleton {
        names: s.names,
        parents: s.parents.iter().map(|&p| usize::try_from(p).ok()).collect(),
        offsets: s.offsets.iter().map(|o| glam::DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)).collect(),
        end_sites: vec![None; n],
        channels: vec![Default::default(); n],
    })
}

/// Says so (a notice) when the clip's joint names are not the model's: another rig with the
/// model's hierarchy runs, but `--rig-map` maps it onto the model's proportions.
fn note_other_names(model_dir: &Path, clip: &Clip, p: &dyn Progress) {
    if let Ok(Some(run)) = zoo_nn::checkpoint::RunSkeleton::read(model_dir)
        && run.names != clip.skeleton.names
    {
        let (k, (model, theirs)) = run
            .names
            .iter()
            .zip(&clip.skeleton.names)
            .enumerate()
            .find(|(_, (m, c))| m != c)
            .unwrap_or((0, (&run.names[0], &clip.skeleton.names[0])));
        p.notice(&format!(
            "note: the clip's joint names differ from the model's (joint {k}: `{theirs}`, the model's `{model}`); \
             if it is another rig, pass --rig-map MAP.json to map it onto the model's skeleton (docs/formats.md)"
        ));
    }
}

/// The --from and --to clips on the model's skeleton (with --rig-map), and what maps the
/// result back onto the --from clip's rig.
type RigBack = Option<(zoo_motion::Skeleton, zoo_data::retarget::RigMatch)>;
fn map_rig(a: &TransitionOptions, ca: Clip, cb: Clip) -> RtnResult<(Clip, Clip, RigBack)> {
    let Some(map_path) = &a.rig_map else { return Ok((ca, cb, None)) };
    let map = zoo_data::retarget::RigMap::read(map_path).map_err(Message::new)?;
    let target = run_skeleton(&a.model)?;
    let ma =
        map.match_rigs(&ca.skeleton, &target, true).with_context(|| format!("--rig-map --from {}", a.from_label))?;
    let mb = map.match_rigs(&cb.skeleton, &target, true).with_context(|| format!("--rig-map --to {}", a.to_label))?;
    let (ra, rb) = (zoo_data::retarget::retarget(&ca, &target, &ma), zoo_data::retarget::retarget(&cb, &target, &mb));
    println!(
        "--rig-map: {} joints mapped onto the model's skeleton, root translation x{:.4}",
        target.len(),
        ma.root_scale
    );
    let back = ma.inverse(ca.joints());
    Ok((ra, rb, Some((ca.skeleton, back))))
}

/// Refuses a clip whose skeleton is not the model's: another joint count, or the same count
/// in another hierarchy (the parents the run folder's `config.json` records).
/// Brings `clip` (read from `path`) to the skeleton of the model in `model_dir` by the one rule of
/// [`zoo_data::clip_io::conform`] (a moving dummy root folded, said on stderr), then refuses it
/// when it is still on another one.
pub fn check_skeleton(model_dir: &Path, config: &crate::Config, clip: &mut Clip, path: &Path) -> RtnResult<()> {
    let fits = |s: &zoo_motion::Skeleton| {
        s.len() == config.joints && (config.parents.is_empty() || s.parents_i32() == config.parents)
    };
    if let Some(clip_io::Conformed::Folded(how)) = clip_io::conform(clip, &fits, None) {
        eprintln!("{}: {how}", path.display());
    }
    if config.joints != clip.joints() {
        bail!(
            "the model in {} was trained on {} joints, {} has {}",
            model_dir.display(),
            config.joints,
            path.display(),
            clip.joints()
        );
    }
    let parents = clip.skeleton.parents_i32();
    if !config.parents.is_empty() && config.parents != parents {
        let j = (0..parents.len()).find(|&j| config.parents[j] != parents[j]).unwrap_or(0);
        bail!(
            "{} has the model's {} joints but another hierarchy: joint {j} (`{}`) has parent {}, the model in {} \
             was trained with parent {}; use a clip of the training skeleton",
            path.display(),
            config.joints,
            clip.skeleton.names[j],
            parents[j],
            model_dir.display(),
            config.parents[j]
        );
    }
    Ok(())
}

/// Writes the `--positions` file of a transition: inputs, raw and blended frames (`3K` global
/// positions each, joint-major, model units).
#[allow(clippy::too_many_arguments)]
fn write_transition_positions(
    path: &Path,
    a: &TransitionOptions,
    from: &Clip,
    from_frame: usize,
    inputs: &pipeline::TransitionInputs,
    raw: &[f32],
    blended: &[f32],
    miss: f32,
    weight: f32,
) -> RtnResult<()> {
    let d = inputs.target.len();
    let rows = |v: &[f32]| v.chunks_exact(d).map(<[f32]>::to_vec).collect::<Vec<_>>();
    if let Some(i) = raw.iter().chain(blended).position(|v| !v.is_finite()) {
        bail!("--positions {}: the network gave a non-finite position (value {i}); nothing written", path.display());
    }
    let joints = match zoo_nn::checkpoint::RunSkeleton::read(&a.model)? {
        Some(s) => s.names,
        None => from.skeleton.names.clone(),
    };
    let v = serde_json::json!({
        "format": zoo_data::positions::POSITIONS_FORMAT,
        "version": 1,
        "command": "transition",
        "joints": joints,
        "fps": from.fps(),
        "first_frame": from_frame,
        "past": rows(&inputs.past),
        "target": inputs.target,
        "next": inputs.next,
        "raw": rows(raw),
        "frames": rows(blended),
        "miss": miss,
        "fallback_weight": weight,
    });
    zoo_data::positions::write(path, &v).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Runs `zoo transition`: the transition written with the clips around it; returns what the
/// command says.
pub fn run(a: &TransitionOptions, p: &dyn Progress) -> RtnResult<String> {
    let ((pa, fa), (pb, fb)) = (a.from.clone(), a.to.clone());
    let opts = clip_io::ReadOptions { drop_dummy_root: true, take: a.take.clone() };
    let ca = clip_io::read_model_clip_with(&pa, &opts).map_err(Message::new)?;
    let cb = clip_io::read_model_clip_with(&pb, &opts).map_err(Message::new)?;
    let (mut ca, mut cb, rig_back) = map_rig(a, ca, cb)?;
    if a.foot_lock && zoo_motion::footlock::FootLock::from_skeleton(&ca.skeleton.names, &ca.skeleton.parents).is_none()
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
    let (model, stats) = crate::checkpoint::load_run(&a.model, "transition")?;
    check_skeleton(&a.model, model.config(), &mut ca, &pa)?;
    if rig_back.is_none() {
        note_other_names(&a.model, &ca, p);
    }
    check_skeleton(&a.model, model.config(), &mut cb, &pb)?;
    // On terrain both clips stand in the heightmap's world frame: the target stays on its
    // ground instead of being moved to where the source's last speed would take it.
    let inputs = match a.heightmap {
        Some(_) => pipeline::transition_inputs_in_place(&ca, fa, &cb, fb, a.frames),
        None => pipeline::transition_inputs(&ca, fa, &mut cb, fb, a.frames),
    }
    .with_context(|| format!("--from {} --to {} --frames {}", a.from_label, a.to_label, a.frames))?;
    let terrain = read_heightmap(a.heightmap.as_deref(), &a.model, model.config(), &pa)?;
    let fallback = model.config().fallback_for(a.frames).filter(|_| !a.no_fallback);
    let checked = model
        .transition_checked(
            &stats,
            &inputs.past,
            &inputs.target,
            &inputs.next,
            a.frames,
            terrain.as_ref(),
            fallback.as_ref(),
        )
        .context("generating the transition")?;
    let y = checked.frames;
    zoo_motion::finite::check_values(
        "the RTN transition network (check the run folder's normalization.json)",
        "frames",
        &y,
    )
    .map_err(Message::new)?;
    if let Some(path) = &a.positions {
        let raw = model
            .unroll(&stats, &inputs.past, &inputs.target, &inputs.next, a.frames, terrain.as_ref())
            .context("generating the raw transition for --positions")?;
        write_transition_positions(path, a, &ca, fa, &inputs, &raw, &y, checked.miss, checked.weight)?;
    }
    let mut said = match &fallback {
        Some(f) => format!(
            "target miss {:.2} (fallback from {:.2}, fully at {:.2}): interpolation weight {:.2}\n",
            checked.miss, f.start, f.full, checked.weight
        ),
        None => format!("target miss {:.2} (no fallback)\n", checked.miss),
    };
    let mut out = pipeline::splice_transition(&ca, fa, &cb, fb, &inputs, &y, a.foot_lock);
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
