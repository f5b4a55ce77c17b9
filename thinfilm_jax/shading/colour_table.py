r"""Prefiltered colour tables (Kneiphof & Klein 2022, SPEC §11): brightness × colour under a map.

K&K 2022 factor a BRDF into a *brightness* BRDF f_b that standard real-time IBL handles (the
split sum) and a *colour* χ that carries the angular colour variation. For a film on GGX,
f_b = ρ̃ (GGX with F = 1, height-correlated Smith) and χ_jk = R_jk(⟨h, ω_i⟩), the exact
cross-band reflectance under RGB light (SPEC §9). The colour is prefiltered with the kernel
that the map and the brightness BRDF define:

$$ C_{jk}(\omega_r, \theta_o) = \frac{\big\langle \int f_b\,\langle n,\omega_i\rangle\,
   \chi_{jk}\, L_k(\omega_i)\, d\omega_i \big\rangle_\psi}
   {\big\langle \int f_b\,\langle n,\omega_i\rangle\, L_k(\omega_i)\, d\omega_i
   \big\rangle_\psi}, $$

where the configuration (n, ω_o) is fixed by the ideal reflection direction ω_r, the view
angle θ_o = ∠(n, ω_o) and the azimuth ψ of n around ω_r, and ⟨·⟩_ψ marginalises ψ (the 3D
table of K&K 2022: ω_r × θ_o; the ratio of the ψ-means, so a dark azimuth does not weigh as
much as a bright one). Shading is the split-sum brightness times the table:

$$ L_j(n, \omega_o) = A(\theta_o, \alpha)\,\sum_k C_{jk}(\omega_r, \theta_o)\,
   P_k(\omega_r, \alpha) \qquad (\text{K 9 for } A\,P). $$

A car paint (`brdf.carpaint.CarPaint`, the AxF CPA2 form) is already written this way: f_b is
its Lambert term and GGX lobes seen through the coat, χ_j(θ_h, θ_d) its colour table (one
channel per band, no cross bands). Its brightness is a sum of terms, each an albedo row
A_b(θ_o) times a prefiltered map: every lobe the map at min(1, η_c α_l) read at ω_r (a lobe
refracted out of the coat is η_c times wider near normal view), the Lambert term the
cosine-filtered map read at n, and the coat's mirror F(θ_o) times the box-filtered map at ω_r,
added uncoloured (`ColourTable.terms`).

The table is stored as K&K 2022 do, decomposed into a function of ω_r (their low-resolution
cubemap; here an equirect map of the same role) times a function of θ_o (their 2D array:
θ_o × channel), per channel the best rank-1 approximation (truncated SVD); `rank` r > 1 keeps
r terms, r = full reproduces the 3D table (also kept, `ColourTable.full`, for `rank=None`).

Quadrature of the table (host, once per material and map): every texel of the map (box-
filtered with `envmap.downsample` while its texels stay ≤ α/4, as `prefilter`), s × s
Gauss–Legendre nodes per texel (`subdivisions`), `n_azimuth` uniform ψ nodes (the integrand
is periodic in ψ: the trapezoid rule converges geometrically), view nodes
u = √cos θ_o = 1/n, 2/n, …, 1 (n = `n_view`; the variable of `prefilter.albedo_table`), R_jk(c)
exact spectral on `n_cos` nodes of c, interpolated. A(θ_o, α) is the exact `microfacet.albedo` at
the material's α on 64 nodes of √cos θ_o; P(ω_r, α) is the map prefiltered at exactly α
(`prefilter.filter_level`). Measured errors (tests/shading/test_colour_table.py): the
decomposition's own error (`decomposition_error`), convergence under refinement, and the
method against the exact reference and the exact-colour ceiling (`exact_colour_radiance`,
C_jk computed at each shading point) in the colour-table study.

Example (a white map: C summed over k is the uniform-light film colour, so the shading is
the exact patch radiance up to the quadrature of the table; the table's memory in bytes):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, patch_radiance
    >>> from thinfilm_jax.shading.colour_table import prefilter_colour, colour_table_radiance
    >>> film = Film(600.0, 1.3, 2.0, 0.5)
    >>> table = prefilter_colour(np.ones((16, 32, 3)), film, 0.3, resolution=(4, 8),
    ...                          n_view=4, n_azimuth=2, brightness_resolution=(8, 16))
    >>> L = colour_table_radiance(table, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    >>> exact = patch_radiance(film, 0.0, 0.3, method="reference")
    >>> bool(np.abs(L - exact).max() < 2e-3)
    True
    >>> table.colour.shape, table.view.shape  # rank 1: (h, w, r, J·K), (n_view, r, J·K)
    ((4, 8, 1, 9), (4, 1, 9))
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..brdf.carpaint import (CarPaint, brightness_and_colour, check_paint, coat_reflectance,
                             lobe_albedo)
from ..brdf.microfacet import albedo
from ..core import _validate as V
from ..core._pytree import pytree_dataclass
from ..core.film import Film
from ..optics.airy import choose_arithmetic
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS
from ..spectral.uplift import cross_band_name
from .envmap import (EnvMap, downsample, load_envmap, lookup_bilinear, texel_centers,
                     texel_solid_angles)
from .ibl_integrand import interp_table, _local_frame, lobe_cos_weight, reflectance_table, texel_nodes
from ..realtime.improved import bin_table
from .prefilter import bin_radiance, filter_level, level_source

__all__ = ["ColourTable", "prefilter_colour", "colour_table_radiance", "check_colour_table",
           "exact_colour_radiance", "decomposition_error", "map_fingerprint"]

HIGHEST = jax.lax.Precision.HIGHEST
N_ALBEDO = 64  # nodes of A(θ_o) in √cos θ_o


class ColourTable:
    """The K&K 2022 tables of one material under one map (a pytree; arrays are leaves).

    colour: (h, w, r, C) the ω_r factors (equirect, texel centres), C channels
        (J·K = 9 cross bands R_jk of a film; J = 3 for a paint's diagonal colour χ_j).
    view: (n_view, r, C) the θ_o factors at u = √cos θ_o = (i + 1)/n_view.
    full: (h, w, n_view, C) the 3D table C(ω_r, θ_o) before the decomposition.
    brightness: (B, hb, wb, 3) the brightness terms' prefiltered maps: per GGX lobe the map
        prefiltered at its width (read at ω_r), a paint's Lambert term the cosine-filtered
        map (read at n), a paint's coat the box-filtered map (read at ω_r).
    albedo: (N_ALBEDO, B) each term's directional albedo on a uniform grid of √cos θ_o
        (A(θ_o, α) of GGX; a paint's `carpaint.lobe_albedo` and `coat_reflectance`).
    Static: `terms` (B names: "specular", "diffuse", "coat"; the coat is not coloured),
    `alphas` (the GGX α of each term, 0 elsewhere), `material` (fingerprint of the concrete
    material the table was built for), `envmap` (fingerprint of the map), `observer`,
    `cross` (C = J·K), `build_seconds`.
    """

    colour: Array
    view: Array
    full: Array
    brightness: Array
    albedo: Array
    terms: tuple = ("specular",)
    alphas: tuple = ()
    material: tuple = ()
    envmap: str = ""
    observer: str = DEFAULT_OBSERVER
    cross: bool = True
    build_seconds: float = 0.0

    @property
    def rank(self) -> int:
        return int(self.colour.shape[-2])

    @property
    def nbytes(self) -> dict:
        """Memory of what shading reads: the decomposed colour, the 3D table, brightness."""
        item = lambda a: int(np.prod(a.shape)) * a.dtype.itemsize  # noqa: E731
        return {"colour_table": item(self.colour) + item(self.view),
                "full_table": item(self.full),
                "brightness": item(self.brightness) + item(self.albedo)}


ColourTable = pytree_dataclass(ColourTable, ["colour", "view", "full", "brightness", "albedo"],
                               ["terms", "alphas", "material", "envmap", "observer", "cross",
                                "build_seconds"])


# ----------------------------------------------------------------------------- fingerprints
def map_fingerprint(envmap) -> str:
    """A short hash of a map's radiance (what a `ColourTable` was built under)."""
    a = np.ascontiguousarray(np.asarray(getattr(envmap, "radiance", envmap), np.float64))
    return hashlib.sha1(a.tobytes() + str(a.shape).encode()).hexdigest()[:16]


def _film_fingerprint(film: Film, alpha) -> tuple:
    """("film", each of `Film._fields` in that order, alpha), all Python floats."""
    vals = [np.asarray(x, np.float64) for x in (*(getattr(film, k) for k in Film._fields),
                                                 alpha)]
    if any(v.size != 1 for v in vals):
        raise ValueError("prefilter_colour builds the table of one homogeneous material: "
                         "film fields and alpha must be scalars, got shapes "
                         f"{[v.shape for v in vals]}")
    return ("film",) + tuple(float(v.reshape(())) for v in vals)


def _fingerprint_film(key: tuple) -> Film:
    """The `Film` (float fields, by name) that a `_film_fingerprint` key describes."""
    return Film(**dict(zip(Film._fields, key[1:-1], strict=True)))


def _paint_fingerprint(paint: CarPaint) -> tuple:
    h = hashlib.sha1()
    for x in paint:
        a = np.ascontiguousarray(np.asarray(x, np.float64))
        h.update(a.tobytes() + str(a.shape).encode())
    return ("paint", h.hexdigest()[:16])


def check_colour_table(table, film: Film | None = None, alpha=None, envmap=None) -> None:
    """Raise a `ValueError` if `table` is not a `ColourTable` built for this film and α (or
    this `CarPaint` passed as `film`) and this map (concrete inputs only; traced ones are not
    checked), or if its arrays hold NaN/inf."""
    if not isinstance(table, ColourTable):
        raise ValueError(f"method='colour_table' reads a ColourTable (prefilter_colour), got "
                         f"{type(table).__name__}")
    for name in ("colour", "view", "brightness", "albedo"):
        a = getattr(table, name)
        if V.is_concrete(a) and not np.all(np.isfinite(np.asarray(a))):
            raise ValueError(f"ColourTable.{name} holds NaN or inf")
    if isinstance(film, CarPaint):
        if table.material[:1] != ("paint",):
            raise ValueError("the ColourTable was built for a film, not a car paint")
        if (all(V.is_concrete(x) for x in film)
                and _paint_fingerprint(film) != table.material):
            raise ValueError("the ColourTable was built for another material (car paint)")
    elif film is not None:
        leaves = (*film, alpha)
        if all(V.is_concrete(x) for x in leaves) and table.material[:1] == ("film",):
            want = np.asarray(table.material[1:], np.float64)
            for i, (name, x) in enumerate(zip(Film._fields + ("alpha",), leaves)):
                v = np.asarray(x, np.float64)
                if not np.allclose(v, want[i], rtol=1e-9, atol=1e-12):
                    raise ValueError(
                        f"the ColourTable was built for another material: {name} = "
                        f"{want[i]:.6g} in the table, got {v.ravel()[:3]}")
        elif table.material[:1] != ("film",):
            raise ValueError("the ColourTable was built for a car paint, not a film")
    if envmap is not None and map_fingerprint(envmap) != table.envmap:
        raise ValueError("the ColourTable was built under another environment map")


# ----------------------------------------------------------------------------- geometry
def view_nodes(n_view: int) -> np.ndarray:
    """u = √cos θ_o = (i + 1)/n, i < n: normal view is a node, grazing is clamped to the
    first node θ_o = arccos(1/n²) (host float64)."""
    return (np.arange(n_view) + 1.0) / n_view


def configurations(omega_r, cos_o, n_azimuth: int):
    """(n, ω_o) with reflection direction ω_r, ⟨n, ω_o⟩ = cos θ_o and n at azimuth ψ round
    ω_r: n = cos θ_o ω_r + sin θ_o (cos ψ t + sin ψ b), ω_o = 2 cos θ_o n − ω_r.
    omega_r (M, 3), cos_o (V,) → (M, V, A, 3) each."""
    t, b = _local_frame(omega_r)
    psi = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
    co = jnp.asarray(cos_o, omega_r.dtype)[None, :, None, None]
    so = jnp.sqrt(1 - co * co)
    cp = jnp.asarray(np.cos(psi), omega_r.dtype)[None, None, :, None]
    sp = jnp.asarray(np.sin(psi), omega_r.dtype)[None, None, :, None]
    r = omega_r[:, None, None, :]
    n = co * r + so * (cp * t[:, None, None, :] + sp * b[:, None, None, :])
    return n, 2 * co * n - r


# ----------------------------------------------------------------------------- the 3D table
def _film_point(material, n, wo, dirs):
    """Film on GGX: f_b⟨n,ω_i⟩ = ρ̃⟨n,ω_i⟩ (chunk, N), colour R_jk(⟨h,ω_i⟩) (chunk, N, J, K)."""
    alpha, r_table = material
    f, c = lobe_cos_weight(dirs, n, wo, alpha)
    r = interp_table(r_table, c)
    return f, r.reshape(r.shape[:-1] + (-1, 3))


def _paint_point(paint, n, wo, dirs):
    """Car paint: f_b⟨n,ω_i⟩ (the brightness through the coat, `carpaint.paint_brightness`)
    and the colour χ_j (`carpaint.paint_colour`) (chunk, N, J): diagonal in the channels."""
    ci = jnp.clip(jnp.sum(dirs * n, -1), 0.0, 1.0)
    fb, col = brightness_and_colour(paint, dirs, wo, n)
    return fb * ci, col


@functools.partial(jax.jit, static_argnames=("point", "chunk"))
def _config_sums(point, material, normal, view, dirs, weight, light, chunk):
    """Per configuration (n, ω_o): Σ_nodes f_b⟨n,ω_i⟩ w L_k (M, 3) and Σ f_b⟨n,ω_i⟩ w χ L
    (M, C) (C = J·K for a cross colour χ_jk, J for a diagonal χ_j), `chunk` at a time."""
    m = normal.shape[0]
    pad = -m % chunk
    nv = jnp.pad(jnp.stack([normal, view], 1), ((0, pad), (0, 0), (0, 0)), mode="edge")

    def one(cfg):  # cfg (chunk, 2, 3)
        f, col = point(material, cfg[:, 0, None], cfg[:, 1, None], dirs[None])
        fw = f * weight[None]  # (chunk, N)
        den = jnp.matmul(fw, light, precision=HIGHEST)  # (chunk, 3)
        if col.ndim == 4:  # cross: χ_jk L_k
            num = jnp.einsum("mn,mnjk->mjk", fw, col * light[None, :, None, :],
                             precision=HIGHEST)
        else:
            num = jnp.einsum("mn,mnj->mj", fw, col * light[None], precision=HIGHEST)
        return den, num.reshape(num.shape[0], -1)

    den, num = jax.lax.map(one, nv.reshape(-1, chunk, 2, 3))
    return den.reshape(-1, 3)[:m], num.reshape(-1, num.shape[-1])[:m]


def _ratio(num, den, num1, den1, cross):
    """C = num/den per light channel k, the white-light ratio where the light is black."""
    kk = den.shape[-1]
    shape = num.shape[:-1] + (-1, kk) if cross else num.shape
    nr, n1 = num.reshape(shape), num1.reshape(shape)
    d = den[..., None, :] if cross else den
    d1 = den1[..., None, :] if cross else den1
    ok = d > 0
    c = jnp.where(ok, nr / jnp.where(ok, d, 1.0), n1 / jnp.where(d1 > 0, d1, 1.0))
    return c.reshape(num.shape)


def _source_map(env: EnvMap, alpha: float, subdivisions: int | None):
    """Box-filter the map while its texels stay ≤ α/4 (as `prefilter`); nodes per texel."""
    src = level_source(env, alpha, 16)
    h, w = src.shape
    s = subdivisions or int(np.clip(np.ceil(2 * np.pi / h / alpha), 1, 4))
    return src, h, w, s


def _integrand(material, alpha: float, env: EnvMap, subdivisions, observer, n_cos, dt):
    """(point function, its material data, node directions, weights, node radiance): what
    `_config_sums` integrates for a `Film` (its R_jk table at `alpha`) or a `CarPaint`."""
    src, sh, sw, s = _source_map(env, alpha, subdivisions)
    d, wgt, idx = texel_nodes(sh, sw, s)
    light = jnp.asarray(np.asarray(src.radiance, np.float64).reshape(-1, 3)[idx], dt)
    if isinstance(material, CarPaint):
        point, mat = _paint_point, CarPaint(*(jnp.asarray(x, dt) for x in material))
    else:
        film = jax.tree.map(lambda x: jnp.asarray(x, dt), material)
        r_tab = reflectance_table(film, cross_band_name(observer), n_cos,
                         choose_arithmetic(film, "auto"), dt)
        point, mat = _film_point, (jnp.asarray(alpha, dt), r_tab)
    return point, mat, jnp.asarray(d, dt), jnp.asarray(wgt, dt), light


def decompose(full, rank: int | None):
    """Per channel the truncated SVD of the (h·w) × n_view matrix: U·S (h, w, r, C) and
    V (n_view, r, C); rank None or ≥ n_view keeps every term (exact)."""
    full = np.asarray(full, np.float64)
    h, w, nv, ch = full.shape
    r = nv if rank is None else min(int(rank), nv)
    us = np.zeros((h * w, r, ch))
    vs = np.zeros((nv, r, ch))
    for c in range(ch):
        u, s, vt = np.linalg.svd(full[..., c].reshape(h * w, nv), full_matrices=False)
        us[:, :, c] = u[:, :r] * s[None, :r]
        vs[:, :, c] = vt[:r].T
    return us.reshape(h, w, r, ch), vs


def decomposition_error(table: ColourTable) -> float:
    """max |C_full − Σ_r U_r V_r| over the table's nodes: the decomposition's own error."""
    approx = np.einsum("hwrc,vrc->hwvc", np.asarray(table.colour), np.asarray(table.view))
    return float(np.abs(approx - np.asarray(table.full)).max())


def prefilter_colour(envmap, material, alpha=None, *, observer: str = DEFAULT_OBSERVER,
                     resolution: tuple[int, int] = (16, 32), n_view: int = 8,
                     n_azimuth: int = 8, rank: int | None = 1, subdivisions: int | None = None,
                     n_cos: int = 512, brightness_resolution: tuple[int, int] = (64, 128),
                     chunk: int = 64, dtype=None) -> ColourTable:
    """The K&K 2022 colour table of one material under one map (module docstring; SPEC §11).

    Args:
        envmap: `EnvMap`, path, shipped name or (H, W, 3) array.
        material: a `Film` (scalar fields) with its GGX `alpha`, or a `carpaint.CarPaint`
            (its brightness: the GGX lobes, the Lambert term and the coat's mirror; its
            colour χ_j(θ_h, θ_d) per channel).
        alpha: the film's GGX roughness α ∈ (0, 1] (required for a `Film`; None for a paint).
        observer: colour bands J of a film (the table holds the cross bands R_jk, J·3
            channels); a paint's colour table is in the default bands already.
        resolution: (h, w = 2h) of the ω_r factor (K&K 2022: a low-resolution cubemap).
        n_view: nodes of u = √cos θ_o (the θ_o factor), `view_nodes`.
        n_azimuth: ψ nodes of the marginalisation.
        rank: terms of the decomposition (1: K&K 2022's separable form; None: all).
        subdivisions: s × s nodes per texel (None: ⌈2 (π/H)/α⌉ in [1, 4], α the narrowest).
        n_cos: nodes of a film's exact R_jk(c) table.
        brightness_resolution: (h, w) of the prefiltered brightness maps.
        chunk: configurations integrated together (memory ≈ chunk × nodes × C floats).
        dtype: of the stored tables (default: float64 where enabled; the build runs in it).
    Raises:
        ValueError: a non-scalar film, a bad α, a `Film` without α or a paint with one,
            resolutions that are not (h, 2h), counts below their minimum.
    """
    V.check_choice("observer", observer, OBSERVERS)
    paint = isinstance(material, CarPaint)
    if paint:
        check_paint(material)
        if alpha is not None:
            raise ValueError("a CarPaint carries its own lobe widths: pass alpha=None")
        if observer != DEFAULT_OBSERVER:
            raise ValueError("a CarPaint's colour table is in the default bands: leave "
                             "observer at its default")
        key = _paint_fingerprint(material)
        alphas = [float(x) for x in np.asarray(material.lobe_alpha, np.float64)]
        a_min = min(alphas)
    elif isinstance(material, Film):
        if alpha is None:
            raise ValueError("alpha is required with a Film (the GGX roughness of the table)")
        V.check_film(material)
        V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
        key = _film_fingerprint(material, alpha)
        a_min = float(alpha)
    else:
        raise ValueError(f"prefilter_colour takes a Film (with alpha) or a CarPaint, got "
                         f"{type(material).__name__}")
    h, w = resolution
    hb, wb = brightness_resolution
    for name, (a, b) in (("resolution", resolution),
                         ("brightness_resolution", brightness_resolution)):
        if not (isinstance(a, int) and isinstance(b, int) and a >= 2 and b == 2 * a):
            raise ValueError(f"{name} must be (h, 2h) with h ≥ 2, got {(a, b)}")
    for name, v, lo in (("n_view", n_view, 2), ("n_azimuth", n_azimuth, 1),
                        ("n_cos", n_cos, 2), ("chunk", chunk, 1)):
        V.check_int(name, v, lo)
    if rank is not None:
        V.check_int("rank", rank, 1)
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    if env.shape[0] % hb or env.shape[1] % wb:
        raise ValueError(f"brightness_resolution {brightness_resolution} must divide the "
                         f"map's {env.shape}")
    start = time.perf_counter()
    f64 = jnp.result_type(float)  # float64 where enabled (the reference precision)
    point, mat, d, wgt, light = _integrand(material if paint else _fingerprint_film(key), a_min,
                                           env, subdivisions, observer, n_cos, f64)
    omega_r = jnp.asarray(texel_centers(h, w).reshape(-1, 3), f64)
    u = view_nodes(n_view)
    n, wo = configurations(omega_r, u * u, n_azimuth)
    flat = lambda x: x.reshape(-1, 3)  # noqa: E731
    sums = [_config_sums(point, mat, flat(n), flat(wo), d, wgt, lt, chunk)
            for lt in (light, jnp.ones_like(light))]
    shape = (h, w, n_view, n_azimuth)
    (den, num), (den1, num1) = [tuple(x.reshape(shape + x.shape[-1:]).sum(3) for x in p)
                                for p in sums]
    full = np.asarray(_ratio(num, den, num1, den1, not paint))
    us, vs = decompose(full, rank)
    ua = np.linspace(0.0, 1.0, N_ALBEDO)
    if paint:
        terms, levels = _paint_brightness(material, env, hb, wb, f64, alphas)
        alb = np.concatenate([np.asarray(lobe_albedo(mat, ua**2)),
                              np.asarray(coat_reflectance(mat, ua**2))[:, None]], -1)
    else:
        terms, levels = ("specular",), [_ggx_level(env, a_min, hb, wb, f64)]
        alb = np.asarray(albedo(np.arccos(ua**2), a_min))[:, None]
        alphas = [a_min]
    dt = dtype or f64
    out = ColourTable(jnp.asarray(us, dt), jnp.asarray(vs, dt), jnp.asarray(full, dt),
                      jnp.asarray(np.stack([np.asarray(x) for x in levels]), dt),
                      jnp.asarray(alb, dt), terms=terms,
                      alphas=tuple(alphas) + (0.0,) * (len(terms) - len(alphas)),
                      material=key, envmap=map_fingerprint(env), observer=observer,
                      cross=not paint)
    jax.block_until_ready(out.full)
    return dataclasses.replace(out, build_seconds=round(time.perf_counter() - start, 3))


def _ggx_level(env: EnvMap, alpha: float, hb: int, wb: int, dt):
    """P(ω_r, α) (hb, wb, 3): the map prefiltered at exactly α (`prefilter.filter_level`),
    its input box-filtered while the texels stay ≤ α/4."""
    p, _ = filter_level(alpha, level_source(env, alpha, hb).radiance, hb, wb)
    return jnp.asarray(p, dt)


def _paint_brightness(paint: CarPaint, env: EnvMap, hb: int, wb: int, dt, alphas):
    """A paint's brightness terms: each GGX lobe prefiltered at its width outside the coat
    (min(1, η_c α_l): refraction widens a lobe by η_c near normal view, dθ = η_c dθ'), the
    Lambert term's cosine-filtered map E(n)/π, the coat's mirror (the map box-filtered)."""
    eta = float(np.asarray(paint.coat_ior))
    levels = [_ggx_level(env, min(1.0, eta * a), hb, wb, dt) for a in alphas]
    src = downsample(env, max(1, env.shape[0] // max(hb, 32)))
    bh, bw = src.shape
    dirs = jnp.asarray(texel_centers(bh, bw).reshape(-1, 3), dt)
    om = jnp.asarray(texel_solid_angles(bh, bw).reshape(-1), dt)
    rad = jnp.asarray(np.asarray(src.radiance), dt).reshape(-1, 3)
    out_dirs = jnp.asarray(texel_centers(hb, wb).reshape(-1, 3), dt)
    cos = jnp.clip(jnp.matmul(out_dirs, dirs.T, precision=HIGHEST), 0.0, None)
    levels.append(jnp.matmul(cos * om[None], rad, precision=HIGHEST).reshape(hb, wb, 3)
                  / np.pi)
    levels.append(downsample(env, env.shape[0] // hb).radiance)
    return ("specular",) * len(alphas) + ("diffuse", "coat"), levels


# ----------------------------------------------------------------------------- shading
def _view_lerp(n_view: int, u):
    t = jnp.clip(u * n_view - 1.0, 0.0, n_view - 1.0)
    i0 = jnp.clip(jnp.floor(t), 0, max(n_view - 2, 0))
    return i0.astype(jnp.int32), (t - i0)[..., None]


def table_colour(table: ColourTable, omega_r, cos_o, rank: int | None = 0):
    """C (..., C) at ω_r and cos θ_o: the decomposed table (rank 0 = all stored terms,
    r ≤ stored: the first r) or, with rank None, the 3D table (trilinear)."""
    u = jnp.sqrt(jnp.clip(cos_o, 0.0, 1.0))
    nv = table.view.shape[0]
    i0, f = _view_lerp(nv, u)
    if rank is None:
        lo = lookup_bilinear(jnp.moveaxis(table.full, 2, 0), omega_r, i0)
        hi = lookup_bilinear(jnp.moveaxis(table.full, 2, 0), omega_r, jnp.minimum(i0 + 1, nv - 1))
        return lo * (1 - f) + hi * f
    r = table.rank if rank == 0 else min(int(rank), table.rank)
    uf = lookup_bilinear(table.colour[..., :r, :], omega_r)  # (..., r, C)
    vf = table.view[i0, :r] * (1 - f[..., None]) + table.view[jnp.minimum(i0 + 1, nv - 1), :r] \
        * f[..., None]
    return jnp.sum(uf * vf, axis=-2)


def _albedo_lookup(table, cos_o):
    """Each term's albedo (..., B), linear in √cos θ_o."""
    n = table.albedo.shape[0]
    t = jnp.sqrt(jnp.clip(cos_o, 0.0, 1.0)) * (n - 1)
    i0 = jnp.clip(jnp.floor(t), 0, n - 2)
    f = (t - i0)[..., None]
    i0 = i0.astype(jnp.int32)
    return table.albedo[i0] * (1 - f) + table.albedo[i0 + 1] * f


def _brightness(table, normal, view, omega_r, cos_o, brightness):
    """(coloured (…, 3), uncoloured (…, 3)): Σ_b A_b(θ_o) P_b over the table's brightness
    terms, the coat apart. `brightness` None: the split sum, P_b from the table (a lobe at
    ω_r, the Lambert term at n, the coat at ω_r); a `PrefilteredEnvMap` of the same map: a
    film's lobe reads the improved model's bins instead (`prefilter.bin_radiance`)."""
    a = _albedo_lookup(table, cos_o)
    coloured = jnp.zeros(cos_o.shape + (3,), cos_o.dtype)
    plain = jnp.zeros_like(coloured)
    for b, term in enumerate(table.terms):
        if brightness is not None:
            if table.terms != ("specular",):
                raise ValueError("brightness=PrefilteredEnvMap applies to a film's table "
                                 "(one GGX lobe), not to a car paint's")
            bins = bin_table(dtype=cos_o.dtype)
            p = jnp.mean(bin_radiance(brightness, bins, normal, view, cos_o,
                                      jnp.asarray(table.alphas[b], cos_o.dtype)), axis=-2)
        else:
            p = lookup_bilinear(table.brightness[b], normal if term == "diffuse" else omega_r)
        if term == "coat":
            plain = plain + a[..., b, None] * p
        else:
            coloured = coloured + a[..., b, None] * p
    return coloured, plain


def _shade(table, c, coloured, plain, up):
    if table.cross:
        out = jnp.sum(c.reshape(c.shape[:-1] + (-1, 3)) * coloured[..., None, :], -1)
    else:
        out = c * coloured
    return jnp.where(up[..., None], out + plain, 0.0)


def _geometry(normal, view, dtype):
    normal, view = (jnp.asarray(x, dtype) for x in (normal, view))
    shape = jnp.broadcast_shapes(normal.shape, view.shape)
    normal, view = (jnp.broadcast_to(x, shape) for x in (normal, view))
    cos_o = jnp.sum(normal * view, -1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    return normal, view, up, co, 2 * co[..., None] * normal - view


def colour_table_radiance(table: ColourTable, normal, view, *, rank: int | None = 0,
                          brightness=None) -> Array:
    """L_j (..., J) = Σ_k C_jk(ω_r, θ_o) B_k + coat (module docstring); 0 where ⟨n,ω_o⟩ ≤ 0.

    B_k = Σ_b A_b(θ_o) P_b,k: the split-sum brightness of the material's terms (a film: one
    GGX lobe; a paint: its lobes, its Lambert term read at n; the coat's mirror F(θ_o)
    P(ω_r) is added uncoloured).
    rank: 0 = the stored decomposition, r = its first r terms, None = the 3D table.
    brightness: None = the split sum of K&K 2022; a `PrefilteredEnvMap` of the same map
        (films only) = the improved model's per-bin reads averaged, a brightness that
        follows the lobe's off-specular shift and spread (docs/improved.md)."""
    dtype = jnp.result_type(jnp.asarray(normal), jnp.asarray(view), table.colour)
    normal, view, up, co, refl = _geometry(normal, view, dtype)
    table = jax.tree.map(lambda x: jnp.asarray(x, dtype), table)
    c = table_colour(table, refl, co, rank)
    return _shade(table, c, *_brightness(table, normal, view, refl, co, brightness), up)


# ----------------------------------------------------------------------------- the ceiling
def exact_colour_radiance(material, alpha, normal, view, envmap, table: ColourTable, *,
                          observer: str = DEFAULT_OBSERVER, subdivisions: int | None = None,
                          n_cos: int = 512, chunk: int = 64, brightness=None) -> Array:
    """The method's ceiling: the brightness of `table` times the colour computed exactly at
    each shading point, C = ∫ f_b⟨n,ω_i⟩ χ L_k / ∫ f_b⟨n,ω_i⟩ L_k (no table, no
    marginalisation): what a colour table would give if its colour were exact.
    material: the `Film` (with `alpha`) or `CarPaint` (alpha None) of `table`;
    normal, view (N, 3) unit vectors → (N, J); `brightness` as `colour_table_radiance`."""
    check_colour_table(table, material, alpha, envmap)
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    f64 = jnp.result_type(float)
    paint = isinstance(material, CarPaint)
    a_min = (float(np.min(np.asarray(material.lobe_alpha))) if paint else float(alpha))
    point, mat, d, wgt, light = _integrand(material, a_min, env, subdivisions, observer,
                                           n_cos, f64)
    normal, view, up, co, refl = _geometry(jnp.asarray(normal).reshape(-1, 3),
                                           jnp.asarray(view).reshape(-1, 3), f64)
    sums = [_config_sums(point, mat, normal, jnp.where(up[:, None], view, normal), d, wgt,
                         lt, chunk)
            for lt in (light, jnp.ones_like(light))]
    (den, num), (den1, num1) = sums
    c = _ratio(num, den, num1, den1, not paint)
    table = jax.tree.map(lambda x: jnp.asarray(x, f64), table)
    return _shade(table, c, *_brightness(table, normal, view, refl, co, brightness), up)
