//! The synthetic skeleton: bandai2's joints without its dummy root, and the leg geometry the
//! other stages read from it.

use super::geometry::look_rotation;
use glam::{DQuat, DVec3};
use zoo_motion::{EulerOrder, JointChannels, Skeleton};

/// Joint names (bandai2 without `joint_Root`).
pub const JOINT_NAMES: [&str; 21] = [
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "Shoulder_L",
    "UpperArm_L",
    "LowerArm_L",
    "Hand_L",
    "Shoulder_R",
    "UpperArm_R",
    "LowerArm_R",
    "Hand_R",
    "UpperLeg_L",
    "LowerLeg_L",
    "Foot_L",
    "Toes_L",
    "UpperLeg_R",
    "LowerLeg_R",
    "Foot_R",
    "Toes_R",
];

/// Parent of each joint (`-1` for the root).
pub const JOINT_PARENTS: [i32; 21] = [-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19];

/// Rest offsets (cm) from bandai2 `dataset-2_walk_normal_001.bvh` (the root's is the dummy
/// root's offset plus `Hips`'s).
pub const JOINT_OFFSETS: [[f64; 3]; 21] = [
    [-0.726466, 93.3139, -2.00062],
    [15.7357, 0.0, 0.0],
    [8.98455, -0.406207, 0.0],
    [16.3773, 0.0, 0.0],
    [6.45672, 0.0, 0.0],
    [12.9942, -0.242716, 4.98039],
    [5.34809, 0.0, 0.0],
    [24.3286, 1.87007e-05, 0.0],
    [22.2916, 0.0, 0.0],
    [12.9945, -0.242716, -4.98039],
    [-5.34813, 0.0, 0.0],
    [-24.3289, 0.000322201, 0.0],
    [-22.2915, -0.000108084, 0.0],
    [-2.19248, -6.46944, 0.0],
    [39.0811, 0.0, -1.23785e-05],
    [40.9854, 0.0, -1.26872e-05],
    [11.7543, 0.0, 0.0],
    [-2.19251, 6.46944, 0.0],
    [-39.0811, -0.00228153, -0.0401928],
    [-40.9854, 0.0, 0.0],
    [-11.7543, 0.0, 0.0],
];

/// The foot joints of the foot-skate metric, in order.
pub const FOOT_JOINTS: [&str; 4] = ["Foot_L", "Toes_L", "Foot_R", "Toes_R"];

/// Height of a planted ankle (`Foot_*`) above the ground (cm, bandai2: about 11.7).
pub const ANKLE_HEIGHT: f64 = 11.7;
/// Height of planted toes (`Toes_*`) above the ground (cm, bandai2: about 4.3).
pub const TOE_HEIGHT: f64 = 4.3;

pub(super) const HIPS: usize = 0;
pub(super) const SPINE: usize = 1;
pub(super) const CHEST: usize = 2;
pub(super) const NECK: usize = 3;
pub(super) const HEAD: usize = 4;
pub(super) const SHOULDER: [usize; 2] = [5, 9];
pub(super) const UPPER_ARM: [usize; 2] = [6, 10];
pub(super) const LOWER_ARM: [usize; 2] = [7, 11];
pub(super) const HAND: [usize; 2] = [8, 12];
pub(super) const UPPER_LEG: [usize; 2] = [13, 17];
pub(super) const LOWER_LEG: [usize; 2] = [14, 18];
pub(super) const FOOT: [usize; 2] = [15, 19];
pub(super) const TOES: [usize; 2] = [16, 20];

/// The synthetic skeleton: bandai2's names, hierarchy and offsets; root with 6 channels,
/// other joints 3 (all ZXY).
pub fn skeleton() -> Skeleton {
    let n = JOINT_NAMES.len();
    let leaf = |j: usize| !JOINT_PARENTS.contains(&(j as i32));
    Skeleton {
        names: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
        parents: JOINT_PARENTS.iter().map(|&p| (p >= 0).then_some(p as usize)).collect(),
        offsets: JOINT_OFFSETS.iter().map(|o| DVec3::from_array(*o)).collect(),
        end_sites: (0..n).map(|j| leaf(j).then_some(DVec3::ZERO)).collect(),
        channels: (0..n).map(|j| JointChannels { position: j == 0, order: EulerOrder::Zxy }).collect(),
    }
}

/// Whether clips on `skeleton` (the first of them named `first`, at `fps` frames per second
/// where it is known) can be trained with the generator's clips at `generator_fps`: the same
/// joint names and parents (offsets may differ: bandai2's performers do), and the same frame
/// rate. The refusal names the training option `option`, the difference and the fix.
pub fn check_mixable(
    option: &str,
    first: &str,
    skeleton: &Skeleton,
    fps: Option<f64>,
    generator_fps: f64,
) -> Result<(), String> {
    let names: Vec<&str> = skeleton.names.iter().map(String::as_str).collect();
    let parents: Vec<Option<usize>> = JOINT_PARENTS.iter().map(|&p| (p >= 0).then_some(p as usize)).collect();
    let other_rate = fps.is_some_and(|f| (f - generator_fps).abs() > 0.01);
    if names == JOINT_NAMES && skeleton.parents == parents && !other_rate {
        return Ok(());
    }
    let rate = fps.map_or(String::new(), |f| format!(" at {f:.3} fps"));
    Err(format!(
        "{option}: the synthetic clips are on bandai2's skeleton ({} joints, `{}` first) at {generator_fps} fps, but \
         {first} is on {} joints (`{}` first){rate}; leave {option} out for this data",
        JOINT_NAMES.len(),
        JOINT_NAMES[0],
        names.len(),
        names.first().copied().unwrap_or("")
    ))
}

/// Lengths (cm) of the thigh (hip to knee) and of the shin (knee to ankle).
pub(super) fn leg_lengths() -> (f64, f64) {
    (DVec3::from_array(JOINT_OFFSETS[14]).length(), DVec3::from_array(JOINT_OFFSETS[15]).length())
}

/// Length (cm) of the foot, ankle to toes.
pub(super) fn foot_length() -> f64 {
    JOINT_OFFSETS[16][0].abs()
}

/// Offsets of the left and right hips from the root, in the root's frame.
pub(super) fn hip_offsets() -> [DVec3; 2] {
    [DVec3::from_array(JOINT_OFFSETS[13]), DVec3::from_array(JOINT_OFFSETS[17])]
}

/// The hips' rest frame: local X (bandai2's up) to world +Y, local Z to world +Z.
pub(super) fn hips_frame() -> DQuat {
    look_rotation(DVec3::X, DVec3::Z, DVec3::Y, DVec3::Z)
}
