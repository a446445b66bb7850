//! Coordinated attention: the GPT base + head stacks over 10 streams
//! `[music, L_up, L_down, L_lh, L_rh, F_up, F_down, F_lh, F_rh, F_transl]`,
//! each `t` rows, laid out one after another in `x` (10t, C).
//!
//! Stream `s` adds position-embedding rows `s*block_size .. s*block_size+t`;
//! the mask is the `t x t` lower triangle tiled 10 x 10 (a token at
//! position i sees every stream at positions <= i). No final LayerNorm.

use crate::nn::block::{block_forward, block_forward_rows, BlockScratch};
use crate::error::Error;
use crate::kernels::TiledCausalMask;
use crate::duolando::model::GptW;

/// First follower stream (F_up); follower streams are 5..10.
pub const FIRST_FOLLOWER_STREAM: usize = 5;
/// Number of follower streams (up, down, lhand, rhand, transl).
pub const FOLLOWER_STREAMS: usize = 5;

/// Embedding table used for follower stream `j` (0..5): the original
/// embeds follower right-hand tokens with the LEFT-hand table.
pub const fn follower_table(j: usize) -> usize {
    if j == 3 {
        2
    } else {
        j
    }
}

/// Writes follower token embeddings into streams 5..9 of `x` (10t, C).
/// `follower`: (t, 5) row-major tokens (up, down, lhand, rhand, transl).
pub fn embed_followers(gpt: &GptW<'_>, follower: &[u32], t: usize, c: usize, x: &mut [f32]) -> Result<(), Error> {
    for j in 0..FOLLOWER_STREAMS {
        let table = &gpt.tok_emb[follower_table(j)];
        let base = (FIRST_FOLLOWER_STREAM + j) * t;
        for p in 0..t {
            let tok = follower[p * FOLLOWER_STREAMS + j];
            if tok as usize >= table.rows() {
                return Err(Error::Token { stream: j as u8, token: tok, vocab: table.rows() as u32 });
            }
            table.row_into(tok as usize, &mut x[(base + p) * c..(base + p + 1) * c]);
        }
    }
    Ok(())
}

/// Adds the learned position embedding: stream `s`, position `p` gets row
/// `s * block_size + p` of `pos_emb`.
pub fn add_positions(pos_emb: &[f32], block_size: usize, streams: usize, t: usize, c: usize, x: &mut [f32]) {
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

/// Runs the base and head blocks over `x` (10t, C). The last head block
/// is evaluated only at the last position of the 5 follower streams:
/// `last` (5, C) receives those rows (all a logits head reads).
pub fn forward_last(gpt: &GptW<'_>, x: &mut [f32], t: usize, c: usize, n_head: usize, s: &mut BlockScratch<'_>, last: &mut [f32]) {
    let mask = TiledCausalMask { t_q: t, t_k: t, q_pos0: 0 };
    let n_head_blocks = gpt.head.len();
    let all = gpt.base.iter().chain(gpt.head.iter().take(n_head_blocks.saturating_sub(1)));
    for b in all {
        block_forward(b, x, c, n_head, &mask, s);
    }
    let mut rows = [0usize; FOLLOWER_STREAMS];
    for (j, r) in rows.iter_mut().enumerate() {
        *r = (FIRST_FOLLOWER_STREAM + j) * t + t - 1;
    }
    match gpt.head.last() {
        Some(b) => {
            let q_mask = TiledCausalMask { t_q: 1, t_k: t, q_pos0: t - 1 };
            block_forward_rows(b, x, &rows, c, n_head, &q_mask, s, last);
        }
        None => {
            for (j, &r) in rows.iter().enumerate() {
                last[j * c..(j + 1) * c].copy_from_slice(&x[r * c..(r + 1) * c]);
            }
        }
    }
}
