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

**Under an environment** (`shading.methods.improved.improved_envmap`, called by
`envmap_radiance`) the light L(ω_i) weights the lobe, and the film–light coupling is what a split-sum method loses: a bright
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

*The bins' cosines* c̄_k + Δc_k (`methods.improved.bin_radiance_parts`): the light-weighted
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
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from .filtered import filtered_bands
from .improved_table import (ALPHA_FLOOR, DEFAULT_BINS, KERNEL_NODES,  # noqa: F401
                             READ_FIT, TABLE_QUADRATURE, TABLE_SHAPE, BinTable, bin_table,
                             prefilter_kernel)
from ..optics.fresnel import safe_div, safe_sqrt
from ..spectral.lut import ShatLUT
from ..optics.opd import OPDMoments, opd_of_cos
from ..spectral.spectra import DEFAULT_OBSERVER

__all__ = ["BinTable", "BinLight", "ImprovedOptions", "bin_table", "lookup_bins",
           "lookup_lobe", "lookup_reads", "prefilter_kernel", "bin_bands", "scan_bins",
           "improved_bins", "improved_bands", "improved_kernel"]


class ImprovedOptions(NamedTuple):
    """The options `method="improved"` owns (hashable, a static `jit` argument); the
    user-facing `ModelOptions` carries them as its fields ``bins``, ``bin_reads`` and
    ``light_spread`` (`ModelOptions.improved`).

    bins: K ≥ 1 equal-probability bins of cos θ₁ (the (θ_o, α) table's K, `bin_table`).
    bin_reads: g ≥ 1 prefiltered reads a bin under a map (`bin_table(reads=g)`).
    light_spread: under a map, each bin's spread of cos θ₁ follows its read's light too
        (`shading.methods.improved.bin_radiance_parts`).
    """

    bins: int = DEFAULT_BINS
    bin_reads: int = 1
    light_spread: bool = False

    def checked(self) -> ImprovedOptions:
        """The same options validated (ValueError naming the field)."""
        if not isinstance(self.light_spread, bool):
            raise ValueError(f"light_spread must be True or False, got {self.light_spread!r}")
        return self._replace(bins=V.check_int("bins", self.bins, 1),
                             bin_reads=V.check_int("bin_reads", self.bin_reads, 1))


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
    """The light of the K bins under an environment (`methods.improved.bin_radiance_parts`), bins
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
