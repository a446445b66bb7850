#!/usr/bin/env python3
"""Goldens for Transflower motion -> skeleton (docs/TRANSFLOWER.md "Motion to a skeleton"):
the AUTHORS' pymo inverse pipeline (guillefix/transflower-lightning, analysis/pymo) run on
small deterministic feature arrays, and the joint positions it gives.

    mkdir -p /tmp/tf && git -C /work/.mirror/guillefix+transflower-lightning/repo archive HEAD \
        analysis/pymo analysis/mixamo.bvh | tar -x -C /tmp/tf
    /work/venv/bin/python tools/make_transflower_motion_fixtures.py --authors /tmp/tf

Needs numpy, pandas, scipy, scikit-learn, transforms3d (what pymo imports). For each case the
pipeline of feature_extraction/process_motions.py (DownSampler(20) -> RootTransformer
('pos_rot_deltas') -> JointSelector(the 20 joints, include_root=True) ->
MocapParameterizer('expmap') -> [ConstantsRemover(Hips_X/Zposition)] -> Numpyfier) is FIT on a
3-frame BVH of the case's skeleton (first frame: unselected joints at zero rotation), a
StandardScaler is fit on seeded random features, and then, as inference/generate.py and
analysis/visualization/generate_video_from_expmaps.py do:
    unscaled = scaler.inverse_transform(scaled)         # scaled: float32, as the model writes
    bvh = pipeline.inverse_transform([unscaled])
    pos = MocapParameterizer('position').fit_transform(bvh)
Written per case under tests/fixtures/transflower_motion/<case>/: `scaled.npy` (N, 1, C)
float32, `scaler.json` (tools/transflower_scalers.py's format), `positions.npy` (N, J, 3)
float64 in the skeleton's units (every non-end-site joint, BVH file order), `meta.json`
(the forward pipeline's column names, joint names, skeleton file). The hand-made skeleton is
written as tests/fixtures/transflower_motion/hand.bvh.
"""
import argparse
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from transflower_scalers import plain  # noqa: E402

# feature_extraction/process_motions.py's JointSelector list (include_root=True adds Hips).
SELECTED = ['Spine', 'Spine1', 'Neck', 'Head', 'RightShoulder', 'RightArm', 'RightForeArm', 'RightHand',
            'LeftShoulder', 'LeftArm', 'LeftForeArm', 'LeftHand', 'RightUpLeg', 'RightLeg', 'RightFoot',
            'RightToeBase', 'LeftUpLeg', 'LeftLeg', 'LeftFoot', 'LeftToeBase']

# A small hand-made skeleton (metres): the 21 joints the pipeline keeps, plus an unselected
# Spine2 in the chain and an unselected finger; bones off the axes; mixed rotation orders.
HAND_JOINTS = [
    # name, parent, offset, channel order
    ("Hips", None, (0.0, 0.0, 0.0), "ZXY"),
    ("LeftUpLeg", "Hips", (0.091, -0.063, -0.012), "ZXY"),
    ("LeftLeg", "LeftUpLeg", (0.012, -0.418, 0.021), "ZXY"),
    ("LeftFoot", "LeftLeg", (-0.004, -0.409, -0.031), "XYZ"),
    ("LeftToeBase", "LeftFoot", (0.003, -0.061, 0.118), "ZXY"),
    ("RightUpLeg", "Hips", (-0.089, -0.061, -0.014), "ZXY"),
    ("RightLeg", "RightUpLeg", (-0.010, -0.421, 0.018), "ZYX"),
    ("RightFoot", "RightLeg", (0.006, -0.405, -0.027), "ZXY"),
    ("RightToeBase", "RightFoot", (-0.002, -0.058, 0.121), "ZXY"),
    ("Spine", "Hips", (0.0, 0.103, 0.008), "YZX"),
    ("Spine1", "Spine", (0.002, 0.112, -0.011), "ZXY"),
    ("Spine2", "Spine1", (-0.001, 0.094, -0.012), "ZXY"),
    ("LeftShoulder", "Spine2", (0.048, 0.107, -0.027), "ZXY"),
    ("LeftArm", "LeftShoulder", (0.108, -0.007, -0.021), "XZY"),
    ("LeftForeArm", "LeftArm", (0.271, 0.004, 0.009), "ZXY"),
    ("LeftHand", "LeftForeArm", (0.259, -0.006, 0.004), "ZXY"),
    ("LeftHandIndex1", "LeftHand", (0.088, -0.004, 0.021), "ZXY"),
    ("Neck", "Spine2", (0.001, 0.161, -0.024), "ZXY"),
    ("Head", "Neck", (0.0, 0.098, 0.019), "ZXY"),
    ("RightShoulder", "Spine2", (-0.047, 0.109, -0.025), "ZXY"),
    ("RightArm", "RightShoulder", (-0.106, -0.005, -0.023), "ZXY"),
    ("RightForeArm", "RightArm", (-0.276, -0.002, 0.006), "YXZ"),
    ("RightHand", "RightForeArm", (-0.262, 0.003, -0.005), "ZXY"),
]
END_SITES = {"LeftToeBase": (0.0, 0.0, 0.05), "RightToeBase": (0.0, 0.0, 0.05), "Head": (0.0, 0.12, 0.0),
             "LeftHandIndex1": (0.03, 0.0, 0.0), "RightHand": (-0.09, 0.0, 0.0)}


def hand_bvh_hierarchy():
    kids = {}
    for name, parent, _, _ in HAND_JOINTS:
        kids.setdefault(parent, []).append(name)
    info = {n: (o, c) for n, _, o, c in HAND_JOINTS}
    lines = ["HIERARCHY"]

    def emit(name, depth, root):
        ind = "\t" * depth
        off, order = info[name]
        lines.append(f"{ind}{'ROOT' if root else 'JOINT'} {name}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}\tOFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}")
        rot = " ".join(f"{a}rotation" for a in order)
        if root:
            lines.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition {rot}")
        else:
            lines.append(f"{ind}\tCHANNELS 3 {rot}")
        for k in kids.get(name, []):
            emit(k, depth + 1, False)
        if name in END_SITES:
            e = END_SITES[name]
            lines.extend([f"{ind}\tEnd Site", f"{ind}\t{{", f"{ind}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}", f"{ind}\t}}"])
        lines.append(f"{ind}}}")

    emit("Hips", 0, True)
    return "\n".join(lines) + "\n"


def with_motion(hierarchy, channel_count, selected_channel_mask, seed):
    """3 frames at 20 fps: root at (0.3, 0.95, -0.2) turning, selected joints bent, unselected
    joints at zero (pymo fills them with the first frame's values on the way back)."""
    rng = np.random.default_rng(seed)
    rows = []
    for f in range(3):
        r = rng.uniform(-40, 40, size=channel_count)
        r[~selected_channel_mask] = 0.0
        r[0:3] = [0.3 + 0.02 * f, 0.95, -0.2 + 0.01 * f]
        rows.append(r)
    body = "\n".join(" ".join(f"{v:.6f}" for v in r) for r in rows)
    return hierarchy + f"MOTION\nFrames: 3\nFrame Time: 0.05\n{body}\n"


def pipeline(cr):
    from sklearn.pipeline import Pipeline
    from analysis.pymo.preprocessing import (ConstantsRemover, DownSampler, JointSelector, MocapParameterizer,
                                             Numpyfier, RootTransformer)
    steps = [('dwnsampl', DownSampler(tgt_fps=20, keep_all=False)),
             ('root', RootTransformer('pos_rot_deltas')),
             ('jtsel', JointSelector(SELECTED, include_root=True)),
             ('expmap', MocapParameterizer('expmap'))]
    if cr:
        steps.append(('cnst', ConstantsRemover(only_cols=["Hips_Xposition", "Hips_Zposition"])))
    steps.append(('np', Numpyfier()))
    return Pipeline(steps)


def features(columns, n, seed):
    """Unscaled features in the pipeline's column order: expmaps of random axes with angles up
    to 3.1 rad, row 1 all-zero rotations, row 2 tiny (1e-9 rad) ones; root height ~0.95,
    per-frame deltas of a few cm and up to ~0.2 rad of heading."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, len(columns)))
    for c, name in enumerate(columns):
        if name.endswith("_alpha"):
            for t in range(n):
                axis = rng.normal(size=3)
                axis /= np.linalg.norm(axis)
                ang = 3.1 if (t == 3 and c % 9 == 0) else rng.uniform(0, 2.5)
                if t == 1:
                    ang = 0.0
                if t == 2:
                    ang = 1e-9
                x[t, c:c + 3] = axis * ang
    col = {name: i for i, name in enumerate(columns)}
    x[:, col["Hips_Yposition"]] = 0.95 + 0.05 * rng.normal(size=n)
    x[:, col["Hips_dXposition"]] = 0.03 * rng.normal(size=n)
    x[:, col["Hips_dZposition"]] = 0.03 * rng.normal(size=n)
    x[:, col["Hips_dYrotation"]] = 0.1 * rng.normal(size=n)
    for k in ("Hips_Xposition", "Hips_Zposition"):
        if k in col:  # the 69-d layout keeps them: what a model generates there is not zero
            x[:, col[k]] = 0.02 * rng.normal(size=n)
    return x


def independent(x, columns, clip, joints):
    """The same positions derived without pymo (Rodrigues, the root integrated as
    RootTransformer.inverse_transform does, FK in float64): the check that the facts in
    docs/TRANSFLOWER.md describe what pymo computes. Returns (N, J, 3)."""
    def rod(v):
        th = np.linalg.norm(v)
        if th == 0:
            return np.eye(3)
        k = v / th
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K

    def ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    col = {n: i for i, n in enumerate(columns)}
    get = lambda t, n: x[t, col[n]] if n in col else 0.0  # noqa: E731
    h, acc, out = 0.0, np.zeros(3), []
    for t in range(x.shape[0]):
        if t > 0:
            h += get(t, "Hips_dYrotation")
            acc = acc + ry(h) @ np.array([get(t, "Hips_dXposition"), 0, get(t, "Hips_dZposition")])
        own = ry(h) @ np.array([get(t, "Hips_Xposition"), 0, get(t, "Hips_Zposition")])
        G, P = {}, {}
        for j in joints:
            sk = clip.skeleton[j]
            e = np.array([get(t, j + "_alpha"), get(t, j + "_beta"), get(t, j + "_gamma")])
            if sk["parent"] is None:
                G[j], P[j] = ry(h) @ rod(e), np.array([acc[0] + own[0], get(t, "Hips_Yposition"), acc[2] + own[2]])
            else:
                q = sk["parent"]
                G[j], P[j] = G[q] @ rod(e), P[q] + G[q] @ np.array(sk["offsets"])
        out.append([P[j] for j in joints])
    return np.array(out)


def run_case(name, hierarchy, cr, n, seed, out_dir, skeleton_file):
    from sklearn.preprocessing import StandardScaler
    from analysis.pymo.parsers import BVHParser
    from analysis.pymo.preprocessing import MocapParameterizer

    tmp = os.path.join(out_dir, "_fit.bvh")
    # Count channels and mark the selected joints' ones.
    kept = set(SELECTED) | {"Hips"}
    names, mask = [], []
    for line in hierarchy.splitlines():
        t = line.split()
        if t and t[0] in ("ROOT", "JOINT"):
            names.append(t[1])
        if t and t[0] == "CHANNELS":
            mask += [names[-1] in kept] * int(t[1])
    with open(tmp, "w") as f:
        f.write(with_motion(hierarchy, len(mask), np.array(mask), seed))
    clip = BVHParser().parse(tmp)
    os.remove(tmp)

    pipe = pipeline(cr)
    fwd = pipe.fit_transform([clip])
    columns = list(pipe.named_steps['np'].org_mocap_.values.columns)
    x = features(columns, n, seed + 1)
    sc = StandardScaler().fit(x + np.random.default_rng(seed + 2).normal(size=x.shape) * 0.1)
    scaled = sc.transform(x).astype(np.float32)
    unscaled = sc.inverse_transform(scaled.astype(np.float64))
    bvh = pipe.inverse_transform([unscaled])
    pos = MocapParameterizer('position').fit_transform(bvh)[0].values
    joints = [j for j in clip.skeleton if not j.endswith("_Nub")]  # file order
    p = np.stack([np.stack([pos[f"{j}_{a}position"].values for a in "XYZ"], axis=-1) for j in joints], axis=1)

    indep = float(np.abs(independent(unscaled, columns, clip, joints) - p).max())
    d = os.path.join(out_dir, name)
    os.makedirs(d, exist_ok=True)
    np.save(os.path.join(d, "scaled.npy"), scaled[:, None, :])
    doc = plain(sc, f"{name}_scaler.pkl")
    with open(os.path.join(d, "scaler.json"), "w") as f:
        json.dump(doc, f, allow_nan=False, indent=1)
        f.write("\n")
    np.save(os.path.join(d, "positions.npy"), p)
    meta = {
        "skeleton": skeleton_file,
        "constants_removed": cr,
        "frames": n,
        "columns": columns,
        "joints": joints,
        "forward_features_of_fit_clip_shape": list(np.asarray(fwd).shape),
        "max_abs_position": float(np.abs(p).max()),
        "independent_numpy_vs_pymo_max_abs": indep,
        "made_by": "tools/make_transflower_motion_fixtures.py (the authors' pymo, analysis/pymo)",
    }
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")
    print(f"{name}: {n} frames x {len(columns)} features -> positions {p.shape}, |p| <= {meta['max_abs_position']:.3f}; "
          f"independent numpy derivation vs pymo {indep:.2e}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--authors", required=True, help="a `git archive` of transflower-lightning with analysis/pymo and analysis/mixamo.bvh")
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "fixtures", "transflower_motion"))
    a = ap.parse_args()
    sys.path.insert(0, a.authors)
    os.makedirs(a.out, exist_ok=True)
    hand = hand_bvh_hierarchy()
    with open(os.path.join(a.out, "hand.bvh"), "w") as f:
        f.write(hand + "MOTION\nFrames: 1\nFrame Time: 0.05\n" + " ".join(["0.000000"] * (6 + 3 * (len(HAND_JOINTS) - 1))) + "\n")
    with open(os.path.join(a.authors, "analysis", "mixamo.bvh")) as f:
        mixamo = f.read().split("MOTION")[0]
    run_case("hand_cr", hand, True, 12, 3901, a.out, "hand.bvh")
    run_case("hand_full", hand, False, 8, 3902, a.out, "hand.bvh")
    run_case("mixamo_cr", mixamo, True, 10, 3903, a.out, "built-in table (the authors' analysis/mixamo.bvh)")


if __name__ == "__main__":
    main()
