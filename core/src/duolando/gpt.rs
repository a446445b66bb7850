//! The follower GPT (`GPT2nt.forward` at one sampling step): LATs ->
//! coordinated attention -> 5 heads, returning the logits at the LAST
//! window position of each follower stream.

use crate::arena::{ArenaError, Carve};
use crate::duolando::config::ModelConfig;
use crate::duolando::coordinated_attention::{
    add_positions, embed_followers, forward_last, FOLLOWER_STREAMS,
};
use crate::duolando::lat::{lat_forward, LatInput, LatScratch};
use crate::duolando::model::Model;
use crate::error::{check_len, Buffer, Error};
use crate::kernels::linear;
use crate::nn::block::BlockScratch;

/// One GPT window: `c` follower tokens per stream and the conditioning
/// that covers them plus the look-ahead.
#[derive(Clone, Copy)]
pub struct Window<'x> {
    /// Context length (follower tokens per stream), 1..=block_size-1.
    pub c: usize,
    /// Music frames ((c + look_forward) * ds, n_music).
    pub music: &'x [f32],
    /// Leader tokens per part (up, down, lhand, rhand), c + look_forward each.
    pub leader: [&'x [u32]; 4],
    /// Follower tokens (c, 5) row-major: up, down, lhand, rhand, transl.
    pub follower: &'x [u32],
}

/// Working memory of [`window_logits`] for contexts up to `max_c`.
pub struct GptScratch<'s> {
    pub lat: LatScratch<'s>,
    pub block: BlockScratch<'s>,
    /// (10 * max_c, C) the 10 streams.
    pub x: &'s mut [f32],
    /// (5, C) last-position features of the follower streams.
    pub last: &'s mut [f32],
    pub max_c: usize,
}

impl<'s> GptScratch<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &ModelConfig,
        max_c: usize,
    ) -> Result<Self, ArenaError> {
        let g = &cfg.gpt;
        let c = g.n_embd as usize;
        let lf = g.look_forward as usize;
        let ov = ArenaError::Overflow;
        let lat_rows = max_c
            .checked_add(lf)
            .ok_or(ov)?
            .checked_mul(g.music.downsample_rate.max(1) as usize)
            .ok_or(ov)?;
        let streams = g.n_streams as usize;
        let x_rows = max_c.checked_mul(streams).ok_or(ov)?;
        Ok(GptScratch {
            lat: LatScratch::carve(a, lat_rows, c)?,
            block: BlockScratch::carve(a, lat_rows.max(x_rows), c)?,
            x: a.f32(x_rows.checked_mul(c).ok_or(ov)?)?,
            last: a.f32(FOLLOWER_STREAMS * c)?,
            max_c,
        })
    }
}

/// Largest context R mode uses: `block_size - 1`.
pub fn max_context(cfg: &ModelConfig) -> usize {
    cfg.gpt.block_size as usize - 1
}

/// Scratch bytes of [`window_logits`] for contexts up to `max_c`
/// (aligned base; add [`crate::arena::ALIGN`]` - 1` for any base).
pub fn scratch_bytes(cfg: &ModelConfig, max_c: usize) -> Option<usize> {
    let mut p = crate::arena::Planner::new();
    GptScratch::carve(&mut p, cfg, max_c).ok()?;
    p.total_for_any_base()
}

/// Rows of each head's logits (vocab_up, vocab_down, vocab_up,
/// vocab_down, vocab_transl: the original heads' quirk).
pub fn head_rows(cfg: &ModelConfig) -> [usize; 5] {
    let v = cfg.gpt.vocab;
    [
        v[0] as usize,
        v[1] as usize,
        v[0] as usize,
        v[1] as usize,
        v[4] as usize,
    ]
}

/// Floats of the concatenated logits of the 5 heads.
pub fn logits_len(cfg: &ModelConfig) -> usize {
    head_rows(cfg).iter().sum()
}

/// The GPT at one window: `logits` (sum of [`head_rows`]) = the 5 heads
/// (up, down, lhand, rhand, transl) at the last window position,
/// concatenated in that order.
pub fn window_logits(
    model: &Model<'_>,
    win: &Window<'_>,
    s: &mut GptScratch<'_>,
    logits: &mut [f32],
) -> Result<(), Error> {
    let cfg = &model.cfg;
    let g = &cfg.gpt;
    let c = g.n_embd as usize;
    let lf = g.look_forward as usize;
    let t = win.c;
    let max = s.max_c.min(g.block_size as usize);
    if t == 0 || t > max {
        return Err(Error::Context { c: t, max });
    }
    let ds = g.music.downsample_rate as usize;
    check_len(
        Buffer::Music,
        win.music.len(),
        (t + lf) * ds * g.music.n_in as usize,
    )?;
    for l in win.leader {
        check_len(Buffer::LeaderTokens, l.len(), t + lf)?;
    }
    check_len(
        Buffer::FollowerTokens,
        win.follower.len(),
        t * FOLLOWER_STREAMS,
    )?;
    check_len(Buffer::Logits, logits.len(), logits_len(cfg))?;
    let streams = g.n_streams as usize;
    let x = &mut s.x[..streams * t * c];
    // Stream 0: music LAT; streams 1..5: leader LATs over their token embeddings.
    lat_forward(
        &model.gpt.music,
        c,
        lf,
        LatInput::Features(win.music),
        &mut s.lat,
        &mut s.block,
        &mut x[..t * c],
    )?;
    for p in 0..4 {
        let input = LatInput::Tokens {
            tokens: win.leader[p],
            table: &model.gpt.tok_emb[p],
            stream: p as u8,
        };
        let out = &mut x[(1 + p) * t * c..(2 + p) * t * c];
        lat_forward(
            &model.gpt.leaders[p],
            c,
            lf,
            input,
            &mut s.lat,
            &mut s.block,
            out,
        )?;
    }
    embed_followers(&model.gpt, win.follower, t, c, x)?;
    add_positions(model.gpt.pos_emb, g.block_size as usize, streams, t, c, x);
    forward_last(&model.gpt, x, t, c, g.n_head as usize, &mut s.block, s.last);
    let mut off = 0;
    for (j, rows) in head_rows(cfg).iter().enumerate() {
        linear(
            &s.last[j * c..(j + 1) * c],
            &model.gpt.heads[j],
            None,
            &mut logits[off..off + rows],
        );
        off += rows;
    }
    Ok(())
}

/// [`window_logits`] with byte scratch (>= [`scratch_bytes`]`(cfg, win.c)`).
pub fn step_logits(
    model: &Model<'_>,
    win: &Window<'_>,
    scratch: &mut [u8],
    logits: &mut [f32],
) -> Result<(), Error> {
    let mut a = crate::arena::Arena::new(scratch);
    let mut s = GptScratch::carve(&mut a, &model.cfg, win.c)?;
    window_logits(model, win, &mut s, logits)
}
