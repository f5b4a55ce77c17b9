"""What a thickness map checks of itself (`fit.map_quality`, SPEC §9 map fits): the noise
level read off the image, the pixels another fringe order explains or the box's bound holds
(flagged `ambiguous`), and `fit_envmap_map`'s choice of map model."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, prefilter_envmap
from thinfilm_jax.fit.map_quality import estimate_noise, order_flags
from thinfilm_jax.fit.options import MisfitWarning
from thinfilm_jax.fit.thickness_map import fit_envmap_map
from thinfilm_jax.shading.ibl import envmap_radiance


def _smooth_image(h=40, w=50):
    y, x = np.mgrid[0:h, 0:w] / 50.0
    base = np.stack([0.3 + 0.2 * x, 0.5 - 0.1 * y, 0.2 + 0.05 * x * y], -1)
    return base


@pytest.mark.parametrize("sigma", [0.003, 0.02])
def test_estimate_noise_recovers_gaussian_noise(sigma):
    """Independent Gaussian noise of level σ on a smooth image: the local-difference MAD
    estimate is σ within 8 % (2,000 pixels × 3 bands: the MAD's relative standard error is
    ≈ 1.7 %; the curvature of this image adds < 1e-4)."""
    clean = _smooth_image()
    noisy = clean + np.random.default_rng(0).normal(0.0, sigma, clean.shape)
    est = estimate_noise(noisy, np.ones(clean.shape[:2], bool))
    assert abs(est / sigma - 1) < 0.08


def test_estimate_noise_ignores_masked_pixels_and_floors():
    """Pixels outside `valid` (a background of other values) do not enter; a noise-free
    linear image (no local difference at all) gives the floor, 1e-3 of the median value."""
    clean = _smooth_image()
    valid = np.zeros(clean.shape[:2], bool)
    valid[5:35, 5:45] = True
    rng = np.random.default_rng(1)
    img = np.where(valid[..., None], clean + rng.normal(0.0, 0.01, clean.shape),
                   rng.uniform(0, 5, clean.shape))
    assert abs(estimate_noise(img, valid) / 0.01 - 1) < 0.1
    y, x = np.mgrid[0:20, 0:20]
    ramp = np.stack([1.0 + x, 2.0 + y, 3.0 + x + y], -1).astype(float)
    floor = 1e-3 * np.median(ramp)
    assert estimate_noise(ramp, np.ones((20, 20), bool)) == pytest.approx(floor)


def test_order_flags_by_hand():
    """Four pixels in a row over a grid with loss minima at 100 and 300 nm (the third not
    fitted): a second order 1 (loss) above the fit is ambiguous (within 2 · max(1, robust
    χ²ᵣ)); 50 above is not; a thickness on the box's bound is flagged whatever its
    alternatives."""
    d_grid = np.linspace(0.0, 400.0, 81)
    well = lambda c, depth: depth + 0.002 * (d_grid - c) ** 2  # noqa: E731
    e_d = np.stack([np.minimum(well(100, 0.5), well(300, 1.5)),
                    np.minimum(well(100, 0.5), well(300, 50.5)),
                    0 * d_grid, well(400, 0.5)])[None]  # (1, 4, G)
    d = np.array([[100.0, 100.0, np.nan, 400.0]])
    loss = np.full((1, 4), 0.5)  # χ² = 1 per pixel: robust χ²ᵣ = 1 / (2 ln 2), J − p = 2
    valid = np.array([[True, True, False, True]])
    amb, alt, at_bound, robust = order_flags(e_d, d_grid, d, loss, valid, (0.0, 400.0), 3, 1)
    assert robust == pytest.approx(1.0 / 1.3862943611198906, rel=1e-6)  # median of χ²₂: 2 ln 2
    np.testing.assert_array_equal(amb, [[True, False, False, True]])
    np.testing.assert_array_equal(at_bound, [[False, False, False, True]])
    np.testing.assert_allclose(alt[0, :2], [300.0, 300.0])


def test_order_flags_unexplained_and_neighbours():
    """A 3 × 3 map at 100 nm whose grid losses have one clear minimum: nothing flagged;
    then the centre's χ² far above the others' (the 99 % point of χ²₂ is 9.2) is flagged, and
    so is a centre 150 nm (about one fringe order) off its neighbours — but not the
    neighbours, whose other neighbours agree with them."""
    d_grid = np.linspace(0.0, 400.0, 81)
    e_d = np.broadcast_to(0.5 + 0.002 * (d_grid - 100.0) ** 2, (3, 3, 81))
    d, loss, valid = np.full((3, 3), 100.0), np.full((3, 3), 0.5), np.ones((3, 3), bool)
    box = (0.0, 400.0)
    assert not order_flags(e_d, d_grid, d, loss, valid, box, 3, 1)[0].any()
    hot = loss.copy()
    hot[1, 1] = 10.0  # χ² = 20 > 9.2
    np.testing.assert_array_equal(order_flags(e_d, d_grid, d, hot, valid, box, 3, 1)[0],
                                  np.eye(3)[::-1] * np.eye(3) > 0)
    off = d.copy()
    off[1, 1] = 250.0
    flags = order_flags(e_d, d_grid, off, loss, valid, box, 3, 1)[0]
    assert flags[1, 1] and flags.sum() == 1


@pytest.fixture(scope="module")
def scene():
    """A 3 × 4 patch of a sphere under a small map with one bright texel row (uneven light,
    where `improved` and `filtered` differ), rendered with `improved`."""
    env = np.full((8, 16, 3), 0.2)
    env[1, 3:6] = [40.0, 30.0, 20.0]
    pref = prefilter_envmap(env, levels=3, resolution=(8, 16), albedo_shape=(8, 5))
    u = np.linspace(-0.5, 0.5, 4)
    v = np.linspace(-0.4, 0.4, 3)
    x, y = np.meshgrid(u, v)
    n = np.stack([x, y, np.sqrt(1 - x ** 2 - y ** 2)], -1)
    view = np.broadcast_to([0.0, 0.0, 1.0], n.shape)
    d = np.linspace(300.0, 420.0, 12).reshape(3, 4)
    img = np.asarray(envmap_radiance(Film(jnp.asarray(d), 1.33, 1.0), 0.2, n, view, pref,
                                     method="improved"))
    return img, n, view, pref, d


def test_fit_envmap_map_model_is_the_chosen_method(scene):
    """`method=` picks the per-pixel model: the model of `method="improved"` at a pixel is
    `envmap_radiance(method="improved")` there (a full `improved` map fit compiles for
    minutes on a 2-core machine: its recovery is measured in the map-fit study instead)."""
    from thinfilm_jax.fit.thickness_map import _envmap_model
    from thinfilm_jax.shading.ibl import REALTIME_OPTIONS

    img, n, view, pref, d = scene
    model = _envmap_model(_observer(), REALTIME_OPTIONS, 0.2,
                          True, "improved")
    x = jnp.asarray([d[1, 2], 1.33])
    ctx = (jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(1.0), pref)
    np.testing.assert_allclose(model(x, (n[1, 2], view[1, 2]), ctx), img[1, 2], rtol=1e-6)


def test_fit_envmap_map_warns_on_the_other_model(scene):
    """An `improved` image fitted with `filtered` (not the model that made it), its noise
    estimated from the image: the misfit test warns (the reduced χ² far above 1), where the
    same fit of a `filtered` image of the same film does not."""
    img, n, view, pref, d = scene
    kw = dict(alpha=0.2, initial=Film(350.0, 1.33, 1.0), bounds={"thickness": (0.0, 800.0)},
              grid=81, method="filtered")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        other = fit_envmap_map(img, n, view, pref, **kw)
    assert other.reduced_chi2 > 30 and other.sigma > 0
    assert any(issubclass(w.category, MisfitWarning) for w in caught)
    same_img = np.asarray(envmap_radiance(Film(jnp.asarray(d), 1.33, 1.0), 0.2, n, view, pref,
                                          method="filtered"))
    same = fit_envmap_map(same_img, n, view, pref, sigma=1e-3, **kw)
    assert np.max(np.abs(np.asarray(same.thickness) - d)) < 0.5
    assert same.reduced_chi2 < 1 and not same.warnings and not np.any(same.ambiguous)


def _observer():
    from thinfilm_jax.spectral.spectra import DEFAULT_OBSERVER

    return DEFAULT_OBSERVER


def test_fit_envmap_map_rejects_other_methods(scene):
    img, n, view, pref, _ = scene
    with pytest.raises(ValueError, match="method"):
        fit_envmap_map(img, n, view, pref, alpha=0.2, initial=Film(350.0, 1.33, 1.0),
                       method="reference")
