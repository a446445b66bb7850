#!/usr/bin/env python3
"""The papers' metrics (`duolando eval`) of a Transflower demo model on the held-out takes.

    /work/venv/bin/python tools/train/transflower/evaluate.py --model M.duo \
        --prep /work/tfdata/prep --synth /work/tfdata/synth --work /tmp/tf_eval [--seed 1] [--json OUT]

Every dance goes through the same engine path (features -> the engine's scaler inverse,
expmaps, root deltas and FK on the built-in Mixamo table -> the SMPL-X rig of the exports ->
`dancer_pos3d.npy`, resampled 20 -> 30 fps), so the real and the generated sides differ only in where the features came from:

- real: the true features of every dancer (train and test), decoded by a Transflower model whose
  flow is the identity (engine_decode_check.identity_model: `generate --noise` returns the noise);
- generated: `duolando dance --model M --music wav/<take>.wav --audio-scaler --scaler
  --motion-seed <the true dancer's first 120 rows, scaled> --seed S`, for both dancers of every
  test take (the follower `_00` and the leader `_01` of a duet are two solo dancers here);
- frozen: the seed's last pose held for the generated span (a model that stops dancing).

Clips are named `<Genre>_<CC>_<TT>_00` (the follower) and `<Genre>_<CC+50>_<TT>_00` (the leader
as a solo dancer), music `<Genre>_<CC>_<TT>.npy` as `duolando eval` matches it. The generated
frames start at song time 6 s (Transflower's first output is the frame after its 120-frame motion
window): their music features are the synth's from 6 s on. `duolando eval` reads .npy clips at 30 fps:
every clip is resampled from 20 fps by linear interpolation.

Reported (and written to --json): FID_k, FID_g, Div_k, Div_g, BAS and foot skating for
generated vs real-train, real-test vs real-train (the floor a perfect model reaches with this many
clips) and frozen vs real-train; plus per-channel std of the generated scaled features and their
frame-to-frame speed against the real test features'.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "../../.."))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "tools/reference"))

WIN = 120  # the paper config's motion window


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}\n{r.stderr}")
    return r


def pos3d_30fps(out_dir, dst):
    """`dancer_pos3d.npy` (T, 165) at 20 fps -> (T', 165) at 30 fps (linear), so that
    `duolando eval` (which reads .npy at 30 fps) sees the right speed and counts foot skating."""
    p = np.load(os.path.join(out_dir, "dancer_pos3d.npy")).astype(np.float64).reshape(-1, 165)
    t20 = np.arange(p.shape[0]) / 20.0
    t30 = np.arange(int(np.floor(t20[-1] * 30.0)) + 1) / 30.0
    q = np.stack([np.interp(t30, t20, p[:, c]) for c in range(165)], axis=1)
    np.save(dst, q.astype(np.float32))


def clip_name(take, dancer):
    genre, cc, tt = take.split("_")
    return f"{genre}_{int(cc) + (50 if dancer == '01' else 0):02d}_{tt}_00"


def identity_duo(work, bin_):
    import yaml
    import engine_decode_check as edc

    path = os.path.join(work, "identity.duo")
    if os.path.exists(path):
        return path
    _, state, opt, _ = edc.identity_model()
    with open(os.path.join(work, "identity_hparams.yaml"), "w") as f:
        yaml.safe_dump(opt, f, sort_keys=True)
    edc.save_safetensors(state, os.path.join(work, "identity.safetensors"))
    run([bin_, "convert", "--config", os.path.join(work, "identity_hparams.yaml"), "--weights",
         os.path.join(work, "identity.safetensors"), "-o", path])
    return path


def identity_decode(bin_, duo, z, out, prep):
    """Scaled features z (N, 69) through the engine's export path: the identity-flow model
    replays them as its base samples (`generate --noise`), `--scaler` decodes them."""
    import engine_decode_check as edc

    os.makedirs(out, exist_ok=True)
    n, w = z.shape[0], edc.WIN
    np.save(os.path.join(out, "noise.npy"), z.astype(np.float32)[:, :, None])
    np.save(os.path.join(out, "seed.npy"), np.zeros((w, z.shape[1]), np.float32))
    np.save(os.path.join(out, "audio.npy"), np.zeros((n + w - 1, 85), np.float32))
    run([bin_, "generate", "--model", duo, "--mode", "exact",
         "--input", f"expmap_scaled_20={out}/seed.npy", "--input", f"audio_feats_scaled_20={out}/audio.npy",
         "--noise", f"{out}/noise.npy", "--scaler", os.path.join(prep, "motion_scaler.json"), "--out", out])
    return out


def decode_true(bin_, duo, prep, split, name, out, scaler):
    """The true features of one dancer through the engine's export path."""
    x = np.load(os.path.join(prep, split, name + ".motion.npy")).astype(np.float64)
    return identity_decode(bin_, duo, (x - scaler[0]) / scaler[1], out, prep)


def frozen_decode(bin_, duo, out_dir, last_scaled, frames, prep):
    """The seed's last pose held for `frames` frames, decoded like the others (ground deltas 0)."""
    z = np.repeat(last_scaled[None, :], frames, axis=0).astype(np.float32)
    sc = json.load(open(os.path.join(prep, "motion_scaler.json")))
    mean, scale = np.array(sc["mean"]), np.array(sc["scale"])
    cols = json.load(open(os.path.join(prep, "manifest.json")))["motion_columns"]
    for c in ("Hips_dXposition", "Hips_dZposition", "Hips_dYrotation"):
        j = cols.index(c)
        z[:, j] = (0.0 - mean[j]) / scale[j]
    return identity_decode(bin_, duo, z, out_dir, prep)


def evaluate(bin_, gen, real, music, out_json):
    cmd = [bin_, "eval", "--gen", gen, "--json", out_json]
    if real:
        cmd += ["--real", real]
    if music:
        cmd += ["--music", music]
    run(cmd)
    return json.load(open(out_json))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", required=True)
    ap.add_argument("--prep", required=True)
    ap.add_argument("--synth", required=True)
    ap.add_argument("--work", default="/tmp/tf_eval")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json")
    ap.add_argument("--bin", default=os.path.join(REPO, "target/debug/duolando"))
    ap.add_argument("--window", type=int, default=WIN, help="the model's motion window (rows of the seed)")
    ap.add_argument("--max-takes", type=int, help="first N takes per split (a quick check)")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    man = json.load(open(os.path.join(a.prep, "manifest.json")))
    sc = json.load(open(os.path.join(a.prep, "motion_scaler.json")))
    scaler = (np.array(sc["mean"]), np.array(sc["scale"]))
    ident = identity_duo(a.work, a.bin)
    dirs = {k: os.path.join(a.work, k) for k in ("real_train", "real_test", "gen", "frozen", "music_full", "music_6s")}
    for d in dirs.values():
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
    stats = {"gen_std": [], "gen_speed": [], "true_std": [], "true_speed": []}
    takes = man["takes"]
    if a.max_takes:
        takes = [t for t in takes if t["split"] == "train"][: a.max_takes] + \
                [t for t in takes if t["split"] == "test"][: a.max_takes]
    for t in takes:
        take, split = t["name"], t["split"]
        m30 = np.load(os.path.join(a.synth, "music/feature", split, take + ".npy"))
        for d in ("00", "01"):
            name, clip = f"{take}_{d}", clip_name(take, d)
            np.save(os.path.join(dirs["music_full"], clip[:-3] + ".npy"), m30)
            np.save(os.path.join(dirs["music_6s"], clip[:-3] + ".npy"), m30[a.window * 3 // 2:])
            dec = decode_true(a.bin, ident, a.prep, split, name, os.path.join(a.work, "decoded", name), scaler)
            pos3d_30fps(dec, os.path.join(dirs["real_" + split], clip + ".npy"))
            if split != "test":
                continue
            x = np.load(os.path.join(a.prep, "test", name + ".motion.npy")).astype(np.float64)
            z = ((x - scaler[0]) / scaler[1]).astype(np.float32)
            out = os.path.join(a.work, "generated", name)
            os.makedirs(out, exist_ok=True)
            np.save(os.path.join(out, "seed_in.npy"), z[:a.window])
            run([a.bin, "dance", "--model", a.model, "--music", os.path.join(a.prep, "wav", take + ".wav"),
                 "--audio-scaler", os.path.join(a.prep, "audio_scaler.json"),
                 "--scaler", os.path.join(a.prep, "motion_scaler.json"),
                 "--motion-seed", os.path.join(out, "seed_in.npy"), "--seed", str(a.seed), "--out", out])
            pos3d_30fps(out, os.path.join(dirs["gen"], clip + ".npy"))
            g = np.load(os.path.join(out, "output.npy"))[:, 0].astype(np.float64)
            true = z[a.window:a.window + g.shape[0]].astype(np.float64)
            stats["gen_std"].append(g.std(0))
            stats["true_std"].append(true.std(0))
            stats["gen_speed"].append(np.abs(np.diff(g, axis=0)).mean())
            stats["true_speed"].append(np.abs(np.diff(true, axis=0)).mean())
            fb = frozen_decode(a.bin, ident, os.path.join(a.work, "frozen_dec", name), z[a.window - 1], g.shape[0], a.prep)
            pos3d_30fps(fb, os.path.join(dirs["frozen"], clip + ".npy"))
    rep = {"model": a.model, "seed": a.seed,
           "clips": {k: len(os.listdir(dirs[k])) for k in ("real_train", "real_test", "gen", "frozen")}}
    rep["generated_vs_train"] = evaluate(a.bin, dirs["gen"], dirs["real_train"], dirs["music_6s"],
                                         os.path.join(a.work, "gen.json"))
    rep["real_test_vs_train"] = evaluate(a.bin, dirs["real_test"], dirs["real_train"], dirs["music_full"],
                                         os.path.join(a.work, "real_test.json"))
    rep["frozen_vs_train"] = evaluate(a.bin, dirs["frozen"], dirs["real_train"], dirs["music_6s"],
                                      os.path.join(a.work, "frozen.json"))
    gs, ts = np.mean(stats["gen_std"], 0), np.mean(stats["true_std"], 0)
    rep["features"] = {
        "generated_std_mean_over_channels": float(gs.mean()), "true_std_mean_over_channels": float(ts.mean()),
        "generated_speed": float(np.mean(stats["gen_speed"])), "true_speed": float(np.mean(stats["true_speed"])),
    }
    keys = ("fid_k", "fid_g", "div_k", "div_g", "div_k_real", "div_g_real", "bas", "fsr_00")
    print(f"{'':22s}" + "".join(f"{k:>11s}" for k in keys))
    for side in ("generated_vs_train", "real_test_vs_train", "frozen_vs_train"):
        r = rep[side]
        print(f"{side:22s}" + "".join(f"{r[k]:11.3f}" if isinstance(r.get(k), (int, float)) else f"{'-':>11s}"
                                      for k in keys))
    print(json.dumps(rep["features"], indent=1))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rep, f, indent=1)


if __name__ == "__main__":
    main()
