//! One matrix product of the zoo ops, `y[c, o] = sum_i x[c, i] * w[o, i]` for the characters
//! `c` of a call, on tract-linalg's kernels: the weights are packed once (when a plan is made),
//! the activations packed per call into a buffer kept between calls, and the kernel run with
//! its fused output stage.
//!
//! - f32: the activations of several inputs are packed side by side along `i`, so one kernel
//!   call computes a sum of products (an LSTM's gate pre-activations) and the bias, a
//!   per-character addend and a LeakyReLU run in the kernel's output stage. On x86-64 with
//!   AVX2 + FMA (or AVX-512F) a plan for a given number of characters above one runs on the
//!   runtime's own tiles instead ([`super::tiles`]), which reach more of the core's peak there.
//! - int8 (the files `zoo export --weights int8` writes): each character's row of each input is
//!   quantized and packed in one pass, with exactly the ONNX graph's arithmetic (`s = max(max|x|
//!   / 127, 1e-30)`, `q = trunc(x / s + 128.5) - 128`, true divisions), the integer product runs
//!   on tract-linalg's i32 kernel where the CPU has VNNI (or AMX), else on its f32 kernel with
//!   the integers held as floats (both exact, see [`Product::new`]), and
//!   [`Product::dequantize`] applies `(acc * channel_scale) * row_scale` as the graph does.
//!   So the integers are the graph's on every CPU.
//!
//! `unsafe` is confined to this file and the tiles' vector code: here, the calls into
//! tract-linalg's kernel entry point, which read the packed operands and write the output
//! through raw pointers (the contract tract's own matmul op keeps): every operand is sized for
//! the `m`, `k`, `n` passed here and outlives the call.
#![allow(unsafe_code)]

use super::tiles::{Epilogue, TileIsa, Tiles};
use super::tiles_i8::{I8Isa, I8Tiles};
use std::cell::RefCell;
use std::sync::Arc;
use tract_onnx::prelude::tract_linalg::mmm::{
    AsInputValue, EagerPackedInput, FusedSpec, MMMInputFormat, MMMInputValue, MatMatMul, Query, ScratchSpace,
};
use tract_onnx::prelude::tract_linalg::pack::{PackedFormat, PackedI8K4};
use tract_onnx::prelude::tract_linalg::{BinOp, MmmDispatch};
use tract_onnx::tract_core::internal::*;

/// The largest activation of a row maps to this integer.
const Q_MAX: f32 = 127.0;
/// The smallest row scale (an all-zero row quantizes to zeros).
const MIN_SCALE: f32 = 1e-30;

/// tract-linalg's f32 tiles that run well below [`WIDE_ON_AMD`] on AMD's AVX-512 cores.
const SLOW_ON_AMD: [&str; 2] = ["avx512_mmm_f32_16x12", "avx512_mmm_f32_16x8"];
/// The f32 tile used instead of [`SLOW_ON_AMD`] on AMD.
const WIDE_ON_AMD: &str = "avx512_mmm_f32_32x6";

/// Whether this is an AMD CPU (its vendor string).
fn amd_cpu() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        static AMD: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *AMD.get_or_init(|| {
            // SAFETY: `cpuid` leaf 0 exists on every x86-64 CPU.
            #[allow(unused_unsafe)]
            let r = unsafe { std::arch::x86_64::__cpuid(0) };
            let vendor: Vec<u8> = [r.ebx, r.edx, r.ecx].iter().flat_map(|v| v.to_le_bytes()).collect();
            vendor == b"AuthenticAMD"
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Weights in one of the two arithmetics.
#[derive(Clone, Debug)]
pub(crate) enum Weights {
    /// `[out, in]` f32.
    F32(Vec<f32>),
    /// `[out, in]` integers in -127..=127 and one scale per output channel.
    I8 { q: Vec<i8>, scales: Vec<f32> },
}

impl Weights {
    /// Output channels `from..to` of these weights (`m` channels in all).
    pub(crate) fn channels(&self, m: usize, from: usize, to: usize) -> Weights {
        match self {
            Weights::F32(v) => {
                let k = v.len() / m.max(1);
                Weights::F32(v[from * k..to * k].to_vec())
            }
            Weights::I8 { q, scales } => {
                let k = q.len() / m.max(1);
                Weights::I8 { q: q[from * k..to * k].to_vec(), scales: scales[from..to].to_vec() }
            }
        }
    }
}

/// The kernel, its packing and the packed weights of a product.
#[derive(Clone, Debug)]
pub(crate) struct Product {
    /// Output channels.
    pub(crate) m: usize,
    /// Width of each input (the `in` of each weight part).
    pub(crate) ks: Vec<usize>,
    kernel: Box<dyn MatMatMul>,
    packing: usize,
    /// f32: one packed matrix over all inputs; int8: one per input.
    a: Vec<Arc<Box<dyn MMMInputValue>>>,
    /// int8: the channel scales of each input's weights.
    scales: Vec<Arc<Vec<f32>>>,
    /// int8: each input's weights laid out for one character at a time ([`Gemv`]), when
    /// plans may run one character.
    gemv: Vec<Arc<Gemv>>,
    /// int8 on an f32 kernel, the integers held as floats (exact; CPUs without VNNI).
    int8_in_f32: bool,
    /// The weights held in 16 bits for a plan for one character: f32 weights that are all
    /// half floats (a file written with `--weights f16`), or the int8 file's integers of a
    /// GRU's recurrence ([`Product::with_recurrent`]).
    one: Option<Arc<Recurrent>>,
    /// f32 weights packed for the runtime's own tiles ([`Tiles`]), which then run every product
    /// of this plan in place of `kernel` (plans for a given number of characters above one).
    tiles: Option<Arc<Tiles>>,
    /// int8: each input's weights packed for the runtime's own VNNI tiles ([`I8Tiles`]), which
    /// then run in place of `kernel` (the same plans as `tiles`; AVX-512 VNNI or AVX2).
    i8_tiles: Vec<Arc<I8Tiles>>,
}

/// int8 weights for a product of one character (a matrix-vector product, which the tiled
/// kernels run at a fraction of their speed): `[m, kp]` row-major, `kp` the input width
/// rounded up to 32 with zeros, and each row's sum (the VNNI form multiplies the activations
/// as u8, `q + 128`, and takes `128 * sum` back).
#[derive(Debug)]
pub(crate) struct Gemv {
    kp: usize,
    w: Vec<i8>,
    sums: Vec<i32>,
}

impl Gemv {
    fn new(q: &[i8], m: usize) -> Gemv {
        let k = q.len() / m.max(1);
        let kp = k.div_ceil(32) * 32;
        let mut w = vec![0i8; m * kp];
        for (dst, src) in w.chunks_exact_mut(kp).zip(q.chunks_exact(k.max(1))) {
            dst[..k].copy_from_slice(src);
        }
        let sums = q.chunks_exact(k.max(1)).map(|r| r.iter().map(|v| i32::from(*v)).sum()).collect();
        Gemv { kp, w, sums }
    }

    /// `out[o] = sum_i w[o, i] * q[i]` for `q` the quantized row (i8 bits, zero-padded to `kp`).
    fn run(&self, q: &[u8], q16: &mut Vec<i16>, out: &mut [i32]) {
        #[cfg(target_arch = "x86_64")]
        match gemv_isa() {
            GemvIsa::Vnni => {
                // SAFETY: the CPU has the features (`gemv_isa`); `w` is `out.len() x kp` and `q`
                // holds `kp` bytes (checked by the caller).
                return unsafe { gemv_vnni(&self.w, &self.sums, self.kp, q, out) };
            }
            GemvIsa::Avx2 => {
                q16.clear();
                q16.extend(q.iter().map(|v| i16::from(*v as i8)));
                // SAFETY: as above, `q16` holds `kp` values.
                return unsafe { gemv_avx2(&self.w, self.kp, q16, out) };
            }
            GemvIsa::None => {}
        }
        let _ = q16;
        for (o, row) in out.iter_mut().zip(self.w.chunks_exact(self.kp)) {
            *o = row.iter().zip(q).map(|(w, q)| i32::from(*w) * i32::from(*q as i8)).sum();
        }
    }
}

/// Rows of a [`Recurrent`] block: eight AVX2 registers of eight lanes.
const BLOCK_ROWS: usize = 64;

/// How a file stores the weights of a [`Recurrent`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RecurrentWidth {
    /// Half floats.
    F16,
    /// Integers in -127..=127 with one scale per row (`w = q * scale`).
    I8,
}

/// Weights for a matrix-vector product of one character, `out[o] = sum_i w[o, i] * x[i]`, held
/// in 16 bits: a recurrence multiplies the same weights every frame, and in f32 a GRU layer's
/// (786 KB at 256 hidden) do not stay in the core's cache beside its other data, while in 16
/// bits they do. The f16 file's weights are its half floats; the int8 file's integers are held
/// as half floats too (exact: every integer up to 2048 is one), which the CPU widens faster
/// than bytes, and each row's sum is multiplied by the row's scale. Rows in blocks of
/// [`BLOCK_ROWS`], each block `[k, 64]` (the 64 rows' weights of one input side by side), the
/// last block padded with zeros.
#[derive(Debug, PartialEq, Eq)]
pub(crate) struct Recurrent {
    m: usize,
    k: usize,
    width: RecurrentWidth,
    /// The weights' (or integers') f16 bits.
    w: Vec<u16>,
    /// `I8`: the f32 bits of each row's scale, padded to the blocks.
    scales: Vec<u32>,
}

impl Recurrent {
    /// `[m, k]` row-major weights: for `F16`, `w` must hold f16 values (widened to f32); for
    /// `I8`, `q` and `scales` are the file's integers and row scales (`w` unused).
    pub(crate) fn new(
        m: usize,
        k: usize,
        width: RecurrentWidth,
        w: &[f32],
        q: &[i8],
        scales: &[f32],
    ) -> TractResult<Recurrent> {
        let blocks = m.div_ceil(BLOCK_ROWS);
        let at = |o: usize, i: usize| (o / BLOCK_ROWS * k + i) * BLOCK_ROWS + o % BLOCK_ROWS;
        let mut r = Recurrent { m, k, width, w: vec![0; blocks * BLOCK_ROWS * k], scales: Vec::new() };
        match width {
            RecurrentWidth::F16 => {
                ensure!(w.len() == m * k, "{} weights for {m} x {k}", w.len());
                for o in 0..m {
                    for i in 0..k {
                        let (v, h) = (w[o * k + i], f16::from_f32(w[o * k + i]));
                        ensure!(h.to_f32().to_bits() == v.to_bits(), "weight {v} is not a half float");
                        r.w[at(o, i)] = h.to_bits();
                    }
                }
            }
            RecurrentWidth::I8 => {
                ensure!(
                    q.len() == m * k && scales.len() == m,
                    "{} integers and {} scales for {m} x {k}",
                    q.len(),
                    scales.len()
                );
                for o in 0..m {
                    for i in 0..k {
                        r.w[at(o, i)] = f16::from_f32(f32::from(q[o * k + i])).to_bits();
                    }
                }
                r.scales = scales.iter().map(|s| s.to_bits()).collect();
                r.scales.resize(blocks * BLOCK_ROWS, 0);
            }
        }
        Ok(r)
    }

    pub(crate) fn width(&self) -> RecurrentWidth {
        self.width
    }

    /// Whether this CPU runs [`Recurrent::run`] in vector form (x86-64 with AVX2, FMA and
    /// F16C); elsewhere tract-linalg's own kernels are faster than its portable form, which
    /// is kept for tests.
    pub(crate) fn available() -> bool {
        #[cfg(target_arch = "x86_64")]
        return recurrent_avx2();
        #[cfg(not(target_arch = "x86_64"))]
        false
    }

    /// `out[o] = sum_i w[o, i] * x[i]` (`x` of `k` values, `out` of `m`).
    pub(crate) fn run(&self, x: &[f32], out: &mut [f32]) {
        assert!(x.len() == self.k && out.len() == self.m, "a recurrent product of the wrong size");
        let mut tile = [0f32; BLOCK_ROWS];
        for (b, rows) in out.chunks_mut(BLOCK_ROWS).enumerate() {
            let w = &self.w[b * self.k * BLOCK_ROWS..(b + 1) * self.k * BLOCK_ROWS];
            #[cfg(target_arch = "x86_64")]
            if recurrent_avx2() {
                // SAFETY: the CPU has AVX2, FMA and F16C (`recurrent_avx2`).
                unsafe { block_avx2(w, x, &mut tile) };
            } else {
                block(w, x, &mut tile);
            }
            #[cfg(not(target_arch = "x86_64"))]
            block(w, x, &mut tile);
            for (j, o) in rows.iter_mut().enumerate() {
                *o = match self.width {
                    RecurrentWidth::F16 => tile[j],
                    RecurrentWidth::I8 => tile[j] * f32::from_bits(self.scales[b * BLOCK_ROWS + j]),
                };
            }
        }
    }
}

/// One block of [`Recurrent::run`]: `tile[j] = sum_i w[i, j] * x[i]`, `w` `[x.len(), 64]`.
fn block(w: &[u16], x: &[f32], tile: &mut [f32; BLOCK_ROWS]) {
    tile.fill(0.0);
    for (row, xi) in w.chunks_exact(BLOCK_ROWS).zip(x) {
        for (t, v) in tile.iter_mut().zip(row) {
            *t = f16::from_bits(*v).to_f32().mul_add(*xi, *t);
        }
    }
}

/// [`block`] on AVX2: eight registers of eight rows, each weight widened by F16C.
///
/// # Safety
/// The CPU has AVX2, FMA and F16C.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn block_avx2(w: &[u16], x: &[f32], tile: &mut [f32; BLOCK_ROWS]) {
    use std::arch::x86_64::*;
    assert!(w.len() == x.len() * BLOCK_ROWS, "a block of the wrong size");
    let mut acc = [_mm256_setzero_ps(); 8];
    for (row, xi) in w.chunks_exact(BLOCK_ROWS).zip(x) {
        let xb = _mm256_set1_ps(*xi);
        for (r, a) in acc.iter_mut().enumerate() {
            // SAFETY: `row` holds 64 values, so `8 r + 8 <= 64`.
            let h = unsafe { _mm_loadu_si128(row.as_ptr().add(r * 8) as *const __m128i) };
            *a = _mm256_fmadd_ps(_mm256_cvtph_ps(h), xb, *a);
        }
    }
    for (r, a) in acc.iter().enumerate() {
        // SAFETY: `tile` holds 64 values.
        unsafe { _mm256_storeu_ps(tile.as_mut_ptr().add(r * 8), *a) };
    }
}

/// Whether [`Recurrent::run`] has its AVX2 form on this CPU (`TRACT_CPU_ISA` can take
/// features away, as for tract's kernels).
#[cfg(target_arch = "x86_64")]
fn recurrent_avx2() -> bool {
    use tract_onnx::tract_core::tract_linalg::isa::{Isa, native};
    static AVX2: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVX2.get_or_init(|| {
        let isa = native();
        isa.has(Isa::X86_64Avx2) && isa.has(Isa::X86_64Fma) && std::arch::is_x86_feature_detected!("f16c")
    })
}

#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, PartialEq)]
enum GemvIsa {
    Vnni,
    Avx2,
    None,
}

/// The matrix-vector form this CPU runs (`TRACT_CPU_ISA` can take features away).
#[cfg(target_arch = "x86_64")]
fn gemv_isa() -> GemvIsa {
    use tract_onnx::tract_core::tract_linalg::isa::{Isa, native};
    static ISA: std::sync::OnceLock<GemvIsa> = std::sync::OnceLock::new();
    *ISA.get_or_init(|| {
        let isa = native();
        if isa.has(Isa::X86_64Avx512Vnni)
            && isa.has(Isa::X86_64Avx512f)
            && std::arch::is_x86_feature_detected!("avx512vl")
        {
            GemvIsa::Vnni
        } else if isa.has(Isa::X86_64Avx2) {
            GemvIsa::Avx2
        } else {
            GemvIsa::None
        }
    })
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn hsum(v: std::arch::x86_64::__m256i) -> i32 {
    use std::arch::x86_64::*;
    let s = _mm_add_epi32(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
    let s = _mm_add_epi32(s, _mm_shuffle_epi32::<0b01_00_11_10>(s));
    let s = _mm_add_epi32(s, _mm_shuffle_epi32::<0b10_11_00_01>(s));
    _mm_cvtsi128_si32(s)
}

/// `out[o] = sum_i w[o, i] * q[i]` with VNNI's u8 x s8 dot products of 4: the activations as
/// `q + 128` (u8), less `128 * sum_i w[o, i]`. Exact.
///
/// # Safety
/// The CPU has AVX2, AVX-512F/VL/VNNI; `w.len() >= out.len() * kp`, `q.len() >= kp`, `kp` a
/// multiple of 32.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl,avx512vnni")]
unsafe fn gemv_vnni(w: &[i8], sums: &[i32], kp: usize, q: &[u8], out: &mut [i32]) {
    use std::arch::x86_64::*;
    debug_assert!(kp % 32 == 0 && q.len() >= kp && w.len() >= out.len() * kp);
    let flip = _mm256_set1_epi8(-128);
    let (w, q) = (w.as_ptr(), q.as_ptr());
    let load = |p: *const i8| unsafe { _mm256_loadu_si256(p as *const __m256i) };
    let m = out.len();
    let mut o = 0;
    while o + 4 <= m {
        let mut acc = [_mm256_setzero_si256(); 4];
        let rows = [0, 1, 2, 3].map(|j| unsafe { w.add((o + j) * kp) });
        let mut c = 0;
        while c < kp {
            let x = _mm256_xor_si256(load(unsafe { q.add(c) } as *const i8), flip);
            for j in 0..4 {
                acc[j] = _mm256_dpbusd_epi32(acc[j], x, load(unsafe { rows[j].add(c) }));
            }
            c += 32;
        }
        for j in 0..4 {
            out[o + j] = hsum(acc[j]) - 128 * sums[o + j];
        }
        o += 4;
    }
    while o < m {
        let mut acc = _mm256_setzero_si256();
        let row = unsafe { w.add(o * kp) };
        let mut c = 0;
        while c < kp {
            let x = _mm256_xor_si256(load(unsafe { q.add(c) } as *const i8), flip);
            acc = _mm256_dpbusd_epi32(acc, x, load(unsafe { row.add(c) }));
            c += 32;
        }
        out[o] = hsum(acc) - 128 * sums[o];
        o += 1;
    }
}

/// `out[o] = sum_i w[o, i] * q[i]` with AVX2's 16-bit pair products (`vpmaddwd` on the
/// weights widened to 16 bits). Exact.
///
/// # Safety
/// The CPU has AVX2; `w.len() >= out.len() * kp`, `q16.len() >= kp`, `kp` a multiple of 32.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gemv_avx2(w: &[i8], kp: usize, q16: &[i16], out: &mut [i32]) {
    use std::arch::x86_64::*;
    debug_assert!(kp % 32 == 0 && q16.len() >= kp && w.len() >= out.len() * kp);
    let (w, q) = (w.as_ptr(), q16.as_ptr());
    let widen = |p: *const i8| unsafe { _mm256_cvtepi8_epi16(_mm_loadu_si128(p as *const __m128i)) };
    let m = out.len();
    let mut o = 0;
    while o + 4 <= m {
        let mut acc = [_mm256_setzero_si256(); 4];
        let rows = [0, 1, 2, 3].map(|j| unsafe { w.add((o + j) * kp) });
        let mut c = 0;
        while c < kp {
            let x = unsafe { _mm256_loadu_si256(q.add(c) as *const __m256i) };
            for j in 0..4 {
                acc[j] = _mm256_add_epi32(acc[j], _mm256_madd_epi16(widen(unsafe { rows[j].add(c) }), x));
            }
            c += 16;
        }
        for j in 0..4 {
            out[o + j] = hsum(acc[j]);
        }
        o += 4;
    }
    while o < m {
        let mut acc = _mm256_setzero_si256();
        let row = unsafe { w.add(o * kp) };
        let mut c = 0;
        while c < kp {
            let x = unsafe { _mm256_loadu_si256(q.add(c) as *const __m256i) };
            acc = _mm256_add_epi32(acc, _mm256_madd_epi16(widen(unsafe { row.add(c) }), x));
            c += 16;
        }
        out[o] = hsum(acc);
        o += 1;
    }
}

impl PartialEq for Product {
    fn eq(&self, other: &Self) -> bool {
        self.m == other.m
            && self.ks == other.ks
            && self.kernel.name() == other.kernel.name()
            && self.a.iter().zip(&other.a).all(|(a, b)| Arc::ptr_eq(a, b))
            && match (&self.tiles, &other.tiles) {
                (Some(a), Some(b)) => Arc::ptr_eq(a, b),
                (a, b) => a.is_none() && b.is_none(),
            }
    }
}
impl Eq for Product {}

impl std::hash::Hash for Product {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.m.hash(state);
        self.ks.hash(state);
        self.kernel.name().hash(state);
    }
}

impl Product {
    /// Packs `parts` (each `[m, k_i]`, the same arithmetic) for the kernel tract-linalg picks
    /// for `n` characters (`None`: any).
    pub(crate) fn new(m: usize, parts: &[Weights], n: Option<usize>) -> TractResult<Product> {
        let int8 = matches!(parts.first(), Some(Weights::I8 { .. }));
        let ks: Vec<usize> = parts
            .iter()
            .map(|w| match w {
                Weights::F32(v) => v.len() / m.max(1),
                Weights::I8 { q, .. } => q.len() / m.max(1),
            })
            .collect();
        let k_total: usize = ks.iter().sum();
        let pick = |acc: DatumType, k: Option<usize>| {
            let dispatch = MmmDispatch::native();
            let query = Query { allow_extractor: false, ..Query::plain(acc, Some(m), k, n) };
            let picked = dispatch.pick(&query).with_context(|| format!("no {acc:?} matrix kernel on this CPU"))?;
            // tract's AMD model picks the 16-row AVX-512 tiles for many of these products, which
            // ran at 0.63-0.80x the 32x6 tile on every product shape of the zoo's models on a
            // Zen 4 core (`examples/mmm_kernels`); its Intel model is left as it is.
            if acc == DatumType::F32 && n != Some(1) && amd_cpu() && SLOW_ON_AMD.contains(&picked.0.name()) {
                if let Some(wide) =
                    dispatch.suitable(&query).into_iter().find(|(k, _, e)| k.name() == WIDE_ON_AMD && e.is_none())
                {
                    return Ok(wide);
                }
            }
            Ok::<_, TractError>(picked)
        };
        let (mut kernel, mut packing, _) =
            if int8 { pick(DatumType::I32, ks.iter().max().copied())? } else { pick(DatumType::F32, Some(k_total))? };
        // Without VNNI, tract's integer kernels run at a third of its f32 ones (AVX2 widens
        // the bytes to 16 bits in the loop); the integers are then multiplied in f32, exactly:
        // both operands are the graph's u8 values less their zero point 128, so in -127..=127
        // (weights checked when read, activations by construction, `quantize_row`), every
        // product is a whole number of magnitude at most 127 * 127 and every partial sum of
        // `k` of them, in whatever order the kernel adds them, is a whole number below 2^24,
        // which f32 holds exactly (k <= 1040).
        let int8_in_f32 = int8
            && !kernel.name().contains("vnni")
            && !kernel.name().contains("amx")
            && ks.iter().all(|k| 127 * 127 * k < 1 << 24);
        if int8_in_f32 {
            (kernel, packing, _) = pick(DatumType::F32, ks.iter().max().copied())?;
        }
        let (pa, _) = &kernel.packings()[packing];
        let mut a = Vec::new();
        let mut scales = Vec::new();
        let mut gemv = Vec::new();
        let mut all_f32 = None;
        let mut tiles = None;
        let mut i8_tiles = Vec::new();
        // The same plans as the f32 tiles below: a known number of characters above one.
        let own_i8 = if int8 && n.is_some_and(|n| n > 1) { I8Isa::native() } else { None };
        if int8 {
            for w in parts {
                let Weights::I8 { q, scales: s } = w else { bail!("an int8 product mixes f32 weights") };
                if let Some(isa) = own_i8 {
                    i8_tiles.push(Arc::new(I8Tiles::new(isa, q, m, q.len() / m.max(1))));
                    scales.push(Arc::new(s.clone()));
                    continue;
                }
                let t = if int8_in_f32 {
                    let f: Vec<f32> = q.iter().map(|v| f32::from(*v)).collect();
                    Tensor::from_shape(&[m, q.len() / m], &f)?
                } else {
                    Tensor::from_shape(&[m, q.len() / m], q)?
                };
                a.push(Arc::new(pa.prepare_one(&t, 1, 0)?));
                scales.push(Arc::new(s.clone()));
                if n.is_none_or(|n| n == 1) {
                    gemv.push(Arc::new(Gemv::new(q, m)));
                }
            }
        } else {
            let mut all = vec![0f32; m * k_total];
            let mut offset = 0;
            for (w, &k) in parts.iter().zip(&ks) {
                let Weights::F32(v) = w else { bail!("an f32 product mixes int8 weights") };
                for o in 0..m {
                    all[o * k_total + offset..o * k_total + offset + k].copy_from_slice(&v[o * k..(o + 1) * k]);
                }
                offset += k;
            }
            // The runtime's tiles for plans of a known number of characters above one. A plan for
            // one keeps tract-linalg's matrix-vector kernel (or the 16-bit weights below); a
            // plan for any number (synthesis) keeps tract-linalg's kernel too: its one or two
            // characters per call read the weights from memory faster on tract's 64-row
            // panels than on the tiles' 32-row ones (a synthesis frame took 1.15-1.2x the time).
            match TileIsa::native().filter(|_| n.is_some_and(|n| n > 1)) {
                Some(isa) => tiles = Some(Arc::new(Tiles::new(isa, &all, m, k_total))),
                None => {
                    let t = Tensor::from_shape(&[m, k_total], &all)?;
                    a.push(Arc::new(pa.prepare_one(&t, 1, 0)?));
                }
            }
            all_f32 = Some(all);
        }
        // Only in plans for one character: a plan for any number keeps one arithmetic for all
        // (synthesis gives a character the same frames whatever the others of its call).
        let one = match (&all_f32, n) {
            (Some(all), Some(1))
                if Recurrent::available()
                    && all.iter().all(|v| f16::from_f32(*v).to_f32().to_bits() == v.to_bits()) =>
            {
                Some(Arc::new(Recurrent::new(m, k_total, RecurrentWidth::F16, all, &[], &[])?))
            }
            _ => None,
        };
        Ok(Product { m, ks, kernel, packing, a, scales, gemv, int8_in_f32, one, tiles, i8_tiles })
    }

    pub(crate) fn int8(&self) -> bool {
        !self.scales.is_empty()
    }

    pub(crate) fn kernel_name(&self) -> &str {
        match &self.tiles {
            Some(t) => t.isa().name(),
            None if !self.i8_tiles.is_empty() => self.i8_tiles[0].isa().name(),
            None => self.kernel.name(),
        }
    }

    /// The width of the weights one character runs on when they are held in 16 bits
    /// ([`Recurrent`]).
    pub(crate) fn one_character(&self) -> Option<RecurrentWidth> {
        self.one.as_ref().map(|r| r.width())
    }

    /// This product with `one` as the weights of one character (an f32 product whose weights
    /// `one` holds in 16 bits: the int8 file's GRU weights, `q * scale`).
    pub(crate) fn with_recurrent(mut self, one: Recurrent) -> TractResult<Product> {
        ensure!(
            !self.int8() && (one.m, one.k) == (self.m, self.ks.iter().sum()),
            "a recurrent product of another size"
        );
        self.one = Some(Arc::new(one));
        Ok(self)
    }

    /// f32: `out[c, o] = act(sum_i x_i[c] . w_i[o] + bias[o] + addend[c, o])` for the `n` rows
    /// of `xs` (each `[n, k_i]`), in one kernel call; `out` is `[n, m]`.
    pub(crate) fn run_f32(
        &self,
        xs: &[&[f32]],
        n: usize,
        bias: Option<&Tensor>,
        addend: Option<&Tensor>,
        leaky: Option<&Tensor>,
        out: &mut Tensor,
    ) -> TractResult<()> {
        ensure!(!self.int8() && out.len() == n * self.m && xs.iter().zip(&self.ks).all(|(x, k)| x.len() == n * k));
        if let (Some(one), 1) = (&self.one, n) {
            return self.run_one(one, xs, bias, addend, leaky, out);
        }
        if let Some(tiles) = &self.tiles {
            let epilogue = Epilogue {
                bias: bias.map(|t| t.try_as_plain_ram()?.as_slice::<f32>()).transpose()?,
                addend: addend.map(|t| t.try_as_plain_ram()?.as_slice::<f32>()).transpose()?,
                alpha: leaky
                    .map(|t| t.try_as_plain_ram()?.as_slice::<f32>()?.first().copied().context("no LeakyReLU slope"))
                    .transpose()?,
            };
            let mut view = out.try_as_plain_ram_mut()?;
            let y = view.as_slice_mut::<f32>()?;
            SCRATCH.with_borrow_mut(|s| tiles.run(xs, &self.ks, n, epilogue, y, &mut s.tiles));
            return Ok(());
        }
        SCRATCH.with_borrow_mut(|s| {
            let (_, pb) = &self.kernel.packings()[self.packing];
            let format = pb.downcast_ref::<PackedFormat>().context("f32 activations in a plain packing")?;
            let k: usize = self.ks.iter().sum();
            let b = packed(&mut s.packed, format, k, n)?;
            pack_f32(format, b, xs, &self.ks, n)?;
            let space = space(&mut s.spaces, &*self.kernel);
            let m = self.m;
            // Output, bias and addend are row-major `[n, m]`: the kernel's rows are our channels.
            unsafe {
                let store = self.kernel.c_from_data_and_strides(4, 1, m as isize);
                let mut ops: TVec<FusedSpec> = tvec![FusedSpec::AddMatMul {
                    a: AsInputValue::Borrowed(&**self.a[0]),
                    b: AsInputValue::Borrowed(&*b),
                    packing: self.packing,
                }];
                if let Some(bias) = bias {
                    ops.push(FusedSpec::BinPerRow(bias.view(), BinOp::Add));
                }
                let addend_view = addend.map(|t| t.view());
                if let Some(v) = &addend_view {
                    ops.push(FusedSpec::AddUnicast(store.wrap(v)));
                }
                if let Some(alpha) = leaky {
                    ops.push(FusedSpec::LeakyRelu(alpha));
                }
                let out_view = out.view_mut();
                ops.push(FusedSpec::Store(store.wrap(&out_view)));
                self.kernel.run_with_scratch_space(m, n, &mut **space, &ops)?;
            }
            Ok(())
        })
    }

    /// [`Product::run_f32`] for one character on the weights held in 16 bits: the product, then
    /// the bias, the addend and the LeakyReLU in the kernel's order.
    fn run_one(
        &self,
        one: &Recurrent,
        xs: &[&[f32]],
        bias: Option<&Tensor>,
        addend: Option<&Tensor>,
        leaky: Option<&Tensor>,
        out: &mut Tensor,
    ) -> TractResult<()> {
        let mut view = out.try_as_plain_ram_mut()?;
        let y = view.as_slice_mut::<f32>()?;
        SCRATCH.with_borrow_mut(|s| {
            s.quantized.clear();
            xs.iter().for_each(|x| s.quantized.extend_from_slice(x));
            one.run(&s.quantized, y);
        });
        if let Some(b) = bias {
            y.iter_mut().zip(b.try_as_plain_ram()?.as_slice::<f32>()?).for_each(|(y, b)| *y += b);
        }
        if let Some(a) = addend {
            y.iter_mut().zip(a.try_as_plain_ram()?.as_slice::<f32>()?).for_each(|(y, a)| *y += a);
        }
        if let Some(alpha) = leaky {
            let alpha = *alpha.try_as_plain_ram()?.as_slice::<f32>()?.first().context("no LeakyReLU slope")?;
            y.iter_mut().filter(|y| **y < 0.0).for_each(|y| *y *= alpha);
        }
        Ok(())
    }

    /// int8: quantizes each row of each `xs[i]` (`[n, k_i]`), runs the integer products and
    /// calls `f(i, acc, row_scales, channel_scales)` with input `i`'s i32 sums (`[n, m]`
    /// row-major), its row scales (`[n]`) and its weights' channel scales (`[m]`).
    pub(crate) fn run_i8(
        &self,
        xs: &[&[f32]],
        n: usize,
        mut f: impl FnMut(usize, &[i32], &[f32], &[f32]) -> TractResult<()>,
    ) -> TractResult<()> {
        ensure!(self.int8() && xs.len() == self.ks.len());
        SCRATCH.with_borrow_mut(|s| {
            let (_, pb) = &self.kernel.packings()[self.packing];
            let m = self.m;
            for (i, (x, &k)) in xs.iter().zip(&self.ks).enumerate() {
                ensure!(x.len() == n * k, "input {i} has {} values, expected {n} x {k}", x.len());
                if n == 1 && !self.gemv.is_empty() {
                    let g = &self.gemv[i];
                    s.row.resize(g.kp, 0);
                    s.row_scales.clear();
                    s.row_scales.push(quantize_row(x, &mut s.row[..k]));
                    s.row[k..].fill(0);
                    at_least::<i32>(&mut s.acc, m)?;
                    let mut view = s.acc.try_as_plain_ram_mut()?;
                    g.run(&s.row, &mut s.row16, &mut view.as_slice_mut::<i32>()?[..m]);
                    drop(view);
                    let acc = &s.acc.try_as_plain_ram()?.as_slice::<i32>()?[..m];
                    f(i, acc, &s.row_scales, &self.scales[i])?;
                    continue;
                }
                at_least::<i32>(&mut s.acc, n * m)?;
                if let Some(tiles) = self.i8_tiles.get(i) {
                    s.rows8.resize(n * k, 0);
                    s.row_scales.clear();
                    for (x, q) in x.chunks_exact(k).zip(s.rows8.chunks_exact_mut(k)) {
                        s.row_scales.push(quantize_row(x, q));
                    }
                    tiles.run(
                        &s.rows8,
                        n,
                        &mut s.acc.try_as_plain_ram_mut()?.as_slice_mut::<i32>()?[..n * m],
                        &mut s.packed8,
                    );
                    let acc = &s.acc.try_as_plain_ram()?.as_slice::<i32>()?[..n * m];
                    f(i, acc, &s.row_scales, &self.scales[i])?;
                    continue;
                }
                if self.int8_in_f32 {
                    let format = pb.downcast_ref::<PackedFormat>().context("f32 activations in a plain packing")?;
                    s.row.resize(k, 0);
                    s.quantized.clear();
                    s.row_scales.clear();
                    for x in x.chunks_exact(k) {
                        s.row_scales.push(quantize_row(x, &mut s.row[..k]));
                        s.quantized.extend(s.row[..k].iter().map(|q| f32::from(*q as i8)));
                    }
                    let b = packed(&mut s.packed, format, k, n)?;
                    pack_f32(format, b, &[&s.quantized], &[k], n)?;
                    at_least::<f32>(&mut s.sums, n * m)?;
                    self.store_product(i, b, space(&mut s.spaces, &*self.kernel), &mut s.sums, m, n)?;
                    {
                        let sums = &s.sums.try_as_plain_ram()?.as_slice::<f32>()?[..n * m];
                        let mut view = s.acc.try_as_plain_ram_mut()?;
                        // Whole numbers below 2^24: the conversion is exact.
                        view.as_slice_mut::<i32>()?.iter_mut().zip(sums).for_each(|(a, v)| *a = *v as i32);
                    }
                    let acc = &s.acc.try_as_plain_ram()?.as_slice::<i32>()?[..n * m];
                    f(i, acc, &s.row_scales, &self.scales[i])?;
                    continue;
                }
                let b = packed_i8(&mut s.packed, &**pb, k, n)?;
                pack_i8(&**pb, b, x, &mut s.row_scales, k, &mut s.row)?;
                self.store_product(i, b, space(&mut s.spaces, &*self.kernel), &mut s.acc, m, n)?;
                let acc = &s.acc.try_as_plain_ram()?.as_slice::<i32>()?[..n * m];
                f(i, acc, &s.row_scales, &self.scales[i])?;
            }
            Ok(())
        })
    }

    /// Runs the kernel on input `i`'s packed weights and the packed activations `b` into `out`
    /// (4-byte values, the f32 sums or the i32 accumulators, `[n, m]` row-major at its start:
    /// it may hold more), overwriting them.
    fn store_product(
        &self,
        i: usize,
        b: &EagerPackedInput,
        space: &mut Box<dyn ScratchSpace>,
        out: &mut Tensor,
        m: usize,
        n: usize,
    ) -> TractResult<()> {
        // SAFETY: `out` is `[n, m]` of 4-byte values, as the store's strides say; the packed
        // operands were sized for `m`, `k` and `n` by this product's plan.
        unsafe {
            let store = self.kernel.c_from_data_and_strides(4, 1, m as isize);
            let view = out.view_mut();
            let ops = [
                FusedSpec::AddMatMul {
                    a: AsInputValue::Borrowed(&**self.a[i]),
                    b: AsInputValue::Borrowed(b),
                    packing: self.packing,
                },
                FusedSpec::Store(store.wrap(&view)),
            ];
            self.kernel.run_with_scratch_space(m, n, &mut **space, &ops)
        }
    }

    /// `out[c, o] = (acc[c, o] as f32 * channel[o]) * row[c]` (the graph's `Cast`, `Mul` by the
    /// channel scales and `Mul` by the row scale, in that order), added to `out` when `add`,
    /// then `+ bias[o]`.
    pub(crate) fn dequantize(
        acc: &[i32],
        row: &[f32],
        channel: &[f32],
        bias: Option<&[f32]>,
        out: &mut [f32],
        add: bool,
    ) {
        let bias = bias.unwrap_or_default();
        #[cfg(target_arch = "x86_64")]
        if avx2() {
            // SAFETY: the CPU has AVX2 and FMA (checked above).
            return unsafe { dequantize_avx2(acc, row, channel, bias, out, add) };
        }
        dequantize_body(acc, row, channel, bias, out, add)
    }
}

/// Quantizes one row (`x`, into `q`, padded with zeros) as the graph does and returns its scale:
/// `s = max(max|x| / 127, 1e-30)` (`Abs`, `ReduceMax`, `Div`, `Max`), then `trunc(x / s + 128.5)`
/// (`Div`, `Add`, `Cast` to u8, which truncates) less the zero point 128.
#[inline(always)]
fn quantize_row_body(x: &[f32], q: &mut [u8]) -> f32 {
    // The largest magnitude through the bits (the same order for non-negative floats; a loop
    // the compiler vectorizes); anything at or past infinity's bits is not finite.
    let bits = x.iter().fold(0u32, |m, v| m.max(v.to_bits() & 0x7fff_ffff));
    if bits < 0x7f80_0000 {
        let s = (f32::from_bits(bits) / Q_MAX).max(MIN_SCALE);
        // `x / s + 128.5` lies in 1.5..=255.5 for every `x` of a finite row, so the conversion
        // needs no saturation.
        for (q, v) in q.iter_mut().zip(x) {
            // SAFETY: finite and within i32 (above).
            let i: i32 = unsafe { ((v / s) + 128.5).to_int_unchecked() };
            *q = (i as u8) ^ 0x80;
        }
        s
    } else {
        let s = (x.iter().fold(0f32, |m, v| m.max(v.abs())) / Q_MAX).max(MIN_SCALE);
        for (q, v) in q.iter_mut().zip(x) {
            *q = ((((v / s) + 128.5) as i32 as u8) ^ 0x80) as u8;
        }
        s
    }
}

/// The `out` rows of [`Product::dequantize`].
#[inline(always)]
fn dequantize_body(acc: &[i32], row: &[f32], channel: &[f32], bias: &[f32], out: &mut [f32], add: bool) {
    let m = channel.len();
    for ((acc, out), &s) in acc.chunks_exact(m).zip(out.chunks_exact_mut(m)).zip(row) {
        match (add, bias.len() == m) {
            (false, false) => {
                for ((o, &a), &w) in out.iter_mut().zip(acc).zip(channel) {
                    *o = (a as f32 * w) * s;
                }
            }
            (false, true) => {
                for (((o, &a), &w), &b) in out.iter_mut().zip(acc).zip(channel).zip(bias) {
                    *o = (a as f32 * w) * s + b;
                }
            }
            (true, false) => {
                for ((o, &a), &w) in out.iter_mut().zip(acc).zip(channel) {
                    *o += (a as f32 * w) * s;
                }
            }
            (true, true) => {
                for (((o, &a), &w), &b) in out.iter_mut().zip(acc).zip(channel).zip(bias) {
                    *o += (a as f32 * w) * s + b;
                }
            }
        }
    }
}

/// Whether the element-wise loops may use AVX2 (the CPU has it and `TRACT_CPU_ISA` leaves it).
#[cfg(target_arch = "x86_64")]
fn avx2() -> bool {
    use tract_onnx::tract_core::tract_linalg::isa::{Isa, native};
    static AVX2: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVX2.get_or_init(|| native().has(Isa::X86_64Avx2) && native().has(Isa::X86_64Fma))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn quantize_row_avx2(x: &[f32], q: &mut [u8]) -> f32 {
    quantize_row_body(x, q)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn dequantize_avx2(acc: &[i32], row: &[f32], channel: &[f32], bias: &[f32], out: &mut [f32], add: bool) {
    dequantize_body(acc, row, channel, bias, out, add)
}

fn quantize_row(x: &[f32], q: &mut [u8]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        return unsafe { quantize_row_avx2(x, q) };
    }
    quantize_row_body(x, q)
}

fn pack_f32(format: &PackedFormat, b: &mut EagerPackedInput, xs: &[&[f32]], ks: &[usize], n: usize) -> TractResult<()> {
    let r = format.r;
    let panel = b.panel_bytes / 4;
    let blob = Arc::get_mut(&mut b.packed).context("packed activations are shared")?;
    let dst: &mut [f32] = bytemuck::try_cast_slice_mut(blob.as_bytes_mut())
        .map_err(|e| format_err!("packed activations are not f32: {e:?}"))?;
    let mut offset = 0;
    for (x, &k) in xs.iter().zip(ks) {
        ensure!(x.len() == n * k, "an input has {} values, expected {n} x {k}", x.len());
        // Panel `p` holds characters `p r..`: for each input `i`, their `r` values side by
        // side. Written in that order (one contiguous run per input), reading `r` rows.
        for (p, rows) in x.chunks(k * r).enumerate() {
            let chars = rows.len() / k.max(1);
            let out = &mut dst[p * panel + offset * r..][..k * r];
            for (i, cell) in out.chunks_exact_mut(r).enumerate() {
                for (j, v) in cell[..chars].iter_mut().enumerate() {
                    *v = rows[j * k + i];
                }
            }
        }
        offset += k;
    }
    Ok(())
}

/// Quantizes the rows of `x` (`[n, k]`) into `b`, laid out for the kernel, and their scales
/// into `scales`.
fn pack_i8(
    format: &dyn MMMInputFormat,
    b: &mut EagerPackedInput,
    x: &[f32],
    scales: &mut Vec<f32>,
    k: usize,
    row: &mut Vec<u8>,
) -> TractResult<()> {
    let panel = b.panel_bytes;
    let blob = Arc::get_mut(&mut b.packed).context("packed activations are shared")?;
    let dst = blob.as_bytes_mut();
    row.resize(k.div_ceil(4) * 4, 0);
    scales.clear();
    if let Some(f) = format.downcast_ref::<PackedI8K4>() {
        // Panels of `r` characters; within one, blocks of 4 inputs, each character's 4 bytes
        // together.
        let r = f.r;
        row[k..].fill(0);
        for (c, x) in x.chunks_exact(k).enumerate() {
            scales.push(quantize_row(x, &mut row[..k]));
            let base = (c / r) * panel + (c % r) * 4;
            for (block, bytes) in row.chunks_exact(4).enumerate() {
                let at = base + block * r * 4;
                dst[at..at + 4].copy_from_slice(bytes);
            }
        }
    } else if let Some(f) = format.downcast_ref::<PackedFormat>() {
        let r = f.r;
        for (c, x) in x.chunks_exact(k).enumerate() {
            scales.push(quantize_row(x, &mut row[..k]));
            let base = (c / r) * panel + c % r;
            for (i, q) in row[..k].iter().enumerate() {
                dst[base + i * r] = *q;
            }
        }
    } else {
        bail!("no int8 packing for {format:?}");
    }
    Ok(())
}

/// Buffers reused from call to call on one thread (one op runs at a time on a thread): packed
/// activations by format and size, the kernels' scratch spaces, integer sums, row scales.
#[derive(Default)]
struct Scratch {
    packed: PackedBuffers,
    spaces: Vec<(String, Box<dyn ScratchSpace>)>,
    /// Integer sums, `[n, m]` row-major at the start (grown, never shrunk: products of
    /// different sizes share it without allocating).
    acc: Tensor,
    row_scales: Vec<f32>,
    row: Vec<u8>,
    row16: Vec<i16>,
    quantized: Vec<f32>,
    /// f32 sums, like `acc`.
    sums: Tensor,
    /// The characters packed for [`Tiles`].
    tiles: Vec<f32>,
    /// The characters' quantized rows, and as packed for [`I8Tiles`].
    rows8: Vec<u8>,
    packed8: Vec<u8>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Packed activation buffers by packing (the hash of its name), depth and width.
type PackedBuffers = Vec<(u64, usize, usize, EagerPackedInput)>;

/// `T` at least `len` values long (a 1-D tensor, grown when shorter).
fn at_least<T: Datum + tract_onnx::tract_core::num_traits::Zero>(t: &mut Tensor, len: usize) -> TractResult<()> {
    if t.datum_type() != T::datum_type() || t.len() < len {
        *t = Tensor::zero::<T>(&[len])?;
    }
    Ok(())
}

/// A key for a packing: the hash of what it displays, computed without allocating (a per-call
/// `to_string` allocated in every product).
fn packing_key(format: &dyn std::fmt::Display) -> u64 {
    use std::hash::Hasher;
    struct Feed(std::collections::hash_map::DefaultHasher);
    impl std::fmt::Write for Feed {
        fn write_str(&mut self, s: &str) -> std::fmt::Result {
            self.0.write(s.as_bytes());
            Ok(())
        }
    }
    let mut feed = Feed(std::collections::hash_map::DefaultHasher::new());
    let _ = std::fmt::write(&mut feed, format_args!("{format}"));
    feed.0.finish()
}

fn packed_at(
    buffers: &mut PackedBuffers,
    key: u64,
    k: usize,
    n: usize,
    make: impl FnOnce() -> TractResult<EagerPackedInput>,
) -> TractResult<&mut EagerPackedInput> {
    let at = match buffers.iter().position(|(f, kk, nn, _)| *f == key && *kk == k && *nn == n) {
        Some(at) => at,
        None => {
            // A few shapes per thread at most (one per input width and batch size).
            if buffers.len() >= 16 {
                buffers.remove(0);
            }
            buffers.push((key, k, n, make()?));
            buffers.len() - 1
        }
    };
    Ok(&mut buffers[at].3)
}

fn packed<'s>(
    buffers: &'s mut PackedBuffers,
    format: &PackedFormat,
    k: usize,
    n: usize,
) -> TractResult<&'s mut EagerPackedInput> {
    packed_at(buffers, packing_key(format), k, n, || format.new_packed_buffer(k, n))
}

fn packed_i8<'s>(
    buffers: &'s mut PackedBuffers,
    format: &dyn MMMInputFormat,
    k: usize,
    n: usize,
) -> TractResult<&'s mut EagerPackedInput> {
    packed_at(buffers, packing_key(format), k, n, || {
        // A zero tensor packed once gives the buffer with its padding zeroed.
        format
            .prepare_one(&Tensor::zero::<i8>(&[n, k])?, 1, 0)?
            .downcast::<EagerPackedInput>()
            .map(|b| *b)
            .map_err(|_| format_err!("{format:?} does not pack eagerly"))
    })
}

fn space<'s>(
    spaces: &'s mut Vec<(String, Box<dyn ScratchSpace>)>,
    kernel: &dyn MatMatMul,
) -> &'s mut Box<dyn ScratchSpace> {
    let at = match spaces.iter().position(|(name, _)| name == kernel.name()) {
        Some(at) => at,
        None => {
            // SAFETY: a fresh scratch space of the kernel that will use it.
            spaces.push((kernel.name().to_string(), unsafe { kernel.allocate_scratch_space() }));
            spaces.len() - 1
        }
    };
    &mut spaces[at].1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `m x k` values of some spread, and a vector of `k`.
    fn data(m: usize, k: usize) -> (Vec<f32>, Vec<f32>) {
        let w = (0..m * k).map(|i| ((i * 7919 % 1009) as f32 / 1009.0 - 0.5) * 0.9).collect();
        let x = (0..k).map(|i| ((i as f32) * 0.61).sin()).collect();
        (w, x)
    }

    #[test]
    fn a_recurrent_product_is_its_weights_times_the_vector() {
        // 130 rows: two full blocks of 64 and a padded one; several widths of input.
        for (m, k) in [(130, 37), (18, 6), (768, 256)] {
            let (w, x) = data(m, k);
            // f16: the weights rounded to half floats first (the file's own values).
            let w16: Vec<f32> = w.iter().map(|v| f16::from_f32(*v).to_f32()).collect();
            // int8: integers and row scales, `w = q * scale`.
            let scales: Vec<f32> = w.chunks(k).map(|r| r.iter().fold(0f32, |a, v| a.max(v.abs())) / 127.0).collect();
            let q: Vec<i8> = w.iter().enumerate().map(|(i, v)| (v / scales[i / k]).round() as i8).collect();
            for width in [RecurrentWidth::F16, RecurrentWidth::I8] {
                let r = Recurrent::new(m, k, width, &w16, &q, &scales).unwrap();
                let mut out = vec![f32::NAN; m];
                r.run(&x, &mut out);
                for o in 0..m {
                    let want: f64 = (0..k)
                        .map(|i| {
                            let wi = match width {
                                RecurrentWidth::F16 => f64::from(w16[o * k + i]),
                                RecurrentWidth::I8 => f64::from(q[o * k + i]) * f64::from(scales[o]),
                            };
                            wi * f64::from(x[i])
                        })
                        .sum();
                    let err = (f64::from(out[o]) - want).abs();
                    assert!(err <= 1e-5 * (1.0 + want.abs()), "{width:?} {m}x{k} row {o}: {} against {want}", out[o]);
                }
                // The portable form gives the same sums as the vector form, to rounding.
                let mut tile = [0f32; BLOCK_ROWS];
                block(&r.w[..k * BLOCK_ROWS], &x, &mut tile);
                let scale = |j: usize| if width == RecurrentWidth::I8 { f32::from_bits(r.scales[j]) } else { 1.0 };
                for j in 0..m.min(BLOCK_ROWS) {
                    assert!((tile[j] * scale(j) - out[j]).abs() <= 1e-5 * (1.0 + out[j].abs()), "{width:?} row {j}");
                }
            }
        }
        // Weights that are not half floats are refused, not rounded.
        assert!(Recurrent::new(1, 1, RecurrentWidth::F16, &[0.1], &[], &[]).is_err());
    }

    #[test]
    fn one_character_on_half_float_weights_is_the_kernel_product() {
        // Two inputs (as an LSTM's gate products), f16 weights: the plan for one character
        // holds them in 16 bits, a plan for any number does not; the same outputs, with the
        // bias, a per-character addend and a LeakyReLU.
        let (m, ks) = (70, [13usize, 9]);
        let parts: Vec<Weights> = ks
            .iter()
            .map(|&k| Weights::F32(data(m, k).0.iter().map(|v| f16::from_f32(*v).to_f32()).collect()))
            .collect();
        let one = Product::new(m, &parts, Some(1)).unwrap();
        let any = Product::new(m, &parts, None).unwrap();
        assert!(one.one_character().is_some() == Recurrent::available() && any.one_character().is_none());
        let xs: Vec<Vec<f32>> = ks.iter().map(|&k| data(1, k).1).collect();
        let xs: Vec<&[f32]> = xs.iter().map(|x| x.as_slice()).collect();
        let bias = tensor1(&(0..m).map(|o| (o as f32 * 0.3).cos()).collect::<Vec<f32>>());
        let addend =
            Tensor::from_shape(&[1, m], &(0..m).map(|o| (o as f32 * 0.7).sin()).collect::<Vec<f32>>()).unwrap();
        let alpha = tensor0(0.1f32);
        let run = |p: &Product| {
            let mut out = Tensor::zero::<f32>(&[1, m]).unwrap();
            p.run_f32(&xs, 1, Some(&bias), Some(&addend), Some(&alpha), &mut out).unwrap();
            out.try_as_plain_ram().unwrap().as_slice::<f32>().unwrap().to_vec()
        };
        let (a, b) = (run(&one), run(&any));
        assert!(a.iter().any(|v| *v < 0.0) && a.iter().any(|v| *v > 0.0), "{a:?}");
        for (o, (a, b)) in a.iter().zip(&b).enumerate() {
            assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "channel {o}: {a} against {b}");
        }
        // f32 weights that are not all half floats stay on the kernel.
        let f32_parts: Vec<Weights> = ks.iter().map(|&k| Weights::F32(data(m, k).0)).collect();
        assert!(Product::new(m, &f32_parts, Some(1)).unwrap().one_character().is_none());
    }
}
