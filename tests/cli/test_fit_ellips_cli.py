"""``thinfilm-jax fit-ellips`` (SPEC §14): a synthetic WVASE ``.dat`` in eV with σ columns
(one film, its thickness recovered, WVASE's MSE ≈ 1), the shipped WVASE PNIPAM file with a
stack of the shipped tables (skipped where ../shared is absent), and usage errors."""

import json
from pathlib import Path

import numpy as np
import pytest

from thinfilm_jax import Film
from thinfilm_jax.cli.main import main
from thinfilm_jax.core.units import HC_EV_NM
from thinfilm_jax.optics.ellipsometry import ellipsometry

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "real" / "ellipsometry"


def test_synthetic_dat_in_ev(tmp_path, capsys):
    """A 230 nm oxide (n = 1.46) on a silicon-like base, written as WVASE 'E' rows in eV with
    σψ = 0.01°, σΔ = 0.05° and noise of that size: the thickness comes back within 0.2 nm."""
    ev = np.linspace(1.6, 3.2, 25)
    lam = HC_EV_NM / ev
    rng = np.random.default_rng(3)
    rows = []
    for aoi in (65.0, 70.0):
        psi, delta = (np.asarray(v) for v in ellipsometry(Film(230.0, 1.46, 3.9, 0.02),
                                                          np.cos(np.deg2rad(aoi)), lam))
        psi = psi + rng.normal(0, 0.01, psi.shape)
        delta = delta + rng.normal(0, 0.05, delta.shape)
        rows += [f"E\t{e:.6f}\t{aoi:.3f}\t{p:.5f}\t{d:.4f}\t0.0100\t0.0500"
                 for e, p, d in zip(ev, psi, delta)]
    path = tmp_path / "oxide.dat"
    path.write_text("oxide on Si, synthetic\neV\n" + "\n".join(rows) + "\n")
    rc = main(["fit-ellips", str(path), "--eta-film", "1.46", "--thickness", "150",
               "--eta-base", "3.9+0.02j"])
    assert rc == 0
    out = json.loads((tmp_path / "oxide.ellips.json").read_text())
    res = out["result"]
    assert out["sigma_from_file"] and abs(res["params"]["thickness"] - 230.0) < 0.2
    assert 0.5 < res["reduced_chi2"] < 1.6  # WVASE's MSE² with σ from the file
    assert "MSE" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="fit-ellips: .* exists; pass --overwrite"):
        main(["fit-ellips", str(path), "--eta-film", "1.46", "--thickness", "150",
              "--eta-base", "3.9+0.02j"])  # never over a result without --overwrite


@pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} is absent")
def test_wvase_pnipam_file(tmp_path, capsys):
    m = REAL / "materials"
    out = tmp_path / "pn.json"
    rc = main(["fit-ellips", str(REAL / "WVASE_example_2nmSiO2_20nmPNIPAM_MultiWavelength.txt"),
               "--layers", f"{m / 'pnipam.csv'}:15,{m / 'silica.csv'}:2",
               "--eta-base", str(m / "silicon.csv"), "--interpolation", "epsilon",
               "--free", "thickness[0]", "--out", str(out)])
    assert rc == 0
    res = json.loads(out.read_text())["result"]
    assert abs(res["params"]["thickness[0]"] - 19.40) < 0.01  # tests/fit: the same fit
    assert "thickness[0] = 19.39" in capsys.readouterr().out


@pytest.mark.parametrize("args,match", [
    (["--eta-base", "Si"], "either --layers"),
    (["--eta-film", "1.46", "--eta-base", "Si"], "--thickness"),
    (["--layers", "SiO2:x", "--eta-base", "Si"], "--layers"),
    (["--layers", "SiO2:10", "--eta-base", "nosuchmaterial"], "--eta-base"),
])
def test_usage_errors(tmp_path, capsys, args, match):
    path = tmp_path / "d.dat"
    path.write_text("nm\nE 500 70 20 100 0.01 0.05\nE 600 70 22 110 0.01 0.05\n")
    with pytest.raises(SystemExit) as e:
        main(["fit-ellips", str(path), *args])
    assert e.value.code == 2 and match in capsys.readouterr().err
