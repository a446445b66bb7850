#!/usr/bin/env python3
"""Regenerates tests/fixtures/music/: golden Duolando music features from librosa 0.8.1.

Run in the pinned environment (its own venv, not the project one):
    python3 -m venv /work/venv-music
    /work/venv-music/bin/pip install "librosa==0.8.1" "numpy<1.24" "scipy==1.12.0" soundfile resampy samplerate
    /work/venv-music/bin/python tools/music_goldens.py            # fixtures
    /work/venv-music/bin/python tools/music_goldens.py --speed    # librosa time for 180 s

Every synthetic signal is quantised to 16-bit so that the Rust tests read
exactly the samples librosa saw (stored as int16 .npy, value/32768 as f32).
The feature code follows the original extractor.py call for call.
"""
import argparse
import os
import sys
import time

import numpy as np
import librosa

SR = 15360
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures", "music")


def features(audio, sr=SR):
    """The 54-d feature exactly as the original _prepare_music_data.signal_to_feature computes it."""
    melspe_db = librosa.power_to_db(librosa.feature.melspectrogram(y=audio, sr=sr), ref=np.max)
    mfcc = librosa.feature.mfcc(S=melspe_db)
    mfcc_delta = librosa.feature.delta(mfcc, width=3)
    harm, perc = librosa.effects.hpss(audio)
    chroma = librosa.feature.chroma_cqt(y=harm, sr=sr, n_octaves=7)
    onset_env = librosa.onset.onset_strength(y=perc, aggregate=np.median, sr=sr)
    tempo, beats = librosa.beat.beat_track(onset_envelope=onset_env, sr=sr)
    beat = np.zeros(len(onset_env))
    beat[beats] = 1
    feat = np.concatenate([mfcc, mfcc_delta, chroma, onset_env[None], beat[None]], axis=0).T
    tuning = librosa.estimate_tuning(y=harm, sr=sr, bins_per_octave=36)
    return np.ascontiguousarray(feat, dtype=np.float32), float(tempo), float(tuning)


def clicks(n, bpm_at, amp=0.8, sr=SR):
    """Decaying 1.5 kHz bursts (20 ms) at beat times; bpm_at(t) gives the local tempo."""
    y = np.zeros(n)
    t = 0.25
    burst = np.arange(int(0.02 * sr)) / sr
    shape = np.sin(2 * np.pi * 1500 * burst) * np.exp(-burst * 200)
    while t < n / sr:
        i = int(t * sr)
        m = min(len(shape), n - i)
        y[i:i + m] += amp * shape[:m]
        t += 60.0 / bpm_at(t)
    return y


def tone(n, freqs, amp=0.15, sr=SR):
    t = np.arange(n) / sr
    return sum(amp * np.sin(2 * np.pi * f * t) for f in freqs)


def chord_progression(n, seconds_per_chord=1.5, sr=SR):
    chords = [[261.63, 329.63, 392.00], [196.00, 246.94, 293.66], [220.00, 261.63, 329.63], [174.61, 220.00, 261.63]]
    y = np.zeros(n)
    step = int(seconds_per_chord * sr)
    fade = np.minimum(1, np.minimum(np.arange(step), np.arange(step)[::-1]) / (0.02 * sr))
    for k, i in enumerate(range(0, n, step)):
        m = min(step, n - i)
        y[i:i + m] = tone(m, chords[k % len(chords)], sr=sr) * fade[:m]
    return y


def signals():
    rng = np.random.default_rng(7)
    s = {}
    s["click_90"] = clicks(5 * SR, lambda t: 90.0)
    s["click_120"] = clicks(5 * SR, lambda t: 120.0)
    s["click_150"] = clicks(5 * SR, lambda t: 150.0)
    s["clicks_chords"] = clicks(6 * SR, lambda t: 110.0, amp=0.6) + chord_progression(6 * SR)
    s["chords"] = chord_progression(6 * SR)
    n = 5 * SR
    t = np.arange(n) / SR
    f0, f1 = 50.0, 5000.0
    s["chirp"] = 0.5 * np.sin(2 * np.pi * f0 * (5 / np.log(f1 / f0)) * ((f1 / f0) ** (t / 5) - 1))
    s["noise"] = 0.3 * rng.standard_normal(3 * SR)
    s["tempo_change"] = clicks(8 * SR, lambda t: 90.0 if t < 4 else 140.0)
    s["short"] = tone(1500, [440.0], amp=0.5) + np.where(np.arange(1500) == 700, 0.9, 0.0)
    s["silence"] = np.zeros(2 * SR)
    return s


def quantise(y):
    q = np.clip(np.round(y * 32767), -32768, 32767).astype(np.int16)
    return q, (q.astype(np.float32) / 32768.0)


def write_decoded_fixture(manifest):
    """A 2 s stereo 44.1 kHz FLAC (lossless) and the original loader's view of it:
    essentia's MonoLoader = (L+R)/2 then libsamplerate SINC_MEDIUM to 15360 Hz."""
    import samplerate
    import soundfile as sf
    sr = 44100
    n = 2 * sr
    t = np.arange(n) / sr
    left = 0.3 * np.sin(2 * np.pi * 330.0 * t) + 0.2 * np.sin(2 * np.pi * 2500 * t) * (np.sin(2 * np.pi * 2 * t) > 0)
    right = 0.3 * np.sin(2 * np.pi * 440.0 * t)
    for k in range(8):
        i = int((0.1 + 0.25 * k) * sr)
        right[i:i + 400] += 0.6 * np.exp(-np.arange(400) / 60.0) * np.sin(2 * np.pi * 1200 * np.arange(400) / sr)
    st = np.stack([left, right], 1)
    q = np.clip(np.round(st * 32767), -32768, 32767).astype(np.int16)
    path = os.path.join(OUT, "stereo_44k.flac")
    sf.write(path, q, sr, subtype="PCM_16")
    back, _ = sf.read(path, dtype="int16")
    assert np.array_equal(back, q)
    mono = q.astype(np.float32).mean(axis=1) / 32768.0
    y = samplerate.resample(mono, SR / sr, "sinc_medium").astype(np.float32)
    np.save(os.path.join(OUT, "stereo_44k_mono_15360.npy"), y)
    feat, tempo, tuning = features(y)
    np.save(os.path.join(OUT, "stereo_44k.features.npy"), feat)
    manifest.append(f"stereo_44k {tempo:.6f} {tuning:.6f} {feat.shape[0]} {len(y)}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--speed", action="store_true", help="time librosa on a 180 s signal and exit")
    ap.add_argument("--one", help="(internal) compute one signal's fixtures and print its manifest line")
    args = ap.parse_args()
    assert librosa.__version__ == "0.8.1", librosa.__version__
    if args.speed:
        rng = np.random.default_rng(1)
        n = 180 * SR
        y = (clicks(n, lambda t: 118.0) + chord_progression(n) + 0.05 * rng.standard_normal(n)).astype(np.float32)
        features(y[: 5 * SR])  # warm numba / caches
        t0 = time.perf_counter()
        feat, _, _ = features(y)
        dt = time.perf_counter() - t0
        print(f"librosa 0.8.1: 180 s signal -> {feat.shape} in {dt:.3f} s")
        return
    os.makedirs(OUT, exist_ok=True)
    if args.one:
        # One signal per process: librosa 0.8.1 keeps state between calls (after
        # several signals in one process it returned a non-finite harmonic part
        # for the 1500-sample clip that is fine in a fresh process).
        y = signals()[args.one]
        q, yf = quantise(y)
        feat, tempo, tuning = features(yf)
        np.save(os.path.join(OUT, f"{args.one}.pcm16.npy"), q)
        np.save(os.path.join(OUT, f"{args.one}.features.npy"), feat)
        print(f"{args.one} {tempo:.6f} {tuning:.6f} {feat.shape[0]} {len(q)}")
        print(args.one, feat.shape, "tempo", tempo, "tuning", tuning, "beats", np.flatnonzero(feat[:, 53]).tolist(), file=sys.stderr)
        return
    import subprocess
    manifest = []
    for name in signals():
        line = subprocess.run([sys.executable, "-W", "ignore", __file__, "--one", name], check=True, capture_output=True, text=True)
        sys.stderr.write(line.stderr)
        manifest.append(line.stdout.strip())
    write_decoded_fixture(manifest)
    with open(os.path.join(OUT, "manifest.txt"), "w") as f:
        f.write("# name tempo_bpm tuning frames samples (regenerate: tools/music_goldens.py)\n")
        f.write("\n".join(manifest) + "\n")


if __name__ == "__main__":
    main()
