//! The actor GPT at one sampling step (`CrossCondGPT2.forward` on one
//! window): streams `[music, up, down]` (`t` rows each, the music rows
//! through `cond_emb`), learned positions per stream, the base and head
//! blocks under the tiled causal mask (`nn::streams`), `ln_f`, and the two
//! heads at the last position of the up and down streams.

use crate::arena::{ArenaError, Carve};
use crate::bailando::config::{BailandoConfig, N_STREAMS};
use crate::bailando::model::Model;
use crate::error::{check_len, Buffer, Error};
use crate::kernels::{layernorm, linear};
use crate::nn::block::BlockScratch;
use crate::nn::streams::{add_positions, forward_last};

/// Working memory of [`window_logits`] for windows up to `max_c` tokens.
pub struct GptScratch<'s> {
    pub block: BlockScratch<'s>,
    /// (3 * max_c, C): the three streams.
    pub x: &'s mut [f32],
    /// (2, C): last rows of the up and down streams.
    pub last: &'s mut [f32],
    /// (C): one row after `ln_f`.
    pub ln: &'s mut [f32],
    pub max_c: usize,
}

impl<'s> GptScratch<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &BailandoConfig,
        max_c: usize,
    ) -> Result<Self, ArenaError> {
        let c = cfg.gpt.n_embd as usize;
        let rows = max_c.checked_mul(N_STREAMS).ok_or(ArenaError::Overflow)?;
        Ok(GptScratch {
            block: BlockScratch::carve(a, rows, c)?,
            x: a.f32(rows.checked_mul(c).ok_or(ArenaError::Overflow)?)?,
            last: a.f32(2 * c)?,
            ln: a.f32(c)?,
            max_c,
        })
    }
}

/// Largest window: `block_size - 1` tokens.
pub fn max_context(cfg: &BailandoConfig) -> usize {
    cfg.gpt.block_size as usize - 1
}

/// Floats of the logits of both heads (vocab_up + vocab_down).
pub fn logits_len(cfg: &BailandoConfig) -> usize {
    (cfg.gpt.vocab[0] + cfg.gpt.vocab[1]) as usize
}

/// The GPT at one window of `t` positions: `tokens` (t, 2) up/down,
/// `music` (t, n_music) the rows in the same slots; `logits` = head_up then
/// head_down at the last position.
pub fn window_logits(
    model: &Model<'_>,
    tokens: &[u32],
    music: &[f32],
    s: &mut GptScratch<'_>,
    logits: &mut [f32],
) -> Result<(), Error> {
    let cfg = &model.cfg;
    let g = &cfg.gpt;
    let c = g.n_embd as usize;
    let nm = g.n_music as usize;
    if tokens.is_empty() || tokens.len() % 2 != 0 {
        return Err(Error::Ragged {
            buffer: Buffer::Tokens,
            len: tokens.len(),
            row: 2,
        });
    }
    let t = tokens.len() / 2;
    let max = s.max_c.min(max_context(cfg));
    if t > max {
        return Err(Error::Context { c: t, max });
    }
    check_len(Buffer::Music, music.len(), t * nm)?;
    check_len(Buffer::Logits, logits.len(), logits_len(cfg))?;
    let x = &mut s.x[..N_STREAMS * t * c];
    // The music stream's t rows in one call (one read of `cond_emb`; rows
    // are computed independently, so the same numbers as row by row).
    linear(
        music,
        &model.gpt.cond_emb.w,
        model.gpt.cond_emb.b,
        &mut x[..t * c],
    );
    for (j, table) in model.gpt.tok_emb.iter().enumerate() {
        for p in 0..t {
            let tok = tokens[2 * p + j];
            if tok as usize >= table.rows() {
                return Err(Error::Token {
                    stream: j as u8,
                    token: tok,
                    vocab: table.rows() as u32,
                });
            }
            let row = (1 + j) * t + p;
            table.row_into(tok as usize, &mut x[row * c..(row + 1) * c]);
        }
    }
    add_positions(model.gpt.pos_emb, g.block_size as usize, N_STREAMS, t, c, x);
    let rows = [2 * t - 1, 3 * t - 1];
    forward_last(
        &model.gpt.base,
        &model.gpt.head,
        x,
        &rows,
        t,
        c,
        g.n_head as usize,
        &mut s.block,
        s.last,
    );
    let (up, down) = logits.split_at_mut(g.vocab[0] as usize);
    for (j, out) in [up, down].into_iter().enumerate() {
        layernorm(
            &s.last[j * c..(j + 1) * c],
            model.gpt.ln_f.w,
            model.gpt.ln_f.b,
            s.ln,
        );
        linear(s.ln, &model.gpt.heads[j], None, out);
    }
    Ok(())
}
