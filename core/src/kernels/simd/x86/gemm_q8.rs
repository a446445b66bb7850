//! int8 GEMMs over row-major Q8 weights (AVX-512 VNNI, AVX-512BW, AVX2)
//! and the block scale helpers.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// See [`simd::q8_scales`] (F16C, 8 scales per conversion).
///
/// # Safety
/// The CPU must support avx2 and f16c.
#[target_feature(enable = "avx2,f16c")]
pub unsafe fn q8_scales(row: &[u8], out: &mut [f32]) {
    for (o, blks) in out.chunks_mut(8).zip(row.chunks(8 * Q8_BLOCK_BYTES)) {
        let mut h = [0u16; 8];
        for (hi, blk) in h.iter_mut().zip(blks.chunks_exact(Q8_BLOCK_BYTES)) {
            *hi = u16::from_le_bytes([blk[0], blk[1]]);
        }
        let mut f = [0f32; 8];
        // SAFETY: h holds 8 u16 (128 bits), f 8 floats.
        unsafe {
            _mm256_storeu_ps(
                f.as_mut_ptr(),
                _mm256_cvtph_ps(_mm_loadu_si128(h.as_ptr() as *const __m128i)),
            )
        };
        let n = o.len().min(blks.len() / Q8_BLOCK_BYTES);
        o[..n].copy_from_slice(&f[..n]);
    }
}

/// The 32 quantised bytes of blocks `b` and `b + 1` of a stored row as one
/// 64-byte vector (two 32-byte loads; the scale bytes between are skipped).
///
/// # Safety
/// avx512f; `row` holds at least `b + 2` blocks.
#[inline]
#[target_feature(enable = "avx512f,avx2")]
unsafe fn two_blocks(row: &[u8], b: usize) -> __m512i {
    let blk = &row[b * Q8_BLOCK_BYTES..(b + 2) * Q8_BLOCK_BYTES];
    // SAFETY: blk holds 68 bytes: 2..34 and 36..68 are in bounds.
    let (lo, hi) = unsafe {
        (
            _mm256_loadu_si256(blk.as_ptr().add(2) as *const __m256i),
            _mm256_loadu_si256(blk.as_ptr().add(36) as *const __m256i),
        )
    };
    _mm512_inserti64x4::<1>(_mm512_castsi256_si512(lo), hi)
}

/// `[s[b] x 8, s[b + 1] x 8]` (per-block scales of a block pair, by lane).
///
/// # Safety
/// The CPU must support avx512f (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn pair_scales(s: &[f32], b: usize) -> __m512 {
    let p = &s[b..b + 2];
    // SAFETY: p holds 2 floats (8 bytes, one unaligned 64-bit load).
    let v = unsafe { _mm_castpd_ps(_mm_load_sd(p.as_ptr() as *const f64)) };
    _mm512_permutexvar_ps(
        _mm512_setr_epi32(0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 1),
        _mm512_castps128_ps512(v),
    )
}

/// See [`simd::gemm_q8`]: two blocks per 64-byte step; weights made
/// unsigned (`w ^ 0x80 = w + 128`) for `vpdpbusd`, whose accumulator starts
/// at the activation block's corrections (lanes 0 and 1 of each block's 8
/// lanes), so each block's 8 i32 lanes sum to the exact
/// `sum(w q)`; then converted, scaled by `wd * xd` and accumulated in f32.
/// An odd last block takes one 32-byte step.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl/vnni, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
pub unsafe fn gemm_q8_vnni<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = simd::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
    let flip = _mm512_set1_epi8(-128);
    let corr_idx = _mm512_setr_epi32(0, 1, 0, 0, 0, 0, 0, 0, 2, 3, 0, 0, 0, 0, 0, 0);
    let mut acc = [[_mm512_setzero_ps(); TN]; M];
    let mut b = 0;
    while b + 2 <= nb {
        // SAFETY (both): every row holds at least nb >= b + 2 blocks.
        let wv: [__m512i; TN] =
            core::array::from_fn(|n| _mm512_xor_si512(unsafe { two_blocks(w[n], b) }, flip));
        // SAFETY: this function's target features include pair_scales' avx512f.
        let dw: [__m512; TN] = core::array::from_fn(|n| unsafe { pair_scales(wd[n], b) });
        for m in 0..M {
            let xs = &xq[m][b * Q8_BLOCK..(b + 2) * Q8_BLOCK];
            let cs = &xc[m][2 * b..2 * b + 4];
            // SAFETY: xs holds 64 bytes; cs 4 i32 (one 128-bit load).
            let (xv, cv) = unsafe {
                (
                    _mm512_loadu_si512(xs.as_ptr() as *const _),
                    _mm_loadu_si128(cs.as_ptr() as *const __m128i),
                )
            };
            // Lanes 0, 1 <- block b's parity corrections, lanes 8, 9 <- block b + 1's.
            let init = _mm512_maskz_permutexvar_epi32(0x0303, corr_idx, _mm512_castsi128_si512(cv));
            // SAFETY: xd[m] holds at least b + 2 scales.
            let dx = unsafe { pair_scales(xd[m], b) };
            for n in 0..TN {
                let dp = _mm512_dpbusd_epi32(init, wv[n], xv);
                acc[m][n] =
                    _mm512_fmadd_ps(_mm512_cvtepi32_ps(dp), _mm512_mul_ps(dw[n], dx), acc[m][n]);
            }
        }
        b += 2;
    }
    // SAFETY: avx512f (this fn's features).
    let mut out = unsafe { reduce_tile(acc) };
    if b < nb {
        let flip = _mm256_set1_epi8(-128);
        let wv: [__m256i; TN] = core::array::from_fn(|n| {
            let q = &w[n][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
            // SAFETY: q holds exactly 32 bytes.
            _mm256_xor_si256(
                unsafe { _mm256_loadu_si256(q.as_ptr() as *const __m256i) },
                flip,
            )
        });
        for m in 0..M {
            let xs = &xq[m][b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
            // SAFETY: xs holds exactly 32 bytes.
            let xv = unsafe { _mm256_loadu_si256(xs.as_ptr() as *const __m256i) };
            let init = _mm256_setr_epi32(xc[m][2 * b], xc[m][2 * b + 1], 0, 0, 0, 0, 0, 0);
            for n in 0..TN {
                let dp = _mm256_dpbusd_epi32(init, wv[n], xv);
                out[m][n] += (wd[n][b] * xd[m][b]) * hsum(_mm256_cvtepi32_ps(dp));
            }
        }
    }
    out
}

/// [`gemm_q8_vnni`] without VNNI (AVX-512BW): `|w|` (unsigned) times
/// `sign(w) x` (signed) with `vpmaddubsw` (pairs, at most 2*128*127 in
/// magnitude: no i16 saturation since x is in [-127, 127]) and `vpmaddwd`
/// by ones; `xc` unused.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2,fma,f16c")]
pub unsafe fn gemm_q8_512<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = simd::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
    let ones = _mm512_set1_epi16(1);
    let zero = _mm512_setzero_si512();
    let mut acc = [[_mm512_setzero_ps(); TN]; M];
    let mut b = 0;
    while b + 2 <= nb {
        // SAFETY (both): every row holds at least nb >= b + 2 blocks.
        let raw: [__m512i; TN] = core::array::from_fn(|n| unsafe { two_blocks(w[n], b) });
        // SAFETY: this function's target features include pair_scales' avx512f.
        let dw: [__m512; TN] = core::array::from_fn(|n| unsafe { pair_scales(wd[n], b) });
        let aw = raw.map(|r| _mm512_abs_epi8(r));
        let neg = raw.map(|r| _mm512_movepi8_mask(r));
        for m in 0..M {
            let xs = &xq[m][b * Q8_BLOCK..(b + 2) * Q8_BLOCK];
            // SAFETY: xs holds 64 bytes; xd[m] at least b + 2 scales.
            let (xv, dx) = unsafe {
                (
                    _mm512_loadu_si512(xs.as_ptr() as *const _),
                    pair_scales(xd[m], b),
                )
            };
            for n in 0..TN {
                let sx = _mm512_mask_sub_epi8(xv, neg[n], zero, xv);
                let p = _mm512_madd_epi16(_mm512_maddubs_epi16(aw[n], sx), ones);
                acc[m][n] =
                    _mm512_fmadd_ps(_mm512_cvtepi32_ps(p), _mm512_mul_ps(dw[n], dx), acc[m][n]);
            }
        }
        b += 2;
    }
    // SAFETY: avx512f (this fn's features).
    let mut out = unsafe { reduce_tile(acc) };
    if b < nb {
        let tail = gemm_q8_avx2_from(w, wd, xq, xd, b, nb);
        for (o, t) in out.iter_mut().zip(tail) {
            for (a, v) in o.iter_mut().zip(t) {
                *a += v;
            }
        }
    }
    out
}

/// See [`simd::gemm_q8`] on 32-byte vectors, one block per step, weight
/// rows two at a time (8 accumulators for M = 4 fit the 16 registers); the
/// `vpsignb` trick of [`dot_q8`]; `xc` unused.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn gemm_q8_avx2<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; TN]; M] {
    let nb = simd::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
    gemm_q8_avx2_from(w, wd, xq, xd, 0, nb)
}

/// Blocks `b0..nb` of [`gemm_q8_avx2`].
///
/// # Safety
/// The CPU must support avx2, fma, f16c (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn gemm_q8_avx2_from<const M: usize>(
    w: [&[u8]; TN],
    wd: [&[f32]; TN],
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    b0: usize,
    nb: usize,
) -> [[f32; TN]; M] {
    let ones = _mm256_set1_epi16(1);
    let mut out = [[0.0f32; TN]; M];
    for n0 in (0..TN).step_by(2) {
        let mut acc = [[_mm256_setzero_ps(); 2]; M];
        for b in b0..nb {
            let (qa, qb) = (
                &w[n0][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES],
                &w[n0 + 1][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES],
            );
            // SAFETY: qa and qb hold exactly 32 bytes each.
            let (wa, wb) = unsafe {
                (
                    _mm256_loadu_si256(qa.as_ptr() as *const __m256i),
                    _mm256_loadu_si256(qb.as_ptr() as *const __m256i),
                )
            };
            let (ua, ub) = (_mm256_sign_epi8(wa, wa), _mm256_sign_epi8(wb, wb));
            let (dwa, dwb) = (_mm256_set1_ps(wd[n0][b]), _mm256_set1_ps(wd[n0 + 1][b]));
            for (m, am) in acc.iter_mut().enumerate() {
                let xs = &xq[m][b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
                // SAFETY: xs holds exactly 32 bytes.
                let xv = unsafe { _mm256_loadu_si256(xs.as_ptr() as *const __m256i) };
                let dx = _mm256_set1_ps(xd[m][b]);
                let pa =
                    _mm256_madd_epi16(_mm256_maddubs_epi16(ua, _mm256_sign_epi8(xv, wa)), ones);
                let pb =
                    _mm256_madd_epi16(_mm256_maddubs_epi16(ub, _mm256_sign_epi8(xv, wb)), ones);
                am[0] = _mm256_fmadd_ps(_mm256_cvtepi32_ps(pa), _mm256_mul_ps(dwa, dx), am[0]);
                am[1] = _mm256_fmadd_ps(_mm256_cvtepi32_ps(pb), _mm256_mul_ps(dwb, dx), am[1]);
            }
        }
        for (o, am) in out.iter_mut().zip(&acc) {
            o[n0] = hsum(am[0]);
            o[n0 + 1] = hsum(am[1]);
        }
    }
    out
}
