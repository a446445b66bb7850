"""Tiny model configs with the ORIGINAL YAML structure, and seeded random weights.

Config dicts mirror configs/follower_gpt_beta0.9_final.yaml, configs/sep_vqvaexm_full_final.yaml
and configs/transl_vqvaex_final.yaml key for key (training-only keys kept with their values).
"""
import math

import numpy as np
import torch

from .config import Cfg
from .gpt import GPT2nt
from .synth import pair
from .pipeline import normalise_pos3d, TRANSL_SCALE
from .vqvae import PARTS, SepVQVAEXM, VQVAE

SIZES = {
    "tiny": dict(n_embd=32, n_head=4, base_layers=2, head_layers=2, lat_layers=2, block_size=30,
                 look_forward=29, vocab=64, vq_width=16, vq_depth=3, emb_width=16, l_bins=64,
                 growth=3),
    "tiny2": dict(n_embd=24, n_head=2, base_layers=1, head_layers=2, lat_layers=1, block_size=8,
                  look_forward=5, vocab=48, vq_width=12, vq_depth=2, emb_width=8, l_bins=48,
                  growth=3),
}
PART_SECTIONS = {"up": "up_half", "down": "down_half", "lhand": "lhand", "rhand": "rhand"}
POS_CHANNELS = {"up": 48, "down": 27, "lhand": 45, "rhand": 45}


def _vq_common(s):
    return {"levels": 1, "downs_t": [2], "strides_t": [2], "emb_width": s["emb_width"],
            "l_bins": s["l_bins"], "l_mu": 0.99, "commit": 0.02, "hvqvae_multipliers": [1],
            "width": s["vq_width"], "depth": s["vq_depth"], "m_conv": 1.0,
            "dilation_growth_rate": s["growth"], "sample_length": 240, "use_bottleneck": True,
            "joint_channel": 3}


def motion_structure(s):
    d = {}
    for p in PARTS:
        sec = _vq_common(s)
        sec.update({"rot_joint_channel": 9, "pos_channel": POS_CHANNELS[p],
                    "rot_channel": POS_CHANNELS[p] * 3, "vel": 1, "acc": 1,
                    "vqvae_reverse_decoder_dilation": True})
        d[PART_SECTIONS[p]] = sec
    d = {"name": "SepVQVAEXM", **d, "use_bottleneck": True, "joint_channel": 3,
         "rot_joint_channel": 9, "l_bins": s["l_bins"]}
    return d


def transl_structure(s):
    d = {"name": "VQVAE", **_vq_common(s), "input_dim": 3, "vel": 1, "acc": 1,
         "vqvae_reverse_decoder_dilation": True}
    return d


def _lat(s, n_music, ds):
    e = s["n_embd"]
    return {"n_music": n_music, "embd_pdrop": 0.1, "resid_pdrop": 0.1, "attn_pdrop": 0.1,
            "n_layer": s["lat_layers"], "n_embd": e, "downsample_rate": ds,
            "block_size": s["block_size"], "look_forward": s["look_forward"], "n_head": s["n_head"],
            "n_music_emb": e}


def generate_structure(s):
    e, v, bs, lf = s["n_embd"], s["vocab"], s["block_size"], s["look_forward"]
    return {
        "name": "GPT2ntLN", "block_size": bs, "look_forward": lf,
        "vocab_size_up": v, "vocab_size_down": v, "vocab_size_lhand": v, "vocab_size_rhand": v,
        "vocab_size_transl": v, "n_embd": e,
        "base": {"embd_pdrop": 0.1, "resid_pdrop": 0.1, "attn_pdrop": 0.1, "vocab_size_up": v,
                 "vocab_size_down": v, "block_size": bs, "look_forward": lf,
                 "n_layer": s["base_layers"], "n_head": s["n_head"], "n_embd": e, "n_music": e,
                 "n_music_emb": e},
        "head": {"embd_pdrop": 0.1, "resid_pdrop": 0.1, "attn_pdrop": 0.1, "vocab_size": v,
                 "block_size": bs, "look_forward": lf, "n_layer": s["head_layers"],
                 "n_head": s["n_head"], "n_embd": e, "vocab_size_up": v, "vocab_size_down": v,
                 "vocab_size_transl": v},
        "music_trans": _lat(s, 54, 4),
        "leader_up_trans": _lat(s, e, 1),
        "leader_down_trans": _lat(s, e, 1),
        "leader_lhand_trans": _lat(s, e, 1),
        "leader_rhand_trans": _lat(s, e, 1),
        "n_music": 54, "n_music_emb": e,
    }


_TRAIN_KEYS = {
    "loss_weight": {"mse_weight": 1},
    "optimizer": {"type": "Adam", "kwargs": {"lr": 0.0003, "betas": [0.9, 0.999], "weight_decay": 0},
                  "schedular_kwargs": {"milestones": [100, 200], "gamma": 0.1}},
    "data": {"train": {"music_root": "./data/music", "data_root": "./data/motion", "move": 4,
                       "dtype": "both", "split": "train", "interval": 240, "batch_size": 128,
                       "music_dance_rate": 1},
             "test": {"music_root": "./data/music", "data_root": "./data/motion", "move": 4,
                      "dtype": "both", "split": "test", "interval": None, "music_dance_rate": 1}},
}
_RUN_KEYS = {"epoch": 500, "batch_size": 32, "save_per_epochs": 20, "test_freq": 500,
             "log_per_updates": 1, "seed": 42, "rotmat": False, "cuda": True, "global_vel": False,
             "ds_rate": 4, "move_train": 4}


def yaml_docs(name):
    """The three YAML documents (as dicts) for model size `name`."""
    s = SIZES[name]
    gpt = {"structure": motion_structure(s), "structure_transl_vqvae": transl_structure(s),
           "structure_generate": generate_structure(s), **_TRAIN_KEYS,
           "music_motion_rate": 4, "music_len": (s["block_size"] + s["look_forward"]) * 4 - 4,
           "motion_len": s["block_size"], "look_forward_size": s["look_forward"],
           "testing": {"height": 540, "width": 960, "ckpt_epoch": 500, "music_source": "./data/music/mp3/test/"},
           "vqvae_weight": "./experiments/motion_vqvae/ckpt/epoch_500.pt",
           "transl_vqvae_weight": "./experiments/transl_vqvae/ckpt/epoch_500.pt",
           "expname": "follower_gpt", **_RUN_KEYS, "epoch": 250, "batch_size": 256, "save_per_epochs": 10}
    motion = {"structure": motion_structure(s), **_TRAIN_KEYS,
              "testing": {"height": 540, "width": 960, "ckpt_epoch": 500},
              "expname": "motion_vqvae", **_RUN_KEYS}
    transl = {"structure": transl_structure(s), **_TRAIN_KEYS,
              "testing": {"height": 540, "width": 960, "ckpt_epoch": 300, "music_source": "./data/music/mp3"},
              "expname": "transl_vqvae_final_512", **_RUN_KEYS}
    return {"follower_gpt.yaml": gpt, "motion_vqvae.yaml": motion, "transl_vqvae.yaml": transl}


def build(name):
    docs = yaml_docs(name)
    gpt_doc = Cfg(docs["follower_gpt.yaml"])
    vq = SepVQVAEXM(Cfg(docs["motion_vqvae.yaml"]).structure)
    tr = VQVAE(Cfg(docs["transl_vqvae.yaml"]).structure)
    gpt = GPT2nt(gpt_doc.structure_generate)
    return gpt, vq, tr


def init_random(module, gen, head_gain=1.0):
    """Seeded non-trivial values for every parameter (masks and codebooks handled elsewhere)."""
    for name, p in module.named_parameters():
        with torch.no_grad():
            if name.endswith("pos_emb"):
                p.copy_(torch.randn(p.shape, generator=gen) * 0.5)
            elif ".ln" in name or name.startswith("ln"):
                base = 1.0 if name.endswith("weight") else 0.0
                p.copy_(base + torch.randn(p.shape, generator=gen) * 0.1)
            elif "tok_emb" in name:
                p.copy_(torch.randn(p.shape, generator=gen))
            elif name.endswith("bias"):
                p.copy_(torch.randn(p.shape, generator=gen) * 0.05)
            else:  # Linear / Conv / ConvTranspose weights
                fan_in = p.shape[1] * (p.shape[2] if p.ndim == 3 else 1)
                gain = head_gain if ".head_" in name else 1.0
                p.copy_(torch.randn(p.shape, generator=gen) * gain / math.sqrt(fan_in))


def init_codebooks(vq, tr, gen_seed, l_bins):
    """Codebook rows = encoder features of synthetic motion (like the original init_k), plus
    noise, so that codes vary along a sequence and nearest codes are well separated."""
    feats = {p: [] for p in PARTS}
    tfeats = []
    with torch.no_grad():
        for i in range(3):
            leader, follower, _ = pair(10_000 + gen_seed * 10 + i, 480)
            for who in (leader, follower):
                norm = normalise_pos3d(torch.from_numpy(who))
                norm[:, :3] = 0
                for p in PARTS:
                    x = vq.split(norm[None], p).clone()
                    x[:, :, :3] = 0
                    feats[p].append(vq.part(p).features(x)[0].t())
            rel = (torch.from_numpy(follower[:, :3]) - torch.from_numpy(leader[:, :3])) * TRANSL_SCALE
            tfeats.append(tr.features(rel[None])[0].t())
        rng = np.random.default_rng(gen_seed)
        for block, rows in [(vq.part(p).bottleneck.level_blocks[0], torch.cat(feats[p])) for p in PARTS] + \
                           [(tr.bottleneck.level_blocks[0], torch.cat(tfeats))]:
            idx = rng.choice(rows.shape[0], size=l_bins, replace=rows.shape[0] < l_bins)
            k = rows[torch.from_numpy(idx)]
            noise = torch.from_numpy(rng.normal(0, 1, size=k.shape).astype(np.float32))
            block.k.copy_(k + noise * rows.std(0, keepdim=True) * 0.3)
