"""SPEC §3 (BB17 series) and §4 (Fourier-domain band integration).

Independent references: the exact Airy sum (checked against tmm in test_fresnel_airy.py),
the closed form of the geometric tail of the series, and a NumPy trapezoid integral over
colour-science's own CMF tables with tmm reflectances.
"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import tmm

import thinfilm_jax as tf
from thinfilm_jax.optics import airy
from thinfilm_jax.optics import fresnel
from thinfilm_jax.optics import series
from thinfilm_jax.spectral import spectra
from thinfilm_jax.spectral.spectra import OBSERVERS, get_observer, sensitivity_ft, shat_at_zero

# Series with M = 200 vs Airy per polarisation (SPEC §3), test_series_m200_equals_airy:
# measured max 7.8e-16 (complex path), 1.7e-16 (real path), i.e. rounding; asserted at 1e-14.
SERIES_ATOL = 1e-14
# Fourier path vs spectral bands (SPEC §4), max over FOURIER_FILMS × bands, per M of M_LIST
# (0, 1, 2, 4, 8, 16, 32, 64). Measured (test_fourier_converges_to_spectral prints them):
#   S&B 10°:   M = 1 … 32: 5.1e-3, 5.9e-4, 4.6e-5, 3.0e-7, 1.6e-8, 8e-15
#   CIE 1931:  M = 1 … 32: 1.9e-3, 1.7e-4, 1.8e-6, 4.3e-8, 4.7e-12, 1.3e-15
# Asserted: each M ≥ 1 within 1.3× of its measured value; rounding-level entries (M ≥ 32,
# and M = 64 everywhere) below 3e-14.
FOURIER_MAX = {
    "stiles_burch_1959_10": {1: 6.6e-3, 2: 7.7e-4, 4: 6.0e-5, 8: 3.9e-7, 16: 2.1e-8,
                             32: 3e-14, 64: 3e-14},
    "cie_1931_2": {1: 2.5e-3, 2: 2.2e-4, 4: 2.3e-6, 8: 5.6e-8, 16: 6.1e-12,
                   32: 3e-14, 64: 3e-14},
}
MIRROR_ATOL = 1e-12  # a perfect mirror gives 1 in every band
BAND_ATOL = 1e-10  # spectral band integral vs NumPy/colour-science/tmm
OBSERVER_NAMES = ("stiles_burch_1959_10", "cie_1931_2")


def _films_no_tir(rng, n, *, theta_max=np.deg2rad(80.0)):
    """Random films without TIR at 1|2 (η_film ≥ η_outer); half absorbing; θ ≤ theta_max."""
    eta_outer = np.where(rng.random(n) < 0.3, 1.33, 1.0)
    eta_film = rng.uniform(eta_outer, 3.0)
    kappa = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.0, 10.0, n))
    film = tf.Film(rng.uniform(0, 10000, n), eta_film, rng.uniform(1.0, 4.0, n), kappa, eta_outer)
    cos_theta = np.cos(rng.uniform(0.0, theta_max, n))
    return film, cos_theta


def _per_pol_airy(film, c, lam, arithmetic="complex"):
    ifc = fresnel.film_interfaces(film, jnp.asarray(c), arithmetic=arithmetic)
    return np.asarray(airy.polarised_reflectance(ifc, film.thickness, lam))


def _rho_amp(terms):
    """ρ = √(R₁₂R₂₃) = |z| and R* − T₁₂₁ per polarisation (NumPy)."""
    return np.abs(np.asarray(terms.z)), np.asarray(terms.amp)


# ------------------------------------------------------------------------------ §3 series


@pytest.mark.parametrize("arithmetic", ["real", "complex"])
def test_series_m200_equals_airy(arithmetic):
    rng = np.random.default_rng(11)
    n = 400
    film, c = _films_no_tir(rng, n)
    if arithmetic == "real":
        film = tf.Film(film.thickness, film.eta_film, np.maximum(film.eta_base, film.eta_outer),
                       0.0, film.eta_outer)
    lam = rng.uniform(360.0, 830.0, n)
    terms = series.series_terms(film, jnp.asarray(c), arithmetic=arithmetic)
    rho, _ = _rho_amp(terms)
    assert rho.max() ** 200 < 1e-14  # M = 200 is converged for these cases
    r_series = np.asarray(series.series_reflectance(terms, lam, 200))
    r_airy = _per_pol_airy(film, c, lam, arithmetic)
    assert r_series.shape == (2, n)
    np.testing.assert_allclose(r_series, r_airy, rtol=0, atol=SERIES_ATOL)


def test_series_coefficients_match_definitions():
    """C₀ = R₁₂ + R*, C_m = (R* − T₁₂₁)ρ^m, φ₂ = arg r₂₁ + arg r₂₃ with r₂₁ = −r₁₂ (SPEC §3)."""
    rng = np.random.default_rng(12)
    film, c = _films_no_tir(rng, 50)
    ifc = fresnel.film_interfaces(film, jnp.asarray(c))
    r12, r23 = np.asarray(ifc.r12), np.asarray(ifc.r23)
    R12, R23 = np.abs(r12) ** 2, np.abs(r23) ** 2
    T = 1 - R12
    rstar = T**2 * R23 / (1 - R12 * R23)
    terms = series.series_terms(film, jnp.asarray(c))
    np.testing.assert_allclose(terms.c0, R12 + rstar, rtol=0, atol=1e-14)
    np.testing.assert_allclose(terms.cm(3), (rstar - T) * np.sqrt(R12 * R23) ** 3, rtol=1e-12,
                               atol=1e-15)
    phi2 = np.angle(-r12) + np.angle(r23)
    dphi = np.angle(np.exp(1j * (np.asarray(terms.phi2) - phi2)))  # compare modulo 2π
    assert np.abs(dphi).max() < 1e-12
    np.testing.assert_allclose(terms.opd, 2 * film.thickness * np.real(np.asarray(ifc.q2)),
                               rtol=1e-15)


# Configurations with a slowly converging series (ρ ≈ 0.2–0.85 for s and p): near-grazing
# incidence, metallic (absorbing) and dielectric bases.
DECAY_FILMS = tf.Film(thickness=np.array([900.0, 1500.0, 400.0, 2500.0]),
                      eta_film=np.array([1.2, 1.4, 1.6, 1.8]),
                      eta_base=np.array([0.2, 3.5, 0.3, 1.5]),
                      kappa_base=np.array([3.0, 0.0, 5.0, 9.0]),
                      eta_outer=np.array([1.0, 1.0, 1.0, 1.33]))
DECAY_COS = np.cos(np.deg2rad([85.0, 85.0, 84.0, 86.0]))
MS = np.arange(1, 31)


def _truncation_errors(film, c, lam):
    terms = series.series_terms(film, jnp.asarray(c))
    exact = _per_pol_airy(film, c, lam)
    errs = np.stack([np.abs(np.asarray(series.series_reflectance(terms, lam, int(m))) - exact)
                     for m in MS])  # (M, 2, n)
    return errs, terms


def test_truncation_error_is_the_geometric_tail_when_phases_align():
    """Choose λ so that z e^{iδ} is real positive per polarisation: then the tail
    2(R*−T)Σ_{m>M} ρ^m is not oscillating and err_M = 2|R*−T| ρ^{M+1}/(1−ρ) exactly, so
    log err_M has slope log ρ in M."""
    terms = series.series_terms(DECAY_FILMS, jnp.asarray(DECAY_COS))
    rho, amp = _rho_amp(terms)
    arg_z = np.angle(np.asarray(terms.z) + 0j)  # (2, n)
    opd = np.asarray(terms.opd)
    # δ = 2π D/λ ≡ −arg z (mod 2π)  →  λ = 2π D / (2πk − arg z) with λ near 550 nm
    k = np.round(opd / 550.0)
    lam = 2 * np.pi * opd / (2 * np.pi * k - arg_z)
    assert np.all((lam > 360) & (lam < 830)) and rho.min() > 0.15
    slopes = []
    for pol in (0, 1):
        errs, _ = _truncation_errors(DECAY_FILMS, DECAY_COS, lam[pol])
        errs = errs[:, pol]  # (M, n)
        tail = 2 * np.abs(amp[pol]) * rho[pol] ** (MS[:, None] + 1) / (1 - rho[pol])
        big = tail > 1e-12  # above rounding
        np.testing.assert_allclose(errs[big], tail[big], rtol=1e-6, atol=1e-15)  # rounding ~1e-16
        for j in range(errs.shape[1]):
            ok = big[:, j]
            slope = np.polyfit(MS[ok], np.log(errs[ok, j]), 1)[0]
            slopes.append((slope, np.log(rho[pol, j])))
            assert slope == pytest.approx(np.log(rho[pol, j]), rel=0.01)
    print("\nseries truncation slope vs log ρ:",
          ", ".join(f"{s:.4f}/{r:.4f}" for s, r in slopes))


def test_truncation_error_bounded_by_geometric_tail_any_phase():
    """Any λ: err_M ≤ 2|R*−T| ρ^{M+1}/(1−ρ), and the decreasing envelope of err_M decays like ρ^M
    (slope of log envelope within 5 % of log ρ)."""
    lam = np.array([433.0, 517.0, 611.0, 702.0])
    errs, terms = _truncation_errors(DECAY_FILMS, DECAY_COS, lam)
    rho, amp = _rho_amp(terms)
    bound = 2 * np.abs(amp) * rho ** (MS[:, None, None] + 1) / (1 - rho)
    assert np.all(errs <= bound * (1 + 1e-9) + 1e-15)
    for pol in (0, 1):
        for j in range(len(lam)):
            e = errs[:, pol, j]
            env = np.maximum.accumulate(e[::-1])[::-1]  # max over M' ≥ M
            ok = env > 1e-12
            slope = np.polyfit(MS[ok], np.log(env[ok]), 1)[0]
            assert slope == pytest.approx(np.log(rho[pol, j]), rel=0.05), (pol, j)


def test_series_tir_limitation_is_documented_truth():
    """η_outer > η_film beyond the critical angle: the series (T₁₂₁ = 0) says R = 1 exactly,
    while the exact Airy sum keeps frustrated transmission through a very thin film."""
    film = tf.Film(20.0, 1.0, 1.5, 0.0, 1.5)  # glass | 20 nm air gap | glass
    c = np.cos(np.deg2rad(60.0))  # 1.5 sin 60° = 1.30 > 1: TIR at 1|2
    lam = 550.0
    terms = series.series_terms(film, jnp.asarray(c))
    for m in (2, 8, 200):
        np.testing.assert_allclose(series.series_reflectance(terms, lam, m), 1.0, rtol=0,
                                   atol=1e-14)
    r_airy = float(tf.airy_reflectance(film, c, lam))
    assert r_airy < 0.5  # most light tunnels through the 20 nm gap
    # and Airy is right: tmm agrees (independent check of the frustrated-TIR value)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = np.mean([tmm.coh_tmm(p, [1.5, 1.0, 1.5], [np.inf, 20.0, np.inf], np.arccos(c), lam)
                       ["R"] for p in "sp"])
    assert r_airy == pytest.approx(ref, abs=1e-12)
    # for a thick gap the tunnelling vanishes and both agree on R = 1
    thick = film._replace(thickness=3000.0)
    assert float(tf.airy_reflectance(thick, c, lam)) == pytest.approx(1.0, abs=1e-12)


# Regression cases (found by the float32-vs-float64 comparison): TIR at 1|2 with an evanescent
# film. (a) dielectric base: |r₁₂| = |r₂₃| = 1, so 1 − R₁₂R₂₃ is a rounding residue (~1e-33
# once XLA fuses it into an FMA) and R* = T²R₂₃/(1 − R₁₂R₂₃) used to come out O(1);
# (b) metal base: |r₂₃| ≈ 5 > 1 for the evanescent wave, so rounding in T multiplied |z|^m.
TIR_FILMS = tf.Film(np.array([703.79, 44.86]), np.array([1.192, 1.221]), np.array([3.663, 3.200]),
                    np.array([0.0, 8.545]), 1.33)
TIR_COS = np.array([0.4306, 0.3804])


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32], ids=["f64", "f32"])
def test_series_under_tir_is_exactly_one(dtype):
    film, c = TIR_FILMS.astype(dtype), jnp.asarray(TIR_COS, dtype)
    r23 = np.abs(np.asarray(fresnel.film_interfaces(film, c).r23))
    assert r23.max() > 2  # case (b) really has |r₂₃| > 1
    terms = series.series_terms(film, c)
    for m in (2, 64):
        np.testing.assert_allclose(series.series_reflectance(terms, dtype(550.0), m), 1.0,
                                   rtol=0, atol=10 * np.finfo(dtype).eps)
    # jitted (case (a) appeared only there, where XLA may contract 1 − R₁₂R₂₃ into an FMA)
    bands = tf.rgb_reflectance(film, c, method="fourier", terms=2)
    np.testing.assert_allclose(bands, 1.0, rtol=0, atol=10 * np.finfo(dtype).eps)


# ------------------------------------------------------------------------------ §4 Fourier

# Films with ρ ≤ 0.6 at the chosen angles so that ρ^65 is negligible at M = 64.
FOURIER_FILMS = tf.Film(thickness=np.array([0.0, 150.0, 600.0, 1200.0, 3000.0, 8000.0, 450.0,
                                            20000.0]),
                        eta_film=np.array([1.5, 1.33, 1.3, 2.2, 1.8, 1.45, 2.5, 1.6]),
                        eta_base=np.array([1.5, 2.0, 2.0, 1.5, 0.2, 3.0, 1.0, 1.2]),
                        kappa_base=np.array([0.0, 0.0, 0.5, 0.0, 3.0, 0.0, 8.0, 0.0]),
                        eta_outer=np.array([1.0, 1.0, 1.0, 1.33, 1.0, 1.0, 1.0, 1.33]))
FOURIER_COS = np.cos(np.deg2rad([0.0, 20.0, 45.0, 30.0, 10.0, 50.0, 0.0, 60.0]))
M_LIST = (0, 1, 2, 4, 8, 16, 32, 64)


@pytest.mark.parametrize("observer", OBSERVER_NAMES)
def test_fourier_converges_to_spectral(observer):
    ref = np.asarray(tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, observer=observer))
    terms = series.series_terms(FOURIER_FILMS, jnp.asarray(FOURIER_COS))
    rho, amp = _rho_amp(terms)
    assert rho.max() < 0.62
    w_abs = np.abs(get_observer(observer).weights).sum(axis=0)  # Σ_k |W_kj| (S&B has lobes < 0)
    errs = []
    for m in M_LIST:
        # run eagerly (op by op): the same code, without compiling one program per M
        with jax.disable_jit():
            got = np.asarray(tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, observer=observer,
                                                method="fourier", terms=m))
        err = np.abs(got - ref)  # (n, J)
        # per band: |error| ≤ Σ_k |W_kj| · max_pol 2|R*−T|ρ^{M+1}/(1−ρ)
        tail = (2 * np.abs(amp) * rho ** (m + 1) / (1 - rho)).max(axis=0)
        assert np.all(err <= tail[:, None] * w_abs[None, :] * (1 + 1e-9) + 1e-14), m
        errs.append(err.max())
    # the compiled path gives the same numbers
    jitted = tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, observer=observer, method="fourier",
                                terms=2)
    with jax.disable_jit():
        eager = tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, observer=observer,
                                   method="fourier", terms=2)
    np.testing.assert_allclose(jitted, eager, rtol=0, atol=1e-14)
    print(f"\n{observer}: max |fourier − spectral| for M = {M_LIST}:",
          ", ".join(f"{e:.1e}" for e in errs))
    for m, e in zip(M_LIST, errs):
        if m in FOURIER_MAX[observer]:
            assert e <= FOURIER_MAX[observer][m], (m, e, FOURIER_MAX[observer][m])
    assert errs[0] > 1e-3  # M = 0 is a poor approximation: the test can fail
    # decreasing envelope (up to rounding once converged)
    for a, b in zip(errs, errs[1:]):
        assert b <= max(a, 1e-14)
    assert errs[3] < 1e-2 * errs[0]


# |bands with the Gaussian-fit Ŝ − bands with the tabulated Ŝ| over FOURIER_FILMS, M = 4,
# S&B 10° (default observer): measured max per band 3.8e-3, 4.6e-3, 2.40e-2 (the fit's own Ŝ
# error is 0.011 / 0.013 / 0.008, test_spectra_colour.py). Asserted with a 1.1× margin.
GAUSSIAN_BANDS_MAX = np.array([4.2e-3, 5.1e-3, 2.64e-2])


def test_fourier_gaussian_shat_close_to_tabulated():
    """The Gaussian-fit Ŝ (BB17) in the Fourier path stays near the tabulated one."""
    # regression: the (cached) fit must also work when first needed while jit is tracing
    spectra.gaussian_fit.cache_clear()
    a = tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, method="fourier", terms=4)
    b = tf.rgb_reflectance(FOURIER_FILMS, FOURIER_COS, method="fourier", terms=4, shat="gaussian")
    diff = np.abs(np.asarray(a) - np.asarray(b)).max(axis=0)
    assert np.all(diff <= GAUSSIAN_BANDS_MAX), diff


@pytest.mark.parametrize("observer", OBSERVER_NAMES)
def test_mirror_gives_one_in_every_band(observer):
    obs = get_observer(observer)
    # the weights themselves: Σ_k W_kj = 1 (each band has unit area, SPEC §1)
    np.testing.assert_allclose(obs.weights.sum(axis=0), 1.0, rtol=0, atol=MIRROR_ATOL)
    np.testing.assert_allclose(shat_at_zero(observer), 1.0, rtol=0, atol=MIRROR_ATOL)
    np.testing.assert_allclose(sensitivity_ft(0.0, observer), 1.0, rtol=0, atol=MIRROR_ATOL)
    # total internal reflection: η_outer = 3 > η_film = 1, grazing, a thick gap (no tunnelling);
    # dielectric and metallic bases (8 films: the shapes of FOURIER_FILMS, compiled once)
    n = len(FOURIER_COS)
    film = tf.Film(np.linspace(5000.0, 20000.0, n), 1.0, np.linspace(1.0, 4.0, n),
                   np.where(np.arange(n) % 2 == 0, 0.0, 3.0), 3.0)
    c = np.linspace(0.0, 0.3, n)  # 3 sin θ ≥ 2.86 > 1
    for method, m in (("fourier", 2), ("fourier", 16), ("spectral", 2)):
        with jax.disable_jit(m > 2):  # M = 16 eagerly (no 16-term compilation)
            got = np.asarray(tf.rgb_reflectance(film, c, observer=observer, method=method,
                                                terms=m))
        assert got.shape == (n, obs.n_bands)
        np.testing.assert_allclose(got, 1.0, rtol=0, atol=MIRROR_ATOL, err_msg=method)


def _tmm_spectrum(film_args, theta, lams):
    n_list = [film_args[4], film_args[1], film_args[2] + 1j * film_args[3]]
    d_list = [np.inf, film_args[0], np.inf]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.array([0.5 * (tmm.coh_tmm("s", n_list, d_list, theta, lam)["R"]
                                + tmm.coh_tmm("p", n_list, d_list, theta, lam)["R"])
                         for lam in lams])


@pytest.mark.parametrize("observer", OBSERVER_NAMES)
def test_spectral_band_integral_independent(observer):
    """∫R(λ)S_j dλ / ∫S_j dλ with numpy.trapezoid over colour-science's own CMF table and tmm R."""
    import colour

    cmfs = colour.MSDS_CMFS[OBSERVERS[observer]]
    lams = np.asarray(cmfs.wavelengths, float)
    s = np.asarray(cmfs.values, float)  # (K, 3)
    cases = [((600.0, 1.3, 2.0, 0.5, 1.0), 0.0), ((350.0, 2.1, 1.5, 0.0, 1.0), 0.6),
             ((2500.0, 1.45, 3.0, 4.0, 1.33), 1.1)]
    for args, theta in cases:
        r = _tmm_spectrum(args, theta, lams)
        want = np.trapezoid(r[:, None] * s, lams, axis=0) / np.trapezoid(s, lams, axis=0)
        got = np.asarray(tf.rgb_reflectance(tf.Film(*args), np.cos(theta), observer=observer))
        np.testing.assert_allclose(got, want, rtol=0, atol=BAND_ATOL)
