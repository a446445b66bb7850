"""Helpers shared by the onnxruntime baselines of `duolando bench --ort-json`
(tools/{duolando,bailando,transflower}_ort_r_step.py): their common arguments, the CPU's
name, one onnxruntime session timed on N intra-op threads, and the JSON the bench reads."""
import json
import platform
import statistics
import time


def add_common_args(ap, onnx, size, runs, threads=True):
    """The arguments every baseline script takes: --onnx (default `onnx`, about `size` on
    disk), --out, --runs (default `runs`), --warmup; with `threads`, also --threads and --seed."""
    ap.add_argument("--onnx", default=onnx, help=f"where the exported step goes (~{size})")
    ap.add_argument("--out", required=True, help="JSON with the timing, for `bench --ort-json`")
    ap.add_argument("--runs", type=int, default=runs)
    ap.add_argument("--warmup", type=int, default=3)
    if threads:
        ap.add_argument("--threads", default="1,2",
                        help="onnxruntime intra-op thread counts to time (the first is the headline)")
        ap.add_argument("--seed", type=int, default=0)


def cpu_name():
    """The CPU model as /proc/cpuinfo names it (what the bench prints beside its own figures)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def time_session(ort, path, threads, feed, warmup, runs):
    """Runs the ONNX graph at `path` in onnxruntime (CPU, `threads` intra-op threads, one
    inter-op thread, every graph optimisation) `warmup + runs` times on `feed`; returns its
    outputs and {threads, median_ms, p99_ms, min_ms, runs} of the timed runs."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    sess = ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])
    got = sess.run(None, feed)
    times = []
    for i in range(warmup + runs):
        t0 = time.perf_counter()
        sess.run(None, feed)
        if i >= warmup:
            times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    p99 = times[min(len(times) - 1, int(round(0.99 * (len(times) - 1))))]
    return got, {"threads": threads, "median_ms": statistics.median(times), "p99_ms": p99,
                 "min_ms": times[0], "runs": runs}


def write_json(path, out):
    """Writes the bench's JSON to `path` and prints it."""
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    print(json.dumps(out, indent=1))
