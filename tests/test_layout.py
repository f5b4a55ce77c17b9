"""The package's layout: docs/reference/layout.md names every module once (and nothing else),
the layers import only earlier layers, no cycles, modules readable in one sitting (≤ 600 lines,
functions ≤ 120), one version, no tracker references; the studies in `benchmarks/` (outside the
package) are listed too and import only public names."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _listed(prefix: str = "") -> list[str]:
    """The modules docs/reference/layout.md lists: the package's (`prefix` "") or those of the
    repository folder `prefix` (e.g. "benchmarks/"), relative to it."""
    section = (ROOT / "docs" / "reference" / "layout.md").read_text(encoding="utf-8")
    listed = re.findall(r"^\| `([^`]+\.py)` \|", section, flags=re.M)
    if prefix:
        return [m[len(prefix):] for m in listed if m.startswith(prefix)]
    return [m for m in listed if not m.startswith("benchmarks/")]


def test_layout_matches_tree():
    """docs/reference/layout.md (the package layout page the README links to, on the docs
    site) has one table row per module of thinfilm_jax/, and one per module of benchmarks/:
    none missing, none extra, none twice."""
    for folder, prefix in (("thinfilm_jax", ""), ("benchmarks", "benchmarks/")):
        listed = _listed(prefix)
        package = ROOT / folder
        modules = sorted(str(p.relative_to(package)) for p in package.rglob("*.py"))
        assert len(listed) == len(set(listed)), f"a module of {folder} is listed twice"
        missing, extra = sorted(set(modules) - set(listed)), sorted(set(listed) - set(modules))
        assert not missing and not extra, (f"add to docs/reference/layout.md: {prefix}{missing}; "
                                           f"remove: {extra}")


LAYERS = ("core", "optics", "spectral", "brdf", "realtime", "shading", "fit", "interop",
          "render", "cli")


def _imports(path: Path, package: str):
    """Every module of the package that `path` imports (relative or absolute, lazy included)."""
    import ast

    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            names = [target] + [f"{target}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for n in names:
            parts = n.split(".")
            if parts[0] == "thinfilm_jax" and len(parts) > 1 and parts[1] in LAYERS:
                yield n, parts[1]


def test_layers_import_only_downwards():
    """core → optics → spectral → brdf → realtime → shading → fit → interop → render → cli: a
    module imports its own layer and those before it, never one after (README "## Layout")."""
    package = ROOT / "thinfilm_jax"
    bad = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if len(rel.parts) < 2:  # __init__.py, __main__.py: the public face, above every layer
            continue
        own = LAYERS.index(rel.parts[0])
        pkg = ".".join(("thinfilm_jax",) + rel.parts[:-1])
        for name, layer in _imports(path, pkg):
            if LAYERS.index(layer) > own:
                bad.append(f"{rel} imports {name}")
    assert not bad, "\n".join(bad)


def test_no_import_cycle_between_modules():
    """The module import graph (lazy imports included) has no cycle."""
    package = ROOT / "thinfilm_jax"
    graph = {}
    for path in package.rglob("*.py"):
        rel = path.relative_to(package)
        mod = ".".join(("thinfilm_jax",) + rel.with_suffix("").parts)
        pkg = mod.rsplit(".", 1)[0] if path.name != "__init__.py" else mod[: -len(".__init__")]
        mods = set()
        for name, _ in _imports(path, pkg):
            while name and not (ROOT / (name.replace(".", "/") + ".py")).exists():
                name = name.rpartition(".")[0]  # `from pkg.mod import func` → pkg.mod
            if name and name != mod:
                mods.add(name)
        graph[mod] = mods
    state = {}

    def visit(m, stack):
        state[m] = 1
        for n in graph.get(m, ()):
            if state.get(n) == 1:
                raise AssertionError("import cycle: " + " → ".join(stack + [m, n]))
            if n not in state:
                visit(n, stack + [m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])


def test_release_metadata_agrees():
    """One version everywhere: pyproject, `thinfilm_jax.__version__` (what `--version`
    prints), CITATION.cff, and the newest released CHANGELOG.md entry (after "Unreleased")."""
    import tomllib

    import thinfilm_jax

    version = tomllib.loads((ROOT / "pyproject.toml").read_text("utf-8"))["project"]["version"]
    assert thinfilm_jax.__version__ == version
    assert re.search(rf"^version: {re.escape(version)}$", (ROOT / "CITATION.cff").read_text("utf-8"),
                     flags=re.M)
    first = re.search(r"^## (\d\S*)", (ROOT / "CHANGELOG.md").read_text("utf-8"), flags=re.M)
    assert first and first.group(1) == version


def test_no_tracker_references():
    """Code, tests, notebooks and docs cite papers, equations, docs pages and tests, never the
    project's work tracker (numbered tickets), which a reader of the package cannot open."""
    pattern = re.compile(r"\bissues?\s*#?\s*\d+|\bthe issue\b|\bissue tracker\b|/issues/\d+",
                         flags=re.I)
    files = [p for d in ("thinfilm_jax", "tests", "docs", "notebooks") for p in (ROOT / d).rglob("*")
             if p.suffix in {".py", ".md", ".ipynb"}] + [ROOT / "README.md", ROOT / "CHANGELOG.md"]
    hits = [f"{p.relative_to(ROOT)}: {m.group(0)!r}" for p in files
            for m in pattern.finditer(p.read_text("utf-8", errors="replace"))]
    assert not hits, "\n".join(hits)


def test_tests_mirror_the_layers():
    """Every test folder is named after a layer of the package (README "## Layout"), or is
    `tests/benchmarks` (the studies outside the package)."""
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert folders <= set(LAYERS) | {"benchmarks"}, sorted(folders - set(LAYERS))


#: the private names of the library the studies still import, each with why: a new one is an
#: error here (make the library offer a public function instead), a fixed one must be removed
PRIVATE_IMPORTS: dict[str, str] = {}


def _private_imports(path: Path):
    """`module` or `module.name` of every import of `path` from thinfilm_jax that names a
    private module or a private name (underscore; dunders excepted)."""
    import ast

    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and not node.level and node.module \
                and node.module.split(".")[0] == "thinfilm_jax":
            if any(p.startswith("_") for p in node.module.split(".")):
                yield node.module
            for a in node.names:
                if a.name.startswith("_") and not a.name.startswith("__"):
                    yield f"{node.module}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "thinfilm_jax" and any(
                        p.startswith("_") for p in a.name.split(".")):
                    yield a.name


def test_benchmarks_import_public_names():
    """The studies (benchmarks/, outside the package) import the library's public names, but
    for the listed private ones (`PRIVATE_IMPORTS`), and the package never imports
    `benchmarks` (nor `tests`) but in ``thinfilm-jax bench``, which hands over to the clone's
    `benchmarks.bench` (cli/main.py, lazily)."""
    found = {}
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        for name in _private_imports(path):
            found.setdefault(name, []).append(path.name)
    new = {k: v for k, v in found.items() if k not in PRIVATE_IMPORTS}
    gone = sorted(set(PRIVATE_IMPORTS) - set(found))
    assert not new, f"private library names imported by benchmarks/: {new}"
    assert not gone, f"no longer imported, remove from PRIVATE_IMPORTS: {gone}"
    import ast

    for path in sorted((ROOT / "thinfilm_jax").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            mods = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                    [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                    else [])
            if path.relative_to(ROOT).as_posix() == "thinfilm_jax/cli/main.py":
                mods = [m for m in mods if m != "benchmarks.bench"]
            assert not any(m.split(".")[0] in ("benchmarks", "tests") for m in mods), \
                f"{path.relative_to(ROOT)} imports {mods}"


def test_private_import_scan_sees_one(tmp_path):
    """The scan finds a private module, a private name and ignores public ones."""
    mod = tmp_path / "m.py"
    mod.write_text("from thinfilm_jax.core._validate import checked\n"
                   "from thinfilm_jax.shading.ibl import _batch, envmap_radiance\n"
                   "import numpy as _np\nfrom thinfilm_jax import Film\n")
    assert list(_private_imports(mod)) == ["thinfilm_jax.core._validate",
                                           "thinfilm_jax.shading.ibl._batch"]


def test_modules_and_functions_read_in_one_sitting():
    """No package module over 600 lines and no function over 120 (docs/reference/style.md);
    `python -m benchmarks.house` lists the largest."""
    import ast

    long = []
    for path in sorted((ROOT / "thinfilm_jax").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(ROOT)
        if len(text.splitlines()) > 600:
            long.append(f"{rel}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and node.end_lineno - node.lineno + 1 > 120:
                long.append(f"{rel}:{node.name}: {node.end_lineno - node.lineno + 1} lines")
    assert not long, "\n".join(long)
