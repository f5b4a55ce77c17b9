r"""The improved real-time model (`method="improved"`, docs/improved.md): K 29 per quantile bin.

Both `patch_radiance` and `envmap_radiance` call `improved_kernel`; it uses what `filtered`
may use in real time (a table in (θ_o, α), the Ŝ LUT, the shading point's n, ω_o, α, film).

**What is approximated.** Under a light lobe p (uniform light: p = p_R ∝ ρ̃⟨n,ω_i⟩, K 12) the
film's band reflectance is an expectation over the microfacet incidence cosine
c = cos θ₁ = ⟨h, ω_i⟩ alone (SPEC §7):

$$ \bar R_j = \mathbb E_p\big[R_j(c)\big],\qquad
   R_j(c) = C_0(c)\hat S_j(0) + \sum_{m=1}^{M} C_m(c)\big[e^{im\varphi_2(c)}\hat S_j(-mD(c))
   + \text{c.c.}\big],\qquad D(c) = 2d\sqrt{\eta_2^2-\eta_1^2(1-c^2)} \quad (K\ 4, 5). $$

K 29 replaces the distribution of c by one point, cos θ₁* of the mean light direction (K 22)
for C_m, φ₂, and by a Gaussian on D (K 20–28). Both are poor where the distribution of c is
wide and skewed (rough films, grazing views): C₀(c) is convex, so C₀(E c) ≠ E C₀(c) (a Jensen
bias, the largest error of K 29), and D(c) inherits the skew.

**The model.** Split the distribution of c into K bins of equal probability,
B_k = [q_{(k−1)/K}, q_{k/K}] (q_t: the t-quantile of c under p), so that exactly

$$ \bar R_j = \frac1K\sum_{k=1}^{K}\mathbb E\big[R_j(c)\,\big|\,c\in B_k\big]. $$

Inside a bin c has mean c̄_k and standard deviation s_k ≪ the whole spread. Apply K 29 per
bin: the BB17 terms at c̄_k (the Jensen error falls as s_k², i.e. by ~K² for a smooth
density), and D Gaussian with the first-order moments of D(c) about c̄_k (K 25–28's Taylor
chain, written in c):

$$ \mu_{D,k} = D(\bar c_k),\qquad \sigma_{D,k} = |D'(\bar c_k)|\,s_k,\qquad
   D'(c) = \frac{(2d)^2\eta_1^2\,c}{D(c)}, $$
$$ \bar R_j \approx \frac1K\sum_{k=1}^{K}\Big\{C_0(\bar c_k)\hat S_j(0) + \sum_{m=1}^{M}
   C_m(\bar c_k)\big[e^{im\varphi_2(\bar c_k)}\hat S_j(-m\mu_{D,k}, m^2\sigma_{D,k}^2)
   + \text{c.c.}\big]\Big\}\qquad (\text{K 29 per bin}). $$

The skewed mixture of K Gaussians on D follows the true distribution of D(c), and the C₀
average is a K-point rule placed where the mass is. K = 3 is the default (measured: 1.1–1.2× the
cost of `filtered` per shading point on a CPU before the kernels were written for XLA fusion,
1.65× since, under a map 2.4×: figures/kernel_bench.md; K = 2 is cheaper and about 1.6× less accurate,
K = 4 more accurate and dearer: docs/improved.md); K = 1 is K 29 fed with the exact E[c],
Var c of the lobe instead of ⟨ω_o, μ_ω⟩.

**Table.** c̄_k − cos θ_o and s_k depend only on (θ_o, α) (and the NDF): `bin_table` computes
them once on the host from the exact half-vector quadrature (`microfacet.patch_quadrature`,
horizon clipping and the non-split-sum lobe included) on a uniform grid of (√cos θ_o, √α),
the grid of the albedo table, and `lookup_bins` reads them bilinearly. Storing offsets from
cos θ_o makes α → 0 exact: every bin collapses onto c = cos θ_o with s = 0, i.e. `ideal`.

**Ŝ.** ``shat="lut"`` reads the Ŝ(μ, σ²) table of `lut` (the same table `filtered` reads)
*bilinearly* in (|μ|, σ) (`lut.lookup(..., interpolation="linear")`), not bicubically: the
table stores the slowly varying demodulated envelope (≳ 1 µm scale against Δμ = 25 nm), so
the bilinear read is within 2e-3 of the exact Ŝ and about 10× cheaper on a CPU, which pays
for the K bins.
``"exact"`` and ``"gaussian"`` are as for `filtered_kernel`.

**Under an environment** (`ibl.improved_envmap`, called by `envmap_radiance`) the light L(ω_i)
weights the lobe, and the film–light coupling is what a split-sum method loses: a bright
source at one c. The same bins split it exactly,

$$ L_j = A\,\mathbb E_{p_R}\big[R(c)\,L(\omega_i)\big]
       = \frac{A}{K}\sum_{k=1}^{K}\mathbb E\big[R(c)\,L(\omega_i)\,\big|\,c\in B_k\big]
   \approx \frac{A(\theta_o,\alpha)}{K}\sum_{k=1}^{K} R(\bar c_k + \Delta c_k, s_k)\,
       P(d_k, \alpha_k). $$

*The reads* P(d_k, α_k) (`lookup_reads`, `BinTable.reads`): K prefiltered reads whose
kernels, weighted 1/K, are the least-absolute-deviation fit of the lobe p_R that keeps its
first and second moments (`_fit_reads`), the k-th serving the bin of the k-th incidence
cosine; from θ_o = 70° to 85° they go over to the moment-matched reads of each bin's part of
the lobe (`lookup_lobe`: its mean direction and equal-variance level), which the horizon-cut
lobe there favours. Where the light is made of small bright texels, a texel's share of a
shading point is the lobe's value at it, so the reads must follow the lobe's shape, not
only its moments: the moment-matched reads leave ∫ |p_R − mixture| dω = 0.4–0.75 at
θ_o ≤ 60°, the fitted ones 0.01–0.25.

*The bins' cosines* c̄_k + Δc_k (`prefilter.bin_radiance_parts`): the light-weighted
incidence cosine of the bin instead of its uniform-light mean. A read of uniform light has
the mean direction m₁(α_k) d_k; the read's luminance-weighted mean direction μ_k (the
prefiltered moments' first three channels, K §3.2) shows where the light inside it lies, and
Δc_k = c(⟨ω_o, μ_k⟩) − c(m₁⟨ω_o, d_k⟩), c(x) = √((1 + x)/2) (K 22), clipped to the bin's
±√3 s_k. This puts back the covariance of R and L inside a bin, which the bins alone
neglect: a bright texel shows the film at its own incidence cosine. Uniform light gives
Δc = 0, the uniform-light model up to the prefilter's accuracy (measured 7.2e-5,
asserted 1.2e-4: tests/shading/test_ibl.py). Per point: K reads of the radiance and of the
first three moment channels, against `filtered`'s one read of 3 + 9 channels.

*The bins' spreads* (``ModelOptions(light_spread=True)``, off by default): each bin's s_k
scaled by the square root of the ratio of its read's light-weighted variance of ⟨ω_o, ω_i⟩
(the moments' second-moment channels) to the kernel's own (`BinTable.kernel_moments`), at
most 2×: 6 % lower mean ΔE₀₀ over the small-sources renders at 1.18× the cost.

*More reads per bin* (``ModelOptions(bin_reads=g)``, off by default): `bin_table(reads=g)`
holds the g·K kernels fitted to the lobe and bin k pools reads gk … gk + g − 1 (`prefilter.
bin_radiance_parts`); narrower kernels follow each bin's part of the lobe more closely. With
g = 3 every render of the small-sources study is within ≤ 3 ΔE₀₀ and ≤ 0.56× `filtered`, at
2× the default's cost (docs/studies/improved.md, "Choosing K").

Before (`prefilter.bin_radiance`, `benchmarks.small_sources.previous_improved`) each bin read
its moment-matched part of the lobe at its uniform-light cosine: under maps of many small
bright sources and no sun (`benchmarks.small_sources`) it lost its advantage over `filtered`
(0.67–1.35× its mean ΔE₀₀), and the cause is both neglected terms: with each bin's exact
light, uniform-light cosines give 2.5–3.8 ΔE₀₀ and light-weighted ones 0.7–1.1
(docs/studies/improved.md, "Many small sources").

Measured (`benchmarks.improved_study`, float32 kernels, a loaded 2-core CPU): uniform light
0.30 / 0.28 × `filtered`'s ΔE mean / p95 on a wide grid, 0.11–0.38 on the Figure 7 grids,
at 1.17× its cost per shading point (before the fused kernels; figures/kernel_bench.md now
has 1.65×); sphere renders under the four shipped maps 0.22 / 0.21 × (with the suns
split and shaded apart, `sources`; 0.30 / 0.27 × before the lobe-fitted reads).
Measured gains, cost and the regions where it is not better: docs/improved.md.

Example:
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.realtime.improved import bin_table, improved_kernel
    >>> tab = bin_table(shape=(16, 9), quadrature=(24, 24))
    >>> improved_kernel(Film(600.0, 1.3, 2.0, 0.5), 0.8, 0.25, tab, shat="exact").shape
    (3,)
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core.compilation_cache import cached_host_tables
from ..core.film import Film
from .filtered import filtered_bands
from ..optics.fresnel import safe_div, safe_sqrt
from ..spectral.lut import ShatLUT
from ..brdf.microfacet import (PatchQuadrature, brdf_no_fresnel, light_moments,
                               normal_distribution, patch_quadrature, smith_g2)
from ..optics.opd import OPDMoments, opd_of_cos
from ..spectral.spectra import DEFAULT_OBSERVER

__all__ = ["BinTable", "BinLight", "bin_table", "lookup_bins", "lookup_lobe", "lookup_reads",
           "prefilter_kernel", "bin_bands", "scan_bins", "improved_bins", "improved_bands",
           "improved_kernel"]

DEFAULT_BINS = 3
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

    def resid(x):
        m = 0.0
        for b in range(k):
            a = jnp.maximum(x[2 * b + 1] ** 2, ALPHA_FLOOR)
            m = m + prefilter_kernel(d @ direction(x[2 * b]), a) / _kernel_integrals(a)[0]
        return target - m * sq / k

    eps = jnp.maximum(1e-3 * jnp.max(jnp.abs(target)), 1e-12)
    fl = [d[:, 0], d[:, 2]] + ([d[:, 0] ** 2, d[:, 2] ** 2, d[:, 0] * d[:, 2]]
                               if moments > 1 else [])
    feats = jnp.stack(fl, -1) * sq[:, None]

    def rows(x, u):  # the L1 rows (reweighted) and the moments' penalty rows
        r = resid(x)
        return jnp.concatenate([r * u, weight * (r @ feats)]) if moments else r * u

    def step(carry, _):
        x, lam = carry
        r = resid(x)
        u = jax.lax.stop_gradient(jax.lax.rsqrt(jnp.sqrt(r * r + eps * eps)))
        jac = jax.jacfwd(rows)(x, u)
        ru = rows(x, u)
        h = jac.T @ jac
        dx = -jnp.linalg.solve(h + lam * jnp.diag(jnp.diag(h) + 1e-12), jac.T @ ru)
        xn = x + dx
        xn = xn.at[1::2].set(jnp.clip(xn[1::2], 0.01, 1.0))
        better = jnp.sum(rows(xn, u) ** 2) < jnp.sum(ru * ru)
        return (jnp.where(better, xn, x), jnp.where(better, lam / 3, lam * 4)), None

    (x, _), _ = jax.lax.scan(step, (x0, jnp.asarray(1e-2, dt)), None, length=iterations)
    x = x.reshape(k, 2)
    z, zt, _ = jax.vmap(_kernel_integrals)(jnp.maximum(x[:, 1] ** 2, ALPHA_FLOOR))
    key = (zt / z) * (jax.vmap(direction)(x[:, 0]) @ wo)
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
            incidence cosine (`prefilter.bin_radiance_parts`).
        shape: (n_u ≥ 5, n_a ≥ 2) nodes in √cos θ_o and √α (√α = 0: the mirror limit,
            offsets and spreads 0).
        quadrature: (n_u, n_φ) of the half-vector quadrature of each node.
        ndf: "ggx" or "beckmann".
        dtype: float dtype of the table.
    Cost: n_u · n_a quadratures of n_u·n_φ nodes (≈ 10 s on a 2-core CPU for the default,
    once per process; once per cache folder when JAX's persistent compilation cache is on).
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


def _bilinear(tab, x, y):
    """tab[(x, y) ∈ [0, 1]², ...] read bilinearly on its uniform grid.

    The two columns in y are the two steps of a `lax.scan`, so the read is a buffer:
    unrolled, XLA's CPU backend fused its 4 gathers into each consumer (the bins' means,
    the lobe's directions and levels) and recomputed them there (`envmap_radiance(method=
    "improved")` 1.1× slower, tests/realtime/test_kernel_fusion.py)."""
    def cell(v, n):
        t = jnp.clip(v, 0.0, 1.0) * (n - 1)
        i = jnp.clip(jnp.floor(t), 0, n - 2)
        return i.astype(jnp.int32), t - i

    n_x, n_y = tab.shape[:2]
    x, y = jnp.broadcast_arrays(jnp.asarray(x), jnp.asarray(y))
    i0, fx = cell(x, n_x)
    j0, fy = cell(y, n_y)
    extra = (1,) * (tab.ndim - 2)
    fx, fy = fx.reshape(fx.shape + extra), fy.reshape(fy.shape + extra)

    def column(acc, step):  # the two y-columns as loop steps: the read is a buffer
        j = j0 + step
        a = tab[i0, j] * (1 - fx) + tab[i0 + 1, j] * fx
        return acc + a * jnp.where(step == 0, 1 - fy, fy), None

    acc = jnp.zeros(x.shape + tab.shape[2:], jnp.result_type(tab, fx))
    return jax.lax.scan(column, acc, jnp.arange(2, dtype=jnp.int32))[0]


def lookup_bins(table: BinTable, cos_o, alpha):
    """(c̄_k (..., K), s_k (..., K)) at cos θ_o ∈ [0, 1] and α ∈ (0, 1], bilinear in
    (√cos θ_o, √α); c̄_k = cos θ_o + tabulated offset, clamped to [0, 1]."""
    cos_o = jnp.asarray(cos_o)
    st = _bilinear(table.stats, safe_sqrt(cos_o), safe_sqrt(alpha))
    cos_o = jnp.broadcast_to(cos_o, st.shape[:-2])
    return jnp.clip(cos_o[..., None] + st[..., 0, :], 0.0, 1.0), st[..., 1, :]


def _plane_cos(h, cos_o):
    """(cos β, sin²θ_o) of `_plane_directions` from h = sin β / sin θ_o:
    cos β = √(1 − h² sin²θ_o)."""
    sin2_o = jnp.clip(1.0 - cos_o * cos_o, 0.0, 1.0)[..., None]
    return safe_sqrt(jnp.clip(1.0 - h * h * sin2_o, 0.0, 1.0)), sin2_o


def _plane_directions(st, normal, view, cos_o):
    """d = cos β n + sin β ê (..., R, 3) from h = sin β / sin θ_o (..., R): ê ⟂ n in the plane
    of n and ω_r, towards ω_r; smooth at normal view. Without gradient where d = ±z (the
    equirect lookup's (φ, θ) have none at the poles: arctan2(0, 0))."""
    tangent = cos_o[..., None] * normal - view  # (sin θ_o) ê = ω_r − cos θ_o n
    cos_b, _ = _plane_cos(st, cos_o)
    d = cos_b[..., None] * normal[..., None, :] + st[..., None] * tangent[..., None, :]
    pole = (d[..., 0] == 0) & (d[..., 1] == 0)
    return jnp.where(pole[..., None], jax.lax.stop_gradient(d), d)


def lookup_lobe(table: BinTable, normal, view, cos_o, alpha):
    """Per bin and for the whole lobe, (direction (..., K + 1, 3), √α_eff (..., K + 1)) at
    which `prefilter.bin_radiance` reads the prefiltered radiance (`BinTable.lobe`): the
    mean light direction of the bin's part of the lobe, d = cos β n + sin β ê in the plane
    of n and ω_r (ê ⟂ n towards ω_r, sin β = h sin θ_o with the tabulated h, smooth at
    normal view), and the level of equal total variance. World vectors; cos_o = ⟨n, ω_o⟩ > 0."""
    st = _bilinear(table.lobe, safe_sqrt(cos_o), safe_sqrt(alpha))  # (..., 2, K + 1)
    return _plane_directions(st[..., 0, :], normal, view, cos_o), st[..., 1, :]


def lookup_reads(table: BinTable, normal, view, cos_o, alpha, *, view_cosines: bool = False):
    """The K prefiltered reads of `envmap_radiance(method="improved")` (`BinTable.reads`):
    (direction (..., K, 3), level √α (..., K)), directions in the plane of n and ω_r as in
    `lookup_lobe`. World vectors; cos_o = ⟨n, ω_o⟩ > 0.

    `view_cosines`: also ⟨ω_o, d_k⟩ (..., K) in closed form. With d = cos β n + h (cos θ_o n
    − ω_o) (`_plane_directions`) and ⟨ω_o, n⟩ = cos θ_o it is cos β cos θ_o − h sin²θ_o:
    no 3-vectors (a dot product of the directions moved bins first cost XLA:CPU two
    transposes, 3 % of the call)."""
    st = _bilinear(table.reads, safe_sqrt(cos_o), safe_sqrt(alpha))  # (..., 2, K)
    h = st[..., 0, :]
    out = _plane_directions(h, normal, view, cos_o), st[..., 1, :]
    if not view_cosines:
        return out
    cos_b, sin2_o = _plane_cos(h, cos_o)
    return out + (cos_b * cos_o[..., None] - h * sin2_o,)


class BinLight(NamedTuple):
    """The light of the K bins under an environment (`prefilter.bin_radiance_parts`), bins
    first: `radiance` (K, ..., 3) read for each bin, `cos_shift` (K, ...), the shift of
    each bin's mean c̄_k towards the mean incidence cosine of the light it reads, and
    `spread` (K, ...) or None, the bin's spread of c under that light (docs/improved.md).
    `scan_bins` given a `BinLight` as `extra` evaluates bin k at c̄_k + shift_k (clipped to
    [0, 1]), with spread_k in place of s_k when given, and passes its radiance on."""

    radiance: Array
    cos_shift: Array
    spread: Array | None = None


# ----------------------------------------------------------------------------- kernel
def bin_bands(film: Film, c, s, light=None, *, observer, terms, shat, lut,
              arithmetic) -> Array:
    """K 29 in one bin (mean c̄ = `c`, spread s), shape broadcast(film, c, s) + (J,);
    with `light` (..., K) and a cross-band observer, Σ_k R_jk light_k (`filtered_bands`)."""
    d = opd_of_cos(film, c)
    slope = safe_div((2.0 * film.thickness * film.eta_outer) ** 2 * c, d)  # D'(c)
    return filtered_bands(film, c, OPDMoments(d, jnp.abs(slope) * s), observer, terms=terms,
                          shat=shat, lut=lut, arithmetic=arithmetic, interpolation="linear",
                          light=light)


def scan_bins(film: Film, cos_bins, std_bins, bands, *, extra=None,
              stack: bool = False) -> Array:
    """The K bins as the steps of a `lax.scan`: Σ_k bands(film, c̄_k, s_k[, extra_k]), or
    the K terms stacked on axis −2 when `stack`.

    `film` broadcasts with the leading axes of `cos_bins`, `std_bins` (..., K); `extra`
    (K, ..., C), bins first, is sliced per bin (e.g. each bin's light); a `BinLight` also
    moves each bin's mean cosine by its `cos_shift` and takes its `spread` (if any) for s_k (the
    light-weighted bins of `envmap_radiance(method="improved")`), and passes its `radiance`
    on. XLA compiles each
    step into loops of its own: the K bins unrolled fuse into one loop that XLA's CPU backend
    compiles to slow code (`improved_kernel` 3.0× slower, `envmap_radiance(method=
    "improved")` 1.2×: figures/kernel_bench.md), at the same results. A bin axis broadcast
    against the film would be materialised instead."""
    cos_bins, std_bins = jnp.asarray(cos_bins), jnp.asarray(std_bins)
    shift = spread = None
    if isinstance(extra, BinLight):
        shift, spread, extra = extra.cos_shift, extra.spread, extra.radiance
    k = max(cos_bins.shape[-1], std_bins.shape[-1])
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in jax.tree.leaves(film)),
                                 cos_bins.shape[:-1], std_bins.shape[:-1],
                                 *(() if extra is None else (jnp.shape(extra)[1:-1],)))
    film = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), shape), film)
    def bins_first(x):
        return jnp.moveaxis(jnp.broadcast_to(x, shape + (k,)), -1, 0)

    # a BinLight's shift and spread come bins first (no transposes); the spread replaces s_k
    xs = [bins_first(cos_bins), bins_first(std_bins) if spread is None
          else jnp.broadcast_to(spread, (k,) + shape)]
    if shift is not None:
        xs[0] = jnp.clip(xs[0] + shift, 0.0, 1.0)
    if extra is not None:
        xs.append(jnp.broadcast_to(extra, (k,) + shape + jnp.shape(extra)[-1:]))

    def one(x):
        return bands(film, *x)

    if stack:
        return jnp.moveaxis(jax.lax.scan(lambda _, x: (None, one(x)), None, xs)[1], 0, -2)
    out = jax.eval_shape(one, [x[0] for x in xs])
    return jax.lax.scan(lambda total, x: (total + one(x), None),
                        jnp.zeros(out.shape, out.dtype), xs)[0]


def improved_bins(film: Film, cos_bins, std_bins, observer=DEFAULT_OBSERVER, *,
                  terms: int = 2, shat: str = "lut", lut: ShatLUT | None = None,
                  arithmetic: str = "complex") -> Array:
    """K 29 in each bin (module docstring): the bins' band reflectances, shape (..., K, J).

    Args:
        film: `Film`, fields broadcasting with the leading axes of `cos_bins`.
        cos_bins: c̄_k (..., K) ∈ [0, 1], bin means of cos θ₁.
        std_bins: s_k (..., K) ≥ 0, bin standard deviations of cos θ₁.
        observer: band name (plain or cross-band, `uplift`).
        terms: M Fourier orders.
        shat: "lut" (bilinear read of `lut`), "exact" or "gaussian".
        arithmetic: "complex" or "real" (κ₃ = 0 only) Fresnel arithmetic.
    The bins are the steps of one loop (`scan_bins`), stacked on axis −2.
    """
    return scan_bins(film, cos_bins, std_bins, functools.partial(
        bin_bands, observer=observer, terms=terms, shat=shat, lut=lut,
        arithmetic=arithmetic), stack=True)


def improved_bands(film: Film, cos_bins, std_bins, observer=DEFAULT_OBSERVER, *,
                   terms: int = 2, shat: str = "lut", lut: ShatLUT | None = None,
                   arithmetic: str = "complex") -> Array:
    """The mean of `improved_bins` over the K equal-probability bins: R̄_j (..., J), the
    model under uniform light. Arguments as `improved_bins`; the bins are summed as they are
    computed (`scan_bins`, no bin axis)."""
    k = max(jnp.shape(cos_bins)[-1], jnp.shape(std_bins)[-1])
    return scan_bins(film, cos_bins, std_bins, functools.partial(
        bin_bands, observer=observer, terms=terms, shat=shat, lut=lut,
        arithmetic=arithmetic)) * (1.0 / k)


def improved_kernel(film: Film, cos_o, alpha, table: BinTable, *,
                    observer=DEFAULT_OBSERVER, terms: int = 2, shat: str = "lut",
                    lut: ShatLUT | None = None, arithmetic: str = "complex") -> Array:
    """Improved band reflectance under uniform light, (..., J): `lookup_bins` then
    `improved_bands`. Multiply by A(θ_o, α) for the patch radiance.

    Args:
        film: `Film` (fields broadcast with cos_o and alpha).
        cos_o: cos θ_o ∈ [0, 1].
        alpha: GGX roughness α ∈ (0, 1].
        table: `bin_table(...)` (its K is the number of bins).
        observer, terms, shat, lut, arithmetic: as `improved_bands`.
    """
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in film), jnp.shape(cos_o),
                                 jnp.shape(alpha))
    cb, sb = lookup_bins(table, jnp.broadcast_to(cos_o, shape), jnp.broadcast_to(alpha, shape))
    return improved_bands(film, cb, sb, observer, terms=terms, shat=shat, lut=lut,
                          arithmetic=arithmetic)
