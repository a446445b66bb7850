"""Self-check of tools/transflower_ckpt_to_safetensors.py on tiny checkpoints built with the
AUTHORS' classes (paper and label configs of tiny.py), saved the way Lightning saves them
(`state_dict`, `hyper_parameters` as a pickled `pytorch_lightning.utilities.parsing.AttributeDict`,
optimizer/callback entries), then read back in a process WITHOUT pytorch_lightning:

1. every state-dict tensor is written unchanged (names, dtypes, values);
2. --hparams writes the options so that they parse to the same values (PyYAML) as the
   hparams.yaml the reference writes for the goldens;
3. with --duolando BIN: `duolando convert` of the export and `duolando generate --noise` with the
   noise the authors' loop drew give the authors' output (rel err <= TOL).

    nice -n 10 /work/venv/bin/python tools/reference/transflower/check_ckpt_export.py \
        [--duolando target/debug/duolando]
"""
import argparse
import collections
import os
import subprocess
import sys
import tempfile
import types

import numpy as np
import torch
import yaml
from safetensors.torch import load_file

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, os.path.dirname(HERE))
from transflower import env, reference, tiny  # noqa: E402

EXPORTER = os.path.join(ROOT, "tools", "transflower_ckpt_to_safetensors.py")
TOL = 1e-4  # rel = max|a-b| / max(1, max|b|); the goldens' own f32-vs-f64 is <= 3e-5
CASES = {"paper": (31, 18, 18), "label": (32, 12, 19)}  # weight seed, motion rows, audio rows


def fake_lightning():
    """A module path for AttributeDict at save time only (pickle stores module + name)."""
    mod = types.ModuleType("pytorch_lightning.utilities.parsing")

    class AttributeDict(dict):
        def __getattr__(self, k):
            return self[k]
    AttributeDict.__module__ = mod.__name__
    AttributeDict.__qualname__ = "AttributeDict"
    mod.AttributeDict = AttributeDict
    return mod


def save_ckpt(model, opt, path):
    mod = fake_lightning()
    saved = {k: sys.modules.get(k) for k in ("pytorch_lightning.utilities", "pytorch_lightning.utilities.parsing")}
    sys.modules["pytorch_lightning.utilities"] = types.ModuleType("pytorch_lightning.utilities")
    sys.modules["pytorch_lightning.utilities.parsing"] = mod
    try:
        torch.save({
            "epoch": 3, "global_step": 120, "pytorch-lightning_version": "1.4.9",
            "state_dict": collections.OrderedDict((k, v.detach().clone()) for k, v in model.state_dict().items()),
            "callbacks": {}, "optimizer_states": [{"state": {}, "param_groups": []}], "lr_schedulers": [],
            "hparams_name": "kwargs", "hyper_parameters": mod.AttributeDict(opt),
        }, path)
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v


def check(case, tmp, duolando):
    w_seed, m_rows, a_rows = CASES[case]
    hp = tiny.CONFIGS[case]
    torch.set_num_threads(1)
    model = reference.build(hp, w_seed)
    opt = dict(vars(env.make_opt(hp)))
    ckpt = os.path.join(tmp, f"{case}.ckpt")
    save_ckpt(model, opt, ckpt)
    st, hy = os.path.join(tmp, f"{case}.safetensors"), os.path.join(tmp, f"{case}.hparams.yaml")
    # A clean interpreter: no stubs, no pytorch_lightning.
    r = subprocess.run([sys.executable, EXPORTER, ckpt, st, "--hparams", hy], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    got = load_file(st)
    want = model.state_dict()
    assert list(sorted(got)) == list(sorted(want)), f"{case}: names differ"
    for k, v in want.items():
        assert got[k].dtype == v.dtype and torch.equal(got[k], v), f"{case}: {k} differs"
    parsed = yaml.safe_load(open(hy))
    assert parsed == yaml.safe_load(yaml.safe_dump(opt)), f"{case}: hparams differ"
    msg = f"{case}: {len(got)} tensors and {len(parsed)} options exported unchanged"
    if duolando:
        rng = np.random.default_rng(w_seed)
        inputs = {}
        for i, mod in enumerate(model.input_mods):
            if model.input_types[i] == "d":
                inputs[mod] = np.array([2], dtype=np.int64)
            else:
                rows = a_rows if i == len(model.input_mods) - 1 else m_rows
                inputs[mod] = rng.standard_normal((rows, model.dins[i])).astype(np.float32)
        res = reference.generate(model, inputs, seed=w_seed)
        args = []
        for mod, x in inputs.items():
            p = os.path.join(tmp, f"{case}.{mod}.npy")
            np.save(p, x)
            args += ["--input", f"{mod}={p}"]
        noise = os.path.join(tmp, f"{case}.noise.npy")
        np.save(noise, res["noise"])
        duo, out = os.path.join(tmp, f"{case}.duo"), os.path.join(tmp, f"{case}.out")
        for cmd in (["convert", "--config", hy, "--weights", st, "-o", duo],
                    ["generate", "--model", duo, *args, "--noise", noise, "--out", out]):
            r = subprocess.run([duolando, *cmd], capture_output=True, text=True)
            assert r.returncode == 0, f"{case}: duolando {cmd[0]}: {r.stderr}"
        y = np.load(os.path.join(out, "output.npy"))
        assert y.shape == res["output"].shape, (y.shape, res["output"].shape)
        err = float(np.abs(y - res["output"]).max() / max(1.0, float(np.abs(res["output"]).max())))
        assert err <= TOL, f"{case}: duolando vs the authors' loop: rel err {err:.3g} > {TOL}"
        msg += f"; duolando convert + generate --noise: {y.shape[0]} frames, rel err {err:.2e}"
    print(msg)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duolando", help="the duolando binary: also convert and generate")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            check(case, tmp, args.duolando and os.path.abspath(args.duolando))
    print("ok")


if __name__ == "__main__":
    main()
