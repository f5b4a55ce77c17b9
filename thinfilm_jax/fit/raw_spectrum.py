r"""Raw spectrometer spectra: `fit_spectrum(..., envelope=k)` (SPEC §14).

A spectrometer reports counts, not reflectance: the lamp's spectrum times the detector's
response multiplies R, and stray light plus dark current add to it. The model is

$$ o(\lambda) = g(\lambda)\,R(\lambda; x) + b(\lambda),\qquad
   g = \sum_{j=0}^{k} a_j P_j(t),\quad b = \sum_{j=0}^{k} c_j P_j(t),\quad
   t = \frac{2\lambda - \lambda_{\min} - \lambda_{\max}}{\lambda_{\max} - \lambda_{\min}}
   \in [-1, 1], $$

with $P_j$ the Legendre polynomials (`numpy.polynomial.legendre.legvander`) in the centred,
scaled wavelength $t$: on $[-1, 1]$ the columns of the basis are nearly orthogonal, where
the monomials $\lambda^j$ of a 400–800 nm band are collinear to 1e-6. Each spectrum (one
angle of incidence) has its own $g$ and $b$: $m = 2(k + 1)$ linear parameters per angle.

**Variable projection** (Golub & Pereyra 1973, SIAM J. Numer. Anal. 10, 413; the review of
Golub & Pereyra 2003, Inverse Problems 19, R1). For given film parameters $x$ the model is
linear in $(a, c)$: with the design matrix $A(x) = [\,\mathrm{diag}(R)\,V,\; V\,]$
($V$ the $n_\lambda \times (k+1)$ Legendre basis) and the weights $W = \mathrm{diag}(1/\sigma)$,
the linear coefficients are the weighted least-squares solution
$\hat u(x) = \arg\min_u \lVert W(A u - o)\rVert$, and the fit minimises the *projected*
residual

$$ r(x) = W\,(A(x)\,\hat u(x) - o) = -P^\perp_{WA(x)}\, W o , $$

over the film parameters alone. $\hat u$ is computed by Householder QR
(`jax.numpy.linalg.qr`) of $WA$ with its columns scaled to unit norm, stacked on
$\sqrt{\epsilon}\,I$ ($\epsilon$ the dtype's machine epsilon): a ridge of relative size
√eps, which changes a well-posed solution by $O(\epsilon)$ and keeps value and derivatives
finite where $A$ is rank deficient ($R$ constant in λ: $d \to 0$, or $\eta_2 = \eta_1$;
a column $R = 0$). Every stage of the search
(`fit.multistart`: the screen, the short solves, the fringe-order moves, the polish) sees
only $r(x)$, so the global search runs over the film parameters alone.

**Derivatives.** The Jacobian of $r$ is the exact Golub–Pereyra Jacobian (not Kaufman's
approximation), taken by forward-mode AD with a custom rule for the solve: with $B = WA$
(unit columns), $G = B^TB + \epsilon I = R^TR$ ($R$ the QR's triangle) and
$G\hat u = B^T b$, differentiating gives
$G\,d\hat u = B^T(db - dB\,\hat u) - dB^T(B\hat u - b)$ and
$d(B\hat u - b) = dB\,\hat u + B\,d\hat u - db$: two triangular solves with $R$ and four
products with $n \times m$ matrices. It is the derivative of the same ridge solution that
AD through the QR gives (they agree to rounding), 13 times cheaper: on a 1161 × 6 design
(2-core CPU) 0.4 ms against 5.4 ms for JAX's QR derivative rule, ≈ 50 residual
evaluations, and the Levenberg–Marquardt steps of the search take a Jacobian after every
accepted step (a raw fit of 1161 wavelengths: 0.23 s warm, from 0.7–3 s).

**Standard errors.** $\operatorname{cov}(x) = s^2 (J_{VP}^T J_{VP})^{-1}$ with $J_{VP}$ the
Jacobian of the projected residual. At the optimum $J_{VP}^T J_{VP}$ equals, up to terms of
the order of the residual, the Schur complement of the full Gauss–Newton matrix of the
joint problem (film + linear parameters) on the film block: the marginal covariance of the
film parameters with $g$ and $b$ free (Golub & Pereyra 2003, §3). The degrees of freedom
are $\nu = n - p - m\,n_\text{angles}$ ($n$ observations, $p$ film parameters), used for
$s^2 = \sum r^2/\nu$, the Student-t intervals, Δχ² of the runner-ups and the reduced χ².

**Screen density.** The film's phase at wavelength λ is $\varphi = 4\pi n d \cos\theta_2/\lambda$,
$\partial\varphi/\partial d = 4\pi n\cos\theta_2/\lambda$, largest at the bluest wavelength:
a thickness error $\delta$ puts the fringes at $\lambda_{\min}$ out of phase by
$4\pi n\delta/\lambda_{\min}$, and the basin of the true minimum is about
$\pm\lambda_{\min}/(8 n \cos\theta_2)$ wide (a quarter period at $\lambda_{\min}$) at any
$d$: a 3 µm film has the same basin as a 150 nm one but many more near-degenerate
neighbours (fringes 15–60 nm apart in λ over 400–800 nm). The screen therefore places
thickness starts $\Delta d = \lambda_{\min}/(16\,n\cos\theta_2)$ apart (two per half-basin)
over the whole thickness box, at least `DEFAULT_N_STARTS` (256): `raw_starts`. Over
0–5000 nm with λ ≥ 450 nm and n = 1.33 that is 237 → 256 starts, 19.5 nm apart.

**Noise weights** (``sigma=None``). Spectrometer noise is not uniform: shot noise follows
the counts and the lamp is dim in the blue, so the relative noise is several times larger
below ~450 nm. Unweighted, the noisy blue end pulls the fit; the fit estimates σ(λ) from
the data in two passes: (1) the fit with uniform weights; (2) σ̂²(λ) = the moving average
of the squared residuals over a window of `SIGMA_WINDOW` (1/16) of the band (odd, ≥ 11
samples; edge-normalised), floored at `SIGMA_FLOOR` (0.2) × its median so that a window
that happens to fit exactly cannot take all the weight; (3) the fit again (the full
search) with σ = σ̂. The residual-based estimate measures the noise *and* what the model
cannot explain (an envelope of too low a degree, a bad pixel range), and down-weights both;
a local high-pass of the data alone would confuse the fringes of a thick film (15 nm apart
in the blue for 4 µm, comparable to the window) with noise. With σ estimated, no misfit
test is made (`reduced_chi2` is NaN): the estimate makes χ²/ν ≈ 1 by construction.

Example (a 300 nm film under a sloping lamp with an offset; the envelope is found with it):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, airy_reflectance
    >>> lam = np.linspace(450.0, 800.0, 200)
    >>> lamp = 2.0 + 3.0 * (lam - 450.0) / 350.0
    >>> raw = lamp * airy_reflectance(Film(300.0, 1.33, 1.0), 1.0, lam) + 0.05
    >>> from thinfilm_jax import fit_spectrum
    >>> res = fit_spectrum(raw, lam, 1.0, initial=Film(500.0, 1.33, 1.0), envelope=1,
    ...                    sigma=1e-3)
    >>> round(float(res.film.thickness), 3), res.envelope.degree
    (300.0, 1)
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax import Array

from ..core import _validate as V
from ..core.stack import Stack
from ..optics.index import index_at
from .multistart import order_moves, solve_multistart
from .options import DEFAULT_N_STARTS, FitResult, MisfitWarning, misfit_warnings, reduced_chi2

__all__ = ["Envelope", "SIGMA_FLOOR", "SIGMA_WINDOW", "envelope_basis", "estimate_sigma",
           "project", "raw_starts"]

_HI = jax.lax.Precision.HIGHEST
#: moving window of the σ(λ) estimate, as a fraction of the number of wavelengths
SIGMA_WINDOW = 1.0 / 16.0
#: σ̂ is at least this fraction of its median over the band
SIGMA_FLOOR = 0.2


class Envelope(NamedTuple):
    """The fitted lamp envelope of a raw-spectrum fit: o(λ) = g(λ)·R(λ) + b(λ).

    Attributes:
        degree: k, the degree of g and b.
        center_nm, half_width_nm: the scaled variable t = (λ − center) / half_width ∈ [−1, 1].
        gain_coefficients, offset_coefficients: (n_angles, k + 1) Legendre coefficients of g
            and b in t (`numpy.polynomial.legendre.legval(t, c)`), one row per spectrum.
        gain, offset: (n_angles, n_wl) g and b on the fit's wavelengths.
        sigma: (n_angles, n_wl) the noise σ the fit weighted by (given, or estimated: module
            docstring).
        sigma_estimated: True when σ was estimated from the data.
        offset_fitted: False when a known background was given (b is that background, its
            coefficients zero and not counted as fitted).
    """

    degree: int
    center_nm: float
    half_width_nm: float
    gain_coefficients: Array
    offset_coefficients: Array
    gain: Array
    offset: Array
    sigma: Array
    sigma_estimated: bool
    offset_fitted: bool = True

    @property
    def n_linear(self) -> int:
        """The number of eliminated linear parameters: 2 (k + 1) per spectrum (k + 1 with a
        known background)."""
        per = (2 if self.offset_fitted else 1) * (self.degree + 1)
        return per * int(np.shape(self.gain_coefficients)[0])

    def evaluate(self, wavelength) -> tuple[np.ndarray, np.ndarray]:
        """(g, b) at `wavelength` (nm), each (n_angles, n) (b None when a known background
        was given: it exists on the fit's wavelengths only, `offset`)."""
        t = (np.asarray(wavelength, float) - self.center_nm) / self.half_width_nm
        leg = np.polynomial.legendre.legval
        gain = np.stack([leg(t, c) for c in np.asarray(self.gain_coefficients, float)])
        if not self.offset_fitted:  # a known background, given on the fit's grid only
            return gain, None
        return gain, np.stack([leg(t, c) for c in np.asarray(self.offset_coefficients, float)])

    def to_dict(self) -> dict:
        """JSON-ready: degree, the t scaling and the coefficients."""
        return {"degree": int(self.degree), "basis": "legendre",
                "center_nm": float(self.center_nm), "half_width_nm": float(self.half_width_nm),
                "gain_coefficients": np.asarray(self.gain_coefficients, float).tolist(),
                "offset_coefficients": np.asarray(self.offset_coefficients, float).tolist(),
                "sigma_estimated": bool(self.sigma_estimated),
                "offset_fitted": bool(self.offset_fitted)}


def envelope_basis(wavelength, degree: int) -> tuple[np.ndarray, float, float]:
    """(V (n_wl, k + 1), center, half_width): the Legendre basis P_j(t) in the scaled
    wavelength t = (λ − center)/half_width ∈ [−1, 1] (module docstring). Host NumPy."""
    lam = np.asarray(wavelength, float)
    lo, hi = float(lam.min()), float(lam.max())
    center, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    half = half if half > 0 else 1.0
    return np.polynomial.legendre.legvander((lam - center) / half, degree), center, half


def project(reflectance, observed, weight, basis, offset: bool = True):
    r"""Variable projection of the envelope for one film (module docstring).

    Args:
        reflectance: R (n_angles, n_wl).
        observed: o (n_angles, n_wl).
        weight: 1/σ (n_angles, n_wl).
        basis: V (n_wl, k + 1).
        offset: fit the offset b (else b ≡ 0: a known background was subtracted).

    Returns:
        (r (n_angles, n_wl) the weighted projected residual W(A û − o),
        û (n_angles, 2(k + 1)): the gain coefficients a then the offset coefficients c).
        Where the free solution's gain g(λ) = V a is not positive on the whole grid, the
        envelope is the offset alone (a = 0; module docstring).
    """
    v = jnp.asarray(basis, reflectance.dtype)
    k1 = v.shape[1]

    def one(r_a, o_a, w_a):
        wo = w_a * o_a
        cols = [r_a[:, None] * v, v] if offset else [r_a[:, None] * v]
        res, u = _lstsq(jnp.concatenate(cols, axis=1) * w_a[:, None], wo)
        # the lamp is positive: where the free solution's g(λ) is not, the offset alone
        # (g ≡ 0: the constrained minimum's upper bound, independent of the film)
        if offset:
            res0, u0 = _lstsq(v * w_a[:, None], wo)
        else:
            res0, u0 = -wo, jnp.zeros((0,), wo.dtype)
        u0 = jnp.concatenate([jnp.zeros((k1,), wo.dtype), u0])
        ok = jnp.min(jnp.matmul(v, u[:k1], precision=_HI)) > 0
        return jnp.where(ok, res, res0), jnp.where(ok, u, u0)

    return jax.vmap(one)(reflectance, observed, weight)


def _lstsq(a, b):
    """(a û − b, û) of min ‖a u − b‖ (a (n, m)): Householder QR of a with unit-norm columns
    stacked on √eps·I (module docstring)."""
    n2 = jnp.sum(a * a, axis=0)
    ok = n2 > 0
    s = jnp.where(ok, jnp.sqrt(jnp.where(ok, n2, 1.0)), 1.0)  # double where: zero column
    res, u = _ridge_solve(a / s, b)
    return res, u / s


def _ridge_factor(a, b):
    """(R, û, a û − b) of the ridge least squares min ‖a u − b‖² + eps‖u‖² (a (n, m), unit
    columns): Householder QR of [a; √eps I] (`jax.numpy.linalg.qr`)."""
    m = a.shape[1]
    eps = jnp.finfo(a.dtype).eps
    aug = jnp.concatenate([a, jnp.sqrt(eps) * jnp.eye(m, dtype=a.dtype)], axis=0)
    q, rr = jnp.linalg.qr(aug)
    rhs = jnp.matmul(q[: b.shape[0]].T, b, precision=_HI)
    u = jax.scipy.linalg.solve_triangular(rr, rhs, lower=False)
    return rr, u, jnp.matmul(a, u, precision=_HI) - b


@jax.custom_jvp
def _ridge_solve(a, b):
    """(a û − b, û), û = argmin ‖a u − b‖² + eps‖u‖² (`_ridge_factor`), with its exact
    derivative as a custom JVP (module docstring, "Derivatives")."""
    _, u, res = _ridge_factor(a, b)
    return res, u


@_ridge_solve.defjvp
def _ridge_solve_jvp(primals, tangents):
    # G û = aᵀb with G = aᵀa + eps I = RᵀR, differentiated:
    # G dû = aᵀ(db − da û) − daᵀ(a û − b); d(a û − b) = da û + a dû − db
    a, b = primals
    da, db = tangents
    rr, u, res = _ridge_factor(a, b)
    dau = jnp.matmul(da, u, precision=_HI)
    g = jnp.matmul(a.T, db - dau, precision=_HI) - jnp.matmul(da.T, res, precision=_HI)
    y = jax.scipy.linalg.solve_triangular(rr, g, lower=False, trans="T")
    du = jax.scipy.linalg.solve_triangular(rr, y, lower=False)
    return (res, u), (dau + jnp.matmul(a, du, precision=_HI) - db, du)


def _moving_mean(x, window):
    """Edge-normalised moving mean of each row of x over `window` (odd) samples."""
    kern = jnp.ones((window,), x.dtype)

    def one(row):
        num = jnp.convolve(row, kern, mode="same", precision=_HI)
        den = jnp.convolve(jnp.ones_like(row), kern, mode="same", precision=_HI)
        return num / den

    return jax.vmap(one)(x)


def estimate_sigma(residuals):
    """σ̂(λ) (n_angles, n_wl) from the residuals of a fit (module docstring): the square root
    of the moving mean of r² over `SIGMA_WINDOW` of the band (odd, ≥ 11 samples), floored at
    `SIGMA_FLOOR` × its median per spectrum; trace-safe."""
    r = jnp.asarray(residuals)
    n = r.shape[-1]
    window = max(11, int(round(n * SIGMA_WINDOW)) | 1)
    window = min(window, n if n % 2 else n - 1)
    var = _moving_mean(r * r, max(window, 1))
    sig = jnp.sqrt(jnp.where(var > 0, var, 1.0))
    sig = jnp.where(var > 0, sig, 0.0)
    floor = SIGMA_FLOOR * jnp.median(sig, axis=-1, keepdims=True)
    tiny = jnp.finfo(r.dtype).tiny ** 0.5
    return jnp.maximum(sig, jnp.maximum(floor, tiny))


def raw_starts(spec, material, wavelength, cos_theta, n_starts) -> int:
    """Thickness starts of the screen of a raw-spectrum fit with one free thickness (module
    docstring): `n_starts` when given, else max(`DEFAULT_N_STARTS`, ⌈(hi − lo)/Δd⌉) with
    Δd = λ_min / (16 n cos θ₂), n the layer's Re index at λ_min (its initial value) and
    cos θ₂ the smallest over the angles (Snell). Several free layers: the product-grid
    default of the absolute fit."""
    if n_starts is not None or len(spec.thick) != 1 or not (
            V.is_concrete(wavelength) and V.is_concrete(cos_theta)):
        return n_starts  # (traced wavelengths: the absolute fit's default)
    k, layer = spec.thick[0]
    lam_min = float(np.min(np.asarray(wavelength)))
    n = _real_index(material.eta[layer] if isinstance(material, Stack) else material.eta_film,
                    lam_min)
    n0 = _real_index(material.eta_outer, lam_min)
    sin2 = 1.0 - float(np.min(np.asarray(cos_theta, float))) ** 2  # the most oblique view
    cos2 = math.sqrt(max(1.0 - (n0 / n) ** 2 * sin2, 1e-4))
    step = lam_min / (16.0 * n * cos2)
    width = float(spec.hi[k]) - float(spec.lo[k])
    return max(DEFAULT_N_STARTS["spectrum"], int(math.ceil(width / step)))


def _real_index(eta, lam):
    """Re n of a number or an index model at λ (nm), a host float."""
    return float(np.real(np.asarray(index_at(eta, lam))))


@functools.partial(jax.jit, static_argnames=("cfg", "offset", "model", "finish"))
def _fit_raw_jit(observed, w, wavelength, cos_theta, base, y_starts, box, basis, cfg, offset,
                 model, finish):
    spec = cfg.spec._replace(lo=box[0], hi=box[1])

    def res_film(film, obs, ww):
        refl = model(film, cos_theta, wavelength)
        return project(refl, obs, ww, basis, offset)[0].reshape(-1)

    def res(y, args):
        return res_film(spec.x_full(y, base)[0], *args)

    def res_x(x_free, args):
        return res_film(spec.with_free(x_free, base)[0], *args)

    args = (observed, w)
    orders, distinct = order_moves(spec, base, cos_theta, cfg.wavelength, cfg.n_orders)
    out = solve_multistart(res, res, y_starts, args, cfg, orders, distinct)
    fin = finish(out, res_x, spec, base, args, w, cfg)
    film = fin[1][0]
    refl = jax.lax.stop_gradient(model(film, cos_theta, wavelength))
    _, u = project(refl, jax.lax.stop_gradient(observed), jax.lax.stop_gradient(w), basis,
                   offset)
    return fin, u


def fit_raw(observed, w, wavelength, cos_theta, base, y_starts, x_starts, box, cfg, free,
            degree, sigma_given, background, model, finish):
    """The raw-spectrum fit behind `fit_spectrum(..., envelope=degree)`: one search with the
    weights `w`, or (σ not given) two (module docstring); `background` (n_angles, n_wl), a
    known b(λ) (a dark or no-film spectrum), subtracted, b not fitted, or None. `model`
    (`film_fit.spectrum_model`) and `finish` (`film_fit._finish`: the fitted values, errors
    and runner-ups) are `fit_spectrum`'s own, passed in (`film_fit` imports this module).
    Returns the `FitResult`."""
    basis, center, half = envelope_basis(wavelength, degree)
    basis = jnp.asarray(basis, observed.dtype)
    offset = background is None
    if not offset:
        observed = observed - background

    def run(weights):
        return _fit_raw_jit(observed, weights, wavelength, cos_theta, base, y_starts, box,
                            basis, cfg, offset, model, finish)

    with jax.default_matmul_precision("highest"):
        out, u = run(w)
        if not sigma_given:
            w = 1.0 / estimate_sigma(jax.lax.stop_gradient(out[3]))
            out, u = run(w)
    k1 = degree + 1
    gain_c = u[:, :k1]
    off_c = u[:, k1:] if offset else jnp.zeros_like(gain_c)
    gain = jnp.matmul(gain_c, basis.T, precision=_HI)
    off = jnp.matmul(off_c, basis.T, precision=_HI) if offset else background
    env = Envelope(degree, center, half, gain_c, off_c, gain, off, 1.0 / w, not sigma_given,
                   offset)
    return _result_raw(out, free, x_starts, sigma_given, env, cfg.absolute_sigma)


def _result_raw(out, free, x_starts, sigma_given, env, absolute_sigma):
    """`film_fit._result` for a raw fit: ν = n − p − n_linear for s², the standard errors,
    Δχ² and the reduced χ² (module docstring)."""
    sol, (film, _), loss, resid, stderr, corr, start_loss, alt_x, alt_loss, dchi2 = out
    n, p, m = int(np.size(resid)), len(free), env.n_linear
    dof = n - p - m
    if not absolute_sigma:  # engine.covariance divided Σr² by n − p
        fix = math.sqrt((n - p) / dof) if dof > 0 else math.nan
        stderr = stderr * fix
        dchi2 = dchi2 / fix ** 2
    red = reduced_chi2(2.0 * loss, n, p + m, sigma_given)
    msg = misfit_warnings(red, dof) if sigma_given else ()
    for s in msg:
        warnings.warn(s, MisfitWarning, stacklevel=4)
    return FitResult(film, None, loss, sol.result == optx.RESULTS.successful,
                     sol.stats["num_steps"], dict(zip(free, stderr)), corr, free, resid,
                     x_starts, start_loss, sol, alt_x, alt_loss, dchi2, red, msg, env)
