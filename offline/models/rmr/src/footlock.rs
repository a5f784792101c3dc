//! Foot lock by the predicted contacts (RMR sec. 6: "we lock the foot joints in contact with
//! the ground using inverse kinematics") and the ankles placed at the refiner's predicted
//! positions (sec. 5): defined in the core layer ([`zoo_protocol::stitch::lock`]) so that the
//! engine's runtime applies the same lock, re-exported here.

pub use zoo_protocol::stitch::lock::{LOCK_MAX_STEP, lock_feet, lock_feet_with, place_ankles};
