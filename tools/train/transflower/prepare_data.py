#!/usr/bin/env python3
"""Transflower training data from a `duolando synth` dataset, in the feature spaces the
engine uses at inference (tools/train/transflower/README.md "## Data").

    /work/venv/bin/python tools/train/transflower/prepare_data.py \
        --synth /work/tfdata/synth --out /work/tfdata/prep [--minutes 30 --seed 7] [--jobs 2]

With --minutes/--seed and no SYNTH/takes.json, runs `duolando synth --minutes M --seed S
--out SYNTH` first. Writes:

    OUT/{train,test}/<take>_00.motion.npy   (T, 69) float32 UNSCALED motion features, 20 fps
    OUT/{train,test}/<take>_01.motion.npy   (follower _00, leader _01: two solo dancers)
    OUT/{train,test}/<take>.audio.npy       (Ta, 85) float32 UNSCALED audio features, 20 fps
    OUT/wav/<take>.wav                      the take's synthesized music (synth_audio.py), 0.25 s longer
    OUT/motion_scaler.json, OUT/audio_scaler.json   StandardScaler over the TRAIN split
    OUT/manifest.json                       takes, frame counts, options, checks
    OUT/verify_motion.json                  verify_motion.py on the first test takes

Motion: tf_motion.dancer_features (see its docstring: SMPL-X -> the engine's built-in
Mixamo table, the inverse of the engine's root code, expmaps in the authors' column order).
Audio: `duolando features --for transflower OUT/wav/<take>.wav -o OUT/<split>/<take>.audio.npy`,
the engine's own extractor (row k of both files is the frame the engine pairs at inference),
cut to the motion's rows (the wav runs 0.25 s past the take so that no kept row sees the end).
"""
import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import time
from multiprocessing import Pool

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import synth_audio  # noqa: E402
import tf_motion as tm  # noqa: E402

REPO = os.path.abspath(os.path.join(HERE, "../../.."))
DEFAULT_BIN = os.path.join(REPO, "target/debug/duolando")
AUDIO_DIM = 85
FPS = 20
TAIL_S = 0.25


def process_take(job):
    """One take: both dancers' motion features, the wav, the audio features."""
    take, a = job
    t0 = time.time()
    split, name = take["split"], take["name"]
    out_split = os.path.join(a["out"], split)
    info = {"name": name, "split": split, "genre": take["genre"], "bpm": take["bpm"],
            "beats_per_bar": take["beats_per_bar"], "frames_30fps": take["frames"], "dancers": {}}
    for d in ("00", "01"):
        rot = np.load(os.path.join(a["synth"], "motion/rotmat", split, f"{name}_{d}.npy"))
        pos = np.load(os.path.join(a["synth"], "motion/pos3d", split, f"{name}_{d}.npy"))
        f, di = tm.dancer_features(rot, pos, a["retarget"], a["root_scale"], a["unwrap"], a["twist_fix"])
        f32 = f.astype(np.float32)
        if not np.isfinite(f32).all():
            raise SystemExit(f"{name}_{d}: non-finite motion features")
        np.save(os.path.join(out_split, f"{name}_{d}.motion.npy"), f32)
        di["role"] = "follower" if d == "00" else "leader"
        info["dancers"][d] = di
    seconds = take["frames"] / 30.0
    # The music runs TAIL_S past the take's end and the audio rows are cut to the motion's:
    # the extractor's last row (its window at the very end of the file) carries the
    # resampler's edge (up to +25 dB in the top mel bands: z-scores of 70), which no kept
    # row then sees.
    y = synth_audio.render_take(take, seconds + TAIL_S, a["sr"], a["seed"])
    wav = os.path.join(a["out"], "wav", name + ".wav")
    synth_audio.write_wav(wav, y, a["sr"])
    apath = os.path.join(out_split, name + ".audio.npy")
    r = subprocess.run([a["bin"], "features", "--for", "transflower", wav, "-o", apath],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"duolando features failed on {wav}:\n{r.stderr}")
    m = re.search(r"tempo ([0-9.]+) BPM", r.stderr)
    info["engine_tempo_bpm"] = float(m.group(1)) if m else None
    af = np.load(apath)
    if af.ndim != 2 or af.shape[1] != AUDIO_DIM or af.dtype != np.float32:
        raise SystemExit(f"{apath}: unexpected {af.shape} {af.dtype}")
    info["motion_frames"] = min(di["frames"] for di in info["dancers"].values())
    info["audio_frames_extracted"] = int(af.shape[0])
    if af.shape[0] <= info["motion_frames"]:
        raise SystemExit(f"{apath}: {af.shape[0]} audio rows for {info['motion_frames']} motion rows")
    af = af[: info["motion_frames"]]
    np.save(apath, af)
    info["audio_frames"] = int(af.shape[0])
    info["seconds"] = seconds
    info["wav"] = os.path.relpath(wav, a["out"])
    info["time_s"] = round(time.time() - t0, 3)
    return info


class Moments:
    """Per-column mean / variance over all rows of many arrays (Chan et al.'s merge, f64)."""

    def __init__(self, width):
        self.n, self.mean, self.m2 = 0, np.zeros(width), np.zeros(width)

    def add(self, x):
        x = np.asarray(x, dtype=np.float64)
        nb = x.shape[0]
        if nb == 0:
            return
        mb = x.mean(0)
        m2b = ((x - mb) ** 2).sum(0)
        n = self.n + nb
        d = mb - self.mean
        self.mean = self.mean + d * nb / n
        self.m2 = self.m2 + m2b + d * d * self.n * nb / n
        self.n = n

    def scaler(self, source, floor=None):
        """The scaler file's dict; `floor` (width,) or None: a lower bound on a non-constant
        column's scale (see --audio-mel-scale-floor)."""
        var = self.m2 / self.n  # population variance, as sklearn's StandardScaler
        scale = np.sqrt(var)
        # sklearn (>= 1.0) StandardScaler: a constant column (_is_constant_feature: var within
        # float rounding of 0) gets scale 1 (_handle_zeros_in_scale, which also catches
        # scale < 10 eps). Columns of tiny but real variance keep their scale, as in sklearn.
        eps = np.finfo(np.float64).eps
        const = var <= self.n * eps * var + (self.n * self.mean * eps) ** 2
        const = const | (scale < 10 * eps)
        scale[const] = 1.0
        if floor is not None:
            self.floored = [int(i) for i in np.flatnonzero(~const & (scale < floor))]
            scale = np.where(const, scale, np.maximum(scale, floor))
        return {"format": "duolando-transflower-scaler", "version": 1, "source": source,
                "width": int(len(self.mean)), "with_mean": True, "with_std": True,
                "mean": [float(v) for v in self.mean], "scale": [float(v) for v in scale],
                "var": [float(v) for v in var], "n_samples_seen": int(self.n)}


def check_scaler_rules(s):
    """The engine's Scaler::parse refusals (scaler.rs), in Python."""
    assert s["format"] == "duolando-transflower-scaler" and s["version"] == 1
    for k in ("mean", "scale"):
        assert len(s[k]) == s["width"] and all(np.isfinite(s[k])), k
    assert min(s["scale"]) > 0 and s["width"] > 0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--synth", required=True, help="duolando synth dataset (read; written first with --minutes)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--minutes", type=float, help="run `duolando synth --minutes M --seed S --out SYNTH` when SYNTH/takes.json is missing")
    ap.add_argument("--seed", type=int, default=None, help="synth seed (with --minutes; default 7)")
    ap.add_argument("--bin", default=DEFAULT_BIN, help="the duolando binary")
    ap.add_argument("--sr", type=int, default=48000, help="wav sample rate")
    ap.add_argument("--retarget", choices=("align", "copy"), default="align",
                    help="align: rest corrections so the Mixamo bones point as the synth's; copy: local rotations as they are")
    ap.add_argument("--root-scale", choices=("legs", "none"), default="legs",
                    help="legs: pelvis position x (Mixamo leg / synth leg) so the feet reach the floor and do not slide; none: metres as they are")
    ap.add_argument("--no-unwrap", action="store_true", help="keep scipy's rotvecs (angle <= pi; jumps of 2 pi near pi)")
    ap.add_argument("--no-twist-fix", action="store_true", help="keep the synth's arm twist flips (tf_motion.fix_twist_flips)")
    ap.add_argument("--audio-mel-scale-floor", type=float, default=1.0, metavar="DB",
                    help="lower bound on a mel column's scale (dB; 0: sklearn's exactly). The synthetic wavs have "
                         "nothing above 24 kHz, so the mel band at 23-26 kHz sits at the -80 dB floor with a std of "
                         "0.03 dB: 1-2 dB of edge energy (or real music at inference) would be z = 50-700")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--limit", type=int, help="only the first N takes of each split (tests)")
    ap.add_argument("--verify-takes", type=int, default=3, help="test takes checked by verify_motion.py (0: none)")
    a = ap.parse_args()

    t_start = time.time()
    synth_cmd = None
    tj = os.path.join(a.synth, "takes.json")
    if not os.path.exists(tj):
        if a.minutes is None:
            raise SystemExit(f"{tj} is missing: give --minutes (and --seed) to run duolando synth")
        seed = 7 if a.seed is None else a.seed
        cmd = [a.bin, "synth", "--minutes", f"{a.minutes:g}", "--seed", str(seed), "--out", a.synth]
        print("running", shlex.join(cmd), flush=True)
        t0 = time.time()
        subprocess.run(cmd, check=True)
        synth_cmd = {"command": shlex.join(cmd), "time_s": round(time.time() - t0, 2)}
    meta = json.load(open(tj))
    if synth_cmd is None:
        synth_cmd = {"command": shlex.join(["duolando", "synth", "--minutes", f"{meta['minutes_requested']:g}",
                                             "--seed", str(meta["seed"]), "--out", a.synth])}
    if float(meta.get("fps", 30)) != 30.0:
        raise SystemExit(f"{tj}: fps {meta.get('fps')}, expected 30")
    takes = meta["takes"]
    if a.limit:
        takes = [t for s in ("train", "test") for t in [t for t in takes if t["split"] == s][: a.limit]]
    for sub in ("train", "test", "wav"):
        os.makedirs(os.path.join(a.out, sub), exist_ok=True)
    tm.check_table_against_rust(os.path.join(REPO, "std-adapters/src/transflower_motion/skeleton.rs"))
    opts = {"synth": a.synth, "out": a.out, "bin": a.bin, "sr": a.sr, "seed": int(meta["seed"]),
            "retarget": a.retarget, "root_scale": a.root_scale, "unwrap": not a.no_unwrap,
            "twist_fix": not a.no_twist_fix}
    jobs = [(t, opts) for t in takes]
    t0 = time.time()
    done = []
    with Pool(max(1, a.jobs)) as pool:
        for i, info in enumerate(pool.imap(process_take, jobs)):
            done.append(info)
            if (i + 1) % 10 == 0 or i + 1 == len(jobs):
                print(f"{i + 1}/{len(jobs)} takes ({time.time() - t0:.1f} s)", flush=True)
    t_takes = time.time() - t0

    # scalers over the TRAIN split, all frames (both dancers' motion; every take's audio)
    mm, am = Moments(tm.WIDTH), Moments(AUDIO_DIM)
    for info in done:
        if info["split"] != "train":
            continue
        for d in ("00", "01"):
            mm.add(np.load(os.path.join(a.out, "train", f"{info['name']}_{d}.motion.npy")))
        am.add(np.load(os.path.join(a.out, "train", info["name"] + ".audio.npy")))
    if mm.n == 0:
        raise SystemExit("no train takes: nothing to fit the scalers on")
    ms = mm.scaler(f"prepare_data.py over {a.out}/train/*.motion.npy")
    afloor = np.zeros(AUDIO_DIM)
    afloor[:80] = a.audio_mel_scale_floor
    aus = am.scaler(f"prepare_data.py over {a.out}/train/*.audio.npy"
                    + (f" (mel columns' scale >= {a.audio_mel_scale_floor:g} dB)" if a.audio_mel_scale_floor > 0 else ""), afloor)
    for name, s in (("motion_scaler.json", ms), ("audio_scaler.json", aus)):
        check_scaler_rules(s)
        with open(os.path.join(a.out, name), "w") as fh:
            json.dump(s, fh)

    # the engine reads the audio scaler: its scaled features = ours
    check = {}
    first = done[0]
    wav = os.path.join(a.out, first["wav"])
    tmp = os.path.join(a.out, ".scaled_check.npy")
    r = subprocess.run([a.bin, "features", "--for", "transflower", wav, "-o", tmp, "--scaler",
                        os.path.join(a.out, "audio_scaler.json")], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"the engine refused audio_scaler.json:\n{r.stderr}")
    z = np.load(tmp)
    os.remove(tmp)
    x = np.load(os.path.join(a.out, first["split"], first["name"] + ".audio.npy")).astype(np.float64)
    z = z[: x.shape[0]]
    want = (x - np.array(aus["mean"])) / np.array(aus["scale"])
    want[:, 83:85] = 0.0  # the engine writes the substituted PCA columns as exactly 0 when scaled
    check["engine_scaled_audio_vs_ours_max_abs"] = float(np.abs(z - want).max())
    check["engine_scaled_audio_take"] = first["name"]

    ms_mean = np.array(ms["mean"])
    manifest = {
        "format": "duolando-transflower-prepared", "version": 1,
        "fps": FPS, "motion_width": tm.WIDTH, "audio_width": AUDIO_DIM,
        "motion_columns": tm.column_names(),
        "audio_columns": "0..80 mel dB, 80 onset envelope, 81 beat, 82 downbeat (substitutes), 83..85 DDC PCA (0: substitute); docs/TRANSFLOWER.md 'Audio features'",
        "time_base": "motion row k at k/20 s from the take's start; audio row k is the engine's row k of the take's wav (mel/envelope window centred at (k+1)/20 s, beat columns at k/20 s), as `duolando dance` pairs them; the wav runs %.2f s past the take and the audio rows are cut to the motion's" % TAIL_S,
        "synth": {"dir": os.path.abspath(a.synth), "seed": int(meta["seed"]), "minutes_requested": meta["minutes_requested"],
                  **synth_cmd},
        "prepare": {"command": shlex.join([sys.executable] + sys.argv), "retarget": a.retarget,
                    "root_scale": a.root_scale, "unwrap_expmaps": not a.no_unwrap,
                    "twist_fix": not a.no_twist_fix, "wav_sample_rate": a.sr, "wav_tail_s": TAIL_S,
                    "audio_mel_scale_floor_db": a.audio_mel_scale_floor, "jobs": a.jobs,
                    "limit": a.limit},
        "splits": {s: [i["name"] for i in done if i["split"] == s] for s in ("train", "test")},
        "frames": {s: {"motion_rows_per_dancer": int(sum(i["motion_frames"] for i in done if i["split"] == s)),
                       "motion_rows_all_dancers": int(sum(d["frames"] for i in done if i["split"] == s for d in i["dancers"].values())),
                       "audio_rows": int(sum(i["audio_frames"] for i in done if i["split"] == s)),
                       "takes": sum(1 for i in done if i["split"] == s)} for s in ("train", "test")},
        "scalers": {"motion": {"file": "motion_scaler.json", "n_samples_seen": ms["n_samples_seen"],
                               "hips_height_mean_m": float(ms_mean[tm.ROOT_Y]),
                               "unit_scale_columns": [tm.column_names()[i] for i, v in enumerate(ms["var"]) if ms["scale"][i] == 1.0 and v < 1e-12],
                               "small_scale_columns": {tm.column_names()[i]: v for i, v in enumerate(ms["scale"]) if v < 1e-3}},
                    "audio": {"file": "audio_scaler.json", "n_samples_seen": aus["n_samples_seen"],
                              "mel_scale_floor_db": a.audio_mel_scale_floor,
                              "floored_columns": {i: float(np.sqrt(aus["var"][i])) for i in am.floored},
                              "unit_scale_columns": [i for i, v in enumerate(aus["var"]) if aus["scale"][i] == 1.0 and v < 1e-12]}},
        "checks": check,
        "takes": done,
        "time_s": {"takes": round(t_takes, 1)},
    }
    with open(os.path.join(a.out, "manifest.json"), "w") as fh:
        json.dump(manifest, fh, indent=1)

    if a.verify_takes > 0 and manifest["splits"]["test"]:
        r = subprocess.run([sys.executable, os.path.join(HERE, "verify_motion.py"), "--synth", a.synth,
                            "--prep", a.out, "--takes", str(a.verify_takes)], capture_output=True, text=True)
        print(r.stdout, r.stderr, sep="")
        if r.returncode != 0:
            raise SystemExit("verify_motion.py failed")
    manifest["time_s"]["total"] = round(time.time() - t_start, 1)
    with open(os.path.join(a.out, "manifest.json"), "w") as fh:
        json.dump(manifest, fh, indent=1)
    size = sum(os.path.getsize(os.path.join(dp, f)) for dp, _, fs in os.walk(a.out) for f in fs)
    print(f"{len(done)} takes -> {a.out}: train {manifest['frames']['train']}, test {manifest['frames']['test']}; "
          f"{size / 2**20:.1f} MiB; {manifest['time_s']['total']} s")
    print("engine-scaled audio vs ours: max abs", check["engine_scaled_audio_vs_ours_max_abs"])


if __name__ == "__main__":
    main()
