r"""Oscillator dispersion models: the dielectric function as a sum of Kramers–Kronig
consistent terms, an index model with differentiable parameters (SPEC §14).

`DielectricIndex(eps_inf, terms)` is the index model

$$ \varepsilon(E) = \varepsilon_\infty + \sum_j \varepsilon_j(E),\qquad n + i\kappa =
   \sqrt{\varepsilon}\ (\kappa \ge 0),\qquad E\,[\mathrm{eV}] = \frac{hc}{\lambda}, $$

hc = 1239.84198 eV nm by default (`core.units.HC_EV_NM`; ``hc=1240.0`` reproduces J.A.
Woollam's WVASE and CompleteEASE, which convert with 1240: their Lorentz and Gaussian n, k
tables agree to 3e-7 with 1240 and to 1.6e-3 with 1239.84, tests/optics/test_oscillators.py).
Each term holds k oscillators as arrays of shape (k,) (leaves: ``jax.grad`` reaches every
amplitude, broadening and energy, and `fit_ellipsometry` frees them by name,
``"eta[0].terms[0].energy[1]"``, ``"eta[0].eps_inf"``: `fit.params`). The sign convention is
the library's (κ ≥ 0 absorbs: Im ε ≥ 0). The terms:

* `Lorentz` (WVASE's Lorentz oscillator): $\varepsilon_j = A / (E_0^2 - E^2 - iBE)$, A in
  eV², broadening B and centre E₀ in eV.
* `Gaussian` (CompleteEASE's Gaussian; D. De Sousa Meneses et al., J. Non-Cryst. Solids
  351, 124 (2005)): $\varepsilon_2 = A[e^{-((E - E_0)/\sigma)^2} - e^{-((E + E_0)/\sigma)^2}]$,
  σ = B / (2√ln 2) (B the full width at half maximum), and its Kramers–Kronig transform in
  closed form with Dawson's integral $D(x) = e^{-x^2}\int_0^x e^{t^2}dt$:
  $\varepsilon_1 = \frac{2A}{\sqrt\pi}[D(\frac{E + E_0}{\sigma}) - D(\frac{E - E_0}{\sigma})]$
  (the Hilbert transform of $e^{-x^2}$ is $\frac{2}{\sqrt\pi}D(x)$; `dawson`).
* `TaucLorentz` (G. E. Jellison and F. A. Modine, Appl. Phys. Lett. 69, 371 (1996) and its
  erratum 69, 2137): $\varepsilon_2 = \frac{A E_0 C (E - E_g)^2}{(E^2 - E_0^2)^2 + C^2E^2}
  \frac{1}{E}$ for E > E_g, 0 below, with ε₁ the closed-form Kramers–Kronig integral of
  that paper (`_tauc_lorentz_eps1`; checked against a direct principal-value integral in
  the tests, and against CompleteEASE's table to its printed digits). C < 2E₀ is required.

Example (a Lorentz oscillator far below its resonance is a lossless dielectric of
ε = ε∞ + A/E₀²):
    >>> import numpy as np
    >>> m = lorentz(amplitude=[10.0], broadening=[0.1], energy=[8.0], eps_inf=1.0)
    >>> n = complex(m(1.0e5))  # λ = 100 µm: E = 0.0124 eV
    >>> abs(n.real ** 2 - (1.0 + 10.0 / 64.0)) < 1e-4, n.imag < 1e-5
    (True, True)
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core._validate import as_array, check_real, is_concrete
from ..core.units import HC_EV_NM
from .fresnel import sqrt_upper_parts
from .index import IndexModel

__all__ = ["DielectricIndex", "Gaussian", "Lorentz", "TaucLorentz", "dawson", "gaussian",
           "lorentz", "tauc_lorentz"]


# ----------------------------------------------------------------------------- Dawson
def _dawson_rybicki(x):
    """Dawson's integral by Rybicki's sampling sum (Numerical Recipes 3rd ed. §6.9.1, Eq.
    6.9.4 with h = 0.2, |n| ≤ 39: truncation error below e^{−(π/2h)²} ≈ 1e-27 and the tail
    below e^{−(39h − 0.2)²} ≈ 1e-25): the fallback where jax.scipy has no `dawsn`."""
    h = 0.2
    x0 = 2.0 * h * jnp.round(x / (2.0 * h))  # the nearest even multiple of h
    xp = x - x0
    n = jnp.arange(-39, 40, 2, dtype=x.dtype)  # odd n
    terms = jnp.exp(-(xp[..., None] - n * h) ** 2) / (n + x0[..., None] / h)
    return jnp.sum(terms, axis=-1) / math.sqrt(math.pi)


def dawson(x) -> Array:
    """Dawson's integral D(x) = e^{−x²} ∫₀ˣ e^{t²} dt (real x; `jax.scipy.special.dawsn`
    where this JAX has it, else `_dawson_rybicki`); differentiable, D'(x) = 1 − 2x D(x)."""
    x = jnp.asarray(x)
    fn = getattr(jax.scipy.special, "dawsn", None)
    return fn(x) if fn is not None else _dawson_rybicki(x)


# ----------------------------------------------------------------------------- terms
def _param(name, v):
    a = jnp.atleast_1d(jnp.asarray(check_real(name, as_array(name, v))))
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(jnp.result_type(float))
    if a.ndim != 1:
        raise ValueError(f"{name} must be a number or a 1-D sequence (one per oscillator); "
                         f"got shape {a.shape}")
    return a


def _positive(where, **arrays):
    for k, a in arrays.items():
        if is_concrete(a) and not np.all(np.asarray(a) > 0):
            raise ValueError(f"{where}: {k} must be > 0; got {np.asarray(a).tolist()}")


class _Term(eqx.Module):
    amplitude: Array
    broadening: Array
    energy: Array

    def __init__(self, amplitude, broadening, energy):
        a, b, e = (_param(k, v) for k, v in (("amplitude", amplitude),
                                              ("broadening", broadening), ("energy", energy)))
        if not (a.shape == b.shape == e.shape):
            raise ValueError(f"{type(self).__name__}: amplitude, broadening and energy must "
                             f"have one length (one per oscillator); got {a.shape}, "
                             f"{b.shape}, {e.shape}")
        _positive(type(self).__name__, broadening=b, energy=e)
        self.amplitude, self.broadening, self.energy = a, b, e

    def _cast(self, E):
        return (v.astype(E.dtype)[:, None] for v in (self.amplitude, self.broadening,
                                                     self.energy))


class Lorentz(_Term):
    """WVASE's Lorentz oscillators ε = Σ A / (E₀² − E² − iBE) (A eV², B and E₀ eV; module
    docstring). ``epsilon(E)`` → (ε₁, ε₂) of photon energies E (flattened, eV)."""

    def epsilon(self, E):
        a, b, e0 = self._cast(E)
        re, im = e0 * e0 - E * E, -b * E
        m = re * re + im * im
        return jnp.sum(a * re / m, axis=0), jnp.sum(-a * im / m, axis=0)


class Gaussian(_Term):
    """CompleteEASE's Gaussian oscillators (amplitude A, FWHM B, centre E₀ in eV), ε₁ by the
    closed-form Kramers–Kronig transform with Dawson's integral (module docstring)."""

    def epsilon(self, E):
        a, b, e0 = self._cast(E)
        s = b / (2.0 * math.sqrt(math.log(2.0)))
        up, dn = (E - e0) / s, (E + e0) / s
        e2 = a * (jnp.exp(-up * up) - jnp.exp(-dn * dn))
        e1 = (2.0 / math.sqrt(math.pi)) * a * (dawson(dn) - dawson(up))
        return jnp.sum(e1, axis=0), jnp.sum(e2, axis=0)


def _xlogx2(u):
    """u² ln|u| with its limit 0 (value and gradient) at u = 0 (double-where)."""
    z = u == 0
    us = jnp.where(z, 1.0, u)
    return jnp.where(z, 0.0, us * us * jnp.log(jnp.abs(us)))


def _tauc_lorentz_eps1(E, a, c, e0, eg):
    """ε₁ − ε∞ of Jellison & Modine (1996, with the erratum), one oscillator per row: the
    five terms of their Eq. (the `a_ln`, `a_atan`, the γ, and the two logarithms), the
    ln|E − E_g| of the last two combined into −(E − E_g)² ln|E − E_g| / E (finite at
    E = E_g, where each alone diverges)."""
    al = jnp.sqrt(4.0 * e0 * e0 - c * c)
    g2 = e0 * e0 - 0.5 * c * c  # γ²
    z4 = (E * E - g2) ** 2 + 0.25 * al * al * c * c  # ζ⁴
    e02, eg2 = e0 * e0, eg * eg
    a_ln = (eg2 - e02) * E * E + eg2 * c * c - e02 * (e02 + 3.0 * eg2)
    a_atan = (E * E - e02) * (e02 + eg2) + eg2 * c * c
    pi = math.pi
    t1 = a * c * a_ln / (2.0 * pi * z4 * al * e0) * jnp.log(
        (e02 + eg2 + al * eg) / (e02 + eg2 - al * eg))
    t2 = -a * a_atan / (pi * z4 * e0) * (pi - jnp.arctan((2.0 * eg + al) / c)
                                         + jnp.arctan((al - 2.0 * eg) / c))
    t3 = 2.0 * a * e0 * eg * (E * E - g2) / (pi * z4 * al) * (
        pi + 2.0 * jnp.arctan(2.0 * (g2 - eg2) / (al * c)))
    k = a * e0 * c / (pi * z4)
    t45 = k * (-_xlogx2(E - eg) / E + (E + eg) ** 2 / E * jnp.log(E + eg)
               - eg * jnp.log((e02 - eg2) ** 2 + eg2 * c * c))
    return t1 + t2 + t3 + t45


class TaucLorentz(_Term):
    """Tauc–Lorentz oscillators of a common band gap `gap` (Jellison & Modine 1996): amplitude
    A (eV), broadening C (eV, < 2E₀), centre E₀ (eV), gap E_g (eV, ≥ 0); module docstring."""

    gap: Array

    def __init__(self, amplitude, broadening, energy, gap):
        super().__init__(amplitude, broadening, energy)
        g = jnp.asarray(check_real("gap", as_array("gap", gap)))
        if not jnp.issubdtype(g.dtype, jnp.floating):
            g = g.astype(jnp.result_type(float))
        if g.ndim != 0:
            raise ValueError(f"TaucLorentz: gap must be one number (eV); got shape {g.shape}")
        if is_concrete(g) and not float(g) >= 0:
            raise ValueError(f"TaucLorentz: gap must be ≥ 0 eV; got {float(g)}")
        if is_concrete(self.broadening) and is_concrete(self.energy) and not np.all(
                np.asarray(self.broadening) < 2.0 * np.asarray(self.energy)):
            raise ValueError("TaucLorentz: each broadening C must be < 2 × its energy E₀ "
                             "(α = √(4E₀² − C²) real)")
        self.gap = g

    def epsilon(self, E):
        a, c, e0 = self._cast(E)
        eg = self.gap.astype(E.dtype)
        above = E > eg
        num = a * e0 * c * (E - eg) ** 2
        e2 = jnp.where(above, num / (E * ((E * E - e0 * e0) ** 2 + c * c * E * E)), 0.0)
        return (jnp.sum(_tauc_lorentz_eps1(E, a, c, e0, eg), axis=0), jnp.sum(e2, axis=0))


# ----------------------------------------------------------------------------- the model
class DielectricIndex(IndexModel):
    """ε∞ plus oscillator terms (`Lorentz`, `Gaussian`, `TaucLorentz`) as an index model
    (module docstring): ``model(λ_nm)`` → n + iκ = √ε on the branch κ ≥ 0. `eps_inf` and
    the terms' arrays are leaves; `hc` (eV nm) is static. Range: the wavelengths where
    hc/λ is defined, (0, inf) nm, unless `wavelength_range` is given."""

    eps_inf: Array
    terms: tuple
    hc: float = eqx.field(static=True, default=HC_EV_NM, kw_only=True)

    def __init__(self, eps_inf=1.0, terms=(), *, hc: float = HC_EV_NM, wavelength_range=None,
                 name: str = "", citation: str = ""):
        e = jnp.asarray(check_real("eps_inf", as_array("eps_inf", eps_inf)))
        if not jnp.issubdtype(e.dtype, jnp.floating):
            e = e.astype(jnp.result_type(float))
        if e.ndim != 0:
            raise ValueError(f"DielectricIndex: eps_inf must be one number; got shape {e.shape}")
        terms = tuple(terms)
        for t in terms:
            if not isinstance(t, Lorentz | Gaussian | TaucLorentz):
                raise TypeError(f"DielectricIndex: terms must be Lorentz, Gaussian or "
                                f"TaucLorentz; got {type(t).__name__}")
        if not (isinstance(hc, int | float) and hc > 0):
            raise ValueError(f"DielectricIndex: hc must be a positive number (eV nm); got {hc!r}")
        self.eps_inf, self.terms, self.hc = e, terms, float(hc)
        self.name = name or " + ".join(type(t).__name__ for t in terms) or "constant ε"
        self.citation = citation
        if wavelength_range is None:
            self.wavelength_range = (0.0, math.inf)
        else:
            lo, hi = (float(v) for v in wavelength_range)
            if not 0 <= lo < hi:
                raise ValueError(f"DielectricIndex: wavelength_range must be (lo, hi) nm with "
                                 f"0 ≤ lo < hi; got {wavelength_range!r}")
            self.wavelength_range = (lo, hi)

    def epsilon(self, wavelength) -> tuple[Array, Array]:
        """(ε₁, ε₂) at `wavelength` (nm), any shape."""
        w = jnp.asarray(wavelength)
        E = (self.hc / w).reshape(-1)
        e1 = self.eps_inf.astype(w.dtype) + jnp.zeros_like(E)
        e2 = jnp.zeros_like(E)
        for t in self.terms:
            a, b = t.epsilon(E)
            e1, e2 = e1 + a, e2 + b
        return e1.reshape(w.shape), e2.reshape(w.shape)

    def _evaluate(self, w):
        e1, e2 = self.epsilon(w)
        n, k = sqrt_upper_parts(e1, e2)
        return jax.lax.complex(n, k)


def lorentz(amplitude, broadening, energy, *, eps_inf=1.0, **kw) -> DielectricIndex:
    """ε∞ + Lorentz oscillators (`Lorentz`; keywords of `DielectricIndex`)."""
    return DielectricIndex(eps_inf, (Lorentz(amplitude, broadening, energy),), **kw)


def gaussian(amplitude, broadening, energy, *, eps_inf=1.0, **kw) -> DielectricIndex:
    """ε∞ + Gaussian oscillators (`Gaussian`, B the FWHM; keywords of `DielectricIndex`)."""
    return DielectricIndex(eps_inf, (Gaussian(amplitude, broadening, energy),), **kw)


def tauc_lorentz(amplitude, broadening, energy, gap, *, eps_inf=1.0, **kw) -> DielectricIndex:
    """ε∞ + Tauc–Lorentz oscillators of one gap (`TaucLorentz`; keywords of
    `DielectricIndex`)."""
    return DielectricIndex(eps_inf, (TaucLorentz(amplitude, broadening, energy, gap),), **kw)
