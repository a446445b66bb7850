//! The pre-LN transformer block shared by the LATs (`MusicBlock`, band
//! mask) and the coordinated attention (`Block`, tiled causal mask):
//! `x += proj(attn(ln1 x)); x += mlp.2(gelu(mlp.0(ln2 x)))`.

use crate::arena::{ArenaError, Carve};
use crate::error::{Buffer, Error};
use crate::kernels::{
    attention, attention_ahead, attention_band, attention_staircase, layernorm, linear_each,
    linear_each_with, linear_gelu_with, linear_with, GemmMask, KvRows, Mask, Q8Room,
};
use crate::nn::weights::{BlockW, Linear};

/// Working memory of one block over at most `rows` rows of width `c`.
///
/// The MLP hidden rows reuse the memory of the query, key and value rows:
/// those are dead once the attention has run, before the MLP starts. The
/// MLP output reuses `ln` (dead once the hidden rows are computed). A
/// streaming session's scratch ([`BlockScratch::carve_keys`]) has no `att`:
/// [`block_attend_groups`] writes the attention output over `ln` (dead once
/// the queries are computed) and the projection over the queries.
#[derive(Default)]
pub struct BlockScratch<'s> {
    /// (rows, C) LayerNorm output, then projection output (R mode), or
    /// attention output (a session's groups); the MLP output.
    pub ln: &'s mut [f32],
    /// (rows, C) attention output (R mode's `block_forward`,
    /// `block_forward_rows`); empty in a session's scratch.
    pub att: &'s mut [f32],
    /// (rows, 4C): query | key | value, (rows, C) each, during the
    /// attention; the MLP hidden rows (rows, 4C) after it.
    work: &'s mut [f32],
    /// (max(rows, keys)) attention scores of one query.
    pub scores: &'s mut [f32],
    /// (rows, 4C) int8 activation rows of the block's GEMMs, quantised at
    /// once ([`linear_with`]; R mode's windows); empty in a streaming
    /// session, whose GEMMs take the stack panel.
    pub panel: Q8Room<'s>,
    pub rows: usize,
}

/// The parts of a [`BlockScratch`] live during the attention, each
/// `(rows, C)` (the caller takes the prefixes it needs).
pub struct QkvParts<'a> {
    pub ln: &'a mut [f32],
    pub q: &'a mut [f32],
    pub k: &'a mut [f32],
    pub v: &'a mut [f32],
    pub att: &'a mut [f32],
    pub scores: &'a mut [f32],
    pub panel: Q8Room<'a>,
}

impl<'s> BlockScratch<'s> {
    /// For blocks over at most `rows` rows whose queries see at most `rows`
    /// keys, with an int8 panel for all of them (R mode: a whole window's
    /// rows are quantised once per GEMM, each weight tile read once).
    pub fn carve<A: Carve<'s>>(a: &mut A, rows: usize, c: usize) -> Result<Self, ArenaError> {
        let mut s = Self::carve_keys(a, rows, rows, c)?;
        s.att = a.f32(rows.checked_mul(c).ok_or(ArenaError::Overflow)?)?;
        let values = rows
            .checked_mul(c)
            .and_then(|v| v.checked_mul(4))
            .ok_or(ArenaError::Overflow)?;
        s.panel = Q8Room::carve(a, values)?;
        Ok(s)
    }
    /// For [`block_attend_groups`] over at most `rows` rows whose queries
    /// see at most `keys` keys (a chunk of rows attending a longer cache):
    /// a streaming session's, without `att` (the attention output goes
    /// over `ln`).
    pub fn carve_keys<A: Carve<'s>>(
        a: &mut A,
        rows: usize,
        keys: usize,
        c: usize,
    ) -> Result<Self, ArenaError> {
        let rc = rows.checked_mul(c).ok_or(ArenaError::Overflow)?;
        Ok(BlockScratch {
            ln: a.f32(rc)?,
            att: &mut [],
            work: a.f32(rc.checked_mul(4).ok_or(ArenaError::Overflow)?)?,
            scores: a.f32(rows.max(keys))?,
            panel: Q8Room::default(),
            rows,
        })
    }

    /// Floats of one (rows, C) buffer.
    pub fn row_floats(&self) -> usize {
        self.ln.len()
    }

    /// The attention-phase buffers (query, key and value over the work region).
    pub fn qkv(&mut self) -> QkvParts<'_> {
        let rc = self.ln.len();
        let (q, rest) = self.work.split_at_mut(rc);
        let (k, rest) = rest.split_at_mut(rc);
        QkvParts {
            ln: self.ln,
            q,
            k,
            v: &mut rest[..rc],
            att: self.att,
            scores: self.scores,
            panel: self.panel.reborrow(),
        }
    }

    /// The MLP-phase buffers: LayerNorm output (then the MLP output), hidden rows (rows, 4C), int8 panel.
    fn mlp_parts(&mut self) -> (&mut [f32], &mut [f32], Q8Room<'_>) {
        (self.ln, self.work, self.panel.reborrow())
    }
}

/// R mode's attention as per-head GEMMs where the mask allows
/// ([`Mask::gemm`]: a whole window's coordinated attention, a LAT's band),
/// over `work`; false: the caller runs [`attention`].
#[allow(clippy::too_many_arguments)]
fn attention_as_gemms<M: Mask>(
    q: &[f32],
    k: &[f32],
    v: &[f32],
    c: usize,
    n_head: usize,
    mask: &M,
    work: &mut [f32],
    out: &mut [f32],
) -> bool {
    match mask.gemm() {
        Some(GemmMask::Staircase(t)) => attention_staircase(q, k, v, c, n_head, t, work, out),
        Some(GemmMask::Band(r)) => attention_band(q, k, v, c, n_head, r, work, out),
        None => false,
    }
}

fn lin(x: &[f32], l: &Linear<'_>, y: &mut [f32], panel: &mut Q8Room<'_>) {
    linear_with(x, &l.w, l.b, y, panel);
}

fn add(x: &mut [f32], y: &[f32]) {
    for (a, b) in x.iter_mut().zip(y) {
        *a += b;
    }
}

/// One block over all rows of `x` (n, C) in place; `n <= s.rows` (callers
/// size the scratch). `mask` relates query row i to key row j of `x`.
pub fn block_forward<M: Mask>(
    w: &BlockW<'_>,
    x: &mut [f32],
    c: usize,
    n_head: usize,
    mask: &M,
    s: &mut BlockScratch<'_>,
) {
    let nc = x.len();
    let n = nc / c;
    let mut p = s.qkv();
    let (ln, q, k, v, att) = (
        &mut p.ln[..nc],
        &mut p.q[..nc],
        &mut p.k[..nc],
        &mut p.v[..nc],
        &mut p.att[..nc],
    );
    layernorm(x, w.ln1.w, w.ln1.b, ln);
    linear_each_with(
        ln,
        [&w.query.w, &w.key.w, &w.value.w],
        [w.query.b, w.key.b, w.value.b],
        [q, k, v],
        &mut p.panel,
    );
    // As GEMMs where the mask allows, over `ln` (dead until the projection
    // writes it).
    if !attention_as_gemms(q, k, v, c, n_head, mask, ln, att) {
        attention(q, k, v, c, n_head, mask, &mut p.scores[..n], att);
    }
    lin(att, &w.proj, ln, &mut p.panel);
    add(x, ln);
    mlp(w, x, s, nc);
}

/// `x += mlp.2(gelu(mlp.0(ln2 x)))` over the first `nc` floats of the
/// scratch's MLP buffers (`x`: (n, C), `nc = n * C`).
fn mlp(w: &BlockW<'_>, x: &mut [f32], s: &mut BlockScratch<'_>, nc: usize) {
    let (ln, hid, mut panel) = s.mlp_parts();
    let (ln, hid) = (&mut ln[..nc], &mut hid[..4 * nc]);
    layernorm(x, w.ln2.w, w.ln2.b, ln);
    // GELU as the GEMM writes each output segment (`linear_gelu_with`: the same bits as after it).
    linear_gelu_with(ln, &w.fc.w, w.fc.b, hid, &mut panel);
    // The output over `ln`, dead once the hidden rows exist.
    lin(hid, &w.fc_out, ln, &mut panel);
    add(x, ln);
}

/// The block's output for selected query rows only (keys and values from
/// every row of `x` (n, C)): `out` (rows.len(), C). `mask` relates query
/// `i` (index into `rows`) to key row `j` of `x`. Used for the last GPT
/// layer, where only the last position of each follower stream is read.
#[allow(clippy::too_many_arguments)]
pub fn block_forward_rows<M: Mask>(
    w: &BlockW<'_>,
    x: &[f32],
    rows: &[usize],
    c: usize,
    n_head: usize,
    mask: &M,
    s: &mut BlockScratch<'_>,
    out: &mut [f32],
) {
    block_forward_selected(w, x, Queried::Rows(rows), c, n_head, mask, s, out)
}

/// [`block_forward_rows`] for the first `r` rows of `x` (a LAT's last
/// layer, whose rows past the kept outputs only serve as keys and values):
/// each kept row's numbers are [`block_forward`]'s, bit for bit (every
/// GEMM, LayerNorm and attention query is row by row).
#[allow(clippy::too_many_arguments)]
pub fn block_forward_prefix<M: Mask>(
    w: &BlockW<'_>,
    x: &[f32],
    r: usize,
    c: usize,
    n_head: usize,
    mask: &M,
    s: &mut BlockScratch<'_>,
    out: &mut [f32],
) {
    block_forward_selected(w, x, Queried::First(r), c, n_head, mask, s, out)
}

/// The query rows of [`block_forward_selected`].
#[derive(Clone, Copy)]
enum Queried<'r> {
    /// Rows `0..r` (the attention may run as GEMMs, [`attention_as_gemms`]).
    First(usize),
    /// These rows, in this order.
    Rows(&'r [usize]),
}

impl Queried<'_> {
    fn len(self) -> usize {
        match self {
            Queried::First(r) => r,
            Queried::Rows(rows) => rows.len(),
        }
    }
    /// The row of `x` of query `i`.
    fn row(self, i: usize) -> usize {
        match self {
            Queried::First(_) => i,
            Queried::Rows(rows) => rows[i],
        }
    }
}

/// The body of [`block_forward_rows`] / [`block_forward_prefix`].
#[allow(clippy::too_many_arguments)]
fn block_forward_selected<M: Mask>(
    w: &BlockW<'_>,
    x: &[f32],
    queried: Queried<'_>,
    c: usize,
    n_head: usize,
    mask: &M,
    s: &mut BlockScratch<'_>,
    out: &mut [f32],
) {
    let nc = x.len();
    let n = nc / c;
    let r = queried.len();
    let rc = r * c;
    let mut p = s.qkv();
    let (ln, q, k, v, att) = (
        &mut p.ln[..nc],
        &mut p.q[..rc],
        &mut p.k[..nc],
        &mut p.v[..nc],
        &mut p.att[..nc],
    );
    layernorm(x, w.ln1.w, w.ln1.b, ln);
    linear_each_with(
        ln,
        [&w.key.w, &w.value.w],
        [w.key.b, w.value.b],
        [k, v],
        &mut p.panel,
    );
    // Gather the selected rows of ln1(x) and of x.
    for i in 0..r {
        let (a, b) = (queried.row(i) * c, (queried.row(i) + 1) * c);
        att[i * c..(i + 1) * c].copy_from_slice(&ln[a..b]);
        out[i * c..(i + 1) * c].copy_from_slice(&x[a..b]);
    }
    lin(&att[..rc], &w.query, q, &mut p.panel);
    let att_sel = &mut att[..rc];
    // `ln` is dead until the projection writes it (its rows are in `att`).
    let first = matches!(queried, Queried::First(_));
    if !(first && attention_as_gemms(q, k, v, c, n_head, mask, ln, att_sel)) {
        attention(q, k, v, c, n_head, mask, &mut p.scores[..n], att_sel);
    }
    let proj = &mut ln[..rc];
    lin(att_sel, &w.proj, proj, &mut p.panel);
    add(&mut out[..rc], proj);
    mlp(w, &mut out[..rc], s, rc);
}

/// Keys and values of rows `x` (n, C): `k`, `v` (n, C) = key/value(ln1 x).
/// `ln`: >= n * C scratch. Used by the streaming session, whose caches
/// hold every row's K/V once computed.
pub fn block_kv(w: &BlockW<'_>, x: &[f32], ln: &mut [f32], k: &mut [f32], v: &mut [f32]) {
    let ln = &mut ln[..x.len()];
    layernorm(x, w.ln1.w, w.ln1.b, ln);
    linear_each(ln, [&w.key.w, &w.value.w], [w.key.b, w.value.b], [k, v]);
}

/// The rest of a block for groups of new rows in place, given the keys
/// and values each group may attend to: for every group `g`,
/// `x_g += proj(attn(query(ln1 x_g), k_g, v_g)); x_g += mlp(ln2 x_g)`.
///
/// `x` (n, C) holds the groups one after another, group `g` at rows
/// `bounds[g]..bounds[g + 1]` (`bounds`: groups + 1 ascending row offsets,
/// first 0, last n). `keys(g)` gives group g's keys and values
/// ((nk_g, C) each as [`KvRows`], already computed, including the group's own rows where
/// its mask allows) and its mask (query row i of the group, key row j).
/// Groups are independent (one streaming session's window or LAT each);
/// every weight matrix is read once for all of them, and a row's result
/// does not depend on the other groups (the kernels compute rows
/// independently: `linear_rows_do_not_depend_on_the_batch`). While group
/// `g` attends, group `g + 1`'s keys and values (their first run) are
/// prefetched (`attention_ahead`; no number depends on it).
pub fn block_attend_groups<'k, M, F>(
    w: &BlockW<'_>,
    x: &mut [f32],
    bounds: &[usize],
    c: usize,
    n_head: usize,
    keys: F,
    s: &mut BlockScratch<'_>,
) -> Result<(), Error>
where
    M: Mask,
    F: Fn(usize) -> Result<(KvRows<'k>, KvRows<'k>, M), Error>,
{
    let nc = x.len();
    let groups = bounds.len().saturating_sub(1);
    if c == 0
        || !nc.is_multiple_of(c)
        || bounds.first() != Some(&0)
        || bounds.last() != Some(&(nc / c))
        || nc > s.ln.len()
    {
        return Err(Error::Length {
            buffer: Buffer::Features,
            len: nc,
            expected: bounds.last().copied().unwrap_or(0) * c,
        });
    }
    let mut p = s.qkv();
    let (ln, q, scores) = (&mut p.ln[..nc], &mut p.q[..nc], p.scores);
    layernorm(x, w.ln1.w, w.ln1.b, ln);
    lin(ln, &w.query, q, &mut p.panel);
    // `ln` is dead once the queries exist: the attention output goes over
    // it, the projection over the queries (no `att` rows).
    let att = ln;
    for g in 0..groups {
        let (a, b) = (bounds[g], bounds[g + 1]);
        if b < a {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: a,
                expected: b,
            });
        }
        let (k, v, mask) = keys(g)?;
        let nk = k.rows(c);
        if nk > scores.len() {
            return Err(Error::Length {
                buffer: Buffer::Features,
                len: nk,
                expected: scores.len(),
            });
        }
        // The next group's keys and values stream in while this one computes.
        let ahead = if g + 1 < groups {
            keys(g + 1).map(|(k, v, _)| [k.lead_bytes(), v.lead_bytes()])?
        } else {
            [&[][..], &[][..]]
        };
        attention_ahead(
            &q[a * c..b * c],
            k,
            v,
            c,
            n_head,
            &mask,
            &mut scores[..nk],
            &mut att[a * c..b * c],
            ahead,
        );
    }
    lin(att, &w.proj, q, &mut p.panel);
    add(x, q);
    mlp(w, x, s, nc);
    Ok(())
}
