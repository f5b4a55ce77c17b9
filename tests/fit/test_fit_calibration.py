"""Are `fit_*` standard errors calibrated? (The fast in-suite check; the study over 200 films,
views and α with the full search is `benchmarks.coverage`, README "Error bars".)

Two checks of different kinds:

* deterministic: at each fitted optimum, `FitResult.stderr` and `.correlation` equal the
  linearised Gauss–Newton covariance s²(JᵀJ)⁻¹, s² = Σr²/(n − p), built here in NumPy from a
  central finite-difference Jacobian of `airy_reflectance` and the residuals against the
  noisy data (no code of `fit.py`): pins the formula (scale, dof, inversion) to 1e-6;
* statistical: seeded Gaussian noise of known σ on exact model data, N_FITS fits started at
  the truth; the standardised errors z = (fit − truth) / stderr must have E[z²] ≈ ν/(ν − 2)
  (Student t, ν = 46 dof), and the Student-t intervals of `FitResult.interval` must cover
  the truth at their level. Power stated at each assertion.
"""

import numpy as np
import pytest

from thinfilm_jax import Film, airy_reflectance
from thinfilm_jax.fit.film_fit import FitOptions, fit_spectrum

# 400 fits: one compilation, then ~25 ms per fit (2 shared cores); 100 fits could not tell a
# standard error 20 % off from a right one (sd of the mean of z² over N fits ≈ √(2.13 / N)).
N_FITS = 400
LAM = np.linspace(420.0, 720.0, 16)
COS = np.cos(np.deg2rad([0.0, 40.0, 65.0]))
TRUTH = Film(430.0, 1.45, 2.2, 0.3)
FREE = ("thickness", "eta_film")
DOF = LAM.size * COS.size - len(FREE)  # 46


def _model(d, eta_film):
    return np.asarray(airy_reflectance(TRUTH._replace(thickness=d, eta_film=eta_film),
                                       COS[:, None], LAM))


@pytest.fixture(scope="module")
def spectrum_fits():
    clean = _model(TRUTH.thickness, TRUTH.eta_film)
    sd = 0.01 * np.sqrt(np.mean(clean**2))
    rng = np.random.default_rng(7)
    opts = FitOptions(n_starts=1, n_orders=0)  # start at the truth: calibration, not search
    out = []
    for _ in range(N_FITS):
        obs = clean + sd * rng.standard_normal(clean.shape)
        out.append((obs, fit_spectrum(obs, LAM, COS, initial=TRUTH, free=FREE, options=opts)))
    return out


def test_stderr_is_the_linearised_covariance(spectrum_fits):
    """stderr and correlation = s²(JᵀJ)⁻¹ with a finite-difference J, for 8 of the fits.

    Measured max relative difference: ~1e-9 (the central differences' own error). Asserted
    at 1e-6: a wrong dof (n instead of n − p: 2 %), a missing or doubled s², or a Jacobian
    in the unconstrained coordinates all fail."""
    steps = (1e-3, 1e-6)  # nm, refractive index: truncation ~1e-11, rounding ~1e-12 relative
    worst = 0.0
    for obs, res in spectrum_fits[:8]:
        x = np.array([float(res.params[k]) for k in FREE])
        cols = []
        for i, h in enumerate(steps):
            e = np.eye(2)[i] * h
            cols.append(((_model(*(x + e)) - _model(*(x - e))) / (2 * h)).ravel())
        jac = np.stack(cols, axis=1)  # (n, p)
        r = (obs - _model(*x)).ravel()
        cov = (r @ r) / DOF * np.linalg.inv(jac.T @ jac)
        se = np.sqrt(np.diag(cov))
        corr = cov / np.outer(se, se)
        got_se = np.array([float(res.stderr[k]) for k in FREE])
        worst = max(worst, float(np.abs(got_se / se - 1).max()))
        np.testing.assert_allclose(got_se, se, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(res.correlation), corr, rtol=0, atol=1e-6)
    print(f"\nstderr vs finite-difference covariance: max relative difference {worst:.1e}")


def _z(fits, k):
    return np.array([(float(r.params[k]) - getattr(TRUTH, k)) / float(r.stderr[k])
                     for _, r in fits])


def test_spectrum_stderr_calibrated(spectrum_fits):
    """E z² = ν/(ν − 2) = 1.045 for ν = 46 (the t distribution); the estimate's sd over 400
    fits is √(2.13 / 400) ≈ 0.073 (Var z² = 2.13 for t₄₆). Asserted within ±0.25 (3.4 sd):
    a standard error 15 % too small (E z² = 1.38) or 15 % too large (0.79) fails, as does
    one 2× off; a 10 % error can pass. Measured E z²: printed (d, η₂)."""
    means = []
    for k in FREE:
        z = _z(spectrum_fits, k)
        assert np.all(np.isfinite(z))
        means.append(float(np.mean(z**2)))
        assert abs(means[-1] - DOF / (DOF - 2)) < 0.25, (k, means[-1])
    print("\nE z² (thickness, eta_film):", ", ".join(f"{m:.3f}" for m in means))


def test_student_t_intervals_cover(spectrum_fits):
    """Coverage of the t intervals at 68 % and 95 %: binomial sd over 400 fits 2.3 and 1.1
    points; asserted within 7 and 3.5 points absolute (≈ 3 sd). Measured: 0.662 / 0.677 at
    68 %, 0.960 / 0.953 at 95 % (d / η₂)."""
    rows = []
    for level, tol in ((0.68, 0.07), (0.95, 0.035)):
        intervals = [r.interval(level) for _, r in spectrum_fits]  # one call per fit and level
        for k in FREE:
            hit = [iv[k][0] <= getattr(TRUTH, k) <= iv[k][1] for iv in intervals]
            rows.append(f"{k} {level}: {np.mean(hit):.3f}")
            assert abs(np.mean(hit) - level) < tol, (level, k, np.mean(hit))
    print("\ncoverage:", "; ".join(rows))


def test_interval_uses_student_t(spectrum_fits):
    """The half-width of `interval(0.95)` is q · stderr with q the Student-t quantile of
    n − p degrees of freedom (n observations): t₀.₉₇₅ = 2.0129 for ν = 46 (these fits),
    2.2281 for ν = 10 (12 observations, e.g. four views × three bands, 2 free), not the
    normal 1.9600, which ``absolute_sigma=True`` gives. Quantiles from printed t tables, not
    from scipy. (Reuses the spectral fits: a patch fit would only add a compilation; the
    interval reads the residual count and `free`, nothing model-specific.)"""
    _, res = spectrum_fits[0]
    few = res._replace(residuals=np.zeros((4, 3)))
    for r, absolute, q_want in ((res, False, 2.0129), (few, False, 2.2281),
                                (res, True, 1.9600), (few, True, 1.9600)):
        lo, hi = r.interval(0.95, absolute_sigma=absolute)["thickness"]
        q = (hi - lo) / 2 / float(r.stderr["thickness"])
        assert abs(q - q_want) < 1e-3, (q, q_want, absolute)
    with pytest.raises(ValueError, match="level"):
        res.interval(1.5)
