//! The coordinated attention under S (docs/STREAMING.md §3.5): the GPT's
//! base and head blocks over one chunked window, with a per-layer K/V
//! cache. Within a window (fixed start `lo`) the inputs of every cached
//! row are unchanged and the mask is causal in rows, so appending the new
//! row computes exactly what the full window forward computes; when the
//! window start moves, the cache is cleared and the window re-prefilled.
//!
//! Layout: position-major, row `i * 10 + s` = window row `i`, stream `s`
//! (`[music, L_up, L_down, L_lh, L_rh, F_up, F_down, F_lh, F_rh, F_transl]`).

use crate::arena::{ArenaError, Carve};
use crate::block::{block_attend, block_kv, BlockScratch};
use crate::coordinated_attention::{FIRST_FOLLOWER_STREAM, FOLLOWER_STREAMS};
use crate::error::{Buffer, Error};
use crate::kernels::Mask;
use crate::model::GptW;

/// Causal over window rows for a position-major layout: query row `qi`
/// (flat index `q_row0 + qi`) sees every key whose window row is not later.
struct RowCausal {
    streams: usize,
    q_row0: usize,
}

impl Mask for RowCausal {
    #[inline]
    fn allowed(&self, qi: usize, kj: usize) -> bool {
        kj / self.streams <= (self.q_row0 + qi) / self.streams
    }
}

/// Per-layer K/V of the current window.
pub struct GptCache<'s> {
    /// (layers, streams * m, C) keys and values, position-major.
    k: &'s mut [f32],
    v: &'s mut [f32],
    layers: usize,
    streams: usize,
    /// Window rows a cache holds (`block_size - 1`).
    m: usize,
    c: usize,
    /// Window rows cached.
    rows: usize,
    /// Start (token index) of the cached window; None when empty.
    lo: Option<usize>,
}

impl<'s> GptCache<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, layers: usize, streams: usize, m: usize, c: usize) -> Result<Self, ArenaError> {
        let n = layers.checked_mul(streams).and_then(|v| v.checked_mul(m)).and_then(|v| v.checked_mul(c)).ok_or(ArenaError::Overflow)?;
        Ok(GptCache { k: a.f32(n)?, v: a.f32(n)?, layers, streams, m, c, rows: 0, lo: None })
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

    /// Appends `n` window rows `x` (n * streams, C) (inputs with position
    /// rows added) and runs every layer over them. With `need_output`, on
    /// return the last `FOLLOWER_STREAMS` rows of `x` hold the final hidden
    /// state of the follower streams at the last new row (what the heads
    /// read); without it the last layer's attention and MLP are skipped
    /// (only its K/V are kept). Other rows of `x` are scratch.
    pub fn append(&mut self, gpt: &GptW<'_>, n_head: usize, x: &mut [f32], need_output: bool, s: &mut BlockScratch<'_>) -> Result<(), Error> {
        let (st, c) = (self.streams, self.c);
        let n = x.len() / (st * c).max(1);
        if n == 0 || x.len() != n * st * c || self.rows + n > self.m || gpt.base.len() + gpt.head.len() != self.layers {
            return Err(Error::Context { c: self.rows + n, max: self.m });
        }
        let per_layer = st * self.m * c;
        let (r0, r1) = (self.rows * st, (self.rows + n) * st);
        for (l, b) in gpt.base.iter().chain(gpt.head.iter()).enumerate() {
            let kl = &mut self.k[l * per_layer..(l + 1) * per_layer];
            let vl = &mut self.v[l * per_layer..(l + 1) * per_layer];
            block_kv(b, x, s.ln, &mut kl[r0 * c..r1 * c], &mut vl[r0 * c..r1 * c]);
            let (kr, vr) = (&kl[..r1 * c], &vl[..r1 * c]);
            if l + 1 < self.layers {
                block_attend(b, x, kr, vr, c, n_head, &RowCausal { streams: st, q_row0: r0 }, s);
            } else if need_output {
                // Last layer: only the follower rows of the last new row are read.
                let q0 = r1 - FOLLOWER_STREAMS;
                let xs = &mut x[(q0 - r0) * c..];
                block_attend(b, xs, kr, vr, c, n_head, &RowCausal { streams: st, q_row0: q0 }, s);
            }
        }
        self.rows += n;
        Ok(())
    }
}

/// Checks the stream layout this module assumes.
pub fn check_layout(streams: usize) -> Result<(), Error> {
    if streams != FIRST_FOLLOWER_STREAM + FOLLOWER_STREAMS {
        return Err(Error::Length { buffer: Buffer::Features, len: streams, expected: FIRST_FOLLOWER_STREAM + FOLLOWER_STREAMS });
    }
    Ok(())
}
