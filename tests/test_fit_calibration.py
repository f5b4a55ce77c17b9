"""Are `fit_*` standard errors calibrated? (issue 13 §2, the fast in-suite check.)

Seeded Gaussian noise of known σ on exact model data; the fitted parameters' standardised
errors z = (fit − truth) / stderr must have E[z²] ≈ 1 (a covariance wrong by 2× gives 0.5 or
2), and the Student-t intervals of `FitResult.interval` must cover the truth at their level.
The study over 200 films, views and α with the full search is `studies.coverage` (README).
"""

import numpy as np
import pytest

from thinfilm_jax import Film, airy_reflectance
from thinfilm_jax.fit import FitOptions, fit_film, fit_spectrum

N_FITS = 100


@pytest.fixture(scope="module")
def spectrum_fits():
    lam = np.linspace(420.0, 720.0, 16)
    cos = np.cos(np.deg2rad([0.0, 40.0, 65.0]))
    truth = Film(430.0, 1.45, 2.2, 0.3)
    clean = np.asarray(airy_reflectance(truth, cos[:, None], lam))
    sd = 0.01 * np.sqrt(np.mean(clean**2))
    rng = np.random.default_rng(7)
    opts = FitOptions(n_starts=1, n_orders=0)  # start at the truth: calibration, not search
    out = []
    for _ in range(N_FITS):
        obs = clean + sd * rng.standard_normal(clean.shape)
        res = fit_spectrum(obs, lam, cos, initial=truth, free=("thickness", "eta_film"),
                           options=opts)
        out.append(res)
    return truth, out


def test_spectrum_stderr_calibrated(spectrum_fits):
    truth, fits = spectrum_fits
    for k in ("thickness", "eta_film"):
        z = np.array([(float(r.params[k]) - getattr(truth, k)) / float(r.stderr[k])
                      for r in fits])
        assert np.all(np.isfinite(z))
        # dof = 48 − 2 = 46: E z² = 46/44 ≈ 1.05; the estimate's sd over 100 fits ≈ 0.15
        assert 0.7 < np.mean(z**2) < 1.5, (k, np.mean(z**2))


def test_student_t_intervals_cover(spectrum_fits):
    truth, fits = spectrum_fits
    for level in (0.68, 0.95):
        for k in ("thickness", "eta_film"):
            hit = [lo <= getattr(truth, k) <= hi
                   for lo, hi in (r.interval(level)[k] for r in fits)]
            # binomial sd over 100 fits: 4.7 % at 68 %, 2.2 % at 95 %
            assert abs(np.mean(hit) - level) < 0.12, (level, k, np.mean(hit))


def test_interval_uses_student_t():
    """Few observations: the t quantile (12 obs, 3 free: 2.26 at 95 %) widens the interval
    over ±1.96 SE; absolute σ gives the normal quantile."""
    theta = np.deg2rad([10.0, 27.0, 43.0, 60.0])
    truth = Film(350.0, 1.4, 2.0, 0.5)
    from thinfilm_jax import ModelOptions, patch_radiance

    obs = np.asarray(patch_radiance(truth, theta, 0.2, options=ModelOptions(quadrature=(8, 8))))
    obs = obs * (1 + 0.01 * np.random.default_rng(1).standard_normal(obs.shape))
    res = fit_film(obs, theta, alpha=0.2, initial=truth, free=("thickness", "eta_film", "alpha"),
                   options=FitOptions(n_starts=1, n_orders=0, quadrature=(8, 8)))
    lo, hi = res.interval(0.95)["thickness"]
    q = (hi - lo) / 2 / float(res.stderr["thickness"])
    assert abs(q - 2.262) < 1e-3, q
    lo, hi = res.interval(0.95, absolute_sigma=True)["thickness"]
    assert abs((hi - lo) / 2 / float(res.stderr["thickness"]) - 1.960) < 1e-3
    with pytest.raises(ValueError, match="level"):
        res.interval(1.5)
