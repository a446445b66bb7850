"""Motion VQ-VAEs of Duolando: per-part conv encoder, nearest-code quantiser, conv decoders.

State-dict names follow the original (models/encdec.py, models/resnet.py,
models/bottleneck.py, models/vqvae_mix.py, models/vqvae_root_mix.py, models/vqvae.py,
models/sep_vqvae_xm.py). Only `levels == 1` (the released configs) is supported.

Layout conventions: the public functions take motion as (N, T, C) (time-major like the
original callers); convolutions run on (N, C, T).
"""
import torch
import torch.nn as nn
import torch.nn.functional as F

# SMPL-X joint indices of each body part, channel order = list order (models/sep_vqvae_xm.py).
SMPL_DOWN = [0, 1, 2, 4, 5, 7, 8, 10, 11]
SMPL_UP = [3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24]
SMPL_LHAND = list(range(25, 40))
SMPL_RHAND = list(range(40, 55))
PART_JOINTS = {"up": SMPL_UP, "down": SMPL_DOWN, "lhand": SMPL_LHAND, "rhand": SMPL_RHAND}
PARTS = ("up", "down", "lhand", "rhand")


class ResConv1DBlock(nn.Module):
    """x + Conv1x1(ReLU(Conv1d_k3_dil_d(ReLU(x)))); names model.1 / model.3."""

    def __init__(self, width, dilation):
        super().__init__()
        self.model = nn.Sequential(
            nn.ReLU(),
            nn.Conv1d(width, width, 3, 1, dilation, dilation),
            nn.ReLU(),
            nn.Conv1d(width, width, 1, 1, 0),
        )

    def forward(self, x):  # (N, width, T) -> (N, width, T)
        return x + self.model(x)


class Resnet1D(nn.Module):
    """`depth` residual blocks with dilations growth**d; reversed order in decoders."""

    def __init__(self, width, depth, growth, reverse=False):
        super().__init__()
        blocks = [ResConv1DBlock(width, growth ** d) for d in range(depth)]
        if reverse:
            blocks = blocks[::-1]
        self.model = nn.Sequential(*blocks)

    def forward(self, x):
        return self.model(x)


class EncoderConvBlock(nn.Module):
    """[Conv1d(k=2s, stride s, pad s//2) -> Resnet1D] x down_t -> Conv1d(k3, p1) to emb_width."""

    def __init__(self, in_ch, emb_width, down_t, stride_t, width, depth, growth):
        super().__init__()
        blocks = []
        for i in range(down_t):
            blocks.append(nn.Sequential(
                nn.Conv1d(in_ch if i == 0 else width, width, stride_t * 2, stride_t, stride_t // 2),
                Resnet1D(width, depth, growth),
            ))
        blocks.append(nn.Conv1d(width, emb_width, 3, 1, 1))
        self.model = nn.Sequential(*blocks)

    def forward(self, x):  # (N, C, T) -> (N, emb, T / stride**down)
        return self.model(x)


class DecoderConvBlock(nn.Module):
    """Conv1d(k3) emb->width -> [Resnet1D(reversed) -> ConvTranspose1d(k=2s, s, s//2)] x down_t.

    The last transposed conv outputs emb_width channels (the original passes emb_width as the
    block's "input" width); `Decoder.out` then maps emb_width -> C.
    """

    def __init__(self, emb_width, down_t, stride_t, width, depth, growth, reverse):
        super().__init__()
        blocks = [nn.Conv1d(emb_width, width, 3, 1, 1)]
        for i in range(down_t):
            blocks.append(nn.Sequential(
                Resnet1D(width, depth, growth, reverse=reverse),
                nn.ConvTranspose1d(width, emb_width if i == down_t - 1 else width,
                                   stride_t * 2, stride_t, stride_t // 2),
            ))
        self.model = nn.Sequential(*blocks)

    def forward(self, x):  # (N, emb, Q) -> (N, emb, Q * stride**down)
        return self.model(x)


def _check_levels(hps):
    if hps.levels != 1 or len(hps.downs_t) != 1 or len(hps.strides_t) != 1:
        raise ValueError(f"only levels == 1 is supported, got levels={hps.levels}")
    if float(hps.get("m_conv", 1.0)) != 1.0 or hps.get("dilation_cycle") is not None:
        raise ValueError("only m_conv == 1.0 and dilation_cycle == None are supported")
    mult = hps.get("hvqvae_multipliers", [1])
    if list(mult) != [1]:
        raise ValueError(f"only hvqvae_multipliers [1] is supported, got {mult}")


class Encoder(nn.Module):
    """names: level_blocks.0.model.*"""

    def __init__(self, in_ch, hps):
        super().__init__()
        _check_levels(hps)
        self.level_blocks = nn.ModuleList([EncoderConvBlock(
            in_ch, hps.emb_width, hps.downs_t[0], hps.strides_t[0], hps.width, hps.depth,
            hps.dilation_growth_rate)])

    def forward(self, x):  # (N, C, T) -> (N, emb, T/4)
        return self.level_blocks[0](x)


class Decoder(nn.Module):
    """names: level_blocks.0.model.*, out"""

    def __init__(self, out_ch, hps):
        super().__init__()
        _check_levels(hps)
        self.level_blocks = nn.ModuleList([DecoderConvBlock(
            hps.emb_width, hps.downs_t[0], hps.strides_t[0], hps.width, hps.depth,
            hps.dilation_growth_rate, bool(hps.vqvae_reverse_decoder_dilation))])
        self.out = nn.Conv1d(hps.emb_width, out_ch, 3, 1, 1)

    def forward(self, x):  # (N, emb, Q) -> (N, out_ch, 4Q)
        return self.out(self.level_blocks[0](x))


class BottleneckBlock(nn.Module):
    """Nearest-codebook-row quantiser; buffer `k` (l_bins, emb_width)."""

    def __init__(self, l_bins, emb_width):
        super().__init__()
        self.register_buffer("k", torch.zeros(l_bins, emb_width))

    def distances(self, x):  # x (M, emb) -> (M, l_bins), same expression as the original
        k_w = self.k.t()
        return (torch.sum(x ** 2, dim=-1, keepdim=True) - 2 * torch.matmul(x, k_w)
                + torch.sum(k_w ** 2, dim=0, keepdim=True))

    def encode(self, x):  # (N, emb, T) -> codes (N, T) int64
        n, w, t = x.shape
        flat = x.permute(0, 2, 1).reshape(-1, w)  # (N*T, emb)
        return torch.argmin(self.distances(flat), dim=-1).view(n, t)

    def decode(self, codes):  # (N, Q) -> (N, emb, Q)
        return F.embedding(codes, self.k).permute(0, 2, 1)


class Bottleneck(nn.Module):
    """names: level_blocks.0.k"""

    def __init__(self, l_bins, emb_width):
        super().__init__()
        self.level_blocks = nn.ModuleList([BottleneckBlock(l_bins, emb_width)])


class PartVQVAE(nn.Module):
    """One body part (original VQVAEmix; with_root=True is VQVAERmix, whose `decoders_root`
    is a training-only root-velocity head, kept for state_dict round trips)."""

    def __init__(self, hps, with_root=False):
        super().__init__()
        self.hps = hps
        self.encoders = nn.ModuleList([Encoder(hps.pos_channel, hps)])
        self.decoders = nn.ModuleList([Decoder(hps.pos_channel, hps)])
        self.decoders_rot = nn.ModuleList([Decoder(hps.rot_channel, hps)])
        if with_root:
            self.decoders_root = nn.ModuleList([Decoder(hps.joint_channel, hps)])
        self.bottleneck = Bottleneck(hps.l_bins, hps.emb_width)

    def features(self, x):  # (N, T, C) -> pre-quantisation (N, emb, T/4); no zeroing
        return self.encoders[0](x.permute(0, 2, 1))

    def encode(self, x):
        """(N, T, C) -> codes (N, T/4). Like the original encode(): the part's first joint
        (joint_channel channels) is zeroed first (on a copy)."""
        x = x.clone()
        x[:, :, :self.hps.joint_channel] = 0
        return self.bottleneck.level_blocks[0].encode(self.features(x))

    def decode(self, codes):  # (N, Q) -> pos (N, 4Q, C), rot (N, 4Q, 3C)
        z = self.bottleneck.level_blocks[0].decode(codes)
        pos = self.decoders[0](z).permute(0, 2, 1)
        rot = self.decoders_rot[0](z).permute(0, 2, 1)
        return pos, rot


class SepVQVAEXM(nn.Module):
    """Four part VQ-VAEs: vqvae_up, vqvae_down (with decoders_root), vqvae_lhand, vqvae_rhand."""

    def __init__(self, hps):
        super().__init__()
        self.hps = hps
        self.vqvae_up = PartVQVAE(hps.up_half)
        self.vqvae_down = PartVQVAE(hps.down_half, with_root=True)
        self.vqvae_lhand = PartVQVAE(hps.lhand)
        self.vqvae_rhand = PartVQVAE(hps.rhand)

    def part(self, name):
        return getattr(self, "vqvae_" + name)

    @staticmethod
    def split(x, name):  # (N, T, 165) -> (N, T, 3 * len(joints))
        n, t, c = x.shape
        return x.view(n, t, c // 3, 3)[:, :, PART_JOINTS[name]].reshape(n, t, -1)

    def encode(self, x):
        """(N, T, 165) normalised positions -> tuple of 4 code tensors (N, T/4), part order."""
        return tuple(self.part(p).encode(self.split(x, p)) for p in PARTS)

    def decode(self, zs):
        """4 code tensors (N, Q) -> positions (N, 4Q, 165), rotations (N, 4Q, 495)."""
        outs = [self.part(p).decode(z) for p, z in zip(PARTS, zs)]
        n, t = outs[0][0].shape[:2]
        pos = outs[0][0].new_zeros(n, t, 55, 3)  # (N, 4Q, J, 3)
        rot = outs[0][0].new_zeros(n, t, 55, 9)  # (N, 4Q, J, 9)
        for p, (xp, xr) in zip(PARTS, outs):
            pos[:, :, PART_JOINTS[p]] = xp.reshape(n, t, -1, 3)
            rot[:, :, PART_JOINTS[p]] = xr.reshape(n, t, -1, 9)
        return pos.view(n, t, -1), rot.view(n, t, -1)


class VQVAE(nn.Module):
    """Relative-translation VQ-VAE (original models/vqvae.py): input_dim channels, no zeroing."""

    def __init__(self, hps):
        super().__init__()
        self.hps = hps
        self.encoders = nn.ModuleList([Encoder(hps.input_dim, hps)])
        self.decoders = nn.ModuleList([Decoder(hps.input_dim, hps)])
        self.bottleneck = Bottleneck(hps.l_bins, hps.emb_width)

    def features(self, x):  # (N, T, 3) -> (N, emb, T/4)
        return self.encoders[0](x.permute(0, 2, 1))

    def encode(self, x):  # (N, T, 3) -> (N, T/4)
        return self.bottleneck.level_blocks[0].encode(self.features(x))

    def decode(self, codes):  # (N, Q) -> (N, 4Q, 3)
        z = self.bottleneck.level_blocks[0].decode(codes)
        return self.decoders[0](z).permute(0, 2, 1)
