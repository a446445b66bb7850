#!/usr/bin/env python3
"""Regenerates tests/fixtures/madmom/: goldens of madmom's downbeat activations.

madmom's own classes run the whole `RNNDownBeatProcessor` chain (signal,
three framed STFTs, log filterbanks, log magnitudes, positive differences,
the BLSTM ensemble, the non-beat column dropped), with small networks of the
same architecture and seeded random weights in place of madmom's trained
ones (those are CC BY-NC-SA 4.0 and not committed; tools/madmom_weights.py
converts a user's copy). The Rust tests (std-adapters/tests/madmom_downbeats.rs)
read these files.

Run in the venv described in tools/transflower_audio_goldens.py (madmom 0.16.1):
    /work/venv-tfaudio/bin/python tools/madmom_goldens.py

Writes (from tests/fixtures/music/stereo_44k.flac: 2 s, 44.1 kHz, 16-bit
stereo, loaded by madmom from a WAV of the same samples, as the authors call it):
  random_downbeats.bin       2 networks, 3 BLSTM layers of 4 units, our format
  stereo_44k_fps20.input.npy (T, 314) float32: the networks' input at fps 20
  stereo_44k_fps20.act.npy   (T, 2) float32: beat, downbeat at fps 20 (the authors' call)
  stereo_44k_fps100.input.npy (50, 314) float32: the first 50 input rows at
                             madmom's own 100 fps (differences over 2 frames at 4096)
  stereo_44k_fps100.act.npy  (T, 2) float32 at fps 100
  manifest.json
"""
import collections
import collections.abc
import json
import os
import sys
import tempfile

collections.MutableSequence = collections.abc.MutableSequence  # madmom 0.16.1 on Python >= 3.10

import madmom
import numpy as np
import soundfile as sf
from madmom.audio.signal import FramedSignalProcessor, SignalProcessor
from madmom.audio.spectrogram import (FilteredSpectrogramProcessor, LogarithmicSpectrogramProcessor,
                                      SpectrogramDifferenceProcessor)
from madmom.audio.stft import ShortTimeFourierTransformProcessor
from madmom.ml.nn import NeuralNetwork, NeuralNetworkEnsemble
from madmom.ml.nn.activations import sigmoid, softmax, tanh
from madmom.ml.nn.layers import BidirectionalLayer, Cell, FeedForwardLayer, Gate, LSTMLayer
from madmom.processors import ParallelProcessor, SequentialProcessor

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from madmom_weights import ensemble_bytes  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "tests", "fixtures", "madmom")
STEREO = os.path.join(HERE, "..", "tests", "fixtures", "music", "stereo_44k.flac")
HIDDEN = 4
NETS = 2
LAYERS = 3


def pre_processor():
    """RNNDownBeatProcessor's pre-processing chain, as madmom builds it."""
    sig = SignalProcessor(num_channels=1, sample_rate=44100)
    multi = ParallelProcessor([])
    for frame_size, num_bands in zip([1024, 2048, 4096], [3, 6, 12]):
        frames = FramedSignalProcessor(frame_size=frame_size, fps=100)
        stft = ShortTimeFourierTransformProcessor()
        filt = FilteredSpectrogramProcessor(num_bands=num_bands, fmin=30, fmax=17000, norm_filters=True)
        spec = LogarithmicSpectrogramProcessor(mul=1, add=1)
        diff = SpectrogramDifferenceProcessor(diff_ratio=0.5, positive_diffs=True, stack_diffs=np.hstack)
        multi.append(SequentialProcessor((frames, stft, filt, spec, diff)))
    return SequentialProcessor((sig, multi, np.hstack))


def random_network(rng, n_in):
    def lstm(width):
        def gate(cls, peep, act):
            w = (rng.standard_normal((width, HIDDEN)) * 0.4).astype(np.float32)
            b = (rng.standard_normal(HIDDEN) * 0.3).astype(np.float32)
            r = (rng.standard_normal((HIDDEN, HIDDEN)) * 0.5).astype(np.float32)
            if cls is Cell:
                return Cell(w, b, r, activation_fn=act)
            p = (rng.standard_normal(HIDDEN) * 0.5).astype(np.float32) if peep else None
            return Gate(w, b, r, peephole_weights=p, activation_fn=act)

        return LSTMLayer(gate(Gate, True, sigmoid), gate(Gate, True, sigmoid), gate(Cell, False, tanh),
                         gate(Gate, True, sigmoid), activation_fn=tanh)

    layers = []
    for li in range(LAYERS):
        width = n_in if li == 0 else 2 * HIDDEN
        layers.append(BidirectionalLayer(lstm(width), lstm(width)))
    w = (rng.standard_normal((2 * HIDDEN, 3)) * 1.5).astype(np.float32)
    b = (rng.standard_normal(3) * 0.5).astype(np.float32)
    layers.append(FeedForwardLayer(w, b, activation_fn=softmax))
    return NeuralNetwork(layers)


def main():
    os.makedirs(OUT, exist_ok=True)
    rng = np.random.default_rng(20261207)
    n_in = 314
    nets = [random_network(rng, n_in) for _ in range(NETS)]
    with open(os.path.join(OUT, "random_downbeats.bin"), "wb") as f:
        f.write(ensemble_bytes(nets))
    manifest = {"source": "tools/madmom_goldens.py", "madmom": madmom.__version__, "numpy": np.__version__,
                "networks": NETS, "layers": LAYERS, "hidden": HIDDEN, "files": {}}
    pcm, sr = sf.read(STEREO, dtype="int16")
    assert sr == 44100 and pcm.ndim == 2
    with tempfile.TemporaryDirectory() as tmp:
        wav = os.path.join(tmp, "stereo_44k.wav")
        sf.write(wav, pcm, sr, subtype="PCM_16")
        for fps in (20, 100):
            # The authors' call: RNNDownBeatProcessor()(path, fps=fps), its
            # networks replaced by `nets`.
            pre = pre_processor()
            x = pre(wav, fps=fps)
            ens = NeuralNetworkEnsemble(nets)
            act = np.delete(ens(x), 0, axis=1)
            # The same through madmom's class (its processors' kwargs path).
            full = SequentialProcessor((pre_processor(), NeuralNetworkEnsemble(nets),
                                        lambda a: np.delete(a, 0, axis=1)))
            assert np.array_equal(full(wav, fps=fps), act)
            x = np.asarray(x, dtype=np.float32)
            keep = x if fps == 20 else x[:50]
            np.save(os.path.join(OUT, f"stereo_44k_fps{fps}.input.npy"), np.ascontiguousarray(keep))
            np.save(os.path.join(OUT, f"stereo_44k_fps{fps}.act.npy"), np.ascontiguousarray(act, dtype=np.float32))
            manifest["files"][f"fps{fps}"] = {"rows": int(x.shape[0]), "input_rows_kept": int(keep.shape[0]),
                                              "act_min": float(act.min()), "act_max": float(act.max())}
    with open(os.path.join(OUT, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=1)
    print(json.dumps(manifest, indent=1))


if __name__ == "__main__":
    main()
