"""How the package's floor plan reads: the files one shading call runs through, and the sizes.

For each method of `envmap_radiance` and `patch_radiance`, one Film → pixels call (the first
call, traced) under Python's profiler (`sys.setprofile`):

* **files run**: the package files with a Python function that runs (host tables built
  before, the jit caches cleared so that the call traces again), leaf formulas included
  (Fresnel, Airy, the Ŝ table, ...);
* **call chain**: the package files on the deepest call stack, in order (a file entered
  twice in a row counts once, a return to it later counts again in the chain but once in the
  number): what a reader follows from the entry point down to the innermost formula.

Then the largest modules and functions of the package (lines), against the house limits of
600 and 120 (tests/test_layout.py), and every ``method == "`` comparison left outside the
method modules and the registry.

Run: ``python -m benchmarks.house`` (about a minute; nothing is written).
"""

from __future__ import annotations

import ast
import os
import re
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "thinfilm_jax"


def _profile(call):
    """(files run, deepest chain) of the package while `call()` runs."""
    root = str(PKG)
    seen, best = set(), []

    def prof(frame, event, arg):
        if event != "call" or not frame.f_code.co_filename.startswith(root):
            return
        seen.add(os.path.relpath(frame.f_code.co_filename, root))
        chain, f = [], frame
        while f is not None:
            name = f.f_code.co_filename
            if name.startswith(root):
                rel = os.path.relpath(name, root)
                if not chain or chain[-1] != rel:
                    chain.append(rel)
            f = f.f_back
        if len(set(chain)) > len(set(best)):
            best[:] = chain

    sys.setprofile(prof)
    try:
        call()
    finally:
        sys.setprofile(None)
    return sorted(seen), list(reversed(best))


def call_paths():
    """Rows (entry point, method, files run, chain) for every registered method."""
    import jax
    import numpy as np

    import thinfilm_jax as tf
    from thinfilm_jax.core.methods import names

    jax.config.update("jax_enable_x64", True)
    warnings.simplefilter("ignore")
    img = np.random.default_rng(0).uniform(0.2, 2.0, (8, 16, 3))
    film = tf.Film(np.array([100.0, 350.0]), 1.33, 1.5)
    n = np.array([[0.0, 0.0, 1.0], [0.0, np.sin(0.3), np.cos(0.3)]])
    v = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    pref = tf.prefilter_envmap(img, levels=3, resolution=(8, 16), albedo_shape=(8, 5),
                               sources=0)
    rows = []
    for m in names("patch"):
        tf.patch_radiance(film, 0.4, 0.3, method=m)  # host tables built outside the count
        jax.clear_caches()  # the call traces again: its Python runs
        files, chain = _profile(lambda: tf.patch_radiance(film, 0.5, 0.3, method=m))
        rows.append(("patch_radiance", m, files, chain))
    for m in names("envmap"):
        env = {"reference": img, "mc": img}.get(m, pref)
        if m == "colour_table":
            env = tf.prefilter_colour(np.ones((64, 128, 3)), tf.Film(350.0, 1.33, 1.5), 0.3)
            film_m = tf.Film(350.0, 1.33, 1.5)
        else:
            film_m = film
        kw = {"n_samples": 64} if m == "mc" else {}
        tf.envmap_radiance(film_m, 0.3, n[:1], v, env, method=m, **kw)
        jax.clear_caches()
        files, chain = _profile(lambda: tf.envmap_radiance(film_m, 0.3, n, v, env, method=m,
                                                           **kw))
        rows.append(("envmap_radiance", m, files, chain))
    return rows


def sizes(top: int = 5):
    """The `top` largest modules and functions of the package: (lines, name) each.

    >>> modules, functions = sizes(top=1)
    >>> modules[0][0] <= 600, functions[0][0] <= 120
    (True, True)
    """
    modules, functions = [], []
    for path in sorted(PKG.rglob("*.py")):
        text = path.read_text()
        rel = str(path.relative_to(PKG))
        modules.append((len(text.splitlines()), rel))
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions.append((node.end_lineno - node.lineno + 1, f"{rel}:{node.name}"))
    return sorted(modules, reverse=True)[:top], sorted(functions, reverse=True)[:top]


def method_comparisons():
    """``method == "…"`` outside the method modules and the registry: (file, line)."""
    hits = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG)
        if rel.parts[:2] == ("shading", "methods") or rel == Path("core/methods.py"):
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"method\s*==\s*[\"']", line):
                hits.append((str(rel), i))
    return hits


def main():
    print("| entry point | method | files run | call chain (files) | chain |")
    print("|---|---|---:|---:|---|")
    for entry, m, files, chain in call_paths():
        print(f"| {entry} | {m} | {len(files)} | {len(set(chain))} | {' → '.join(chain)} |")
    mods, fns = sizes()
    print("\nlargest modules:", ", ".join(f"{n} {p}" for n, p in mods))
    print("largest functions:", ", ".join(f"{n} {p}" for n, p in fns))
    hits = method_comparisons()
    print(f'method == "…" outside the methods and the registry: {len(hits)}',
          *(f"{p}:{i}" for p, i in hits))


if __name__ == "__main__":
    main()
