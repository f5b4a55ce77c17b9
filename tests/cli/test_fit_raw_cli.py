"""``thinfilm-jax fit`` on spectra (SPEC §14): normal incidence when no angle is given, and
spectrometer exports fitted as raw spectra with ``--envelope``."""

import json

import numpy as np
import pytest

from thinfilm_jax.cli import fit as fit_cli
from thinfilm_jax.cli.main import main

SPECTRUM_CSV = ('# initial = {"thickness": 400, "eta_film": 1.46, "eta_base": 3.9}\n'
                "wavelength_nm,R\n400,0.2\n500,0.3\n600,0.25\n700,0.2\n")


def test_spectrum_csv_without_angle_is_normal_incidence(tmp_path):
    src = tmp_path / "spec.csv"
    src.write_text(SPECTRUM_CSV)
    obs = fit_cli.read_observations(src)
    assert obs["theta_deg"] == [0.0]
    assert "normal incidence" in obs[fit_cli.NOTES][0]


def test_spectrum_csv_without_angle_runs_and_says_so(tmp_path, monkeypatch, capsys):
    seen = {}

    def spy(refl, lam, cos_theta, **kw):
        seen["cos_theta"] = np.asarray(cos_theta)
        raise ValueError("stop here")  # reported as a one-line file error

    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_spectrum", spy)
    src = tmp_path / "spec.csv"
    src.write_text(SPECTRUM_CSV)
    with pytest.raises(SystemExit, match="stop here"):
        main(["fit", str(src)])
    np.testing.assert_array_equal(seen["cos_theta"], [1.0])
    assert "normal incidence (theta_deg = 0) assumed" in capsys.readouterr().out


def test_envelope_setting_is_checked(tmp_path, monkeypatch):
    monkeypatch.setattr("thinfilm_jax.fit.film_fit.fit_spectrum",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("fitted")))
    src = tmp_path / "spec.csv"
    src.write_text("# envelope = -1\n" + SPECTRUM_CSV)
    with pytest.raises(SystemExit, match="envelope must be an integer"):
        main(["fit", str(src)])
    with pytest.raises(SystemExit):
        main(["fit", str(tmp_path / "spec.csv"), "--envelope", "-2"])


def test_raw_export_is_fitted_with_an_envelope(tmp_path, capsys):
    """A two-column .xy of a synthetic raw spectrum (tmm × lamp + offset + noise, as
    tests/fit/test_raw_spectrum.py; 3 µm film) through the command line."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "_raw_tests", Path(__file__).resolve().parents[1] / "fit" / "test_raw_spectrum.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    LAM = mod.LAM
    obs, _, _, _ = mod.raw_signal(3000.0, seed=4)
    src = tmp_path / "film.xy"
    src.write_text("# exported\n" + "".join(f"{a:.1f},{b:.6f}\n" for a, b in zip(LAM, obs)))
    out = tmp_path / "film.fit.json"
    assert main(["fit", str(src), "--eta-film", "1.33", "--eta-base", "1", "--envelope", "2",
                 "--thickness-range", "0", "5000", "--thickness", "1000"]) == 0
    res = json.loads(out.read_text())
    assert res["result"]["params"]["thickness"] == pytest.approx(3000.0, abs=2.0)
    assert res["result"]["envelope"]["degree"] == 2
    assert res["settings"]["envelope"] == 2
    text = capsys.readouterr().out
    assert "raw signal" in text and "thickness = 300" in text
