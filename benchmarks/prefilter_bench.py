"""Prefiltering environment maps: warm time per map and agreement with an older checkout.

`prefilter_envmap` (17 levels, 64 × 128) of every shipped map and of any further maps
given (a user's 1k or 2k .hdr/.exr), in float64 and float32, each after a warm-up call on a
small map so that compilation is not counted. With ``--baseline PATH`` (a folder holding an
older ``thinfilm_jax`` package, e.g. ``git worktree add /tmp/old b98e891``, whose prefilter
summed every input texel for every output texel) the old prefilter is timed on the same
maps and the radiance tables are compared per level against the old float64 ones (largest
relative difference over the levels, relative to each level's largest value). Writes
``prefilter_bench.json`` and ``prefilter_bench.md``. Timings never assert anything.

Run: ``python -m benchmarks.prefilter_bench [--out figures] [--baseline DIR]
[--maps PATH ...]``.

Example (the agreement measure: the largest over the levels of max |Δ| / the level's largest
value):
    >>> import numpy as np
    >>> ref = np.ones((2, 1, 1, 3)); ref[1] *= 10.0
    >>> _rel(ref + np.array([0.0, 0.5])[:, None, None, None], ref)
    0.05
"""

from __future__ import annotations

import argparse
import importlib
import time
from pathlib import Path

import jax
import numpy as np

from thinfilm_jax.shading.envmap import SHIPPED, load_envmap
from thinfilm_jax.shading.prefilter import prefilter_envmap
from ._timing import environment, log, write_report
from .kernel_bench import _commit, baseline_record, load_package

DTYPES = (np.float64, np.float32)


def _timed(fn, radiance, dtype):
    t0 = time.perf_counter()
    pref = fn(radiance, dtype=dtype)
    jax.block_until_ready(pref.moments)
    return time.perf_counter() - t0, np.asarray(pref.radiance, np.float64)


def _rel(a, ref):
    """Largest |a − ref| over each level relative to the level's largest |ref|, max over
    levels."""
    scale = np.abs(ref).max(axis=(1, 2, 3))
    return float((np.abs(a - ref).max(axis=(1, 2, 3)) / scale).max())


def run_prefilter_bench(out="figures", *, baseline=None, maps=(), verbose=True) -> dict:
    """Time and compare (module docstring); writes prefilter_bench.json / .md in `out`."""
    fns = {"new": prefilter_envmap}
    if baseline is not None:
        load_package(baseline, "thinfilm_jax_prefilter_baseline")
        fns["old"] = importlib.import_module(
            "thinfilm_jax_prefilter_baseline.shading.prefilter").prefilter_envmap
    for dtype in DTYPES:  # compile first: the rows are warm
        for fn in fns.values():
            fn(np.ones((16, 32, 3)), dtype=dtype, resolution=(8, 16), levels=3)
    rows = []
    for name in [*SHIPPED, *maps]:
        radiance = np.asarray(load_envmap(name).radiance)  # an array: any checkout reads it
        row = {"map": name if name in SHIPPED else Path(name).name,
               "size": list(radiance.shape[:2])}
        tables = {}
        for version, fn in fns.items():
            for dtype in DTYPES:
                key = f"{version} {np.dtype(dtype).name}"
                row[f"{key} s"], tables[key] = _timed(fn, radiance, dtype)
        ref = tables["old float64" if baseline is not None else "new float64"]
        for key, table in tables.items():
            if table is not ref:
                row[f"{key} vs {'old' if baseline is not None else 'new'} float64"] = \
                    _rel(table, ref)
        rows.append(row)
        log(f"  {row}", verbose)
    result = {"environment": environment(), "current_commit": _commit(Path(__file__).resolve().parents[1]),
              "baseline": baseline_record(baseline),
              "rows": rows}
    text = write_report(out, "prefilter_bench", result, report_markdown)
    if verbose:
        print(text)
    return result


def report_markdown(result: dict) -> str:
    env = result["environment"]
    keys = [k for k in result["rows"][0] if k not in ("map", "size")]
    lines = ["## Prefiltering environment maps: warm time and agreement", "",
             f"`prefilter_envmap` (17 levels, 64 × 128 output), warm (compiled beforehand); "
             f"{env['cpu_count']} CPUs, load average at start {env['load_average']}, "
             f"jax {env['jax']}, {env['date']}; commit {result['current_commit']}"
             + (f", old: commit {result['baseline']['commit']}" if result["baseline"] else "")
             + ". Differences: the largest over the levels of max |Δ radiance| / the level's "
             "largest radiance.", "",
             "| map | size | " + " | ".join(keys) + " |",
             "|---|---|" + "---:|" * len(keys)]
    for r in result["rows"]:
        cells = [f"{r[k]:.2f}" if k.endswith(" s") else f"{r[k]:.1e}" for k in keys]
        lines.append(f"| {r['map']} | {r['size'][0]} × {r['size'][1]} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--baseline", help="folder of an older checkout to time and compare against")
    p.add_argument("--maps", nargs="*", default=[], help="further maps (paths) to prefilter")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    run_prefilter_bench(args.out, baseline=args.baseline, maps=args.maps)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
