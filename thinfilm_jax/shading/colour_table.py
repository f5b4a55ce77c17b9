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

The table is stored as K&K 2022 do, decomposed into a function of ω_r (their low-resolution
cubemap; here an equirect map of the same role) times a function of θ_o (their 2D array:
θ_o × channel), per channel the best rank-1 approximation (truncated SVD); `rank` r > 1 keeps
r terms, r = full reproduces the 3D table (also kept, `ColourTable.full`, for `rank=None`).

Quadrature of the table (host, once per material and map): every texel of the map (box-
filtered with `envmap.downsample` while its texels stay ≤ α/4, as `prefilter`), s × s
Gauss–Legendre nodes per texel (`subdivisions`), `n_azimuth` uniform ψ nodes (the integrand
is periodic in ψ: the trapezoid rule converges geometrically), view nodes u = √cos θ_o = 1/n, 2/n, …, 1
(n = `n_view`) (the grid of `prefilter.albedo_table`), R_jk(c) exact
spectral on `n_cos` nodes of c, interpolated. A(θ_o, α) is the exact `microfacet.albedo` at
the material's α on 64 nodes of √cos θ_o; P(ω_r, α) is the map prefiltered at exactly α
(`prefilter._filter_level`). Measured errors (tests/shading/test_colour_table.py): the
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

from ..brdf.microfacet import albedo
from ..core import _validate as V
from ..core.film import Film
from ..optics.airy import choose_arithmetic
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from ..spectral.uplift import cross_band_name
from .envmap import (EnvMap, downsample, load_envmap, lookup_bilinear, luminance_weights,
                     texel_centers, texel_solid_angles)
from .ibl_reference import _interp, _local_frame, _lobe_cos_weight, _r_table, texel_nodes
from ..realtime.improved import bin_table
from .prefilter import _filter_level, bin_radiance

__all__ = ["ColourTable", "prefilter_colour", "colour_table_radiance", "check_colour_table",
           "exact_colour_radiance", "decomposition_error", "map_fingerprint"]

HIGHEST = jax.lax.Precision.HIGHEST
N_ALBEDO = 64  # nodes of A(θ_o) in √cos θ_o


def _dataclass(cls, data, meta):
    cls = dataclasses.dataclass(frozen=True)(cls)
    return jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)


class ColourTable:
    """The K&K 2022 tables of one material under one map (a pytree; arrays are leaves).

    colour: (h, w, r, C) the ω_r factors (equirect, texel centres), C channels
        (J·K = 9 cross bands R_jk of a film; J for a diagonal colour).
    view: (n_view, r, C) the θ_o factors at u = √cos θ_o = (i + 1)/n_view.
    full: (h, w, n_view, C) the 3D table C(ω_r, θ_o) before the decomposition.
    brightness: (hb, wb, 3) P_k(ω_r, α): the map prefiltered at the material's α.
    albedo: (N_ALBEDO,) A(θ_o, α) on a uniform grid of √cos θ_o.
    Static: `material` (fingerprint of the concrete material the table was built for),
    `envmap` (fingerprint of the map), `observer`, `cross` (C = J·K), `build_seconds`.
    """

    colour: Array
    view: Array
    full: Array
    brightness: Array
    albedo: Array
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


ColourTable = _dataclass(ColourTable, ["colour", "view", "full", "brightness", "albedo"],
                         ["material", "envmap", "observer", "cross", "build_seconds"])


# ----------------------------------------------------------------------------- fingerprints
def map_fingerprint(envmap) -> str:
    """A short hash of a map's radiance (what a `ColourTable` was built under)."""
    a = np.ascontiguousarray(np.asarray(getattr(envmap, "radiance", envmap), np.float64))
    return hashlib.sha1(a.tobytes() + str(a.shape).encode()).hexdigest()[:16]


def _film_fingerprint(film: Film, alpha) -> tuple:
    vals = [np.asarray(x, np.float64) for x in (*film, alpha)]
    if any(v.size != 1 for v in vals):
        raise ValueError("prefilter_colour builds the table of one homogeneous material: "
                         "film fields and alpha must be scalars, got shapes "
                         f"{[v.shape for v in vals]}")
    return ("film",) + tuple(float(v.reshape(())) for v in vals)


def check_colour_table(table, film: Film | None = None, alpha=None, envmap=None) -> None:
    """Raise a `ValueError` if `table` is not a `ColourTable` built for this film, α and map
    (concrete inputs only; traced ones are not checked), or if its arrays hold NaN/inf."""
    if not isinstance(table, ColourTable):
        raise ValueError(f"method='colour_table' reads a ColourTable (prefilter_colour), got "
                         f"{type(table).__name__}")
    for name in ("colour", "view", "brightness", "albedo"):
        a = getattr(table, name)
        if V.is_concrete(a) and not np.all(np.isfinite(np.asarray(a))):
            raise ValueError(f"ColourTable.{name} holds NaN or inf")
    if film is not None:
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
@functools.partial(jax.jit, static_argnames=("chunk",))
def _film_sums(normal, view, alpha, dirs, weight, light, r_table, chunk):
    """Σ_nodes f_b⟨n,ω_i⟩ w L_k (M, 3) and Σ f_b⟨n,ω_i⟩ w R_jk(c) L_k (M, J·K) per
    configuration, `chunk` configurations at a time."""
    m = normal.shape[0]
    pad = -m % chunk
    nv = jnp.pad(jnp.stack([normal, view], 1), ((0, pad), (0, 0), (0, 0)), mode="edge")

    def one(cfg):  # cfg (chunk, 2, 3)
        f, c = _lobe_cos_weight(dirs[None], cfg[:, 0, None], cfg[:, 1, None], alpha)
        fw = f * weight[None]  # (chunk, N)
        den = jnp.matmul(fw, light, precision=HIGHEST)  # (chunk, 3)
        r = _interp(r_table, c)  # (chunk, N, J·K)
        kk = light.shape[-1]
        rk = r.reshape(r.shape[:-1] + (-1, kk)) * light[None, :, None, :]
        num = jnp.einsum("mn,mnjk->mjk", fw, rk, precision=HIGHEST)
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
    src = env
    while (src.shape[0] // 2 >= 16 and src.shape[0] % 2 == 0
           and np.pi / (src.shape[0] // 2) <= alpha / 4):
        src = downsample(src, 2)
    h, w = src.shape
    s = subdivisions or int(np.clip(np.ceil(2 * np.pi / h / alpha), 1, 4))
    return src, h, w, s


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
        material: a `Film` (scalar fields) with its GGX `alpha` ∈ (0, 1].
        alpha: the film's GGX roughness (required for a `Film`).
        observer: colour bands J (the table holds the cross bands R_jk, J·3 channels).
        resolution: (h, w = 2h) of the ω_r factor (K&K 2022: a low-resolution cubemap).
        n_view: nodes of u = √cos θ_o (the θ_o factor), `view_nodes`.
        n_azimuth: ψ nodes of the marginalisation.
        rank: terms of the decomposition (1: K&K 2022's separable form; None: all).
        subdivisions: s × s nodes per texel (None: ⌈2 (π/H)/α⌉ in [1, 4]).
        n_cos: nodes of the exact R_jk(c) table.
        brightness_resolution: (h, w) of the prefiltered brightness P(ω_r, α).
        chunk: configurations integrated together (memory ≈ chunk × nodes × 9 floats).
        dtype: of the stored tables (default float64; the build runs in float64).
    """
    V.check_choice("observer", observer, OBSERVERS)
    if not isinstance(material, Film):
        raise ValueError(f"prefilter_colour takes a Film (with alpha) here, got "
                         f"{type(material).__name__}")
    if alpha is None:
        raise ValueError("alpha is required with a Film (the GGX roughness of the table)")
    V.check_film(material)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    key = _film_fingerprint(material, alpha)
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
    start = time.perf_counter()
    a = float(alpha)
    f64 = jnp.result_type(float)  # float64 where enabled (the reference precision)
    src, sh, sw, s = _source_map(env, a, subdivisions)
    d, wgt, idx = texel_nodes(sh, sw, s)
    rad = np.asarray(src.radiance, np.float64).reshape(-1, 3)
    dirs, weight = jnp.asarray(d, f64), jnp.asarray(wgt, f64)
    light = jnp.asarray(rad[idx], f64)
    film = Film(*(jnp.asarray(x, f64) for x in key[1:6]))
    arithmetic = choose_arithmetic(film, "auto")
    r_tab = _r_table(film, cross_band_name(observer), n_cos, arithmetic, f64)
    omega_r = jnp.asarray(texel_centers(h, w).reshape(-1, 3), f64)
    u = view_nodes(n_view)
    n, wo = configurations(omega_r, u * u, n_azimuth)
    flat = lambda x: x.reshape(-1, 3)  # noqa: E731
    sums = [_film_sums(flat(n), flat(wo), jnp.asarray(a, f64), dirs, weight, lt, r_tab, chunk)
            for lt in (light, jnp.ones_like(light))]
    shape = (h, w, n_view, n_azimuth)
    (den, num), (den1, num1) = [tuple(x.reshape(shape + x.shape[-1:]).sum(3) for x in p)
                                for p in sums]
    full = np.asarray(_ratio(num, den, num1, den1, True))
    us, vs = decompose(full, rank)
    # the brightness: P(ω_r, α) at exactly α, and A(θ_o, α)
    bsrc = env
    while (bsrc.shape[0] // 2 >= hb and bsrc.shape[0] % 2 == 0
           and np.pi / (bsrc.shape[0] // 2) <= a / 4):
        bsrc = downsample(bsrc, 2)
    bh, bw = bsrc.shape
    if bh % hb or bw % wb:
        raise ValueError(f"brightness_resolution {brightness_resolution} must divide the "
                         f"map's {env.shape}")
    p, _ = _filter_level(jnp.asarray(a, f64),
                         jnp.asarray(np.asarray(bsrc.radiance), f64).reshape(-1, 3),
                         jnp.asarray(texel_centers(bh, bw).reshape(-1, 3), f64),
                         jnp.asarray(texel_solid_angles(bh, bw).reshape(-1), f64),
                         jnp.asarray(texel_centers(hb, wb), f64),
                         jnp.asarray(luminance_weights(), f64), False)
    ua = np.linspace(0.0, 1.0, N_ALBEDO)
    alb = np.asarray(albedo(np.arccos(ua**2), a))
    dt = dtype or f64
    out = ColourTable(jnp.asarray(us, dt), jnp.asarray(vs, dt), jnp.asarray(full, dt),
                      jnp.asarray(p, dt), jnp.asarray(alb, dt), material=key,
                      envmap=map_fingerprint(env), observer=observer, cross=True,
                      build_seconds=0.0)
    jax.block_until_ready(out.full)
    return dataclasses.replace(out, build_seconds=round(time.perf_counter() - start, 3))


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
    n = table.albedo.shape[0]
    t = jnp.sqrt(jnp.clip(cos_o, 0.0, 1.0)) * (n - 1)
    i0 = jnp.clip(jnp.floor(t), 0, n - 2)
    f = t - i0
    i0 = i0.astype(jnp.int32)
    return table.albedo[i0] * (1 - f) + table.albedo[i0 + 1] * f


def _brightness(table, normal, view, omega_r, cos_o, alpha, brightness):
    """(A(θ_o) (…,), P_k (…, 3)): the brightness of the material. `brightness` None: the
    split sum, P_k(ω_r, α) from the table; a `PrefilteredEnvMap` of the same map: the mean of
    the improved model's per-bin reads (`prefilter.bin_radiance`), A from the table."""
    a = _albedo_lookup(table, cos_o)
    if brightness is None:
        return a, lookup_bilinear(table.brightness, omega_r)
    bins = bin_table(dtype=cos_o.dtype)
    return a, jnp.mean(bin_radiance(brightness, bins, normal, view, cos_o,
                                    jnp.asarray(alpha, cos_o.dtype)), axis=-2)


def colour_table_radiance(table: ColourTable, normal, view, *, rank: int | None = 0,
                          brightness=None) -> Array:
    """L_j (..., J) = A(θ_o) Σ_k C_jk(ω_r, θ_o) P_k (module docstring); 0 where ⟨n, ω_o⟩ ≤ 0.

    rank: 0 = the stored decomposition, r = its first r terms, None = the 3D table.
    brightness: None = the split sum P_k(ω_r, α) of K&K 2022; a `PrefilteredEnvMap` of the
        same map = the improved model's per-bin reads averaged (a brightness that follows
        the lobe's off-specular shift and spread; docs/improved.md)."""
    normal = jnp.asarray(normal)
    view = jnp.asarray(view)
    dtype = jnp.result_type(normal, view, table.colour)
    normal, view = (jnp.asarray(x, dtype) for x in (normal, view))
    shape = jnp.broadcast_shapes(normal.shape, view.shape)
    normal, view = (jnp.broadcast_to(x, shape) for x in (normal, view))
    cos_o = jnp.sum(normal * view, -1)
    up = cos_o > 0
    co = jnp.where(up, cos_o, 1.0)
    refl = 2 * co[..., None] * normal - view
    table = jax.tree.map(lambda x: jnp.asarray(x, dtype), table)
    c = table_colour(table, refl, co, rank)
    a, p = _brightness(table, normal, view, refl, co, table.material[-1], brightness)
    if table.cross:
        out = jnp.sum(c.reshape(c.shape[:-1] + (-1, 3)) * p[..., None, :], -1)
    else:
        out = c * p
    return jnp.where(up[..., None], a[..., None] * out, 0.0)


# ----------------------------------------------------------------------------- the ceiling
def exact_colour_radiance(film: Film, alpha, normal, view, envmap, table: ColourTable, *,
                          observer: str = DEFAULT_OBSERVER, subdivisions: int | None = None,
                          n_cos: int = 512, chunk: int = 64, brightness=None) -> Array:
    """The method's ceiling: the split-sum brightness of `table` times the colour computed
    exactly at each shading point, C_jk = ∫ f_b⟨n,ω_i⟩ R_jk L_k / ∫ f_b⟨n,ω_i⟩ L_k (no table,
    no marginalisation): what the colour table would give if its colour were exact.
    normal, view (N, 3) unit vectors → (N, J); `brightness` as `colour_table_radiance`."""
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    a = float(alpha)
    f64 = jnp.result_type(float)  # float64 where enabled (the reference precision)
    src, sh, sw, s = _source_map(env, a, subdivisions)
    d, wgt, idx = texel_nodes(sh, sw, s)
    light = jnp.asarray(np.asarray(src.radiance, np.float64).reshape(-1, 3)[idx], f64)
    film = Film(*(jnp.asarray(x, f64) for x in film))
    r_tab = _r_table(film, cross_band_name(observer), n_cos, choose_arithmetic(film, "auto"),
                     f64)
    normal = jnp.asarray(normal, f64).reshape(-1, 3)
    view = jnp.asarray(view, f64).reshape(-1, 3)
    cos_o = jnp.sum(normal * view, -1)
    up = cos_o > 0
    sums = [_film_sums(normal, jnp.where(up[:, None], view, normal), jnp.asarray(a, f64),
                       jnp.asarray(d, f64), jnp.asarray(wgt, f64), lt, r_tab, chunk)
            for lt in (light, jnp.ones_like(light))]
    (den, num), (den1, num1) = sums
    c = _ratio(num, den, num1, den1, True)
    co = jnp.where(up, cos_o, 1.0)
    refl = 2 * co[:, None] * normal - view
    aa, p = _brightness(table, normal, view, refl, co, a, brightness)
    out = jnp.sum(c.reshape(-1, get_observer(observer).n_bands, 3) * p[:, None, :], -1)
    return jnp.where(up[:, None], aa[:, None] * out, 0.0)
