r"""`method="improved"` under uniform light and under a map: the method object and its map
path (the model and its kernels: `realtime.improved`; its (θ_o, α) tables:
`realtime.improved_table`; docs/improved.md).

Uniform light: L_j = A(θ_o, α) (1/K) Σ_k R_j(bin k), K 29 per equal-probability bin of
cos θ₁ (`improved.improved_kernel`); a bare layer (d = 0) the mean of the exact R₁₃ Ŝ_j(0)
over the bins' cosines c̄_k. Under a map (`improved_envmap`):

$$ L_j = \frac{A(\theta_o,\alpha)}{K}\sum_{k=1}^{K}\sum_c
   R_{jc}(\bar c_k + \Delta c_k, s_k)\, P_c(d_k, \alpha_k), $$

each bin times read k of K prefiltered reads fitted to the lobe's shape
(`improved.lookup_reads`), at the bin's cosine moved by the read's light-weighted mean
direction (`bin_radiance_parts`). Its options: `improved.ImprovedOptions` (the fields
``bins``, ``bin_reads``, ``light_spread`` of `ModelOptions`); its host tables: `bin_table`,
cached by value; it splits up to `DEFAULT_SOURCES` suns from a map it prefilters itself.

Example:
    >>> from thinfilm_jax.core.methods import implementation
    >>> m = implementation("improved")
    >>> m.default_sources, m.map_static(__import__("thinfilm_jax").ModelOptions())
    (4, False)
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax.numpy as jnp
from jax import Array

from ...core.film import Film
from ...optics.fresnel import safe_sqrt
from ...realtime.improved import (BinLight, BinTable, bin_bands, bin_table, improved_kernel,
                                  lookup_bins, lookup_reads, scan_bins)
from ...spectral.lut import ShatLUT
from ...spectral.reflectance import bare_bands
from ...spectral.spectra import DEFAULT_OBSERVER
from ...spectral.uplift import cross_band_name
from ..envmap import bilinear_taps, luminance_weights
from ..prefilter import (MOMENT_RESOLUTION, VARIANCE_RESOLUTION, PrefilteredEnvMap,
                         _level_lerp, _read_geometry, _read_levels, lookup_albedo)
from . import DEFAULT_SOURCES, ShadingMethod, shat_lut


class Improved(ShadingMethod):
    name = "improved"
    envmap_kind = "realtime"
    default_sources = DEFAULT_SOURCES

    def patch_tables(self, options, dtype):
        """The (θ_o, α) table of its K bins (under uniform light only K acts)."""
        return bin_table(options.improved.bins, ndf=options.ndf, dtype=dtype)

    def patch_point(self, film, theta_o, alpha, quad, *, observer, options, lut, table):
        o = options
        albedo = jnp.sum(quad.weight)
        if table is None:  # the default table (host-built, cached; fine under jit too)
            table = bin_table(o.bins, ndf=o.ndf, dtype=albedo.dtype)
        if o.layer == "bare":  # the mean over the bins' cosines c̄_k
            cb, _ = lookup_bins(table, jnp.cos(theta_o), alpha)
            return albedo * jnp.mean(bare_bands(film, cb, observer, shat=o.shat,
                                                arithmetic=o.arithmetic), axis=-2)
        return albedo * improved_kernel(film, jnp.cos(theta_o), alpha, table, observer=observer,
                                        terms=o.terms, shat=o.shat, lut=lut,
                                        arithmetic=o.arithmetic)

    def envmap_tables(self, pref, options, dtype):
        """The map and the (θ_o, α) tables of its reads (they travel together)."""
        own = options.improved  # `ImprovedOptions`: K, reads a bin, light spread
        return pref, bin_table(own.bins, reads=own.bin_reads, dtype=dtype)

    def map_static(self, options):
        return options.improved.light_spread

    def prefiltered(self, pref):
        return pref[0]

    def map_light(self, film, alpha, normal, view, pref, cfg):
        pref, table = pref
        return improved_envmap(film, alpha, normal, view, pref, table, observer=cfg.observer,
                               terms=cfg.terms, shat=cfg.shat,
                               lut=shat_lut(pref, cfg, alpha.dtype), arithmetic=cfg.arithmetic,
                               cross_band=cfg.cross_band, light_spread=cfg.static,
                               layer=cfg.layer)


IMPROVED = Improved()


def improved_envmap(film: Film, alpha, normal, view, pref, table: BinTable, *,
                    observer=DEFAULT_OBSERVER, terms: int = 2, shat: str = "lut",
                    lut: ShatLUT | None = None, arithmetic: str = "complex",
                    cross_band: bool = True, light_spread: bool = False,
                    layer: str = "film") -> Array:
    r"""`envmap_radiance(method="improved")` at shading points: L_j (..., J), 0 where ⟨n,ω_o⟩ ≤ 0.

    $$ L_j = \frac{A(\theta_o,\alpha)}{K}\sum_{k=1}^{K}\sum_c
       R_{jc}(\bar c_k + \Delta c_k, s_k)\, P_c(d_k, \alpha_k) $$

    The bins split the lobe exactly (E[R L] = (1/K) Σ_k E[R L | bin k]); bin k's film
    reflectance (`improved_bins`) multiplies read k of the K prefiltered reads fitted to the
    lobe's shape (`improved.lookup_reads`), at the bin's mean incidence cosine moved by what
    the read's luminance-weighted mean direction says, Δc_k (`bin_radiance_parts`:
    the covariance of R and L inside a bin). A constant environment gives Δc = 0 and the
    uniform-light model. Per point: K reads of 3 radiance and 3 moment channels (9 with
    `light_spread`, which also moves each bin's spread), against `filtered`'s one read of
    3 + 9 (docs/improved.md); g·K reads when `table` has g reads a bin
    (`bin_table(reads=g)`, `ModelOptions.bin_reads`), pooled per bin.

    Args:
        film: `Film` broadcasting with the shading points.
        alpha: GGX α (...).
        normal, view: unit world vectors (..., 3).
        pref: `prefilter.PrefilteredEnvMap` (its radiance levels and albedo table).
        table: `bin_table(...)`.
        observer: plain band name (the cross bands are used when `cross_band`).
        terms, shat, lut, arithmetic: as `improved_bins`; `lut` must hold the bands used
            (the map's cross-band table when `cross_band`).
        cross_band: R_jc under RGB light (SPEC §9) or the diagonal R_j P_j.
        light_spread: each bin's spread of cos θ₁ follows its read's light too
            (`bin_radiance_parts`; `ModelOptions.light_spread`).
        layer: "film", or "bare" (d = 0): each bin's film term is the exact R₁₃ Ŝ_jc(0) at
            its cosine c̄_k + Δc_k (`reflectance.bare_bands`), as `patch_radiance` gives a
            bare layer at c̄_k.
    """
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    a = lookup_albedo(pref, co, safe_sqrt(alpha))
    cb, sb = lookup_bins(table, co, alpha)
    light = bin_radiance_parts(pref, table, normal, view, co, alpha, sb,
                               light_spread=light_spread)  # bins first
    obs = cross_band_name(observer) if cross_band else observer
    # Σ_c R_jc P_c: the cross-band table read per light channel in place (`lut.read_parts(
    # channel=...)`); three strided copies (`split_by_light`) made in every chunk cost 8 %
    per_light = cross_band and shat == "lut" and layer != "bare"
    bands = functools.partial(bin_bands, observer=obs, terms=terms, shat=shat, lut=lut,
                              arithmetic=arithmetic)
    if layer == "bare":  # no film: R₁₃(c) Ŝ_jc(0), no series, no spread
        bands = functools.partial(_bare_bin, observer=obs, shat=shat, arithmetic=arithmetic)

    def under_light(film, c, s, light):  # the bin's film × its radiance P_k (..., 3)
        if per_light:
            return bands(film, c, s, light)
        r = bands(film, c, s)
        if cross_band:
            return jnp.sum(r.reshape(r.shape[:-1] + (3, 3)) * light[..., None, :], axis=-1)
        return r * light

    out = scan_bins(film, cb, sb, under_light, extra=light)  # Σ_k (..., J)
    return jnp.where(up[..., None], a[..., None] * out * (1.0 / cb.shape[-1]), 0.0)


def _bare_bin(film, c, s, *, observer, shat, arithmetic):
    """A bin's bands of a bare layer (d = 0): R₁₃(c̄) Ŝ_j(0), whatever the spread s."""
    return bare_bands(film, c, observer, shat=shat, arithmetic=arithmetic)


def bin_radiance_parts(pref: PrefilteredEnvMap, table, normal, view, cos_o, alpha, spread, *,
                       light_spread: bool = False):
    r"""The light of the improved model's K bins (docs/improved.md): an `improved.BinLight`
    (radiance (K, ..., 3), cosine shifts and, with `light_spread`, spreads (K, ...), bins
    first: the layout `improved.scan_bins` steps through).

    Read k is the prefiltered radiance P_k and the luminance-weighted moments of the light
    direction, mean μ_k and second moment S_k (K §3.2; S_k only with `light_spread`), at the
    tabulated direction d_k and level α_k (`improved.lookup_reads`: the K kernels fitted to
    the lobe). They place bin k's film where the bin's light is, through x = ⟨ω_o, ω_i⟩
    (c = √((1 + x)/2), K 22). Under uniform light the read's kernel, symmetric about d_k
    with moments m₁, m₂ of ⟨d_k, ω_i⟩ (`BinTable.kernel_moments`, interpolated between the
    levels as the read is), gives x the mean and variance

    $$ \bar x_k = m_1 x_d,\qquad v_k = \tfrac12(1 - m_2) + \tfrac12(3m_2 - 1)\,x_d^2
       - m_1^2 x_d^2,\qquad x_d = \langle\omega_o, d_k\rangle; $$

    the light moves them to ⟨ω_o, μ_k⟩ and v^L_k = ω_oᵀS_kω_o − ⟨ω_o, μ_k⟩², and the bin
    follows (the spread only with `light_spread`; else s'_k = s_k):

    $$ \Delta c_k = \operatorname{clip}\big(c(\langle\omega_o,\mu_k\rangle) - c(\bar x_k),
       \ \pm\sqrt3\,s_k\big),\qquad
       s'_k = s_k\sqrt{\operatorname{clip}(v^L_k / v_k,\ 0,\ 4)}, $$

    the shift clipped to the bin's width (a uniform bin of spread s_k spans ±√3 s_k), the
    spread scaled as the read's light narrows or widens x (one bright texel: s' → 0, the film
    at that texel's cosine; at most twice s_k: wider light belongs to the neighbouring bins,
    which their own reads carry). The spread reads six more moment channels per read (the
    second moments): ≈ 1.18× the cost of `improved` a point, for ≈ 6 % lower mean ΔE₀₀ over
    the small-sources study's 18 renders (docs/studies/improved.md, "Choosing K"). Both
    moves are measured against what the same read of a constant map gives, m₁ Σ_t w_t x_t
    and ½(1 − m₂) + ½(3m₂ − 1) Σ_t w_t x_t² over its four texel centres ω_t, x_t = ⟨ω_o, ω_t⟩
    (`prefilter._read_geometry`; not m₁x_d: within half a row of a pole the read clamps to
    the first row, tilted from d_k by up to π/2h, which moved a constant map's bins by up to
    3.5e-3 in c at 64 rows), and shrunk by what the prefilter resolves (soft thresholds,
    `MOMENT_RESOLUTION`, `VARIANCE_RESOLUTION`: the sampled kernels of narrow levels), so a
    constant environment gives Δc = 0 and s' = s, the uniform-light model (64 × 128, random
    points, α ≥ 0.1; below, the narrow levels' polar rows leave shifts ≤ 9.3e-4).
    Per-channel moments are combined weighted by each channel's luminance. cos_o = ⟨n, ω_o⟩
    > 0; `spread`: the bins' s_k (..., K) (`improved.lookup_bins`, which the caller reads).

    With g reads a bin (a table of ``bin_table(reads=g)``: R = g·K reads, sorted by their
    incidence cosine, bin k served by reads gk … gk + g − 1; `ModelOptions.bin_reads`) the
    bin's light is their pool: P_k the mean of their radiances, μ_k and S_k the
    luminance-weighted means of their moments (each read's light is its kernel's share of
    the bin), and the uniform-light x̄_k, v_k those of the g kernels pooled, i.e. the mean of
    m₁x_d and of E[x²] less the pooled mean squared; g = 1 is the formulas above."""
    reads = _pooled_reads(pref, table, normal, view, alpha, cos_o, spread, light_spread)
    dx = _soft(reads.x_light - reads.x_read, MOMENT_RESOLUTION)
    s = jnp.moveaxis(spread, -1, 0)
    lim = 3.0**0.5 * s
    shift = jnp.clip(_incidence_cos(reads.x_uniform + dx) - _incidence_cos(reads.x_uniform),
                     -lim, lim)
    if not light_spread:
        return BinLight(reads.radiance, shift)
    return BinLight(reads.radiance, shift, _light_spread(reads, table, s))


class _Reads(NamedTuple):
    """`bin_radiance_parts`'s reads, pooled per bin: radiance (K, ..., 3), the read moments
    (R, ..., 3 or 9), ⟨ω_o, μ⟩ under the light and under uniform light (K, ...), ⟨ω_o, d⟩
    (R, ...), ω_o's components, the reads per bin g, and the functions that interpolate a
    kernel moment between the read's levels and pool a read quantity per bin by luminance."""

    radiance: Array
    moments: Array
    x_light: Array
    x_uniform: Array
    x_read: Array
    x_d: Array
    x2_read: Array
    view: tuple  # ω_o's components (vx, vy, vz)
    g: int
    at_read: Any
    light_mean: Any


def _pooled_reads(pref, table, normal, view, alpha, cos_o, spread, light_spread) -> _Reads:
    """The R reads of the bins (`improved.lookup_reads`), their luminance-weighted moments,
    and their means per bin when a bin has g > 1 reads (`bin_radiance_parts`)."""
    dirn, sqa, view_cos = lookup_reads(table, normal, view, cos_o, alpha, view_cosines=True)
    dirn, sqa = jnp.moveaxis(dirn, -2, 0), jnp.moveaxis(sqa, -1, 0)
    h, w = pref.radiance.shape[1:3]
    taps = bilinear_taps(dirn, h, w)
    rad, mom = _read_levels(pref, (pref.radiance, pref.moments), dirn, sqa,
                            channels=(slice(None), slice(None if light_spread else 3)),
                            taps=taps)
    xt1, xt2 = _read_geometry(taps, h, w, view)  # Σ w_t x_t, Σ w_t x_t² of the read
    lum = [float(c) for c in luminance_weights()]

    def luminance(v):  # components written out: a size-3 jnp.sum is a slow XLA:CPU kernel
        return v[..., 0] * lum[0] + v[..., 1] * lum[1] + v[..., 2] * lum[2]

    if pref.per_channel:  # (R, ..., 3 channels, 3 or 9): weight by each channel's luminance
        y_sum = luminance(rad)[..., None]
        y = rad * jnp.asarray(lum, rad.dtype) / jnp.where(y_sum > 0, y_sum, 1.0)
        mom = jnp.sum(y[..., None] * mom, axis=-2)
    g = rad.shape[0] // spread.shape[-1]  # reads per bin (`bin_table(reads=...)`)
    # uniform light: m₁, m₂ of the two levels the read interpolates, with the read's weights
    n_m = table.kernel_moments.shape[-1]
    grid = jnp.linspace(0.0, 1.0, n_m, dtype=sqa.dtype)
    i0, f = _level_lerp(pref, sqa)

    def at_read(m):
        m_levels = jnp.interp(pref.sqrt_alpha, grid, m)
        return m_levels[i0] * (1 - f) + m_levels[i0 + 1] * f

    m1 = at_read(table.kernel_moments[0])
    x_d = jnp.moveaxis(view_cos, -1, 0)
    vx, vy, vz = view[..., 0], view[..., 1], view[..., 2]
    x_light = mom[..., 0] * vx + mom[..., 1] * vy + mom[..., 2] * vz  # ⟨ω_o, μ_r⟩
    x_uniform = m1 * x_d
    x_read = m1 * xt1  # what the read of a constant map gives (`prefilter._read_geometry`)
    light_mean = None
    if g > 1:  # a bin's g reads: radiance and uniform moments averaged, light's by luminance
        y = luminance(rad)
        y_bin = _bin_mean(y, g)
        lit = y_bin > 0
        y_div = jnp.where(lit, y_bin, 1.0)

        def light_mean(v):  # luminance-weighted over the bin's reads (plain mean if dark)
            return jnp.where(lit, _bin_mean(y * v, g) / y_div, _bin_mean(v, g))

        rad = _bin_mean(rad, g)
        x_light, x_uniform = light_mean(x_light), _bin_mean(x_uniform, g)
        x_read = _bin_mean(x_read, g)
    return _Reads(rad, mom, x_light, x_uniform, x_read, x_d, xt2, (vx, vy, vz), g, at_read,
                  light_mean)


def _light_spread(reads: _Reads, table, s):
    """s'_k = s_k √clip(v^L_k / v_k, 0, 4): each bin's spread of c under its read's light
    (`bin_radiance_parts`, ``light_spread=True``)."""
    mom, x_d, g = reads.moments, reads.x_d, reads.g
    vx, vy, vz = reads.view
    m2 = reads.at_read(table.kernel_moments[1])
    xx, yy, zz, xy, yz, zx = (mom[..., c] for c in range(3, 9))
    x2_light = (xx * vx * vx + yy * vy * vy + zz * vz * vz
                + 2.0 * (xy * vx * vy + yz * vy * vz + zx * vz * vx))  # E_L⟨ω_o, ω_i⟩²
    x2_uniform = 0.5 * (1.0 - m2) + 0.5 * (3.0 * m2 - 1.0) * x_d * x_d  # E_U⟨ω_o, ω_i⟩²
    x2_read = 0.5 * (1.0 - m2) + 0.5 * (3.0 * m2 - 1.0) * reads.x2_read  # a constant map's
    if g > 1:  # the bin's reads pooled, as their means above
        x2_light, x2_uniform = reads.light_mean(x2_light), _bin_mean(x2_uniform, g)
        x2_read = _bin_mean(x2_read, g)
    x_light, x_uniform, x_read = reads.x_light, reads.x_uniform, reads.x_read
    v_light = x2_light - x_light * x_light
    v_uniform = x2_uniform - x_uniform * x_uniform
    dv = _soft(v_light - (x2_read - x_read * x_read), VARIANCE_RESOLUTION)
    ok = v_uniform > 0
    ratio = jnp.where(ok, (v_uniform + dv) / jnp.where(ok, v_uniform, 1.0), 1.0)
    return s * safe_sqrt(jnp.clip(ratio, 0.0, 4.0))


def _soft(d, tol):
    """A move within the prefilter's resolution is no move (soft threshold)."""
    return jnp.sign(d) * jnp.maximum(jnp.abs(d) - tol, 0.0)


def _incidence_cos(x):
    """cos θ₁ = √((1 + ⟨ω_o, ω_i⟩)/2) of the mean ⟨ω_o, ω_i⟩ (K 22)."""
    return safe_sqrt(jnp.clip((1.0 + x) * 0.5, 0.0, 1.0))


def _bin_mean(v, g):
    """Means of `g` consecutive reads (R, ...) → (R / g, ...): bin k's reads are
    gk … gk + g − 1 (`bin_table(reads=g)`: the R reads sorted by incidence cosine)."""
    return sum(v[i::g] for i in range(g)) * (1.0 / g)
