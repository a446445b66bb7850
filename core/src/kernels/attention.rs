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
    /// A `p > 0` such that queries `p` apart mostly see the same keys
    /// (`allowed(qi, kj) == allowed(qi + p, kj)`: for all `qi` in the tiled
    /// causal mask, within a window row in the streaming GPT's row-causal
    /// one): [`attention`] scores them together (each key and value row
    /// read once for a group). `None`: every query alone. Only a hint for
    /// speed: a group's members are checked to have the same key runs, and
    /// a group ends where they differ.
    fn period(&self) -> Option<usize> {
        None
    }
    /// The runs of keys `0..nk` query `qi` may see, in closed form: what
    /// scanning [`Mask::allowed`] key by key gives (ascending, maximal runs
    /// of allowed keys), written to `runs` (as many as fit); returns how
    /// many there are. `None` (the default): no closed form, the attention
    /// scans. Only a shortcut: tests hold every implementation to the scan.
    fn key_runs(&self, qi: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        let _ = (qi, nk, runs);
        None
    }
    /// How [`super::attention_gemm`] computes this mask as per-head GEMMs
    /// (every query sees one run of keys in a layout), where it can; `None`
    /// (the default): the key-by-key [`attention`].
    fn gemm(&self) -> Option<GemmMask> {
        None
    }
}

/// A mask [`super::attention_gemm`] computes as per-head GEMMs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmMask {
    /// The coordinated attention of a whole window of `t` positions
    /// ([`super::attention_staircase`]).
    Staircase(usize),
    /// A band of this radius from row 0 ([`super::attention_band`]).
    Band(usize),
}

/// Writes the single run `[a, b)` (none if empty); returns the count.
pub(crate) fn one_run(a: usize, b: usize, runs: &mut [(usize, usize)]) -> usize {
    if a >= b {
        return 0;
    }
    if let Some(r) = runs.first_mut() {
        *r = (a, b);
    }
    1
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
    /// One run: the keys within `radius` of the query's position.
    fn key_runs(&self, qi: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        let qp = self.q_pos0.checked_add(qi)?;
        let lo = qp.saturating_sub(self.radius).saturating_sub(self.k_pos0);
        let hi = match qp.checked_add(self.radius)?.checked_sub(self.k_pos0) {
            Some(last) => last.saturating_add(1).min(nk),
            None => 0,
        };
        Some(one_run(lo, hi, runs))
    }
    /// From row 0 on both sides (a LAT over its window, R mode).
    fn gemm(&self) -> Option<GemmMask> {
        (self.q_pos0 == 0 && self.k_pos0 == 0).then_some(GemmMask::Band(self.radius))
    }
}

/// No mask: every query sees every key (torch's `TransformerEncoderLayer`
/// without `src_mask`); all queries are one group ([`Mask::period`] 1).
#[derive(Clone, Copy, Debug)]
pub struct AllKeys;

impl Mask for AllKeys {
    #[inline]
    fn allowed(&self, _: usize, _: usize) -> bool {
        true
    }
    fn period(&self) -> Option<usize> {
        Some(1)
    }
    fn key_runs(&self, _: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        Some(one_run(0, nk, runs))
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
    /// The streams' rows at one position (`t_q` apart) see the same keys.
    fn period(&self) -> Option<usize> {
        (self.t_q > 0).then_some(self.t_q)
    }
    /// A whole window from position 0 (R mode's blocks).
    fn gemm(&self) -> Option<GemmMask> {
        (self.t_q > 0 && self.t_q == self.t_k && self.q_pos0 == 0)
            .then_some(GemmMask::Staircase(self.t_q))
    }
    /// The first `pos + 1` keys of every stream of `t_k` (one run when
    /// that is all of them).
    fn key_runs(&self, qi: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        if self.t_q == 0 || self.t_k == 0 {
            return None;
        }
        let seen = self
            .q_pos0
            .checked_add(qi % self.t_q)?
            .saturating_add(1)
            .min(self.t_k);
        if seen == self.t_k {
            return Some(one_run(0, nk, runs));
        }
        let streams = nk.div_ceil(self.t_k);
        for (s, r) in runs.iter_mut().take(streams).enumerate() {
            let a = s * self.t_k;
            *r = (a, (a + seen).min(nk));
        }
        Some(streams)
    }
}

/// A mask with its [`Mask::period`] hidden: [`attention`] takes every query
/// alone, with the same numbers (the per-query path, for comparisons of the
/// query groups: tests and the kernel bench).
#[derive(Clone, Copy, Debug)]
pub struct Ungrouped<M>(pub M);

impl<M: Mask> Mask for Ungrouped<M> {
    #[inline]
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        self.0.allowed(qi, kj)
    }
    fn key_runs(&self, qi: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        self.0.key_runs(qi, nk, runs)
    }
}

/// Runs of allowed keys remembered per query (the masks of the model have
/// one run (band) or one per stream (tiled causal)); a query whose mask
/// breaks into more runs takes the key-by-key path.
const MAX_RUNS: usize = 64;

/// Most keys of an attention split over threads: each thread scores its
/// queries in a stack buffer of [`SPLIT_SCORES`] floats; longer key runs
/// stay on the calling thread (with the caller's `scores`, one query at a
/// time unless it holds more than one row of scores).
pub const SPLIT_MAX_KEYS: usize = 1024;

/// Floats of a thread's score buffer (8 KiB): two rows of
/// [`SPLIT_MAX_KEYS`], or [`simd::QUERY_GROUP`] rows of up to 409 keys (a
/// query group needs one row of scores per member).
const SPLIT_SCORES: usize = 2 * SPLIT_MAX_KEYS;

/// `out = softmax(mask(q k^T / sqrt(hd))) v`, per head. `q`: (nq, C);
/// `k`, `v`: (nk, C) ([`KvRows`]: a plain f32 slice, or a cache's one or
/// two runs of f32 / f16 rows); `out`: (nq, C); `scores`: >= nk scratch;
/// `C = n_head * hd`. Masked keys are skipped (= -inf before softmax). A query that
/// sees no key gets zeros (cannot happen with the model's masks).
///
/// Per query the mask is read once into runs of consecutive allowed keys;
/// per head and run the scores are one [`simd::dot_rows_group`] call and
/// the probability-weighted values one [`simd::axpy_rows_group_f32`] call
/// for a group of queries that see the same keys ([`Mask::period`]; each
/// query's numbers are those of [`simd::dot_rows`] and
/// [`simd::axpy_rows_f32`] on it alone). With a worker
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
    attention_ahead(q, k, v, c, n_head, mask, scores, out, [&[], &[]])
}

/// [`attention`] that also prefetches `ahead` into L2 while it computes,
/// with the same numbers: `ahead[0]` spread key by key over the score
/// passes of the first query group, `ahead[1]` row by row over its value
/// passes (an even share per head and key run). A batch of sessions
/// passes the next session's keys and values: they arrive while this one
/// computes, instead of one session's reads waiting on memory after
/// another's compute. Prefetching them in one burst before the call
/// stalls the core on the burst (measured: no gain); only the AVX-512
/// kernels take the prefetch.
#[allow(clippy::too_many_arguments)]
pub fn attention_ahead<'a, M: Mask>(
    q: &[f32],
    k: impl Into<KvRows<'a>>,
    v: impl Into<KvRows<'a>>,
    c: usize,
    n_head: usize,
    mask: &M,
    scores: &mut [f32],
    out: &mut [f32],
    ahead: [&[u8]; 2],
) {
    if c == 0 || n_head == 0 {
        return;
    }
    let (k, v) = (k.into(), v.into());
    let nq = (q.len() / c).min(out.len() / c);
    let nk = k.rows(c).min(v.rows(c)).min(scores.len());
    let out = &mut out[..nq * c];
    if nk > SPLIT_MAX_KEYS {
        return attend_queries(q, &k, &v, c, n_head, mask, 0, nk, scores, out, ahead);
    }
    split_cols_aligned(
        out,
        nq * c,
        c,
        nq.saturating_mul(nk).saturating_mul(c),
        |mut cols| {
            let (lo, hi) = (cols.lo(), cols.hi());
            let mut scores = [0.0f32; SPLIT_SCORES];
            // The first share of the queries prefetches `ahead` (once).
            let ahead = if lo == 0 { ahead } else { [&[][..], &[][..]] };
            attend_queries(
                q,
                &k,
                &v,
                c,
                n_head,
                mask,
                lo / c,
                nk,
                &mut scores,
                cols.seg(0, lo, hi),
                ahead,
            );
        },
    );
}

/// Queries `q0 .. q0 + out.len() / c` of [`attention`] (`out`: their rows).
///
/// Queries a [`Mask::period`] apart are taken in groups of up to
/// [`simd::QUERY_GROUP`] consecutive members of their class whose key runs
/// are equal (as many groups as needed, sized evenly), so each key and
/// value row is read once per group; `scores` holds one row of `nk` per
/// member. Each query's numbers are those of attending it alone. The
/// first group prefetches `ahead` ([`attention_ahead`]).
#[allow(clippy::too_many_arguments)]
fn attend_queries<M: Mask>(
    q: &[f32],
    k: &KvRows<'_>,
    v: &KvRows<'_>,
    c: usize,
    n_head: usize,
    mask: &M,
    q0: usize,
    nk: usize,
    scores: &mut [f32],
    out: &mut [f32],
    mut ahead: [&[u8]; 2],
) {
    let nq = out.len() / c;
    let g_max = simd::QUERY_GROUP.min(scores.len() / nk.max(1)).max(1);
    let p = match mask.period() {
        Some(p) if p > 0 && g_max > 1 => p,
        _ => nq.max(1),
    };
    let mut runs = [(0usize, 0usize); MAX_RUNS];
    let mut next = [(0usize, 0usize); MAX_RUNS];
    for lead in 0..p.min(nq) {
        let count = (nq - lead).div_ceil(p);
        let size = count.div_ceil(count.div_ceil(g_max));
        let (mut first, mut g, mut nr) = (lead, 0usize, 0usize);
        for li in (lead..nq).step_by(p) {
            let n = key_runs(mask, q0 + li, nk, &mut next);
            let same = n == nr && n <= MAX_RUNS && next[..n] == runs[..n];
            if g > 0 && (g == size || !same) {
                attend_group(
                    q,
                    k,
                    v,
                    c,
                    n_head,
                    mask,
                    q0 + first,
                    p,
                    g,
                    &runs,
                    nr,
                    nk,
                    scores,
                    &mut out[first * c..],
                    ahead,
                );
                ahead = [&[], &[]];
                g = 0;
            }
            if g == 0 {
                (first, nr) = (li, n);
                let keep = n.min(MAX_RUNS);
                runs[..keep].copy_from_slice(&next[..keep]);
            }
            g += 1;
        }
        if g > 0 {
            attend_group(
                q,
                k,
                v,
                c,
                n_head,
                mask,
                q0 + first,
                p,
                g,
                &runs,
                nr,
                nk,
                scores,
                &mut out[first * c..],
                ahead,
            );
            ahead = [&[], &[]];
        }
    }
}

/// The runs of keys `0..nk` query `qi` may see, as `(start, end)` pairs in
/// `runs`; returns their number (more than [`MAX_RUNS`]: only the first
/// `MAX_RUNS` are written, and the caller goes key by key).
fn key_runs<M: Mask>(
    mask: &M,
    qi: usize,
    nk: usize,
    runs: &mut [(usize, usize); MAX_RUNS],
) -> usize {
    if let Some(n) = mask.key_runs(qi, nk, runs) {
        return n;
    }
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
    nr
}

/// `g` queries `qi0, qi0 + p, ..` that see the same `nr` key runs (`out`:
/// from the first one's row; the others `p` rows apart). Per head: the
/// scores of all members in one [`KvRows::dot_rows_group`] call per run
/// (`scores`: `g` rows of `nk`), each member's softmax, and the weighted
/// values in one [`KvRows::axpy_rows_group`] call per run; each call
/// prefetches its share of `ahead` ([`attention_ahead`]).
#[allow(clippy::too_many_arguments)]
fn attend_group<M: Mask>(
    q: &[f32],
    k: &KvRows<'_>,
    v: &KvRows<'_>,
    c: usize,
    n_head: usize,
    mask: &M,
    qi0: usize,
    p: usize,
    g: usize,
    runs: &[(usize, usize); MAX_RUNS],
    nr: usize,
    nk: usize,
    scores: &mut [f32],
    out: &mut [f32],
    ahead: [&[u8]; 2],
) {
    let hd = c / n_head;
    let scale = 1.0 / libm::sqrtf(hd as f32);
    let rs = p * c;
    if nr > MAX_RUNS {
        for m in 0..g {
            attention_query_keywise(
                q,
                k,
                v,
                c,
                n_head,
                mask,
                qi0 + m * p,
                nk,
                scale,
                scores,
                &mut out[m * rs..m * rs + c],
            );
        }
        return;
    }
    let runs = &runs[..nr];
    let scores = &mut scores[..g * nk];
    let mut sums = [0.0f32; simd::QUERY_GROUP];
    for h in 0..n_head {
        let (qh, oh) = (&q[qi0 * c + h * hd..], &mut out[h * hd..]);
        // Call (h, run r)'s share of `ahead`.
        let share = |bytes, r| share(bytes, h * nr + r, n_head * nr);
        for (r, &(a, b)) in runs.iter().enumerate() {
            k.dot_rows_group(
                qh,
                hd,
                rs,
                g,
                a,
                b,
                c,
                h * hd,
                &mut scores[a..],
                nk,
                share(ahead[0], r),
            );
        }
        // A query that sees no key (or only zero weights) keeps zeros.
        for (row, sum) in scores.chunks_exact_mut(nk).zip(&mut sums) {
            *sum = simd::softmax_runs(row, runs, scale);
        }
        for m in 0..g {
            oh[m * rs..m * rs + hd].fill(0.0);
        }
        for (r, &(a, b)) in runs.iter().enumerate() {
            v.axpy_rows_group(
                &scores[a..],
                nk,
                a,
                b,
                c,
                h * hd,
                oh,
                rs,
                hd,
                g,
                share(ahead[1], r),
            );
        }
        for (m, &sum) in sums[..g].iter().enumerate() {
            if sum == 0.0 {
                oh[m * rs..m * rs + hd].fill(0.0);
            }
        }
    }
}

/// Part `i` of `parts` of `bytes`, cut at 64-byte lines.
fn share(bytes: &[u8], i: usize, parts: usize) -> &[u8] {
    let (b0, b1) = simd::part_bytes(bytes.len(), i, parts);
    &bytes[b0..b1]
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
