"""Test configuration: float64 by default, strict dtype promotion, shared tolerances."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

# Tolerances named once, keyed by dtype (see README "Accuracy").
TOL = {
    np.dtype("float64"): dict(rtol=1e-12, atol=1e-12),
    np.dtype("float32"): dict(rtol=2e-5, atol=2e-5),
}


@pytest.fixture(autouse=True)
def _strict_promotion():
    with jax.numpy_dtype_promotion("strict"):
        yield
