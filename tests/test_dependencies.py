"""Every third-party package the library imports is declared in pyproject.toml: a package that
the installed library imports must be a dependency, or matplotlib, which the figures import when
they draw (the `[plots]` extra); one that a study of the repository's `benchmarks/` folder (not
installed) imports must be a dependency or in `[bench]` (the peers), `[plots]` or `[test]`. A
missing declaration works on a developer's machine and fails on a user's (`pip install
thinfilm_jax`). The wheel holds `thinfilm_jax` alone: neither `benchmarks` nor `tests`."""

import ast
import re
import sys
try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import pytest

    tomllib = pytest.importorskip("tomli")
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "thinfilm_jax"

#: import name -> distribution name, where they differ (PyPI's names; PEP 503 normalised below)
DISTRIBUTION = {"colour": "colour-science", "OpenImageIO": "openimageio", "yaml": "pyyaml",
                "tmm_fast": "tmm-fast", "mpl_toolkits": "matplotlib", "PIL": "pillow",
                "skimage": "scikit-image", "sklearn": "scikit-learn"}


def _normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_names(requirements) -> set[str]:
    return {_normalise(re.split(r"[\s<>=!~;\[]", r, maxsplit=1)[0]) for r in requirements}


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def _declared():
    project = _pyproject()["project"]
    core = _requirement_names(project["dependencies"])
    extras = set().union(*(_requirement_names(v)
                           for v in project.get("optional-dependencies", {}).values()))
    return core, extras


def _extra(name: str) -> set[str]:
    return _requirement_names(_pyproject()["project"]["optional-dependencies"][name])


def _third_party_imports(path: Path):
    """(top-level import name, line) of every absolute import in `path`, lazy ones included."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            top = name.split(".")[0]
            # the repository's own packages: the library and its studies (benchmarks/)
            if top not in ("thinfilm_jax", "benchmarks") and top not in sys.stdlib_module_names:
                yield top, node.lineno


def test_third_party_imports_are_declared():
    core, _ = _declared()
    library = core | _extra("plots")
    studies = core | _extra("bench") | _extra("plots") | _extra("test")
    missing = []
    for folder, allowed in ((PACKAGE, library), (ROOT / "benchmarks", studies)):
        for path in sorted(folder.rglob("*.py")):
            for top, line in _third_party_imports(path):
                if _normalise(DISTRIBUTION.get(top, top)) not in allowed:
                    missing.append(f"{path.relative_to(ROOT)}:{line} imports {top}")
    assert not missing, "declare in pyproject.toml:\n" + "\n".join(missing)


def test_matplotlib_is_optional():
    """matplotlib is the `[plots]` extra, not a dependency: the library imports it inside the
    functions that draw (never at a module's top level), and importing the package loads it
    not."""
    import os
    import subprocess

    core, _ = _declared()
    assert "matplotlib" not in core and "matplotlib" in _extra("plots")
    top_level = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[0] == "matplotlib" for n in names):
                top_level.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not top_level, top_level
    code = ("import sys, thinfilm_jax, thinfilm_jax.cli.main, thinfilm_jax.render.figure7, "
            "thinfilm_jax.render.scene; print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env=dict(os.environ, JAX_PLATFORMS="cpu"))
    assert out.stdout.strip() == "False", out.stderr[-2000:]


def test_missing_matplotlib_names_the_extra(monkeypatch):
    """Without matplotlib a figure is an ImportError that says which extra to install."""
    import pytest

    from thinfilm_jax.render import plot

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib → ImportError
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    with pytest.raises(ImportError, match=r"thinfilm_jax\[plots\]"):
        plot.subplots()


def test_wheel_holds_the_package_only():
    """The wheel's packages are `thinfilm_jax` and its sub-packages (setuptools' discovery with
    pyproject's ``[tool.setuptools.packages.find]``, as ``pip wheel .`` runs it): the studies
    (`benchmarks/`) and the tests stay in the repository, and the installed package has no
    `studies` left."""
    import pytest

    setuptools = pytest.importorskip("setuptools")
    find = _pyproject()["tool"]["setuptools"]["packages"]["find"]
    assert find == {"include": ["thinfilm_jax*"]}
    packages = setuptools.find_packages(where=str(ROOT), **find)
    assert "thinfilm_jax" in packages and "thinfilm_jax.render" in packages
    assert all(p == "thinfilm_jax" or p.startswith("thinfilm_jax.") for p in packages), packages
    assert "thinfilm_jax.studies" not in packages
    assert (ROOT / "benchmarks" / "__init__.py").is_file()  # the folder the wheel leaves out
    assert not any(p.startswith("benchmarks") for p in packages)


def test_the_check_sees_a_missing_declaration(tmp_path):
    """The scan finds an undeclared import (guards against a scan that sees nothing)."""
    mod = tmp_path / "m.py"
    mod.write_text("import numpy\ndef f():\n    import not_a_declared_package\n")
    found = dict(_third_party_imports(mod))
    assert found == {"numpy": 1, "not_a_declared_package": 3}
    core, _ = _declared()
    assert "numpy" in core and "not-a-declared-package" not in core
