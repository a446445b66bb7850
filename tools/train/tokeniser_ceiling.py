#!/usr/bin/env python3
"""What the tokenisers alone allow: the held-out true followers sent through the VQ-VAEs and back
(their own tokens, no GPT), scored by `duolando eval` like any generated set.

Three motion folders, each `<take>_00.npy` (the round-tripped follower, (T, 165) world positions)
beside `<take>_01.npy` (the true leader):
- `both`: the body through the part VQ-VAE and the root through the translation VQ-VAE (the
  best a GPT that predicted every true token could do);
- `body`: the body round-tripped, the true root;
- `root`: the true body, the root round-tripped.

    python tokeniser_ceiling.py --ckpt DIR --data DATA --real LC/real --real-stats LC/real_stats.json \\
        --music LC/music --bin ../../target/release/duolando --out /tmp/ceiling

`--real`, `--real-stats` and `--music` are the folders `latency_curve.py --out LC` writes (the true
followers cut to the rollouts' frames, their features, the music), so the figures compare with the
rollouts' rows. Prints one line per folder and writes `<out>/ceiling.json`.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np
import torch

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from common import build_models, load_checkpoint, load_split, setup_threads  # noqa: E402
from reference.pipeline import (TRANSL_SCALE, denormalise_pos3d, encode_motion,  # noqa: E402
                                encode_transl, normalise_pos3d)

VARIANTS = {"both": (True, True), "body": (True, False), "root": (False, True)}
KEYS = ("fid_k", "div_k", "fid_cd", "div_cd", "bed", "bas", "fsr_00", "fid_k_mean_term")


def write_folders(vq, tr, takes, real, out):
    for v in VARIANTS:
        os.makedirs(os.path.join(out, v), exist_ok=True)
    for tk in takes:
        ref = os.path.join(real, tk["name"] + "_00.npy")
        t_len = len(np.load(ref))
        norm = normalise_pos3d(torch.from_numpy(tk["follower"]))
        root_true = norm[:, :3].clone()
        norm[:, :3] = 0
        body, _ = vq.decode(encode_motion(vq, norm[None]))
        body = body[0]
        rel = torch.from_numpy((tk["follower"][:, :3] - tk["leader"][:, :3]) * TRANSL_SCALE)
        root_rec = torch.from_numpy(tk["leader"][:, :3]) + tr.decode(encode_transl(tr, rel[None]))[0] / TRANSL_SCALE
        n = min(t_len, len(body), len(root_rec), len(norm))
        leader = np.load(os.path.join(real, tk["name"] + "_01.npy"))[:n]
        for v, (b, r) in VARIANTS.items():
            p = (body[:n] if b else norm[:n]).clone()
            p[:, :3] = root_rec[:n] if r else root_true[:n]
            np.save(os.path.join(out, v, tk["name"] + "_00.npy"), denormalise_pos3d(p).numpy().astype(np.float32))
            np.save(os.path.join(out, v, tk["name"] + "_01.npy"), leader)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ckpt", required=True, help="directory with motion_vqvae.pt and transl_vqvae.pt")
    ap.add_argument("--data", required=True, help="`duolando synth` output (the recipe's data)")
    ap.add_argument("--real", required=True, help="the true duets, <take>_00/_01.npy (latency_curve.py's LC/real)")
    ap.add_argument("--real-stats", required=True, help="their saved features (LC/real_stats.json)")
    ap.add_argument("--music", required=True, help="music features per take (LC/music)")
    ap.add_argument("--bin", required=True, help="the duolando binary")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    setup_threads()
    _, vq, tr = build_models(None)
    load_checkpoint(vq, os.path.join(args.ckpt, "motion_vqvae.pt")).eval()
    load_checkpoint(tr, os.path.join(args.ckpt, "transl_vqvae.pt")).eval()
    with torch.no_grad():
        write_folders(vq, tr, load_split(args.data, "test"), args.real, args.out)
    result = {}
    for v in VARIANTS:
        js = os.path.join(args.out, v + ".json")
        subprocess.run([args.bin, "eval", "--gen", os.path.join(args.out, v), "--real-stats", args.real_stats,
                        "--music", args.music, "--json", js], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        e = json.load(open(js))
        result[v] = {k: e.get(k) for k in KEYS}
        print(v, " ".join(f"{k} {result[v][k]:.4g}" for k in KEYS if result[v][k] is not None), flush=True)
    json.dump(result, open(os.path.join(args.out, "ceiling.json"), "w"), indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
