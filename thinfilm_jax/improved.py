r"""The improved real-time filtered model (`method="improved"`, issue #11): K 29 per quantile bin.

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
cost of `filtered` per shading point on a CPU; K = 2 is cheaper and about 1.6× less accurate,
K = 4 more accurate and dearer: docs/improved.md); K = 1 is K 29 fed with the exact E[c],
Var c of the lobe instead of ⟨ω_o, μ_ω⟩.

**Table.** c̄_k − cos θ_o and s_k depend only on (θ_o, α) (and the NDF): `bin_table` computes
them once on the host from the exact half-vector quadrature (`microfacet.patch_quadrature`,
horizon clipping and the non-split-sum lobe included) on a uniform grid of (√cos θ_o, √α),
the grid of the albedo table, and `lookup_bins` reads them bilinearly. Storing offsets from
cos θ_o makes α → 0 exact: every bin collapses onto c = cos θ_o with s = 0, i.e. `ideal`.

**Ŝ.** ``shat="lut"`` reads the Ŝ(μ, σ²) table of `lut` (the same table `filtered` reads)
*bilinearly* in (|μ|, σ) (`lut.lookup(..., interpolation="linear")`), not bicubically: the table stores the slowly
varying demodulated envelope (≳ 1 µm scale against Δμ = 25 nm), so the bilinear read is
within 2e-3 of the exact Ŝ and about 10× cheaper on a CPU, which pays for the K bins.
``"exact"`` and ``"gaussian"`` are as for `filtered_kernel`.

**Under an environment** (`improved_envmap`, called by `envmap_radiance`):

$$ L_j = A(\theta_o, \alpha)\sum_k \bar R_{jk}\,P_k(\omega_\mu, \alpha_\mathrm{eff}). $$

(i) The prefiltered radiance P is read at the lobe's mean light direction ω_μ (ω_r rotated
towards n by a tabulated angle) and at the level α_eff whose normal-view lobe has the same
total variance tr Σ_ω (`lookup_lobe`), not at (ω_r, α): away from normal view the split-sum
lobe centred on ω_r is the wrong lobe, and under the shipped maps that error exceeds the
film's. (ii) The table gives the bins of uniform light; the light-weighted lobe differs by
the radiance inside it, which the prefiltered moments (read at the same (ω_μ, α_eff)) tell:
with μ_x, σ_x² their projection on ω_o and μ_x⁰, σ_x⁰² those of a constant map there
(`splitsum_projection_at`, closed form from the normal-view lobe's E⟨ω_i,n⟩, E⟨ω_i,n⟩²),
`shift_bins` moves every bin in x = 2c² − 1 = ⟨ω_i, ω_o⟩ by μ_x − μ_x⁰ and scales the bins'
spread by σ_x/σ_x⁰. A constant environment gives the uniform-light model (tests: 1e-3).

Measured (`studies.improved_study`, float32 kernels, a loaded 2-core CPU): uniform light
0.30 / 0.28 × `filtered`'s ΔE mean / p95 on a wide grid, 0.11–0.38 on the Figure 7 grids,
at 1.17× its cost per shading point; sphere renders under the shipped maps 0.63 / 0.70 ×.
Measured gains, cost and the regions where it is not better: docs/improved.md.

Example:
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.improved import bin_table, improved_kernel
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

from .film import Film
from .filtered import filtered_bands
from .fresnel import safe_div, safe_sqrt
from .lut import ShatLUT
from .microfacet import light_moments, patch_quadrature
from .opd import OPDMoments, opd_of_cos
from .spectra import DEFAULT_OBSERVER

__all__ = ["BinTable", "bin_table", "lookup_bins", "lookup_lobe", "lookup_normal_view",
           "improved_bands", "improved_kernel", "improved_envmap", "shift_bins",
           "splitsum_projection", "splitsum_projection_at"]

DEFAULT_BINS = 3
TABLE_SHAPE = (64, 33)  # (√cos θ_o, √α) nodes, as the albedo table
TABLE_QUADRATURE = (96, 96)  # half-vector quadrature of the table build
ALPHA_FLOOR = 1e-4  # quadrature floor of α (the √α = 0 column is the exact mirror limit)


class BinTable(NamedTuple):
    """Tables of the lobe p_R of uniform light (a pytree of arrays), on uniform grids of
    √cos θ_o and √α ∈ [0, 1] (the √α = 0 column is the mirror limit):

    stats: (n_u, n_a, 2, K): [0] offsets c̄_k − cos θ_o of the K equal-probability bin means
        of c = cos θ₁, [1] the bin standard deviations s_k.
    lobe: (n_u, n_a, 2): [0] β − θ_o, the angle from the mirror direction ω_r to the lobe's
        mean light direction μ_ω/|μ_ω| (negative: towards n), [1] √α_eff, the roughness whose
        normal-view lobe has the same total variance tr Σ_ω (the prefiltered level to read).
    normal_view: (n_a, 2): (a, e_z) = (E⟨ω_i,n⟩, E⟨ω_i,n⟩²) of the normal-view lobe
        (`microfacet.lobe_moments_normal_view`), for `splitsum_projection`.
    """

    stats: Array
    lobe: Array
    normal_view: Array

    @property
    def bins(self) -> int:
        return self.stats.shape[-1]

    def astype(self, dtype) -> BinTable:
        return BinTable(*(x.astype(dtype) for x in self))


# ----------------------------------------------------------------------------- table
def _bin_stats(theta_o, alpha, bins, quadrature, ndf):
    """(c̄_k − cos θ_o, s_k) of `bins` equal-mass bins of c under p_R at one (θ_o, α)."""
    q = patch_quadrature(theta_o, alpha, quadrature=quadrature, ndf=ndf)
    order = jnp.argsort(q.cos_hi)
    c, w = q.cos_hi[order], q.weight[order]
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
    mu, cov = light_moments(q)  # frame n = z, ω_o = (sin θ_o, 0, cos θ_o): ω_r at −x
    beta = jnp.arctan2(-mu[0], mu[2])
    lobe = jnp.stack([jnp.where(total > 0, beta - theta_o, 0.0), jnp.trace(cov),
                      mu[2], cov[2, 2] + mu[2] ** 2])
    return stats, lobe


@functools.cache
def _bin_table_host(shape, bins, quadrature, ndf, x64) -> np.ndarray:
    n_u, n_a = shape
    u = np.linspace(0.0, 1.0, n_u)
    sqa = np.linspace(0.0, 1.0, n_a)
    theta = np.arccos(u**2)
    t, a = np.meshgrid(theta, np.maximum(sqa**2, ALPHA_FLOOR), indexing="ij")
    fn = jax.jit(jax.vmap(functools.partial(_bin_stats, bins=bins, quadrature=quadrature,
                                            ndf=ndf)))
    dt = jnp.result_type(float)  # float64 when enabled
    rows = [jax.tree.map(lambda x: np.asarray(x, np.float64),
                         fn(jnp.asarray(t[i], dt), jnp.asarray(a[i], dt))) for i in range(n_u)]
    stats = np.stack([r[0] for r in rows])  # (n_u, n_a, 2, K)
    lobe = np.stack([r[1] for r in rows])  # (n_u, n_a, 4): β − θ_o, tr Σ, a, e_z
    # √α_eff: invert tr Σ of the normal-view lobe (θ_o = 0, increasing in α) on a fine grid
    sqa_f = np.linspace(0.0, 1.0, 257)
    tr0 = np.asarray(fn(jnp.zeros(257, dt), jnp.asarray(np.maximum(sqa_f**2, ALPHA_FLOOR),
                                                        dt))[1][:, 1], np.float64).copy()
    tr0[0] = 0.0
    tr0 = np.maximum.accumulate(tr0)
    sqa_eff = np.interp(lobe[..., 1], tr0, sqa_f)
    normal_view = lobe[-1, :, 2:].copy()  # u = 1 row: θ_o = 0
    normal_view[0] = 1.0
    stats[:, 0] = 0.0  # √α = 0 is the mirror limit itself: every bin at cos θ_o, no spread
    out_lobe = np.stack([lobe[..., 0], sqa_eff], axis=-1)
    out_lobe[:, 0] = 0.0
    return stats, out_lobe, normal_view


def bin_table(bins: int = DEFAULT_BINS, *, shape: tuple[int, int] = TABLE_SHAPE,
              quadrature: tuple[int, int] = TABLE_QUADRATURE, ndf: str = "ggx",
              dtype=jnp.float64) -> BinTable:
    """The (θ_o, α) table of the bins (module docstring), built once per argument set.

    Args:
        bins: K ≥ 1 equal-probability bins of cos θ₁.
        shape: (n_u, n_a) nodes in √cos θ_o and √α (√α = 0: the mirror limit, offsets and
            spreads 0).
        quadrature: (n_u, n_φ) of the half-vector quadrature of each node.
        ndf: "ggx" or "beckmann".
        dtype: float dtype of the table.
    Cost: n_u · n_a quadratures of n_u·n_φ nodes (≈ 10 s on a 2-core CPU for the default,
    once per process). Computed in float64 when enabled, else in float32.
    """
    from . import _validate as V

    bins = V.check_int("bins", bins, 1)
    shape = tuple(V.check_int(f"shape[{i}]", s, 2) for i, s in enumerate(shape))
    quadrature = V.check_quadrature(quadrature)
    V.check_choice("ndf", ndf, ("ggx", "beckmann"))
    with jax.ensure_compile_time_eval():  # a host table, also when first asked for under jit
        host = _bin_table_host(shape, bins, quadrature, ndf, bool(jax.config.jax_enable_x64))
    return BinTable(*(jnp.asarray(x, dtype) for x in host))


def _bilinear(tab, x, y):
    """tab[(x, y) ∈ [0, 1]², ...] read bilinearly on its uniform grid."""
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
    a0 = tab[i0, j0] * (1 - fx) + tab[i0 + 1, j0] * fx
    a1 = tab[i0, j0 + 1] * (1 - fx) + tab[i0 + 1, j0 + 1] * fx
    return a0 * (1 - fy) + a1 * fy


def lookup_bins(table: BinTable, cos_o, alpha):
    """(c̄_k (..., K), s_k (..., K)) at cos θ_o ∈ [0, 1] and α ∈ (0, 1], bilinear in
    (√cos θ_o, √α); c̄_k = cos θ_o + tabulated offset, clamped to [0, 1]."""
    cos_o = jnp.asarray(cos_o)
    st = _bilinear(table.stats, safe_sqrt(cos_o), safe_sqrt(alpha))
    cos_o = jnp.broadcast_to(cos_o, st.shape[:-2])
    return jnp.clip(cos_o[..., None] + st[..., 0, :], 0.0, 1.0), st[..., 1, :]


def lookup_lobe(table: BinTable, normal, view, cos_o, alpha):
    """(direction (..., 3), √α_eff (...)) at which to read the prefiltered radiance: ω_r
    rotated towards n by the tabulated angle to the lobe's mean light direction, and the
    level of equal total variance (`BinTable.lobe`). World vectors; cos_o = ⟨n, ω_o⟩ > 0."""
    st = _bilinear(table.lobe, safe_sqrt(cos_o), safe_sqrt(alpha))
    refl = 2.0 * cos_o[..., None] * normal - view
    b = normal - cos_o[..., None] * refl  # ⟨n, ω_r⟩ = cos θ_o: b ⟂ ω_r, |b| = sin θ_o
    nb = safe_sqrt(jnp.sum(b * b, axis=-1, keepdims=True))
    b = safe_div(b, nb)
    db = st[..., 0:1]
    d = jnp.cos(db) * refl - jnp.sin(db) * b
    # the equirect lookup's (φ, θ) have no derivative at the poles (arctan2(0, 0)); there the
    # direction is ω_r = ±z (normal view of a z normal) and Δβ = 0: pass no gradient through
    pole = (d[..., 0] == 0) & (d[..., 1] == 0)
    return jnp.where(pole[..., None], jax.lax.stop_gradient(d), d), st[..., 1]


def lookup_normal_view(table: BinTable, alpha):
    """(a, e_z) of the normal-view lobe at α (`BinTable.normal_view`, linear in √α)."""
    nv = table.normal_view
    n = nv.shape[0]
    t = jnp.clip(safe_sqrt(alpha), 0.0, 1.0) * (n - 1)
    i = jnp.clip(jnp.floor(t), 0, n - 2)
    f = (t - i)[..., None]
    i = i.astype(jnp.int32)
    v = nv[i] * (1 - f) + nv[i + 1] * f
    return v[..., 0], v[..., 1]


# ----------------------------------------------------------------------------- environment
def splitsum_projection_at(r, ez_a):
    """(μ_x⁰, σ_x⁰²) of x = ⟨ω_i, ω_o⟩ under the split-sum lobe of a constant map centred
    on a direction ω_c with ⟨ω_o, ω_c⟩ = r.

    The prefiltered lobe is the normal-view lobe rotated onto ω_c (`microfacet.
    splitsum_light_moments`): μ = a ω_c, Σ = e_t(I − ω_cω_cᵀ) + e_z ω_cω_cᵀ − μμᵀ with
    (a, e_z) = `ez_a` = E[⟨ω_i,n⟩], E[⟨ω_i,n⟩²] at θ_o = 0 and e_t = (1 − e_z)/2, so
    μ_x⁰ = a r and σ_x⁰² = e_t(1 − r²) + (e_z − a²) r².
    """
    a, ez = ez_a
    et = (1.0 - ez) / 2.0
    return a * r, jnp.maximum(et * (1.0 - r * r) + (ez - a * a) * r * r, 0.0)


def splitsum_projection(cos_o, ez_a):
    """`splitsum_projection_at` for the mirror direction ω_r: r = 2cos²θ_o − 1."""
    return splitsum_projection_at(2.0 * cos_o * cos_o - 1.0, ez_a)


def shift_bins(cos_bins, std_bins, mu_x, var_x, mu_x0, var_x0):
    """Move the uniform-light bins by the environment's change of the lobe (module docstring).

    In x = 2c² − 1: x_k ↦ μ' + g (x_k − μ⁰_tab) with μ' = μ⁰_tab + (μ_x − μ_x⁰),
    g = σ_x / σ_x⁰ (clipped to [0, 2]), where μ⁰_tab is the mean of the bins; s_k scales by g.
    Equal to the identity when (μ_x, σ_x²) = (μ_x⁰, σ_x⁰²) (a constant map).
    """
    x = 2.0 * cos_bins * cos_bins - 1.0
    xm = jnp.mean(x, axis=-1, keepdims=True)
    g = jnp.clip(safe_div(safe_sqrt(var_x), safe_sqrt(var_x0), 1.0), 0.0, 2.0)[..., None]
    x_new = jnp.clip(xm + (mu_x - mu_x0)[..., None] + g * (x - xm), -1.0, 1.0)
    return safe_sqrt((1.0 + x_new) / 2.0), g * std_bins


# ----------------------------------------------------------------------------- kernel
def improved_bands(film: Film, cos_bins, std_bins, observer=DEFAULT_OBSERVER, *,
                   terms: int = 2, shat: str = "lut", lut: ShatLUT | None = None,
                   arithmetic: str = "complex") -> Array:
    """K 29 per bin, averaged over the K bins (module docstring): shape (..., J).

    Args:
        film: `Film`, fields broadcasting with the leading axes of `cos_bins`.
        cos_bins: c̄_k (..., K) ∈ [0, 1], bin means of cos θ₁.
        std_bins: s_k (..., K) ≥ 0, bin standard deviations of cos θ₁.
        observer: band name (plain or cross-band, `uplift`).
        terms: M Fourier orders.
        shat: "lut" (bilinear read of `lut`), "exact" or "gaussian".
        arithmetic: "complex" or "real" (κ₃ = 0 only) Fresnel arithmetic.
    """
    cos_bins, std_bins = jnp.asarray(cos_bins), jnp.asarray(std_bins)
    lead = jnp.broadcast_shapes(cos_bins.shape[:-1], std_bins.shape[:-1],
                                *(jnp.shape(x) for x in film))
    shape = lead + cos_bins.shape[-1:]
    cos_bins, std_bins = jnp.broadcast_to(cos_bins, shape), jnp.broadcast_to(std_bins, shape)
    f = Film(*(jnp.broadcast_to(jnp.broadcast_to(jnp.asarray(x), lead)[..., None], shape)
               for x in film))
    d = opd_of_cos(f, cos_bins)
    slope = safe_div((2.0 * f.thickness * f.eta_outer) ** 2 * cos_bins, d)  # D'(c)
    sd = jnp.abs(slope) * std_bins
    r = filtered_bands(f, cos_bins, OPDMoments(d, sd), observer, terms=terms, shat=shat,
                       lut=lut, arithmetic=arithmetic, interpolation="linear")  # (..., K, J)
    return jnp.mean(r, axis=-2)


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


def improved_envmap(film: Film, alpha, normal, view, pref, table: BinTable, *,
                    observer=DEFAULT_OBSERVER, terms: int = 2, shat: str = "lut",
                    lut: ShatLUT | None = None, arithmetic: str = "complex",
                    cross_band: bool = True) -> Array:
    r"""`envmap_radiance(method="improved")` at shading points: L_j (..., J), 0 where ⟨n,ω_o⟩ ≤ 0.

    $$ L_j = A(\theta_o,\alpha)\sum_k \bar R_{jk}\,P_k(\omega_\mu, \alpha_\mathrm{eff}) $$

    * P at the lobe's mean light direction ω_μ and the level α_eff of equal total variance
      (`lookup_lobe`), not at (ω_r, α): the split-sum lobe centred on ω_r is the wrong
      lobe away from normal view (rough or grazing), and that error exceeds the film's;
    * R̄_jk = `improved_bands` on the uniform-light bins moved by `shift_bins` with the
      prefiltered moments read at the same (ω_μ, α_eff) against those of a constant map
      there (μ_x⁰ = a⟨ω_o, ω_μ⟩, σ_x⁰² from (a, e_z) of the normal-view lobe at α_eff):
      a constant environment gives the uniform-light model exactly.

    Args:
        film: `Film` broadcasting with the shading points.
        alpha: GGX α (...).
        normal, view: unit world vectors (..., 3).
        pref: `prefilter.PrefilteredEnvMap` (luminance or per-channel moments; per-channel
            moments are averaged over the channels).
        table: `bin_table(...)`.
        observer: plain band name (the cross bands are used when `cross_band`).
        terms, shat, lut, arithmetic: as `improved_bands`; `lut` must hold the bands used
            (the map's cross-band table when `cross_band`).
        cross_band: R_jk under RGB light (SPEC §9) or the diagonal R_j P_j.
    """
    from .opd import project_light_moments
    from .prefilter import lookup_albedo, lookup_prefiltered, moments_to_mean_cov
    from .uplift import cross_band_name

    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    a = lookup_albedo(pref, co, safe_sqrt(alpha))
    dirn, sqa_eff = lookup_lobe(table, normal, view, co, alpha)
    rad, mom = lookup_prefiltered(pref, dirn, sqa_eff)
    if mom.ndim > rad.ndim:  # per-channel moments (..., 3, 9)
        mom = jnp.mean(mom, axis=-2)
    mean, cov = moments_to_mean_cov(mom)
    mu_x, var_x = project_light_moments(view, mean, cov)
    r_mu = jnp.sum(view * dirn, axis=-1)
    mu_x0, var_x0 = splitsum_projection_at(r_mu, lookup_normal_view(table, sqa_eff**2))
    cb, sb = lookup_bins(table, co, alpha)
    cb, sb = shift_bins(cb, sb, mu_x, var_x, mu_x0, var_x0)
    obs = cross_band_name(observer) if cross_band else observer
    r = improved_bands(film, cb, sb, obs, terms=terms, shat=shat, lut=lut,
                       arithmetic=arithmetic)
    if cross_band:
        out = jnp.sum(r.reshape(r.shape[:-1] + (3, 3)) * rad[..., None, :], axis=-1)
    else:
        out = r * rad
    return jnp.where(up[..., None], a[..., None] * out, 0.0)

