//! Fitting joint rotations to joint positions, for methods that generate positions only
//! (`BENCHMARK.md`, "Methods that generate joint positions only").
//!
//! Per joint, the rotation that turns the rest-pose directions of its children into the
//! generated ones: shortest arc for one child, a least-squares (Wahba / Horn) fit for
//! several. Twist, which positions cannot see, comes from a reference rotation (for RTN: the
//! context and target frames' rotations, interpolated): the fit is the smallest correction of
//! the reference.

use glam::{DQuat, DVec3};
use zoo_motion::quat::shortest_arc;

/// Reusable buffers of [`fit_rotations_with`]: after the first frame of a skeleton, fitting
/// allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct FitScratch {
    global: Vec<DQuat>,
    a: Vec<DVec3>,
    b: Vec<DVec3>,
}

/// Fits local rotations of one frame to global positions.
///
/// - `parents`, `offsets`: the skeleton (rest offsets of each joint from its parent);
/// - `positions`: global joint positions to match;
/// - `reference`: local rotations giving the twist (and the rotation of leaf joints);
/// - `out`: fitted local rotations.
///
/// Bones of zero length are ignored. The root position is `positions[0]`.
pub fn fit_rotations(
    parents: &[Option<usize>],
    offsets: &[DVec3],
    positions: &[DVec3],
    reference: &[DQuat],
    out: &mut [DQuat],
) {
    fit_rotations_with(&mut FitScratch::default(), parents, offsets, positions, reference, out);
}

/// [`fit_rotations`] with caller-owned buffers (for per-frame use without allocation).
pub fn fit_rotations_with(
    scratch: &mut FitScratch,
    parents: &[Option<usize>],
    offsets: &[DVec3],
    positions: &[DVec3],
    reference: &[DQuat],
    out: &mut [DQuat],
) {
    let n = parents.len();
    let FitScratch { global, a, b } = scratch;
    global.clear();
    global.resize(n, DQuat::IDENTITY);
    for j in 0..n {
        let parent_global = parents[j].map_or(DQuat::IDENTITY, |p| global[p]);
        let guess = (parent_global * reference[j]).normalize();
        a.clear();
        b.clear();
        for c in (j + 1)..n {
            if parents[c] != Some(j) {
                continue;
            }
            let rest = guess * offsets[c];
            let target = positions[c] - positions[j];
            let (lr, lt) = (rest.length(), target.length());
            if lr < 1e-9 || lt < 1e-9 {
                continue;
            }
            a.push(rest / lr);
            b.push(target / lt);
        }
        let fix = match a.len() {
            0 => DQuat::IDENTITY,
            1 => shortest_arc(a[0], b[0]),
            _ => wahba(a, b),
        };
        global[j] = (fix * guess).normalize();
        let inv_parent = parent_global.inverse();
        let local = (inv_parent * global[j]).normalize();
        // keep the reference's hemisphere so sequences stay free of sign flips
        out[j] = if local.dot(reference[j]) < 0.0 { -local } else { local };
    }
}

/// Rotation `q` minimising `sum |q a_i - b_i|^2` (unit vectors), by Horn's quaternion method:
/// the eigenvector of the largest eigenvalue of a symmetric 4x4 matrix.
pub fn wahba(a: &[DVec3], b: &[DVec3]) -> DQuat {
    // S = sum a_i b_i^T
    let mut s = [[0.0f64; 3]; 3];
    for (u, v) in a.iter().zip(b) {
        for r in 0..3 {
            for c in 0..3 {
                s[r][c] += u[r] * v[c];
            }
        }
    }
    let (sxx, sxy, sxz) = (s[0][0], s[0][1], s[0][2]);
    let (syx, syy, syz) = (s[1][0], s[1][1], s[1][2]);
    let (szx, szy, szz) = (s[2][0], s[2][1], s[2][2]);
    // Horn 1987, quaternion order (w, x, y, z)
    let m = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (vals, vecs) = jacobi_eigen4(m);
    let mut best = 0;
    for i in 1..4 {
        if vals[i] > vals[best] {
            best = i;
        }
    }
    let v = [vecs[0][best], vecs[1][best], vecs[2][best], vecs[3][best]];
    let q = DQuat::from_xyzw(v[1], v[2], v[3], v[0]).normalize();
    if q.is_finite() { q } else { DQuat::IDENTITY }
}

/// Eigenvalues and eigenvectors (columns) of a symmetric 4x4 matrix (cyclic Jacobi).
fn jacobi_eigen4(mut a: [[f64; 4]; 4]) -> ([f64; 4], [[f64; 4]; 4]) {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..50 {
        let mut off = 0.0;
        for p in 0..4 {
            for q in (p + 1)..4 {
                off += a[p][q] * a[p][q];
            }
        }
        if off < 1e-30 {
            break;
        }
        for p in 0..4 {
            for q in (p + 1)..4 {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..4 {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..4 {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for k in 0..4 {
                    let (vkp, vkq) = (v[k][p], v[k][q]);
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2], a[3][3]], v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::fk::forward_kinematics_frame;

    fn skeleton() -> (Vec<Option<usize>>, Vec<DVec3>) {
        // root with three children (like Hips), a chain below each
        let parents = vec![None, Some(0), Some(1), Some(0), Some(3), Some(0), Some(5)];
        let offsets = vec![
            DVec3::ZERO,
            DVec3::new(0.0, 10.0, 0.0),
            DVec3::new(0.0, 10.0, 1.0),
            DVec3::new(5.0, -2.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
            DVec3::new(-5.0, -2.0, 0.0),
            DVec3::new(0.0, -40.0, 0.0),
        ];
        (parents, offsets)
    }

    fn pose(seed: f64) -> Vec<DQuat> {
        (0..7)
            .map(|j| {
                let s = seed + j as f64;
                DQuat::from_euler(glam::EulerRot::ZXY, (1.3 * s).sin(), (0.7 * s).cos(), (2.1 * s).sin() * 0.5)
            })
            .collect()
    }

    #[test]
    fn fit_recovers_positions_from_any_reference() {
        let (parents, offsets) = skeleton();
        let truth = pose(0.3);
        let mut lp = offsets.clone();
        lp[0] = DVec3::new(1.0, 90.0, 3.0);
        let (mut gr, mut gp) = (vec![DQuat::IDENTITY; 7], vec![DVec3::ZERO; 7]);
        forward_kinematics_frame(&parents, &truth, &lp, &mut gr, &mut gp);
        let reference = pose(2.0); // a different pose: only twist is taken from it
        let mut fitted = vec![DQuat::IDENTITY; 7];
        fit_rotations(&parents, &offsets, &gp, &reference, &mut fitted);
        let (mut gr2, mut gp2) = (vec![DQuat::IDENTITY; 7], vec![DVec3::ZERO; 7]);
        forward_kinematics_frame(&parents, &fitted, &lp, &mut gr2, &mut gp2);
        for j in 0..7 {
            assert!((gp[j] - gp2[j]).length() < 1e-9, "joint {j}: {:?} vs {:?}", gp[j], gp2[j]);
        }
    }

    #[test]
    fn fit_with_true_reference_is_exact() {
        let (parents, offsets) = skeleton();
        let truth = pose(1.1);
        let mut lp = offsets.clone();
        lp[0] = DVec3::ZERO;
        let (mut gr, mut gp) = (vec![DQuat::IDENTITY; 7], vec![DVec3::ZERO; 7]);
        forward_kinematics_frame(&parents, &truth, &lp, &mut gr, &mut gp);
        let mut fitted = vec![DQuat::IDENTITY; 7];
        fit_rotations(&parents, &offsets, &gp, &truth, &mut fitted);
        for j in 0..7 {
            assert!(fitted[j].dot(truth[j]) > 1.0 - 1e-12, "joint {j}");
        }
    }

    #[test]
    fn wahba_finds_a_known_rotation() {
        let q = DQuat::from_rotation_y(0.8) * DQuat::from_rotation_x(-0.3);
        let a = [DVec3::X, DVec3::Y, DVec3::new(0.0, 0.6, 0.8)];
        let b: Vec<DVec3> = a.iter().map(|v| q * *v).collect();
        let r = wahba(&a, &b);
        assert!(r.dot(q).abs() > 1.0 - 1e-12);
    }
}
