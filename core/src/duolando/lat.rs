//! Look-Ahead Transformer (LAT; `MusicTrans` in the original): the music
//! LAT and the four leader LATs.
//!
//! `Linear(n_in -> C)` (leader LATs first look their tokens up in the
//! shared `tok_emb_<part>` table), `n_layer` pre-LN blocks under the band
//! mask `|i - j| <= look_forward * downsample_rate` (no position
//! embedding), then `downsample_rate` consecutive rows concatenated ->
//! `Linear(C * ds -> C)`; the last `look_forward` outputs are dropped.
//! The band is relative to the rows given (the original slices its mask
//! `[:L, :L]`), so a window's LAT output depends on where the window starts.

use crate::arena::{Arena, ArenaError, Carve, Planner};
use crate::duolando::config::{ModelConfig, Part};
use crate::duolando::model::{LatW, Model};
use crate::error::{check_len, Buffer, Error};
use crate::kernels::{linear, BandMask, Matrix};
use crate::nn::block::{block_forward, block_forward_prefix, BlockScratch};

/// What a LAT reads.
#[derive(Clone, Copy)]
pub enum LatInput<'x> {
    /// Feature rows (n, n_in): music frames.
    Features(&'x [f32]),
    /// Token ids (n), looked up in `table` (vocab, C): leader tokens.
    Tokens {
        tokens: &'x [u32],
        table: &'x Matrix<'x>,
        stream: u8,
    },
}

/// Working memory of a LAT over at most `rows` input rows.
pub struct LatScratch<'s> {
    /// (rows, C) residual stream.
    pub x: &'s mut [f32],
    /// (rows, C) token embeddings (leader LATs).
    pub emb: &'s mut [f32],
}

impl<'s> LatScratch<'s> {
    pub fn carve<A: Carve<'s>>(a: &mut A, rows: usize, c: usize) -> Result<Self, ArenaError> {
        let rc = rows.checked_mul(c).ok_or(ArenaError::Overflow)?;
        Ok(LatScratch {
            x: a.f32(rc)?,
            emb: a.f32(rc)?,
        })
    }
}

/// Output rows of a LAT over `n_in_rows` input rows: `n/ds - look_forward`
/// (None unless `n` is a positive multiple of ds with more than
/// `look_forward` tokens).
pub fn lat_out_rows(n_in_rows: usize, ds: usize, look_forward: usize) -> Option<usize> {
    if ds == 0 || n_in_rows % ds != 0 {
        return None;
    }
    (n_in_rows / ds)
        .checked_sub(look_forward)
        .filter(|&c| c > 0)
}

/// Runs a LAT: `out` (n/ds - look_forward, C). `block` and `s` must hold
/// `n` rows. Returns the number of output rows.
pub fn lat_forward(
    w: &LatW<'_>,
    c: usize,
    look_forward: usize,
    input: LatInput<'_>,
    s: &mut LatScratch<'_>,
    block: &mut BlockScratch<'_>,
    out: &mut [f32],
) -> Result<usize, Error> {
    let ds = w.cfg.downsample_rate as usize;
    let n_in = w.cfg.n_in as usize;
    let n = match input {
        LatInput::Features(f) => {
            if n_in == 0 || f.len() % n_in != 0 {
                return Err(Error::Ragged {
                    buffer: Buffer::Music,
                    len: f.len(),
                    row: n_in,
                });
            }
            f.len() / n_in
        }
        LatInput::Tokens { tokens, .. } => tokens.len(),
    };
    let rows = lat_out_rows(n, ds, look_forward).ok_or(Error::TooShort {
        buffer: Buffer::Features,
        frames: n,
        min: (look_forward + 1) * ds,
    })?;
    let cap = (s.x.len() / c.max(1)).min(block.rows);
    if n > cap {
        return Err(Error::Length {
            buffer: Buffer::Features,
            len: n,
            expected: cap,
        });
    }
    check_len(Buffer::Output, out.len(), rows * c)?;
    let x = &mut s.x[..n * c];
    match input {
        LatInput::Features(f) => linear(f, &w.cond_emb.w, w.cond_emb.b, x),
        LatInput::Tokens {
            tokens,
            table,
            stream,
        } => {
            if n_in != c || table.cols() != c {
                return Err(Error::Length {
                    buffer: Buffer::Features,
                    len: table.cols(),
                    expected: n_in,
                });
            }
            let emb = &mut s.emb[..n * c];
            for (i, &t) in tokens.iter().enumerate() {
                if t as usize >= table.rows() {
                    return Err(Error::Token {
                        stream,
                        token: t,
                        vocab: table.rows() as u32,
                    });
                }
                table.row_into(t as usize, &mut emb[i * c..(i + 1) * c]);
            }
            linear(emb, &w.cond_emb.w, w.cond_emb.b, x);
        }
    }
    let mask = BandMask {
        radius: look_forward * ds,
        q_pos0: 0,
        k_pos0: 0,
    };
    let n_head = w.cfg.n_head as usize;
    let kept = rows * ds;
    // The last block only for the rows the downsample reads (the others
    // only give it keys and values): its output (kept, C) over `emb`, dead
    // once the first projection has read it. No block: `x` itself.
    let last = match w.blocks.split_last() {
        Some((b, others)) => {
            for b in others {
                block_forward(b, x, c, n_head, &mask, block);
            }
            let y = &mut s.emb[..kept * c];
            block_forward_prefix(b, x, kept, c, n_head, &mask, block, y);
            &*y
        }
        None => &*x,
    };
    // (kept, C) viewed as (n/ds - look_forward, ds*C).
    linear(&last[..kept * c], &w.downsample.w, w.downsample.b, out);
    Ok(rows)
}

/// Input rows a LAT reads for context `c`: `(c + look_forward) * ds`.
pub fn input_rows(
    cfg: &ModelConfig,
    lat: &crate::duolando::config::LatConfig,
    c: usize,
) -> Option<usize> {
    c.checked_add(cfg.gpt.look_forward as usize)?
        .checked_mul(lat.downsample_rate as usize)
}

fn carve_standalone<'s, A: Carve<'s>>(
    a: &mut A,
    cfg: &ModelConfig,
    c: usize,
) -> Result<(LatScratch<'s>, BlockScratch<'s>), ArenaError> {
    let rows = input_rows(cfg, &cfg.gpt.music, c)
        .ok_or(ArenaError::Overflow)?
        .max(input_rows(cfg, &cfg.gpt.leader, c).ok_or(ArenaError::Overflow)?);
    let e = cfg.gpt.n_embd as usize;
    Ok((
        LatScratch::carve(a, rows, e)?,
        BlockScratch::carve(a, rows, e)?,
    ))
}

/// Scratch bytes of [`music_lat`] / [`leader_lat`] for context `c` (any base address).
pub fn scratch_bytes(cfg: &ModelConfig, c: usize) -> Option<usize> {
    let mut p = Planner::new();
    carve_standalone(&mut p, cfg, c).ok()?;
    p.total_for_any_base()
}

/// The music LAT alone: `music` ((c + lf) * ds, n_music) -> `out` (c, C).
/// Returns c. `scratch` >= [`scratch_bytes`]`(cfg, c)`.
pub fn music_lat(
    model: &Model<'_>,
    music: &[f32],
    scratch: &mut [u8],
    out: &mut [f32],
) -> Result<usize, Error> {
    let cfg = &model.cfg;
    let (e, lf) = (cfg.gpt.n_embd as usize, cfg.gpt.look_forward as usize);
    let c = out.len() / e.max(1);
    let mut a = Arena::new(scratch);
    let (mut s, mut b) = carve_standalone(&mut a, cfg, c)?;
    lat_forward(
        &model.gpt.music,
        e,
        lf,
        LatInput::Features(music),
        &mut s,
        &mut b,
        out,
    )
}

/// A leader LAT alone, including its `tok_emb_<part>` lookup: `tokens`
/// (c + lf) -> `out` (c, C). Returns c.
pub fn leader_lat(
    model: &Model<'_>,
    part: Part,
    tokens: &[u32],
    scratch: &mut [u8],
    out: &mut [f32],
) -> Result<usize, Error> {
    let cfg = &model.cfg;
    let (e, lf) = (cfg.gpt.n_embd as usize, cfg.gpt.look_forward as usize);
    let c = out.len() / e.max(1);
    let mut a = Arena::new(scratch);
    let (mut s, mut b) = carve_standalone(&mut a, cfg, c)?;
    let p = part as usize;
    let input = LatInput::Tokens {
        tokens,
        table: &model.gpt.tok_emb[p],
        stream: p as u8,
    };
    lat_forward(&model.gpt.leaders[p], e, lf, input, &mut s, &mut b, out)
}
