r"""Band-integrated reflectance R_j(θ₁) of a film (SPEC §4, K 2–4).

* ``method="spectral"``: the reference, R_j = Σ_k W_kj R(θ₁, λ_k) with the exact Airy R.
* ``method="fourier"``: BB17's Fourier-domain sum truncated after M = `terms` orders,
  R_j = C₀Ŝ_j(0) + Σ_{m≤M} C_m[e^{imφ₂}Ŝ_j(−mD) + e^{−imφ₂}Ŝ_j(mD)], with Ŝ tabulated on the
  same samples (converges to "spectral" as M grows) or the Gaussian closed form.
* ``method="khr"``: glTF `KHR_materials_iridescence`'s `F_iridescence` in linear Rec. 709 RGB
  (SPEC §10, `khr.khr_reflectance`); `observer` does not apply (only its default is accepted).

Scene specialisation ``layer``: a film of thickness 0 is no film, R(θ₁, λ) = R₁₃(θ₁) of the
bare outer|base interface, flat in λ for the non-dispersive base, so that R_j = R₁₃ Ŝ_j(0)
exactly (`bare_bands`): no series terms, no Ŝ(mD), no wavelength loop. ``layer="auto"`` takes
this path when every thickness is concretely 0 (the Fourier method then returns the exact
value instead of its M-term truncation: ≤ 0.22 ΔE₀₀ at M = 2); under `jit` the caller forces it
with ``layer="bare"`` (``"film"`` keeps the general path).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core import _validate as V
from ..core.methods import MethodNames
from ..optics.airy import broadcast_all, choose_arithmetic, polarised_reflectance
from ..core.film import Film
from ..core.material import batch_shape, expand_batch
from ..core.methods import implementation, material_path
from ..core.stack import Stack
from ..optics.stack import stack_reflectance_traced
from ..optics.fresnel import film_interfaces
from ..optics.series import fourier_band_reflectance, series_terms
from .khr import _khr_jit
from .spectra import DEFAULT_OBSERVER, SHAT_METHODS, get_observer, sensitivity_ft, shat_at_zero

__all__ = [
    "RGB_METHODS",
    "LAYERS",
    "choose_layer",
    "bare_bands",
    "rgb_reflectance",
    "band_centroids",
    "band_film",
    "per_band",
    "stack_bands",
    "spectral_bands",
    "fourier_bands",
]

RGB_METHODS = MethodNames("rgb")  # the registry's, read at each use (core/methods.py)
LAYERS = ("auto", "film", "bare")


def choose_layer(film: Film, layer: str = "auto") -> str:
    """Resolve ``layer="auto"``: "bare" when every (concrete) thickness is 0, else "film".

    Traced thicknesses (inside `jit`, or under `grad`) keep "film" unless ``layer="bare"`` is
    forced; ``"bare"`` with a concrete non-zero thickness raises a ValueError.
    """
    import numpy as np

    V.check_choice("layer", layer, LAYERS)
    d = film.thickness
    if layer == "bare" and V.is_concrete(d) and np.any(np.asarray(d) != 0):
        raise ValueError(f"layer='bare' means no film (thickness 0 nm); got thickness up to "
                         f"{float(np.max(np.asarray(d)))!r} nm: use layer='film' or 'auto'")
    if layer != "auto":
        return layer
    return "bare" if V.is_concrete(d) and np.all(np.asarray(d) == 0) else "film"


def bare_bands(film: Film, cos_theta, observer=DEFAULT_OBSERVER, *, shat: str = "exact",
               arithmetic: str = "complex") -> Array:
    """R_j = R₁₃(cos θ₁) Ŝ_j(0) of the bare outer|base interface (the d = 0 limit, exact).

    R₁₃ = ½(|r_s|² + |r_p|²) is `fresnel.film_interfaces` with η₂ = η₁ (then r₁₂ = 0 and
    r₂₃ = r₁₃); broadcast inputs, no validation.
    """
    bare = film._replace(eta_film=film.eta_outer)
    r = film_interfaces(bare, cos_theta, arithmetic=arithmetic).r23
    refl = jnp.mean(jnp.real(r) ** 2 + jnp.imag(r) ** 2, axis=0)
    return refl[..., None] * shat_at_zero(observer, refl.dtype, shat)


def rgb_reflectance(film: Film, cos_theta, *, observer: str = DEFAULT_OBSERVER,
                    method: str = "spectral", terms: int = 2, shat: str = "exact",
                    arithmetic: str = "auto", layer: str = "auto") -> Array:
    """Band reflectances R_j of `film` at cos θ₁, shape broadcast(film, cos_theta) + (n_bands,).

    Args:
        film: `Film`.
        cos_theta: cos θ₁ ∈ [0, 1].
        observer: "stiles_burch_1959_10" (RGB, default) or "cie_1931_2" (XYZ).
        method: "spectral" (exact quadrature of Airy over λ), "fourier" (K 4, M = terms) or
            "khr" (glTF `KHR_materials_iridescence`, SPEC §10: (..., 3) linear Rec. 709 RGB;
            M = 2 fixed, so `terms` must stay 2, `observer` and `shat` at their defaults;
            `arithmetic` and `layer` choose paths of the exact methods and are ignored).
        terms: M ≥ 0, number of Fourier orders (method="fourier" only).
        shat: "exact" | "gaussian" source of Ŝ for method="fourier".
        arithmetic: "auto" | "real" | "complex" arithmetic path (see `airy.choose_arithmetic`).
        layer: "auto" | "film" | "bare" (no film, d = 0; see `choose_layer`).

    Example:
        >>> film = Film(600.0, 1.3, 2.0, 0.5)
        >>> rgb_reflectance(film, 1.0).shape
        (3,)
    """
    V.check_choice("observer", observer, ("stiles_burch_1959_10", "cie_1931_2"))
    V.check_choice("method", method, RGB_METHODS)
    path = material_path(film, method)  # a Stack, or a Film with index models (SPEC §12)
    if path != "film":
        if path == "bands":  # a dispersive single film: indices at each band's centroid
            V.check_material(film, wavelengths=band_centroids(observer))
            return per_band(lambda f, c: rgb_reflectance(
                f, c, observer=observer, method=method, terms=terms, shat=shat,
                arithmetic=arithmetic, layer=layer), film, cos_theta, observer=observer)
        stack = V.check_material(film, wavelengths=get_observer(observer).wavelengths)
        cos_theta = V.check_cos_theta(cos_theta)
        V.check_broadcast([("film", np.zeros(batch_shape(stack))), ("cos_theta", cos_theta)])
        return _stack_rgb_jit(stack, cos_theta, observer)
    film = V.check_film(film)
    cos_theta = V.check_cos_theta(cos_theta)
    V.check_choice("shat", shat, SHAT_METHODS)
    # any integer type (np.arange(...) elements too), not bool; a plain int for the jit cache
    terms = V.check_int("terms", terms, 0)
    V.check_broadcast([("film", jnp.zeros(film.shape)), ("cos_theta", cos_theta)])
    return implementation(method).rgb(film, cos_theta, observer, terms, shat, arithmetic, layer)


def khr_rgb(film, cos_theta, observer, terms, shat, arithmetic, layer):
    """method="khr": glTF's fixed formula, its knobs checked to be at their defaults."""
    for name, value, default in (("observer", observer, DEFAULT_OBSERVER),
                                 ("terms", terms, 2), ("shat", shat, "exact")):
        if value != default:
            raise ValueError(f"method='khr' is the glTF extension's fixed formula (linear "
                             f"Rec. 709 RGB, M = 2): {name}={value!r} does not apply; "
                             f"leave {name} at its default {default!r}")
    return _khr_jit(film, cos_theta)


def _bands_rgb(method):
    """method="spectral" / "fourier": the band integrals, specialised to the film."""
    def run(film, cos_theta, observer, terms, shat, arithmetic, layer):
        return _rgb_jit(film, cos_theta, observer, method, terms, shat,
                        choose_arithmetic(film, arithmetic), choose_layer(film, layer))
    return run


@functools.partial(jax.jit, static_argnums=(2, 3, 4, 5, 6, 7))
def _rgb_jit(film, cos_theta, observer, method, terms, shat, arithmetic, layer):
    film, c = broadcast_all(film, cos_theta)
    if layer == "bare":
        return bare_bands(film, c, observer, shat=shat, arithmetic=arithmetic)
    return _BAND_FUNCTIONS[method](film, c, observer, terms, shat, arithmetic)


#: the band reflectance of each method of `rgb_reflectance` (one film, its film layer)
_BAND_FUNCTIONS = {
    "spectral": lambda film, c, observer, terms, shat, arithmetic: spectral_bands(
        film, c, observer, arithmetic=arithmetic),
    "fourier": lambda film, c, observer, terms, shat, arithmetic: fourier_bands(
        film, c, observer, terms=terms, shat=shat, arithmetic=arithmetic),
}


class BandMethod:
    """A method of `rgb_reflectance` only (a registry row's ``impl``, `core.methods`): its
    ``rgb(film, cos_theta, observer, terms, shat, arithmetic, layer)`` gives the film's band
    reflectances on validated inputs. A method of the shading entry points that is also
    offered by `rgb_reflectance` has the same hook on its shading object (``khr``)."""

    def __init__(self, name: str):
        self.name = name
        self.rgb = _bands_rgb(name)

    def __repr__(self):
        return f"<band method {self.name!r}>"


SPECTRAL, FOURIER = BandMethod("spectral"), BandMethod("fourier")


def band_centroids(observer=DEFAULT_OBSERVER) -> np.ndarray:
    """λ̄_j = Σ_k W⁺_kj λ_k / Σ_k W⁺_kj (nm, (J,)), the centroid of band j's positive part
    (Stiles & Burch's colour-matching functions have negative lobes, left out here)."""
    obs = get_observer(observer)
    w = np.maximum(np.asarray(obs.weights, float), 0.0)
    return (w * np.asarray(obs.wavelengths, float)[:, None]).sum(0) / w.sum(0)


def band_film(film: Film, observer=DEFAULT_OBSERVER) -> Film:
    """The constant-index film of each band: a dispersive film's indices evaluated at the band
    centroids `band_centroids` (fields of shape (J,), band j in entry j). The real-time
    methods' approximation of dispersion (core/methods.py: ``dispersion="bands"``): each band
    sees the film at one wavelength. The film's and outer medium's κ are dropped (K 29 has no
    absorbing film); the base keeps n + iκ. Measured error: docs/studies/materials.md."""
    lam = band_centroids(observer)

    def at(x):
        return x(jnp.asarray(lam)) if V._is_model(x) else jnp.asarray(x)

    eb = at(film.eta_base)
    return Film(jnp.asarray(film.thickness), jnp.real(at(film.eta_film)), jnp.real(eb),
                jnp.imag(eb) + jnp.asarray(film.kappa_base), jnp.real(at(film.eta_outer)))


def per_band(fn, film: Film, *args, observer=DEFAULT_OBSERVER):
    """``fn(film, *args)`` (..., J) of a dispersive single film, band j computed with the film
    at band j's centroid (`band_film`): fn runs once on a film batched over a trailing band
    axis (the other arguments get a unit axis) and the diagonal is kept."""
    if not isinstance(film, Film) or np.ndim(film.thickness) != 0:
        raise ValueError("the real-time methods take a dispersive Film with a scalar thickness "
                         "(vmap over thicknesses); a Stack needs an exact method")
    bf = band_film(film, observer)
    out = fn(bf, *(jnp.asarray(a)[..., None] for a in args))
    return jnp.diagonal(out, axis1=-2, axis2=-1)


@functools.partial(jax.jit, static_argnums=2)
def _stack_rgb_jit(stack, cos_theta, observer):
    return stack_bands(stack, cos_theta, observer)


def stack_bands(stack: Stack, cos_theta, observer=DEFAULT_OBSERVER):
    """Σ_k W_kj R(θ₁, λ_k) of a `Stack` (`optics.stack`; every index evaluated at each λ_k):
    shape broadcast(batch, cos θ₁) + (J,). No validation."""
    obs = get_observer(observer)
    dtype = jnp.result_type(cos_theta, float)
    lam = jnp.asarray(obs.wavelengths, dtype)
    r = stack_reflectance_traced(expand_batch(stack), jnp.asarray(cos_theta, dtype)[..., None],
                                 lam)
    return jnp.matmul(r, jnp.asarray(obs.weights, r.dtype), precision=jax.lax.Precision.HIGHEST)


def spectral_bands(film: Film, cos_theta, observer=DEFAULT_OBSERVER, *, arithmetic="complex"):
    """Σ_k W_kj R(θ₁, λ_k): exact band reflectance (broadcast inputs, no validation); a
    `Stack` runs `stack_bands`."""
    if isinstance(film, Stack):
        return stack_bands(film, cos_theta, observer)
    obs = get_observer(observer)
    dtype = jnp.result_type(cos_theta, float)
    lam = jnp.asarray(obs.wavelengths, dtype)
    ifc = film_interfaces(film, cos_theta, arithmetic=arithmetic)
    ifc = jax.tree.map(lambda a: a[..., None], ifc)  # wavelength axis last
    r = jnp.mean(polarised_reflectance(ifc, jnp.asarray(film.thickness)[..., None], lam), axis=0)
    return jnp.matmul(r, jnp.asarray(obs.weights, r.dtype), precision=jax.lax.Precision.HIGHEST)


def fourier_bands(film: Film, cos_theta, observer=DEFAULT_OBSERVER, *, terms=2,
                  shat="exact", arithmetic="complex", partial_sums: bool = False):
    """BB17 Fourier-domain band reflectance (K 4), M = `terms` (broadcast inputs).

    With ``partial_sums=True``, every M' = 0 … `terms` at once, stacked on a leading axis
    (`series.fourier_band_reflectance`).
    """
    st = series_terms(film, cos_theta, arithmetic=arithmetic)
    dtype = jnp.result_type(cos_theta, float)
    s0 = shat_at_zero(observer, dtype, shat)
    per_pol = fourier_band_reflectance(
        st, lambda m: sensitivity_ft(-m * st.opd, observer, shat=shat), terms, s0,
        partial_sums=partial_sums)
    return jnp.mean(per_pol, axis=1 if partial_sums else 0)
