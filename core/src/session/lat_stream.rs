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

use heapless::Vec;

use crate::arena::{ArenaError, Carve};
use crate::block::{block_attend, block_kv, BlockScratch};
use crate::error::{check_len, Buffer, Error};
use crate::kernels::{linear, Mask};
use crate::limits::MAX_LAT_LAYERS;
use crate::model::LatW;
use crate::session::ring::RowRing;

/// Every key handed to the attention is visible (the band is applied by
/// choosing the key rows).
pub struct Visible;

impl Mask for Visible {
    #[inline]
    fn allowed(&self, _: usize, _: usize) -> bool {
        true
    }
}

/// Per-step working memory shared by all LATs of a session.
pub struct LatStepScratch<'s> {
    /// (C) the position being pushed / processed.
    pub h: &'s mut [f32],
    /// (C) its K and V.
    pub k: &'s mut [f32],
    pub v: &'s mut [f32],
    /// (C) LayerNorm output.
    pub ln: &'s mut [f32],
    /// (ds_max * C) concatenated last-layer rows.
    pub cat: &'s mut [f32],
}

impl<'s> LatStepScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, c: usize, ds_max: usize) -> Result<Self, ArenaError> {
        Ok(LatStepScratch {
            h: a.f32(c)?,
            k: a.f32(c)?,
            v: a.f32(c)?,
            ln: a.f32(c)?,
            cat: a.f32(ds_max.checked_mul(c).ok_or(ArenaError::Overflow)?)?,
        })
    }
}

/// Keys a query of one LAT may see at most (the attention scratch size).
pub fn max_keys(past: usize, fut: usize) -> usize {
    past + fut + 1
}

/// State of one LAT in a session.
pub struct LatStream<'s> {
    /// Per layer: keys and values of the last `past + 1` positions (layer
    /// 1: `past + fut + 1`), mirrored rings of (cap, C).
    k: Vec<RowRing<'s>, { MAX_LAT_LAYERS as usize }>,
    v: Vec<RowRing<'s>, { MAX_LAT_LAYERS as usize }>,
    /// (fut + 1, C) residual inputs of layer 1 (a query waits `fut`
    /// positions for its keys).
    h0: RowRing<'s>,
    /// (ds, C) last-layer outputs of the output row being assembled.
    last: &'s mut [f32],
    past: usize,
    fut: usize,
    ds: usize,
    c: usize,
    /// Positions pushed so far.
    pushed: usize,
    /// Output rows produced so far.
    rows: usize,
}

impl<'s> LatStream<'s> {
    /// `past`, `fut`: band in LAT input units.
    pub fn carve<A: Carve<'s>>(a: &mut A, w_layers: usize, ds: usize, c: usize, past: usize, fut: usize) -> Result<Self, ArenaError> {
        let mut k = Vec::new();
        let mut v = Vec::new();
        for l in 0..w_layers {
            let cap = past + 1 + if l == 0 { fut } else { 0 };
            k.push(RowRing::carve(a, cap, c)?).map_err(|_| ArenaError::Overflow)?;
            v.push(RowRing::carve(a, cap, c)?).map_err(|_| ArenaError::Overflow)?;
        }
        Ok(LatStream {
            k,
            v,
            h0: RowRing::carve_plain(a, fut + 1, c)?,
            last: a.f32(ds.checked_mul(c).ok_or(ArenaError::Overflow)?)?,
            past,
            fut,
            ds,
            c,
            pushed: 0,
            rows: 0,
        })
    }

    pub fn reset(&mut self) {
        for r in self.k.iter_mut().chain(self.v.iter_mut()) {
            r.clear();
        }
        self.h0.clear();
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

    /// Pushes one input position `x` (n_in). When it completes an output
    /// row, writes it to `out` (C) and returns `Ok(true)`.
    pub fn push(&mut self, w: &LatW<'_>, x: &[f32], s: &mut LatStepScratch<'_>, blk: &mut BlockScratch<'_>, out: &mut [f32]) -> Result<bool, Error> {
        let c = self.c;
        let n_head = w.cfg.n_head as usize;
        check_len(Buffer::Features, x.len(), w.cond_emb.w.cols())?;
        check_len(Buffer::Output, out.len(), c)?;
        if w.blocks.len() != self.k.len() || w.blocks.is_empty() {
            return Err(Error::Length { buffer: Buffer::Features, len: w.blocks.len(), expected: self.k.len() });
        }
        // Layer-1 input of the new position, and its key/value.
        linear(x, &w.cond_emb.w, w.cond_emb.b, s.h);
        block_kv(&w.blocks[0], s.h, s.ln, s.k, s.v);
        self.k[0].push(s.k)?;
        self.v[0].push(s.v)?;
        self.h0.push(s.h)?;
        self.pushed += 1;
        // The position whose layer-1 keys are now all present.
        let Some(p) = self.pushed.checked_sub(1 + self.fut) else { return Ok(false) };
        s.h.copy_from_slice(self.h0.row(p)?);
        let lo = p.saturating_sub(self.past);
        for (l, b) in w.blocks.iter().enumerate() {
            if l > 0 {
                block_kv(b, s.h, s.ln, s.k, s.v);
                self.k[l].push(s.k)?;
                self.v[l].push(s.v)?;
            }
            let hi = p + 1 + if l == 0 { self.fut } else { 0 };
            let (kr, vr) = (self.k[l].rows(lo, hi)?, self.v[l].rows(lo, hi)?);
            block_attend(b, s.h, kr, vr, c, n_head, &Visible, blk);
        }
        let slot = p % self.ds;
        self.last[slot * c..(slot + 1) * c].copy_from_slice(s.h);
        if slot + 1 < self.ds {
            return Ok(false);
        }
        // (ds, C) viewed as one row of ds*C.
        let cat = &mut s.cat[..self.ds * c];
        cat.copy_from_slice(self.last);
        linear(cat, &w.downsample.w, w.downsample.b, out);
        self.rows += 1;
        Ok(true)
    }
}
