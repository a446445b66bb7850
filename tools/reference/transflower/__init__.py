"""Transflower reference: the authors' classes (vendored under authors/) and our driver."""
