//! LayerNorm rows, GELU, the bias/activation epilogues and the f16
//! conversions.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// See [`simd::layernorm_row`]: the twin's operations on 8 lanes.
///
/// # Safety
/// The CPU must support avx2.
#[target_feature(enable = "avx2")]
pub unsafe fn layernorm_row(x: &[f32], w: &[f32], b: &[f32], eps: f32, y: &mut [f32]) {
    use simd::scalar::{ln_affine, ln_inv_std, ln_mean};
    let n = x.len().min(w.len()).min(b.len()).min(y.len());
    if n == 0 {
        return;
    }
    let (x, w, b, y) = (&x[..n], &w[..n], &b[..n], &mut y[..n]);
    let body = n - n % 8;
    let lanes = |v: __m256| {
        let mut a = [0f32; 8];
        // SAFETY: a holds 8 floats.
        unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
        a
    };
    let mut acc = _mm256_setzero_ps();
    for c in x[..body].chunks_exact(8) {
        // SAFETY: c holds 8 floats.
        acc = _mm256_add_ps(acc, unsafe { _mm256_loadu_ps(c.as_ptr()) });
    }
    let mean = ln_mean(lanes(acc), x, body);
    let m = _mm256_set1_ps(mean);
    let mut acc = _mm256_setzero_ps();
    for c in x[..body].chunks_exact(8) {
        // SAFETY: c holds 8 floats.
        let d = _mm256_sub_ps(unsafe { _mm256_loadu_ps(c.as_ptr()) }, m);
        acc = _mm256_add_ps(acc, _mm256_mul_ps(d, d));
    }
    let inv = ln_inv_std(lanes(acc), x, body, mean, eps);
    let iv = _mm256_set1_ps(inv);
    for i in (0..body).step_by(8) {
        // SAFETY: i + 8 <= body <= n, the length of all four slices.
        unsafe {
            let t = _mm256_mul_ps(
                _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(x.as_ptr().add(i)), m), iv),
                _mm256_loadu_ps(w.as_ptr().add(i)),
            );
            _mm256_storeu_ps(
                y.as_mut_ptr().add(i),
                _mm256_add_ps(t, _mm256_loadu_ps(b.as_ptr().add(i))),
            );
        }
    }
    ln_affine(x, w, b, mean, inv, y, body);
}

/// See [`simd::gelu_inplace`]: [`simd::scalar::gelu`] on 8 lanes, the
/// same operations in the same order (bit-identical).
///
/// # Safety
/// The CPU must support avx2.
#[target_feature(enable = "avx2")]
pub unsafe fn gelu_inplace(x: &mut [f32]) {
    let n = x.len();
    let (body, tail) = x.split_at_mut(n - n % 8);
    for c in body.chunks_exact_mut(8) {
        // SAFETY: c holds 8 floats.
        unsafe { _mm256_storeu_ps(c.as_mut_ptr(), gelu8(_mm256_loadu_ps(c.as_ptr()))) };
    }
    for v in tail {
        *v = simd::scalar::gelu(*v);
    }
}

/// [`simd::scalar::gelu`] on 8 lanes, operation for operation.
#[inline]
#[target_feature(enable = "avx2")]
fn gelu8(xv: __m256) -> __m256 {
    use simd::scalar::erf_c::*;
    let sign = _mm256_set1_ps(-0.0);
    let u = _mm256_mul_ps(xv, _mm256_set1_ps(core::f32::consts::FRAC_1_SQRT_2));
    let neg = _mm256_cmp_ps::<_CMP_LT_OQ>(u, _mm256_setzero_ps());
    let a = _mm256_blendv_ps(u, _mm256_xor_ps(u, sign), neg);
    let t = _mm256_div_ps(
        _mm256_set1_ps(1.0),
        _mm256_add_ps(_mm256_set1_ps(1.0), _mm256_mul_ps(_mm256_set1_ps(P), a)),
    );
    let mut y = _mm256_set1_ps(A[0]);
    for &cf in &A[1..] {
        y = _mm256_add_ps(_mm256_mul_ps(y, t), _mm256_set1_ps(cf));
    }
    // SAFETY: avx2 is enabled here (exp8's contract).
    let e = unsafe { exp8(_mm256_xor_ps(_mm256_mul_ps(a, a), sign)) };
    let e = _mm256_sub_ps(_mm256_set1_ps(1.0), _mm256_mul_ps(_mm256_mul_ps(y, t), e));
    let erf = _mm256_blendv_ps(e, _mm256_xor_ps(e, sign), neg);
    _mm256_mul_ps(
        _mm256_mul_ps(_mm256_set1_ps(0.5), xv),
        _mm256_add_ps(_mm256_set1_ps(1.0), erf),
    )
}

/// See [`simd::bias_act_rows`] (AVX2 and AVX-VNNI): two rows' sums and
/// [`gelu8`]s at a time in one call (four independent chains of 8 lanes),
/// each the twin's operations, so bit-identical to it; a call's rows
/// once, where row by row each took two calls.
///
/// # Safety
/// The CPU must support avx2.
#[target_feature(enable = "avx2")]
pub unsafe fn bias_act_rows_avx2(rows: &mut [[f32; 16]], b: Option<&[f32; 16]>, gelu: bool) {
    // SAFETY: b holds 16 floats.
    let bv = b.map_or([_mm256_setzero_ps(); 2], |b| unsafe {
        [
            _mm256_loadu_ps(b.as_ptr()),
            _mm256_loadu_ps(b.as_ptr().add(8)),
        ]
    });
    let mut pairs = rows.chunks_exact_mut(2);
    for q in &mut pairs {
        // Lanes 0-7 and 8-15 of the two rows. SAFETY: each row holds 16 floats.
        let mut v: [__m256; 4] = core::array::from_fn(|i| {
            _mm256_add_ps(bv[i % 2], unsafe {
                _mm256_loadu_ps(q[i / 2].as_ptr().add(8 * (i % 2)))
            })
        });
        if gelu {
            // Unrolled by hand: four independent chains in one block.
            v = [gelu8(v[0]), gelu8(v[1]), gelu8(v[2]), gelu8(v[3])];
        }
        for (i, v) in v.into_iter().enumerate() {
            // SAFETY: as above.
            unsafe { _mm256_storeu_ps(q[i / 2].as_mut_ptr().add(8 * (i % 2)), v) };
        }
    }
    for r in pairs.into_remainder() {
        for (h, bh) in bv.into_iter().enumerate() {
            // SAFETY: r holds 16 floats.
            unsafe {
                let v = _mm256_add_ps(bh, _mm256_loadu_ps(r.as_ptr().add(8 * h)));
                _mm256_storeu_ps(r.as_mut_ptr().add(8 * h), if gelu { gelu8(v) } else { v });
            }
        }
    }
}

/// See [`simd::gelu_inplace`]: [`gelu_inplace`] on 16 lanes ([`exp16`];
/// the signs by integer `xor`, the tail masked): the same operations,
/// bit-identical to the twin.
///
/// # Safety
/// The CPU must support avx512f.
#[target_feature(enable = "avx512f")]
pub unsafe fn gelu_inplace_512(x: &mut [f32]) {
    // Two vectors per step: their long dependency chains (a division, two
    // polynomials) interleave.
    let mut pairs = x.chunks_exact_mut(32);
    for c in &mut pairs {
        // SAFETY: c holds 32 floats.
        unsafe {
            let (a, b) = (
                _mm512_loadu_ps(c.as_ptr()),
                _mm512_loadu_ps(c.as_ptr().add(16)),
            );
            let (ga, gb) = (gelu16(a), gelu16(b));
            _mm512_storeu_ps(c.as_mut_ptr(), ga);
            _mm512_storeu_ps(c.as_mut_ptr().add(16), gb);
        }
    }
    for c in pairs.into_remainder().chunks_mut(16) {
        let m = lanes16(c.len());
        // SAFETY: masked lanes < c.len() of c only.
        unsafe {
            _mm512_mask_storeu_ps(
                c.as_mut_ptr(),
                m,
                gelu16(_mm512_maskz_loadu_ps(m, c.as_ptr())),
            )
        };
    }
}

/// See [`simd::bias_act_rows`]: four rows' sums and [`gelu16`]s at a
/// time (four independent chains: the divisions and polynomials of one
/// overlap the others'), each the twin's operations, so bit-identical to
/// it.
///
/// # Safety
/// The CPU must support avx512f.
#[target_feature(enable = "avx512f")]
pub unsafe fn bias_act_rows_512(rows: &mut [[f32; 16]], b: Option<&[f32; 16]>, gelu: bool) {
    // SAFETY: b holds 16 floats.
    let bv = b.map_or(_mm512_setzero_ps(), |b| unsafe {
        _mm512_loadu_ps(b.as_ptr())
    });
    let mut quads = rows.chunks_exact_mut(4);
    for q in &mut quads {
        // SAFETY: each row holds 16 floats.
        let mut v: [__m512; 4] =
            core::array::from_fn(|m| _mm512_add_ps(bv, unsafe { _mm512_loadu_ps(q[m].as_ptr()) }));
        if gelu {
            // Unrolled by hand: four independent chains in one block.
            v = [gelu16(v[0]), gelu16(v[1]), gelu16(v[2]), gelu16(v[3])];
        }
        for (r, v) in q.iter_mut().zip(v) {
            // SAFETY: r holds 16 floats.
            unsafe { _mm512_storeu_ps(r.as_mut_ptr(), v) };
        }
    }
    for r in quads.into_remainder() {
        // SAFETY: r holds 16 floats.
        let v = _mm512_add_ps(bv, unsafe { _mm512_loadu_ps(r.as_ptr()) });
        // SAFETY: as above.
        unsafe { _mm512_storeu_ps(r.as_mut_ptr(), if gelu { gelu16(v) } else { v }) };
    }
}

/// See [`simd::bias_act`]: 16 lanes at a time, the tail masked; the sum
/// and [`gelu16`] as the twin's operations, so bit-identical to it.
///
/// # Safety
/// The CPU must support avx512f.
#[target_feature(enable = "avx512f")]
pub unsafe fn bias_act_512(t: &[f32], b: Option<&[f32]>, gelu: bool, y: &mut [f32]) {
    let n = t.len().min(b.map_or(t.len(), <[f32]>::len)).min(y.len());
    let mut j = 0;
    while j < n {
        let m = lanes16((n - j).min(16));
        // SAFETY: the masked lanes j..min(j + 16, n) lie in t, b and y.
        unsafe {
            let tv = _mm512_maskz_loadu_ps(m, t.as_ptr().add(j));
            let bv = match b {
                Some(b) => _mm512_maskz_loadu_ps(m, b.as_ptr().add(j)),
                None => _mm512_setzero_ps(),
            };
            let v = _mm512_add_ps(bv, tv);
            _mm512_mask_storeu_ps(y.as_mut_ptr().add(j), m, if gelu { gelu16(v) } else { v });
        }
        j += 16;
    }
}

/// [`simd::scalar::gelu`] on 16 lanes, operation for operation.
#[inline]
#[target_feature(enable = "avx512f")]
pub(in crate::kernels::simd) fn gelu16(xv: __m512) -> __m512 {
    use simd::scalar::erf_c::*;
    let sign = _mm512_set1_epi32(i32::MIN);
    let flip = |v: __m512| _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(v), sign));
    let u = _mm512_mul_ps(xv, _mm512_set1_ps(core::f32::consts::FRAC_1_SQRT_2));
    let neg = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(u, _mm512_setzero_ps());
    let a = _mm512_mask_blend_ps(neg, u, flip(u));
    let t = _mm512_div_ps(
        _mm512_set1_ps(1.0),
        _mm512_add_ps(_mm512_set1_ps(1.0), _mm512_mul_ps(_mm512_set1_ps(P), a)),
    );
    let mut y = _mm512_set1_ps(A[0]);
    for &cf in &A[1..] {
        y = _mm512_add_ps(_mm512_mul_ps(y, t), _mm512_set1_ps(cf));
    }
    // SAFETY: exp16 needs avx512f (this fn's feature).
    let e = unsafe { exp16(flip(_mm512_mul_ps(a, a))) };
    let e = _mm512_sub_ps(_mm512_set1_ps(1.0), _mm512_mul_ps(_mm512_mul_ps(y, t), e));
    let erf = _mm512_mask_blend_ps(neg, e, flip(e));
    _mm512_mul_ps(
        _mm512_mul_ps(_mm512_set1_ps(0.5), xv),
        _mm512_add_ps(_mm512_set1_ps(1.0), erf),
    )
}

/// See [`simd::narrow_f16`]: `vcvtps2ph` (round to nearest even) on 8
/// lanes, the tail by the twin.
///
/// # Safety
/// The CPU must support avx2 and f16c.
#[target_feature(enable = "avx2,f16c")]
pub unsafe fn narrow_f16(src: &[f32], dst: &mut [u16]) {
    let n = src.len().min(dst.len());
    let n8 = n - n % 8;
    for (s, d) in src[..n8].chunks_exact(8).zip(dst[..n8].chunks_exact_mut(8)) {
        // SAFETY: s and d hold 8 values each.
        unsafe {
            _mm_storeu_si128(
                d.as_mut_ptr() as *mut __m128i,
                _mm256_cvtps_ph::<_MM_FROUND_TO_NEAREST_INT>(_mm256_loadu_ps(s.as_ptr())),
            )
        };
    }
    simd::scalar::narrow_f16(&src[n8..n], &mut dst[n8..n]);
}

/// See [`simd::widen_f16`] (F16C, exact: bit-identical to the twin).
///
/// # Safety
/// The CPU must support avx2 and f16c.
#[target_feature(enable = "avx2,f16c")]
pub unsafe fn widen_f16(src: &[u16], dst: &mut [f32]) {
    let n = src.len().min(dst.len());
    let (src, dst) = (&src[..n], &mut dst[..n]);
    let n8 = n - n % 8;
    let (s8, s1) = src.split_at(n8);
    let (d8, d1) = dst.split_at_mut(n8);
    for (s, d) in s8.chunks_exact(8).zip(d8.chunks_exact_mut(8)) {
        // SAFETY: s holds 8 u16 (128 bits), d 8 floats.
        unsafe {
            _mm256_storeu_ps(
                d.as_mut_ptr(),
                _mm256_cvtph_ps(_mm_loadu_si128(s.as_ptr() as *const __m128i)),
            )
        };
    }
    simd::scalar::widen_f16(s1, d1);
}
