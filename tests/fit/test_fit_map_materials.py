"""Thickness maps of a dispersive film (SPEC §12): thermal oxide on silicon, the exact per-pixel
stack model (`reference`) and the real-time one (`filtered`, each band at its centroid), each
recovering the thicknesses it rendered; what a map cannot fit is refused by name."""

import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.fit.thickness_map import fit_patch_map

SI, SIO2 = tf.refractive_index("Si"), tf.refractive_index("SiO2")
D = np.linspace(120.0, 880.0, 6).reshape(2, 3)  # nm, several fringe orders
THETA = 0.3


@pytest.mark.parametrize("method", ["reference", "filtered"])
def test_oxide_on_silicon_map(method):
    """Noise-free maps rendered by `patch_radiance` with the same method: every pixel back to
    ≤ 0.1 nm from a 400 nm start (measured 0.018 nm, the refinement's tolerance)."""
    img = np.stack([np.asarray(tf.patch_radiance(tf.Film(float(d), SIO2, SI), THETA, 0.2,
                                                 method=method)) for d in D.ravel()])
    res = fit_patch_map(img.reshape(2, 3, 3), THETA, alpha=0.2, initial=tf.Film(400.0, SIO2, SI),
                        method=method, sigma=1e-3, grid=101)
    assert np.max(np.abs(np.asarray(res.thickness) - D)) < 0.1


def test_map_refusals():
    img = np.full((1, 2, 3), 0.1)
    with pytest.raises(ValueError, match="eta_film"):
        fit_patch_map(img, THETA, alpha=0.2, initial=tf.Film(400.0, SIO2, SI),
                      free=("thickness", "eta_film"))
    with pytest.raises(ValueError, match="one film"):
        fit_patch_map(img, THETA, alpha=0.2, method="reference",
                      initial=tf.Stack([100.0, 50.0], (SIO2, 2.0), SI))
    with pytest.raises(ValueError, match="method='khr' cannot model dispersive"):
        fit_patch_map(img, THETA, alpha=0.2, method="khr", initial=tf.Film(400.0, SIO2, SI))
