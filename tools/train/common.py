"""Shared pieces of the demo training recipe: sizes, YAML configs in the original structure,
dataset loading (original DD100 layout as written by `duolando synth`), the EMA codebook
quantiser used during VQ-VAE training, residual dropout hooks, checkpoint I/O.

The model classes are the ones of tools/reference (original state_dict names); this package
adds only what training needs on top of them.
"""
import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

TOOLS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if TOOLS not in sys.path:
    sys.path.insert(0, TOOLS)

from reference.config import Cfg  # noqa: E402
from reference.pipeline import normalise_pos3d, TRANSL_SCALE  # noqa: E402
from reference.tiny import generate_structure, motion_structure, transl_structure, _TRAIN_KEYS, _RUN_KEYS  # noqa: E402
from reference.vqvae import PARTS, SepVQVAEXM, VQVAE  # noqa: E402
from reference.gpt import GPT2nt  # noqa: E402

# The demo size (see docs/DEMO_MODEL.md). The original is n_embd 768 / 6+6 layers / LAT 3 /
# VQ width 512 / codebook 512; block_size 30 and look_forward 29 are kept as in the original.
DEMO = dict(n_embd=128, n_head=4, base_layers=1, head_layers=1, lat_layers=1, block_size=30,
            look_forward=29, vocab=128, vq_width=64, vq_depth=3, emb_width=64, l_bins=128,
            growth=3)
TRANSL = dict(DEMO, vq_width=32, emb_width=32)  # 3-channel input: a narrower stack suffices
RATE = 4            # frames per token (downs_t [2] x strides_t [2])
WINDOW = 240        # original data.train.interval / sample_length
MOVE = 4            # original data.train.move


def yaml_docs(s=DEMO, st=TRANSL):
    """The three YAML documents (dicts) in the original structure for the demo size."""
    bs, lf = s["block_size"], s["look_forward"]
    gpt = {"structure": motion_structure(s), "structure_transl_vqvae": transl_structure(st),
           "structure_generate": generate_structure(s), **_TRAIN_KEYS,
           "music_motion_rate": RATE, "music_len": (bs + lf) * RATE,
           "motion_len": bs, "look_forward_size": lf,
           "testing": {"height": 540, "width": 960, "ckpt_epoch": 1, "music_source": "./data/music/mp3/test/"},
           "vqvae_weight": "./experiments/motion_vqvae/ckpt/epoch_1.pt",
           "transl_vqvae_weight": "./experiments/transl_vqvae/ckpt/epoch_1.pt",
           "expname": "follower_gpt", **_RUN_KEYS, "epoch": 1, "batch_size": 32, "save_per_epochs": 1}
    motion = {"structure": motion_structure(s), **_TRAIN_KEYS,
              "testing": {"height": 540, "width": 960, "ckpt_epoch": 1},
              "expname": "motion_vqvae", **_RUN_KEYS, "epoch": 1}
    transl = {"structure": transl_structure(st), **_TRAIN_KEYS,
              "testing": {"height": 540, "width": 960, "ckpt_epoch": 1, "music_source": "./data/music/mp3"},
              "expname": "transl_vqvae", **_RUN_KEYS, "epoch": 1}
    return {"follower_gpt.yaml": gpt, "motion_vqvae.yaml": motion, "transl_vqvae.yaml": transl}


def demo_size(look_forward=None):
    """The demo size, with another leader/music look-ahead (tokens) when given: the recipe's
    latency knob (`train_gpt.py --look-forward`, docs/DEMO_MODEL.md "Latency chosen at
    training time"). Only the GPT depends on it; the VQ-VAEs are the same for every value."""
    return DEMO if look_forward is None else dict(DEMO, look_forward=int(look_forward))


def checkpoint_look_forward(path):
    """look_forward of a follower GPT checkpoint: stored by train_gpt.py, else read off the
    music LAT's position table ((block_size + look_forward) * 4 rows; 29 for older files)."""
    ck = torch.load(path, map_location="cpu", weights_only=False)
    if "look_forward" in ck:
        return int(ck["look_forward"])
    rows = ck["model"]["music_trans.pos_emb"].shape[1]
    return rows // RATE - DEMO["block_size"]


def build_models(look_forward=None):
    docs = yaml_docs(demo_size(look_forward))
    vq = SepVQVAEXM(Cfg(docs["motion_vqvae.yaml"]).structure)
    tr = VQVAE(Cfg(docs["transl_vqvae.yaml"]).structure)
    gpt = GPT2nt(Cfg(docs["follower_gpt.yaml"]).structure_generate)
    return gpt, vq, tr


def setup_threads():
    torch.set_num_threads(1)
    torch.set_num_interop_threads(1)


# ---------------------------------------------------------------- data (original layout)

def load_split(root, split):
    """Takes of one split: list of dicts with name, leader/follower raw pos3d (T,165),
    rotmat without translation (T,495), music (T,54); lengths cut to min over files and to a
    multiple of 4 (datasets/dd100lf_all2.py)."""
    pdir = os.path.join(root, "motion", "pos3d", split)
    takes = []
    for fname in sorted(os.listdir(pdir)):
        if not fname.endswith("_00.npy"):
            continue
        name = fname[:-7]
        f = np.load(os.path.join(pdir, fname)).astype(np.float32)
        l = np.load(os.path.join(pdir, name + "_01.npy")).astype(np.float32)
        rdir = os.path.join(root, "motion", "rotmat", split)
        fr = np.load(os.path.join(rdir, fname)).astype(np.float32)[:, 3:]
        lr = np.load(os.path.join(rdir, name + "_01.npy")).astype(np.float32)[:, 3:]
        m = np.load(os.path.join(root, "music", "feature", split, name + ".npy")).astype(np.float32)
        t = min(len(f), len(l), len(m)) // MOVE * MOVE
        takes.append(dict(name=name, leader=l[:t], follower=f[:t], leader_rot=lr[:t],
                          follower_rot=fr[:t], music=m[:t]))
    return takes


def normalised(pos):
    """Raw (T,165) -> dataset normalisation (pelvis channel keeps the absolute root)."""
    return normalise_pos3d(torch.from_numpy(pos)).numpy()


# ---------------------------------------------------------------- EMA codebook (models/bottleneck.py)

class EMAQuantiser:
    """Training-time state of one original BottleneckBlock: codebook `k` (the module's buffer,
    the only thing saved, as in the original), EMA sums k_sum / k_elem (plain attributes in
    the original, not in the state_dict), init from the first batch, dead-code restart from
    random batch vectors when the EMA count falls below the threshold, commitment loss and a
    straight-through estimator."""

    def __init__(self, block, mu, threshold=1.0, gen=None):
        self.block, self.mu, self.threshold, self.gen = block, mu, threshold, gen
        self.k_sum = None
        self.k_elem = None

    def _tile(self, x):
        d, ew = x.shape
        bins = self.block.k.shape[0]
        if d < bins:
            x = x.repeat((bins + d - 1) // d, 1)
            x = x + torch.randn(x.shape, generator=self.gen) * (0.01 / np.sqrt(ew))
        return x

    def _rand_rows(self, x):
        y = self._tile(x)
        return y[torch.randperm(y.shape[0], generator=self.gen)][:self.block.k.shape[0]]

    def __call__(self, x, update=True):
        """x (N, emb, T) encoder output -> codes (N, T), straight-through quantised (N, emb, T),
        commitment loss, metrics."""
        n, w, t = x.shape
        flat = x.permute(0, 2, 1).reshape(-1, w)
        blk = self.block
        with torch.no_grad():
            if update and self.k_sum is None:
                blk.k.copy_(self._rand_rows(flat.detach()))
                self.k_sum = blk.k.clone()
                self.k_elem = torch.ones(blk.k.shape[0])
            codes = torch.argmin(blk.distances(flat.detach()), dim=-1)
        xd = F.embedding(codes, blk.k)
        metrics = {}
        if update:
            with torch.no_grad():
                fd = flat.detach()
                onehot = torch.zeros(blk.k.shape[0], fd.shape[0])
                onehot.scatter_(0, codes.view(1, -1), 1)
                k_sum_b = onehot @ fd
                k_elem_b = onehot.sum(-1)
                rand = self._rand_rows(fd)
                self.k_sum = self.mu * self.k_sum + (1 - self.mu) * k_sum_b
                self.k_elem = self.mu * self.k_elem + (1 - self.mu) * k_elem_b
                usage = (self.k_elem.view(-1, 1) >= self.threshold).float()
                blk.k.copy_(usage * (self.k_sum / self.k_elem.view(-1, 1)) + (1 - usage) * rand)
                p = k_elem_b / k_elem_b.sum()
                metrics = dict(used=int((k_elem_b > 0).sum()),
                               perplexity=float(torch.exp(-(p * torch.log(p + 1e-8)).sum())))
        commit = torch.sum((xd.detach() - flat) ** 2) / flat.numel()
        xq = flat + (xd - flat).detach()
        return codes.view(n, t), xq.view(n, t, w).permute(0, 2, 1), commit, metrics


# ---------------------------------------------------------------- dropout (training only)

def add_residual_dropout(module, p, types):
    """The reference modules are eval-only (no Dropout modules, so state_dict names match the
    original exactly). Training adds the original resid_pdrop as forward hooks on the outputs
    of the given submodule types (attention projection and MLP, i.e. where the original's
    resid_drop / mlp Dropout sit). Returns the hook handles."""
    hooks = []
    for m in module.modules():
        if isinstance(m, types):
            hooks.append(m.register_forward_hook(
                lambda mod, inp, out: F.dropout(out, p, training=mod.training)))
    return hooks


# ---------------------------------------------------------------- checkpoints

def save_checkpoint(model, path, epoch=1, **extra):
    """Original checkpoint layout: {'model': state_dict, 'epoch': ...} (the original also
    pickles its config object; we keep only plain data, plus `extra` keys such as the GPT's
    look_forward)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    torch.save({"model": {k: v.detach().clone() for k, v in model.state_dict().items()},
                "epoch": epoch, **extra}, path)


def load_checkpoint(model, path):
    sd = torch.load(path, map_location="cpu", weights_only=False)["model"]
    model.load_state_dict(sd, strict=True)
    return model


class Clock:
    """Wall and process CPU time of a training stage."""

    def __init__(self):
        self.w0, self.c0 = time.time(), time.process_time()

    def __str__(self):
        return f"wall {time.time() - self.w0:.0f} s, cpu {time.process_time() - self.c0:.0f} s"

    def cpu(self):
        return time.process_time() - self.c0
