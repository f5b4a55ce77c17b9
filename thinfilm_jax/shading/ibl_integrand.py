r"""The integrand of the exact IBL paths (SPEC §9), g = ρ̃(ω_i, ω_o)⟨n,ω_i⟩ R_jk(⟨h,ω_i⟩).

The GGX factors of a light direction (`_lobe_terms`: one formula for every node of the
reference, the scores of its adaptive rule included), the film's exact R_jk(cos θ₁) table
and its linear read (`reflectance_table`, `interp_table`), GGX visible-normal sampling (Heitz 2018,
`_vndf_sample`), the per-point contractions over nodes and light channels, and the host
tables of the texel quadrature (Gauss–Legendre sub-nodes of every texel: `sub_nodes`,
`texel_nodes`). `ibl_reference` (the exhaustive rule, Monte Carlo), `ibl_adaptive`,
`colour_table`, `material_ibl` and `carpaint_ibl` share them.

Example (the sub-nodes of every texel carry its solid angle: the sphere's weights sum to 4π):
    >>> import numpy as np
    >>> d, w, idx = texel_nodes(4, 8, 2)
    >>> d.shape, bool(np.isclose(w.sum(), 4 * np.pi))
    ((128, 3), True)
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .envmap import _row_geometry
from ..core.material import expand_batch
from ..brdf.microfacet import normal_distribution, smith_g2
from ..spectral.reflectance import spectral_bands

__all__ = ["HIGHEST", "sub_nodes", "texel_nodes", "lobe_cos_weight", "reflectance_table",
           "interp_table"]

HIGHEST = jax.lax.Precision.HIGHEST


@functools.lru_cache(maxsize=16)
def sub_nodes(h: int, w: int, s: int):
    """Gauss–Legendre sub-nodes of each row and column: cos θ (h, s), its weights (h, s),
    cos φ and sin φ (w, s), φ weights (s,) (so that Σ over a texel's s² nodes = Ω_t)."""
    x, wt = np.polynomial.legendre.leggauss(s)
    x, wt = (x + 1) / 2, wt / 2
    ct, _ = _row_geometry(h, w)
    u = ct[:-1, None] + (ct[1:] - ct[:-1])[:, None] * x[None]
    wu = (ct[:-1] - ct[1:])[:, None] * wt[None]
    phi = (np.arange(w)[:, None] + x[None]) * 2 * np.pi / w
    return u, wu, np.cos(phi), np.sin(phi), (2 * np.pi / w) * wt


@functools.lru_cache(maxsize=8)
def texel_nodes(h: int, w: int, s: int):
    """Quadrature of the piecewise-constant map: directions (h·w·s², 3), weights (…,) in sr
    (`sub_nodes` in every texel: Gauss–Legendre in cos θ and φ, so Σ weights over a texel
    = Ω), and the flat texel index of each node. Host float64."""
    u, wu, cphi, sphi, wphi = sub_nodes(h, w, s)
    st = np.sqrt(np.maximum(1 - u * u, 0))
    d = np.stack([st[:, None, :, None] * cphi[None, :, None, :],
                  st[:, None, :, None] * sphi[None, :, None, :],
                  np.broadcast_to(u[:, None, :, None], (h, w, s, s))], axis=-1)
    wgt = wu[:, None, :, None] * wphi[None, None, None, :]
    idx = np.broadcast_to((np.arange(h)[:, None] * w + np.arange(w)[None])[:, :, None, None],
                          (h, w, s, s))
    return d.reshape(-1, 3), np.broadcast_to(wgt, (h, w, s, s)).reshape(-1), idx.reshape(-1)


# ----------------------------------------------------------------------------- kernels
def _local_frame(n):
    """Orthonormal tangents (t, b) of unit n, branch-free (Duff et al. 2017)."""
    sign = jnp.where(n[..., 2] >= 0, 1.0, -1.0).astype(n.dtype)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = jnp.stack([1 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], -1)
    bt = jnp.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], -1)
    return t, bt


def _lobe_terms(wi, n, wo, alpha):
    """The GGX factors of ω_i (…, 3) for the world normal n and view ω_o: (ρ̃⟨n,ω_i⟩,
    c = ⟨h,ω_i⟩ clipped to [0, 1], ⟨n,ω_i⟩, ⟨n,h⟩ (0 where h is undefined), D(⟨n,h⟩),
    ⟨n,ω_o⟩ (1 below the horizon), whether h is defined); ρ̃⟨n,ω_i⟩ is 0 below either
    horizon. One formula for every node of the reference, the scores of its adaptive rule
    included."""
    ci = jnp.sum(wi * n, -1)
    co = jnp.sum(wo * n, -1)
    hs = wi + wo
    hn2 = jnp.sum(hs * hs, -1)
    okh = (hn2 > 1e-12) & (co > 0)  # ω_i ≠ −ω_o: |ω_i + ω_o| > 0
    hn = jnp.sqrt(jnp.where(okh, hn2, 1.0))
    ch = jnp.where(okh, jnp.sum(hs * n, -1) / hn, 0.0)
    c = jnp.clip(jnp.sum(hs * wi, -1) / hn, 0.0, 1.0)
    cos_ = jnp.where(co > 0, co, 1.0)
    dist = normal_distribution(ch, alpha)
    up = (ci > 0) & okh
    f = jnp.where(up, dist * smith_g2(jnp.where(up, ci, 1.0), cos_, alpha) / (4 * cos_), 0.0)
    return f, c, ci, ch, dist, cos_, okh


def lobe_cos_weight(wi, n, wo, alpha):
    """(ρ̃ ⟨n,ω_i⟩ (…), c = ⟨h, ω_i⟩) for world directions; 0 below either horizon."""
    return _lobe_terms(wi, n, wo, alpha)[:2]


def reflectance_table(film, observer, n_cos, arithmetic, dtype):
    """R_jk (or R_j) at c = linspace(0, 1, n_cos): the exact spectral bands of `film` over
    cos θ, (n_cos, ..., J[, 3]), tabulated once per film for the texel rule (read with
    `interp_table`)."""
    c = jnp.linspace(0.0, 1.0, n_cos, dtype=dtype)
    return spectral_bands(expand_batch(film), c, observer, arithmetic=arithmetic)


def interp_table(table, c):
    """`table` (n, ...) over c = linspace(0, 1, n) read at c ∈ [0, 1], linearly."""
    n = table.shape[0]
    t = c * (n - 1)
    i0 = jnp.clip(jnp.floor(t), 0, n - 2)
    f = (t - i0)[..., None]
    i0 = i0.astype(jnp.int32)
    return table[i0] * (1 - f) + table[i0 + 1] * f


def _vndf_sample(u1, u2, wo_l, alpha):
    """Visible normal of GGX in the local frame (Heitz 2018), isotropic α."""
    vh = jnp.stack([alpha * wo_l[..., 0], alpha * wo_l[..., 1], wo_l[..., 2]], -1)
    vh = vh / jnp.linalg.norm(vh, axis=-1, keepdims=True)
    lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
    ok = lensq > 0
    inv = jnp.where(ok, 1 / jnp.sqrt(jnp.where(ok, lensq, 1)), 0)
    t1 = jnp.where(ok[..., None], jnp.stack([-vh[..., 1] * inv, vh[..., 0] * inv,
                                             jnp.zeros_like(inv)], -1),
                   jnp.asarray([1.0, 0.0, 0.0], vh.dtype))
    t2 = jnp.cross(vh, t1)
    r = jnp.sqrt(u1)
    phi = 2 * jnp.pi * u2
    p1, p2 = r * jnp.cos(phi), r * jnp.sin(phi)
    s = 0.5 * (1 + vh[..., 2])
    p2 = (1 - s) * jnp.sqrt(jnp.maximum(1 - p1 * p1, 0)) + s * p2
    nh = (p1[..., None] * t1 + p2[..., None] * t2
          + jnp.sqrt(jnp.maximum(1 - p1 * p1 - p2 * p2, 0))[..., None] * vh)
    ne = jnp.stack([alpha * nh[..., 0], alpha * nh[..., 1], jnp.maximum(nh[..., 2], 0)], -1)
    return ne / jnp.linalg.norm(ne, axis=-1, keepdims=True)


def _contract(r, light, cross):
    """Σ_n R(c_n) · light_n → (J,); r (N, J[·3]), light (N, 3): one contraction over n, k."""
    if cross:
        r = r.reshape(r.shape[:-1] + (-1, 3))
        return jnp.einsum("njk,nk->j", r, light, precision=HIGHEST)
    return jnp.sum(r * light, axis=0)


def _per_row(r, light, cross):
    """Σ_(n, k) R · light over the last axes only, elementwise (no batched tiny matmuls):
    r (..., N, J[·3]), light (..., N, 3) → (..., J)."""
    if cross:
        r = r.reshape(r.shape[:-1] + (-1, 3))
        return jnp.sum(r * light[..., None, :], axis=(-3, -1))
    return jnp.sum(r * light, axis=-2)
