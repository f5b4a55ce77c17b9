r"""`method="khr"`: glTF `KHR_materials_iridescence`'s F_iridescence (SPEC §10, `spectral.khr`)
at h = n under the split sum, computed in linear Rec. 709 as engines do and returned in the
observer's bands (`colorimetry.rec709_to_bands`) like every method.

Uniform light: A(θ_o, α) F_iridescence(cos θ_o) (its d = 0 is its own formula, not the bare
base). Under a map: per channel, F_iridescence(cos θ_o) × (A · the prefiltered map's RGB +
the split suns' Σ_s m_s L_s, the same Fresnel for every light as the renderer's punctual
ones), then to the bands; `cross_band`, `options` and the map's Ŝ table do not apply.

Example: at d = 0 glTF's formula is its own, not the bare base (which `ideal` gives, the
same in every band):
    >>> from thinfilm_jax import Film, patch_radiance
    >>> bare = Film(0.0, 1.3, 2.0, 0.5)
    >>> k, i = (patch_radiance(bare, 0.3, 0.25, method=m) for m in ("khr", "ideal"))
    >>> [round(float(x), 3) for x in k], [round(float(x), 3) for x in i]
    ([0.129, 0.121, 0.119], [0.123, 0.123, 0.123])
"""

from __future__ import annotations

import jax.numpy as jnp

from ...spectral.khr import khr_bands, khr_to_bands
from ...spectral.reflectance import khr_rgb
from ..prefilter import lookup_albedo, lookup_radiance
from ..sources import source_light
from . import ShadingMethod


class KhrMethod(ShadingMethod):
    name = "khr"
    envmap_kind = "realtime"
    rgb = staticmethod(khr_rgb)  # `rgb_reflectance(method="khr")`: linear Rec. 709, at h = n

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        rgb = jnp.sum(quad.weight) * khr_bands(film, jnp.cos(theta_o))  # linear Rec. 709
        return khr_to_bands(rgb, observer)  # the bands, as every method

    def map_points(self, film, alpha, normal, view, pref, cfg):
        """Per channel, Rec. 709 F_iridescence(cos θ_o) × (A · the prefiltered map's RGB +
        the split suns' Σ_s m_s L_s), then to the bands (module docstring)."""
        observer = cfg.observer
        cos_o = jnp.sum(normal * view, axis=-1)
        up = cos_o > 0
        co = jnp.where(up, cos_o, 1.0)
        sqa = jnp.sqrt(alpha)
        rad = lookup_radiance(pref, 2 * co[..., None] * normal - view, sqa)
        light = lookup_albedo(pref, co, sqa)[..., None] * rad
        if pref.has_sources:  # the same Fresnel for every light, as the renderer's punctual
            light = light + source_light(alpha, normal, view, pref.sources)
        rgb = jnp.where(up[..., None], khr_bands(film, co) * light, 0.0)
        return khr_to_bands(rgb, observer)


KHR = KhrMethod()
