//! The small motion core of zoo.
//!
//! Skeletons, clips of local joint transforms, quaternion and Euler utilities, forward
//! kinematics, facing/heading helpers, transition blending, the positional features the
//! runtime shares with training, terrain heightmaps, the seeded random generator, and the
//! motion pipeline around a model (fitting rotations to generated positions, the foot lock,
//! splicing clips). Offline data tools, the candle models and the engine-side runtime all read
//! motion through these types, so they share one implementation of every convention (units,
//! frames, rotation orders). Nothing here reads files or depends on candle; the one way files are
//! written in the workspace ([`atomic`]: a temporary file renamed into place) lives here so
//! that every crate, the BVH writer the Python package compiles in included, shares it.
//!
//! Conventions: quaternions are glam `DQuat` (stored x, y, z, w; the benchmark prints w first),
//! positions are `DVec3` in the clip's own units (bandai2 and the synthetic data: cm, Y up).
//! Per-frame arrays are laid out frame-major: `index = frame * joints + joint`.

pub mod atomic;
pub mod blend;
pub mod clip;
pub mod euler;
pub mod facing;
pub mod fcurve;
pub mod features;
pub mod finite;
pub mod fit;
pub mod fk;
pub mod footlock;
pub mod frame;
pub mod inbetween;
pub mod keyhit;
pub mod keylock;
pub mod pipeline;
pub mod quat;
pub mod rng;
pub mod skeleton;
pub mod stitch;
pub mod terrain;
pub mod ticks;

pub use clip::Clip;
pub use euler::EulerOrder;
pub use skeleton::{JointChannels, Skeleton};

/// Re-exported so callers use the same glam version as the core.
pub use glam;

/// The common imports of motion code.
pub mod prelude {
    pub use crate::clip::Clip;
    pub use crate::euler::EulerOrder;
    pub use crate::fk::{forward_kinematics, forward_kinematics_frame};
    pub use crate::skeleton::{JointChannels, Skeleton};
    pub use glam::{DQuat, DVec3};
}
