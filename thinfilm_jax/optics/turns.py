r"""(cos 2πu, sin 2πu) of a phase in turns without a libm call (`sincos_turns`): the one
trigonometric kernel of the film phases (`airy`, `stack`, `series`, the Ŝ table's carrier).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import Array

__all__ = ["sincos_turns"]


def _taylor(n: int, odd: bool) -> tuple:
    """Taylor coefficients of sin(x)/x − 1 (odd) or cos(x) − 1 in powers of z = x², z¹ … zⁿ."""
    return tuple((-1.0) ** k / math.factorial(2 * k + odd) for k in range(1, n + 1))


# Truncation error of the series at |x| = π/4 (first omitted term): float64 sin to x¹⁵,
# cos to x¹⁶: ≤ 4.6e-17, 2e-18 (< ½ ulp of 1); float32 sin to x⁹, cos to x¹⁰: ≤ 1.8e-9, 1.2e-10.
_SIN = {8: _taylor(7, True), 4: _taylor(4, True)}
_COS = {8: _taylor(8, False), 4: _taylor(5, False)}


def _poly(coeffs, z):
    acc = coeffs[-1]
    for a in reversed(coeffs[:-1]):
        acc = acc * z + a
    return acc * z


@jax.custom_jvp
def sincos_turns(u: Array) -> tuple[Array, Array]:
    r"""(cos 2πu, sin 2πu) for real `u` in turns, vectorisable (no libm call).

    Range reduction in turns is exact in floating point: r = u − round(u) ∈ [−½, ½], then
    the quadrant m = round(4r) ∈ {−2, …, 2} and f = r − m/4 ∈ [−⅛, ⅛] (both exact for
    |u| < 2^(p−1)), x = 2πf ∈ [−π/4, π/4] with one rounding. sin x and cos x are their Taylor
    series, truncated below ½ ulp (float64 to x¹⁵ / x¹⁶), and the quadrant rotates
    (cos, sin) by m·90°. Errors ≤ 2 ulp of 1 against NumPy for any u (tests/optics/test_sincos.py).
    The derivative is exact calculus, d(cos, sin)/du = 2π(−sin, cos) (custom JVP).

    Example:
        >>> c, s = sincos_turns(jnp.array([0.0, 0.125, 0.75]))
        >>> [round(float(v), 12) for v in c], [round(float(v), 12) for v in s]
        ([1.0, 0.707106781187, 0.0], [0.0, 0.707106781187, -1.0])
    """
    u = jnp.asarray(u)
    key = 8 if jnp.finfo(u.dtype).bits > 32 else 4
    r = u - jnp.round(u)
    m = jnp.round(4.0 * r)
    x = (2.0 * math.pi) * (r - 0.25 * m)
    z = x * x
    s = x + x * _poly(_SIN[key], z)
    c = 1.0 + _poly(_COS[key], z)
    odd = jnp.abs(m) == 1.0  # ±90°: swap
    c, s = jnp.where(odd, s, c), jnp.where(odd, c, s)
    c = jnp.where((m == 1.0) | (jnp.abs(m) == 2.0), -c, c)
    s = jnp.where((m == -1.0) | (jnp.abs(m) == 2.0), -s, s)
    return c, s


@sincos_turns.defjvp
def _sincos_turns_jvp(primals, tangents):
    c, s = sincos_turns(primals[0])
    du = (2.0 * math.pi) * tangents[0]
    return (c, s), (-s * du, c * du)
