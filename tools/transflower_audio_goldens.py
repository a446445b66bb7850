#!/usr/bin/env python3
"""Regenerates tests/fixtures/transflower_audio/: golden Transflower audio features.

The authors' extraction (guillefix/transflower-lightning, feature_extraction/
process_audio.py + audio_feature_utils.py, called by audio_feature_extraction.sh
with `--feature_names mel,envelope,madmombeats --mel_feature_size 80 --fps 20`
and process_audio.py's default `--sampling_rate 96000`) is copied call for call
below (`authors_features`). The DDC PCA columns (83, 84) need a checkpoint and a
fitted PCA that are not available, so the goldens hold the first 83 columns.

Run in its own venv (librosa 0.8.1 as the authors' era; madmom 0.16.1, the
version the authors vendor, built from the sdist with its .c files deleted so
that Cython 0.29 regenerates them for Python 3.11):
    python3 -m venv /work/venv-tfaudio
    /work/venv-tfaudio/bin/pip install "librosa==0.8.1" "numpy<1.24" "scipy==1.12.0" soundfile resampy "cython<3" setuptools wheel mido
    pip download --no-deps --no-binary :all: madmom==0.16.1; tar xzf madmom-0.16.1.tar.gz
    cd madmom-0.16.1; find madmom -name '*.c' -delete; /work/venv-tfaudio/bin/pip install --no-build-isolation .
    /work/venv-tfaudio/bin/python tools/transflower_audio_goldens.py

Writes:
  clip96k.flac              3 s mono 96 kHz 16-bit synthetic clip (clicks at 120 BPM,
                            chords, a chirp), quantised to 12 bits so FLAC stays small.
                            At the features' own rate: librosa reads it unresampled,
                            so the Rust test checks the feature code alone.
  clip96k.golden.npy        (T, 83) float32: mel 80, envelope, madmom beat, downbeat.
  stereo_44k.golden.npy     (T, 83) float32 of tests/fixtures/music/stereo_44k.flac
                            loaded like the authors do (librosa.load(sr=96000):
                            resampy kaiser_best), i.e. the whole file path.
  manifest.json             versions, shapes, what each column is.
madmom runs on a 44.1 kHz int16 WAV path, as the authors call it
(`RNNDownBeatProcessor()(path, fps=20)`); for clip96k that WAV is
librosa.resample(kaiser_best) to 44.1 kHz (the authors' madmom would have
used ffmpeg), so clip96k's madmom columns are informative only.
"""
import collections
import collections.abc
import json
import os
import tempfile

collections.MutableSequence = collections.abc.MutableSequence  # madmom 0.16.1 on Python >= 3.10

import librosa
import madmom
import numpy as np
import soundfile as sf

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "transflower_audio")
STEREO = os.path.join(HERE, "..", "tests", "fixtures", "music", "stereo_44k.flac")
SR = 96000  # process_audio.py --sampling_rate default
FPS = 20


# --- the authors' functions (audio_feature_utils.py), verbatim in substance ---
def extract_features_mel(y, sr, hop, mel_dim=100):
    mel = librosa.feature.melspectrogram(y=y, sr=sr, n_mels=mel_dim, hop_length=hop)
    return librosa.power_to_db(mel, ref=np.max)


def extract_features_envelope(y, sr, hop, mel_dim=100):
    envelope = librosa.onset.onset_strength(y=y, hop_length=hop, n_mels=mel_dim)  # sr not passed
    return np.expand_dims(envelope, 1)


def extract_features_madmombeat(music_file, tgt_fps=20):
    proc_dwn = madmom.features.RNNDownBeatProcessor()
    return proc_dwn(music_file, fps=20)


def authors_features(song_file_path, madmom_wav):
    """process_audio.py's loop for feature_names mel,envelope,madmombeats."""
    featuress = []
    for feature_name in ["mel", "envelope", "madmombeats"]:
        y_wav, sr = librosa.load(song_file_path, sr=SR)
        sr = SR
        hop = int(round(sr * (1.0 / FPS)))
        if feature_name == "mel":
            features = extract_features_mel(y_wav, sr, hop, mel_dim=80).transpose(1, 0)[1:]
        elif feature_name == "envelope":
            features = extract_features_envelope(y_wav, sr, hop)[1:]
        elif feature_name == "madmombeats":
            features = extract_features_madmombeat(madmom_wav, FPS)
        featuress.append(features)
    shortest = min(f.shape[0] for f in featuress)
    featuress = [f[:shortest] for f in featuress]
    lengths = [f.shape[0] for f in featuress]
    return np.ascontiguousarray(np.concatenate(featuress, 1), dtype=np.float32), lengths


def clip(seconds=3.0):
    n = int(seconds * SR)
    t = np.arange(n) / SR
    y = np.zeros(n)
    burst = np.arange(int(0.03 * SR)) / SR
    for k, bt in enumerate(np.arange(0.25, seconds, 0.5)):  # 120 BPM, accent every 4th
        i = int(bt * SR)
        m = min(len(burst), n - i)
        amp = 0.6 if k % 4 == 0 else 0.3
        y[i:i + m] += amp * np.sin(2 * np.pi * 1500 * burst[:m]) * np.exp(-burst[:m] * 150)
        y[i:i + m] += 0.2 * amp * np.sin(2 * np.pi * 9000 * burst[:m]) * np.exp(-burst[:m] * 300)
    chord = [220.0, 277.18, 329.63]
    env = np.clip(np.sin(np.pi * t / seconds), 0, 1)
    y += sum(0.08 * env * np.sin(2 * np.pi * f * t) for f in chord)
    f0, f1 = 100.0, 20000.0  # exponential chirp over the whole clip
    y += 0.03 * np.sin(2 * np.pi * f0 * seconds / np.log(f1 / f0) * ((f1 / f0) ** (t / seconds) - 1))
    q = np.round(y * 2048) * 16  # 12 significant bits in int16
    return np.clip(q, -32768, 32767).astype(np.int16)


def write_wav44(y_float, path):
    sf.write(path, np.clip(np.round(y_float * 32768), -32768, 32767).astype(np.int16), 44100, subtype="PCM_16")


def main():
    os.makedirs(OUT, exist_ok=True)
    pcm = clip()
    flac = os.path.join(OUT, "clip96k.flac")
    sf.write(flac, pcm, SR, subtype="PCM_16")
    assert np.array_equal(sf.read(flac, dtype="int16")[0], pcm)
    manifest = {
        "source": "tools/transflower_audio_goldens.py",
        "librosa": librosa.__version__,
        "madmom": madmom.__version__,
        "numpy": np.__version__,
        "columns": "0..80 mel (power_to_db ref max), 80 onset envelope, 81 madmom beat, 82 madmom downbeat",
        "files": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        # clip96k: madmom on a 44.1 kHz WAV resampled by librosa (informative)
        wav = os.path.join(tmp, "clip96k.wav")
        write_wav44(librosa.resample(pcm.astype(np.float32) / 32768, SR, 44100), wav)
        f, lengths = authors_features(flac, wav)
        np.save(os.path.join(OUT, "clip96k.golden.npy"), f)
        manifest["files"]["clip96k"] = {"audio": "clip96k.flac", "samples_96k": int(len(pcm)),
                                        "shape": list(f.shape), "part_lengths": lengths,
                                        "madmom_input": "librosa.resample kaiser_best to 44.1 kHz int16 WAV"}
        # stereo_44k: the whole path; madmom on the file's own 44.1 kHz samples
        data, sr = sf.read(STEREO, dtype="int16")
        assert sr == 44100
        wav = os.path.join(tmp, "stereo_44k.wav")
        sf.write(wav, data, 44100, subtype="PCM_16")
        f, lengths = authors_features(STEREO, wav)
        np.save(os.path.join(OUT, "stereo_44k.golden.npy"), f)
        manifest["files"]["stereo_44k"] = {"audio": "../music/stereo_44k.flac",
                                           "shape": list(f.shape), "part_lengths": lengths,
                                           "madmom_input": "the file's int16 stereo as a WAV path (the authors' call)"}
    with open(os.path.join(OUT, "manifest.json"), "w") as fh:
        json.dump(manifest, fh, indent=1)
        fh.write("\n")
    for name in sorted(os.listdir(OUT)):
        print(name, os.path.getsize(os.path.join(OUT, name)))


if __name__ == "__main__":
    main()
