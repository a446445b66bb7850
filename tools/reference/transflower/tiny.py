"""Tiny hparams in the authors' YAML structure, and a seeded initialisation of every tensor.

Each config keeps the structure and the options of a published one
(training/hparams/dance_combined/) and only shrinks sizes:
- `paper`:  transflower_expmap.yaml (the paper's): 2 continuous inputs, output_lengths 3,
  cond = first output_lengths rows, channel-concat couplings, BatchNorm, coupling pos. encoding,
  Gaussian base. Sizes 120/140 -> 12/14, dims 69/85 -> 11/7, dhid 800 -> 16, 12 -> 3 layers,
  16 -> 3 flow steps, dhid_flow 512 (default) -> 12, num_heads_flow 8 (default) -> 3.
- `label`:  transflower_expmap_cr4_label_bs5.yaml: discrete style input ("single"), learned
  relative attention bias in the input encoders, (zero-buffer) positional encoding in the
  cross-modal transformer, sequence-concat couplings over conditioning_seq_lens rows,
  ActNorm, Student-t base (df = flow_dist_param default 50). Even motion dim (10) on purpose.
- `real`:   the paper config with the REAL feature dims (69, 85) and windows (120, 140,
  output_time_offsets 120) but tiny widths: long free-running goldens where the windows slide.
"""
import torch

PAPER = {
    "model": "transflower",
    "dins": "11,7",
    "douts": "11",
    "input_modalities": "expmap_scaled_20,audio_feats_scaled_20",
    "output_modalities": "expmap_scaled_20",
    "input_lengths": "12,14",
    "output_lengths": 3,
    "output_time_offsets": 12,
    "nlayers": 3,
    "nhead": 2,
    "scales": "[[3,0]]",
    "num_glow_coupling_blocks": 2,
    "glow_use_attn": True,
    "use_transformer_nn": True,
    "use_pos_emb_coupling": True,
    "dhid": 16,
    "dhid_flow": 12,
    "num_heads_flow": 3,
    "cond_concat_dims": True,
    "glow_norm_layer": "batchnorm",
    "glow_bn_momentum": 0.1,
    "dropout": 0,
}

LABEL = {
    "model": "transflower",
    "dins": "6,10,7",
    "douts": "10",
    "input_modalities": "dance_style,expmap_cr_scaled_20,audio_feats_scaled_20",
    "output_modalities": "expmap_cr_scaled_20",
    "input_lengths": "1,12,14",
    "output_lengths": 1,
    "output_time_offsets": 12,
    "input_fix_length_types": "single,end,end",
    "input_types": "d,c,c",
    "input_num_tokens": "5,0,0",
    "nlayers": 2,
    "nhead": 2,
    "scales": "[[4,0]]",
    "num_glow_coupling_blocks": 2,
    "glow_use_attn": True,
    "use_transformer_nn": True,
    "use_rel_pos_emb_inputs": True,
    "use_pos_emb_output": True,
    "flow_dist": "studentT",
    "dhid": 16,
    "dhid_flow": 12,
    "num_heads_flow": 3,
    "cond_concat_dims": False,
    "conditioning_seq_lens": 8,
    "glow_norm_layer": "actnorm",
    "glow_bn_momentum": 0.1,
    "dropout": 0,
}

REAL = dict(PAPER, **{
    "dins": "69,85",
    "douts": "69",
    "input_lengths": "120,140",
    "output_time_offsets": 120,
    "nlayers": 2,
    "scales": "[[2,0]]",
    "dhid_flow": 8,
    "num_heads_flow": 2,
})

CONFIGS = {"paper": PAPER, "label": LABEL, "real": REAL}


def init_weights(model, seed):
    """Every tensor of the state dict gets seeded values (in place), including the ones the
    authors' init leaves at zero / one / identity, so that a missing term shows in the goldens:
    positional buffers `pe` (zeros in every trained checkpoint: a buffer, never optimised),
    relative biases `pos_emb`, norm statistics, LayerNorm affine, biases, the masked-out
    triangles of the LU factors `l` / `u` (the mask must be applied), weight-norm g and v.
    Kept: the permutation `p`, `sign_s` (from the authors' seeded init), `bounds`."""
    g = torch.Generator().manual_seed(seed)

    def randn(shape):
        return torch.randn(shape, generator=g)

    with torch.no_grad():
        for name, t in model.state_dict().items():
            leaf = name.rsplit(".", 1)[-1]
            if leaf == "is_initialized":
                t.fill_(1.0)
            elif leaf in ("p", "sign_s", "bounds"):
                pass
            elif leaf in ("l", "u"):
                # used triangle (strictly lower of l, strictly upper of u): small perturbation
                # of the authors' LU-of-orthogonal init; the masked-out part (diagonal and the
                # other triangle): large garbage, which the mask must remove
                c = t.shape[0]
                used = torch.tril(torch.ones(c, c), -1)
                if leaf == "u":
                    used = used.t()
                t.add_(used * (0.3 / c ** 0.5) * randn(t.shape) + (1 - used) * 3.0 * randn(t.shape))
            elif leaf == "log_s":
                t.add_(0.2 * randn(t.shape))
            elif leaf in ("gamma", "running_var", "inv_std"):
                t.copy_(torch.exp(0.3 * randn(t.shape)))
            elif leaf in ("beta", "running_mean", "mean", "pe"):
                t.copy_(0.3 * randn(t.shape))
            elif leaf == "pos_emb":
                t.copy_(0.5 * randn(t.shape))
            elif leaf in ("weight_g", "weight_v"):
                t.copy_(randn(t.shape))
            elif ".norm1." in name or ".norm2." in name:
                t.copy_((1.0 if leaf == "weight" else 0.0) + 0.2 * randn(t.shape))
            elif name.endswith(".encoder.weight") and t.dim() == 2:
                t.copy_(randn(t.shape))  # nn.Embedding of a discrete input
            elif t.dim() == 2:
                bound = (3.0 / t.shape[1]) ** 0.5
                t.copy_((torch.rand(t.shape, generator=g) * 2 - 1) * bound)
            elif t.dim() == 1:
                t.copy_(0.1 * randn(t.shape))
            else:
                raise ValueError(f"no init rule for {name} {tuple(t.shape)}")
