#!/usr/bin/env python3
"""Stage 3: the follower GPT's off-policy reinforcement stage (Duolando §3.3; the authors'
actor_critic_new.py `train`, models/gpt2ntac2_woln.py `forward(..., rewards, targets)`,
models/reward3.py `reward3`, datasets/aclf.py `AClf`, config
rl_final_debug_reward3_random_5mem_lr3e-5.yaml).

What the authors do, and what this script does the same way:
- Every epoch the CURRENT policy rolls out greedily (their `sample` takes the top-1 token) on
  leader + music, follower seeded as in their test path (its first-4-frame tokens); the
  rollout is decoded by the frozen VQ-VAEs: body positions, the down part's root-velocity
  head (`decoders_root`, `vel_sample`), and the follower root = leader root + transl / 20.
- Reward (`reward3`): up, lhand, rhand and transl streams get 1 everywhere; the down stream
  gets the lower-body/translation consistency per frame, -100 |v_pred - v_root| (the velocity
  the lower body implies against the root's actual velocity, forward differences with the
  last repeated), set to 1 where it is above -3 (under 3 cm per frame of disagreement: no
  skating); per token the minimum over its 4 frames.
- Replay (the config's "5mem"): the first epoch's rollouts are kept for ever; from the second
  epoch on, an epoch trains on its own rollouts + the first epoch's + up to 5x as many drawn
  at random from every earlier epoch's.
- Windows (`AClf`, interval 30, look_forward 29): for each start ii, follower tokens
  [ii, ii+30) in, [ii+1, ii+31) as targets with their rewards, leader tokens [ii, ii+59),
  music frames [4(ii+1), 4(ii+60)).
- Loss per stream: rewards smoothed r[t] + 0.2 r[t+1]; y = sigmoid(alpha r) (alpha 3); the
  probability p the policy gives the rolled-out token is pulled towards y:
  -log(1.001 - |p - y|), mean over positions, summed over the five streams. So a token that
  skated (r <= -3: y ~ 0) is pushed down, one that did not (r = 1: y = 0.97) up.
- Adam (betas 0.9, 0.999), lr 3e-5, no dropout (`freeze_drop`).
Deviations, for a CPU budget: rollouts on a random subset of the training takes per epoch
(`--takes`; the authors roll out their whole demo set), a fixed number of updates per epoch
(`--updates`; theirs: one pass over the replay windows at batch 256), batch 32 by default.
The training takes are the ones the supervised stage saw (never the test split).
"""
import argparse
import random
import sys

import numpy as np
import torch

from common import Clock, RATE, build_models, checkpoint_look_forward, load_checkpoint, load_split, \
    save_checkpoint, setup_threads
from reference.pipeline import generate_exact

STREAMS = ("up", "down", "lhand", "rhand", "transl")


def topk_pick(k, gen):
    """The authors' `samplek` choice: uniform among the k most probable tokens."""
    def pick(logits):
        top = torch.topk(logits, k).indices
        return int(top[torch.randint(0, k, (1,), generator=gen)])
    return pick


@torch.no_grad()
def rollout(gpt, vq, tr, tk, pick=None):
    """Rollout of the current policy on one take (greedy, or `pick`) -> (leader tokens (4, n),
    follower tokens (5, K+1), music (T, 54), rewards (5, K+1), stats)."""
    res = generate_exact(gpt, vq, tr, tk["leader"], tk["music"], follower_start=tk["follower"][:4], pick=pick)
    toks = res["tokens"].t().contiguous()                      # (5, K+1)
    root = res["follower_pos3d"][:, :3]                        # (4(K+1), 3) world root
    down = vq.part("down")
    z = down.bottleneck.level_blocks[0].decode(toks[1][None])  # (1, emb, K+1)
    v_pred = down.decoders_root[0](z)[0].t()                   # (4(K+1), 3) per-frame root velocity
    v_root = torch.empty_like(root)
    v_root[:-1] = root[1:] - root[:-1]
    v_root[-1] = v_root[-2]
    r_down = -torch.linalg.norm(v_pred - v_root, dim=-1) * 100  # cm per frame of disagreement
    r_down[r_down > -3] = 1
    r_down = r_down.view(-1, RATE).min(dim=-1).values           # per token
    rewards = torch.ones(5, toks.shape[1])
    rewards[1] = r_down
    return dict(leader=res["leader_tokens"].t().contiguous(), follower=toks,
                music=torch.as_tensor(tk["music"]), rewards=rewards,
                skating=float((r_down < 1).float().mean()))


def windows(seq, interval, lf):
    """AClf: every training window of one rollout."""
    out = []
    n_lead = seq["leader"].shape[1]
    for ii in range(n_lead - lf - interval - 1):
        music = seq["music"][(ii + 1) * RATE:(ii + interval + lf + 1) * RATE]
        if music.shape[0] != (interval + lf) * RATE or ii + interval + 1 > seq["follower"].shape[1]:
            continue
        out.append((seq["follower"][:, ii:ii + interval], seq["follower"][:, ii + 1:ii + interval + 1],
                    seq["leader"][:, ii:ii + interval + lf], music,
                    seq["rewards"][:, ii + 1:ii + interval + 1]))
    return out


def rl_loss(logits, targets, rewards, alpha, streams=range(5)):
    """The authors' reinforce branch of GPT2ntAC2LN.forward (over the given streams)."""
    r = rewards.clone()                                 # (B, 5, T)
    r[:, :, :-1] += r[:, :, 1:] * 0.2
    y = torch.sigmoid(alpha * r)
    total = 0.0
    for j in streams:
        lg = logits[j]                                  # (B, T, V)
        p = torch.softmax(lg, dim=-1).gather(-1, targets[:, j].unsqueeze(-1)).squeeze(-1)
        total = total + (-torch.log(1.001 - torch.abs(p - y[:, j]))).mean()
    return total


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--ckpt", required=True, help="directory with motion_vqvae.pt, transl_vqvae.pt, follower_gpt.pt "
                                                  "(the supervised stage)")
    ap.add_argument("--gpt", default=None, help="the supervised GPT checkpoint (default: CKPT/follower_gpt.pt)")
    ap.add_argument("--out", required=True, help="the fine-tuned follower GPT checkpoint")
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--takes", type=int, default=24, help="training takes rolled out per epoch")
    ap.add_argument("--updates", type=int, default=60, help="optimiser steps per epoch")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=3e-5)
    ap.add_argument("--alpha", type=float, default=3.0)
    ap.add_argument("--mem", type=int, default=5, help="replay: up to MEM x the epoch's rollouts from earlier epochs")
    ap.add_argument("--seed", type=int, default=42)
    ap.add_argument("--rollout-topk", type=int, default=None,
                    help="roll out with the authors' `samplek` (uniform among the k best tokens) instead of their "
                         "greedy `sample` (a deviation: exploration)")
    ap.add_argument("--streams", default="up,down,lhand,rhand,transl",
                    help="streams whose loss is trained (default all five, as the authors; `down` = only the one "
                         "whose reward varies: a deviation)")
    ap.add_argument("--measure", default=None, metavar="SPLIT",
                    help="only roll out every take of SPLIT (train/test) with the --gpt/--ckpt model and print the "
                         "share of down tokens the reward penalises (what this stage lowers); --out unused")
    args = ap.parse_args(argv)
    setup_threads()
    random.seed(args.seed)
    torch.manual_seed(args.seed)
    clock = Clock()
    gpt_path = args.gpt or f"{args.ckpt}/follower_gpt.pt"
    gpt, vq, tr = build_models(checkpoint_look_forward(gpt_path))
    for m, f in ((gpt, gpt_path), (vq, f"{args.ckpt}/motion_vqvae.pt"), (tr, f"{args.ckpt}/transl_vqvae.pt")):
        load_checkpoint(m, f).eval()
    bs, lf = gpt.block_size, gpt.look_forward
    if args.measure:
        seqs = [rollout(gpt, vq, tr, tk) for tk in load_split(args.data, args.measure)]
        n = [s["follower"].shape[1] for s in seqs]
        share = float(np.average([s["skating"] for s in seqs], weights=n))
        print(f"[rl] {args.measure}: {len(seqs)} takes, {sum(n)} tokens, down tokens penalised {share:.4f} | {clock}")
        return 0
    train = load_split(args.data, "train")
    opt = torch.optim.Adam(gpt.parameters(), lr=args.lr, betas=(0.9, 0.999), weight_decay=0)
    first, replay = [], []
    gen = torch.Generator().manual_seed(args.seed)
    streams = [STREAMS.index(n) for n in args.streams.split(",")]
    rng = random.Random(args.seed)
    for epoch in range(1, args.epochs + 1):
        gpt.eval()
        takes = rng.sample(train, min(args.takes, len(train)))
        pick = topk_pick(args.rollout_topk, gen) if args.rollout_topk else None
        fresh = [rollout(gpt, vq, tr, tk, pick) for tk in takes]
        skate = float(np.mean([s["skating"] for s in fresh]))
        seqs = list(fresh)
        if epoch == 1:
            first = list(fresh)
        else:
            seqs += first
            # the authors' random.choices: with replacement, 5x the epoch's sequences at most
            seqs += rng.choices(replay, k=min(args.mem * len(seqs), len(replay)))
            replay += fresh
        pool = [w for s in seqs for w in windows(s, bs, lf)]
        print(f"[rl] epoch {epoch}: {len(fresh)} rollouts, down tokens penalised {skate:.3f}, "
              f"{len(seqs)} sequences / {len(pool)} windows in replay | {clock}", flush=True)
        gpt.train()
        losses = []
        for _ in range(args.updates):
            batch = [pool[i] for i in np.random.default_rng(rng.randrange(1 << 30)).integers(len(pool), size=args.batch)]
            fin = torch.stack([b[0] for b in batch])    # (B, 5, 30)
            tgt = torch.stack([b[1] for b in batch])    # (B, 5, 30)
            lead = torch.stack([b[2] for b in batch])   # (B, 4, 59)
            music = torch.stack([b[3] for b in batch])  # (B, 236, 54)
            rew = torch.stack([b[4] for b in batch])    # (B, 5, 30)
            logits = gpt([fin[:, j] for j in range(5)], music, [lead[:, j] for j in range(4)])
            loss = rl_loss(logits, tgt, rew, args.alpha, streams)
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(loss.item())
        print(f"[rl] epoch {epoch}: loss {np.mean(losses):.4f} | {clock}", flush=True)
    gpt.eval()
    save_checkpoint(gpt, args.out, look_forward=lf)
    print(f"[rl] saved {args.out} ({clock})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
