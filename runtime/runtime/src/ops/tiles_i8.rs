//! int8 products of several characters on the runtime's own integer register tiles.
//!
//! An int8 file's products sum `x_q . w_q` over each input, both in -127..=127: `x_q` a
//! character's row quantized on its own ([`super::product`]), `w_q` the file's integers. The
//! sums are integers, exact in any order, so every kernel here gives tract's kernels' outputs
//! bit for bit.
//!
//! - AVX-512 VNNI: 32 rows by 8 characters (16 vectors of sums) over the whole input width,
//!   `vpdpbusd` multiplying the activations as u8 (`x_q + 128`) by the weights as i8, four
//!   inputs per lane, then taking back `128 * sum(w_q)` per row. On tract-linalg's VNNI kernel
//!   (8 x 8 integer tiles) a batch-64 RTN step's products ran at about 46 % of the core's 8-bit
//!   peak; on these at about 70 %.
//! - AVX2 (no VNNI: most game PCs and consoles): 16 rows by 6 characters, weights and
//!   activations widened to 16 bits, `vpmaddwd` summing two products per lane (at most
//!   `2 * 127 * 127`, no saturation). tract runs such CPUs' int8 products on its f32 kernel.
//!
//! Used for plans of a known number of characters above one; `ZOO_RUNTIME_TILES=0` keeps
//! tract's kernels and `ZOO_RUNTIME_TILES=avx2` the AVX2 tile (comparisons).
//!
//! `unsafe`: the vector loads and stores, inside the panels and the sums sized in
//! [`I8Tiles::run`] (checked there before any tile runs).
#![allow(unsafe_code)]

/// The instruction set an [`I8Tiles`] product runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum I8Isa {
    /// 32 rows x 8 characters, `vpdpbusd` (AVX-512F + AVX-512 VNNI).
    Vnni,
    /// 16 rows x 6 characters, `vpmaddwd` (AVX2).
    Avx2,
}

impl I8Isa {
    /// The tile this CPU runs, if any (see the module's doc for `ZOO_RUNTIME_TILES`).
    pub fn native() -> Option<I8Isa> {
        static ISA: std::sync::OnceLock<Option<I8Isa>> = std::sync::OnceLock::new();
        use super::tiles::{Setting, setting};
        *ISA.get_or_init(|| {
            let allowed: &[I8Isa] = match setting() {
                Setting::Off => &[],
                Setting::Avx2 => &[I8Isa::Avx2],
                Setting::All => &[I8Isa::Vnni, I8Isa::Avx2],
            };
            allowed.iter().copied().find(|isa| isa.supported())
        })
    }

    /// Whether this CPU runs these tiles.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            match self {
                I8Isa::Vnni => {
                    std::arch::is_x86_feature_detected!("avx512f") && std::arch::is_x86_feature_detected!("avx512vnni")
                }
                I8Isa::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// Rows of a panel (one vector of 32-bit sums).
    fn panel(self) -> usize {
        match self {
            I8Isa::Vnni => 16,
            I8Isa::Avx2 => 8,
        }
    }

    /// Inputs per 32-bit lane.
    fn depth(self) -> usize {
        match self {
            I8Isa::Vnni => 4,
            I8Isa::Avx2 => 2,
        }
    }

    /// Characters of a tile.
    fn nr(self) -> usize {
        match self {
            I8Isa::Vnni => 8,
            I8Isa::Avx2 => 6,
        }
    }

    /// The tile's name in node descriptions and benchmarks.
    pub fn name(self) -> &'static str {
        match self {
            I8Isa::Vnni => "zoo_avx512vnni_i8_32x8",
            I8Isa::Avx2 => "zoo_avx2_i16_16x6",
        }
    }
}

/// int8 weights `[m, k]` packed for one [`I8Isa`]: panels of `panel` rows, each `kd / depth`
/// groups of `panel x depth` values (i8 on VNNI, i16 on AVX2; zero past `m` and `k`, `kd` the
/// input width rounded up to `depth`), and on VNNI each row's `128 * sum(w_q)` (what
/// multiplying `x_q + 128` adds).
#[derive(Debug)]
pub struct I8Tiles {
    isa: I8Isa,
    m: usize,
    k: usize,
    kd: usize,
    a8: Vec<i8>,
    a16: Vec<i16>,
    correction: Vec<i32>,
}

impl I8Tiles {
    /// Packs `q` (`[m, k]` row-major). Panics when this CPU does not run `isa`.
    pub fn new(isa: I8Isa, q: &[i8], m: usize, k: usize) -> I8Tiles {
        assert!(isa.supported(), "{isa:?} tiles on a CPU without them");
        assert_eq!(q.len(), m * k, "weights of another size");
        let (panel, depth) = (isa.panel(), isa.depth());
        let kd = k.div_ceil(depth) * depth;
        let panels = m.div_ceil(panel);
        let at = |o: usize, j: usize| {
            (o / panel) * panel * kd + (j / depth) * panel * depth + (o % panel) * depth + j % depth
        };
        let (mut a8, mut a16) = (Vec::new(), Vec::new());
        match isa {
            I8Isa::Vnni => a8 = vec![0i8; panels * panel * kd],
            I8Isa::Avx2 => a16 = vec![0i16; panels * panel * kd],
        }
        for o in 0..m {
            for (j, v) in q[o * k..(o + 1) * k].iter().enumerate() {
                match isa {
                    I8Isa::Vnni => a8[at(o, j)] = *v,
                    I8Isa::Avx2 => a16[at(o, j)] = i16::from(*v),
                }
            }
        }
        let mut correction = vec![0i32; panels * panel];
        if isa == I8Isa::Vnni {
            for (o, c) in correction.iter_mut().take(m).enumerate() {
                *c = 128 * q[o * k..(o + 1) * k].iter().map(|v| i32::from(*v)).sum::<i32>();
            }
        }
        I8Tiles { isa, m, k, kd, a8, a16, correction }
    }

    /// The instruction set these weights are packed for.
    pub fn isa(&self) -> I8Isa {
        self.isa
    }

    /// `acc[c, o] = sum_j x_q[c, j] . w_q[o, j]` for the `n` characters of `xq` (`[n, k]`, each
    /// byte an i8 `x_q`); `acc` is `[n, m]`; `packed` is reused from call to call.
    pub fn run(&self, xq: &[u8], n: usize, acc: &mut [i32], packed: &mut Vec<u8>) {
        let (isa, m, k, kd) = (self.isa, self.m, self.k, self.kd);
        let (panel, nr) = (isa.panel(), isa.nr());
        assert!(xq.len() == n * k && acc.len() >= n * m);
        // The characters, `kd` values each (zero past `k`: the weights there are zero), in
        // groups of `nr` (zero past `n`): u8 `x_q + 128` on VNNI, i16 `x_q` on AVX2 (as bytes).
        let width = kd * if isa == I8Isa::Avx2 { 2 } else { 1 };
        let groups = n.div_ceil(nr);
        packed.clear();
        packed.resize(groups * nr * width, 0);
        for (c, x) in xq.chunks_exact(k.max(1)).enumerate().take(n) {
            let row = &mut packed[c * width..(c + 1) * width];
            match isa {
                I8Isa::Vnni => row.iter_mut().zip(x).for_each(|(d, v)| *d = v ^ 0x80),
                I8Isa::Avx2 => {
                    for (d, v) in row.chunks_exact_mut(2).zip(x) {
                        d.copy_from_slice(&i16::from(*v as i8).to_le_bytes());
                    }
                }
            }
        }
        let panels = m.div_ceil(panel);
        // Row panels in blocks of 128 rows (their weights stay in L2 while every group of
        // characters passes over them), two at a time.
        let block_panels = 128 / panel;
        for block in (0..panels).step_by(block_panels) {
            let end = (block + block_panels).min(panels);
            for g in 0..groups {
                let cols = nr.min(n - g * nr);
                let b = &packed[g * nr * width..(g + 1) * nr * width];
                let mut p = block;
                while p < end {
                    let two = p + 2 <= end;
                    let count = if two { 2 } else { 1 };
                    let rows = (count * panel).min(m - p * panel);
                    let correction = &self.correction[p * panel..];
                    let at = g * nr * m + p * panel;
                    let weights = p * panel * kd..(p + count) * panel * kd;
                    // SAFETY: the CPU runs `isa` (checked in `new`); the weights hold one or two
                    // panels of `kd` inputs, `b` `nr` characters of `kd` values, `correction`
                    // at least the panels' rows; the stores write `rows` sums of `cols`
                    // characters at `acc[at + c * m..]`, inside `acc` (`[n, m]`).
                    #[cfg(target_arch = "x86_64")]
                    unsafe {
                        match (isa, two) {
                            (I8Isa::Vnni, true) => {
                                x86::vnni::<2>(&self.a8[weights], b, kd, correction, acc, at, m, rows, cols)
                            }
                            (I8Isa::Vnni, false) => {
                                x86::vnni::<1>(&self.a8[weights], b, kd, correction, acc, at, m, rows, cols)
                            }
                            (I8Isa::Avx2, true) => x86::avx2::<2>(&self.a16[weights], b, kd, acc, at, m, rows, cols),
                            (I8Isa::Avx2, false) => x86::avx2::<1>(&self.a16[weights], b, kd, acc, at, m, rows, cols),
                        }
                    };
                    p += count;
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    /// `P` panels of 16 rows by 8 characters (`b`: 8 rows of `kd` u8): the sums over `kd`
    /// inputs, less the rows' corrections, stored for `rows` rows and `cols` characters at
    /// `acc[at + c * m + r]`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f,avx512vnni")]
    pub(super) unsafe fn vnni<const P: usize>(
        a: &[i8],
        b: &[u8],
        kd: usize,
        correction: &[i32],
        acc: &mut [i32],
        at: usize,
        m: usize,
        rows: usize,
        cols: usize,
    ) {
        const PANEL: usize = 16;
        debug_assert!(a.len() == P * PANEL * kd && b.len() == 8 * kd && correction.len() >= rows);
        debug_assert!(rows <= P * PANEL && cols <= 8 && at + (cols - 1) * m + rows <= acc.len());
        // SAFETY: the caller's (`I8Tiles::run`), restated above.
        unsafe {
            let (a, b) = (a.as_ptr(), b.as_ptr());
            let mut sums = [[_mm512_setzero_si512(); P]; 8];
            for g in 0..kd / 4 {
                let mut w = [_mm512_setzero_si512(); P];
                for (p, w) in w.iter_mut().enumerate() {
                    *w = _mm512_loadu_si512(a.add(p * PANEL * kd + g * PANEL * 4).cast());
                }
                for (c, sums) in sums.iter_mut().enumerate() {
                    let x = _mm512_set1_epi32(std::ptr::read_unaligned(b.add(c * kd + g * 4).cast::<i32>()));
                    for p in 0..P {
                        sums[p] = _mm512_dpbusd_epi32(sums[p], x, w[p]);
                    }
                }
            }
            for p in 0..P {
                let valid = rows.saturating_sub(p * PANEL).min(PANEL);
                if valid == 0 {
                    continue;
                }
                let mask: __mmask16 = if valid == PANEL { 0xffff } else { (1u16 << valid) - 1 };
                let back = _mm512_maskz_loadu_epi32(mask, correction.as_ptr().add(p * PANEL));
                for (c, sums) in sums.iter().enumerate().take(cols) {
                    let y = _mm512_sub_epi32(sums[p], back);
                    _mm512_mask_storeu_epi32(acc.as_mut_ptr().add(at + c * m + p * PANEL), mask, y);
                }
            }
        }
    }

    /// `P` panels of 8 rows by 6 characters (`b`: 6 rows of `kd` i16): the sums over `kd`
    /// inputs stored for `rows` rows and `cols` characters at `acc[at + c * m + r]`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn avx2<const P: usize>(
        a: &[i16],
        b: &[u8],
        kd: usize,
        acc: &mut [i32],
        at: usize,
        m: usize,
        rows: usize,
        cols: usize,
    ) {
        const PANEL: usize = 8;
        debug_assert!(a.len() == P * PANEL * kd && b.len() == 6 * kd * 2);
        debug_assert!(rows <= P * PANEL && cols <= 6 && at + (cols - 1) * m + rows <= acc.len());
        // SAFETY: the caller's (`I8Tiles::run`), restated above.
        unsafe {
            let (a, b) = (a.as_ptr(), b.as_ptr());
            let mut sums = [[_mm256_setzero_si256(); P]; 6];
            for g in 0..kd / 2 {
                let mut w = [_mm256_setzero_si256(); P];
                for (p, w) in w.iter_mut().enumerate() {
                    *w = _mm256_loadu_si256(a.add(p * PANEL * kd + g * PANEL * 2).cast());
                }
                for (c, sums) in sums.iter_mut().enumerate() {
                    let x = _mm256_set1_epi32(std::ptr::read_unaligned(b.add(c * kd * 2 + g * 4).cast::<i32>()));
                    for p in 0..P {
                        sums[p] = _mm256_add_epi32(sums[p], _mm256_madd_epi16(w[p], x));
                    }
                }
            }
            let mut tile = [0i32; PANEL];
            for p in 0..P {
                let valid = rows.saturating_sub(p * PANEL).min(PANEL);
                for (c, sums) in sums.iter().enumerate().take(cols) {
                    let dst = acc.as_mut_ptr().add(at + c * m + p * PANEL);
                    if valid == PANEL {
                        _mm256_storeu_si256(dst.cast(), sums[p]);
                    } else if valid > 0 {
                        _mm256_storeu_si256(tile.as_mut_ptr().cast(), sums[p]);
                        std::ptr::copy_nonoverlapping(tile.as_ptr(), dst, valid);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{I8Isa, I8Tiles};

    /// Each tile's sums equal the plain integer sums, for shapes with partial panels, inputs
    /// not a multiple of 4 and a partial group of characters.
    #[test]
    fn integer_tiles_compute_the_integer_products() {
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 9) % 255) as i32 - 127
        };
        for isa in [I8Isa::Vnni, I8Isa::Avx2] {
            if !isa.supported() {
                eprintln!("no {isa:?} here: not checked");
                continue;
            }
            for (m, k, n) in [(63, 142, 13), (2048, 512, 64), (16, 4, 8), (40, 7, 3), (130, 1152, 9)] {
                let q: Vec<i8> = (0..m * k).map(|_| next() as i8).collect();
                let x: Vec<i8> = (0..n * k).map(|_| next() as i8).collect();
                let xq: Vec<u8> = x.iter().map(|v| *v as u8).collect();
                let tiles = I8Tiles::new(isa, &q, m, k);
                let mut acc = vec![i32::MIN; n * m];
                tiles.run(&xq, n, &mut acc, &mut Vec::new());
                for c in 0..n {
                    for o in 0..m {
                        let want: i32 = (0..k).map(|j| i32::from(x[c * k + j]) * i32::from(q[o * k + j])).sum();
                        assert_eq!(acc[c * m + o], want, "{isa:?} {m} x {k}, {n} characters: row {o} of character {c}");
                    }
                }
            }
        }
    }
}
