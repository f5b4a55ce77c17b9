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

from ..core import _validate as V
from ..core.material import batch_shape, is_dispersive, needs_stack, point_split
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import names as method_names
from ..core.methods import require
from ..core.stack import Stack
from ..optics.airy import choose_arithmetic
from ..core.film import Film
from ..realtime.filtered import filtered_bands
from ..realtime.improved import BinTable, bin_table, improved_kernel, lookup_bins
from ..spectral.lut import ShatLUT, build_shat_lut
from ..brdf.microfacet import (light_moments, patch_quadrature, sample_patch_mc,
                         splitsum_light_moments, view_direction)
from ..realtime.kernels import filtered_kernel, ideal_kernel
from ..optics.opd import cos_incidence_from_projection, opd_moments_exact, project_light_moments
from ..realtime.options import ModelOptions, check_options
from ..spectral.khr import khr_bands, khr_to_bands
from ..spectral.reflectance import (band_centroids, bare_bands, choose_layer, per_band,
                                    spectral_bands, stack_bands)
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS, get_observer

METHODS = method_names("patch")  # the registry's order (core/methods.py)


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
    V.check_choice("method", method, METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    options = check_options(options)
    shape = V.check_broadcast([("film", np.zeros(batch_shape(film))), ("theta_o", theta_o),
                               ("alpha", alpha)])
    return film, theta_o, alpha, options, shape


def patch_radiance(film: Film, theta_o, alpha, *, method: str = "reference",
                   observer: str = DEFAULT_OBSERVER, options: ModelOptions = ModelOptions(),
                   lut: ShatLUT | None = None, batch_size: int = 64) -> Array:
    """Band radiances L_j of a patch under uniform light, shape broadcast(...) + (n_bands,).

    The first call in a process compiles (XLA) for the shapes, dtypes and options given:
    tens of seconds on a small CPU (27–35 s measured on a 2-core machine), then each call
    with the same shapes runs compiled. ``thinfilm_jax.enable_compilation_cache()`` keeps the
    compilations on disk for later processes (the ``thinfilm-jax`` command and the notebooks
    turn it on).

    Args:
        film: `Film` (fields broadcast with theta_o and alpha).
        theta_o: view angle θ_o ∈ [0, π/2] (radians).
        alpha: GGX roughness α ∈ (0, 1].
        method: one of `METHODS` (SPEC §7).
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
    if needs_stack(film):  # a Stack or a dispersive Film (SPEC §12)
        return _material_patch(film, theta_o, alpha, method, observer, options, lut,
                               batch_size)
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
    table = (bin_table(options.bins, ndf=options.ndf, dtype=dtype) if method == "improved"
             else None)
    return _patch_jit(film, theta_o, alpha, (lut, table), (method, observer, options, batch_size),
                      shape)


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


def _material_patch(material, theta_o, alpha, method, observer, options, lut, batch_size):
    """`patch_radiance` of a `Stack` or a dispersive `Film`: exact methods evaluate every
    index at each of the observer's wavelengths; "ideal" is A(θ_o, α) times the exact bands at
    h = n (what a per-material table R_j(cos θ) gives an engine); the other real-time ones
    take a dispersive single film at each band's centroid (`spectral.reflectance.per_band`);
    the rest is a ValueError from the registry naming what the method lacks."""
    V.check_choice("method", method, METHODS)
    V.check_choice("observer", observer, OBSERVERS)
    require(method, dispersive=is_dispersive(material), stack=isinstance(material, Stack))
    if not METHOD_INFO[method].exact and method != "ideal":
        V.check_material(material, wavelengths=band_centroids(observer))
        return per_band(lambda f, t, a: patch_radiance(
            f, t, a, method=method, observer=observer, options=options, lut=lut,
            batch_size=batch_size), material, theta_o, alpha, observer=observer)
    stack, theta_o, alpha, options, shape = _check_patch_args(material, theta_o, alpha, method,
                                                              observer, options)
    batch_size = V.check_int("batch_size", batch_size, 1)
    return _stack_patch_jit(stack, theta_o, alpha, (method, observer, options.quadrature,
                                                    options.ndf, batch_size), shape)


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
    `reference` quadrature of the exact stack bands, or `ideal`'s A(θ_o, α) · R_j(cos θ_o)
    (the exact bands at h = n). No validation (trace-safe)."""
    quad = patch_quadrature(theta_o, alpha, quadrature=quadrature, ndf=ndf)
    if method == "ideal":
        return jnp.sum(quad.weight) * stack_bands(stack, jnp.cos(theta_o), observer)
    rj = stack_bands(stack, quad.cos_hi, observer)  # (N, J)
    return jnp.matmul(quad.weight, rj, precision=jax.lax.Precision.HIGHEST)


def patch_one(film: Film, theta_o, alpha, *, method: str, observer: str,
              options: ModelOptions = ModelOptions(shat="exact", arithmetic="complex",
                                                   layer="film"),
              lut=None, table: BinTable | None = None) -> Array:
    """One patch (scalar film fields, θ_o, α) → (n_bands,). The kernel `patch_radiance` maps.

    No validation (trace-safe); ``options.arithmetic`` must already be "real" or "complex"
    and ``options.layer`` "film" or "bare"; method "improved" reads `table`
    (`improved.bin_table`; None: the default table). A bare layer (d = 0) replaces each
    method's band reflectance by the exact R₁₃ Ŝ_j(0) at the cosine that method evaluates:
    the nodes c_n (reference), cos θ_o (ideal), cos θ₁* of K 22 (the filtered methods), the
    bin means c̄_k (improved, averaged over the bins).
    """
    o = options
    if o.shat == "auto":  # uniform light's default Ŝ source (`ModelOptions`), as patch_radiance
        o = o._replace(shat="exact")
    quad = patch_quadrature(theta_o, alpha, quadrature=o.quadrature, ndf=o.ndf)
    if method == "khr":  # as `ideal`; its d = 0 is its own formula, not the bare base
        rgb = jnp.sum(quad.weight) * khr_bands(film, jnp.cos(theta_o))  # linear Rec. 709
        return khr_to_bands(rgb, observer)  # the bands, as every method
    if o.layer == "bare":
        return _bare_patch(film, theta_o, alpha, quad, method, observer, o, table)
    if method == "reference":
        rj = spectral_bands(film, quad.cos_hi, observer, arithmetic=o.arithmetic)  # (N, J)
        return jnp.matmul(quad.weight, rj, precision=jax.lax.Precision.HIGHEST)
    albedo = jnp.sum(quad.weight)
    if method == "ideal":
        return albedo * ideal_kernel(film, jnp.cos(theta_o), observer=observer, terms=o.terms,
                                     shat="exact", arithmetic=o.arithmetic)
    if method == "improved":
        if table is None:  # the default table (host-built, cached; fine under jit too)
            table = bin_table(o.bins, ndf=o.ndf, dtype=albedo.dtype)
        return albedo * improved_kernel(film, jnp.cos(theta_o), alpha, table, observer=observer,
                                        terms=o.terms, shat=o.shat, lut=lut,
                                        arithmetic=o.arithmetic)
    if method == "filtered":
        mean, cov = splitsum_light_moments(theta_o, alpha, quadrature=o.quadrature, ndf=o.ndf)
    else:
        mean, cov = light_moments(quad)
    wo = view_direction(theta_o)
    if method == "filtered_gt_opd":
        mu_c, _ = project_light_moments(wo, mean, cov)
        opd = opd_moments_exact(film, quad.cos_hi, quad.weight)
        return albedo * filtered_bands(film, cos_incidence_from_projection(mu_c), opd, observer,
                                       terms=o.terms, shat=o.shat, lut=lut,
                                       arithmetic=o.arithmetic)
    return albedo * filtered_kernel(film, wo, mean, cov, observer=observer, terms=o.terms,
                                    shat=o.shat, lut=lut, arithmetic=o.arithmetic)


def _bare_patch(film, theta_o, alpha, quad, method, observer, o, table):
    def bands(c):
        return bare_bands(film, c, observer, shat="exact" if method == "reference" else o.shat,
                          arithmetic=o.arithmetic)

    if method == "reference":
        return jnp.matmul(quad.weight, bands(quad.cos_hi), precision=jax.lax.Precision.HIGHEST)
    albedo = jnp.sum(quad.weight)
    if method == "ideal":
        return albedo * bands(jnp.cos(theta_o))
    if method == "improved":  # the mean over the bins' cosines c̄_k
        if table is None:
            table = bin_table(o.bins, ndf=o.ndf, dtype=albedo.dtype)
        cb, _ = lookup_bins(table, jnp.cos(theta_o), alpha)
        return albedo * jnp.mean(bands(cb), axis=-2)
    if method == "filtered":
        mean, cov = splitsum_light_moments(theta_o, alpha, quadrature=o.quadrature, ndf=o.ndf)
    else:
        mean, cov = light_moments(quad)
    wo = view_direction(theta_o)
    mu_c, _ = project_light_moments(wo, mean, cov)
    return albedo * bands(cos_incidence_from_projection(mu_c))


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
