"""Test configuration: float64 by default, strict dtype promotion (tolerances are named in the
test module that asserts them), one compilation cache per test run, and the work units of
``pytest -n 2 --dist loadgroup`` (the Makefile's `make test`)."""

import atexit
import os
import shutil
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

# JAX's persistent compilation cache in a fresh folder per test run, removed at the end:
# hermetic (nothing is read from or written to the user's cache, ~/.cache/thinfilm_jax), and
# a program compiled twice in one run — by two callables that trace the same program, by the
# CLI and the notebook kernels the tests start (they call `enable_compilation_cache()`, which
# reads THINFILM_JAX_CACHE_DIR), or by the two pytest-xdist workers — compiles once. The
# folder is made by the first process (pytest itself, or xdist's controller) and inherited
# through the environment by the workers and subprocesses; the process that made it removes
# it. tests/test_compilation_cache.py runs its subprocesses with folders of its own.
if "THINFILM_JAX_TEST_CACHE" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="thinfilm-jax-test-cache-")
    os.environ["THINFILM_JAX_TEST_CACHE"] = _cache
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
os.environ["THINFILM_JAX_CACHE_DIR"] = os.environ["THINFILM_JAX_TEST_CACHE"]
os.environ["THINFILM_JAX_NO_CACHE"] = ""
jax.config.update("jax_compilation_cache_dir", os.environ["THINFILM_JAX_TEST_CACHE"])

import pytest  # noqa: E402

# Work units of `--dist loadgroup`: by default one per test file, so that a module's fixtures
# and the programs its tests share are built once, in one worker (as `--dist loadfile`).
# Tests that share nothing expensive with their file get units of their own, so that long
# tests can run on both workers: each notebook runs in its own kernel, and the stiff grids of
# tests/test_stability.py share one compiled group per dtype (`stability._patch_group`).
def _unit(item) -> str:
    name = item.path.name
    if name == "test_notebooks.py" or item.name == "test_fitting_notebook_executes":
        return f"{name}::{item.name}"
    if name == "test_stability.py":
        params = getattr(item, "callspec", None)
        return f"{name}:{params.params.get('dtype', 'float64') if params else 'float64'}"
    return name


# Units known to be long start first (notebooks ≈ 1 min each, a stiff patch grid ≈ 1 min per
# dtype, measured on the 2-core machine); with xdist's default order (most tests first)
# single-test units would start last and leave one worker idle at the end. The order only
# matters under `--dist loadgroup`; a plain `pytest` run keeps the collection order.
FIRST = ("test_notebooks.py::", "test_fit.py::test_fitting_notebook_executes",
         "test_stability.py:")


def _rank(item) -> int:
    unit = _unit(item)
    return next((i for i, p in enumerate(FIRST) if unit.startswith(p)), len(FIRST))


def pytest_configure(config):
    if getattr(config.option, "dist", "no") == "loadgroup":
        config.option.loadscopereorder = False  # the order of `pytest_collection_modifyitems`


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(_unit(item)))
    if getattr(config.option, "dist", "no") == "loadgroup":
        items.sort(key=_rank)  # stable: a unit's tests keep their order


@pytest.fixture(autouse=True)
def _strict_promotion():
    with jax.numpy_dtype_promotion("strict"):
        yield
