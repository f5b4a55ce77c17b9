"""The soap bubble of `thinfilm-jax render --scene bubble` (`scene`; the equations are in its
module docstring): the draining film's thickness (Mysels, Shinoda & Frankel 1959), each
pixel's path through the two walls, and the spectral factors of the path's terms from the
exact one-layer stack (`optics.stack`, s and p carried apart).

Example (d → 0: no reflection, full transmission, so the bubble shows the map behind it):
    >>> import numpy as np
    >>> r, t = bubble_factors([np.zeros(1), np.zeros(1)], np.ones(1))
    >>> bool(np.allclose(r, 0.0, atol=1e-12)), bool(np.allclose(t, 1.0))
    (True, True)
"""

from __future__ import annotations

import numpy as np

from ..core.stack import Stack
from ..optics.materials import refractive_index
from ..spectral.spectra import DEFAULT_OBSERVER, get_observer

__all__ = ["bubble_thickness", "bubble_paths", "bubble_factors"]


def bubble_thickness(z, top: float = 30.0, bottom: float = 1200.0):
    """d = top + (bottom − top)·√(ψ/π), ψ = arccos z the polar angle from the top pole (nm)."""
    psi = np.arccos(np.clip(z, -1.0, 1.0))
    return top + (bottom - top) * np.sqrt(psi / np.pi)


def bubble_paths(p, dirs, cos, orders: int = 1):
    """The events of each pixel's path (module docstring): the wall points [p₁, p₂, …,
    p_{orders+2}] and the directions [ω_r, ω, ω⁽¹⁾, …, ω⁽ᴹ⁾] the map is read in."""
    points, out_dirs = [p], [dirs + 2 * cos[..., None] * p]  # ω_r = ω − 2⟨ω, n⟩ n
    q, w = p, dirs
    out_dirs.append(w)
    for m in range(orders + 1):
        q = q + 2 * cos[..., None] * w  # the chord to the next wall point
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        points.append(q)
        if m < orders:
            w = w - 2 * np.sum(w * q, -1, keepdims=True) * q  # inner mirror reflection
            out_dirs.append(w)
    return points, out_dirs


def bubble_factors(thicknesses, cos, eta_film="water", observer: str = DEFAULT_OBSERVER):
    """Spectral factors F (…, I) at the observer's wavelengths of the bubble's terms:
    [R(d₁), T(d₁)T(d₂), T(d₁)R(d₂)T(d₃), …] (s and p carried apart, then averaged), for the
    wall thicknesses `thicknesses` [d₁, d₂, …] (…) and cos θ (…)."""
    import jax.numpy as jnp

    from ..optics.stack import stack_reflectance, stack_transmittance

    lam = jnp.asarray(get_observer(observer).wavelengths, float)
    eta = refractive_index(eta_film) if isinstance(eta_film, str) else eta_film
    c = jnp.asarray(cos, float)[..., None]

    def rt(d, pol):
        st = Stack(jnp.asarray(d, float)[..., None, None], (eta,), 1.0)
        return (np.asarray(stack_reflectance(st, c, lam, pol)),
                np.asarray(stack_transmittance(st, c, lam, pol)))

    out = None
    for pol in ("s", "p"):
        r, t = zip(*(rt(d, pol) for d in thicknesses))
        terms = [r[0], t[0] * t[1]]
        inner = t[0]
        for m in range(1, len(thicknesses) - 1):
            inner = inner * r[m]
            terms.append(inner * t[m + 1])
        out = terms if out is None else [0.5 * (a + b) for a, b in zip(out, terms)]
    return out
