//! Token streams side by side (Duolando's coordinated attention over 10
//! streams, Bailando's cross-conditional GPT over 3): `x` holds each
//! stream's `t` rows one after another ((streams * t, C)); stream `s`
//! adds learned position rows `s * block_size ..`; the mask is the
//! `t x t` lower triangle tiled streams x streams (a row at position i
//! sees every stream at positions <= i).

use crate::kernels::TiledCausalMask;
use crate::nn::block::{block_forward, block_forward_rows, BlockScratch};
use crate::nn::weights::BlockW;

/// Adds the learned position embedding: stream `s`, position `p` gets row
/// `s * block_size + p` of `pos_emb`.
pub fn add_positions(
    pos_emb: &[f32],
    block_size: usize,
    streams: usize,
    t: usize,
    c: usize,
    x: &mut [f32],
) {
    for s in 0..streams {
        for p in 0..t {
            let row = &pos_emb[(s * block_size + p) * c..(s * block_size + p + 1) * c];
            let xr = &mut x[(s * t + p) * c..(s * t + p + 1) * c];
            for (a, b) in xr.iter_mut().zip(row) {
                *a += b;
            }
        }
    }
}

/// Runs the `base` then `head` blocks over `x` (streams * t, C). The last
/// block is evaluated only at `rows` (row indices into `x`, typically the
/// last position of the streams that have a logits head): `out`
/// (rows.len(), C) receives them. With no blocks at all, `out` gets the
/// rows of `x` as they are.
#[allow(clippy::too_many_arguments)]
pub fn forward_last(
    base: &[BlockW<'_>],
    head: &[BlockW<'_>],
    x: &mut [f32],
    rows: &[usize],
    t: usize,
    c: usize,
    n_head: usize,
    s: &mut BlockScratch<'_>,
    out: &mut [f32],
) {
    let mask = TiledCausalMask {
        t_q: t,
        t_k: t,
        q_pos0: 0,
    };
    let all: &[&[BlockW<'_>]] = &[base, head];
    let n = base.len() + head.len();
    let mut blocks = all.iter().flat_map(|b| b.iter());
    for _ in 0..n.saturating_sub(1) {
        if let Some(b) = blocks.next() {
            block_forward(b, x, c, n_head, &mask, s);
        }
    }
    match blocks.next() {
        Some(b) => {
            let q_mask = TiledCausalMask {
                t_q: 1,
                t_k: t,
                q_pos0: t - 1,
            };
            block_forward_rows(b, x, rows, c, n_head, &q_mask, s, out);
        }
        None => {
            for (j, &r) in rows.iter().enumerate() {
                out[j * c..(j + 1) * c].copy_from_slice(&x[r * c..(r + 1) * c]);
            }
        }
    }
}
