"""Raw spectrometer spectra (SPEC §14): `fit_spectrum(..., envelope=k)`, variable projection,
`read_spectrum`.

Independent sources: the synthetic spectra's reflectance is Byrnes' `tmm` (coh_tmm), the
linear solve is checked against `numpy.linalg.lstsq`, the eliminated fit against a joint
fit of film and envelope by `scipy.optimize.least_squares` (its standard error from the
full Jacobian), and two of optifik's published spectra against their labels.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.fit.film_fit import spectrum_model
from thinfilm_jax.fit.raw_spectrum import envelope_basis, estimate_sigma, project
from thinfilm_jax.fit.spectrum_file import read_spectrum

tmm = pytest.importorskip("tmm")

LAM = np.arange(450.0, 901.0)  # 1 nm steps: the grid of the manue spectra cut to 450–900 nm
BOX = tf.FitOptions(bounds={"thickness": (0.0, 5000.0)})
N_SOAP = 1.33
#: recovered thickness of the synthetic raw spectra (noise 3e-4 of a signal ~0.1, five times
#: that at 450 nm): about 3 standard errors (1.1–1.8 nm thin, k = 1; ~0.5 nm thick, k = 2)
MARGIN_NM = {150.0: 5.0, 3000.0: 2.0}
#: envelope degree of each synthetic case (the lamp's true degree)
DEGREE = {150.0: 1, 3000.0: 2}
REAL = Path(__file__).resolve().parents[2].parent / "shared" / "real" / "spectra_optifik"


def tmm_reflectance(d, lam, n=N_SOAP):
    """R at normal incidence of air | film | air from tmm (independent of the library)."""
    return np.array([tmm.coh_tmm("s", [1.0, n, 1.0], [np.inf, d, np.inf], 0.0, x)["R"]
                     for x in lam])


def raw_signal(d, seed=0, degree=2):
    """A raw spectrum: a lamp rising 3× across the band (quadratic, or linear), an offset,
    and noise five times larger at 450 nm than in the red."""
    t = (LAM - 450.0) / 450.0
    lamp = 1.0 + 1.4 * t + 0.6 * t * t if degree == 2 else 1.0 + 2.0 * t
    offset = 0.004 + 0.002 * t
    sigma = 3e-4 * (1.0 + 4.0 * np.exp(-(LAM - 450.0) / 60.0))
    rng = np.random.default_rng(seed)
    return lamp * tmm_reflectance(d, LAM) + offset + rng.normal(0.0, sigma), sigma, lamp, offset


@pytest.mark.parametrize("d", [150.0, 3000.0])
def test_synthetic_raw_spectrum_recovered(d):
    k = DEGREE[d]
    obs, sigma, lamp, offset = raw_signal(d, degree=k)
    res = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=k,
                          options=BOX)
    assert abs(float(res.film.thickness) - d) < MARGIN_NM[d]
    env = res.envelope
    assert env.degree == k and env.sigma_estimated and env.n_linear == 2 * (k + 1)
    # the fitted signal g R + b is the noise-free one (to a fraction of the noise); a thick
    # film's fringes separate g from b (a thin film's broad R trades them: signal only)
    clean = lamp * tmm_reflectance(d, LAM) + offset
    model = obs + np.asarray(res.residuals)[0]
    assert np.sqrt(np.mean(((model - clean) / sigma) ** 2)) < 0.5
    if d > 1000.0:
        np.testing.assert_allclose(np.asarray(env.gain)[0], lamp, rtol=0.02)
        np.testing.assert_allclose(np.asarray(env.offset)[0], offset, atol=2e-3)
    g, b = env.evaluate(LAM)
    np.testing.assert_allclose(g, env.gain, rtol=1e-10)
    np.testing.assert_allclose(b, env.offset, rtol=1e-10, atol=1e-12)
    # the estimated noise is blue-heavy, as the true one
    est = np.asarray(env.sigma)[0]
    assert est[:20].mean() > 2.0 * est[-200:].mean()
    assert res.stderr["thickness"] < MARGIN_NM[d]
    assert "envelope" in res.to_dict()


def test_second_raw_fit_of_the_same_shapes_neither_traces_nor_compiles():
    """A second spectrum of the same length (other data, same options) reuses the compiled
    fit: no jaxpr is traced and XLA compiles nothing (`jax.monitoring`'s trace and compile
    events; a data-dependent Python value among the jit's static arguments would retrace
    every spectrum, about 25 s on a 2-core CPU)."""
    import jax.monitoring as monitoring

    events = ("/jax/core/compile/jaxpr_trace_duration",
              "/jax/core/compile/backend_compile_duration")
    seen = []

    def listen(event, seconds, **_):
        if event in events:
            seen.append(event)

    def fit(seed):
        obs, _, _, _ = raw_signal(3000.0, seed=seed)
        res = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0),
                              envelope=2, options=BOX)
        return float(jax.block_until_ready(res.film.thickness))

    d0 = fit(3)  # (compiled here, or by the tests above: the same shapes and options)
    monitoring.register_event_duration_secs_listener(listen)
    try:
        d1 = fit(4)
    finally:
        monitoring.unregister_event_duration_listener(listen)
    assert seen == []
    assert abs(d0 - 3000.0) < MARGIN_NM[3000.0] and abs(d1 - 3000.0) < MARGIN_NM[3000.0]


def test_thin_film_under_a_quadratic_lamp_is_honestly_uncertain():
    """150 nm under a quadratic lamp fitted with k = 2: the film's one broad fringe trades
    with the lamp's curvature; the standard error says so (7–60 nm over three noise seeds,
    where k = 1 on a linear lamp gives 1.1–1.8 nm), and the fit stays within the fringe
    order (seeds 0–2 gave 150, 127, 181 nm: the linearised error is itself rough on such a
    curved valley, 3.3 standard errors off for seed 1)."""
    obs, _, _, _ = raw_signal(150.0, seed=1)
    res = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=2,
                          options=BOX)
    assert float(res.stderr["thickness"]) > 5.0
    assert abs(float(res.film.thickness) - 150.0) < 50.0


def test_given_sigma_and_background():
    """σ given: used as is (no estimate); a known background: only g is fitted."""
    d = 3000.0
    obs, sigma, lamp, offset = raw_signal(d, seed=1)
    res = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=2,
                          sigma=sigma, options=BOX)
    assert abs(float(res.film.thickness) - d) < MARGIN_NM[d]
    assert not res.envelope.sigma_estimated
    np.testing.assert_allclose(np.asarray(res.envelope.sigma)[0], sigma, rtol=1e-12)
    assert 0.7 < float(res.reduced_chi2) < 1.3  # the model explains the data within σ
    res_b = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=2,
                            sigma=sigma, background=offset, options=BOX)
    assert abs(float(res_b.film.thickness) - d) < MARGIN_NM[d]
    assert res_b.envelope.n_linear == 3 and not res_b.envelope.offset_fitted
    np.testing.assert_allclose(np.asarray(res_b.envelope.offset)[0], offset)


def test_linear_solve_is_numpy_lstsq():
    rng = np.random.default_rng(3)
    lam = np.linspace(400.0, 800.0, 57)
    basis, _, _ = envelope_basis(lam, 2)
    refl = rng.uniform(0.0, 0.2, (2, lam.size))
    gain = 1.0 + (lam - 400.0) / 200.0  # positive: the free solution is kept
    obs = gain * refl + 0.1 + rng.normal(0.0, 0.01, (2, lam.size))
    w = rng.uniform(0.5, 2.0, (2, lam.size))
    r, u = project(jnp.asarray(refl), jnp.asarray(obs), jnp.asarray(w), jnp.asarray(basis))
    for a in range(2):
        design = np.concatenate([refl[a, :, None] * basis, basis], axis=1) * w[a, :, None]
        ref, *_ = np.linalg.lstsq(design, w[a] * obs[a], rcond=None)
        np.testing.assert_allclose(np.asarray(u[a]), ref, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(np.asarray(r[a]), design @ ref - w[a] * obs[a], atol=1e-9)
    # monomials λ^j instead of Legendre P_j(t): the same space, the same residual
    mono = np.vander(lam, 3, increasing=True)
    design = np.concatenate([refl[0, :, None] * mono, mono], axis=1) * w[0, :, None]
    ref, *_ = np.linalg.lstsq(design, w[0] * obs[0], rcond=None)
    np.testing.assert_allclose(np.asarray(r[0]), design @ ref - w[0] * obs[0], atol=1e-7)


def _projection_case(theta):
    """A design that moves with θ (fringes shifting in phase) under random weights: numpy."""
    lam = np.linspace(400.0, 800.0, 57)
    basis, _, _ = envelope_basis(lam, 2)
    rng = np.random.default_rng(5)
    w = rng.uniform(0.5, 2.0, lam.size)
    obs = (1.0 + lam / 400.0) * (0.05 + 0.04 * np.sin(lam / 25.0 + 0.3)) + 0.1 \
        + rng.normal(0.0, 0.01, lam.size)
    refl = 0.05 + 0.04 * np.sin(lam / 25.0 + theta)
    return basis, w, obs, refl


def _numpy_projected_residual(theta):
    basis, w, obs, refl = _projection_case(theta)
    design = np.concatenate([refl[:, None] * basis, basis], axis=1) * w[:, None]
    u, *_ = np.linalg.lstsq(design, w * obs, rcond=None)
    return design @ u - w * obs


def test_projection_derivatives_are_the_least_squares_ones():
    """The projected residual's derivatives (the custom JVP of the ridge solve, module
    docstring "Derivatives"): forward and reverse mode in the film parameter against central
    differences of `numpy.linalg.lstsq`, in the observations against the closed form
    ∂r/∂o = (B B⁺ − I) W (numpy's pinv), and the second derivative of ½‖r‖² (what the
    implicit derivatives of the fit use) against a second difference."""
    basis, w, obs, _ = _projection_case(0.0)
    lam = jnp.asarray(np.linspace(400.0, 800.0, 57))

    def solve(theta, o=jnp.asarray(obs)):
        refl = 0.05 + 0.04 * jnp.sin(lam / 25.0 + theta)
        r, u = project(refl[None], o[None], jnp.asarray(w)[None], jnp.asarray(basis))
        return r[0], u[0]

    def r_of(theta, o=jnp.asarray(obs)):
        return solve(theta, o)[0]

    theta, h = 0.7, 1e-5
    assert np.min(basis @ np.asarray(solve(theta)[1][:3])) > 0  # the free solution is kept
    fd = (_numpy_projected_residual(theta + h) - _numpy_projected_residual(theta - h)) / (2 * h)
    scale = np.max(np.abs(fd))
    np.testing.assert_allclose(np.asarray(jax.jacfwd(r_of)(theta)), fd, atol=1e-7 * scale)
    np.testing.assert_allclose(np.asarray(jax.jacrev(r_of)(theta)), fd, atol=1e-7 * scale)
    _, _, _, refl = _projection_case(theta)
    design = np.concatenate([refl[:, None] * basis, basis], axis=1) * w[:, None]
    closed = (design @ np.linalg.pinv(design) - np.eye(w.size)) * w[None, :]
    np.testing.assert_allclose(np.asarray(jax.jacfwd(lambda o: r_of(theta, o))(
        jnp.asarray(obs))), closed, atol=1e-9)

    def loss_np(t):
        return 0.5 * np.sum(_numpy_projected_residual(t) ** 2)

    h2 = 1e-3
    second = (loss_np(theta + h2) - 2.0 * loss_np(theta) + loss_np(theta - h2)) / h2 ** 2
    hess = jax.hessian(lambda t: 0.5 * jnp.sum(r_of(t) ** 2))(theta)
    assert float(hess) == pytest.approx(second, rel=1e-5)


def test_negative_gain_falls_back_to_the_offset():
    """A signal that falls where R rises asks for g < 0: not a lamp; the envelope is the
    offset alone (its lstsq), g = 0."""
    lam = np.linspace(400.0, 800.0, 41)
    basis, _, _ = envelope_basis(lam, 1)
    refl = (0.05 + 0.04 * np.sin(lam / 30.0))[None]  # fringes: g is determined (= −3)
    obs = 1.0 - 3.0 * refl
    r, u = project(jnp.asarray(refl), jnp.asarray(obs), jnp.ones_like(jnp.asarray(obs)),
                   jnp.asarray(basis))
    ref, *_ = np.linalg.lstsq(basis, obs[0], rcond=None)
    np.testing.assert_allclose(np.asarray(u[0]), np.concatenate([[0.0, 0.0], ref]), atol=1e-9)
    np.testing.assert_allclose(np.asarray(r[0]), basis @ ref - obs[0], atol=1e-9)


def test_projection_is_finite_where_the_design_is_rank_deficient():
    """d = 0 on air | water | air: R ≡ 0, the gain columns vanish; value and derivative
    stay finite (a zero column, double where)."""
    lam = jnp.asarray(LAM[::10])
    basis = jnp.asarray(envelope_basis(LAM[::10], 1)[0])
    obs = jnp.ones((1, lam.size)) + 0.01 * jnp.sin(lam)[None]

    def loss(d):
        refl = spectrum_model(tf.Film(d, N_SOAP, 1.0), jnp.ones(1), lam)
        r, _ = project(refl, obs, jnp.ones_like(obs), basis)
        return jnp.sum(r * r)

    for d in (0.0, 1e-6, 200.0):
        v, g = jax.value_and_grad(loss)(jnp.asarray(d))
        assert np.isfinite(float(v)) and np.isfinite(float(g))


def test_variable_projection_equals_the_joint_fit():
    """The eliminated fit's thickness and standard error equal those of the joint
    least-squares fit over (d, g, b) (scipy), whose covariance is the full Jacobian's."""
    from scipy.optimize import least_squares

    d0 = 3000.0
    obs, sigma, _, _ = raw_signal(d0, seed=2)
    res = tf.fit_spectrum(obs, LAM, 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=2,
                          sigma=sigma, options=BOX)
    d_vp = float(res.film.thickness)
    basis, _, _ = envelope_basis(LAM, 2)
    u0 = np.concatenate([np.asarray(res.envelope.gain_coefficients[0]),
                         np.asarray(res.envelope.offset_coefficients[0])])

    def resid(p):
        refl = tmm_reflectance(p[0], LAM)
        return ((refl * (basis @ p[1:4]) + basis @ p[4:]) - obs) / sigma

    joint = least_squares(resid, np.concatenate([[d_vp + 0.5], u0 * 1.01]), x_scale="jac",
                          xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert abs(joint.x[0] - d_vp) < 0.01
    jac = joint.jac
    cov = np.linalg.inv(jac.T @ jac) * np.sum(joint.fun ** 2) / (obs.size - 7)
    assert float(res.stderr["thickness"]) == pytest.approx(np.sqrt(cov[0, 0]), rel=0.02)
    # and Σr² at the optimum: the profile's minimum is the joint minimum
    assert 2.0 * float(res.loss) == pytest.approx(np.sum(joint.fun ** 2), rel=1e-6)


def test_absolute_path_unchanged():
    lam = np.linspace(400.0, 800.0, 81)
    obs = np.asarray(tf.airy_reflectance(tf.Film(812.0, 1.46, 3.9, 0.02), 1.0, lam))
    res = tf.fit_spectrum(obs, lam, 1.0, initial=tf.Film(400.0, 1.46, 3.9, 0.02))
    assert res.envelope is None and "envelope" not in res.to_dict()
    assert float(res.film.thickness) == pytest.approx(812.0, abs=1e-6)


@pytest.mark.parametrize("kw, word", [
    ({"envelope": -1}, "envelope"), ({"envelope": 1.5}, "envelope"),
    ({"envelope": True}, "envelope"), ({"background": 0.1}, "background"),
    ({"envelope": 0, "background": [0.1, 0.2]}, "background"),
    ({"envelope": 0, "background": np.nan}, "background"),
])
def test_bad_envelope_arguments(kw, word):
    lam = np.linspace(400.0, 800.0, 20)
    with pytest.raises(ValueError, match=word):
        tf.fit_spectrum(np.ones(20), lam, 1.0, initial=tf.Film(300.0, 1.33, 1.0), **kw)


def test_too_few_points_for_the_envelope():
    lam = np.linspace(400.0, 800.0, 6)
    with pytest.raises(ValueError, match="envelope"):
        tf.fit_spectrum(np.ones(6), lam, 1.0, initial=tf.Film(300.0, 1.33, 1.0), envelope=2)


def test_sigma_estimate_follows_the_noise():
    rng = np.random.default_rng(5)
    s = np.where(np.arange(400) < 100, 4.0, 1.0)
    est = np.asarray(estimate_sigma(jnp.asarray(rng.normal(0.0, s)[None])))[0]
    assert est[30:70].mean() == pytest.approx(4.0, rel=0.2)
    assert est[200:].mean() == pytest.approx(1.0, rel=0.2)


# ----------------------------------------------------------------------------- real spectra
@pytest.mark.parametrize("name", ["042855.xy", "072523.xy"])
def test_optifik_spectrum_within_ten_percent(name):
    """Two of manue_sample3's spectra (labels 1604 and 425 nm) divided by the set reference
    (the median of the series' normalised spectra: benchmarks.raw_spectra), 450–900 nm."""
    import yaml

    folder = REAL / "manue_sample3"
    if not folder.is_dir():
        pytest.skip(f"{folder} absent (the optifik spectra, shared/real)")
    labels = yaml.safe_load(open(folder / "labels.yaml"))["known_thicknesses"]
    spectra = [read_spectrum(folder / f, nonfinite="drop") for f in sorted(labels)]
    lam = spectra[0][0]
    m = (lam >= 450.0) & (lam <= 900.0)
    stack = np.stack([v[m] for _, v in spectra])
    ref = np.median(stack / stack.mean(axis=1, keepdims=True), axis=0)
    obs = stack[sorted(labels).index(name)] / ref
    res = tf.fit_spectrum(obs, lam[m], 1.0, initial=tf.Film(1000.0, N_SOAP, 1.0), envelope=1,
                          options=BOX)
    assert float(res.film.thickness) == pytest.approx(labels[name], rel=0.10)


# ----------------------------------------------------------------------------- read_spectrum
def _write(tmp_path, text, name="s.txt"):
    p = tmp_path / name
    p.write_text(text)
    return p


PAIRS = [(500.0 + i, 10.0 + i) for i in range(8)]


@pytest.mark.parametrize("sep", [",", "\t", "   ", ";"])
def test_read_two_columns(tmp_path, sep):
    text = f"wavelength{sep}counts\n# a comment\n" + "".join(
        f"{a}{sep}{b}\n" for a, b in PAIRS)
    lam, val = read_spectrum(_write(tmp_path, text))
    np.testing.assert_array_equal(lam, [a for a, _ in PAIRS])
    np.testing.assert_array_equal(val, [b for _, b in PAIRS])


@pytest.mark.parametrize("marker", [">>>>>Begin Spectral Data<<<<<",
                                    ">>>>>Begin Processed Spectral Data<<<<<"])
def test_read_oceanview_export(tmp_path, marker):
    header = ("Data from spectrum.txt Node\n\nDate: Mon Jan 01 12:00:00 CET 2024\n"
              "User: lab\nSpectrometer: USB4F00001\nIntegration Time (sec): 1.000000E-1\n"
              "Scans to average: 10\nNumber of Pixels in Spectrum: 8\n")
    text = header + marker + "\n" + "".join(f"{a:.3f}\t{b:.2f}\n" for a, b in PAIRS) \
        + ">>>>>End Spectral Data<<<<<\n"
    lam, val = read_spectrum(_write(tmp_path, text))
    np.testing.assert_array_equal(lam, [a for a, _ in PAIRS])
    np.testing.assert_array_equal(val, [b for _, b in PAIRS])


def test_read_nonfinite(tmp_path):
    text = "382,NaN\n" + "".join(f"{a},{b}\n" for a, b in PAIRS)
    p = _write(tmp_path, text, "s.xy")
    with pytest.raises(ValueError, match=r"values.*line 1"):
        read_spectrum(p)
    lam, _ = read_spectrum(p, nonfinite="drop")
    assert lam.size == len(PAIRS)


@pytest.mark.parametrize("rows, word", [
    ([(-1.0, 1.0)] + PAIRS, "wavelength"),
    ([PAIRS[1]] + PAIRS[1:], "wavelength"),          # repeated wavelength
    (PAIRS[::-1], "wavelength"),                     # decreasing
    (PAIRS[:3], "values"),                           # too few points
])
def test_read_bad_spectra(tmp_path, rows, word):
    text = "".join(f"{a},{b}\n" for a, b in rows)
    with pytest.raises(ValueError, match=word):
        read_spectrum(_write(tmp_path, text))


def test_read_garbage(tmp_path):
    with pytest.raises(ValueError, match="path"):
        read_spectrum(_write(tmp_path, "no numbers here\n"))
    with pytest.raises(ValueError, match="line 3"):
        read_spectrum(_write(tmp_path, "500,1\n501,2\noops\n502,3\n"))
    with pytest.raises(ValueError, match="path"):
        read_spectrum(tmp_path / "absent.txt")
    with pytest.raises(ValueError, match="nonfinite"):
        read_spectrum(_write(tmp_path, "500,1\n"), nonfinite="keep")
