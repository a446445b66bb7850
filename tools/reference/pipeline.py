"""The R (reference) pipeline: the authors' evaluation (original gpt2t.py `MCTall.eval`,
GPT2nt.sample, datasets/dd100lf_all2.py) reproduced token for token with greedy decoding.

`generate_exact` works on one sequence (batch 1) on CPU, in the dtype of the modules.
"""
from dataclasses import dataclass

import numpy as np
import torch

from .vqvae import PARTS

N_JOINTS = 55
MUSIC_MOTION_RATE = 4  # original config `music_motion_rate` / `ds_rate`: 4 frames per token
TRANSL_SCALE = 20.0    # relative translation is encoded as (root_f - root_l) * 20


def normalise_pos3d(pos):
    """(T, 165) world joints -> the dataset's normalised layout (datasets/dd100lf_all2.py):
    every joint minus the pelvis (joint 0), the pelvis channel keeps the absolute root,
    hand joints 25..54 become (joint - wrist) * 10 with the wrist already pelvis-relative
    (left wrist joint 20 = channels 60:63, right wrist joint 21 = channels 63:66)."""
    pos = torch.as_tensor(pos)
    root = pos[:, :3]
    out = pos - root.repeat(1, N_JOINTS)
    out[:, :3] = root
    out[:, 75:120] = (out[:, 75:120] - out[:, 60:63].repeat(1, 15)) * 10
    out[:, 120:165] = (out[:, 120:165] - out[:, 63:66].repeat(1, 15)) * 10
    return out


def denormalise_pos3d(pos):
    """Inverse of `normalise_pos3d` as the original eval does it (hands * 0.1 + wrist, then
    every joint + root, root kept)."""
    pos = pos.clone()
    pos[:, 75:120] = pos[:, 75:120] * 0.1 + pos[:, 60:63].repeat(1, 15)
    pos[:, 120:165] = pos[:, 120:165] * 0.1 + pos[:, 63:66].repeat(1, 15)
    root = pos[:, :3].clone()
    pos = pos + root.repeat(1, N_JOINTS)
    pos[:, :3] = root
    return pos


def window_context(k, max_ctx, shift=None):
    """Number c of follower tokens in the GPT window at step k (original GPT2nt.sample):
    max_ctx = block_size - 1; block_shift = min(shift, max_ctx) or max_ctx when shift is None;
    c = k + 1 while k < max_ctx, else block_shift + (k - max_ctx - 1) mod (max_ctx - block_shift + 1)
    (Python modulo). With shift None this is min(k + 1, max_ctx)."""
    block_shift = max_ctx if shift is None else min(shift, max_ctx)
    if k < max_ctx:
        return k + 1
    return block_shift + (k - max_ctx - 1) % (max_ctx - block_shift + 1)


class MarginTooSmall(Exception):
    """Raised by `Margins` when a decision is closer to a tie than its floor."""


@dataclass
class Margins:
    """Smallest decision margins seen (to prove f32/f64 round-off cannot flip a token).
    With floors set, a decision below its floor raises MarginTooSmall (used by the seed search)."""
    logit_abs: float = float("inf")   # min over steps/heads of top1 - top2 logit
    logit_rel: float = float("inf")   # same divided by max |logit| of that head
    vq_abs: float = float("inf")      # min over codes of d2 - d1 (squared distances)
    vq_rel: float = float("inf")      # same divided by (|x|^2 + |k_best|^2)
    logit_floor: float = 0.0
    vq_floor: float = 0.0

    def logits(self, lg):  # lg (V,)
        top = torch.topk(lg.double(), 2).values
        gap = float(top[0] - top[1])
        self.logit_abs = min(self.logit_abs, gap)
        self.logit_rel = min(self.logit_rel, gap / float(lg.abs().max()))
        if self.logit_rel < self.logit_floor:
            raise MarginTooSmall(f"logit margin {self.logit_rel:.3g} < {self.logit_floor}")

    def vq(self, block, feats):  # feats (N, emb, T)
        x = feats.permute(0, 2, 1).reshape(-1, feats.shape[1]).double()
        k = block.k.double()
        d = (x ** 2).sum(-1, keepdim=True) - 2 * x @ k.t() + (k ** 2).sum(-1)[None]  # (M, bins)
        top = torch.topk(-d, 2, dim=-1)
        gap = -(top.values[:, 1] - top.values[:, 0])  # d2 - d1 >= 0
        scale = (x ** 2).sum(-1) + (k[top.indices[:, 0]] ** 2).sum(-1)
        self.vq_abs = min(self.vq_abs, float(gap.min()))
        self.vq_rel = min(self.vq_rel, float((gap / scale).min()))
        if self.vq_rel < self.vq_floor:
            raise MarginTooSmall(f"vq margin {self.vq_rel:.3g} < {self.vq_floor}")


def _encode_part_tracked(part_vae, x, margins):
    x = x.clone()
    x[:, :, :part_vae.hps.joint_channel] = 0
    feats = part_vae.features(x)
    if margins is not None:
        margins.vq(part_vae.bottleneck.level_blocks[0], feats)
    return part_vae.bottleneck.level_blocks[0].encode(feats)


def encode_motion(vqvae, norm, margins=None):
    """norm (1, T, 165) normalised with root channels zeroed -> 4 x (1, T/4) codes."""
    return tuple(_encode_part_tracked(vqvae.part(p), vqvae.split(norm, p), margins) for p in PARTS)


def encode_transl(transl_vqvae, rel, margins=None):
    """rel (1, T, 3) = (root_f - root_l) * 20 -> (1, T/4) codes."""
    feats = transl_vqvae.features(rel)
    if margins is not None:
        margins.vq(transl_vqvae.bottleneck.level_blocks[0], feats)
    return transl_vqvae.bottleneck.level_blocks[0].encode(feats)


@torch.no_grad()
def prepare(gpt, vqvae, transl_vqvae, leader, music, seed_tokens=None, follower_start=None, margins=None):
    """Inputs -> (leader_codes 4 x (1, T4/4), seed xs 5 x (1, 1), music (T4, 54), leader root
    (T4, 3), T4). Sequences are truncated to T4 = T - T mod 4 like the test dataset."""
    dtype = next(gpt.parameters()).dtype
    leader = torch.as_tensor(np.asarray(leader), dtype=dtype)
    music = torch.as_tensor(np.asarray(music), dtype=dtype)
    if leader.ndim != 2 or leader.shape[1] != 165:
        raise ValueError(f"leader must be (T, 165), got {tuple(leader.shape)}")
    if music.ndim != 2 or music.shape[1] != gpt.cfg.music_trans.n_music or music.shape[0] < leader.shape[0]:
        raise ValueError(f"music must be (>= T, {gpt.cfg.music_trans.n_music}), got {tuple(music.shape)}")
    if (seed_tokens is None) == (follower_start is None):
        raise ValueError("give exactly one of seed_tokens and follower_start")

    rate = MUSIC_MOTION_RATE
    t4 = leader.shape[0] // rate * rate  # dataset: sequence truncated to a multiple of `move` = 4
    leader, music = leader[:t4], music[:t4]
    l_root = leader[:, :3].clone()

    l_norm = normalise_pos3d(leader)
    l_norm[:, :3] = 0
    leader_codes = encode_motion(vqvae, l_norm[None], margins)  # 4 x (1, T4/4)

    if seed_tokens is not None:
        seed = torch.as_tensor(np.asarray(seed_tokens), dtype=torch.long).view(5)
        xs = [seed[i].view(1, 1) for i in range(5)]
    else:
        fs = torch.as_tensor(np.asarray(follower_start), dtype=dtype)
        f = fs.shape[0]
        if fs.ndim != 2 or fs.shape[1] != 165 or f % rate != 0 or not rate <= f <= t4:
            raise ValueError(f"follower_start must be (F, 165), F % 4 == 0, 4 <= F <= {t4}; got {tuple(fs.shape)}")
        rel = (fs[:, :3] - l_root[:f]) * TRANSL_SCALE  # (F, 3)
        f_norm = normalise_pos3d(fs)
        f_norm[:, :3] = 0
        body = encode_motion(vqvae, f_norm[None, :rate], margins)  # original: encode(pose_seqf[:, :4])
        tr = encode_transl(transl_vqvae, rel[None], margins)
        xs = [z[:, :1] for z in body] + [tr[:, :1]]
    return leader_codes, xs, music, l_root, t4


@torch.no_grad()
def generate_exact(gpt, vqvae, transl_vqvae, leader, music, seed_tokens=None,
                   follower_start=None, shift=None, margins=None, pick=None):
    """R rollout, greedy (or `pick`).

    leader (T, 165) raw world joints; music (>= T, 54); exactly one of
      seed_tokens (5,) ints (up, down, lhand, rhand, transl), or
      follower_start (F, 165) raw follower joints, F % 4 == 0, 4 <= F <= T4: body tokens from
      the first 4 frames, transl token = code 0 of the translation encoder over all F frames
      (the original encodes the whole follower sequence; F = 4 uses only the first 4 frames).
    shift: the original sample(shift=...) chunked window (None = the authors' eval).
    pick: the next token from a head's last logits (V,) -> int; None = greedy (the authors'
      `sample`; the training recipe's RL stage passes their `samplek`'s uniform top-k draw).
    Returns dict: tokens (K+1, 5) int64, follower_pos3d (4(K+1), 165) in the leader's input
    coordinates, follower_rotmat (4(K+1), 495), leader_tokens (T4/4, 4), T4, K.
    """
    leader_codes, xs, music, l_root, t4 = prepare(gpt, vqvae, transl_vqvae, leader, music,
                                                  seed_tokens, follower_start, margins)
    rate, lf = MUSIC_MOTION_RATE, gpt.look_forward

    # GPT2nt.sample: the music condition starts at frame 4 (music_seq[:, music_motion_rate:])
    cond_music = music[rate:][None]  # (1, T4-4, 54)
    n_steps = cond_music.shape[1] // rate - lf
    max_ctx = gpt.block_size - 1
    for k in range(max(n_steps, 0)):
        c = window_context(k, max_ctx, shift)
        lo, hi = k + 1 - c, k + 1 + lf  # leader token window; music frames [lo*4, hi*4)
        window = [x[:, -c:] for x in xs]
        logits = gpt(window, cond_music[:, lo * rate:hi * rate], [z[:, lo:hi] for z in leader_codes])
        nxt = []
        for lg in logits:
            last = lg[0, -1]
            if margins is not None:
                margins.logits(last)
            nxt.append((torch.argmax(last) if pick is None else torch.as_tensor(pick(last))).view(1, 1))
        xs = [torch.cat([x, n], dim=1) for x, n in zip(xs, nxt)]

    tokens = torch.cat(xs, dim=0).t().contiguous()  # (K+1, 5)
    pos, rot = vqvae.decode(tuple(xs[:4]))           # (1, 4(K+1), 165), (1, 4(K+1), 495)
    transl = transl_vqvae.decode(xs[4])              # (1, 4(K+1), 3)
    n_out = pos.shape[1]
    pos = pos[0].clone()
    pos[:, :3] = (l_root[:n_out] - l_root[:1]) + transl[0] / TRANSL_SCALE
    pos = denormalise_pos3d(pos)
    pos = pos + l_root[:1].repeat(1, N_JOINTS)  # back to the leader's input coordinates
    return {
        "tokens": tokens,
        "follower_pos3d": pos,
        "follower_rotmat": rot[0],
        "leader_tokens": torch.cat(leader_codes, dim=0).t().contiguous(),
        "T4": t4,
        "K": max(n_steps, 0),
    }
