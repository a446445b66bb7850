#!/usr/bin/env python3
"""Bailando demo: checkpoints -> the authors' file set (actor_critic.yaml,
actor_critic_demo.yaml, gpt.safetensors and vqvae.safetensors as `nn.DataParallel` state dicts,
`module.` prefix, critic included), ready for `duolando convert`; optionally the demo music
(the first --demo-seconds of a held-out take's 438-d features)."""
import argparse
import json
import os

import numpy as np
import torch
import yaml
from safetensors.torch import save_file

import common as C


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vqvae", required=True)
    ap.add_argument("--gpt", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--data", help="prepared data (for the demo music)")
    ap.add_argument("--demo-take", default="")
    ap.add_argument("--demo-seconds", type=float, default=20.0)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    for fname, doc in C.yaml_docs().items():
        with open(os.path.join(args.out, fname), "w") as f:
            yaml.safe_dump(doc, f, sort_keys=False)
    vq = torch.load(args.vqvae, weights_only=False)
    gpt = torch.load(args.gpt, weights_only=False)
    save_file({"module." + k: v.contiguous() for k, v in gpt["model"].items()}, os.path.join(args.out, "gpt.safetensors"))
    save_file({"module." + k: v.contiguous() for k, v in vq["model"].items()}, os.path.join(args.out, "vqvae.safetensors"))
    up, down = gpt["seed_tokens"]
    meta = {"seed_tokens": [int(up), int(down)], "teacher_forced": gpt["teacher_forced"],
            "vqvae_cpu": vq["cpu_s"], "gpt_cpu": gpt["cpu_s"]}
    if args.data and args.demo_take:
        m = np.load(os.path.join(args.data, "wav", args.demo_take + ".npy"))
        rows = int(round(args.demo_seconds * 7.5))
        np.save(os.path.join(args.out, "bailando_demo_music.npy"), np.ascontiguousarray(m[:rows], dtype="<f4"))
        meta["demo_music"] = {"take": args.demo_take, "rows": min(rows, len(m))}
    json.dump(meta, open(os.path.join(args.out, "meta.json"), "w"), indent=1, default=float)
    print(json.dumps(meta, default=float))


if __name__ == "__main__":
    main()
