"""Real-time kernels against the machine: XLA cost per shading point and warm time.

For each real-time kernel (`kernels.filtered_kernel`, `kernels.ideal_kernel`,
`improved.improved_kernel`, all with Ŝ from the LUT, and `envmap_radiance` with
method ideal / filtered / improved on a prefiltered map, and filtered / improved with one
sun split from the map, `sources`), float32, `points` shading points:

* XLA's cost analysis of the compiled program (`jax.jit(f).lower(...).compile()
  .cost_analysis()`): flops, transcendentals and bytes accessed, per point. Deterministic
  for a given jax/XLA version: the lead figures. Beside them, the floor and the cause: the
  bytes of the per-point arguments and results (what one fused loop would move) and the
  number of XLA kernels (fusions) in the compiled program, each of which writes an
  intermediate array that later kernels read back. On XLA:CPU the kernels split where an
  expensive value (a sqrt or a divide) has users in more than one fusion: the instruction
  fusion pass does not duplicate it ("too expensive to duplicate", its VLOG), so the value
  goes through memory.
* the warm time per point: calls interleaved over every program (old and new), the minimum
  of `repeats` kept (the machine is shared; the minimum is the least disturbed run), compile
  time apart (the explicit lower + compile of the cost analysis, or first call − warm);
* the fraction of the elementwise peak: flops per second of the kernel against a fused
  float32 multiply-add loop over 2²⁰ values measured in the same run, same repeats.

With a baseline checkout (``--baseline PATH``, a folder holding an older ``thinfilm_jax``
package, e.g. a ``git worktree`` of an earlier commit) its kernels are loaded under another
module name and timed interleaved with the current ones: before/after in one run. Writes
``kernel_bench.json`` and ``kernel_bench.md``. Timings never assert anything.

Run: ``python -m benchmarks.kernel_bench [--out figures] [--quick]
[--baseline /path/to/old/checkout] [--repeats N]``.

Reference mode (``--reference [CHECKOUT ...]``, `run_reference_bench`): the float64 IBL
reference (`envmap_radiance(method="reference")`) of this checkout and of each older
checkout given, on the points of an 8 px sphere at α = 0.05, 0.25, 0.6, interleaved;
writes ``reference_bench.json`` / ``.md``.

Per-size mode (``--sizes N ...``, `run_size_bench`): the envmap paths only (ideal,
filtered, improved, and filtered / improved with one sun) at each point count and each
chunk size ``--batch-sizes B ...`` (`envmap_radiance`'s `batch_size`: the points are shaded
`B` at a time by ``lax.map``; 0 = its default), all programs interleaved in one run, the
minimum of ``--repeats`` kept and the load average before each round recorded; prints the
cost ratios filtered / ideal and improved / filtered (and with the sun) per size. Writes
``kernel_bench_sizes.json`` / ``.md``; ``--append`` adds the run to those already there.
E.g. ``--sizes 65536 1048576 3686400`` (3,686,400 = 2560 × 1440, a 1440p frame).

Example (the cost of one fused loop: y = 2x + 1 reads 4 B and writes 4 B of float32 and
does two flops per point, no transcendental, in one kernel that moves only its inputs and
outputs):
    >>> import jax, jax.numpy as jnp
    >>> c = cost_per_point(jax.jit(lambda x: x * 2.0 + 1.0), (jnp.ones(1024, jnp.float32),),
    ...                    1024)
    >>> c["flops"], c["transcendentals"], c["bytes_accessed"], c["io_bytes"], c["fusions"]
    (2.0, 0.0, 8.0, 8.0, 1)
    >>> c["loops"]
    []
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import re
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ._timing import environment, log, time_interleaved, write_report

F32 = jnp.float32
PEAK_VALUES = 2**20
PEAK_DEPTH = 64  # fused multiply-adds per value in the peak loop
KERNELS = ("filtered_kernel", "ideal_kernel", "improved_kernel", "envmap ideal",
           "envmap filtered", "envmap improved", "envmap filtered + 1 sun",
           "envmap improved + 1 sun")


def load_package(path, alias: str = "thinfilm_jax_baseline"):
    """The ``thinfilm_jax`` package under folder `path`, imported as module `alias`."""
    root = Path(path) / "thinfilm_jax"
    spec = importlib.util.spec_from_file_location(alias, root / "__init__.py",
                                                  submodule_search_locations=[str(root)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[alias] = mod
    spec.loader.exec_module(mod)
    _resolve_own_methods(mod)
    return mod


def _resolve_own_methods(pkg) -> None:
    """Bind the method registry of a checkout loaded under another name to its own modules.
    A registry (``core.methods``) before 2026-12-06 imported each row's implementation as
    ``thinfilm_jax.<module>``, which under an alias is this checkout's code: its map path
    then called the current method objects with its own configuration tuple. Resolving every
    row here, from the alias, gives each checkout its own methods."""
    methods = _module(pkg, "core.methods")
    if methods is None or not hasattr(methods, "_RESOLVED"):
        return
    for name, row in methods.METHODS.items():
        if isinstance(row.impl, str):
            module, attr = row.impl.split(":")
            methods._RESOLVED[name] = getattr(importlib.import_module(f"{pkg.__name__}.{module}"),
                                              attr)


def _module(pkg, *names):
    """The first of `names` (dotted, under `pkg`) that exists: the layered path of this
    package (``realtime.kernels``) or the flat one of an older checkout (``kernels``);
    None when none does."""
    for name in names:
        full = f"{pkg.__name__}.{name}"
        try:
            if importlib.util.find_spec(full) is not None:
                return importlib.import_module(full)
        except ModuleNotFoundError:  # a parent package that this checkout lacks
            continue
    return None


def _commit(path) -> str | None:
    try:
        return subprocess.run(["git", "-C", str(path), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def baseline_record(baseline) -> dict | None:
    """The "baseline" entry of a before/after report: the checkout's path and commit."""
    return None if baseline is None else {"path": str(baseline), "commit": _commit(baseline)}


def shading_points(n: int, seed: int = 0):
    """`n` float32 shading points on a wide grid: films (d ∈ [0, 1000] nm, η₂ ∈ [1.2, 2.4],
    absorbing bases), views θ_o ∈ [0°, 85°], α ∈ [0.02, 0.8], and the light moments of
    the uniform-light lobe (`kernels.lobe_moments` on a 16 × 8 (θ_o, α) grid, nearest node)."""
    from thinfilm_jax.realtime.kernels import lobe_moments

    rng = np.random.default_rng(seed)
    tg, ag = np.linspace(0.0, np.radians(85.0), 16), np.linspace(0.02, 0.8, 8)
    _, mean, cov = (np.asarray(x) for x in lobe_moments(tg[:, None], ag[None, :],
                                                        quadrature=(16, 16)))
    it, ia = rng.integers(0, 16, n), rng.integers(0, 8, n)
    wo = np.stack([np.sin(tg[it]), np.zeros(n), np.cos(tg[it])], -1)
    film = dict(thickness=rng.uniform(0, 1000, n), eta_film=rng.uniform(1.2, 2.4, n),
                eta_base=rng.uniform(1.0, 2.5, n), kappa_base=rng.uniform(0.0, 3.0, n),
                eta_outer=np.ones(n))
    return dict(film={k: jnp.asarray(x, F32) for k, x in film.items()}, wo=jnp.asarray(wo, F32),
                mean=jnp.asarray(mean[it, ia], F32), cov=jnp.asarray(cov[it, ia], F32),
                cos_o=jnp.asarray(wo[:, 2], F32), alpha=jnp.asarray(ag[ia], F32),
                normal=jnp.asarray(np.tile([0.0, 0.0, 1.0], (n, 1)), F32))


def programs(pkg, pts, pref_np, envmap: bool = True, batch_size: int | None = None):
    """{kernel name: (jitted callable, args)} of package `pkg` (this one or a baseline);
    `batch_size`: the envmap programs' chunk (`envmap_radiance(batch_size=...)`), None for
    its default."""
    K = _module(pkg, "realtime.kernels", "kernels")
    I = _module(pkg, "realtime.improved", "improved")  # noqa: E741
    L = _module(pkg, "spectral.lut", "lut")
    film = pkg.Film(**pts["film"])  # by field name: the same in every checkout's Film
    lut = L.build_shat_lut(dtype=F32)
    tab = I.bin_table(dtype=F32)
    out = {
        "filtered_kernel": (jax.jit(lambda f, w, m, c, lt: K.filtered_kernel(
            f, w, m, c, shat="lut", lut=lt)), (film, pts["wo"], pts["mean"], pts["cov"], lut)),
        "ideal_kernel": (jax.jit(lambda f, c, lt: K.ideal_kernel(f, c, shat="lut", lut=lt)),
                         (film, pts["cos_o"], lut)),
        "improved_kernel": (jax.jit(lambda f, c, a, tb, lt: I.improved_kernel(
            f, c, a, tb, shat="lut", lut=lt)), (film, pts["cos_o"], pts["alpha"], tab, lut)),
    }
    if envmap:
        P = _module(pkg, "shading.prefilter", "prefilter")
        ibl = _module(pkg, "shading.ibl", "ibl")
        kw = {} if batch_size is None else {"batch_size": int(batch_size)}
        pref = P.PrefilteredEnvMap(*(jnp.asarray(x, F32) for x in pref_np[:4]),
                                   L.ShatLUT(*pref_np[4]))
        for method in ("ideal", "filtered", "improved"):
            out[f"envmap {method}"] = (
                jax.jit(lambda f, a, n, v, p, m=method: ibl.envmap_radiance(
                    f, a, n, v, p, method=m, **kw)),
                (film, pts["alpha"], pts["normal"], pts["wo"], pref))
        S = _module(pkg, "shading.sources", "sources")
        if S is not None:
            sun = S.Sources(jnp.asarray([[0.6, 0.0, 0.8]], F32), jnp.asarray([6e-5], F32),
                            jnp.asarray([[5e4, 4.6e4, 4.1e4]], F32))  # one 0.5° sun
            sun = S.with_film_tables(sun, "stiles_burch_1959_10", F32).astype(F32)
            for method in ("filtered", "improved"):
                out[f"envmap {method} + 1 sun"] = (
                    jax.jit(lambda f, a, n, v, p, m=method: ibl.envmap_radiance(
                        f, a, n, v, p, method=m, **kw)),
                    (film, pts["alpha"], pts["normal"], pts["wo"], pref._replace(sources=sun)))
    return out


def cost_per_point(fn, args, n: int, compiled=None) -> dict:
    """XLA's cost analysis of the compiled `fn(*args)`, divided by the point count, and the
    known trip counts of its while loops (`loops`, in program order). XLA counts a loop's
    body once (HloCostAnalysis::HandleWhile): where `loops` is not empty the figures are
    one step of each loop plus what the loops carry, not the whole run. `io_bytes`: the
    per-point arguments and results (leading axis `n`; the tables, shared by all points,
    left out) per point, the traffic of one fused loop; `fusions`: the XLA
    kernels of the compiled program (loop bodies counted once). `compiled`: the program
    already compiled from ``fn.lower(*args)`` (else compiled here)."""
    compiled = fn.lower(*args).compile() if compiled is None else compiled
    ca = compiled.cost_analysis()
    ca = ca[0] if isinstance(ca, list) else ca
    text = compiled.as_text()
    loops = [int(t) for t in re.findall(r' while\(.*?"known_trip_count":\{"n":"(\d+)"\}',
                                        text)]
    io = sum(np.dtype(x.dtype).itemsize * x.size  # per-point arrays; tables are shared
             for x in jax.tree.leaves((args, jax.eval_shape(fn, *args)))
             if x.ndim and x.shape[0] == n)
    return {"flops": ca.get("flops", 0.0) / n, "transcendentals":
            ca.get("transcendentals", 0.0) / n, "bytes_accessed": ca.get("bytes accessed",
                                                                          0.0) / n,
            "io_bytes": io / n, "fusions": text.count(" fusion("),
            "loops": loops}


def peak_program():
    """A fused float32 multiply-add chain over 2²⁰ values (one XLA loop): the elementwise
    peak of the machine. Returns (callable, args, flops per call)."""
    def f(x, a, b):
        for _ in range(PEAK_DEPTH):
            x = x * a + b
        return x

    x = jnp.linspace(0.0, 1.0, PEAK_VALUES, dtype=F32)
    return jax.jit(f), (x, F32(0.999), F32(1e-3)), 2.0 * PEAK_DEPTH * PEAK_VALUES


def _timed(fn, args) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - t0


def run_kernel_bench(out="figures", *, points: int = 65536, repeats: int = 7,
                     baseline=None, envmap: bool = True, verbose: bool = True) -> dict:
    """Measure every kernel (module docstring) and write kernel_bench.json / .md in `out`."""
    import thinfilm_jax as current

    from thinfilm_jax.shading.prefilter import prefilter_envmap

    out = Path(out)
    env = environment()
    log(f"kernel bench: {points} float32 points, {repeats} interleaved repeats", verbose)
    pts = shading_points(points)
    pref_np = None
    if envmap:
        pref = prefilter_envmap("venice_sunset").astype(F32)
        pref_np = (*pref[:4], tuple(pref.lut))
    versions = {"new": programs(current, pts, pref_np, envmap)}
    if baseline is not None:
        versions["old"] = programs(load_package(baseline), pts, pref_np, envmap)
    peak_fn, peak_args, peak_flops = peak_program()
    rows, timed = [], {}
    for version, progs in versions.items():
        for name, (fn, args) in progs.items():
            t0 = time.perf_counter()
            cost = cost_per_point(fn, args, points)  # lowers and compiles: the compile time
            lowered_s = time.perf_counter() - t0
            first = _timed(fn, args)  # the jitted call's own compile (or cache hit) + run
            row = {"kernel": name, "version": version, **cost, "first_call_s": first,
                   "lower_compile_s": lowered_s}
            rows.append(row)
            timed[len(rows) - 1] = (fn, args)
            log(f"  {version} {name}: {cost['bytes_accessed']:.0f} B/point", verbose)
    _timed(peak_fn, peak_args)
    # interleaved: every program once per round, the peak loop too
    times, _ = time_interleaved({"peak": (peak_fn, peak_args), **timed}, repeats)
    peak = peak_flops / min(times["peak"])
    for i, row in enumerate(rows):
        row["times_s"] = times[i]
        t = min(row["times_s"])
        row["ns_per_point"] = t / points * 1e9
        row["ns_per_point_median"] = float(np.median(row["times_s"])) / points * 1e9
        # compile time apart from the warm time: the larger of the explicit lower + compile
        # (with the cost analysis) and the first call less a warm one (jit may reuse it)
        row["compile_s"] = max(row["lower_compile_s"], row["first_call_s"] - t, 0.0)
        row["gflops_per_s"] = row["flops"] * points / t / 1e9
        row["fraction_of_peak"] = row["flops"] * points / t / peak
    speedup = {}
    if baseline is not None:
        by = {(r["kernel"], r["version"]): r for r in rows}
        for name in versions["new"]:
            o, n = by.get((name, "old")), by.get((name, "new"))
            if o and n:
                speedup[name] = {"time": o["ns_per_point"] / n["ns_per_point"],
                                 "bytes": o["bytes_accessed"] / n["bytes_accessed"]}
    result = {"environment": env, "points": points, "repeats": repeats,
              "baseline": baseline_record(baseline),
              "current_commit": _commit(Path(current.__file__).parent.parent),
              "peak_gflops_per_s": peak / 1e9,
              "peak_loop": f"{PEAK_DEPTH} fused float32 multiply-adds over {PEAK_VALUES} "
                           "values, minimum of the same interleaved repeats",
              "rows": [{k: v for k, v in r.items() if k != "times_s"} for r in rows],
              "speedup_old_over_new": speedup}
    text = write_report(out, "kernel_bench", result, report_markdown)
    if verbose:
        print(text)
    return result


def run_reference_bench(out="figures", *, baselines=(), alphas=(0.05, 0.25, 0.6),
                        resolution: int = 8, repeats: int = 5, verbose: bool = True) -> dict:
    """The IBL reference (`envmap_radiance(method="reference")`, float64, the public call) of
    this checkout and of each baseline checkout on the same points: the shading points of an
    8 px sphere (Figure 4's film, d = 600 nm, η₂ = 1.2 on η₃ = 2.0) under the shipped
    128 × 256 venice_sunset, every version timed once per round, rounds interleaved, warm
    minima (compile apart). Writes ``reference_bench.json`` / ``.md`` in `out`."""
    import thinfilm_jax as current

    from thinfilm_jax.render.study_scenes import camera, sphere

    if not jax.config.jax_enable_x64:
        raise RuntimeError("the reference bench needs float64: jax_enable_x64")
    out = Path(out)
    env = environment()
    wo, right, up = camera(0.7, 15.0)
    mask, n = sphere(resolution, wo, right, up)
    pts = np.asarray(n[mask])
    k = len(pts)
    versions = {"new": current}
    for i, b in enumerate(baselines):
        versions[f"old {i + 1}"] = load_package(b, alias=f"thinfilm_jax_baseline{i}")
    rows, calls = [], {}
    for version, pkg in versions.items():
        emap = _module(pkg, "shading.envmap", "envmap").load_envmap("venice_sunset")
        ibl = _module(pkg, "shading.ibl", "ibl")
        film = pkg.Film(*(jnp.full(k, x) for x in (600.0, 1.2, 2.0, 0.0)))
        for alpha in alphas:
            args = (film, jnp.full(k, alpha), jnp.asarray(pts),
                    jnp.broadcast_to(jnp.asarray(wo), pts.shape), emap)

            def call(*a, ibl=ibl):
                return ibl.envmap_radiance(*a, method="reference")

            t0 = time.perf_counter()
            jax.block_until_ready(call(*args))
            row = {"version": version, "alpha": alpha, "points": k,
                   "first_call_s": time.perf_counter() - t0}
            rows.append(row)
            calls[len(rows) - 1] = (call, args)
            log(f"  {version} α = {alpha:g}: first call {row['first_call_s']:.1f} s", verbose)
    times, loads = time_interleaved(calls, repeats, lambda i, load: log(
        f"  round {i + 1}/{repeats}, load {load}", verbose))
    for i, row in enumerate(rows):
        row["warm_s"] = min(times[i])
        row["points_per_s"] = k / row["warm_s"]
        row["compile_s"] = max(row["first_call_s"] - row["warm_s"], 0.0)
    by = {(r["version"], r["alpha"]): r for r in rows}
    result = {"environment": env, "repeats": repeats, "points": k,
              "current_commit": _commit(Path(current.__file__).parent.parent),
              "baselines": [baseline_record(b) for b in baselines],
              "load_average_per_round": loads, "rows": rows,
              "speedup": {v: {str(a): by[(v, a)]["warm_s"] / by[("new", a)]["warm_s"]
                              for a in alphas} for v in versions if v != "new"}}
    text = write_report(out, "reference_bench", result, reference_markdown)
    if verbose:
        print(text)
    return result


def reference_markdown(result: dict) -> str:
    env = result["environment"]
    names = {"new": f"this checkout ({result['current_commit']})"}
    names.update({f"old {i + 1}": f"{b['commit']} ({b['path']})"
                  for i, b in enumerate(result["baselines"])})
    lines = ["## The IBL reference against older checkouts", "",
             f"`envmap_radiance(method=\"reference\")`, float64, the {result['points']} "
             "shading points of an 8 px sphere (d = 600 nm, η₂ = 1.2 on η₃ = 2.0) under the "
             f"shipped 128 × 256 venice_sunset; {env['devices']}, {env['cpu_count']} CPUs, "
             f"jax {env['jax']}, {env['date']}; every version once per round, "
             f"{result['repeats']} rounds interleaved, warm minima; 1-min load average per "
             "round: " + ", ".join(f"{x[0]:.1f}" for x in result["load_average_per_round"])
             + ".", "", "| version | α | points / s | warm s | compile s | × this checkout |",
             "|---|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        sp = result["speedup"].get(r["version"], {}).get(str(r["alpha"]))
        lines.append(f"| {names[r['version']]} | {r['alpha']:g} | {r['points_per_s']:.0f} | "
                     f"{r['warm_s']:.3f} | {r['compile_s']:.1f} | "
                     + ("—" if sp is None else f"{1 / sp:.3f} (new {sp:.1f}× faster)") + " |")
    return "\n".join(lines) + "\n"


def report_markdown(result: dict) -> str:
    """The table: cost analysis first (deterministic), then the warm times."""
    env = result["environment"]
    lines = ["## Real-time kernels: XLA cost and warm time per shading point", "",
             f"{result['points']} float32 shading points; {env['devices']}, "
             f"{env['cpu_count']} CPUs, load average at start {env['load_average']}, "
             f"jax {env['jax']}, {env['date']}. Cost: XLA cost analysis of the compiled "
             "program (deterministic); XLA counts a while loop's body once, so where the "
             "loops column lists trip counts (the table reads as loop steps) flops and bytes "
             "are one step of each loop plus what the loops carry; in + out: the arguments and "
             "results per point, tables left out (what one fused loop would move); XLA "
             "kernels: fusions in "
             "the compiled program, each writing an intermediate array. Time: minimum of "
             f"{result['repeats']} interleaved warm calls (median in brackets; a shared, "
             f"noisy machine). Elementwise peak in the same run: "
             f"{result['peak_gflops_per_s']:.1f} GFLOP/s ({result['peak_loop']}).", ""]
    if result["baseline"]:
        lines += [f"old: {result['baseline']['path']} (commit {result['baseline']['commit']});"
                  f" new: commit {result['current_commit']}.", ""]
    lines += ["| kernel | version | flops / pt | transcendentals / pt | bytes / pt "
              "| in + out B / pt | XLA kernels | loops | ns / pt | compile s | GFLOP/s "
              "| fraction of peak |",
              "|---|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|"]
    for r in sorted(result["rows"], key=lambda r: (KERNELS.index(r["kernel"]), r["version"])):
        loops = " ".join(str(t) for t in r.get("loops", [])) or "–"
        lines.append(f"| {r['kernel']} | {r['version']} | {r['flops']:.0f} "
                     f"| {r['transcendentals']:.1f} | {r['bytes_accessed']:.0f} "
                     f"| {r.get('io_bytes', float('nan')):.0f} | {r.get('fusions', '–')} "
                     f"| {loops} "
                     f"| {r['ns_per_point']:.0f} ({r['ns_per_point_median']:.0f}) "
                     f"| {r['compile_s']:.1f} | {r['gflops_per_s']:.2f} "
                     f"| {r['fraction_of_peak']:.3f} |")
    if result["speedup_old_over_new"]:
        lines += ["", "Old / new: " + "; ".join(
            f"{k}: time {v['time']:.1f}×, bytes {v['bytes']:.1f}×"
            for k, v in result["speedup_old_over_new"].items())]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ per-size mode (--sizes)
SIZE_KERNELS = ("envmap ideal", "envmap filtered", "envmap improved",
                "envmap filtered + 1 sun", "envmap improved + 1 sun")
FRAME_1440P = 2560 * 1440  # the shading points of a 1440p frame (Kneiphof et al. 2019, §6)
#: (name, numerator, denominator) of the cost ratios the sizes table reports; targets ≤ 1.5
RATIOS = (("filtered / ideal", "envmap filtered", "envmap ideal"),
          ("improved / filtered", "envmap improved", "envmap filtered"),
          ("improved+sun / filtered+sun", "envmap improved + 1 sun",
           "envmap filtered + 1 sun"),
          ("improved+sun / filtered", "envmap improved + 1 sun", "envmap filtered"))
RATIO_TARGET = 1.5


def size_ratios(rows: list, key: str = "ns_per_point") -> list:
    """The `RATIOS` of every (points, batch_size) group of `rows`, from `key`."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["points"], r["batch_size"]), {})[r["kernel"]] = r[key]
    out = []
    for (points, batch), t in groups.items():
        row = {"points": points, "batch_size": batch}
        for name, num, den in RATIOS:
            row[name] = t[num] / t[den] if num in t and den in t else None
        out.append(row)
    return out


def run_size_bench(out="figures", *, sizes=(65536, 2**20, FRAME_1440P), batch_sizes=(None,),
                   repeats: int = 5, append: bool = False, stem: str = "kernel_bench_sizes",
                   verbose: bool = True) -> dict:
    """The envmap paths (`SIZE_KERNELS`) at several point counts and chunk sizes
    (`envmap_radiance(batch_size=...)`, None: its default), every program timed once per
    round, rounds interleaved, the minimum of `repeats` kept; the load average before
    each round is recorded. Writes ``<stem>.json`` / ``.md`` in `out`; with `append` the
    run is added to the runs already there (one file holds several runs, each < 5 min)."""
    import json

    import thinfilm_jax as current

    from thinfilm_jax.shading.prefilter import prefilter_envmap

    out = Path(out)
    env = environment()
    pref = prefilter_envmap("venice_sunset").astype(F32)
    pref_np = (*pref[:4], tuple(pref.lut))
    rows, timed = [], {}
    for n in sizes:
        pts = shading_points(int(n))
        for b in batch_sizes:
            progs = programs(current, pts, pref_np, True, b)
            for name in SIZE_KERNELS:
                fn, args = progs[name]
                t0 = time.perf_counter()
                compiled = fn.lower(*args).compile()
                compile_s = time.perf_counter() - t0
                cost = cost_per_point(fn, args, int(n), compiled=compiled)
                _timed(compiled, args)  # first run: allocations, page faults
                row = {"points": int(n), "batch_size": b, "kernel": name,
                       "bytes_accessed": cost["bytes_accessed"], "fusions": cost["fusions"],
                       "loops": cost["loops"], "compile_s": compile_s}
                rows.append(row)
                timed[len(rows) - 1] = (compiled, args)
                log(f"  {n} points, batch {b}, {name}: compiled in {compile_s:.1f} s", verbose)
    times, loads = time_interleaved(timed, repeats, lambda i, load: log(
        f"  round {i + 1}/{repeats}, load {load}", verbose))
    for i, row in enumerate(rows):
        row["times_s"] = times[i]
        row["ns_per_point"] = min(row["times_s"]) / row["points"] * 1e9
        row["ns_per_point_median"] = float(np.median(row["times_s"])) / row["points"] * 1e9
        row["median_over_min"] = row["ns_per_point_median"] / row["ns_per_point"]
    import os

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    run = {"environment": env, "cpus_usable": cpus, "sizes": [int(n) for n in sizes],
           "batch_sizes": list(batch_sizes), "repeats": repeats,
           "current_commit": _commit(Path(current.__file__).parent.parent),
           "load_average_per_round": loads, "rows": rows,
           "ratios": size_ratios(rows), "ratios_median": size_ratios(rows, "ns_per_point_median")}
    path = out / f"{stem}.json"
    runs = json.loads(path.read_text())["runs"] if append and path.exists() else []
    result = {"target": RATIO_TARGET, "runs": runs + [run]}
    text = write_report(out, stem, result, sizes_markdown)
    if verbose:
        print(text)
    return result


def _batch(b) -> str:
    return "default" if b is None else f"{b:,}"


def sizes_markdown(result: dict) -> str:
    """Per run: the ratio table (minimum times; medians in brackets), then the times."""
    lines = ["## Envmap paths per frame size: cost ratios and time per shading point", "",
             "float32 shading points of `shading_points` (wide grid of films, views, α) under "
             "the prefiltered venice_sunset map; `envmap_radiance` of each method, `batch_size` "
             "(the chunk of its `lax.map`) as listed (default: the library's). Each run times "
             "every program once per round, rounds interleaved; a ratio is of the minima "
             f"(of the medians in brackets). Target: each ratio ≤ {result['target']}. The "
             "machine is shared: the load average before each round is listed (2 CPUs). "
             "XLA bytes / pt: the cost analysis of the whole program over its points; XLA "
             "counts a while loop's body once, so where loops lists the chunk loop (its trip "
             "count last) the figure is one chunk's traffic plus what the loop carries, spread "
             "over all points: compare it only within one size and batch.", ""]
    for k, run in enumerate(result["runs"], 1):
        env = run["environment"]
        loads = [f"{x[0]:.1f}" for x in run["load_average_per_round"] if x]
        lines += [f"### Run {k}: {env['date']}, commit {run['current_commit']}", "",
                  f"{run['repeats']} rounds; {env['devices']}, {env['cpu_count']} CPUs "
                  f"({run.get('cpus_usable') or env['cpu_count']} usable by the run), "
                  f"jax {env['jax']}; 1-min load average per round: {', '.join(loads)}.", "",
                  "| points | batch | " + " | ".join(n for n, _, _ in RATIOS) + " |",
                  "|---:|---:|" + "---:|" * len(RATIOS)]
        med = {(r["points"], r["batch_size"]): r for r in run["ratios_median"]}
        for r in run["ratios"]:
            m = med[(r["points"], r["batch_size"])]
            cells = [f"{r[n]:.2f} ({m[n]:.2f})" if r[n] is not None else "–"
                     for n, _, _ in RATIOS]
            lines.append(f"| {r['points']:,} | {_batch(r['batch_size'])} | "
                         + " | ".join(cells) + " |")
        lines += ["", "| points | batch | kernel | ns / pt min (median) | median / min "
                  "| XLA bytes / pt | XLA kernels | loops | compile s |",
                  "|---:|---:|---|---:|---:|---:|---:|---|---:|"]
        for r in run["rows"]:
            loops = " ".join(str(t) for t in r["loops"]) or "–"
            lines.append(f"| {r['points']:,} | {_batch(r['batch_size'])} | {r['kernel']} "
                         f"| {r['ns_per_point']:.0f} ({r['ns_per_point_median']:.0f}) "
                         f"| {r['median_over_min']:.2f} | {r['bytes_accessed']:.0f} "
                         f"| {r['fusions']} | {loops} | {r['compile_s']:.1f} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--quick", action="store_true", help="4096 points, 3 repeats")
    p.add_argument("--points", type=int, default=65536)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--baseline", help="folder of an older checkout to time against")
    p.add_argument("--no-envmap", action="store_true", help="the per-point kernels only")
    p.add_argument("--sizes", type=int, nargs="+", metavar="N",
                   help="per-size mode: the envmap paths at these point counts "
                        f"(e.g. 65536 1048576 {FRAME_1440P}), ratios per size")
    p.add_argument("--batch-sizes", type=int, nargs="+", metavar="B",
                   help="per-size mode: envmap_radiance chunk sizes (0: its default)")
    p.add_argument("--append", action="store_true",
                   help="per-size mode: add this run to the runs in the existing report")
    p.add_argument("--reference", nargs="*", metavar="CHECKOUT",
                   help="reference mode: the float64 IBL reference of this checkout and of "
                        "these older ones (reference_bench.json / .md)")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    if args.reference is not None:
        run_reference_bench(args.out, baselines=tuple(args.reference),
                            repeats=3 if args.quick else args.repeats)
        return 0
    if args.sizes:
        batch = tuple(b or None for b in (args.batch_sizes or [0]))
        run_size_bench(args.out, sizes=args.sizes, batch_sizes=batch,
                       repeats=3 if args.quick else args.repeats, append=args.append)
        return 0
    points, repeats = (4096, 3) if args.quick else (args.points, args.repeats)
    run_kernel_bench(args.out, points=points, repeats=repeats, baseline=args.baseline,
                     envmap=not args.no_envmap)
    return 0


if __name__ == "__main__":
    sys.exit(main())
