//! Training-window augmentations that create motion the data lacks (issue 19, not in the
//! paper): time reversal (walking backwards), left-right mirroring and speed changes, on
//! windows of global joint positions (`frames * 3K`, frame-major, Y up; the layout of
//! [`crate::MotionWindow`]). Each returns a new window; the originals are kept.
//!
//! Written here rather than taken from a crate: they are a few lines each on the project's own
//! position layout, and the mirroring needs the skeleton's naming convention.

use crate::error::{RtnError, RtnResult};

/// The window played backwards: frame `f` becomes frame `frames - 1 - f` (a forward walk
/// becomes a backward walk with the same poses).
pub fn reverse_time(window: &[f32], joints: usize) -> Vec<f32> {
    let d = 3 * joints;
    assert!(d > 0 && window.len().is_multiple_of(d), "a window holds whole frames of {joints} joints");
    window.chunks_exact(d).rev().flatten().copied().collect()
}

/// The left/right partner of every joint, from names: a joint ending in `_L` / `_R`, `.L` /
/// `.R`, `Left` / `Right` (or starting with `Left` / `Right`, e.g. Mixamo's `LeftArm`) is paired
/// with the joint of the same name on the other side; other joints (spine, head) are their own
/// partner. Errors on a sided joint without a partner, naming it.
pub fn mirror_pairs(names: &[String]) -> RtnResult<Vec<usize>> {
    const SIDES: [(&str, &str); 4] = [("_L", "_R"), (".L", ".R"), ("Left", "Right"), ("left", "right")];
    let other = |name: &str| -> Option<String> {
        for (l, r) in SIDES {
            for (a, b) in [(l, r), (r, l)] {
                if let Some(stem) = name.strip_suffix(a) {
                    return Some(format!("{stem}{b}"));
                }
                if let Some(rest) = name.strip_prefix(a) {
                    return Some(format!("{b}{rest}"));
                }
            }
        }
        None
    };
    names
        .iter()
        .enumerate()
        .map(|(j, n)| match other(n) {
            None => Ok(j),
            Some(partner) => names.iter().position(|m| *m == partner).ok_or_else(|| {
                RtnError::Config(format!(
                    "mirroring: joint `{n}` has no partner `{partner}` on the other side; mirroring needs a \
                     skeleton whose left and right joints are named alike (`_L`/`_R`, `.L`/`.R`, `Left`/`Right`)"
                ))
            }),
        })
        .collect()
}

/// Checks that `pairs` (from [`mirror_pairs`]) mirror the hierarchy: the partner of a joint's
/// parent is the parent of its partner, so mirrored bones are bones of the skeleton.
pub fn check_mirror_pairs(pairs: &[usize], parents: &[Option<usize>], names: &[String]) -> RtnResult<()> {
    for (j, &p) in pairs.iter().enumerate() {
        if pairs[p] != j || parents[p].map(|q| pairs[q]) != parents[j] {
            return Err(RtnError::Config(format!(
                "mirroring: joints `{}` and `{}` are named as partners but do not sit at mirrored places of the \
                 hierarchy",
                names[j], names[p]
            )));
        }
    }
    Ok(())
}

/// The window mirrored left-right: every position's x negated (a reflection through the
/// vertical plane x = 0) and each joint's values taken from its partner (`pairs`, from
/// [`mirror_pairs`]), so the left leg of the mirror image is the right leg of the original.
/// Bone lengths are kept and mirroring twice gives the window back.
pub fn mirror(window: &[f32], pairs: &[usize]) -> Vec<f32> {
    let d = 3 * pairs.len();
    assert!(d > 0 && window.len().is_multiple_of(d), "a window holds whole frames of {} joints", pairs.len());
    let mut out = vec![0.0; window.len()];
    for (src, dst) in window.chunks_exact(d).zip(out.chunks_exact_mut(d)) {
        for (j, &p) in pairs.iter().enumerate() {
            dst[3 * j] = -src[3 * p];
            dst[3 * j + 1] = src[3 * p + 1];
            dst[3 * j + 2] = src[3 * p + 2];
        }
    }
    out
}

/// The window played `factor` times faster (0.5: half speed), resampled by linear
/// interpolation of positions: output frame `f` is the window at time `f * factor`. Returns
/// `frames` frames, or `None` when the window is too short for them (`(frames - 1) * factor`
/// beyond its last frame) or the factor is not positive.
pub fn change_speed(window: &[f32], joints: usize, factor: f32, frames: usize) -> Option<Vec<f32>> {
    let d = 3 * joints;
    assert!(d > 0 && window.len().is_multiple_of(d), "a window holds whole frames of {joints} joints");
    let have = window.len() / d;
    if !(factor.is_finite() && factor > 0.0) || frames == 0 || have == 0 {
        return None;
    }
    let last = (frames - 1) as f32 * factor;
    if last > (have - 1) as f32 + 1e-4 {
        return None;
    }
    let mut out = Vec::with_capacity(frames * d);
    for f in 0..frames {
        let t = (f as f32 * factor).min((have - 1) as f32);
        let i = (t.floor() as usize).min(have - 1);
        let w = t - i as f32;
        let a = &window[i * d..(i + 1) * d];
        if w <= 0.0 || i + 1 >= have {
            out.extend_from_slice(a);
        } else {
            let b = &window[(i + 1) * d..(i + 2) * d];
            out.extend(a.iter().zip(b).map(|(x, y)| x + w * (y - x)));
        }
    }
    Some(out)
}

/// On-the-fly augmentation of training windows ([`crate::TrainConfig::augment`]): each
/// window of a training step is, independently, time-reversed with probability `reverse`,
/// mirrored with probability `mirror` and played at a speed drawn from `speed_range` with
/// probability `speed` (in that order, so one window may get several). The epoch keeps its
/// size: augmentation replaces views of the data, it does not add windows, so runs with and
/// without it take the same steps per epoch.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Augment {
    /// Probability of a time-reversed window ([`reverse_time`]).
    pub reverse: f64,
    /// Probability of a mirrored window ([`mirror`]).
    pub mirror: f64,
    /// The mirror partner of every joint ([`mirror_pairs`]); required when `mirror > 0`.
    #[serde(default)]
    pub mirror_pairs: Vec<usize>,
    /// Probability of a speed change ([`change_speed`]).
    pub speed: f64,
    /// Range of the speed factors (uniform; factors the window is too short for are clamped).
    pub speed_range: (f32, f32),
}

impl Augment {
    /// Checks probabilities, the speed range and the mirror pairs of a `joints`-joint skeleton.
    pub fn check(&self, joints: usize) -> RtnResult<()> {
        for (what, p) in [("reverse", self.reverse), ("mirror", self.mirror), ("speed", self.speed)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(RtnError::Config(format!("augmentation probability `{what}` is {p}, not in [0, 1]")));
            }
        }
        let (lo, hi) = self.speed_range;
        if self.speed > 0.0 && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return Err(RtnError::Config(format!("speed range {lo}..{hi} is not a range of positive factors")));
        }
        if self.mirror > 0.0 && (self.mirror_pairs.len() != joints || self.mirror_pairs.iter().any(|&p| p >= joints)) {
            return Err(RtnError::Config(format!(
                "mirroring needs a partner for each of the {joints} joints, got {:?}",
                self.mirror_pairs
            )));
        }
        Ok(())
    }

    /// The window (`frames * 3K` global positions, `frames >= out_frames`) as this step sees
    /// it: `out_frames` frames, augmented by draws of `rng` (three draws, plus one for a speed
    /// factor when a speed change is drawn).
    pub fn apply(
        &self,
        window: &[f32],
        joints: usize,
        out_frames: usize,
        rng: &mut zoo_nn::rng::SplitMix64,
    ) -> Vec<f32> {
        let d = 3 * joints;
        let (r, m, s) = (rng.next_f64(), rng.next_f64(), rng.next_f64());
        let mut w = window.to_vec();
        if r < self.reverse {
            w = reverse_time(&w, joints);
        }
        if m < self.mirror {
            w = mirror(&w, &self.mirror_pairs);
        }
        if s < self.speed {
            let have = w.len() / d;
            let max = have.saturating_sub(1) as f32 / (out_frames.max(2) - 1) as f32;
            let (lo, hi) = self.speed_range;
            let factor = (lo + rng.next_f64() as f32 * (hi - lo)).min(max);
            if let Some(v) = change_speed(&w, joints, factor, out_frames) {
                w = v;
            }
        }
        w.truncate(out_frames * d);
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> Vec<String> {
        ["Hips", "Spine", "UpperLeg_L", "Foot_L", "UpperLeg_R", "Foot_R"].iter().map(|s| s.to_string()).collect()
    }

    const PARENTS: [Option<usize>; 6] = [None, Some(0), Some(0), Some(2), Some(0), Some(4)];

    /// A walking window with distinct left and right legs (6 joints).
    fn window(frames: usize) -> Vec<f32> {
        let mut w = Vec::new();
        for f in 0..frames {
            let t = f as f32 * 0.2;
            let root = [3.0 * f as f32, 90.0 + t.sin(), 0.5 * f as f32];
            let rel = [
                [0.0, 0.0, 0.0],
                [1.0, 20.0, 0.0],
                [10.0, -5.0, 1.0],
                [12.0 + 5.0 * t.sin(), -80.0, 3.0 * t.cos()],
                [-9.0, -5.0, 0.0],
                [-11.0 - 4.0 * t.cos(), -80.0, -2.0 * t.sin()],
            ];
            for r in rel {
                w.extend((0..3).map(|a| root[a] + r[a]));
            }
        }
        w
    }

    fn bone_lengths(w: &[f32], parents: &[Option<usize>]) -> Vec<f32> {
        let d = 3 * parents.len();
        let mut out = Vec::new();
        for fr in w.chunks_exact(d) {
            for (j, p) in parents.iter().enumerate() {
                if let Some(p) = p {
                    let l: f32 = (0..3).map(|a| (fr[3 * j + a] - fr[3 * p + a]).powi(2)).sum::<f32>().sqrt();
                    out.push(l);
                }
            }
        }
        out
    }

    #[test]
    fn pairs_follow_the_names_and_the_hierarchy() {
        let pairs = mirror_pairs(&names()).unwrap();
        assert_eq!(pairs, [0, 1, 4, 5, 2, 3]);
        check_mirror_pairs(&pairs, &PARENTS, &names()).unwrap();
        let mixamo: Vec<String> = ["Hips", "LeftArm", "RightArm"].iter().map(|s| s.to_string()).collect();
        assert_eq!(mirror_pairs(&mixamo).unwrap(), [0, 2, 1]);
        let lonely: Vec<String> = ["Hips", "Foot_L"].iter().map(|s| s.to_string()).collect();
        let err = mirror_pairs(&lonely).unwrap_err().to_string();
        assert!(err.contains("`Foot_L` has no partner `Foot_R`"), "{err}");
        // Partners by name at places that are not mirrored: refused.
        let wrong = [None, Some(0), Some(0), Some(2), Some(0), Some(1)];
        assert!(check_mirror_pairs(&pairs, &wrong, &names()).is_err());
    }

    #[test]
    fn mirroring_twice_is_identity_and_keeps_bone_lengths() {
        let w = window(12);
        let pairs = mirror_pairs(&names()).unwrap();
        let m = mirror(&w, &pairs);
        assert_ne!(m, w);
        assert_eq!(mirror(&m, &pairs), w);
        // Each mirrored bone has the length of its partner bone in the original.
        let (a, b) = (bone_lengths(&w, &PARENTS), bone_lengths(&m, &PARENTS));
        let bones = 5;
        for f in 0..12 {
            let (o, r) = (&a[f * bones..(f + 1) * bones], &b[f * bones..(f + 1) * bones]);
            // bones: Spine, UpperLeg_L, Foot_L, UpperLeg_R, Foot_R
            let partner = [0, 3, 4, 1, 2];
            for (i, &p) in partner.iter().enumerate() {
                assert!((r[i] - o[p]).abs() < 1e-4, "frame {f} bone {i}: {} vs {}", r[i], o[p]);
            }
        }
        // The mirrored left foot is where the right foot was, reflected.
        assert_eq!(m[3 * 3], -w[3 * 5]);
        assert_eq!(m[3 * 3 + 1], w[3 * 5 + 1]);
    }

    #[test]
    fn reversal_reverses_frames_and_twice_is_identity() {
        let w = window(10);
        let r = reverse_time(&w, 6);
        let d = 18;
        assert_eq!(&r[..d], &w[9 * d..]);
        assert_eq!(&r[9 * d..], &w[..d]);
        assert_eq!(reverse_time(&r, 6), w);
        // A forward walk (+x) walks backwards (-x) after reversal, with the same bone lengths.
        assert!(r[9 * d] < r[0]);
        assert_eq!(bone_lengths(&r, &PARENTS).len(), bone_lengths(&w, &PARENTS).len());
    }

    #[test]
    fn on_the_fly_augmentation_draws_each_kind() {
        let w = window(50);
        let pairs = mirror_pairs(&names()).unwrap();
        let aug =
            Augment { reverse: 1.0, mirror: 1.0, mirror_pairs: pairs.clone(), speed: 0.0, speed_range: (1.0, 1.0) };
        aug.check(6).unwrap();
        let mut rng = zoo_nn::rng::SplitMix64::new(3);
        let out = aug.apply(&w, 6, 42, &mut rng);
        assert_eq!(out, mirror(&reverse_time(&w, 6), &pairs)[..42 * 18]);
        let none = Augment { reverse: 0.0, mirror: 0.0, speed: 0.0, ..aug.clone() };
        assert_eq!(none.apply(&w, 6, 42, &mut rng), w[..42 * 18]);
        let fast = Augment { reverse: 0.0, mirror: 0.0, speed: 1.0, speed_range: (2.0, 2.0), ..aug.clone() };
        // 2x is more than 50 frames allow for 42: clamped to 49/41.
        let out = fast.apply(&w, 6, 42, &mut rng);
        assert_eq!(out, change_speed(&w, 6, 49.0 / 41.0, 42).unwrap());
        assert!(Augment { mirror_pairs: vec![], ..aug.clone() }.check(6).is_err());
        assert!(Augment { reverse: 1.5, ..aug }.check(6).is_err());
    }

    #[test]
    fn speed_changes_resample_the_motion() {
        let w = window(50);
        let d = 18;
        // Factor 1 is the window itself.
        assert_eq!(change_speed(&w, 6, 1.0, 50).unwrap(), w);
        // Twice as fast: frame f is frame 2f; the root covers twice the distance per frame.
        let fast = change_speed(&w, 6, 2.0, 25).unwrap();
        assert_eq!(&fast[3 * d..4 * d], &w[6 * d..7 * d]);
        assert!(((fast[d] - fast[0]) - 2.0 * (w[d] - w[0])).abs() < 1e-4);
        // Slower: half frames interpolated.
        let slow = change_speed(&w, 6, 0.5, 50).unwrap();
        for i in 0..d {
            assert!((slow[d + i] - 0.5 * (w[i] + w[d + i])).abs() < 1e-4);
        }
        // Too fast for the frames asked, or a bad factor.
        assert!(change_speed(&w, 6, 1.25, 42).is_none());
        assert!(change_speed(&w, 6, 1.19, 42).is_some());
        assert!(change_speed(&w, 6, 0.0, 42).is_none());
        assert!(change_speed(&w, 6, f32::NAN, 42).is_none());
    }
}
