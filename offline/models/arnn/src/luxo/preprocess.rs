//! Section 5: from a simulated sequence to a training sequence with keys.
//!
//! Each hop is sampled at [`HOP_SAMPLES`] (25) evenly spaced times from liftoff to landing,
//! and the still phase between a landing and the next liftoff at [`STILL_SAMPLES`] (6) evenly
//! spaced times strictly between them. Three hops give `3 * 25 + 2 * 6 = 87` frames. The keys
//! are each hop's liftoff (its sample 0), its in-air sample (chosen when the sequence was
//! generated) and its landing (sample 24), so the first frame and the last are keys.
//! Training removes 0, 1 or 2 keys at random each time it feeds a sequence ([`drop_keys`]);
//! the first and last keys are never removed, so every frame lies between two keys.

use super::LuxoError;
pub use super::sequence::HOP_SAMPLES;
use super::sequence::LuxoSequence;
use serde::{Deserialize, Serialize};
use zoo_motion::rng::SplitMix64;

/// Samples of the still phase between two hops.
pub const STILL_SAMPLES: usize = 6;

/// A preprocessed sequence: evenly resampled frames and the frames that are keys.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KeyedSequence {
    /// Name of the source sequence.
    pub name: String,
    /// The degrees of freedom at every frame (the paper's `Y`): the lamp's six
    /// ([`LampPose`](super::LampPose) order), or any fixed number (the humanoid's root and joint rotations).
    pub frames: Vec<Vec<f64>>,
    /// Frame indices of the keys (the paper's `T`), increasing; the first is 0 and the last
    /// is `frames.len() - 1`.
    pub keys: Vec<usize>,
}

impl KeyedSequence {
    /// The key poses (the paper's `X`).
    pub fn key_poses(&self) -> Vec<Vec<f64>> {
        self.keys.iter().map(|&k| self.frames[k].clone()).collect()
    }

    /// For frame `t`, the keys `K` and `K + 1` around it (indices into `keys`) and
    /// `t_rel = (t - T_K) / (T_{K+1} - T_K)` (section 6), for `keys` in use (all of them or
    /// what [`drop_keys`] left). Frames on a key belong to the interval that ends there,
    /// except frame 0.
    pub fn interval(keys: &[usize], t: usize) -> (usize, usize, f64) {
        let n = keys.len();
        let mut k = 0;
        while k + 2 < n && keys[k + 1] < t {
            k += 1;
        }
        let (a, b) = (keys[k], keys[k + 1]);
        (k, k + 1, (t as f64 - a as f64) / (b - a).max(1) as f64)
    }
}

/// Resamples a generated sequence into frames and keys (see the module docs).
pub fn preprocess(seq: &LuxoSequence) -> Result<KeyedSequence, LuxoError> {
    seq.validate().map_err(|message| LuxoError::BadSequence { path: seq.name.clone().into(), message })?;
    if seq.hops.is_empty() {
        return Err(LuxoError::BadSequence {
            path: seq.name.clone().into(),
            message: "the sequence has no hop".into(),
        });
    }
    let mut frames = Vec::with_capacity(seq.hops.len() * (HOP_SAMPLES + STILL_SAMPLES));
    let mut keys = Vec::with_capacity(seq.hops.len() * 3);
    for (h, e) in seq.hops.iter().enumerate() {
        if h > 0 {
            let (a, b) = (seq.hops[h - 1].hop.landing_s, e.hop.liftoff_s);
            for i in 0..STILL_SAMPLES {
                frames.push(seq.pose_at(a + (b - a) * (i + 1) as f64 / (STILL_SAMPLES + 1) as f64).to_vec());
            }
        }
        let start = frames.len();
        let (a, b) = (e.hop.liftoff_s, e.hop.landing_s);
        for i in 0..HOP_SAMPLES {
            frames.push(seq.pose_at(a + (b - a) * i as f64 / (HOP_SAMPLES - 1) as f64).to_vec());
        }
        keys.extend([start, start + e.in_air_sample, start + HOP_SAMPLES - 1]);
    }
    Ok(KeyedSequence { name: seq.name.clone(), frames, keys })
}

/// Removes 0, 1 or 2 keys (each count equally likely, capped by the number of interior
/// keys) chosen uniformly among the keys other than the first and the last.
pub fn drop_keys(keys: &[usize], rng: &mut SplitMix64) -> Vec<usize> {
    let interior = keys.len().saturating_sub(2);
    let count = (rng.below(3) as usize).min(interior);
    let mut kept = keys.to_vec();
    for _ in 0..count {
        let i = 1 + rng.below((kept.len() - 2) as u64) as usize;
        kept.remove(i);
    }
    kept
}

/// A train/test split of whole sequences.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    /// Indices of the training sequences, increasing.
    pub train: Vec<usize>,
    /// Indices of the test sequences, increasing.
    pub test: Vec<usize>,
}

/// Splits `n` sequences: `round(n * test_fraction)` of them (at least 1 when `n >= 2` and
/// the fraction is positive) go to the test set, chosen by a shuffle seeded with `seed`.
pub fn split(n: usize, test_fraction: f64, seed: u64) -> Result<Split, LuxoError> {
    if !(0.0..1.0).contains(&test_fraction) {
        return Err(LuxoError::Config(format!("test fraction must be in [0, 1), found {test_fraction}")));
    }
    let mut order: Vec<usize> = (0..n).collect();
    SplitMix64::new(seed).shuffle(&mut order);
    let mut n_test = (n as f64 * test_fraction).round() as usize;
    if test_fraction > 0.0 && n >= 2 {
        n_test = n_test.clamp(1, n - 1);
    }
    let mut test = order[..n_test].to_vec();
    let mut train = order[n_test..].to_vec();
    test.sort_unstable();
    train.sort_unstable();
    Ok(Split { train, test })
}

/// Mean and standard deviation of each degree of freedom over all frames (for normalising
/// network inputs); a standard deviation below 1e-6 is reported as 1. The number of degrees
/// of freedom is the first frame's (sequences holding other numbers are the caller's error).
pub fn dof_statistics(seqs: &[KeyedSequence]) -> (Vec<f64>, Vec<f64>) {
    let d = seqs.iter().flat_map(|s| s.frames.first()).next().map_or(0, |f| f.len());
    let n = seqs.iter().map(|s| s.frames.len()).sum::<usize>().max(1) as f64;
    let mut mean = vec![0.0; d];
    for f in seqs.iter().flat_map(|s| &s.frames) {
        for (m, v) in mean.iter_mut().zip(f) {
            *m += v / n;
        }
    }
    let mut var = vec![0.0; d];
    for f in seqs.iter().flat_map(|s| &s.frames) {
        for ((q, v), m) in var.iter_mut().zip(f).zip(&mean) {
            *q += (v - m).powi(2) / n;
        }
    }
    (mean, var.into_iter().map(|v: f64| if v.sqrt() < 1e-6 { 1.0 } else { v.sqrt() }).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drop_keys_keeps_the_ends_and_drops_at_most_two() {
        let keys: Vec<usize> = vec![0, 10, 24, 31, 40, 55, 62, 70, 86];
        let mut rng = SplitMix64::new(1);
        let mut seen = [0usize; 3];
        for _ in 0..300 {
            let kept = drop_keys(&keys, &mut rng);
            assert_eq!(kept[0], 0);
            assert_eq!(*kept.last().unwrap(), 86);
            assert!(kept.windows(2).all(|w| w[0] < w[1]));
            assert!(kept.iter().all(|k| keys.contains(k)));
            seen[keys.len() - kept.len()] += 1;
        }
        assert!(seen.iter().all(|&c| c > 50), "{seen:?}");
        assert_eq!(drop_keys(&[0, 5], &mut rng), vec![0, 5]);
    }

    #[test]
    fn split_is_fixed_by_seed_and_covers_everything() {
        let a = split(300, 0.2, 7).unwrap();
        assert_eq!(a, split(300, 0.2, 7).unwrap());
        assert_ne!(a, split(300, 0.2, 8).unwrap());
        assert_eq!((a.train.len(), a.test.len()), (240, 60));
        let mut all: Vec<usize> = a.train.iter().chain(&a.test).copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..300).collect::<Vec<_>>());
        assert_eq!(split(3, 0.01, 0).unwrap().test.len(), 1);
        assert!(split(3, 1.0, 0).is_err());
    }

    #[test]
    fn interval_gives_t_rel() {
        let keys = [0, 12, 24];
        assert_eq!(KeyedSequence::interval(&keys, 0), (0, 1, 0.0));
        assert_eq!(KeyedSequence::interval(&keys, 6), (0, 1, 0.5));
        assert_eq!(KeyedSequence::interval(&keys, 12), (0, 1, 1.0));
        assert_eq!(KeyedSequence::interval(&keys, 18), (1, 2, 0.5));
        assert_eq!(KeyedSequence::interval(&keys, 24), (1, 2, 1.0));
    }
}
