"""The documentation site: `mkdocs build --strict` passes, and the API pages cover the package.

* The site (mkdocs.yml, docs/) builds with MkDocs Material and mkdocstrings in strict mode:
  a broken link, a missing figure (figures/ is served by docs/_hooks/figures.py), a docstring
  that griffe cannot parse or an unresolved cross-reference fails the build. Strict mode lets
  some link problems through as INFO (an unrecognized relative link such as the ``[f](θ_o, α)``
  of a docstring's ``L[f](θ_o, α)``, a missing anchor, an absolute link): the build log must
  have none of them (`LINK_PROBLEMS`), and every relative href/src of the built HTML must name
  a file of the site (`broken_links`).
* Every public name of `thinfilm_jax` (the names `thinfilm_jax/__init__.py` imports) is a
  `:::` target of docs/api/*.md, directly or as a member of a documented module (a subpackage
  documents the names of its ``__all__``), and has its anchor in the built API pages; every
  name of a documented subpackage's ``__all__`` has its anchor too.
* (docs/reference/layout.md, the package layout page, is checked by tests/test_layout.py.)
* Every page under docs/ is in the nav (except the draft and the hook that mkdocs.yml
  excludes).
* The measured numbers of the studies pages agree with figures/ (the checks of
  tests/test_readme_numbers.py, applied to those pages).

Build time here: about 3 s on one core (the API pages read the source statically).
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
API = DOCS / "api"


def _mkdocs_missing() -> str | None:
    import importlib.util

    for mod in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        try:
            found = importlib.util.find_spec(mod) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            return mod
    return None


MISSING = _mkdocs_missing()
needs_mkdocs = pytest.mark.skipif(
    MISSING is not None,
    reason=f"{MISSING} is not installed: `make setup` (pip install -e '.[test]') installs "
           "mkdocs, mkdocs-material and mkdocstrings[python]")


# ------------------------------------------------------------------ public names and targets

def exports() -> dict[str, str]:
    """{public name: dotted path it is imported from} for every `from .x import y as name` of
    thinfilm_jax/__init__.py (``kernels`` is the module thinfilm_jax.realtime.kernels)."""
    tree = ast.parse((ROOT / "thinfilm_jax" / "__init__.py").read_text("utf-8"))
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            for a in node.names:
                out[a.asname or a.name] = f"thinfilm_jax.{node.module}.{a.name}"
    return out


def candidate_paths(name: str, imported_from: str) -> set[str]:
    """Where `name` may be documented: the path it is imported from, the path of the
    object's definition (a class or function re-exported by another module), and the path
    under its subpackage (``thinfilm_jax.core.Film``) where that subpackage's ``__all__``
    exports the same object."""
    import importlib
    import types

    import thinfilm_jax

    paths = {imported_from}
    obj = getattr(thinfilm_jax, name)
    if isinstance(obj, types.ModuleType):
        paths.add(obj.__name__)
    elif isinstance(getattr(obj, "__module__", None), str) and hasattr(obj, "__qualname__"):
        paths.add(f"{obj.__module__}.{obj.__qualname__}")
    for path in list(paths):
        parts = path.split(".")
        if len(parts) > 3 and parts[0] == "thinfilm_jax":
            sub = importlib.import_module(".".join(parts[:2]))
            leaf = parts[-1]
            if leaf in getattr(sub, "__all__", ()) and getattr(sub, leaf) is obj:
                paths.add(f"{sub.__name__}.{leaf}")
    return paths


def subpackage_exports(targets) -> dict[str, list[str]]:
    """{subpackage: its ``__all__``} for every subpackage that is a `:::` target documenting
    all its public members."""
    import importlib
    import types

    out = {}
    for _, target, members in targets:
        if members is None and re.fullmatch(r"thinfilm_jax\.\w+", target):
            mod = importlib.import_module(target)
            if isinstance(mod, types.ModuleType) and hasattr(mod, "__path__"):
                out[target] = list(mod.__all__)
    return out


def api_targets(texts: dict[str, str]) -> list[tuple[str, str, object]]:
    """Every ``::: target`` of the API pages: (page, target, members), members None (all
    public members), False (none) or the listed names."""
    out = []
    for page, text in texts.items():
        lines = text.splitlines()
        for i, line in enumerate(lines):
            m = re.match(r"^::: *(\S+)\s*$", line)
            if not m:
                continue
            members: object = None
            j = i + 1
            while j < len(lines) and (lines[j].startswith(" ") or not lines[j].strip()):
                if not lines[j].strip() and j + 1 < len(lines) and not lines[j + 1].startswith(" "):
                    break
                mm = re.match(r"^\s+members:\s*(.*)$", lines[j])
                if mm:
                    value = mm.group(1).strip()
                    if value in ("false", "False", "no"):
                        members = False
                    elif value.startswith("["):
                        members = [v.strip(" '\"") for v in value.strip("[]").split(",")]
                    else:  # a YAML list below
                        members, k = [], j + 1
                        while k < len(lines) and re.match(r"^\s+- ", lines[k]):
                            members.append(lines[k].split("- ", 1)[1].strip(" '\""))
                            k += 1
                j += 1
            out.append((page, m.group(1), members))
    return out


def uncovered(names: dict[str, set[str]], targets) -> list[str]:
    """The public names that no ``:::`` target documents (`names`: candidate paths)."""
    missing = []
    for name, paths in sorted(names.items()):
        ok = False
        for _, target, members in targets:
            for p in paths:
                parent, _, leaf = p.rpartition(".")
                if p == target or (parent == target and (
                        members is None or (members is not False and leaf in members))):
                    ok = True
        if not ok:
            missing.append(f"{name} ({' or '.join(sorted(paths))})")
    return missing


def api_texts() -> dict[str, str]:
    return {p.name: p.read_text("utf-8") for p in sorted(API.glob("*.md"))}


def public_names() -> dict[str, set[str]]:
    return {n: candidate_paths(n, p) for n, p in exports().items()}


#: mkdocs 1.6's messages about a link it could not resolve, WARNING or INFO
#: (mkdocs/structure/pages.py; INFO passes `--strict`)
LINK_PROBLEMS = re.compile(r"contains an unrecognized relative link|is not found among "
                           r"documentation files|there is no such anchor|contains an absolute "
                           r"link|excluded from the built site|contains a link")
_HREF = re.compile(r"""\b(?:href|src)\s*=\s*(?:"([^"]*)"|'([^']*)')""")


def link_problems(log: str) -> list[str]:
    """The lines of a `mkdocs build` log (run without -q) that report an unresolved link."""
    return [ln.strip() for ln in log.splitlines() if LINK_PROBLEMS.search(ln)]


def broken_links(site: Path) -> list[str]:
    """Every relative href or src of the built HTML pages that names no file of `site`
    ("page.html: target"); a folder link needs its index.html. Links with a scheme (http:,
    mailto:, data:) and same-page anchors are not files and are skipped."""
    from urllib.parse import unquote, urlsplit

    out = []
    for page in sorted(site.rglob("*.html")):
        for m in _HREF.finditer(page.read_text("utf-8", errors="replace")):
            url = m.group(1) if m.group(1) is not None else m.group(2)
            parts = urlsplit(url)
            if parts.scheme or parts.netloc or not parts.path:
                continue
            path = unquote(parts.path)
            target = (site / path.lstrip("/")) if path.startswith("/") else page.parent / path
            if path.endswith("/") or target.is_dir():
                target = target / "index.html"
            if not target.resolve().is_file():
                out.append(f"{page.relative_to(site)}: {url}")
    return out


# ------------------------------------------------------------------------------ the tests

def test_every_public_name_is_a_target_of_the_api_pages():
    names = public_names()
    assert len(names) >= 50  # the parse found the exports (59 when written)
    missing = uncovered(names, api_targets(api_texts()))
    assert not missing, "add to docs/api/*.md: " + ", ".join(missing)


def test_api_index_lists_every_public_name():
    """docs/api/index.md has a row per public name (the table a reader scans first)."""
    listed = set(re.findall(r"^\| `(\w+)` \|", (API / "index.md").read_text("utf-8"), flags=re.M))
    missing = sorted(set(exports()) - listed)
    assert not missing, f"add a row to docs/api/index.md for: {missing}"


def test_the_coverage_check_fails_when_a_name_is_missing():
    """The check itself: a page without the module, or with a member list that leaves the
    name out, does not cover it; the module or the name itself does."""
    names = {"Film": {"thinfilm_jax.core.film.Film"}}
    assert uncovered(names, api_targets({"a.md": "::: thinfilm_jax.core.sharding\n"}))
    assert uncovered(names, api_targets({"a.md": (
        "::: thinfilm_jax.core.film\n    options:\n      members:\n        - FILM_FIELDS\n")}))
    assert uncovered(names, api_targets({"a.md": (
        "::: thinfilm_jax.core.film\n    options:\n      members: false\n")}))
    assert not uncovered(names, api_targets({"a.md": "::: thinfilm_jax.core.film\n"}))
    assert not uncovered(names, api_targets({"a.md": "::: thinfilm_jax.core.film.Film\n"}))
    assert not uncovered(names, api_targets({"a.md": (
        "::: thinfilm_jax.core.film\n    options:\n      members: [Film]\n")}))
    # the subpackage documents the names of its __all__ (Film is one of core's)
    via_core = {"Film": candidate_paths("Film", "thinfilm_jax.core.film.Film")}
    assert "thinfilm_jax.core.Film" in via_core["Film"]
    assert not uncovered(via_core, api_targets({"a.md": "::: thinfilm_jax.core\n"}))
    assert uncovered(via_core, api_targets({"a.md": "::: thinfilm_jax.optics\n"}))


# The studies pages carry the README's measured tables and sentences (copied, with their
# captions): tests/test_readme_numbers.py's checks hold on them too, read as one text in this
# order (each table and checked sentence once; the theory pages quote some again, unchecked).
def test_studies_numbers_match_artifacts():
    import test_readme_numbers as numbers

    text = numbers.read_document()  # the pages of `numbers.PAGES`
    mismatches = numbers.check(text)
    assert not mismatches, "docs pages disagree with figures/:\n" + "\n".join(map(str, mismatches))
    assert numbers.unchecked_tables(text) == []


def test_every_page_is_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text("utf-8").split("\nnav:", 1)[1]
    in_nav = set(re.findall(r"([\w./-]+\.md)\s*$", nav, flags=re.M))
    pages = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md")
             if not p.name.startswith("_") and "_hooks" not in p.parts}
    assert pages - in_nav == set(), f"pages missing from the nav of mkdocs.yml: {pages - in_nav}"
    assert in_nav - pages == set(), f"nav entries without a page: {in_nav - pages}"


def test_the_link_checks_find_unresolved_links(tmp_path):
    """The checks themselves: the INFO line strict mode let through for ``L[f](θ_o, α)``, and
    a built page whose relative links name a missing file; good links pass."""
    log = ("INFO    -  Building documentation to directory: /tmp/site\n"
           "INFO    -  Doc file 'api/brdf.md' contains an unrecognized relative link 'θ_o, α', "
           "it was left as is.\n"
           "INFO    -  Documentation built in 8.19 seconds\n")
    assert link_problems(log) == ["INFO    -  Doc file 'api/brdf.md' contains an unrecognized "
                                  "relative link 'θ_o, α', it was left as is."]
    (tmp_path / "api" / "brdf").mkdir(parents=True)
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "a.png").write_bytes(b"")
    (tmp_path / "index.html").write_text("<a href='api/brdf/'>ok</a>", "utf-8")
    (tmp_path / "api" / "brdf" / "index.html").write_text(
        '<a href="../../">up</a> <img src="../../figures/a.png"> <a href="#x">anchor</a> '
        '<a href="https://example.org/x">web</a> <a href="mailto:a@b">mail</a> '
        '<a href="θ_o, α">L[f]</a> <img src="../../figures/b.png"> '
        '<a href="../../api/missing/#sec">gone</a>', "utf-8")
    assert broken_links(tmp_path) == ["api/brdf/index.html: θ_o, α",
                                      "api/brdf/index.html: ../../figures/b.png",
                                      "api/brdf/index.html: ../../api/missing/#sec"]


@needs_mkdocs
def test_site_builds_strict_and_documents_every_public_name(tmp_path):
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                           "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    unresolved = link_problems(proc.stdout + proc.stderr)
    assert not unresolved, "links mkdocs left unresolved:\n" + "\n".join(unresolved)
    broken = broken_links(site)
    assert not broken, "hrefs of the built site to missing files:\n" + "\n".join(broken)
    html = "\n".join(p.read_text("utf-8") for p in (site / "api").rglob("*.html"))
    anchors = set(re.findall(r'\bid="(thinfilm_jax[\w.]*)"', html))
    missing = [f"{n} ({' or '.join(sorted(ps))})" for n, ps in sorted(public_names().items())
               if not ps & anchors]
    assert not missing, "no anchor in the built API pages for: " + ", ".join(missing)
    exported = subpackage_exports(api_targets(api_texts()))
    assert len(exported) >= 8  # one page per layer, core to interop
    missing = [f"{sub}.{n}" for sub, names in exported.items() for n in names
               if f"{sub}.{n}" not in anchors]
    assert not missing, "names of a subpackage's __all__ without an anchor: " + ", ".join(missing)
    # the figures of the studies pages are served from figures/ (docs/_hooks/figures.py)
    assert (site / "figures" / "figure7.png").is_file()
    assert "figures/figure7.png" in (site / "studies" / "figure7" / "index.html").read_text("utf-8")


# Pages whose ```python blocks run as written (each page in one namespace, in order); the
# other pages' blocks read files a reader supplies (my_sky.hdr, wedge.npy) or are README
# copies that tests/test_readme.py runs.
RUNNABLE_PAGES = ("getting-started/index.md", "how-to/new-method.md", "how-to/devices.md")


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE_PAGES)
def test_page_examples_run(page, capsys):
    import jax

    text = (DOCS / page).read_text("utf-8")
    blocks = re.findall(r"^```python[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.S | re.M)
    assert blocks, f"{page} has no python block"
    namespace = {"__name__": "docs"}
    with jax.numpy_dtype_promotion("standard"):
        for i, block in enumerate(blocks):
            code = compile(block, f"docs/{page} python block {i + 1}", "exec")
            exec(code, namespace)  # noqa: S102  (this repository's own pages)
    out = capsys.readouterr().out
    if page == "getting-started/index.md":  # the numbers the page quotes
        err, grad = (float(x) for x in out.split()[:2])
        assert abs(err - 2.7e-3) < 0.05e-3 and abs(grad + 1.2e-4) < 0.05e-4
    if page == "how-to/new-method.md":  # the table the page quotes
        assert "ideal           ΔE00 mean 10.04  p95 24.17" in out
        assert "filtered        ΔE00 mean  3.53  p95  9.87" in out
        assert "mean direction  ΔE00 mean  9.54  p95 22.13" in out
