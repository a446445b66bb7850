//! R mode's coordinated attention as per-head GEMMs over a staircase.
//!
//! A window of `S` streams of `t` positions (rows stream-major: row
//! `s t + p`) under the tiled causal mask ([`super::TiledCausalMask`] with
//! `q_pos0 = 0`): the query at position `p` of any stream sees every
//! stream's keys at positions `<= p`. Taken position-major (key `p' S +
//! s`), those keys are the first `(p + 1) S`: one contiguous run, the same
//! for the `S` queries of a position. So per head the scores of a
//! position's queries are one GEMM against the keys transposed
//! (`rows_times`: one running sum per score over the head's lanes, no
//! horizontal reduction), the softmax runs over one run, and the output is
//! one GEMM of the probabilities against the values in position-major
//! order. Key-by-key kernels ([`super::attention`]) take each stream's run
//! of `p + 1` keys apart: 10 short runs per query, each with its own
//! calls and reductions, 1.6x the time at the published size.
//!
//! The numbers: each score sums the head's lanes in order (the key-by-key
//! kernels sum them in lane groups, differently on each ISA), the softmax
//! and the output sum the keys position-major. Every SIMD variant of
//! `rows_times` gives the same bits, so this attention is bit-identical
//! across AVX2, AVX-512 and NEON (the scalar twin within its limit).

use super::parallel::split_cols_aligned;
use super::simd::{self, matmul::rows_times, matmul::COLS, matmul::ROWS};

/// Floats of one head's part of the `work` buffer of
/// [`attention_staircase`]: its keys transposed and its values
/// position-major (`n hd` each), the score rows of a group of queries
/// (`ROWS n`) and its output (`n hd`).
fn head_work(n: usize, hd: usize) -> Option<usize> {
    n.checked_mul(hd)?
        .checked_mul(3)?
        .checked_add(ROWS.checked_mul(n)?)
}

/// Floats of the `work` buffer [`attention_staircase`] needs at least (one
/// head at a time). With room for more heads, up to one per installed
/// thread is computed at once ([`super::parallel`]).
pub fn staircase_work(n: usize, hd: usize) -> Option<usize> {
    head_work(n, hd)
}

/// `out = softmax(mask(q k^T / sqrt(hd))) v` per head for a whole window of
/// `t` positions (see the module doc): `q`, `k`, `v`, `out` (n, C) with `n
/// = streams * t`, `C = n_head * hd`. `work`: >= [`staircase_work`] floats
/// of scratch (room for `m` heads: up to `m` at a time, one a thread).
/// Returns false (nothing written) when the shapes are not a whole window
/// or `work` is too short: the caller then runs [`super::attention`].
/// Each value is computed by the same code whatever the thread count.
#[allow(clippy::too_many_arguments)]
pub fn attention_staircase(
    q: &[f32],
    k: &[f32],
    v: &[f32],
    c: usize,
    n_head: usize,
    t: usize,
    work: &mut [f32],
    out: &mut [f32],
) -> bool {
    if c == 0 || n_head == 0 || t == 0 || c % n_head != 0 {
        return false;
    }
    let n = q.len() / c;
    let hd = c / n_head;
    if n == 0 || n % t != 0 || k.len() < n * c || v.len() < n * c || out.len() < n * c {
        return false;
    }
    let streams = n / t;
    let per = match head_work(n, hd) {
        Some(w) if w > 0 && work.len() >= w => w,
        _ => return false,
    };
    // As many heads at a time as threads (more only grow the working set).
    let threads = super::parallel::workers().map_or(1, |w| w.threads().max(1));
    let at_once = (work.len() / per).min(n_head).min(threads);
    let shape = Shape {
        c,
        hd,
        t,
        streams,
        n,
    };
    let mut h0 = 0;
    while h0 < n_head {
        let m = at_once.min(n_head - h0);
        let regions = &mut work[..m * per];
        // Work: the MACs of the heads' two GEMMs (about n^2 hd each).
        let macs = n.saturating_mul(n).saturating_mul(hd).saturating_mul(m);
        split_cols_aligned(regions, m * per, per, macs, |mut cols| {
            for i in cols.lo() / per..cols.hi() / per {
                one_head(q, k, v, &shape, h0 + i, cols.seg(0, i * per, (i + 1) * per));
            }
        });
        // Each head's output (n, hd), rows in window order, into its lanes of `out`.
        for (i, region) in regions.chunks_exact(per).enumerate() {
            let (o, h) = (&region[per - n * hd..], h0 + i);
            for (r, row) in o.chunks_exact(hd).enumerate() {
                out[r * c + h * hd..r * c + (h + 1) * hd].copy_from_slice(row);
            }
        }
        h0 += m;
    }
    true
}

/// The sizes of one window: `n = streams t` rows of width `c`, heads of `hd`.
struct Shape {
    c: usize,
    hd: usize,
    t: usize,
    streams: usize,
    n: usize,
}

/// Head `h` of [`attention_staircase`] in `region` ([`head_work`] floats):
/// its output (n, hd) in the region's last `n hd` floats, rows in window
/// order.
fn one_head(q: &[f32], k: &[f32], v: &[f32], sh: &Shape, h: usize, region: &mut [f32]) {
    let Shape {
        c,
        hd,
        t,
        streams,
        n,
    } = *sh;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let (kt, rest) = region.split_at_mut(n * hd);
    let (vp, rest) = rest.split_at_mut(n * hd);
    // (ROWS, n): score rows of a group of queries; o (n, hd).
    let (scores, o) = rest.split_at_mut(ROWS * n);
    let mut tile = [[0.0f32; COLS]; ROWS];
    // Where head h's lanes of row (stream s, position p) start.
    let row = |s: usize, p: usize| (s * t + p) * c + h * hd;
    // kt (hd, n): lane d of key p' S + s; vp (n, hd): value p' S + s.
    for p in 0..t {
        for s in 0..streams {
            let (j, r) = (p * streams + s, row(s, p));
            for (d, &x) in k[r..r + hd].iter().enumerate() {
                kt[d * n + j] = x;
            }
            vp[j * hd..(j + 1) * hd].copy_from_slice(&v[r..r + hd]);
        }
    }
    // The queries position-major too (query p S + s: stream s, position p)
    // in groups of ROWS, a group across positions where S is not a multiple
    // of ROWS: every row of a group is scored against the keys its last
    // row sees; each row's softmax covers its own keys and zeros the rest,
    // so the value GEMM over the group's keys adds exact zeros past a row's
    // own (its sums are what its own keys alone give).
    for j0 in (0..n).step_by(ROWS) {
        let rows = (n - j0).min(ROWS);
        let at = |i: usize| {
            let j = j0 + i.min(rows - 1);
            (j % streams, j / streams)
        };
        let nk_of = |i: usize| (at(i).1 + 1) * streams;
        let nk = nk_of(rows - 1);
        let ar: [&[f32]; ROWS] = core::array::from_fn(|i| {
            let (s, p) = at(i);
            &q[row(s, p)..row(s, p) + hd]
        });
        let mut k0 = 0;
        while k0 < nk {
            let w = (nk - k0).min(COLS);
            rows_times(ar, kt, n, k0, w, &mut tile);
            for (i, tr) in tile.iter().enumerate().take(rows) {
                scores[i * n + k0..i * n + k0 + w].copy_from_slice(&tr[..w]);
            }
            k0 += w;
        }
        for i in 0..rows {
            let sr = &mut scores[i * n..i * n + nk];
            let own = nk_of(i);
            // A query whose probabilities sum to 0 keeps zeros (as in `attention`).
            simd::softmax_runs(sr, &[(0, own)], scale);
            sr[own..].fill(0.0);
        }
        let ar: [&[f32]; ROWS] = core::array::from_fn(|i| {
            let i = i.min(rows - 1);
            &scores[i * n..i * n + nk]
        });
        // The head's lanes in chunks of COLS (one for heads <= 64).
        for e0 in (0..hd).step_by(COLS) {
            let w = (hd - e0).min(COLS);
            rows_times(ar, vp, hd, e0, w, &mut tile);
            for (i, tr) in tile.iter().enumerate().take(rows) {
                let (s, p) = at(i);
                let r = (s * t + p) * hd + e0;
                o[r..r + w].copy_from_slice(&tr[..w]);
            }
        }
    }
}
