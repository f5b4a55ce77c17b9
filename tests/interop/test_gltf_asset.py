"""The glTF assets of `interop.gltf_file.write_gltf` open in a viewer: the Khronos glTF-Validator
(the npm package `gltf-validator`, run by Node) reports no error, no warning and no unused
object, for `.gltf` and `.glb`, with and without a thickness texture, and for the asset of
``thinfilm-jax fit-map --gltf``. They read back (`read_gltf`, `alpha_from_gltf`) as written.

The validator is looked for in ``$XDG_CACHE_HOME/thinfilm_jax-node`` (default
``~/.cache/thinfilm_jax-node``); where it is missing and `npm` exists it is installed there
once (``npm install --prefix <that folder> gltf-validator@2.0.0-dev.3.10``, 180 s at most).
Without Node, or when that install fails, the validator tests skip and say why; the mesh,
GLB-layout and roughness tests run regardless.
"""

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from thinfilm_jax import Film
from thinfilm_jax.interop import gltf as G
from thinfilm_jax.interop import gltf_file as GF

VALIDATOR = "gltf-validator@2.0.0-dev.3.10"  # the version these tests were measured with
ALPHA = 0.1

#: validates each file named on the command line; prints one JSON report per file (a list)
VALIDATE_JS = r"""
const fs = require("fs"), path = require("path");
const validator = require(process.argv[2]);
async function one(file) {
  return validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file), maxIssues: 0, writeTimestamp: false,
    externalResourceFunction: (uri) => new Promise((resolve, reject) => fs.readFile(
      path.resolve(path.dirname(file), decodeURIComponent(uri)),
      (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)))),
  });
}
Promise.all(process.argv.slice(3).map(one)).then(
  (reports) => console.log(JSON.stringify(reports)),
  (e) => { console.error(String(e)); process.exit(2); });
"""


def _cache() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "thinfilm_jax-node"


@pytest.fixture(scope="module")
def validate(tmp_path_factory):
    """validate(*paths) → the validator's reports (dicts), one per path."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js (node) is not installed: the Khronos glTF-Validator runs on it")
    package = _cache() / "node_modules" / "gltf-validator"
    if not (package / "package.json").exists():
        npm = shutil.which("npm")
        if npm is None:
            pytest.skip(f"the npm package gltf-validator is not in {_cache()} and npm is absent")
        try:
            subprocess.run([npm, "install", "--prefix", str(_cache()), "--no-audit",
                            "--no-fund", "--loglevel=error", VALIDATOR],
                           check=True, capture_output=True, text=True, timeout=180)
        except (subprocess.SubprocessError, OSError) as e:
            pytest.skip(f"could not install {VALIDATOR} into {_cache()} with npm: {e}")
    script = tmp_path_factory.mktemp("validator") / "validate.js"
    script.write_text(VALIDATE_JS)

    def run(*paths):
        out = subprocess.run([node, str(script), str(package), *map(str, paths)],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    return run


def _problems(report) -> list:
    """The errors, warnings and unused objects of one report (what a viewer trips on)."""
    return [(m["code"], m.get("pointer"), m["message"]) for m in report["issues"]["messages"]
            if m["severity"] < 2 or m["code"] == "UNUSED_OBJECT"]


def _map():
    y, x = np.mgrid[0:16, 0:32]
    return 330.0 + 250.0 * np.sin(x / 5.0) * np.cos(y / 7.0)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
@pytest.mark.parametrize("textured", [False, True])
def test_asset_validates_and_reads_back(validate, tmp_path, suffix, textured):
    """0 errors, 0 warnings, no UNUSED_OBJECT; a default scene drawing one sphere (32 × 16:
    960 triangles, 559 vertices) with the one material; the texture's PNG is read as linear.

    Measured (validator 2.0.0-dev.3.10): no issue at all without a texture; with the 32 × 16
    map one information, IMAGE_NPOT_DIMENSIONS (allowed by glTF 2.0). The film reads back
    exactly (one thickness) or to the 8-bit quantisation (max − min)/510 nm (the map:
    measured 0.98 nm of the 1.0 nm bound); α = roughnessFactor² to 1 ulp.
    """
    thickness = _map() if textured else 420.0
    path = tmp_path / f"film{suffix}"
    doc = GF.write_gltf(path, Film(thickness, 1.33, 1.5), 0.8, alpha=ALPHA)
    (report,) = validate(path)
    assert _problems(report) == []
    info = report["info"]
    assert info["hasDefaultScene"] and info["drawCallCount"] == 1
    assert (info["totalTriangleCount"], info["totalVertexCount"]) == (960, 559)
    assert info["materialCount"] == 1 and info["extensionsUsed"] == [G.EXTENSION,
                                                                      G.IOR_EXTENSION]
    images = [r for r in info["resources"] if r["pointer"].startswith("/images/")]
    assert len(images) == textured
    if textured:
        assert images[0]["image"]["transfer"] == "linear" and images[0]["mimeType"] == "image/png"
        assert images[0]["storage"] == ("buffer-view" if suffix == ".glb" else "external")
    expected = {".glb": {"film.glb"},
                ".gltf": {"film.gltf", "film.bin"} | ({"film_thickness.png"} if textured
                                                      else set())}[suffix]
    assert {p.name for p in tmp_path.iterdir()} == expected  # nothing else, no temporary
    assert GF.load_gltf(path) == json.loads(json.dumps(doc))
    film, factor = GF.read_gltf(path)
    assert factor == 0.8 and tuple(film[1:]) == (1.33, 1.5, 0.0, 1.0)
    if textured:
        d = _map()
        bound = (d.max() - d.min()) / 510
        assert np.asarray(film.thickness).shape == d.shape
        assert np.abs(np.asarray(film.thickness) - d).max() <= bound * (1 + 1e-9)
    else:
        assert film.thickness == 420.0
    assert G.alpha_from_gltf(GF.load_gltf(path)["materials"][0]) == pytest.approx(ALPHA,
                                                                                 rel=3e-16)


def test_validator_flags_what_the_old_writer_wrote(validate, tmp_path):
    """The check is not vacuous: a material-only document (the writer before the complete
    asset) is UNUSED_OBJECT /materials/0, and POSITION without min/max is an error."""
    GF.write_gltf(tmp_path / "ok.gltf", Film(400.0, 1.3, 1.5), alpha=0.2)
    doc = json.loads((tmp_path / "ok.gltf").read_text())
    (tmp_path / "material_only.gltf").write_text(json.dumps(
        {k: doc[k] for k in ("asset", "extensionsUsed", "materials")}))
    del doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]["min"]
    (tmp_path / "no_bounds.gltf").write_text(json.dumps(doc))
    old, unbounded = validate(tmp_path / "material_only.gltf", tmp_path / "no_bounds.gltf")
    assert [p[:2] for p in _problems(old)] == [("UNUSED_OBJECT", "/materials/0")]
    assert unbounded["issues"]["numErrors"] == 1
    assert _problems(unbounded)[0][0] == "MESH_PRIMITIVE_POSITION_ACCESSOR_WITHOUT_BOUNDS"


def test_fit_map_gltf_asset_validates(validate, tmp_path):
    """``fit-map --gltf`` (a 4 × 4 soap wedge, grid 61) writes an asset the validator passes,
    with roughnessFactor = √α of the fit (measured: no issue besides none; the 4 × 4 PNG is
    a power of two)."""
    from thinfilm_jax.cli.main import main
    from thinfilm_jax.fit.thickness_map import render_patch_map

    yy, xx = np.mgrid[0:4, 0:4]
    d = 250.0 + 40.0 * (xx + yy)
    img = np.asarray(render_patch_map(Film(d, 1.33, 1.0), np.deg2rad(20.0), 0.2))
    np.save(tmp_path / "img.npy", img)
    assert main(["fit-map", str(tmp_path / "img.npy"), "--theta-o", "20", "--alpha", "0.2",
                 "--eta-film", "1.33", "--eta-base", "1.0", "--thickness-range", "200", "600",
                 "--grid", "61", "--out", str(tmp_path / "out"), "--gltf",
                 str(tmp_path / "gltf"), "--quiet"]) == 0
    (report,) = validate(tmp_path / "gltf" / "fit_map.gltf")
    assert _problems(report) == [] and report["info"]["hasDefaultScene"]
    material = GF.load_gltf(tmp_path / "gltf" / "fit_map.gltf")["materials"][0]
    assert material["pbrMetallicRoughness"]["roughnessFactor"] == math.sqrt(0.2)


# -------------------------------------------------------------- without the validator
def test_sphere_mesh():
    """The UV sphere: unit positions equal to the normals, triangles wound counter-clockwise
    seen from outside (glTF's front face; every one), none degenerate, every vertex used, texcoords
    in [0, 1] with v = 0 at the north pole (+Y) and the map's centre facing +Z; its area tends to 4π
    from below (measured 12.316 at 16 × 32, 4π = 12.566)."""
    p, n, uv, tri = GF.uv_sphere(16, 32)
    np.testing.assert_allclose((p * p).sum(-1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(n, p)
    a, b, c = (p[tri[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    assert (np.einsum("ij,ij->i", cross, a + b + c) > 0).all()  # outward: CCW from outside
    area = 0.5 * np.linalg.norm(cross, axis=-1)
    assert area.min() > 1e-4 and 0.97 * 4 * np.pi < area.sum() < 4 * np.pi
    assert tri.shape == (2 * 32 * 15, 3) and len(np.unique(tri)) == len(p)
    assert uv.min() == 0 and uv.max() == 1 and p.shape == (17 * 33 - 2, 3)
    np.testing.assert_allclose(p[uv[:, 1] == 0], [[0, 1, 0]] * 32, atol=1e-15)
    np.testing.assert_allclose(p[uv[:, 1] == 1], [[0, -1, 0]] * 32, atol=1e-15)
    centre = np.flatnonzero((uv[:, 0] == 0.5) & (uv[:, 1] == 0.5))
    np.testing.assert_allclose(p[centre], [[0, 0, 1]], atol=1e-15)
    right = np.flatnonzero((uv[:, 0] == 0.5 + 1 / 32) & (uv[:, 1] == 0.5))
    assert p[right, 0] > 0  # u grows towards +X seen from +Z: the map is not mirrored


def test_glb_layout_and_position_bounds(tmp_path):
    """The GLB container (glTF 2.0 §4.4): header magic/version/length = file size, the JSON
    chunk (space-padded) then the BIN chunk (zero-padded), both lengths multiples of 4, the
    buffer's byteLength within 3 bytes of the BIN chunk; POSITION's min/max are its data's
    (float32) extremes, every bufferView 4-byte aligned and inside the buffer."""
    doc = GF.write_gltf(tmp_path / "a.glb", Film(_map(), 1.33, 1.5), alpha=ALPHA)
    blob = (tmp_path / "a.glb").read_bytes()
    u32 = lambda at: int.from_bytes(blob[at:at + 4], "little")  # noqa: E731
    assert blob[:4] == b"glTF" and u32(4) == 2 and u32(8) == len(blob)
    n_json = u32(12)
    assert blob[16:20] == b"JSON" and n_json % 4 == 0
    assert json.loads(blob[20:20 + n_json]) == json.loads(json.dumps(doc))
    n_bin = u32(20 + n_json)
    assert blob[24 + n_json:28 + n_json] == b"BIN\0" and n_bin % 4 == 0
    assert 28 + n_json + n_bin == len(blob)
    assert 0 <= n_bin - doc["buffers"][0]["byteLength"] <= 3 and "uri" not in doc["buffers"][0]
    data = blob[28 + n_json:]
    for view in doc["bufferViews"]:
        assert view["byteOffset"] % 4 == 0
        assert view["byteOffset"] + view["byteLength"] <= doc["buffers"][0]["byteLength"]
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    pos = np.frombuffer(data, np.float32, acc["count"] * 3, view["byteOffset"]).reshape(-1, 3)
    assert acc["min"] == pos.min(0).tolist() and acc["max"] == pos.max(0).tolist()
    png = doc["bufferViews"][doc["images"][0]["bufferView"]]
    assert data[png["byteOffset"]:png["byteOffset"] + 4] == b"\x89PNG"


def test_roughness_factor_is_sqrt_alpha():
    """glTF's roughness r has GGX α = r² (glTF 2.0 specification, Appendix B): α = 0.25 is
    written 0.5; without alpha the field is left out (glTF's default r = 1, α = 1); the
    material otherwise unchanged; α outside [0, 1] is a ValueError naming alpha."""
    film = Film(350.0, 1.33, 1.52)
    plain, rough = G.film_to_gltf(film, 0.7), G.film_to_gltf(film, 0.7, alpha=0.25)
    assert rough["pbrMetallicRoughness"] == {"metallicFactor": 0.0, "roughnessFactor": 0.5}
    assert "roughnessFactor" not in plain["pbrMetallicRoughness"]
    assert G.alpha_from_gltf(plain) == 1.0 and G.alpha_from_gltf(rough) == 0.25
    assert {k: v for k, v in rough.items() if k != "pbrMetallicRoughness"} == {
        k: v for k, v in plain.items() if k != "pbrMetallicRoughness"}
    assert G.film_from_gltf(rough) == G.film_from_gltf(plain)
    assert G.film_to_gltf(film, alpha=np.float32(0.0))["pbrMetallicRoughness"][
        "roughnessFactor"] == 0.0
    for bad in (1.5, -0.1, math.nan, [0.1, 0.2]):
        with pytest.raises(ValueError, match="alpha"):
            G.film_to_gltf(film, alpha=bad)
    with pytest.raises(ValueError, match="metallicRoughnessTexture"):
        G.alpha_from_gltf({"pbrMetallicRoughness": {"metallicRoughnessTexture": {"index": 0}}})


# -------------------------------------------------------------- dispersive films
def test_dispersive_film_is_written_at_a_stated_wavelength(tmp_path):
    """A dispersive film (water on glass; TiO₂ on glass) is written with its indices at
    ``wavelength_nm`` (550 nm by default), recorded in the material's ``extras.thinfilm_jax``
    with the model's name and its n, k there; it reads back as that constant film. An index
    absorbing at the wavelength is refused where glTF cannot hold it (a silicon base), as is a
    wavelength outside the model's data; a film of numbers has no such record."""
    from thinfilm_jax import refractive_index

    water, tio2 = refractive_index("water"), refractive_index("TiO2")
    doc = GF.write_gltf(tmp_path / "soap.gltf", Film(_map(), water, 1.5), alpha=ALPHA)
    material = doc["materials"][0]
    n550 = float(np.real(water(550.0)))
    assert material["extensions"][G.EXTENSION]["iridescenceIor"] == n550
    record = material["extras"]["thinfilm_jax"]
    assert record["index_wavelength_nm"] == 550.0
    assert record["dispersive_indices"]["eta_film"] == {"name": "water", "n": n550, "k": 0.0}
    film, _ = GF.read_gltf(tmp_path / "soap.gltf")
    assert film.eta_film == n550 and film.eta_base == 1.5
    # another wavelength, another constant index; TiO₂'s κ ≈ 1e-5 at 450 nm is recorded
    m450 = G.film_to_gltf(Film(300.0, tio2, 1.5), wavelength_nm=450.0)
    n450 = complex(np.asarray(tio2(450.0)))
    assert m450["extensions"][G.EXTENSION]["iridescenceIor"] == n450.real
    assert m450["extras"]["thinfilm_jax"]["index_wavelength_nm"] == 450.0
    assert m450["extras"]["thinfilm_jax"]["dispersive_indices"]["eta_film"]["k"] == n450.imag
    assert "extras" not in G.film_to_gltf(Film(300.0, 1.33, 1.5))
    with pytest.raises(ValueError, match="absorbing base"):
        G.film_to_gltf(Film(300.0, refractive_index("SiO2"), refractive_index("Si")))
    with pytest.raises(ValueError, match=r"wavelength_nm = 2000.*182"):
        G.film_to_gltf(Film(300.0, water, 1.5), wavelength_nm=2000.0)
    with pytest.raises(ValueError, match="wavelength_nm"):
        G.film_to_gltf(Film(300.0, water, 1.5), wavelength_nm=-5.0)
    # what it costs is measured, not zero (docs/how-to/gltf.md: soap film mean 0.81, max 3.65)
    cost = G.constant_index_error(Film(0.0, water, 1.0), thickness=[500.0, 900.0],
                                  theta_deg=[0.0, 60.0])
    assert cost["n"] == 4 and 0 < cost["mean"] <= cost["max"] < 10


def _photo(folder):
    """An 8 × 6 sRGB PNG of a soap wedge (water in air, 150–650 nm) and a mask of its left
    half."""
    import OpenImageIO as oiio

    from thinfilm_jax import refractive_index
    from thinfilm_jax.fit.photo import render_photo

    d = np.broadcast_to(150.0 + 500.0 * np.arange(8)[None, :] / 7, (6, 8)).copy()
    lin = render_photo(Film(0.0, refractive_index("water"), 1.0), d, exposure=0.8)
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.clip(lin, 0, 1) ** (1 / 2.4)
                    - 0.055)
    for name, a in (("soap.png", np.round(np.clip(srgb, 0, 1) * 255).astype(np.uint8)),
                    ("left.png", np.where(np.arange(8)[None, :] < 4, 255, 0)
                     .astype(np.uint8).repeat(6, 0)[..., None])):
        out = oiio.ImageOutput.create(str(folder / name))
        assert out.open(str(folder / name), oiio.ImageSpec(8, 6, a.shape[-1], oiio.UINT8))
        out.write_image(np.ascontiguousarray(a))
        out.close()
    return d


def test_fit_map_photo_gltf_asset_validates(validate, tmp_path):
    """``fit-map PHOTO --camera srgb --eta-film water --gltf DIR`` (the photographs page's
    soap film) writes an asset the validator passes, its IOR water's at 550 nm recorded in
    the material; with ``--mask`` the unfitted pixels take their nearest fitted value (the
    texture has no holes) and their count is in fit_photo.json."""
    from thinfilm_jax import refractive_index
    from thinfilm_jax.cli.main import main

    _photo(tmp_path)
    args = ["fit-map", str(tmp_path / "soap.png"), "--camera", "srgb", "--eta-film", "water",
            "--eta-base", "1", "--thickness-range", "0", "1000", "--quiet",
            "--mask", str(tmp_path / "left.png"), "--out", str(tmp_path / "out"),
            "--gltf", str(tmp_path / "gltf"), "--gltf-wavelength", "589"]
    assert main(args) == 0
    (report,) = validate(tmp_path / "gltf" / "fit_map.gltf")
    assert _problems(report) == [] and report["info"]["hasDefaultScene"]
    material = GF.load_gltf(tmp_path / "gltf" / "fit_map.gltf")["materials"][0]
    assert material["extras"]["thinfilm_jax"]["index_wavelength_nm"] == 589.0
    n589 = float(np.real(refractive_index("water")(589.0)))
    assert material["extensions"][G.EXTENSION]["iridescenceIor"] == n589
    assert material["pbrMetallicRoughness"]["roughnessFactor"] == 0.0  # a mirror fit
    summary = json.loads((tmp_path / "out" / "fit_photo.json").read_text())
    assert summary["gltf"]["unfitted_pixels_filled"] == 24
    fitted = np.load(tmp_path / "out" / "thickness.npy")
    film, _ = GF.read_gltf(tmp_path / "gltf" / "fit_map.gltf")
    back = np.asarray(film.thickness)
    bound = (np.nanmax(fitted) - np.nanmin(fitted)) / 510
    assert np.isfinite(back).all()
    np.testing.assert_allclose(back[:, :4], fitted[:, :4], rtol=0, atol=bound * (1 + 1e-9))
    np.testing.assert_allclose(back[:, 4:], back[:, 3:4].repeat(4, 1), rtol=0, atol=1e-9)
