"""Transflower's R step in ONNX Runtime: the baseline `duolando bench --family transflower
--ort-json` prints its ratios against (issue #39).

The authors' `TransflowerModel` (guillefix/transflower-lightning, vendored unmodified under
tools/reference/transflower/authors and built by its env.py) at the PUBLISHED paper config
(training/hparams/dance_combined/transflower_expmap.yaml: dhid 800, 10 heads, 2 + 2 input
layers, 12 cross-modal layers, 16 flow steps with 2-layer 512-wide coupling transformers;
122,323,152 parameters) with seeded random weights (the authors' own initialisation under
`np.random.seed` / `torch.manual_seed`: a flow that stays well conditioned, frames of order
1-10; tiny.py's `init_weights` makes the 16 inverse couplings amplify to ~1e6), in eval mode,
exported as ONE R step, the step `duolando bench --family transflower` times
(`transflower::exact::step`):

    inputs   motion (120, 69)  the motion window (scaled expmap features)
             audio  (140, 85)  the audio window (scaled audio features)
             z      (69, 3)    the base sample (C, output_lengths), what the flow's
                               distribution.sample would draw
    output   frame  (69,)      the next frame (row 0 of the 3 sampled frames: what the authors'
                               loop keeps and feeds back)

The graph holds both input transformers, the cross-modal transformer (cond = its first 3
rows) and the flow's whole reverse pass (16 x BatchNorm, LU 1x1 conv, affine coupling with
its transformer), traced from the authors' modules as they are: `TransflowerModel.forward` is
called unchanged; the wrapper only reshapes the inputs to the authors' (T, 1, d) layout and
makes the flow's `distribution.sample` return `z` (instance attribute, as
tools/reference/transflower/reference.py replays recorded noise). The 1x1 convs' inverse
weights are constants in the graph: the authors' `InvertibleConv1x1` computes them (float64
inverses of L and U) on its first reverse pass and reuses `saved_weight` afterwards, and the
export traces a later pass (`torch.inverse` has no ONNX op; the engine also holds them as
constants). Before export the step is checked against the authors' own generation loop
(`reference.generate` with a 140-row audio window = one step, `z` replayed): identical. Cost
does not depend on the weights' values.

Timed in onnxruntime (f32, graph optimisations on, 1 intra-op and 1 inter-op thread; then 2
intra-op threads) after warm-up; writes a JSON the bench reads: median/p99 ms (1 thread) and
`by_threads` (1 and 2), onnxruntime version, CPU, load, torch-vs-onnxruntime difference.

    /work/venv/bin/python tools/transflower_ort_r_step.py --out /tmp/transflower_ort.json   # repo root
    cargo run --release -p duolando -- bench --family transflower --dtypes int8,f32 \\
        --threads 1 --runs 3 --ort-json /tmp/transflower_ort.json

Needs torch, onnx, onnxruntime, pyyaml, numpy, scipy (pip; tools/requirements.txt); none of
them is a dependency of the engine or CI. ~30 s on a quiet machine (export ~10 s, then
2 x 33 steps), writes a ~490 MB ONNX file (--onnx). Figures: docs/TRANSFLOWER.md
"onnxruntime baseline of the R step". `--hparams FILE` builds from the YAML file instead of
the copy below (e.g. `git -C /work/.mirror/guillefix+transflower-lightning/repo show
HEAD:training/hparams/dance_combined/transflower_expmap.yaml > /tmp/tf.yaml`).
"""
import argparse
import os
import sys

import numpy as np
import torch
import yaml

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "reference"))
from transflower import env, reference  # noqa: E402
from ort_timing import add_common_args, cpu_name, time_session, write_json  # noqa: E402

# training/hparams/dance_combined/transflower_expmap.yaml at the vendored commit (the keys that
# reach the model; dhid_flow 512 and num_heads_flow 8 are the option defaults it leaves unset).
PAPER_YAML = {
    "model": "transflower",
    "dins": "69,85",
    "douts": "69",
    "input_modalities": "expmap_scaled_20,audio_feats_scaled_20",
    "output_modalities": "expmap_scaled_20",
    "input_lengths": "120,140",
    "output_lengths": 3,
    "output_time_offsets": 120,
    "nlayers": 12,
    "nhead": 10,
    "scales": "[[16,0]]",
    "num_glow_coupling_blocks": 2,
    "glow_use_attn": True,
    "use_transformer_nn": True,
    "use_pos_emb_coupling": True,
    "dhid": 800,
    "cond_concat_dims": True,
    "glow_norm_layer": "batchnorm",
    "glow_bn_momentum": 0.1,
    "dropout": 0,
}
PAPER_PARAMS = 122_323_152  # docs/TRANSFLOWER.md, tools/reference/transflower/README.md §8


class RStep(torch.nn.Module):
    """One R step: motion (120, 69), audio (140, 85), z (69, 3) -> the next frame (69,).

    Calls the authors' `TransflowerModel.forward` (input nets, cross-modal net, flow reverse)
    with the windows in their (T, 1, d) layout; the flow's base distribution returns `z`."""

    def __init__(self, model):
        super().__init__()
        self.model = model
        self.dist = model.output_mod_glows[0].distribution

    def forward(self, motion, audio, z):
        zb = z.unsqueeze(0)  # (1, C, H): GaussianDiag.sample's shape

        def sample(z_shape, eps_std=None, device=None):
            assert tuple(z_shape) == tuple(zb.shape), (z_shape, zb.shape)
            return zb

        self.dist.sample = sample
        try:
            out = self.model.forward([motion.unsqueeze(1), audio.unsqueeze(1)])[0]  # (H, 1, C)
        finally:
            del self.dist.sample
        return out[0, 0]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hparams", help="a Transflower hparams YAML (default: the paper config above)")
    add_common_args(ap, "/tmp/transflower_r_step.onnx", "490 MB", runs=30)
    args = ap.parse_args()

    import onnx
    import onnxruntime as ort

    torch.set_num_threads(1)
    if args.hparams:
        with open(args.hparams) as f:
            hp = yaml.safe_load(f)
    else:
        hp = dict(PAPER_YAML)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    model = env.build(hp)
    n_params = sum(p.numel() for p in model.parameters())
    if not args.hparams and n_params != PAPER_PARAMS:
        raise SystemExit(f"{n_params} parameters, expected {PAPER_PARAMS} for the paper config")
    assert len(model.input_mods) == 2 and len(model.output_mods) == 1, "two continuous inputs, one output"
    (lm, la), (dm, da) = model.input_lengths, model.dins
    c, h = model.douts[0], model.output_lengths[0]

    g = torch.Generator().manual_seed(args.seed + 1)
    motion = torch.randn(lm, dm, generator=g)
    audio = torch.randn(la, da, generator=g)
    z = torch.randn(c, h, generator=g)
    step = RStep(model).eval()
    with torch.no_grad():
        want = step(motion, audio, z)  # first reverse pass: the 1x1 convs compute their inverses
        again = step(motion, audio, z)  # later passes reuse them (what the export traces)
        # The authors' own loop, one step (audio rows = its window), the same z replayed.
        loop = reference.generate(model, {model.input_mods[0]: motion.numpy(), model.input_mods[1]: audio.numpy()},
                                  replay={"noise": z.numpy()[None]})["output"]
    if loop.shape != (1, 1, c) or not np.array_equal(loop[0, 0], want.numpy()) or not torch.equal(want, again):
        raise SystemExit(f"the wrapper's step differs from the authors' loop: max |diff| {np.abs(loop[0, 0] - want.numpy()).max()}")

    with torch.no_grad():
        torch.onnx.export(step, (motion, audio, z), args.onnx, input_names=["motion", "audio", "z"],
                          output_names=["frame"], opset_version=17, dynamo=False)
    m = onnx.load(args.onnx, load_external_data=False)
    ops = {}
    for n in m.graph.node:
        ops[n.op_type] = ops.get(n.op_type, 0) + 1
    del m
    drawn = sorted(o for o in ops if o.startswith("Random") or o == "Multinomial")
    if drawn:
        raise SystemExit(f"the graph draws its own noise ({drawn}): z must be its input")

    feed = {"motion": motion.numpy(), "audio": audio.numpy(), "z": z.numpy()}
    thread_counts = [int(t) for t in args.threads.split(",")]
    load = os.getloadavg()[0]
    by_threads = []
    err = None
    for t in thread_counts:
        got, st = time_session(ort, args.onnx, t, feed, args.warmup, args.runs)
        e = float(np.abs(got[0] - want.numpy()).max())
        err = e if err is None else max(err, e)
        by_threads.append(st)
        print(f"onnxruntime f32 t{t}: median {st['median_ms']:.1f} ms  p99 {st['p99_ms']:.1f} ms  (max |ort - torch| {e:.2e})", file=sys.stderr)
    head = by_threads[0]
    out = {
        "family": "transflower",
        "what": "Transflower R step (paper config: input nets, cross-modal net, flow reverse from z; one frame), onnxruntime f32",
        "onnxruntime": ort.__version__,
        "torch": torch.__version__,
        "threads": head["threads"],
        "cpu": cpu_name(),
        "loadavg_1min_before": load,
        "params": n_params,
        "inputs": {"motion": list(motion.shape), "audio": list(audio.shape), "z": list(z.shape)},
        "output": list(want.shape),
        "onnx_ops": dict(sorted(ops.items())),
        "median_ms": head["median_ms"],
        "p99_ms": head["p99_ms"],
        "runs": args.runs,
        "by_threads": by_threads,
        "max_abs_err_vs_torch": err,
        "frame_scale": float(want.abs().max()),
        "torch_equals_authors_loop": True,
    }
    write_json(args.out, out)


if __name__ == "__main__":
    main()
