"""Smoke test of the materials study (benchmarks/materials_study.py) at tiny sizes,
and the colorimetry its colour charts rest on. The full run's numbers are
figures/materials.md (docs/studies/materials.md)."""

import dataclasses
import json
import warnings

import numpy as np

from thinfilm_jax import refractive_index
from benchmarks.materials_study import (
    GRID_NM,
    MaterialsConfig,
    run,
    spectra_xyz,
    white_xy,
)


def test_tiny_run_writes_its_report_and_dispersive_silicon_matters(tmp_path):
    """Every part of the report is there and finite; SiO₂ on a constant Si (3.9 + 0.02i, or
    Si at 589 nm) is visibly off the colour of SiO₂ on Schinke's dispersive Si (measured
    ΔE₀₀ mean 6.3–6.4 on this grid, 5.9 in the committed run: the constant misses Si's
    n = 5.6 at 400 nm); the d = 0 chart is the bare Si colour (checked against the
    normal-incidence Fresnel formula, independently of the stack code)."""
    cfg = dataclasses.replace(MaterialsConfig.tiny(), chart_step_nm=500.0, si_n_thickness=3)
    run(cfg, out=tmp_path, verbose=False)
    res = json.loads((tmp_path / "materials.json").read_text())
    assert set(res) >= {"config", "charts", "silicon", "realtime", "environment", "times"}
    assert "| SiO2 on Si |" in (tmp_path / "materials.md").read_text()

    # the silicon comparison: ΔE > 1 (a visible difference) for both constants
    rows = res["silicon"]["rows"]
    assert {r["constant"] for r in rows} == {"3.9 + 0.02i", "Si at 589 nm"}
    assert all(r["dE_mean"] > 1.0 for r in rows), [r["dE_mean"] for r in rows]

    # the real-time part: finite, non-negative errors for each variant
    (row,) = res["realtime"]["rows"]
    for key in ("dispersive", "constant", "on_centroid_films"):
        assert row[key]["finite"] and row[key]["dE_mean"] >= 0.0
    assert res["realtime"]["centroid_resampling_error"] < 1e-5  # measured 6.4e-8

    # d = 0: bare Si, R = |(1 − n̂)/(1 + n̂)|² at normal incidence
    chart = res["charts"]["charts"]["SiO2 on Si | D65"]
    assert res["charts"]["thickness_nm"][0] == 0.0 and res["charts"]["angles_deg"] == [0.0]
    n = np.asarray(refractive_index("Si")(GRID_NM))
    bare = np.abs((1 - n) / (1 + n)) ** 2
    np.testing.assert_allclose(chart["xyz_d0"][0], spectra_xyz(bare, "D65"), rtol=1e-12)
    # the two films share the bare base: the same colour at d = 0
    np.testing.assert_allclose(res["charts"]["charts"]["Si3N4 on Si | D65"]["xyz_d0"][0],
                               chart["xyz_d0"][0], rtol=1e-12)


def test_chart_colorimetry_is_colour_sciences_integration():
    """`spectra_xyz` (colour-science's `msds_to_XYZ`, 1 nm, perfect diffuser Y = 1) agrees
    with `colour.sd_to_XYZ(method="Integration")` of the same spectrum (measured 1e-16 rel.),
    the perfect diffuser has Y = 1 and D65's white is the standard (0.3127, 0.3290)."""
    import colour

    r = 0.3 + 0.2 * np.sin(GRID_NM / 40.0)
    sd = colour.SpectralDistribution(dict(zip(GRID_NM, r)))
    for ill in ("D65", "FL2"):
        with warnings.catch_warnings():  # "Aligning the illuminant to the CMFs": intended
            warnings.simplefilter("ignore")
            ref = colour.sd_to_XYZ(sd, colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"],
                                   colour.SDS_ILLUMINANTS[ill], method="Integration") / 100.0
        np.testing.assert_allclose(spectra_xyz(r, ill), ref, rtol=1e-9)
        assert abs(spectra_xyz(np.ones_like(r), ill)[1] - 1.0) < 1e-12
    np.testing.assert_allclose(white_xy("D65"), [0.3127, 0.3290], atol=2e-4)
