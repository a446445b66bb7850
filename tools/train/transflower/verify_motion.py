"""Checks prepared Transflower motion features against the synth data they came from.

    /work/venv/bin/python tools/train/transflower/verify_motion.py --synth SYNTH --prep PREP \
        [--takes N] [--split test] [--json OUT.json]

For each checked dancer: the features are decoded by tf_motion.decode (a numpy copy of the
engine's transflower_motion::decode, itself checked here against the authors' pymo goldens in
tests/fixtures/transflower_motion) on the engine's built-in Mixamo table, and compared with the
synth's pos3d at the same times (20-fps frame 2m = 30-fps frame 3m exactly; odd frames against
the mean of the two 30-fps frames around them). The decode starts at the origin facing +z, so
the synth positions are first moved to that start (minus the pelvis' ground position at frame 0,
turned by minus its heading) and scaled by the dancer's root scale k (manifest.json; 1 when
prepared with --root-scale none). Reported (metres, radians):

- root: ground (xz) distance of the decoded Hips to the synth pelvis, height difference, heading
  difference; the same ground distance against the UNSCALED synth trajectory (what k changes);
- joints: distance of each decoded Mixamo body joint to its SMPL-X joint (MIXAMO_BODY map),
  max / mean over frames, per joint and overall (the rest skeletons differ: bone lengths,
  hip width, spine and foot geometry);
- feet: planted frames = synth ankle moving < 0.5 mm between 20-fps frames; the decoded
  ankle's (Mixamo LeftFoot/RightFoot) motion over those frames (foot sliding), and the lowest
  decoded toe joint (ToeBase) height against the synth's lowest ball-of-foot joint (x k);
- bones: the angle between each decoded Mixamo bone that the rest corrections align and the
  synth bone it follows (0 up to rounding with --retarget align; the rest-pose angle between
  the rigs' bones with --retarget copy);
- round trip: features -> decode -> the forward again (tf_motion.features_from_world) ->
  max difference to the features (expmaps compared as rotations).
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tf_motion as tm  # noqa: E402

FIXTURES = os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../../tests/fixtures/transflower_motion")


def check_decoder_against_pymo():
    """tf_motion.decode vs the authors' pymo positions of the mixamo_cr golden (built-in
    table, 67-d), max distance in metres (None when the fixture is absent)."""
    d = os.path.join(FIXTURES, "mixamo_cr")
    if not os.path.isdir(d):
        return None
    meta = json.load(open(os.path.join(d, "meta.json")))
    s = json.load(open(os.path.join(d, "scaler.json")))
    if meta["columns"] != [c for c in tm.column_names() if c not in ("Hips_Xposition", "Hips_Zposition")]:
        raise SystemExit("mixamo_cr golden: column names differ from tf_motion's layout")
    z = np.load(os.path.join(d, "scaled.npy"))[:, 0].astype(np.float64)
    x = z * np.array(s["scale"]) + np.array(s["mean"])
    P, _ = tm.decode(x, root_cols=(None, 63, None, 64, 65, 66))
    pos = np.load(os.path.join(d, "positions.npy"))
    idx = [meta["joints"].index(n) for n in tm.MIX_NAMES]
    return float(np.abs(P - pos[:, idx]).max())


def synth_at_20(pos3d, n):
    """(T, 165) at 30 fps -> (n, 22, 3) at t = k/20 (linear between frames)."""
    T = pos3d.shape[0]
    u = np.arange(n) * 1.5
    i0 = np.minimum(np.floor(u).astype(int), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = (u - i0)[:, None, None]
    p = pos3d.reshape(T, 55, 3)[:, :22].astype(np.float64)
    return p[i0] * (1 - a) + p[i1] * a


def rotation_distance(a, b):
    """Angle between rotations given as expmaps (..., 3)."""
    Ra, Rb = tm.rodrigues(a), tm.rodrigues(b)
    c = (np.trace(np.swapaxes(Ra, -1, -2) @ Rb, axis1=-2, axis2=-1) - 1) / 2
    return np.arccos(np.clip(c, -1, 1))


def check_dancer(features, pos3d, rotmat, k):
    F = features.astype(np.float64)
    n = F.shape[0]
    P, G = tm.decode(F)
    S = synth_at_20(pos3d, n)
    # The synth's start: pelvis ground position and heading at frame 0 (pelvis +z axis).
    R0 = rotmat[0, 3:12].reshape(3, 3).astype(np.float64)
    h0 = np.arctan2(R0[0, 2], R0[2, 2])
    M = tm.about_y(-h0)
    base = S[0, 0] * np.array([1.0, 0.0, 1.0])
    raw = np.einsum("ij,tkj->tki", M, S - base)  # moved to the start, metres
    tgt = raw * k
    mix_of = [tm.MIXAMO_BODY.index(nm) for nm in tm.MIX_NAMES]  # Mixamo joint -> SMPL-X joint
    T = tgt[:, mix_of]
    exact = np.arange(0, n, 2)
    # root
    rxz = np.linalg.norm(P[:, 0, [0, 2]] - T[:, 0, [0, 2]], axis=-1)
    rxz_raw = np.linalg.norm(P[:, 0, [0, 2]] - raw[:, 0, [0, 2]], axis=-1)
    ry = np.abs(P[:, 0, 1] - T[:, 0, 1])
    # heading of the synth pelvis at 20 fps (from the resampled rotations) vs decoded Hips
    _, R = tm.resample_30_to_20(rotmat)
    hs = np.arctan2(R[:, 0, 0, 2], R[:, 0, 2, 2]) - h0
    hd = np.arctan2(G[:, 0, 0, 2], G[:, 0, 2, 2])
    dh = np.abs(tm.wrap(hd - hs))
    # joints
    err = np.linalg.norm(P - T, axis=-1)  # (n, 22)
    per_joint = {nm: {"max": float(err[:, j].max()), "mean": float(err[:, j].mean())}
                 for j, nm in enumerate(tm.MIX_NAMES)}
    # bone directions: each Mixamo bone the rest corrections align (tf_motion._ALIGN) against
    # the synth bone it follows (0 up to rounding with --retarget align)
    bones, bones_exact = {}, {}
    for m, (child, (sa, sb)) in tm._ALIGN.items():
        u = P[:, tm.MIX_NAMES.index(child)] - P[:, tm.MIX_NAMES.index(m)]
        w = raw[:, sb] - raw[:, sa]
        c = (u * w).sum(-1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(w, axis=-1)
        ang = np.degrees(np.arccos(np.clip(c, -1, 1)))
        bones[m] = float(ang.max())
        bones_exact[m] = float(ang[exact].max())
    # feet
    feet = {}
    for side, sj, mj, toe in (("left", 7, "LeftFoot", "LeftToeBase"), ("right", 8, "RightFoot", "RightToeBase")):
        sv = np.linalg.norm(np.diff(S[:, sj], axis=0), axis=-1)
        planted = sv < 5e-4
        mv = np.linalg.norm(np.diff(P[:, tm.MIX_NAMES.index(mj)], axis=0), axis=-1)
        feet[side] = {"planted_frames": int(planted.sum()),
                      "decoded_ankle_slide_per_frame_mean": float(mv[planted].mean()) if planted.any() else None,
                      "decoded_ankle_slide_per_frame_max": float(mv[planted].max()) if planted.any() else None,
                      "decoded_toe_min_height": float(P[:, tm.MIX_NAMES.index(toe), 1].min()),
                      "synth_foot_min_height_x_k": float(S[:, sj + 3, 1].min() * k)}
    # round trip through the forward
    F2, _ = tm.features_from_world(G, P[:, 0])
    rot_cols = 3 * len(tm.KEPT)
    rt_rot = rotation_distance(F[:, :rot_cols].reshape(n, -1, 3), F2[:, :rot_cols].reshape(n, -1, 3)).max()
    rt_root = np.abs(F[:, rot_cols:] - F2[:, rot_cols:]).max()
    return {
        "frames": n, "root_scale_k": k,
        "root_xz_m": {"max": float(rxz.max()), "mean": float(rxz.mean())},
        "root_xz_vs_unscaled_trajectory_m": {"max": float(rxz_raw.max()), "mean": float(rxz_raw.mean())},
        "root_height_m": {"max": float(ry.max()), "mean": float(ry.mean())},
        "heading_rad": {"max": float(dh.max()), "mean": float(dh.mean())},
        "joints_m": {"max": float(err.max()), "mean": float(err.mean()),
                     "max_at_exact_30fps_frames": float(err[exact].max()),
                     "mean_at_exact_30fps_frames": float(err[exact].mean())},
        "per_joint_m": per_joint,
        "bone_direction_max_deg": bones,
        "bone_direction_max_deg_at_exact_30fps_frames": bones_exact,
        "feet": feet,
        "round_trip": {"rotation_rad": float(rt_rot), "root_columns": float(rt_root)},
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--synth", required=True, help="the duolando synth dataset")
    ap.add_argument("--prep", required=True, help="prepare_data.py's output")
    ap.add_argument("--split", default="test")
    ap.add_argument("--takes", type=int, default=3, help="takes to check (both dancers each)")
    ap.add_argument("--json", help="write the report here (default PREP/verify_motion.json)")
    a = ap.parse_args()
    man = json.load(open(os.path.join(a.prep, "manifest.json")))
    takes = [t for t in man["takes"] if t["split"] == a.split][: a.takes]
    rep = {"decoder_vs_authors_pymo_golden_m": check_decoder_against_pymo(), "dancers": {}}
    for t in takes:
        for d in ("00", "01"):
            name = f"{t['name']}_{d}"
            f = np.load(os.path.join(a.prep, a.split, name + ".motion.npy"))
            pos = np.load(os.path.join(a.synth, "motion/pos3d", a.split, name + ".npy"))
            rot = np.load(os.path.join(a.synth, "motion/rotmat", a.split, name + ".npy"))
            rep["dancers"][name] = check_dancer(f, pos, rot, t["dancers"][d]["root_scale_k"])
    ds = list(rep["dancers"].values())
    if ds:
        agg = lambda key, sub: (max(x[key]["max"] for x in ds), float(np.mean([x[key][sub] for x in ds])))  # noqa: E731
        rep["summary"] = {
            "dancers": len(ds),
            "root_xz_m_max_meanofmeans": agg("root_xz_m", "mean"),
            "root_height_m_max_meanofmeans": agg("root_height_m", "mean"),
            "heading_rad_max_meanofmeans": agg("heading_rad", "mean"),
            "joints_m_max_meanofmeans": agg("joints_m", "mean"),
            "bone_direction_max_deg": max(max(x["bone_direction_max_deg"].values()) for x in ds),
            "bone_direction_max_deg_at_exact_30fps_frames": max(max(x["bone_direction_max_deg_at_exact_30fps_frames"].values()) for x in ds),
            "round_trip_rotation_rad_max": max(x["round_trip"]["rotation_rad"] for x in ds),
            "round_trip_root_columns_max": max(x["round_trip"]["root_columns"] for x in ds),
            "ankle_slide_per_frame_mean": float(np.mean([x["feet"][s]["decoded_ankle_slide_per_frame_mean"]
                                                         for x in ds for s in ("left", "right")
                                                         if x["feet"][s]["decoded_ankle_slide_per_frame_mean"] is not None])),
            "toe_min_height_m": min(x["feet"][s]["decoded_toe_min_height"] for x in ds for s in ("left", "right")),
        }
    out = a.json or os.path.join(a.prep, "verify_motion.json")
    with open(out, "w") as fh:
        json.dump(rep, fh, indent=1)
    print(json.dumps({"decoder_vs_authors_pymo_golden_m": rep["decoder_vs_authors_pymo_golden_m"],
                      "summary": rep.get("summary")}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
