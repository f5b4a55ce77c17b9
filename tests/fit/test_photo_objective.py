"""Microscope images in `fit_photo(na=...)` (SPEC §14): graphene flakes on 285 nm of thermal
oxide on silicon, seen through an objective of NA 0.9, counted layer by layer; the colours
come from the objective's cone (`optics.objective`), and a fit that ignores the NA miscounts
(Blake et al. 2007: the contrast depends on the NA)."""

import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.fit.photo import fit_photo, photo_colours, render_photo
from thinfilm_jax.spectral.camera import camera_response

MONO = tf.MONOLAYER_NM["graphene"]
NA = 0.9


def _template():
    return tf.Stack([0.0, 285.0], (tf.refractive_index("graphene"), tf.refractive_index("SiO2")),
                    tf.refractive_index("Si"))


@pytest.fixture(scope="module")
def flake():
    """A 12 × 16 image: bare oxide, then 1, 2, 3 layers in vertical bands, rendered through
    the NA 0.9 objective (linear sRGB, exposure 0.8, noise 0.2 %)."""
    layers = np.repeat(np.arange(4), 4)[None, :].repeat(12, axis=0)
    img = render_photo(_template(), layers * MONO, camera="srgb", exposure=0.8, na=NA)
    img = img + np.random.default_rng(3).normal(0.0, 0.002, img.shape)
    return np.clip(img, 0.0, 1.0), layers


def test_colours_are_the_cone_average():
    """photo_colours(na) equals the camera weights applied to `objective_reflectance` of the
    same stack (an independent path: the public function with its own node count)."""
    cam = camera_response("srgb", "D65")
    d = 2 * MONO
    s = photo_colours(_template(), np.asarray([d]), camera=cam, na=NA)[0]
    st = _template()._replace(thickness=np.asarray([d, 285.0]))
    r = np.asarray(tf.objective_reflectance(st, cam.wavelengths, NA))
    np.testing.assert_allclose(s, r @ cam.weights, rtol=1e-9)
    s0 = photo_colours(_template(), np.asarray([d]), camera=cam)[0]
    assert np.max(np.abs(s - s0)) > 1e-3  # the NA changes the colours


def test_layer_count_with_and_without_the_na(flake):
    """With the NA at least 99 % of the pixels' layer counts are right (measured 191 of 192:
    one pixel lost to the noise); ignoring the NA (normal incidence) the fit puts most of
    the 2- and 3-layer pixels in the wrong count."""
    img, layers = flake
    ref = [(layers == 0, 0.0)]
    kw = dict(camera="srgb", encoding="linear", reference=ref, thickness_range=(0.0, 1.6),
              grid_step_nm=0.005, screen_step_nm=0.02)
    res = fit_photo(img, _template(), na=NA, **kw)
    count = np.rint(np.asarray(res.thickness) / MONO)
    assert np.mean(count == layers) >= 0.99
    res0 = fit_photo(img, _template(), **kw)
    count0 = np.rint(np.asarray(res0.thickness) / MONO)
    assert np.mean(count0[layers >= 2] == layers[layers >= 2]) < 0.5


def test_na_bad_input(flake):
    img, _ = flake
    kw = dict(camera="srgb", encoding="linear", thickness_range=(0.0, 1.6))
    with pytest.raises(ValueError, match="na must lie"):
        fit_photo(img, _template(), na=1.2, **kw)
    with pytest.raises(ValueError, match="na must be"):
        fit_photo(img, _template(), na=-0.1, **kw)
    with pytest.raises(ValueError, match="theta_o=0"):
        fit_photo(img, _template(), na=0.5, theta_o=0.2, **kw)
