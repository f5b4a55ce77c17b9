"""The quality presets of `improved` through the public call (`ModelOptions.preset`), timed
against `ideal` and `filtered` in one process.

Each method is ``jax.jit(lambda n, v: envmap_radiance(film, 0.25, n, v, prefiltered,
method=m, options=...))`` on 2²⁰ random front-facing normals and views in float32, under
``venice_sunset`` box-filtered to 64 × 128 (so the map is no cache burden), after one call
that compiles, five calls interleaved across the methods, their median; for two films
(`FILMS`), each timed against `filtered` on the same film: Figure 4's dielectric film
(d = 600 nm, η₂ = 1.33, η₃ = 1.5), which ``arithmetic="auto"`` shades in real arithmetic,
and the same film on an absorbing base (η₃ = 2.0 + 0.5i, the kernel bench's), which needs
complex Fresnel arithmetic, once per bin of `improved` (K times) and once for `filtered`.

``python -m benchmarks.presets_bench [--points 1048576] [--out figures]`` writes
``presets_bench.json`` and prints a table (≈ 6 min on a 2-core CPU, the compilations
included).
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

#: the films timed: (d nm, η₂, η₃, κ₃)
FILMS = {"dielectric": (600.0, 1.33, 1.5, 0.0), "absorbing base": (600.0, 1.33, 2.0, 0.5)}
CASES = (("ideal", None), ("filtered", None), ("improved", "fast"), ("improved", "default"),
         ("improved", "accurate"))


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def run(points: int = 1 << 20, repeats: int = 5) -> dict:
    import jax
    import jax.numpy as jnp

    from thinfilm_jax.core.film import Film
    from thinfilm_jax.shading.envmap import load_envmap
    from thinfilm_jax.shading.prefilter import prefilter_envmap

    px = np.asarray(load_envmap("venice_sunset").radiance)
    while px.shape[0] > 64:
        px = 0.25 * (px[0::2, 0::2] + px[1::2, 0::2] + px[0::2, 1::2] + px[1::2, 1::2])
    pref = prefilter_envmap(px.astype(np.float32))
    rng = np.random.default_rng(0)
    n = _unit(rng.normal(size=(points, 3)))
    n[:, 2] = np.abs(n[:, 2])
    n = _unit(n)
    v = _unit(n + 0.8 * _unit(rng.normal(size=(points, 3))))
    v = np.where((np.sum(n * v, -1) > 0)[:, None], v, n)
    n, v = jnp.asarray(n, jnp.float32), jnp.asarray(v, jnp.float32)
    from ._timing import environment

    out = {"points": points, "repeats": repeats, "machine": platform.processor() or
           platform.machine(), "devices": [str(d) for d in jax.devices()],
           "environment": environment(), "films": {}}
    for name, (d, eta2, eta3, kappa3) in FILMS.items():
        film = Film(*(jnp.float32(x) for x in (d, eta2, eta3, kappa3)))
        out["films"][name] = {"film": dict(thickness=d, eta_film=eta2, eta_base=eta3,
                                           kappa_base=kappa3),
                              "rows": _time_methods(film, pref, n, v, points, repeats)}
    return out


def _time_methods(film, pref, n, v, points, repeats) -> dict:
    """Each of `CASES` on one film: first call (compiles), then `repeats` interleaved calls."""
    import jax

    from thinfilm_jax.realtime.options import ModelOptions
    from thinfilm_jax.shading.ibl import envmap_radiance

    fns, rows = {}, {}
    for m, q in CASES:
        kw = {} if q is None else {"options": ModelOptions.preset(q)}
        key = m if q is None else f"{m} ({q})"
        fns[key] = jax.jit(lambda n, v, m=m, kw=kw: envmap_radiance(film, 0.25, n, v, pref,
                                                                   method=m, **kw))
        t0 = time.perf_counter()
        fns[key](n, v).block_until_ready()
        rows[key] = {"first_call_s": time.perf_counter() - t0, "warm_s": []}
    for _ in range(repeats):
        for key, fn in fns.items():
            t0 = time.perf_counter()
            fn(n, v).block_until_ready()
            rows[key]["warm_s"].append(time.perf_counter() - t0)
    base = float(np.median(rows["filtered"]["warm_s"]))
    for r in rows.values():
        med = float(np.median(r["warm_s"]))
        r.update(median_s=med, ns_per_point=med / points * 1e9, x_filtered=med / base)
    return rows


def main(argv=None) -> int:
    from thinfilm_jax.core.files import write_json

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1 << 20)
    ap.add_argument("--out", default="figures")
    args = ap.parse_args(argv)
    res = run(args.points)
    write_json(Path(args.out) / "presets_bench.json", res)
    for film, f in res["films"].items():
        for key, r in f["rows"].items():
            print(f"{film:15s} {key:20s} {r['ns_per_point']:8.1f} ns a point  "
                  f"{r['x_filtered']:.2f}× filtered  (first call {r['first_call_s']:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
