#!/usr/bin/env python3
"""Transflower Lightning checkpoint (.ckpt) -> safetensors state dict (+ hparams.yaml).

The input of `duolando convert --config hparams.yaml --weights model.safetensors`
(docs/TRANSFLOWER.md): the checkpoint's `state_dict`, tensor names kept exactly
(guillefix/transflower-lightning `TransflowerModel.state_dict()`: the buffers
`is_initialized` and `bounds` included; the converter skips and counts them), and,
with --hparams, the options as a flat `key: value` YAML.

The checkpoint directory of a training run already holds the hparams.yaml the authors'
inference/generate.py reads (Lightning writes it next to the checkpoints): use that one
when you have it. --hparams writes the same keys from the checkpoint's
`hyper_parameters` (what `save_hyperparameters(vars(opt))` stored) for a checkpoint
that travels alone.

pytorch_lightning need not be installed: a Lightning checkpoint pickles some of its
objects (`AttributeDict` hyper-parameters, callback states); classes that cannot be
imported are loaded as plain stand-ins (dict-like or attribute bags). Only tensors are
written; every `state_dict` entry must be a tensor.

    /work/venv/bin/python tools/transflower_ckpt_to_safetensors.py last.ckpt model.safetensors \
        [--hparams hparams.yaml]
"""
import argparse
import pickle
import sys
import types

import torch
from safetensors.torch import save_file


class _Stand_in(dict):
    """A class the checkpoint names but this Python cannot import: keeps whatever
    the pickle gives it (dict items, attributes, constructor arguments)."""

    def __init__(self, *args, **kwargs):
        if args and isinstance(args[0], dict):
            super().__init__(args[0])
        self.__dict__["_args"] = args
        self.update(kwargs)

    def __setstate__(self, state):
        if isinstance(state, dict):
            self.update(state)
        elif isinstance(state, tuple) and state and isinstance(state[-1], dict):
            self.update(state[-1])

    def __reduce_ex__(self, protocol):  # pragma: no cover - never re-pickled
        return (dict, (dict(self),))


def _stand_in_class(module, name):
    return type(name, (_Stand_in,), {"__module__": module})


class _Unpickler(pickle.Unpickler):
    def find_class(self, module, name):
        try:
            return super().find_class(module, name)
        except (ImportError, AttributeError):
            return _stand_in_class(module, name)


# torch.load(pickle_module=...) wants a module-like object with Unpickler and load.
_pickle_module = types.SimpleNamespace(Unpickler=_Unpickler, load=lambda f, **kw: _Unpickler(f, **kw).load(), __name__="stand_in_pickle")


def load_checkpoint(path):
    """The checkpoint's state_dict (name -> tensor) and hyper_parameters (dict or None)."""
    obj = torch.load(path, map_location="cpu", weights_only=False, pickle_module=_pickle_module)
    if isinstance(obj, dict) and "state_dict" in obj:
        sd, hp = obj["state_dict"], obj.get("hyper_parameters")
    elif isinstance(obj, dict) and all(isinstance(v, torch.Tensor) for v in obj.values()):
        sd, hp = obj, None  # a bare state_dict
    else:
        raise ValueError(f"{path}: not a Lightning checkpoint (no 'state_dict' key) nor a bare state_dict")
    bad = [k for k, v in sd.items() if not isinstance(v, torch.Tensor)]
    if bad:
        raise ValueError(f"{path}: state_dict entries that are not tensors: {bad[:5]}{' ...' if len(bad) > 5 else ''}")
    if hp is not None:
        hp = dict(hp)
        # save_hyperparameters(opt) with a namespace-like object nests it under 'opt'.
        if set(hp) == {"opt"}:
            hp = dict(vars(hp["opt"]) if hasattr(hp["opt"], "__dict__") and not isinstance(hp["opt"], dict) else hp["opt"])
    return sd, hp


def _yaml_scalar(v):
    """A value as PyYAML's safe_dump writes it for the flat options file."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    s = str(v)
    plain = s and all(c.isalnum() or c in "_-./," for c in s) and not s[0].isdigit() and s.lower() not in ("true", "false", "null", "yes", "no", "on", "off", "~")
    return s if plain else "'" + s.replace("'", "''") + "'"


def write_hparams(hp, path):
    """Flat `key: value` lines, sorted (as Lightning's hparams.yaml); nested values as text."""
    with open(path, "w") as f:
        for k in sorted(hp):
            f.write(f"{k}: {_yaml_scalar(hp[k])}\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint", help="the Lightning .ckpt (or a torch-saved bare state_dict)")
    ap.add_argument("output", help="output .safetensors file")
    ap.add_argument("--hparams", help="also write the checkpoint's hyper_parameters as a flat hparams.yaml here")
    args = ap.parse_args(argv)
    try:
        sd, hp = load_checkpoint(args.checkpoint)
    except (OSError, ValueError, RuntimeError, pickle.UnpicklingError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    if args.hparams:
        if not hp:
            print(f"error: {args.checkpoint} holds no hyper_parameters; use the hparams.yaml of its training run", file=sys.stderr)
            return 1
        write_hparams(hp, args.hparams)
    # safetensors needs contiguous, non-shared storage; clone keeps dtype and values.
    save_file({k: v.detach().contiguous().clone() for k, v in sd.items()}, args.output)
    n = sum(v.numel() for v in sd.values())
    print(f"{args.output}: {len(sd)} tensors, {n} values" + (f"; {args.hparams}: {len(hp)} options" if args.hparams else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
