"""Smoke test of `thinfilm-jax bench --suite models` (thinfilm_jax/studies/models_bench.py) at
its quick sizes, through the command line, plus the physics its rows rest on."""

import json

import numpy as np

from thinfilm_jax import Film, rgb_reflectance
from thinfilm_jax.cli.main import main
from thinfilm_jax.studies.models_bench import (_bands_to_rec709, delta_e_rec709,
                                                tint_f0)


def test_models_suite_quick_writes_its_outputs(tmp_path):
    """The quick run (one lobe, one film, one α, methods khr and improved, an 8 × 16 map)
    writes the JSON, the table and the figure; every ΔE is finite and ≥ 0, every cost > 0.
    The full run's numbers are figures/models.md."""
    assert main(["bench", "--suite", "models", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "models.json").read_text())
    rows = res["schlick_tint"] + res["film_methods"] + res["ibl"]["rows"]
    assert rows and all(np.isfinite(r["dE2000_mean"]) and r["dE2000_mean"] >= 0 for r in rows)
    assert all(r.get("warm_s_per_point", 1.0) > 0 for r in rows)
    assert {r["method"] for r in res["film_methods"]} == {"reference", "khr", "improved"}
    assert (tmp_path / "models.md").read_text().count("|") > 20
    assert (tmp_path / "models.png").stat().st_size > 10_000


def test_schlick_tint_is_exact_at_normal_incidence_and_the_mirror_is_white():
    """F₀ of the tint is the film's band reflectance at c = 1 (so the tint and the film agree
    at normal view of a mirror-like lobe), and the Rec. 709 conversion used for `khr` maps
    the perfect mirror to (1, 1, 1) (ΔE 0 to it; a 10 % darker grey is ΔE > 1)."""
    film = Film(600.0, 1.3, 2.0, 0.5)
    np.testing.assert_allclose(tint_f0(film), rgb_reflectance(film, 1.0), atol=1e-15)
    np.testing.assert_allclose(_bands_to_rec709(np.ones(3)), 1.0, atol=2e-3)
    assert float(delta_e_rec709(_bands_to_rec709(np.ones(3)), np.ones(3))) < 0.2
    assert float(delta_e_rec709(np.full(3, 0.9), np.ones(3))) > 1
