#!/usr/bin/env python3
"""Self-check of tests/fixtures/transflower_*/:
1. the AUTHORS' classes, loaded from model.safetensors + hparams.yaml, replaying noise.npy,
   reproduce output.npy and flow_out.npy (bit for bit with the torch that wrote them, else
   within REPLAY_RTOL) and, with stages, stages_step0.safetensors;
2. the Student-t noise equals normal / sqrt(chi2_over_df) as the authors compute it;
3. documented.py (README's algorithm in plain float64 ops, no authors' class) reproduces
   output.npy within DOC_RTOL, and cond / flow output of step 0.

    /work/venv/bin/python tools/reference/transflower/check_fixtures.py [--fixtures tests/fixtures]
"""
import argparse
import glob
import json
import os
import sys

import numpy as np
import torch
import yaml
from safetensors.numpy import load_file as load_np
from safetensors.torch import load_file

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from transflower import documented, reference  # noqa: E402

REPLAY_RTOL = 1e-5  # another torch build
DOC_RTOL = 1e-4     # float64 restatement vs float32 golden (observed <= ~1e-5, see meta.json)


def rel(a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float((np.abs(a - b) / np.maximum(1.0, np.abs(b))).max())


def check(d):
    meta = json.load(open(os.path.join(d, "meta.json")))
    hp = yaml.safe_load(open(os.path.join(d, "config.yaml")))
    opt = yaml.safe_load(open(os.path.join(d, "hparams.yaml")))
    state = load_file(os.path.join(d, "model.safetensors"))
    inputs = {m: np.load(os.path.join(d, f"in_{m}.npy")) for m in meta["input_modalities"]}
    gold = {k: np.load(os.path.join(d, k + ".npy")) for k in ("output", "flow_out", "noise")}
    same_torch = meta["torch"] == torch.__version__
    tol = 0.0 if same_torch else REPLAY_RTOL
    report = {}

    model = reference.build_from_state(hp, state)
    has_stages = os.path.exists(os.path.join(d, "stages_step0.safetensors"))
    res = reference.generate(model, inputs, replay={"noise": gold["noise"]}, stages=has_stages)
    for k in ("output", "flow_out"):
        e = rel(res[k], gold[k])
        assert e <= tol, f"{d}: authors' replay {k} {e:.3g} > {tol}"
    report["authors_replay"] = "bit-identical" if tol == 0.0 else rel(res["output"], gold["output"])
    if has_stages:
        st = load_np(os.path.join(d, "stages_step0.safetensors"))
        assert set(st) == set(res["stages"]), set(st) ^ set(res["stages"])
        e = max(rel(res["stages"][k], st[k]) for k in st)
        assert e <= tol, f"{d}: stages {e:.3g}"
        report["stages"] = len(st)

    if os.path.exists(os.path.join(d, "noise_normal.npy")):
        nn_ = np.load(os.path.join(d, "noise_normal.npy"))
        chi = np.load(os.path.join(d, "noise_chi2_over_df.npy"))
        z = torch.from_numpy(nn_) / torch.sqrt(torch.from_numpy(chi)[:, None, :])
        assert torch.equal(z, torch.from_numpy(gold["noise"])), f"{d}: Student-t composition"
        report["student_t_composition"] = "exact"

    out, stg = documented.generate(state, opt, inputs, gold["noise"])
    e = rel(out.numpy(), gold["output"][:, 0, :])
    assert e <= DOC_RTOL, f"{d}: documented algorithm vs golden {e:.3g} > {DOC_RTOL}"
    report["documented_vs_golden_max_rel"] = e
    report["documented_step0_flow_out_rel"] = rel(stg["flow_out"].numpy(), gold["flow_out"][0])
    if has_stages:
        key = [k for k in st if k.endswith(".cond")][0]
        report["documented_step0_cond_rel"] = rel(stg["cond"].numpy(), st[key][0])
        assert report["documented_step0_cond_rel"] <= DOC_RTOL
    return report


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--fixtures", default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                       "..", "..", "..", "tests", "fixtures"))
    args = ap.parse_args()
    torch.set_num_threads(1)
    dirs = sorted(glob.glob(os.path.join(os.path.normpath(args.fixtures), "transflower_*")))
    assert dirs, "no transflower fixtures"
    for d in dirs:
        print(os.path.basename(d), json.dumps(check(d)), flush=True)
    print("ok")


if __name__ == "__main__":
    main()
