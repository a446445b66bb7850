#!/usr/bin/env python3
"""Cross-check the committed goldens against the ORIGINAL Duolando code (run on CPU).

Needs a checkout of lisiyao21/Duolando (only its `models/` package is imported, at run time;
nothing is copied). Its GPU-only bits are neutralised: Tensor.cuda becomes a no-op and the
unused imports pytorch3d / smplx / tqdm are stubbed. For each rollout it loads the tiny
weights with strict=True into the original classes, replays the authors' eval steps
(gpt2t.py MCTall.eval: normalise, encode, GPT2nt.sample, decode, de-normalise) and compares.

    git -C <mirror> archive HEAD models | tar -x -C /tmp/duolando
    /work/venv/bin/python tools/reference/compare_original.py /tmp/duolando
"""
import argparse
import glob
import json
import os
import sys
import types

import numpy as np
import torch
from safetensors.torch import load_file

HERE = os.path.dirname(os.path.abspath(__file__))


def import_original(repo):
    torch.Tensor.cuda = lambda self, *a, **k: self  # the original allocates with .cuda()
    stubs = {"tqdm": {"tqdm": None}, "pytorch3d": {}, "pytorch3d.transforms": {},
             "pytorch3d.transforms.rotation_conversions": {"matrix_to_axis_angle": None},
             "smplx": {"SMPL": None}}
    for name, attrs in stubs.items():
        mod = types.ModuleType(name)
        for k, v in attrs.items():
            setattr(mod, k, v)
        sys.modules.setdefault(name, mod)
    sys.path.insert(0, repo)
    from models.gpt2nt_woln import GPT2nt
    from models.sep_vqvae_xm import SepVQVAEXM
    from models.vqvae import VQVAE
    return GPT2nt, SepVQVAEXM, VQVAE


def dataset_normalise(p):
    """datasets/dd100lf_all2.py pos3d normalisation (numpy, float32)."""
    p = p.astype(np.float32).copy()
    root = p[:, :3].copy()
    p = p - np.tile(root, (1, 55))
    p[:, :3] = root
    p[:, 75:120] = (p[:, 75:120] - np.tile(p[:, 60:63], (1, 15))) * 10
    p[:, 120:165] = (p[:, 120:165] - np.tile(p[:, 63:66], (1, 15))) * 10
    return p


def replay(og, ov, ot, rdir, meta):
    ld = lambda n: np.load(f"{rdir}/{n}.npy")  # noqa: E731
    leader, music = ld("leader_pos3d"), ld("music")
    t4 = len(leader) // 4 * 4
    pl = torch.from_numpy(dataset_normalise(leader[:t4]))[None]
    ms = torch.from_numpy(music[:t4])[None]
    transll = pl[:, :, :3].clone()
    transll = transll - transll[:, :1, :3].clone()
    pl[:, :, :3] = 0
    y = tuple(z[0] for z in ov.encode(pl))
    if meta["seed"] == "frames":
        fs = ld("follower_start")
        pf = torch.from_numpy(dataset_normalise(fs))[None]
        lft = (pf[:, :, :3] - torch.from_numpy(leader[None, :len(fs), :3])) * 20.0
        pf[:, :, :3] = 0
        x = tuple(z[0][:, :1] for z in ov.encode(pf[:, :4]))
        tr = (ot.encode(lft)[0][:, :1],)
    else:
        s = torch.from_numpy(ld("seed_tokens"))
        x, tr = tuple(s[i].view(1, 1) for i in range(4)), (s[4].view(1, 1),)
    zs, tz = og.sample(x + tr, cond=(ms[:, 4:],) + y)
    tokens = torch.cat([z[0] for z in zs] + [tz[0]], 0).t().numpy()
    pose, rot, _ = ov.decode(zs)
    lt = ot.decode(tz)
    pose[:, :, :3] = transll[:, :lt.size(1)] + lt / 20.0
    pose = pose.numpy()
    pose[:, :, 75:120] = pose[:, :, 75:120] * 0.1 + np.tile(pose[:, :, 60:63], (1, 1, 15))
    pose[:, :, 120:165] = pose[:, :, 120:165] * 0.1 + np.tile(pose[:, :, 63:66], (1, 1, 15))
    root = pose[:, :, :3]
    pose = pose + np.tile(root, (1, 1, 55))
    pose[:, :, :3] = root
    pose = pose[0] + np.tile(leader[:1, :3], (1, 55))  # leader's input coordinates
    return {"tokens_equal": bool(np.array_equal(tokens, ld("tokens"))),
            "leader_tokens_equal": bool(np.array_equal(torch.cat(y, 0).t().numpy(), ld("leader_tokens"))),
            "pos_max_err": float(np.abs(pose - ld("follower_pos3d")).max()),
            "rot_max_err": float(np.abs(rot[0].numpy() - ld("follower_rotmat")).max())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("repo", help="directory holding the original `models/` package")
    ap.add_argument("--fixtures", default=os.path.normpath(os.path.join(HERE, "..", "..", "tests", "fixtures")))
    args = ap.parse_args()
    torch.set_num_threads(1)
    GPT2nt, SepVQVAEXM, VQVAE = import_original(args.repo)
    sys.path.insert(0, os.path.dirname(HERE))
    from reference.config import load_yaml
    failed = False
    with torch.no_grad():
        models = {}
        for rdir in sorted(glob.glob(f"{args.fixtures}/rollout_*")):
            meta = json.load(open(f"{rdir}/meta.json"))
            name = meta["model"]
            if name not in models:
                mdir = f"{args.fixtures}/{name}"
                og = GPT2nt(load_yaml(f"{mdir}/follower_gpt.yaml").structure_generate).eval()
                ov = SepVQVAEXM(load_yaml(f"{mdir}/motion_vqvae.yaml").structure).eval()
                ot = VQVAE(load_yaml(f"{mdir}/transl_vqvae.yaml").structure).eval()
                og.load_state_dict({k[len("module."):]: v for k, v in load_file(f"{mdir}/gpt.safetensors").items()}, strict=True)
                ov.load_state_dict(load_file(f"{mdir}/vqvae.safetensors"), strict=True)
                ot.load_state_dict(load_file(f"{mdir}/transl.safetensors"), strict=True)
                models[name] = (og, ov, ot)
            res = replay(*models[name], rdir, meta)
            ok = res["tokens_equal"] and res["leader_tokens_equal"] and res["pos_max_err"] <= 1e-5 and res["rot_max_err"] <= 1e-5
            failed |= not ok
            print(("ok " if ok else "FAIL ") + os.path.basename(rdir), json.dumps(res), flush=True)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
