//! What each task's network reads and writes, and the steps around it, shared by training (the
//! candle models) and the engine runtime (tract), so both compute them value for value:
//!
//! - [`features`]: the positional features of the Recurrent Transition Network (transitions);
//! - [`terrain`]: heightmaps and the terrain patches RTN reads;
//! - [`stitch`]: the pose vector of the Recurrent Motion Refiner (stitching), its guard, its
//!   foot lock by the predicted contacts and its reach;
//! - [`fcurve`], [`inbetween`], [`keyhit`], [`keylock`]: the key-to-key in-betweening inputs
//!   around Blender's default F-curves, keys hit exactly and the foot lock between keys;
//! - [`pipeline`], [`fit`], [`footlock`]: the motion pipeline around a model that generates
//!   joint positions (rotations fitted to them, the foot lock, clips spliced from them).
//!
//! It sits on the small motion core (`zoo_motion`: skeletons, clips, rotations, forward
//! kinematics, blending) and reads no files: the exported model file is `zoo_format`'s, the
//! dataset formats `zoo_data`'s. No tract, no candle.
//!
//! Conventions are the motion core's: positions in the clip's units, Y up, per-frame arrays
//! frame-major (`index = frame * joints + joint`).

pub mod fcurve;
pub mod features;
pub mod fit;
pub mod footlock;
pub mod inbetween;
pub mod keyhit;
pub mod keylock;
pub mod pipeline;
pub mod stitch;
pub mod terrain;
