//! The attention's query-against-rows products (`dot_rows*`, one query
//! against many key rows, f32 and f16 keys) and the tile reductions.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// `y += a * x` (FMA).
///
/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn axpy_f32(a: f32, x: &[f32], y: &mut [f32]) {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &mut y[..n]);
    let av = _mm256_set1_ps(a);
    let n8 = n - n % 8;
    let (x8, x1) = x.split_at(n8);
    let (y8, y1) = y.split_at_mut(n8);
    for (xc, yc) in x8.chunks_exact(8).zip(y8.chunks_exact_mut(8)) {
        // SAFETY: 8 floats each.
        unsafe {
            _mm256_storeu_ps(
                yc.as_mut_ptr(),
                _mm256_fmadd_ps(
                    av,
                    _mm256_loadu_ps(xc.as_ptr()),
                    _mm256_loadu_ps(yc.as_ptr()),
                ),
            )
        };
    }
    for (yi, xi) in y1.iter_mut().zip(x1) {
        *yi += a * xi;
    }
}

/// See [`simd::dot_rows`] (one AVX2 dot per key row, inlined).
///
/// # Safety
/// The CPU must support avx2 and fma.
#[target_feature(enable = "avx2,fma")]
pub unsafe fn dot_rows(q: &[f32], k: &[f32], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    for (j, o) in out.iter_mut().enumerate() {
        *o = dot_f32(q, &k[j * stride..j * stride + hd]);
    }
}

/// See [`simd::dot_rows_f16`] (one AVX2 [`dot_f16`] per key row: the
/// operations of [`dot_rows`] on the widened rows).
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn dot_rows_f16(q: &[f32], k: &[u16], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    for (j, o) in out.iter_mut().enumerate() {
        // SAFETY: this fn's contract.
        *o = unsafe { dot_f16(&k[j * stride..j * stride + hd], q) };
    }
}

/// See [`simd::dot_rows`]: the query (up to 64 floats) stays in four
/// 16-wide registers; keys two at a time; masked tail lanes, no scalar tail.
/// Longer queries take the AVX2 dot.
///
/// # Safety
/// The CPU must support avx512f, avx2 and fma.
#[target_feature(enable = "avx512f,avx2,fma")]
pub unsafe fn dot_rows_512(q: &[f32], k: &[f32], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    if hd > 64 {
        return dot_rows(q, k, stride, out);
    }
    // SAFETY: masked loads read only lanes < hd of key row j (in bounds: `k` holds the rows).
    let load = |j: usize, i: usize, m: __mmask16| unsafe {
        _mm512_maskz_loadu_ps(m, k[j * stride..j * stride + hd].as_ptr().add(16 * i))
    };
    // SAFETY: this fn's contract.
    unsafe { dot_rows_512_by(q, load, out) }
}

/// See [`simd::dot_rows_f16`]: [`dot_rows_512`] with each key lane loaded
/// as binary16 and widened by `vcvtph2ps` (exact), so every FMA and the
/// reduction see the values [`dot_rows_512`] sees on the widened rows.
///
/// # Safety
/// The CPU must support avx512f, avx512bw, avx512vl, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
pub unsafe fn dot_rows_512_f16(q: &[f32], k: &[u16], stride: usize, out: &mut [f32]) {
    let hd = q.len();
    if hd > 64 {
        // SAFETY: this fn's contract implies dot_rows_f16's.
        return unsafe { dot_rows_f16(q, k, stride, out) };
    }
    // SAFETY: masked 16-bit loads read only lanes < hd of key row j.
    let load = |j: usize, i: usize, m: __mmask16| unsafe {
        _mm512_cvtph_ps(_mm256_maskz_loadu_epi16(
            m,
            k[j * stride..j * stride + hd].as_ptr().add(16 * i) as *const i16,
        ))
    };
    // SAFETY: this fn's contract.
    unsafe { dot_rows_512_by(q, load, out) }
}

/// The shared body of [`dot_rows_512`] and [`dot_rows_512_f16`]:
/// `out[j] = q . key j`, with `load(j, i, mask)` giving lanes
/// `16 i .. 16 i + 16` of key row `j` as f32 (masked lanes zero);
/// `q.len() <= 64`.
///
/// Always inlined into its callers (no features of its own), so that their
/// `load` (F16C and AVX512-BW for [`dot_rows_512_f16`]) is inlined too.
///
/// # Safety
/// The CPU must support avx512f and fma (and what `load` uses); `load`
/// must be sound for `j < out.len()`, `i < ceil(q.len() / 16)`.
#[inline(always)]
unsafe fn dot_rows_512_by(
    q: &[f32],
    load: impl Fn(usize, usize, __mmask16) -> __m512,
    out: &mut [f32],
) {
    // SAFETY (every intrinsic below): the caller's features (avx512f, fma);
    // the loads read only lanes < hd as noted.
    unsafe {
        let hd = q.len().min(64);
        let nv = hd.div_ceil(16);
        let mask: [__mmask16; 4] = core::array::from_fn(|i| {
            if 16 * (i + 1) <= hd {
                0xffff
            } else if 16 * i < hd {
                lanes16(hd - 16 * i)
            } else {
                0
            }
        });
        // Masked loads read only lanes < hd of q.
        let qv: [__m512; 4] = core::array::from_fn(|i| {
            if i < nv {
                _mm512_maskz_loadu_ps(mask[i], q.as_ptr().add(16 * i))
            } else {
                _mm512_setzero_ps()
            }
        });
        let n = out.len();
        let mut j = 0;
        while j + 2 <= n {
            let (mut a, mut b) = (_mm512_setzero_ps(), _mm512_setzero_ps());
            for i in 0..nv {
                a = _mm512_fmadd_ps(qv[i], load(j, i, mask[i]), a);
                b = _mm512_fmadd_ps(qv[i], load(j + 1, i, mask[i]), b);
            }
            out[j] = _mm512_reduce_add_ps(a);
            out[j + 1] = _mm512_reduce_add_ps(b);
            j += 2;
        }
        if j < n {
            let mut a = _mm512_setzero_ps();
            for i in 0..nv {
                a = _mm512_fmadd_ps(qv[i], load(j, i, mask[i]), a);
            }
            out[j] = _mm512_reduce_add_ps(a);
        }
    }
}

/// Key rows ahead of the one multiplied whose lanes the AVX-512 group
/// kernels prefetch ([`dot_block`], [`axpy_block`]). A head's lanes of
/// successive keys lie a whole row apart (`C` values), a stride the
/// hardware prefetchers follow poorly, and in a batch of streaming sessions
/// each cache is read cold from memory. Measured against the same kernels
/// without it (min of 5, two runs each): 16 sessions' S-append attention
/// over 192 distinct f16 caches 0.55-0.57x, one hot cache 0.92x, the R
/// window (f32, 290 keys) 0.93x; distances 3-16 gave the same within noise.
/// The AVX2 per-query kernels ran 1.05-1.25x slower with it and go without.
pub(super) const KEY_PREFETCH: usize = 8;

/// Prefetches (into L1) every 64-byte line `s` touches. No result depends
/// on it.
#[inline(always)]
pub(super) fn prefetch_span<T>(s: &[T]) {
    let (p, bytes) = (s.as_ptr() as *const i8, core::mem::size_of_val(s));
    let mut off = 0;
    while off < bytes {
        // SAFETY: a prefetch is a hint with no architectural effect (sse is
        // baseline on x86_64); the address lies inside `s`.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(off)) };
        off += 64;
    }
    if bytes > 0 {
        // SAFETY: as above; the last byte of `s` (its last line, when `s` does not start on a line).
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(bytes - 1)) };
    }
}

/// See [`simd::dot_rows_group`]: [`dot_rows_512`] for `g`
/// queries, up to [`simd::QUERY_GROUP`] of them held in registers while
/// each key row is loaded once; every (query, key) score takes the FMAs
/// and the reduction of [`dot_rows_512`], so bit for bit the same.
/// Heads wider than 64 take [`dot_rows_512`] per query.
///
/// # Safety
/// The CPU must support avx512f, avx2 and fma.
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn dot_rows_512_group(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    k: &[f32],
    stride: usize,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    if hd == 0 || hd > 64 {
        for m in 0..g {
            // SAFETY: this fn's contract.
            unsafe {
                dot_rows_512(
                    &q[m * q_stride..m * q_stride + hd],
                    k,
                    stride,
                    &mut out[m * out_stride..m * out_stride + n],
                )
            };
        }
        return;
    }
    // SAFETY: masked loads read only lanes < hd of key row j (the slice is bounds-checked).
    let load = |j: usize, i: usize, m: __mmask16| unsafe {
        _mm512_maskz_loadu_ps(m, k[j * stride..j * stride + hd].as_ptr().add(16 * i))
    };
    let ahead = |j: usize| prefetch_span(&k[j * stride..j * stride + hd]);
    // SAFETY: this fn's contract.
    unsafe { dot_rows_512_group_by(q, hd, q_stride, g, load, ahead, n, out, out_stride, side) }
}

/// [`dot_rows_512_group`] over binary16 key rows: each key lane widened by
/// `vcvtph2ps` (exact) once for the group, as [`dot_rows_512_f16`] widens it
/// per query: bit for bit what [`dot_rows_512_f16`] gives per query.
///
/// # Safety
/// The CPU must support avx512f, avx512bw, avx512vl, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn dot_rows_512_group_f16(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    k: &[u16],
    stride: usize,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    if hd == 0 || hd > 64 {
        for m in 0..g {
            // SAFETY: this fn's contract.
            unsafe {
                dot_rows_512_f16(
                    &q[m * q_stride..m * q_stride + hd],
                    k,
                    stride,
                    &mut out[m * out_stride..m * out_stride + n],
                )
            };
        }
        return;
    }
    // SAFETY: masked 16-bit loads read only lanes < hd of key row j (bounds-checked slice).
    let load = |j: usize, i: usize, m: __mmask16| unsafe {
        _mm512_cvtph_ps(_mm256_maskz_loadu_epi16(
            m,
            k[j * stride..j * stride + hd].as_ptr().add(16 * i) as *const i16,
        ))
    };
    let ahead = |j: usize| prefetch_span(&k[j * stride..j * stride + hd]);
    // SAFETY: this fn's contract.
    unsafe { dot_rows_512_group_by(q, hd, q_stride, g, load, ahead, n, out, out_stride, side) }
}

/// The shared body of [`dot_rows_512_group`] and [`dot_rows_512_group_f16`]
/// (`0 < hd <= 64`; `load` as in [`dot_rows_512_by`]; `ahead(j)` prefetches
/// key row `j < n`'s lanes): the queries in blocks of up to
/// [`simd::QUERY_GROUP`].
///
/// # Safety
/// As [`dot_rows_512_by`], for `j < n`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn dot_rows_512_group_by(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    g: usize,
    load: impl Fn(usize, usize, __mmask16) -> __m512 + Copy,
    ahead: impl Fn(usize) + Copy,
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    let mut m0 = 0;
    while m0 < g {
        let gm = (g - m0).min(simd::QUERY_GROUP);
        let (q, out) = (&q[m0 * q_stride..], &mut out[m0 * out_stride..]);
        // The first block's pass over the keys prefetches `side`.
        let side = if m0 == 0 { side } else { &[] };
        // SAFETY: this fn's contract.
        unsafe {
            match gm {
                5 => dot_block::<5>(q, hd, q_stride, load, ahead, n, out, out_stride, side),
                4 => dot_block::<4>(q, hd, q_stride, load, ahead, n, out, out_stride, side),
                3 => dot_block::<3>(q, hd, q_stride, load, ahead, n, out, out_stride, side),
                2 => dot_block::<2>(q, hd, q_stride, load, ahead, n, out, out_stride, side),
                _ => dot_block::<1>(q, hd, q_stride, load, ahead, n, out, out_stride, side),
            }
        }
        m0 += gm;
    }
}

/// `G` queries (query `m`: `q[m q_stride ..][..hd]`, `0 < hd <= 64`) against keys `0..n`: per key,
/// its `ceil(hd / 16)` lane groups loaded once and multiplied into `G`
/// accumulators, reduced side by side ([`reduce4`]: the tree of
/// [`dot_rows_512_by`]'s `_mm512_reduce_add_ps`);
/// `out[m out_stride + j]`.
///
/// # Safety
/// As [`dot_rows_512_group_by`].
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn dot_block<const G: usize>(
    q: &[f32],
    hd: usize,
    q_stride: usize,
    load: impl Fn(usize, usize, __mmask16) -> __m512,
    ahead: impl Fn(usize),
    n: usize,
    out: &mut [f32],
    out_stride: usize,
    side: &[u8],
) {
    let nv = hd.div_ceil(16);
    let mask: [__mmask16; 4] = core::array::from_fn(|i| {
        if 16 * (i + 1) <= hd {
            0xffff
        } else if 16 * i < hd {
            lanes16(hd - 16 * i)
        } else {
            0
        }
    });
    let q = &q[..(G - 1) * q_stride + hd];
    // SAFETY: masked loads read only lanes < hd of query m (within `q`).
    let qv: [[__m512; 4]; G] = core::array::from_fn(|m| {
        core::array::from_fn(|i| {
            if i < nv {
                unsafe { _mm512_maskz_loadu_ps(mask[i], q.as_ptr().add(m * q_stride + 16 * i)) }
            } else {
                _mm512_setzero_ps()
            }
        })
    });
    let out = &mut out[..(G - 1) * out_stride + n];
    for j in 0..n {
        if j + KEY_PREFETCH < n {
            ahead(j + KEY_PREFETCH);
        }
        simd::prefetch_part(side, j, n);
        let mut acc = [_mm512_setzero_ps(); G];
        for i in 0..nv {
            let kv = load(j, i, mask[i]);
            for (a, qm) in acc.iter_mut().zip(&qv) {
                *a = _mm512_fmadd_ps(qm[i], kv, *a);
            }
        }
        // Queries 0-3, then 4-7 (G > 4), four sums side by side.
        let mut lanes = [0f32; 32];
        for (h, half) in lanes.chunks_exact_mut(16).enumerate().take(G.div_ceil(4)) {
            // SAFETY: avx512f (this fn's features); `half` holds 16 floats.
            unsafe {
                _mm512_storeu_ps(
                    half.as_mut_ptr(),
                    reduce4(core::array::from_fn(|m| {
                        if 4 * h + m < G {
                            acc[4 * h + m]
                        } else {
                            _mm512_setzero_ps()
                        }
                    })),
                )
            };
        }
        for m in 0..G {
            out[m * out_stride + j] = lanes[16 * (m / 4) + 4 * (m % 4)];
        }
    }
}

/// `_mm512_reduce_add_ps` of every accumulator of a tile, bit for bit: the
/// [`TN`] sums of a row at once ([`reduce4`]) instead of one after another.
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn reduce_tile<const M: usize>(acc: [[__m512; TN]; M]) -> [[f32; TN]; M] {
    const { assert!(TN == 4) };
    // SAFETY: avx512f (this fn's features).
    acc.map(|am| unsafe { sums4(am) })
}

/// `_mm512_reduce_add_ps` of each of four accumulators, bit for bit
/// ([`reduce4`], lanes 0, 4, 8, 12 read out).
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn sums4(a: [__m512; 4]) -> [f32; 4] {
    let mut lanes = [0f32; 16];
    // SAFETY: avx512f (this fn's features); lanes holds 16 floats.
    unsafe { _mm512_storeu_ps(lanes.as_mut_ptr(), reduce4(a)) };
    core::array::from_fn(|n| lanes[4 * n])
}

/// Four horizontal sums at once: lane `4 m` of the result is
/// `_mm512_reduce_add_ps(a[m])`, bit for bit. Each sum takes that
/// intrinsic's tree (the 256-bit halves, the 128-bit halves, lanes `i + 2`,
/// then `i + 1`), the four side by side at each level.
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn reduce4(a: [__m512; 4]) -> __m512 {
    // 128-bit lanes: the 256-bit half sums of a[0] (lanes 0, 1) and a[1] (2, 3); of a[2], a[3].
    let b0 = _mm512_add_ps(
        _mm512_shuffle_f32x4::<0x44>(a[0], a[1]),
        _mm512_shuffle_f32x4::<0xEE>(a[0], a[1]),
    );
    let b1 = _mm512_add_ps(
        _mm512_shuffle_f32x4::<0x44>(a[2], a[3]),
        _mm512_shuffle_f32x4::<0xEE>(a[2], a[3]),
    );
    // 128-bit lane m: the 128-bit half sum of a[m].
    let c = _mm512_add_ps(
        _mm512_shuffle_f32x4::<0x88>(b0, b1),
        _mm512_shuffle_f32x4::<0xDD>(b0, b1),
    );
    // Lanes (i, i + 2), then (0, 1), within each 128-bit lane.
    let d = _mm512_add_ps(c, _mm512_permute_ps::<0x4E>(c));
    _mm512_add_ps(d, _mm512_movehdup_ps(d))
}
