"""Scaling across devices: the large jobs on 1, 2 and 4 devices.

``python -m benchmarks.scaling`` (about 3 min here) starts one subprocess per
device count k (``XLA_FLAGS=--xla_force_host_platform_device_count=k`` on a CPU host; on a
machine with k accelerators the same command uses the first k of them), runs every workload
through `thinfilm_jax.core.sharding.map_sharded` there, and writes ``figures/scaling.md`` and
``figures/scaling.json``: warm seconds per call, speed-up against one device, and the
largest difference from the one-device result (in units of the float64 eps of the largest
value, `diff_eps`).

Workloads (float64, the drivers' own block functions):

* ``figure7_reference`` — Figure 7 row (e)–(h), the spectral reference on an R × R grid
  (32 × 32 half-vector quadrature, `figure7.patch_block`);
* ``figure7_ideal`` — the same row with the real-time ideal method at the paper's 256²;
* ``ibl_filtered`` — one real-time IBL frame: K 29 with the prefiltered map on a sphere of
  ``ibl_resolution``² pixels (Figure 4 material, `study_scenes.shade_block`);
* ``thickness_map`` — spectral band reflectance (89 λ) of a 512² thickness map.

On a CPU host the k "devices" are one process's virtual devices over the same cores: XLA
runs each device's program on the shared thread pool, so scaling is bounded by the core
count (2 on this project's machines) and by whatever else runs there; the table says what
was measured, not what k accelerators would give.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

WORKLOADS = ("figure7_reference", "figure7_ideal", "ibl_filtered", "thickness_map")
DESCRIPTIONS = {
    "figure7_reference": "Figure 7 (e)–(h), spectral reference, 32² quadrature",
    "figure7_ideal": "Figure 7 (e)–(h), ideal (BB17, M = 2)",
    "ibl_filtered": "IBL frame, filtered K 29 + LUT, prefiltered map",
    "thickness_map": "thickness map, spectral band R (89 λ)",
}
OBSERVER = "stiles_burch_1959_10"


@dataclass(frozen=True)
class ScalingConfig:
    devices: tuple[int, ...] = (1, 2, 4)
    workloads: tuple[str, ...] = WORKLOADS
    reference_resolution: int = 64  # Figure 7 reference grid side (the figure's default)
    ideal_resolution: int = 256  # the paper's 256²
    ibl_resolution: int = 512  # sphere frame side: ≈ 0.77 · R² shading points
    map_resolution: int = 512
    repeats: int = 3  # warm calls (median); the reference runs `max(1, repeats // 3)`
    envmap: str = "venice_sunset"


#: small sizes of ``--quick`` (a smoke test of the machinery, not a measurement)
QUICK = dict(reference_resolution=8, ideal_resolution=32, ibl_resolution=48, map_resolution=64,
             repeats=1)


# ----------------------------------------------------------------------------- the child
def _inputs(cfg: ScalingConfig, name: str):
    """(block function, in_axes, arguments, items) of one workload."""
    import jax

    from thinfilm_jax.optics.airy import choose_arithmetic
    from thinfilm_jax.core.film import Film
    from thinfilm_jax.realtime.options import ModelOptions
    from thinfilm_jax.render import figure7
    from thinfilm_jax.render import study_scenes as render

    if name.startswith("figure7"):
        ref = name == "figure7_reference"
        f7 = figure7.Figure7Config(
            resolution=cfg.reference_resolution if ref else cfg.ideal_resolution)
        film, t, a = figure7.row_inputs(f7, "thickness")
        flat = jax.tree.map(lambda x: np.asarray(np.broadcast_to(x, t.shape), float).reshape(-1),
                            (film, t, a))  # (film, θ_o, α) of flat per-point arrays
        opts = ModelOptions(quadrature=tuple(f7.quadrature), terms=f7.terms,
                            arithmetic=choose_arithmetic(film))
        fn = functools.partial(figure7.patch_block, method="reference" if ref else "ideal",
                               observer=f7.observer, options=opts)
        return fn, 0, flat, t.size
    if name == "ibl_filtered":
        from thinfilm_jax.shading.envmap import load_envmap
        from thinfilm_jax.shading.ibl import REALTIME_OPTIONS
        from thinfilm_jax.shading.prefilter import prefilter_envmap

        env = load_envmap(cfg.envmap)
        pref = prefilter_envmap(env, observer=OBSERVER)
        wo, right, up = render.camera(render.view_azimuth(env), 15.0)
        mask, n = render.sphere(cfg.ibl_resolution, wo, right, up)
        pts = n[mask]
        film = Film(render.thickness_field(pts), 1.2, 2.0, 0.0)
        opts = REALTIME_OPTIONS._replace(arithmetic=choose_arithmetic(film))
        fn = functools.partial(render.shade_block, method="filtered", observer=OBSERVER,
                               options=opts, subdivisions=None)
        return fn, (0, 0, None, None, None), (film, pts, 0.25, wo, pref), len(pts)
    if name == "thickness_map":
        from thinfilm_jax.spectral.reflectance import rgb_reflectance

        m = cfg.map_resolution
        y, x = np.meshgrid(np.linspace(0, 1, m), np.linspace(0, 1, m), indexing="ij")
        d = (450.0 + 350.0 * np.sin(7 * x + 3 * y) * np.cos(5 * y - 2 * x)).reshape(-1)
        cos_t = np.cos(np.deg2rad(60.0) * x).reshape(-1)
        film = Film(d, 1.33, 1.0, 0.0)  # a soap film in air

        def fn(film, c):
            return rgb_reflectance(film, c, arithmetic="real")

        return fn, 0, (film, cos_t), d.size
    raise ValueError(f"unknown workload {name!r}; expected one of {WORKLOADS}")


def run_child(cfg: ScalingConfig, k: int, npz_path: str) -> dict:
    """Time every workload on k devices (inside a subprocess); save the outputs."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from thinfilm_jax.core.sharding import map_sharded, to_host
    from ._timing import environment

    rows, outs = {}, {}
    for name in cfg.workloads:
        fn, in_axes, args, items = _inputs(cfg, name)
        shade = map_sharded(fn, in_axes=in_axes, devices=k)
        repeats = max(1, cfg.repeats // 3) if name == "figure7_reference" else cfg.repeats
        t0 = time.perf_counter()
        out = to_host(shade(*args))
        first = time.perf_counter() - t0
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            to_host(shade(*args))
            ts.append(time.perf_counter() - t0)
        outs[name] = out
        rows[name] = {"items": int(items), "first_s": first, "warm_s": float(np.median(ts)),
                      "warm_min_s": min(ts), "repeats": repeats}
        print(f"  k={k} {name}: {items} items, warm {np.median(ts):.3g} s", file=sys.stderr,
              flush=True)
    np.savez(npz_path, **outs)
    return {"devices": k, "environment": environment(), "workloads": rows}


# ----------------------------------------------------------------------------- the parent
def _spawn(cfg: ScalingConfig, k: int, npz: str) -> dict:
    env = dict(os.environ)
    flags = [f for f in env.get("XLA_FLAGS", "").split()
             if not f.startswith("--xla_force_host_platform_device_count")]
    env["XLA_FLAGS"] = " ".join(flags + [f"--xla_force_host_platform_device_count={k}"])
    cmd = [sys.executable, "-m", "benchmarks.scaling", "--child", str(k),
           "--config", json.dumps(dataclasses.asdict(cfg)), "--npz", npz]
    res = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _diff_eps(a: np.ndarray, ref: np.ndarray) -> float:
    """max |a − ref| in units of eps · max |ref| (0: identical)."""
    scale = np.finfo(ref.dtype).eps * max(float(np.max(np.abs(ref))), np.finfo(ref.dtype).tiny)
    return float(np.max(np.abs(a - ref)) / scale) if ref.size else 0.0


def run_scaling(cfg: ScalingConfig = ScalingConfig(), out_dir="figures") -> dict:
    """Run the workloads on every device count; write scaling.json and scaling.md."""
    from ._timing import write_report

    if any(k < 1 for k in cfg.devices):
        raise ValueError(f"devices must be positive ints, got {cfg.devices}")
    runs, outputs = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in cfg.devices:
            npz = os.path.join(tmp, f"k{k}.npz")
            print(f"scaling: {k} device(s)", file=sys.stderr, flush=True)
            runs[k] = _spawn(cfg, k, npz)
            with np.load(npz) as z:
                outputs[k] = {n: z[n] for n in z.files}
    base = min(cfg.devices)
    table = []
    for name in cfg.workloads:
        t1 = runs[base]["workloads"][name]["warm_s"]
        row = {"workload": name, "description": DESCRIPTIONS[name],
               "items": runs[base]["workloads"][name]["items"], "per_devices": {}}
        for k in cfg.devices:
            w = runs[k]["workloads"][name]
            row["per_devices"][k] = {
                "warm_s": w["warm_s"], "first_s": w["first_s"],
                "speedup": t1 / w["warm_s"], "efficiency": t1 / w["warm_s"] / (k / base),
                "diff_eps_vs_base": _diff_eps(outputs[k][name], outputs[base][name])}
        table.append(row)
    summary = {"config": dataclasses.asdict(cfg), "baseline_devices": base,
               "environment": {k: runs[k]["environment"] for k in cfg.devices},
               "table": table}
    write_report(out_dir, "scaling", summary, format_table)
    return summary


def format_table(summary: dict) -> str:
    ks = sorted(int(k) for k in summary["environment"])
    env = summary["environment"][ks[0]] if ks[0] in summary["environment"] else \
        summary["environment"][str(ks[0])]
    head = ("| workload | items | " + " | ".join(f"{k} dev. s" for k in ks) + " | "
            + " | ".join(f"×{k}" for k in ks[1:]) + " | max diff vs 1 dev. (eps) |")
    lines = [
        "# Scaling across devices (`python -m benchmarks.scaling`)", "",
        f"Backend {env['backend']}, {env['cpu_count']} CPU cores, JAX {env['jax']}, "
        f"load average at start {', '.join(f'{x:.1f}' for x in env['load_average'] or [])}. "
        "Warm seconds per call (median), speed-up against one device, largest difference "
        "from the one-device result in eps of its largest value.", "",
        head, "|" + "---|" * (3 + 2 * len(ks) - 1)]
    for row in summary["table"]:
        pd = {int(k): v for k, v in row["per_devices"].items()}
        diffs = max(pd[k]["diff_eps_vs_base"] for k in ks)
        lines.append(f"| {row['description']} | {row['items']:,} | "
                     + " | ".join(f"{pd[k]['warm_s']:.3g}" for k in ks) + " | "
                     + " | ".join(f"{pd[k]['speedup']:.2f}" for k in ks[1:])
                     + f" | {diffs:.3g} |")
    lines += ["", "On a CPU host the devices are virtual (`--xla_force_host_platform_device_"
              "count`): they share the machine's cores and XLA's thread pool, so the "
              "speed-up is bounded by the core count and by other load; on k accelerators "
              "each block runs on its own chip.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.scaling",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--devices", type=int, nargs="+", default=[1, 2, 4],
                   help="device counts (default 1 2 4)")
    p.add_argument("--workload", action="append", choices=WORKLOADS,
                   help="workloads (repeatable; default all)")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--child", type=int, help=argparse.SUPPRESS)
    p.add_argument("--config", help=argparse.SUPPRESS)
    p.add_argument("--npz", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child is not None:
        kw = json.loads(args.config)
        cfg = ScalingConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in kw.items()})
        print(json.dumps(run_child(cfg, args.child, args.npz)))
        return 0
    kw = {"devices": tuple(args.devices)}
    if args.workload:
        kw["workloads"] = tuple(args.workload)
    if args.quick:
        kw.update(QUICK)
    summary = run_scaling(ScalingConfig(**kw), out_dir=args.out)
    print(format_table(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
