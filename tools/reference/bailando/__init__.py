"""Bailando (Siyao et al., CVPR 2022) reference: the AUTHORS' classes (lisiyao21/Bailando,
repository root) driven by our own re-statement of `AC.eval()` (actor_critic.py).

Nothing of the authors' code is copied here: `authors.load(checkout)` imports `SepVQVAER`
and `CrossCondGPT2AC` from a checkout given at run time. See README.md.
"""
