//! The foot lock between an animator's keys: [`crate::footlock::FootLock`] applied to every
//! interval between two consecutive key frames of a completed motion (local rotations and root
//! positions), the legs refitted to the locked feet and every key frame left as it is.
//!
//! A key-to-key in-betweening model hits its keys but lets the planted feet slide between them.
//! Each interval `a..=b` is a transition from key frame `a` to key frame `b`: its frames are
//! posed by forward kinematics, the lock pins the feet in contact (from their position on
//! key `a` when a contact starts there, on key `b` when it ends there) and lifts dragged feet,
//! and the hip, knee and ankle rotations of each leg are fitted to the locked positions
//! ([`crate::fit`], twist from the completion's own rotations). The root, the rest of the body
//! and the key frames are unchanged, so every key stays hit exactly.
//!
//! [`key_foot_lock`] is the lock's setting for keys: the transitions' defaults (half the slide
//! taken out, dragged feet lifted). What the other settings did on bandai2's keys-only benchmark
//! is in docs/keys-only.md ("The foot lock between the keys").

use crate::footlock::FootLock;
use crate::pipeline::{fit_frames, skeleton_positions_f32};
use glam::{DQuat, DVec3};
use zoo_motion::skeleton::Skeleton;

/// The foot lock for completed keys: [`FootLock::from_skeleton`]'s defaults, the transitions'
/// (`None` for a skeleton without legs).
pub fn key_foot_lock(skeleton: &Skeleton) -> Option<FootLock> {
    FootLock::from_skeleton(&skeleton.names, &skeleton.parents)
}

/// Locks the feet of a completed motion between its keys, in place.
///
/// - `skeleton`, `offsets`: the joints and their local rest offsets (the root's is ignored);
/// - `key_frames`: the key frames, strictly increasing; frames outside the first and last key
///   are left alone, as are intervals with no frame between their keys;
/// - `kept`: per frame, the share of an in-betweening network's correction the fallback
///   towards the curves kept ([`crate::inbetween::Completed::kept`]), or empty (the lock at
///   full strength everywhere). An interval locks its feet with the strength and the lift
///   height scaled by the share at its middle frame, `kept[(a + b) / 2]`, and is left alone
///   where that is 0: an interval handed to the curves stays the curves (on keys 5 frames apart
///   of held-out turns the lock made the curves 1.24x worse in L2P);
/// - `root`: root position per frame; `rot`: local rotations, frames x joints (changed on the
///   legs' hip, knee and ankle joints of the frames between keys).
///
/// Returns the number of frames changed. A skeleton without legs ([`FootLock::from_skeleton`]
/// is `None`) or buffers of the wrong size change nothing.
pub fn lock_feet_between_keys(
    lock: &FootLock,
    skeleton: &Skeleton,
    offsets: &[DVec3],
    key_frames: &[usize],
    kept: &[f64],
    root: &[DVec3],
    rot: &mut [DQuat],
) -> usize {
    let j = skeleton.len();
    let n = root.len();
    if j == 0 || offsets.len() != j || rot.len() != n * j {
        return 0;
    }
    let legs: Vec<usize> = lock.legs.iter().flat_map(|l| [l.hip, l.knee, l.ankle]).filter(|&x| x < j).collect();
    let d = 3 * j;
    let mut positions = Vec::new();
    let mut changed = 0;
    for w in key_frames.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b < a + 2 || b >= n {
            continue;
        }
        let share = kept.get((a + b) / 2).map_or(1.0, |&k| k.clamp(0.0, 1.0));
        if share <= 0.0 {
            continue;
        }
        positions.clear();
        skeleton_positions_f32(skeleton, offsets, &rot[a * j..(b + 1) * j], &root[a..=b], &mut positions);
        let (prev, frames) = positions.split_at_mut(d);
        if share < 1.0 {
            let scaled = FootLock {
                strength: lock.strength * share as f32,
                lift_height: lock.lift_height * share as f32,
                ..lock.clone()
            };
            scaled.apply(prev, frames);
        } else {
            lock.apply(prev, frames);
        }
        let inner = b - a - 1;
        let (fitted, _) = fit_frames(skeleton, offsets, &frames[..inner * d], &rot[(a + 1) * j..b * j]);
        for f in 0..inner {
            for &leg in &legs {
                rot[(a + 1 + f) * j + leg] = fitted[f * j + leg];
            }
        }
        changed += inner;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::{EulerOrder, JointChannels};

    fn legged() -> Skeleton {
        Skeleton {
            names: ["Hips", "Spine", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
            parents: vec![None, Some(0), Some(0), Some(2), Some(3), Some(4)],
            offsets: vec![
                DVec3::ZERO,
                DVec3::new(0.0, 10.0, 0.0),
                DVec3::new(10.0, -5.0, 0.0),
                DVec3::new(0.0, -40.0, 0.0),
                DVec3::new(0.0, -37.0, 0.0),
                DVec3::new(0.0, -5.0, 12.0),
            ],
            end_sites: vec![None; 6],
            channels: vec![JointChannels { position: true, order: EulerOrder::Zxy }; 6],
        }
    }

    fn ankle(s: &Skeleton, root: &[DVec3], rot: &[DQuat], f: usize) -> DVec3 {
        let mut p = Vec::new();
        skeleton_positions_f32(s, &s.offsets, &rot[f * 6..(f + 1) * 6], &root[f..=f], &mut p);
        DVec3::new(p[12] as f64, p[13] as f64, p[14] as f64)
    }

    #[test]
    fn a_foot_planted_on_both_keys_is_held_between_them_and_the_keys_are_kept() {
        let s = legged();
        let mut lock = FootLock::from_skeleton(&s.names, &s.parents).unwrap();
        lock.strength = 1.0;
        // The hips stand still; the planted foot slides out (up to 2.3 cm) and back between the
        // keys at 0, 10 and 20 (a completion's skate); the spine sways.
        let root = vec![DVec3::new(0.0, 87.0, 0.0); 21];
        let mut rot = Vec::new();
        for f in 0..21 {
            let slide = 0.03 * (std::f64::consts::PI * f as f64 / 10.0).sin();
            rot.extend([
                DQuat::IDENTITY,
                DQuat::from_rotation_x(0.01 * f as f64),
                DQuat::from_rotation_z(slide),
                DQuat::IDENTITY,
                DQuat::IDENTITY,
                DQuat::IDENTITY,
            ]);
        }
        let raw = rot.clone();
        let changed = lock_feet_between_keys(&lock, &s, &s.offsets, &[0, 10, 20], &[], &root, &mut rot);
        assert_eq!(changed, 18);
        for key in [0, 10, 20] {
            assert_eq!(rot[key * 6..(key + 1) * 6], raw[key * 6..(key + 1) * 6], "key frame {key} unchanged");
        }
        for f in 0..21 {
            assert_eq!(rot[f * 6..f * 6 + 2], raw[f * 6..f * 6 + 2], "root and spine of frame {f} unchanged");
        }
        let planted = ankle(&s, &root, &raw, 0);
        let (mut before, mut after) = (0.0f64, 0.0f64);
        for f in 1..20 {
            let (a, b) = (ankle(&s, &root, &rot, f), ankle(&s, &root, &raw, f));
            before = before.max(DVec3::new(b.x - planted.x, 0.0, b.z - planted.z).length());
            after = after.max(DVec3::new(a.x - planted.x, 0.0, a.z - planted.z).length());
        }
        assert!(before > 2.0, "the raw foot slides {before}");
        assert!(after < 0.05, "the locked foot moves {after}");
        // The fallback handed the first interval to the curves and kept half of the second:
        // the first is left as it is, the second's slide halved.
        let kept: Vec<f64> = (0..21).map(|f| if f < 10 { 0.0 } else { 0.5 }).collect();
        let mut shared = raw.clone();
        assert_eq!(lock_feet_between_keys(&lock, &s, &s.offsets, &[0, 10, 20], &kept, &root, &mut shared), 9);
        assert_eq!(shared[..10 * 6], raw[..10 * 6]);
        let slide = |r: &[DQuat]| {
            (11..20)
                .map(|f| {
                    let (a, p) = (ankle(&s, &root, r, f), ankle(&s, &root, &raw, 10));
                    DVec3::new(a.x - p.x, 0.0, a.z - p.z).length()
                })
                .fold(0.0f64, f64::max)
        };
        let (half, free) = (slide(&shared), slide(&raw));
        assert!(half > 0.3 * free && half < 0.7 * free, "half the lock: {half} of {free}");
    }

    #[test]
    fn without_legs_or_with_wrong_buffers_nothing_changes() {
        let s = legged();
        let lock = FootLock::from_skeleton(&s.names, &s.parents).unwrap();
        let root = vec![DVec3::new(0.0, 87.0, 0.0); 5];
        let mut rot = vec![DQuat::IDENTITY; 5 * 6 - 1];
        assert_eq!(lock_feet_between_keys(&lock, &s, &s.offsets, &[0, 4], &[], &root, &mut rot), 0);
        let mut rot = vec![DQuat::IDENTITY; 5 * 6];
        assert_eq!(lock_feet_between_keys(&lock, &s, &s.offsets, &[0, 1, 2], &[], &root, &mut rot), 0);
        assert_eq!(lock_feet_between_keys(&lock, &s, &s.offsets, &[0, 9], &[], &root, &mut rot), 0);
    }
}
