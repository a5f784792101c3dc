//! Conversions between engine pose types (glam) and the flat `f32` buffers the runner takes.
//!
//! Flat layout: joint-major, `[x0, y0, z0, x1, y1, z1, ...]` (3 values per joint).

use glam::{Quat, Vec3};

/// Writes joint positions into a flat buffer. `dst.len()` must be `3 * src.len()`.
/// Returns `false` (writing nothing) when the lengths do not match.
pub fn write_positions(src: &[Vec3], dst: &mut [f32]) -> bool {
    if dst.len() != 3 * src.len() {
        return false;
    }
    for (p, d) in src.iter().zip(dst.chunks_exact_mut(3)) {
        d.copy_from_slice(&p.to_array());
    }
    true
}

/// Reads joint positions from a flat buffer. `src.len()` must be `3 * dst.len()`.
/// Returns `false` (reading nothing) when the lengths do not match.
pub fn read_positions(src: &[f32], dst: &mut [Vec3]) -> bool {
    if src.len() != 3 * dst.len() {
        return false;
    }
    for (s, p) in src.chunks_exact(3).zip(dst.iter_mut()) {
        *p = Vec3::from_slice(s);
    }
    true
}

/// Writes joint rotations into a flat buffer, 4 values per joint in glam order `x, y, z, w`.
/// Returns `false` (writing nothing) when `dst.len() != 4 * src.len()`.
pub fn write_rotations(src: &[Quat], dst: &mut [f32]) -> bool {
    if dst.len() != 4 * src.len() {
        return false;
    }
    for (q, d) in src.iter().zip(dst.chunks_exact_mut(4)) {
        d.copy_from_slice(&q.to_array());
    }
    true
}

/// Reads joint rotations (`x, y, z, w` per joint) and normalizes them.
/// Returns `false` (reading nothing) when `src.len() != 4 * dst.len()`.
pub fn read_rotations(src: &[f32], dst: &mut [Quat]) -> bool {
    if src.len() != 4 * dst.len() {
        return false;
    }
    for (s, q) in src.chunks_exact(4).zip(dst.iter_mut()) {
        *q = Quat::from_slice(s).normalize();
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_length_checks() {
        let p = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)];
        let mut flat = [0.0; 6];
        assert!(write_positions(&p, &mut flat));
        assert_eq!(flat, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let mut back = [Vec3::ZERO; 2];
        assert!(read_positions(&flat, &mut back));
        assert_eq!(back, p);
        assert!(!read_positions(&flat[..5], &mut back));
        let q = [Quat::from_rotation_y(0.5)];
        let mut flat = [0.0; 4];
        assert!(write_rotations(&q, &mut flat));
        let mut back = [Quat::IDENTITY];
        assert!(read_rotations(&flat, &mut back));
        assert!(back[0].abs_diff_eq(q[0], 1e-6));
    }
}
