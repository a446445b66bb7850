"""Deterministic synthetic inputs: a skeleton-sized leader/follower pair and music features.

Not real dance: sums of sinusoids plus noise around a fixed rest pose, so that the VQ codes
and the GPT conditions vary over a sequence.
"""
import numpy as np

N_JOINTS = 55
HAND_JOINTS = range(25, 55)


def rest_pose(rng):
    """(55, 3) joint offsets from the pelvis, in metres; hand joints within ~10 cm of a wrist."""
    pose = rng.normal(0.0, 0.25, size=(N_JOINTS, 3))
    pose[0] = 0.0
    pose[20] = [0.55, 0.35, 0.05]   # left wrist
    pose[21] = [-0.55, 0.35, 0.05]  # right wrist
    for j in range(25, 40):
        pose[j] = pose[20] + rng.normal(0.0, 0.05, size=3)
    for j in range(40, 55):
        pose[j] = pose[21] + rng.normal(0.0, 0.05, size=3)
    return pose


def motion(rng, t, root_offset=(0.0, 0.0, 0.0), n_waves=4):
    """(t, 165) float32 world joint positions at 30 fps."""
    time = np.arange(t)[:, None, None] / 30.0                  # (t, 1, 1)
    rest = rest_pose(rng)[None]                                  # (1, 55, 3)
    out = np.repeat(rest, t, axis=0)                             # (t, 55, 3)
    for _ in range(n_waves):
        freq = rng.uniform(0.2, 2.0)
        phase = rng.uniform(0, 2 * np.pi, size=(1, N_JOINTS, 3))
        amp = rng.uniform(0.02, 0.12, size=(1, N_JOINTS, 3))
        amp[:, 25:] *= 0.3  # fingers move less
        out = out + amp * np.sin(2 * np.pi * freq * time + phase)
    out = out + rng.normal(0.0, 0.004, size=out.shape)
    root = np.zeros((t, 3))                                      # pelvis path, metres
    for _ in range(2):
        freq = rng.uniform(0.05, 0.3)
        root += rng.uniform(0.2, 0.6, size=3) * np.sin(2 * np.pi * freq * time[:, 0] + rng.uniform(0, 6.3, size=3))
    root[:, 1] = 0.9 + 0.05 * root[:, 1]                         # pelvis height ~0.9 m
    root += np.asarray(root_offset)
    out = out + root[:, None, :]
    return out.reshape(t, N_JOINTS * 3).astype(np.float32)


def music(rng, t, dim=54, n_waves=6):
    """(t, dim) float32 music-like features (order-1 values, beat-like periodicities)."""
    time = np.arange(t)[:, None] / 30.0
    out = np.zeros((t, dim))
    for _ in range(n_waves):
        freq = rng.uniform(0.3, 3.0)
        out += rng.normal(0, 0.7, size=(1, dim)) * np.sin(2 * np.pi * freq * time + rng.uniform(0, 6.3, size=(1, dim)))
    out += rng.normal(0, 0.1, size=out.shape)
    return out.astype(np.float32)


def pair(seed, t):
    """A (leader, follower, music) triple for one rollout; the follower stands ~1 m away."""
    rng = np.random.default_rng(seed)
    leader = motion(rng, t)
    follower = motion(rng, t, root_offset=(0.8, 0.0, 0.6))
    return leader, follower, music(rng, t)
