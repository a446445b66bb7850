"""Transflower motion features (the authors' `expmap_scaled_20` layout, 69 columns) from
`duolando synth` dancers, and an independent numpy copy of the engine's inverse.

Forward (what tools/train/transflower/prepare_data.py writes), per dancer:

1. the synth's (T, 3 + 495) rotmat file: pelvis world position + 55 local rotations
   (row-major 3x3 acting on column vectors, SMPL-X joint order, docs/SKELETON.md);
2. 30 -> 20 fps: at t = k/20 s the local rotations of the 22 body joints are slerped and
   the pelvis position is interpolated linearly between the two 30-fps frames around it;
3. world rotations of SMPL-X joints 0..21 by the chain, then each Mixamo joint of the
   engine's built-in table (std-adapters/src/transflower_motion/skeleton.rs DEFAULT_TABLE)
   gets the world rotation of its SMPL-X joint (SMPL-X j -> MIXAMO_BODY[j]) times a rest
   correction C_m (`retarget="align"`: the smallest rotation taking the Mixamo rest bone to
   the synth rig's rest bone, so the bones point where the synth's point; `"copy"`: C = I,
   the local rotations carried over unchanged). Mixamo's Spine2 (SMPL-X spine3) is not in
   the features and the engine keeps it at rest, so Spine1 takes spine3's WORLD rotation:
   its local rotation is the composed chain R_spine2 R_spine3 (conjugated by C in "align");
4. the root as the inverse of the engine's `decode` (= pymo's pos_rot_deltas): heading
   h_t = atan2(f_x, f_z), f = Hips' +z axis (third column of its world rotation); root
   rotation R_y(-h_t) G_hips; Hips_Xposition = Hips_Zposition = 0, Hips_Yposition = the
   height; dX, dZ = R_y(-h_t) (p_t - p_{t-1}) (x, z); dY = h_t - h_{t-1} wrapped to
   (-pi, pi]; frame 0 copies frame 1's three deltas. R_y(h) = [[c,0,s],[0,1,0],[-s,0,c]]
   (expmap.rs `about_y`). With `root_scale="legs"` the pelvis position (height and ground
   trajectory) is first multiplied by k = Mixamo rest hips-above-toe (1.0428 m) / the
   synth dancer's rest pelvis-above-ball-of-foot, so the Mixamo legs reach the floor and
   planted feet do not slide; "none" keeps metres as they are;
5. expmap = axis * angle (radians, scipy's rotvec) per kept joint, columns in REVERSE
   BVH file order of the table (layout.rs), then Hips_X/Y/Zposition, dX, dZ, dY.

`decode` is the engine's inverse (mod.rs `decode`) in numpy, f64.
"""
import numpy as np
from scipy.spatial.transform import Rotation

# std-adapters/src/transflower_motion/skeleton.rs DEFAULT_TABLE (the body of the authors'
# analysis/mixamo.bvh): (name, parent, rest offset in metres), BVH file order.
MIXAMO_TABLE = [
    ("Hips", None, (0.0, 0.0, 0.0)),
    ("LeftUpLeg", "Hips", (0.082078, -0.067517, -0.015996)),
    ("LeftLeg", "LeftUpLeg", (0.0, -0.443705, 0.002846)),
    ("LeftFoot", "LeftLeg", (0.0, -0.444279, -0.029822)),
    ("LeftToeBase", "LeftFoot", (0.0, -0.087287, 0.107106)),
    ("RightUpLeg", "Hips", (-0.082078, -0.067517, -0.015996)),
    ("RightLeg", "RightUpLeg", (0.0, -0.443705, 0.002862)),
    ("RightFoot", "RightLeg", (0.0, -0.444277, -0.029838)),
    ("RightToeBase", "RightFoot", (0.0, -0.087287, 0.107106)),
    ("Spine", "Hips", (0.0, 0.101816, 0.001315)),
    ("Spine1", "Spine", (0.0, 0.100835, -0.010008)),
    ("Spine2", "Spine1", (0.0, 0.091000, -0.013734)),
    ("LeftShoulder", "Spine2", (0.045704, 0.109460, -0.026280)),
    ("LeftArm", "LeftShoulder", (0.105924, -0.005246, -0.022321)),
    ("LeftForeArm", "LeftArm", (0.278415, -0.000001, 0.0)),
    ("LeftHand", "LeftForeArm", (0.283288, 0.0, 0.0)),
    ("Neck", "Spine2", (0.0, 0.166717, -0.025162)),
    ("Head", "Neck", (0.0, 0.096179, 0.016850)),
    ("RightShoulder", "Spine2", (-0.045700, 0.109462, -0.026280)),
    ("RightArm", "RightShoulder", (-0.105929, -0.005248, -0.022321)),
    ("RightForeArm", "RightArm", (-0.278415, 0.0, 0.0)),
    ("RightHand", "RightForeArm", (-0.283288, 0.0, 0.000001)),
]
MIX_NAMES = [r[0] for r in MIXAMO_TABLE]
MIX_PARENTS = [None if r[1] is None else MIX_NAMES.index(r[1]) for r in MIXAMO_TABLE]
MIX_OFFSETS = np.array([r[2] for r in MIXAMO_TABLE], dtype=np.float64)

# layout.rs SELECTED (feature_extraction/process_motions.py's JointSelector list).
SELECTED = ["Spine", "Spine1", "Neck", "Head", "RightShoulder", "RightArm", "RightForeArm",
            "RightHand", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "RightUpLeg",
            "RightLeg", "RightFoot", "RightToeBase", "LeftUpLeg", "LeftLeg", "LeftFoot",
            "LeftToeBase"]
# Kept joints in file order; the expmap columns are in the reverse of it.
KEPT = [j for j in range(len(MIX_NAMES)) if MIX_PARENTS[j] is None or MIX_NAMES[j] in SELECTED]
ROT_COLS = [(j, 3 * k) for k, j in enumerate(reversed(KEPT))]  # (mixamo joint, first column)
WIDTH = 3 * len(KEPT) + 6  # 69
ROOT_X, ROOT_Y, ROOT_Z, ROOT_DX, ROOT_DZ, ROOT_DYAW = range(3 * len(KEPT), WIDTH)


def column_names():
    names = [""] * WIDTH
    for j, c in ROT_COLS:
        for k, s in enumerate(("alpha", "beta", "gamma")):
            names[c + k] = f"{MIX_NAMES[j]}_{s}"
    for c, s in zip(range(3 * len(KEPT), WIDTH),
                    ("Xposition", "Yposition", "Zposition", "dXposition", "dZposition", "dYrotation")):
        names[c] = f"Hips_{s}"
    return names


# SMPL-X (docs/SKELETON.md, skeleton::PARENTS), body joints 0..21.
SMPLX_PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19]
SMPLX_NAMES = ["pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
               "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
               "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
               "left_elbow", "right_elbow", "left_wrist", "right_wrist"]
# leader_bvh.rs MIXAMO_BODY: Mixamo's names of SMPL-X joints 0..21.
MIXAMO_BODY = ["Hips", "LeftUpLeg", "RightUpLeg", "Spine", "LeftLeg", "RightLeg", "Spine1",
               "LeftFoot", "RightFoot", "Spine2", "LeftToeBase", "RightToeBase", "Neck",
               "LeftShoulder", "RightShoulder", "Head", "LeftArm", "RightArm", "LeftForeArm",
               "RightForeArm", "LeftHand", "RightHand"]
# SMPL-X joint whose world rotation each Mixamo joint takes (Spine1 <- spine3: the fold).
MIX_SOURCE = {m: MIXAMO_BODY.index(m) for m in MIX_NAMES}
MIX_SOURCE["Spine1"] = 9
MIX_SOURCE["Spine2"] = None  # rest local rotation: world = Spine1's
# Bone aligned by the rest correction ("align"): Mixamo joint -> (Mixamo bone vector in the
# rest pose, synth rest bone as (from, to) SMPL-X joints). Leaves reuse their parent's C.
_ALIGN = {
    "LeftUpLeg": ("LeftLeg", (1, 4)), "RightUpLeg": ("RightLeg", (2, 5)),
    "LeftLeg": ("LeftFoot", (4, 7)), "RightLeg": ("RightFoot", (5, 8)),
    "LeftFoot": ("LeftToeBase", (7, 10)), "RightFoot": ("RightToeBase", (8, 11)),
    "Spine": ("Spine1", (3, 6)), "Spine1": ("Neck", (9, 12)), "Neck": ("Head", (12, 15)),
    "LeftShoulder": ("LeftArm", (13, 16)), "RightShoulder": ("RightArm", (14, 17)),
    "LeftArm": ("LeftForeArm", (16, 18)), "RightArm": ("RightForeArm", (17, 19)),
    "LeftForeArm": ("LeftHand", (18, 20)), "RightForeArm": ("RightHand", (19, 21)),
}
_LEAF_LIKE = {"LeftToeBase": "LeftFoot", "RightToeBase": "RightFoot", "Head": "Neck",
              "LeftHand": "LeftForeArm", "RightHand": "RightForeArm"}


def mixamo_rest_positions():
    p = np.zeros((len(MIX_NAMES), 3))
    for j, q in enumerate(MIX_PARENTS):
        if q is not None:
            p[j] = p[q] + MIX_OFFSETS[j]
    return p


MIX_REST = mixamo_rest_positions()
# Hips above the toe joints at rest (both sides' mean): 1.042787 m.
MIX_HIP_ABOVE_TOE = -0.5 * (MIX_REST[MIX_NAMES.index("LeftToeBase"), 1]
                            + MIX_REST[MIX_NAMES.index("RightToeBase"), 1])


def check_table_against_rust(path):
    """Parses DEFAULT_TABLE out of skeleton.rs and checks it equals MIXAMO_TABLE."""
    import re
    text = open(path).read()
    body = text[text.index("DEFAULT_TABLE"):]
    body = body[: body.index("];")]
    rows = re.findall(r'\(\s*"(\w+)",\s*(None|Some\("(\w+)"\)),\s*\[([^\]]*)\]', body)
    got = [(n, p or None, tuple(float(v) for v in o.split(",") if v.strip())) for n, _, p, o in rows]
    want = [(n, p, tuple(o)) for n, p, o in MIXAMO_TABLE]
    if got != want:
        raise SystemExit(f"{path}: DEFAULT_TABLE differs from tf_motion.MIXAMO_TABLE:\n{got}\n{want}")


# ---------------------------------------------------------------------------------------
# rotations

def about_y(h):
    """R_y(h) for an array of angles: (..., 3, 3), expmap.rs `about_y`."""
    h = np.asarray(h, dtype=np.float64)
    s, c = np.sin(h), np.cos(h)
    m = np.zeros(h.shape + (3, 3))
    m[..., 0, 0] = c
    m[..., 0, 2] = s
    m[..., 1, 1] = 1.0
    m[..., 2, 0] = -s
    m[..., 2, 2] = c
    return m


def rodrigues(v):
    """expmap (..., 3) -> (..., 3, 3), as expmap.rs `rotation` (series below 1e-8 rad)."""
    v = np.asarray(v, dtype=np.float64)
    t2 = (v * v).sum(-1)
    t = np.sqrt(t2)
    small = t < 1e-8
    ts = np.where(small, 1.0, t)
    h = np.sin(0.5 * ts) / ts
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(ts) / ts)
    b = np.where(small, 0.5 - t2 / 24.0, 2.0 * h * h)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    m = np.empty(v.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 + b * (x * x - t2)
    m[..., 0, 1] = -a * z + b * x * y
    m[..., 0, 2] = a * y + b * x * z
    m[..., 1, 0] = a * z + b * x * y
    m[..., 1, 1] = 1.0 + b * (y * y - t2)
    m[..., 1, 2] = -a * x + b * y * z
    m[..., 2, 0] = -a * y + b * x * z
    m[..., 2, 1] = a * x + b * y * z
    m[..., 2, 2] = 1.0 + b * (z * z - t2)
    return m


def to_quat(m):
    """(..., 3, 3) -> (..., 4) xyzw (nearest rotation via scipy)."""
    sh = m.shape[:-2]
    return Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat().reshape(sh + (4,))


def from_quat(q):
    sh = q.shape[:-1]
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(sh + (3, 3))


def slerp(q0, q1, a):
    """Quaternion slerp (..., 4) with weights a broadcast over the leading axes."""
    d = (q0 * q1).sum(-1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    a = np.asarray(a, dtype=np.float64)[..., None]
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    sin_t = np.sin(theta)
    lin = sin_t < 1e-6
    st = np.where(lin, 1.0, sin_t)
    w0 = np.where(lin, 1.0 - a, np.sin((1.0 - a) * theta) / st)
    w1 = np.where(lin, a, np.sin(a * theta) / st)
    q = w0 * q0 + w1 * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def swing(a, b):
    """The smallest rotation taking direction a to direction b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    c = np.cross(a, b)
    s = np.linalg.norm(c)
    ang = np.arctan2(s, float(np.dot(a, b)))
    if s < 1e-12:
        return np.eye(3)
    return Rotation.from_rotvec(c / s * ang).as_matrix()


def wrap(a):
    """To (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


# ---------------------------------------------------------------------------------------
# the synth rig

def synth_rest_offsets(pos3d, rotmat):
    """Rest offsets (22, 3) of the synth dancer's body joints, measured from its data:
    offset_j = G_parent^T (P_j - P_parent) (exact for FK data; median over a few frames)."""
    T = rotmat.shape[0]
    idx = np.unique(np.linspace(0, T - 1, min(T, 8)).astype(int))
    R = rotmat[idx, 3:].reshape(len(idx), 55, 3, 3).astype(np.float64)[:, :22]
    P = pos3d[idx].reshape(len(idx), 55, 3).astype(np.float64)[:, :22]
    G = world_rotations(R)
    off = np.zeros((len(idx), 22, 3))
    for j in range(1, 22):
        q = SMPLX_PARENTS[j]
        off[:, j] = np.einsum("tki,tk->ti", G[:, q], P[:, j] - P[:, q])
    return np.median(off, axis=0)


def world_rotations(R):
    """Local (T, 22, 3, 3) -> world along the SMPL-X chain."""
    G = np.empty_like(R)
    for j in range(R.shape[1]):
        q = SMPLX_PARENTS[j]
        G[:, j] = R[:, j] if q < 0 else G[:, q] @ R[:, j]
    return G


def synth_rest_positions(off):
    p = np.zeros((22, 3))
    for j in range(1, 22):
        p[j] = p[SMPLX_PARENTS[j]] + off[j]
    return p


def mixamo_positions(W, root):
    """FK of the Mixamo table from world rotations (N, 22, 3, 3) and hips positions (N, 3)."""
    P = np.zeros(W.shape[:2] + (3,))
    P[:, 0] = root
    for j in range(1, len(MIX_NAMES)):
        q = MIX_PARENTS[j]
        P[:, j] = P[:, q] + np.einsum("tij,j->ti", W[:, q], MIX_OFFSETS[j])
    return P


def leg_scale(off, C):
    """k = the Mixamo hips' height above its toe joints when the synth's REST pose is carried
    over (rest corrections C applied; 1.0428 m for "copy") / the synth pelvis' height above
    its ball-of-foot joints at rest."""
    p = synth_rest_positions(off)
    W = mixamo_world(np.tile(np.eye(3), (1, 22, 1, 1)), C)
    P = mixamo_positions(W, np.zeros((1, 3)))[0]
    toe = 0.5 * (P[MIX_NAMES.index("LeftToeBase"), 1] + P[MIX_NAMES.index("RightToeBase"), 1])
    return -toe / (-0.5 * (p[10, 1] + p[11, 1]))


def rest_corrections(off, retarget):
    """C_m (22, 3, 3) per Mixamo joint (identity for "copy")."""
    C = np.tile(np.eye(3), (len(MIX_NAMES), 1, 1))
    if retarget == "copy":
        return C
    if retarget != "align":
        raise ValueError(retarget)
    sp = synth_rest_positions(off)
    for m, (child, (a, b)) in _ALIGN.items():
        j = MIX_NAMES.index(m)
        c = MIX_NAMES.index(child)
        mix_bone = MIX_REST[c] - MIX_REST[j]  # through a rest Spine2 for Spine1 -> Neck
        C[j] = swing(mix_bone, sp[b] - sp[a])
    for leaf, parent in _LEAF_LIKE.items():
        C[MIX_NAMES.index(leaf)] = C[MIX_NAMES.index(parent)]
    return C


# ---------------------------------------------------------------------------------------
# forward

# (joint, child whose rest offset is the bone, child compensated?): shoulders, then elbows.
TWIST_JOINTS = [(16, 18, True), (17, 19, True), (18, 20, False), (19, 21, False)]


def fix_twist_flips(R, off):
    """The synth's arm IK sometimes turns the upper arm or the forearm by pi about its own
    bone between two frames (the twist solution flips; the joint positions stay continuous).
    A twist about the bone moves no joint of the Mixamo table (the hand is a leaf there), so
    per frame the local rotation R or R Q (Q = a half turn about the bone) nearest to the
    previous frame's is kept; for the shoulders the elbow gets Q R_elbow so that the forearm
    does not move. R: (T, 22, 3, 3) local, changed in place; returns how many flips were
    removed (how often the choice changes)."""
    flips = 0
    for j, c, comp in TWIST_JOINTS:
        b = off[c] / np.linalg.norm(off[c])
        Q = 2.0 * np.outer(b, b) - np.eye(3)  # rotation by pi about b
        prev, was = R[0, j], False
        for t in range(1, R.shape[0]):
            a, aq = R[t, j], R[t, j] @ Q
            # trace(prev^T X) is larger for the nearer rotation
            now = bool(np.sum(prev * aq) > np.sum(prev * a))
            if now:
                R[t, j] = aq
                if comp:
                    R[t, c] = Q @ R[t, c]
            flips += now != was
            prev, was = R[t, j], now
    return flips


def resample_30_to_20(rotmat, off=None):
    """(T, 498) at 30 fps -> (root (N, 3), local rotations (N, 22, 3, 3)) at t = k/20 s,
    N = floor((T - 1) / 1.5) + 1: slerp of the local rotations, linear root. With `off` (the
    synth rest offsets) the arm twist flips are removed first (fix_twist_flips)."""
    T = rotmat.shape[0]
    n = int(np.floor((T - 1) / 1.5)) + 1
    u = np.arange(n) * 1.5
    i0 = np.minimum(np.floor(u).astype(int), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    a = u - i0
    root = rotmat[:, :3].astype(np.float64)
    R = rotmat[:, 3:].reshape(T, 55, 3, 3)[:, :22].astype(np.float64)
    resample_30_to_20.flips = fix_twist_flips(R, off) if off is not None else 0
    q = to_quat(R)
    qi = slerp(q[i0], q[i1], np.broadcast_to(a[:, None], (n, 22)))
    ri = root[i0] * (1.0 - a)[:, None] + root[i1] * a[:, None]
    return ri, from_quat(qi)


def mixamo_world(G_smplx, C):
    """World rotations (N, 22, 3, 3) of the Mixamo table's joints."""
    n = G_smplx.shape[0]
    W = np.empty((n, len(MIX_NAMES), 3, 3))
    for j, name in enumerate(MIX_NAMES):
        s = MIX_SOURCE[name]
        if s is None:  # Spine2: at rest under Spine1
            W[:, j] = W[:, MIX_PARENTS[j]]
        else:
            W[:, j] = G_smplx[:, s] @ C[j]
    return W


def features_from_world(W, root_pos):
    """Mixamo world rotations (N, 22, 3, 3) + hips positions (N, 3) -> (N, 69) features."""
    n = W.shape[0]
    fwd = W[:, 0, :, 2]  # Hips' +z axis
    h = np.arctan2(fwd[:, 0], fwd[:, 2])
    Ry_inv = about_y(-h)
    local = np.empty_like(W)
    local[:, 0] = Ry_inv @ W[:, 0]
    for j in range(1, len(MIX_NAMES)):
        local[:, j] = np.swapaxes(W[:, MIX_PARENTS[j]], -1, -2) @ W[:, j]
    f = np.zeros((n, WIDTH))
    rv = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_rotvec().reshape(n, -1, 3)
    for j, c in ROT_COLS:
        f[:, c:c + 3] = rv[:, j]
    f[:, ROOT_Y] = root_pos[:, 1]
    if n > 1:
        d = np.zeros((n, 3))
        d[1:, [0, 2]] = root_pos[1:, [0, 2]] - root_pos[:-1, [0, 2]]
        dl = np.einsum("tij,tj->ti", Ry_inv, d)
        f[1:, ROOT_DX] = dl[1:, 0]
        f[1:, ROOT_DZ] = dl[1:, 2]
        f[1:, ROOT_DYAW] = wrap(h[1:] - h[:-1])
        f[0, [ROOT_DX, ROOT_DZ, ROOT_DYAW]] = f[1, [ROOT_DX, ROOT_DZ, ROOT_DYAW]]
    return f, h


def dancer_features(rotmat, pos3d, retarget="align", root_scale="legs", unwrap=True, twist_fix=True):
    """One synth dancer -> ((N, 69) float64 features at 20 fps, info dict)."""
    off = synth_rest_offsets(pos3d, rotmat)
    C = rest_corrections(off, retarget)
    if root_scale not in ("legs", "none"):
        raise ValueError(root_scale)
    k = leg_scale(off, C) if root_scale == "legs" else 1.0
    root, R = resample_30_to_20(rotmat, off if twist_fix else None)
    G = world_rotations(R)
    W = mixamo_world(G, C)
    f, h = features_from_world(W, root * k)
    if unwrap:
        f = unwrap_expmaps(f)
    info = {"frames": int(f.shape[0]), "root_scale_k": float(k), "twist_flips_removed": resample_30_to_20.flips,
            "max_expmap_angle_rad": float(np.linalg.norm(f[:, :3 * len(KEPT)].reshape(len(f), -1, 3), axis=-1).max())}
    return f, info


def unwrap_expmaps(f):
    """Makes every joint's expmap continuous in time: the rotation by angle t about n is also
    the one by t - 2 pi m about n; per frame the representative v + 2 pi m n (m = -2..2) nearest
    to the previous frame's is kept (frame 0: scipy's, angle in [0, pi]). Near pi the plain
    rotvec flips its axis (a jump of 2 pi in the feature); this keeps the same rotations (the
    engine's Rodrigues takes any angle) without the jumps."""
    f = f.copy()
    n, r = f.shape[0], 3 * len(KEPT)
    v = f[:, :r].reshape(n, -1, 3)
    ang = np.linalg.norm(v, axis=-1, keepdims=True)
    axis = np.where(ang > 1e-9, v / np.where(ang > 1e-9, ang, 1.0), 0.0)
    m = np.arange(-2, 3)[None, None, :, None]
    cand = v[:, :, None, :] + 2 * np.pi * m * axis[:, :, None, :]  # (n, joints, 5, 3)
    out = np.empty_like(v)
    out[0] = v[0]
    rows = np.arange(v.shape[1])
    for t in range(1, n):
        d = ((cand[t] - out[t - 1][:, None, :]) ** 2).sum(-1)
        out[t] = cand[t, rows, np.argmin(d, axis=1)]
    f[:, :r] = out.reshape(n, r)
    return f


# ---------------------------------------------------------------------------------------
# inverse: the engine's transflower_motion::decode in numpy

def decode(features, offsets=MIX_OFFSETS, parents=MIX_PARENTS, rot_cols=ROT_COLS,
           root_cols=(ROOT_X, ROOT_Y, ROOT_Z, ROOT_DX, ROOT_DZ, ROOT_DYAW)):
    """(N, C) unscaled features -> (positions (N, J, 3), world rotations (N, J, 3, 3)).
    root_cols: (x or None, y, z or None, dx, dz, dyaw)."""
    x_c, y_c, z_c, dx_c, dz_c, dy_c = root_cols
    F = np.asarray(features, dtype=np.float64)
    n, nj = F.shape[0], len(parents)
    heading = np.zeros(n)
    traj = np.zeros((n, 3))
    for t in range(1, n):
        heading[t] = heading[t - 1] + F[t, dy_c]
        d = about_y(heading[t]) @ np.array([F[t, dx_c], 0.0, F[t, dz_c]])
        traj[t] = traj[t - 1] + np.array([d[0], 0.0, d[2]])
    hy = about_y(heading)
    own = np.zeros((n, 3))
    if x_c is not None:
        own[:, 0] = F[:, x_c]
    if z_c is not None:
        own[:, 2] = F[:, z_c]
    own = np.einsum("tij,tj->ti", hy, own)
    root = np.stack([traj[:, 0] + own[:, 0], F[:, y_c], traj[:, 2] + own[:, 2]], axis=1)
    local = np.tile(np.eye(3), (n, nj, 1, 1))
    for j, c in rot_cols:
        local[:, j] = rodrigues(F[:, c:c + 3])
    P = np.zeros((n, nj, 3))
    G = np.zeros((n, nj, 3, 3))
    for j in range(nj):
        q = parents[j]
        if q is None:
            P[:, j] = root
            G[:, j] = hy @ local[:, j]
        else:
            P[:, j] = P[:, q] + np.einsum("tij,j->ti", G[:, q], offsets[j])
            G[:, j] = G[:, q] @ local[:, j]
    return P, G
