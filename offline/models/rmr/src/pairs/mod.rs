//! Training and test pairs for motion stitching: the data generation of the Recurrent Motion
//! Refiner (Kim, Cho, Hong & Noh 2023, sec. 4), on clips of joint transforms (no candle).
//!
//! - [`layout`]: which joints are the lower body and the feet, the ground root (hips projected
//!   on the floor, heading about +Y) and the foot contacts;
//! - [`segments`]: per-length databases of motion segments and their weighted feature
//!   `{0.1 * first pose, 1.0 * last pose, 1.0 * root trajectory}`;
//! - [`knn`]: exact k-th nearest neighbour search over a database (brute force with early
//!   termination, ties broken by index);
//! - [`align`]: the runtime's alignment of whole clips end to start (sec. 6);
//! - [`baselines`]: inertialization and interpolation at the seams of an aligned sequence;
//! - [`eval`]: the stitching benchmark's measures (pose error, foot sliding, skate, pops);
//! - [`cache`]: planned pairs saved as JSON and reused for the same clips and configuration;
//! - [`generate`]: ground-truth windows, random segment lengths, retrieval of B and C, alignment,
//!   and the input clip `X` beside the ground truth `Y`.
//!
//! The generation is split in two so that its expensive part can be cached: [`generate::plan_pairs`]
//! runs the searches and returns small [`generate::PairSpec`]s (serde), and [`generate::build_pair`]
//! turns one spec into its two clips in microseconds.

pub mod align;
pub mod baselines;
pub mod cache;
pub mod eval;
pub mod generate;
pub mod knn;
pub mod layout;
pub mod segments;

pub use align::{AlignedClips, MIN_CLIP_FRAMES, align_clips};
pub use cache::{PairPlan, SetFingerprint};
pub use generate::{PairConfig, PairSpec, Retrieved, StitchPair, build_pair, make_pairs, plan_pairs};
pub use layout::{GroundRoot, LayoutError, StitchLayout, ground_roots};
pub use segments::{MotionSet, SegmentDatabase, SegmentRef, StitchDatabases};

use std::path::PathBuf;

/// Why stitching data could not be made. Each message names the problem and the fix.
#[derive(Debug, thiserror::Error)]
pub enum StitchError {
    /// The layout does not fit the skeleton (see [`LayoutError`]).
    #[error(transparent)]
    Layout(#[from] LayoutError),
    /// Two clips of one set use different rigs.
    #[error(
        "clip {index}{name}: skeleton differs from clip 0's ({why}); every clip must use the same rig \
         (retarget it first)"
    )]
    Skeleton {
        /// Index of the clip in its set.
        index: usize,
        /// ` (file name)` when known.
        name: String,
        /// What differs.
        why: String,
    },
    /// Two clips of one set have different frame rates.
    #[error(
        "clip {index}{name}: {found} fps, but the other clips are {expected} fps; resample it to {expected} fps first"
    )]
    FrameRate {
        /// Index of the clip.
        index: usize,
        /// ` (file name)` when known.
        name: String,
        /// Frame rate of the set.
        expected: f64,
        /// Frame rate of this clip.
        found: f64,
    },
    /// The set holds no clip.
    #[error("no clips given: pass at least one clip of at least {needed} frames")]
    NoClips {
        /// Frames needed.
        needed: usize,
    },
    /// No clip is long enough for a segment or window of the asked length.
    #[error("no clip has {needed} frames or more (the longest has {longest}); use longer clips or a shorter window")]
    TooShort {
        /// Frames needed.
        needed: usize,
        /// Longest clip.
        longest: usize,
    },
    /// A configuration value is invalid.
    #[error("invalid stitching configuration: {0}")]
    Config(String),
    /// A database for a segment length was not built.
    #[error(
        "no segment database of length {length} (built: {built:?}); build the databases with the pair configuration's lengths"
    )]
    NoDatabase {
        /// Length asked for.
        length: usize,
        /// Lengths built.
        built: Vec<usize>,
    },
    /// The two sets (ground truth and database) use different rigs or frame rates.
    #[error("the ground-truth clips and the database clips differ: {0}; use clips of the same rig and frame rate")]
    Mismatch(String),
    /// A spec refers to a clip or frame that does not exist.
    #[error("pair spec out of range: {0} (was the cache made from other clips? delete it and generate again)")]
    Spec(String),
    /// A cache file could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}
