"""Fitting film parameters to patch colours and spectra (SPEC §8).

Synthetic data come from the converged reference (`patch_radiance`, quadrature 48 × 48);
the fits use their own, smaller quadrature (16 × 16, ~1e-5 from converged), so
"noise-free" recovery also checks that this quadrature is accurate enough. Compilation
dominates the run time: the fits below share configurations where they can (same
`free`, method and shapes ⇒ one compiled solver).
"""

import json
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film, airy_reflectance
from thinfilm_jax.cli.main import main as cli_main
from thinfilm_jax.fit.film_fit import (DEFAULT_BOUNDS, FitOptions, FitResult, _to_x, _to_y, fit_film,
                              fit_spectrum, patch_model, spectrum_model)
from thinfilm_jax.fit.options import MisfitWarning
from thinfilm_jax.shading.patch import patch_radiance

FIG7 = Film(600.0, 1.3, 2.0, 0.5)  # Kneiphof et al. 2019 Figure 7 film (SPEC §7)
ALPHA = 0.25
THETA = np.deg2rad(np.linspace(0.0, 80.0, 9))  # 9 view angles
FOUR = ("thickness", "eta_film", "eta_base", "kappa_base")

# Spectral metrology case: SiO₂-like film on a Si-like base, 3 angles, 400–800 nm.
SPEC_FILM = Film(812.3, 1.46, 3.9, 0.02)
LAMBDA = np.arange(400.0, 800.1, 5.0)
COS = np.cos(np.deg2rad([0.0, 30.0, 60.0]))

# Acceptance tolerances (README, fitting).
TOL_D_PATCH = 1.0  # nm
TOL_ETA = 0.01
TOL_D_SPECTRUM = 0.5  # nm


@pytest.fixture(scope="module")
def fig7_obs():
    return np.asarray(patch_radiance(FIG7, THETA, ALPHA))


@pytest.fixture(scope="module")
def spectra():
    return np.asarray(airy_reflectance(SPEC_FILM, COS[:, None], LAMBDA))


# ----------------------------------------------------------------------------- patch fits
@pytest.mark.parametrize("d0", [350.0, 850.0])  # ≥ 200 nm either side: other fringe orders
def test_fit_thickness_alone(fig7_obs, d0):
    res = fit_film(fig7_obs, THETA, alpha=ALPHA, initial=FIG7._replace(thickness=d0))
    assert isinstance(res, FitResult)
    assert abs(float(res.film.thickness) - 600.0) <= TOL_D_PATCH
    assert bool(res.converged)
    # the fixed fields are returned unchanged, α as given
    assert float(res.film.eta_film) == 1.3 and float(res.alpha) == ALPHA
    se = float(res.stderr["thickness"])
    assert np.isfinite(se) and 0 <= se < 0.01  # noise-free: only quadrature error is left
    assert res.correlation.shape == (1, 1) and res.degenerate == []
    assert res.residuals.shape == fig7_obs.shape
    assert float(res.loss) < 1e-10


def test_single_start_finds_wrong_fringe(fig7_obs):
    """Why multi-start: from 350 nm a single local solve stops in another fringe order
    (the thickness loss has minima ~220 nm apart; see notebooks/fitting.ipynb). The cheap
    `filtered` model (quadrature 8 × 8) is enough to show it."""
    q = (8, 8)
    opts = FitOptions(quadrature=q, start_quadrature=q)
    kw = dict(alpha=ALPHA, method="filtered")
    one = fit_film(fig7_obs, THETA, initial=FIG7._replace(thickness=350.0),
                   options=opts.replace(n_starts=1), **kw)
    assert abs(float(one.film.thickness) - 600.0) > 50.0
    multi = fit_film(fig7_obs, THETA, initial=FIG7._replace(thickness=350.0), options=opts,
                     **kw)
    assert abs(float(multi.film.thickness) - 600.0) < 10.0  # filtered is biased by ~3 nm
    assert float(one.loss) > 10 * float(multi.loss)
    # runner-ups: other fringe orders, reported with their loss gap; the data tell them
    # apart (Δχ² ≫ 9) ...
    ru = multi.runner_ups
    assert ru and all(abs(r["params"]["thickness"] - float(multi.film.thickness)) > 100.0
                      for r in ru)
    assert all(r["loss"] > float(multi.loss) and r["dchi2"] > 100.0 for r in ru)
    assert not multi.ambiguous
    # ... unless the noise is as large as the signal (same compiled fit)
    rng = np.random.default_rng(1)
    noisy = np.abs(fig7_obs + 0.5 * fig7_obs.std() * rng.standard_normal(fig7_obs.shape))
    vague = fit_film(noisy, THETA, initial=FIG7._replace(thickness=350.0), options=opts, **kw)
    assert vague.ambiguous and min(r["dchi2"] for r in vague.runner_ups) < 9.0


@pytest.mark.slow
def test_fit_four_film_parameters(fig7_obs):
    """d, η₂, η₃, κ₃ together from RGB: recovered noise-free, but η₃ and κ₃ are almost
    interchangeable (corr ≈ −0.998, flagged as degenerate): with 1 % noise their standard
    errors are ~0.05 (measured), so only d and η₂ are well posed
    (benchmarks/fit_study.py)."""
    init = Film(350.0, 1.45, 1.7, 0.3)
    res = fit_film(fig7_obs, THETA, alpha=ALPHA, initial=init, free=FOUR)
    assert abs(float(res.film.thickness) - 600.0) <= TOL_D_PATCH
    for k, truth in (("eta_film", 1.3), ("eta_base", 2.0), ("kappa_base", 0.5)):
        assert abs(float(getattr(res.film, k)) - truth) <= TOL_ETA, k
    assert bool(res.converged)
    corr = np.asarray(res.correlation)
    assert corr.shape == (4, 4)
    np.testing.assert_allclose(np.diag(corr), 1.0, atol=1e-12)
    np.testing.assert_allclose(corr, corr.T, atol=1e-12)
    assert corr[2, 3] < -0.95
    assert ("eta_base", "kappa_base") in res.degenerate
    assert set(res.stderr) == set(FOUR)
    assert all(np.isfinite(float(v)) for v in res.stderr.values())


def test_stderr_in_physical_units(fig7_obs):
    """stderr is √diag(s²(JᵀJ)⁻¹) with J taken in the physical parameters (nm, not logit);
    with the noise σ given (which s² makes no difference to), the reduced χ² is Σ(r/σ)²/(n − 1)
    and the right film raises no misfit warning."""
    rng = np.random.default_rng(3)
    obs = fig7_obs + 1e-3 * rng.standard_normal(fig7_obs.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MisfitWarning)
        res = fit_film(obs, THETA, alpha=ALPHA, initial=FIG7._replace(thickness=350.0),
                       sigma=1e-3)
    d = float(res.film.thickness)
    jac = jax.jacfwd(lambda t: patch_model(FIG7._replace(thickness=t), THETA, ALPHA)
                     .reshape(-1))(jnp.asarray(d))
    r = np.asarray(res.residuals).reshape(-1)
    s2 = np.sum(r * r) / (r.size - 1)
    np.testing.assert_allclose(float(res.stderr["thickness"]), np.sqrt(s2 / (jac @ jac)),
                               rtol=1e-6)
    assert abs(d - 600.0) < 4 * float(res.stderr["thickness"]) + 0.05
    np.testing.assert_allclose(float(res.reduced_chi2), s2 / 1e-6, rtol=1e-9)
    assert res.warnings == ()


def test_gradient_through_fit_film():
    """d(fitted d)/d(observed) by jax.grad through optx.least_squares (implicit adjoint).

    At a zero-residual optimum the implicit function theorem gives exactly
    ∂d̂/∂o = (JᵀJ)⁻¹Jᵀ (J = ∂model/∂d): the gradient must equal that row."""
    q = (8, 8)
    truth = FIG7._replace(thickness=450.0)
    obs = patch_model(truth, THETA, ALPHA, method="filtered", quadrature=q)

    def fitted(o):
        res = fit_film(o, THETA, alpha=ALPHA, initial=truth._replace(thickness=440.0),
                       method="filtered",
                       options=FitOptions(quadrature=q, start_quadrature=q, n_starts=1))
        return res.film.thickness

    g = jax.grad(fitted)(obs)
    assert g.shape == obs.shape and bool(jnp.all(jnp.isfinite(g)))
    jac = jax.jacfwd(lambda t: patch_model(truth._replace(thickness=t), THETA, ALPHA,
                                           method="filtered", quadrature=q).reshape(-1))(450.0)
    np.testing.assert_allclose(np.asarray(g).reshape(-1), np.asarray(jac / (jac @ jac)),
                               rtol=1e-5, atol=1e-8)


# ----------------------------------------------------------------------------- spectra
def test_fit_spectrum_thickness(spectra):
    res = fit_spectrum(spectra, LAMBDA, COS, initial=SPEC_FILM._replace(thickness=300.0))
    assert abs(float(res.film.thickness) - 812.3) <= TOL_D_SPECTRUM
    assert bool(res.converged) and res.alpha is None
    assert res.residuals.shape == spectra.shape


def test_fit_spectrum_four_parameters(spectra):
    init = Film(1500.0, 1.6, 3.5, 0.1)
    res = fit_spectrum(spectra, LAMBDA, COS, initial=init, free=FOUR)
    assert abs(float(res.film.thickness) - 812.3) <= TOL_D_SPECTRUM
    for k in FOUR[1:]:
        assert abs(float(getattr(res.film, k)) - getattr(SPEC_FILM, k)) <= TOL_ETA, k


def test_spectrum_stderr_coverage(spectra):
    """Seeded Monte Carlo: 1 % noise, d and η₂ free; |fit − truth| ≤ 1.96·stderr in about
    95 % of the fits (linearised errors are good here: the spectral problem is near-linear
    at 1 % noise)."""
    rng = np.random.default_rng(0)
    sd = 0.01 * np.sqrt(np.mean(spectra**2))
    hits, n = [], 40
    for _ in range(n):
        obs = spectra + sd * rng.standard_normal(spectra.shape)
        res = fit_spectrum(obs, LAMBDA, COS, initial=SPEC_FILM._replace(thickness=500.0),
                           free=("thickness", "eta_film"))
        hits.append([abs(float(res.params[k]) - getattr(SPEC_FILM, k))
                     <= 1.96 * float(res.stderr[k]) for k in ("thickness", "eta_film")])
    cover = np.mean(hits, axis=0)
    assert np.all(cover >= 0.85), cover  # binomial(40, 0.95): P(< 0.85) ≈ 1 %


def test_gradient_through_fit_spectrum(spectra):
    g = jax.grad(lambda o: fit_spectrum(o, LAMBDA, COS, initial=SPEC_FILM._replace(
        thickness=800.0), options=FitOptions(n_starts=1)).film.thickness)(jnp.asarray(spectra))
    jac = jax.jacfwd(lambda t: spectrum_model(SPEC_FILM._replace(thickness=t), COS, LAMBDA)
                     .reshape(-1))(812.3)
    np.testing.assert_allclose(np.asarray(g).reshape(-1), np.asarray(jac / (jac @ jac)),
                               rtol=1e-6, atol=1e-10)


def test_fit_spectrum_under_jit_and_vmap(spectra):
    """SPEC §8: the fit composes with jax.jit and jax.vmap over the observations."""
    other = np.asarray(airy_reflectance(SPEC_FILM._replace(thickness=505.0), COS[:, None],
                                        LAMBDA))

    def fitted(o):
        return fit_spectrum(o, LAMBDA, COS, initial=SPEC_FILM._replace(thickness=700.0),
                            options=FitOptions(n_starts=64)).film.thickness

    d = jax.jit(jax.vmap(fitted))(jnp.stack([jnp.asarray(spectra), jnp.asarray(other)]))
    np.testing.assert_allclose(np.asarray(d), [812.3, 505.0], atol=TOL_D_SPECTRUM)


def test_solvers_by_name(spectra):
    init = SPEC_FILM._replace(thickness=790.0)
    for solver in ("gauss_newton", "dogleg", "bfgs"):
        res = fit_spectrum(spectra, LAMBDA, COS, initial=init,
                           options=FitOptions(n_starts=1, solver=solver))
        assert abs(float(res.film.thickness) - 812.3) <= TOL_D_SPECTRUM, solver


# ----------------------------------------------------------------------------- parameter map
def test_box_map_round_trip_and_bounds():
    lo, hi = DEFAULT_BOUNDS["thickness"]
    x = jnp.linspace(50.0, 1950.0, 7)
    np.testing.assert_allclose(_to_x(_to_y(x, lo, hi), lo, hi), x, rtol=1e-12)
    y = jnp.asarray([-800.0, -30.0, 0.0, 30.0, 800.0])
    xs = _to_x(y, lo, hi)
    assert bool(jnp.all((xs >= lo) & (xs <= hi)))
    assert bool(jnp.all(jnp.isfinite(jax.vmap(jax.grad(lambda t: _to_x(t, lo, hi)))(y))))


def test_misfit_warning(spectra):
    """σ given: `reduced_chi2` = Σ((R(fit) − o)/σ)²/(n − p), recomputed here with
    `airy_reflectance`; spectra of the film with noise σ fit to ≈ 1 (ν = 242: the 99.9 %
    point of χ²_ν/ν is 1.30, the sd 0.09) and raise nothing; spectra of a base η₃ = 3.5
    fitted with η₃ = 3.9 (the wrong material) cannot be explained within σ: reduced χ² ≫ 1,
    a `MisfitWarning`. Without σ there is no scale: NaN, no warning. (Same compiled fit as
    `test_fit_spectrum_thickness`.)"""
    sd = 1e-3
    rng = np.random.default_rng(11)
    init = SPEC_FILM._replace(thickness=750.0)
    noisy = spectra + sd * rng.standard_normal(spectra.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MisfitWarning)
        res = fit_spectrum(noisy, LAMBDA, COS, initial=init, sigma=sd)
        plain = fit_spectrum(noisy, LAMBDA, COS, initial=init)
    r = (np.asarray(airy_reflectance(res.film, COS[:, None], LAMBDA)) - noisy) / sd
    np.testing.assert_allclose(float(res.reduced_chi2), np.sum(r * r) / (r.size - 1),
                               rtol=1e-9)
    assert 0.7 < float(res.reduced_chi2) < 1.3 and res.warnings == ()
    assert np.isnan(float(plain.reduced_chi2)) and plain.warnings == ()
    wrong = np.asarray(airy_reflectance(SPEC_FILM._replace(eta_base=3.5), COS[:, None],
                                        LAMBDA)) + sd * rng.standard_normal(spectra.shape)
    with pytest.warns(MisfitWarning, match="does not explain the data within the noise"):
        bad = fit_spectrum(wrong, LAMBDA, COS, initial=init, sigma=sd)
    assert float(bad.reduced_chi2) > 100.0
    assert len(bad.warnings) == 1 and "reduced χ²" in bad.warnings[0]
    assert bad.to_dict()["warnings"] == list(bad.warnings)


def test_fitted_values_stay_in_bounds(spectra):
    # bounds are traced arguments: same compiled solver as test_fit_spectrum_thickness
    res = fit_spectrum(spectra, LAMBDA, COS, initial=SPEC_FILM._replace(thickness=750.0),
                       options=FitOptions(bounds={"thickness": (700.0, 780.0)}))
    assert 700.0 <= float(res.film.thickness) <= 780.0


# ----------------------------------------------------------------------------- bad inputs
def _patch_call(**over):
    obs = np.full((9, 3), 0.1)
    kw = dict(alpha=ALPHA, initial=FIG7, free=("thickness",))
    opt_fields = {k: over.pop(k) for k in list(over) if k in FitOptions.__dataclass_fields__}
    if opt_fields:
        kw["options"] = FitOptions(**opt_fields)
    kw.update(over)
    obs = kw.pop("observed", obs)
    theta = kw.pop("theta_o", THETA)
    return fit_film(obs, theta, **kw)


@pytest.mark.parametrize("over, err, match", [
    (dict(observed=np.full((8, 3), 0.1)), ValueError, r"observed must have shape"),
    (dict(observed=np.full((9, 3), np.nan)), ValueError, r"observed must be finite"),
    (dict(theta_o=np.linspace(0.0, 2.0, 9)), ValueError, r"theta_o must lie in"),
    (dict(alpha=0.0), ValueError, r"alpha must lie in"),
    (dict(alpha=np.array([0.2, 0.3])), ValueError, r"alpha must be a scalar"),
    (dict(free=("thickness", "colour")), ValueError, r"unknown free parameter 'colour'"),
    (dict(free=("thickness", "thickness")), ValueError, r"names a parameter twice"),
    (dict(free=()), ValueError, r"at least one"),
    (dict(method="exact"), ValueError, r"unknown method"),
    (dict(refine_method="nope"), ValueError, r"unknown refine_method"),
    (dict(solver="adam"), ValueError, r"unknown solver"),
    (dict(initial=(600.0, 1.3, 2.0)), TypeError, r"initial must be a thinfilm_jax.Film"),
    (dict(initial=Film(-1.0, 1.3, 2.0)), ValueError, r"initial.thickness must lie in"),
    (dict(initial=Film(2500.0, 1.3, 2.0)), ValueError, r"initial thickness = 2500.0 lies "
                                                       r"outside its bounds"),
    (dict(bounds={"thickness": (10.0, 5.0)}), ValueError, r"lo < hi"),
    (dict(bounds={"depth": (0.0, 5.0)}), ValueError, r"unknown parameter 'depth'"),
    (dict(n_starts=0), ValueError, r"n_starts must be an int >= 1"),
    (dict(quadrature=(16,)), ValueError, r"quadrature must be a pair"),
    (dict(sigma=-1.0), ValueError, r"sigma must lie in"),
    (dict(observed=np.full((1, 3), 0.1), theta_o=[0.3],
          free=("thickness", "eta_film", "eta_base")), ValueError, r"cannot determine"),
])
def test_fit_film_bad_inputs(over, err, match):
    with pytest.raises(err, match=match):
        _patch_call(**over)


@pytest.mark.parametrize("args, kw, match", [
    ((np.zeros((2, 5)), np.linspace(400, 800, 5), [1.0, 0.5, 0.2]), {}, r"observed must have shape"),
    ((np.zeros((1, 3)), [400.0, -5.0, 600.0], [1.0]), {}, r"wavelength must lie in"),
    ((np.zeros((1, 3)), [400.0, 500.0, 600.0], [1.5]), {}, r"cos_theta must lie in"),
    ((np.full((1, 3), np.inf), [400.0, 500.0, 600.0], [1.0]), {}, r"observed must be finite"),
    ((np.zeros((1, 3)), [400.0, 500.0, 600.0], [1.0]), dict(free=("alpha",)),
     r"unknown free parameter 'alpha'"),
])
def test_fit_spectrum_bad_inputs(args, kw, match):
    with pytest.raises(ValueError, match=match):
        fit_spectrum(*args, initial=SPEC_FILM, **kw)


# ----------------------------------------------------------------------------- CLI
def _write_patch_csv(path, obs, header="# alpha = 0.25\n"
                     '# initial = {"thickness": 350, "eta_film": 1.3, "eta_base": 2.0, '
                     '"kappa_base": 0.5}\n'):
    lines = [header + "theta_o_deg,R,G,B"]
    lines += [f"{t!r},{o[0]!r},{o[1]!r},{o[2]!r}" for t, o in zip(np.rad2deg(THETA), obs)]
    path.write_text("\n".join(lines) + "\n")


def test_cli_patch_csv(tmp_path, fig7_obs, capsys):
    """Same configuration as test_fit_thickness_alone (default method, d free): no recompile."""
    src = tmp_path / "obs.csv"
    _write_patch_csv(src, fig7_obs)
    assert cli_main(["fit", str(src)]) == 0
    out = json.loads((tmp_path / "obs.fit.json").read_text())
    assert out["kind"] == "patch"
    assert abs(out["result"]["film"]["thickness"] - 600.0) <= TOL_D_PATCH
    assert out["result"]["converged"] is True
    assert "wrote" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="exists; pass --overwrite"):
        cli_main(["fit", str(src)])


def test_cli_spectrum_csv_and_json(tmp_path, spectra):
    th = [0.0, 30.0, 60.0]
    rows = [f"{t},{lam},{spectra[i, j]!r}" for i, t in enumerate(th)
            for j, lam in enumerate(LAMBDA)]
    src = tmp_path / "spec.csv"
    src.write_text('# initial = {"eta_film": 1.46, "eta_base": 3.9, "kappa_base": 0.02}\n'
                   "# free = thickness, eta_film\ntheta_deg,wavelength_nm,R\n"
                   + "\n".join(rows) + "\n")
    dst = tmp_path / "res" / "out.json"
    assert cli_main(["fit", str(src), "--out", str(dst)]) == 0
    res = json.loads(dst.read_text())["result"]
    assert abs(res["params"]["thickness"] - 812.3) <= TOL_D_SPECTRUM
    assert res["free"] == ["thickness", "eta_film"]
    # JSON input, and --overwrite replaces the existing result
    src2 = tmp_path / "spec.json"
    src2.write_text(json.dumps({"wavelength_nm": LAMBDA.tolist(), "theta_deg": th,
                                "R": spectra.tolist(), "initial": {"eta_film": 1.46,
                                "eta_base": 3.9, "kappa_base": 0.02}}))
    assert cli_main(["fit", str(src2), "--out", str(dst), "--overwrite"]) == 0
    assert json.loads(dst.read_text())["input"] == str(src2)


@pytest.mark.parametrize("text, match", [
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_o_deg,R,G\n0,0.1,0.1\n", r"missing column 'B'"),
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_o_deg,R,G,B\n0,0.1,nan,0.1\n", r"line 4, column 'G'.*not finite"),
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_o_deg,R,G,B\n95,0.1,0.1,0.1\n10,0.1,0.1,0.1\n", r"theta_o_deg = 95.0 lies outside"),
    ("# alpha = 1.5\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_o_deg,R,G,B\n0,0.1,0.1,0.1\n10,0.1,0.1,0.1\n", r"alpha = 1.5 lies outside"),
    ("# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_o_deg,R,G,B\n0,0.1,0.1,0.1\n", r"missing setting 'alpha'"),
    ("# alpha = 0.25\ntheta_o_deg,R,G,B\n0,0.1,0.1,0.1\n", r"missing setting 'initial'"),
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3}\ntheta_o_deg,R,G,B\n0,0.1,0.1,0.1\n",
     r"initial: missing field 'eta_base'"),
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "# free = thickness, colour\ntheta_o_deg,R,G,B\n0,0.1,0.1,0.1\n10,0.1,0.1,0.1\n",
     r"unknown free parameter 'colour'"),
    ("# alpha = 0.25\n# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n# colour = red\n"
     "theta_o_deg,R,G,B\n0,0.1,0.1,0.1\n", r"unknown key\(s\) \['colour'\]"),
    ("angle,R,G,B\n0,0.1,0.1,0.1\n", r"missing column 'theta_o_deg'"),
    ("# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\n"
     "theta_deg,wavelength_nm,R\n0,400,0.1\n0,500,0.1\n30,400,0.1\n",
     r"every angle needs the same wavelength_nm"),
    # no angle: normal incidence (SPEC §14); one wavelength cannot determine the film
    ("# initial = {\"eta_film\": 1.3, \"eta_base\": 2.0}\nwavelength_nm,R\n400,0.1\n",
     r"1 observations cannot determine"),
])
def test_cli_bad_files(tmp_path, text, match):
    src = tmp_path / "bad.csv"
    src.write_text(text)
    with pytest.raises(SystemExit, match=match):
        cli_main(["fit", str(src)])
    assert not (tmp_path / "bad.fit.json").exists()


def test_cli_bad_paths(tmp_path):
    with pytest.raises(SystemExit, match="no such file"):
        cli_main(["fit", str(tmp_path / "missing.csv")])
    (tmp_path / "x.bmp").write_text("1")
    with pytest.raises(SystemExit, match="expected .csv, .json or a spectrometer export"):
        cli_main(["fit", str(tmp_path / "x.bmp")])
    (tmp_path / "x.txt").write_text("1")  # a spectrometer export (SPEC §14) without pairs
    with pytest.raises(SystemExit, match="no 'wavelength value' pairs"):
        cli_main(["fit", str(tmp_path / "x.txt")])
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(SystemExit, match="not valid JSON"):
        cli_main(["fit", str(tmp_path / "x.json")])


# ----------------------------------------------------------------------------- notebook
@pytest.mark.slow
def test_fitting_notebook_executes():
    """notebooks/fitting.ipynb runs end to end (small size via THINFILM_FIT_NOTEBOOK_SMALL)."""
    nbformat = pytest.importorskip("nbformat")
    from _notebook import execute
    path = Path(__file__).resolve().parents[2] / "notebooks" / "fitting.ipynb"
    nb = nbformat.read(path, as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), \
        "commit the notebook with outputs stripped"
    execute(nb, cwd=path.parent, env={"THINFILM_FIT_NOTEBOOK_SMALL": "1"}, timeout=600)
