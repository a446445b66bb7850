#!/usr/bin/env python3
"""Bailando demo: how predictable the VQ token streams are, and the shipping bar's token figures.

  token_stats.py --data DATA --vqvae WORK/vqvae.pt [--synth SYNTH]   # the real dances' token streams
  token_stats.py --eval WORK/eval                               # evaluate.py's generated tokens

Real streams (every dance encoded once, as danced): share of steps where the code changes, mean
run length, distinct codes per take, accuracy of 1/2/3-gram predictors fitted on train and
scored on test (against "repeat the previous code"), t == t-p matches (periodicity), and the
greedy walk of the ideal "next DIFFERENT code" bigram (what a GPT with repeats weighted to 0
could at best do without context): its cycle lengths. Both: distinct up / down codes in the
first 20 s (150 tokens), the largest share of one (up, down) pair in any 10 s (75-token) window.
"""
import argparse
import collections
import json
import os

import numpy as np


def bar(seqs):
    du, dd, mx = [], [], 0.0
    for t in seqs:
        du.append(len(set(t[:150, 0])))
        dd.append(len(set(t[:150, 1])))
        for s in range(0, max(1, len(t) - 75 + 1)):
            w = t[s:s + 75]
            mx = max(mx, collections.Counter(map(tuple, w)).most_common(1)[0][1] / len(w))
    return {"distinct_up_20s": float(np.mean(du)), "distinct_down_20s": float(np.mean(dd)),
            "min_up_20s": int(min(du)), "min_down_20s": int(min(dd)), "max_pair_share_10s": mx}


def predictability(tr, te):
    out = {}
    for s, nm in ((0, "up"), (1, "down")):
        runs = [len(list(g)) for t in tr for _, g in __import__("itertools").groupby(t[:, s])]
        r = {"change_rate": float(np.concatenate([t[1:, s] != t[:-1, s] for t in tr]).mean()),
             "mean_run": float(np.mean(runs)), "distinct_per_take": float(np.mean([len(set(t[:, s])) for t in tr]))}
        for order in (1, 2, 3):
            cnt = collections.defaultdict(collections.Counter)
            for t in tr:
                for i in range(order, len(t)):
                    cnt[tuple(t[i - order:i, s])][t[i, s]] += 1
            hit = n = 0
            for t in te:
                for i in range(order, len(t)):
                    c = cnt.get(tuple(t[i - order:i, s]))
                    hit += (c.most_common(1)[0][0] if c else t[i - 1, s]) == t[i, s]
                    n += 1
            r[f"{order}gram_acc_test"] = hit / n
        r["repeat_prev_test"] = float(np.concatenate([t[1:, s] == t[:-1, s] for t in te]).mean())
        r["match_t_minus_p"] = {p: float(np.concatenate([t[p:, s] == t[:-p, s] for t in tr]).mean()) for p in (1, 2, 4, 8, 16)}
        nxt = collections.defaultdict(collections.Counter)
        for t in tr:
            for a, b in zip(t[:-1, s], t[1:, s]):
                if a != b:
                    nxt[int(a)][int(b)] += 1
        f = {a: c.most_common(1)[0][0] for a, c in nxt.items()}
        cyc, path = [], []
        for x0 in f:
            seen, x = {}, x0
            while x in f and x not in seen:
                seen[x] = len(seen)
                x = f[x]
            if x in seen:
                cyc.append(len(seen) - seen[x])
            path.append(len(seen))
        r["change_bigram_greedy"] = {"top_successor_share": float(np.mean([c.most_common(1)[0][1] / sum(c.values()) for c in nxt.values()])),
                                     "cycle_lengths": dict(collections.Counter(cyc).most_common(4)),
                                     "mean_distinct_on_walk": float(np.mean(path))}
        out[nm] = r
    return out


def beat_lags(names, seqs, synth):
    """Mean of t == t - p per stream at p = one beat and one bar in tokens (7.5 a second), over the
    dances (name = <take>_<dancer>) whose beat is a whole number of tokens."""
    takes = {t["name"]: t for t in json.load(open(os.path.join(synth, "takes.json")))["takes"]}
    out = {"beat": [[], []], "bar": [[], []]}
    for name, t in zip(names, seqs):
        take = takes[name.rsplit("_", 1)[0]]
        beat = 60.0 / take["bpm"] * 7.5
        if abs(beat - round(beat)) > 1e-3:
            continue
        for key, p in (("beat", round(beat)), ("bar", round(beat) * take["beats_per_bar"])):
            for s in (0, 1):
                if len(t) > p:
                    out[key][s].append(float((t[p:, s] == t[:-p, s]).mean()))
    return {"dances": len(out["beat"][0]),
            **{f"{k}_{nm}": (float(np.mean(v[s])) if v[s] else None) for k, v in out.items() for s, nm in ((0, "up"), (1, "down"))}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--vqvae")
    ap.add_argument("--checkout", default="/tmp/bailando")
    ap.add_argument("--eval", help="an evaluate.py --out folder")
    ap.add_argument("--synth", help="the `duolando synth` folder of DATA: adds t == t - p at p = one beat and "
                    "one bar in tokens, over the training dances whose beat is a whole number of tokens "
                    "(`synth --beat-grid-frames 4`)")
    args = ap.parse_args()
    res = {}
    if args.eval:
        raw = os.path.join(args.eval, "raw")
        res["generated"] = bar([np.load(os.path.join(raw, t, "tokens.npy"))[1:] for t in sorted(os.listdir(raw))])
    if args.data and args.vqvae:
        import torch
        import common as C
        from train_gpt import encode
        torch.set_num_threads(1)
        vq, _ = C.build(C.load_authors(args.checkout), train=False)
        vq.load_state_dict(torch.load(args.vqvae, weights_only=False)["model"])
        vq.eval()
        loaded = {sp: C.load_split(args.data, sp) for sp in ("train", "test")}
        sets = {sp: [np.stack(encode(vq, d), 1) for _, d, _ in v] for sp, v in loaded.items()}
        if args.synth:
            res["beat_lags"] = beat_lags([n for n, _, _ in loaded["train"]], sets["train"], args.synth)
        res["real_test_bar"] = bar(sets["test"])
        res["real_streams"] = predictability(sets["train"], sets["test"])
    print(json.dumps(res, indent=1, default=float))


if __name__ == "__main__":
    main()
