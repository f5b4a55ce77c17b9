r"""The shading methods' common form: one object per method, one module each, named by the
registry row that holds it (`core.methods`, ``impl``).

`patch_radiance` (`shading.patch`) and `envmap_radiance` (`shading.ibl`) validate, prepare
and batch; what differs between methods is asked of the method object:

| hook | called by | what it does |
|---|---|---|
| ``patch_tables(options, dtype)`` | `patch_radiance` | host-side tables (cached by value), a jit argument |
| ``patch_point(film, θ_o, α, quad, ...)`` | `patch.patch_one` | one patch of a `Film` → (J,), both layers (``options.layer``) |
| ``stack_patch_point(stack, θ_o, quad, observer)`` | `patch.stack_patch_one` | one patch of a `Stack` (methods of exact dispersion) |
| ``envmap_kind`` | `envmap_radiance` | "realtime" (reads a `PrefilteredEnvMap`), "exact" (integrates an `EnvMap`), "table" (a `ColourTable`) |
| ``envmap_tables(pref, options, dtype)`` | `envmap_radiance` | what travels with the prefiltered map into the jit |
| ``map_static(options)`` | `envmap_radiance` | the method's static options in the jit's configuration |
| ``map_points(film, α, n, ω_o, pref, cfg)`` | `ibl._realtime_points` | flat shading points → (P, J), sources included (``cfg``: a `MapConfig`) |
| ``envmap_stack(...)`` | `envmap_radiance` | a `Stack` or dispersive film under a map (methods of exact dispersion) |
| ``monte_carlo`` | the exact drivers | the sampled rule instead of the quadrature |
| ``rgb(film, cos θ, observer, terms, shat, arithmetic, layer)`` | `rgb_reflectance` | the band reflectances at one cosine (a method whose row lists "rgb"; the methods of `rgb_reflectance` only are `spectral.reflectance.BandMethod`s) |

Which of the film, stack and per-band paths a material takes is `core.methods.material_path`.
The split-sum methods (`ideal`, `filtered`) share `SplitSum.map_light`, the read of
A(θ_o, α) and the prefiltered radiance P_k(ω_r, α) around their band reflectance (SPEC §9):

$$ L_j = A(\theta_o, \alpha) \sum_k R_{jk} P_k(\omega_r, \alpha). $$

Example:
    >>> from thinfilm_jax.core.methods import implementation
    >>> implementation("improved").envmap_kind, implementation("mc").monte_carlo
    ('realtime', True)
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from ...core.material import expand_batch
from ...spectral.lut import build_shat_lut
from ...spectral.reflectance import bare_bands
from ...spectral.uplift import cross_band_name
from ..prefilter import lookup_albedo, lookup_prefiltered
from ..sources import source_radiance

DEFAULT_SOURCES = 4  # suns split from a map that `improved` prefilters itself


class MapConfig(NamedTuple):
    """The static configuration of `envmap_radiance`'s real-time jit (hashable: a static
    argument), what the method hooks under a map read by name."""

    method: str
    observer: str
    terms: int
    shat: str  # "lut", "exact" or "gaussian" (resolved)
    cross_band: bool
    arithmetic: str  # "real" or "complex" (resolved)
    static: object  # the method's own static options (`ShadingMethod.map_static`)
    layer: str  # "film" or "bare" (resolved)


class ShadingMethod:
    """A method of `patch_radiance` / `envmap_radiance` (module table of hooks). The base
    offers nothing: a subclass defines the hooks of the entry points its row lists."""

    name = ""
    envmap_kind = ""  # "realtime" | "exact" | "table"; "" where the method has no map path
    monte_carlo = False
    default_sources = 0  # suns split when `envmap_radiance` prefilters an EnvMap itself

    def __repr__(self):
        return f"<shading method {self.name!r}>"

    def patch_tables(self, options, dtype):
        """Host-side tables of `patch_radiance` (a jit argument), None if none."""
        return None

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        raise NotImplementedError(f"method {self.name!r} has no uniform-light path")

    def stack_patch_point(self, stack, theta_o, quad, observer):
        raise NotImplementedError(f"method {self.name!r} has no stack path")

    def envmap_tables(self, pref, options, dtype):
        """What travels with the `PrefilteredEnvMap` into the jit (the map itself here)."""
        return pref

    def map_static(self, options):
        """The method's static options in `envmap_radiance`'s jit configuration."""
        return False

    def map_points(self, film, alpha, normal, view, pref, cfg):
        """L_j at flat shading points (the map's method plus the split suns)."""
        out = self.map_light(film, alpha, normal, view, pref, cfg)
        return with_sources(out, film, alpha, normal, view, self.prefiltered(pref), cfg)

    def prefiltered(self, pref):
        """The `PrefilteredEnvMap` inside what `envmap_tables` made."""
        return pref

    def map_light(self, film, alpha, normal, view, pref, cfg):
        raise NotImplementedError(f"method {self.name!r} has no prefiltered-map path")

    def envmap_stack(self, material, alpha, normal, view, envmap, observer, kw):
        raise NotImplementedError(f"method {self.name!r} has no stack path under a map")


def shat_lut(pref, cfg, dtype):
    """The Ŝ table a real-time method reads: the map's cross-band one, the plain bands' one
    on the diagonal path, None for another Ŝ source."""
    if cfg.cross_band:
        return pref.lut
    return build_shat_lut(cfg.observer, dtype=dtype) if cfg.shat == "lut" else None


def with_sources(out, film, alpha, normal, view, pref, cfg):
    """`out` plus the suns split from the map (`sources.source_radiance`), if any."""
    if pref.has_sources:
        lut = shat_lut(pref, cfg, alpha.dtype)
        out = out + source_radiance(film, alpha, normal, view, pref.sources,
                                    observer=cfg.observer, terms=cfg.terms, shat=cfg.shat,
                                    lut=lut, arithmetic=cfg.arithmetic,
                                    cross_band=cfg.cross_band)
    return out


class SplitSum(ShadingMethod):
    """A split-sum method under a map: A(θ_o, α) Σ_k R_jk P_k(ω_r, α) (module docstring);
    a subclass gives R through `bands_per_light` (Σ_k R_jk P_k read per light channel) and
    `bands` (R_j or R_jk, per moment channel where the map has them), and for a bare layer
    (d = 0, ``cfg.layer == "bare"``: `reflectance.choose_layer`) the incidence cosine of its
    exact R₁₃ Ŝ_jk(0) through `bare_cos`, as its uniform-light `patch_point` does."""

    envmap_kind = "realtime"

    def bands_per_light(self, film, co, view, mom, kw):
        raise NotImplementedError

    def bands(self, film, co, view, mom, pref, kw):
        raise NotImplementedError

    def bare_cos(self, co, view, mom):
        """cos θ₁ of the bare interface's R₁₃ (..., [k]), per moment channel where the map
        has them."""
        raise NotImplementedError

    def map_light(self, film, alpha, normal, view, pref, cfg):
        observer, terms, shat, arithmetic, layer = (cfg.observer, cfg.terms, cfg.shat,
                                                    cfg.arithmetic, cfg.layer)
        cross = cfg.cross_band
        cos_o = jnp.sum(normal * view, axis=-1)
        up = cos_o > 0
        co = jnp.where(up, cos_o, 1.0)
        refl = 2 * co[..., None] * normal - view
        sqa = jnp.sqrt(alpha)
        rad, mom = lookup_prefiltered(pref, refl, sqa)
        a = lookup_albedo(pref, co, sqa)
        obs = cross_band_name(observer) if cross else observer
        lut = pref.lut if cross else None
        if shat == "lut" and not cross:  # the diagonal path reads the plain bands' table
            lut = build_shat_lut(observer, dtype=alpha.dtype)
        per_light = cross and shat == "lut" and not pref.per_channel and layer != "bare"
        if per_light:  # Σ_k R_jk P_k read per light channel (`filtered.filtered_bands`)
            kw = dict(observer=obs, terms=terms, shat=shat, lut=lut, arithmetic=arithmetic,
                      light=rad)
            out = self.bands_per_light(film, co, view, mom, kw)
            return jnp.where(up[..., None], a[..., None] * out, 0.0)
        if layer == "bare":  # no film: the exact R₁₃ Ŝ_jk(0) (`bare_bands`)
            c = self.bare_cos(co, view, mom)
            r = bare_bands(expand_batch(film) if c.ndim > co.ndim else film, c, obs,
                           shat=shat, arithmetic=arithmetic)
        else:
            r = self.bands(film, co, view, mom, pref, dict(observer=obs, terms=terms,
                                                            shat=shat, lut=lut,
                                                            arithmetic=arithmetic))
        if cross:
            r = r.reshape(r.shape[:-1] + (3, 3))  # (..., [k,] j, k)
            if r.ndim > rad.ndim + 1:  # per-channel moments: keep k of the moments = k of R
                r = jnp.diagonal(r, axis1=-3, axis2=-1)  # (..., j, k)
            out = jnp.sum(r * rad[..., None, :], axis=-1)
        else:
            if r.ndim > rad.ndim:
                r = jnp.diagonal(r, axis1=-2, axis2=-1)
            out = r * rad
        return jnp.where(up[..., None], a[..., None] * out, 0.0)
