//! x86_64 AVX2 + FMA + F16C variants of the [`super::scalar`] kernels.
//! Every function is `unsafe` only because of `#[target_feature]`: the
//! caller must have checked that the CPU supports avx2, fma and f16c
//! (the dispatchers in `super` do, via `Isa::Avx2`). All memory access goes
//! through `chunks_exact` sub-slices, so loads are in bounds by construction.

use core::arch::x86_64::*;

use super::{Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

// The tiled kernels walk the weight rows two at a time (8 f32 accumulators
// for a 4x2 sub-tile, plus two weight and one activation register).
const _: () = assert!(TN.is_multiple_of(2));

/// Horizontal sum of 8 lanes.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn hsum(v: __m256) -> f32 {
    let lo = _mm256_castps256_ps128(v);
    let hi = _mm256_extractf128_ps::<1>(v);
    let s = _mm_add_ps(lo, hi);
    let s = _mm_add_ps(s, _mm_movehl_ps(s, s));
    let s = _mm_add_ss(s, _mm_shuffle_ps::<0b01>(s, s));
    _mm_cvtss_f32(s)
}

/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn dot_f32(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [_mm256_setzero_ps(); 4];
    let (a32, ar) = a.split_at(n - n % 32);
    let (b32, br) = b.split_at(n - n % 32);
    for (x, y) in a32.chunks_exact(32).zip(b32.chunks_exact(32)) {
        for (l, accl) in acc.iter_mut().enumerate() {
            // SAFETY: x and y hold 32 floats; lanes l*8..l*8+8 are in bounds.
            let (xv, yv) = unsafe { (_mm256_loadu_ps(x.as_ptr().add(l * 8)), _mm256_loadu_ps(y.as_ptr().add(l * 8))) };
            *accl = _mm256_fmadd_ps(xv, yv, *accl);
        }
    }
    let (a8, a1) = ar.split_at(ar.len() - ar.len() % 8);
    let (b8, b1) = br.split_at(a8.len());
    for (x, y) in a8.chunks_exact(8).zip(b8.chunks_exact(8)) {
        // SAFETY: 8 floats each.
        let (xv, yv) = unsafe { (_mm256_loadu_ps(x.as_ptr()), _mm256_loadu_ps(y.as_ptr())) };
        acc[0] = _mm256_fmadd_ps(xv, yv, acc[0]);
    }
    let s = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), _mm256_add_ps(acc[2], acc[3]));
    let mut tail = 0.0f32;
    for (x, y) in a1.iter().zip(b1) {
        tail += x * y;
    }
    hsum(s) + tail
}

/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn dot_f16(w: &[u16], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let (w, x) = (&w[..n], &x[..n]);
    let mut acc = [_mm256_setzero_ps(); 4];
    let (w32, wr) = w.split_at(n - n % 32);
    let (x32, xr) = x.split_at(n - n % 32);
    for (wc, xc) in w32.chunks_exact(32).zip(x32.chunks_exact(32)) {
        for (l, accl) in acc.iter_mut().enumerate() {
            // SAFETY: wc holds 32 u16 (8 per 128-bit load), xc 32 floats.
            let (wv, xv) = unsafe {
                (
                    _mm256_cvtph_ps(_mm_loadu_si128(wc.as_ptr().add(l * 8) as *const __m128i)),
                    _mm256_loadu_ps(xc.as_ptr().add(l * 8)),
                )
            };
            *accl = _mm256_fmadd_ps(wv, xv, *accl);
        }
    }
    let (w8, w1) = wr.split_at(wr.len() - wr.len() % 8);
    let (x8, x1) = xr.split_at(w8.len());
    for (wc, xc) in w8.chunks_exact(8).zip(x8.chunks_exact(8)) {
        // SAFETY: 8 u16 and 8 floats.
        let (wv, xv) = unsafe { (_mm256_cvtph_ps(_mm_loadu_si128(wc.as_ptr() as *const __m128i)), _mm256_loadu_ps(xc.as_ptr())) };
        acc[0] = _mm256_fmadd_ps(wv, xv, acc[0]);
    }
    let s = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), _mm256_add_ps(acc[2], acc[3]));
    let mut tail = 0.0f32;
    for (a, b) in w1.iter().zip(x1) {
        tail += super::f16_to_f32(*a) * b;
    }
    hsum(s) + tail
}

/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    let nb = (w.len() / Q8_BLOCK_BYTES).min(xq.len() / Q8_BLOCK).min(xd.len());
    let ones = _mm256_set1_epi16(1);
    let mut acc = _mm256_setzero_ps();
    for ((blk, xs), &dx) in w.chunks_exact(Q8_BLOCK_BYTES).zip(xq.chunks_exact(Q8_BLOCK)).zip(xd).take(nb) {
        let d = super::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) * dx;
        // SAFETY: blk[2..] and xs hold exactly 32 bytes each.
        let (wv, xv) = unsafe {
            (_mm256_loadu_si256(blk[2..].as_ptr() as *const __m256i), _mm256_loadu_si256(xs.as_ptr() as *const __m256i))
        };
        // |w| (unsigned) times sign(w)*x (signed): maddubs gives pairwise
        // i16 sums, at most 2*128*127 = 32512 in magnitude (no saturation,
        // since the activation quantiser keeps x in [-127, 127]).
        let aw = _mm256_sign_epi8(wv, wv);
        let sx = _mm256_sign_epi8(xv, wv);
        let p16 = _mm256_maddubs_epi16(aw, sx);
        let p32 = _mm256_madd_epi16(p16, ones);
        acc = _mm256_fmadd_ps(_mm256_set1_ps(d), _mm256_cvtepi32_ps(p32), acc);
    }
    hsum(acc)
}

/// The shortest of the tile's row lengths.
#[inline]
fn tile_len<A, B>(w: &[&[A]; TN], x: &[&[B]; TM]) -> usize {
    let kw = w.iter().map(|r| r.len()).min().unwrap_or(0);
    x.iter().map(|r| r.len()).min().unwrap_or(0).min(kw)
}

/// Register-blocked tile (see [`super::scalar::tile_f32`]): each 4x2
/// sub-tile keeps 8 accumulators in registers, so every weight and
/// activation vector loaded is used 2 or 4 times.
///
/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    let k = tile_len(&w, &x);
    let k8 = k - k % 8;
    let mut out = [[0.0f32; TN]; TM];
    for n0 in (0..TN).step_by(2) {
        let (wa, wb) = (&w[n0][..k], &w[n0 + 1][..k]);
        let mut acc = [[_mm256_setzero_ps(); 2]; TM];
        let mut c = 0;
        while c < k8 {
            // SAFETY: c + 8 <= k8 <= k, and wa, wb and every x[m] hold at
            // least k floats.
            let (va, vb) = unsafe { (_mm256_loadu_ps(wa.as_ptr().add(c)), _mm256_loadu_ps(wb.as_ptr().add(c))) };
            for (am, xm) in acc.iter_mut().zip(&x) {
                // SAFETY: as above.
                let xv = unsafe { _mm256_loadu_ps(xm.as_ptr().add(c)) };
                am[0] = _mm256_fmadd_ps(xv, va, am[0]);
                am[1] = _mm256_fmadd_ps(xv, vb, am[1]);
            }
            c += 8;
        }
        for (m, am) in acc.iter().enumerate() {
            for (j, wr) in [wa, wb].into_iter().enumerate() {
                let mut tail = 0.0f32;
                for (a, b) in wr[k8..].iter().zip(&x[m][k8..k]) {
                    tail += a * b;
                }
                out[m][n0 + j] = hsum(am[j]) + tail;
            }
        }
    }
    out
}

/// [`tile_f32`] with binary16 weights: each weight vector is converted
/// (F16C) once per step and used for all `TM` activation rows.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    let k = tile_len(&w, &x);
    let k8 = k - k % 8;
    let mut out = [[0.0f32; TN]; TM];
    for n0 in (0..TN).step_by(2) {
        let (wa, wb) = (&w[n0][..k], &w[n0 + 1][..k]);
        let mut acc = [[_mm256_setzero_ps(); 2]; TM];
        let mut c = 0;
        while c < k8 {
            // SAFETY: c + 8 <= k8 <= k: 8 u16 (one 128-bit load) of wa and wb in bounds.
            let (va, vb) = unsafe {
                (
                    _mm256_cvtph_ps(_mm_loadu_si128(wa.as_ptr().add(c) as *const __m128i)),
                    _mm256_cvtph_ps(_mm_loadu_si128(wb.as_ptr().add(c) as *const __m128i)),
                )
            };
            for (am, xm) in acc.iter_mut().zip(&x) {
                // SAFETY: every x[m] holds at least k floats.
                let xv = unsafe { _mm256_loadu_ps(xm.as_ptr().add(c)) };
                am[0] = _mm256_fmadd_ps(xv, va, am[0]);
                am[1] = _mm256_fmadd_ps(xv, vb, am[1]);
            }
            c += 8;
        }
        for (m, am) in acc.iter().enumerate() {
            for (j, wr) in [wa, wb].into_iter().enumerate() {
                let mut tail = 0.0f32;
                for (a, b) in wr[k8..].iter().zip(&x[m][k8..k]) {
                    tail += super::f16_to_f32(*a) * b;
                }
                out[m][n0 + j] = hsum(am[j]) + tail;
            }
        }
    }
    out
}

/// One binary16 scale to f32 (F16C, exact).
#[inline]
#[target_feature(enable = "avx2,f16c")]
unsafe fn f16_scale(blk: &[u8]) -> f32 {
    _mm_cvtss_f32(_mm_cvtph_ps(_mm_cvtsi32_si128(u16::from_le_bytes([blk[0], blk[1]]) as i32)))
}

/// Blocked int8 tile (see [`dot_q8`]): per block of 32, each weight row is
/// loaded and made unsigned once and used for all `TM` activation rows;
/// the i32 block sums (maddubs + madd) are scaled into f32 accumulators.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nbw = w.iter().map(|r| r.len() / Q8_BLOCK_BYTES).min().unwrap_or(0);
    let nbx = xq.iter().map(|r| r.len() / Q8_BLOCK).chain(xd.iter().map(|r| r.len())).min().unwrap_or(0);
    let nb = nbw.min(nbx);
    let ones = _mm256_set1_epi16(1);
    let mut out = [[0.0f32; TN]; TM];
    for n0 in (0..TN).step_by(2) {
        let mut acc = [[_mm256_setzero_ps(); 2]; TM];
        let blocks = w[n0].chunks_exact(Q8_BLOCK_BYTES).zip(w[n0 + 1].chunks_exact(Q8_BLOCK_BYTES)).take(nb);
        for (b, (ba, bb)) in blocks.enumerate() {
            let (da, db) = (f16_scale(ba), f16_scale(bb));
            // SAFETY: ba[2..] and bb[2..] hold exactly 32 bytes each.
            let (wa, wb) = unsafe {
                (_mm256_loadu_si256(ba[2..].as_ptr() as *const __m256i), _mm256_loadu_si256(bb[2..].as_ptr() as *const __m256i))
            };
            // |w| (unsigned) x sign(w)*x (signed), as in `dot_q8`: no i16
            // saturation since the quantiser keeps x in [-127, 127].
            let (ua, ub) = (_mm256_sign_epi8(wa, wa), _mm256_sign_epi8(wb, wb));
            for (m, am) in acc.iter_mut().enumerate() {
                let xs = &xq[m][b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
                let dx = xd[m][b];
                // SAFETY: xs holds exactly 32 bytes.
                let xv = unsafe { _mm256_loadu_si256(xs.as_ptr() as *const __m256i) };
                let pa = _mm256_madd_epi16(_mm256_maddubs_epi16(ua, _mm256_sign_epi8(xv, wa)), ones);
                let pb = _mm256_madd_epi16(_mm256_maddubs_epi16(ub, _mm256_sign_epi8(xv, wb)), ones);
                am[0] = _mm256_fmadd_ps(_mm256_set1_ps(da * dx), _mm256_cvtepi32_ps(pa), am[0]);
                am[1] = _mm256_fmadd_ps(_mm256_set1_ps(db * dx), _mm256_cvtepi32_ps(pb), am[1]);
            }
        }
        for (m, am) in acc.iter().enumerate() {
            out[m][n0] = hsum(am[0]);
            out[m][n0 + 1] = hsum(am[1]);
        }
    }
    out
}
