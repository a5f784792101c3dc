//! Dataset tooling of zoo: clip reading and writing (BVH, glTF, FBX; [`clip_io`]), rig
//! mapping ([`retarget`]), datasets and windows, the in-betweening
//! benchmark's metrics and baselines, and synthetic motion.

pub mod benchmark;
pub mod bvh;
pub mod clip_io;
pub mod controls;
pub mod dataset;
pub mod denoise;
pub mod fbx;
pub mod gltf;
pub mod luxo;
pub mod metrics;
pub mod path;
pub mod plausibility;
pub mod position_method;
pub mod retarget;
pub(crate) mod scene;
pub mod stitch;
pub mod synth;
pub mod terrain;
