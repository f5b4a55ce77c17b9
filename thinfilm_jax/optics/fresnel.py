r"""Fresnel amplitudes at the two interfaces of a film (outer 1 | film 2 | base 3).

Everything is written with the *normal wavenumbers* $q_k = \eta_k\cos\theta_k
= \sqrt{\eta_k^2 - \eta_1^2\sin^2\theta_1}$ (Snell's law is built in, no division by η),
with the branch $\operatorname{Im} q_k \ge 0$ so that waves in absorbing or evanescent
media decay (SPEC §2). In these variables (Born & Wolf §1.5; the `tmm` sign convention)

$$ r^s_{ab} = \frac{q_a - q_b}{q_a + q_b}, \qquad
   r^p_{ab} = \frac{\varepsilon_b q_a - \varepsilon_a q_b}{\varepsilon_b q_a + \varepsilon_a q_b},
   \qquad \varepsilon = \eta^2 . $$

Two arithmetic paths, chosen statically ("a scene pays only for what it needs"):

* ``arithmetic="real"``: real arithmetic. Valid when κ₃ = 0 and there is no total
  internal reflection anywhere (η₂ ≥ η₁ and η₃ ≥ η₁); amplitudes are real and signed.
* ``arithmetic="complex"``: complex arithmetic; absorbing bases (κ₃ > 0), TIR at either
  interface (η₁ > η₂ or η₁ > η₃) and evanescent films.

Singular points are guarded with the double-where pattern so that values *and*
gradients stay finite at θ₁ = 90° (q₁ = 0), at η₂ = η₁ (no 1|2 interface) and at
q = 0 (critical angle).

Example (normal incidence: r_p = −r_s in this convention, so R_s = R_p = ((η₂ − η₁)/(η₂ + η₁))²;
Brewster's angle tan θ₁ = η₂/η₁: r_p = 0; a base matched to the film: r₂₃ = 0):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.optics.fresnel import film_interfaces
    >>> film = Film(100.0, 1.5, 1.5)
    >>> ifc = film_interfaces(film, 1.0, arithmetic="real")
    >>> [round(float(r), 6) for r in ifc.r12], [float(r) for r in ifc.r23]  # (s, p)
    ([-0.2, 0.2], [0.0, 0.0])
    >>> r12 = film_interfaces(film, np.cos(np.arctan(1.5)), arithmetic="real").r12
    >>> round(float(r12[0]), 4), bool(abs(r12[1]) < 1e-12)
    (-0.3846, True)
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core.film import Film

__all__ = [
    "safe_sqrt",
    "sqrt_upper_parts",
    "sqrt_upper",
    "complex_dtype",
    "as_complex",
    "safe_div",
    "sin2_outer",
    "interface_amplitudes",
    "Interfaces",
    "film_interfaces",
    "normal_reflectance",
    "fresnel_schlick",
]

ARITHMETIC = ("real", "complex")


def safe_sqrt(x: Array) -> Array:
    """√x for x ≥ 0 with a finite (zero) gradient at x = 0 (double-where)."""
    pos = x > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def sqrt_upper_parts(x: Array, y: Array) -> tuple[Array, Array]:
    r"""(Re, Im) of √(x + iy) on the branch Im ≥ 0, finite gradient at 0 (double-where).

    Written on real parts, which XLA:CPU fuses with its neighbours (its own complex square
    root is several separate loops): with t = √((|z| + |x|)/2) ≥ √(|z|/2) (no cancellation),
    √z = ±t + i|y|/(2t) for x ≥ 0 (sign of y), and y/(2t) + it for x < 0.
    """
    zero = (x == 0) & (y == 0)
    x = jnp.where(zero, 1.0, x)
    t = jnp.sqrt(0.5 * (jnp.hypot(x, y) + jnp.abs(x)))
    h = 0.5 * y / t
    right = x >= 0
    re = jnp.where(right, jnp.where(y < 0, -t, t), h)
    im = jnp.where(right, jnp.abs(h), t)
    return jnp.where(zero, 0.0, re), jnp.where(zero, 0.0, im)


def sqrt_upper(z: Array) -> Array:
    """Complex √z on the branch Im ≥ 0, finite gradient at z = 0 (`sqrt_upper_parts`)."""
    return jax.lax.complex(*sqrt_upper_parts(jnp.real(z), jnp.imag(z)))


def complex_dtype(*xs):
    """The complex dtype matching the real precision of `xs` (float32 → complex64, …); real
    and complex inputs may be mixed (each is read alone: no dtype promotion between them,
    which strict promotion forbids)."""
    bits = 0
    for x in xs:  # Python numbers and weakly typed arrays follow the others, as in promotion
        if type(x) in (bool, int, float, complex) or getattr(x, "weak_type", False):
            continue
        dt = jnp.result_type(x)
        if jnp.issubdtype(dt, jnp.inexact):
            bits = max(bits, np.dtype(jnp.finfo(dt).dtype).itemsize)
    real = (jax.dtypes.canonicalize_dtype(np.float64 if bits > 4 else np.float32) if bits
            else jnp.result_type(float))
    return np.result_type(real, np.complex64)


def as_complex(x: Array) -> Array:
    """`x` as a complex array of matching precision (explicit, for strict dtype promotion)."""
    x = jnp.asarray(x)
    return x if jnp.iscomplexobj(x) else jax.lax.complex(x, jnp.zeros_like(x))


def safe_div(num: Array, den: Array, limit=0.0) -> Array:
    """num/den, `limit` where den == 0 (double-where).

    Complex operands are divided on (re, im): num·conj(den)/|den|², den first scaled by
    1/(|Re den| + |Im den|) (no overflow or underflow of |den|²), one reciprocal shared by
    both parts; XLA:CPU fuses this, its own complex division is a separate loop.
    """
    zero = den == 0
    if not (jnp.iscomplexobj(num) or jnp.iscomplexobj(den)):
        return jnp.where(zero, limit, num / jnp.where(zero, 1.0, den))
    num, den = as_complex(num), as_complex(jnp.where(zero, 1.0, den))
    dr, di = jnp.real(den), jnp.imag(den)
    k = 1.0 / (jnp.abs(dr) + jnp.abs(di))
    dr, di = dr * k, di * k
    k = k / (dr * dr + di * di)
    nr, ni = jnp.real(num), jnp.imag(num)
    q = jax.lax.complex((nr * dr + ni * di) * k, (ni * dr - nr * di) * k)
    return jnp.where(zero, limit, q)


def sin2_outer(eta_outer, cos_theta) -> Array:
    """η₁² sin²θ₁, computed as η₁²(1−c)(1+c) to keep precision near normal incidence."""
    return eta_outer**2 * (1.0 - cos_theta) * (1.0 + cos_theta)


def interface_amplitudes(qa, qb, eps_a, eps_b) -> Array:
    """Fresnel amplitudes (r_s, r_p) stacked on a leading axis of size 2.

    Where both wavenumbers vanish (identical media at grazing incidence) there is no
    interface and the amplitude is 0.
    """
    rs = safe_div(qa - qb, qa + qb)
    rp = safe_div(eps_b * qa - eps_a * qb, eps_b * qa + eps_a * qb)
    return jnp.stack(jnp.broadcast_arrays(rs, rp))


class Interfaces(NamedTuple):
    """Amplitudes of one film at one angle; leading axis of r12, r23 is (s, p)."""

    r12: Array  # outer → film
    r23: Array  # film → base
    q2: Array  # η₂ cos θ₂ (real on the dielectric path)


def film_interfaces(film: Film, cos_theta, *, arithmetic: str = "complex") -> Interfaces:
    """Fresnel amplitudes r₁₂, r₂₃ and the film's normal wavenumber q₂ at cos θ₁.

    Args:
        film: the film (fields broadcast with `cos_theta`).
        cos_theta: cos θ₁ in [0, 1], angle of incidence in the outer medium.
        arithmetic: "real" (real arithmetic, no TIR, κ₃ ignored) or "complex".
    """
    eta1, eta2, eta3, kappa3 = film.eta_outer, film.eta_film, film.eta_base, film.kappa_base
    c = jnp.asarray(cos_theta)
    s2 = sin2_outer(eta1, c)
    q1 = eta1 * c
    if arithmetic == "real":
        q2 = safe_sqrt(eta2**2 - s2)
        q3 = safe_sqrt(eta3**2 - s2)
        eps3 = eta3**2
    elif arithmetic == "complex":
        # explicit real → complex casts (no implicit promotion: works under "strict")
        cdt = complex_dtype(c, eta1, eta2, eta3, kappa3)
        n3 = jnp.asarray(eta3, cdt) + 1j * jnp.asarray(kappa3, cdt)
        eps3 = n3 * n3
        q2 = sqrt_upper(jnp.asarray(eta2**2 - s2, cdt))
        q3 = sqrt_upper(eps3 - jnp.asarray(s2, cdt))
        q1 = jnp.asarray(q1, cdt)
    else:
        raise ValueError(f"unknown arithmetic {arithmetic!r}; expected one of {ARITHMETIC}")
    eps1, eps2 = eta1**2, eta2**2
    if arithmetic == "complex":
        eps1, eps2 = jnp.asarray(eps1, cdt), jnp.asarray(eps2, cdt)
    r12 = interface_amplitudes(q1, q2, eps1, eps2)
    r23 = interface_amplitudes(q2, q3, eps2, eps3)
    return Interfaces(r12, r23, q2)


def normal_reflectance(eta, kappa=0.0, eta_outer=1.0) -> Array:
    r"""Reflectance at normal incidence of a base η + iκ under a medium η₁ (both polarisations):
    F₀ = ((η − η₁)² + κ²) / ((η + η₁)² + κ²) (Born & Wolf §13.2; κ = 0: a dielectric)."""
    eta, kappa, eta_outer = jnp.asarray(eta), jnp.asarray(kappa), jnp.asarray(eta_outer)
    k2 = kappa * kappa
    return ((eta - eta_outer) ** 2 + k2) / ((eta + eta_outer) ** 2 + k2)


def fresnel_schlick(f0, cos_theta) -> Array:
    r"""Schlick's approximation of the unpolarised Fresnel reflectance (Schlick 1994, Eq. 24;
    SPEC §10): $F = F_0 + (1 - F_0)(1 - \cos\theta)^5$, broadcasting `f0` (e.g. the bands
    (..., J) of a tint, or `normal_reflectance`) against `cos_theta` ∈ [0, 1] (clipped there,
    so a grazing or back-facing cosine gives 1, not a value above it).

    Example (exact at normal incidence and at grazing; glass at 60°: 0.070 against the exact
    unpolarised 0.089):
        >>> from thinfilm_jax.optics.fresnel import fresnel_schlick, normal_reflectance
        >>> f0 = normal_reflectance(1.5)
        >>> [round(float(fresnel_schlick(f0, c)), 4) for c in (1.0, 0.5, 0.0)]
        [0.04, 0.07, 1.0]
    """
    f0 = jnp.asarray(f0)
    c = jnp.clip(jnp.asarray(cos_theta), 0.0, 1.0)
    m = 1.0 - c
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)
