//! The small motion core of zoo: what every task uses.
//!
//! Skeletons, clips of local joint transforms, quaternion and Euler utilities, forward
//! kinematics, facing/heading helpers, transition blending, coordinate frames, the seeded random
//! generator, the check that values about to be written are finite, and the grid lines of a
//! drawing. Offline data tools, the candle models and the engine-side runtime all read motion
//! through these types, so they share one implementation of every convention (units, frames,
//! rotation orders). What a task's network reads and writes (RTN's features, RMR's pose vector,
//! the in-betweening inputs, terrain patches, the foot locks) lives in `zoo_protocol`, files in
//! `zoo_format` and `zoo_data`. Nothing here reads or writes files or depends on candle or
//! tract, and no other crate of the workspace is a dependency.
//!
//! Conventions: quaternions are glam `DQuat` (stored x, y, z, w; the benchmark prints w first),
//! positions are `DVec3` in the clip's own units (bandai2 and the synthetic data: cm, Y up).
//! Per-frame arrays are laid out frame-major: `index = frame * joints + joint`.

pub mod blend;
pub mod clip;
pub mod euler;
pub mod facing;
pub mod finite;
pub mod fk;
pub mod frame;
pub mod quat;
pub mod rng;
pub mod skeleton;
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
