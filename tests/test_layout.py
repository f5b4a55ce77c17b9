"""The package's layout: docs/reference/layout.md names every module once (and nothing else),
the layers import only earlier layers, no cycles, one version, no tracker references."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_layout_matches_tree():
    """docs/reference/layout.md (the package layout page the README links to, on the docs
    site) has one table row per module of thinfilm_jax/: none missing, none extra, none twice."""
    section = (ROOT / "docs" / "reference" / "layout.md").read_text(encoding="utf-8")
    listed = re.findall(r"^\| `([^`]+\.py)` \|", section, flags=re.M)
    package = ROOT / "thinfilm_jax"
    modules = sorted(str(p.relative_to(package)) for p in package.rglob("*.py"))
    assert len(listed) == len(set(listed)), "a module is listed twice"
    missing, extra = sorted(set(modules) - set(listed)), sorted(set(listed) - set(modules))
    assert not missing and not extra, f"add to docs/reference/layout.md: {missing}; remove: {extra}"


LAYERS = ("core", "optics", "spectral", "brdf", "realtime", "shading", "fit", "interop",
          "studies", "cli")


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
    """core → optics → spectral → brdf → realtime → shading → fit → interop → studies → cli: a
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
    """Every test folder is named after a layer of the package (README "## Layout")."""
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert folders <= set(LAYERS), sorted(folders - set(LAYERS))
