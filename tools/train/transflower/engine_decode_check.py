#!/usr/bin/env python3
"""The ENGINE's own inverse on prepared motion features: a Transflower model whose flow is the
identity, so that `duolando generate --noise Z.npy --scaler motion_scaler.json` outputs the
replayed noise Z (our scaled features) and decodes it onto the built-in Mixamo table with the
engine's code (std-adapters/src/transflower_motion: scaler, layout, expmaps, root, FK).

    /work/venv/bin/python tools/train/transflower/engine_decode_check.py \
        --prep /work/tfdata/prep --synth /work/tfdata/synth [--takes 2] [--work /tmp/tf_engine_check]

The model: the authors' TransflowerModel (tools/reference/transflower, tiny.REAL's sizes with
69/85 dims, windows 4/4, output_lengths 1) with every flow step made the identity: BatchNorm
beta 0, gamma 1, running_mean 0, sqrt(running_var) + 1e-5 = 1; InvertibleConv1x1 p = I, l = u = 0,
log_s = 0, sign_s = 1; the coupling network's last linear layer (decoder) 0, so its shift is 0
and its scale sigmoid(offset) + (1 - sigmoid(offset)) = 1. The authors' generation
(reference.generate, replaying the noise) is checked to return the noise first. Then for each
dancer: Z = (features - mean) / scale (float32) as noise (N, 69, 1), zeros as motion seed and
audio, `duolando generate --mode exact --noise --scaler`; compared: output_unscaled.npy with the
features, positions.npy with tf_motion.decode (numpy) and, through verify_motion.check_dancer's
conventions, with the synth's positions. Writes PREP/engine_decode_check.json (and prints it).
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.abspath(os.path.join(HERE, "../../.."))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(REPO, "tools/reference"))
import tf_motion as tm  # noqa: E402
import verify_motion as vm  # noqa: E402

WIN = 4


def save_safetensors(state, path):
    """The safetensors format (8-byte header length, JSON header, raw little-endian data)."""
    kinds = {"torch.float32": "F32", "torch.float64": "F64", "torch.int64": "I64"}
    header, blobs, off = {}, [], 0
    for k, v in state.items():
        a = v.detach().cpu().contiguous().numpy()
        b = a.astype(a.dtype.newbyteorder("<")).tobytes()
        header[k] = {"dtype": kinds[str(v.dtype)], "shape": list(a.shape), "data_offsets": [off, off + len(b)]}
        blobs.append(b)
        off += len(b)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * (-len(h) % 8)
    with open(path, "wb") as f:
        f.write(len(h).to_bytes(8, "little"))
        f.write(h)
        for b in blobs:
            f.write(b)


def identity_model():
    import torch
    from transflower import env, reference, tiny
    hp = dict(tiny.REAL, input_lengths=f"{WIN},{WIN}", output_time_offsets=WIN, output_lengths=1)
    torch.set_num_threads(1)
    model = reference.build(hp, 5)
    state = model.state_dict()
    with torch.no_grad():
        for name, t in state.items():
            if "net_output_glow" not in name:
                continue
            leaf = name.rsplit(".", 1)[-1]
            if leaf == "beta":
                t.zero_()
            elif leaf == "gamma":
                t.fill_(1.0)
            elif leaf == "running_mean":
                t.zero_()
            elif leaf == "running_var":
                t.fill_((1.0 - 1e-5) ** 2)
            elif leaf == "p":
                t.copy_(torch.eye(t.shape[0]))
            elif leaf in ("l", "u", "log_s"):
                t.zero_()
            elif leaf == "sign_s":
                t.fill_(1.0)
            elif ".nn.transformer.decoder." in name:
                t.zero_()
    state = {k: v.detach().clone().contiguous() for k, v in state.items()}
    model = reference.build_from_state(hp, state)
    # the authors' generation returns the replayed noise
    rng = np.random.default_rng(0)
    z = rng.standard_normal((6, 69, 1)).astype(np.float32)
    inputs = {"expmap_scaled_20": np.zeros((WIN, 69), np.float32),
              "audio_feats_scaled_20": np.zeros((WIN + 5, 85), np.float32)}
    res = reference.generate(model, inputs, seed=0, replay={"noise": z})
    err = float(np.abs(res["output"][:, 0] - z[:, :, 0]).max())
    return hp, state, {k: v for k, v in vars(env.make_opt(hp)).items()}, err


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--prep", required=True)
    ap.add_argument("--synth", required=True)
    ap.add_argument("--takes", type=int, default=2, help="first N test takes, both dancers")
    ap.add_argument("--work", default="/tmp/tf_engine_check", help="model and generate outputs (~5 MB per dancer)")
    ap.add_argument("--bin", default=os.path.join(REPO, "target/debug/duolando"))
    a = ap.parse_args()
    import yaml
    os.makedirs(a.work, exist_ok=True)
    hp, state, opt, ref_err = identity_model()
    with open(os.path.join(a.work, "hparams.yaml"), "w") as f:
        yaml.safe_dump(opt, f, sort_keys=True)
    save_safetensors(state, os.path.join(a.work, "model.safetensors"))
    duo = os.path.join(a.work, "identity.duo")
    subprocess.run([a.bin, "convert", "--config", os.path.join(a.work, "hparams.yaml"), "--weights",
                    os.path.join(a.work, "model.safetensors"), "-o", duo], check=True, capture_output=True)
    man = json.load(open(os.path.join(a.prep, "manifest.json")))
    sc = json.load(open(os.path.join(a.prep, "motion_scaler.json")))
    mean, scale = np.array(sc["mean"]), np.array(sc["scale"])
    rep = {"authors_generate_identity_flow_output_vs_noise_max_abs": ref_err, "dancers": {}}
    for t in [t for t in man["takes"] if t["split"] == "test"][: a.takes]:
        for d in ("00", "01"):
            name = f"{t['name']}_{d}"
            x = np.load(os.path.join(a.prep, "test", name + ".motion.npy")).astype(np.float64)
            n = x.shape[0]
            z = ((x - mean) / scale).astype(np.float32)
            dd = os.path.join(a.work, name)
            os.makedirs(dd, exist_ok=True)
            np.save(os.path.join(dd, "noise.npy"), z[:, :, None])
            np.save(os.path.join(dd, "seed.npy"), np.zeros((WIN, 69), np.float32))
            np.save(os.path.join(dd, "audio.npy"), np.zeros((n + WIN - 1, 85), np.float32))
            r = subprocess.run([a.bin, "generate", "--model", duo, "--mode", "exact",
                                "--input", f"expmap_scaled_20={dd}/seed.npy",
                                "--input", f"audio_feats_scaled_20={dd}/audio.npy",
                                "--noise", f"{dd}/noise.npy", "--scaler", os.path.join(a.prep, "motion_scaler.json"),
                                "--out", dd], capture_output=True, text=True)
            if r.returncode != 0:
                raise SystemExit(f"duolando generate failed:\n{r.stderr}")
            out = np.load(os.path.join(dd, "output.npy"))[:, 0]
            unscaled = np.load(os.path.join(dd, "output_unscaled.npy"))[:, 0].astype(np.float64)
            pos = np.load(os.path.join(dd, "positions.npy")).astype(np.float64)
            names = json.load(open(os.path.join(dd, "motion.json")))
            P, _ = tm.decode(unscaled)
            # the synth comparison on the engine's positions, as verify_motion does with ours
            rot = np.load(os.path.join(a.synth, "motion/rotmat/test", name + ".npy"))
            p3 = np.load(os.path.join(a.synth, "motion/pos3d/test", name + ".npy"))
            k = t["dancers"][d]["root_scale_k"]
            S = vm.synth_at_20(p3, n)
            R0 = rot[0, 3:12].reshape(3, 3).astype(np.float64)
            h0 = np.arctan2(R0[0, 2], R0[2, 2])
            T = np.einsum("ij,tkj->tki", tm.about_y(-h0), S - S[0, 0] * np.array([1.0, 0.0, 1.0])) * k
            T = T[:, [tm.MIXAMO_BODY.index(m) for m in tm.MIX_NAMES]]
            e = np.linalg.norm(pos - T, axis=-1)
            rxz = np.linalg.norm(pos[:, 0, [0, 2]] - T[:, 0, [0, 2]], axis=-1)
            rep["dancers"][name] = {
                "frames": int(n), "engine_output_vs_noise_max_abs": float(np.abs(out - z).max()),
                "engine_unscaled_vs_features_max_abs": float(np.abs(unscaled - x).max()),
                "engine_positions_vs_numpy_decode_of_its_unscaled_max_m": float(np.abs(pos - P).max()),
                "engine_positions_vs_numpy_decode_of_our_features_max_m": float(np.abs(pos - tm.decode(x)[0]).max()),
                "engine_vs_synth_root_xz_m": {"max": float(rxz.max()), "mean": float(rxz.mean())},
                "engine_vs_synth_joints_m": {"max": float(e.max()), "mean": float(e.mean())},
                "joint_names_ok": names["joints"] == tm.MIX_NAMES,
            }
    for path in (os.path.join(a.work, "engine_decode_check.json"), os.path.join(a.prep, "engine_decode_check.json")):
        with open(path, "w") as f:
            json.dump(rep, f, indent=1)
    print(json.dumps(rep, indent=1))


if __name__ == "__main__":
    main()
