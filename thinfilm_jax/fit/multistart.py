"""The multi-start solve that `fit_film` and `fit_spectrum` share (docs/how-to/fit-film.md):
a screening grid of starts in the free parameters, the best few local minima of a cheap
start model, short Levenberg–Marquardt solves from them, the fringe-order and d–η₂ ridge
moves that resolve which interference order fits, and the final polish of the best distinct
minima with the full model (`engine.lm_solve`, or an optimistix solver by name).

Example (the cell midpoints the screening grid places in a box):
    >>> from thinfilm_jax.fit.multistart import _cells
    >>> _cells(0.0, 100.0, 4).tolist()
    [12.5, 37.5, 62.5, 87.5]
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..core.stack import Stack
from ..optics.fresnel import safe_div
from ..optics.index import index_at
from .engine import START_MARGIN, implicit_solution, lm_solve
from .options import SOLVERS

__all__ = ["solve_multistart", "order_moves", "grid_starts"]


def _least_squares(fn, y0, args, max_steps, cfg, implicit):
    """`max_steps` steps of the solver `cfg.solver` on ``fn(y, args) → (n,)`` from y0 →
    `optx.Solution` (its `state` dropped: it holds jaxprs, not returnable from jit).

    Levenberg–Marquardt is the engine's (`engine.lm_solve`: one implementation for every fit
    of the library; measured against optimistix's in docs/how-to/fit-film.md), run without
    gradients and, if `implicit`, given the implicit-function-theorem derivatives at the
    solution (`engine.implicit_solution`, as optimistix's implicit adjoint). The other
    `SOLVERS` are optimistix's (implicit adjoint)."""
    if cfg.solver == "levenberg_marquardt":
        a = jax.lax.stop_gradient(args)
        big = jnp.full(y0.shape, jnp.inf, y0.dtype)  # y is unconstrained: the box is in it
        out = lm_solve(lambda y: fn(y, a), jax.lax.stop_gradient(y0), -big, big, max_steps,
                       rtol=cfg.rtol, atol=cfg.atol)
        y = implicit_solution(lambda v: fn(v, args), out.x) if implicit else out.x
        result = optx.RESULTS.where(out.converged, optx.RESULTS.successful,
                                    optx.RESULTS.nonlinear_max_steps_reached)
        return optx.Solution(value=y, result=result, aux=None, state=None,
                             stats={"num_steps": out.steps, "max_steps": max_steps})
    sol = optx.least_squares(fn, SOLVERS[cfg.solver](cfg.rtol, cfg.atol), y0, args,
                             throw=False, max_steps=max_steps)
    return optx.Solution(value=sol.value, result=sol.result, aux=sol.aux, stats=sol.stats,
                         state=None)


def _loss(fn, y, args):
    r = fn(y, args)
    return 0.5 * jnp.sum(r * r)


def _batch(fn, xs, batching):
    """fn over the leading axis of xs: `jax.vmap`, or sequential `jax.lax.map`."""
    return jax.vmap(fn)(xs) if batching == "vmap" else jax.lax.map(fn, xs)


def _local_min(g):
    """True where g (rows, *grid) is ≤ its neighbours along every grid axis (not axis 0)."""
    ok = jnp.ones(g.shape, bool)
    for ax in range(1, g.ndim):
        n = g.shape[ax]
        inf = jnp.full(g.shape[:ax] + (1,) + g.shape[ax + 1:], jnp.inf, g.dtype)
        left = jnp.concatenate([inf, jax.lax.slice_in_dim(g, 0, n - 1, axis=ax)], axis=ax)
        right = jnp.concatenate([jax.lax.slice_in_dim(g, 1, n, axis=ax), inf], axis=ax)
        ok = ok & (g <= left) & (g <= right)
    return ok


def _screen(res_screen, y_starts, grid, n_solves, args, batching):
    """Loss at every start (one model evaluation each, no gradient) and the `n_solves` most
    promising starts: local minima of each row of the thickness grid (a row: the `grid`
    thicknesses, a product grid when several layers are free, at one screened η₂; a
    minimum: no higher than its neighbours along every thickness axis), lowest first (the
    initial guess, last in `y_starts`, always counts as a candidate).

    Candidates are ranked by the loss *profiled over a brightness gain*,
    min_g ½|g m − o|² with g ∈ [0.5, 2] (closed form): the starts' α and η₂ are guesses that
    scale the patch's brightness more than they move its fringes, and the plain loss ranks
    the right fringe order below brighter wrong ones (`benchmarks.coverage`: two of 200 noisy fits,
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
    n_cols = int(np.prod(grid))
    row_min = _local_min(safe[:-1].reshape(-1, *grid)).reshape(-1, n_cols)
    grid = safe[:-1].reshape(-1, n_cols)
    is_min = jnp.concatenate([row_min.reshape(-1), jnp.ones((1,), bool)])
    # rank of each local minimum within its row: the best minimum of every row comes
    # first, then the second best of every row, ... (a wrong η₂ row cannot crowd out the
    # others); the initial guess ranks with the row bests
    masked = jnp.where(row_min, grid, jnp.inf)
    rank = jnp.argsort(jnp.argsort(masked, axis=1), axis=1).reshape(-1)
    rank = jnp.concatenate([rank, jnp.zeros((1,), rank.dtype)])
    order = jnp.lexsort((safe, rank, (~is_min).astype(jnp.int32)))
    return y_starts[order[:n_solves]], losses


def solve_multistart(res_start, res_final, y_starts, args, cfg, orders=None, distinct=None):
    """Screen the starts, run short solves from the best few, resolve the fringe order,
    polish the best distinct minima with the final model and keep the best.

    Stages 1–2 use the cheap start model `res_start` and carry no gradient. Stage 2 runs
    in two rounds of the same batch of short solves (one compiled solver): round 1 from
    the screened candidates, round 2 from `orders(y)` of round 1's best y (thickness ± k
    fringe orders at the same other parameters; the batch is padded with copies of that
    best, which are converged already and cost a step). All results are ranked by the
    final model `res_final`; the `1 + cfg.n_alternatives` best *distinct* ones
    (`distinct(y1, y2)`: different minima) are solved to convergence with it (stage 3,
    with implicit derivatives); the best is the answer, the others are returned as
    runner-ups (y (K, p), loss (K,), inf where there is none).
    """
    a = jax.lax.stop_gradient(args)
    m = 1 + cfg.n_alternatives

    def final_loss(y):
        return _loss(res_final, y, a)

    if y_starts.shape[0] > 1:
        cand, start_loss = _screen(res_start, y_starts, cfg.grid, cfg.n_solves, a,
                                   cfg.batching)

        def short(y0):
            return _least_squares(res_start, y0, a, cfg.start_steps, cfg, False).value

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
        return _least_squares(res_final, y0, args, cfg.max_steps, cfg, True)

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


def _real_index(eta, lam, dtype):
    """Re n of index `eta` (a number or a model) at the wavelength `lam` (nm), in `dtype`."""
    return jnp.real(index_at(eta, lam)).astype(dtype)


def order_moves(spec, base, cos_outer, lam, n_orders):
    """`orders(y)` for `solve_multistart`: starting points ±1 … ±n_orders fringe orders from y in
    each free layer thickness (one layer at a time), then, when η₂ of a `Film` is free,
    moves along the d–η₂ ridge.

    One order of layer i's interference is a change of its optical path D = 2 n_i d_i cos θ_i
    by one (mean) wavelength λ̄, i.e. Δd_i = λ̄ / (2 n_i ⟨cos θ_i⟩) at the current n_i (Re of
    the layer's index at λ̄; cos θ_i by Snell from the views' cos θ₁, averaged over them).
    The order moves change only that thickness. The ridge moves (η₂ free) set η₂' = η₂ ·
    (1 ± 0.08), (1 ± 0.16) and the thickness that keeps the optical thickness η₂ d, and that
    ± one order: the data fix η₂ d far better than η₂ (a wrong η₂ at the right η₂ d fits
    nearly as well: `benchmarks.coverage`, film d = 1090 nm, η₂ = 1.31 fitted as 1163 nm, 1.23
    from four views), and the short solves from one (d, η₂) pair do not cross the barriers
    between such minima. None when no thickness is free.
    """
    if not spec.thick or n_orders < 1:
        return None, None
    j = spec.eta_k
    ks = np.concatenate([-np.arange(n_orders, 0, -1), np.arange(1, n_orders + 1)])
    ridge_eta = np.asarray([0.92, 1.08, 0.84, 1.16])
    ridge_k = np.asarray([0.0, -1.0, 1.0])  # fringe orders added at each ridge η₂'

    def cos2(eta1, eta2):  # ⟨cos θ₂⟩ over the views (Snell)
        s1 = 1.0 - cos_outer * cos_outer
        return jnp.mean(jnp.sqrt(jnp.clip(1.0 - (eta1 / eta2) ** 2 * s1, 1e-4, 1.0)))

    def indices(mat, dtype):  # (Re η_outer, (Re η of each layer)) at λ̄
        layers = mat.eta if isinstance(mat, Stack) else (mat.eta_film,)
        return (_real_index(mat.eta_outer, lam, dtype),
                [_real_index(e, lam, dtype) for e in layers])

    def steps(y):
        """Δd of one order of each free layer, (len(thick),)."""
        mat, _ = spec.x_full(y, base)
        n0, ns = indices(mat, y.dtype)
        return jnp.stack([lam / (2.0 * ns[i] * cos2(n0, ns[i])) for _, i in spec.thick])

    def orders(y):
        xf = spec.x_free(y)
        st = steps(y)
        blocks = []
        for a, (k, _) in enumerate(spec.thick):
            d = xf[k] + jnp.asarray(ks, y.dtype) * st[a]
            blocks.append(jnp.broadcast_to(xf, (ks.size, xf.shape[0])).at[:, k].set(d))
        xs = jnp.concatenate(blocks)
        if j is not None:
            k = spec.thick[0][0]
            mat, _ = spec.with_free(xf, base)
            n0 = _real_index(mat.eta_outer, lam, y.dtype)
            elo, ehi = jnp.asarray(spec.lo[j], y.dtype), jnp.asarray(spec.hi[j], y.dtype)
            e_m = START_MARGIN * (ehi - elo)
            e2 = jnp.clip(xf[j] * jnp.asarray(ridge_eta, y.dtype), elo + e_m, ehi - e_m)
            c2 = jax.vmap(lambda e: cos2(n0, e))(e2)
            # the same η₂ d (the path at normal incidence), then ± one order at η₂'
            d2 = (xf[j] * xf[k] / e2[None, :] + jnp.asarray(ridge_k, y.dtype)[:, None] * lam
                  / (2.0 * e2 * c2)[None, :]).reshape(-1)
            xr = jnp.broadcast_to(xf, (d2.size, xf.shape[0]))
            xr = xr.at[:, k].set(d2).at[:, j].set(jnp.tile(e2, ridge_k.size))
            xs = jnp.concatenate([xs, xr])
        for k, _ in spec.thick:
            lo, hi = jnp.asarray(spec.lo[k], y.dtype), jnp.asarray(spec.hi[k], y.dtype)
            margin = START_MARGIN * (hi - lo)
            xs = xs.at[:, k].set(jnp.clip(xs[:, k], lo + margin, hi - margin))
        return jax.vmap(spec.y_of)(xs)

    def distinct(y1, y2):
        """Different minima: some free thickness apart by more than a quarter order."""
        x1, x2 = spec.x_free(y1), spec.x_free(y2)
        s1, s2 = steps(y1), steps(y2)
        apart = [jnp.abs(x1[k] - x2[k]) > 0.25 * jnp.minimum(s1[a], s2[a])
                 for a, (k, _) in enumerate(spec.thick)]
        return functools.reduce(jnp.logical_or, apart)

    return orders, distinct


def _cells(lo, hi, n):
    """Midpoints of n equal cells of [lo, hi]."""
    return lo + (hi - lo) * (np.arange(n) + 0.5) / n


def grid_starts(spec, x_free0, n_starts, n_eta_starts, starts, dtype):
    """Screening grid: thickness (`n_starts` cell midpoints of its box, or `starts`; with
    several free layers the product grid of one such axis per layer) × film index (its
    initial value plus `n_eta_starts` cell midpoints of its box, if "eta_film" of a `Film` is
    free), other free parameters at their initial values, and the initial guess itself last.

    Returns (y (N, p), x (N, p) physical, grid = the thickness grid's shape per row)."""
    x_free0 = np.asarray(x_free0, float)
    if not spec.thick or (n_starts <= 1 and starts is None):
        xs = x_free0[None, :]
        grid = (1,)
    else:
        axes = []
        for k, _ in spec.thick:
            lo, hi = float(spec.lo[k]), float(spec.hi[k])
            if starts is None:
                d = _cells(lo, hi, n_starts)
            else:
                d = np.sort(np.asarray(starts, float).reshape(-1))
                if d.size == 0 or not (np.all(np.isfinite(d))
                                       and np.all((d >= lo) & (d <= hi))):
                    raise ValueError(f"starts must be finite thicknesses within [{lo}, {hi}] "
                                     f"nm")
            axes.append(d)
        mesh = [m.reshape(-1) for m in np.meshgrid(*axes, indexing="ij")]
        rows = [x_free0]
        if spec.eta_k is not None and n_eta_starts > 0:
            j = spec.eta_k
            for e in _cells(float(spec.lo[j]), float(spec.hi[j]), n_eta_starts):
                rows.append(x_free0.copy())
                rows[-1][j] = e
        n_cols = mesh[0].size
        xs = np.concatenate([np.repeat(r[None, :], n_cols, axis=0) for r in rows])
        for (k, _), d in zip(spec.thick, mesh):
            xs[:, k] = np.tile(d, len(rows))
        xs = np.concatenate([xs, x_free0[None, :]])
        grid = tuple(d.size for d in axes)
    xs = jnp.asarray(xs, dtype)
    return jax.vmap(spec.y_of)(xs), xs, grid
