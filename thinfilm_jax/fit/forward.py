r"""The fits' forward models: what `patch_radiance` and `spectral.reflectance` run, per point
and trace-safe (no validation), for the solvers to differentiate.

* `patch_model`: L_j (SPEC §7) of one film at several view angles, `fit_film`'s model: the
  kernels of `shading.patch` (`patch_one`; `stack_patch_one` for a `Stack` or a dispersive
  `Film` with an exact method or `ideal`; for the other real-time methods `band_patch`, each
  band from the film at its centroid, `spectral.reflectance.band_film`, as `patch_radiance`
  does through `spectral.reflectance.per_band`).
* `spectrum_model`: exact R(θ₁, λ) (SPEC §2, §12), `fit_spectrum`'s model.

Example (`patch_model` is `patch_radiance`'s kernel, vmapped over the view angles):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax import Film, ModelOptions, patch_radiance
    >>> from thinfilm_jax.fit.forward import patch_model
    >>> film = Film(300.0, 1.33, 1.0)
    >>> a = patch_model(film, jnp.array([0.2]), 0.3, method="filtered", quadrature=(8, 8))
    >>> b = patch_radiance(film, 0.2, 0.3, method="filtered",
    ...                    options=ModelOptions(quadrature=(8, 8), arithmetic="complex"))
    >>> bool(jnp.allclose(a[0], b, rtol=1e-12, atol=0))
    True
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import Array

from ..core.film import Film
from ..core.material import needs_stack
from ..core.methods import METHODS as METHOD_INFO
from ..core.stack import Stack
from ..optics.airy import polarised_reflectance
from ..optics.fresnel import film_interfaces
from ..optics.stack import stack_reflectance_traced
from ..realtime.options import ModelOptions
from ..shading.patch import patch_one, stack_patch_one
from ..spectral.reflectance import band_centroids, band_film
from ..spectral.spectra import DEFAULT_OBSERVER

__all__ = ["band_patch", "patch_model", "spectrum_model"]


def traced_stack(material) -> Stack:
    """The one-layer `Stack` of a dispersive `Film` (trace-safe: no value checks)."""
    return material if isinstance(material, Stack) else Stack.from_film(material)


def band_patch(bf: Film, theta_o, alpha, *, method: str, observer: str, options, lut=None,
               in_axes=0) -> Array:
    """(J,): band j of `patch_one` with the band film j of `bf` (fields (J,) batched as
    `in_axes` says; `spectral.reflectance.band_film`): the real-time methods on a dispersive
    single film, what `patch_radiance` computes through `per_band`."""
    out = jax.vmap(lambda f: patch_one(f, theta_o, alpha, method=method, observer=observer,
                                       options=options, lut=lut), in_axes=(in_axes,))(bf)
    return jnp.diagonal(out)  # (J, J) → band j of film j


def patch_model(film, theta_o, alpha, *, method: str = "reference",
                observer: str = DEFAULT_OBSERVER, terms: int = 2, shat: str = "exact", lut=None,
                quadrature: tuple[int, int] = (16, 16), ndf: str = "ggx",
                arithmetic: str = "complex") -> Array:
    """L_j at each view angle: `patch_one` vmapped over `theta_o` (n_angles,) → (n_angles, J).

    Scalar film fields and α; no validation (jit- and vmap-safe): the fit's forward model.
    A `Stack` or a dispersive `Film` (SPEC §12) runs what `patch_radiance` runs for it: an
    exact method or "ideal", `shading.patch.stack_patch_one` (the stack code at each of the
    observer's wavelengths on `patch_quadrature`'s nodes; "ideal", A(θ_o, α) times the exact
    bands at cos θ_o); the other real-time methods, a dispersive single film at each band's
    centroid (`band_patch`). The caller checks the method can model the material
    (`core.methods.require`).
    """
    options = ModelOptions(terms=terms, shat=shat, ndf=ndf, quadrature=tuple(quadrature),
                           arithmetic=arithmetic)
    theta_o = jnp.asarray(theta_o)
    if needs_stack(film) and (METHOD_INFO[method].dispersion == "exact"):
        stack = traced_stack(film)

        def one(t):
            return stack_patch_one(stack, t, alpha, method=method, observer=observer,
                                   quadrature=tuple(quadrature), ndf=ndf)

        return jax.vmap(one)(theta_o)
    if needs_stack(film):  # real time: band j sees the film at its centroid
        n_bands = len(band_centroids(observer))
        bf = jax.tree.map(lambda v: jnp.broadcast_to(v, (n_bands,)), band_film(film, observer))

        def one(t):
            return band_patch(bf, t, alpha, method=method, observer=observer, options=options,
                              lut=lut)

        return jax.vmap(one)(theta_o)

    def one(t):
        return patch_one(film, t, alpha, method=method, observer=observer, options=options,
                         lut=lut)

    return jax.vmap(one)(theta_o)


def spectrum_model(film, cos_theta, wavelength) -> Array:
    """Exact R (SPEC §2) on the grid cos θ₁ (n_angles,) × λ (n_wl,) → (n_angles, n_wl).

    A constant `Film`: the Airy formula, general (complex) Fresnel path; a `Stack` or a
    dispersive `Film`: the stack code (`optics.stack`, every index at each λ). Scalar
    fields; no validation.
    """
    c = jnp.asarray(cos_theta)[:, None]
    lam = jnp.asarray(wavelength)[None, :]
    if needs_stack(film):
        return stack_reflectance_traced(traced_stack(film), c, lam)
    ifc = film_interfaces(film, c, arithmetic="complex")
    return jnp.mean(polarised_reflectance(ifc, film.thickness, lam), axis=0)
