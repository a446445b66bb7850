#!/usr/bin/env python3
"""Self-check of the Bailando fixtures: load each committed tiny model into the AUTHORS'
classes (nn.DataParallel-wrapped, strict=True, `module.` names), rerun our AC.eval driver
on every committed rollout and compare: tokens and dance codes exactly, pos3d and
logits_step0 within 1e-5, meta.json counts; also the input and output dtypes/shapes.
Then replays each rollout a second way, the algorithm exactly as README.md states it
(`replay_documented`: explicit windows, single-module calls), against the same goldens.

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


def replay_documented(auth, vq, gpt, cfg, music, dance, seed):
    """The algorithm as README.md states it, index by index, calling only the authors'
    single modules (encoders + nearest code, gpt.forward on an explicit window, part
    decoders): must give the goldens too. Returns (tokens (K+1, 2), pos3d (N, 72))."""
    g, v = gpt.module, vq.module
    bs1 = cfg.structure_generate.block_size - 1
    with torch.no_grad():
        if cfg.demo:
            x = [int(seed[0]), int(seed[1])]
            r = len(music)
            padded = np.concatenate([music] + [music[-1:]] * ((r // cfg.move + 1) * cfg.move - r))
        else:
            d = dance.astype(np.float64)
            d[:, 3:] -= np.tile(d[:, :3], (1, 23))
            t = len(d)
            d = np.concatenate([d] + [d[-1:]] * ((t // cfg.move + 1) * cfg.move - t))
            d = torch.from_numpy(d).float().view(1, -1, 24, 3)
            x = []
            for name, joints in (("up", auth.smpl_up), ("down", auth.smpl_down)):
                part = getattr(v, "vqvae_" + name)
                xp = d[:, :, joints].reshape(1, d.shape[1], -1).clone()
                if name == "down":
                    xp[:, :, :3] = 0
                feats = part.encoders[0](xp.permute(0, 2, 1))[-1][0].t()           # (n, emb)
                k = part.bottleneck.level_blocks[0].k
                dist = (feats ** 2).sum(-1, keepdim=True) - 2 * feats @ k.t() + (k ** 2).sum(-1)[None]
                x.append(int(dist.argmin(-1)[0]))
            padded = np.concatenate([music, music[-1:]])
        cond = torch.from_numpy(padded[:, :cfg.structure_generate.n_music]).float()
        K = len(padded) - 1
        toks = [x]
        for k in range(K):
            c = min(k + 1, bs1)
            lo = k + 1 - c
            win = torch.tensor(toks[lo:k + 1]).T[:, None, :]                        # (2, 1, c)
            (lu, ld), _ = g.forward((win[0], win[1]), cond[lo + 1:k + 2][None])
            toks.append([int(lu[0, -1].argmax()), int(ld[0, -1].argmax())])
        z = torch.tensor(toks)                                                    # (K+1, 2)
        up = v.vqvae_up.decoders[0]([v.vqvae_up.bottleneck.level_blocks[0].k[z[:, 0]].t()[None]], all_levels=False)
        dn = v.vqvae_down.decoders[0]([v.vqvae_down.bottleneck.level_blocks[0].k[z[:, 1]].t()[None]], all_levels=False)
        vel = v.vqvae_down.decoders_root[0]([v.vqvae_down.bottleneck.level_blocks[0].k[z[:, 1]].t()[None]], all_levels=False)
        n = up.shape[-1]
        out = torch.zeros(n, 24, 3)
        out[:, auth.smpl_up] = up[0].t().reshape(n, -1, 3)
        out[:, auth.smpl_down] = dn[0].t().reshape(n, -1, 3)
        vel = vel[0].t()
        root = torch.zeros(n, 3)
        for i in range(1, n):
            root[i] = root[i - 1] + vel[i - 1]
        out[:, 1:] += root[:, None]
        out[:, 0] = root
    return z.numpy(), out.reshape(n, 72).numpy()


def check_rollout(rdir, models, auth=None):
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
    if auth is not None:
        tok2, pos2 = replay_documented(auth, vq, gpt, cfgs[meta["config"]], music, dance, seed)
        if not np.array_equal(tok2, ld("tokens")):
            raise AssertionError(f"{rdir}: README algorithm replay: tokens differ")
        errs["pos3d_readme_replay"] = float(np.abs(pos2 - ld("pos3d")).max())
        if errs["pos3d_readme_replay"] > ATOL:
            raise AssertionError(f"{rdir}: README algorithm replay: pos3d err {errs['pos3d_readme_replay']:.3g}")
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
        errs, m = check_rollout(rdir, models, auth)
        print(f"ok {os.path.basename(rdir)}: max err {errs}, min logit margin {m.logit_rel:.3g}, "
              f"min vq margin {m.vq_rel:.3g}")
    print(f"all {len(rdirs)} Bailando rollouts match ({len(models)} models)")


if __name__ == "__main__":
    main()
