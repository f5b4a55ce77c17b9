r"""The adaptive rule of the IBL reference (SPEC §9): `envmap_radiance(method="reference")`
by default, called through `ibl_reference.exact_radiance` (resampling, the exhaustive rule,
Monte Carlo and the grazing-view check live there; the integrand in `ibl_integrand`).

The map is cut into blocks of b × b texels (b = 4 on
the shipped 128 × 256 maps: 32 × 64 blocks of 5.6°; `block_size`). Per shading point:

1. *Block rule.* The integrand g = ρ̃⟨n,ω⟩ R_jk(⟨h,ω⟩) is evaluated once per block, at its
   centre (θ_B, φ_B), with the exact R_jk(cos θ₁) read from the film's table; over the block
   g is replaced by its second-order Taylor polynomial in x = θ − θ_B, y = φ − φ_B, whose
   derivatives are central differences on the block grid (φ periodic; beyond a pole the
   grid continues through it, (−θ, φ) being the direction (θ, φ + π)). The light enters
   only through its exact moments over the block's texels,
   M_pq,k = Σ_t c_t,k ∫_t x^p y^q sin θ dθ dφ (p + q ≤ 2), so the rule is exact for the
   piecewise-constant map and third order in (block size / lobe width). Summed by parts,
   the whole map costs one contraction Σ_B g_B · L_B with per-map weights L_B
   (`block_light`), one node per block.
2. *Texel rule.* The K = 256 blocks with the largest estimated error (`refine_counts`),
   score_B = ρ̃⟨n,ω⟩ Σ_(t∈B) Ω_t Σ_k c_k,t · min(1, (Δ_B / ℓ_B)³),
   ℓ_B = 2⟨h,ω_B⟩ √(α² cos⁴θ_h + sin²θ_h cos²θ_h) (the local width of the GGX lobe mapped
   to ω_i: 2α at its peak, compressed by ⟨h,ω_i⟩ at grazing views; Δ_B the block's angular
   size; blocks within two block radii of the horizon, where g has a kink, count
   (Δ/ℓ)³ ≥ 1/8 and the largest weight of their 3 × 3 neighbourhood, since the stencil
   reaches across the kink), are integrated again: g is evaluated at their b × b texel
   centres and replaced by its tensor-product Lagrange interpolant in (θ, φ) (degree b − 1
   per axis), integrated exactly against the piecewise-constant light
   (Σ_t c_t ∫_t ℓ_i(θ) ℓ_j(φ) sin θ dθ dφ: per-map weights, `block_interpolant`,
   `interpolant_light`): b² nodes per block, fourth order in (texel size / lobe width).
   The K blocks are found without a sort (bisection on the score: XLA's TopK on the CPU
   costs more than the block pass).
3. *Sub-texel nodes.* Among the texels of the K_c best-scored of those blocks (a quarter
   of them, at least 2 K₃ texels' worth: `level3_blocks`) the K₃ (256 to 1024 where s ≤ 4,
   else 64 s²; `refine_counts`: more where the lobe is narrower) with the largest score
   (the same score per texel; near the horizon the weight is the block's largest, since the
   interpolant spreads a lit node over the block) are integrated with s × s Gauss–Legendre
   nodes in (cos θ, φ), s = `auto_subdivisions` (the exhaustive rule's own nodes), and
   replace their texel-rule value. Where a block is one texel (maps whose sides 4 does not
   divide) level 2 is skipped and level 3 refines blocks.
4. *Neglected part.* At levels 2 and 3 the difference between the new and the replaced
   values of the refined regions calibrates the score: est = max(|fine − coarse| / score) ·
   Σ_(not refined) score (at level 3 over the candidates' texels only), summed over the two
   levels and returned by `exact_radiance(..., return_estimate=True)` per point, an
   estimate of what the rule left out (not a rigorous bound).

With every block and texel refined (`refine=(T_B, T)`) the result is the exhaustive rule's
to rounding (its nodes are the same; tests/shading/test_ibl_reference.py). With the default
counts it is within 1.9e-4 of it (largest band error / band maximum, at most at α = 0.25
on forest_slope; 8e-5 at most at α ≤ 0.15; the SPEC's bound is 1e-3), measured at α = 0.03,
0.05, 0.08, 0.1, 0.12, 0.15, 0.2, 0.25, 0.3, 0.4, 0.6, 1 on each shipped map: the 52 points
of an 8 px sphere and 6 random points, two of them at 85° from the normal
(`refine_counts`), at
H W / b² + K b² + K₃ s² node evaluations per point against the exhaustive rule's H W s²:
7.2k against 131k at α = 0.25 (s = 2) and 22.5k against 524k at α = 0.05 (s = 4) on the
shipped maps.

Example (the counts on the shipped 128 × 256 maps: 4 × 4-texel blocks; the lobe 10 texels
wide at α = 0.25 needs 256 sub-texel cells, 4 texels wide at α = 0.1 1024):
    >>> import numpy as np
    >>> block_size(128, 256)
    4
    >>> refine_counts(2048, 4, 2, 0.25 * 128 / np.pi), refine_counts(2048, 4, 2, 0.1 * 128 / np.pi)
    ((256, 256), (256, 1024))
"""

from __future__ import annotations

import functools
import weakref

import jax
import jax.numpy as jnp
import numpy as np

from .envmap import texel_solid_angles
from .ibl_integrand import (HIGHEST, _contract, interp_table, lobe_cos_weight, _lobe_terms, _per_row,
                            reflectance_table, sub_nodes)
from ..core.material import first_point, point_split
from ..brdf.microfacet import smith_g2
from ..spectral.uplift import cross_band_name

__all__ = [
    "block_interpolant",
    "block_size",
    "refine_counts",
    "level3_blocks",
    "adaptive_radiance",
]


def _select(score, k: int, iterations: int = 20):
    """Indices (k,) of blocks with the largest scores, padded with len(score): those above
    a threshold found by bisection on log(score) so that at most k pass (a sort-free top-k:
    XLA's TopK on the CPU sorts, several times slower than the whole coarse pass). The
    bracket [e⁻⁴⁰, e] × the largest score in 20 halvings: 4e-5 in log(score), so at most
    the scores that close to the threshold are left out (and none above e⁻⁴⁰ of the largest
    is refined for lack of range; such blocks hold nothing a band would show). Each step
    counts the scores above the trial threshold as a float32 dot product of log(score) > t
    with ones (exact for counts below 2²⁴): XLA:CPU's integer sum of a float64 comparison
    took 2.2× as long on 13 points × 4096 scores."""
    top = jnp.max(score)
    lt = jnp.log(jnp.where(top > 0, top, 1.0))
    tiny = jnp.finfo(score.dtype).tiny
    log_score = jnp.log(jnp.where(score > 0, score, tiny)).astype(jnp.float32)
    ones = jnp.ones(score.shape[-1], jnp.float32)

    def body(_, lo_hi):
        lo, hi = lo_hi
        mid = (lo + hi) / 2
        above = (log_score > mid.astype(jnp.float32)).astype(jnp.float32)
        many = jnp.dot(above, ones, precision=HIGHEST) > k
        return jnp.where(many, mid, lo), jnp.where(many, hi, mid)

    _, hi = jax.lax.fori_loop(0, iterations, body, (lt - 40.0, lt + 1.0))
    mask = (score > jnp.exp(hi)) & (score > 0)
    pos = jax.lax.associative_scan(jnp.add, mask.astype(jnp.int32))
    return jnp.searchsorted(pos, jnp.arange(1, k + 1, dtype=pos.dtype), side="left")


@functools.lru_cache(maxsize=8)
def block_layout(h: int, w: int, b: int):
    """The block grid of the adaptive reference (module docstring): b × b texels per block,
    (h/b) × (w/b) blocks, flat index B = I·(w/b) + J plus one zero-weight pad entry.

    Returns (host float64 / int): centre ω_B (T_B+1, 3); the 3 × 3 neighbourhood of each
    block (T_B+1, 9), rows I−1..I+1 × columns J−1..J+1, φ periodic and the rows beyond a
    pole reflected through it ((−θ, φ) is the direction (θ, φ + π), so the stencil sees a
    smooth function there); the block's half-diagonal angle sin r_B and angular size Δ_B
    (T_B+1,); the texel-moment factors ∫_row x^p sin θ dθ (h, 3) and ∫_col y^q dφ (w, 3),
    x = θ − θ_B, y = φ − φ_B of the texel's block; the grid steps (Δθ_B, Δφ_B)."""
    hb, wb = h // b, w // b
    dth, dph = np.pi / hb, 2 * np.pi / wb
    th = (np.arange(hb) + 0.5) * dth
    ph = (np.arange(wb) + 0.5) * dph
    centre = np.stack([np.sin(th)[:, None] * np.cos(ph)[None], np.sin(th)[:, None] * np.sin(ph)[None],
                       np.broadcast_to(np.cos(th)[:, None], (hb, wb))], -1).reshape(-1, 3)
    rows, cols = np.meshgrid(np.arange(hb), np.arange(wb), indexing="ij")
    nb = []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            i, j = rows + di, cols + dj
            flip = (i < 0) | (i >= hb)
            i = np.where(i < 0, -1 - i, np.where(i >= hb, 2 * hb - 1 - i, i))
            j = np.where(flip, j + wb // 2, j) % wb
            nb.append(i * wb + j)
    nb = np.stack(nb, -1).reshape(-1, 9)
    # the farthest point of a block from its centre: a corner (or, on the pole rows, the pole)
    t0, t1 = th - dth / 2, th + dth / 2
    cosang = np.minimum(np.sin(th) * np.sin(t0) * np.cos(dph / 2) + np.cos(th) * np.cos(t0),
                        np.sin(th) * np.sin(t1) * np.cos(dph / 2) + np.cos(th) * np.cos(t1))
    sin_r = np.sin(np.arccos(np.clip(cosang, -1, 1)) * (1 + 1e-9) + 1e-12)
    size = np.maximum(dth, np.maximum(np.sin(t0), np.sin(t1)) * dph)
    # ∫ x^p sin θ dθ over each texel row, x relative to its block's centre (Gauss–Legendre,
    # 8 nodes: exact to rounding for these entire functions on a texel)
    gx, gw = np.polynomial.legendre.leggauss(8)
    tr = np.arange(h + 1) * np.pi / h
    tn = (tr[:-1, None] + tr[1:, None]) / 2 + (tr[1:, None] - tr[:-1, None]) / 2 * gx[None]
    tw = (tr[1:, None] - tr[:-1, None]) / 2 * gw[None]
    x = tn - th[np.arange(h) // b][:, None]
    row_m = np.stack([np.sum(tw * np.sin(tn) * x**p, -1) for p in range(3)], -1)
    pr = np.arange(w + 1) * 2 * np.pi / w
    y0, y1 = pr[:-1] - ph[np.arange(w) // b], pr[1:] - ph[np.arange(w) // b]
    col_m = np.stack([(y1 ** (q + 1) - y0 ** (q + 1)) / (q + 1) for q in range(3)], -1)
    pad = lambda a, v: np.concatenate([a, np.full((1,) + a.shape[1:], v, a.dtype)])
    return dict(centre=pad(centre, 0.0), nb=pad(nb, hb * wb), sin_r=pad(np.repeat(sin_r, wb), 1.0),
                size=pad(np.repeat(size, wb), 0.0), row_m=row_m, col_m=col_m, steps=(dth, dph))


# Taylor terms of the block rule: (p, q) of x^p y^q and the stencil of ∂^(p+q) g/∂θ^p ∂φ^q /
# (p! q!) on the 3 × 3 neighbourhood (rows −1, 0, 1 × columns −1, 0, 1), in units of the
# grid steps (divided by Δθ^p Δφ^q where used)
_TAYLOR = (
    ((0, 0), np.array([[0, 0, 0], [0, 1, 0], [0, 0, 0]], float)),
    ((1, 0), np.array([[0, -0.5, 0], [0, 0, 0], [0, 0.5, 0]])),
    ((0, 1), np.array([[0, 0, 0], [-0.5, 0, 0.5], [0, 0, 0]])),
    ((2, 0), np.array([[0, 0.5, 0], [0, -1, 0], [0, 0.5, 0]])),
    ((1, 1), np.array([[0.25, 0, -0.25], [0, 0, 0], [-0.25, 0, 0.25]])),
    ((0, 2), np.array([[0, 0, 0], [0.5, -1, 0.5], [0, 0, 0]])),
)


def block_light(radiance, b: int):
    """Per block the light moments M_pq,k = Σ_t c_t,k ∫_t x^p y^q sin θ dθ dφ folded with
    the Taylor stencils: the 3 × 3 neighbourhood weights (T_B+1, 9, 3) such that the block
    rule's value of block B is Σ_n g(nb[B, n]) · weights[B, n], and the same folded onto
    each block's own g by summation by parts, `light_eff` (T_B+1, 3): the map's whole
    coarse pass is then Σ_B g_B · light_eff_B."""
    h, w = radiance.shape[:2]
    lay = block_layout(h, w, b)
    hb, wb = h // b, w // b
    dth, dph = lay["steps"]
    dtype = radiance.dtype
    c = radiance.reshape(hb, b, wb, b, 3)
    rm = jnp.asarray(lay["row_m"], dtype).reshape(hb, b, 3)
    cm = jnp.asarray(lay["col_m"], dtype).reshape(wb, b, 3)
    wts = jnp.zeros((hb * wb, 9, 3), dtype)
    for (p, q), st in _TAYLOR:
        m = jnp.einsum("IiJjk,Ii,Jj->IJk", c, rm[..., p], cm[..., q],
                       precision=HIGHEST).reshape(-1, 1, 3)
        wts = wts + jnp.asarray(st.reshape(9, 1) / (dth**p * dph**q), dtype) * m
    nb = jnp.asarray(lay["nb"][:-1])
    eff = jnp.zeros((hb * wb + 1, 3), dtype).at[nb.reshape(-1)].add(wts.reshape(-1, 3))
    wts = jnp.concatenate([wts, jnp.zeros((1, 9, 3), dtype)])
    return wts, eff


@functools.lru_cache(maxsize=8)
def block_interpolant(h: int, w: int, b: int):
    """The texel rule of a block (module docstring, level 2): g is interpolated by the
    tensor-product Lagrange polynomial through its b × b texel centres, whose integral
    against the piecewise-constant light is exact. Returns (host float64)
    A (h, b) = ∫_(row r) ℓ_i(θ) sin θ dθ and B (w, b) = ∫_(col c) ℓ_j(φ) dφ, ℓ_i the Lagrange
    basis on the centres of the rows (columns) of r's (c's) block, so that the rule's value
    of texel t is c_t Σ_ij g_ij A[r_t, i] B[c_t, j] (Gauss–Legendre, 8 nodes per texel:
    exact to rounding for these entire integrands)."""
    gx, gw = np.polynomial.legendre.leggauss(8)
    x = np.arange(b)[:, None] + (gx[None] + 1) / 2  # (b, 8) local positions in texel units
    nodes = np.arange(b) + 0.5
    lag = np.ones((b, 8, b))
    for i in range(b):
        for m in range(b):
            if m != i:
                lag[..., i] *= (x - nodes[m]) / (nodes[i] - nodes[m])
    dth, dph = np.pi / h, 2 * np.pi / w
    theta = (np.arange(h) // b * b)[:, None] * dth + np.tile(x, (h // b, 1)) * dth  # (h, 8)
    a = np.einsum("rg,rgi->ri", gw[None] / 2 * dth * np.sin(theta), np.tile(lag, (h // b, 1, 1)))
    bm = np.tile(np.einsum("g,rgj->rj", gw / 2 * dph, lag), (w // b, 1))
    return a, bm


def interpolant_light(radiance, b: int):
    """Per block the weights (T_B+1, b², 3) of its texel rule: Σ_(t∈B) c_t,k A[r_t, i]
    B[c_t, j] (`block_interpolant`), so that the rule's value of block B is
    Σ_ij g_ij · weights[B, ij] (the pad block's weights are 0)."""
    h, w = radiance.shape[:2]
    a, bm = block_interpolant(h, w, b)
    dtype = radiance.dtype
    c = radiance.reshape(h // b, b, w // b, b, 3)
    wts = jnp.einsum("IrJck,Iri,Jcj->IJijk", c, jnp.asarray(a, dtype).reshape(h // b, b, b),
                     jnp.asarray(bm, dtype).reshape(w // b, b, b), precision=HIGHEST)
    wts = wts.reshape(-1, b * b, 3)
    return jnp.concatenate([wts, jnp.zeros((1, b * b, 3), dtype)])


def block_size(h: int, w: int) -> int:
    """Texels per block side: 4 where the grid allows (h, w/2 divisible), else 2, else 1."""
    return next(b for b in (4, 2, 1) if h % b == 0 and w % (2 * b) == 0)


SMALL_MAP_TEXELS = 64 * 128  # maps of at most 64 × 128 texels: K₃ ≥ K b² / 4 (`refine_counts`)


def refine_counts(blocks: int, b: int, s: int, lobe_texels: float | None = None
                  ) -> tuple[int, int]:
    """(K, K₃) of the adaptive rule: the blocks integrated again by the texel rule, and the
    texels among theirs (among all blocks where a block is one texel) integrated with s × s
    sub-nodes, per point. `lobe_texels` r = α_min / texel angle (π/H) is the narrowest
    lobe's width in texels (None: the narrowest lobe of s's range, r = 8/s).

    K = 256 blocks (at most all of them). K₃ = max(64 s², 64 ⌈400 / r²⌉ clipped to
    [256, 1024]): as r falls the texels that the texel rule resolves too coarsely grow in
    number (256 for r ≥ 10, α ≥ 0.25 on a 128-row map; 1024 for r ≤ 5, α ≤ 0.12, where
    s ≤ 4); on maps of at most 64 × 128 texels (their texels are coarse, and the whole rule
    costs little) at least a quarter of the K blocks' texels, up to 1024. No sub-texel level
    where s = 1, since one node per texel is coarser than the texel rule.

    Measured against the exhaustive rule (largest band error / band maximum; the shipped
    maps, the 52 points of an 8 px sphere and 6 random points, two at 85° from the normal):
    the former K₃ = 64 s² (256 wherever s = 2) erred up to 4.1e-3 at α = 0.1 and 1.3e-3 at
    α = 0.15 (forest_slope), over the SPEC's 1e-3: the lobe spans more texels than the
    texel rule resolves there; K₃ = 1024 gives 7.2e-5 at α = 0.1. K cannot fall for wide
    lobes: a white map seen at 86° from the normal (the white furnace, against A(θ_o, α),
    128 rows) errs 1.0e-3, 1.5e-3, 2.9e-3 at α = 0.25, 0.5, 1 with K = 64 and 4.2e-4,
    5.6e-4, 6.1e-4 with K = 256: the block rule's small errors over a lobe that spans the
    horizon add up. A white 32 × 64 map seen at 86° erred 2.7e-3 at α = 1 with K₃ = 256
    (512: 2.0e-4) and a 64 × 128 one 1.4e-3 at 88° (1024: 2.4e-5); on a 16 × 32 map the
    exhaustive rule itself errs 1.3e-3 there."""
    if s <= 1:
        return (0, 0) if b == 1 else (int(min(blocks, 256)), 0)
    r = 8.0 / s if lobe_texels is None else max(float(lobe_texels), 1e-9)
    k3 = max(64 * s * s, int(np.clip(64 * np.ceil(400.0 / r**2), 256, 1024)))
    if b == 1:
        return 0, int(min(blocks, k3))
    k = int(min(blocks, 256))
    if blocks * b * b <= SMALL_MAP_TEXELS:  # a quarter of the refined blocks' texels
        k3 = max(k3, min(1024, k * b * b // 4))
    return k, int(min(k * b * b, k3))


def level3_blocks(k2: int, k3: int, bb: int) -> int:
    """K_c: of the K = `k2` blocks of the texel rule, how many (the best-scored) offer their
    b² = `bb` texels as level-3 candidates: a quarter, at least twice the K₃ texels'
    worth, at most all."""
    return int(min(k2, max(k2 // 4, -(-2 * k3 // bb))))


def _peak_weight(terms, a, sin_r):
    """ρ̃⟨n,ω⟩ at a region's most-lit point: ⟨n,ω⟩ raised by its half-diagonal sin r."""
    _, _, ci, _, dist, cos_, okh = terms
    return jnp.where(okh, dist * smith_g2(jnp.maximum(ci, sin_r), cos_, a) / (4 * cos_), 0.0)


def _score(terms, a, sin_r, size, ws, ws_nb, horizon=None):
    """The adaptive rule's error score of a block or texel (module docstring): its peak
    weight `ws` × min(1, (Δ/ℓ)³); near the horizon (a kink of g) (Δ/ℓ)³ ≥ 1/8 and the
    weight is the largest of its 3 × 3 neighbourhood's, `ws_nb` (the stencil reaches
    across the kink); `horizon` overrides which regions count as near it."""
    _, c, ci, ch, _, _, _ = terms
    chc = jnp.clip(ch, 0.0, 1.0)
    ell = 2 * jnp.maximum(c, 1e-3) * jnp.sqrt(a * a * chc**4 + (1 - chc**2) * chc**2 + 1e-30)
    ratio = jnp.minimum((size / ell) ** 3, 1.0)  # an unresolved region: its whole value
    horizon = ci < 2 * sin_r if horizon is None else horizon
    ratio = jnp.where(horizon, jnp.maximum(ratio, 0.125), ratio)
    return jnp.where(horizon, jnp.maximum(ws, ws_nb), ws) * ratio


def _top(score, k):
    """The k best-scored regions (`_select`; padded entries have score 0) and their scores."""
    score = jax.lax.stop_gradient(score)
    t = _select(score, k).astype(jnp.int32)
    return t, jnp.concatenate([score, jnp.zeros((1,), score.dtype)])[t]


def _correction(fine, coarse, top, score):
    """Σ (fine − coarse) (J,) over the refined regions, and the estimate of what the
    unrefined ones leave out: the worst |fine − coarse| / score of the refined times the
    score left unrefined."""
    ok = top > 0
    delta = jnp.where(ok[:, None], fine - coarse, 0.0)
    err = jax.lax.stop_gradient(jnp.sum(jnp.abs(delta), -1))
    calib = jnp.max(jnp.where(ok, err / jnp.where(ok, top, 1.0), 0.0))
    rest = jnp.maximum(jax.lax.stop_gradient(jnp.sum(score)) - jnp.sum(top), 0.0)
    return jnp.sum(delta, axis=0), calib * rest


def _adaptive_point(table, a, n, wo, geo, rad, cfg):
    """(L_j (J,), estimate of what the rule leaves out ()) of one point (module docstring:
    block rule, texel rule in the K worst blocks, s × s sub-nodes in the K₃ worst texels)."""
    s, (k2, k3), cross = cfg
    (centre, nb, sin_r, size, wts, eff, mass), texels, sub = geo

    def g_of(terms):  # g = ρ̃⟨n,ω⟩ R_jk(⟨h,ω⟩) (…, J·3)
        return terms[0][..., None] * interp_table(table, terms[1])

    # level 1: the block rule at the block centres, by parts over the whole map
    t1 = _lobe_terms(centre[:-1], n, wo, a)
    g = g_of(t1)  # (T_B, J·3)
    total = _contract(g, eff[:-1], cross)
    bb = texels[4].shape[-1]  # texels per block
    if not (k2 if bb > 1 else k3):  # nothing refined (one-texel blocks go to level 3)
        return total, jnp.zeros((), total.dtype)
    ws = _peak_weight(t1, a, sin_r[:-1])
    ws_nb = jnp.max(jnp.concatenate([ws, jnp.zeros((1,), ws.dtype)])[nb[:-1]], axis=-1)
    score1 = _score(t1, a, sin_r[:-1], size[:-1], ws, ws_nb) * mass[:-1]
    gp = jnp.concatenate([g, jnp.zeros((1, g.shape[-1]), g.dtype)])
    u, wu, cphi, sphi, wphi = sub
    tcentre, tsin_r, tsize, mass_t, tex, iw, a_row, b_col = texels
    w = cphi.shape[0]
    if bb > 1:
        # level 2: the texel rule (the interpolant through the b × b texel centres) in the K
        # worst blocks
        t, top = _top(score1, k2)
        ti = tex[t]  # (K, b²) texel ids (the pad block's: the pad texel)
        t2 = _lobe_terms(tcentre[ti], n, wo, a)
        gt = g_of(t2)  # (K, b², J·3)
        d2, est2 = _correction(_per_row(gt, iw[t], cross), _per_row(gp[nb[t]], wts[t], cross),
                               top, score1)
        total = total + d2
        if k3 == 0:
            return total, est2
        # candidates of level 3: the texels of the K_c best-scored of those blocks
        # (`level3_blocks`); where a block reaches the horizon (the interpolant of a kink
        # errs over the whole block) each of its texels counts as near it, with the
        # block's largest weight
        kc = level3_blocks(k2, k3, bb)
        if kc < k2:
            sel = _select(top, kc)
            live = sel < k2  # pad entries: no block, no score
            sel = jnp.minimum(sel, k2 - 1)
            ti, gt = ti[sel], gt[sel]
            t2 = tuple(x[sel] if jnp.ndim(x) else x for x in t2)
        else:
            live = jnp.ones((k2,), bool)
        ws = _peak_weight(t2, a, tsin_r[ti])
        horizon = jnp.any(t2[2] < 2 * tsin_r[ti], axis=-1, keepdims=True)
        score2 = _score(t2, a, tsin_r[ti], tsize[ti], ws, jnp.max(ws, -1, keepdims=True),
                        horizon)
        score2 = jnp.where(live[:, None], score2 * mass_t[ti], 0.0).reshape(-1)
        cand = ti.reshape(-1)

        def coarse_of(q):  # the texel rule's value of candidate q
            k, r, col = q // bb, cand[q] // w, cand[q] % w
            bi = b_col.shape[-1]
            wq = (a_row[r][:, :, None] * b_col[col][:, None, :]).reshape(-1, bi * bi)
            return _per_row(gt[k], wq[..., None] * rad[cand[q]][:, None, :], cross)
    else:  # one texel per block: level 3 refines blocks, in place of their block rule
        est2, score2, cand = 0.0, score1, jnp.arange(score1.shape[0], dtype=jnp.int32)

        def coarse_of(q):
            return _per_row(gp[nb[q]], wts[q], cross)
    # level 3: s × s Gauss sub-nodes (the exhaustive rule's) in the K₃ worst texels
    q, top = _top(score2, k3)
    q = jnp.minimum(q, score2.shape[0] - 1)  # a pad entry (score 0, masked) reads the last one
    ti = cand[q]  # (K₃,) texel ids
    r, col = ti // w, ti % w
    stt = jnp.sqrt(jnp.maximum(1 - u[r] ** 2, 0.0))  # (K₃, s)
    d = jnp.stack([stt[:, :, None] * cphi[col][:, None, :], stt[:, :, None] * sphi[col][:, None, :],
                   jnp.broadcast_to(u[r][:, :, None], stt.shape + (s,))], -1)
    wf, cf = lobe_cos_weight(d.reshape(-1, s * s, 3), n, wo, a)
    wq = (wu[r][:, :, None] * wphi[None, None, :]).reshape(-1, s * s)
    fine = _per_row(interp_table(table, cf), (wq * wf)[..., None] * rad[ti][:, None, :], cross)
    d3, est3 = _correction(fine, coarse_of(q), top, score2)
    return total + d3, est2 + est3


@functools.partial(jax.jit, static_argnums=(7,))
def _adaptive_jit(film, alpha, normal, view, radiance, geo, extra, cfg):
    observer, s, n_cos, cross, arithmetic, counts, one_film, chunk = cfg
    del extra
    dtype = alpha.dtype
    obs = cross_band_name(observer) if cross else observer
    shape = alpha.shape
    mat, point = point_split(film, shape)
    flat = (mat, alpha.reshape(-1), normal.reshape(-1, 3), view.reshape(-1, 3))
    rad = jnp.concatenate([radiance.reshape(-1, 3), jnp.zeros((1, 3), dtype)])
    shared = (reflectance_table(point(first_point(mat)), obs, n_cos, arithmetic, dtype)
              if one_film else None)

    def one(xs):
        m, a, n, wo = xs
        table = shared if one_film else reflectance_table(point(m), obs, n_cos, arithmetic, dtype)
        return _adaptive_point(table, a, n, wo, geo, rad, (s, counts, cross))

    n = flat[1].shape[0]
    m = -(-n // chunk)
    if m * chunk > n:  # whole steps: pad with the last point (lax.map would vmap the rest apart)
        flat = jax.tree.map(lambda x: jnp.concatenate(
            [x, jnp.broadcast_to(x[-1:], (m * chunk - n,) + x.shape[1:])]), flat)
    out, est = jax.lax.map(one, flat, batch_size=chunk)
    out, est = out[:n], est[:n]
    cos_o = jnp.sum(normal * view, -1)
    up = cos_o > 0
    return (jnp.where(up[..., None], out.reshape(*shape, out.shape[-1]), 0.0),
            jnp.where(up, est.reshape(shape), 0.0))


@functools.partial(jax.jit, static_argnums=(1, 2))
def _adaptive_geometry(rad, b: int, s: int):
    """What the adaptive rule reads per map (module docstring): the block grid with its
    Taylor weights (`block_layout`, `block_light`) and light per block; the texel grid with
    light per texel, the texels of each block and the weights of its texel rule
    (`block_interpolant`, `interpolant_light`); the sub-nodes of each row and column (`sub_nodes`)."""
    h, w = rad.shape[:2]
    dtype = rad.dtype
    omega_c = jnp.sum(jnp.asarray(texel_solid_angles(h, w), dtype)[..., None] * rad, -1)  # Σ_k Ω c
    pad = lambda x: jnp.concatenate([x, jnp.zeros((1,), dtype)])
    lay = block_layout(h, w, b)
    wts, eff = block_light(rad, b)
    mass = omega_c.reshape(h // b, b, w // b, b).sum(axis=(1, 3)).reshape(-1)
    blocks = (jnp.asarray(lay["centre"], dtype), jnp.asarray(lay["nb"], jnp.int32),
              jnp.asarray(lay["sin_r"], dtype), jnp.asarray(lay["size"], dtype), wts, eff,
              pad(mass))
    lay1 = block_layout(h, w, 1)
    hb, wb = h // b, w // b
    tex = (np.arange(h).reshape(hb, 1, b, 1) * w + np.arange(w).reshape(1, wb, 1, b))
    tex = np.concatenate([tex.reshape(hb * wb, b * b), np.full((1, b * b), h * w)])
    a_row, b_col = block_interpolant(h, w, b)
    texels = (jnp.asarray(lay1["centre"], dtype), jnp.asarray(lay1["sin_r"], dtype),
              jnp.asarray(lay1["size"], dtype), pad(omega_c.reshape(-1)),
              jnp.asarray(tex, jnp.int32), interpolant_light(rad, b),
              jnp.asarray(a_row, dtype), jnp.asarray(b_col, dtype))
    return blocks, texels, tuple(jnp.asarray(x, dtype) for x in sub_nodes(h, w, s))


_GEOMETRY: dict = {}  # id(map) → (weak reference to it, {(b, s): geometry}), `_map_geometry`


def _map_geometry(rad, b: int, s: int):
    """`_adaptive_geometry` of a concrete map, kept while the map lives (0.9 ms a call on the
    shipped maps, 3 % of a 52-point call at α = 0.25): JAX arrays are immutable, so the
    same object holds the same texels; the entry goes with the map (`weakref.finalize`).
    A traced map (a gradient with respect to the light) is not kept. A concrete map's
    geometry is computed concretely (`jax.ensure_compile_time_eval`), also when the caller
    is being traced: under `jax.jit` its operations would otherwise be staged into the
    caller's trace and the cache would keep that trace's tracers for the next one."""
    if isinstance(rad, jax.core.Tracer):
        return _adaptive_geometry(rad, b, s)
    key = id(rad)
    entry = _GEOMETRY.get(key)
    if entry is None or entry[0]() is not rad:
        entry = (weakref.ref(rad), {})
        _GEOMETRY[key] = entry
        weakref.finalize(rad, _GEOMETRY.pop, key, None)
    per_map = entry[1]
    if (b, s) not in per_map:
        with jax.ensure_compile_time_eval():
            per_map[(b, s)] = _adaptive_geometry(rad, b, s)
    return per_map[(b, s)]


def _balanced_chunk(n_pts: int, most: int) -> int:
    """Points per `lax.map` step (vmapped): at most `most`, as many steps as that needs,
    the points shared evenly (`_adaptive_jit` pads the last step with its last point)."""
    steps = -(-max(n_pts, 1) // most)
    return -(-max(n_pts, 1) // steps)


def adaptive_radiance(film, alpha, normal, view, rad, *, observer, s: int, n_cos: int,
                      cross_band: bool, arithmetic, one_film: bool, a_min: float,
                      batch_size=None, refine=None):
    """(L_j (..., J), estimate of what the rule leaves out (...)) of the adaptive rule on
    the inputs of `ibl_reference.exact_radiance` (broadcast, validated; `rad` the map to
    integrate, already resampled): counts from `refine_counts` at the narrowest lobe
    `a_min` unless `refine` = (K, K₃) is given."""
    h, w = rad.shape[:2]
    n_pts = int(np.prod(alpha.shape))
    b = block_size(h, w)
    counts = (refine_counts(h * w // b**2, b, s, a_min * h / np.pi)
              if refine is None else tuple(int(x) for x in refine))
    geo = _map_geometry(rad, b, s)
    nodes = h * w // b**2 + counts[0] * b * b + counts[1] * s * s
    chunk = int(batch_size or _balanced_chunk(n_pts, 16 if nodes <= 8192 else 4))
    cfg = (observer, s, int(n_cos), bool(cross_band), arithmetic, counts,
           one_film, max(1, min(chunk, max(n_pts, 1))))
    return _adaptive_jit(film, alpha, normal, view, rad, geo, None, cfg)
