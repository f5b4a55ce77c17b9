r"""`method="mc"`: importance-sampled Monte Carlo of the exact reflectance under a map
(SPEC §9): GGX visible-normal sampling (Heitz 2018), weight G₂/G₁, the exact spectral R_jk
per sample, nearest-texel radiance; a fixed key and count (`ibl_reference`). Under uniform
light the Monte Carlo estimator is `patch.patch_radiance_mc`.

Example:
    >>> from thinfilm_jax.core.methods import implementation
    >>> implementation("mc").envmap_kind, implementation("mc").monte_carlo
    ('exact', True)
"""

from __future__ import annotations

from .reference import Reference


class MonteCarlo(Reference):
    name = "mc"
    monte_carlo = True

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        raise NotImplementedError("method 'mc' is offered under a map only "
                                  "(uniform light: patch_radiance_mc)")

    stack_patch_point = patch_point


MC = MonteCarlo()
