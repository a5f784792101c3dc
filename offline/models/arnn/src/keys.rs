//! Which frames are keys, and which parts of a key are fixed, each time training feeds a
//! sequence: the lamp's own keys with some dropped (section 5), or keys drawn afresh for
//! humanoid motion ([`KeySampling::Sampled`]); partial keys (beyond the paper, which notes
//! their absence) fix only some groups of degrees of freedom.

use crate::config::KeySampling;
use crate::luxo::preprocess::drop_keys;
use zoo_nn::rng::SplitMix64;

/// Key frames for a sequence of `len >= 2` frames whose own keys are `given`.
pub fn choose_keys(sampling: &KeySampling, given: &[usize], len: usize, rng: &mut SplitMix64) -> Vec<usize> {
    match *sampling {
        KeySampling::Given => drop_keys(given, rng),
        KeySampling::Sampled { min_gap, max_gap, context, max_first_gap, context_probability } => {
            if len < 2 {
                // No interval to fill (training refuses such sequences).
                return vec![0];
            }
            let last = len - 1;
            let mut keys = vec![0];
            let mut context_keys = 1;
            let mut first_gap = None;
            if context > 1 && context < len && rng.next_f64() < context_probability {
                keys.extend(1..context);
                context_keys = context;
                // Transition lengths min_gap..=max_first_gap frames: a gap of one more.
                first_gap = Some(min_gap + 1 + rng.below((max_first_gap - min_gap + 1) as u64) as usize);
            }
            let mut t = *keys.last().unwrap_or(&0);
            loop {
                let gap =
                    first_gap.take().unwrap_or_else(|| min_gap + rng.below((max_gap - min_gap + 1) as u64) as usize);
                if t + gap >= last {
                    break;
                }
                t += gap;
                keys.push(t);
            }
            // A remainder shorter than the shortest gap joins the gap before it.
            if keys.len() > context_keys && last - t < min_gap {
                keys.pop();
            }
            keys.push(last);
            keys
        }
    }
}

/// For `n` keys over `groups` groups: which groups each key fixes. Empty when there are no
/// groups (whole keys). The first key is always whole (it is the start pose); each later key is
/// partial with probability `partial`, keeping each group with probability 1/2 and at least one.
pub fn choose_masks(n: usize, groups: usize, partial: f64, rng: &mut SplitMix64) -> Vec<Vec<bool>> {
    if groups == 0 {
        return vec![];
    }
    (0..n)
        .map(|k| {
            if k == 0 || partial <= 0.0 || rng.next_f64() >= partial {
                return vec![true; groups];
            }
            let mut m: Vec<bool> = (0..groups).map(|_| rng.next_f64() < 0.5).collect();
            if !m.contains(&true) {
                m[rng.below(groups as u64) as usize] = true;
            }
            m
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const HUMANOID: KeySampling =
        KeySampling::Sampled { min_gap: 5, max_gap: 30, context: 10, max_first_gap: 45, context_probability: 0.5 };

    #[test]
    fn sampled_keys_follow_the_layout() {
        let mut rng = SplitMix64::new(3);
        let (mut with_context, mut first_gaps) = (0, vec![]);
        for _ in 0..2000 {
            let k = choose_keys(&HUMANOID, &[0, 65], 66, &mut rng);
            assert_eq!((k[0], *k.last().unwrap()), (0, 65), "{k:?}");
            assert!(k.windows(2).all(|w| w[0] < w[1]), "{k:?}");
            let context = k.len() > 10 && k[..10] == (0..10).collect::<Vec<_>>()[..];
            let start = if context { 9 } else { 0 };
            if context {
                with_context += 1;
                first_gaps.push(k[10] - 9);
            }
            for (i, w) in k.windows(2).enumerate().skip(start) {
                let gap = w[1] - w[0];
                let first = context && i == start;
                let max = if first { 46 } else { 30 + 5 };
                // The last gap may be cut short by the end of the sequence only if it is the
                // first after the context; otherwise it is at least min_gap.
                assert!(gap <= max, "{k:?}");
                assert!(gap >= 5 || (first && w[1] == 65), "{k:?}");
            }
        }
        assert!((900..1100).contains(&with_context), "{with_context} of 2000 in the benchmark layout");
        // Every transition length of the benchmark (5..=45 frames between the keys) occurs.
        for n in 5..=45 {
            assert!(first_gaps.contains(&(n + 1)), "no first gap of {} frames", n + 1);
        }
    }

    #[test]
    fn given_keys_are_dropped_as_the_paper_does() {
        let mut rng = SplitMix64::new(1);
        let k = choose_keys(&KeySampling::Given, &[0, 10, 20, 30], 31, &mut rng);
        assert!(k.len() >= 2 && k[0] == 0 && *k.last().unwrap() == 30);
    }

    #[test]
    fn masks_keep_the_first_key_whole_and_one_group_at_least() {
        let mut rng = SplitMix64::new(2);
        assert!(choose_masks(4, 0, 0.5, &mut rng).is_empty());
        let mut partial = 0;
        for _ in 0..500 {
            let m = choose_masks(5, 22, 0.2, &mut rng);
            assert_eq!(m.len(), 5);
            assert!(m[0].iter().all(|&b| b));
            assert!(m.iter().all(|k| k.len() == 22 && k.contains(&true)));
            partial += m.iter().filter(|k| k.contains(&false)).count();
        }
        // 4 candidate keys per draw, a fifth of them partial.
        assert!((300..500).contains(&partial), "{partial} partial keys of 2000");
    }
}
