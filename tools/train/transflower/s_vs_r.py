"""S mode against R mode on a trained Transflower model: the same base samples replayed
(`duolando generate --noise`) through `--mode exact` and `--mode streaming --preset P` for each
preset, on held-out takes.

    /work/venv/bin/python tools/train/transflower/s_vs_r.py --model M.duo --hparams RUN/hparams.yaml \
        [--prep /work/tfdata/prep] [--steps 200] [--presets exact,reference,realtime]

Per preset, over 6 held-out takes: the whole run's max |S - R| / max(1, max |R|) (max and
median over takes), the same for the first frame alone, and S's mean frame-to-frame change
over R's (a sampler's free run diverges from any change, so the amount of motion is the
comparable figure after the first frames).
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from freerun import BIN, HeldOut  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--hparams", required=True)
    ap.add_argument("--prep", default="/work/tfdata/prep")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--presets", default="exact,reference,realtime")
    ap.add_argument("--bin", default=BIN)
    a = ap.parse_args(argv)
    d = HeldOut(a.hparams, a.prep, a.steps)
    rng = np.random.default_rng(5)
    res = {}
    for _, m, au in d.test:
        z = d.noise(rng)
        r = d.generate(a.bin, a.model, m, au, z, ["--mode", "exact"])
        scale = max(1.0, float(np.abs(r).max()))
        rspeed = np.abs(np.diff(r, axis=0)).sum(1).mean()
        for p in a.presets.split(","):
            s = d.generate(a.bin, a.model, m, au, z, ["--mode", "streaming", "--preset", p])
            res.setdefault(p, []).append((np.abs(s - r).max() / scale, np.abs(s[0] - r[0]).max() / scale,
                                          np.abs(np.diff(s, axis=0)).sum(1).mean() / rspeed))
    for p, v in res.items():
        v = np.array(v)
        print(f"{p:10s} whole run: max {v[:, 0].max():.3g}, median {np.median(v[:, 0]):.3g}; "
              f"first frame: max {v[:, 1].max():.3g}; motion S / R {v[:, 2].mean():.3f}")


if __name__ == "__main__":
    main()
