r"""Gradient-based fitting of film parameters to observations (SPEC §8).

Two problems, one machinery:

* `fit_film`: patch radiances L_j(θ_o, α) of SPEC §7 (shape (n_angles, n_bands)) → the
  free subset of thickness, IORs, κ₃ and α.
* `fit_spectrum`: reflectance spectra R(θ₁, λ) of SPEC §2 at one or more angles (classic
  film metrology) → the free film parameters.

Both minimise $\tfrac12\sum_k r_k^2$ with weighted residuals $r_k = (m_k(x) - o_k)/\sigma_k$
(σ = 1 unless given) with optimistix (`optx.least_squares`, Levenberg–Marquardt by default).

**Bounded parameters.** Every free parameter lives in a box [lo, hi] (`DEFAULT_BOUNDS`,
overridable with `FitOptions.bounds`) and is solved for in an unconstrained variable y with

$$ x = lo + (hi - lo)\,\sigma(y),\qquad y = \operatorname{logit}\frac{x - lo}{hi - lo}, $$

so the solver can never leave the physical domain (d ≥ 0, η ∈ [1, 4], κ ∈ [0, 10],
α ∈ (0, 1]). Starting points are pulled at least 0.5 % of the box width inside it, where
σ' is not vanishingly small.

**Fringe order.** The loss is multimodal in thickness: neighbouring minima are one
interference order apart (~220 nm for RGB patches of an η₂ = 1.3 film; see
`notebooks/fitting.ipynb`), and a local solver started a few hundred nm away stops in the
wrong one. When the thickness is free the solve is multi-start, in these stages:

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
   three are found (`python -m thinfilm_jax.studies.coverage`). When η₂ is free the same
   round also starts on the d–η₂ ridge: η₂ · (1 ± 0.08), (1 ± 0.16) at the same optical
   thickness η₂ d and ± one order (the data fix η₂ d far better than η₂).
3. *polish*: the 1 + `n_alternatives` (3) best *distinct* minima (thickness more than a
   quarter order apart), ranked by the final model, are solved to convergence with it
   (`max_steps`, implicit adjoint); the best is the answer, the others are reported as
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
`jax.lax.map` on CPU (``batching="auto"``; "vmap" / "map" force one): a vmapped
`optx.least_squares` runs every start until the slowest has finished and, on CPU, compiles
~3× slower for no parallel gain.

**Quadrature.** `patch_one`'s deterministic half-vector quadrature at n_u = n_φ = 16 (the
fit default; 256 nodes) is within ~1e-5 of the converged reference for θ_o ≤ 80°,
d ≤ 2 µm and every α (measured against 64 × 64; 24 gives < 1e-6, 32 < 1e-7). That is
< 1 % of the 1e-3 noise of a 1 % measurement and biases a noise-free thickness fit by
~0.01 nm. Raise `quadrature` for grazing views (θ_o → 90°), where convergence slows.

**Uncertainties.** At the optimum, with the Jacobian J of the weighted residuals with
respect to the *physical* free parameters (the chain rule through the box map, taken
directly by forward-mode AD in x),

$$ \operatorname{cov} = s^2 (J^T J)^{-1},\qquad s^2 = \frac{\sum_k r_k^2}{n - p} $$

(`absolute_sigma=True` uses s² = 1, i.e. σ are true standard deviations). Standard errors
are √diag(cov); the correlation matrix flags trade-offs (thickness vs film IOR for thin
films; η₃ vs κ₃ from RGB patch colours): `FitResult.degenerate` lists the pairs
with |corr| > 0.95. The linearised errors are meaningful only at a converged optimum in
the right fringe order.

**Gradients.** The final solve runs under optimistix's implicit adjoint, so e.g.
``jax.grad(lambda o: fit_film(o, ...).film.thickness)`` differentiates the fitted value
with respect to the observations (implicit function theorem at the optimum); the
multi-start stage is under `stop_gradient`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax import Array

from ..core import _validate as V
from ..optics.airy import polarised_reflectance
from ..core.film import Film
from ..optics.fresnel import film_interfaces, safe_div
from ..spectral.lut import build_shat_lut
from ..realtime.options import ModelOptions
from ..shading.patch import METHODS, patch_one
from ..spectral.spectra import DEFAULT_OBSERVER, get_observer

from .options import (_PATCH_ONLY, _START_MARGIN, BATCHING, DEFAULT_BOUNDS,
                          DEFAULT_N_STARTS, FILM_PARAMS, PARAMS, SOLVERS, FitOptions, FitResult)

__all__ = ["DEFAULT_BOUNDS", "FILM_PARAMS", "FitOptions", "FitResult", "SOLVERS", "fit_film",
           "fit_spectrum", "patch_model", "spectrum_model"]

# ----------------------------------------------------------------------------- forward models
def patch_model(film: Film, theta_o, alpha, *, method: str = "reference",
                observer: str = DEFAULT_OBSERVER, terms: int = 2, shat: str = "exact", lut=None,
                quadrature: tuple[int, int] = (16, 16), ndf: str = "ggx",
                arithmetic: str = "complex") -> Array:
    """L_j at each view angle: `patch_one` vmapped over `theta_o` (n_angles,) → (n_angles, J).

    Scalar film fields and α; no validation (jit- and vmap-safe): the fit's forward model.
    """
    options = ModelOptions(terms=terms, shat=shat, ndf=ndf, quadrature=tuple(quadrature),
                           arithmetic=arithmetic)

    def one(t):
        return patch_one(film, t, alpha, method=method, observer=observer, options=options,
                         lut=lut)

    return jax.vmap(one)(jnp.asarray(theta_o))


def spectrum_model(film: Film, cos_theta, wavelength) -> Array:
    """Airy R (SPEC §2) on the grid cos θ₁ (n_angles,) × λ (n_wl,) → (n_angles, n_wl).

    Scalar film fields; general (complex) Fresnel path; no validation.
    """
    c = jnp.asarray(cos_theta)[:, None]
    ifc = film_interfaces(film, c, arithmetic="complex")
    return jnp.mean(polarised_reflectance(ifc, film.thickness, jnp.asarray(wavelength)[None, :]),
                    axis=0)


# ----------------------------------------------------------------------------- parameter map
def _to_x(y, lo, hi):
    return lo + (hi - lo) * jax.nn.sigmoid(y)


def _to_y(x, lo, hi):
    u = jnp.clip((x - lo) / (hi - lo), _START_MARGIN, 1.0 - _START_MARGIN)
    return jnp.log(u) - jnp.log1p(-u)


class _Spec(NamedTuple):
    """The free parameters: names and indices into PARAMS (static), boxes lo, hi (p,) (host
    arrays, passed to the jitted solve as traced arrays: new bounds never recompile)."""

    free: tuple
    index: tuple
    lo: object
    hi: object

    def x_free(self, y):
        """Physical values of the free parameters from the unconstrained y (p,)."""
        return _to_x(y, jnp.asarray(self.lo, y.dtype), jnp.asarray(self.hi, y.dtype))

    def with_free(self, x_free, base_x):
        """The six physical parameters (a tuple of scalars), free ones from `x_free`.

        Built field by field (no scatter), so that derivatives with respect to the free
        parameters never flow through the fixed ones: a jvp through the patch model then
        skips e.g. the α-dependence of the quadrature when α is fixed.
        """
        out = [base_x[i] for i in range(len(PARAMS))]
        for k, i in enumerate(self.index):
            out[i] = x_free[k]
        return tuple(out)

    def x_full(self, y, base_x):
        """The six physical parameters with the free ones mapped from y."""
        return self.with_free(self.x_free(y), base_x)

    def y_of(self, x_free):
        return _to_y(x_free, jnp.asarray(self.lo, x_free.dtype), jnp.asarray(self.hi, x_free.dtype))


def _split(x):
    return Film(*(x[i] for i in range(5))), x[5]


# ----------------------------------------------------------------------------- shared solve
def _solver(name, rtol, atol):
    return SOLVERS[name](rtol, atol)


def _loss(fn, y, args):
    r = fn(y, args)
    return 0.5 * jnp.sum(r * r)


def _batch(fn, xs, batching):
    """fn over the leading axis of xs: `jax.vmap`, or sequential `jax.lax.map`."""
    return jax.vmap(fn)(xs) if batching == "vmap" else jax.lax.map(fn, xs)


def _screen(res_screen, y_starts, n_cols, n_solves, args, batching):
    """Loss at every start (one model evaluation each, no gradient) and the `n_solves` most
    promising starts: local minima along each thickness row of the grid (rows of `n_cols`
    thicknesses, one per screened η₂), lowest first (the initial guess, last in `y_starts`,
    always counts as a candidate).

    Candidates are ranked by the loss *profiled over a brightness gain*,
    min_g ½|g m − o|² with g ∈ [0.5, 2] (closed form): the starts' α and η₂ are guesses that
    scale the patch's brightness more than they move its fringes, and the plain loss ranks
    the right fringe order below brighter wrong ones (`studies.coverage`: two of 200 noisy fits,
    d ≈ 930 and 1070 nm, were found only this way). The returned losses are the plain ones.
    """
    a = jax.lax.stop_gradient(args)
    ow = (a[0] * a[1]).reshape(-1)  # the weighted observations

    def losses_at(y):
        r = res_screen(y, a)
        mw = r + ow  # the weighted model
        g = jnp.clip(safe_div(jnp.sum(mw * ow), jnp.sum(mw * mw), 1.0), 0.5, 2.0)
        rg = g * mw - ow
        return 0.5 * jnp.sum(r * r), 0.5 * jnp.sum(rg * rg)

    losses, profiled = _batch(losses_at, y_starts, batching)
    safe = jnp.where(jnp.isnan(profiled), jnp.inf, profiled)
    grid = safe[:-1].reshape(-1, n_cols)
    inf = jnp.full((grid.shape[0], 1), jnp.inf, grid.dtype)
    left = jnp.concatenate([inf, grid[:, :-1]], axis=1)
    right = jnp.concatenate([grid[:, 1:], inf], axis=1)
    row_min = (grid <= left) & (grid <= right)
    is_min = jnp.concatenate([row_min.reshape(-1), jnp.ones((1,), bool)])
    # rank of each local minimum within its row: the best minimum of every row comes
    # first, then the second best of every row, ... (a wrong η₂ row cannot crowd out the
    # others); the initial guess ranks with the row bests
    masked = jnp.where(row_min, grid, jnp.inf)
    rank = jnp.argsort(jnp.argsort(masked, axis=1), axis=1).reshape(-1)
    rank = jnp.concatenate([rank, jnp.zeros((1,), rank.dtype)])
    order = jnp.lexsort((safe, rank, (~is_min).astype(jnp.int32)))
    return y_starts[order[:n_solves]], losses


def _strip(sol):
    # the solver state holds jaxprs (not returnable from jit) and is of no use afterwards
    return optx.Solution(value=sol.value, result=sol.result, aux=sol.aux, stats=sol.stats,
                         state=None)


def _pipeline(res_start, res_final, y_starts, args, cfg, orders=None, distinct=None):
    """Screen the starts, run short solves from the best few, resolve the fringe order,
    polish the best distinct minima with the final model and keep the best.

    Stages 1–2 use the cheap start model `res_start` and carry no gradient. Stage 2 runs
    in two rounds of the same batch of short solves (one compiled solver): round 1 from
    the screened candidates, round 2 from `orders(y)` of round 1's best y (thickness ± k
    fringe orders at the same other parameters; the batch is padded with copies of that
    best, which are converged already and cost a step). All results are ranked by the
    final model `res_final`; the `1 + cfg.n_alternatives` best *distinct* ones
    (`distinct(y1, y2)`: different minima) are solved to convergence with it (stage 3,
    under the implicit adjoint); the best is the answer, the others are returned as
    runner-ups (y (K, p), loss (K,), inf where there is none).
    """
    solver = _solver(cfg.solver, cfg.rtol, cfg.atol)
    a = jax.lax.stop_gradient(args)
    m = 1 + cfg.n_alternatives

    def final_loss(y):
        return _loss(res_final, y, a)

    if y_starts.shape[0] > 1:
        cand, start_loss = _screen(res_start, y_starts, cfg.n_cols, cfg.n_solves, a,
                                   cfg.batching)

        def short(y0):
            return optx.least_squares(res_start, solver, y0, a, throw=False,
                                      max_steps=cfg.start_steps).value

        def round_(seeds, _):
            ys = _batch(short, seeds, cfg.batching)
            # ranked by the final model: a cheap start model's bias cannot pick the order
            losses = _nan_inf(_batch(final_loss, ys, cfg.batching))
            best = ys[jnp.argmin(losses)]
            nxt = jnp.broadcast_to(best, seeds.shape)
            if orders is not None:
                yo = orders(best)
                nxt = nxt.at[:yo.shape[0]].set(yo[:seeds.shape[0]])
            return nxt, (ys, losses)

        rounds = 2 if orders is not None else 1
        _, (ys, losses) = jax.lax.scan(round_, cand, None, length=rounds)
        ys, losses = ys.reshape(-1, ys.shape[-1]), losses.reshape(-1)
        pick, valid = _best_distinct(ys, losses, m, distinct)
        y_pol = jax.lax.stop_gradient(ys[pick])
    else:
        start_loss = _loss(res_start, y_starts[0], a)[None]
        y_pol = jax.lax.stop_gradient(y_starts[:1])
        valid = jnp.ones((1,), bool)

    def solve(y0):
        return _strip(optx.least_squares(res_final, solver, y0, args, throw=False,
                                         max_steps=cfg.max_steps))

    sols = _batch(solve, y_pol, cfg.batching)
    lp = jnp.where(valid, _nan_inf(jax.vmap(final_loss)(jax.lax.stop_gradient(sols.value))),
                   jnp.inf)
    rank = jnp.argsort(lp)
    sol = jax.tree_util.tree_map(lambda v: v[rank[0]], sols)
    alt_y = jax.lax.stop_gradient(sols.value[rank[1:]])
    alt_loss = lp[rank[1:]]
    if distinct is not None and m > 1:
        # two starts that converged into the same minimum as the answer are no runner-up
        same = ~jax.vmap(distinct, (0, None))(alt_y, jax.lax.stop_gradient(sol.value))
        alt_loss = jnp.where(same, jnp.inf, alt_loss)
    k = cfg.n_alternatives  # fixed output size, whatever the path
    pad = k - alt_y.shape[0]
    if pad > 0:
        alt_y = jnp.concatenate([alt_y, jnp.broadcast_to(sol.value, (pad,) + sol.value.shape)])
        alt_loss = jnp.concatenate([alt_loss, jnp.full((pad,), jnp.inf, lp.dtype)])
    return sol, start_loss, alt_y, alt_loss


def _nan_inf(x):
    return jnp.where(jnp.isnan(x), jnp.inf, x)


def _best_distinct(ys, losses, m, distinct):
    """Indices (m,) of the m lowest-loss rows of `ys` that are pairwise `distinct`, greedily
    (lowest first), and whether each exists (fewer distinct minima than m: invalid)."""
    order = jnp.argsort(losses)
    ys, losses = ys[order], losses[order]
    taken = jnp.zeros(losses.shape, bool).at[0].set(True)
    pos, valid = [jnp.asarray(0)], [jnp.isfinite(losses[0])]
    for _ in range(1, m):
        ok = jnp.isfinite(losses) & ~taken
        if distinct is not None:
            for pj in pos:
                ok = ok & jax.vmap(distinct, (0, None))(ys, ys[pj])
        i = jnp.argmax(ok)  # the first (lowest-loss) admissible row
        pos.append(i)
        valid.append(ok[i])
        taken = taken.at[i].set(True)
    return order[jnp.stack(pos)], jnp.stack(valid)


def _orders_fn(spec, x0, cos_outer, lam, n_orders):
    """`orders(y)` for `_pipeline`: starting points ±1 … ±n_orders fringe orders from y,
    then, when η₂ is free, moves along the d–η₂ ridge.

    One order of the film's interference is a change of the optical path D = 2 η₂ d cos θ₂
    by one (mean) wavelength λ̄, i.e. Δd = λ̄ / (2 η₂ ⟨cos θ₂⟩) at the current η₂ (cos θ₂ by
    Snell from the views' cos θ₁, averaged over them). The order moves change only the
    thickness. The ridge moves (η₂ free) set η₂' = η₂ · (1 ± 0.08), (1 ± 0.16) and the
    thickness that keeps the optical thickness η₂ d, and that ± one order: the data fix η₂ d
    far better than η₂ (a wrong η₂ at the right η₂ d fits nearly as well: `studies.coverage`, film
    d = 1090 nm, η₂ = 1.31 fitted as 1163 nm, 1.23 from four views), and the short solves
    from one (d, η₂) pair do not cross the barriers between such minima. None when
    thickness is not free.
    """
    if "thickness" not in spec.free or n_orders < 1:
        return None, None
    k = spec.free.index("thickness")
    j = spec.free.index("eta_film") if "eta_film" in spec.free else None
    ks = np.concatenate([-np.arange(n_orders, 0, -1), np.arange(1, n_orders + 1)])
    ridge_eta = np.asarray([0.92, 1.08, 0.84, 1.16])
    ridge_k = np.asarray([0.0, -1.0, 1.0])  # fringe orders added at each ridge η₂'

    def cos2(eta1, eta2):  # ⟨cos θ₂⟩ over the views (Snell)
        s1 = 1.0 - cos_outer * cos_outer
        return jnp.mean(jnp.sqrt(jnp.clip(1.0 - (eta1 / eta2) ** 2 * s1, 1e-4, 1.0)))

    def step(y):
        x = spec.with_free(spec.x_free(y), x0)
        return lam / (2.0 * x[1] * cos2(x[4], x[1]))

    def orders(y):
        xf = spec.x_free(y)
        lo, hi = jnp.asarray(spec.lo[k], y.dtype), jnp.asarray(spec.hi[k], y.dtype)
        margin = _START_MARGIN * (hi - lo)
        d = xf[k] + jnp.asarray(ks, y.dtype) * step(y)
        xs = jnp.broadcast_to(xf, (ks.size, xf.shape[0])).at[:, k].set(d)
        if j is not None:
            x = spec.with_free(xf, x0)
            elo, ehi = jnp.asarray(spec.lo[j], y.dtype), jnp.asarray(spec.hi[j], y.dtype)
            e_m = _START_MARGIN * (ehi - elo)
            e2 = jnp.clip(xf[j] * jnp.asarray(ridge_eta, y.dtype), elo + e_m, ehi - e_m)
            c2 = jax.vmap(lambda e: cos2(x[4], e))(e2)
            # the same η₂ d (the path at normal incidence), then ± one order at η₂'
            d2 = (x[1] * x[0] / e2[None, :] + jnp.asarray(ridge_k, y.dtype)[:, None] * lam
                  / (2.0 * e2 * c2)[None, :]).reshape(-1)
            xr = jnp.broadcast_to(xf, (d2.size, xf.shape[0]))
            xr = xr.at[:, k].set(d2).at[:, j].set(jnp.tile(e2, ridge_k.size))
            xs = jnp.concatenate([xs, xr])
        xs = xs.at[:, k].set(jnp.clip(xs[:, k], lo + margin, hi - margin))
        return jax.vmap(spec.y_of)(xs)

    def distinct(y1, y2):
        """Different minima: thickness apart by more than a quarter order."""
        d1, d2 = spec.x_free(y1)[k], spec.x_free(y2)[k]
        return jnp.abs(d1 - d2) > 0.25 * jnp.minimum(step(y1), step(y2))

    return orders, distinct


def _covariance(res_x, x_free, args, n_obs, absolute_sigma):
    """(stderr (p,), correlation (p, p)) from the Jacobian in physical parameters."""
    r = res_x(x_free, args)
    jac = jax.jacfwd(res_x)(x_free, args)  # (n, p)
    p = x_free.shape[0]
    jtj = jnp.matmul(jac.T, jac, precision=jax.lax.Precision.HIGHEST)
    scale = jnp.sqrt(jnp.diag(jtj))
    ok = scale > 0
    scale = jnp.where(ok, scale, 1.0)
    a = jtj / (scale[:, None] * scale[None, :])  # unit diagonal: better conditioned
    ainv = jnp.linalg.inv(a)
    if absolute_sigma:
        s2 = jnp.asarray(1.0, r.dtype)
    else:
        s2 = jnp.sum(r * r) / (n_obs - p) if n_obs > p else jnp.asarray(jnp.nan, r.dtype)
    cov = s2 * ainv / (scale[:, None] * scale[None, :])
    var = jnp.diag(cov)
    stderr = jnp.where(ok & (var >= 0), jnp.sqrt(jnp.abs(var)), jnp.inf)
    d = jnp.sqrt(jnp.abs(jnp.diag(ainv)))
    corr = ainv / (d[:, None] * d[None, :])
    return stderr, corr, s2


def _cells(lo, hi, n):
    """Midpoints of n equal cells of [lo, hi]."""
    return lo + (hi - lo) * (np.arange(n) + 0.5) / n


def _grid_starts(spec, x0_host, n_starts, n_eta_starts, starts, dtype):
    """Screening grid: thickness (`n_starts` cell midpoints of its box, or `starts`) × film
    index (its initial value plus `n_eta_starts` cell midpoints of its box, if it is free),
    other free parameters at their initial values, and the initial guess itself last.

    Returns (y (N, p), x (N, p) physical, n_cols = thicknesses per row)."""
    x_free0 = np.asarray([float(np.asarray(x0_host[i])) for i in spec.index])
    if "thickness" not in spec.free or (n_starts <= 1 and starts is None):
        xs = x_free0[None, :]
        n_cols = 1
    else:
        k = spec.free.index("thickness")
        lo, hi = float(spec.lo[k]), float(spec.hi[k])
        if starts is None:
            d = _cells(lo, hi, n_starts)
        else:
            d = np.sort(np.asarray(starts, float).reshape(-1))
            if d.size == 0 or not (np.all(np.isfinite(d)) and np.all((d >= lo) & (d <= hi))):
                raise ValueError(f"starts must be finite thicknesses within [{lo}, {hi}] nm")
        rows = [x_free0]
        if "eta_film" in spec.free and n_eta_starts > 0:
            j = spec.free.index("eta_film")
            for e in _cells(float(spec.lo[j]), float(spec.hi[j]), n_eta_starts):
                rows.append(x_free0.copy())
                rows[-1][j] = e
        xs = np.concatenate([np.repeat(r[None, :], d.size, axis=0) for r in rows])
        xs[:, k] = np.tile(d, len(rows))
        xs = np.concatenate([xs, x_free0[None, :]])
        n_cols = d.size
    xs = jnp.asarray(xs, dtype)
    return jax.vmap(spec.y_of)(xs), xs, n_cols


# ----------------------------------------------------------------------------- validation
def _check_free(free, allowed):
    if isinstance(free, str):
        free = (free,)
    free = tuple(free)
    if not free:
        raise ValueError("free must name at least one parameter")
    for k in free:
        if k not in allowed:
            raise ValueError(f"unknown free parameter {k!r}; expected names from {list(allowed)}")
    if len(set(free)) != len(free):
        raise ValueError(f"free names a parameter twice: {free}")
    return free


def _make_spec(free, bounds, x0):
    """The free parameters' `_Spec`; `bounds` is the full {name: (lo, hi)} dict."""
    index = tuple(PARAMS.index(k) for k in free)
    for k, i in zip(free, index):
        lo, hi = bounds[k]
        if V.is_concrete(x0[i]):
            v = float(np.asarray(x0[i]))
            if not lo <= v <= hi:
                raise ValueError(f"initial {k} = {v!r} lies outside its bounds [{lo}, {hi}]")
    return _Spec(free, index, np.asarray([bounds[k][0] for k in free]),
                 np.asarray([bounds[k][1] for k in free]))


def _static(spec):
    """(static part for the jit cache key, dynamic boxes): bounds never trigger a recompile."""
    return spec._replace(lo=None, hi=None), (spec.lo, spec.hi)


def _check_batching(batching):
    V.check_choice("batching", batching, BATCHING)
    if batching == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batching


def _check_scalar_film(film):
    """The checked, normalised `initial` film (complex eta_base folded into kappa_base)."""
    film = V.check_film(film, "initial")
    for k, v in film._asdict().items():
        if np.shape(v) != ():
            raise ValueError(f"initial.{k} must be a scalar, got shape {np.shape(v)}")
    return film


def _check_options(options, kind):
    """The `FitOptions` of a fit (default if None); patch-only fields rejected for spectra."""
    if options is None:
        options = FitOptions()
    if not isinstance(options, FitOptions):
        raise TypeError(f"options must be a thinfilm_jax.FitOptions, got "
                        f"{type(options).__name__}")
    if kind == "spectrum":
        default = FitOptions()
        changed = [k for k in _PATCH_ONLY if getattr(options, k) != getattr(default, k)]
        if changed:
            raise ValueError(f"FitOptions field(s) {changed} apply to fit_film (patch models) "
                             f"only")
    return options


def _weights(sigma, shape, dtype):
    if sigma is None:
        return jnp.ones(shape, dtype)
    V.check_range("sigma", sigma, 0.0, lo_open=True)
    try:
        return 1.0 / jnp.broadcast_to(jnp.asarray(sigma, dtype), shape)
    except ValueError:
        raise ValueError(f"sigma of shape {np.shape(sigma)} does not broadcast to the "
                         f"observations {shape}") from None


def _mean_wavelength(observer):
    """λ̄ of an observer: the mean of its bands' centroids Σ_k λ_k W_kj (nm)."""
    obs = get_observer(observer)
    return float(np.mean(np.asarray(obs.wavelengths) @ np.asarray(obs.weights)))


def _n_candidates(y_starts, n_cols, n_solves):
    """n_solves, by default 2 per screened row (≥ 8), at most the number of starts."""
    if n_solves is None:
        rows = (y_starts.shape[0] - 1) // n_cols
        n_solves = max(8, 2 * rows + 2)
    return min(int(n_solves), y_starts.shape[0])


# ----------------------------------------------------------------------------- fit_film
class _FilmCfg(NamedTuple):
    spec: _Spec
    method: str
    refine_method: str | None
    observer: str
    terms: int
    shat: str
    quadrature: tuple
    start_quadrature: tuple
    ndf: str
    solver: str
    rtol: float
    atol: float
    n_cols: int
    n_solves: int
    start_steps: int
    max_steps: int
    absolute_sigma: bool
    batching: str
    n_orders: int
    n_alternatives: int
    wavelength: float


def fit_film(observed, theta_o, *, alpha, initial: Film, free: Sequence[str] = ("thickness",),
             method: str = "reference", sigma=None,
             options: FitOptions | None = None) -> FitResult:
    """Fit film parameters (and α) to patch radiances observed at view angles θ_o (SPEC §8).

    Residuals r = (model − observed)/σ over all angles and bands; the model is
    `patch_model` (`patch.patch_one` vmapped over θ_o) with `method`'s forward model.

    Args:
        observed: L_j, shape (n_angles, n_bands), as from
            ``patch_radiance(film, theta_o, alpha, method=...)``.
        theta_o: view angles (n_angles,), radians in [0, π/2].
        alpha: GGX roughness (the initial guess if "alpha" is free), scalar in (0, 1].
        initial: `Film` with scalar fields: fixed values and initial guesses (concrete:
            they seed the start grid on the host; `observed` may be traced, so the fit
            works under `jax.jit`, `jax.vmap` and `jax.grad` with respect to it).
        free: names of the fitted parameters: `Film` fields and/or "alpha".
        method: forward model, a `patch.METHODS` name (SPEC §7).
        sigma: standard deviations of the observations (broadcast to `observed`).
        options: `FitOptions` (search, solver, quadrature, observer, ...); None = defaults.

    Returns:
        `FitResult`.

    Example:
        >>> import numpy as np
        >>> from thinfilm_jax.shading.patch import patch_radiance
        >>> theta = np.linspace(0.0, 1.4, 9)
        >>> obs = patch_radiance(Film(600.0, 1.3, 2.0, 0.5), theta, 0.25)
        >>> res = fit_film(obs, theta, alpha=0.25, initial=Film(350.0, 1.3, 2.0, 0.5))
        >>> round(float(res.film.thickness), 2), bool(res.converged)
        (600.0, True)
    """
    if not isinstance(initial, Film):
        raise TypeError(f"initial must be a thinfilm_jax.Film, got {type(initial).__name__}")
    initial = _check_scalar_film(initial)
    free = _check_free(free, PARAMS)
    V.check_choice("method", method, METHODS)
    o = _check_options(options, "patch")
    refine_method = None if o.refine_method == method else o.refine_method
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
    dtype = jnp.result_type(observed, theta_o, alpha, *initial, float)
    x0 = jnp.stack([jnp.asarray(v, dtype) for v in (*initial, alpha)])
    spec = _make_spec(free, o.bounds_dict, [*initial, alpha])
    n_starts = DEFAULT_N_STARTS["patch"] if o.n_starts is None else o.n_starts
    y_starts, x_starts, n_cols = _grid_starts(spec, [*initial, alpha], n_starts,
                                              o.n_eta_starts, o.starts, dtype)
    w = _weights(sigma, observed.shape, dtype)
    lut = build_shat_lut(observer, dtype=dtype) if o.shat == "lut" else None
    static, box = _static(spec)
    cfg = _FilmCfg(static, method, refine_method, observer, o.terms, o.shat, quadrature,
                   start_quadrature, o.ndf, o.solver, o.rtol, o.atol, n_cols,
                   _n_candidates(y_starts, n_cols, o.n_solves), o.start_steps, o.max_steps,
                   o.absolute_sigma, batching, o.n_orders, o.n_alternatives,
                   _mean_wavelength(observer))
    box = tuple(jnp.asarray(b, dtype) for b in box)
    with jax.default_matmul_precision("highest"):  # optimistix/lineax contractions too
        out = _fit_film_jit(observed.astype(dtype), w, theta_o.astype(dtype), x0, y_starts,
                            box, lut, cfg)
    return _result(out, free, x_starts, True)


@functools.partial(jax.jit, static_argnames="cfg")
def _fit_film_jit(observed, w, theta_o, x0, y_starts, box, lut, cfg: _FilmCfg):
    spec = cfg.spec._replace(lo=box[0], hi=box[1])
    final_method = cfg.refine_method or cfg.method

    def model_x(x, method, quad):
        film, alpha = _split(x)
        return patch_model(film, theta_o, alpha, method=method, observer=cfg.observer,
                           terms=cfg.terms, shat=cfg.shat, lut=lut, quadrature=quad,
                           ndf=cfg.ndf, arithmetic="complex")

    def residuals(method, quad):
        def fn(y, args):
            obs, ww = args
            return ((model_x(spec.x_full(y, x0), method, quad) - obs) * ww).reshape(-1)
        return fn

    def res_x(x_free, args):
        obs, ww = args
        return ((model_x(spec.with_free(x_free, x0), final_method, cfg.quadrature) - obs)
                * ww).reshape(-1)

    args = (observed, w)
    orders, distinct = _orders_fn(spec, x0, jnp.cos(theta_o), cfg.wavelength, cfg.n_orders)
    out = _pipeline(residuals(cfg.method, cfg.start_quadrature),
                    residuals(final_method, cfg.quadrature), y_starts, args, cfg, orders,
                    distinct)
    return _finish(out, res_x, spec, x0, args, w, cfg)


# ----------------------------------------------------------------------------- fit_spectrum
class _SpecCfg(NamedTuple):
    spec: _Spec
    solver: str
    rtol: float
    atol: float
    n_cols: int
    n_solves: int
    start_steps: int
    max_steps: int
    absolute_sigma: bool
    batching: str
    n_orders: int
    n_alternatives: int
    wavelength: float


def fit_spectrum(observed, wavelength, cos_theta, *, initial: Film,
                 free: Sequence[str] = ("thickness",), sigma=None,
                 options: FitOptions | None = None) -> FitResult:
    """Fit film parameters to reflectance spectra R(θ₁, λ) (SPEC §2; film metrology).

    The model is `spectrum_model` (the exact Airy reflectance, general Fresnel path).

    Args:
        observed: unpolarised reflectance, shape (n_angles, n_wl) (or (n_wl,) for one angle).
        wavelength: λ in nm, shape (n_wl,).
        cos_theta: cos θ₁ of each spectrum, shape (n_angles,) (or scalar), in [0, 1].
        initial: `Film` with scalar fields (fixed values and initial guesses).
        free: `Film` field names to fit.
        sigma: standard deviations of the observations (broadcast to `observed`).
        options: `FitOptions` (search and solver fields; the patch-model fields must keep
            their defaults). ``n_starts=None`` screens 256 thicknesses: spectral minima are
            closer together than patch-colour minima, and the model is cheap.

    Returns:
        `FitResult` with ``alpha=None``; residuals of shape (n_angles, n_wl).

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
    if not isinstance(initial, Film):
        raise TypeError(f"initial must be a thinfilm_jax.Film, got {type(initial).__name__}")
    initial = _check_scalar_film(initial)
    free = _check_free(free, FILM_PARAMS)
    o = _check_options(options, "spectrum")
    batching = _check_batching(o.batching)
    wavelength = jnp.asarray(V.as_array("wavelength", wavelength))
    cos_theta = jnp.atleast_1d(jnp.asarray(V.as_array("cos_theta", cos_theta)))
    if wavelength.ndim != 1 or cos_theta.ndim != 1:
        raise ValueError(f"wavelength and cos_theta must be 1-D; got shapes {wavelength.shape}, "
                         f"{cos_theta.shape}")
    wavelength = V.check_range("wavelength", wavelength, 0.0, lo_open=True, why=" (nm)")
    cos_theta = V.check_cos_theta(cos_theta)
    observed = jnp.asarray(V.as_array("observed", observed))
    if observed.ndim == 1:
        observed = observed[None, :]
    shape = (cos_theta.shape[0], wavelength.shape[0])
    if observed.shape != shape:
        raise ValueError(f"observed must have shape (n_angles, n_wl) = {shape} to match "
                         f"cos_theta and wavelength; got {observed.shape}")
    V.check_finite("observed", observed)
    if observed.size <= len(free):
        raise ValueError(f"{observed.size} observations cannot determine {len(free)} free "
                         f"parameters {free}")
    dtype = jnp.result_type(observed, wavelength, cos_theta, *initial, float)
    x0 = jnp.stack([jnp.asarray(v, dtype) for v in (*initial, 1.0)])
    spec = _make_spec(free, o.bounds_dict, [*initial, 1.0])
    n_starts = DEFAULT_N_STARTS["spectrum"] if o.n_starts is None else o.n_starts
    y_starts, x_starts, n_cols = _grid_starts(spec, [*initial, 1.0], n_starts,
                                              o.n_eta_starts, o.starts, dtype)
    w = _weights(sigma, shape, dtype)
    static, box = _static(spec)
    cfg = _SpecCfg(static, o.solver, o.rtol, o.atol, n_cols,
                   _n_candidates(y_starts, n_cols, o.n_solves), o.start_steps, o.max_steps,
                   o.absolute_sigma, batching, o.n_orders, o.n_alternatives,
                   float(np.mean(wavelength)) if V.is_concrete(wavelength) else 550.0)
    box = tuple(jnp.asarray(b, dtype) for b in box)
    with jax.default_matmul_precision("highest"):  # optimistix/lineax contractions too
        out = _fit_spectrum_jit(observed.astype(dtype), w, wavelength.astype(dtype),
                                cos_theta.astype(dtype), x0, y_starts, box, cfg)
    return _result(out, free, x_starts, False)


@functools.partial(jax.jit, static_argnames="cfg")
def _fit_spectrum_jit(observed, w, wavelength, cos_theta, x0, y_starts, box, cfg: _SpecCfg):
    spec = cfg.spec._replace(lo=box[0], hi=box[1])

    def res(y, args):
        obs, ww = args
        return ((spectrum_model(_split(spec.x_full(y, x0))[0], cos_theta, wavelength) - obs)
                * ww).reshape(-1)

    def res_x(x_free, args):
        obs, ww = args
        film = _split(spec.with_free(x_free, x0))[0]
        return ((spectrum_model(film, cos_theta, wavelength) - obs) * ww).reshape(-1)

    args = (observed, w)
    orders, distinct = _orders_fn(spec, x0, cos_theta, cfg.wavelength, cfg.n_orders)
    out = _pipeline(res, res, y_starts, args, cfg, orders, distinct)
    return _finish(out, res_x, spec, x0, args, w, cfg)


def _finish(out, res_x, spec, x0, args, w, cfg):
    """Fitted parameters, loss, residuals, standard errors and runner-ups (inside jit)."""
    sol, start_loss, alt_y, alt_loss = out
    observed = args[0]
    x_free = spec.x_free(sol.value)
    x = jnp.stack(spec.with_free(x_free, x0))
    r = res_x(x_free, args)
    loss = 0.5 * jnp.sum(r * r)
    stderr, corr, s2 = _covariance(res_x, jax.lax.stop_gradient(x_free),
                                   jax.lax.stop_gradient(args), observed.size,
                                   cfg.absolute_sigma)
    alt_x = jax.vmap(spec.x_free)(alt_y)
    # Δχ² = Σr²/s² of the runner-up minus that of the answer (s² as for the errors)
    gap = jax.lax.stop_gradient(alt_loss - loss)
    dchi2 = jnp.where(jnp.isfinite(alt_loss), 2.0 * gap / jnp.where(s2 > 0, s2, 1.0), jnp.inf)
    dchi2 = jnp.where((s2 > 0) | ~jnp.isfinite(alt_loss), dchi2,
                      jnp.where(gap > 0, jnp.inf, 0.0))
    return (sol, x, loss, r.reshape(observed.shape) / w, stderr, corr, start_loss, alt_x,
            alt_loss, dchi2)


def _result(out, free, x_starts, has_alpha):
    sol, x, loss, resid, stderr, corr, start_loss, alt_x, alt_loss, dchi2 = out
    film, alpha = _split(x)
    return FitResult(film, alpha if has_alpha else None, loss,
                     sol.result == optx.RESULTS.successful, sol.stats["num_steps"],
                     dict(zip(free, stderr)), corr, free, resid, x_starts, start_loss, sol,
                     alt_x, alt_loss, dchi2)
