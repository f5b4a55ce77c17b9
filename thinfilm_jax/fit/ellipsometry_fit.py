r"""Fitting a film or a layer stack to ellipsometric angles ψ, Δ (SPEC §14).

`fit_ellipsometry` is `fit_spectrum` with the ellipsometric model in place of the
reflectance: the same parameters (`params`: any thickness ``"thickness[i]"``, any real
scalar of an index model such as a Cauchy coefficient or an oscillator's energy), the same
boxes, the same multi-start search (a screen of the thickness box, short
Levenberg–Marquardt solves from the best local minima, the fringe-order moves, the polish of
the best distinct minima: `fit.multistart`, `engine.lm_solve`), the same standard errors
and misfit test (`options`).

**Residuals.** Two per measured point i, in degrees,

$$ r_i^\psi = \frac{\psi_i^{\rm model} - \psi_i}{\sigma^\psi_i},\qquad
   r_i^\Delta = \frac{F(\Delta_i^{\rm model}) - F(\Delta_i)}{\sigma^\Delta_i},\qquad
   F(\Delta) = \text{Δ mod 360°, reflected about 180°} \in [0°, 180°], $$

With σ given, ½Σr² is WVASE's MSE² (2n − p)/2 (J.A. Woollam, *Guide to using WVASE*:
MSE = √(Σ[(Δψ/σψ)² + (ΔΔ/σΔ)²]/(2n − p))) and the reduced χ² is that MSE². **Without σ**,
σψ = 1° and σΔ = 1°/sin 2ψ_i (the observed ψ): a Δ error δΔ moves the measured Stokes pair
(C, S) = sin 2ψ (cos Δ, sin Δ) by sin 2ψ δΔ, so this is the weighting of CompleteEASE's
N, C, S misfit, and it fades out the points where ψ → 0 and Δ is undefined (ρ → 0). With
1° for every Δ instead, one point near a ψ minimum (Δ swinging through 40° within 10 nm of
wavelength) made the loss of a 120 nm oxide on silicon rugged at the 1 nm scale, and the
search stopped in a false minimum at 121.2 nm. The model's Δ is folded as WVASE folds the
data (`optics.ellipsometry`:
F(Δ) = atan2(|Im ρ|, Re ρ)), and so is the observed Δ (data already in [0°, 180°] are
unchanged; data reported in [0°, 360°) or (−180°, 180°] are folded the same way). Why
this residual:

* F is continuous (a reflection: 179.9° and 180.1° both give ≈ 180°, 0.1° and 359.9° both
  ≈ 0°), so there is no 0/360 wrap jump anywhere; its one non-smooth point, a kink where
  Im ρ = 0 (Δ exactly 0° or 180°), is where the folded data lie anyway.
* A residual on cos Δ would be smooth, but d cos Δ / dΔ = −sin Δ vanishes at 0° and 180°,
  where silicon substrates and thin films on them are measured (Δ ≈ 170–180°): it would
  discard most of their information. A residual on the complex ρ = tan ψ e^{iΔ} weights
  the points by tan ψ (a 5× spread over one spectrum) and loses the meaning of σψ, σΔ,
  which instruments report (the σ columns of a WVASE export).
* The data's Δ is undefined where ψ → 0 (ρ → 0): the default σΔ above, or the file's σΔ
  (WVASE's exports carry it, large there), down-weights such points.

The multi-start screen ranks its candidates by a loss profiled over a brightness gain
(`multistart._screen`, made for patch colours); here that only reorders candidates of
similar loss (ψ and Δ of the right basin match at gain 1), and the candidates are ranked by
their converged loss afterwards.

Example (a 120 nm SiO₂-like film on a silicon-like base, recovered from ψ, Δ):
    >>> import numpy as np
    >>> from thinfilm_jax import Film
    >>> from thinfilm_jax.optics.ellipsometry import ellipsometry
    >>> lam = np.linspace(400.0, 800.0, 41); aoi = np.full(41, 70.0)
    >>> psi, delta = ellipsometry(Film(120.0, 1.46, 3.9, 0.02), np.cos(np.deg2rad(aoi)), lam)
    >>> res = fit_ellipsometry(psi, delta, lam, aoi, initial=Film(300.0, 1.46, 3.9, 0.02))
    >>> round(float(res.film.thickness), 4)
    120.0
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..core import _validate as V
from ..core.film import Film
from ..core.stack import Stack
from ..optics.ellipsometry import check_lossless_ambient, fold_delta, psi_delta_traced
from . import params as P
from .film_fit import (
    _check_batching,
    _check_free,
    _check_material,
    _check_options,
    _default_starts,
    _finish,
    _make_spec,
    _n_candidates,
    _real_dtype,
    _result,
    _SolveCfg,
    _static,
)
from .multistart import grid_starts, order_moves, solve_multistart
from .options import FitOptions, FitResult

__all__ = ["ellipsometry_model", "fit_ellipsometry"]


def ellipsometry_model(material, cos_theta, wavelength):
    """(ψ, F(Δ)) in degrees stacked on a leading axis of size 2, shape (2, n), at the
    measured points (cos θ_i, λ_i) (n,): the fit's forward model (no validation)."""
    psi, delta = psi_delta_traced(material, cos_theta, wavelength, fold=True)
    return jnp.stack([psi, delta])


def _points(psi, delta, wavelength, angle_deg):
    """The measured points as four 1-D float arrays of one length, checked (names in errors)."""
    arrs = {}
    for name, v in (("psi", psi), ("delta", delta), ("wavelength", wavelength),
                    ("angle_deg", angle_deg)):
        a = jnp.atleast_1d(jnp.asarray(V.as_array(name, v)))
        if a.ndim != 1:
            raise ValueError(f"{name} must be 1-D (one value per measured point); got shape "
                             f"{a.shape}")
        V.check_finite(name, a)
        arrs[name] = a
    n = arrs["psi"].shape[0]
    shapes = {k: a.shape[0] for k, a in arrs.items()}
    bad = {k: m for k, m in shapes.items() if m not in (n, 1) or (k != "wavelength" and
                                                                   k != "angle_deg" and m != n)}
    if bad:
        raise ValueError(f"psi, delta, wavelength and angle_deg must have one value per "
                         f"point (wavelength, angle_deg may be one value for all); got "
                         f"lengths {shapes}")
    arrs["wavelength"] = jnp.broadcast_to(arrs["wavelength"], (n,))
    arrs["angle_deg"] = jnp.broadcast_to(arrs["angle_deg"], (n,))
    V.check_range("psi", arrs["psi"], 0.0, 90.0, why=" (degrees)")
    V.check_range("wavelength", arrs["wavelength"], 0.0, lo_open=True, why=" (nm)")
    V.check_range("angle_deg", arrs["angle_deg"], 0.0, 90.0, hi_open=True,
                  why=" (degrees of incidence)")
    return arrs["psi"], arrs["delta"], arrs["wavelength"], arrs["angle_deg"]


def _sigma_weights(sigma_psi, sigma_delta, psi, dtype):
    """1/σ of shape (2, n) (ψ row, Δ row); both σ or none. None: 1 for ψ and sin 2ψ for Δ
    (module docstring)."""
    n = psi.shape[0]
    if (sigma_psi is None) != (sigma_delta is None):
        raise ValueError("give both sigma_psi and sigma_delta (the misfit test needs the noise "
                         "of both) or neither")
    if sigma_psi is None:
        return jnp.stack([jnp.ones((n,), dtype),
                          jnp.sin(jnp.deg2rad(2.0 * psi.astype(dtype)))])
    rows = []
    for name, s in (("sigma_psi", sigma_psi), ("sigma_delta", sigma_delta)):
        s = jnp.asarray(V.as_array(name, s))
        if V.is_concrete(s) and not np.all(np.isfinite(np.asarray(s))):
            raise ValueError(f"{name} must be finite (a file without σ columns gives NaN: pass "
                             f"None then); got NaN or inf")
        V.check_range(name, s, 0.0, lo_open=True, why=" (degrees)")
        try:
            rows.append(1.0 / jnp.broadcast_to(jnp.asarray(s, dtype), (n,)))
        except ValueError:
            raise ValueError(f"{name} of shape {np.shape(s)} does not broadcast to the {n} "
                             f"points") from None
    return jnp.stack(rows)


def fit_ellipsometry(psi, delta, wavelength, angle_deg, *, initial: Film | Stack,
                     free: Sequence[str] = ("thickness",), sigma_psi=None, sigma_delta=None,
                     options: FitOptions | None = None) -> FitResult:
    """Fit film or stack parameters to ellipsometric angles ψ, Δ (SPEC §14; module
    docstring).

    Args:
        psi, delta: ψ ∈ [0°, 90°] and Δ (degrees; folded into [0°, 180°] as WVASE does),
            one value per measured point, shape (n,) (e.g. from `read_ellipsometry`).
        wavelength: λ of each point in nm, (n,) (or one value for all).
        angle_deg: angle of incidence of each point in degrees, in [0°, 90°), (n,) (or one).
        initial: a `Film` (constant or with index models) or a `Stack`: fixed values and
            initial guesses; its ambient `eta_outer` must be lossless; index models must
            cover `wavelength`.
        free: the fitted scalars (`params`): ``"thickness"`` / ``"thickness[i]"``, an index
            model's ``"eta[0].coefficients[0]"`` (Cauchy A), an oscillator's
            ``"eta[0].terms[0].energy[0]"``, ...
        sigma_psi, sigma_delta: standard deviations of ψ and Δ (degrees; broadcast to (n,));
            both or neither (None: 1° and 1°/sin 2ψ, module docstring). With them
            `FitResult.reduced_chi2` is WVASE's MSE² and the misfit test runs.
        options: `FitOptions` (search and solver fields, as for `fit_spectrum`).

    Returns:
        `FitResult` (``alpha=None``); ``residuals`` (2, n): model − observed ψ (row 0) and
        folded Δ (row 1), degrees.
    """
    if not isinstance(initial, Film | Stack):
        raise TypeError(f"initial must be a thinfilm_jax.Film or Stack, got "
                        f"{type(initial).__name__}")
    o = _check_options(options, "spectrum")
    batching = _check_batching(o.batching)
    psi, delta, wavelength, angle = _points(psi, delta, wavelength, angle_deg)
    concrete = V.is_concrete(wavelength)
    check_lossless_ambient(initial, wavelength, "initial")
    initial = _check_material(initial, wavelength if concrete else None)
    table = P.scalar_table(initial)
    free = _check_free(free, table, initial)
    n = psi.shape[0]
    if 2 * n <= len(free):
        raise ValueError(f"{2 * n} observations (ψ and Δ of {n} points) cannot determine "
                         f"{len(free)} free parameters {free}")
    dtype = _real_dtype(psi, delta, wavelength, angle, *jax.tree_util.tree_leaves(initial))
    observed = jnp.stack([psi, fold_delta(delta)]).astype(dtype)
    cos_theta = jnp.cos(jnp.deg2rad(angle.astype(dtype)))
    base = P.leaves(initial, None, dtype)
    spec, x_free0 = _make_spec(free, dict(o.bounds or ()), initial, None, table)
    n_starts = _default_starts(o.n_starts, "spectrum", spec)
    y_starts, x_starts, grid = grid_starts(spec, x_free0, n_starts, o.n_eta_starts, o.starts,
                                           dtype)
    w = _sigma_weights(sigma_psi, sigma_delta, psi, dtype)
    static, box = _static(spec)
    cfg = _SolveCfg(static, o.solver, o.rtol, o.atol, grid,
                     _n_candidates(y_starts, grid, o.n_solves), o.start_steps, o.max_steps,
                     o.absolute_sigma, batching, o.n_orders, o.n_alternatives,
                     float(np.mean(np.asarray(wavelength))) if concrete else 550.0)
    box = tuple(jnp.asarray(b, dtype) for b in box)
    with jax.default_matmul_precision("highest"):
        out = _fit_ellipsometry_jit(observed, w, wavelength.astype(dtype), cos_theta, base,
                                    y_starts, box, cfg)
    return _result(out, free, x_starts, False, sigma_psi is not None)


@functools.partial(jax.jit, static_argnames="cfg")
def _fit_ellipsometry_jit(observed, w, wavelength, cos_theta, base, y_starts, box,
                          cfg: _SolveCfg):
    spec = cfg.spec._replace(lo=box[0], hi=box[1])

    def res_x(x_free, args):
        obs, ww = args
        material = spec.with_free(x_free, base)[0]
        return ((ellipsometry_model(material, cos_theta, wavelength) - obs) * ww).reshape(-1)

    def res(y, args):
        return res_x(spec.x_free(y), args)

    args = (observed, w)
    orders, distinct = order_moves(spec, base, cos_theta, cfg.wavelength, cfg.n_orders)
    out = solve_multistart(res, res, y_starts, args, cfg, orders, distinct)
    return _finish(out, res_x, spec, base, args, w, cfg)
