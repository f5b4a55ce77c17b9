r"""Reflected radiance of a patch under uniform lighting, by every method of SPEC §7.

$$ L_j(\theta_o, \alpha) = \int \tilde\rho(\omega_i, \omega_o)\langle n, \omega_i\rangle
   R_j(\langle h, \omega_i\rangle)\, d\omega_i \quad (K\ 11,\ L_i \equiv 1) $$

| method                | R_j part                                                         |
|-----------------------|------------------------------------------------------------------|
| ``reference``         | Σ_n w_n R_j^spectral(c_n): converged half-vector quadrature (exact) |
| ``ideal``             | A · R_j^Fourier(cos θ_o) (BB17 real time, h = n)                 |
| ``filtered_gt_moments`` | A · K 29 with μ_D, σ_D from the true μ_ω, Σ_ω via K 20–28      |
| ``filtered_gt_opd``   | A · K 29 with the true mean and std of D under p_R               |
| ``filtered``          | A · K 29 with μ_ω, Σ_ω of the split-sum prefiltered uniform environment |
| ``improved``          | A · K 29 per equal-probability bin of cos θ₁ (`improved`, docs/improved.md) |
| ``khr``               | A · glTF `F_iridescence`(cos θ_o) (SPEC §10, h = n): its linear Rec. 709 taken to the bands (`colorimetry.rec709_to_bands`) |

Each method is one object of `shading.methods` (its module holds the row's formula), looked
up in the registry (`core.methods.implementation`); the material's kind picks the path by
type (`_patch_of`): a `Film` or `Stack` (one-film code, stack code or a dispersive film per
band, `core.methods.material_path`), a classic-lobe `Material`
(`material_patch.material_patch_radiance`) or a `CarPaint` (`carpaint_ibl.paint_patch_radiance`).

A(θ_o, α) = Σ_n w_n is the prefiltered BRDF (exact quadrature, K 12). The quadrature
(`microfacet.patch_quadrature`) is deterministic and film-independent; its convergence and
the reference's accuracy are measured in tests/shading/test_patch.py. `patch_radiance_mc` is an
independent Monte Carlo estimator of the reference (with its standard error).

Example (16 × 16 quadrature to stay quick; d = 0 has no interference: equal bands; every band
lies below the albedo A(θ_o, α), since 0 ≤ R ≤ 1):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film, ModelOptions, albedo
    >>> from thinfilm_jax.shading.patch import patch_radiance
    >>> opts = ModelOptions(quadrature=(16, 16))
    >>> L = patch_radiance(Film(jnp.array([0.0, 600.0]), 1.3, 2.0, 0.5), 0.3, 0.25, options=opts)
    >>> L.shape
    (2, 3)
    >>> bool(jnp.ptp(L[0]) < 1e-12)
    True
    >>> bool(jnp.all((L > 0) & (L < albedo(0.3, 0.25, quadrature=(16, 16)))))
    True
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..brdf.carpaint import CarPaint
from ..brdf.material import Material
from ..brdf.microfacet import patch_quadrature, sample_patch_mc
from ..core import _validate as V
from ..core.film import Film
from ..core.material import batch_shape, needs_stack, point_split
from ..core.methods import implementation, material_path
from ..core.methods import MethodNames
from ..core.stack import Stack
from ..optics.airy import choose_arithmetic
from ..realtime.improved import BinTable
from ..realtime.options import ModelOptions, check_options
from ..spectral.lut import ShatLUT, build_shat_lut
from ..spectral.reflectance import choose_layer, per_band, band_centroids, spectral_bands
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer
from .carpaint_ibl import paint_patch_radiance
from .material_patch import material_patch_radiance

__all__ = [
    "PATCH_METHODS",
    "PATCH_KIND_METHODS",
    "patch_radiance",
    "stack_patch_one",
    "patch_one",
    "patch_radiance_mc",
]

#: the built-in methods, the registry's order (core/methods.py)
PATCH_METHODS = MethodNames("patch")
#: the methods of the material kinds that carry their own lobe (`Material`, `CarPaint`)
PATCH_KIND_METHODS = {Material: ("reference",), CarPaint: ("reference",)}


def _check_patch_args(film, theta_o, alpha, method, observer, options):
    """(film, theta_o, alpha, options, broadcast shape), checked and normalised; a `Stack` or a
    dispersive `Film` comes back as the validated `Stack` (its models cover the observer's
    wavelengths) and its batch shape counts."""
    if needs_stack(film):
        film = V.check_material(film, wavelengths=get_observer(observer).wavelengths)
    else:
        film = V.check_film(film)
    theta_o = V.check_angle("theta_o", theta_o)
    alpha = V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    V.check_choice("method", method, PATCH_METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    options = check_options(options)
    shape = V.check_broadcast([("film", np.zeros(batch_shape(film))), ("theta_o", theta_o),
                               ("alpha", alpha)])
    return film, theta_o, alpha, options, shape


def patch_radiance(film, theta_o, alpha=None, *, method: str = "reference",
                   observer: str = DEFAULT_OBSERVER, options: ModelOptions = ModelOptions(),
                   lut: ShatLUT | None = None, batch_size: int = 64, **kind_options) -> Array:
    """Band radiances L_j of a patch under uniform light, shape broadcast(...) + (n_bands,).

    A process's first call compiles for its shapes, dtypes and options (27–35 s on a 2-core
    CPU); ``thinfilm_jax.enable_compilation_cache()`` keeps that on disk for later processes.

    Args:
        film: the material, by type: a `Film` (fields broadcast with theta_o and alpha) or a
            `Stack` (SPEC §12); a classic-lobe `Material` or a `CarPaint`, which carry their
            own lobe (`alpha` None, method "reference"; `kind_options` go to
            `material_patch_radiance` / `paint_patch_radiance`: tangent, quadratures).
        theta_o: view angle θ_o ∈ [0, π/2] (radians).
        alpha: GGX roughness α ∈ (0, 1] of a film or stack.
        method: one of `core.methods.names("patch")` (SPEC §7).
        observer: colour bands of the result, for every method ("khr" computes glTF's
            linear Rec. 709 and returns it in these bands, `colorimetry.rec709_to_bands`).
        options: `ModelOptions` — terms (M of the non-reference methods; K 29 uses 2),
            shat (Ŝ source of K 29: "exact", "lut" or "gaussian"), ndf, quadrature
            (n_u, n_φ) of the half-vector quadrature, arithmetic ("auto" specialises a
            concrete dielectric film to real arithmetic).
        lut: a prebuilt `ShatLUT` (built once per observer/dtype if None and shat="lut").
        batch_size: patches evaluated together (memory of the reference is
            batch_size · n_u · n_φ · n_λ).
    """
    return _patch_of(film, theta_o, alpha, method, dict(
        observer=observer, options=options, lut=lut, batch_size=batch_size), kind_options)


@functools.singledispatch
def _patch_of(material, theta_o, alpha, method, kw, kind_options):
    """`patch_radiance` by the material's type (one handler per kind)."""
    raise TypeError(f"patch_radiance takes a thinfilm_jax Film, Stack, Material or CarPaint, "
                    f"got {type(material).__name__}")


def _no_kind_options(kind_options):
    if kind_options:
        raise TypeError(f"patch_radiance of a film or stack got unexpected keyword arguments "
                        f"{sorted(kind_options)}")


@_patch_of.register(Film)
@_patch_of.register(Stack)
def _film_patch(film, theta_o, alpha, method, kw, kind_options):
    """A `Film` or `Stack`: the path `core.methods.material_path` picks."""
    _no_kind_options(kind_options)
    if alpha is None:
        raise TypeError("patch_radiance of a Film or Stack needs alpha, the GGX roughness "
                        "α ∈ (0, 1]")
    observer, options, lut, batch_size = kw["observer"], kw["options"], kw["lut"], \
        kw["batch_size"]
    V.check_choice("method", method, PATCH_METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    path = material_path(film, method)
    if path == "bands":  # a dispersive single film at each band's centroid (SPEC §12)
        V.check_material(film, wavelengths=band_centroids(observer))
        return per_band(lambda f, t, a: patch_radiance(
            f, t, a, method=method, observer=observer, options=options, lut=lut,
            batch_size=batch_size), film, theta_o, alpha, observer=observer)
    if path == "stack":  # every index at each of the observer's wavelengths
        stack, theta_o, alpha, options, shape = _check_patch_args(film, theta_o, alpha, method,
                                                                  observer, options)
        batch_size = V.check_int("batch_size", batch_size, 1)
        return _stack_patch_jit(stack, theta_o, alpha, (method, observer, options.quadrature,
                                                        options.ndf, batch_size), shape)
    film, theta_o, alpha, options, shape = _check_patch_args(film, theta_o, alpha, method,
                                                             observer, options)
    batch_size = V.check_int("batch_size", batch_size, 1)
    if lut is not None and not isinstance(lut, ShatLUT):
        raise TypeError(f"lut must be a ShatLUT (build_shat_lut) or None, got "
                        f"{type(lut).__name__}")
    dtype = jnp.result_type(theta_o, alpha, *jax.tree.leaves(film), float)
    if options.shat == "lut" and lut is None:
        lut = build_shat_lut(observer, dtype=dtype)
    options = options._replace(arithmetic=choose_arithmetic(film, options.arithmetic),
                               layer=choose_layer(film, options.layer))
    table = implementation(method).patch_tables(options, dtype)  # host side, cached by value
    return _patch_jit(film, theta_o, alpha, (lut, table), (method, observer, options, batch_size),
                      shape)


def _lobe_kind(fn):
    """The handler of a material kind that carries its own lobe (no `alpha`, its methods
    `PATCH_KIND_METHODS`; observer, options, lut and batch_size are the films')."""
    def handler(material, theta_o, alpha, method, kw, kind_options):
        if alpha is not None:
            raise ValueError(f"alpha must be None for a {type(material).__name__} (it carries "
                             f"its own lobe), got {alpha!r}")
        V.check_choice("method", method, PATCH_KIND_METHODS[type(material)])
        return fn(material, theta_o, **kind_options)
    return handler


_patch_of.register(Material, _lobe_kind(material_patch_radiance))
_patch_of.register(CarPaint, _lobe_kind(paint_patch_radiance))


@functools.partial(jax.jit, static_argnums=(4, 5))
def _patch_jit(film, theta_o, alpha, tables, cfg, shape):
    method, observer, options, batch = cfg
    lut, table = tables
    # One flat pytree (film, θ_o, α) of per-point vectors; lax.map slices every leaf.
    flat = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), shape).reshape(-1),
                        (film, theta_o, alpha))

    def one(xs):
        f, t, a = xs
        return patch_one(f, t, a, method=method, observer=observer, options=options, lut=lut,
                         table=table)

    out = jax.lax.map(one, flat, batch_size=min(batch, max(math.prod(shape), 1)))
    return out.reshape(*shape, out.shape[-1])


@functools.partial(jax.jit, static_argnums=(3, 4))
def _stack_patch_jit(stack, theta_o, alpha, cfg, shape):
    method, observer, quadrature, ndf, batch = cfg
    dtype = jnp.result_type(theta_o, alpha, float)
    t, point = point_split(stack, shape)
    th, al = (jnp.broadcast_to(jnp.asarray(x, dtype), shape).reshape(-1) for x in (theta_o, alpha))

    def one(xs):
        ti, tho, a = xs
        return stack_patch_one(point(ti), tho, a, method=method, observer=observer,
                               quadrature=quadrature, ndf=ndf)

    out = jax.lax.map(one, (t.astype(dtype), th, al), batch_size=min(batch, max(th.shape[0], 1)))
    return out.reshape(*shape, out.shape[-1])


def stack_patch_one(stack: Stack, theta_o, alpha, *, method: str, observer: str,
                    quadrature=ModelOptions().quadrature, ndf: str = "ggx") -> Array:
    """One patch of a `Stack` (one point: thickness (N,), scalar θ_o and α) → (J,): the
    method's `stack_patch_point` (`reference`: the quadrature of the exact stack bands;
    `ideal`: A(θ_o, α) · R_j(cos θ_o), the exact bands at h = n). No validation (trace-safe)."""
    quad = patch_quadrature(theta_o, alpha, quadrature=quadrature, ndf=ndf)
    return implementation(method).stack_patch_point(stack, theta_o, quad, observer)


def patch_one(film: Film, theta_o, alpha, *, method: str, observer: str,
              options: ModelOptions = ModelOptions(shat="exact", arithmetic="complex",
                                                   layer="film"),
              lut=None, table: BinTable | None = None) -> Array:
    """One patch (scalar film fields, θ_o, α) → (n_bands,). The kernel `patch_radiance` maps:
    the half-vector quadrature, then the method's `patch_point` (`shading.methods`).

    No validation (trace-safe); ``options.arithmetic`` must already be "real" or "complex"
    and ``options.layer`` "film" or "bare"; `table` is the method's `patch_tables` (None: the
    method builds its default, e.g. `improved`'s `bin_table`). A bare layer (d = 0) replaces
    each method's band reflectance by the exact R₁₃ Ŝ_j(0) at the cosine that method
    evaluates: the nodes c_n (reference), cos θ_o (ideal), cos θ₁* of K 22 (the filtered
    methods), the bin means c̄_k (improved, averaged over the bins); `khr`'s d = 0 is its own
    formula.
    """
    o = options
    if o.shat == "auto":  # uniform light's default Ŝ source (`ModelOptions`), as patch_radiance
        o = o._replace(shat="exact")
    quad = patch_quadrature(theta_o, alpha, quadrature=o.quadrature, ndf=o.ndf)
    return implementation(method).patch_point(film, theta_o, alpha, quad, observer=observer,
                                              options=o, lut=lut, table=table)


def patch_radiance_mc(film: Film, theta_o: float, alpha: float, key, *, n_samples: int = 100_000,
                      observer: str = DEFAULT_OBSERVER,
                      options: ModelOptions = ModelOptions()):
    """Monte Carlo estimate of the reference L_j for one patch: (mean (J,), standard error (J,)).

    Independent of the deterministic quadrature: h ~ D cos θ_h over the full azimuth.
    `n_samples` ≥ 2 (the standard error needs two); film fields, θ_o and α scalars;
    `options` supplies ndf and arithmetic (the other fields do not apply).
    """
    film, theta_o, alpha, options, shape = _check_patch_args(film, theta_o, alpha, "reference",
                                                             observer, options)
    # a Stack (or dispersive Film) runs the stack code (SPEC §12), complex by nature
    arithmetic = ("complex" if isinstance(film, Stack)
                  else choose_arithmetic(film, options.arithmetic))
    if shape != ():
        raise ValueError(f"patch_radiance_mc evaluates one patch: film fields, theta_o and "
                         f"alpha must be scalars; got broadcast shape {shape}")
    n_samples = V.check_int("n_samples", n_samples, 2)
    return _mc_jit(film, theta_o, alpha, key, n_samples, observer, options.ndf, arithmetic)


@functools.partial(jax.jit, static_argnums=(4, 5, 6, 7))
def _mc_jit(film, theta_o, alpha, key, n, observer, ndf, arithmetic):
    q = sample_patch_mc(key, theta_o, alpha, n, ndf=ndf)
    vals = n * q.weight[:, None] * spectral_bands(film, q.cos_hi, observer, arithmetic=arithmetic)
    return jnp.mean(vals, axis=0), jnp.std(vals, axis=0, ddof=1) / float(np.sqrt(n))
