r"""The cost of every shading method under an environment map, against `filtered`: one table.

`run_method_cost` times `envmap_radiance` of each method of the registry
(`core.methods.names("envmap")`, read when it runs) a shading point, on one map (the shipped
venice_sunset) and one grid of points, and writes ``method_cost.json`` / ``method_cost.md``:
the one artifact the README and the docs quote for what a method costs relative to
`filtered`. The harness is the bins sweep's (`small_sources.bins_cost`): float32 points of
the kernel bench's wide grid (`kernel_bench.shading_points`: films, views, roughness),
each method's call jitted whole and compiled first (compile time apart), every program once
per round, rounds interleaved (`_timing.time_interleaved`), the minimum of `repeats` kept
(the median beside it) and the 1-min load average before each round recorded.

* the real-time methods (``envmap_kind == "realtime"``: ideal, filtered, improved, khr)
  read the map prefiltered once (`prefilter_envmap`, float32, no sun split off, so that
  every method reads the same map); `improved` once per named preset
  (`ModelOptions.preset`: "fast" K = 2, "default" K = 3, "accurate" K = 3 with three reads
  a bin);
* `colour_table` (Kneiphof & Klein 2022) tabulates one material under one map: it shades
  the same normals and views for one film (d = 600 nm, η₂ = 1.3, η₃ = 2.0 + 0.5i) at one
  α, and `filtered` is timed on those same inputs to give its ratio; the table's build
  (`prefilter_colour`) is timed apart, once;
* the exact methods (reference, mc) are float64 references of seconds a thousand points:
  they run on the first `exact_points` points of the grid, float64, the public call
  (its host-side resampling of the map included), one call per round after a first one
  that compiles.

Run: ``python -m benchmarks.method_cost [--out figures] [--points N] [--repeats N]
[--quick]``; ``python -m benchmarks.bench`` writes it too (its ``kernels`` step). Timings
never assert anything.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from ._timing import environment, log, time_interleaved, write_report

MAP = "venice_sunset"
TABLE_FILM = dict(thickness=600.0, eta_film=1.3, eta_base=2.0, kappa_base=0.5)
TABLE_ALPHA = 0.25


def method_programs(presets=("fast", "default", "accurate")):
    """{row name: (method, preset or None, `ModelOptions`)} of the real-time rows: every
    ``envmap_kind == "realtime"`` method of the registry, `improved` once per preset."""
    from thinfilm_jax.core.methods import implementation, names
    from thinfilm_jax.realtime.options import ModelOptions
    from thinfilm_jax.shading.ibl import REALTIME_OPTIONS

    rows = {}
    for m in names("envmap", exact=False):
        if implementation(m).envmap_kind != "realtime":
            continue
        if m == "improved":
            for p in presets:
                q = ModelOptions.preset(p)
                rows[f"improved {p}"] = (m, p, REALTIME_OPTIONS._replace(
                    bins=q.bins, bin_reads=q.bin_reads))
        else:
            rows[m] = (m, None, REALTIME_OPTIONS)
    return rows


def _jit(method, opts, **kw):
    from thinfilm_jax.shading.ibl import envmap_radiance

    return jax.jit(lambda f, a, n, v, p: envmap_radiance(f, a, n, v, p, method=method,
                                                         options=opts, **kw))


def run_method_cost(out="figures", points: int = 2**18, repeats: int = 21,
                    exact_points: int = 64, exact_repeats: int = 3,
                    presets=("fast", "default", "accurate"), table_resolution=(16, 32),
                    verbose: bool = True) -> dict:
    """Time every method (module docstring) and write ``method_cost.json`` / ``.md`` in
    `out`; returns the result."""
    from thinfilm_jax.core.film import Film
    from thinfilm_jax.core.methods import implementation, names
    from thinfilm_jax.shading.colour_table import prefilter_colour
    from thinfilm_jax.shading.envmap import load_envmap
    from thinfilm_jax.shading.ibl import REALTIME_OPTIONS, envmap_radiance
    from thinfilm_jax.shading.prefilter import prefilter_envmap
    from .kernel_bench import F32, shading_points

    env0 = environment()
    pts = shading_points(points)
    film = Film(**pts["film"])
    env = load_envmap(MAP)
    t0 = time.perf_counter()
    pref = prefilter_envmap(env).astype(F32)
    jax.block_until_ready(pref)
    prefilter_s = time.perf_counter() - t0
    args = (film, pts["alpha"], pts["normal"], pts["wo"], pref)
    progs = method_programs(presets)
    calls, compile_s, meta = {}, {}, {}

    def add(name, fn, a, **info):
        log(f"(cost) compile {name}", verbose)
        t = time.perf_counter()
        calls[name] = (fn.lower(*a).compile(), a)
        jax.block_until_ready(calls[name][0](*a))
        compile_s[name] = time.perf_counter() - t
        meta[name] = info

    for name, (m, p, opts) in progs.items():
        add(name, _jit(m, opts), args, method=m, preset=p, inputs="wide grid")
    one = Film(*(jnp.full(points, v, F32) for v in TABLE_FILM.values()), jnp.ones(points, F32))
    alpha1 = jnp.full(points, TABLE_ALPHA, F32)
    args1 = (one, alpha1, pts["normal"], pts["wo"], pref)
    add("filtered (one film, one α)", _jit("filtered", REALTIME_OPTIONS), args1,
        method="filtered", preset=None, inputs="one film, one α")
    table_s = None
    if "colour_table" in names("envmap"):
        log("(cost) colour table build", verbose)
        t = time.perf_counter()
        table = prefilter_colour(env, Film(**TABLE_FILM), TABLE_ALPHA,
                                 resolution=tuple(table_resolution), dtype=F32)
        jax.block_until_ready(table)
        table_s = time.perf_counter() - t
        film1 = Film(**TABLE_FILM)  # the table's own (Python) values: checked equal
        add("colour_table", jax.jit(lambda n, v, tb: envmap_radiance(
            film1, TABLE_ALPHA, n, v, tb, method="colour_table")),
            (pts["normal"], pts["wo"], table), method="colour_table", preset=None,
            inputs="one film, one α")
    log(f"(cost) {repeats} interleaved rounds on {points} points", verbose)
    times, loads = time_interleaved(calls, repeats)
    rows = []
    for name, ts in times.items():
        rows.append({"name": name, **meta[name], "dtype": "float32", "points": points,
                     "ns_min": min(ts) / points * 1e9,
                     "ns_median": statistics.median(ts) / points * 1e9,
                     "compile_s": compile_s[name]})
    # the exact methods: float64, a few points, the public call
    sub = slice(0, min(exact_points, points))
    a64 = (Film(**{k: jnp.asarray(np.asarray(v)[sub], jnp.float64)
                   for k, v in pts["film"].items()}),
           *(jnp.asarray(np.asarray(x)[sub], jnp.float64)
             for x in (pts["alpha"], pts["normal"], pts["wo"])))
    exact_loads = []
    for m in names("envmap", exact=True):
        if implementation(m).envmap_kind != "exact":
            continue
        log(f"(cost) {m}, {len(a64[1])} points float64", verbose)
        t = time.perf_counter()
        jax.block_until_ready(envmap_radiance(*a64, env, method=m))
        first = time.perf_counter() - t
        ts = []
        for _ in range(exact_repeats):
            exact_loads.append(_load())
            t = time.perf_counter()
            jax.block_until_ready(envmap_radiance(*a64, env, method=m))
            ts.append(time.perf_counter() - t)
        n = len(a64[1])
        rows.append({"name": m, "method": m, "preset": None, "inputs": "wide grid (first "
                     f"{n} points)", "dtype": "float64", "points": n,
                     "ns_min": min(ts) / n * 1e9, "ns_median": statistics.median(ts) / n * 1e9,
                     "compile_s": max(first - min(ts), 0.0)})
    by = {r["name"]: r for r in rows}
    for r in rows:
        base = by["filtered (one film, one α)" if r["inputs"] == "one film, one α"
                  else "filtered"]
        r["x_filtered"] = r["ns_min"] / base["ns_min"]
        r["x_filtered_median"] = r["ns_median"] / base["ns_median"]
    result = {"environment": env0, "map": MAP, "map_shape": list(env.shape),
              "prefilter_s": prefilter_s, "colour_table_build_s": table_s,
              "colour_table": {"film": TABLE_FILM, "alpha": TABLE_ALPHA,
                               "resolution": list(table_resolution)},
              "points": points, "repeats": repeats, "exact_repeats": exact_repeats,
              "load_average_per_round": loads, "load_average_exact": exact_loads,
              "command": f"python -m benchmarks.method_cost --points {points} "
                         f"--repeats {repeats}", "rows": rows}
    text = write_report(out, "method_cost", result, markdown)
    if verbose:
        print(text)
    return result


def _load():
    import os

    return list(os.getloadavg()) if hasattr(os, "getloadavg") else None


def markdown(result) -> str:
    """The table of `run_method_cost`'s result."""
    env = result["environment"]
    loads = [x[0] for x in result["load_average_per_round"] if x]
    lines = [
        "## Cost of each method a shading point under an environment map, against `filtered`",
        "",
        f"`{result['command']}` on {', '.join(env['devices'])} ({env['cpu_count']} CPUs, "
        f"shared), jax {env['jax']}, {env['date']}; 1-min load average per round: "
        + ", ".join(f"{x:.1f}" for x in loads) + ".",
        "",
        f"`envmap_radiance` of each method of the registry on {result['points']:,} float32 "
        f"points of the kernel bench's wide grid (films, views, α ∈ [0.02, 0.8]) under the "
        f"shipped {result['map']} ({result['map_shape'][0]} × {result['map_shape'][1]}), "
        f"prefiltered once ({result['prefilter_s']:.1f} s, apart, no sun split off); each call "
        "jitted whole and compiled first (apart); every program once a round, "
        f"{result['repeats']} rounds interleaved; ns a point: the minimum (the median in "
        "brackets); × `filtered`: of the minima, against `filtered` on the same inputs. "
        f"`colour_table` shades the same normals and views for one film at one α "
        f"(d = {result['colour_table']['film']['thickness']:g} nm, "
        f"α = {result['colour_table']['alpha']:g}), its table built once apart "
        f"({fmt_s(result['colour_table_build_s'])}); the exact methods run float64 on the "
        "first points of the grid, through the public call.",
        "",
        "| method | setting | inputs | dtype | ns a point | × `filtered` | compile s |",
        "|---|---|---|---|---:|---:|---:|"]
    for r in result["rows"]:
        setting = r["preset"] and f'preset "{r["preset"]}"' or "default"
        lines.append(f"| {r['method']} | {setting} | {r['inputs']} | {r['dtype']} "
                     f"| {r['ns_min']:,.0f} ({r['ns_median']:,.0f}) | {_x(r['x_filtered'])} "
                     f"| {r['compile_s']:.1f} |")
    return "\n".join(lines) + "\n"


def _x(ratio) -> str:
    """A ratio to `filtered`: two decimals, whole thousands-separated numbers from 100 up.

    Example:
        >>> _x(2.3149), _x(218977.67)
        ('2.31', '218,978')
    """
    return f"{ratio:,.0f}" if ratio >= 100 else f"{ratio:.2f}"


def fmt_s(x):
    return "—" if x is None else f"{x:.1f} s"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.method_cost", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures")
    p.add_argument("--points", type=int, default=2**18)
    p.add_argument("--repeats", type=int, default=21)
    p.add_argument("--exact-points", type=int, default=64)
    p.add_argument("--quick", action="store_true", help="4096 points, 3 rounds, 16 exact")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    from thinfilm_jax.core.compilation_cache import enable_compilation_cache

    enable_compilation_cache()
    if args.quick:
        run_method_cost(args.out, points=4096, repeats=3, exact_points=16, exact_repeats=1)
    else:
        run_method_cost(args.out, points=args.points, repeats=args.repeats,
                        exact_points=args.exact_points)
    return 0


if __name__ == "__main__":
    sys.exit(main())
