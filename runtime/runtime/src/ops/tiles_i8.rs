//! int8 products of several characters on the runtime's own AVX-512 VNNI register tiles.
//!
//! An int8 file's products sum `x_q . w_q` over each input, both in -127..=127: `x_q` a
//! character's row quantized on its own ([`super::product`]), `w_q` the file's integers. On
//! tract-linalg's VNNI kernel (8 x 8 integer tiles) a batch-64 RTN step's products ran at
//! about 46 % of the core's 8-bit peak. These tiles hold 32 rows by 8 characters (16 vectors of
//! sums) over the whole input width, `vpdpbusd` multiplying the activations as u8 (`x_q + 128`)
//! by the weights as i8, four inputs per lane, then taking back `128 * sum(w_q)` per row: the
//! same integers as any other order of the same products (integer sums are exact), so every
//! output is the one tract's kernel gives, bit for bit.
//!
//! Used for plans of a known number of characters above one on CPUs with AVX-512F and
//! AVX-512 VNNI, unless `ZOO_RUNTIME_TILES=0` or `ZOO_RUNTIME_TILES=avx2` (comparisons).
//!
//! `unsafe`: the vector loads and stores, inside the panels and the sums sized in
//! [`I8Tiles::run`] (checked there before any tile runs).
#![allow(unsafe_code)]

/// Rows of a panel (one vector of 16 sums).
const PANEL: usize = 16;
/// Characters of a tile.
const NR: usize = 8;

/// int8 weights `[m, k]` packed for the VNNI tiles: `ceil(m / 16)` panels, each `ceil(k / 4)`
/// groups of 64 bytes (16 rows x 4 inputs, zero past `m` and `k`), and each row's
/// `128 * sum(w_q)` (what multiplying `x_q + 128` adds).
#[derive(Debug)]
pub struct I8Tiles {
    m: usize,
    k: usize,
    /// `k` rounded up to 4.
    k4: usize,
    a: Vec<i8>,
    correction: Vec<i32>,
}

impl I8Tiles {
    /// Whether this CPU runs the tiles (and `ZOO_RUNTIME_TILES` leaves them on).
    pub fn available() -> bool {
        static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *ON.get_or_init(|| {
            let allowed = !matches!(std::env::var("ZOO_RUNTIME_TILES").as_deref(), Ok("0" | "avx2"));
            #[cfg(target_arch = "x86_64")]
            {
                allowed
                    && std::arch::is_x86_feature_detected!("avx512f")
                    && std::arch::is_x86_feature_detected!("avx512vnni")
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                let _ = allowed;
                false
            }
        })
    }

    /// The tile's name in node descriptions and benchmarks.
    pub fn name() -> &'static str {
        "zoo_avx512vnni_i8_32x8"
    }

    /// Packs `q` (`[m, k]` row-major). Panics when this CPU does not run the tiles.
    pub fn new(q: &[i8], m: usize, k: usize) -> I8Tiles {
        assert!(Self::available(), "VNNI tiles on a CPU without them");
        assert_eq!(q.len(), m * k, "weights of another size");
        let k4 = k.div_ceil(4) * 4;
        let panels = m.div_ceil(PANEL);
        let mut a = vec![0i8; panels * PANEL * k4];
        for o in 0..m {
            let (p, r) = (o / PANEL, o % PANEL);
            for (j, v) in q[o * k..(o + 1) * k].iter().enumerate() {
                a[p * PANEL * k4 + (j / 4) * PANEL * 4 + r * 4 + j % 4] = *v;
            }
        }
        let mut correction = vec![0i32; panels * PANEL];
        for (o, c) in correction.iter_mut().take(m).enumerate() {
            *c = 128 * q[o * k..(o + 1) * k].iter().map(|v| i32::from(*v)).sum::<i32>();
        }
        I8Tiles { m, k, k4, a, correction }
    }

    /// `acc[c, o] = sum_j x_q[c, j] . w_q[o, j]` for the `n` characters of `xq` (`[n, k]`, each
    /// byte an i8 `x_q`); `acc` is `[n, m]`; `packed` is reused from call to call.
    pub fn run(&self, xq: &[u8], n: usize, acc: &mut [i32], packed: &mut Vec<u8>) {
        let (m, k, k4) = (self.m, self.k, self.k4);
        assert!(xq.len() == n * k && acc.len() >= n * m);
        // The characters as u8 (`x_q + 128`), `k4` bytes each (zero past `k`: the weights there
        // are zero), in groups of 8 (zero past `n`).
        let groups = n.div_ceil(NR);
        packed.clear();
        packed.resize(groups * NR * k4, 0);
        for (c, x) in xq.chunks_exact(k.max(1)).enumerate().take(n) {
            for (d, v) in packed[c * k4..c * k4 + k].iter_mut().zip(x) {
                *d = v ^ 0x80;
            }
        }
        let panels = m.div_ceil(PANEL);
        // Row panels in blocks of 8 (128 rows: their weights stay in L2 while every group of
        // characters passes over them), two at a time.
        for block in (0..panels).step_by(8) {
            let end = (block + 8).min(panels);
            for g in 0..groups {
                let cols = NR.min(n - g * NR);
                let b = &packed[g * NR * k4..(g + 1) * NR * k4];
                let mut p = block;
                while p < end {
                    let two = p + 2 <= end;
                    let rows = (if two { 2 } else { 1 } * PANEL).min(m - p * PANEL);
                    let a = &self.a[p * PANEL * k4..(p + if two { 2 } else { 1 }) * PANEL * k4];
                    let correction = &self.correction[p * PANEL..];
                    let at = g * NR * m + p * PANEL;
                    // SAFETY: AVX-512F and VNNI (checked in `new`); `a` holds one or two panels
                    // of `k4 / 4` groups of 64 bytes, `b` 8 characters of `k4` bytes,
                    // `correction` at least one or two panels' rows; the stores write `rows`
                    // sums of `cols` characters at `acc[at + c * m..]`, inside `acc` (`[n, m]`).
                    #[cfg(target_arch = "x86_64")]
                    unsafe {
                        if two {
                            x86::tile::<2>(a, b, k4, correction, acc, at, m, rows, cols)
                        } else {
                            x86::tile::<1>(a, b, k4, correction, acc, at, m, rows, cols)
                        }
                    };
                    p += if two { 2 } else { 1 };
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{NR, PANEL};
    use std::arch::x86_64::*;

    /// `P` panels (16 rows each) by 8 characters: the sums over `k4` inputs, less the rows'
    /// corrections, stored for `rows` rows and `cols` characters at `acc[at + c * m + r]`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f,avx512vnni")]
    pub(super) unsafe fn tile<const P: usize>(
        a: &[i8],
        b: &[u8],
        k4: usize,
        correction: &[i32],
        acc: &mut [i32],
        at: usize,
        m: usize,
        rows: usize,
        cols: usize,
    ) {
        debug_assert!(a.len() == P * PANEL * k4 && b.len() == NR * k4 && correction.len() >= rows);
        debug_assert!(rows <= P * PANEL && cols <= NR && at + (cols - 1) * m + rows <= acc.len());
        // SAFETY: the caller's (`I8Tiles::run`), restated above.
        unsafe {
            let (a, b) = (a.as_ptr(), b.as_ptr());
            let mut sums = [[_mm512_setzero_si512(); P]; NR];
            for g in 0..k4 / 4 {
                let mut w = [_mm512_setzero_si512(); P];
                for (p, w) in w.iter_mut().enumerate() {
                    *w = _mm512_loadu_si512(a.add(p * PANEL * k4 + g * PANEL * 4).cast());
                }
                for (c, sums) in sums.iter_mut().enumerate() {
                    let x = _mm512_set1_epi32(std::ptr::read_unaligned(b.add(c * k4 + g * 4).cast::<i32>()));
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
}

#[cfg(test)]
mod tests {
    use super::I8Tiles;

    /// The tiles' sums equal the plain integer sums, for shapes with partial panels, inputs
    /// not a multiple of 4 and a partial group of characters.
    #[test]
    fn vnni_tiles_compute_the_integer_products() {
        if !I8Tiles::available() {
            eprintln!("no AVX-512 VNNI here: nothing to check");
            return;
        }
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 9) % 255) as i32 - 127
        };
        for (m, k, n) in [(63, 142, 13), (2048, 512, 64), (16, 4, 8), (40, 7, 3), (130, 1152, 9)] {
            let q: Vec<i8> = (0..m * k).map(|_| next() as i8).collect();
            let x: Vec<i8> = (0..n * k).map(|_| next() as i8).collect();
            let xq: Vec<u8> = x.iter().map(|v| *v as u8).collect();
            let tiles = I8Tiles::new(&q, m, k);
            let mut acc = vec![i32::MIN; n * m];
            tiles.run(&xq, n, &mut acc, &mut Vec::new());
            for c in 0..n {
                for o in 0..m {
                    let want: i32 = (0..k).map(|j| i32::from(x[c * k + j]) * i32::from(q[o * k + j])).sum();
                    assert_eq!(acc[c * m + o], want, "{m} x {k}, {n} characters: row {o} of character {c}");
                }
            }
        }
    }
}
