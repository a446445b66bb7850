"""Tiny Bailando configs in the AUTHORS' YAML structure (configs/actor_critic.yaml and
configs/actor_critic_demo.yaml, key for key, training keys kept), seeded random weights and
codebooks made of encoder features of synthetic dances."""
import copy

import numpy as np
import torch

from ..tiny import init_random  # our Duolando init: the same parameter-name rules fit Bailando
from . import synth

# hop = strides_t ** downs_t dance frames per token; window = block_size - 1
SIZES = {
    "btiny": dict(vq_width=16, vq_depth=2, downs_t=3, emb_width=16, l_bins=24, growth=3,
                  n_embd=32, n_head=4, base_layers=1, head_layers=1, critic_layers=1,
                  block_size=8, n_music=438),
    "btiny2": dict(vq_width=20, vq_depth=3, downs_t=2, emb_width=12, l_bins=32, growth=2,
                   n_embd=40, n_head=2, base_layers=2, head_layers=2, critic_layers=1,
                   block_size=12, n_music=72),
}
CONFIG_FILES = ("actor_critic.yaml", "actor_critic_demo.yaml")


def _half(s):
    return {"levels": 1, "downs_t": [s["downs_t"]], "strides_t": [2], "emb_width": s["emb_width"],
            "l_bins": s["l_bins"], "l_mu": 0.99, "commit": 0.02, "hvqvae_multipliers": [1],
            "width": s["vq_width"], "depth": s["vq_depth"], "m_conv": 1.0,
            "dilation_growth_rate": s["growth"], "sample_length": 240, "use_bottleneck": True,
            "joint_channel": 3, "vqvae_reverse_decoder_dilation": True}


def _gpt_part(s, drop, **extra):
    return {"embd_pdrop": drop, "resid_pdrop": drop, "attn_pdrop": drop, **extra}


def yaml_docs(name):
    """{file name: dict} for model `name`: actor_critic.yaml (AIST++ test path) and
    actor_critic_demo.yaml (music-only demo path), as in the authors' configs/."""
    s = SIZES[name]
    e, v, bs = s["n_embd"], s["l_bins"], s["block_size"]
    structure = {"name": "SepVQVAER", "up_half": _half(s), "down_half": _half(s),
                 "use_bottleneck": True, "joint_channel": 3}
    generate = {
        "name": "CrossCondGPT2AC", "block_size": bs,
        "base": _gpt_part(s, 0.1, vocab_size_up=v, vocab_size_down=v, block_size=bs,
                          n_layer=s["base_layers"], n_head=s["n_head"], n_embd=e,
                          n_music=s["n_music"], n_music_emb=e),
        "head": _gpt_part(s, 0.1, vocab_size=v, block_size=bs, n_layer=s["head_layers"],
                          n_head=s["n_head"], n_embd=e, vocab_size_up=v, vocab_size_down=v),
        "critic_net": _gpt_part(s, 0.0, block_size=bs, n_layer=s["critic_layers"], n_head=s["n_head"],
                                n_embd=e, vocab_size_up=1, vocab_size_down=1),
        "n_music": s["n_music"], "n_music_emb": e,
    }
    aist = {
        "structure": structure, "structure_generate": generate,
        "reward": {"name": "UpDownReward", "rate": 0},
        "loss_weight": {"mse_weight": 1},
        "optimizer": {"type": "Adam", "kwargs": {"lr": 1e-05, "betas": [0.5, 0.999], "weight_decay": 0},
                      "schedular_kwargs": {"milestones": [40], "gamma": 1}},
        "data": {"name": "aist", "train_dir": "data/aistpp_test_full_wav", "test_dir": "data/aistpp_test_full_wav",
                 "seq_len": 240, "data_type": "None"},
        "testing": {"height": 540, "width": 960, "ckpt_epoch": 10},
        "need_not_train_data": True,
        "vqvae_weight": "experiments/sep_vqvae_root/ckpt/epoch_500.pt",
        "expname": "actor_critic", "init_weight": "experiments/cc_motion_gpt/ckpt/epoch_400.pt",
        "epoch": 500, "batch_size": 128, "save_per_epochs": 5, "test_freq": 5, "log_per_updates": 1,
        "seed": 42, "rotmat": False, "cuda": True, "global_vel": True, "ds_rate": 8, "move": 8,
        "external_wav": "data/aistpp_music_feat_7.5fps", "external_wav_rate": 1,
        "gamma": 1.0, "pretrain_critic_epoch": 0, "critic_iter": 5, "actor_iter": 5,
        "sample_code_rate": 8, "use_entropy": False, "entropy_alpha": 0.0, "actor_loss_decay": 1,
        "demo": False, "rl_music_root": "data/aistpp_test_full_wav",
    }
    demo = copy.deepcopy(aist)
    demo["data"].update(train_dir="data/demo_music_feat_7.5fps", test_dir="data/demo_music_feat_7.5fps")
    demo["testing"]["ckpt_epoch"] = 5
    del demo["need_not_train_data"], demo["external_wav"], demo["external_wav_rate"]
    demo.update(expname="actor_critic_for_demo_paper", epoch=50, save_per_epochs=1, ds_rate=1, demo=True,
                rl_music_root="data/demo_music_feat_60fps")
    return {"actor_critic.yaml": aist, "actor_critic_demo.yaml": demo}


def init_weights(vq, gpt, vq_seed, gpt_seed, root_gain=0.02):
    """Seeded values for every parameter (tools/reference/tiny.py `init_random` rules). The
    root decoder's output conv is scaled by `root_gain`: per-frame pelvis velocities of a few
    mm, like real 60 fps motion, so the float32 running sum stays small."""
    if vq_seed is not None:
        init_random(vq, torch.Generator().manual_seed(vq_seed))
        with torch.no_grad():
            out = vq.vqvae_down.decoders_root[0].out
            out.weight.mul_(root_gain)
            out.bias.mul_(root_gain)
    if gpt_seed is not None:
        init_random(gpt, torch.Generator().manual_seed(gpt_seed))


def loader_dance(d):
    """pelvis-relative joints with the world pelvis in 0:3 (the loader's normalisation)."""
    d = d.astype(np.float64)
    root = d[:, :3].copy()
    d = d - np.tile(root, (1, 24))
    d[:, :3] = root
    return d


def part_features(auth, vq, dance64):
    """{part: (n, emb) encoder features} of one normalised dance, parts as SepVQVAER.encode
    splits them; the down part's first joint zeroed as VQVAER.encode does."""
    x = torch.from_numpy(dance64).float().view(1, -1, 24, 3)
    out = {}
    for name, joints, zero in (("up", auth.smpl_up, False), ("down", auth.smpl_down, True)):
        part = getattr(vq, "vqvae_" + name)
        xp = x[:, :, joints].reshape(1, x.shape[1], -1).clone()
        if zero:
            xp[:, :, :3] = 0
        out[name] = part.encoders[0](part.preprocess(xp))[-1][0].t()
    return out


def init_codebooks(auth, vq, cb_seed, l_bins, frames=480):
    """Codebook rows = encoder features of synthetic dances (like the authors' `init_k`,
    random rows of the data) plus noise of 0.3 x the feature std, so codes vary in a sequence
    and nearest codes are well separated."""
    feats = {"up": [], "down": []}
    with torch.no_grad():
        for i in range(3):
            d = synth.dance(np.random.default_rng(50_000 + 10 * cb_seed + i), frames)
            for k, v in part_features(auth, vq, loader_dance(d)).items():
                feats[k].append(v)
        rng = np.random.default_rng(cb_seed)
        for name in ("up", "down"):
            rows = torch.cat(feats[name])
            idx = rng.choice(rows.shape[0], size=l_bins, replace=rows.shape[0] < l_bins)
            k = rows[torch.from_numpy(idx)]
            noise = torch.from_numpy(rng.normal(0, 1, size=k.shape).astype(np.float32))
            getattr(vq, "vqvae_" + name).bottleneck.level_blocks[0].k.copy_(k + noise * rows.std(0, keepdim=True) * 0.3)
