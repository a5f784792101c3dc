//! Forward kinematics.

use glam::{DQuat, DVec3};

/// Global rotations and positions of one frame from local ones.
///
/// `parents[j] < j` for every non-root joint. All slices have one entry per joint.
#[inline]
pub fn forward_kinematics_frame(
    parents: &[Option<usize>],
    local_rot: &[DQuat],
    local_pos: &[DVec3],
    global_rot: &mut [DQuat],
    global_pos: &mut [DVec3],
) {
    for j in 0..parents.len() {
        match parents[j] {
            None => {
                global_rot[j] = local_rot[j];
                global_pos[j] = local_pos[j];
            }
            Some(p) => {
                global_pos[j] = global_rot[p] * local_pos[j] + global_pos[p];
                global_rot[j] = global_rot[p] * local_rot[j];
            }
        }
    }
}

/// Forward kinematics over many frames (frame-major arrays of `frames * joints`).
pub fn forward_kinematics(
    parents: &[Option<usize>],
    local_rot: &[DQuat],
    local_pos: &[DVec3],
    global_rot: &mut [DQuat],
    global_pos: &mut [DVec3],
) {
    let j = parents.len();
    for (((lr, lp), gr), gp) in local_rot
        .chunks_exact(j)
        .zip(local_pos.chunks_exact(j))
        .zip(global_rot.chunks_exact_mut(j))
        .zip(global_pos.chunks_exact_mut(j))
    {
        forward_kinematics_frame(parents, lr, lp, gr, gp);
    }
}

/// Local rotations and positions of one frame from global ones (inverse of FK).
pub fn global_to_local_frame(
    parents: &[Option<usize>],
    global_rot: &[DQuat],
    global_pos: &[DVec3],
    local_rot: &mut [DQuat],
    local_pos: &mut [DVec3],
) {
    for j in 0..parents.len() {
        match parents[j] {
            None => {
                local_rot[j] = global_rot[j];
                local_pos[j] = global_pos[j];
            }
            Some(p) => {
                let inv = global_rot[p].inverse();
                local_rot[j] = inv * global_rot[j];
                local_pos[j] = inv * (global_pos[j] - global_pos[p]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn chain_with_known_pose() {
        // Root at (1,0,0) rotated 90 deg about Z; child offset (2,0,0); grandchild offset
        // (0,3,0) with the child rotated 90 deg about Z as well.
        let parents = [None, Some(0), Some(1)];
        let rz = DQuat::from_rotation_z(FRAC_PI_2);
        let lr = [rz, rz, DQuat::IDENTITY];
        let lp = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(2.0, 0.0, 0.0), DVec3::new(0.0, 3.0, 0.0)];
        let mut gr = [DQuat::IDENTITY; 3];
        let mut gp = [DVec3::ZERO; 3];
        forward_kinematics_frame(&parents, &lr, &lp, &mut gr, &mut gp);
        // child: (1,0,0) + Rz90 (2,0,0) = (1,2,0)
        assert!((gp[1] - DVec3::new(1.0, 2.0, 0.0)).length() < 1e-12);
        // grandchild: (1,2,0) + Rz180 (0,3,0) = (1,-1,0)
        assert!((gp[2] - DVec3::new(1.0, -1.0, 0.0)).length() < 1e-12);
        let mut lr2 = [DQuat::IDENTITY; 3];
        let mut lp2 = [DVec3::ZERO; 3];
        global_to_local_frame(&parents, &gr, &gp, &mut lr2, &mut lp2);
        for j in 0..3 {
            assert!(lr2[j].dot(lr[j]).abs() > 1.0 - 1e-12);
            assert!((lp2[j] - lp[j]).length() < 1e-12);
        }
    }
}
