#!/usr/bin/env python3
"""Self-check of the Bailando fixtures: load each committed tiny model into the AUTHORS'
classes (nn.DataParallel-wrapped, strict=True, `module.` names), rerun our AC.eval driver
on every committed rollout and compare: tokens and dance codes exactly, pos3d and
logits_step0 within 1e-5, meta.json counts; also the input and output dtypes/shapes.

    /work/venv/bin/python tools/reference/bailando/check_fixtures.py [--checkout /tmp/bailando] [--fixtures tests/fixtures]
"""
import argparse
import glob
import json
import os
import sys

import numpy as np
import torch
import yaml
from safetensors.torch import load_file

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from reference.config import Cfg  # noqa: E402
from reference.bailando import authors  # noqa: E402
from reference.bailando.pipeline import Margins, eval_one  # noqa: E402

ATOL = 1e-5


def load_model(auth, mdir):
    cfgs = {}
    for f in ("actor_critic.yaml", "actor_critic_demo.yaml"):
        with open(os.path.join(mdir, f)) as fh:
            cfgs[f] = Cfg(yaml.safe_load(fh))
    vq, gpt = authors.build(auth, cfgs["actor_critic.yaml"])
    for name, model in (("vqvae", vq), ("gpt", gpt)):
        sd = load_file(os.path.join(mdir, f"{name}.safetensors"))
        if not all(k.startswith("module.") for k in sd):
            raise AssertionError(f"{mdir}/{name}.safetensors: every name must carry the module. prefix")
        model.load_state_dict(sd, strict=True)
    if not any(".critic_net." in k for k in gpt.state_dict()):
        raise AssertionError(f"{mdir}: no critic_net weights")
    return vq, gpt, cfgs


def check_rollout(rdir, models):
    meta = json.load(open(os.path.join(rdir, "meta.json")))
    vq, gpt, cfgs = models[meta["model"]]
    ld = lambda n: np.load(os.path.join(rdir, n + ".npy"))  # noqa: E731
    music = ld("music")
    dance = ld("dance") if meta["path"] == "aist" else None
    seed = ld("seed_tokens") if meta["path"] == "demo" else None
    for arr, dt in ((music, np.float32), (dance, np.float32), (seed, np.int64)):
        if arr is not None and arr.dtype != dt:
            raise AssertionError(f"{rdir}: input dtype {arr.dtype}")
    m = Margins()
    res = eval_one(vq, gpt, cfgs[meta["config"]], music, dance, seed, m)
    if not np.array_equal(res["tokens"].numpy(), ld("tokens")) or ld("tokens").dtype != np.int64:
        raise AssertionError(f"{rdir}: tokens differ")
    if meta["path"] == "aist" and not np.array_equal(res["dance_codes"].numpy(), ld("dance_codes")):
        raise AssertionError(f"{rdir}: dance_codes differ")
    errs = {}
    for k, got in (("pos3d", res["pos3d"]), ("logits_step0", res["logits_step0"].numpy())):
        want = ld(k)
        if want.dtype != np.float32 or want.shape != got.shape:
            raise AssertionError(f"{rdir}: {k} dtype/shape {want.dtype}{want.shape} vs {got.shape}")
        errs[k] = float(np.abs(got - want).max())
        if errs[k] > ATOL:
            raise AssertionError(f"{rdir}: {k} max err {errs[k]:.3g} > {ATOL}")
    for k in ("K", "n_frames", "music_rows_padded", "dance_frames_padded"):
        got = {"music_rows_padded": res["music_rows"], "dance_frames_padded": res["dance_frames"]}.get(k, res.get(k))
        if got != meta[k]:
            raise AssertionError(f"{rdir}: {k} {got} != meta {meta[k]}")
    if res["tokens"].shape != (meta["K"] + 1, 2) or res["pos3d"].shape != (meta["n_frames"], 72):
        raise AssertionError(f"{rdir}: shapes")
    return errs, m


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkout", default=authors.DEFAULT_CHECKOUT)
    ap.add_argument("--fixtures", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "tests", "fixtures"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    auth = authors.load(args.checkout)
    fx = os.path.normpath(args.fixtures)
    models = {}
    for mdir in sorted(glob.glob(os.path.join(fx, "bailando_*"))):
        if os.path.isfile(os.path.join(mdir, "gpt.safetensors")):
            models[os.path.basename(mdir)[len("bailando_"):]] = load_model(auth, mdir)
    rdirs = sorted(glob.glob(os.path.join(fx, "bailando_rollout_*")))
    if not models or not rdirs:
        raise SystemExit(f"no Bailando fixtures under {fx}")
    for rdir in rdirs:
        errs, m = check_rollout(rdir, models)
        print(f"ok {os.path.basename(rdir)}: max err {errs}, min logit margin {m.logit_rel:.3g}, "
              f"min vq margin {m.vq_rel:.3g}")
    print(f"all {len(rdirs)} Bailando rollouts match ({len(models)} models)")


if __name__ == "__main__":
    main()
