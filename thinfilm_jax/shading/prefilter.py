r"""Prefiltered environment maps for the real-time IBL methods (Karis 2013; K §3.2).

Split-sum assumption ω_o = n = ω_r: the light-direction distribution of a microfacet lobe
becomes a kernel that depends only on ⟨ω_r, ω_i⟩ (K 9). For GGX with height-correlated
Smith and n = ω_o = ω_r,

$$ k_\alpha(\omega_r, \omega_i) = \tilde\rho\,\langle n,\omega_i\rangle =
   \frac{D(\cos\theta_h)\,G_2(\langle\omega_r,\omega_i\rangle, 1)}{4},\qquad
   \cos\theta_h = \sqrt{(1 + \langle\omega_r,\omega_i\rangle)/2}, $$

and per roughness level α_l and output direction ω_r the map stores, over the input texels
t (centre ω_t, solid angle Ω_t, RGB radiance c_t, weights w_t = k_α(ω_r, ω_t) Ω_t):

* prefiltered radiance P(ω_r) = Σ w_t c_t / Σ w_t (normalised as in Karis 2013, so a
  constant environment is reproduced exactly);
* the nine moment channels of K §3.2, E[ω], E[ω ωᵀ] (x, y, z, xx, yy, zz, xy, yz, zx) of
  ω_i under p ∝ k_α Y(c_t) (luminance Y of Rec. 709, `moments="luminance"`, the paper's
  choice) or under p ∝ k_α c_{t,k} per RGB channel (`moments="per_channel"`);
* the prefiltered BRDF A(θ_o, α) (K 9, SPEC §6) on a (θ_o, √α) grid, from
  `microfacet.albedo` (the one implementation);
* the Ŝ(μ, σ²) LUT of the cross bands S_j B_k (`uplift`), for K 29 under RGB light.

Levels are uniform in √α from 0 (the map itself, box-filtered to the output resolution,
mean = ω_r, covariance 0) to 1; lookups interpolate bilinearly in direction and linearly in
√α. Each level's input is the map box-filtered (`envmap.downsample`) until its texels are
no wider than a quarter of the lobe (≈ α radians), which bounds the cost. Errors of the
resolution and level count against the exact reference are measured in tests/shading/test_ibl.py
and the README.

Example (a constant environment is reproduced exactly at every level, Karis' normalisation):
    >>> import numpy as np
    >>> from thinfilm_jax.shading.prefilter import prefilter_envmap
    >>> pref = prefilter_envmap(np.ones((8, 16, 3)), levels=3, resolution=(8, 16),
    ...                         albedo_shape=(8, 5))
    >>> pref.radiance.shape, pref.moments.shape  # (L, h, w, 3), (L, h, w, 9)
    ((3, 8, 16, 3), (3, 8, 16, 9))
    >>> bool(np.allclose(pref.radiance, 1.0))
    True
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from .envmap import (EnvMap, bilinear_taps, downsample, load_envmap, luminance_weights,
                     read_taps, texel_centers, texel_solid_angles)
from ..optics.fresnel import complex_dtype, safe_sqrt
from ..realtime.improved import BinLight, _bilinear, lookup_lobe, lookup_reads
from ..spectral.lut import ShatLUT, build_shat_lut
from ..brdf.microfacet import albedo, normal_distribution, smith_g2
from .sources import Sources, extract_sources, with_film_tables
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS
from ..spectral.uplift import cross_band_name

MOMENTS = ("luminance", "per_channel")
#: moves of ⟨ω_o, mean light direction⟩ below this are the prefilter's own error
#: (`bin_radiance_parts`)
MOMENT_RESOLUTION = 1e-3
#: moves of the variance of ⟨ω_o, ω_i⟩ below this are the prefilter's own error
#: (`bin_radiance_parts`)
VARIANCE_RESOLUTION = 1e-3


class PrefilteredEnvMap(NamedTuple):
    """Prefiltered maps (a pytree of arrays). L levels, output (h, w), moment channels:

    sqrt_alpha: (L,) √α of the levels, from 0 to 1.
    radiance: (L, h, w, 3) prefiltered RGB radiance.
    moments: (L, h, w, 9) luminance-weighted or (L, h, w, 3, 9) per-channel moments
        (x, y, z, xx, yy, zz, xy, yz, zx).
    albedo: (n_u, n_a) A(θ_o, α) on uniform grids of √cos θ_o and √α (`albedo_table`).
    lut: `ShatLUT` of the cross bands (J·3 bands).
    sources: `sources.Sources` split from the map (`prefilter_envmap(sources=...)`), shaded
        apart by every real-time method; the levels then hold the residual map. None: none.
    """

    sqrt_alpha: Array
    radiance: Array
    moments: Array
    albedo: Array
    lut: ShatLUT
    sources: Sources | None = None

    @property
    def per_channel(self) -> bool:
        return self.moments.ndim == 5

    def astype(self, dtype) -> PrefilteredEnvMap:
        """Every table in `dtype` (complex tables in its complex counterpart), e.g. float32
        for the real-time paths."""
        cdt = complex_dtype(jnp.zeros((), dtype))
        return jax.tree.map(lambda x: x.astype(cdt if jnp.iscomplexobj(x) else dtype), self)

    @property
    def has_sources(self) -> bool:
        return self.sources is not None and self.sources.count > 0


def _features(d, xp=jnp):
    """The nine moment features (x, y, z, xx, yy, zz, xy, yz, zx) of directions (..., 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return xp.stack([x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], axis=-1)


@jax.jit
def _lobe_rows(alpha, cos_r, sin_r, cos_i, sin_i, cos_dphi):
    """k_α(ω_r, ω_t) (R, H, W) between output rows r and the input texels of rows i at
    azimuth offsets Δφ: ⟨ω_r, ω_t⟩ = sin θ_r sin θ_i cos Δφ + cos θ_r cos θ_i (no
    contraction). In float64 where JAX has it (the narrow lobes' D is steep in ⟨ω_r, ω_t⟩)."""
    ci = (sin_r[:, None, None] * sin_i[None, :, None] * cos_dphi[None, None, :]
          + cos_r[:, None, None] * cos_i[None, :, None])
    ok = ci > 0
    cs = jnp.where(ok, jnp.minimum(ci, 1.0), 0.0)
    ch = jnp.sqrt((1 + cs) / 2)
    k = normal_distribution(ch, alpha) * smith_g2(cs, jnp.ones_like(cs), alpha) / 4
    return jnp.where(ok, k, 0.0)


def level_source(env: EnvMap, alpha: float, min_rows: int) -> EnvMap:
    """The coarsest box-filtered map (`envmap.downsample` by 2, repeatedly) whose texels stay
    no wider than a quarter of the lobe (π/H ≤ α/4) and whose rows stay ≥ `min_rows`: the
    input of a level (also of `colour_table`'s filtered maps)."""
    src = env
    while (src.shape[0] // 2 >= min_rows and src.shape[0] % 2 == 0
           and np.pi / (src.shape[0] // 2) <= alpha / 4):
        src = downsample(src, 2)
    return src


def filter_level(alpha: float, radiance, h: int, w: int, per_channel: bool = False,
                 row_block: int = 16):
    """One level of the prefilter: P (h, w, 3) and the moments (h, w, 9) or (h, w, 3, 9)
    (NaN where the lobe sees no light) of an equirect map `radiance` (H, W, 3), W a multiple
    of w, at the output texel centres, float64 NumPy arrays (the kernel evaluated by
    `_lobe_rows` in JAX's default float, the sums in float64 on the host).

    The weights w_t = k_α(ω_r, ω_t) Ω_t of an output direction depend on its column only
    through the azimuth offset φ_t − φ_r, so each output row is a circular correlation
    along φ: evaluated with FFTs, Σ_t w_t s_t for every column of a row costs
    O(H W log W) instead of O(w H W) products (s_t: the radiance, 1, the luminance and its
    products with the nine direction features). Sums below 1e-12 of the lobe's weight times
    the map's largest luminance are taken as no light (FFT rounding, ~1e-16 of it)."""
    rad = np.asarray(radiance, np.float64)
    big_h, big_w = rad.shape[:2]
    f = big_w // w
    th_i = (np.arange(big_h) + 0.5) * np.pi / big_h
    th_r = (np.arange(h) + 0.5) * np.pi / h
    dphi = (np.arange(big_w) - (f - 1) / 2) * 2 * np.pi / big_w  # φ_t − φ_r, t = m + f j
    omega = texel_solid_angles(big_h, big_w)[:, 0]
    lum = luminance_weights()
    y = rad if per_channel else rad @ lum[:, None]  # (H, W, 1 or 3)
    feats = _features(texel_centers(big_h, big_w), np)  # (H, W, 9)
    num = (y[..., :, None] * feats[..., None, :]).reshape(big_h, big_w, -1)
    sig = np.concatenate([rad, np.ones((big_h, big_w, 1)), y, num], axis=-1)  # (H, W, C)
    spec = np.fft.rfft(sig, axis=1).transpose(1, 0, 2)  # (K, H, C)
    dt = jnp.result_type(float)
    args = [jnp.asarray(x, dt) for x in (np.cos(th_i), np.sin(th_i), np.cos(dphi))]
    out = []
    for r0 in range(0, h, row_block):
        rows = th_r[r0:r0 + row_block]
        k = np.asarray(_lobe_rows(jnp.asarray(alpha, dt), jnp.asarray(np.cos(rows), dt),
                                  jnp.asarray(np.sin(rows), dt), *args), np.float64)
        g = np.fft.rfft(k * omega[None, :, None], axis=2).transpose(2, 0, 1)  # (K, R, H)
        corr = np.matmul(g.conj(), spec)  # (K, R, C): Σ_i conj(Ĝ) Ŝ
        out.append(np.fft.irfft(corr.transpose(1, 2, 0), n=big_w, axis=2)[:, :, ::f])
    sums = np.concatenate(out).transpose(0, 2, 1)  # (h, w, C)
    n_y = y.shape[-1]
    p = sums[..., :3] / sums[..., 3:4]
    den = sums[..., 4:4 + n_y]
    safe = den > 1e-12 * sums[..., 3:4] * y.max(axis=(0, 1))
    mom = sums[..., 4 + n_y:].reshape(h, w, n_y, 9) / np.where(safe, den, 1.0)[..., None]
    mom = np.where(safe[..., None], mom, np.nan)
    return p, (mom if per_channel else mom[..., 0, :])


def prefilter_envmap(envmap, *, observer: str = DEFAULT_OBSERVER, levels: int = 17,
                     resolution: tuple[int, int] | None = None, moments: str = "luminance",
                     albedo_shape: tuple[int, int] = (64, 33), dtype=None,
                     sources: int = 0) -> PrefilteredEnvMap:
    """Prefilter an `EnvMap` (or anything `load_envmap` reads) for the real-time methods.

    Args:
        envmap: `EnvMap`, path, shipped name or (H, W, 3) array.
        observer: colour bands of the output (the LUT holds their cross bands).
        levels: number of roughness levels, uniform in √α ∈ [0, 1] (≥ 2).
        resolution: (h, w) of every level, w = 2h, dividing the map's size; default
            (64, 128) or the map's own if smaller.
        moments: "luminance" (K §3.2, 9 channels) or "per_channel" (27 channels).
        albedo_shape: nodes of the A table in √cos θ_o and in √α (`albedo_table`).
        dtype: float dtype of the tables (default: the map's).
        sources: split up to this many compact bright sources (suns) from the map at its
            full resolution (`sources.extract_sources`, defaults there) and prefilter the
            residual; the real-time methods then shade the sources apart
            (`sources.source_radiance`). 0 (default): the map as it is (the published
            `filtered` method).
    Cost: Σ_levels h·N_l kernel evaluations and h FFT correlations over N_l texels (N_l input
    texels of level l, `filter_level`), once: 2.8–3.3 s for a 512 × 1024 map (float64, 2-core
    CPU; 44–45 s when every output texel summed every input texel; figures/prefilter_bench.md).
    """
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(env)):
        raise ValueError("prefilter_envmap runs on the host and needs a concrete map, got a "
                         "traced one (under jax.jit, vmap or grad with respect to the map): "
                         "call prefilter_envmap outside jit and pass the PrefilteredEnvMap")
    with jax.ensure_compile_time_eval():  # a concrete map: host tables, also under a trace
        return _prefilter(env, observer, levels, resolution, moments, albedo_shape, dtype,
                          sources)


def _prefilter(env, observer, levels, resolution, moments, albedo_shape, dtype, sources):
    """`prefilter_envmap` of a concrete `EnvMap` (arguments as there)."""
    found = None
    if sources:
        env, found = extract_sources(env, max_sources=sources)
    V.check_choice("observer", observer, OBSERVERS)
    V.check_choice("moments", moments, MOMENTS)
    big_h, big_w = env.shape
    h, w = resolution or (min(big_h, 64), min(big_w, 128))
    if not (isinstance(levels, int) and levels >= 2):
        raise ValueError(f"levels must be an int >= 2, got {levels!r}")
    if w != 2 * h or big_h % h or big_w % w:
        raise ValueError(f"resolution must be (h, 2h) dividing the map's {big_h} × {big_w}, "
                         f"got {resolution}")
    dtype = dtype or env.radiance.dtype
    sqa = np.linspace(0.0, 1.0, levels)
    out_dirs = jnp.asarray(texel_centers(h, w), dtype)
    per_channel = moments == "per_channel"
    rads, moms = [], []
    for s in sqa:
        if s == 0.0:
            base = downsample(env, big_h // h).radiance.astype(dtype)
            f = _features(out_dirs)
            m = f[..., None, :].repeat(3, -2) if per_channel else f
            rads.append(base)
            moms.append(m)
            continue
        alpha = s * s
        src = level_source(env, alpha, h)  # not below the output's rows
        p, m = (jnp.asarray(x, dtype) for x in filter_level(alpha, src.radiance, h, w,
                                                             per_channel))
        lobe = _features(out_dirs)  # only used where the neighbourhood is black
        if per_channel:
            lobe = lobe[..., None, :]
        m = jnp.where(jnp.isnan(m), lobe, m)
        rads.append(p)
        moms.append(m)
    table = albedo_table(*albedo_shape)
    lut = build_shat_lut(cross_band_name(observer), dtype=dtype)
    return PrefilteredEnvMap(jnp.asarray(sqa, dtype), jnp.stack(rads), jnp.stack(moms),
                             jnp.asarray(table, dtype), lut,
                             None if found is None else
                             with_film_tables(found, observer, dtype).astype(dtype))


@functools.cache
def albedo_table(n_u: int = 64, n_a: int = 33) -> np.ndarray:
    """A(θ_o, α) (`microfacet.albedo`) on uniform grids of u = √cos θ_o and √α ∈ [0, 1]
    (√α = 0 evaluated at α = 1e-4). The √cos grid resolves the steep fall of A at grazing
    views: bilinear lookup error ≤ 8e-4 for θ_o < 80°, ≤ 5e-3 up to 90° (64 × 33)."""
    u = np.linspace(0.0, 1.0, n_u)
    sqa = np.linspace(0.0, 1.0, n_a)
    theta = np.arccos(u**2)
    return np.asarray(albedo(theta[:, None], np.maximum(sqa**2, 1e-4)[None, :]))


def _level_lerp(pref: PrefilteredEnvMap, sqrt_alpha):
    n = pref.sqrt_alpha.shape[0]
    t = jnp.clip(sqrt_alpha, 0.0, 1.0) * (n - 1)
    i0 = jnp.clip(jnp.floor(t), 0, n - 2)
    return i0.astype(jnp.int32), t - i0


def _read_levels(pref: PrefilteredEnvMap, tables, direction, sqrt_alpha, channels=None):
    """Each of `tables` (L, h, w, ...) bilinear in direction, linear in √α between levels;
    `channels`: per table, the index of the last axis to read (`envmap.read_taps`).

    The texels and weights in direction (`envmap.bilinear_taps`, two arctangents) are found
    once for all tables and both levels; the two levels are the two steps of a `lax.scan`,
    so the read is a loop whose results are buffers. Unrolled, XLA's CPU backend fuses the
    gathers into every consumer of the read (the kernels use the moments in dozens of
    places) and recomputes them there: `envmap_radiance(method="filtered")` took 1.9× as
    long (figures/kernel_bench.md)."""
    i0, f = _level_lerp(pref, sqrt_alpha)
    h, w = tables[0].shape[1:3]
    taps = bilinear_taps(direction, h, w)
    shape = jnp.broadcast_shapes(direction.shape[:-1], f.shape)
    channels = (slice(None),) * len(tables) if channels is None else channels

    def level(acc, step):  # step 0: level i0 with weight 1 − f; step 1: i0 + 1 with f
        wgt = jnp.where(step == 0, 1 - f, f)
        reads = (read_taps(t, i0 + step, taps, c) for t, c in zip(tables, channels))
        return tuple(a + r * wgt.reshape(wgt.shape + (1,) * (r.ndim - wgt.ndim))
                     for a, r in zip(acc, reads)), None

    acc = tuple(jnp.zeros(shape + np.empty(t.shape[3:])[..., c].shape, jnp.result_type(t, f))
                for t, c in zip(tables, channels))
    return jax.lax.scan(level, acc, jnp.arange(2, dtype=jnp.int32))[0]


def lookup_prefiltered(pref: PrefilteredEnvMap, omega_r, sqrt_alpha):
    """(P (..., 3), moments (..., 9) or (..., 3, 9)) at the reflection direction and √α."""
    return _read_levels(pref, (pref.radiance, pref.moments), omega_r, sqrt_alpha)


def lookup_radiance(pref: PrefilteredEnvMap, direction, sqrt_alpha):
    """P (..., 3) alone (no moments) at a direction and √α."""
    return _read_levels(pref, (pref.radiance,), direction, sqrt_alpha)[0]


def lookup_albedo(pref: PrefilteredEnvMap, cos_o, sqrt_alpha):
    """A(θ_o, α) from the table: bilinear in (√cos θ_o, √α)."""
    n_u, n_a = pref.albedo.shape

    def cell(x, n):
        t = jnp.clip(x, 0.0, 1.0) * (n - 1)
        i = jnp.clip(jnp.floor(t), 0, n - 2)
        return i.astype(jnp.int32), t - i

    j0, fu = cell(jnp.sqrt(jnp.clip(cos_o, 0.0, 1.0)), n_u)
    i0, fa = cell(sqrt_alpha, n_a)
    tab = pref.albedo
    a0 = tab[j0, i0] * (1 - fu) + tab[j0 + 1, i0] * fu
    a1 = tab[j0, i0 + 1] * (1 - fu) + tab[j0 + 1, i0 + 1] * fu
    return a0 * (1 - fa) + a1 * fa


def bin_radiance(pref: PrefilteredEnvMap, table, normal, view, cos_o, alpha):
    """The prefiltered radiance of each bin's part of the lobe (..., K, 3), moment-matched:
    read at the part's mean light direction and equal-variance level (`improved.lookup_lobe`);
    where the bins are rings round ω_o (near normal view, ring weight w of `BinTable.ring`)
    their mean is moved to the whole lobe's read, w (P − (1/K) Σ_k P_k). cos_o = ⟨n, ω_o⟩ > 0.
    (`colour_table` reads it; `envmap_radiance(method="improved")` reads
    `bin_radiance_parts`, whose reads are fitted to the lobe instead: docs/improved.md.)"""
    dirn, sqa_eff = lookup_lobe(table, normal, view, cos_o, alpha)  # (..., K + 1, 3), (..., K + 1)
    rad = lookup_radiance(pref, jnp.moveaxis(dirn, -2, 0), jnp.moveaxis(sqa_eff, -1, 0))
    k = rad.shape[0] - 1  # rad: (K + 1, ..., 3), the whole lobe's read last
    w = _bilinear(table.ring, safe_sqrt(cos_o), safe_sqrt(alpha))[..., None]
    shift = w * (rad[k] - sum(rad[b] for b in range(k)) * (1.0 / k))
    return jnp.moveaxis(rad[:k] + shift, 0, -2)


def _incidence_cos(x):
    """cos θ₁ = √((1 + ⟨ω_o, ω_i⟩)/2) of the mean ⟨ω_o, ω_i⟩ (K 22)."""
    return safe_sqrt(jnp.clip((1.0 + x) * 0.5, 0.0, 1.0))


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
    moves are shrunk by what the prefilter resolves (soft thresholds): a constant map's
    read moments differ from the kernel's by ≤ 5.6e-4 in the mean (`MOMENT_RESOLUTION`)
    and ≤ 7.2e-4 in the variance of x (`VARIANCE_RESOLUTION`;
    64 × 128, 17 levels, random directions and levels, α = 0.05–0.5: the sampled kernel of
    narrow levels and the bilinear read), so a constant environment gives Δc = 0 and s' = s,
    the uniform-light model. Per-channel moments are combined weighted by each channel's
    luminance. cos_o = ⟨n, ω_o⟩ > 0; `spread`: the bins' s_k (..., K)
    (`improved.lookup_bins`, which the caller reads).

    With g reads a bin (a table of ``bin_table(reads=g)``: R = g·K reads, sorted by their
    incidence cosine, bin k served by reads gk … gk + g − 1; `ModelOptions.bin_reads`) the
    bin's light is their pool: P_k the mean of their radiances, μ_k and S_k the
    luminance-weighted means of their moments (each read's light is its kernel's share of
    the bin), and the uniform-light x̄_k, v_k those of the g kernels pooled, i.e. the mean of
    m₁x_d and of E[x²] less the pooled mean squared; g = 1 is the formulas above."""
    dirn, sqa, view_cos = lookup_reads(table, normal, view, cos_o, alpha, view_cosines=True)
    dirn, sqa = jnp.moveaxis(dirn, -2, 0), jnp.moveaxis(sqa, -1, 0)
    rad, mom = _read_levels(pref, (pref.radiance, pref.moments), dirn, sqa,
                            channels=(slice(None), slice(None if light_spread else 3)))
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
    if g > 1:  # a bin's g reads: radiance and uniform moments averaged, light's by luminance
        y = luminance(rad)
        y_bin = _bin_mean(y, g)
        lit = y_bin > 0
        y_div = jnp.where(lit, y_bin, 1.0)

        def light_mean(v):  # luminance-weighted over the bin's reads (plain mean if dark)
            return jnp.where(lit, _bin_mean(y * v, g) / y_div, _bin_mean(v, g))

        rad = _bin_mean(rad, g)
        x_light, x_uniform = light_mean(x_light), _bin_mean(x_uniform, g)

    def soft(d, tol):  # a move within the prefilter's resolution is no move
        return jnp.sign(d) * jnp.maximum(jnp.abs(d) - tol, 0.0)

    dx = soft(x_light - x_uniform, MOMENT_RESOLUTION)
    s = jnp.moveaxis(spread, -1, 0)
    lim = 3.0**0.5 * s
    shift = jnp.clip(_incidence_cos(x_uniform + dx) - _incidence_cos(x_uniform), -lim, lim)
    if not light_spread:
        return BinLight(rad, shift)
    m2 = at_read(table.kernel_moments[1])
    xx, yy, zz, xy, yz, zx = (mom[..., c] for c in range(3, 9))
    x2_light = (xx * vx * vx + yy * vy * vy + zz * vz * vz
                + 2.0 * (xy * vx * vy + yz * vy * vz + zx * vz * vx))  # E_L⟨ω_o, ω_i⟩²
    x2_uniform = 0.5 * (1.0 - m2) + 0.5 * (3.0 * m2 - 1.0) * x_d * x_d  # E_U⟨ω_o, ω_i⟩²
    if g > 1:  # the bin's reads pooled, as their means above
        x2_light, x2_uniform = light_mean(x2_light), _bin_mean(x2_uniform, g)
    v_light = x2_light - x_light * x_light
    v_uniform = x2_uniform - x_uniform * x_uniform
    dv = soft(v_light - v_uniform, VARIANCE_RESOLUTION)
    ok = v_uniform > 0
    ratio = jnp.where(ok, (v_uniform + dv) / jnp.where(ok, v_uniform, 1.0), 1.0)
    return BinLight(rad, shift, s * safe_sqrt(jnp.clip(ratio, 0.0, 4.0)))


def _bin_mean(v, g):
    """Means of `g` consecutive reads (R, ...) → (R / g, ...): bin k's reads are
    gk … gk + g − 1 (`bin_table(reads=g)`: the R reads sorted by incidence cosine)."""
    return sum(v[i::g] for i in range(g)) * (1.0 / g)


def moments_to_mean_cov(m):
    """μ (..., 3) and Σ (..., 3, 3) from the nine moment channels."""
    mean = m[..., :3]
    xx, yy, zz, xy, yz, zx = (m[..., k] for k in range(3, 9))
    second = jnp.stack([jnp.stack([xx, xy, zx], -1), jnp.stack([xy, yy, yz], -1),
                        jnp.stack([zx, yz, zz], -1)], -2)
    return mean, second - mean[..., :, None] * mean[..., None, :]
