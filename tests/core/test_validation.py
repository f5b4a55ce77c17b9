"""Bad input at the public boundary raises ValueError/TypeError naming the argument (SPEC §8).

Checks run on concrete values; inside jax.jit they are skipped by design (see _validate.py).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.core._validate import checking

FILM = tf.Film(500.0, 1.4, 1.8, 0.3)


def airy(film=FILM, cos_theta=0.5, wavelength=550.0, **kw):
    return tf.airy_reflectance(film, cos_theta, wavelength, **kw)


def rgb(film=FILM, cos_theta=0.5, **kw):
    return tf.rgb_reflectance(film, cos_theta, **kw)


BAD_FILMS = [  # (field, bad value, words the message must contain)
    ("thickness", -1.0, "film.thickness"),
    ("thickness", np.array([100.0, -1e-9]), "film.thickness"),
    ("thickness", np.inf, "film.thickness"),
    ("eta_film", 0.9, "film.eta_film"),
    ("eta_outer", 0.5, "film.eta_outer"),
    ("eta_base", 0.0, "film.eta_base"),
    ("kappa_base", -0.1, "film.kappa_base"),
] + [(field, np.nan, f"film.{field}") for field in tf.Film._fields] \
  + [(field, np.array([1.5, np.nan]), f"film.{field}") for field in tf.Film._fields]


@pytest.mark.parametrize("field, value, words", BAD_FILMS)
@pytest.mark.parametrize("fn", [airy, rgb], ids=["airy", "rgb"])
def test_bad_film_field(fn, field, value, words):
    with pytest.raises(ValueError, match=words.replace(".", r"\.")):
        fn(film=FILM._replace(**{field: value}))


@pytest.mark.parametrize("value", [np.nan, 1.0 + 1e-9, -1e-9, np.array([0.5, np.nan]),
                                   np.array([0.2, 1.5])])
@pytest.mark.parametrize("fn", [airy, rgb], ids=["airy", "rgb"])
def test_bad_cos_theta(fn, value):
    with pytest.raises(ValueError, match="cos_theta"):
        fn(cos_theta=value)


@pytest.mark.parametrize("value", [0.0, -550.0, np.nan, np.array([550.0, 0.0])])
def test_bad_wavelength(value):
    with pytest.raises(ValueError, match="wavelength"):
        airy(wavelength=value)


def test_not_a_film():
    with pytest.raises(TypeError, match="film"):
        airy(film=(500.0, 1.4, 1.8))
    with pytest.raises(TypeError, match="film"):
        rgb(film={"thickness": 500.0})


@pytest.mark.parametrize("kw, words", [
    (dict(observer="cie_1964_10"), "observer"),
    (dict(observer="CIE 1931 2 Degree Standard Observer"), "observer"),  # the long name is not one
    (dict(method="fast"), "method"),
    (dict(method="fourier", terms=-1), "terms"),
    (dict(method="fourier", terms=2.5), "terms"),
    (dict(method="fourier", shat="lut"), "shat"),
    (dict(arithmetic="metal"), "arithmetic"),
])
def test_bad_options(kw, words):
    with pytest.raises(ValueError, match=words):
        rgb(**kw)


def test_bad_options_elsewhere():
    with pytest.raises(ValueError, match="arithmetic"):
        airy(arithmetic="metal")
    with pytest.raises(ValueError, match="observer"):
        tf.get_observer("nope")
    with pytest.raises(ValueError, match="observer"):
        tf.sensitivity_ft(0.0, "nope")
    with pytest.raises(ValueError, match="shat"):
        tf.sensitivity_ft(0.0, shat="nope")


def test_incompatible_shapes():
    film3 = FILM._replace(thickness=np.full(3, 500.0))
    with pytest.raises(ValueError, match=r"film \(3,\).*cos_theta \(4,\)"):
        rgb(film=film3, cos_theta=np.full(4, 0.5))
    with pytest.raises(ValueError, match=r"film.*\(3,\).*cos_theta.*\(4,\)"):
        airy(film=film3, cos_theta=np.full(4, 0.5))
    with pytest.raises(ValueError, match=r"wavelength.*\(4,\)"):
        airy(film=film3, wavelength=np.full(4, 550.0))
    with pytest.raises(ValueError, match=r"film\.thickness \(3,\).*film\.eta_film \(2,\)"):
        airy(film=film3._replace(eta_film=np.full(2, 1.3)))


def test_valid_edge_inputs_are_accepted():
    """The closed ends of the domain are valid: d = 0, cos θ ∈ {0, 1}, κ = 0, η = 1, and any
    integer type for `terms` (also NumPy integers)."""
    film = tf.Film(0.0, 1.0, 1.0 + 1e-12, 0.0, 1.0)
    for c in (0.0, 1.0):
        assert np.isfinite(float(airy(film=film, cos_theta=c)))
        assert np.all(np.isfinite(np.asarray(rgb(film=film, cos_theta=c))))
    a = rgb(method="fourier", terms=np.int64(2))
    np.testing.assert_array_equal(a, rgb(method="fourier", terms=2))
    assert rgb(method="fourier", terms=0).shape == (3,)


def test_checks_are_skipped_under_jit_and_errors_not_raised_on_tracers():
    """Documented behaviour: validation needs concrete values; under jit nothing is raised."""
    f = jax.jit(lambda d: tf.airy_reflectance(FILM._replace(thickness=d), 0.5, 550.0))
    assert np.isfinite(float(f(jnp.asarray(500.0))))
    # the un-jitted call with the same bad value raises
    with pytest.raises(ValueError, match="thickness"):
        tf.airy_reflectance(FILM._replace(thickness=-5.0), 0.5, 550.0)


# ------------------------------------------------------------------- input checks at the public boundary
def _airy_numpy(d, n2, n3, cos1, lam, n1=1.0):
    """Independent textbook Airy sum (complex Snell, s and p) in NumPy complex128."""
    s2 = (n1 * n1) * (1.0 - cos1 * cos1)
    q1 = n1 * cos1
    q2 = np.sqrt(complex(n2 * n2 - s2))
    q3 = np.sqrt(n3 * n3 - s2)
    q3 = q3 if q3.imag >= 0 else -q3
    rs12, rs23 = (q1 - q2) / (q1 + q2), (q2 - q3) / (q2 + q3)
    rp12 = (n2**2 * q1 - n1**2 * q2) / (n2**2 * q1 + n1**2 * q2)
    rp23 = (n3**2 * q2 - n2**2 * q3) / (n3**2 * q2 + n2**2 * q3)
    e = np.exp(2j * (2 * np.pi * d * q2 / lam))
    r = [(a + b * e) / (1 + a * b * e) for a, b in ((rs12, rs23), (rp12, rp23))]
    return 0.5 * (abs(r[0]) ** 2 + abs(r[1]) ** 2)


def test_complex_eta_base_is_eta_plus_i_kappa():
    """Film(600, 1.3, 2.0 + 0.5j) is the base 2.0 + 0.5i (it used to drop κ: 0.0857)."""
    exact = _airy_numpy(600.0, 1.3, 2.0 + 0.5j, 0.6, 550.0)
    assert abs(exact - 0.0835274069) < 1e-9
    r_c = float(tf.airy_reflectance(tf.Film(600.0, 1.3, 2.0 + 0.5j), 0.6, 550.0))
    r_k = float(tf.airy_reflectance(tf.Film(600.0, 1.3, 2.0, 0.5), 0.6, 550.0))
    assert abs(r_c - r_k) <= 1e-12 and abs(r_c - exact) <= 1e-12
    # arrays, NumPy complex, split κ (complex part adds to kappa_base), every entry point
    eta = np.array([2.0 + 0.5j, 1.5 + 0.0j, 3.0 + 2.0j])
    split = tf.Film(600.0, 1.3, np.real(eta), np.imag(eta))
    cplx = tf.Film(600.0, 1.3, eta)
    half = tf.Film(600.0, 1.3, np.real(eta) + 0.5j * np.imag(eta), 0.5 * np.imag(eta))
    c = np.array([0.6, 0.9, 0.2])
    for f in (cplx, half):
        np.testing.assert_allclose(tf.airy_reflectance(f, c, 550.0),
                                   tf.airy_reflectance(split, c, 550.0), rtol=0, atol=1e-12)
        for m in ("spectral", "fourier"):
            np.testing.assert_allclose(rgb(film=f, cos_theta=c, method=m),
                                       rgb(film=split, cos_theta=c, method=m), atol=1e-12)
    np.testing.assert_allclose(
        tf.patch_radiance(cplx, 0.4, 0.3, method="ideal"),
        tf.patch_radiance(split, 0.4, 0.3, method="ideal"), atol=1e-12)
    assert cplx.real_base().kappa_base.tolist() == [0.5, 0.0, 2.0]
    f32 = tf.Film(600.0, 1.3, 2.0 + 0.5j).astype(jnp.float32)  # keeps κ, real fields
    assert f32.eta_base.dtype == jnp.float32 and float(f32.kappa_base) == 0.5


def test_complex_eta_base_sign_convention_and_other_complex_fields():
    with pytest.raises(ValueError, match=r"film\.kappa_base must lie in \[0\.0, inf\].*n \+ ik"):
        airy(film=tf.Film(600.0, 1.3, 2.0 - 0.5j))  # the n − ik convention is not ours
    with pytest.raises(TypeError, match="film.eta_film must be real"):
        airy(film=tf.Film(600.0, 1.3 + 0.1j, 2.0))
    with pytest.raises(TypeError, match="cos_theta must be real"):
        airy(cos_theta=0.5 + 0.1j)


def test_dielectric_base_with_absorption_is_rejected():
    """arithmetic='real' cannot represent κ₃ > 0 (it used to return 0.0889 for 0.0835)."""
    film = tf.Film(600.0, 1.3, 2.0, 0.5)
    for fn in (airy, rgb):
        with pytest.raises(ValueError, match=r"arithmetic='real' needs kappa_base = 0.*0\.5"):
            fn(film=film, arithmetic="real")
    with pytest.raises(ValueError, match="kappa_base = 0"):
        tf.patch_radiance(film, 0.3, 0.3, method="ideal",
                          options=tf.ModelOptions(arithmetic="real"))
    with pytest.raises(ValueError, match="kappa_base = 0"):
        tf.series_terms(film, 0.5, arithmetic="real")
    lossless = film._replace(kappa_base=0.0)
    assert abs(float(airy(film=lossless, arithmetic="real"))
               - float(airy(film=lossless, arithmetic="complex"))) < 1e-13


def test_python_lists_are_arrays():
    ref = np.asarray(tf.airy_reflectance(tf.Film(np.array([500.0, 600.0]), 1.3, 2.0),
                                         np.array([0.5, 0.6]), 550.0))
    got = tf.airy_reflectance(tf.Film([500.0, 600.0], 1.3, 2.0), [0.5, 0.6], 550.0)
    np.testing.assert_array_equal(got, ref)
    assert rgb(film=tf.Film([500.0, 600.0], 1.3, 2.0), cos_theta=[0.5, 0.6]).shape == (2, 3)
    assert tf.patch_radiance(FILM, [0.2, 0.5], 0.3, method="ideal").shape == (2, 3)
    assert tf.albedo([0.2, 0.5], [0.3, 0.4], quadrature=(8, 8)).shape == (2,)
    with pytest.raises(TypeError, match="cos_theta must be a number or a rectangular array"):
        airy(cos_theta=[0.5, [0.6, 0.7]])
    with pytest.raises(TypeError, match="film.thickness must be a number"):
        airy(film=tf.Film(["thick"], 1.3, 2.0))
    with pytest.raises(TypeError, match="wavelength must be a number"):
        airy(wavelength="550")
    with pytest.raises(TypeError, match="theta_o must be a number"):
        tf.patch_radiance(FILM, None, 0.3)


def test_float32_rounding_at_the_ends_is_clamped_not_rejected():
    """float32 cos(π/2) = −4.4e-8: a rounding, clamped to 0; a real negative still raises."""
    c = np.cos(np.float32(np.pi / 2))
    assert np.float32(-1e-7) < c < 0
    f32 = FILM.astype(jnp.float32)
    r = tf.airy_reflectance(f32, c, np.float32(550.0))
    assert r.dtype == jnp.float32
    assert float(r) == float(tf.airy_reflectance(f32, np.float32(0.0), np.float32(550.0)))
    np.testing.assert_array_equal(rgb(film=f32, cos_theta=jnp.asarray([c, 0.5], jnp.float32)),
                                  rgb(film=f32, cos_theta=jnp.asarray([0.0, 0.5], jnp.float32)))
    assert float(tf.airy_reflectance(f32, np.float32(1.0) + np.float32(1.2e-7), 550.0)) > 0
    for bad in (np.float32(-1e-5), np.float32(1.0 + 1e-5), -1e-12):  # float64 ulp is 2e-16
        with pytest.raises(ValueError, match="cos_theta must lie in"):
            tf.airy_reflectance(f32, bad, 550.0)
    # θ_o = float32(π/2) lies 4.4e-8 above π/2: accepted
    assert tf.patch_radiance(f32, np.float32(np.pi / 2), np.float32(0.3),
                             method="ideal").shape == (3,)
    with pytest.raises(ValueError, match="theta_o must lie in"):
        tf.patch_radiance(f32, np.float32(1.5708), np.float32(0.3), method="ideal")


@pytest.mark.parametrize("call, err, words", [
    (lambda: tf.patch_radiance_mc(FILM, 0.3, 0.3, jax.random.PRNGKey(0), n_samples=0),
     ValueError, "n_samples must be an int >= 2"),
    (lambda: tf.patch_radiance_mc(FILM, 0.3, 0.3, jax.random.PRNGKey(0), n_samples=1),
     ValueError, "n_samples must be an int >= 2"),
    (lambda: tf.patch_radiance_mc(FILM, [0.3, 0.4], 0.3, jax.random.PRNGKey(0)),
     ValueError, "must be scalars"),
    (lambda: tf.patch_radiance(FILM, 0.3, 0.3, options=tf.ModelOptions(quadrature=(0, 8))),
     ValueError, "quadrature"),
    (lambda: tf.patch_radiance(FILM, 0.3, 0.3, options=tf.ModelOptions(quadrature=8)),
     ValueError, "quadrature"),
    (lambda: tf.patch_radiance(FILM, 0.3, 0.3, options=(2, "exact")), TypeError, "ModelOptions"),
    (lambda: tf.patch_radiance(FILM, 0.3, 0.3, batch_size=0), ValueError, "batch_size"),
    # the materials' exact map paths share one rule (`ibl_reference.exact_rule`): a zero
    # batch was clamped to 1 silently on the classic-lobe path (and lists of numbers for
    # the directions were refused there with a dtype error)
    (lambda: tf.envmap_radiance(tf.Material(tf.ggx_lobe(0.3), tf.schlick_fresnel(0.04),
                                            tf.no_diffuse()), None, [0.0, 0.0, 1.0],
                                [0.0, 0.0, 1.0], np.ones((4, 8, 3)), batch_size=0),
     ValueError, "batch_size"),
    (lambda: tf.patch_radiance(FILM, 0.3, 0.3, method="ideal",
                               options=tf.ModelOptions(terms=np.int64(-1))),
     ValueError, "terms"),
    (lambda: tf.albedo(0.3, 0.3, quadrature=(0, 8)), ValueError, r"quadrature.*n_u >= 1"),
    (lambda: tf.albedo(0.3, 0.3, quadrature=(8, 1)), ValueError, r"n_phi >= 2"),
    (lambda: tf.albedo(0.3, 0.3, quadrature=(8.5, 8)), ValueError, "quadrature"),
    (lambda: tf.albedo(2.0, 0.3), ValueError, r"theta_o must lie in \[0.0, 1.57"),
    (lambda: tf.albedo(0.3, 0.0), ValueError, r"alpha must lie in \(0.0, 1.0\]"),
    (lambda: tf.albedo(0.3, 0.3, ndf="phong"), ValueError, "ndf"),
    (lambda: tf.series_terms(FILM, 1.5), ValueError, "cos_theta must lie in"),
    (lambda: tf.series_terms(FILM._replace(thickness=-1.0), 0.5), ValueError, "film.thickness"),
    (lambda: tf.series_terms(FILM, 0.5, arithmetic="auto"), ValueError, "arithmetic"),
    (lambda: tf.taylor_opd_moments(FILM, 1.5, 0.1), ValueError, "mu_c must lie in"),
    (lambda: tf.taylor_opd_moments(FILM, 0.5, -0.1), ValueError, "var_c must lie in"),
    (lambda: tf.sensitivity_ft(np.nan), ValueError, "x must be finite"),
    (lambda: tf.sensitivity_ft(100.0, sigma2=-1.0), ValueError, "sigma2 must lie in"),
    (lambda: tf.build_shat_lut(d_mu=0.0), ValueError, "d_mu must lie in"),
    (lambda: tf.build_shat_lut(n_sigma=1), ValueError, "n_sigma must be an int >= 2"),
    (lambda: tf.build_shat_lut(sigma_max=-5.0), ValueError, "sigma_max must lie in"),
    (lambda: tf.build_shat_lut("cie_1964"), ValueError, "observer"),
])
def test_sizes_orders_and_ranges_are_checked(call, err, words):
    with pytest.raises(err, match=words):
        call()


def test_fit_film_rejects_negative_radiances():
    """Radiances are ≥ 0: a negative one is a data error, not a fit that "converges"."""
    theta = np.linspace(0.0, 1.2, 4)
    obs = np.full((4, 3), 0.1)
    obs[2, 1] = -0.05
    with pytest.raises(ValueError, match=r"observed must lie in \[0.0, inf\].*-0.05"):
        tf.fit_film(obs, theta, alpha=0.3, initial=tf.Film(400.0, 1.3, 2.0, 0.5))
    with pytest.raises(ValueError, match=r"initial\.kappa_base"):
        tf.fit_film(np.abs(obs), theta, alpha=0.3, initial=tf.Film(400.0, 1.3, 2.0, -0.5))


# ----------------------------------------------------------------- traced inputs: checked
def _r_of_kappa(k):
    return tf.airy_reflectance(tf.Film(600.0, 1.3, 2.0, k), 0.6, 550.0)


def test_unchecked_jit_is_documented_garbage():
    """Without `checked`, nothing is checked under jit: κ < 0 gives R > 1 (README)."""
    assert float(jax.jit(_r_of_kappa)(-0.5)) > 1.0


def test_checked_raises_under_jit_vmap_and_grad():
    f = jax.jit(tf.checked(_r_of_kappa))
    assert float(f(0.5)) == pytest.approx(0.0835274069, abs=1e-9)
    with pytest.raises(Exception, match=r"film\.kappa_base must lie in \[0\.0, inf\]"):
        jax.block_until_ready(f(-0.5))
    g = jax.jit(tf.checked(lambda c: rgb(film=FILM, cos_theta=c)))
    np.testing.assert_allclose(g(jnp.asarray([0.2, 0.7])), rgb(cos_theta=np.array([0.2, 0.7])),
                               atol=1e-12)
    with pytest.raises(Exception, match="cos_theta must lie in"):
        jax.block_until_ready(g(jnp.asarray([0.2, 1.5])))
    with pytest.raises(Exception, match="cos_theta must lie in"):
        jax.block_until_ready(g(jnp.asarray([0.2, jnp.nan])))
    gv = jax.vmap(tf.checked(_r_of_kappa))
    assert gv(jnp.asarray([0.5, 0.2])).shape == (2,)
    with pytest.raises(Exception, match="film.kappa_base"):
        jax.block_until_ready(gv(jnp.asarray([0.5, -0.2])))
    gg = jax.grad(tf.checked(_r_of_kappa))
    assert float(gg(0.5)) == pytest.approx(float(jax.grad(_r_of_kappa)(0.5)), abs=1e-12)
    h = jax.jit(tf.checked(lambda t, a: tf.patch_radiance(FILM, t, a, method="ideal")))
    with pytest.raises(Exception, match="alpha must lie in"):
        jax.block_until_ready(h(0.3, 1.5))
    with pytest.raises(Exception, match="theta_o must lie in"):
        jax.block_until_ready(h(-0.3, 0.5))


def test_checked_as_a_context():
    with tf.checked():
        f = jax.jit(lambda k: _r_of_kappa(k) * 1.0)
        with pytest.raises(Exception, match="film.kappa_base"):
            jax.block_until_ready(f(-0.5))
        assert checking()
    assert not checking()
    with pytest.raises(TypeError, match="checked"):
        tf.checked(3)


# ------------------------------------------------------- documented limitations (README)
def test_tir_limitation_numbers():
    """README "Conventions and documented limitations": under TIR at 1|2 the Fourier and
    filtered paths give 1 where the exact band reflectance keeps frustrated transmission."""
    from thinfilm_jax.realtime.filtered import filtered_bands
    from thinfilm_jax.optics.opd import OPDMoments

    d = np.arange(0.0, 3001.0)
    crit = np.rad2deg(np.arcsin(1.2 / 1.5))
    assert crit == pytest.approx(53.13, abs=0.01)
    found = {}
    for theta_deg in (60.0, crit + 1.0):
        film = tf.Film(d, 1.2, 2.0, 0.5, 1.5)
        c = np.full(d.shape, np.cos(np.deg2rad(theta_deg)))
        exact = np.asarray(rgb(film=film, cos_theta=c))
        fourier = np.asarray(rgb(film=film, cos_theta=c, method="fourier"))
        np.testing.assert_allclose(fourier, 1.0, atol=1e-12)
        err = np.abs(fourier - exact).max(axis=1)
        found[theta_deg] = (exact[:, 1], d[err > 1e-2].max(), d[err > 1e-3].max())
    r_g, d01, d001 = found[60.0]
    np.testing.assert_allclose(r_g[[0, 31, 100, 200, 300, 500]],
                               [0.099, 0.15, 0.41, 0.75, 0.91, 0.99], atol=0.006)
    assert d01 == pytest.approx(553, abs=2) and d001 == pytest.approx(779, abs=2)
    r_g, d01, _ = found[crit + 1.0]
    assert d01 == pytest.approx(1139, abs=2) and r_g[889] == pytest.approx(0.98, abs=0.005)
    # the filtered path (K 29 at the mean direction) is the same series: 1 as well
    film = tf.Film(300.0, 1.2, 2.0, 0.5, 1.5)
    fb = filtered_bands(film, np.cos(np.deg2rad(60.0)),
                        OPDMoments(np.asarray(400.0), np.asarray(20.0)), "stiles_burch_1959_10")
    np.testing.assert_allclose(fb, 1.0, atol=1e-12)


def test_stiles_burch_bands_leave_unit_interval():
    """README: the negative lobes let S&B band reflectances leave [0, 1] (by ≤ Σ of the
    negative weights); the worst films of a 4·10⁵-film random search, re-evaluated."""
    w = tf.get_observer().weights
    np.testing.assert_allclose(w.clip(max=0).sum(axis=0), [-0.101, -0.0102, -0.0100], atol=5e-4)
    assert tf.get_observer("cie_1931_2").weights.min() >= 0
    hi = rgb(film=tf.Film(195.29301829655776, 1.1596523653978552, 1.1364467564784333,
                          6.241653847759671), cos_theta=0.00820502284522)
    lo = rgb(film=tf.Film(190.96750780490424, 1.6924986901679104, 1.0253167430639638, 0.0),
             cos_theta=0.805742046677)
    assert 1.0115 < float(hi[0]) < 1.0 - w[:, 0].clip(max=0).sum()
    assert -1.2e-3 < float(lo[0]) < -1.1e-3


def test_out_of_range_materials_are_all_named_by_the_callers_names():
    """A `Film` with index models is checked under its own field names (``initial.eta_film``,
    not the ``initial.eta[0]`` of the one-layer stack it runs as), and every index that does
    not cover the wavelengths is listed, not only the first; a `Stack` lists its layers by
    ``eta[i]`` the same way."""
    lam = np.linspace(150.0, 1100.0, 20)  # water: 182–1129 nm, Si: 250–1450 nm
    water, si, sio2 = (tf.refractive_index(n) for n in ("water", "Si", "SiO2"))
    obs = np.full(lam.shape, 0.1)
    with pytest.raises(ValueError) as e:
        tf.fit_spectrum(obs, lam, 1.0, initial=tf.Film(300.0, water, si))
    msg = str(e.value)
    assert "initial.eta_film (water)" in msg and "initial.eta_base (Si)" in msg
    assert "eta[0]" not in msg and "2 indices" in msg
    with pytest.raises(ValueError) as e:
        tf.fit_spectrum(obs, lam, 1.0, initial=tf.Stack([100.0, 50.0], (water, sio2), si))
    msg = str(e.value)
    assert all(s in msg for s in ("initial.eta[0] (water)", "initial.eta[1] (SiO2)",
                                  "initial.eta_base (Si)"))
    from thinfilm_jax.core._validate import check_material

    with pytest.raises(ValueError, match=r"^film\.eta_film \(water\) is defined on 182"):
        check_material(tf.Film(300.0, water, 1.5), "film", lam)  # one failing: as it was
