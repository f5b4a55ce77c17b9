r"""`method="ideal"`: BB17's reflectance at h = n times the split-sum albedo (SPEC §7, §9).

Uniform light: L_j = A(θ_o, α) R_j^Fourier(cos θ_o) (`kernels.ideal_kernel`); a bare layer
(d = 0) the exact R₁₃ Ŝ_j(0) at cos θ_o; a `Stack` (or dispersive film) its exact bands at
h = n, A · R_j^stack(cos θ_o). Under a map: A(θ_o, α) Σ_k R_jk(cos θ_o) P_k(ω_r, α) (Ŝ from
the map's LUT at σ = 0); a homogeneous `Stack` or dispersive film has its exact R_jk(cos θ)
tabulated once over cos θ (`n_cos` nodes, linear interpolation) instead of the M-term
series: the table an engine would upload per material.

Example:
    >>> from thinfilm_jax import Film, patch_radiance
    >>> patch_radiance(Film(600.0, 1.3, 2.0, 0.5), 0.3, 0.25, method="ideal").shape
    (3,)
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ...core import _validate as V
from ...core.material import batch_shape
from ...realtime.kernels import ideal_kernel
from ...spectral.reflectance import bare_bands, stack_bands
from ...spectral.spectra import get_observer
from ...spectral.uplift import cross_band_name
from ..envmap import EnvMap, load_envmap
from ..ibl_integrand import interp_table, reflectance_table
from ..prefilter import PrefilteredEnvMap, lookup_albedo, lookup_radiance, prefilter_envmap
from . import SplitSum


class Ideal(SplitSum):
    name = "ideal"

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        o = options
        albedo = jnp.sum(quad.weight)
        if o.layer == "bare":
            return albedo * bare_bands(film, jnp.cos(theta_o), observer, shat=o.shat,
                                       arithmetic=o.arithmetic)
        return albedo * ideal_kernel(film, jnp.cos(theta_o), observer=observer, terms=o.terms,
                                     shat="exact", arithmetic=o.arithmetic)

    def stack_patch_point(self, stack, theta_o, quad, observer):
        return jnp.sum(quad.weight) * stack_bands(stack, jnp.cos(theta_o), observer)

    def bands_per_light(self, film, co, view, mom, kw):
        return ideal_kernel(film, co, **kw)

    def bands(self, film, co, view, mom, pref, kw):
        return ideal_kernel(film, co, **kw)

    def bare_cos(self, co, view, mom):
        return co

    def envmap_stack(self, material, alpha, normal, view, envmap, observer, kw):
        return tabulated_ideal(material, alpha, normal, view, envmap, observer, kw)


IDEAL = Ideal()


def tabulated_ideal(material, alpha, normal, view, envmap, observer, kw):
    """`ideal` for a `Stack` or a dispersive `Film` with one set of thicknesses (a homogeneous
    material): the split sum A(θ_o, α) Σ_k R_jk(cos θ_o) P_k(ω_r, α) with R_jk the exact cross
    bands tabulated once over cos θ (module docstring)."""
    stack = V.check_material(material, wavelengths=get_observer(observer).wavelengths)
    if batch_shape(stack) != ():
        raise ValueError("method='ideal' tabulates one homogeneous material: its thicknesses "
                         "must not vary per point (use method='reference', or vmap)")
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    V.check_directions(normal, view)
    shape = V.check_broadcast([("alpha", alpha), ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    pref = envmap
    if not isinstance(pref, PrefilteredEnvMap):
        pref = prefilter_envmap(envmap if isinstance(envmap, EnvMap) else load_envmap(envmap),
                                observer=observer, sources=kw["sources"] or 0)
    if pref.has_sources:
        raise ValueError("method='ideal' of a tabulated material shades the prefiltered map "
                         "only: prefilter it with sources=0")
    dtype = jnp.result_type(alpha, normal, view, float)
    cross = bool(kw["cross_band"])
    obs = cross_band_name(observer) if cross else observer
    table = reflectance_table(stack, obs, int(kw["n_cos"]), "complex", dtype)
    alpha = jnp.broadcast_to(jnp.asarray(alpha, dtype), shape)
    nv = [jnp.broadcast_to(jnp.asarray(v, dtype), shape + (3,)) for v in (normal, view)]
    return _tabulated_ideal_jit(table, alpha, *nv, pref, cross)


@functools.partial(jax.jit, static_argnums=5)
def _tabulated_ideal_jit(table, alpha, normal, view, pref, cross):
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    sqa = jnp.sqrt(alpha)
    rad = lookup_radiance(pref, 2 * co[..., None] * normal - view, sqa)
    r = interp_table(table, co)
    if cross:
        out = jnp.sum(r.reshape(r.shape[:-1] + (-1, 3)) * rad[..., None, :], axis=-1)
    else:
        out = r * rad
    return jnp.where(up[..., None], lookup_albedo(pref, co, sqa)[..., None] * out, 0.0)
