#!/usr/bin/env python3
"""Self-check: reload the committed tiny models and re-run the reference on every committed
rollout; the goldens must match (tokens exactly, floats within 1e-5), every ONNX file listed in
index.json must exist and reproduce the torch module under onnx.reference.

    /work/venv/bin/python tools/reference/check_fixtures.py [--fixtures tests/fixtures] [--skip-onnx]
"""
import argparse
import glob
import json
import os
import sys

import numpy as np
import onnx
import torch
from onnx.reference import ReferenceEvaluator
from safetensors.torch import load_file

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from reference.config import load_yaml  # noqa: E402
from reference.gpt import GPT2nt  # noqa: E402
from reference.pipeline import Margins, generate_exact  # noqa: E402
from reference.vqvae import SepVQVAEXM, VQVAE  # noqa: E402

ATOL = 1e-5


def load_model(mdir):
    gpt = GPT2nt(load_yaml(f"{mdir}/follower_gpt.yaml").structure_generate).eval()
    vq = SepVQVAEXM(load_yaml(f"{mdir}/motion_vqvae.yaml").structure).eval()
    tr = VQVAE(load_yaml(f"{mdir}/transl_vqvae.yaml").structure).eval()
    gsd = load_file(f"{mdir}/gpt.safetensors")
    if not all(k.startswith("module.") for k in gsd):
        raise AssertionError(f"{mdir}/gpt.safetensors: every name must carry the module. prefix")
    gpt.load_state_dict({k[len("module."):]: v for k, v in gsd.items()}, strict=True)
    vq.load_state_dict(load_file(f"{mdir}/vqvae.safetensors"), strict=True)
    tr.load_state_dict(load_file(f"{mdir}/transl.safetensors"), strict=True)
    return gpt, vq, tr


def check_rollout(rdir, models):
    meta = json.load(open(f"{rdir}/meta.json"))
    gpt, vq, tr = models[meta["model"]]
    ld = lambda n: np.load(f"{rdir}/{n}.npy")  # noqa: E731
    seed = {"seed_tokens": ld("seed_tokens")} if meta["seed"] == "tokens" else {"follower_start": ld("follower_start")}
    m = Margins()
    res = generate_exact(gpt, vq, tr, ld("leader_pos3d"), ld("music"), margins=m, **seed)
    for k in ("tokens", "leader_tokens"):
        if not np.array_equal(res[k].numpy(), ld(k)):
            raise AssertionError(f"{rdir}: {k} differ")
    errs = {}
    for k in ("follower_pos3d", "follower_rotmat"):
        want = ld(k)
        if want.dtype != np.float32 or want.shape != tuple(res[k].shape):
            raise AssertionError(f"{rdir}: {k} dtype/shape {want.dtype}{want.shape}")
        errs[k] = float(np.abs(res[k].numpy() - want).max())
        if errs[k] > ATOL:
            raise AssertionError(f"{rdir}: {k} max err {errs[k]:.3g} > {ATOL}")
    if res["K"] != meta["K"] or res["T4"] != meta["T4"]:
        raise AssertionError(f"{rdir}: K/T4 differ from meta.json")
    print(f"ok {os.path.basename(rdir)}: K={res['K']} tokens equal, max err {errs}, "
          f"min logit margin rel {m.logit_rel:.3g}, min vq margin rel {m.vq_rel:.3g}")


def check_onnx(mdir):
    index = json.load(open(f"{mdir}/onnx/index.json"))
    rng = np.random.default_rng(0)
    for e in index:
        model = onnx.load(f"{mdir}/onnx/{e['file']}")
        onnx.checker.check_model(model)
        feeds = {}
        for i in e["inputs"]:
            feeds[i["name"]] = (rng.integers(0, 8, size=i["shape"]).astype(np.int64) if i["dtype"] == "int64"
                                else rng.normal(size=i["shape"]).astype(np.float32))
        outs = ReferenceEvaluator(model).run(None, feeds)
        for o, got in zip(e["outputs"], outs):
            if list(got.shape) != o["shape"] or str(got.dtype) != o["dtype"]:
                raise AssertionError(f"{e['file']}: output {o['name']} is {got.dtype}{got.shape}, index says {o}")
    print(f"ok {mdir}/onnx: {len(index)} files load and match index.json shapes")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    here = os.path.dirname(os.path.abspath(__file__))
    ap.add_argument("--fixtures", default=os.path.normpath(os.path.join(here, "..", "..", "tests", "fixtures")))
    ap.add_argument("--skip-onnx", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(1)
    models = {}
    for mdir in sorted(glob.glob(f"{args.fixtures}/tiny*/")):
        models[os.path.basename(mdir.rstrip("/"))] = load_model(mdir.rstrip("/"))
        if not args.skip_onnx:
            check_onnx(mdir.rstrip("/"))
    rdirs = sorted(glob.glob(f"{args.fixtures}/rollout_*"))
    if not rdirs:
        raise AssertionError("no rollout_* directories")
    for rdir in rdirs:
        check_rollout(rdir, models)
    print("all fixtures ok")


if __name__ == "__main__":
    main()
