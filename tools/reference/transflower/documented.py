"""The algorithm exactly as README.md "Algorithm step by step" writes it, in plain torch float64
ops on the state dict (no authors' class is used here). check_fixtures.py runs it against the
goldens: if the README misses or misstates a step, this file disagrees with the authors'
classes. Batch size is 1 throughout and dropped from every shape.
"""
import ast
import math

import torch

F64 = torch.float64


def _t(sd, k):
    return sd[k].to(F64)


def layer_norm(x, w, b, eps=1e-5):
    mu = x.mean(-1, keepdim=True)
    var = ((x - mu) ** 2).mean(-1, keepdim=True)
    return (x - mu) / torch.sqrt(var + eps) * w + b


def encoder_layer(sd, p, x, nhead, bias):
    """torch.nn.TransformerEncoderLayer(d, nhead, dim_feedforward=d), post-LN, ReLU. x: (L, d)."""
    L, d = x.shape
    hd = d // nhead
    qkv = x @ _t(sd, p + "self_attn.in_proj_weight").T + _t(sd, p + "self_attn.in_proj_bias")
    q, k, v = qkv[:, :d], qkv[:, d:2 * d], qkv[:, 2 * d:]
    q = q.view(L, nhead, hd).transpose(0, 1)
    k = k.view(L, nhead, hd).transpose(0, 1)
    v = v.view(L, nhead, hd).transpose(0, 1)
    scores = q @ k.transpose(1, 2) / math.sqrt(hd)
    if bias is not None:
        scores = scores + bias  # (L, L), same for every head and layer
    att = torch.softmax(scores, -1) @ v  # (h, L, hd)
    att = att.transpose(0, 1).reshape(L, d)
    att = att @ _t(sd, p + "self_attn.out_proj.weight").T + _t(sd, p + "self_attn.out_proj.bias")
    x = layer_norm(x + att, _t(sd, p + "norm1.weight"), _t(sd, p + "norm1.bias"))
    ff = torch.relu(x @ _t(sd, p + "linear1.weight").T + _t(sd, p + "linear1.bias"))
    ff = ff @ _t(sd, p + "linear2.weight").T + _t(sd, p + "linear2.bias")
    return layer_norm(x + ff, _t(sd, p + "norm2.weight"), _t(sd, p + "norm2.bias"))


def basic_transformer(sd, p, x, nhead, tokens=None):
    """BasicTransformerModel. x: (L, din) or tokens (1,) for a discrete input. -> (L, dout)."""
    if tokens is not None:
        x = _t(sd, p + "encoder.weight")[tokens]  # (1, din)
    x = x @ _t(sd, p + "encoder1.weight").T + _t(sd, p + "encoder1.bias")
    if p + "pos_encoder.pe" in sd:
        x = x + _t(sd, p + "pos_encoder.pe")[:, 0, :]  # (input_length, 1, d): lengths must match
    bias = _t(sd, p + "pos_emb") if p + "pos_emb" in sd else None
    i = 0
    while f"{p}transformer_encoder.layers.{i}.norm1.weight" in sd:
        x = encoder_layer(sd, f"{p}transformer_encoder.layers.{i}.", x, nhead, bias)
        i += 1
    return x @ _t(sd, p + "decoder.weight").T + _t(sd, p + "decoder.bias")


def flow_reverse(sd, p, opt, z, cond):
    """FlowPlusPlus reverse, one scale ([[n, 0]]). z: (C, H) base sample, cond: (cond_len, dhid).
    -> x (C, H)."""
    scales = ast.literal_eval(opt["scales"])
    assert len(scales) == 1 and scales[0][1] == 0, "only [[n, 0]] (published except two configs)"
    n_steps = scales[0][0]
    per = 3 if opt["glow_norm_layer"] in ("batchnorm", "actnorm") else 2
    C, H = z.shape
    cc = (C + 1) // 2  # x_change = first ceil(C/2) channels, x_id = the rest
    x = z.clone()
    for j in reversed(range(n_steps)):
        base = f"{p}flows.channels."
        # coupling (module index per*j + per-1)
        q = f"{base}{per * j + per - 1}."
        xc, xid = x[:cc], x[cc:]
        if opt["cond_concat_dims"]:
            seq = torch.cat([xid, cond.T], 0).T  # (H, C_id + dhid); cond_len == H
        else:
            enc = xid.T @ _t(sd, q + "input_encoder.weight").T + _t(sd, q + "input_encoder.bias")  # (H, dhid)
            seq = torch.cat([enc, cond], 0)  # (H + cond_len, dhid): x_id rows first
        y = basic_transformer(sd, q + "nn.transformer.", seq, opt["num_heads_flow"])[:H]  # (H, 2 cc)
        s, t = y[:, :cc].T, y[:, cc:2 * cc].T  # (cc, H)
        g = _t(sd, q + "nn.rescale.weight_g").view(cc, 1)
        v = _t(sd, q + "nn.rescale.weight_v").view(cc, 1)
        a = g * v / v.abs() * torch.tanh(s)  # weight norm over a (cc,1,1) weight: g * sign(v)
        scale = torch.sigmoid(a + 2.0) + (1 - 1 / (1 + math.exp(-2.0)))
        x = torch.cat([xc / scale - t, xid], 0)
        # invertible 1x1 conv (module index per*j + per-2)
        q = f"{base}{per * j + per - 2}."
        lmask = torch.tril(torch.ones(C, C, dtype=torch.float32), -1)
        l_ = sd[q + "l"] * lmask + torch.eye(C)
        u_ = sd[q + "u"] * lmask.T + torch.diag(sd[q + "sign_s"] * torch.exp(sd[q + "log_s"]))
        li = torch.inverse(l_.double()).float()
        ui = torch.inverse(u_.double()).float()
        w = ui @ (li @ torch.inverse(sd[q + "p"]))  # float32 as the authors assemble it
        x = w.to(F64) @ x
        # norm (module index per*j)
        if per == 3:
            q = f"{base}{per * j}."
            if opt["glow_norm_layer"] == "batchnorm":
                inv_std = 1.0 / (torch.sqrt(_t(sd, q + "running_var")) + 1e-5)
                x = x + _t(sd, q + "beta").view(C, 1)
                x = x / _t(sd, q + "gamma").view(C, 1)
                x = x / inv_std.view(C, 1)
                x = x + _t(sd, q + "running_mean").view(C, 1)
            else:
                x = x / _t(sd, q + "inv_std").view(C, 1) + _t(sd, q + "mean").view(C, 1)
    return x


def generate(sd, opt, inputs, noise):
    """The loop of models/util/generation.py for one autoregressive output modality.
    inputs: {mod: array}, noise: (N, C, H). -> outputs (N, C) float64, stage dict of step 0."""
    mods = opt["input_modalities"].split(",")
    out_mod = opt["output_modalities"]
    lengths = [int(v) for v in str(opt["input_lengths"]).split(",")]
    offs = [int(v) for v in str(opt["input_time_offsets"]).split(",")]
    offs = offs * len(mods) if len(offs) == 1 else offs
    types = (opt["input_types"] or ",".join("c" * len(mods))).split(",")
    fix = (opt["input_fix_length_types"] or ",".join(["end"] * len(mods))).split(",")
    out_len = int(opt["output_lengths"])
    cond_len = int(opt["conditioning_seq_lens"]) if opt["conditioning_seq_lens"] is not None else out_len
    n_steps = inputs[mods[-1]].shape[0] - max(lengths) + 1
    full = {m: torch.as_tensor(inputs[m]) for m in mods}
    win = {m: (full[m] if types[i] == "d" else full[m].to(torch.float32).to(F64))[offs[i]:offs[i] + lengths[i]].clone()
           for i, m in enumerate(mods)}
    outs, stages = [], {}
    for t in range(n_steps):
        lat = []
        for i, m in enumerate(mods):
            p = f"net_input_{m}."
            if types[i] == "d":
                lat.append(basic_transformer(sd, p, None, opt["nhead"], tokens=win[m]))
            else:
                lat.append(basic_transformer(sd, p, win[m], opt["nhead"]))
        latent = torch.cat(lat, 0)
        h = basic_transformer(sd, f"net_output_{out_mod}.", latent, opt["nhead"])
        cond = h[:cond_len]
        z = torch.as_tensor(noise[t]).to(F64)
        x = flow_reverse(sd, f"net_output_glow_{out_mod}.", opt, z, cond).T  # (H, C)
        if t == 0:
            stages = {"latent": latent, "cond": cond, "flow_out": x}
        outs.append(x[0])
        for i, m in enumerate(mods):
            if m == out_mod:
                win[m] = torch.cat([win[m][1:], x[:1]], 0)
            elif fix[i] != "single":
                nxt = full[m][offs[i] + lengths[i] + t:offs[i] + lengths[i] + t + 1].to(torch.float32).to(F64)
                win[m] = torch.cat([win[m][1:], nxt], 0)
    return torch.stack(outs), stages
