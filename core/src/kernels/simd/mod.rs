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

pub mod scalar;
#[cfg(target_arch = "x86_64")]
pub mod x86;
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
}

/// The best ISA the compile-time target features guarantee.
pub const COMPILE_TIME_ISA: Isa = if cfg!(all(
    target_arch = "x86_64",
    target_feature = "avx2",
    target_feature = "fma",
    target_feature = "f16c"
)) {
    Isa::Avx2
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
        _ => Isa::Scalar,
    }
}

/// Selects the kernels every later call uses (process-wide).
///
/// # Safety
/// The CPU running this process must support `isa` (for [`Isa::Avx2`]:
/// avx2, fma and f16c; for [`Isa::Neon`]: an aarch64 CPU, which always has
/// it), and `isa` must be one this build has a variant for (an arm for a
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

/// `a . b` (f32 weights or activations).
#[inline]
pub fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: ISA holds Avx2 only via COMPILE_TIME_ISA (features enabled
        // at build time) or `set_isa`, whose caller vouched for the CPU.
        Isa::Avx2 => unsafe { x86::dot_f32(a, b) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::dot_f32(a, b) },
        _ => scalar::dot_f32(a, b),
    }
}

/// `w . x` with binary16 weights.
#[inline]
pub fn dot_f16(w: &[u16], x: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 => unsafe { x86::dot_f16(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::dot_f16(w, x) },
        _ => scalar::dot_f16(w, x),
    }
}

/// Blocked int8 dot (see [`scalar::dot_q8`]).
#[inline]
pub fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 => unsafe { x86::dot_q8(w, xq, xd) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::dot_q8(w, xq, xd) },
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
pub(crate) fn pairwise(mut f: impl FnMut(usize, usize) -> f32) -> Tile {
    let mut out = [[0.0; TN]; TM];
    for (m, row) in out.iter_mut().enumerate() {
        for (n, o) in row.iter_mut().enumerate() {
            *o = f(m, n);
        }
    }
    out
}

/// Register-blocked `x . w^T` tile with f32 weights: `out[m][n] = w[n] .
/// x[m]` over the shortest slice length (see [`scalar::tile_f32`]).
#[inline]
pub fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32`.
        Isa::Avx2 => unsafe { x86::tile_f32(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::tile_f32(w, x) },
        _ => scalar::tile_f32(w, x),
    }
}

/// [`tile_f32`] with binary16 weights (converted once per tile step).
#[inline]
pub fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    match isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `dot_f32` (Avx2 implies f16c).
        Isa::Avx2 => unsafe { x86::tile_f16(w, x) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::tile_f16(w, x) },
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
        Isa::Avx2 => unsafe { x86::tile_q8(w, xq, xd) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build (cfg above).
        Isa::Neon => unsafe { neon::tile_q8(w, xq, xd) },
        _ => scalar::tile_q8(w, xq, xd),
    }
}

/// Quantises activations for [`dot_q8`]: per block of 32, `d = max|x| /
/// 127` (f32) and `q = round(x / d)` in [-127, 127] (0 when the block is
/// all zeros). `x.len()` must be a multiple of 32 (a trailing partial
/// block is ignored); `q` >= x.len(), `d` >= x.len() / 32.
pub fn quantise_q8(x: &[f32], q: &mut [i8], d: &mut [f32]) {
    for ((xb, qb), db) in x.chunks_exact(Q8_BLOCK).zip(q.chunks_exact_mut(Q8_BLOCK)).zip(d.iter_mut()) {
        let amax = xb.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        // Non-finite activations give a non-finite scale (NaN propagates to
        // the output, never a panic); the i8 cast saturates.
        let scale = amax / 127.0;
        *db = scale;
        let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
        for (qv, &v) in qb.iter_mut().zip(xb) {
            *qv = libm::roundf(v * inv) as i8;
        }
    }
}
