"""onnxruntime baseline of the Duolando R step, for `duolando bench --ort-json` (issue #40).

The follower GPT at the published size with seeded random weights (the step of
tools/reference/export_full_r_step.py, which tract times: the 5 heads' logits at the last
position of a 29-token window, LATs included), exported as ONE plain ONNX graph (opset 17, no
rerouted tables: those are a tract workaround), checked against torch, and timed in onnxruntime
(f32, CPU, intra-op threads 1 and 2, one inter-op thread, every graph optimisation). Writes the
JSON `duolando bench --ort-json` reads (family "duolando", `median_ms`/`p99_ms` of the first
thread count, `by_threads`); the bench prints onnxruntime / ours per weight type and thread count.
Timing needs no real weights: onnxruntime's cost does not depend on the values.

    /work/venv/bin/python tools/duolando_ort_r_step.py --out /tmp/ort_duolando.json   # repo root
    cargo run --release -p duolando -- bench --dtypes int8 --ort-json /tmp/ort_duolando.json

`--tiny` builds a small GPT instead (a check of the plumbing in seconds; its times mean nothing).
Needs torch, onnx, onnxruntime (pip); none of them is a dependency of the engine or CI.
"""
import argparse
import os
import sys

import numpy as np
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from tools.reference.export_full_r_step import PUBLISHED, build  # noqa: E402
from tools.ort_timing import add_common_args, cpu_name, time_session, write_json  # noqa: E402

TINY = dict(PUBLISHED, n_embd=64, n_head=4, base_layers=1, head_layers=1, lat_layers=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_common_args(ap, "/tmp/duolando_r_step_ort.onnx", "0.8 GB", runs=20)
    ap.add_argument("--tiny", action="store_true", help="a small GPT: checks the plumbing, times mean nothing")
    ap.add_argument("--reuse-onnx", action="store_true",
                    help="time the --onnx file an earlier run with the same --seed and size exported (the export "
                         "takes minutes); the output is still checked against torch")
    args = ap.parse_args()

    import onnxruntime as ort

    torch.set_num_threads(1)
    structure = TINY if args.tiny else PUBLISHED
    step, inputs, names, want = build(args.seed, structure)
    n_params = sum(p.numel() for p in step.parameters())
    if not (args.reuse_onnx and os.path.exists(args.onnx)):
        with torch.no_grad():
            torch.onnx.export(step, tuple(inputs), args.onnx, input_names=names, output_names=["logits"],
                              opset_version=17, do_constant_folding=True, dynamo=False)
    feed = {n: x.numpy() for n, x in zip(names, inputs)}
    load = os.getloadavg()[0]
    by_threads, err = [], None
    for t in [int(t) for t in args.threads.split(",")]:
        got, st = time_session(ort, args.onnx, t, feed, args.warmup, args.runs)
        e = float(np.abs(got[0] - want.numpy()).max())
        err = e if err is None else max(err, e)
        by_threads.append(st)
        print(f"onnxruntime f32 t{t}: median {st['median_ms']:.1f} ms  p99 {st['p99_ms']:.1f} ms  (max |ort - torch| {e:.2e})",
              file=sys.stderr)
    scale = float(want.abs().max())
    if err > 1e-3 * max(1.0, scale):
        raise SystemExit(f"onnxruntime's logits differ from torch's by {err:.3g} (scale {scale:.3g}): "
                         f"{args.onnx} is not this step (a --reuse-onnx file of another size or seed?)")
    head = by_threads[0]
    write_json(args.out, {
        "family": "duolando",
        "what": "Duolando R step (follower GPT, 29-token window, LATs included, the 5 heads' last logits)"
                + (" TINY GPT: plumbing check only" if args.tiny else ", published size") + ", onnxruntime f32",
        "onnxruntime": ort.__version__,
        "torch": torch.__version__,
        "threads": head["threads"],
        "cpu": cpu_name(),
        "loadavg_1min_before": load,
        "params": n_params,
        "median_ms": head["median_ms"],
        "p99_ms": head["p99_ms"],
        "runs": args.runs,
        "by_threads": by_threads,
        "max_abs_err_vs_torch": err,
        "logit_scale": scale,
    })


if __name__ == "__main__":
    main()
