"""``thinfilm-jax fit-map ... --gltf DIR``: the fitted thickness map as a glTF 2.0 material with
`KHR_materials_iridescence` and its `iridescenceThicknessTexture` (SPEC §10,
`thinfilm_jax.interop.gltf`).

The image, model and command line are those of tests/fit/test_fit_map.py::test_cli_fit_map (an
8×8 soap wedge, grid 101, filtered), so a full run shares their compiled functions. The PNG is
read back with OpenImageIO (`read_thickness_texture`), independently of the writer's codes,
and compared with the fitted ``thickness_map.npy`` to the PNG quantisation
(max − min)/(2(2ᵇ − 1)).
"""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax import Film
from thinfilm_jax.cli.main import main
from thinfilm_jax.fit.thickness_map import render_patch_map
from thinfilm_jax.interop.gltf import read_thickness_texture
from thinfilm_jax.interop.gltf_file import read_gltf

H = W = 8
ALPHA = 0.2


@pytest.fixture(scope="module")
def wedge_files(tmp_path_factory):
    """The soap wedge of tests/fit/test_fit_map.py (200–500 nm, θ_o 10°–50°) on disk."""
    yy, xx = np.mgrid[0:H, 0:W]
    d = 200.0 + 300.0 * (xx + 0.5 * yy) / (W - 1 + 0.5 * (H - 1))
    theta = np.deg2rad(10.0 + 40.0 * yy / (H - 1))
    img = np.asarray(render_patch_map(Film(jnp.asarray(d), 1.33, 1.0), jnp.asarray(theta),
                                      ALPHA))
    folder = tmp_path_factory.mktemp("wedge")
    np.save(folder / "img.npy", img)
    np.save(folder / "theta.npy", np.rad2deg(theta))
    return folder, d


def _argv(folder, out, *extra):
    return ["fit-map", str(folder / "img.npy"), "--theta-o-map", str(folder / "theta.npy"),
            "--alpha", str(ALPHA), "--eta-film", "1.33", "--eta-base", "1.0",
            "--thickness-range", "0", "1000", "--grid", "101", "--sigma", "0.001",
            "--out", str(out), "--quiet", *extra]


@pytest.mark.parametrize("bits", [8, 16])
def test_gltf_texture_reproduces_fitted_map(wedge_files, tmp_path, capsys, bits):
    """The texture read back (G through mix(min, max, G)) is the fitted map to the PNG
    quantisation; min/max cover the map exactly; the material holds η₂ and η₃ and reads back
    (`read_gltf`) as the film that was fitted.

    Measured (8×8 wedge, fitted range 200.0–500.0 nm): max |Δd| = 0.504 nm at 8 bits
    against the bound 0.588 nm ((max − min)/510), 0.00204 nm at 16 bits (bound 0.00229 nm);
    asserted at the bound plus 1e-9 nm (float rounding only), and above half the bound (a
    texture that is not quantised, or read without min/max, fails one side).
    """
    folder, truth = wedge_files
    out, gdir = tmp_path / "out", tmp_path / "gltf"
    assert main(_argv(folder, out, "--gltf", str(gdir), "--gltf-bits", str(bits))) == 0
    fitted = np.load(out / "thickness_map.npy")
    assert np.median(np.abs(fitted - truth)) < 1.0  # nm: the fit itself (noise-free)
    doc = json.loads((gdir / "fit_map.gltf").read_text())
    ext = doc["materials"][0]["extensions"]["KHR_materials_iridescence"]
    lo, hi = ext["iridescenceThicknessMinimum"], ext["iridescenceThicknessMaximum"]
    assert (lo, hi) == (fitted.min(), fitted.max())  # the codes cover the map
    assert ext["iridescenceIor"] == 1.33
    assert doc["materials"][0]["extensions"]["KHR_materials_ior"]["ior"] == 1.0
    assert doc["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    png = gdir / doc["images"][0]["uri"]
    assert png.name == "fit_map_thickness.png" and png.read_bytes()[:4] == b"\x89PNG"
    back = read_thickness_texture(png, lo, hi)
    bound = (hi - lo) / (2 * (2**bits - 1))
    err = np.abs(back - fitted)
    assert back.shape == fitted.shape and err.max() <= bound + 1e-9
    assert err.max() > 0.5 * bound  # the quantisation is real: not a lossless copy
    film, factor = read_gltf(gdir / "fit_map.gltf")
    assert factor == 1.0 and (film.eta_film, film.eta_base, film.kappa_base) == (1.33, 1.0, 0)
    np.testing.assert_allclose(np.asarray(film.thickness), back, rtol=0, atol=1e-9)
    summary = json.loads((out / "fit_map.json").read_text())
    assert summary["gltf"]["bits"] == bits
    assert summary["gltf"]["files"] == ["fit_map.gltf", "fit_map.bin", "fit_map_thickness.png"]
    assert doc["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] == ALPHA**0.5
    assert "fit_map.gltf" in capsys.readouterr().out
    assert not [p for p in gdir.iterdir() if p.name.startswith(".")]  # no temporary left


@pytest.mark.parametrize("extra, match", [
    (["--kappa-base", "0.02"], "absorbing base"),
    (["--eta-outer", "1.33"], "eta_outer"),
    (["--free", "thickness", "eta_film"], "one iridescenceIor"),
])
def test_gltf_cannot_hold_is_usage_error(wedge_files, tmp_path, capsys, extra, match):
    """What glTF cannot hold (κ₃ > 0, η₁ ≠ 1, a fitted η₂ map; SPEC §10) is a one-line usage
    error (exit status 2) before the fit: nothing is written."""
    folder, _ = wedge_files
    out, gdir = tmp_path / "out", tmp_path / "gltf"
    with pytest.raises(SystemExit) as e:
        main(_argv(folder, out, "--gltf", str(gdir), *extra))
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert match in err[-1] and "argument --gltf" in err[-1]
    if "--kappa-base" in extra:  # says how to get a glTF material
        assert "--kappa-base 0" in err[-1]
    assert not out.exists() and not gdir.exists()
