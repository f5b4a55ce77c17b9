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
* the prefiltered BRDF A(θ_o, α) (K 9, SPEC §6) on a (θ_o, √α) grid dense near grazing, from
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
from ..realtime.improved import _bilinear, lookup_lobe
from ..spectral.lut import ShatLUT, build_shat_lut
from ..brdf.microfacet import albedo, normal_distribution, smith_g2
from .sources import Sources, extract_sources, with_film_tables
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS
from ..spectral.uplift import cross_band_name

__all__ = [
    "MOMENT_RESOLUTION",
    "VARIANCE_RESOLUTION",
    "PrefilteredEnvMap",
    "level_source",
    "filter_level",
    "prefilter_envmap",
    "albedo_table",
    "albedo_coordinate",
    "lookup_prefiltered",
    "lookup_radiance",
    "lookup_albedo",
    "bin_radiance",
    "moments_to_mean_cov",
]

MOMENTS = ("luminance", "per_channel")
#: moves of ⟨ω_o, mean light direction⟩ below this are the prefilter's own error
#: (`methods.improved.bin_radiance_parts`)
MOMENT_RESOLUTION = 1e-3
#: moves of the variance of ⟨ω_o, ω_i⟩ below this are the prefilter's own error
#: (`methods.improved.bin_radiance_parts`)
VARIANCE_RESOLUTION = 1e-3


class PrefilteredEnvMap(NamedTuple):
    """Prefiltered maps (a pytree of arrays). L levels, output (h, w), moment channels:

    sqrt_alpha: (L,) √α of the levels, from 0 to 1.
    radiance: (L, h, w, 3) prefiltered RGB radiance.
    moments: (L, h, w, 9) luminance-weighted or (L, h, w, 3, 9) per-channel moments
        (x, y, z, xx, yy, zz, xy, yz, zx).
    albedo: (n_u, n_a) A(θ_o, α) on uniform grids of the view coordinate t
        (`albedo_coordinate`) and √α (`albedo_table`).
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
        albedo_shape: nodes of the A table in its view coordinate t and in √α
            (`albedo_table`).
        dtype: float dtype of the tables (default: the map's).
        sources: split up to this many compact bright sources (suns) from the map at its
            full resolution (`sources.extract_sources`, defaults there) and prefilter the
            residual; the real-time methods then shade the sources apart
            (`sources.source_radiance`). 0 (default): the map as it is (the published
            `filtered` method).
    Cost: Σ_levels h·N_l kernel evaluations and h FFT correlations over N_l texels (N_l input
    texels of level l, `filter_level`), once: 2.8–3.3 s for a 512 × 1024 map (float64, 2-core
    CPU; 44–45 s when every output texel summed every input texel; figures/prefilter_bench.md).

    Uniform light (SPEC §7, §9): under a constant map L ≡ 1 a real-time method's
    `envmap_radiance` is its own `patch_radiance` model when the levels have at least
    64 rows (a map of 64 × 128 or larger at the default `resolution`). Worst band
    difference, film d = 600 nm (and d = 0 alike), α ∈ [0.005, 0.6], two normals
    (benchmarks/envmap_consistency.py):

    | levels | method | θ_o < 80° | 80–88° | 88–90° |
    |---|---|---:|---:|---:|
    | 64 × 128 (maps 64 × 128, 128 × 256) | ideal, improved (all presets) | 1.1e-4 | 2.1e-4 | 3.9e-4 |
    | 32 × 64 | ideal | 7.5e-5 | 1.9e-4 | 3.9e-4 |
    | 32 × 64 | improved (all presets) | 8.7e-4 | 6.2e-3 | 1.6e-2 |

    Below 64 rows a texel (π/32 = 0.098 rad) is wider than the narrow levels' lobes
    (α ≲ 0.04), so `filter_level`'s midpoint sum over texels misstates the constant map's
    mean cosine m₁ by more than `MOMENT_RESOLUTION` (equator, √α = 0.125: 0.99914 against
    the kernel's 0.99676; 64 rows: 0.99748); `improved` compares each read with the
    kernel's own m₁ (`methods.improved.bin_radiance_parts`) and moves its bins by up to
    5e-3 in cos θ₁. `filtered` reads its light moments as
    stored (the published method): they are bilinear in direction and linear in √α
    between levels, so its K 22 cosine near grazing departs from the uniform-light split
    sum's at any size (64 × 128: ≤ 1.5e-3 below 80°, ≤ 3.7e-2 above; 2–4× less at α on
    a level, e.g. 4.0e-3 against 1.1e-2 at θ_o = 89°, √α = 0.1875 against 0.2236).
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


#: c of the albedo table's view coordinate t = u (1 + k) / (u + k), k = c max(√α, √α_min)
#: (`albedo_table`)
ALBEDO_WARP = 1.0
#: the α of the table's √α = 0 column (and the floor of k's √α)
ALBEDO_MIN_ALPHA = 1e-4


def albedo_coordinate(u, sqrt_alpha, xp=jnp):
    r"""The albedo table's view coordinate t ∈ [0, 1] of u = √cos θ_o at √α (`albedo_table`):

    $$ t = \frac{u\,(1 + k)}{u + k},\qquad k = c\,\max(\sqrt\alpha, 10^{-2}),\ c = 1. $$

    t(0) = 0, t(1) = 1, increasing; u = k t / (1 + k − t) inverts it. c = 1 of 0.5, 1, 2
    (worst read error at θ_o ≥ 88° on the 64 × 33 table: 5.4e-4, 5.3e-4, 7.8e-4)."""
    k = _albedo_k(sqrt_alpha, xp)
    return u * (1 + k) / (u + k)


def _albedo_k(sqrt_alpha, xp):
    """k = c max(√α, √α_min) of `albedo_coordinate` (and of its inverse in `albedo_table`)."""
    return ALBEDO_WARP * xp.maximum(sqrt_alpha, float(np.sqrt(ALBEDO_MIN_ALPHA)))


@functools.cache
def albedo_table(n_u: int = 64, n_a: int = 33) -> np.ndarray:
    r"""A(θ_o, α) (`microfacet.albedo`) on uniform grids of the view coordinate t of
    `albedo_coordinate` and of √α ∈ [0, 1] (√α = 0 evaluated at α = 1e-4).

    Near grazing the GGX albedo is a function of cos θ_o / α: it dips (to ≈ 0.89) where
    cos θ_o ≈ α and returns to 1 at cos θ_o = 0, a feature of width ∝ √α in u = √cos θ_o.
    t = u (1 + k)/(u + k) with k ∝ √α puts that dip at the same t for every small α (half
    the nodes below u = √α at c = 1), so the bilinear read follows it in both directions;
    uniform in u, the table missed it at small α (linear in √α between columns whose dips
    sit at different u). Bilinear read against the quadrature (`lookup_albedo`, 64 × 33,
    α ∈ [0.002, 1], measured by benchmarks/envmap_consistency.py --table): θ_o < 80°:
    ≤ 4.3e-4; 80–88°: ≤ 3.5e-4; 88–90°: ≤ 5.1e-4 (uniform in u: 6.1e-4, 3.2e-3, 2.9e-2).
    The read costs one division more than uniform u (t), at the same two-by-two taps."""
    t = np.linspace(0.0, 1.0, n_u)[:, None]
    sqa = np.linspace(0.0, 1.0, n_a)[None, :]
    k = _albedo_k(sqa, np)
    u = k * t / (1 + k - t)  # the inverse of `albedo_coordinate`
    theta = np.arccos(np.clip(u * u, 0.0, 1.0))
    return np.asarray(albedo(theta, np.broadcast_to(np.maximum(sqa**2, ALBEDO_MIN_ALPHA),
                                                    theta.shape)))


def _level_lerp(pref: PrefilteredEnvMap, sqrt_alpha):
    n = pref.sqrt_alpha.shape[0]
    t = jnp.clip(sqrt_alpha, 0.0, 1.0) * (n - 1)
    i0 = jnp.clip(jnp.floor(t), 0, n - 2)
    return i0.astype(jnp.int32), t - i0


def _read_levels(pref: PrefilteredEnvMap, tables, direction, sqrt_alpha, channels=None,
                 taps=None):
    """Each of `tables` (L, h, w, ...) bilinear in direction, linear in √α between levels;
    `channels`: per table, the index of the last axis to read (`envmap.read_taps`); `taps`:
    `envmap.bilinear_taps(direction, h, w)` when the caller has them (`_read_geometry`).

    The texels and weights in direction (`envmap.bilinear_taps`, two arctangents) are found
    once for all tables and both levels; the two levels are the two steps of a `lax.scan`,
    so the read is a loop whose results are buffers. Unrolled, XLA's CPU backend fuses the
    gathers into every consumer of the read (the kernels use the moments in dozens of
    places) and recomputes them there: `envmap_radiance(method="filtered")` took 1.9× as
    long (figures/kernel_bench.md)."""
    i0, f = _level_lerp(pref, sqrt_alpha)
    h, w = tables[0].shape[1:3]
    taps = bilinear_taps(direction, h, w) if taps is None else taps
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


def _read_geometry(taps, h: int, w: int, view):
    r"""What a bilinear read (`envmap.bilinear_taps` on an h × w level) sees of a view ω_o:
    (Σ_t w_t x_t, Σ_t w_t x_t²), x_t = ⟨ω_o, ω_t⟩ over its four texel centres ω_t, weights
    w_t. Every level of a constant map stores, at each texel centre, the moments of its
    kernel, symmetric about ω_t: mean m₁ω_t and second moment ½(1 − m₂)I + ½(3m₂ − 1)ω_tω_tᵀ
    (`prefilter_envmap`). Its read at d is their blend, so the read's ⟨ω_o, μ⟩ is m₁Σ w_t x_t
    and its E⟨ω_o, ω_i⟩² is ½(1 − m₂) + ½(3m₂ − 1)Σ w_t x_t², not m₁⟨ω_o, d⟩ and
    ½(1 − m₂) + ½(3m₂ − 1)⟨ω_o, d⟩²: the blend of unit vectors is shorter than d (second
    order in the texel size) and, within half a texel of a pole, where the read clamps to
    the first row, tilted from d by up to π/2h (first order: 0.049 at h = 32).
    `methods.improved.bin_radiance_parts` compares the light's moments with these."""
    i0, i1, j0, j1, fx, fy = taps
    dt = fx.dtype
    th = (np.arange(h) + 0.5) * np.pi / h
    ph = (np.arange(w) + 0.5) * 2 * np.pi / w
    st, ct = jnp.asarray(np.sin(th), dt), jnp.asarray(np.cos(th), dt)
    cp, sp = jnp.asarray(np.cos(ph), dt), jnp.asarray(np.sin(ph), dt)
    vx, vy, vz = view[..., 0], view[..., 1], view[..., 2]
    x1 = x2 = 0.0
    for i, j, wt in ((i0, j0, (1 - fx) * (1 - fy)), (i0, j1, fx * (1 - fy)),
                     (i1, j0, (1 - fx) * fy), (i1, j1, fx * fy)):
        x = st[i] * (cp[j] * vx + sp[j] * vy) + ct[i] * vz
        x1, x2 = x1 + wt * x, x2 + wt * x * x
    return x1, x2


def lookup_prefiltered(pref: PrefilteredEnvMap, omega_r, sqrt_alpha):
    """(P (..., 3), moments (..., 9) or (..., 3, 9)) at the reflection direction and √α."""
    return _read_levels(pref, (pref.radiance, pref.moments), omega_r, sqrt_alpha)


def lookup_radiance(pref: PrefilteredEnvMap, direction, sqrt_alpha):
    """P (..., 3) alone (no moments) at a direction and √α."""
    return _read_levels(pref, (pref.radiance,), direction, sqrt_alpha)[0]


def lookup_albedo(pref: PrefilteredEnvMap, cos_o, sqrt_alpha):
    """A(θ_o, α) from the table: bilinear in (t, √α), t = `albedo_coordinate`(√cos θ_o, √α)."""
    n_u, n_a = pref.albedo.shape

    def cell(x, n):
        t = jnp.clip(x, 0.0, 1.0) * (n - 1)
        i = jnp.clip(jnp.floor(t), 0, n - 2)
        return i.astype(jnp.int32), t - i

    j0, fu = cell(albedo_coordinate(jnp.sqrt(jnp.clip(cos_o, 0.0, 1.0)), sqrt_alpha), n_u)
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
    `methods.improved.bin_radiance_parts`, whose reads are fitted to the lobe instead:
    docs/improved.md.)"""
    dirn, sqa_eff = lookup_lobe(table, normal, view, cos_o, alpha)  # (..., K + 1, 3), (..., K + 1)
    rad = lookup_radiance(pref, jnp.moveaxis(dirn, -2, 0), jnp.moveaxis(sqa_eff, -1, 0))
    k = rad.shape[0] - 1  # rad: (K + 1, ..., 3), the whole lobe's read last
    w = _bilinear(table.ring, safe_sqrt(cos_o), safe_sqrt(alpha))[..., None]
    shift = w * (rad[k] - sum(rad[b] for b in range(k)) * (1.0 / k))
    return jnp.moveaxis(rad[:k] + shift, 0, -2)


def moments_to_mean_cov(m):
    """μ (..., 3) and Σ (..., 3, 3) from the nine moment channels."""
    mean = m[..., :3]
    xx, yy, zz, xy, yz, zx = (m[..., k] for k in range(3, 9))
    second = jnp.stack([jnp.stack([xx, xy, zx], -1), jnp.stack([xy, yy, yz], -1),
                        jnp.stack([zx, yz, zz], -1)], -2)
    return mean, second - mean[..., :, None] * mean[..., None, :]
