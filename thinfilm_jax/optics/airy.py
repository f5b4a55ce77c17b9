r"""Exact reflectance of one film by Airy summation (SPEC §2).

Per polarisation, with the amplitudes of `fresnel.film_interfaces` and the round-trip
phase δ = 2β = 4π d q₂ / λ = 2π D / λ (D = 2 η₂ d cos θ₂, K 5):

$$ r = \frac{r_{12} + r_{23} e^{i\delta}}{1 + r_{12} r_{23} e^{i\delta}},\qquad
   R = \tfrac12\left(|r_s|^2 + |r_p|^2\right). $$

It is evaluated in the expanded real form (see `polarised_reflectance`); on the dielectric
path the amplitudes are real and R = (R₁₂ + R₂₃ + 2r₁₂r₂₃ cos δ)/(1 + R₁₂R₂₃ + 2r₁₂r₂₃ cos δ).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from .fresnel import Interfaces, film_interfaces
from .index import is_index_model
from .turns import sincos_turns

__all__ = [
    "choose_arithmetic",
    "polarised_reflectance",
    "airy_reflectance",
    "BLOCK",
    "broadcast_all",
]


def choose_arithmetic(film: Film, arithmetic: str = "auto") -> str:
    """Resolve ``arithmetic="auto"``: the real dielectric path when the (concrete) film allows it.

    The dielectric path needs κ₃ = 0, η₂ ≥ η₁ and η₃ ≥ η₁ (no TIR). With traced fields
    (inside `jit`) "auto" cannot look at the values and takes the general path; pass
    ``arithmetic="real"`` explicitly to specialise a jitted dielectric scene.
    ``arithmetic="real"`` with a concrete κ₃ > 0 (or a complex η₃) raises a ValueError: the
    real path cannot represent absorption. With a traced κ₃ it is not checked (the
    dielectric path reads η₃ only, so κ₃ is ignored there).
    """
    import numpy as np

    V.check_choice("arithmetic", arithmetic, ("auto", "real", "complex"))
    if arithmetic == "real":
        if jnp.iscomplexobj(film.eta_base):
            raise ValueError("arithmetic='real' cannot represent a complex eta_base; use "
                             "arithmetic='complex' or 'auto'")
        if V.is_concrete(film.kappa_base) and np.any(np.asarray(film.kappa_base) != 0):
            raise ValueError(f"arithmetic='real' needs kappa_base = 0 (real arithmetic, no "
                             f"absorption); got kappa_base = "
                             f"{float(np.max(np.asarray(film.kappa_base)))!r}: use "
                             f"arithmetic='complex' or 'auto'")
    if arithmetic != "auto":
        return arithmetic
    if not all(V.is_concrete(x) for x in film) or any(jnp.iscomplexobj(x) for x in film):
        return "complex"

    k, e1, e2, e3 = (np.asarray(x) for x in (film.kappa_base, film.eta_outer, film.eta_film,
                                             film.eta_base))
    if np.all(k == 0) and np.all(e2 >= e1) and np.all(e3 >= e1):
        return "real"
    return "complex"


def polarised_reflectance(ifc: Interfaces, thickness, wavelength) -> Array:
    """R_s, R_p (leading axis 2) from interface amplitudes at wavelength λ (nm).

    Expanded real form of |r₁₂ + r₂₃e^{iδ}|² / |1 + r₁₂r₂₃e^{iδ}|² with g = |e^{iδ}|
    (g = 1 unless the film is evanescent):
    num = R₁₂ + g²R₂₃ + 2g Re(r̄₁₂r₂₃ e^{iRe δ}), den = 1 + g²R₁₂R₂₃ + 2g Re(r₁₂r₂₃ e^{iRe δ}).
    The products are formed once per angle; each wavelength costs one cos/sin pair shared
    by both polarisations, evaluated in turns (δ/2π = 2 d q₂/λ, `sincos_turns`).
    """
    return jnp.stack(_reflectance_sp(ifc, thickness, wavelength))


def _reflectance_sp(ifc: Interfaces, thickness, wavelength) -> tuple[Array, Array]:
    """(R_s, R_p) of `polarised_reflectance` as two arrays: one elementwise program (XLA
    fuses it into a single loop; a stacked polarisation axis would be materialised)."""
    thickness, wavelength = jnp.broadcast_arrays(thickness, wavelength)  # explicit ranks
    nd = max(jnp.ndim(ifc.q2), thickness.ndim, jnp.ndim(ifc.r12) - 1)

    def lift(x):  # leading unit axes, no implicit rank promotion
        return jnp.reshape(x, (1,) * (nd - jnp.ndim(x)) + jnp.shape(x))

    q2, d, lam = lift(ifc.q2), lift(thickness), lift(wavelength)
    # δ/2π = D/λ with D = 2 d Re q₂ (K 5), the same rounding as `series.series_reflectance`;
    # Re δ and Im δ formed separately (no implicit real → complex promotion, so this also
    # runs under jax_numpy_dtype_promotion="strict")
    cos_d, sin_d = sincos_turns(2.0 * d * jnp.real(q2) / lam)
    complex_path = jnp.iscomplexobj(ifc.r12)
    if complex_path:
        g = jnp.exp((-2.0 * math.pi) * (2.0 * d * jnp.imag(q2) / lam))
        g2 = g * g
    out = []
    for pol in range(2):
        r12, r23 = lift(ifc.r12[pol]), lift(ifc.r23[pol])
        if complex_path:
            a12, b12, a23, b23 = jnp.real(r12), jnp.imag(r12), jnp.real(r23), jnp.imag(r23)
            R12 = a12 * a12 + b12 * b12
            R23 = a23 * a23 + b23 * b23
            b_re, b_im = a12 * a23 + b12 * b23, a12 * b23 - b12 * a23  # r̄₁₂ r₂₃
            p_re, p_im = a12 * a23 - b12 * b23, a12 * b23 + b12 * a23  # r₁₂ r₂₃
            num = R12 + g2 * R23 + 2.0 * g * (b_re * cos_d - b_im * sin_d)
            den = 1.0 + g2 * (R12 * R23) + 2.0 * g * (p_re * cos_d - p_im * sin_d)
        else:
            p = r12 * r23
            x = 2.0 * p * cos_d
            num = r12 * r12 + r23 * r23 + x
            den = 1.0 + p * p + x
        # den = 0 only if |r12 r23 e^{iδ}| = 1 with opposite phase (grazing, TIR corner): R → 1
        zero = den == 0
        out.append(jnp.where(zero, 1.0, num / jnp.where(zero, 1.0, den)))
    return tuple(out)


def airy_reflectance(film: Film, cos_theta, wavelength, *, arithmetic: str = "auto") -> Array:
    """Unpolarised reflectance R(θ₁, λ) of `film` (SPEC §2, exact).

    Args:
        film: `Film`; fields broadcast with the other arguments (a complex `eta_base` is
            read as η₃ + iκ₃, `Film.real_base`). An index may be an index model
            (`refractive_index`, SPEC §12): it is evaluated at each wavelength (the film's
            one-layer `Stack`, `stack_reflectance`; thickness may vary, the indices are
            shared).
        cos_theta: cos θ₁ ∈ [0, 1] in the outer medium (excursions of a few ulps, e.g.
            float32 cos(π/2) = −4.4e-8, are clamped).
        wavelength: λ in nm (> 0).
        arithmetic: "auto" | "real" | "complex" (see `choose_arithmetic`; "real" with
            κ₃ > 0 raises).

    Returns:
        R with the broadcast shape of all arguments, dtype following the inputs.

    Example:
        >>> round(float(airy_reflectance(Film(0.0, 1.5, 1.5), 1.0, 550.0)), 12)  # glass, 4 %
        0.04
    """
    if isinstance(film, Film) and any(is_index_model(getattr(film, k))
                                      for k in ("eta_film", "eta_base", "eta_outer")):
        # index models (SPEC §12): each evaluated at every wavelength, by the one-layer
        # stack's recursion (the same R as §2 to 1e-12; `arithmetic` does not apply)
        from .stack import stack_reflectance

        return stack_reflectance(V.check_material(film), cos_theta, wavelength)
    film = V.check_film(film)
    cos_theta = V.check_cos_theta(cos_theta)
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    V.check_broadcast([("film", jnp.zeros(film.shape)), ("cos_theta", cos_theta),
                       ("wavelength", wavelength)])
    return _airy_jit(film, cos_theta, wavelength, choose_arithmetic(film, arithmetic))


# Pairs per block of the blocked evaluation (see `_airy_jit`): the intermediates of a block
# (a few dozen float64 arrays) stay in the L2 cache.
BLOCK = 4096


@functools.partial(jax.jit, static_argnames="arithmetic")
def _airy_jit(film, cos_theta, wavelength, arithmetic):
    """Without angle × wavelength structure (every pair has its own Fresnel terms, the "flat"
    layout) the pairs run in blocks of `BLOCK` (`jax.lax.map`): XLA:CPU writes every
    intermediate it does not fuse to memory, and at 10⁶ pairs those round trips, not the
    arithmetic, dominated. With structure, `_airy_direct` forms the Fresnel terms per angle."""
    leaves, tree = jax.tree.flatten((film, cos_theta, wavelength))
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in leaves))
    n = math.prod(shape)
    no_wavelength = jax.tree.leaves((film, cos_theta))
    if math.prod(jnp.broadcast_shapes(*(jnp.shape(x) for x in no_wavelength))) < n \
            or n <= 2 * BLOCK:
        return _airy_direct(film, cos_theta, wavelength, arithmetic)
    mapped = [i for i, x in enumerate(leaves) if jnp.size(x) > 1]  # the others are constants

    def block(xs):
        vals = [None if i in mapped else jnp.reshape(x, ()) for i, x in enumerate(leaves)]
        for i, x in zip(mapped, xs):
            vals[i] = x
        return _airy_direct(*jax.tree.unflatten(tree, vals), arithmetic)

    xs = tuple(jnp.reshape(jnp.broadcast_to(leaves[i], shape), (n,)) for i in mapped)
    return jnp.reshape(jax.lax.map(block, xs, batch_size=BLOCK), shape)


def _airy_direct(film, cos_theta, wavelength, arithmetic):
    # Fresnel terms depend on (film, θ) only: form them on that shape, then broadcast to λ.
    film, cos_theta = broadcast_all(film, cos_theta)
    shape = jnp.broadcast_shapes(cos_theta.shape, jnp.shape(wavelength))
    pad = (1,) * (len(shape) - cos_theta.ndim)
    ifc = film_interfaces(film, cos_theta, arithmetic=arithmetic)
    ifc = Interfaces(*(x.reshape(*x.shape[:x.ndim - cos_theta.ndim], *pad, *cos_theta.shape)
                       for x in ifc))
    d = jnp.reshape(film.thickness, pad + cos_theta.shape)
    r_s, r_p = _reflectance_sp(ifc, d, wavelength)
    return jnp.broadcast_to(0.5 * (r_s + r_p), shape)


def broadcast_all(film: Film, *args):
    """Broadcast every film field and every extra argument to one common shape."""
    leaves, tree = jax.tree.flatten((film, args))
    film, args = jax.tree.unflatten(tree, jnp.broadcast_arrays(*leaves))
    return (film, *args)
