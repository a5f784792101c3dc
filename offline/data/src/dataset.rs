//! Datasets: folders of clips (BVH, glTF, FBX: [`crate::clip_io`]), name-glob splits, sliding windows with the benchmark's
//! centring and facing unification, and normalization statistics.

use crate::bvh::BvhError;

/// Where a training command's clips come from: `data` split by `valid_glob`, or synthetic
/// locomotion generated in memory with every tenth clip held out.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingClips {
    /// BVH file or folder (`None`: synthetic locomotion generated in memory).
    pub data: Option<PathBuf>,
    /// Glob on file names selecting the validation split of `data`.
    pub valid_glob: Option<String>,
    /// Clips of `data` left out (their file names match).
    pub exclude_glob: Option<String>,
    /// Leave out the clips of `data` that cannot join the dataset, and list them.
    pub skip_invalid: bool,
    /// Minutes of synthetic motion without `data`.
    pub synth_minutes: f64,
    /// Seed of the synthetic motion.
    pub seed: u64,
}

/// The split of synthetic clips: every tenth clip validates; with fewer than ten, the last one.
pub fn split_synth<T>(clips: Vec<T>) -> (Vec<T>, Vec<T>) {
    let n = clips.len();
    let (mut train, mut valid) = (Vec::new(), Vec::new());
    for (i, c) in clips.into_iter().enumerate() {
        if i % 10 == 9 || (n < 10 && i + 1 == n) { valid.push(c) } else { train.push(c) }
    }
    (train, valid)
}

/// A synthetic clip as a named clip (its name as its path).
pub fn named_synth(c: crate::synth::SynthClip) -> NamedClip {
    NamedClip { path: PathBuf::from(&c.name), name: c.name, clip: c.clip }
}

/// Training and validation clips and where they came from, in words: `data` split by
/// `valid_glob` (after leaving out `exclude_glob`), or synthetic clips with every tenth clip
/// held out. Notices go to `progress`.
pub fn training_clips(
    t: &TrainingClips,
    progress: &dyn crate::Progress,
) -> Result<(Vec<NamedClip>, Vec<NamedClip>, String), crate::Message> {
    let Some(path) = &t.data else {
        if t.exclude_glob.is_some() {
            return Err(crate::Message::new("--exclude-glob leaves clips of --data out: pass --data too"));
        }
        let (minutes, seed) = (t.synth_minutes, t.seed);
        let cfg = crate::synth::SynthConfig { minutes, seed, terrain: false, ..Default::default() };
        let (train, valid) = split_synth(crate::synth::generate(&cfg).into_iter().map(named_synth).collect());
        return Ok((train, valid, format!("synthetic locomotion, {minutes} min, seed {seed}")));
    };
    let Some(glob_text) = &t.valid_glob else {
        return Err(crate::Message::new(
            "--data needs --valid-glob GLOB to choose the validation clips (bandai2: '*_youthful_*')",
        ));
    };
    glob(glob_text).map_err(crate::Message::new)?;
    let mut clips = load_reporting(path, None, t.skip_invalid, progress)?;
    if let Some(pattern) = &t.exclude_glob {
        let m = glob(pattern).map_err(crate::Message::new)?;
        let before = clips.len();
        clips.retain(|c| !m.is_match(&c.name));
        if clips.is_empty() {
            return Err(crate::Message(format!(
                "--exclude-glob {pattern}: every one of the {before} clips matches; nothing is left"
            )));
        }
        progress.notice(&format!("--exclude-glob {pattern}: left out {} of {before} clips", before - clips.len()));
    }
    let (train, valid) = split(clips, glob_text).map_err(crate::Message::new)?;
    let without = t.exclude_glob.as_ref().map_or(String::new(), |e| format!(", without {e}"));
    Ok((train, valid, format!("{} (validation: {glob_text}{without})", path.display())))
}

#[cfg(test)]
use crate::bvh::{self, ReadOptions};
use crate::clip_io::{self, ClipError, ClipFormat};
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use zoo_motion::facing::yaw_between;
use zoo_motion::fk::forward_kinematics;
use zoo_motion::{Clip, Skeleton};

/// Errors of dataset loading.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A BVH file could not be read or parsed.
    #[error(transparent)]
    Bvh(#[from] BvhError),
    /// A glTF or FBX file could not be read, or holds no usable clip.
    #[error(transparent)]
    Clip(ClipError),
    /// The path does not exist or holds no clip files.
    #[error(
        "{0}: no clip files found (.bvh, .bvh.gz, .glb, .gltf or .fbx); pass a clip file or a folder that contains some"
    )]
    Empty(PathBuf),
    /// Walking the folder failed.
    #[error("{path}: cannot list folder: {source}")]
    Io {
        /// Folder.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A clip's skeleton differs from the first clip's.
    #[error(
        "{path}: skeleton differs from {first} ({why}); every clip of a dataset must use the same rig \
         (retarget it first, load the two rigs as separate datasets, or pass --skip-invalid to leave such clips out)"
    )]
    Skeleton {
        /// Offending file.
        path: PathBuf,
        /// File that defined the skeleton.
        first: PathBuf,
        /// What differs.
        why: String,
    },
    /// A clip's frame rate differs from the first clip's.
    #[error(
        "{path}: {fps} fps but {first} has {first_fps} fps; every clip of a dataset must have one frame rate \
         (resample it first, or pass --skip-invalid to leave such clips out)"
    )]
    FrameRate {
        /// Offending file.
        path: PathBuf,
        /// Its frame rate.
        fps: f64,
        /// File that defined the frame rate.
        first: PathBuf,
        /// The dataset's frame rate.
        first_fps: f64,
    },
    /// `skip_invalid` left no clip.
    #[error("{path}: all {skipped} clips were skipped as invalid; nothing is left to load")]
    AllSkipped {
        /// The dataset.
        path: PathBuf,
        /// How many were skipped.
        skipped: usize,
    },
    /// A glob pattern is invalid.
    #[error("invalid glob `{pattern}`: {message}")]
    Glob {
        /// The pattern.
        pattern: String,
        /// Why.
        message: String,
    },
    /// A split came out empty.
    #[error("{0}")]
    Split(String),
}

/// A clip and the file it came from.
#[derive(Clone, Debug)]
pub struct NamedClip {
    /// File path.
    pub path: PathBuf,
    /// File name without folders (what split globs match).
    pub name: String,
    /// The motion.
    pub clip: Clip,
}

impl From<ClipError> for DataError {
    fn from(e: ClipError) -> Self {
        match e {
            ClipError::Bvh(b) => DataError::Bvh(b),
            other => DataError::Clip(other),
        }
    }
}

/// Whether a path names a BVH file (`.bvh` or `.bvh.gz`, any case).
pub fn is_bvh_path(p: &Path) -> bool {
    ClipFormat::of(p) == Some(ClipFormat::Bvh)
}

/// Every clip file (BVH, glTF, FBX: [`clip_io::is_clip_path`]) under `path` (recursively),
/// sorted; `path` itself if it is a file.
pub fn find_bvh_files(path: &Path) -> Result<Vec<PathBuf>, DataError> {
    find_clip_files(path)
}

/// Every clip file (BVH, glTF, FBX: [`clip_io::is_clip_path`]) under `path` (recursively),
/// sorted; `path` itself if it is a file.
pub fn find_clip_files(path: &Path) -> Result<Vec<PathBuf>, DataError> {
    if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    if !path.is_dir() {
        return Err(DataError::Empty(path.to_path_buf()));
    }
    let mut out = Vec::new();
    let mut stack = vec![path.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let rd = std::fs::read_dir(&dir).map_err(|source| DataError::Io { path: dir.clone(), source })?;
        for entry in rd {
            let entry = entry.map_err(|source| DataError::Io { path: dir.clone(), source })?;
            let p = entry.path();
            if p.is_dir() {
                stack.push(p);
            } else if clip_io::is_clip_path(&p) {
                out.push(p);
            }
        }
    }
    out.sort();
    if out.is_empty() {
        return Err(DataError::Empty(path.to_path_buf()));
    }
    Ok(out)
}

/// Loads every clip under `path` in parallel (sorted by path), drops or folds a dummy root,
/// removes quaternion sign flips over time, and checks that all clips share one skeleton and
/// one frame rate (see [`load_with`]); any bad clip refuses the dataset.
pub fn load(path: &Path) -> Result<Vec<NamedClip>, DataError> {
    load_matching(path, None)
}

/// [`load`], keeping only files whose name matches `name_glob` (when given).
pub fn load_matching(path: &Path, name_glob: Option<&str>) -> Result<Vec<NamedClip>, DataError> {
    Ok(load_with(path, &LoadOptions { name_glob, skip_invalid: false, take: None })?.clips)
}

/// How [`load_with`] loads a dataset.
#[derive(Clone, Copy, Debug, Default)]
pub struct LoadOptions<'a> {
    /// Keep only files whose name matches this glob.
    pub name_glob: Option<&'a str>,
    /// Leave out the clips that cannot join the dataset (unreadable, another skeleton, another
    /// frame rate) and list them in [`Dataset::skipped`], instead of refusing the dataset.
    pub skip_invalid: bool,
    /// The FBX take (animation stack) or glTF animation to read by name (default: the first).
    pub take: Option<&'a str>,
}

/// A clip left out by `skip_invalid`, and why.
#[derive(Clone, Debug)]
pub struct SkippedClip {
    /// File.
    pub path: PathBuf,
    /// The error that refused it.
    pub reason: String,
}

/// A loaded dataset: its clips, the clips left out and what was changed on the way.
#[derive(Clone, Debug, Default)]
pub struct Dataset {
    /// The clips, sorted by path.
    pub clips: Vec<NamedClip>,
    /// Clips left out (only with [`LoadOptions::skip_invalid`]).
    pub skipped: Vec<SkippedClip>,
    /// Harmless differences that were repaired, one line each (e.g. a folded dummy root).
    pub notices: Vec<String>,
}

/// Two frame times are the same rate when their frame rates differ by less than this (fps).
const FPS_TOLERANCE: f64 = 1e-3;

/// Loads a dataset: every clip file under `path` in parallel (sorted by path), BVH, glTF and
/// FBX mixed (glTF and FBX converted to centimetres, Y up, right-handed: see
/// [`crate::clip_io`]; a notice says which units and axes each format came in).
///
/// - A clip whose joints are the reference's (same names and parents) in another order (an
///   FBX or glTF exporter's order) is reordered to the reference's order.
/// - A dummy root (a first joint with a single child and a zero offset, like bandai2's
///   `joint_Root`) that is zero in every frame is dropped. One that carries motion while the
///   dataset's other clips have it zero is folded into its child (the child's global motion
///   is the same, see `Clip::drop_root`), with a notice, instead of making its clip another
///   skeleton.
/// - Every clip must have the hierarchy (joint names and parents) of the first clip that has
///   no such moving dummy root, and its frame rate: another one is refused (they are not
///   resampled), or left out with `skip_invalid`, like a file that does not parse.
pub fn load_with(path: &Path, opts: &LoadOptions) -> Result<Dataset, DataError> {
    let mut files = find_clip_files(path)?;
    if let Some(pattern) = opts.name_glob {
        let m = glob(pattern)?;
        files.retain(|p| p.file_name().is_some_and(|n| m.is_match(n)));
        if files.is_empty() {
            return Err(DataError::Split(format!("no file name under {} matches `{pattern}`", path.display())));
        }
    }
    let read = clip_io::ReadOptions { drop_dummy_root: true, take: opts.take.map(str::to_string) };
    let read: Vec<Result<(NamedClip, clip_io::ClipSource), DataError>> = files
        .par_iter()
        .map(|p| {
            let (clip, source) = clip_io::read_with_source(p, &read)?;
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string();
            Ok((NamedClip { path: p.clone(), name, clip }, source))
        })
        .collect();
    let mut out = Dataset::default();
    let mut clips = Vec::with_capacity(read.len());
    let mut sources: std::collections::BTreeMap<String, usize> = Default::default();
    for (r, p) in read.into_iter().zip(&files) {
        match r {
            Ok((c, source)) => {
                if source.format != ClipFormat::Bvh {
                    let how = if source.frame == zoo_motion::frame::CoordinateFrame::ZOO_CM {
                        "already in zoo's centimetres, Y up, right-handed"
                    } else {
                        "converted to centimetres, Y up, right-handed"
                    };
                    *sources.entry(format!("{}; {how}", source.describe())).or_default() += 1;
                }
                clips.push(c)
            }
            Err(e) if opts.skip_invalid => out.skipped.push(SkippedClip { path: p.clone(), reason: e.to_string() }),
            Err(e) => return Err(e),
        }
    }
    for (what, n) in sources {
        out.notices.push(format!("{n} clip(s) read from {what}"));
    }
    let Some((reference, shared, pool)) = reference_clip(&clips) else {
        return Err(DataError::AllSkipped { path: path.to_path_buf(), skipped: out.skipped.len() });
    };
    if shared < pool {
        out.notices.push(format!(
            "the clips disagree on the skeleton or the frame rate: the reference is what most share, {shared} of \
             {pool} clips ({}: {} joints, {:.2} fps); the others are checked against it",
            clips[reference].path.display(),
            clips[reference].clip.joints(),
            clips[reference].clip.fps()
        ));
    }
    let (first, first_skeleton, first_fps) =
        (clips[reference].path.clone(), clips[reference].clip.skeleton.clone(), clips[reference].clip.fps());
    for mut c in clips {
        let why = match clip_io::conform_to(&mut c.clip, &first_skeleton) {
            Some(clip_io::Conformed::Folded(how)) => {
                out.notices.push(format!("{}: {how}", c.path.display()));
                None
            }
            Some(_) => None,
            None => first_skeleton.topology_difference(&c.clip.skeleton),
        };
        let err = match why {
            Some(why) => Some(DataError::Skeleton { path: c.path.clone(), first: first.clone(), why }),
            None if (c.clip.fps() - first_fps).abs() > FPS_TOLERANCE => {
                Some(DataError::FrameRate { path: c.path.clone(), fps: c.clip.fps(), first: first.clone(), first_fps })
            }
            None => None,
        };
        match err {
            None => {
                c.clip.remove_sign_flips();
                out.clips.push(c);
            }
            Some(e) if opts.skip_invalid => out.skipped.push(SkippedClip { path: c.path, reason: e.to_string() }),
            Some(e) => return Err(e),
        }
    }
    out.clips.sort_by(|a, b| a.path.cmp(&b.path));
    out.skipped.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(out)
}

/// The clip whose skeleton and frame rate the others must have: among the clips without a
/// moving dummy root (its dummy was dropped, or it never had one; all clips when every one has
/// it), the first of those whose hierarchy and frame rate most clips share (a stray clip that
/// sorts first does not make the others invalid). Returns it, how many clips share it and how
/// many voted.
fn reference_clip(clips: &[NamedClip]) -> Option<(usize, usize, usize)> {
    let plain: Vec<usize> = (0..clips.len()).filter(|&i| !clip_io::has_dummy_shaped_root(&clips[i].clip)).collect();
    let pool = if plain.is_empty() { (0..clips.len()).collect() } else { plain };
    let key = |i: usize| {
        let c = &clips[i].clip;
        (&c.skeleton.names, &c.skeleton.parents, (c.fps() / FPS_TOLERANCE).round() as i64)
    };
    let mut votes = std::collections::HashMap::new();
    for &i in &pool {
        *votes.entry(key(i)).or_insert(0usize) += 1;
    }
    // max_by_key keeps the last of equal maxima: scan in reverse to keep the first.
    let best = pool.iter().rev().copied().max_by_key(|&i| votes[&key(i)])?;
    Some((best, votes[&key(best)], pool.len()))
}

/// Errors unless every clip has the first clip's joint names and parents.
pub fn check_same_skeleton(clips: &[NamedClip]) -> Result<(), DataError> {
    if let Some(first) = clips.first() {
        for c in &clips[1..] {
            if let Some(why) = first.clip.skeleton.topology_difference(&c.clip.skeleton) {
                return Err(DataError::Skeleton { path: c.path.clone(), first: first.path.clone(), why });
            }
        }
    }
    Ok(())
}

/// Loads a dataset for a command (`name_glob` choosing clips by file name): with
/// `skip_invalid`, the clips that cannot join it are left out and listed with the reason;
/// repaired differences (a folded dummy root) are noted. Both go to `progress` as notices,
/// before the long work.
pub fn load_reporting(
    path: &Path,
    name_glob: Option<&str>,
    skip_invalid: bool,
    progress: &dyn crate::Progress,
) -> Result<Vec<NamedClip>, crate::Message> {
    let opts = LoadOptions { name_glob, skip_invalid, take: None };
    let d = load_with(path, &opts).map_err(|e| crate::Message(format!("loading {}: {e}", path.display())))?;
    for n in &d.notices {
        progress.notice(&format!("note: {n}"));
    }
    if !d.skipped.is_empty() {
        progress.notice(&format!(
            "--skip-invalid: skipped {} of {} clips:",
            d.skipped.len(),
            d.skipped.len() + d.clips.len()
        ));
        for s in &d.skipped {
            progress.notice(&format!("  {}", s.reason));
        }
    }
    Ok(d.clips)
}

/// Compiles a file-name glob (`*` matches any run of characters, including `/`).
pub fn glob(pattern: &str) -> Result<globset::GlobMatcher, DataError> {
    globset::Glob::new(pattern)
        .map(|g| g.compile_matcher())
        .map_err(|e| DataError::Glob { pattern: pattern.to_string(), message: e.to_string() })
}

/// Splits clips into (training, validation): validation clips are those whose file name
/// matches `valid_glob`.
pub fn split(clips: Vec<NamedClip>, valid_glob: &str) -> Result<(Vec<NamedClip>, Vec<NamedClip>), DataError> {
    let m = glob(valid_glob)?;
    let (valid, train): (Vec<_>, Vec<_>) = clips.into_iter().partition(|c| m.is_match(&c.name));
    if valid.is_empty() {
        return Err(DataError::Split(format!(
            "no clip file name matches --valid-glob `{valid_glob}`: the validation split is empty"
        )));
    }
    if train.is_empty() {
        return Err(DataError::Split(format!(
            "every clip file name matches --valid-glob `{valid_glob}`: the training split is empty"
        )));
    }
    Ok((train, valid))
}

/// Fixed-length windows of local motion, frame-major within each window:
/// `local_rot[(w * window + f) * joints + j]`.
#[derive(Clone, Debug)]
pub struct Windows {
    /// Skeleton the windows are on.
    pub skeleton: Skeleton,
    /// Frames per window.
    pub window: usize,
    /// Number of windows.
    pub count: usize,
    /// Local rotations.
    pub local_rot: Vec<DQuat>,
    /// Local positions.
    pub local_pos: Vec<DVec3>,
    /// Index of the source clip of each window and its first frame.
    pub source: Vec<(usize, usize)>,
}

/// How windows are cut and prepared (benchmark steps 3-5).
#[derive(Clone, Copy, Debug)]
pub struct WindowOptions {
    /// Frames per window.
    pub window: usize,
    /// Step between window starts.
    pub offset: usize,
    /// Past context frames: facing is unified at frame `n_past - 1`.
    pub n_past: usize,
    /// Local axis of the root whose ground projection is "forward" (bandai2 and LaFAN1: +Y).
    pub forward_axis: DVec3,
}

impl WindowOptions {
    /// Training windows of the benchmark: 50 frames, offset 20, 10 past frames.
    pub const TRAIN: WindowOptions = WindowOptions { window: 50, offset: 20, n_past: 10, forward_axis: DVec3::Y };
    /// Test windows of the benchmark: 65 frames, offset 40, 10 past frames.
    pub const TEST: WindowOptions = WindowOptions { window: 65, offset: 40, n_past: 10, forward_axis: DVec3::Y };
}

impl Windows {
    /// Joints per frame.
    pub fn joints(&self) -> usize {
        self.skeleton.len()
    }

    /// Local rotations of window `w` (frames x joints).
    pub fn rot(&self, w: usize) -> &[DQuat] {
        let n = self.window * self.joints();
        &self.local_rot[w * n..(w + 1) * n]
    }

    /// Local positions of window `w` (frames x joints).
    pub fn pos(&self, w: usize) -> &[DVec3] {
        let n = self.window * self.joints();
        &self.local_pos[w * n..(w + 1) * n]
    }

    /// Global joint positions of all windows as `f32`, `(windows, frames, joints, 3)` flattened:
    /// the input layout of the position-based models.
    pub fn global_positions_f32(&self) -> Vec<f32> {
        let (_, gp) = self.global();
        gp.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()
    }

    /// Global rotations and positions of all windows.
    pub fn global(&self) -> (Vec<DQuat>, Vec<DVec3>) {
        let mut gr = vec![DQuat::IDENTITY; self.local_rot.len()];
        let mut gp = vec![DVec3::ZERO; self.local_pos.len()];
        forward_kinematics(&self.skeleton.parents, &self.local_rot, &self.local_pos, &mut gr, &mut gp);
        (gr, gp)
    }
}

/// Cuts windows from clips (start 0, step `offset`, while `start + window < frames`), centres
/// each on the mean root x/z of its frames and unifies facing at frame `n_past - 1`.
pub fn windows(clips: &[NamedClip], opts: &WindowOptions) -> Windows {
    let skeleton = clips.first().map(|c| c.clip.skeleton.clone()).unwrap_or_else(|| Skeleton {
        names: vec![],
        parents: vec![],
        offsets: vec![],
        end_sites: vec![],
        channels: vec![],
    });
    let j = skeleton.len();
    let mut source = Vec::new();
    for (ci, c) in clips.iter().enumerate() {
        let frames = c.clip.frames();
        let mut i = 0;
        while i + opts.window < frames {
            source.push((ci, i));
            i += opts.offset;
        }
    }
    let per = opts.window * j;
    let mut local_rot = vec![DQuat::IDENTITY; source.len() * per];
    let mut local_pos = vec![DVec3::ZERO; source.len() * per];
    local_rot.par_chunks_mut(per.max(1)).zip(local_pos.par_chunks_mut(per.max(1))).zip(source.par_iter()).for_each(
        |((rot, pos), &(ci, start))| {
            let clip = &clips[ci].clip;
            rot.copy_from_slice(&clip.local_rotations[start * j..start * j + per]);
            pos.copy_from_slice(&clip.local_positions[start * j..start * j + per]);
            prepare_window(rot, pos, j, opts);
        },
    );
    Windows { skeleton, window: opts.window, count: source.len(), local_rot, local_pos, source }
}

/// Benchmark steps 4-5 on one window in place: centre root x/z, then rotate the whole window
/// about +Y so the root faces +X at frame `n_past - 1`.
///
/// Only the root's transform changes: rotating every global transform by the same yaw leaves
/// the parent-relative (local) transforms of the other joints as they are.
pub fn prepare_window(rot: &mut [DQuat], pos: &mut [DVec3], joints: usize, opts: &WindowOptions) {
    let frames = rot.len() / joints;
    let t = window_transform(rot, pos, joints, frames, opts);
    apply_window_transform(rot, pos, joints, t);
}

/// The centring (mean root x/z of the first `frames` frames) and facing (the inverse yaw of the
/// root at frame `n_past - 1`) that [`prepare_window`] applies.
fn window_transform(
    rot: &[DQuat],
    pos: &[DVec3],
    joints: usize,
    frames: usize,
    opts: &WindowOptions,
) -> (f64, f64, DQuat) {
    let (mut mx, mut mz) = (0.0, 0.0);
    for f in 0..frames {
        mx += pos[f * joints].x;
        mz += pos[f * joints].z;
    }
    mx /= frames as f64;
    mz /= frames as f64;
    let key = rot[(opts.n_past - 1) * joints];
    let fwd = key * opts.forward_axis;
    let fwd = DVec3::new(fwd.x, 0.0, fwd.z).normalize();
    (mx, mz, yaw_between(DVec3::X, fwd).inverse())
}

fn apply_window_transform(rot: &mut [DQuat], pos: &mut [DVec3], joints: usize, (mx, mz, inv): (f64, f64, DQuat)) {
    for f in 0..rot.len() / joints {
        pos[f * joints].x -= mx;
        pos[f * joints].z -= mz;
        rot[f * joints] = inv * rot[f * joints];
        pos[f * joints] = inv * pos[f * joints];
    }
}

/// The windows of `w` (cut from `clips` with `opts`) continued to `frames` frames where their
/// clips go on: global positions (`w.count * frames * 3K`, frame-major), each window in the
/// frame [`windows`] put it in (its first `w.window` frames are `w`'s), frames past its clip's
/// end repeating the clip's last frame, and how many frames of each are the clip's (at least
/// `w.window`). For augmentations that read past a window's end (e.g. playing it faster).
pub fn windows_continued(
    clips: &[NamedClip],
    w: &Windows,
    opts: &WindowOptions,
    frames: usize,
) -> (Vec<f32>, Vec<usize>) {
    let frames = frames.max(w.window);
    let j = w.joints();
    let per = frames * j;
    let real: Vec<usize> = w.source.iter().map(|&(ci, start)| frames.min(clips[ci].clip.frames() - start)).collect();
    let mut out = vec![0f32; w.count * per * 3];
    out.par_chunks_mut((per * 3).max(1)).zip(w.source.par_iter().zip(real.par_iter())).for_each(
        |(o, (&(ci, start), &n))| {
            let clip = &clips[ci].clip;
            let mut rot = Vec::with_capacity(per);
            let mut pos = Vec::with_capacity(per);
            for f in 0..frames {
                let at = (start + f.min(n - 1)) * j;
                rot.extend_from_slice(&clip.local_rotations[at..at + j]);
                pos.extend_from_slice(&clip.local_positions[at..at + j]);
            }
            let t = window_transform(&rot, &pos, j, w.window, opts);
            apply_window_transform(&mut rot, &mut pos, j, t);
            let (mut gr, mut gp) = (vec![DQuat::IDENTITY; per], vec![DVec3::ZERO; per]);
            forward_kinematics(&w.skeleton.parents, &rot, &pos, &mut gr, &mut gp);
            for (dst, p) in o.chunks_exact_mut(3).zip(&gp) {
                dst.copy_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
            }
        },
    );
    (out, real)
}

/// Normalization statistics of global joint positions (benchmark step 6).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PositionStats {
    /// Mean per coordinate (joint-major: `j * 3 + axis`).
    pub mean: Vec<f64>,
    /// Population standard deviation per coordinate.
    pub std: Vec<f64>,
}

/// Per-coordinate mean and population std of global positions over all windows and frames.
pub fn position_stats(global_pos: &[DVec3], joints: usize) -> PositionStats {
    let n = (global_pos.len() / joints) as f64;
    let mut mean = vec![0.0; joints * 3];
    for (i, p) in global_pos.iter().enumerate() {
        let j = i % joints;
        mean[j * 3] += p.x;
        mean[j * 3 + 1] += p.y;
        mean[j * 3 + 2] += p.z;
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut var = vec![0.0; joints * 3];
    for (i, p) in global_pos.iter().enumerate() {
        let j = i % joints;
        for a in 0..3 {
            let d = p[a] - mean[j * 3 + a];
            var[j * 3 + a] += d * d;
        }
    }
    let std = var.into_iter().map(|v| (v / n).sqrt()).collect();
    PositionStats { mean, std }
}

pub use zoo_protocol::stitch::percentile;

#[cfg(test)]
mod tests {
    use super::*;

    /// joint_Root (a dummy: one child, zero offset) -> Hips -> (Spine, Leg); `root` is the
    /// dummy's six channel values in both frames.
    fn dummy_rooted(root: &str) -> String {
        format!(
            "HIERARCHY\nROOT joint_Root\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
             JOINT Hips\n{{\nOFFSET 0 90 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
             JOINT Spine\n{{\nOFFSET 0 10 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{{\nOFFSET 0 5 0\n}}\n}}\n\
             JOINT Leg\n{{\nOFFSET 5 -40 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{{\nOFFSET 0 -40 0\n}}\n}}\n}}\n}}\n\
             MOTION\nFrames: 2\nFrame Time: 0.0333333\n\
             {root} 1 90 2 10 20 30 5 0 0 0 0 10\n{root} 2 91 2 12 22 28 6 1 0 0 1 11\n"
        )
    }

    #[test]
    fn a_moving_dummy_root_is_folded_with_the_same_global_motion() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a_still.bvh"), dummy_rooted("0 0 0 0 0 0")).unwrap();
        let moving = dummy_rooted("30 -2 7 15 -5 40");
        std::fs::write(dir.path().join("b_moving.bvh"), &moving).unwrap();
        let d = load_with(dir.path(), &LoadOptions::default()).unwrap();
        assert_eq!(d.clips.len(), 2);
        assert!(
            d.notices.len() == 1 && d.notices[0].contains("b_moving.bvh: its dummy root `joint_Root`"),
            "{:?}",
            d.notices
        );
        let folded = &d.clips[1].clip;
        assert_eq!(folded.skeleton.names, ["Hips", "Spine", "Leg"]);
        assert_eq!(folded.skeleton.parents, d.clips[0].clip.skeleton.parents);
        // The same global motion: every remaining joint where it was under the moving dummy.
        let raw = bvh::parse(&moving, Path::new("b_moving.bvh"), &ReadOptions { drop_dummy_root: false }).unwrap();
        let (_, before) = raw.global();
        let (_, after) = folded.global();
        for f in 0..2 {
            for j in 0..3 {
                let (a, b) = (before[f * 4 + j + 1], after[f * 3 + j]);
                assert!((a - b).length() < 1e-9, "frame {f} joint {j}: {a} vs {b}");
            }
        }
        // Alone, a moving dummy is part of the skeleton: nothing to fold it for.
        let alone = tempfile::tempdir().unwrap();
        std::fs::write(alone.path().join("b_moving.bvh"), &moving).unwrap();
        let d = load_with(alone.path(), &LoadOptions::default()).unwrap();
        assert_eq!((d.clips[0].clip.joints(), d.notices.len()), (4, 0));
    }

    #[test]
    fn the_reference_is_what_most_clips_share_and_a_stray_clip_is_the_one_left_out() {
        let dir = tempfile::tempdir().unwrap();
        let still = dummy_rooted("0 0 0 0 0 0");
        // Sorts first, at another frame rate: the two others must not be the invalid ones.
        std::fs::write(dir.path().join("a_stray.bvh"), still.replace("0.0333333", "0.0166667")).unwrap();
        std::fs::write(dir.path().join("b.bvh"), &still).unwrap();
        std::fs::write(dir.path().join("c.bvh"), &still).unwrap();
        let d = load_with(dir.path(), &LoadOptions { skip_invalid: true, ..LoadOptions::default() }).unwrap();
        let names: Vec<&str> = d.clips.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(names, ["b.bvh", "c.bvh"]);
        assert!(d.skipped.len() == 1 && d.skipped[0].path.ends_with("a_stray.bvh"), "{:?}", d.skipped);
        assert!(d.notices.iter().any(|n| n.contains("what most share, 2 of 3 clips")), "{:?}", d.notices);
    }

    #[test]
    fn continued_windows_start_as_the_windows_and_go_on_where_their_clips_do() {
        let cfg = crate::synth::SynthConfig { minutes: 0.5, seed: 3, clip_seconds: 5.0, ..Default::default() };
        let clips: Vec<NamedClip> = crate::synth::generate(&cfg).into_iter().map(named_synth).collect();
        let opts = WindowOptions::TRAIN;
        let w = windows(&clips, &opts);
        let (frames, d) = (w.window + 40, 3 * w.joints());
        let (long, real) = windows_continued(&clips, &w, &opts, frames);
        assert_eq!((long.len(), real.len()), (w.count * frames * d, w.count));
        let short = w.global_positions_f32();
        for i in 0..w.count {
            let (a, b) = (&long[i * frames * d..][..w.window * d], &short[i * w.window * d..][..w.window * d]);
            let err = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
            assert!(err < 1e-3, "window {i}: its first frames differ by {err}");
            let (ci, start) = w.source[i];
            assert_eq!(real[i], frames.min(clips[ci].clip.frames() - start));
            // Past the clip's end the last frame repeats.
            let win = &long[i * frames * d..][..frames * d];
            for f in real[i]..frames {
                assert_eq!(&win[f * d..][..d], &win[(real[i] - 1) * d..][..d]);
            }
        }
        assert!(real.iter().any(|&n| n == frames) && real.iter().any(|&n| n < frames), "{real:?}");
    }

    #[test]
    fn percentile_matches_numpy() {
        // numpy.percentile([1, 2, 3, 4], 5) == 1.15
        let mut v = vec![4.0, 1.0, 3.0, 2.0];
        assert!((percentile(&mut v, 5.0) - 1.15).abs() < 1e-12);
        assert!((percentile(&mut v, 50.0) - 2.5).abs() < 1e-12);
    }

    #[test]
    fn stats_are_population_std() {
        let p = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(3.0, 0.0, 0.0)];
        let s = position_stats(&p, 1);
        assert_eq!(s.mean[0], 2.0);
        assert_eq!(s.std[0], 1.0);
        assert_eq!(s.std[1], 0.0);
    }

    #[test]
    fn facing_unified_at_last_past_frame() {
        let opts = WindowOptions { window: 3, offset: 1, n_past: 2, forward_axis: DVec3::Y };
        // root facing: local +Y rotated to world -Z, with some tilt
        let r = DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2) * DQuat::from_rotation_z(0.1);
        let mut rot = vec![r; 3];
        let mut pos = vec![DVec3::new(5.0, 1.0, 2.0), DVec3::new(6.0, 1.0, 3.0), DVec3::new(7.0, 1.0, 4.0)];
        prepare_window(&mut rot, &mut pos, 1, &opts);
        let f = rot[1] * DVec3::Y;
        let f = DVec3::new(f.x, 0.0, f.z).normalize();
        assert!((f - DVec3::X).length() < 1e-12, "{f:?}");
        // centred: mean x/z now zero (rotation about Y keeps the centroid at the origin)
        let mean = (pos[0] + pos[1] + pos[2]) / 3.0;
        assert!(mean.x.abs() < 1e-12 && mean.z.abs() < 1e-12);
        assert!((pos[0].y - 1.0).abs() < 1e-12);
    }
}
