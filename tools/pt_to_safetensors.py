#!/usr/bin/env python3
"""Original Duolando checkpoint (.pt) -> safetensors, tensor names kept exactly.

Accepts `torch.load(path)['model']` (the authors' checkpoints: {'model': state_dict, ...})
or a bare state_dict. A DataParallel `module.` prefix is kept as is (the Rust converter
accepts names with and without it). Non-tensor entries are rejected with a message.

    /work/venv/bin/python tools/pt_to_safetensors.py epoch_500.pt gpt.safetensors
"""
import argparse
import sys

import torch
from safetensors.torch import save_file


def load_state_dict(path):
    """Return the checkpoint's state_dict (name -> tensor), original names."""
    obj = torch.load(path, map_location="cpu", weights_only=False)
    if isinstance(obj, dict) and "model" in obj and isinstance(obj["model"], dict):
        obj = obj["model"]
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: expected a state_dict or a dict with key 'model', got {type(obj).__name__}")
    bad = [k for k, v in obj.items() if not isinstance(v, torch.Tensor)]
    if bad:
        raise ValueError(f"{path}: entries that are not tensors: {bad[:5]}{' ...' if len(bad) > 5 else ''}")
    return obj


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint", help="original .pt file")
    ap.add_argument("output", help="output .safetensors file")
    args = ap.parse_args(argv)
    try:
        sd = load_state_dict(args.checkpoint)
    except (OSError, ValueError, RuntimeError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    # safetensors needs contiguous, non-shared storage; clone keeps dtype and values.
    save_file({k: v.detach().contiguous().clone() for k, v in sd.items()}, args.output)
    n = sum(v.numel() for v in sd.values())
    print(f"{args.output}: {len(sd)} tensors, {n} values")
    return 0


if __name__ == "__main__":
    sys.exit(main())
