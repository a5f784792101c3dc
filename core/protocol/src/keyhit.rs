//! Hitting keys exactly: a completed motion (a keyframe network's output) corrected so that
//! each key frame equals its key, the difference spread over the frames before it, like RTN's
//! target blend (`features::target_blend`) but between every pair of keys.
//!
//! Per pose value `d` of key group `g`, with `e_k = key_k[d] - out[frame_k][d]` the miss at each
//! key `k` that fixes `g`: between two such keys at frames `a < b`, frame `t` moves by
//! `(1 - w) e_a + w e_b`, `w = (t - a) / (b - a)`; after the last key fixing `g` the offset
//! stays `e_last`; the key frames take the key's values. The offset is continuous, zero where
//! the motion already meets the keys, and leaves the network's motion between keys otherwise
//! untouched. Groups of four values are unit quaternions when `quaternions` is set: each key is
//! first taken on the output's hemisphere (the same rotation), so the offset does not run
//! through the origin.

/// A pose value type: `f32` (the runtime) or `f64`.
pub trait KeyValue: Copy {
    /// As f64.
    fn to_f64(self) -> f64;
    /// From f64.
    fn from_f64(v: f64) -> Self;
}

impl KeyValue for f32 {
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl KeyValue for f64 {
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// The keys of a completion, as [`hit_keys`] reads them.
#[derive(Clone, Copy, Debug)]
pub struct KeyLayout<'a> {
    /// Values per pose.
    pub dofs: usize,
    /// Key frames, strictly increasing; the first key fixes every group.
    pub frames: &'a [usize],
    /// The group of each pose value (empty: one group, every key whole).
    pub key_groups: &'a [usize],
    /// Groups of four values are unit quaternions (compared up to sign).
    pub quaternions: bool,
}

impl KeyLayout<'_> {
    fn groups(&self) -> usize {
        self.key_groups.iter().max().map_or(1, |g| g + 1)
    }

    fn group(&self, d: usize) -> usize {
        if self.key_groups.is_empty() { 0 } else { self.key_groups[d] }
    }
}

/// Corrects `out` (`frames x dofs`, frame-major, frame 0 the first key) towards `poses`
/// (`keys x dofs`): afterwards every key frame holds its key's values for the groups it fixes
/// (`fixed(key, group)`). `scratch` holds `dofs` values (nothing is allocated). Frames past
/// `out`'s end and keys past it are ignored.
pub fn hit_keys<T: KeyValue>(
    keys: KeyLayout<'_>,
    poses: &[T],
    fixed: impl Fn(usize, usize) -> bool,
    out: &mut [T],
    scratch: &mut [T],
) {
    let d = keys.dofs;
    if d == 0 {
        return;
    }
    let n = out.len() / d;
    for g in 0..keys.groups() {
        let in_group = |v: &usize| keys.group(*v) == g;
        let quaternion = keys.quaternions && (0..d).filter(in_group).count() == 4;
        let mut prev: Option<usize> = None;
        for (k, &fb) in keys.frames.iter().enumerate() {
            if fb >= n || !fixed(k, g) {
                continue;
            }
            let key = &poses[k * d..(k + 1) * d];
            let dot: f64 = (0..d).filter(in_group).map(|v| key[v].to_f64() * out[fb * d + v].to_f64()).sum();
            let sign = if quaternion && dot < 0.0 { -1.0 } else { 1.0 };
            for v in (0..d).filter(in_group) {
                let target = sign * key[v].to_f64();
                let eb = target - out[fb * d + v].to_f64();
                let (from, ea) = match prev {
                    Some(fa) => (fa + 1, scratch[v].to_f64()),
                    None => (0, eb),
                };
                let span = fb.saturating_sub(prev.unwrap_or(0)).max(1) as f64;
                for f in from..fb {
                    let w = match prev {
                        Some(fa) => (f - fa) as f64 / span,
                        None => 1.0,
                    };
                    let y = &mut out[f * d + v];
                    *y = T::from_f64(y.to_f64() + (1.0 - w) * ea + w * eb);
                }
                out[fb * d + v] = T::from_f64(target);
                scratch[v] = T::from_f64(eb);
            }
            prev = Some(fb);
        }
        if let Some(fa) = prev {
            for f in fa + 1..n {
                for v in (0..d).filter(in_group) {
                    let y = &mut out[f * d + v];
                    *y = T::from_f64(y.to_f64() + scratch[v].to_f64());
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_hit_and_the_offset_is_continuous() {
        // Two values, one group; keys at 0, 4, 10; the "network" misses by 1 and -2.
        let frames = [0, 4, 10];
        let poses = [0.0f32, 1.0, 4.0, 5.0, 10.0, 11.0];
        let mut out: Vec<f32> = (0..11).flat_map(|f| [f as f32, f as f32 + 1.0]).collect();
        out[4 * 2] += -1.0;
        out[10 * 2 + 1] += 2.0;
        let raw = out.clone();
        let keys = KeyLayout { dofs: 2, frames: &frames, key_groups: &[], quaternions: false };
        hit_keys(keys, &poses, |_, _| true, &mut out, &mut [0.0; 2]);
        for (k, &f) in frames.iter().enumerate() {
            assert_eq!(&out[f * 2..f * 2 + 2], &poses[k * 2..k * 2 + 2]);
        }
        // Value 0 between frames 4 and 10: the offset +1 at frame 4 fades out linearly.
        for f in 5..10 {
            let w = (f - 4) as f32 / 6.0;
            assert!((out[f * 2] - (raw[f * 2] + (1.0 - w))).abs() < 1e-6, "frame {f}");
        }
        // Value 1 before frame 10: the offset -2 grows from frame 4 on, nothing before it.
        assert_eq!(&out[..8 * 2].iter().skip(1).step_by(2).take(4).copied().collect::<Vec<_>>(), &[1.0, 2.0, 3.0, 4.0]);
        assert!((out[7 * 2 + 1] - (raw[7 * 2 + 1] - 2.0 * 3.0 / 6.0)).abs() < 1e-6);
    }

    #[test]
    fn partial_keys_correct_only_the_groups_they_fix_and_quaternions_keep_their_sign() {
        // Group 0: one value; group 1: a quaternion. Key 1 fixes group 0 only.
        let frames = [0, 2, 4];
        let q = [1.0f64, 0.0, 0.0, 0.0];
        let mut poses = vec![0.0];
        poses.extend(q);
        poses.push(5.0);
        poses.extend([0.0; 4]); // free: ignored
        poses.push(9.0);
        poses.extend(q.map(|v| -v)); // the same rotation, other sign
        let mut out: Vec<f64> = (0..5).flat_map(|f| [f as f64, 0.9, 0.1, 0.0, 0.0]).collect();
        out[1..5].copy_from_slice(&q); // frame 0 is the first key
        let raw = out.clone();
        let keys = KeyLayout { dofs: 5, frames: &frames, key_groups: &[0, 1, 1, 1, 1], quaternions: true };
        hit_keys(keys, &poses, |k, g| k != 1 || g == 0, &mut out, &mut [0.0; 5]);
        assert_eq!(out[2 * 5], 5.0);
        assert_eq!(out[4 * 5], 9.0);
        // The quaternion at the last key is the key's rotation on the output's hemisphere.
        assert_eq!(&out[4 * 5 + 1..5 * 5], &q);
        // Frame 2's quaternion is not pulled to key 1's free values, only halfway to the last key.
        assert!((out[2 * 5 + 1] - (raw[2 * 5 + 1] + 0.5 * 0.1)).abs() < 1e-12);
    }
}
