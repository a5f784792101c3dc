//! Dataset tooling of zoo: BVH reading and writing, datasets and windows, the in-betweening
//! benchmark's metrics and baselines, and synthetic motion.

pub mod benchmark;
pub mod bvh;
pub mod controls;
pub mod dataset;
pub mod denoise;
pub mod luxo;
pub mod metrics;
pub mod path;
pub mod plausibility;
pub mod position_method;
pub mod stitch;
pub mod synth;
pub mod terrain;
