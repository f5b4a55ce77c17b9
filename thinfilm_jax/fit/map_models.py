r"""The pixel models of the thickness maps of band radiances (`fit.pixelwise`): a function
``model(x = (d, η₂), pixel inputs, shared inputs) → (J,)`` per map front end, each running the
forward path's own kernel at one point.

* `fit_patch_map` (uniform light, SPEC §7): `shading.patch.patch_one` at the pixel's θ_o;
  a dispersive film or one-layer `Stack` (SPEC §12) runs `stack_patch_one` (exact methods,
  `ideal`) or `fit.forward.band_patch` (each band from the film at its centroid), as
  `patch_radiance` does;
* `fit_envmap_map` (an environment map, SPEC §9): one shading point of
  `envmap_radiance(method=...)` at the pixel's normal and view;
* `render_patch_map`: the uniform-light model over a map of films (tests, examples).

The models are cached (`functools.lru_cache`): one jit compilation per model, not per call.

Example:
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.fit.map_models import render_patch_map
    >>> render_patch_map(Film(300.0, 1.33, 1.0), [[0.1, 0.2]], 0.2).shape
    (1, 2, 3)
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..core.material import batch_shape
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import require
from ..core.stack import Stack
from ..optics.index import index_at
from ..realtime.options import ModelOptions
from ..shading.patch import patch_one, stack_patch_one
from ..spectral.reflectance import band_centroids, band_film
from ..spectral.spectra import DEFAULT_OBSERVER, get_observer
from .forward import band_patch

__all__ = ["ENVMAP_MAP_METHODS", "MAP_OPTIONS", "render_patch_map"]

#: The map model's defaults: the real-time `filtered` path, small quadrature (its moments).
MAP_OPTIONS = ModelOptions(shat="exact", quadrature=(8, 8), arithmetic="complex")

@functools.lru_cache(maxsize=32)
def _pixel_model(method, observer, options, alpha):
    """model(x = (d, η₂), θ_o, ctx = (η₃, κ₃, η₁)) → (J,) of one pixel (cached: one jit
    compilation per model, not per call)."""
    def model(x, theta, ctx):
        film = Film(x[0], x[1], ctx[0], ctx[1], ctx[2])
        return patch_one(film, theta, alpha, method=method, observer=observer,
                         options=options)
    return model


def render_patch_map(film: Film, theta_o, alpha, *, method: str = "filtered",
                     observer: str = DEFAULT_OBSERVER,
                     options: ModelOptions = MAP_OPTIONS) -> Array:
    """Band radiances (H, W, J) of a film whose fields (H, W) vary per pixel, seen at the
    per-pixel view angles θ_o (H, W) under uniform light (SPEC §7): the map model. The
    fields and θ_o broadcast together (a scalar θ_o, or a scalar field, is fine)."""
    theta_o = jnp.asarray(theta_o)
    dt = theta_o.dtype if jnp.issubdtype(theta_o.dtype, jnp.floating) else float
    shape = np.broadcast_shapes(theta_o.shape, *(np.shape(v) for v in film))
    f = jax.tree.map(lambda v: jnp.broadcast_to(jnp.asarray(v, dt), shape), film)
    theta_o = jnp.broadcast_to(theta_o.astype(dt), shape)
    model = _pixel_model(method, observer, options, float(alpha))
    out = _render_flat(tuple(v.reshape(-1) for v in (*f, theta_o)), model)
    return out.reshape(*theta_o.shape, -1)


@functools.partial(jax.jit, static_argnames=("model",))
def _render_flat(flat, model):
    def one(d, e, e3, k3, e1, t):
        return model(jnp.stack([d, e]), t, (e3, k3, e1))

    return jax.vmap(one)(*flat)

def _material_pixel_model(initial, free, method, observer, options, alpha):
    """(model, ctx, η₂ reported) of a dispersive single film (SPEC §12): the exact methods and
    `ideal` run the stack code per pixel (`patch.stack_patch_one`, ctx = the one-layer
    stack); the other real-time ones each band with the film at its centroid wavelength
    (`spectral.reflectance.band_film`, ctx = the band films' indices (J,) each)."""
    require(method, dispersive=True, stack=isinstance(initial, Stack))
    if isinstance(initial, Stack) and initial.n_layers > 1:
        raise ValueError("a thickness map fits one film: initial must be a Film (or a "
                         "one-layer Stack); fit a multi-layer stack with fit_film/fit_spectrum")
    if "eta_film" in free:
        raise ValueError("free='eta_film' needs a constant film index: this film's index is a "
                         "model (free its parameters with fit_film)")
    exact = METHOD_INFO[method].dispersion == "exact"
    stack = V.check_material(initial, "initial", wavelengths=(
        get_observer(observer).wavelengths if exact else band_centroids(observer)))
    if batch_shape(stack) != ():
        raise ValueError("initial must have a scalar thickness (the map's start)")
    eta0 = float(np.real(np.asarray(index_at(stack.eta[0], np.float64(550.0)))))
    if exact:
        return _stack_pixel_model(method, observer, options.quadrature, options.ndf,
                                  alpha), stack, eta0
    bf = band_film(initial if isinstance(initial, Film) else Film(
        0.0, stack.eta[0], stack.eta_base, 0.0, stack.eta_outer), observer)
    n_bands = len(band_centroids(observer))
    ctx = tuple(jnp.broadcast_to(jnp.asarray(v, float), (n_bands,))
                for v in (bf.eta_film, bf.eta_base, bf.kappa_base, bf.eta_outer))
    return _band_pixel_model(method, observer, options, alpha), ctx, eta0


@functools.lru_cache(maxsize=32)
def _stack_pixel_model(method, observer, quadrature, ndf, alpha):
    """model(x = (d, ·), θ_o, ctx = the one-layer stack) → (J,): exact per pixel."""
    def model(x, theta, ctx):
        return stack_patch_one(ctx._replace(thickness=x[:1]), theta, alpha, method=method,
                               observer=observer, quadrature=quadrature, ndf=ndf)
    return model


@functools.lru_cache(maxsize=32)
def _band_pixel_model(method, observer, options, alpha):
    """model(x = (d, ·), θ_o, ctx = (η₂, η₃, κ₃, η₁) of the J band films) → (J,): band j from
    the film at band j's centroid (the real-time methods' approximation of dispersion)."""
    def model(x, theta, ctx):
        return band_patch(Film(x[0], *ctx), theta, alpha, method=method, observer=observer,
                          options=options, in_axes=Film(None, 0, 0, 0, 0))
    return model


#: The map models of `fit_envmap_map`: the real-time paths of `envmap_radiance` (one shading
#: point costs them a few hundred ns; the exact ones take a quadrature per point and per
#: grid thickness, 10⁴–10⁶ times that, beyond a per-pixel screen).
ENVMAP_MAP_METHODS = ("filtered", "improved")


@functools.lru_cache(maxsize=32)
def _envmap_model(observer, options, alpha, cross_band, method="filtered"):
    """model(x = (d, η₂), (n, ω_o), ctx = (η₃, κ₃, η₁, prefiltered map)) → (J,): one
    shading point of `envmap_radiance(method=method)` (SPEC §9)."""
    from ..shading.ibl import envmap_radiance  # lazily: the IBL stack only for envmap maps

    def model(x, pix, ctx):
        film = Film(x[0], x[1], ctx[0], ctx[1], ctx[2])
        return envmap_radiance(film, alpha, pix[0], pix[1], ctx[3], method=method,
                               observer=observer, options=options, cross_band=cross_band)
    return model
