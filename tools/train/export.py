#!/usr/bin/env python3
"""Original-format checkpoints -> YAML configs (original structure) + safetensors, and the demo
clip (leader, music, follower start) cut from a held-out take of the test split.

    python export.py --ckpt DIR --out DIR --data SYNTH_DIR --assets ASSETS_DIR
Then: duolando convert --config DIR/follower_gpt.yaml --gpt DIR/gpt.safetensors
      --vqvae DIR/vqvae.safetensors --transl DIR/transl.safetensors --dtype f16 -o demo.duo
"""
import argparse
import json
import os
import sys

import numpy as np
import yaml

from common import TOOLS, checkpoint_look_forward, demo_size, load_split, yaml_docs

sys.path.insert(0, TOOLS)
import pt_to_safetensors  # noqa: E402

DEMO_SECONDS = 25


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--ckpt", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--assets", required=True)
    ap.add_argument("--take", default=None, help="test take name for the demo clip (default: the longest)")
    ap.add_argument("--look-forward", type=int, default=None,
                    help="the GPT's look_forward for the YAML (default: the one stored in follower_gpt.pt)")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    lf = args.look_forward
    if lf is None:
        lf = checkpoint_look_forward(os.path.join(args.ckpt, "follower_gpt.pt"))
    print(f"follower GPT look_forward {lf}")
    for name, doc in yaml_docs(demo_size(lf)).items():
        with open(os.path.join(args.out, name), "w") as f:
            yaml.safe_dump(doc, f, sort_keys=False)
    for pt, st in (("follower_gpt.pt", "gpt.safetensors"), ("motion_vqvae.pt", "vqvae.safetensors"),
                   ("transl_vqvae.pt", "transl.safetensors")):
        if pt_to_safetensors.main([os.path.join(args.ckpt, pt), os.path.join(args.out, st)]) != 0:
            return 1
    test = load_split(args.data, "test")
    tk = max(test, key=lambda t: len(t["leader"])) if args.take is None else next(t for t in test if t["name"] == args.take)
    n = min(len(tk["leader"]), DEMO_SECONDS * 30) // 4 * 4
    os.makedirs(args.assets, exist_ok=True)
    np.save(os.path.join(args.assets, "demo_leader_pos3d.npy"), tk["leader"][:n].astype(np.float32))
    np.save(os.path.join(args.assets, "demo_music.npy"), tk["music"][:n].astype(np.float32))
    np.save(os.path.join(args.assets, "demo_follower_start.npy"), tk["follower"][:4].astype(np.float32))
    with open(os.path.join(args.data, "takes.json")) as f:
        meta = json.load(f)
    synth = f"duolando synth --minutes {meta['minutes_requested']:g} --seed {meta['seed']}"
    with open(os.path.join(args.assets, "demo_take.txt"), "w") as f:
        f.write(f"{tk['name']} frames 0..{n} of the test split of `{synth}`\n")
    print(f"demo clip: {tk['name']} frames 0..{n} ({n / 30:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
