r"""Refractive-index models (SPEC §12): n + iκ as a function of wavelength.

An index model is a pytree (`equinox.Module`) called with wavelengths in nm and returning the
complex index $\hat n = n + i\kappa$ ($\kappa \ge 0$, the sign convention of `Film` and of the
Fresnel code), with the complex dtype matching the wavelengths' precision (float32 →
complex64, float64 → complex128; integers count as the default float). It broadcasts over
any wavelength shape and works under `jax.jit`, `jax.vmap` and `jax.grad`. Its numeric fields
are leaves (so `jax.grad` reaches a Cauchy coefficient or a table value); its `name`,
`citation` and `wavelength_range` (lo_nm, hi_nm) are static.

Models:

* `ConstantIndex(value)`: a real or complex number (or array), the same at every wavelength;
  its range is (0, inf).
* `TabulatedIndex(wavelength_nm, n, k)`: measured n and κ, interpolated **linearly in λ**,
  n and κ separately (`jnp.interp`); ``interpolation="epsilon"`` interpolates the
  dielectric function ε = (n + iκ)² linearly in λ instead (what J.A. Woollam's WVASE does:
  `optics.ellipsometry`). Why linear: it is exact at the nodes, linear in the
  table values (so gradients with respect to them are the interpolation weights), and a
  convex combination of neighbouring nodes, so κ ≥ 0 and n stay within the measured values
  (a cubic spline can overshoot to κ < 0 near a sharp absorption edge). The bundled tables
  are dense enough that the rule's own error is below the measurements' (measured in
  ``docs/how-to/materials.md``).
* `FormulaIndex(formula, coefficients, wavelength_range)`: refractiveindex.info's dispersion
  formulas 1–9, λ in µm, exactly as that database defines them ("Dispersion formulas",
  refractiveindex.info database documentation), with $C_1, C_2, \dots$ the coefficients:

  1. Sellmeier: $n^2 - 1 = C_1 + \sum_i C_{2i}\,\lambda^2 / (\lambda^2 - C_{2i+1}^2)$
  2. Sellmeier-2: $n^2 - 1 = C_1 + \sum_i C_{2i}\,\lambda^2 / (\lambda^2 - C_{2i+1})$
  3. polynomial: $n^2 = C_1 + \sum_i C_{2i}\,\lambda^{C_{2i+1}}$
  4. RefractiveIndex.INFO: $n^2 = C_1 + \frac{C_2\lambda^{C_3}}{\lambda^2 - C_4^{C_5}}
     + \frac{C_6\lambda^{C_7}}{\lambda^2 - C_8^{C_9}} + \sum_{i\ge5} C_{2i}\,\lambda^{C_{2i+1}}$
  5. Cauchy: $n = C_1 + \sum_i C_{2i}\,\lambda^{C_{2i+1}}$
  6. gases: $n - 1 = C_1 + \sum_i C_{2i} / (C_{2i+1} - \lambda^{-2})$
  7. Herzberger: $n = C_1 + \frac{C_2}{\lambda^2 - 0.028} + C_3\left(\frac{1}{\lambda^2 -
     0.028}\right)^2 + C_4\lambda^2 + C_5\lambda^4 + C_6\lambda^6$
  8. Retro: $\frac{n^2 - 1}{n^2 + 2} = C_1 + \frac{C_2\lambda^2}{\lambda^2 - C_3} + C_4\lambda^2$
  9. Exotic: $n^2 = C_1 + \frac{C_2}{\lambda^2 - C_3} + \frac{C_4(\lambda - C_5)}{(\lambda -
     C_5)^2 + C_6}$

  Formulas give κ = 0. Coefficients missing at the end of the list are zero (formulas 4, 7, 8,
  9); formulas 1, 2, 3, 5, 6 take $C_1$ and then complete pairs. `cauchy` and `sellmeier`
  build the common cases.
* `CompositeIndex(n_model, k_model)`: n from one model and κ from another (a
  refractiveindex.info file with a `formula` for n and `tabulated k`); its range is the
  intersection of theirs.

Range checks (`check_wavelengths`): every model with a finite range raises a `ValueError`
naming its range in nm when called at a *concrete* wavelength outside it (a few ulps of
rounding are accepted): there is no silent extrapolation. Inside `jax.jit` / `jax.vmap` /
`jax.grad` the wavelengths are traced and unknown, so by default nothing is checked there:
a tabulated model then holds its end values beyond its range (`jnp.interp`), a formula
evaluates its formula. Inside `thinfilm_jax.checked` the same check runs on traced values
as an `equinox.error_if` (an error when the result is computed), like every other range
check of the library (`core/_validate.py`).

`index_at(eta, wavelength)` is the one place the exact paths evaluate an index: a number
(real or complex) or array is a constant index, a model is called.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from ..core._validate import as_array, check_range, check_real, checking, is_concrete
from .fresnel import sqrt_upper_parts

__all__ = [
    "IndexModel",
    "is_index_model",
    "index_at",
    "check_wavelengths",
    "ConstantIndex",
    "check_table",
    "TabulatedIndex",
    "FormulaIndex",
    "cauchy",
    "sellmeier",
    "CompositeIndex",
]

_INF_RANGE = (0.0, math.inf)
#: How `TabulatedIndex` interpolates between its rows: n and κ, or ε = (n + iκ)², linearly in λ.
INTERPOLATIONS = ("nk", "epsilon")


def _wavelength_array(wavelength, name: str = "wavelength") -> Array:
    """The wavelengths as a real floating array (integers become the default float)."""
    w = jnp.asarray(check_real(name, as_array(name, wavelength)))
    if not jnp.issubdtype(w.dtype, jnp.floating):
        w = w.astype(jnp.result_type(float))
    return w


def _complex(n, k, dtype) -> Array:
    """n + iκ in the complex dtype of the real `dtype` (float64 → complex128, else complex64)."""
    dtype = jnp.float64 if dtype == jnp.float64 else jnp.float32
    n, k = jnp.asarray(n, dtype), jnp.asarray(k, dtype)
    shape = jnp.broadcast_shapes(n.shape, k.shape)
    return jax.lax.complex(jnp.broadcast_to(n, shape), jnp.broadcast_to(k, shape))


def _range_text(rng) -> str:
    return f"[{rng[0]:g}, {rng[1]:g}] nm"


class IndexModel(eqx.Module):
    """Base class of index models: ``model(wavelength_nm)`` → complex n + iκ (κ ≥ 0).

    Subclasses implement ``_evaluate(w)`` for a floating array `w` of wavelengths in nm;
    ``__call__`` converts the wavelengths, checks them against `wavelength_range`
    (`check_wavelengths`) and evaluates. Static metadata: `name`, `citation` and
    `wavelength_range` = (lo_nm, hi_nm) (``(0, inf)`` when unlimited).
    """

    name: str = eqx.field(static=True, default="", kw_only=True)
    citation: str = eqx.field(static=True, default="", kw_only=True)
    wavelength_range: tuple[float, float] = eqx.field(static=True, default=_INF_RANGE,
                                                      kw_only=True)

    def __call__(self, wavelength) -> Array:
        w = check_wavelengths(self, wavelength)
        return self._evaluate(w)

    def _evaluate(self, w: Array) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError


def is_index_model(x) -> bool:
    """True for an index model (a callable pytree), False for a number or an array."""
    return isinstance(x, IndexModel)


def index_at(eta, wavelength) -> Array:
    """The index `eta` at `wavelength` (nm): a model is evaluated, a number or array is
    returned as an array (a constant index; its shape broadcasts with the wavelengths)."""
    if is_index_model(eta):
        return eta(wavelength)
    return jnp.asarray(eta)


def check_wavelengths(model: IndexModel, wavelength, name: str = "wavelength") -> Array:
    """`wavelength` (nm) as a floating array, after checking it lies in the model's range.

    Concrete values outside ``model.wavelength_range`` (beyond a few ulps of rounding) raise
    a `ValueError` naming `name`, the range in nm and the model; so do NaN and inf. Traced
    values are checked only inside `thinfilm_jax.checked` (`equinox.error_if`).
    """
    w = _wavelength_array(wavelength, name)
    lo, hi = getattr(model, "wavelength_range", _INF_RANGE)
    label = model.name or type(model).__name__
    unlimited = math.isinf(hi) and lo <= 0.0
    where = (f"the wavelength range of the index model {label}"
             + (f" ({model.citation})" if model.citation else ""))
    if not is_concrete(w):
        if not checking():
            return w
        if unlimited:  # constants, formulas without a stated range: only λ > 0
            return check_range(name, w, 0.0, None, lo_open=True, why=f" nm ({label})")
        return check_range(name, w, lo, None if math.isinf(hi) else hi, ulps=4,
                           why=f" nm, {where}; an index is never extrapolated")
    v = np.asarray(w)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite; got NaN or inf (index model {label})")
    if unlimited:
        bad = v <= 0.0
        rng = "(0, inf) nm"
    else:
        slack = 4.0 * float(np.finfo(v.dtype).eps) * max(1.0, abs(hi) if math.isfinite(hi)
                                                         else abs(lo))
        bad = (v < lo - slack) | (v > hi + slack)
        rng = _range_text((lo, hi))
    if np.any(bad):
        raise ValueError(f"{name} = {float(v[bad].flat[0]):g} nm lies outside {rng}, {where}"
                         f"; an index is never extrapolated beyond its data")
    return w


# --------------------------------------------------------------------------- constant


class ConstantIndex(IndexModel):
    """A wavelength-independent index n + iκ: ``ConstantIndex(1.5)``,
    ``ConstantIndex(0.2 + 3.0j)``. `n` and `k` are leaves (real arrays); κ must be ≥ 0.

    >>> import thinfilm_jax.optics.index as ix
    >>> complex(ix.ConstantIndex(1.5 + 0.25j)(550.0))
    (1.5+0.25j)
    """

    n: Array
    k: Array

    def __init__(self, value, k=None, *, name: str = "", citation: str = ""):
        if k is None:
            v = jnp.asarray(as_array("value", value))
            if jnp.iscomplexobj(v):
                n, k = jnp.real(v), jnp.imag(v)
            else:
                n, k = v, jnp.zeros_like(v)
        else:
            n, k = jnp.asarray(check_real("n", as_array("n", value))), \
                jnp.asarray(check_real("k", as_array("k", k)))
        if not jnp.issubdtype(n.dtype, jnp.floating):
            n = n.astype(jnp.result_type(float))
        if not jnp.issubdtype(k.dtype, jnp.floating):
            k = k.astype(jnp.result_type(float))
        if is_concrete(k) and np.any(np.asarray(k) < 0):
            raise ValueError(f"ConstantIndex: the extinction coefficient κ must be ≥ 0 "
                             f"(n + iκ with κ ≥ 0 absorbs); got κ = {np.min(np.asarray(k))!r}")
        self.n, self.k = n, k
        self.name = name or "constant"
        self.citation = citation
        self.wavelength_range = _INF_RANGE

    def _evaluate(self, w):
        shape = jnp.broadcast_shapes(jnp.shape(self.n), w.shape)
        return jnp.broadcast_to(_complex(self.n, self.k, w.dtype), shape)


# --------------------------------------------------------------------------- tables


def check_table(wavelength_nm, n, k=None, *, where: str = "table"):
    """Validated float64 NumPy copies (wavelength_nm, n, k) of a concrete table.

    A `ValueError` names `where` (a file, a model) and the problem: not 1-D, fewer than two
    rows, different lengths, non-finite values, wavelengths ≤ 0 or not strictly increasing,
    κ < 0.
    """
    cols = {"wavelength": wavelength_nm, "n": n, "k": np.zeros_like(np.asarray(n, float))
            if k is None else k}
    arrs = {}
    for key, v in cols.items():
        a = np.asarray(v, dtype=float)
        if a.ndim != 1:
            raise ValueError(f"{where}: the {key} column must be one-dimensional; got shape "
                             f"{a.shape}")
        arrs[key] = a
    wl, nn, kk = arrs["wavelength"], arrs["n"], arrs["k"]
    if not (len(wl) == len(nn) == len(kk)):
        raise ValueError(f"{where}: columns of different lengths (wavelength {len(wl)}, n "
                         f"{len(nn)}, k {len(kk)})")
    if len(wl) < 2:
        raise ValueError(f"{where}: a table needs at least two wavelengths; got {len(wl)}")
    for key, a in arrs.items():
        if not np.all(np.isfinite(a)):
            i = int(np.flatnonzero(~np.isfinite(a))[0])
            raise ValueError(f"{where}: non-finite {key} in row {i + 1}: {a[i]!r}")
    if wl[0] <= 0:
        raise ValueError(f"{where}: wavelengths must be positive; got {wl[0]!r}")
    d = np.diff(wl)
    if np.any(d <= 0):
        i = int(np.flatnonzero(d <= 0)[0])
        raise ValueError(f"{where}: wavelengths must increase strictly; row {i + 2} "
                         f"({wl[i + 1]!r}) does not exceed row {i + 1} ({wl[i]!r})")
    if np.any(kk < 0):
        i = int(np.flatnonzero(kk < 0)[0])
        raise ValueError(f"{where}: the extinction coefficient k must be ≥ 0; row {i + 1} "
                         f"(wavelength {wl[i]!r}) has k = {kk[i]!r}")
    return wl, nn, kk


class TabulatedIndex(IndexModel):
    r"""A measured table of n and κ, **interpolated linearly in λ**, n and κ separately.

    Between nodes $\lambda_j \le \lambda \le \lambda_{j+1}$ with $t = (\lambda -
    \lambda_j)/(\lambda_{j+1} - \lambda_j)$: $n = (1-t)\,n_j + t\,n_{j+1}$, likewise κ. Exact
    at the nodes, continuous, linear in the table values (gradients with respect to `n` and
    `k` are the weights $1-t$, $t$), and κ stays ≥ 0 (a convex combination), which a cubic
    spline does not guarantee near an absorption edge. Outside ``[λ_0, λ_last]`` a concrete
    wavelength is a `ValueError` naming the range; inside `jax.jit` (unchecked) the end
    values are held.

    ``interpolation="epsilon"``: ε₁ = n² − κ² and ε₂ = 2nκ are interpolated linearly in λ
    and n + iκ = √ε (branch κ ≥ 0; ε₂ ≥ 0 stays a convex combination). This is the rule of
    J.A. Woollam's WVASE: on its bare-silicon ψ, Δ (refellips test data, 45–85°, 300–800
    nm, a 46-row table 0.21–0.83 µm) it reproduces WVASE to 0.0005° in ψ and 0.005° in Δ
    (the files' printed digits), where n, κ interpolation misses by 0.03° and 0.07°
    (``docs/how-to/ellipsometry.md``). Both rules are exact at the nodes.

    Arguments: `wavelength_nm` (strictly increasing, nm), `n`, `k` (optional, default 0,
    ≥ 0), all 1-D of one length; `interpolation` "nk" (default) or "epsilon" (static).
    Concrete tables are validated (`check_table`).

    >>> import thinfilm_jax.optics.index as ix
    >>> m = ix.TabulatedIndex([400.0, 500.0], [1.5, 1.25], [0.0, 0.5])
    >>> complex(m(450.0))
    (1.375+0.25j)
    """

    wavelength_nm: Array
    n: Array
    k: Array
    interpolation: str = eqx.field(static=True, default="nk", kw_only=True)

    def __init__(self, wavelength_nm, n, k=None, *, name: str = "", citation: str = "",
                 interpolation: str = "nk"):
        if interpolation not in INTERPOLATIONS:
            raise ValueError(f"TabulatedIndex: interpolation must be one of {INTERPOLATIONS}; "
                             f"got {interpolation!r}")
        self.interpolation = interpolation
        leaves = (wavelength_nm, n, k)
        if all(x is None or is_concrete(x) for x in leaves):
            wl, nn, kk = check_table(wavelength_nm, n, k, where=f"TabulatedIndex {name}".strip())
            rng = (float(wl[0]), float(wl[-1]))
            # Keep float64 tables when x64 is on (jnp.asarray follows the default float).
            self.wavelength_nm = jnp.asarray(wl, jnp.result_type(float))
            self.n = jnp.asarray(nn, jnp.result_type(float))
            self.k = jnp.asarray(kk, jnp.result_type(float))
        else:
            self.wavelength_nm = jnp.asarray(wavelength_nm)
            self.n = jnp.asarray(n)
            self.k = jnp.zeros_like(self.n) if k is None else jnp.asarray(k)
            rng = _INF_RANGE
        self.name = name
        self.citation = citation
        self.wavelength_range = rng

    def _evaluate(self, w):
        dt = w.dtype
        xp = self.wavelength_nm.astype(dt)
        n, k = self.n.astype(dt), self.k.astype(dt)
        if self.interpolation == "epsilon":
            e1 = jnp.interp(w, xp, n * n - k * k)
            e2 = jnp.interp(w, xp, 2.0 * n * k)
            return _complex(*sqrt_upper_parts(e1, e2), dt)
        return _complex(jnp.interp(w, xp, n), jnp.interp(w, xp, k), dt)

    def with_interpolation(self, interpolation: str) -> TabulatedIndex:
        """This table with another `interpolation` rule ("nk" or "epsilon")."""
        return TabulatedIndex(self.wavelength_nm, self.n, self.k, name=self.name,
                              citation=self.citation, interpolation=interpolation)


# --------------------------------------------------------------------------- formulas

#: The number of coefficients formulas 4, 7, 8, 9 use at most before the open tail (4) or
#: in all (7, 8, 9); missing trailing coefficients are zero.
_FIXED = {7: 6, 8: 4, 9: 6}
_PAIRS = (1, 2, 3, 5, 6)


def _safe_ratio(num_coef, num, den):
    """num / den, exactly 0 (value and gradient finite) where the term's coefficient is 0:
    a zero-padded term of formula 4 would otherwise give 0/0 at λ² = C^0 = 1 µm²."""
    off = num_coef == 0
    return jnp.where(off, jnp.zeros_like(num), num / jnp.where(off, jnp.ones_like(den), den))


class FormulaIndex(IndexModel):
    """refractiveindex.info dispersion formula `formula` (1–9) with `coefficients` C₁, C₂, …
    (λ in µm inside the formula; the model is called in nm), valid over `wavelength_range`
    (nm; default unlimited). κ = 0. The formulas are listed in the module docstring.

    `coefficients` is a leaf: ``jax.grad`` with respect to ``model.coefficients`` gives the
    sensitivity of n to each coefficient.

    >>> import thinfilm_jax.optics.index as ix
    >>> silica = ix.FormulaIndex(1, [0, 0.6961663, 0.0684043, 0.4079426, 0.1162414,
    ...                              0.8974794, 9.896161], (210.0, 6700.0))
    >>> round(float(silica(587.56).real), 4)
    1.4585
    """

    formula: int = eqx.field(static=True)
    coefficients: Array

    def __init__(self, formula: int, coefficients, wavelength_range=None, *, name: str = "",
                 citation: str = ""):
        if isinstance(formula, bool) or not isinstance(formula, (int, np.integer)) \
                or not 1 <= int(formula) <= 9:
            raise ValueError(f"FormulaIndex: formula must be an integer 1-9 (refractiveindex.info"
                             f"'s dispersion formulas); got {formula!r}")
        formula = int(formula)
        c = jnp.asarray(check_real("coefficients", as_array("coefficients", coefficients)))
        if not jnp.issubdtype(c.dtype, jnp.floating):
            c = c.astype(jnp.result_type(float))
        if c.ndim != 1 or c.shape[0] < 1:
            raise ValueError(f"FormulaIndex: coefficients must be a non-empty 1-D sequence; got "
                             f"shape {c.shape}")
        m = c.shape[0]
        if formula in _PAIRS and m % 2 == 0:
            raise ValueError(f"FormulaIndex: formula {formula} takes C1 followed by complete "
                             f"pairs (an odd number of coefficients); got {m}")
        if formula in _FIXED and m > _FIXED[formula]:
            raise ValueError(f"FormulaIndex: formula {formula} takes at most "
                             f"{_FIXED[formula]} coefficients; got {m}")
        if formula == 4 and m > 9 and (m - 9) % 2:
            raise ValueError(f"FormulaIndex: formula 4 takes C1-C9 and then complete pairs "
                             f"(C10, C11), …; got {m} coefficients")
        full = 9 if formula == 4 else _FIXED.get(formula, 0)
        if m < full:  # missing trailing coefficients are zero
            c = jnp.concatenate([c, jnp.zeros(full - m, c.dtype)])
        if wavelength_range is None:
            rng = _INF_RANGE
        else:
            lo, hi = (float(x) for x in wavelength_range)
            if not (0 <= lo < hi):
                raise ValueError(f"FormulaIndex: wavelength_range must be (lo, hi) nm with "
                                 f"0 ≤ lo < hi; got {wavelength_range!r}")
            rng = (lo, hi)
        self.formula = formula
        self.coefficients = c
        self.name = name or f"formula {formula}"
        self.citation = citation
        self.wavelength_range = rng

    def _evaluate(self, w):
        dt = w.dtype
        x = w / 1000.0  # nm → µm
        c = self.coefficients.astype(dt)
        f, m = self.formula, c.shape[0]
        x2 = x * x
        if f in (1, 2):
            s = 1.0 + c[0] + jnp.zeros_like(x)
            for i in range(1, m, 2):
                pole = c[i + 1] ** 2 if f == 1 else c[i + 1]
                s = s + c[i] * x2 / (x2 - pole)
            n = jnp.sqrt(s)
        elif f in (3, 5):
            s = c[0] + jnp.zeros_like(x)
            for i in range(1, m, 2):
                s = s + c[i] * jnp.power(x, c[i + 1])
            n = jnp.sqrt(s) if f == 3 else s
        elif f == 4:
            s = c[0] + jnp.zeros_like(x)
            for i in (1, 5):
                s = s + _safe_ratio(c[i], c[i] * jnp.power(x, c[i + 1]),
                                    x2 - jnp.power(c[i + 2], c[i + 3]))
            for i in range(9, m, 2):
                s = s + c[i] * jnp.power(x, c[i + 1])
            n = jnp.sqrt(s)
        elif f == 6:
            s = 1.0 + c[0] + jnp.zeros_like(x)
            for i in range(1, m, 2):
                s = s + c[i] / (c[i + 1] - 1.0 / x2)
            n = s
        elif f == 7:
            L = 1.0 / (x2 - 0.028)
            n = (c[0] + c[1] * L + c[2] * L * L + c[3] * x2 + c[4] * x2 ** 2
                 + c[5] * x2 ** 3)
        elif f == 8:
            a = c[0] + c[1] * x2 / (x2 - c[2]) + c[3] * x2
            n = jnp.sqrt((1.0 + 2.0 * a) / (1.0 - a))
        else:  # 9
            u = x - c[4]
            n = jnp.sqrt(c[0] + c[1] / (x2 - c[2]) + c[3] * u / (u * u + c[5]))
        return _complex(n, jnp.zeros_like(n), dt)


def cauchy(A, B=0.0, C=0.0, *, wavelength_range=None, name: str = "Cauchy",
           citation: str = "") -> FormulaIndex:
    """Cauchy's $n = A + B/λ^2 + C/λ^4$ with λ in µm (B in µm², C in µm⁴): formula 5 with
    coefficients ``[A, B, -2, C, -4]`` (so ``model.coefficients[0]`` is A, ``[1]`` B,
    ``[3]`` C)."""
    c = jnp.stack([jnp.asarray(v, jnp.result_type(float)) for v in (A, B, -2.0, C, -4.0)])
    return FormulaIndex(5, c, wavelength_range, name=name, citation=citation)


def sellmeier(B, C, *, wavelength_range=None, name: str = "Sellmeier",
              citation: str = "") -> FormulaIndex:
    """Sellmeier's $n^2 = 1 + \\sum_i B_i λ^2/(λ^2 - C_i)$ with λ in µm and $C_i$ in µm² (the
    glass catalogues' convention): formula 2 with coefficients ``[0, B1, C1, B2, C2, …]``."""
    B = jnp.atleast_1d(jnp.asarray(B, jnp.result_type(float)))
    C = jnp.atleast_1d(jnp.asarray(C, jnp.result_type(float)))
    if B.shape != C.shape or B.ndim != 1:
        raise ValueError(f"sellmeier: B and C must be 1-D of one length; got shapes {B.shape} "
                         f"and {C.shape}")
    c = jnp.concatenate([jnp.zeros(1, B.dtype), jnp.stack([B, C], axis=1).reshape(-1)])
    return FormulaIndex(2, c, wavelength_range, name=name, citation=citation)


# --------------------------------------------------------------------------- composite


class CompositeIndex(IndexModel):
    """n from `n_model` (its real part) and κ from `k_model` (its imaginary part), e.g. a
    dispersion formula for n with a measured κ table. The range is the intersection of the
    two models' ranges (a `ValueError` if they do not overlap)."""

    n_model: IndexModel
    k_model: IndexModel

    def __init__(self, n_model: IndexModel, k_model: IndexModel, *, name: str = "",
                 citation: str = ""):
        if not (is_index_model(n_model) and is_index_model(k_model)):
            raise TypeError("CompositeIndex takes two index models (n_model, k_model)")
        lo = max(n_model.wavelength_range[0], k_model.wavelength_range[0])
        hi = min(n_model.wavelength_range[1], k_model.wavelength_range[1])
        if not lo < hi:
            raise ValueError(f"CompositeIndex {name}: the n data "
                             f"({_range_text(n_model.wavelength_range)}) and the k data "
                             f"({_range_text(k_model.wavelength_range)}) do not overlap")
        self.n_model, self.k_model = n_model, k_model
        self.name = name or f"{n_model.name} + {k_model.name}"
        self.citation = citation or "; ".join(
            dict.fromkeys(c for c in (n_model.citation, k_model.citation) if c))
        self.wavelength_range = (lo, hi)

    def _evaluate(self, w):
        n = jnp.real(self.n_model._evaluate(w))
        k = jnp.imag(self.k_model._evaluate(w))
        return _complex(n, k, w.dtype)
