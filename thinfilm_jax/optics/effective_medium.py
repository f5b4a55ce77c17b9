r"""Effective-medium mixtures of two materials as an index model (SPEC §14): a porous or
swollen layer (a polymer brush with solvent, a rough interface) as one effective ε.

`EffectiveMedium(host, inclusion, fraction, method)`: ε_a = host², ε_b = inclusion² at each
wavelength, f the volume fraction of the inclusion (WVASE's "EMA %" / 100), L the
depolarisation factor (1/3: spheres):

* ``"linear"``: ε = (1 − f) ε_a + f ε_b.
* ``"maxwell_garnett"`` (inclusions dispersed in the host; Maxwell Garnett 1904):
  $\varepsilon = \varepsilon_a + \frac{f\varepsilon_a(\varepsilon_b - \varepsilon_a)}
  {\varepsilon_a + L(1 - f)(\varepsilon_b - \varepsilon_a)}$.
* ``"bruggeman"`` (both phases alike; Bruggeman 1935): the root of
  $(1 - f)\frac{\varepsilon_a - \varepsilon}{\varepsilon + L(\varepsilon_a - \varepsilon)} +
  f\frac{\varepsilon_b - \varepsilon}{\varepsilon + L(\varepsilon_b - \varepsilon)} = 0$, i.e.
  $(1 - L)\varepsilon^2 - b\,\varepsilon - L\varepsilon_a\varepsilon_b = 0$ with
  $b = (1 - f)((1 - L)\varepsilon_a - L\varepsilon_b) + f((1 - L)\varepsilon_b - L\varepsilon_a)$
  (for L = 1/3 the familiar ε = (B + √(B² + 8ε_aε_b))/4, B = (3f_a − 1)ε_a + (3f_b − 1)ε_b);
  of the two roots, the one nearer the linear mixture (the physical branch: it joins ε_a at
  f = 0 and ε_b at f = 1).

n + iκ = √ε on the branch κ ≥ 0. `fraction` is a leaf (``"eta[0].fraction"`` is a fit
parameter); `method` and `depolarisation` are static. The range is the intersection of the two
materials' ranges.

Example (a 50 % Bruggeman mixture of two media is symmetric; Maxwell Garnett at f = 0 is
the host):
    >>> m = EffectiveMedium(1.33, 1.50, 0.5)
    >>> round(abs(complex(m(600.0)) - complex(EffectiveMedium(1.50, 1.33, 0.5)(600.0))), 12)
    0.0
    >>> complex(EffectiveMedium(1.33, 1.50, 0.0, method="maxwell_garnett")(600.0))
    (1.33+0j)
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import Array

from ..core._validate import as_array, check_real, is_concrete
from .fresnel import sqrt_upper
from .index import ConstantIndex, IndexModel, _range_text

__all__ = ["EMA_METHODS", "EffectiveMedium"]

EMA_METHODS = ("bruggeman", "maxwell_garnett", "linear")


def _model(x) -> IndexModel:
    return x if isinstance(x, IndexModel) else ConstantIndex(x)


class EffectiveMedium(IndexModel):
    """Two materials mixed by an effective-medium rule (module docstring): `host` and
    `inclusion` index models or numbers, `fraction` f ∈ [0, 1] of the inclusion, `method`
    ("bruggeman", "maxwell_garnett", "linear"), `depolarisation` L ∈ [0, 1) (1/3: spheres)."""

    host: IndexModel
    inclusion: IndexModel
    fraction: Array
    method: str = eqx.field(static=True, default="bruggeman", kw_only=True)
    depolarisation: float = eqx.field(static=True, default=1.0 / 3.0, kw_only=True)

    def __init__(self, host, inclusion, fraction, *, method: str = "bruggeman",
                 depolarisation: float = 1.0 / 3.0, name: str = "", citation: str = ""):
        if method not in EMA_METHODS:
            raise ValueError(f"EffectiveMedium: method must be one of {EMA_METHODS}; got "
                             f"{method!r}")
        if not (isinstance(depolarisation, int | float) and 0.0 <= depolarisation < 1.0):
            raise ValueError(f"EffectiveMedium: depolarisation must be in [0, 1); got "
                             f"{depolarisation!r}")
        f = jnp.asarray(check_real("fraction", as_array("fraction", fraction)))
        if not jnp.issubdtype(f.dtype, jnp.floating):
            f = f.astype(jnp.result_type(float))
        if f.ndim != 0:
            raise ValueError(f"EffectiveMedium: fraction must be one number; got shape {f.shape}")
        if is_concrete(f) and not 0.0 <= float(f) <= 1.0:
            raise ValueError(f"EffectiveMedium: fraction must lie in [0, 1]; got {float(f)}")
        self.host, self.inclusion, self.fraction = _model(host), _model(inclusion), f
        self.method, self.depolarisation = method, float(depolarisation)
        lo = max(self.host.wavelength_range[0], self.inclusion.wavelength_range[0])
        hi = min(self.host.wavelength_range[1], self.inclusion.wavelength_range[1])
        if not lo < hi:
            raise ValueError(f"EffectiveMedium {name}: the two materials' ranges "
                             f"({_range_text(self.host.wavelength_range)}, "
                             f"{_range_text(self.inclusion.wavelength_range)}) do not overlap")
        self.wavelength_range = (lo, hi)
        self.name = name or f"{method}({self.host.name}, {self.inclusion.name})"
        self.citation = citation

    def epsilon(self, w) -> Array:
        """The effective ε at wavelengths `w` (nm, a floating array)."""
        na, nb = self.host._evaluate(w), self.inclusion._evaluate(w)
        ea, eb = na * na, nb * nb
        f = self.fraction.astype(jnp.real(ea).dtype)
        f = jax.lax.complex(f, jnp.zeros_like(f))  # explicit (strict dtype promotion)
        lin = (1.0 - f) * ea + f * eb
        if self.method == "linear":
            return lin
        L = self.depolarisation
        if self.method == "maxwell_garnett":
            return ea + f * ea * (eb - ea) / (ea + L * (1.0 - f) * (eb - ea))
        u = 1.0 - L
        b = (1.0 - f) * (u * ea - L * eb) + f * (u * eb - L * ea)
        s = sqrt_upper(b * b + 4.0 * u * L * ea * eb)
        r1, r2 = (b + s) / (2.0 * u), (b - s) / (2.0 * u)
        return jnp.where(jnp.abs(r1 - lin) <= jnp.abs(r2 - lin), r1, r2)

    def _evaluate(self, w):
        return sqrt_upper(self.epsilon(w))

