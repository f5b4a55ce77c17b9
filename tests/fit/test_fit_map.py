"""Thickness maps (`thinfilm_jax.fit.thickness_map`): recovery of a synthetic oxide /
soap wedge rendered by the library, the neighbour prior against fringe-order outliers, input
checks and the ``thinfilm-jax fit-map`` command.

Every fit uses the same tiny image (8×8), grid and model, so the compiled functions are
shared between tests (small CI cost). Tolerances are named where they are asserted.
"""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film
from thinfilm_jax.fit.options import DEFAULT_BOUNDS, MAP_BOUNDS, FitOptions, MisfitWarning
from thinfilm_jax.fit.thickness_map import (MAP_OPTIONS, _grid_losses, _pixel_model, fit_patch_map,
                                  render_patch_map)

H = W = 8
ALPHA = 0.2
FILM = Film(400.0, 1.33, 1.0)  # soap film: η₂ = 1.33 between air (η₁ = η₃ = 1)
KW = dict(alpha=ALPHA, initial=FILM, bounds={"thickness": (0.0, 1000.0)}, grid=101)


def _truth():
    yy, xx = np.mgrid[0:H, 0:W]
    d = 200.0 + 300.0 * (xx + 0.5 * yy) / (W - 1 + 0.5 * (H - 1))  # wedge 200-500 nm
    theta = np.deg2rad(10.0 + 40.0 * yy / (H - 1))  # per-pixel view angle
    return d, theta


@pytest.fixture(scope="module")
def wedge():
    d, theta = _truth()
    img = np.asarray(render_patch_map(Film(jnp.asarray(d), 1.33, 1.0), jnp.asarray(theta),
                                      ALPHA))
    return d, theta, img


def test_noise_free_wedge_recovered(wedge):
    d, theta, img = wedge
    res = fit_patch_map(img, theta, sigma=1e-3, **KW)
    err = np.abs(np.asarray(res.thickness) - d)
    assert np.median(err) < 1.0  # nm: noise-free, same model → exact up to the solver
    assert np.max(err) < 1.0
    assert np.all(np.isfinite(np.asarray(res.stderr)))
    assert res.pixels_per_second > 0
    # float32 input: read as float64, same map
    res32 = fit_patch_map(img.astype(np.float32), theta.astype(np.float32), sigma=1e-3, **KW)
    assert np.median(np.abs(np.asarray(res32.thickness) - d)) < 1.0


def _alias(d, theta, img, p):
    """A grid thickness > 100 nm from d[p] whose colour is closest to pixel p's (a
    fringe-order alias), its colour (rendered) and its colour distance."""
    dg = np.linspace(*KW["bounds"]["thickness"], KW["grid"])
    energy = np.asarray(_grid_losses(jnp.asarray(img.reshape(-1, 3)),
                                     jnp.asarray(theta.reshape(-1)),
                                     tuple(jnp.asarray(v) for v in (1.0, 0.0, 1.0)),
                                     jnp.asarray(np.stack([dg, np.full_like(dg, 1.33)], -1)),
                                     1.0, model=_pixel_model("filtered", "stiles_burch_1959_10",
                                                             MAP_OPTIONS, ALPHA)))
    e = energy.reshape(H, W, -1)[p]
    k = int(np.argmin(np.where(np.abs(dg - d[p]) > 100.0, e, np.inf)))
    alt = d.copy()
    alt[p] = dg[k]
    col = np.asarray(render_patch_map(Film(jnp.asarray(alt), 1.33, 1.0), jnp.asarray(theta),
                                      ALPHA))[p]
    return dg[k], col, float(np.linalg.norm(col - img[p]))


def test_prior_removes_fringe_order_outlier(wedge):
    """Noise σ everywhere; one pixel's observation is exactly the colour of a fringe-order
    alias (> 100 nm away). On its own that pixel fits the alias; the prior (τ = 30 nm) makes
    the alias cost ½ Σ_q ((d_alias − d_q)/τ)² ≫ the data cost of the truth, ½ |ΔL/σ|²."""
    d, theta, img = wedge
    sigma = 2e-3
    noisy = img + np.random.default_rng(0).normal(0.0, sigma, img.shape)
    p = (3, 4)
    d_alias, col, dist = _alias(d, theta, img, p)
    assert 0.5 * (dist / sigma) ** 2 < 0.25 * 0.5 * 4 * ((d_alias - d[p]) / 30.0) ** 2
    noisy[p] = col
    free = fit_patch_map(noisy, theta, sigma=sigma, **KW)
    prior = fit_patch_map(noisy, theta, sigma=sigma, smoothness_nm=30.0, **KW)
    e_free = np.abs(np.asarray(free.thickness) - d)
    e_prior = np.abs(np.asarray(prior.thickness) - d)
    assert e_free[p] > 50.0  # the outlier, independently fitted
    # back in the right fringe order (the data still pull it: its colour is the alias's)
    assert e_prior[p] < 0.25 * abs(d_alias - d[p])
    assert np.sum(e_prior > 20.0) <= np.sum(e_free > 20.0) - 1
    others = np.ones((H, W), bool)
    others[p] = False
    # not worse elsewhere: median within 0.5 nm (noise 2 % of the radiance scale)
    assert np.median(e_prior[others]) <= np.median(e_free[others]) + 0.5


def test_devices_one_identical(wedge):
    d, theta, img = wedge
    a = fit_patch_map(img, theta, sigma=1e-3, **KW)
    b = fit_patch_map(img, theta, sigma=1e-3, devices=1, **KW)
    np.testing.assert_allclose(np.asarray(b.thickness), np.asarray(a.thickness), rtol=0,
                               atol=1e-9)
    # the box from the fits' one options type is the same box
    kw = {k: v for k, v in KW.items() if k != "bounds"}
    c = fit_patch_map(img, theta, sigma=1e-3, options=FitOptions(bounds=KW["bounds"]), **kw)
    np.testing.assert_array_equal(np.asarray(c.thickness), np.asarray(a.thickness))


def test_map_misfit_warning(wedge):
    """`MapResult.reduced_chi2` = Σ((L(fit) − o)/σ)² / (P (J − 1)), recomputed here from
    `render_patch_map` of the fitted map: ≈ 1 for the soap film with noise σ (ν = 128:
    the 99.9 % point of χ²_ν/ν is 1.43, the sd 0.125), no warning; the same image fitted
    with a glass base (η₃ = 1.5 instead of air) cannot be explained within σ: a
    `MisfitWarning`. One table of boxes: the map's thickness box is `fit_film`'s."""
    d, theta, img = wedge
    sigma = 2e-3
    noisy = img + np.random.default_rng(4).normal(0.0, sigma, img.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MisfitWarning)
        res = fit_patch_map(noisy, theta, sigma=sigma, **KW)
    fitted = np.asarray(render_patch_map(Film(res.thickness, 1.33, 1.0), jnp.asarray(theta),
                                         ALPHA))
    chi2 = np.sum(((fitted - noisy) / sigma) ** 2)
    np.testing.assert_allclose(res.reduced_chi2, chi2 / (H * W * 2), rtol=1e-9)
    assert 0.6 < res.reduced_chi2 < 1.43 and res.warnings == ()
    with pytest.warns(MisfitWarning, match="does not explain the data within the noise"):
        bad = fit_patch_map(noisy, theta, sigma=sigma, **{**KW, "initial": Film(400.0, 1.33,
                                                                                 1.5)})
    assert bad.reduced_chi2 > 10.0 and "pixels beyond" in bad.warnings[0]
    assert MAP_BOUNDS["thickness"] == DEFAULT_BOUNDS["thickness"]


@pytest.mark.parametrize("change, match", [
    (dict(theta_o=np.zeros((4, 4))), "theta_o"),
    (dict(image=np.full((H, W, 2), 0.1)), "image"),
    (dict(image="nan"), "image must be finite"),
    (dict(image="negative"), "non-negative"),
    (dict(alpha=0.0), "alpha"),
    (dict(alpha=1.5), "alpha"),
    (dict(free=("thickness", "eta_base")), "free"),
    (dict(free=("eta_film",)), "free"),
    (dict(sigma=-1.0), "sigma"),
    (dict(smoothness_nm=0.0), "smoothness_nm"),
    (dict(bounds={"thickness": (500.0, 100.0)}), "bounds"),
    (dict(options=MAP_OPTIONS), "model_options"),
    (dict(options=FitOptions(max_steps=5)), "do not apply"),
    (dict(options=FitOptions(bounds={"alpha": (0.1, 0.5)})), "bounds"),
    (dict(model_options="filtered"), "model_options"),
    (dict(theta_o=np.full((H, W), 2.0)), "theta_o"),
])
def test_bad_input_named(change, match):
    d, theta = _truth()
    args = dict(image=np.full((H, W, 3), 0.1), theta_o=theta, alpha=ALPHA, initial=FILM,
                sigma=1e-3)
    args.update(change)
    if isinstance(args["image"], str):
        img = np.full((H, W, 3), 0.1)
        img[2, 3, 1] = np.nan if args["image"] == "nan" else -0.5
        args["image"] = img
    with pytest.raises(ValueError, match=match):
        fit_patch_map(args.pop("image"), args.pop("theta_o"), **args)


def test_cli_fit_map(wedge, tmp_path, capsys):
    """``thinfilm-jax fit-map``: the map, PNG and JSON written; per-pixel view angles."""
    import json

    from thinfilm_jax.cli.main import main

    d, theta, img = wedge
    np.save(tmp_path / "img.npy", img)
    np.save(tmp_path / "theta.npy", np.rad2deg(theta))
    out = tmp_path / "out"
    rc = main(["fit-map", str(tmp_path / "img.npy"), "--theta-o-map",
               str(tmp_path / "theta.npy"), "--alpha", str(ALPHA), "--eta-film", "1.33",
               "--eta-base", "1.0", "--thickness-range", "0", "1000", "--grid", "101",
               "--sigma", "0.001", "--out", str(out), "--quiet"])
    assert rc == 0
    fitted = np.load(out / "thickness_map.npy")
    assert np.median(np.abs(fitted - d)) < 1.0  # nm, noise-free
    summary = json.loads((out / "fit_map.json").read_text())
    assert summary["shape"] == [H, W] and summary["compile_seconds"] >= 0
    # the misfit test travels with the map: a noise-free image of the model fits (≈ 3e-28)
    assert summary["reduced_chi2"] < 1.0 and summary["warnings"] == []
    assert (out / "thickness_map.png").read_bytes()[:4] == b"\x89PNG"
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary left


@pytest.mark.parametrize("extra, rc_or_exit, match", [
    (["--theta-o", "20", "--alpha", "0"], 2, "--alpha"),
    (["--theta-o", "95", "--alpha", "0.2"], 2, "--theta-o"),
    (["--theta-o", "20", "--alpha", "0.2", "--smoothness", "-5"], 2, "--smoothness"),
    (["--theta-o-map", "THETA", "--alpha", "0.2"], 1, "does not match"),
    (["--theta-o", "20", "--alpha", "0.2", "--thickness-range", "500", "100"], 1,
     "--thickness-range"),
])
def test_cli_fit_map_bad_arguments(tmp_path, capsys, extra, rc_or_exit, match):
    """Usage errors (exit 2) and bad files (exit 1) are one line, before any fitting."""
    from thinfilm_jax.cli.main import main

    np.save(tmp_path / "img.npy", np.full((H, W, 3), 0.1))
    np.save(tmp_path / "theta.npy", np.zeros((3, 3)))
    extra = [str(tmp_path / "theta.npy") if e == "THETA" else e for e in extra]
    argv = ["fit-map", str(tmp_path / "img.npy"), "--eta-film", "1.33", "--eta-base", "1.0",
            "--out", str(tmp_path / "out"), *extra]
    if rc_or_exit == 2:
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
    else:
        assert main(argv) == 1
    assert match in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_envmap_map_background_and_recovery():
    """`fit_envmap_map`: background (NaN normal) and back-facing pixels come back NaN and
    do not feed the prior; the fitted pixels (tilted normals, a non-uniform map) are
    recovered noise-free. Same map / α / grid / pixel count as the module's doctest, so the
    compiled functions are shared in a full run."""
    from thinfilm_jax import prefilter_envmap
    from thinfilm_jax.fit.thickness_map import fit_envmap_map
    from thinfilm_jax.shading.ibl import envmap_radiance

    sky = np.ones((8, 16, 3)) * np.linspace(2.0, 0.5, 8)[:, None, None]  # bright zenith
    pref = prefilter_envmap(sky, levels=3, resolution=(8, 16), albedo_shape=(8, 5))
    nan = [np.nan] * 3
    n = np.array([[[0.0, 0.0, 1.0], nan, [0.6, 0.0, 0.8]],
                  [nan, [0.0, 0.0, -1.0], nan]])
    v = np.broadcast_to([0.0, 0.0, 1.0], n.shape)
    d = np.array([[300.0, 0.0, 420.0], [0.0, 0.0, 0.0]])
    ok = np.isfinite(n).all(-1) & (n[..., 2] > 0)
    img = np.zeros((2, 3, 3))
    img[ok] = np.asarray(envmap_radiance(Film(jnp.asarray(d[ok]), 1.33, 1.0), 0.2, n[ok],
                                         v[ok], pref, method="filtered"))
    res = fit_envmap_map(img, n, v, pref, alpha=0.2, initial=Film(350.0, 1.33, 1.0),
                         sigma=1e-3, bounds={"thickness": (0.0, 1000.0)}, grid=101,
                         smoothness_nm=50.0)
    t = np.asarray(res.thickness)
    assert np.all(np.isnan(t[~ok])) and np.all(np.isnan(np.asarray(res.loss)[~ok]))
    assert np.max(np.abs(t[ok] - d[ok])) < 0.5  # nm, noise-free, same model
    with pytest.raises(ValueError, match="view"):
        fit_envmap_map(img, n, v[:1], pref, alpha=0.2, initial=FILM)
    with pytest.raises(ValueError, match="image"):
        fit_envmap_map(img[:1], n, v, pref, alpha=0.2, initial=FILM)
