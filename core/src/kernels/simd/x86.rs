//! x86_64 AVX2 + FMA + F16C variants of the [`super::scalar`] kernels.
//! Every function is `unsafe` only because of `#[target_feature]`: the
//! caller must have checked that the CPU supports avx2, fma and f16c
//! (the dispatchers in `super` do, via `Isa::Avx2`). All memory access goes
//! through `chunks_exact` sub-slices, so loads are in bounds by construction.

use core::arch::x86_64::*;

use super::{distinct_rows, Tile, Q8_BLOCK, Q8_BLOCK_BYTES, TM, TN};

// The tiled kernels walk the weight rows two at a time (8 f32 accumulators
// for a 4x2 sub-tile, plus two weight and one activation register).
const _: () = assert!(TN.is_multiple_of(2));

/// Horizontal sum of 8 lanes.
///
/// # Safety
/// The CPU must support avx2, fma (slices are bounds-checked).
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
        tail += super::f16_to_f32(*a) * b;
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
        let d = super::f16_to_f32(u16::from_le_bytes([blk[0], blk[1]])) * dx;
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

/// Register-blocked tile (see [`super::scalar::tile_f32`]): each 4x2
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
    unsafe { tile_256(w, x, load, |v: &u16| super::f16_to_f32(*v)) }
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
fn lanes16(n: usize) -> __mmask16 {
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

/// See [`super::quantise_q8_corr`]; bit-identical to the scalar twin (same
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
        let (scale, inv) = super::q8_scale(hmax(m));
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

/// See [`super::quantise_q8_corr`]: [`quantise_q8_corr`]'s values, 16
/// blocks at a time on 16 lanes. The per-block scalar steps of the AVX2
/// kernel (the horizontal maximum, then two dependent IEEE divisions per
/// block) become one vector division of the 16 blocks' maxima for the
/// scales and one for their reciprocals (the same IEEE quotients, lane by
/// lane: [`super::q8_scale`]'s zero and overflow rules as masks); each block
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

/// See [`super::q8_scales`] (F16C, 8 scales per conversion).
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

/// See [`super::gemm_q8`]: two blocks per 64-byte step; weights made
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
    let nb = super::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
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
    let nb = super::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
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

/// See [`super::gemm_q8`] on 32-byte vectors, one block per step, weight
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
    let nb = super::scalar::gemm_blocks(&w, &wd, &xq, &xd, &xc);
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

/// See [`super::dot_rows`] (one AVX2 dot per key row, inlined).
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

/// See [`super::dot_rows_f16`] (one AVX2 [`dot_f16`] per key row: the
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

/// See [`super::dot_rows`]: the query (up to 64 floats) stays in four
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

/// See [`super::dot_rows_f16`]: [`dot_rows_512`] with each key lane loaded
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
const KEY_PREFETCH: usize = 8;

/// Prefetches (into L1) every 64-byte line `s` touches. No result depends
/// on it.
#[inline(always)]
fn prefetch_span<T>(s: &[T]) {
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

/// See [`super::dot_rows_group`]: [`dot_rows_512`] for `g`
/// queries, up to [`super::QUERY_GROUP`] of them held in registers while
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
/// [`super::QUERY_GROUP`].
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
        let gm = (g - m0).min(super::QUERY_GROUP);
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
        super::prefetch_part(side, j, n);
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
unsafe fn reduce_tile<const M: usize>(acc: [[__m512; TN]; M]) -> [[f32; TN]; M] {
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
unsafe fn sums4(a: [__m512; 4]) -> [f32; 4] {
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

/// See [`super::gemm_q8_packed`]: per block, the 4 packed groups made
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
/// AMX kernel ([`super::amx`]) performs exactly these f32 steps per lane on
/// the tile unit's block sums, so both give the same bits.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl/vnni, avx2, fma and f16c.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_vnni<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_vnni_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_vnni`] that also prefetches `ahead` into L2, spread
/// over its block pairs ([`super::prefetch_part`]).
///
/// # Safety
/// As [`gemm_q8_packed_vnni`].
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx512vnni,avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_vnni_ahead<const M: usize>(
    w: super::PackedQ8<'_>,
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
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    use super::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
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
        super::prefetch_part(ahead, b / 2, pairs);
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
        super::prefetch_part(ahead, b / 2, pairs);
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
/// ([`super::passes_of_four`]), each pass on `$kernel::<K, Q4>` (one of
/// [`packed_avx2`] / [`packed_avxvnni`]: one function per `K` and value
/// width). Expands to unsafe calls: the caller's features must be the
/// kernel's.
macro_rules! ymm_passes {
    ($kernel:ident, $w:ident, $xq:ident, $xd:ident, $xc:ident, $ahead:ident) => {
        super::passes_of_four!(M, $ahead, |K, m0, a| {
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

/// See [`super::gemm_q8_packed`] on 32-byte vectors (AVX2, and AVX-512
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
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are this function's.
    unsafe { gemm_q8_packed_avx2_ahead(w, xq, xd, xc, &[]) }
}

/// [`gemm_q8_packed_avx2`] that also prefetches `ahead` into L2, spread over the
/// blocks of its first pass ([`super::prefetch_part`]).
///
/// # Safety
/// As [`gemm_q8_packed_avx2`].
#[target_feature(enable = "avx2,fma,f16c")]
pub unsafe fn gemm_q8_packed_avx2_ahead<const M: usize>(
    w: super::PackedQ8<'_>,
    xq: [&[i8]; M],
    xd: [&[f32]; M],
    xc: [&[i32]; M],
    ahead: &[u8],
) -> [[f32; 8]; M] {
    // SAFETY: the caller's features are `packed_avx2`'s.
    unsafe { ymm_passes!(packed_avx2, w, xq, xd, xc, ahead) }
}

/// See [`super::gemm_q8_packed`] on 32-byte vectors with AVX-VNNI: the
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
    w: super::PackedQ8<'_>,
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
    w: super::PackedQ8<'_>,
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
    w: super::PackedQ8<'_>,
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
    w: super::PackedQ8<'_>,
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
    w: super::PackedQ8<'_>,
    xq: [&[i8]; K],
    xd: [&[f32]; K],
    xc: [&[i32]; K],
    ahead: &[u8],
) -> [[f32; 8]; K] {
    use super::{PACK_BLOCK_NIBBLES as PN, PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
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
            super::prefetch_part(ahead, b, nb);
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

/// See [`super::q8_pack8`]: per block, the 8 rows' 32 bytes (as 4 qwords
/// each) transposed to 4 vectors of 8 qwords with two `vpermt2q` and one
/// `vshufi64x2` stage; the 8 scale words gathered.
///
/// # Safety
/// The CPU must support avx512f/bw/dq/vl, avx2; every row holds `nb` blocks.
#[target_feature(enable = "avx512f,avx512bw,avx512dq,avx512vl,avx2")]
pub unsafe fn q8_pack8(rows: [&[u8]; 8], nb: usize, v: &mut [u8], s: &mut [u8]) {
    use super::{PACK_BLOCK_SCALES as PS, PACK_BLOCK_VALUES as PV};
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

/// See [`super::axpy_rows_f32`].
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

/// See [`super::axpy_rows_f16`] (lanes widened by F16C, exact).
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
    unsafe { axpy_rows_by(coef, w, stride, y, e0, load, super::f16_to_f32) }
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
    let nk = super::scalar::whole_rows(coef.len(), rows.len(), stride, n);
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

/// See [`super::axpy_rows_group_f32`]: [`axpy_rows_512_f32`] for `g`
/// queries, the 64-lane blocks of up to [`super::QUERY_GROUP`] queries
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
/// blocks of up to [`super::QUERY_GROUP`]; returns `64 k`.
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
    let nk = super::scalar::whole_rows(nk, rows.len(), stride, n);
    let n8 = n - n % 8;
    let done = n8 - n8 % 64;
    let mut m0 = 0;
    while m0 < g {
        let gm = (g - m0).min(super::QUERY_GROUP);
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
                super::prefetch_part(side, j, nk);
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
        let nk = super::scalar::whole_rows(coef.len(), rows.len(), stride, n);
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
        *yi += a * super::f16_to_f32(*wi);
    }
}

/// [`super::scalar::exp`] on 8 lanes, the same operations in the same
/// order (no FMA): bit-identical.
///
/// # Safety
/// The CPU must support avx2.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn exp8(x: __m256) -> __m256 {
    use super::scalar::exp_c::*;
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
/// [`super::scalar::exp`], bit for bit.
///
/// # Safety
/// The CPU must support avx512f.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn exp16(x: __m512) -> __m512 {
    use super::scalar::exp_c::*;
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

/// See [`super::exp_shifted_sum`]: [`exp_shifted_sum`] with the
/// exponentials on 16 lanes (the tail masked); the two 8-lane halves of a
/// 16-lane block are added into the 8 lane sums one after the other, as
/// the 8-wide loop adds two blocks, and the tail in order: bit for bit.
///
/// # Safety
/// The CPU must support avx512f and avx2.
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
    super::scalar::reduce8(a, t)
}

/// See [`super::scale_max`]: 16 lanes at a time, the tail masked; the lane
/// maxima by `vmaxps` with the running maximum as its second operand (a NaN
/// score leaves it as it was, as `f32::max` does).
///
/// # Safety
/// The CPU must support avx512f.
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

/// See [`super::scale_max`]: 8 lanes at a time, the tail as the twin's; the
/// lane maxima by `vmaxps` with the running maximum as its second operand
/// (a NaN score leaves it as it was, as `f32::max` does).
///
/// # Safety
/// The CPU must support avx2.
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

/// See [`super::exp_shifted_sum`] (8 lane sums, reduced as the twin does).
///
/// # Safety
/// The CPU must support avx2.
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
    super::scalar::reduce8(a, t)
}

/// See [`super::layernorm_row`]: the twin's operations on 8 lanes.
///
/// # Safety
/// The CPU must support avx2.
#[target_feature(enable = "avx2")]
pub unsafe fn layernorm_row(x: &[f32], w: &[f32], b: &[f32], eps: f32, y: &mut [f32]) {
    use super::scalar::{ln_affine, ln_inv_std, ln_mean};
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

/// See [`super::gelu_inplace`]: [`super::scalar::gelu`] on 8 lanes, the
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
        *v = super::scalar::gelu(*v);
    }
}

/// [`super::scalar::gelu`] on 8 lanes, operation for operation.
#[inline]
#[target_feature(enable = "avx2")]
fn gelu8(xv: __m256) -> __m256 {
    use super::scalar::erf_c::*;
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

/// See [`super::bias_act_rows`] (AVX2 and AVX-VNNI): two rows' sums and
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

/// See [`super::gelu_inplace`]: [`gelu_inplace`] on 16 lanes ([`exp16`];
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

/// See [`super::bias_act_rows`]: four rows' sums and [`gelu16`]s at a
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

/// See [`super::bias_act`]: 16 lanes at a time, the tail masked; the sum
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

/// [`super::scalar::gelu`] on 16 lanes, operation for operation.
#[inline]
#[target_feature(enable = "avx512f")]
pub(super) fn gelu16(xv: __m512) -> __m512 {
    use super::scalar::erf_c::*;
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

/// See [`super::narrow_f16`]: `vcvtps2ph` (round to nearest even) on 8
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
    super::scalar::narrow_f16(&src[n8..n], &mut dst[n8..n]);
}

/// See [`super::widen_f16`] (F16C, exact: bit-identical to the twin).
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
    super::scalar::widen_f16(s1, d1);
}
