r"""`python -m benchmarks.bench --suite colour_table`: Kneiphof & Klein 2022's prefiltered colour table
beside `filtered`, `improved` and the exact reference, per map and film.

For each shipped map (`envmap.SHIPPED`, the suns not split off: the published methods) and
each film — Figure 4's (d = 600 nm, η₂ = 1.2 on η₃ = 2.0, α = 0.25) and a film on a
metal-like base (Figure 3's: d = 650 nm, η₂ = 1.3 on η₃ = 2.0 + 0.5i, α = 0.12) — on
`points` shading points (normals uniform on the sphere, views uniform on each normal's
hemisphere, a fixed seed) against `envmap_radiance(method="reference")`:

* `colour_table` rank 1 (the paper's separable table), rank 2, and the 3D table before the
  decomposition, all under the split-sum brightness A(θ_o, α) P_k(ω_r, α);
* `ceiling`: the same brightness with the colour computed exactly at each point (no table,
  no marginalisation): the best any colour table can do under the split sum;
* the two again under the improved model's per-bin brightness (`brightness=pref`), the
  method beyond the paper;
* `filtered` (K 29, the published method) and `improved` (docs/improved.md).

And each example car paint (`carpaint.PAINTS`: metallic, pearlescent, plain; their own
lobes, colour tables and clear coat): the table (ranks 1, 2, 3D) and the exact-colour
ceiling against the paint's exact reference (`carpaint_ibl.paint_envmap_radiance`), with a
smaller table (`PAINT_TABLE`: 8 × 16 × 8 views × 4 azimuths; the films' is 16 × 32 × 8 × 8).

ΔE: CIEDE2000 with the mirror as white (`colorimetry.delta_e2000`), mean and 95th
percentile per map × film (no average over maps is reported: each map is its own case).
Cost: warm wall time per shading point of each real-time method on 65,536 float32 points
(median of `repeats`, a shared machine: noisy); precompute time of the table (float64,
host + XLA, first call includes compilation); memory per material × map of what shading
reads: the decomposed table + its brightness level and albedo row against the prefiltered
map (17 levels of radiance and moments, the albedo and Ŝ tables), which `filtered` and
`improved` share across every film and roughness. A spatially varying film needs one
colour table per film (or a thickness axis): there the per-point methods win by design.

Example (the configuration of the smoke test):
    >>> from benchmarks.colour_table_study import CASES, TableStudyConfig
    >>> TableStudyConfig.quick().maps, sorted(CASES)
    (('venice_sunset',), ['fig3_metal', 'fig4', 'paint_metallic', 'paint_pearlescent', 'paint_plain'])
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.files import atomic_write, write_json
from thinfilm_jax.brdf.carpaint import PAINTS
from thinfilm_jax.core.film import Film
from thinfilm_jax.shading.colour_table import (colour_table_radiance, decomposition_error,
                                    exact_colour_radiance, prefilter_colour)
from thinfilm_jax.shading.carpaint_ibl import paint_envmap_radiance
from thinfilm_jax.shading.envmap import SHIPPED, load_envmap
from thinfilm_jax.shading.ibl import envmap_radiance
from thinfilm_jax.shading.prefilter import prefilter_envmap
from thinfilm_jax.render.study_scenes import PAINT_TABLE
from thinfilm_jax.spectral.colorimetry import delta_e2000
from ._timing import environment, time_call

CASES = {"fig4": (Film(600.0, 1.2, 2.0, 0.0), 0.25),
         "fig3_metal": (Film(650.0, 1.3, 2.0, 0.5), 0.12),
         "paint_metallic": ("metallic", None), "paint_pearlescent": ("pearlescent", None),
         "paint_plain": ("plain", None)}


@dataclasses.dataclass(frozen=True)
class TableStudyConfig:
    maps: tuple[str, ...] = tuple(SHIPPED)
    cases: tuple[str, ...] = tuple(CASES)
    points: int = 96
    timing_points: int = 65536
    repeats: int = 3
    seed: int = 1

    @classmethod
    def quick(cls):
        return cls(maps=("venice_sunset",), cases=("fig4",), points=16, timing_points=4096,
                   repeats=1)


def shading_points(m: int, seed: int):
    """Normals uniform on the sphere, views uniform on each normal's hemisphere."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(m, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    v = rng.normal(size=(m, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return n, np.where(np.sum(v * n, -1, keepdims=True) < 0, -v, v)


def _stats(x, ref):
    de = delta_e2000(np.asarray(x), np.asarray(ref))
    return {"dE2000_mean": float(de.mean()), "dE2000_p95": float(np.percentile(de, 95)),
            "dE2000_max": float(de.max())}


def _nbytes(tree) -> int:
    return int(sum(np.prod(x.shape) * x.dtype.itemsize for x in jax.tree.leaves(tree)))


def _cost(cfg, film, alpha, table, pref):
    """Warm ns per point of the real-time methods, float32, `timing_points` points."""
    n, v = shading_points(cfg.timing_points, cfg.seed + 1)
    n32, v32 = jnp.asarray(n, jnp.float32), jnp.asarray(v, jnp.float32)
    f32 = jax.tree.map(jnp.float32, film)
    t32 = jax.tree.map(lambda x: x.astype(jnp.float32), table)
    p32 = pref.astype(jnp.float32)
    a32 = jnp.float32(alpha)
    calls = {
        "colour_table": jax.jit(lambda n, v: colour_table_radiance(t32, n, v)),
        "colour_table+improved_brightness": jax.jit(
            lambda n, v: colour_table_radiance(t32, n, v, brightness=p32)),
        "filtered": lambda n, v: envmap_radiance(f32, a32, n, v, p32, method="filtered"),
        "improved": lambda n, v: envmap_radiance(f32, a32, n, v, p32, method="improved"),
    }
    out = {}
    for name, fn in calls.items():
        _, t = time_call(fn, (n32, v32), cfg.repeats)
        out[name] = {"ns_per_point": t.warm_s / cfg.timing_points * 1e9,
                     "compile_s": t.compile_s}
    return out


def run_paint_case(cfg: TableStudyConfig, map_name: str, case: str, verbose: bool) -> dict:
    """A car paint (`carpaint.PAINTS`): the table (ranks 1, 2, 3D) and its exact-colour
    ceiling against the paint's exact reference (`carpaint_ibl.paint_envmap_radiance`)."""
    paint = PAINTS[CASES[case][0]]()
    env = load_envmap(map_name)
    n, v = shading_points(cfg.points, cfg.seed)
    t0 = time.perf_counter()
    table = prefilter_colour(env, paint, rank=2, **PAINT_TABLE)
    build = time.perf_counter() - t0
    ref = paint_envmap_radiance(paint, n, v, env, method="reference")
    rows = {"colour_table": colour_table_radiance(table, n, v, rank=1),
            "colour_table_rank2": colour_table_radiance(table, n, v, rank=2),
            "colour_table_3d": colour_table_radiance(table, n, v, rank=None),
            "ceiling": exact_colour_radiance(paint, None, n, v, env, table)}
    rank1 = dataclasses.replace(table, colour=table.colour[..., :1, :],
                                view=table.view[:, :1, :])
    n32, v32 = (jnp.asarray(x, jnp.float32) for x in shading_points(cfg.timing_points,
                                                                   cfg.seed + 1))
    t32 = jax.tree.map(lambda x: x.astype(jnp.float32), rank1)
    _, t = time_call(jax.jit(lambda a, b: colour_table_radiance(t32, a, b)), (n32, v32),
                     cfg.repeats)
    out = {"map": map_name, "case": case, "build_s": build,
           "decomposition_error_rank1": decomposition_error(rank1),
           "decomposition_error_rank2": decomposition_error(table),
           "memory_bytes": {"colour_table_rank1": rank1.nbytes["colour_table"],
                            "table_brightness": rank1.nbytes["brightness"],
                            "table_3d": table.nbytes["full_table"]},
           "errors": {k: _stats(x, ref) for k, x in rows.items()},
           "cost": {"colour_table": {"ns_per_point": t.warm_s / cfg.timing_points * 1e9,
                                     "compile_s": t.compile_s}}}
    if verbose:
        e = out["errors"]
        print(f"{map_name:14s} {case:18s} build {build:5.1f} s  "
              + "  ".join(f"{k} {e[k]['dE2000_mean']:.2f}" for k in ("colour_table", "ceiling")),
              flush=True)
    return out


def run_case(cfg: TableStudyConfig, map_name: str, case: str, verbose: bool = True) -> dict:
    if case.startswith("paint_"):
        return run_paint_case(cfg, map_name, case, verbose)
    film, alpha = CASES[case]
    env = load_envmap(map_name)
    n, v = shading_points(cfg.points, cfg.seed)
    t0 = time.perf_counter()
    table = prefilter_colour(env, film, alpha, rank=2)
    build = time.perf_counter() - t0
    pref = prefilter_envmap(env)
    ref = envmap_radiance(film, alpha, n, v, env, method="reference")
    rows = {
        "colour_table": colour_table_radiance(table, n, v, rank=1),
        "colour_table_rank2": colour_table_radiance(table, n, v, rank=2),
        "colour_table_3d": colour_table_radiance(table, n, v, rank=None),
        "ceiling": exact_colour_radiance(film, alpha, n, v, env, table),
        "colour_table+improved_brightness": colour_table_radiance(table, n, v, rank=1,
                                                                  brightness=pref),
        "ceiling+improved_brightness": exact_colour_radiance(film, alpha, n, v, env, table,
                                                             brightness=pref),
        "filtered": envmap_radiance(film, alpha, n, v, pref, method="filtered"),
        "improved": envmap_radiance(film, alpha, n, v, pref, method="improved"),
    }
    rank1 = dataclasses.replace(table, colour=table.colour[..., :1, :],
                                view=table.view[:, :1, :])
    out = {"map": map_name, "case": case, "alpha": alpha, "film": [float(x) for x in film],
           "build_s": build, "decomposition_error_rank1": decomposition_error(rank1),
           "decomposition_error_rank2": decomposition_error(table),
           "memory_bytes": {"colour_table_rank1": rank1.nbytes["colour_table"],
                            "table_brightness": rank1.nbytes["brightness"],
                            "table_3d": table.nbytes["full_table"],
                            "prefiltered_map": _nbytes(pref)},
           "errors": {k: _stats(x, ref) for k, x in rows.items()},
           "cost": _cost(cfg, film, alpha, table, pref)}
    if verbose:
        e = out["errors"]
        print(f"{map_name:14s} {case:10s} build {build:5.1f} s  "
              + "  ".join(f"{k} {e[k]['dE2000_mean']:.2f}" for k in
                          ("colour_table", "ceiling", "filtered", "improved")), flush=True)
    return out


def markdown(result) -> str:
    cols = ["colour_table", "colour_table_rank2", "colour_table_3d", "ceiling",
            "colour_table+improved_brightness", "ceiling+improved_brightness", "filtered",
            "improved"]
    lines = ["| map | material | " + " | ".join(cols) + " |",
             "|---|---|" + "---|" * len(cols)]
    for r in result["rows"]:
        e = r["errors"]
        lines.append(f"| {r['map']} | {r['case']} | " + " | ".join(
            f"{e[c]['dE2000_mean']:.2f} / {e[c]['dE2000_p95']:.2f}" if c in e else "–"
            for c in cols) + " |")
    lines += ["", "CIEDE2000 mean / p95 against the exact reference (module docstring).", "",
              "| map | material | build (s) | rank-1 decomposition error | table + brightness (kB) | "
              "prefiltered map (kB) | colour_table (ns/pt) | filtered (ns/pt) | "
              "improved (ns/pt) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        m, c = r["memory_bytes"], r["cost"]
        ns = lambda k: f"{c[k]['ns_per_point']:.0f}" if k in c else "–"  # noqa: E731
        lines.append(
            f"| {r['map']} | {r['case']} | {r['build_s']:.1f} | "
            f"{r['decomposition_error_rank1']:.3g} | "
            f"{(m['colour_table_rank1'] + m['table_brightness']) / 1024:.0f} | "
            + (f"{m['prefiltered_map'] / 1024:.0f}" if "prefiltered_map" in m else "–")
            + f" | {ns('colour_table')} | {ns('filtered')} | {ns('improved')} |")
    return "\n".join(lines) + "\n"


def run_colour_table_study(out="figures", quick: bool = False, verbose: bool = True,
                           cfg: TableStudyConfig | None = None, resume: bool = True) -> dict:
    """Every map × case (module docstring); writes colour_table.{json,md} into `out` after
    each case. `resume`: keep the rows of an earlier run of the same configuration found
    there (a run cut short goes on where it stopped)."""
    cfg = cfg or (TableStudyConfig.quick() if quick else TableStudyConfig())
    result = {"config": dataclasses.asdict(cfg), "environment": environment(), "rows": []}
    name = "colour_table_quick" if quick else "colour_table"
    done = _finished(out, name, result["config"]) if resume else {}
    for m in cfg.maps:
        for c in cfg.cases:
            row = done.get((m, c)) or run_case(cfg, m, c, verbose)
            result["rows"].append(row)
            if out is not None:  # after every case: a long run keeps what it finished
                Path(out).mkdir(parents=True, exist_ok=True)
                write_json(Path(out) / f"{name}.json", result)
                atomic_write(Path(out) / f"{name}.md",
                             lambda p: Path(p).write_text(markdown(result)))
    return result


def _finished(out, name, config) -> dict:
    """Rows of an earlier run with the same configuration, by (map, case)."""
    path = Path(out) / f"{name}.json" if out is not None else None
    if path is None or not path.exists():
        return {}
    import json

    old = json.loads(path.read_text())
    keep = {k: v for k, v in old.get("config", {}).items() if k not in ("maps", "cases")}
    if keep != {k: v for k, v in config.items() if k not in ("maps", "cases")}:
        return {}
    return {(r["map"], r["case"]): r for r in old.get("rows", [])}
