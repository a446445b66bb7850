#!/usr/bin/env python3
"""Bailando demo, stage 1 + 2: the two half VQ-VAEs, then the root-velocity decoder, with the
authors' SepVQVAER and their own loss code.

Stage 1 (the authors' motion_vqvae.py with configs/sep_vqvae.yaml, `global_vel: False`): windows
of 240 frames, pelvis-relative joints with the pelvis channel zeroed; the up half runs the
authors' `VQVAE.forward`, the down half the same `VQVAE.forward` on its VQVAER (the stage-1
SepVQVAE trains both halves as plain VQVAEs; VQVAER has the same encoder / decoder / bottleneck
names). Loss per half: L1 positions + commit 0.02 x commitment + vel 1 x L1 of velocities
+ acc 1 x L1 of accelerations; EMA codebook (mu 0.99) initialised from the first batch, dead
codes restarted from batch vectors (the authors' bottleneck.py, in training mode).
Stage 2 (configs/sep_vqvae_root.yaml, `global_vel: True`): the pelvis channel becomes the
forward root velocity (`p[t+1] - p[t]`, the last frame repeats the previous one) and the authors'
`VQVAER.forward` trains `decoders_root` alone (encoder, codebook, decoder frozen: L1 velocity
+ acc 1 x L1 of its differences).
Deviations (CPU budget): one-cycle Adam instead of Adam 5e-5 for 500 + 500 epochs; random
windows with a random rotation about the vertical axis instead of stride-8 windows.
"""
import argparse

import numpy as np
import torch

import common as C


FIXED_HEADING = False
FLAT_ROOT_Y = False


def windows(clips, rng, batch, vel):
    xs = []
    for _ in range(batch):
        d = clips[rng.integers(len(clips))]
        s = rng.integers(0, len(d) - C.WINDOW + 1)
        w = d[s:s + C.WINDOW]
        if not FIXED_HEADING:
            w = C.yaw(w, rng.uniform(0, 2 * np.pi))
        w = C.loader_dance(w)
        if vel:
            w[:-1, :3] = w[1:, :3] - w[:-1, :3]
            w[-1, :3] = w[-2, :3]
            if FLAT_ROOT_Y:
                w[:, 1] = 0.0
        else:
            w[:, :3] = 0
        xs.append(w)
    return torch.from_numpy(np.stack(xs))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--checkout", default="/tmp/bailando")
    ap.add_argument("--out", required=True)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--root-steps", type=int, default=600)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=6e-4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--flat-root-y", action="store_true",
                    help="the root decoder learns no vertical velocity (the pelvis keeps its height; the "
                         "legs carry the bounce): a sampled dance cannot drift up or down")
    ap.add_argument("--root-only", metavar="CKPT",
                    help="start from CKPT and train the root decoder alone (the codebooks frozen: the "
                         "codes, and a GPT trained on them, stay valid)")
    ap.add_argument("--no-yaw", action="store_true",
                    help="no random heading per window (data made with prepare_data.py --fold-heading)")
    args = ap.parse_args()
    global FIXED_HEADING, FLAT_ROOT_Y
    FIXED_HEADING = args.no_yaw
    FLAT_ROOT_Y = args.flat_root_y
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    auth = C.load_authors(args.checkout)
    from models.vqvae import VQVAE  # the authors' (imported by load)
    vq, _ = C.build(auth)
    clips = [d for _, d, _ in C.load_split(args.data, "train") if len(d) >= C.WINDOW]
    print(f"{len(clips)} training dances, {sum(map(len, clips)) / C.FPS / 60:.1f} min", flush=True)
    up, down = auth.smpl_up, auth.smpl_down
    timer = C.Timer()

    if args.root_only:
        vq.load_state_dict(torch.load(args.root_only, weights_only=False)["model"])
        args.steps = 0
    # stage 1: both halves
    params = list(vq.vqvae_up.parameters()) + [p for n, p in vq.vqvae_down.named_parameters()
                                               if not n.startswith("decoders_root")]
    opt = torch.optim.Adam(params, lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=max(args.steps, 1), pct_start=0.1)
    vq.train()
    for step in range(args.steps):
        x = windows(clips, rng, args.batch, vel=False).view(args.batch, C.WINDOW, 24, 3)
        xu = x[:, :, up].reshape(args.batch, C.WINDOW, -1)
        xd = x[:, :, down].reshape(args.batch, C.WINDOW, -1)
        _, lu, mu = vq.vqvae_up(xu)
        _, ld, md = VQVAE.forward(vq.vqvae_down, xd)
        loss = lu + ld
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == args.steps - 1:
            print(f"vq {step} loss {loss.item():.4f} l1 up {mu['l1_loss']:.4f} down {md['l1_loss']:.4f} "
                  f"used {int(mu['used_curr'])}/{int(md['used_curr'])} ({timer})", flush=True)

    # stage 2: root velocity decoder
    params = list(vq.vqvae_down.decoders_root.parameters())
    opt = torch.optim.Adam(params, lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.root_steps, pct_start=0.1)
    if args.root_only:
        vq.vqvae_down.bottleneck.eval()  # codebook frozen (no EMA update)
    for step in range(args.root_steps):
        x = windows(clips, rng, args.batch, vel=True).view(args.batch, C.WINDOW, 24, 3)
        xd = x[:, :, down].reshape(args.batch, C.WINDOW, -1)
        _, ld, md = vq.vqvae_down(xd)
        opt.zero_grad()
        ld.backward()
        opt.step()
        sched.step()
        if step % 100 == 0 or step == args.root_steps - 1:
            print(f"root {step} loss {ld.item():.5f} vel l1 {md['l1_loss']:.5f} ({timer})", flush=True)
    vq.eval()
    C.save(args.out, model=vq.state_dict(), config=C.yaml_docs(), cpu_s=timer.__str__())
    print(f"saved {args.out} ({timer})")


if __name__ == "__main__":
    main()
