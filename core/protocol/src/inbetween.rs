//! The inputs of the key-to-key in-betweening network (the candle model is
//! `zoo_arnn::inbetween`, the exported graph runs in the runtime's keyframes task): per frame of
//! a shot, features built from an animator's keys around Blender's default F-curves through them
//! ([`crate::fcurve::bezier_inbetween`]), and the envelope that scales the network's correction
//! so that every key is met by construction. Training, `zoo complete`, the keys-only benchmark
//! and the engine runtime all build them here, so they agree value for value.
//!
//! Poses are the humanoid pose vector: the root position, then one quaternion `(w, x, y, z)`
//! per joint, `d = 3 + 4 J` values. Key groups: group 0 is the root position, group `1 + j`
//! joint `j`'s rotation. Per frame `t` of a shot (frames `0..=last key`) the features are, in
//! order (`3 d + 2 + 2 (1 + J)` values, f32):
//! - `(b_t - mean) / std`, the Bezier pose normalised;
//! - `(k-_t - b_t) / std` and `(k+_t - b_t) / std`: per value, the previous key fixing its
//!   group (at or before `t`) and the next one (after `t`), minus the Bezier pose (a key's
//!   quaternion taken with the sign nearest the Bezier one);
//! - the phase `s_t = (t - t-) / (t+ - t-)` and the gap `(t+ - t-) / gap_unit` of the keys
//!   fixing the root;
//! - per group, 1 where a key fixes it at `t`, and its envelope `e_g(t) = 4 s (1 - s)` (`s` the
//!   phase between the keys fixing the group; 0 on them and outside them).
//!
//! The completed pose is `b_t + r_t * std` ([`InbetweenFeatures::compose`], f64), the residual
//! `r` made from the network's output `c` so that it is zero on every key frame fixing a value
//! ([`Residual`]): `e(t) c_t` (`e` per value its group's envelope) or `c_t` minus the straight
//! line through `c` on the keys around `t` fixing the value.

use crate::fcurve::{ShotKeys, bezier_inbetween};
use glam::{DQuat, DVec3};
use zoo_motion::euler::EulerOrder;

/// Keys or settings the features cannot be built from, said in words with the fix.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct InbetweenError(pub String);

/// How the network's correction `c` becomes the residual `r` added to the Bezier pose, zero on
/// every key frame fixing a value so that the keys are met by construction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Residual {
    /// `r = e(t) c(t)`, the envelope `4 s (1 - s)` of the value's phase `s` between the keys
    /// fixing it. Smooth through a key only where `c` changes sign there: with a correction
    /// that does not, the motion has a kink on every key.
    #[default]
    Envelope,
    /// `r = c(t) - ((1 - s) c(t-) + s c(t+))`: the correction minus the straight line through
    /// its own values on the keys `t-` and `t+` fixing the value. Smooth through a key wherever
    /// the correction's values on the neighbouring keys lie on a line (e.g. are zero).
    KeyLerp,
}

/// What a shot's features depend on besides its keys: the skeleton's Euler orders (the F-curves
/// are drawn on these channels, as Blender draws them), the gap unit and the pose statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct InbetweenFeatures {
    /// Each joint's Euler channel order.
    pub orders: Vec<EulerOrder>,
    /// Frames the gap feature is divided by.
    pub gap_unit: f64,
    /// Mean per pose value (`d` values).
    pub mean: Vec<f64>,
    /// Standard deviation per pose value (`d` values, positive).
    pub std: Vec<f64>,
    /// How the correction is made zero on the keys.
    pub residual: Residual,
}

/// One shot's features and its Bezier poses.
#[derive(Clone, Debug, PartialEq)]
pub struct ShotInputs {
    /// Frames of the shot (`0..=last key`).
    pub frames: usize,
    /// Features, frames x [`InbetweenFeatures::input_width`].
    pub features: Vec<f32>,
    /// The Bezier pose of each frame in clip units, frames x d.
    pub bezier: Vec<f64>,
    /// The envelope of each value, frames x d (0 on a key frame fixing its group).
    pub envelope: Vec<f64>,
    /// Per frame and value (frames x d), the frames of the keys fixing the value before `t` (at
    /// or before it) and after it, and the phase between them ([`Residual::KeyLerp`]); `(t, t,
    /// 0)` on those keys, before the first and after the last, where the residual is zero.
    pub lerp: Vec<(u32, u32, f64)>,
    /// The shot's key frames (from 0, increasing), whole or partial.
    pub keys: Vec<usize>,
    /// Per key, whether it fixes every group (a whole key).
    pub whole: Vec<bool>,
}

/// The fallback towards the curves through the keys (not in any paper): an interval between
/// keys whose network correction is larger than the corrections it made on in-distribution
/// validation shots with keys as far apart is blended back towards the Bezier curves, which
/// meet the same keys.
///
/// The confidence signal is computed from the inputs only: per interval between two consecutive
/// key frames at least two frames apart, both whole keys, the root mean square of the residual
/// `r` (normalised units, every pose value, the frames strictly between the keys;
/// [`InbetweenFeatures::interval_sizes`]). Each interval's size gives a weight `w` in `[0, 1]`
/// from the thresholds of its gap (0 below `start`, 1 from `full` on, linear between). The
/// completed pose is `b + k(t) r std` with `k = 1 - w` at the middle of each interval, on a key
/// frame the smaller `k` of the two intervals it joins, and linear between ([`Fallback::kept`]):
/// the keys are still met by construction and the motion stays continuous.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fallback {
    /// Thresholds per range of gaps, by increasing `up_to`: an interval of `n` frames uses the
    /// first entry with `n <= up_to`, the last one beyond them all.
    pub gaps: Vec<GapFallback>,
}

/// The fallback's thresholds for intervals of at most `up_to` frames (and more than the
/// previous entry's).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GapFallback {
    /// The longest interval (frames from key to key) these thresholds are for.
    pub up_to: usize,
    /// Correction size (normalised RMS) from which the interval is blended towards the curves.
    pub start: f32,
    /// Size from which the interval is the curves.
    pub full: f32,
}

impl GapFallback {
    /// Thresholds under which every interval of at most `up_to` frames is the curves: `start`
    /// 0 and `full` 1e-6 (a range where the network is not used).
    pub fn curves(up_to: usize) -> Self {
        GapFallback { up_to, start: 0.0, full: 1e-6 }
    }
}

impl Fallback {
    /// Checks the thresholds: at least one range, `up_to` strictly increasing, every `start`
    /// finite and at least 0, every `full` above its `start`.
    pub fn check(&self) -> Result<(), InbetweenError> {
        if self.gaps.is_empty() || self.gaps.windows(2).any(|w| w[0].up_to >= w[1].up_to) {
            return Err(InbetweenError(
                "the fallback needs at least one range of gaps, their up_to strictly increasing".into(),
            ));
        }
        if let Some(g) = self.gaps.iter().find(|g| !(g.start.is_finite() && g.start >= 0.0 && g.full > g.start)) {
            return Err(InbetweenError(format!(
                "fallback thresholds start {} and full {} (gaps up to {} frames): start must be finite and at least 0, \
                 full above start",
                g.start, g.full, g.up_to
            )));
        }
        Ok(())
    }

    /// The thresholds for an interval of `gap` frames.
    pub fn thresholds(&self, gap: usize) -> GapFallback {
        *self.gaps.iter().find(|g| gap <= g.up_to).or(self.gaps.last()).expect("checked: at least one range")
    }

    /// The weight towards the curves of an interval of `gap` frames whose correction has `size`.
    pub fn weight(&self, gap: usize, size: f32) -> f32 {
        let t = self.thresholds(gap);
        if !size.is_finite() {
            return 1.0;
        }
        ((size - t.start) / (t.full - t.start)).clamp(0.0, 1.0)
    }

    /// The largest weight of a shot's intervals ([`InbetweenFeatures::interval_sizes`]).
    pub fn shot_weight(&self, sizes: &[IntervalSize]) -> f32 {
        sizes.iter().map(|i| self.weight(i.gap(), i.size)).fold(0.0, f32::max)
    }

    /// The share `k(t)` of the residual kept on each of a shot's `frames` frames, from its
    /// intervals' sizes: `1 - w` at the middle of an interval, on a key frame the smaller of the
    /// two intervals' (1 for an interval without frames between its keys), linear between.
    pub fn kept(&self, frames: usize, sizes: &[IntervalSize]) -> Vec<f64> {
        let mut kept = vec![1.0f64; frames];
        let mut edge = vec![1.0f64; frames];
        let own: Vec<f64> = sizes.iter().map(|i| 1.0 - self.weight(i.gap(), i.size) as f64).collect();
        for (i, &k) in sizes.iter().zip(&own) {
            for f in [i.from, i.to] {
                if f < frames {
                    edge[f] = edge[f].min(k);
                }
            }
        }
        for (i, &k) in sizes.iter().zip(&own) {
            let n = i.gap() as f64;
            for t in i.from..=i.to.min(frames.saturating_sub(1)) {
                let s = (t - i.from) as f64 / n;
                kept[t] = if s <= 0.5 {
                    edge[i.from] + (k - edge[i.from]) * 2.0 * s
                } else {
                    edge[i.to] + (k - edge[i.to]) * 2.0 * (1.0 - s)
                };
            }
        }
        kept
    }

    /// Thresholds from the intervals of in-distribution shots: per range of gaps of
    /// [`FALLBACK_GAP_RANGES`] holding at least [`FALLBACK_MIN_INTERVALS`] of them, `start` at
    /// their sizes' `quantile` (nearest rank) and `full` at `factor` times it (at least 1e-6
    /// above); `None` when no range has enough.
    pub fn calibrate(sizes: &[IntervalSize], quantile: f64, factor: f32) -> Option<Fallback> {
        let mut gaps = Vec::new();
        let mut low = 0;
        for &up_to in FALLBACK_GAP_RANGES {
            let range: Vec<(usize, f32)> = sizes
                .iter()
                .map(|i| (i.gap(), i.size))
                .filter(|(g, s)| *g > low && *g <= up_to && s.is_finite())
                .collect();
            low = up_to;
            if range.len() < FALLBACK_MIN_INTERVALS {
                continue;
            }
            let mut v: Vec<f32> = range.iter().map(|(_, s)| *s).collect();
            v.sort_by(f32::total_cmp);
            let start = v[((v.len() - 1) as f64 * quantile.clamp(0.0, 1.0)).round() as usize].max(0.0);
            // The open range ends at its longest interval (the last range covers longer ones).
            let longest = range.iter().map(|(g, _)| *g).max().unwrap_or(up_to);
            gaps.push(GapFallback { up_to: up_to.min(longest), start, full: (start * factor).max(start + 1e-6) });
        }
        (!gaps.is_empty()).then_some(Fallback { gaps })
    }
}

/// The ranges of gaps (frames from key to key, upper bounds) the fallback is calibrated on:
/// around the keys-only benchmark's spacings (5, 10, 15, 20, 30) and the transition benchmark's
/// gaps (6, 16, 31, 46 frames from the last context frame to the target; keys 5 frames apart
/// and transitions of 5 frames fall in ranges of their own).
pub const FALLBACK_GAP_RANGES: &[usize] = &[5, 7, 12, 17, 25, 37, usize::MAX];

/// Intervals a range of gaps needs for its own thresholds.
pub const FALLBACK_MIN_INTERVALS: usize = 20;

/// The [`Fallback`]'s signal on one interval between consecutive key frames `from < to`: the
/// root mean square `size` of the residual over the frames strictly between them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntervalSize {
    /// The interval's first key frame.
    pub from: usize,
    /// Its last key frame.
    pub to: usize,
    /// The residual's root mean square (normalised units).
    pub size: f32,
}

impl IntervalSize {
    /// Frames from key to key.
    pub fn gap(&self) -> usize {
        self.to - self.from
    }
}

/// Values per pose of `joints` joints, `3 + 4 J`.
pub fn dofs(joints: usize) -> usize {
    3 + 4 * joints
}

/// The key group of each pose value of `joints` joints: 0 for the root position, `1 + j` for
/// joint `j`'s quaternion.
pub fn key_groups(joints: usize) -> Vec<usize> {
    let mut groups = vec![0, 0, 0];
    groups.extend((0..joints).flat_map(|j| [1 + j; 4]));
    groups
}

/// The root position and unit rotations of a pose (a quaternion of length 0 is the identity).
pub fn decode_pose(pose: &[f64], joints: usize) -> (DVec3, Vec<DQuat>) {
    let root = DVec3::new(pose[0], pose[1], pose[2]);
    let rot = (0..joints)
        .map(|j| {
            let v = &pose[3 + 4 * j..7 + 4 * j];
            let q = DQuat::from_xyzw(v[1], v[2], v[3], v[0]);
            if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY }
        })
        .collect();
    (root, rot)
}

/// A pose vector (root position, quaternions `w, x, y, z`) of a root and rotations.
pub fn pose_values(root: DVec3, rot: &[DQuat]) -> Vec<f64> {
    let mut v = Vec::with_capacity(dofs(rot.len()));
    v.extend([root.x, root.y, root.z]);
    for q in rot {
        v.extend([q.w, q.x, q.y, q.z]);
    }
    v
}

/// The index of the previous key fixing a group (at or before `t`) and of the next one (after
/// `t`; the previous one at or after the last), of the group's keys `(index, frame)`; `None`
/// before the first.
fn around(keys: &[(usize, usize)], t: usize) -> Option<((usize, usize), (usize, usize))> {
    let i = keys.partition_point(|(_, f)| *f <= t);
    if i == 0 {
        return None;
    }
    Some((keys[i - 1], keys.get(i).copied().unwrap_or(keys[i - 1])))
}

/// The envelope `4 s (1 - s)` at frame `t` between keys at frames `a` and `c` (0 when `a == c`).
fn envelope(a: usize, c: usize, t: usize) -> f64 {
    if c <= a {
        return 0.0;
    }
    let s = (t - a) as f64 / (c - a) as f64;
    4.0 * s * (1.0 - s)
}

/// A key's value `i` (of pose `key`) for a frame whose Bezier pose is `bez`: quaternions take
/// the sign nearest the Bezier one.
fn key_value(key: &[f64], bez: &[f64], i: usize) -> f64 {
    if i < 3 {
        return key[i];
    }
    let q = 3 + 4 * ((i - 3) / 4);
    let dot: f64 = (q..q + 4).map(|k| key[k] * bez[k]).sum();
    if dot < 0.0 { -key[i] } else { key[i] }
}

impl InbetweenFeatures {
    /// Joints.
    pub fn joints(&self) -> usize {
        self.orders.len()
    }

    /// Values per pose, `3 + 4 J`.
    pub fn dofs(&self) -> usize {
        dofs(self.joints())
    }

    /// Key groups, `1 + J`.
    pub fn groups(&self) -> usize {
        1 + self.joints()
    }

    /// Values per frame of the features, `3 d + 2 + 2 (1 + J)`.
    pub fn input_width(&self) -> usize {
        3 * self.dofs() + 2 + 2 * self.groups()
    }

    /// Checks the settings: at least one joint, a positive gap unit, `d` finite means and `d`
    /// positive standard deviations.
    pub fn check(&self) -> Result<(), InbetweenError> {
        let d = self.dofs();
        let bad = |m: String| Err(InbetweenError(m));
        if self.orders.is_empty() {
            return bad("the in-betweening features need at least one joint (one Euler order)".into());
        }
        if !(self.gap_unit.is_finite() && self.gap_unit > 0.0) {
            return bad(format!("gap_unit is {}: a positive number of frames is needed", self.gap_unit));
        }
        if self.mean.len() != d || self.std.len() != d {
            return bad(format!(
                "{} means and {} standard deviations for poses of {d} values ({} joints): one of each per value",
                self.mean.len(),
                self.std.len(),
                self.joints()
            ));
        }
        if let Some(i) = self.mean.iter().position(|m| !m.is_finite()) {
            return bad(format!("mean {i} is {}: every mean must be finite", self.mean[i]));
        }
        if let Some(i) = self.std.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
            return bad(format!("standard deviation {i} is {}: every one must be positive", self.std[i]));
        }
        Ok(())
    }

    /// Checks a shot's keys: frames from 0 strictly increasing, at least two; `poses` one pose
    /// of `d` finite values per key (key-major); `fixed` empty (whole keys) or one row of
    /// `1 + J` group flags per key, every group fixed by some key.
    pub fn check_keys(&self, frames: &[usize], poses: &[f64], fixed: &[bool]) -> Result<(), InbetweenError> {
        let (d, g, n) = (self.dofs(), self.groups(), frames.len());
        let bad = |m: String| Err(InbetweenError(m));
        if n < 2 || frames[0] != 0 || frames.windows(2).any(|w| w[0] >= w[1]) {
            return bad(format!("key frames {frames:?}: at least two, from frame 0, strictly increasing"));
        }
        if poses.len() != n * d {
            return bad(format!(
                "{n} key frames need as many poses of {d} values ({} values), got {} values",
                n * d,
                poses.len()
            ));
        }
        if let Some(i) = poses.iter().position(|v| !v.is_finite()) {
            return bad(format!("key {} value {} is {}: every key value must be finite", i / d, i % d, poses[i]));
        }
        if !fixed.is_empty() {
            if fixed.len() != n * g {
                return bad(format!("partial keys need one row of {g} group flags per key ({} flags)", n * g));
            }
            if let Some(missing) = (0..g).find(|&k| !(0..n).any(|key| fixed[key * g + k])) {
                return bad(format!(
                    "no key fixes group {missing} (0 is the root, 1 + j joint j): key it at least once"
                ));
            }
        }
        Ok(())
    }

    /// The features and the Bezier poses of a shot: keys at `frames` (from 0) with poses
    /// `poses` (key-major, the humanoid pose layout, clip units) fixing the groups `fixed`
    /// (key-major, `1 + J` per key; empty: whole keys). The settings are assumed checked
    /// ([`InbetweenFeatures::check`]).
    pub fn shot(&self, frames: &[usize], poses: &[f64], fixed: &[bool]) -> Result<ShotInputs, InbetweenError> {
        self.check_keys(frames, poses, fixed)?;
        let (j, d, g) = (self.joints(), self.dofs(), self.groups());
        let key = |k: usize| &poses[k * d..(k + 1) * d];
        let mut roots = Vec::with_capacity(frames.len());
        let mut rots = Vec::with_capacity(frames.len() * j);
        for k in 0..frames.len() {
            let (r, q) = decode_pose(key(k), j);
            roots.push(r);
            rots.extend(q);
        }
        let rows: Vec<Vec<bool>> = fixed.chunks(g).map(<[bool]>::to_vec).collect();
        let keys = ShotKeys { frames, root: &roots, rot: &rots, fixed: &rows };
        let (broot, brot) = bezier_inbetween(&self.orders, &keys)
            .ok_or_else(|| InbetweenError(format!("keys at frames {frames:?} do not make F-curves")))?;
        let n = broot.len();
        let bezier: Vec<f64> = (0..n).flat_map(|f| pose_values(broot[f], &brot[f * j..(f + 1) * j])).collect();
        let fixes = |k: usize, gr: usize| fixed.is_empty() || fixed[k * g + gr];
        let per_group: Vec<Vec<(usize, usize)>> =
            (0..g).map(|gr| (0..frames.len()).filter(|&k| fixes(k, gr)).map(|k| (k, frames[k])).collect()).collect();
        let groups = key_groups(j);
        let mut features = Vec::with_capacity(n * self.input_width());
        let mut env = vec![0.0f64; n * d];
        let mut lerp = vec![(0u32, 0u32, 0.0f64); n * d];
        let mut group_env = vec![0.0f64; g];
        let mut prev = vec![0.0f64; d];
        let mut next = vec![0.0f64; d];
        for t in 0..n {
            let bez = &bezier[t * d..(t + 1) * d];
            for (gr, keys) in per_group.iter().enumerate() {
                group_env[gr] = around(keys, t).map_or(0.0, |((_, a), (_, c))| envelope(a, c, t));
            }
            for i in 0..d {
                let (a, c) = match around(&per_group[groups[i]], t) {
                    Some(((a, _), (c, _))) => (a, c),
                    None => (per_group[groups[i]][0].0, per_group[groups[i]][0].0),
                };
                prev[i] = key_value(key(a), bez, i) - bez[i];
                next[i] = key_value(key(c), bez, i) - bez[i];
                env[t * d + i] = group_env[groups[i]];
                lerp[t * d + i] = match around(&per_group[groups[i]], t) {
                    Some(((_, fa), (_, fc))) if fc > fa && t > fa => {
                        (fa as u32, fc as u32, (t - fa) as f64 / (fc - fa) as f64)
                    }
                    _ => (t as u32, t as u32, 0.0),
                };
            }
            features.extend(bez.iter().zip(&self.mean).zip(&self.std).map(|((v, m), s)| ((v - m) / s) as f32));
            features.extend(prev.iter().zip(&self.std).map(|(v, s)| (v / s) as f32));
            features.extend(next.iter().zip(&self.std).map(|(v, s)| (v / s) as f32));
            let ((_, a), (_, c)) = around(&per_group[0], t).unwrap_or(((0, 0), (0, 0)));
            let phase = if c > a { (t - a) as f64 / (c - a) as f64 } else { 0.0 };
            features.push(phase as f32);
            features.push(((c - a) as f64 / self.gap_unit) as f32);
            features.extend((0..g).map(|gr| if per_group[gr].iter().any(|(_, f)| *f == t) { 1.0f32 } else { 0.0 }));
            features.extend(group_env.iter().map(|&e| e as f32));
        }
        let whole = (0..frames.len()).map(|k| (0..g).all(|gr| fixes(k, gr))).collect();
        Ok(ShotInputs { frames: n, features, bezier, envelope: env, lerp, keys: frames.to_vec(), whole })
    }

    /// The residual of value `x` (flat index, frame-major) of a shot from the network's
    /// correction (normalised units, frames x d; [`Residual`]): zero on every key frame fixing
    /// the value.
    pub fn residual(&self, shot: &ShotInputs, correction: &[f32], x: usize) -> f64 {
        let d = self.dofs();
        match self.residual {
            Residual::Envelope => shot.envelope[x] * correction[x] as f64,
            Residual::KeyLerp => {
                let (a, c, s) = shot.lerp[x];
                let v = x % d;
                let (ya, yc) = (correction[a as usize * d + v] as f64, correction[c as usize * d + v] as f64);
                correction[x] as f64 - (ya + s * (yc - ya))
            }
        }
    }

    /// The completed value `x` (flat index, frame-major) of a shot from the network's correction
    /// (normalised units, frames x d): `b + r * std` ([`Residual`]), in f64, so that a value
    /// equals its Bezier value, and so its key, on every key frame fixing it.
    pub fn compose(&self, shot: &ShotInputs, correction: &[f32], x: usize) -> f64 {
        self.compose_kept(shot, correction, x, 1.0)
    }

    /// [`InbetweenFeatures::compose`] with the residual scaled by `kept` (the
    /// [`Fallback::kept`] share of the value's frame): `b + kept * r * std`.
    pub fn compose_kept(&self, shot: &ShotInputs, correction: &[f32], x: usize, kept: f64) -> f64 {
        shot.bezier[x] + kept * self.residual(shot, correction, x) * self.std[x % self.dofs()]
    }

    /// The [`Fallback`]'s signal: per interval between consecutive whole keys at least two
    /// frames apart, the root mean square of the residual over the frames strictly between the
    /// keys and every pose value (normalised units). An interval next to a partial key has
    /// none: the fallback is calibrated on whole keys, and between partial keys the network
    /// fills the free joints from keys far apart, where the curves are much worse.
    pub fn interval_sizes(&self, shot: &ShotInputs, correction: &[f32]) -> Vec<IntervalSize> {
        let d = self.dofs();
        (0..shot.keys.len().saturating_sub(1))
            .filter(|&k| shot.whole[k] && shot.whole[k + 1])
            .map(|k| [shot.keys[k], shot.keys[k + 1]])
            .filter(|w| w[1] - w[0] >= 2 && w[1] < shot.frames)
            .map(|w| {
                let xs = (w[0] + 1) * d..w[1] * d;
                let n = xs.len() as f64;
                let sum: f64 = xs.map(|x| self.residual(shot, correction, x).powi(2)).sum();
                IntervalSize { from: w[0], to: w[1], size: (sum / n).sqrt() as f32 }
            })
            .collect()
    }

    /// The completed shot from the network's correction, with the `fallback` when given.
    pub fn complete(&self, shot: &ShotInputs, correction: &[f32], fallback: Option<&Fallback>) -> Completed {
        let d = self.dofs();
        let (kept, weight) = match fallback {
            Some(f) => {
                let sizes = self.interval_sizes(shot, correction);
                (f.kept(shot.frames, &sizes), f.shot_weight(&sizes))
            }
            None => (vec![1.0; shot.frames], 0.0),
        };
        let poses = (0..shot.frames * d).map(|x| self.compose_kept(shot, correction, x, kept[x / d])).collect();
        Completed { poses, weight, kept }
    }
}

/// A shot completed by [`InbetweenFeatures::complete`].
#[derive(Clone, Debug, PartialEq)]
pub struct Completed {
    /// The poses, frames x d, clip units.
    pub poses: Vec<f64>,
    /// The largest weight towards the curves of the shot's intervals (0 without a fallback).
    pub weight: f32,
    /// The share of the network's residual kept on each frame ([`Fallback::kept`]; all 1
    /// without a fallback): the foot lock between the keys is scaled by it
    /// ([`crate::keylock::lock_feet_between_keys`]), so that where the fallback hands an
    /// interval to the curves, the output is the curves as they are drawn.
    pub kept: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features() -> InbetweenFeatures {
        InbetweenFeatures {
            orders: vec![EulerOrder::Zxy; 3],
            gap_unit: 30.0,
            mean: vec![0.0; 15],
            std: vec![0.5; 15],
            residual: Residual::Envelope,
        }
    }

    fn keys() -> (Vec<usize>, Vec<f64>) {
        let frames = vec![0, 7, 15, 20];
        let poses = frames
            .iter()
            .flat_map(|&f| {
                let a = f as f64 * 0.1;
                let rot = [DQuat::from_rotation_y(a), DQuat::from_rotation_x(-a), DQuat::from_rotation_z(0.5 * a)];
                pose_values(DVec3::new(f as f64, 90.0, 0.5 * f as f64), &rot)
            })
            .collect();
        (frames, poses)
    }

    #[test]
    fn features_have_the_documented_width_envelope_and_flags() {
        let f = features();
        let (frames, poses) = keys();
        let (d, w) = (f.dofs(), f.input_width());
        assert_eq!((d, f.groups(), w), (15, 4, 3 * 15 + 2 + 8));
        let s = f.shot(&frames, &poses, &[]).unwrap();
        assert_eq!((s.frames, s.features.len(), s.envelope.len()), (21, 21 * w, 21 * d));
        for &k in &frames {
            assert!(s.envelope[k * d..(k + 1) * d].iter().all(|&e| e == 0.0));
            // A key frame: every group flagged, and the Bezier pose is the key.
            assert!(s.features[k * w + 3 * d + 2..k * w + 3 * d + 6].iter().all(|&v| v == 1.0));
        }
        // Midway between keys 7 and 15 (frame 11) the envelope peaks at 1, the phase is 1/2 and
        // the gap 8 frames.
        assert!((s.envelope[11 * d] - 1.0).abs() < 1e-12);
        assert_eq!(&s.features[11 * w + 3 * d..11 * w + 3 * d + 2], &[0.5, (8.0 / 30.0) as f32]);
        // Composed with any correction, every key frame is its key.
        let correction: Vec<f32> = (0..21 * d).map(|i| (i % 7) as f32 - 3.0).collect();
        for (k, &frame) in frames.iter().enumerate() {
            for i in 0..3 {
                let v = f.compose(&s, &correction, frame * d + i);
                assert!((v - poses[k * d + i]).abs() < 1e-9, "key {k} value {i}: {v}");
            }
        }
    }

    #[test]
    fn partial_keys_leave_free_groups_to_the_curves_through_the_others() {
        let f = features();
        let (frames, poses) = keys();
        let g = f.groups();
        // Key 1 leaves joint 1 (group 2) free, key 2 the root.
        let mut fixed = vec![true; 4 * g];
        fixed[g + 2] = false;
        fixed[2 * g] = false;
        let s = f.shot(&frames, &poses, &fixed).unwrap();
        let d = f.dofs();
        // The root's envelope runs from key 1 (frame 7) to key 3 (frame 20) past the free key.
        assert!(s.envelope[15 * d] > 0.0 && s.envelope[15 * d + 7] == 0.0);
        let whole = f.shot(&frames, &poses, &[]).unwrap();
        assert_ne!(s.features, whole.features);
    }

    #[test]
    fn both_residuals_meet_the_keys_and_the_key_line_removes_straight_corrections() {
        let (frames, poses) = keys();
        let partial: Vec<bool> = (0..4).flat_map(|k| [true, k != 1, true, k != 2]).collect();
        for fixed in [vec![], partial] {
            for residual in [Residual::Envelope, Residual::KeyLerp] {
                let f = InbetweenFeatures { residual, ..features() };
                let s = f.shot(&frames, &poses, &fixed).unwrap();
                let d = f.dofs();
                // A correction that is nowhere zero, varying per frame and value.
                let wavy: Vec<f32> = (0..s.frames * d).map(|x| 1.0 + ((x * 7 % 13) as f32) * 0.1).collect();
                let g = f.groups();
                let groups = key_groups(f.joints());
                for (k, &t) in frames.iter().enumerate() {
                    for v in 0..d {
                        if fixed.is_empty() || fixed[k * g + groups[v]] {
                            let x = t * d + v;
                            assert_eq!(f.compose(&s, &wavy, x), s.bezier[x], "{residual:?} key {k} value {v}");
                        }
                    }
                }
                // A correction that is a straight line in time leaves the curve unchanged with
                // the key line (it is its own line through the keys); the envelope keeps it.
                let line: Vec<f32> = (0..s.frames * d).map(|x| 0.3 + 0.05 * (x / d) as f32).collect();
                let moved =
                    (0..s.frames * d).map(|x| (f.compose(&s, &line, x) - s.bezier[x]).abs()).fold(0.0, f64::max);
                match residual {
                    Residual::KeyLerp => assert!(moved < 1e-6, "{moved}"),
                    Residual::Envelope => assert!(moved > 0.1, "{moved}"),
                }
            }
        }
    }

    #[test]
    fn bad_keys_and_settings_are_refused() {
        let f = features();
        let (frames, poses) = keys();
        let err = |r: Result<ShotInputs, InbetweenError>| r.unwrap_err().to_string();
        assert!(err(f.shot(&[1, 7, 15, 20], &poses, &[])).contains("from frame 0"));
        assert!(err(f.shot(&[0], &poses[..15], &[])).contains("at least two"));
        assert!(err(f.shot(&frames, &poses[..45], &[])).contains("got 45 values"));
        let mut nan = poses.clone();
        nan[3] = f64::NAN;
        assert!(err(f.shot(&frames, &nan, &[])).contains("key 0 value 3 is NaN"));
        let mut none_fix = vec![true; 16];
        for k in 0..4 {
            none_fix[k * 4 + 2] = false;
        }
        assert!(err(f.shot(&frames, &poses, &none_fix)).contains("no key fixes group 2"));
        assert!(err(f.shot(&frames, &poses, &none_fix[..15])).contains("16 flags"));
        assert!(InbetweenFeatures { std: vec![0.0; 15], ..f.clone() }.check().unwrap_err().0.contains("positive"));
        assert!(InbetweenFeatures { mean: vec![0.0; 14], ..f.clone() }.check().is_err());
        assert!(InbetweenFeatures { gap_unit: 0.0, ..f.clone() }.check().is_err());
        assert!(InbetweenFeatures { orders: vec![], ..f }.check().is_err());
    }

    #[test]
    fn pose_layout_helpers_agree() {
        assert_eq!(key_groups(2), vec![0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2]);
        let rot = [DQuat::from_rotation_y(0.3), DQuat::IDENTITY];
        let v = pose_values(DVec3::new(1.0, 2.0, 3.0), &rot);
        let (root, back) = decode_pose(&v, 2);
        assert_eq!(root, DVec3::new(1.0, 2.0, 3.0));
        assert!(back[0].abs_diff_eq(rot[0], 1e-15) && back[1] == DQuat::IDENTITY);
        // A zero quaternion decodes to the identity.
        assert_eq!(decode_pose(&[0.0; 7], 1).1[0], DQuat::IDENTITY);
    }

    fn fallback() -> Fallback {
        Fallback {
            gaps: vec![
                GapFallback { up_to: 7, start: 0.1, full: 0.2 },
                GapFallback { up_to: 16, start: 0.5, full: 1.0 },
            ],
        }
    }

    #[test]
    fn the_fallback_weighs_each_interval_by_its_gaps_thresholds() {
        let f = fallback();
        f.check().unwrap();
        // Gaps up to 7 use the first thresholds, longer ones the second, beyond 16 the last.
        assert_eq!(f.weight(5, 0.05), 0.0);
        assert!((f.weight(5, 0.15) - 0.5).abs() < 1e-6);
        assert_eq!(f.weight(7, 0.3), 1.0);
        assert_eq!(f.weight(8, 0.3), 0.0);
        assert!((f.weight(40, 0.75) - 0.5).abs() < 1e-6);
        assert_eq!(f.weight(10, f32::NAN), 1.0);
        let bad = |gaps: Vec<GapFallback>| Fallback { gaps }.check().unwrap_err().0;
        assert!(bad(vec![]).contains("at least one range"));
        assert!(bad(vec![GapFallback { up_to: 5, start: 0.2, full: 0.2 }]).contains("full above start"));
        assert!(bad(vec![GapFallback { up_to: 5, start: f32::NAN, full: 1.0 }]).contains("finite"));
        let mut twice = fallback();
        twice.gaps[1].up_to = 7;
        assert!(twice.check().is_err());
    }

    #[test]
    fn the_kept_share_is_the_intervals_at_their_middles_the_smaller_on_keys_and_continuous() {
        let f = fallback();
        // Keys at 0, 4, 12 and 20: the first interval in range, the second at weight 1/2, the
        // third fully fallen back.
        let sizes = [
            IntervalSize { from: 0, to: 4, size: 0.05 },
            IntervalSize { from: 4, to: 12, size: 0.75 },
            IntervalSize { from: 12, to: 20, size: 2.0 },
        ];
        assert_eq!(f.shot_weight(&sizes), 1.0);
        let k = f.kept(21, &sizes);
        assert_eq!(k[0], 1.0);
        // The first interval keeps all at its middle and ramps to the next one's 1/2 on key 4.
        assert_eq!((k[2], k[3]), (1.0, 0.75), "{k:?}");
        assert_eq!((k[4], k[8], k[12], k[16], k[20]), (0.5, 0.5, 0.0, 0.0, 0.0));
        // Never more than the interval's own share, and no jump larger than a linear ramp's.
        assert!(k[5..12].iter().all(|&v| v <= 0.5) && k[13..].iter().all(|&v| v == 0.0));
        assert!(k.windows(2).all(|w| (w[1] - w[0]).abs() <= 0.25 + 1e-12), "{k:?}");
    }

    #[test]
    fn a_shot_fallen_back_is_the_curves_and_keeps_its_keys() {
        let (frames, poses) = keys();
        let f = InbetweenFeatures { residual: Residual::KeyLerp, ..features() };
        let s = f.shot(&frames, &poses, &[]).unwrap();
        let d = f.dofs();
        let wavy: Vec<f32> = (0..s.frames * d).map(|x| ((x * 7 % 13) as f32) * 0.3 - 1.5).collect();
        let sizes = f.interval_sizes(&s, &wavy);
        assert_eq!(sizes.iter().map(|i| (i.from, i.to)).collect::<Vec<_>>(), vec![(0, 7), (7, 15), (15, 20)]);
        assert!(sizes.iter().all(|i| i.size > 0.1));
        let Completed { poses: alone, weight: w0, .. } = f.complete(&s, &wavy, None);
        assert_eq!(w0, 0.0);
        assert!((0..s.frames * d).all(|x| alone[x] == f.compose(&s, &wavy, x)));
        // Thresholds far below every interval's size: the curves themselves, keys included.
        let tiny = Fallback { gaps: vec![GapFallback { up_to: 30, start: 0.0, full: 1e-3 }] };
        let Completed { poses: back, weight: w, kept } = f.complete(&s, &wavy, Some(&tiny));
        assert_eq!(w, 1.0);
        assert!(back.iter().zip(&s.bezier).all(|(a, b)| a == b));
        assert!(kept.iter().all(|&k| k == 0.0), "{kept:?}");
        assert!(f.complete(&s, &wavy, None).kept.iter().all(|&k| k == 1.0));
        // Thresholds far above: the network's completion.
        let huge = Fallback { gaps: vec![GapFallback { up_to: 30, start: 1e3, full: 2e3 }] };
        assert_eq!(f.complete(&s, &wavy, Some(&huge)).poses, alone);
        // Key 1 partial: the intervals next to it have no signal and keep the network's values.
        let partial: Vec<bool> = (0..4).flat_map(|k| [true, k != 1, true, true]).collect();
        let p = f.shot(&frames, &poses, &partial).unwrap();
        assert_eq!(p.whole, [true, false, true, true]);
        let sizes = f.interval_sizes(&p, &wavy);
        assert_eq!(sizes.iter().map(|i| (i.from, i.to)).collect::<Vec<_>>(), vec![(15, 20)]);
        let back = f.complete(&p, &wavy, Some(&tiny)).poses;
        assert_eq!(back[3 * d..4 * d], f.complete(&p, &wavy, None).poses[3 * d..4 * d]);
    }

    #[test]
    fn the_fallback_calibrates_per_range_of_gaps_at_the_quantile() {
        // 100 intervals of 5 frames sized 0.01..1.00, 100 of 30 frames sized ten times more, and
        // 5 of 10 frames (too few for their own range).
        let mut sizes: Vec<IntervalSize> =
            (1..=100).map(|i| IntervalSize { from: 0, to: 5, size: i as f32 * 0.01 }).collect();
        sizes.extend((1..=100).map(|i| IntervalSize { from: 10, to: 40, size: i as f32 * 0.1 }));
        sizes.extend((0..5).map(|_| IntervalSize { from: 0, to: 10, size: 100.0 }));
        let f = Fallback::calibrate(&sizes, 0.95, 2.0).unwrap();
        f.check().unwrap();
        assert_eq!(f.gaps.len(), 2);
        assert_eq!(f.gaps[0], GapFallback { up_to: 5, start: 0.95, full: 1.9 });
        assert_eq!(f.gaps[1].up_to, 30);
        assert!((f.gaps[1].start - 9.5).abs() < 1e-5 && (f.gaps[1].full - 19.0).abs() < 1e-4, "{f:?}");
        // Gaps of 10 frames use the next range's thresholds; longer than 30 the last.
        assert_eq!(f.thresholds(10).up_to, 30);
        assert_eq!(f.thresholds(45).up_to, 30);
        assert!(Fallback::calibrate(&sizes[..10], 0.95, 2.0).is_none());
    }
}
