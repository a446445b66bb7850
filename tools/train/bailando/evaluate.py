#!/usr/bin/env python3
"""Bailando demo: quality on the held-out takes, from music alone (the demo path,
`duolando generate --seed-tokens UP,DOWN --mode exact` on the converted .duo).

Per held-out take (one music, two real dancers): the generated dance's tokens (distinct up /
down codes, longest run of one code, share of steps repeating the previous code), its root
motion (horizontal speed, distance from the start: first and last 10 s, maximum) against the
real dancers', then `duolando eval` (FID_k / FID_g / Div_k / Div_g / BAS / foot skating) of the
generated set against the held-out real set. `duolando eval` reads SMPL-X (T, 165) at 30 fps,
so every SMPL-24 60 fps dance (generated and real alike) is written as SMPL-X: every second
frame (the real ones: exactly the synth's 30 fps frames), joints 0..21 as they are, the five
finger bases of each hand (and every other finger joint) at SMPL joint 22 / 23, jaw and eyes at
the head; the metrics' SMPL-24 view (`smpl24_rooted`: the mean of the five finger bases) is then
the SMPL-24 dance itself. Real set: both dancers of each held-out take, the leader renamed
<Genre>_<CC>_<TT+50> (music copied under that name for BAS). BAS uses the synth's (T, 54) music
features (beat column 53: the synth's beat grid, the beats the audio's clicks were rendered on).
The real set's features are saved as <out>/real_stats.json (`duolando eval --save-real`): the
bundled assets/bailando_demo_real_stats.json is that file of the demo model's evaluation.
Also: the reference figures of training dances against the same real set (what a perfect
copy of the training distribution scores) and of the VQ-VAE round trip of the held-out dances.
"""
import argparse
import json
import os
import shutil
import subprocess
import tempfile

import numpy as np

import common as C


def to_smplx30(d72):
    d = d72[0::2].reshape(-1, 24, 3)
    out = np.empty((len(d), 55, 3), np.float32)
    out[:, :22] = d[:, :22]
    out[:, 22:25] = d[:, 15:16]
    out[:, 25:40] = d[:, 22:23]
    out[:, 40:55] = d[:, 23:24]
    return out.reshape(len(d), 165)


def runs(x):
    best, cur = 1, 1
    for a, b in zip(x[:-1], x[1:]):
        cur = cur + 1 if a == b else 1
        best = max(best, cur)
    return best


def root_stats(d72):
    r = d72[:, [0, 2]]
    sp = np.linalg.norm(np.diff(r, axis=0), axis=1) * C.FPS
    dist = np.linalg.norm(r - r[0], axis=1)
    return {"speed_mps": float(sp.mean()), "max_dist_m": float(dist.max()), "end_dist_m": float(dist[-1])}


def foot_stats(d72):
    """Own skating figure at 60 fps: horizontal ankle/foot speed (m/s) on frames where that foot
    is the lower one and within 5 cm of the lowest foot point of the clip."""
    x = d72.reshape(-1, 24, 3)
    feet = x[:, [10, 11]]  # SMPL left / right foot
    h = feet[..., 1]
    floor = h.min()
    v = np.linalg.norm(np.diff(feet[..., [0, 2]], axis=0), axis=-1) * C.FPS
    low = (h[:-1] < floor + 0.05) & (h[:-1] <= h[:-1].max(1, keepdims=True))
    return float(v[low].mean()) if low.any() else 0.0


def eval_dir(binary, gen, real, music, js, extra=()):
    cmd = [binary, "eval", "--gen", gen, "--real", real, "--music", music, "--json", js, *extra]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError(r.stderr)
    return json.load(open(js)), " ".join(cmd)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", required=True, help="prepare_data.py output")
    ap.add_argument("--synth", required=True, help="the duolando synth folder (54-d music for BAS)")
    ap.add_argument("--duo", required=True)
    ap.add_argument("--seed-tokens", required=True)
    ap.add_argument("--vqvae", help="VQ-VAE checkpoint: adds the round-trip reference")
    ap.add_argument("--checkout", default="/tmp/bailando")
    ap.add_argument("--bin", default="/work/bin/duolando")
    ap.add_argument("--out", required=True)
    ap.add_argument("--json", required=True)
    ap.add_argument("--stream", default="",
                    help="generate in a streaming session with these flags instead of R mode, e.g. "
                         "\"--preset reference --topk 3 --rng-seed 1\" (sampling: the authors' `samplek`)")
    args = ap.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    dirs = {k: os.path.join(args.out, k) for k in ("gen", "real", "train", "recon", "music", "raw")}
    for d in dirs.values():
        os.makedirs(d)
    test = C.load_split(args.data, "test")
    takes = sorted({n[:-3] for n, _, _ in test})
    real = {n: d for n, d, _ in test}
    music54 = lambda take: os.path.join(args.synth, "music", "feature", "test", take + ".npy")  # noqa: E731

    def alias(take):  # the leader as another clip name (TT + 50)
        g, c, t = take.split("_")
        return f"{g}_{c}_{int(t) + 50:02d}"

    per_take, all_up, all_down, tok_rows = {}, [], [], 0
    for take in takes:
        out = os.path.join(dirs["raw"], take)
        music = os.path.join(args.data, "wav", take + ".npy")
        mode = ["--mode", "streaming"] + args.stream.split() if args.stream else ["--mode", "exact"]
        subprocess.run([args.bin, "generate", "--model", args.duo, "--music", music, "--seed-tokens", args.seed_tokens,
                        *mode, "--out", out], check=True, capture_output=True)
        tok = np.load(os.path.join(out, "tokens.npy"))
        pos = np.load(os.path.join(out, "pos3d.npy"))
        t60 = len(real[take + "_00"])
        pos = pos[:t60]
        np.save(os.path.join(dirs["gen"], take + "_00.npy"), to_smplx30(pos))
        shutil.copy(music54(take), os.path.join(dirs["music"], take + ".npy"))
        shutil.copy(music54(take), os.path.join(dirs["music"], alias(take) + ".npy"))
        np.save(os.path.join(dirs["real"], take + "_00.npy"), to_smplx30(real[take + "_00"]))
        np.save(os.path.join(dirs["real"], alias(take) + "_00.npy"), to_smplx30(real[take + "_01"]))
        t = tok[1:]  # row 0 is the seed
        all_up.append(t[:, 0])
        all_down.append(t[:, 1])
        tok_rows += len(t)
        per_take[take] = {
            "tokens": int(len(t)),
            "distinct_up": int(len(set(t[:, 0]))), "distinct_down": int(len(set(t[:, 1]))),
            "distinct_up_frac": len(set(t[:, 0])) / len(t), "distinct_down_frac": len(set(t[:, 1])) / len(t),
            "longest_run_up": runs(t[:, 0]), "longest_run_down": runs(t[:, 1]),
            "repeat_prev_up": float((t[1:, 0] == t[:-1, 0]).mean()), "repeat_prev_down": float((t[1:, 1] == t[:-1, 1]).mean()),
            "root_gen": root_stats(pos), "root_real": [root_stats(real[take + s]) for s in ("_00", "_01")],
            "foot_speed_gen": foot_stats(pos), "foot_speed_real": [foot_stats(real[take + s]) for s in ("_00", "_01")],
            "pose_std_gen_m": float(C.loader_dance(pos)[:, 3:].std(0).mean()),
            "pose_std_real_m": float(np.mean([C.loader_dance(real[take + s])[:, 3:].std(0).mean() for s in ("_00", "_01")])),
        }
    up, down = np.concatenate(all_up), np.concatenate(all_down)

    def mean(key, sub=None):
        v = [p[key] if sub is None else p[key][sub] for p in per_take.values()]
        return float(np.mean(v))

    summary = {
        "takes": len(takes), "generated_tokens": tok_rows,
        "distinct_codes_used": {"up": int(len(set(up))), "down": int(len(set(down))), "vocab": C.BDEMO["l_bins"]},
        "mean_distinct_frac_per_take": {"up": mean("distinct_up_frac"), "down": mean("distinct_down_frac")},
        "longest_run_max": {"up": max(p["longest_run_up"] for p in per_take.values()),
                            "down": max(p["longest_run_down"] for p in per_take.values())},
        "longest_run_mean": {"up": mean("longest_run_up"), "down": mean("longest_run_down")},
        "repeat_prev": {"up": mean("repeat_prev_up"), "down": mean("repeat_prev_down")},
        "root_speed_mps": {"gen": mean("root_gen", "speed_mps"),
                           "real": float(np.mean([r["speed_mps"] for p in per_take.values() for r in p["root_real"]]))},
        "root_max_dist_m": {"gen_max": max(p["root_gen"]["max_dist_m"] for p in per_take.values()),
                            "gen_mean": mean("root_gen", "max_dist_m"),
                            "real_mean": float(np.mean([r["max_dist_m"] for p in per_take.values() for r in p["root_real"]]))},
        "foot_speed_when_low_mps": {"gen": mean("foot_speed_gen"),
                                    "real": float(np.mean([f for p in per_take.values() for f in p["foot_speed_real"]]))},
        "pose_std_m": {"gen": mean("pose_std_gen_m"), "real": mean("pose_std_real_m")},
    }
    res = {"summary": summary}
    res["eval_gen_vs_real"], res["eval_cmd"] = eval_dir(args.bin, dirs["gen"], dirs["real"], dirs["music"],
                                                        os.path.join(args.out, "eval_gen.json"))
    # reference: as many training dances (first take of each training choreography) against the real set
    train = C.load_split(args.data, "train")
    seen, picked = set(), []
    for n, d, _ in train:
        chore = n.split("_")[1]
        if n.endswith("_00") and chore not in seen:
            seen.add(chore)
            picked.append((n, d))
    for n, d in picked[:len(takes)]:
        np.save(os.path.join(dirs["train"], n[:-3] + "_00.npy"), to_smplx30(d))
        shutil.copy(os.path.join(args.synth, "music", "feature", "train", n[:-3] + ".npy"), os.path.join(dirs["music"], n[:-3] + ".npy"))
    res["eval_train_vs_real"], _ = eval_dir(args.bin, dirs["train"], dirs["real"], dirs["music"], os.path.join(args.out, "eval_train.json"))
    res["eval_real_bas"], _ = eval_dir(args.bin, dirs["real"], dirs["real"], dirs["music"], os.path.join(args.out, "eval_real.json"),
                                       ["--save-real", os.path.join(args.out, "real_stats.json")])
    if args.vqvae:
        import torch
        auth = C.load_authors(args.checkout)
        vq, _ = C.build(auth, train=False)
        vq.load_state_dict(torch.load(args.vqvae, weights_only=False)["model"])
        errs, root_errs = [], []
        for n, d, _ in test:
            x = torch.from_numpy(C.loader_dance(C.pad8(d))).float()[None]
            with torch.no_grad():
                zs = vq.encode(x)
                y = vq.decode(zs)[0].numpy()[:len(d)]
            rel = C.loader_dance(d)
            errs.append(np.linalg.norm((y[:, 3:] - rel[:, 3:]).reshape(-1, 23, 3), axis=-1).mean())
            vel = np.diff(d[:, :3], axis=0)
            root_errs.append(np.abs(y[:-1, :3] - vel).mean() * C.FPS)
        res["vq_round_trip"] = {"joint_err_mm_pelvis_relative": float(np.mean(errs) * 1000),
                                "root_velocity_l1_mps": float(np.mean(root_errs))}
    res["per_take"] = per_take
    json.dump(res, open(args.json, "w"), indent=1, default=float)
    keys = ("fid_k", "fid_g", "div_k", "div_g", "div_k_real", "div_g_real", "bas", "fsr")
    print(json.dumps(summary, indent=1))
    for k in ("eval_gen_vs_real", "eval_train_vs_real", "eval_real_bas"):
        print(k, {a: res[k].get(a) for a in res[k] if any(a.startswith(b) for b in keys)})
    print("vq_round_trip", res.get("vq_round_trip"))


if __name__ == "__main__":
    main()
