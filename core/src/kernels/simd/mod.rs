//! The innermost weight-reading kernels (dot products of a weight row with
//! f32 activations, for each stored weight type), with a scalar reference
//! twin ([`scalar`]) and SIMD variants ([`x86`]: AVX2+FMA+F16C; [`neon`]:
//! aarch64 NEON). Everything above this module (`linear`, `conv`,
//! `attention`, the quantizer) is written once and calls the dispatchers
//! here, so a new instruction set is one file plus one match arm.
//!
//! Which variant runs is the process-wide [`Isa`]:
//! - no_std: fixed at compile time by the target features (`-C
//!   target-feature=+avx2,+fma,+f16c` or `-C target-cpu=native` on x86_64;
//!   NEON is baseline on aarch64 targets with an FPU);
//! - std: `duolando::simd::init()` detects the CPU at run time and calls
//!   [`set_isa`] (an `unsafe fn`: the caller vouches for the CPU).
//!
//! Unsafe code is allowed in this module only (intrinsics); every unsafe
//! block carries a SAFETY comment. Tests: `core/src/tests/simd.rs` compares
//! every SIMD kernel to its scalar twin with named error limits.
#![allow(unsafe_code)]

use core::sync::atomic::{AtomicU8, Ordering};

#[cfg(target_arch = "x86_64")]
pub mod amx;
pub mod i8mm;
pub mod matmul;
pub mod peak;
pub mod scalar;
#[cfg(test)]
mod tests;
#[cfg(target_arch = "x86_64")]
pub mod tile_pair;
#[cfg(target_arch = "x86_64")]
pub mod x86;
#[cfg(target_arch = "x86_64")]
pub use amx::{amx_rows, gemm_q8_packed_amx, COLS as AMX_COLS, ROWS as AMX_ROWS};
#[cfg(not(target_arch = "x86_64"))]
pub use no_amx::{amx_rows, gemm_q8_packed_amx, COLS as AMX_COLS, ROWS as AMX_ROWS};
#[cfg(not(target_arch = "x86_64"))]
pub use no_amx::{gemm_q8_pair, TilePair, PAIR_CALL_ROWS};
#[cfg(target_arch = "x86_64")]
pub use tile_pair::{gemm_q8_pair, TilePair, PAIR_CALL_ROWS};
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
pub mod neon;

/// Values per int8 block (`DType::Q8Block32`).
pub const Q8_BLOCK: usize = 32;
/// Bytes per stored int8 block: f16 scale + 32 i8.
pub const Q8_BLOCK_BYTES: usize = 34;

/// An instruction set the kernels have a variant for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Isa {
    Scalar = 0,
    /// x86_64 AVX2 + FMA + F16C (Haswell and later, Zen and later).
    Avx2 = 1,
    /// aarch64 Advanced SIMD (NEON).
    Neon = 2,
    /// x86_64 AVX-512 F/BW/DQ/VL (+ AVX2, FMA, F16C): 16-wide f32 tiles,
    /// int8 via `vpmaddubsw` / `vpmaddwd` on 64-byte vectors.
    Avx512 = 3,
    /// [`Isa::Avx512`] + AVX512-VNNI: int8 dots with `vpdpbusd`.
    Avx512Vnni = 4,
    /// aarch64 NEON + the dot-product extension (`sdot`).
    NeonDot = 5,
    /// [`Isa::Avx2`] + AVX-VNNI (Intel Alder Lake and later desktops, AMD
    /// Zen 5): the packed int8 GEMM with `{vex} vpdpbusd` on 32-byte
    /// vectors; every other kernel is [`Isa::Avx2`]'s.
    AvxVnni = 6,
}

impl Isa {
    /// True for the x86_64 variants (all imply AVX2 + FMA + F16C).
    #[inline]
    pub fn is_x86(self) -> bool {
        matches!(
            self,
            Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni
        )
    }
}

/// The best ISA the compile-time target features guarantee.
pub const COMPILE_TIME_ISA: Isa = if cfg!(all(
    target_arch = "x86_64",
    target_feature = "avx512f",
    target_feature = "avx512bw",
    target_feature = "avx512dq",
    target_feature = "avx512vl",
    target_feature = "avx512vnni",
    target_feature = "avx2",
    target_feature = "fma",
    target_feature = "f16c"
)) {
    Isa::Avx512Vnni
} else if cfg!(all(
    target_arch = "x86_64",
    target_feature = "avx512f",
    target_feature = "avx512bw",
    target_feature = "avx512dq",
    target_feature = "avx512vl",
    target_feature = "avx2",
    target_feature = "fma",
    target_feature = "f16c"
)) {
    Isa::Avx512
} else if cfg!(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma",
    target_feature = "f16c",
    target_feature = "avxvnni"
)) {
    Isa::AvxVnni
} else if cfg!(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma",
    target_feature = "f16c"
)) {
    Isa::Avx2
} else if cfg!(all(
    target_arch = "aarch64",
    target_feature = "neon",
    target_feature = "dotprod"
)) {
    Isa::NeonDot
} else if cfg!(all(target_arch = "aarch64", target_feature = "neon")) {
    Isa::Neon
} else {
    Isa::Scalar
};

static ISA: AtomicU8 = AtomicU8::new(COMPILE_TIME_ISA as u8);

/// The ISA the dispatchers use now.
#[inline]
pub fn isa() -> Isa {
    match ISA.load(Ordering::Relaxed) {
        1 => Isa::Avx2,
        2 => Isa::Neon,
        3 => Isa::Avx512,
        4 => Isa::Avx512Vnni,
        5 => Isa::NeonDot,
        6 => Isa::AvxVnni,
        _ => Isa::Scalar,
    }
}

/// Selects the kernels every later call uses (process-wide).
///
/// # Safety
/// The CPU running this process must support `isa` (for [`Isa::Avx2`]:
/// avx2, fma and f16c; [`Isa::Avx512`]: those and avx512f, avx512bw,
/// avx512dq, avx512vl; [`Isa::Avx512Vnni`]: those and avx512vnni;
/// [`Isa::AvxVnni`]: avx2, fma, f16c and avxvnni; for
/// [`Isa::Neon`]: an aarch64 CPU, which always has it; [`Isa::NeonDot`]:
/// the dotprod extension), and `isa` must be one this build has a variant for (an arm for a
/// foreign architecture falls back to scalar). [`Isa::Scalar`] is always safe.
pub unsafe fn set_isa(isa: Isa) {
    ISA.store(isa as u8, Ordering::Relaxed);
}

/// Selects the scalar reference kernels (always sound).
pub fn force_scalar() {
    ISA.store(Isa::Scalar as u8, Ordering::Relaxed);
}

/// IEEE binary16 bits to f32, exact for every value (the `half` crate).
#[inline]
pub fn f16_to_f32(bits: u16) -> f32 {
    half::f16::from_bits(bits).to_f32()
}

/// `dst[i] = f32(src[i])` for binary16 bits, exact (the f16 K/V cache
/// widened for the attention), over the shorter length.
#[inline]
pub fn widen_f16(src: &[u16], dst: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::widen_f16(src, dst)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::widen_f16(src, dst) },
        _ => scalar::widen_f16(src, dst),
    }
}

/// `dst[i] = binary16(src[i])`, rounded to nearest even (`half`'s
/// `f16::from_f32`), over the shorter length: the rows an f16 K/V cache
/// stores. The F16C variant is bit-identical to the twin on every non-NaN
/// input (NaNs stay NaN).
#[inline]
pub fn narrow_f16(src: &[f32], dst: &mut [u16]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::narrow_f16(src, dst)
        },
        _ => scalar::narrow_f16(src, dst),
    }
}

/// Hints the CPU to bring `bytes` into cache (one prefetch per 64-byte
/// line; x86 `prefetcht0`, aarch64 `prfm pldl1keep`; nothing elsewhere).
/// Changes no result: the unpacked int8 tiles call it one tile ahead so
/// memory reads overlap the multiplies.
#[inline]
pub fn prefetch(bytes: &[u8]) {
    prefetch_into::<false>(bytes)
}

/// [`prefetch`] into the second-level cache only (x86 `prefetcht1`,
/// aarch64 `prfm pldl2keep`). The packed int8 GEMM streams its weights
/// this way two tiles ahead: a whole tile prefetched into L1 at once
/// (`prefetcht0`, one tile ahead, before 2026-12-03) stalled the 1-10-row
/// panels of a streaming step on cold weights (measured: 0.65-0.75x the
/// time at 5-10 rows of 768-wide matrices).
#[inline]
pub fn prefetch_l2(bytes: &[u8]) {
    prefetch_into::<true>(bytes)
}

/// One prefetch per 64-byte line of `bytes`, into L1 or (`L2`) into the
/// second-level cache only.
#[inline(always)]
fn prefetch_into<const L2: bool>(bytes: &[u8]) {
    #[cfg(target_arch = "x86_64")]
    for line in bytes.chunks(64) {
        use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0, _MM_HINT_T1};
        let p = line.as_ptr() as *const i8;
        // SAFETY: a prefetch is a hint with no architectural effect; the
        // address lies inside `bytes` (sse is baseline on x86_64).
        unsafe {
            if L2 {
                _mm_prefetch::<_MM_HINT_T1>(p)
            } else {
                _mm_prefetch::<_MM_HINT_T0>(p)
            }
        };
    }
    #[cfg(target_arch = "aarch64")]
    for line in bytes.chunks(64) {
        // SAFETY: as above; `prfm` neither faults nor writes.
        unsafe {
            if L2 {
                core::arch::asm!("prfm pldl2keep, [{0}]", in(reg) line.as_ptr(), options(nostack, readonly, preserves_flags))
            } else {
                core::arch::asm!("prfm pldl1keep, [{0}]", in(reg) line.as_ptr(), options(nostack, readonly, preserves_flags))
            }
        };
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    let _ = bytes;
}

/// Splits `m` activation rows into the fewest passes of at most `most`
/// rows, the rows shared evenly (10 rows at most 8: 5 + 5; 20 at most 12: 10 + 10; 5 at most 4:
/// 3 + 2): `f(first row, rows)` per pass, in order.
#[inline(always)]
pub(crate) fn even_passes(m: usize, most: usize, f: &mut impl FnMut(usize, usize)) {
    let mut m0 = 0;
    while m0 < m {
        let left = m - m0;
        let k = left.div_ceil(left.div_ceil(most.max(1)));
        f(m0, k);
        m0 += k;
    }
}

/// Where row `m` of a call group of `rows` activation rows keeps its block
/// `b` in the layout [`gemm_q8_pair`] reads: its 32 values at `32 i`, its
/// scale at `i` and its two corrections at `2 i`, `2 i + 1` of the group's
/// slices, for `i = b rows + m` (per block the group's rows one after
/// another: the kernel walks one pointer per operand with the rows at fixed
/// offsets). A group of `rows` rows of `n_in` values takes as much memory
/// as the same rows one after another.
#[inline(always)]
pub const fn pair_group_index(b: usize, m: usize, rows: usize) -> usize {
    b * rows + m
}

/// `[[f32; PACK_ROWS]; $m]` from a packed kernel of at most 4 activation
/// rows per pass (AVX2, NEON dotprod): `$m` rows in the fewest passes,
/// shared evenly ([`even_passes`]); `$body` gives rows `$m0 .. $m0 + $k`
/// with `$k` a `const usize` (1..=4) and `$a` the bytes to prefetch (all
/// of `$ahead` in the first pass, none after).
#[cfg_attr(
    not(any(target_arch = "x86_64", target_arch = "aarch64")),
    allow(unused_macros)
)]
macro_rules! passes_of_four {
    ($m:expr, $ahead:expr, |$k:ident, $m0:ident, $a:ident| $body:expr) => {{
        let mut out = [[0.0f32; $crate::kernels::simd::PACK_ROWS]; $m];
        $crate::kernels::simd::even_passes($m, 4, &mut |$m0: usize, rows: usize| {
            let $a: &[u8] = if $m0 == 0 { $ahead } else { &[] };
            match rows {
                1 => {
                    const $k: usize = 1;
                    out[$m0..$m0 + $k].copy_from_slice(&$body);
                }
                2 => {
                    const $k: usize = 2;
                    out[$m0..$m0 + $k].copy_from_slice(&$body);
                }
                3 => {
                    const $k: usize = 3;
                    out[$m0..$m0 + $k].copy_from_slice(&$body);
                }
                _ => {
                    const $k: usize = 4;
                    out[$m0..$m0 + $k].copy_from_slice(&$body);
                }
            }
        });
        out
    }};
}
#[cfg_attr(
    not(any(target_arch = "x86_64", target_arch = "aarch64")),
    allow(unused_imports)
)]
pub(crate) use passes_of_four;

/// Prefetches (into L2) part `i` of `parts` of `ahead`'s 64-byte lines: a
/// kernel that calls it once per block (pair) spreads the next tiles'
/// prefetch over its work. One burst of a tile's lines at the tile's start
/// held the core on the prefetch instructions themselves (a full miss
/// queue): 14% of a streaming step's samples sat in the burst loop.
#[inline(always)]
pub(crate) fn prefetch_part(ahead: &[u8], i: usize, parts: usize) {
    // Nothing to prefetch (most calls): no part arithmetic (two divisions).
    if ahead.is_empty() {
        return;
    }
    let (b0, b1) = part_bytes(ahead.len(), i, parts);
    if b0 < b1 {
        prefetch_l2(&ahead[b0..b1]);
    }
}

/// The bytes of part `i` of `parts` of `len` bytes, cut at 64-byte lines:
/// parts `0..parts` cover `0..len` once, in order; empty past the last.
#[inline(always)]
pub(crate) fn part_bytes(len: usize, i: usize, parts: usize) -> (usize, usize) {
    if parts == 0 {
        return (0, 0);
    }
    let lines = len.div_ceil(64);
    let (l0, l1) = (
        (i * lines / parts).min(lines),
        ((i + 1) * lines / parts).min(lines),
    );
    ((l0 * 64).min(len), (l1 * 64).min(len))
}

/// `a . b` (f32 weights or activations).
#[inline]
pub fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds Avx2 only via COMPILE_TIME_ISA (features enabled
        // at build time) or `set_isa`, whose caller vouched for the CPU.
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::dot_f32(a, b) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::dot_f32(a, b) },
        _ => scalar::dot_f32(a, b),
    }
}

/// `w . x` with binary16 weights.
#[inline]
pub fn dot_f16(w: &[u16], x: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::dot_f16(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::dot_f16(w, x) },
        _ => scalar::dot_f16(w, x),
    }
}

/// Blocked int8 dot (see [`scalar::dot_q8`]).
#[inline]
pub fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::dot_q8(w, xq, xd)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::dot_q8(w, xq, xd) },
        _ => scalar::dot_q8(w, xq, xd),
    }
}

/// Activation rows per register tile (the `m` side of [`tile_f32`] & co.).
pub const TM: usize = 4;
/// Weight rows per register tile (the `n` side).
pub const TN: usize = 4;

/// A `TM x TN` tile of dot products: `out[m][n] = w[n] . x[m]`.
pub type Tile = [[f32; TN]; TM];

/// Every pair of a tile through a single-row dot (the scalar twins, and
/// the NEON path until it has a register-blocked kernel).
#[inline]
pub(crate) fn pairwise(f: impl FnMut(usize, usize) -> f32) -> Tile {
    pairwise_rows(TM, f)
}

/// [`pairwise`] over rows `0..d` only; rows `d..` repeat row `d - 1` (the
/// numbers of a repeated activation row: [`distinct_rows`]).
#[inline]
pub(crate) fn pairwise_rows(d: usize, mut f: impl FnMut(usize, usize) -> f32) -> Tile {
    let d = d.clamp(1, TM);
    let mut out = [[0.0; TN]; TM];
    for (m, row) in out.iter_mut().enumerate().take(d) {
        for (n, o) in row.iter_mut().enumerate() {
            *o = f(m, n);
        }
    }
    let last = out[d - 1];
    out[d..].fill(last);
    out
}

/// Activation rows of a tile to compute: `linear` pads a partial tile by
/// handing the last row again (the same slice), and rows that repeat the
/// one before them at the end of `x` give that row's numbers, so the f32 /
/// f16 tiles compute rows `0..distinct_rows(x)` and copy the rest (a 1-row
/// GEMV does a quarter of the multiplies; every f32 / f16 tile, the scalar
/// one included; bit-identical, tested by
/// `simd_tiles_give_repeated_rows_the_numbers_of_copies`).
#[inline]
pub(crate) fn distinct_rows<T>(x: &[&[T]; TM]) -> usize {
    let mut d = TM;
    while d > 1 && core::ptr::eq(x[d - 1], x[d - 2]) {
        d -= 1;
    }
    d
}

/// Register-blocked `x . w^T` tile with f32 weights: `out[m][n] = w[n] .
/// x[m]` over the shortest slice length (see [`scalar::tile_f32`]).
#[inline]
pub fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::tile_f32_512(w, x) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::tile_f32(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::tile_f32(w, x) },
        _ => scalar::tile_f32(w, x),
    }
}

/// [`tile_f32`] with binary16 weights (converted once per tile step).
#[inline]
pub fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::tile_f16_512(w, x) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::tile_f16(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::tile_f16(w, x) },
        _ => scalar::tile_f16(w, x),
    }
}

/// [`tile_f32`] for blocked int8: `w[n]` stored Q8Block32 rows, `xq[m]` /
/// `xd[m]` quantised activation rows ([`quantise_q8`]); see [`dot_q8`].
#[inline]
pub fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::tile_q8(w, xq, xd)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::tile_q8(w, xq, xd) },
        _ => scalar::tile_q8(w, xq, xd),
    }
}

/// Quantises activations for [`dot_q8`]: per block of 32, `d = max|x| /
/// 127` (f32) and `q = round(x / d)` in [-127, 127] (0 when the block is
/// all zeros, or so small that `1 / d` overflows: [`q8_scale`]). `x.len()`
/// must be a multiple of 32 (a trailing partial block is ignored); `q` >=
/// x.len(), `d` >= x.len() / 32.
pub fn quantise_q8(x: &[f32], q: &mut [i8], d: &mut [f32]) {
    for ((xb, qb), db) in x
        .chunks_exact(Q8_BLOCK)
        .zip(q.chunks_exact_mut(Q8_BLOCK))
        .zip(d.iter_mut())
    {
        let amax = xb.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let (scale, inv) = q8_scale(amax);
        *db = scale;
        for (qv, &v) in qb.iter_mut().zip(xb) {
            *qv = libm::roundf(v * inv) as i8;
        }
    }
}

/// The scale `d` of an activation block of largest magnitude `amax` and the
/// factor `1 / d` its values are multiplied by before rounding, as every
/// quantiser kernel computes them (scalar IEEE operations, so every ISA
/// gives the same bits). A block of zeros gets `(0, 0)`. So does a block
/// below ~1.5e-36 (`d` subnormal, `1 / d` overflows to infinity): its
/// values would otherwise become infinities, which the scalar cast and the
/// SIMD conversions turn into different integers; its contribution to any
/// product is below `256 d` per value either way. Non-finite activations
/// give a non-finite `d` and `1 / d = 0` (the NaN reaches the output, never
/// a panic).
#[inline]
pub fn q8_scale(amax: f32) -> (f32, f32) {
    let scale = amax / 127.0;
    let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
    if inv == f32::INFINITY {
        (0.0, 0.0)
    } else {
        (scale, inv)
    }
}

// ---------------------------------------------------------------------
// Int8 GEMM with activations quantised once per call (`linear` over a
// `Q8Rows` matrix): the activation rows are quantised into a panel
// ([`quantise_q8_corr`]), the weight scales of a tile of weight rows are
// read out once ([`q8_scales`]), and [`gemm_q8`] forms a `M x TN` tile of
// dot products with integer arithmetic per block of 32.
// ---------------------------------------------------------------------

/// [`quantise_q8`] (bit-identical `q` and `d`) that also writes, per
/// block `b` and lane parity `j`, the offset correction `c[2b + j] = -128 *
/// sum(q[32b + i] : (i % 8) / 4 == j)` the unsigned x signed VNNI dot needs
/// (`sum((w + 128) q) + c = sum(w q)`, exact per 4-byte lane class).
/// `c` >= 2 * x.len() / 32.
#[inline]
pub fn quantise_q8_corr(x: &[f32], q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f, avx2 and fma).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::quantise_q8_corr_512(x, q, d, c) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies avx2 + fma).
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::quantise_q8_corr(x, q, d, c) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::quantise_q8_corr(x, q, d, c) },
        _ => scalar::quantise_q8_corr(x, q, d, c),
    }
}

/// The f16 block scales of one stored Q8Block32 row as f32 (`out` >= blocks).
#[inline]
pub fn q8_scales(row: &[u8], out: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies f16c).
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::q8_scales(row, out)
        },
        _ => scalar::q8_scales(row, out),
    }
}

/// A `M x TN` tile of int8 dot products: `out[m][n] = sum_b (wd[n][b] *
/// xd[m][b]) * (w[n] block b . xq[m] block b)` over the fewest blocks of
/// any argument, with `w[n]` stored Q8Block32 rows (their f16 scales are
/// not read: `wd[n]` holds them as f32, [`q8_scales`]), and `xq` / `xd` /
/// `xc` from [`quantise_q8_corr`]. `M` is 1..=4 (small-batch and
/// matrix-vector products waste no lanes on padding rows).
#[inline]
pub fn gemm_q8<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds Avx512Vnni only via COMPILE_TIME_ISA or `set_isa`,
        // whose caller vouched for avx512f/bw/dq/vl/vnni + avx2/fma/f16c.
        Isa::Avx512Vnni => unsafe { x86::gemm_q8_vnni(w, wd, xq, xd, xc) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as above, without vnni.
        Isa::Avx512 => unsafe { x86::gemm_q8_512(w, wd, xq, xd, xc) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::gemm_q8_avx2(w, wd, xq, xd, xc) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: ISA holds NeonDot only via COMPILE_TIME_ISA (dotprod enabled
        // at build time) or `set_isa`, whose caller vouched for the CPU.
        Isa::NeonDot => unsafe { neon::gemm_q8_dot(w, wd, xq, xd, xc) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::gemm_q8(w, wd, xq, xd, xc) },
        _ => scalar::gemm_q8(w, wd, xq, xd, xc),
    }
}

/// `y += a * x` over the shorter length (attention's probability-weighted
/// value rows, the transposed-convolution GEMM).
#[inline]
pub fn axpy_f32(a: f32, x: &[f32], y: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::axpy_f32(a, x, y)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::axpy_f32(a, x, y) },
        _ => scalar::axpy_f32(a, x, y),
    }
}

/// `s[i] = e^(s[i] - max)` and their sum (a softmax's numerator and
/// denominator): [`scalar::exp`] (Cephes-style polynomial, max relative
/// error ~2e-7 vs libm); the AVX2 and NEON variants are bit-identical to
/// the twin (same operations, no FMA, the same 8 lane sums).
#[inline]
pub fn exp_shifted_sum(s: &mut [f32], max: f32) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f and avx2).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::exp_shifted_sum_512(s, max) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::exp_shifted_sum(s, max) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::exp_shifted_sum(s, max) },
        _ => scalar::exp_shifted_sum(s, max),
    }
}

/// The softmax of one attention row over its runs of allowed keys
/// (`runs`: ascending `(start, end)` pairs within `row`): the scores
/// scaled by `scale` and their maximum ([`scale_max`] run after run), the
/// shifted exponentials and their sum ([`exp_shifted_sum`] per run, the
/// runs' sums added in order), then each probability times `1 / sum` (0
/// when the sum is 0: such a row keeps zeros). Returns the sum. One call
/// per row where the attention made three per run (a query of the R
/// step's coordinated attention sees 10 runs): the same operations, so
/// bit for bit what those calls give.
#[inline]
pub fn softmax_runs(row: &mut [f32], runs: &[(usize, usize)], scale: f32) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f and avx2).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::softmax_runs_512(row, runs, scale) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::softmax_runs_avx2(row, runs, scale) },
        _ => softmax_runs_with(row, runs, scale, scale_max, exp_shifted_sum),
    }
}

/// The body of [`softmax_runs`] over given [`scale_max`] and
/// [`exp_shifted_sum`] variants (inlined into each ISA's caller, so the
/// pieces inline too).
#[inline(always)]
pub(crate) fn softmax_runs_with(
    row: &mut [f32],
    runs: &[(usize, usize)],
    scale: f32,
    scale_max: impl Fn(&mut [f32], f32, f32) -> f32,
    exp_shifted_sum: impl Fn(&mut [f32], f32) -> f32,
) -> f32 {
    let mut max = f32::NEG_INFINITY;
    for &(a, b) in runs {
        max = scale_max(&mut row[a..b], scale, max);
    }
    let mut sum = 0.0f32;
    for &(a, b) in runs {
        sum += exp_shifted_sum(&mut row[a..b], max);
    }
    let inv = if sum == 0.0 { 0.0 } else { 1.0 / sum };
    for &(a, b) in runs {
        for s in row[a..b].iter_mut() {
            *s *= inv;
        }
    }
    sum
}

/// `s[i] *= scale`, and the largest of `max` and the scaled values
/// (`f32::max`: NaN scores are skipped; `max` itself is not NaN): the
/// attention's scaled scores and softmax shift. The maximum of a set is
/// exact and independent of the order, so every variant returns the twin's
/// value (only the sign of a zero maximum may differ, which
/// [`exp_shifted_sum`] does not see); the scaled scores are the twin's.
#[inline]
pub fn scale_max(s: &mut [f32], scale: f32, max: f32) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::scale_max_512(s, scale, max) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::scale_max_avx2(s, scale, max) },
        _ => scalar::scale_max(s, scale, max),
    }
}

/// One LayerNorm row, `y = (x - mean) / sqrt(var + eps) * w + b` (biased
/// variance), over the shortest of the four slices: mean and variance as 8
/// lane sums ([`scalar::layernorm_row`]); the AVX2 and NEON variants are
/// bit-identical to the twin.
#[inline]
pub fn layernorm_row(x: &[f32], w: &[f32], b: &[f32], eps: f32, y: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::layernorm_row(x, w, b, eps, y)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::layernorm_row(x, w, b, eps, y) },
        _ => scalar::layernorm_row(x, w, b, eps, y),
    }
}

/// Exact GELU in place, erf by Abramowitz & Stegun 7.1.26 (absolute error
/// 1.5e-7) with [`scalar::exp`]; the AVX-512, AVX2 and NEON variants are
/// bit-identical to the twin on finite inputs.
#[inline]
pub fn gelu_inplace(x: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::gelu_inplace_512(x) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::gelu_inplace(x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::gelu_inplace(x) },
        _ => scalar::gelu_inplace(x),
    }
}

/// A GEMM's epilogue over one output segment: `y[j] = b[j] + t[j]` (`0 +
/// t[j]` without a bias), then [`gelu_inplace`] of it where `gelu`, over
/// the shortest slice ([`scalar::bias_act`]). AVX-512 does both in one
/// pass over 16 lanes; elsewhere the sum, then the ISA's GELU: each
/// variant is bit-identical to the twin.
#[inline]
pub fn bias_act(t: &[f32], b: Option<&[f32]>, gelu: bool, y: &mut [f32]) {
    if y.len() < 16 && !gelu {
        // A small tile's few sums: the twin inline costs less than a call.
        return scalar::bias_act(t, b, false, y);
    }
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::bias_act_512(t, b, gelu, y) },
        _ => {
            scalar::bias_act(t, b, false, y);
            if gelu {
                let n = t.len().min(b.map_or(t.len(), <[f32]>::len)).min(y.len());
                gelu_inplace(&mut y[..n]);
            }
        }
    }
}

/// [`bias_act`] on whole rows of 16 values in place: `rows[m][j] = b[j] +
/// rows[m][j]` (`0 + ...` without a bias), then GELU where `gelu`; the
/// same values as [`bias_act`] row by row, bit for bit. On AVX-512 four
/// rows at a time, on AVX2 / AVX-VNNI two (four 8-lane vectors), their
/// GELUs interleaved (the tile pair kernel's call hands over 5-8 rows of
/// 16 columns: the MLP's first layer in R mode).
#[inline]
pub fn bias_act_rows(rows: &mut [[f32; 16]], b: Option<&[f32; 16]>, gelu: bool) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::bias_act_rows_512(rows, b, gelu) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::bias_act_rows_avx2(rows, b, gelu) },
        _ => {
            for r in rows {
                let t = *r;
                bias_act(&t, b.map(|b| &b[..]), gelu, r);
            }
        }
    }
}

/// `out[j] = q . k[j * stride ..][..q.len()]` for `j < out.len()` (one
/// attention query against a run of key rows of a strided matrix; `k`
/// holds at least `(out.len() - 1) * stride + q.len()` floats when
/// `out` is not empty).
#[inline]
pub fn dot_rows(q: &[f32], k: &[f32], stride: usize, out: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::dot_rows_512(q, k, stride, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::dot_rows(q, k, stride, out) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::dot_rows(q, k, stride, out) },
        _ => scalar::dot_rows(q, k, stride, out),
    }
}

/// [`dot_rows`] over binary16 key rows (an f16 K/V cache read in place):
/// the same operations in the same order as [`dot_rows`] on the exactly
/// widened rows, so the result is bit-identical to widening first.
#[inline]
pub fn dot_rows_f16(q: &[f32], k: &[u16], stride: usize, out: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f/bw/vl and f16c).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::dot_rows_512_f16(q, k, stride, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::dot_rows_f16(q, k, stride, out) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::dot_rows_f16(q, k, stride, out) },
        _ => scalar::dot_rows_f16(q, k, stride, out),
    }
}

/// Weight rows of a packed int8 tile ([`PackedQ8`]).
pub const PACK_ROWS: usize = 8;
/// Blocks (of 32 columns) a [`Q8Pack8`] holds: inputs up to 3072 wide.
pub const PACK_BLOCKS: usize = 96;
/// Value bytes of one block of a packed tile (8 rows x 32).
pub const PACK_BLOCK_VALUES: usize = PACK_ROWS * Q8_BLOCK;
/// Scale bytes of one block of a packed tile (8 f16).
pub const PACK_BLOCK_SCALES: usize = PACK_ROWS * 2;

/// Value bytes of one block of a packed 4-bit tile (8 rows x 16).
pub const PACK_BLOCK_NIBBLES: usize = PACK_ROWS * Q8_BLOCK / 2;

/// 8 weight rows over `nb` blocks in the interleaved layout of
/// `DType::Q8Block32x8` or `DType::Q4Block32x8` (docs/FORMAT.md §4).
///
/// int8 (`from_group`): `v` holds, per block `b` and 8-byte group `g`
/// (0..4), values `8g..8g + 8` of block `b` of rows 0..8 (row `n` at
/// `256b + 64g + 8n`), signed.
///
/// 4-bit (`from_q4_group`): `v` holds, per block `b`, two 64-byte halves
/// `h` (0, 1): row `n`'s stored Q4Block32 bytes `8h..8h + 8` at `128b +
/// 64h + 8n` (byte `j` of a row: element `j` in the low nibble, `j + 16`
/// in the high one, each `q + 8`), so the low nibbles of half `h` are group
/// `h` and the high nibbles group `h + 2` of the int8 layout.
///
/// Both: `s` holds row `n`'s f16 scale of block `b` at `16b + 2n`. This is
/// the operand order `vpdpbusd` (and `sdot`) want with each activation
/// 8-byte group broadcast: one packing serves every activation row of a
/// panel, and an x8 file stores its row groups this way, so its tiles need
/// no packing at all.
#[derive(Clone, Copy, Debug)]
pub struct PackedQ8<'a> {
    v: &'a [u8],
    s: &'a [u8],
    nb: usize,
    q4: bool,
}

impl<'a> PackedQ8<'a> {
    /// One stored int8 group of `nb` blocks (`nb * 256` value bytes then
    /// `nb * 16` scale bytes); None if `group` is shorter.
    pub fn from_group(group: &'a [u8], nb: usize) -> Option<Self> {
        Self::split(group, nb, PACK_BLOCK_VALUES, false)
    }
    /// One stored 4-bit group of `nb` blocks (`nb * 128` value bytes then
    /// `nb * 16` scale bytes); None if `group` is shorter.
    pub fn from_q4_group(group: &'a [u8], nb: usize) -> Option<Self> {
        Self::split(group, nb, PACK_BLOCK_NIBBLES, true)
    }
    fn split(group: &'a [u8], nb: usize, per_block: usize, q4: bool) -> Option<Self> {
        let nv = nb.checked_mul(per_block)?;
        let ns = nb.checked_mul(PACK_BLOCK_SCALES)?;
        let v = group.get(..nv)?;
        let s = group.get(nv..nv.checked_add(ns)?)?;
        Some(PackedQ8 { v, s, nb, q4 })
    }
    pub fn blocks(&self) -> usize {
        self.nb
    }
    /// The blocks a packed kernel computes: the group's, cut to what every
    /// activation row, scale row and correction row (2 per block) holds.
    #[inline]
    pub(crate) fn blocks_for<const M: usize, const C: usize>(
        &self,
        xq: [&[i8]; M],
        xd: [&[f32]; M],
        xc: [&[i32]; C],
    ) -> usize {
        let pv = if self.q4 {
            PACK_BLOCK_NIBBLES
        } else {
            PACK_BLOCK_VALUES
        };
        xq.iter()
            .map(|r| r.len() / Q8_BLOCK)
            .chain(xd.iter().map(|r| r.len()))
            .chain(xc.iter().map(|r| r.len() / 2))
            .fold(
                self.nb
                    .min(self.v.len() / pv)
                    .min(self.s.len() / PACK_BLOCK_SCALES),
                usize::min,
            )
    }
    /// Row `n`'s value `i` (0..32) of block `b` (`n < 8`, `b < nb`), as the
    /// signed integer the scale multiplies.
    #[inline]
    pub fn value(&self, b: usize, n: usize, i: usize) -> i8 {
        if self.q4 {
            let (g, k) = (i / 8, i % 8);
            let byte = self.v[PACK_BLOCK_NIBBLES * b + 64 * (g % 2) + 8 * n + k];
            let nib = if g < 2 { byte & 0x0f } else { byte >> 4 };
            nib as i8 - 8
        } else {
            self.v[PACK_BLOCK_VALUES * b + 64 * (i / 8) + 8 * n + i % 8] as i8
        }
    }
    /// Row `n`'s f16 scale bits of block `b`.
    #[inline]
    pub fn scale_bits(&self, b: usize, n: usize) -> u16 {
        u16::from_le_bytes([
            self.s[PACK_BLOCK_SCALES * b + 2 * n],
            self.s[PACK_BLOCK_SCALES * b + 2 * n + 1],
        ])
    }
    /// Row `n`'s block `b` as a stored Q8Block32 block (`dst`: at least 34
    /// bytes: the f16 scale, then the 32 values): [`Self::scale_bits`] and
    /// [`Self::value`] for every value, taken 8-byte group by group (one
    /// copy per group for int8; per value, the element-wise reads cost more
    /// than the dot products of the tiles that use them).
    pub fn q8_block_of_row(&self, b: usize, n: usize, dst: &mut [u8]) {
        dst[..2].copy_from_slice(&self.scale_bits(b, n).to_le_bytes());
        let vals = &mut dst[2..2 + Q8_BLOCK];
        if self.q4 {
            let base = PACK_BLOCK_NIBBLES * b + 8 * n;
            for (g, d) in vals.chunks_exact_mut(8).enumerate() {
                let src = &self.v[base + 64 * (g % 2)..base + 64 * (g % 2) + 8];
                for (q, &byte) in d.iter_mut().zip(src) {
                    let nib = if g < 2 { byte & 0x0f } else { byte >> 4 };
                    *q = (nib as i8 - 8) as u8;
                }
            }
        } else {
            let base = PACK_BLOCK_VALUES * b + 8 * n;
            for (g, d) in vals.chunks_exact_mut(8).enumerate() {
                d.copy_from_slice(&self.v[base + 64 * g..base + 64 * g + 8]);
            }
        }
    }
}

/// Room for one tile of 8 stored Q8Block32 rows packed on the fly
/// ([`q8_pack8`]; the layout of [`PackedQ8`]).
#[repr(C, align(64))]
pub struct Q8Pack8 {
    v: [u8; PACK_BLOCKS * PACK_BLOCK_VALUES],
    s: [u8; PACK_BLOCKS * PACK_BLOCK_SCALES],
    nb: usize,
}

impl Q8Pack8 {
    pub fn new() -> Self {
        Q8Pack8 {
            v: [0; PACK_BLOCKS * PACK_BLOCK_VALUES],
            s: [0; PACK_BLOCKS * PACK_BLOCK_SCALES],
            nb: 0,
        }
    }
    /// The packed tile of the last [`q8_pack8`].
    pub fn view(&self) -> PackedQ8<'_> {
        let nb = self.nb.min(PACK_BLOCKS);
        PackedQ8 {
            v: &self.v[..nb * PACK_BLOCK_VALUES],
            s: &self.s[..nb * PACK_BLOCK_SCALES],
            nb,
            q4: false,
        }
    }
}

impl Default for Q8Pack8 {
    fn default() -> Self {
        Self::new()
    }
}

/// Whether [`gemm_q8_packed`] has a SIMD variant on the selected ISA
/// (x86: AVX2, AVX-512, AVX512-VNNI; aarch64: NEON with dotprod), so that
/// stored row groups (`Q8Block32x8`, `Q4Block32x8`) are read in place;
/// callers expand them to rows for [`gemm_q8`] otherwise.
#[inline]
pub fn packed_q8_fast() -> bool {
    matches!(
        isa(),
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni | Isa::NeonDot
    )
}

/// Whether packing 8 stored rows per tile ([`q8_pack8`]) for
/// [`gemm_q8_packed`] pays off over [`gemm_q8`] on the rows (AVX512-VNNI,
/// from a few activation rows on: measured). Elsewhere the packing itself
/// is the scalar twin's byte copy.
#[inline]
pub fn q8_packing_pays() -> bool {
    isa() == Isa::Avx512Vnni
}

/// Packs 8 stored Q8Block32 rows (first `nb` blocks; `nb <= PACK_BLOCKS`,
/// every row at least `nb` blocks), scales included: a pure byte
/// rearrangement (the layout of [`PackedQ8`]).
pub fn q8_pack8(rows: [&[u8]; PACK_ROWS], nb: usize, pack: &mut Q8Pack8) {
    let nb = nb.min(PACK_BLOCKS);
    pack.nb = nb;
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `gemm_q8_packed`.
        Isa::Avx512Vnni => unsafe { x86::q8_pack8(rows, nb, &mut pack.v, &mut pack.s) },
        _ => scalar::q8_pack8(rows, nb, &mut pack.v, &mut pack.s),
    }
}

/// `out[m][n] = sum_b (s_n,b * xd[m][b]) * (row n block b . xq[m] block b)`
/// over the packed rows (see [`gemm_q8`]; `xc` from [`quantise_q8_corr`]).
/// `M` is 1..=12 (`linear` hands it at most 12 rows per call).
#[inline]
pub fn gemm_q8_packed<const M: usize>(
    w: PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; PACK_ROWS]; M] {
    gemm_q8_packed_ahead(w, xq, xd, xc, &[])
}

/// [`gemm_q8_packed`] that also prefetches `ahead` (the weights of a later
/// tile) into L2, spread over its blocks (the SIMD variants; a hint, no
/// numeric effect).
#[inline]
pub fn gemm_q8_packed_ahead<const M: usize>(
    w: PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; PACK_ROWS]; M] {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds Avx512Vnni only via COMPILE_TIME_ISA or `set_isa`,
        // whose caller vouched for avx512f/bw/dq/vl/vnni + avx2/fma/f16c.
        Isa::Avx512Vnni => unsafe { x86::gemm_q8_packed_vnni_ahead(w, xq, xd, xc, ahead) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds Avx2 or Avx512 only via COMPILE_TIME_ISA or
        // `set_isa`, whose caller vouched for avx2/fma/f16c (both imply them).
        Isa::Avx2 | Isa::Avx512 => unsafe { x86::gemm_q8_packed_avx2_ahead(w, xq, xd, xc, ahead) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds AvxVnni only via COMPILE_TIME_ISA or `set_isa`,
        // whose caller vouched for avx2/fma/f16c/avxvnni.
        Isa::AvxVnni => unsafe { x86::gemm_q8_packed_avxvnni_ahead(w, xq, xd, xc, ahead) },
        #[cfg(target_arch = "aarch64")]
        // SAFETY: as below, and `i8mm::enable`'s caller vouched for i8mm.
        Isa::NeonDot if i8mm::enabled() => unsafe {
            neon::gemm_q8_packed_i8mm_ahead(w, xq, xd, xc, ahead)
        },
        #[cfg(target_arch = "aarch64")]
        // SAFETY: ISA holds NeonDot only via COMPILE_TIME_ISA or `set_isa`,
        // whose caller vouched for neon + dotprod.
        Isa::NeonDot => unsafe { neon::gemm_q8_packed_dot_ahead(w, xq, xd, xc, ahead) },
        _ => {
            prefetch_l2(ahead);
            scalar::gemm_q8_packed(w, xq, xd, xc)
        }
    }
}

/// `y += sum_j coef[j] * row j` (row `j`: `x[j * stride ..][..y.len()]`;
/// rows that are not whole are left out): attention's probability-weighted
/// values of one query and head. Per lane the same operations in the same
/// order as [`axpy_f32`] called row after row (bit-identical to that), with
/// the output lanes held in registers across the rows.
#[inline]
pub fn axpy_rows_f32(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::axpy_rows_512_f32(coef, x, stride, y) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::axpy_rows_f32(coef, x, stride, y) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::axpy_rows_f32(coef, x, stride, y) },
        _ => scalar::axpy_rows_f32(coef, x, stride, y),
    }
}

/// [`axpy_rows_f32`] over binary16 rows (an f16 value cache read in
/// place): [`axpy_f16`] row after row, bit for bit.
#[inline]
pub fn axpy_rows_f16(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies f16c).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe { x86::axpy_rows_512_f16(coef, w, stride, y) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies f16c).
        Isa::Avx2 | Isa::AvxVnni => unsafe { x86::axpy_rows_f16(coef, w, stride, y) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::axpy_rows_f16(coef, w, stride, y) },
        _ => scalar::axpy_rows_f16(coef, w, stride, y),
    }
}

/// Most queries one register block of [`dot_rows_group`] /
/// [`axpy_rows_group_f32`] holds (larger groups go this many at a time):
/// 5 x 4 query registers plus 5 sums (AVX-512 has 32), so a GPT
/// position's 10 stream rows are two groups. Measured against 4 (4 + 4 +
/// 2; 2026-12-03, the Xeon, two rounds each, kernel bench): the R window's
/// attention 0.92-0.93x, 192 S appends over one hot f16 cache 0.87-0.95x
/// (one append alone: the same within noise).
pub const QUERY_GROUP: usize = 5;

/// [`dot_rows`] for `g` queries against the same `n` key rows: query `m`
/// is `q[m q_stride ..][..hd]`, its scores go to `out[m
/// out_stride ..][..n]` (`out_stride >= n`). Bit for bit [`dot_rows`] per
/// query on every ISA; AVX-512 loads each key row once for up to
/// [`QUERY_GROUP`] queries (heads of at most 64 lanes), the others call
/// [`dot_rows`] per query. `side`: bytes prefetched into L2 spread over
/// the pass (key by key: the next attention's keys, read while this one
/// computes; no result depends on it); only the AVX-512 kernels use it,
/// for heads of at most 64 lanes.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn dot_rows_group(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    k: &[f32],
    stride: usize,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::dot_rows_512_group(q, hd, q_stride, g, k, stride, n, out, out_stride, side)
        },
        _ => {
            let _ = side;
            per_query(q, hd, q_stride, g, n, out, out_stride, |qm, o| {
                dot_rows(qm, k, stride, o)
            })
        }
    }
}

/// [`dot_rows_group`] over binary16 key rows: bit for bit
/// [`dot_rows_f16`] per query.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn dot_rows_group_f16(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    k: &[u16],
    stride: usize,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx512* imply avx512f/bw/vl and f16c).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::dot_rows_512_group_f16(q, hd, q_stride, g, k, stride, n, out, out_stride, side)
        },
        _ => {
            let _ = side;
            per_query(q, hd, q_stride, g, n, out, out_stride, |qm, o| {
                dot_rows_f16(qm, k, stride, o)
            })
        }
    }
}

/// `f(query m, its n scores)` for each query of a [`dot_rows_group`] call.
#[allow(clippy::too_many_arguments)]
fn per_query(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    mut f: impl FnMut(&[f32], &mut [f32]),
) {
    for m in 0..g {
        f(
            &q[m * q_stride..m * q_stride + hd],
            &mut out[m * out_stride..m * out_stride + n],
        );
    }
}

/// [`axpy_rows_f32`] for `g` queries over the same value rows: query `m`'s
/// coefficients are `coef[m coef_stride ..][..nk]`, its output `y[m
/// y_stride ..][..n]`. Bit for bit [`axpy_rows_f32`] per query on
/// every ISA; AVX-512 loads each value row once for up to [`QUERY_GROUP`]
/// queries, the others call [`axpy_rows_f32`] per query. `side`: as in
/// [`dot_rows_group`].
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn axpy_rows_group_f32(
    coef: &[f32],
    coef_stride: usize,
    nk: usize,
    x: &[f32],
    stride: usize,
    y: &mut [f32],
    y_stride: usize,
    n: usize,
    g: usize,
    side: &[u8],
) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::axpy_rows_512_group_f32(coef, coef_stride, nk, x, stride, y, y_stride, n, g, side)
        },
        _ => {
            let _ = side;
            per_query_axpy(coef, coef_stride, nk, y, y_stride, n, g, |c, ym| {
                axpy_rows_f32(c, x, stride, ym)
            })
        }
    }
}

/// [`axpy_rows_group_f32`] over binary16 rows: bit for bit
/// [`axpy_rows_f16`] per query.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn axpy_rows_group_f16(
    coef: &[f32],
    coef_stride: usize,
    nk: usize,
    w: &[u16],
    stride: usize,
    y: &mut [f32],
    y_stride: usize,
    n: usize,
    g: usize,
    side: &[u8],
) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies f16c).
        Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::axpy_rows_512_group_f16(coef, coef_stride, nk, w, stride, y, y_stride, n, g, side)
        },
        _ => {
            let _ = side;
            per_query_axpy(coef, coef_stride, nk, y, y_stride, n, g, |c, ym| {
                axpy_rows_f16(c, w, stride, ym)
            })
        }
    }
}

/// `f(query m's coefficients, its output row)` for each query of an
/// [`axpy_rows_group_f32`] call.
#[allow(clippy::too_many_arguments)]
fn per_query_axpy(
    coef: &[f32],
    coef_stride: usize,
    nk: usize,
    y: &mut [f32],
    y_stride: usize,
    n: usize,
    g: usize,
    mut f: impl FnMut(&[f32], &mut [f32]),
) {
    for m in 0..g {
        f(
            &coef[m * coef_stride..m * coef_stride + nk],
            &mut y[m * y_stride..m * y_stride + n],
        );
    }
}

/// `y += a * w` with binary16 `w` (exact f16 -> f32), over the shorter
/// length: the same operations as [`axpy_f32`] on the widened `w`
/// (bit-identical to widening first).
#[inline]
pub fn axpy_f16(a: f32, w: &[u16], y: &mut [f32]) {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (every x86 variant implies f16c).
        Isa::Avx2 | Isa::AvxVnni | Isa::Avx512 | Isa::Avx512Vnni => unsafe {
            x86::axpy_f16(a, w, y)
        },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon | Isa::NeonDot => unsafe { neon::axpy_f16(a, w, y) },
        _ => scalar::axpy_f16(a, w, y),
    }
}

/// Whether the tile pair kernels run ([`tile_pair::enabled`]: AVX-512
/// VNNI, AVX-VNNI, AVX2; never off x86_64) on rows of `nb` blocks: at most
/// [`PACK_BLOCKS`], and on AVX2, whose operand holds its values as i16, at
/// most [`tile_pair::WIDE_BLOCKS`].
#[inline]
pub fn pair_takes(nb: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    return tile_pair::enabled()
        && nb <= if tile_pair::wide_isa() { tile_pair::WIDE_BLOCKS } else { PACK_BLOCKS };
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = nb;
        false
    }
}

/// Whether the AMX int8 kernel runs ([`amx::enabled`]; never off x86_64).
#[inline]
pub fn amx_enabled() -> bool {
    #[cfg(target_arch = "x86_64")]
    return amx::enabled();
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The AMX and tile pair entry points on targets without them: nothing is
/// prepared and no row is computed, so callers take [`gemm_q8_packed`] for
/// every row.
#[cfg(not(target_arch = "x86_64"))]
mod no_amx {
    /// As on x86_64.
    pub const ROWS: usize = 12;
    /// As on x86_64.
    pub const COLS: usize = 2 * super::PACK_ROWS;
    /// As on x86_64.
    pub const PAIR_CALL_ROWS: usize = 8;
    /// Holds nothing.
    pub struct TilePair;
    impl TilePair {
        pub fn new() -> Self {
            TilePair
        }
        /// Always false.
        pub fn prepare(&mut self, _: usize, _: super::PackedQ8<'_>) -> bool {
            false
        }
        /// Always false.
        pub fn prepare_both(&mut self, _: super::PackedQ8<'_>, _: super::PackedQ8<'_>) -> bool {
            false
        }
        /// Always false.
        pub fn unsigned(&self) -> bool {
            false
        }
        /// Always false.
        pub fn ready(&self) -> bool {
            false
        }
    }
    impl Default for TilePair {
        fn default() -> Self {
            Self::new()
        }
    }
    /// Always None.
    pub fn gemm_q8_pair<const M: usize>(
        _: &TilePair,
        _: &[i8],
        _: &[f32],
        _: &[i32],
        _: usize,
        _: &[u8],
    ) -> Option<[[f32; 2 * super::PACK_ROWS]; M]> {
        None
    }
    /// Always 0 rows.
    pub fn amx_rows(_: usize, _: usize, _: usize, _: usize, _: usize) -> usize {
        0
    }
    /// Always 0 rows.
    #[allow(clippy::too_many_arguments)]
    pub fn gemm_q8_packed_amx(
        _: &TilePair,
        _: &[i8],
        _: usize,
        _: &[f32],
        _: crate::kernels::parallel::Window<'_>,
        _: Option<&[f32]>,
        _: bool,
        _: &[u8],
    ) -> usize {
        0
    }
}
