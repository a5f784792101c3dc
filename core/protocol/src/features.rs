//! Positional motion features of the Recurrent Transition Network (Harvey & Pal 2018, sec. 3.2)
//! that the engine-side runtime shares with training, on plain `f32` slices: the feature
//! encoding and its inverse, the target vector and the target blend. What only training needs
//! (normalization statistics, global offsets, terrain patches, augmentation) lives in
//! `zoo_rtn::features`.
//!
//! Layout conventions (all frame-major, Y up, clip units):
//! - global positions: `positions[(f * joints + j) * 3 + axis]`;
//! - a feature frame `x~_t` has `D = 3 * joints` values: the root's global velocity
//!   `r_t - r_(t-1)` (3) followed by the root-relative positions of joints `1..joints` (RTN sec. 3.2);
//! - the target vector has `2 * D` values: the target pose features (its root slot holds the
//!   forward root velocity `r_(T+1) - r_T`, because frame `T - 1` is what is being generated)
//!   followed by the global velocities `y_(T+1) - y_T` of every joint.

use zoo_motion::blend::target_blend_offset_weight;

/// Number of values of one feature frame for `joints` joints.
pub fn feature_dim(joints: usize) -> usize {
    3 * joints
}

/// Root position (joint 0) of one frame of global positions.
#[inline]
pub fn root_of(frame: &[f32]) -> [f32; 3] {
    [frame[0], frame[1], frame[2]]
}

/// Encodes one frame of global positions (`3 * joints`) into features `x~_t` (RTN sec. 3.2)
/// given the previous frame's root position.
pub fn encode_frame(prev_root: [f32; 3], frame: &[f32], out: &mut [f32]) {
    debug_assert_eq!(frame.len(), out.len());
    let r = root_of(frame);
    for a in 0..3 {
        out[a] = r[a] - prev_root[a];
    }
    for (o, p) in out[3..].chunks_exact_mut(3).zip(frame[3..].chunks_exact(3)) {
        for a in 0..3 {
            o[a] = p[a] - r[a];
        }
    }
}

/// Decodes one feature frame back to global positions given the previous frame's root
/// position; returns the new root position (root velocity integration, RTN sec. 4.5).
pub fn decode_frame(prev_root: [f32; 3], features: &[f32], out: &mut [f32]) -> [f32; 3] {
    debug_assert_eq!(features.len(), out.len());
    out.copy_from_slice(features);
    decode_frame_in_place(prev_root, out)
}

/// [`decode_frame`] on a buffer holding the features, replaced by the positions.
pub fn decode_frame_in_place(prev_root: [f32; 3], frame: &mut [f32]) -> [f32; 3] {
    let r = [prev_root[0] + frame[0], prev_root[1] + frame[1], prev_root[2] + frame[2]];
    frame[..3].copy_from_slice(&r);
    for p in frame[3..].chunks_exact_mut(3) {
        for a in 0..3 {
            p[a] += r[a];
        }
    }
    r
}

/// Encodes every frame of a sequence of global positions (`frames * 3 * joints`) into
/// features. Frame 0 has no predecessor: its root velocity is taken equal to frame 1's
/// (zero for a one-frame sequence).
pub fn encode_positions(positions: &[f32], joints: usize, out: &mut [f32]) {
    let d = feature_dim(joints);
    assert_eq!(positions.len(), out.len(), "positions and features must have the same length");
    assert_eq!(positions.len() % d, 0, "positions must hold whole frames of {joints} joints");
    let frames = positions.len() / d;
    for f in 0..frames {
        let frame = &positions[f * d..(f + 1) * d];
        let prev = if f > 0 {
            root_of(&positions[(f - 1) * d..])
        } else if frames > 1 {
            let (r0, r1) = (root_of(frame), root_of(&positions[d..]));
            [2.0 * r0[0] - r1[0], 2.0 * r0[1] - r1[1], 2.0 * r0[2] - r1[2]]
        } else {
            root_of(frame)
        };
        encode_frame(prev, frame, &mut out[f * d..(f + 1) * d]);
    }
}

/// Decodes a sequence of feature frames to global positions, integrating root velocities
/// from `start_root` (the root of the frame before the first one).
pub fn decode_features(start_root: [f32; 3], features: &[f32], joints: usize, out: &mut [f32]) {
    let d = feature_dim(joints);
    assert_eq!(features.len(), out.len(), "features and positions must have the same length");
    let mut root = start_root;
    for (x, y) in features.chunks_exact(d).zip(out.chunks_exact_mut(d)) {
        root = decode_frame(root, x, y);
    }
}

/// Unnormalized target vector `t` (`2 * D` values) from the target frame `y_T` and the one
/// after it `y_(T+1)` (RTN sec. 3.2): the target pose features, whose root slot is the
/// forward root velocity, then the global velocity of every joint.
pub fn target_vector(target: &[f32], next: &[f32], out: &mut [f32]) {
    let d = target.len();
    assert_eq!(next.len(), d, "target and next frames must have the same length");
    assert_eq!(out.len(), 2 * d, "the target vector has twice the frame size");
    let (r, n) = (root_of(target), root_of(next));
    let prev = [2.0 * r[0] - n[0], 2.0 * r[1] - n[1], 2.0 * r[2] - n[2]];
    encode_frame(prev, target, &mut out[..d]);
    for ((o, a), b) in out[d..].iter_mut().zip(target).zip(next) {
        *o = b - a;
    }
}

/// Target blend (RTN eq. 15-16) of a generated transition in global positions.
///
/// `frames` holds the generated frames (`n * 3 * joints`), the last one being the predicted
/// target; each frame `t` within `blend_len` frames of the target is moved by `w_t * e`,
/// `e = target - predicted target`, `w_t = 1 - (T - t) / blend_len`, so the last frame lands on
/// `target` exactly.
pub fn target_blend(frames: &mut [f32], target: &[f32], blend_len: usize) {
    let d = target.len();
    assert!(
        d > 0 && frames.len().is_multiple_of(d) && !frames.is_empty(),
        "frames must hold whole target-sized frames"
    );
    let n = frames.len() / d;
    let e: Vec<f32> = target.iter().zip(&frames[(n - 1) * d..]).map(|(t, y)| t - y).collect();
    for f in 0..n {
        let w = target_blend_offset_weight(f, n - 1, blend_len) as f32;
        if w > 0.0 {
            for (y, e) in frames[f * d..(f + 1) * d].iter_mut().zip(&e) {
                *y += w * e;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk(frames: usize, joints: usize) -> Vec<f32> {
        let mut p = Vec::new();
        for f in 0..frames {
            let t = f as f32 * 0.1;
            for j in 0..joints {
                p.extend_from_slice(&[t * 3.0 + j as f32, 90.0 + (t + j as f32).sin(), t * 2.0 - j as f32 * 0.5]);
            }
        }
        p
    }

    #[test]
    fn encode_decode_round_trip() {
        let (frames, joints) = (6, 4);
        let p = walk(frames, joints);
        let mut x = vec![0.0; p.len()];
        encode_positions(&p, joints, &mut x);
        // root velocity of frame 3 and root-relative joint 2 of frame 3
        let d = 3 * joints;
        assert!((x[3 * d] - (p[3 * d] - p[2 * d])).abs() < 1e-6);
        assert!((x[3 * d + 7] - (p[3 * d + 7] - p[3 * d + 1])).abs() < 1e-6);
        let start = root_of(&p[..]);
        let mut y = vec![0.0; p.len()];
        decode_features(start, &x[d..], joints, &mut y[d..]);
        for (a, b) in y[d..].iter().zip(&p[d..]) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
    }

    #[test]
    fn target_vector_layout() {
        let joints = 3;
        let p = walk(2, joints);
        let d = 3 * joints;
        let mut t = vec![0.0; 2 * d];
        target_vector(&p[..d], &p[d..], &mut t);
        assert!((t[0] - (p[d] - p[0])).abs() < 1e-6, "root slot is the forward root velocity");
        assert!((t[d + 4] - (p[d + 4] - p[4])).abs() < 1e-6);
        assert!((t[5] - (p[5] - p[2])).abs() < 1e-6);
    }

    #[test]
    fn target_blend_lands_on_target() {
        let mut frames = vec![0.0f32; 5 * 3];
        let target = [3.0, 3.0, 3.0];
        target_blend(&mut frames, &target, 2);
        assert_eq!(&frames[12..15], &target);
        assert_eq!(&frames[..9], &[0.0; 9]);
        assert!((frames[9] - 1.5).abs() < 1e-6);
    }
}
