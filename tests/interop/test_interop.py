"""glTF `KHR_materials_iridescence` and OpenPBR `thin_film_*` interop (`thinfilm_jax.interop`).

Against the formats' own texts: field names and defaults of the ratified schema
`material.KHR_materials_iridescence.schema.json` (and the draft spelling `iridescenceIOR`),
`KHR_materials_ior` (1.5), glTF's default `metallicFactor` 1, the README's
thickness = mix(min, max, texture.g) (min > max allowed: "MAY be greater"); OpenPBR Surface
v1.1.1's thin_film_thickness in µm (default 0.5), thin_film_ior 1.4, thin_film_weight 0,
specular_ior 1.5. Textures are read back with OpenImageIO directly, not through the module.
"""

import json
import math

import numpy as np
import pytest

import thinfilm_jax as tf
from thinfilm_jax.interop import gltf as G
from thinfilm_jax.interop import gltf_file as GF
from thinfilm_jax.interop import openpbr as P

EXT = "KHR_materials_iridescence"
DIELECTRIC = {"pbrMetallicRoughness": {"metallicFactor": 0.0}}


def material(ext=None, **top):
    return {**DIELECTRIC, **top, "extensions": {EXT: dict(ext or {}),
                                                **top.get("extensions", {})}}


FILMS = [tf.Film(350.0, 1.33, 1.52), tf.Film(0.0, 1.0, 1.0), tf.Film(1234.5678, 2.4, 1.2),
         tf.Film(0.1, 1.0000001, 3.7), tf.Film(np.float32(407.3), np.float32(1.41), 1.5)]


# ---------------------------------------------------------------------------------- glTF
@pytest.mark.parametrize("factor", [0.0, 0.37, 1.0])
def test_gltf_round_trip_is_exact(factor):
    """film → material → JSON text → film: every field bit-exact (JSON keeps float64)."""
    for film in FILMS:
        got, f = tf.film_from_gltf(json.loads(json.dumps(tf.film_to_gltf(film, factor))))
        want = tuple(float(np.asarray(x)) for x in film)
        assert tuple(got) == want and f == factor, (got, film)


def test_gltf_schema_defaults_and_spellings():
    film, factor = tf.film_from_gltf(material())
    assert tuple(film) == (400.0, 1.3, 1.5, 0.0, 1.0) and factor == 0.0  # schema defaults
    film, _ = tf.film_from_gltf(material({"iridescenceIOR": 1.8}))  # draft spelling
    assert film.eta_film == 1.8
    film, _ = tf.film_from_gltf(material(extensions={"KHR_materials_ior": {"ior": 1.7}}))
    assert film.eta_base == 1.7
    # a metal base: glTF has only a Schlick tint, so the caller gives η₃ + iκ₃
    metal = {"extensions": {EXT: {"iridescenceThicknessMaximum": 600.0}}}  # metallic default 1
    film, _ = tf.film_from_gltf(metal, eta_base=2.0, kappa_base=0.5)
    assert tuple(film) == (600.0, 1.3, 2.0, 0.5, 1.0)


def test_gltf_texture_mapping_and_mix():
    """thickness = mix(min, max, g), min > max allowed (inverted); factor × texture.r; the
    iridescenceFactor mix is F_schlick at 0 and khr at 1."""
    ext = {"iridescenceThicknessMinimum": 500.0, "iridescenceThicknessMaximum": 200.0,
           "iridescenceThicknessTexture": {"index": 0}, "iridescenceFactor": 0.5,
           "iridescenceTexture": {"index": 1}}
    g = np.array([0.0, 0.25, 1.0])
    film, factor = tf.film_from_gltf(material(ext), thickness_g=g, factor_r=np.array([1, 0.5, 0]))
    np.testing.assert_array_equal(film.thickness, [500.0, 425.0, 200.0])
    np.testing.assert_array_equal(factor, [0.5, 0.25, 0.0])
    film = tf.Film(300.0, 1.33, 1.5)
    base = tf.fresnel_schlick(tf.normal_reflectance(1.5), 0.6)
    khr = tf.khr_reflectance(film, 0.6)
    assert np.array_equal(G.iridescence_mix(base, khr, 0.0), np.broadcast_to(base, (3,)))
    assert np.array_equal(G.iridescence_mix(base, khr, 1.0), khr)


BAD_GLTF = [
    (material({"iridescenceThickness": 300.0}), "unknown"),
    (material({"iridescenceThicknessMaximum": -1.0}), r"\[0.0, inf\]"),
    (material({"iridescenceThicknessMinimum": -5.0}), r"\[0.0, inf\]"),
    (material({"iridescenceIor": float("nan")}), "finite"),
    (material({"iridescenceFactor": 1.5}), r"\[0.0, 1.0\]"),
    (material({"iridescenceIor": 0.9}), r"\[1.0, inf\]"),
    (material({"iridescenceIor": "1.3"}), "number"),
    (material({"iridescenceFactor": True}), "number"),
    (material({"iridescenceIor": 1.3, "iridescenceIOR": 1.4}), "both"),
    (material({"iridescenceThicknessTexture": {"index": 0}}), "thickness_g"),
    (material({"iridescenceTexture": {"index": 0}}), "factor_r"),
    ({"extensions": {EXT: {}}}, "metallic"),  # glTF's default metallicFactor is 1
    (material(pbrMetallicRoughness={"metallicFactor": 0.5}), "mixes"),
    (material(extensions={"KHR_materials_specular": {"specularFactor": 0.5}}), "specular"),
    (material(extensions={"KHR_materials_ior": {"ior": 0.5}}), "ior"),
    ({"extensions": {}}, "no extensions"),
]


@pytest.mark.parametrize("bad, match", BAD_GLTF)
def test_gltf_bad_input_is_a_clear_error(bad, match):
    with pytest.raises(ValueError, match=match):
        tf.film_from_gltf(bad)


def test_gltf_what_it_cannot_hold_is_an_error():
    with pytest.raises(ValueError, match="absorbing base"):
        tf.film_to_gltf(tf.Film(300.0, 1.3, 2.0, 0.5))
    with pytest.raises(ValueError, match="eta_outer"):
        tf.film_to_gltf(tf.Film(300.0, 1.3, 2.0, 0.0, 1.33))
    with pytest.raises(ValueError, match="factor"):
        tf.film_to_gltf(tf.Film(300.0, 1.3, 2.0), factor=1.2)
    with pytest.raises(ValueError, match="ior >= 1"):
        tf.film_to_gltf(tf.Film(300.0, 1.3, 0.5))
    with pytest.raises(ValueError, match="one value"):
        tf.film_to_gltf(tf.Film(np.array([1.0, 2.0]), 1.3, 1.5))
    with pytest.raises(ValueError, match="eta_base=/kappa_base= are for metallic"):
        tf.film_from_gltf(material(), eta_base=2.0)


@pytest.mark.parametrize("bits", [8, 16])
def test_thickness_texture_round_trip(tmp_path, bits):
    """A map written by `write_gltf` and read back with OpenImageIO directly (G codes over
    2ᵇ − 1, mapped through the material's min/max) reproduces the map to the PNG quantisation
    |Δd| ≤ (max − min)/(2(2ᵇ − 1)) (8-bit: 0.984 nm and 16-bit: 3.83e-3 nm for this 79–581 nm
    map; measured 0.984 and 3.82e-3: rounding to the nearest code); the extremes are exact,
    R = B = 0, the PNG has the asked bit depth; `read_gltf` gives the same film."""
    import OpenImageIO as oiio

    y, x = np.mgrid[0:24, 0:32]
    d = 330.0 + 250.0 * np.sin(x / 5.0) * np.cos(y / 7.0)
    d[0, 0], d[-1, -1] = d.min() - 1.0, d.max() + 1.0  # extremes in known places
    film = tf.Film(d, 1.33, 1.5)
    doc = GF.write_gltf(tmp_path / "film.gltf", film, 0.9, bits=bits)
    ext = json.loads((tmp_path / "film.gltf").read_text())["materials"][0]["extensions"][EXT]
    assert doc["materials"][0]["extensions"][EXT] == ext
    lo, hi = ext["iridescenceThicknessMinimum"], ext["iridescenceThicknessMaximum"]
    assert (lo, hi) == (d.min(), d.max())
    inp = oiio.ImageInput.open(str(tmp_path / "film_thickness.png"))
    spec = inp.spec()
    raw = np.asarray(inp.read_image(format=spec.format))
    inp.close()
    assert str(spec.format) == f"uint{bits}" and raw.shape == d.shape + (3,)
    assert not raw[..., 0].any() and not raw[..., 2].any()
    back = lo * (1 - raw[..., 1] / (2**bits - 1)) + hi * (raw[..., 1] / (2**bits - 1))
    bound = (hi - lo) / (2 * (2**bits - 1))
    err = np.abs(back - d)
    assert err.max() <= bound * (1 + 1e-9), (err.max(), bound)
    assert err.max() > 0.9 * bound  # the quantisation is really b bits
    assert back[0, 0] == lo and back[-1, -1] == hi
    got, factor = GF.read_gltf(tmp_path / "film.gltf")
    np.testing.assert_allclose(got.thickness, back, rtol=0, atol=1e-9)
    assert tuple(got[1:]) == (1.33, 1.5, 0.0, 1.0) and factor == 0.9
    with pytest.raises(ValueError, match="no material"):
        GF.read_gltf(tmp_path / "film.gltf", material=3)


def test_thickness_texture_bad_input(tmp_path):
    with pytest.raises(ValueError, match="finite"):
        G.write_thickness_texture(tmp_path / "t.png", np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="finite"):
        G.write_thickness_texture(tmp_path / "t.png", np.array([[1.0, -2.0]]))
    with pytest.raises(ValueError, match="bits"):
        G.write_thickness_texture(tmp_path / "t.png", np.ones((2, 2)), bits=12)
    lo, hi = G.write_thickness_texture(tmp_path / "c.png", np.full((2, 3), 250.0))
    assert (lo, hi) == (250.0, 250.0)
    np.testing.assert_array_equal(G.read_thickness_texture(tmp_path / "c.png", lo, hi), 250.0)


# ------------------------------------------------------------------------------- OpenPBR
def test_openpbr_round_trip():
    """Exact except the thickness (nm → µm → nm, ×/÷ 1000): ≤ 1 ulp; measured bit-exact on
    194 of 200 random thicknesses (asserted > half)."""
    rng = np.random.default_rng(3)
    exact, n = 0, 200
    for d, e2, e3, w in zip(rng.uniform(0, 3000, n), rng.uniform(1, 3, n),
                            rng.uniform(1, 3, n), rng.uniform(0, 1, n), strict=True):
        film, weight = P.film_from_openpbr(P.film_to_openpbr(tf.Film(d, e2, e3), w))
        assert tuple(film)[1:] == (e2, e3, 0.0, 1.0) and weight == w
        assert abs(film.thickness - d) <= np.spacing(d)
        exact += film.thickness == d
    assert exact > 0.5 * n, exact


def test_openpbr_units_and_defaults():
    film, weight = P.film_from_openpbr({})
    assert tuple(film) == (500.0, 1.4, 1.5, 0.0, 1.0) and weight == 0.0  # 0.5 µm, v1.1.1
    assert P.film_to_openpbr(tf.Film(250.0, 1.3, 1.5))["thin_film_thickness"] == 0.25
    # the same film through glTF (nm) and OpenPBR (µm)
    g, f = tf.film_from_gltf(tf.film_to_gltf(tf.Film(420.0, 1.38, 1.6), 0.7))
    o, w = P.film_from_openpbr(P.film_to_openpbr(g, f))
    assert tuple(o) == tuple(g) and w == f
    film, _ = P.film_from_openpbr({"base_metalness": 1.0, "base_color": (0.9, 0.6, 0.2)},
                                  eta_base=0.4, kappa_base=2.5)
    assert tuple(film) == (500.0, 1.4, 0.4, 2.5, 1.0)


BAD_OPENPBR = [
    ({"thin_film_thicknes": 0.3}, "unknown"),
    ({"thin_film_thickness": -0.1}, r"\[0.0, inf\]"),
    ({"thin_film_thickness": math.nan}, "finite"),
    ({"thin_film_ior": 0.8}, r"\[1.0, inf\]"),
    ({"thin_film_weight": 2.0}, r"\[0.0, 1.0\]"),
    ({"base_metalness": 1.0}, "F82"),
    ({"base_metalness": 0.3}, "mixes"),
    ({"coat_weight": 0.5}, "coat"),
    ({"specular_weight": 0.5}, "specular_weight"),
    ({"specular_color": (1.0, 0.9, 0.8)}, "specular_color"),
    ({"specular_ior": math.inf}, "finite"),
]


@pytest.mark.parametrize("bad, match", BAD_OPENPBR)
def test_openpbr_bad_input_is_a_clear_error(bad, match):
    with pytest.raises(ValueError, match=match):
        P.film_from_openpbr(bad)


def test_openpbr_what_it_cannot_hold_is_an_error():
    with pytest.raises(ValueError, match="F82"):
        P.film_to_openpbr(tf.Film(300.0, 1.3, 2.0, 0.5))
    with pytest.raises(ValueError, match="eta_outer"):
        P.film_to_openpbr(tf.Film(300.0, 1.3, 2.0, 0.0, 1.5))
