//! Every buffer of a session, carved once by ONE function (run with a
//! [`Planner`](crate::arena::Planner) it gives `Model::session_bytes`, with
//! an [`Arena`](crate::arena::Arena) the state itself).

use crate::arena::{ArenaError, Carve};
use crate::duolando::config::{ModelConfig, POSE_DIM, ROT_DIM};
use crate::duolando::model::Model;
use crate::duolando::session::batch::music_burst;
use crate::duolando::session::config::{CacheSchedule, SessionConfig, MAX_WINDOWS};
use crate::duolando::session::lat_stream::{LatIn, LatStream};
use crate::error::Error;
use crate::nn::gpt_cache::GptCache;
use crate::nn::quantizer::codebook_norms;
use crate::nn::ring::{RowRing, TokenRing};
use crate::nn::stream_conv::{StackKind, StreamStack};
use heapless::Vec;

/// Floats of one decoded follower frame waiting to be pulled:
/// normalised pose (165) | rotation matrices (495) | translation (3).
pub const FRAME_WIDTH: usize = POSE_DIM + ROT_DIM + 3;

pub struct State<'s> {
    // --- leader path ---
    /// (hop, 165) normalised leader frames of the token being filled.
    pub block: &'s mut [f32],
    /// (hop, max in_channels) one part's encoder input.
    pub part_in: &'s mut [f32],
    /// Streaming encoders, one per part (up, down, lhand, rhand).
    pub enc: [StreamStack<'s>; 4],
    /// (4, kk_stride) squared codebook row norms per part.
    pub kk: &'s mut [f32],
    pub kk_stride: usize,
    /// (max emb) one feature / one dequantised code.
    pub feat: &'s mut [f32],
    pub leader_lat: [LatStream<'s>; 4],
    // --- music path ---
    pub music_lat: LatStream<'s>,
    /// (music_buffer_frames, n_music) pushed music frames (plain ring).
    pub music: RowRing<'s>,
    // --- GPT ---
    /// Frozen condition rows per stream (music, L_up, L_down, L_lh, L_rh):
    /// (m + 1, C) each (plain rings): rows up to the next step's.
    pub cond: [RowRing<'s>; 5],
    /// Leader rows that may wait for music before leader pushes are refused.
    pub cond_slack: usize,
    /// (cond_slack + 1, 4) leader codes not yet in the leader LATs: those
    /// whose condition rows would lie beyond the next step's (they wait,
    /// 16 bytes each, instead of C-wide rows).
    pub codes: TokenRing<'s>,
    /// (m + 1, 5) follower history.
    pub toks: TokenRing<'s>,
    /// GPT K/V caches: one (re-prefill schedule) or one per live window
    /// (staggered schedule).
    pub gpt: Vec<GptCache<'s>, MAX_WINDOWS>,
    // --- decoders ---
    /// Position decoders of the 4 parts and the translation decoder.
    pub dec_pos: [StreamStack<'s>; 5],
    /// Rotation decoders of the 4 parts (where the model has them).
    pub dec_rot: [Option<StreamStack<'s>>; 4],
    /// (hop, max(in, rot, 3)) one decoder's frames.
    pub dec_out: &'s mut [f32],
    /// (hop, FRAME_WIDTH) the frames of one token being assembled.
    pub frames: &'s mut [f32],
    /// (cap, FRAME_WIDTH) decoded frames waiting for their leader root / a pull.
    pub pending: RowRing<'s>,
    /// (cap, 3) leader roots of frames not yet pulled.
    pub roots: RowRing<'s>,
}

fn widths(cfg: &ModelConfig) -> (usize, usize, usize, usize) {
    let (mut pos, mut rot, mut emb, mut bins) = (3usize, 0usize, 0usize, 0usize);
    for vq in cfg.parts.iter().chain(core::iter::once(&cfg.transl)) {
        pos = pos.max(vq.in_channels as usize);
        rot = rot.max(vq.rot_channels as usize);
        emb = emb.max(vq.emb_width as usize);
        bins = bins.max(vq.l_bins as usize);
    }
    (pos, rot, emb, bins)
}

fn ov() -> ArenaError {
    ArenaError::Overflow
}

impl<'s> State<'s> {
    /// Every buffer for a model of config `cfg` (bound models have a
    /// rotation decoder exactly where `rot_channels > 0`).
    pub fn carve<A: Carve<'s>>(
        a: &mut A,
        cfg: &ModelConfig,
        sc: &SessionConfig,
    ) -> Result<Self, Error> {
        let g = &cfg.gpt;
        let hop = cfg.hop();
        let c = g.n_embd as usize;
        let m = (g.block_size as usize).checked_sub(1).ok_or(ov())?;
        let streams = g.n_streams as usize;
        let (pos, rot, emb, bins) = widths(cfg);
        let (e, d) = (sc.enc_future as usize, sc.dec_future as usize);
        let (la, am) = (sc.lookahead as usize, sc.music_lookahead as usize);
        let lds = g.leader.downsample_rate as usize;
        let mds = g.music.downsample_rate as usize;
        let past = sc.lat_past as usize;

        let enc = [0, 1, 2, 3].map(|p| StreamStack::carve(a, &cfg.parts[p], StackKind::Encoder, e));
        let [e0, e1, e2, e3] = enc;
        let enc = [e0?, e1?, e2?, e3?];
        let lat_layers = |l: &crate::duolando::config::LatConfig| l.n_layer as usize;
        let leader_lat = [0, 1, 2, 3].map(|_| {
            LatStream::carve(
                a,
                sc.kv,
                lat_layers(&g.leader),
                lds,
                c,
                LatIn::Tokens,
                past * lds,
                la * lds,
                1,
            )
        });
        let [l0, l1, l2, l3] = leader_lat;
        let leader_lat = [l0?, l1?, l2?, l3?];
        let music_lat = LatStream::carve(
            a,
            sc.kv,
            lat_layers(&g.music),
            mds,
            c,
            LatIn::Rows(g.music.n_in as usize),
            past * mds,
            am * mds,
            music_burst(cfg),
        )?;
        let cond_slack = am + 10;
        let codes_cap = cond_slack.checked_add(1).ok_or(ov())?;
        // Every condition row of step k is made once step k may use it (rows
        // <= k: the window's m): the music row when step k wants it, a leader
        // row when its code comes (codes further ahead wait in `codes`).
        let cond = [0, 1, 2, 3, 4].map(|_| RowRing::carve(a, m + 1, c));
        let [c0, c1, c2, c3, c4] = cond;
        let cond = [c0?, c1?, c2?, c3?, c4?];
        let dec_pos = [0, 1, 2, 3, 4].map(|p| {
            let vq = if p < 4 { &cfg.parts[p] } else { &cfg.transl };
            StreamStack::carve(a, vq, StackKind::Decoder, d)
        });
        let [d0, d1, d2, d3, d4] = dec_pos;
        let dec_pos = [d0?, d1?, d2?, d3?, d4?];
        let dec_rot = [0, 1, 2, 3].map(|p| match cfg.parts[p].rot_channels {
            0 => Ok(None),
            _ => StreamStack::carve(a, &cfg.parts[p], StackKind::Decoder, d).map(Some),
        });
        let [r0, r1, r2, r3] = dec_rot;
        let dec_rot = [r0?, r1?, r2?, r3?];

        let n_caches = sc.schedule.caches(m, sc.shift as usize);
        let mut gpt = Vec::new();
        for i in 0..n_caches.min(MAX_WINDOWS) {
            // The spread schedule's second cache holds the next window's
            // rows before its jump: at most `shift - 1` of them (the jump's
            // own row goes to the first cache, which takes them over).
            let rows = match sc.schedule {
                CacheSchedule::Spread if i == 1 => (sc.shift as usize).clamp(1, m),
                _ => m,
            };
            let cache = GptCache::carve(
                a,
                sc.kv,
                g.n_layer_base as usize + g.n_layer_head as usize,
                streams,
                rows,
                c,
                g.n_head as usize,
            )?;
            gpt.push(cache).map_err(|_| ov())?;
        }
        // The backlog refusal admits `latency + 1 + pending_frames` unpulled
        // leader frames, `latency` the session's (with music pushed live
        // it may be the live latency: `Session::latency_frames`).
        let latency = sc.live_latency_frames(hop as u32) as usize;
        let extra = latency - sc.latency_frames(hop as u32) as usize;
        let roots_cap = latency + 2 + sc.pending_frames as usize;
        // Decoded, unpulled frames. Step k runs once leader frame
        // hop(k + a + e + 1) - 1 is in and then completes the frames of token
        // k + 1 - d, so at most hop(1 - a - e - d) frames are decoded beyond
        // those pushed; with at most latency + 1 + pending_frames pushed and
        // unpulled (the backlog refusal), at most pending_frames + hop + 1
        // decoded frames wait (the +1: latency 0 is not hop(a+e+d) - 1);
        // with music pushed live the refusal comes `extra` frames later
        // (the live latency), and as many more may wait.
        let pending_cap = (sc.pending_frames as usize)
            .checked_add(hop + 1 + extra)
            .ok_or(ov())?;
        Ok(State {
            block: a.f32(hop.checked_mul(POSE_DIM).ok_or(ov())?)?,
            part_in: a.f32(hop.checked_mul(pos).ok_or(ov())?)?,
            enc,
            kk: a.f32(4 * bins)?,
            kk_stride: bins,
            feat: a.f32(emb)?,
            leader_lat,
            music_lat,
            music: RowRing::carve(a, sc.music_buffer_frames as usize, g.music.n_in as usize)?,
            cond,
            cond_slack,
            codes: TokenRing::carve(a, codes_cap, 4)?,
            toks: TokenRing::carve(a, m + 1, 5)?,
            gpt,
            dec_pos,
            dec_rot,
            dec_out: a.f32(hop.checked_mul(pos.max(rot)).ok_or(ov())?)?,
            frames: a.f32(hop.checked_mul(FRAME_WIDTH).ok_or(ov())?)?,
            pending: RowRing::carve(a, pending_cap, FRAME_WIDTH)?,
            roots: RowRing::carve(a, roots_cap, 3)?,
        })
    }

    /// Squared codebook norms of the 4 part codebooks (the quantiser's `|k|^2`).
    pub fn init_codebooks(&mut self, model: &Model<'_>) {
        for p in 0..4 {
            let cb = &model.parts[p].codebook;
            let (emb, bins) = (model.parts[p].cfg.emb_width as usize, cb.rows());
            codebook_norms(
                cb,
                &mut self.feat[..emb],
                &mut self.kk[p * self.kk_stride..p * self.kk_stride + bins],
            );
        }
    }

    /// Back to an empty session (no allocation).
    pub fn reset(&mut self) {
        for s in self
            .enc
            .iter_mut()
            .chain(self.dec_pos.iter_mut())
            .chain(self.dec_rot.iter_mut().flatten())
        {
            s.reset();
        }
        for l in self.leader_lat.iter_mut() {
            l.reset();
        }
        self.music_lat.reset();
        self.music.clear();
        for r in self.cond.iter_mut() {
            r.clear();
        }
        self.codes.clear();
        self.toks.clear();
        for g in self.gpt.iter_mut() {
            g.reset();
        }
        self.pending.clear();
        self.roots.clear();
    }
}
