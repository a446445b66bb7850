#!/usr/bin/env python3
"""Bailando demo data from `duolando synth` (DD100 layout, SMPL-X 55 joints, 30 fps, no audio).

For every take:
  * both dancers become solo dances: SMPL-X -> SMPL 24 (joints 0..21 kept; 22 / 23 = mean of the
    five left / right finger bases 25,28,31,34,37 / 40,43,46,49,52, the same mapping as the
    Duolando evaluation's `calc_and_save_feats` and `duolando eval`), 30 -> 60 fps by linear
    interpolation (2T frames: the last frame repeated once);
  * the take's music is rendered as audio (procedural, from takes.json: the take's own beat
    times, tempo, metre and genre: kick / snare / hat on the beat grid, bass + chord pad + a
    melody per bar, genre-dependent timbre and key), written as WAV, and its 438-d Bailando
    features are computed by `duolando features --for bailando` (7.5 rows/s: row j starts at
    j / 7.5 s = motion frame 8 j at 60 fps).
Output: OUT/<split>/<take>_<dancer>.npz with `dance` (T60, 72) float32 world positions and
`music` (R, 438) float32, plus OUT/wav/<take>.wav and OUT/index.json.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np
from scipy.io import wavfile

SR = 3840  # the rate the Bailando features are computed at: written as is (resampling to 3840 Hz
           # adds a noise floor that silences their onset envelope, the median over the mel bands)
CLICK = 1.0  # beat clicks: decaying 1.5 kHz bursts (tools/music_goldens.py `clicks`)
FINGERS_L = [25, 28, 31, 34, 37]
FINGERS_R = [40, 43, 46, 49, 52]
GENRE = {  # (root midi, scale, harmonic weights of the lead instrument, swing of the hats)
    "Waltz": (62, "major", (1.0, 0.3, 0.1), 0.0), "Tango": (57, "minor", (1.0, 0.6, 0.4, 0.3), 0.0),
    "Foxtrot": (65, "major", (1.0, 0.5, 0.2), 0.15), "Quickstep": (67, "major", (1.0, 0.2, 0.4), 0.1),
    "Rumba": (60, "minor", (1.0, 0.4), 0.0), "ChaCha": (64, "minor", (1.0, 0.7, 0.5), 0.0),
    "Samba": (69, "major", (1.0, 0.8, 0.2, 0.4), 0.0), "Jive": (58, "major", (1.0, 0.3, 0.6, 0.1), 0.2),
}
SCALES = {"major": [0, 2, 4, 5, 7, 9, 11], "minor": [0, 2, 3, 5, 7, 8, 10]}
PROG = [0, 3, 4, 0, 5, 3, 4, 4]  # scale degrees of the bar chords


def smplx_to_smpl24(p165):
    p = p165.reshape(len(p165), 55, 3)
    out = np.empty((len(p), 24, 3), np.float32)
    out[:, :22] = p[:, :22]
    out[:, 22] = p[:, FINGERS_L].mean(1)
    out[:, 23] = p[:, FINGERS_R].mean(1)
    return out.reshape(len(p), 72)


def to_60fps(d30):
    t = len(d30)
    out = np.empty((2 * t, d30.shape[1]), np.float32)
    out[0::2] = d30
    out[1:-1:2] = 0.5 * (d30[:-1] + d30[1:])
    out[-1] = d30[-1]
    return out


def fold_heading(d60, window=31):
    """Each frame's body turned about the pelvis so that it faces +z: the heading is the ground
    projection of the left-minus-right hip vector (SMPL joints 1, 2) turned a quarter, smoothed
    over `window` frames (0.5 s at 60 fps: a turn of the body, not the hips' twist within a
    step). The pelvis travels by the same steps measured in the body's frame (each frame's
    horizontal pelvis step turned by the same angle, summed from the first frame): a step forward
    is a step towards +z at any heading, so the root decoder sees travel the codes can predict;
    turning figures become straight paths."""
    p = d60.reshape(len(d60), 24, 3).astype(np.float64)
    hip = p[:, 1] - p[:, 2]
    k = np.ones(window) / window
    hx = np.convolve(np.pad(hip[:, 0], window // 2, mode="edge"), k, "valid")
    hz = np.convolve(np.pad(hip[:, 2], window // 2, mode="edge"), k, "valid")
    # facing = hip vector turned by +90 degrees about y; rotate so facing -> +z
    ang = np.arctan2(hx, hz) - np.pi / 2  # heading angle of the facing direction from +z
    c, s_ = np.cos(-ang)[:, None], np.sin(-ang)[:, None]
    rel = p - p[:, :1]
    x0, z0 = rel[..., 0].copy(), rel[..., 2].copy()
    rel[..., 0] = c * x0 + s_ * z0
    rel[..., 2] = -s_ * x0 + c * z0
    step = np.diff(p[:, 0], axis=0)
    sx, sz = step[:, 0].copy(), step[:, 2].copy()
    c1, s1 = c[:-1, 0], s_[:-1, 0]
    step[:, 0] = c1 * sx + s1 * sz
    step[:, 2] = -s1 * sx + c1 * sz
    root = np.concatenate([p[:1, 0], p[0, 0] + np.cumsum(step, axis=0)])
    return (rel + root[:, None]).reshape(len(d60), 72).astype(np.float32)


def midi_hz(m):
    return 440.0 * 2 ** ((m - 69) / 12)


def render(take, n_sec, seed):
    """Mono float audio of one take at SR."""
    rng = np.random.default_rng(seed)
    genre = take["genre"]
    root, scale, harm, swing = GENRE.get(genre, (60, "major", (1.0, 0.3), 0.0))
    root += int(rng.integers(-3, 4))
    sc = SCALES[scale]
    n = int(n_sec * SR)
    y = np.zeros(n + SR, np.float64)
    beats = np.asarray(take["beats_s"], np.float64)
    bpb = int(take["beats_per_bar"])
    period = 60.0 / float(take["bpm"])

    def add(t0, sig):
        i = int(round(t0 * SR))
        if i < 0 or i >= n:
            return
        m = min(len(sig), len(y) - i)
        y[i:i + m] += sig[:m]

    def tone(freq, dur, amp, hw=(1.0,), decay=3.0):
        tt = np.arange(int(dur * SR)) / SR
        env = np.exp(-decay * tt) * np.minimum(1, tt * 200)
        s = sum(w * np.sin(2 * np.pi * freq * (h + 1) * tt) for h, w in enumerate(hw) if freq * (h + 1) < 0.45 * SR)
        return amp * env * s

    tk = np.arange(int(0.25 * SR)) / SR
    kick = np.sin(2 * np.pi * (50 + 80 * np.exp(-25 * tk)) * tk) * np.exp(-12 * tk)
    noise = rng.normal(0, 1, int(0.2 * SR))
    snare = noise * np.exp(-25 * np.arange(len(noise)) / SR) * 0.5
    hat = np.diff(noise[:int(0.05 * SR)], prepend=0) * np.exp(-80 * np.arange(int(0.05 * SR)) / SR) * 0.3
    tb = np.arange(int(0.02 * SR)) / SR
    click = CLICK * np.sin(2 * np.pi * 1500 * tb) * np.exp(-200 * tb)
    for b, t0 in enumerate(beats):
        pos = b % bpb
        bar = b // bpb
        add(t0, kick * (1.0 if pos == 0 else 0.55))
        add(t0, click * (1.0 if pos == 0 else 0.7))
        if bpb != 3 and pos % 2 == 1:
            add(t0, snare)
        if bpb == 3 and pos > 0:
            add(t0, snare * 0.5)
        add(t0 + period * (0.5 + swing), hat)
        deg = PROG[bar % len(PROG)]
        if pos == 0:  # bass and chord pad for the bar
            bass = root - 24 + sc[deg % 7]
            add(t0, tone(midi_hz(bass), period * bpb, 0.35, (1.0, 0.5), decay=1.0))
            for k in (0, 2, 4):
                d = deg + k
                add(t0, tone(midi_hz(root - 12 + sc[d % 7] + 12 * (d // 7)), period * bpb, 0.08, (1.0, 0.2), 0.6))
        if rng.random() < 0.8:  # melody: chord tones on beats, passing notes between
            d = deg + int(rng.choice([0, 2, 4, 7]))
            add(t0, tone(midi_hz(root + sc[d % 7] + 12 * (d // 7)), period * 0.9, 0.18, harm, 4.0))
        if rng.random() < 0.35:
            d = deg + int(rng.integers(0, 7))
            add(t0 + period / 2, tone(midi_hz(root + sc[d % 7] + 12 * (d // 7)), period * 0.45, 0.12, harm, 6.0))
    y = y[:n]
    return (y / (np.abs(y).max() + 1e-9) * 0.8).astype(np.float32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--synth", required=True, help="a `duolando synth` output folder")
    ap.add_argument("--out", required=True)
    ap.add_argument("--bin", default="/work/bin/duolando")
    ap.add_argument("--fold-heading", action="store_true",
                    help="turn every frame's body to face +z (smoothed heading) and its travel with it: "
                         "codes of the same step at any heading are one code")
    args = ap.parse_args()
    meta = json.load(open(os.path.join(args.synth, "takes.json")))
    os.makedirs(os.path.join(args.out, "wav"), exist_ok=True)
    index = {"train": [], "test": []}
    for i, take in enumerate(meta["takes"]):
        name, split = take["name"], take["split"]
        os.makedirs(os.path.join(args.out, split), exist_ok=True)
        d30 = [np.load(os.path.join(args.synth, "motion", "pos3d", split, f"{name}_{k}.npy")) for k in ("00", "01")]
        t30 = len(d30[0])
        wav = os.path.join(args.out, "wav", name + ".wav")
        audio = render(take, t30 / 30.0, seed=1000 + i)
        wavfile.write(wav, SR, (audio * 32767).astype(np.int16))
        feat = os.path.join(args.out, "wav", name + ".npy")
        subprocess.run([args.bin, "features", "--for", "bailando", wav, "-o", feat], check=True,
                       stdout=subprocess.DEVNULL)
        music = np.load(feat).astype(np.float32)
        for k, d in zip(("00", "01"), d30):
            dance = to_60fps(smplx_to_smpl24(d))
            if args.fold_heading:
                dance = fold_heading(dance)
            np.savez(os.path.join(args.out, split, f"{name}_{k}.npz"), dance=dance, music=music)
            index[split].append(f"{name}_{k}")
        print(f"{split} {name}: {t30} frames at 30 fps -> {2 * t30} at 60, music {music.shape}", flush=True)
    json.dump(index, open(os.path.join(args.out, "index.json"), "w"), indent=1)


if __name__ == "__main__":
    sys.exit(main())
