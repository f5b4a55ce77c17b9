"""Every third-party package the library imports is declared in pyproject.toml: a package that
the installed library (anything outside `studies/`) imports must be a dependency, and one that a
study imports must be a dependency or in an extra (`[bench]` holds the peers). A missing
declaration works on a developer's machine and fails on a user's (`pip install thinfilm_jax`)."""

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


def _declared():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    core = _requirement_names(project["dependencies"])
    extras = set().union(*(_requirement_names(v)
                           for v in project.get("optional-dependencies", {}).values()))
    return core, extras


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
            if top != "thinfilm_jax" and top not in sys.stdlib_module_names:
                yield top, node.lineno


def test_third_party_imports_are_declared():
    core, extras = _declared()
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        study = "studies" in path.relative_to(PACKAGE).parts
        for top, line in _third_party_imports(path):
            dist = _normalise(DISTRIBUTION.get(top, top))
            allowed = core | extras if study else core
            if dist not in allowed:
                missing.append(f"{path.relative_to(ROOT)}:{line} imports {top} ({dist})")
    assert not missing, "declare in pyproject.toml:\n" + "\n".join(missing)


def test_the_check_sees_a_missing_declaration(tmp_path):
    """The scan finds an undeclared import (guards against a scan that sees nothing)."""
    mod = tmp_path / "m.py"
    mod.write_text("import numpy\ndef f():\n    import not_a_declared_package\n")
    found = dict(_third_party_imports(mod))
    assert found == {"numpy": 1, "not_a_declared_package": 3}
    core, _ = _declared()
    assert "numpy" in core and "not-a-declared-package" not in core
