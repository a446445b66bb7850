"""Bailando's R step in ONNX Runtime: the baseline `duolando bench --family bailando --ort-json`
prints its ratios against (issue #38 §5).

The authors' actor GPT (`CrossCondGPT2AC` from lisiyao21/Bailando, imported unmodified by
`tools/reference/bailando/authors.py`) at the published size (`configs/actor_critic.yaml`'s
`structure_generate`: n_embd 768, 12 heads, 6 + 6 blocks, block_size 29, vocabularies 512,
438 music features) with seeded random weights, in eval mode, exported as ONE R step: the
forward over a full window of 28 tokens and their music rows (what `AC.eval` runs at every
step once the window slides), returning the two heads' logits at the last position. The same
step `duolando bench --family bailando` times (`bailando::gpt::window_logits`). Cost does not
depend on the weights' values.

Timed in onnxruntime (f32, graph optimisations on, 1 intra-op and 1 inter-op thread) after
warm-up; writes a JSON the bench reads: median/p99 ms, onnxruntime version, threads, CPU.

    mkdir -p /tmp/bailando && git -C /work/.mirror/lisiyao21+Bailando/repo archive HEAD \\
        models configs | tar -x -C /tmp/bailando
    /work/venv/bin/python tools/bailando_ort_r_step.py --out /tmp/bailando_ort.json   # repo root
    cargo run --release -p duolando -- bench --family bailando --ort-json /tmp/bailando_ort.json

Needs torch, onnx, onnxruntime, pyyaml (pip); none of them is a dependency of the engine or CI.
"""
import argparse
import os
import sys

import numpy as np
import torch
import yaml

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__))))
from reference.bailando import authors  # noqa: E402
from reference.config import Cfg  # noqa: E402
from ort_timing import add_common_args, cpu_name, time_session, write_json  # noqa: E402


class RStep(torch.nn.Module):
    """One window step: tokens (1, 28) x 2 and music (1, 28, 438) -> logits (512,) x 2 at the
    last position (the authors' forward computes every position's; the engine computes only
    the last, so the graph slices before the heads' output is used)."""

    def __init__(self, gpt):
        super().__init__()
        self.gpt = gpt

    def forward(self, up, down, music):
        (lu, ld), _ = self.gpt((up, down), music)
        return lu[0, -1], ld[0, -1]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkout", default=authors.DEFAULT_CHECKOUT, help="the authors' repository (models/, configs/)")
    add_common_args(ap, "/tmp/bailando_r_step.onnx", "350 MB", runs=20, threads=False)
    args = ap.parse_args()

    import onnxruntime as ort

    torch.manual_seed(0)
    auth = authors.load(args.checkout)
    with open(os.path.join(args.checkout, "configs", "actor_critic.yaml")) as f:
        cfg = Cfg(yaml.safe_load(f))
    gpt = auth.CrossCondGPT2AC(cfg.structure_generate).eval()
    n_params = sum(p.numel() for n, p in gpt.named_parameters() if not n.startswith("critic_net"))
    c = cfg.structure_generate.block_size - 1
    n_music = cfg.structure_generate.base.n_music
    g = torch.Generator().manual_seed(1)
    up = torch.randint(0, 512, (1, c), generator=g)
    down = torch.randint(0, 512, (1, c), generator=g)
    music = torch.randn(1, c, n_music, generator=g)
    step = RStep(gpt).eval()
    with torch.no_grad():
        want = step(up, down, music)
        torch.onnx.export(step, (up, down, music), args.onnx, input_names=["up", "down", "music"],
                          output_names=["logits_up", "logits_down"], opset_version=17, dynamo=False)

    feed = {"up": up.numpy(), "down": down.numpy(), "music": music.numpy()}
    got, st = time_session(ort, args.onnx, 1, feed, args.warmup, args.runs)
    err = max(float(np.abs(got[i] - want[i].numpy()).max()) for i in range(2))
    out = {
        "family": "bailando",
        "what": "Bailando R step (actor GPT over a 28-token window), onnxruntime f32",
        "onnxruntime": ort.__version__,
        "torch": torch.__version__,
        "threads": 1,
        "cpu": cpu_name(),
        "params": n_params,
        "window_tokens": c,
        "median_ms": st["median_ms"],
        "p99_ms": st["p99_ms"],
        "runs": args.runs,
        "max_abs_err_vs_torch": err,
        "logit_scale": max(float(want[i].abs().max()) for i in range(2)),
    }
    write_json(args.out, out)


if __name__ == "__main__":
    main()
