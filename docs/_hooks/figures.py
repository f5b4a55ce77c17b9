"""MkDocs hook: serve the repository's committed ``figures/`` as part of the site.

The studies pages show the figures that the studies write into ``figures/`` at the repository
root (``make figure7``, ``python -m benchmarks.bench``, ...). Copying them into ``docs/`` would leave two
copies to keep in step, and a symbolic link does not survive every checkout, so this hook adds
``figures/**/*.png`` (and the ``.json`` result files, for download) to the site's files as
if they lay in ``docs/figures/``. A page links them with a path relative to itself, e.g.
``![Figure 7](../figures/figure7.png)`` from ``docs/studies/figure7.md``; MkDocs then checks
every such link in ``--strict`` mode like any other, so a missing figure fails the build.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

SUFFIXES = {".png", ".json"}


def on_files(files: Files, config) -> Files:
    root = Path(config["config_file_path"]).resolve().parent
    figures = root / "figures"
    for path in sorted(figures.rglob("*")):
        if path.suffix not in SUFFIXES or not path.is_file():
            continue
        uri = f"figures/{path.relative_to(figures).as_posix()}"
        if files.get_file_from_path(uri) is not None:
            continue
        # src_dir = the repository root: the file's source is figures/<name>, its URL too
        files.append(File(uri, src_dir=str(root), dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    return files


# ------------------------------------------------------------------ doctests in docstrings
# Module and function docstrings of the package show their examples as doctests (`>>>` lines,
# run by tests/test_doctests.py) under a free-form "Example (...):" line, which no docstring
# parser recognises as a section. Markdown would read `>>>` as nested block quotes (and
# `x["a"]["b"]` as a reference link), so this preprocessor fences every run of doctest lines
# as `pycon` code, for the pages and the docstrings that mkdocstrings renders alike.

import re  # noqa: E402

from markdown import Extension  # noqa: E402
from markdown.preprocessors import Preprocessor  # noqa: E402
from mkdocs.plugins import event_priority  # noqa: E402

_FENCE = re.compile(r"^\s*(```|~~~)")
_PROMPT = re.compile(r"^(\s*)>>>( |$)")


_DETAILS = re.compile(r"^\?\?\?\+? ")
_HEADING = re.compile(r"^(\s{4,})#{1,6} +(.*?)\s*#*\s*$")


class _DoctestFences(Preprocessor):
    def run(self, lines):
        out, i, fence, details = [], 0, None, False
        while i < len(lines):
            line = lines[i]
            # a study's report included in a collapsible block (`??? ...` + snippets) keeps
            # its text, but its headings become bold lines: they would otherwise enter the
            # page's table of contents above the page's own sections
            if _DETAILS.match(line):
                details = True
            elif details and line.strip() and not line.startswith("    "):
                details = False
            h = _HEADING.match(line) if details and not fence else None
            if h:
                out.append(f"{h.group(1)}**{h.group(2)}**")
                i += 1
                continue
            m = _FENCE.match(line)
            if m:
                fence = None if fence == m.group(1) else (fence or m.group(1))
                out.append(line)
                i += 1
                continue
            p = None if fence else _PROMPT.match(line)
            if p is None:
                out.append(line)
                i += 1
                continue
            indent = len(p.group(1))
            block = []
            while i < len(lines) and lines[i].strip() and not _FENCE.match(lines[i]):
                block.append(lines[i][indent:] if lines[i][:indent].strip() == "" else
                             lines[i].lstrip())
                i += 1
            out += ["", "```pycon", *block, "```", ""]
        return out


class DoctestExtension(Extension):
    def extendMarkdown(self, md):  # noqa: N802 (Markdown's API)
        md.preprocessors.register(_DoctestFences(md), "thinfilm_doctest_fences", 29)


@event_priority(100)  # before mkdocstrings reads the extensions for its docstring renderer
def on_config(config):
    config["markdown_extensions"].append(DoctestExtension())
    # `--8<-- "figures/x.md"` paths are from the repository root, wherever mkdocs runs
    root = str(Path(config["config_file_path"]).resolve().parent)
    config["mdx_configs"].setdefault("pymdownx.snippets", {})["base_path"] = [root]
    return config
