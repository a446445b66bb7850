//! `C = A B` in f32 with `B` row-major ([`simd::matmul`]: one running sum
//! per output value over the inner index in order, the row of `B` in
//! vector lanes), split over the installed threads by output columns
//! ([`parallel::split_cols_aligned`]): every value is computed by the same
//! code whatever the thread count, so the results are bit-identical.
//! Used where the right operand is activations, not weights: attention as
//! per-head GEMMs (`nn::encoder_layer`).

use super::parallel;
use super::simd::matmul::{rows_times, COLS, ROWS};

/// `c (m, n) = a (m, k) b (k, n)`, all row-major and contiguous. Sizes
/// that the slices do not hold are a caller's bug: panics (like slice
/// indexing) rather than reading past them.
pub fn matmul(a: &[f32], b: &[f32], m: usize, k: usize, n: usize, c: &mut [f32]) {
    assert!(a.len() >= m * k, "matmul: a holds fewer than m x k values");
    assert!(b.len() >= k * n, "matmul: b holds fewer than k x n values");
    assert!(c.len() >= m * n, "matmul: c holds fewer than m x n values");
    if m == 0 || n == 0 {
        return;
    }
    let c = &mut c[..m * n];
    let b = &b[..k * n];
    let work = m.saturating_mul(k).saturating_mul(n).saturating_mul(4);
    parallel::split_cols_aligned(c, n, 16, work, |mut cols| {
        let (lo, hi) = (cols.lo(), cols.hi());
        let mut t = [[0.0f32; COLS]; ROWS];
        // Column chunks outside, rows inside: a chunk of B (k x 64) is
        // read from L1 by every row group after the first.
        let mut j0 = lo;
        while j0 < hi {
            let w = (hi - j0).min(COLS);
            for i0 in (0..m).step_by(ROWS) {
                let rows = (m - i0).min(ROWS);
                // Rows past the last repeat it (computed, not stored).
                let ar: [&[f32]; ROWS] = core::array::from_fn(|r| {
                    let i = i0 + r.min(rows - 1);
                    &a[i * k..(i + 1) * k]
                });
                rows_times(ar, b, n, j0, w, &mut t);
                for (r, tr) in t.iter().enumerate().take(rows) {
                    cols.seg(i0 + r, j0, j0 + w).copy_from_slice(&tr[..w]);
                }
            }
            j0 += w;
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a plain triple loop (unfused, in order) within the tile
    /// twins' limit, for shapes with row and column tails.
    #[test]
    fn matmul_matches_a_triple_loop() {
        let mut seed = 0x1234_5678u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for &(m, k, n) in &[
            (1, 1, 1),
            (5, 80, 260),
            (7, 3, 17),
            (4, 260, 80),
            (9, 33, 129),
        ] {
            let a: Vec<f32> = (0..m * k).map(|_| rnd()).collect();
            let b: Vec<f32> = (0..k * n).map(|_| rnd()).collect();
            let mut c = vec![f32::NAN; m * n];
            matmul(&a, &b, m, k, n, &mut c);
            for i in 0..m {
                for j in 0..n {
                    let (mut want, mut mag) = (0.0f32, 0.0f32);
                    for t in 0..k {
                        want += a[i * k + t] * b[t * n + j];
                        mag += (a[i * k + t] * b[t * n + j]).abs();
                    }
                    let got = c[i * n + j];
                    assert!(
                        (got - want).abs() <= 1e-6 * mag + 1e-30,
                        "({m},{k},{n}) [{i},{j}]: {got} vs {want}"
                    );
                }
            }
        }
    }
}
