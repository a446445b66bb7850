"""S, the streaming semantics of Duolando (docs/STREAMING.md), as a full-sequence reference.

Everything here is computed the obvious way, over whole sequences, with no caches: a leader
code is the code of an encoder run on a truncated prefix, a LAT output is one row of a
masked full-sequence LAT, a GPT step is one full window forward, a follower frame is one
frame of a decoder run on a truncated token prefix. A streaming session (KV caches, LAT
rings, streaming convolutions) must reproduce these values; docs/STREAMING.md says how.
`StreamingSession` at the end of this file is such an incremental implementation, in
Python, used only to prove that the definition can be computed incrementally.

Time base (docs/STREAMING.md §1): frame f at 30 fps; token q covers frames [4q, 4q+4).
Step k (k = 0, 1, ...) predicts follower token k+1 from follower tokens <= k.
"""
import math
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np
import torch

from .pipeline import (MUSIC_MOTION_RATE, N_JOINTS, TRANSL_SCALE, Margins, denormalise_pos3d,
                       normalise_pos3d, prepare, window_context)
from .vqvae import PARTS

RATE = MUSIC_MOTION_RATE  # frames per token


# ----------------------------------------------------------------------------------------------
# Configuration
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StreamConfig:
    """The latency budget and window policy of S (docs/STREAMING.md §2).

    lookahead       a: leader look-ahead tokens, 0..=look_forward (first LAT layer only).
    enc_future      e: encoder future context, tokens, 0..=enc_future_max (code q is computed
                    from leader frames [0, 4(q+1+e))).
    dec_future      d: decoder future context, tokens, 0..=dec_future_max (frames of token q
                    are decoded from follower tokens [0, q+d]).
    shift           s: chunked GPT window (the original sample(shift=s)), 1..=block_size-1.
    music_lookahead music look-ahead tokens, 0..=look_forward; None = look_forward (music is
                    known ahead: a track).
    lat_past        past band of every LAT layer in LAT input units; None = look_forward*ds
                    (the original band).
    """
    lookahead: int
    enc_future: int
    dec_future: int
    shift: int
    music_lookahead: Optional[int] = None
    lat_past: Optional[int] = None
    lat_split: str = "first"   # study only: "first" (S) or "even" (look-ahead split over layers)
    lat_clip: str = "none"     # study only: "none" (S) or "window" (LAT inputs cut at the window start)

    def futures(self, lat_cfg, a):
        """Per-layer look-ahead in LAT input units: S puts all of it in the first layer."""
        ds, n = lat_cfg.downsample_rate, lat_cfg.n_layer
        if self.lat_split == "first":
            return [a * ds] + [0] * (n - 1)
        base = [(a // n + (1 if i < a % n else 0)) * ds for i in range(n)]
        return base

    def music_a(self, gpt):
        return gpt.look_forward if self.music_lookahead is None else self.music_lookahead

    def past(self, lat_cfg):
        return lat_cfg.look_forward * lat_cfg.downsample_rate if self.lat_past is None else self.lat_past * lat_cfg.downsample_rate

    def validate(self, gpt, vqvae, transl_vqvae):
        lf, m = gpt.look_forward, gpt.block_size - 1
        emax = max(enc_future_max(vqvae.part(p).hps) for p in PARTS)
        dmax = max(max(dec_future_max(vqvae.part(p).hps) for p in PARTS), dec_future_max(transl_vqvae.hps))
        checks = [(0 <= self.lookahead <= lf, f"lookahead {self.lookahead} not in 0..={lf}"),
                  (0 <= self.enc_future <= emax, f"enc_future {self.enc_future} not in 0..={emax}"),
                  (0 <= self.dec_future <= dmax, f"dec_future {self.dec_future} not in 0..={dmax}"),
                  (1 <= self.shift <= m, f"shift {self.shift} not in 1..={m}"),
                  (0 <= self.music_a(gpt) <= lf, f"music_lookahead {self.music_lookahead} not in 0..={lf}"),
                  (self.lat_past is None or 0 <= self.lat_past <= lf, f"lat_past {self.lat_past} not in 0..={lf}")]
        for ok, msg in checks:
            if not ok:
                raise ValueError(msg)


def default_config(gpt, vqvae, transl_vqvae):
    """Largest budget (closest to R): a = look_forward, e = e_max, d = d_max; s = 22 for the
    original block size 30 (scaled for smaller models: s = round(22/29 * (block_size-1)))."""
    m = gpt.block_size - 1
    return StreamConfig(lookahead=gpt.look_forward,
                        enc_future=max(enc_future_max(vqvae.part(p).hps) for p in PARTS),
                        dec_future=max(max(dec_future_max(vqvae.part(p).hps) for p in PARTS),
                                       dec_future_max(transl_vqvae.hps)),
                        shift=max(1, min(m, round(22 * m / 29))))


def minimum_config(gpt, shift):
    """Smallest budget: no leader look-ahead, no encoder or decoder future context."""
    return StreamConfig(lookahead=0, enc_future=0, dec_future=0, shift=shift)


# ----------------------------------------------------------------------------------------------
# Receptive fields of the conv stacks (interval arithmetic, exact)
# ----------------------------------------------------------------------------------------------

def _conv_in(lo, hi, k, s, p, d=1):
    """Input interval read by conv outputs [lo, hi]: out t reads [t*s - p, t*s - p + d*(k-1)]."""
    return lo * s - p, hi * s - p + d * (k - 1)


def _convt_in(lo, hi, k, s, p):
    """Input interval read by transposed-conv outputs [lo, hi]: input i writes outputs
    [i*s - p, i*s - p + k - 1]."""
    return math.ceil((lo + p - (k - 1)) / s), (hi + p) // s


def _res_in(lo, hi, dils):
    for dil in dils:
        lo, hi = lo - dil, hi + dil  # k3, dilation dil, pad dil (+ identity, + 1x1)
    return lo, hi


def encoder_cone(hps, q):
    """Frames [lo, hi] that pre-quantisation feature q depends on (original padding)."""
    s, down = hps.strides_t[0], hps.downs_t[0]
    dils = [hps.dilation_growth_rate ** i for i in range(hps.depth)]
    lo, hi = _conv_in(q, q, 3, 1, 1)                  # final Conv1d k3 p1
    for _ in range(down):
        lo, hi = _res_in(lo, hi, dils[::-1])          # Resnet1D (order irrelevant for the cone)
        lo, hi = _conv_in(lo, hi, 2 * s, s, s // 2)   # Conv1d k=2s stride s pad s//2
    return lo, hi


def decoder_cone(hps, f):
    """Tokens [lo, hi] that decoded frame f depends on."""
    s, down = hps.strides_t[0], hps.downs_t[0]
    dils = [hps.dilation_growth_rate ** i for i in range(hps.depth)]
    lo, hi = _conv_in(f, f, 3, 1, 1)                  # out Conv1d k3 p1
    for _ in range(down):
        lo, hi = _convt_in(lo, hi, 2 * s, s, s // 2)  # ConvTranspose1d k=2s stride s pad s//2
        lo, hi = _res_in(lo, hi, dils)
    return _conv_in(lo, hi, 3, 1, 1)                  # first Conv1d k3 p1


def enc_future_max(hps):
    """Smallest e such that code q computed from frames [0, 4(q+1+e)) equals the
    full-sequence code (the whole receptive field is inside the prefix)."""
    q = 10_000
    _, hi = encoder_cone(hps, q)
    return max(0, math.ceil((hi + 1 - RATE * (q + 1)) / RATE))


def dec_future_max(hps):
    """Smallest d such that frames of token q decoded from tokens [0, q+d] equal the
    full-sequence decode."""
    q = 10_000
    return max(max(decoder_cone(hps, RATE * q + r)[1] for r in range(RATE)) - q, 0)


# ----------------------------------------------------------------------------------------------
# Latency and availability (docs/STREAMING.md §4)
# ----------------------------------------------------------------------------------------------

def n_steps(cfg, gpt, t4):
    """Steps S runs on T4 frames: step k needs leader code k+a (frames < 4(k+a+1+e)) and music
    LAT token k (music frames < 4(k+2+a_m)). No end-of-stream handling: a step runs only when
    every input it needs exists."""
    q = t4 // RATE
    return max(0, min(q - cfg.lookahead - cfg.enc_future, q - 1 - cfg.music_a(gpt)))


def step_ready_frame(cfg, k):
    """Index of the leader frame after whose push step k can run (music preloaded)."""
    return RATE * (k + cfg.lookahead + cfg.enc_future + 1) - 1


def frame_ready_frame(cfg, f):
    """Index of the leader frame after whose push follower frame f is ready: its token's
    frames need tokens <= f//4 + d (token j >= 1 is known after step j - 1, token 0 is the
    seed) and the leader root at f. Music preloaded."""
    q = f // RATE
    if q + cfg.dec_future == 0:  # token 0 is the seed, known before any leader frame
        return f
    return max(f, RATE * (q + cfg.lookahead + cfg.enc_future + cfg.dec_future) - 1)


def latency_frames(cfg):
    """max over f of frame_ready_frame(f) - f = max(0, 4(a+e+d) - 1)."""
    return max(0, RATE * (cfg.lookahead + cfg.enc_future + cfg.dec_future) - 1)


# ----------------------------------------------------------------------------------------------
# Top-k sampling with an explicit RNG (docs/STREAMING.md §3.6)
# ----------------------------------------------------------------------------------------------

MASK64 = (1 << 64) - 1


class SplitMix64:
    """splitmix64 (Steele, Lea, Flood 2014): state += 0x9E3779B97F4A7C15; z = state;
    z = (z ^ z>>30) * 0xBF58476D1CE4E5B9; z = (z ^ z>>27) * 0x94D049BB133111EB; z ^ z>>31.
    All arithmetic mod 2^64."""

    def __init__(self, seed):
        self.state = int(seed) & MASK64

    def next_u64(self):
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        return z ^ (z >> 31)

    def below(self, k):
        """r in [0, k): r = ((next_u64() >> 32) * k) >> 32 (one draw, no rejection)."""
        return ((self.next_u64() >> 32) * k) >> 32


def topk_set(logits, k):
    """The k token ids with the largest logits (ties: the lower id ranks first), returned in
    ASCENDING id order. logits: 1-D tensor."""
    order = sorted(range(logits.shape[0]), key=lambda i: (-float(logits[i]), i))
    return sorted(order[:k])


def choose(logits, topk, rng):
    """Greedy (topk None): argmax, lower id on ties, no draw. Top-k: one draw r = rng.below(k),
    pick the r-th id of the top-k set in ascending id order (uniform over the top-k set, like
    the original GPT2nt.samplek)."""
    if topk is None:
        return int(torch.argmax(logits))
    return topk_set(logits, topk)[rng.below(topk)]


# ----------------------------------------------------------------------------------------------
# The modules under S
# ----------------------------------------------------------------------------------------------

def stream_codes(part_vae, x, n_codes, enc_future, margins=None, zero_first_joint=True):
    """S encoder: code q = nearest code of feature q of the encoder run on x[:, :min(T, 4(q+1+e))]
    (zero padding at that prefix end, as at a sequence end). x (1, T, C), T % 4 == 0.
    Returns (1, n_codes) int64."""
    x = x.clone()
    if zero_first_joint:
        x[:, :, :part_vae.hps.joint_channel] = 0
    t = x.shape[1]
    block = part_vae.bottleneck.level_blocks[0]
    codes = []
    for q in range(n_codes):
        n = min(t, RATE * (q + 1 + enc_future))
        feat = part_vae.features(x[:, :n])[:, :, q:q + 1]  # (1, emb, 1)
        if margins is not None:
            margins.vq(block, feat)
        codes.append(block.encode(feat)[0, 0])
    return torch.stack(codes).view(1, -1)


def lat_masks(n, past, futures):
    """Per-layer (n, n) 0/1 masks of the S LAT: in layer l, query p sees keys p' with
    max(0, p - past) <= p' <= p + futures[l]. S: futures = (F, 0, ..., 0)."""
    i = torch.arange(n)[:, None]
    j = torch.arange(n)[None, :]
    return [((j >= i - past) & (j <= i + fut)).float() for fut in futures]


def run_lat(lat, x, past, first_future, futures=None):
    """S LAT over a whole input sequence x (1, N*ds, n_in) -> (1, N, E): the original blocks
    with the S masks, then the ds-frame concat + downsample Linear. Row j is final once input
    position (j+1)*ds - 1 + sum(futures) exists. futures None = (first_future, 0, ..., 0)."""
    ds = lat.cfg.downsample_rate
    n = x.shape[1]
    if futures is None:
        futures = [first_future] + [0] * (len(lat.blocks) - 1)
    h = lat.cond_emb(x)
    for blk, mask in zip(lat.blocks, lat_masks(n, past, futures)):
        h = h + blk.attn.attend(blk.ln1(h), mask)
        h = h + blk.mlp(blk.ln2(h))
    b, l, c = h.shape
    return lat.downsample(h.reshape(b, l // ds, c * ds))


LEADER_LATS = ("leader_up_trans", "leader_down_trans", "leader_lhand_trans", "leader_rhand_trans")
LEADER_EMBS = ("tok_emb_up", "tok_emb_down", "tok_emb_lhand", "tok_emb_rhand")
FOLLOWER_EMBS = ("tok_emb_up", "tok_emb_down", "tok_emb_lhand", "tok_emb_lhand", "tok_emb_transl")  # rhand quirk


def conditions(gpt, cfg, cond_music, leader_codes, n_cond, left=0):
    """The 5 frozen condition streams (music, L_up, L_down, L_lh, L_rh), each (1, n_cond, E)
    (rows < left are zero: never used). cond_music (1, >= 4(n_cond + a_m), 54) = music from
    frame 4; leader_codes 4 x (1, >= n_cond + a). LAT inputs before token `left` are cut off
    (left > 0 only for the lat_clip="window" variant)."""
    ml = gpt.music_trans
    a_m = cfg.music_a(gpt)
    rows = n_cond - left
    mus = cond_music[:, RATE * left:RATE * (n_cond + a_m)]  # music positions rows need
    out = [run_lat(ml, mus, cfg.past(ml.cfg), RATE * a_m, cfg.futures(ml.cfg, a_m))[:, :rows]]
    for lat_name, emb_name, codes in zip(LEADER_LATS, LEADER_EMBS, leader_codes):
        lat = getattr(gpt, lat_name)
        toks = codes[:, left:n_cond + cfg.lookahead]
        out.append(run_lat(lat, getattr(gpt, emb_name)(toks), cfg.past(lat.cfg), cfg.lookahead,
                           cfg.futures(lat.cfg, cfg.lookahead))[:, :rows])
    if left:
        out = [torch.cat([o.new_zeros(1, left, o.shape[2]), o], dim=1) for o in out]
    return out


def window_logits(gpt, conds, hist, lo, hi):
    """One GPT window over token positions [lo, hi): streams = 5 frozen conditions + 5 follower
    token embeddings, position rows s*block_size + (j - lo). Logits of the 5 heads at the last
    position, (5, V)."""
    streams = [c[:, lo:hi] for c in conds]
    streams += [getattr(gpt, e)(hist[:, lo:hi, i]) for i, e in enumerate(FOLLOWER_EMBS)]
    logits = gpt.gpt_head(gpt.gpt_base(streams))
    return torch.stack([lg[0, -1] for lg in logits])


def stream_decode(vqvae, transl_vqvae, tokens, dec_future, n_frames):
    """S decoders: frames [4q, 4q+4) = those frames of the decoders run on tokens[:q+d+1]
    (zero padding at that prefix end). tokens (N, 5) -> pos (n_frames, 165) normalised layout,
    rot (n_frames, 495), transl (n_frames, 3)."""
    n_tok = tokens.shape[0]
    pos, rot, tr = [], [], []
    for q in range(n_frames // RATE):
        hi = min(n_tok, q + dec_future + 1)
        zs = tuple(tokens[None, :hi, i] for i in range(4))
        p, r = vqvae.decode(zs)
        t = transl_vqvae.decode(tokens[None, :hi, 4])
        sl = slice(RATE * q, RATE * (q + 1))
        pos.append(p[0, sl])
        rot.append(r[0, sl])
        tr.append(t[0, sl])
    cat = lambda xs, w: torch.cat(xs) if xs else torch.zeros(0, w)  # noqa: E731
    return cat(pos, 165), cat(rot, 495), cat(tr, 3)


def to_world(pos, transl, l_root):
    """Follower joints in the leader's input coordinates (same rule as R)."""
    n = pos.shape[0]
    pos = pos.clone()
    pos[:, :3] = (l_root[:n] - l_root[:1]) + transl / TRANSL_SCALE
    pos = denormalise_pos3d(pos)
    return pos + l_root[:1].repeat(1, N_JOINTS)


# ----------------------------------------------------------------------------------------------
# The S rollout
# ----------------------------------------------------------------------------------------------

class DecisionMargins(Margins):
    """Margins plus the top-k boundary margin (k-th minus (k+1)-th logit, relative)."""
    topk_rel: float = float("inf")

    def boundary(self, lg, k):
        top = torch.topk(lg.double(), k + 1).values
        gap = float(top[k - 1] - top[k]) / float(lg.abs().max())
        self.topk_rel = min(self.topk_rel, gap)
        if gap < self.logit_floor:
            from .pipeline import MarginTooSmall
            raise MarginTooSmall(f"top-k boundary margin {gap:.3g} < {self.logit_floor}")


@torch.no_grad()
def s_rollout(gpt, cfg, codes, cond_music, hist0, n_k, forced=None, topk=None, rng_seed=0, margins=None,
              logits_out=None):
    """The GPT part of S on token-level inputs: n_k steps of the chunked window over frozen
    conditions. codes 4 x (1, >= n_k + a) S leader codes; cond_music (1, >= 4(n_k + a_m), 54)
    (music from frame 4); hist0 (5,) seed; forced (n >= n_k + 1, 5) or None; logits_out: a
    list that receives the (5, V) logits of every step (study only).
    Returns (tokens (n_k+1, 5), pred (n_k, 5), context list, window_lo list)."""
    m = gpt.block_size - 1
    hist = torch.as_tensor(hist0, dtype=torch.long).view(1, 1, 5)
    rng = SplitMix64(rng_seed)
    conds, conds_lo = None, None
    preds, ctxs, los = [], [], []
    for k in range(n_k):
        c = window_context(k, m, cfg.shift)
        lo = k + 1 - c
        if conds is None or (cfg.lat_clip == "window" and lo != conds_lo):
            left = lo if cfg.lat_clip == "window" else 0
            conds, conds_lo = conditions(gpt, cfg, cond_music, codes, n_k, left), lo
        lg = window_logits(gpt, conds, hist, lo, k + 1)
        if logits_out is not None:
            logits_out.append(lg)
        step = []
        for h in range(5):
            if margins is not None:
                if topk is None:
                    margins.logits(lg[h])
                else:
                    margins.boundary(lg[h], topk)
            step.append(choose(lg[h], topk, rng))
        nxt = torch.tensor(step, dtype=torch.long)
        preds.append(nxt)
        ctxs.append(c)
        los.append(lo)
        app = forced[k + 1] if forced is not None else nxt
        hist = torch.cat([hist, app.view(1, 1, 5)], dim=1)
    pred = torch.stack(preds) if preds else torch.zeros(0, 5, dtype=torch.long)
    return hist[0], pred, ctxs, los


@torch.no_grad()
def generate_streaming(gpt, vqvae, transl_vqvae, leader, music, cfg, seed_tokens=None,
                       follower_start=None, forced=None, topk=None, rng_seed=0, margins=None):
    """Full-sequence reference of S.

    leader (T, 165) raw world joints, music (>= T, 54); the seed as in R (exactly one of
    seed_tokens (5,), follower_start (F, 165)); or forced (n, 5) int: forced-history mode, the
    follower history at step k is forced[0..=k] (forced[0] is the seed), S's choice at step k
    is reported in `pred` but never enters the history.
    topk None = greedy; else uniform over the top-k set with SplitMix64(rng_seed), 5 draws per
    step in head order (up, down, lhand, rhand, transl).

    Returns dict (torch tensors unless noted):
      tokens (K_S+1, 5)    history: row 0 seed, row k+1 = token appended by step k
      pred (K_S, 5)        S's choice at step k (== tokens[k+1] unless forced)
      leader_tokens (Q, 4) S leader codes for q < K_S + a (-1 beyond: never computed)
      follower_pos3d (N, 165), follower_rotmat (N, 495), N = 4*(K_S + 1 - d) frames
      step_ready (K_S,), frame_ready (N,) int64: leader frame indices (see *_ready_frame)
      context (K_S,), window_lo (K_S,) int64: GPT window per step
      K (int), T4 (int), latency_frames (int)
    """
    cfg.validate(gpt, vqvae, transl_vqvae)
    if forced is not None:
        forced = torch.as_tensor(np.asarray(forced), dtype=torch.long)
        if forced.ndim != 2 or forced.shape[1] != 5 or forced.shape[0] < 1:
            raise ValueError(f"forced must be (n >= 1, 5), got {tuple(forced.shape)}")
        if seed_tokens is not None or follower_start is not None:
            raise ValueError("forced mode takes its seed from forced[0]")
        seed_tokens = forced[0].numpy()
    _, xs, music_t, l_root, t4 = prepare(gpt, vqvae, transl_vqvae, leader, music, seed_tokens,
                                         follower_start, margins)
    leader_t = torch.as_tensor(np.asarray(leader), dtype=music_t.dtype)[:t4]
    n_k = n_steps(cfg, gpt, t4)
    if forced is not None:
        n_k = min(n_k, forced.shape[0] - 1)
    q_all = t4 // RATE

    # Leader codes under S (truncated-prefix encoder), only those some step needs.
    l_norm = normalise_pos3d(leader_t)
    l_norm[:, :3] = 0
    n_codes = n_k + cfg.lookahead if n_k > 0 else 0
    codes = tuple(stream_codes(vqvae.part(p), vqvae.split(l_norm[None], p), n_codes, cfg.enc_future, margins)
                  for p in PARTS)

    hist0 = torch.cat([x.view(1) for x in xs]).to(torch.long)
    tokens, pred, ctxs, los = s_rollout(gpt, cfg, codes, music_t[RATE:][None], hist0, n_k, forced,
                                        topk, rng_seed, margins)

    n_frames = RATE * max(0, n_k + 1 - cfg.dec_future)
    pos, rot, tr = stream_decode(vqvae, transl_vqvae, tokens, cfg.dec_future, n_frames)
    pos = to_world(pos, tr, l_root)
    lt = torch.full((q_all, 4), -1, dtype=torch.long)
    if n_codes:
        lt[:n_codes] = torch.cat(codes, dim=0).t()
    return {
        "tokens": tokens,
        "pred": pred,
        "leader_tokens": lt,
        "follower_pos3d": pos,
        "follower_rotmat": rot,
        "step_ready": torch.tensor([step_ready_frame(cfg, k) for k in range(n_k)], dtype=torch.long),
        "frame_ready": torch.tensor([frame_ready_frame(cfg, f) for f in range(n_frames)], dtype=torch.long),
        "context": torch.tensor(ctxs, dtype=torch.long),
        "window_lo": torch.tensor(los, dtype=torch.long),
        "K": n_k,
        "T4": t4,
        "latency_frames": latency_frames(cfg),
    }


# ----------------------------------------------------------------------------------------------
# Incremental implementation (proof that S can be computed with caches; docs/STREAMING.md §5)
# ----------------------------------------------------------------------------------------------
# Written like a session: every module keeps only the state named in docs/STREAMING.md and
# asserts that it never reads an older entry than its ring holds. Not optimised; used by
# tools/streaming_study.py `incremental` to check it reproduces generate_streaming.

class Ring:
    """A fixed-capacity window over an append-only sequence of tensors: get(i) fails unless
    i is among the last `cap` appended. Records the oldest age ever read (`max_age`)."""

    def __init__(self, cap, name):
        self.cap, self.name, self.items, self.n, self.max_age = cap, name, {}, 0, 0

    def push(self, x):
        self.items[self.n] = x
        self.items.pop(self.n - self.cap, None)
        self.n += 1

    def get(self, i):
        if not (self.n - self.cap <= i < self.n):
            raise AssertionError(f"{self.name}: read {i} outside the last {self.cap} of {self.n}")
        self.max_age = max(self.max_age, self.n - i)
        return self.items[i]

    def reset(self):
        self.items, self.n = {}, 0


class StreamConv:
    """Truncated-prefix streaming of one conv stack (VQ encoder or decoder).

    units: list of (kind, module, k, stride, pad, dil), kind in conv / res / convt; `ch` the
    input channel count of each unit. Each unit keeps a ring of its SETTLED input columns (those
    that no longer depend on the end-of-prefix zero padding); per `feed`, the unsettled tail of
    every unit is recomputed from its ring plus the tail of the unit below, with zeros past the
    current end (exactly what the full conv on the prefix computes)."""

    def __init__(self, units, chans, caps, name):
        self.units, self.chans = units, chans
        self.rings = [Ring(c, f"{name}.unit{i}") for i, c in enumerate(caps)]
        self.settled_out = [0] * len(units)  # settled output count per unit
        self.tail_sizes = [0] * len(units)   # max recomputed (unsettled) outputs per feed

    @staticmethod
    def out_len(kind, n, k, s, p, d):
        if kind == "convt":
            return (n - 1) * s - 2 * p + k
        return (n + 2 * p - d * (k - 1) - 1) // s + 1

    @staticmethod
    def last_in(kind, t, k, s, p, d):
        """Largest input index output t reads."""
        return (t + p) // s if kind == "convt" else t * s - p + d * (k - 1)

    def apply(self, u, col, n_in, t0, t1):
        """Outputs [t0, t1) of unit u given input columns col(i) (zero outside [0, n_in))."""
        kind, mod, k, s, p, d = self.units[u]
        if kind == "convt":
            i0, i1 = math.ceil((t0 + p - (k - 1)) / s), (t1 - 1 + p) // s + 1
        else:
            i0, i1 = t0 * s - p, (t1 - 1) * s - p + d * (k - 1) + 1
        zero = torch.zeros(self.chans[u])
        x = torch.stack([col(i) if 0 <= i < n_in else zero for i in range(i0, i1)], dim=1)[None]
        if kind == "conv":
            y = torch.nn.functional.conv1d(x, mod.weight, mod.bias, s, 0, d)
        elif kind == "res":
            c1, c2 = mod.model[1], mod.model[3]
            h = torch.nn.functional.conv1d(torch.relu(x), c1.weight, c1.bias, 1, 0, d)
            y = x[:, :, d:d + h.shape[2]] + c2(torch.relu(h))
        else:
            y = torch.nn.functional.conv_transpose1d(x, mod.weight, mod.bias, s, 0)
            off = t0 - (i0 * s - p)
            y = y[:, :, off:off + (t1 - t0)]
        return y[0]

    def feed(self, cols):
        """cols (C, n_new): settled input columns appended. Returns (n_out, settled_out,
        col(t)) of the last unit for the current prefix (tail values valid until the next feed)."""
        ring0 = self.rings[0]
        for j in range(cols.shape[1]):
            ring0.push(cols[:, j])
        n_in = n_set_in = ring0.n
        col = ring0.get
        for u, (kind, _, k, s, p, d) in enumerate(self.units):
            n_out = self.out_len(kind, n_in, k, s, p, d)
            lo = self.settled_out[u]
            t = lo
            while t < n_out and self.last_in(kind, t, k, s, p, d) < n_set_in:
                t += 1
            new_set = t
            vals = self.apply(u, col, n_in, lo, n_out) if n_out > lo else torch.zeros(self.chans[u], 0)
            self.tail_sizes[u] = max(self.tail_sizes[u], n_out - new_set)
            got = {j: vals[:, j - lo] for j in range(lo, n_out)}
            if u + 1 < len(self.units):
                nxt = self.rings[u + 1]
                for j in range(lo, new_set):
                    nxt.push(got[j])
                col = (lambda r, tl: (lambda i: tl[i] if i in tl else r.get(i)))(nxt, got)
            else:  # the stack output: a small ring of settled outputs plus the current tail
                if not hasattr(self, "out_ring"):
                    self.out_ring = Ring(8, "out")
                for j in range(lo, new_set):
                    self.out_ring.push(got[j])
                col = (lambda r, tl: (lambda i: tl[i] if i in tl and i >= r.n else r.get(i)))(self.out_ring, got)
            self.settled_out[u] = new_set
            n_in, n_set_in = n_out, new_set
        return n_in, n_set_in, col


def encoder_units(part_vae):
    blocks = part_vae.encoders[0].level_blocks[0].model
    units = []
    for lvl in blocks[:-1]:
        c = lvl[0]
        units.append(("conv", c, c.kernel_size[0], c.stride[0], c.padding[0], 1))
        for r in lvl[1].model:
            cv = r.model[1]
            units.append(("res", r, 3, 1, cv.padding[0], cv.dilation[0]))
    c = blocks[-1]
    units.append(("conv", c, 3, 1, 1, 1))
    return units


def decoder_units(decoder):
    blocks = decoder.level_blocks[0].model
    c = blocks[0]
    units = [("conv", c, 3, 1, 1, 1)]
    for lvl in blocks[1:]:
        for r in lvl[0].model:
            cv = r.model[1]
            units.append(("res", r, 3, 1, cv.padding[0], cv.dilation[0]))
        t = lvl[1]
        units.append(("convt", t, t.kernel_size[0], t.stride[0], t.padding[0], 1))
    units.append(("conv", decoder.out, 3, 1, 1, 1))
    return units


def _attend(mod, q_rows, k_rows, v_rows):
    """Multi-head attention of query rows (n, E) over key/value rows (m, E), all allowed."""
    h = mod.n_head
    n, e = q_rows.shape
    q = q_rows.view(n, h, e // h).transpose(0, 1)            # (h, n, hs)
    k = k_rows.view(-1, h, e // h).transpose(0, 1)           # (h, m, hs)
    v = v_rows.view(-1, h, e // h).transpose(0, 1)
    att = torch.softmax((q @ k.transpose(1, 2)) * (1.0 / math.sqrt(e // h)), dim=-1)
    return mod.proj((att @ v).transpose(0, 1).reshape(n, e))


class IncLat:
    """Incremental S LAT: per layer a K/V ring (layer 1: past + 1 + F entries, others past + 1)
    and, for layer 1, a ring of the F + 1 newest residual inputs; ds rows of the last layer are
    concatenated into one output row."""

    def __init__(self, lat, past, fut, name):
        self.lat, self.past, self.fut, self.ds = lat, past, fut, lat.cfg.downsample_rate
        n = len(lat.blocks)
        self.kv = [Ring(past + 1 + (fut if l == 0 else 0), f"{name}.kv{l}") for l in range(n)]
        self.h0 = Ring(fut + 1, f"{name}.h0")
        self.last = Ring(self.ds, f"{name}.out")
        self.rows = []  # output rows (the caller keeps what it needs in its own ring)

    def push(self, x):
        """x (n_in,) one LAT input position (a music frame or a leader token embedding)."""
        blk0 = self.lat.blocks[0]
        h0 = self.lat.cond_emb(x)
        ln = blk0.ln1(h0)
        self.kv[0].push((blk0.attn.key(ln), blk0.attn.value(ln)))
        self.h0.push(h0)
        p = self.h0.n - 1 - self.fut  # layer-1 output position now computable
        if p < 0:
            return
        h = self.h0.get(p)
        for l, blk in enumerate(self.lat.blocks):
            if l > 0:
                ln = blk.ln1(h)
                self.kv[l].push((blk.attn.key(ln), blk.attn.value(ln)))
            keys = range(max(0, p - self.past), p + (self.fut if l == 0 else 0) + 1)
            kv = [self.kv[l].get(j) for j in keys]
            q = blk.attn.query(blk.ln1(h))[None]
            h = h + _attend(blk.attn, q, torch.stack([a for a, _ in kv]), torch.stack([b for _, b in kv]))[0]
            h = h + blk.mlp(blk.ln2(h))
        self.last.push(h)
        if (p + 1) % self.ds == 0:
            cat = torch.cat([self.last.get(p - self.ds + 1 + i) for i in range(self.ds)])
            self.rows.append(self.lat.downsample(cat))


class IncGpt:
    """GPT with one K/V cache per layer (10 streams x block_size - 1 positions); a step whose
    window start differs from the previous one re-prefills the whole window."""

    def __init__(self, gpt):
        self.gpt = gpt
        self.blocks = list(gpt.gpt_base.blocks) + list(gpt.gpt_head.blocks)
        self.m = gpt.block_size - 1
        self.lo = None
        self.cache = [[] for _ in self.blocks]  # per layer: list of (k (10, E), v (10, E)) per position
        self.positions_computed = 0
        self.max_positions_per_step = 0

    def _position(self, x):
        """x (10, E) the 10 stream inputs of the next window position -> (10, E) last hidden."""
        for l, blk in enumerate(self.blocks):
            ln = blk.ln1(x)
            self.cache[l].append((blk.attn.key(ln), blk.attn.value(ln)))
            if len(self.cache[l]) > self.m:
                raise AssertionError("GPT cache over capacity")
            ks = torch.cat([k for k, _ in self.cache[l]])
            vs = torch.cat([v for _, v in self.cache[l]])
            x = x + _attend(blk.attn, blk.attn.query(ln), ks, vs)
            x = x + blk.mlp(blk.ln2(x))
        return x

    def step(self, lo, k, inputs):
        """inputs(j, i) -> (10, E) stream inputs of token position j at window row i.
        Returns logits (5, V) at token k."""
        bs = self.gpt.block_size
        pos = self.gpt.gpt_base.pos_emb[0]
        if lo != self.lo:
            self.lo, self.cache = lo, [[] for _ in self.blocks]
            todo = range(lo, k + 1)
        else:
            todo = range(k, k + 1)
        for j in todo:
            i = j - lo
            x = inputs(j) + torch.stack([pos[s * bs + i] for s in range(10)])
            h = self._position(x)
        self.positions_computed += len(todo)
        self.max_positions_per_step = max(self.max_positions_per_step, len(todo))
        g = self.gpt.gpt_head
        heads = (g.head_up, g.head_down, g.head_lhand, g.head_rhand, g.head_transl)
        return torch.stack([hd(h[5 + i]) for i, hd in enumerate(heads)])


class StreamingSession:
    """Incremental S session (Python model of the Rust one): push leader frames one by one,
    music preloaded; follower frames come out as soon as they are ready."""

    def __init__(self, gpt, vqvae, transl_vqvae, cfg, music, hist0, topk=None, rng_seed=0,
                 forced=None, conv_caps=None):
        self.g, self.vq, self.tr, self.cfg = gpt, vqvae, transl_vqvae, cfg
        self.lf, self.m = gpt.look_forward, gpt.block_size - 1
        self.cond_music = torch.as_tensor(np.asarray(music), dtype=torch.float32)[RATE:]
        self.topk, self.rng, self.forced = topk, SplitMix64(rng_seed), forced
        caps = conv_caps or {}
        big = 1 << 30
        self.enc = {p: StreamConv(encoder_units(vqvae.part(p)), self._chans(encoder_units(vqvae.part(p)), vqvae.part(p).hps.pos_channel),
                                  caps.get("enc", [big] * 20), f"enc_{p}") for p in PARTS}
        self.dec = {}
        for p in PARTS:
            for nm, d in (("pos", vqvae.part(p).decoders[0]), ("rot", vqvae.part(p).decoders_rot[0])):
                u = decoder_units(d)
                self.dec[(p, nm)] = StreamConv(u, self._chans(u, vqvae.part(p).hps.emb_width), caps.get("dec", [big] * 20), f"dec_{p}_{nm}")
        u = decoder_units(transl_vqvae.decoders[0])
        self.dec[("transl", "pos")] = StreamConv(u, self._chans(u, transl_vqvae.hps.emb_width), caps.get("dec", [big] * 20), "dec_transl")
        a, am = cfg.lookahead, cfg.music_a(gpt)
        self.music_lat = IncLat(gpt.music_trans, cfg.past(gpt.music_trans.cfg), RATE * am, "music_lat")
        self.leader_lats = [IncLat(getattr(gpt, n), cfg.past(getattr(gpt, n).cfg), a, n) for n in LEADER_LATS]
        self.music_fed = 0
        self.gptc = IncGpt(gpt)
        self.cond = [Ring(self.m, f"cond{s}") for s in range(5)]   # frozen condition rows
        self.toks = Ring(self.m + 1, "tokens")                      # follower history
        self.toks.push(torch.as_tensor(hist0, dtype=torch.long).view(5))
        self.roots = Ring(latency_frames(cfg) + 8, "leader_root")
        self.n_frames = 0      # leader frames pushed
        self.n_codes = 0       # leader codes emitted
        self.k = 0             # next step
        self.dec_fed = 0       # tokens fed to the decoders
        self.dec_out = {}      # decoder col functions of the last feed
        self.emitted = 0       # follower frames emitted
        self.l_root0 = None
        self.tokens, self.preds, self.codes = [self.toks.get(0)], [], []
        # decoded frames waiting for their leader root (at most latency + 4 frames)
        self.pending_out = Ring(latency_frames(cfg) + 2 * RATE, "pending_out")
        self._feed_decoders()

    @staticmethod
    def _chans(units, c_in):
        out = []
        for kind, mod, *_ in units:
            out.append(c_in)
            c_in = mod.model[3].out_channels if kind == "res" else mod.out_channels
        return out

    def _feed_decoders(self):
        tok = self.toks.get(self.toks.n - 1)
        for (p, nm), sc in self.dec.items():
            if p == "transl":
                z = self.tr.bottleneck.level_blocks[0].k[tok[4]]
            else:
                z = self.vq.part(p).bottleneck.level_blocks[0].k[tok[PARTS.index(p)]]
            self.dec_out[(p, nm)] = sc.feed(z[:, None])
        self.dec_fed += 1
        q = self.dec_fed - 1 - self.cfg.dec_future  # token whose 4 frames are now final
        if q < 0:
            return
        for f in range(RATE * q, RATE * (q + 1)):
            pos = torch.zeros(55, 3)
            rot = torch.zeros(55, 9)
            for p in PARTS:
                pos[PART_JOINTS_T[p]] = self.dec_out[(p, "pos")][2](f).view(-1, 3)
                rot[PART_JOINTS_T[p]] = self.dec_out[(p, "rot")][2](f).view(-1, 9)
            self.pending_out.push((pos.view(165), rot.view(495), self.dec_out[("transl", "pos")][2](f)))

    def push_leader_frame(self, frame):
        frame = torch.as_tensor(np.asarray(frame), dtype=torch.float32).view(1, 165)
        if self.l_root0 is None:
            self.l_root0 = frame[0, :3].clone()
        self.roots.push(frame[0, :3].clone())
        norm = normalise_pos3d(frame)
        norm[:, :3] = 0
        self.pending = getattr(self, "pending", []) + [norm]
        self.n_frames += 1
        if self.n_frames % RATE == 0:
            block = torch.cat(self.pending)[None]  # (1, 4, 165)
            self.pending = []
            outs = {}
            for p in PARTS:
                x = self.vq.split(block, p)[0].clone()
                x[:, :3] = 0
                outs[p] = self.enc[p].feed(x.t())
            q = self.n_frames // RATE - 1 - self.cfg.enc_future
            if q >= 0:
                code = []
                for p in PARTS:
                    _, _, col = outs[p]
                    blk = self.vq.part(p).bottleneck.level_blocks[0]
                    code.append(int(blk.encode(col(q)[None, :, None])[0, 0]))
                self.codes.append(code)
                for i, (lat, emb) in enumerate(zip(self.leader_lats, LEADER_EMBS)):
                    lat.push(getattr(self.g, emb)(torch.tensor(code[i])))
                self.n_codes += 1
        self._run_steps()

    def _music_rows(self, n):
        while len(self.music_lat.rows) < n:
            self.music_lat.push(self.cond_music[self.music_fed])
            self.music_fed += 1

    def _run_steps(self):
        while all(len(l.rows) > self.k for l in self.leader_lats):
            k = self.k
            if RATE * (k + 1 + self.cfg.music_a(self.g)) > self.cond_music.shape[0]:
                return
            self._music_rows(k + 1)
            self.cond[0].push(self.music_lat.rows[k])
            for s, lat in enumerate(self.leader_lats):
                self.cond[s + 1].push(lat.rows[k])
            c = window_context(k, self.m, self.cfg.shift)
            lo = k + 1 - c

            def inputs(j):  # (10, E) stream inputs of token position j (without position rows)
                t = self.toks.get(j)
                rows = [self.cond[s].get(j) for s in range(5)]
                rows += [getattr(self.g, FOLLOWER_EMBS[i])(t[i]) for i in range(5)]
                return torch.stack(rows)
            lg = self.gptc.step(lo, k, inputs)
            nxt = torch.tensor([choose(lg[h], self.topk, self.rng) for h in range(5)], dtype=torch.long)
            self.preds.append(nxt)
            app = torch.as_tensor(self.forced[k + 1]) if self.forced is not None else nxt
            self.toks.push(app)
            self.tokens.append(app)
            self._feed_decoders()
            self.k += 1

    def pull(self):
        """Follower frames ready now: list of (f, pos (165,), rot (495,)). Frame f is ready when
        its token's frames are final (token f//4 + d fed to the decoders) and leader frame f has
        been pushed (its root)."""
        out = []
        while self.emitted < self.pending_out.n and self.emitted < self.n_frames:
            f = self.emitted
            pos, rot, tr = self.pending_out.get(f)
            pos = pos.clone().view(1, 165)
            pos[0, :3] = (self.roots.get(f) - self.l_root0) + tr / TRANSL_SCALE
            pos = denormalise_pos3d(pos) + self.l_root0.repeat(N_JOINTS)
            out.append((f, pos[0], rot))
            self.emitted += 1
        return out


from .vqvae import PART_JOINTS as _PJ  # noqa: E402
PART_JOINTS_T = {p: torch.tensor(v) for p, v in _PJ.items()}
