"""Test configuration: float64 by default, strict dtype promotion (tolerances are named in the
test module that asserts them), one compilation cache per test run, and the work units of
``pytest -n 2 --dist loadfile`` (the Makefile's `make test`)."""

import atexit
import gc
import os
import shutil
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

# JAX's persistent compilation cache, shared by every process of a test run — the two
# pytest-xdist workers, the CLI and notebook kernels the tests start (they call
# `enable_compilation_cache()`, which reads THINFILM_JAX_CACHE_DIR) — and kept between runs
# and between checkouts of this machine in ~/.cache/thinfilm_jax-tests/jax ($XDG_CACHE_HOME
# if set; emptied when a run starts with more than 2 GiB in it), so that the edit–test loop
# and a clean clone's check (.ci/run) compile only the programs that changed. Hermetic all
# the same: the user's own cache (~/.cache/thinfilm_jax) is neither read nor written, and an
# entry is keyed by the program's HLO, the compile options and the JAX/XLA version, so a hit
# is the program a compile would produce (programs and their numbers do not depend on the
# cache). Every program is stored, not only those over JAX's default 1 s.
# THINFILM_JAX_TEST_CACHE=fresh gives a folder of the run's own, removed at the end (a fresh
# machine's cost); any other value is a folder to use. tests/core/test_compilation_cache.py
# runs its subprocesses with folders of their own.
_MACHINE_CACHE = os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"),
                              "thinfilm_jax-tests", "jax")
_cache = os.environ.get("THINFILM_JAX_TEST_CACHE") or _MACHINE_CACHE
if _cache == "fresh":
    _cache = tempfile.mkdtemp(prefix="thinfilm-jax-test-cache-")
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
elif "PYTEST_XDIST_WORKER" not in os.environ and os.path.isdir(_cache):
    if sum(e.stat().st_size for e in os.scandir(_cache) if e.is_file()) > 2 << 30:
        shutil.rmtree(_cache, ignore_errors=True)
os.makedirs(_cache, exist_ok=True)
os.environ["THINFILM_JAX_TEST_CACHE"] = _cache  # inherited by the workers and subprocesses
os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"  # the subprocesses too
os.environ["THINFILM_JAX_CACHE_DIR"] = _cache
os.environ["THINFILM_JAX_NO_CACHE"] = ""
jax.config.update("jax_compilation_cache_dir", _cache)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)

import pytest  # noqa: E402

# Work units of `pytest -n 2 --dist loadfile` (the Makefile's `make test`): one per test file,
# so that a module's fixtures and the programs its tests share are built once, in one
# worker; tests that share nothing expensive with their file get units of their own, so that
# long tests run on both workers: each notebook runs in its own kernel, and each stiff patch
# grid of tests/benchmarks/test_stability.py is one compiled program (`stability._patch_variant`)
# while its other checks share one per dtype (`stability._rgb_group`).
# Long tests that build everything they need themselves (no module fixture, no program
# another test of their file compiles): one unit per parametrisation. The persistent
# compilation cache above still shares a program two units trace alike.
# (Not tests/shading/test_sources.py::test_gradients_finite: its one program per dtype,
# `_shade_and_grad`, is the one its file's other checks run — the float32 one that of
# test_stiff_inputs_finite — and a unit of its own traced it again and read the ≈ 2 s
# executable back from the persistent cache: 5.6 of its 5.6 worker-seconds.)
ALONE = ("tests/shading/test_ibl.py::test_stiff_inputs_finite_and_bounded[",
         "tests/shading/test_ibl.py::test_gradients_finite[")


def _unit(nodeid: str) -> str:
    path, _, name = nodeid.partition("::")
    if (path.endswith("test_notebooks.py") or name == "test_fitting_notebook_executes"
            or nodeid.startswith(ALONE) or name.startswith("test_stiff_inputs[patch_radiance")):
        return nodeid
    if path.endswith("test_stability.py"):  # the other checks: one unit per dtype
        return f"{path}:{'float32' if nodeid.endswith('-float32]') else 'float64'}"
    return path


# Units known to be long start first (notebooks ≈ 1 min each on the 2-core machine, the stiff
# grids; matched anywhere in the unit): xdist's own order (most tests first) would start
# single-test units last and leave one worker alone with a long test at the end.
FIRST = ("tests/test_notebooks.py::", "tests/fit/test_fit.py::test_fitting_notebook_executes",
         "tests/benchmarks/test_stability.py:", "tests/shading/test_ibl.py::test_stiff_inputs_finite_and_bounded[")


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


def pytest_collection_finish(session):
    """Python's cyclic garbage collector, tuned for tracing: JAX allocates and drops millions of
    small objects while it traces and lowers a program, so with the default thresholds
    (700, 10, 10) a worker ran ~10 000 collections and spent 10 % of its CPU time in them
    (16.8 of 164.6 CPU s over tests/optics, tests/spectral, the film-fit files and their CLI
    tests), most of it in full collections that walk every live object, the imported modules
    and the collected tests included. Here what is alive after collection is frozen (never
    scanned again, `gc.freeze`) and collections run less often; cyclic garbage is still
    freed, and no result depends on when. Same files: 1314 collections, 4.4 s."""
    gc.collect()
    gc.freeze()
    gc.set_threshold(10_000, 20, 20)


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


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's in-memory caches of compiled programs after each test file: a worker that
    kept every program of its files grew to ~8 GB, and two of them on the 24 GB CI machine
    aborted inside XLA while serialising an executable. A later file that needs a program
    again reads it from the persistent compilation cache above."""
    yield
    jax.clear_caches()
