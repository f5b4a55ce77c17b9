r"""What the fits take and return: `FitOptions` (search, solver and patch-model settings,
validated once, hashable: a jit static argument), `FitResult` (the fitted film, standard
errors and Student-t intervals, runner-up minima, the ambiguity flag, the misfit test), and
the constants they share (parameter names, the one table of default boxes, solvers). The
search itself is `film_fit`; the thickness maps (`thickness_map`) take their boxes and
`options` type from here too.

**Misfit test.** With the noise σ of the data given, the weighted residuals of a model that
explains the data are N(0, 1), and $\chi^2 = \sum_k r_k^2$ at the optimum follows χ² with
ν = n − p degrees of freedom (n observations, p free parameters; linearised). The reduced
χ² = χ²/ν above the 99.9 % quantile of χ²_ν/ν (`MISFIT_QUANTILE`; `scipy.stats.chi2.ppf`,
Press et al. 2007, *Numerical Recipes* §15.1–15.2) is a warning (`misfit_warnings`,
`MisfitWarning`): one fit in a thousand of a right model raises it falsely; a wrong σ,
material, view angle or forward model raises it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import NamedTuple

import numpy as np
import optimistix as optx
from jax import Array

from ..core import _validate as V
from ..core.film import Film
from ..core.stack import Stack
from ..realtime.filtered import SHAT_SOURCES
from ..core.methods import names as method_names
from ..spectral.spectra import DEFAULT_OBSERVER, OBSERVERS
from . import params as P

__all__ = ["AMBIGUOUS_DCHI2", "DEFAULT_BOUNDS", "FILM_PARAMS", "MAP_BOUNDS", "MISFIT_QUANTILE",
           "PARAMS", "SOLVERS", "FitOptions", "FitResult", "MisfitWarning", "misfit_warnings",
           "reduced_chi2"]

FILM_PARAMS = Film._fields  # ("thickness", "eta_film", "eta_base", "kappa_base", "eta_outer")
PARAMS = (*FILM_PARAMS, "alpha")

#: Boxes of the free parameters (physical units: nm, dimensionless). α's lower end keeps the
#: GGX lobe resolvable by the quadrature. A `Stack`'s ``"thickness[i]"`` takes the box of
#: "thickness"; other scalars of a material (index-model parameters, a `Stack`'s constant
#: indices) get `params.default_box`.
DEFAULT_BOUNDS = {
    "thickness": (0.0, 2000.0),
    "eta_film": (1.0, 4.0),
    "eta_base": (1.0, 4.0),
    "kappa_base": (0.0, 10.0),
    "eta_outer": (1.0, 4.0),
    "alpha": (1e-3, 1.0),
}
#: ... and of the per-pixel thickness maps (`thickness_map`): the same table, except η₂,
#: whose box is the range of the map's η₂ screen (`eta_grid` points): three band values
#: per pixel barely separate η₂ from d (the data fix the optical thickness η₂ d), so a map
#: screens the indices of real films (water 1.33 … oxides and polymers 1.5–1.7) rather
#: than all of (1, 4), where 7 screened values would be 0.5 apart.
MAP_BOUNDS = {"thickness": DEFAULT_BOUNDS["thickness"], "eta_film": (1.2, 1.8)}

#: Solver names → optimistix constructors taking (rtol, atol), except Levenberg–Marquardt
#: (None): the library's own (`engine.lm_solve`), which every fit uses (measured faster
#: than optimistix's: docs/how-to/fit-film.md). BFGS and nonlinear CG minimise ½Σr² as a
#: scalar function (no Jacobian structure): the first-order baselines.
SOLVERS = {
    "levenberg_marquardt": None,
    "gauss_newton": lambda rtol, atol: optx.GaussNewton(rtol, atol),
    "dogleg": lambda rtol, atol: optx.Dogleg(rtol, atol),
    "bfgs": lambda rtol, atol: optx.BFGS(rtol, atol),
    "nonlinear_cg": lambda rtol, atol: optx.NonlinearCG(rtol, atol),
}

DEGENERATE_CORRELATION = 0.95
#: Runner-up minima closer than this in Δχ² make a fit `FitResult.ambiguous`.
AMBIGUOUS_DCHI2 = 9.0
BATCHING = ("auto", "vmap", "map")
#: Reduced χ² above this quantile of χ²_ν/ν is a misfit warning (module docstring).
MISFIT_QUANTILE = 0.999


class MisfitWarning(UserWarning):
    """The model does not explain the data within the given noise (module docstring)."""


def reduced_chi2(chi2, n: int, p: int, sigma_given: bool):
    """χ²/(n − p), NaN when σ was not given (then χ² is not in units of the noise) or
    n ≤ p. `chi2` = Σr² of the σ-weighted residuals (array or traced)."""
    if not sigma_given or n <= p:
        return chi2 * math.nan
    return chi2 / (n - p)


def misfit_warnings(red_chi2, dof: int, what: str = "the model") -> tuple[str, ...]:
    """(message,) when the reduced χ² `red_chi2` (concrete; ν = `dof`) exceeds the
    `MISFIT_QUANTILE` point of χ²_ν/ν, else (); () for NaN or traced values."""
    from scipy.stats import chi2

    try:
        v = float(np.asarray(red_chi2))
    except (TypeError, ValueError, RuntimeError):  # a tracer: no verdict inside jit
        return ()
    if not (np.isfinite(v) and dof >= 1):
        return ()
    limit = float(chi2.ppf(MISFIT_QUANTILE, dof)) / dof
    if v <= limit:
        return ()
    return (f"reduced χ² = {v:.4g} > {limit:.4g} (the {100 * MISFIT_QUANTILE:g} % point of "
            f"χ²_ν/ν, ν = {dof}): {what} does not explain the data within the noise σ; "
            f"check σ, the material (indices), the view angles and the model",)


#: Default number of screened thicknesses per problem (`FitOptions.n_starts` = None):
#: spectral minima are closer together than patch-colour minima, and the model is cheap.
DEFAULT_N_STARTS = {"patch": 64, "spectrum": 256}
#: ... and per free layer when several layer thicknesses are free (a product grid: 48 × 48
#: for two layers of a spectrum fit; measured in docs/how-to/fit-film.md).
DEFAULT_N_STARTS_LAYERS = {"patch": 24, "spectrum": 48}


@dataclasses.dataclass(frozen=True)
class FitOptions:
    """How `fit_film` / `fit_spectrum` search and solve: one frozen, hashable value.

    The observations, the model's physics (`alpha`, `initial`, `free`, `method`) and the
    data's uncertainties (`sigma`) are arguments of the fit; everything about *how* the
    optimum is found lives here, validated once on construction. Equal options hash
    equal, so they can key a cache or a `jax.jit` static argument; vary one field with
    ``dataclasses.replace(opts, n_starts=16)`` or ``opts.replace(n_starts=16)``.

    Search (both fits):
        solver: a `SOLVERS` name (Levenberg–Marquardt by default).
        n_starts: thickness guesses spread over the thickness box (midpoints of equal
            cells), screened by their loss; 1 = the initial guess only; None = the
            problem's default (`DEFAULT_N_STARTS`: 64 for patches, 256 for spectra). With
            several free layer thicknesses (a `Stack`) this many per layer, on their product
            grid (default `DEFAULT_N_STARTS_LAYERS`: 24 per layer for patches, 48 for
            spectra).
        n_eta_starts: if "eta_film" is free, the thickness grid is screened at the
            initial η₂ and at this many η₂ values spread over its box (0: initial η₂ only).
        n_solves: short solves from the best-screened guesses (None: 2 per screened η₂
            row, at least 8 per free layer thickness).
        starts: explicit thickness guesses (nm) instead of the spread (the same for every
            free layer).
        start_steps: solver steps of each short solve.
        max_steps: solver steps of the final solve (and of each polish).
        n_orders: fringe orders either side of the best short solve that are solved
            explicitly (thickness ± k Δd, k = 1 … n_orders; 0: none; module docstring).
        n_alternatives: runner-up minima polished with the final model and reported
            (`FitResult.runner_up_params`, `FitResult.ambiguous`).
        rtol, atol: solver tolerances (on the unconstrained parameters and the loss).
        bounds: {name: (lo, hi)} overriding `DEFAULT_BOUNDS` or the default box of a
            material's scalar (a path name such as "thickness[1]" or
            "eta[0].coefficients[0]": `params`; checked against the material by the fit)
            (stored as a sorted tuple of pairs; `bounds_dict` gives the dict back).
        absolute_sigma: treat the fit's `sigma` as exact standard deviations (s² = 1)
            instead of estimating s² from the residuals.
        batching: how the starts are batched: "vmap", "map" (sequential `lax.map`) or
            "auto" (map on CPU, vmap on accelerators; module docstring).

    Patch model (`fit_film` only; `fit_spectrum` rejects non-default values):
        refine_method: if given (and different from the fit's `method`), the best
            solution of `method` is refined with this model, e.g. ``method="filtered"``
            with ``refine_method="reference"``: screening and multi-start with the cheap
            real-time path, one final solve with the reference.
        observer, terms, shat, ndf: as for `patch_radiance`.
        quadrature: (n_u, n_φ) of the fit's half-vector quadrature (default (16, 16);
            accuracy in the module docstring).
        start_quadrature: quadrature of the screening and short solves (None:
            `quadrature`).

    Example:
        >>> opts = FitOptions(n_starts=32, quadrature=(8, 8))
        >>> opts.replace(max_steps=20).max_steps, hash(opts) == hash(FitOptions(n_starts=32,
        ...     quadrature=[8, 8]))
        (20, True)
    """

    solver: str = "levenberg_marquardt"
    n_starts: int | None = None
    n_eta_starts: int = 6
    n_solves: int | None = None
    starts: tuple | None = None
    start_steps: int = 50
    max_steps: int = 100
    rtol: float = 1e-8
    atol: float = 1e-10
    bounds: tuple | None = None
    absolute_sigma: bool = False
    batching: str = "auto"
    refine_method: str | None = None
    observer: str = DEFAULT_OBSERVER
    terms: int = 2
    shat: str = "exact"
    quadrature: tuple = (16, 16)
    start_quadrature: tuple | None = (8, 8)
    ndf: str = "ggx"
    n_orders: int = 2
    n_alternatives: int = 2

    def __post_init__(self):
        put = functools.partial(object.__setattr__, self)
        V.check_choice("solver", self.solver, SOLVERS)
        for name in ("n_starts", "n_solves"):
            v = getattr(self, name)
            if v is not None:
                put(name, V.check_int(name, v, 1))
        put("n_eta_starts", V.check_int("n_eta_starts", self.n_eta_starts, 0))
        put("start_steps", V.check_int("start_steps", self.start_steps, 1))
        put("max_steps", V.check_int("max_steps", self.max_steps, 1))
        put("n_orders", V.check_int("n_orders", self.n_orders, 0))
        put("n_alternatives", V.check_int("n_alternatives", self.n_alternatives, 0))
        for name in ("rtol", "atol"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, int | float | np.floating)
                                           and np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a non-negative float, got {v!r}")
            put(name, float(v))
        if self.starts is not None:
            try:
                d = np.sort(np.asarray(self.starts, float).reshape(-1))
            except (TypeError, ValueError):
                raise ValueError(f"starts must be thicknesses (nm), got {self.starts!r}") from None
            if d.size == 0 or not np.all(np.isfinite(d)):
                raise ValueError("starts must be finite thicknesses (nm), at least one")
            put("starts", tuple(float(v) for v in d))
        put("bounds", _normalise_bounds(self.bounds))
        if not isinstance(self.absolute_sigma, bool | np.bool_):
            raise ValueError(f"absolute_sigma must be a bool, got {self.absolute_sigma!r}")
        put("absolute_sigma", bool(self.absolute_sigma))
        V.check_choice("batching", self.batching, BATCHING)
        if self.refine_method is not None:
            V.check_choice("refine_method", self.refine_method, method_names("patch"))
        V.check_choice("observer", self.observer, OBSERVERS)
        V.check_choice("shat", self.shat, SHAT_SOURCES)
        V.check_choice("ndf", self.ndf, ("ggx", "beckmann"))
        put("terms", V.check_int("terms", self.terms, 0))
        put("quadrature", V.check_quadrature(self.quadrature, "quadrature"))
        if self.start_quadrature is not None:
            put("start_quadrature", V.check_quadrature(self.start_quadrature,
                                                       "start_quadrature"))

    @property
    def bounds_dict(self) -> dict:
        """{name: (lo, hi)}: `DEFAULT_BOUNDS` with the overrides of `bounds` applied."""
        return {**DEFAULT_BOUNDS, **dict(self.bounds or ())}

    def replace(self, **changes) -> FitOptions:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


_PATCH_ONLY = ("refine_method", "observer", "terms", "shat", "quadrature", "start_quadrature",
               "ndf")


def _normalise_bounds(bounds):
    """{name: (lo, hi)} or pairs → a sorted tuple of (name, (lo, hi)) (hashable), checked."""
    if bounds is None:
        return None
    items = bounds.items() if isinstance(bounds, dict) else bounds
    out = {}
    for k, v in items:
        if k not in DEFAULT_BOUNDS and not P.is_path_name(k):
            raise ValueError(f"bounds: unknown parameter {k!r}; expected names from "
                             f"{list(DEFAULT_BOUNDS)} or a material's path name such as "
                             f"'thickness[1]' (thinfilm_jax.fit.params)")
        try:
            lo, hi = (float(t) for t in v)
        except (TypeError, ValueError):
            raise ValueError(f"bounds[{k!r}] must be a pair (lo, hi); got {v!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"bounds[{k!r}] must be finite with lo < hi; got {v!r}")
        out[k] = (lo, hi)
    return tuple(sorted(out.items()))


class FitResult(NamedTuple):
    """Outcome of `fit_film` / `fit_spectrum`.

    Attributes:
        film: the fitted material, a `Film` or a `Stack` as `initial` was (fixed fields as
            given in `initial`).
        alpha: fitted (or given) GGX α; None for `fit_spectrum`.
        loss: ½ Σ r² at the optimum (weighted residuals).
        converged: True where the final solve met its tolerances
            (``solution.result == optx.RESULTS.successful``).
        steps: number of steps of the final solve.
        stderr: {name: standard error} for each free parameter (physical units), keyed by
            the names as given in `free`.
        correlation: (p, p) correlation matrix of the free parameters, in the order `free`.
        free: names of the free parameters.
        residuals: model − observed (unweighted), shape of the observations.
        start_params: (N, p) screened starting points (physical, in the order `free`; the
            initial guess last).
        start_loss: (N,) loss of the start model at each of them.
        solution: the `optx.Solution` of the final solve (`.value` is unconstrained y).
        runner_up_params: (K, p) the next-best distinct local minima found (K =
            `FitOptions.n_alternatives`; physical, in the order `free`), best first; a
            neighbouring fringe order is usually among them.
        runner_up_loss: (K,) their loss ½Σr² (inf: no further distinct minimum found).
        runner_up_dchi2: (K,) Δχ² = (Σr²(runner-up) − Σr²(answer)) / s², with s² as for the
            standard errors: how much worse the data say each runner-up is. Under Gaussian
            noise, Δχ² < `AMBIGUOUS_DCHI2` (9) means a likelihood ratio below e^4.5 ≈ 90:
            see `ambiguous`.
        reduced_chi2: Σr²/(n − p) of the σ-weighted residuals (n observations, p free
            parameters); NaN when the fit was given no `sigma` or n ≤ p. ≈ 1 when the
            model explains the data within the noise.
        warnings: messages about the fit: the misfit test (module docstring), when the
            reduced χ² exceeds the 99.9 % point of χ²_ν/ν (the fits also `warnings.warn`
            it as a `MisfitWarning`); empty under `jax.jit` (no concrete values).
        envelope: the fitted lamp envelope g(λ), b(λ) of a raw-spectrum fit
            (``fit_spectrum(..., envelope=k)``: `raw_spectrum.Envelope`); None otherwise.
    """

    film: Film | Stack
    alpha: Array | None
    loss: Array
    converged: Array
    steps: Array
    stderr: dict
    correlation: Array
    free: tuple
    residuals: Array
    start_params: Array
    start_loss: Array
    solution: optx.Solution
    runner_up_params: Array
    runner_up_loss: Array
    runner_up_dchi2: Array
    reduced_chi2: Array = math.nan
    warnings: tuple = ()
    envelope: object = None

    @property
    def ambiguous(self) -> bool:
        """True when a runner-up minimum (typically another fringe order) fits the data
        almost as well, Δχ² < `AMBIGUOUS_DCHI2`: the data cannot tell them apart, and the
        standard errors (local to one minimum) understate the uncertainty."""
        return bool(np.any(np.asarray(self.runner_up_dchi2) < AMBIGUOUS_DCHI2))

    @property
    def runner_ups(self) -> list[dict]:
        """The runner-up minima as [{"params": {name: value}, "loss": ..., "dchi2": ...}]
        (only those found), best first."""
        out = []
        for xk, lk, ck in zip(np.asarray(self.runner_up_params), np.asarray(self.runner_up_loss),
                              np.asarray(self.runner_up_dchi2)):
            if np.isfinite(lk):
                out.append({"params": dict(zip(self.free, map(float, xk))), "loss": float(lk),
                            "dchi2": float(ck)})
        return out

    def interval(self, level: float = 0.95, *, absolute_sigma: bool = False) -> dict:
        """{name: (low, high)} confidence intervals, fitted value ± q · stderr.

        With s² estimated from the residuals (the default), (fit − truth)/stderr follows
        Student's t with n − p degrees of freedom (n observations, p free parameters), not
        N(0, 1): q is its (1 + level)/2 quantile (few views: 12 observations and 3 free
        parameters give q = 2.26 at 95 %, where ±2 SE covers 92.3 %). Pass
        ``absolute_sigma=True`` when the fit used ``FitOptions(absolute_sigma=True)`` (σ
        known): then q is the normal quantile. Measured calibration (1 % noise, 200 films):
        README "The global minimum and honest error bars", `benchmarks.coverage`.
        Local to this minimum: see `ambiguous` for other fringe orders. A raw-spectrum fit
        (`envelope`) also counts its eliminated linear parameters: n − p − 2(k + 1) per
        spectrum.
        """
        from scipy.stats import norm, t

        if not 0.0 < float(level) < 1.0:
            raise ValueError(f"level must be in (0, 1), got {level!r}")
        dof = int(np.asarray(self.residuals).size) - len(self.free) - (
            0 if self.envelope is None else self.envelope.n_linear)
        q = norm.ppf(0.5 + level / 2) if absolute_sigma or dof < 1 else t.ppf(0.5 + level / 2,
                                                                               dof)
        return {k: (float(v) - q * float(self.stderr[k]), float(v) + q * float(self.stderr[k]))
                for k, v in self.params.items()}

    @property
    def params(self) -> dict:
        """{name: fitted value} of the free parameters."""
        return {k: P.value_of(self.film, self.alpha, k) for k in self.free}

    @property
    def degenerate(self) -> list[tuple[str, str]]:
        """Pairs of free parameters with |correlation| > 0.95 (ill-posed combinations)."""
        c = np.asarray(self.correlation)
        return [(a, b) for i, a in enumerate(self.free) for j, b in enumerate(self.free)
                if j > i and not abs(c[i, j]) <= DEGENERATE_CORRELATION]

    def to_dict(self) -> dict:
        """JSON-ready summary: plain floats and lists, None for non-finite values."""

        def f(x):
            if x is None:
                return None
            v = float(np.asarray(x))
            return v if np.isfinite(v) else None

        def lst(x):
            a = np.asarray(x, float)
            return [lst(v) for v in a] if a.ndim > 1 else [f(v) for v in a]

        return {
            "film": material_dict(self.film),
            "alpha": f(self.alpha),
            "free": list(self.free),
            "params": {k: f(v) for k, v in self.params.items()},
            "stderr": {k: f(v) for k, v in self.stderr.items()},
            "correlation": lst(self.correlation),
            "degenerate": [list(p) for p in self.degenerate],
            "loss": f(self.loss),
            "rms_residual": f(np.sqrt(np.mean(np.asarray(self.residuals) ** 2))),
            "converged": bool(self.converged),
            "steps": int(self.steps),
            "residuals": lst(self.residuals),
            "n_starts_screened": int(np.shape(self.start_loss)[0]),
            "runner_ups": [{"params": {k: f(v) for k, v in ru["params"].items()},
                            "loss": f(ru["loss"]), "dchi2": f(ru["dchi2"])}
                           for ru in self.runner_ups],
            "ambiguous": self.ambiguous,
            "reduced_chi2": f(self.reduced_chi2),
            "warnings": list(self.warnings),
            **({} if self.envelope is None else {"envelope": self.envelope.to_dict()}),
        }


def _index_json(eta):
    """An index for JSON: a real number, {"n": …, "k": …} for a complex one, or an index
    model's name (its `name`, or its type)."""
    if callable(eta):
        return getattr(eta, "name", "") or type(eta).__name__
    v = complex(np.asarray(eta))
    if v.imag == 0:
        return float(v.real) if np.isfinite(v.real) else None
    return {"n": float(v.real), "k": float(v.imag)}


def material_dict(material) -> dict:
    """A fitted `Film` or `Stack` as plain JSON: numbers, index names for index models, a
    `Stack` as ``{"thickness": [...], "eta": [...], "eta_base": ..., "eta_outer": ...}``
    (layer 0 first)."""
    if isinstance(material, Stack):
        d = np.asarray(material.thickness, float).reshape(-1)
        return {"thickness": [float(v) if np.isfinite(v) else None for v in d],
                "eta": [_index_json(e) for e in material.eta],
                "eta_base": _index_json(material.eta_base),
                "eta_outer": _index_json(material.eta_outer)}
    return {k: _index_json(v) for k, v in material._asdict().items()}
