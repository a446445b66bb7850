//! The Look-Ahead Transformer under S (docs/STREAMING.md §3.3, §3.4): the
//! original blocks, one new position per push, with a band mask that is
//! causal except for `fut` positions of look-ahead in the FIRST layer.
//!
//! Position `p` of layer 1 attends keys `max(0, p - past) ..= p + fut`;
//! layers 2.. attend `max(0, p - past) ..= p`. Layer 1 of position `p`
//! therefore runs when position `p + fut` is pushed; every later layer
//! follows at once. Every `ds` finished positions make one output row
//! `downsample(concat(h_L[ds j .. ds j + ds]))`, final and frozen.
//!
//! Positions are LAT input units: tokens for the leader LATs (`ds = 1`),
//! music frames for the music LAT (`ds = 4`).
//!
//! One push may carry up to `burst` consecutive positions of a LAT (the
//! music LAT takes a step's 4 frames at once): every weight matrix is then
//! read once for all of them, and each position computes what it computes
//! pushed alone (row-independent kernels; a position's queries only see
//! keys of its band: the rows before the push from the rings, the push's
//! own from the step scratch, appended to the rings once the queries ran).

use heapless::Vec;

use crate::arena::{ArenaError, Carve};
use crate::duolando::model::LatW;
use crate::duolando::session::MAX_BATCH;
use crate::error::{check_len, Buffer, Error};
use crate::kernels::{linear, KvRows, Mask, Matrix, RowData};
use crate::limits::MAX_LAT_LAYERS;
use crate::nn::block::{block_attend_groups, block_kv, BlockScratch};
use crate::nn::kv_store::{KvRing, KvType};
use crate::nn::ring::{RowRing, TokenRing};

/// Most positions one [`LatStream::push_many`] call carries over all its
/// LATs (a batch of [`MAX_BATCH`] sessions, 4 music frames each).
pub const MAX_LAT_ROWS: usize = 4 * MAX_BATCH;

/// Every key handed to the attention is visible (the band is applied by
/// choosing the key rows).
pub struct Visible;

impl Mask for Visible {
    #[inline]
    fn allowed(&self, _: usize, _: usize) -> bool {
        true
    }
    fn key_runs(&self, _: usize, nk: usize, runs: &mut [(usize, usize)]) -> Option<usize> {
        Some(crate::kernels::attention::one_run(0, nk, runs))
    }
}

/// Per-step working memory shared by all LATs, for up to `n` LAT pushes
/// (one per session of a batch; `n = 1` inside a session) of up to `rows`
/// positions in all.
#[derive(Default)]
pub struct LatStepScratch<'s> {
    /// (2 rows, C) the positions being pushed, then the positions whose
    /// queries run (`cond_emb` of both in one call), then the latter alone.
    pub h: &'s mut [f32],
    /// (rows, C) their K and V.
    pub k: &'s mut [f32],
    pub v: &'s mut [f32],
    /// (rows, C) LayerNorm output.
    pub ln: &'s mut [f32],
    /// The inputs of `h`'s first rows: the new positions', then those of
    /// the positions whose queries run; room for twice the larger of `n`
    /// C-wide rows (one token a push) and `rows` rows `in_width` wide.
    pub xin: &'s mut [f32],
    /// (n, ds_max * C) concatenated last-layer rows.
    pub cat: &'s mut [f32],
    /// Pushes (LATs) it holds.
    pub n: usize,
    /// Positions it holds over all pushes.
    pub rows: usize,
}

impl<'s> LatStepScratch<'s> {
    /// Room for `n` pushes of `rows` positions in all: rows of inputs at
    /// most `in_width` wide, or one token a push (a C-wide embedding row).
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        c: usize,
        ds_max: usize,
        n: usize,
        rows: usize,
        in_width: usize,
    ) -> Result<Self, ArenaError> {
        let rows = rows.max(n);
        let mul = |x: usize, y: usize| x.checked_mul(y).ok_or(ArenaError::Overflow);
        let rc = mul(rows, c)?;
        Ok(LatStepScratch {
            h: a.f32(mul(2, rc)?)?,
            k: a.f32(rc)?,
            v: a.f32(rc)?,
            ln: a.f32(rc)?,
            xin: a.f32(mul(2, mul(n, c)?.max(mul(rows, in_width)?))?)?,
            cat: a.f32(mul(ds_max, mul(n, c)?)?)?,
            n,
            rows,
        })
    }
}

/// What a LAT's inputs are, chosen when it is carved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LatIn {
    /// Rows of this many floats (the music LAT's 54-wide frames).
    Rows(usize),
    /// Token ids, each input the row of an embedding table (the leader
    /// LATs: a leader code embedded with its part's table).
    Tokens,
}

/// The new positions of one [`LatStream::push_many`] call, all LATs'
/// in order.
#[derive(Clone, Copy)]
pub enum LatInputs<'x, 'w> {
    /// (positions, n_in) input rows.
    Rows(&'x [f32]),
    /// One token id per position and the table that embeds them.
    Tokens(&'x [u32], &'x Matrix<'w>),
}

impl LatInputs<'_, '_> {
    /// Input row `j` into `out` (n_in floats).
    fn row_into(&self, j: usize, out: &mut [f32]) {
        match self {
            LatInputs::Rows(x) => out.copy_from_slice(&x[j * out.len()..(j + 1) * out.len()]),
            LatInputs::Tokens(ids, table) => table.row_into(ids[j] as usize, out),
        }
    }
}

/// What a LAT holds of the positions waiting `fut` pushes for their keys:
/// enough to give their layer-1 residual rows when their queries run.
enum Held<'s> {
    /// Their input rows, narrower than C; `cond_emb` runs on them again.
    Inputs(RowRing<'s>),
    /// Their token ids (4 bytes a position); embedded and `cond_emb` again.
    Tokens(TokenRing<'s>),
    /// Their residual rows `cond_emb(x)` themselves, C wide (inputs at
    /// least as wide as C).
    Residuals(RowRing<'s>),
}

/// A ring's rows, then rows `t0..t1` of `t` (rows of width `c`).
fn with_tail<'x>(
    ring: KvRows<'x>,
    t: &'x [f32],
    t0: usize,
    t1: usize,
    c: usize,
) -> Result<KvRows<'x>, Error> {
    let tail = t.get(t0 * c..t1 * c).ok_or(Error::State)?;
    ring.then(RowData::F32(tail)).ok_or(Error::State)
}

/// A push's rows of layer `l` kept apart in `k` / `v` (each LAT `i`'s
/// `counts[i]` rows one after another): their first rows into `tails`,
/// the rows rounded in place to what the LAT's rings store.
fn hold_tails(
    lats: &[&mut LatStream<'_>],
    counts: &[usize],
    l: usize,
    k: &mut [f32],
    v: &mut [f32],
    c: usize,
    tails: &mut Vec<usize, MAX_BATCH>,
) -> Result<(), Error> {
    tails.clear();
    let mut row = 0;
    for (lat, &cnt) in lats.iter().zip(counts) {
        tails.push(row).map_err(|_| Error::State)?;
        let rows = row * c..(row + cnt) * c;
        let kv = lat.k[l].kv_type();
        kv.round_as_stored(k.get_mut(rows.clone()).ok_or(Error::State)?);
        kv.round_as_stored(v.get_mut(rows).ok_or(Error::State)?);
        row += cnt;
    }
    Ok(())
}

/// Appends to layer `l`'s rings of each LAT `i` its `counts[i]` rows of
/// `k` / `v` starting at row `tails[i]` (a push's rows, read by its
/// queries from the step scratch, kept once they ran).
fn append_tails(
    lats: &mut [&mut LatStream<'_>],
    counts: &[usize],
    tails: &[usize],
    l: usize,
    k: &[f32],
    v: &[f32],
    c: usize,
) -> Result<(), Error> {
    for ((lat, &cnt), &t) in lats.iter_mut().zip(counts).zip(tails) {
        for j in t..t + cnt {
            let r = j * c..(j + 1) * c;
            lat.k[l].push(k.get(r.clone()).ok_or(Error::State)?)?;
            lat.v[l].push(v.get(r).ok_or(Error::State)?)?;
        }
    }
    Ok(())
}

/// Keys a query of one LAT may see at most (the attention scratch size).
pub fn max_keys(past: usize, fut: usize) -> usize {
    past + fut + 1
}

/// State of one LAT in a session.
pub struct LatStream<'s> {
    /// Per layer: keys and values of the last `past` positions (layer 1:
    /// `past + fut`; at least 1) before a push's, rings of (cap, C) in the
    /// session's `KvType`. A push's own rows are read from the step
    /// scratch (rounded as stored) and appended once its queries ran.
    k: Vec<KvRing<'s>, { MAX_LAT_LAYERS as usize }>,
    v: Vec<KvRing<'s>, { MAX_LAT_LAYERS as usize }>,
    /// The last `fut + burst` positions' layer-1 inputs (a query waits
    /// `fut` positions for its keys), as [`Held`]: token ids (the leader
    /// LATs), (fut + burst, n_in) input rows narrower than C (the music
    /// LAT's 54-wide frames; `cond_emb` is applied again when the query
    /// runs, row by row the same numbers), else (fut + burst, C) the
    /// residual rows `cond_emb(x)` themselves.
    h0: Held<'s>,
    /// (ds - 1, C) last-layer outputs of the output row being assembled
    /// (its last position's goes straight into the downsample's input).
    last: &'s mut [f32],
    past: usize,
    fut: usize,
    ds: usize,
    c: usize,
    /// Most positions one push carries.
    burst: usize,
    /// Positions pushed so far.
    pushed: usize,
    /// Output rows produced so far.
    rows: usize,
}

impl<'s> LatStream<'s> {
    /// `past`, `fut`: band in LAT input units; `kv`: K/V storage type;
    /// `burst` (>= 1): most positions one push carries; `input`: what the
    /// LAT's inputs are (rows held as rows where narrower than C, else as
    /// residual rows; tokens held as ids).
    #[allow(clippy::too_many_arguments)]
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        kv: KvType,
        w_layers: usize,
        ds: usize,
        c: usize,
        input: LatIn,
        past: usize,
        fut: usize,
        burst: usize,
    ) -> Result<Self, ArenaError> {
        let burst = burst.clamp(1, ds.max(1));
        let mut k = Vec::new();
        let mut v = Vec::new();
        for l in 0..w_layers {
            // A push's own rows are read from the step scratch
            // (`push_many`), so a ring holds only the rows before them
            // that a query of the push may see.
            let cap = (past + if l == 0 { fut } else { 0 }).max(1);
            k.push(KvRing::carve(a, kv, cap, c)?)
                .map_err(|_| ArenaError::Overflow)?;
            v.push(KvRing::carve(a, kv, cap, c)?)
                .map_err(|_| ArenaError::Overflow)?;
        }
        Ok(LatStream {
            k,
            v,
            h0: match input {
                LatIn::Tokens => Held::Tokens(TokenRing::carve(a, fut + burst, 1)?),
                LatIn::Rows(n_in) if n_in < c => {
                    Held::Inputs(RowRing::carve(a, fut + burst, n_in)?)
                }
                LatIn::Rows(_) => Held::Residuals(RowRing::carve(a, fut + burst, c)?),
            },
            last: a.f32(
                ds.saturating_sub(1)
                    .checked_mul(c)
                    .ok_or(ArenaError::Overflow)?,
            )?,
            past,
            fut,
            ds,
            c,
            burst,
            pushed: 0,
            rows: 0,
        })
    }

    pub fn reset(&mut self) {
        for r in self.k.iter_mut().chain(self.v.iter_mut()) {
            r.clear();
        }
        match &mut self.h0 {
            Held::Inputs(r) | Held::Residuals(r) => r.clear(),
            Held::Tokens(t) => t.clear(),
        }
        self.pushed = 0;
        self.rows = 0;
    }

    /// Positions pushed so far.
    pub fn pushed(&self) -> usize {
        self.pushed
    }

    /// Output rows produced so far (row `j` is produced when position
    /// `ds j + ds - 1 + fut` is pushed).
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Positions still to push before output row `row` exists (row `j` is
    /// produced when position `ds j + ds - 1 + fut` is pushed).
    pub fn pushes_before_row(&self, row: usize) -> usize {
        (self.ds * (row + 1) + self.fut).saturating_sub(self.pushed)
    }

    /// Most positions one push may carry (`burst`, at most `ds`: a push
    /// completes at most one output row).
    pub fn burst(&self) -> usize {
        self.burst
    }

    /// Pushes `counts[i]` consecutive input positions into `lats[i]`, for
    /// several LATs with the same weights `w` (one per session of a batch):
    /// `inputs` holds LAT 0's positions, then LAT 1's, ... (rows `n_in`
    /// wide, or token ids and their table). Where a push completes an
    /// output row, it is written to row `i` of `out` (n, C) and
    /// `produced[i]` is set (else cleared). Every weight matrix is read once
    /// for all positions; each LAT's result is what pushing its positions
    /// one at a time would give.
    #[allow(clippy::too_many_arguments)]
    pub fn push_many(
        w: &LatW<'_>,
        lats: &mut [&mut LatStream<'_>],
        counts: &[usize],
        inputs: LatInputs<'_, '_>,
        s: &mut LatStepScratch<'_>,
        blk: &mut BlockScratch<'_>,
        out: &mut [f32],
        produced: &mut [bool],
    ) -> Result<(), Error> {
        let n = lats.len();
        let Some(first) = lats.first() else {
            return Ok(());
        };
        let (c, ds) = (first.c, first.ds);
        let n_head = w.cfg.n_head as usize;
        let n_in = w.cond_emb.w.cols();
        let total: usize = counts.iter().sum();
        check_len(Buffer::Features, counts.len(), n)?;
        match inputs {
            LatInputs::Rows(x) => check_len(Buffer::Features, x.len(), total * n_in)?,
            LatInputs::Tokens(ids, table) => {
                check_len(Buffer::Tokens, ids.len(), total)?;
                check_len(Buffer::Features, table.cols(), n_in)?;
                if let Some(&id) = ids.iter().find(|&&id| id as usize >= table.rows()) {
                    return Err(Error::Token {
                        stream: 0,
                        token: id,
                        vocab: table.rows().min(u32::MAX as usize) as u32,
                    });
                }
            }
        }
        check_len(Buffer::Output, out.len(), n * c)?;
        check_len(Buffer::Output, produced.len(), n)?;
        if n > s.n
            || n > MAX_BATCH
            || total > s.rows
            || total > MAX_LAT_ROWS
            || total.saturating_mul(2 * n_in) > s.xin.len()
        {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: total,
                expected: s.rows.min(MAX_LAT_ROWS),
            });
        }
        for (lat, &cnt) in lats.iter().zip(counts) {
            if w.blocks.len() != lat.k.len()
                || w.blocks.is_empty()
                || lat.c != c
                || w.cond_emb.w.rows() != c
            {
                return Err(Error::Length {
                    buffer: Buffer::Features,
                    len: w.blocks.len(),
                    expected: lat.k.len(),
                });
            }
            if cnt > lat.burst {
                return Err(Error::Length {
                    buffer: Buffer::Features,
                    len: cnt,
                    expected: lat.burst,
                });
            }
            // What a LAT holds must be what it is given: rows of its width, or tokens.
            let fits = match (&lat.h0, inputs) {
                (Held::Inputs(r), LatInputs::Rows(_)) => r.width() == n_in,
                (Held::Tokens(_), LatInputs::Tokens(..)) | (Held::Residuals(_), _) => true,
                _ => false,
            };
            if !fits {
                return Err(Error::Length {
                    buffer: Buffer::Features,
                    len: n_in,
                    expected: c,
                });
            }
        }
        produced.fill(false);
        // The new positions held; the positions whose layer-1 keys are then
        // all present: (index into `lats`, position), each LAT's in order.
        let mut ready: Vec<(usize, usize), MAX_LAT_ROWS> = Vec::new();
        let mut row = 0;
        for (i, (lat, &cnt)) in lats.iter_mut().zip(counts).enumerate() {
            for _ in 0..cnt {
                match (&mut lat.h0, inputs) {
                    (Held::Inputs(h0), LatInputs::Rows(x)) => {
                        h0.push(&x[row * n_in..(row + 1) * n_in])?
                    }
                    (Held::Tokens(h0), LatInputs::Tokens(ids, _)) => h0.push(&ids[row..row + 1])?,
                    // Residual rows are held once computed, below.
                    _ => {}
                }
                lat.pushed += 1;
                row += 1;
                if let Some(p) = lat.pushed.checked_sub(1 + lat.fut) {
                    ready.push((i, p)).map_err(|_| Error::State)?;
                }
            }
        }
        // (total + again, n_in) inputs: the new positions', then those of the
        // ready positions whose residual rows are not held (`again` of them).
        let tc = total * c;
        let xin = &mut s.xin[..];
        for j in 0..total {
            inputs.row_into(j, &mut xin[j * n_in..(j + 1) * n_in]);
        }
        let mut again = 0;
        for &(i, p) in ready.iter() {
            let x = &mut xin[(total + again) * n_in..(total + again + 1) * n_in];
            match (&lats[i].h0, inputs) {
                (Held::Inputs(h0), _) => x.copy_from_slice(h0.row(p)?),
                (Held::Tokens(h0), LatInputs::Tokens(_, table)) => {
                    table.row_into(h0.row(p)?[0] as usize, x)
                }
                _ => continue,
            }
            again += 1;
        }
        // One `cond_emb` for both: (total + again, C) layer-1 residual rows
        // (row by row what each alone gives), then the new positions'
        // keys and values.
        linear(
            &xin[..(total + again) * n_in],
            &w.cond_emb.w,
            w.cond_emb.b,
            &mut s.h[..tc + again * c],
        );
        block_kv(
            &w.blocks[0],
            &s.h[..tc],
            &mut s.ln[..tc],
            &mut s.k[..tc],
            &mut s.v[..tc],
        );
        // Per LAT: where its rows of the layer being run start in `s.k` /
        // `s.v` (layer 1: its new positions; later layers: its ready ones).
        let mut tails: Vec<usize, MAX_BATCH> = Vec::new();
        hold_tails(
            lats,
            counts,
            0,
            &mut s.k[..tc],
            &mut s.v[..tc],
            c,
            &mut tails,
        )?;
        let mut row = 0;
        for (lat, &cnt) in lats.iter_mut().zip(counts) {
            for _ in 0..cnt {
                if let Held::Residuals(h0) = &mut lat.h0 {
                    h0.push(&s.h[row * c..(row + 1) * c])?;
                }
                row += 1;
            }
        }
        let r = ready.len();
        if r == 0 {
            return append_tails(lats, counts, &tails, 0, &s.k[..tc], &s.v[..tc], c);
        }
        // (r, C) the ready positions, one row (= one attention group) each,
        // moved to the front in order. Row g comes from row total + (its
        // index among the recomputed) >= g, or from the held residuals.
        let rc = r * c;
        let mut from = total;
        for (g, &(i, p)) in ready.iter().enumerate() {
            if let Held::Residuals(h0) = &lats[i].h0 {
                s.h[g * c..(g + 1) * c].copy_from_slice(h0.row(p)?);
            } else {
                s.h.copy_within(from * c..(from + 1) * c, g * c);
                from += 1;
            }
        }
        let mut bounds: Vec<usize, { MAX_LAT_ROWS + 1 }> = Vec::new();
        for g in 0..=r {
            bounds.push(g).map_err(|_| Error::State)?;
        }
        // Ready positions per LAT (each LAT's are consecutive in `ready`).
        let mut readies: Vec<usize, MAX_BATCH> = Vec::new();
        for i in 0..n {
            readies
                .push(ready.iter().filter(|&&(j, _)| j == i).count())
                .map_err(|_| Error::State)?;
        }
        for (l, b) in w.blocks.iter().enumerate() {
            if l > 0 {
                block_kv(
                    b,
                    &s.h[..rc],
                    &mut s.ln[..rc],
                    &mut s.k[..rc],
                    &mut s.v[..rc],
                );
                hold_tails(
                    lats,
                    &readies,
                    l,
                    &mut s.k[..rc],
                    &mut s.v[..rc],
                    c,
                    &mut tails,
                )?;
            }
            // The layer's new rows: `s.k` / `s.v` rows `tails[i]..` of LAT i
            // (layer 1: `total` of them; later layers: `r`).
            let nt = if l == 0 { total } else { r };
            {
                let lats_ro: &[&mut LatStream<'_>] = lats;
                let (tk, tv) = (&s.k[..nt * c], &s.v[..nt * c]);
                let tails = &tails;
                let keys = |g: usize| {
                    let (i, p) = ready[g];
                    let lat = &lats_ro[i];
                    let lo = p.saturating_sub(lat.past);
                    let hi = p + 1 + if l == 0 { lat.fut } else { 0 };
                    // Rows before the ring's end from the ring, the rest
                    // from this push's rows.
                    let held = lat.k[l].len();
                    let (a, e) = (lo.min(held), hi.min(held));
                    let (t0, t1) = (
                        tails[i] + lo.max(held) - held,
                        tails[i] + hi.max(held) - held,
                    );
                    Ok((
                        with_tail(lat.k[l].rows(a, e)?, tk, t0, t1, c)?,
                        with_tail(lat.v[l].rows(a, e)?, tv, t0, t1, c)?,
                        Visible,
                    ))
                };
                block_attend_groups(b, &mut s.h[..rc], &bounds, c, n_head, keys, blk)?;
            }
            let counts_l: &[usize] = if l == 0 { counts } else { &readies };
            append_tails(lats, counts_l, &tails, l, &s.k[..nt * c], &s.v[..nt * c], c)?;
        }
        // Last-layer rows into each LAT's output row; the complete ones,
        // (ds, C) viewed as one row of ds*C, go through the downsample.
        let mut done: Vec<usize, MAX_BATCH> = Vec::new();
        for (g, &(i, p)) in ready.iter().enumerate() {
            let lat = &mut lats[i];
            if lat.ds != ds {
                return Err(Error::Length {
                    buffer: Buffer::Features,
                    len: lat.ds,
                    expected: ds,
                });
            }
            let slot = p % ds;
            let h = &s.h[g * c..(g + 1) * c];
            if slot + 1 < ds {
                lat.last[slot * c..(slot + 1) * c].copy_from_slice(h);
            } else {
                if done.contains(&i) {
                    // Two output rows from one push (counts above `ds`).
                    return Err(Error::State);
                }
                let d = done.len();
                let cat = &mut s.cat[d * ds * c..(d + 1) * ds * c];
                let (held, own) = cat.split_at_mut(slot * c);
                held.copy_from_slice(lat.last);
                own.copy_from_slice(h);
                done.push(i).map_err(|_| Error::State)?;
            }
        }
        let d = done.len();
        if d == 0 {
            return Ok(());
        }
        let y = &mut s.k[..d * c];
        linear(&s.cat[..d * ds * c], &w.downsample.w, w.downsample.b, y);
        for (j, &i) in done.iter().enumerate() {
            out[i * c..(i + 1) * c].copy_from_slice(&y[j * c..(j + 1) * c]);
            produced[i] = true;
            lats[i].rows += 1;
        }
        Ok(())
    }
}
