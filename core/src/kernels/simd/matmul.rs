//! `C = A B` in f32 with a row-major right operand: each output value is
//! one running sum over the inner index `t` in order (`c += a_t b_t`), with
//! the row of `B` in vector lanes and `a_t` broadcast, so no lane ever needs
//! a horizontal reduction. What it serves: attention as per-head GEMMs
//! (`nn::encoder_layer`: scores = queries x transposed keys, output =
//! probabilities x values), where the inner length is a head's width (80 in
//! Transflower's paper config) and the dot-product tiles
//! ([`super::tile_f32`]) spend as much on their end-of-row reductions as on
//! the products.
//!
//! Every SIMD variant performs, per output value, the same fused
//! multiply-adds in the same order (AVX-512 on 16 lanes, AVX2 on 8, NEON on
//! 4; the column tail masked, never scalar), so they give the same bits as
//! each other (tested); the scalar twin ([`scalar_rows`]) multiplies and
//! adds unfused, within the tile twins' error limit.

#[cfg(target_arch = "x86_64")]
use core::arch::x86_64::*;

/// Rows of `A` per call of [`rows_times`].
pub const ROWS: usize = 6;
/// Most columns of `B` per call of [`rows_times`].
pub const COLS: usize = 64;

/// `out[r][j] = sum_t a[r][t] * b[t * ldb + j0 + j]` for `j < cols`
/// (`cols <= COLS`; the rest of each output row 0): `ROWS` rows of `A`
/// against columns `j0 .. j0 + cols` of `B`, whose row `t` starts at `t *
/// ldb`. The inner length is the shortest row of `a`, cut to the rows of
/// `B` that hold the columns (a short `b` is never read past its end).
/// `out` is the caller's (one tile for many calls: nothing to zero per call).
#[inline]
pub fn rows_times(
    a: [&[f32]; ROWS],
    b: &[f32],
    ldb: usize,
    j0: usize,
    cols: usize,
    out: &mut [[f32; COLS]; ROWS],
) {
    let cols = cols.min(COLS);
    let k = inner_len(&a, b, ldb, j0, cols);
    if k == 0 || cols == 0 {
        *out = [[0.0; COLS]; ROWS];
        return;
    }
    match super::isa() {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the Avx512 ISAs' `set_isa` contract covers avx512f/vl,
        // fma; `k` rows of `a` and of `b` (columns j0..j0 + cols) exist.
        super::Isa::Avx512 | super::Isa::Avx512Vnni => unsafe {
            match cols.div_ceil(16) {
                1 => avx512::<1>(&a, b, ldb, j0, cols, k, out),
                2 => avx512::<2>(&a, b, ldb, j0, cols, k, out),
                3 => avx512::<3>(&a, b, ldb, j0, cols, k, out),
                _ => avx512::<4>(&a, b, ldb, j0, cols, k, out),
            }
        },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: every x86 ISA implies avx2 and fma; extents as above.
        super::Isa::Avx2 | super::Isa::AvxVnni => unsafe { avx2(&a, b, ldb, j0, cols, k, out) },
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        // SAFETY: NEON is enabled for this build; extents as above.
        super::Isa::Neon | super::Isa::NeonDot => unsafe { neon(&a, b, ldb, j0, cols, k, out) },
        _ => scalar_rows(&a, b, ldb, j0, cols, k, out),
    }
    // Lanes past `cols` (computed against zeros: 0 x NaN is NaN, or not
    // written at all): cleared.
    if cols < COLS {
        for o in out.iter_mut() {
            o[cols..].fill(0.0);
        }
    }
}

/// The inner length [`rows_times`] uses: the shortest row of `a`, cut to
/// the rows `t` of `b` with `t * ldb + j0 + cols <= b.len()`.
fn inner_len(a: &[&[f32]; ROWS], b: &[f32], ldb: usize, j0: usize, cols: usize) -> usize {
    let k = a.iter().map(|r| r.len()).min().unwrap_or(0);
    let Some(room) = b.len().checked_sub(j0 + cols) else {
        return 0;
    };
    match room.checked_div(ldb) {
        Some(rows) => k.min(rows.saturating_add(1)),
        None => k,
    }
}

/// The scalar twin of [`rows_times`] (unfused multiply and add, `t` in
/// order), over `k` inner values.
pub fn scalar_rows(
    a: &[&[f32]; ROWS],
    b: &[f32],
    ldb: usize,
    j0: usize,
    cols: usize,
    k: usize,
    out: &mut [[f32; COLS]; ROWS],
) {
    for (o, ar) in out.iter_mut().zip(a) {
        let acc = &mut o[..cols];
        acc.fill(0.0);
        // Row t of B against all the columns at once: each column's sum
        // still takes its terms in order of t.
        for (t, &at) in ar.iter().enumerate().take(k) {
            for (y, &bj) in acc.iter_mut().zip(&b[t * ldb + j0..t * ldb + j0 + cols]) {
                *y += at * bj;
            }
        }
    }
}

/// [`rows_times`] on `V` 16-lane vectors of columns (the last masked to
/// `cols`): `ROWS` x `V` accumulators, per `t` `V` loads of `B` and
/// `ROWS` broadcasts of `A`.
///
/// # Safety
/// avx512f/vl and fma; `k` values in each row of `a`; `b` holds row `k - 1`
/// up to column `j0 + cols`; `16 (V - 1) < cols <= 16 V`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma")]
unsafe fn avx512<const V: usize>(
    a: &[&[f32]; ROWS],
    b: &[f32],
    ldb: usize,
    j0: usize,
    cols: usize,
    k: usize,
    out: &mut [[f32; COLS]; ROWS],
) {
    let last = (cols - 16 * (V - 1)).min(16);
    let tail: __mmask16 = if last == 16 {
        0xffff
    } else {
        ((1u32 << last) - 1) as __mmask16
    };
    let ap: [*const f32; ROWS] = core::array::from_fn(|r| a[r].as_ptr());
    let mut acc = [[_mm512_setzero_ps(); V]; ROWS];
    let mut bp = b.as_ptr().wrapping_add(j0);
    for t in 0..k {
        // SAFETY: row t < k of b holds columns j0 .. j0 + cols (the caller);
        // the last vector is masked to them.
        let bv: [__m512; V] = core::array::from_fn(|v| unsafe {
            if v + 1 < V {
                _mm512_loadu_ps(bp.add(16 * v))
            } else {
                _mm512_maskz_loadu_ps(tail, bp.add(16 * v))
            }
        });
        for (r, ar) in acc.iter_mut().enumerate() {
            // SAFETY: t < k <= a[r].len().
            let x = _mm512_set1_ps(unsafe { *ap[r].add(t) });
            for (v, av) in ar.iter_mut().enumerate() {
                *av = _mm512_fmadd_ps(x, bv[v], *av);
            }
        }
        bp = bp.wrapping_add(ldb);
    }
    for (o, ar) in out.iter_mut().zip(acc) {
        for (v, av) in ar.into_iter().enumerate() {
            // SAFETY: 16 v + 16 <= 16 V <= COLS floats of o.
            unsafe { _mm512_storeu_ps(o.as_mut_ptr().add(16 * v), av) };
        }
    }
}

/// [`rows_times`] on 8-lane vectors, 16 columns at a time (`ROWS` x 2
/// accumulators), the last vector masked to `cols`.
///
/// # Safety
/// avx2 and fma; extents as [`avx512`]'s.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn avx2(
    a: &[&[f32]; ROWS],
    b: &[f32],
    ldb: usize,
    j0: usize,
    cols: usize,
    k: usize,
    out: &mut [[f32; COLS]; ROWS],
) {
    let ap: [*const f32; ROWS] = core::array::from_fn(|r| a[r].as_ptr());
    let mut c0 = 0;
    while c0 < cols {
        // Lanes of the two vectors inside `cols` (a mask of -1 / 0 per lane).
        let mask: [__m256i; 2] = core::array::from_fn(|v| {
            let base = (c0 + 8 * v) as i32;
            let idx = _mm256_add_epi32(
                _mm256_set1_epi32(base),
                _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            );
            _mm256_cmpgt_epi32(_mm256_set1_epi32(cols as i32), idx)
        });
        // A whole chunk takes plain loads (a masked load costs more).
        let full = c0 + 16 <= cols;
        let mut acc = [[_mm256_setzero_ps(); 2]; ROWS];
        let mut bp = b.as_ptr().wrapping_add(j0 + c0);
        for t in 0..k {
            // SAFETY: row t's columns c0 .. c0 + 16 inside j0 .. j0 + cols
            // where `full`, else masked to them.
            let bv: [__m256; 2] = core::array::from_fn(|v| unsafe {
                if full {
                    _mm256_loadu_ps(bp.add(8 * v))
                } else {
                    _mm256_maskload_ps(bp.add(8 * v), mask[v])
                }
            });
            for (r, ar) in acc.iter_mut().enumerate() {
                // SAFETY: t < k <= a[r].len().
                let x = _mm256_set1_ps(unsafe { *ap[r].add(t) });
                for (v, av) in ar.iter_mut().enumerate() {
                    *av = _mm256_fmadd_ps(x, bv[v], *av);
                }
            }
            bp = bp.wrapping_add(ldb);
        }
        for (o, ar) in out.iter_mut().zip(acc) {
            for (v, av) in ar.into_iter().enumerate() {
                // SAFETY: c0 + 8 v + 8 <= c0 + 16 <= COLS (c0 < cols <= COLS, a multiple of 16).
                unsafe { _mm256_storeu_ps(o.as_mut_ptr().add(c0 + 8 * v), av) };
            }
        }
        c0 += 16;
    }
}

/// [`rows_times`] on 4-lane vectors, 16 columns at a time (`ROWS` x 4
/// accumulators); a column tail of fewer than 4 goes through a zero-padded
/// copy of its lanes.
///
/// # Safety
/// NEON; extents as [`avx512`]'s.
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
#[target_feature(enable = "neon")]
unsafe fn neon(
    a: &[&[f32]; ROWS],
    b: &[f32],
    ldb: usize,
    j0: usize,
    cols: usize,
    k: usize,
    out: &mut [[f32; COLS]; ROWS],
) {
    use core::arch::aarch64::*;
    let mut c0 = 0;
    while c0 < cols {
        let mut acc = [[vdupq_n_f32(0.0); 4]; ROWS];
        for t in 0..k {
            let row = &b[t * ldb + j0..t * ldb + j0 + cols];
            let bv: [float32x4_t; 4] = core::array::from_fn(|v| {
                let c = c0 + 4 * v;
                if c + 4 <= cols {
                    // SAFETY: lanes c .. c + 4 lie in `row`.
                    unsafe { vld1q_f32(row.as_ptr().add(c)) }
                } else {
                    let mut pad = [0.0f32; 4];
                    for (p, &x) in pad.iter_mut().zip(row.get(c..).unwrap_or(&[])) {
                        *p = x;
                    }
                    // SAFETY: pad holds 4 floats.
                    unsafe { vld1q_f32(pad.as_ptr()) }
                }
            });
            for (r, ar) in acc.iter_mut().enumerate() {
                let x = vdupq_n_f32(a[r][t]);
                for (v, av) in ar.iter_mut().enumerate() {
                    *av = vfmaq_f32(*av, x, bv[v]);
                }
            }
        }
        for (o, ar) in out.iter_mut().zip(acc) {
            for (v, av) in ar.into_iter().enumerate() {
                // SAFETY: c0 + 4 v + 4 <= c0 + 16 <= COLS.
                unsafe { vst1q_f32(o.as_mut_ptr().add(c0 + 4 * v), av) };
            }
        }
        c0 += 16;
    }
}

#[cfg(test)]
#[allow(unsafe_code)]
mod tests {
    use super::*;

    fn rng(seed: &mut u64) -> f32 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 40) as f32 / (1u64 << 24) as f32 * 6.0 - 3.0
    }

    /// A variant of [`rows_times`] over `k` inner values.
    ///
    /// # Safety
    /// The CPU must run the variant; the extents of [`avx512`].
    type Variant =
        unsafe fn(&[&[f32]; ROWS], &[f32], usize, usize, usize, usize, &mut [[f32; COLS]; ROWS]);

    /// The SIMD variants this CPU runs, by name.
    fn variants() -> std::vec::Vec<(&'static str, Variant)> {
        #[allow(unused_mut)]
        let mut v: std::vec::Vec<(&'static str, Variant)> = std::vec::Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            use std::is_x86_feature_detected as has;
            if has!("avx2") && has!("fma") {
                v.push(("avx2", avx2));
            }
            if has!("avx512f") && has!("avx512vl") && has!("avx2") && has!("fma") {
                fn by_cols(
                    a: &[&[f32]; ROWS],
                    b: &[f32],
                    ldb: usize,
                    j0: usize,
                    cols: usize,
                    k: usize,
                    out: &mut [[f32; COLS]; ROWS],
                ) {
                    // SAFETY: avx512f/vl, avx2, fma detected by the caller
                    // (`variants`); extents checked by the test (inner_len).
                    unsafe {
                        match cols.div_ceil(16) {
                            1 => avx512::<1>(a, b, ldb, j0, cols, k, out),
                            2 => avx512::<2>(a, b, ldb, j0, cols, k, out),
                            3 => avx512::<3>(a, b, ldb, j0, cols, k, out),
                            _ => avx512::<4>(a, b, ldb, j0, cols, k, out),
                        }
                    }
                }
                v.push(("avx512", by_cols));
            }
        }
        #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
        v.push(("neon", neon));
        v
    }

    /// Every variant against the scalar twin within the tile twins' limit
    /// (1e-6 x sum |a b|), and every SIMD variant against the first bit
    /// for bit (the same fused multiply-adds in the same order), over
    /// column counts with every kind of tail, inner lengths from 1, row
    /// strides wider than the columns and a column offset.
    #[test]
    fn simd_variants_match_the_scalar_twin_and_each_other() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for &(k, cols, ldb, j0) in &[
            (1, 1, 1, 0),
            (80, 64, 260, 0),
            (80, 4, 260, 256),
            (260, 64, 80, 16),
            (260, 16, 80, 64),
            (7, 37, 50, 3),
            (33, 63, 63, 0),
            (5, 9, 9, 0),
            (3, 49, 100, 51),
        ] {
            let a: std::vec::Vec<std::vec::Vec<f32>> = (0..ROWS)
                .map(|_| (0..k).map(|_| rng(&mut seed)).collect())
                .collect();
            let b: std::vec::Vec<f32> = (0..(k - 1) * ldb + j0 + cols)
                .map(|_| rng(&mut seed))
                .collect();
            let ar: [&[f32]; ROWS] = core::array::from_fn(|r| a[r].as_slice());
            assert_eq!(inner_len(&ar, &b, ldb, j0, cols), k);
            let mut want = [[0.0f32; COLS]; ROWS];
            scalar_rows(&ar, &b, ldb, j0, cols, k, &mut want);
            let mut first: Option<[[f32; COLS]; ROWS]> = None;
            for (name, f) in variants() {
                let mut got = [[f32::NAN; COLS]; ROWS];
                // SAFETY: `variants` lists only what this CPU runs; the
                // extents hold (inner_len above).
                unsafe { f(&ar, &b, ldb, j0, cols, k, &mut got) };
                for r in 0..ROWS {
                    for j in 0..cols {
                        let mag: f32 = (0..k).map(|t| (a[r][t] * b[t * ldb + j0 + j]).abs()).sum();
                        assert!(
                            (got[r][j] - want[r][j]).abs() <= 1e-6 * mag,
                            "{name} k={k} cols={cols} [{r}][{j}]: {} vs {}",
                            got[r][j],
                            want[r][j]
                        );
                    }
                }
                if let Some(f0) = first {
                    for r in 0..ROWS {
                        for j in 0..cols {
                            assert_eq!(
                                got[r][j].to_bits(),
                                f0[r][j].to_bits(),
                                "{name} k={k} cols={cols} [{r}][{j}]"
                            );
                        }
                    }
                } else {
                    first = Some(got);
                }
            }
        }
    }

    /// The dispatcher clears the lanes past `cols` even where `A` holds
    /// infinities, and reads no row of `B` past its end.
    #[test]
    fn lanes_past_the_columns_are_zero_and_short_b_cuts_the_inner_length() {
        let a = [f32::INFINITY; 8];
        let ar: [&[f32]; ROWS] = [&a; ROWS];
        let b = [1.0f32; 8 * 10];
        let mut out = [[f32::NAN; COLS]; ROWS];
        rows_times(ar, &b, 10, 0, 5, &mut out);
        for o in &out {
            assert!(o[..5].iter().all(|&x| x == f32::INFINITY));
            assert!(o[5..].iter().all(|&x| x == 0.0));
        }
        // b holds 3 whole rows of 10 (and part of a 4th): k = 3.
        let ones = [1.0f32; 8];
        rows_times([&ones; ROWS], &b[..35], 10, 0, 10, &mut out);
        assert!(out.iter().all(|o| o[..10].iter().all(|&x| x == 3.0)));
        assert_eq!(inner_len(&[&ones; ROWS], &b[..35], 10, 0, 10), 3);
        assert_eq!(inner_len(&[&ones; ROWS], &b[..5], 10, 0, 10), 0);
    }
}
