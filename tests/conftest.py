"""Test configuration: float64 by default, strict dtype promotion (tolerances are named in the
test module that asserts them)."""

import jax

jax.config.update("jax_enable_x64", True)

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _strict_promotion():
    with jax.numpy_dtype_promotion("strict"):
        yield
