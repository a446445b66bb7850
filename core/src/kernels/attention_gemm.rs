//! R mode's masked attention as per-head GEMMs where every query sees one
//! contiguous run of keys.
//!
//! - The coordinated attention of a whole window ([`attention_staircase`]):
//!   `S` streams of `t` positions (rows stream-major: row `s t + p`) under
//!   the tiled causal mask ([`super::TiledCausalMask`], `q_pos0 = 0`): the
//!   query at position `p` of any stream sees every stream's keys at
//!   positions `<= p`. Taken position-major (key `p' S + s`), those keys
//!   are the first `(p + 1) S`: one run, a staircase over the queries
//!   (also position-major). The key-by-key kernel ([`super::attention`])
//!   takes each stream's run of `p + 1` keys apart: 10 short runs per query
//!   at the published size, each with its own calls and reductions.
//! - A LAT's band ([`attention_band`]; [`super::BandMask`] from row 0):
//!   query `i` sees keys `i - r ..= i + r`, one run in row order, which the
//!   key-by-key kernel takes one query at a time (no two see the same keys).
//!
//! Per head the keys are transposed and the values copied in key order
//! once; then per group of [`ROWS`] queries the scores are one GEMM
//! against the keys the group sees (`rows_times`: one running sum per
//! score over the head's lanes, no horizontal reduction), each row's
//! softmax covers its own keys and zeros the rest of the group's, and the
//! output is one GEMM of the probabilities against the values. Zero
//! probabilities add exact zeros, so a row's numbers are those of its own
//! keys alone, whatever group it falls in (a LAT's last block computes only
//! its first rows: the same bits as all of them).
//!
//! The numbers: each score sums the head's lanes in order (the key-by-key
//! kernels sum them in lane groups, differently on each ISA), the softmax
//! and the output sum the keys in the layout's order. Every SIMD variant of
//! `rows_times` gives the same bits, so these are bit-identical across
//! AVX2, AVX-512 and NEON (the scalar twin within its limit).

use super::parallel::split_cols_aligned;
use super::simd::{self, matmul::rows_times, matmul::COLS, matmul::ROWS};

/// Floats of one head's part of the `work` buffer: its keys transposed and
/// its values in key order (`nk hd` each), the score rows of a group of
/// queries (`ROWS nk`) and its output (`nq hd`).
fn head_work(nq: usize, nk: usize, hd: usize) -> Option<usize> {
    nk.checked_mul(hd)?
        .checked_mul(2)?
        .checked_add(ROWS.checked_mul(nk)?)?
        .checked_add(nq.checked_mul(hd)?)
}

/// Floats of the `work` buffer [`attention_staircase`] and
/// [`attention_band`] need at least for `nq` queries over `nk` keys (one
/// head at a time). With room for more heads, up to one per installed
/// thread is computed at once ([`super::parallel`]).
pub fn gemm_attention_work(nq: usize, nk: usize, hd: usize) -> Option<usize> {
    head_work(nq, nk, hd)
}

/// How queries and keys are ordered and which keys each query sees.
#[derive(Clone, Copy)]
enum Layout {
    /// `streams` of `t` positions, queries and keys position-major.
    Staircase { t: usize, streams: usize },
    /// Row order; query `i` sees keys `i - radius ..= i + radius`.
    Band { radius: usize },
}

impl Layout {
    /// The window row of key (or query) number `j` in the layout's order.
    fn row(self, j: usize) -> usize {
        match self {
            Layout::Staircase { t, streams } => (j % streams) * t + j / streams,
            Layout::Band { .. } => j,
        }
    }
    /// The keys (in the layout's order) query number `i` sees.
    fn keys(self, i: usize, nk: usize) -> (usize, usize) {
        match self {
            Layout::Staircase { streams, .. } => (0, ((i / streams + 1) * streams).min(nk)),
            Layout::Band { radius } => (
                i.saturating_sub(radius),
                i.saturating_add(radius).saturating_add(1).min(nk),
            ),
        }
    }
}

/// `out = softmax(mask(q k^T / sqrt(hd))) v` per head for a whole window of
/// `t` positions under the tiled causal mask (see the module doc): `q`,
/// `k`, `v`, `out` (n, C) with `n = streams * t`, `C = n_head * hd`.
/// `work`: >= [`gemm_attention_work`]`(n, n, hd)` floats of scratch (room
/// for `m` heads: up to `m` at a time, one a thread). Returns false
/// (nothing written) when the shapes are not a whole window or `work` is
/// too short: the caller then runs [`super::attention`]. Each value is
/// computed by the same code whatever the thread count.
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
    if c == 0 || t == 0 {
        return false;
    }
    let n = q.len() / c;
    if n == 0 || n % t != 0 || k.len() / c != n {
        return false;
    }
    let layout = Layout::Staircase { t, streams: n / t };
    gemm_attention(q, k, v, c, n_head, layout, work, out)
}

/// [`attention_staircase`] for a LAT's band from row 0 (query `i` sees
/// keys `i - radius ..= i + radius`): queries `q` (nq, C), the first `nq`
/// rows; keys and values (nk, C), `nq <= nk`; `work`: >=
/// [`gemm_attention_work`]`(nq, nk, hd)` floats.
#[allow(clippy::too_many_arguments)]
pub fn attention_band(
    q: &[f32],
    k: &[f32],
    v: &[f32],
    c: usize,
    n_head: usize,
    radius: usize,
    work: &mut [f32],
    out: &mut [f32],
) -> bool {
    if c == 0 || q.len() / c > k.len() / c {
        return false;
    }
    gemm_attention(q, k, v, c, n_head, Layout::Band { radius }, work, out)
}

/// The body of [`attention_staircase`] / [`attention_band`].
#[allow(clippy::too_many_arguments)]
fn gemm_attention(
    q: &[f32],
    k: &[f32],
    v: &[f32],
    c: usize,
    n_head: usize,
    layout: Layout,
    work: &mut [f32],
    out: &mut [f32],
) -> bool {
    if c == 0 || n_head == 0 || c % n_head != 0 {
        return false;
    }
    let (nq, nk, hd) = (q.len() / c, k.len() / c, c / n_head);
    if nq == 0 || v.len() < nk * c || out.len() < nq * c {
        return false;
    }
    let per = match head_work(nq, nk, hd) {
        Some(w) if w > 0 && work.len() >= w => w,
        _ => return false,
    };
    // As many heads at a time as threads (more only grow the working set).
    let threads = super::parallel::workers().map_or(1, |w| w.threads().max(1));
    let at_once = (work.len() / per).min(n_head).min(threads);
    let sh = Shape {
        c,
        hd,
        nq,
        nk,
        layout,
    };
    let mut h0 = 0;
    while h0 < n_head {
        let m = at_once.min(n_head - h0);
        let regions = &mut work[..m * per];
        // Work: the MACs of the heads' two GEMMs (at most nq nk hd each).
        let macs = nq.saturating_mul(nk).saturating_mul(hd).saturating_mul(m);
        split_cols_aligned(regions, m * per, per, macs, |mut cols| {
            for i in cols.lo() / per..cols.hi() / per {
                one_head(q, k, v, &sh, h0 + i, cols.seg(0, i * per, (i + 1) * per));
            }
        });
        // Each head's output (nq, hd), rows in window order, into its lanes of `out`.
        for (i, region) in regions.chunks_exact(per).enumerate() {
            let (o, h) = (&region[per - nq * hd..], h0 + i);
            for (r, row) in o.chunks_exact(hd).enumerate() {
                out[r * c + h * hd..r * c + (h + 1) * hd].copy_from_slice(row);
            }
        }
        h0 += m;
    }
    true
}

/// The sizes of one call: `nq` queries, `nk` keys of width `c`, heads of `hd`.
struct Shape {
    c: usize,
    hd: usize,
    nq: usize,
    nk: usize,
    layout: Layout,
}

/// Head `h` in `region` ([`head_work`] floats): its output (nq, hd) in the
/// region's last `nq hd` floats, rows in window order.
fn one_head(q: &[f32], k: &[f32], v: &[f32], sh: &Shape, h: usize, region: &mut [f32]) {
    let Shape {
        c,
        hd,
        nq,
        nk,
        layout,
    } = *sh;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let (kt, rest) = region.split_at_mut(nk * hd);
    let (vp, rest) = rest.split_at_mut(nk * hd);
    // (ROWS, nk): score rows of a group of queries; o (nq, hd).
    let (scores, o) = rest.split_at_mut(ROWS * nk);
    let mut tile = [[0.0f32; COLS]; ROWS];
    // Where head h's lanes of window row r start.
    let at = |r: usize| r * c + h * hd;
    // kt (hd, nk): lane d of key j (layout order); vp (nk, hd): value j.
    for j in 0..nk {
        let r = at(layout.row(j));
        for (d, &x) in k[r..r + hd].iter().enumerate() {
            kt[d * nk + j] = x;
        }
        vp[j * hd..(j + 1) * hd].copy_from_slice(&v[r..r + hd]);
    }
    // Queries in groups of ROWS (a short group repeats its last query:
    // computed, not kept), each group against the keys its rows see (the
    // runs only move forward with the query number).
    for i0 in (0..nq).step_by(ROWS) {
        let rows = (nq - i0).min(ROWS);
        let qn = |i: usize| i0 + i.min(rows - 1);
        let (lo, hi) = (layout.keys(qn(0), nk).0, layout.keys(qn(rows - 1), nk).1);
        let w_all = hi.saturating_sub(lo);
        let ar: [&[f32]; ROWS] = core::array::from_fn(|i| {
            let r = at(layout.row(qn(i)));
            &q[r..r + hd]
        });
        let mut k0 = 0;
        while k0 < w_all {
            let w = (w_all - k0).min(COLS);
            rows_times(ar, kt, nk, lo + k0, w, &mut tile);
            for (i, tr) in tile.iter().enumerate().take(rows) {
                scores[i * nk + k0..i * nk + k0 + w].copy_from_slice(&tr[..w]);
            }
            k0 += w;
        }
        for i in 0..rows {
            let sr = &mut scores[i * nk..i * nk + w_all];
            let (a, b) = layout.keys(qn(i), nk);
            let (a, b) = (a - lo, b - lo);
            // A query whose probabilities sum to 0 keeps zeros (as in `attention`).
            simd::softmax_runs(sr, &[(a, b)], scale);
            sr[..a].fill(0.0);
            sr[b..].fill(0.0);
        }
        let ar: [&[f32]; ROWS] = core::array::from_fn(|i| {
            let i = i.min(rows - 1);
            &scores[i * nk..i * nk + w_all]
        });
        // The head's lanes in chunks of COLS (one for heads <= 64).
        for e0 in (0..hd).step_by(COLS) {
            let w = (hd - e0).min(COLS);
            rows_times(ar, &vp[lo * hd..], hd, e0, w, &mut tile);
            for (i, tr) in tile.iter().enumerate().take(rows) {
                let r = layout.row(qn(i)) * hd + e0;
                o[r..r + w].copy_from_slice(&tr[..w]);
            }
        }
    }
}
