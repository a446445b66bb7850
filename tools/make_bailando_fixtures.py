#!/usr/bin/env python3
"""Write the Bailando fixtures: tests/fixtures/bailando_<model>/ (authors' YAML + weights)
and tests/fixtures/bailando_rollout_<name>/ (greedy AC.eval goldens), made with the AUTHORS'
classes (lisiyao21/Bailando checkout) and our driver tools/reference/bailando/pipeline.py.

Deterministic. Seeds are searched as in tools/make_fixtures.py: the first codebook seed
(from 0) whose every nearest-code decision of every rollout of the model clears VQ_FLOOR,
then the first GPT seed (from 1000) whose every greedy decision clears LOGIT_FLOOR; every
rollout is rerun in float64: tokens must be equal and positions within GOLDEN_ATOL.

    mkdir -p /tmp/bailando && git -C /work/.mirror/lisiyao21+Bailando/repo archive HEAD models | tar -x -C /tmp/bailando
    /work/venv/bin/python tools/make_bailando_fixtures.py [--checkout /tmp/bailando] [--out tests/fixtures]
"""
import argparse
import itertools
import json
import os
import shutil
import sys

import numpy as np
import torch
import yaml
from safetensors.torch import save_file

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reference.config import Cfg  # noqa: E402
from reference.bailando import authors, synth, tiny  # noqa: E402
from reference.bailando.pipeline import Margins, MarginTooSmall, eval_one  # noqa: E402

LOGIT_FLOOR = 1e-3   # min (top1 - top2) / max|logit| over every greedy decision
VQ_FLOOR = 1e-4      # min (d2 - d1) / (|x|^2 + |k_best|^2) over every nearest-code decision
GOLDEN_ATOL = 1e-5   # float64 rerun vs float32 golden, positions
VQ_SEED = 1          # VQ-VAE weights (codebooks searched separately)
MIN_VARIETY = 0.5    # GPT seed search: distinct (up, down) rows / rows >= this on rollouts with K >= 20

# name -> (model, path, input seed, music rows, dance frames (aist path only))
ROLLOUTS = {
    "btiny_aist_min": ("btiny", "aist", 301, 1, 1),
    "btiny_aist_slide": ("btiny", "aist", 302, 37, 291),
    "btiny_demo_min": ("btiny", "demo", 303, 1, None),
    "btiny_demo_odd": ("btiny", "demo", 304, 21, None),
    "btiny2_aist_odd": ("btiny2", "aist", 401, 29, 119),
    "btiny2_aist_short": ("btiny2", "aist", 402, 6, 24),
    "btiny2_demo_slide": ("btiny2", "demo", 403, 45, None),
    "btiny2_demo_exact": ("btiny2", "demo", 404, 16, None),
}
CONFIG_OF_PATH = {"aist": "actor_critic.yaml", "demo": "actor_critic_demo.yaml"}


def rollout_inputs(name):
    model, path, seed, rows, frames = ROLLOUTS[name]
    rng = np.random.default_rng(seed)
    inp = {"music": synth.music(rng, rows, tiny.SIZES[model]["n_music"])}
    if path == "aist":
        inp["dance"] = synth.dance(rng, frames)
    else:
        inp["seed_tokens"] = rng.integers(0, tiny.SIZES[model]["l_bins"], size=2).astype(np.int64)
    return inp


def run(vq, gpt, cfgs, name, margins=None):
    inp = rollout_inputs(name)
    cfg = cfgs[CONFIG_OF_PATH[ROLLOUTS[name][1]]]
    return eval_one(vq, gpt, cfg, inp["music"], inp.get("dance"), inp.get("seed_tokens"), margins)


def save_npy(path, arr):
    arr = np.ascontiguousarray(arr)
    assert arr.dtype in (np.float32, np.int64), arr.dtype
    np.save(path, arr.astype(arr.dtype.newbyteorder("<")))


def variety(tokens):
    return len(set(map(tuple, tokens.tolist()))) / len(tokens)


def first_seed(start, setup, names, run_fn, min_variety=0.0, **floors):
    """First seed >= start whose rollouts clear the floors (and, for long ones, the variety)."""
    for seed in itertools.count(start):
        setup(seed)
        try:
            for n in names:
                res = run_fn(n, Margins(**floors))
                if res["K"] >= 20 and variety(res["tokens"]) < min_variety:
                    raise MarginTooSmall("too few distinct tokens")
        except MarginTooSmall:
            continue
        return seed


def make_model(auth, model, out, report):
    names = [n for n, r in ROLLOUTS.items() if r[0] == model]
    docs = tiny.yaml_docs(model)
    cfgs = {k: Cfg(v) for k, v in docs.items()}
    vq, gpt = authors.build(auth, cfgs["actor_critic.yaml"])
    s = tiny.SIZES[model]
    tiny.init_weights(vq.module, gpt.module, VQ_SEED, 1000)
    run_fn = lambda n, m: run(vq, gpt, cfgs, n, m)  # noqa: E731
    aist_names = [n for n in names if ROLLOUTS[n][1] == "aist"]
    cb_seed = first_seed(0, lambda sd: tiny.init_codebooks(auth, vq.module, sd, s["l_bins"]), aist_names,
                         run_fn, vq_floor=VQ_FLOOR)
    gpt_seed = first_seed(1000, lambda sd: tiny.init_weights(vq.module, gpt.module, None, sd), names,
                          run_fn, min_variety=MIN_VARIETY, logit_floor=LOGIT_FLOOR, vq_floor=VQ_FLOOR)
    print(f"[{model}] codebook seed {cb_seed}, gpt seed {gpt_seed}", flush=True)

    mdir = os.path.join(out, f"bailando_{model}")
    shutil.rmtree(mdir, ignore_errors=True)
    os.makedirs(mdir)
    for fname, doc in docs.items():
        with open(os.path.join(mdir, fname), "w") as f:
            yaml.safe_dump(doc, f, sort_keys=False)
    save_file({k: v.contiguous() for k, v in gpt.state_dict().items()}, os.path.join(mdir, "gpt.safetensors"))
    save_file({k: v.contiguous() for k, v in vq.state_dict().items()}, os.path.join(mdir, "vqvae.safetensors"))
    n_params = {"gpt": sum(v.numel() for v in gpt.state_dict().values()),
                "gpt_critic_only": sum(v.numel() for k, v in gpt.state_dict().items() if ".critic_net." in k),
                "vqvae": sum(v.numel() for v in vq.state_dict().values())}
    report[model] = {"codebook_seed": cb_seed, "gpt_seed": gpt_seed, "vq_seed": VQ_SEED, "state_numel": n_params}

    with authors.float64():
        vq64, gpt64 = authors.build(auth, cfgs["actor_critic.yaml"])
    vq64.double().load_state_dict(vq.state_dict(), strict=True)
    gpt64.double().load_state_dict(gpt.state_dict(), strict=True)
    for n in names:
        _, path, _, _, _ = ROLLOUTS[n]
        inp = rollout_inputs(n)
        m = Margins()
        res = run(vq, gpt, cfgs, n, m)
        with authors.float64():
            res64 = run(vq64, gpt64, cfgs, n)
        if not torch.equal(res["tokens"], res64["tokens"]):
            raise AssertionError(f"{n}: float64 tokens differ")
        if res["dance_codes"] is not None and not torch.equal(res["dance_codes"], res64["dance_codes"]):
            raise AssertionError(f"{n}: float64 dance codes differ")
        err_pos = float(np.abs(res["pos3d"].astype(np.float64) - res64["pos3d"]).max())
        err_lg = float((res["logits_step0"].double() - res64["logits_step0"]).abs().max())
        if err_pos > GOLDEN_ATOL:
            raise AssertionError(f"{n}: pos3d float32 vs float64 {err_pos:.3g} > {GOLDEN_ATOL}")
        rdir = os.path.join(out, f"bailando_rollout_{n}")
        shutil.rmtree(rdir, ignore_errors=True)
        os.makedirs(rdir)
        for k, v in inp.items():
            save_npy(os.path.join(rdir, k + ".npy"), v)
        save_npy(os.path.join(rdir, "tokens.npy"), res["tokens"].numpy())
        save_npy(os.path.join(rdir, "pos3d.npy"), res["pos3d"])
        save_npy(os.path.join(rdir, "logits_step0.npy"), res["logits_step0"].numpy())
        if res["dance_codes"] is not None:
            save_npy(os.path.join(rdir, "dance_codes.npy"), res["dance_codes"].numpy())
        cfg = cfgs[CONFIG_OF_PATH[path]]
        window = cfg.structure_generate.block_size - 1
        hop = 2 ** s["downs_t"]
        meta = {"model": model, "path": path, "config": CONFIG_OF_PATH[path],
                "music_rows": int(inp["music"].shape[0]), "music_rows_padded": res["music_rows"],
                "dance_frames": int(inp["dance"].shape[0]) if "dance" in inp else None,
                "dance_frames_padded": res["dance_frames"],
                "n_dance_codes": None if res["dance_codes"] is None else int(res["dance_codes"].shape[0]),
                "K": res["K"], "n_tokens": res["K"] + 1, "hop": hop, "n_frames": res["n_frames"],
                "window_max": window, "window_slides": res["K"] > window,
                "seed_tokens": res["tokens"][0].tolist(),
                "min_logit_margin_rel": m.logit_rel, "min_logit_margin_abs": m.logit_abs,
                "min_vq_margin_rel": None if m.vq_rel == float("inf") else m.vq_rel,
                "min_vq_margin_abs": None if m.vq_abs == float("inf") else m.vq_abs,
                "f32_vs_f64_max_abs_err": {"pos3d": err_pos, "logits_step0": err_lg},
                "distinct_tokens": [len(set(res["tokens"][:, i].tolist())) for i in range(2)],
                "distinct_rows_frac": variety(res["tokens"]),
                "max_abs_pos3d": float(np.abs(res["pos3d"]).max())}
        with open(os.path.join(rdir, "meta.json"), "w") as f:
            json.dump(meta, f, indent=1)
        report[n] = meta
        print(f"[{n}] {json.dumps(meta)}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkout", default=authors.DEFAULT_CHECKOUT, help="lisiyao21/Bailando checkout (needs models/)")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures"))
    ap.add_argument("--only", choices=sorted(tiny.SIZES), action="append")
    args = ap.parse_args()
    torch.set_num_threads(1)
    auth = authors.load(args.checkout)
    report = {}
    for model in args.only or sorted(tiny.SIZES):
        make_model(auth, model, os.path.normpath(args.out), report)
    print(json.dumps({k: v for k, v in report.items() if k in tiny.SIZES}, indent=1))


if __name__ == "__main__":
    main()
