"""`read_ellipsometry` (SPEC §14): WVASE ``.dat`` exports (synthetic fixtures written here, in
nm and in eV), CompleteEASE rows without the ``E``, the shipped tab-separated WVASE text
(../shared/real/ellipsometry; skipped where absent), and bad input."""

from pathlib import Path

import numpy as np
import pytest

from thinfilm_jax.core.ellipsometry_data import read_ellipsometry
from thinfilm_jax.core.units import HC_EV_NM, to_nanometres

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "real" / "ellipsometry"

# a WVASE export as the program writes it: comment, unit line, E rows, other row kinds
WVASE_NM = """Si with native oxide, spot 3
nm
E\t400.000\t65.000\t28.4710\t112.3040\t0.0120\t0.0450
dpolE\t400.000\t65.000\t0.5120\t0.1000
E\t500.000\t65.000\t22.1050\t130.1020\t0.0100\t0.0380
E\t600.000\t70.000\t14.9980\t141.5060\t0.0090\t0.0410
"""


def _write(tmp_path, text, name="s.dat", encoding="utf-8"):
    p = tmp_path / name
    p.write_bytes(text.encode(encoding))
    return p


def test_wvase_dat_nm(tmp_path):
    d = read_ellipsometry(_write(tmp_path, WVASE_NM))
    np.testing.assert_array_equal(d.wavelength, [400.0, 500.0, 600.0])
    np.testing.assert_array_equal(d.angle, [65.0, 65.0, 70.0])
    np.testing.assert_array_equal(d.psi, [28.471, 22.105, 14.998])
    np.testing.assert_array_equal(d.delta, [112.304, 130.102, 141.506])
    np.testing.assert_array_equal(d.sigma_psi, [0.012, 0.010, 0.009])
    np.testing.assert_array_equal(d.sigma_delta, [0.045, 0.038, 0.041])
    assert d.has_sigma and len(d) == 6  # unpacks as six arrays


def test_wvase_dat_other_units(tmp_path):
    """eV (λ = hc/E, hc = 1239.84198 eV nm), µm written as WVASE's Latin-1 byte 0xB5, Å."""
    ev = WVASE_NM.replace("\nnm\n", "\neV\n").replace("400.000", "3.0").replace(
        "500.000", "2.5").replace("600.000", "2.0")
    d = read_ellipsometry(_write(tmp_path, ev))
    np.testing.assert_allclose(d.wavelength, HC_EV_NM / np.array([3.0, 2.5, 2.0]), rtol=1e-15)
    um = WVASE_NM.replace("\nnm\n", "\nµm\n").replace("400.000", "0.4")
    d = read_ellipsometry(_write(tmp_path, um, encoding="latin-1"))
    assert d.wavelength[0] == 400.0
    a = WVASE_NM.replace("\nnm\n", "\nA\n").replace("400.000", "4000")
    assert read_ellipsometry(_write(tmp_path, a)).wavelength[0] == 400.0
    assert abs(to_nanometres(2.0, "eV") - 619.92099) < 1e-5


def test_completeease_rows_without_e(tmp_path):
    """CompleteEASE writes the six numbers without 'E', beside dPolE and uR rows."""
    text = ("\nVASEmethod[EllipsometerType=4, CompleteEASE=3.65]\nnm\n"
            "370.324\t70.000\t21.4553\t145.7525\t0.0140\t0.0318\t\n"
            "dPolE\t370.324\t0.000\t-5.2834\t1.0000\nuR\t370.324\t0.000\t0.6504\t1.0000\n"
            "371.917\t70.000\t21.0311\t147.7014\t0.0130\t0.0295\t\n")
    d = read_ellipsometry(_write(tmp_path, text))
    np.testing.assert_array_equal(d.psi, [21.4553, 21.0311])
    np.testing.assert_array_equal(d.sigma_delta, [0.0318, 0.0295])


def test_text_without_sigma(tmp_path):
    """λ angle ψ Δ text: σ is NaN (documented), Δ as written (here unfolded, > 180°)."""
    d = read_ellipsometry(_write(tmp_path, "Wavelength\tAngle\tPsi\tDelta\n400\t60.00\t29.485"
                                           "\t266.54\n410\t60.00\t37.883\t279.13\n", "l.txt"))
    assert not d.has_sigma and np.all(np.isnan(d.sigma_psi))
    np.testing.assert_array_equal(d.delta, [266.54, 279.13])


@pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} is absent")
def test_shipped_text_files():
    d = read_ellipsometry(REAL / "TestData_bareSI.txt")
    assert d.psi.shape == (99,) and d.wavelength[0] == 300.0 and d.angle[-1] == 85.0
    assert d.psi[0] == 40.299 and d.delta[0] == 171.85
    d = read_ellipsometry(REAL / "WVASE_example_2nmSiO2_20nmPNIPAM_MultiWavelength.txt")
    assert d.psi.shape == (10,) and set(d.wavelength) == {600.0, 700.0}


@pytest.mark.parametrize("text,match", [
    ("sample\nnm\ndpolE 400 65 0.5 0.1\n", "no ψ, Δ data rows"),
    ("nm\nE 400 65 95.0 100.0 0.01 0.02\n", "psi 95.0° lies outside"),
    ("nm\nE 400 65 nan 100.0 0.01 0.02\n", "psi is nan"),
    ("nm\nE 400 65 20.0 inf 0.01 0.02\n", "delta is inf"),
    ("nm\nE 400 65 20.0 100.0 0.01\n", "5 numbers"),
    ("nm\nE 400 65 20.0 abc 0.01 0.02\n", "'E' row must hold numbers"),
    ("nm\nE -400 65 20.0 100.0 0.01 0.02\n", "wavelength -400.0 must be > 0"),
    ("nm\nE 400 95 20.0 100.0 0.01 0.02\n", "angle 95.0°"),
    ("nm\nE 400 65 20.0 100.0 -0.01 0.02\n", "sigma_psi"),
])
def test_bad_input(tmp_path, text, match):
    with pytest.raises(ValueError, match=match) as e:
        read_ellipsometry(_write(tmp_path, text))
    assert "s.dat" in str(e.value)  # the message names the file (and the line)
