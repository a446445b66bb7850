#!/usr/bin/env python3
"""Write the Transflower goldens: tests/fixtures/transflower_<case>/, made with the AUTHORS'
classes (guillefix/transflower-lightning, vendored under tools/reference/transflower/authors)
driven by tools/reference/transflower/reference.py (their generation loop, noise recorded).

Deterministic (seeded weights, inputs and sampler; CPU, float32, one thread). Every case is
also replayed from its recorded noise in float64 (tolerance GOLDEN_ATOL on the first step's
flow output, drift of the free run reported in meta.json) and with two threads.

    /work/venv/bin/python tools/make_transflower_fixtures.py [--out tests/fixtures] [--only paper]
    /work/venv/bin/python tools/reference/transflower/check_fixtures.py
"""
import argparse
import json
import os
import shutil
import sys

import numpy as np
import torch
import yaml
from safetensors.torch import save_file

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "reference"))
from transflower import env, reference, tiny  # noqa: E402

GOLDEN_ATOL = 1e-4  # float32 golden vs float64 replay, flow output of step 0 (relative to max(1, |x|))

# case -> (config, weight seed, input seed, sampler seed, motion rows, audio rows, stages, style label)
# steps = audio rows - max(input_lengths) + 1
CASES = {
    "paper": ("paper", 11, 101, 1001, 18, 18, True, None),   # 5 steps; motion rows past the window are ignored
    "label": ("label", 12, 102, 1002, 12, 19, True, 3),      # 6 steps, style label 3 of 5
    "min": ("paper", 13, 103, 1003, 12, 14, False, None),    # shortest input: exactly one step
    "slide": ("real", 14, 104, 1004, 120, 264, False, None),  # 125 steps, real dims/windows: seed leaves the window
}


def make_inputs(model, case):
    cfg, _, in_seed, _, m_rows, a_rows, _, label = CASES[case]
    rng = np.random.default_rng(in_seed)
    inputs = {}
    for i, mod in enumerate(model.input_mods):
        if model.input_types[i] == "d":
            inputs[mod] = np.array([label], dtype=np.int64)
        else:
            rows = a_rows if i == len(model.input_mods) - 1 else m_rows
            inputs[mod] = rng.standard_normal((rows, model.dins[i])).astype(np.float32)
    return inputs


def save_npy(path, arr):
    arr = np.ascontiguousarray(arr)
    assert arr.dtype in (np.float32, np.int64), arr.dtype
    np.save(path, arr.astype(arr.dtype.newbyteorder("<")))


def rel_err(a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float((np.abs(a - b) / np.maximum(1.0, np.abs(b))).max())


def resolved_opt(hp):
    return {k: v for k, v in vars(env.make_opt(hp)).items()}


def make_case(case, out, report):
    cfg_name, w_seed, _, s_seed, _, _, stages, _ = CASES[case]
    hp = tiny.CONFIGS[cfg_name]
    torch.set_num_threads(1)
    model = reference.build(hp, w_seed)
    inputs = make_inputs(model, case)
    res = reference.generate(model, inputs, seed=s_seed, stages=stages)
    state = {k: v.detach().clone().contiguous() for k, v in model.state_dict().items()}

    # replay from the recorded noise: bit-identical (same process, same threads)
    rep = reference.generate(reference.build_from_state(hp, state), inputs, seed=0, replay={"noise": res["noise"]})
    assert np.array_equal(rep["output"], res["output"]), f"{case}: replay differs"
    # two threads
    torch.set_num_threads(2)
    rep2 = reference.generate(reference.build_from_state(hp, state), inputs, seed=0, replay={"noise": res["noise"]})
    torch.set_num_threads(1)
    # float64 (fresh model: InvertibleConv1x1 caches its inverse weight on the first reverse pass)
    with env.float64():
        m64 = reference.build_from_state(hp, {k: v.double() if v.is_floating_point() else v for k, v in state.items()},
                                         dtype=torch.float64)
        r64 = reference.generate(m64, inputs, seed=0, replay={"noise": res["noise"]})
    err0 = rel_err(res["flow_out"][0], r64["flow_out"][0])
    if err0 > GOLDEN_ATOL:
        raise AssertionError(f"{case}: step-0 flow output float32 vs float64 {err0:.3g} > {GOLDEN_ATOL}")
    drift = [rel_err(res["output"][k], r64["output"][k]) for k in range(len(res["output"]))]

    d = os.path.join(out, f"transflower_{case}")
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    with open(os.path.join(d, "config.yaml"), "w") as f:
        yaml.safe_dump(hp, f, sort_keys=False)
    with open(os.path.join(d, "hparams.yaml"), "w") as f:
        yaml.safe_dump(resolved_opt(hp), f, sort_keys=True)
    save_file(state, os.path.join(d, "model.safetensors"))
    for mod, x in inputs.items():
        save_npy(os.path.join(d, f"in_{mod}.npy"), x)
    for k in ("output", "flow_out", "noise", "noise_normal", "noise_chi2_over_df"):
        if k in res:
            save_npy(os.path.join(d, k + ".npy"), res[k])
    if stages:
        st = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in res["stages"].items()}
        save_file(st, os.path.join(d, "stages_step0.safetensors"))

    n_steps = int(res["output"].shape[0])
    il = model.input_lengths
    meta = {
        "case": case, "config": cfg_name, "authors_commit": env.SOURCE_COMMIT,
        "torch": torch.__version__, "numpy": np.__version__,
        "weight_seed": w_seed, "sampler_seed": s_seed, "input_seed": CASES[case][2],
        "input_modalities": model.input_mods, "output_modalities": model.output_mods,
        "input_shapes": {m: list(x.shape) for m, x in inputs.items()},
        "input_lengths": il, "output_lengths": model.output_lengths,
        "output_time_offsets": model.output_time_offsets, "input_time_offsets": model.input_time_offsets,
        "conditioning_seq_lens": model.conditioning_seq_lens,
        "steps": n_steps, "steps_formula": "rows(last input) - max(input_lengths) + 1",
        "window_fully_generated_after_step": il[model.input_mods.index(model.output_mods[0])],
        "base_distribution": type(model.output_mod_glows[0].distribution).__name__,
        "student_t_df": getattr(model.output_mod_glows[0].distribution, "df", None),
        "files": {"output": list(res["output"].shape), "flow_out": list(res["flow_out"].shape),
                  "noise": list(res["noise"].shape)},
        "state_numel": int(sum(v.numel() for v in state.values())),
        "max_abs_output": float(np.abs(res["output"]).max()),
        "replay_bit_identical": True,
        "f32_threads2_vs_threads1_max_rel_err": rel_err(rep2["output"], res["output"]),
        "f32_vs_f64_step0_flow_out_max_rel_err": err0,
        "f32_vs_f64_output_max_rel_err_per_step": drift,
        "tolerance_note": "rel err = |a-b| / max(1,|b|). Per-step drift of the free run (the motion window "
                          "feeds back) grows with the step; compare late steps teacher-forced (rebuild the "
                          "motion window from output.npy) or with a looser bound.",
    }
    if stages:
        meta["stages"] = {k: list(v.shape) for k, v in res["stages"].items()}
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)
    report[case] = {k: meta[k] for k in ("steps", "max_abs_output", "f32_vs_f64_step0_flow_out_max_rel_err",
                                          "f32_threads2_vs_threads1_max_rel_err")}
    report[case]["f32_vs_f64_last_step"] = drift[-1]
    print(f"[{case}] {json.dumps(report[case])}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "fixtures"))
    ap.add_argument("--only", choices=sorted(CASES), action="append")
    args = ap.parse_args()
    torch.set_num_threads(1)
    report = {}
    for case in args.only or list(CASES):
        make_case(case, os.path.normpath(args.out), report)


if __name__ == "__main__":
    main()
