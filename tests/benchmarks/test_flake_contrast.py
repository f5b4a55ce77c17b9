"""The flake-contrast study's layer counting (benchmarks/flake_contrast.py): with
the objective's NA in the model every pixel of the synthetic flake is counted right; a model
that ignores NA 0.9 (normal incidence) miscounts thicker flakes on 285 nm oxide, the claim of
docs/how-to/microscope.md. (Blake et al.'s contrast maxima are checked, from the library's
own calls, in tests/optics/test_objective.py.)"""

import numpy as np

from thinfilm_jax.spectral.camera import camera_response
from benchmarks import flake_contrast as fc


def test_counting_needs_the_na_on_285_nm_oxide():
    cam = camera_response(fc.CAMERA, fc.LAMP)
    truth = fc.layer_map()
    img = fc.render(285.0, 0.9, cam, np.random.default_rng(fc.SEED))
    right = fc.count_layers(img, 285.0, 0.9, cam)
    assert np.all(right == truth)
    ignored = fc.count_layers(img, 285.0, 0.0, cam)
    assert np.mean(ignored == truth) < 0.9
    assert np.all(ignored[truth == 0] == 0)  # the reference region and the bare oxide stay 0
