"""Attribute-style access to the original YAML configs (nested dicts)."""
import yaml


class Cfg:
    """A read-only nested namespace over a dict: `cfg.structure_generate.base.n_layer`."""

    def __init__(self, d):
        for k, v in d.items():
            setattr(self, k, Cfg(v) if isinstance(v, dict) else v)

    def get(self, name, default=None):
        return getattr(self, name, default)

    def __repr__(self):
        return f"Cfg({vars(self)!r})"


def load_yaml(path):
    """Load an original-style YAML config file as a `Cfg`."""
    with open(path) as f:
        return Cfg(yaml.safe_load(f))
