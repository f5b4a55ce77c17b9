r"""The fitting engine: box transform, batched Levenberg–Marquardt, linearised covariance.

Every fit of the library is a weighted least-squares problem
$\min_x \tfrac12 \lVert r(x) \rVert^2$ over a box $lo \le x \le hi$, with
$r = (\text{model}(x) - \text{observed}) / \sigma$ (Nocedal & Wright 2006, ch. 10). The pieces
are written once here:

* **box transform**: $x = lo + (hi - lo)\,\mathrm{sigmoid}(y)$ maps an unconstrained $y$ into
  the box (`to_box`, inverse `from_box`), so an unconstrained solver never leaves it;
* **batched Levenberg–Marquardt** (`levenberg_marquardt`): a fixed number of damped
  Gauss–Newton steps $(J^TJ + \lambda\,\mathrm{diag}(J^TJ))\,\delta = -J^T r$, a step kept only
  where it lowers the loss (λ × 0.3), else λ × 10 (Marquardt 1963). A fixed step count has no
  data-dependent control flow, so thousands of independent problems (one per pixel) run as one
  `jax.vmap` with no lane waiting on the slowest; the iterate is clipped to the box;
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

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

__all__ = ["Covariance", "covariance", "from_box", "levenberg_marquardt", "to_box"]

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


def levenberg_marquardt(residual, x0, lo, hi, steps: int, *, damping: float = 1e-3) -> Array:
    """`steps` Levenberg–Marquardt steps on ``residual(x) → (n,)`` from x0 (p,), clipped to
    [lo, hi] (p,) (module docstring). One problem; `jax.vmap` it over a batch. Returns x (p,).

    A step is accepted only where it lowers ½‖r‖², so the loss never rises; λ starts at
    `damping`. The Jacobian is forward-mode (`jax.jacfwd`: p ≪ n here).
    """
    lo = jnp.asarray(lo, x0.dtype)
    hi = jnp.asarray(hi, x0.dtype)

    def step(_, carry):
        x, lam = carry
        r = residual(x)
        jac = jax.jacfwd(residual)(x)
        jtj = jnp.matmul(jac.T, jac, precision=_HI)
        g = jnp.matmul(jac.T, r, precision=_HI)
        a = jtj + lam * jnp.diag(jnp.diag(jtj) + jnp.finfo(x.dtype).tiny ** 0.5)
        xn = jnp.clip(x - jnp.linalg.solve(a, g), lo, hi)
        rn = residual(xn)
        better = jnp.sum(rn * rn) < jnp.sum(r * r)
        return jnp.where(better, xn, x), jnp.where(better, lam * 0.3, lam * 10.0)

    x, _ = jax.lax.fori_loop(0, steps, step, (x0, jnp.asarray(damping, x0.dtype)))
    return x


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
