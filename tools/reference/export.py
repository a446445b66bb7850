"""Fixed-shape ONNX exports of the reference modules (opset 17, batch 1), one file per length.

Every export is checked against the torch module with onnx.reference (no onnxruntime).
The file contract (names, shapes, dtypes) is documented in tests/fixtures/README.md.
"""
import json
import os

import numpy as np
import onnx
import torch
import torch.nn as nn
from onnx.reference import ReferenceEvaluator

from .vqvae import PARTS


class MusicLat(nn.Module):
    def __init__(self, gpt):
        super().__init__()
        self.lat = gpt.music_trans

    def forward(self, music):  # (1, (c+lf)*4, 54) -> (1, c, E)
        return self.lat(music)


class LeaderLat(nn.Module):
    def __init__(self, gpt, part):
        super().__init__()
        self.emb = getattr(gpt, f"tok_emb_{part}")
        self.lat = getattr(gpt, f"leader_{part}_trans")

    def forward(self, tokens):  # (1, c+lf) int64 -> (1, c, E)
        return self.lat(self.emb(tokens))


class GptStep(nn.Module):
    """One R window step: logits of the 5 heads at the last window position."""

    def __init__(self, gpt):
        super().__init__()
        self.gpt = gpt

    def forward(self, f_up, f_down, f_lhand, f_rhand, f_transl, music, l_up, l_down, l_lhand, l_rhand):
        logits = self.gpt([f_up, f_down, f_lhand, f_rhand, f_transl], music, [l_up, l_down, l_lhand, l_rhand])
        return torch.stack([lg[:, -1, :] for lg in logits], dim=1)  # (1, 5, V)


class VqEncoder(nn.Module):
    """Pure conv encoder + nearest code (no first-joint zeroing)."""

    def __init__(self, vae):
        super().__init__()
        self.vae = vae

    def forward(self, x):  # (1, T, C) -> feat (1, T/4, emb), codes (1, T/4)
        feat = self.vae.features(x)
        codes = self.vae.bottleneck.level_blocks[0].encode(feat)
        return feat.permute(0, 2, 1), codes


class VqDecoder(nn.Module):
    def __init__(self, vae, which):
        super().__init__()
        self.vae, self.which = vae, which

    def forward(self, codes):  # (1, Q) -> (1, 4Q, C)
        z = self.vae.bottleneck.level_blocks[0].decode(codes)
        dec = {"pos": self.vae.decoders, "rot": getattr(self.vae, "decoders_rot", None),
               "transl": self.vae.decoders}[self.which][0]
        return dec(z).permute(0, 2, 1)


def _spec(name, arr):
    return {"name": name, "dtype": "int64" if arr.dtype == np.int64 else "float32", "shape": list(arr.shape)}


def runtime_gather_tables(model):
    """Route every constant table read by a Gather through `Mul(table, one)`,
    with `one` a new float (1,) graph input (fed 1.0: exact).

    tract-onnx 0.21's optimizer fails on the GPT step when an embedding
    table is a constant read by a Gather (its codegen "versatile packing"
    of the const substitutes an F16 fact); a runtime table sidesteps that
    and lets the Rust property tests run the GPT step optimized (seconds
    instead of many minutes). Returns the number of tables rerouted."""
    inits = {i.name for i in model.graph.initializer}
    model.graph.input.append(onnx.helper.make_tensor_value_info("one", onnx.TensorProto.FLOAT, [1]))
    nodes, k = [], 0
    for n in model.graph.node:
        if n.op_type == "Gather" and n.input[0] in inits:
            out = f"{n.input[0]}.runtime{k}"
            k += 1
            nodes.append(onnx.helper.make_node("Mul", [n.input[0], "one"], [out]))
            n.input[0] = out
        nodes.append(n)
    del model.graph.node[:]
    model.graph.node.extend(nodes)
    return k


def export_one(module, inputs, in_names, out_names, path, atol=2e-5, runtime_tables=False):
    """Export, then run the ONNX file with onnx.reference and compare with torch.

    With `runtime_tables`, the file gets the extra input `one` (see
    runtime_gather_tables)."""
    module.eval()
    with torch.no_grad():
        ref = module(*inputs)
    ref = ref if isinstance(ref, tuple) else (ref,)
    kwargs = {"dynamo": False} if "dynamo" in torch.onnx.export.__code__.co_varnames else {}
    torch.onnx.export(module, tuple(inputs), path, input_names=in_names, output_names=out_names,
                      opset_version=17, do_constant_folding=True, **kwargs)
    model = onnx.load(path)
    feeds = {n: x.numpy() for n, x in zip(in_names, inputs)}
    if runtime_tables:
        runtime_gather_tables(model)
        onnx.save(model, path)
        feeds["one"] = np.ones(1, dtype=np.float32)
    onnx.checker.check_model(model)
    got = ReferenceEvaluator(model).run(None, feeds)
    worst = 0.0
    for name, r, g in zip(out_names, ref, got):
        r = r.numpy()
        if r.dtype == np.int64:
            if not np.array_equal(r, g):
                raise AssertionError(f"{path}: output {name} codes differ from torch")
        else:
            err = float(np.max(np.abs(r - g)))
            worst = max(worst, err / max(1.0, float(np.max(np.abs(r)))))
    if worst > atol:
        raise AssertionError(f"{path}: onnx.reference differs from torch by {worst:.3g} (rel)")
    ops = sorted({n.op_type for n in model.graph.node})
    return {"file": os.path.basename(path),
            "inputs": [_spec(n, f.numpy()) for n, f in zip(in_names, inputs)]
                      + ([_spec("one", np.ones(1, dtype=np.float32))] if runtime_tables else []),
            "outputs": [_spec(n, r.numpy()) for n, r in zip(out_names, ref)],
            "ops": ops, "onnx_reference_max_rel_err": worst}


def export_all(gpt, vq, tr, out_dir, ctxs, gpt_ctxs, enc_lengths, dec_lengths, seed=0):
    """Write every ONNX file for one model into out_dir and an index.json describing them."""
    os.makedirs(out_dir, exist_ok=True)
    g = torch.Generator().manual_seed(seed)
    lf = gpt.look_forward
    v = gpt.cfg.vocab_size_up
    index = []

    def toks(n, vocab=v):
        return torch.randint(0, vocab, (1, n), generator=g)

    for c in ctxs:
        music = torch.randn(1, (c + lf) * 4, 54, generator=g)
        index.append(export_one(MusicLat(gpt), [music], ["music"], ["cond"], f"{out_dir}/music_lat_c{c}.onnx"))
        for p in PARTS:
            index.append(export_one(LeaderLat(gpt, p), [toks(c + lf)], ["tokens"], ["cond"],
                                    f"{out_dir}/leader_lat_{p}_c{c}.onnx"))
    for c in gpt_ctxs:
        music = torch.randn(1, (c + lf) * 4, 54, generator=g)
        f = [toks(c) for _ in range(5)]
        l = [toks(c + lf) for _ in range(4)]
        names = ["f_up", "f_down", "f_lhand", "f_rhand", "f_transl", "music", "l_up", "l_down", "l_lhand", "l_rhand"]
        index.append(export_one(GptStep(gpt), f + [music] + l, names, ["logits"], f"{out_dir}/gpt_step_c{c}.onnx",
                                runtime_tables=True))
    for p in PARTS:
        vae = vq.part(p)
        for t in enc_lengths:
            x = torch.randn(1, t, vae.hps.pos_channel, generator=g)
            index.append(export_one(VqEncoder(vae), [x], ["pos"], ["feat", "codes"], f"{out_dir}/vq_{p}_encoder_t{t}.onnx"))
        for q in dec_lengths:
            for which in ("pos", "rot"):
                index.append(export_one(VqDecoder(vae, which), [toks(q, vae.hps.l_bins)], ["codes"], [which],
                                        f"{out_dir}/vq_{p}_decoder_{which}_q{q}.onnx"))
    for t in enc_lengths:
        x = torch.randn(1, t, 3, generator=g) * 10
        index.append(export_one(VqEncoder(tr), [x], ["transl"], ["feat", "codes"], f"{out_dir}/transl_encoder_t{t}.onnx"))
    for q in dec_lengths:
        index.append(export_one(VqDecoder(tr, "transl"), [toks(q, tr.hps.l_bins)], ["codes"], ["transl"],
                                f"{out_dir}/transl_decoder_q{q}.onnx"))
    with open(f"{out_dir}/index.json", "w") as fh:
        json.dump(index, fh, indent=1)
    return index
