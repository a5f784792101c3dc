//! Completing an animator's keys into a whole motion (`zoo complete`): the keys file (format in
//! docs/arnn.md, "Keys file"; lamp poses, or humanoid poses from a BVH with partial keys), the
//! completion written as a clip (and as JSON, positions and a plot of every degree of freedom,
//! like the paper's Figure 8).

use crate::ArnnResult;
use crate::luxo::LampPose;
use crate::luxo::sequence::poses_to_clip;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use zoo_data::{Context, Message, bail};

/// The longest span of keys completed, in frames.
pub const MAX_FRAMES: usize = 100_000;

/// The largest frame number of a keys file (`frame`, `source_frame`, `frames`): the command
/// line's frame index range (about 92 hours at 30 fps).
pub const MAX_KEY_FRAME: usize = 10_000_000;

/// The largest value of a lamp key's pose, either way: metres for the base's position (10 km),
/// radians for the angles. The network works in f32 on normalised values: far beyond the
/// training data it gives no useful motion, and past f32's range (about 3.4e38) its rows are
/// NaN.
pub const MAX_KEY_VALUE: f64 = 10_000.0;

/// Format name of a keys file.
pub const KEYS_FORMAT: &str = "zoo-arnn-keys";
/// Format name of the JSON written by `--json`.
pub const COMPLETION_FORMAT: &str = "zoo-arnn-completion";
/// Frames per second of the BVH when neither the keys file nor `--fps` gives one: the lamp's
/// hops (25 network frames from liftoff to landing, about 0.45 s) play near their simulated speed.
pub const DEFAULT_FPS: f64 = 50.0;

/// One key as written in the file: a lamp key gives its `pose`; a humanoid key takes its pose
/// from frame `source_frame` (default: `frame`) of the file's `bvh` and may fix only some
/// `joints` (`"root"`: the root position).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeyEntry {
    frame: usize,
    pose: Option<Vec<f64>>,
    source_frame: Option<usize>,
    joints: Option<Vec<String>>,
}

/// A keys file as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeysFile {
    format: Option<String>,
    version: Option<u32>,
    dof_names: Option<Vec<String>>,
    fps: Option<f64>,
    frames: Option<usize>,
    bvh: Option<PathBuf>,
    keys: Vec<KeyEntry>,
}

/// Checked keys: frames relative to the first key (which is frame 0), one pose per key.
#[derive(Debug, PartialEq)]
pub struct Keys {
    /// Key frames, strictly increasing, the first 0.
    pub frames: Vec<usize>,
    /// Frame of the first key in the file (the output starts there).
    pub offset: usize,
    /// One pose per key.
    pub poses: Vec<Vec<f64>>,
    /// Frames per second, if the file gives it.
    pub fps: Option<f64>,
}

/// Parses and checks the text of a keys file for a model of `dof_names` degrees of freedom.
/// Errors say what is wrong and how to fix it (without the file name).
pub fn parse_keys(text: &str, dof_names: &[String]) -> Result<Keys, String> {
    let file = parse_file(text)?;
    if file.bvh.is_some() || file.keys.iter().any(|k| k.joints.is_some() || k.source_frame.is_some()) {
        return Err(
            "\"bvh\", \"source_frame\" and \"joints\" are for humanoid models; this model completes the lamp's \
                    degrees of freedom: give each key a \"pose\""
                .into(),
        );
    }
    let d = dof_names.len();
    if let Some(names) = &file.dof_names
        && names != dof_names
    {
        return Err(format!(
            "the keys are for the degrees of freedom {names:?}, but the model was trained on {dof_names:?}: this \
             keys file is for another character"
        ));
    }
    for (i, k) in file.keys.iter().enumerate() {
        let Some(pose) = &k.pose else {
            return Err(format!(
                "key {i} (frame {}) has no \"pose\": give its {d} values ({})",
                k.frame,
                dof_names.join(", ")
            ));
        };
        if pose.len() != d {
            return Err(format!(
                "key {i} (frame {}) has {} values; the model completes {d} degrees of freedom: {}",
                k.frame,
                pose.len(),
                dof_names.join(", ")
            ));
        }
        if let Some(j) = pose.iter().position(|v| !v.is_finite()) {
            return Err(format!("key {i} (frame {}): {} is {}, not a finite number", k.frame, dof_names[j], pose[j]));
        }
        if let Some(j) = pose.iter().position(|v| v.abs() > MAX_KEY_VALUE) {
            return Err(format!(
                "key {i} (frame {}): {} is {:?}, outside the valid range [-{MAX_KEY_VALUE}, {MAX_KEY_VALUE}] (metres \
                 or radians)",
                k.frame, dof_names[j], pose[j]
            ));
        }
    }
    let offset = file.keys[0].frame;
    Ok(Keys {
        frames: file.keys.iter().map(|k| k.frame - offset).collect(),
        offset,
        poses: file.keys.into_iter().map(|k| k.pose.unwrap_or_default()).collect(),
        fps: file.fps,
    })
}

/// Checked humanoid keys ([`parse_humanoid_keys`]).
#[derive(Debug, PartialEq)]
pub struct HumanoidKeys {
    /// The BVH holding the key poses, as the file names it (relative to the keys file).
    pub bvh: PathBuf,
    /// Frame of the first key in the file (the output starts there).
    pub offset: usize,
    /// The keys, frames relative to the first.
    pub keys: Vec<crate::humanoid::HumanoidKey>,
    /// Frames per second, if the file gives it.
    pub fps: Option<f64>,
}

/// Parses and checks a humanoid keys file for a model of joints `joint_names`: the poses come
/// from the file's `bvh`, a key's `joints` (names, `"root"` for the root position) fix only
/// those parts of its pose.
pub fn parse_humanoid_keys(text: &str, joint_names: &[String]) -> Result<HumanoidKeys, String> {
    let file = parse_file(text)?;
    let Some(bvh) = file.bvh.clone() else {
        return Err(
            "a humanoid model takes its key poses from a BVH: add \"bvh\": \"POSES.bvh\" (relative to the keys \
                    file) and give each key the \"frame\" (and \"source_frame\") of its pose there"
                .into(),
        );
    };
    if file.dof_names.is_some() || file.keys.iter().any(|k| k.pose.is_some()) {
        return Err("\"pose\" and \"dof_names\" are for the lamp; a humanoid key's pose comes from the \"bvh\" (its \
                    \"source_frame\")"
            .into());
    }
    let offset = file.keys[0].frame;
    let groups = 1 + joint_names.len();
    let mut keys = Vec::with_capacity(file.keys.len());
    for (i, k) in file.keys.iter().enumerate() {
        let fixed = match &k.joints {
            None => None,
            Some(names) => {
                let mut m = vec![false; groups];
                for n in names {
                    let g = if n == "root" {
                        0
                    } else {
                        1 + joint_names.iter().position(|j| j == n).ok_or_else(|| {
                            format!(
                                "key {i} (frame {}) fixes joint \"{n}\", which the model's skeleton does not have \
                                 (joints: root, {}): this keys file is for another skeleton",
                                k.frame,
                                joint_names.join(", ")
                            )
                        })?
                    };
                    m[g] = true;
                }
                if !m.contains(&true) {
                    return Err(format!(
                        "key {i} (frame {}) fixes no joint: list at least one, or drop the key",
                        k.frame
                    ));
                }
                if i == 0 && m.contains(&false) {
                    return Err(
                        "the first key is the start pose: it must fix the whole pose (leave out \"joints\")".into()
                    );
                }
                Some(m)
            }
        };
        keys.push(crate::humanoid::HumanoidKey {
            frame: k.frame - offset,
            source: k.source_frame.unwrap_or(k.frame),
            fixed,
        });
    }
    Ok(HumanoidKeys { bvh, offset, keys, fps: file.fps })
}

/// Parses a keys file and checks what every model needs: format, version, fps, at least two
/// keys in increasing frame order, `frames` consistent with the last key, the span.
fn parse_file(text: &str) -> Result<KeysFile, String> {
    let file: KeysFile = serde_json::from_str(text).map_err(|e| {
        format!(
            "not a keys file: {e} (expected {{\"format\": \"{KEYS_FORMAT}\", \"version\": 1, \"keys\": [{{\"frame\": 0, \
             \"pose\": [...]}}, ...]}}; NaN and infinity are not JSON numbers, every value must be finite)"
        )
    })?;
    if let Some(f) = &file.format
        && f != KEYS_FORMAT
    {
        return Err(format!("format is \"{f}\", expected \"{KEYS_FORMAT}\""));
    }
    if let Some(v) = file.version
        && v != 1
    {
        return Err(format!("keys file version {v} is not known to this zoo (it reads version 1): update zoo"));
    }
    // The command line's range of frame rates (`zoo complete --fps`): 1e-30 or 1e30 fps is a typo.
    if let Some(fps) = file.fps
        && !(1.0..=1000.0).contains(&fps)
    {
        return Err(format!("fps {fps} is outside the valid range [1, 1000] frames per second"));
    }
    let n = file.keys.len();
    if n > MAX_FRAMES {
        return Err(format!(
            "{n} keys given: at most {MAX_FRAMES} (one per frame of the longest completion, {MAX_FRAMES} frames)"
        ));
    }
    if n < 2 {
        return Err(format!(
            "{n} key(s) given: completion needs at least 2 (the motion is filled in between the first and the last key)"
        ));
    }
    for (i, k) in file.keys.iter().enumerate() {
        for (name, f) in [("frame", Some(k.frame)), ("source_frame", k.source_frame)] {
            if let Some(f) = f
                && f > MAX_KEY_FRAME
            {
                return Err(format!(
                    "key {i} has \"{name}\": {f}, outside the valid range 0..={MAX_KEY_FRAME} (the command line's frame \
                     numbers)"
                ));
            }
        }
        if i > 0 && k.frame <= file.keys[i - 1].frame {
            return Err(format!(
                "key {i} is at frame {} but key {} is at frame {}: keys must be in increasing frame order, one key per \
                 frame",
                k.frame,
                i - 1,
                file.keys[i - 1].frame
            ));
        }
    }
    if let Some(len) = file.frames
        && len > MAX_KEY_FRAME + 1
    {
        return Err(format!("\"frames\" is {len}, outside the valid range 0..={} frames", MAX_KEY_FRAME + 1));
    }
    if let Some(len) = file.frames {
        let last = file.keys[n - 1].frame;
        if let Some((i, k)) = file.keys.iter().enumerate().find(|(_, k)| k.frame >= len) {
            return Err(format!(
                "key {i} is at frame {}, past the sequence of {len} frames (frames 0 to {}): move it inside or \
                 raise \"frames\"",
                k.frame,
                len.saturating_sub(1)
            ));
        }
        if last + 1 != len {
            return Err(format!(
                "the sequence has {len} frames but its last key is at frame {last}: the motion ends on the last key: \
                 add a key at frame {} (or set \"frames\" to {})",
                len - 1,
                last + 1
            ));
        }
    }
    let offset = file.keys[0].frame;
    let span = file.keys[n - 1].frame - offset;
    if span >= MAX_FRAMES {
        return Err(format!(
            "the keys span {span} frames (frame {offset} to {}), past the {} frames zoo complete generates",
            file.keys[n - 1].frame,
            MAX_FRAMES
        ));
    }
    Ok(file)
}

/// What `zoo complete` writes: the completion as a clip (`out`), and optionally as JSON, as
/// global joint positions, and as a plot of every degree of freedom (lamp only).
#[derive(Clone, Debug)]
pub struct CompleteOptions {
    /// Run folder of `zoo train arnn`.
    pub model: PathBuf,
    /// The keys file.
    pub keys: PathBuf,
    /// Output clip.
    pub out: PathBuf,
    /// Every completed pose (and the key misses) as JSON.
    pub json: Option<PathBuf>,
    /// Each degree of freedom over the frames with the keys, as a PNG (lamp only).
    pub plot: Option<PathBuf>,
    /// Keep a base that sinks below the ground where the network put it (lamp only).
    pub no_ground: bool,
    /// Humanoid keys: no foot lock between the keys ([`zoo_protocol::keylock`]).
    pub no_foot_lock: bool,
    /// The in-betweening design: the network alone, without the fallback towards the curves its
    /// run calibrated ([`zoo_protocol::inbetween::Fallback`]).
    pub no_fallback: bool,
    /// Frames per second of the output (`None`: the keys file's, else [`DEFAULT_FPS`]).
    pub fps: Option<f64>,
    /// The global joint positions of every completed frame (a positions file).
    pub positions: Option<PathBuf>,
    /// Humanoid keys without a keys file: a clip (BVH, glTF, FBX) and where its keys are.
    pub poses: Option<PoseKeys>,
}

/// Humanoid keys read from a clip instead of a keys file (`zoo complete --poses CLIP`).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseKeys {
    /// The clip (any format `zoo` reads).
    pub clip: PathBuf,
    /// The keys' frames in the output; `None` with [`Self::every`].
    pub frames: Option<Vec<usize>>,
    /// Keys every this many frames (instead of [`Self::frames`]).
    pub every: Option<usize>,
    /// `false`: the clip holds only the key poses, one per frame, in order. `true`: the clip is
    /// a whole motion and the keys are its poses at the key frames.
    pub sample: bool,
}

impl PoseKeys {
    /// The keys for a clip of `n` frames: output frame and clip frame of each.
    pub fn keys(&self, n: usize) -> Result<Vec<crate::humanoid::HumanoidKey>, String> {
        let frames: Vec<usize> = match (&self.frames, self.every) {
            (Some(f), None) => f.clone(),
            (None, Some(k)) if k > 0 && self.sample => (0..n).step_by(k).collect(),
            (None, Some(k)) if k > 0 => (0..n).map(|i| i * k).collect(),
            _ => return Err("give the key frames with either --key-frames LIST or --every K (K > 0)".into()),
        };
        if frames.len() < 2 {
            return Err(format!("{} key(s): completion needs at least two", frames.len()));
        }
        if frames.len() > MAX_FRAMES {
            return Err(format!(
                "{} key frames given: at most {MAX_FRAMES} (one per frame of the longest completion)",
                frames.len()
            ));
        }
        if let Some(&f) = frames.iter().find(|&&f| f > MAX_KEY_FRAME) {
            return Err(format!(
                "key frame {f} is outside the valid range 0..={MAX_KEY_FRAME} (the bound of a keys file's frames)"
            ));
        }
        if let Some(i) = frames.windows(2).position(|w| w[0] >= w[1]) {
            return Err(format!("--key-frames must strictly increase: {} then {}", frames[i], frames[i + 1]));
        }
        let span = frames[frames.len() - 1] - frames[0];
        if span >= MAX_FRAMES {
            return Err(format!(
                "the key frames span {span} frames (frame {} to {}), past the {MAX_FRAMES} frames zoo complete \
                 generates: bring the keys closer",
                frames[0],
                frames[frames.len() - 1]
            ));
        }
        if self.sample {
            if let Some(&f) = frames.iter().find(|&&f| f >= n) {
                return Err(format!("key frame {f} is past the clip's {n} frames (0 to {})", n.saturating_sub(1)));
            }
        } else if frames.len() != n {
            return Err(format!(
                "{} key frames for a clip of {n} poses: the clip holds one key pose per frame, give one key frame per \
                 pose (or --sample to take the key frames out of a whole motion)",
                frames.len()
            ));
        }
        let first = frames[0];
        Ok(frames
            .iter()
            .enumerate()
            .map(|(i, &f)| crate::humanoid::HumanoidKey {
                frame: f - first,
                source: if self.sample { f } else { i },
                fixed: None,
            })
            .collect())
    }
}

fn read_keys(path: &Path, dof_names: &[String]) -> ArnnResult<Keys> {
    let text = std::fs::read_to_string(path).with_context(|| format!("--keys {}: cannot read it", path.display()))?;
    Ok(parse_keys(&text, dof_names).map_err(|e| Message(format!("--keys {}: {e}", path.display())))?)
}

/// Writes the positions file of the completed clip, when asked.
fn write_positions(o: &CompleteOptions, clip: &zoo_motion::Clip, first_frame: usize) -> ArnnResult<()> {
    let Some(p) = &o.positions else { return Ok(()) };
    let extra = serde_json::json!({ "first_frame": first_frame });
    let v = zoo_data::positions::clip_positions_json("complete", clip, extra).map_err(zoo_data::Message::new)?;
    zoo_data::positions::write(p, &v).with_context(|| format!("writing {}", p.display()))?;
    Ok(())
}

/// Writes `value` as pretty JSON to `path` (atomically).
fn write_json(path: &Path, value: &serde_json::Value) -> ArnnResult<()> {
    let text = serde_json::to_string_pretty(value).context("JSON")?;
    zoo_format::atomic::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Writes the completed clip to `o.out`, its positions file and its JSON (the completion's
/// header and `fields`) when asked.
fn write_outputs(
    o: &CompleteOptions,
    clip: &zoo_motion::Clip,
    first_frame: usize,
    fps: f64,
    fields: serde_json::Value,
) -> ArnnResult<()> {
    if !fps.is_finite() {
        bail!("the completion's frame rate is {fps}: give --fps");
    }
    zoo_data::clip_io::write(clip, &o.out).with_context(|| format!("writing {}", o.out.display()))?;
    write_positions(o, clip, first_frame)?;
    let Some(j) = &o.json else { return Ok(()) };
    let mut v = serde_json::json!({
        "format": COMPLETION_FORMAT,
        "version": 1,
        "model": o.model,
        "fps": fps,
        "first_frame": first_frame,
    });
    if let (Some(v), serde_json::Value::Object(fields)) = (v.as_object_mut(), fields) {
        v.extend(fields);
    }
    write_json(j, &v)
}

/// The foot lock between the keys of a completed humanoid clip ([`zoo_protocol::keylock`], the
/// clip's own bone offsets), as `zoo complete` and the runtime's keyframes task apply it,
/// scaled by the share of the correction the fallback `kept` per frame (empty: none;
/// [`KeyNet::kept`]); returns the number of frames it changed (0 without legs).
pub fn lock_feet(clip: &mut zoo_motion::Clip, key_frames: &[usize], kept: &[f64]) -> usize {
    let Some(lock) = zoo_protocol::keylock::key_foot_lock(&clip.skeleton) else { return 0 };
    let j = clip.joints();
    let offsets = zoo_protocol::pipeline::rest_offsets(clip);
    let root: Vec<glam::DVec3> = clip.local_positions.iter().step_by(j.max(1)).copied().collect();
    let skeleton = clip.skeleton.clone();
    zoo_protocol::keylock::lock_feet_between_keys(
        &lock,
        &skeleton,
        &offsets,
        key_frames,
        kept,
        &root,
        &mut clip.local_rotations,
    )
}

/// The keyframe network `zoo complete` runs: the exported model through the engine runtime
/// (`zoo_tasks::complete`), what engines, Python and Blender run.
pub trait KeyNet {
    /// A humanoid network's skeleton and frame rate; `None` for the lamp.
    fn humanoid(&self) -> Option<&crate::config::HumanoidSkeleton>;
    /// The lamp ARNN's configuration (its geometry, degrees of freedom and their names); `None`
    /// for a humanoid network.
    fn lamp(&self) -> Option<&crate::ArnnConfig>;
    /// The network's own completion of keys (frames from 0, one pose per key, per key and group
    /// whether the key fixes it, or nothing for whole keys): the poses of frames `0..=last key`,
    /// keys not hit, feet not locked.
    fn complete(&self, frames: &[usize], poses: &[Vec<f64>], fixed: &[Vec<bool>]) -> ArnnResult<Vec<Vec<f64>>>;
    /// The share of the network's correction its fallback towards the curves kept on each
    /// frame of the last completion (empty: no fallback), which scales the foot lock.
    fn kept(&self) -> Vec<f64> {
        Vec::new()
    }
}

/// Completes the keys of `o` with `net` and writes what `o` asks for; returns the summary the
/// command prints.
pub fn complete_command(o: &CompleteOptions, net: &dyn KeyNet) -> ArnnResult<String> {
    match (net.humanoid(), net.lamp()) {
        (Some(skeleton), _) => complete_humanoid(o, net, skeleton),
        (None, Some(config)) => complete_lamp(o, net, config),
        (None, None) => bail!("{}: the model is neither a humanoid nor the lamp's keyframe network", o.model.display()),
    }
}

/// The key misses of a lamp completion: the largest in position and in angle.
fn lamp_misses(misses: &[Vec<f64>], dofs: usize) -> ((f64, usize, usize), (f64, usize, usize)) {
    let worst = |range: std::ops::Range<usize>| {
        misses
            .iter()
            .enumerate()
            .flat_map(|(k, m)| range.clone().map(move |j| (m[j].abs(), k, j)))
            .fold((0.0, 0, 0), |a, b| if b.0 > a.0 { b } else { a })
    };
    (worst(0..2), worst(2..dofs.max(2)))
}

/// The completed pose at each key frame minus the key.
fn misses_at_keys(frames: &[Vec<f64>], key_frames: &[usize], key_poses: &[Vec<f64>]) -> Vec<Vec<f64>> {
    key_frames.iter().zip(key_poses).map(|(&f, p)| frames[f].iter().zip(p).map(|(y, x)| y - x).collect()).collect()
}

/// `zoo complete` with the lamp's ARNN.
fn complete_lamp(o: &CompleteOptions, net: &dyn KeyNet, config: &crate::ArnnConfig) -> ArnnResult<String> {
    let Some(lamp) = config.lamp.clone() else {
        bail!("{}: the model has no lamp geometry in config.json (retrain it with `zoo train arnn`)", o.model.display())
    };
    let dof_names: Vec<String> = if config.dof_names.is_empty() {
        (0..config.dofs).map(|i| format!("dof{i}")).collect()
    } else {
        config.dof_names.clone()
    };
    if o.poses.is_some() {
        bail!("--poses is for humanoid models; the lamp's keys come from a keys file (--keys)");
    }
    let keys = read_keys(&o.keys, &dof_names)?;
    let fps = o.fps.or(keys.fps).unwrap_or(DEFAULT_FPS);
    let mut frames = net.complete(&keys.frames, &keys.poses, &[])?;
    // The network's own misses, before the keys are hit.
    let raw_misses = misses_at_keys(&frames, &keys.frames, &keys.poses);
    crate::hit_keys(config, &keys.frames, &keys.poses, &[], &mut frames);
    let lamp_dofs = config.dofs == crate::luxo::DOFS && dof_names == crate::luxo::DOF_NAMES;
    let lift = if o.no_ground || !lamp_dofs { 0.0 } else { crate::eval::project_to_ground(&lamp, &mut frames) };
    let misses = misses_at_keys(&frames, &keys.frames, &keys.poses);
    let poses: Vec<LampPose> = frames
        .iter()
        .map(|f| <LampPose>::try_from(f.as_slice()))
        .collect::<Result<_, _>>()
        .map_err(|_| Message(format!("the model completes {} values per frame, not the lamp's 6", config.dofs)))?;
    let clip = poses_to_clip(&poses, fps, &lamp);
    // Checked before `json!`, which would turn a NaN into `null`.
    zoo_motion::finite::check_serialize(
        "the lamp completion (.0: key misses, .1: the network's, .2: ground lift, .3: frames)",
        &(&misses, &raw_misses, lift, &frames),
    )
    .map_err(zoo_data::Message::new)?;
    let fields = serde_json::json!({
        "dof_names": dof_names,
                "key_frames": keys.frames,
                "key_misses": misses,
                "network_key_misses": raw_misses,
                "ground_lift": lift,
                "frames": frames,
    });
    write_outputs(o, &clip, keys.offset, fps, fields)?;
    if let Some(p) = &o.plot {
        let keyed: Vec<(usize, Vec<f64>)> = keys.frames.iter().copied().zip(keys.poses.iter().cloned()).collect();
        plot_dofs(p, &[DofSeries { frames: &frames, rgb: (31, 80, 180), width: 2.0 }], &keyed)?;
    }
    let ((pos, pk, pj), (ang, ak, aj)) = lamp_misses(&raw_misses, config.dofs);
    let ((hit_pos, _, _), (hit_ang, _, _)) = lamp_misses(&misses, config.dofs);
    let mut s = String::new();
    if lift > 0.0 {
        s += &format!(
            "the network's base sank up to {:.2} cm below the ground: lifted onto it (--no-ground keeps it)\n",
            lift * 100.0
        );
    }
    Ok(s + &format!(
        "completed {} frames from {} keys ({} fps) into {}{}; the network's largest key miss: {:.2} cm ({} at key \
         {pk}), {:.2} deg ({} at key {ak}); corrected towards the keys, largest miss {:.1e} cm, {:.1e} deg",
        frames.len(),
        keys.frames.len(),
        fps,
        o.out.display(),
        o.json.as_ref().map(|j| format!(" and {}", j.display())).unwrap_or_default(),
        pos * 100.0,
        dof_names[pj],
        ang.to_degrees(),
        dof_names.get(aj).map_or("-", |s| s.as_str()),
        hit_pos * 100.0,
        hit_ang.to_degrees(),
    ))
}

/// The frame rate at which a glTF file's key times become frames when `--fps` is not given.
pub const KEY_TIMES_FPS: f64 = 30.0;

/// The key poses of a glTF file read at its own key times, and their frames at `fps` (the
/// first key at frame 0); refused when two keys fall on one frame.
pub fn key_poses(path: &Path, fps: f64) -> Result<(zoo_motion::Clip, Vec<usize>), String> {
    let (mut clip, times) = zoo_data::clip_io::read_key_poses(path, &Default::default()).map_err(|e| e.to_string())?;
    // Its poses stand at those frames of a clip at `fps`.
    clip.frame_time = 1.0 / fps;
    let frames: Vec<usize> = times.iter().map(|t| (t * fps).round() as usize).collect();
    if let Some(i) = frames.windows(2).position(|w| w[0] == w[1]) {
        return Err(format!(
            "its keys at {:.4} s and {:.4} s fall on the same frame at {fps} fps: give a higher --fps, or the key \
             frames with --key-frames",
            times[i],
            times[i + 1]
        ));
    }
    Ok((clip, frames))
}

/// Brings the clip the keys' poses come from to the model's frame rate `fps`. A whole motion
/// (the keys file's clip, or `--poses` with `--sample`) at another rate is resampled as every
/// command resamples a clip ([`zoo_data::clip_io::to_frame_rate`], with its note), and the
/// keys' clip frames carried to the new rate (with `--sample` the output frames too: they are
/// the clip's). A clip of key poses only (one pose per frame) has no motion between its frames:
/// its rate says nothing and it is taken at the model's.
fn at_model_rate(
    o: &CompleteOptions,
    source: &mut zoo_motion::Clip,
    keys: &mut HumanoidKeys,
    fps: f64,
) -> ArnnResult<()> {
    let sample = match &o.poses {
        Some(p) if !p.sample => {
            source.frame_time = 1.0 / fps;
            return Ok(());
        }
        Some(_) => true,
        None => false,
    };
    let path = match &o.poses {
        Some(p) => p.clip.clone(),
        None => o.keys.parent().unwrap_or(Path::new(".")).join(&keys.bvh),
    };
    let Some((note, ratio)) = zoo_data::clip_io::to_frame_rate(source, fps, &path).map_err(Message)? else {
        return Ok(());
    };
    eprintln!("{note}");
    let last = source.frames().saturating_sub(1);
    for k in &mut keys.keys {
        k.source = ((k.source as f64 * ratio).round() as usize).min(last);
    }
    if sample {
        let first = keys.keys[0].source;
        for k in &mut keys.keys {
            k.frame = k.source - first;
        }
        keys.offset = first;
        if let Some(w) = keys.keys.windows(2).find(|w| w[0].frame >= w[1].frame) {
            bail!(
                "two keys fall on frame {} of the clip at the model's {fps} fps: space the key frames further apart",
                w[1].source
            );
        }
    }
    Ok(())
}

/// `zoo complete` with a humanoid ARNN: key poses from a BVH, partial keys, a clip out.
fn complete_humanoid(
    o: &CompleteOptions,
    net: &dyn KeyNet,
    skeleton: &crate::config::HumanoidSkeleton,
) -> ArnnResult<String> {
    let joint_names = &skeleton.names;
    if o.plot.is_some() || o.no_ground {
        bail!(
            "--plot and --no-ground are for the lamp; look at a humanoid completion with `zoo render {}`",
            o.out.display()
        );
    }
    let (keys, source, what) = match &o.poses {
        Some(p) if p.frames.is_none() && p.every.is_none() => {
            // A glTF file's own key times give the frames.
            let (source, frames) = key_poses(&p.clip, o.fps.unwrap_or(KEY_TIMES_FPS))
                .map_err(|e| Message(format!("--poses {}: {e}", p.clip.display())))?;
            let p = PoseKeys { frames: Some(frames), ..p.clone() };
            let keys = p.keys(source.frames()).map_err(|e| Message(format!("--poses {}: {e}", p.clip.display())))?;
            (
                HumanoidKeys { bvh: p.clip.clone(), offset: 0, keys, fps: Some(o.fps.unwrap_or(KEY_TIMES_FPS)) },
                source,
                format!("--poses {} (its key times)", p.clip.display()),
            )
        }
        Some(p) => {
            let source = zoo_data::clip_io::read_model_clip(&p.clip)
                .with_context(|| format!("--poses {}: reading it", p.clip.display()))?;
            let keys = p.keys(source.frames()).map_err(|e| Message(format!("--poses {}: {e}", p.clip.display())))?;
            let offset = if p.sample { keys[0].source } else { 0 };
            (
                HumanoidKeys { bvh: p.clip.clone(), offset, keys, fps: None },
                source,
                format!("--poses {}", p.clip.display()),
            )
        }
        None => {
            let text = std::fs::read_to_string(&o.keys)
                .with_context(|| format!("--keys {}: cannot read it", o.keys.display()))?;
            let keys = parse_humanoid_keys(&text, joint_names)
                .map_err(|e| Message(format!("--keys {}: {e}", o.keys.display())))?;
            let bvh = o.keys.parent().unwrap_or(Path::new(".")).join(&keys.bvh);
            let source = zoo_data::clip_io::read_model_clip(&bvh)
                .with_context(|| format!("--keys {}: reading its bvh {}", o.keys.display(), bvh.display()))?;
            (keys, source, format!("--keys {}", o.keys.display()))
        }
    };
    crate::humanoid::check_trained_skeleton(skeleton, &source.skeleton).context(what.clone())?;
    let (mut source, mut keys) = (source, keys);
    at_model_rate(o, &mut source, &mut keys, skeleton.fps).context(what.clone())?;
    // The output is at the model's frame rate: key frames numbered at another rate (the keys
    // file's `fps`, or `--fps`) are carried to it, with a note.
    if let Some(given) = o.fps.or(keys.fps)
        && !zoo_motion::clip::same_frame_rate(given, skeleton.fps)
    {
        let ratio = skeleton.fps / given;
        for k in &mut keys.keys {
            k.frame = (k.frame as f64 * ratio).round() as usize;
        }
        if let Some(w) = keys.keys.windows(2).find(|w| w[0].frame >= w[1].frame) {
            bail!(
                "{what}: two keys fall on frame {} at the model's {} fps (the keys are numbered at {given} fps): space \
                 them further apart",
                w[1].frame,
                skeleton.fps
            );
        }
        eprintln!(
            "note: the keys are numbered at {given} fps, the model runs at {} fps: their frames are carried to {} fps, \
             the rate of the output",
            skeleton.fps, skeleton.fps
        );
    }
    let mut done =
        crate::humanoid::complete_clip_with(&source, &keys.keys, Some(skeleton.fps), |f, p, x| net.complete(f, p, x))
            .context(what)?;
    let key_frames: Vec<usize> = keys.keys.iter().map(|k| k.frame).collect();
    let locked = if o.no_foot_lock { 0 } else { lock_feet(&mut done.clip, &key_frames, &net.kept()) };
    done.clip.frame_time = 1.0 / skeleton.fps;
    let (raw_root, (deg, key, joint)) = done.raw_miss;
    zoo_motion::finite::check_serialize(
        "the completion's key misses (root, angle, the network's root and angle)",
        &(done.root_miss, done.angle_miss.0, raw_root, deg),
    )
    .map_err(zoo_data::Message::new)?;
    let fields = serde_json::json!({
        "key_frames": key_frames,
                "foot_lock_frames": locked,
                "root_miss": done.root_miss,
                "angle_miss_degrees": done.angle_miss.0,
                "network_root_miss": raw_root,
                "network_angle_miss_degrees": deg,
                "frames": done.clip.frames(),
    });
    write_outputs(o, &done.clip, keys.offset, 1.0 / done.clip.frame_time, fields)?;
    Ok(format!(
        "completed {} frames from {} keys ({} partial) into {}{}; the network's largest key miss: root {:.2} (clip \
         units), {:.2} deg ({} at key {key}); corrected towards the keys, largest miss {:.1e}, {:.1e} deg; {}",
        done.clip.frames(),
        keys.keys.len(),
        keys.keys.iter().filter(|k| k.fixed.as_ref().is_some_and(|f| f.contains(&false))).count(),
        o.out.display(),
        o.json.as_ref().map(|j| format!(" and {}", j.display())).unwrap_or_default(),
        raw_root,
        deg,
        joint_names.get(joint).map_or("-", |s| s.as_str()),
        done.root_miss,
        done.angle_miss.0,
        if o.no_foot_lock {
            "no foot lock (--no-foot-lock)".to_string()
        } else {
            format!("feet locked between the keys on {locked} frames (--no-foot-lock: off)")
        },
    ))
}

/// One curve of [`plot_dofs`]: a pose per frame and its colour.
pub struct DofSeries<'a> {
    /// Poses, one per frame from frame 0.
    pub frames: &'a [Vec<f64>],
    /// Colour (red, green, blue).
    pub rgb: (u8, u8, u8),
    /// Line width in pixels.
    pub width: f32,
}

/// Plots each degree of freedom over the frames, one panel per degree of freedom (two columns,
/// in pose order, each scaled to its own range), like the paper's Figure 8: the curves of
/// `series` in order (later ones on top) and the keys as circles. 960 x 720 pixels.
pub fn plot_dofs(path: &Path, series: &[DofSeries], keys: &[(usize, Vec<f64>)]) -> ArnnResult<()> {
    use tiny_skia::{Color, Paint, PathBuilder, Pixmap, Stroke, Transform};
    let d = series.first().and_then(|s| s.frames.first()).map_or(0, |f| f.len());
    let frames = series.iter().map(|s| s.frames.len()).max().unwrap_or(0);
    if d == 0 || frames < 2 {
        bail!("{}: nothing to plot", path.display());
    }
    let (w, h, cols) = (960u32, 720u32, 2usize);
    let rows = d.div_ceil(cols);
    let (pw, ph, m) = (w as f32 / cols as f32, h as f32 / rows as f32, 14.0f32);
    let mut pm = Pixmap::new(w, h).context("cannot allocate the plot")?;
    pm.fill(Color::WHITE);
    let mut paint = Paint { anti_alias: true, ..Paint::default() };
    for j in 0..d {
        let (x0, y0) = ((j % cols) as f32 * pw, (j / cols) as f32 * ph);
        let values = series.iter().flat_map(|s| s.frames.iter().map(|f| f[j])).chain(keys.iter().map(|k| k.1[j]));
        let (lo, hi) =
            values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        let (lo, hi) = if hi - lo < 1e-9 { (lo - 0.5, hi + 0.5) } else { (lo, hi) };
        let x = |t: usize| x0 + m + (pw - 2.0 * m) * t as f32 / (frames - 1) as f32;
        let y = |v: f64| y0 + ph - m - (ph - 2.0 * m) * ((v - lo) / (hi - lo)) as f32;
        // Panel frame.
        paint.set_color_rgba8(190, 190, 190, 255);
        if let Some(r) = tiny_skia::Rect::from_xywh(x0 + m, y0 + m, pw - 2.0 * m, ph - 2.0 * m) {
            let p = PathBuilder::from_rect(r);
            pm.stroke_path(&p, &paint, &Stroke::default(), Transform::identity(), None);
        }
        for s in series {
            let mut pb = PathBuilder::new();
            for (t, f) in s.frames.iter().enumerate().filter(|(_, f)| f[j].is_finite()) {
                if pb.is_empty() { pb.move_to(x(t), y(f[j])) } else { pb.line_to(x(t), y(f[j])) }
            }
            paint.set_color_rgba8(s.rgb.0, s.rgb.1, s.rgb.2, 255);
            if let Some(p) = pb.finish() {
                pm.stroke_path(
                    &p,
                    &paint,
                    &Stroke { width: s.width, ..Stroke::default() },
                    Transform::identity(),
                    None,
                );
            }
        }
        paint.set_color_rgba8(0, 110, 40, 255);
        for (t, pose) in keys {
            if let Some(c) = PathBuilder::from_circle(x(*t), y(pose[j]), 5.0) {
                pm.stroke_path(&c, &paint, &Stroke { width: 2.0, ..Stroke::default() }, Transform::identity(), None);
            }
        }
    }
    let png = pm.encode_png().map_err(|e| Message(format!("{}: cannot encode the PNG: {e}", path.display())))?;
    zoo_format::atomic::write(path, png).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        crate::luxo::DOF_NAMES.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn keys_parse_and_start_at_frame_zero() {
        let text = r#"{"format": "zoo-arnn-keys", "version": 1, "fps": 30,
            "keys": [{"frame": 5, "pose": [0, 0.02, 0, 0.5, -1.1, -1.2]}, {"frame": 29, "pose": [0.4, 0.02, 0, 0.5, -1.1, -1.2]}]}"#;
        let k = parse_keys(text, &names()).unwrap();
        assert_eq!((k.frames, k.offset, k.fps), (vec![0, 24], 5, Some(30.0)));
    }

    #[test]
    fn a_keys_files_frame_rate_outside_the_command_lines_range_is_refused() {
        for fps in ["1e-30", "1e30", "0", "-30"] {
            let text = format!(
                r#"{{"format": "zoo-arnn-keys", "version": 1, "fps": {fps},
                "keys": [{{"frame": 0, "pose": [0, 0.02, 0, 0.5, -1.1, -1.2]}}, {{"frame": 9, "pose": [0, 0.02, 0, 0.5, -1.1, -1.2]}}]}}"#
            );
            let e = parse_keys(&text, &names()).unwrap_err();
            assert!(e.contains("is outside the valid range [1, 1000] frames per second"), "{fps}: {e}");
        }
    }

    #[test]
    fn humanoid_keys_name_joints_and_refuse_lamp_fields() {
        let joints: Vec<String> = ["Hips", "Spine", "Head"].iter().map(|s| s.to_string()).collect();
        let k = parse_humanoid_keys(
            r#"{"bvh": "a.bvh", "keys": [{"frame": 4}, {"frame": 10, "source_frame": 50, "joints": ["root", "Head"]},
                {"frame": 20}]}"#,
            &joints,
        )
        .unwrap();
        assert_eq!((k.bvh, k.offset), (PathBuf::from("a.bvh"), 4));
        assert_eq!(k.keys.iter().map(|k| (k.frame, k.source)).collect::<Vec<_>>(), [(0, 4), (6, 50), (16, 20)]);
        assert_eq!(k.keys[1].fixed, Some(vec![true, false, false, true]));
        assert_eq!((k.keys[0].fixed.clone(), k.keys[2].fixed.clone()), (None, None));
        let err = |t: &str| parse_humanoid_keys(t, &joints).unwrap_err();
        assert!(err(r#"{"keys": [{"frame": 0}, {"frame": 5}]}"#).contains("add \"bvh\""));
        assert!(
            err(r#"{"bvh": "a.bvh", "keys": [{"frame": 0, "pose": [1]}, {"frame": 5}]}"#).contains("are for the lamp")
        );
        assert!(
            err(r#"{"bvh": "a.bvh", "keys": [{"frame": 0}, {"frame": 5, "joints": []}]}"#).contains("fixes no joint")
        );
        assert!(
            err(r#"{"bvh": "a.bvh", "keys": [{"frame": 0, "joints": ["Hips"]}, {"frame": 5}]}"#).contains("start pose")
        );
        assert!(
            err(r#"{"bvh": "a.bvh", "keys": [{"frame": 0}, {"frame": 5, "joints": ["Tail"]}]}"#)
                .contains("another skeleton")
        );
        // The lamp refuses humanoid fields.
        let e = parse_keys(r#"{"bvh": "a.bvh", "keys": [{"frame": 0}, {"frame": 5}]}"#, &names()).unwrap_err();
        assert!(e.contains("are for humanoid models"), "{e}");
    }

    #[test]
    fn pose_clips_give_keys_by_frame_list_spacing_or_sampling() {
        let p = |frames: Option<Vec<usize>>, every: Option<usize>, sample: bool| PoseKeys {
            clip: "k.bvh".into(),
            frames,
            every,
            sample,
        };
        let pairs = |k: Vec<crate::humanoid::HumanoidKey>| k.iter().map(|k| (k.frame, k.source)).collect::<Vec<_>>();
        assert_eq!(pairs(p(Some(vec![5, 17, 35]), None, false).keys(3).unwrap()), [(0, 0), (12, 1), (30, 2)]);
        assert_eq!(pairs(p(None, Some(15), false).keys(3).unwrap()), [(0, 0), (15, 1), (30, 2)]);
        assert_eq!(pairs(p(None, Some(20), true).keys(50).unwrap()), [(0, 0), (20, 20), (40, 40)]);
        assert_eq!(pairs(p(Some(vec![10, 40]), None, true).keys(50).unwrap()), [(0, 10), (30, 40)]);
        let e = p(Some(vec![0, 12]), None, false).keys(3).unwrap_err();
        assert!(e.contains("2 key frames for a clip of 3 poses"), "{e}");
        let e = p(Some(vec![0, 12, 12]), None, false).keys(3).unwrap_err();
        assert!(e.contains("must strictly increase: 12 then 12"), "{e}");
        let e = p(Some(vec![0, 60]), None, true).keys(50).unwrap_err();
        assert!(e.contains("key frame 60 is past the clip's 50 frames"), "{e}");
        assert!(p(None, None, false).keys(3).unwrap_err().contains("--key-frames LIST or --every K"));
    }

    /// `--key-frames 0,X` with X up to 2^64-1 divided by zero (X + 1 frames wrapped to 0),
    /// aborted at 2^32 and ran a minute at 10^7: the frames are bounded like a keys file's.
    #[test]
    fn key_frames_past_the_keys_files_bounds_are_refused_before_any_work() {
        let p =
            |frames: Vec<usize>| PoseKeys { clip: "k.bvh".into(), frames: Some(frames), every: None, sample: false };
        for x in [usize::MAX, 1 << 32, 10_000_001] {
            let e = p(vec![0, x]).keys(2).unwrap_err();
            assert!(e.contains(&format!("key frame {x} is outside the valid range 0..=10000000")), "{e}");
        }
        let e = p(vec![0, 10_000_000]).keys(2).unwrap_err();
        assert!(e.contains("the key frames span 10000000 frames (frame 0 to 10000000), past the 100000 frames"), "{e}");
        let e = p(vec![0, 100_000]).keys(2).unwrap_err();
        assert!(e.contains("span 100000 frames"), "{e}");
        assert_eq!(p(vec![0, 99_999]).keys(2).unwrap()[1].frame, 99_999);
    }

    #[test]
    fn bad_keys_are_named() {
        let pose = "[0, 0.02, 0, 0.5, -1.1, -1.2]";
        let err = |t: String| parse_keys(&t, &names()).unwrap_err();
        let e = err(format!(r#"{{"keys": [{{"frame": 0, "pose": {pose}}}]}}"#));
        assert!(e.contains("1 key(s) given: completion needs at least 2"), "{e}");
        let e = err(format!(r#"{{"keys": [{{"frame": 9, "pose": {pose}}}, {{"frame": 3, "pose": {pose}}}]}}"#));
        assert!(e.contains("key 1 is at frame 3 but key 0 is at frame 9"), "{e}");
        let e = err(format!(r#"{{"keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 3, "pose": [1, 2]}}]}}"#));
        assert!(e.contains("key 1 (frame 3) has 2 values; the model completes 6"), "{e}");
        let e = err(format!(
            r#"{{"keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 3, "pose": [NaN, 0, 0, 0, 0, 0]}}]}}"#
        ));
        assert!(e.contains("not a keys file") && e.contains("finite"), "{e}");
        let e = err(format!(
            r#"{{"dof_names": ["a"], "keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 5, "pose": {pose}}}]}}"#
        ));
        assert!(e.contains("another character"), "{e}");
        let e = err(format!(r#"{{"keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 300000, "pose": {pose}}}]}}"#));
        assert!(e.contains("past the 100000 frames"), "{e}");
        let e = err(format!(
            r#"{{"frames": 10, "keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 10, "pose": {pose}}}]}}"#
        ));
        assert!(e.contains("key 1 is at frame 10, past the sequence of 10 frames (frames 0 to 9)"), "{e}");
        let k = parse_keys(
            &format!(r#"{{"frames": 11, "keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 10, "pose": {pose}}}]}}"#),
            &names(),
        )
        .unwrap();
        assert_eq!(k.frames, vec![0, 10]);
    }

    #[test]
    fn keys_at_the_value_bound_complete_to_finite_frames() {
        // A lamp model (seeded random weights) with the smallest std the statistics allow: a key
        // of 10,000 normalises to 1e10, far from f32's limit, so every completed value is finite.
        let config = crate::ArnnConfig::tiny();
        let varmap = candle_nn::VarMap::new();
        let vb = zoo_nn::SeededVarMap::builder(&varmap, 1, candle_core::DType::F32, &candle_core::Device::Cpu);
        let model = crate::Arnn::new(&config, vb).unwrap();
        let norm = crate::Normalization { mean: vec![0.0; 6], std: vec![1e-6; 6] };
        let b = MAX_KEY_VALUE;
        let text = format!(
            r#"{{"keys": [{{"frame": 0, "pose": [{b}, -{b}, {b}, -{b}, {b}, -{b}]}}, {{"frame": 20, "pose": [-{b}, {b}, 0, 0, 0, {b}]}}]}}"#
        );
        let keys = parse_keys(&text, &names()).unwrap();
        let frames = crate::complete(&model, &norm, &keys.frames, &keys.poses).unwrap();
        assert_eq!(frames.len(), 21);
        assert!(frames.iter().flatten().all(|v| v.is_finite()), "{frames:?}");
    }

    #[test]
    fn key_values_frame_numbers_and_key_counts_past_their_bounds_are_refused_with_the_range() {
        let pose = "[0, 0.02, 0, 0.5, -1.1, -1.2]";
        let lamp = |a: &str, b: &str| parse_keys(&format!(r#"{{"keys": [{a}, {b}]}}"#), &names());
        // At the bounds: loads.
        let k = lamp(
            &format!(r#"{{"frame": 10000000, "pose": [10000, -10000, 0, 0, 0, 0]}}"#),
            &format!(r#"{{"frame": 10000005, "pose": {pose}}}"#),
        );
        assert!(k.is_err(), "frame 10000005 is past the bound");
        let k = lamp(
            &format!(r#"{{"frame": 9999990, "pose": [10000, -10000, 0, 0, 0, 0]}}"#),
            &format!(r#"{{"frame": 10000000, "pose": {pose}}}"#),
        )
        .unwrap();
        assert_eq!((k.offset, k.frames.clone()), (9_999_990, vec![0, 10]));
        for (a, b, want) in [
            // The huge value that gave a completion of NaN rows.
            (
                format!(r#"{{"frame": 0, "pose": {pose}}}"#),
                r#"{"frame": 5, "pose": [1e300, 0, 0, 0, 0, 0]}"#.to_string(),
                "key 1 (frame 5): base_x is 1e300, outside the valid range [-10000, 10000]",
            ),
            (
                format!(r#"{{"frame": 0, "pose": {pose}}}"#),
                r#"{"frame": 5, "pose": [0, 0, 0, 0, 0, -10000.5]}"#.to_string(),
                "theta3 is -10000.5",
            ),
            (
                format!(r#"{{"frame": 18446744073709551610, "pose": {pose}}}"#),
                format!(r#"{{"frame": 18446744073709551615, "pose": {pose}}}"#),
                "key 0 has \"frame\": 18446744073709551610, outside the valid range 0..=10000000",
            ),
        ] {
            let e = lamp(&a, &b).unwrap_err();
            assert!(e.contains(want), "{a} {b}: {e}");
        }
        let e = parse_keys(
            &format!(r#"{{"frames": 18446744073709551615, "keys": [{{"frame": 0, "pose": {pose}}}, {{"frame": 1, "pose": {pose}}}]}}"#),
            &names(),
        )
        .unwrap_err();
        assert!(e.contains("\"frames\" is 18446744073709551615, outside the valid range 0..=10000001"), "{e}");
        let many: Vec<String> = (0..=MAX_FRAMES).map(|f| format!(r#"{{"frame": {f}, "pose": {pose}}}"#)).collect();
        let e = parse_keys(&format!(r#"{{"keys": [{}]}}"#, many.join(",")), &names()).unwrap_err();
        assert!(e.contains("100001 keys given: at most 100000"), "{e}");
        // Humanoid keys: the source frame too.
        let joints = vec!["hips".to_string()];
        let e = parse_humanoid_keys(
            r#"{"bvh": "p.bvh", "keys": [{"frame": 0}, {"frame": 4, "source_frame": 99999999999}]}"#,
            &joints,
        )
        .unwrap_err();
        assert!(e.contains("key 1 has \"source_frame\": 99999999999, outside the valid range 0..=10000000"), "{e}");
        assert!(
            parse_humanoid_keys(
                r#"{"bvh": "p.bvh", "keys": [{"frame": 0}, {"frame": 4, "source_frame": 10000000}]}"#,
                &joints
            )
            .is_ok()
        );
    }
}
