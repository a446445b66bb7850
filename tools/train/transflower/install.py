"""Installs a trained Transflower run as the bundled demo (assets/transflower_demo.*).

    /work/venv/bin/python tools/train/transflower/install.py --run RUN --prep /work/tfdata/prep \
        [--take Foxtrot_35_01] [--seconds 20] [--assets assets]

Writes, for `duolando dance --model assets/transflower_demo.duo --music assets/transflower_demo_music.ogg`
(docs/CLI.md: the files beside a model stand in for absent flags):

- `transflower_demo.duo`: `duolando convert --dtype f16` of RUN's model.safetensors + hparams.yaml;
- `transflower_demo.audio_scaler.json`, `transflower_demo.motion_scaler.json`: the prepared data's
  scalers (fitted on the training split);
- `transflower_demo.motion_seed.npy`: the first motion-window rows of a held-out dancer (`--take`'s
  follower `_00`, scaled): the couple standing in hold, where every take starts;
- `transflower_demo_music.ogg`: the first `--seconds` of that held-out take's music (the synth's beat
  grid played as audio, prepare_data.py), Ogg Vorbis (needs the `soundfile` package);
- `transflower_demo_take.txt`: where the files came from.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, HERE)
import train as T  # noqa: E402  (scalers, data loading)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="train.py output directory")
    ap.add_argument("--prep", default="/work/tfdata/prep")
    ap.add_argument("--take", default="Foxtrot_35_01", help="held-out take (test split) of the seed and the music")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--assets", default=os.path.join(ROOT, "assets"))
    ap.add_argument("--duolando", default=os.path.join(ROOT, "target", "release", "duolando"))
    a = ap.parse_args(argv)
    import soundfile as sf
    import yaml

    hp = yaml.safe_load(open(os.path.join(a.run, "hparams.yaml")))
    lm = int(str(hp["input_lengths"]).split(",")[0])
    stem = os.path.join(a.assets, "transflower_demo")
    subprocess.run([a.duolando, "convert", "--config", os.path.join(a.run, "hparams.yaml"), "--weights",
                    os.path.join(a.run, "model.safetensors"), "--dtype", "f16", "--out", stem + ".duo"], check=True)
    for kind in ("audio", "motion"):
        shutil.copyfile(os.path.join(a.prep, f"{kind}_scaler.json"), f"{stem}.{kind}_scaler.json")
    mpath = os.path.join(a.prep, "test", a.take + "_00.motion.npy")
    if not os.path.exists(mpath):
        raise SystemExit(f"{mpath}: no such held-out dancer")
    ms = T.read_scaler(os.path.join(a.prep, "motion_scaler.json"), T.MOTION_DIM)
    seed = T.scale_rows(np.load(mpath)[:lm], ms).astype(np.float32)
    np.save(stem + ".motion_seed.npy", seed)
    x, sr = sf.read(os.path.join(a.prep, "wav", a.take + ".wav"))
    music = os.path.join(a.assets, "transflower_demo_music.ogg")
    sf.write(music, x[: int(round(a.seconds * sr))], sr)
    run = json.load(open(os.path.join(a.run, "run.json"))) if os.path.exists(os.path.join(a.run, "run.json")) else {}
    with open(os.path.join(a.assets, "transflower_demo_take.txt"), "w") as f:
        args = run.get("args", {})
        opts = " ".join(f"--{k.replace('_', '-')} {args[k]}" for k in ("motion_window", "audio_window", "lr", "minutes",
                                                                        "seed", "init") if args.get(k) is not None)
        nll = run.get("best_test_nll")
        f.write(f"model: run {os.path.basename(os.path.abspath(a.run))} (train.py {opts}"
                f"{' --rel-pos-emb-inputs' if args.get('rel_pos_emb_inputs') else ''}; best held-out NLL "
                f"{nll:.1f} bits/frame at step {run.get('best_step', '?')}), f16\n" if nll is not None else
                f"model: run {os.path.basename(os.path.abspath(a.run))}, f16\n")
        f.write(f"seed: the first {lm} rows of the held-out dancer {a.take}_00 (test split), scaled\n")
        f.write(f"music: the first {a.seconds:g} s of {a.take} ({sr} Hz, Ogg Vorbis)\n")
    for p in sorted(os.listdir(a.assets)):
        if p.startswith("transflower_demo"):
            print(f"{os.path.join(a.assets, p)}: {os.path.getsize(os.path.join(a.assets, p)):,} bytes")


if __name__ == "__main__":
    main()
