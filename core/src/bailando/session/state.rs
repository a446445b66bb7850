//! Every buffer of a Bailando session, carved once by ONE function (a
//! [`Planner`](crate::arena::Planner) gives the bytes, an
//! [`Arena`](crate::arena::Arena) the state), and the working memory of a
//! step ([`StepScratch`]: a session's own, or a batch's for several).

use crate::arena::{ArenaError, Carve};
use crate::bailando::config::{BailandoConfig, DOWN_JOINTS, N_STREAMS, POSE_DIM, UP_JOINTS};
use crate::bailando::session::config::{window_rows, CacheSchedule, SessionConfig};
use crate::error::Error;
use crate::nn::block::BlockScratch;
use crate::nn::gpt_cache::GptCache;
use crate::nn::ring::{RowRing, TokenRing};
use crate::nn::stream_conv::{ScratchNeed, StackKind, StreamScratch, StreamStack};

/// Rows of its next window a spread session appends in one step at most;
/// also a batch's scratch rows per session (`1 + PREFILL_CHUNK`).
pub const PREFILL_CHUNK: usize = 8;

/// Decoders of a session: the up half, the down half, the root velocity.
pub const DECODERS: usize = 3;

fn ov() -> ArenaError {
    ArenaError::Overflow
}

pub struct State<'s> {
    /// (m + music_buffer_rows, n_music) pushed music rows: the window's
    /// rows a re-prefill reads and the rows pushed ahead.
    pub music: RowRing<'s>,
    /// (m + 1, 2) token history (up, down): the window's tokens.
    pub toks: TokenRing<'s>,
    /// K/V of the current GPT window (re-prefilled when it jumps), and
    /// with the spread schedule the next window's first `shift - 1` rows,
    /// filled ahead and moved into the first at the jump.
    pub gpt: heapless::Vec<GptCache<'s>, 2>,
    /// Streaming decoders: up, down (positions), root velocity.
    pub dec: [StreamStack<'s>; DECODERS],
    /// (hop, 45), (hop, 27), (hop, 3) one token's frames from the up and
    /// down decoders and the root velocity from the root decoder.
    pub dec_out: &'s mut [f32],
    /// (hop, 72) the frames of one token being assembled.
    pub frames: &'s mut [f32],
    /// (pending_frames + hop max(d + 1, 2), 72) decoded frames waiting for
    /// a pull: a step runs with at most `pending_frames` waiting and makes
    /// one token's frames final; the first step two (the seed's and token
    /// 1's, when d = 0), the last step of an ended session up to `d + 1`.
    pub pending: RowRing<'s>,
}

impl<'s> State<'s> {
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &BailandoConfig,
        sc: &SessionConfig,
    ) -> Result<Self, Error> {
        let g = &cfg.gpt;
        let m = window_rows(cfg);
        let c = g.n_embd as usize;
        let hop = cfg.hop();
        let d = sc.dec_future as usize;
        let layers = (g.n_layer_base + g.n_layer_head) as usize;
        let music = RowRing::carve(
            a,
            m.checked_add(sc.music_buffer_rows as usize).ok_or(ov())?,
            g.n_music as usize,
        )?;
        let toks = TokenRing::carve(a, m + 1, 2)?;
        // The window's own cache, and with the spread schedule a second one
        // for the next window's rows before its jump: at most `shift - 1`
        // of them (the jump's own row goes to the first cache, which takes
        // them over).
        let mut gpt = heapless::Vec::new();
        let caches = if sc.schedule == CacheSchedule::Spread {
            2
        } else {
            1
        };
        for i in 0..caches {
            let rows = if i == 1 {
                (sc.shift as usize).clamp(1, m)
            } else {
                m
            };
            gpt.push(GptCache::carve(
                a,
                sc.kv,
                layers,
                N_STREAMS,
                rows,
                c,
                g.n_head as usize,
            )?)
            .map_err(|_| ov())?;
        }
        let up = StreamStack::carve(a, &cfg.parts[0], StackKind::Decoder, d)?;
        let down = StreamStack::carve(a, &cfg.parts[1], StackKind::Decoder, d)?;
        let root = StreamStack::carve(a, &cfg.parts[1], StackKind::Decoder, d)?;
        Ok(State {
            music,
            toks,
            gpt,
            dec: [up, down, root],
            dec_out: a.f32(
                hop.checked_mul((UP_JOINTS.len() + DOWN_JOINTS.len()) * 3 + 3)
                    .ok_or(ov())?,
            )?,
            frames: a.f32(hop.checked_mul(POSE_DIM).ok_or(ov())?)?,
            pending: RowRing::carve(
                a,
                hop.checked_mul((d + 1).max(2))
                    .and_then(|f| f.checked_add(sc.pending_frames as usize))
                    .ok_or(ov())?,
                POSE_DIM,
            )?,
        })
    }

    /// Back to an empty session (no allocation).
    pub fn reset(&mut self) {
        self.music.clear();
        self.toks.clear();
        for g in self.gpt.iter_mut() {
            g.reset();
        }
        for d in self.dec.iter_mut() {
            d.reset();
        }
        self.pending.clear();
    }
}

/// Working memory of a step for up to `n` sessions at once.
pub struct StepScratch<'s> {
    /// Sessions a step may hold.
    pub n: usize,
    /// (3 r, C) the GPT's new rows, `r` window rows (`n (1 + PREFILL_CHUNK)`
    /// for a batch; a re-prefilling session's own scratch holds its whole
    /// re-prefill, `shift` rows), position-major: row `i * 3 + s`, stream s
    /// of new window row i: each session's new row, the window rows its
    /// cache lacks (after a jump) where they fit, and up to PREFILL_CHUNK
    /// rows of its next window (spread); or a re-prefill chunk; after the
    /// GPT the first `2 n` rows hold the up and down streams' final hidden
    /// states.
    pub x: &'s mut [f32],
    pub block: BlockScratch<'s>,
    /// (C) one row after `ln_f`.
    pub ln: &'s mut [f32],
    /// (vocab_up + vocab_down) the two heads' logits.
    pub logits: &'s mut [f32],
    /// (max emb_width) one dequantised code.
    pub feat: &'s mut [f32],
    /// The decoders' conv scratch (one stack at a time).
    pub conv: StreamScratch<'s>,
}

impl<'s> StepScratch<'s> {
    /// A batch's scratch for up to `n` sessions: `n (1 + PREFILL_CHUNK)`
    /// window rows at once.
    pub fn carve<A: Carve<'s>>(a: &mut A, cfg: &BailandoConfig, n: usize) -> Result<Self, Error> {
        let rows = n.checked_mul(1 + PREFILL_CHUNK).ok_or(ov())?;
        Self::carve_rows(a, cfg, n, rows)
    }

    /// A session's own scratch: with the re-prefill schedule it holds the
    /// whole re-prefill of a jump and the new row (`shift` window rows), so
    /// that a jump reads the weights once, not once per chunk.
    pub fn carve_own<A: Carve<'s>>(
        a: &mut A,
        cfg: &BailandoConfig,
        sc: &SessionConfig,
    ) -> Result<Self, Error> {
        let rows = match sc.schedule {
            CacheSchedule::Reprefill => (sc.shift as usize).max(1 + PREFILL_CHUNK),
            // (Staggered is refused by `SessionConfig::check`.)
            CacheSchedule::Spread | CacheSchedule::Staggered => 1 + PREFILL_CHUNK,
        };
        Self::carve_rows(a, cfg, 1, rows)
    }

    /// `window_rows_per_call` window rows of new GPT rows per call, for `n` sessions.
    fn carve_rows<A: Carve<'s>>(
        a: &mut A,
        cfg: &BailandoConfig,
        n: usize,
        window_rows_per_call: usize,
    ) -> Result<Self, Error> {
        let g = &cfg.gpt;
        let c = g.n_embd as usize;
        let m = window_rows(cfg);
        let rows = window_rows_per_call.checked_mul(N_STREAMS).ok_or(ov())?;
        let emb = cfg
            .parts
            .iter()
            .map(|p| p.emb_width as usize)
            .max()
            .unwrap_or(0);
        let need = ScratchNeed::for_vqs(&cfg.vqs()).ok_or(ov())?;
        Ok(StepScratch {
            n,
            x: a.f32(rows.checked_mul(c).ok_or(ov())?)?,
            block: BlockScratch::carve_keys(a, rows, m.checked_mul(N_STREAMS).ok_or(ov())?, c)?,
            ln: a.f32(c)?,
            logits: a.f32((g.vocab[0] + g.vocab[1]) as usize)?,
            feat: a.f32(emb)?,
            conv: StreamScratch::carve(a, need, 1)?,
        })
    }
}
