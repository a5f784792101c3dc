//! Dataset tooling every model of zoo shares: clip reading and writing (BVH, glTF, FBX;
//! [`clip_io`]), rig mapping ([`retarget`]), datasets, splits and windows, the benchmark
//! protocol with its metrics and baselines, terrain heightmaps and the synthetic biped.
//!
//! What serves one model lives with it: the stitching pairs in `zoo_rmr::pairs`, the simulated
//! lamp in `zoo_arnn::luxo`, control scripts, ground paths and the denoising noise in
//! `zoo_rnngmm`.

pub mod benchmark;
pub mod bvh;
pub use bvh::limits;
pub mod clip_io;
pub mod dataset;
pub mod fbx;
pub mod gltf;
pub mod metrics;
pub mod plausibility;
pub mod position_method;
pub mod positions;
pub mod render;
pub mod report;
pub mod retarget;
pub(crate) mod scene;
pub mod stats;
pub mod synth;
pub mod terrain;

pub use report::{Context, Message, Progress, Quiet};
