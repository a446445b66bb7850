//! Masked multi-head scaled dot-product attention over explicit query and
//! key/value row sets, so the same kernel serves the exact window (all
//! rows), the last-position shortcut and, later, a streaming session
//! (new queries against a cached key range).

use super::kv_rows::KvRows;
use super::parallel::split_cols_aligned;
use super::simd;

/// Which keys a query may see. Row indices are relative to the `q` and
/// `k`/`v` slices handed to [`attention`]; positions are derived by the mask.
pub trait Mask: Sync {
    fn allowed(&self, qi: usize, kj: usize) -> bool;
}

/// The LAT band (`get_subsequent_mask` in the original): query at
/// position `q_pos0 + qi` sees key at `k_pos0 + kj` iff `|qpos - kpos| <= radius`.
#[derive(Clone, Copy, Debug)]
pub struct BandMask {
    pub radius: usize,
    pub q_pos0: usize,
    pub k_pos0: usize,
}

impl Mask for BandMask {
    #[inline]
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        (self.q_pos0 + qi).abs_diff(self.k_pos0 + kj) <= self.radius
    }
}

/// The coordinated-attention mask: streams laid out one after another,
/// `t_q` query rows and `t_k` key rows per stream; a query at in-stream
/// position `q_pos0 + qi % t_q` sees every key (any stream) whose
/// in-stream position `kj % t_k` is not later (lower-triangular `t x t`
/// tiled `streams x streams`).
#[derive(Clone, Copy, Debug)]
pub struct TiledCausalMask {
    pub t_q: usize,
    pub t_k: usize,
    pub q_pos0: usize,
}

impl Mask for TiledCausalMask {
    #[inline]
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        kj % self.t_k <= self.q_pos0 + qi % self.t_q
    }
}

/// Runs of allowed keys remembered per query (the masks of the model have
/// one run (band) or one per stream (tiled causal)); a query whose mask
/// breaks into more runs takes the key-by-key path.
const MAX_RUNS: usize = 64;

/// Most keys of an attention split over threads: each thread scores its
/// queries in a stack buffer of this many floats (4 KiB); longer key runs
/// stay on the calling thread (with the caller's `scores`).
pub const SPLIT_MAX_KEYS: usize = 1024;

/// `out = softmax(mask(q k^T / sqrt(hd))) v`, per head. `q`: (nq, C);
/// `k`, `v`: (nk, C) ([`KvRows`]: a plain f32 slice, or a cache's one or
/// two runs of f32 / f16 rows); `out`: (nq, C); `scores`: >= nk scratch; `C = n_head
/// * hd`. Masked keys are skipped (= -inf before softmax). A query that
/// sees no key gets zeros (cannot happen with the model's masks).
///
/// Per query the mask is read once into runs of consecutive allowed keys;
/// per head and run the scores are one [`simd::dot_rows`] call and the
/// probability-weighted values one [`simd::axpy_rows_f32`] call. With a worker
/// pool ([`super::parallel`]) and at most [`SPLIT_MAX_KEYS`] keys, the
/// queries are split over its threads (each query computed as on one
/// thread: bit-identical).
#[allow(clippy::too_many_arguments)]
pub fn attention<'a, M: Mask>(
    q: &[f32],
    k: impl Into<KvRows<'a>>,
    v: impl Into<KvRows<'a>>,
    c: usize,
    n_head: usize,
    mask: &M,
    scores: &mut [f32],
    out: &mut [f32],
) {
    if c == 0 || n_head == 0 {
        return;
    }
    let (k, v) = (k.into(), v.into());
    let nq = (q.len() / c).min(out.len() / c);
    let nk = k.rows(c).min(v.rows(c)).min(scores.len());
    let out = &mut out[..nq * c];
    if nk > SPLIT_MAX_KEYS {
        return attend_queries(q, &k, &v, c, n_head, mask, 0, nk, scores, out);
    }
    split_cols_aligned(out, nq * c, c, nq.saturating_mul(nk).saturating_mul(c), |mut cols| {
        let (lo, hi) = (cols.lo(), cols.hi());
        let mut scores = [0.0f32; SPLIT_MAX_KEYS];
        attend_queries(q, &k, &v, c, n_head, mask, lo / c, nk, &mut scores, cols.seg(0, lo, hi));
    });
}

/// Queries `q0 .. q0 + out.len() / c` of [`attention`] (`out`: their rows).
#[allow(clippy::too_many_arguments)]
fn attend_queries<M: Mask>(q: &[f32], k: &KvRows<'_>, v: &KvRows<'_>, c: usize, n_head: usize, mask: &M, q0: usize, nk: usize, scores: &mut [f32], out: &mut [f32]) {
    let hd = c / n_head;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let mut runs = [(0usize, 0usize); MAX_RUNS];
    for (qi, orow) in (q0..).zip(out.chunks_exact_mut(c)) {
        let mut nr = 0;
        let mut kj = 0;
        while kj < nk && nr <= MAX_RUNS {
            if !mask.allowed(qi, kj) {
                kj += 1;
                continue;
            }
            let start = kj;
            while kj < nk && mask.allowed(qi, kj) {
                kj += 1;
            }
            if nr < MAX_RUNS {
                runs[nr] = (start, kj);
            }
            nr += 1;
        }
        if nr > MAX_RUNS {
            attention_query_keywise(q, k, v, c, n_head, mask, qi, nk, scale, scores, orow);
            continue;
        }
        let runs = &runs[..nr];
        for h in 0..n_head {
            let qh = &q[qi * c + h * hd..qi * c + (h + 1) * hd];
            let mut max = f32::NEG_INFINITY;
            for &(a, b) in runs {
                let run = &mut scores[a..b];
                k.dot_rows(qh, a, b, c, h * hd, run);
                for s in run.iter_mut() {
                    *s *= scale;
                    max = max.max(*s);
                }
            }
            let oh = &mut orow[h * hd..(h + 1) * hd];
            oh.fill(0.0);
            let mut sum = 0.0f32;
            for &(a, b) in runs {
                sum += simd::exp_shifted_sum(&mut scores[a..b], max);
            }
            if sum == 0.0 {
                continue;
            }
            let inv = 1.0 / sum;
            for &(a, b) in runs {
                let p = &mut scores[a..b];
                for s in p.iter_mut() {
                    *s *= inv;
                }
                v.axpy_rows(p, a, b, c, h * hd, oh);
            }
        }
    }
}

/// One query of [`attention`], key by key (masks with many runs); `out`:
/// the query's output row.
#[allow(clippy::too_many_arguments)]
fn attention_query_keywise<M: Mask>(
    q: &[f32],
    k: &KvRows<'_>,
    v: &KvRows<'_>,
    c: usize,
    n_head: usize,
    mask: &M,
    qi: usize,
    nk: usize,
    scale: f32,
    scores: &mut [f32],
    out: &mut [f32],
) {
    let hd = c / n_head;
    for h in 0..n_head {
        let qh = &q[qi * c + h * hd..qi * c + (h + 1) * hd];
        let mut max = f32::NEG_INFINITY;
        for kj in 0..nk {
            if mask.allowed(qi, kj) {
                let s = k.dot(qh, kj, c, h * hd) * scale;
                scores[kj] = s;
                max = max.max(s);
            }
        }
        let oh = &mut out[h * hd..(h + 1) * hd];
        oh.fill(0.0);
        let mut sum = 0.0f32;
        for kj in 0..nk {
            if mask.allowed(qi, kj) {
                let e = simd::scalar::exp(scores[kj] - max);
                scores[kj] = e;
                sum += e;
            }
        }
        if sum == 0.0 {
            continue;
        }
        let inv = 1.0 / sum;
        for kj in 0..nk {
            if mask.allowed(qi, kj) {
                v.axpy(scores[kj] * inv, kj, c, h * hd, oh);
            }
        }
    }
}
