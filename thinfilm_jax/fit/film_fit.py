r"""Gradient-based fitting of film parameters to observations (SPEC §8).

Two problems, one machinery:

* `fit_film`: patch radiances L_j(θ_o, α) of SPEC §7 (shape (n_angles, n_bands)) → the
  free subset of thickness, IORs, κ₃ and α.
* `fit_spectrum`: reflectance spectra R(θ₁, λ) of SPEC §2 at one or more angles (classic
  film metrology) → the free film parameters.

Both minimise $\tfrac12\sum_k r_k^2$ with weighted residuals $r_k = (m_k(x) - o_k)/\sigma_k$
(σ = 1 unless given) with Levenberg–Marquardt by default: the library's one implementation,
`engine.lm_solve` (the map fits run it too), stopped by the Cauchy test optimistix uses
(`FitOptions.rtol`, `atol`); optimistix's other solvers by name (`SOLVERS`). With `sigma`
given, `FitResult.reduced_chi2` and the misfit warning (`options` module docstring) say
whether the model explains the data within the noise.

**Materials (SPEC §12).** `initial` is a constant `Film` (the Airy model, the names
`PARAMS`), a `Film` with index models or a `Stack`: the model is then the stack code with
every index at each wavelength, and a free parameter is any real scalar of the material
named by its pytree path, e.g. ``"thickness[1]"`` or ``"eta_film.coefficients[0]"``
(`params`: names, default boxes, the rebuild of the material from the free values). With
several free layer thicknesses the screen below is a product grid, one axis per layer
(`DEFAULT_N_STARTS_LAYERS`), with 8 short solves per free layer, and the fringe-order moves
step each layer alone by its own order Δd_i = λ̄ / (2 n_i ⟨cos θ_i⟩).

**Bounded parameters.** Every free parameter lives in a box [lo, hi] (`DEFAULT_BOUNDS`,
overridable with `FitOptions.bounds`) and is solved for in an unconstrained variable y with

$$ x = lo + (hi - lo)\,\sigma(y),\qquad y = \operatorname{logit}\frac{x - lo}{hi - lo}, $$

so the solver can never leave the physical domain (d ≥ 0, η ∈ [1, 4], κ ∈ [0, 10],
α ∈ (0, 1]). Starting points are pulled at least 0.5 % of the box width inside it, where
σ' is not vanishingly small.

**Fringe order.** The loss is multimodal in thickness: neighbouring minima are one
interference order apart (~220 nm for RGB patches of an η₂ = 1.3 film; see
`notebooks/fitting.ipynb`), and a local solver started a few hundred nm away stops in the
wrong one. When the thickness is free the solve is multi-start (`fit.multistart`), in these
stages:

1. *screen*: the loss at `n_starts` thicknesses (default 64: midpoints of equal cells of the
   thickness box, 31 nm apart over [0, 2000] nm, so every ~±100 nm basin holds several) plus
   the initial guess, other parameters at their initial values: one model evaluation each,
   ranked by the loss profiled over a brightness gain (the guesses of α and η₂ scale the
   brightness more than they move the fringes);
2. *short solves* from the `n_solves` (8) most promising starts (the lowest local minima of
   the screened loss along the grid), `start_steps` (50) solver steps each, all free
   parameters moving (a wrong η₂ guess shifts every fringe: the solves slide along the
   d–η₂ valley); their results are ranked by the loss of the *final* model;
2b. *fringe order, explicitly*: from the best short solve, starts ±1 … ±`n_orders` (2)
   interference orders away in thickness, Δd = λ̄ / (2 η₂ ⟨cos θ₂⟩) (λ̄ the observer's mean
   band centroid), short-solved in a second round of the same batch. The screen alone
   missed 3 of 80 noise-free films of the calibration set (d 150–1200 nm, η₂ 1.2–1.7, six
   views 0–70°, one initial guess d = 500 nm, η₂ = 1.4): each landed one order too thick
   with η₂ nearly right (d 805 → 1003, 1170 → 1370, 981 → 1171 nm); with this stage all
   three are found (`python -m benchmarks.coverage`). When η₂ is free the same
   round also starts on the d–η₂ ridge: η₂ · (1 ± 0.08), (1 ± 0.16) at the same optical
   thickness η₂ d and ± one order (the data fix η₂ d far better than η₂).
3. *polish*: the 1 + `n_alternatives` (3) best *distinct* minima (thickness more than a
   quarter order apart), ranked by the final model, are solved to convergence with it
   (`max_steps`, implicit derivatives); the best is the answer, the others are reported as
   runner-ups (`FitResult.runner_up_params`, `.runner_up_loss`, `.runner_up_dchi2` =
   Δχ² against the answer) and `FitResult.ambiguous` flags a runner-up with Δχ² < 9 (the
   data cannot tell the fringe orders apart).

A full solve from every one of 64 starts would cost ~5 model evaluations per step and
start; screening costs one per start. Stages 1–2 use the start model: `method` at the
coarse `start_quadrature` (default (8, 8), ~4e-4 from converged: enough to rank fringe
orders), and stage 3 `refine_method` (default: `method`) at `quadrature`. So
``method="filtered", options=FitOptions(refine_method="reference")`` screens and explores
with the real-time path (~100× cheaper) and measures with the reference.

**Batching.** The starts are batched with `jax.vmap` on accelerators and with a sequential
`jax.lax.map` on CPU (``batching="auto"``; "vmap" / "map" force one): a vmapped solve
(a batched `while_loop`) runs every start until the slowest has finished, for no parallel
gain on CPU.

**Quadrature.** `patch_one`'s deterministic half-vector quadrature at n_u = n_φ = 16 (the
fit default; 256 nodes) is within ~1e-5 of the converged reference for θ_o ≤ 80°,
d ≤ 2 µm and every α (measured against 64 × 64; 24 gives < 1e-6, 32 < 1e-7). That is
< 1 % of the 1e-3 noise of a 1 % measurement and biases a noise-free thickness fit by
~0.01 nm. Raise `quadrature` for grazing views (θ_o → 90°), where convergence slows.

**Uncertainties.** At the optimum, with the Jacobian J of the weighted residuals with
respect to the *physical* free parameters (the chain rule through the box map, taken
directly by forward-mode AD in x),

$$ \operatorname{cov} = s^2 (J^T J)^{-1},\qquad s^2 = \frac{\sum_k r_k^2}{n - p} $$

(`engine.covariance`; `absolute_sigma=True` uses s² = 1, i.e. σ are true standard
deviations). Standard errors are √diag(cov); the correlation matrix flags trade-offs
(thickness vs film IOR for thin films; η₃ vs κ₃ from RGB patch colours):
`FitResult.degenerate` lists the pairs with |corr| > 0.95. The linearised errors are
meaningful only at a converged optimum in the right fringe order.

**Gradients.** The final solve's solution carries the implicit-function-theorem
derivatives (`engine.implicit_solution`; optimistix's implicit adjoint for its solvers),
so e.g. ``jax.grad(lambda o: fit_film(o, ...).film.thickness)`` differentiates the fitted
value with respect to the observations (implicit function theorem at the optimum); the
multi-start stage is under `stop_gradient`.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..core import _validate as V
from ..core.film import Film
from ..core.material import is_dispersive, needs_stack
from ..core.methods import METHODS as METHOD_INFO
from ..core.methods import require
from ..core.stack import Stack
from ..core.methods import names as method_names
from ..spectral.lut import build_shat_lut
from ..spectral.reflectance import band_centroids
from ..spectral.spectra import get_observer
from . import params as P
from .engine import covariance
from .film_spec import (  # the parameter map and the input checks
    _check_background,
    _check_batching,
    _check_free,
    _check_material,
    _check_options,
    _make_spec,
    _mean_wavelength,
    _n_candidates,
    _real_dtype,
    _Spec,
    _static,
    _to_x,  # noqa: F401  (the box map, read by tests)
    _to_y,  # noqa: F401
    _weights,
)
from .forward import patch_model, spectrum_model
from .multistart import grid_starts, order_moves, solve_multistart
from .options import (
    DEFAULT_BOUNDS,
    DEFAULT_N_STARTS,
    DEFAULT_N_STARTS_LAYERS,
    FILM_PARAMS,
    PARAMS,
    SOLVERS,
    FitOptions,
    FitResult,
    MisfitWarning,
    misfit_warnings,
    reduced_chi2,
)
from .raw_spectrum import fit_raw, raw_starts

__all__ = ["DEFAULT_BOUNDS", "FILM_PARAMS", "PARAMS", "FitOptions", "FitResult", "SOLVERS",
           "fit_film", "fit_spectrum", "patch_model", "spectrum_model"]



# ----------------------------------------------------------------------------- fit_film
class _SolveCfg(NamedTuple):
    """The static configuration of a multistart solve (`multistart.solve_multistart`) shared
    by the fits: the spectrum and ellipsometry fits use it as it is, `fit_film` inside its
    own (`_FilmCfg`)."""

    spec: _Spec
    solver: str
    rtol: float
    atol: float
    grid: tuple
    n_solves: int
    start_steps: int
    max_steps: int
    absolute_sigma: bool
    batching: str
    n_orders: int
    n_alternatives: int
    wavelength: float


class _FilmCfg(NamedTuple):
    """`fit_film`'s static configuration: the solve's and the forward model's."""

    solve: _SolveCfg
    method: str
    refine_method: str | None
    observer: str
    terms: int
    shat: str
    quadrature: tuple
    start_quadrature: tuple
    ndf: str


def fit_film(observed, theta_o, *, alpha, initial: Film | Stack,
             free: Sequence[str] = ("thickness",), method: str = "reference", sigma=None,
             options: FitOptions | None = None) -> FitResult:
    """Fit film parameters (and α) to patch radiances observed at view angles θ_o (SPEC §8).

    Residuals r = (model − observed)/σ over all angles and bands; the model is
    `patch_model` (`patch.patch_one` vmapped over θ_o) with `method`'s forward model.

    A process's first call compiles for its shapes, dtypes and options (27–35 s on a 2-core
    CPU); ``thinfilm_jax.enable_compilation_cache()`` keeps that on disk for later processes.

    Args:
        observed: L_j, shape (n_angles, n_bands), as from
            ``patch_radiance(film, theta_o, alpha, method=...)``.
        theta_o: view angles (n_angles,), radians in [0, π/2].
        alpha: GGX roughness (the initial guess if "alpha" is free), scalar in (0, 1].
        initial: a `Film` with scalar fields, a `Film` with index models, or a `Stack` (one
            thickness per layer) (SPEC §12): fixed values and initial guesses (concrete:
            they seed the start grid on the host; `observed` may be traced, so the fit
            works under `jax.jit`, `jax.vmap` and `jax.grad` with respect to it). A `Stack`
            needs an exact method ("reference"); a dispersive `Film` takes the real-time
            methods too (each band at its centroid), `core.methods.require` says which.
        free: names of the fitted parameters (`params` module: `Film` fields,
            ``"thickness[i]"`` of a `Stack`, an index model's ``"eta[1].coefficients[0]"``,
            ...) and/or "alpha".
        method: forward model, a `core.methods.names("patch")` name (SPEC §7).
        sigma: standard deviations of the observations (broadcast to `observed`).
        options: `FitOptions` (search, solver, quadrature, observer, ...); None = defaults.

    Returns:
        `FitResult` (``film``: the fitted material, of the type of `initial`).

    Example:
        >>> import numpy as np
        >>> from thinfilm_jax.shading.patch import patch_radiance
        >>> theta = np.linspace(0.0, 1.4, 9)
        >>> obs = patch_radiance(Film(600.0, 1.3, 2.0, 0.5), theta, 0.25)
        >>> res = fit_film(obs, theta, alpha=0.25, initial=Film(350.0, 1.3, 2.0, 0.5))
        >>> round(float(res.film.thickness), 2), bool(res.converged)
        (600.0, True)
    """
    if not isinstance(initial, Film | Stack):
        raise TypeError(f"initial must be a thinfilm_jax.Film or Stack, got "
                        f"{type(initial).__name__}")
    V.check_choice("method", method, method_names("patch"))
    o = _check_options(options, "patch")
    refine_method = None if o.refine_method == method else o.refine_method
    methods = (method,) if refine_method is None else (method, refine_method)
    if needs_stack(initial):
        for m in methods:
            require(m, dispersive=is_dispersive(initial), stack=isinstance(initial, Stack))
    exact = any(METHOD_INFO[m].dispersion == "exact" for m in methods)
    initial = _check_material(initial, get_observer(o.observer).wavelengths if exact
                              else band_centroids(o.observer))
    table = P.scalar_table(initial, with_alpha=True)
    free = _check_free(free, table, initial)
    observer = o.observer
    quadrature = o.quadrature
    start_quadrature = quadrature if o.start_quadrature is None else o.start_quadrature
    batching = _check_batching(o.batching)
    theta_o = jnp.atleast_1d(jnp.asarray(V.as_array("theta_o", theta_o)))
    if theta_o.ndim != 1:
        raise ValueError(f"theta_o must be 1-D (n_angles,), got shape {theta_o.shape}")
    theta_o = V.check_angle("theta_o", theta_o)
    if np.shape(alpha) != ():
        raise ValueError(f"alpha must be a scalar, got shape {np.shape(alpha)}")
    alpha = V.check_range("alpha", alpha, 0.0, 1.0, lo_open=True, why=" (GGX roughness)")
    observed = jnp.asarray(V.as_array("observed", observed))
    n_bands = get_observer(observer).n_bands
    if observed.shape != (theta_o.shape[0], n_bands):
        raise ValueError(f"observed must have shape (n_angles, n_bands) = "
                         f"({theta_o.shape[0]}, {n_bands}) to match theta_o and observer "
                         f"{observer!r}; got {observed.shape}")
    observed = V.check_range("observed", observed, 0.0,
                             why=" (patch radiances are non-negative)")
    if observed.size <= len(free):
        raise ValueError(f"{observed.size} observations cannot determine {len(free)} free "
                         f"parameters {free}")
    dtype = _real_dtype(observed, theta_o, alpha, *jax.tree_util.tree_leaves(initial))
    base = P.leaves(initial, alpha, dtype)
    spec, x_free0 = _make_spec(free, dict(o.bounds or ()), initial, alpha, table)
    n_starts = _default_starts(o.n_starts, "patch", spec)
    y_starts, x_starts, grid = grid_starts(spec, x_free0, n_starts, o.n_eta_starts,
                                            o.starts, dtype)
    w = _weights(sigma, observed.shape, dtype)
    lut = build_shat_lut(observer, dtype=dtype) if o.shat == "lut" else None
    static, box = _static(spec)
    solve = _SolveCfg(static, o.solver, o.rtol, o.atol, grid,
                      _n_candidates(y_starts, grid, o.n_solves), o.start_steps, o.max_steps,
                      o.absolute_sigma, batching, o.n_orders, o.n_alternatives,
                      _mean_wavelength(observer))
    cfg = _FilmCfg(solve, method, refine_method, observer, o.terms, o.shat, quadrature,
                   start_quadrature, o.ndf)
    box = tuple(jnp.asarray(b, dtype) for b in box)
    with jax.default_matmul_precision("highest"):  # optimistix/lineax contractions too
        out = _fit_film_jit(observed.astype(dtype), w, theta_o.astype(dtype), base, y_starts,
                            box, lut, cfg)
    return _result(out, free, x_starts, True, sigma is not None)


def _default_starts(n_starts, kind, spec):
    """Thicknesses per free layer of the screen: `n_starts`, else `DEFAULT_N_STARTS` for one
    free thickness and `DEFAULT_N_STARTS_LAYERS` per layer for several."""
    if n_starts is not None:
        return n_starts
    return (DEFAULT_N_STARTS if len(spec.thick) <= 1 else DEFAULT_N_STARTS_LAYERS)[kind]


@functools.partial(jax.jit, static_argnames="cfg")
def _fit_film_jit(observed, w, theta_o, base, y_starts, box, lut, cfg: _FilmCfg):
    spec = cfg.solve.spec._replace(lo=box[0], hi=box[1])
    final_method = cfg.refine_method or cfg.method

    def model_x(x, method, quad):
        film, alpha = x
        return patch_model(film, theta_o, alpha, method=method, observer=cfg.observer,
                           terms=cfg.terms, shat=cfg.shat, lut=lut, quadrature=quad,
                           ndf=cfg.ndf, arithmetic="complex")

    def residuals(method, quad):
        def fn(y, args):
            obs, ww = args
            return ((model_x(spec.x_full(y, base), method, quad) - obs) * ww).reshape(-1)
        return fn

    def res_x(x_free, args):
        obs, ww = args
        return ((model_x(spec.with_free(x_free, base), final_method, cfg.quadrature) - obs)
                * ww).reshape(-1)

    args = (observed, w)
    orders, distinct = order_moves(spec, base, jnp.cos(theta_o), cfg.solve.wavelength,
                                   cfg.solve.n_orders)
    out = solve_multistart(residuals(cfg.method, cfg.start_quadrature),
                           residuals(final_method, cfg.quadrature), y_starts, args, cfg.solve,
                           orders, distinct)
    return _finish(out, res_x, spec, base, args, w, cfg.solve)


# ----------------------------------------------------------------------------- fit_spectrum
def fit_spectrum(observed, wavelength, cos_theta, *, initial: Film | Stack,
                 free: Sequence[str] = ("thickness",), sigma=None, envelope: int | None = None,
                 background=None, options: FitOptions | None = None) -> FitResult:
    """Fit film parameters to reflectance spectra R(θ₁, λ) (SPEC §2, §12, §14; film metrology).

    The model is `spectrum_model`: the exact Airy reflectance (general Fresnel path) of a
    constant `Film`, the stack code (every index at each λ) of a `Stack` or a dispersive
    `Film`.

    A process's first call compiles for its shapes, dtypes and options (27–35 s on a 2-core
    CPU); ``thinfilm_jax.enable_compilation_cache()`` keeps that on disk for later processes.

    Args:
        observed: unpolarised reflectance, shape (n_angles, n_wl) (or (n_wl,) for one angle).
        wavelength: λ in nm, shape (n_wl,).
        cos_theta: cos θ₁ of each spectrum, shape (n_angles,) (or scalar), in [0, 1].
        initial: a `Film` with scalar fields, a `Film` with index models or a `Stack` (one
            thickness per layer): fixed values and initial guesses; index models must cover
            `wavelength`.
        free: names of the fitted scalars (`params` module): `Film` fields, a `Stack`'s
            ``"thickness[i]"`` (``"thickness"`` is layer 0), an index model's
            ``"eta[0].coefficients[0]"``, ...
        sigma: standard deviations of the observations (broadcast to `observed`). With
            `envelope` and ``sigma=None``, σ(λ) is estimated from the data (two passes:
            `raw_spectrum` module docstring).
        envelope: None (default): `observed` is absolute reflectance. An int k ≥ 0:
            `observed` is a raw spectrometer signal g(λ)·R(λ) + b(λ), g and b polynomials
            of degree k in λ per spectrum (lamp × detector; stray light and dark),
            eliminated exactly at every trial of the film parameters by variable projection
            (`thinfilm_jax.fit.raw_spectrum`): the search and the standard errors are over
            the film parameters alone, with ν = n − p − 2(k + 1)·n_angles degrees of
            freedom, and the screen's thickness spacing resolves the bluest fringes
            (`raw_spectrum.raw_starts`). `FitResult.envelope` holds g and b.
        background: with `envelope` only: a known offset b(λ) (a dark spectrum, or the
            signal with no film in the beam), broadcast to `observed`; it is subtracted and
            only g is fitted ((k + 1) linear parameters per spectrum).
        options: `FitOptions` (search and solver fields; the patch-model fields must keep
            their defaults). ``n_starts=None`` screens 256 thicknesses (one free layer) or
            a 48 × 48 grid (two free layers; `DEFAULT_N_STARTS_LAYERS` per layer): spectral
            minima are closer together than patch-colour minima, and the model is cheap.

    Returns:
        `FitResult` with ``alpha=None``; residuals of shape (n_angles, n_wl) (with
        `envelope`: g R + b − observed).

    Example:
        >>> import numpy as np
        >>> from thinfilm_jax import airy_reflectance
        >>> lam = np.linspace(400.0, 800.0, 81)
        >>> c = np.cos(np.deg2rad([0.0, 45.0]))[:, None]
        >>> obs = airy_reflectance(Film(812.0, 1.46, 3.9, 0.02), c, lam)
        >>> res = fit_spectrum(obs, lam, c[:, 0], initial=Film(400.0, 1.46, 3.9, 0.02))
        >>> round(float(res.film.thickness), 2)
        812.0
    """
    if not isinstance(initial, Film | Stack):
        raise TypeError(f"initial must be a thinfilm_jax.Film or Stack, got "
                        f"{type(initial).__name__}")
    o = _check_options(options, "spectrum")
    batching = _check_batching(o.batching)
    if envelope is not None:
        envelope = V.check_int("envelope", envelope, 0)
    elif background is not None:
        raise ValueError("background applies to raw spectra only: give envelope=k too")
    wavelength = jnp.asarray(V.as_array("wavelength", wavelength))
    cos_theta = jnp.atleast_1d(jnp.asarray(V.as_array("cos_theta", cos_theta)))
    if wavelength.ndim != 1 or cos_theta.ndim != 1:
        raise ValueError(f"wavelength and cos_theta must be 1-D; got shapes {wavelength.shape}, "
                         f"{cos_theta.shape}")
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    initial = _check_material(initial, wavelength if V.is_concrete(wavelength) else None)
    table = P.scalar_table(initial)
    free = _check_free(free, table, initial)
    cos_theta = V.check_cos_theta(cos_theta)
    observed = jnp.asarray(V.as_array("observed", observed))
    if observed.ndim == 1:
        observed = observed[None, :]
    shape = (cos_theta.shape[0], wavelength.shape[0])
    if observed.shape != shape:
        raise ValueError(f"observed must have shape (n_angles, n_wl) = {shape} to match "
                         f"cos_theta and wavelength; got {observed.shape}")
    V.check_finite("observed", observed)
    n_lin = 0 if envelope is None else (1 if background is not None else 2) * (
        envelope + 1) * shape[0]
    if observed.size <= len(free) + n_lin:
        raise ValueError(f"{observed.size} observations cannot determine {len(free)} free "
                         f"parameters {free}" + ("" if envelope is None else
                                                 f" and {n_lin} envelope coefficients "
                                                 f"(envelope={envelope})"))
    dtype = _real_dtype(observed, wavelength, cos_theta, *jax.tree_util.tree_leaves(initial))
    base = P.leaves(initial, None, dtype)
    spec, x_free0 = _make_spec(free, dict(o.bounds or ()), initial, None, table)
    n_starts = o.n_starts
    if envelope is not None:
        n_starts = raw_starts(spec, initial, wavelength, cos_theta, n_starts)
    n_starts = _default_starts(n_starts, "spectrum", spec)
    y_starts, x_starts, grid = grid_starts(spec, x_free0, n_starts, o.n_eta_starts,
                                            o.starts, dtype)
    w = _weights(sigma, shape, dtype)
    static, box = _static(spec)
    cfg = _SolveCfg(static, o.solver, o.rtol, o.atol, grid,
                   _n_candidates(y_starts, grid, o.n_solves), o.start_steps, o.max_steps,
                   o.absolute_sigma, batching, o.n_orders, o.n_alternatives,
                   float(np.mean(wavelength)) if V.is_concrete(wavelength) else 550.0)
    box = tuple(jnp.asarray(b, dtype) for b in box)
    if envelope is not None:
        background = _check_background(background, shape, dtype)
        return fit_raw(observed.astype(dtype), w, wavelength.astype(dtype),
                       cos_theta.astype(dtype), base, y_starts, x_starts, box, cfg, free,
                       envelope, sigma is not None, background, spectrum_model, _finish)
    with jax.default_matmul_precision("highest"):  # optimistix/lineax contractions too
        out = _fit_spectrum_jit(observed.astype(dtype), w, wavelength.astype(dtype),
                                cos_theta.astype(dtype), base, y_starts, box, cfg)
    return _result(out, free, x_starts, False, sigma is not None)


@functools.partial(jax.jit, static_argnames="cfg")
def _fit_spectrum_jit(observed, w, wavelength, cos_theta, base, y_starts, box, cfg: _SolveCfg):
    spec = cfg.spec._replace(lo=box[0], hi=box[1])

    def res(y, args):
        obs, ww = args
        return ((spectrum_model(spec.x_full(y, base)[0], cos_theta, wavelength) - obs)
                * ww).reshape(-1)

    def res_x(x_free, args):
        obs, ww = args
        film = spec.with_free(x_free, base)[0]
        return ((spectrum_model(film, cos_theta, wavelength) - obs) * ww).reshape(-1)

    args = (observed, w)
    orders, distinct = order_moves(spec, base, cos_theta, cfg.wavelength, cfg.n_orders)
    out = solve_multistart(res, res, y_starts, args, cfg, orders, distinct)
    return _finish(out, res_x, spec, base, args, w, cfg)


def _finish(out, res_x, spec, base, args, w, cfg):
    """Fitted parameters, loss, residuals, standard errors and runner-ups (inside jit)."""
    sol, start_loss, alt_y, alt_loss = out
    observed = args[0]
    x_free = spec.x_free(sol.value)
    fitted = spec.with_free(x_free, base)
    r = res_x(x_free, args)
    loss = 0.5 * jnp.sum(r * r)
    a = jax.lax.stop_gradient(args)
    stderr, corr, s2 = covariance(lambda v: res_x(v, a), jax.lax.stop_gradient(x_free),
                                  absolute_sigma=cfg.absolute_sigma)
    alt_x = jax.vmap(spec.x_free)(alt_y)
    # Δχ² = Σr²/s² of the runner-up minus that of the answer (s² as for the errors)
    gap = jax.lax.stop_gradient(alt_loss - loss)
    dchi2 = jnp.where(jnp.isfinite(alt_loss), 2.0 * gap / jnp.where(s2 > 0, s2, 1.0), jnp.inf)
    dchi2 = jnp.where((s2 > 0) | ~jnp.isfinite(alt_loss), dchi2,
                      jnp.where(gap > 0, jnp.inf, 0.0))
    return (sol, fitted, loss, r.reshape(observed.shape) / w, stderr, corr, start_loss, alt_x,
            alt_loss, dchi2)


def _result(out, free, x_starts, has_alpha, sigma_given):
    """The `FitResult`, with the misfit test (`options.misfit_warnings`) warned as a
    `MisfitWarning` when it fails (concrete results only: not under `jax.jit`)."""
    sol, (film, alpha), loss, resid, stderr, corr, start_loss, alt_x, alt_loss, dchi2 = out
    n, p = int(np.size(resid)), len(free)
    red = reduced_chi2(2.0 * loss, n, p, sigma_given)
    msg = misfit_warnings(red, n - p) if sigma_given else ()  # (no wait for the result)
    for m in msg:
        warnings.warn(m, MisfitWarning, stacklevel=3)
    return FitResult(film, alpha if has_alpha else None, loss,
                     sol.result == optx.RESULTS.successful, sol.stats["num_steps"],
                     dict(zip(free, stderr)), corr, free, resid, x_starts, start_loss, sol,
                     alt_x, alt_loss, dchi2, red, msg)
