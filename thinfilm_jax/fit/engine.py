r"""The fitting engine: box transform, batched Levenberg–Marquardt, linearised covariance.

Every fit of the library is a weighted least-squares problem
$\min_x \tfrac12 \lVert r(x) \rVert^2$ over a box $lo \le x \le hi$, with
$r = (\text{model}(x) - \text{observed}) / \sigma$ (Nocedal & Wright 2006, ch. 10). The pieces
are written once here, and every fit uses them (`film_fit`, `thickness_map`, the photo fit):

* **box transform**: $x = lo + (hi - lo)\,\mathrm{sigmoid}(y)$ maps an unconstrained $y$ into
  the box (`to_box`, inverse `from_box`), so an unconstrained solver never leaves it;
* **Levenberg–Marquardt** (`lm_solve`, `levenberg_marquardt`): damped Gauss–Newton steps
  $(J^TJ + \lambda\,\mathrm{diag}(J^TJ))\,\delta = -J^T r$, a step kept only where it lowers
  the loss (λ × 0.3), else λ × 10 (Marquardt 1963); the iterate is clipped to the box, and
  a coordinate on a bound that the gradient pushes outward is held there while the others
  take their reduced step (an active set, Nocedal & Wright 2006 §16.7: clipping the full
  step alone converges slowly once a bound binds). With a fixed step count
  (`levenberg_marquardt`) there is no data-dependent control flow, so thousands of
  independent problems (one per pixel) run as one `jax.vmap`; with tolerances (`lm_solve`)
  it stops at the Cauchy test optimistix uses, for the few, larger problems of `fit_film`.
  It is the library's only Levenberg–Marquardt: against optimistix's `LevenbergMarquardt`
  it measured 1.7–2.8× cheaper per step on the per-pixel batches (no lineax operator; the
  Jacobian recomputed only after an accepted step) and 1.3–8× faster on `fit_film`'s and
  `fit_spectrum`'s solves at equal accuracy (docs/how-to/fit-film.md);
* **implicit derivatives** (`implicit_solution`): the solve runs without gradients and its
  solution carries $dx^*/d\theta = -H^{-1} \partial_\theta \nabla_x L$ (the implicit function
  theorem on $\nabla_x L = 0$), as optimistix's implicit adjoint;
* **covariance** (`covariance`): $C = s^2 (J^TJ)^{-1}$ at the solution, with
  $s^2 = \lVert r\rVert^2 / (n - p)$ (the reduced χ²) or 1 when σ is absolute; standard
  errors $\sqrt{C_{ii}}$, and the correlation matrix. $J^TJ$ is equilibrated to a unit
  diagonal before the inverse.

All contractions state `Precision.HIGHEST` (GPUs would otherwise use TF32).

Example (a line through three points; a box that does not bind):
    >>> import jax.numpy as jnp
    >>> from thinfilm_jax.fit.engine import levenberg_marquardt, covariance
    >>> t = jnp.array([0.0, 1.0, 2.0]); obs = jnp.array([1.0, 3.0, 5.0])
    >>> res = lambda x: x[0] + x[1] * t - obs
    >>> x = levenberg_marquardt(res, jnp.zeros(2), jnp.full(2, -10.0), jnp.full(2, 10.0), 20)
    >>> [round(float(v), 6) for v in x]
    [1.0, 2.0]
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

__all__ = ["Covariance", "Solve", "covariance", "from_box", "implicit_solution",
           "levenberg_marquardt", "lm_solve", "to_box"]

_HI = jax.lax.Precision.HIGHEST
#: starting points are moved at least this fraction of the box inside it (`from_box`)
START_MARGIN = 5e-3


def to_box(y, lo, hi):
    """x = lo + (hi − lo) sigmoid(y): any real y inside the box (lo, hi)."""
    return lo + (hi - lo) * jax.nn.sigmoid(y)


def from_box(x, lo, hi, margin: float = START_MARGIN):
    """The y with ``to_box(y) = x``, x first moved `margin` of the box inside it."""
    u = jnp.clip((x - lo) / (hi - lo), margin, 1.0 - margin)
    return jnp.log(u) - jnp.log1p(-u)


class Solve(NamedTuple):
    """Outcome of `lm_solve`: the solution `x` (p,), its loss ½‖r‖², the number of `steps`
    taken and whether the stopping test held (`converged`; always False with zero
    tolerances, which run exactly the given number of steps)."""

    x: Array
    loss: Array
    steps: Array
    converged: Array


def lm_solve(residual, x0, lo, hi, max_steps: int, *, damping: float = 1e-3,
             rtol: float = 0.0, atol: float = 0.0) -> Solve:
    """Levenberg–Marquardt on ``residual(x) → (n,)`` from x0 (p,), clipped to [lo, hi] (p,)
    (module docstring). One problem; `jax.vmap` or `jax.lax.map` it over a batch.

    At most `max_steps` steps; with `rtol` or `atol` > 0 it stops once a proposed step
    changes x by less than ``atol + rtol‖x‖∞`` (max norm) and the loss by less than
    ``atol + rtol·loss`` (the Cauchy test of optimistix's least-squares solvers). Under
    `jax.vmap` a stopped problem waits for the slowest of its batch (a batched
    `while_loop`); zero tolerances run a fixed number of steps as a `fori_loop`, which
    reverse-mode AD can differentiate through (use `implicit_solution` instead). The
    Jacobian (forward mode, `jax.jacfwd`: p ≪ n) is recomputed only after an accepted step.
    """
    dtype = jnp.result_type(x0)
    x0 = jnp.asarray(x0, dtype)
    lo = jnp.asarray(lo, dtype)
    hi = jnp.asarray(hi, dtype)
    fi = jnp.finfo(dtype)
    lam_lo, lam_hi = fi.eps ** 2, 1.0 / fi.eps ** 2  # no under/overflow of λ
    jac_fn = jax.jacfwd(residual)
    r0 = residual(x0)
    n, p = r0.shape[0], x0.shape[0]

    def body(_, carry):
        i, x, r, loss, jac, stale, lam, _ = carry
        jac = jax.lax.cond(stale, jac_fn, lambda _x: jac, x)
        jtj = jnp.matmul(jac.T, jac, precision=_HI)
        g = jnp.matmul(jac.T, r, precision=_HI)
        a = jtj + lam * jnp.diag(jnp.diag(jtj) + fi.tiny ** 0.5)
        # active set: a coordinate on its bound that the gradient pushes out stays there,
        # and the step of the others is their own (reduced) damped Gauss–Newton step
        free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        a = jnp.where(free[:, None] & free[None, :], a, jnp.eye(p, dtype=a.dtype))
        xn = jnp.clip(x - jnp.linalg.solve(a, jnp.where(free, g, 0.0)), lo, hi)
        rn = residual(xn)
        ln = 0.5 * jnp.sum(rn * rn)
        better = ln < loss  # NaN: rejected
        small = ((jnp.max(jnp.abs(xn - x)) < atol + rtol * jnp.max(jnp.abs(x)))
                 & (jnp.abs(ln - loss) < atol + rtol * loss))
        lam = jnp.clip(jnp.where(better, lam * 0.3, lam * 10.0), lam_lo, lam_hi)
        # (a stopped problem of a vmapped while_loop is held by the loop's batching rule)
        return (i + 1, jnp.where(better, xn, x), jnp.where(better, rn, r),
                jnp.where(better, ln, loss), jac, better, lam, small)

    init = (jnp.asarray(0, jnp.int32), x0, r0, 0.5 * jnp.sum(r0 * r0),
            jnp.zeros((n, p), r0.dtype), jnp.asarray(True), jnp.asarray(damping, dtype),
            jnp.asarray(False))
    if rtol == 0 and atol == 0:
        out = jax.lax.fori_loop(0, max_steps, body, init)
    else:
        out = jax.lax.while_loop(lambda c: (c[0] < max_steps) & ~c[7],
                                 lambda c: body(None, c), init)
    i, x, _, loss, _, _, _, done = out
    return Solve(x, loss, i, done)


def levenberg_marquardt(residual, x0, lo, hi, steps: int, *, damping: float = 1e-3) -> Array:
    """`steps` Levenberg–Marquardt steps on ``residual(x) → (n,)`` from x0 (p,), clipped to
    [lo, hi] (p,) (module docstring; `lm_solve` with zero tolerances). One problem;
    `jax.vmap` it over a batch. Returns x (p,).

    A step is accepted only where it lowers ½‖r‖², so the loss never rises; λ starts at
    `damping`. The Jacobian is forward-mode (`jax.jacfwd`: p ≪ n here).
    """
    return lm_solve(residual, x0, lo, hi, steps, damping=damping).x


def implicit_solution(residual, x):
    r"""x (a solution of min ½‖r‖², found without gradients) with the derivatives of the
    implicit function theorem attached: the value is x, and its derivative with respect to
    whatever `residual` closes over is $-H^{-1}\,\partial_\theta \nabla_x L$, $H$ the Hessian
    of $L = \tfrac12\lVert r\rVert^2$ at x (the stationarity condition $\nabla_x L = 0$
    differentiated; what optimistix's `ImplicitAdjoint` computes). A `jax.custom_jvp` (the
    closed-over values hoisted by `jax.closure_convert`): nothing is computed unless it is
    differentiated; forward and reverse mode, under `jax.jit` and `jax.vmap`.
    """
    x = jax.lax.stop_gradient(x)
    fn, consts = jax.closure_convert(residual, x)
    return _implicit(fn, x, *consts)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _implicit(fn, x, *consts):
    return x


@_implicit.defjvp
def _implicit_jvp(fn, primals, tangents):
    x, *consts = primals
    dconsts = tangents[1:]

    def loss(v, *c):
        r = fn(v, *c)
        return 0.5 * jnp.sum(r * r)

    _, dg = jax.jvp(lambda *c: jax.grad(loss)(x, *c), tuple(consts), tuple(dconsts))
    h = jax.hessian(loss)(x, *consts)
    # H⁻¹ equilibrated to a unit diagonal, as a pseudo-inverse: a direction the loss does
    # not determine (H singular, e.g. a box transform saturated at a bound) gets no
    # derivative instead of NaN
    d = jnp.sqrt(jnp.abs(jnp.diag(h)))
    d = jnp.where(d > 0, d, 1.0)
    hinv = jnp.linalg.pinv(h / (d[:, None] * d[None, :])) / (d[:, None] * d[None, :])
    return x, -jnp.matmul(hinv, dg, precision=_HI)


class Covariance(NamedTuple):
    """Linearised uncertainty at a solution: `stderr` (p,) (inf where a parameter is not
    determined), `correlation` (p, p) and the scale `s2` used (reduced χ² or 1)."""

    stderr: Array
    correlation: Array
    s2: Array


def covariance(residual, x, *, absolute_sigma: bool = True) -> Covariance:
    """Covariance of the least-squares solution x (p,) of ``residual(x) → (n,)`` (module
    docstring): s² = 1 when the residuals are already divided by a known σ
    (`absolute_sigma`), else the reduced χ² ‖r‖²/(n − p) (NaN when n ≤ p)."""
    r = residual(x)
    jac = jax.jacfwd(residual)(x)
    n, p = jac.shape
    jtj = jnp.matmul(jac.T, jac, precision=_HI)
    scale = jnp.sqrt(jnp.diag(jtj))
    ok = scale > 0
    scale = jnp.where(ok, scale, 1.0)
    a = jtj / (scale[:, None] * scale[None, :])
    ainv = jnp.linalg.inv(a)
    if absolute_sigma:
        s2 = jnp.asarray(1.0, r.dtype)
    else:
        s2 = jnp.sum(r * r) / (n - p) if n > p else jnp.asarray(jnp.nan, r.dtype)
    var = s2 * jnp.diag(ainv) / (scale * scale)
    stderr = jnp.where(ok & (var >= 0) & jnp.isfinite(var), jnp.sqrt(jnp.abs(var)), jnp.inf)
    d = jnp.sqrt(jnp.abs(jnp.diag(ainv)))
    return Covariance(stderr, ainv / (d[:, None] * d[None, :]), s2)
