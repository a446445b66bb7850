//! The activation quantiser (Q8 blocks with their corrections), AVX2 and
//! AVX-512, and its rounding helpers.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// `roundf` (half away from zero) of integral-range lanes, exactly as
/// `libm::roundf`; NaN lanes become 0 (as the scalar `as i8` cast).
///
/// # Safety
/// The CPU must support avx2, fma (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn round_away(t: __m256) -> __m256 {
    let r = _mm256_round_ps::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(t);
    let absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let frac = _mm256_and_ps(_mm256_sub_ps(t, r), absmask);
    let half = _mm256_cmp_ps::<_CMP_GE_OQ>(frac, _mm256_set1_ps(0.5));
    let one = _mm256_or_ps(_mm256_set1_ps(1.0), _mm256_andnot_ps(absmask, t)); // copysign(1, t)
    let r = _mm256_add_ps(r, _mm256_and_ps(half, one));
    _mm256_and_ps(r, _mm256_cmp_ps::<_CMP_ORD_Q>(t, t))
}

/// Horizontal max of 8 lanes.
///
/// # Safety
/// The CPU must support avx2 (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn hmax(v: __m256) -> f32 {
    let s = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
    let s = _mm_max_ps(s, _mm_movehl_ps(s, s));
    let s = _mm_max_ss(s, _mm_shuffle_ps::<0b01>(s, s));
    _mm_cvtss_f32(s)
}

/// See [`simd::quantise_q8_corr`]; bit-identical to the scalar twin (same
/// IEEE divisions and products, `roundf` emulated exactly).
///
/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn quantise_q8_corr(x: &[f32], q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    let absmask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    let fix = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    let blocks = x
        .chunks_exact(Q8_BLOCK)
        .zip(q.chunks_exact_mut(Q8_BLOCK))
        .zip(d.iter_mut().zip(c.chunks_exact_mut(2)));
    for ((xb, qb), (db, cb)) in blocks {
        // SAFETY: xb holds exactly 32 floats.
        let v: [__m256; 4] =
            core::array::from_fn(|i| unsafe { _mm256_loadu_ps(xb.as_ptr().add(8 * i)) });
        // max(|v|, acc) keeps acc when v is NaN: f32::max's NaN rule, as the twin.
        let mut m = _mm256_setzero_ps();
        for vi in &v {
            m = _mm256_max_ps(_mm256_and_ps(*vi, absmask), m);
        }
        let (scale, inv) = simd::q8_scale(hmax(m));
        *db = scale;
        let inv = _mm256_set1_ps(inv);
        let r: [__m256; 4] = core::array::from_fn(|i| round_away(_mm256_mul_ps(v[i], inv)));
        let sum = _mm256_add_ps(_mm256_add_ps(r[0], r[1]), _mm256_add_ps(r[2], r[3]));
        // Lanes 0..4 of each 8 are parity 0, lanes 4..8 parity 1 (exact sums of integers).
        let (lo, hi) = (_mm256_castps256_ps128(sum), _mm256_extractf128_ps::<1>(sum));
        let h4 = |v: __m128| {
            let s = _mm_add_ps(v, _mm_movehl_ps(v, v));
            _mm_cvtss_f32(_mm_add_ss(s, _mm_shuffle_ps::<0b01>(s, s)))
        };
        cb[0] = -128 * h4(lo) as i32;
        cb[1] = -128 * h4(hi) as i32;
        let i: [__m256i; 4] = r.map(|ri| _mm256_cvtps_epi32(ri));
        let p = _mm256_packs_epi16(
            _mm256_packs_epi32(i[0], i[1]),
            _mm256_packs_epi32(i[2], i[3]),
        );
        let p = _mm256_permutevar8x32_epi32(p, fix);
        // SAFETY: qb holds exactly 32 bytes.
        unsafe { _mm256_storeu_si256(qb.as_mut_ptr() as *mut __m256i, p) };
    }
}

/// See [`simd::quantise_q8_corr`]: [`quantise_q8_corr`]'s values, 16
/// blocks at a time on 16 lanes. The per-block scalar steps of the AVX2
/// kernel (the horizontal maximum, then two dependent IEEE divisions per
/// block) become one vector division of the 16 blocks' maxima for the
/// scales and one for their reciprocals (the same IEEE quotients, lane by
/// lane: [`simd::q8_scale`]'s zero and overflow rules as masks); each block
/// is then scaled, rounded half away from zero ([`round_away_512`]),
/// narrowed with signed saturation in order, and its parity corrections
/// summed (exact integer sums). A last group of 4-15 blocks runs the same
/// way on its blocks' lanes (a 768-wide row is 16 + 8 blocks); one of 1-3
/// takes [`quantise_q8_corr`]. Bit for bit the AVX2 kernel and the scalar twin.
///
/// # Safety
/// The CPU must support avx512f, avx2 and fma.
#[target_feature(enable = "avx512f,avx2,fma")]
pub unsafe fn quantise_q8_corr_512(x: &[f32], q: &mut [i8], d: &mut [f32], c: &mut [i32]) {
    let nb = (x.len() / Q8_BLOCK)
        .min(q.len() / Q8_BLOCK)
        .min(d.len())
        .min(c.len() / 2);
    // A last group of at least PARTIAL_MIN blocks (a 768-wide row: 16 + 8)
    // runs here too, its missing blocks' lanes zero and never stored.
    const PARTIAL_MIN: usize = 4;
    let whole = if nb % 16 >= PARTIAL_MIN {
        nb
    } else {
        nb - nb % 16
    };
    let zero = _mm512_setzero_ps();
    for b0 in (0..whole).step_by(16) {
        let valid = (whole - b0).min(16);
        // Lane maxima of |x| per block (a NaN lane keeps the running maximum, f32::max's
        // rule: `vmaxps` returns its second operand where either is NaN), then the 16
        // blocks' maxima in one vector by a transposing tree: no NaN is left, so any
        // order of maxima gives the same bits.
        let lane_max: [__m512; 16] = core::array::from_fn(|b| {
            if b >= valid {
                return zero;
            }
            // SAFETY: blocks b0 + b < nb: 32 floats each in `x`.
            let (v0, v1) = unsafe {
                (
                    _mm512_loadu_ps(x.as_ptr().add(32 * (b0 + b))),
                    _mm512_loadu_ps(x.as_ptr().add(32 * (b0 + b) + 16)),
                )
            };
            _mm512_max_ps(_mm512_abs_ps(v1), _mm512_max_ps(_mm512_abs_ps(v0), zero))
        });
        let amax = fold16_ps(lane_max, |a, b| _mm512_max_ps(a, b))[0];
        // q8_scale: scale = amax / 127; inv = 1 / scale where scale > 0; both 0 where inv overflows.
        let scale = _mm512_div_ps(amax, _mm512_set1_ps(127.0));
        let inv = _mm512_maskz_div_ps(
            _mm512_cmp_ps_mask::<_CMP_GT_OQ>(scale, zero),
            _mm512_set1_ps(1.0),
            scale,
        );
        let keep = _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(inv, _mm512_set1_ps(f32::INFINITY));
        let (scale, inv) = (
            _mm512_maskz_mov_ps(keep, scale),
            _mm512_maskz_mov_ps(keep, inv),
        );
        // SAFETY: d holds blocks b0 .. b0 + valid (the masked lanes).
        unsafe { _mm512_mask_storeu_ps(d.as_mut_ptr().add(b0), lanes16(valid), scale) };
        let mut invs = [0f32; 16];
        // SAFETY: invs holds 16 floats.
        unsafe { _mm512_storeu_ps(invs.as_mut_ptr(), inv) };
        let sums: [__m512i; 16] = core::array::from_fn(|b| {
            if b >= valid {
                return _mm512_setzero_si512();
            }
            let at = 32 * (b0 + b);
            let ib = _mm512_set1_ps(invs[b]);
            // SAFETY: block b0 + b: 32 floats of `x`, 32 bytes of `q`.
            unsafe {
                let r0 = round_away_512(_mm512_mul_ps(_mm512_loadu_ps(x.as_ptr().add(at)), ib));
                let r1 =
                    round_away_512(_mm512_mul_ps(_mm512_loadu_ps(x.as_ptr().add(at + 16)), ib));
                let (i0, i1) = (_mm512_cvtps_epi32(r0), _mm512_cvtps_epi32(r1));
                _mm_storeu_si128(
                    q.as_mut_ptr().add(at) as *mut __m128i,
                    _mm512_cvtsepi32_epi8(i0),
                );
                _mm_storeu_si128(
                    q.as_mut_ptr().add(at + 16) as *mut __m128i,
                    _mm512_cvtsepi32_epi8(i1),
                );
                // Value i is lane i % 16 of i0 / i1; its parity (i % 8) / 4 that of its lane.
                _mm512_add_epi32(i0, i1)
            }
        });
        // Per block, the sums of lanes 0-3 and 8-11 (even parity) and of 4-7 and 12-15 (odd):
        // the tree's first three levels keep the parities apart and leave them side by side,
        // (c[2b], c[2b + 1]) for 8 blocks per vector (integer sums: any order is exact).
        let [lo, hi, ..] = fold16_epi32(sums);
        let k = _mm512_set1_epi32(-128);
        // Blocks 0-7 of the group in `lo`, 8-15 in `hi`, two corrections each.
        let (n_lo, n_hi) = ((2 * valid).min(16), (2 * valid).saturating_sub(16));
        // SAFETY: c holds the 2 * valid corrections of blocks b0 .. b0 + valid (the masked lanes).
        unsafe {
            _mm512_mask_storeu_epi32(
                c.as_mut_ptr().add(2 * b0),
                lanes16(n_lo),
                _mm512_mullo_epi32(lo, k),
            );
            _mm512_mask_storeu_epi32(
                c.as_mut_ptr().add(2 * b0 + 16),
                lanes16(n_hi),
                _mm512_mullo_epi32(hi, k),
            );
        }
    }
    // SAFETY: this fn's contract covers the AVX2 kernel's.
    unsafe {
        quantise_q8_corr(
            &x[32 * whole..32 * nb],
            &mut q[32 * whole..32 * nb],
            &mut d[whole..nb],
            &mut c[2 * whole..2 * nb],
        )
    };
}

/// Lane pairs of the quantiser's transposing trees: per level, the two
/// `vpermt2ps` / `vpermt2d` index vectors over a pair of vectors `a`, `b`
/// (indices 16 and up are `b`'s lanes); output lane `i` combines lane
/// `first[i]` with lane `second[i]` of the pair. Level 0: lane `h` of each
/// 8-lane half with lane `h + 8` (a block's 16 lanes to 8, `a`'s block in
/// lanes 0-7, `b`'s in 8-15); level 1: in each group of 4 lanes, lanes 0
/// and 1 with lanes 2 and 3 (8 to 4 per block); levels 2 and 3: each even
/// lane with the odd lane after it (4 to 2, 2 to 1). Lanes 0-3 and 8-11 of
/// a block (one parity of `quantise_q8_corr`'s corrections) only ever meet
/// each other until level 2, and so do lanes 4-7 and 12-15.
const FOLD: [([i32; 16], [i32; 16]); 4] = {
    let mut f = [([0i32; 16], [0i32; 16]); 4];
    let mut i = 0;
    while i < 16 {
        let (v, h) = ((i / 8) as i32 * 16, (i % 8) as i32);
        f[0].0[i] = v + h;
        f[0].1[i] = v + h + 8;
        let (g, r) = ((i / 2) as i32, (i % 2) as i32);
        f[1].0[i] = 4 * g + r;
        f[1].1[i] = 4 * g + r + 2;
        f[2].0[i] = 2 * i as i32;
        f[2].1[i] = 2 * i as i32 + 1;
        f[3].0[i] = 2 * i as i32;
        f[3].1[i] = 2 * i as i32 + 1;
        i += 1;
    }
    f
};

/// Folds 16 vectors (one per block) into 1 with `op` (exact and
/// order-free on the values given): lane `b` = `op` over vector `b`'s lanes.
#[inline]
#[target_feature(enable = "avx512f")]
fn fold16_ps(v: [__m512; 16], op: impl Fn(__m512, __m512) -> __m512) -> [__m512; 1] {
    // SAFETY: FOLD's rows are 16 i32 each.
    let idx = |l: usize, h: usize| unsafe {
        _mm512_loadu_si512(if h == 0 {
            FOLD[l].0.as_ptr()
        } else {
            FOLD[l].1.as_ptr()
        } as *const _)
    };
    let level = |l: usize, a: __m512, b: __m512| {
        op(
            _mm512_permutex2var_ps(a, idx(l, 0), b),
            _mm512_permutex2var_ps(a, idx(l, 1), b),
        )
    };
    let v: [__m512; 8] = core::array::from_fn(|i| level(0, v[2 * i], v[2 * i + 1]));
    let v: [__m512; 4] = core::array::from_fn(|i| level(1, v[2 * i], v[2 * i + 1]));
    let v: [__m512; 2] = core::array::from_fn(|i| level(2, v[2 * i], v[2 * i + 1]));
    [level(3, v[0], v[1])]
}

/// The first three levels of [`fold16_ps`]'s tree as integer sums: per
/// block `b` (vector `b / 8`, lanes `2 (b % 8)` and `2 (b % 8) + 1`), the
/// sum of its vector's lanes 0-3 and 8-11, and of lanes 4-7 and 12-15.
#[inline]
#[target_feature(enable = "avx512f")]
fn fold16_epi32(v: [__m512i; 16]) -> [__m512i; 2] {
    // SAFETY: FOLD's rows are 16 i32 each.
    let idx = |l: usize, h: usize| unsafe {
        _mm512_loadu_si512(if h == 0 {
            FOLD[l].0.as_ptr()
        } else {
            FOLD[l].1.as_ptr()
        } as *const _)
    };
    let level = |l: usize, a: __m512i, b: __m512i| {
        _mm512_add_epi32(
            _mm512_permutex2var_epi32(a, idx(l, 0), b),
            _mm512_permutex2var_epi32(a, idx(l, 1), b),
        )
    };
    let v: [__m512i; 8] = core::array::from_fn(|i| level(0, v[2 * i], v[2 * i + 1]));
    let v: [__m512i; 4] = core::array::from_fn(|i| level(1, v[2 * i], v[2 * i + 1]));
    core::array::from_fn(|i| level(2, v[2 * i], v[2 * i + 1]))
}

/// [`round_away`] on 16 lanes: `roundf` (half away from zero), NaN to zero.
#[inline]
#[target_feature(enable = "avx512f")]
fn round_away_512(t: __m512) -> __m512 {
    let r = _mm512_roundscale_ps::<{ _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC }>(t);
    let half =
        _mm512_cmp_ps_mask::<_CMP_GE_OQ>(_mm512_abs_ps(_mm512_sub_ps(t, r)), _mm512_set1_ps(0.5));
    // copysign(1, t)
    let sign = _mm512_and_si512(_mm512_castps_si512(t), _mm512_set1_epi32(i32::MIN));
    let one = _mm512_castsi512_ps(_mm512_or_si512(
        _mm512_castps_si512(_mm512_set1_ps(1.0)),
        sign,
    ));
    let r = _mm512_mask_add_ps(r, half, r, one);
    _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_ORD_Q>(t, t), r)
}
