"""Our driver of the authors' Bailando inference: `AC.eval()` (actor_critic.py) for ONE test
file, with the loader step it depends on (utils/functional.py `load_test_data_aist`, as
`AC._build_test_loader` calls it: rotmat False, wav_padding 0) and the post-processing of
`visualizeAndWrite` (utils/functional.py) up to `pred_position`, the array `write2pkl` saves.

Model calls are the authors' methods: `vqvae.module.encode`, `gpt.module.sample`,
`vqvae.module.decode`. Only the glue between them is restated here, line for line.
"""
import numpy as np
import torch

from ..pipeline import Margins, MarginTooSmall  # noqa: F401  (re-exported)

DEMO_SEED = (423, 12)  # AC.eval demo branch: x = (ones(1,1)*423, ones(1,1)*12)


def _pad_last(a, move):
    """`for kk in range((len(a) // move + 1) * move - len(a)): a = append(a, a[-1:])`:
    1..move copies of the last row (a full `move` when len(a) is already a multiple)."""
    n = (len(a) // move + 1) * move - len(a)
    return np.concatenate([a] + [a[-1:]] * n, axis=0) if len(a) else a


def load_test_sample(cfg, music, dance=None):
    """One file of `load_test_data_aist`. `music` (R, C): the `music_array` the loader reads
    (the external_wav file on the AIST++ path, the test_dir file on the demo path); `dance`
    (T, 72) world joints (`dance_array`) or None. JSON gives float64: so do we.
    Returns (music (R', C) float64, dance (T', 72) float64 or None)."""
    move = cfg.move
    external_wav = cfg.external_wav if hasattr(cfg, "external_wav") else None
    external_wav_rate = cfg.external_wav_rate if hasattr(cfg, "external_wav_rate") else 1
    np_music = np.asarray(music, dtype=np.float64)
    np_dance = None
    if dance is not None:
        np_dance = np.asarray(dance, dtype=np.float64)
        if not cfg.rotmat:
            root = np_dance[:, :3]
            np_dance = np_dance - np.tile(root, (1, 24))
            np_dance[:, :3] = root
        np_dance = _pad_last(np_dance, move)
    music_move = external_wav_rate if external_wav is not None else move
    np_music = _pad_last(np_music, music_move)
    return np_music, np_dance


class _Hooks:
    """Forward hooks that watch the authors' modules: logits of every sampling step (last
    window position, both heads) and the encoder features of every nearest-code decision."""

    def __init__(self, vq, gpt, margins):
        self.logits = []
        self.handles = [gpt.gpt_head.register_forward_hook(self._head)]
        self.margins = margins
        for name in ("up", "down"):
            part = getattr(vq, "vqvae_" + name)
            block = part.bottleneck.level_blocks[0]
            self.handles.append(part.encoders[0].register_forward_hook(
                lambda m, i, o, block=block: self._vq(block, o[-1])))

    def _head(self, module, inp, out):
        lu, ld = out[0][0, -1].detach().clone(), out[1][0, -1].detach().clone()
        self.logits.append((lu, ld))
        if self.margins is not None:
            self.margins.logits(lu)
            self.margins.logits(ld)

    def _vq(self, block, feats):
        if self.margins is not None:
            self.margins.vq(block, feats)

    def close(self):
        for h in self.handles:
            h.remove()


def eval_one(vqvae, gpt, cfg, music, dance=None, seed_tokens=None, margins=None):
    """`AC.eval()` on one test file. `vqvae`, `gpt`: the authors' models wrapped in
    nn.DataParallel (as `AC._build_model`), eval mode. `cfg.demo` selects the path:
    AIST++ (dance given, seed = first code of the encoded dance) or demo (music only, seed
    tokens = `seed_tokens` (up, down), default the authors' hard-coded (423, 12)).

    Returns dict: tokens int64 (K+1, 2) [up, down] (row 0 = seed), pos3d float32 (N, 72)
    (= pred_position), dance_codes int64 (n, 2) or None, logits_step0 float32 (2, V) or None,
    K, n_frames, music_rows (after padding), dance_frames (after padding)."""
    demo = bool(getattr(cfg, "demo", False))
    np_music, np_dance = load_test_sample(cfg, music, None if demo else dance)
    hooks = _Hooks(vqvae.module, gpt.module, margins)
    try:
        with torch.no_grad():
            # DataLoader(batch_size=1) default collate: float64 tensors with a batch axis
            music_seq = torch.from_numpy(np_music)[None]
            dance_codes = None
            if demo:
                up, down = DEMO_SEED if seed_tokens is None else (int(seed_tokens[0]), int(seed_tokens[1]))
                quants = ([torch.ones(1, 1).long() * up], [torch.ones(1, 1).long() * down])
            else:
                pose_seq = torch.from_numpy(np_dance)[None]
                quants = vqvae.module.encode(pose_seq)
                dance_codes = torch.stack([quants[0][0][0], quants[1][0][0]], dim=1)
            x = tuple(quants[i][0][:, :1] for i in range(len(quants)))
            music_ds_rate = cfg.ds_rate if not hasattr(cfg, "external_wav") else cfg.external_wav_rate
            music_seq = music_seq[:, :, :cfg.structure_generate.n_music // music_ds_rate].contiguous().float()
            b, t, c = music_seq.size()
            music_seq = music_seq.view(b, t // music_ds_rate, c * music_ds_rate)
            music_seq = music_seq[:, 1:]
            zs = gpt.module.sample(x, cond=music_seq)
            pose_sample = vqvae.module.decode(zs)
            if cfg.global_vel:
                global_vel = pose_sample[:, :, :3].clone()
                pose_sample[:, 0, :3] = 0
                for iii in range(1, pose_sample.size(1)):
                    pose_sample[:, iii, :3] = pose_sample[:, iii - 1, :3] + global_vel[:, iii - 1, :]
    finally:
        hooks.close()
    # visualizeAndWrite (config.data.name == "aist", rotmat False) -> write2pkl pred_position
    np_dance_out = pose_sample[0].data.cpu().numpy()
    root = np_dance_out[:, :3]
    np_dance_out = np_dance_out + np.tile(root, (1, 24))
    np_dance_out[:, :3] = root
    tokens = torch.stack([zs[0][0][0], zs[1][0][0]], dim=1)
    lg0 = torch.stack(hooks.logits[0]) if hooks.logits else None
    return {"tokens": tokens, "pos3d": np_dance_out, "dance_codes": dance_codes, "logits_step0": lg0,
            "K": int(music_seq.shape[1]), "n_frames": int(np_dance_out.shape[0]),
            "music_rows": int(np_music.shape[0]), "dance_frames": None if np_dance is None else int(np_dance.shape[0])}
