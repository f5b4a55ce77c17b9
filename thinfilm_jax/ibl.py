r"""Reflected radiance of a film under an environment map, every method of SPEC §9.

$$ L_j(n, \omega_o) = \sum_k \int \tilde\rho(\omega_i, \omega_o)\langle n,\omega_i\rangle
   R_{jk}(\langle h,\omega_i\rangle)\, c_k(\omega_i)\, d\omega_i \qquad (K\ 7, 11;\ SPEC\ §9) $$

| method      | how                                                                          |
|-------------|------------------------------------------------------------------------------|
| `reference` | texel-space quadrature of the piecewise-constant map: s×s Gauss–Legendre nodes in (cos θ, φ) inside every texel (exact solid-angle measure), R_jk(c) exact spectral on a fine c-grid, interpolated |
| `mc`        | GGX visible-normal sampling (Heitz 2018), weight G₂/G₁, exact spectral R_jk per sample, nearest-texel radiance; fixed key and count |
| `ideal`     | A(θ_o, α) · Σ_k R_jk(cos θ_o) P_k(ω_r, α): BB17 under the split sum (`kernels.ideal_kernel`, Ŝ from the LUT at σ = 0 by default) |
| `filtered`  | A(θ_o, α) · Σ_k R̄_jk P_k(ω_r, α), R̄ = K 29 with the prefiltered moments μ_ω, Σ_ω (`kernels.filtered_kernel`) |
| `improved`  | A(θ_o, α) · (1/K) Σ_b Σ_k R_jk(bin b) P_k(ω_μ,b, α_eff,b): K 29 per equal-probability bin b of cos θ₁, each bin times the prefiltered radiance of its own part of the lobe (tabulated mean direction and equal-variance level; near normal view their mean moved to the whole lobe's read) (`improved.improved_envmap`, issue 11) |

R_jk are the cross bands S_j B_k of the Mallett–Yuksel uplift (`uplift`); the per-channel
("diagonal") approximation L_j ≈ R_j P_j is the option `cross_band=False`.

Reference accuracy. The integrand ρ̃⟨n,ω_i⟩R_jk is smooth inside a texel; s Gauss nodes per
axis integrate it with an error that falls quickly once the sub-cells are narrower than
the lobe (≈ α rad); `subdivisions=None` picks s = ⌈8 Δθ / α⌉ (Δθ = π/H, clipped to [2, 16]; grazing views
compress the lobe, which a factor 4 did not resolve to 1e-3).
R_jk(c) is tabulated on `n_cos` uniform nodes of c = cos θ₁ ∈ [0, 1] and interpolated
linearly: the error is ≤ (Δc)²/8 · max|∂²R/∂c²|, about 1e-6 for d ≤ 1 µm at n_cos = 1024.
The convergence in both (the SPEC's 1e-3 of the band maximum) is tested in tests/test_ibl.py.
Cost per shading point: H·W·s² BRDF evaluations plus n_cos·n_λ Airy evaluations.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from . import _validate as V
from .airy import choose_arithmetic
from .envmap import EnvMap, _row_geometry, load_envmap, lookup_nearest
from .film import Film
from .improved import bin_table, improved_envmap
from .kernels import filtered_kernel, ideal_kernel
from .lut import build_shat_lut
from .microfacet import normal_distribution, smith_g1, smith_g2
from .options import ModelOptions, check_options
from .prefilter import (PrefilteredEnvMap, lookup_albedo, lookup_prefiltered,
                        moments_to_mean_cov, prefilter_envmap)
from .reflectance import spectral_bands
from .spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from .uplift import cross_band_name

METHODS = ("reference", "mc", "ideal", "filtered", "improved")
REALTIME_OPTIONS = ModelOptions(shat="lut")  # the real-time default: Ŝ from the map's table
HIGHEST = jax.lax.Precision.HIGHEST


# ----------------------------------------------------------------------------- public
def envmap_radiance(film: Film, alpha, normal, view, envmap, *, method: str = "reference",
                    observer: str = DEFAULT_OBSERVER, options: ModelOptions = REALTIME_OPTIONS,
                    cross_band: bool = True, subdivisions: int | None = None,
                    n_cos: int = 1024, n_samples: int = 4096, key=None,
                    batch_size: int | None = None) -> Array:
    """Band radiances L_j (..., J) of a film under an environment map (SPEC §9).

    Args:
        film: `Film`, fields broadcasting with the shading points.
        alpha: GGX roughness α ∈ (0, 1].
        normal, view: unit world vectors (..., 3) (z-up); view points toward the eye.
        envmap: `EnvMap` (any method; real-time methods prefilter it on the host each call)
            or `PrefilteredEnvMap` (real-time methods only; build it once).
        method: "reference" | "mc" | "ideal" | "filtered" | "improved".
        observer: colour bands.
        options: `ModelOptions` (default `REALTIME_OPTIONS`: shat="lut", the map's table):
            terms = Fourier orders M and shat = Ŝ source of the real-time methods,
            arithmetic ("auto" specialises a concrete dielectric film); ndf must be "ggx"
            (the prefiltered maps are GGX); quadrature does not apply.
        cross_band: True: R_jk under RGB light (SPEC §9); False: the diagonal approximation.
        subdivisions: s Gauss nodes per axis inside each texel (reference); None = auto.
        n_cos: nodes of the reference's R_jk(cos θ₁) table.
        n_samples, key: Monte Carlo sample count and PRNG key (default key 0).
        batch_size: shading points evaluated together (default: 65536 for the real-time
            methods, about 2¹⁹ quadrature nodes' worth for the exact ones).
    Shading points with ⟨n, ω_o⟩ ≤ 0 give 0.
    """
    V.check_film(film)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    V.check_choice("method", method, METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    options = check_options(options)
    if options.ndf != "ggx":
        raise ValueError(f"envmap_radiance supports ndf='ggx' only (the prefiltered maps and "
                         f"the reference's lobe are GGX), got ndf={options.ndf!r}")
    if options.layer == "bare":
        raise ValueError("envmap_radiance has no bare-interface path (ModelOptions.layer): "
                         "use layer='auto' or 'film'")
    terms, shat = options.terms, options.shat
    for name, v in (("normal", normal), ("view", view)):
        if np.shape(v)[-1:] != (3,):
            raise ValueError(f"{name} must have shape (..., 3), got {np.shape(v)}")
        if V.is_concrete(v):
            V.check_finite(name, v)
            nrm = np.linalg.norm(np.asarray(v, float), axis=-1)
            if np.any(np.abs(nrm - 1) > 1e-3):
                raise ValueError(f"{name} must be unit vectors; got a norm of "
                                 f"{nrm.flat[np.argmax(np.abs(nrm - 1))]:.6g}")
    shape = V.check_broadcast([("film", np.zeros(film.shape)), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    arithmetic = choose_arithmetic(film, options.arithmetic)
    realtime = method in ("ideal", "filtered", "improved")
    if isinstance(envmap, PrefilteredEnvMap):
        if not realtime:
            raise ValueError(f"method={method!r} integrates the map itself: pass an EnvMap, "
                             "not a PrefilteredEnvMap")
        pref = envmap
    elif realtime:
        pref = prefilter_envmap(envmap, observer=observer)
    else:
        env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    dtype = jnp.result_type(alpha, normal, view, *film, float)
    args = [jnp.broadcast_to(jnp.asarray(x, dtype), shape) for x in (*film, alpha)]
    nv = [jnp.broadcast_to(jnp.asarray(v, dtype), shape + (3,)) for v in (normal, view)]
    if realtime:
        if shat == "lut" and pref.lut.table.shape[-1] != 3 * get_observer(observer).n_bands:
            raise ValueError("the PrefilteredEnvMap was built for another observer")
        cfg = (method, observer, terms, shat, bool(cross_band), arithmetic)
        if method == "improved":  # its (θ_o, α) tables travel with the map
            pref = (pref, bin_table(dtype=dtype))
        return _realtime_jit(Film(*args[:5]), args[5], *nv, pref, cfg,
                             int(batch_size or 65536))
    n_pts = int(np.prod(shape))
    if method == "reference":
        if subdivisions is None:
            subdivisions = auto_subdivisions(env.shape[0], alpha)
        subdivisions = int(subdivisions)
        if subdivisions < 1:
            raise ValueError(f"subdivisions must be a positive int, got {subdivisions!r}")
        d, wt, idx = texel_nodes(*env.shape, subdivisions)
        rad = env.radiance.astype(dtype).reshape(-1, 3)
        nodes = (jnp.asarray(d, dtype), jnp.asarray(wt, dtype)[:, None] * rad[idx])
        cfg = ("reference", observer, subdivisions, int(n_cos), bool(cross_band), arithmetic,
               _batch(batch_size, n_pts, len(wt)), film.shape == ())
        return _exact_jit(Film(*args[:5]), args[5], *nv, env.radiance.astype(dtype), nodes, cfg)
    if not (isinstance(n_samples, int) and n_samples >= 1):
        raise ValueError(f"n_samples must be a positive int, got {n_samples!r}")
    key = jax.random.key(0) if key is None else key
    cfg = ("mc", observer, int(n_samples), 0, bool(cross_band), arithmetic,
           _batch(batch_size, n_pts, n_samples * 64), False)
    return _exact_jit(Film(*args[:5]), args[5], *nv, env.radiance.astype(dtype), key, cfg)


def auto_subdivisions(height: int, alpha) -> int:
    """s = ⌈8 (π/H) / α_min⌉ in [2, 16]: sub-cells an eighth of the narrowest lobe."""
    a = float(np.min(np.asarray(alpha))) if V.is_concrete(alpha) else 0.05
    return int(np.clip(np.ceil(8 * np.pi / height / a), 2, 16))


def _batch(batch_size, n_pts, per_point):
    if batch_size is None:
        batch_size = max(1, int(2**19 // max(per_point, 1)))
    return int(max(1, min(batch_size, max(n_pts, 1))))


# ----------------------------------------------------------------------------- real time
@functools.partial(jax.jit, static_argnums=(5, 6))
def _realtime_jit(film, alpha, normal, view, pref, cfg, chunk):
    """Flatten the shading points and shade them `chunk` at a time (bounded memory)."""
    shape = alpha.shape
    flat = [x.reshape(-1) for x in (*film, alpha)] + [v.reshape(-1, 3) for v in (normal, view)]
    n = flat[0].shape[0]
    if n <= chunk:
        out = _realtime_points(Film(*flat[:5]), *flat[5:], pref, cfg)
    else:
        m = -(-n // chunk)
        padded = [jnp.pad(x, [(0, m * chunk - n)] + [(0, 0)] * (x.ndim - 1), mode="edge")
                  for x in flat]
        out = jax.lax.map(lambda xs: _realtime_points(Film(*xs[:5]), *xs[5:], pref, cfg),
                          [x.reshape((m, chunk) + x.shape[1:]) for x in padded])
        out = out.reshape(m * chunk, -1)[:n]
    return out.reshape(*shape, out.shape[-1])


def _realtime_points(film, alpha, normal, view, pref, cfg):
    method, observer, terms, shat, cross, arithmetic = cfg
    if method == "improved":
        pref, table = pref
        lut = pref.lut if cross else (build_shat_lut(observer, dtype=alpha.dtype)
                                      if shat == "lut" else None)
        return improved_envmap(film, alpha, normal, view, pref, table, observer=observer,
                               terms=terms, shat=shat, lut=lut, arithmetic=arithmetic,
                               cross_band=cross)
    cos_o = jnp.sum(normal * view, axis=-1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    refl = 2 * co[..., None] * normal - view
    sqa = jnp.sqrt(alpha)
    rad, mom = lookup_prefiltered(pref, refl, sqa)
    a = lookup_albedo(pref, co, sqa)
    obs = cross_band_name(observer) if cross else observer
    lut = pref.lut if cross else None
    if shat == "lut" and not cross:  # the diagonal path reads the plain bands' table
        lut = build_shat_lut(observer, dtype=alpha.dtype)
    if method == "ideal":
        r = ideal_kernel(film, co, observer=obs, terms=terms, shat=shat, lut=lut,
                         arithmetic=arithmetic)
    else:
        if pref.per_channel:  # moments of channel k drive R_jk (..., 3[k], 9)
            mean, cov = moments_to_mean_cov(mom)
            f3 = Film(*(jnp.asarray(x)[..., None] for x in film))
            r = filtered_kernel(f3, view[..., None, :], mean, cov, observer=obs, terms=terms,
                                shat=shat, lut=lut, arithmetic=arithmetic)
        else:
            mean, cov = moments_to_mean_cov(mom)
            r = filtered_kernel(film, view, mean, cov, observer=obs, terms=terms, shat=shat,
                                lut=lut, arithmetic=arithmetic)
    if cross:
        r = r.reshape(r.shape[:-1] + (3, 3))  # (..., [k,] j, k)
        if r.ndim > rad.ndim + 1:  # per-channel moments: keep k of the moments = k of R
            r = jnp.diagonal(r, axis1=-3, axis2=-1)  # (..., j, k)
        out = jnp.sum(r * rad[..., None, :], axis=-1)
    else:
        if r.ndim > rad.ndim:
            r = jnp.diagonal(r, axis1=-2, axis2=-1)
        out = r * rad
    return jnp.where(up[..., None], a[..., None] * out, 0.0)


# ----------------------------------------------------------------------------- exact
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


@functools.partial(jax.jit, static_argnums=(6,))
def _exact_jit(film, alpha, normal, view, radiance, extra, cfg):
    """extra: (node directions, node weight × radiance) for the reference, a key for MC."""
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
        if cross:
            r = r.reshape(r.shape[:-1] + (-1, 3))  # (N, j, k)
            return jnp.einsum("njk,nk->j", r, light, precision=HIGHEST)
        return jnp.sum(r * light, axis=0)

    xs = tuple(flat) + ((keys,) if method == "mc" else ())
    out = jax.lax.map(one, xs, batch_size=batch)
    cos_o = jnp.sum(normal * view, -1)
    return jnp.where((cos_o > 0)[..., None], out.reshape(*shape, out.shape[-1]), 0.0)
