//! aarch64 NEON variants of the [`super::scalar`] kernels. Compiled only
//! when the target enables NEON (baseline on aarch64 Linux/Android/Apple
//! and on `aarch64-unknown-none`). All memory access goes through
//! `chunks_exact` sub-slices, so loads are in bounds by construction.
//!
//! f16 -> f32 is done with integer ops (the NEON `fcvtl` intrinsic needs the
//! unstable f16 vector types): `bits(|h| << 13) * 2^112` is exact for every
//! finite binary16 value (normal and subnormal); Inf/NaN get the f32
//! all-ones exponent; then the sign is put back.

use core::arch::aarch64::*;

use super::scalar::{common, common_blocks};
use super::{pairwise, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

/// 4 binary16 values (low 16 bits of each u32 lane... as a u16x4) to f32x4.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn f16x4_to_f32(h: uint16x4_t) -> float32x4_t {
    let h32 = vmovl_u16(h);
    let sign = vshlq_n_u32::<16>(vandq_u32(h32, vdupq_n_u32(0x8000)));
    let mag = vandq_u32(h32, vdupq_n_u32(0x7fff));
    let scaled = vmulq_f32(vreinterpretq_f32_u32(vshlq_n_u32::<13>(mag)), vdupq_n_f32(f32::from_bits(0x7780_0000))); // 2^112
    // exponent all ones (Inf/NaN): force the f32 exponent to all ones.
    let is_special = vcgeq_u32(mag, vdupq_n_u32(0x7c00));
    let special = vorrq_u32(vshlq_n_u32::<13>(mag), vdupq_n_u32(0x7f80_0000));
    let bits = vbslq_u32(is_special, special, vreinterpretq_u32_f32(scaled));
    vreinterpretq_f32_u32(vorrq_u32(bits, sign))
}

/// # Safety
/// NEON must be available (guaranteed where this module is compiled).
#[target_feature(enable = "neon")]
pub unsafe fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [vdupq_n_f32(0.0); 4];
    let (a16, ar) = a.split_at(n - n % 16);
    let (b16, br) = b.split_at(n - n % 16);
    for (x, y) in a16.chunks_exact(16).zip(b16.chunks_exact(16)) {
        for (l, accl) in acc.iter_mut().enumerate() {
            // SAFETY: x and y hold 16 floats; lanes l*4..l*4+4 are in bounds.
            let (xv, yv) = unsafe { (vld1q_f32(x.as_ptr().add(l * 4)), vld1q_f32(y.as_ptr().add(l * 4))) };
            *accl = vfmaq_f32(*accl, xv, yv);
        }
    }
    let (a4, a1) = ar.split_at(ar.len() - ar.len() % 4);
    let (b4, b1) = br.split_at(a4.len());
    for (x, y) in a4.chunks_exact(4).zip(b4.chunks_exact(4)) {
        // SAFETY: 4 floats each.
        let (xv, yv) = unsafe { (vld1q_f32(x.as_ptr()), vld1q_f32(y.as_ptr())) };
        acc[0] = vfmaq_f32(acc[0], xv, yv);
    }
    let s = vaddq_f32(vaddq_f32(acc[0], acc[1]), vaddq_f32(acc[2], acc[3]));
    let mut tail = 0.0f32;
    for (x, y) in a1.iter().zip(b1) {
        tail += x * y;
    }
    vaddvq_f32(s) + tail
}

/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn dot_f16(w: &[u16], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let (w, x) = (&w[..n], &x[..n]);
    let mut acc = [vdupq_n_f32(0.0); 2];
    let (w8, wr) = w.split_at(n - n % 8);
    let (x8, xr) = x.split_at(n - n % 8);
    for (wc, xc) in w8.chunks_exact(8).zip(x8.chunks_exact(8)) {
        // SAFETY: wc holds 8 u16, xc 8 floats.
        let (wv, x0, x1) = unsafe { (vld1q_u16(wc.as_ptr()), vld1q_f32(xc.as_ptr()), vld1q_f32(xc.as_ptr().add(4))) };
        acc[0] = vfmaq_f32(acc[0], f16x4_to_f32(vget_low_u16(wv)), x0);
        acc[1] = vfmaq_f32(acc[1], f16x4_to_f32(vget_high_u16(wv)), x1);
    }
    let mut tail = 0.0f32;
    for (a, b) in wr.iter().zip(xr) {
        tail += super::f16_to_f32(*a) * b;
    }
    vaddvq_f32(vaddq_f32(acc[0], acc[1])) + tail
}

/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    let nb = (w.len() / Q8_BLOCK_BYTES).min(xq.len() / Q8_BLOCK).min(xd.len());
    let mut acc = vdupq_n_f32(0.0);
    for ((blk, xs), &dx) in w.chunks_exact(Q8_BLOCK_BYTES).zip(xq.chunks_exact(Q8_BLOCK)).zip(xd).take(nb) {
        let d = super::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) * dx;
        let q = &blk[2..];
        // SAFETY: q and xs hold exactly 32 bytes each (two 16-byte loads).
        let (w0, w1, x0, x1) = unsafe {
            (
                vld1q_s8(q.as_ptr() as *const i8),
                vld1q_s8(q.as_ptr().add(16) as *const i8),
                vld1q_s8(xs.as_ptr()),
                vld1q_s8(xs.as_ptr().add(16)),
            )
        };
        // i8 x i8 -> i16 products (|p| <= 128*127, exact), pairwise into i32.
        let mut s = vdupq_n_s32(0);
        s = vpadalq_s16(s, vmull_s8(vget_low_s8(w0), vget_low_s8(x0)));
        s = vpadalq_s16(s, vmull_high_s8(w0, x0));
        s = vpadalq_s16(s, vmull_s8(vget_low_s8(w1), vget_low_s8(x1)));
        s = vpadalq_s16(s, vmull_high_s8(w1, x1));
        acc = vfmaq_n_f32(acc, vcvtq_f32_s32(s), d);
    }
    vaddvq_f32(acc)
}

/// Tile of pairwise NEON dots over the common row length (no register-
/// blocked NEON kernel yet; same contract as [`super::scalar::tile_f32`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    // SAFETY: NEON is available (this fn's contract).
    pairwise(|m, n| unsafe { dot_f32(&w[n][..k], &x[m][..k]) })
}

/// Pairwise NEON tile with binary16 weights (see [`tile_f32`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    // SAFETY: NEON is available (this fn's contract).
    pairwise(|m, n| unsafe { dot_f16(&w[n][..k], &x[m][..k]) })
}

/// Pairwise NEON int8 tile (see [`tile_f32`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nb = common_blocks(&w, &xq, &xd);
    // SAFETY: NEON is available (this fn's contract).
    pairwise(|m, n| unsafe { dot_q8(&w[n][..nb * Q8_BLOCK_BYTES], &xq[m][..nb * Q8_BLOCK], &xd[m][..nb]) })
}
