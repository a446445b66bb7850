#!/usr/bin/env python3
"""Export a train.py checkpoint directory to .duo files and check them.

    /work/venv/bin/python tools/train/transflower/export.py --run RUN --data /work/tfdata/prep \
        [--out RUN/export] [--dtypes f32,f16,int8] [--wav song.wav] [--seconds 20] [--takes 3]

1. `duolando convert --config RUN/hparams.yaml --weights RUN/model.safetensors --dtype D
   --out OUT/transflower_D.duo` for each dtype, then `duolando inspect` (OUT/inspect_D.txt);
   the file sizes.
2. Engine vs the authors' loop: the authors' `TransflowerModel` loaded from the same state
   dict runs their `autoregressive_generation_multimodal` (tools/reference/transflower/
   reference.py) for `--check-frames` frames on a test take, recording its base samples;
   `duolando generate --noise` replays them on every .duo: max relative error per dtype.
3. `duolando dance --model OUT/transflower_D.duo --music WAV --audio-scaler
   DATA/audio_scaler.json --scaler DATA/motion_scaler.json --motion-seed SEED.npy --out
   OUT/dance_D` (WAV: --wav, else DATA/wav/<first test take>.wav, else a generated 20 s
   click-and-bass track); the seed is that take's first motion rows; checks output.npy.
4. Sanity evaluation: on `--takes` test sequences spread over the split, the first `motion window` rows of the
   true (scaled) motion as the seed and the take's scaled audio, `duolando generate --seed
   S` for `--seconds` of motion; statistics of the generated scaled features against the
   true motion of the same span (per-channel std, frame-to-frame velocity, seed-boundary
   jump, frozen frames, extreme values). OUT/sanity.json.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import wave

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
sys.path.insert(0, HERE)
import train as T  # noqa: E402  (scalers, data loading, safetensors I/O, env import)


def run(cmd, log=None):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if log:
        with open(log, "w") as f:
            f.write(p.stdout + p.stderr)
    if p.returncode != 0:
        raise SystemExit(f"failed ({p.returncode}): {' '.join(cmd)}\n{p.stdout}{p.stderr}")
    return p.stdout + p.stderr


def rel_err(a, b):
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def write_wav(path, seconds=20.0, sr=44100, bpm=120.0):
    """A click on every beat, a louder one on each bar's first beat, and a bass note per bar."""
    t = np.arange(int(seconds * sr)) / sr
    y = np.zeros_like(t)
    beat = 60.0 / bpm
    for k in range(int(seconds / beat) + 1):
        s = int(k * beat * sr)
        n = min(len(y) - s, int(0.05 * sr))
        if n <= 0:
            break
        env_ = np.exp(-np.arange(n) / (0.008 * sr))
        y[s:s + n] += (0.8 if k % 4 == 0 else 0.4) * env_ * np.sin(2 * np.pi * 1800 * np.arange(n) / sr)
    notes = [55.0, 65.41, 73.42, 49.0]
    for b in range(int(seconds / (4 * beat)) + 1):
        s, e = int(b * 4 * beat * sr), min(len(y), int((b + 1) * 4 * beat * sr))
        if s >= e:
            break
        tt = np.arange(e - s) / sr
        y[s:e] += 0.25 * np.sin(2 * np.pi * notes[b % 4] * tt) * np.exp(-tt / 1.5)
    y = np.clip(y, -1, 1)
    with wave.open(path, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(sr)
        w.writeframes((y * 32000).astype("<i2").tobytes())


def motion_stats(gen, true, seed_last, cols=None):
    """gen, true: (F, C) scaled features of the same song rows; seed_last: the seed's last row;
    cols: the channels to use (default all)."""
    if cols is not None:
        gen, true, seed_last = gen[:, cols], true[:, cols], seed_last[cols]
    vg = np.linalg.norm(np.diff(gen, axis=0), axis=1)
    vt = np.linalg.norm(np.diff(true, axis=0), axis=1)
    sg, st = gen.std(0), true.std(0)
    med_vt = float(np.median(vt))
    frozen = vg < 0.1 * med_vt
    run_, longest = 0, 0
    for f in frozen:
        run_ = run_ + 1 if f else 0
        longest = max(longest, run_)
    q = len(gen) // 4
    return {
        "frames": int(len(gen)),
        "finite": bool(np.isfinite(gen).all()),
        "max_abs_gen": float(np.abs(gen).max()), "max_abs_true": float(np.abs(true).max()),
        "frac_abs_gt_5_gen": float((np.abs(gen) > 5).mean()), "frac_abs_gt_5_true": float((np.abs(true) > 5).mean()),
        "channel_std_gen_mean": float(sg.mean()), "channel_std_gen_median": float(np.median(sg)),
        "channel_std_true_mean": float(st.mean()), "channel_std_true_median": float(np.median(st)),
        "channel_std_ratio_median": float(np.median(sg / np.maximum(st, 1e-6))),
        "channel_std_gen_first_quarter": float(gen[:q].std(0).mean()),
        "channel_std_gen_last_quarter": float(gen[-q:].std(0).mean()),
        "velocity_gen_mean": float(vg.mean()), "velocity_true_mean": float(vt.mean()),
        "velocity_gen_median": float(np.median(vg)), "velocity_true_median": med_vt,
        "velocity_gen_p99": float(np.percentile(vg, 99)), "velocity_true_p99": float(np.percentile(vt, 99)),
        "velocity_gen_last_quarter": float(vg[-q:].mean()),
        "seed_jump": float(np.linalg.norm(gen[0] - seed_last)),
        "true_jump": float(np.linalg.norm(true[0] - seed_last)),
        "frozen_frac": float(frozen.mean()), "frozen_longest": int(longest),
        "mean_offset_rms": float(np.sqrt(np.mean((gen.mean(0) - true.mean(0)) ** 2))),
        "rmse_to_true": float(np.sqrt(np.mean((gen - true) ** 2))),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="train.py output directory")
    ap.add_argument("--data", default="/work/tfdata/prep")
    ap.add_argument("--out", help="default RUN/export")
    ap.add_argument("--duolando", default=os.path.join(ROOT, "target", "debug", "duolando"))
    ap.add_argument("--dtypes", default="f32,f16,int8")
    ap.add_argument("--wav", help="music for the dance smoke test (default: a generated 20 s track)")
    ap.add_argument("--seconds", type=float, default=20.0, help="generated motion per sanity take")
    ap.add_argument("--takes", type=int, default=6, help="test sequences in the sanity evaluation (spread over the split)")
    ap.add_argument("--check-frames", type=int, default=20, help="frames of the engine-vs-authors check (0: skip)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args(argv)
    out = a.out or os.path.join(a.run, "export")
    os.makedirs(out, exist_ok=True)
    dtypes = a.dtypes.split(",")
    bin_ = a.duolando
    report = {"run": a.run, "sizes": {}, "engine_vs_authors": {}, "dance": {}, "sanity": {}}

    # 1. convert + inspect
    duos = {}
    for d in dtypes:
        p = os.path.join(out, f"transflower_{d}.duo")
        cmd = [bin_, "convert", "--config", os.path.join(a.run, "hparams.yaml"),
               "--weights", os.path.join(a.run, "model.safetensors"), "--dtype", d, "--out", p]
        print("$ " + " ".join(cmd))
        print(run(cmd).strip())
        run([bin_, "inspect", p], log=os.path.join(out, f"inspect_{d}.txt"))
        duos[d] = p
        report["sizes"][d] = os.path.getsize(p)
        print(f"  {d}: {os.path.getsize(p):,} bytes ({os.path.getsize(p) / 2**20:.2f} MiB)")
    print(open(os.path.join(out, f"inspect_{dtypes[0]}.txt")).read())

    import yaml
    hp = yaml.safe_load(open(os.path.join(a.run, "hparams.yaml")))
    lm, la = (int(x) for x in str(hp["input_lengths"]).split(","))
    mods = str(hp["input_modalities"]).split(",")
    mscaler = T.read_scaler(os.path.join(a.data, "motion_scaler.json"), T.MOTION_DIM)
    ascaler = T.read_scaler(os.path.join(a.data, "audio_scaler.json"), T.AUDIO_DIM)
    frames = int(round(a.seconds * 20))
    test, _ = T.load_split(a.data, "test", mscaler, ascaler, max(la, lm + frames))
    if not test:
        test, _ = T.load_split(a.data, "test", mscaler, ascaler, max(la, lm + 1))
    if not test:
        raise SystemExit("no usable test sequence")
    name0, m0, a0 = test[0]
    # smooth channels: std > 0.1 and lag-1 autocorrelation > 0.5 on the training split (the
    # prepared motion has exactly constant columns and white-noise columns of ~1e-6 rad scale)
    train_seqs, _ = T.load_split(a.data, "train", mscaler, ascaler, 2)
    num = np.zeros(T.MOTION_DIM)
    den = np.zeros(T.MOTION_DIM)
    for _, m, _ in train_seqs:
        x = m - m.mean(0)
        num += (x[1:] * x[:-1]).sum(0)
        den += (x * x).sum(0)
    tstd = np.sqrt(den / sum(len(m) for _, m, _ in train_seqs))
    smooth = np.where((tstd > 0.1) & (num / np.maximum(den, 1e-12) > 0.5))[0]
    report["smooth_channels"] = smooth.tolist()
    print(f"{len(smooth)} smooth channels of {T.MOTION_DIM} (the rest constant or white noise on the training split)")

    # 2. engine vs the authors' loop, recorded noise replayed
    if a.check_frames > 0:
        import torch
        from transflower import reference
        torch.set_num_threads(a.threads)
        k = min(a.check_frames, len(a0) - la + 1)
        inputs = {mods[0]: m0[:lm].copy(), mods[1]: a0[:la + k - 1].copy()}
        state = T.load_safetensors(os.path.join(a.run, "model.safetensors"))
        model = reference.build_from_state(hp, state)
        res = reference.generate(model, inputs, seed=a.seed)
        np.save(os.path.join(out, "check_noise.npy"), res["noise"])
        for m, x in inputs.items():
            np.save(os.path.join(out, f"check_in_{m}.npy"), x)
        np.save(os.path.join(out, "check_authors_output.npy"), res["output"])
        for d, p in duos.items():
            g = os.path.join(out, f"check_{d}")
            run([bin_, "generate", "--model", p, "--input", f"{mods[0]}={out}/check_in_{mods[0]}.npy",
                 "--input", f"{mods[1]}={out}/check_in_{mods[1]}.npy", "--noise", f"{out}/check_noise.npy",
                 "--out", g])
            o = np.load(os.path.join(g, "output.npy"))
            e = rel_err(o, res["output"])
            report["engine_vs_authors"][d] = {"frames": int(o.shape[0]), "max_rel_err": e}
            print(f"engine ({d}) vs the authors' loop, {o.shape[0]} frames, same base samples: max rel err {e:.3g}")

    # 3. dance smoke test
    wav = a.wav
    take_wav = os.path.join(a.data, "wav", name0.rsplit("_", 1)[0] + ".wav")
    if not wav and os.path.exists(take_wav):
        wav = take_wav  # the test take's own music (prepare_data.py writes DATA/wav/<take>.wav)
    if not wav:
        wav = os.path.join(out, "clicks_120bpm.wav")
        write_wav(wav, 20.0)
    seed_npy = os.path.join(out, "seed_motion.npy")
    np.save(seed_npy, m0[:lm])
    for d, p in duos.items():
        g = os.path.join(out, f"dance_{d}")
        cmd = [bin_, "dance", "--model", p, "--music", wav, "--audio-scaler", os.path.join(a.data, "audio_scaler.json"),
               "--scaler", os.path.join(a.data, "motion_scaler.json"), "--motion-seed", seed_npy, "--out", g]
        if d == dtypes[0]:
            print("$ " + " ".join(cmd))
        run(cmd, log=os.path.join(out, f"dance_{d}.log"))
        o = np.load(os.path.join(g, "output.npy"))
        files = sorted(os.path.basename(f) for f in glob.glob(os.path.join(g, "*")))
        report["dance"][d] = {"output_shape": list(o.shape), "finite": bool(np.isfinite(o).all()), "files": files}
        print(f"dance ({d}): output.npy {o.shape}, finite {bool(np.isfinite(o).all())}; {', '.join(files)}")

    # 4. sanity evaluation on test takes
    per = {d: [] for d in dtypes}
    outs = {}
    # sequences spread over the test split (sorted by name: genres in turn), both dancers alike
    pick = sorted(set(np.linspace(0, len(test) - 1, min(a.takes, len(test))).round().astype(int).tolist()))
    chosen = [test[i] for i in pick]
    for name, m, au in chosen:
        f = min(frames, len(m) - lm, len(au) - la + 1)
        am = au[: f + la - 1]
        sd = os.path.join(out, f"sanity_{name}")
        os.makedirs(sd, exist_ok=True)
        np.save(os.path.join(sd, "seed.npy"), m[:lm])
        np.save(os.path.join(sd, "audio.npy"), am)
        true = m[lm: lm + f]
        for d, p in duos.items():
            g = os.path.join(sd, d)
            run([bin_, "generate", "--model", p, "--input", f"{mods[0]}={sd}/seed.npy",
                 "--input", f"{mods[1]}={sd}/audio.npy", "--seed", str(a.seed), "--out", g])
            gen = np.load(os.path.join(g, "output.npy"))[:, 0, :]
            outs[(name, d)] = gen
            st = motion_stats(gen, true, m[lm - 1], smooth)
            st_all = motion_stats(gen, true, m[lm - 1])
            st.update({k + "_allch": v for k, v in st_all.items()})
            st["take"] = name
            per[d].append(st)
    keys = [k for k in per[dtypes[0]][0] if k not in ("take",)]
    for d in dtypes:
        report["sanity"][d] = {"takes": per[d], "mean": {k: float(np.mean([s[k] for s in per[d]])) for k in keys}}
        if d != dtypes[0]:
            report["sanity"][d]["max_rel_err_vs_" + dtypes[0]] = max(
                rel_err(outs[(n, d)], outs[(n, dtypes[0])]) for n, _, _ in chosen)
    print(f"\nsanity ({len(per[dtypes[0]])} test sequences x {frames} frames, seed {a.seed}; scaled features "
          f"(training data std 1), the {len(smooth)} smooth channels):")
    show = ["channel_std_gen_mean", "channel_std_true_mean", "channel_std_ratio_median", "channel_std_gen_first_quarter",
            "channel_std_gen_last_quarter", "velocity_gen_mean", "velocity_true_mean", "velocity_gen_p99",
            "velocity_true_p99", "velocity_gen_last_quarter", "seed_jump", "true_jump", "frozen_frac", "frozen_longest",
            "max_abs_gen", "max_abs_true", "mean_offset_rms", "rmse_to_true", "channel_std_gen_mean_allch",
            "channel_std_true_mean_allch", "velocity_gen_mean_allch", "velocity_true_mean_allch"]
    print(f"{'':32s}" + "".join(f"{d:>10s}" for d in dtypes))
    for k in show:
        print(f"{k:32s}" + "".join(f"{report['sanity'][d]['mean'][k]:10.3f}" for d in dtypes))
    for d in dtypes[1:]:
        print(f"{d} vs {dtypes[0]} (same seed): max rel err {report['sanity'][d]['max_rel_err_vs_' + dtypes[0]]:.3g}")
    with open(os.path.join(out, "sanity.json"), "w") as f:
        json.dump(report, f, indent=1)
    print(f"\n{out}/sanity.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
