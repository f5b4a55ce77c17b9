r"""The exact paths of `envmap_radiance` (SPEC §9): the deterministic `reference` and `mc`.

$$ L_j(n, \omega_o) = \sum_k \sum_{t} c_{k,t} \int_{t} \tilde\rho(\omega_i, \omega_o)
   \langle n,\omega_i\rangle R_{jk}(\langle h,\omega_i\rangle)\, d\omega_i $$

over the texels t of the piecewise-constant map (radiance c_t, SPEC §9).

Reference, adaptive (the default; `ibl_adaptive`): one node per 4 × 4-texel block from a
second-order Taylor rule against the light's exact moments, the texel interpolant in the K
blocks it scores worst, s × s Gauss sub-nodes in the K₃ texels it scores worst among theirs;
within 1.9e-4 of the exhaustive rule at twelve α from 0.03 to 1 on the shipped maps, at
7.2k node evaluations a point against 131k at α = 0.25.

The exhaustive rule (every texel with s × s nodes, the reference before the adaptive one) stays
reachable as `exact_radiance(..., exhaustive=True)`: tests/shading/test_ibl_reference.py
compares the two and `benchmarks.ibl_bench` times both in one run.

Points are shaded in `jax.lax.map` steps (the exhaustive rule: one point per step, its
intermediates, H W s² × 9 doubles, near the cache; the adaptive rule: up to 16 points per
step where a point has at most 8192 nodes, else 4, shared evenly over the steps,
`batch_size`, which amortises the per-operation cost of its small gathers); one film shared
by every point builds its R_jk table once, and the adaptive rule's per-map tables are kept
while the map lives.

Grazing views. Near θ_o = 90° the lobe in ω_i is about 2α cos θ_o wide, while s sizes the
nodes by α alone: where it is narrower than two node spacings π/(H s) neither rule is
converged (errors of 1e-2 and more at θ_o ≥ 88° with α ≤ 0.1; `_warn_unresolved_lobes`) and
the call warns with the number of such points; `mc` is unbiased there. (Nodes that follow
the lobe, GGX visible normals at Gauss nodes with the map's texel at each, fix a white map
but converge slowly across texel edges: docs/studies/ibl.md.)

Large maps. The cost per point grows with H·W (the block rule's H W / b² nodes, the
exhaustive rule's H W s²). `reference_radiance` (and so `envmap_radiance`)
resamples a map taller than `max_height` (default 256) with the solid-angle-exact
`envmap.downsample` by the largest power-of-two factor f that keeps the texel size
f·π/H ≤ α_min/8 and H/f ≥ 128, and warns with the factor. Resampling replaces the radiance
inside each f × f block by its solid-angle mean; the error is ∫ ρ̃⟨n,ω⟩R (c − c̄): zero
where the lobe is linear across a block, first order in (block size / lobe width) times
the radiance contrast inside the block otherwise (measured in tests/shading/test_ibl_reference.py
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
import os
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.material import batch_shape
from ..core.methods import implementation
from ..spectral.spectra import get_observer
from .envmap import EnvMap, downsample, load_envmap, lookup_nearest
from .prefilter import PrefilteredEnvMap
from .ibl_adaptive import adaptive_radiance
from .ibl_integrand import (HIGHEST, _contract, interp_table, _local_frame, lobe_cos_weight, reflectance_table,
                            _vndf_sample, texel_nodes)
from ..core.material import expand_batch, first_point, point_split
from ..core.stack import Stack
from ..brdf.microfacet import smith_g1, smith_g2
from ..spectral.reflectance import spectral_bands
from ..spectral.uplift import cross_band_name

__all__ = [
    "auto_subdivisions",
    "resample_factor",
    "exact_radiance",
    "GrazingLobeWarning",
    "exact_stack_envmap",
]

MIN_HEIGHT = 128  # large maps are never resampled below the shipped maps' 128 rows


def auto_subdivisions(height: int, alpha) -> int:
    """s = ⌈8 (π/H) / α_min⌉ in [2, 16]: sub-cells an eighth of the narrowest lobe."""
    a = float(np.min(np.asarray(alpha))) if _concrete(alpha) else 0.05
    return int(np.clip(np.ceil(8 * np.pi / height / a), 2, 16))


def _concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def resample_factor(height: int, alpha_min: float, max_height: int | None) -> int:
    """Power-of-two downsampling factor of a map taller than `max_height` (module docstring)."""
    if max_height is None or height <= max_height:
        return 1
    f = 1
    while (height % (2 * f) == 0 and height // (2 * f) >= MIN_HEIGHT
           and 2 * f * np.pi / height <= alpha_min / 8):
        f *= 2
    return f


# ----------------------------------------------------------------------------- exhaustive, MC
@functools.partial(jax.jit, static_argnums=(6,))
def _exact_jit(film, alpha, normal, view, radiance, extra, cfg):
    """extra: (node directions, node weight × radiance) for the exhaustive reference, a key
    for MC."""
    mc, observer, s, n_cos, cross, arithmetic, batch, one_film = cfg
    dtype = alpha.dtype
    obs = cross_band_name(observer) if cross else observer
    shape = alpha.shape
    mat, point = point_split(film, shape)
    flat = (mat, alpha.reshape(-1), normal.reshape(-1, 3), view.reshape(-1, 3))
    n_pts = flat[1].shape[0]
    if not mc:  # the exhaustive texel rule: extra = its nodes
        dirs, e = extra
        # one film for every shading point: its R_jk(cos θ₁) table is built once, not per point
        shared_table = (reflectance_table(point(first_point(mat)), obs, n_cos, arithmetic, dtype)
                        if one_film else None)
    else:
        keys = jax.random.split(extra, n_pts)

    def one(xs):
        f, a, n, wo = point(xs[0]), xs[1], xs[2], xs[3]
        if not mc:
            wgt, c = lobe_cos_weight(dirs, n, wo, a)  # (N,)
            table = shared_table if one_film else reflectance_table(f, obs, n_cos, arithmetic, dtype)
            r = interp_table(table, c)  # (N, J[·3])
            light = wgt[:, None] * e  # (N, 3)
        else:
            k = xs[4]
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
            r = spectral_bands(expand_batch(f), c, obs, arithmetic=arithmetic)
            light = wgt[:, None] * lookup_nearest(radiance, wi)
        return _contract(r, light, cross)

    xs = flat + ((keys,) if mc else ())
    out = jax.lax.map(one, xs, batch_size=batch)
    cos_o = jnp.sum(normal * view, -1)
    return jnp.where((cos_o > 0)[..., None], out.reshape(*shape, out.shape[-1]), 0.0)


def _batch(batch_size, n_pts, per_point):
    if batch_size is None:
        batch_size = max(1, int(2**19 // max(per_point, 1)))
    return int(max(1, min(batch_size, max(n_pts, 1))))


def texel_light(radiance, s: int, dtype):
    """The piecewise-constant map as point lights: the `texel_nodes` directions (N, 3) and
    each node's weight (sr) times its texel's radiance (N, 3), in `dtype` (the exact rule's
    light; N = H·W·s²)."""
    h, w = radiance.shape[:2]
    d, wt, idx = texel_nodes(h, w, s)
    return jnp.asarray(d, dtype), jnp.asarray(wt, dtype)[:, None] * radiance.reshape(-1, 3)[idx]


def exact_rule(method: str, radiance, alpha, n_pts: int, *, subdivisions, n_samples, key,
               batch_size, lobes: int = 1):
    """The light a material's exact map path integrates (`material_ibl`, `carpaint_ibl`):
    (monte_carlo, light, n_samples, batch). The `method` object says which rule: texel
    quadrature (light = `texel_light` with `subdivisions`, None: `auto_subdivisions` of
    ``alpha()``, a callable so that only this rule needs the lobe's width; n_samples 0) or
    Monte Carlo (light = the PRNG key, default key 0; `lobes` sampled lobes a point). The
    batch of shading points holds ≈ 2¹⁹ nodes or samples unless `batch_size` is given."""
    mc = implementation(method).monte_carlo
    if not mc:
        s = auto_subdivisions(radiance.shape[0], alpha()) if subdivisions is None \
            else V.check_int("subdivisions", subdivisions, 1)
        light = texel_light(radiance, s, radiance.dtype)
        per_point, n_samples = len(light[0]), 0
    else:
        n_samples = V.check_int("n_samples", n_samples, 2)
        light = jax.random.key(0) if key is None else key
        per_point = n_samples * lobes
    if batch_size is not None:
        batch_size = V.check_int("batch_size", batch_size, 1)
    return mc, light, n_samples, _batch(batch_size, n_pts, per_point)


# ----------------------------------------------------------------------------- entry points
def exact_radiance(film, alpha, normal, view, env: EnvMap, *, method, observer, cross_band,
                   arithmetic, one_film=False, subdivisions=None, n_cos=1024, n_samples=4096,
                   key=None, batch_size=None, exhaustive=False, return_estimate=False,
                   max_height: int | None = 256, refine=None):
    """`reference` / `mc` (`method`, whose object says which rule: ``monte_carlo``) of
    `envmap_radiance` on broadcast inputs (validated by the caller):
    film fields and alpha of one shape, normal and view (..., 3) of that shape. `one_film`:
    every point has the same film (its R_jk table is built once); also detected here for
    concrete fields whose entries are all equal. `refine`: (K, K₃) of the adaptive rule
    instead of `refine_counts` (all blocks and all texels: the exhaustive rule's value)."""
    dtype = alpha.dtype
    n_pts = int(np.prod(alpha.shape))
    one_film = bool(one_film) or (not isinstance(film, Stack)
                                  and all(_same(x) for x in jax.tree.leaves(film)))
    if implementation(method).monte_carlo:
        if not (isinstance(n_samples, int) and n_samples >= 1):
            raise ValueError(f"n_samples must be a positive int, got {n_samples!r}")
        key = jax.random.key(0) if key is None else key
        cfg = (True, observer, int(n_samples), 0, bool(cross_band), arithmetic,
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
            "max_height=None to integrate every texel", stacklevel=_user_stacklevel())
        env = downsample(env, f)
        h = env.shape[0]
    if subdivisions is None:
        subdivisions = auto_subdivisions(h, alpha)
    s = int(subdivisions)
    if s < 1:
        raise ValueError(f"subdivisions must be a positive int, got {subdivisions!r}")
    _warn_unresolved_lobes(alpha, normal, view, np.pi / h / s)
    rad = env.radiance.astype(dtype)
    if exhaustive:
        nodes = texel_light(rad, s, dtype)
        cfg = (False, observer, s, int(n_cos), bool(cross_band), arithmetic,
               _batch(batch_size, n_pts, len(nodes[0])), one_film)
        out = _exact_jit(film, alpha, normal, view, rad, nodes, cfg)
        return (out, jnp.zeros(alpha.shape, dtype)) if return_estimate else out
    out, est = adaptive_radiance(film, alpha, normal, view, rad, observer=observer, s=s,
                                 n_cos=n_cos, cross_band=cross_band, arithmetic=arithmetic,
                                 one_film=one_film, a_min=a_min, batch_size=batch_size,
                                 refine=refine)
    return (out, est) if return_estimate else out


class GrazingLobeWarning(UserWarning):
    """`envmap_radiance(method="reference")` at `count` of `total` shading points whose lobe
    the texel nodes cannot resolve (module docstring, "Grazing views")."""

    def __init__(self, message: str, count: int, total: int):
        super().__init__(message)
        self.count, self.total = count, total


def _warn_unresolved_lobes(alpha, normal, view, spacing: float) -> None:
    """Warn where the quadrature cannot resolve the reflected lobe (concrete inputs only).

    At a grazing view the lobe in ω_i is squeezed against the tangent plane: its width at
    the peak is ℓ = 2α⟨h,ω_i⟩ ≈ 2α cos θ_o (module docstring), while s = `auto_subdivisions`
    sizes the nodes (spacing π/(H s)) by α alone. Where ℓ < 2 × spacing neither rule, the
    exhaustive one included, is converged: a near-mirror under a white 128 × 256 map gives
    A(θ_o, α) to 5e-3 at α = 0.1, θ_o = 88°, 1.2e-2 to 2.5e-2 at α = 0.05, 88°, and 0.66 at
    α = 0.02, 89.9° (L = 1.64 > 1), where `method="mc"` stays unbiased (measured within its
    standard error); at ℓ ≥ 2.8 × spacing (α = 0.25, 86°) the error is 6e-4."""
    if not all(_concrete(x) for x in (alpha, normal, view)):
        return
    n, v = np.asarray(normal, float), np.asarray(view, float)
    cos_o = np.sum(n * v, axis=-1)
    width = 2 * np.asarray(alpha, float) * cos_o
    bad = (cos_o > 0) & (width < 2 * spacing)
    if np.any(bad):
        worst = np.degrees(np.arccos(np.clip(np.min(cos_o[bad]), -1, 1)))
        warnings.warn(GrazingLobeWarning(
            f"envmap_radiance(method='reference'): at {int(np.sum(bad))} of {bad.size} "
            f"shading points the view is so oblique (θ_o up to {worst:.1f}°) that the "
            f"reflected lobe, about 2α cos θ_o wide (down to {np.min(width[bad]):.2g} rad), "
            f"is narrower than twice the quadrature's node spacing ({spacing:.2g} rad): the "
            "reference is not converged there (errors of 1e-2 and more at θ_o ≥ 88° with "
            "α ≤ 0.1); method='mc' is unbiased there", int(np.sum(bad)), bad.size),
            stacklevel=_user_stacklevel())


def _user_stacklevel() -> int:
    """The `warnings.warn` stack level of the first frame outside the package (the user's
    call), however many of the package's frames (entry point, kind and method dispatch) lie
    between it and the function that warns (`functools.singledispatch`'s frame counts as the
    package's)."""
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    internal = (package, os.path.abspath(functools.__file__))
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(internal):
        frame, level = frame.f_back, level + 1
    return level


def _same(x) -> bool:
    """A concrete array whose entries are all equal (one film broadcast over the points)."""
    if not _concrete(x):
        return False
    a = np.asarray(x)
    return a.size == 0 or bool(np.all(a == a.flat[0]))


def exact_stack_envmap(material, alpha, normal, view, envmap, method, observer, kw):
    """`reference` / `mc` of a `Stack` or a dispersive `Film` (`envmap_radiance`'s keywords
    `kw`): validated, broadcast, then `exact_radiance` on the stack code (complex by nature;
    its thicknesses may vary per point, its indices are shared)."""
    stack = V.check_material(material, wavelengths=get_observer(observer).wavelengths)
    V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    V.check_directions(normal, view)
    shape = V.check_broadcast([("film", np.zeros(batch_shape(stack))), ("alpha", alpha),
                               ("normal", np.zeros(np.shape(normal)[:-1])),
                               ("view", np.zeros(np.shape(view)[:-1]))])
    if isinstance(envmap, PrefilteredEnvMap):
        raise ValueError(f"method={method!r} integrates the map itself: pass an EnvMap, "
                         "not a PrefilteredEnvMap")
    env = envmap if isinstance(envmap, EnvMap) else load_envmap(envmap)
    dtype = jnp.result_type(alpha, normal, view, float)
    alpha = jnp.broadcast_to(jnp.asarray(alpha, dtype), shape)
    nv = [jnp.broadcast_to(jnp.asarray(v, dtype), shape + (3,)) for v in (normal, view)]
    return exact_radiance(stack, alpha, *nv, env, method=method, observer=observer,
                          cross_band=bool(kw["cross_band"]), arithmetic="complex",
                          one_film=batch_shape(stack) == (), subdivisions=kw["subdivisions"],
                          n_cos=kw["n_cos"], n_samples=kw["n_samples"], key=kw["key"],
                          batch_size=kw["batch_size"], max_height=kw["max_height"])
