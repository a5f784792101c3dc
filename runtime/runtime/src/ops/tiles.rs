//! f32 products of several characters on the runtime's own register tiles.
//!
//! A batch-64 RTN step spends nearly all its time in its products. On tract-linalg's f32 tiles
//! the LSTM cell's product ran at about 44 GMAC/s in a step (51 in isolation); on these tiles,
//! two vectors of weight rows by `NR` characters kept in registers over the whole input width,
//! with each block of four weight panels kept in L2 while every panel of characters passes
//! over it, at about 50 (`examples/profile_step`; 52 in isolation, `examples/mmm_kernels`).
//! Each output is the sum of its products in input order, one fused multiply-add at a time
//! from zero, then the bias, the addend and the LeakyReLU: the same arithmetic whatever the
//! tile, so a character's values never depend on how many others share its call or where it
//! sits among them.
//!
//! AVX-512F: 32 rows x 8 characters (16 accumulators); AVX2 + FMA: 16 rows x 6 characters
//! (12). Elsewhere, or with `ZOO_RUNTIME_TILES=0`, products keep tract-linalg's kernels
//! (`ZOO_RUNTIME_TILES=avx2` keeps to the AVX2 tile on an AVX-512 CPU).
//!
//! `unsafe`: the vector loads and stores, inside the panels and the output sized in
//! [`Tiles::run`] (checked there before any tile runs).
#![allow(unsafe_code)]

/// Which of the runtime's tiles `ZOO_RUNTIME_TILES` allows (f32 and integer alike).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Setting {
    /// `0`: tract-linalg's kernels only.
    Off,
    /// `avx2`: the AVX2 tiles only, on any CPU that has them.
    Avx2,
    /// Unset or anything else: the widest this CPU runs.
    All,
}

pub(crate) fn setting() -> Setting {
    match std::env::var("ZOO_RUNTIME_TILES").as_deref() {
        Ok("0") => Setting::Off,
        Ok("avx2") => Setting::Avx2,
        _ => Setting::All,
    }
}

/// The instruction set a [`Tiles`] product runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TileIsa {
    /// 32 rows x 8 characters of 16-lane vectors.
    Avx512,
    /// 16 rows x 6 characters of 8-lane vectors.
    Avx2,
}

impl TileIsa {
    /// The widest tile this CPU runs, if any. `ZOO_RUNTIME_TILES=0` turns the tiles off and
    /// `ZOO_RUNTIME_TILES=avx2` keeps to the AVX2 tile (for comparisons).
    pub fn native() -> Option<TileIsa> {
        static ISA: std::sync::OnceLock<Option<TileIsa>> = std::sync::OnceLock::new();
        *ISA.get_or_init(|| {
            let allowed: &[TileIsa] = match setting() {
                Setting::Off => &[],
                Setting::Avx2 => &[TileIsa::Avx2],
                Setting::All => &[TileIsa::Avx512, TileIsa::Avx2],
            };
            allowed.iter().copied().find(|isa| isa.supported())
        })
    }

    /// Whether this CPU runs these tiles.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            match self {
                TileIsa::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
                TileIsa::Avx2 => {
                    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// Rows (output channels) of a tile.
    pub fn mr(self) -> usize {
        match self {
            TileIsa::Avx512 => 32,
            TileIsa::Avx2 => 16,
        }
    }

    /// Characters (columns) of a tile.
    pub fn nr(self) -> usize {
        match self {
            TileIsa::Avx512 => 8,
            TileIsa::Avx2 => 6,
        }
    }

    /// The tile's name in node descriptions and benchmarks.
    pub fn name(self) -> &'static str {
        match self {
            TileIsa::Avx512 => "zoo_avx512_f32_32x8",
            TileIsa::Avx2 => "zoo_fma_f32_16x6",
        }
    }
}

/// What follows the product, per output: `+ bias[o]`, `+ addend[c, o]`, then `y < 0 ? alpha * y`.
#[derive(Clone, Copy, Default)]
pub struct Epilogue<'a> {
    pub(crate) bias: Option<&'a [f32]>,
    pub(crate) addend: Option<&'a [f32]>,
    pub(crate) alpha: Option<f32>,
}

impl Epilogue<'_> {
    /// The epilogue of one output (the vector forms compute the same, lane by lane).
    #[inline]
    fn apply(&self, y: f32, c: usize, o: usize, m: usize) -> f32 {
        let mut y = y;
        if let Some(b) = self.bias {
            y += b[o];
        }
        if let Some(a) = self.addend {
            y += a[c * m + o];
        }
        match self.alpha {
            Some(alpha) if y < 0.0 => y * alpha,
            _ => y,
        }
    }
}

/// Weights `[m, k]` packed for one [`TileIsa`]: `ceil(m / mr)` panels, each `k` rows of `mr`
/// channels (channels past `m` are zero).
#[derive(Debug)]
pub struct Tiles {
    isa: TileIsa,
    m: usize,
    k: usize,
    a: Vec<f32>,
}

impl Tiles {
    /// Packs `w` (`[m, k]` row-major). Panics when this CPU does not run `isa`.
    pub fn new(isa: TileIsa, w: &[f32], m: usize, k: usize) -> Tiles {
        assert!(isa.supported(), "{isa:?} tiles on a CPU without them");
        assert_eq!(w.len(), m * k, "weights of another size");
        let mr = isa.mr();
        let panels = m.div_ceil(mr);
        let mut a = vec![0f32; panels * mr * k];
        for (p, panel) in a.chunks_exact_mut(mr * k).enumerate() {
            for r in 0..mr.min(m - p * mr) {
                let row = &w[(p * mr + r) * k..(p * mr + r + 1) * k];
                for (kk, v) in row.iter().enumerate() {
                    panel[kk * mr + r] = *v;
                }
            }
        }
        Tiles { isa, m, k, a }
    }

    /// The instruction set these weights are packed for.
    pub fn isa(&self) -> TileIsa {
        self.isa
    }

    /// `out[c, o] = epilogue(sum_i x_i[c] . w_i[o])` for the `n` characters of `xs` (each
    /// `[n, k_i]`, the inputs side by side along `k`); `out` is `[n, m]`; `packed` is reused
    /// from call to call.
    pub fn run(
        &self,
        xs: &[&[f32]],
        ks: &[usize],
        n: usize,
        epilogue: Epilogue,
        out: &mut [f32],
        packed: &mut Vec<f32>,
    ) {
        let (m, k, mr, nr) = (self.m, self.k, self.isa.mr(), self.isa.nr());
        assert!(out.len() == n * m && ks.iter().sum::<usize>() == k);
        assert!(xs.iter().zip(ks).all(|(x, ki)| x.len() == n * ki));
        assert!(epilogue.bias.is_none_or(|b| b.len() == m) && epilogue.addend.is_none_or(|a| a.len() == n * m));
        // The characters packed in panels of `nr`, each `k` rows of `nr` values (zero past `n`).
        let panels = n.div_ceil(nr);
        packed.resize(panels * nr * k, 0.0);
        // Every value of the `n` characters is written below; the padding is zeroed.
        for c in n..panels * nr {
            let panel = &mut packed[(c / nr) * nr * k..(c / nr + 1) * nr * k];
            panel.iter_mut().skip(c % nr).step_by(nr).for_each(|v| *v = 0.0);
        }
        for c in 0..n {
            // Full panels of 8 on AVX-512 CPUs: 8 x 8 blocks transposed in registers below.
            if nr == 8 && c - c % 8 + 8 <= n && self.isa == TileIsa::Avx512 {
                continue;
            }
            let panel = &mut packed[(c / nr) * nr * k..];
            let mut at = c % nr;
            for (x, &ki) in xs.iter().zip(ks) {
                for v in &x[c * ki..(c + 1) * ki] {
                    panel[at] = *v;
                    at += nr;
                }
            }
        }
        #[cfg(target_arch = "x86_64")]
        if nr == 8 && self.isa == TileIsa::Avx512 {
            for q in 0..n / 8 {
                let panel = &mut packed[q * 8 * k..(q + 1) * 8 * k];
                let mut offset = 0;
                for (x, &ki) in xs.iter().zip(ks) {
                    // SAFETY: AVX-512F implies AVX (checked in `Tiles::new`); the rows read are
                    // characters `8q..8q + 8` of `x` (`[n, ki]`), the values written lie in
                    // `panel` (`k` rows of 8).
                    unsafe {
                        x86::pack8(&x[q * 8 * ki..(q + 1) * 8 * ki], ki, &mut panel[offset * 8..(offset + ki) * 8])
                    };
                    offset += ki;
                }
            }
        }
        // Row panels in blocks of four (the weights of a block stay in L2 while every panel of
        // characters passes over them); a panel of one or two characters runs on two or four
        // row panels at once, so that its sums still fill the vector units.
        let row_panels = m.div_ceil(mr);
        // The raw sums of calls that do not store into `out` (partial rows).
        let mut tile = [0f32; 32 * 8];
        for block in (0..row_panels).step_by(4) {
            let block_end = (block + 4).min(row_panels);
            for q in 0..panels {
                let b = &packed[q * nr * k..(q + 1) * nr * k];
                let cols = nr.min(n - q * nr);
                let most = match cols {
                    1 => 4,
                    2 => 2,
                    _ => 1,
                };
                let mut first = block;
                while first < block_end {
                    let together = [4, 2, 1].into_iter().find(|&g| g <= most && first + g <= block_end).unwrap_or(1);
                    let rows = (together * mr).min(m - first * mr);
                    let full = rows == together * mr;
                    let at = q * nr * m + first * mr;
                    let a = &self.a[first * mr * k..(first + together) * mr * k];
                    // SAFETY: `a` holds `together` panels of `k x mr` values and `b` `k x nr`; a
                    // full call stores `cols` rows of `together x mr` outputs at
                    // `out[at + c * m..]`, all inside `out` (`[n, m]`), with the addend read at
                    // the same places; any other stores into `tile` (`cols x together x mr`
                    // values, at most 256).
                    #[cfg(target_arch = "x86_64")]
                    unsafe {
                        let call = x86::Call { a, b, k, m, full, at, ep: epilogue };
                        x86::tiles(self.isa, together, cols, call, out, &mut tile)
                    };
                    #[cfg(not(target_arch = "x86_64"))]
                    unreachable!("tiles exist only on x86-64");
                    if !full {
                        let width = together * mr;
                        for c in 0..cols {
                            for r in 0..rows {
                                let (cc, o) = (q * nr + c, first * mr + r);
                                out[cc * m + o] = epilogue.apply(tile[c * width + r], cc, o, m);
                            }
                        }
                    }
                    first += together;
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{Epilogue, TileIsa};
    use std::arch::x86_64::*;

    /// One kernel per instruction set: `$name::<P, C>` runs `P` consecutive row panels of `$mr`
    /// rows (`2 * P` vectors) by `C` characters (`b`'s rows hold `$nr`), each output the sum of
    /// its `k` products from zero in input order; then (`full`) the epilogue and the store at
    /// `out[at + c * m + r]`, or (not `full`) the raw sums into `tile[c * P * $mr + r]`.
    macro_rules! kernel {
        ($name:ident, $feature:literal, $mr:literal, $nr:literal, $lanes:literal, $v:ty, $zero:ident, $load:ident,
         $store:ident, $splat:ident, $fma:ident, $add:ident, $leaky:expr) => {
            #[target_feature(enable = $feature)]
            unsafe fn $name<const P: usize, const C: usize>(call: Call, out: &mut [f32], tile: &mut [f32; 256]) {
                let Call { a, b, k, m, full, at, ep } = call;
                // SAFETY: the caller's (`Tiles::run`): `a` holds `P` panels of `k x $mr` values,
                // `b` `k x $nr`; the stores of a full call land inside `out` and read the addend
                // at the same places; the others inside `tile` (`C x P x $mr <= 256`).
                unsafe {
                    debug_assert!(a.len() == P * k * $mr && b.len() == k * $nr && C * P * $mr <= 256);
                    let (a, b) = (a.as_ptr(), b.as_ptr());
                    let mut acc: [[$v; P]; C] = [[$zero(); P]; C];
                    let mut acc2: [[$v; P]; C] = [[$zero(); P]; C];
                    for kk in 0..k {
                        let mut lo = [$zero(); P];
                        let mut hi = [$zero(); P];
                        for p in 0..P {
                            lo[p] = $load(a.add(p * k * $mr + kk * $mr));
                            hi[p] = $load(a.add(p * k * $mr + kk * $mr + $lanes));
                        }
                        for c in 0..C {
                            let x = $splat(*b.add(kk * $nr + c));
                            for p in 0..P {
                                acc[c][p] = $fma(lo[p], x, acc[c][p]);
                                acc2[c][p] = $fma(hi[p], x, acc2[c][p]);
                            }
                        }
                    }
                    if !full {
                        for c in 0..C {
                            for p in 0..P {
                                $store(tile.as_mut_ptr().add(c * P * $mr + p * $mr), acc[c][p]);
                                $store(tile.as_mut_ptr().add(c * P * $mr + p * $mr + $lanes), acc2[c][p]);
                            }
                        }
                        return;
                    }
                    let o = at % m;
                    for c in 0..C {
                        for p in 0..P {
                            for (h, mut y) in [(p * $mr, acc[c][p]), (p * $mr + $lanes, acc2[c][p])] {
                                if let Some(bias) = ep.bias {
                                    y = $add(y, $load(bias.as_ptr().add(o + h)));
                                }
                                if let Some(add) = ep.addend {
                                    y = $add(y, $load(add.as_ptr().add(at + c * m + h)));
                                }
                                if let Some(alpha) = ep.alpha {
                                    y = $leaky(y, alpha);
                                }
                                $store(out.as_mut_ptr().add(at + c * m + h), y);
                            }
                        }
                    }
                }
            }
        };
    }

    #[target_feature(enable = "avx512f")]
    #[inline]
    fn leaky512(y: __m512, alpha: f32) -> __m512 {
        let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(y, _mm512_setzero_ps());
        _mm512_mask_mul_ps(y, negative, y, _mm512_set1_ps(alpha))
    }

    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn leaky256(y: __m256, alpha: f32) -> __m256 {
        let negative = _mm256_cmp_ps::<_CMP_LT_OQ>(y, _mm256_setzero_ps());
        _mm256_blendv_ps(y, _mm256_mul_ps(y, _mm256_set1_ps(alpha)), negative)
    }

    kernel!(
        avx512_of,
        "avx512f",
        32,
        8,
        16,
        __m512,
        _mm512_setzero_ps,
        _mm512_loadu_ps,
        _mm512_storeu_ps,
        _mm512_set1_ps,
        _mm512_fmadd_ps,
        _mm512_add_ps,
        leaky512
    );
    kernel!(
        avx2_of,
        "avx2,fma",
        16,
        6,
        8,
        __m256,
        _mm256_setzero_ps,
        _mm256_loadu_ps,
        _mm256_storeu_ps,
        _mm256_set1_ps,
        _mm256_fmadd_ps,
        _mm256_add_ps,
        leaky256
    );

    /// Runs `$f::<together, cols>`: four, two or one row panels for one character, two or
    /// one for two, one for more.
    macro_rules! dispatch {
        ($f:ident, $together:expr, $cols:expr, $($arg:expr),*) => {
            match ($together, $cols) {
                (4, 1) => $f::<4, 1>($($arg),*),
                (2, 1) => $f::<2, 1>($($arg),*),
                (2, 2) => $f::<2, 2>($($arg),*),
                (1, 1) => $f::<1, 1>($($arg),*),
                (1, 2) => $f::<1, 2>($($arg),*),
                (1, 3) => $f::<1, 3>($($arg),*),
                (1, 4) => $f::<1, 4>($($arg),*),
                (1, 5) => $f::<1, 5>($($arg),*),
                (1, 6) => $f::<1, 6>($($arg),*),
                (1, 7) => $f::<1, 7>($($arg),*),
                (1, 8) => $f::<1, 8>($($arg),*),
                (p, c) => unreachable!("{p} row panels by {c} characters"),
            }
        };
    }

    /// Characters `x` (`[8, ki]`) packed as `ki` rows of 8 values into `panel`: 8 x 8 blocks
    /// transposed in registers, the last `ki % 8` columns one value at a time.
    #[target_feature(enable = "avx")]
    pub(super) unsafe fn pack8(x: &[f32], ki: usize, panel: &mut [f32]) {
        debug_assert!(x.len() == 8 * ki && panel.len() == 8 * ki);
        let full = ki - ki % 8;
        // SAFETY: every load reads 8 values of a row `c` at `j < full`, inside `x`; every store
        // writes row `j + r < full` of `panel`.
        unsafe {
            let (src, dst) = (x.as_ptr(), panel.as_mut_ptr());
            for j in (0..full).step_by(8) {
                let r: [__m256; 8] = std::array::from_fn(|c| _mm256_loadu_ps(src.add(c * ki + j)));
                let t0 = _mm256_unpacklo_ps(r[0], r[1]);
                let t1 = _mm256_unpackhi_ps(r[0], r[1]);
                let t2 = _mm256_unpacklo_ps(r[2], r[3]);
                let t3 = _mm256_unpackhi_ps(r[2], r[3]);
                let t4 = _mm256_unpacklo_ps(r[4], r[5]);
                let t5 = _mm256_unpackhi_ps(r[4], r[5]);
                let t6 = _mm256_unpacklo_ps(r[6], r[7]);
                let t7 = _mm256_unpackhi_ps(r[6], r[7]);
                let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
                let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
                let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
                let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
                let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
                let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
                let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
                let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
                let rows = [
                    _mm256_permute2f128_ps::<0x20>(u0, u4),
                    _mm256_permute2f128_ps::<0x20>(u1, u5),
                    _mm256_permute2f128_ps::<0x20>(u2, u6),
                    _mm256_permute2f128_ps::<0x20>(u3, u7),
                    _mm256_permute2f128_ps::<0x31>(u0, u4),
                    _mm256_permute2f128_ps::<0x31>(u1, u5),
                    _mm256_permute2f128_ps::<0x31>(u2, u6),
                    _mm256_permute2f128_ps::<0x31>(u3, u7),
                ];
                for (i, row) in rows.into_iter().enumerate() {
                    _mm256_storeu_ps(dst.add((j + i) * 8), row);
                }
            }
        }
        for j in full..ki {
            for c in 0..8 {
                panel[j * 8 + c] = x[c * ki + j];
            }
        }
    }

    /// One call's operands: `P` panels of weights `a`, the characters `b` (`k` rows each), the
    /// output's width `m`, whether the call stores into the output (`full`) at `at`, and the
    /// epilogue.
    pub(super) struct Call<'a> {
        pub(super) a: &'a [f32],
        pub(super) b: &'a [f32],
        pub(super) k: usize,
        pub(super) m: usize,
        pub(super) full: bool,
        pub(super) at: usize,
        pub(super) ep: Epilogue<'a>,
    }

    /// `together` panels of `isa`'s rows by `cols` characters (see `kernel!`).
    pub(super) unsafe fn tiles(
        isa: TileIsa,
        together: usize,
        cols: usize,
        call: Call,
        out: &mut [f32],
        tile: &mut [f32; 256],
    ) {
        // SAFETY: the caller's, and `isa` is one this CPU runs (checked when the weights were
        // packed, `Tiles::new`).
        unsafe {
            match isa {
                TileIsa::Avx512 => dispatch!(avx512_of, together, cols, call, out, tile),
                TileIsa::Avx2 => dispatch!(avx2_of, together, cols, call, out, tile),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(len: usize, seed: usize) -> Vec<f32> {
        (0..len).map(|i| (((i * 7919 + seed * 104729) % 2001) as f32 / 1000.0 - 1.0) * 0.7).collect()
    }

    /// The product, bias, addend and LeakyReLU in plain Rust, one fused multiply-add at a time.
    fn reference(w: &[f32], xs: &[&[f32]], ks: &[usize], n: usize, m: usize, ep: Epilogue) -> Vec<f32> {
        let k: usize = ks.iter().sum();
        let mut out = vec![0f32; n * m];
        for c in 0..n {
            let x: Vec<f32> = xs.iter().zip(ks).flat_map(|(x, &ki)| x[c * ki..(c + 1) * ki].to_vec()).collect();
            for o in 0..m {
                let y = (0..k).fold(0f32, |acc, kk| w[o * k + kk].mul_add(x[kk], acc));
                out[c * m + o] = ep.apply(y, c, o, m);
            }
        }
        out
    }

    #[test]
    fn tiles_compute_the_product_and_its_epilogue_exactly() {
        let Some(native) = TileIsa::native() else {
            eprintln!("no AVX2 + FMA on this CPU: the tiles are not used, nothing to check");
            return;
        };
        let isas: Vec<TileIsa> = match native {
            TileIsa::Avx512 => vec![TileIsa::Avx512, TileIsa::Avx2],
            TileIsa::Avx2 => vec![TileIsa::Avx2],
        };
        let mut packed = Vec::new();
        for isa in isas {
            // Full and partial tiles on both axes, one input or three side by side, one or two
            // characters on several row panels at once.
            for (m, ks, n) in [
                (64, vec![40], 16),
                (70, vec![13, 29, 7], 11),
                (5, vec![3], 1),
                (33, vec![64, 1], 9),
                (200, vec![40], 1),
                (130, vec![17, 5], 2),
                (100, vec![9], 3),
                (256, vec![8], 8),
            ] {
                let k: usize = ks.iter().sum();
                let w = data(m * k, 1);
                let inputs: Vec<Vec<f32>> = ks.iter().enumerate().map(|(i, ki)| data(n * ki, i + 2)).collect();
                let xs: Vec<&[f32]> = inputs.iter().map(|x| x.as_slice()).collect();
                let (bias, addend) = (data(m, 7), data(n * m, 8));
                let tiles = Tiles::new(isa, &w, m, k);
                for ep in [
                    Epilogue::default(),
                    Epilogue { bias: Some(&bias), addend: Some(&addend), alpha: Some(0.2) },
                    Epilogue { bias: Some(&bias), addend: None, alpha: Some(0.01) },
                ] {
                    let mut out = vec![f32::NAN; n * m];
                    tiles.run(&xs, &ks, n, ep, &mut out, &mut packed);
                    let want = reference(&w, &xs, &ks, n, m, ep);
                    assert!(
                        out.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()),
                        "{isa:?} {m} x {ks:?} x {n}: not the sequential product"
                    );
                    // Both branches of the LeakyReLU are exercised.
                    assert!(n * m < 64 || (want.iter().any(|v| *v < 0.0) && want.iter().any(|v| *v > 0.0)));
                }
            }
        }
    }

    #[test]
    fn a_character_gets_the_same_values_whatever_its_company() {
        let Some(isa) = TileIsa::native() else { return };
        let (m, k) = (200, 37);
        let w = data(m * k, 3);
        let tiles = Tiles::new(isa, &w, m, k);
        let crowd = data(23 * k, 4);
        let mut packed = Vec::new();
        let mut all = vec![0f32; 23 * m];
        tiles.run(&[&crowd], &[k], 23, Epilogue::default(), &mut all, &mut packed);
        for c in [0, 7, 22] {
            let mut one = vec![0f32; m];
            tiles.run(&[&crowd[c * k..(c + 1) * k]], &[k], 1, Epilogue::default(), &mut one, &mut packed);
            assert_eq!(one, all[c * m..(c + 1) * m], "character {c}");
        }
        let mut two = vec![0f32; 2 * m];
        tiles.run(&[&crowd[..2 * k]], &[k], 2, Epilogue::default(), &mut two, &mut packed);
        assert_eq!(two, all[..2 * m]);
    }
}
