"""The uneven-light study's light (`benchmarks.photo_light`): it falls from 1 to `CORNER` and is
not in `fit_photo`'s family (rendering and fitting the photographs is the study's, a few
minutes: `python -m benchmarks.photo_light`)."""

import numpy as np
import pytest

from benchmarks import photo_light as S

pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")


def test_light_field_is_outside_the_fits_family():
    """1 at the peak, 0.55 in the darkest corner; a least-squares degree-3 exp-polynomial
    misses it by more than 0.1 % somewhere (so the study does not test the model against
    itself)."""
    from thinfilm_jax.fit.photo_light import basis

    n = 48
    f = S.light_field(n)
    assert np.isclose(f.max(), 1.0) and np.isclose(f.min(), S.CORNER)
    phi = np.c_[np.ones(n * n), basis(np.arange(n * n), n, n)]
    coef, *_ = np.linalg.lstsq(phi, np.log(f).ravel(), rcond=None)
    assert np.abs(phi @ coef - np.log(f).ravel()).max() > 1e-3

