"""The one per-pixel pipeline (`fit.pixelwise`) on a toy pixel model with a known answer:
three phase-shifted fringes of one thickness, m_j(d) = 1 + a(d) cos(2π d / P + 2π j / 3), whose
fringe orders d and d + P give the same colours when the amplitude a is constant (an exact
ambiguity) and nearly the same when it decays slowly with d (a = exp(−d / L))."""

import warnings

import jax.numpy as jnp
import numpy as np

from thinfilm_jax.fit import pixelwise as PW
from thinfilm_jax.fit.options import MisfitWarning

PERIOD = 200.0  # nm: one fringe order
BOX = {"thickness": (0.0, 1000.0), "eta_film": (1.2, 1.8)}


def _toy(x, pix, ctx):
    """m_j(d) (3,): a fringe of period P, amplitude exp(−d / L) with L = ctx."""
    phase = 2 * jnp.pi * x[0] / PERIOD + 2 * jnp.pi * jnp.arange(3.0) / 3
    return 1.0 + jnp.exp(-x[0] / ctx) * jnp.cos(phase) + 0.0 * pix


def _image(d, decay):
    return np.stack([np.asarray(_toy(jnp.asarray([t, 1.0]), 0.0, decay)) for t in d.ravel()])


def _fit(d, obs, decay, tau=None, sigma=1e-3):
    valid = np.ones(d.shape, bool)
    with warnings.catch_warnings():  # the wrong-order pixel fails the misfit test: intended
        warnings.simplefilter("ignore", MisfitWarning)
        return PW.fit_map(obs, np.zeros(obs.shape[0]), jnp.asarray(decay), _toy, valid,
                          eta0=1.0, free=("thickness",), sigma=sigma, smoothness_nm=tau,
                          bounds=BOX, grid=201, eta_grid=1, steps=10, sweeps=3, chunk=64,
                          devices=None, progress_bar=False)


#: a gentle ramp in the third order, on the screen's grid points (5 nm apart) so that the
#: other orders' grid losses are as low as the fit's (`map_quality.order_flags` reads them)
D = (420.0 + 5.0 * np.arange(12.0)).reshape(3, 4)


def test_exact_ambiguity_is_flagged_with_the_other_order():
    """Constant amplitude: every order d + kP explains each pixel exactly. The fit recovers d
    modulo P to 1e-6 nm, flags every pixel ambiguous, and its `alternative` is another order:
    a whole number of periods away from the fit."""
    res = _fit(D, _image(D, 1e12), 1e12)
    d = np.asarray(res.thickness)
    off = (d - D) / PERIOD
    np.testing.assert_allclose(off, np.round(off), atol=1e-8)
    assert np.all(res.ambiguous)
    k = (res.alternative - d) / PERIOD
    assert np.all(np.abs(np.round(k)) >= 1)
    np.testing.assert_allclose(k, np.round(k), atol=0.03)  # grid points, 5 nm apart
    np.testing.assert_allclose(res.chi2, 2 * np.asarray(res.loss))
    assert res.n_pixels == D.size and res.chi2.max() < 1e-12


def test_distinct_orders_are_not_ambiguous():
    """Amplitude decaying over L = 300 nm: the orders' colours differ by ≫ σ, so the fit lands
    on the truth (to 1e-6 nm) and no pixel is ambiguous. The standard error is the closed
    form σ / ‖∂m/∂d‖ = σ / (a √1.5 √((2π/P)² + 1/L²)) (Σ_j sin² = Σ_j cos² = 3/2 over the
    three phases, Σ_j sin cos = 0)."""
    d = D + 2.3  # off the screen's grid: the refine stage finds it
    res = _fit(d, _image(d, 300.0), 300.0)
    np.testing.assert_allclose(np.asarray(res.thickness), d, atol=1e-6)
    assert not np.any(res.ambiguous)
    a = np.exp(-d / 300.0)
    expect = 1e-3 / (a * np.sqrt(1.5) * np.hypot(2 * np.pi / PERIOD, 1 / 300.0))
    np.testing.assert_allclose(np.asarray(res.stderr), expect, rtol=1e-6)


def test_neighbour_prior_picks_the_continuous_order():
    """One pixel's data belong to the next order (d + P). A slowly decaying amplitude (L =
    5000 nm: the orders' colours differ by ≈ 0.036 · a, ½χ² ≈ 2.4 at σ = 0.02) makes the
    neighbours' order nearly as good for it. Alone, the fit follows its data into the other
    order; with the neighbour prior (τ = 30 nm: ½(P/τ)² ≈ 22 per neighbour) ICM puts it in
    its neighbours' order, within the amplitude's small bias of the ramp, flagged ambiguous
    with the other order as its `alternative`."""
    decay = 5000.0
    wrong = D.copy()
    wrong[1, 2] += PERIOD
    obs_wrong = _image(wrong, decay)
    alone = _fit(D, obs_wrong, decay, sigma=0.02)
    assert abs(float(alone.thickness[1, 2]) - wrong[1, 2]) < 1e-6
    prior = _fit(D, obs_wrong, decay, tau=30.0, sigma=0.02)
    t = np.asarray(prior.thickness)
    assert abs(t[1, 2] - D[1, 2]) < 20.0, t[1, 2]
    mask = np.ones(D.shape, bool)
    mask[1, 2] = False
    np.testing.assert_allclose(t[mask], D[mask], atol=5.0)
    assert prior.ambiguous[1, 2]  # its data fit the other order better: flagged
    np.testing.assert_allclose(prior.alternative[1, 2], wrong[1, 2], atol=5.0)


def test_icm_and_choose():
    """`icm` on a 1 × 3 row: the middle pixel alone prefers 300 nm (energy 0 vs 0.1), its
    neighbours hold 100 nm firmly (50 vs 0), and τ = 50 nm makes 100 nm its lower total
    energy (0.1 vs 2 · ½(200/50)² = 16); with
    no sweeps, or a prior too weak (τ = 1e4 nm), each pixel takes its own best. `choose`
    without τ is each pixel's lowest χ²."""
    energy = np.zeros((1, 3, 2))
    energy[0, 0] = energy[0, 2] = [0.0, 50.0]
    energy[0, 1] = [0.1, 0.0]
    values = np.broadcast_to([100.0, 300.0], (1, 3, 2))
    valid = np.ones((1, 3), bool)
    assert PW.icm(energy, values, valid, 50.0, 2).tolist() == [[0, 0, 0]]
    assert PW.icm(energy, values, valid, 1e4, 2).tolist() == [[0, 1, 0]]
    assert PW.icm(energy, values, valid, 50.0, 0).tolist() == [[0, 1, 0]]
    cand = values.reshape(3, 2)
    where = np.arange(3)
    assert PW.choose(cand, 2 * energy.reshape(3, 2), where, valid, None, 2).tolist() == [0, 1, 0]
    assert PW.choose(cand, 2 * energy.reshape(3, 2), where, valid, 50.0, 2).tolist() == [0, 0, 0]
    d_alt, has = PW.alternative(cand, 2 * energy.reshape(3, 2), np.array([100.0, 100.0, 300.0]),
                                15.0)
    assert d_alt.tolist() == [300.0, 300.0, 100.0] and has.all()


def test_one_result_type():
    """The map fits and `fit_photo` return the one `MapResult` (`PhotoResult` is its name in
    the photographs' pages): a map's summary has the χ² statistics and no camera fields."""
    from thinfilm_jax.fit.photo import PhotoResult
    from thinfilm_jax.fit.results import MapResult

    assert PhotoResult is MapResult
    res = _fit(D, _image(D, 300.0), 300.0)
    assert isinstance(res, MapResult) and res.exposure is None and res.camera is None
    s = res.summary()
    assert "exposure" not in s and s["pixels_fitted"] == D.size == res.n_pixels
    assert s["pixels_ambiguous"] == 0 and s["chi2_p50_p99"][1] < 1e-12


def test_refine_pulls_a_pixel_toward_its_neighbours_as_the_prior_weighs():
    """Stage 3's solve with the prior's residuals, on a linear pixel model with one residual
    (d − a)/s and neighbours at b: it minimises ((d − a)/s)² + Σ_q ((d − b)/τ)² over the
    neighbours present, whose minimum is the precision-weighted mean
    d* = (a/s² + n b/τ²)/(1/s² + n/τ²) (closed form), n = 4 and n = 2 (two neighbours off
    the map), and d = a with none (the prior's residuals are zero where `ok` is False)."""
    a, b, s, tau = 500.0, 520.0, 4.0, 10.0
    lo, hi = jnp.asarray([0.0]), jnp.asarray([1000.0])

    def data(x):
        return jnp.atleast_1d((x[0] - a) / s)

    q = jnp.full(4, b)
    for ok, n in (([True] * 4, 4), ([True, False, True, False], 2), ([False] * 4, 0)):
        x, _, _ = PW.refine_pixel(data, jnp.asarray([a]), q, jnp.asarray(ok), tau, lo, hi,
                                  steps=30)
        want = (a / s**2 + n * b / tau**2) / (1 / s**2 + n / tau**2)
        np.testing.assert_allclose(float(x[0]), want, atol=1e-6)
