r"""Compact light sources (suns) split from an environment map, shaded apart (docs/improved.md).

A clear-sky map puts most of its power in a few texels (the sun subtends ~0.5°, a 64 × 128
texel 2.8°). A prefiltered read spreads that power over the lobe's mean direction, while the
exact integral sees a nearly directional light whose film term is set by its own half
vector. So the map is split, exactly in energy, into a residual map and S spherical caps:

$$ L(\omega) = L_{\mathrm{res}}(\omega) + \sum_s L_s\,\mathbb 1[\omega \in \mathrm{cap}_s],
   \qquad \int L\,d\omega = \int L_{\mathrm{res}}\,d\omega + \sum_s L_s\,\Omega_s
   \quad\text{(per RGB channel)} $$

`extract_sources` finds each source as the texels connected to the brightest one (8-
neighbours, wrapping in φ and across the poles) whose luminance exceeds `threshold` × its
peak, keeps it when its solid angle is ≤ `max_solid_angle` and its power above the fill is
≥ `min_fraction` of the map's, and replaces those texels in the residual by the
solid-angle-weighted mean of the ring of texels around them (never above the texel itself).
The source keeps the rest: power Φ_s = Σ_t (L_t − L_res,t) Ω_t, solid angle Ω_s = Σ_t Ω_t,
radiance L_s = Φ_s / Ω_s, direction = the excess-luminance-weighted mean of the texel centres.

`source_radiance` shades the caps at shading points (SPEC §9's integrand, restricted to a cap):

$$ L_j \mathrel{+}= \sum_s \sum_k \bar R_{jk}(\mu_s, \Sigma_s)\, L_{s,k}\, m_s,\qquad
   m_s = \int_{\mathrm{cap}_s} \tilde\rho\,\langle n,\omega_i\rangle\, d\omega_i
   \approx \sum_q w_q\, \frac{D(h_q)\, G_2}{4\cos\theta_o} $$

The lobe mass m_s is a product rule on the cap (`cap_rule`: Gauss–Radau in cos ρ from the
cap's axis × equally spaced φ, default the axis and a ring of 4; exact for the cap's area
and its first and second direction moments); nodes below the horizon weigh 0. μ_s, Σ_s are
the mean and covariance of the light direction under those weights, and R̄ is K 29 of that
small distribution: for a cap much smaller than the lobe it is the film term at the
source's own half vector, and it filters the phase spread where the cap is not small. Each
source's colour is folded into the bands once on the host (`with_film_tables`: a J-band Ŝ
LUT of S_j Σ_k ĉ_k B_k), so the K 29 read costs what a plain J-band read costs, not the
J·3 cross bands; it is read bilinearly (as `improved`'s bins, within 2e-3 of the exact Ŝ).
Cost per source and shading point: the nodes' D·G₂ (default 5) and one J-band K 29.

Example (a map that is a constant sky plus one bright texel: the split keeps every channel's
∫ L dω, and the source sits at that texel's centre):
    >>> import numpy as np
    >>> from thinfilm_jax.shading.envmap import texel_centers, texel_solid_angles
    >>> from thinfilm_jax.shading.sources import extract_sources
    >>> m = np.ones((32, 64, 3)); m[5, 7] = 1000.0
    >>> residual, src = extract_sources(m)
    >>> src.radiance.shape, round(float(np.asarray(residual.radiance)[5, 7, 0]), 12)
    ((1, 3), 1.0)
    >>> om = texel_solid_angles(32, 64)[..., None]
    >>> total = (np.asarray(residual.radiance) * om).sum((0, 1)) + np.asarray(
    ...     src.radiance * src.solid_angle[:, None]).sum(0)
    >>> bool(np.allclose(total, (m * om).sum((0, 1)), rtol=1e-12))
    True
    >>> bool(np.allclose(src.direction[0], texel_centers(32, 64)[5, 7]))
    True
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from .envmap import EnvMap, load_envmap, luminance_weights, texel_centers, texel_solid_angles
from ..core.film import Film
from ..core.material import expand_batch
from ..realtime.filtered import filtered_bands
from ..optics.fresnel import complex_dtype
from ..spectral.lut import ShatLUT, build_shat_lut
from ..brdf.microfacet import _g2_over_cos_o, normal_distribution
from ..optics.opd import cos_incidence_from_projection, taylor_opd_moments
from ..spectral.spectra import Observer, get_observer
from ..spectral.uplift import cross_band_name

__all__ = [
    "FilmTable",
    "Sources",
    "extract_sources",
    "with_film_tables",
    "cap_nodes",
    "source_radiance",
    "source_light",
]

#: (rings, angles per ring) of the cap rule (`cap_rule`): the axis and one ring of 4, 5 nodes
DEFAULT_CAP_RULE = (1, 4)


class FilmTable(NamedTuple):
    """One source's colour folded into the cross bands: the Ŝ LUT of the J bands
    S_j(λ) Σ_k ĉ_k B_k(λ) (ĉ = the source's RGB over its sum), their Ŝ_j(0) (J,), and the
    sum of the RGB radiance (the scale ĉ left out)."""

    lut: ShatLUT
    shat0: Array
    scale: Array


class Sources(NamedTuple):
    """S spherical-cap sources (a pytree): world directions (S, 3) of the caps' axes, solid
    angles Ω_s (S,) in sr, linear RGB radiance (S, 3) over each cap; `tables`: one
    `FilmTable` per source (`with_film_tables`), or None (the cross-band LUT is read)."""

    direction: Array
    solid_angle: Array
    radiance: Array
    tables: tuple[FilmTable, ...] | None = None

    @property
    def count(self) -> int:
        return self.solid_angle.shape[0]

    def power(self) -> Array:
        """Φ_s = L_s Ω_s (S, 3), W·m⁻²-like units of the map times sr."""
        return self.radiance * self.solid_angle[:, None]

    def astype(self, dtype) -> Sources:
        cdt = complex_dtype(jnp.zeros((), dtype))
        return jax.tree.map(lambda x: jnp.asarray(x, cdt if jnp.iscomplexobj(x) else dtype),
                            self)


def no_sources(dtype=None) -> Sources:
    """The empty set (S = 0): shading it adds nothing."""
    dtype = dtype or jnp.result_type(float)
    return Sources(jnp.zeros((0, 3), dtype), jnp.zeros((0,), dtype), jnp.zeros((0, 3), dtype))


# ----------------------------------------------------------------------------- extraction
def _neighbours(i: int, j: int, h: int, w: int):
    """8-neighbours of texel (i, j): wrapping in φ; across a pole, the texel opposite in φ."""
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == dj == 0:
                continue
            ii, jj = i + di, (j + dj) % w
            if ii < 0 or ii >= h:  # over the pole: same polar row, φ + π
                ii, jj = (0 if ii < 0 else h - 1), (jj + w // 2) % w
            yield ii, jj


def _grow(bright: np.ndarray, seed, omega: np.ndarray, limit: float):
    """Texels connected to `seed` where `bright`; None once their solid angle exceeds `limit`."""
    h, w = bright.shape
    region, todo, total = {seed}, [seed], 0.0
    while todo:
        i, j = todo.pop()
        total += omega[i, j]
        if total > limit:
            return None
        for nb in _neighbours(i, j, h, w):
            if nb not in region and bright[nb]:
                region.add(nb)
                todo.append(nb)
    return sorted(region)


def extract_sources(envmap, *, max_sources: int = 4, threshold: float = 0.02,
                    min_fraction: float = 0.05, max_solid_angle: float = 0.01
                    ) -> tuple[EnvMap, Sources]:
    """Split a map into (residual `EnvMap`, `Sources`) with equal ∫ L dω per channel.

    Args:
        envmap: `EnvMap`, path, shipped name or (H, W, 3) array (`load_envmap`).
        max_sources: at most this many sources, brightest first (0: none).
        threshold: a source is the texels connected to the current peak whose luminance
            exceeds `threshold` × the peak's.
        min_fraction: keep a source only if its power above the fill is at least this
            fraction of the map's luminous power (stop at the first that is not).
        max_solid_angle: keep a source only if its texels cover at most this many sr (a
            larger bright region is sky, not a sun; stop there).
    Host-side (NumPy, float64), once per map; the maps keep their dtype.
    """
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    if not (isinstance(max_sources, int) and max_sources >= 0):
        raise ValueError(f"max_sources must be an int >= 0, got {max_sources!r}")
    for name, v, hi in (("threshold", threshold, 1.0), ("min_fraction", min_fraction, 1.0),
                        ("max_solid_angle", max_solid_angle, 4 * np.pi)):
        if not (0.0 < v <= hi):
            raise ValueError(f"{name} must be in (0, {hi:.6g}], got {v!r}")
    dtype = env.radiance.dtype
    rad = np.array(env.radiance, np.float64)
    h, w = env.shape
    omega = texel_solid_angles(h, w)
    dirs = texel_centers(h, w)
    lum_w = luminance_weights()
    total = float(np.sum((rad @ lum_w) * omega))
    found = []
    done = np.zeros((h, w), bool)
    while len(found) < max_sources and total > 0:
        y = rad @ lum_w
        y_free = np.where(done, -np.inf, y)
        seed = np.unravel_index(int(np.argmax(y_free)), (h, w))
        peak = y_free[seed]
        if not peak > 0:
            break
        region = _grow((y > threshold * peak) & ~done, seed, omega, max_solid_angle)
        if region is None:
            break
        inside = np.zeros((h, w), bool)
        inside[tuple(np.array(region).T)] = True
        ring = {nb for t in region for nb in _neighbours(*t, h, w) if not inside[nb]}
        ring = tuple(np.array(sorted(ring)).T)
        fill = (rad[ring] * omega[ring][:, None]).sum(0) / omega[ring].sum()
        idx = tuple(np.array(region).T)
        resid = np.minimum(rad[idx], fill)
        excess = (rad[idx] - resid) * omega[idx][:, None]  # (n, 3) power above the fill
        power = excess.sum(0)
        if float(power @ lum_w) < min_fraction * total:
            break
        wy = excess @ lum_w
        axis = (dirs[idx] * wy[:, None]).sum(0)
        axis = axis / np.linalg.norm(axis)
        solid = float(omega[idx].sum())
        found.append((axis, solid, power / solid))
        rad[idx] = resid
        done |= inside
    if found:
        src = Sources(*(jnp.asarray(np.stack(x) if k != 1 else np.array(x), dtype)
                        for k, x in enumerate(zip(*found))))
    else:
        src = no_sources(dtype)
    return EnvMap(jnp.asarray(rad, dtype)), src


def with_film_tables(sources: Sources, observer: str, dtype=None) -> Sources:
    """`sources` with one `FilmTable` each for `observer`'s bands (host-side, ~0.3 s each).

    Under a source of RGB radiance c, L_j = Σ_k R_jk c_k with R_jk linear in the band
    weights S_j B_k; folding ĉ = c / Σc into the weights gives J bands S_j Σ_k ĉ_k B_k whose
    K 29 reflectance, times Σc, is L_j: a J-band LUT read instead of J·3 (the cross bands)."""
    dtype = dtype or sources.radiance.dtype
    cross = get_observer(cross_band_name(observer))
    base = get_observer(observer)
    w = cross.weights.reshape(cross.weights.shape[0], base.n_bands, 3)  # (K, J, RGB)
    tables = []
    for rgb in np.asarray(sources.radiance, np.float64):
        scale = float(rgb.sum())
        chroma = rgb / scale if scale > 0 else np.full(3, 1.0 / 3.0)
        weights = w @ chroma  # (K, J)
        obs = Observer(f"{base.name}·source", base.wavelengths, weights, base.areas,
                       base.band_names)
        tables.append(FilmTable(build_shat_lut(obs, dtype=dtype),
                                jnp.asarray(weights.sum(0), dtype), jnp.asarray(scale, dtype)))
    return sources._replace(tables=tuple(tables))


# ----------------------------------------------------------------------------- shading
@functools.cache
def cap_rule(rings: int, n_phi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, φ, weight) of the product rule on a cap, t = (1 − cos ρ)/(1 − cos γ) ∈ [0, 1]
    (uniform in solid angle): Gauss–Radau in t with its fixed node on the axis (t = 0, one
    node) and `rings` rings of n_phi equally spaced angles (rotated by half a step on even
    rings); weights sum to 1. rings = 1: t = 2/3, weights 1/4 and 3/4 (exact to degree 2
    in cos ρ); rings = 2: degree 4. With n_phi ≥ 3 the cap's area and its first and second
    direction moments are exact; the axis node catches a lobe narrower than the cap."""
    if rings == 1:
        t, w = np.array([0.0, 2.0 / 3.0]), np.array([0.25, 0.75])
    elif rings == 2:
        r6 = np.sqrt(6.0)
        t = np.array([0.0, (6.0 - r6) / 10.0, (6.0 + r6) / 10.0])
        w = np.array([1.0 / 9.0, (16.0 + r6) / 36.0, (16.0 - r6) / 36.0])
    else:
        raise ValueError(f"cap_rule: rings must be 1 or 2, got {rings!r}")
    if not (isinstance(n_phi, int) and n_phi >= 3):
        raise ValueError(f"cap_rule: n_phi must be an int >= 3, got {n_phi!r}")
    ring = np.repeat(np.arange(1, rings + 1), n_phi)
    phi = 2 * np.pi * (np.tile(np.arange(n_phi), rings) + 0.5 * (ring % 2 == 0)) / n_phi
    return (np.concatenate([[0.0], np.repeat(t[1:], n_phi)]), np.concatenate([[0.0], phi]),
            np.concatenate([[w[0]], np.repeat(w[1:], n_phi) / n_phi]))


def _frame(axis):
    """Orthonormal (t, b) ⟂ axis, branch-free (Duff et al. 2017)."""
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    sign = jnp.where(z >= 0, 1.0, -1.0).astype(axis.dtype)
    a = -1.0 / (sign + z)
    b = x * y * a
    t = jnp.stack([1.0 + sign * x * x * a, sign * b, -sign * x], -1)
    u = jnp.stack([b, sign + y * y * a, -y], -1)
    return t, u


def cap_nodes(sources: Sources, rule: tuple[int, int] = DEFAULT_CAP_RULE):
    """Node directions (S, Q, 3) and solid-angle weights (S, Q) (Σ_q = Ω_s) of every cap."""
    t, phi, wq = (jnp.asarray(v, sources.solid_angle.dtype) for v in cap_rule(*rule))
    one_minus_cos_cap = sources.solid_angle / (2 * jnp.pi)  # Ω = 2π (1 − cos γ)
    cos_r = 1.0 - t[None, :] * one_minus_cos_cap[:, None]  # (S, Q)
    s2 = (1.0 - cos_r) * (1.0 + cos_r)
    off = s2 > 0  # the axis node (t = 0): sin ρ = 0 with a finite gradient (double-where)
    sin_r = jnp.where(off, jnp.sqrt(jnp.where(off, s2, 1.0)), 0.0)
    tan1, tan2 = _frame(sources.direction)
    d = (cos_r[..., None] * sources.direction[:, None, :]
         + (sin_r * jnp.cos(phi))[..., None] * tan1[:, None, :]
         + (sin_r * jnp.sin(phi))[..., None] * tan2[:, None, :])
    return d, sources.solid_angle[:, None] * wq[None, :]


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]  # no contraction


def _node_terms(d, w, normal, view, alpha, co, c_axis, dot=_dot):
    """f, f·δ, f·δ² of cap nodes `d` (..., 3) with weights `w`: f = ρ̃ ⟨n, ω_i⟩ dω of the node
    (GGX D·G₂/(4 cos θ_o), 0 below the horizon) and δ = ⟨ω_i, ω_o⟩ − c_axis (the shift keeps
    the variance of a tiny cap free of cancellation). Elementwise: `d` may be one node (its
    scalars against per-point arrays) or nodes on an axis of their own; `dot` the 3-vector
    product."""
    ci = dot(normal, d)
    h = d + view
    hn2 = dot(h, h)
    lit = (ci > 0) & (hn2 > 0)
    cos_h = dot(normal, h) / jnp.sqrt(jnp.where(lit, hn2, 1.0))
    f = normal_distribution(cos_h, alpha) * _g2_over_cos_o(jnp.where(lit, ci, 0.0), co, alpha,
                                                           "ggx") / 4
    f = jnp.where(lit, f, 0.0) * w
    delta = dot(view, d) - c_axis
    fd = f * delta
    return f, fd, fd * delta


@jax.custom_vjp
def _cap_sums(nodes, wts, normal, view, alpha, co, c_axis):
    """Σ_q of `_node_terms` over one cap's nodes (Q, 3), (Q,) at every shading point.

    Forward: the Q nodes unrolled on per-point arrays (one elementwise pass; a reduction over
    a short node axis would be a loop of its own). Backward: the same terms with the nodes on
    an axis, so that each point's cotangent reaches the nodes through one reduction; the
    unrolled form's transpose has one reduction per node scalar, and XLA:CPU fused the whole
    per-point backward pass into each of them (15 copies for a 5-node cap). The gradient of
    `source_radiance` w.r.t. film, α, normal, view and sources (18 points, cross-band LUT)
    compiles in 10.7 s instead of 16.1 (2-core CPU)."""
    terms = [_node_terms(nodes[q], wts[q], normal, view, alpha, co, c_axis)
             for q in range(nodes.shape[0])]
    return tuple(functools.reduce(jnp.add, t) for t in zip(*terms))


def _sum_dot(a, b):
    return jnp.sum(a * b, axis=-1)  # the transpose of `_dot`'s three slices is three pads


def _cap_sums_on_axis(nodes, wts, normal, view, alpha, co, c_axis):
    """`_cap_sums` with the nodes on an axis (what its backward pass differentiates)."""
    x = (normal[..., None, :], view[..., None, :], alpha[..., None], co[..., None],
         c_axis[..., None])
    return tuple(jnp.sum(t, axis=-1) for t in _node_terms(nodes, wts, *x, dot=_sum_dot))


def _cap_sums_fwd(*args):
    return _cap_sums(*args), args


def _cap_sums_bwd(args, cts):
    return jax.vjp(_cap_sums_on_axis, *args)[1](cts)


_cap_sums.defvjp(_cap_sums_fwd, _cap_sums_bwd)


def source_radiance(film: Film, alpha, normal, view, sources: Sources, *, observer: str,
                    terms: int = 2, shat: str = "lut", lut=None, arithmetic: str = "complex",
                    cross_band: bool = True, rule: tuple[int, int] = DEFAULT_CAP_RULE) -> Array:
    """Band radiance (..., J) of the caps at shading points (module docstring); 0 for S = 0
    and where ⟨n, ω_o⟩ ≤ 0.

    Args:
        film, alpha, normal, view: as `ibl.envmap_radiance` (broadcast shading points).
        sources: `Sources` in the map's world frame; with `tables` (and shat="lut",
            `cross_band`) each source reads its own J-band table, else the cross bands.
        observer: the plain band name (the cross bands are read when `cross_band`).
        terms, shat, lut, arithmetic: as `kernels.filtered_kernel`; `lut` holds the
            bands read without tables (the cross bands when `cross_band`).
        cross_band: R_jk under the sources' RGB (SPEC §9) or the diagonal R_j L_j.
        rule: (rings, n_phi) of `cap_rule`.
    """
    shape = normal.shape[:-1]
    n_bands = get_observer(observer).n_bands
    if sources.count == 0:
        return jnp.zeros(shape + (n_bands,), normal.dtype)
    nodes, wts = cap_nodes(sources.astype(normal.dtype), rule)  # (S, Q, 3), (S, Q)
    cos_o = _dot(normal, view)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    alpha = jnp.asarray(alpha)
    mass, mu_c, var_c = [], [], []
    for s in range(sources.count):
        c_axis = _dot(view, sources.direction[s].astype(normal.dtype))
        m, m1, m2 = _cap_sums(nodes[s], wts[s], normal, view, alpha, co, c_axis)
        has = m > 0
        inv = 1.0 / jnp.where(has, m, 1.0)
        mean_d = jnp.where(has, m1 * inv, 0.0)  # a cap with no lit node: its axis (term 0)
        var = jnp.where(has, m2 * inv - mean_d * mean_d, 0.0)
        mu = c_axis + mean_d
        mu = jnp.where(mu > 1.0, 1.0, jnp.where(mu < -1.0, -1.0, mu))  # rounding only
        mass.append(m), mu_c.append(mu), var_c.append(jnp.where(var > 0, var, 0.0))
    kw = dict(terms=terms, arithmetic=arithmetic)
    if sources.tables is not None and shat == "lut" and cross_band:
        out = None
        for tab, m, mu, var in zip(sources.tables, mass, mu_c, var_c):  # K 29 per source
            r = filtered_bands(film, cos_incidence_from_projection(mu),
                               taylor_opd_moments(film, mu, var), None, shat="lut",
                               lut=tab.lut, shat0=tab.shat0, interpolation="linear", **kw)
            r = r * (tab.scale.astype(r.dtype) * m)[..., None]
            out = r if out is None else out + r
    else:  # the cross bands (or the plain ones, diagonal) for all sources at once
        mass, mu_c, var_c = (jnp.stack(x, axis=-1) for x in (mass, mu_c, var_c))  # (..., S)
        f3 = expand_batch(film)
        obs = cross_band_name(observer) if cross_band else observer
        r = filtered_bands(f3, cos_incidence_from_projection(mu_c),
                           taylor_opd_moments(f3, mu_c, var_c), obs, shat=shat, lut=lut,
                           **kw)  # (..., S, J[·3])
        light = sources.radiance.astype(normal.dtype)  # (S, 3)
        if cross_band:
            r = jnp.sum(r.reshape(r.shape[:-1] + (3, 3)) * light[:, None, :], axis=-1)
        else:
            r = r * light
        out = jnp.sum(r * mass[..., None], axis=-2)
    return jnp.where(up[..., None], out, 0.0)


def source_light(alpha, normal, view, sources: Sources, *,
                 rule: tuple[int, int] = DEFAULT_CAP_RULE) -> Array:
    """Σ_s m_s L_s (..., 3): the caps' RGB radiance through the GGX lobe with no film term
    (m_s the lobe mass of cap s, module docstring), 0 for S = 0 and where ⟨n, ω_o⟩ ≤ 0. What
    a per-channel Fresnel that does not depend on the light direction multiplies (the `khr`
    method, which reads glTF's F_iridescence at ⟨n, ω_o⟩ for every light as engines do)."""
    shape = normal.shape[:-1]
    if sources.count == 0:
        return jnp.zeros(shape + (3,), normal.dtype)
    nodes, wts = cap_nodes(sources.astype(normal.dtype), rule)  # (S, Q, 3), (S, Q)
    cos_o = _dot(normal, view)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    alpha = jnp.asarray(alpha)
    light = sources.radiance.astype(normal.dtype)  # (S, 3)
    out = jnp.zeros(shape + (3,), normal.dtype)
    for s in range(sources.count):
        c_axis = _dot(view, sources.direction[s].astype(normal.dtype))
        m = _cap_sums(nodes[s], wts[s], normal, view, alpha, co, c_axis)[0]
        out = out + m[..., None] * light[s]
    return jnp.where(up[..., None], out, 0.0)
