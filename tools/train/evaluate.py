#!/usr/bin/env python3
"""Quality of the demo model on the held-out (test split) synthetic takes, with baselines.

1. Teacher-forced token accuracy per follower stream over training-style windows (stride 4
   tokens), against two trivial baselines: the most frequent train token of the stream, and
   "repeat the previous token".
2. R-mode greedy rollouts (tools/reference/pipeline.py generate_exact, the authors' eval
   window; follower seeded from its first 4 frames) vs the true follower:
   - follower root distance (mm, world, per frame, mean);
   - mean joint position error (mm, world);
   - foot skating ratio (the original utils/metric_footskating_dur.py: a frame counts when the
     pelvis moves > 3 cm/frame horizontally while both ankles move < 1 cm/frame relative to
     the pelvis; ratio over frame differences; our data is y-up, so the horizontal plane is xz);
   - beat-echo degree BED (utils/metrics_duet.py: kinetic velocity = mean joint speed,
     Gaussian smoothing sigma 5, motion beats = strict local minima; for every leader beat
     exp(-d^2 / 18) with d the distance in frames to the nearest follower beat, averaged).
   Baselines: root = leader root + the initial offset held constant; BED of a follower taken
   from another test take (chance level); the true follower's own figures.
3. Issue #41's liveliness targets on the same rollouts: up / down codes used over the test set,
   the largest share of one up / down token in any 10 s window (75 tokens) per take, model and
   true follower (max and mean over takes), and the share of frames whose pelvises (leader and
   follower, 3-D) are closer than 0.25 m, model and true follower, with the smallest distance.
"""
import argparse
import json
import sys

import numpy as np
import torch

from common import (Clock, RATE, build_models, checkpoint_look_forward, load_checkpoint, load_split, setup_threads)
from train_gpt import batch_windows, encode_split, n_windows, window
from reference.pipeline import generate_exact

STREAMS = ("up", "down", "lhand", "rhand", "transl")


def gaussian_filter1d(x, sigma, truncate=4.0):
    """scipy.ndimage.gaussian_filter on a 1-D array (mode 'reflect', truncate 4)."""
    r = int(truncate * sigma + 0.5)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    xp = np.pad(x, r, mode="symmetric")  # scipy 'reflect' = numpy 'symmetric'
    return np.convolve(xp, k, mode="valid")


def motion_beats(pos):
    p = pos.reshape(-1, 55, 3)
    vel = np.mean(np.linalg.norm(p[1:] - p[:-1], axis=2), axis=1)
    v = gaussian_filter1d(vel, 5)
    return np.where((v[1:-1] < v[:-2]) & (v[1:-1] < v[2:]))[0] + 1  # argrelextrema(np.less)


def bed(leader, follower):
    lb, fb = motion_beats(leader), motion_beats(follower)
    if len(lb) == 0 or len(fb) == 0:
        return 0.0
    return float(np.mean([np.exp(-np.min((fb - b) ** 2) / 2 / 9) for b in lb]))


def foot_skating(pos, up_axis=1):
    p = pos.reshape(-1, 55, 3)
    pelvis = p[:, 0].copy()
    l, r = p[:, 7] - pelvis, p[:, 8] - pelvis
    pelvis[:, up_axis] = 0
    pv = np.linalg.norm(np.diff(pelvis, axis=0), axis=1)
    lv = np.linalg.norm(np.diff(l, axis=0), axis=1)
    rv = np.linalg.norm(np.diff(r, axis=0), axis=1)
    n = len(pv)
    dur = int(np.sum((pv[1:] > 0.03) & (lv[1:] < 0.01) & (rv[1:] < 0.01)))  # original loops i = 1..n-1
    return dur, n


@torch.no_grad()
def token_accuracy(gpt, train_tt, test_tt, stride=4):
    bs, lf = gpt.block_size, gpt.look_forward
    freq = [torch.bincount(torch.cat([t["follower"][j] for t in train_tt]), minlength=gpt.cfg.vocab_size_up)
            for j in range(5)]
    mode = [int(f.argmax()) for f in freq]
    tfreq = [torch.bincount(torch.cat([t["follower"][j] for t in test_tt]), minlength=gpt.cfg.vocab_size_up)
             for j in range(5)]
    tmode = [int(f.argmax()) for f in tfreq]  # oracle: the test set's own most frequent token
    hits = np.zeros(5); hits_last = np.zeros(5); base_mode = np.zeros(5); base_rep = np.zeros(5)
    base_tmode = np.zeros(5)
    n = 0; n_last = 0
    for tt in test_tt:
        starts = list(range(0, n_windows(tt, bs, lf), stride))
        for i in range(0, len(starts), 32):
            fin, tgt, music, lead = batch_windows([window(tt, s, bs, lf) for s in starts[i:i + 32]])
            logits = gpt(fin, music, lead)
            for j in range(5):
                pred = logits[j].argmax(-1)
                hits[j] += float((pred == tgt[j]).sum())
                hits_last[j] += float((pred[:, -1] == tgt[j][:, -1]).sum())
                base_mode[j] += float((tgt[j] == mode[j]).sum())
                base_tmode[j] += float((tgt[j] == tmode[j]).sum())
                base_rep[j] += float((fin[j] == tgt[j]).sum())
            n += tgt[0].numel(); n_last += tgt[0].shape[0]
    return {s: dict(model=hits[j] / n, model_full_context=hits_last[j] / n_last,
                    most_frequent=base_mode[j] / n,
                    most_frequent_test=base_tmode[j] / n, repeat_previous=base_rep[j] / n)
            for j, s in enumerate(STREAMS)} | {"n_tokens": n, "n_windows": n_last}


def python_rollout(gpt, vq, tr):
    def run(tk):
        res = generate_exact(gpt, vq, tr, tk["leader"], tk["music"], follower_start=tk["follower"][:4])
        return res["tokens"].numpy(), res["follower_pos3d"].numpy()
    return run


def rust_rollout(binary, duo, stream=()):
    """`duolando generate --mode exact` on the converted model (what ships); with `stream`
    flags, `--mode streaming` with them instead (e.g. `--topk 3 --rng-seed 1`: S mode at the
    reference preset, top-k sampling)."""
    import os
    import subprocess
    import tempfile

    def run(tk):
        with tempfile.TemporaryDirectory() as d:
            for k, a in (("leader", tk["leader"]), ("music", tk["music"]), ("start", tk["follower"][:4])):
                np.save(os.path.join(d, k + ".npy"), np.ascontiguousarray(a, dtype=np.float32))
            subprocess.run([binary, "generate", "--mode", "streaming" if stream else "exact", "--model", duo,
                            "--leader", os.path.join(d, "leader.npy"), "--music", os.path.join(d, "music.npy"),
                            "--follower-start", os.path.join(d, "start.npy"), "--out", os.path.join(d, "out"),
                            *stream],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            return (np.load(os.path.join(d, "out", "tokens.npy")),
                    np.load(os.path.join(d, "out", "follower_pos3d.npy")))
    return run


def rollout_metrics(generate, vq, tr, takes):
    rows = []
    outs = []
    for tk in takes:
        tokens, pred = generate(tk)
        n = len(pred)
        true, lead = tk["follower"][:n], tk["leader"][:n]
        root_d = np.linalg.norm(pred[:, :3] - true[:, :3], axis=1).mean() * 1000
        base = lead[:, :3] + (true[0, :3] - lead[0, :3])
        base_d = np.linalg.norm(base - true[:, :3], axis=1).mean() * 1000
        mpjpe = np.linalg.norm((pred - true).reshape(n, 55, 3), axis=2).mean() * 1000
        outs.append(tokens)
        truth = true_tokens(vq, tr, tk, len(tokens))
        rows.append(dict(name=tk["name"], frames=n, root_mm=root_d, root_baseline_mm=base_d, mpjpe_mm=mpjpe,
                         skate=foot_skating(pred), skate_true=foot_skating(true), skate_leader=foot_skating(lead),
                         bed=bed(lead, pred), bed_true=bed(lead, true),
                         token_agreement=float((tokens[1:] == truth[1:]).mean()),
                         **liveliness(tokens, truth, pred, true, lead)))
    # chance BED: each leader against the true follower of the next test take
    for i, r in enumerate(rows):
        other = takes[(i + 1) % len(takes)]["follower"]
        lead = takes[i]["leader"]
        m = min(len(other), len(lead))
        r["bed_other_take"] = bed(lead[:m], other[:m])
    return rows, outs


WINDOW_TOKENS = 75  # 10 s of rows: 300 frames at 30 fps, 4 frames per token


def max_window_share(seq, w=WINDOW_TOKENS):
    """Largest share of one token in any window of `w` consecutive tokens (the whole
    sequence when shorter): 1.0 = one token held for 10 s."""
    seq = np.asarray(seq)
    w = min(w, len(seq))
    return max(float(np.bincount(seq[i:i + w]).max()) / w for i in range(len(seq) - w + 1))


def liveliness(tokens, truth, pred, true, lead):
    """Issue #41's targets per take: the up and down tokens used, the largest share of one up /
    down token in a 10 s window (model and true follower), and the frames whose pelvises are
    closer than 0.25 m (3-D, model and true follower)."""
    pd = np.linalg.norm(pred[:, :3] - lead[:, :3], axis=1)
    td = np.linalg.norm(true[:, :3] - lead[:, :3], axis=1)
    return dict(used_up=sorted(set(tokens[:, 0].tolist())), used_down=sorted(set(tokens[:, 1].tolist())),
                share10_up=max_window_share(tokens[:, 0]), share10_down=max_window_share(tokens[:, 1]),
                share10_up_true=max_window_share(truth[:, 0]), share10_down_true=max_window_share(truth[:, 1]),
                pelvis_close=[int((pd < 0.25).sum()), len(pd)], pelvis_close_true=[int((td < 0.25).sum()), len(td)],
                pelvis_min_m=float(pd.min()))


@torch.no_grad()
def reconstruction(vq, tr, takes):
    """VQ-VAE round trip on the test takes: mean joint error (mm) of the body (pelvis-relative,
    hands de-normalised), codes used per part, translation error (mm)."""
    from reference.pipeline import encode_motion, encode_transl, normalise_pos3d, denormalise_pos3d, TRANSL_SCALE
    errs, terr, used = [], [], {p: set() for p in ("up", "down", "lhand", "rhand", "transl")}
    for tk in takes:
        for who in ("leader", "follower"):
            norm = normalise_pos3d(torch.from_numpy(tk[who]))
            norm[:, :3] = 0
            codes = encode_motion(vq, norm[None])
            for p, c in zip(("up", "down", "lhand", "rhand"), codes):
                used[p] |= set(c.flatten().tolist())
            pos, _ = vq.decode(codes)
            pos = pos[0]
            pos[:, :3] = 0
            a, b = denormalise_pos3d(pos), denormalise_pos3d(norm)
            errs.append(torch.linalg.norm((a - b).view(-1, 55, 3), dim=-1).mean().item())
        rel = torch.from_numpy((tk["follower"][:, :3] - tk["leader"][:, :3]) * TRANSL_SCALE)
        c = encode_transl(tr, rel[None])
        used["transl"] |= set(c.flatten().tolist())
        out = tr.decode(c)[0]
        terr.append(torch.linalg.norm(out - rel, dim=-1).mean().item() / TRANSL_SCALE)
    return dict(joint_mm=1000 * float(np.mean(errs)), transl_mm=1000 * float(np.mean(terr)),
                codes_used={p: len(u) for p, u in used.items()})


def true_tokens(vq, tr, tk, k):
    from train_gpt import take_tokens
    return take_tokens(vq, tr, tk)["follower"].t().numpy()[:k]


def summarise(rows):
    w = np.array([r["frames"] for r in rows], float)
    avg = lambda key: float(np.average([r[key] for r in rows], weights=w))
    sk = lambda key: sum(r[key][0] for r in rows) / sum(r[key][1] for r in rows)
    return dict(root_mm=avg("root_mm"), root_baseline_mm=avg("root_baseline_mm"), mpjpe_mm=avg("mpjpe_mm"),
                token_agreement_free_running=avg("token_agreement"),
                skate_ratio=sk("skate"), skate_ratio_true_follower=sk("skate_true"),
                skate_ratio_leader=sk("skate_leader"),
                bed=float(np.mean([r["bed"] for r in rows])), bed_true_follower=float(np.mean([r["bed_true"] for r in rows])),
                bed_other_take=float(np.mean([r["bed_other_take"] for r in rows])),
                codes_used_up=len(set().union(*[r["used_up"] for r in rows])),
                codes_used_down=len(set().union(*[r["used_down"] for r in rows])),
                share10_up_max=max(r["share10_up"] for r in rows), share10_down_max=max(r["share10_down"] for r in rows),
                share10_up_mean=float(np.mean([r["share10_up"] for r in rows])),
                share10_down_mean=float(np.mean([r["share10_down"] for r in rows])),
                share10_up_true_mean=float(np.mean([r["share10_up_true"] for r in rows])),
                share10_down_true_mean=float(np.mean([r["share10_down_true"] for r in rows])),
                pelvis_close_ratio=sk("pelvis_close"), pelvis_close_ratio_true=sk("pelvis_close_true"),
                pelvis_min_m=min(r["pelvis_min_m"] for r in rows),
                frames=int(w.sum()), takes=len(rows))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", required=True)
    ap.add_argument("--ckpt", required=True, help="directory with motion_vqvae.pt, transl_vqvae.pt, follower_gpt.pt")
    ap.add_argument("--json", required=True)
    ap.add_argument("--recon-only", action="store_true")
    ap.add_argument("--duo", default=None, help="also roll out this .duo with the Rust CLI")
    ap.add_argument("--bin", default="../../target/release/duolando")
    ap.add_argument("--stream", default=None,
                    help="roll the .duo out in S mode with these `generate` flags (e.g. \"--topk 3 --rng-seed 1\": "
                         "top-k sampling at the reference preset) instead of R mode; the Python rollouts stay R")
    args = ap.parse_args(argv)
    setup_threads()
    clock = Clock()
    gpt, vq, tr = build_models(None if args.recon_only else checkpoint_look_forward(f"{args.ckpt}/follower_gpt.pt"))
    for m, f in ((gpt, "follower_gpt.pt"), (vq, "motion_vqvae.pt"), (tr, "transl_vqvae.pt")):
        if args.recon_only and m is gpt:
            continue
        load_checkpoint(m, f"{args.ckpt}/{f}").eval()
    test = load_split(args.data, "test")
    if args.recon_only:
        print(json.dumps(reconstruction(vq, tr, test)))
        return 0
    train_tt = encode_split(vq, tr, load_split(args.data, "train"))
    test_tt = encode_split(vq, tr, test)
    rec = reconstruction(vq, tr, test)
    print(json.dumps(rec), flush=True)
    acc = token_accuracy(gpt, train_tt, test_tt)
    print(json.dumps(acc, indent=1), flush=True)
    rows, toks_py = rollout_metrics(python_rollout(gpt, vq, tr), vq, tr, test)
    summ = summarise(rows)
    print("python f32 R:", json.dumps(summ, indent=1), flush=True)
    result = dict(reconstruction=rec, token_accuracy=acc, rollout_python_f32=summ, per_take_python=rows)
    if args.duo:
        stream = tuple(args.stream.split()) if args.stream else ()
        rows_rs, toks_rs = rollout_metrics(rust_rollout(args.bin, args.duo, stream), vq, tr, test)
        summ_rs = summarise(rows_rs)
        same = [float(np.mean(a == b)) for a, b in zip(toks_py, toks_rs)]
        summ_rs["token_agreement_with_python_f32"] = float(np.mean(same))
        summ_rs["mode"] = "streaming " + " ".join(stream) if stream else "exact"
        print("rust R (" + args.duo + "):", json.dumps(summ_rs, indent=1), flush=True)
        result.update(rollout_rust=summ_rs, per_take_rust=rows_rs)
    with open(args.json, "w") as f:
        json.dump(result, f, indent=1, default=float)
    print(f"[eval] {clock}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
