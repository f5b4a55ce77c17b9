"""A prepared accelerator check: the test suite and the GPU table of the bench in one run.

A GPU slot is short (minutes), so everything is decided here in advance and the run only
measures. ``make gpu-check`` (on the accelerator machine, offline, dependencies installed
from the wheels that ``make gpu-wheels`` downloads beforehand) runs

1. the test suite (``pytest``, with ``pytest-xdist`` workers when it is installed), under a
   time budget; its summary line, counts and failures go into the JSON;
2. the GPU table: Airy reflectance over 10⁶ and 10⁷ (cos θ, λ) pairs (float32 and float64);
   a 2560 × 1440 frame of shading points under a prefiltered map for ``ideal``,
   ``filtered`` and ``improved`` (float32); reference patches (float64); a reference fit
   cold and warm in two fresh processes sharing JAX's persistent compilation cache;
3. the kernel bench (`kernel_bench.run_kernel_bench`, float32, 2²⁰ points): every real-time
   kernel's XLA cost per point (flops, transcendentals, bytes accessed) and warm time against
   the elementwise peak of the same device, written beside the JSON as kernel_bench.json /
   .md; ``--kernel-baseline PATH`` (a checkout of an older commit carried along) times the
   old kernels in the same run.

Every timing reports the first call (compile + run) apart from the warm median. The JSON is
rewritten atomically after each section, so a run stopped by its time limit keeps what it
finished. No timing is asserted.

Check it on a CPU, small sizes, end to end::

    JAX_PLATFORMS=cpu python -m benchmarks.gpu_check --small --out /tmp/gpu_check

Example (the sizes of the two modes):
    >>> SIZES["small"]["frame"], SIZES["full"]["frame"]
    ((64, 36), (2560, 1440))
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SIZES = {
    "full": {"airy": (10**6, 10**7), "frame": (2560, 1440), "patches": 4096,
             "fit_quadrature": 16, "test_budget_s": 300, "kernel_points": 2**20},
    "small": {"airy": (10**4, 10**5), "frame": (64, 36), "patches": 64,
              "fit_quadrature": 8, "test_budget_s": 60, "kernel_points": 4096},
}

_SUMMARY = re.compile(r"^=*\s*(?P<body>(\d+ \w+(, )?)+).* in (?P<t>[\d.]+)s", re.M)


def _write(report: dict, out: Path) -> None:
    from thinfilm_jax.core.files import write_json

    write_json(out / "gpu_check.json", report)


def _device_info() -> dict:
    import jax

    from ._timing import environment

    info = environment()
    info["device_kinds"] = sorted({d.device_kind for d in jax.devices()})
    try:
        smi = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total",
                              "--format=csv,noheader"], capture_output=True, text=True,
                             timeout=20)
        info["nvidia_smi"] = smi.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        info["nvidia_smi"] = None
    return info


def run_tests(budget_s: float, extra: list[str] | None = None) -> dict:
    """The suite in a subprocess under `budget_s`; counts parsed from pytest's summary."""
    import importlib.util

    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rf"]
    if importlib.util.find_spec("xdist") is not None:
        workers = max(1, min(8, (os.cpu_count() or 2) // 2))
        cmd += ["-n", str(workers), "--dist", "loadfile"]
    cmd += extra or []
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false", PYTHONUNBUFFERED="1")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=budget_s, env=env,
                              cwd=Path(__file__).resolve().parents[1])
        out, rc, timed_out = proc.stdout + proc.stderr, proc.returncode, False
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        rc, timed_out = None, True
    wall = time.perf_counter() - t0
    counts = {}
    m = _SUMMARY.search(out.splitlines()[-1] if out.strip() else "") or _SUMMARY.search(out)
    if m:
        for part in m.group("body").split(", "):
            n, what = part.split(" ", 1)
            counts[what] = int(n)
    failed = [ln for ln in out.splitlines() if ln.startswith(("FAILED", "ERROR"))]
    return {"command": " ".join(cmd), "returncode": rc, "timed_out": timed_out,
            "wall_s": wall, "counts": counts, "failed": failed[:50],
            "tail": out[-3000:]}


def _timed(fn, repeats: int = 3) -> dict:
    from ._timing import time_call

    _, t = time_call(fn, (), repeats)
    return {"first_s": t.first_s, "warm_s": t.warm_s, "min_s": t.min_s,
            "compile_s": max(t.first_s - t.warm_s, 0.0)}


def bench_airy(sizes) -> list[dict]:
    """Airy reflectance of the Figure 7 film at n (cos θ, λ) pairs, flat."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from thinfilm_jax.optics.airy import airy_reflectance
    from thinfilm_jax.core.film import Film

    rows = []
    for dtype in (jnp.float32, jnp.float64):
        for n in sizes:
            rng = np.random.default_rng(0)
            c = jnp.asarray(rng.uniform(0, 1, n), dtype)
            lam = jnp.asarray(rng.uniform(380, 780, n), dtype)
            film = jax.tree.map(lambda x: jnp.asarray(x, dtype), Film(600.0, 1.3, 2.0, 0.5))
            f = jax.jit(lambda c, lam, film=film: airy_reflectance(film, c, lam))
            t = _timed(lambda f=f, c=c, lam=lam: f(c, lam))
            t.update(path="airy_reflectance (flat pairs)", dtype=jnp.dtype(dtype).name, n=n,
                     ns_per_eval=1e9 * t["min_s"] / n)
            rows.append(t)
    return rows


def bench_frame(width: int, height: int) -> list[dict]:
    """A frame of shading points under the prefiltered `venice_sunset`, float32."""
    import jax.numpy as jnp

    from thinfilm_jax.shading.ibl import envmap_radiance
    from thinfilm_jax.shading.prefilter import prefilter_envmap
    from .ibl_bench import frame_inputs

    t0 = time.perf_counter()
    pref = prefilter_envmap("venice_sunset").astype(jnp.float32)
    prefilter_s = time.perf_counter() - t0
    film, alpha, n, view = frame_inputs(width, height)
    rows = []
    for method in ("ideal", "filtered", "improved"):
        t = _timed(lambda m=method: envmap_radiance(film, alpha, n, view, pref, method=m))
        t.update(path=f"envmap_radiance {method} (frame)", dtype="float32",
                 n=width * height, ns_per_eval=1e9 * t["min_s"] / (width * height),
                 prefilter_s=prefilter_s)
        rows.append(t)
    return rows


def bench_patches(n: int) -> list[dict]:
    """Reference patches (float64, default 48² quadrature) of the Figure 7 film."""
    import numpy as np

    from thinfilm_jax.core.film import Film
    from thinfilm_jax.shading.patch import patch_radiance

    side = int(np.sqrt(n))
    t, a = np.meshgrid(np.linspace(0, 1.5, side), np.linspace(0.01, 1.0, side))
    film = Film(600.0, 1.3, 2.0, 0.5)
    row = _timed(lambda: patch_radiance(film, t, a), repeats=2)
    row.update(path="patch_radiance reference (48² quadrature)", dtype="float64", n=side * side,
               ns_per_eval=1e9 * row["min_s"] / (side * side))
    return [row]


_FIT_SNIPPET = """
import json, sys, time
t0 = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import thinfilm_jax as tf
tf.enable_compilation_cache()
q = int(sys.argv[1])
theta = np.linspace(0.0, 1.2, 9)
opts = tf.FitOptions(quadrature=(q, q))
obs = tf.patch_radiance(tf.Film(600.0, 1.3, 2.0, 0.5), theta, 0.25,
                        options=tf.ModelOptions(quadrature=(q, q)))
t1 = time.perf_counter()
res = tf.fit_film(np.asarray(obs), theta, alpha=0.25, initial=tf.Film(450.0, 1.3, 2.0, 0.5),
                  free=("thickness", "eta_film"), options=opts)
t2 = time.perf_counter()
print(json.dumps({"fit_s": t2 - t1, "process_s": t2 - t0,
                  "thickness": float(res.film.thickness), "converged": bool(res.converged)}))
"""


def bench_fit_cache(quadrature: int) -> list[dict]:
    """A reference fit in two fresh processes sharing a new persistent compilation cache."""
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, THINFILM_JAX_CACHE_DIR=cache, THINFILM_JAX_NO_CACHE="0",
                   XLA_PYTHON_CLIENT_PREALLOCATE="false")
        for label in ("cold cache", "warm cache"):
            proc = subprocess.run([sys.executable, "-c", _FIT_SNIPPET, str(quadrature)],
                                  capture_output=True, text=True, env=env, timeout=600)
            row = {"path": f"fit_film reference, {label}", "quadrature": quadrature,
                   "returncode": proc.returncode}
            try:
                row.update(json.loads(proc.stdout.strip().splitlines()[-1]))
            except (IndexError, json.JSONDecodeError):
                row["error"] = proc.stderr[-2000:]
            rows.append(row)
    return rows


def bench_kernels(points: int, out: Path, baseline=None) -> list[dict]:
    """`kernel_bench.run_kernel_bench` on this device (5 interleaved repeats); its rows."""
    from .kernel_bench import run_kernel_bench

    result = run_kernel_bench(out, points=points, repeats=5, baseline=baseline, verbose=False)
    return [{**r, "peak_gflops_per_s": result["peak_gflops_per_s"]} for r in result["rows"]]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.gpu_check",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.environ.get("OUT", "figures"),
                   help="folder for gpu_check.json (default: $OUT, else figures)")
    p.add_argument("--small", action="store_true", help="small sizes (a CPU check of the script)")
    p.add_argument("--skip-tests", action="store_true", help="only the bench table")
    p.add_argument("--test-budget", type=float, default=None, help="seconds for the suite")
    p.add_argument("--pytest-args", default="", help="extra pytest arguments (one string)")
    p.add_argument("--kernel-baseline", default=None,
                   help="folder of an older checkout whose kernels the kernel bench times too")
    args = p.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)  # the reference rows; real-time rows are float32
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = SIZES["small" if args.small else "full"]
    report = {"mode": "small" if args.small else "full", "sizes": size,
              "environment": _device_info(), "sections": {}}
    _write(report, out)
    t_start = time.perf_counter()
    sections = [("airy", lambda: bench_airy(size["airy"])),
                ("frame", lambda: bench_frame(*size["frame"])),
                ("patches", lambda: bench_patches(size["patches"])),
                ("fit_cache", lambda: bench_fit_cache(size["fit_quadrature"])),
                ("kernels", lambda: bench_kernels(size["kernel_points"], out,
                                                  args.kernel_baseline))]
    if not args.skip_tests:
        budget = args.test_budget or size["test_budget_s"]
        sections.insert(0, ("tests", lambda: run_tests(budget, args.pytest_args.split())))
    for name, fn in sections:
        t0 = time.perf_counter()
        print(f"[gpu-check] {name} ...", file=sys.stderr, flush=True)
        try:
            result = fn()
        except Exception as e:  # noqa: BLE001 - a failed section is reported, the rest runs
            result = {"error": f"{type(e).__name__}: {e}"}
        report["sections"][name] = {"wall_s": time.perf_counter() - t0, "result": result}
        _write(report, out)
        print(f"[gpu-check] {name} done in {time.perf_counter() - t0:.1f} s",
              file=sys.stderr, flush=True)
    report["total_s"] = time.perf_counter() - t_start
    _write(report, out)
    print(table(report))
    return 0


def table(report: dict) -> str:
    """The bench rows as a Markdown table."""
    lines = ["| path | dtype | n | first s | warm s | ns / eval |", "|---|---|---|---|---|---|"]
    for name in ("airy", "frame", "patches"):
        rows = report["sections"].get(name, {}).get("result", [])
        for r in rows if isinstance(rows, list) else []:
            lines.append(f"| {r['path']} | {r['dtype']} | {r['n']} | {r['first_s']:.3g} | "
                         f"{r['warm_s']:.3g} | {r['ns_per_eval']:.3g} |")
    for r in report["sections"].get("fit_cache", {}).get("result", []):
        if isinstance(r, dict) and "fit_s" in r:
            lines.append(f"| {r['path']} | float64 | 1 | {r['process_s']:.3g} | "
                         f"{r['fit_s']:.3g} | – |")
    kernels = report["sections"].get("kernels", {}).get("result", [])
    if isinstance(kernels, list) and kernels:
        lines += ["", "| kernel | version | bytes / pt | in + out B / pt | XLA kernels | ns / pt "
                  "| fraction of peak |", "|---|---|---|---|---|---|---|"]
        lines += [f"| {r['kernel']} | {r['version']} | {r['bytes_accessed']:.0f} | "
                  f"{r.get('io_bytes', float('nan')):.0f} | {r.get('fusions', '–')} | "
                  f"{r['ns_per_point']:.3g} | {r['fraction_of_peak']:.3f} |" for r in kernels]
    tests = report["sections"].get("tests", {}).get("result", {})
    if tests:
        lines.append(f"\ntests: {tests.get('counts')} in {tests.get('wall_s', 0):.0f} s "
                     f"(timed out: {tests.get('timed_out')})")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
