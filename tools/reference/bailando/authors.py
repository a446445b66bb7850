"""Import the authors' Bailando classes from a checkout of lisiyao21/Bailando.

    mkdir -p /tmp/bailando && git -C /work/.mirror/lisiyao21+Bailando/repo archive HEAD \
        models configs actor_critic.py dataset utils | tar -x -C /tmp/bailando

Only `models/` is imported (the package `models`, whose `__init__.py` also imports the
reward and the non-AC GPT modules). What we change, all of it here and nothing in their files:

- `torch.Tensor.cuda` and `torch.nn.Module.cuda` become the identity (process-wide, once,
  in `load`): `BottleneckBlock.reset_k` builds its codebook with `.cuda()` and
  `SepVQVAER.decode` builds its output with `torch.zeros(...).cuda()`; everything stays on
  the CPU. (`torch.zeros` uses the default dtype: float32, or float64 under `float64()`.)
- Missing import-time-only packages get an empty stand-in module: `tqdm` (imported by
  models/utils/logger.py, never called by the classes we use); `scipy.ndimage` /
  `scipy.signal` (models/up_down_half_reward.py, the training reward) only if scipy is absent.
- `float64()` (the float64 cross-check only): default dtype float64 and `Tensor.float()`
  returning a float64 tensor, because the authors' `preprocess` and the eval cast to
  float32 with `.float()`.
"""
import contextlib
import importlib
import io
import os
import sys
import types
import warnings

import torch

DEFAULT_CHECKOUT = "/tmp/bailando"
_REQUIRED = ("models/__init__.py", "models/sep_vqvae_root.py", "models/cross_cond_gpt2_ac.py")


def _identity(self, *args, **kwargs):
    return self


def _stub(name, **attrs):
    try:
        importlib.import_module(name)
    except ImportError:
        mod = types.ModuleType(name)
        mod.__dict__.update(attrs)
        mod.__bailando_stub__ = True
        sys.modules[name] = mod
        parent, _, child = name.rpartition(".")
        if parent:
            setattr(sys.modules[parent], child, mod)


def _tqdm(iterable=None, *args, **kwargs):
    return iterable


def load(checkout=DEFAULT_CHECKOUT):
    """Import the authors' `models` package from `checkout`; returns a namespace with
    `models` (the package, for getattr by config name as AC._build_model does),
    `SepVQVAER`, `CrossCondGPT2AC`, `smpl_up`, `smpl_down`, `checkout`."""
    checkout = os.path.abspath(checkout)
    for rel in _REQUIRED:
        if not os.path.isfile(os.path.join(checkout, rel)):
            raise FileNotFoundError(f"{checkout}/{rel} missing: not a lisiyao21/Bailando checkout")
    torch.Tensor.cuda = _identity
    torch.nn.Module.cuda = _identity
    _stub("tqdm", tqdm=_tqdm)
    try:
        import scipy  # noqa: F401
    except ImportError:
        _stub("scipy")
        _stub("scipy.ndimage", gaussian_filter=None)
        _stub("scipy.signal", argrelextrema=None)
    # their `if self.reg is 0:` is a SyntaxWarning on Python >= 3.8
    warnings.filterwarnings("ignore", category=SyntaxWarning, module=r"models\.")
    warnings.filterwarnings("ignore", category=SyntaxWarning, message=r".*\"is\" with a literal")
    if checkout not in sys.path:
        sys.path.insert(0, checkout)
    models = importlib.import_module("models")
    svr = importlib.import_module("models.sep_vqvae_root")
    gac = importlib.import_module("models.cross_cond_gpt2_ac")
    for mod in (models, svr, gac):
        if not os.path.abspath(mod.__file__).startswith(checkout + os.sep):
            raise ImportError(f"{mod.__name__} imported from {mod.__file__}, not from {checkout}")
    return types.SimpleNamespace(models=models, SepVQVAER=svr.SepVQVAER, CrossCondGPT2AC=gac.CrossCondGPT2AC,
                                 smpl_up=list(svr.smpl_up), smpl_down=list(svr.smpl_down), checkout=checkout)


def build(auth, cfg):
    """`AC._build_model` without the reward net and without `.cuda()`: the classes named by
    `cfg.structure.name` / `cfg.structure_generate.name`, each wrapped in nn.DataParallel
    (so checkpoints carry `module.`), in eval mode. The constructors' prints are swallowed."""
    with contextlib.redirect_stdout(io.StringIO()):
        vq = getattr(auth.models, cfg.structure.name)(cfg.structure)
        gpt = getattr(auth.models, cfg.structure_generate.name)(cfg.structure_generate)
    return torch.nn.DataParallel(vq).eval(), torch.nn.DataParallel(gpt).eval()


@contextlib.contextmanager
def float64():
    """Run the authors' code in float64 (for the f32-vs-f64 margin check only)."""
    prev_dtype, prev_float = torch.get_default_dtype(), torch.Tensor.float
    torch.set_default_dtype(torch.float64)
    torch.Tensor.float = lambda self, *a, **k: self.to(torch.float64)
    try:
        yield
    finally:
        torch.set_default_dtype(prev_dtype)
        torch.Tensor.float = prev_float
