#!/usr/bin/env python3
"""Writes madmom's downbeat network ensemble in the engine's plain format.

Transflower's audio columns 81 and 82 are madmom's `RNNDownBeatProcessor`
activations (beat, downbeat). The engine computes them itself
(`std-adapters/src/music/madmom/`), but it does not ship the networks: madmom's
trained models are licensed CC BY-NC-SA 4.0 (madmom/models/LICENSE), so a user
who may use them converts them from their own madmom install:

    pip install madmom            # 0.16.1; see tools/transflower_audio_goldens.py for Python >= 3.10
    python3 tools/madmom_weights.py madmom_downbeats.bin
    duolando features --for transflower --madmom madmom_downbeats.bin song.mp3 -o audio.npy

Format (docs/TRANSFLOWER.md "madmom's downbeat networks"), little-endian:
    8 bytes  magic b"DUOMMRNN"
    u32 x 6  version (1), networks, inputs, BLSTM layers, hidden units, outputs
    then per network, per BLSTM layer, per direction (forward, backward), per
    gate (input, forget, cell, output): W (in, hidden) row-major, bias
    (hidden), recurrent W (hidden, hidden), and for every gate but the cell
    its peephole weights (hidden); `in` is `inputs` for the first layer and
    2 * hidden above. Then the softmax layer: W (2 * hidden, outputs), bias
    (outputs). All f32.
"""
import struct
import sys

import numpy as np

MAGIC = b"DUOMMRNN"
VERSION = 1
GATES = ("input_gate", "forget_gate", "cell", "output_gate")


def _f32(a):
    return np.ascontiguousarray(a, dtype="<f4").tobytes()


def ensemble_bytes(networks):
    """The file's bytes for a list of madmom `NeuralNetwork`s of the downbeat
    architecture (BLSTM layers of LSTMLayers with peepholes, then a softmax
    FeedForwardLayer); anything else is refused."""
    from madmom.ml.nn.layers import BidirectionalLayer, FeedForwardLayer, LSTMLayer

    first = networks[0]
    n_layers = len(first.layers) - 1
    lstm0 = first.layers[0].fwd_layer
    n_in, hidden = lstm0.input_gate.weights.shape
    n_out = first.layers[-1].weights.shape[1]
    out = [MAGIC, struct.pack("<6I", VERSION, len(networks), n_in, n_layers, hidden, n_out)]
    for nn in networks:
        assert len(nn.layers) == n_layers + 1, "every network needs the same layer count"
        for li, layer in enumerate(nn.layers[:-1]):
            assert isinstance(layer, BidirectionalLayer), type(layer)
            width = n_in if li == 0 else 2 * hidden
            for lstm in (layer.fwd_layer, layer.bwd_layer):
                assert isinstance(lstm, LSTMLayer), type(lstm)
                assert lstm.activation_fn.__name__ == "tanh"
                assert not np.any(lstm.init) and not np.any(lstm.cell_init), "non-zero initial state"
                for g in GATES:
                    gate = getattr(lstm, g)
                    assert gate.weights.shape == (width, hidden), (g, gate.weights.shape)
                    assert gate.recurrent_weights.shape == (hidden, hidden)
                    want = "tanh" if g == "cell" else "sigmoid"
                    assert gate.activation_fn.__name__ == want, (g, gate.activation_fn.__name__)
                    out += [_f32(gate.weights), _f32(gate.bias.reshape(hidden)), _f32(gate.recurrent_weights)]
                    peep = getattr(gate, "peephole_weights", None)
                    if g == "cell":
                        assert peep is None
                    else:
                        assert peep is not None and peep.size == hidden
                        out.append(_f32(peep.reshape(hidden)))
        last = nn.layers[-1]
        assert isinstance(last, FeedForwardLayer) and last.activation_fn.__name__ == "softmax"
        assert last.weights.shape == (2 * hidden, n_out)
        out += [_f32(last.weights), _f32(last.bias.reshape(n_out))]
    return b"".join(out)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    import collections
    import collections.abc

    collections.MutableSequence = collections.abc.MutableSequence  # madmom 0.16.1 on Python >= 3.10
    from madmom.ml.nn import NeuralNetwork
    from madmom.models import DOWNBEATS_BLSTM

    nets = [NeuralNetwork.load(f) for f in DOWNBEATS_BLSTM]
    data = ensemble_bytes(nets)
    with open(sys.argv[1], "wb") as f:
        f.write(data)
    print(f"{sys.argv[1]}: {len(nets)} networks, {len(data)} bytes (madmom's models: CC BY-NC-SA 4.0)")


if __name__ == "__main__":
    main()
