"""``python -m benchmarks.bench``: the whole benchmark, its report and the stated targets.

`run_bench` runs the error-vs-run-time rows (`error_runtime`), the peers (`peers`), the
specialisation costs (`specialisation`) and the stability suite (`stability`), and writes
``bench.json``, ``error_vs_runtime.png``, ``error_vs_runtime.md``, ``peers.json``, ``peers.md``
(the peers also under "peers" in ``bench.json``), ``specialisation.json``, ``specialisation.md``
and ``stability_report.md``, then the kernel costs (``kernel_bench.*``) and the cost of every
method a shading point under a map against `filtered` (``method_cost.*``, `method_cost`):
``python -m benchmarks.bench [--quick] [--repeats N] [--no-stability]`` from a clone
(``make bench``); ``--rows-only`` reruns the error-vs-run-time rows alone and merges them
into ``bench.json`` (`run_rows_only`); ``--suite`` runs the other studies (`run_suite`;
``--suite cost``: ``method_cost.*`` alone). Benchmarks never assert timings.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import jax

from thinfilm_jax.core.files import atomic_write, write_json
from ._common import MATERIALS, BenchConfig
from ._timing import environment, fmt, jsonable, log
from .error_runtime import absent_from_patches, bench_patches, bench_shading
from .pareto import markdown_table, pareto_rows, render_error_vs_runtime
from .peers import bench_peers, memory_roofline, peers_table, write_peers
from .specialisation import run_specialisation
from .stability import write_stability_report


def _find(rows, path):
    """The row called `path` (None if absent)."""
    return next((r for r in rows if r["path"] == path), None)


def summarise_targets(rows, peers) -> dict:
    """The cost of each specialisation and the stated targets (README, "Targets")."""
    def per(path):
        r = _find(rows, path)
        return None if r is None or "warm_s_per_eval" not in r else r["warm_s_per_eval"]

    def ratio(a, b):
        pa, pb = per(a), per(b)
        return None if pa is None or pb is None else pa / pb

    s = {
        "filtered_K29_lut_f32_points_per_s": (1.0 / per("kernel K29 LUT f32")
                                              if per("kernel K29 LUT f32") else None),
        "target_points_per_s": 1e7,
        "filtered_over_ideal_cost (K29 LUT f32 / ideal M=2 f32)":
            ratio("kernel K29 LUT f32", "kernel ideal M=2 f32"),
        "filtered_over_ideal_cost, both Gaussian Ŝ (K29 / ideal M=2, f32)":
            ratio("kernel K29 Gaussian Ŝ f32", "kernel ideal M=2 Gaussian Ŝ f32"),
        "target_filtered_over_ideal": 1.5,
        "lut_over_exact_shat_cost (K29 f32)": ratio("kernel K29 LUT f32",
                                                    "kernel K29 exact Ŝ f32"),
        "f32_over_f64_cost (K29 LUT)": ratio("kernel K29 LUT f32", "kernel K29 LUT f64"),
        "f32_over_f64_cost (spectral)": ratio("spectral f32", "spectral (reference)"),
        "real_over_complex_cost (spectral)": ratio("spectral, real arithmetic",
                                                         "spectral, complex arithmetic"),
        "real_over_complex_cost (Fourier M=2)": ratio(
            "Fourier M=2, real arithmetic", "Fourier M=2, complex arithmetic"),
        "cie1931_over_stiles_burch_cost (spectral)": ratio("spectral CIE 1931 (reference)",
                                                           "spectral (reference)"),
        "patch_filtered_over_ideal_cost": ratio("filtered", "ideal"),
        "patch_filtered_gt_moments_over_ideal_cost": ratio("filtered_gt_moments", "ideal"),
    }
    for key, g in peers.get("grids", {}).items():
        s[f"airy_speedup_vs_numpy [{key}]"] = g["speedup_airy_vs"]["numpy_closed_form"]
        s[f"airy_speedup_vs_numpy, flat pairs [{key}]"] = g["speedup_airy_vs"][
            "numpy_closed_form_flat"]
        s[f"airy_speedup_vs_tmm [{key}]"] = g["speedup_airy_vs"]["tmm_coh_tmm"]
    s["target_airy_vs_numpy_at_1e6"] = 2.0
    s["target_airy_vs_tmm"] = 100.0
    return s


def run_rows_only(out="figures", *, config: BenchConfig | None = None,
                  verbose: bool = True) -> dict:
    """Rerun the error-vs-run-time rows alone (panels (a) and (b): `bench_shading`,
    `bench_patches`) and merge them into ``out/bench.json`` (which must exist), keeping its
    peers, specialisation, stability and kernels sections from the run that wrote them (their
    own files are not touched); rewrites ``error_vs_runtime.png`` / ``.md``. The rows' machine
    and time are in "environment", the earlier run's in "environment_other_sections"."""
    import json

    if not jax.config.jax_enable_x64:
        raise RuntimeError("run_rows_only needs float64: jax.config.update('jax_enable_x64', "
                           "True)")
    cfg = config or BenchConfig.full()
    out = Path(out)
    old = json.loads((out / "bench.json").read_text())
    t_start = time.perf_counter()
    env = environment()
    rows_a, m_sweep = bench_shading(cfg, verbose)
    rows_b, ref_check, lut_table = bench_patches(cfg, verbose)
    rows = rows_a + rows_b
    result = dict(old)
    result.update({
        "environment": env,
        "environment_other_sections": old.get("environment_other_sections", old["environment"]),
        "config": dataclasses.asdict(cfg), "rows": rows,
        "panel_b_absent": absent_from_patches(),
        "pareto": {fam: [rows[i]["path"] for i in pareto_rows(rows, fam)] for fam in "ab"},
        "m_selection": m_sweep, "reference_check": ref_check, "lut": lut_table,
        "targets": summarise_targets(rows, old.get("peers", {})),
        "seconds_rows": time.perf_counter() - t_start})
    _write_rows_report(result, out, cfg, env, verbose)
    return result


def _write_rows_report(result, out, cfg, env, verbose):
    """bench.json, error_vs_runtime.png and error_vs_runtime.md of `result`."""
    title = (f"thinfilm_jax {cfg.name} benchmark on {', '.join(env['devices'])} "
             f"({env['cpu_count']} CPUs, load {env['load_average'][0]:.1f} at start); "
             f"warm median of {cfg.repeats}")
    write_json(out / "bench.json", jsonable(result))
    render_error_vs_runtime(result["rows"], out / "error_vs_runtime.png", title=title,
                            absent=result["panel_b_absent"])
    text = report_markdown(result)
    atomic_write(out / "error_vs_runtime.md", lambda tmp: Path(tmp).write_text(text))
    if verbose:
        print(text)


def run_bench(out="figures", quick: bool = False, *, config: BenchConfig | None = None,
              verbose: bool = True) -> dict:
    """Run the whole study and write its files (module docstring) into `out`.

    Args:
        out: output folder.
        quick: the ≤ 1 minute smoke configuration (`BenchConfig.quick`).
        config: an explicit configuration (overrides `quick`).
        verbose: progress on stderr and the tables on stdout.

    Returns:
        the JSON-serialisable result (also written to ``out/bench.json``).
    """
    if not jax.config.jax_enable_x64:
        raise RuntimeError("run_bench needs float64: jax.config.update('jax_enable_x64', True)")
    cfg = config or (BenchConfig.quick() if quick else BenchConfig.full())
    out = Path(out)
    t_start = time.perf_counter()
    env = environment()
    log(f"config {cfg.name}; devices {env['devices']}", verbose)
    rows_a, m_sweep = bench_shading(cfg, verbose)
    rows_b, ref_check, lut_table = bench_patches(cfg, verbose)
    peers = bench_peers(cfg, verbose)
    peers["roofline"] = memory_roofline(10**7 if max(cfg.peer_sides) >= 1000 else 10**5)
    spec = run_specialisation(cfg, out, verbose) if cfg.specialisation_points else None
    rows = rows_a + rows_b
    result = {
        "environment": env,
        "config": dataclasses.asdict(cfg),
        "materials": {k: dict(zip(("eta_film", "eta_base", "kappa_base", "eta_outer"), v))
                      for k, v in MATERIALS.items()},
        "grids": {
            "a": "materials × d ∈ linspace(0, 1000, n_thickness) nm × θ ∈ linspace(0°, 89°, "
                 "n_angle); Stiles & Burch 1959 10° bands unless stated",
            "b": "materials × patch_thickness × patch_theta_deg × patch_alpha (GGX); "
                 "uniform light; Stiles & Burch 1959 10° bands",
            "peers": "θ ∈ linspace(0°, 89°, side) × λ ∈ linspace(380, 780, side) nm, d = 600 nm",
        },
        "rows": rows,
        "panel_b_absent": absent_from_patches(),
        "pareto": {fam: [rows[i]["path"] for i in pareto_rows(rows, fam)]
                   for fam in ("a", "b")},
        "m_selection": m_sweep,
        "reference_check": ref_check,
        "lut": lut_table,
        "peers": peers,
        "targets": summarise_targets(rows, peers),
    }
    if spec is not None:
        result["specialisation"] = spec
    if cfg.stability:
        log("stability report", verbose)
        result["stability"] = write_stability_report(out / "stability_report.md")
    if cfg.name != "tiny":  # kernel_bench.json / .md: XLA cost and time per shading point
        from .kernel_bench import run_kernel_bench

        small = cfg.name == "quick"
        result["kernels"] = run_kernel_bench(out, points=4096 if small else 65536,
                                             repeats=3 if small else 7, verbose=verbose)
        from .method_cost import run_method_cost  # method_cost.json / .md: ns a point, maps

        result["method_cost"] = run_method_cost(out, points=4096 if small else 2**18,
                                                repeats=3 if small else 21,
                                                exact_points=16 if small else 64,
                                                verbose=verbose)["rows"]
    result["seconds_total"] = time.perf_counter() - t_start
    write_peers(peers, out, environment_=env, command="python -m benchmarks.bench (run_bench)",
                config={"name": cfg.name, "peer_sides": list(cfg.peer_sides),
                        "tmm_calls": cfg.tmm_calls, "repeats": cfg.repeats,
                        "extras": cfg.extras})
    _write_rows_report(result, out, cfg, env, verbose)
    return result


def report_markdown(result: dict) -> str:
    """The printed report: environment, the table, M per tolerance, peers, targets."""
    env, rows = result["environment"], result["rows"]
    lines = [f"## thinfilm_jax benchmark ({result['config']['name']})", "",
             f"Devices: {env['devices']} (GPU available: {env['gpu_available']}), "
             f"{env['cpu_count']} CPUs, jax {env['jax']}, load average at start "
             f"{env['load_average']}, {env['date']}. Warm time: median of "
             f"{result['config']['repeats']} calls per evaluation; compile = first call − warm.",
             "", markdown_table(rows), ""]
    other = result.get("environment_other_sections")
    if other:  # `run_rows_only`: the rows above are newer than the sections below
        lines += [f"The rows above: `python -m benchmarks.bench --rows-only` ("
                  f"{result['seconds_rows']:.0f} s). Peers, specialisation, stability and "
                  f"kernels below: the run of {other['date']} (load average at start "
                  f"{other['load_average']}).", ""]
    lines += ["Pareto front (ΔE p95 vs time; rows on another grid or reference excluded): "
              "(a) " + ", ".join(result["pareto"]["a"])
              + "; (b) " + ", ".join(result["pareto"]["b"]), ""]
    lines += ["Panel (b) has a row for every uniform-light method of the registry "
              "(`core.methods.names(\"patch\", exact=False)`, `improved` at each preset of "
              "`ModelOptions.preset`); the registry's other methods: " + "; ".join(
                  f"`{m}`: {why}" for m, why in result.get("panel_b_absent", {}).items()), ""]
    ms = result["m_selection"]
    lines.append("Smallest Fourier order M (family (a) grid, up to "
                 f"{result['config']['m_sweep_max']}; None = not reached):")
    for shat, e in ms.items():
        lines.append(f"- {shat} Ŝ: ΔE max < 1: {e['smallest_M_dE_max_below_1']}, "
                     f"< 0.1: {e['smallest_M_dE_max_below_0.1']}; ΔE p95 < 1: "
                     f"{e['smallest_M_dE_p95_below_1']}, < 0.1: "
                     f"{e['smallest_M_dE_p95_below_0.1']}; θ ≤ 80° only: ΔE max < 1: "
                     f"{e['smallest_M_dE_max_below_1_theta_le_80deg']}, < 0.1: "
                     f"{e['smallest_M_dE_max_below_0.1_theta_le_80deg']}")
    lines += ["", "Peers (µs per (θ, λ) evaluation; ×: speed-up of airy_reflectance value):",
              "", peers_table(result["peers"]), ""]
    lines.append("Targets and specialisation costs:")
    for k, v in result["targets"].items():
        lines.append(f"- {k}: {fmt(v, '.3g') if isinstance(v, float) else v}")
    lines += ["", "LUT of Ŝ(μ, σ²) against the exact quadrature (`lut_max_error`, 4000 random "
              "(μ, σ)) and its effect on K 29 (filtered_gt_moments, patch grid):", "",
              "| Δμ nm | nσ | MiB | build s | max \\|Ŝ_LUT − Ŝ\\| | patch ΔE max vs exact Ŝ "
              "| patch max abs band err vs exact Ŝ |", "|---|---|---|---|---|---|---|"]
    for t in result["lut"]:
        lines.append(f"| {t['d_mu']:g} | {t['n_sigma']} | {t['table_MiB']:.2f} "
                     f"| {t['build_s']:.2f} | {t['shat_max_abs_error']:.2g} "
                     f"| {fmt(t['patch_vs_exact_dE_max'], '.2g')} "
                     f"| {fmt(t['patch_vs_exact_band_abs_max'], '.2g')} |")
    rc = result["reference_check"]
    lines += ["", f"Reference check: {rc['reference']}; max band diff vs order "
              f"{rc['order_check']}: {fmt(rc['max_band_diff_vs_order_check'], '.2g')}; "
              "Monte Carlo max z = " + ", ".join(f"{k}: {v['max_z']:.2f}"
                                                 for k, v in rc["monte_carlo"].items())]
    if "stability" in result:
        s = result["stability"]
        lines.append(f"Stability: {s['n_checks']} checks, {s['n_problems']} problems "
                     "(see stability_report.md)")
    return "\n".join(lines) + "\n"


SUITES = ("core", "ibl", "scaling", "improved", "models", "colour_table", "materials", "photo",
          "cost")


def run_suite(suite: str, out: str = "figures", quick: bool = False) -> None:
    """One suite other than ``core`` (`SUITES`): each study module's own entry point."""
    if suite == "ibl":
        from .ibl_bench import run_ibl_bench

        run_ibl_bench(out=out, quick=quick)
    elif suite == "scaling":
        from .scaling import QUICK, ScalingConfig, format_table, run_scaling

        cfg = ScalingConfig(**(QUICK if quick else {}))
        print(format_table(run_scaling(cfg, out_dir=out)))
    elif suite == "improved":
        from .improved_study import StudyConfig, run

        run(StudyConfig.quick() if quick else StudyConfig(), out=out)
    elif suite == "models":
        from .models_bench import run_models_bench

        run_models_bench(out=out, quick=quick)
    elif suite == "colour_table":
        from .colour_table_study import run_colour_table_study

        run_colour_table_study(out=out, quick=quick)
    elif suite == "materials":
        from . import materials_study as ms

        ms.run(ms.MaterialsConfig.tiny() if quick else ms.MaterialsConfig(), out=out)
    elif suite == "photo":
        from . import photo_study

        photo_study.run(out=out, quick=quick)
    elif suite == "cost":
        from .method_cost import main as cost_main

        cost_main(["--out", str(out)] + (["--quick"] if quick else []))
    else:
        raise ValueError(f"suite must be one of {SUITES}, got {suite!r}")


def main(argv=None) -> int:
    """``python -m benchmarks.bench [--suite S]``: `run_bench` (``--suite core``, the
    default) or another suite (`run_suite`), or all nine (``--suite all``)."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="figures", help="output folder (default: figures)")
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.add_argument("--suite", choices=SUITES + ("all",), default="core",
                   help="core: error vs run time, peers, specialisation (default); ibl: the "
                        "2560×1440 IBL frame and the real-time options' errors; scaling: the "
                        "large jobs on 1, 2 and 4 devices (subprocesses); improved: "
                        "method='improved' against filtered (regions, IBL renders, "
                        "kernel cost, Pareto); models: the classic lobes with a thin film, "
                        "Schlick tint and the film methods against the exact film "
                        "(figures/models.*); colour_table: Kneiphof & Klein 2022's prefiltered "
                        "colour table against filtered, improved and the reference per map "
                        "(figures/colour_table.*); materials: colour charts of films on "
                        "silicon, constant vs dispersive Si, the real-time methods on "
                        "dispersive films (figures/materials.*); photo: thickness maps from "
                        "synthetic photographs and fit_spectrum against optifik "
                        "(figures/photo_study.*); cost: ns a shading point of every method "
                        "under a map against filtered (figures/method_cost.*); all: the nine")
    p.add_argument("--repeats", type=int, help="core: warm repeats per timing (default 5)")
    p.add_argument("--no-stability", action="store_true",
                   help="core: skip stability_report.md")
    p.add_argument("--rows-only", action="store_true",
                   help="core: rerun the error-vs-run-time rows (panels a and b) alone and "
                        "merge them into the existing bench.json (run_rows_only)")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    from thinfilm_jax.core.compilation_cache import enable_compilation_cache

    enable_compilation_cache()  # opt out: THINFILM_JAX_NO_CACHE=1
    if args.suite in ("core", "all"):
        cfg = BenchConfig.quick() if args.quick else BenchConfig.full()
        if args.repeats:
            cfg = dataclasses.replace(cfg, repeats=args.repeats)
        if args.no_stability:
            cfg = dataclasses.replace(cfg, stability=False)
        if args.rows_only:
            run_rows_only(out=args.out, config=cfg)
        else:
            result = run_bench(out=args.out, config=cfg)
            print(f"total {result['seconds_total']:.0f} s; wrote {args.out}/bench.json, "
                  "error_vs_runtime.png, error_vs_runtime.md", file=sys.stderr)
    for suite in SUITES[1:]:
        if args.suite in (suite, "all"):
            run_suite(suite, out=args.out, quick=args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
