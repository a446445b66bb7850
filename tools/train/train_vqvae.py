#!/usr/bin/env python3
"""Stage 1a: the four part VQ-VAEs (original motion_vqvae_mix.py + models/sep_vqvae_xm.py,
models/vqvae_mix.py, models/vqvae_root_mix.py), jointly, as in the original.

Per batch: 240-frame windows (start on a multiple of 4) of leader AND follower takes (the
original motion dataset reads every file of the split); normalised positions; the pelvis
channel becomes the root velocity (next - current, last frame repeated), kept as the target of
the down part's `decoders_root` head, then zeroed. Loss per part (the original's):
  L1(pos) + L1(rot) [+ L1(root vel) for down]
  + vel * (L1 of first differences of pos and rot)
  + acc * (L1 of second differences of pos and rot [+ first differences of root vel])
  + commit * commitment,  EMA codebook (mu = l_mu).
Deviation: the part's first joint is zeroed in the training input too (the original zeroes it
only in encode(); training on the zeroed input makes training match encoding).
"""
import argparse
import sys

import numpy as np
import torch

from common import (Clock, EMAQuantiser, PARTS, RATE, WINDOW, build_models, load_split, normalised,
                    save_checkpoint, setup_threads)


def l1(a, b):
    return torch.mean(torch.abs(a - b))


def d1(x):
    return x[:, 1:] - x[:, :-1]


def d2(x):
    return x[:, 2:] + x[:, :-2] - 2 * x[:, 1:-1]


class Windows:
    """Random 240-frame windows of every dancer of the split, normalised, root -> velocity."""

    def __init__(self, takes, rng):
        self.seqs = []
        for tk in takes:
            for who in ("leader", "follower"):
                pos = normalised(tk[who])
                vel = np.empty((len(pos), 3), np.float32)
                vel[:-1] = pos[1:, :3] - pos[:-1, :3]
                vel[-1] = vel[-2]
                pos[:, :3] = 0
                self.seqs.append((pos, tk[who + "_rot"], vel))
        self.rng = rng

    def batch(self, b):
        pos, rot, vel = [], [], []
        for _ in range(b):
            p, r, v = self.seqs[self.rng.integers(len(self.seqs))]
            s = self.rng.integers((len(p) - WINDOW) // RATE + 1) * RATE
            pos.append(p[s:s + WINDOW]); rot.append(r[s:s + WINDOW]); vel.append(v[s:s + WINDOW])
        return tuple(torch.from_numpy(np.stack(a)) for a in (pos, rot, vel))


def split_rot(vq, rot, part):
    n, t, c = rot.shape
    from reference.vqvae import PART_JOINTS
    return rot.view(n, t, 55, 9)[:, :, PART_JOINTS[part]].reshape(n, t, -1)


def part_loss(pv, quant, x, xrot, vel, update=True):
    hps = pv.hps
    x_in = x.clone()
    x_in[:, :, :hps.joint_channel] = 0
    codes, zq, commit, met = quant(pv.features(x_in), update)
    pos = pv.decoders[0](zq).permute(0, 2, 1)
    rot = pv.decoders_rot[0](zq).permute(0, 2, 1)
    rec = l1(pos, x) + l1(rot, xrot)
    vl = l1(d1(pos), d1(x)) + l1(d1(rot), d1(xrot))
    al = l1(d2(pos), d2(x)) + l1(d2(rot), d2(xrot))
    if hasattr(pv, "decoders_root"):
        rv = pv.decoders_root[0](zq).permute(0, 2, 1)
        rec = rec + l1(rv, vel)
        al = al + l1(d1(rv), d1(vel))
    loss = rec + hps.vel * vl + hps.acc * al + hps.commit * commit
    return loss, dict(rec=float(l1(pos.detach(), x)), **met)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True, help="checkpoint path (original format)")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--lr", type=float, default=6e-4)
    ap.add_argument("--seed", type=int, default=42)
    args = ap.parse_args(argv)
    setup_threads()
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    _, vq, _ = build_models()
    vq.train()
    quants = {p: EMAQuantiser(vq.part(p).bottleneck.level_blocks[0], vq.part(p).hps.l_mu, gen=gen) for p in PARTS}
    data = Windows(load_split(args.data, "train"), np.random.default_rng(args.seed))
    params = [p for p in vq.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=args.lr, betas=(0.9, 0.999))
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.05)
    clock = Clock()
    for step in range(1, args.steps + 1):
        pos, rot, vel = data.batch(args.batch)
        total, log = 0.0, {}
        for p in PARTS:
            x = vq.split(pos, p)
            loss, met = part_loss(vq.part(p), quants[p], x, split_rot(vq, rot, p), vel)
            total = total + loss
            log[p] = met
        opt.zero_grad()
        total.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == 1:
            parts = " ".join(f"{p}: rec {m['rec']:.4f} used {m['used']} ppl {m['perplexity']:.0f}" for p, m in log.items())
            print(f"[vqvae] step {step}/{args.steps} loss {float(total):.4f} | {parts} | {clock}", flush=True)
    save_checkpoint(vq, args.out)
    print(f"[vqvae] saved {args.out} ({clock})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
