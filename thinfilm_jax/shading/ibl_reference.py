r"""The exact paths of `envmap_radiance` (SPEC §9): the deterministic `reference` and `mc`.

$$ L_j(n, \omega_o) = \sum_k \sum_{t} c_{k,t} \int_{t} \tilde\rho(\omega_i, \omega_o)
   \langle n,\omega_i\rangle R_{jk}(\langle h,\omega_i\rangle)\, d\omega_i $$

over the texels t of the piecewise-constant map (radiance c_t, SPEC §9).

Reference, adaptive (the default). Per shading point:

1. *Coarse pass.* One Gauss node per texel (the midpoint in (cos θ, φ), weight Ω_t), the
   exact R_jk(cos θ₁) read from the film's table, plus the midpoint rule's leading error
   term from second differences over the grid of texel centres:
   ∫_t g dω ≈ Ω_t (g_t + Δu_t²/24 ∂²g/∂u² + Δφ²/24 ∂²g/∂φ²), u = cos θ (none on the two
   rows next to each pole, where g is not smooth in u). Fourth order where the lobe is wide.
2. *Refinement.* The K texels with the largest estimated error of that rule,
   score_t = ρ̃⟨n,ω⟩ Ω_t Σ_k c_k,t · (Δ_t / ℓ_t)⁴, ℓ_t = 2⟨h,ω_t⟩ √(α² cos⁴θ_h + sin²θ_h cos²θ_h)
   (the local width of the GGX lobe mapped to ω_i: 2α at its peak, compressed by ⟨h,ω_i⟩
   at grazing views; Δ_t the texel's angular size; texels within two texels of the
   horizon, where g has a kink, and on the pole rows count (Δ/ℓ)⁴ ≥ 1/8), are integrated
   again with s × s Gauss–Legendre nodes in (cos θ, φ), s = `auto_subdivisions` (the
   exhaustive rule's own s), and replace their coarse value. The K texels are found
   without a sort (bisection on the score: XLA's TopK on the CPU costs more than the
   coarse pass).
3. *Neglected part.* The difference between the refined and coarse values of the refined
   texels calibrates the score: est = max_t(|fine_t − coarse_t| / score_t) · Σ_(not refined)
   score_t, returned by `exact_radiance(..., return_estimate=True)` per point, an estimate
   of what the coarse rule left out (not a rigorous bound; measured 2–90× above the actual
   difference to the exhaustive rule in tests/test_ibl_reference.py).

K = `refine_count(H, α, s)`: 1024 (the horizon band and what grazing views compress), plus
1536 when the lobe 2α is narrower than 16 texels (the disc of 16 texels' radius around
its peak, × 4 for the denser texels near the poles).

The exhaustive rule (every texel with s × s nodes, the reference before this module) stays
reachable as `reference_radiance(..., exhaustive=True)`: tests/test_ibl_reference.py
compares the two and `thinfilm_jax.studies.ibl_bench` times both in one run.

Points are shaded one `jax.lax.map` step at a time (a step's intermediates, H W × 9
doubles, stay near the cache); one film shared by every point builds its R_jk table once.

Large maps. The cost per point is ∝ H·W. `reference_radiance` (and so `envmap_radiance`)
resamples a map taller than `max_height` (default 256) with the solid-angle-exact
`envmap.downsample` by the largest power-of-two factor f that keeps the texel size
f·π/H ≤ α_min/8 and H/f ≥ 128, and warns with the factor. Resampling replaces the radiance
inside each f × f block by its solid-angle mean; the error is ∫ ρ̃⟨n,ω⟩R (c − c̄): zero
where the lobe is linear across a block, first order in (block size / lobe width) times
the radiance contrast inside the block otherwise (measured in tests/test_ibl_reference.py
on a 1k map). `max_height=None` keeps the full map.

MC: GGX visible-normal sampling (Heitz 2018), weight G₂/G₁, exact spectral R_jk per sample,
nearest-texel radiance; fixed key and count.

Example (a white map is the uniform light of `patch_radiance`, since Σ_k R_jk = R_j: the
reference under a 16 × 32 white map matches the patch reference, measured 2.7e-7; a 1k map
is resampled by 8 at α = 0.25 unless `max_height=None`):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, envmap_radiance, patch_radiance
    >>> film, view = Film(600.0, 1.3, 2.0, 0.5), np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    >>> L = envmap_radiance(film, 0.3, np.array([0.0, 0.0, 1.0]), view, np.ones((16, 32, 3)))
    >>> float(np.abs(L - patch_radiance(film, 0.5, 0.3)).max()) < 1e-6
    True
    >>> resample_factor(1024, 0.25, 256), resample_factor(1024, 0.25, None)
    (8, 1)
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .envmap import EnvMap, _row_geometry, downsample, lookup_nearest
from ..core.film import Film
from ..brdf.microfacet import normal_distribution, smith_g1, smith_g2
from ..spectral.reflectance import spectral_bands
from ..spectral.uplift import cross_band_name

HIGHEST = jax.lax.Precision.HIGHEST
MIN_HEIGHT = 128  # large maps are never resampled below the shipped maps' 128 rows


def auto_subdivisions(height: int, alpha) -> int:
    """s = ⌈8 (π/H) / α_min⌉ in [2, 16]: sub-cells an eighth of the narrowest lobe."""
    a = float(np.min(np.asarray(alpha))) if _concrete(alpha) else 0.05
    return int(np.clip(np.ceil(8 * np.pi / height / a), 2, 16))


def _concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def refine_count(height: int, alpha_min: float, s: int, texels: int) -> int:
    """Texels refined per point (module docstring, step 2): 1024 (the horizon band and what
    grazing views compress), plus the disc of 16 texels' radius around the lobe's peak
    (× 4 for the denser texels near the poles) when the lobe 2α is narrower than it."""
    if s <= 1:
        return 0
    dtheta = np.pi / height
    k = 1024
    if 2 * alpha_min < 16 * dtheta:
        k += 64 * int(np.ceil(4 * np.pi * 16**2 / 2 / 64))
    return int(min(k, texels))


def resample_factor(height: int, alpha_min: float, max_height: int | None) -> int:
    """Power-of-two downsampling factor of a map taller than `max_height` (module docstring)."""
    if max_height is None or height <= max_height:
        return 1
    f = 1
    while (height % (2 * f) == 0 and height // (2 * f) >= MIN_HEIGHT
           and 2 * f * np.pi / height <= alpha_min / 8):
        f *= 2
    return f


# ----------------------------------------------------------------------------- host tables
@functools.lru_cache(maxsize=8)
def texel_nodes(h: int, w: int, s: int):
    """Quadrature of the piecewise-constant map: directions (h·w·s², 3), weights (…,) in sr
    (Gauss–Legendre in cos θ and φ inside each texel, so Σ weights over a texel = Ω), and
    the flat texel index of each node. Host float64."""
    x, wt = np.polynomial.legendre.leggauss(s)
    x, wt = (x + 1) / 2, wt / 2
    ct, _ = _row_geometry(h, w)
    u = ct[:-1, None] + (ct[1:] - ct[:-1])[:, None] * x[None]  # (h, s) cos θ nodes
    wu = (ct[:-1] - ct[1:])[:, None] * wt[None]
    phi = (np.arange(w)[:, None] + x[None]) * 2 * np.pi / w  # (w, s)
    wphi = np.full((w, s), 2 * np.pi / w) * wt[None]
    st = np.sqrt(np.maximum(1 - u * u, 0))
    d = np.stack([st[:, None, :, None] * np.cos(phi)[None, :, None, :],
                  st[:, None, :, None] * np.sin(phi)[None, :, None, :],
                  np.broadcast_to(u[:, None, :, None], (h, w, s, s))], axis=-1)
    wgt = wu[:, None, :, None] * wphi[None, :, None, :]
    idx = np.broadcast_to((np.arange(h)[:, None] * w + np.arange(w)[None])[:, :, None, None],
                          (h, w, s, s))
    return d.reshape(-1, 3), wgt.reshape(-1), idx.reshape(-1)


@functools.lru_cache(maxsize=8)
def texel_layout(h: int, w: int):
    """Per texel (flat index t = i·w + j, plus one zero-weight pad entry at t = h·w):
    centre node ω_t (T+1, 3) (midpoint in cos θ and φ), Ω_t (T+1,), sin r_t (T+1,) with r_t
    the largest angle from ω_t to a corner, angular size Δ_t = max(Δθ, sin θ Δφ) (T+1,),
    row and column (T+1,); the flag of the pole rows (T+1,) and the u-second-difference
    stencil of each row (h, 3)."""
    ct, om_row = _row_geometry(h, w)
    u = (ct[:-1] + ct[1:]) / 2
    st = np.sqrt(1 - u * u)
    dphi = 2 * np.pi / w
    phi = (np.arange(w) + 0.5) * dphi
    centre = np.stack([st[:, None] * np.cos(phi)[None], st[:, None] * np.sin(phi)[None],
                       np.broadcast_to(u[:, None], (h, w))], -1)
    # corners of row i relative to the centre at φ = 0: angle = arccos(⟨ω_t, corner⟩)
    sc = np.sqrt(np.maximum(1 - ct * ct, 0))
    cosang = np.minimum(np.minimum(st * sc[:-1] * np.cos(dphi / 2) + u * ct[:-1],
                                   st * sc[1:] * np.cos(dphi / 2) + u * ct[1:]), 1.0)
    r = np.arccos(cosang) * (1 + 1e-9) + 1e-12
    size = np.maximum(np.pi / h, np.maximum(sc[:-1], sc[1:]) * dphi)
    pad = lambda a, v: np.concatenate([a.reshape((h * w,) + a.shape[2:]),
                                       np.full((1,) + a.shape[2:], v, a.dtype)])
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    cols = np.broadcast_to(np.arange(w)[None], (h, w))
    # u-second-difference weights of row i (times Δu_i²/24) on rows i−1, i, i+1; the pole
    # rows (u(θ) is not smooth in θ there) get none and are flagged
    hm = np.r_[np.nan, u[:-1] - u[1:]]  # u_{i−1} − u_i
    hp = np.r_[u[:-1] - u[1:], np.nan]  # u_i − u_{i+1}
    du2 = (ct[:-1] - ct[1:]) ** 2 / 24
    stencil = np.stack([du2 * 2 / (hm * (hm + hp)), -du2 * 2 / (hm * hp),
                        du2 * 2 / (hp * (hm + hp))], -1)
    edge_rows = np.zeros(h, bool)
    edge_rows[[0, 1, h - 2, h - 1]] = True
    stencil[edge_rows] = 0.0
    return dict(centre=pad(centre, 0.0), omega=pad(np.broadcast_to(om_row[:, None], (h, w)), 0.0),
                sin_r=pad(np.broadcast_to(np.sin(r)[:, None], (h, w)), 1.0),
                size=pad(np.broadcast_to(size[:, None], (h, w)), 0.0),
                row=pad(rows, 0), col=pad(cols, 0),
                edge=pad(np.broadcast_to(edge_rows[:, None], (h, w)), False), stencil=stencil)


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
    return u, wu, np.cos(phi), np.sin(phi), wt * 2 * np.pi / w


# ----------------------------------------------------------------------------- kernels
def _local_frame(n):
    """Orthonormal tangents (t, b) of unit n, branch-free (Duff et al. 2017)."""
    sign = jnp.where(n[..., 2] >= 0, 1.0, -1.0).astype(n.dtype)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = jnp.stack([1 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], -1)
    bt = jnp.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], -1)
    return t, bt


def _lobe_cos_weight(wi, n, wo, alpha):
    """(ρ̃ ⟨n,ω_i⟩ (…), c = ⟨h, ω_i⟩) for world directions; 0 below either horizon."""
    ci = jnp.sum(wi * n, -1)
    co = jnp.sum(wo * n, -1)
    hs = wi + wo
    up = (ci > 0) & (co > 0)  # then ω_i ≠ −ω_o and |ω_i + ω_o| > 0
    hn = jnp.sqrt(jnp.where(up, jnp.sum(hs * hs, -1), 1.0))
    ch = jnp.sum(hs * n, -1) / hn
    c = jnp.sum(hs * wi, -1) / hn
    cis = jnp.where(up, ci, 1.0)
    cos_ = jnp.where(up, co, 1.0)
    f = normal_distribution(ch, alpha) * smith_g2(cis, cos_, alpha) / (4 * cos_)
    return jnp.where(up, f, 0.0), jnp.clip(c, 0.0, 1.0)


def _r_table(film, observer, n_cos, arithmetic, dtype):
    """R_jk (or R_j) at c = linspace(0, 1, n_cos): exact spectral bands."""
    c = jnp.linspace(0.0, 1.0, n_cos, dtype=dtype)
    return spectral_bands(Film(*(jnp.asarray(x)[..., None] for x in film)), c, observer,
                          arithmetic=arithmetic)


def _interp(table, c):
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


# ----------------------------------------------------------------------------- adaptive
def _select(score, k: int, iterations: int = 32):
    """Indices (k,) of texels with the largest scores, padded with len(score): those above
    a threshold found by bisection on log(score) so that at most k pass (a sort-free top-k:
    XLA's TopK on the CPU sorts, several times slower than the whole coarse pass)."""
    t = score.shape[0]
    top = jnp.max(score)
    lt = jnp.log(jnp.where(top > 0, top, 1.0))

    def body(_, lo_hi):
        lo, hi = lo_hi
        mid = (lo + hi) / 2
        many = jnp.sum(score > jnp.exp(mid)) > k
        return jnp.where(many, mid, lo), jnp.where(many, hi, mid)

    _, hi = jax.lax.fori_loop(0, iterations, body, (lt - 80.0, lt + 1.0))
    mask = (score > jnp.exp(hi)) & (score > 0)
    pos = jax.lax.associative_scan(jnp.add, mask.astype(jnp.int32))
    return jnp.searchsorted(pos, jnp.arange(1, k + 1, dtype=pos.dtype), side="left")


def _light_eff(rad, omega, stencil):
    """a + Sᵀa (T+1, 3), a_t = Ω_t c_t: the per-texel light under the corrected midpoint
    rule (module docstring, step 1) with its stencil S moved onto the light, so that a
    shading point pays one node per texel for it."""
    h, w = rad.shape[:2]
    a = omega.reshape(h, w, 1) * rad
    sa, sb, sc = (stencil[:, k, None, None] for k in range(3))
    zero = jnp.zeros_like(a[:1])
    from_below = jnp.concatenate([(sa * a)[1:], zero])  # row i+1 weighs g_i by its A
    from_above = jnp.concatenate([zero, (sc * a)[:-1]])  # row i−1 weighs g_i by its C
    phi = (jnp.roll(a, 1, axis=1) + jnp.roll(a, -1, axis=1) - 2 * a) / 24
    e = a + from_below + sb * a + from_above + phi
    return jnp.concatenate([e.reshape(h * w, 3), jnp.zeros((1, 3), e.dtype)])


def _adaptive_point(table, a, n, wo, geo, rad, cfg):
    """(L_j (J,), estimate of what the corrected midpoint rule leaves out ()) of one point."""
    s, k_fine, cross = cfg
    centre, omega, sin_r, size, row, col, edge, stencil, light_eff, sub = geo
    h = stencil.shape[0]
    tn = centre.shape[0] - 1
    w = tn // h
    d, om, sr, lt = centre[:-1], omega[:-1], sin_r[:-1], rad[:-1]
    # coarse pass: the integrand g = ρ̃⟨n,ω⟩ R_jk(⟨h,ω⟩) at one node per texel
    co = jnp.sum(wo * n)
    ci = jnp.matmul(d, n, precision=HIGHEST)
    hs = d + wo
    hn2 = jnp.sum(hs * hs, -1)
    okh = (hn2 > 1e-12) & (co > 0)
    hn = jnp.sqrt(jnp.where(okh, hn2, 1.0))
    ch = jnp.matmul(hs, n, precision=HIGHEST) / hn
    c = jnp.clip(jnp.sum(hs * d, -1) / hn, 0.0, 1.0)
    cos_ = jnp.where(co > 0, co, 1.0)
    dist = normal_distribution(jnp.where(okh, ch, 0.0), a)
    up = (ci > 0) & okh
    wgt = jnp.where(up, dist * smith_g2(jnp.where(up, ci, 1.0), cos_, a) / (4 * cos_), 0.0)
    g = wgt[:, None] * _interp(table, c)  # (T, J·3)
    # midpoint rule plus its leading error term, summed by parts: Σ_t a_t·(g + S g)_t =
    # Σ_t g_t·(a + Sᵀa)_t with a_t = Ω_t c_t, the light weights `light_eff` of the map
    total = _contract(g, light_eff[:-1], cross)
    if k_fine == 0:
        return total, jnp.zeros((), total.dtype)
    # refinement score: the corrected rule's error, (Δ/ℓ)⁴ of the texel's weight; texels
    # near the horizon (a kink of g) or on the pole rows count (Δ/ℓ)⁴ ≥ 1/8
    ws = jnp.where(okh, dist * smith_g2(jnp.maximum(ci, sr), cos_, a) / (4 * cos_), 0.0)
    chc = jnp.clip(ch, 0.0, 1.0)
    ell = 2 * jnp.maximum(c, 1e-3) * jnp.sqrt(a * a * chc**4 + (1 - chc**2) * chc**2 + 1e-30)
    sz = size[:-1]
    ratio = (sz / ell) ** 4
    rough = (ci < sr + 2 * sz) | edge[:-1]
    ratio = jnp.where(rough, jnp.maximum(ratio, 0.125), ratio)
    score = jax.lax.stop_gradient(jnp.where(ci > -sr, ws * om * jnp.sum(lt, -1) * ratio, 0.0))
    t = _select(score, k_fine)
    top = jnp.concatenate([score, jnp.zeros((1,), score.dtype)])[t]
    u, wu, cphi, sphi, wphi = sub
    uu, ww = u[row[t]], wu[row[t]]  # (K, s)
    cp, sp = cphi[col[t]], sphi[col[t]]
    stt = jnp.sqrt(jnp.maximum(1 - uu * uu, 0.0))
    dirs = jnp.stack([stt[:, :, None] * cp[:, None, :], stt[:, :, None] * sp[:, None, :],
                      jnp.broadcast_to(uu[:, :, None], (k_fine, s, s))], -1)
    wf, cf = _lobe_cos_weight(dirs.reshape(k_fine, s * s, 3), n, wo, a)
    wq = (ww[:, :, None] * wphi[None, None, :]).reshape(k_fine, s * s)
    rf = _interp(table, cf)  # (K, s², J·3)
    fine = _per_row(rf, (wq * wf)[..., None] * rad[t][:, None, :], cross)  # (K, J)
    # their coarse value a_t·(g + S g)_t, from g at the texel and its four neighbours
    gp = jnp.concatenate([g, jnp.zeros((1, g.shape[-1]), g.dtype)])
    i, j = row[t], col[t]
    valid = t < tn
    up_t = jnp.where(valid & (i > 0), t - w, t)
    dn_t = jnp.where(valid & (i < h - 1), t + w, t)
    lf_t = jnp.where(valid, i * w + jnp.mod(j - 1, w), t)
    rt_t = jnp.where(valid, i * w + jnp.mod(j + 1, w), t)
    st = stencil[i]  # (K, 3)
    gc = (gp[t] + st[:, :1] * gp[up_t] + st[:, 1:2] * gp[t] + st[:, 2:] * gp[dn_t]
          + (gp[lf_t] + gp[rt_t] - 2 * gp[t]) / 24)
    light = jnp.concatenate([om[:, None] * lt, jnp.zeros((1, 3), lt.dtype)])
    coarse = _per_row(gc[:, None], light[t][:, None], cross)  # (K, J)
    delta = jnp.where((top > 0)[:, None], fine - coarse, 0.0)
    total = total + jnp.sum(delta, axis=0)
    # what was not refined: the worst |fine − coarse| / score of the refined texels times
    # the score left unrefined
    err = jax.lax.stop_gradient(jnp.sum(jnp.abs(delta), -1))
    okt = top > 0
    calib = jnp.max(jnp.where(okt, err / jnp.where(okt, top, 1.0), 0.0))
    rest = jnp.maximum(jnp.sum(score) - jnp.sum(top), 0.0)
    return total, calib * rest


@functools.partial(jax.jit, static_argnums=(7,))
def _adaptive_jit(film, alpha, normal, view, radiance, geo, extra, cfg):
    observer, s, n_cos, cross, arithmetic, k_fine, one_film, chunk = cfg
    del extra
    dtype = alpha.dtype
    obs = cross_band_name(observer) if cross else observer
    shape = alpha.shape
    flat = [x.reshape(-1) for x in (*film, alpha)] + [v.reshape(-1, 3) for v in (normal, view)]
    rad = jnp.concatenate([radiance.reshape(-1, 3), jnp.zeros((1, 3), dtype)])
    shared = (_r_table(Film(*(x[0] for x in flat[:5])), obs, n_cos, arithmetic, dtype)
              if one_film else None)

    def one(xs):
        table = shared if one_film else _r_table(Film(*xs[:5]), obs, n_cos, arithmetic, dtype)
        return _adaptive_point(table, xs[5], xs[6], xs[7], geo, rad, (s, k_fine, cross))

    out, est = jax.lax.map(one, tuple(flat), batch_size=chunk)
    cos_o = jnp.sum(normal * view, -1)
    up = cos_o > 0
    return (jnp.where(up[..., None], out.reshape(*shape, out.shape[-1]), 0.0),
            jnp.where(up, est.reshape(shape), 0.0))


# ----------------------------------------------------------------------------- exhaustive, MC
@functools.partial(jax.jit, static_argnums=(6,))
def _exact_jit(film, alpha, normal, view, radiance, extra, cfg):
    """extra: (node directions, node weight × radiance) for the exhaustive reference, a key
    for MC."""
    method, observer, s, n_cos, cross, arithmetic, batch, one_film = cfg
    dtype = alpha.dtype
    obs = cross_band_name(observer) if cross else observer
    shape = alpha.shape
    flat = [x.reshape(-1) for x in (*film, alpha)] + [v.reshape(-1, 3) for v in (normal, view)]
    n_pts = flat[0].shape[0]
    if method == "reference":
        dirs, e = extra
        # one film for every shading point: its R_jk(cos θ₁) table is built once, not per point
        shared_table = (_r_table(Film(*(x[0] for x in flat[:5])), obs, n_cos, arithmetic, dtype)
                        if one_film else None)
    else:
        keys = jax.random.split(extra, n_pts)

    def one(xs):
        f = Film(*xs[:5])
        a, n, wo = xs[5], xs[6], xs[7]
        if method == "reference":
            wgt, c = _lobe_cos_weight(dirs, n, wo, a)  # (N,)
            table = shared_table if one_film else _r_table(f, obs, n_cos, arithmetic, dtype)
            r = _interp(table, c)  # (N, J[·3])
            light = wgt[:, None] * e  # (N, 3)
        else:
            k = xs[8]
            u = jax.random.uniform(k, (s, 2), dtype)
            t, b = _local_frame(n)
            frame = jnp.stack([t, b, n])  # rows: local axes in world
            wo_l = jnp.matmul(frame, wo, precision=HIGHEST)
            m_l = _vndf_sample(u[:, 0], u[:, 1], wo_l, a)
            m = jnp.matmul(m_l, frame, precision=HIGHEST)
            wi = 2 * jnp.sum(m * wo, -1, keepdims=True) * m - wo
            ci, co = jnp.sum(wi * n, -1), jnp.sum(wo * n, -1)
            ok = (ci > 0) & (co > 0)
            c = jnp.clip(jnp.sum(m * wi, -1), 0.0, 1.0)
            g = smith_g2(jnp.where(ok, ci, 1.0), jnp.where(ok, co, 1.0), a) / smith_g1(
                jnp.where(ok, co, 1.0), a)
            wgt = jnp.where(ok, g, 0.0) / s
            r = spectral_bands(Film(*(jnp.asarray(x)[..., None] for x in f)), c, obs,
                               arithmetic=arithmetic)
            light = wgt[:, None] * lookup_nearest(radiance, wi)
        return _contract(r, light, cross)

    xs = tuple(flat) + ((keys,) if method == "mc" else ())
    out = jax.lax.map(one, xs, batch_size=batch)
    cos_o = jnp.sum(normal * view, -1)
    return jnp.where((cos_o > 0)[..., None], out.reshape(*shape, out.shape[-1]), 0.0)


def _batch(batch_size, n_pts, per_point):
    if batch_size is None:
        batch_size = max(1, int(2**19 // max(per_point, 1)))
    return int(max(1, min(batch_size, max(n_pts, 1))))


# ----------------------------------------------------------------------------- entry points
def exact_radiance(film, alpha, normal, view, env: EnvMap, *, method, observer, cross_band,
                   arithmetic, one_film=False, subdivisions=None, n_cos=1024, n_samples=4096,
                   key=None, batch_size=None, exhaustive=False, return_estimate=False,
                   max_height: int | None = 256):
    """`reference` / `mc` of `envmap_radiance` on broadcast inputs (validated by the caller):
    film fields and alpha of one shape, normal and view (..., 3) of that shape. `one_film`:
    every point has the same film (its R_jk table is built once); also detected here for
    concrete fields whose entries are all equal."""
    dtype = alpha.dtype
    n_pts = int(np.prod(alpha.shape))
    one_film = bool(one_film) or all(_same(x) for x in film)
    if method == "mc":
        if not (isinstance(n_samples, int) and n_samples >= 1):
            raise ValueError(f"n_samples must be a positive int, got {n_samples!r}")
        key = jax.random.key(0) if key is None else key
        cfg = ("mc", observer, int(n_samples), 0, bool(cross_band), arithmetic,
               _batch(batch_size, n_pts, n_samples * 64), False)
        return _exact_jit(film, alpha, normal, view, env.radiance.astype(dtype), key, cfg)
    a_min = float(np.min(np.asarray(alpha))) if _concrete(alpha) else 0.05
    h = env.shape[0]
    f = 1 if exhaustive else resample_factor(h, a_min, max_height)
    if f > 1:
        warnings.warn(
            f"envmap_radiance(method='reference'): the {h} × {2 * h} map is resampled by "
            f"{f} to {h // f} × {2 * h // f} (solid-angle-exact box filter; texel "
            f"{f * 180 / h:.2f}° ≤ α_min/8 rad = {np.degrees(a_min / 8):.2f}°); pass "
            "max_height=None to integrate every texel", stacklevel=3)
        env = downsample(env, f)
        h = env.shape[0]
    if subdivisions is None:
        subdivisions = auto_subdivisions(h, alpha)
    s = int(subdivisions)
    if s < 1:
        raise ValueError(f"subdivisions must be a positive int, got {subdivisions!r}")
    rad = env.radiance.astype(dtype)
    if exhaustive:
        d, wt, idx = texel_nodes(*env.shape, s)
        nodes = (jnp.asarray(d, dtype), jnp.asarray(wt, dtype)[:, None] * rad.reshape(-1, 3)[idx])
        cfg = ("reference", observer, s, int(n_cos), bool(cross_band), arithmetic,
               _batch(batch_size, n_pts, len(wt)), one_film)
        out = _exact_jit(film, alpha, normal, view, rad, nodes, cfg)
        return (out, jnp.zeros(alpha.shape, dtype)) if return_estimate else out
    lay = texel_layout(*env.shape)
    k_fine = refine_count(h, a_min, s, h * 2 * h)
    geo = tuple(jnp.asarray(lay[k], dtype) for k in ("centre", "omega", "sin_r", "size"))
    geo += (jnp.asarray(lay["row"], jnp.int32), jnp.asarray(lay["col"], jnp.int32),
            jnp.asarray(lay["edge"]), jnp.asarray(lay["stencil"], dtype),
            _light_eff(rad, jnp.asarray(lay["omega"][:-1], dtype),
                       jnp.asarray(lay["stencil"], dtype)),
            tuple(jnp.asarray(x, dtype) for x in sub_nodes(*env.shape, s)))
    chunk = int(batch_size or 1)
    cfg = (observer, s, int(n_cos), bool(cross_band), arithmetic, k_fine,
           one_film, max(1, min(chunk, max(n_pts, 1))))
    out, est = _adaptive_jit(film, alpha, normal, view, rad, geo, None, cfg)
    return (out, est) if return_estimate else out


def _same(x) -> bool:
    """A concrete array whose entries are all equal (one film broadcast over the points)."""
    if not _concrete(x):
        return False
    a = np.asarray(x)
    return a.size == 0 or bool(np.all(a == a.flat[0]))
