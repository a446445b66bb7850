#!/usr/bin/env python3
"""eval.json (evaluate.py) -> the markdown tables of docs/DEMO_MODEL.md."""
import json
import sys


def main(path):
    e = json.load(open(path))
    r = e["reconstruction"]
    print("| | value |\n|---|---|")
    print(f"| mean joint position error, pelvis-relative (mm) | {r['joint_mm']:.0f} |")
    print(f"| relative translation error (mm) | {r['transl_mm']:.0f} |")
    print("| codes used (up / down / lhand / rhand / transl, of 128) | "
          + " / ".join(str(r["codes_used"][p]) for p in ("up", "down", "lhand", "rhand", "transl")) + " |")
    print()
    a = e["token_accuracy"]
    print(f"{a['n_tokens']} target tokens per stream ({a['n_windows']} windows).\n")
    print("| stream | model | model, last window position (full context) | most frequent train token | most frequent test token (oracle) | repeat previous token |")
    print("|---|---|---|---|---|---|")
    for s in ("up", "down", "lhand", "rhand", "transl"):
        x = a[s]
        print(f"| {s} | {x['model']:.3f} | {x['model_full_context']:.3f} | {x['most_frequent']:.3f} | "
              f"{x.get('most_frequent_test', float('nan')):.3f} | {x['repeat_previous']:.3f} |")
    print()
    py, rs = e["rollout_python_f32"], e.get("rollout_rust")
    print(f"{py['takes']} takes, {py['frames']} generated frames.\n")
    print("| metric | Python f32 | Rust `generate --mode exact`, f16 .duo | reference |")
    print("|---|---|---|---|")
    g = lambda k, f: (f.format(py[k]), f.format(rs[k]) if rs else "-")
    rows = [
        ("follower root distance to the true follower (mm)", "root_mm", "{:.0f}",
         f"baseline 'leader root + initial offset': {py['root_baseline_mm']:.0f}"),
        ("mean joint position error vs the true follower (mm, world)", "mpjpe_mm", "{:.0f}", ""),
        ("free-running token agreement with the true follower's tokens", "token_agreement_free_running", "{:.3f}", ""),
        ("foot skating ratio", "skate_ratio", "{:.4f}",
         f"true follower {py['skate_ratio_true_follower']:.4f}, leader {py['skate_ratio_leader']:.4f}"),
        ("BED (leader vs follower)", "bed", "{:.3f}",
         f"true follower {py['bed_true_follower']:.3f}; follower of another take (chance) {py['bed_other_take']:.3f}"),
    ]
    for name, k, f, ref in rows:
        a1, a2 = g(k, f)
        print(f"| {name} | {a1} | {a2} | {ref} |")
    if rs:
        print(f"\nRust f16 vs Python f32 tokens: agreement {rs['token_agreement_with_python_f32']:.4f} over every generated token.")


if __name__ == "__main__":
    main(sys.argv[1])
