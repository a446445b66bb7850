"""Follower GPT of Duolando (original models/gpt2nt_woln.py, class GPT2nt), inference only.

Pieces, named after the paper:
- `LookAheadTransformer` (LAT; original class MusicTrans): band-masked pre-LN transformer over
  music frames (downsample 4) or leader token embeddings (downsample 1); 4 frames are
  concatenated and projected; the last look_forward outputs are dropped.
- `CoordinatedBlock` (original Block + CausalCrossConditionalSelfAttention): attention over
  10 streams of t tokens, mask = tril(t, t) tiled 10 x 10.
- `GPTBase` / `GPTHead`: position embedding + blocks / blocks + five bias-free heads.
Dropout is omitted (eval mode): it has no parameters, so state_dict names are unaffected.
"""
import math

import torch
import torch.nn as nn
import torch.nn.functional as F


def band_mask(n, band):
    """(n, n) float mask, 1 where |i - j| <= band (original get_subsequent_mask)."""
    m = torch.ones(n, n)
    return torch.tril(torch.triu(m, diagonal=-band), diagonal=band)


class MaskedSelfAttention(nn.Module):
    """Multi-head self-attention with a fixed 0/1 mask buffer `mask` (1, 1, L, L)."""

    def __init__(self, n_embd, n_head, mask):
        super().__init__()
        if n_embd % n_head != 0:
            raise ValueError(f"n_embd {n_embd} not divisible by n_head {n_head}")
        self.key = nn.Linear(n_embd, n_embd)
        self.query = nn.Linear(n_embd, n_embd)
        self.value = nn.Linear(n_embd, n_embd)
        self.proj = nn.Linear(n_embd, n_embd)
        self.n_head = n_head
        self.register_buffer("mask", mask[None, None])

    def attend(self, x, mask):  # x (B, L, C), mask (L, L) 0/1
        b, l, c = x.shape
        h = self.n_head
        k = self.key(x).view(b, l, h, c // h).transpose(1, 2)    # (B, h, L, hs)
        q = self.query(x).view(b, l, h, c // h).transpose(1, 2)  # (B, h, L, hs)
        v = self.value(x).view(b, l, h, c // h).transpose(1, 2)  # (B, h, L, hs)
        att = (q @ k.transpose(-2, -1)) * (1.0 / math.sqrt(k.size(-1)))  # (B, h, L, L)
        att = att.masked_fill(mask == 0, float("-inf"))
        att = F.softmax(att, dim=-1)
        y = (att @ v).transpose(1, 2).contiguous().view(b, l, c)  # (B, L, C)
        return self.proj(y)


class BandAttention(MaskedSelfAttention):
    """LAT attention (original MaskAttention): band |i-j| <= look_forward*ds over a window of
    (block_size + look_forward)*ds positions; a shorter input uses the top-left crop."""

    def __init__(self, cfg):
        n = (cfg.block_size + cfg.look_forward) * cfg.downsample_rate
        super().__init__(cfg.n_embd, cfg.n_head,
                         band_mask(n, cfg.look_forward * cfg.downsample_rate))

    def forward(self, x):
        l = x.shape[1]
        return self.attend(x, self.mask[:, :, :l, :l])


class CoordinatedAttention(MaskedSelfAttention):
    """GPT attention over 10 streams of t tokens: tril(t, t) repeated 10 x 10, i.e. a token at
    window position i sees every stream at positions <= i."""

    def __init__(self, cfg):
        super().__init__(cfg.n_embd, cfg.n_head, torch.tril(torch.ones(cfg.block_size, cfg.block_size)))

    def forward(self, x):
        t = x.shape[1] // 10
        return self.attend(x, self.mask[:, :, :t, :t].repeat(1, 1, 10, 10))


class _PreLNBlock(nn.Module):
    """x + attn(ln1(x)); x + mlp(ln2(x)); mlp = Linear(C, 4C), GELU (erf), Linear(4C, C)."""

    def __init__(self, n_embd, attn):
        super().__init__()
        self.ln1 = nn.LayerNorm(n_embd)
        self.ln2 = nn.LayerNorm(n_embd)
        self.attn = attn
        self.mlp = nn.Sequential(nn.Linear(n_embd, 4 * n_embd), nn.GELU(), nn.Linear(4 * n_embd, n_embd))

    def forward(self, x):
        x = x + self.attn(self.ln1(x))
        return x + self.mlp(self.ln2(x))


class LatBlock(_PreLNBlock):
    def __init__(self, cfg):
        super().__init__(cfg.n_embd, BandAttention(cfg))


class CoordinatedBlock(_PreLNBlock):
    def __init__(self, cfg):
        super().__init__(cfg.n_embd, CoordinatedAttention(cfg))


class LookAheadTransformer(nn.Module):
    """LAT (original MusicTrans). `pos_emb` exists in checkpoints but is never used."""

    def __init__(self, cfg):
        super().__init__()
        self.cfg = cfg
        ds = cfg.downsample_rate
        self.pos_emb = nn.Parameter(torch.zeros(1, (cfg.block_size + cfg.look_forward) * ds, cfg.n_embd))
        self.cond_emb = nn.Linear(cfg.n_music, cfg.n_embd)
        self.blocks = nn.Sequential(*[LatBlock(cfg) for _ in range(cfg.n_layer)])
        self.downsample = nn.Linear(cfg.n_embd * ds, cfg.n_embd)

    def forward(self, x):
        """x (B, L, n_music) with L = (c + look_forward) * ds -> (B, c, n_embd)."""
        b, l, _ = x.shape
        ds, lf = self.cfg.downsample_rate, self.cfg.look_forward
        if l % ds != 0 or l // ds <= lf or l > (self.cfg.block_size + lf) * ds:
            raise ValueError(f"LAT input length {l} must be a multiple of {ds}, > {lf * ds} "
                             f"and <= {(self.cfg.block_size + lf) * ds}")
        h = self.blocks(self.cond_emb(x))                       # (B, L, C)
        c = h.shape[-1]
        h = self.downsample(h.reshape(b, l // ds, c * ds))      # (B, L/ds, C)
        return h[:, :-lf, :]                                    # (B, c, C)


class GPTBase(nn.Module):
    """Position embedding (block_size*10 rows; stream s uses rows s*block_size + [0, t)) and
    blocks. `cond_emb`, `cond_{up,down,lhand,rhand}_emb` exist in checkpoints but are unused."""

    def __init__(self, cfg):
        super().__init__()
        self.block_size = cfg.block_size
        self.pos_emb = nn.Parameter(torch.zeros(1, cfg.block_size * 10, cfg.n_embd))
        self.cond_emb = nn.Linear(cfg.n_music, cfg.n_embd)
        self.cond_up_emb = nn.Linear(cfg.n_embd, cfg.n_embd)
        self.cond_down_emb = nn.Linear(cfg.n_embd, cfg.n_embd)
        self.cond_lhand_emb = nn.Linear(cfg.n_embd, cfg.n_embd)
        self.cond_rhand_emb = nn.Linear(cfg.n_embd, cfg.n_embd)
        self.blocks = nn.Sequential(*[CoordinatedBlock(cfg) for _ in range(cfg.n_layer)])

    def forward(self, streams):
        """streams: 10 tensors (B, t, C) in order [music, L_up, L_down, L_lh, L_rh, F_up,
        F_down, F_lh, F_rh, F_transl] -> (B, 10t, C)."""
        t = streams[0].shape[1]
        if t > self.block_size:
            raise ValueError(f"window {t} exceeds block_size {self.block_size}")
        bs = self.block_size
        pos = torch.cat([self.pos_emb[:, s * bs:s * bs + t, :] for s in range(10)], dim=1)
        return self.blocks(torch.cat(streams, dim=1) + pos)


class GPTHead(nn.Module):
    """Blocks + five bias-free heads on streams 5..9. No final LayerNorm. Vocabulary sizes as
    in the original: head_lhand uses vocab_size_up, head_rhand uses vocab_size_down."""

    def __init__(self, cfg):
        super().__init__()
        self.blocks = nn.Sequential(*[CoordinatedBlock(cfg) for _ in range(cfg.n_layer)])
        self.head_up = nn.Linear(cfg.n_embd, cfg.vocab_size_up, bias=False)
        self.head_down = nn.Linear(cfg.n_embd, cfg.vocab_size_down, bias=False)
        self.head_lhand = nn.Linear(cfg.n_embd, cfg.vocab_size_up, bias=False)
        self.head_rhand = nn.Linear(cfg.n_embd, cfg.vocab_size_down, bias=False)
        self.head_transl = nn.Linear(cfg.n_embd, cfg.vocab_size_transl, bias=False)

    def forward(self, x):  # (B, 10t, C) -> 5 x (B, t, V)
        x = self.blocks(x)
        t = x.shape[1] // 10
        heads = (self.head_up, self.head_down, self.head_lhand, self.head_rhand, self.head_transl)
        return tuple(h(x[:, t * (5 + i):t * (6 + i), :]) for i, h in enumerate(heads))


class GPT2nt(nn.Module):
    """The follower GPT. `cfg` is the original `structure_generate` section."""

    def __init__(self, cfg):
        super().__init__()
        self.cfg = cfg
        self.music_trans = LookAheadTransformer(cfg.music_trans)
        self.leader_up_trans = LookAheadTransformer(cfg.leader_up_trans)
        self.leader_down_trans = LookAheadTransformer(cfg.leader_down_trans)
        self.leader_lhand_trans = LookAheadTransformer(cfg.leader_lhand_trans)
        self.leader_rhand_trans = LookAheadTransformer(cfg.leader_rhand_trans)
        self.tok_emb_up = nn.Embedding(cfg.vocab_size_up, cfg.n_embd)
        self.tok_emb_down = nn.Embedding(cfg.vocab_size_down, cfg.n_embd)
        self.tok_emb_lhand = nn.Embedding(cfg.vocab_size_lhand, cfg.n_embd)
        self.tok_emb_rhand = nn.Embedding(cfg.vocab_size_rhand, cfg.n_embd)
        self.tok_emb_transl = nn.Embedding(cfg.vocab_size_transl, cfg.n_embd)
        self.gpt_base = GPTBase(cfg.base)
        self.gpt_head = GPTHead(cfg.head)
        # original: block_size - 1 is the max context; sample rate / look-ahead from music_trans
        self.block_size = cfg.block_size
        self.music_sample_size = cfg.music_trans.downsample_rate
        self.look_forward = cfg.music_trans.look_forward

    def conditions(self, music, leader):
        """music (B, (c+lf)*4, 54), leader 4 x (B, c+lf) tokens -> 5 x (B, c, C)."""
        l_up, l_down, l_lh, l_rh = leader
        return (self.music_trans(music),
                self.leader_up_trans(self.tok_emb_up(l_up)),
                self.leader_down_trans(self.tok_emb_down(l_down)),
                self.leader_lhand_trans(self.tok_emb_lhand(l_lh)),
                self.leader_rhand_trans(self.tok_emb_rhand(l_rh)))

    def forward(self, follower, music, leader):
        """follower: 5 x (B, c) tokens (up, down, lhand, rhand, transl); music (B, (c+lf)*4, 54);
        leader: 4 x (B, c+lf) tokens -> 5 x (B, c, V) logits."""
        f_up, f_down, f_lh, f_rh, f_tr = follower
        cond = self.conditions(music, leader)
        emb = (self.tok_emb_up(f_up), self.tok_emb_down(f_down), self.tok_emb_lhand(f_lh),
               self.tok_emb_lhand(f_rh),  # original quirk: follower rhand uses the LEFT-hand table
               self.tok_emb_transl(f_tr))
        return self.gpt_head(self.gpt_base(cond + emb))
