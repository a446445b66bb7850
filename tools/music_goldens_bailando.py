#!/usr/bin/env python3
"""Regenerates tests/fixtures/music/bailando/: golden Bailando (438-d, 7.5 fps)
music features from librosa 0.8.1.

Same pinned environment as tools/music_goldens.py (see its docstring):
    /work/venv-music/bin/python tools/music_goldens_bailando.py

The Bailando CVPR model reads the features of `_prepro_aistpp_music.py` at its
default sampling rate 15360*2/8 = 3840.0 Hz (the actor-critic configs point
`external_wav` at that script's 7.5 fps output with `external_wav_rate: 1`),
which takes `extract_acoustic_feature` with `n_octaves = 5` (7 only at 30720).
`features` below performs that function's librosa calls in the same order with
the same arguments; nothing of the authors' code is copied.

Signals are synthesised at 3840 Hz and quantised to int16 (stored as
`.pcm16.npy`, read as value/32768 on both sides); each runs in a fresh
process, as in music_goldens.py. Also written: the original loader's view of
tests/fixtures/music/stereo_44k.flac at 3840 Hz (channel mean, libsamplerate
SINC_MEDIUM as essentia's MonoLoader) and its features.
"""
import argparse
import os
import subprocess
import sys

import numpy as np
import librosa

import music_goldens as mg

SR = 15360 * 2 / 8  # 3840.0, a float as in the original script
ISR = int(SR)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "music", "bailando")


def features(audio, sr=SR):
    """(T, 438): mfcc 20, delta 20, chroma 12, onset 1, beat 1, tempogram 384."""
    melspe_db = librosa.power_to_db(librosa.feature.melspectrogram(y=audio, sr=sr), ref=np.max)
    mfcc = librosa.feature.mfcc(S=melspe_db)
    mfcc_delta = librosa.feature.delta(mfcc, width=3)
    harm, perc = librosa.effects.hpss(audio)
    chroma = librosa.feature.chroma_cqt(y=harm, sr=sr, n_octaves=7 if sr == 15360 * 2 else 5)
    onset_env = librosa.onset.onset_strength(perc, aggregate=np.median, sr=sr)
    tempogram = librosa.feature.tempogram(onset_envelope=onset_env, sr=sr)
    tempo, beats = librosa.beat.beat_track(onset_envelope=onset_env, sr=sr)
    librosa.util.peak_pick(onset_env, 3, 3, 3, 5, 0.5, 10)  # computed by the original, not used
    beat = np.zeros(len(onset_env))
    beat[beats] = 1
    feat = np.concatenate([mfcc, mfcc_delta, chroma, onset_env[None], beat[None], tempogram], axis=0).T
    assert feat.shape[1] == 438, feat.shape
    tuning = librosa.estimate_tuning(y=harm, sr=sr, bins_per_octave=36)
    # the original keeps float64 (JSON); the model reads it as float32
    return np.ascontiguousarray(feat, dtype=np.float32), float(tempo), float(tuning)


def signals():
    rng = np.random.default_rng(7)
    s = {}
    s["click_120"] = mg.clicks(8 * ISR, lambda t: 120.0, sr=ISR)
    s["clicks_chords"] = mg.clicks(10 * ISR, lambda t: 110.0, amp=0.6, sr=ISR) + mg.chord_progression(10 * ISR, sr=ISR)
    s["chords"] = mg.chord_progression(6 * ISR, sr=ISR)
    s["noise"] = 0.3 * rng.standard_normal(4 * ISR)
    s["tempo_change"] = mg.clicks(12 * ISR, lambda t: 90.0 if t < 6 else 140.0, sr=ISR)
    s["silence"] = np.zeros(2 * ISR)
    return s


def write_decoded_fixture():
    """The original loader's view of ../stereo_44k.flac at 3840 Hz and its features."""
    import samplerate
    import soundfile as sf
    q, sr = sf.read(os.path.join(OUT, "..", "stereo_44k.flac"), dtype="int16")
    mono = q.astype(np.float32).mean(axis=1) / 32768.0
    y = samplerate.resample(mono, SR / sr, "sinc_medium").astype(np.float32)
    np.save(os.path.join(OUT, "stereo_44k_mono_3840.npy"), y)
    feat, tempo, tuning = features(y)
    np.save(os.path.join(OUT, "stereo_44k.features.npy"), feat)
    return f"stereo_44k {tempo:.6f} {tuning:.6f} {feat.shape[0]} {len(y)}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--one", help="(internal) compute one signal's fixtures and print its manifest line")
    args = ap.parse_args()
    assert librosa.__version__ == "0.8.1", librosa.__version__
    os.makedirs(OUT, exist_ok=True)
    if args.one == "stereo_44k":
        print(write_decoded_fixture())
        return
    if args.one:
        q, yf = mg.quantise(signals()[args.one])
        feat, tempo, tuning = features(yf)
        np.save(os.path.join(OUT, f"{args.one}.pcm16.npy"), q)
        np.save(os.path.join(OUT, f"{args.one}.features.npy"), feat)
        print(f"{args.one} {tempo:.6f} {tuning:.6f} {feat.shape[0]} {len(q)}")
        print(args.one, feat.shape, "tempo", tempo, "tuning", tuning, "beats", np.flatnonzero(feat[:, 53]).tolist(), file=sys.stderr)
        return
    manifest = []
    for name in list(signals()) + ["stereo_44k"]:
        line = subprocess.run([sys.executable, "-W", "ignore", __file__, "--one", name], check=True, capture_output=True, text=True)
        sys.stderr.write(line.stderr)
        manifest.append(line.stdout.strip())
    with open(os.path.join(OUT, "manifest.txt"), "w") as f:
        f.write("# name tempo_bpm tuning frames samples at 3840 Hz (regenerate: tools/music_goldens_bailando.py)\n")
        f.write("\n".join(manifest) + "\n")


if __name__ == "__main__":
    main()
