"""Deterministic synthetic Bailando inputs (not real dance, not real music).

dance: (T, 72) float32 SMPL-24 world joint positions at 60 fps (metres): a fixed rest pose
plus sinusoids plus noise, and a slowly wandering pelvis at ~0.9 m height.
music: (R, dim) float32 music-feature-like rows at 7.5 fps (one row per 8 dance frames).
"""
import numpy as np

N_JOINTS = 24


def dance(rng, t, n_waves=4):
    time = np.arange(t)[:, None, None] / 60.0
    rest = rng.normal(0.0, 0.3, size=(1, N_JOINTS, 3))
    rest[:, 0] = 0.0
    out = np.repeat(rest, t, axis=0)
    for _ in range(n_waves):
        freq = rng.uniform(0.3, 2.5)
        phase = rng.uniform(0, 2 * np.pi, size=(1, N_JOINTS, 3))
        amp = rng.uniform(0.03, 0.15, size=(1, N_JOINTS, 3))
        out = out + amp * np.sin(2 * np.pi * freq * time + phase)
    out = out + rng.normal(0.0, 0.004, size=out.shape)
    out[:, 0] = 0.0
    root = np.zeros((t, 3))
    for _ in range(2):
        freq = rng.uniform(0.05, 0.4)
        root += rng.uniform(0.2, 0.6, size=3) * np.sin(2 * np.pi * freq * time[:, 0] + rng.uniform(0, 6.3, size=3))
    root[:, 1] = 0.9 + 0.05 * root[:, 1]
    out = out + root[:, None, :]
    return out.reshape(t, N_JOINTS * 3).astype(np.float32)


def music(rng, rows, dim, n_waves=6):
    time = np.arange(rows)[:, None] / 7.5
    out = np.zeros((rows, dim))
    for _ in range(n_waves):
        freq = rng.uniform(0.05, 1.5)
        out += rng.normal(0, 0.7, size=(1, dim)) * np.sin(2 * np.pi * freq * time + rng.uniform(0, 6.3, size=(1, dim)))
    out += rng.normal(0, 0.3, size=out.shape)
    return out.astype(np.float32)
