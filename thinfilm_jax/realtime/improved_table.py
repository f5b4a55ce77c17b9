r"""The (θ_o, α) tables of `method="improved"` (`realtime.improved`, docs/improved.md), built
on the host once per argument set (cached by value: `functools.cache` and JAX's persistent
compilation cache, `core.compilation_cache.cached_host_tables`).

`BinTable`: at each (√cos θ_o, √α) node the K equal-probability bins of c = cos θ₁ under the
uniform-light lobe p_R (their means and spreads), each bin's part of the lobe (mean direction,
equal-variance level), the ring weight, and the K prefiltered reads fitted to the lobe
(`_fit_reads`, least absolute deviation), with the prefilter kernel's moments. `bin_table`
builds them; `realtime.improved` reads them.

Example:
    >>> BinTable._fields
    ('stats', 'lobe', 'ring', 'reads', 'kernel_moments')
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..brdf.microfacet import (PatchQuadrature, brdf_no_fresnel, light_moments,
                               normal_distribution, patch_quadrature, smith_g2)
from ..core.compilation_cache import cached_host_tables
from ..optics.fresnel import safe_div, safe_sqrt

__all__ = ["BinTable", "bin_table", "prefilter_kernel", "DEFAULT_BINS"]

DEFAULT_BINS = 3
HI = jax.lax.Precision.HIGHEST  # the host fits' contractions (GPUs default to TF32)
TABLE_SHAPE = (64, 33)  # (√cos θ_o, √α) nodes, as the albedo table
TABLE_QUADRATURE = (96, 96)  # half-vector quadrature of the table build
ALPHA_FLOOR = 1e-4  # quadrature floor of α (the √α = 0 column is the exact mirror limit)
#: the reads' fit (`_fit_reads`): (ρ, φ) grid, LM steps, moments matched and their weight;
#: θ_o (degrees) over which the reads go over to the moment-matched ones (`_fit_reads_host`)
READ_FIT = dict(grid=(32, 24), iterations=30, moments=2, weight=100.0, grazing=(70.0, 85.0))
KERNEL_NODES = 257  # √α nodes of the prefilter kernel's moments (`BinTable.kernel_moments`)


class BinTable(NamedTuple):
    """Tables of the lobe p_R of uniform light (a pytree of arrays), on uniform grids of
    √cos θ_o and √α ∈ [0, 1] (the √α = 0 column is the mirror limit):

    stats: (n_u, n_a, 2, K): [0] offsets c̄_k − cos θ_o of the K equal-probability bin means
        of c = cos θ₁, [1] the bin standard deviations s_k.
    lobe: (n_u, n_a, 2, K + 1): for each bin's part of the lobe (the part whose c lies in
        the bin) and, last, the whole lobe: [0] h = sin β / sin θ_o, with β the angle of its
        mean light direction from n towards ω_r (h = 1: ω_r; h < 0: past n, towards ω_o;
        the ratio is even in θ_o, so smooth at normal view), [1] √α_eff, the roughness whose
        normal-view lobe has the same total variance tr Σ_ω (the prefiltered level to read).
    ring: (n_u, n_a): w = 1 − (angle from ω_o to the whole lobe's mean direction) / (mean
        angle ψ_k = arccos(2c̄_k² − 1) of the bins from ω_o), clipped to [0, 1]: 1 where the
        bins are rings round ω_o (normal view), 0 where they are arcs across the lobe.
        (`lobe` and `ring` place the moment-matched reads of `prefilter.bin_radiance`.)
    reads: (n_u, n_a, 2, K): the K prefiltered reads of `envmap_radiance(method=
        "improved")`: [0] h = sin β / sin θ_o of each read's direction (as `lobe`), [1] its
        level √α; the K prefilter kernels, weighted 1/K each, are the least-absolute-
        deviation fit of the lobe p_R (`_fit_reads`; the √α = 0 column reads ω_r at level 0).
    kernel_moments: (2, KERNEL_NODES) the mean cosine m₁ = E⟨ω_r, ω_i⟩ and mean squared
        cosine m₂ = E⟨ω_r, ω_i⟩² of the prefilter's kernel (`prefilter_kernel`) on a uniform
        grid of √α ∈ [0, 1]: a read of uniform light in direction d has mean light direction
        m₁ d and second moment E[ω_i ω_iᵀ] = ½(1 − m₂) I + ½(3m₂ − 1) d dᵀ (the kernel is
        symmetric about d).
    """

    stats: Array
    lobe: Array
    ring: Array
    reads: Array
    kernel_moments: Array

    @property
    def bins(self) -> int:
        return self.stats.shape[-1]

    def astype(self, dtype) -> BinTable:
        return BinTable(*(x.astype(dtype) for x in self))


# ----------------------------------------------------------------------------- table
def _bin_stats(theta_o, alpha, bins, quadrature, ndf):
    """At one (θ_o, α): (c̄_k − cos θ_o, s_k) (2, K) of `bins` equal-mass bins of c under
    p_R, and (sin β, tr Σ_ω) (2, K + 1) of each bin's part of the lobe and of the whole."""
    q = patch_quadrature(theta_o, alpha, quadrature=quadrature, ndf=ndf)
    order = jnp.argsort(q.cos_hi)
    c, w, wi = q.cos_hi[order], q.weight[order], q.wi[order]
    total = jnp.sum(w)
    p = safe_div(w, total)
    hi = jnp.cumsum(p)
    lo = hi - p
    edges = jnp.arange(bins + 1, dtype=c.dtype) / bins
    e0 = edges[:-1].at[0].set(-1.0)[:, None]  # the first and last bins take every node
    e1 = edges[1:].at[-1].set(2.0)[:, None]
    part = jnp.clip(jnp.minimum(hi[None], e1) - jnp.maximum(lo[None], e0), 0.0, None)
    mass = jnp.sum(part, axis=-1)
    mean = safe_div(jnp.sum(part * c[None], axis=-1), mass)
    var = safe_div(jnp.sum(part * (c[None] - mean[:, None]) ** 2, axis=-1), mass)
    cos_o = jnp.cos(theta_o)
    ok = mass > 0  # θ_o = 90°: no lobe; the bins sit at the view cosine
    stats = jnp.stack([jnp.where(ok, mean - cos_o, 0.0), jnp.where(ok, jnp.sqrt(var), 0.0)])

    def sub_lobe(pk):  # mean light direction and tr Σ_ω of a part of the lobe
        mu, cov = light_moments(PatchQuadrature(c, pk, wi))
        sin_beta = safe_div(-mu[0], jnp.hypot(mu[0], mu[2]))  # frame n = z, ω_r at −x
        return jnp.stack([sin_beta, jnp.trace(cov)])

    # the K bins' parts, then the whole lobe (the mean of the K parts)
    lobe = jax.vmap(sub_lobe, out_axes=-1)(jnp.concatenate([part, p[None]]))  # (2, K + 1)
    return stats, lobe


# ----------------------------------------------------------------------------- reads
def prefilter_kernel(t, alpha):
    r"""The prefilter's kernel k_α(t) = D(√((1 + t)/2)) G₂(t, 1) / 4 of t = ⟨ω_r, ω_i⟩, 0 for
    t ≤ 0 (GGX, split sum n = ω_o = ω_r: K 9; the weights of `prefilter.filter_level`).
    Unnormalised: ∫ k_α dω = `_kernel_norm(α)`."""
    ok = t > 0
    cs = jnp.where(ok, jnp.minimum(t, 1.0), 0.0)
    k = normal_distribution(jnp.sqrt((1 + cs) / 2), alpha) * smith_g2(cs, jnp.ones_like(cs),
                                                                     alpha) / 4
    return jnp.where(ok, k, 0.0)


def _kernel_integrals(alpha, nodes: int = 64):
    r"""(∫ k_α dω, ∫ t k_α dω, ∫ t² k_α dω) by the GGX inverse-CDF variable β
    (tan θ_h = α tan β): with
    n = ω_o, dω_i = 4 cos θ_h dω_h and D cos θ_h dω_h = d(sin²β) dφ/2π, so
    ∫ k_α f dω = ∫₀^{β_max} G₂(t, 1) f(t) d(sin²β), t = cos 2θ_h, β_max = atan(1/α)
    (t = 0): a smooth integrand, Gauss–Legendre in β."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    bmax = jnp.arctan(1.0 / alpha)
    b = bmax * (x + 1) / 2
    tan_h2 = (alpha * jnp.tan(b)) ** 2
    t = (1 - tan_h2) / (1 + tan_h2)
    dw = bmax * w / 2 * jnp.sin(2 * b)  # d(sin²β)
    g = smith_g2(jnp.clip(t, 0.0, 1.0), jnp.ones_like(t), alpha) * dw
    return jnp.sum(g), jnp.sum(g * t), jnp.sum(g * t * t)


def _kernel_moments_host(n: int) -> np.ndarray:
    """(m₁, m₂)(√α) = (∫ t k_α, ∫ t² k_α) / ∫ k_α on √α = linspace(0, 1, n), shape (2, n)
    (1 at √α = 0: a mirror read)."""
    sqa = np.linspace(0.0, 1.0, n)
    z, zt, zt2 = (np.asarray(x, np.float64) for x in jax.jit(jax.vmap(_kernel_integrals))(
        jnp.asarray(np.maximum(sqa**2, ALPHA_FLOOR))))
    m = np.stack([zt / z, zt2 / z])
    m[:, 0] = 1.0
    return m


def _fit_reads(theta_o, alpha, x0, grid, iterations, moments, weight, ndf):
    r"""K reads (h_k, √α_k) whose mixture (1/K) Σ_k k̂_k, k̂_k(ω) = k_{α_k}(⟨d_k, ω⟩) / ∫ k_{α_k},
    d_k = (−sin β_k, 0, cos β_k), sin β_k = h_k sin θ_o (frame n = z, ω_r towards −x; the
    parametrisation of `BinTable.lobe`, so that every read tends to n at normal view), is the
    least-absolute-deviation fit of the lobe's density p_R ∝ ρ̃⟨n, ω_i⟩ (K 12) that keeps the
    lobe's low moments: min ∫ |p_R − mixture| dω with ∫ (p_R − mixture) φ dω ≈ 0 for
    φ ∈ {x, z} (`moments` ≥ 1: the mean direction, hence also tr Σ = 1 − |μ|²) and
    {x², z², xz} (`moments` = 2: the covariance in the plane of n and ω_r).

    Why L1: a map of sparse bright texels puts one texel's light on a shading point with a
    probability ∝ p_R(ω), and the relative error of that point is |p_R − mixture| / p_R at
    it, so the expected relative error is the L1 distance. Why the moments: under smooth
    light a read errs by ∇L · ∫ (p_R − mixture) ω dω + ½ ∇²L : ∫ (p_R − mixture) ω ωᵀ dω
    (what the moment-matched reads of `lobe` make small). The integrals run over a polar
    grid round ω_r (ρ = ρ_max t², Gauss–Legendre in t, y ≥ 0 by symmetry), ρ_max = 6 atan 4α
    (the lobe's core). Levenberg–Marquardt on iteratively reweighted least squares (weights
    1/√(|r| + ε)), the moments as penalty rows of `weight`, from `x0` (the moment-matched
    reads); `iterations` steps (converged at 30: 60 change no render by 0.01 ΔE). The K
    kernels are returned sorted by the incidence cosine √((1 + m₁⟨ω_o, d_k⟩)/2) (K 22) of
    their mean direction: the order of the bins they serve."""
    n_r, n_p = grid
    dt = x0.dtype
    zero = jnp.zeros((), dt)
    wo = jnp.stack([jnp.sin(theta_o), zero, jnp.cos(theta_o)])
    wr = jnp.stack([-jnp.sin(theta_o), zero, jnp.cos(theta_o)])
    e1 = jnp.stack([jnp.cos(theta_o), zero, jnp.sin(theta_o)])
    xg, wg = np.polynomial.legendre.leggauss(n_r)
    tg, wg = jnp.asarray((xg + 1) / 2, dt), jnp.asarray(wg / 2, dt)
    rmax = jnp.minimum(jnp.pi, 6 * jnp.arctan(4 * alpha) + 0.02)
    rho, drho = rmax * tg**2, rmax * 2 * tg * wg
    phi = jnp.asarray((np.arange(n_p) + 0.5) * np.pi / n_p, dt)
    r_, p_ = rho[:, None], phi[None, :]
    d = (jnp.cos(r_)[..., None] * wr + (jnp.sin(r_) * jnp.cos(p_))[..., None] * e1
         + (jnp.sin(r_) * jnp.sin(p_))[..., None] * jnp.asarray([0.0, 1.0, 0.0], dt))
    d = d.reshape(-1, 3)
    dw = jnp.broadcast_to(jnp.sin(r_) * drho[:, None] * (2 * np.pi / n_p), (n_r, n_p))
    sq = jnp.sqrt(dw.reshape(-1))
    f = brdf_no_fresnel(d, wo, alpha, ndf) * jnp.maximum(d[:, 2], 0.0)
    target = safe_div(f, jnp.sum(f * sq * sq)) * sq
    k = x0.shape[0] // 2
    sin_o = jnp.sin(theta_o)

    def direction(h):
        sb = jnp.clip(h * sin_o, -1.0, 1.0)
        return jnp.stack([-sb, zero, safe_sqrt(1 - sb * sb)])

    def column(h, s):  # one read's normalised kernel k̂ on the grid, times √dω
        a = jnp.maximum(s * s, ALPHA_FLOOR)
        k_a = prefilter_kernel(jnp.matmul(d, direction(h), precision=HI), a)
        return k_a / _kernel_integrals(a)[0] * sq

    def resid(x):
        return target - jnp.sum(jax.vmap(column)(x[0::2], x[1::2]), axis=0) / k

    eps = jnp.maximum(1e-3 * jnp.max(jnp.abs(target)), 1e-12)
    fl = [d[:, 0], d[:, 2]] + ([d[:, 0] ** 2, d[:, 2] ** 2, d[:, 0] * d[:, 2]]
                               if moments > 1 else [])
    feats = jnp.stack(fl, -1) * sq[:, None]

    def rows(r, u):  # the L1 rows (reweighted) and the moments' penalty rows of residuals r
        if not moments:
            return r * u
        return jnp.concatenate([r * u, weight * jnp.matmul(r, feats, precision=HI)])

    def jacobian(x, u):  # ∂rows/∂x: read b moves only its own column (2 tangents a read,
        # not 2K through every read: the fit of g·K reads costs ∝ K, not K²); `rows` is
        # linear in r, so its Jacobian is `rows` of each column of ∂r/∂x
        dh, ds = jax.vmap(jax.jacfwd(column, argnums=(0, 1)))(x[0::2], x[1::2])  # (K, G)
        dr = -jnp.stack([dh, ds], 1).reshape(2 * k, -1) / k  # (2K, G), as x: h₀, s₀, h₁ …
        return jax.vmap(rows, in_axes=(0, None), out_axes=1)(dr, u)

    def step(carry, _):
        x, lam = carry
        r = resid(x)
        u = jax.lax.stop_gradient(jax.lax.rsqrt(jnp.sqrt(r * r + eps * eps)))
        jac = jacobian(x, u)
        ru = rows(r, u)
        h = jnp.matmul(jac.T, jac, precision=HI)
        dx = -jnp.linalg.solve(h + lam * jnp.diag(jnp.diag(h) + 1e-12),
                               jnp.matmul(jac.T, ru, precision=HI))
        xn = x + dx
        xn = xn.at[1::2].set(jnp.clip(xn[1::2], 0.01, 1.0))
        better = jnp.sum(rows(resid(xn), u) ** 2) < jnp.sum(ru * ru)
        return (jnp.where(better, xn, x), jnp.where(better, lam / 3, lam * 4)), None

    (x, _), _ = jax.lax.scan(step, (x0, jnp.asarray(1e-2, dt)), None, length=iterations)
    x = x.reshape(k, 2)
    z, zt, _ = jax.vmap(_kernel_integrals)(jnp.maximum(x[:, 1] ** 2, ALPHA_FLOOR))
    key = (zt / z) * jnp.matmul(jax.vmap(direction)(x[:, 0]), wo, precision=HI)
    return x[jnp.argsort(key)].reshape(-1)


def _fit_reads_host(theta, sqa, lobe, bins, ndf, dt):
    """`_fit_reads` at every node (θ_o, √α) of the table from the moment-matched `lobe`
    (h, √α_eff); returns reads (n_u, n_a, 2, K) with the limits of `lobe` at θ_o = 0, 90°
    and √α = 0. One compiled call, a row of nodes per step.

    From θ_o = 70° to 85° (`READ_FIT["grazing"]`, a smoothstep) the reads go over to the
    moment-matched ones: there the horizon cuts the lobe and no isotropic mixture fits it
    (the fit's L1 distance rises from ≤ 0.25 below 60° to 0.4–1.4 above 80°), and reads that
    keep each bin's own mean and spread err less under smooth light (measured by θ_o band
    on the shipped maps' renders, docs/improved.md)."""
    n_u, n_a = lobe.shape[:2]
    x0 = np.stack([lobe[:, :, 0, :bins], np.maximum(lobe[:, :, 1, :bins], 0.02)], -1)
    x0 = x0.reshape(n_u, n_a, 2 * bins)
    t, a = np.meshgrid(theta, np.maximum(sqa**2, ALPHA_FLOOR), indexing="ij")
    fit = {k: v for k, v in READ_FIT.items() if k != "grazing"}
    row = jax.vmap(functools.partial(_fit_reads, ndf=ndf, **fit))
    fn = jax.jit(lambda t, a, x: jax.lax.map(lambda tax: row(*tax), (t, a, x)))
    x = np.array(fn(*(jnp.asarray(v, dt) for v in (t, a, x0))), np.float64)
    # towards grazing the moment-matched reads (`_fit_reads_host` docstring): smoothstep
    g0, g1 = np.radians(READ_FIT["grazing"])
    w = np.clip((g1 - theta) / (g1 - g0), 0.0, 1.0)[:, None, None]
    x = (w * w * (3 - 2 * w)) * x + (1 - w * w * (3 - 2 * w)) * x0
    x = x.reshape(n_u, n_a, bins, 2)
    reads = np.moveaxis(x, -1, -2).copy()  # (n_u, n_a, 2, K): h, √α
    reads[..., 1, :] = np.abs(reads[..., 1, :])
    # θ_o = 0: h has no effect there (every read is n); extrapolated in θ_o² from the next
    # three rows (as `lobe`) for the interpolation towards it. 90°: no lobe, as `lobe`
    xs = theta[-4:-1] ** 2
    lag = [np.prod([-xs[m] / (xs[i] - xs[m]) for m in range(3) if m != i]) for i in range(3)]
    reads[-1, :, 0] = sum(w * reads[-4 + i, :, 0] for i, w in enumerate(lag))
    reads[0] = lobe[0, :, :, :bins]
    reads[:, 0, 0], reads[:, 0, 1] = 1.0, 0.0  # √α = 0: the mirror read
    return reads


def _bin_table_host(shape, bins, quadrature, ndf, x64) -> np.ndarray:
    n_u, n_a = shape
    u = np.linspace(0.0, 1.0, n_u)
    sqa = np.linspace(0.0, 1.0, n_a)
    theta = np.arccos(u**2)
    t, a = np.meshgrid(theta, np.maximum(sqa**2, ALPHA_FLOOR), indexing="ij")
    row = jax.vmap(functools.partial(_bin_stats, bins=bins, quadrature=quadrature, ndf=ndf))
    # one compiled call for the whole table, a row of nodes per step (one dispatch and one
    # copy to the host, where a Python loop over rows paid both per row)
    fn = jax.jit(lambda t, a: jax.lax.map(lambda ta: row(*ta), (t, a)))
    dt = jnp.result_type(float)  # float64 when enabled
    stats, lobe = (np.array(x, np.float64) for x in fn(jnp.asarray(t, dt), jnp.asarray(a, dt)))
    # stats (n_u, n_a, 2, K); lobe (n_u, n_a, 2, K + 1): sin β_k, tr Σ_k
    # h_k = sin β_k / sin θ_o is even in θ_o, hence smooth in √cos θ_o (β_k is not): the
    # θ_o = 0 row is its limit, extrapolated quadratically in θ_o² from the next three rows
    # (at θ_o = 0 itself β_k = 0 exactly); the θ_o = 90° row (no lobe) reads along ω_r
    lobe[1:-1, :, 0] /= np.sin(theta[1:-1])[:, None, None]
    x = theta[-4:-1] ** 2
    lag = [np.prod([-x[m] / (x[i] - x[m]) for m in range(3) if m != i]) for i in range(3)]
    lobe[-1, :, 0] = sum(w * lobe[-4 + i, :, 0] for i, w in enumerate(lag))
    lobe[0, :, 0] = 1.0
    # √α_eff: invert tr Σ of the whole normal-view lobe (θ_o = 0, increasing in α)
    sqa_f = np.linspace(0.0, 1.0, 257)
    whole = jax.jit(jax.vmap(functools.partial(_bin_stats, bins=1, quadrature=quadrature,
                                               ndf=ndf)))
    tr0 = np.asarray(whole(jnp.zeros(257, dt), jnp.asarray(np.maximum(sqa_f**2, ALPHA_FLOOR),
                                                           dt))[1][:, 1, -1], np.float64).copy()
    tr0[0] = 0.0
    tr0 = np.maximum.accumulate(tr0)
    lobe[..., 1, :] = np.interp(lobe[..., 1, :], tr0, sqa_f)
    # ring weight: how close the whole lobe's mean direction is to ω_o against the bins'
    # angular distance ψ_k = arccos(2c̄_k² − 1) from ω_o (1: the bins are rings round ω_o)
    sinb = np.clip(lobe[..., 0, -1] * np.sin(theta)[:, None], -1, 1)
    dist = np.abs(np.arcsin(sinb) + theta[:, None])
    cb = np.clip(stats[..., 0, :] + np.cos(theta)[:, None, None], 0, 1)
    psi = np.mean(np.arccos(np.clip(2 * cb**2 - 1, -1, 1)), -1)
    ring = np.clip(1 - dist / np.maximum(psi, 1e-12), 0, 1)
    stats[:, 0] = 0.0  # √α = 0 is the mirror limit itself: every bin at cos θ_o, no spread
    lobe[:, 0, 0], lobe[:, 0, 1] = 1.0, 0.0  # ... and every part is ω_r at level 0
    ring[:, 0] = 0.0
    reads = _fit_reads_host(theta, sqa, lobe, bins, ndf, dt)
    return stats, lobe, ring, reads, _kernel_moments_host(KERNEL_NODES)


@functools.cache
def _bin_table_cached(shape, bins, quadrature, ndf, x64):
    """`_bin_table_host` once per process, and once per cache folder when JAX's persistent
    compilation cache is on (`core.compilation_cache.cached_host_tables`: ≈ 15 s saved in
    every later process, e.g. each notebook kernel and CLI run)."""
    from ..brdf import microfacet

    return cached_host_tables("bin_table", (shape, bins, quadrature, ndf, x64),
                              (__file__, microfacet.__file__),
                              lambda: _bin_table_host(shape, bins, quadrature, ndf, x64))


def bin_table(bins: int = DEFAULT_BINS, *, reads: int = 1,
              shape: tuple[int, int] = TABLE_SHAPE,
              quadrature: tuple[int, int] = TABLE_QUADRATURE, ndf: str = "ggx",
              dtype=jnp.float64) -> BinTable:
    """The (θ_o, α) table of the bins (module docstring), built once per argument set.

    Args:
        bins: K ≥ 1 equal-probability bins of cos θ₁.
        reads: g ≥ 1 prefiltered reads per bin under a map (`ModelOptions.bin_reads`): the
            table's `reads` are then the g·K reads fitted to the lobe (those of
            ``bin_table(g·K)``), bin k served by reads gk … gk + g − 1 in their order of
            incidence cosine (`methods.improved.bin_radiance_parts`).
        shape: (n_u ≥ 5, n_a ≥ 2) nodes in √cos θ_o and √α (√α = 0: the mirror limit,
            offsets and spreads 0).
        quadrature: (n_u, n_φ) of the half-vector quadrature of each node.
        ndf: "ggx" or "beckmann".
        dtype: float dtype of the table.
    Cost: n_u · n_a quadratures of n_u·n_φ nodes and the reads' fit, ∝ the number of reads
    (≈ 15 s on a 2-core CPU for the default, compilation included; 23 s with ``reads=3``),
    once per process; once per cache folder when JAX's persistent compilation
    cache is on.
    Computed in float64 when enabled, else in float32.
    """
    from ..core import _validate as V

    bins = V.check_int("bins", bins, 1)
    reads = V.check_int("reads", reads, 1)
    if not isinstance(shape, (tuple, list)) or len(shape) != 2:
        raise ValueError(f"shape must be (n_u, n_a), got {shape!r}")
    shape = (V.check_int("shape[0]", shape[0], 5),  # the θ_o = 0 limit needs 3 interior rows
             V.check_int("shape[1]", shape[1], 2))
    quadrature = V.check_quadrature(quadrature)
    V.check_choice("ndf", ndf, ("ggx", "beckmann"))
    x64 = bool(jax.config.jax_enable_x64)
    with jax.ensure_compile_time_eval():  # a host table, also when first asked for under jit
        host = _bin_table_cached(shape, bins, quadrature, ndf, x64)
        if reads > 1:  # the g·K reads' fit, with the K bins' statistics
            host = BinTable(*host)._replace(
                reads=_bin_table_cached(shape, bins * reads, quadrature, ndf, x64)[3])
    return BinTable(*(jnp.asarray(x, dtype) for x in host))
