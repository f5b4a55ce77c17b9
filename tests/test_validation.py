"""Bad input at the public boundary raises ValueError/TypeError naming the argument (SPEC §8).

Checks run on concrete values; inside jax.jit they are skipped by design (see _validate.py).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import thinfilm_jax as tf

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
    (dict(base="metal"), "base"),
])
def test_bad_options(kw, words):
    with pytest.raises(ValueError, match=words):
        rgb(**kw)


def test_bad_options_elsewhere():
    with pytest.raises(ValueError, match="base"):
        airy(base="metal")
    with pytest.raises(ValueError, match="observer"):
        tf.get_observer("nope")
    with pytest.raises(ValueError, match="observer"):
        tf.sensitivity_ft(0.0, "nope")
    with pytest.raises(ValueError, match="method"):
        tf.sensitivity_ft(0.0, method="nope")


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
