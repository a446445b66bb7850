#!/usr/bin/env python3
"""Quality against latency, both ways: the 29-token follower cut to a streaming budget, and
followers trained for that look-ahead (`train_gpt.py --look-forward L`), scored against the
TRUE follower on the held-out (test split) synthetic takes. docs/DEMO_MODEL.md "Latency chosen
at training time" has the figures of the demo recipe.

    python latency_curve.py --data /tmp/lat_synth --bin /work/bin/duolando --out /tmp/lat_eval \\
        --model29 /tmp/lat_work/lf29/demo.duo --trained 4=/tmp/lat_work/lf4/demo.duo \\
        --trained 1=/tmp/lat_work/lf1/demo.duo --trained 8=/tmp/lat_work/lf8/demo.duo \\
        --lookaheads 1,4,8 --json /tmp/lat_eval/latency.json

Rows (every one through `duolando generate`, greedy, follower seeded from its first 4 frames):
- `29 R`: the 29-token model in R mode (offline; the authors' evaluation).
- `29 S reference`: the 29-token model in S mode at the reference preset (a 29, e = d = 22).
- `29 S cut a`: the 29-token model in S mode at leader look-ahead a with the interactive
  preset's conv futures (--enc-future E --dec-future D, default 2 / 2) and the music known
  ahead (music look-ahead = its look_forward, 29: the preset's setting for a music track).
- `29 S cut a, music a`: the same with the music look-ahead cut to a as well (what a model
  trained for a has).
- `L S`: the model trained for L in S mode at look-ahead L, same E / D, music look-ahead L
  (its look_forward; nothing more is possible).
- `L R`: the model trained for L in R mode (offline).
S mode drains (the default), so every S row outputs its model's R frame count; all figures are
taken over the frames every row has (per take the shortest output, i.e. the 29-token model's
R count: the last 29 tokens of each take have no follower), so every row scores the same
frames. Latency (frames) is the one `generate` prints for S (hop * (a + e + d) - 1).

Figures per row, against the true follower of each take: follower root distance (mm, world,
frame mean), mean joint position error (mm, world), the constant-offset root baseline, foot
skating and BED as tools/train/evaluate.py computes them, and `duolando eval`'s paper metrics
(FID_k, FID_g, FID_cd, Div_k, Div_g, Div_cd, BED, BAS, fsr) with the same reference statistics
for every row: the true held-out duets over the same frames (`--save-real` once, then
`--real-stats`).
"""
import argparse
import json
import os
import re
import subprocess
import sys
import time

import numpy as np

from common import load_split
from evaluate import bed, foot_skating


def run_generate(binary, duo, d, mode_args):
    t0 = time.time()
    p = subprocess.run([binary, "generate", "--model", duo, "--leader", os.path.join(d, "leader.npy"),
                        "--music", os.path.join(d, "music.npy"), "--follower-start", os.path.join(d, "start.npy"),
                        "--threads", "1", "--out", os.path.join(d, "out"), *mode_args],
                       check=True, capture_output=True, text=True)
    lat = re.search(r"latency (\d+) frames", p.stderr + p.stdout)
    return (np.load(os.path.join(d, "out", "follower_pos3d.npy")), int(lat.group(1)) if lat else None,
            time.time() - t0)


def rows_spec(args):
    e, dd = str(args.enc_future), str(args.dec_future)
    spec = [("29 R", args.model29, 29, None, ["--mode", "exact"]),
            ("29 S reference", args.model29, 29, 29, ["--mode", "streaming", "--preset", "reference"])]
    trained = {}
    for t in args.trained:
        l, path = t.split("=", 1)
        trained[int(l)] = path
    for a in args.lookaheads:
        spec.append((f"29 S cut {a}", args.model29, 29, a,
                     ["--mode", "streaming", "--preset", "interactive", "--lookahead", str(a), "--enc-future", e,
                      "--dec-future", dd, "--music-lookahead", "29"]))
        spec.append((f"29 S cut {a}, music {a}", args.model29, 29, a,
                     ["--mode", "streaming", "--preset", "interactive", "--lookahead", str(a), "--enc-future", e,
                      "--dec-future", dd, "--music-lookahead", str(a)]))
    for l in sorted(trained):
        spec.append((f"{l} S", trained[l], l, l,
                     ["--mode", "streaming", "--preset", "interactive", "--lookahead", str(l), "--enc-future", e,
                      "--dec-future", dd, "--music-lookahead", str(l)]))
        spec.append((f"{l} R", trained[l], l, None, ["--mode", "exact"]))
    if args.sample:
        # every S row samples (R is greedy by definition: `generate --mode exact` refuses --topk)
        spec = [(lab, m, lf, a, mode + args.sample.split() if "streaming" in mode else mode)
                for lab, m, lf, a, mode in spec]
    return spec


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True, help="`duolando synth` output (the recipe's data)")
    ap.add_argument("--bin", required=True)
    ap.add_argument("--out", required=True, help="scratch folder (per-row motions for `duolando eval`)")
    ap.add_argument("--model29", required=True, help="the .duo trained with look_forward 29")
    ap.add_argument("--trained", action="append", default=[], help="L=PATH.duo, a model trained with look_forward L")
    ap.add_argument("--lookaheads", default="1,4,8")
    ap.add_argument("--enc-future", type=int, default=2)
    ap.add_argument("--dec-future", type=int, default=2)
    ap.add_argument("--sample", default=None,
                    help="extra `generate` flags for every S row, e.g. \"--topk 3 --rng-seed 1\" (top-k sampling)")
    ap.add_argument("--only", default=None, help="comma-separated row labels to run (default: all)")
    ap.add_argument("--json", required=True)
    ap.add_argument("--table", action="store_true", help="only print the markdown table of an existing --json")
    ap.add_argument("--svg", default=None, help="also write the curves (joint error, root error) as SVG: PREFIX_joint.svg, PREFIX_root.svg")
    args = ap.parse_args(argv)
    if args.table:
        with open(args.json) as f:
            res = json.load(f)
        print(markdown(res))
        write_svgs(res, args.svg)
        return 0
    args.lookaheads = [int(a) for a in args.lookaheads.split(",") if a]
    spec = rows_spec(args)
    if args.only:
        keep = set(args.only.split(";"))
        spec = [r for r in spec if r[0] in keep]
    test = load_split(args.data, "test")
    os.makedirs(args.out, exist_ok=True)
    gens = {}
    lats, secs = {}, {}
    for tk in test:
        d = os.path.join(args.out, "in", tk["name"])
        os.makedirs(d, exist_ok=True)
        for k, a in (("leader", tk["leader"]), ("music", tk["music"]), ("start", tk["follower"][:4])):
            np.save(os.path.join(d, k + ".npy"), np.ascontiguousarray(a, dtype=np.float32))
        for label, duo, lf, a, mode_args in spec:
            pos, lat, sec = run_generate(args.bin, duo, d, mode_args)
            gens.setdefault(label, {})[tk["name"]] = pos
            lats[label] = lat
            secs[label] = secs.get(label, 0.0) + sec
        print(f"[latency] {tk['name']}: " + ", ".join(f"{lab} {len(gens[lab][tk['name']])}" for lab, *_ in spec),
              flush=True)
    # the frames every row has, per take
    common = {tk["name"]: min(len(gens[lab][tk["name"]]) for lab, *_ in spec) for tk in test}
    # reference statistics: the true held-out duets over the same frames, computed once
    real = os.path.join(args.out, "real")
    mus = os.path.join(args.out, "music")
    os.makedirs(real, exist_ok=True)
    os.makedirs(mus, exist_ok=True)
    for tk in test:
        n = common[tk["name"]]
        np.save(os.path.join(real, tk["name"] + "_00.npy"), tk["follower"][:n])
        np.save(os.path.join(real, tk["name"] + "_01.npy"), tk["leader"][:n])
        np.save(os.path.join(mus, tk["name"] + ".npy"), tk["music"][:n])
    stats = os.path.join(args.out, "real_stats.json")
    subprocess.run([args.bin, "eval", "--gen", real, "--real", real, "--music", mus, "--save-real", stats,
                    "--json", os.path.join(args.out, "eval_true_follower.json")],
                   check=True, capture_output=True, text=True)
    with open(os.path.join(args.out, "eval_true_follower.json")) as f:
        true_eval = json.load(f)
    result = dict(common_frames=int(sum(common.values())), takes=len(test), enc_future=args.enc_future,
                  dec_future=args.dec_future, true_follower_eval=true_eval, rows=[])
    for label, duo, lf, a, mode_args in spec:
        gdir = os.path.join(args.out, "gen", label.replace(" ", "_").replace(",", ""))
        os.makedirs(gdir, exist_ok=True)
        root, mpj, base, skate, beds, w = [], [], [], [0, 0], [], []
        for tk in test:
            n = common[tk["name"]]
            pred = gens[label][tk["name"]][:n]
            true, lead = tk["follower"][:n], tk["leader"][:n]
            root.append(np.linalg.norm(pred[:, :3] - true[:, :3], axis=1).mean() * 1000)
            b = lead[:, :3] + (true[0, :3] - lead[0, :3])
            base.append(np.linalg.norm(b - true[:, :3], axis=1).mean() * 1000)
            mpj.append(np.linalg.norm((pred - true).reshape(n, 55, 3), axis=2).mean() * 1000)
            s = foot_skating(pred)
            skate = [skate[0] + s[0], skate[1] + s[1]]
            beds.append(bed(lead, pred))
            w.append(n)
            np.save(os.path.join(gdir, tk["name"] + "_00.npy"), pred.astype(np.float32))
            np.save(os.path.join(gdir, tk["name"] + "_01.npy"), lead.astype(np.float32))
        ej = os.path.join(gdir, "eval.json")
        subprocess.run([args.bin, "eval", "--gen", gdir, "--real-stats", stats, "--music", mus, "--json", ej],
                       check=True, capture_output=True, text=True)
        with open(ej) as f:
            ev = json.load(f)
        row = dict(label=label, model=duo, look_forward=lf, lookahead=a, args=" ".join(mode_args),
                   latency_frames=lats[label], latency_s=None if lats[label] is None else lats[label] / 30,
                   root_mm=float(np.average(root, weights=w)), root_baseline_mm=float(np.average(base, weights=w)),
                   mpjpe_mm=float(np.average(mpj, weights=w)), skate_ratio=skate[0] / skate[1],
                   bed_ours=float(np.mean(beds)), generate_wall_s=secs[label], eval=ev,
                   per_take={tk["name"]: dict(frames=n_, root_mm=float(r_), mpjpe_mm=float(m_))
                             for tk, n_, r_, m_ in zip(test, w, root, mpj)})
        result["rows"].append(row)
        print(f"[latency] {label}: latency {row['latency_frames']} root {row['root_mm']:.0f} mm "
              f"mpjpe {row['mpjpe_mm']:.0f} mm | " + " ".join(f"{k} {v:.4g}" for k, v in ev.items()
                                                           if isinstance(v, (int, float))), flush=True)
    with open(args.json, "w") as f:
        json.dump(result, f, indent=1, default=float)
    print(markdown(result))
    write_svgs(result, args.svg)
    return 0


def write_svgs(result, prefix):
    if not prefix:
        return
    with open(prefix + "_joint.svg", "w") as f:
        f.write(svg(result))
    with open(prefix + "_root.svg", "w") as f:
        f.write(svg(result, "root_mm", "follower root distance to the true follower (mm)"))


def svg(result, key="mpjpe_mm", title="mean joint position error vs the true follower (mm)"):
    """A small line chart (text SVG): quality against latency, the cut 29-token model and the
    models trained for each look-ahead."""
    rows = [r for r in result["rows"] if r["latency_frames"] is not None]
    series = {"29-token model cut (music known ahead)": [r for r in rows if r["look_forward"] == 29
                                                        and "music" not in r["label"]],
              "29-token model cut (music cut too)": [r for r in rows if r["look_forward"] == 29
                                                    and "music" in r["label"]],
              "trained for the look-ahead": [r for r in rows if r["look_forward"] != 29]}
    colours = ["#1f77b4", "#9ecae1", "#d62728"]
    xs = [r["latency_s"] for r in rows]
    ys = [r[key] for r in rows]
    W, H, L, B = 560, 320, 60, 40
    x0, x1 = 0.0, max(xs) * 1.05
    y0, y1 = min(ys) * 0.95, max(ys) * 1.05
    X = lambda x: L + (x - x0) / (x1 - x0) * (W - L - 20)
    Y = lambda y: H - B - (y - y0) / (y1 - y0) * (H - B - 30)
    o = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="11">',
         f'<rect width="{W}" height="{H}" fill="white"/>', f'<text x="{L}" y="16">{title}</text>',
         f'<line x1="{L}" y1="{H - B}" x2="{W - 20}" y2="{H - B}" stroke="black"/>',
         f'<line x1="{L}" y1="{H - B}" x2="{L}" y2="30" stroke="black"/>',
         f'<text x="{W / 2 - 80}" y="{H - 8}">latency (s; S mode, e = d = {result["enc_future"]}/{result["dec_future"]})</text>']
    for k in range(6):
        y = y0 + (y1 - y0) * k / 5
        o.append(f'<text x="{L - 6}" y="{Y(y) + 4:.1f}" text-anchor="end">{y:.0f}</text>')
        o.append(f'<line x1="{L}" y1="{Y(y):.1f}" x2="{W - 20}" y2="{Y(y):.1f}" stroke="#eee"/>')
    for x in sorted(set(round(v, 2) for v in xs)):
        o.append(f'<text x="{X(x):.1f}" y="{H - B + 14}" text-anchor="middle">{x:g}</text>')
    for i, (name, rs) in enumerate(series.items()):
        rs = sorted(rs, key=lambda r: r["latency_s"])
        if not rs:
            continue
        pts = " ".join(f"{X(r['latency_s']):.1f},{Y(r[key]):.1f}" for r in rs)
        o.append(f'<polyline points="{pts}" fill="none" stroke="{colours[i]}" stroke-width="2"/>')
        for r in rs:
            o.append(f'<circle cx="{X(r["latency_s"]):.1f}" cy="{Y(r[key]):.1f}" r="3.5" fill="{colours[i]}">'
                     f'<title>{r["label"]}: {r[key]:.0f}</title></circle>')
        o.append(f'<rect x="{W - 250}" y="{34 + 16 * i}" width="12" height="3" fill="{colours[i]}"/>'
                 f'<text x="{W - 234}" y="{39 + 16 * i}">{name}</text>')
    o.append("</svg>")
    return "\n".join(o) + "\n"


def paired(result):
    """Per look-ahead a: the model trained for a against the 29-token model cut to a (music
    known ahead, and music cut to a), take by take (frame-weighted means; takes where the
    trained model is closer to the true follower)."""
    rows = {r["label"]: r for r in result["rows"]}
    out = ["| a | compared with | root mm: trained - cut | takes trained closer (root) | "
           "joint mm: trained - cut | takes trained closer (joint) |", "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        if r["look_forward"] == 29 or r["lookahead"] is None:
            continue
        a = r["lookahead"]
        for other in (f"29 S cut {a}", f"29 S cut {a}, music {a}"):
            if other not in rows:
                continue
            o = rows[other]
            names = sorted(r["per_take"])
            w = np.array([r["per_take"][n]["frames"] for n in names], float)
            dr = np.array([r["per_take"][n]["root_mm"] - o["per_take"][n]["root_mm"] for n in names])
            dm = np.array([r["per_take"][n]["mpjpe_mm"] - o["per_take"][n]["mpjpe_mm"] for n in names])
            out.append(f"| {a} | {other} | {np.average(dr, weights=w):+.0f} | {int((dr < 0).sum())} of {len(names)} | "
                       f"{np.average(dm, weights=w):+.0f} | {int((dm < 0).sum())} of {len(names)} |")
    return out


def markdown(result):
    """The table of docs/DEMO_MODEL.md from a result JSON (`--table FILE` prints it again)."""
    t = result["true_follower_eval"]
    out = ["| row | trained look_forward | leader look-ahead a | latency frames (s) | root mm | joint mm | "
           "FID_k | Div_k | FID_cd | Div_cd | BED | BAS | fsr_00 % | FID_g |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        e = r["eval"]
        lat = "offline" if r["latency_frames"] is None else f"{r['latency_frames']} ({r['latency_s']:.2f})"
        out.append(f"| {r['label']} | {r['look_forward']} | {'-' if r['lookahead'] is None else r['lookahead']} | {lat} | "
                   f"{r['root_mm']:.0f} | {r['mpjpe_mm']:.0f} | {e['fid_k']:.1f} | {e['div_k']:.2f} | {e['fid_cd']:.0f} | "
                   f"{e['div_cd']:.1f} | {e['bed']:.3f} | {e['bas']:.3f} | {e['fsr_00']:.2f} | {e['fid_g']:.2g} |")
    base = result["rows"][0]["root_baseline_mm"]
    out.append(f"| true follower | | | | 0 | 0 | 0 | {t['div_k']:.2f} | 0 | {t['div_cd']:.1f} | {t['bed']:.3f} | "
               f"{t['bas']:.3f} | {t['fsr_00']:.2f} | 0 |")
    out.append(f"\n{result['takes']} takes, {result['common_frames']} frames scored per row; "
               f"constant-offset root baseline {base:.0f} mm.\n")
    out.extend(paired(result))
    return "\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
