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

/// Element type of the K/V cache.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KvType {
    F32,
    /// f16 storage (half the bytes); rows are widened to f32 per layer for
    /// the attention, and a new row's own K/V is rounded the same way.
    F16,
}

/// (layers, streams * m, C) keys or values, position-major, in `KvType`.
enum KvBuf<'s> {
    F32(&'s mut [f32]),
    F16(&'s mut [u16]),
}

impl<'s> KvBuf<'s> {
    fn carve<A: Carve<'s>>(a: &mut A, kv: KvType, n: usize) -> Result<Self, ArenaError> {
        Ok(match kv {
            KvType::F32 => KvBuf::F32(a.f32(n)?),
            KvType::F16 => KvBuf::F16(a.u16(n)?),
        })
    }
}

/// Per-step f32 view of one layer's f16 K/V: (streams * m, C) each.
pub struct KvScratch<'s> {
    pub k: &'s mut [f32],
    pub v: &'s mut [f32],
}

impl<'s> KvScratch<'s> {
    /// Empty for an f32 cache (it is read in place).
    pub fn carve<A: Carve<'s>>(a: &mut A, kv: KvType, streams: usize, m: usize, c: usize) -> Result<Self, ArenaError> {
        let n = match kv {
            KvType::F32 => 0,
            KvType::F16 => streams.checked_mul(m).and_then(|v| v.checked_mul(c)).ok_or(ArenaError::Overflow)?,
        };
        Ok(KvScratch { k: a.f32(n)?, v: a.f32(n)? })
    }
}

/// Stores rows `x` (f32) at `dst` of an f16 buffer and writes the rounded
/// values back to `x` (so every reader sees the same numbers).
fn store_f16(x: &mut [f32], dst: &mut [u16]) {
    for (a, d) in x.iter_mut().zip(dst.iter_mut()) {
        let h = half::f16::from_f32(*a);
        *d = h.to_bits();
        *a = h.to_f32();
    }
}

fn widen_f16(src: &[u16], dst: &mut [f32]) {
    for (s, d) in src.iter().zip(dst.iter_mut()) {
        *d = half::f16::from_bits(*s).to_f32();
    }
}

/// Per-layer K/V of the current window.
pub struct GptCache<'s> {
    k: KvBuf<'s>,
    v: KvBuf<'s>,
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
    pub fn carve<A: Carve<'s>>(a: &mut A, kv: KvType, layers: usize, streams: usize, m: usize, c: usize) -> Result<Self, ArenaError> {
        let n = layers.checked_mul(streams).and_then(|v| v.checked_mul(m)).and_then(|v| v.checked_mul(c)).ok_or(ArenaError::Overflow)?;
        Ok(GptCache { k: KvBuf::carve(a, kv, n)?, v: KvBuf::carve(a, kv, n)?, layers, streams, m, c, rows: 0, lo: None })
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
    /// `kv`: the f32 view scratch of an f16 cache (unused for f32).
    #[allow(clippy::too_many_arguments)]
    pub fn append(&mut self, gpt: &GptW<'_>, n_head: usize, x: &mut [f32], need_output: bool, kv: &mut KvScratch<'_>, s: &mut BlockScratch<'_>) -> Result<(), Error> {
        let (st, c) = (self.streams, self.c);
        let n = x.len() / (st * c).max(1);
        if n == 0 || x.len() != n * st * c || self.rows + n > self.m || gpt.base.len() + gpt.head.len() != self.layers {
            return Err(Error::Context { c: self.rows + n, max: self.m });
        }
        let per_layer = st * self.m * c;
        let (r0, r1) = (self.rows * st, (self.rows + n) * st);
        for (l, b) in gpt.base.iter().chain(gpt.head.iter()).enumerate() {
            let layer = l * per_layer..(l + 1) * per_layer;
            // (r1, C) keys and values visible to the new rows, as f32.
            let (kr, vr): (&[f32], &[f32]) = match (&mut self.k, &mut self.v) {
                (KvBuf::F32(k), KvBuf::F32(v)) => {
                    let (kl, vl) = (&mut k[layer.clone()], &mut v[layer]);
                    block_kv(b, x, s.ln, &mut kl[r0 * c..r1 * c], &mut vl[r0 * c..r1 * c]);
                    (&kl[..r1 * c], &vl[..r1 * c])
                }
                (KvBuf::F16(k), KvBuf::F16(v)) => {
                    let (kl, vl) = (&mut k[layer.clone()], &mut v[layer]);
                    let (kf, vf) = (&mut kv.k[..r1 * c], &mut kv.v[..r1 * c]);
                    block_kv(b, x, s.ln, &mut kf[r0 * c..], &mut vf[r0 * c..]);
                    store_f16(&mut kf[r0 * c..], &mut kl[r0 * c..r1 * c]);
                    store_f16(&mut vf[r0 * c..], &mut vl[r0 * c..r1 * c]);
                    widen_f16(&kl[..r0 * c], &mut kf[..r0 * c]);
                    widen_f16(&vl[..r0 * c], &mut vf[..r0 * c]);
                    (kf, vf)
                }
                _ => return Err(Error::State),
            };
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
