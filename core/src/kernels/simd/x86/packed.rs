//! int8 GEMMs over packed weights (8 rows interleaved: `PackedQ8`), per
//! ISA: AVX-512 VNNI, AVX-VNNI and AVX2, and the packer.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// See [`simd::gemm_q8_packed`]: per block, the 4 packed groups made
/// unsigned (int8: `^ 0x80` = `w + 128`; 4-bit: the nibbles as stored, `q +
/// 8`, split out of the two halves) and the 8 f16 scales widened once for
/// every activation row; per activation row, 4 `vpdpbusd` of the groups
/// against the row's 8-byte groups broadcast to every lane, started at the
/// row's parity corrections (int8: `-128 sum(q)` as given, 4-bit: the same
/// shifted to `-8 sum(q)`, exact), so the two i32 lanes of a weight row
/// hold the halves of its block dot, added (exact) into the block's sum.
///
/// Blocks go in pairs: lane `2n` of the accumulator takes weight row `n`'s
/// even blocks, lane `2n + 1` its odd blocks, each block with one convert,
/// one scale product `s_n,b * xd_b` and one FMA (a last unpaired block
/// updates the even lanes only); the two lanes are added at the end. The
/// AMX kernel ([`simd::amx`]) performs exactly these f32 steps per lane on
/// the tile unit's block sums, so both give the same bits.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl/vnni, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_vnni<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_vnni_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_vnni`] that also prefetches `ahead` into L2, spread
/// over its block pairs ([`simd::prefetch_part`]).
///
/// # Safety
/// As [`gemm_q8_packed_vnni`].
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_vnni_ahead<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    if w.q4 {
        // SAFETY: the caller's features are this function's.
        unsafe { packed_vnni::<M, true>(w, xq, xd, xc, ahead) }
    } else {
        // SAFETY: as above.
        unsafe { packed_vnni::<M, false>(w, xq, xd, xc, ahead) }
    }
}

/// [`gemm_q8_packed_vnni`] for one value width (`Q4`: 4-bit halves).
///
/// # Safety
/// As [`gemm_q8_packed_vnni`].
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
unsafe fn packed_vnni<const M: usize, const Q4: bool>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    use simd::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    let pv = if Q4 { PN } else { PV };
    debug_assert_eq!(w.q4, Q4);
    let nb = w.blocks_for(xq, xd, xc);
    let flip = _mm512_set1_epi8(-128);
    let low = _mm512_set1_epi8(0x0f);
    let ilv = _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
    // Raw row pointers: `nb` (blocks_for) is at most what every row, the
    // values and the scales hold, so the indexing below needs no bounds
    // checks (they cost a quarter of this kernel's time on a 12-row call).
    let (vp, sp) = (w.v.as_ptr(), w.s.as_ptr());
    let qp: [*const i8; M] = core::array::from_fn(|m| xq[m].as_ptr());
    let dp_: [*const f32; M] = core::array::from_fn(|m| xd[m].as_ptr());
    let cp: [*const i32; M] = core::array::from_fn(|m| xc[m].as_ptr());
    // Block b's 4 unsigned groups and 8 widened scales.
    let block = |b: usize| -> ([__m512i; 4], __m256) {
        // SAFETY: b < nb: the values hold pv bytes and the scales PS bytes
        // of block b.
        let (vb, sb) = unsafe { (vp.add(pv * b), sp.add(PS * b)) };
        let wv: [__m512i; 4] = if Q4 {
            // SAFETY: vb holds 2 x 64 bytes.
            let h: [__m512i; 2] =
                core::array::from_fn(|k| unsafe { _mm512_loadu_si512(vb.add(64 * k) as *const _) });
            [
                _mm512_and_si512(h[0], low),
                _mm512_and_si512(h[1], low),
                _mm512_and_si512(_mm512_srli_epi16::<4>(h[0]), low),
                _mm512_and_si512(_mm512_srli_epi16::<4>(h[1]), low),
            ]
        } else {
            // SAFETY: vb holds 4 x 64 bytes.
            core::array::from_fn(|g| {
                _mm512_xor_si512(
                    unsafe { _mm512_loadu_si512(vb.add(64 * g) as *const _) },
                    flip,
                )
            })
        };
        // SAFETY: sb holds 8 f16 (128 bits).
        (
            wv,
            _mm256_cvtph_ps(unsafe { _mm_loadu_si128(sb as *const __m128i) }),
        )
    };
    // Row m's dot with block b's groups: lanes (2n, 2n + 1) = row n's halves.
    let dot = |m: usize, b: usize, wv: &[__m512i; 4]| -> __m512i {
        // SAFETY: b < nb: row m holds Q8_BLOCK values and 2 corrections of block b.
        let (xs, cs) = unsafe { (qp[m].add(b * Q8_BLOCK), cp[m].add(2 * b)) };
        // SAFETY: cs holds 2 i32 (8 bytes), xs 32 bytes (4 x 8).
        let mut dp = unsafe { _mm512_set1_epi64((cs as *const i64).read_unaligned()) };
        if Q4 {
            dp = _mm512_srai_epi32::<4>(dp);
        }
        for (g, wg) in wv.iter().enumerate() {
            // SAFETY: 8g + 8 <= 32.
            let xg = unsafe { _mm512_set1_epi64((xs.add(8 * g) as *const i64).read_unaligned()) };
            dp = _mm512_dpbusd_epi32(dp, *wg, xg);
        }
        dp
    };
    let mut acc = [_mm512_setzero_ps(); M];
    let mut b = 0;
    let pairs = nb.div_ceil(2);
    while b + 1 < nb {
        simd::prefetch_part(ahead, b / 2, pairs);
        let (w0, s0) = block(b);
        let (w1, s1) = block(b + 1);
        // Lane 2n: s_n,b; lane 2n + 1: s_n,b+1.
        let sv =
            _mm512_permutex2var_ps(_mm512_castps256_ps512(s0), ilv, _mm512_castps256_ps512(s1));
        for (m, am) in acc.iter_mut().enumerate() {
            let (d0, d1) = (dot(m, b, &w0), dot(m, b + 1, &w1));
            // Lane 2n: block b's sum of row n; lane 2n + 1: block b + 1's.
            let sums = _mm512_add_epi32(
                _mm512_mask_shuffle_epi32::<0xb1>(d0, 0xaaaa, d1),
                _mm512_mask_shuffle_epi32::<0xb1>(d1, 0x5555, d0),
            );
            // SAFETY: xd[m] holds blocks b and b + 1 (b + 1 < nb).
            let xdv = _mm512_castsi512_ps(_mm512_set1_epi64(unsafe {
                (dp_[m].add(b) as *const i64).read_unaligned()
            }));
            *am = _mm512_fmadd_ps(_mm512_cvtepi32_ps(sums), _mm512_mul_ps(sv, xdv), *am);
        }
        b += 2;
    }
    if b < nb {
        simd::prefetch_part(ahead, b / 2, pairs);
        let (w0, s0) = block(b);
        let dup = _mm512_setr_epi32(0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7);
        let sv = _mm512_permutexvar_ps(dup, _mm512_castps256_ps512(s0));
        for (m, am) in acc.iter_mut().enumerate() {
            let d0 = dot(m, b, &w0);
            let sums = _mm512_add_epi32(d0, _mm512_shuffle_epi32::<0xb1>(d0));
            *am = _mm512_mask3_fmadd_ps(
                _mm512_cvtepi32_ps(sums),
                _mm512_mul_ps(sv, _mm512_set1_ps(xd[m][b])),
                *am,
                0x5555,
            );
        }
    }
    let mut out = [[0.0f32; 8]; M];
    for (o, a) in out.iter_mut().zip(acc) {
        // Lane pairs (2n, 2n + 1) are row n.
        let pairs = _mm512_add_ps(a, _mm512_permute_ps::<0b10_11_00_01>(a));
        let mut t = [0f32; 16];
        // SAFETY: t holds 16 floats.
        unsafe { _mm512_storeu_ps(t.as_mut_ptr(), pairs) };
        for (n, on) in o.iter_mut().enumerate() {
            *on = t[2 * n];
        }
    }
    out
}

/// The rows of a `*_ahead` 32-byte packed kernel in passes of at most 4
/// ([`simd::passes_of_four`]), each pass on `$kernel::<K, Q4>` (one of
/// [`packed_avx2`] / [`packed_avxvnni`]: one function per `K` and value
/// width). Expands to unsafe calls: the caller's features must be the
/// kernel's.
macro_rules! ymm_passes {
    ($kernel:ident, $w:ident, $xq:ident, $xd:ident, $xc:ident, $ahead:ident) => {
        simd::passes_of_four!(M, $ahead, |K, m0, a| {
            let q: [&[i8]; K] = core::array::from_fn(|m| $xq[m0 + m]);
            let d: [&[f32]; K] = core::array::from_fn(|m| $xd[m0 + m]);
            let c: [&[i32]; K] = core::array::from_fn(|m| $xc[m0 + m]);
            if $w.q4 {
                $kernel::<K, true>($w, q, d, c, a)
            } else {
                $kernel::<K, false>($w, q, d, c, a)
            }
        })
    };
}

/// See [`simd::gemm_q8_packed`] on 32-byte vectors (AVX2, and AVX-512
/// without VNNI): the stored groups read in place, no expansion to rows.
///
/// Per block and 8-byte group `g`, the group's two 32-byte halves (weight
/// rows 0-3, 4-7) are the unsigned operand of `vpmaddubsw` (int8: `|w|`,
/// with the activation group broadcast to every lane and given `w`'s sign
/// by `vpsignb`, the sign trick of [`gemm_q8_avx2`]; 4-bit: the stored
/// nibbles `q + 8` against the activation group as it is, the sums started
/// at the row's corrections shifted to `-8 sum(q)`), then `vpmaddwd` by
/// ones: i32 lanes `(2r, 2r + 1)` hold the halves of weight row `r`'s
/// block dot, exact. `vphaddd` of the two halves gives the 8 block sums
/// (lanes: rows 0, 1, 4, 5 | 2, 3, 6, 7), and the f32 steps are
/// [`gemm_q8_packed_vnni`]'s: per block one convert, one scale product
/// `s_n,b * xd_b` and one FMA, even blocks and odd blocks in their own
/// accumulators, added at the end, so both give the same bits.
///
/// The activation rows go 4 at most at a time (the rows shared evenly:
/// 5 = 3 + 2), each row's numbers the same whatever its company.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_avx2<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_avx2_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_avx2`] that also prefetches `ahead` into L2, spread over the
/// blocks of its first pass ([`simd::prefetch_part`]).
///
/// # Safety
/// As [`gemm_q8_packed_avx2`].
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_avx2_ahead<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are `packed_avx2`'s.
    unsafe { ymm_passes!(packed_avx2, w, xq, xd, xc, ahead) }
}

/// See [`simd::gemm_q8_packed`] on 32-byte vectors with AVX-VNNI: the
/// layout, passes and f32 steps of [`gemm_q8_packed_avx2`], the block dots
/// by `{vex} vpdpbusd` (int8: the weights made unsigned `w + 128` by `^
/// 0x80`, the sums started at the row's parity corrections `-128 sum(q)`;
/// 4-bit: as [`gemm_q8_packed_avx2`]), so the same bits as every other
/// packed kernel.
///
/// # Safety
/// The CPU must support avx2, fma, f16c and avxvnni.
#[target_feature(enable = "avx2,fma,f16c,avxvnni")]
pub unsafe fn gemm_q8_packed_avxvnni<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_avxvnni_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_avxvnni`] that also prefetches `ahead` into L2 (as
/// [`gemm_q8_packed_avx2_ahead`]).
///
/// # Safety
/// As [`gemm_q8_packed_avxvnni`].
#[target_feature(enable = "avx2,fma,f16c,avxvnni")]
pub unsafe fn gemm_q8_packed_avxvnni_ahead<const M: usize>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are `packed_avxvnni`'s.
    unsafe { ymm_passes!(packed_avxvnni, w, xq, xd, xc, ahead) }
}

/// [`packed_ymm`] with `vpmaddubsw` + `vpmaddwd`: one function per `K` and
/// value width, shared by every row count `M` of its callers (the body
/// inlined into each `M` made the C library 0.5 MB larger).
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn packed_avx2<const K: usize, const Q4: bool>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    xc: [&[i32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    // SAFETY: this fn's features are packed_ymm's without VNNI.
    unsafe { packed_ymm::<K, Q4, false>(w, xq, xd, xc, ahead) }
}

/// [`packed_ymm`] with `{vex} vpdpbusd` (as [`packed_avx2`]).
///
/// # Safety
/// The CPU must support avx2, fma, f16c and avxvnni.
#[inline]
#[target_feature(enable = "avx2,fma,f16c,avxvnni")]
unsafe fn packed_avxvnni<const K: usize, const Q4: bool>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    xc: [&[i32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    // SAFETY: this fn's features are packed_ymm's with VNNI.
    unsafe { packed_ymm::<K, Q4, true>(w, xq, xd, xc, ahead) }
}

/// The packed kernel on 32-byte vectors for `K` (1..=4) activation rows,
/// one value width (`Q4`: 4-bit halves) and one multiply (`VNNI`:
/// `vpdpbusd`; else `vpmaddubsw` + `vpmaddwd`). Always inlined into its
/// callers, whose `#[target_feature]` sets the instructions it may use.
///
/// # Safety
/// The CPU must support avx2, fma and f16c, and avxvnni where `VNNI`.
#[inline(always)]
unsafe fn packed_ymm<const K: usize, const Q4: bool, const VNNI: bool>(
    w: simd::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    xc: [&[i32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    use simd::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    let pv = if Q4 { PN } else { PV };
    debug_assert_eq!(w.q4, Q4);
    let nb = w.blocks_for(xq, xd, xc);
    // Raw row pointers: `nb` (blocks_for) is at most what every row, the
    // values and the scales hold, so the indexing below needs no bounds checks.
    let (vp, sp) = (w.v.as_ptr(), w.s.as_ptr());
    let qp: [*const i8; K] = core::array::from_fn(|m| xq[m].as_ptr());
    let dp_: [*const f32; K] = core::array::from_fn(|m| xd[m].as_ptr());
    let cp: [*const i32; K] = core::array::from_fn(|m| xc[m].as_ptr());
    // SAFETY (every intrinsic and pointer offset below): the caller's
    // features (avx2, fma, f16c; avxvnni for `_mm256_dpbusd_avx_epi32`,
    // used only where VNNI); every offset is of block b < nb.
    unsafe {
        let ones = _mm256_set1_epi16(1);
        let low = _mm256_set1_epi8(0x0f);
        let flip = _mm256_set1_epi8(-128);
        // The lane order of `vphaddd` over the two halves, and back (its own inverse).
        let order = _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7);
        // [row m][even / odd blocks]: lanes in `order`.
        let mut acc = [[_mm256_setzero_ps(); 2]; K];
        for b in 0..nb {
            simd::prefetch_part(ahead, b, nb);
            let (vb, sb) = (vp.add(pv * b), sp.add(PS * b));
            // sb holds 8 f16 (128 bits).
            let sv = _mm256_permutevar8x32_ps(
                _mm256_cvtph_ps(_mm_loadu_si128(sb as *const __m128i)),
                order,
            );
            // [row m][weight rows 0-3 / 4-7]: i32 lanes (2r, 2r + 1) = halves
            // of row r's block dot, started at the parity corrections where
            // the weights are offset (4-bit: `q + 8`; VNNI int8: `w + 128`).
            let mut dp: [[__m256i; 2]; K] = core::array::from_fn(|m| {
                if Q4 || VNNI {
                    // Row m's 2 corrections of block b (8 bytes).
                    let c = _mm256_set1_epi64x((cp[m].add(2 * b) as *const i64).read_unaligned());
                    let c = if Q4 { _mm256_srai_epi32::<4>(c) } else { c };
                    [c, c]
                } else {
                    [_mm256_setzero_si256(); 2]
                }
            });
            for g in 0..4 {
                let wg: [__m256i; 2] = core::array::from_fn(|h| {
                    if Q4 {
                        // vb holds 2 x 64 bytes; 64 (g % 2) + 32 h + 32 <= 128.
                        let v = _mm256_loadu_si256(vb.add(64 * (g % 2) + 32 * h) as *const __m256i);
                        if g < 2 {
                            _mm256_and_si256(v, low)
                        } else {
                            _mm256_and_si256(_mm256_srli_epi16::<4>(v), low)
                        }
                    } else {
                        // vb holds 4 x 64 bytes; 64 g + 32 h + 32 <= 256.
                        _mm256_loadu_si256(vb.add(64 * g + 32 * h) as *const __m256i)
                    }
                });
                // The unsigned operand: 4-bit as stored; int8 `w + 128`
                // (VNNI) or `|w|` (the sign trick of [`gemm_q8_avx2`]).
                let uw = if Q4 {
                    wg
                } else if VNNI {
                    wg.map(|v| _mm256_xor_si256(v, flip))
                } else {
                    wg.map(|v| _mm256_sign_epi8(v, v))
                };
                for (m, dm) in dp.iter_mut().enumerate() {
                    // Row m's 8 bytes of group g of block b.
                    let xs = qp[m].add(b * Q8_BLOCK + 8 * g);
                    let xg = _mm256_set1_epi64x((xs as *const i64).read_unaligned());
                    for h in 0..2 {
                        dm[h] = if VNNI {
                            _mm256_dpbusd_avx_epi32(dm[h], uw[h], xg)
                        } else {
                            let sx = if Q4 { xg } else { _mm256_sign_epi8(xg, wg[h]) };
                            _mm256_add_epi32(
                                dm[h],
                                _mm256_madd_epi16(_mm256_maddubs_epi16(uw[h], sx), ones),
                            )
                        };
                    }
                }
            }
            for (m, am) in acc.iter_mut().enumerate() {
                // Lanes: the block sums of rows 0, 1, 4, 5 | 2, 3, 6, 7.
                let sums = _mm256_hadd_epi32(dp[m][0], dp[m][1]);
                let a = &mut am[b % 2];
                *a = _mm256_fmadd_ps(
                    _mm256_cvtepi32_ps(sums),
                    _mm256_mul_ps(sv, _mm256_set1_ps(*dp_[m].add(b))),
                    *a,
                );
            }
        }
        let mut out = [[0.0f32; 8]; K];
        for (o, a) in out.iter_mut().zip(acc) {
            // o holds 8 floats.
            _mm256_storeu_ps(
                o.as_mut_ptr(),
                _mm256_permutevar8x32_ps(_mm256_add_ps(a[0], a[1]), order),
            );
        }
        out
    }
}

/// See [`simd::q8_pack8`]: per block, the 8 rows' 32 bytes (as 4 qwords
/// each) transposed to 4 vectors of 8 qwords with two `vpermt2q` and one
/// `vshufi64x2` stage; the 8 scale words gathered.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl, avx2; every row holds `nb` blocks.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2")]
pub unsafe fn q8_pack8(rows: [&[u8]; 8], nb: usize, v: &mut [u8], s: &mut [u8]) {
    use simd::{PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
    let ia = _mm512_setr_epi64(0, 4, 8, 12, 1, 5, 9, 13);
    let ib = _mm512_setr_epi64(2, 6, 10, 14, 3, 7, 11, 15);
    for b in 0..nb.min(v.len() / PV).min(s.len() / PS) {
        let r: [__m256i; 8] = core::array::from_fn(|n| {
            let q = &rows[n][b * Q8_BLOCK_BYTES + 2..(b + 1) * Q8_BLOCK_BYTES];
            // SAFETY: q holds exactly 32 bytes.
            unsafe { _mm256_loadu_si256(q.as_ptr() as *const __m256i) }
        });
        let z: [__m512i; 4] = core::array::from_fn(|i| {
            _mm512_inserti64x4::<1>(_mm512_castsi256_si512(r[2 * i]), r[2 * i + 1])
        });
        let a = _mm512_permutex2var_epi64(z[0], ia, z[1]);
        let bq = _mm512_permutex2var_epi64(z[0], ib, z[1]);
        let c = _mm512_permutex2var_epi64(z[2], ia, z[3]);
        let d = _mm512_permutex2var_epi64(z[2], ib, z[3]);
        let out = [
            _mm512_shuffle_i64x2::<0b01_00_01_00>(a, c),
            _mm512_shuffle_i64x2::<0b11_10_11_10>(a, c),
            _mm512_shuffle_i64x2::<0b01_00_01_00>(bq, d),
            _mm512_shuffle_i64x2::<0b11_10_11_10>(bq, d),
        ];
        let vb = &mut v[PV * b..PV * (b + 1)];
        for (g, o) in out.into_iter().enumerate() {
            // SAFETY: vb holds 4 x 64 bytes.
            unsafe { _mm512_storeu_si512(vb.as_mut_ptr().add(64 * g) as *mut _, o) };
        }
        let sb = &mut s[PS * b..PS * (b + 1)];
        for (n, row) in rows.iter().enumerate() {
            sb[2 * n..2 * n + 2].copy_from_slice(&row[b * Q8_BLOCK_BYTES..b * Q8_BLOCK_BYTES + 2]);
        }
    }
}
