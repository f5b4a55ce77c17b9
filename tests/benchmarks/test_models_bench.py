"""Smoke test of `python -m benchmarks.bench --suite models` (benchmarks/models_bench.py) at
its quick sizes, through its command line (`benchmarks.bench.main`), plus the physics its rows rest on."""

import json

import numpy as np

from benchmarks.bench import main
from benchmarks.models_bench import delta_e, tint_f0
from thinfilm_jax import Film, rgb_reflectance
from thinfilm_jax.spectral import colorimetry as C


def test_models_suite_quick_writes_its_outputs(tmp_path):
    """The quick run (one lobe, one film, one α, methods khr and improved, an 8 × 16 map)
    writes the JSON, the table and the figure; every ΔE is finite and ≥ 0, every cost > 0.
    The full run's numbers are figures/models.md."""
    assert main(["--suite", "models", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "models.json").read_text())
    rows = res["schlick_tint"] + res["film_methods"] + res["ibl"]["rows"]
    assert rows and all(np.isfinite(r["dE2000_mean"]) and r["dE2000_mean"] >= 0 for r in rows)
    assert all(r.get("warm_s_per_point", 1.0) > 0 for r in rows)
    assert {r["method"] for r in res["film_methods"]} == {"reference", "khr", "improved"}
    assert (tmp_path / "models.md").read_text().count("|") > 20
    assert (tmp_path / "models.png").stat().st_size > 10_000


def test_schlick_tint_is_exact_at_normal_incidence_and_the_mirror_is_white():
    """F₀ of the tint is the film's band reflectance at c = 1 (so the tint and the film agree
    at normal view of a mirror-like lobe), and `khr`'s Rec. 709, returned in the bands, is
    compared with the mirror as white: RGB (1, 1, 1) is bands (1, 1, 1), ΔE 0 to the mirror
    (measured 0.0), a 10 % darker grey is ΔE > 1 (measured 2.3)."""
    film = Film(600.0, 1.3, 2.0, 0.5)
    np.testing.assert_allclose(tint_f0(film), rgb_reflectance(film, 1.0), atol=1e-15)
    np.testing.assert_allclose(C.bands_to_rec709(np.ones(3)), 1.0, atol=1e-12)
    assert float(delta_e("khr", C.rec709_to_bands(np.ones(3)), np.ones(3))) < 1e-9
    assert float(delta_e("khr", C.rec709_to_bands(np.full(3, 0.9)), np.ones(3))) > 1


def test_khr_delta_e_is_one_convention_across_studies():
    """The same pair (a `khr` linear Rec. 709 colour, exact bands) gets the same CIEDE2000 from
    `khr.delta_e_to_exact` (CIE 1931 2°), the render and scene studies (khr's values are the bands,
    as `envmap_radiance` returns them: `rec709_to_bands` of its RGB, then the per-pixel ΔE of
    `study_scenes.summarise`) and this bench (`models_bench.delta_e` of the same bands):
    `colorimetry.delta_e2000_rec709`, to 1e-9 (measured ~1e-14). The bench's former convention (the
    reference's bands to Rec. 709, CIELAB with the D65 white) differs from it by up to 0.93 ΔE (mean
    0.17) on these colours, Stiles & Burch bands (asserted > 0.05: the check tells the two
    conventions apart)."""
    import colour

    from thinfilm_jax.spectral.khr import delta_e_to_exact
    from thinfilm_jax.render import study_scenes as R

    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.02, 1.0, (40, 3))
    for observer in ("stiles_burch_1959_10", "cie_1931_2"):
        bands = np.clip(C.rec709_to_bands(rgb, observer)
                        + rng.normal(0.0, 0.05, rgb.shape), 0.01, None)
        want = C.delta_e2000_rec709(rgb, bands, observer)
        # render: khr's values go to the bands once, then the per-pixel ΔE of every method
        r = {"label": "x", "scene": "fig4", "envmap": "m", "alpha": 0.25,
             "mask": np.ones(len(rgb), bool), "times": {"reference": 1.0, "khr": 1.0},
             "values": {"reference": bands, "khr": C.rec709_to_bands(rgb, observer)}}
        cfg = R.RenderConfig(methods=("reference", "khr"), observer=observer, exposure=1.0)
        got = R.summarise([r], cfg)["renders"][0]["dE2000"]["khr"]
        np.testing.assert_allclose([got["mean"], got["max"]], [want.mean(), want.max()],
                                   rtol=1e-9)
        if observer == "cie_1931_2":
            np.testing.assert_allclose(delta_e_to_exact(rgb, bands), want, rtol=0, atol=1e-9)
        else:
            np.testing.assert_allclose(delta_e("khr", C.rec709_to_bands(rgb), bands), want,
                                       rtol=0, atol=1e-9)
            cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]
            ref_rgb = C.bands_to_rec709(bands)
            old = colour.delta_E(*(colour.XYZ_to_Lab(colour.RGB_to_XYZ(x, cs),
                                                     illuminant=cs.whitepoint)
                                   for x in (rgb, ref_rgb)), method="CIE 2000")
            assert np.abs(old - want).max() > 0.05
