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
use super::{distinct_rows, pairwise, pairwise_rows, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

/// 4 binary16 values (low 16 bits of each u32 lane... as a u16x4) to f32x4.
///
/// # Safety
/// The CPU must support neon (slices are bounds-checked).
#[inline]
#[target_feature(enable = "neon")]
unsafe fn f16x4_to_f32(h: uint16x4_t) -> float32x4_t {
    let h32 = vmovl_u16(h);
    let sign = vshlq_n_u32::<16>(vandq_u32(h32, vdupq_n_u32(0x8000)));
    let mag = vandq_u32(h32, vdupq_n_u32(0x7fff));
    let scaled = vmulq_f32(
        vreinterpretq_f32_u32(vshlq_n_u32::<13>(mag)),
        vdupq_n_f32(f32::from_bits(0x7780_0000)),
    ); // 2^112
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
            let (xv, yv) = unsafe {
                (
                    vld1q_f32(x.as_ptr().add(l * 4)),
                    vld1q_f32(y.as_ptr().add(l * 4)),
                )
            };
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
        let (wv, x0, x1) = unsafe {
            (
                vld1q_u16(wc.as_ptr()),
                vld1q_f32(xc.as_ptr()),
                vld1q_f32(xc.as_ptr().add(4)),
            )
        };
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
    let nb = (w.len() / Q8_BLOCK_BYTES)
        .min(xq.len() / Q8_BLOCK)
        .min(xd.len());
    let mut acc = vdupq_n_f32(0.0);
    for ((blk, xs), &dx) in w
        .chunks_exact(Q8_BLOCK_BYTES)
        .zip(xq.chunks_exact(Q8_BLOCK))
        .zip(xd)
        .take(nb)
    {
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
/// blocked NEON kernel yet; same contract as [`super::scalar::tile_f32`]);
/// activation rows repeated at the end are computed once
/// ([`distinct_rows`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    // SAFETY: NEON is available (this fn's contract).
    pairwise_rows(distinct_rows(&x), |m, n| unsafe {
        dot_f32(&w[n][..k], &x[m][..k])
    })
}

/// Pairwise NEON tile with binary16 weights (see [`tile_f32`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    let k = common(&w, &x);
    // SAFETY: NEON is available (this fn's contract).
    pairwise_rows(distinct_rows(&x), |m, n| unsafe {
        dot_f16(&w[n][..k], &x[m][..k])
    })
}

/// Pairwise NEON int8 tile (see [`tile_f32`]).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nb = common_blocks(&w, &xq, &xd);
    // SAFETY: NEON is available (this fn's contract).
    pairwise(|m, n| unsafe {
        dot_q8(
            &w[n][..nb * Q8_BLOCK_BYTES],
            &xq[m][..nb * Q8_BLOCK],
            &xd[m][..nb],
        )
    })
}

/// See [`super::quantise_q8_corr`]: `vrndaq_f32` is `roundf` exactly (ties
/// away from zero), `fcvtzs` maps NaN to 0 and `fmaxnm` ignores NaN like
/// `f32::max`, so the result is bit-identical to the scalar twin.
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn quantise_q8_corr(x: &[f32], q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    let blocks = x
        .chunks_exact(Q8_BLOCK)
        .zip(q.chunks_exact_mut(Q8_BLOCK))
        .zip(d.iter_mut().zip(c.chunks_exact_mut(2)));
    for ((xb, qb), (db, cb)) in blocks {
        // SAFETY: xb holds exactly 32 floats.
        let v: [float32x4_t; 8] =
            core::array::from_fn(|i| unsafe { vld1q_f32(xb.as_ptr().add(4 * i)) });
        let mut m = vdupq_n_f32(0.0);
        for vi in &v {
            m = vmaxnmq_f32(m, vabsq_f32(*vi));
        }
        let (scale, inv) = super::q8_scale(vmaxnmvq_f32(m));
        *db = scale;
        let r: [int32x4_t; 8] = v.map(|vi| vcvtq_s32_f32(vrndaq_f32(vmulq_n_f32(vi, inv))));
        // Quads 0, 2, 4, 6 are lane parity 0; 1, 3, 5, 7 parity 1.
        let s0 = vaddq_s32(vaddq_s32(r[0], r[2]), vaddq_s32(r[4], r[6]));
        let s1 = vaddq_s32(vaddq_s32(r[1], r[3]), vaddq_s32(r[5], r[7]));
        cb[0] = -128 * vaddvq_s32(s0);
        cb[1] = -128 * vaddvq_s32(s1);
        for (k, pair) in r.chunks_exact(4).enumerate() {
            let h0 = vcombine_s16(vqmovn_s32(pair[0]), vqmovn_s32(pair[1]));
            let h1 = vcombine_s16(vqmovn_s32(pair[2]), vqmovn_s32(pair[3]));
            let b = vcombine_s8(vqmovn_s16(h0), vqmovn_s16(h1));
            // SAFETY: qb holds 32 bytes: 16 at 16k, k in 0..2.
            unsafe { vst1q_s8(qb.as_mut_ptr().add(16 * k), b) };
        }
    }
}

/// `sdot` (4-way i8 dot into each i32 lane), via asm: the intrinsic is
/// not stable Rust yet.
///
/// # Safety
/// The CPU must support neon, dotprod (slices are bounds-checked).
#[inline]
#[target_feature(enable = "neon,dotprod")]
unsafe fn sdot(acc: int32x4_t, a: int8x16_t, b: int8x16_t) -> int32x4_t {
    let mut r = acc;
    // SAFETY: a register-only instruction of the dotprod extension (this
    // fn's target feature; the caller vouched for the CPU).
    unsafe {
        core::arch::asm!("sdot {0:v}.4s, {1:v}.16b, {2:v}.16b", inout(vreg) r, in(vreg) a, in(vreg) b, options(pure, nomem, nostack))
    };
    r
}

/// The 32 weights of block `b` of a stored row (two 16-byte vectors).
///
/// # Safety
/// The CPU must support neon (slices are bounds-checked).
#[inline]
#[target_feature(enable = "neon")]
unsafe fn wblock(row: &[u8], b: usize) -> [int8x16_t; 2] {
    let q = &row[b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
    // SAFETY: q holds exactly 32 bytes.
    unsafe {
        [
            vld1q_s8(q.as_ptr() as *const i8),
            vld1q_s8(q.as_ptr().add(16) as *const i8),
        ]
    }
}

/// The 32 quantised activations of block `b`.
///
/// # Safety
/// The CPU must support neon (slices are bounds-checked).
#[inline]
#[target_feature(enable = "neon")]
unsafe fn xblock(xq: &[i8], b: usize) -> [int8x16_t; 2] {
    let q = &xq[b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
    // SAFETY: q holds exactly 32 bytes.
    unsafe { [vld1q_s8(q.as_ptr()), vld1q_s8(q.as_ptr().add(16))] }
}

/// See [`super::gemm_q8`]: per block, each weight row loaded once for all
/// `M` activation rows; i8 x i8 -> i16 products (`smull`, exact) pairwise
/// accumulated into i32 (`sadalp`); `xc` unused.
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn gemm_q8<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = super::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
    let mut acc = [[vdupq_n_f32(0.0); TN]; M];
    for b in 0..nb {
        // SAFETY: every row holds at least nb blocks.
        let wv: [[int8x16_t; 2]; TN] = core::array::from_fn(|n| unsafe { wblock(w[n], b) });
        for m in 0..M {
            // SAFETY: as above.
            let xv = unsafe { xblock(xq[m], b) };
            for n in 0..TN {
                let mut s = vdupq_n_s32(0);
                s = vpadalq_s16(s, vmull_s8(vget_low_s8(wv[n][0]), vget_low_s8(xv[0])));
                s = vpadalq_s16(s, vmull_high_s8(wv[n][0], xv[0]));
                s = vpadalq_s16(s, vmull_s8(vget_low_s8(wv[n][1]), vget_low_s8(xv[1])));
                s = vpadalq_s16(s, vmull_high_s8(wv[n][1], xv[1]));
                acc[m][n] = vfmaq_n_f32(acc[m][n], vcvtq_f32_s32(s), wd[n][b] * xd[m][b]);
            }
        }
    }
    acc.map(|am| am.map(|a| vaddvq_f32(a)))
}

/// [`gemm_q8`] with `sdot` (the dotprod extension).
///
/// # Safety
/// NEON and the dotprod extension must be available.
#[target_feature(enable = "neon,dotprod")]
pub unsafe fn gemm_q8_dot<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = super::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
    let mut acc = [[vdupq_n_f32(0.0); TN]; M];
    for b in 0..nb {
        // SAFETY: every row holds at least nb blocks.
        let wv: [[int8x16_t; 2]; TN] = core::array::from_fn(|n| unsafe { wblock(w[n], b) });
        for m in 0..M {
            // SAFETY: as above.
            let xv = unsafe { xblock(xq[m], b) };
            for n in 0..TN {
                let s = sdot(sdot(vdupq_n_s32(0), wv[n][0], xv[0]), wv[n][1], xv[1]);
                acc[m][n] = vfmaq_n_f32(acc[m][n], vcvtq_f32_s32(s), wd[n][b] * xd[m][b]);
            }
        }
    }
    acc.map(|am| am.map(|a| vaddvq_f32(a)))
}

/// The rows of a NEON `*_ahead` packed kernel in passes of at most 4
/// ([`super::passes_of_four`]), each pass on `$kernel::<K, Q4>` (one of
/// [`packed_dot`] / [`packed_i8mm`]). Expands to unsafe calls: the
/// caller's features must be the kernel's.
macro_rules! neon_passes {
    ($kernel:ident, $w:ident, $xq:ident, $xd:ident, $ahead:ident) => {
        super::passes_of_four!(M, $ahead, |K, m0, a| {
            let q: [&[i8]; K] = core::array::from_fn(|m| $xq[m0 + m]);
            let d: [&[f32]; K] = core::array::from_fn(|m| $xd[m0 + m]);
            if $w.q4 {
                $kernel::<K, true>($w, q, d, a)
            } else {
                $kernel::<K, false>($w, q, d, a)
            }
        })
    };
}

/// See [`super::gemm_q8_packed`] with `sdot`: the stored groups read in
/// place, no expansion to rows. Per block and 8-byte group `g`, the
/// group's four 16-byte quarters (weight rows `2j, 2j + 1`) are `sdot`
/// against the activation group held twice (int8: the stored values;
/// 4-bit: the nibbles less 8, so no correction): i32 lanes `(2r, 2r + 1)`
/// hold the halves of row `r`'s block dot, exact; `addp` gives the 8 block
/// sums. The f32 steps are those of the AVX512-VNNI kernel (per block one
/// convert, one scale product `s_n,b * xd_b`, one FMA; even and odd
/// blocks in their own accumulators, added at the end); `xc` unused.
///
/// The activation rows go 4 at most at a time (shared evenly), each row's
/// numbers the same whatever its company.
///
/// # Safety
/// NEON and the dotprod extension must be available.
#[target_feature(enable = "neon,dotprod")]
pub unsafe fn gemm_q8_packed_dot<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    _xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_dot_ahead(w, xq, xd, _xc, &[]) }
}

/// [`gemm_q8_packed_dot`] that also prefetches `ahead` into L2, spread over the
/// blocks of its first pass ([`super::prefetch_part`]).
///
/// # Safety
/// As [`gemm_q8_packed_dot`].
#[target_feature(enable = "neon,dotprod")]
pub unsafe fn gemm_q8_packed_dot_ahead<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    _xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are `packed_dot`'s.
    unsafe { neon_passes!(packed_dot, w, xq, xd, ahead) }
}

/// [`gemm_q8_packed_dot`] for `K` (1..=4) activation rows and one value
/// width (`Q4`: 4-bit halves).
///
/// # Safety
/// As [`gemm_q8_packed_dot`].
#[inline]
#[target_feature(enable = "neon,dotprod")]
unsafe fn packed_dot<const K: usize, const Q4: bool>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    use super::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    let pv = if Q4 { PN } else { PV };
    let nb = w.blocks_for(xq, xd, []);
    // [row m][even / odd blocks][rows 0-3 / 4-7].
    let mut acc = [[[vdupq_n_f32(0.0); 2]; 2]; K];
    for b in 0..nb {
        super::prefetch_part(ahead, b, nb);
        let vb = &w.v[pv * b..pv * (b + 1)];
        let sb = &w.s[PS * b..PS * (b + 1)];
        // SAFETY: sb holds 8 f16 (16 bytes).
        let s16 = unsafe { vld1q_u16(sb.as_ptr() as *const u16) };
        // SAFETY: this function's features include f16x4_to_f32's.
        let sv = unsafe {
            [
                f16x4_to_f32(vget_low_u16(s16)),
                f16x4_to_f32(vget_high_u16(s16)),
            ]
        };
        // [row m][quarter j]: lanes (2r, 2r + 1) = halves of row 2j + r's block dot.
        let mut dp = [[vdupq_n_s32(0); 4]; K];
        for g in 0..4 {
            // SAFETY: vb is block b's values (`pv` bytes); neon is this fn's.
            let wg = unsafe { packed_group::<Q4>(vb, g) };
            for (m, dm) in dp.iter_mut().enumerate() {
                let xs = &xq[m][b * Q8_BLOCK + 8 * g..b * Q8_BLOCK + 8 * g + 8];
                // SAFETY: xs holds 8 bytes.
                let xg = vreinterpretq_s8_u64(vdupq_n_u64(unsafe {
                    (xs.as_ptr() as *const u64).read_unaligned()
                }));
                for (d, wj) in dm.iter_mut().zip(&wg) {
                    // SAFETY: this function's features are sdot's.
                    *d = unsafe { sdot(*d, *wj, xg) };
                }
            }
        }
        for (m, am) in acc.iter_mut().enumerate() {
            let sums = [0, 1].map(|h| vpaddq_s32(dp[m][2 * h], dp[m][2 * h + 1]));
            // SAFETY: neon is this fn's.
            unsafe { block_fma(&mut am[b % 2], sums, &sv, xd[m][b]) };
        }
    }
    // SAFETY: as above.
    unsafe { packed_out(acc) }
}

/// The 64 bytes of 8-byte group `g` (0..4) of a packed block's values `vb`
/// as 4 vectors, vector `j` = weight rows `2j` (bytes 0-7) and `2j + 1`
/// (bytes 8-15), signed (4-bit: the stored nibble minus 8).
///
/// # Safety
/// The CPU must support neon; `vb` holds one block (2 x 64 bytes 4-bit, 4
/// x 64 int8).
#[inline]
#[target_feature(enable = "neon")]
unsafe fn packed_group<const Q4: bool>(vb: &[u8], g: usize) -> [int8x16_t; 4] {
    debug_assert!(vb.len() >= if Q4 { 128 } else { 256 });
    core::array::from_fn(|j| {
        if Q4 {
            // SAFETY: vb holds 2 x 64 bytes; 64 (g % 2) + 16 j + 16 <= 128.
            let v = unsafe { vld1q_u8(vb.as_ptr().add(64 * (g % 2) + 16 * j)) };
            let nib = if g < 2 {
                vandq_u8(v, vdupq_n_u8(0x0f))
            } else {
                vshrq_n_u8::<4>(v)
            };
            vsubq_s8(vreinterpretq_s8_u8(nib), vdupq_n_s8(8))
        } else {
            // SAFETY: vb holds 4 x 64 bytes; 64 g + 16 j + 16 <= 256.
            unsafe { vld1q_s8(vb.as_ptr().add(64 * g + 16 * j) as *const i8) }
        }
    })
}

/// One block's f32 step of a packed kernel for one activation row: `a[h]
/// += f32(sums[h]) * (s[h] * xd)` (weight rows 4h..4h + 4), the same
/// operations as every other packed kernel's.
///
/// # Safety
/// The CPU must support neon.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn block_fma(a: &mut [float32x4_t; 2], sums: [int32x4_t; 2], s: &[float32x4_t; 2], xd: f32) {
    let sx = vdupq_n_f32(xd);
    for h in 0..2 {
        a[h] = vfmaq_f32(a[h], vcvtq_f32_s32(sums[h]), vmulq_f32(s[h], sx));
    }
}

/// The rows' outputs: even-block plus odd-block accumulators (`acc[m][parity][h]`).
///
/// # Safety
/// The CPU must support neon.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn packed_out<const K: usize>(acc: [[[float32x4_t; 2]; 2]; K]) -> [[f32; 8]; K] {
    let mut out = [[0.0f32; 8]; K];
    for (o, a) in out.iter_mut().zip(acc) {
        for h in 0..2 {
            // SAFETY: o holds 8 floats: 4 at 4h.
            unsafe { vst1q_f32(o.as_mut_ptr().add(4 * h), vaddq_f32(a[0][h], a[1][h])) };
        }
    }
    out
}

/// See [`super::gemm_q8_packed`] with the i8mm extension: per 8-byte group,
/// `smmla` multiplies two weight rows (one 16-byte vector of the packed
/// group) by two activation rows (their 8 bytes side by side): 4 `smmla`
/// for 2 activation rows x 8 weight rows, half the instructions of
/// [`gemm_q8_packed_dot`]'s `sdot`. The exact i32 block sums are unzipped
/// into [`gemm_q8_packed_dot`]'s lane order and take its f32 steps, so the
/// same bits as every packed kernel. Activation rows go in passes of at
/// most 4, as pairs (an odd last row paired with itself, its twin dropped).
///
/// # Safety
/// The CPU must support neon, dotprod and i8mm.
#[target_feature(enable = "neon,dotprod,i8mm")]
pub unsafe fn gemm_q8_packed_i8mm<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_i8mm_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_i8mm`] that also prefetches `ahead` into L2 (as
/// [`gemm_q8_packed_dot_ahead`]).
///
/// # Safety
/// As [`gemm_q8_packed_i8mm`].
#[target_feature(enable = "neon,dotprod,i8mm")]
pub unsafe fn gemm_q8_packed_i8mm_ahead<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    _xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are `packed_i8mm`'s.
    unsafe { neon_passes!(packed_i8mm, w, xq, xd, ahead) }
}

/// `smmla`: `acc += a b^T` for `a`, `b` two rows of 8 i8 each (lanes:
/// a0.b0, a0.b1, a1.b0, a1.b1), via asm: the intrinsic is not stable Rust yet.
///
/// # Safety
/// The CPU must support neon and i8mm.
#[inline]
#[target_feature(enable = "neon,i8mm")]
unsafe fn smmla(acc: int32x4_t, a: int8x16_t, b: int8x16_t) -> int32x4_t {
    let mut r = acc;
    // SAFETY: a register-only instruction of the i8mm extension (this fn's
    // target feature; the caller vouched for the CPU).
    unsafe {
        core::arch::asm!("smmla {0:v}.4s, {1:v}.16b, {2:v}.16b", inout(vreg) r, in(vreg) a, in(vreg) b, options(pure, nomem, nostack))
    };
    r
}

/// [`gemm_q8_packed_i8mm`] for `K` (1..=4) activation rows and one value
/// width (`Q4`: 4-bit halves).
///
/// # Safety
/// As [`gemm_q8_packed_i8mm`].
#[inline]
#[target_feature(enable = "neon,dotprod,i8mm")]
unsafe fn packed_i8mm<const K: usize, const Q4: bool>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    use super::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    let pv = if Q4 { PN } else { PV };
    let nb = w.blocks_for(xq, xd, []);
    // Activation row pairs: (0, 1), (2, 3); an odd last row twice.
    let pair = |p: usize| [2 * p, (2 * p + 1).min(K - 1)];
    let mut acc = [[[vdupq_n_f32(0.0); 2]; 2]; K];
    for b in 0..nb {
        super::prefetch_part(ahead, b, nb);
        let vb = &w.v[pv * b..pv * (b + 1)];
        let sb = &w.s[PS * b..PS * (b + 1)];
        // SAFETY: sb holds 8 f16 (16 bytes).
        let s16 = unsafe { vld1q_u16(sb.as_ptr() as *const u16) };
        // SAFETY: this function's features include f16x4_to_f32's.
        let sv = unsafe {
            [
                f16x4_to_f32(vget_low_u16(s16)),
                f16x4_to_f32(vget_high_u16(s16)),
            ]
        };
        // [pair p][weight rows 2j, 2j + 1]: lanes (row 2j, act 0), (2j, act 1),
        // (2j + 1, act 0), (2j + 1, act 1).
        let mut dp = [[vdupq_n_s32(0); 4]; 2];
        for g in 0..4 {
            // SAFETY: vb is block b's values; neon is this fn's.
            let wg = unsafe { packed_group::<Q4>(vb, g) };
            for (p, dpp) in dp.iter_mut().enumerate().take(K.div_ceil(2)) {
                let [m0, m1] = pair(p);
                let x8 = |m: usize| {
                    let xs = &xq[m][b * Q8_BLOCK + 8 * g..b * Q8_BLOCK + 8 * g + 8];
                    // SAFETY: xs holds 8 bytes.
                    unsafe { vld1_s8(xs.as_ptr()) }
                };
                let xg = vcombine_s8(x8(m0), x8(m1));
                for (d, wj) in dpp.iter_mut().zip(&wg) {
                    // SAFETY: this function's features are smmla's.
                    *d = unsafe { smmla(*d, *wj, xg) };
                }
            }
        }
        for (p, dpp) in dp.iter().enumerate().take(K.div_ceil(2)) {
            let [m0, m1] = pair(p);
            // Weight rows 0-3 / 4-7 of activation row m0 (even lanes) and m1 (odd lanes).
            let first = [0, 1].map(|h| vuzp1q_s32(dpp[2 * h], dpp[2 * h + 1]));
            let second = [0, 1].map(|h| vuzp2q_s32(dpp[2 * h], dpp[2 * h + 1]));
            // SAFETY: neon is this fn's.
            unsafe { block_fma(&mut acc[m0][b % 2], first, &sv, xd[m0][b]) };
            if m1 != m0 {
                // SAFETY: as above.
                unsafe { block_fma(&mut acc[m1][b % 2], second, &sv, xd[m1][b]) };
            }
        }
    }
    // SAFETY: as above.
    unsafe { packed_out(acc) }
}

/// `y += a * x` (fused multiply-add).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn axpy_f32(a: f32, x: &[f32], y: &mut [f32]) {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &mut y[..n]);
    let n4 = n - n % 4;
    let (x4, x1) = x.split_at(n4);
    let (y4, y1) = y.split_at_mut(n4);
    for (xc, yc) in x4.chunks_exact(4).zip(y4.chunks_exact_mut(4)) {
        // SAFETY: 4 floats each.
        unsafe {
            vst1q_f32(
                yc.as_mut_ptr(),
                vfmaq_n_f32(vld1q_f32(yc.as_ptr()), vld1q_f32(xc.as_ptr()), a),
            )
        };
    }
    for (yi, xi) in y1.iter_mut().zip(x1) {
        *yi += a * xi;
    }
}

/// See [`super::dot_rows`] (one NEON dot per key row).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn dot_rows(q: &[f32], k: &[f32], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    for (j, o) in out.iter_mut().enumerate() {
        // SAFETY: NEON is available (this fn's contract).
        *o = unsafe { dot_f32(q, &k[j * stride..j * stride + hd]) };
    }
}

/// See [`super::dot_rows_f16`]: per key row the operations of
/// [`dot_f32`] (4 accumulators over 16 lanes, then 4-lane steps into the
/// first, a scalar tail) on the exactly widened binary16 lanes, so the
/// result is [`dot_rows`]'s on the widened rows, bit for bit.
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn dot_rows_f16(q: &[f32], k: &[u16], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    let (q16, qr) = q.split_at(hd - hd % 16);
    let (q4, q1) = qr.split_at(qr.len() - qr.len() % 4);
    for (j, o) in out.iter_mut().enumerate() {
        let row = &k[j * stride..j * stride + hd];
        let (k16, kr) = row.split_at(q16.len());
        let (k4, k1) = kr.split_at(q4.len());
        let mut acc = [vdupq_n_f32(0.0); 4];
        for (x, y) in q16.chunks_exact(16).zip(k16.chunks_exact(16)) {
            for (l, accl) in acc.iter_mut().enumerate() {
                // SAFETY: x holds 16 floats, y 16 u16; lanes l*4..l*4+4 are in bounds.
                let (xv, yv) = unsafe {
                    (
                        vld1q_f32(x.as_ptr().add(l * 4)),
                        f16x4_to_f32(vld1_u16(y.as_ptr().add(l * 4))),
                    )
                };
                *accl = vfmaq_f32(*accl, xv, yv);
            }
        }
        for (x, y) in q4.chunks_exact(4).zip(k4.chunks_exact(4)) {
            // SAFETY: 4 floats and 4 u16.
            let (xv, yv) = unsafe { (vld1q_f32(x.as_ptr()), f16x4_to_f32(vld1_u16(y.as_ptr()))) };
            acc[0] = vfmaq_f32(acc[0], xv, yv);
        }
        let s = vaddq_f32(vaddq_f32(acc[0], acc[1]), vaddq_f32(acc[2], acc[3]));
        let mut tail = 0.0f32;
        for (x, y) in q1.iter().zip(k1) {
            tail += x * super::f16_to_f32(*y);
        }
        *o = vaddvq_f32(s) + tail;
    }
}

/// See [`super::axpy_f16`]: [`axpy_f32`]'s operations on the exactly
/// widened binary16 lanes (bit-identical to widening first).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn axpy_f16(a: f32, w: &[u16], y: &mut [f32]) {
    let n = w.len().min(y.len());
    let (w, y) = (&w[..n], &mut y[..n]);
    let n4 = n - n % 4;
    let (w4, w1) = w.split_at(n4);
    let (y4, y1) = y.split_at_mut(n4);
    for (wc, yc) in w4.chunks_exact(4).zip(y4.chunks_exact_mut(4)) {
        // SAFETY: 4 u16 and 4 floats.
        unsafe {
            vst1q_f32(
                yc.as_mut_ptr(),
                vfmaq_n_f32(
                    vld1q_f32(yc.as_ptr()),
                    f16x4_to_f32(vld1_u16(wc.as_ptr())),
                    a,
                ),
            )
        };
    }
    for (yi, wi) in y1.iter_mut().zip(w1) {
        *yi += a * super::f16_to_f32(*wi);
    }
}

/// See [`super::axpy_rows_f32`].
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn axpy_rows_f32(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32]) {
    // SAFETY: `row` holds y.len() floats and `e + 4 <= y.len()` (axpy_rows_by's contract).
    let load = |row: &[f32], e: usize| unsafe { vld1q_f32(row.as_ptr().add(e)) };
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_by(coef, x, stride, y, load, |v| v) }
}

/// See [`super::axpy_rows_f16`].
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn axpy_rows_f16(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32]) {
    // SAFETY: as in `axpy_rows_f32` (4 u16 at e).
    let load = |row: &[u16], e: usize| unsafe { f16x4_to_f32(vld1_u16(row.as_ptr().add(e))) };
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_by(coef, w, stride, y, load, super::f16_to_f32) }
}

/// The shared body of [`axpy_rows_f32`] and [`axpy_rows_f16`]: per lane
/// below `n - n % 4` the FMA of [`axpy_f32`] / [`axpy_f16`] row after row
/// (64 lanes, then 4, held in registers over all rows); the last `n % 4`
/// lanes unfused, as those kernels' tails.
///
/// # Safety
/// NEON must be available; `load(row, e)` must be sound for `e + 4 <= row.len()`.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn axpy_rows_by<E: Copy>(
    coef: &[f32],
    rows: &[E],
    stride: usize,
    y: &mut [f32],
    load: impl Fn(&[E], usize) -> float32x4_t,
    widen: impl Fn(E) -> f32,
) {
    let n = y.len();
    let nk = super::scalar::whole_rows(coef.len(), rows.len(), stride, n);
    let n4 = n - n % 4;
    let row = |j: usize| &rows[j * stride..j * stride + n];
    let mut e = 0;
    while e + 64 <= n4 {
        // SAFETY: lanes e .. e + 64 of y (<= n).
        let mut acc: [float32x4_t; 16] =
            core::array::from_fn(|t| unsafe { vld1q_f32(y.as_ptr().add(e + 4 * t)) });
        for (j, &a) in coef.iter().enumerate().take(nk) {
            let r = row(j);
            for (t, acc) in acc.iter_mut().enumerate() {
                *acc = vfmaq_n_f32(*acc, load(r, e + 4 * t), a);
            }
        }
        for (t, acc) in acc.iter().enumerate() {
            // SAFETY: as above.
            unsafe { vst1q_f32(y.as_mut_ptr().add(e + 4 * t), *acc) };
        }
        e += 64;
    }
    while e + 4 <= n4 {
        // SAFETY: lanes e .. e + 4 of y.
        let mut acc = unsafe { vld1q_f32(y.as_ptr().add(e)) };
        for (j, &a) in coef.iter().enumerate().take(nk) {
            acc = vfmaq_n_f32(acc, load(row(j), e), a);
        }
        // SAFETY: as above.
        unsafe { vst1q_f32(y.as_mut_ptr().add(e), acc) };
        e += 4;
    }
    for (j, &a) in coef.iter().enumerate().take(nk) {
        let r = row(j);
        for (yi, &xi) in y[n4..].iter_mut().zip(&r[n4..]) {
            *yi += a * widen(xi);
        }
    }
}

/// [`super::scalar::exp`] on 4 lanes, the same operations in the same
/// order (no FMA): bit-identical.
///
/// # Safety
/// NEON must be available.
#[inline]
#[target_feature(enable = "neon")]
unsafe fn exp4(x: float32x4_t) -> float32x4_t {
    use super::scalar::exp_c::*;
    // fminnm would drop a NaN; fmin keeps it, like the twin.
    let x = vminq_f32(x, vdupq_n_f32(HI));
    let below = vcltq_f32(x, vdupq_n_f32(LO));
    let fx = vrndmq_f32(vaddq_f32(
        vmulq_f32(x, vdupq_n_f32(LOG2E)),
        vdupq_n_f32(0.5),
    ));
    let r = vsubq_f32(x, vmulq_f32(fx, vdupq_n_f32(C1)));
    let r = vsubq_f32(r, vmulq_f32(fx, vdupq_n_f32(C2)));
    let z = vmulq_f32(r, r);
    let mut y = vdupq_n_f32(P[0]);
    for &p in &P[1..] {
        y = vaddq_f32(vmulq_f32(y, r), vdupq_n_f32(p));
    }
    let y = vaddq_f32(vaddq_f32(vmulq_f32(y, z), r), vdupq_n_f32(1.0));
    let n = vcvtq_s32_f32(fx);
    let pow2n = vreinterpretq_f32_s32(vshlq_n_s32::<23>(vaddq_s32(n, vdupq_n_s32(127))));
    vreinterpretq_f32_u32(vbicq_u32(vreinterpretq_u32_f32(vmulq_f32(y, pow2n)), below))
}

/// See [`super::exp_shifted_sum`] (the twin's 8 lane sums as two 4-lane
/// accumulators, reduced the same way).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn exp_shifted_sum(s: &mut [f32], max: f32) -> f32 {
    let n = s.len();
    let (body, tail) = s.split_at_mut(n - n % 8);
    let m = vdupq_n_f32(max);
    let (mut lo, mut hi) = (vdupq_n_f32(0.0), vdupq_n_f32(0.0));
    for c in body.chunks_exact_mut(8) {
        let (a, b) = c.split_at_mut(4);
        // SAFETY: a and b hold 4 floats each.
        unsafe {
            let ea = exp4(vsubq_f32(vld1q_f32(a.as_ptr()), m));
            let eb = exp4(vsubq_f32(vld1q_f32(b.as_ptr()), m));
            vst1q_f32(a.as_mut_ptr(), ea);
            vst1q_f32(b.as_mut_ptr(), eb);
            lo = vaddq_f32(lo, ea);
            hi = vaddq_f32(hi, eb);
        }
    }
    let mut a = [0f32; 8];
    let (al, ah) = a.split_at_mut(4);
    // SAFETY: 4 floats each.
    unsafe {
        vst1q_f32(al.as_mut_ptr(), lo);
        vst1q_f32(ah.as_mut_ptr(), hi);
    }
    let mut t = 0.0f32;
    for v in tail {
        *v = super::scalar::exp(*v - max);
        t += *v;
    }
    super::scalar::reduce8(a, t)
}

/// The 8 lanes of a (lo, hi) pair of 4-lane vectors.
///
/// # Safety
/// NEON must be available (always on aarch64).
#[inline]
unsafe fn lanes8(lo: float32x4_t, hi: float32x4_t) -> [f32; 8] {
    let mut a = [0f32; 8];
    let (al, ah) = a.split_at_mut(4);
    // SAFETY: 4 floats each.
    unsafe {
        vst1q_f32(al.as_mut_ptr(), lo);
        vst1q_f32(ah.as_mut_ptr(), hi);
    }
    a
}

/// See [`super::layernorm_row`]: the twin's operations on 2 x 4 lanes.
///
/// # Safety
/// NEON must be available (always on aarch64).
#[target_feature(enable = "neon")]
pub unsafe fn layernorm_row(x: &[f32], w: &[f32], b: &[f32], eps: f32, y: &mut [f32]) {
    use super::scalar::{ln_affine, ln_inv_std, ln_mean};
    let n = x.len().min(w.len()).min(b.len()).min(y.len());
    if n == 0 {
        return;
    }
    let (x, w, b, y) = (&x[..n], &w[..n], &b[..n], &mut y[..n]);
    let body = n - n % 8;
    let (mut lo, mut hi) = (vdupq_n_f32(0.0), vdupq_n_f32(0.0));
    for c in x[..body].chunks_exact(8) {
        // SAFETY: c holds 8 floats.
        unsafe {
            lo = vaddq_f32(lo, vld1q_f32(c.as_ptr()));
            hi = vaddq_f32(hi, vld1q_f32(c.as_ptr().add(4)));
        }
    }
    // SAFETY: NEON (this function's feature).
    let mean = ln_mean(unsafe { lanes8(lo, hi) }, x, body);
    let m = vdupq_n_f32(mean);
    let (mut lo, mut hi) = (vdupq_n_f32(0.0), vdupq_n_f32(0.0));
    for c in x[..body].chunks_exact(8) {
        // SAFETY: c holds 8 floats.
        unsafe {
            let da = vsubq_f32(vld1q_f32(c.as_ptr()), m);
            let db = vsubq_f32(vld1q_f32(c.as_ptr().add(4)), m);
            lo = vaddq_f32(lo, vmulq_f32(da, da));
            hi = vaddq_f32(hi, vmulq_f32(db, db));
        }
    }
    // SAFETY: NEON (this function's feature).
    let inv = ln_inv_std(unsafe { lanes8(lo, hi) }, x, body, mean, eps);
    let iv = vdupq_n_f32(inv);
    for i in (0..body).step_by(4) {
        // SAFETY: i + 4 <= body <= n, the length of all four slices.
        unsafe {
            let t = vmulq_f32(
                vmulq_f32(vsubq_f32(vld1q_f32(x.as_ptr().add(i)), m), iv),
                vld1q_f32(w.as_ptr().add(i)),
            );
            vst1q_f32(
                y.as_mut_ptr().add(i),
                vaddq_f32(t, vld1q_f32(b.as_ptr().add(i))),
            );
        }
    }
    ln_affine(x, w, b, mean, inv, y, body);
}

/// See [`super::gelu_inplace`]: [`super::scalar::gelu`] on 4 lanes, the
/// same operations in the same order (bit-identical on finite inputs).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn gelu_inplace(x: &mut [f32]) {
    use super::scalar::erf_c::*;
    let n = x.len();
    let (body, tail) = x.split_at_mut(n - n % 4);
    let one = vdupq_n_f32(1.0);
    for c in body.chunks_exact_mut(4) {
        // SAFETY: c holds 4 floats.
        unsafe {
            let xv = vld1q_f32(c.as_ptr());
            let u = vmulq_f32(xv, vdupq_n_f32(core::f32::consts::FRAC_1_SQRT_2));
            let neg = vcltq_f32(u, vdupq_n_f32(0.0));
            let a = vbslq_f32(neg, vnegq_f32(u), u);
            let t = vdivq_f32(one, vaddq_f32(one, vmulq_f32(vdupq_n_f32(P), a)));
            let mut y = vdupq_n_f32(A[0]);
            for &cf in &A[1..] {
                y = vaddq_f32(vmulq_f32(y, t), vdupq_n_f32(cf));
            }
            let e = exp4(vnegq_f32(vmulq_f32(a, a)));
            let e = vsubq_f32(one, vmulq_f32(vmulq_f32(y, t), e));
            let erf = vbslq_f32(neg, vnegq_f32(e), e);
            vst1q_f32(
                c.as_mut_ptr(),
                vmulq_f32(vmulq_f32(vdupq_n_f32(0.5), xv), vaddq_f32(one, erf)),
            );
        }
    }
    for v in tail {
        *v = super::scalar::gelu(*v);
    }
}

/// See [`super::widen_f16`] (exact: bit-identical to the twin).
///
/// # Safety
/// NEON must be available.
#[target_feature(enable = "neon")]
pub unsafe fn widen_f16(src: &[u16], dst: &mut [f32]) {
    let n = src.len().min(dst.len());
    let (src, dst) = (&src[..n], &mut dst[..n]);
    let n4 = n - n % 4;
    let (s4, s1) = src.split_at(n4);
    let (d4, d1) = dst.split_at_mut(n4);
    for (s, d) in s4.chunks_exact(4).zip(d4.chunks_exact_mut(4)) {
        // SAFETY: s holds 4 u16, d 4 floats.
        unsafe { vst1q_f32(d.as_mut_ptr(), f16x4_to_f32(vld1_u16(s.as_ptr()))) };
    }
    super::scalar::widen_f16(s1, d1);
}
