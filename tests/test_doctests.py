"""Docstring examples are executed: every `>>>` in every module of the package runs here, and
every public module has at least one (a module without examples would pass with nothing
checked; `NO_EXAMPLES` names the few that need none, each with its reason)."""

import doctest
import importlib
import pkgutil

import pytest

import thinfilm_jax

# not imported at all: importing it runs the command line
SKIP = {"thinfilm_jax.__main__"}
# modules with nothing a user calls, so no example is required; every other module must show
# at least one (the public API — the package itself, every core module, the CLI parsers — and
# each study with a function of its own contract: peers, stiff, stability, figure7, render, …)
NO_EXAMPLES = {
    "thinfilm_jax.cli._checks": "private: the CLI's range checks of parsed options "
                                "(tests/cli/test_cli_robustness.py runs them through the CLI)",
    "benchmarks": "a package docstring only: it defines nothing",
    "benchmarks._common": "private: materials and error statistics of the studies",
    "benchmarks._timing": "private: timing and bookkeeping of the studies",
    "benchmarks.bench": "the driver of `python -m benchmarks.bench`: each function runs or "
                        "reports the whole benchmark (minutes; "
                        "tests/benchmarks/test_bench_smoke.py)",
    "benchmarks.stack_bench": "a benchmark script against installed peers (tmm, tmm_fast, "
                              "tmmax in subprocesses): run as a module",
    "benchmarks.presets_bench": "a timing script: one `run` of five jitted `envmap_radiance` "
                                "calls on 2²⁰ points (minutes)",
    "benchmarks.scaling": "the device-scaling driver: it spawns one subprocess per device "
                          "count and times the large jobs (minutes)",
    "benchmarks.coverage": "a seeded study script: its functions are undocumented steps of "
                           "`run` (a `patch_radiance` or `fit_film` call, whose examples are "
                           "in patch.py and fit.py, or summaries and plots of a run's records)",
}
NO_EXAMPLES.update({f"thinfilm_jax.{layer}": "a layer's package docstring only: it defines nothing"
                    for layer in ("core", "optics", "spectral", "brdf", "realtime", "shading",
                                  "fit", "render", "cli")})
# the package, and the studies of the repository's benchmarks/ folder (importable from a clone:
# pyproject's pytest `pythonpath`)
MODULES = ["thinfilm_jax"] + sorted(
    m.name for m in pkgutil.walk_packages(thinfilm_jax.__path__, "thinfilm_jax.")
    if m.name not in SKIP)
try:
    import benchmarks
except ImportError:  # an installed package tested without its clone
    benchmarks = None
if benchmarks is not None:
    MODULES += ["benchmarks"] + sorted(m.name for m in pkgutil.walk_packages(
        benchmarks.__path__, "benchmarks."))
# known failures, each reported to the module's owner (remove the entry with the fix)
KNOWN: dict[str, str] = {}


def test_exemptions_are_modules():
    """A stale exemption (a renamed or removed module) would silently exempt nothing."""
    names = set(NO_EXAMPLES) if benchmarks is not None else {
        k for k in NO_EXAMPLES if not k.startswith("benchmarks")}
    assert names <= set(MODULES), names - set(MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for test in finder.find(module, name, globs=vars(module).copy()):
        runner.run(test)
    result = runner.summarize(verbose=False)
    if name in KNOWN:
        assert result.failed, f"{name} passes now: remove it from KNOWN"
        pytest.xfail(KNOWN[name])
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
    if name not in NO_EXAMPLES:
        assert result.attempted > 0, (f"{name} has no docstring example: add a short `>>>` "
                                      f"example, or exempt it in NO_EXAMPLES with the reason")
