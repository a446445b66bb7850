"""Import the AUTHORS' Transflower classes (vendored, unmodified, under ./authors) and build
`TransflowerModel` from an hparams dict the way inference/generate.py does.

Only import plumbing is replaced (never the math):
- `pytorch_lightning`: `LightningModule` becomes a plain `nn.Module` with the three members the
  used code touches (`save_hyperparameters`, `device`, `log`); `BaseModel` subclasses it.
- `models.optimizer` (imports madgrad, pl_bolts and models/nero.py: training only) becomes a
  module with `get_optimizers` / `get_scheduler` that raise if called.
- `x_transformers` (imported by models/transformer.py; used only when `use_x_transformers`,
  which no published config sets) becomes a module whose names raise if called.
The authors' modules print progress lines ("HOOOOOO", "t", MSEs); `quiet()` swallows stdout.

Run conditions: CPU, float32 (float64 only for the cross-check, see `float64()`),
`torch.set_num_threads(1)`, eval mode (the authors' loop calls `model.eval()` itself).
"""
import argparse
import contextlib
import io
import os
import sys
import types

import torch
import torch.nn as nn

HERE = os.path.dirname(os.path.abspath(__file__))
AUTHORS = os.path.join(HERE, "authors")
SOURCE_COMMIT = "56e93a569d85a768c178b15461e5362c25fdc3e3"  # guillefix/transflower-lightning HEAD, 2021-12-09


def _unavailable(name):
    def f(*a, **k):
        raise RuntimeError(f"{name} is stubbed in tools/reference/transflower/env.py (training / x-transformers only)")
    return f


class LightningModule(nn.Module):
    """Stand-in for pytorch_lightning.LightningModule: only what BaseModel / generation use."""

    def save_hyperparameters(self, *args, **kwargs):
        self.hparams = dict(args[0]) if args and isinstance(args[0], dict) else {}

    @property
    def device(self):
        for p in self.parameters():
            return p.device
        return torch.device("cpu")

    def log(self, *args, **kwargs):
        pass


def _install_stubs():
    if "pytorch_lightning" not in sys.modules or not hasattr(sys.modules["pytorch_lightning"], "_tf_stub"):
        pl = types.ModuleType("pytorch_lightning")
        pl.LightningModule = LightningModule
        pl.Trainer = None
        pl._tf_stub = True
        sys.modules["pytorch_lightning"] = pl
    opt = types.ModuleType("models.optimizer")
    opt.get_optimizers = _unavailable("get_optimizers")
    opt.get_scheduler = _unavailable("get_scheduler")
    sys.modules["models.optimizer"] = opt
    xt = types.ModuleType("x_transformers")
    for n in ("ContinuousTransformerWrapper", "Decoder", "Encoder", "AutoregressiveWrapper"):
        setattr(xt, n, _unavailable(n))
    sys.modules["x_transformers"] = xt


@contextlib.contextmanager
def quiet():
    with contextlib.redirect_stdout(io.StringIO()):
        yield


_LOADED = None


def load():
    """Import the vendored authors' packages; returns a namespace with the classes used."""
    global _LOADED
    if _LOADED is not None:
        return _LOADED
    for m in list(sys.modules):
        if m == "models" or m.startswith("models.") or m == "training" or m.startswith("training."):
            raise RuntimeError(f"a module named {m} is already imported; the authors' package would clash")
    _install_stubs()
    sys.path.insert(0, AUTHORS)
    with quiet():
        import models  # noqa: F401
        from models.transflower_model import TransflowerModel
        from models.flowplusplus import flowplusplus, act_norm, inv_conv, coupling, transformer_nn
        from models.moglow import modules as moglow_modules
        from models.util import generation
        from models import transformer
        from training.datasets.multimodal_dataset import MultimodalDataset
    _LOADED = types.SimpleNamespace(
        TransflowerModel=TransflowerModel, flowplusplus=flowplusplus, act_norm=act_norm,
        inv_conv=inv_conv, coupling=coupling, transformer_nn=transformer_nn,
        moglow_modules=moglow_modules, generation=generation, transformer=transformer,
        MultimodalDataset=MultimodalDataset)
    return _LOADED


def default_opts():
    """The option defaults that matter to the model: TransflowerModel.modify_commandline_options
    and MultimodalDataset.modify_commandline_options (the authors' functions), plus the
    BaseOptions / TrainOptions entries generate.py forces or the model reads."""
    a = load()
    p = argparse.ArgumentParser()
    a.TransflowerModel.modify_commandline_options(p, None)
    a.MultimodalDataset.modify_commandline_options(p, True)
    d = vars(p.parse_args([]))
    d.update({"model": "transflower", "dataset_name": "multimodal", "batch_size": 1, "phase": "inference",
              "tpu_cores": 0})
    return d


class Struct:  # inference/generate.py `Struct`
    def __init__(self, **entries):
        self.__dict__.update(entries)


def make_opt(hparams):
    """generate.py: opt = defaults; opt.update(hparams.yaml); batch_size 1; phase inference."""
    opt = default_opts()
    opt.update(hparams)
    opt["batch_size"] = 1
    opt["phase"] = "inference"
    opt["tpu_cores"] = 0
    return Struct(**opt)


def build(hparams):
    """TransflowerModel(opt) in eval mode (as create_model(opt) in generate.py)."""
    a = load()
    with quiet():
        model = a.TransflowerModel(make_opt(hparams))
    return model.eval()


@contextlib.contextmanager
def float64():
    """float64 cross-check only: default dtype float64 and Tensor.float() -> double
    (the authors' generation casts inputs with .float() and InvertibleConv1x1 casts its
    float64 inverses back with .float())."""
    old_dtype = torch.get_default_dtype()
    old_float = torch.Tensor.float
    torch.set_default_dtype(torch.float64)
    torch.Tensor.float = lambda self, *a, **k: self.double()
    try:
        yield
    finally:
        torch.Tensor.float = old_float
        torch.set_default_dtype(old_dtype)
