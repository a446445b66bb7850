//! The softmax's pieces: `exp` on 8 and 16 lanes (bit-identical to the
//! scalar twin), the shifted exponential sum, scale-and-max.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// [`simd::scalar::exp`] on 8 lanes, the same operations in the same
/// order (no FMA): bit-identical.
///
/// # Safety
/// The CPU must support avx2.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn exp8(x: __m256) -> __m256 {
    use simd::scalar::exp_c::*;
    // min(HI, x) keeps a NaN x (the second operand is returned on NaN).
    let x = _mm256_min_ps(_mm256_set1_ps(HI), x);
    let below = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_set1_ps(LO));
    let fx = _mm256_floor_ps(_mm256_add_ps(
        _mm256_mul_ps(x, _mm256_set1_ps(LOG2E)),
        _mm256_set1_ps(0.5),
    ));
    let r = _mm256_sub_ps(x, _mm256_mul_ps(fx, _mm256_set1_ps(C1)));
    let r = _mm256_sub_ps(r, _mm256_mul_ps(fx, _mm256_set1_ps(C2)));
    let z = _mm256_mul_ps(r, r);
    let mut y = _mm256_set1_ps(P[0]);
    for &p in &P[1..] {
        y = _mm256_add_ps(_mm256_mul_ps(y, r), _mm256_set1_ps(p));
    }
    let y = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(y, z), r), _mm256_set1_ps(1.0));
    let n = _mm256_cvtps_epi32(fx);
    let pow2n = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(
        n,
        _mm256_set1_epi32(127),
    )));
    _mm256_andnot_ps(below, _mm256_mul_ps(y, pow2n))
}

/// [`exp8`] on 16 lanes: the same operations (no FMA; `vrndscaleps` as
/// floor, a zeroing mask for the underflow), so each lane is
/// [`simd::scalar::exp`], bit for bit.
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn exp16(x: __m512) -> __m512 {
    use simd::scalar::exp_c::*;
    // min(HI, x) keeps a NaN x (the second operand is returned on NaN).
    let x = _mm512_min_ps(_mm512_set1_ps(HI), x);
    let below = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, _mm512_set1_ps(LO));
    let fx = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC }>(_mm512_add_ps(
        _mm512_mul_ps(x, _mm512_set1_ps(LOG2E)),
        _mm512_set1_ps(0.5),
    ));
    let r = _mm512_sub_ps(x, _mm512_mul_ps(fx, _mm512_set1_ps(C1)));
    let r = _mm512_sub_ps(r, _mm512_mul_ps(fx, _mm512_set1_ps(C2)));
    let z = _mm512_mul_ps(r, r);
    let mut y = _mm512_set1_ps(P[0]);
    for &p in &P[1..] {
        y = _mm512_add_ps(_mm512_mul_ps(y, r), _mm512_set1_ps(p));
    }
    let y = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(y, z), r), _mm512_set1_ps(1.0));
    let n = _mm512_cvtps_epi32(fx);
    let pow2n = _mm512_castsi512_ps(_mm512_slli_epi32::<23>(_mm512_add_epi32(
        n,
        _mm512_set1_epi32(127),
    )));
    _mm512_maskz_mov_ps(!below, _mm512_mul_ps(y, pow2n))
}

/// See [`simd::exp_shifted_sum`]: [`exp_shifted_sum`] with the
/// exponentials on 16 lanes (the tail masked); the two 8-lane halves of a
/// 16-lane block are added into the 8 lane sums one after the other, as
/// the 8-wide loop adds two blocks, and the tail in order: bit for bit.
///
/// # Safety
/// The CPU must support avx512f and avx2.
#[inline]
#[target_feature(enable = "avx512f,avx2")]
pub unsafe fn exp_shifted_sum_512(s: &mut [f32], max: f32) -> f32 {
    let n = s.len();
    let (body, rest) = s.split_at_mut(n - n % 16);
    let m = _mm512_set1_ps(max);
    let mut acc = _mm256_setzero_ps();
    for c in body.chunks_exact_mut(16) {
        // SAFETY: c holds 16 floats.
        unsafe {
            let e = exp16(_mm512_sub_ps(_mm512_loadu_ps(c.as_ptr()), m));
            _mm512_storeu_ps(c.as_mut_ptr(), e);
            acc = _mm256_add_ps(acc, _mm512_castps512_ps256(e));
            acc = _mm256_add_ps(
                acc,
                _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(e))),
            );
        }
    }
    let mut t = 0.0f32;
    if !rest.is_empty() {
        let k = lanes16(rest.len());
        let mut e = [0f32; 16];
        // SAFETY: masked lanes < rest.len() of rest; e holds 16 floats.
        unsafe {
            _mm512_storeu_ps(
                e.as_mut_ptr(),
                exp16(_mm512_sub_ps(_mm512_maskz_loadu_ps(k, rest.as_ptr()), m)),
            )
        };
        rest.copy_from_slice(&e[..rest.len()]);
        let whole = if rest.len() >= 8 { 8 } else { 0 };
        if whole == 8 {
            // SAFETY: e holds 16 floats.
            acc = _mm256_add_ps(acc, unsafe { _mm256_loadu_ps(e.as_ptr()) });
        }
        for &v in &e[whole..rest.len()] {
            t += v;
        }
    }
    let mut a = [0f32; 8];
    // SAFETY: a holds 8 floats.
    unsafe { _mm256_storeu_ps(a.as_mut_ptr(), acc) };
    simd::scalar::reduce8(a, t)
}

/// See [`simd::scale_max`]: 16 lanes at a time, the tail masked; the lane
/// maxima by `vmaxps` with the running maximum as its second operand (a NaN
/// score leaves it as it was, as `f32::max` does).
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
pub unsafe fn scale_max_512(s: &mut [f32], scale: f32, max: f32) -> f32 {
    let (sc, mut vm) = (_mm512_set1_ps(scale), _mm512_set1_ps(f32::NEG_INFINITY));
    for c in s.chunks_mut(16) {
        let m = lanes16(c.len());
        // SAFETY: masked lanes < c.len() of c only.
        unsafe {
            let v = _mm512_mul_ps(_mm512_maskz_loadu_ps(m, c.as_ptr()), sc);
            _mm512_mask_storeu_ps(c.as_mut_ptr(), m, v);
            vm = _mm512_mask_max_ps(vm, m, v, vm);
        }
    }
    max.max(_mm512_reduce_max_ps(vm))
}

/// See [`simd::scale_max`]: 8 lanes at a time, the tail as the twin's; the
/// lane maxima by `vmaxps` with the running maximum as its second operand
/// (a NaN score leaves it as it was, as `f32::max` does).
///
/// # Safety
/// The CPU must support avx2.
#[inline]
#[target_feature(enable = "avx2")]
pub unsafe fn scale_max_avx2(s: &mut [f32], scale: f32, max: f32) -> f32 {
    let n = s.len();
    let (body, tail) = s.split_at_mut(n - n % 8);
    let (sc, mut vm) = (_mm256_set1_ps(scale), _mm256_set1_ps(f32::NEG_INFINITY));
    for c in body.chunks_exact_mut(8) {
        // SAFETY: c holds 8 floats.
        unsafe {
            let v = _mm256_mul_ps(_mm256_loadu_ps(c.as_ptr()), sc);
            _mm256_storeu_ps(c.as_mut_ptr(), v);
            vm = _mm256_max_ps(v, vm);
        }
    }
    let mut lanes = [0f32; 8];
    // SAFETY: lanes holds 8 floats.
    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), vm) };
    let mut max = lanes.iter().fold(max, |a, &b| a.max(b));
    for x in tail {
        *x *= scale;
        max = max.max(*x);
    }
    max
}

/// See [`simd::exp_shifted_sum`] (8 lane sums, reduced as the twin does).
///
/// # Safety
/// The CPU must support avx2.
#[inline]
#[target_feature(enable = "avx2")]
pub unsafe fn exp_shifted_sum(s: &mut [f32], max: f32) -> f32 {
    let n = s.len();
    let (body, tail) = s.split_at_mut(n - n % 8);
    let m = _mm256_set1_ps(max);
    let mut acc = _mm256_setzero_ps();
    for c in body.chunks_exact_mut(8) {
        // SAFETY: c holds 8 floats.
        unsafe {
            let e = exp8(_mm256_sub_ps(_mm256_loadu_ps(c.as_ptr()), m));
            _mm256_storeu_ps(c.as_mut_ptr(), e);
            acc = _mm256_add_ps(acc, e);
        }
    }
    let mut a = [0f32; 8];
    // SAFETY: a holds 8 floats.
    unsafe { _mm256_storeu_ps(a.as_mut_ptr(), acc) };
    // The tail's exponentials on 8 lanes too (each lane is `scalar::exp`,
    // bit for bit), then added in order as the twin adds them.
    let mut t = 0.0f32;
    if !tail.is_empty() {
        let mut pad = [0f32; 8];
        pad[..tail.len()].copy_from_slice(tail);
        // SAFETY: pad holds 8 floats.
        unsafe {
            _mm256_storeu_ps(
                pad.as_mut_ptr(),
                exp8(_mm256_sub_ps(_mm256_loadu_ps(pad.as_ptr()), m)),
            )
        };
        for (v, &e) in tail.iter_mut().zip(&pad) {
            *v = e;
            t += e;
        }
    }
    simd::scalar::reduce8(a, t)
}

/// See [`simd::softmax_runs`]: its body over [`scale_max_512`] and
/// [`exp_shifted_sum_512`] (inlined), so bit for bit their calls run by run.
///
/// # Safety
/// The CPU must support avx512f and avx2.
#[target_feature(enable = "avx512f,avx2")]
pub unsafe fn softmax_runs_512(row: &mut [f32], runs: &[(usize, usize)], scale: f32) -> f32 {
    simd::softmax_runs_with(
        row,
        runs,
        scale,
        // SAFETY: this fn's features.
        |s, sc, m| unsafe { scale_max_512(s, sc, m) },
        // SAFETY: as above.
        |s, m| unsafe { exp_shifted_sum_512(s, m) },
    )
}

/// See [`simd::softmax_runs`]: its body over [`scale_max_avx2`] and
/// [`exp_shifted_sum`] (inlined), so bit for bit their calls run by run.
///
/// # Safety
/// The CPU must support avx2.
#[target_feature(enable = "avx2")]
pub unsafe fn softmax_runs_avx2(row: &mut [f32], runs: &[(usize, usize)], scale: f32) -> f32 {
    simd::softmax_runs_with(
        row,
        runs,
        scale,
        // SAFETY: this fn's features.
        |s, sc, m| unsafe { scale_max_avx2(s, sc, m) },
        // SAFETY: as above.
        |s, m| unsafe { exp_shifted_sum(s, m) },
    )
}
