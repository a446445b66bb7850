"""Full-size R step as ONNX, for `duolando bench`'s tract ratio (`tract_r_step_ms_t1`).

The follower GPT at the published size (n_embd 768, 12 heads, 6 + 6 blocks, LATs of 3 blocks,
block_size 30, look_forward 29, vocab 512: `core::presets::duolando_published`) with seeded
random weights, exported as one R window step (`export.GptStep`: the 5 heads' logits at the last
position of a 29-token window, LATs included) exactly like the fixtures' `gpt_step_c*.onnx`
(opset 17, constant embedding tables routed through the `one` input for tract 0.21).
Writes DIR/full_r_step.onnx (~0.81 GB) and DIR/full_r_step_io/*.npy (the inputs, 2-D, and
torch's logits (5, 512), which the bench compares tract's output with). Timing needs no real weights: tract's
cost does not depend on the values.

    /work/venv/bin/python -m tools.reference.export_full_r_step [--out DIR]   # from the repo root
    cargo run --release -p duolando --features tract -- bench --tract-onnx DIR/full_r_step.onnx
"""
import argparse
import os

import numpy as np
import onnx
import torch

from .config import Cfg
from .export import GptStep, runtime_gather_tables
from .gpt import GPT2nt
from .tiny import generate_structure

PUBLISHED = dict(n_embd=768, n_head=12, base_layers=6, head_layers=6, lat_layers=3, block_size=30,
                 look_forward=29, vocab=512)


def build(seed=0, structure=PUBLISHED):
    """The R window step of a follower GPT of `structure` (default: the published size) with
    seeded random weights, and its inputs: (step, inputs, names, logits (1, 5, vocab)).
    tools/duolando_ort_r_step.py times the same step in onnxruntime."""
    torch.manual_seed(seed)
    g = torch.Generator().manual_seed(seed)
    gpt = GPT2nt(Cfg(generate_structure(structure)))
    with torch.no_grad():
        for name, p in gpt.named_parameters():
            if name.endswith("weight") and p.dim() >= 2:
                p.copy_(torch.randn(p.shape, generator=g) * 0.02)
            elif ".ln" in name and name.endswith("weight"):
                p.fill_(1.0)
            else:
                p.copy_(torch.randn(p.shape, generator=g) * 0.01)
    gpt.eval()
    c, lf, v = structure["block_size"] - 1, structure["look_forward"], structure["vocab"]
    f = [torch.randint(0, v, (1, c), generator=g) for _ in range(5)]
    music = torch.randn(1, (c + lf) * 4, 54, generator=g)
    l = [torch.randint(0, v, (1, c + lf), generator=g) for _ in range(4)]
    names = ["f_up", "f_down", "f_lhand", "f_rhand", "f_transl", "music", "l_up", "l_down", "l_lhand", "l_rhand"]
    inputs = f + [music] + l
    step = GptStep(gpt)
    with torch.no_grad():
        logits = step(*inputs)
    return step, inputs, names, logits


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="/tmp/duolando_full")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    step, inputs, names, logits = build(args.seed)
    n_params = sum(p.numel() for p in step.parameters())
    c = PUBLISHED["block_size"] - 1
    path = os.path.join(args.out, "full_r_step.onnx")
    kwargs = {"dynamo": False} if "dynamo" in torch.onnx.export.__code__.co_varnames else {}
    torch.onnx.export(step, tuple(inputs), path, input_names=names, output_names=["logits"],
                      opset_version=17, do_constant_folding=True, **kwargs)
    model = onnx.load(path)
    k = runtime_gather_tables(model)
    onnx.save(model, path)
    io = os.path.join(args.out, "full_r_step_io")
    os.makedirs(io, exist_ok=True)
    for n, x in zip(names, inputs):
        np.save(os.path.join(io, f"{n}.npy"), x.numpy()[0] if n == "music" else x.numpy())
    np.save(os.path.join(io, "logits.npy"), logits.numpy()[0])
    print(f"wrote {path} ({os.path.getsize(path) / 1e6:.0f} MB, {n_params / 1e6:.1f}M parameters, "
          f"{k} tables rerouted) and full_r_step_io/; window {c} tokens, logits {tuple(logits.shape)}")


if __name__ == "__main__":
    main()
