"""Test configuration: float64 by default, strict dtype promotion (tolerances are named in the
test module that asserts them)."""

import os

import jax

jax.config.update("jax_enable_x64", True)
# hermetic: the CLI and notebooks run by the tests do not write the user's compilation cache
# (tests/test_compilation_cache.py turns it on explicitly, in a temporary folder)
os.environ.setdefault("THINFILM_JAX_NO_CACHE", "1")

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _strict_promotion():
    with jax.numpy_dtype_promotion("strict"):
        yield
