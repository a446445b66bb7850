//! AVX2 dot products and TM x TN tiles (f32, f16, Q8), and the AVX-512
//! f32 / f16 tiles.

use core::arch::x86_64::*;

use super::*;
use crate::kernels::simd;

/// Horizontal sum of 8 lanes.
///
/// # Safety
/// The CPU must support avx2, fma (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn hsum(v: __m256) -> f32 {
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
            let (xv, yv) = unsafe {
                (
                    _mm256_loadu_ps(x.as_ptr().add(l * 8)),
                    _mm256_loadu_ps(y.as_ptr().add(l * 8)),
                )
            };
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
        let (wv, xv) = unsafe {
            (
                _mm256_cvtph_ps(_mm_loadu_si128(wc.as_ptr() as *const __m128i)),
                _mm256_loadu_ps(xc.as_ptr()),
            )
        };
        acc[0] = _mm256_fmadd_ps(wv, xv, acc[0]);
    }
    let s = _mm256_add_ps(_mm256_add_ps(acc[0], acc[1]), _mm256_add_ps(acc[2], acc[3]));
    let mut tail = 0.0f32;
    for (a, b) in w1.iter().zip(x1) {
        tail += simd::f16_to_f32(*a) * b;
    }
    hsum(s) + tail
}

/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn dot_q8(w: &[u8], xq: &[i8], xd: &[f32]) -> f32 {
    let nb = (w.len() / Q8_BLOCK_BYTES)
        .min(xq.len() / Q8_BLOCK)
        .min(xd.len());
    let ones = _mm256_set1_epi16(1);
    let mut acc = _mm256_setzero_ps();
    for ((blk, xs), &dx) in w
        .chunks_exact(Q8_BLOCK_BYTES)
        .zip(xq.chunks_exact(Q8_BLOCK))
        .zip(xd)
        .take(nb)
    {
        let d = simd::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) * dx;
        // SAFETY: blk[2..] and xs hold exactly 32 bytes each.
        let (wv, xv) = unsafe {
            (
                _mm256_loadu_si256(blk[2..].as_ptr() as *const __m256i),
                _mm256_loadu_si256(xs.as_ptr() as *const __m256i),
            )
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

/// Register-blocked tile (see [`simd::scalar::tile_f32`]): each 4x2
/// sub-tile keeps 8 accumulators in registers, so every weight and
/// activation vector loaded is used 2 or 4 times. Activation rows repeated
/// at the end of `x` are computed once ([`distinct_rows`]).
///
/// # Safety
/// The CPU must support avx2, fma and f16c (as every x86 `Isa` does).
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn tile_f32(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    // SAFETY: lanes c..c + 8 of a row holding at least k >= c + 8 floats.
    let load = |r: &[f32], c: usize| unsafe { _mm256_loadu_ps(r.as_ptr().add(c)) };
    // SAFETY: the caller's features are tile_256's.
    unsafe { tile_256(w, x, load, |v: &f32| *v) }
}

/// [`tile_f32`] with binary16 weights: each weight vector is converted
/// (F16C) once per step and used for all `TM` activation rows.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn tile_f16(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    // SAFETY: 8 u16 (one 128-bit load) of lanes c..c + 8 of a row holding
    // at least k >= c + 8 values.
    let load = |r: &[u16], c: usize| unsafe {
        _mm256_cvtph_ps(_mm_loadu_si128(r.as_ptr().add(c) as *const __m128i))
    };
    // SAFETY: the caller's features are tile_256's.
    unsafe { tile_256(w, x, load, |v: &u16| simd::f16_to_f32(*v)) }
}

/// The tile of [`tile_f32`] / [`tile_f16`] over any weight element (`load`:
/// lanes c..c + 8 as f32; `val`: one value, for the scalar column tail).
///
/// # Safety
/// The CPU must support avx2, fma and f16c; `load` must be sound for lanes
/// below the shortest row's length.
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn tile_256<E>(
    w: [&[E]; TN],
    x: [&[f32]; TM],
    load: impl Fn(&[E], usize) -> __m256,
    val: impl Fn(&E) -> f32,
) -> Tile {
    let k = tile_len(&w, &x);
    // SAFETY: the caller's features are rows_256's; d <= TM.
    unsafe {
        let d = distinct_rows(&x);
        match (d, one_stream(d, k)) {
            (1, _) => padded(seq_rows_256::<E, 1>(&w, &x, k, &load, &val)),
            (2, true) => padded(seq_rows_256::<E, 2>(&w, &x, k, &load, &val)),
            (3, true) => padded(seq_rows_256::<E, 3>(&w, &x, k, &load, &val)),
            (_, true) => padded(seq_rows_256::<E, TM>(&w, &x, k, &load, &val)),
            (2, false) => padded(rows_256::<E, 2>(&w, &x, k, &load, &val)),
            (3, false) => padded(rows_256::<E, 3>(&w, &x, k, &load, &val)),
            _ => padded(rows_256::<E, TM>(&w, &x, k, &load, &val)),
        }
    }
}

/// Activation rows `0..M` against the tile's weight rows, one weight row
/// after another (the same numbers as [`rows_256`]; why: [`seq_rows_512`];
/// 2-4 rows while `rows x k <= SEQ_TILE_VALUES`). Measured cold under
/// AVX2 (2026-12-03, f16): 512x512 at 2-4 rows 0.45-0.57x the time of
/// the tile's pairs of weight rows, 512x1536 at 2 rows 0.55x.
///
/// # Safety
/// As [`tile_256`]; `M <= TM`.
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn seq_rows_256<E, const M: usize>(
    w: &[&[E]; TN],
    x: &[&[f32]; TM],
    k: usize,
    load: &impl Fn(&[E], usize) -> __m256,
    val: &impl Fn(&E) -> f32,
) -> [[f32; TN]; M] {
    let k8 = k - k % 8;
    let mut out = [[0.0f32; TN]; M];
    for (n, wn) in w.iter().enumerate() {
        let wr = &wn[..k];
        let mut acc = [_mm256_setzero_ps(); M];
        let mut c = 0;
        while c < k8 {
            let wv = load(wr, c);
            for (a, xm) in acc.iter_mut().zip(x) {
                // SAFETY: c + 8 <= k8 <= k, and every x[m] holds at least k floats.
                let xv = unsafe { _mm256_loadu_ps(xm.as_ptr().add(c)) };
                *a = _mm256_fmadd_ps(xv, wv, *a);
            }
            c += 8;
        }
        for ((o, a), xm) in out.iter_mut().zip(acc).zip(x) {
            let mut tail = 0.0f32;
            for (wv, b) in wr[k8..].iter().zip(&xm[k8..k]) {
                tail += val(wv) * b;
            }
            o[n] = hsum(a) + tail;
        }
    }
    out
}

/// Rows `0..M` of [`tile_256`] (each row's dots in the same order for any `M`).
///
/// # Safety
/// As [`tile_256`]; `M <= TM`.
#[inline]
#[target_feature(enable = "avx2,fma,f16c")]
unsafe fn rows_256<E, const M: usize>(
    w: &[&[E]; TN],
    x: &[&[f32]; TM],
    k: usize,
    load: &impl Fn(&[E], usize) -> __m256,
    val: &impl Fn(&E) -> f32,
) -> [[f32; TN]; M] {
    let k8 = k - k % 8;
    let mut out = [[0.0f32; TN]; M];
    for n0 in (0..TN).step_by(2) {
        let (wa, wb) = (&w[n0][..k], &w[n0 + 1][..k]);
        let mut acc = [[_mm256_setzero_ps(); 2]; M];
        let mut c = 0;
        while c < k8 {
            let (va, vb) = (load(wa, c), load(wb, c));
            for (am, xm) in acc.iter_mut().zip(x) {
                // SAFETY: c + 8 <= k8 <= k and every x[m] holds at least k floats.
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
                    tail += val(a) * b;
                }
                out[m][n0 + j] = hsum(am[j]) + tail;
            }
        }
    }
    out
}

/// One binary16 scale to f32 (F16C, exact).
///
/// # Safety
/// The CPU must support avx2, f16c (slices are bounds-checked).
#[inline]
#[target_feature(enable = "avx2,f16c")]
unsafe fn f16_scale(blk: &[u8]) -> f32 {
    _mm_cvtss_f32(_mm_cvtph_ps(_mm_cvtsi32_si128(
        u16::from_le_bytes([blk[0], blk[1]]) as i32,
    )))
}

/// Blocked int8 tile (see [`dot_q8`]): per block of 32, each weight row is
/// loaded and made unsigned once and used for all `TM` activation rows;
/// the i32 block sums (maddubs + madd) are scaled into f32 accumulators.
///
/// # Safety
/// The CPU must support avx2, fma and f16c.
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn tile_q8(w: [&[u8]; TN], xq: [&[i8]; TM], xd: [&[f32]; TM]) -> Tile {
    let nbw = w
        .iter()
        .map(|r| r.len() / Q8_BLOCK_BYTES)
        .min()
        .unwrap_or(0);
    let nbx = xq
        .iter()
        .map(|r| r.len() / Q8_BLOCK)
        .chain(xd.iter().map(|r| r.len()))
        .min()
        .unwrap_or(0);
    let nb = nbw.min(nbx);
    let ones = _mm256_set1_epi16(1);
    let mut out = [[0.0f32; TN]; TM];
    for n0 in (0..TN).step_by(2) {
        let mut acc = [[_mm256_setzero_ps(); 2]; TM];
        let blocks = w[n0]
            .chunks_exact(Q8_BLOCK_BYTES)
            .zip(w[n0 + 1].chunks_exact(Q8_BLOCK_BYTES))
            .take(nb);
        for (b, (ba, bb)) in blocks.enumerate() {
            let (da, db) = (f16_scale(ba), f16_scale(bb));
            // SAFETY: ba[2..] and bb[2..] hold exactly 32 bytes each.
            let (wa, wb) = unsafe {
                (
                    _mm256_loadu_si256(ba[2..].as_ptr() as *const __m256i),
                    _mm256_loadu_si256(bb[2..].as_ptr() as *const __m256i),
                )
            };
            // |w| (unsigned) x sign(w)*x (signed), as in `dot_q8`: no i16
            // saturation since the quantiser keeps x in [-127, 127].
            let (ua, ub) = (_mm256_sign_epi8(wa, wa), _mm256_sign_epi8(wb, wb));
            for (m, am) in acc.iter_mut().enumerate() {
                let xs = &xq[m][b * Q8_BLOCK..(b + 1) * Q8_BLOCK];
                let dx = xd[m][b];
                // SAFETY: xs holds exactly 32 bytes.
                let xv = unsafe { _mm256_loadu_si256(xs.as_ptr() as *const __m256i) };
                let pa =
                    _mm256_madd_epi16(_mm256_maddubs_epi16(ua, _mm256_sign_epi8(xv, wa)), ones);
                let pb =
                    _mm256_madd_epi16(_mm256_maddubs_epi16(ub, _mm256_sign_epi8(xv, wb)), ones);
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

// ---------------------------------------------------------------------
// AVX-512 f32 / f16 tiles, int8 GEMM (VNNI, AVX-512BW, AVX2), the
// activation quantiser and axpy.
// ---------------------------------------------------------------------

/// Mask of the first `n` (< 16) lanes.
#[inline]
pub(super) fn lanes16(n: usize) -> __mmask16 {
    ((1u32 << n) - 1) as __mmask16
}

/// Register-blocked tile on 16-wide vectors: the whole `TM x TN` tile in
/// 16 accumulators (AVX-512 has 32 registers), so each loaded vector is
/// used 4 times; the column tail is one masked step (no scalar tail).
/// Activation rows that repeat the row before them at the end of `x` (a
/// partial tile's padding) are not computed again: their results are the
/// same numbers, copied ([`distinct_rows`]), so a 1-row GEMV does 4 FMAs per
/// loaded weight vector, not 16 (the AVX2 and NEON tiles do the same).
///
/// # Safety
/// The CPU must support avx512f (and the dispatcher's Avx512 set).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
pub unsafe fn tile_f32_512(w: [&[f32]; TN], x: [&[f32]; TM]) -> Tile {
    // SAFETY: the tile reads lanes c..c + 16 of rows holding at least k >= c + 16 floats.
    let load = |r: &[f32], c: usize| unsafe { _mm512_loadu_ps(r.as_ptr().add(c)) };
    // SAFETY: a masked load of lanes c..k, inside every row.
    let tail = |r: &[f32], c: usize, mk: __mmask16| unsafe {
        _mm512_maskz_loadu_ps(mk, r.as_ptr().add(c))
    };
    // SAFETY: the caller's features are tile_512's.
    unsafe { tile_512(w, x, load, tail) }
}

/// [`tile_f32_512`] with binary16 weights (16 converted per F16C step).
///
/// # Safety
/// As [`tile_f32_512`].
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
pub unsafe fn tile_f16_512(w: [&[u16]; TN], x: [&[f32]; TM]) -> Tile {
    // SAFETY: 16 u16 (one 256-bit load) of lanes c..c + 16 of a row holding at least k >= c + 16 values.
    let load = |r: &[u16], c: usize| unsafe {
        _mm512_cvtph_ps(_mm256_loadu_si256(r.as_ptr().add(c) as *const __m256i))
    };
    // SAFETY: a masked load of lanes c..k, inside every row.
    let tail = |r: &[u16], c: usize, mk: __mmask16| unsafe {
        _mm512_cvtph_ps(_mm256_maskz_loadu_epi16(
            mk,
            r.as_ptr().add(c) as *const i16,
        ))
    };
    // SAFETY: as in tile_f32_512.
    unsafe { tile_512(w, x, load, tail) }
}

/// The tile of [`tile_f32_512`] / [`tile_f16_512`] over any weight element
/// (`load(row, c)`: lanes c..c + 16 as f32; `tail`: the masked lanes).
///
/// # Safety
/// As [`tile_f32_512`]; `load` / `tail` must be sound for lanes below the
/// shortest row's length.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
unsafe fn tile_512<E>(
    w: [&[E]; TN],
    x: [&[f32]; TM],
    load: impl Fn(&[E], usize) -> __m512,
    tail: impl Fn(&[E], usize, __mmask16) -> __m512,
) -> Tile {
    let k = tile_len(&w, &x);
    // SAFETY: the caller's features are rows_512's; d <= TM.
    unsafe {
        let d = distinct_rows(&x);
        match (d, one_stream(d, k)) {
            (1, _) => padded(seq_rows_512::<E, 1>(&w, &x, k, &load, &tail)),
            (2, true) => padded(seq_rows_512::<E, 2>(&w, &x, k, &load, &tail)),
            (3, true) => padded(seq_rows_512::<E, 3>(&w, &x, k, &load, &tail)),
            (_, true) => padded(seq_rows_512::<E, TM>(&w, &x, k, &load, &tail)),
            (2, false) => padded(rows_512::<E, 2>(&w, &x, k, &load, &tail)),
            (3, false) => padded(rows_512::<E, 3>(&w, &x, k, &load, &tail)),
            _ => padded(rows_512::<E, TM>(&w, &x, k, &load, &tail)),
        }
    }
}

/// A tile whose rows `M..` repeat row `M - 1` (`M >= 1`).
#[inline]
fn padded<const M: usize>(r: [[f32; TN]; M]) -> Tile {
    core::array::from_fn(|m| r[m.min(M - 1)])
}

/// Most activation values (`rows x k`) of a 2-4-row tile that takes its
/// weight rows one after another ([`seq_rows_512`]); longer tiles take
/// [`rows_512`]. At 12 KiB of f32 rows the activations stay in L1 while a
/// weight row streams past them. Measured cold (96 MB of f16 matrices,
/// 2026-12-03, AMD EPYC): 512x512 at 2-4 rows 0.50-0.65x the time of the
/// tile, 512x1536 at 2 rows 0.69x; longer (3 x 1536: 0.88-0.98x; 4 x 1536,
/// 2-4 x 2048: 1.08-1.74x, the rows re-read from L2) stay on the tile.
const SEQ_TILE_VALUES: usize = 3072;

/// Whether a tile of `d` distinct activation rows of `k` values takes its
/// weight rows one after another (one memory stream): one row always, 2-4
/// rows up to [`SEQ_TILE_VALUES`] values (the AVX2 and AVX-512 tiles).
#[inline]
fn one_stream(d: usize, k: usize) -> bool {
    d == 1 || d * k <= SEQ_TILE_VALUES
}

/// Activation rows `0..M` against the tile's weight rows, one weight row
/// after another (a single memory stream through the tile, which is
/// contiguous in the weights: 4 rows side by side are 4 streams that each
/// restart every row, which the hardware prefetchers follow badly on short
/// rows): per entry the operations of [`rows_512`] (one accumulator over
/// the 16-lane steps, the masked tail, one reduction), so the same numbers
/// (test `tile_rows_equal_one_row_tiles_bit_for_bit`). One row: 1.3-2.4x
/// faster out of memory than the tile on the measured shapes (f32
/// 768x3072: 1.07x slower; docs/PERFORMANCE.md); 2-4 rows: see
/// [`SEQ_TILE_VALUES`].
///
/// # Safety
/// As [`tile_512`]; `M <= TM`.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
unsafe fn seq_rows_512<E, const M: usize>(
    w: &[&[E]; TN],
    x: &[&[f32]; TM],
    k: usize,
    load: &impl Fn(&[E], usize) -> __m512,
    tail: &impl Fn(&[E], usize, __mmask16) -> __m512,
) -> [[f32; TN]; M] {
    let k16 = k - k % 16;
    let mut out = [[0.0f32; TN]; M];
    for (n, wn) in w.iter().enumerate() {
        let mut acc = [_mm512_setzero_ps(); M];
        let mut c = 0;
        while c < k16 {
            let wv = load(wn, c);
            for (a, xm) in acc.iter_mut().zip(x) {
                // SAFETY: c + 16 <= k16 <= k, and every x[m] holds at least k floats.
                let xv = unsafe { _mm512_loadu_ps(xm.as_ptr().add(c)) };
                *a = _mm512_fmadd_ps(xv, wv, *a);
            }
            c += 16;
        }
        if c < k {
            let mk = lanes16(k - c);
            let wv = tail(wn, c, mk);
            for (a, xm) in acc.iter_mut().zip(x) {
                // SAFETY: a masked load of lanes c..k, inside every x[m].
                let xv = unsafe { _mm512_maskz_loadu_ps(mk, xm.as_ptr().add(c)) };
                *a = _mm512_fmadd_ps(xv, wv, *a);
            }
        }
        // The M sums at once (each `_mm512_reduce_add_ps`, bit for bit).
        // SAFETY: avx512f (this fn's features).
        let sums = unsafe {
            sums4(core::array::from_fn(|m| {
                if m < M {
                    acc[m]
                } else {
                    _mm512_setzero_ps()
                }
            }))
        };
        for (o, v) in out.iter_mut().zip(sums) {
            o[n] = v;
        }
    }
    out
}

/// Rows `0..M` of [`tile_512`] (each row's dots in the same order for any `M`).
///
/// # Safety
/// As [`tile_512`]; `M <= TM`.
#[inline]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma,f16c")]
unsafe fn rows_512<E, const M: usize>(
    w: &[&[E]; TN],
    x: &[&[f32]; TM],
    k: usize,
    load: &impl Fn(&[E], usize) -> __m512,
    tail: &impl Fn(&[E], usize, __mmask16) -> __m512,
) -> [[f32; TN]; M] {
    let k16 = k - k % 16;
    let mut acc = [[_mm512_setzero_ps(); TN]; M];
    let mut c = 0;
    while c < k16 {
        let wv: [__m512; TN] = core::array::from_fn(|n| load(w[n], c));
        for (am, xm) in acc.iter_mut().zip(x) {
            // SAFETY: every x[m] holds at least k floats.
            let xv = unsafe { _mm512_loadu_ps(xm.as_ptr().add(c)) };
            for (a, wn) in am.iter_mut().zip(&wv) {
                *a = _mm512_fmadd_ps(xv, *wn, *a);
            }
        }
        c += 16;
    }
    if c < k {
        let mk = lanes16(k - c);
        let wv: [__m512; TN] = core::array::from_fn(|n| tail(w[n], c, mk));
        for (am, xm) in acc.iter_mut().zip(x) {
            // SAFETY: masked loads read only lanes c..k, inside every row.
            let xv = unsafe { _mm512_maskz_loadu_ps(mk, xm.as_ptr().add(c)) };
            for (a, wn) in am.iter_mut().zip(&wv) {
                *a = _mm512_fmadd_ps(xv, *wn, *a);
            }
        }
    }
    // SAFETY: avx512f (this fn's features).
    unsafe { reduce_tile(acc) }
}
