r"""`method="reference"`: the converged quadrature of the exact spectral reflectance (SPEC §7,
§9).

Uniform light: L_j = Σ_n w_n R_j^spectral(c_n), the deterministic half-vector quadrature
(`microfacet.patch_quadrature`) of the exact band reflectance (a bare layer: the exact
R₁₃ Ŝ_j(0) at each node; a `Stack` or dispersive film: the stack code's bands). Under a map:
the texel-space quadrature of `ibl_reference` (adaptive by default), any material of SPEC §12.

Example:
    >>> from thinfilm_jax.core.methods import implementation
    >>> implementation("reference").envmap_kind, implementation("reference").monte_carlo
    ('exact', False)
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ...spectral.reflectance import bare_bands, spectral_bands, stack_bands
from ..ibl_reference import exact_stack_envmap
from . import ShadingMethod

HIGHEST = jax.lax.Precision.HIGHEST


class Reference(ShadingMethod):
    name = "reference"
    envmap_kind = "exact"

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        o = options
        if o.layer == "bare":
            return jnp.matmul(quad.weight, bare_bands(film, quad.cos_hi, observer, shat="exact",
                                                      arithmetic=o.arithmetic),
                              precision=HIGHEST)
        rj = spectral_bands(film, quad.cos_hi, observer, arithmetic=o.arithmetic)  # (N, J)
        return jnp.matmul(quad.weight, rj, precision=HIGHEST)

    def stack_patch_point(self, stack, theta_o, quad, observer):
        rj = stack_bands(stack, quad.cos_hi, observer)  # (N, J)
        return jnp.matmul(quad.weight, rj, precision=HIGHEST)

    def envmap_stack(self, material, alpha, normal, view, envmap, observer, kw):
        return exact_stack_envmap(material, alpha, normal, view, envmap, self.name, observer,
                                  kw)


REFERENCE = Reference()
