//! A streaming GPT's window under S (docs/STREAMING.md §3.5): the base
//! and head blocks of a multi-stream GPT (Duolando's coordinated
//! attention, Bailando's cross-conditional GPT) over one chunked window,
//! with a per-layer K/V cache. Within a window (fixed start `lo`) the inputs of every cached
//! row are unchanged and the mask is causal in rows, so appending the new
//! row computes exactly what the full window forward computes; when the
//! window start moves, the cache is cleared and the window re-prefilled.
//!
//! Layout: position-major, row `i * streams + s` = window row `i`, stream
//! `s` (Duolando: `[music, L_up, L_down, L_lh, L_rh, F_up, F_down, F_lh,
//! F_rh, F_transl]`; Bailando: `[music, up, down]`); the streams a family's
//! heads read are the last `out_streams` of a row;
//! per layer head-major ([`KvRows::head_major`]): head `h`'s lanes of all
//! rows side by side, so the attention's pass over one head reads one
//! contiguous stretch of a cold cache, not `hd` lanes of every row.
//!
//! The window's last row (`m - 1`, a full window) is kept apart, in a tail
//! of one window row reused by every layer: its keys are seen only by its
//! own queries (the mask is causal in rows), which run in the call that
//! makes them, and the window jumps at the next step. So a cache holds
//! `m - 1` rows per layer and one row (`tail_k`, `tail_v`) for all layers:
//! the attention reads the cached rows, then the tail's, in place
//! ([`KvRows::head_major_then`]), the same numbers as one stretch.

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};
use crate::kernels::{KvRows, Mask};
use crate::nn::block::{block_attend_groups, block_kv, BlockScratch};
use crate::nn::kv_store::KvBuf;
pub use crate::nn::kv_store::KvType;
use crate::nn::weights::BlockW;

/// The most sessions a step batch holds.
pub const MAX_BATCH: usize = 64;
/// Most caches one [`GptCache::append_many`] call appends to (a batch's
/// sessions, each with up to two windows).
pub const MAX_ITEMS: usize = 2 * MAX_BATCH;
use heapless::Vec;

/// Causal over window rows for a position-major layout: query row `qi`
/// (flat index `q_row0 + qi`) sees every key whose window row is not later.
#[derive(Clone, Copy)]
struct RowCausal {
    streams: usize,
    q_row0: usize,
}

impl Mask for RowCausal {
    #[inline]
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        kj / self.streams <= (self.q_row0 + qi) / self.streams
    }
    /// The streams of one window row see the same keys: consecutive
    /// queries are scored together, in groups that end where a row does.
    fn period(&self) -> Option<usize> {
        Some(1)
    }
    /// One run: the keys of the window rows up to the query's.
    fn key_runs(&self, qi: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        let row = self.q_row0.checked_add(qi)?.checked_div(self.streams)?;
        let end = row.checked_add(1)?.checked_mul(self.streams)?.min(nk);
        Some(crate::kernels::attention::one_run(0, end, runs))
    }
}

/// Per-layer K/V of the current window.
pub struct GptCache<'s> {
    /// Per layer (heads, streams * (m - 1), C / n_head) keys and values.
    k: KvBuf<'s>,
    v: KvBuf<'s>,
    /// (streams, C) the keys and values of window row `m - 1` (row-major),
    /// of the layer being run.
    tail_k: KvBuf<'s>,
    tail_v: KvBuf<'s>,
    layers: usize,
    streams: usize,
    /// Window rows a cache holds (`block_size - 1`).
    m: usize,
    c: usize,
    /// Lanes of one head.
    hd: usize,
    /// Window rows cached.
    rows: usize,
    /// Start (token index) of the cached window; None when empty.
    lo: Option<usize>,
}

impl<'s> GptCache<'s> {
    /// Per layer (heads, streams * (m - 1), C / n_head) keys and values,
    /// and one window row's (the tail).
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        kv: KvType,
        layers: usize,
        streams: usize,
        m: usize,
        c: usize,
        n_head: usize,
    ) -> Result<Self, ArenaError> {
        let n = layers
            .checked_mul(streams)
            .and_then(|v| v.checked_mul(m.saturating_sub(1)))
            .and_then(|v| v.checked_mul(c))
            .ok_or(ArenaError::Overflow)?;
        let t = streams.checked_mul(c).ok_or(ArenaError::Overflow)?;
        let hd = c
            .checked_div(n_head)
            .filter(|&hd| hd > 0 && hd * n_head == c)
            .ok_or(ArenaError::Overflow)?;
        Ok(GptCache {
            k: KvBuf::carve(a, kv, n)?,
            v: KvBuf::carve(a, kv, n)?,
            tail_k: KvBuf::carve(a, kv, t)?,
            tail_v: KvBuf::carve(a, kv, t)?,
            layers,
            streams,
            m,
            c,
            hd,
            rows: 0,
            lo: None,
        })
    }

    /// Stream-rows cached per layer (all but the window's last row).
    fn cap(&self) -> usize {
        self.streams * self.m.saturating_sub(1)
    }

    pub fn reset(&mut self) {
        self.rows = 0;
        self.lo = None;
    }

    /// Start of the cached window.
    pub fn window_start(&self) -> Option<usize> {
        self.lo
    }

    /// Window rows cached.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Starts a new window at token `lo` (drops the cache).
    pub fn restart(&mut self, lo: usize) {
        self.rows = 0;
        self.lo = Some(lo);
    }

    /// Window rows this cache holds before its tail (`m - 1` of the `m` it
    /// was carved for).
    pub fn capacity_rows(&self) -> usize {
        self.m.saturating_sub(1)
    }

    /// Moves `other`'s window (start and rows, none in its tail) into this
    /// cache, each head's stretch copied unchanged, and empties `other`.
    /// The spread schedule's second cache holds the next window's first
    /// rows in fewer rows than a window; at the jump they move here. Both
    /// caches of one GPT and storage type.
    pub fn take_window(&mut self, other: &mut GptCache<'_>) -> Result<(), Error> {
        let (c, hd, cap, ocap) = (self.c, self.hd, self.cap(), other.cap());
        let r = other.rows * other.streams;
        if other.layers != self.layers
            || other.streams != self.streams
            || other.c != c
            || other.hd != hd
            || r > ocap
            || r > cap
        {
            return Err(Error::Context { c: r, max: cap.min(ocap) });
        }
        for l in 0..self.layers {
            for h in 0..c / hd {
                let (at, from) = (l * cap * c + h * cap * hd, l * ocap * c + h * ocap * hd);
                self.k.copy_from(at, &other.k, from, r * hd)?;
                self.v.copy_from(at, &other.v, from, r * hd)?;
            }
        }
        self.rows = other.rows;
        self.lo = other.lo;
        other.reset();
        Ok(())
    }

    /// The spread schedule's jump, shared by every family: makes
    /// `caches[0]` (the window's own cache) hold the window starting at
    /// `lo`, taking over the rows `caches[1]` (the next window's, where
    /// there is one) gathered ahead for it, or else empty. Nothing changes
    /// where `caches[0]` already holds that window.
    pub fn enter_window(caches: &mut [GptCache<'_>], lo: usize) -> Result<(), Error> {
        let Some((main, rest)) = caches.split_first_mut() else {
            return Err(Error::State);
        };
        if main.window_start() == Some(lo) {
            return Ok(());
        }
        match rest.first_mut() {
            Some(ahead) if ahead.window_start() == Some(lo) => main.take_window(ahead),
            _ => {
                main.restart(lo);
                Ok(())
            }
        }
    }

    /// The spread schedule's share of step `k` in this (second) cache,
    /// which gathers the next window (start `nlo`, first used at step
    /// `k2 > k`; restarted here if it held another): the window rows
    /// `nlo..k2` it holds (at most [`Self::capacity_rows`]) must be cached
    /// by the end of step `k2 - 1`, so each step to then appends an equal
    /// share of those still missing, of rows that exist (`<= k`). Returns
    /// `(first row, rows)` to append at this step, or `None`.
    pub fn ahead_share(&mut self, k: usize, k2: usize, nlo: usize) -> Option<(usize, usize)> {
        if k2 <= k {
            return None;
        }
        if self.window_start() != Some(nlo) {
            self.restart(nlo);
        }
        let first = nlo + self.rows;
        let end = k2.min(nlo + self.capacity_rows());
        let share = end.saturating_sub(first).div_ceil(k2 - k);
        let rows = share.min((k + 1).saturating_sub(first));
        (rows > 0).then_some((first, rows))
    }

    /// This cache's K/V of layer `l`, rows `..r1` (streams-rows), read in
    /// place (f32 or f16): head-major, the layer's stretch from its first
    /// head's row 0 to its last head's row `min(r1, cap)`, then the tail's
    /// rows up to `r1` (window row `m - 1`, stored by this layer's `store`).
    fn visible(&self, l: usize, r1: usize) -> Result<(KvRows<'_>, KvRows<'_>), Error> {
        let (c, hd, cap) = (self.c, self.hd, self.cap());
        let (rc, rt) = (r1.min(cap), r1.saturating_sub(cap));
        if rt > self.streams {
            return Err(Error::Context {
                c: r1,
                max: cap + self.streams,
            });
        }
        let base = l * cap * c;
        let end = base + (c - hd) * cap + rc * hd;
        let rows = |d, tail| {
            KvRows::head_major_then(d, rc, cap, hd, tail).ok_or(Error::Context { c: r1, max: cap })
        };
        Ok((
            rows(self.k.view(base, end)?, self.tail_k.view(0, rt * c)?)?,
            rows(self.v.view(base, end)?, self.tail_v.view(0, rt * c)?)?,
        ))
    }

    /// Stores the new rows' K/V (`k`, `v`: (r1 - r0, C) f32) of layer `l`
    /// at stream-rows `r0..r1`, each head's lanes at their head-major place,
    /// window row `m - 1`'s in the tail (an f16 cache rounds them).
    fn store(&mut self, l: usize, r0: usize, r1: usize, k: &[f32], v: &[f32]) -> Result<(), Error> {
        let (c, hd, cap) = (self.c, self.hd, self.cap());
        if k.len() != (r1 - r0) * c || v.len() != k.len() || r1 > cap + self.streams {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: k.len(),
                expected: (r1 - r0) * c,
            });
        }
        for (i, (kr, vr)) in k.chunks_exact(c).zip(v.chunks_exact(c)).enumerate() {
            let r = r0 + i;
            if r >= cap {
                self.tail_k.store((r - cap) * c, kr)?;
                self.tail_v.store((r - cap) * c, vr)?;
                continue;
            }
            for (h, (kh, vh)) in kr.chunks_exact(hd).zip(vr.chunks_exact(hd)).enumerate() {
                let at = l * cap * c + (h * cap + r) * hd;
                self.k.store(at, kh)?;
                self.v.store(at, vh)?;
            }
        }
        Ok(())
    }

    /// Appends window rows to several caches at once (one per session of a
    /// batch, or one alone) and runs every layer over them, reading each
    /// weight matrix once for all. `x` (sum of n_i * streams, C) holds the
    /// inputs (position rows added) of item `i`'s `n_i = items[i].rows` new
    /// window rows, one item after another.
    ///
    /// `blocks` are the GPT's base then head blocks, one per cached layer.
    /// On return, for the `j`-th item with `need_output` (in item order),
    /// rows `j * out_streams ..` of `x` hold the final hidden state of
    /// the last `out_streams` streams at its last new row (what the heads read);
    /// items without it skip the last layer's attention and MLP (only its
    /// K/V are kept). Other rows of `x` are scratch. An item's result is
    /// what an append of its own would give.
    pub fn append_many<'w: 'b, 'b>(
        blocks: impl Iterator<Item = &'b BlockW<'w>> + Clone,
        n_head: usize,
        out_streams: usize,
        items: &mut [GptItem<'_, '_>],
        x: &mut [f32],
        s: &mut BlockScratch<'_>,
    ) -> Result<(), Error> {
        let Some(first) = items.first() else {
            return Ok(());
        };
        let (st, c, layers) = (first.cache.streams, first.cache.c, first.cache.layers);
        if out_streams == 0 || out_streams > st {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: out_streams,
                expected: st,
            });
        }
        if blocks.clone().count() != layers || items.len() > MAX_ITEMS {
            return Err(Error::Context {
                c: items.len(),
                max: MAX_ITEMS,
            });
        }
        // The caches are head-major for heads of `hd` lanes (carved with
        // `hd * heads == c`): other heads would read across them.
        if c.checked_div(n_head) != Some(first.cache.hd) {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: n_head,
                expected: c / first.cache.hd,
            });
        }
        // Row bounds of the items in `x`, and each item's first cached row.
        let mut bounds: Vec<usize, { MAX_ITEMS + 1 }> = Vec::new();
        bounds.push(0).map_err(|_| Error::State)?;
        let mut total = 0usize;
        for it in items.iter() {
            let ch = &it.cache;
            if it.rows == 0
                || ch.streams != st
                || ch.c != c
                || ch.hd != first.cache.hd
                || ch.layers != layers
                || ch.rows + it.rows > ch.m
            {
                return Err(Error::Context {
                    c: ch.rows + it.rows,
                    max: ch.m,
                });
            }
            total += it.rows * st;
            bounds.push(total).map_err(|_| Error::State)?;
        }
        if x.len() != total * c || total * c > s.row_floats() {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: x.len(),
                expected: total * c,
            });
        }
        let row0 = |it: &GptItem<'_, '_>| it.cache.rows * st;
        for (l, b) in blocks.enumerate() {
            // (total, C) keys and values of every new row, in one pass.
            let p = s.qkv();
            let (kn, vn) = (&mut p.k[..total * c], &mut p.v[..total * c]);
            block_kv(b, x, p.ln, kn, vn);
            for (i, it) in items.iter_mut().enumerate() {
                let (a, z) = (bounds[i] * c, bounds[i + 1] * c);
                let r0 = row0(it);
                it.cache
                    .store(l, r0, r0 + it.rows * st, &kn[a..z], &vn[a..z])?;
            }
            let items_ro: &[GptItem<'_, '_>] = items;
            if l + 1 < layers {
                let keys = |g: usize| {
                    let it = &items_ro[g];
                    let r0 = row0(it);
                    let (k, v) = it.cache.visible(l, r0 + it.rows * st)?;
                    Ok((
                        k,
                        v,
                        RowCausal {
                            streams: st,
                            q_row0: r0,
                        },
                    ))
                };
                block_attend_groups(b, x, &bounds, c, n_head, keys, s)?;
            } else {
                // Last layer: only the output rows of each output item's
                // last new row are read; they are gathered to the front.
                let mut outs: Vec<usize, MAX_ITEMS> = Vec::new();
                let mut ob: Vec<usize, { MAX_ITEMS + 1 }> = Vec::new();
                ob.push(0).map_err(|_| Error::State)?;
                for (i, it) in items_ro.iter().enumerate() {
                    if it.need_output {
                        let j = outs.len();
                        let src = (bounds[i + 1] - out_streams) * c;
                        x.copy_within(src..src + out_streams * c, j * out_streams * c);
                        outs.push(i).map_err(|_| Error::State)?;
                        ob.push((j + 1) * out_streams).map_err(|_| Error::State)?;
                    }
                }
                if !outs.is_empty() {
                    let keys = |g: usize| {
                        let it = &items_ro[outs[g]];
                        let r1 = row0(it) + it.rows * st;
                        let (k, v) = it.cache.visible(l, r1)?;
                        Ok((
                            k,
                            v,
                            RowCausal {
                                streams: st,
                                q_row0: r1 - out_streams,
                            },
                        ))
                    };
                    let xs = &mut x[..outs.len() * out_streams * c];
                    block_attend_groups(b, xs, &ob, c, n_head, keys, s)?;
                }
            }
        }
        for it in items.iter_mut() {
            it.cache.rows += it.rows;
        }
        Ok(())
    }
}

/// One cache's share of [`GptCache::append_many`]: `rows` new window rows.
pub struct GptItem<'r, 's> {
    pub cache: &'r mut GptCache<'s>,
    pub rows: usize,
    pub need_output: bool,
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::RowCausal;
    use crate::kernels::{attention, KvRows, RowData, Ungrouped};

    /// `take_window` moves a smaller cache's rows into a window-sized one:
    /// every layer's keys and values read back as the rows stored (f32 and
    /// f16), the start and row count move, the source empties; rows past
    /// the destination's capacity or another geometry are refused.
    #[test]
    fn take_window_moves_every_layer_and_head() {
        use super::{GptCache, KvType};
        use crate::arena::Arena;
        let (layers, streams, c, heads) = (2usize, 3usize, 8usize, 2usize);
        for kv in [KvType::F32, KvType::F16] {
            let mut mem = std::vec![0u8; 1 << 16];
            let mut a = Arena::new(&mut mem);
            let mut main = GptCache::carve(&mut a, kv, layers, streams, 6, c, heads).unwrap();
            let mut ahead = GptCache::carve(&mut a, kv, layers, streams, 4, c, heads).unwrap();
            assert_eq!((main.capacity_rows(), ahead.capacity_rows()), (5, 3));
            ahead.restart(7);
            // Three window rows, values that f16 holds exactly.
            let val = |l: usize, r: usize, j: usize, v: usize| (l * 1000 + r * 40 + j + v * 500) as f32 / 8.0;
            for l in 0..layers {
                let k: Vec<f32> = (0..3 * streams * c).map(|i| val(l, i / c, i % c, 0)).collect();
                let v: Vec<f32> = (0..3 * streams * c).map(|i| val(l, i / c, i % c, 1)).collect();
                ahead.store(l, 0, 3 * streams, &k, &v).unwrap();
            }
            ahead.rows = 3;
            main.restart(0);
            main.take_window(&mut ahead).unwrap();
            assert_eq!((main.window_start(), main.rows()), (Some(7), 3));
            assert_eq!((ahead.window_start(), ahead.rows()), (None, 0));
            let (hd, cap) = (c / heads, main.cap());
            for l in 0..layers {
                for (buf, which) in [(&main.k, 0), (&main.v, 1)] {
                    for r in 0..3 * streams {
                        for j in 0..c {
                            let at = l * cap * c + ((j / hd) * cap + r) * hd + j % hd;
                            let got = match buf.view(at, at + 1).unwrap() {
                                RowData::F32(d) => d[0],
                                RowData::F16(d) => half::f16::from_bits(d[0]).to_f32(),
                            };
                            assert_eq!(got, val(l, r, j, which), "{kv:?} layer {l} row {r} lane {j}");
                        }
                    }
                }
            }
            // Four rows do not fit a cache of three; another geometry is refused.
            let mut big = GptCache::carve(&mut a, kv, layers, streams, 6, c, heads).unwrap();
            big.restart(1);
            big.rows = 4;
            let mut small = GptCache::carve(&mut a, kv, layers, streams, 4, c, heads).unwrap();
            assert!(small.take_window(&mut big).is_err());
            let mut other = GptCache::carve(&mut a, kv, layers + 1, streams, 6, c, heads).unwrap();
            assert!(other.take_window(&mut main).is_err());
            assert_eq!(main.rows(), 3, "a refusal changes nothing");
        }
    }

    /// The spread schedule run by `enter_window` and `ahead_share` over
    /// many steps, with the second cache carved as the sessions carve it
    /// (`shift - 1` rows): each step appends rows that exist, right after
    /// those cached, no row twice; at every jump the window's cache holds
    /// every row the second could gather (`min(k2 - lo, shift - 1)`), so a
    /// step computes only its new row (and its share of the next window,
    /// spread evenly over the steps between jumps).
    #[test]
    fn spread_shares_gather_the_next_window_by_its_jump() {
        use super::{GptCache, KvType};
        use crate::arena::Arena;
        use crate::nn::window::{next_window, window_start};
        for (m, shift) in [(30usize, 22usize), (30, 21), (30, 29), (8, 2), (8, 1), (8, 8), (5, 3)] {
            let mut mem = std::vec![0u8; 1 << 16];
            let mut a = Arena::new(&mut mem);
            let main = GptCache::carve(&mut a, KvType::F32, 1, 1, m, 4, 1).unwrap();
            let ahead = GptCache::carve(&mut a, KvType::F32, 1, 1, shift.clamp(1, m), 4, 1).unwrap();
            let mut caches = [main, ahead];
            for k in 0..6 * m {
                let lo = window_start(k, m, shift);
                let jump = caches[0].window_start() != Some(lo);
                let had = caches[1].window_start().filter(|&x| x == lo).map(|_| caches[1].rows());
                GptCache::enter_window(&mut caches, lo).unwrap();
                assert_eq!(caches[0].window_start(), Some(lo));
                if jump {
                    assert_eq!(caches[0].rows(), had.unwrap_or(0), "m {m} shift {shift} step {k}");
                    if k >= m && shift > 1 {
                        assert_eq!(caches[0].rows(), (k - lo).min(shift - 1), "m {m} shift {shift} step {k}");
                    }
                }
                // The step appends rows first..=k to the window's cache.
                let first = lo + caches[0].rows();
                assert!(first <= k);
                caches[0].rows += k + 1 - first;
                let (k2, nlo) = next_window(k, m, shift);
                if nlo > lo {
                    let before = match caches[1].window_start() {
                        Some(x) if x == nlo => nlo + caches[1].rows(),
                        _ => nlo,
                    };
                    if let Some((f, n)) = caches[1].ahead_share(k, k2, nlo) {
                        assert_eq!(f, before, "right after the cached rows");
                        assert!(n > 0 && f + n - 1 <= k, "rows that exist");
                        assert!(f + n <= k2 && caches[1].rows() + n <= caches[1].capacity_rows());
                        // Spread evenly over the steps between jumps, not left to the last.
                        let period = m + 1 - shift;
                        if k >= m + period {
                            assert!(n <= (shift - 1).div_ceil(period), "m {m} shift {shift} step {k}: {n} rows");
                        }
                        caches[1].rows += n;
                    }
                }
            }
        }
    }

    /// The window-row causal mask's closed-form key runs equal the scan.
    #[test]
    fn row_causal_key_runs_equal_the_scan() {
        for streams in [1usize, 3, 10] {
            for q_row0 in [0usize, 1, 9, 10, 37] {
                crate::tests::kernels::assert_key_runs_scan(
                    &std::format!("row-causal streams={streams} q_row0={q_row0}"),
                    &RowCausal { streams, q_row0 },
                    2 * streams + 1,
                    6 * streams + 2,
                );
            }
        }
    }

    /// The row-causal mask's query groups (`period`: a window row's streams
    /// scored together) give every query what it gets alone, bit for bit:
    /// an append of one row, a chunk of rows (groups end at row ends), the
    /// last layer's 5 follower rows (not row-aligned), f32 and f16 keys.
    #[test]
    fn row_causal_groups_equal_queries_alone() {
        let mut seed = 0x9e37_79b9_u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 6.0 - 3.0
        };
        let (st, c, nh) = (10usize, 128usize, 2usize);
        for (nq, q_row0) in [(10usize, 40usize), (30, 20), (5, 45), (13, 27)] {
            let nk = q_row0 + nq;
            let q: Vec<f32> = (0..nq * c).map(|_| next()).collect();
            let k: Vec<f32> = (0..nk * c).map(|_| next()).collect();
            let v: Vec<f32> = (0..nk * c).map(|_| next()).collect();
            let k16: Vec<u16> = k
                .iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect();
            let v16: Vec<u16> = v
                .iter()
                .map(|&x| half::f16::from_f32(x).to_bits())
                .collect();
            let mask = RowCausal {
                streams: st,
                q_row0,
            };
            let mut scores = std::vec![0f32; nk];
            for (kr, vr) in [
                (KvRows::from(&k[..]), KvRows::from(&v[..])),
                (
                    KvRows::one(RowData::F16(&k16)),
                    KvRows::one(RowData::F16(&v16)),
                ),
            ] {
                let (mut grouped, mut alone) =
                    (std::vec![f32::NAN; nq * c], std::vec![f32::NAN; nq * c]);
                attention(&q, kr, vr, c, nh, &mask, &mut scores, &mut grouped);
                attention(&q, kr, vr, c, nh, &Ungrouped(mask), &mut scores, &mut alone);
                assert!(
                    grouped
                        .iter()
                        .zip(&alone)
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "nq {nq} q_row0 {q_row0}: grouped queries differ from alone"
                );
            }
        }
    }
}
