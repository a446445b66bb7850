"""How much of a trained model's motion is its sampling noise: free runs from held-out seeds
with the base samples scaled by each factor (1 = the authors' sampling; 0 = the flow's image of
zero noise), through `duolando generate --noise`.

    /work/venv/bin/python tools/train/transflower/noise_check.py --model M.duo --hparams RUN/hparams.yaml \
        [--prep /work/tfdata/prep] [--scales 1,0.5,0] [--steps 160]

Per scale, means over 6 held-out dancers (scaled features, the channels whose training std is
above 0.1): `jitter` = mean frame-to-frame change (sum over channels) against the real motion's
(`real`), `dist20` = mean distance to the true frames over the first 20, `std` = per-channel
spread against the real one's. Not the authors' sampling below scale 1: a diagnostic only.
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import train as T  # noqa: E402
from freerun import BIN, HeldOut  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--hparams", required=True, help="the run's hparams.yaml (windows, modalities)")
    ap.add_argument("--prep", default="/work/tfdata/prep")
    ap.add_argument("--scales", default="1,0.5,0")
    ap.add_argument("--steps", type=int, default=160)
    ap.add_argument("--bin", default=BIN)
    a = ap.parse_args(argv)
    d = HeldOut(a.hparams, a.prep, a.steps)
    train, _ = T.load_split(a.prep, "train", d.ms, d.asc, 2)
    smooth = np.where(np.concatenate([m for _, m, _ in train]).std(0) > 0.1)[0]
    rng = np.random.default_rng(0)
    for scale in (float(s) for s in a.scales.split(",")):
        jit, real, dist, spread, tspread = [], [], [], [], []
        for _, m, au in d.test:
            o = d.generate(a.bin, a.model, m, au, d.noise(rng) * scale)[:, smooth]
            t = m[d.lm:d.lm + a.steps][:, smooth]
            jit.append(np.abs(np.diff(o, axis=0)).sum(1).mean())
            real.append(np.abs(np.diff(t, axis=0)).sum(1).mean())
            dist.append(np.abs(o[:20] - t[:20]).sum(1).mean())
            spread.append(o.std(0).mean())
            tspread.append(t.std(0).mean())
        print(f"scale {scale:g}: jitter {np.mean(jit):.2f} (real {np.mean(real):.2f}, {np.mean(jit) / np.mean(real):.2f}x), "
              f"dist20 {np.mean(dist):.2f}, std {np.mean(spread):.3f} (real {np.mean(tspread):.3f})", flush=True)


if __name__ == "__main__":
    main()
