#!/usr/bin/env python3
"""Train a SMALL Transflower (the paper config's structure, sized down) on CPU with the
AUTHORS' classes (tools/reference/transflower/authors, built through env.py) and their loss.

    nice -n 5 /work/venv/bin/python tools/train/transflower/train.py \
        --data /work/tfdata/prep --out runs/tf_demo --minutes 25 --threads 2 [--seed 0]

Reads the prepared data (tools/train/transflower/README.md "## Data"):
  DATA/{train,test}/<take>_00.motion.npy, <take>_01.motion.npy  (T, 69) unscaled, 20 fps
  DATA/{train,test}/<take>.audio.npy                            (Ta, 85) unscaled, 20 fps
  DATA/motion_scaler.json, DATA/audio_scaler.json               z = (x - mean) / scale
Each dancer of a take is one sequence (motion) sharing the take's audio; rows beyond the
shorter of the two are dropped.

Model: `TransflowerModel(opt)` of the authors, opt = their option defaults + the hparams
below (env.make_opt, as inference/generate.py): inputs motion (69) + audio (85), windows
120 / 140 rows, output_time_offsets 120, output_lengths 3, cond = the first 3 rows of the
cross-modal transformer, a single-scale flow of `--flow-blocks` x [BatchNorm (the authors'),
LU 1x1 conv, affine coupling with a transformer net (channel concat, zero `pe` buffer)],
Gaussian base: transflower_expmap.yaml with dhid / nlayers / nhead / 16 steps / dhid_flow /
num_heads_flow replaced by the options. Windows can be changed (--motion-window,
--audio-window: the engine accepts any length <= 4096; output_time_offsets = the motion
window as in the paper).

Loss: the model's own `training_step(batch)` (the flow's negative log-likelihood,
`FlowPlusPlus.loss_generative`: -mean(log p(x)) / (ln 2 * output_lengths) = bits per frame,
summed over the 69 channels) on random windows (uniform over every window of every training
sequence, as `MultimodalDataset`). The first training-mode forward initialises the flow's
norm layers from the data (BatchNorm copies the batch moments into running_mean /
running_var, `is_initialized` -> 1; ActNorm sets mean / inv_std): it is run once on
`--init-batch` windows without a gradient step. Every later training-mode forward updates
BatchNorm's running statistics with momentum `glow_bn_momentum` (0.1) and then uses them
(the authors' BatchNorm has no per-batch normalisation); eval mode freezes them.

Optimiser: AdamW (decay on weight matrices only), linear warm-up then cosine decay to
`--min-lr-ratio`, gradient-norm clipping 0.5 (the YAML's gradient_clip_val). With
`--minutes` the step count is calibrated from the first steps and the evaluation time
(printed as `steps N`) and re-fitted to the remaining time at every evaluation (printed as
`steps N -> M`: the machine's speed changes with other jobs), so such a run depends on the
timing; `--steps N` (with a large enough `--minutes`) is reproducible exactly for a seed and
thread count.

Writes OUT/: model.safetensors (best held-out NLL; the authors' state-dict names, buffers
included, as tools/transflower_ckpt_to_safetensors.py writes), hparams.yaml (every option
resolved as generate.py resolves them, flat key: value, as the fixtures' hparams.yaml),
last.safetensors (the final state), log.jsonl (one line per evaluation), run.json
(arguments, parameter count, steps, timings, best).

Smoke test data: `train.py --make-fake DIR` writes random takes in the same layout.
"""
import argparse
import copy
import glob
import json
import math
import os
import struct
import sys
import time

import warnings

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "tools", "reference"))
from transflower import env  # noqa: E402  (tools/reference/transflower/env.py)

# the authors' construction warns about torch API choices (nested tensors, weight_norm): noise here
warnings.filterwarnings("ignore", message=".*enable_nested_tensor.*")
warnings.filterwarnings("ignore", message=".*weight_norm.*")

MOTION = "expmap_scaled_20"        # the paper config's modality names (the engine keeps them)
AUDIO = "audio_feats_scaled_20"
MOTION_DIM, AUDIO_DIM = 69, 85


# ----------------------------------------------------------------------------- config

def hparams(a):
    """The authors' option keys (transflower_expmap.yaml), sized by the command line."""
    return {
        "model": "transflower",
        "dins": f"{MOTION_DIM},{AUDIO_DIM}",
        "douts": f"{MOTION_DIM}",
        "input_modalities": f"{MOTION},{AUDIO}",
        "output_modalities": MOTION,
        "input_lengths": f"{a.motion_window},{a.audio_window}",
        "output_lengths": a.output_lengths,
        "output_time_offsets": a.motion_window,
        "nlayers": a.layers,
        "nhead": a.heads,
        "scales": f"[[{a.flow_blocks},0]]",
        "num_glow_coupling_blocks": a.coupling_layers,
        "glow_use_attn": True,
        "use_transformer_nn": True,
        "use_pos_emb_coupling": True,
        "use_rel_pos_emb_inputs": bool(a.rel_pos_emb_inputs),
        "dhid": a.dhid,
        "dhid_flow": a.dhid_flow,
        "num_heads_flow": a.heads_flow,
        "cond_concat_dims": True,
        "glow_norm_layer": "batchnorm",
        "glow_bn_momentum": 0.1,
        "dropout": 0,
    }


def resolved_hparams(hp):
    """What a checkpoint directory's hparams.yaml holds: the options as generate.py resolves
    them (defaults + hparams), as tools/make_transflower_fixtures.py writes them."""
    return dict(vars(env.make_opt(hp)))


def write_hparams_yaml(hp, path):
    import yaml
    with open(path, "w") as f:
        yaml.safe_dump(resolved_hparams(hp), f, sort_keys=True)


# ----------------------------------------------------------------------------- safetensors

_ST_DTYPES = {torch.float32: "F32", torch.float16: "F16", torch.float64: "F64", torch.int64: "I64",
              torch.int32: "I32", torch.bool: "BOOL", torch.uint8: "U8"}


def save_safetensors(state, path):
    """safetensors.torch.save_file when installed, else the same format written here
    (8-byte little-endian header length, JSON header sorted by name, raw little-endian data)."""
    tensors = {k: v.detach().contiguous().clone().cpu() for k, v in state.items()}
    tmp = path + ".tmp"
    try:
        from safetensors.torch import save_file
        save_file(tensors, tmp)
    except ImportError:
        header, blobs, off = {}, [], 0
        for k in sorted(tensors):
            t = tensors[k]
            b = t.numpy().tobytes() if t.dtype != torch.bool else t.to(torch.uint8).numpy().tobytes()
            header[k] = {"dtype": _ST_DTYPES[t.dtype], "shape": list(t.shape), "data_offsets": [off, off + len(b)]}
            blobs.append(b)
            off += len(b)
        h = json.dumps(header, separators=(",", ":")).encode()
        h += b" " * ((8 - len(h) % 8) % 8)
        with open(tmp, "wb") as f:
            f.write(struct.pack("<Q", len(h)))
            f.write(h)
            for b in blobs:
                f.write(b)
    os.replace(tmp, path)


def load_safetensors(path):
    """name -> torch tensor (safetensors when installed, else the format read here)."""
    try:
        from safetensors.torch import load_file
        return load_file(path)
    except ImportError:
        inv = {v: k for k, v in _ST_DTYPES.items()}
        with open(path, "rb") as f:
            n = struct.unpack("<Q", f.read(8))[0]
            header = json.loads(f.read(n))
            data = f.read()
        out = {}
        for k, m in header.items():
            if k == "__metadata__":
                continue
            s, e = m["data_offsets"]
            dt = inv[m["dtype"]]
            np_dt = {torch.bool: np.uint8}.get(dt, torch.empty(0, dtype=dt).numpy().dtype)
            arr = np.frombuffer(data[s:e], dtype=np_dt).reshape(m["shape"]).copy()
            out[k] = torch.from_numpy(arr).to(dt)
        return out


# ----------------------------------------------------------------------------- data

def read_scaler(path, width):
    with open(path) as f:
        s = json.load(f)
    if s.get("format") != "duolando-transflower-scaler" or int(s.get("width", -1)) != width:
        raise ValueError(f"{path}: not a duolando-transflower-scaler of width {width}")
    mean = np.asarray(s["mean"], dtype=np.float64)
    scale = np.asarray(s["scale"], dtype=np.float64)
    if mean.shape != (width,) or scale.shape != (width,) or not np.all(scale > 0):
        raise ValueError(f"{path}: bad mean/scale")
    return mean, scale


def scale_rows(x, scaler):
    mean, scale = scaler
    return ((x.astype(np.float64) - mean) / scale).astype(np.float32)


def load_split(data, split, mscaler, ascaler, min_rows):
    """[(name, motion_z (T, 69), audio_z (T, 85))], both dancers of every take, rows cut to
    the shorter of motion and audio; sequences shorter than `min_rows` are skipped."""
    seqs, skipped = [], []
    for mpath in sorted(glob.glob(os.path.join(data, split, "*.motion.npy"))):
        name = os.path.basename(mpath)[: -len(".motion.npy")]
        take = name.rsplit("_", 1)[0]
        apath = os.path.join(data, split, take + ".audio.npy")
        m = np.load(mpath)
        a = np.load(apath)
        if m.ndim != 2 or m.shape[1] != MOTION_DIM or a.ndim != 2 or a.shape[1] != AUDIO_DIM:
            raise ValueError(f"{mpath} {m.shape} / {apath} {a.shape}: expected (T, {MOTION_DIM}) / (T, {AUDIO_DIM})")
        n = min(len(m), len(a))
        if n < min_rows:
            skipped.append(name)
            continue
        mz, az = scale_rows(m[:n], mscaler), scale_rows(a[:n], ascaler)
        if not (np.isfinite(mz).all() and np.isfinite(az).all()):
            raise ValueError(f"{name}: non-finite features")
        seqs.append((name, mz, az))
    return seqs, skipped


class Windows:
    """Every training window of every sequence, drawn uniformly (MultimodalDataset.__getitem__:
    input i = rows [idx, idx + L_i), target = rows [idx + offset, idx + offset + H))."""

    def __init__(self, seqs, lm, la, off, h):
        self.seqs, self.lm, self.la, self.off, self.h = seqs, lm, la, off, h
        need = max(lm, la, off + h)
        self.counts = np.array([len(s[1]) - need + 1 for s in seqs], dtype=np.int64)
        assert (self.counts > 0).all()
        self.cum = np.cumsum(self.counts)
        self.total = int(self.cum[-1])

    def batch(self, items):
        ms, as_, ts = [], [], []
        for it in items:
            k = int(np.searchsorted(self.cum, it, side="right"))
            idx = int(it - (self.cum[k - 1] if k else 0))
            _, m, a = self.seqs[k]
            ms.append(m[idx: idx + self.lm])
            as_.append(a[idx: idx + self.la])
            ts.append(m[idx + self.off: idx + self.off + self.h])
        return {"in_" + MOTION: torch.from_numpy(np.stack(ms)),
                "in_" + AUDIO: torch.from_numpy(np.stack(as_)),
                "out_" + MOTION: torch.from_numpy(np.stack(ts))}


def make_fake(out, seed=0, train_takes=6, test_takes=2, rows=(700, 1100)):
    """Random takes in the prepared layout (smooth random motion, noisy audio) + scalers."""
    rng = np.random.default_rng(seed)
    allm, alla = [], []
    for split, n in (("train", train_takes), ("test", test_takes)):
        os.makedirs(os.path.join(out, split), exist_ok=True)
        for t in range(n):
            take = f"fake{split}{t:02d}"
            T = int(rng.integers(*rows))
            a = rng.normal(size=(T + int(rng.integers(0, 5)), AUDIO_DIM)).astype(np.float32) * 3 - 20
            np.save(os.path.join(out, split, take + ".audio.npy"), a)
            alla.append(a)
            for d in range(2):
                w = rng.normal(size=(T, MOTION_DIM)).cumsum(0)
                k = np.ones(15) / 15
                w = np.stack([np.convolve(w[:, c], k, mode="same") for c in range(MOTION_DIM)], 1)
                m = (0.05 * w + rng.normal(size=(1, MOTION_DIM))).astype(np.float32)
                np.save(os.path.join(out, split, f"{take}_{d:02d}.motion.npy"), m)
                allm.append(m)
    for name, arrs, w in (("motion_scaler.json", allm, MOTION_DIM), ("audio_scaler.json", alla, AUDIO_DIM)):
        x = np.concatenate(arrs).astype(np.float64)
        sd = x.std(0)
        sd[sd == 0] = 1.0
        with open(os.path.join(out, name), "w") as f:
            json.dump({"format": "duolando-transflower-scaler", "version": 1, "source": "fake", "width": w,
                       "with_mean": True, "with_std": True, "mean": x.mean(0).tolist(), "scale": sd.tolist(),
                       "var": (sd ** 2).tolist(), "n_samples_seen": len(x)}, f)
    with open(os.path.join(out, "manifest.json"), "w") as f:
        json.dump({"fake": True, "seed": seed}, f)
    print(f"fake data in {out}: {train_takes} train takes, {test_takes} test takes")


# ----------------------------------------------------------------------------- training

def lr_at(step, a, total):
    """Linear warm-up over `--warmup` steps, then cosine from lr to lr * min_lr_ratio at `total`."""
    if step < a.warmup:
        return a.lr * (step + 1) / a.warmup
    p = min(1.0, (step - a.warmup) / max(1, total - a.warmup))
    return a.lr * (a.min_lr_ratio + (1 - a.min_lr_ratio) * 0.5 * (1 + math.cos(math.pi * p)))


def evaluate(model, batches):
    """Mean of the authors' loss over fixed held-out batches, eval mode (running statistics
    frozen), weighted by batch size."""
    model.eval()
    tot, n = 0.0, 0
    with torch.no_grad(), env.quiet():
        for b in batches:
            loss = model.training_step(b, 0)
            k = b["out_" + MOTION].shape[0]
            tot += float(loss) * k
            n += k
    model.train()
    return tot / n


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="/work/tfdata/prep")
    ap.add_argument("--out", help="checkpoint directory (created)")
    ap.add_argument("--make-fake", metavar="DIR", help="write a random dataset in the prepared layout to DIR and exit")
    # size (paper: dhid 800, nlayers 12, nhead 10, 16 steps, dhid_flow 512, 8 flow heads, 2 coupling layers)
    ap.add_argument("--dhid", type=int, default=160)
    ap.add_argument("--layers", type=int, default=3, help="cross-modal transformer layers (nlayers); input nets have 2 (hard-coded)")
    ap.add_argument("--heads", type=int, default=4)
    ap.add_argument("--dhid-flow", type=int, default=96)
    ap.add_argument("--heads-flow", type=int, default=4)
    ap.add_argument("--flow-blocks", type=int, default=8, help="flow steps (scales [[n,0]])")
    ap.add_argument("--coupling-layers", type=int, default=2, help="num_glow_coupling_blocks (coupling transformer depth)")
    ap.add_argument("--motion-window", type=int, default=120)
    ap.add_argument("--audio-window", type=int, default=140)
    ap.add_argument("--output-lengths", type=int, default=3)
    ap.add_argument("--rel-pos-emb-inputs", action="store_true",
                    help="learned (L, L) attention bias in the input nets (label configs' option; NOT the paper config)")
    # optimisation
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=5e-4)
    ap.add_argument("--min-lr-ratio", type=float, default=0.05)
    ap.add_argument("--warmup", type=int, default=100)
    ap.add_argument("--weight-decay", type=float, default=0.01)
    ap.add_argument("--clip", type=float, default=0.5)
    ap.add_argument("--target-noise", type=float, default=0.02,
                    help="std of Gaussian noise added to the target frames (scaled units): dequantisation, keeps the "
                         "likelihood of constant feature columns bounded (0: the authors' loss on the raw targets)")
    ap.add_argument("--input-noise", type=float, default=0.02,
                    help="std of Gaussian noise added to the motion input window (scaled units)")
    ap.add_argument("--init-batch", type=int, default=256, help="windows of the data-dependent norm init")
    ap.add_argument("--init", metavar="SAFETENSORS",
                    help="start from these weights (a previous run's model.safetensors, same sizes) instead of "
                         "a fresh model: training goes on with a new schedule (warm-up, cosine) from --lr")
    ap.add_argument("--minutes", type=float, default=25.0, help="wall-clock budget (init, training, evaluations)")
    ap.add_argument("--steps", type=int, default=0, help="step count (0: calibrated from --minutes)")
    ap.add_argument("--calib-steps", type=int, default=15)
    ap.add_argument("--eval-every", type=int, default=50)
    ap.add_argument("--eval-windows", type=int, default=256)
    ap.add_argument("--eval-batch", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)

    if a.make_fake:
        make_fake(a.make_fake, a.seed)
        return 0
    if not a.out:
        ap.error("--out is required")
    if a.calib_steps > a.warmup:
        a.calib_steps = a.warmup  # the schedule before calibration must not depend on the total
    torch.set_num_threads(a.threads)
    t_start = time.time()
    os.makedirs(a.out, exist_ok=True)

    mscaler = read_scaler(os.path.join(a.data, "motion_scaler.json"), MOTION_DIM)
    ascaler = read_scaler(os.path.join(a.data, "audio_scaler.json"), AUDIO_DIM)
    need = max(a.motion_window, a.audio_window, a.motion_window + a.output_lengths)
    train, sk_tr = load_split(a.data, "train", mscaler, ascaler, need)
    test, sk_te = load_split(a.data, "test", mscaler, ascaler, need)
    if not train or not test:
        raise SystemExit(f"no usable sequences (train {len(train)}, test {len(test)}; need >= {need} rows)")
    wtr = Windows(train, a.motion_window, a.audio_window, a.motion_window, a.output_lengths)
    wte = Windows(test, a.motion_window, a.audio_window, a.motion_window, a.output_lengths)
    print(f"data: train {len(train)} sequences ({sum(len(s[1]) for s in train)} rows, {wtr.total} windows), "
          f"test {len(test)} ({sum(len(s[1]) for s in test)} rows, {wte.total} windows); skipped short: "
          f"{len(sk_tr)} train, {len(sk_te)} test", flush=True)

    hp = hparams(a)
    np.random.seed(a.seed)      # InvertibleConv1x1 draws its init with numpy
    torch.manual_seed(a.seed)
    model = env.build(hp)       # the authors' TransflowerModel(opt), eval mode
    model.train()
    n_params = sum(p.numel() for p in model.parameters())
    n_values = sum(t.numel() for t in model.state_dict().values())
    per_net = {}
    for k, p in model.named_parameters():
        per_net[k.split(".")[0]] = per_net.get(k.split(".")[0], 0) + p.numel()
    print(f"model: {n_params:,} parameters ({n_values:,} state-dict values, f32 {4 * n_values / 1e6:.2f} MB); "
          + ", ".join(f"{k} {v:,}" for k, v in per_net.items()), flush=True)

    rng = np.random.default_rng(a.seed)
    erng = np.random.default_rng(a.seed + 1_000_003)
    ev_items = erng.choice(wte.total, size=min(a.eval_windows, wte.total), replace=False)
    noise_gen = torch.Generator().manual_seed(a.seed)

    def noised(b, gen):
        # dequantisation / input noise (train.py's addition, not the authors'): the prepared motion
        # has exactly constant columns (scaled value 0), whose density a flow can make unbounded
        if a.target_noise > 0:
            t = b["out_" + MOTION]
            b["out_" + MOTION] = t + a.target_noise * torch.randn(t.shape, generator=gen)
        if a.input_noise > 0:
            t = b["in_" + MOTION]
            b["in_" + MOTION] = t + a.input_noise * torch.randn(t.shape, generator=gen)
        return b

    ev_gen = torch.Generator().manual_seed(a.seed + 1_000_003)
    ev_batches = [noised(wte.batch(ev_items[i:i + a.eval_batch]), ev_gen) for i in range(0, len(ev_items), a.eval_batch)]

    # data-dependent init of the flow's norm layers: the first training-mode forward
    with torch.no_grad(), env.quiet():
        init = noised(wtr.batch(rng.integers(0, wtr.total, size=a.init_batch)), noise_gen)
        model.training_step(init, 0)
    if a.init:
        # a previous run's weights over the freshly initialised model: every key must match
        state = load_safetensors(a.init)
        missing = model.load_state_dict(state, strict=True)
        print(f"weights from {a.init} ({len(state)} tensors; {missing})", flush=True)
    flags = [float(t) for k, t in model.state_dict().items() if k.endswith("is_initialized")]
    assert flags and all(f == 1.0 for f in flags), flags

    decay, no_decay = [], []
    for k, p in model.named_parameters():
        leaf = k.rsplit(".", 1)[-1]
        (decay if p.dim() == 2 and leaf in ("weight", "in_proj_weight") else no_decay).append(p)
    opt = torch.optim.AdamW([{"params": decay, "weight_decay": a.weight_decay},
                             {"params": no_decay, "weight_decay": 0.0}], lr=a.lr, betas=(0.9, 0.999))

    budget = a.minutes * 60.0
    t0 = time.time()
    ev_t = time.time()
    best = evaluate(model, ev_batches)
    eval_s = time.time() - ev_t
    best_step, best_state = 0, copy.deepcopy(model.state_dict())
    log = open(os.path.join(a.out, "log.jsonl"), "w")

    def record(step, train_nll, test_nll, lr):
        rec = {"step": step, "seconds": round(time.time() - t0, 1), "windows": step * a.batch,
               "train_nll": train_nll, "test_nll": test_nll, "lr": lr}
        log.write(json.dumps(rec) + "\n")
        log.flush()
        print(f"step {step:5d}  {rec['seconds']:7.1f} s  train {train_nll if train_nll is None else round(train_nll, 3)}"
              f"  test {test_nll:.3f}  lr {lr:.2e}", flush=True)

    def save_best():
        save_safetensors(best_state, os.path.join(a.out, "model.safetensors"))
        write_hparams_yaml(hp, os.path.join(a.out, "hparams.yaml"))

    record(0, None, best, 0.0)
    save_best()
    total = a.steps if a.steps > 0 else 10 ** 9
    step, recent, skipped, t_calib = 0, [], 0, None
    eval_in_calib = [0.0]
    t_seg = [None, 0]  # start time and step of the current evaluation period
    while step < total:
        if a.steps <= 0 and step == a.calib_steps:
            # steps that fit: the remaining budget over (step time + evaluation time / eval_every)
            per_step = (time.time() - t_calib - eval_in_calib[0]) / (a.calib_steps - 1)
            remaining = budget - (time.time() - t_start) - eval_s  # the final evaluation
            total = max(step + 1, int(0.9 * remaining / (per_step + eval_s / a.eval_every)) + step)
            print(f"steps {total} (calibrated: {per_step:.2f} s a step, {eval_s:.1f} s an evaluation)", flush=True)
        if step == 1:
            t_calib = time.time()
        lr = lr_at(step, a, total)
        for g in opt.param_groups:
            g["lr"] = lr
        batch = noised(wtr.batch(rng.integers(0, wtr.total, size=a.batch)), noise_gen)
        with env.quiet():
            loss = model.training_step(batch, step)
        if not torch.isfinite(loss):
            skipped += 1
            if skipped > 20:
                raise SystemExit(f"step {step}: {skipped} non-finite losses; lower --lr")
            opt.zero_grad(set_to_none=True)
            step += 1
            continue
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), a.clip)
        opt.step()
        recent.append(loss.item())
        step += 1
        over = time.time() - t_start > budget - eval_s
        if step % a.eval_every == 0 or step == total or over:
            t_ev = time.time()
            te = evaluate(model, ev_batches)
            if step < a.calib_steps:
                eval_in_calib[0] += time.time() - t_ev
            record(step, float(np.mean(recent)), te, lr)
            recent = []
            now = time.time()
            if a.steps <= 0 and step > a.calib_steps and t_seg[0] is not None and not over:
                # --minutes: re-fit the step count to the remaining time at the speed of the last
                # evaluation period (other jobs on the machine change it)
                per = (now - t_seg[0]) / (step - t_seg[1])
                new_total = max(step + 1, int(0.95 * (budget - (now - t_start) - eval_s) / per) + step)
                if abs(new_total - total) > 0.02 * total:
                    print(f"steps {total} -> {new_total} ({per:.2f} s a step with evaluations)", flush=True)
                    total = new_total
            t_seg[:] = [now, step]
            if te < best:
                best, best_step, best_state = te, step, copy.deepcopy(model.state_dict())
                save_best()
        if over:
            print(f"wall-clock budget reached at step {step} of {total}", flush=True)
            break
    save_safetensors(model.state_dict(), os.path.join(a.out, "last.safetensors"))
    save_best()
    log.close()
    run = {"args": vars(a), "hparams": hp, "parameters": n_params, "state_dict_values": n_values,
           "per_net": per_net, "steps": step, "planned_steps": total, "skipped_nonfinite": skipped,
           "best_test_nll": best, "best_step": best_step, "seconds": round(time.time() - t_start, 1),
           "train_sequences": len(train), "test_sequences": len(test), "train_windows": wtr.total,
           "test_windows": wte.total, "loss_unit": "bits per output frame (FlowPlusPlus.loss_generative)",
           "torch": torch.__version__}
    with open(os.path.join(a.out, "run.json"), "w") as f:
        json.dump(run, f, indent=1)
    print(f"best held-out NLL {best:.3f} bits/frame at step {best_step}; {a.out}/model.safetensors, hparams.yaml",
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
