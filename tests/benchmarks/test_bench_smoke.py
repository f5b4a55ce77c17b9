"""The benchmark code path on a tiny configuration (no timing assertions): it never rots."""

import json

import jax
import numpy as np

from benchmarks import bench, pareto
from thinfilm_jax.core import methods


def test_bench_tiny(tmp_path, capsys):
    # a method registered at run time gets its row in panel (b), beside every uniform-light
    # method of the registry (read from the registry, not a list in the bench)
    extra = methods.Method("ideal_again", ("patch",), False, "exact", True,
                           "the ideal method under another name (test)",
                           impl=methods.implementation("ideal"))
    methods.register(extra)
    try:
        result = bench.run_bench(out=tmp_path, config=bench.BenchConfig.tiny(), verbose=True)
    finally:
        methods.unregister("ideal_again")
    data = json.loads((tmp_path / "bench.json").read_text())
    panel_b = {r["knobs"].get("method") for r in data["rows"] if r["family"] == "b: patch"}
    assert "ideal_again" in panel_b
    assert set(methods.names("patch", exact=False)) <= panel_b
    assert {"improved", "khr"} <= panel_b
    # the registry's methods without a point in (b) are named, with why, in the report
    md = (tmp_path / "error_vs_runtime.md").read_text()
    assert set(data["panel_b_absent"]) == (set(methods.names("envmap"))
                                           - set(methods.names("patch")))
    assert "`colour_table`: no uniform-light form" in md
    assert (tmp_path / "error_vs_runtime.png").stat().st_size > 0
    assert (tmp_path / "error_vs_runtime.md").exists()
    assert data["environment"]["devices"] == [str(d) for d in jax.devices()]
    families = {r["family"] for r in data["rows"]}
    assert families == {"a: shading point", "b: patch", "b: real-time kernel"}
    for r in data["rows"]:
        assert r["warm_s_per_eval"] > 0 and r["compile_s"] >= 0, r
        assert r["dE_max"] is not None and r["dE_max"] >= 0, r
    # the reference itself has zero error; the M sweep agrees with rgb_reflectance
    assert data["rows"][0]["path"] == "spectral (reference)" and data["rows"][0]["dE_max"] == 0
    assert data["m_selection"]["exact"]["max_diff_vs_rgb_reflectance"] < 1e-12
    # the per-point kernels reproduce the patch methods they stand for
    rc = data["reference_check"]
    assert rc["kernel_ideal_vs_patch_ideal_max_abs"] < 1e-5
    assert rc["kernel_K29_exact_vs_patch_filtered_gt_moments_max_abs"] < 1e-5
    # peers agree with each other on the dielectric film
    g = data["peers"]["grids"]["tio2_glass/4x4"]
    assert g["max_abs_diff"]["numpy_vs_airy"] < 1e-12
    assert g["max_abs_diff"]["airy_vs_tmm"] < 1e-10
    # the specialisation table: every row timed and scored; exact specialisations add ~0
    spec = json.loads((tmp_path / "specialisation.json").read_text())
    assert (tmp_path / "specialisation.md").exists()
    rows = {(r["baseline"], r["specialised"], r["films"]): r for r in spec["rows"]}
    assert len(rows) == len(spec["rows"]) >= 10
    for r in spec["rows"]:
        assert r["baseline_us"] > 0 and r["specialised_us"] > 0, r
        assert r["dE_added_max"] is not None and r["dE_added_max"] >= 0, r
    assert rows["ideal M=2, general", "ideal M=2, dielectric", "dielectric"][
        "band_abs_added_max"] < 1e-5
    assert rows["ideal M=2", "ideal M=2, band G only", "absorbing"]["band_abs_added_max"] < 1e-6
    # Fresnel only is the exact d = 0 value: closer to the reference than M = 2
    d0 = rows["ideal M=2", "Fresnel only", "bare"]
    assert d0["specialised_dE_vs_reference_max"] < 0.01
    assert d0["specialised_dE_vs_reference_max"] <= d0["baseline_dE_vs_reference_max"]
    out = capsys.readouterr().out
    assert "| spectral (reference) |" in out and "| no film (d = 0) |" in out
    assert result["pareto"]["a"]


def test_pareto_front():
    t = np.array([1.0, 2.0, 3.0, 0.5, 4.0])
    e = np.array([5.0, 1.0, 2.0, 9.0, 0.1])
    assert pareto.pareto_front(t, e) == [3, 0, 1, 4]


def test_reference_bench_tiny(tmp_path):
    """`kernel_bench --reference`: this checkout against itself loaded as a baseline (the
    path an older checkout takes), one α, one round: both versions are timed and the
    report has its table (x64 is on for the suite: tests/conftest.py)."""
    from pathlib import Path

    from benchmarks import kernel_bench

    here = Path(kernel_bench.__file__).resolve().parents[1]  # the repository root
    r = kernel_bench.run_reference_bench(tmp_path, baselines=(here,), alphas=(0.25,),
                                         resolution=4, repeats=1, verbose=False)
    data = json.loads((tmp_path / "reference_bench.json").read_text())
    assert {row["version"] for row in data["rows"]} == {"new", "old 1"}
    assert all(row["points_per_s"] > 0 for row in data["rows"]) and r["points"] > 0
    assert "× this checkout" in (tmp_path / "reference_bench.md").read_text()


def test_bins_cost_tiny():
    """`small_sources.bins_cost` (the cost column of "Choosing K") on 512 points, one round:
    every program is timed, the light-spread and reads-per-bin variants (K = 3) included."""
    from benchmarks.small_sources import READS_VARIANTS, bins_cost

    r = bins_cost(bins=(2,), points=512, repeats=1, verbose=False)
    assert set(r["ns_per_point"]) == {"ideal", "filtered", "improved K=2",
                                      "improved K=3 + spread"} | {
                                          f"improved {k}" for k in READS_VARIANTS}
    assert all(v > 0 for v in r["ns_per_point"].values())


def test_method_cost_rows_follow_the_registry():
    """The cost table (`benchmarks.method_cost`) times every real-time `envmap_radiance`
    method of the registry as it stands, a method registered at run time included, and
    `improved` once per named preset (no timing here)."""
    from benchmarks.method_cost import method_programs
    from thinfilm_jax import ModelOptions

    methods.register(methods.Method("filtered_again", ("envmap",), False, "bands", False,
                                    "filtered under another name (test)",
                                    impl=methods.implementation("filtered")))
    try:
        progs = method_programs()
    finally:
        methods.unregister("filtered_again")
    assert "filtered_again" in progs
    realtime = {m for m in methods.names("envmap")
                if methods.implementation(m).envmap_kind == "realtime"}
    assert {m for m, _, _ in progs.values()} == realtime | {"filtered_again"}
    for p in ("fast", "default", "accurate"):
        m, preset, opts = progs[f"improved {p}"]
        q = ModelOptions.preset(p)
        assert (m, preset, opts.bins, opts.bin_reads) == ("improved", p, q.bins, q.bin_reads)
