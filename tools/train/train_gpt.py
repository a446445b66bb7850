#!/usr/bin/env python3
"""Stage 2: the follower GPT, supervised (original gpt2t.py `MCTall.train`, models/gpt2nt_woln.py).

Windows as in the original training (data.train.interval 240, move 4, music_dance_rate 1):
a window starts at frame i = 4s; with bs = block_size (30) and lf = look_forward (29 as the
original; `--look-forward N` trains another leader/music look-ahead, the recipe's latency knob):
  follower input tokens  [s, s+bs)        (up, down, lhand, rhand, transl)
  follower targets       [s+1, s+bs+1)    (teacher forcing)
  leader tokens          [s, s+bs+lf)     (look-ahead)
  music frames           [i+4, i+4+(bs+lf)*4)   (config music_len, from the move offset
                                                 music_motion_rate = 4)
Loss: the sum of the five cross-entropies (original GPT2nt.forward with targets).
Tokens come from the frozen VQ-VAEs with the roots zeroed; transl tokens encode
20 * (root_f - root_l). Deviation: every take is encoded ONCE over its whole length and the
windows are sliced from the token sequences (the original encodes each 240-frame window on the
fly); this is cheaper and is exactly how the R pipeline encodes the leader at inference.
Dropout (original *_pdrop 0.1) is added as hooks on attention and MLP outputs and embeddings.
"""
import argparse
import sys

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from common import (Clock, DEMO, RATE, TRANSL_SCALE, build_models, load_checkpoint, load_split, normalised,
                    save_checkpoint, setup_threads)
from reference.pipeline import encode_motion, encode_transl


@torch.no_grad()
def take_tokens(vq, tr, tk):
    """One take -> leader tokens (4, n), follower tokens (5, n), music (T, 54)."""
    out = {}
    for who in ("leader", "follower"):
        norm = torch.from_numpy(normalised(tk[who]))
        norm[:, :3] = 0
        out[who] = torch.cat(encode_motion(vq, norm[None]), 0)  # (4, n)
    rel = torch.from_numpy((tk["follower"][:, :3] - tk["leader"][:, :3]) * TRANSL_SCALE)
    transl = encode_transl(tr, rel[None])  # (1, n)
    return dict(name=tk["name"], leader=out["leader"], follower=torch.cat([out["follower"], transl], 0),
                music=torch.from_numpy(tk["music"]))


def encode_split(vq, tr, takes):
    return [take_tokens(vq, tr, tk) for tk in takes]


def window(tt, s, bs, lf):
    """The training window starting at token s of one encoded take."""
    i = s * RATE
    return (tt["follower"][:, s:s + bs], tt["follower"][:, s + 1:s + bs + 1],
            tt["leader"][:, s:s + bs + lf], tt["music"][i + RATE:i + RATE + (bs + lf) * RATE])


def n_windows(tt, bs, lf):
    """Number of valid starts: the window spans bs + lf + 1 tokens (240 frames at 30/29)."""
    return tt["leader"].shape[1] - (bs + lf + 1) + 1


def batch_windows(items):
    fin = torch.stack([w[0] for w in items])      # (B, 5, bs)
    tgt = torch.stack([w[1] for w in items])      # (B, 5, bs)
    lead = torch.stack([w[2] for w in items])     # (B, 4, bs+lf)
    music = torch.stack([w[3] for w in items])    # (B, (bs+lf)*4, 54)
    return ([fin[:, j] for j in range(5)], [tgt[:, j] for j in range(5)], music,
            [lead[:, j] for j in range(4)])


# The follower's input streams, in the GPT's order.
FOLLOWER_STREAMS = ("up", "down", "lhand", "rhand", "transl")


def corrupt(tokens, vocab, p):
    """`tokens` with each entry replaced, with probability p, by a uniform draw from [0, vocab)."""
    mask = torch.rand(tokens.shape) < p
    return torch.where(mask, torch.randint(0, vocab, tokens.shape), tokens)


def init_weights(gpt):
    """Original GPT2nt._init_weights: Linear/Embedding N(0, 0.02), biases 0, LayerNorm 1/0;
    position embeddings start at zero."""
    for m in gpt.modules():
        if isinstance(m, (nn.Linear, nn.Embedding)):
            nn.init.normal_(m.weight, 0.0, 0.02)
            if isinstance(m, nn.Linear) and m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.LayerNorm):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


def add_dropout(gpt, p):
    hooks = []
    for name, m in gpt.named_modules():
        if name.endswith(".attn") or name.endswith(".mlp") or name.startswith("tok_emb") or name.endswith("cond_emb"):
            hooks.append(m.register_forward_hook(lambda mod, inp, out: F.dropout(out, p, training=mod.training)))
    return hooks


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--vqvae", required=True)
    ap.add_argument("--transl", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=int, default=900)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--dropout", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=44)
    ap.add_argument("--init", default=None, help="continue from this GPT checkpoint (original init_weight)")
    ap.add_argument("--token-noise", type=float, default=0.0,
                    help="probability that a follower INPUT token is replaced by a uniformly drawn token of its "
                         "stream's codebook (targets unchanged): against exposure bias, where the model learns "
                         "to copy its previous token and greedy decoding then holds one token (not the "
                         "original's; 0 = off, the recipe's default)")
    ap.add_argument("--token-noise-streams", default="up,down,lhand,rhand,transl",
                    help="the follower input streams --token-noise corrupts (comma separated, of "
                         "up,down,lhand,rhand,transl; default all)")
    ap.add_argument("--look-forward", type=int, default=DEMO["look_forward"],
                    help="leader and music look-ahead in tokens (4 frames each; default 29 as the original): "
                         "the windows take leader tokens [s, s+bs+lf); R and S modes then need lf tokens "
                         "of leader ahead (docs/DEMO_MODEL.md, latency)")
    args = ap.parse_args(argv)
    if args.look_forward < 1:
        ap.error("--look-forward must be >= 1")
    if not 0.0 <= args.token_noise <= 1.0:
        ap.error("--token-noise must be in [0, 1]")
    noised = args.token_noise_streams.split(",")
    if not noised or any(n not in FOLLOWER_STREAMS for n in noised) or len(set(noised)) != len(noised):
        ap.error(f"--token-noise-streams takes distinct names of {','.join(FOLLOWER_STREAMS)}")
    setup_threads()
    torch.manual_seed(args.seed)
    gpt, vq, tr = build_models(args.look_forward)
    load_checkpoint(vq, args.vqvae).eval()
    load_checkpoint(tr, args.transl).eval()
    clock = Clock()
    train = encode_split(vq, tr, load_split(args.data, "train"))
    print(f"[gpt] encoded {len(train)} train takes ({clock})", flush=True)
    bs, lf = gpt.block_size, gpt.look_forward
    starts = [(ti, s) for ti, tt in enumerate(train) for s in range(n_windows(tt, bs, lf))]
    rng = np.random.default_rng(args.seed)
    init_weights(gpt)
    if args.init:
        load_checkpoint(gpt, args.init)
        rng = np.random.default_rng(args.seed + 1)
    gpt.train()
    add_dropout(gpt, args.dropout)
    opt = torch.optim.AdamW(gpt.parameters(), lr=args.lr, betas=(0.9, 0.95), weight_decay=0.01)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.05)
    n_params = sum(p.numel() for p in gpt.parameters())
    print(f"[gpt] {n_params} parameters, look_forward {lf}, {len(starts)} training windows", flush=True)
    run = None
    # Input streams' codebook sizes (up, down, lhand, rhand, transl), for --token-noise.
    vocabs = [e.num_embeddings for e in (gpt.tok_emb_up, gpt.tok_emb_down, gpt.tok_emb_lhand,
                                         gpt.tok_emb_rhand, gpt.tok_emb_transl)]
    for step in range(1, args.steps + 1):
        pick = rng.integers(len(starts), size=args.batch)
        fin, tgt, music, lead = batch_windows([window(train[starts[j][0]], starts[j][1], bs, lf) for j in pick])
        if args.token_noise > 0:
            fin = [corrupt(f, vocab, args.token_noise) if name in noised else f
                   for f, vocab, name in zip(fin, vocabs, FOLLOWER_STREAMS)]
        logits = gpt(fin, music, lead)
        losses = [F.cross_entropy(lg.reshape(-1, lg.shape[-1]), t.reshape(-1)) for lg, t in zip(logits, tgt)]
        loss = sum(losses)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(gpt.parameters(), 1.0)
        opt.step()
        sched.step()
        with torch.no_grad():
            acc = [float((lg.argmax(-1) == t).float().mean()) for lg, t in zip(logits, tgt)]
        run = np.array(acc) if run is None else 0.95 * run + 0.05 * np.array(acc)
        if step % 100 == 0 or step == 1:
            print(f"[gpt] step {step}/{args.steps} loss {float(loss):.3f} "
                  f"train acc (ema) up/down/lh/rh/tr {' '.join(f'{a:.2f}' for a in run)} | {clock}", flush=True)
    gpt.eval()
    save_checkpoint(gpt, args.out, look_forward=lf)
    print(f"[gpt] saved {args.out} ({clock})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
