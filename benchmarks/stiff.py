"""Stiff and extreme inputs, and the bookkeeping of the stability suite (`stability`).

The input grids (`STIFF_*`), a `StabilityResult` per (function, dtype), one-call values and
gradients over a grid (`value_and_grads`), and the three kinds of finding: non-finite values
or gradients (`finish`), bound violations (`bound_check`), disagreement with a reference
(`ref_check`), each with a reproducer. References: tmm (`tmm_grid`) and the 80-bit closed
form (`airy_longdouble`).

Example (the grazing cosine is exactly 0; the 80-bit reference agrees with float64 away from
the stiff inputs):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, airy_reflectance
    >>> from benchmarks.stiff import airy_longdouble, stiff_cos
    >>> float(stiff_cos(np.pi / 2)), float(np.cos(np.pi / 2)) > 0
    (0.0, True)
    >>> film = Film(600.0, 1.3, 2.0, 0.5)
    >>> ref = airy_longdouble(film, np.cos(0.6), 550.0)
    >>> bool(abs(float(airy_reflectance(film, np.cos(0.6), 550.0)) - ref) < 1e-14)
    True
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.film import Film
from thinfilm_jax.spectral.spectra import get_observer
from .peers import numpy_airy, tmm_unpolarised

STIFF_THICKNESS = (0.0, 1e-6, 500.0, 1e4, 1e5)  # nm
STIFF_OPTICS = (  # (eta_outer, eta_film, eta_base, kappa_base) and what each stresses
    (1.0, 1.0, 1.5, 0.0),  # η₂ = η₁: no 1|2 interface
    (1.0, 1.0 + 1e-12, 1.5, 0.0),  # η₂ = η₁ + 1e-12 (= η₁ in float32)
    (1.0, 4.0, 1.5, 0.0),  # high-index film
    (1.0, 1.3, 2.0, 0.5),  # the Figure 7 film
    (1.0, 1.3, 2.0, 1e-12),  # κ₃ → 0⁺
    (1.0, 1.3, 2.0, 50.0),  # κ₃ huge (perfect-conductor limit)
    (1.0, 1.3, 1.3, 0.0),  # η₃ = η₂: no 2|3 interface
    (1.5, 1.2, 1.0, 0.0),  # η₁ > η₂ > η₃: TIR at 1|2 beyond 53.1° (and at 1|3 beyond 41.8°)
    (1.5, 1.2, 2.0, 0.5),  # TIR at 1|2 over an absorbing base
    (1.33, 1.33, 1.0, 0.0),  # η₂ = η₁ with TIR at the base
)
STIFF_THETA = (0.0, 1e-9, 0.7, 1.2, np.pi / 2 - 1e-9, np.pi / 2)
STIFF_ALPHA = (1e-4, 0.3, 1.0)
STIFF_WAVELENGTH = (380.0, 555.0, 830.0)
STABILITY_QUADRATURE = 8  # patch quadrature order of the stability grid (finiteness, bounds)
F32_BELOW_HALF_PI = float(np.nextafter(np.float32(np.pi / 2), np.float32(0)))
# rounding slack of the bounds, by dtype (R ≤ 1: see tests/optics/test_fresnel_airy.py R_MAX_ROUNDING)
BOUND_SLACK = {"float64": 1e-12, "float32": 2e-6}


@dataclass
class StabilityResult:
    """Findings for one public function and dtype over its grid of extreme inputs."""

    function: str
    dtype: str
    n_cases: int = 0
    nonfinite_value: int = 0
    nonfinite_grad: dict = dataclasses.field(default_factory=dict)
    value_min: float = math.nan
    value_max: float = math.nan
    bound: str = ""
    bound_violations: int = 0
    bound_excess: float = 0.0
    reference: str = ""
    ref_tol: float = math.nan
    ref_error: float = math.nan
    ref_violations: int = 0
    documented: list = dataclasses.field(default_factory=list)
    examples: list = dataclasses.field(default_factory=list)
    seconds: float = 0.0

    @property
    def problems(self) -> int:
        bad_doc = sum(1 for d in self.documented if not d["holds"])
        return (self.nonfinite_value + sum(self.nonfinite_grad.values()) + self.bound_violations
                + self.ref_violations + bad_doc)


def rounded(tree, dtype):
    """`tree` rounded to `dtype`, as float64 NumPy: the inputs a `dtype` run really sees, on
    which its float64 reference is evaluated."""
    return jax.tree.map(lambda x: np.asarray(x).astype(dtype).astype(np.float64), tree)


def stiff_cos(theta):
    """cos θ with cos(π/2) = 0 exactly (the grazing case, not 6e-17)."""
    theta = np.asarray(theta, np.float64)
    return np.where(theta == np.pi / 2, 0.0, np.cos(theta))


def stiff_grid(*axes):
    """Flat product grid of thickness × optics × the extra `axes` (float64 NumPy).

    Returns (Film, [flattened extra axes…]); optics rows come from `STIFF_OPTICS`.
    """
    optics = np.asarray(STIFF_OPTICS)
    grids = np.meshgrid(np.asarray(STIFF_THICKNESS), np.arange(len(optics)),
                        *(np.asarray(a, np.float64) for a in axes), indexing="ij")
    d, o = grids[0].ravel(), grids[1].ravel().astype(int)
    film = Film(d, optics[o, 1], optics[o, 2], optics[o, 3], optics[o, 0])
    return film, [g.ravel() for g in grids[2:]]


def _flat_names(tree, prefix):
    if isinstance(tree, Film):
        return [f"{prefix}.{k}" for k in Film._fields]
    return [prefix]


def value_and_grads(fn, args: tuple, names: tuple[str, ...], consts: tuple = ()):
    """(value, {input name: gradient}) of an elementwise `fn(*args, *consts)` in one compiled
    call.

    The gradient is the VJP with an all-ones cotangent, i.e. for an elementwise function
    the per-case derivative of the sum over its outputs (bands, real and imaginary parts).
    `consts` (tables: pytrees of arrays) are not differentiated and reach the compiled call
    as arguments: a table closed over by `fn` would be a constant compiled into the program
    (the Ŝ LUT: 8.5 MB of HLO text).
    """
    def real_fn(*a):
        y = fn(*a)
        return jnp.stack([jnp.real(y), jnp.imag(y)]) if jnp.iscomplexobj(y) else y

    @jax.jit
    def run(a, c):
        y, pull = jax.vjp(lambda *x: real_fn(*x, *c), *a)
        return y, pull(jnp.ones_like(y))

    y, grads = run(tuple(args), tuple(consts))
    out = {}
    for name, g in zip(names, grads):
        leaves = jax.tree.leaves(g)
        for leaf_name, leaf in zip(_flat_names(g, name), leaves):
            out[leaf_name] = np.asarray(leaf)
    return np.asarray(y), out


def _repro(call: str, args: dict, i: int, dtype: str) -> str:
    parts = []
    for k, v in args.items():
        if isinstance(v, Film):
            f = ", ".join(f"{n}={float(np.asarray(x)[i])!r}" for n, x in zip(Film._fields, v))
            parts.append(f"Film({f}).astype(jnp.{dtype})")
        else:
            parts.append(f"{k}=jnp.{dtype}({float(np.asarray(v).reshape(-1)[i])!r})")
    return f"{call}({', '.join(parts)})"


def finish(res: StabilityResult, value, grads, case_args: dict, call: str, per_case):
    """Count non-finite values and gradients, and record reproducers of the first ones."""
    v = np.asarray(value)
    bad_v = ~np.isfinite(per_case(v)).all(axis=1)
    res.nonfinite_value = int(bad_v.sum())
    fin = v[np.isfinite(v)]
    res.value_min = float(fin.min()) if fin.size else math.nan
    res.value_max = float(fin.max()) if fin.size else math.nan
    for name, g in grads.items():
        bad = ~np.isfinite(g.reshape(len(bad_v), -1)).all(axis=1)
        res.nonfinite_grad[name] = int(bad.sum())
        if bad.any() and len(res.examples) < 6:
            res.examples.append(f"non-finite d/d{name}: " + _repro(
                call, case_args, int(np.flatnonzero(bad)[0]), res.dtype))
    if bad_v.any():
        res.examples.append("non-finite value: " + _repro(call, case_args,
                                                           int(np.flatnonzero(bad_v)[0]),
                                                           res.dtype))


def bound_check(res, v, lo, hi, case_args, call, what):
    slack = BOUND_SLACK[res.dtype]
    lo_x = np.maximum(lo - slack - v, 0.0)
    hi_x = np.maximum(v - hi - slack, 0.0)
    excess = np.maximum(lo_x, hi_x)
    per = excess.reshape(excess.shape[0], -1).max(axis=1)
    per = np.where(np.isfinite(per), per, 0.0)
    res.bound = what
    res.bound_violations = int((per > 0).sum())
    res.bound_excess = float(per.max()) if per.size else 0.0
    if res.bound_violations and len(res.examples) < 6:
        i = int(np.argmax(per))
        res.examples.append(f"bound {what} exceeded by {per[i]:.3g}: "
                            + _repro(call, case_args, i, res.dtype))


def ref_check(res, err, tol, case_args, call, what):
    """Compare per-case errors with tolerances (NaN error = reference not defined there).

    `err` and `tol` broadcast to (cases,) or (cases, bands); with bands, each case is
    judged by its worst band (largest err − tol), and that band's err and tol are reported.
    """
    err = np.asarray(err, np.float64)
    tol = np.broadcast_to(np.asarray(tol, np.float64), err.shape)
    if err.ndim == 2:
        margin = np.where(np.isfinite(err), err - tol, -np.inf)
        j = np.argmax(margin, axis=1)[:, None]
        err = np.take_along_axis(err, j, 1)[:, 0]
        tol = np.take_along_axis(tol, j, 1)[:, 0]
    defined = np.isfinite(err)
    res.reference = what
    res.ref_error = float(err[defined].max()) if defined.any() else math.nan
    res.ref_tol = float(tol[defined].max()) if defined.any() else math.nan
    bad = defined & (err > tol)
    res.ref_violations = int(bad.sum())
    if bad.any() and len(res.examples) < 6:
        i = int(np.argmax(np.where(bad, err - tol, -np.inf)))
        res.examples.append(f"{what}: error {err[i]:.3g} > tol {tol[i]:.3g}: "
                            + _repro(call, case_args, i, res.dtype))


def weights_range(observer):
    """(Σ_k min(W_kj, 0), Σ_k max(W_kj, 0), Σ_k |W_kj|) per band of `observer`."""
    w = get_observer(observer).weights
    return np.minimum(w, 0).sum(0), np.maximum(w, 0).sum(0), np.abs(w).sum(0)


def tir12(film: Film, cos_theta):
    """Total internal reflection at the outer|film interface, per case."""
    s2 = np.asarray(film.eta_outer) ** 2 * (1 - np.asarray(cos_theta)) * (1 + np.asarray(cos_theta))
    return s2 > np.asarray(film.eta_film) ** 2


def tmm_grid(film: Film, cos_theta, lam):
    """tmm.coh_tmm reference per case; NaN where θ = 90° (outside tmm's domain)."""
    out = np.full(len(cos_theta), np.nan)
    for i in range(len(cos_theta)):
        if cos_theta[i] <= 0:
            continue
        n3 = complex(film.eta_base[i], film.kappa_base[i])
        out[i] = tmm_unpolarised(float(film.eta_outer[i]), float(film.eta_film[i]), n3,
                                 float(film.thickness[i]), float(np.arccos(cos_theta[i])),
                                 float(lam[i]))
    return out


def airy_longdouble(film: Film, cos_theta, wavelength):
    """Independent 80-bit reference of `airy_reflectance`: the NumPy closed form
    (`peers.numpy_airy`) in extended precision, where tmm itself loses accuracy (near
    grazing, tmm's cos θ = √(1 − sin²θ) cancels). NaN at cos θ = 0 (0/0 at η₂ = η₁)."""
    n_base = np.asarray(film.eta_base, np.float64) + 1j * np.asarray(film.kappa_base, np.float64)
    r = numpy_airy(film.eta_outer, film.eta_film, n_base, film.thickness, cos_theta, wavelength,
                   real=np.longdouble)
    return np.where(np.asarray(cos_theta) > 0, r, np.nan).astype(np.float64)
