//! The one seeded random generator of zoo: SplitMix64 (Steele, Lea & Flood 2014).
//!
//! Data generation, training (shuffles, augmentation, teacher forcing, initialisation) and
//! the runtime's sampling all draw from this type, so a fixed seed reproduces a result on
//! every platform. Its whole state is one `u64` ([`SplitMix64::state`]), which checkpoints
//! save so that a resumed run draws the same numbers as an uninterrupted one.

/// SplitMix64: small, fast, seedable, and its state is a single `u64`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// An independent generator for stream `stream` of seed `seed` (e.g. one per clip, so
    /// that clips do not depend on the order in which they are generated).
    pub fn with_stream(seed: u64, stream: u64) -> Self {
        let mut mix = SplitMix64(seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
        SplitMix64(mix.next_u64())
    }

    /// The generator's whole state (to checkpoint it).
    pub fn state(&self) -> u64 {
        self.0
    }

    /// A generator continuing from a saved [`SplitMix64::state`].
    pub fn from_state(state: u64) -> Self {
        SplitMix64(state)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next_f64()
    }

    /// +1 or -1 with equal probability.
    pub fn sign(&mut self) -> f64 {
        if self.next_u64() >> 63 == 0 { 1.0 } else { -1.0 }
    }

    /// Uniform integer in `0..n` (`n > 0`; 0 when `n == 0`).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next_u64() % n }
    }

    /// A standard normal sample (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.next_f64();
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Shuffles `items` in place (Fisher-Yates, from the back).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            items.swap(i, (self.next_u64() % (i as u64 + 1)) as usize);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values_and_state_round_trip() {
        // Reference values of SplitMix64 for seed 0 (the algorithm's published test vector).
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
        let saved = r.state();
        let a: Vec<u64> = (0..4).map(|_| r.next_u64()).collect();
        let mut resumed = SplitMix64::from_state(saved);
        let b: Vec<u64> = (0..4).map(|_| resumed.next_u64()).collect();
        assert_eq!(a, b);
    }

    #[test]
    fn streams_differ_and_ranges_hold() {
        let mut a = SplitMix64::with_stream(1, 0);
        let mut b = SplitMix64::with_stream(1, 1);
        assert_ne!(a.next_u64(), b.next_u64());
        for _ in 0..1000 {
            let x = a.range(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&x));
            assert!(a.below(7) < 7);
        }
        let mut v: Vec<u32> = (0..50).collect();
        a.shuffle(&mut v);
        let mut sorted = v.clone();
        sorted.sort();
        assert_eq!(sorted, (0..50).collect::<Vec<_>>());
        assert_ne!(v, sorted);
    }
}
