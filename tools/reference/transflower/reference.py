"""Reference driver: the AUTHORS' TransflowerModel and their autoregressive loop
(`BaseModel.generate` -> models/util/generation.py `autoregressive_generation_multimodal`),
fed the way inference/generate.py feeds it, with the base-distribution noise recorded at
every step (or replayed from a recording).

Nothing of the computation is restated here. Instrumentation only:
- the flow's `distribution.sample` is wrapped (instance attribute) to record what it returned,
  or to return the recorded tensor instead of drawing (replay);
- forward hooks read (never change) module outputs: the flow output of every step and, with
  `stages=True`, every stage of step 0.

Randomness in the authors' path: GaussianDiag.sample draws with `torch.normal` (global torch
generator); StudentT.sample draws `np.random.chisquare` (global numpy generator) then
`torch.normal`. generate.py seeds neither (and picks a random sequence with np.random.choice);
we seed both (`torch.manual_seed(seed)`, `np.random.seed(seed)`) right before the loop. The
model's own init uses numpy (InvertibleConv1x1: QR + LU of a random matrix) and torch: seeded
in `build`.
"""
import contextlib

import numpy as np
import torch

from . import env, tiny


def build(hparams, seed):
    """TransflowerModel(opt) with seeded weights (tiny.init_weights), eval mode."""
    np.random.seed(seed)
    torch.manual_seed(seed)
    model = env.build(hparams)
    tiny.init_weights(model, seed)
    return model


def build_from_state(hparams, state, dtype=torch.float32):
    """TransflowerModel(opt) loaded from a state dict (strict). float64 needs env.float64()."""
    model = env.build(hparams)
    if dtype == torch.float64:
        model = model.double()
    model.load_state_dict(state, strict=True)
    return model.eval()


def features_like_generate_py(model, inputs):
    """inference/generate.py: features["in_"+mod] = expand_dims(x, 1) (time, batch=1, dim), or
    expand_dims(expand_dims(x, 1), 1) for a 'single' (sequence-level label) input."""
    feats = {}
    for i, mod in enumerate(model.input_mods):
        x = inputs[mod]
        if model.input_fix_length_types[i] == "single":
            feats["in_" + mod] = np.expand_dims(np.expand_dims(x, 1), 1)
        else:
            feats["in_" + mod] = np.expand_dims(x, 1)
    return feats


@contextlib.contextmanager
def _patched(obj, name, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


def generate(model, inputs, seed=0, replay=None, stages=False):
    """Run the authors' generation. inputs: {modality: np array} (continuous: (T, d) float32;
    'single' discrete: (1,) int64). Returns a dict:
      output      (N, 1, C) float32: model.generate(...)[0] as generate.py saves it (--no-use_scalers)
      flow_out    (N, H, C): every flow sample (all H = output_lengths frames; the loop keeps row 0)
      noise       (N, C, H): the tensor the base distribution returned at each step ([0] of its (1, C, H))
      noise_normal, noise_chi2_over_df (Student-t only): its normal draw (N, C, H) and the
                  chi-square / df factor (N, H); noise = normal / sqrt(chi2_over_df)
      stages      {name: array} of step 0 (if stages)
    replay: {"noise": (N, C, H)} -> the sampler returns these instead of drawing."""
    assert len(model.output_mods) == 1
    glow = model.output_mod_glows[0]
    dist = glow.distribution
    is_t = type(dist).__name__ == "StudentT"
    rec = {"noise": [], "noise_normal": [], "noise_chi2_over_df": [], "flow_out": []}
    original_sample = dist.sample

    def sample(z_shape, eps_std=None, device=None):
        k = len(rec["noise"])
        if replay is not None:
            z = torch.from_numpy(np.ascontiguousarray(replay["noise"][k][None])).float()
            assert tuple(z.shape) == tuple(z_shape), (z.shape, z_shape)
        elif is_t:
            real_chi = np.random.chisquare
            real_normal = torch.normal

            def chi(*a, **kw):
                v = real_chi(*a, **kw)
                rec["noise_chi2_over_df"].append(np.asarray(v, dtype=np.float64)[0, 0] / dist.df)
                return v

            def normal(*a, **kw):
                v = real_normal(*a, **kw)
                rec["noise_normal"].append(v[0].detach().clone().float().numpy())
                return v
            with _patched(np.random, "chisquare", chi), _patched(torch, "normal", normal):
                z = original_sample(z_shape, eps_std, device)
        else:
            z = original_sample(z_shape, eps_std, device)
        rec["noise"].append(z[0].detach().clone().float().numpy())
        return z

    hooks = [glow.register_forward_hook(lambda m, i, o: rec["flow_out"].append(o[0][0].detach().clone().float().numpy()))]
    stage_store = {}
    if stages:
        hooks += _stage_hooks(model, stage_store)
    feats = features_like_generate_py(model, inputs)
    torch.manual_seed(seed)
    np.random.seed(seed)
    dist.sample = sample
    try:
        with env.quiet():
            out = model.generate(feats)
    finally:
        del dist.sample
        for h in hooks:
            h.remove()
    res = {"output": out[0].detach().float().numpy(), "noise": np.stack(rec["noise"]),
           "flow_out": np.stack(rec["flow_out"])}
    if is_t and replay is None:
        res["noise_normal"] = np.stack(rec["noise_normal"])
        res["noise_chi2_over_df"] = np.stack(rec["noise_chi2_over_df"]).astype(np.float32)
    if stages:
        res["stages"] = stage_store
    return res


def _arr(t):
    return t.detach().clone().float().numpy()


def _stage_hooks(model, store):
    """Forward hooks that keep the FIRST output (= step 0) of the stages an engine computes:
    per input net: encoder1 (after the Embedding for a discrete input), [pos_encoder], every
    TransformerEncoderLayer, decoder; the same for the cross-modal net; every flow op (norm,
    LU 1x1 conv, coupling: output of the op as one (1, C, H, 1) tensor, in the order the reverse
    pass applies them) and every coupling net (s after tanh and weight-normed rescale, t)."""
    hooks = []

    def keep(name, fn):
        def hook(m, i, o):
            if name not in store:
                store[name] = fn(i, o)
        return hook

    for mname, mod in model.named_modules():
        cls = type(mod).__name__
        if cls == "BasicTransformerModel":
            if getattr(mod, "discrete_inputs", False):
                hooks.append(mod.encoder.register_forward_hook(keep(mname + ".encoder", lambda i, o: _arr(o))))
            for sub in ("encoder1", "pos_encoder", "decoder"):
                if hasattr(mod, sub):
                    hooks.append(getattr(mod, sub).register_forward_hook(keep(f"{mname}.{sub}", lambda i, o: _arr(o))))
            for li, layer in enumerate(mod.transformer_encoder.layers):
                hooks.append(layer.register_forward_hook(
                    keep(f"{mname}.transformer_encoder.layers.{li}", lambda i, o: _arr(o))))
        elif cls in ("BatchNorm", "ActNorm", "InvertibleConv1x1", "Coupling"):
            hooks.append(mod.register_forward_hook(keep(mname, lambda i, o: _arr(torch.cat(o[0], dim=1)))))
            if cls == "Coupling" and hasattr(mod, "input_encoder"):
                hooks.append(mod.input_encoder.register_forward_hook(
                    keep(mname + ".input_encoder", lambda i, o: _arr(o))))
        elif cls == "TransformerNN":
            hooks.append(mod.register_forward_hook(keep(mname + ".s", lambda i, o: _arr(o[0]))))
            hooks.append(mod.register_forward_hook(keep(mname + ".t", lambda i, o: _arr(o[1]))))
        elif cls == "FlowPlusPlus":
            def flow_hook(m, args, kwargs, o, mname=mname):
                if mname + ".cond" not in store:
                    store[mname + ".cond"] = _arr(kwargs["cond"])  # (1, cond_len, dhid), before the flow's permute
                    store[mname + ".out"] = _arr(o[0])           # (1, H, C)
            hooks.append(mod.register_forward_hook(flow_hook, with_kwargs=True))
    return hooks
