#!/usr/bin/env python3
"""Goldens for `duolando eval`: the authors' own metric code run on a deterministic motion set.

Needs a checkout of lisiyao21/Duolando; its `utils/` folder (metrics.py, metrics_duet.py,
metric_footskating_dur.py, features/) is imported at run time from the path given on the
command line. Nothing of it is copied; nothing is fetched. Requirements: numpy, scipy.

    git -C <mirror-of-Duolando> archive HEAD utils | tar -x -C /tmp/duolando
    python3 tools/metrics_goldens.py /tmp/duolando            # writes tests/fixtures/metrics/goldens.json
    python3 tools/metrics_goldens.py /tmp/duolando --check    # recomputes and diffs, writes nothing
    python3 tools/metrics_goldens.py /tmp/duolando --keep /tmp/evalset   # also keeps the motion files

The motion set is not committed: it is rebuilt bit for bit from a small integer recipe by
this script and by the Rust tests (`duolando::eval::testset`, same recipe): float64 arithmetic
with only +, *, / and `sin` (glibc's, through Python's `math.sin` and Rust's `f64::sin`),
rounded once to float32. Every file's checksum (the bits of the float64 sum of its float32
values, in row-major order) goes into the JSON, and the Rust test checks it before any metric.
Layout (as the authors' eval folders): DIR/{real,gen}/<G>_<CC>_<TT>_00.npy (follower, dancer
under test), _01.npy (leader), DIR/music/<G>_<CC>_<TT>.npy ((T, 54), beat column 53).
"""
import argparse
import json
import math
import struct
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "metrics", "goldens.json")
MASK = (1 << 64) - 1

# ---- the recipe (mirrored in std-adapters/src/eval/testset.rs) ------------------------------

SEED = 41
N_REAL = 80
N_GEN = 24
PRIME = 1000003


def splitmix64(x):
    z = (x + 0x9E3779B97F4A7C15) & MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def unit(*keys):
    """A float64 in [0, 1) from integer keys (exact: 53 bits over 2^53)."""
    k = SEED
    for v in keys:
        k = (k * PRIME + v) & MASK
    return (splitmix64(k) >> 11) / 9007199254740992.0


def base_pose():
    """First frame of assets/demo_follower_start.npy in whole millimetres (stored in the JSON)."""
    a = np.load(os.path.join(HERE, "..", "assets", "demo_follower_start.npy")).reshape(-1, 55, 3)[0]
    return [int(round(float(v) * 1000.0)) for v in a.reshape(-1)]


def clip_frames(set_id, k, role):
    base = 40 + int(unit(set_id, k, 900) * 40.0)  # 40..79
    if role == 1:  # the leader is up to 4 frames shorter or longer
        base += int(unit(set_id, k, 901) * 9.0) - 4
    return base


def make_motion(pose_mm, set_id, k, role):
    """(T, 165) float32: the pose, a swaying root, and per-channel sines of a clip-wide amplitude."""
    t_len = clip_frames(set_id, k, role)
    amp = 0.01 + 0.2 * unit(set_id, k, role, 1)
    sway = 0.05 + 0.5 * unit(set_id, k, role, 2)
    tempo = 0.5 + 2.0 * unit(set_id, k, role, 3)
    gen_bias = 0.03 * set_id  # the generated set is a little more energetic
    out = np.zeros((t_len, 165), dtype=np.float32)
    chans = []
    for ch in range(165):
        f1 = tempo * (0.3 + 1.5 * unit(set_id, k, role, 10, ch))
        p1 = 6.283185307179586 * unit(set_id, k, role, 11, ch)
        a1 = (amp + gen_bias) * unit(set_id, k, role, 12, ch)
        chans.append((f1, p1, a1))
    fr = 0.2 + 0.6 * unit(set_id, k, role, 4)
    for t in range(t_len):
        time = t / 30.0
        root = [
            sway * math.sin(6.283185307179586 * fr * time),
            0.04 * sway * math.sin(12.566370614359172 * fr * time + 1.0),
            sway * 0.5 * math.sin(6.283185307179586 * fr * time + 2.0),
        ]
        for ch in range(165):
            f1, p1, a1 = chans[ch]
            v = pose_mm[ch] / 1000.0 + root[ch % 3] + a1 * math.sin(6.283185307179586 * f1 * time + p1)
            out[t, ch] = v
    return out


def make_music(set_id, k, motion_frames):
    t_len = motion_frames + int(unit(set_id, k, 950) * 11.0) - 5  # up to 5 frames shorter or longer
    period = 8 + int(unit(set_id, k, 951) * 9.0)  # 8..16 frames between beats
    offset = int(unit(set_id, k, 952) * period)
    out = np.zeros((t_len, 54), dtype=np.float32)
    for t in range(offset, t_len, period):
        out[t, 53] = 1.0
    return out


def name(set_id, k):
    return "Synth_%02d_%02d" % (set_id, k)


def checksum(a):
    """The float64 sum of the float32 values in row-major order, as its IEEE bits (an integer:
    JSON readers need not round decimal floats to the nearest double)."""
    s = 0.0
    for v in np.asarray(a, dtype=np.float32).reshape(-1).tolist():
        s += v
    return struct.unpack("<Q", struct.pack("<d", s))[0]


def build(root, pose_mm):
    sums = {}
    os.makedirs(os.path.join(root, "music"), exist_ok=True)
    for set_id, sub, n in ((0, "real", N_REAL), (1, "gen", N_GEN)):
        os.makedirs(os.path.join(root, sub), exist_ok=True)
        for k in range(n):
            nm = name(set_id, k)
            f = make_motion(pose_mm, set_id, k, 0)
            l = make_motion(pose_mm, set_id, k, 1)
            m = make_music(set_id, k, f.shape[0])
            np.save(os.path.join(root, sub, nm + "_00.npy"), f)
            np.save(os.path.join(root, sub, nm + "_01.npy"), l)
            np.save(os.path.join(root, "music", nm + ".npy"), m)
            sums[sub + "/" + nm + "_00.npy"] = checksum(f)
            sums[sub + "/" + nm + "_01.npy"] = checksum(l)
            sums["music/" + nm + ".npy"] = checksum(m)
    return sums


# ---- the authors' code ----------------------------------------------------------------------

def run_authors(repo, root):
    sys.path.insert(0, os.path.join(repo, "utils"))
    import metrics as M  # Duolando utils/metrics.py
    import metrics_duet as MD  # Duolando utils/metrics_duet.py
    import metric_footskating_dur as FS  # Duolando utils/metric_footskating_dur.py
    from features.kinetic import extract_kinetic_features
    from features.manual_new import extract_manual_features

    real, gen, music = (os.path.join(root, s) for s in ("real", "gen", "music"))
    out = {}
    # Solo features and FID_k / FID_g / Div (metrics.py __main__ order).
    M.calc_and_save_feats(real)
    M.calc_and_save_feats(gen)
    q = M.quantized_metrics(gen, real)
    out["fid_k"], out["fid_g"] = float(np.real(q["fid_k"])), float(np.real(q["fid_m"]))
    out["div_k"], out["div_g"] = float(q["div_k"]), float(q["div_m"])
    out["div_k_real"], out["div_g_real"] = float(q["div_k_gt"]), float(q["div_m_gt"])
    out["bas"] = float(M.calc_ba_score(gen, music))
    # Duet: FID_cd / Div_cd, BED.
    MD.calc_and_save_feats_duet(real)
    MD.calc_and_save_feats_duet(gen)
    qd = MD.quantized_metrics(gen, real)
    out["fid_cd"] = float(np.real(qd["fid_k"]))
    out["div_cd"], out["div_cd_real"] = float(qd["div"]), float(qd["div_gt"])
    out["bed"] = float(MD.calc_duet_be_score(gen))
    # Foot skating: the script's __main__ loop over glob(root/*.npy) (leaders included).
    dur = frames = 0
    dur00 = frames00 = 0
    for f in sorted(os.listdir(gen)):
        if not f.endswith(".npy"):
            continue
        d, n = FS.detect_footskating_dur(np.load(os.path.join(gen, f)).reshape(-1, 55, 3))
        dur, frames = dur + d, frames + n
        if f.endswith("_00.npy"):
            dur00, frames00 = dur00 + d, frames00 + n
    out["fsr"] = dur / frames * 100.0
    out["fsr_00"] = dur00 / frames00 * 100.0
    out["fs_frames"], out["fs_dur"] = frames, dur

    # Per-clip values of the first clips of each set (exact feature-level checks).
    clips = []
    for sub, set_id in (("real", 0), ("gen", 1)):
        for k in range(3):
            nm = name(set_id, k)
            f = os.path.join(root, sub, nm + "_00.npy")
            l = os.path.join(root, sub, nm + "_01.npy")
            kin = np.load(os.path.join(root, sub, "kinetic_features", nm + "_00.npy"))
            man = np.load(os.path.join(root, sub, "manual_features_new", nm + "_00.npy"))
            cd = np.load(os.path.join(root, sub, "duet_features", nm + "_00.npy"))
            jf, jl = np.load(f), np.load(l)
            beats_f, _ = M.calc_db(jf)
            beats_l, _ = M.calc_db(jl)
            mus = np.load(os.path.join(music, nm + ".npy"))
            n = min(len(jf), len(mus))
            db, length = M.calc_db(jf[:n])
            mb = M.get_mb(music, nm + ".npy", length)
            clips.append({
                "set": sub, "k": k, "name": nm,
                "kinetic": [float(v) for v in kin], "geometric": [float(v) for v in man],
                "cd": [float(v) for v in cd],
                "motion_beats": [int(v) for v in beats_f[0]],
                "leader_beats": [int(v) for v in beats_l[0]],
                "ba": float(M.BA(mb, db[0])),
                "be": float(MD.BA(beats_l, beats_f)),
                "fs": list(FS.detect_footskating_dur(jf.reshape(-1, 55, 3))),
            })
    out["clips"] = clips
    _ = (extract_kinetic_features, extract_manual_features)
    return out, M


def fid_unit_cases(M):
    """FID / Div on small feature matrices straight through normalize + calc_fid (the
    quantized_metrics path without files): one well-conditioned case, one rank-deficient."""
    cases = []
    for case, (d, nr, ng) in enumerate(((6, 40, 25), (5, 4, 3))):
        real = np.array([[unit(7000 + case, i, c) * (1.0 + c) + (c == 2) * unit(7100, i)
                          for c in range(d)] for i in range(nr)], dtype=np.float32)
        gen = np.array([[unit(7200 + case, i, c) * (1.3 + 0.5 * c) + 0.2
                         for c in range(d)] for i in range(ng)], dtype=np.float32)
        r, g = M.normalize(real, gen)
        cases.append({
            "d": d, "n_real": nr, "n_gen": ng,
            "real": [[float(v) for v in row] for row in real],
            "gen": [[float(v) for v in row] for row in gen],
            "fid": float(np.real(M.calc_fid(g, r))),
            "div_gen": float(M.calculate_avg_distance(g)),
            "div_real": float(M.calculate_avg_distance(r)),
        })
    return cases


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("duolando", help="checkout of lisiyao21/Duolando (its utils/ is imported)")
    ap.add_argument("--check", action="store_true", help="compare with the committed JSON, write nothing")
    ap.add_argument("--keep", help="build the motion set in this folder and keep it")
    a = ap.parse_args()
    pose = base_pose()
    root = a.keep or tempfile.mkdtemp(prefix="duo-metrics-")
    sums = build(root, pose)
    figures, M = run_authors(os.path.abspath(a.duolando), root)
    doc = {
        "about": "tools/metrics_goldens.py: the authors' Duolando metric code on the recipe set "
                 "(std-adapters/src/eval/testset.rs); docs/EVAL.md",
        "recipe": {"seed": SEED, "n_real": N_REAL, "n_gen": N_GEN, "base_pose_mm": pose},
        "checksums": sums,
        "figures": {k: v for k, v in figures.items() if k != "clips"},
        "clips": figures["clips"],
        "fid_cases": fid_unit_cases(M),
    }
    if a.check:
        old = json.load(open(OUT))
        worst = 0.0
        for k, v in doc["figures"].items():
            w = old["figures"][k]
            rel = abs(v - w) / max(abs(w), 1e-12)
            worst = max(worst, rel)
            print("%-12s %.10g vs committed %.10g (rel %.2e)" % (k, v, w, rel))
        print("max relative difference", worst)
        return
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(json.dumps(doc["figures"], indent=1))
    print("wrote", os.path.normpath(OUT))


if __name__ == "__main__":
    main()
