//! The attention's weighted sums of value rows (`axpy_rows*`, f32 and
//! f16 values) and `axpy_f16`.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// See [`simd::axpy_rows_f32`].
///
/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn axpy_rows_f32(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32]) {
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_f32_from(coef, x, stride, y, 0) }
}

/// Lanes `e0 ..` of [`axpy_rows_f32`] (`e0`: a multiple of 8).
///
/// # Safety
/// As [`axpy_rows_f32`].
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn axpy_rows_f32_from(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32], e0: usize) {
    // SAFETY: `row` holds y.len() floats and `e + 8 <= y.len()` (axpy_rows_by's contract).
    let load = |row: &[f32], e: usize| unsafe { _mm256_loadu_ps(row.as_ptr().add(e)) };
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_by(coef, x, stride, y, e0, load, |v| v) }
}

/// See [`simd::axpy_rows_f16`] (lanes widened by F16C, exact).
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn axpy_rows_f16(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32]) {
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_f16_from(coef, w, stride, y, 0) }
}

/// Lanes `e0 ..` of [`axpy_rows_f16`] (`e0`: a multiple of 8).
///
/// # Safety
/// As [`axpy_rows_f16`].
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn axpy_rows_f16_from(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32], e0: usize) {
    // SAFETY: as in `axpy_rows_f32_from` (8 u16 = 128 bits at e).
    let load = |row: &[u16], e: usize| unsafe {
        _mm256_cvtph_ps(_mm_loadu_si128(row.as_ptr().add(e) as *const __m128i))
    };
    // SAFETY: this fn's contract.
    unsafe { axpy_rows_by(coef, w, stride, y, e0, load, simd::f16_to_f32) }
}

/// [`axpy_rows_f32`] on 512-bit registers: the same FMA per lane (lanes
/// below `n - n % 8`; FMA rounds each lane alone), so bit-identical.
///
/// # Safety
/// The CPU must support avx512f, avx2 and fma.
#[target_feature(enable = "avx512f,avx2,fma")]
pub unsafe fn axpy_rows_512_f32(coef: &[f32], x: &[f32], stride: usize, y: &mut [f32]) {
    // SAFETY: `row` holds y.len() floats and `e + 16 <= y.len()` (axpy_rows_512_by's contract).
    let load = |row: &[f32], e: usize| unsafe { _mm512_loadu_ps(row.as_ptr().add(e)) };
    // SAFETY: this fn's contract.
    let done = unsafe { axpy_rows_512_by(coef, x, stride, y, load) };
    // SAFETY: as above; lanes from `done` on take the 256-bit body.
    unsafe { axpy_rows_f32_from(coef, x, stride, y, done) }
}

/// [`axpy_rows_f16`] on 512-bit registers (`vcvtph2ps`, exact): bit-identical.
///
/// # Safety
/// The CPU must support avx512f, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx2,fma,f16c")]
pub unsafe fn axpy_rows_512_f16(coef: &[f32], w: &[u16], stride: usize, y: &mut [f32]) {
    // SAFETY: as in `axpy_rows_512_f32` (16 u16 = 256 bits at e).
    let load = |row: &[u16], e: usize| unsafe {
        _mm512_cvtph_ps(_mm256_loadu_si256(row.as_ptr().add(e) as *const __m256i))
    };
    // SAFETY: this fn's contract.
    let done = unsafe { axpy_rows_512_by(coef, w, stride, y, load) };
    // SAFETY: as above.
    unsafe { axpy_rows_f16_from(coef, w, stride, y, done) }
}

/// Lanes `0 .. 64 k` (the largest multiple of 64 within `n - n % 8`) of
/// [`axpy_rows_512_f32`] / [`axpy_rows_512_f16`], 64 lanes in 4 registers
/// over all rows; returns `64 k`.
///
/// # Safety
/// The CPU must support avx512f; `load(row, e)` must be sound for `e + 16 <= row.len()`.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn axpy_rows_512_by<E: Copy>(
    coef: &[f32],
    rows: &[E],
    stride: usize,
    y: &mut [f32],
    load: impl Fn(&[E], usize) -> __m512,
) -> usize {
    let n = y.len();
    let nk = simd::scalar::whole_rows(coef.len(), rows.len(), stride, n);
    let n8 = n - n % 8;
    let mut e = 0;
    while e + 64 <= n8 {
        // SAFETY: lanes e .. e + 64 of y (<= n).
        let mut acc: [__m512; 4] =
            core::array::from_fn(|t| unsafe { _mm512_loadu_ps(y.as_ptr().add(e + 16 * t)) });
        for (j, &a) in coef.iter().enumerate().take(nk) {
            let (r, av) = (&rows[j * stride..j * stride + n], _mm512_set1_ps(a));
            for (t, acc) in acc.iter_mut().enumerate() {
                *acc = _mm512_fmadd_ps(av, load(r, e + 16 * t), *acc);
            }
        }
        for (t, acc) in acc.iter().enumerate() {
            // SAFETY: as above.
            unsafe { _mm512_storeu_ps(y.as_mut_ptr().add(e + 16 * t), *acc) };
        }
        e += 64;
    }
    e
}

/// See [`simd::axpy_rows_group_f32`]: [`axpy_rows_512_f32`] for `g`
/// queries, the 64-lane blocks of up to [`simd::QUERY_GROUP`] queries
/// held in registers while each value row's lanes are loaded once (per lane
/// the FMAs of [`axpy_rows_512_f32`] in the same order); the lanes past
/// them per query as there. Bit for bit [`axpy_rows_512_f32`] per query.
///
/// # Safety
/// The CPU must support avx512f, avx2 and fma.
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn axpy_rows_512_group_f32(
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
    // SAFETY: `row` holds n floats and `e + 16 <= n` (axpy_rows_512_group_by's contract).
    let load = |row: &[f32], e: usize| unsafe { _mm512_loadu_ps(row.as_ptr().add(e)) };
    // SAFETY: this fn's contract.
    let done = unsafe {
        axpy_rows_512_group_by(
            coef,
            coef_stride,
            nk,
            x,
            stride,
            y,
            y_stride,
            n,
            g,
            load,
            side,
        )
    };
    // Lanes past the 64-lane blocks (none for 64-lane heads) per query.
    for m in 0..if done < n { g } else { 0 } {
        let ym = &mut y[m * y_stride..m * y_stride + n];
        // SAFETY: as above; lanes from `done` on take the 256-bit body.
        unsafe {
            axpy_rows_f32_from(
                &coef[m * coef_stride..m * coef_stride + nk],
                x,
                stride,
                ym,
                done,
            )
        };
    }
}

/// [`axpy_rows_512_group_f32`] over binary16 rows (`vcvtph2ps`, exact):
/// bit for bit [`axpy_rows_512_f16`] per query.
///
/// # Safety
/// The CPU must support avx512f, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx2,fma,f16c")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn axpy_rows_512_group_f16(
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
    // SAFETY: as in `axpy_rows_512_group_f32` (16 u16 = 256 bits at e).
    let load = |row: &[u16], e: usize| unsafe {
        _mm512_cvtph_ps(_mm256_loadu_si256(row.as_ptr().add(e) as *const __m256i))
    };
    // SAFETY: this fn's contract.
    let done = unsafe {
        axpy_rows_512_group_by(
            coef,
            coef_stride,
            nk,
            w,
            stride,
            y,
            y_stride,
            n,
            g,
            load,
            side,
        )
    };
    // Lanes past the 64-lane blocks (none for 64-lane heads) per query.
    for m in 0..if done < n { g } else { 0 } {
        let ym = &mut y[m * y_stride..m * y_stride + n];
        // SAFETY: as above.
        unsafe {
            axpy_rows_f16_from(
                &coef[m * coef_stride..m * coef_stride + nk],
                w,
                stride,
                ym,
                done,
            )
        };
    }
}

/// Lanes `0 .. 64 k` (as in [`axpy_rows_512_by`]) of every query of
/// [`axpy_rows_512_group_f32`] / [`axpy_rows_512_group_f16`], the queries in
/// blocks of up to [`simd::QUERY_GROUP`]; returns `64 k`.
///
/// # Safety
/// As [`axpy_rows_512_by`].
#[allow(clippy::too_many_arguments)]
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn axpy_rows_512_group_by<E: Copy>(
    coef: &[f32],
    coef_stride: usize,
    nk: usize,
    rows: &[E],
    stride: usize,
    y: &mut [f32],
    y_stride: usize,
    n: usize,
    g: usize,
    load: impl Fn(&[E], usize) -> __m512 + Copy,
    side: &[u8],
) -> usize {
    if n == 0 {
        return 0;
    }
    let nk = simd::scalar::whole_rows(nk, rows.len(), stride, n);
    let n8 = n - n % 8;
    let done = n8 - n8 % 64;
    let mut m0 = 0;
    while m0 < g {
        let gm = (g - m0).min(simd::QUERY_GROUP);
        let (coef, y) = (&coef[m0 * coef_stride..], &mut y[m0 * y_stride..]);
        // The first block's pass over the rows prefetches `side`.
        let side = if m0 == 0 { side } else { &[] };
        // SAFETY: this fn's contract.
        unsafe {
            match gm {
                5 => axpy_block::<5, E>(
                    coef,
                    coef_stride,
                    nk,
                    rows,
                    stride,
                    y,
                    y_stride,
                    n,
                    done,
                    load,
                    side,
                ),
                4 => axpy_block::<4, E>(
                    coef,
                    coef_stride,
                    nk,
                    rows,
                    stride,
                    y,
                    y_stride,
                    n,
                    done,
                    load,
                    side,
                ),
                3 => axpy_block::<3, E>(
                    coef,
                    coef_stride,
                    nk,
                    rows,
                    stride,
                    y,
                    y_stride,
                    n,
                    done,
                    load,
                    side,
                ),
                2 => axpy_block::<2, E>(
                    coef,
                    coef_stride,
                    nk,
                    rows,
                    stride,
                    y,
                    y_stride,
                    n,
                    done,
                    load,
                    side,
                ),
                _ => axpy_block::<1, E>(
                    coef,
                    coef_stride,
                    nk,
                    rows,
                    stride,
                    y,
                    y_stride,
                    n,
                    done,
                    load,
                    side,
                ),
            }
        }
        m0 += gm;
    }
    done
}

/// `G` queries' lanes `0..done` (`done`: a multiple of 64, `<= n`): per 64
/// lanes, `G x 4` accumulators over value rows `0..nk`, each row's four lane
/// groups loaded once.
///
/// # Safety
/// As [`axpy_rows_512_by`]; `y` holds `G` rows of `n` lanes, `y_stride` apart.
#[allow(clippy::too_many_arguments)]
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn axpy_block<const G: usize, E: Copy>(
    coef: &[f32],
    coef_stride: usize,
    nk: usize,
    rows: &[E],
    stride: usize,
    y: &mut [f32],
    y_stride: usize,
    n: usize,
    done: usize,
    load: impl Fn(&[E], usize) -> __m512,
    side: &[u8],
) {
    let coef = &coef[..(G - 1) * coef_stride + nk];
    let y = &mut y[..(G - 1) * y_stride + n];
    let mut e = 0;
    while e + 64 <= done {
        // SAFETY: lanes e .. e + 64 <= n of row m of y.
        let mut acc: [[__m512; 4]; G] = core::array::from_fn(|m| {
            core::array::from_fn(|t| unsafe {
                _mm512_loadu_ps(y.as_ptr().add(m * y_stride + e + 16 * t))
            })
        });
        for j in 0..nk {
            if j + KEY_PREFETCH < nk {
                let a = (j + KEY_PREFETCH) * stride + e;
                prefetch_span(&rows[a..a + 64]);
            }
            // `side` over the first 64-lane block's rows.
            if e == 0 {
                simd::prefetch_part(side, j, nk);
            }
            let r = &rows[j * stride..j * stride + n];
            let v: [__m512; 4] = core::array::from_fn(|t| load(r, e + 16 * t));
            for (m, acc) in acc.iter_mut().enumerate() {
                let av = _mm512_set1_ps(coef[m * coef_stride + j]);
                for (a, v) in acc.iter_mut().zip(&v) {
                    *a = _mm512_fmadd_ps(av, *v, *a);
                }
            }
        }
        for (m, acc) in acc.iter().enumerate() {
            for (t, a) in acc.iter().enumerate() {
                // SAFETY: as above.
                unsafe { _mm512_storeu_ps(y.as_mut_ptr().add(m * y_stride + e + 16 * t), *a) };
            }
        }
        e += 64;
    }
}

/// The shared body of [`axpy_rows_f32`] and [`axpy_rows_f16`]: per lane
/// below `n - n % 8` the FMA of [`axpy_f32`] / [`axpy_f16`] row after row
/// (64 lanes, then 8, held in registers over all rows), from lane `e0` (a
/// multiple of 8) on; the last `n % 8` lanes unfused, as those kernels'
/// tails. `load(row, e)` gives lanes
/// `e .. e + 8` of a row (`e + 8 <= row.len()`), `widen` one lane.
///
/// Always inlined into its callers (no features of its own), so that their
/// `load` (an F16C conversion for [`axpy_rows_f16`]) is inlined too: with
/// `#[target_feature(enable = "avx2,fma")]` here, the F16C closure could not
/// be, and every 8-lane load was a call (8% of a Transflower `realtime`
/// step on AVX2, 2026-12-05 profile).
///
/// # Safety
/// The CPU must support avx2 and fma (and what `load` uses); `load` must
/// be sound for such `e`.
#[inline(always)]
unsafe fn axpy_rows_by<E: Copy>(
    coef: &[f32],
    rows: &[E],
    stride: usize,
    y: &mut [f32],
    e0: usize,
    load: impl Fn(&[E], usize) -> __m256,
    widen: impl Fn(E) -> f32,
) {
    // SAFETY (every intrinsic below): the caller's features (avx2, fma);
    // every load and store is in bounds as noted.
    unsafe {
        let n = y.len();
        let nk = simd::scalar::whole_rows(coef.len(), rows.len(), stride, n);
        let n8 = n - n % 8;
        let row = |j: usize| &rows[j * stride..j * stride + n];
        let mut e = e0.min(n8);
        while e + 64 <= n8 {
            // In bounds: lanes e .. e + 64 of y (<= n).
            let mut acc: [__m256; 8] =
                core::array::from_fn(|t| _mm256_loadu_ps(y.as_ptr().add(e + 8 * t)));
            for (j, &a) in coef.iter().enumerate().take(nk) {
                let (r, av) = (row(j), _mm256_set1_ps(a));
                for (t, acc) in acc.iter_mut().enumerate() {
                    *acc = _mm256_fmadd_ps(av, load(r, e + 8 * t), *acc);
                }
            }
            for (t, acc) in acc.iter().enumerate() {
                // In bounds: as above.
                _mm256_storeu_ps(y.as_mut_ptr().add(e + 8 * t), *acc);
            }
            e += 64;
        }
        while e + 8 <= n8 {
            // In bounds: lanes e .. e + 8 of y.
            let mut acc = _mm256_loadu_ps(y.as_ptr().add(e));
            for (j, &a) in coef.iter().enumerate().take(nk) {
                acc = _mm256_fmadd_ps(_mm256_set1_ps(a), load(row(j), e), acc);
            }
            // In bounds: as above.
            _mm256_storeu_ps(y.as_mut_ptr().add(e), acc);
            e += 8;
        }
        for (j, &a) in coef.iter().enumerate().take(nk) {
            let r = row(j);
            for (yi, &xi) in y[n8..].iter_mut().zip(&r[n8..]) {
                *yi += a * widen(xi);
            }
        }
    }
}

/// `y += a * w`, binary16 `w` converted by F16C (exact), FMA.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn axpy_f16(a: f32, w: &[u16], y: &mut [f32]) {
    let n = w.len().min(y.len());
    let (w, y) = (&w[..n], &mut y[..n]);
    let av = _mm256_set1_ps(a);
    let n8 = n - n % 8;
    let (w8, w1) = w.split_at(n8);
    let (y8, y1) = y.split_at_mut(n8);
    for (wc, yc) in w8.chunks_exact(8).zip(y8.chunks_exact_mut(8)) {
        // SAFETY: 8 u16 (128 bits) and 8 floats.
        unsafe {
            let wv = _mm256_cvtph_ps(_mm_loadu_si128(wc.as_ptr() as *const __m128i));
            _mm256_storeu_ps(
                yc.as_mut_ptr(),
                _mm256_fmadd_ps(av, wv, _mm256_loadu_ps(yc.as_ptr())),
            );
        }
    }
    for (yi, wi) in y1.iter_mut().zip(w1) {
        *yi += a * simd::f16_to_f32(*wi);
    }
}
