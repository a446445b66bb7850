#!/usr/bin/env python3
"""Convert a Transflower feature scaler (a pickled sklearn StandardScaler, as the authors'
feature_extraction/extract_transform2.py and apply_transforms.py write it: e.g.
`expmap_cr_scaled_20_scaler.pkl`, `bvh_expmap_cr_scaler.pkl`) into the plain JSON file
`duolando generate --scaler` reads (docs/TRANSFLOWER.md "Motion to a skeleton").

    /work/venv/bin/python tools/transflower_scalers.py expmap_cr_scaled_20_scaler.pkl scaler.json
    /work/venv/bin/python tools/transflower_scalers.py --self-test

The JSON holds the EFFECTIVE affine map of `inverse_transform` (x = z * scale + mean):
`mean` is the scaler's `mean_` (zeros when `with_mean` is false), `scale` its `scale_` (ones
when `with_std` is false; sklearn already stores 1 for a zero-variance column); `var` and
`n_samples_seen` are copied for information. Every value is written in full float64
precision (shortest round-trip repr). Refused: a pickle that is not a fitted StandardScaler,
non-finite values, a scale that is not > 0.

Needs numpy and scikit-learn (the pickle names sklearn classes). CI never runs this: the
self-test's output is committed as tests/fixtures/transflower_motion/scaler_selftest.json.
"""
import argparse
import json
import math
import os
import pickle
import sys

import numpy as np

FORMAT = "duolando-transflower-scaler"
VERSION = 1


def plain(scaler, source):
    for attr in ("n_features_in_",):
        if not hasattr(scaler, attr):
            raise SystemExit(f"{source}: not a fitted StandardScaler (no {attr})")
    if type(scaler).__name__ != "StandardScaler":
        raise SystemExit(f"{source}: a {type(scaler).__module__}.{type(scaler).__name__}, not a StandardScaler")
    width = int(scaler.n_features_in_)
    with_mean = bool(getattr(scaler, "with_mean", True))
    with_std = bool(getattr(scaler, "with_std", True))
    mean = np.asarray(scaler.mean_, dtype=np.float64) if with_mean and scaler.mean_ is not None else np.zeros(width)
    scale = np.asarray(scaler.scale_, dtype=np.float64) if with_std and scaler.scale_ is not None else np.ones(width)
    var = getattr(scaler, "var_", None)
    for name, a in (("mean", mean), ("scale", scale)):
        if a.shape != (width,):
            raise SystemExit(f"{source}: {name} has shape {a.shape}, expected ({width},)")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise SystemExit(f"{source}: {name}[{bad[0]}] = {a[bad[0]]} is not finite")
    bad = np.flatnonzero(scale <= 0)
    if bad.size:
        raise SystemExit(f"{source}: scale[{bad[0]}] = {scale[bad[0]]} is not > 0")
    out = {
        "format": FORMAT,
        "version": VERSION,
        "source": os.path.basename(source),
        "width": width,
        "with_mean": with_mean,
        "with_std": with_std,
        "mean": [float(v) for v in mean],
        "scale": [float(v) for v in scale],
    }
    if var is not None:
        out["var"] = [float(v) for v in np.asarray(var, dtype=np.float64)]
    n = getattr(scaler, "n_samples_seen_", None)
    if n is not None:
        out["n_samples_seen"] = int(np.max(n))
    return out


def write(doc, path):
    with open(path, "w") as f:
        json.dump(doc, f, allow_nan=False, indent=1)
        f.write("\n")


def self_test(out_dir):
    """Fit a StandardScaler on seeded random data (one constant column, as the 69-d features'
    Hips_Xposition), pickle it, convert it, and check the JSON's map reproduces sklearn's
    inverse_transform exactly in float64."""
    from sklearn.preprocessing import StandardScaler

    rng = np.random.default_rng(39)
    x = rng.normal(size=(50, 7)) * rng.uniform(0.01, 3, size=7) + rng.normal(size=7) * 5
    x[:, 2] = 0.25  # zero variance: sklearn stores scale 1
    sc = StandardScaler().fit(x)
    pkl = os.path.join(out_dir, "selftest_scaler.pkl")
    with open(pkl, "wb") as f:
        pickle.dump(sc, f)
    with open(pkl, "rb") as f:
        doc = plain(pickle.load(f), pkl)
    os.remove(pkl)
    z = sc.transform(x[:5])
    want = sc.inverse_transform(z)
    got = z * np.array(doc["scale"]) + np.array(doc["mean"])
    assert np.array_equal(got, want), "the plain map differs from sklearn's inverse_transform"
    assert doc["scale"][2] == 1.0 and doc["width"] == 7
    # Round trip through the text: every float64 survives.
    text = json.dumps(doc, allow_nan=False)
    back = json.loads(text)
    assert all(a == b for a, b in zip(back["mean"], doc["mean"]))
    path = os.path.join(out_dir, "scaler_selftest.json")
    write(doc, path)
    print(f"self-test ok: wrote {path} (width {doc['width']}; inverse map equals sklearn's bit for bit)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pickle", nargs="?", help="the authors' *_scaler.pkl")
    ap.add_argument("out", nargs="?", help="the JSON file to write")
    ap.add_argument("--self-test", action="store_true", help="fit, convert and check a scaler on random data")
    ap.add_argument("--out-dir", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures", "transflower_motion"))
    a = ap.parse_args()
    if a.self_test:
        os.makedirs(a.out_dir, exist_ok=True)
        self_test(a.out_dir)
        return
    if not a.pickle or not a.out:
        ap.error("give PICKLE OUT.json (or --self-test)")
    with open(a.pickle, "rb") as f:
        sc = pickle.load(f)
    doc = plain(sc, a.pickle)
    write(doc, a.out)
    print(f"wrote {a.out}: width {doc['width']}, scale range [{min(doc['scale']):.3g}, {max(doc['scale']):.3g}]")


if __name__ == "__main__":
    sys.exit(main())
