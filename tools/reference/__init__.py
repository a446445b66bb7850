"""Clean PyTorch reference of the Duolando inference path (float32, eval mode).

Modules keep the ORIGINAL state_dict names (lisiyao21/Duolando) so that an original
checkpoint loads with strict=True. See README.md for every fact used and its source.
"""
from .config import Cfg, load_yaml
from .vqvae import SepVQVAEXM, VQVAE
from .gpt import GPT2nt
from .pipeline import generate_exact, normalise_pos3d

__all__ = ["Cfg", "load_yaml", "SepVQVAEXM", "VQVAE", "GPT2nt", "generate_exact", "normalise_pos3d"]
