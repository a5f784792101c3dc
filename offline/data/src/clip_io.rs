//! One reader and one writer for clips in every format zoo knows, chosen by the file name.
//!
//! | extension            | read | write | units and axes                                         |
//! |----------------------|------|-------|--------------------------------------------------------|
//! | `.bvh`, `.bvh.gz`    | yes  | yes   | taken as zoo's: centimetres, Y up, right-handed        |
//! | `.glb`, `.gltf`      | yes  | yes   | glTF's: metres, Y up, right-handed (converted)         |
//! | `.fbx` (binary 7.x)  | yes  | no    | the file's global settings (converted)                 |
//!
//! Every clip read is in zoo's frame ([`CoordinateFrame::ZOO_CM`]); [`ClipSource`] records the
//! file's own units and axes. glTF and FBX rotations are expressed relative to the rig's rest
//! pose (see `scene.rs`), so that, as in BVH, the rest pose is the identity on every joint.

use crate::bvh::{self, BvhError};
use std::path::{Path, PathBuf};
use zoo_motion::Clip;
use zoo_motion::frame::{CoordinateFrame, Handedness, UpAxis};

/// A clip file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipFormat {
    /// BVH text (`.bvh`, or gzip-compressed `.bvh.gz`).
    Bvh,
    /// glTF 2.0 (`.glb` binary or `.gltf` JSON).
    Gltf,
    /// FBX (binary 7.x; `.fbx`), read only.
    Fbx,
}

impl ClipFormat {
    /// The format's name.
    pub fn name(self) -> &'static str {
        match self {
            ClipFormat::Bvh => "BVH",
            ClipFormat::Gltf => "glTF",
            ClipFormat::Fbx => "FBX",
        }
    }

    /// The format a file name says (`.bvh`, `.bvh.gz`, `.glb`, `.gltf`, `.fbx`, any case).
    pub fn of(path: &Path) -> Option<ClipFormat> {
        let n = path.file_name().and_then(|n| n.to_str()).unwrap_or("").to_ascii_lowercase();
        if n.ends_with(".bvh") || n.ends_with(".bvh.gz") {
            Some(ClipFormat::Bvh)
        } else if n.ends_with(".glb") || n.ends_with(".gltf") {
            Some(ClipFormat::Gltf)
        } else if n.ends_with(".fbx") {
            Some(ClipFormat::Fbx)
        } else {
            None
        }
    }
}

/// The extensions [`read()`] accepts, for messages.
pub const READ_EXTENSIONS: &str = ".bvh, .bvh.gz, .glb, .gltf or .fbx";
/// The extensions [`write()`] accepts, for messages.
pub const WRITE_EXTENSIONS: &str = ".bvh, .bvh.gz, .glb or .gltf";

/// Whether a path names a clip file zoo reads.
pub fn is_clip_path(p: &Path) -> bool {
    ClipFormat::of(p).is_some()
}

/// How to read a clip.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Drop a dummy root (one child, zero offset, no motion), as for BVH
    /// ([`bvh::ReadOptions::drop_dummy_root`]).
    pub drop_dummy_root: bool,
    /// The animation to read by name: an FBX animation stack (take) or a glTF animation
    /// (default: the first). BVH files hold one and ignore it.
    pub take: Option<String>,
}

/// Where a clip came from: its format and its file's units and axes before conversion.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipSource {
    /// The format.
    pub format: ClipFormat,
    /// The file's units and axes (BVH says none: zoo's, centimetres, Y up, right-handed).
    pub frame: CoordinateFrame,
    /// The animation read (glTF animation or FBX take name; empty for BVH or an unnamed one).
    pub take: String,
    /// What was left out or repaired on the way, one line each (end-site bones, other takes).
    pub notes: Vec<String>,
}

impl ClipSource {
    /// The source of a BVH file (zoo's frame).
    pub fn bvh() -> Self {
        ClipSource { format: ClipFormat::Bvh, frame: CoordinateFrame::ZOO_CM, take: String::new(), notes: vec![] }
    }

    /// "glTF, metres, Y up, right-handed": for notes and messages.
    pub fn describe(&self) -> String {
        format!("{}, {}", self.format.name(), describe_frame(&self.frame))
    }
}

/// "metres, Y up, right-handed".
pub fn describe_frame(f: &CoordinateFrame) -> String {
    let unit = match f.unit_name() {
        Some("cm") => "centimetres".to_string(),
        Some("m") => "metres".to_string(),
        Some("mm") => "millimetres".to_string(),
        Some("in") => "inches".to_string(),
        _ => format!("units of {} m", f.metres_per_unit),
    };
    let up = match f.up_axis {
        UpAxis::Y => "Y up",
        UpAxis::Z => "Z up",
    };
    let hand = match f.handedness {
        Handedness::Right => "right-handed",
        Handedness::Left => "left-handed",
    };
    format!("{unit}, {up}, {hand}")
}

/// Why a clip could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ClipError {
    /// A BVH file could not be read or parsed.
    #[error(transparent)]
    Bvh(#[from] BvhError),
    /// A glTF or FBX file could not be read, or holds no clip zoo can use.
    #[error("{path}: {format}: {message}")]
    Format {
        /// File.
        path: PathBuf,
        /// `glTF` or `FBX`.
        format: &'static str,
        /// What is wrong and what to do.
        message: String,
    },
    /// The clip holds values a model cannot take (see [`check_model_values`]).
    #[error("{path}: {message}")]
    Values {
        /// File.
        path: PathBuf,
        /// The value, where it is, and the valid range.
        message: String,
    },
    /// The file name has no extension zoo knows.
    #[error("{path}: unknown clip format: expected a file name ending in {expected}")]
    Extension {
        /// File.
        path: PathBuf,
        /// The accepted extensions.
        expected: &'static str,
    },
    /// The file could not be read or written.
    #[error("{path}: {action}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// `cannot read` or `cannot write`.
        action: &'static str,
        /// Cause.
        source: std::io::Error,
    },
}

/// Reads a clip in the format its name says, converted to zoo's frame (centimetres, Y up,
/// right-handed), with where it came from.
pub fn read_with_source(path: &Path, opts: &ReadOptions) -> Result<(Clip, ClipSource), ClipError> {
    match ClipFormat::of(path) {
        Some(ClipFormat::Bvh) => {
            let clip = bvh::read_file(path, &bvh::ReadOptions { drop_dummy_root: opts.drop_dummy_root })?;
            Ok((clip, ClipSource::bvh()))
        }
        Some(ClipFormat::Gltf) => checked(path, "glTF", crate::gltf::read_file(path, opts)?),
        Some(ClipFormat::Fbx) => checked(path, "FBX", crate::fbx::read_file(path, opts)?),
        None => Err(ClipError::Extension { path: path.to_path_buf(), expected: READ_EXTENSIONS }),
    }
}

/// The range checks the BVH reader makes at parse time, for the other formats: the frame time
/// ([`Clip::check_frame_time`]) and the hierarchy's depth ([`zoo_motion::Skeleton::MAX_DEPTH`]).
fn checked(path: &Path, format: &'static str, read: (Clip, ClipSource)) -> Result<(Clip, ClipSource), ClipError> {
    let fail = |message: String| ClipError::Format { path: path.to_path_buf(), format, message };
    Clip::check_frame_time(read.0.frame_time).map_err(fail)?;
    check_depth(path, format, &read.0)?;
    Ok(read)
}

/// Refuses a hierarchy deeper than [`zoo_motion::Skeleton::MAX_DEPTH`].
fn check_depth(path: &Path, format: &'static str, clip: &Clip) -> Result<(), ClipError> {
    if clip.joints() > zoo_motion::Skeleton::MAX_JOINTS {
        return Err(ClipError::Format {
            path: path.to_path_buf(),
            format,
            message: format!("{} joints; zoo reads at most {}", clip.joints(), zoo_motion::Skeleton::MAX_JOINTS),
        });
    }
    let depth = clip.skeleton.depth();
    if depth > zoo_motion::Skeleton::MAX_DEPTH {
        return Err(ClipError::Format {
            path: path.to_path_buf(),
            format,
            message: format!(
                "the joint hierarchy is {depth} levels deep; zoo reads at most {} levels",
                zoo_motion::Skeleton::MAX_DEPTH
            ),
        });
    }
    Ok(())
}

/// The key poses of a clip file that stores only its keys, and their times in seconds from the
/// first key, the way the models see clips (dummy root dropped, sign flips removed): glTF keys
/// each joint at its own times, and a pose is read at every time any joint is keyed
/// ([`crate::gltf::read_key_poses`]). BVH and FBX files are refused: a BVH file has a pose in
/// every frame, and zoo reads an FBX take frame by frame.
pub fn read_key_poses(path: &Path, opts: &ReadOptions) -> Result<(Clip, Vec<f64>), ClipError> {
    match ClipFormat::of(path) {
        Some(ClipFormat::Gltf) => {
            let opts = ReadOptions { drop_dummy_root: true, ..opts.clone() };
            let (mut clip, times) = crate::gltf::read_key_poses(path, &opts)?;
            check_depth(path, "glTF", &clip)?;
            clip.remove_sign_flips();
            Ok((clip, times))
        }
        Some(f) => Err(ClipError::Format {
            path: path.to_path_buf(),
            format: f.name(),
            message: "only a glTF file (.glb, .gltf) stores its keys' times: give the key frames of this one \
                      (--key-frames 0,15,40 or --every K)"
                .into(),
        }),
        None => Err(ClipError::Extension { path: path.to_path_buf(), expected: READ_EXTENSIONS }),
    }
}

/// [`read_with_source`] without the source.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<Clip, ClipError> {
    Ok(read_with_source(path, opts)?.0)
}

/// Reads a clip the way the models see it (any format): the dummy root dropped and
/// quaternion sign flips removed (as [`bvh::read_model_clip`]).
pub fn read_model_clip(path: &Path) -> Result<Clip, ClipError> {
    read_model_clip_with(path, &ReadOptions { drop_dummy_root: true, take: None })
}

/// [`read_model_clip`] with options (a take name); the dummy root is always dropped.
pub fn read_model_clip_with(path: &Path, opts: &ReadOptions) -> Result<Clip, ClipError> {
    let opts = ReadOptions { drop_dummy_root: true, ..opts.clone() };
    let mut clip = read(path, &opts)?;
    check_model_values(&clip).map_err(|message| ClipError::Values { path: path.to_path_buf(), message })?;
    clip.remove_sign_flips();
    Ok(clip)
}

/// The largest offset or position (clip units: 1e7 cm is 100 km) a clip given to a model may
/// hold. A model computes in 32-bit floats (at most about 3.4e38), and its steps (differences,
/// squares, velocities) overflow long before: a value of 1e39 made `zoo stitch` panic.
pub const MAX_MODEL_VALUE: f64 = 1e7;

/// Checks a clip read for a model where it enters: at least one frame, every offset and
/// position within [`MAX_MODEL_VALUE`], every rotation finite and non-zero.
pub fn check_model_values(clip: &Clip) -> Result<(), String> {
    if clip.frames() == 0 {
        return Err("the clip has no frame; a model needs at least one".into());
    }
    let j = clip.joints().max(1);
    let far = |v: &zoo_motion::glam::DVec3| !(v.abs().max_element() <= MAX_MODEL_VALUE);
    if let Some(i) = clip.skeleton.offsets.iter().position(far) {
        return Err(format!(
            "joint `{}` has the offset {:?}, outside the valid range [-{MAX_MODEL_VALUE:e}, {MAX_MODEL_VALUE:e}] \
             (clip units) of a clip given to a model",
            clip.skeleton.names[i], clip.skeleton.offsets[i]
        ));
    }
    if let Some(i) = clip.local_positions.iter().position(far) {
        return Err(format!(
            "frame {} joint `{}` has the position {:?}, outside the valid range [-{MAX_MODEL_VALUE:e}, \
             {MAX_MODEL_VALUE:e}] (clip units) of a clip given to a model",
            i / j,
            clip.skeleton.names[i % j],
            clip.local_positions[i]
        ));
    }
    if let Some(i) = clip.local_rotations.iter().position(|q| !(q.is_finite() && q.length() > 1e-9)) {
        return Err(format!(
            "frame {} joint `{}` has no valid rotation ({:?})",
            i / j,
            clip.skeleton.names[i % j],
            clip.local_rotations[i]
        ));
    }
    Ok(())
}

/// The memory a command may give one clip it makes (2 GB by default): sizes are computed and
/// checked against it before anything is allocated.
pub const DEFAULT_MEMORY_BOUND: u64 = 2_000_000_000;

/// Bytes a clip of `frames` frames and `joints` joints holds in memory (a rotation and a position
/// per joint and frame: 56 bytes), saturating.
pub fn clip_bytes(frames: usize, joints: usize) -> u64 {
    (frames as u64).saturating_mul(joints as u64).saturating_mul(56)
}

/// Refuses a clip of `frames` x `joints` past `bound` bytes, naming the size, the bound and
/// `option`, the option that raises it.
pub fn check_clip_size(frames: usize, joints: usize, bound: u64, option: &str) -> Result<(), String> {
    let bytes = clip_bytes(frames, joints);
    if bytes > bound {
        return Err(format!(
            "{frames} frames of {joints} joints need {:.2} GB, past the memory bound of {:.2} GB; raise it with \
             {option} (in GB) if the machine holds it",
            bytes as f64 / 1e9,
            bound as f64 / 1e9
        ));
    }
    Ok(())
}

/// Brings a clip read from `path` to the frame rate `fps` of the model it is given to: a clip at
/// the same rate (within 0.01 %, [`zoo_motion::clip::same_frame_rate`]) is kept; another rate is
/// resampled (rotations by slerp, positions linearly, [`Clip::resampled`]) after its size is
/// checked against [`DEFAULT_MEMORY_BOUND`]. Returns the note to print, and the factor that maps
/// a frame number of the file to the resampled clip's.
pub fn to_frame_rate(clip: &mut Clip, fps: f64, path: &Path) -> Result<Option<(String, f64)>, String> {
    if clip.plays_at(fps) {
        return Ok(None);
    }
    let from = clip.fps();
    let frames = clip.resampled_frames(fps);
    check_clip_size(frames, clip.joints(), DEFAULT_MEMORY_BOUND, "`zoo data resample --max-memory`")
        .map_err(|e| format!("{}: resampling {from:.3} fps to the model's {fps:.3} fps: {e}", path.display()))?;
    let old = clip.frames();
    *clip = clip.resampled(fps);
    let note = format!(
        "note: {} is at {from:.3} fps, the model at {fps:.3} fps: resampled to {fps:.3} fps ({old} frames become {}; \
         `zoo data resample {} OUT --fps {fps}` writes it once)",
        path.display(),
        frames,
        path.display()
    );
    Ok(Some((note, fps / from)))
}

/// How [`conform`] brought a clip to the skeleton a command needs.
#[derive(Clone, Debug, PartialEq)]
pub enum Conformed {
    /// The clip was on it already.
    AsIs,
    /// The same joints (names and parents) in another order, put in the skeleton's order.
    Reordered,
    /// A dummy root that carries motion was folded into its child; the sentence says so.
    Folded(String),
}

/// The one rule by which every command brings a clip it has read to the skeleton it needs (a
/// model's, or a dataset's reference clip's): `fits` says whether a skeleton is that one, and
/// `reference` gives its joint names when they are known. A clip that fits is taken as it is; one
/// with the same joints in another order (an FBX or glTF exporter's order) is reordered; one whose
/// dummy-shaped root (one child, zero offset, like bandai2's `joint_Root`) carries motion is
/// folded into its child (the same global motion, see `Clip::drop_root`) when that makes it fit.
/// Returns `None`, leaving the clip as it was, when none of these makes it fit: the caller
/// refuses it with the difference.
pub fn conform(
    clip: &mut Clip,
    fits: &dyn Fn(&zoo_motion::Skeleton) -> bool,
    reference: Option<&zoo_motion::Skeleton>,
) -> Option<Conformed> {
    if fits(&clip.skeleton) {
        return Some(Conformed::AsIs);
    }
    if let Some(reordered) = reference.and_then(|r| crate::retarget::reorder_like(clip, r))
        && fits(&reordered.skeleton)
    {
        *clip = reordered;
        return Some(Conformed::Reordered);
    }
    if has_dummy_shaped_root(clip) {
        let mut folded = clip.clone();
        let dummy = folded.skeleton.names[0].clone();
        if folded.drop_root() && fits(&folded.skeleton) {
            let into = folded.skeleton.names[0].clone();
            *clip = folded;
            return Some(Conformed::Folded(format!(
                "its dummy root `{dummy}` carries motion; folded into `{into}` (the same global motion)"
            )));
        }
    }
    None
}

/// [`conform`] to a known skeleton (same joint names and parents).
pub fn conform_to(clip: &mut Clip, skeleton: &zoo_motion::Skeleton) -> Option<Conformed> {
    conform(clip, &|s| skeleton.topology_difference(s).is_none(), Some(skeleton))
}

/// Whether the root is shaped like a dummy root: one child and a zero offset (a reader keeps
/// it when its channels carry motion).
pub fn has_dummy_shaped_root(clip: &Clip) -> bool {
    let s = &clip.skeleton;
    s.len() >= 2 && s.offsets[0] == zoo_motion::glam::DVec3::ZERO && s.children(0) == [1]
}

/// Writes a clip (in zoo's frame) in the format its name says: `.bvh` / `.bvh.gz` (BVH) or
/// `.glb` / `.gltf` (glTF 2.0 in metres, with a skin and a stick-figure mesh). The file is
/// written to a temporary name and renamed into place.
pub fn write(clip: &Clip, path: &Path) -> Result<(), ClipError> {
    let io = |source| ClipError::Io { path: path.to_path_buf(), action: "cannot write", source };
    match ClipFormat::of(path) {
        Some(ClipFormat::Bvh) => bvh::write_file(clip, path).map_err(io),
        Some(ClipFormat::Gltf) => crate::gltf::write_file(clip, path).map_err(io),
        _ => Err(ClipError::Extension { path: path.to_path_buf(), expected: WRITE_EXTENSIONS }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_extension() {
        for (name, f) in [
            ("a.bvh", Some(ClipFormat::Bvh)),
            ("A.BVH.GZ", Some(ClipFormat::Bvh)),
            ("a.glb", Some(ClipFormat::Gltf)),
            ("a.gltf", Some(ClipFormat::Gltf)),
            ("dir/a.FBX", Some(ClipFormat::Fbx)),
            ("a.obj", None),
            ("a.gz", None),
        ] {
            assert_eq!(ClipFormat::of(Path::new(name)), f, "{name}");
        }
        let e = read(Path::new("walk.obj"), &ReadOptions::default()).unwrap_err().to_string();
        assert!(e.contains("walk.obj: unknown clip format") && e.contains(".fbx"), "{e}");
        assert_eq!(describe_frame(&CoordinateFrame::ZOO_CM), "centimetres, Y up, right-handed");
    }
}
