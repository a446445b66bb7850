//! Coordinated attention: the GPT base + head stacks over 10 streams
//! `[music, L_up, L_down, L_lh, L_rh, F_up, F_down, F_lh, F_rh, F_transl]`,
//! each `t` rows, laid out one after another in `x` (10t, C).
//!
//! Stream `s` adds position-embedding rows `s*block_size .. s*block_size+t`;
//! the mask is the `t x t` lower triangle tiled 10 x 10 (a token at
//! position i sees every stream at positions <= i). No final LayerNorm.

use crate::duolando::model::GptW;
use crate::error::Error;
use crate::nn::block::BlockScratch;
use crate::nn::streams;
pub use crate::nn::streams::add_positions;

/// First follower stream (F_up); follower streams are 5..10.
pub const FIRST_FOLLOWER_STREAM: usize = 5;
/// Number of follower streams (up, down, lhand, rhand, transl).
pub const FOLLOWER_STREAMS: usize = 5;

/// Checks the stream layout a session assumes (music, 4 leader, 5 follower).
pub fn check_layout(streams: usize) -> Result<(), Error> {
    if streams != FIRST_FOLLOWER_STREAM + FOLLOWER_STREAMS {
        return Err(Error::Length {
            buffer: crate::error::Buffer::Features,
            len: streams,
            expected: FIRST_FOLLOWER_STREAM + FOLLOWER_STREAMS,
        });
    }
    Ok(())
}

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
pub fn embed_followers(
    gpt: &GptW<'_>,
    follower: &[u32],
    t: usize,
    c: usize,
    x: &mut [f32],
) -> Result<(), Error> {
    for j in 0..FOLLOWER_STREAMS {
        let table = &gpt.tok_emb[follower_table(j)];
        let base = (FIRST_FOLLOWER_STREAM + j) * t;
        for p in 0..t {
            let tok = follower[p * FOLLOWER_STREAMS + j];
            if tok as usize >= table.rows() {
                return Err(Error::Token {
                    stream: j as u8,
                    token: tok,
                    vocab: table.rows() as u32,
                });
            }
            table.row_into(tok as usize, &mut x[(base + p) * c..(base + p + 1) * c]);
        }
    }
    Ok(())
}

/// Runs the base and head blocks over `x` (10t, C). The last head block
/// is evaluated only at the last position of the 5 follower streams:
/// `last` (5, C) receives those rows (all a logits head reads).
pub fn forward_last(
    gpt: &GptW<'_>,
    x: &mut [f32],
    t: usize,
    c: usize,
    n_head: usize,
    s: &mut BlockScratch<'_>,
    last: &mut [f32],
) {
    let mut rows = [0usize; FOLLOWER_STREAMS];
    for (j, r) in rows.iter_mut().enumerate() {
        *r = (FIRST_FOLLOWER_STREAM + j) * t + t - 1;
    }
    streams::forward_last(&gpt.base, &gpt.head, x, &rows, t, c, n_head, s, last);
}
