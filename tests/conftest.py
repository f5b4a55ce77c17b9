"""Test configuration: float64 by default, strict dtype promotion (tolerances are named in the
test module that asserts them), one compilation cache per test run, and the work units of
``pytest -n 2 --dist loadfile`` (the Makefile's `make test`)."""

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
# it. tests/core/test_compilation_cache.py runs its subprocesses with folders of its own.
if "THINFILM_JAX_TEST_CACHE" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="thinfilm-jax-test-cache-")
    os.environ["THINFILM_JAX_TEST_CACHE"] = _cache
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
os.environ["THINFILM_JAX_CACHE_DIR"] = os.environ["THINFILM_JAX_TEST_CACHE"]
os.environ["THINFILM_JAX_NO_CACHE"] = ""
jax.config.update("jax_compilation_cache_dir", os.environ["THINFILM_JAX_TEST_CACHE"])

import pytest  # noqa: E402

# Work units of `pytest -n 2 --dist loadfile` (the Makefile's `make test`): one per test file,
# so that a module's fixtures and the programs its tests share are built once, in one
# worker; tests that share nothing expensive with their file get units of their own, so that
# long tests run on both workers: each notebook runs in its own kernel, and the stiff grids of
# tests/studies/test_stability.py share one compiled group per dtype (`stability._patch_group`).
# Long tests that build everything they need themselves (no module fixture, no program
# another test of their file compiles): one unit per parametrisation. The persistent
# compilation cache above still shares a program two units trace alike.
ALONE = ("tests/shading/test_ibl.py::test_stiff_inputs_finite_and_bounded[",
         "tests/shading/test_ibl.py::test_gradients_finite[",
         "tests/shading/test_sources.py::test_gradients_finite[")


def _unit(nodeid: str) -> str:
    path, _, name = nodeid.partition("::")
    if (path.endswith("test_notebooks.py") or name == "test_fitting_notebook_executes"
            or nodeid.startswith(ALONE)):
        return nodeid
    if path.endswith("test_stability.py"):
        # the patch grids (one shared compiled group per dtype) apart from the other checks
        group = "patch" if name.startswith("test_stiff_inputs[patch_radiance") else "other"
        return f"{path}:{'float32' if nodeid.endswith('-float32]') else 'float64'}:{group}"
    return path


# Units known to be long start first (notebooks ≈ 1 min each, a stiff patch grid ≈ 1 min per
# dtype on the 2-core machine; matched anywhere in the unit): xdist's own order (most tests first) would start single-test
# units last and leave one worker alone with a long test at the end.
FIRST = ("tests/test_notebooks.py::", "tests/fit/test_fit.py::test_fitting_notebook_executes",
         "tests/studies/test_stability.py:", "tests/shading/test_ibl.py::test_stiff_inputs_finite_and_bounded[")


def _rank(nodeid: str) -> int:
    unit = _unit(nodeid)
    return next((i for i, p in enumerate(FIRST) if p in unit), len(FIRST))


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadfile` with the units above (pytest-xdist's `--dist loadgroup` marks do not
    reach the scheduler under pytest 9); other modes are xdist's own."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Units(LoadScopeScheduling):
        def _split_scope(self, nodeid):
            return _unit(nodeid)

    config.option.loadscopereorder = False  # the workers' order (`FIRST` first)
    return Units(config, log)


def pytest_collection_modifyitems(config, items):
    # in xdist's workers only (the scheduler reads their collection): `FIRST` first, stable
    if os.environ.get("PYTEST_XDIST_WORKER"):
        items.sort(key=lambda item: _rank(item.nodeid))


def pytest_addoption(parser):
    parser.addoption("--jax-time-report", metavar="PATH", default=None,
                     help="write per-test wall, JAX trace, lowering and XLA compile seconds "
                          "to PATH.<worker>.json (tests/_compile_report.py)")


def pytest_configure(config):
    path = config.getoption("--jax-time-report")
    if path:
        from _compile_report import TimeReport

        config.pluginmanager.register(TimeReport(os.path.abspath(path)), "jax-time-report")


@pytest.fixture(autouse=True)
def _strict_promotion():
    with jax.numpy_dtype_promotion("strict"):
        yield
