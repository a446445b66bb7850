#!/usr/bin/env python3
"""Stage 1b: the relative-translation VQ-VAE (original transl_vqvae.py + models/vqvae.py).

Input: 20 * (root_follower - root_leader) over 240-frame windows of the train split (3
channels, nothing zeroed). Loss (the original's): L1(x) + vel * L1(first differences)
+ acc * L1(second differences) + commit * commitment; EMA codebook.
"""
import argparse
import sys

import numpy as np
import torch

from common import (Clock, EMAQuantiser, RATE, TRANSL_SCALE, WINDOW, build_models, load_split,
                    save_checkpoint, setup_threads)
from train_vqvae import d1, d2, l1


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=43)
    args = ap.parse_args(argv)
    setup_threads()
    torch.manual_seed(args.seed)
    gen = torch.Generator().manual_seed(args.seed)
    _, _, tr = build_models()
    tr.train()
    quant = EMAQuantiser(tr.bottleneck.level_blocks[0], tr.hps.l_mu, gen=gen)
    rels = [((tk["follower"][:, :3] - tk["leader"][:, :3]) * TRANSL_SCALE).astype(np.float32)
            for tk in load_split(args.data, "train")]
    rng = np.random.default_rng(args.seed)
    opt = torch.optim.Adam(tr.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.steps, pct_start=0.05)
    clock = Clock()
    for step in range(1, args.steps + 1):
        xs = []
        for _ in range(args.batch):
            r = rels[rng.integers(len(rels))]
            s = rng.integers((len(r) - WINDOW) // RATE + 1) * RATE
            xs.append(r[s:s + WINDOW])
        x = torch.from_numpy(np.stack(xs))
        _, zq, commit, met = quant(tr.features(x))
        out = tr.decoders[0](zq).permute(0, 2, 1)
        loss = l1(out, x) + tr.hps.vel * l1(d1(out), d1(x)) + tr.hps.acc * l1(d2(out), d2(x)) + tr.hps.commit * commit
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == 1:
            print(f"[transl] step {step}/{args.steps} loss {float(loss):.4f} rec {float(l1(out.detach(), x)):.4f} "
                  f"(x20 units) used {met['used']} ppl {met['perplexity']:.0f} | {clock}", flush=True)
    save_checkpoint(tr, args.out)
    print(f"[transl] saved {args.out} ({clock})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
