"""Shared pieces of the Bailando demo recipe: the demo size, the configs in the authors' YAML
structure (tools/reference/bailando/tiny.py), the AUTHORS' classes (SepVQVAER,
CrossCondGPT2AC, imported from a lisiyao21/Bailando checkout by tools/reference/bailando/authors.py),
the data prepared by prepare_data.py, checkpoint I/O."""
import copy
import json
import os
import sys
import time

import numpy as np
import torch

TOOLS = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if TOOLS not in sys.path:
    sys.path.insert(0, TOOLS)

from reference.config import Cfg  # noqa: E402
from reference.bailando import authors, tiny  # noqa: E402

# The demo size (docs/DEMO_MODEL.md, "Bailando demo model"). The paper: VQ width / emb 512,
# 512 codes, GPT n_embd 768, 6 + 6 layers, 12 heads; block_size 29 and 8 frames per token kept.
BDEMO = dict(vq_width=96, vq_depth=3, downs_t=3, emb_width=96, l_bins=256, growth=3,
             n_embd=128, n_head=4, base_layers=2, head_layers=2, critic_layers=1,
             block_size=29, n_music=438)
HOP = 8          # frames per token (2 ** downs_t)
WINDOW = 240     # training window (frames), the authors' seq_len / sample_length
FPS = 60


def yaml_docs():
    """{actor_critic.yaml, actor_critic_demo.yaml} for the demo size (authors' structure),
    with the VQ-VAE loss weights of configs/sep_vqvae.yaml (vel 1, acc 1) in both halves."""
    tiny.SIZES["bdemo"] = BDEMO
    docs = tiny.yaml_docs("bdemo")
    for d in docs.values():
        d["expname"] = "bailando_demo_" + d["expname"]
        d["vqvae_weight"] = "vqvae.safetensors"
        d["init_weight"] = "gpt.safetensors"
        for half in ("up_half", "down_half"):
            d["structure"][half].update(vel=1.0, acc=1.0)
    return docs


def cfg(name="actor_critic_demo.yaml"):
    return Cfg(copy.deepcopy(yaml_docs()[name]))


def load_authors(checkout):
    """authors.load, plus a module spec on its `tqdm` stand-in (torch's optimisers import
    torch._dynamo, which calls find_spec on every loaded module name)."""
    import importlib.machinery
    auth = authors.load(checkout)
    for name, mod in list(sys.modules.items()):
        if getattr(mod, "__bailando_stub__", False) and mod.__spec__ is None:
            mod.__spec__ = importlib.machinery.ModuleSpec(name, None)
    return auth


def build(auth, train=True):
    """The authors' SepVQVAER and CrossCondGPT2AC (not DataParallel-wrapped; export adds `module.`)."""
    import contextlib
    import io
    c = cfg()
    with contextlib.redirect_stdout(io.StringIO()):
        vq = auth.SepVQVAER(c.structure)
        gpt = auth.CrossCondGPT2AC(c.structure_generate)
    return vq.train(train), gpt.train(train)


def load_split(data, split):
    """[(name, dance (T, 72) float32 world positions at 60 fps, music (R, 438))]."""
    index = json.load(open(os.path.join(data, "index.json")))
    out = []
    for name in index[split]:
        z = np.load(os.path.join(data, split, name + ".npz"))
        out.append((name, z["dance"], z["music"]))
    return out


def loader_dance(d):
    """The authors' loader normalisation: joints minus the pelvis, world pelvis in 0:3."""
    d = d.astype(np.float32)
    root = d[:, :3].copy()
    d = d - np.tile(root, (1, 24))
    d[:, :3] = root
    return d


def pad8(d):
    """Pad to a multiple of HOP frames with copies of the last row."""
    r = (-len(d)) % HOP
    return np.concatenate([d, np.repeat(d[-1:], r, 0)]) if r else d


def yaw(d, angle):
    """Rotate (T, 72) positions about the vertical (y) axis."""
    c, s = np.cos(angle), np.sin(angle)
    x = d.reshape(len(d), 24, 3).copy()
    x0, z0 = x[..., 0].copy(), x[..., 2].copy()
    x[..., 0] = c * x0 + s * z0
    x[..., 2] = -s * x0 + c * z0
    return x.reshape(len(d), 72)


def save(path, **kw):
    torch.save(kw, path)


class Timer:
    def __init__(self):
        self.t0 = time.time()
        self.c0 = time.process_time()

    def __str__(self):
        return f"wall {time.time() - self.t0:.0f} s, cpu {time.process_time() - self.c0:.0f} s"
