"""ψ, Δ of films and stacks (SPEC §14, `thinfilm_jax.optics.ellipsometry`) against closed
forms (a bare substrate's Fresnel ratio, normal incidence, Brewster's angle), `tmm` (Byrnes)
with its Δ convention mapped, and J.A. Woollam's WVASE on the shipped refellips data
(../shared/real/ellipsometry; skipped where absent)."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, Stack
from thinfilm_jax.optics.ellipsometry import (
    ellipsometric_ratio,
    ellipsometry,
    fold_delta,
    psi_delta_traced,
)
from thinfilm_jax.optics.materials import read_csv
from thinfilm_jax.optics.stack import stack_amplitudes, stack_reflectance

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "real" / "ellipsometry"
needs_real = pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} (the shared WVASE data) "
                                                          f"is absent")


def _bare_rho_nebraska(n0, n1, theta):
    """ρ of a bare substrate from the Fresnel formulas in the Nebraska convention (e^{+iωt},
    N = n − iκ; Azzam & Bashara, *Ellipsometry and Polarized Light*, Eq. 4.37), written
    independently of the library: r_p = (N cos θ₀ − n₀ cos θ₁)/(N cos θ₀ + n₀ cos θ₁)."""
    N = np.conj(n1)  # n + iκ → n − iκ
    c0 = np.cos(theta)
    c1 = np.sqrt(1 - (n0 * np.sin(theta) / N) ** 2 + 0j)
    c1 = np.where(np.imag(N * c1) > 0, -c1, c1)  # decaying in e^{+iωt}: Im(N cos θ₁) ≤ 0
    rs = (n0 * c0 - N * c1) / (n0 * c0 + N * c1)
    rp = (N * c0 - n0 * c1) / (N * c0 + n0 * c1)
    return rp / rs


def test_bare_substrate_matches_fresnel_in_nebraska_convention():
    """A bare absorbing base: ψ, Δ equal the Nebraska-convention Fresnel ratio (Δ unfolded)."""
    theta = np.deg2rad(np.array([10.0, 45.0, 70.0, 80.0]))
    n1 = 3.9 + 0.25j
    rho = _bare_rho_nebraska(1.0, n1, theta)
    psi, delta = ellipsometry(Stack([], (), n1), np.cos(theta), 633.0, fold=False)
    np.testing.assert_allclose(psi, np.degrees(np.arctan(np.abs(rho))), atol=1e-10)
    np.testing.assert_allclose(delta, np.degrees(np.angle(rho)) % 360.0, atol=1e-9)
    np.testing.assert_allclose(ellipsometric_ratio(Stack([], (), n1), np.cos(theta), 633.0),
                               rho, atol=1e-12)
    # an absorbing base has Δ in (0°, 180°) in this convention, as WVASE reports silicon
    assert np.all((delta > 0) & (delta < 180))


def test_normal_incidence_and_brewster():
    """ψ = 45°, Δ = 180° at normal incidence (r_p = −r_s); a dielectric at Brewster's angle
    has ψ = 0; Δ = 180° below it and 0° above it (Azzam & Bashara §4.3)."""
    glass = Stack([], (), 1.5)
    tb = np.arctan(1.5)
    psi, delta = (np.asarray(v) for v in ellipsometry(glass, np.cos([0.0, tb - 0.1, tb, tb + 0.1]),
                                                      550.0))
    np.testing.assert_allclose(psi[[0, 2]], [45.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(delta[[0, 1, 3]], [180.0, 180.0, 0.0], atol=1e-9)
    # |r_p|², |r_s|² are stack_reflectance's: the amplitudes are the stack code's
    r = stack_amplitudes(Stack([100.0], (1.46,), 3.9 + 0.02j), 0.6, 550.0)
    for i, pol in enumerate("sp"):
        np.testing.assert_allclose(np.abs(r[i]) ** 2, stack_reflectance(
            Stack([100.0], (1.46,), 3.9 + 0.02j), 0.6, 550.0, pol), rtol=1e-13)


def test_gradient_finite_at_brewster():
    """ψ = 0 (ρ = 0) is a double-where point: the gradient of ψ and Δ is finite there."""
    tb = float(np.arctan(1.5))
    for i in (0, 1):
        g = jax.grad(lambda c, i=i: psi_delta_traced(Stack(jnp.zeros((0,)), (), 1.5), c,
                                                     550.0)[i])(jnp.cos(tb))
        assert np.isfinite(float(g))


def test_against_tmm_absorbing_stack():
    """ψ and Δ of a three-layer stack with an absorbing layer against `tmm.ellips`, whose Δ
    is arg(−r_p/r_s) in the e^{−iωt} convention: Δ_WVASE = 180° − Δ_tmm (mod 360°)."""
    tmm = pytest.importorskip("tmm")
    n = [1.0, 1.46, 2.1 + 0.3j, 1.38, 3.9 + 0.02j]
    d = [np.inf, 120.0, 35.0, 80.0, np.inf]
    lam = np.linspace(350.0, 850.0, 11)
    aoi = np.deg2rad([0.0, 45.0, 65.0, 75.0])
    st = Stack(d[1:-1], tuple(n[1:-1]), n[-1])
    psi, delta = (np.asarray(v) for v in ellipsometry(st, np.cos(aoi)[:, None], lam, fold=False))
    for i, th in enumerate(aoi):
        for j, w in enumerate(lam):
            e = tmm.ellips(n, d, th, w)
            assert abs(psi[i, j] - np.degrees(e["psi"])) < 1e-9
            ref = (180.0 - np.degrees(e["Delta"])) % 360.0
            assert abs((delta[i, j] - ref + 180.0) % 360.0 - 180.0) < 1e-8
    folded = ellipsometry(st, np.cos(aoi)[:, None], lam)[1]
    np.testing.assert_allclose(folded, fold_delta(delta), atol=1e-12)


def test_film_equals_one_layer_stack_and_checks():
    f = Film(250.0, 1.46, 3.9, 0.02)
    a = ellipsometry(f, 0.5, np.array([450.0, 650.0]))
    b = ellipsometry(Stack([250.0], (1.46,), 3.9 + 0.02j), 0.5, np.array([450.0, 650.0]))
    np.testing.assert_allclose(a, b, atol=1e-12)
    with pytest.raises(ValueError, match="eta_outer must be a lossless ambient"):
        ellipsometry(Stack([10.0], (1.5,), 3.9, 1.33 + 0.01j), 0.5, 500.0)
    with pytest.raises(ValueError, match="wavelength"):
        ellipsometry(f, 0.5, -1.0)


def test_fold_delta():
    np.testing.assert_allclose(fold_delta(np.array([0.0, 90.0, 180.0, 190.0, 359.0, -10.0,
                                                    540.0])),
                               [0.0, 90.0, 180.0, 170.0, 1.0, 10.0, 180.0])


def _table(name, interpolation="epsilon"):
    return read_csv(REAL / "materials" / f"{name}.csv", interpolation=interpolation)


@needs_real
def test_read_refellips_tables():
    """The shipped tables (UTF-8 BOM, quoted "Wavelength, µm" header; air.csv names a k
    column it never fills) read as TabulatedIndex: values at the nodes are the file's."""
    si = _table("silicon", "nk")
    assert si.wavelength_range == (206.6, 826.6)
    np.testing.assert_allclose(complex(si(300.0 + 2.4)), 5.02 + 3.979j)  # row 0.3024 µm
    air = read_csv(REAL / "materials" / "air.csv", wavelength_unit="um")
    assert abs(complex(air(230.0)) - 1.000308003) < 1e-12
    with pytest.raises(ValueError, match="without its unit"):
        read_csv(REAL / "materials" / "air.csv")
    # the two rules agree at the nodes
    e = _table("silicon")
    assert abs(complex(e(302.4)) - (5.02 + 3.979j)) < 1e-12


@needs_real
def test_bare_silicon_against_wvase():
    """TestData_bareSI.txt (WVASE, 45–85°, 300–800 nm): with the table interpolated in ε (WVASE's
    rule) ψ and Δ agree to the file's printed digits (ψ 3 decimals, Δ 2); interpolating n, k
    instead misses by 0.03° in ψ (the table is sparse near the 300 nm peaks)."""
    from thinfilm_jax.core.ellipsometry_data import read_ellipsometry

    d = read_ellipsometry(REAL / "TestData_bareSI.txt")
    psi, delta = ellipsometry(Stack([], (), _table("silicon")), np.cos(np.deg2rad(d.angle)),
                              d.wavelength)
    assert np.max(np.abs(psi - d.psi)) < 0.0015
    assert np.max(np.abs(delta - d.delta)) < 0.008
    psi_nk, _ = ellipsometry(Stack([], (), _table("silicon", "nk")),
                             np.cos(np.deg2rad(d.angle)), d.wavelength)
    assert np.max(np.abs(psi_nk - d.psi)) > 0.02  # the rule matters (docstring numbers)
